//! Optimal-load tracking on the TMD at 0.5 Hz (compact model, `hal_sim::study::Sim`, with the
//! firmware's fixed-point tracking law): from 10 Ω and from 1 kΩ it settles within 2 % of the
//! best fixed-R_L power found by a simulated sweep, and re-converges after the excitation
//! frequency and amplitude change.

use hal_sim::lqg::LinModel;
use hal_sim::study::{sine_best_fixed, sine_power_analytic, study_config, Excitation, Sim};
use regen_fw::laws::{Law, LawKind};

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
fn track(sim: &mut Sim, p_best: f64, horizon: f64) -> (Option<f64>, f64) {
    let win = 32.0;
    let t0 = sim.t;
    let mut settled: Option<f64> = None;
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
    }
    let _ = t0;
    let p_final = sim.run(80.0);
    (settled, p_final)
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
        let (settle, p_final) = track(&mut sim, p1, 384.0);
        eprintln!(
            "from {start} Ω: within 2 % for good after {settle:?} s; final P {p_final:.3} W ({:+.2} % of best fixed), R̂ {:.1} Ω",
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
        let (settle2, p2_final) = track(&mut sim, p2, 320.0);
        eprintln!(
            "after 0.5→0.3 Hz: within 2 % after {settle2:?} s; final P {p2_final:.3} W ({:+.2} %), R̂ {:.1} Ω",
            (p2_final / p2 - 1.0) * 100.0,
            r_hat(&sim)
        );
        // ln(95/43) ≈ 0.8: three bounded steps plus the fine approach; bound 10 cycles.
        assert!(settle2.is_some_and(|t| t <= 160.0) && p2_final >= 0.98 * p2);
        sim.run(T_AMP - sim.t);
        assert!((sim.t - T_AMP).abs() < 1e-6);
        let (settle3, p3_final) = track(&mut sim, p3, 160.0 - 32.0);
        eprintln!(
            "after 1→2 m/s²: within 2 % after {settle3:?} s; final P {p3_final:.3} W ({:+.2} %), R̂ {:.1} Ω",
            (p3_final / p3 - 1.0) * 100.0,
            r_hat(&sim)
        );
        assert!(settle3.is_some_and(|t| t <= 64.0) && p3_final >= 0.98 * p3);
    }
}
