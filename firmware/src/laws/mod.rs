//! Command laws: what current the machine should carry, given the motion.
//!
//! A law is a [`CommandLaw`]: from the shaft state and measurements of one period it returns
//! the rotor-frame current reference. [`Law`] is the closed set the controller can switch
//! between at run time (an enum, so switching needs no allocation and costs one branch).
//! To add a law: write a type implementing [`CommandLaw`], add a [`Law`] variant and a
//! [`LawKind`], and build it in [`Law::from_config`].

mod impedance;
pub mod lti;
mod optimal;
mod resistor;
mod tracking;

pub use impedance::{discretise as impedance_discretise, Impedance};
pub use lti::LtiParams;
pub use optimal::{clip_one_way, Optimal};
pub use resistor::Resistor;
pub use tracking::{Tracking, TrackingParams};

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
    /// Emulated series R_L–L_L–C_L branch (resonant load).
    Impedance = 1,
    /// Emulated resistor with R_L tracked online for maximum harvested power.
    Tracking = 2,
    /// Host-designed optimal (LQG/H2) controller, two-way power flow.
    TwoWay = 3,
    /// The same controller clipped to regenerative-only (one-way) power flow.
    OneWay = 4,
}

impl LawKind {
    /// All kinds, in parameter-code order.
    pub const ALL: &'static [LawKind] = &[
        LawKind::Resistor,
        LawKind::Impedance,
        LawKind::Tracking,
        LawKind::TwoWay,
        LawKind::OneWay,
    ];

    /// Kind from its numeric code.
    pub fn from_code(c: u8) -> Option<LawKind> {
        Self::ALL.iter().copied().find(|k| *k as u8 == c)
    }

    /// Short name, as the console shows it.
    pub fn name(self) -> &'static str {
        match self {
            LawKind::Resistor => "resistor",
            LawKind::Impedance => "impedance",
            LawKind::Tracking => "tracking",
            LawKind::TwoWay => "two_way",
            LawKind::OneWay => "one_way",
        }
    }

    /// Kind from its console name.
    pub fn from_name(n: &str) -> Option<LawKind> {
        Self::ALL.iter().copied().find(|k| k.name() == n)
    }
}

/// The law the controller runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Law {
    Resistor(Resistor),
    Impedance(Impedance),
    Tracking(Tracking),
    /// Two-way or one-way optimal controller ([`Optimal::is_one_way`]).
    Optimal(Optimal),
}

impl Law {
    /// Build the configured law (the config is already validated).
    pub fn from_config(cfg: &Config) -> Law {
        match cfg.law {
            LawKind::Resistor => Law::Resistor(Resistor::new(cfg.r_phase_ohm, cfg.r_load_ohm)),
            LawKind::Impedance => Law::Impedance(Impedance::new(
                cfg.r_phase_ohm,
                cfg.r_load_ohm,
                cfg.l_load_h,
                cfg.c_load_f,
                cfg.pwm_hz,
                cfg.law_rate_hz,
            )),
            LawKind::Tracking => Law::Tracking(Tracking::new(&TrackingParams {
                r_phase: cfg.r_phase_ohm,
                r_start: cfg.r_load_ohm,
                dither: cfg.trk_dither,
                period_s: cfg.trk_period_s,
                gain: cfg.trk_gain,
                step_max: cfg.trk_step_max,
                r_min: cfg.trk_r_min_ohm,
                r_max: cfg.trk_r_max_ohm,
                p_min_w: cfg.trk_p_min_w,
                pwm_hz: cfg.pwm_hz,
            })),
            LawKind::TwoWay | LawKind::OneWay => Law::Optimal(Optimal::new(
                &cfg.opt,
                cfg.law == LawKind::OneWay,
                cfg.r_phase_ohm,
                cfg.pwm_hz,
                cfg.law_rate_hz,
            )),
        }
    }

    /// Does going from `a` to `b` change the law (so its state must be rebuilt)?
    pub fn params_changed(a: &Config, b: &Config) -> bool {
        a.law != b.law
            || a.r_load_ohm != b.r_load_ohm
            || a.r_phase_ohm != b.r_phase_ohm
            || (b.law != LawKind::Resistor
                && (a.pwm_hz != b.pwm_hz
                    || a.law_rate_hz != b.law_rate_hz
                    || a.l_load_h != b.l_load_h
                    || a.c_load_f != b.c_load_f
                    || a.trk_dither != b.trk_dither
                    || a.trk_period_s != b.trk_period_s
                    || a.trk_gain != b.trk_gain
                    || a.trk_step_max != b.trk_step_max
                    || a.trk_r_min_ohm != b.trk_r_min_ohm
                    || a.trk_r_max_ohm != b.trk_r_max_ohm
                    || a.trk_p_min_w != b.trk_p_min_w
                    || a.opt != b.opt))
    }
}

impl CommandLaw for Law {
    #[inline(always)]
    fn command(&mut self, inp: &LawInput) -> Dq {
        match self {
            Law::Resistor(l) => l.command(inp),
            Law::Impedance(l) => l.command(inp),
            Law::Tracking(l) => l.command(inp),
            Law::Optimal(l) => l.command(inp),
        }
    }
}
