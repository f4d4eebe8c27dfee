//! Position ripples on a motion that turns at the same positions (docs/diagnose.md,
//! "Stability as evidence": the ripple apart from the reversals). On a rounded triangle of one
//! stroke x = x_r + d·u (u the travel since the last reversal at x_r, d the direction), so a
//! force that the reversals excite, d·g(u), and the part of a position ripple that is odd
//! about the stroke's centre are the same record; only the even part tells a ripple locked to
//! position. The records are built here in closed form (the motion integrated from its
//! velocity, the force from the device's terms), sharing nothing with the diagnosis.

mod common;

use hal_sim::diagnose::effects::{
    self, build_columns, ripple_apart_from_reversals, travel_since_reversal, Context, Effect,
};
use hal_sim::diagnose::synth::Rng;
use hal_sim::diagnose::{diagnose, parse_csv, Options};
use std::f64::consts::TAU;

const SAMPLES: usize = 12_000;
const FS: f64 = 1000.0;
/// Period of the triangle, s; sharpness of its reversals; peak speed, m/s.
const PERIOD: f64 = 2.0;
const SHARP: f64 = 6.0;
const V_PEAK: f64 = 0.08;

/// Rounded triangle v = V·tanh(s·sin(2πt/T)), x its integral (Simpson over 10 substeps per
/// sample), a its derivative: (t, x, v, a) at the samples.
fn triangle() -> Vec<(f64, f64, f64, f64)> {
    let vel = |t: f64| V_PEAK * (SHARP * (TAU * t / PERIOD).sin()).tanh();
    let mut x = 0.0;
    let sub = 10;
    let h = 1.0 / (FS * sub as f64);
    (0..SAMPLES)
        .map(|i| {
            let t = i as f64 / FS;
            let s = SHARP * (TAU * t / PERIOD).sin();
            let a = V_PEAK * SHARP * (TAU / PERIOD) * (TAU * t / PERIOD).cos() / s.cosh().powi(2);
            let out = (t, x, vel(t), a);
            for k in 0..sub {
                let t0 = t + k as f64 * h;
                x += h / 6.0 * (vel(t0) + 4.0 * vel(t0 + 0.5 * h) + vel(t0 + h));
            }
            out
        })
        .collect()
}

/// The device on the triangle (50 kg, 300 N·s/m, 25 N Coulomb, 0.3 N noise) with an extra
/// force `extra(x, v)`; CSV text.
fn record(seed: u64, extra: &dyn Fn(f64, f64) -> f64) -> String {
    use std::fmt::Write;
    let mut rng = Rng::new(seed);
    let mut out = String::from("# rounded triangle\nt_s,x_m,f_N\n");
    for (t, x, v, a) in triangle() {
        let f = 50.0 * a + 300.0 * v + 25.0 * v.signum() + extra(x, v) + 0.3 * rng.normal();
        let _ = writeln!(out, "{t:.6},{x:.12e},{f:.6}");
    }
    out
}

/// The triangle's turning points (closed form: the extremes of x) and its centre.
fn turning_points() -> (f64, f64) {
    let tr = triangle();
    let lo = tr.iter().map(|p| p.1).fold(f64::MAX, f64::min);
    let hi = tr.iter().map(|p| p.1).fold(f64::MIN, f64::max);
    (lo, hi)
}

/// A force locked to the last reversal, 1 N·d·sin(2πu/λ + 0.4) (u the travel since the
/// turning point, closed form from the extremes), and a 1 N cogging even about the stroke's
/// centre, cos(2π(x − x_c)/λ).
fn reversal_ripple(lambda: f64) -> impl Fn(f64, f64) -> f64 {
    let (lo, hi) = turning_points();
    move |x, v| {
        let (d, u) = if v >= 0.0 {
            (1.0, x - lo)
        } else {
            (-1.0, hi - x)
        };
        d * (TAU * u / lambda + 0.4).sin()
    }
}
fn even_cogging(lambda: f64) -> impl Fn(f64, f64) -> f64 {
    let (lo, hi) = turning_points();
    move |x, _| (TAU * (x - 0.5 * (lo + hi)) / lambda).cos()
}

/// `travel_since_reversal` against the closed form: at every sample in motion away from the
/// reversals (|v| above half its peak) the travel since the last turning point within 1 µm
/// (the position's own rounding; measured below) and the direction right.
#[test]
fn travel_since_reversal_is_the_closed_form() {
    let rec = parse_csv(&record(1, &|_, _| 0.0), None).expect("record parses");
    let ctx = Context::new(&rec);
    let (u, d) = travel_since_reversal(&ctx);
    let (lo, hi) = turning_points();
    let mut worst = 0.0f64;
    // the first flank starts at the record's start, not at a turning point: from the first
    // reversal on
    let first = (PERIOD / 2.0 * FS) as usize;
    for (i, (_, x, v, _)) in triangle().into_iter().enumerate().skip(first) {
        if v.abs() < 0.5 * V_PEAK {
            continue;
        }
        let (dw, uw) = if v > 0.0 {
            (1.0, x - lo)
        } else {
            (-1.0, hi - x)
        };
        assert_eq!(d[i], dw, "sample {i}");
        worst = worst.max((u[i] - uw).abs());
    }
    println!("travel since reversal: worst {worst:.3e} m");
    assert!(worst < 1e-6, "{worst}");
}

/// Beside the reversal-locked ripple, a cogging at its wavelength carries nothing the record
/// tells apart (Wald of χ² with 2 degrees of freedom, below 9) when the force is the
/// reversal-locked ripple, and stands far out (Wald in the thousands) when it is a cogging
/// even about the stroke's centre.
#[test]
fn ripple_locked_to_reversals_is_not_apart_from_them() {
    let lambda = 0.013;
    let rev = reversal_ripple(lambda);
    let cog = even_cogging(lambda);
    for (label, extra, apart) in [
        ("reversal-locked", &rev as &dyn Fn(f64, f64) -> f64, false),
        ("cogging", &cog, true),
    ] {
        let rec = parse_csv(&record(3, extra), None).expect("record parses");
        let ctx = Context::new(&rec);
        let e = Effect {
            kind: effects::COGGING,
            param: lambda,
            param2: 0.0,
        };
        let cols = build_columns(&ctx, std::slice::from_ref(&e));
        let wald = ripple_apart_from_reversals(&ctx, &cols, (cols.len() - 2, cols.len()), lambda);
        println!("{label}: Wald {wald:.1} beside the reversal-locked ripple");
        assert_eq!(wald >= 9.0, apart, "{label}: Wald {wald}");
    }
}

/// The diagnosis on the two records: the reversal-locked ripple is given no periodic name;
/// the cogging even about the centre is named `cogging`, its wavelength within 1 %.
#[test]
fn reversal_ripple_on_a_triangle_is_not_named_cogging() {
    let lambda = 0.013;
    let rev = reversal_ripple(lambda);
    let cog = even_cogging(lambda);
    for seed in 0..2u64 {
        let d = diagnose(
            &parse_csv(&record(10 + seed, &rev), None).expect("parses"),
            &Options::default(),
        );
        let names: Vec<(&str, f64)> = d.effects.iter().map(|e| (e.kind.name(), e.param)).collect();
        println!(
            "seed {seed}: reversal-locked -> {names:?}; {:?}",
            d.verdicts
        );
        assert!(
            !common::names_a_periodic_effect(&d),
            "seed {seed}: the reversal-locked ripple named {names:?}"
        );
        let d = diagnose(
            &parse_csv(&record(20 + seed, &cog), None).expect("parses"),
            &Options::default(),
        );
        let names: Vec<(&str, f64)> = d.effects.iter().map(|e| (e.kind.name(), e.param)).collect();
        println!(
            "seed {seed}: cogging {lambda} m -> {names:?}; {:?}",
            d.findings.iter().map(|f| &f.note).collect::<Vec<_>>()
        );
        assert!(
            common::names_cogging_at(&d, lambda),
            "seed {seed}: the cogging not named: {names:?}"
        );
    }
}
