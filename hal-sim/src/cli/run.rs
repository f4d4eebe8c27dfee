//! `regen run SCENARIO`: one closed-loop run → its answer (mean harvested power after
//! settling, peak force, energy balance, faults latched; [`crate::summary::RunSummary`]), a
//! CSV of the recorded channels and plots of force against time, displacement and velocity,
//! and, when recorded, of the currents against their references, the bus voltage and the
//! power into the drive, the settle time marked on each plot against time.

use super::output::{check_out_dir, write};
use super::progress::Progress;
use crate::plot::{Mark, Plot, Series};
use crate::scenario::Scenario;
use crate::sim::{Channel, Energy, Recorder};
use crate::summary::{run_to_end, si, RunSummary};
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
    /// No progress bar (it is also hidden when stderr is not a terminal).
    #[arg(long, short)]
    pub quiet: bool,
    /// A diagnosed device model (the fragment `regen diagnose --model` writes: one `[model]`
    /// table) replacing the scenario's `[model]`; needs an imposed motion.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Also write the run as a record in the `diagnose` schema (`t_s, x_m, f_N`, and `i_q_A`
    /// when recorded) at the recorder's rate; the channels t, x and force are recorded.
    #[arg(long)]
    pub record_diagnose: Option<PathBuf>,
}

/// A run's recorded channels as a record in the `diagnose` schema (docs/diagnose.md): CSV
/// `t_s, x_m, f_N` (force on the device in +x), `i_q_A` when recorded, the screw's lead as
/// `# lead_m_per_rev` metadata; every value written exactly (shortest text reading back to
/// the same `f64`).
pub fn diagnose_record_csv(rec: &Recorder, lead_m_per_rev: f64) -> Result<String, String> {
    let col = |c| rec.column(c);
    let (Some(t), Some(x), Some(f)) = (col(Channel::T), col(Channel::X), col(Channel::Force))
    else {
        return Err(
            "--record-diagnose: the channels t, x and force must be recorded (record.channels)"
                .into(),
        );
    };
    let iq = col(Channel::Iq);
    let mut s = format!(
        "# regen run record in the diagnose schema\n# lead_m_per_rev = {lead_m_per_rev}\nt_s,x_m,f_N{}\n",
        if iq.is_some() { ",i_q_A" } else { "" }
    );
    for i in 0..t.len() {
        s.push_str(&format!("{},{},{}", t[i], x[i], f[i]));
        if let Some(q) = &iq {
            s.push_str(&format!(",{}", q[i]));
        }
        s.push('\n');
    }
    Ok(s)
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

/// What one closed-loop run leaves: its summary (the ledger at the end and at `settle_s`, the
/// latched fault and when, the figures `regen run` prints), the console's decoding of the
/// fault, the recorded channels and the wall time. `regen run` prints and writes it; the
/// Python module (`hal-sim/python`) returns it.
pub struct RunOutcome {
    pub summary: RunSummary,
    /// The console's `faults` reply (snapshot at the trip, safe state, later faults).
    pub faults_text: Option<String>,
    /// Recorded channels (None when the scenario records none).
    pub recorder: Option<Recorder>,
    /// Wall time of the stepping, s.
    pub wall_s: f64,
}

/// Run a scenario for its `duration_s` (whole PWM periods); `progress` is called with the
/// simulated seconds advanced since its last call ([`run_to_end`]).
pub fn simulate(sc: &Scenario, progress: &mut dyn FnMut(f64)) -> Result<RunOutcome, String> {
    let mut sim = sc.build()?;
    let t = std::time::Instant::now();
    let summary = run_to_end(sc, &mut sim, progress);
    let wall_s = t.elapsed().as_secs_f64();
    let faults_text = summary.fault.map(|_| {
        let mut out = String::new();
        let _ = regen_fw::console::Console::new().execute(
            "faults",
            sim.controller_mut(),
            &mut regen_fw::console::NoStore,
            &mut out,
        );
        out
    });
    Ok(RunOutcome {
        summary,
        faults_text,
        recorder: sim.take_recorder(),
        wall_s,
    })
}

/// The ledger on one line with every value exact (the shortest text that reads back to the
/// same `f64`): `energy ledger (J, exact): external_work = …, to_inverter = …, …`.
pub fn exact_ledger_line(e: &Energy) -> String {
    let d = format!("{e:?}");
    let inner = d
        .strip_prefix("Energy { ")
        .and_then(|s| s.strip_suffix(" }"))
        .unwrap_or(&d);
    format!("energy ledger (J, exact): {}", inner.replace(": ", " = "))
}

pub fn run(a: &RunArgs) -> Result<(), String> {
    let mut sc = Scenario::from_file(&a.scenario)?;
    if let Some(m) = &a.model {
        sc = sc.with_model_file(m).map_err(|e| format!("--model {e}"))?;
    }
    if let Some(p) = &a.record_diagnose {
        if p.is_dir() {
            return Err(format!(
                "--record-diagnose {}: is a directory, a file path expected",
                p.display()
            ));
        }
        for c in ["t", "x", "force"] {
            if !sc.record.channels.iter().any(|k| k == c) {
                sc.record.channels.push(c.into());
            }
        }
    }
    let window = check_window(&a.window, sc.duration_s)?;
    check_out_dir(&a.out)?;
    let bar = Progress::new(&sc.name, sc.duration_s, a.quiet);
    let o = simulate(&sc, &mut bar.callback())?;
    bar.finish();
    let (s, wall) = (&o.summary, o.wall_s);
    if let (Some(p), Some(rec)) = (&a.record_diagnose, &o.recorder) {
        let lead = sc.screw.lead_m_per_rad * std::f64::consts::TAU;
        write(p, &diagnose_record_csv(rec, lead)?)?;
        println!("diagnose record: {}", p.display());
    }
    if let Some(rec) = &o.recorder {
        let csv = a.out.join(format!("{}.csv", sc.name));
        write(&csv, &rec.to_csv())?;
        println!("trace: {}", csv.display());
        println!(
            "channels digest (FNV-1a 64 of the f64 bits, row-major): {:016x}",
            rec.digest()
        );
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
            let settle = Mark::VLine {
                x: s.settle_s,
                label: format!("settled: averages from t = {} s", s.settle_s),
            };
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
                if file == "force-t" {
                    p.marks.push(settle.clone());
                }
                let path = p.write_svg(&a.out.join(format!("{}-{file}.svg", sc.name)))?;
                println!("plot: {}", path.display());
            }
            let time_plot = |file: &str, title: &str, ylabel: &str, series: Vec<Series>| {
                let mut p = Plot::new(format!("{what}: {title}"), "time t (s)", ylabel);
                if file == "currents" {
                    // The reference light, the measured current dark, i_d apart.
                    p.colours = vec![(0x9e, 0xc5, 0xe8), (0x08, 0x30, 0x6b), (0xe6, 0x55, 0x0d)];
                }
                p.series = series;
                p.window = window;
                p.marks.push(settle.clone());
                let path = p.write_svg(&a.out.join(format!("{}-{file}.svg", sc.name)))?;
                println!("plot: {}", path.display());
                Ok::<(), String>(())
            };
            if let (Some(iq), Some(iq_ref)) = (col(Channel::Iq), col(Channel::IqRef)) {
                // The reference wide and light under the measured current, thin and dark.
                let mut series = vec![
                    Series {
                        width: Some(5),
                        ..Series::line("reference i_q* (the law's command)", zip(&t, &iq_ref))
                    },
                    Series {
                        width: Some(1),
                        ..Series::line("q current i_q (measured by the firmware)", zip(&t, &iq))
                    },
                ];
                if let Some(id) = col(Channel::Id) {
                    series.push(Series::line("d current i_d (reference 0 A)", zip(&t, &id)));
                }
                time_plot(
                    "currents",
                    "currents against their references",
                    "current (A)",
                    series,
                )?;
            }
            if let Some(vb) = col(Channel::VBus) {
                // A bus held by its source moves by millivolts: then its deviation from the
                // first sample is drawn, in mV (round ticks, the ripple visible).
                let v0 = vb.first().copied().unwrap_or(0.0);
                let (lo, hi) = vb.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |m, &v| {
                    (m.0.min(v), m.1.max(v))
                });
                let (ylabel, series) = if hi - lo < 0.01 * v0.abs() {
                    let dv: Vec<f64> = vb.iter().map(|v| (v - v0) * 1e3).collect();
                    (
                        format!("bus voltage − {v0:.1} V (mV)"),
                        Series::line(format!("bus voltage v_bus − {v0:.1} V"), zip(&t, &dv)),
                    )
                } else {
                    (
                        "bus voltage (V)".to_string(),
                        Series::line("bus voltage v_bus", zip(&t, &vb)),
                    )
                };
                time_plot("bus", "DC bus voltage", &ylabel, vec![series])?;
            }
            if let Some(pw) = col(Channel::PInverter) {
                let mut series = vec![Series::line(
                    "power from the machine into the inverter",
                    zip(&t, &pw),
                )];
                if s.valid() {
                    series.push(Series::line(
                        format!("mean after settling: {}", si(s.mean_power_w, "W")),
                        vec![(s.settle_s, s.mean_power_w), (s.duration_s, s.mean_power_w)],
                    ));
                }
                time_plot(
                    "power",
                    "harvested power",
                    "power into the drive (W)",
                    series,
                )?;
            }
        }
    }
    println!(
        "{:.2} s simulated in {:.2} s ({:.0}× real time)",
        sc.duration_s,
        wall,
        sc.duration_s / wall
    );
    if let Some(text) = &o.faults_text {
        // The console's decoding: snapshot at the trip, safe state, later faults.
        print!("{text}");
    }
    println!("{}", exact_ledger_line(&s.energy));
    print!("{}", s.text());
    match &s.invalid {
        Some(why) => Err(format!("invalid run: {why}")),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The ledger at `settle_s` and at the end equal a plain run stepped to those times.
    #[test]
    fn simulate_reads_the_ledger_at_settle() {
        let mut sc = Scenario::tmd(306.0);
        sc.duration_s = 0.5;
        sc.settle_s = 0.1837;
        let run = simulate(&sc, &mut |_| {}).unwrap();
        let o = &run.summary;
        let mut sim = sc.build().unwrap();
        let settle = (sc.settle_s / sim.period()).round() as u64;
        let n = (sc.duration_s / sim.period()).round() as u64;
        assert_eq!((o.settle_step, o.steps), (settle, n));
        for _ in 0..settle {
            sim.step();
        }
        assert_eq!(o.energy_at_settle, sim.energy());
        for _ in settle..n {
            sim.step();
        }
        assert_eq!(o.energy, sim.energy());
        assert!(o.energy_at_settle.external_work < o.energy.external_work);
        let rec = run.recorder.unwrap();
        assert_eq!(rec.rows.len() as u64, n / sc.record.every);
    }
}
