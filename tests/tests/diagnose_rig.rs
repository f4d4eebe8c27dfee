//! The diagnosis on records of the independent bench rig (`hal_sim::bench_rig`: effects as
//! physics, several trajectory families, random noise and sensor resolution). Per hidden kind:
//! exactly right (catalogue names = the hidden one, or none), detection rate, false names.

use hal_sim::bench_rig::{Hidden, RigSpec, Trajectory};
use hal_sim::diagnose::{diagnose, parse_csv, Diagnosis, Options};
use std::collections::BTreeMap;

/// The EMPS estimation record's measured position (the repository's `data/emps/`; a missing or
/// unreadable file fails the test with its path).
fn emps_x() -> Vec<f64> {
    let p = regen_tests::emps_file("emps_estimation.csv");
    hal_sim::diagnose::read_csv(&p, None)
        .unwrap_or_else(|e| panic!("EMPS record {}: {e}", p.display()))
        .x
}

/// The long run's trajectory of record `j` of a kind (families in turn; the recorded one is
/// EMPS's position).
fn trajectory(j: usize, emps: &[f64], samples: usize) -> Trajectory {
    match j % 5 {
        0 => Trajectory::Multisine,
        1 => Trajectory::RoundedTriangle,
        2 => Trajectory::PointToPoint,
        3 => Trajectory::Narrowband,
        _ => Trajectory::Recorded(emps[..samples.min(emps.len())].to_vec()),
    }
}

/// The long run's record of a seed (`rig_long_run`: seed 1 + 100,000·kind + j, 12,000 samples).
fn long_run_spec(seed: u64, emps: &[f64]) -> RigSpec {
    let kind = Hidden::KINDS[((seed - 1) / 100_000) as usize];
    let j = ((seed - 1) % 100_000) as usize;
    RigSpec::random(seed, kind, trajectory(j, emps, 12_000), 12_000)
}

/// The long run's record of `seed` (`long_run_spec`) diagnosed with the default options.
fn diagnosed_long_run_record(seed: u64) -> (RigSpec, Diagnosis) {
    let spec = long_run_spec(seed, &emps_x());
    let rec = parse_csv(&spec.csv(), None).expect("rig record parses");
    let d = diagnose(&rec, &Options::default());
    (spec, d)
}

/// The first parameter of the finding named `effect` (0 when there is none).
fn first_parameter(d: &Diagnosis, effect: &str) -> f64 {
    d.findings
        .iter()
        .find(|f| f.effect == effect)
        .map_or(0.0, |f| f.parameters[0].1)
}

/// The record `seed` of the long run is named its hidden effect alone (`lag`, `stribeck`,
/// `presliding_hysteresis` or `backlash`), the finding's first parameter (delay, v_s, x_c,
/// width) within `bound` (relative) of the rig's.
fn named_alone(seed: u64, bound: f64) {
    let (spec, d) = diagnosed_long_run_record(seed);
    let (name, truth) = match spec.hidden {
        Hidden::Delay { delay_s } => ("lag", delay_s),
        Hidden::Stribeck { vs_m_s, .. } => ("stribeck", vs_m_s),
        Hidden::Presliding { x_char_m } => ("presliding_hysteresis", x_char_m),
        Hidden::Backlash { width_m } => ("backlash", width_m),
        _ => panic!("{seed} is a delay, Stribeck, presliding or backlash record"),
    };
    let names = d.catalogue_names();
    let p = first_parameter(&d, name);
    println!("{seed}: {names:?}: {name} {p} for {truth}");
    assert_eq!(names, [name], "{:?}", d.verdicts);
    assert!(
        (p / truth - 1.0).abs() < bound,
        "{seed}: {name} {p} for {truth}"
    );
}

/// The seeds listed in `RIG_SEEDS` (comma-separated).
fn env_seeds() -> Vec<u64> {
    std::env::var("RIG_SEEDS")
        .unwrap_or_default()
        .split(',')
        .filter_map(|s| s.trim().parse().ok())
        .collect()
}

#[derive(Default)]
struct Tally {
    records: usize,
    exact: usize,
    detected: usize,
    false_name: usize,
    /// records whose hidden effect the rig's observability rule holds for, and of them exact
    observable: usize,
    observable_exact: usize,
}

/// One diagnosed record of a run: its tally flags and the lines it prints.
struct Outcome {
    kind: &'static str,
    exact: bool,
    detected: bool,
    false_names: bool,
    observable: bool,
    text: String,
}

/// Diagnose the record of `seed` (`kind`, trajectory family of `j`) and say how it came out.
fn outcome(kind: &'static str, j: usize, seed: u64, samples: usize, emps: &[f64]) -> Outcome {
    use std::fmt::Write;
    let spec = RigSpec::random(seed, kind, trajectory(j, emps, samples), samples);
    let rec = parse_csv(&spec.csv(), None).expect("rig record parses");
    let d = diagnose(&rec, &Options::default());
    let names = d.catalogue_names();
    let unexpl = d.findings.iter().any(|f| f.effect == "unexplained");
    let want = spec.hidden.expected();
    let detected = match want {
        None => true,
        Some("unexplained") => unexpl,
        Some(w) => names.contains(&w),
    };
    let false_names = names.iter().any(|n| Some(*n) != want);
    let exact = detected && !false_names;
    let mut text = format!(
        "{kind:>20} {:>16} seed {seed}: hidden {:?} (rms {:.2} N, noise {:.2} N, observable {}{}) -> {:?}{} held-out {:.2} % -> {:.2} %{}\n",
        spec.trajectory.name(),
        spec.hidden,
        spec.effect_rms_n,
        spec.noise_n,
        spec.observable,
        if spec.requested != spec.trajectory.name() {
            format!("; asked for {}", spec.requested)
        } else {
            String::new()
        },
        names,
        if unexpl { " + unexplained" } else { "" },
        100.0 * d.baseline_holdout_rel_error,
        100.0 * d.final_holdout_rel_error,
        if exact { "" } else { "  <-- not exact" }
    );
    if std::env::var("RIG_EVIDENCE").is_ok() {
        // the evidence of each finding: held-out gain, BIC change, consistency
        for f in &d.findings {
            let _ = writeln!(
                text,
                "    {} {:?}: held-out rss -{:.2} %, ΔBIC {:.1}, held on {:.0} % of segments; {}",
                f.effect,
                f.parameters,
                100.0 * f.holdout_rss_drop,
                f.delta_bic,
                100.0 * f.consistency,
                f.note
            );
        }
        for v in &d.verdicts {
            let _ = writeln!(text, "    verdict: {v}");
        }
    }
    Outcome {
        kind,
        exact,
        detected,
        false_names,
        observable: spec.observable,
        text,
    }
}

/// Whether `RIG_KINDS` or `RIG_SEEDS` narrows the run to some records.
fn narrowed() -> bool {
    std::env::var("RIG_KINDS").is_ok() || std::env::var("RIG_SEEDS").is_ok()
}

/// Run `per_kind` records of every kind, trajectories cycling; returns the tallies. The
/// records are diagnosed in parallel (each alone: the diagnosis is a pure function of its
/// record) and printed and tallied in the order of their seeds.
fn run(per_kind: usize, samples: usize, seed0: u64) -> BTreeMap<&'static str, Tally> {
    use rayon::prelude::*;
    let emps = emps_x();
    // RIG_KINDS=none,delay runs only those kinds (same seeds as in the full run)
    let only = std::env::var("RIG_KINDS").ok();
    // RIG_SEEDS=400002,600022 runs only those records (the seeds of the full run)
    let seeds = std::env::var("RIG_SEEDS").is_ok().then(env_seeds);
    let mut jobs = Vec::new();
    for (ki, kind) in Hidden::KINDS.iter().enumerate() {
        if only
            .as_ref()
            .is_some_and(|o| !o.split(',').any(|k| k == *kind))
        {
            continue;
        }
        for j in 0..per_kind {
            let seed = seed0 + (ki * 100_000 + j) as u64;
            if seeds.as_ref().is_none_or(|s| s.contains(&seed)) {
                jobs.push((*kind, j, seed));
            }
        }
    }
    let outcomes: Vec<Outcome> = jobs
        .par_iter()
        .map(|&(kind, j, seed)| outcome(kind, j, seed, samples, &emps))
        .collect();
    let mut out: BTreeMap<&'static str, Tally> = BTreeMap::new();
    for o in &outcomes {
        let t = out.entry(o.kind).or_default();
        t.records += 1;
        t.exact += o.exact as usize;
        t.detected += o.detected as usize;
        t.false_name += o.false_names as usize;
        t.observable += o.observable as usize;
        t.observable_exact += (o.observable && o.exact) as usize;
        print!("{}", o.text);
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

/// The long run (`RIG_N` records per kind, 56 by default: 504 records of 12 s) against
/// issue #16's targets, asserted on the whole run (not when `RIG_KINDS` or `RIG_SEEDS`
/// narrows it): ≥ 95 % of the records exactly right (measured 485/504; the target's 479 is 6
/// records below), ≤ 2 % of the effect-free records given a catalogue name (measured 0/56;
/// the limit is 1), ≥ 90 % of the out-of-catalogue effects (hum, drift) reported
/// `unexplained` (measured 112/112; the limit is 101). The bounds are the issue's; the rig
/// is the independent generator (`hal_sim::bench_rig`). Run by CI (`.ci/run`).
#[test]
#[ignore]
fn rig_long_run() {
    let n: usize = std::env::var("RIG_N")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(56);
    let t = run(n, 12_000, 1);
    let all: usize = t.values().map(|t| t.records).sum();
    let exact: usize = t.values().map(|t| t.exact).sum();
    let obs: usize = t.values().map(|t| t.observable).sum();
    let obs_exact: usize = t.values().map(|t| t.observable_exact).sum();
    println!(
        "all kinds: {exact}/{all} exactly right; of the {obs} records whose effect is observable \
         (the rig's rule), {obs_exact} exactly right"
    );
    if narrowed() {
        return;
    }
    // whole numbers of records: the smallest count that reaches each target
    let floor = |share: f64, of: usize| (share * of as f64 - 1e-9).ceil() as usize;
    assert!(
        exact >= floor(0.95, all),
        "{exact}/{all} exactly right: the target is ≥ 95 % ({})",
        floor(0.95, all)
    );
    let none = &t["none"];
    assert!(
        none.false_name as f64 <= 0.02 * none.records as f64,
        "{}/{} effect-free records given a catalogue name: the target is ≤ 2 %",
        none.false_name,
        none.records
    );
    let (out_all, out_unexpl) = (
        t["hum"].records + t["drift"].records,
        t["hum"].detected + t["drift"].detected,
    );
    assert!(
        out_unexpl >= floor(0.90, out_all),
        "{out_unexpl}/{out_all} out-of-catalogue effects reported unexplained: the target is \
         ≥ 90 % ({})",
        floor(0.90, out_all)
    );
}

#[test]
fn rig_sample() {
    let t = run(3, 8_000, 500);
    let all: usize = t.values().map(|t| t.records).sum();
    let exact: usize = t.values().map(|t| t.exact).sum();
    let detected: usize = t.values().map(|t| t.detected).sum();
    println!("all kinds: {exact}/{all} exactly right, {detected}/{all} detected");
    // measured: 22/27 exactly right, 24/27 detected (the drift point-to-point 800502, its
    // moves running one way then back, carried as a drift since the slow change is also
    // tested beside the baseline's refit); the bounds guard what is reached, 3 records of
    // margin (a seeded sample: the figures move only with the code)
    assert!(exact >= 19, "{exact}/{all} exactly right (measured 22)");
    assert!(detected >= 21, "{detected}/{all} detected (measured 24)");
    // the drift (a slow change of the residual's mean) is reported as unexplained on 3/3
    // drift records, and no effect-free record gets a catalogue name (0/3); one record of
    // margin on the first (the check runs on the baseline residual of any motion)
    assert!(
        t["drift"].detected >= 2,
        "drift detected {}/3 (measured 3)",
        t["drift"].detected
    );
    assert_eq!(
        t["none"].false_name, 0,
        "effect-free records given a catalogue name"
    );
}

/// The rig's linear offset drift (out of the catalogue) on the first four trajectory families
/// of the long run (seeds 800001–800004): reported as a slow change of the residual's mean
/// (`unexplained` with `change_N`), of the hidden drift's sign and size, and given no
/// catalogue name. Size: the baseline's other terms take a part of a drift that correlates
/// with the motion; measured ratios 0.936 (point-to-point) … 1.001, asserted within 0.8 … 1.2
/// (3× the largest measured deviation, 6.4 %).
#[test]
fn drift_is_reported_as_a_slow_change() {
    let trajs = [
        Trajectory::Multisine,
        Trajectory::RoundedTriangle,
        Trajectory::PointToPoint,
        Trajectory::Narrowband,
    ];
    for (j, traj) in trajs.into_iter().enumerate() {
        let seed = 1 + (8 * 100_000 + j) as u64;
        let spec = RigSpec::random(seed, "drift", traj, 12_000);
        let hal_sim::bench_rig::Hidden::Drift { total_n } = spec.hidden else {
            panic!("seed {seed}: not a drift");
        };
        let rec = parse_csv(&spec.csv(), None).expect("rig record parses");
        let d = diagnose(&rec, &Options::default());
        let change = d
            .findings
            .iter()
            .filter(|f| f.effect == "unexplained")
            .find_map(|f| f.parameters.iter().find(|p| p.0 == "change_N").map(|p| p.1));
        let names = d.catalogue_names();
        println!(
            "seed {seed} {}: hidden drift {total_n:.2} N -> slow change {change:?} N, names {names:?}",
            spec.trajectory.name()
        );
        let c = change.unwrap_or_else(|| panic!("seed {seed}: no slow change reported"));
        let ratio = c / total_n;
        assert!(
            (0.8..1.2).contains(&ratio),
            "seed {seed}: {c} N against {total_n} N"
        );
        assert!(names.is_empty(), "seed {seed}: {names:?}");
    }
}

/// A drive acting as a damper whose force saturates (the rig clips c·v at ±L): `current_limit`
/// is named under the drive's hypothesis, with the level and the drive's damping of the rig,
/// on a rounded triangle too (`effects::speed_levels`: without the crossing quantiles its
/// saturation speed is outside the scanned range and `current_limit` is not named).
#[test]
fn clipped_drive_is_named_with_its_level() {
    let mut worst: (f64, f64) = (0.0, 0.0);
    for (seed, traj) in [
        (100_001, Trajectory::Multisine),
        (100_003, Trajectory::PointToPoint),
        (100_004, Trajectory::Narrowband),
        (100_006, Trajectory::Multisine),
        // a motion cruising at one speed: the saturation speed lies below every time
        // quantile of |v| and is scanned through the speeds the motion crosses
        (100_007, Trajectory::RoundedTriangle),
    ] {
        let spec = RigSpec::random(seed, "clipped_current_loop", traj, 12_000);
        let Hidden::ClippedCurrentLoop { limit_n } = spec.hidden else {
            unreachable!()
        };
        let rec = parse_csv(&spec.csv(), None).expect("rig record parses");
        let d = diagnose(&rec, &Options::default());
        let f = d
            .findings
            .iter()
            .find(|f| f.effect == "current_limit")
            .unwrap_or_else(|| panic!("seed {seed}: current_limit not named"));
        let p = |k: &str| f.parameters.iter().find(|(n, _)| n == k).map(|p| p.1);
        let (l, cd) = (p("limit_N").unwrap(), p("drive_damping_Ns_per_m").unwrap());
        let (el, ec) = (l / limit_n - 1.0, cd / spec.drive_damping - 1.0);
        println!(
            "seed {seed}: limit {l:.2} N (rig {limit_n:.2}, {:+.1} %), drive damping {cd:.1} N·s/m (rig {:.1}, {:+.1} %)",
            100.0 * el,
            spec.drive_damping,
            100.0 * ec
        );
        worst = (worst.0.max(el.abs()), worst.1.max(ec.abs()));
    }
    println!(
        "worst: limit {:.1} %, drive damping {:.1} %",
        100.0 * worst.0,
        100.0 * worst.1
    );
    // Measured 2026-11-24: worst 0.5 % on the level and 0.5 % on the drive's damping (the
    // rig's c·v clipped at L, 20 substeps per sample, noise and quantisation; the rounded
    // triangle 0.1 %). Bound 3×: 1.5 %.
    // With the column's sign flipped `current_limit` is named on none of these records.
    assert!(worst.0 < 0.015 && worst.1 < 0.015, "{worst:?}");
}

/// Play named with its width on three rig records (seeds of the long run: rounded triangle,
/// narrowband, multisine; the rig's device behind the gap with a 60 Hz, ζ 0.5 contact):
/// `backlash` the only catalogue name, its width within 4.5 % of the rig's (measured −0.2 %
/// … +1.5 %: 3× the worst), the gain of the force that stops across the gap within the unit
/// range and the impact's momentum within the rule (measured 0.84 … 1.00·M; gain 0.83 … 0.99).
#[test]
fn backlash_is_named_with_its_width() {
    for (seed, traj) in [
        (600_002, Trajectory::RoundedTriangle),
        (600_004, Trajectory::Narrowband),
        (600_006, Trajectory::Multisine),
    ] {
        let spec = RigSpec::random(seed, "backlash", traj, 12_000);
        let Hidden::Backlash { width_m } = spec.hidden else {
            panic!("seed {seed}: not a play record");
        };
        let rec = parse_csv(&spec.csv(), None).expect("rig record parses");
        let d = diagnose(&rec, &Options::default());
        let names = d.catalogue_names();
        assert_eq!(names, ["backlash"], "seed {seed}");
        let f = &d.findings.iter().find(|f| f.effect == "backlash").unwrap();
        let p = |k: &str| f.parameters.iter().find(|(n, _)| n == k).unwrap().1;
        let (w, g, mi) = (p("width_m"), p("gain"), p("impact_mass_kg"));
        println!(
            "seed {seed}: width {w:.4e} m (rig {width_m:.4e}, {:+.1} %), gain {g:.3}, impact {mi:.1} kg (rig mass {:.1} kg)",
            100.0 * (w / width_m - 1.0),
            spec.mass_kg
        );
        assert!(
            (w / width_m - 1.0).abs() < 0.045,
            "seed {seed}: width {w} against {width_m}"
        );
        assert!((0.8..=1.25).contains(&g), "seed {seed}: gain {g}");
        assert!(
            mi >= 0.5 * spec.mass_kg && mi <= 2.0 * spec.mass_kg,
            "seed {seed}: impact {mi} kg, mass {}",
            spec.mass_kg
        );
    }
}

/// The rig's observability rule redraws the trajectory's own parameters when 40 draws of the
/// effect fail on the first motion, and moves the record to the next family when 8 motions of
/// its own fail (`bench_rig`, module doc). Stribeck 400047 (rounded triangle) is observable on
/// its sixth triangle (2.59 N rms in motion against 0.49 N noise); 400002, 400017 and 400022
/// stay unobservable over 8 triangles (a rounded triangle crosses the Stribeck band only at
/// its reversals, whatever its period and sharpness, and the samples near a reversal are at
/// rest) and are drawn as point-to-point records (5.48, 21.5, 6.71 N rms in motion). A clipping
/// level that no family shows, even lowered to a tenth of the drive's peak force (seed
/// 100038, 0.63 N rms against 1.95 N noise), stays flagged in its own family. Records
/// observable on their first motion keep it (draw 0: the same record as without the rule).
/// Without the motion redraw the first assert fails (400047 not observable); without the
/// family's change the second (400002 flagged on its triangle).
#[test]
fn unobservable_effects_redraw_the_motion() {
    let s = RigSpec::random(400_047, "stribeck", Trajectory::RoundedTriangle, 12_000);
    println!(
        "seed 400047: draw {}, {:?}, rms {:.2} N, noise {:.2} N",
        s.motion_draw, s.hidden, s.effect_rms_n, s.noise_n
    );
    assert!(
        s.observable && s.motion_draw > 0 && s.trajectory == Trajectory::RoundedTriangle,
        "seed 400047"
    );
    // no rounded triangle shows these: the record is drawn in the next family
    for seed in [400_002, 400_017, 400_022] {
        let s = RigSpec::random(seed, "stribeck", Trajectory::RoundedTriangle, 12_000);
        println!(
            "seed {seed}: {} (asked for {}), draw {}, rms {:.2} N, noise {:.2} N",
            s.trajectory.name(),
            s.requested,
            s.motion_draw,
            s.effect_rms_n,
            s.noise_n
        );
        assert!(
            s.observable
                && s.trajectory == Trajectory::PointToPoint
                && s.requested == "rounded_triangle",
            "seed {seed}"
        );
    }
    // a clipping level no family shows (0.63 N rms against 1.95 N noise): flagged, in the
    // family it was asked for
    let s = RigSpec::random(
        100_038,
        "clipped_current_loop",
        Trajectory::PointToPoint,
        12_000,
    );
    assert!(
        !s.observable && s.trajectory == Trajectory::PointToPoint && s.motion_draw == 7,
        "seed 100038"
    );
    for (seed, traj) in [
        (400_001, Trajectory::Multisine),
        (400_003, Trajectory::PointToPoint),
        (400_004, Trajectory::Narrowband),
        (400_007, Trajectory::RoundedTriangle),
    ] {
        let spec = RigSpec::random(seed, "stribeck", traj, 12_000);
        assert!(spec.observable && spec.motion_draw == 0, "seed {seed}");
    }
}

/// The observability rule counts only the samples in motion (`bench_rig::rest_of`: within 20
/// samples of a true speed below one encoder quantum per 20 ms), where a fit may use the
/// force: the recorded (EMPS) Stribeck records 400015, 400030, 400035, whose effect lies on
/// the static friction held at the near-stops, are not observable on the recorded motion (a
/// recorded motion has nothing to redraw) and are drawn as multisines. The rig's rest set and
/// the diagnosis's (`effects::at_rest`, from the quantised record) agree on the recorded
/// motion of these devices: see `REST_AGREEMENT`. Break: the rest samples counted again
/// (`rest_of` all false) keeps the three on the recorded motion and the first assert fails.
#[test]
fn effect_at_rest_is_no_evidence() {
    let x = emps_x();
    for seed in [400_015, 400_030, 400_035] {
        let rec_traj = Trajectory::Recorded(x[..12_000].to_vec());
        let s = RigSpec::random(seed, "stribeck", rec_traj.clone(), 12_000);
        println!(
            "seed {seed}: {} (asked for {}), {:?}, rms {:.2} N in motion, noise {:.2} N",
            s.trajectory.name(),
            s.requested,
            s.hidden,
            s.effect_rms_n,
            s.noise_n
        );
        assert!(
            s.observable && s.trajectory == Trajectory::Multisine && s.requested == "recorded",
            "seed {seed}"
        );
        // the two rest sets on the recorded motion of this device
        let mut r = s.clone();
        r.trajectory = rec_traj;
        r.motion_draw = 0;
        let rig = r.rest();
        let rec = parse_csv(&r.csv(), None).expect("rig record parses");
        let diag = hal_sim::diagnose::effects::at_rest(&rec.x, &rec.v, rec.dt());
        // the record's first and last 20 samples are at rest to the diagnosis for its
        // filter's edges, not for the motion: left out of the comparison
        let w = 20;
        let (mut both, mut only_rig, mut only_diag) = (0usize, 0usize, 0usize);
        for (a, b) in rig.iter().zip(&diag).take(12_000 - w).skip(w) {
            both += (*a && *b) as usize;
            only_rig += (*a && !*b) as usize;
            only_diag += (!*a && *b) as usize;
        }
        let union = both + only_rig + only_diag;
        let agree = both as f64 / union.max(1) as f64;
        println!(
            "  rest: rig {} samples, diagnosis {}, both {both}, rig only {only_rig}, diagnosis only {only_diag}: overlap {:.1} % of the union (quantum {:.1e} m)",
            both + only_rig,
            both + only_diag,
            100.0 * agree,
            r.quantum_m
        );
        assert!(agree >= REST_AGREEMENT, "seed {seed}: overlap {agree}");
        assert!(
            only_rig <= 3,
            "seed {seed}: {only_rig} samples at rest to the rig only"
        );
    }
}

/// Least overlap (of the union) of the rig's rest set and the diagnosis's asserted by
/// `effect_at_rest_is_no_evidence`. Measured 87.0, 87.7, 89.9 % (6.4 µm encoders): the rig's
/// set lies inside the diagnosis's but for 1 sample of 650–670 (asserted ≤ 3), the
/// diagnosis leaving out 72–99 samples more (its threshold adds 3σ of the position noise it
/// estimates to the quantum); bound 3× the largest shortfall, 13 %: 61 %.
const REST_AGREEMENT: f64 = 0.61;

/// Effects sized to the rule (`bench_rig`, `size_to_rule`): a record no family shows at its
/// drawn size keeps its motion and draw, and its size is raised to the least the rule
/// accepts. Drift 800012 (rounded triangle, eighth motion) and hum 700013 (point-to-point)
/// are observable with an rms in motion of 5× the force noise (the binding clause; within
/// 10⁻⁵); drift 800028, whose rule needs more than `SIZE_MAX_SCALE` times its draw, stays
/// flagged. Break: the sizing removed, 800012 is flagged and the first assert fails.
#[test]
fn effects_are_sized_to_the_rule() {
    for (seed, kind, traj) in [
        (800_012, "drift", Trajectory::RoundedTriangle),
        (700_013, "hum", Trajectory::PointToPoint),
    ] {
        let s = RigSpec::random(seed, kind, traj, 12_000);
        let k = s.effect_rms_n / (5.0 * s.noise_n);
        println!(
            "seed {seed}: {:?}, draw {}, rms {:.3} N in motion = {k:.6} × 5·noise",
            s.hidden, s.motion_draw, s.effect_rms_n
        );
        assert!(s.observable && s.motion_draw == 7, "seed {seed}");
        assert!((1.0..1.00001).contains(&k), "seed {seed}: {k}");
    }
    let s = RigSpec::random(800_028, "drift", Trajectory::PointToPoint, 12_000);
    assert!(!s.observable, "seed 800028");
}

/// A load-path mode 2 % below the motion's band edge (rig seed 300006, multisine, 2.643 Hz,
/// the last Welch bin holding the motion at 2.686 Hz) is inside the compliance scan, which
/// reaches one bin width beyond the edge (`effects::motion_bandwidth`), and is named alone.
/// Measured: 2.707 Hz (+2.4 %); bound 7.5 % (3×). Without the bin beyond the edge the fit's
/// optimum (2.718 Hz) is not bracketed and nothing is named.
#[test]
fn mode_at_the_motion_band_edge_is_named() {
    let spec = RigSpec::random(300_006, "resonance", Trajectory::Multisine, 12_000);
    let Hidden::Resonance { freq_hz, .. } = spec.hidden else {
        panic!("not a resonance");
    };
    let rec = parse_csv(&spec.csv(), None).expect("rig record parses");
    let d = diagnose(&rec, &Options::default());
    let names = d.catalogue_names();
    let f = d.findings.iter().find(|f| f.effect == "compliance");
    println!(
        "rig {freq_hz:.4} Hz -> {names:?} {:?}",
        f.map(|f| &f.parameters)
    );
    assert_eq!(names, ["compliance"]);
    let fr = f.unwrap().parameters[0].1;
    assert!(
        (fr / freq_hz - 1.0).abs() < 0.075,
        "{fr} Hz against {freq_hz}"
    );
}

/// The play's width as its impacts show it (`effects::impact_travel`: the travel from each
/// reversal to the first impact in the new direction of motion, median) on rig records of the
/// long run whose coarse width grid missed the play (point-to-point 600003, 600008; recorded
/// EMPS motion 600005): within 3× the measured deviation of the rig's width (measured +0.71 %,
/// +0.60 %, +0.27 %; the travel is read at whole samples and position quanta).
#[test]
fn impact_travel_is_the_play_width() {
    let emps = emps_x();
    for (seed, traj) in [
        (600_003, Trajectory::PointToPoint),
        (600_008, Trajectory::PointToPoint),
        (
            600_005,
            Trajectory::Recorded(emps[..12_000.min(emps.len())].to_vec()),
        ),
    ] {
        let spec = RigSpec::random(seed, "backlash", traj, 12_000);
        let Hidden::Backlash { width_m } = spec.hidden else {
            panic!("seed {seed}: not a play record");
        };
        let rec = parse_csv(&spec.csv(), None).expect("rig record parses");
        let ctx = hal_sim::diagnose::effects::Context::new(&rec);
        let t = hal_sim::diagnose::effects::impact_travel(&ctx);
        println!("seed {seed}: impact travel {t:?} m, rig width {width_m:.4e} m");
        let t = t.unwrap_or_else(|| panic!("seed {seed}: no impact travel"));
        assert!(
            (t / width_m - 1.0).abs() < TRAVEL_BOUND,
            "seed {seed}: {t} against {width_m}"
        );
    }
}

/// Bound of `impact_travel_is_the_play_width`: 3× the largest measured deviation.
const TRAVEL_BOUND: f64 = 0.021;

/// Records of the long run (`long_run_spec`, any family) diagnosed with the rig's true velocity
/// and acceleration given as `v_m_s`, `a_m_s2` beside the derived ones (`RIG_SEEDS=500002,…
/// cargo test -p regen-tests --test diagnose_rig rig_true_acceleration -- --ignored
/// --nocapture`; `RIG_TRUE=v` or `RIG_TRUE=a` gives only that one the rig's, the other derived):
/// the inertial error M·(a − a_derived) at the reversals and what the diagnosis names without
/// the derived signals' errors.
#[test]
#[ignore]
fn rig_true_acceleration() {
    let emps = emps_x();
    for seed in env_seeds() {
        let kind = Hidden::KINDS[((seed - 1) / 100_000) as usize];
        let spec = long_run_spec(seed, &emps);
        let (v_true, a_true) = spec.true_motion();
        let text = spec.csv();
        let rec = parse_csv(&text, None).expect("rig record parses");
        let err: Vec<f64> = rec
            .a
            .iter()
            .zip(&a_true)
            .map(|(ad, at)| spec.mass_kg * (at - ad))
            .collect();
        let amax = a_true.iter().fold(0.0f64, |m, a| m.max(a.abs()));
        // reversals: where |a| exceeds a fifth of its peak
        let (mut e_rev, mut n_rev, mut e_all) = (0.0, 0usize, 0.0);
        for (e, a) in err.iter().zip(&a_true).skip(100).take(err.len() - 200) {
            e_all += e * e;
            if a.abs() > 0.2 * amax {
                e_rev += e * e;
                n_rev += 1;
            }
        }
        let m = (err.len() - 200) as f64;
        println!(
            "{kind} seed {seed}: quantum {:.1e} m, mass {:.1} kg, peak a {amax:.2} m/s², M·(a − a_derived) rms {:.3} N overall, {:.3} N on the {n_rev} reversal samples; noise {:.2} N, effect {:.2} N rms",
            spec.quantum_m,
            spec.mass_kg,
            (e_all / m).sqrt(),
            (e_rev / n_rev.max(1) as f64).sqrt(),
            spec.noise_n,
            spec.effect_rms_n
        );
        let mut lines = text.lines();
        let mut with_a = String::new();
        for l in lines.by_ref() {
            if l.starts_with('#') {
                with_a.push_str(l);
                with_a.push('\n');
            } else {
                with_a.push_str(l);
                with_a.push_str(",v_m_s,a_m_s2\n");
                break;
            }
        }
        // RIG_TRUE=v (or a): only that signal the rig's, the other the record's derived one
        let only = std::env::var("RIG_TRUE").unwrap_or_default();
        let v_in = if only == "a" { &rec.v } else { &v_true };
        let a_in = if only == "v" { &rec.a } else { &a_true };
        for ((l, v), a) in lines.zip(v_in).zip(a_in) {
            with_a.push_str(&format!("{l},{v:.9e},{a:.9e}\n"));
        }
        let rec2 = parse_csv(&with_a, None).expect("record with a parses");
        for (label, r) in [("derived a", &rec), ("true a", &rec2)] {
            let d = diagnose(r, &Options::default());
            println!(
                "    {label}: {:?} held-out {:.2} % -> {:.2} %",
                d.catalogue_names(),
                100.0 * d.baseline_holdout_rel_error,
                100.0 * d.final_holdout_rel_error
            );
            if std::env::var("RIG_EVIDENCE").is_ok() {
                for f in &d.findings {
                    println!(
                        "      {} {:?}: held-out rss -{:.2} %, held on {:.0} %",
                        f.effect,
                        f.parameters,
                        100.0 * f.holdout_rss_drop,
                        100.0 * f.consistency
                    );
                }
            }
        }
    }
}

/// A recorded (EMPS position) record whose near-stops drew a false
/// `velocity_strengthening_friction`: backlash 600050 (encoder 1.6 µm), exactly right by the
/// build-up's band rule (`effects::buildup_in_band`: the rise where the derived signals follow
/// the build-up, 12.4 N, differs from the one at the motion's fast near-stops, 6.3 N, by 49 %
/// at Wald 12.4). Break: the rule removed names the friction beside `backlash`.
#[test]
fn recorded_near_stops_name_no_speed_friction() {
    let x = emps_x();
    let spec = RigSpec::random(
        600050,
        "backlash",
        Trajectory::Recorded(x[..12_000].to_vec()),
        12_000,
    );
    let rec = parse_csv(&spec.csv(), None).expect("rig record parses");
    let d = diagnose(&rec, &Options::default());
    println!("seed 600050: {:?}", d.catalogue_names());
    for v in &d.verdicts {
        println!("  verdict: {v}");
    }
    assert_eq!(d.catalogue_names(), vec!["backlash"]);
}

/// The device behind the play fitted on its contact samples (`effects::play_device_fit`, the
/// device walked at the rig's width with the baseline's coefficients and the velocity through
/// the acceleration's band, `Context::v_with_a`, as `play_columns` starts it) is the rig's device: inertia, viscous (the drive's damping and the viscous friction)
/// and Coulomb friction on rounded triangles, where an impact strikes the device from near
/// rest at the cruise speed. The contact (60 Hz, ζ 0.5, it can only push) releases the device
/// after its pulse and catches it again, so the samples within `CONTACT_SETTLE` of each
/// contact are left out. Measured: see `PLAY_DEVICE_BOUND`. With only the pulse's
/// `IMPACT_TAPS` left out, 600002's viscous is +12 % and 600032's −10 % and the test fails.
#[test]
fn play_device_is_fitted_off_the_contact_transient() {
    for seed in [600_002, 600_007, 600_032] {
        let spec = RigSpec::random(seed, "backlash", Trajectory::RoundedTriangle, 12_000);
        let Hidden::Backlash { width_m } = spec.hidden else {
            panic!("seed {seed}: not a play record");
        };
        let rec = parse_csv(&spec.csv(), None).expect("rig record parses");
        let ctx = hal_sim::diagnose::effects::Context::new(&rec);
        let dev = hal_sim::diagnose::effects::play_device(
            &rec.x,
            ctx.v_with_a(),
            &rec.a,
            &ctx.sgn,
            ctx.dt,
            width_m,
            ctx.base_th[0],
            ctx.base_th[1],
            ctx.base_th[2],
            0.0,
        );
        let (m, fv, fc) = hal_sim::diagnose::effects::play_device_fit(&ctx, &dev)
            .unwrap_or_else(|| panic!("seed {seed}: no device fit"));
        assert_device_is_the_rigs(&spec, (m, fv, fc), PLAY_DEVICE_BOUND);
    }
}

/// Bounds of `play_device_is_fitted_off_the_contact_transient` (inertia, viscous, Coulomb):
/// 3× the largest measured deviation for inertia and viscous (−3.37 %, +0.94 % measured);
/// Coulomb 4 % against 600032's −3.51 % (its device walked from the baseline fitted with the
/// velocity through its own band, "Input" in docs/diagnose.md; 600002 and 600007 −0.45 %,
/// +0.28 %): 1.1× the worst, the one record that sets it.
const PLAY_DEVICE_BOUND: [f64; 3] = [0.105, 0.015, 0.04];

/// The play's joint fit profiled over its width on records of the long run's backlash kind
/// (`RIG_SEEDS=600007,600011 cargo test -p regen-tests --test diagnose_rig
/// rig_play_width_profile -- --ignored --nocapture`): the play's columns
/// (`effects::play_columns_with`) at the rig's width × (1 + 0.02k), k = −10 … 10, fitted with
/// the baseline's columns on the training part; per width the held-out rss against the
/// baseline's, the free force's gain and the impact's sum (kg), with the device the diagnosis
/// fits (`play_device_coefficients`) and with the rig's own (inertia, drive damping plus
/// viscous friction, Coulomb). It separates what the device's fit costs from what the walk
/// lacks. The trajectory of a seed is the long run's (`run`: seed 600001 + j, family j mod 5).
#[test]
#[ignore]
fn rig_play_width_profile() {
    use hal_sim::diagnose::effects::{
        impact_travel, play_columns_with, play_device_coefficients, Context,
    };
    use hal_sim::diagnose::{holdout_mask, normals, AT_REST};
    let emps = emps_x();
    for seed in env_seeds()
        .into_iter()
        .filter(|s| (600_001..700_000).contains(s))
    {
        let spec = long_run_spec(seed, &emps);
        let Hidden::Backlash { width_m } = spec.hidden else {
            println!("seed {seed}: not a play record");
            continue;
        };
        let rec = parse_csv(&spec.csv(), None).expect("rig record parses");
        let ctx = Context::new(&rec);
        let n = rec.len();
        let mut part = holdout_mask(n);
        for (p, &r) in part.iter_mut().zip(&ctx.rest) {
            if r {
                *p = AT_REST;
            }
        }
        let ones = vec![1.0; n];
        let fit = |extra: &[(String, Vec<f64>)]| -> (f64, Vec<f64>) {
            let mut cols: Vec<&[f64]> = vec![&rec.a, &rec.v, &ctx.sgn, &ones];
            cols.extend(extra.iter().map(|c| c.1.as_slice()));
            let (tr, ho) = normals(&cols, &rec.f, &part, 1);
            let th = tr.solve();
            (ho.rss(&th), th)
        };
        let (rss0, th0) = fit(&[]);
        let rig = (
            spec.mass_kg,
            spec.drive_damping + spec.viscous,
            spec.coulomb,
        );
        // the contact's restitution walked (`RIG_E`, default 0: the plastic contact)
        let e: f64 = std::env::var("RIG_E")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(0.0);
        let fitted = play_device_coefficients(&ctx, n, width_m, e);
        // the device walked once more, from the one fitted (None: that fit fails)
        let refit = hal_sim::diagnose::effects::play_device_fit(
            &ctx,
            &hal_sim::diagnose::effects::play_device(
                &rec.x, &rec.v, &rec.a, &ctx.sgn, ctx.dt, width_m, fitted.0, fitted.1, fitted.2, e,
            ),
        );
        println!(
            "seed {seed} ({}): width {:.4e} m, impacts' width {:?}; baseline M {:.1} Fv {:.1} Fc {:.1}; device fitted {:.1} {:.1} {:.2}, rig's {:.1} {:.1} {:.2} (Fv/M {:.1} s⁻¹)",
            spec.trajectory.name(),
            width_m,
            impact_travel(&ctx).map(|t| t / width_m),
            th0[0],
            th0[1],
            th0[2],
            fitted.0,
            fitted.1,
            fitted.2,
            rig.0,
            rig.1,
            rig.2,
            rig.1 / rig.0
        );
        for k in -10..=10 {
            let b = width_m * (1.0 + 0.02 * k as f64);
            let mut line = format!("  {:+3} %:", 2 * k);
            for dev in [None, Some(rig)].into_iter().chain(refit.map(Some)) {
                let cols = play_columns_with(&ctx, None, b, e, dev);
                let (rss, th) = fit(&cols);
                line.push_str(&format!(
                    "  held-out rss {:6.2} %, gain {:+.2}, impact {:6.1} kg;",
                    100.0 * rss / rss0,
                    th[4],
                    th[5..].iter().sum::<f64>()
                ));
            }
            println!("{line}");
        }
    }
}

/// The recorded motion's play is named where the record's contacts lie in one of the five
/// stability segments (`diagnose::agreement_of_held`): on 600010 and 600015 the fit without
/// the first segment leaves the impact taps in their null space (±200 … ±3,000 kg,
/// alternating), the play does not hold there, and the other four agree (gain 1.00 within
/// 0.5 %). With the agreement asked of all five segments (t = 0.25 on both) the play is not
/// kept and the test fails.
#[test]
fn recorded_play_agrees_on_the_segments_that_hold() {
    let x = emps_x();
    for seed in [600_010, 600_015] {
        let spec = RigSpec::random(
            seed,
            "backlash",
            Trajectory::Recorded(x[..12_000].to_vec()),
            12_000,
        );
        let rec = parse_csv(&spec.csv(), None).expect("rig record parses");
        let d = diagnose(&rec, &Options::default());
        println!("seed {seed}: {:?}", d.catalogue_names());
        assert!(
            d.catalogue_names().contains(&"backlash"),
            "seed {seed}: play not named"
        );
    }
}

/// A drive's clip that a second effect's fit would leave non-physical (`diagnose::set_physical`:
/// a candidate is refused when, beside it, an effect already in the set leaves its physical
/// range). On the rig's clipped multisine 100051 (level 30.1 N) a `screw_efficiency` beside
/// the clip took part of the viscous force, leaving the clip's damping above the viscous
/// coefficient (353 against 297 N·s/m on every stability segment): the clip held on 0/5
/// segments and nothing was named. With the rule it is named alone with the rig's level.
/// Break: the rule removed from the scan, nothing is named and the test fails.
#[test]
fn clip_is_not_left_non_physical_by_a_second_effect() {
    let spec = RigSpec::random(
        100_051,
        "clipped_current_loop",
        Trajectory::Multisine,
        12_000,
    );
    let Hidden::ClippedCurrentLoop { limit_n } = spec.hidden else {
        unreachable!()
    };
    let rec = parse_csv(&spec.csv(), None).expect("rig record parses");
    let d = diagnose(&rec, &Options::default());
    assert_eq!(d.catalogue_names(), vec!["current_limit"]);
    let f = &d.findings[0];
    let p = |k: &str| f.parameters.iter().find(|(n, _)| n == k).map(|p| p.1);
    let (l, cd) = (p("limit_N").unwrap(), p("drive_damping_Ns_per_m").unwrap());
    let (el, ec) = (l / limit_n - 1.0, cd / spec.drive_damping - 1.0);
    println!(
        "limit {l:.2} N (rig {limit_n:.2}, {:+.2} %), drive damping {cd:.1} N·s/m (rig {:.1}, {:+.2} %)",
        100.0 * el,
        spec.drive_damping,
        100.0 * ec
    );
    // the bound of `clipped_drive_is_named_with_its_level` (3× its worst measured deviation)
    assert!(el.abs() < 0.015 && ec.abs() < 0.015, "{el} {ec}");
}

/// Where a record's hidden effect acts (`RIG_SEEDS=400015,… cargo test -p regen-tests --test
/// diagnose_rig rig_effect_at_rest -- --ignored --nocapture`; trajectories as in the long
/// run): the force the effect changes (the record with and without it: the same motion and
/// noise) split into the samples the diagnosis leaves out as at rest (`effects::at_rest`) and
/// those in motion, which are all a column can fit.
#[test]
#[ignore]
fn rig_effect_at_rest() {
    let emps = emps_x();
    for seed in env_seeds() {
        let kind = Hidden::KINDS[((seed - 1) / 100_000) as usize];
        let spec = long_run_spec(seed, &emps);
        let mut free = spec.clone();
        free.hidden = Hidden::None;
        let rec = parse_csv(&spec.csv(), None).expect("rig record parses");
        let rec0 = parse_csv(&free.csv(), None).expect("rig record parses");
        let ctx = hal_sim::diagnose::effects::Context::new(&rec);
        let (mut e_rest, mut n_rest, mut e_move, mut n_move) = (0.0, 0usize, 0.0, 0usize);
        for ((a, b), &r) in rec.f.iter().zip(&rec0.f).zip(&ctx.rest) {
            let d = (a - b) * (a - b);
            if r {
                e_rest += d;
                n_rest += 1;
            } else {
                e_move += d;
                n_move += 1;
            }
        }
        println!(
            "{kind} {} seed {seed}: effect {:.2} N rms; at rest ({n_rest} samples) {:.2} N rms, {:.0} % of its energy; in motion ({n_move}) {:.2} N rms; noise {:.2} N",
            spec.trajectory.name(),
            spec.effect_rms_n,
            (e_rest / n_rest.max(1) as f64).sqrt(),
            100.0 * e_rest / (e_rest + e_move).max(1e-300),
            (e_move / n_move.max(1) as f64).sqrt(),
            spec.noise_n
        );
    }
}

/// A presliding transition beside a lag must carry the margin on top of the lag's parts given
/// amplitudes of their own (the scan's `carries_beyond_switch`, `effects::delayed_switch`):
/// delay 200021 (multisine, 19.7 ms, 6.4 µm encoder), whose lag's least-squares gain is 0.80,
/// is named `lag` alone. Break: the rule removed names a `presliding_hysteresis` of
/// x_c 0.18 mm and 4.7 N beside the lag.
#[test]
fn delayed_switch_is_not_presliding() {
    // measured +1.7 % (20.08 ms for 19.74); 5 % is the bound of the other lag tests
    named_alone(200_021, 0.05);
}

/// A position ripple whose time frequency on the motion lies in the band of a mode kept is
/// the mode's (`effects::ripple_at_mode`, among the verdicts): resonance 300017 (rounded
/// triangle cruising at 72.4 mm/s on 89 % of its samples, a 2.686 Hz mode, ζ 0.107, 38.6 kg),
/// where a `cogging` of 26.92 mm (72.4 mm/s / 26.92 mm = 2.689 Hz) took 13.8 % of the
/// held-out rss beside the `compliance`, is named `compliance` alone. Break: the rule's
/// condition flipped (a ripple dropped when most of the motion lies outside the mode's band)
/// names the `cogging` beside it.
#[test]
fn ripple_at_the_mode_frequency_is_the_mode() {
    let (spec, d) = diagnosed_long_run_record(300_017);
    let Hidden::Resonance { freq_hz, .. } = spec.hidden else {
        panic!("300017 is a resonance record");
    };
    let names = d.catalogue_names();
    let f = first_parameter(&d, "compliance");
    println!("300017: {names:?}: compliance {f} Hz for {freq_hz}");
    assert_eq!(names, ["compliance"], "{:?}", d.verdicts);
    // measured +0.06 % (2.6875 Hz for 2.6858): 0.2 % is 3× that
    assert!((f / freq_hz - 1.0).abs() < 0.002, "{f} Hz for {freq_hz}");
}

/// A resonance beside a lag must carry the margin on top of the lag's three parts (delayed
/// inertial, viscous and Coulomb) given amplitudes of their own (the scan's
/// `carries_beyond_switch`): delay 200035 (recorded EMPS motion, 37.8 ms, 1.01 N noise),
/// whose lag's one gain leaves part of its delayed inertial and viscous force, is named `lag`
/// alone. Break: the rule removed names a 7.25 Hz `compliance` (8.2 kg, ζ 0.32, 5.0 % of the
/// held-out rss) beside the lag.
#[test]
fn delay_remainder_is_not_a_resonance() {
    // measured −0.66 % (37.57 ms for 37.82): 2 % is 3× that
    named_alone(200_035, 0.02);
}

/// The derived acceleration's quantisation noise is no mode (the scan's rule on `compliance`,
/// `Context::compliance_noise`): presliding 500002 and 500052 (rounded triangle, 6.4 µm
/// encoder, M·(a − a_derived) 1.1 and 0.96 N rms against 1.05 and 1.30 N of force noise) are
/// named `presliding_hysteresis` alone, its displacement within the bound below of the rig's.
/// Break: the rule removed (the long run's base) names a `compliance` (8.8 and 5.2 Hz, modal
/// mass 36 and 25 kg) beside it on both.
#[test]
fn derived_acceleration_noise_is_no_compliance() {
    // measured −26.6 % and −8.9 % (the Dahl column fitted through the derived signals;
    // with the `compliance` beside it 500002 gave −12.7 %); bound 40 % (1.5× the larger):
    // a displacement of the build-up's order, not its precision, is what the name asserts
    for seed in [500_002, 500_052] {
        named_alone(seed, 0.4);
    }
}

/// A mode must carry the margin on columns freed of the derived acceleration's noise (the
/// scan's errors-in-variables rule on `compliance`: the fits with and without the mode
/// corrected by `Context::compliance_noise`, the covariance of the inertia's, the viscous and
/// the mode's columns): on 6.4 µm records whose mode's column is well above its noise (so the
/// half-noise rule lets it through) least squares credits a modal mass with the quantisation
/// noise it cancels in the inertia's column, on the held-out rows as on the training rows.
/// Stribeck 400002 (point-to-point), presliding 500015 and backlash 600020 (recorded motion)
/// are named their own effect alone, its first parameter within the bound below of the
/// rig's. Break: the rule removed (the long run's base) names a `compliance` beside each
/// (2.39 Hz, 6.4 kg; 4.29 Hz, 4.0 kg; 7.66 Hz, 5.0 kg); S × 0.5, or S without the mode's
/// covariances with the inertia and viscous columns, names it beside `stribeck` on 400002.
#[test]
fn derived_acceleration_noise_carries_no_margin() {
    // measured −1.04 % (v_s), +1.33 % (x_c), −0.64 % (width); bound 4 %, 3× the largest
    for seed in [400_002, 500_015, 600_020] {
        named_alone(seed, 0.04);
    }
}

/// `lag`'s delays are ranked against each other on common rows (the scan leaves out, for every
/// τ, the samples the longest τ scanned leaves out): each τ's own fit leaves out the first τ of
/// each move (its delayed rest), where an undelayed baseline is furthest from the dwell's
/// force, so on its own rows a longer τ is compared with a baseline relieved of more of its
/// worst rows. Delay 200023 (point-to-point, 33.4 ms, 0.4 µm encoder: no derivation noise to
/// speak of) is named `lag` alone. Break: ranked on each τ's own rows, the scan takes 29.8 ms
/// (least-squares gain 1.24, at the top of its range), which holds on 1 of 5 segments, and
/// nothing is named.
#[test]
fn delay_is_ranked_on_common_rows() {
    // measured +11.4 % (37.26 ms for 33.43; the least-squares gain 0.82); bound 3× that
    named_alone(200_023, 0.34);
}

/// A play is tested on its contacts: a `lag` chosen beside it leaves out of its own test the
/// rows whose delayed motion is at rest or inside the Coulomb sign's band (right after each
/// reversal), which are where the play's contacts lie, so the stability segments test the play
/// and a lag beside it on every row in motion. Backlash 600012 (rounded triangle, 0.70 mm) is
/// named `backlash` alone, its width within the bound below of the rig's. Breaks: the play
/// tested on the lag's rows (the segment fits see no contact, the impact taps fit to zero
/// and fail the momentum rule on 5/5 segments) names nothing (and `lag` alone when the lag
/// too is tested on its own rows, as before the rule); the play on every row but the lag
/// beside it still on its own rows names `backlash` and `lag`.
#[test]
fn play_is_tested_on_its_contacts() {
    // measured +1.0 % (0.7095 mm for 0.7024); bound 3× that
    named_alone(600_012, 0.03);
}

/// A play whose flank is a spring: recorded-motion backlash 600040 (1.46 mm, the rig's 60 Hz
/// contact) is named `backlash` alone with a compliant flank (contact mode fs/8, kept by the
/// selection's margin over the rigid flank). With the rigid flank only
/// (`PLAY_CONTACT_FRACTIONS` empty) a `velocity_strengthening_friction` of 27 N over
/// 0.26 mm/s is named beside it and the test fails.
#[test]
fn play_with_a_compliant_flank_is_named_alone() {
    // measured +2.15 % (1.4932 mm for 1.4617); bound 3× that
    named_alone(600_040, 0.065);
}

/// A compliant flank the whole record does not bear out is not kept: rounded-triangle
/// backlash 600003 (1.02 mm) takes a 62.5 Hz flank on the screening window, but over the whole
/// record's held-out part the rigid flank fits better (3.44 % against 6.40 % with the spring),
/// so the rigid flank is kept. Measured 3.44 %; bound 4.5 %, between it and the compliant
/// flank's 6.40 % (the test fails when the whole-record check is left out).
#[test]
fn a_flank_spring_the_whole_record_refutes_is_dropped() {
    let (_, d) = diagnosed_long_run_record(600_003);
    assert_eq!(d.catalogue_names(), ["backlash"], "{:?}", d.verdicts);
    let f = d.findings.iter().find(|f| f.effect == "backlash").unwrap();
    assert!(
        !f.parameters.iter().any(|(k, _)| k == "contact_Hz"),
        "{:?}",
        f.parameters
    );
    assert!(
        d.final_holdout_rel_error < 0.045,
        "held-out {:.2} %",
        100.0 * d.final_holdout_rel_error
    );
}

/// The long run's records as the rig draws them, without the diagnosis (`RIG_N=56 cargo test
/// -p regen-tests --test diagnose_rig rig_specs -- --ignored --nocapture`; `RIG_KINDS` and
/// `RIG_SEEDS` as in the long run): family (and the one asked for), motion draw, hidden
/// effect, its rms over the samples in motion, the force noise, observable. Two rules'
/// outputs diffed list the records whose spec a change of the rule moved.
#[test]
#[ignore]
fn rig_specs() {
    let emps = emps_x();
    let n: u64 = std::env::var("RIG_N")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(56);
    let only = std::env::var("RIG_KINDS").ok();
    let seeds = env_seeds();
    for (ki, kind) in Hidden::KINDS.iter().enumerate() {
        if only
            .as_ref()
            .is_some_and(|o| !o.split(',').any(|k| k == *kind))
        {
            continue;
        }
        for j in 0..n {
            let seed = 1 + ki as u64 * 100_000 + j;
            if !seeds.is_empty() && !seeds.contains(&seed) {
                continue;
            }
            let s = long_run_spec(seed, &emps);
            println!(
                "{kind:>20} seed {seed}: {} (asked for {}, draw {}) {:?} rms {:.2} N, noise {:.2} N, observable {}",
                s.trajectory.name(),
                s.requested,
                s.motion_draw,
                s.hidden,
                s.effect_rms_n,
                s.noise_n,
                s.observable
            );
        }
    }
}

/// The device behind the play is fitted from a second walk (`effects::PLAY_DEVICE_WALKS`):
/// walked with the baseline's coefficients (on rounded triangles 600042 and 600037 a baseline
/// biased by the impacts, viscous −982 N·s/m on 600042) the device's contacts fall off the
/// rig's and the device fitted on them splits viscous and Coulomb friction wrongly (600042
/// viscous −30 %, 600037 −18 %); walked once more with that device its contacts are the
/// rig's and so is the device fitted on them: inertia, viscous (drive damping and viscous
/// friction) and Coulomb at the rig's width, on the two triangles and point-to-point 600038.
/// Bounds `PLAY_DEVICE_WALKED_BOUND`. With one walk (`PLAY_DEVICE_WALKS` = 1) 600042's
/// viscous is −30 % and the test fails.
#[test]
fn play_device_is_fitted_from_its_own_walk() {
    let emps = emps_x();
    for seed in [600_042, 600_037, 600_038] {
        let spec = long_run_spec(seed, &emps);
        let Hidden::Backlash { width_m } = spec.hidden else {
            panic!("seed {seed}: not a play record");
        };
        let rec = parse_csv(&spec.csv(), None).expect("rig record parses");
        let ctx = hal_sim::diagnose::effects::Context::new(&rec);
        let (m, fv, fc) =
            hal_sim::diagnose::effects::play_device_coefficients(&ctx, rec.len(), width_m, 0.0);
        assert_device_is_the_rigs(&spec, (m, fv, fc), PLAY_DEVICE_WALKED_BOUND);
    }
}

/// Bounds of `play_device_is_fitted_from_its_own_walk` (inertia, viscous, Coulomb): 3× the
/// largest measured deviation.
const PLAY_DEVICE_WALKED_BOUND: [f64; 3] = [0.115, 0.084, 0.105];

/// The play's device (inertia, viscous, Coulomb) against the rig's own (its mass, drive
/// damping plus viscous friction, Coulomb), each relative deviation within its bound.
fn assert_device_is_the_rigs(spec: &RigSpec, (m, fv, fc): (f64, f64, f64), bound: [f64; 3]) {
    let seed = spec.seed;
    let want = [
        spec.mass_kg,
        spec.drive_damping + spec.viscous,
        spec.coulomb,
    ];
    let dev = [m / want[0] - 1.0, fv / want[1] - 1.0, fc / want[2] - 1.0];
    println!(
        "seed {seed} ({}): M {m:.2} kg ({:+.2} %), Fv {fv:.1} N·s/m ({:+.2} %), Fc {fc:.2} N ({:+.2} %)",
        spec.trajectory.name(),
        100.0 * dev[0],
        100.0 * dev[1],
        100.0 * dev[2]
    );
    for (k, (d, b)) in dev.iter().zip(bound).enumerate() {
        assert!(
            d.abs() < b,
            "seed {seed}: coefficient {k} off by {:+.2} %",
            100.0 * d
        );
    }
}

/// An effect-free point-to-point record (none 33: one move of 1.42 mm/s peak among moves up to
/// 0.26 m/s, 279 of its samples in motion inside the Coulomb sign's linear band, ±0.52 mm/s)
/// is named nothing: the Coulomb force the band's linear column leaves out there (baseline
/// held-out error 5.01 %, 0.36 % with the exact sign) is not a Stribeck bump (the rule under
/// "Effect-free records named" in docs/diagnose.md). Break: without the rule it is named
/// `stribeck` (v_s 1.5 mm/s, 6.1 N, 94 % of the held-out rss).
#[test]
fn coulomb_band_is_not_stribeck() {
    let (_, d) = diagnosed_long_run_record(33);
    assert!(d.catalogue_names().is_empty(), "{:?}", d.catalogue_names());
}

/// An effect-free point-to-point record (none 38, 0.4 µm encoder, the velocity through its own
/// band at 250 Hz, 6,535 of its 12,000 samples at rest) is named nothing: a Dahl state of a
/// few µm has reached the direction of sliding within a few samples of each move's start, so
/// where the motion slides inside the Coulomb sign's linear band its column z − sgn v is the
/// force the band leaves out, sign v − v/v_eps; it must carry the margin against the baseline
/// with the exact sign, as a Stribeck bump must (docs/diagnose.md, "One cause, one name").
/// Break: without the rule for `presliding_hysteresis` it is named so (x_c 2.63 µm, 33.4 N,
/// 49.9 % of the held-out rss, held on 4/5 segments).
#[test]
fn coulomb_band_is_not_presliding() {
    let (_, d) = diagnosed_long_run_record(38);
    assert!(d.catalogue_names().is_empty(), "{:?}", d.catalogue_names());
}
