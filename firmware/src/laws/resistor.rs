//! Emulated resistor: each phase behaves as if `R_L` were wired across it (star), so
//! `i = −e/(R + R_L)` per phase, i.e. `i_q* = −e_q/(R + R_L)`, `i_d* = 0`.
//!
//! `R_L = ∞` is open circuit (zero current), `R_L = 0` short circuit (`−e_q/R`). The
//! conductance `1/(R + R_L)` is computed once when the parameter changes, so the loop has no
//! division.

use super::{CommandLaw, LawInput};
use crate::frames::Dq;
use crate::fx::{Gain, Q};

/// Emulated-resistance law.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Resistor {
    /// −1/(R + R_L), siemens: the command is this gain times the back-emf, with no negation
    /// in the loop (the gain's product saturates at the sign it has, so the command's sign
    /// holds at any emf).
    pub neg_conductance: Gain,
}

impl Resistor {
    /// Law for machine phase resistance `r` and load `r_load` (both Ω; `r_load` may be
    /// infinite for open circuit). Inputs are validated by [`crate::config`].
    pub fn new(r: f32, r_load: f32) -> Resistor {
        let total = r + r_load;
        let g = if total.is_finite() && total > 0.0 {
            1.0 / total
        } else {
            0.0
        };
        Resistor {
            neg_conductance: Gain::from_f32(-g),
        }
    }
}

impl CommandLaw for Resistor {
    #[inline(always)]
    fn command(&mut self, inp: &LawInput) -> Dq {
        Dq {
            d: Q::ZERO,
            q: self.neg_conductance.scale(inp.e_q),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fx::q;

    #[test]
    fn current_is_emf_over_total_resistance() {
        for (r_load, e) in [
            (10.0f32, 50.0f32),
            (306.0, 120.0),
            (1000.0, -80.0),
            (0.0, 5.0),
        ] {
            let mut l = Resistor::new(2.41, r_load);
            let i = l.command(&LawInput {
                e_q: q(e),
                ..Default::default()
            });
            let want = -e / (2.41 + r_load);
            // Gain keeps ≥ 2^-30·2^k relative precision; Q16.16 output rounding 1.5e-5 A.
            assert!(
                (i.q.to_num::<f32>() - want).abs() < 2e-5 + want.abs() * 1e-6,
                "{r_load} Ω"
            );
            assert_eq!(i.d, Q::ZERO);
        }
        let mut open = Resistor::new(2.41, f32::INFINITY);
        assert_eq!(
            open.command(&LawInput {
                e_q: q(100.0),
                ..Default::default()
            })
            .q,
            Q::ZERO
        );
    }
}
