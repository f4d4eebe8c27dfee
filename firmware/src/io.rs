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

#[cfg(test)]
mod tests {
    use super::RawSample;
    use proptest::prelude::*;

    proptest! {
        /// The packed form is the sample, every field in any value.
        #[test]
        fn words_round_trip(a: u16, b: u16, c: u16, v: u16, e: u16) {
            let s = RawSample { i_abc: [a, b, c], v_bus: v, encoder: e };
            prop_assert_eq!(RawSample::from_words(s.to_words()), s);
        }
    }
}
