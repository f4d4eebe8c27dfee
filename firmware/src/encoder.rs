//! Quadrature encoder: multi-turn position from a wrapping 16-bit hardware counter, rotor
//! angles, and a speed estimate from a second-order tracking loop (PLL).
//!
//! The tracking loop (as in ODrive) estimates position `p̂` and speed `v̂` in counts:
//! `ε = p − p̂`, `p̂ ← p̂ + v̂·Ts + kp·ε`, `v̂ ← v̂ + ki·ε` with `kp = 2ω_b·Ts`,
//! `ki = (ω_b·Ts)²` (critically damped, bandwidth ω_b). It filters the count quantisation
//! without the bias of a plain difference filter and gives a position between counts.

use crate::fx::{sat_i32, Angle, Gain, Q};

/// Constants derived from the configuration (see [`crate::config`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct EncoderGains {
    /// Counts per mechanical revolution (after ×4 decoding).
    pub cpr: u32,
    /// Mechanical turn per count, 2³²/cpr (truncated).
    pub turn_per_count: u32,
    /// Pole pairs.
    pub pole_pairs: u32,
    /// Electrical angle of the d axis when the count within a turn is zero.
    pub offset: Angle,
    /// PLL gains per step (dimensionless).
    pub kp: Gain,
    pub ki: Gain,
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
    last_raw: u16,
    primed: bool,
    /// Multi-turn position, counts.
    pub position: i32,
    /// Count within the revolution, 0 … cpr−1.
    pub in_turn: u32,
    /// PLL position estimate, counts · 2^16.
    pos_est: i64,
    /// PLL speed estimate, counts per step (Q16.16).
    pub vel: Q,
    /// The last raw change exceeded `max_step_counts` (encoder glitch or loss).
    pub implausible: bool,
}

/// Angles and speed from one update.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Shaft {
    /// Electrical angle of the d axis.
    pub theta_e: Angle,
    /// Mechanical speed, rad/s.
    pub omega_m: Q,
    /// Linear travel from the zero position, m (from the PLL position).
    pub x: Q,
}

impl Encoder {
    /// Set the multi-turn zero here (the next update defines count 0).
    pub fn rezero(&mut self) {
        *self = Encoder::default();
    }

    /// One step with the raw hardware counter.
    #[inline(always)]
    pub fn update(&mut self, raw: u16, g: &EncoderGains) -> Shaft {
        if !self.primed {
            self.primed = true;
            self.last_raw = raw;
        }
        let delta = raw.wrapping_sub(self.last_raw) as i16 as i32;
        self.last_raw = raw;
        self.implausible = delta.abs() > g.max_step_counts;
        self.position = self.position.saturating_add(delta);
        // Count within the turn, kept by wrap-around (|delta| < cpr).
        let mut t = self.in_turn as i32 + delta;
        if t < 0 {
            t += g.cpr as i32;
        } else if t >= g.cpr as i32 {
            t -= g.cpr as i32;
        }
        self.in_turn = (t.max(0) as u32).min(g.cpr.saturating_sub(1));
        let theta_m = self.in_turn.wrapping_mul(g.turn_per_count);
        let theta_e = Angle(theta_m.wrapping_mul(g.pole_pairs).wrapping_add(g.offset.0));

        // Tracking loop.
        let err_bits = sat_i32(((self.position as i64) << 16) - self.pos_est);
        let err = Q::from_bits(err_bits);
        self.pos_est = self.pos_est + self.vel.to_bits() as i64 + g.kp.scale(err).to_bits() as i64;
        self.vel = self.vel.saturating_add(g.ki.scale(err));

        // x = position estimate · m/count (64-bit, saturated to Q16.16 metres).
        let x = sat_i32(g.m_per_count.mul_wide(self.pos_est));
        Shaft {
            theta_e,
            omega_m: g.rad_s_per_count_step.scale(self.vel),
            x: Q::from_bits(x),
        }
    }
}
