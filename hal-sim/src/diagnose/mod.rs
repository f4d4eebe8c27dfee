//! The model diagnosis (crate `regen-diagnose`, which reads records and shares no simulator
//! code) and what binds it to the simulator: the `regen diagnose` command line, its residual
//! plots and the extended model as the plant's `[model]` fragment (`regen run --model`).

pub use regen_diagnose::*;

pub mod cli;
pub mod model;
pub mod plots;

/// The diagnosis's report, with the simulator's side of it: the residual plots and the
/// extended model as a scenario fragment.
pub mod report {
    pub use super::plots::write_plots;
    pub use regen_diagnose::report::*;

    /// Extended model as a scenario fragment (TOML, `[model]`; docs/diagnose.md, "The loop").
    pub fn model_toml(rec: &super::Record, d: &super::Diagnosis) -> String {
        super::model::fragment_toml(rec, d)
    }
}
