//! Closed-loop simulator: energy balance and the TMD power against the harmonic balance.
//! Runs are short (a few simulated seconds at 20 kHz); hal-sim and regen-fw are built with
//! opt-level 3 in the dev/test profile (workspace Cargo.toml), so this file takes seconds.

use hal_sim::analytic::{tmd_power, DampingFormula};
use hal_sim::plant::{Drive, Excitation, Motion};
use hal_sim::scenario::Scenario;
use hal_sim::sim::Energy;

fn check_balance(e: &Energy, what: &str) {
    // The bound: 0.5 % of the largest energy flow over any run.
    assert!(
        e.relative_residual().abs() < 5e-3,
        "{what}: residual {:.3e} J = {:.3} % of the flows; ledger {e:#?}",
        e.residual(),
        100.0 * e.relative_residual()
    );
}

#[test]
fn energy_balances_for_imposed_motion_structure_and_brake() {
    // Imposed sine with friction ripple and screw efficiency on, sensors noisy.
    let mut sc = Scenario::imposed(
        Motion::Sine {
            amplitude_m: 0.075,
            freq_hz: 0.5,
        },
        5.0,
        1.0,
    );
    sc.screw.efficiency = 0.9;
    sc.screw.p3 = 0.1;
    sc.screw.p5 = 0.05;
    sc.screw.b_nms = 1e-4;
    sc.sensors.current_noise_a = 0.02;
    sc.sensors.vbus_noise_v = 0.2;
    let mut sim = sc.build().unwrap();
    sim.run_for(sc.duration_s);
    let e = sim.energy();
    check_balance(&e, "imposed sine");
    assert!(e.screw_loss > 0.0 && e.friction_loss > 0.0 && e.copper_loss > 0.0);
    assert!(sim.controller().fault().is_none());

    // TMD under base excitation, bus without a source: the bus charges, the brake chopper
    // regulates it through the firmware's hysteresis.
    let mut sc = Scenario::tmd(50.0);
    sc.duration_s = 3.0;
    sc.bus.source_v = None;
    sc.bus.capacitance_f = 2e-4;
    sc.bus.initial_v = 360.0;
    let mut sim = sc.build().unwrap();
    sim.run_for(sc.duration_s);
    let e = sim.energy();
    check_balance(&e, "tmd with brake");
    assert!(e.brake > 0.0, "brake never closed: {e:#?}");
    assert!(sim.controller().fault().is_none());

    // Noise excitation.
    let mut sc = Scenario::tmd(100.0);
    sc.duration_s = 2.0;
    if let Drive::Structure { excitation, .. } = &mut sc.drive {
        *excitation = Excitation::KanaiTajimi {
            s0: 0.01,
            omega_g: 15.0,
            zeta_g: 0.6,
            seed: 7,
        };
    }
    let mut sim = sc.build().unwrap();
    sim.run_for(sc.duration_s);
    check_balance(&sim.energy(), "kanai-tajimi");
}

#[test]
fn tmd_power_matches_harmonic_balance() {
    // The resistor law on the reference TMD (0.5 Hz, 1 m/s²), ripple-free friction so that
    // the harmonic balance's assumptions hold. Tolerance 3 %: the harmonic balance replaces
    // the Coulomb term by its first harmonic (the neglected odd harmonics carry a few % of
    // the friction force, F_c/(m·a0) = 10 % of the drive), the runs average 2 periods after
    // 8 s of settling (the envelope of the start-up transient decays with 2m̄/c̄, at most
    // 1.2 s at 1 kΩ: e^-6.8 leaves 0.1 % of the amplitude), and the firmware's fixed-point speed estimate and current loop add well
    // under 1 %.
    for r_l in [10.0, 100.0, 1000.0] {
        let mut sc = Scenario::tmd(r_l);
        sc.duration_s = 12.0;
        sc.settle_s = 8.0;
        let (p, resid) = hal_sim::cli::sweep::average_power(&sc).unwrap();
        let Drive::Structure { structure, .. } = &sc.drive else {
            unreachable!()
        };
        let a = tmd_power(
            r_l,
            &sc.machine,
            &sc.screw,
            structure,
            1.0,
            0.5,
            DampingFormula::PerPhasePeak,
        );
        assert!(
            (p - a.p_load).abs() < 0.03 * a.p_load,
            "R_L = {r_l}: closed loop {p:.3} W, analytic {:.3} W",
            a.p_load
        );
        assert!(resid.abs() < 5e-3);
    }
}
