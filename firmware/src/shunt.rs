//! Low-side shunt sensing: which two phase currents of a period are valid, the third
//! reconstructed from `i_a + i_b + i_c = 0`.
//!
//! A low-side shunt carries its phase current only while that phase's low-side switch (or,
//! in the dead time, its diode) conducts: with centre-aligned PWM an interval of
//! `(1 − d)·T` centred on the sampling instant (the counter's end where all three low sides
//! are on), shortened by the dead time. The converters take I_a and I_b ≈ 0.3 µs after that
//! instant and I_c ≈ 0.9 µs after it (`firmware/board/src/board.rs`), and the shunt
//! amplifier needs time to settle after its window opens. So a phase whose duty exceeds
//! [`UNREAD_ABOVE`] (the highest one, the shortest window) is not read; it is reconstructed
//! from the other two.
//!
//! The duties that decide are the ones in force while the sample is taken: written by the
//! previous step and loaded by the timer at the update event that triggers this sample (the
//! one-period PWM delay), i.e. the controller's previous output.
//!
//! Why two valid phases always remain up to `m_max`: the current loop limits its vector to
//! `|v| ≤ m_max·V_bus/√3` and min–max modulation centres the phases, so the middle duty is at
//! most `½ + ¾·|v|/V_bus ≤ ½ + ¾·m_max/√3` (reached where two phases are equal, at a sector
//! boundary): 0.911 for m_max = 0.95, a low-side interval of (1 − 0.911)·T/2 = 2.2 µs on
//! each side of the sampling instant at 20 kHz, minus the 0.5 µs dead time before it: 1.7 µs
//! of settling before I_a/I_b and the I_c conversion inside the interval. The highest duty
//! reaches `½ + m_max/2` = 0.975 (0.6 µs each side): never read. So the rule needs neither a
//! duty limit below m_max nor a shifted sampling instant (`docs/laws.md`, `docs/board.md`).

use crate::fx::Duty;

/// Duty (U1F15 bits) above which a phase is not read: 0.9375 (`0x7800`, a Thumb-2 immediate:
/// the comparison needs no constant load). Up to m_max = 0.95 at most one phase exceeds it
/// (the middle duty stays ≤ 0.911), and a phase at or below it has a low-side interval of at
/// least (1 − 0.9375)·T/2 = 1.56 µs on each side of the sampling instant at 20 kHz: I_c's
/// 0.88 µs instant lies inside it, and the amplifier has had ≥ 1.35 µs (6.7 time constants
/// of 0.2 µs: settled to 0.1 %) since the interval opened (after the 0.5 µs dead time) when
/// I_a and I_b are taken at 0.29 µs.
pub const UNREAD_ABOVE: u16 = 0x7800; // 0.9375·2^15

/// The three phase codes with the phase whose duty `d` exceeds [`UNREAD_ABOVE`] replaced by
/// the one that makes the three currents sum to zero (`zero3` = the sum of the three
/// zero-current codes). When no duty exceeds it all three are valid and are kept: the
/// three-phase Clarke transform then averages the three converters' noise, and a single
/// failed sensor shows as a zero-sum error (the supervision's consistency check) rather than
/// being fed back in full.
#[inline(always)]
pub fn two_valid(i: [i32; 3], d: &[Duty; 3], zero3: i32) -> [i32; 3] {
    let [a, b, c] = i;
    if d[0].to_bits() > UNREAD_ABOVE {
        [zero3 - b - c, b, c]
    } else if d[1].to_bits() > UNREAD_ABOVE {
        [a, zero3 - a - c, c]
    } else if d[2].to_bits() > UNREAD_ABOVE {
        [a, b, zero3 - a - b]
    } else {
        i
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn duty(x: f64) -> Duty {
        Duty::from_num(x)
    }

    #[test]
    fn the_highest_duty_is_reconstructed_and_the_sum_is_zero() {
        let z = 2048;
        // Currents (codes above zero) 100, −30, −70; the invalid phase reads 0 A (z).
        let cases = [
            (
                [z, z - 30, z - 70],
                [0.97, 0.5, 0.1],
                [z + 100, z - 30, z - 70],
            ),
            (
                [z + 100, z, z - 70],
                [0.4, 0.96, 0.1],
                [z + 100, z - 30, z - 70],
            ),
            (
                [z + 100, z - 30, z],
                [0.2, 0.5, 0.975],
                [z + 100, z - 30, z - 70],
            ),
            // None above 0.9375: all three read as they are.
            (
                [z + 100, z - 30, z - 71],
                [0.91, 0.91, 0.1],
                [z + 100, z - 30, z - 71],
            ),
        ];
        for (read, d, want) in cases {
            let out = two_valid(read, &[duty(d[0]), duty(d[1]), duty(d[2])], 3 * z);
            assert_eq!(out, want, "duties {d:?}");
            if d.iter().any(|&x| x > 0.9375) {
                assert_eq!(out.iter().sum::<i32>(), 3 * z);
            }
        }
    }

    #[test]
    fn the_middle_duty_stays_below_the_bound_up_to_m_max() {
        // Closed form vs a scan of min–max modulation on the m_max circle.
        let m = 0.95f64;
        let bound = 0.5 + 0.75 * m / 3f64.sqrt();
        let mut worst: f64 = 0.0;
        for k in 0..3600 {
            let th = k as f64 * core::f64::consts::TAU / 3600.0;
            let v = m / 3f64.sqrt();
            let ph = [
                v * th.cos(),
                v * (th - 2.0 * core::f64::consts::PI / 3.0).cos(),
                v * (th + 2.0 * core::f64::consts::PI / 3.0).cos(),
            ];
            let (mx, mn) = (ph[0].max(ph[1]).max(ph[2]), ph[0].min(ph[1]).min(ph[2]));
            let mut d = ph.map(|x| 0.5 + x - (mx + mn) / 2.0);
            d.sort_by(f64::total_cmp);
            worst = worst.max(d[1]);
        }
        assert!(
            worst <= bound + 1e-12 && worst > bound - 1e-5,
            "{worst} vs {bound}"
        );
        assert!(bound < UNREAD_ABOVE as f64 / 32768.0);
    }
}
