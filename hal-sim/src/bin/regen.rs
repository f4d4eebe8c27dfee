//! `regen`: the host command line.

use clap::{Parser, Subcommand};

#[derive(Parser, Debug)]
#[command(name = "regen", about = "Regenerative servo drive: host tools")]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Studies of the command laws (regimes of two-way flow, device sizing, LQG design).
    Study(hal_sim::study::StudyArgs),
}

fn main() {
    let cli = Cli::parse();
    let res = match &cli.cmd {
        Cmd::Study(a) => hal_sim::study::run(a),
    };
    match res {
        Ok(text) => print!("{text}"),
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(2);
        }
    }
}
