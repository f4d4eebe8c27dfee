//! Optimal-load tracking: an emulated resistor whose `R_L` is adjusted online to maximise the
//! harvested electrical power, by extremum seeking with a square-wave dither on `ln R_L`.
//!
//! One *cycle* lasts `trk_period_s`: during its first half `R_L = R̂·e^{+a}`, during its second
//! `R_L = R̂·e^{−a}` (`a` = `trk_dither`). In each half the first `settle` fraction (one half of
//! the half, so the structure's transient after the switch dies out) is discarded and the
//! terminal power
//!
//! `p = −3/2·(e_q·i_q + R·(i_d² + i_q²))`
//!
//! (power leaving the machine's terminals, i.e. into the drive; the machine's own copper loss
//! excluded) is averaged over the rest with a triangular window. Synchronous demodulation of the square dither gives the
//! relative gradient `g = d ln P / d ln R_L ≈ (P₊ − P₋) / (a·(P₊ + P₋))`, and the integrator
//! moves `ln R̂ ← ln R̂ + clamp(γ·g, ±Δ_max)` (`γ` = `trk_gain`, `Δ_max` = `trk_step_max`),
//! bounded to `[trk_r_min_ohm, trk_r_max_ohm]`. Near the optimum
//! `ln P ≈ ln P* − κ·(ln R − ln R*)²`, so each cycle contracts the error by `1 − 2κγ`; far
//! from it the step is bounded, so the convergence time is about
//! `trk_period_s·(|ln(R_start/R*)|/Δ_max + a few)`. The relative (normalised) gradient makes
//! the law's speed independent of the excitation amplitude. Cycles whose mean power is below
//! `trk_p_min_w` leave `R̂` unchanged (no motion, no information).
//!
//! Everything runs in integers: `R_L = 2^θ` with `θ` in Q16.16 (see [`super::lti::exp2_q`]),
//! the conductance `1/(R + R_L)` is one i128 division per half-cycle.

use super::lti::{div_i128, exp2_q, q_to_state, state_to_q, Coef};
use super::{CommandLaw, LawInput};
use crate::frames::Dq;
use crate::fx::{Gain, Q};

const LOG2_E: f32 = core::f32::consts::LOG2_E;

/// Parameters of the tracking law (SI; see the module text).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackingParams {
    pub r_phase: f32,
    pub r_start: f32,
    pub dither: f32,
    pub period_s: f32,
    pub gain: f32,
    pub step_max: f32,
    pub r_min: f32,
    pub r_max: f32,
    pub p_min_w: f32,
    pub pwm_hz: f32,
}

/// Extremum-seeking load tracker.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tracking {
    // compiled parameters
    r_q32: i64,
    r_gain: Gain,
    half_len: u32,
    settle_len: u32,
    dither: Q,
    k_step: Gain,
    step_max: Q,
    theta_min: Q,
    theta_max: Q,
    p_min: i64,
    // state
    theta: Q,
    plus: bool,
    count: u32,
    acc: i128,
    w_acc: i128,
    p_plus: i64,
    g: Coef,
    cycles: u32,
}

fn log2_f32(x: f32) -> f32 {
    // log2 by exponent extraction and a few Newton steps on 2^y = x (only + − × ÷).
    if x.is_nan() || x <= 0.0 {
        return -30.0;
    }
    if x == f32::INFINITY {
        // Open circuit (R_L = ∞ is a valid load): the top of the f32 range (log2 f32::MAX ≈ 128); the
        // halving loop below would never end on it.
        return 128.0;
    }
    let mut y = 0.0f32;
    let mut m = x;
    while m >= 2.0 {
        m /= 2.0;
        y += 1.0;
    }
    while m < 1.0 {
        m *= 2.0;
        y -= 1.0;
    }
    // m in [1,2): ln m by atanh series, s = (m−1)/(m+1)
    let s = (m - 1.0) / (m + 1.0);
    let s2 = s * s;
    let mut term = s;
    let mut sum = 0.0f32;
    let mut k = 1.0f32;
    while k < 30.0 {
        sum += term / k;
        term *= s2;
        k += 2.0;
    }
    y + 2.0 * sum * LOG2_E
}

fn q_of(v: f32) -> Q {
    crate::numtext::q_of(v)
}

impl Tracking {
    /// A tracker starting at `r_start` (clamped to the bounds).
    pub fn new(p: &TrackingParams) -> Tracking {
        let half = p.period_s / 2.0 * p.pwm_hz;
        let half_len = if half > 4.0 { (half + 0.5) as u32 } else { 4 };
        let a = p.dither * LOG2_E;
        let theta_min = q_of(log2_f32(p.r_min));
        let theta_max = q_of(log2_f32(p.r_max));
        let mut t = Tracking {
            // f32·2^32 is exact (power-of-two scaling): no f64 needed.
            r_q32: (p.r_phase * 4_294_967_296.0) as i64,
            r_gain: Gain::from_f32(p.r_phase),
            half_len,
            settle_len: half_len / 2,
            dither: q_of(a),
            // step (log2) = γ/(a_ln·ln2)… written as γ·log2(e)/a_ln applied to the ratio
            // (P₊−P₋)/(P₊+P₋).
            k_step: Gain::from_f32(if p.dither > 0.0 {
                p.gain * LOG2_E / p.dither
            } else {
                0.0
            }),
            step_max: q_of(p.step_max * LOG2_E),
            theta_min,
            theta_max,
            p_min: (p.p_min_w * 65536.0) as i64,
            theta: Q::ZERO,
            plus: true,
            count: 0,
            acc: 0,
            w_acc: 0,
            p_plus: 0,
            g: Coef(0),
            cycles: 0,
        };
        t.theta = q_of(log2_f32(p.r_start)).clamp(theta_min, theta_max);
        t.set_conductance();
        t
    }

    /// The centre of the dither, `R̂`, Ω.
    pub fn r_hat(&self) -> f32 {
        exp2_q(self.theta) as f32 / 4_294_967_296.0
    }

    /// Completed dither cycles.
    pub fn cycles(&self) -> u32 {
        self.cycles
    }

    fn set_conductance(&mut self) {
        let th = if self.plus {
            self.theta.saturating_add(self.dither)
        } else {
            self.theta.saturating_sub(self.dither)
        };
        let total = exp2_q(th).saturating_add(self.r_q32).max(1);
        // 1/total in Coef (2^-40) from a Q32.32 total: 2^72 / total.
        // total ≥ 1.
        self.g = Coef(div_i128(1i128 << 72, total as u64) as i64);
    }

    fn end_half(&mut self) {
        let mean = if self.w_acc > 0 {
            // 0 < w_acc ≤ span² < 2^63 (span < 2^31 periods).
            div_i128(self.acc, self.w_acc as u64) as i64
        } else {
            0
        };
        if self.plus {
            self.p_plus = mean;
        } else {
            let (pp, pm) = (self.p_plus, mean);
            let sum = pp.saturating_add(pm);
            if sum > 2 * self.p_min {
                // ratio in Q16.16
                let ratio = div_i128(((pp - pm) as i128) << 16, sum as u64); // sum > 0
                let ratio = Q::from_bits(crate::fx::sat_i32(ratio as i64));
                let step = self
                    .k_step
                    .scale(ratio)
                    .clamp(-self.step_max, self.step_max);
                self.theta = self
                    .theta
                    .saturating_add(step)
                    .clamp(self.theta_min, self.theta_max);
            }
            self.cycles = self.cycles.saturating_add(1);
        }
        self.plus = !self.plus;
        self.acc = 0;
        self.w_acc = 0;
        self.count = 0;
        self.set_conductance();
    }
}

impl CommandLaw for Tracking {
    fn command(&mut self, inp: &LawInput) -> Dq {
        // Terminal power of the period, Q16.16 W.
        let ei = (inp.e_q.to_bits() as i64 * inp.i_dq.q.to_bits() as i64) >> 16;
        let i2 =
            ((inp.i_dq.q.to_bits() as i64).pow(2) + (inp.i_dq.d.to_bits() as i64).pow(2)) >> 16;
        let s = ei.saturating_add(self.r_gain.mul_wide(i2));
        let p = -(s + s / 2);
        if self.count >= self.settle_len {
            // Triangular window over the averaging span: the power ripple at twice the
            // excitation frequency leaks into the mean as 1/(f·T)² instead of 1/(f·T).
            let n = (self.count - self.settle_len) as i128;
            let span = (self.half_len - self.settle_len) as i128;
            let w = n.min(span - n) + 1;
            self.acc += p as i128 * w;
            self.w_acc += w;
        }
        self.count += 1;
        if self.count >= self.half_len {
            self.end_half();
        }
        Dq {
            d: Q::ZERO,
            q: -state_to_q(self.g.mul_state(q_to_state(inp.e_q))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frames::Dq;
    use crate::fx::q;

    fn params() -> TrackingParams {
        TrackingParams {
            r_phase: 2.41,
            r_start: 10.0,
            dither: 0.15,
            period_s: 0.2,
            gain: 1.0,
            step_max: 0.25,
            r_min: 1.0,
            r_max: 10_000.0,
            p_min_w: 0.01,
            pwm_hz: 1_000.0,
        }
    }

    #[test]
    fn log2_and_current_are_exact_enough() {
        for x in [0.3f32, 1.0, 2.41, 10.0, 306.0, 1000.0, 9999.0] {
            assert!((log2_f32(x) - x.log2()).abs() < 2e-6, "{x}");
        }
        // Open circuit ends (it used to loop for ever) and sits at the top of the range.
        assert!(log2_f32(f32::INFINITY) >= log2_f32(f32::MAX));
        let open = Tracking::new(&TrackingParams {
            r_start: f32::INFINITY,
            ..params()
        });
        assert!(
            (open.r_hat() - params().r_max).abs() < 0.01 * params().r_max,
            "{}",
            open.r_hat()
        );
        let mut t = Tracking::new(&TrackingParams {
            dither: 0.0,
            r_start: 306.0,
            ..params()
        });
        let i = t.command(&LawInput {
            e_q: q(100.0),
            ..Default::default()
        });
        // θ is Q16.16 log2: R_L resolution 2^-16·ln2 = 1e-5 relative.
        assert!((i.q.to_num::<f32>() + 100.0 / 308.41).abs() < 1e-4);
    }

    /// On a source with internal resistance R_s (a Thevenin source e behind R_s, the machine's
    /// R included in R_s) the power in R_L peaks at R_L = R_s − R… here the law's measured power
    /// (terminal, machine copper excluded) peaks at R_L = R_s. The tracker must find it from
    /// both sides and stay within the dither of it.
    #[test]
    fn finds_matched_load_on_a_thevenin_source() {
        // Source: e_q is the open-circuit emf of a series R_s; the law's current flows through
        // it, so the terminal emf seen is e_q (we model a stiff emf and an extra series
        // resistance R_s in the law's power measurement by reporting e = e0 − R_s·i ... keep
        // it simple: the law sees e_q = e0 and the current it commands, with a real extra
        // resistor R_x in series: i = −e0/(R + R_x + R_L).
        for start in [10.0f32, 1000.0] {
            let r_x = 120.0f32;
            let mut t = Tracking::new(&TrackingParams {
                r_start: start,
                ..params()
            });
            for k in 0..40_000u32 {
                let e0 = 60.0 * if (k / 10) % 2 == 0 { 1.0 } else { -1.0 };
                // The real circuit: e0 behind R_x, the machine's R and the emulated R_L.
                let i_q = q(-e0 / (2.41 + r_x + t.current_r()));
                // The law's emf estimate is the terminal emf e0 + R_x·i (R_x is outside
                // the machine model), so it measures p = 3/2·R_L·i².
                let e_term = e0 + r_x * i_q.to_num::<f32>();
                t.command(&LawInput {
                    e_q: q(e_term),
                    i_dq: Dq { d: Q::ZERO, q: i_q },
                    ..Default::default()
                });
            }
            let r = t.r_hat();
            // optimum of P = 3/2·e0²·R_L/(R + R_x + R_L)² … measured power excludes only R:
            // p = −3/2(e_term·i + R i²) = 3/2 i²·R_L → optimum at R_L = R + R_x.
            let want = 2.41 + r_x;
            assert!(
                (r / want - 1.0).abs() < 0.1,
                "from {start} Ω: R̂ = {r}, want {want} after {} cycles",
                t.cycles()
            );
        }
    }

    /// Invariants under arbitrary (here adversarial, pseudo-random) power readings: R̂ stays in
    /// its bounds and moves by at most `step_max` (ln units) per cycle, plus the Q16.16
    /// rounding of the log2 step (2^-16·ln 2 ≈ 1e-5).
    #[test]
    fn steps_are_bounded_and_r_stays_in_range() {
        let p = TrackingParams {
            r_min: 5.0,
            r_max: 500.0,
            gain: 50.0,
            r_start: 50.0,
            ..params()
        };
        let mut t = Tracking::new(&p);
        let mut seed = 12345u32;
        let mut last = (t.r_hat() as f64).ln();
        let mut last_cycles = 0;
        let mut moved = 0;
        for _ in 0..100_000 {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            // Harvesting-signed current of random size: random positive power readings.
            let e = ((seed >> 3) & 0xFFF) as f32 / 4096.0 * 200.0 - 100.0;
            let i = -e / (5.0 + (seed >> 16) as f32 / 65536.0 * 200.0);
            t.command(&LawInput {
                e_q: q(e),
                i_dq: Dq {
                    d: Q::ZERO,
                    q: q(i),
                },
                ..Default::default()
            });
            if t.cycles() != last_cycles {
                last_cycles = t.cycles();
                let now = (t.r_hat() as f64).ln();
                assert!(
                    (now - last).abs() <= p.step_max as f64 + 2e-5,
                    "{last} → {now}"
                );
                assert!(now >= (5.0f64).ln() - 2e-5 && now <= (500.0f64).ln() + 2e-5);
                if (now - last).abs() > 1e-3 {
                    moved += 1;
                }
                last = now;
            }
        }
        assert!(
            moved > 50,
            "the random readings should have moved R̂ ({moved})"
        );
    }

    impl Tracking {
        fn current_r(&self) -> f32 {
            1.0 / self.g.to_f64() as f32 - 2.41
        }
    }
}
