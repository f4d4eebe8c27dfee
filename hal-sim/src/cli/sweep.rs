//! `regen sweep SCENARIO --param NAME --values ...`: one closed-loop run per value, in
//! parallel (rayon), average power into the drive after `settle_s`; for the resistor load
//! the analytic harmonic-balance curve is drawn beside it. With no scenario: the reference
//! TMD sweep (what `cargo run --release` with no arguments does).

use super::output::{plot_svg, write_csv, Series};
use crate::analytic::{logspace, optimum_load, tmd_power, DampingFormula};
use crate::plant::{Drive, Excitation};
use crate::scenario::Scenario;
use rayon::prelude::*;
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

#[derive(clap::Args, Debug)]
pub struct SweepArgs {
    /// Scenario file (TOML); the reference TMD when omitted.
    pub scenario: Option<PathBuf>,
    /// Parameter to sweep: r_load_ohm, a0_m_s2, freq_hz, ke_v_s_per_rad, current_bw_hz.
    #[arg(long, default_value = "r_load_ohm")]
    pub param: String,
    /// Values (comma separated); default: 10 log-spaced loads from 10 Ω to 1 kΩ.
    #[arg(long, value_delimiter = ',')]
    pub values: Vec<f64>,
    /// Output directory.
    #[arg(long, default_value = "regen-out")]
    pub out: PathBuf,
}

/// Apply a parameter value to a scenario.
pub fn set_param(sc: &mut Scenario, name: &str, v: f64) -> Result<(), String> {
    match name {
        "r_load_ohm" => sc.law.r_load_ohm = v,
        "ke_v_s_per_rad" => {
            sc.machine.ke_v_s_per_rad = v;
            sc.firmware.ke_v_s_per_rad = None;
        }
        "current_bw_hz" => sc.firmware.current_bw_hz = v as f32,
        "a0_m_s2" | "freq_hz" => match &mut sc.drive {
            Drive::Structure {
                excitation: Excitation::Sine { a0_m_s2, freq_hz },
                ..
            } => {
                if name == "a0_m_s2" {
                    *a0_m_s2 = v
                } else {
                    *freq_hz = v
                }
            }
            _ => return Err(format!("--param {name}: needs a structure with a sine excitation")),
        },
        _ => return Err(format!("--param: unknown parameter `{name}` (r_load_ohm, a0_m_s2, freq_hz, ke_v_s_per_rad, current_bw_hz)")),
    }
    Ok(())
}

/// Average power from the machine into the drive after `settle_s`, W, and the run's
/// relative energy residual.
pub fn average_power(sc: &Scenario) -> Result<(f64, f64), String> {
    let mut sc = sc.clone();
    sc.record.channels.clear();
    let mut sim = sc.build()?;
    sim.run_for(sc.settle_s);
    let e0 = sim.energy().to_inverter;
    sim.run_for(sc.duration_s - sc.settle_s);
    let e = sim.energy();
    Ok((
        (e.to_inverter - e0) / (sc.duration_s - sc.settle_s),
        e.relative_residual(),
    ))
}

pub fn run(a: &SweepArgs) -> Result<(), String> {
    let sc = match &a.scenario {
        Some(p) => Scenario::from_file(p)?,
        None => Scenario::tmd(306.0),
    };
    let values = if a.values.is_empty() {
        if a.param != "r_load_ohm" {
            return Err("--values: required for this parameter".into());
        }
        logspace(10.0, 1000.0, 10)
    } else {
        a.values.clone()
    };
    let scs: Vec<Scenario> = values
        .iter()
        .map(|&v| {
            let mut s = sc.clone();
            set_param(&mut s, &a.param, v)?;
            s.config()?;
            Ok(s)
        })
        .collect::<Result<_, String>>()?;
    let t = std::time::Instant::now();
    let done = AtomicUsize::new(0);
    let n = scs.len();
    let res: Vec<Result<(f64, f64), String>> = scs
        .par_iter()
        .map(|s| {
            let r = average_power(s);
            let k = done.fetch_add(1, Ordering::Relaxed) + 1;
            eprint!(
                "\r[{}{}] {k}/{n}",
                "#".repeat(k * 30 / n),
                " ".repeat(30 - k * 30 / n)
            );
            r
        })
        .collect();
    eprintln!();
    let wall = t.elapsed().as_secs_f64();
    let mut rows = Vec::new();
    let mut sim_pts = Vec::new();
    for (v, r) in values.iter().zip(res) {
        let (p, resid) = r?;
        sim_pts.push((*v, p));
        rows.push(vec![*v, p, resid]);
    }
    println!(
        "{} runs of {:.1} s simulated in {:.2} s wall",
        n, sc.duration_s, wall
    );
    let mut series = vec![Series {
        name: "closed loop (firmware + plant)".into(),
        points: sim_pts.clone(),
        markers: true,
    }];
    let mut header = vec![a.param.as_str(), "p_closed_loop_w", "energy_residual_rel"];
    // Analytic curves for the resistor sweep of a sine-excited structure.
    if let (
        "r_load_ohm",
        Drive::Structure {
            structure,
            excitation: Excitation::Sine { a0_m_s2, freq_hz },
        },
    ) = (a.param.as_str(), &sc.drive)
    {
        let ta = std::time::Instant::now();
        let grid = logspace(
            values[0].min(10.0),
            values[values.len() - 1].max(1000.0),
            400,
        );
        let model = |f: DampingFormula, r: f64| {
            tmd_power(r, &sc.machine, &sc.screw, structure, *a0_m_s2, *freq_hz, f)
        };
        let an: Vec<(f64, f64)> = grid
            .iter()
            .map(|&r| (r, model(DampingFormula::PerPhasePeak, r).p_load))
            .collect();
        let opt = optimum_load(|r| model(DampingFormula::PerPhasePeak, r).p_load, 1.0, 1e4);
        let ta = ta.elapsed().as_secs_f64();
        // The paper's model: its 9/4 formula with K_e = 0.77 (= 3/2·our K_e for the
        // default device), as eq. 16 is written.
        let mut paper_m = sc.machine;
        paper_m.ke_v_s_per_rad = 0.77;
        let paper = |r: f64| {
            tmd_power(
                r,
                &paper_m,
                &sc.screw,
                structure,
                *a0_m_s2,
                *freq_hz,
                DampingFormula::Paper,
            )
            .p_load
        };
        let opt_paper = optimum_load(paper, 1.0, 1e4);
        println!("analytic (harmonic balance, this device): optimum R_L = {opt:.1} Ω, P = {:.2} W  [{} points + optimum in {:.2} ms]", model(DampingFormula::PerPhasePeak, opt).p_load, grid.len(), ta * 1e3);
        println!("analytic (paper's eq. 16 with K_e = 0.77 and 9/4): optimum R_L = {opt_paper:.1} Ω, P = {:.2} W", paper(opt_paper));
        let best = sim_pts
            .iter()
            .copied()
            .fold((0.0, f64::MIN), |b, p| if p.1 > b.1 { p } else { b });
        println!(
            "closed loop: best of the swept loads R_L = {:.1} Ω, P = {:.2} W",
            best.0, best.1
        );
        for r in rows.iter_mut() {
            r.push(model(DampingFormula::PerPhasePeak, r[0]).p_load);
            r.push(paper(r[0]));
        }
        header.push("p_analytic_w");
        header.push("p_paper_model_w");
        series.push(Series {
            name: format!("harmonic balance (optimum {opt:.0} Ω)"),
            points: an,
            markers: false,
        });
        series.push(Series {
            name: format!("paper's model, 9/4·0.77² (optimum {opt_paper:.0} Ω)"),
            points: grid.iter().map(|&r| (r, paper(r))).collect(),
            markers: false,
        });
    }
    let csv = a.out.join(format!("sweep-{}-{}.csv", sc.name, a.param));
    write_csv(&csv, &header, &rows)?;
    for r in &rows {
        println!(
            "  {} = {:9.3}  P = {:8.3} W  (energy residual {:.2e})",
            a.param, r[0], r[1], r[2]
        );
    }
    let svg = plot_svg(
        &a.out.join(format!("sweep-{}-{}.svg", sc.name, a.param)),
        &format!("{}: average power into the drive", sc.name),
        &a.param,
        "power (W)",
        &series,
        a.param == "r_load_ohm",
    )?;
    println!("CSV: {}\nplot: {}", csv.display(), svg.display());
    Ok(())
}
