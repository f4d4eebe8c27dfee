//! The minimal three-phase plant the firmware's closed-loop tests share, deliberately
//! independent of `hal-sim`: three star-connected phases `L·di/dt = v_xn − R·i − e_x` solved
//! exactly over each period, an averaged inverter `v_x = d_x·V_bus` applied one period after
//! the sample, a constant shaft speed, ideal 12-bit ADC codes and encoder counts.

use regen_fw::fx::Angle;
use regen_fw::{Controller, RawSample};
use std::f64::consts::TAU;

/// The bus voltage of the test plant, V.
pub const V_BUS: f64 = 72.0;

/// The plant's state; it carries over between runs, so the encoder never jumps.
#[derive(Default)]
pub struct Plant {
    i: [f64; 3],
    theta_m: f64,
    pending: [f64; 3],
}

impl Plant {
    /// At rest, no current, the pending duties at 50 % (zero voltage).
    pub fn new() -> Plant {
        Plant {
            pending: [0.5; 3],
            ..Plant::default()
        }
    }

    /// Runs `ctl` against the plant for `seconds` at the screw speed `xdot` (m/s). Every
    /// period of the second half, `each(e, i)` sees the phase back-emfs at mid-period and the
    /// phase currents at its end.
    pub fn run(
        &mut self,
        ctl: &mut Controller,
        xdot: f64,
        seconds: f64,
        mut each: impl FnMut(&[f64; 3], &[f64; 3]),
    ) {
        let cfg = *ctl.config();
        let (r, l, ke, p) = (
            cfg.r_phase_ohm as f64,
            cfg.l_phase_h as f64,
            cfg.ke_v_s_per_rad as f64,
            cfg.pole_pairs as f64,
        );
        let ts = 1.0 / cfg.pwm_hz as f64;
        let w_m = xdot / cfg.lead_m_per_rad as f64;
        let offset = Angle::from_radians(cfg.encoder_offset_rad as f64).radians();
        let n = (seconds / ts) as usize;
        let a = (-r / l * ts).exp();
        let code = |i: f64| {
            ((i / cfg.amps_per_count as f64) + cfg.adc_zero_code as f64)
                .round()
                .clamp(0.0, 4095.0) as u16
        };
        for k in 0..n {
            let counts = (self.theta_m / TAU * cfg.encoder_cpr as f64).floor() as i64;
            let s = RawSample {
                i_abc: self.i.map(code),
                v_bus: (V_BUS / cfg.volts_per_count as f64).round() as u16,
                encoder: counts as u16,
            };
            let out = ctl.step(&s);
            // Apply the previous period's duties (one-period delay); these become pending.
            let d = self.pending;
            self.pending = if out.enable {
                out.duties.map(|x| x.to_num::<f64>())
            } else {
                [0.5; 3]
            };
            let vx = d.map(|x| x * V_BUS);
            let mean = (vx[0] + vx[1] + vx[2]) / 3.0;
            // Back-emf at the middle of the period (speed constant, angle linear in time).
            let th = p * (self.theta_m + 0.5 * w_m * ts) + offset;
            let e = [0.0, -TAU / 3.0, TAU / 3.0].map(|s| -ke * w_m * (th + s).sin());
            for x in 0..3 {
                // Exact solution of L di/dt = u − R i over the period with u held.
                let u = vx[x] - mean - e[x];
                self.i[x] = a * self.i[x] + (1.0 - a) * u / r;
            }
            self.theta_m += w_m * ts;
            if k > n / 2 {
                each(&e, &self.i);
            }
        }
    }
}
