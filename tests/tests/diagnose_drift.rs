//! A drift of the force offset on point-to-point moves whose direction follows time
//! (docs/diagnose.md, "The baseline"): the first five moves run one way, the last
//! five back. The baseline's Coulomb term, sgn v, is then a step in time and takes part of a
//! linear drift; what the baseline leaves of it is a sawtooth over the two halves, which a
//! trend of degree 2 does not follow, so the drift does not stand out of the block means'
//! scatter on the baseline's residual. Fitted beside the trend, the baseline keeps its own
//! coefficients and the drift shows. The records are built here in closed form (the moves,
//! the device's force while it slides and its static friction while it rests), sharing
//! nothing with the diagnosis.

use hal_sim::diagnose::synth::Rng;
use hal_sim::diagnose::{diagnose, parse_csv, Diagnosis, Options};
use std::f64::consts::TAU;

const SAMPLES: usize = 12_000;
const FS: f64 = 1000.0;
/// Each move: `STEP_M` in `MOVE_S` (the acceleration one sine period), then a dwell of
/// `DWELL_S`.
const MOVE_S: f64 = 0.5;
const DWELL_S: f64 = 0.7;
const STEP_M: f64 = 0.005;
/// The device: inertia, viscous and Coulomb friction; at rest it holds a static friction of
/// 0.6·Fc in the direction of its last move (anywhere within its breakaway level).
const M: f64 = 40.0;
const FV: f64 = 300.0;
const FC: f64 = 20.0;

/// The moves' position, velocity, acceleration and direction at time t: five moves of
/// +`STEP_M`, then five of −`STEP_M`.
fn motion(t: f64) -> (f64, f64, f64, f64, bool) {
    let period = MOVE_S + DWELL_S;
    let k = (t / period).floor() as i64;
    let dir = if k < 5 { 1.0 } else { -1.0 };
    // start of move k
    let x0 = STEP_M * if k < 5 { k as f64 } else { (10 - k) as f64 };
    let s = ((t - k as f64 * period) / MOVE_S).min(1.0);
    // p = s − sin(2πs)/(2π): the acceleration a sine period, continuous at both ends
    let (p, dp, ddp) = if s >= 1.0 {
        (1.0, 0.0, 0.0)
    } else {
        let (sn, cs) = (TAU * s).sin_cos();
        (
            s - sn / TAU,
            (1.0 - cs) / MOVE_S,
            TAU * sn / (MOVE_S * MOVE_S),
        )
    };
    (
        x0 + dir * STEP_M * p,
        dir * STEP_M * dp,
        dir * STEP_M * ddp,
        dir,
        s < 1.0 && s > 0.0,
    )
}

/// The device on the moves with a drift of `drift_n` over the record (linear in time,
/// centred), 0.3 N noise, the position quantised to 1 µm; CSV text (x only: v and a derived
/// by the reader).
fn record(seed: u64, drift_n: f64) -> String {
    use std::fmt::Write;
    let mut rng = Rng::new(seed);
    let mut out = String::from("# point-to-point moves, one way then back\nt_s,x_m,f_N\n");
    let dur = SAMPLES as f64 / FS;
    for i in 0..SAMPLES {
        let t = i as f64 / FS;
        let (x, v, a, dir, moving) = motion(t);
        let dev = if moving {
            M * a + FV * v + FC * v.signum()
        } else {
            0.6 * FC * dir
        };
        let f = dev + drift_n * (t / dur - 0.5) + 0.3 * rng.normal();
        let x = (x * 1e6).round() * 1e-6;
        let _ = writeln!(out, "{t:.6},{x:.12e},{f:.6}");
    }
    out
}

/// The drift's change over the record as reported (`unexplained` with `change_N`).
fn drift_change(d: &Diagnosis) -> Option<f64> {
    d.findings
        .iter()
        .filter(|f| f.effect == "unexplained")
        .find_map(|f| {
            f.parameters
                .iter()
                .find(|(k, _)| k == "change_N")
                .map(|p| p.1)
        })
}

/// A −30 N drift on moves one way then back is reported with its change and carried (no
/// catalogue name), on 2 seeds; the same moves without the drift report none. Break: without
/// the baseline refitted beside the trend (`diagnose_checked`'s second slow-change test) no
/// drift is found and the test fails (one of the two records is then named
/// `position_dependent_friction` and `position_periodic_friction`).
#[test]
fn drift_on_moves_one_way_then_back_is_found() {
    for seed in [1u64, 2] {
        let rec = parse_csv(&record(seed, -30.0), None).expect("record parses");
        let d = diagnose(&rec, &Options::default());
        let change = drift_change(&d);
        println!(
            "seed {seed}: {:?}, drift {change:?} N for -30 N; held-out {:.2} % -> {:.2} %",
            d.catalogue_names(),
            100.0 * d.baseline_holdout_rel_error,
            100.0 * d.final_holdout_rel_error
        );
        let change = change.unwrap_or_else(|| panic!("no drift found, {:?}", d.verdicts));
        // measured −29.996 and −29.936 N (−0.01 %, −0.21 %: the block means' trend under
        // 0.3 N noise); bound 0.65 %, 3× the worst
        assert!((change / -30.0 - 1.0).abs() < 6.5e-3, "change {change}");
        assert!(
            d.catalogue_names().is_empty(),
            "{:?} {:?}",
            d.catalogue_names(),
            d.verdicts
        );
        let rec = parse_csv(&record(seed, 0.0), None).expect("record parses");
        let d = diagnose(&rec, &Options::default());
        println!(
            "seed {seed} without drift: {:?}, drift {:?}",
            d.catalogue_names(),
            drift_change(&d)
        );
        assert_eq!(drift_change(&d), None, "{:?}", d.findings);
    }
}
