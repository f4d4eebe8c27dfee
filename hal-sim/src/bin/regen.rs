//! `regen` command line (minimal: the `diagnose` subcommand; the simulator's subcommands are
//! merged in by the lead).
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "regen", about = "Regenerative transducer simulator and tools")]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Diagnose a measured record: what the model gets wrong and why.
    Diagnose(hal_sim::diagnose::cli::DiagnoseArgs),
}

fn main() {
    let cli = Cli::parse();
    let r = match cli.cmd {
        Cmd::Diagnose(a) => hal_sim::diagnose::cli::cli_main(a),
    };
    if let Err(e) = r {
        eprintln!("error: {e}");
        std::process::exit(2);
    }
}
