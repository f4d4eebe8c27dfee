//! Time to diagnose a 1,000,000-sample record (target: under 1 s on one core). Prints the
//! figure; run with `cargo bench -p hal-sim --bench diagnose`. `BENCH_N=200000` diagnoses a
//! record of that many samples instead; `BENCH_ONE_RUN=1` runs once in this process (with
//! `BENCH_N=200000`, a short run under callgrind, whose instruction counts do not depend on
//! the machine's load). The figure is the best of `BENCH_REPS` runs (5 by
//! default), each in a fresh process as a user's `regen diagnose` is: a process that has
//! already diagnosed once runs faster (its allocator holds the memory), which no user sees.
use hal_sim::diagnose::synth::{self, SynthSpec};
use hal_sim::diagnose::{diagnose, parse_csv, Options};
use std::time::Instant;

mod common;
use common::env_number;

/// CPU time of this thread so far (s), from /proc (Linux); None elsewhere. On a shared
/// machine the wall time includes waiting for a core; the CPU time does not.
fn cpu_s() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let ns: f64 = s.split_whitespace().next()?.parse().ok()?;
    Some(ns * 1e-9)
}

/// The record's size and seed from `BENCH_N` and `BENCH_SEED` (a message for a bad value,
/// its default used).
fn record_settings() -> (usize, u64) {
    let n = env_number(
        "BENCH_N",
        1_000_000usize,
        |&k| k >= 1000,
        "a number of samples of at least 1000",
    );
    // BENCH_SEED: another record of the same generator (42 by default: the one the < 1 s
    // target is measured on)
    let seed = env_number("BENCH_SEED", 42u64, |_| true, "an unsigned integer");
    (n, seed)
}

/// One run in this process: the record of `n` samples and `seed` generated, parsed and
/// diagnosed, its figures printed.
fn one_run(n: usize, seed: u64) {
    let spec = SynthSpec::random_hidden(seed, n, 2);
    let csv = synth::generate_csv(&spec);
    let c0 = cpu_s();
    let t0 = Instant::now();
    let rec = parse_csv(&csv, None).expect("parses");
    let t_read = t0.elapsed();
    let t1 = Instant::now();
    // BENCH_WHOLE_RECORD=1: screened over the whole record instead of the screening window
    // (the check that the window changes no finding on this record)
    let opt = match std::env::var("BENCH_WHOLE_RECORD") {
        Ok(_) => Options {
            screen_window: n,
            ..Options::default()
        },
        Err(_) => Options::default(),
    };
    let d = diagnose(&rec, &opt);
    let t_diag = t1.elapsed();
    let c1 = cpu_s();
    let found: Vec<&str> = d.findings.iter().map(|f| f.effect.as_str()).collect();
    let hidden: Vec<&str> = spec.hidden.iter().map(|(e, _)| e.kind.name()).collect();
    println!("record: {n} samples, hidden {hidden:?}, found {found:?}");
    for f in d.findings.iter().filter(|f| f.effect != "unexplained") {
        println!("  {}: {:?}", f.effect, f.parameters);
    }
    println!(
        "parse + zero-phase derivatives: {:.3} s",
        t_read.as_secs_f64()
    );
    println!(
        "diagnose (fit, screening, refit, residual analysis): {:.3} s",
        t_diag.as_secs_f64()
    );
    println!(
        "total: {:.3} s wall (target < 1 s, one core)",
        (t_read + t_diag).as_secs_f64()
    );
    if let (Some(a), Some(b)) = (c0, c1) {
        println!("total CPU time of the diagnosing thread: {:.3} s", b - a);
    }
}

/// The seconds of a run's `total:` line.
fn total_of(out: &str) -> Option<f64> {
    let line = out.lines().find(|l| l.starts_with("total:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

fn main() {
    // (a bad value's message once, here; the runs are given the values used)
    let (n, seed) = record_settings();
    if std::env::var_os("BENCH_ONE_RUN").is_some() {
        return one_run(n, seed);
    }
    let reps = env_number(
        "BENCH_REPS",
        5usize,
        |k| (1..=100).contains(k),
        "a number of runs from 1 to 100",
    );
    let exe = match std::env::current_exe() {
        Ok(e) => e,
        Err(e) => {
            eprintln!("diagnose bench: cannot find its own executable ({e}); one run here");
            return one_run(n, seed);
        }
    };
    let mut runs: Vec<(f64, String)> = Vec::with_capacity(reps);
    for _ in 0..reps {
        let out = std::process::Command::new(&exe)
            .args(std::env::args_os().skip(1))
            .env("BENCH_ONE_RUN", "1")
            .env("BENCH_N", n.to_string())
            .env("BENCH_SEED", seed.to_string())
            .stderr(std::process::Stdio::inherit())
            .output();
        match out {
            Ok(o) if o.status.success() => {
                let text = String::from_utf8_lossy(&o.stdout).into_owned();
                match total_of(&text) {
                    Some(t) => runs.push((t, text)),
                    None => eprintln!("diagnose bench: a run printed no total:\n{text}"),
                }
            }
            Ok(o) => eprintln!("diagnose bench: a run failed ({})", o.status),
            Err(e) => eprintln!("diagnose bench: a run could not start: {e}"),
        }
    }
    let Some((best, text)) = runs.iter().min_by(|a, b| a.0.total_cmp(&b.0)) else {
        eprintln!("diagnose bench: no run finished");
        std::process::exit(1);
    };
    let all: Vec<String> = runs.iter().map(|r| format!("{:.3}", r.0)).collect();
    for line in text.lines() {
        if line.starts_with("total:") {
            println!(
                "total: {best:.3} s wall, the best of {} runs each in a fresh process ({} s) (target < 1 s, one core)",
                runs.len(),
                all.join(", ")
            );
        } else {
            println!("{line}");
        }
    }
}
