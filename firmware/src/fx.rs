//! Fixed-point types and the few primitives the current loop needs beyond `fixed`.
//!
//! Physical quantities inside the loop are [`Q`] (Q16.16: ±32768 with a resolution of
//! 1.5e-5) and named by what they hold through the aliases below. Everything saturates.

use fixed::types::{I16F16, U1F15};

/// Q16.16, the loop's general number format.
pub type Q = I16F16;
/// Amperes.
pub type Amps = Q;
/// Volts.
pub type Volts = Q;
/// Radians per second.
pub type RadPerSec = Q;
/// Metres.
pub type Metres = Q;
/// Duty cycle, 0 … 1 (Q1.15).
pub type Duty = U1F15;

/// A gain kept with more fractional bits than [`Q`] allows: `value = bits / 2^frac`.
///
/// Used where a Q16.16 coefficient would lose too much resolution (a load conductance of
/// 1 mS, a filter coefficient of 1e-3). The product with a [`Q`] is computed in 64 bits and
/// saturated back to [`Q`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Gain {
    bits: i32,
    frac: u8,
}

impl Gain {
    /// Zero gain.
    pub const ZERO: Gain = Gain { bits: 0, frac: 0 };

    /// The nearest representable gain to `v` with the most fractional bits that still hold
    /// it (at most 30). Non-finite input gives zero; out-of-range input saturates.
    pub fn from_f32(v: f32) -> Gain {
        if !v.is_finite() || v == 0.0 {
            return Gain::ZERO;
        }
        let mag = if v < 0.0 { -v } else { v };
        // Largest frac such that |v|·2^frac < 2^31; at least 1 (|v| ≥ 2^30 saturates).
        let mut frac: u8 = 30;
        while frac > 1 && mag * pow2(frac) >= 2_147_483_000.0 {
            frac -= 1;
        }
        let scaled = v * pow2(frac);
        let bits = if scaled >= 2_147_483_647.0 {
            i32::MAX
        } else if scaled <= -2_147_483_648.0 {
            i32::MIN
        } else {
            round_f32(scaled) as i32
        };
        Gain { bits, frac }
    }

    /// The gain as `f32` (for reports and tests).
    pub fn to_f32(self) -> f32 {
        self.bits as f32 / pow2(self.frac)
    }

    /// `self · x` for a 64-bit fixed-point `x` (any format; the result has the same format),
    /// saturating in 64 bits.
    #[inline(always)]
    pub fn mul_wide(self, x: i64) -> i64 {
        x.saturating_mul(self.bits as i64) >> self.frac
    }

    /// `self · x`, saturated to [`Q`].
    #[inline(always)]
    pub fn scale(self, x: Q) -> Q {
        // Same result as `sat_i32((bits·x) >> frac)`, in 32-bit halves: one long multiply, two
        // register shifts and a sign test instead of a 64-bit variable shift and compare.
        let p = self.bits as i64 * x.to_bits() as i64;
        let (hi, lo) = ((p >> 32) as i32, p as u32);
        let f = self.frac as u32; // 1 ..= 30 (from_f32), 0 only for ZERO
        if f == 0 {
            return Q::from_bits(sat_i32(p));
        }
        // p >> f fits in i32 iff bits 31+f … 63 of p are all equal: hi >> (f−1) is 0 or −1.
        let top = hi >> (f - 1);
        if top != 0 && top != -1 {
            return if hi < 0 { Q::MIN } else { Q::MAX };
        }
        Q::from_bits(((hi as u32).wrapping_shl(32 - f) | lo.wrapping_shr(f)) as i32)
    }
}

fn pow2(n: u8) -> f32 {
    (1u64 << n) as f32
}

fn round_f32(x: f32) -> f32 {
    // core has no f32::round in no_std on stable; ties away from zero like f32::round.
    let t = x as i64 as f32; // truncation toward zero (|x| < 2^31 here)
    let d = x - t;
    if d >= 0.5 {
        t + 1.0
    } else if d <= -0.5 {
        t - 1.0
    } else {
        t
    }
}

/// Saturate a 64-bit value to `i32`.
#[inline(always)]
pub fn sat_i32(v: i64) -> i32 {
    if v > i32::MAX as i64 {
        i32::MAX
    } else if v < i32::MIN as i64 {
        i32::MIN
    } else {
        v as i32
    }
}

/// Q16.16 from `f32`, saturating, NaN → 0.
pub fn q(v: f32) -> Q {
    if v.is_nan() {
        Q::ZERO
    } else {
        Q::saturating_from_num(v)
    }
}

/// Saturating `a·b` in Q16.16 (64-bit product, one shift).
#[inline(always)]
pub fn mul(a: Q, b: Q) -> Q {
    Q::from_bits(sat_i32((a.to_bits() as i64 * b.to_bits() as i64) >> 16))
}

/// Clamp `x` to `[-lim, lim]` (`lim ≥ 0`).
#[inline(always)]
pub fn clamp_sym(x: Q, lim: Q) -> Q {
    if x > lim {
        lim
    } else if x < -lim {
        -lim
    } else {
        x
    }
}

/// Electrical or mechanical angle: `u32` turn fraction, 2³² = 2π, wrapping.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Angle(pub u32);

impl Angle {
    /// Radians per least significant bit.
    pub const RAD_PER_LSB: f64 = core::f64::consts::TAU / 4_294_967_296.0;

    /// Angle from radians (any value; wraps).
    pub fn from_radians(r: f64) -> Angle {
        let turns = r / core::f64::consts::TAU;
        let frac = turns - floor_f64(turns);
        Angle((frac * 4_294_967_296.0) as u64 as u32)
    }

    /// The angle in radians, in [0, 2π).
    pub fn radians(self) -> f64 {
        self.0 as f64 * Self::RAD_PER_LSB
    }

    /// (sin, cos) in Q16.16, from a 512-point table with linear interpolation (error < 2e-5).
    #[inline(always)]
    pub fn sin_cos(self) -> (Q, Q) {
        (sin_turn(self.0), sin_turn(self.0.wrapping_add(1 << 30)))
    }
}

fn floor_f64(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

const SIN_BITS: u32 = 9;
const SIN_N: usize = 1 << SIN_BITS;

/// sin(2π·k/512)·65536, k = 0 … 512, built at compile time.
static SIN_TABLE: [i32; SIN_N + 1] = build_sin_table();

const fn build_sin_table() -> [i32; SIN_N + 1] {
    let mut t = [0i32; SIN_N + 1];
    let mut k = 0;
    while k <= SIN_N {
        let x = core::f64::consts::TAU * k as f64 / SIN_N as f64;
        let s = const_sin(x) * 65536.0;
        t[k] = if s >= 0.0 {
            (s + 0.5) as i32
        } else {
            (s - 0.5) as i32
        };
        k += 1;
    }
    t
}

/// sin(x) for x in [0, 2π], by reduction to [-π/2, π/2] and a Taylor series to x^23.
const fn const_sin(x: f64) -> f64 {
    use core::f64::consts::PI;
    let mut y = x;
    if y > PI {
        y -= 2.0 * PI;
    }
    if y > PI / 2.0 {
        y = PI - y;
    } else if y < -PI / 2.0 {
        y = -PI - y;
    }
    let y2 = y * y;
    let mut term = y;
    let mut sum = y;
    let mut n = 1;
    while n < 12 {
        term = -term * y2 / ((2 * n) as f64 * (2 * n + 1) as f64);
        sum += term;
        n += 1;
    }
    sum
}

#[inline(always)]
fn sin_turn(a: u32) -> Q {
    let idx = (a >> (32 - SIN_BITS)) as usize;
    let frac = ((a >> (16 - SIN_BITS)) & 0xFFFF) as i32; // 16-bit position between entries
    let (lo, hi) = (
        SIN_TABLE[idx & (SIN_N - 1)],
        SIN_TABLE[(idx & (SIN_N - 1)) + 1],
    );
    Q::from_bits(lo + (((hi - lo) * frac) >> 16))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sin_cos_table_accuracy() {
        let mut worst = 0.0f64;
        for k in 0..100_000u32 {
            let a = Angle(k.wrapping_mul(42_949));
            let (s, c) = a.sin_cos();
            let r = a.radians();
            worst = worst.max((s.to_num::<f64>() - r.sin()).abs());
            worst = worst.max((c.to_num::<f64>() - r.cos()).abs());
        }
        // Linear interpolation over 512 points: (2π/512)²/8 = 1.9e-5, plus Q16.16 rounding.
        assert!(worst < 1.9e-5 + 2.0 / 65536.0, "worst error {worst}");
    }

    #[test]
    fn gain_keeps_small_values_precise() {
        let g = Gain::from_f32(1.0 / 1002.41);
        assert!((g.to_f32() * 1002.41 - 1.0).abs() < 1e-6);
        assert_eq!(Gain::from_f32(f32::NAN), Gain::ZERO);
        assert_eq!(Gain::from_f32(0.5).scale(q(100.0)), q(50.0));
        // Saturation, not wrap-around.
        assert_eq!(Gain::from_f32(1.0e6).scale(q(1000.0)), Q::MAX);
        assert_eq!(Gain::from_f32(-1.0e6).scale(q(1000.0)), Q::MIN);
    }

    #[test]
    fn scale_equals_the_wide_product() {
        use proptest::prelude::*;
        proptest!(|(v in -1.0e7f32..1.0e7, x in any::<i32>())| {
            let g = Gain::from_f32(v);
            let want = sat_i32((g.bits as i64 * x as i64) >> g.frac);
            prop_assert_eq!(g.scale(Q::from_bits(x)).to_bits(), want);
        });
        for v in [1.0e-9f32, 3.0e-5, 0.5, 1.0, 2.0, 1.0e9, -1.0e9, 1.0e30] {
            let g = Gain::from_f32(v);
            for x in [0, 1, -1, i32::MAX, i32::MIN, 65_536, -65_536] {
                let want = sat_i32((g.bits as i64 * x as i64) >> g.frac);
                assert_eq!(g.scale(Q::from_bits(x)).to_bits(), want, "{v} · {x}");
            }
        }
    }

    #[test]
    fn mul_saturates() {
        assert_eq!(mul(Q::MAX, Q::MAX), Q::MAX);
        assert_eq!(mul(Q::MIN, Q::MAX), Q::MIN);
        assert_eq!(mul(q(1.5), q(-2.0)), q(-3.0));
    }
}
