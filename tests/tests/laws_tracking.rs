//! Optimal-load tracking on the TMD at 0.5 Hz (compact model, `hal_sim::study::Sim`, with the
//! firmware's fixed-point tracking law): from 10 Ω and from 1 kΩ it settles within 2 % of the
//! best fixed-R_L power found by a simulated sweep, and re-converges after the excitation
//! frequency and amplitude change.

use hal_sim::lqg::LinModel;
use hal_sim::study::{
    sine_best_fixed, sine_best_fixed_fc, sine_power_analytic, study_config, Excitation, Sim,
};
use regen_fw::laws::{Law, LawKind};
use regen_fw::Config;

fn r_hat(sim: &Sim) -> f64 {
    match &sim.law {
        Law::Tracking(t) => t.r_hat() as f64,
        _ => unreachable!(),
    }
}

/// Runs `horizon` seconds, then averages over 80 s more. Returns (settle time, final mean
/// power). "Settled" = the start of the first 32 s window (two dither cycles of the default
/// 16 s) after which every window's mean power stays within 2 % of `p_best`. A 32 s window
/// holds ≥ 19 periods of the power ripple (twice the excitation frequency, ≥ 0.6 Hz here), so
/// its mean is within 1/(2·ω·T) ≤ 0.8 % of the true mean, the rest of the 2 % is the criterion.
/// Also returns the first window end after which R̂ stays within 10 % of `r_best`.
fn track(sim: &mut Sim, p_best: f64, r_best: f64, horizon: f64) -> (Option<f64>, Option<f64>, f64) {
    let win = 32.0;
    let t0 = sim.t;
    let mut settled: Option<f64> = None;
    let mut r_in: Option<f64> = None;
    let mut t = 0.0;
    while t < horizon {
        let p = sim.run(win);
        t += win;
        if p >= 0.98 * p_best {
            if settled.is_none() {
                settled = Some(t - win);
            }
        } else {
            settled = None;
        }
        if (r_hat(sim) / r_best).ln().abs() < 0.1 {
            r_in.get_or_insert(t);
        } else {
            r_in = None;
        }
    }
    let _ = t0;
    let p_final = sim.run(80.0);
    (settled, r_in, p_final)
}

/// Excitation schedule: 0.5 Hz 1 m/s² until 480 s, then 0.3 Hz (frequency step: the old
/// optimum loses 18 % there) until 880 s, then 0.3 Hz 2 m/s² (amplitude step; in this linear
/// model the optimum load does not move with amplitude, so this checks that the normalised
/// gradient keeps the tracker where it is while the power quadruples).
const T_FREQ: f64 = 480.0;
const T_AMP: f64 = 880.0;

#[test]
fn tracking_converges_and_reconverges() {
    let model = LinModel::reference();
    let ((r1, p1), ((r2, p2), (r3, p3))) = rayon::join(
        || sine_best_fixed(model, 1.0, 0.5),
        || {
            rayon::join(
                || sine_best_fixed(model, 1.0, 0.3),
                || sine_best_fixed(model, 2.0, 0.3),
            )
        },
    );
    eprintln!("best fixed (sweep): 0.5 Hz 1 m/s² {r1:.1} Ω {p1:.3} W; 0.3 Hz 1 m/s² {r2:.1} Ω {p2:.3} W; 0.3 Hz 2 m/s² {r3:.1} Ω {p3:.3} W");
    // The sweep's optimum must be a real interior peak (not a grid edge), and agree with the
    // analytic steady state of the linear model (the simulated sweep carries the fixed-point
    // law and RK4; 0.5 % covers the law's 1e-5 conductance rounding and the flat peak, where a
    // few % of R_L move P by < 0.1 %).
    for (r, p, a, f) in [(r1, p1, 1.0, 0.5), (r2, p2, 1.0, 0.3), (r3, p3, 2.0, 0.3)] {
        assert!(r > 20.0 && r < 500.0);
        let best_analytic = (0..2000)
            .map(|k| sine_power_analytic(&model, 10f64.powf(k as f64 / 500.0), a, f))
            .fold(0.0, f64::max);
        assert!(
            (p / best_analytic - 1.0).abs() < 5e-3,
            "{p} vs {best_analytic}"
        );
    }
    let sched = vec![(0.0, 1.0, 0.5), (T_FREQ, 1.0, 0.3), (T_AMP, 2.0, 0.3)];
    for start in [10.0f32, 1000.0] {
        let cfg = study_config(LawKind::Tracking, start);
        let mut sim = Sim::new(model, &cfg, Excitation::Sine(sched.clone())).unwrap();
        // 384 s to settle + 80 s of final average, then 16 s more: T_FREQ.
        let (settle, r_in, p_final) = track(&mut sim, p1, r1, 384.0);
        eprintln!(
            "from {start} Ω: within 2 % for good after {settle:?} s, R̂ within 10 % after {r_in:?} s; final P {p_final:.3} W ({:+.2} % of best fixed), R̂ {:.1} Ω",
            (p_final / p1 - 1.0) * 100.0,
            r_hat(&sim)
        );
        // Measured: 128 s from either end (ln(95/10) ≈ 2.25 at ≤ 0.3 per 16 s cycle is 8
        // cycles). Bound: 16 cycles.
        assert!(
            settle.is_some_and(|t| t <= 256.0),
            "did not settle within 2 %"
        );
        // Final 80 s (10 dither cycles) average within 2 % of the best fixed load; the dither
        // itself costs about κ·a² ≈ 0.4 % here (measured), the rest is margin.
        assert!(p_final >= 0.98 * p1, "{p_final} vs {p1}");
        if start != 10.0 {
            continue;
        }
        sim.run(T_FREQ - sim.t);
        assert!((sim.t - T_FREQ).abs() < 1e-6);
        let (settle2, r_in2, p2_final) = track(&mut sim, p2, r2, 320.0);
        eprintln!(
            "after 0.5→0.3 Hz: within 2 % after {settle2:?} s, R̂ within 10 % after {r_in2:?} s; final P {p2_final:.3} W ({:+.2} %), R̂ {:.1} Ω",
            (p2_final / p2 - 1.0) * 100.0,
            r_hat(&sim)
        );
        // ln(95/43) ≈ 0.8: three bounded steps plus the fine approach; bound 10 cycles.
        assert!(settle2.is_some_and(|t| t <= 160.0) && p2_final >= 0.98 * p2);
        assert!(r_in2.is_some_and(|t| t <= 192.0), "R̂ did not follow");
        sim.run(T_AMP - sim.t);
        assert!((sim.t - T_AMP).abs() < 1e-6);
        let (settle3, _, p3_final) = track(&mut sim, p3, r3, 160.0 - 32.0);
        eprintln!(
            "after 1→2 m/s²: within 2 % after {settle3:?} s; final P {p3_final:.3} W ({:+.2} %), R̂ {:.1} Ω",
            (p3_final / p3 - 1.0) * 100.0,
            r_hat(&sim)
        );
        assert!(settle3.is_some_and(|t| t <= 64.0) && p3_final >= 0.98 * p3);
    }
}

/// With Coulomb friction the optimum load depends on the amplitude (friction takes a larger
/// share of small motions), so an amplitude step moves it: 0.5 Hz, F_c = 150 N (the paper's p1
/// is not available; 150 N is 14 % of the device's force rating), 1 → 0.5 m/s² at 480 s. At
/// 0.5 m/s² friction eats most of the motion (best 0.13 W), so the hold threshold
/// `trk_p_min_w` is lowered to 0.02 W for this test.
#[test]
fn tracking_follows_an_amplitude_step_with_coulomb_friction() {
    let model = LinModel::reference();
    let f_c = 150.0;
    let ((ra, pa), (rb, pb)) = rayon::join(
        || sine_best_fixed_fc(model, f_c, 1.0, 0.5),
        || sine_best_fixed_fc(model, f_c, 0.5, 0.5),
    );
    eprintln!("F_c {f_c} N, best fixed: 1 m/s² {ra:.1} Ω {pa:.3} W; 0.5 m/s² {rb:.1} Ω {pb:.3} W");
    let cfg = Config {
        trk_p_min_w: 0.02,
        ..study_config(LawKind::Tracking, 10.0)
    };
    let mut sim = Sim::new(
        model,
        &cfg,
        Excitation::Sine(vec![(0.0, 1.0, 0.5), (T_FREQ, 0.5, 0.5)]),
    )
    .unwrap();
    sim.f_c = f_c;
    let (s1, _, p1) = track(&mut sim, pa, ra, 384.0);
    sim.run(T_FREQ - sim.t);
    let r1 = r_hat(&sim);
    // The power curve is flat near the optimum, so also time R̂ itself: the first dither-cycle
    // boundary after which R̂ stays within 10 % of the new best fixed load.
    let mut r_in: Option<f64> = None;
    for k in 1..=20 {
        sim.run(16.0);
        if (r_hat(&sim) / rb).ln().abs() < 0.1 {
            r_in.get_or_insert(16.0 * k as f64);
        } else {
            r_in = None;
        }
    }
    let p2 = sim.run(80.0);
    eprintln!(
        "1 m/s²: settled {s1:?} s, {:+.2} %, R̂ {r1:.1} Ω; after the step to 0.5 m/s²: R̂ within 10 % of {rb:.1} Ω after {r_in:?} s, final {:+.2} %, R̂ {:.1} Ω",
        (p1 / pa - 1.0) * 100.0,
        (p2 / pb - 1.0) * 100.0,
        r_hat(&sim)
    );
    assert!(s1.is_some_and(|t| t <= 256.0) && p1 >= 0.98 * pa);
    // ln(90/52) = 0.55: two bounded steps plus the fine approach; bound 10 cycles.
    assert!(r_in.is_some_and(|t| t <= 160.0) && p2 >= 0.98 * pb);
}
