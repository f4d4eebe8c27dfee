//! The diagnosis on records of the independent bench rig (`hal_sim::bench_rig`: effects as
//! physics, several trajectory families, random noise and sensor resolution). Per hidden kind:
//! exactly right (catalogue names = the hidden one, or none), detection rate, false names.

use hal_sim::bench_rig::{Hidden, RigSpec, Trajectory};
use hal_sim::diagnose::{diagnose, parse_csv, Options};
use std::collections::BTreeMap;

fn emps_x() -> Option<Vec<f64>> {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data/emps/emps_estimation.csv");
    let r = hal_sim::diagnose::read_csv(&p, None).ok()?;
    Some(r.x)
}

#[derive(Default)]
struct Tally {
    records: usize,
    exact: usize,
    detected: usize,
    false_name: usize,
}

/// Run `per_kind` records of every kind, trajectories cycling; returns the tallies.
fn run(per_kind: usize, samples: usize, seed0: u64) -> BTreeMap<&'static str, Tally> {
    let emps = emps_x();
    let mut out: BTreeMap<&'static str, Tally> = BTreeMap::new();
    for (ki, kind) in Hidden::KINDS.iter().enumerate() {
        for j in 0..per_kind {
            let seed = seed0 + (ki * 100_000 + j) as u64;
            let traj = match j % 5 {
                0 => Trajectory::Multisine,
                1 => Trajectory::RoundedTriangle,
                2 => Trajectory::PointToPoint,
                3 => Trajectory::Narrowband,
                _ => match &emps {
                    Some(x) => Trajectory::Recorded(x[..samples.min(x.len())].to_vec()),
                    None => Trajectory::Multisine,
                },
            };
            let spec = RigSpec::random(seed, kind, traj, samples);
            let rec = parse_csv(&spec.csv(), None).expect("rig record parses");
            let d = diagnose(&rec, &Options::default());
            let names: Vec<&str> = d
                .findings
                .iter()
                .filter(|f| f.effect != "unexplained")
                .map(|f| f.effect.as_str())
                .collect();
            let unexpl = d.findings.iter().any(|f| f.effect == "unexplained");
            let want = spec.hidden.expected();
            let detected = match want {
                None => true,
                Some("unexplained") => unexpl,
                Some(w) => names.contains(&w),
            };
            let false_names = names.iter().any(|n| Some(*n) != want);
            let exact = detected && !false_names;
            let t = out.entry(kind).or_default();
            t.records += 1;
            t.exact += exact as usize;
            t.detected += detected as usize;
            t.false_name += false_names as usize;
            println!(
                "{kind:>20} {:>16} seed {seed}: hidden {:?} (rms {:.2} N, noise {:.2} N, observable {}) -> {:?}{} held-out {:.2} % -> {:.2} %{}",
                spec.trajectory.name(),
                spec.hidden,
                spec.effect_rms_n,
                spec.noise_n,
                spec.observable,
                names,
                if unexpl { " + unexplained" } else { "" },
                100.0 * d.baseline_holdout_rel_error,
                100.0 * d.final_holdout_rel_error,
                if exact { "" } else { "  <-- not exact" }
            );
        }
    }
    println!(
        "{:>20} {:>8} {:>8} {:>9} {:>11}",
        "kind", "records", "exact", "detected", "false name"
    );
    for (k, t) in &out {
        println!(
            "{k:>20} {:>8} {:>7.0}% {:>8.0}% {:>10.0}%",
            t.records,
            100.0 * t.exact as f64 / t.records as f64,
            100.0 * t.detected as f64 / t.records as f64,
            100.0 * t.false_name as f64 / t.records as f64
        );
    }
    out
}

#[test]
#[ignore]
fn rig_long_run() {
    let n: usize = std::env::var("RIG_N")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(60);
    let t = run(n, 12_000, 1);
    let all: usize = t.values().map(|t| t.records).sum();
    let exact: usize = t.values().map(|t| t.exact).sum();
    println!("all kinds: {exact}/{all} exactly right");
}

#[test]
fn rig_sample() {
    let t = run(3, 8_000, 500);
    let all: usize = t.values().map(|t| t.records).sum();
    let exact: usize = t.values().map(|t| t.exact).sum();
    let detected: usize = t.values().map(|t| t.detected).sum();
    println!("all kinds: {exact}/{all} exactly right, {detected}/{all} detected");
    // measured 2026-11-24: 15/27 exactly right, 20/27 detected (the targets, 95 % exactly
    // right, are not reached); the bounds guard what is reached, about 3 records of margin
    // (a seeded sample: the figures move only with the code)
    assert!(exact >= 12, "{exact}/{all} exactly right (measured 15)");
    assert!(detected >= 17, "{detected}/{all} detected (measured 20)");
}
