//! `regen diagnose FILE [--cross FILE2] [--json OUT] [--model OUT.toml] [--plots DIR]
//! [--verbose]`.

use super::{cross_check, read_csv, report, try_diagnose, Options};
use std::path::{Path, PathBuf};

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
    /// Low-pass cutoff (Hz) for derived velocity/acceleration (default fs/20, at most 50 Hz).
    #[arg(long)]
    pub cutoff_hz: Option<f64>,
    /// Low-pass the force with the derivative filter too (parallel filtering, as the EMPS
    /// benchmark's published figures are computed).
    #[arg(long)]
    pub filter_force: bool,
    /// Held-out rss drop a finding must bring (fraction).
    #[arg(long, default_value_t = 0.02)]
    pub min_gain: f64,
    /// Explain the report's statistics (held-out error, rss drop, dBIC, segments, Wald, the
    /// derived acceleration's band) in plain words after the report.
    #[arg(long)]
    pub verbose: bool,
}

/// Where an output file goes: its directory must exist or be creatable (checked before the
/// work, the error naming the path).
fn check_out_file(flag: &str, p: &Path) -> Result<(), String> {
    if p.is_dir() {
        return Err(format!(
            "{flag} {}: is a directory, a file path expected",
            p.display()
        ));
    }
    match p.parent().filter(|d| !d.as_os_str().is_empty()) {
        Some(d) => {
            crate::cli::output::check_out_dir(d).map_err(|e| format!("{flag} {}: {e}", p.display()))
        }
        None => Ok(()),
    }
}

/// The record's implied sample rate, stroke and speed against what a servo record can be:
/// a slip of units (time in ms, position in mm) is named with the column that looks wrong.
pub fn check_units(rec: &super::Record, file: &Path) -> Result<(), String> {
    let n = rec.t.len();
    if n < 3 {
        return Err(format!(
            "{}: {n} samples, at least 3 expected",
            file.display()
        ));
    }
    let dt = rec.dt();
    let fs = 1.0 / dt;
    let span = rec.t[n - 1] - rec.t[0];
    let stroke = rec.x.iter().copied().fold(f64::NEG_INFINITY, f64::max)
        - rec.x.iter().copied().fold(f64::INFINITY, f64::min);
    let vmax = rec
        .x
        .windows(2)
        .zip(rec.t.windows(2))
        .map(|(x, t)| ((x[1] - x[0]) / (t[1] - t[0])).abs())
        .fold(0.0, f64::max);
    // A drive's record: sampled at 10 Hz … 1 MHz, a stroke below 10 m, speeds below 20 m/s.
    if !(10.0..=1e6).contains(&fs) {
        let hint = if fs < 10.0 && (10.0..=1e6).contains(&(fs * 1e3)) {
            format!(
                " (t in milliseconds? t/1000 gives {:.0} Hz over {:.3} s)",
                fs * 1e3,
                span * 1e-3
            )
        } else {
            String::new()
        };
        return Err(format!(
            "{}: column t_s looks wrong: implied sample rate {fs:.4} Hz (dt = {dt} s over {span} s), allowed [10, 1e6] Hz{hint}",
            file.display()
        ));
    }
    if stroke.is_nan() || stroke > 10.0 {
        return Err(format!(
            "{}: column x_m looks wrong: stroke {stroke} m, allowed ≤ 10 m (x in millimetres? x/1000 gives {} m)",
            file.display(),
            stroke * 1e-3
        ));
    }
    if vmax.is_nan() || vmax > 20.0 {
        return Err(format!(
            "{}: columns x_m/t_s look wrong: speed up to {vmax:.4} m/s, allowed ≤ 20 m/s (x in mm or t in ms?)",
            file.display()
        ));
    }
    Ok(())
}

pub fn cli_main(args: DiagnoseArgs) -> Result<(), Box<dyn std::error::Error>> {
    if !(0.0..1.0).contains(&args.min_gain) {
        return Err(format!(
            "--min-gain = {}: must be a fraction in [0, 1)",
            args.min_gain
        )
        .into());
    }
    if let Some(fc) = args.cutoff_hz {
        if !(fc.is_finite() && fc > 0.0) {
            return Err(format!(
                "--cutoff-hz = {fc}: must be a finite frequency > 0 and below the record's Nyquist frequency (Hz)"
            )
            .into());
        }
    }
    if let Some(p) = &args.json {
        check_out_file("--json", p)?;
    }
    if let Some(p) = &args.model {
        check_out_file("--model", p)?;
    }
    if let Some(d) = &args.plots {
        crate::cli::output::check_out_dir(d).map_err(|e| e.replace("--out", "--plots"))?;
    }
    // The reader refuses a cutoff at or above the record's Nyquist frequency
    // (`record::check_cutoff`).
    let mut rec = read_csv(&args.file, args.cutoff_hz)?;
    check_units(&rec, &args.file)?;
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
        check_units(&other, p)?;
        if args.filter_force {
            other.filter_force(args.cutoff_hz);
        }
        cross_check(&mut d, &other);
    }
    if args.verbose {
        print!("{}", report::text_explained(&rec, &d));
    } else {
        print!("{}", report::text(&rec, &d));
        println!("(--verbose explains the statistics in plain words)");
    }
    if let Some(p) = &args.json {
        std::fs::write(p, report::json(&d)).map_err(|e| format!("{}: {e}", p.display()))?;
        println!("wrote {}", p.display());
    }
    if let Some(p) = &args.model {
        std::fs::write(p, report::model_toml(&rec, &d))
            .map_err(|e| format!("{}: {e}", p.display()))?;
        println!("wrote {}", p.display());
    }
    if let Some(dir) = &args.plots {
        for p in report::write_plots(dir, &rec, &d)? {
            println!("wrote {p}");
        }
    }
    Ok(())
}
