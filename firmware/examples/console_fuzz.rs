//! Fuzz benchmark of the console parser/executor: at least 1,000,000 random lines (a mix of
//! near-valid commands and random bytes), checks that nothing panics, that every refused line
//! gets exactly one `error:` line and leaves the configuration unchanged, and that the
//! configuration always validates. Prints the count and the rate.
//!
//! `cargo run --release -p regen-fw --example console_fuzz [N]`

use regen_fw::console::{Console, NoStore};
use regen_fw::params::PARAMS;
use regen_fw::{Config, Controller};

use std::time::Instant;

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        // xorshift64*
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn pick<'a>(&mut self, xs: &[&'a str]) -> &'a str {
        xs[(self.next() % xs.len() as u64) as usize]
    }
}

fn main() {
    let n: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(1_000_000);
    let cmds = [
        "help", "list", "get", "set", "save", "load", "defaults", "status", "faults", "clear",
        "mode", "tel", "", "sett", "SET",
    ];
    let vals = [
        "0", "1", "-1", "1e99", "nan", "inf", "-inf", "3.5", "20000", "1e-30", "0x10", "", "1.",
        ".5e3", "idle", "run", "short", "open", "off", "iq,p", "zz", "306",
    ];
    let names: Vec<&str> = PARAMS.iter().map(|p| p.name).collect();
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let mut ctl = Controller::new(&Config::default()).unwrap();
    let mut con = Console::new();
    let mut ed = regen_fw::console::LineEditor::new();
    let mut out = String::new();
    let mut line = String::new();
    let (mut oks, mut errs) = (0u64, 0u64);
    let t0 = Instant::now();
    for i in 0..n {
        line.clear();
        if rng.next().is_multiple_of(4) {
            // random bytes (valid UTF-8 via char mapping), including control chars
            let len = rng.next() % 40;
            for _ in 0..len {
                let c = char::from_u32((rng.next() % 0x3000) as u32).unwrap_or('?');
                line.push(c);
            }
        } else {
            line.push_str(rng.pick(&cmds));
            let k = rng.next() % 4;
            for j in 0..k {
                line.push(' ');
                if j == 0 && rng.next().is_multiple_of(2) {
                    line.push_str(rng.pick(&names));
                } else {
                    line.push_str(rng.pick(&vals));
                }
            }
        }
        if i.is_multiple_of(1000) {
            // occasionally reset so that "run" mode does not persist forever
            ctl = Controller::new(&Config::default()).unwrap();
        }
        let before = *ctl.config();
        out.clear();
        // The same bytes through the line editor, with a line end: it hands on at most one
        // line (not longer than it takes) and never panics.
        let mut lines = 0;
        for &b in line.as_bytes().iter().chain(b"\r") {
            if let Some(l) = ed.feed(b, &mut out) {
                assert!(l.len() <= regen_fw::console::LINE_MAX, "{line:?}");
                lines += 1;
            }
        }
        assert!(lines <= 1 + line.matches(['\r', '\n']).count(), "{line:?}");
        out.clear();
        match con.execute(&line, &mut ctl, &mut NoStore, &mut out) {
            Ok(()) => oks += 1,
            Err(_) => {
                errs += 1;
                assert_eq!(*ctl.config(), before, "{line:?}");
                assert!(
                    out.starts_with("error: ") && out.matches('\n').count() == 1,
                    "{line:?} -> {out:?}"
                );
            }
        }
        assert!(ctl.config().validate().is_ok(), "{line:?}");
    }
    let dt = t0.elapsed().as_secs_f64();
    println!(
        "console_fuzz: {n} inputs ({oks} ok, {errs} refused) in {dt:.2} s = {:.0} inputs/s, no panic, refusals changed nothing",
        n as f64 / dt
    );
}
