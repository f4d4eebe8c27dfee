//! `regen diagnose FILE [--cross FILE2] [--json OUT] [--model OUT.toml] [--plots DIR]`.

use super::{cross_check, read_csv, report, try_diagnose, Options};
use std::path::PathBuf;

/// Arguments of the `diagnose` subcommand.
#[derive(Debug, Clone, clap::Args)]
pub struct DiagnoseArgs {
    /// Measured record (CSV: t_s,x_m,f_N[,...], `# key = value` metadata comments).
    pub file: PathBuf,
    /// Second record to cross-check the extended model on.
    #[arg(long)]
    pub cross: Option<PathBuf>,
    /// Write the machine-readable report here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write the extended model (TOML) here.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Write SVG residual plots into this directory.
    #[arg(long)]
    pub plots: Option<PathBuf>,
    /// Low-pass cutoff (Hz) for derived velocity/acceleration (default fs/20).
    #[arg(long)]
    pub cutoff_hz: Option<f64>,
    /// Low-pass the force with the derivative filter too (parallel filtering, as the EMPS
    /// benchmark's published figures are computed).
    #[arg(long)]
    pub filter_force: bool,
    /// Held-out rss drop a finding must bring (fraction).
    #[arg(long, default_value_t = 0.02)]
    pub min_gain: f64,
}

pub fn cli_main(args: DiagnoseArgs) -> Result<(), Box<dyn std::error::Error>> {
    if !(0.0..1.0).contains(&args.min_gain) {
        return Err(format!("--min-gain {} must be in [0,1)", args.min_gain).into());
    }
    let mut rec = read_csv(&args.file, args.cutoff_hz)?;
    if args.filter_force {
        rec.filter_force(args.cutoff_hz);
    }
    let opt = Options {
        min_holdout_gain: args.min_gain,
        ..Options::default()
    };
    let mut d = try_diagnose(&rec, &opt)?;
    if let Some(p) = &args.cross {
        let mut other = read_csv(p, args.cutoff_hz)?;
        if args.filter_force {
            other.filter_force(args.cutoff_hz);
        }
        cross_check(&mut d, &other);
    }
    print!("{}", report::text(&rec, &d));
    if let Some(p) = &args.json {
        std::fs::write(p, report::json(&d))?;
        println!("wrote {}", p.display());
    }
    if let Some(p) = &args.model {
        std::fs::write(p, report::model_toml(&d))?;
        println!("wrote {}", p.display());
    }
    if let Some(dir) = &args.plots {
        for p in report::write_plots(dir, &rec, &d)? {
            println!("wrote {p}");
        }
    }
    Ok(())
}
