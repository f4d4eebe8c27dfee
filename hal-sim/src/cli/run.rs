//! `regen run SCENARIO`: one closed-loop run → CSV of the recorded channels, an SVG time
//! trace, force–displacement and force–velocity plots, and the energy ledger.

use super::output::{plot_svg, write, Series};
use crate::scenario::Scenario;
use crate::sim::Channel;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct RunArgs {
    /// Scenario file (TOML).
    pub scenario: PathBuf,
    /// Output directory.
    #[arg(long, default_value = "regen-out")]
    pub out: PathBuf,
}

pub fn run(a: &RunArgs) -> Result<(), String> {
    let sc = Scenario::from_file(&a.scenario)?;
    let mut sim = sc.build()?;
    let t = std::time::Instant::now();
    let n = (sc.duration_s / sim.period()).round() as u64;
    let chunk = (n / 50).max(1);
    let mut done = 0;
    while done < n {
        let k = chunk.min(n - done);
        for _ in 0..k {
            sim.step();
        }
        done += k;
        eprint!("\r{:3.0} %", 100.0 * done as f64 / n as f64);
    }
    eprintln!();
    let wall = t.elapsed().as_secs_f64();
    let e = sim.energy();
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
    if let Some(f) = sim.controller().fault() {
        println!("firmware fault latched: {}", f.name());
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
