//! Control core of the regenerative servo drive (`no_std`, host-testable).
//!
//! The same code runs on the STM32G474 (see `firmware/board`), on an emulated Cortex-M4 (see
//! `firmware/m4check`) and on the host against the simulated transducer (`hal-sim`). All
//! arithmetic inside the current loop is fixed point (`fixed`, Q16.16 unless said otherwise), so
//! the three give the same bits.
//!
//! # Conventions (stated once, checked by the tests of the module named)
//! * **Transforms** ([`frames`]): amplitude-invariant Clarke and Park. A balanced set of phase
//!   currents of peak `I` maps to a vector of length `I`; power is `P = 3/2·(v_d·i_d + v_q·i_q)`.
//! * **Angles**: electrical angle `θ` is the angle of the rotor-flux (d) axis, a [`fx::Angle`]
//!   (`u32`, 2³² = one electrical turn), `θ = p·θ_m + offset`.
//! * **Back-emf**: per-phase peak constant `K_e` (V·s/rad, mechanical), phase-a emf
//!   `e_a = −K_e·ω_m·sin θ`, so in the rotor frame `e_d = 0`, `e_q = K_e·ω_m`. The reference
//!   paper writes `e_a = K_e·θ̇·cos θ_e`: its `θ_e` is our `θ + π/2`.
//! * **Torque and force**: `T = 3/2·K_e·i_q` (N·m), axial force `f_e = T/l`, `l` the lead in
//!   m/rad. Positive `ẋ` turns the shaft positively.
//! * **Emulated resistor** ([`laws::Resistor`]): per phase `i = −e/(R+R_L)`, i.e.
//!   `i_q* = −K_e·ω_m/(R+R_L)`, `i_d* = 0`. Power into the drive from the machine is then
//!   `P = −3/2·e_q·i_q ≥ 0` (regeneration).
//! * **Duties**: fraction of the PWM period that phase's high-side switch conducts, centre
//!   aligned, in [`fx::Duty`] (0 … 1).

#![no_std]
#![forbid(unsafe_code)]

#[cfg(test)]
extern crate std;

pub mod align;
pub mod capture;
pub mod commission;
pub mod config;
pub mod console;
pub mod control;
pub mod encoder;
pub mod frames;
pub mod fx;
pub mod io;
pub mod laws;
pub mod numtext;
pub mod params;
pub mod period;
pub mod pi;
pub mod protect;
pub mod selftest;
pub mod shunt;
pub mod store;
pub mod svpwm;

pub use config::{Config, ConfigError, Gains};
pub use control::{Boot, Compiled, Controller, Mode, ModeError, Telemetry};
pub use io::{Actuation, DriveIo, RawSample};
pub use period::{Pending, Period, PeriodHw, Slot};
