//! A reader that goes away ends every command quietly: each command's standard output is a
//! pipe whose reading end is already closed (as `regen … | head -0`), or one a reader closes
//! after the first two lines (`regen client … | head -2`); the command ends by SIGPIPE, as
//! `cat` does, or with a status below 101 and without a word on stderr (no panic).

#![cfg(unix)]

use std::io::{BufRead, BufReader};
use std::os::unix::process::ExitStatusExt;
use std::process::{Command, Stdio};
use std::time::Duration;

fn quiet(what: &str, st: std::process::ExitStatus, err: &str) {
    assert!(
        !err.contains("panicked") && !err.contains("Broken pipe"),
        "{what}: {err}"
    );
    assert!(
        st.signal() == Some(nix::sys::signal::Signal::SIGPIPE as i32)
            || st.code().is_some_and(|c| c < 101),
        "{what}: {st:?} {err}"
    );
    println!("{what}: {st:?}");
}

/// `regen ARGS` with its stdout a pipe closed on the reading side before it writes.
fn closed_at_once(args: &[&str]) {
    let (r, w) = std::io::pipe().unwrap();
    drop(r);
    let o = Command::new(env!("CARGO_BIN_EXE_regen"))
        .args(args)
        .stdout(Stdio::from(w))
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    quiet(
        &args.join(" "),
        o.status,
        &String::from_utf8_lossy(&o.stderr),
    );
}

#[test]
fn closed_pipes_end_every_command_quietly() {
    let d = std::env::temp_dir().join(format!("regen-pipe-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    let out = d.join("out");
    let out = out.to_str().unwrap();
    let sc = d.join("t.toml");
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/scenarios/tmd-306.toml"
    ))
    .unwrap()
    .replace("duration_s = 12.0", "duration_s = 1.0")
    .replace("settle_s = 8.0", "settle_s = 0.5");
    std::fs::write(&sc, text).unwrap();
    let sc = sc.to_str().unwrap();
    // A record for the diagnosis: the run's own, in its schema.
    let rec = d.join("rec.csv");
    let rec = rec.to_str().unwrap();
    let st = Command::new(env!("CARGO_BIN_EXE_regen"))
        .args(["run", sc, "-q", "--out", out, "--record-diagnose", rec])
        .output()
        .unwrap();
    assert!(st.status.success());
    closed_at_once(&["sizing"]);
    closed_at_once(&["--help"]);
    closed_at_once(&["run", sc, "-q", "--out", out]);
    closed_at_once(&["sweep", sc, "-q", "--out", out, "--values", "100,306"]);
    closed_at_once(&["diagnose", rec]);
}

/// `regen client PTY status help … | head -2` against `regen serve`.
#[test]
fn client_into_head_ends_quietly() {
    let mut serve = Command::new(env!("CARGO_BIN_EXE_regen"))
        .args(["serve", "--speed", "1", "--duration", "120"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Kept open to the end: `serve` writes a second line, and a closed pipe ends it.
    let mut serve_out = BufReader::new(serve.stdout.take().unwrap());
    let mut first = String::new();
    serve_out.read_line(&mut first).unwrap();
    let path = first
        .split("console on ")
        .nth(1)
        .expect("pty path")
        .trim()
        .to_string();
    let mut client = Command::new(env!("CARGO_BIN_EXE_regen"))
        .args(["client", &path, "help", "list", "status", "list", "help"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(client.stdout.take().unwrap()).lines();
    for _ in 0..2 {
        lines.next().expect("a line").unwrap();
    }
    drop(lines);
    // The client writes on; wait (bounded) for it to end.
    let mut st = None;
    for _ in 0..200 {
        if let Some(s) = client.try_wait().unwrap() {
            st = Some(s);
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let _ = serve.kill();
    let _ = serve.wait();
    drop(serve_out);
    let st = st.unwrap_or_else(|| {
        let _ = client.kill();
        panic!("client still running 10 s after its reader closed")
    });
    let mut err = String::new();
    std::io::Read::read_to_string(&mut client.stderr.take().unwrap(), &mut err).unwrap();
    quiet("client | head -2", st, &err);
}
