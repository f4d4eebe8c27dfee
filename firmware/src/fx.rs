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
    /// 2^(32−frac) (0 for ZERO): `x >> frac` of a 64-bit product as multiplies.
    pow: u32,
    /// 2^(frac−1) and 2^frac − 1 (0 for ZERO): the saturation test without a shift.
    half: u32,
    span: u32,
}

impl Gain {
    /// Zero gain.
    pub const ZERO: Gain = Gain {
        bits: 0,
        frac: 0,
        pow: 0,
        half: 0,
        span: 0,
    };

    const fn with_frac(bits: i32, frac: u8) -> Gain {
        if bits == 0 {
            return Gain::ZERO;
        }
        Gain {
            bits,
            frac,
            pow: 1 << (32 - frac as u32),
            half: 1 << (frac - 1),
            span: (1u32 << frac) - 1,
        }
    }

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
        Gain::with_frac(bits, frac)
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
        // Same result as `sat_i32((bits·x) >> frac)` without a variable shift: with
        // p = hi·2^32 + lo, p >> f fits in i32 iff hi ∈ [−2^(f−1), 2^(f−1)) (an add and an
        // unsigned compare), and then p >> f = hi·2^(32−f) + (lo·2^(32−f)) >> 32 (mod 2^32):
        // one multiply-long and one multiply-accumulate. ZERO has p = 0 and all fields 0.
        let p = self.bits as i64 * x.to_bits() as i64;
        let (hi, lo) = ((p >> 32) as i32, p as u32);
        if (hi as u32).wrapping_add(self.half) > self.span {
            // hi < 0 → MIN, else MAX.
            return Q::from_bits((hi >> 31) ^ i32::MAX);
        }
        let low = ((lo as u64 * self.pow as u64) >> 32) as u32;
        Q::from_bits((hi as u32).wrapping_mul(self.pow).wrapping_add(low) as i32)
    }
}

/// A constant multiplier for a bounded integer input, as one multiply by a power of two and
/// one high-word multiply (`SMMUL`): `apply(x) = ((x·2^a)·k) >> 32 ≈ value·x`, with `a` as
/// small as keeps `|k| < 2^31` (the most precise `k`) and `|x|·2^a < 2^31` for every
/// `|x| ≤ x_max`. Everything stays in 32-bit registers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Scale32 {
    m: i32,
    k: i32,
}

impl Scale32 {
    /// The multiplier `v` (finite, |v| < 2^31) for inputs `|x| ≤ x_max` (≥ 1). `None` when
    /// no exponent satisfies both bounds (the caller's validation should exclude that).
    pub fn new(v: f32, x_max: u32) -> Option<Scale32> {
        if !v.is_finite() {
            return None;
        }
        let mag = if v < 0.0 { -v } else { v };
        // Smallest a ≥ 0 with |v|·2^(32−a) < 2^31.
        let mut a: u32 = 0;
        while a <= 31 && mag * pow2((32 - a) as u8) >= 2_147_483_000.0 {
            a += 1;
        }
        if a > 30 || (x_max as u64) << a >= 1 << 31 {
            return None;
        }
        Some(Scale32 {
            m: 1 << a,
            k: round_f32(v * pow2((32 - a) as u8)) as i32,
        })
    }

    /// `value·x` for `|x| ≤ x_max` of the constructor (debug builds check it).
    #[inline(always)]
    pub fn apply(self, x: i32) -> i32 {
        debug_assert!(
            x.checked_mul(self.m).is_some(),
            "Scale32 input out of range"
        );
        (((x.wrapping_mul(self.m)) as i64 * self.k as i64) >> 32) as i32
    }
}

/// `(a·b) >> S` for operands whose shifted product is known to fit in `i32` (the caller
/// states the bound in a comment). One long multiply and two shifts, no saturation; debug
/// builds (the host tests) check the bound.
#[inline(always)]
pub fn mul_shr<const S: u32>(a: i32, b: i32) -> i32 {
    let w = (a as i64 * b as i64) >> S;
    debug_assert!(
        w == w as i32 as i64,
        "mul_shr bound violated: {a}·{b} >> {S}"
    );
    w as i32
}

/// `(a·b) >> 32`: the high word of the product (one `SMMUL`), always in range.
#[inline(always)]
pub fn mulhs(a: i32, b: i32) -> i32 {
    ((a as i64 * b as i64) >> 32) as i32
}

/// `v·2^n` rounded, for a constant with `|v|·2^n < 2^31`; saturates outside, NaN → 0.
pub fn fixed_i32(v: f32, n: u8) -> i32 {
    if !v.is_finite() {
        return 0;
    }
    let s = v * pow2(n);
    if s >= 2_147_483_647.0 {
        i32::MAX
    } else if s <= -2_147_483_648.0 {
        i32::MIN
    } else {
        round_f32(s) as i32
    }
}

fn pow2(n: u8) -> f32 {
    (1u64 << n) as f32
}

pub(crate) fn round_f32(x: f32) -> f32 {
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
    // As `sat_i32(p >> 16)`: p >> 16 fits iff hi ∈ [−2^15, 2^15).
    let p = a.to_bits() as i64 * b.to_bits() as i64;
    let (hi, lo) = ((p >> 32) as i32, p as u32);
    if (hi as u32).wrapping_add(1 << 15) > 0xFFFF {
        return Q::from_bits((hi >> 31) ^ i32::MAX);
    }
    Q::from_bits(((hi as u32) << 16 | lo >> 16) as i32)
}

/// √x for a finite x > 0 by `N` Newton (Heron) steps `y ← (y + x/y)/2` from the exponent
/// halved (`f32` `+ × ÷` only, so the same bits on every IEEE 754 target; `f32::sqrt` is not
/// in `core`). The seed is within [−2.2 %, +4.5 %] of √x; every step after the first lands
/// above √x (`(y + x/y)/2 ≥ √x`), but for the roundings. Seed and steps commute with scaling x by
/// 4 (for normal x), so every `f32` of one even and one odd binade covers all normal x:
/// measured so, the relative error after one step is in [−7.4e-8, 9.6e-4], after two in
/// [−8.8e-8, 5.3e-7], after three within ±9e-8 (a rounding of the last step).
/// (Written out step by step: at opt-level `z` a loop stays a loop.)
#[inline(always)]
pub fn sqrt_newton<const N: usize>(x: f32) -> f32 {
    let step = |y: f32| 0.5 * (y + x / y);
    let y = f32::from_bits((x.to_bits() >> 1) + 0x1fbd_1df5);
    match N {
        0 => y,
        1 => step(y),
        2 => step(step(y)),
        3 => step(step(step(y))),
        _ => {
            let mut y = step(step(step(step(y))));
            for _ in 4..N {
                y = step(y);
            }
            y
        }
    }
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
        sin_cos_turn(self.0)
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

/// Table length: 512 points plus a quarter turn (so cos θ = sin(θ + π/2) reads the same
/// table at index + 128 without wrapping) plus one for the interpolation.
const SIN_LEN: usize = SIN_N + SIN_N / 4 + 1;

/// sin(2π·k/512)·65536, k = 0 … 640, built at compile time.
static SIN_TABLE: [i32; SIN_LEN] = build_sin_table();

const fn build_sin_table() -> [i32; SIN_LEN] {
    let mut t = [0i32; SIN_LEN];
    let mut k = 0;
    while k < SIN_LEN {
        let x = core::f64::consts::TAU * (k % SIN_N) as f64 / SIN_N as f64;
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

/// (sin, cos) of a turn fraction: one index and one interpolation weight serve both (cos is
/// the table a quarter turn on), so it costs two table pairs, two multiplies and no wrap.
#[inline(always)]
fn sin_cos_turn(a: u32) -> (Q, Q) {
    // Index 0 … 511 and the 16-bit position between entries. Table entries are within
    // ±65536 and neighbours differ by < 2^10, so (hi − lo)·frac < 2^26: no overflow.
    let idx = (a >> (32 - SIN_BITS)) as usize;
    let frac = ((a >> (16 - SIN_BITS)) & 0xFFFF) as i32;
    let (s0, s1) = (SIN_TABLE[idx], SIN_TABLE[idx + 1]);
    let (c0, c1) = (SIN_TABLE[idx + SIN_N / 4], SIN_TABLE[idx + SIN_N / 4 + 1]);
    (
        Q::from_bits(s0 + (((s1 - s0) * frac) >> 16)),
        Q::from_bits(c0 + (((c1 - c0) * frac) >> 16)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sqrt_newton_error_over_two_binades() {
        // Every f32 of [1, 2) and [2, 4) (with scaling by 4 that is every normal x), against
        // the f64 square root: the ranges `sqrt_newton`'s documentation states, rounded out.
        let mut lo = [f64::MAX; 3];
        let mut hi = [f64::MIN; 3];
        for bits in 0x3f80_0000u32..0x4080_0000 {
            let x = f32::from_bits(bits);
            let ex = (x as f64).sqrt();
            let e = [
                sqrt_newton::<1>(x) as f64 / ex - 1.0,
                sqrt_newton::<2>(x) as f64 / ex - 1.0,
                sqrt_newton::<3>(x) as f64 / ex - 1.0,
            ];
            for i in 0..3 {
                lo[i] = lo[i].min(e[i]);
                hi[i] = hi[i].max(e[i]);
            }
        }
        for i in 0..3 {
            std::println!("after {} steps: from {:.2e} to {:.2e}", i + 1, lo[i], hi[i]);
        }
        assert!(lo[0] >= -7.5e-8 && hi[0] <= 9.6e-4, "{lo:?} {hi:?}");
        assert!(lo[1] >= -8.8e-8 && hi[1] <= 5.3e-7, "{lo:?} {hi:?}");
        assert!(lo[2] >= -9e-8 && hi[2] <= 9e-8, "{lo:?} {hi:?}");
    }

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
    fn scale32_is_the_product() {
        use proptest::prelude::*;
        proptest!(|(v in -2.0e4f32..2.0e4, xm in 1u32..1_000_000, x in any::<i32>())| {
            if let Some(s) = Scale32::new(v, xm) {
                let x = x % (xm as i32 + 1);
                let want = v as f64 * x as f64;
                // k has ≥ 24 significant bits (f32) or is v·2^32 rounded; result floors.
                let tol = want.abs() * 1e-6 + 1.0 + x.unsigned_abs() as f64 / 2f64.powi(31) * 2.0;
                prop_assert!((s.apply(x) as f64 - want).abs() <= tol, "{} vs {}", s.apply(x), want);
            }
        });
        // The constructor refuses what cannot be held.
        assert!(Scale32::new(3.0e9, 1).is_none());
        assert!(Scale32::new(1.0, u32::MAX).is_none());
        assert!(Scale32::new(f32::NAN, 1).is_none());
    }

    #[test]
    fn mul_equals_the_saturated_wide_product() {
        use proptest::prelude::*;
        proptest!(|(a in any::<i32>(), b in any::<i32>())| {
            let want = sat_i32((a as i64 * b as i64) >> 16);
            prop_assert_eq!(mul(Q::from_bits(a), Q::from_bits(b)).to_bits(), want);
        });
    }

    #[test]
    fn mul_saturates() {
        assert_eq!(mul(Q::MAX, Q::MAX), Q::MAX);
        assert_eq!(mul(Q::MIN, Q::MAX), Q::MIN);
        assert_eq!(mul(q(1.5), q(-2.0)), q(-3.0));
    }
}
