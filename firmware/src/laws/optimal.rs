//! Causal optimal control for stochastic excitation (two-way), and its one-way
//! (regenerative-only) constrained version.
//!
//! The controller is an observer-based state feedback designed on the host (LQG/H2 on the
//! linearised TMD + transducer + excitation-filter model, see `hal_sim::study::design_lqg`) and
//! loaded as parameters: a discrete state space at the law rate with inputs
//! `u = [x (m), ω_m (rad/s), i_q applied at the previous law step (A)]` and output `i_q*`
//! (`ξ[k+1] = A·ξ[k] + B·u[k]`, `i_q*[k] = C·ξ[k] + D·u[k]`, `D[2]` ignored so the loop has no
//! algebraic cycle). Feeding back the *applied* current keeps the observer right when the
//! one-way clip or a limit changed the command.
//!
//! **Two-way** applies `i_q*` as is: at times `i_q*·e_q > 0`, power flows from the bus into
//! the machine (the drive works as a motor for a moment) because that raises the average
//! harvested power under broadband excitation.
//!
//! **One-way** clips `i_q*` every loop period (not only at the law rate) into the interval
//! between `0` and the short-circuit current `−e_q/R`. Inside it the terminal power
//! `−3/2·(e_q·i_q + R·i_q²) = −3/2·i_q·(e_q + R·i_q)` is ≥ 0: the drive never takes power
//! from the bus, not even to pay the machine's copper loss (a stricter condition than
//! `i_q·e_q ≤ 0`, which only keeps mechanical power flowing into the machine). Any passive
//! resistor `R_L ≥ 0` lies in that interval.

use super::lti::{decimation, Lti, LtiParams};
use super::{CommandLaw, LawInput};
use crate::frames::Dq;
use crate::fx::{Gain, Q};

/// Observer-based optimal law.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Optimal {
    filt: Lti,
    one_way: bool,
    inv_r: Gain,
    decim: u32,
    count: u32,
    held: Q,
    applied: Q,
}

/// Clip `i` into the passive interval between 0 and `−e/R` (`inv_r` = 1/R).
#[inline]
pub fn clip_one_way(i: Q, e_q: Q, inv_r: Gain) -> Q {
    let i_sc = -inv_r.scale(e_q);
    let (lo, hi) = if i_sc < Q::ZERO {
        (i_sc, Q::ZERO)
    } else {
        (Q::ZERO, i_sc)
    };
    i.clamp(lo, hi)
}

impl Optimal {
    /// Law from host-designed parameters (`p` valid, see [`LtiParams::is_valid`]).
    pub fn new(p: &LtiParams, one_way: bool, r_phase: f32, pwm_hz: f32, law_rate_hz: f32) -> Self {
        let mut p = *p;
        p.d[2] = 0.0;
        Optimal {
            filt: Lti::new(&p),
            one_way,
            inv_r: Gain::from_f32(1.0 / r_phase),
            decim: decimation(pwm_hz, law_rate_hz),
            count: 0,
            held: Q::ZERO,
            applied: Q::ZERO,
        }
    }

    /// Is this the one-way version?
    pub fn is_one_way(&self) -> bool {
        self.one_way
    }

    /// Observer state (SI units of the design).
    pub fn state(&self) -> [f64; super::lti::N] {
        self.filt.state_f64()
    }
}

impl CommandLaw for Optimal {
    fn command(&mut self, inp: &LawInput) -> Dq {
        if self.count == 0 {
            let u = [inp.x, inp.omega_m, self.applied];
            let raw = self.filt.output(&u);
            self.held = raw;
            let applied = if self.one_way {
                clip_one_way(raw, inp.e_q, self.inv_r)
            } else {
                raw
            };
            self.filt.advance(&[inp.x, inp.omega_m, applied]);
            self.applied = applied;
        }
        self.count += 1;
        if self.count >= self.decim {
            self.count = 0;
        }
        let q = if self.one_way {
            clip_one_way(self.held, inp.e_q, self.inv_r)
        } else {
            self.held
        };
        Dq { d: Q::ZERO, q }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fx::q;

    /// One-way: whatever the controller asks and whatever the emf, the terminal power
    /// `−3/2·i·(e + R·i)` of the command is ≥ −(rounding of one Q16.16 LSB of current).
    #[test]
    fn one_way_never_draws_power() {
        // A controller whose command ignores the emf: i* = 200 A/m · x.
        let mut p = LtiParams::default();
        p.d[0] = 200.0;
        let mut law = Optimal::new(&p, true, 2.41, 20_000.0, 1_000.0);
        let mut worst = 0.0f64;
        let mut n_active = 0;
        for k in 0..200_000u32 {
            let e = 80.0 * ((k as f64) * 7.3e-4).sin() + 5.0 * ((k as f64) * 0.11).cos();
            let i = law
                .command(&LawInput {
                    e_q: q(e as f32),
                    x: q((0.05 * ((k as f64) * 1.3e-4).sin()) as f32),
                    ..Default::default()
                })
                .q
                .to_num::<f64>();
            let e_used = q(e as f32).to_num::<f64>();
            let p_term = -1.5 * i * (e_used + 2.41 * i);
            worst = worst.min(p_term);
            if i.abs() > 0.1 {
                n_active += 1;
            }
        }
        // The clip bound −e/R is rounded to 1 LSB (1.5e-5 A): |P| ≤ 3/2·(|e|+R|i|)·1.5e-5 ≈ 2e-3 W.
        assert!(worst > -3e-3, "drew {worst} W");
        assert!(
            n_active > 10_000,
            "the command was not exercised ({n_active})"
        );
    }

    #[test]
    fn two_way_passes_command_through() {
        let mut p = LtiParams::default();
        p.d[0] = 100.0; // i = 100 A/m · x
        let mut law = Optimal::new(&p, false, 2.41, 20_000.0, 20_000.0);
        let i = law.command(&LawInput {
            x: q(0.05),
            e_q: q(10.0),
            ..Default::default()
        });
        // Same sign as e: power into the machine, allowed for two-way.
        assert!((i.q.to_num::<f32>() - 5.0).abs() < 1e-3);
        let mut ow = Optimal::new(&p, true, 2.41, 20_000.0, 20_000.0);
        let i = ow.command(&LawInput {
            x: q(0.05),
            e_q: q(10.0),
            ..Default::default()
        });
        assert_eq!(i.q, Q::ZERO);
    }
}
