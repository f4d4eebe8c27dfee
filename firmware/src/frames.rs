//! Clarke and Park transforms, amplitude-invariant, and their inverses.
//!
//! * Clarke: `α = (2a − b − c)/3`, `β = (b − c)/√3`. The three-current form rejects a common
//!   offset on all three sensors; for a balanced set (`a+b+c = 0`) it equals `α = a`,
//!   `β = (a + 2b)/√3`.
//! * Park with the d-axis at angle θ: `d = α·cosθ + β·sinθ`, `q = −α·sinθ + β·cosθ`.
//! * A balanced set of peak `I` at angle φ (`a = I·cos φ`, …) gives `|(α, β)| = I`.

use crate::fx::{mul, mulhs, sat_i32, Angle, Q};

/// Stationary-frame vector.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct AlphaBeta {
    pub alpha: Q,
    pub beta: Q,
}

/// Rotor-frame vector.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Dq {
    pub d: Q,
    pub q: Q,
}

// Constants with 30 fractional bits (relative error < 1e-9).
const ONE_THIRD: i64 = 357_913_941; // 1/3
const INV_SQRT3: i64 = 619_925_131; // 1/√3
const SQRT3_2: i64 = 929_887_697; // √3/2

/// `x·k/2^30`, saturated.
#[inline(always)]
fn mulk(x: i64, k: i64) -> Q {
    Q::from_bits(sat_i32((x * k) >> 30))
}

/// Amplitude-invariant Clarke transform of three phase quantities.
#[inline(always)]
pub fn clarke(a: Q, b: Q, c: Q) -> AlphaBeta {
    let (a, b, c) = (a.to_bits() as i64, b.to_bits() as i64, c.to_bits() as i64);
    AlphaBeta {
        alpha: mulk(2 * a - b - c, ONE_THIRD),
        beta: mulk(b - c, INV_SQRT3),
    }
}

/// Inverse Clarke: phase quantities (a, b, c) with zero sum.
#[inline(always)]
pub fn inverse_clarke(v: AlphaBeta) -> [Q; 3] {
    let half_a = Q::from_bits(v.alpha.to_bits() >> 1); // α/2, floored
    let sb = mulk(v.beta.to_bits() as i64, SQRT3_2);
    [
        v.alpha,
        sb.saturating_sub(half_a),
        (-half_a).saturating_sub(sb),
    ]
}

/// Park transform with (sin θ, cos θ).
#[inline(always)]
pub fn park(v: AlphaBeta, sin: Q, cos: Q) -> Dq {
    Dq {
        d: mul(v.alpha, cos).saturating_add(mul(v.beta, sin)),
        q: mul(v.beta, cos).saturating_sub(mul(v.alpha, sin)),
    }
}

/// Inverse Park transform with (sin θ, cos θ).
#[inline(always)]
pub fn inverse_park(v: Dq, sin: Q, cos: Q) -> AlphaBeta {
    AlphaBeta {
        alpha: mul(v.d, cos).saturating_sub(mul(v.q, sin)),
        beta: mul(v.d, sin).saturating_add(mul(v.q, cos)),
    }
}

/// Largest vector length (LSB) the unsaturated rotations below accept: 2^31 − 2^19 (32,760 A
/// or V). A rotation by table (sin, cos) scales a vector by at most 1 + 4e-5 (< 2^19/2^31),
/// so every output stays below 2^31.
pub const ROTATE_BOUND: i64 = (1 << 31) - (1 << 19);

#[inline(always)]
fn within_bound(x: Q, y: Q) -> bool {
    let (x, y) = (x.to_bits() as i64, y.to_bits() as i64);
    x * x + y * y <= ROTATE_BOUND * ROTATE_BOUND
}

/// `(x·c + y·s) >> 16` in one 64-bit accumulation (multiply, multiply-accumulate, shift).
#[inline(always)]
fn dot(x: Q, c: Q, y: Q, s: Q) -> Q {
    let w =
        (x.to_bits() as i64 * c.to_bits() as i64 + y.to_bits() as i64 * s.to_bits() as i64) >> 16;
    debug_assert!(w == w as i32 as i64, "rotation out of range");
    Q::from_bits(w as i32)
}

/// [`park`] without saturation, for `|(α, β)| ≤ ROTATE_BOUND` (and `(sin, cos)` from
/// [`crate::fx::Angle::sin_cos`]): the result has the length of the input within 4e-5, so it
/// fits; the sum is formed before the one rounding shift.
#[inline(always)]
pub fn park_bounded(v: AlphaBeta, sin: Q, cos: Q) -> Dq {
    debug_assert!(within_bound(v.alpha, v.beta));
    Dq {
        d: dot(v.alpha, cos, v.beta, sin),
        q: dot(v.beta, cos, -v.alpha, sin),
    }
}

/// [`inverse_park`] without saturation, for `|(d, q)| ≤ ROTATE_BOUND` (see [`park_bounded`]).
#[inline(always)]
pub fn inverse_park_bounded(v: Dq, sin: Q, cos: Q) -> AlphaBeta {
    debug_assert!(within_bound(v.d, v.q));
    AlphaBeta {
        alpha: dot(v.d, cos, -v.q, sin),
        beta: dot(v.d, sin, v.q, cos),
    }
}

/// A rotation by a fixed angle `a`, kept as `(cos a, sin a, −sin a)` in Q2.30 (from the
/// table of [`Angle::sin_cos`], exactly its values shifted left by 14), for the angle-sum
/// formulas of [`Rotation::rotate`]. The default is the identity.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rotation {
    c: i32,
    s: i32,
    ns: i32,
}

impl Default for Rotation {
    fn default() -> Rotation {
        Rotation {
            c: 1 << 30,
            s: 0,
            ns: 0,
        }
    }
}

impl Rotation {
    /// The rotation by `a`.
    pub fn of(a: Angle) -> Rotation {
        let (s, c) = a.sin_cos();
        // Table values are within ±2^16: the shifted ones within ±2^30.
        let (s, c) = (s.to_bits() << 14, c.to_bits() << 14);
        Rotation { c, s, ns: -s }
    }

    /// `(sin(θ + a), cos(θ + a))` from `(sin θ, cos θ)` of [`Angle::sin_cos`]:
    /// `sin θ·cos a + cos θ·sin a` and `cos θ·cos a − sin θ·sin a`, each as two high-word
    /// products (`SMMUL`, `SMMLA`) of `4·sin θ` or `4·cos θ` (< 2^19) by the Q2.30 constants.
    /// Every term is below 2^16·(1 + 4e-5) in magnitude: no overflow. Each product floors
    /// (< 1 LSB), so the result is within 2 LSB (3e-5) of the exact products of the tables'
    /// values: the pair has the length 1 within 4e-5 (θ's table) + 4e-5 (a's) + 3e-5.
    #[inline(always)]
    pub fn rotate(self, sin: Q, cos: Q) -> (Q, Q) {
        let (s4, c4) = (sin.to_bits() << 2, cos.to_bits() << 2);
        (
            Q::from_bits(mulhs(s4, self.c) + mulhs(c4, self.s)),
            Q::from_bits(mulhs(c4, self.c) + mulhs(s4, self.ns)),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fx::{q, Angle};
    use proptest::prelude::*;

    fn f(x: Q) -> f64 {
        x.to_num()
    }

    proptest! {
        #[test]
        fn balanced_set_has_invariant_amplitude(amp in 0.0f64..500.0, phi in 0.0f64..core::f64::consts::TAU) {
            use core::f64::consts::TAU;
            let a = amp * phi.cos();
            let b = amp * (phi - TAU / 3.0).cos();
            let c = amp * (phi + TAU / 3.0).cos();
            let ab = clarke(q(a as f32), q(b as f32), q(c as f32));
            let mag = (f(ab.alpha).powi(2) + f(ab.beta).powi(2)).sqrt();
            // f32 input rounding (6e-8 relative) plus three Q16.16 roundings (≤ 4e-5 A).
            prop_assert!((mag - amp).abs() < 1e-4 + amp * 1e-6, "{mag} vs {amp}");
            // Angle of the vector is φ.
            if amp > 1.0 {
                let ang = f(ab.beta).atan2(f(ab.alpha));
                let d = (ang - phi + 3.0 * core::f64::consts::PI).rem_euclid(TAU) - core::f64::consts::PI;
                prop_assert!(d.abs() < 1e-3 / amp + 1e-6);
            }
        }

        #[test]
        fn park_round_trip(al in -1000.0f32..1000.0, be in -1000.0f32..1000.0, th in any::<u32>()) {
            let (s, c) = Angle(th).sin_cos();
            let v = AlphaBeta { alpha: q(al), beta: q(be) };
            let back = inverse_park(park(v, s, c), s, c);
            // sin²+cos² of the table is 1 within 4e-5, times |v| ≤ 1415, plus roundings.
            let tol = 1415.0 * 8e-5 + 1e-3;
            prop_assert!((f(back.alpha) - al as f64).abs() < tol);
            prop_assert!((f(back.beta) - be as f64).abs() < tol);
        }

        #[test]
        fn clarke_round_trip(al in -1000.0f32..1000.0, be in -1000.0f32..1000.0) {
            let v = AlphaBeta { alpha: q(al), beta: q(be) };
            let [a, b, c] = inverse_clarke(v);
            let back = clarke(a, b, c);
            prop_assert!((f(back.alpha) - al as f64).abs() < 1e-3);
            prop_assert!((f(back.beta) - be as f64).abs() < 1e-3);
            prop_assert!((f(a) + f(b) + f(c)).abs() < 1e-3);
        }

        #[test]
        fn bounded_rotations_equal_the_saturating_ones(r in 0.0f64..=1.0, phi in 0.0f64..core::f64::consts::TAU, th in any::<u32>()) {
            // Same products, one rounding instead of two: within 1 LSB of the saturating
            // forms (which cannot saturate here), and no overflow up to the bound itself.
            let len = if r > 0.9 { ROTATE_BOUND as f64 } else { r * ROTATE_BOUND as f64 };
            let (a, b) = ((len * phi.cos()) as i32, (len * phi.sin()) as i32);
            let (s, c) = Angle(th).sin_cos();
            let v = AlphaBeta { alpha: Q::from_bits(a), beta: Q::from_bits(b) };
            let (x, y) = (park_bounded(v, s, c), park(v, s, c));
            prop_assert!((x.d.to_bits() as i64 - y.d.to_bits() as i64).abs() <= 1);
            prop_assert!((x.q.to_bits() as i64 - y.q.to_bits() as i64).abs() <= 1);
            let w = Dq { d: Q::from_bits(a), q: Q::from_bits(b) };
            let (x, y) = (inverse_park_bounded(w, s, c), inverse_park(w, s, c));
            prop_assert!((x.alpha.to_bits() as i64 - y.alpha.to_bits() as i64).abs() <= 1);
            prop_assert!((x.beta.to_bits() as i64 - y.beta.to_bits() as i64).abs() <= 1);
        }

        #[test]
        fn rotation_is_the_angle_sum(th in any::<u32>(), a in any::<u32>()) {
            // Each table value is within ε = 1.9e-5 + 2^-15 of the exact (the bound of
            // `sin_cos_table_accuracy`); each of the two products per output then errs by at
            // most ε·(|x| + |y|), and |sin| + |cos| ≤ √2 for both angles: 2√2·ε in all, plus
            // the two floors (2 LSB = 3.1e-5): 1.8e-4.
            let (s, c) = Angle(th).sin_cos();
            let (s2, c2) = Rotation::of(Angle(a)).rotate(s, c);
            let x = Angle(th.wrapping_add(a)).radians();
            prop_assert!((f(s2) - x.sin()).abs() < 1.8e-4, "{} vs {}", f(s2), x.sin());
            prop_assert!((f(c2) - x.cos()).abs() < 1.8e-4, "{} vs {}", f(c2), x.cos());
            // The identity leaves the pair exactly as it was.
            prop_assert_eq!(Rotation::default().rotate(s, c), (s, c));
            prop_assert_eq!(Rotation::of(Angle(0)), Rotation::default());
        }

        #[test]
        fn extreme_inputs_saturate(a in any::<i32>(), b in any::<i32>(), c in any::<i32>(), th in any::<u32>()) {
            // Must not panic (overflow checks are on in tests) for any bits at all.
            let ab = clarke(Q::from_bits(a), Q::from_bits(b), Q::from_bits(c));
            let (s, co) = Angle(th).sin_cos();
            let dq = park(ab, s, co);
            let _ = inverse_clarke(inverse_park(dq, s, co));
        }
    }

    #[test]
    fn rotor_frame_of_a_balanced_set_is_constant() {
        // Currents rotating with the d axis at θ, amplitude 10 A on q only.
        for k in 0..64u32 {
            let th = Angle(k.wrapping_mul(67_108_864));
            let r = th.radians();
            let i = |shift: f64| q((-10.0 * (r - shift).sin()) as f32);
            let ab = clarke(
                i(0.0),
                i(core::f64::consts::TAU / 3.0),
                i(-core::f64::consts::TAU / 3.0),
            );
            let (s, c) = th.sin_cos();
            let dq = park(ab, s, c);
            assert!(f(dq.d).abs() < 2e-3, "d = {}", f(dq.d));
            assert!((f(dq.q) - 10.0).abs() < 2e-3, "q = {}", f(dq.q));
        }
    }
}
