//! Replay a recorded sample file through the default controller on the host and print the
//! digest of every output (compare with the Cortex-M4 run of `firmware/m4check`).
//!
//! `cargo run -p regen-fw --example digest -- firmware/m4check/vectors.bin`

use regen_fw::selftest::replay;
use regen_fw::{Config, Controller, Mode};

fn main() {
    let path = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "firmware/m4check/vectors.bin".into());
    let rec = match std::fs::read(&path) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: cannot read {path}: {e}");
            std::process::exit(2);
        }
    };
    let cfg = Config::default();
    let mut ctl = Controller::new(&cfg).unwrap();
    ctl.set_mode(Mode::Run).unwrap();
    let half = rec.len() / regen_fw::selftest::STEP_BYTES / 2;
    let every = ctl.supervise_every() as usize;
    let mut k = 0usize;
    let (digest, steps) = replay(&mut ctl, &rec, |c, s| {
        if k == half {
            c.set_config(&Config {
                r_load_ohm: 2.0,
                ..cfg
            })
            .unwrap();
        }
        k += 1;
        let a = c.step(s);
        // Protection supervision every 20 steps (1 kHz) on a copy, as the Cortex-M4 run
        // does (see there).
        if k.is_multiple_of(every) {
            c.clone().supervise();
        }
        a
    });
    println!("digest={digest:016x} steps={steps}");
    if let Some(f) = ctl.fault() {
        eprintln!("fault latched during the replay: {}", f.name());
    }
}
