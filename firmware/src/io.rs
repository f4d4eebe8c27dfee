//! The hardware boundary. The board implements [`DriveIo`] over its ADC, timers and GPIO; the
//! simulator (`hal-sim`) implements it over the simulated plant. The control code
//! ([`crate::control::Controller`]) sees only these types.

use crate::fx::Duty;

/// One synchronous sample of the measurements the current loop needs, as raw converter codes.
/// Scaling and offsets are the controller's parameters, so that the same bits give the same
/// result on the board and in simulation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct RawSample {
    /// Phase-current ADC codes (12-bit, right-aligned; mid-scale is zero current).
    pub i_abc: [u16; 3],
    /// Bus-voltage ADC code (12-bit).
    pub v_bus: u16,
    /// Quadrature-encoder hardware counter (wraps at 2^16).
    pub encoder: u16,
}

impl RawSample {
    /// The sample as its five half-words packed in two words and a half-word (little
    /// end first): copied this way it is five instructions at any optimisation level.
    #[inline(always)]
    pub fn to_words(&self) -> (u32, u32, u16) {
        (
            self.i_abc[0] as u32 | (self.i_abc[1] as u32) << 16,
            self.i_abc[2] as u32 | (self.v_bus as u32) << 16,
            self.encoder,
        )
    }

    /// The inverse of [`RawSample::to_words`].
    #[inline(always)]
    pub fn from_words((a, b, c): (u32, u32, u16)) -> RawSample {
        RawSample {
            i_abc: [a as u16, (a >> 16) as u16, b as u16],
            v_bus: (b >> 16) as u16,
            encoder: c,
        }
    }
}

/// What the current loop sets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Actuation {
    /// High-side conduction fraction of each phase, centre-aligned PWM.
    pub duties: [Duty; 3],
    /// Gate drivers enabled. When false every switch is off (phases open; the body diodes
    /// still conduct if the back-emf exceeds the bus).
    pub enable: bool,
    /// Brake-resistor chopper switch closed.
    pub brake: bool,
}

impl Actuation {
    /// All switches off, brake open.
    pub const OFF: Actuation = Actuation {
        duties: crate::svpwm::CENTRED,
        enable: false,
        brake: false,
    };
}

/// Hardware (or simulated hardware) seen by the current loop.
pub trait DriveIo {
    /// The sample taken at the centre of the current PWM period.
    fn sample(&mut self) -> RawSample;
    /// Set duties (taking effect at the next PWM period), gate enable and brake chopper.
    fn apply(&mut self, out: &Actuation);
    /// Monotonic time, microseconds.
    fn now_us(&self) -> u64;
}

/// Absolute maximum bus voltage of the board's stage (a 100 V-class bridge), V: the bus
/// over-voltage comparator sits halfway between the software trip `v_bus_ov` and this.
pub const STAGE_V_ABS_MAX: f32 = 100.0;

/// The hardware trip thresholds as 12-bit DAC codes on the ADC's scale (the DACs and the ADCs
/// share VREF+, and each comparator watches the same signal an ADC channel converts):
/// * `oc`: phase over-current, one comparator per phase tripping when the shunt amplifier
///   shows a current below −i_hw (the direction a shoot-through or a phase-to-DC+ short drives
///   through a low-side shunt; Σi = 0, so a phase above +2·i_hw drives another below −i_hw),
///   i_hw = min(1.1·`i_trip_a`, 95 % of the amplifier's range below zero);
/// * `ov`: bus over-voltage, halfway between `v_bus_ov` and [`STAGE_V_ABS_MAX`];
/// * `chop`: the brake chopper's comparator, at `brake_on_v`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HwThresholds {
    pub oc: u16,
    pub ov: u16,
    pub chop: u16,
}

impl HwThresholds {
    /// From a valid configuration; codes rounded to nearest, within 0 … 4095.
    pub fn of(cfg: &crate::config::Config) -> HwThresholds {
        // `as` saturates (negative and NaN → 0); rounded to nearest, at most full scale.
        let code = |x: f32| ((x + 0.5) as u16).min(4095);
        let zero = cfg.adc_zero_code as f32;
        let (i_trip, i_rail) = (1.1 * cfg.i_trip_a, 0.95 * zero * cfg.amps_per_count);
        let i_hw = if i_trip < i_rail { i_trip } else { i_rail };
        HwThresholds {
            oc: code(zero - i_hw / cfg.amps_per_count),
            ov: code(0.5 * (cfg.v_bus_ov + STAGE_V_ABS_MAX) / cfg.volts_per_count),
            chop: code(cfg.brake_on_v / cfg.volts_per_count),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::RawSample;
    use proptest::prelude::*;

    /// The default configuration's thresholds, worked by hand from `board.rs`'s scaling
    /// (12,207 µA/count, zero at 2,048, 29.3 mV/count): over-current at −min(22 A, 23.75 A) =
    /// −22 A → 2,048 − 22/0.012207 = 245.8; over-voltage (95 + 100)/2 = 97.5 V → 3,327.6;
    /// chopper 85 V → 2,901.0.
    #[test]
    fn default_thresholds() {
        let c = crate::config::Config::default();
        assert!((c.amps_per_count - 0.012_207).abs() < 1e-6 && c.adc_zero_code == 2048);
        assert!((c.volts_per_count - 0.0293).abs() < 1e-4);
        let t = super::HwThresholds::of(&c);
        let v = |x: f64| (x / c.volts_per_count as f64).round() as u16;
        assert_eq!(t.oc, 246);
        assert_eq!(t.ov, v(97.5));
        assert_eq!(t.chop, v(85.0));
    }

    proptest! {
        /// The packed form is the sample, every field in any value.
        #[test]
        fn words_round_trip(a: u16, b: u16, c: u16, v: u16, e: u16) {
            let s = RawSample { i_abc: [a, b, c], v_bus: v, encoder: e };
            prop_assert_eq!(RawSample::from_words(s.to_words()), s);
        }
    }
}
