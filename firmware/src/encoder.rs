//! Quadrature encoder: multi-turn position from a wrapping 16-bit hardware counter, rotor
//! angles, and a speed estimate from a second-order tracking loop (PLL).
//!
//! The tracking loop (as in ODrive) estimates position `p̂` and speed `v̂` in counts:
//! `ε = p − p̂`, `p̂ ← p̂ + v̂·Ts + kp·ε`, `v̂ ← v̂ + ki·ε` with `kp = 2ω_b·Ts`,
//! `ki = (ω_b·Ts)²` (critically damped, bandwidth ω_b). It filters the count quantisation
//! without the bias of a plain difference filter and gives a position between counts.

use crate::fx::{mulhs, sat_i32, Angle, Gain, Q};

/// Constants derived from the configuration (see [`crate::config`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct EncoderGains {
    /// Counts per mechanical revolution (after ×4 decoding).
    pub cpr: u32,
    /// Mechanical turn per count, 2³²/cpr (truncated).
    pub turn_per_count: u32,
    /// Pole pairs.
    pub pole_pairs: u32,
    /// Electrical angle per count, `turn_per_count·pole_pairs` (wrapping: angles are mod 2³²).
    pub e_per_count: u32,
    /// Electrical angle of the d axis when the count within a turn is zero.
    pub offset: Angle,
    /// PLL gains per step (dimensionless): `kp·2^31` and `ki·2^34`, which fit because
    /// `kp = 2ω_b·Ts ≤ 0.6` and `ki = (ω_b·Ts)² ≤ 0.09` by validation (`ω_b·Ts ≤ 0.3`).
    pub kp31: i32,
    pub ki34: i32,
    /// Shaft speed per (count per step): 2π·f_pwm/cpr, rad/s.
    pub rad_s_per_count_step: Gain,
    /// Metres of travel per count: lead (m/rad)·2π/cpr.
    pub m_per_count: Gain,
    /// Largest plausible change of count in one step (beyond it: a glitch or lost encoder).
    pub max_step_counts: i32,
}

/// Encoder and speed-observer state.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Encoder {
    /// The last raw count in the low half, and 0xFFFF in the high half once an update has
    /// been seen (0 before): the high half masks the first change to zero without a branch.
    last: u32,
    /// Multi-turn position, counts.
    pub position: i32,
    /// Count within the revolution, 0 … cpr−1.
    pub in_turn: u32,
    /// PLL position error `position − p̂` after the last update, counts · 2^16 (saturating).
    /// Keeping the error instead of `p̂` keeps the loop in 32 bits: `p̂` itself needs 48.
    err: i32,
    /// PLL speed estimate, counts per step (Q16.16).
    pub vel: Q,
    /// The last raw change exceeded `max_step_counts` (encoder glitch or loss).
    pub implausible: bool,
}

/// `t mod cpr` in [0, cpr) (cpr ≥ 16 by validation; 0 is treated as 1).
#[inline(never)]
fn wrap_turn(t: i32, cpr: u32) -> u32 {
    t.rem_euclid(cpr.max(1) as i32) as u32
}

impl Encoder {
    /// Set the multi-turn zero here (the next update defines count 0).
    pub fn rezero(&mut self) {
        *self = Encoder::default();
    }

    /// One step with the raw hardware counter; returns the electrical angle of the d axis.
    #[inline(always)]
    pub fn update(&mut self, raw: u16, g: &EncoderGains) -> Angle {
        let delta = ((raw as u32).wrapping_sub(self.last) & (self.last >> 16)) as u16 as i16 as i32;
        self.last = raw as u32 | 0xFFFF_0000;
        self.implausible = delta.unsigned_abs() > g.max_step_counts as u32;
        self.position = self.position.saturating_add(delta);
        // Count within the turn, kept by wrap-around. in_turn < cpr ≤ 16384 and |delta| ≤
        // 32768: the sums cannot overflow. One unsigned compare covers both directions; on a
        // wrap, one turn added or taken away is enough for any step below a turn (the usual
        // case), and the full reduction runs only for larger ones.
        let t = self.in_turn as i32 + delta;
        self.in_turn = if (t as u32) < g.cpr {
            t as u32
        } else {
            let cpr = g.cpr as i32;
            let u = if t < 0 { t + cpr } else { t - cpr };
            if (u as u32) < g.cpr {
                u as u32
            } else {
                wrap_turn(t, g.cpr)
            }
        };
        let theta_e = Angle(
            self.in_turn
                .wrapping_mul(g.e_per_count)
                .wrapping_add(g.offset.0),
        );

        // Tracking loop, on the error e = p − p̂: the new count moves e by delta (delta·2^16
        // lies in [−2^31, 2^31 − 2^16], so the shift cannot overflow); then
        // p̂ ← p̂ + v̂ + kp·e and v̂ ← v̂ + ki·e, i.e. e ← e − kp·e − v̂.
        let err = self.err.saturating_add(delta << 16);
        // High-word products (one SMMUL each): kp·e = 2·⌊e·kp31/2^32⌋, ki·e = ⌊e·ki34/2^32⌋/4.
        let kp_e = mulhs(err, g.kp31) << 1; // |.| ≤ 0.6·|e| + 2: fits
        let ki_e = mulhs(err, g.ki34) >> 2;
        // e − kp·e lies between e and 0 (up to 2 LSB of rounding beyond 0 for |e| ≤ 2), and
        // never beyond i32 at the ends (kp ≤ 0.6): no overflow.
        self.err = err.wrapping_sub(kp_e).saturating_sub(self.vel.to_bits());
        self.vel = self.vel.saturating_add(Q::from_bits(ki_e));
        theta_e
    }

    /// PLL position estimate, counts · 2^16.
    pub fn pos_est(&self) -> i64 {
        ((self.position as i64) << 16) - self.err as i64
    }

    /// Linear travel from the zero position, m (from the PLL position), saturated to Q16.16.
    pub fn x(&self, g: &EncoderGains) -> Q {
        Q::from_bits(sat_i32(g.m_per_count.mul_wide(self.pos_est())))
    }

    /// Mechanical speed, rad/s.
    pub fn omega_m(&self, g: &EncoderGains) -> Q {
        g.rad_s_per_count_step.scale(self.vel)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::vec;

    fn gains(cpr: u32) -> EncoderGains {
        EncoderGains {
            cpr,
            max_step_counts: 1000,
            ..EncoderGains::default()
        }
    }

    proptest! {
        /// The first update defines count 0 whatever the counter reads; after it the
        /// multi-turn position follows the counter's wrapping changes, and the count within
        /// the turn is that position modulo cpr, on the one-turn wrap path and on the full
        /// reduction alike (changes up to ±32,767 counts against turns of 16 … 16,384).
        #[test]
        fn position_and_count_within_the_turn(cpr in prop::sample::select(vec![16u32, 100, 10_000, 16_384]),
                                              first in any::<u16>(),
                                              steps in prop::collection::vec(-32_767i32..=32_767, 1..60)) {
            let g = gains(cpr);
            let mut e = Encoder::default();
            e.update(first, &g);
            prop_assert_eq!((e.position, e.in_turn, e.implausible), (0, 0, false));
            let (mut raw, mut pos) = (first, 0i64);
            for d in steps {
                raw = raw.wrapping_add(d as u16);
                pos += d as i64;
                e.update(raw, &g);
                prop_assert_eq!(e.position as i64, pos);
                prop_assert_eq!(e.in_turn as i64, pos.rem_euclid(cpr as i64));
                prop_assert_eq!(e.implausible, d.abs() > 1000);
            }
        }
    }
}
