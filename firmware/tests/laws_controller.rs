//! The new laws inside the full current-loop step (`Controller::step`: ADC codes, encoder PLL,
//! PI loops, SVPWM) at a steady shaft speed, on the minimal three-phase plant of
//! `common/mod.rs`: run-time switching between laws, and the one-way clip against a
//! controller that asks for motoring.

mod common;

use common::Plant;
use regen_fw::laws::{LawKind, LtiParams};
use regen_fw::{Config, Controller, Mode};

/// Runs `ctl` for `seconds` at ẋ; returns the mean terminal power over the second half, W
/// (`−Σ e_x·i_x − R·Σ i_x²`, power out of the machine's terminals).
fn run(ctl: &mut Controller, pl: &mut Plant, xdot: f64, seconds: f64) -> f64 {
    let r = ctl.config().r_phase_ohm as f64;
    let (mut p_sum, mut count) = (0.0, 0usize);
    pl.run(ctl, xdot, seconds, |e, i| {
        p_sum += (0..3).map(|x| -e[x] * i[x] - r * i[x] * i[x]).sum::<f64>();
        count += 1;
    });
    p_sum / count as f64
}

/// Terminal power of an emulated resistor at speed ω: 3/2·R_L·(K_e·ω/(R+R_L))².
fn p_resistor(cfg: &Config, xdot: f64) -> f64 {
    let e = cfg.ke_v_s_per_rad as f64 * xdot / cfg.lead_m_per_rad as f64;
    let rl = cfg.r_load_ohm as f64;
    let i = e / (cfg.r_phase_ohm as f64 + rl);
    1.5 * rl * i * i
}

#[test]
fn laws_switch_at_run_time() {
    let xdot = 0.1;
    let base = Config {
        r_load_ohm: 50.0,
        i_max_a: 15.0,
        i_trip_a: 30.0,
        ..Config::default()
    };
    let mut ctl = Controller::new(&base).unwrap();
    ctl.set_mode(Mode::Run).unwrap();
    let mut pl = Plant::new();
    let want = p_resistor(&base, xdot);
    let p_res = run(&mut ctl, &mut pl, xdot, 0.2);
    // Impedance with neither L nor C is the resistor; tracking starts at r_load_ohm with the
    // first half of its dither cycle (8 s, far longer than this run) at R_L·e^{+a}.
    for kind in [LawKind::Impedance, LawKind::Tracking, LawKind::Resistor] {
        ctl.set_config(&Config { law: kind, ..base }).unwrap();
        let want = if kind == LawKind::Tracking {
            p_resistor(
                &Config {
                    r_load_ohm: base.r_load_ohm * (base.trk_dither as f64).exp() as f32,
                    ..base
                },
                xdot,
            )
        } else {
            want
        };
        assert_eq!(ctl.mode(), Mode::Run);
        let p = run(&mut ctl, &mut pl, xdot, 0.2);
        assert_eq!(ctl.fault(), None);
        // 2 %: ADC quantisation (12 mA/LSB against ~1.6 A) and the PLL's speed ripple.
        assert!(
            (p / want - 1.0).abs() < 0.02,
            "{}: {p:.3} W vs {want:.3} W (resistor law measured {p_res:.3} W)",
            kind.name()
        );
    }
    // A refused change leaves the law and its parameters in force.
    let bad = Config {
        law: LawKind::Impedance,
        c_load_f: f32::NAN,
        ..base
    };
    assert_eq!(ctl.set_config(&bad).unwrap_err().field, "c_load_f");
    assert_eq!(ctl.config().law, LawKind::Resistor);
}

#[test]
fn one_way_clip_holds_in_the_current_loop() {
    // A "controller" that asks for motoring: i_q* = +0.05 A per rad/s of shaft speed
    // (same sign as e_q, so power would flow from the bus into the machine).
    let mut opt = LtiParams::default();
    opt.d[1] = 0.05;
    // ω_m = 19.6 rad/s → 0.98 A asked; e_q = 18.5 V + R·i stays inside the 39 V voltage
    // circle of a 72 V bus.
    let xdot = 0.05;
    // Current limit raised: the one-way clip is under test, not the rating.
    let two = Config {
        law: LawKind::TwoWay,
        opt,
        i_max_a: 15.0,
        i_trip_a: 30.0,
        ..Config::default()
    };
    let mut ctl = Controller::new(&two).unwrap();
    ctl.set_mode(Mode::Run).unwrap();
    let mut pl = Plant::new();
    let p_two = run(&mut ctl, &mut pl, xdot, 0.2);
    let mut ctl1 = Controller::new(&Config {
        law: LawKind::OneWay,
        ..two
    })
    .unwrap();
    ctl1.set_mode(Mode::Run).unwrap();
    let p_one = run(&mut ctl1, &mut Plant::new(), xdot, 0.2);
    // Two-way motors: −3/2·(e·i + R·i²) with e = 18.5 V, i = 0.98 A ≈ −31 W.
    let e = two.ke_v_s_per_rad as f64 * xdot / two.lead_m_per_rad as f64;
    let i = 0.05 * xdot / two.lead_m_per_rad as f64;
    let want_two = -1.5 * (e * i + two.r_phase_ohm as f64 * i * i);
    assert!(
        (p_two / want_two - 1.0).abs() < 0.02,
        "{p_two} vs {want_two}"
    );
    // One-way: the command is clipped to zero; what remains is the current loop's ripple
    // around zero (a few mA): |P| < 3/2·e·(half an ADC LSB, 6 mA) ≈ 0.17 W.
    assert!(p_one > -0.17, "one-way drew {p_one} W");
}
