//! The `regen` command line: one module per subcommand (add yours as a file here and a
//! variant of `Command` in `src/bin/regen.rs`).

pub mod client;
pub mod commission;
pub mod output;
pub mod progress;
pub mod run;
#[cfg(unix)]
pub mod serve;
pub mod sizing;
pub mod sweep;
#[cfg(unix)]
pub mod ui;
