//! The diagnosis judged on records of the independent bench rig (`hal_sim::bench_rig`: effects
//! as physics, several trajectory families, random noise and sensor resolution), on seeds it
//! was never tuned on.
//!
//! **Seed ranges.** Every rig seed lies in one of two disjoint ranges: `TUNING` (the records
//! the diagnosis may be developed against: the classic long run's and every tool's below) and
//! `HELD_OUT` (the records it is judged on). Every target is asserted on the held-out range
//! only; the tuning range's figure is printed beside it and the difference (tuning − held-out)
//! is the overfit. Two rigs: the classic one (`RigSpec::random`: 1 kHz, 12 s, the nine
//! classic kinds; the generator the diagnosis was tuned on) and the widened one
//! (`RigSpec::widened`: 500 Hz … 10 kHz, 6–20 s, wider noise, encoders and devices, a chirp
//! family, and the kinds the classic rig lacks: a load path measured behind its compliance,
//! play without impact, a spring, a spring beside presliding, a drag growing with the square
//! of the speed). Per record: exactly right (the catalogue names are the hidden effect's, or
//! none; `unexplained` for an effect outside the catalogue), detected, false names.

use hal_sim::bench_rig::{Hidden, RigSpec, Trajectory};
use hal_sim::diagnose::{diagnose, parse_csv, Diagnosis, Options};
use std::collections::BTreeMap;

mod rig_seeds;
use rig_seeds::*;

/// Which generator draws a record.
#[derive(Clone, Copy, PartialEq, Debug)]
enum Rig {
    Classic,
    Widened,
}

impl Rig {
    fn name(self) -> &'static str {
        match self {
            Rig::Classic => "classic",
            Rig::Widened => "widened",
        }
    }
    fn kinds(self) -> &'static [&'static str] {
        match self {
            Rig::Classic => &Hidden::KINDS,
            Rig::Widened => &Hidden::WIDE_KINDS,
        }
    }
    /// Seed of record `j` of kind number `k` in the tuning or the held-out range.
    fn seed(self, held_out: bool, k: usize, j: usize) -> u64 {
        let (base, stride) = match (self, held_out) {
            (Rig::Classic, false) => (CLASSIC_TUNING_BASE, TUNING_STRIDE),
            (Rig::Widened, false) => (WIDE_TUNING_BASE, TUNING_STRIDE),
            (Rig::Classic, true) => (CLASSIC_HELD_OUT_BASE, 1_000_000),
            (Rig::Widened, true) => (WIDE_HELD_OUT_BASE, 1_000_000),
        };
        assert!(
            j < stride as usize,
            "record {j} beyond the kind's {stride} seeds"
        );
        let s = base + stride * k as u64 + j as u64;
        let range = if held_out { &HELD_OUT } else { &TUNING };
        assert!(range.contains(&s), "seed {s} outside its range {range:?}");
        s
    }
    /// The record of `seed` (kind `kind`, record number `j` of its kind).
    fn spec(self, seed: u64, kind: &str, j: usize, emps: &[f64]) -> RigSpec {
        match self {
            Rig::Classic => RigSpec::random(seed, kind, trajectory(j, emps, 12_000), 12_000),
            Rig::Widened => RigSpec::widened(seed, kind, Some((emps, 1000.0))),
        }
    }
}

/// The two ranges are disjoint and every seed the evaluation draws lies in its own: the largest
/// tuning seed a run can draw is below the held-out range's start.
#[test]
fn seed_ranges_are_disjoint() {
    for rig in [Rig::Classic, Rig::Widened] {
        let k = rig.kinds().len() - 1;
        for held_out in [false, true] {
            let (lo, hi) = (
                rig.seed(held_out, 0, 0),
                rig.seed(held_out, k, TUNING_STRIDE as usize - 1),
            );
            let range = if held_out { &HELD_OUT } else { &TUNING };
            assert!(
                range.contains(&lo) && range.contains(&hi),
                "{rig:?} {held_out}"
            );
        }
    }
}

#[derive(Default, Clone)]
struct Tally {
    records: usize,
    exact: usize,
    detected: usize,
    false_name: usize,
    /// records whose hidden effect the rig's observability rule holds for, and of them exact
    observable: usize,
    observable_exact: usize,
}

impl Tally {
    fn add(&mut self, o: &Tally) {
        self.records += o.records;
        self.exact += o.exact;
        self.detected += o.detected;
        self.false_name += o.false_name;
        self.observable += o.observable;
        self.observable_exact += o.observable_exact;
    }
}

/// How one record came out: its tally (one record) and the line it prints.
struct Outcome {
    kind: &'static str,
    tally: Tally,
    text: String,
}

/// Whether a diagnosis is exactly right for a hidden effect: (exact, detected, false names).
/// In the catalogue: every expected name given (detected) and no other catalogue name; outside
/// it: `unexplained` reported and no catalogue name; no effect: no catalogue name. A finding
/// reported as confounded with another effect (`Finding::confounded_with`) names neither: it
/// does not detect the hidden effect, and on a record whose hidden effect has no catalogue name
/// (none, or outside the catalogue) it counts as a false name; a record with one is never
/// exact.
fn judge(hidden: &Hidden, d: &Diagnosis) -> (bool, bool, bool) {
    let names = d.catalogue_names();
    let confounded = d.findings.iter().any(|f| f.confounded_with.is_some());
    let unexpl = d.findings.iter().any(|f| f.effect == "unexplained");
    let want = hidden.expected_names();
    let (detected, false_names) = if hidden.out_of_catalogue() {
        (unexpl, !names.is_empty() || confounded)
    } else if want.is_empty() {
        (true, !names.is_empty() || confounded)
    } else {
        (
            want.iter().all(|w| names.contains(w)),
            names.iter().any(|n| !want.contains(n)),
        )
    };
    (
        detected && !false_names && !confounded,
        detected,
        false_names,
    )
}

/// Diagnose the record of `seed` and say how it came out.
fn outcome(rig: Rig, kind: &'static str, j: usize, seed: u64, emps: &[f64]) -> Outcome {
    use std::fmt::Write;
    let spec = rig.spec(seed, kind, j, emps);
    let csv = spec.csv();
    // `RIG_DUMP=DIR` writes the record as DIR/rec_SEED.csv (the CSV the diagnosis reads, the
    // rig's device and hidden effect in its header), to open with `regen diagnose` or another
    // tool
    if let Ok(dir) = std::env::var("RIG_DUMP") {
        let path = std::path::Path::new(&dir).join(format!("rec_{seed}.csv"));
        if let Err(e) = std::fs::write(&path, &csv) {
            eprintln!("RIG_DUMP: cannot write {}: {e}", path.display());
        }
    }
    let rec = parse_csv(&csv, None).expect("rig record parses");
    let d = diagnose(&rec, &Options::default());
    let (exact, detected, false_names) = judge(&spec.hidden, &d);
    let unexpl = d.findings.iter().any(|f| f.effect == "unexplained");
    let mut text = format!(
        "{kind:>20} {:>16} seed {seed} ({} Hz, {} samples, quantum {:.1e} m): hidden {:?} (rms {:.2} N, {}, noise {:.2} N, observable {}{}) -> {:?}{} held-out {:.2} % -> {:.2} %{}\n",
        spec.trajectory.name(),
        spec.fs,
        spec.samples,
        spec.quantum_m,
        spec.hidden,
        spec.effect_rms_n,
        // the classic rig's observability has no refit clause: nothing to print
        if spec.refit_rule {
            format!("unexplained by a refit {:.2} N", spec.effect_unexplained_n)
        } else {
            "no refit clause".to_string()
        },
        spec.noise_n,
        spec.observable,
        if spec.requested != spec.trajectory.name() {
            format!("; asked for {}", spec.requested)
        } else {
            String::new()
        },
        d.catalogue_names(),
        d.findings
            .iter()
            .filter_map(|f| f.confounded_with.as_ref().map(|o| format!(" + confounded {} / {o}", f.effect)))
            .collect::<String>()
            + if unexpl { " + unexplained" } else { "" },
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
        tally: Tally {
            records: 1,
            exact: exact as usize,
            detected: detected as usize,
            false_name: false_names as usize,
            observable: spec.observable as usize,
            observable_exact: (spec.observable && exact) as usize,
        },
        text,
    }
}

/// Run `per_kind` records of every kind of `rig` in the tuning or the held-out range (records
/// `j0 .. j0 + per_kind` of each kind); returns the tallies per kind. `RIG_KINDS=none,delay`
/// narrows the kinds. The records are diagnosed in parallel (each alone: the diagnosis is a
/// pure function of its record) and printed in the order of their seeds when `RIG_VERBOSE` is
/// set, or when not exact.
fn run(
    rig: Rig,
    held_out: bool,
    per_kind: usize,
    j0: usize,
    emps: &[f64],
) -> BTreeMap<&'static str, Tally> {
    use rayon::prelude::*;
    let only = env_kinds();
    let verbose = std::env::var("RIG_VERBOSE").is_ok();
    let mut jobs = Vec::new();
    for (k, kind) in rig.kinds().iter().enumerate() {
        if only.as_ref().is_some_and(|o| !o.iter().any(|x| x == kind)) {
            continue;
        }
        for j in j0..j0 + per_kind {
            jobs.push((*kind, j, rig.seed(held_out, k, j)));
        }
    }
    let outcomes: Vec<Outcome> = jobs
        .par_iter()
        .map(|&(kind, j, seed)| {
            let o = outcome(rig, kind, j, seed, emps);
            if std::env::var("RIG_STREAM").is_ok() {
                // each record as it completes (a long run's partial figures)
                eprintln!(
                    "RECORD {} {} {kind} exact {} detected {} false {} j {j}",
                    rig.name(),
                    if held_out { "held-out" } else { "tuning" },
                    o.tally.exact,
                    o.tally.detected,
                    o.tally.false_name
                );
            }
            o
        })
        .collect();
    let mut out: BTreeMap<&'static str, Tally> = BTreeMap::new();
    for o in &outcomes {
        out.entry(o.kind).or_default().add(&o.tally);
        if verbose || o.tally.exact == 0 {
            print!(
                "{} {}: {}",
                rig.name(),
                if held_out { "held-out" } else { "tuning" },
                o.text
            );
        }
    }
    out
}

/// The share `a/b` in per cent (0 of 0 is printed as 0).
fn pct(a: usize, b: usize) -> f64 {
    100.0 * a as f64 / b.max(1) as f64
}

/// The figures the targets are judged by, of one set of tallies.
#[derive(Debug, Clone, Copy)]
struct Figures {
    all: usize,
    exact: usize,
    none: usize,
    none_named: usize,
    out_all: usize,
    out_unexpl: usize,
}

fn figures(t: &BTreeMap<&'static str, Tally>) -> Figures {
    let mut f = Figures {
        all: 0,
        exact: 0,
        none: 0,
        none_named: 0,
        out_all: 0,
        out_unexpl: 0,
    };
    for (k, t) in t {
        f.all += t.records;
        f.exact += t.exact;
        if *k == "none" {
            f.none += t.records;
            f.none_named += t.false_name;
        }
        if matches!(*k, "hum" | "drift" | "quadratic_drag") {
            f.out_all += t.records;
            f.out_unexpl += t.detected;
        }
    }
    f
}

/// Print the held-out figures per kind with the tuning range's beside them, the difference
/// (tuning − held-out: the overfit) and the three targets' figures; returns the held-out
/// figures.
fn table(
    rig: Rig,
    held: &BTreeMap<&'static str, Tally>,
    tune: &BTreeMap<&'static str, Tally>,
) -> Figures {
    println!(
        "\n{} rig: exactly right per kind, held-out (judged) and tuning (beside it)",
        rig.name()
    );
    println!(
        "{:>20} {:>16} {:>16} {:>9} {:>10} {:>10}",
        "kind", "held-out exact", "tuning exact", "overfit", "detected", "false name"
    );
    for kind in rig.kinds() {
        let Some(h) = held.get(kind) else { continue };
        let t = tune.get(kind).cloned().unwrap_or_default();
        println!(
            "{kind:>20} {:>8}/{:<3} {:>3.0}% {:>8}/{:<3} {:>3.0}% {:>+8.1}% {:>9.0}% {:>9.0}%",
            h.exact,
            h.records,
            pct(h.exact, h.records),
            t.exact,
            t.records,
            pct(t.exact, t.records),
            pct(t.exact, t.records) - pct(h.exact, h.records),
            pct(h.detected, h.records),
            pct(h.false_name, h.records)
        );
    }
    let (h, t) = (figures(held), figures(tune));
    let obs: usize = held.values().map(|t| t.observable).sum();
    let obs_exact: usize = held.values().map(|t| t.observable_exact).sum();
    println!(
        "{} held-out: {}/{} exactly right ({:.1} %; tuning {}/{}, {:.1} %: overfit {:+.1} points); \
         effect-free named {}/{} ({:.1} %; tuning {}/{}); out of catalogue unexplained {}/{} \
         ({:.1} %; tuning {}/{}); of the {obs} observable held-out records {obs_exact} exactly right",
        rig.name(),
        h.exact,
        h.all,
        pct(h.exact, h.all),
        t.exact,
        t.all,
        pct(t.exact, t.all),
        pct(t.exact, t.all) - pct(h.exact, h.all),
        h.none_named,
        h.none,
        pct(h.none_named, h.none),
        t.none_named,
        t.none,
        h.out_unexpl,
        h.out_all,
        pct(h.out_unexpl, h.out_all),
        t.out_unexpl,
        t.out_all
    );
    h
}

/// The three targets on held-out figures: ≥ 95 % exactly right, ≤ 2 % of the
/// effect-free records given a catalogue name, ≥ 90 % of the out-of-catalogue effects
/// `unexplained` (whole numbers of records: the smallest count that reaches each target).
/// Returns the targets missed, in words.
fn targets_missed(rig: Rig, f: &Figures) -> Vec<String> {
    let floor = |share: f64, of: usize| (share * of as f64 - 1e-9).ceil() as usize;
    let mut missed = Vec::new();
    if f.exact < floor(0.95, f.all) {
        missed.push(format!(
            "{}: {}/{} exactly right, the target ≥ 95 % needs {}",
            rig.name(),
            f.exact,
            f.all,
            floor(0.95, f.all)
        ));
    }
    if f.none_named as f64 > 0.02 * f.none as f64 {
        missed.push(format!(
            "{}: {}/{} effect-free records named, the target is ≤ 2 %",
            rig.name(),
            f.none_named,
            f.none
        ));
    }
    if f.out_unexpl < floor(0.90, f.out_all) {
        missed.push(format!(
            "{}: {}/{} out-of-catalogue effects unexplained, the target ≥ 90 % needs {}",
            rig.name(),
            f.out_unexpl,
            f.out_all,
            floor(0.90, f.out_all)
        ));
    }
    missed
}

/// Records per kind of the long run: `RIG_N` for the classic rig (56 by default: 504
/// records, the tuned run's size), `RIG_N_WIDE` for the widened one (36: 504 records);
/// `RIG_N_TUNING` tuning records per kind beside them (as many as held-out by default). The
/// first record's number (`RIG_TUNE_J0`, `RIG_SAMPLE_J0`) reads alike; each is at most
/// `TUNING_STRIDE` (a kind's seeds in the tuning range), and a value outside fails the run
/// with a message naming it.
fn per_kind(var: &str, default: usize) -> usize {
    env_number(var, default, 0..=TUNING_STRIDE as usize)
}

/// The long run: both rigs, the held-out range judged against the targets and the
/// tuning range beside it (`cargo test --release -p regen-tests --test diagnose_rig
/// rig_long_run -- --ignored --nocapture`; minutes on 2 cores). 504 held-out records of the
/// classic rig's nine kinds and 504 of the widened rig's fourteen, as many tuning records of
/// each beside them. The targets are asserted on each rig's held-out records (not when
/// `RIG_KINDS` narrows the run).
#[test]
#[ignore]
fn rig_long_run() {
    let emps = emps_x();
    let mut missed = Vec::new();
    for (rig, n) in [
        (Rig::Classic, per_kind("RIG_N", 56)),
        (Rig::Widened, per_kind("RIG_N_WIDE", 36)),
    ] {
        if n == 0 {
            continue;
        }
        let held = run(rig, true, n, 0, &emps);
        let tune = run(rig, false, per_kind("RIG_N_TUNING", n), 0, &emps);
        let f = table(rig, &held, &tune);
        missed.extend(targets_missed(rig, &f));
    }
    if env_kinds().is_some() {
        return;
    }
    assert!(missed.is_empty(), "targets missed: {}", missed.join("; "));
}

/// The sampled held-out subset CI runs (`.ci/run`; `cargo test -p regen-tests --test
/// diagnose_rig rig_held_out_sample -- --ignored --nocapture`): `RIG_SAMPLE` held-out records
/// per kind of each rig (4 by default: 36 classic and 56 widened records), records
/// `RIG_SAMPLE_J0 ..` of each kind (0 by default: the long run's first held-out records), with
/// as many tuning records of each kind beside them (their figure and the overfit printed; none
/// asserted). Asserts the floors `SAMPLE_FLOOR` (what the
/// diagnosis reaches there today, less a margin) and prints the targets' figures; the
/// long run asserts the targets themselves.
#[test]
#[ignore]
fn rig_held_out_sample() {
    let emps = emps_x();
    let n = per_kind("RIG_SAMPLE", 4);
    let j0 = per_kind("RIG_SAMPLE_J0", 0);
    for (rig, floor) in [
        (Rig::Classic, SAMPLE_FLOOR[0]),
        (Rig::Widened, SAMPLE_FLOOR[1]),
    ] {
        let held = run(rig, true, n, j0, &emps);
        let tune = run(rig, false, n, j0, &emps);
        let f = table(rig, &held, &tune);
        for m in targets_missed(rig, &f) {
            println!("target missed on the sample: {m}");
        }
        if env_kinds().is_some() || (n, j0) != (4, 0) {
            continue;
        }
        assert!(
            f.exact >= floor.0,
            "{}: {}/{} exactly right, the floor is {}",
            rig.name(),
            f.exact,
            f.all,
            floor.0
        );
        assert!(
            f.none_named <= floor.1,
            "{}: {}/{} effect-free records named, the floor is {}",
            rig.name(),
            f.none_named,
            f.none,
            floor.1
        );
        assert!(
            f.out_unexpl >= floor.2,
            "{}: {}/{} out-of-catalogue unexplained, the floor is {}",
            rig.name(),
            f.out_unexpl,
            f.out_all,
            floor.2
        );
    }
}

/// The tuning range's figures per kind, without the held-out range (`cargo test -p
/// regen-tests --test diagnose_rig rig_tuning_sample -- --ignored --nocapture`): the records
/// the diagnosis is developed on. `RIG_TUNE_N` tuning records per kind (8 by default) of the
/// rigs `RIG_RIGS` names (`widened` by default; `classic,widened` for both), `RIG_TUNE_J0`
/// the first record of each kind; `RIG_KINDS` narrows, `RIG_VERBOSE` prints every record,
/// `RIG_EVIDENCE` each finding's evidence and every verdict with it, `RIG_DUMP=DIR` writes
/// every record's CSV into DIR. One record: `RIG_TUNE_J0=j RIG_TUNE_N=1` (its seed is the
/// kind's first seed plus j).
#[test]
#[ignore]
fn rig_tuning_sample() {
    let emps = emps_x();
    let n = per_kind("RIG_TUNE_N", 8);
    let j0 = per_kind("RIG_TUNE_J0", 0);
    let rigs = env_choice("RIG_RIGS", &["classic", "widened"]).unwrap_or(vec!["widened".into()]);
    for rig in [Rig::Classic, Rig::Widened] {
        if !rigs.iter().any(|r| r == rig.name()) {
            continue;
        }
        let tune = run(rig, false, n, j0, &emps);
        println!(
            "\n{} rig, tuning records {j0} .. {} of each kind",
            rig.name(),
            j0 + n
        );
        for kind in rig.kinds() {
            if let Some(t) = tune.get(kind) {
                println!(
                    "{kind:>20} {:>4}/{:<4} {:>4.0}%  detected {:>4.0}%  false name {:>4.0}%",
                    t.exact,
                    t.records,
                    pct(t.exact, t.records),
                    pct(t.detected, t.records),
                    pct(t.false_name, t.records)
                );
            }
        }
        let f = figures(&tune);
        println!(
            "{} tuning: {}/{} exactly right ({:.1} %); effect-free named {}/{}; out of catalogue unexplained {}/{}",
            rig.name(),
            f.exact,
            f.all,
            pct(f.exact, f.all),
            f.none_named,
            f.none,
            f.out_unexpl,
            f.out_all
        );
    }
}

/// Floors of `rig_held_out_sample` (classic, widened): exactly right, effect-free records
/// named (at most), out-of-catalogue effects unexplained. Measured (the long run's records):
/// classic 33/36 exactly right (one of them a clip reported as confounded with a friction
/// building up with speed on a rounded triangle, which a refitted baseline explains entirely),
/// 0/4 named, 8/8 unexplained; widened 51/56, 0/4, 12/12. Two records of margin on each
/// rig's first, one on the third, none on the second.
const SAMPLE_FLOOR: [(usize, usize, usize); 2] = [(31, 0, 7), (49, 0, 11)];

/// A held-out sample in every `cargo test`: records 200 and 201 of each kind of both rigs
/// (apart from the long run's and CI's), exactly right at least as often as `QUICK_FLOOR`
/// says and effect-free records named at most as often. A floor under what the diagnosis
/// reaches there today, not the targets (the long run asserts those).
#[test]
fn rig_sample() {
    let emps = emps_x();
    for (rig, (floor, named)) in [
        (Rig::Classic, QUICK_FLOOR[0]),
        (Rig::Widened, QUICK_FLOOR[1]),
    ] {
        let held = run(rig, true, 2, 200, &emps);
        let f = figures(&held);
        let line = format!(
            "{}: {}/{} exactly right; effect-free named {}/{}; out of catalogue unexplained {}/{}",
            rig.name(),
            f.exact,
            f.all,
            f.none_named,
            f.none,
            f.out_unexpl,
            f.out_all
        );
        println!("{line}");
        assert!(f.exact >= floor, "{line} (floor {floor})");
        assert!(f.none_named <= named, "{line} (at most {named} named)");
    }
}

/// Floors of `rig_sample` (classic, widened): the least records exactly right and the most
/// effect-free records named. Measured 18/18 and 0/2 (classic), 21/28 and 1/2 (widened); 3
/// records of margin on the first, none on the second.
const QUICK_FLOOR: [(usize, usize); 2] = [(15, 0), (18, 1)];

/// The parameter a named effect reports against the rig's: (finding, parameter) the diagnosis
/// gives, and the rig's value, for the kinds with one size (None for the others).
fn truth_of(h: &Hidden) -> Option<(&'static str, &'static str, f64)> {
    Some(match *h {
        Hidden::ClippedCurrentLoop { limit_n } => ("current_limit", "limit_N", limit_n),
        Hidden::Delay { delay_s } => ("lag", "", delay_s),
        Hidden::Resonance { freq_hz, .. } => ("compliance", "", freq_hz),
        Hidden::Stribeck { vs_m_s, .. } => ("stribeck", "", vs_m_s),
        Hidden::Presliding { x_char_m } => ("presliding_hysteresis", "", x_char_m),
        Hidden::Backlash { width_m } => ("backlash", "width_m", width_m),
        Hidden::Drift { total_n } => ("unexplained", "change_N", total_n),
        _ => return None,
    })
}

/// The parameters of named effects as a distribution over held-out records of the classic rig
/// (`PARAM_RECORDS` records of each kind with one size, records 300 … of each kind): per kind,
/// how many records name the effect and the median and largest relative deviation of its size
/// (the first parameter, or the one named in `truth_of`) from the rig's. Asserted: at least
/// `PARAM_BOUNDS`' share named, and the median and largest deviations within their bounds (3×
/// the measured).
#[test]
fn named_parameters_on_held_out() {
    use rayon::prelude::*;
    let emps = emps_x();
    let kinds = [
        "clipped_current_loop",
        "delay",
        "resonance",
        "stribeck",
        "presliding",
        "backlash",
        "drift",
    ];
    let jobs: Vec<(usize, &str, usize)> = kinds
        .iter()
        .flat_map(|kind| {
            let k = Hidden::KINDS.iter().position(|x| x == kind).unwrap();
            (300..300 + PARAM_RECORDS).map(move |j| (k, *kind, j))
        })
        .collect();
    let devs: Vec<(&str, Option<f64>)> = jobs
        .par_iter()
        .map(|&(k, kind, j)| {
            let seed = Rig::Classic.seed(true, k, j);
            let spec = Rig::Classic.spec(seed, kind, j, &emps);
            let rec = parse_csv(&spec.csv(), None).expect("rig record parses");
            let d = diagnose(&rec, &Options::default());
            let (effect, param, truth) = truth_of(&spec.hidden).expect("a kind with a size");
            let p = d
                .findings
                .iter()
                .filter(|f| f.effect == effect)
                .find_map(|f| {
                    if param.is_empty() {
                        f.parameters.first().map(|p| p.1)
                    } else {
                        f.parameters.iter().find(|p| p.0 == param).map(|p| p.1)
                    }
                });
            (kind, p.map(|p| p / truth - 1.0))
        })
        .collect();
    for (i, kind) in kinds.iter().enumerate() {
        let mut dev: Vec<f64> = devs
            .iter()
            .filter(|d| d.0 == *kind)
            .filter_map(|d| d.1.map(f64::abs))
            .collect();
        dev.sort_by(f64::total_cmp);
        let med = dev.get(dev.len() / 2).copied().unwrap_or(f64::NAN);
        let max = dev.last().copied().unwrap_or(f64::NAN);
        println!(
            "{kind:>20}: named on {}/{PARAM_RECORDS}; |deviation| median {:.2} %, largest {:.2} %",
            dev.len(),
            100.0 * med,
            100.0 * max
        );
        let (share, bound_med, bound_max) = PARAM_BOUNDS[i];
        assert!(
            dev.len() as f64 >= share * PARAM_RECORDS as f64,
            "{kind}: named on {}/{PARAM_RECORDS}",
            dev.len()
        );
        assert!(med <= bound_med, "{kind}: median deviation {med}");
        assert!(max <= bound_max, "{kind}: largest deviation {max}");
    }
}

/// Records per kind of `named_parameters_on_held_out`.
const PARAM_RECORDS: usize = 6;
/// Per kind of `named_parameters_on_held_out` (in its order: clip level, delay, mode
/// frequency, Stribeck speed, presliding displacement, play width, drift's change): the least
/// share of records that name the effect (measured 6/6 on every kind; one record of margin),
/// and the bounds on the median and the largest relative deviation of its size, 3× the
/// measured (medians 0.29, 0.87, 0.23, 0.78, 2.02, 2.97, 0.88 %; largest 0.72, 6.71, 0.73,
/// 1.94, 10.98, 11.62, 14.91 %).
const PARAM_BOUNDS: [(f64, f64, f64); 7] = [
    (0.8, 0.009, 0.022),
    (0.8, 0.026, 0.20),
    (0.8, 0.007, 0.022),
    (0.8, 0.023, 0.058),
    (0.8, 0.061, 0.33),
    (0.8, 0.089, 0.35),
    (0.8, 0.026, 0.45),
];

/// The rig's observability rule redraws the trajectory's own parameters when 40 draws of the
/// effect fail on the first motion, and moves the record to the next family when 8 motions of
/// its own fail (`bench_rig`, module doc). It tests the generator, not the diagnosis: a
/// rounded-triangle Stribeck record observable only on its sixth triangle (2.59 N rms in motion
/// against 0.49 N noise); three that stay unobservable over 8 triangles (a rounded triangle
/// crosses the Stribeck band only at its reversals, whatever its period and sharpness, and the
/// samples near a reversal are at rest) and are drawn as point-to-point records (5.48, 21.5,
/// 6.71 N rms in motion); a clipping level no family shows, even lowered to a tenth of the
/// drive's peak force (0.63 N rms against 1.95 N noise), flagged in its own family; records
/// observable on their first motion keep it (draw 0: the same record as without the rule).
/// Without the motion redraw the first assert fails; without the family's change the second.
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
/// force: three recorded-motion (EMPS) Stribeck records, whose effect lies on
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
/// accepts. A rounded-triangle drift (eighth motion) and a point-to-point hum are observable
/// with an rms in motion of 5× the force noise (the binding clause; within 10⁻⁵); a drift
/// whose rule needs more than `SIZE_MAX_SCALE` times its draw stays flagged. Break: the sizing
/// removed, the first drift is flagged and the first assert fails.
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
