//! Record the raw samples of a closed-loop run, for the host/Cortex-M4 bit-identity check.
//!
//! `cargo run -p regen-fw --example record_vectors -- firmware/m4check/vectors.bin`
//!
//! Plant: three star-connected phases (R, L, sinusoidal back-emf) on an averaged inverter with
//! a one-period delay, the shaft moving sinusoidally (0.8 Hz, 4 cm: up to 0.2 m/s, enough to
//! drive the PI loops into the voltage limit near the peaks), ADC codes with deterministic
//! noise of ±2 LSB, and the encoder. The controller runs the default configuration in Run mode
//! with an R_L step from 306 Ω to 2 Ω halfway (so the current limit acts too).

use std::f64::consts::TAU;

use regen_fw::selftest::STEP_BYTES;
use regen_fw::{Config, Controller, Mode, RawSample};

const STEPS: usize = 12_000;

fn main() {
    let path = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "vectors.bin".into());
    let cfg = Config::default();
    let mut ctl = Controller::new(&cfg).unwrap();
    ctl.set_mode(Mode::Run).unwrap();
    let (r, l, ke, p) = (
        cfg.r_phase_ohm as f64,
        cfg.l_phase_h as f64,
        cfg.ke_v_s_per_rad as f64,
        cfg.pole_pairs as f64,
    );
    let ts = 1.0 / cfg.pwm_hz as f64;
    let lead = cfg.lead_m_per_rad as f64;
    let (amp, f) = (0.04, 0.8);
    let v_bus = 72.0;
    let a = (-r / l * ts).exp();
    let mut i = [0.0f64; 3];
    let mut pending = [0.5f64; 3];
    let mut lcg: u32 = 12345;
    let mut noise = || {
        lcg = lcg.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        ((lcg >> 16) % 5) as f64 - 2.0
    };
    let mut out = Vec::with_capacity(STEPS * STEP_BYTES);
    for k in 0..STEPS {
        if k == STEPS / 2 {
            ctl.set_config(&Config {
                r_load_ohm: 2.0,
                ..cfg
            })
            .unwrap();
        }
        let t = k as f64 * ts;
        let theta_m = amp * (TAU * f * t).sin() / lead;
        let w_m = amp * TAU * f * (TAU * f * t).cos() / lead;
        let mut code = |x: f64| {
            ((x / cfg.amps_per_count as f64) + cfg.adc_zero_code as f64 + noise())
                .round()
                .clamp(0.0, 4095.0) as u16
        };
        let s = RawSample {
            i_abc: [code(i[0]), code(i[1]), code(i[2])],
            v_bus: (v_bus / cfg.volts_per_count as f64 + noise()).round() as u16,
            encoder: ((theta_m / TAU * cfg.encoder_cpr as f64).floor() as i64) as u16,
        };
        for v in [s.i_abc[0], s.i_abc[1], s.i_abc[2], s.v_bus, s.encoder] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        let act = ctl.step(&s);
        let d = pending;
        pending = if act.enable {
            act.duties.map(|x| x.to_num::<f64>())
        } else {
            [0.5; 3]
        };
        let vx = d.map(|x| x * v_bus);
        let mean = (vx[0] + vx[1] + vx[2]) / 3.0;
        let th = p * (theta_m + 0.5 * w_m * ts);
        for (x, sh) in [0.0, -TAU / 3.0, TAU / 3.0].iter().enumerate() {
            let e = -ke * w_m * (th + sh).sin();
            let u = vx[x] - mean - e;
            i[x] = a * i[x] + (1.0 - a) * u / r;
        }
    }
    assert!(
        ctl.fault().is_none(),
        "the recorded run must not trip: {:?}",
        ctl.fault()
    );
    std::fs::write(&path, &out).unwrap();
    eprintln!("wrote {STEPS} steps ({} bytes) to {path}", out.len());
}
