//! The `regen` command line as a user meets it: every subcommand with good input ends with
//! its answer; every bad input exits 1 with one line naming the key, the value and the
//! allowed range, and nothing panics (exit 101) or is written.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn regen(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_regen"))
        .args(args)
        .output()
        .expect("spawn regen")
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("regen-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A short reference-TMD scenario (2 s, averaged over the last second).
const TMD: &str = "name = \"t\"\nduration_s = 2.0\nsettle_s = 1.0\n[law]\nkind = \"resistor\"\nr_load_ohm = 306.0\n[drive]\nkind = \"structure\"\n[drive.structure]\nmass_kg = 400.0\nstiffness_n_per_m = 3947.84\n[drive.excitation]\nkind = \"sine\"\na0_m_s2 = 1.0\nfreq_hz = 0.5\n[record]\nchannels = [\"t\", \"x\", \"v\", \"force\"]\nevery = 40\n";

fn scenario(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

/// Exit 1, one line of stderr holding every `needles` item, no panic, and stdout empty of
/// results.
fn refused(o: &Output, needles: &[&str]) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "stderr: {err}");
    assert!(!err.contains("panicked"), "{err}");
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "one line expected: {err}");
    for n in needles {
        assert!(lines[0].contains(n), "`{n}` missing in: {}", lines[0]);
    }
}

#[test]
fn run_prints_its_answer() {
    let d = tmp("run-ok");
    let sc = scenario(&d, "t.toml", TMD);
    let out = d.join("out");
    let o = regen(&[
        "run",
        &sc,
        "--out",
        out.to_str().unwrap(),
        "--window",
        "1,1.5",
    ]);
    let s = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{s}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    for want in [
        "mean harvested power",
        " W over 1.00 … 2.00 s",
        "peak force",
        " N at t =",
        "energy balance",
        "faults latched: none",
    ] {
        assert!(s.contains(want), "`{want}` missing:\n{s}");
    }
    assert!(!s.contains("Energy {"), "debug dump:\n{s}");
    assert!(
        !String::from_utf8_lossy(&o.stderr).contains('%'),
        "progress on a non-terminal"
    );
    for f in ["t.csv", "t-force-t.svg", "t-force-x.svg", "t-force-v.svg"] {
        assert!(out.join(f).is_file(), "{f}");
    }
}

#[test]
fn impossible_physics_is_refused_with_key_value_and_range() {
    let d = tmp("physics");
    let cases: [(&str, &str, &[&str]); 7] = [
        (
            "freq_hz = 0.5",
            "freq_hz = nan",
            &["drive.excitation.freq_hz = NaN", "(0, 50] Hz"],
        ),
        (
            "freq_hz = 0.5",
            "freq_hz = -0.5",
            &["drive.excitation.freq_hz = -0.5", "(0, 50] Hz"],
        ),
        (
            "mass_kg = 400.0",
            "mass_kg = -400.0",
            &["drive.structure.mass_kg = -400", "kg"],
        ),
        (
            "duration_s = 2.0",
            "duration_s = inf",
            &["duration_s = inf", "(0, 100000] s"],
        ),
        (
            "r_load_ohm = 306.0",
            "r_load_ohm = 1e-50",
            &["law.r_load_ohm = 1e-50", "f32"],
        ),
        (
            "r_load_ohm = 306.0",
            "r_load_ohm = -3.0",
            &["law.r_load_ohm = -3", "[0, 1000000000] Ω"],
        ),
        ("every = 40", "every = 0", &["record.every = 0", "≥ 1"]),
    ];
    for (k, (from, to, needles)) in cases.iter().enumerate() {
        let sc = scenario(&d, &format!("bad{k}.toml"), &TMD.replace(from, to));
        let out = d.join(format!("out{k}"));
        let o = regen(&["run", &sc, "--out", out.to_str().unwrap()]);
        refused(&o, needles);
        assert!(!out.exists(), "{to}: output written before the refusal");
    }
}

#[test]
fn bad_command_line_values_are_refused() {
    let d = tmp("args");
    let sc = scenario(&d, "t.toml", TMD);
    let file = scenario(&d, "a-file", "");
    let out = d.join("o");
    let o = out.to_str().unwrap();
    refused(
        &regen(&["run", "/nonexistent/s.toml"]),
        &["/nonexistent/s.toml"],
    );
    refused(
        &regen(&["run", &sc, "--out", &file]),
        &["a-file", "not a directory"],
    );
    refused(
        &regen(&["run", &sc, "--out", o, "--window", "1.5,1"]),
        &["--window = 1.5,1", "[0, 2] s"],
    );
    refused(
        &regen(&["run", &sc, "--out", o, "--window", "1"]),
        &["--window = 1", "two times"],
    );
    refused(
        &regen(&[
            "sweep", &sc, "--out", o, "--param", "freq_hz", "--values", "0.5,nan",
        ]),
        &["--values nan: drive.excitation.freq_hz = NaN", "(0, 50] Hz"],
    );
    refused(
        &regen(&[
            "sweep",
            &sc,
            "--out",
            o,
            "--param",
            "r_load_ohm",
            "--values",
            "10,1e400",
        ]),
        &["--values 1e400: not a finite number", "[0, 1000000000] Ω"],
    );
    refused(
        &regen(&[
            "sweep",
            &sc,
            "--out",
            o,
            "--param",
            "freq_hz",
            "--values=-1",
        ]),
        &["freq_hz = -1", "(0, 50] Hz"],
    );
    refused(
        &regen(&[
            "sweep",
            &sc,
            "--out",
            o,
            "--param",
            "current_bw_hz",
            "--values",
            "1e9",
        ]),
        &["current_bw_hz = 1000000000", "allowed ["],
    );
    refused(
        &regen(&["sweep", &sc, "--out", o, "--param", "mass"]),
        &["--values", "mass"],
    );
    refused(
        &regen(&["sweep", &sc, "--out", o, "--param", "mass", "--values", "1"]),
        &["unknown parameter `mass`", "r_load_ohm"],
    );
    refused(
        &regen(&["study", "regimes", "--out", o, "--q-min", "nan"]),
        &["--q-min = NaN", "> 0"],
    );
    refused(
        &regen(&["study", "regimes", "--out", o, "--secs", "0"]),
        &["--secs = 0", "(0, 1e5] s"],
    );
    refused(
        &regen(&["sizing", "--ke-paper", "nan"]),
        &["--ke-paper = NaN", "(0, 100] V·s/rad"],
    );
    refused(
        &regen(&["sizing", "--ke-paper=-1"]),
        &["--ke-paper = -1", "(0, 100] V·s/rad"],
    );
    assert!(!out.exists());
}

#[test]
fn sweep_reports_the_fault() {
    let d = tmp("sweep-fault");
    let sc = scenario(&d, "t.toml", TMD);
    let out = d.join("o");
    let o = regen(&[
        "sweep",
        &sc,
        "--out",
        out.to_str().unwrap(),
        "--param",
        "a0_m_s2",
        "--values",
        "1,50",
    ]);
    let s = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{s}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(s.contains("best of the swept points: a0_m_s2 = 1,"), "{s}");
    assert!(
        s.contains("invalid runs: 1 of 2 (no power given, left out of the best): a0_m_s2 = 50"),
        "{s}"
    );
    let line = s.lines().find(|l| l.contains("a0_m_s2 = 50 ")).unwrap();
    assert!(
        line.contains("INVALID: protection latched over_force") && !line.contains(" W"),
        "{line}"
    );
    let csv = std::fs::read_to_string(out.join("sweep-t-a0_m_s2.csv")).unwrap();
    let mut lines = csv.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let k = head
        .iter()
        .position(|h| *h == "fault")
        .expect("fault column");
    let rows: Vec<Vec<String>> = lines
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    let col = |name: &str| {
        let j = head.iter().position(|h| *h == name).unwrap();
        rows.iter().map(|r| r[j].clone()).collect::<Vec<_>>()
    };
    assert_eq!(col("fault"), ["none", "over_force"]);
    assert_eq!(col("valid"), ["true", "false"]);
    // The invalid point has no power.
    assert!(!col("p_closed_loop_w")[0].is_empty() && col("p_closed_loop_w")[1].is_empty());
    let _ = k;
}

#[test]
fn diagnose_refuses_unit_slips_and_bad_cutoffs() {
    let d = tmp("diagnose");
    // 2,000 samples at 1 kHz of a friction-and-inertia force on a sine stroke.
    let row = |k: usize, tscale: f64, xscale: f64| {
        let t = k as f64 * 1e-3;
        let w = std::f64::consts::TAU * 2.0;
        let (x, v, a) = (
            0.01 * (w * t).sin(),
            0.01 * w * (w * t).cos(),
            -0.01 * w * w * (w * t).sin(),
        );
        format!(
            "{},{},{}\n",
            t * tscale,
            x * xscale,
            20.0 * a + 200.0 * v + 5.0 * v.signum()
        )
    };
    let make = |name: &str, ts: f64, xs: f64| {
        let mut s = String::from("t_s,x_m,f_N\n");
        for k in 0..2000 {
            s += &row(k, ts, xs);
        }
        scenario(&d, name, &s)
    };
    let good = make("good.csv", 1.0, 1.0);
    let ms = make("ms.csv", 1e3, 1.0);
    let mm = make("mm.csv", 1.0, 1e3);
    let o = regen(&["diagnose", &good]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    refused(
        &regen(&["diagnose", &ms]),
        &[
            "ms.csv",
            "column t_s looks wrong",
            "1.0000 Hz",
            "[10, 1e6] Hz",
            "milliseconds",
        ],
    );
    refused(
        &regen(&["diagnose", &mm]),
        &["mm.csv", "column x_m looks wrong", "stroke 20 m", "≤ 10 m"],
    );
    refused(
        &regen(&["diagnose", &good, "--cutoff-hz", "0"]),
        &["--cutoff-hz = 0", "> 0"],
    );
    refused(
        &regen(&["diagnose", &good, "--cutoff-hz", "nan"]),
        &["--cutoff-hz = NaN"],
    );
    refused(
        &regen(&["diagnose", &good, "--cutoff-hz", "600"]),
        &["cutoff_hz = 600", "(0, 500", "good.csv"],
    );
    refused(
        &regen(&["diagnose", &good, "--min-gain", "2"]),
        &["--min-gain = 2", "[0, 1)"],
    );
    refused(
        &regen(&["diagnose", "/nonexistent/r.csv"]),
        &["/nonexistent/r.csv"],
    );
    let file = scenario(&d, "f", "");
    refused(
        &regen(&["diagnose", &good, "--plots", &file]),
        &["--plots", "not a directory"],
    );
}

#[test]
fn sizing_and_design_print_their_answer() {
    let o = regen(&["sizing"]);
    assert!(o.status.success());
    assert!(String::from_utf8_lossy(&o.stdout).contains("c_short"));
    let o = regen(&["study", "design"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// `regen client` and `regen serve` refuse bad input with one line naming the key, the value
/// and the range, before opening anything.
#[test]
fn client_and_serve_refuse_bad_input() {
    let d = tmp("client-serve");
    refused(
        &regen(&["client", "/nonexistent/tty", "status"]),
        &["port /nonexistent/tty", "cannot open"],
    );
    refused(
        &regen(&["client", "/nonexistent/tty", "status", "--timeout", "0"]),
        &["--timeout = 0", "(0, 3600] s"],
    );
    refused(
        &regen(&["client", "/nonexistent/tty", "status", "--timeout", "nan"]),
        &["--timeout = NaN", "(0, 3600] s"],
    );
    refused(
        &regen(&["client", "/nonexistent/tty", "status", "--listen", "-1"]),
        &["--listen = -1", "[0, 86400] s"],
    );
    refused(
        &regen(&["client", "/nonexistent/tty", "status", "--baud", "0"]),
        &["--baud = 0", "[50, 4000000] Bd"],
    );
    refused(
        &regen(&[
            "client",
            "/nonexistent/tty",
            "--script",
            "/nonexistent/s.txt",
        ]),
        &["--script /nonexistent/s.txt"],
    );
    refused(
        &regen(&["client", "/nonexistent/tty"]),
        &["nothing to do", "--script"],
    );
    #[cfg(unix)]
    {
        refused(
            &regen(&["serve", "--speed", "0"]),
            &["--speed = 0", "(0, 1e6]", "`max`"],
        );
        refused(
            &regen(&["serve", "--speed", "-2"]),
            &["--speed = -2", "(0, 1e6]"],
        );
        refused(
            &regen(&["serve", "--speed", "fast"]),
            &["--speed = fast", "(0, 1e6]"],
        );
        refused(
            &regen(&["serve", "--duration", "-1"]),
            &["--duration = -1", "(0, 1e9] simulated s"],
        );
        refused(
            &regen(&["serve", "/nonexistent/s.toml"]),
            &["/nonexistent/s.toml"],
        );
        let bad = scenario(
            &d,
            "bad.toml",
            &TMD.replace("freq_hz = 0.5", "freq_hz = nan"),
        );
        refused(
            &regen(&["serve", &bad]),
            &["drive.excitation.freq_hz = NaN", "(0, 50] Hz"],
        );
        refused(
            &regen(&["serve", "--duration", "1", "--link", "/nonexistent/dir/tty"]),
            &["--link /nonexistent/dir/tty"],
        );
    }
}

/// `regen serve` on a pty with `regen client` talking to it: an answer, a refusal with the
/// range and the current value (exit 1, the error printed once), and the server's summary
/// after Ctrl-C.
#[cfg(unix)]
#[test]
fn serve_answers_client_on_a_pty() {
    use std::io::{BufRead, BufReader, Read};
    use std::process::Stdio;
    let mut child = Command::new(env!("CARGO_BIN_EXE_regen"))
        .args(["serve", "--speed", "10", "--duration", "600"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn regen serve");
    let mut out = BufReader::new(child.stdout.take().unwrap());
    let mut first = String::new();
    out.read_line(&mut first).unwrap();
    let pty = first
        .split("console on ")
        .nth(1)
        .unwrap_or_else(|| panic!("no pty path in {first:?}"))
        .trim()
        .to_string();
    let client = |args: &[&str]| {
        let mut a = vec!["client", pty.as_str(), "--timeout", "10"];
        a.extend_from_slice(args);
        regen(&a)
    };
    let o = client(&["get r_load_ohm", "status"]);
    let s = String::from_utf8_lossy(&o.stdout).to_string();
    let result = std::panic::catch_unwind(|| {
        assert!(
            o.status.success(),
            "{s}{}",
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(s.contains("r_load_ohm = 306"), "{s}");
        let o = client(&["set r_load_ohm -5"]);
        let s = String::from_utf8_lossy(&o.stdout);
        assert_eq!(o.status.code(), Some(1), "{s}");
        let errors: Vec<&str> = s.lines().filter(|l| l.starts_with("error:")).collect();
        assert_eq!(errors.len(), 1, "{s}");
        assert!(
            errors[0].contains("r_load_ohm") && errors[0].contains("-5"),
            "{}",
            errors[0]
        );
        assert!(
            o.stderr.is_empty(),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
    });
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(child.id() as i32),
        nix::sys::signal::Signal::SIGINT,
    )
    .unwrap();
    let mut rest = String::new();
    out.read_to_string(&mut rest).unwrap();
    let status = child.wait().unwrap();
    if let Err(e) = result {
        std::panic::resume_unwind(e);
    }
    assert!(status.success(), "{rest}");
    assert!(
        rest.contains("stopped:") && rest.contains("real time"),
        "{rest}"
    );
}

/// A usage error (unknown command or option, a number that does not parse, a missing
/// argument) is one line naming what is wrong, exit status 2, no usage block.
#[test]
fn usage_errors_are_one_line() {
    for (args, want) in [
        (&["sweep", "--values", "abc"][..], "'abc' for '--values"),
        (&["run"][..], "<SCENARIO>"),
        (&["frob"][..], "'frob'"),
        (&["run", "x.toml", "--bogus"][..], "'--bogus'"),
    ] {
        let o = regen(args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
        assert_eq!(lines.len(), 1, "{args:?}: {err}");
        assert!(lines[0].contains(want), "{args:?}: {}", lines[0]);
    }
}
