//! The `regen` command line: one module per subcommand (add yours as a file here and a
//! variant of `Command` in `src/bin/regen.rs`).

pub mod output;
pub mod run;
pub mod sizing;
pub mod sweep;
