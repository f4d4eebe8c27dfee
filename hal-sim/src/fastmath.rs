//! Per-period arithmetic without library calls: an incremental sine/cosine for angles that
//! move little from one PWM period to the next, a floor without the `floor` libcall, and a
//! Gaussian generator (xorshift64* uniforms through a 256-layer ziggurat).
//!
//! Accuracy, argued once here so that the simulator's physics does not change:
//! * [`SinCos::at`] rotates the previous (sin, cos) by the angle step δ = θ − θ_prev, with
//!   sin δ and cos δ from their Taylor series to δ¹¹ and δ¹² (truncation below 3e-18 for
//!   |δ| ≤ 0.25 rad; to δ⁷ and δ⁸ for |δ| ≤ 1/16, below 4e-17), or, when δ is within 1e-8
//!   of the last step so computed, from that step's values to first order (below 1e-16), or,
//!   when δ is within 1e-4 of the last step (a speed that changed a little, the common case of
//!   a structure's rotor), by that step's pair and then by the difference ε with sin ε, cos ε
//!   to ε³ and ε² (below 5e-18), the cached step kept until a step leaves 1e-4 of it;
//!   the first rotation needs only the previous pair, so the angle's path through the period
//!   is the difference's few operations. δ itself is exact (Sterbenz: θ and θ_prev are within a factor 2 of each
//!   other whenever |δ| ≤ 0.25 and |θ| > 0.5; for smaller |θ| the subtraction error is below
//!   1e-17), so the only error is the rounding of the rotations, a few 1e-16 each; after
//!   [`SinCos::REANCHOR`] rotations (or a step over 0.25 rad) the pair is recomputed with the
//!   library's `sin_cos`, so the error never exceeds ≈ 1e-13 — far below anything the
//!   plant's discretisation (1e-8 relative in the energy ledger) can see.
//! * [`Gauss`] is an exact rejection sampler of the standard normal (Marsaglia & Tsang, "The
//!   ziggurat method for generating random variables", J. Stat. Softw. 5(8), 2000), with
//!   Doornik's independence fix (the layer index and the abscissa come from disjoint bits of
//!   one 64-bit draw: Doornik, "An improved ziggurat method to generate normal random
//!   samples", 2005). Its output distribution is N(0, 1) up to the 2⁻⁵³ resolution of the
//!   uniforms; about 99 % of draws cost one xorshift64* step, a table load and a compare.
//!   Its moments and tails are tested below.

use std::sync::OnceLock;

/// Taylor coefficients of sin δ/δ (δ², δ⁴ … δ¹⁰) and of cos δ (δ² … δ¹²).
const S: [f64; 5] = [
    -1.0 / 6.0,
    1.0 / 120.0,
    -1.0 / 5040.0,
    1.0 / 362_880.0,
    -1.0 / 39_916_800.0,
];
const C: [f64; 6] = [
    -1.0 / 2.0,
    1.0 / 24.0,
    -1.0 / 720.0,
    1.0 / 40_320.0,
    -1.0 / 3_628_800.0,
    1.0 / 479_001_600.0,
];

/// sin and cos of a slowly moving angle, updated by rotation.
#[derive(Clone, Copy, Debug)]
pub struct SinCos {
    arg: f64,
    s: f64,
    c: f64,
    n: u32,
    /// The last step computed by series, and its sin and cos.
    step: f64,
    s_step: f64,
    c_step: f64,
}

impl Default for SinCos {
    fn default() -> Self {
        SinCos {
            arg: 0.0,
            s: 0.0,
            c: 1.0,
            n: 0,
            step: 0.0,
            s_step: 0.0,
            c_step: 1.0,
        }
    }
}

impl SinCos {
    /// Rotations between two exact evaluations.
    pub const REANCHOR: u32 = 256;
    /// Largest angle step done by rotation, rad.
    pub const MAX_STEP: f64 = 0.25;
    /// Below this step the short series suffice (sin to δ⁷: truncation < 4e-17).
    const SHORT_STEP: f64 = 0.0625;
    /// A step within this of the cached one reuses its sin/cos to first order (error
    /// ≤ ε²/2 < 1e-16): steady motions (a constant-frequency excitation, a constant speed)
    /// then cost one small rotation.
    const REUSE: f64 = 1e-8;
    /// A step within this of the cached one is done by rotating by the cached step and then
    /// by the difference (series to its cube: truncation < 5e-18).
    const NEAR: f64 = 1e-4;

    /// (sin θ, cos θ).
    ///
    /// The two common cases (a step within [`SinCos::REUSE`] of the cached one, and a short
    /// step) are inline; the long series and the exact re-anchoring are out of line.
    #[inline(always)]
    pub fn at(&mut self, arg: f64) -> (f64, f64) {
        let d = arg - self.arg;
        let e = d - self.step;
        if self.n < Self::REANCHOR && e.abs() <= Self::REUSE {
            let sd = self.s_step + self.c_step * e;
            let cd = self.c_step - self.s_step * e;
            self.rotate(sd, cd);
        } else if self.n < Self::REANCHOR && e.abs() <= Self::NEAR && d.abs() <= Self::SHORT_STEP {
            // A step near the cached one (a speed that changed a little): the pair rotated by
            // the cached step (computable before `arg` is known: off the critical path), then
            // by the small difference e with sin e, cos e to e³ and e² (truncation
            // ≤ e⁴/24 < 5e-18). The cached step stays until a step leaves [`SinCos::NEAR`]
            // of it (the next branch computes the new one by series): the bound holds for any
            // e within `NEAR`, so a slowly changing speed costs one series every
            // `NEAR`/(change of the step per period) periods (≈ 20 at the reference TMD's
            // peak acceleration) instead of one a period.
            let (sp, cp) = (
                self.s * self.c_step + self.c * self.s_step,
                self.c * self.c_step - self.s * self.s_step,
            );
            let e2 = e * e;
            let (sp6, cp6) = (sp * (1.0 / 6.0), cp * (1.0 / 6.0));
            self.s = (sp + cp * e) - e2 * (0.5 * sp + cp6 * e);
            self.c = (cp - sp * e) - e2 * (0.5 * cp - sp6 * e);
            self.n += 1;
        } else if self.n < Self::REANCHOR && d.abs() <= Self::SHORT_STEP {
            let (sd, cd) = Self::short_series(d);
            self.step = d;
            self.s_step = sd;
            self.c_step = cd;
            self.rotate(sd, cd);
        } else {
            self.at_far(arg, d);
        }
        self.arg = arg;
        (self.s, self.c)
    }

    /// sin d and cos d for |d| ≤ [`SinCos::SHORT_STEP`] (to d⁷ and d⁸: truncation < 4e-17).
    #[inline(always)]
    fn short_series(d: f64) -> (f64, f64) {
        let d2 = d * d;
        let d4 = d2 * d2;
        // Estrin's scheme: shorter dependency chains than Horner (the angle is on the
        // period's critical path); coefficients as constants, no division at run time.
        let sd = d * ((1.0 + d2 * S[0]) + d4 * (S[1] + d2 * S[2]));
        let cd = (1.0 + d2 * C[0]) + d4 * ((C[1] + d2 * C[2]) + d4 * C[3]);
        (sd, cd)
    }

    /// [`SinCos::at`] for a step beyond [`SinCos::SHORT_STEP`] (long series) or beyond
    /// [`SinCos::MAX_STEP`] or after [`SinCos::REANCHOR`] rotations (exact).
    #[cold]
    #[inline(never)]
    fn at_far(&mut self, arg: f64, d: f64) {
        if self.n < Self::REANCHOR && d.abs() <= Self::MAX_STEP {
            let d2 = d * d;
            // Horner forms of the Taylor series.
            let sd = d * (1.0 + d2 * (S[0] + d2 * (S[1] + d2 * (S[2] + d2 * (S[3] + d2 * S[4])))));
            let cd = 1.0
                + d2 * (C[0] + d2 * (C[1] + d2 * (C[2] + d2 * (C[3] + d2 * (C[4] + d2 * C[5])))));
            self.step = d;
            self.s_step = sd;
            self.c_step = cd;
            self.rotate(sd, cd);
        } else {
            let (s, c) = arg.sin_cos();
            self.s = s;
            self.c = c;
            self.n = 0;
            // The cached step's pair, rotated by the near steps' differences since it was
            // last computed by series, is recomputed at the next step too.
            self.step = f64::INFINITY;
        }
    }

    #[inline(always)]
    fn rotate(&mut self, sd: f64, cd: f64) {
        let (s, c) = (self.s * cd + self.c * sd, self.c * cd - self.s * sd);
        self.s = s;
        self.c = c;
        self.n += 1;
    }
}

/// ⌊x⌋ modulo 2¹⁶ (two's complement, as a 16-bit hardware counter wraps) for |x| < 2⁵¹,
/// without a libcall or a saturating conversion: adding 1.5·2⁵² rounds x to the nearest
/// integer n in the low mantissa bits (every double in [2⁵², 2⁵³) is an integer), and n − 1
/// is taken when n > x. Beyond 2⁵¹ (or NaN) the result is meaningless but defined.
#[inline(always)]
pub fn floor_wrap_u16(x: f64) -> u16 {
    const M: f64 = 6_755_399_441_055_744.0; // 1.5·2⁵²
    let t = x + M;
    let n = t - M;
    (t.to_bits() as u16).wrapping_sub((n > x) as u16)
}

/// xorshift64* (Vigna 2016): 64-bit state, never zero.
#[inline]
pub fn next_u64(s: &mut u64) -> u64 {
    *s ^= *s >> 12;
    *s ^= *s << 25;
    *s ^= *s >> 27;
    s.wrapping_mul(0x2545_F491_4F6C_DD1D)
}

/// Uniform on (0, 1) from the top 53 bits.
#[inline]
pub fn uniform(s: &mut u64) -> f64 {
    ((next_u64(s) >> 11) as f64 + 0.5) * (1.0 / (1u64 << 53) as f64)
}

const ZIG_N: usize = 256;
/// Right edge of the base layer and the common layer area for 256 layers (Marsaglia & Tsang).
const ZIG_R: f64 = 3.654_152_885_361_009;
const ZIG_V: f64 = 4.928_673_233_99e-3;

struct ZigTables {
    /// Layer edges x[0] (virtual, V/f(R)) … x[256] = 0.
    x: [f64; ZIG_N + 1],
    /// x[i+1]/x[i]: below it a draw lies inside the layer's rectangle.
    r: [f64; ZIG_N],
    /// f(x[i]) = exp(−x[i]²/2).
    f: [f64; ZIG_N + 1],
}

fn tables() -> &'static ZigTables {
    static T: OnceLock<ZigTables> = OnceLock::new();
    T.get_or_init(|| {
        let pdf = |x: f64| (-0.5 * x * x).exp();
        let mut x = [0.0; ZIG_N + 1];
        x[0] = ZIG_V / pdf(ZIG_R);
        x[1] = ZIG_R;
        for i in 2..ZIG_N {
            x[i] = (-2.0 * (ZIG_V / x[i - 1] + pdf(x[i - 1])).ln()).sqrt();
        }
        x[ZIG_N] = 0.0;
        let r = core::array::from_fn(|i| x[i + 1] / x[i]);
        let f = core::array::from_fn(|i| pdf(x[i]));
        ZigTables { x, r, f }
    })
}

/// Standard normal deviates.
#[derive(Clone, Copy)]
pub struct Gauss {
    t: &'static ZigTables,
}

impl std::fmt::Debug for Gauss {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Gauss(ziggurat)")
    }
}

impl Default for Gauss {
    fn default() -> Self {
        Gauss { t: tables() }
    }
}

impl Gauss {
    /// One N(0, 1) deviate, advancing the xorshift64* state `s`.
    #[inline]
    pub fn sample(&self, s: &mut u64) -> f64 {
        let t = self.t;
        loop {
            let b = next_u64(s);
            let i = (b & 0xFF) as usize;
            // Abscissa from the top 53 bits (disjoint from the layer index), in (−1, 1).
            let u = ((b >> 11) as f64 + 0.5) * (2.0 / (1u64 << 53) as f64) - 1.0;
            if u.abs() < t.r[i] {
                return u * t.x[i];
            }
            if let Some(x) = self.slow(s, i, u) {
                return x;
            }
        }
    }

    #[cold]
    fn slow(&self, s: &mut u64, i: usize, u: f64) -> Option<f64> {
        let t = self.t;
        if i == 0 {
            // Tail beyond R (Marsaglia 1964).
            loop {
                let x = uniform(s).ln() / ZIG_R;
                let y = uniform(s).ln();
                if -2.0 * y >= x * x {
                    return Some(if u < 0.0 { x - ZIG_R } else { ZIG_R - x });
                }
            }
        }
        // Wedge between f(x[i]) and f(x[i+1]).
        let x = u * t.x[i];
        let f0 = t.f[i];
        let f1 = t.f[i + 1];
        if f0 + uniform(s) * (f1 - f0) < (-0.5 * x * x).exp() {
            Some(x)
        } else {
            None
        }
    }
}

/// Box–Muller reference (used by the tests to compare against).
#[cfg(test)]
fn box_muller(s: &mut u64) -> f64 {
    let (a, b) = (uniform(s), uniform(s));
    (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_tracks_the_library_sin_cos() {
        // A TMD-like angle history: steps up to the rotation limit, both signs, and jumps.
        let mut sc = SinCos::default();
        let mut th: f64 = 0.0;
        let mut worst: f64 = 0.0;
        for k in 0..200_000u32 {
            let step = if (100_000..150_000).contains(&k) {
                0.01 // a constant speed: the cached step is reused
            } else {
                0.25 * ((k as f64) * 1e-3).sin() * if k % 7 == 0 { -0.3 } else { 1.0 }
            };
            th += if k % 50_000 == 0 { 3.0 } else { step };
            let (s, c) = sc.at(th);
            let (s0, c0) = th.sin_cos();
            worst = worst.max((s - s0).abs()).max((c - c0).abs());
        }
        // The bound argued in the module doc (≈ 1e-13): 256 rotations of a few ulp each.
        assert!(worst < 2e-13, "worst error {worst:e}");
    }

    #[test]
    fn near_steps_track_the_library_sin_cos() {
        // A structure's electrical angle: a sinusoidal motion at 0.5 Hz, 0.3 m/s peak, through
        // the reference screw (1963 rad/m electrical), sampled every 50 µs: the step changes by
        // at most ≈ 5e-6 rad a period, so most rotations take the near path, and the cached
        // step is recomputed by series only when the step has moved 1e-4 from it (at least
        // 20 periods apart: fewer than 1 period in 20 needs the series); over 10⁶ periods
        // (the cached step's pair rotated by the differences between re-anchorings) the pair
        // stays within the module's bound.
        let mut sc = SinCos::default();
        let (w, a, k) = (std::f64::consts::PI, 0.3 / std::f64::consts::PI, 1963.5);
        let mut worst: f64 = 0.0;
        let mut last = 0.0;
        let (mut near, mut series) = (0, 0);
        for n in 0..1_000_000u32 {
            let t = n as f64 * 50e-6;
            let th = k * a * (w * t).sin();
            let d = th - last;
            last = th;
            let before = sc.step;
            let (s, c) = sc.at(th);
            let e = d - before;
            if e.abs() > SinCos::REUSE && e.abs() <= SinCos::NEAR {
                near += 1;
            }
            series += (sc.step.to_bits() != before.to_bits()) as u32;
            let (s0, c0) = th.sin_cos();
            worst = worst.max((s - s0).abs()).max((c - c0).abs());
        }
        println!("near-path rotations {near}, series {series}, worst error {worst:e}");
        assert!(near > 900_000, "near-path rotations {near}");
        assert!(series < 50_000, "series evaluations {series}");
        assert!(worst < 2e-13, "worst error {worst:e}");
    }

    #[test]
    fn floor_wrap_matches_std_over_the_counter_range() {
        // Both sides of every integer within a few counter wraps, ties (n + ½, where
        // round-to-nearest-even goes either way) and the largest exact fractions.
        for k in -200_000i64..200_000 {
            for x in [
                k as f64,
                k as f64 + 0.5,
                k as f64 - 1e-9,
                k as f64 + 1e-9,
                k as f64 + 0.999_999_9,
            ] {
                assert_eq!(floor_wrap_u16(x), x.floor() as i64 as u16, "{x}");
            }
        }
        for x in [2f64.powi(50) + 0.5, -(2f64.powi(50)) - 0.5, 1e15 + 0.25] {
            assert_eq!(floor_wrap_u16(x), x.floor() as i64 as u16, "{x}");
        }
    }

    #[test]
    fn floor_matches_std() {
        for x in [
            -2.5,
            -2.0,
            -1e-300,
            -0.0,
            0.0,
            0.3,
            1.0,
            7.999_999_999,
            -7.000_000_1,
            1e15 + 0.5,
        ] {
            assert_eq!(floor_wrap_u16(x), x.floor() as i64 as u16, "{x}");
        }
    }

    #[test]
    fn ziggurat_is_standard_normal() {
        // n = 2e6 draws. Standard errors: mean 1/√n = 7e-4, variance √(2/n) = 1e-3, fourth
        // moment √(96/n) = 7e-3; the bounds are 5 standard errors (a false failure has
        // probability < 1e-6 for a correct sampler, and the seed is fixed anyway). Tail
        // fractions beyond 2σ, 3σ, 4σ (0.0455, 0.0027, 6.3e-5 two-sided) within 5 binomial
        // standard errors. The same checks on Box–Muller confirm the statistics themselves.
        let n = 2_000_000;
        for which in 0..2 {
            let g = Gauss::default();
            let mut s = 0x1234_5678_9ABC_DEF1u64;
            let (mut m1, mut m2, mut m4) = (0.0, 0.0, 0.0);
            let mut tails = [0usize; 3];
            for _ in 0..n {
                let x = if which == 0 {
                    g.sample(&mut s)
                } else {
                    box_muller(&mut s)
                };
                m1 += x;
                m2 += x * x;
                m4 += x * x * x * x;
                for (k, t) in tails.iter_mut().enumerate() {
                    if x.abs() > (k + 2) as f64 {
                        *t += 1;
                    }
                }
            }
            let nf = n as f64;
            let (m1, m2, m4) = (m1 / nf, m2 / nf, m4 / nf);
            assert!(m1.abs() < 5.0 * (1.0 / nf).sqrt(), "{which}: mean {m1}");
            assert!(
                (m2 - 1.0).abs() < 5.0 * (2.0 / nf).sqrt(),
                "{which}: var {m2}"
            );
            assert!(
                (m4 - 3.0).abs() < 5.0 * (96.0 / nf).sqrt(),
                "{which}: m4 {m4}"
            );
            for (k, p) in [0.045_500_263_9, 0.002_699_796_1, 6.334_248_4e-5]
                .iter()
                .enumerate()
            {
                let f = tails[k] as f64 / nf;
                let se = (p * (1.0 - p) / nf).sqrt();
                assert!(
                    (f - p).abs() < 5.0 * se,
                    "{which}: tail {} σ: {f} vs {p}",
                    k + 2
                );
            }
        }
    }

    #[test]
    fn ziggurat_layers_have_equal_area() {
        // Every layer (rectangle x[i]·(f(x[i+1]) − f(x[i]))) has the common area V, and the
        // top edge reaches f = 1 (x[256] = 0): the recursion closes.
        let t = tables();
        for i in 1..ZIG_N - 1 {
            let a = t.x[i] * (t.f[i + 1] - t.f[i]);
            assert!((a - ZIG_V).abs() < 1e-9 * ZIG_V.max(a), "layer {i}: {a}");
        }
        let last = t.x[ZIG_N - 1] * (1.0 - t.f[ZIG_N - 1]);
        assert!((last - ZIG_V).abs() < 1e-6, "top layer {last}");
    }
}
