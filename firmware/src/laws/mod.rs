//! Command laws: what current the machine should carry, given the motion.
//!
//! A law is a [`CommandLaw`]: from the shaft state and measurements of one period it returns
//! the rotor-frame current reference. [`Law`] is the closed set the controller can switch
//! between at run time (an enum, so switching needs no allocation and costs one branch).
//! To add a law: write a type implementing [`CommandLaw`], add a [`Law`] variant and a
//! [`LawKind`], and build it in [`Law::from_config`].

mod resistor;

pub use resistor::Resistor;

use crate::config::Config;
use crate::frames::Dq;
use crate::fx::Q;

/// What a law sees each period.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct LawInput {
    /// Mechanical shaft speed, rad/s.
    pub omega_m: Q,
    /// Back-emf estimate on the q axis, `K_e·ω_m`, V (per-phase peak).
    pub e_q: Q,
    /// Travel from the zero position, m.
    pub x: Q,
    /// Measured rotor-frame currents, A.
    pub i_dq: Dq,
    /// Measured bus voltage, V.
    pub v_bus: Q,
}

/// A command law.
pub trait CommandLaw {
    /// Rotor-frame current reference for this period, A (before current limiting).
    fn command(&mut self, inp: &LawInput) -> Dq;
}

/// Which law runs (the parameter users set).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[repr(u8)]
pub enum LawKind {
    /// Emulated resistor R_L across each phase.
    #[default]
    Resistor = 0,
}

impl LawKind {
    /// All kinds, in parameter-code order.
    pub const ALL: &'static [LawKind] = &[LawKind::Resistor];

    /// Kind from its numeric code.
    pub fn from_code(c: u8) -> Option<LawKind> {
        Self::ALL.iter().copied().find(|k| *k as u8 == c)
    }

    /// Short name, as the console shows it.
    pub fn name(self) -> &'static str {
        match self {
            LawKind::Resistor => "resistor",
        }
    }
}

/// The law the controller runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Law {
    Resistor(Resistor),
}

impl Law {
    /// Build the configured law (the config is already validated).
    pub fn from_config(cfg: &Config) -> Law {
        match cfg.law {
            LawKind::Resistor => Law::Resistor(Resistor::new(cfg.r_phase_ohm, cfg.r_load_ohm)),
        }
    }
}

impl CommandLaw for Law {
    #[inline(always)]
    fn command(&mut self, inp: &LawInput) -> Dq {
        match self {
            Law::Resistor(l) => l.command(inp),
        }
    }
}
