//! Every answer is checked before it is given (`hal_sim::summary::verdict`): over random
//! scenarios drawn within the scenario's allowed ranges, no run reported valid has an open
//! energy ledger or a recorded state outside its physical range, both judged here from the
//! ledger's fields and the recorded channels; `regen run` of an invalid run exits 1 and says
//! why, and every shipped scenario runs valid. `REGEN_VALIDITY_RUNS=1` prints every random
//! run (its keys, residual and verdict).

use hal_sim::plant::{Drive, Excitation};
use hal_sim::summary::{run_scenario, LEDGER_LIMIT};
use hal_sim::Scenario;
use rayon::prelude::*;
use std::process::Command;

/// SplitMix64: the test's own generator.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Log-uniform in [lo, hi].
    fn log(&mut self, lo: f64, hi: f64) -> f64 {
        (lo.ln() + self.next() * (hi.ln() - lo.ln())).exp()
    }
}

/// A reference-TMD scenario of 2 s with the plant's and the excitation's keys drawn
/// log-uniformly within their allowed ranges (`docs/simulator.md`, "Scenario ranges"; the
/// draw is checked against them).
fn random_scenario(seed: u64) -> Scenario {
    let mut r = Rng(seed);
    let mut sc = Scenario::tmd(r.log(1.0, 1e4));
    sc.duration_s = 2.0;
    sc.settle_s = 1.0;
    sc.record.channels = ["v", "v_bus", "i_q", "force"].map(String::from).to_vec();
    sc.record.every = 10;
    sc.machine.ke_v_s_per_rad = r.log(0.05, 5.0);
    sc.machine.r_ohm = r.log(0.05, 50.0);
    sc.machine.l_h = r.log(1e-4, 0.1);
    sc.screw.coulomb_n = r.log(0.1, 1e3);
    if let Drive::Structure {
        structure,
        excitation,
    } = &mut sc.drive
    {
        structure.mass_kg = r.log(1.0, 1e5);
        let fn_hz = r.log(0.05, 20.0);
        structure.stiffness_n_per_m = structure.mass_kg * (std::f64::consts::TAU * fn_hz).powi(2);
        if let Excitation::Sine { a0_m_s2, freq_hz } = excitation {
            *a0_m_s2 = r.log(0.01, 100.0);
            *freq_hz = fn_hz * r.log(0.5, 2.0);
        }
    }
    sc.check()
        .expect("the draw lies within the scenario's ranges (hal_sim::scenario::RANGES)");
    sc
}

/// The ledger's residual relative to its largest flow, from the ledger's fields.
fn open_fraction(e: &hal_sim::sim::Energy) -> f64 {
    let out = e.friction_loss
        + e.viscous_b_loss
        + e.screw_loss
        + e.copper_loss
        + e.switching_loss
        + e.conduction_loss
        + e.logic_loss
        + e.brake
        + e.source_r_loss
        + e.sink
        + e.structure_damping
        + e.stored_now
        - e.stored_start;
    let big = [
        e.external_work.abs(),
        e.to_inverter.abs(),
        e.copper_loss.abs(),
        e.sink.abs(),
        e.friction_loss.abs(),
    ]
    .into_iter()
    .fold(1e-12, f64::max);
    ((e.external_work - out) / big).abs()
}

#[test]
fn no_valid_looking_run_has_an_open_ledger() {
    const N: u64 = 240;
    let runs: Vec<_> = (0..N)
        .into_par_iter()
        .map(|k| {
            let sc = random_scenario(0x5eed_0000 + k);
            let cfg = sc.config();
            let mut sim = sc.build().expect("a scenario within the ranges builds");
            let s = hal_sim::summary::run_to_end(&sc, &mut sim, &mut |_| {});
            let rec = sim.take_recorder().expect("recorded");
            (sc, cfg.expect("config"), s, rec)
        })
        .collect();
    let mut valid_resid: Vec<f64> = Vec::new();
    let mut invalid_resid: Vec<f64> = Vec::new();
    let mut reasons = std::collections::BTreeMap::<String, usize>::new();
    for (sc, cfg, s, rec) in &runs {
        let open = open_fraction(&s.energy);
        if std::env::var("REGEN_VALIDITY_RUNS").is_ok() {
            if let Drive::Structure {
                structure,
                excitation: Excitation::Sine { a0_m_s2, freq_hz },
            } = &sc.drive
            {
                println!(
                    "open {open:.1e}  f_n {:.2} Hz  f {freq_hz:.2} Hz  a0 {a0_m_s2:.3}  m {:.0} kg  R_L {:.0}  K_e {:.2}  R {:.2}  L {:.4}  peak θe/T {:.3}  i {:.1}  why {:?}",
                    (structure.stiffness_n_per_m / structure.mass_kg).sqrt() / std::f64::consts::TAU,
                    structure.mass_kg,
                    sc.law.r_load_ohm,
                    sc.machine.ke_v_s_per_rad,
                    sc.machine.r_ohm,
                    sc.machine.l_h,
                    s.extremes.theta_e_per_period_max,
                    s.extremes.i_phase_max,
                    s.invalid
                );
            }
        }
        match &s.invalid {
            Some(why) => {
                invalid_resid.push(open);
                for w in why.split("; ") {
                    let head: String = w.split([' ', '(']).take(2).collect::<Vec<_>>().join(" ");
                    *reasons.entry(head).or_default() += 1;
                }
            }
            None => {
                valid_resid.push(open);
                assert!(
                    open <= LEDGER_LIMIT,
                    "{}: valid with the ledger open by {open:.2e}",
                    sc.name
                );
                // The recorded state inside its range: the bus between 0 V and the trip, the
                // q current within the trip.
                let col = |c| rec.column(c).unwrap();
                let vb = col(hal_sim::Channel::VBus);
                let iq = col(hal_sim::Channel::Iq);
                assert!(
                    vb.iter().all(|&v| (0.0..=cfg.v_bus_ov as f64).contains(&v)),
                    "valid run with the bus outside [0, v_bus_ov]"
                );
                assert!(
                    iq.iter().all(|&i| i.abs() <= 1.1 * cfg.i_trip_a as f64),
                    "valid run with i_q beyond 1.1·i_trip_a"
                );
                assert!(s.mean_power_w.is_finite() && s.fault.is_none());
            }
        }
    }
    let q = |v: &mut Vec<f64>, f: f64| {
        v.sort_by(f64::total_cmp);
        v.get(((v.len().max(1) - 1) as f64 * f) as usize)
            .copied()
            .unwrap_or(f64::NAN)
    };
    println!(
        "{} random scenarios: {} valid, {} invalid",
        N,
        valid_resid.len(),
        invalid_resid.len()
    );
    println!(
        "valid runs' ledger residual (relative): median {:.1e}, 99 % {:.1e}, max {:.1e} (limit {LEDGER_LIMIT:.0e})",
        q(&mut valid_resid, 0.5),
        q(&mut valid_resid, 0.99),
        q(&mut valid_resid, 1.0)
    );
    println!(
        "invalid runs' ledger residual: median {:.1e}, max {:.1e}",
        q(&mut invalid_resid, 0.5),
        q(&mut invalid_resid, 1.0)
    );
    println!("invalid runs' reasons: {reasons:?}");
    // Both kinds are drawn: the test exercises the verdict both ways.
    assert!(valid_resid.len() >= N as usize / 5, "too few valid runs");
    assert!(
        invalid_resid.len() >= N as usize / 10,
        "too few invalid runs"
    );
}

#[test]
fn an_excitation_beyond_the_device_is_an_invalid_run() {
    let d = std::env::temp_dir().join(format!("regen-validity-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/scenarios/tmd-306.toml"
    ))
    .unwrap();
    for (a0, key) in [("10000.0", "drive.excitation.a0_m_s2"), ("50.0", "")] {
        println!("a0 = {a0}");
        let p = d.join(format!("a{a0}.toml"));
        std::fs::write(
            &p,
            text.replace("a0_m_s2 = 1.0", &format!("a0_m_s2 = {a0}")),
        )
        .unwrap();
        let o = Command::new(env!("CARGO_BIN_EXE_regen"))
            .args(["run", p.to_str().unwrap(), "-q", "--out"])
            .arg(d.join("out"))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        let out = String::from_utf8_lossy(&o.stdout);
        println!("{err}");
        assert_eq!(o.status.code(), Some(1), "a0 = {a0}: {err}");
        assert_eq!(err.lines().count(), 1, "one line: {err}");
        if key.is_empty() {
            // Inside the range: the run says it is invalid and why, and gives no power.
            assert!(err.contains("invalid run: protection latched"), "{err}");
            assert!(out.contains("INVALID run, no result"), "{out}");
            assert!(!out.contains("mean harvested power"), "{out}");
        } else {
            assert!(err.contains(key) && err.contains("m/s²"), "{err}");
        }
    }
}

#[test]
fn every_shipped_scenario_runs_valid() {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/scenarios");
    let mut n = 0;
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "toml") {
            let sc = Scenario::from_file(&p).unwrap();
            let s = run_scenario(&sc, &mut |_| {}).unwrap();
            println!(
                "{}: residual {:.1e}, {:?}",
                p.display(),
                s.energy.relative_residual(),
                s.invalid
            );
            assert!(s.valid(), "{}: {:?}", p.display(), s.invalid);
            n += 1;
        }
    }
    assert!(n >= 6);
}
