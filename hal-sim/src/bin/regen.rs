//! `regen`: the simulator's command line. One `Command` variant per subcommand, each
//! implemented in `hal_sim::cli::<name>`. With no arguments: the reference TMD power sweep.

use clap::{Parser, Subcommand};
use hal_sim::cli;

#[derive(Parser, Debug)]
#[command(
    name = "regen",
    version,
    about = "Regenerative transducer simulator and tools",
    after_help = "Without a command: the reference TMD power sweep (as `regen sweep`), written to regen-out/. \
                  `regen help COMMAND` for a command's options."
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Device sizing indices of the reference device (Cassidy et al. 2011, eq. 6–12).
    Sizing(cli::sizing::SizingArgs),
    /// One closed-loop scenario run: mean harvested power, peak force, energy balance, faults;
    /// CSV and plots.
    Run(cli::run::RunArgs),
    /// Sweep a parameter over closed-loop runs in parallel: the best point and any that
    /// faulted; CSV and plot (default: the reference TMD power sweep).
    Sweep(cli::sweep::SweepArgs),
    /// Studies of the command laws (regimes of two-way flow, device sizing, LQG design).
    Study(hal_sim::study::StudyArgs),
    /// Diagnose a measured record: what the model gets wrong, the physical cause, the gain.
    Diagnose(hal_sim::diagnose::cli::DiagnoseArgs),
    /// Run a scenario in real time (or --speed X) with the firmware's console on a
    /// pseudo-terminal (connect with picocom, screen, minicom or `regen client`).
    #[cfg(unix)]
    Serve(cli::serve::ServeArgs),
    /// Send console commands (arguments or --script) to a serial port or `regen serve`'s
    /// pseudo-terminal and print the replies; exit status 1 on an error reply or a timeout.
    Client(cli::client::ClientArgs),
    /// Commission a drive over its console: align, measure R, L_d, L_q and K_e, show them
    /// against the configuration (--apply, --save), and the load the device wants
    /// (--scenario, --model).
    Commission(cli::commission::CommissionArgs),
    /// The browser UI: serves the page and bridges the simulated drive (--sim) or a board
    /// (--port) over a WebSocket; prints the URL to open (with this run's token).
    #[cfg(unix)]
    Ui(cli::ui::UiArgs),
}

/// Parse the command line; a usage error is one line (clap's message and tip, without the
/// usage block) and exit status 2; help and version print as clap formats them.
fn parse() -> Cli {
    use clap::error::ErrorKind;
    match Cli::try_parse() {
        Ok(c) => c,
        Err(e) if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) => {
            e.exit()
        }
        Err(e) if e.kind() == ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => e.exit(),
        Err(e) => {
            // clap's message up to its usage block, on one line.
            let text = e.render().to_string();
            let msg: Vec<&str> = text
                .lines()
                .map(str::trim)
                .take_while(|l| !l.starts_with("Usage:") && !l.starts_with("For more"))
                .filter(|l| !l.is_empty())
                .collect();
            eprintln!("{}; see `regen help`", msg.join(" "));
            std::process::exit(2);
        }
    }
}

/// A reader that goes away (`regen client … | head -2`, a closed terminal) ends the command
/// quietly: on Unix SIGPIPE gets its default action back (the process ends as `cat` or `grep`
/// does under a closed pipe, status 141 in a shell), and a write to a standard stream that
/// fails otherwise (a hung-up terminal: EIO) ends it with status 1 and no message, where
/// `println!` would panic.
fn quiet_on_closed_output() {
    #[cfg(unix)]
    {
        use nix::sys::signal::{signal, SigHandler, Signal};
        // SAFETY: restoring the default disposition installs no handler.
        let _ = unsafe { signal(Signal::SIGPIPE, SigHandler::SigDfl) };
    }
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let msg = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or("");
        if msg.starts_with("failed printing to std") {
            std::process::exit(1);
        }
        default(info);
    }));
}

fn main() {
    quiet_on_closed_output();
    let c = parse();
    let r = match c.command {
        Some(Command::Sizing(a)) => cli::sizing::run(&a),
        Some(Command::Run(a)) => cli::run::run(&a),
        Some(Command::Sweep(a)) => cli::sweep::run(&a),
        Some(Command::Study(a)) => hal_sim::study::run(&a).map(|text| print!("{text}")),
        #[cfg(unix)]
        Some(Command::Serve(a)) => cli::serve::run(&a),
        Some(Command::Client(a)) => cli::client::run(&a),
        Some(Command::Commission(a)) => cli::commission::run(&a),
        #[cfg(unix)]
        Some(Command::Ui(a)) => cli::ui::run(&a),
        Some(Command::Diagnose(a)) => {
            hal_sim::diagnose::cli::cli_main(a).map_err(|e| e.to_string())
        }
        None => {
            println!(
                "regen: no subcommand, reproducing the reference TMD power sweep (see --help)"
            );
            cli::sweep::run(&cli::sweep::SweepArgs {
                scenario: None,
                param: "r_load_ohm".into(),
                values: Vec::new(),
                out: "regen-out".into(),
                quiet: false,
            })
        }
    };
    if let Err(e) = r {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}
