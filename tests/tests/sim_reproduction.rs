//! The reference device reproduced (Cassidy, Scruggs & Behrens 2011; numbers from
//! docs/physics.md): sizing indices, the TMD power optimum, the force-range and
//! rise-time tests, and what they say about the K_e convention (docs/simulator.md §K_e).

use hal_sim::analytic::{optimum_load, sizing, tmd_power, DampingFormula, DesignCase};
use hal_sim::plant::{Machine, Motion, Screw};
use hal_sim::scenario::Scenario;

/// K_e per-phase peak that makes our (consistent) 3/2 damping formula equal the paper's 9/4
/// one with K_e = 0.77: 0.77·√(3/2).
fn ke_paper_equivalent() -> f64 {
    0.77 * 1.5f64.sqrt()
}

#[test]
fn sizing_indices_match_the_paper() {
    // Published: c_short ≈ 85,130 N·s/m, f_rat ≈ 1,076 N, {I_c, I_f, I_v, I_m} =
    // {33.9, 0.548, 53.4, 17.3}. J = 1.50e-4 kg·m² and ẋ0 = 0.165 m/s are the reference's
    // back-calculated values, given to 3 digits, so 0.5 % is the tolerance on every index
    // except c_short: our l = 0.016/2π gives 85,390, 0.3 % above the published 85,130
    // (the paper evidently rounded l to 2.55e-3 m/rad: that gives 85,120).
    let m = Machine::default();
    let s = Screw::default();
    let d = DesignCase::default();
    let p = sizing(0.77, &m, &s, &d, DampingFormula::Paper);
    let close = |a: f64, b: f64, tol: f64, what: &str| {
        assert!((a - b).abs() <= tol * b.abs(), "{what}: {a} vs {b}");
    };
    close(p.c_short, 85_130.0, 0.005, "c_short");
    close(p.f_rat, 1_076.0, 0.005, "f_rat");
    close(p.i_c, 33.9, 0.005, "I_c");
    close(p.i_f, 0.548, 0.005, "I_f");
    close(p.i_v, 53.4, 0.005, "I_v");
    close(p.i_m, 17.3, 0.005, "I_m");
    // The physically consistent damping 3/2·K_e²/(R·l²) with the simulator's per-phase peak
    // K_e = 0.77·√(3/2) is the paper's 9/4·0.77²/(R·l²): same c_short, same I_c (the
    // reading under which the paper's formulas are physically right; its K_e = 0.77 is not
    // a per-phase peak constant). f32 storage of K_e: 1e-6 relative.
    let c = sizing(m.ke_v_s_per_rad, &m, &s, &d, DampingFormula::PerPhasePeak);
    close(c.c_short / p.c_short, 1.0, 1e-5, "consistent/paper c_short");
    close(c.i_c, 33.9, 0.005, "consistent I_c");
}

#[test]
fn tmd_optimum_of_the_paper_model_is_near_306_ohm() {
    // The paper's model (9/4, K_e = 0.77, c = p2 = 655 N·s/m, J = 1.5e-4, Coulomb F_c) puts
    // the optimum at 306.3 Ω. Near resonance R_L,opt ≈ (9K_e²/4l²)/c + R = 316 Ω for B = 0;
    // the paper's unstated B and its F_c move it by a few %: we accept ±5 %.
    let m = Machine {
        ke_v_s_per_rad: 0.77,
        ..Default::default()
    };
    let s = Screw::default();
    let st = Default::default();
    let opt = optimum_load(
        |r| tmd_power(r, &m, &s, &st, 1.0, 0.5, DampingFormula::Paper).p_load,
        1.0,
        1e4,
    );
    assert!(
        (opt - 306.3).abs() < 0.05 * 306.3,
        "paper-model optimum {opt:.1} Ω"
    );

    // The same device simulated consistently (per-phase peak K_e = 0.77·√1.5, which gives
    // the paper's damping) in closed loop: the power at 100 Ω, 306 Ω and 1 kΩ shows the
    // maximum at the middle point, and matches the harmonic balance within 3× its measured
    // deviation (+0.168 %, +0.054 %, −0.110 %; argument in sim_closed_loop.rs; 306 Ω, near the
    // optimum, 0.16 %).
    // Residuals measured 8.8e-9, 5.6e-9, 2.7e-9: bound 3e-8.
    let mut p = Vec::new();
    for (r_l, tol) in [(100.0, 5.1e-3), (306.0, 1.6e-3), (1000.0, 3.3e-3)] {
        let mut sc = Scenario::tmd(r_l);
        sc.machine.ke_v_s_per_rad = ke_paper_equivalent();
        let (pw, resid) = hal_sim::cli::sweep::average_power(&sc).unwrap();
        let a = tmd_power(
            r_l,
            &sc.machine,
            &sc.screw,
            &st,
            1.0,
            0.5,
            DampingFormula::PerPhasePeak,
        );
        println!(
            "repro R_L {r_l}: dev {:+.4} %, resid {resid:.3e}",
            100.0 * (pw / a.p_load - 1.0)
        );
        assert!(
            (pw - a.p_load).abs() < tol * a.p_load,
            "{r_l} Ω: {pw} vs {}",
            a.p_load
        );
        assert!(resid.abs() < 3e-8, "{r_l} Ω: residual {resid:.3e}");
        p.push(pw);
    }
    assert!(p[1] > p[0] && p[1] > p[2], "{p:?}");

    // The other reading (0.77 N·m per ampere of peak phase current, K_e = 0.513) would put
    // the optimum of the same TMD near (3/2·K_e²/l²)/c − R ≈ 90 Ω, where the bench measured
    // far less power than at 300 Ω: the measured maximum at 300 Ω rules it out.
    let m513 = Machine {
        ke_v_s_per_rad: 0.77 * 2.0 / 3.0,
        ..Default::default()
    };
    let opt513 = optimum_load(
        |r| tmd_power(r, &m513, &s, &st, 1.0, 0.5, DampingFormula::PerPhasePeak).p_load,
        1.0,
        1e4,
    );
    assert!(opt513 < 150.0, "0.513 reading optimum {opt513:.1} Ω");
}

/// Peak |force| (total, electromagnetic) over a 0.1 Hz, 7.5 cm sine stroke at load `r_l`,
/// with the default current limit or a raised one, and the energy residual.
fn force_range_peak(r_l: f64, i_max: Option<f32>) -> (f64, f64, f64, bool) {
    let mut sc = Scenario::imposed(
        Motion::Sine {
            amplitude_m: 0.075,
            freq_hz: 0.1,
        },
        r_l,
        10.0,
    );
    if let Some(i) = i_max {
        sc.firmware.i_max_a = i;
        sc.firmware.i_trip_a = 4.0 * i;
        // Beyond the device rating on purpose: the force trip (protect.rs) off.
        sc.law.set.insert("f_trip_n".into(), f64::INFINITY);
    }
    sc.record.channels.clear();
    let mut sim = sc.build().unwrap();
    // The stroke starts at full speed while the firmware's speed observer starts from rest:
    // skip its start-up (10 ms at 100 Hz bandwidth) by taking the peak from 1 s on, which
    // still holds both velocity peaks (t = 5 s and 10 s).
    sim.run_for(1.0);
    let (mut peak, mut peak_em) = (0.0f64, 0.0f64);
    for _ in 0..(9.0 / sim.period()) as u64 {
        sim.step();
        peak = peak.max(sim.force().0.abs());
        peak_em = peak_em.max(sim.force().1.abs());
    }
    (
        peak,
        peak_em,
        sim.energy().relative_residual(),
        sim.controller().fault().is_none(),
    )
}

#[test]
fn force_range_test_is_the_rated_current_clip() {
    // Bench: at 1 Ω, 0.1 Hz, 7.5 cm (ẋ peak 4.71 cm/s) the force "nearly reaches"
    // f_rat = 1,076 N. With K_e = 0.943 (the reading the TMD optimum supports, above) the
    // resistor law asks for 3/2·K_e²/(l²·3.41 Ω)·ẋ = 2.84 kN: a drive limited at the rated
    // torque (2.74 N·m, i_q = 1.94 A, our default i_max) clips the electromagnetic force at
    // f_rat, which is what the bench saw. Unclipped, the force would have been 2.6× the
    // rating. The clip acts on the current-reference magnitude exactly; the current loop's
    // ripple (ADC LSB 12 mA of 1.94 A) allows 2 %.
    let f_rat = 2.74 / (0.016 / std::f64::consts::TAU);
    let (peak, peak_em, resid, ok) = force_range_peak(1.0, None);
    assert!(ok && resid.abs() < 5e-3);
    assert!(
        (peak_em - f_rat).abs() < 0.02 * f_rat,
        "clipped EM peak {peak_em:.0} N vs {f_rat:.0} N"
    );
    // Total = EM + friction (F_c + p2·ẋ ≈ 71 N) + inertia: "nearly" the rating, not 2.6×.
    assert!(
        peak > f_rat && peak < 1.15 * f_rat,
        "total peak {peak:.0} N"
    );
    let (_, unclipped, resid, ok) = force_range_peak(1.0, Some(10.0));
    assert!(ok && resid.abs() < 5e-3);
    assert!(
        unclipped > 2.4 * f_rat,
        "unclipped EM peak {unclipped:.0} N"
    );
    // Open terminals: only friction remains (F_c + p2·ẋ = 71 N).
    let (open, _, _, _) = force_range_peak(f64::INFINITY, None);
    assert!((open - 71.0).abs() < 3.0, "open-circuit peak {open:.1} N");
}

/// Rise of the electromagnetic force after switching open → 2 Ω mid-stroke on a 0.25 Hz,
/// 5.25 cm triangle: (10–90 % rise time s, overshoot fraction, final force N).
fn rise(p_only: bool) -> (f64, f64, f64) {
    let mut sc = Scenario::imposed(
        Motion::Triangle {
            amplitude_m: 0.0525,
            freq_hz: 0.25,
        },
        f64::INFINITY,
        1.0,
    );
    sc.record.channels.clear();
    let mut sim = sc.build().unwrap();
    if p_only {
        hal_sim::sim::p_only(sim.controller_mut());
    }
    // Mid-stroke: t = 0 is x = 0 rising at constant speed; switch at 0.2 s.
    sim.run_for(0.2);
    let mut cfg = *sim.controller().config();
    cfg.r_load_ohm = 2.0;
    sim.controller_mut().set_config(&cfg).unwrap();
    if p_only {
        hal_sim::sim::p_only(sim.controller_mut());
    }
    let mut f = Vec::new();
    for _ in 0..(0.05 / sim.period()) as usize {
        sim.step();
        f.push(sim.force().1);
    }
    let fin = f[f.len() - 200..].iter().sum::<f64>() / 200.0;
    let t10 = f.iter().position(|x| *x >= 0.1 * fin).unwrap();
    let t90 = f.iter().position(|x| *x >= 0.9 * fin).unwrap();
    let peak = f.iter().cloned().fold(0.0, f64::max);
    ((t90 - t10) as f64 * sim.period(), peak / fin - 1.0, fin)
}

#[test]
fn rise_time_after_switching_to_2_ohm() {
    // The bench (analog P-only drive commanded by a dSPACE loop) reached rated force in about
    // 6 ms with ringing. Our PI loop at 1 kHz bandwidth is a first-order ωc/(s+ωc) behind
    // 1.5 periods of delay plus the 100 Hz speed observer's (already converged) estimate:
    // 10–90 % in 2.2/ωc = 0.35 ms, accept < 1 ms; overshoot small (< 20 %).
    let (tr, os, fin) = rise(false);
    // Expected final force: 3/2·K_e²·ẋ/(l²·(R+2)) with ẋ = 4·A·f = 5.25 cm/s is 2.45 kN,
    // above the rating: the current limit holds it at f_rat = 1,076 N ("rated force
    // reached", as on the bench).
    let want = 2.74 / (0.016 / std::f64::consts::TAU);
    assert!(
        (fin - want).abs() < 0.02 * want,
        "final {fin:.0} N vs {want:.0} N"
    );
    assert!(tr < 1e-3, "PI rise {tr:e} s");
    assert!(os < 0.2, "PI overshoot {os}");
    // P-only at the same Kp = L·ωc: no integral, so the current settles at Kp/(Kp+R) of its
    // command (37.7/40.1 = 94 %) and rises faster than 1 ms too; the bench's 6 ms is its
    // outer (dSPACE) loop's doing, not the current loop's.
    let (tr_p, _, fin_p) = rise(true);
    let kp = 6e-3 * std::f64::consts::TAU * 1000.0;
    assert!(
        (fin_p / fin - kp / (kp + 2.41)).abs() < 0.02,
        "P-only final {fin_p:.0} N"
    );
    assert!(tr_p < 1e-3, "P-only rise {tr_p:e}");
    println!("rise 10-90 %: PI {tr:.2e} s (overshoot {os:.3}), P-only {tr_p:.2e} s, final {fin:.0} / {fin_p:.0} N");
}
