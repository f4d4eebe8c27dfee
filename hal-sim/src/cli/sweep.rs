//! `regen sweep SCENARIO --param NAME --values ...`: one closed-loop run per value, in
//! parallel (rayon), average power into the drive after `settle_s`; for the resistor load
//! the analytic harmonic-balance curve is drawn beside it. With no scenario: the reference
//! TMD sweep (what `cargo run --release` with no arguments does). Every run is checked
//! ([`crate::summary::verdict`]); an invalid one is reported with why, without a power (text,
//! the CSV's `valid` and `invalid_why` columns, a red cross at 0 W in the plot), and the best
//! point is the best of the valid runs.

use super::output::{check_out_dir, write};
use super::progress::Progress;
use crate::analytic::{logspace, optimum_load, tmd_power, DampingFormula};
use crate::plant::{Drive, Excitation};
use crate::plot::{Mark, Plot, Series};
use crate::scenario::Scenario;
use crate::summary::{run_scenario, si, RunSummary};
use rayon::prelude::*;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct SweepArgs {
    /// Scenario file (TOML); the reference TMD when omitted.
    pub scenario: Option<PathBuf>,
    /// Parameter to sweep: r_load_ohm, a0_m_s2, freq_hz, ke_v_s_per_rad, current_bw_hz.
    #[arg(long, default_value = "r_load_ohm")]
    pub param: String,
    /// Values, comma separated, in the parameter's unit (its name's suffix: ohm, m_s2 = m/s²,
    /// hz, v_s_per_rad); default for r_load_ohm: 13 loads from 10 Ω to 1 kΩ including 306 Ω.
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true, value_parser = number)]
    pub values: Vec<Number>,
    /// Output directory.
    #[arg(long, default_value = "regen-out")]
    pub out: PathBuf,
    /// No progress bar (it is also hidden when stderr is not a terminal).
    #[arg(long, short)]
    pub quiet: bool,
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

/// A number as given on the command line: its value and its text.
#[derive(Clone, Debug, PartialEq)]
pub struct Number {
    pub v: f64,
    pub text: String,
}

/// Text that is not a number is a usage error (clap's); `nan`, `inf` and an overflowing
/// `1e400` are numbers here and refused by [`parse_values`] with the parameter's range.
fn number(t: &str) -> Result<Number, String> {
    t.trim()
        .parse::<f64>()
        .map(|v| Number {
            v,
            text: t.to_string(),
        })
        .map_err(|_| "not a number".to_string())
}

/// `--values` checked as finite numbers; a value that is not one (text, `nan`, `inf`, `1e400`,
/// which overflows to inf) is refused with the parameter's key and allowed range.
pub fn parse_values(sc: &Scenario, param: &str, values: &[Number]) -> Result<Vec<f64>, String> {
    values
        .iter()
        .map(|n| {
            if n.v.is_finite() {
                return Ok(n.v);
            }
            let t = &n.text;
            // The scenario's own refusal of the value (as `Scenario.set` gives it in Python);
            // where the scenario takes it (an infinite load is an open circuit), the range as
            // the scenario states it for a NaN.
            let mut s = sc.clone();
            if let Err(e) = set_param(&mut s, param, n.v).and_then(|_| s.check()) {
                return Err(format!("--param {param} --values {t}: {e}"));
            }
            let mut probe = sc.clone();
            let range = set_param(&mut probe, param, f64::NAN)
                .and_then(|_| probe.check())
                .err()
                .and_then(|e| {
                    let (key, why) = e.split_once(": ")?;
                    let key = key.split(" = ").next()?;
                    Some(format!("; {key} {}", why.replace(" (or inf = open)", "")))
                })
                .unwrap_or_default();
            Err(format!(
                "--param {param} --values {t}: not a finite number{range}"
            ))
        })
        .collect()
}

/// Average power from the machine into the drive after `settle_s`, W, and the run's
/// relative energy residual ([`run_scenario`]'s figures); an invalid run
/// ([`crate::summary::verdict`]) is an error naming why.
pub fn average_power(sc: &Scenario) -> Result<(f64, f64), String> {
    let r = run_scenario(sc, &mut |_| {})?;
    if let Some(why) = &r.invalid {
        return Err(format!("{}: invalid run: {why}", sc.name));
    }
    Ok((r.mean_power_w, r.energy.relative_residual()))
}

/// Axis label of a swept parameter, with its unit.
fn param_label(name: &str) -> String {
    match name {
        "r_load_ohm" => "load resistance R_L (Ω, log scale)".into(),
        "a0_m_s2" => "base acceleration amplitude a₀ (m/s²)".into(),
        "freq_hz" => "excitation frequency (Hz)".into(),
        "ke_v_s_per_rad" => "back-emf constant K_e (V·s/rad, per-phase peak)".into(),
        "current_bw_hz" => "current-loop bandwidth (Hz)".into(),
        _ => name.into(),
    }
}

/// The default load grid of the reference sweep, Ω (denser near the expected optima).
pub const DEFAULT_LOADS: [f64; 13] = [
    10.0, 20.0, 30.0, 50.0, 75.0, 100.0, 150.0, 200.0, 250.0, 306.0, 400.0, 600.0, 1000.0,
];

pub fn run(a: &SweepArgs) -> Result<(), String> {
    let sc = match &a.scenario {
        Some(p) => Scenario::from_file(p)?,
        None => Scenario::tmd(306.0),
    };
    let values = if a.values.is_empty() {
        if a.param != "r_load_ohm" {
            return Err(format!("--values: required for --param {}", a.param));
        }
        DEFAULT_LOADS.to_vec()
    } else {
        set_param(&mut sc.clone(), &a.param, 1.0)?;
        parse_values(&sc, &a.param, &a.values)?
    };
    let scs: Vec<Scenario> = values
        .iter()
        .map(|&v| {
            let mut s = sc.clone();
            set_param(&mut s, &a.param, v)?;
            s.check()
                .and_then(|_| s.config().map(|_| ()))
                .map_err(|e| format!("--param {} --values {v}: {e}", a.param))?;
            Ok(s)
        })
        .collect::<Result<_, String>>()?;
    check_out_dir(&a.out)?;
    // The reference sweep also runs the paper-equivalent device (per-phase peak K_e =
    // 0.77·√1.5, whose consistent damping equals the paper's 9/4·0.77²) when the scenario's
    // device is another: the paper's optimum reproduced in closed loop beside it.
    let ke_p = 0.77 * 1.5f64.sqrt();
    let reference =
        a.scenario.is_none() && ((sc.machine.ke_v_s_per_rad - ke_p) / ke_p).abs() > 1e-6;
    let n = scs.len();
    let bar = Progress::new(
        &format!("sweep {}", a.param),
        sc.duration_s * n as f64 * if reference { 2.0 } else { 1.0 },
        a.quiet,
    );
    let t = std::time::Instant::now();
    let runs = |scs: &[Scenario]| -> Result<Vec<RunSummary>, String> {
        scs.par_iter()
            .map(|s| run_scenario(s, &mut bar.callback()))
            .collect()
    };
    let res = runs(&scs)?;
    let paper_eq = if reference {
        let scs_p: Vec<Scenario> = scs
            .iter()
            .map(|s| {
                let mut s = s.clone();
                s.machine.ke_v_s_per_rad = ke_p;
                s
            })
            .collect();
        Some(runs(&scs_p)?)
    } else {
        None
    };
    bar.finish();
    let wall = t.elapsed().as_secs_f64();
    let fault_of = |r: &RunSummary| r.fault.unwrap_or("none");
    // An invalid run's power is not a result: an empty CSV field, no figure in the text, its
    // mark at 0 W in the plot.
    let power_field = |r: &RunSummary| {
        if r.valid() {
            format!("{:.6e}", r.mean_power_w)
        } else {
            String::new()
        }
    };
    let why_field = |r: &RunSummary| match &r.invalid {
        Some(w) => w.replace(',', ";"),
        None => String::new(),
    };
    let mut header: Vec<String> = vec![
        a.param.clone(),
        "p_closed_loop_w".into(),
        "peak_force_n".into(),
        "energy_residual_rel".into(),
        "fault".into(),
        "valid".into(),
        "invalid_why".into(),
    ];
    let mut rows: Vec<Vec<String>> = values
        .iter()
        .zip(&res)
        .map(|(v, r)| {
            vec![
                format!("{v:.6e}"),
                power_field(r),
                format!("{:.6e}", r.peak_force_n),
                format!("{:.3e}", r.energy.relative_residual()),
                fault_of(r).to_string(),
                r.valid().to_string(),
                why_field(r),
            ]
        })
        .collect();
    let with_fault = |rs: &[RunSummary]| -> Vec<bool> { rs.iter().map(|r| !r.valid()).collect() };
    let points = |rs: &[RunSummary]| -> Vec<(f64, f64)> {
        values
            .iter()
            .zip(rs)
            .map(|(v, r)| (*v, if r.valid() { r.mean_power_w } else { 0.0 }))
            .collect()
    };
    let mut plot = Plot::new(
        format!(
            "{}: mean harvested power, {} closed-loop runs of {} s",
            sc.name, n, sc.duration_s
        ),
        param_label(&a.param),
        format!("mean harvested power after {} s (W)", sc.settle_s),
    );
    plot.xlog = a.param == "r_load_ohm";
    plot.fault_label = "invalid run (no power: drawn at 0 W)".into();
    plot.series.push(Series {
        faulted: with_fault(&res),
        ..Series::markers(
            format!(
                "closed loop, firmware in the loop (K_e = {:.3} V·s/rad)",
                sc.machine.ke_v_s_per_rad
            ),
            points(&res),
        )
    });
    let mut answer = Vec::new();
    if let Some(pe) = &paper_eq {
        for (row, r) in rows.iter_mut().zip(pe) {
            row.push(power_field(r));
            row.push(fault_of(r).to_string());
            row.push(r.valid().to_string());
        }
        header.push("p_closed_loop_paper_equivalent_w".into());
        header.push("fault_paper_equivalent".into());
        header.push("valid_paper_equivalent".into());
        plot.series.push(Series {
            faulted: with_fault(pe),
            ..Series::markers(
                format!("closed loop, paper-equivalent K_e = {ke_p:.3}"),
                points(pe),
            )
        });
        if let Some((v, r)) = best(&values, pe) {
            answer.push(format!(
                "closed loop, paper-equivalent K_e = {ke_p:.3}: best of the swept points {} = {v}, mean power {}",
                a.param,
                si(r.mean_power_w, "W")
            ));
        }
    }
    // Analytic curves for the resistor sweep of a sine-excited structure.
    if let (
        "r_load_ohm",
        Drive::Structure {
            structure,
            excitation: Excitation::Sine { a0_m_s2, freq_hz },
        },
    ) = (a.param.as_str(), &sc.drive)
    {
        let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let grid = logspace(lo.clamp(1e-3, 10.0), hi.max(1000.0), 400);
        let model = |f: DampingFormula, r: f64| {
            tmd_power(r, &sc.machine, &sc.screw, structure, *a0_m_s2, *freq_hz, f)
        };
        let an: Vec<(f64, f64)> = grid
            .iter()
            .map(|&r| (r, model(DampingFormula::PerPhasePeak, r).p_load))
            .collect();
        let opt = optimum_load(|r| model(DampingFormula::PerPhasePeak, r).p_load, 1.0, 1e4);
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
        answer.push(format!(
            "analytic (harmonic balance, this device): optimum R_L = {opt:.1} Ω, mean power {}",
            si(model(DampingFormula::PerPhasePeak, opt).p_load, "W")
        ));
        answer.push(format!(
            "analytic (paper's eq. 16 with K_e = 0.77 and 9/4): optimum R_L = {opt_paper:.1} Ω, mean power {}",
            si(paper(opt_paper), "W")
        ));
        for (row, v) in rows.iter_mut().zip(&values) {
            row.push(format!(
                "{:.6e}",
                model(DampingFormula::PerPhasePeak, *v).p_load
            ));
            row.push(format!("{:.6e}", paper(*v)));
        }
        header.push("p_analytic_w".into());
        header.push("p_paper_model_w".into());
        let paper_curve: Vec<(f64, f64)> = grid.iter().map(|&r| (r, paper(r))).collect();
        // The paper's curve is drawn only where it differs from the harmonic balance (with the
        // reference K_e the two are the same curve: one line, one legend entry).
        let same = an
            .iter()
            .zip(&paper_curve)
            .all(|(a, b)| (a.1 - b.1).abs() <= 1e-6 * a.1.abs().max(b.1.abs()));
        // The curves go under the closed-loop markers.
        if same {
            let name = "harmonic balance = paper's eq. 16 with 9/4·0.77²";
            plot.series.insert(0, Series::line(name, an));
        } else {
            let name = format!("paper's model, 9/4·0.77² (optimum {opt_paper:.0} Ω)");
            plot.series.insert(0, Series::line("harmonic balance", an));
            plot.series.insert(1, Series::line(name, paper_curve));
        }
        plot.marks.push(Mark::VLine {
            x: opt,
            label: format!("analytic optimum R_L = {opt:.0} Ω"),
        });
    }
    if let Some((v, r)) = best(&values, &res) {
        plot.marks.push(Mark::Star {
            at: (v, r.mean_power_w),
            label: format!(
                "best closed-loop point: {} = {v}, {}",
                a.param,
                si(r.mean_power_w, "W")
            ),
        });
    }
    let stem = format!("sweep-{}-{}", sc.name, a.param);
    let csv = a.out.join(format!("{stem}.csv"));
    let mut text = header.join(",") + "\n";
    for r in &rows {
        text += &(r.join(",") + "\n");
    }
    write(&csv, &text)?;
    let svg = plot.write_svg(&a.out.join(format!("{stem}.svg")))?;
    println!(
        "{n} runs of {:.1} s simulated in {wall:.2} s",
        sc.duration_s
    );
    for (v, r) in values.iter().zip(&res) {
        match &r.invalid {
            None => println!(
                "  {} = {v:<10}  mean power {:>11}  peak force {:>10}  energy residual {:.1e}",
                a.param,
                si(r.mean_power_w, "W"),
                si(r.peak_force_n, "N"),
                r.energy.relative_residual(),
            ),
            Some(why) => println!("  {} = {v:<10}  INVALID: {why}", a.param),
        }
    }
    println!("CSV: {}\nplot: {}", csv.display(), svg.display());
    for l in &answer {
        println!("{l}");
    }
    let invalid: Vec<String> = values
        .iter()
        .zip(&res)
        .filter(|(_, r)| !r.valid())
        .map(|(v, _)| format!("{} = {v}", a.param))
        .collect();
    if invalid.is_empty() {
        println!("invalid runs: none");
    } else {
        println!(
            "invalid runs: {} of {n} (no power given, left out of the best): {}",
            invalid.len(),
            invalid.join(", ")
        );
    }
    match best(&values, &res) {
        Some((v, r)) => {
            println!(
                "best of the swept points: {} = {v}, mean harvested power {}, peak force {}",
                a.param,
                si(r.mean_power_w, "W"),
                si(r.peak_force_n, "N")
            );
            Ok(())
        }
        None => Err("no valid run: the sweep has no best point".into()),
    }
}

/// The valid run of highest mean power ([`crate::summary::verdict`]).
fn best<'a>(values: &[f64], rs: &'a [RunSummary]) -> Option<(f64, &'a RunSummary)> {
    values
        .iter()
        .copied()
        .zip(rs)
        .filter(|(_, r)| r.valid() && r.mean_power_w.is_finite())
        .max_by(|a, b| a.1.mean_power_w.total_cmp(&b.1.mean_power_w))
}
