//! Space-vector modulation by min–max zero-sequence injection, for a centre-aligned timer.
//!
//! The phase voltages of the commanded vector get the common offset `−(max+min)/2`, which
//! centres them in the bus and is equivalent to classic seven-segment SVPWM. Linear range:
//! `|v| ≤ V_bus/√3` (the circle inscribed in the hexagon). Over-modulation is handled before
//! this stage: the current controller limits its output vector to that circle (times
//! `m_max ≤ 1`), so the duties here never clip for a limited vector; for any other input the
//! duties are clamped to [0, 1 − 2^-15] per phase (which amounts to clipping to the hexagon, with
//! distortion).

use crate::frames::{inverse_clarke, AlphaBeta};
use crate::fx::{sat_i32, Duty, Q};

/// Reciprocal of the bus voltage with 23 fractional bits (`2^23 / V`), from one 32-bit
/// division. `v_bus` is floored at 257/256 V, so the result is below 2^23 (and its 2^8
/// multiple fits an `i32` for the high-word multiply of [`modulate_limited`]).
#[inline(always)]
pub fn inv_bus(v_bus: Q) -> u32 {
    let vb8 = (v_bus.to_bits().max(257 << 8) as u32) >> 8; // volts · 256
    (1u32 << 31) / vb8
}

/// Duties for the stationary-frame voltage `v` on a bus whose reciprocal is `inv_vbus`
/// (from [`inv_bus`]).
#[inline(always)]
pub fn modulate(v: AlphaBeta, inv_vbus: u32) -> [Duty; 3] {
    let [a, b, c] = inverse_clarke(v);
    let max = a.max(b).max(c);
    let min = a.min(b).min(c);
    let off = Q::from_bits(((max.to_bits() as i64 + min.to_bits() as i64) >> 1) as i32);
    [
        duty(a, off, inv_vbus),
        duty(b, off, inv_vbus),
        duty(c, off, inv_vbus),
    ]
}

/// [`modulate`] for a vector the current controller has limited: `|v|` at most about
/// `V_bus/√3` (`m_max ≤ 1`) with `V_bus < 30,000 V` (validated ADC full scale), so every
/// intermediate below fits in 32 bits without saturation:
/// * the phase values `a, b, c` have magnitudes ≤ |v| < 17,330 V < 2^31 LSB, and
///   `|max + min|` (minus the middle one, as a + b + c = 0) too;
/// * `max − min ≤ √3·|v| ≤ V_bus·(1 + 3e-4)` < 30,010 V < 2^31 LSB (the 3e-4 covers the
///   limiter's and the rotation's relative errors), so the centred values fit;
/// * `centred·inv_vbus` < 2^31·2^23, and `>> 24` leaves < 2^30.
///
/// The final clamp (one SSAT) stays: it covers a bus below the floor of [`inv_bus`].
#[inline(always)]
pub fn modulate_limited(v: AlphaBeta, inv_vbus: u32) -> [Duty; 3] {
    modulate_scaled(v, (inv_vbus << 8) as i32) // < 2^31 (inv_bus < 2^23)
}

/// [`modulate_limited`] with the reciprocal already in the form its multiplies use,
/// `inv8 = inv_bus(V_bus)·2^8` (the current loop holds it between bus refreshes).
#[inline(always)]
pub fn modulate_scaled(v: AlphaBeta, inv8: i32) -> [Duty; 3] {
    let (al, be) = (v.alpha.to_bits(), v.beta.to_bits());
    debug_assert!((al as i64).pow(2) + (be as i64).pow(2) < (17_330i64 << 16).pow(2));
    // Inverse Clarke: a = α, b = −α/2 + (√3/2)β, c = −α/2 − (√3/2)β.
    let sb = crate::fx::mul_shr::<30>(be, 929_887_697); // √3/2, Q2.30
    let half_a = al >> 1; // as `inverse_clarke` (floor)
    let (a, b, c) = (al, sb - half_a, -half_a - sb);
    let max = a.max(b).max(c);
    let min = a.min(b).min(c);
    let off = (max + min) >> 1; // |max + min| < 2^31
    let d = |x: i32| {
        let centred = x - off;
        // centred·inv >> 24 as one high-word multiply.
        let frac = crate::fx::mulhs(centred, inv8);
        Duty::from_bits((frac.clamp(-(1 << 14), (1 << 14) - 1) + (1 << 14)) as u16)
    };
    [d(a), d(b), d(c)]
}

#[inline(always)]
fn duty(v: Q, off: Q, inv_vbus: u32) -> Duty {
    // Volts · 2^16, then the fraction of the bus, Q.15: centred·2^23/V >> (16 + 23 − 15).
    let centred = v.to_bits() as i64 - off.to_bits() as i64;
    let frac = sat_i32((centred * inv_vbus as i64) >> 24);
    // Centred ± half the bus: [−2^14, 2^14 − 1] (one SSAT) + 0.5. The high side is never
    // commanded fully on (1 − 2^-15 at most: 1.5 ns of a 50 µs period, below any gate
    // driver's resolution; bootstrap supplies need an off time anyway).
    Duty::from_bits((frac.clamp(-(1 << 14), (1 << 14) - 1) + (1 << 14)) as u16)
}

/// Duties that put every phase at half the bus (zero line-to-line voltage).
pub const CENTRED: [Duty; 3] = [Duty::from_bits(1 << 14); 3];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frames::clarke;
    use crate::fx::q;

    fn line_voltages(d: [Duty; 3], vbus: f64) -> [f64; 3] {
        let v: [f64; 3] = core::array::from_fn(|k| d[k].to_num::<f64>() * vbus);
        let mean = (v[0] + v[1] + v[2]) / 3.0;
        [v[0] - mean, v[1] - mean, v[2] - mean]
    }

    #[test]
    fn reproduces_vectors_inside_the_circle() {
        let vbus = 48.0;
        let r = 0.999 * vbus / 3f64.sqrt();
        for k in 0..360 {
            let a = (k as f64).to_radians();
            let v = AlphaBeta {
                alpha: q((r * a.cos()) as f32),
                beta: q((r * a.sin()) as f32),
            };
            let d = modulate(v, inv_bus(q(vbus as f32)));
            for x in d {
                assert!(x > Duty::ZERO && x < Duty::ONE, "clipped at {k}°: {d:?}");
            }
            let ph = line_voltages(d, vbus);
            let back = clarke(q(ph[0] as f32), q(ph[1] as f32), q(ph[2] as f32));
            // Duty resolution 2^-15 of 48 V = 1.5 mV per phase, plus 1/V rounding (≈3e-5 rel).
            assert!((back.alpha.to_num::<f64>() - r * a.cos()).abs() < 5e-3);
            assert!((back.beta.to_num::<f64>() - r * a.sin()).abs() < 5e-3);
        }
    }

    #[test]
    fn clamps_beyond_the_hexagon_without_overflow() {
        let big = AlphaBeta {
            alpha: Q::MAX,
            beta: Q::MIN,
        };
        for vb in [0.0f32, 0.5, 48.0, 30000.0] {
            let d = modulate(big, inv_bus(q(vb)));
            for x in d {
                assert!(x <= Duty::ONE);
            }
        }
        assert_eq!(modulate(AlphaBeta::default(), inv_bus(q(48.0))), CENTRED);
    }

    #[test]
    fn limited_form_matches_the_general_one() {
        // Vectors on and inside the linear-modulation circle at several bus voltages, up to
        // the largest bus the validated scalings allow: the unsaturated form computes the same
        // expressions, so the duties are identical.
        for vbus in [0.5f64, 12.0, 48.0, 320.0, 29_990.0] {
            let ib = inv_bus(q(vbus as f32));
            for k in 0..720 {
                let a = (k as f64 * 0.5).to_radians();
                for m in [0.0, 0.3, 0.999, 1.0002] {
                    let r = m * vbus / 3f64.sqrt();
                    let v = AlphaBeta {
                        alpha: q((r * a.cos()) as f32),
                        beta: q((r * a.sin()) as f32),
                    };
                    let (x, y) = (modulate_limited(v, ib), modulate(v, ib));
                    assert_eq!(x, y, "{vbus} V, {k}, {m}");
                }
            }
        }
    }
}
