//! Proportional-integral current controllers for the d and q axes, with the output vector
//! limited to what the bus can produce and anti-windup by back-calculation.
//!
//! Gains follow the usual pole-zero cancellation design (VESC, ODrive, SimpleFOC):
//! `Kp = L·ωc`, `Ki = R·ωc`, so that with the plant `1/(R + sL)` the closed loop is the
//! first-order `ωc/(s + ωc)`. In discrete time the integral gain per step is `Ki·Ts`.

use crate::frames::Dq;
use crate::fx::{clamp_sym, sqrt_newton, Q};

/// Gains of one axis, as the update multiplies by them (`f32`, held as bits so that the
/// struct stays `Eq`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct PiGains {
    /// Proportional gain, V/A.
    kp: u32,
    /// Integral gain times the step, V/A per step.
    ki_ts: u32,
}

impl PiGains {
    /// The gains `kp` (V/A) and `ki_ts` (V/A per step); a non-finite one counts as zero.
    pub fn new(kp: f32, ki_ts: f32) -> PiGains {
        let finite = |v: f32| if v.is_finite() { v } else { 0.0 };
        PiGains {
            kp: finite(kp).to_bits(),
            ki_ts: finite(ki_ts).to_bits(),
        }
    }

    /// Proportional gain, V/A.
    #[inline(always)]
    pub fn kp(&self) -> f32 {
        f32::from_bits(self.kp)
    }

    /// Integral gain times the step, V/A per step.
    #[inline(always)]
    pub fn ki_ts(&self) -> f32 {
        f32::from_bits(self.ki_ts)
    }
}

/// State of the two axes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct CurrentPi {
    /// Integrator outputs (V).
    pub integ: Dq,
}

/// Result of one controller update.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct PiOutput {
    /// Voltage command, limited to `v_max`.
    pub v: Dq,
    /// The unlimited command was not within `7.2e-7·v_max` inside `v_max` and was scaled
    /// into it.
    pub saturated: bool,
}

/// The allowed voltage circle: radius `r ≥ 0` (LSB of [`Q`]), and as `f32` the test's
/// threshold `r²·(1 − 2^-20)` and the scaling's radius `r·(1 − 2^-19)` (the loop holds them
/// between bus refreshes; as bits, so that the struct stays `Eq`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct VLimit {
    r: u32,
    r2_in: u32,
    r_in: u32,
}

/// The test's threshold on `|v|²` and the scaling's target radius, relative to the circle's
/// (`1 − 2^-20` and `1 − 2^-19`, exact in `f32`): they cover the roundings (`limit_slow`), so
/// that a vector the test passes lies inside the circle and a limited one is inside it and
/// never longer than it was.
const R2_IN: f32 = 1.0 - 1.0 / 1_048_576.0;
const R_IN: f32 = 1.0 - 1.0 / 524_288.0;

impl VLimit {
    /// The circle of radius `v_max` (negative radii count as zero).
    pub fn new(v_max: Q) -> VLimit {
        let r = v_max.to_bits().max(0) as u32;
        let rf = r as f32;
        VLimit {
            r,
            r2_in: (rf * rf * R2_IN).to_bits(),
            r_in: (rf * R_IN).to_bits(),
        }
    }

    /// The radius.
    pub fn radius(&self) -> Q {
        Q::from_bits(self.r as i32)
    }

    /// `v` scaled into the circle when it does not lie within `7.2e-7·r` inside it; `None`
    /// when it does (then it lies inside: `limit_slow`).
    #[inline(always)]
    pub fn limit(&self, v: Dq) -> Option<Dq> {
        self.limit_f32(v.d.to_bits() as f32, v.q.to_bits() as f32)
    }

    /// [`VLimit::limit`] of the vector `(x, y)` (LSB of [`Q`], finite or not) given in
    /// `f32`: `None` when it lies within the circle (then `(x as i32, y as i32)`, truncated
    /// toward zero, lies inside too).
    #[inline(always)]
    pub fn limit_f32(&self, x: f32, y: f32) -> Option<Dq> {
        let s = x * x + y * y;
        if s <= f32::from_bits(self.r2_in) {
            return None;
        }
        Some(limit_slow(x, y, s, f32::from_bits(self.r_in)))
    }
}

impl CurrentPi {
    /// One update. `err` = reference − measurement (A); `ff` = feed-forward voltages (V);
    /// `v_max` ≥ 0 the radius of the allowed voltage circle (V).
    #[inline(always)]
    pub fn update(&mut self, err: Dq, ff: Dq, g: &PiGains, v_max: Q) -> PiOutput {
        self.update_within(err, ff, g, &VLimit::new(v_max))
    }

    /// [`CurrentPi::update`] with the voltage circle given as a [`VLimit`].
    ///
    /// In `f32` on the FPU, in LSB of [`Q`] (2^-16 V, 2^-16 A): the integrators' next values
    /// `integ + ki_ts·err` and the output `kp·err + ff + next`, then the limiter's test on that
    /// output as it is. No sum saturates on the way: with validated gains (`kp` ≤ 1 H ×
    /// 2π·5 kHz, `ki_ts` ≤ 100 Ω × 0.6 per step) and any `i32` inputs every term is below
    /// 2^47 LSB and `|v|²` below 2^96, far inside `f32`'s range; unvalidated gains at worst
    /// give an infinite or NaN sum, which the limiter and the conversions turn into finite
    /// bits (no panic). Each value back to [`Q`] is truncated toward zero and saturates
    /// (`as i32`): a `next` beyond ±32,768 V holds there, as a saturating sum would. Below
    /// 256 V (2^24 LSB) the integrators convert exactly and keep Q16.16's resolution; above
    /// it theirs is `f32`'s, 2^-24 of their value.
    /// IEEE 754 rounds each `+` and `×` correctly and Rust contracts no `a·b + c`, so the
    /// host and the Cortex-M4F give the same bits.
    #[inline(always)]
    pub fn update_within(&mut self, err: Dq, ff: Dq, g: &PiGains, lim: &VLimit) -> PiOutput {
        let (ed, eq) = (err.d.to_bits() as f32, err.q.to_bits() as f32);
        let (kp, ki) = (g.kp(), g.ki_ts());
        let nd = self.integ.d.to_bits() as f32 + ki * ed;
        let nq = self.integ.q.to_bits() as f32 + ki * eq;
        let x = kp * ed + ff.d.to_bits() as f32 + nd;
        let y = kp * eq + ff.q.to_bits() as f32 + nq;
        match lim.limit_f32(x, y) {
            None => {
                self.integ = Dq {
                    d: Q::from_bits(nd as i32),
                    q: Q::from_bits(nq as i32),
                };
                PiOutput {
                    v: Dq {
                        d: Q::from_bits(x as i32),
                        q: Q::from_bits(y as i32),
                    },
                    saturated: false,
                }
            }
            Some(v) => {
                // Anti-windup by conditional integration: while the output is limited the
                // integrators hold (they do not integrate), and they never exceed the limit.
                let r = lim.radius();
                self.integ = Dq {
                    d: clamp_sym(self.integ.d, r),
                    q: clamp_sym(self.integ.q, r),
                };
                PiOutput { v, saturated: true }
            }
        }
    }

    /// Reset both integrators.
    pub fn reset(&mut self) {
        self.integ = Dq::default();
    }
}

/// Scale `v` onto the circle of radius `r` when it lies outside; `None` when inside.
#[inline]
pub fn limit_vector(v: Dq, r: Q) -> Option<Dq> {
    VLimit::new(r).limit(v)
}

/// The test and the scaling, in `f32` (the scaling taken only while limiting; inlined: it is
/// short): `s = x² + y²` of the converted components against `r²·(1 − 2^-20)`, and `k =
/// r'/|v|` (`r' = r·(1 − 2^-19)`, both held by [`VLimit`]; `|v|` by two Newton steps,
/// [`sqrt_newton`]), each component `x·k` truncated toward zero. IEEE 754 rounds `+ × ÷` and
/// the conversions correctly, and Rust contracts no `a·b + c`, so the host and the
/// Cortex-M4F give the same bits.
///
/// With `u = 2^-24`, to first order: the conversions of d, q and r are within `u` of them
/// (exact below 2^24), `s` within `4u` of `|v|²`, the threshold within `4u` of
/// `r²·(1 − 16u)`: a vector the test passes has `|v|² ≤ r²(1 − 12u)/(1 − 4u)`, inside the
/// circle, and a limited one `|v| > r(1 − 12u)` (so `s ≥ 1`: no NaN). The square root is
/// within `[−3.5u, +10.9u]` of `|v|` (the two steps' error and half of `s`'s), `r'` within `2u`
/// of `r(1 − 32u)`, `k` within `[−13.9u, +6.5u]` of `r(1 − 32u)/|v|`, each product within
/// `[−15.9u, +8.5u]` of the exact scaled component times `1 − 32u`: each component is scaled by
/// at most `(1 − 32u)(1 + 8.5u)/(1 − 12u) < 1` (never longer than it was), and the length lies
/// in `r·[1 − 48u, 1 − 23.5u]`, inside the circle. Truncation toward zero moves each component
/// by less than 1 LSB toward zero: the result's length is in `(r·(1 − 48u) − √2, r)`, within
/// `2.9e-6·r + √2` LSB of the circle. `|x·k| < r ≤ 2^31 − 1` converts exactly (`i32::MIN`
/// components included; the conversion saturates anyway).
#[inline(always)]
fn limit_slow(x: f32, y: f32, s: f32, r_in: f32) -> Dq {
    let k = r_in / sqrt_newton::<2>(s);
    Dq {
        d: Q::from_bits((x * k) as i32),
        q: Q::from_bits((y * k) as i32),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fx::q;
    use proptest::prelude::*;
    use std::vec::Vec;

    /// The seeded tests' 64-bit xorshift stream from `s` (not 0).
    fn xorshift(mut s: u64) -> impl FnMut() -> u64 {
        move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        }
    }

    /// Discrete simulation of one axis: plant L di/dt = v − R i (exact zero-order-hold
    /// discretisation), controller gains from R, L and ωc.
    fn step_response(
        r: f64,
        l: f64,
        wc: f64,
        ts: f64,
        i_ref: f64,
        v_max: f64,
        n: usize,
    ) -> Vec<f64> {
        let g = PiGains::new((l * wc) as f32, (r * wc * ts) as f32);
        let mut pi = CurrentPi::default();
        let a = (-r / l * ts).exp();
        let mut i = 0.0f64;
        let mut out = Vec::with_capacity(n);
        for _ in 0..n {
            let e = q(i_ref as f32) - q(i as f32);
            let o = pi.update(Dq { d: Q::ZERO, q: e }, Dq::default(), &g, q(v_max as f32));
            let v = o.v.q.to_num::<f64>();
            i = a * i + (1.0 - a) * v / r;
            out.push(i);
        }
        out
    }

    #[test]
    fn step_matches_first_order_closed_loop() {
        // AKM42E-like: R = 2.41 Ω, L = 5 mH; 1 kHz bandwidth at 20 kHz.
        let (r, l, ts) = (2.41, 5e-3, 5e-5);
        let wc = 2.0 * core::f64::consts::PI * 1000.0;
        let resp = step_response(r, l, wc, ts, 10.0, 1e4, 200);
        // Pole-zero cancellation makes the continuous closed loop 1 − e^{−ωc t}. The sampled
        // loop (control applied one step after the error, ZOH) deviates by O(ωc·Ts) = 0.31:
        // bound it by that fraction of the amplitude.
        let mut worst = 0.0f64;
        for (k, i) in resp.iter().enumerate() {
            let t = (k + 1) as f64 * ts;
            let ideal = 10.0 * (1.0 - (-wc * t).exp());
            worst = worst.max((i - ideal).abs());
        }
        assert!(worst < 10.0 * wc * ts, "worst deviation {worst} A");
        // Time constant: 63 % reached within one step of 1/ωc (159 µs ≈ 3.2 steps).
        let k63 = resp.iter().position(|&i| i >= 6.32).unwrap();
        let tau_steps = 1.0 / (wc * ts);
        assert!(
            (k63 as f64 - tau_steps).abs() <= 1.5,
            "63 % at step {k63}, τ = {tau_steps}"
        );
        // No steady-state error (integral action), within Q16.16 resolution.
        assert!((resp[199] - 10.0).abs() < 1e-3);
    }

    #[test]
    fn anti_windup_recovers_quickly() {
        // A 10 A request against a 5 V limit (max current 5/2.41 = 2.07 A) for 2000 steps,
        // then the request drops to 1 A (reachable). Without anti-windup the integrator would
        // hold Ki·Ts·Σerr ≈ 12 kV and take seconds to unwind; with it the integrator stays
        // within the limit, and what remains after saturation is an integrator mismatch of at
        // most the limit, which the pole-zero-cancelled loop removes at the plant's own rate
        // R/L. So: within 5 % of 1 A after 10 loop time constants plus 5 plant time
        // constants (e^-5 < 1 % of the mismatch).
        let (r, l, ts) = (2.41, 5e-3, 5e-5);
        let wc = 2.0 * core::f64::consts::PI * 1000.0;
        let g = PiGains::new((l * wc) as f32, (r * wc * ts) as f32);
        let mut pi = CurrentPi::default();
        let a = (-r / l * ts).exp();
        let mut i = 0.0f64;
        let run = |pi: &mut CurrentPi, i_ref: f64, n: usize, i: &mut f64| {
            for _ in 0..n {
                let e = q(i_ref as f32) - q(*i as f32);
                let o = pi.update(Dq { d: Q::ZERO, q: e }, Dq::default(), &g, q(5.0));
                assert!(o.v.q.to_num::<f64>().abs() <= 5.0 + 1e-3);
                *i = a * *i + (1.0 - a) * o.v.q.to_num::<f64>() / r;
            }
        };
        run(&mut pi, 10.0, 2000, &mut i);
        assert!((i - 5.0 / r).abs() < 0.01, "saturated current {i}");
        assert!(
            pi.integ.q.to_num::<f64>().abs() <= 5.0 + 1e-3,
            "integrator wound up"
        );
        let settle = ((10.0 / wc + 5.0 * l / r) / ts).ceil() as usize;
        run(&mut pi, 1.0, settle, &mut i);
        assert!((i - 1.0).abs() < 0.05, "after recovery {i}");
    }

    /// The limiter's proven bounds (`limit_slow`), checked on one input, in LSB and in `f64`
    /// from the bits (the reference shares nothing with the `f32` code): a vector passed
    /// inside the circle, a limited one not within `12u·r` inside it (`u = 2^-24`), the
    /// result inside the circle, within `48u·r + √2` of it, never longer than the input, the
    /// direction kept
    /// (the component across the input within `2u·r + 1.5`: only the roundings
    /// that differ between the components turn it, the conversions' and the products', each
    /// ≤ `u` of its component, and the truncations). Returns how far inside the circle the result lies,
    /// relative to `r`, and its component across the input in LSB.
    fn check_limited(d: i32, qq: i32, r: i32) -> Option<(f64, f64)> {
        let v = Dq {
            d: Q::from_bits(d),
            q: Q::from_bits(qq),
        };
        let (fd, fq, rf) = (d as f64, qq as f64, r.max(0) as f64);
        let vm = (fd * fd + fq * fq).sqrt();
        let Some(l) = limit_vector(v, Q::from_bits(r)) else {
            let v2 = d as i128 * d as i128 + qq as i128 * qq as i128;
            assert!(
                v2 <= rf as i128 * rf as i128,
                "{d} {qq} {r}: inside but |v| = {vm}"
            );
            return None;
        };
        let (ld, lq) = (l.d.to_bits() as f64, l.q.to_bits() as f64);
        let m = (ld * ld + lq * lq).sqrt();
        // Limited only when not within 12u of the circle inside it.
        assert!(
            vm > rf * (1.0 - 12.0 * 0.5f64.powi(24)),
            "{d} {qq} {r}: limited inside"
        );
        assert!(m <= rf, "{d} {qq} {r}: {m} outside");
        assert!(
            m >= rf * (1.0 - 3.0 * 0.5f64.powi(20)) - 2f64.sqrt(),
            "{d} {qq} {r}: {m}"
        );
        assert!(m <= vm, "{d} {qq} {r}: longer");
        let across = (fd * lq - fq * ld).abs() / vm;
        assert!(
            across <= 2.0 * 0.5f64.powi(24) * rf + 1.5,
            "{d} {qq} {r}: across {across}"
        );
        assert!(fd * ld + fq * lq >= 0.0, "{d} {qq} {r}: reversed");
        Some(((rf - m) / rf.max(1.0), across))
    }

    proptest! {
        #[test]
        fn limit_keeps_direction_and_radius(d in any::<i32>(), qq in any::<i32>(), r in 0.0f32..1000.0) {
            check_limited(d, qq, q(r).to_bits());
        }

        #[test]
        fn pi_never_panics(ed in any::<i32>(), eq in any::<i32>(), kp in -1e6f32..1e6, ki in -1e6f32..1e6, vm in any::<i32>()) {
            let g = PiGains::new(kp, ki);
            let mut pi = CurrentPi::default();
            for _ in 0..3 {
                let _ = pi.update(Dq { d: Q::from_bits(ed), q: Q::from_bits(eq) }, Dq { d: Q::MAX, q: Q::MIN }, &g, Q::from_bits(vm));
            }
        }
    }

    #[test]
    fn limit_at_the_normalisation_edges() {
        // Powers of two, their neighbours, −2^31 and zero, in every pairing, against radii
        // from 1 LSB to 30,000 V: the bounds of `check_limited`.
        let mut xs = std::vec![0i32, 1, -1, i32::MIN, i32::MAX, i32::MIN + 1];
        for k in 0..31 {
            let p = 1i32 << k;
            xs.extend([p, -p, p - 1, -(p - 1), p + 1, -(p + 1)]);
        }
        for &d in &xs {
            for &qq in &xs {
                for r in [
                    1i32,
                    3,
                    1 << 10,
                    1 << 16,
                    12_345_678,
                    30_000 << 16,
                    i32::MAX,
                ] {
                    check_limited(d, qq, r);
                }
            }
        }
    }

    #[test]
    fn limit_error_distribution() {
        // Seeded inputs of every size (a component of up to 31 bits, a radius below it),
        // each through `check_limited`; printed: how far inside the circle the limited
        // vector lies relative to r, for r ≥ 2^24 (where the truncation's ≤ √2 LSB is below
        // 8.5e-8 of r: the deliberate 2^-19 = 1.9e-6 and the roundings; the bound 48u =
        // 2.9e-6), and the largest component across the input (bound 2u·r + 1.5 LSB).
        let mut next = xorshift(0x9e37_79b9_7f4a_7c15);
        let (mut inside, mut across) = (std::vec::Vec::new(), 0.0f64);
        while inside.len() < 100_000 {
            let (a, b) = (next(), next());
            let sh = (a >> 59) as u32; // 0 … 31 bits
            let d = ((a as i32) >> sh) as i64;
            let qq = ((b as i32) >> (b >> 59) as u32) as i64;
            let vm = ((d * d + qq * qq) as f64).sqrt();
            // r from 16 LSB up to |v| (those below 2^-5 of |v| are mostly the 1-LSB floor).
            let r = (vm * (0.03 + 0.97 * (next() >> 11) as f64 / (1u64 << 53) as f64)) as i32;
            if r < 16 {
                continue;
            }
            if let Some((i, c)) = check_limited(d as i32, qq as i32, r) {
                if r >= 1 << 24 {
                    inside.push(i);
                }
                across = across.max(c);
            }
        }
        inside.sort_by(f64::total_cmp);
        let at = |p: f64| inside[((inside.len() - 1) as f64 * p) as usize];
        std::println!(
            "limited {}: inside the circle (relative) min {:.3e} median {:.3e} p99 {:.3e} max {:.3e}; across at most {across:.2} LSB",
            inside.len(),
            at(0.0),
            at(0.5),
            at(0.99),
            at(1.0)
        );
    }

    /// The update against the same PI computed in `f64` from the inputs' bits (the reference
    /// shares nothing with the `f32` code): seeded gains over their validated ranges
    /// (log-uniform: `kp` = L·ωc from 1 µH at 10 Hz to 1 H at 5 kHz, `ki_ts` up to 60 V/A per
    /// step), errors, feed-forwards and integrators of every size (0 … 31 bits). Unlimited
    /// (the exact output within 0.99 of a radius of 2^31 − 1 LSB): the output and the
    /// integrators' next values are the exact ones truncated toward zero (saturated to `i32`
    /// for the integrators) within the `f32` roundings: `|got − exact| ≤ 1 + 5u·T` LSB, `u =
    /// 2^-24`, `T = |kp·e| + |ff| + |integ| + 2|ki·e| + |out|` (the conversions, two products
    /// and three sums each round by at most `u` of one of these; 1 for the truncation; the
    /// measured worst is 1.65u·T, the bound 3 times it). Limited (a radius 3 … 97 % of the exact output): flagged, inside the circle
    /// and within `48u·r + √2` of it, and the integrators held at their old values clamped
    /// to the radius. Printed: the largest `(|got − exact| − 1)/(u·T)` measured.
    #[test]
    fn update_is_the_pi_within_its_roundings() {
        let mut next = xorshift(0x2545_f491_4f6c_dd1d);
        let mut unit = move || (next() >> 11) as f64 / (1u64 << 53) as f64;
        let any_i32 = |n: u64| (n as i32) >> (n >> 59) as u32;
        let u = 0.5f64.powi(24);
        let (mut worst, mut n_unlim, mut n_lim) = (0.0f64, 0, 0);
        let mut raw = 0x9e37_79b9_7f4a_7c15u64;
        let mut bits = move || {
            raw = raw
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            raw
        };
        while n_unlim < 20_000 || n_lim < 20_000 {
            let kp_min = 1e-6 * core::f64::consts::TAU * 10.0;
            let kp = kp_min * (core::f64::consts::TAU * 5000.0 / kp_min).powf(unit());
            let ki = 60.0 * (1e-9f64).powf(unit());
            let g = PiGains::new(kp as f32, ki as f32);
            let (kp, ki) = (g.kp() as f64, g.ki_ts() as f64);
            let e = [any_i32(bits()), any_i32(bits())];
            let ff = [any_i32(bits()), any_i32(bits())];
            let i0 = [any_i32(bits()), any_i32(bits())];
            let nx: [f64; 2] = core::array::from_fn(|a| i0[a] as f64 + ki * e[a] as f64);
            let x: [f64; 2] = core::array::from_fn(|a| kp * e[a] as f64 + ff[a] as f64 + nx[a]);
            let t: [f64; 2] = core::array::from_fn(|a| {
                (kp * e[a] as f64).abs()
                    + (ff[a] as f64).abs()
                    + (i0[a] as f64).abs()
                    + 2.0 * (ki * e[a] as f64).abs()
                    + x[a].abs()
            });
            let vm = x[0].hypot(x[1]);
            let dq = |v: [i32; 2]| Dq {
                d: Q::from_bits(v[0]),
                q: Q::from_bits(v[1]),
            };
            let mut pi = CurrentPi { integ: dq(i0) };
            let unlimited = vm < 0.99 * i32::MAX as f64;
            let rf = if unlimited {
                i32::MAX as f64
            } else {
                vm * (0.03 + 0.94 * unit())
            };
            if !(16.0..=i32::MAX as f64).contains(&rf) || (!unlimited && rf == i32::MAX as f64) {
                continue;
            }
            let r = rf as i32;
            let o = pi.update_within(dq(e), dq(ff), &g, &VLimit::new(Q::from_bits(r)));
            if unlimited {
                n_unlim += 1;
                assert!(!o.saturated, "{e:?} {ff:?} {i0:?} kp {kp} ki {ki}: limited");
                let got = [o.v.d.to_bits(), o.v.q.to_bits()];
                let integ = [pi.integ.d.to_bits(), pi.integ.q.to_bits()];
                for a in 0..2 {
                    let sat = |v: f64| v.trunc().clamp(i32::MIN as f64, i32::MAX as f64);
                    for (what, got, exact) in [
                        ("output", got[a], x[a]),
                        ("integrator", integ[a], sat(nx[a])),
                    ] {
                        let dev = (got as f64 - exact).abs();
                        assert!(
                            dev <= 1.0 + 5.0 * u * t[a],
                            "{what} {a}: {got} against {exact} ({e:?} {ff:?} {i0:?} kp {kp} ki {ki})"
                        );
                        worst = worst.max((dev - 1.0).max(0.0) / (u * t[a]));
                    }
                }
            } else {
                n_lim += 1;
                assert!(
                    o.saturated,
                    "{e:?} {ff:?} {i0:?} kp {kp} ki {ki} r {r}: not limited"
                );
                let (ld, lq) = (o.v.d.to_bits() as f64, o.v.q.to_bits() as f64);
                let m = ld.hypot(lq);
                let rf = r as f64;
                assert!(
                    m <= rf && m >= rf * (1.0 - 48.0 * u) - 2f64.sqrt(),
                    "|v| {m}, r {r}"
                );
                let held = i0.map(|v| v.clamp(-r, r));
                assert_eq!([pi.integ.d.to_bits(), pi.integ.q.to_bits()], held);
            }
        }
        std::println!(
            "PI update, {n_unlim} unlimited: largest (|got − exact| − 1 LSB)/(u·T) {worst:.2} (bound 5)"
        );
    }
}
