//! `regen run SCENARIO`: one closed-loop run → CSV of the recorded channels, an SVG time
//! trace, force–displacement and force–velocity plots, and the energy ledger.

use super::output::{plot_svg, write, Series};
use crate::scenario::Scenario;
use crate::sim::{Channel, Energy, Recorder};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct RunArgs {
    /// Scenario file (TOML).
    pub scenario: PathBuf,
    /// Output directory.
    #[arg(long, default_value = "regen-out")]
    pub out: PathBuf,
}

/// What one closed-loop run leaves: the ledger at the end and at `settle_s`, the latched
/// fault with the console's decoding, the recorded channels. `regen run` prints and writes it;
/// the Python module (`hal-sim/python`) returns it.
pub struct RunOutcome {
    /// Energy ledger at the end of the run, J.
    pub energy: Energy,
    /// Energy ledger after the PWM period nearest `settle_s`, J (averages are taken after it).
    pub energy_at_settle: Energy,
    /// PWM periods simulated, and the one `energy_at_settle` was read after.
    pub steps: u64,
    pub settle_step: u64,
    /// Name of the latched firmware fault, if any.
    pub fault: Option<&'static str>,
    /// The console's `faults` reply (snapshot at the trip, safe state, later faults).
    pub faults_text: Option<String>,
    /// Recorded channels (None when the scenario records none).
    pub recorder: Option<Recorder>,
    /// Wall time of the stepping, s.
    pub wall_s: f64,
}

/// Run a scenario for its `duration_s` (rounded to whole PWM periods); `progress` is called
/// with the fraction done about 50 times.
pub fn simulate(sc: &Scenario, mut progress: impl FnMut(f64)) -> Result<RunOutcome, String> {
    let mut sim = sc.build()?;
    let t = std::time::Instant::now();
    let n = (sc.duration_s / sim.period()).round() as u64;
    let settle_step = ((sc.settle_s / sim.period()).round() as u64).min(n);
    let mut energy_at_settle = sim.energy();
    let chunk = (n / 50).max(1);
    let mut done = 0;
    while done < n {
        let mut k = chunk.min(n - done);
        if done < settle_step {
            k = k.min(settle_step - done);
        }
        for _ in 0..k {
            sim.step();
        }
        done += k;
        if done == settle_step {
            energy_at_settle = sim.energy();
        }
        progress(done as f64 / n as f64);
    }
    let wall_s = t.elapsed().as_secs_f64();
    let fault = sim.controller().fault().map(|f| f.name());
    let faults_text = fault.map(|_| {
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
        energy: sim.energy(),
        energy_at_settle,
        steps: n,
        settle_step,
        fault,
        faults_text,
        recorder: sim.take_recorder(),
        wall_s,
    })
}

pub fn run(a: &RunArgs) -> Result<(), String> {
    let sc = Scenario::from_file(&a.scenario)?;
    let o = simulate(&sc, |f| eprint!("\r{:3.0} %", 100.0 * f))?;
    eprintln!();
    let wall = o.wall_s;
    let e = o.energy;
    println!(
        "{}: {:.2} s simulated in {:.2} s ({:.0}× real time)",
        sc.name,
        sc.duration_s,
        wall,
        sc.duration_s / wall
    );
    println!(
        "{e:#?}\nenergy residual {:.3e} J ({:.4} %)",
        e.residual(),
        100.0 * e.relative_residual()
    );
    if let (Some(name), Some(text)) = (o.fault, &o.faults_text) {
        println!("firmware fault latched: {name}");
        print!("{text}");
    }
    if let Some(rec) = o.recorder {
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
            let p = plot_svg(
                &a.out.join(format!("{}-force-x.svg", sc.name)),
                "force against displacement",
                "x (m)",
                "force (N)",
                &[Series {
                    name: "f".into(),
                    points: zip(&x, &f),
                    markers: false,
                }],
                false,
            )?;
            println!("plot: {}", p.display());
            let p = plot_svg(
                &a.out.join(format!("{}-force-v.svg", sc.name)),
                "force against velocity",
                "ẋ (m/s)",
                "force (N)",
                &[Series {
                    name: "f".into(),
                    points: zip(&v, &f),
                    markers: false,
                }],
                false,
            )?;
            println!("plot: {}", p.display());
            let p = plot_svg(
                &a.out.join(format!("{}-force-t.svg", sc.name)),
                "force against time",
                "t (s)",
                "force (N)",
                &[Series {
                    name: "f".into(),
                    points: zip(&t, &f),
                    markers: false,
                }],
                false,
            )?;
            println!("plot: {}", p.display());
        }
    }
    Ok(())
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
        let o = simulate(&sc, |_| {}).unwrap();
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
        let rec = o.recorder.unwrap();
        assert_eq!(rec.rows.len() as u64, n / sc.record.every);
    }
}
