//! Proportional-integral current controllers for the d and q axes, with the output vector
//! limited to what the bus can produce and anti-windup by back-calculation.
//!
//! Gains follow the usual pole-zero cancellation design (VESC, ODrive, SimpleFOC):
//! `Kp = L·ωc`, `Ki = R·ωc`, so that with the plant `1/(R + sL)` the closed loop is the
//! first-order `ωc/(s + ωc)`. In discrete time the integral gain per step is `Ki·Ts`.

use crate::frames::Dq;
use crate::fx::{clamp_sym, Gain, Q};

/// Gains of one axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct PiGains {
    /// Proportional gain, V/A.
    pub kp: Gain,
    /// Integral gain times the step, V/A per step.
    pub ki_ts: Gain,
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
    /// The unlimited command exceeded `v_max` and was scaled down.
    pub saturated: bool,
}

/// The allowed voltage circle: radius `r ≥ 0` (LSB of [`Q`]) and `r²`, so the per-period
/// test is two products and a compare (the loop holds it between bus refreshes).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct VLimit {
    r: u32,
    r2: u64,
}

impl VLimit {
    /// The circle of radius `v_max` (negative radii count as zero).
    pub fn new(v_max: Q) -> VLimit {
        let r = v_max.to_bits().max(0) as u32;
        VLimit {
            r,
            r2: r as u64 * r as u64,
        }
    }

    /// The radius.
    pub fn radius(&self) -> Q {
        Q::from_bits(self.r as i32)
    }

    /// `v` scaled onto the circle when it lies outside; `None` when inside.
    #[inline(always)]
    pub fn limit(&self, v: Dq) -> Option<Dq> {
        let (d, q) = (v.d.to_bits() as i64, v.q.to_bits() as i64);
        // Each square ≤ 2^62: the sum fits a u64.
        if (d * d) as u64 + (q * q) as u64 <= self.r2 {
            return None;
        }
        Some(limit_slow(v.d.to_bits(), v.q.to_bits(), self.r))
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
    #[inline(always)]
    pub fn update_within(&mut self, err: Dq, ff: Dq, g: &PiGains, lim: &VLimit) -> PiOutput {
        let next = Dq {
            d: self.integ.d.saturating_add(g.ki_ts.scale(err.d)),
            q: self.integ.q.saturating_add(g.ki_ts.scale(err.q)),
        };
        let pd = g.kp.scale(err.d).saturating_add(ff.d);
        let pq = g.kp.scale(err.q).saturating_add(ff.q);
        let raw = Dq {
            d: pd.saturating_add(next.d),
            q: pq.saturating_add(next.q),
        };
        match lim.limit(raw) {
            None => {
                self.integ = next;
                PiOutput {
                    v: raw,
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

/// The scaling itself (taken only while limiting; inlined: it is short). Arguments as `i32`
/// so the caller keeps no 64-bit copies of its vector.
///
/// Both components are shifted left together until the larger one has 31 bits, and their
/// top 16 bits kept: the larger then has 15 bits (`|·| ∈ [2^14, 2^15]`), so `n = ds² + qs²`
/// lies in `[2^28, 2^31]` and its square root comes from [`sqrt_norm`] on every path (no
/// branch on the size). The truncation changes the larger component by less than 2^-14 of
/// itself (6.1e-5 relative on |v|), `sqrt_norm` adds ≤ 6.2e-5 (its odd result included), the
/// Q1.31 scale and the rounded doubling ≤ 1 LSB per component: the limited magnitude is within
/// 1.3e-4 (+ 2 LSB) of `r` (the tests below allow 2e-4).
#[inline(always)]
fn limit_slow(d: i32, q: i32, r: u32) -> Dq {
    // `x ^ (x >> 31)` is x for x ≥ 0 and |x| − 1 for x < 0 (one instruction), < 2^31; their OR
    // has the top bit of the larger, and `| 1` keeps it non-zero: 1 ≤ lz ≤ 31. Then x ≥ 0 has
    // x < 2^(32−lz), and x < 0 has |x| ≤ 2^(32−lz), so `x << (lz − 1)` lies in [−2^31, 2^31)
    // (fits, nothing is lost), and the larger component lands in [2^30, 2^31) or at −2^31.
    let m = ((d ^ (d >> 31)) | (q ^ (q >> 31)) | 1) as u32;
    let sh = m.leading_zeros() - 1; // 0 ..= 30
    let (ds, qs) = ((d << sh) >> 16, (q << sh) >> 16); // |.| ≤ 2^15, the larger ≥ 2^14
    let n = (ds * ds) as u32 + (qs * qs) as u32; // [2^28, 2^31]
    let mag = sqrt_norm(n); // ≥ 2^14 (non-zero: see `sqrt_norm`)

    // |v| ≈ mag·2^(16−sh), so r/|v| in Q1.31 is r·2^(sh+15)/mag, by two 32-bit divisions (no
    // 64-bit division on a Cortex-M4). r < |v| here (the caller checked), and |v| ≤ √2·max|x|
    // ≤ √2·2^(32−lz), so r·2^sh < 2^31.5 fits a u32; the first quotient is ≈ k·2^16 ≤ 2^16(1 +
    // 1.3e-4), so its 2^15 multiple fits a u32, and the remainder (< mag < 2^15.5) times 2^15
    // fits too.
    let num = r << sh;
    let q1 = num / mag;
    let q2 = ((num % mag) << 15) / mag;
    let k = ((q1 << 15) + q2).min(i32::MAX as u32) as i32;
    // x·k/2^32 rounded to nearest (one `SMMULR`), doubled: the even integer nearest x·k/2^31,
    // which is never longer than x (k < 2^31, so |x·k/2^31| < |x|: an even integer within 1
    // of it has at most |x|'s magnitude), and fits an i32 (at x = −2^31 it is −2^31 + 2).
    Dq {
        d: Q::from_bits(mulhs_round(d, k) << 1),
        q: Q::from_bits(mulhs_round(q, k) << 1),
    }
}

/// `a·b/2^32` rounded to nearest (half up), one `SMMULR` on a Cortex-M4: |a·b| ≤ 2^62, so
/// the sum cannot overflow.
#[inline(always)]
fn mulhs_round(a: i32, b: i32) -> i32 {
    ((a as i64 * b as i64 + (1 << 31)) >> 32) as i32
}

/// √n for n in [2^28, 2^31]: a seed from the top six bits (within 3 %), then two Newton
/// steps (error ≤ 3 %²/2 = 5e-4, then < 1e-7, plus the 1-LSB floor of the division: ≤ 6e-5
/// relative at these sizes). The result is made odd (`| 1`, +1 LSB at most: 6e-5), which
/// proves it non-zero to the divisions that follow without a test.
#[inline(always)]
fn sqrt_norm(n: u32) -> u32 {
    let mut x = SQRT_SEED[(n >> 25) as usize] as u32; // ≥ 2^14
    x = ((x + n / x) >> 1) | 1;
    ((x + n / x) >> 1) | 1
}

/// √((i + ½)·2^25), for the seed of [`sqrt_norm`] (entries below 8 and above 63 are not
/// used; 128 entries make the index provably in range for any `u32 >> 25`).
static SQRT_SEED: [u16; 128] = build_sqrt_seed();

const fn build_sqrt_seed() -> [u16; 128] {
    let mut t = [0u16; 128];
    let mut i = 0;
    while i < 128 {
        // (i + ½)·2^25, and its integer square root by bisection (compile time only).
        let v = (2 * i as u64 + 1) << 24;
        let (mut lo, mut hi) = (0u64, 1u64 << 16);
        while hi - lo > 1 {
            let mid = (lo + hi) / 2;
            if mid * mid <= v {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        t[i] = if lo == 0 { 1 } else { lo as u16 };
        i += 1;
    }
    t
}

/// Integer square root (floor) by Newton's iteration with hardware division: from an
/// estimate above √n the iterates decrease monotonically to ⌊√n⌋ (stop when they no longer
/// decrease). The start, one Newton step from 2^⌈bits/2⌉ done by shifts, is within 25 % of
/// √n, so three to four divisions follow.
#[inline]
pub fn isqrt(n: u32) -> u32 {
    if n < 2 {
        return n;
    }
    // k = ⌈bits/2⌉ ≥ 1, so 2^k > √n; (2^k + n/2^k)/2 ≥ √n (AM–GM) and < 2^16 + 2^15, so
    // no overflow below.
    let k = (33 - n.leading_zeros()) / 2;
    let mut x = (1u32 << (k - 1)) + (n >> (k + 1));
    loop {
        let y = (x + n / x) >> 1;
        if y >= x {
            return x;
        }
        x = y;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fx::q;
    use proptest::prelude::*;
    use std::vec::Vec;

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
        let g = PiGains {
            kp: Gain::from_f32((l * wc) as f32),
            ki_ts: Gain::from_f32((r * wc * ts) as f32),
        };
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
        let g = PiGains {
            kp: Gain::from_f32((l * wc) as f32),
            ki_ts: Gain::from_f32((r * wc * ts) as f32),
        };
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

    proptest! {
        #[test]
        fn limit_keeps_direction_and_radius(d in any::<i32>(), qq in any::<i32>(), r in 0.0f32..1000.0) {
            let v = Dq { d: Q::from_bits(d), q: Q::from_bits(qq) };
            let rq = q(r);
            match limit_vector(v, rq) {
                None => {
                    let m = (v.d.to_num::<f64>().powi(2) + v.q.to_num::<f64>().powi(2)).sqrt();
                    prop_assert!(m <= r as f64 + 1e-4);
                }
                Some(l) => {
                    let m = (l.d.to_num::<f64>().powi(2) + l.q.to_num::<f64>().powi(2)).sqrt();
                    // 15-bit magnitude arithmetic: relative error ≤ 2^-13, plus rounding.
                    prop_assert!(m <= r as f64 * (1.0 + 2e-4) + 1e-4, "{m} > {r}");
                    prop_assert!(m >= r as f64 * (1.0 - 2e-4) - 2e-3, "{m} < {r}");
                    // Same direction: cross product ~ 0, dot product > 0.
                    let cross = v.d.to_num::<f64>() * l.q.to_num::<f64>() - v.q.to_num::<f64>() * l.d.to_num::<f64>();
                    let vm = (v.d.to_num::<f64>().powi(2) + v.q.to_num::<f64>().powi(2)).sqrt();
                    prop_assert!(cross.abs() <= vm * (m * 2e-4 + 2e-3));
                }
            }
        }

        #[test]
        fn pi_never_panics(ed in any::<i32>(), eq in any::<i32>(), kp in -1e6f32..1e6, ki in -1e6f32..1e6, vm in any::<i32>()) {
            let g = PiGains { kp: Gain::from_f32(kp), ki_ts: Gain::from_f32(ki) };
            let mut pi = CurrentPi::default();
            for _ in 0..3 {
                let _ = pi.update(Dq { d: Q::from_bits(ed), q: Q::from_bits(eq) }, Dq { d: Q::MAX, q: Q::MIN }, &g, Q::from_bits(vm));
            }
        }
    }

    #[test]
    fn limit_at_the_normalisation_edges() {
        // Powers of two (negative ones are where `x ^ (x >> 31)` is |x| − 1 and the shift is
        // one larger), their neighbours, −2^31 and zero, in every pairing, against radii from
        // 1 LSB to 30,000 V: magnitude r within the limiter's 1.3e-4 (+ rounding; the bound
        // of `limit_keeps_direction_and_radius`), same direction, never longer than the input.
        let mut xs = std::vec![0i32, 1, -1, i32::MIN, i32::MAX, i32::MIN + 1];
        for k in 0..31 {
            let p = 1i32 << k;
            xs.extend([p, -p, p - 1, -(p - 1), p + 1, -(p + 1)]);
        }
        for &d in &xs {
            for &qq in &xs {
                for r in [1i32, 3, 1 << 10, 1 << 16, 12_345_678, 30_000 << 16] {
                    let v = Dq {
                        d: Q::from_bits(d),
                        q: Q::from_bits(qq),
                    };
                    let (fd, fq) = (d as f64, qq as f64);
                    let vm = (fd * fd + fq * fq).sqrt();
                    match limit_vector(v, Q::from_bits(r)) {
                        None => assert!(vm <= r as f64 + 0.5, "{d} {qq} {r}"),
                        Some(l) => {
                            let (ld, lq) = (l.d.to_bits() as f64, l.q.to_bits() as f64);
                            let m = (ld * ld + lq * lq).sqrt();
                            let rf = r as f64;
                            assert!(m <= rf * (1.0 + 2e-4) + 7.0, "{d} {qq} {r}: {m}");
                            assert!(m >= rf * (1.0 - 2e-4) - 7.0, "{d} {qq} {r}: {m}");
                            assert!(m <= vm + 1.0, "{d} {qq} {r}: longer");
                            assert!((fd * lq - fq * ld).abs() <= vm * (m * 2e-4 + 7.0));
                            assert!(fd * ld + fq * lq >= 0.0);
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn sqrt_norm_is_accurate_over_its_range() {
        let mut worst = 0.0f64;
        let mut n = 1u32 << 28;
        while n <= 1 << 31 {
            let e = (sqrt_norm(n) as f64 - (n as f64).sqrt()) / (n as f64).sqrt();
            worst = worst.max(e.abs());
            n += 997;
        }
        let top = 1u32 << 31; // the end of the range (one component of −2^31)
        let e = (sqrt_norm(top) as f64 - (top as f64).sqrt()) / (top as f64).sqrt();
        worst = worst.max(e.abs());
        // Two Newton steps from a 3 % seed: < 1e-7, plus the division's floor (1 LSB of
        // ≥ 2^14): 6.2e-5.
        assert!(worst < 6.2e-5, "worst {worst}");
    }

    #[test]
    fn isqrt_exact() {
        let mut ns = std::vec![
            0u32,
            1,
            2,
            3,
            4,
            15,
            16,
            17,
            1 << 20,
            u32::MAX,
            u32::MAX - 1
        ];
        ns.extend((0..32).map(|b| 1u32 << b));
        ns.extend((1..32).map(|b| (1u32 << b) - 1));
        ns.extend((1..=65_535u32).map(|r| r * r));
        ns.extend((1..=65_535u32).map(|r| r * r - 1));
        ns.extend((0..100_000u32).map(|k| k.wrapping_mul(2_654_435_761)));
        for n in ns {
            let r = isqrt(n) as u64;
            assert!(r * r <= n as u64 && (r + 1) * (r + 1) > n as u64, "{n}");
        }
    }
}
