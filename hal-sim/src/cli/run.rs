//! `regen run SCENARIO`: one closed-loop run → its answer (mean harvested power after
//! settling, peak force, energy balance, faults latched; [`crate::summary::RunSummary`]), a
//! CSV of the recorded channels and plots of force against time, displacement and velocity.

use super::output::{check_out_dir, write};
use super::progress::Progress;
use crate::plot::{Plot, Series};
use crate::scenario::Scenario;
use crate::sim::Channel;
use crate::summary::run_to_end;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct RunArgs {
    /// Scenario file (TOML).
    pub scenario: PathBuf,
    /// Output directory.
    #[arg(long, default_value = "regen-out")]
    pub out: PathBuf,
    /// Zoom the time plot on an event: `T0,T1` in seconds.
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    pub window: Option<Vec<f64>>,
    /// No progress bar.
    #[arg(long, short)]
    pub quiet: bool,
}

/// `--window T0,T1` checked against the run: finite, T0 < T1, inside [0, duration].
pub fn check_window(w: &Option<Vec<f64>>, duration_s: f64) -> Result<Option<(f64, f64)>, String> {
    let Some(w) = w else { return Ok(None) };
    let &[a, b] = w.as_slice() else {
        return Err(format!(
            "--window = {}: two times T0,T1 in seconds expected, {} given",
            w.iter()
                .map(|v| v.to_string())
                .collect::<Vec<_>>()
                .join(","),
            w.len()
        ));
    };
    if !(a.is_finite() && b.is_finite() && a >= 0.0 && a < b && b <= duration_s) {
        return Err(format!(
            "--window = {a},{b}: must be two times T0 < T1 in [0, {duration_s}] s (the run's duration)"
        ));
    }
    Ok(Some((a, b)))
}

pub fn run(a: &RunArgs) -> Result<(), String> {
    let sc = Scenario::from_file(&a.scenario)?;
    let window = check_window(&a.window, sc.duration_s)?;
    check_out_dir(&a.out)?;
    let mut sim = sc.build()?;
    let t = std::time::Instant::now();
    let bar = Progress::new(&sc.name, sc.duration_s, a.quiet);
    let s = run_to_end(&sc, &mut sim, &mut bar.callback());
    bar.finish();
    let wall = t.elapsed().as_secs_f64();
    if let Some(rec) = sim.take_recorder() {
        let csv = a.out.join(format!("{}.csv", sc.name));
        write(&csv, &rec.to_csv())?;
        println!("trace: {}", csv.display());
        let col = |c| rec.column(c);
        if let (Some(t), Some(x), Some(v), Some(f)) = (
            col(Channel::T),
            col(Channel::X),
            col(Channel::V),
            col(Channel::Force),
        ) {
            let zip =
                |a: &[f64], b: &[f64]| a.iter().copied().zip(b.iter().copied()).collect::<Vec<_>>();
            let what = format!("{} ({}, {} s)", sc.name, sc.law.kind, sc.duration_s);
            for (file, title, xl, xs, win) in [
                (
                    "force-x",
                    "force against displacement",
                    "displacement x (m)",
                    &x,
                    None,
                ),
                (
                    "force-v",
                    "force against velocity",
                    "velocity ẋ (m/s)",
                    &v,
                    None,
                ),
                ("force-t", "force against time", "time t (s)", &t, window),
            ] {
                let mut p = Plot::new(format!("{what}: {title}"), xl, "force on the device (N)");
                p.series.push(Series::line("force", zip(xs, &f)));
                p.window = win;
                let path = p.write_svg(&a.out.join(format!("{}-{file}.svg", sc.name)))?;
                println!("plot: {}", path.display());
            }
        }
    }
    println!(
        "{:.2} s simulated in {:.2} s ({:.0}× real time)",
        sc.duration_s,
        wall,
        sc.duration_s / wall
    );
    if sim.controller().fault().is_some() {
        // The console's decoding: snapshot at the trip, safe state, later faults.
        let mut out = String::new();
        let _ = regen_fw::console::Console::new().execute(
            "faults",
            sim.controller_mut(),
            &mut regen_fw::console::NoStore,
            &mut out,
        );
        print!("{out}");
    }
    print!("{}", s.text());
    Ok(())
}
