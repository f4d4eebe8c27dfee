//! `regen commission PORT`: commission a drive over its console (a board's serial port or
//! `regen serve`'s pseudo-terminal, as `regen client`): `mode idle`, `mode align` (the power-up
//! calibration is the drive's own, at boot), `measure`, its results beside the configured
//! values, and with `--apply` (`--save`) `measure apply` (`save`). With `--scenario FILE` the
//! load the measured device wants: the harmonic balance (the paper's eq. 14–23,
//! [`crate::analytic::tmd_power`]) of the scenario's structure and excitation, its screw's
//! friction (or a diagnosed one, `--model FILE` from `regen diagnose --model`), with the
//! measured R and K_e: the optimum R_L and its power beside the configured `r_load_ohm`'s.
//! `docs/commissioning.md`.

use crate::analytic::{optimum_load, tmd_power, DampingFormula};
use crate::cli::client::{Client, ClientError};
use crate::plant::{Drive, Excitation};
use crate::Scenario;
use std::path::PathBuf;
use std::time::Duration;

#[derive(clap::Args, Debug)]
pub struct CommissionArgs {
    /// Serial port: a board's or the pseudo-terminal `regen serve` printed.
    pub port: String,
    /// Baud rate (ignored by a pseudo-terminal).
    #[arg(long, default_value_t = 115_200)]
    pub baud: u32,
    /// Put the results into the drive's RAM configuration (`measure apply`).
    #[arg(long)]
    pub apply: bool,
    /// Then save them to its flash (`save`; needs --apply).
    #[arg(long)]
    pub save: bool,
    /// Skip `mode align` (the drive is aligned already or trusts its stored angle).
    #[arg(long)]
    pub no_align: bool,
    /// The user's structure and excitation (a scenario file: `[drive.structure]`, a sine
    /// `[drive.excitation]`, `[screw]` friction): the optimum load for the measured machine.
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// A diagnosed device model (`regen diagnose --model`): its Coulomb and viscous friction
    /// replace the scenario's screw's.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Longest wait for the alignment and for the measurement, s, (0, 3600].
    #[arg(long, default_value_t = 60.0)]
    pub timeout: f64,
}

/// What `regen commission` needs of a drive: one console command's reply lines (the last
/// `ok …`/`error: …`), and a wait while the drive works.
pub trait Port {
    fn command(&mut self, line: &str) -> Result<Vec<String>, String>;
    fn wait(&mut self, seconds: f64);
}

impl Port for Client {
    fn command(&mut self, line: &str) -> Result<Vec<String>, String> {
        match Client::command(self, line) {
            Ok(r) => Ok(r.body().map(str::to_string).collect()),
            Err(e @ ClientError::Io(_)) | Err(e @ ClientError::Timeout { .. }) => {
                Err(e.to_string())
            }
        }
    }
    fn wait(&mut self, seconds: f64) {
        std::thread::sleep(Duration::from_secs_f64(seconds));
    }
}

/// One measured value as `measure show` lists it.
#[derive(Clone, Debug, PartialEq)]
pub struct Measured {
    /// The registry's name, with ` (q)` for L_q (`l_phase_h`).
    pub name: String,
    pub value: f64,
    pub sigma: f64,
    pub unit: String,
    pub configured: f64,
}

/// The rows of a `measure show` reply: `NAME [(d|q)] measured V +- S UNIT configured C UNIT`.
pub fn parse_show(lines: &[String]) -> Vec<Measured> {
    let mut out = Vec::new();
    for l in lines {
        let Some((name, rest)) = l.split_once(" measured ") else {
            continue;
        };
        let w: Vec<&str> = rest.split_whitespace().collect();
        if w.len() < 6 || w[1] != "+-" || w[4] != "configured" {
            continue;
        }
        let num = |s: &str| s.parse::<f64>().ok();
        if let (Some(value), Some(sigma), Some(configured)) = (num(w[0]), num(w[2]), num(w[5])) {
            out.push(Measured {
                name: name.to_string(),
                value,
                sigma,
                unit: w[3].to_string(),
                configured,
            });
        }
    }
    out
}

/// The reply's last line, and whether it is `ok`.
fn verdict(lines: &[String]) -> (&str, bool) {
    let last = lines.last().map_or("", |s| s.as_str());
    (last, last == "ok" || last.starts_with("ok "))
}

/// `cmd`, refused unless `ok`.
fn must(p: &mut dyn Port, cmd: &str) -> Result<Vec<String>, String> {
    let r = p.command(cmd)?;
    match verdict(&r) {
        (_, true) => Ok(r),
        (last, false) => Err(format!("{cmd}: {last}")),
    }
}

/// A `status` line's value (`mode`, `boot`, `fault`).
fn status_of(lines: &[String], key: &str) -> String {
    lines
        .iter()
        .find_map(|l| {
            let mut w = l.split_whitespace();
            (w.next() == Some(key)).then(|| w.next().unwrap_or("").to_string())
        })
        .unwrap_or_default()
}

/// The load the measured device wants, from the scenario's structure and excitation.
#[derive(Clone, Debug, PartialEq)]
pub struct Load {
    pub optimum_ohm: f64,
    pub optimum_w: f64,
    pub configured_ohm: f64,
    pub configured_w: f64,
    pub coulomb_n: f64,
    pub viscous_n_s_per_m: f64,
}

/// The harmonic balance with the measured `r_ohm` and `ke`, the scenario's structure, sine
/// excitation and friction (a diagnosed model's if given): the optimum load in [1 Ω, 100 kΩ]
/// and the configured one's power.
pub fn load_for(
    sc: &Scenario,
    model: Option<&crate::device_model::DeviceModel>,
    r_ohm: f64,
    ke: f64,
    configured_ohm: f64,
) -> Result<Load, String> {
    let Drive::Structure {
        structure,
        excitation,
    } = &sc.drive
    else {
        return Err("--scenario: drive.kind must be \"structure\" (a structure to damp)".into());
    };
    let Excitation::Sine { a0_m_s2, freq_hz } = *excitation else {
        return Err(
            "--scenario: drive.excitation.kind must be \"sine\" (the harmonic balance's)".into(),
        );
    };
    let mut screw = sc.screw;
    if let Some(m) = model {
        screw.coulomb_n = m.coulomb_friction_N;
        screw.viscous_n_s_per_m = m.viscous_friction_Ns_per_m;
    }
    let machine = crate::plant::Machine {
        r_ohm,
        ke_v_s_per_rad: ke,
        ..sc.machine
    };
    let p = |r: f64| {
        tmd_power(
            r,
            &machine,
            &screw,
            structure,
            a0_m_s2,
            freq_hz,
            DampingFormula::PerPhasePeak,
        )
        .p_load
    };
    let opt = optimum_load(p, 1.0, 1e5);
    Ok(Load {
        optimum_ohm: opt,
        optimum_w: p(opt),
        configured_ohm,
        configured_w: p(configured_ohm),
        coulomb_n: screw.coulomb_n,
        viscous_n_s_per_m: screw.viscous_n_s_per_m,
    })
}

/// The whole commissioning against `p`; the report's lines.
pub fn commission(p: &mut dyn Port, a: &CommissionArgs) -> Result<Vec<String>, String> {
    let mut rep = Vec::new();
    let polls = (a.timeout / 0.25).ceil() as u32;
    must(p, "mode idle")?;
    if !a.no_align {
        must(p, "mode align")?;
        let mut k = 0;
        loop {
            p.wait(0.25);
            let s = must(p, "status")?;
            let (mode, boot, fault) = (
                status_of(&s, "mode"),
                status_of(&s, "boot"),
                status_of(&s, "fault"),
            );
            if fault != "none" && !fault.is_empty() {
                return Err(format!("mode align: fault {fault}"));
            }
            if mode != "align" {
                rep.push(format!("aligned: mode {mode}, boot {boot}"));
                break;
            }
            k += 1;
            if k > polls {
                return Err(format!("mode align: not done in {} s", a.timeout));
            }
        }
    }
    let started = must(p, "measure")?;
    rep.push(verdict(&started).0.to_string());
    let mut k = 0;
    let shown = loop {
        p.wait(0.25);
        let r = p.command("measure show")?;
        match verdict(&r) {
            (l, true) if l.starts_with("ok measure running") => {}
            (_, true) => break r,
            (l, false) => return Err(l.to_string()),
        }
        k += 1;
        if k > polls {
            return Err(format!("measure: not done in {} s", a.timeout));
        }
    };
    let rows = parse_show(&shown);
    rep.push(format!(
        "{:<18} {:>12} {:>12} {:>12} {:>8}  unit",
        "parameter", "configured", "measured", "uncertainty", "change"
    ));
    for m in &rows {
        rep.push(format!(
            "{:<18} {:>12.6} {:>12.6} {:>12.6} {:>+7.2}%  {}",
            m.name,
            m.configured,
            m.value,
            m.sigma,
            100.0 * (m.value / m.configured - 1.0),
            m.unit
        ));
    }
    for l in shown.iter().filter(|l| l.contains(" refused: ")) {
        rep.push(l.clone());
    }
    if a.apply {
        rep.push(verdict(&must(p, "measure apply")?).0.to_string());
        if a.save {
            rep.push(verdict(&must(p, "save")?).0.to_string());
        }
    }
    if let Some(path) = &a.scenario {
        let sc = Scenario::from_file(path)?;
        let model = match &a.model {
            Some(m) => {
                let text = std::fs::read_to_string(m)
                    .map_err(|e| format!("--model {}: {e}", m.display()))?;
                Some(
                    crate::device_model::Fragment::from_toml(&text)
                        .map_err(|e| format!("--model {}: {e}", m.display()))?
                        .model,
                )
            }
            None => None,
        };
        let get = |name: &str| rows.iter().find(|m| m.name == name);
        let (Some(r), Some(ke)) = (get("r_phase_ohm"), get("ke_v_s_per_rad")) else {
            return Err("the load needs the measured r_phase_ohm and ke_v_s_per_rad".into());
        };
        let g = must(p, "get r_load_ohm")?;
        // `ok r_load_ohm = 306 ohm`
        let configured = verdict(&g)
            .0
            .split_once(" = ")
            .and_then(|(_, v)| v.split_whitespace().next()?.parse::<f64>().ok())
            .ok_or_else(|| format!("get r_load_ohm: no value in '{}'", verdict(&g).0))?;
        let ld = load_for(&sc, model.as_ref(), r.value, ke.value, configured)?;
        rep.push(format!(
            "friction: Coulomb {:.3} N, viscous {:.3} N*s/m ({})",
            ld.coulomb_n,
            ld.viscous_n_s_per_m,
            if a.model.is_some() {
                "diagnosed"
            } else {
                "the scenario's screw"
            }
        ));
        rep.push(format!(
            "load: optimum R_L {:.1} ohm ({:.4} W) for this excitation; configured r_load_ohm {:.1} ohm ({:.4} W, {:+.2} %)",
            ld.optimum_ohm,
            ld.optimum_w,
            ld.configured_ohm,
            ld.configured_w,
            100.0 * (ld.configured_w / ld.optimum_w - 1.0)
        ));
    }
    Ok(rep)
}

pub fn run(a: &CommissionArgs) -> Result<(), String> {
    if !(a.timeout > 0.0 && a.timeout <= 3600.0) {
        return Err(format!(
            "--timeout = {}: must lie in (0, 3600] s",
            a.timeout
        ));
    }
    if a.save && !a.apply {
        return Err("--save needs --apply (it saves the applied results)".into());
    }
    let mut c = Client::open(&a.port, a.baud, Duration::from_secs(2))?;
    for l in commission(&mut c, a)? {
        println!("{l}");
    }
    Ok(())
}
