//! Space-vector modulation by min–max zero-sequence injection, for a centre-aligned timer.
//!
//! The phase voltages of the commanded vector get the common offset `−(max+min)/2`, which
//! centres them in the bus and is equivalent to classic seven-segment SVPWM. Linear range:
//! `|v| ≤ V_bus/√3` (the circle inscribed in the hexagon). Over-modulation is handled before
//! this stage: the current controller limits its output vector to that circle (times
//! `m_max ≤ 1`), so the duties here never clip for a limited vector; for any other input the
//! duties are clamped to [0, 1] per phase (which amounts to clipping to the hexagon, with
//! distortion).

use crate::frames::{inverse_clarke, AlphaBeta};
use crate::fx::{sat_i32, Duty, Q};

/// Reciprocal of the bus voltage with 23 fractional bits (`2^23 / V`), from one 32-bit
/// division. `v_bus` is floored at 1 V.
#[inline(always)]
pub fn inv_bus(v_bus: Q) -> u32 {
    let vb8 = (v_bus.to_bits().max(1 << 16) as u32) >> 8; // volts · 256
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

#[inline(always)]
fn duty(v: Q, off: Q, inv_vbus: u32) -> Duty {
    let centred = v.to_bits() as i64 - off.to_bits() as i64; // volts · 2^16
                                                             // fraction of the bus, Q.15: centred·2^23/V >> (16 + 23 − 15)
    let frac = sat_i32((centred * inv_vbus as i64) >> 24);
    let d = frac.saturating_add(1 << 14); // + 0.5
    Duty::from_bits(d.clamp(0, 1 << 15) as u16)
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
}
