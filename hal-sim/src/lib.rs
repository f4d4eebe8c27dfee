//! Host-side simulator of the regenerative transducer and the tools around it.
//!
//! * [`plant`]: the parts (machine, screw with friction/efficiency, imposed motion or a
//!   structure with base excitation, DC bus, drive losses, sensors), SI units, serde.
//! * [`sim`]: [`sim::Sim`], the firmware's [`regen_fw::Controller`] unchanged against the
//!   plant through [`regen_fw::DriveIo`], one PWM period per [`sim::Sim::step`], with an
//!   energy ledger ([`sim::Energy`]) and a recorder.
//! * [`scenario`]: TOML scenario files → a ready [`sim::Sim`].
//! * [`analytic`]: sizing indices (eq. 6–12) and the harmonic-balance TMD power (eq. 14–23).
//! * [`cli`]: the `regen` command line (one file per subcommand).
//!
//! Conventions are the firmware's (see `regen_fw`): per-phase PEAK back-emf constant K_e,
//! `T = 3/2·K_e·i_q`, amplitude-invariant transforms. The device force in the sense of ẋ is
//! `f_e = −T/l` (power into the device when `f·ẋ > 0`; the resistor law gives `i_q < 0` for
//! `ω > 0`, a braking torque, hence a positive force). See `docs/simulator.md`.

pub mod analytic;
pub mod bench_rig;
pub mod cli;
pub mod device_model;
pub mod diagnose;
pub mod drive;
pub mod fastmath;
pub mod faults;
pub mod lqg;
pub mod plant;
pub mod plot;
pub mod powerup;
pub mod sampling;
pub mod scenario;
pub mod sim;
pub mod stage;
pub mod study;
pub mod summary;

pub use scenario::Scenario;
pub use sim::{Channel, Energy, Rig, Sim};
