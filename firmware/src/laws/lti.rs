//! Fixed-point discrete state-space filter used by the dynamic laws (emulated impedance,
//! optimal two-way / one-way control), and the decimation helper they share.
//!
//! `ξ[k+1] = A·ξ[k] + B·u[k]`, `y[k] = C·ξ[k] + D·u[k]`, at most [`N`] states and [`M`] inputs,
//! one output. Coefficients are [`Coef`] (i64 with 40 fractional bits: ±8.4e6 with a resolution
//! of 9e-13, enough for the near-unity poles of a 1 kHz discretisation of sub-hertz dynamics);
//! states are i64 with 32 fractional bits (±2.1e9, resolution 2.3e-10); products are formed in
//! i128 and saturate. These filters run at the decimated law rate (1 kHz by default), not at the
//! current-loop rate, so the wide arithmetic costs little.

use crate::fx::{sat_i32, Q};

/// Number of states the filters hold.
pub const N: usize = 4;
/// Number of inputs.
pub const M: usize = 3;

const COEF_FRAC: u32 = 40;
const STATE_FRAC: u32 = 32;

/// A filter coefficient: `value = bits / 2^40`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Coef(pub i64);

/// Largest magnitude a [`Coef`] holds.
pub const COEF_MAX: f32 = 8.0e6;

impl Coef {
    /// Nearest coefficient to `v` (saturating; non-finite → 0). Uses only `+ − × ÷`, so the
    /// board and the host get the same bits.
    pub fn from_f32(v: f32) -> Coef {
        // In f32 (no soft-float f64 on the board), bit-identical to `from_f64(v as f64)`:
        // `v·2^40` is exact (a power-of-two scaling), an f32 of magnitude ≥ 2^23 is an
        // integer, and below that `s − trunc(s)` is exact, so the half-away rounding sees the
        // exact fraction.
        if !v.is_finite() {
            return Coef(0);
        }
        let s = v * (1u64 << COEF_FRAC) as f32;
        if s >= 9.2e18 {
            Coef(i64::MAX)
        } else if s <= -9.2e18 {
            Coef(i64::MIN)
        } else {
            let t = s as i64; // toward zero
            let f = s - t as f32;
            Coef(if f >= 0.5 {
                t + 1
            } else if f <= -0.5 {
                t - 1
            } else {
                t
            })
        }
    }

    /// As [`Coef::from_f32`], from `f64`.
    pub fn from_f64(v: f64) -> Coef {
        if !v.is_finite() {
            return Coef(0);
        }
        let s = v * (1u64 << COEF_FRAC) as f64;
        if s >= 9.2e18 {
            Coef(i64::MAX)
        } else if s <= -9.2e18 {
            Coef(i64::MIN)
        } else {
            // Round half away from zero.
            Coef(if s >= 0.0 {
                (s + 0.5) as i64
            } else {
                (s - 0.5) as i64
            })
        }
    }

    /// The coefficient as `f64` (reports, tests).
    pub fn to_f64(self) -> f64 {
        self.0 as f64 / (1u64 << COEF_FRAC) as f64
    }

    /// `self·x` for a state-format (32 fractional bits) `x`, in state format, saturating.
    #[inline]
    pub fn mul_state(self, x: i64) -> i64 {
        sat_i64((self.0 as i128 * x as i128) >> COEF_FRAC)
    }
}

#[inline]
fn sat_i64(v: i128) -> i64 {
    if v > i64::MAX as i128 {
        i64::MAX
    } else if v < i64::MIN as i128 {
        i64::MIN
    } else {
        v as i64
    }
}

/// Q16.16 → state format.
#[inline]
pub fn q_to_state(x: Q) -> i64 {
    (x.to_bits() as i64) << (STATE_FRAC - 16)
}

/// State format → Q16.16 (rounded toward −∞, saturating).
#[inline]
pub fn state_to_q(x: i64) -> Q {
    Q::from_bits(sat_i32(x >> (STATE_FRAC - 16)))
}

/// Coefficients of a discrete single-output state-space filter, in `f32` (the parameter form).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct LtiParams {
    /// State matrix, row-major `N×N`.
    pub a: [f32; N * N],
    /// Input matrix, row-major `N×M`.
    pub b: [f32; N * M],
    /// Output row.
    pub c: [f32; N],
    /// Feed-through row.
    pub d: [f32; M],
}

impl LtiParams {
    /// All coefficients finite and within the [`Coef`] range.
    pub fn is_valid(&self) -> bool {
        let ok = |m: &[f32]| m.iter().all(|v| v.is_finite() && v.abs() <= COEF_MAX);
        ok(&self.a) && ok(&self.b) && ok(&self.c) && ok(&self.d)
    }
}

/// The filter, compiled to fixed point, with its state.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Lti {
    a: [[Coef; N]; N],
    b: [[Coef; M]; N],
    c: [Coef; N],
    d: [Coef; M],
    x: [i64; N],
}

impl Lti {
    /// Compile the parameters (state zero).
    pub fn new(p: &LtiParams) -> Lti {
        let mut f = Lti::default();
        for i in 0..N {
            for j in 0..N {
                f.a[i][j] = Coef::from_f32(p.a[i * N + j]);
            }
            for j in 0..M {
                f.b[i][j] = Coef::from_f32(p.b[i * M + j]);
            }
            f.c[i] = Coef::from_f32(p.c[i]);
        }
        for j in 0..M {
            f.d[j] = Coef::from_f32(p.d[j]);
        }
        f
    }

    /// Output for input `u` at the current state (no state change).
    /// Out of line (as `advance`): one copy shared by the impedance and optimal laws, which
    /// run at the decimated law rate (flash: each inlined copy is over 1 KB on the M4).
    #[inline(never)]
    pub fn output(&self, u: &[Q; M]) -> Q {
        let mut y: i64 = 0;
        for i in 0..N {
            y = y.saturating_add(self.c[i].mul_state(self.x[i]));
        }
        for (dj, uj) in self.d.iter().zip(u.iter()) {
            y = y.saturating_add(dj.mul_state(q_to_state(*uj)));
        }
        state_to_q(y)
    }

    /// Advance the state with input `u`.
    #[inline(never)]
    pub fn advance(&mut self, u: &[Q; M]) {
        let us = [q_to_state(u[0]), q_to_state(u[1]), q_to_state(u[2])];
        let mut nx = [0i64; N];
        for (i, nxi) in nx.iter_mut().enumerate() {
            let mut s: i64 = 0;
            for j in 0..N {
                s = s.saturating_add(self.a[i][j].mul_state(self.x[j]));
            }
            for (j, uj) in us.iter().enumerate() {
                s = s.saturating_add(self.b[i][j].mul_state(*uj));
            }
            *nxi = s;
        }
        self.x = nx;
    }

    /// State in SI units (tests and telemetry).
    pub fn state_f64(&self) -> [f64; N] {
        let mut s = [0.0; N];
        for (o, x) in s.iter_mut().zip(self.x.iter()) {
            *o = *x as f64 / (1u64 << STATE_FRAC) as f64;
        }
        s
    }

    /// Zero the state.
    pub fn reset(&mut self) {
        self.x = [0; N];
    }
}

/// Ratio of loop rate to law rate: `round(pwm_hz / law_rate_hz)`, at least 1.
pub fn decimation(pwm_hz: f32, law_rate_hz: f32) -> u32 {
    let r = pwm_hz / law_rate_hz;
    if !r.is_finite() || r < 1.0 {
        1
    } else {
        (r + 0.5) as u32
    }
}

/// The period, s, at which a decimated law updates: `decimation / pwm_hz`.
pub fn law_period(pwm_hz: f32, law_rate_hz: f32) -> f32 {
    decimation(pwm_hz, law_rate_hz) as f32 / pwm_hz
}

/// `a / d`, truncating toward zero like `/` (`d > 0`; `d = 0` gives 0 instead of a panic):
/// the high 64 bits of `|a|` by one `u64` division, the low 64 bits by shift and subtract.
/// A 32-bit target has no 128-bit division routine: the compiler expands each `i128` `/` in
/// place (≈ 1 KB of flash on the M4); this one copy is a few hundred bytes. The laws divide
/// rarely (the tracking law once per dither half-period, three divisions).
#[inline(never)]
pub fn div_i128(a: i128, d: u64) -> i128 {
    if d == 0 {
        return 0;
    }
    let n = a.unsigned_abs();
    let hi = (n >> 64) as u64;
    let (q_hi, mut r) = (hi / d, hi % d);
    let lo = n as u64;
    let mut q_lo = 0u64;
    for i in (0..64).rev() {
        // r < d before the shift; the bit shifted out of r means r ≥ d.
        let carry = r >> 63;
        r = (r << 1) | ((lo >> i) & 1);
        if carry != 0 || r >= d {
            r = r.wrapping_sub(d);
            q_lo |= 1 << i;
        }
    }
    let q = ((q_hi as u128) << 64 | q_lo as u128) as i128;
    if a < 0 {
        q.wrapping_neg()
    } else {
        q
    }
}

/// `2^x` for `x` in Q16.16 (|x| < 30), as a [`Coef`] bit pattern scaled by 2^-40 … computed in
/// integers only: the fractional part by a degree-14 Taylor series of `e^(f·ln 2)` in 62-bit
/// fixed point (relative error < 1e-12 for f ∈ [0, 1)). Returns the value in Q32.32 (i64),
/// saturating.
pub fn exp2_q(x: Q) -> i64 {
    let bits = x.to_bits() as i64;
    let n = bits >> 16; // floor
    let f = bits & 0xFFFF; // [0, 1) in 1/65536
                           // y = f·ln2 in Q1.62
    const LN2_Q62: u64 = 3_196_577_161_300_663_914; // ln 2 · 2^62
                                                    // Everything below 2^63 (y < ln 2 in Q1.62, terms ≤ 1, sum < 2): u64, with one u64×u64
                                                    // product per term (cheaper on the M4 than i128 arithmetic; the same bits).
    let y = ((f as u128 * LN2_Q62 as u128) >> 16) as u64;
    let one: u64 = 1 << 62;
    let mut term = one;
    let mut sum = one;
    let mut k: u64 = 1;
    while k <= 14 {
        term = ((term as u128 * y as u128) >> 62) as u64 / k;
        sum += term;
        k += 1;
    }
    let sum = sum as i128;
    // sum in Q2.62 → Q32.32 scaled by 2^n
    let shift = 30 - n; // 62 − 32 − n
    let v = if shift >= 0 {
        if shift > 126 {
            0
        } else {
            sum >> shift
        }
    } else if -shift > 60 {
        i128::MAX
    } else {
        sum << (-shift)
    };
    sat_i64(v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fx::q;

    #[test]
    fn exp2_is_accurate() {
        for k in -200..200 {
            let xf = k as f64 * 0.0731;
            let x = q(xf as f32);
            let got = exp2_q(x) as f64 / 4_294_967_296.0;
            let want = (x.to_num::<f64>()).exp2();
            // Q32.32 output: two truncations (series terms, final shift) of 2.3e-10 each; the
            // 14-term series itself is exact to 1e-12 relative.
            assert!(
                (got - want).abs() <= 5e-10 + 1e-12 * want,
                "2^{xf}: {got} vs {want}"
            );
        }
    }

    #[test]
    fn lti_matches_float_recursion() {
        // A damped oscillator driven by a step: fixed point follows f64 to the state resolution.
        let mut p = LtiParams::default();
        p.a[0] = 0.999;
        p.a[1] = 0.01;
        p.a[N] = -0.01;
        p.a[N + 1] = 0.998;
        p.b[0] = 0.001;
        p.c[0] = 2.0;
        p.d[0] = 0.5;
        let mut f = Lti::new(&p);
        let (mut x0, mut x1) = (0.0f64, 0.0f64);
        let u = [q(3.0), Q::ZERO, Q::ZERO];
        for _ in 0..5000 {
            let y = f.output(&u).to_num::<f64>();
            let yw = 2.0 * x0 + 0.5 * 3.0;
            // Q16.16 output rounding (1.5e-5) dominates; coefficient error 1e-12·5000 steps.
            assert!((y - yw).abs() < 3e-5, "{y} vs {yw}");
            f.advance(&u);
            let n0 = 0.999 * x0 + 0.01 * x1 + 0.001 * 3.0;
            let n1 = -0.01 * x0 + 0.998 * x1;
            x0 = n0;
            x1 = n1;
        }
    }

    proptest::proptest! {
        /// The f32 path gives the bits of the f64 one for every finite f32 in the range the
        /// filters accept (and saturates the same way beyond it).
        #[test]
        fn coef_from_f32_is_the_f64_rounding(bits in proptest::prelude::any::<u32>()) {
            let v = f32::from_bits(bits);
            proptest::prop_assume!(v.is_finite() && v.abs() <= 8.3e6);
            proptest::prop_assert_eq!(Coef::from_f32(v), Coef::from_f64(v as f64));
        }
    }

    proptest::proptest! {
        /// The division is `/` (any sign of the dividend, divisors of any size).
        #[test]
        fn div_i128_is_the_division(a in proptest::prelude::any::<i128>(),
                                    d in 1u64..,
                                    shift in 0u32..128) {
            let d = (d >> (shift % 64)).max(1); // small divisors as often as large ones
            proptest::prop_assert_eq!(div_i128(a, d), a / d as i128);
            proptest::prop_assert_eq!(div_i128(a >> shift, d), (a >> shift) / d as i128);
        }
    }

    #[test]
    fn coef_saturates_and_rejects_nan() {
        assert_eq!(Coef::from_f32(f32::NAN), Coef(0));
        assert_eq!(Coef::from_f64(1e30), Coef(i64::MAX));
        assert_eq!(Coef::from_f64(-1e30), Coef(i64::MIN));
        assert_eq!(Coef(i64::MAX).mul_state(i64::MAX), i64::MAX);
        assert!((Coef::from_f32(1.0 / 3.0).to_f64() - 1.0 / 3.0).abs() < 1e-8);
    }
}
