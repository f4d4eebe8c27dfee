//! `velocity_strengthening_friction`: a Coulomb level that builds up with speed,
//! ΔF·(1 − exp(−|v|/v_b))·sgn v (a ballscrew's rolling and lubricant-film drag), on records
//! computed in closed form here (no catalogue column), against `stribeck`, its opposite
//! (static friction above the Coulomb level).

use hal_sim::diagnose::effects;
use hal_sim::diagnose::synth::Rng;
use hal_sim::diagnose::{diagnose, Options};

const SAMPLES: usize = 12_000;

/// A record of an imposed two-sine motion (0.4 Hz ±40 mm, 1.1 Hz ±15 mm; peak speed 0.2 m/s)
/// with the force of a device of inertia, viscous and Coulomb friction, plus `rise_n`·(1 −
/// exp(−|v|/`vb`))·sgn v (the level building up with speed) and `bump_n`·exp(−(v/`vs`)²)·sgn v
/// (a Stribeck bump), 0.3 N force noise. The force is computed from the true motion; the
/// diagnosis derives v and a from the position.
fn record(seed: u64, rise_n: f64, vb: f64, bump_n: f64, vs: f64) -> String {
    use std::fmt::Write;
    let (m, fv, fc) = (50.0, 300.0, 25.0);
    let mut rng = Rng::new(seed);
    let mut out = String::from("# two-sine motion, friction building up with speed\nt_s,x_m,f_N\n");
    for i in 0..SAMPLES {
        let t = i as f64 * 1e-3;
        let (x, v, a) = regen_tests::two_sine(t);
        let sg = v.signum();
        let f = m * a
            + fv * v
            + fc * sg
            + rise_n * (1.0 - (-v.abs() / vb).exp()) * sg
            + bump_n * (-(v / vs).powi(2)).exp() * sg
            + 0.3 * rng.normal();
        let _ = writeln!(out, "{t:.6},{x:.9e},{f:.6}");
    }
    out
}

/// A level rising by 8 N over 10 mm/s (EMPS's size: about a third of its Coulomb level) is
/// named first with its rise and build-up speed; a Stribeck bump of the same size (friction
/// falling, not rising, as the speed rises) is named `stribeck`, never this effect.
///
/// Measured (the three records): rise 7.39–7.47 N (−7.7 … −6.6 %), v_b 11.9–12.3 mm/s (+19 … +23 %),
/// beside a `screw_efficiency` (ratio 1.20) that the same motion without the rise also gets
/// (ratio 1.08: the true Coulomb step at each reversal falls between samples, which the
/// fitted sgn, linear over ±0.2 % of the peak speed, does not follow; the rise, a low-speed
/// term, shares that residual, cause not measured further). Bounds: rise 15 %, v_b 35 %
/// (about twice and 1.5× the largest deviation; the bias is systematic, the seeds fixed).
#[test]
fn friction_building_up_with_speed_is_named_and_stribeck_is_not() {
    for seed in 0..3u64 {
        let (rise, vb) = (8.0, 0.010);
        let rec = hal_sim::diagnose::parse_csv(&record(seed + 10, rise, vb, 0.0, 0.01), None)
            .expect("record parses");
        let d = diagnose(&rec, &Options::default());
        let names = d.catalogue_names();
        println!(
            "seed {seed}: rise {rise} N over {vb} m/s -> {names:?}, held-out {:.2} % -> {:.2} %",
            100.0 * d.baseline_holdout_rel_error,
            100.0 * d.final_holdout_rel_error,
        );
        assert_eq!(
            names.first(),
            Some(&"velocity_strengthening_friction"),
            "seed {seed}: {names:?}"
        );
        let p = |k: &str| {
            d.findings[0]
                .parameters
                .iter()
                .find(|p| p.0 == k)
                .unwrap()
                .1
        };
        let (r, b) = (p("friction_rise_N"), p("buildup_velocity_m_s"));
        println!(
            "seed {seed}: rise {r:.3} N ({:+.2} %), v_b {b:.5} m/s ({:+.2} %)",
            100.0 * (r / rise - 1.0),
            100.0 * (b / vb - 1.0)
        );
        assert!((r / rise - 1.0).abs() < 0.15, "seed {seed}: rise {r}");
        assert!((b / vb - 1.0).abs() < 0.35, "seed {seed}: v_b {b}");

        let st = hal_sim::diagnose::parse_csv(&record(seed + 10, 0.0, vb, 8.0, 0.01), None)
            .expect("record parses");
        let d = diagnose(&st, &Options::default());
        let names = d.catalogue_names();
        println!("seed {seed}: Stribeck bump 8 N -> {names:?}");
        assert!(
            !d.effects
                .iter()
                .any(|e| e.kind == effects::VELOCITY_STRENGTHENING),
            "seed {seed}: a Stribeck bump named {names:?}"
        );
        assert!(names.contains(&"stribeck"), "seed {seed}: {names:?}");
    }
}

/// The physical range (`effects::plausible`): a rise ΔF > 0 (friction growing with speed; a
/// negative one is a Stribeck bump, static friction above the Coulomb level, `stribeck`'s)
/// on a low-speed Coulomb level ≥ 0 (the baseline's Coulomb coefficient fitted with it).
#[test]
fn velocity_strengthening_physical_range() {
    use hal_sim::diagnose::effects::{plausible, Effect};
    let e = Effect {
        kind: effects::VELOCITY_STRENGTHENING,
        param: 0.01,
        param2: 0.0,
    };
    // baseline inertia, viscous, Coulomb (low-speed level), offset
    let base = [95.0, 190.0, 10.3, -0.2];
    assert!(plausible(&e, &[11.7], &base));
    assert!(!plausible(&e, &[-11.7], &base), "a falling level accepted");
    assert!(!plausible(&e, &[0.0], &base), "no rise accepted");
    let neg = [95.0, 190.0, -1.0, -0.2];
    assert!(
        !plausible(&e, &[11.7], &neg),
        "a negative low-speed level accepted"
    );
    assert!(!plausible(&e, &[f64::NAN], &base));
}

/// The simulator's plant (`device_model`, its own implementation) against the closed form
/// Fc·sgn v + ΔF·(1 − exp(−|v|/v_b))·sgn v at constant speeds, and its fragment key checked by
/// name (a negative rise refused with the key, the value and the range).
#[test]
fn plant_friction_building_up_with_speed() {
    use hal_sim::device_model::Fragment;
    let frag = |rise: f64| {
        format!(
            "[model]\ninertia_kg = 0\nviscous_friction_Ns_per_m = 0\ncoulomb_friction_N = 10\n\
             force_offset_N = 0\nsign_band_m_s = 1e-6\n[[model.effect]]\n\
             name = \"velocity_strengthening_friction\"\nbuildup_velocity_m_s = 0.01\n\
             friction_rise_N = {rise}\n"
        )
    };
    let m = Fragment::from_toml(&frag(12.0))
        .expect("fragment loads")
        .model;
    for v in [-0.1f64, -0.01, -0.002, 0.001, 0.005, 0.01, 0.03, 0.2] {
        let f = m.force_series(1e-3, &[0.0, 0.0], &[v, v], &[0.0, 0.0]);
        let want = (10.0 + 12.0 * (1.0 - (-v.abs() / 0.01).exp())) * v.signum();
        assert!((f[1] - want).abs() < 1e-9, "v {v}: {} against {want}", f[1]);
    }
    let err = Fragment::from_toml(&frag(-3.0)).expect_err("a negative rise refused");
    assert!(
        err.contains("friction_rise_N") && err.contains("-3"),
        "{err}"
    );
}
