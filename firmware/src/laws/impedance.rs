//! Emulated impedance: each phase behaves as if a series `R_L`–`L_L`–`C_L` branch were wired
//! across it (star), a resonant load. With the machine's own resistance `R` the branch
//! current obeys
//!
//! `L_L·di/dt = −e − (R + R_L)·i − v_C`, `C_L·dv_C/dt = i`,
//!
//! i.e. `I(s) = −E(s) / (R + R_L + s·L_L + 1/(s·C_L))`, applied on the q axis (`e = e_q`,
//! `i = i_q*`, `i_d* = 0`). `L_L = 0` means no inductor, `C_L = 0` means no capacitor (a short
//! in its place); both zero is exactly the [`super::Resistor`] law.
//!
//! The machine's own inductance `L` is *not* part of the emulated branch: the current loop
//! makes the machine's `L` invisible at the frequencies of interest (its bandwidth is 1 kHz,
//! the structure moves below 1 Hz), so `L_L` is the whole emulated inductance; add the
//! machine's `L` to it if the passive circuit is what you want to mimic.
//!
//! Mechanically (force on the screw `f = −c₀·Y(s)·ẋ` with `c₀ = 3/2·K_e²/l²` and `Y` the branch
//! admittance): well below the branch resonance a capacitor gives an apparent **mass**
//! `c₀·C_L`, a dominant inductor gives an apparent **stiffness** `c₀/L_L`; near
//! `1/√(L_L·C_L)` the branch is resistive (`R + R_L`) and damps most.
//!
//! Discretisation: trapezoidal (Tustin) state-space equivalent at the law rate
//! (`Config::law_rate_hz`, decimated from the loop), computed in `f32` with `+ − × ÷` only
//! (the parameters are `f32` anyway; no soft-float `f64` is linked into the board image for
//! it): a few `f32` roundings (≈ 10⁻⁷ relative) per coefficient, the same on host and board.

use super::lti::{decimation, Lti, LtiParams, M, N};
use super::{CommandLaw, LawInput};
use crate::frames::Dq;
use crate::fx::Q;

/// Emulated series R–L–C load.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Impedance {
    filt: Lti,
    decim: u32,
    count: u32,
    held: Q,
}

/// The continuous branch as a state space (states `[i, v_C]` with an inductor, `[v_C, 0]`
/// without), input `e`, output `i`.
fn continuous(rt: f32, l: f32, c: f32) -> ([[f32; 2]; 2], [f32; 2], [f32; 2], f32) {
    let inv_c = if c > 0.0 { 1.0 / c } else { 0.0 };
    if l > 0.0 {
        (
            [[-rt / l, -1.0 / l], [inv_c, 0.0]],
            [-1.0 / l, 0.0],
            [1.0, 0.0],
            0.0,
        )
    } else {
        // i = −(e + v_C)/R_t, dv_C/dt = i/C.
        let g = 1.0 / rt;
        (
            [[-g * inv_c, 0.0], [0.0, 0.0]],
            [-g * inv_c, 0.0],
            [-g, 0.0],
            -g,
        )
    }
}

/// Tustin equivalent of the branch at period `ts`, as filter parameters (input 0 = `e_q`).
#[allow(clippy::needless_range_loop)]
pub fn discretise(r: f32, r_load: f32, l_load: f32, c_load: f32, ts: f32) -> LtiParams {
    let (a, b, c, d) = continuous(r + r_load, l_load, c_load);
    let h = ts / 2.0;
    // M = (I − h·A)⁻¹ (2×2).
    let (m00, m01, m10, m11) = (
        1.0 - h * a[0][0],
        -h * a[0][1],
        -h * a[1][0],
        1.0 - h * a[1][1],
    );
    let det = m00 * m11 - m01 * m10;
    let mi = [[m11 / det, -m01 / det], [-m10 / det, m00 / det]];
    // P = I + h·A
    let p = [
        [1.0 + h * a[0][0], h * a[0][1]],
        [h * a[1][0], 1.0 + h * a[1][1]],
    ];
    let mut out = LtiParams::default();
    for i in 0..2 {
        for j in 0..2 {
            out.a[i * N + j] = mi[i][0] * p[0][j] + mi[i][1] * p[1][j];
        }
        let mb = mi[i][0] * b[0] + mi[i][1] * b[1];
        out.b[i * M] = 2.0 * h * mb;
    }
    let cm = [
        c[0] * mi[0][0] + c[1] * mi[1][0],
        c[0] * mi[0][1] + c[1] * mi[1][1],
    ];
    out.c[0] = cm[0];
    out.c[1] = cm[1];
    out.d[0] = d + h * (cm[0] * b[0] + cm[1] * b[1]);
    out
}

impl Impedance {
    /// Law for machine resistance `r`, emulated `r_load`, `l_load` (H, 0 = none), `c_load`
    /// (F, 0 = none), running every `round(pwm_hz/law_rate_hz)` loop periods.
    pub fn new(
        r: f32,
        r_load: f32,
        l_load: f32,
        c_load: f32,
        pwm_hz: f32,
        law_rate_hz: f32,
    ) -> Self {
        let decim = decimation(pwm_hz, law_rate_hz);
        let ts = decim as f32 / pwm_hz;
        let p = discretise(r, r_load, l_load, c_load, ts);
        Impedance {
            filt: Lti::new(&p),
            decim,
            count: 0,
            held: Q::ZERO,
        }
    }

    /// Branch state in SI units (`[i, v_C]` or `[v_C, 0]`).
    pub fn state(&self) -> [f64; N] {
        self.filt.state_f64()
    }
}

impl CommandLaw for Impedance {
    fn command(&mut self, inp: &LawInput) -> Dq {
        if self.count == 0 {
            let u = [inp.e_q, Q::ZERO, Q::ZERO];
            self.held = self.filt.output(&u);
            self.filt.advance(&u);
        }
        self.count += 1;
        if self.count >= self.decim {
            self.count = 0;
        }
        Dq {
            d: Q::ZERO,
            q: self.held,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fx::q;
    use std::f64::consts::TAU;

    fn run_sine(law: &mut Impedance, e_amp: f64, f_hz: f64, pwm: f64, secs: f64) -> (f64, f64) {
        // Returns the in-phase and quadrature parts of i/e over the last 10 periods.
        let n = (secs * pwm) as usize;
        let n_last = (10.0 / f_hz * pwm) as usize;
        let (mut ip, mut qd) = (0.0, 0.0);
        for k in 0..n {
            let t = k as f64 / pwm;
            let e = e_amp * (TAU * f_hz * t).sin();
            let i = law
                .command(&LawInput {
                    e_q: q(e as f32),
                    ..Default::default()
                })
                .q
                .to_num::<f64>();
            if k >= n - n_last {
                ip += i * (TAU * f_hz * t).sin();
                qd += i * (TAU * f_hz * t).cos();
            }
        }
        let s = 2.0 / n_last as f64 / e_amp;
        (ip * s, qd * s)
    }

    /// The steady sinusoidal response equals the admittance 1/(R+R_L+jωL+1/(jωC)).
    #[test]
    fn admittance_matches_circuit() {
        let pwm = 20_000.0;
        for (rl, l, c, f) in [
            (300.0f64, 50.0f64, 2.0e-3f64, 0.5f64),
            (100.0, 0.0, 1.0e-3, 0.5),
            (100.0, 80.0, 0.0, 0.3),
            (306.0, 0.0, 0.0, 0.5),
        ] {
            let mut law = Impedance::new(2.41, rl as f32, l as f32, c as f32, pwm as f32, 1000.0);
            let (re, im) = run_sine(&mut law, 50.0, f, pwm, 40.0);
            let w = TAU * f;
            let x = w * l - if c > 0.0 { 1.0 / (w * c) } else { 0.0 };
            let rt = 2.41 + rl;
            let den = rt * rt + x * x;
            // i = −Y·e, Y = (R_t − jX)/|Z|²; in-phase −R_t/|Z|², quadrature (cos) +X/|Z|²
            // (Tustin warping at ωT = 3e-3 is 1e-6; ZOH hold of 1 ms shifts phase by ωT/2 = 1.6e-3 rad).
            let (want_re, want_im) = (-rt / den, x / den);
            let mag = (want_re.hypot(want_im)).max(1e-9);
            assert!(
                (re - want_re).abs() < 5e-3 * mag && (im - want_im).abs() < 5e-3 * mag + 2e-3 * mag,
                "R_L {rl} L {l} C {c}: got ({re:.6},{im:.6}) want ({want_re:.6},{want_im:.6})"
            );
        }
    }

    /// With neither L nor C the law equals the resistor law to the output resolution.
    #[test]
    fn degenerates_to_resistor() {
        let mut imp = Impedance::new(2.41, 306.0, 0.0, 0.0, 20_000.0, 20_000.0);
        let mut res = crate::laws::Resistor::new(2.41, 306.0);
        for e in [-100.0f32, -3.0, 0.0, 7.5, 88.0] {
            let inp = LawInput {
                e_q: q(e),
                ..Default::default()
            };
            let a = imp.command(&inp).q.to_num::<f32>();
            let b = res.command(&inp).q.to_num::<f32>();
            assert!((a - b).abs() < 4e-5, "{a} vs {b}");
        }
    }
}
