//! The resistor law in closed loop at a steady shaft speed: the axial force the machine
//! produces must equal `c_e·ẋ`, `c_e = 3/2·K_e²/(l²·(R+R_L))` (amplitude-invariant
//! convention: per-phase peak `K_e`, `T = 3/2·K_e·i_q`, `f = T/l`).
//!
//! The plant here is deliberately minimal and independent of `hal-sim`: three star-connected
//! phases `L·di/dt = v_xn − R·i − e_x`, averaged inverter `v_x = d_x·V_bus` applied one
//! period after the sample, ideal 12-bit ADC codes and encoder counts.

use regen_fw::fx::Angle;
use regen_fw::{Config, Controller, Mode, RawSample};

struct Plant {
    i: [f64; 3],
    theta_m: f64,
    pending: [f64; 3],
}

fn run(cfg: &Config, xdot: f64, seconds: f64) -> (f64, f64) {
    let mut ctl = Controller::new(cfg).unwrap();
    ctl.set_mode(Mode::Run).unwrap();
    let (r, l, ke, p) = (
        cfg.r_phase_ohm as f64,
        cfg.l_phase_h as f64,
        cfg.ke_v_s_per_rad as f64,
        cfg.pole_pairs as f64,
    );
    let lead = cfg.lead_m_per_rad as f64;
    let ts = 1.0 / cfg.pwm_hz as f64;
    let w_m = xdot / lead;
    let v_bus = 72.0;
    let mut pl = Plant {
        i: [0.0; 3],
        theta_m: 0.0,
        pending: [0.5; 3],
    };
    let n = (seconds / ts) as usize;
    let (mut f_sum, mut count) = (0.0, 0usize);
    let a = (-r / l * ts).exp();
    for k in 0..n {
        let code = |i: f64| {
            ((i / cfg.amps_per_count as f64) + cfg.adc_zero_code as f64)
                .round()
                .clamp(0.0, 4095.0) as u16
        };
        let counts = (pl.theta_m / std::f64::consts::TAU * cfg.encoder_cpr as f64).floor() as i64;
        let s = RawSample {
            i_abc: [code(pl.i[0]), code(pl.i[1]), code(pl.i[2])],
            v_bus: (v_bus / cfg.volts_per_count as f64).round() as u16,
            encoder: counts as u16,
        };
        let out = ctl.step(&s);
        // Apply the previous period's duties (one-period delay), then these become pending.
        let d = pl.pending;
        pl.pending = if out.enable {
            out.duties.map(|x| x.to_num::<f64>())
        } else {
            [0.5; 3]
        };
        let vx = d.map(|x| x * v_bus);
        let mean = (vx[0] + vx[1] + vx[2]) / 3.0;
        // Back-emf at the middle of the period (speed constant, angle advances linearly).
        let th = p * (pl.theta_m + 0.5 * w_m * ts);
        let th = th + Angle::from_radians(cfg.encoder_offset_rad as f64).radians();
        let e = [
            0.0,
            -std::f64::consts::TAU / 3.0,
            std::f64::consts::TAU / 3.0,
        ]
        .map(|s| -ke * w_m * (th + s).sin());
        for x in 0..3 {
            // Exact solution of L di/dt = u − R i over the period with u held.
            let u = vx[x] - mean - e[x];
            pl.i[x] = a * pl.i[x] + (1.0 - a) * u / r;
        }
        pl.theta_m += w_m * ts;
        if k > n / 2 {
            // Electromagnetic force on the screw axis from the instantaneous power balance:
            // f·ẋ = −Σ e_x·i_x (power into the machine's emf sources is −f·ẋ).
            let p_emf: f64 = (0..3).map(|x| e[x] * pl.i[x]).sum();
            f_sum -= p_emf / xdot;
            count += 1;
        }
    }
    let c_e = 1.5 * ke * ke / (lead * lead * (r + cfg.r_load_ohm as f64));
    (f_sum / count as f64, c_e * xdot)
}

#[test]
fn resistor_law_force_is_ce_times_velocity() {
    // Speeds keep e_q = K_e·ẋ/l ≤ 30 V inside the 39 V voltage circle of the 72 V test bus.
    for (r_load, xdot) in [
        (306.0f32, 0.08f64),
        (10.0, 0.05),
        (2.0, 0.047),
        (50.0, -0.08),
    ] {
        // Current limit raised: this checks the law, not the limit.
        let cfg = Config {
            r_load_ohm: r_load,
            i_max_a: 15.0,
            i_trip_a: 30.0,
            ..Config::default()
        };
        let (f, want) = run(&cfg, xdot, 0.2);
        // The PI loop has integral action, so the mean q current equals the law's reference;
        // the reference comes from the PLL speed, exact in the mean at constant speed. What
        // remains: ADC quantisation (12 mA/LSB, dithered by the rotating currents) and Q16.16
        // rounding of the conductance and K_e (< 1e-5). Allow 1 % plus the force of half an
        // ADC LSB of q current.
        let lsb_force = 1.5 * cfg.ke_v_s_per_rad as f64 * cfg.amps_per_count as f64
            / 2.0
            / cfg.lead_m_per_rad as f64;
        assert!(
            (f - want).abs() < 0.01 * want.abs() + lsb_force,
            "R_L = {r_load} Ω, ẋ = {xdot} m/s: force {f:.2} N, c_e·ẋ = {want:.2} N"
        );
        // Sign: the device resists the motion (power flows out of the structure).
        assert!(f * xdot > 0.0);
    }
}

#[test]
fn open_and_short_are_the_limits() {
    let open = Config {
        r_load_ohm: f32::INFINITY,
        ..Config::default()
    };
    let (f, _) = run(&open, 0.1, 0.1);
    // Open: zero current commanded; what remains is the loop's error within the ADC's
    // resolution: at most half an LSB (6 mA) of q current, 3/2·K_e·6 mA/l = 3.3 N.
    let lsb_force = 1.5 * open.ke_v_s_per_rad as f64 * open.amps_per_count as f64
        / 2.0
        / open.lead_m_per_rad as f64;
    assert!(
        f.abs() < lsb_force,
        "open-circuit force {f} N (bound {lsb_force:.2} N)"
    );
    let short = Config {
        r_load_ohm: 0.0,
        i_max_a: 15.0,
        i_trip_a: 30.0,
        ..Config::default()
    };
    let (f, want) = run(&short, 0.02, 0.2);
    assert!(
        (f - want).abs() < 0.01 * want.abs() + 2.0,
        "short: {f} vs {want}"
    );
}

#[test]
fn current_limit_clips_the_force_at_the_rating() {
    // Default limit = rated torque 2.74 N·m → f_rat = 2.74/l = 1,076 N. At 2 Ω and 5.25 cm/s
    // (the rise-time test) the law asks for 2.4 kN; the force must sit at the rating.
    let cfg = Config {
        r_load_ohm: 2.0,
        ..Config::default()
    };
    let (f, want) = run(&cfg, 0.0525, 0.2);
    let f_rat = 1.5 * cfg.ke_v_s_per_rad as f64 * cfg.i_max_a as f64 / cfg.lead_m_per_rad as f64;
    assert!(want > 2.0 * f_rat);
    assert!((f_rat - 1076.0).abs() < 2.0, "rating {f_rat}");
    // Same ADC/rounding allowance as the law test.
    assert!(
        (f - f_rat).abs() < 0.01 * f_rat + 2.0,
        "clipped force {f} vs rating {f_rat}"
    );
}
