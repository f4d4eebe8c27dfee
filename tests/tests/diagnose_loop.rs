//! The diagnosis's loop closed: a record of the independent bench rig (`hal_sim::bench_rig`,
//! effects as physics, no code shared with the fitting) is diagnosed, its `--model` fragment
//! is loaded into a scenario, the closed-loop simulator (firmware in the loop, open-circuit
//! law) replays the record's motion and writes a record in the diagnose schema, and the
//! simulated force is compared with the measured one on the held-out blocks.

use hal_sim::bench_rig::{RigSpec, Trajectory};
use hal_sim::cli::run::diagnose_record_csv;
use hal_sim::device_model::{DeviceModel, Fragment};
use hal_sim::diagnose::{
    diagnose, effects::at_rest, holdout_mask, parse_csv, report, Options, Record, HELD_OUT,
};
use hal_sim::plant::Motion;
use hal_sim::scenario::Scenario;
use hal_sim::summary::run_to_end;

/// Replay `path`'s motion with `model` through the closed-loop simulator (firmware in the
/// loop, gates off: `Mode::Idle`, so the machine carries no current and the device force is
/// the model's, as on the bench record that has no currents); returns the simulator's record
/// in the diagnose schema (`diagnose_record_csv`, what `regen run --record-diagnose` writes).
fn replay(path: &std::path::Path, model: &DeviceModel, duration_s: f64) -> Record {
    let mut sc = Scenario::imposed(
        Motion::Record {
            path: path.display().to_string(),
            cutoff_hz: None,
        },
        f64::INFINITY,
        duration_s,
    );
    sc.model = Some(model.clone());
    // one row per record sample (1 kHz): the PWM rate over 1 kHz
    sc.record.every = (sc.firmware.pwm_hz as f64 / 1000.0).round() as u64;
    sc.record.channels = vec!["t".into(), "x".into(), "force".into()];
    sc.check().expect("scenario with the model");
    let mut sim = sc.build().expect("replay builds");
    sim.controller_mut()
        .set_mode(regen_fw::Mode::Idle)
        .expect("idle");
    let summary = run_to_end(&sc, &mut sim, &mut |_| {});
    assert!(
        summary.fault.is_none(),
        "replay tripped: {:?}",
        summary.fault
    );
    let lead = sc.screw.lead_m_per_rad * std::f64::consts::TAU;
    let csv = diagnose_record_csv(sim.recorder().expect("recorded"), lead).unwrap();
    parse_csv(&csv, None).expect("the simulator's record reads back")
}

/// Relative error of the simulated force against the measured one on the held-out samples
/// in motion of the split `split` (the diagnosis's held-out set: `Diagnosis::split`), samples
/// matched by time.
fn holdout_error(meas: &Record, sim: &Record, split: usize) -> f64 {
    let n = meas.len();
    let hold = holdout_mask(n, split);
    let rest = at_rest(&meas.x, &meas.v, meas.dt());
    let fs = 1.0 / meas.dt();
    let (mut e2, mut f2) = (0.0, 0.0);
    for j in 0..sim.len() {
        let i = (sim.t[j] * fs).round() as usize;
        if i < n && hold[i] == HELD_OUT && !rest[i] {
            e2 += (meas.f[i] - sim.f[j]).powi(2);
            f2 += meas.f[i].powi(2);
        }
    }
    (e2 / f2).sqrt()
}

/// The model of `d`'s baseline alone (its whole-record fit, `stage_models[0]`), as the
/// simulator's plant: what the diagnosis's baseline error is measured with.
fn baseline_model(d: &hal_sim::diagnose::Diagnosis, m: &DeviceModel) -> DeviceModel {
    let get = |n: &str| {
        d.stage_models[0]
            .iter()
            .find(|(k, _)| k == n)
            .map(|(_, v)| *v)
            .unwrap()
    };
    DeviceModel {
        inertia_kg: get("inertia"),
        viscous_friction_Ns_per_m: get("viscous"),
        coulomb_friction_N: get("coulomb"),
        force_offset_N: get("offset"),
        sign_band_m_s: m.sign_band_m_s,
        effects: vec![],
    }
}

/// A rig record diagnosed, its fragment loaded (`effect` must be in it), and its motion
/// replayed by the closed-loop simulator with the extended model, with the baseline alone and
/// with `effect` dropped; each replay's held-out error against the measured force, the
/// diagnosis's own (whole-record) prediction's, and the two gains.
struct Loop {
    rec: Record,
    d: hal_sim::diagnose::Diagnosis,
    toml: String,
    m: DeviceModel,
    /// the replay with the extended model
    e_ext: f64,
    /// the diagnosis's prediction
    e_pred: f64,
    /// the replayed force against the prediction
    e_vs_pred: f64,
    /// the replay with the baseline alone, and with `effect` dropped
    e_base: f64,
    e_drop: f64,
    g_diag: f64,
    g_sim: f64,
}

fn close_loop(spec: &RigSpec, tag: &str, effect: &str) -> Loop {
    let text = spec.csv();
    let dir = std::env::temp_dir().join(format!("regen-diagloop-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("rig.csv");
    std::fs::write(&path, &text).unwrap();
    let rec = parse_csv(&text, None).unwrap();
    let d = diagnose(&rec, &Options::default());
    let toml = report::model_toml(&rec, &d);
    let m = Fragment::from_toml(&toml)
        .expect("the fragment loads")
        .model;
    let k = m
        .effects
        .iter()
        .position(|e| e.name() == effect)
        .unwrap_or_else(|| panic!("{effect} not named: {toml}"));
    let dur = rec.t[rec.len() - 1];
    let sim_ext = replay(&path, &m, dur);
    let e_ext = holdout_error(&rec, &sim_ext, d.split);
    // the simulator's force against the diagnosis's prediction of the same model
    let mut pred = rec.clone();
    pred.f = d.prediction.clone();
    let e_vs_pred = holdout_error(&pred, &sim_ext, d.split);
    let e_pred = holdout_error(&rec, &pred, d.split);
    let e_base = holdout_error(&rec, &replay(&path, &baseline_model(&d, &m), dur), d.split);
    let e_drop = holdout_error(&rec, &replay(&path, &m.without(k), dur), d.split);
    let _ = std::fs::remove_dir_all(&dir);
    let (g_diag, g_sim) = (
        d.baseline_holdout_rel_error / d.final_holdout_rel_error,
        e_base / e_ext,
    );
    Loop {
        rec,
        d,
        toml,
        m,
        e_ext,
        e_pred,
        e_vs_pred,
        e_base,
        e_drop,
        g_diag,
        g_sim,
    }
}

/// The parameter `name` of `d`'s finding `effect`.
fn param(d: &hal_sim::diagnose::Diagnosis, effect: &str, name: &str) -> f64 {
    d.findings
        .iter()
        .find(|f| f.effect == effect)
        .and_then(|f| f.parameters.iter().find(|(n, _)| n == name))
        .unwrap_or_else(|| panic!("{effect}.{name} not reported"))
        .1
}

/// A bench-rig record with a hidden Stribeck bump (static friction 1.5–2.5× Coulomb, LuGre in
/// the rig) on a multisine, 12 s at 1 kHz: diagnosed, its fragment loaded, its motion
/// replayed by the simulator with the extended model, with the baseline alone and with the
/// finding dropped.
#[test]
fn held_out_gain_is_reproduced_by_the_simulator() {
    let seed = 12;
    let spec = RigSpec::random(seed, "stribeck", Trajectory::Multisine, 12_000);
    let Loop {
        d,
        toml,
        m,
        e_ext,
        e_pred,
        e_vs_pred,
        e_base,
        e_drop,
        g_diag,
        g_sim,
        ..
    } = close_loop(&spec, "s", "stribeck");
    // the fragment carries exactly the report's numbers
    let names: Vec<&str> = m.effects.iter().map(|e| e.name()).collect();
    assert_eq!(names, ["stribeck"], "{toml}");
    let f = &d.findings[0];
    let p = |k: &str| f.parameters.iter().find(|(n, _)| n == k).unwrap().1;
    match m.effects[0] {
        hal_sim::device_model::ModelEffect::Stribeck {
            stribeck_velocity_m_s,
            amplitude_N,
        } => {
            assert_eq!(stribeck_velocity_m_s, p("stribeck_velocity_m_s"));
            assert_eq!(amplitude_N, p("amplitude_N"));
        }
        _ => unreachable!(),
    }
    println!(
        "diagnosis: held-out {:.3} % → {:.3} % (gain {g_diag:.2}×), its whole-record model's prediction {:.3} %; simulator replay: {:.3} % → {:.3} % (gain {g_sim:.2}×); stribeck dropped from the fragment: {:.3} %; replay against the prediction {:.4} %",
        100.0 * d.baseline_holdout_rel_error,
        100.0 * d.final_holdout_rel_error,
        100.0 * e_pred,
        100.0 * e_base,
        100.0 * e_ext,
        100.0 * e_drop,
        100.0 * e_vs_pred
    );
    // Measured: diagnosis 19.697 % → 5.146 % (3.83×), its whole-record model's
    // prediction 5.099 %; replay 19.070 % → 5.094 % (3.74×), stribeck dropped 25.78 %; the
    // replayed force against the prediction 0.033 % (bound 3×, 0.1 %).
    // The replay and the prediction of the same model differ by the simulator's own path
    // (mid-period sampling of the Hermite-interpolated motion, period-averaged force):
    // 0.005 points; bound 3× that rounded up, 0.02 points. The gain differs by 2.4 % (the
    // diagnosis's errors are of its training-part fits, the fragment is the whole-record
    // fit); bound 3×, 7.5 %. Dropping the one finding must lose at least half of the gain
    // (measured: all of it, 5.1× worse than the extended model).
    assert!(
        e_vs_pred < 0.001,
        "replay against the prediction: {e_vs_pred}"
    );
    assert!(
        (e_ext - e_pred).abs() < 0.0002,
        "replay {e_ext} vs the diagnosis's prediction {e_pred}"
    );
    assert!(
        (g_sim / g_diag - 1.0).abs() < 0.075,
        "gain {g_sim} vs {g_diag}"
    );
    assert!(
        e_drop > e_ext * (1.0 + 0.5 * (g_diag - 1.0)),
        "dropped {e_drop}"
    );
}

/// A bench-rig record with a hidden load-path resonance (a mass on a spring-damper in the rig,
/// integrated at 20 substeps per sample) on a multisine: `compliance` is named with a modal
/// mass, a resonance and a damping ratio that the simulator's plant (its own integration of a
/// hung mass) replays with the held-out gain the diagnosis reports.
#[test]
fn compliance_is_reproduced_by_the_simulator() {
    let seed = 13;
    let spec = RigSpec::random(seed, "resonance", Trajectory::Multisine, 12_000);
    let Loop {
        d,
        m,
        e_ext,
        e_pred,
        e_vs_pred,
        e_base,
        e_drop,
        g_diag,
        g_sim,
        ..
    } = close_loop(&spec, "c", "compliance");
    println!(
        "hidden {:?}; model {:?}\ndiagnosis: held-out {:.3} % → {:.3} % (gain {g_diag:.2}×), its whole-record model's prediction {:.3} %; simulator replay: {:.3} % → {:.3} % (gain {g_sim:.2}×); compliance dropped: {:.3} %; replay against the prediction {:.4} %",
        spec.hidden,
        m.effects,
        100.0 * d.baseline_holdout_rel_error,
        100.0 * d.final_holdout_rel_error,
        100.0 * e_pred,
        100.0 * e_base,
        100.0 * e_ext,
        100.0 * e_drop,
        100.0 * e_vs_pred
    );
    // Measured: hidden 13.496 kg, 1.3891 Hz, ζ 0.1138; found 13.769 kg (+2.0 %),
    // 1.3888 Hz (−0.02 %), ζ 0.1160 (+1.9 %); diagnosis 33.534 % → 1.063 % (31.6×), its
    // prediction 1.059 %; replay 30.203 % → 1.060 % (28.5×: the replayed baseline is the
    // whole-record fit, the diagnosis's the training fit), compliance dropped 42.30 %; replay
    // against the prediction 0.025 %. Bounds 3× the measured deviations: parameters 6 %, 0.5 %
    // (the frequency's earlier +0.11 %), 6 %; replay against prediction 0.075 %; gain within
    // 30 %; dropping the mode loses at least half of the gain. With the replay's velocity the
    // acceleration's band instead of the reader's own (the friction seen through another
    // velocity than the diagnosis's), the replay is 0.123 % from the prediction and fails.
    let hp = |k: &str| param(&d, "compliance", k);
    let hal_sim::bench_rig::Hidden::Resonance {
        mass_kg,
        freq_hz,
        zeta,
    } = spec.hidden
    else {
        unreachable!()
    };
    assert!(
        (hp("modal_mass_kg") / mass_kg - 1.0).abs() < 0.06,
        "modal mass {}",
        hp("modal_mass_kg")
    );
    assert!(
        (hp("resonance_Hz") / freq_hz - 1.0).abs() < 0.005,
        "resonance {}",
        hp("resonance_Hz")
    );
    assert!(
        (hp("damping_ratio") / zeta - 1.0).abs() < 0.06,
        "damping ratio {}",
        hp("damping_ratio")
    );
    assert!(
        e_vs_pred < 0.00075,
        "replay against the prediction: {e_vs_pred}"
    );
    assert!(
        (g_sim / g_diag - 1.0).abs() < 0.3,
        "gain {g_sim} vs {g_diag}"
    );
    assert!(
        e_drop > e_ext * (1.0 + 0.5 * (g_diag - 1.0)),
        "dropped {e_drop}"
    );
}

/// A bench-rig record with play in the screw (the device's mass and drive behind a gap, a
/// 60 Hz contact in the rig) on a multisine: `backlash` is named with its width, and the
/// simulator's plant (the same device behind the play, `effects::PlayWalk`, with the model's
/// inertia and friction) replays it with the held-out gain the diagnosis reports.
#[test]
fn backlash_is_reproduced_by_the_simulator() {
    let seed = 600_001;
    let spec = RigSpec::random(seed, "backlash", Trajectory::Multisine, 12_000);
    let Loop {
        rec,
        d,
        m,
        e_ext,
        e_pred,
        e_vs_pred,
        e_base,
        e_drop,
        g_diag,
        g_sim,
        ..
    } = close_loop(&spec, "b", "backlash");
    // the model stepped on the record's own samples, without the simulator
    let mut series = rec.clone();
    series.f = m.force_series(rec.dt(), &rec.x, &rec.v, &rec.a);
    let e_series = holdout_error(&rec, &series, d.split);
    println!(
        "hidden {:?}; model {:?}\ndiagnosis: held-out {:.3} % → {:.3} % (gain {g_diag:.2}×), its whole-record model's prediction {:.3} %; simulator replay: {:.3} % → {:.3} % (gain {g_sim:.2}×); backlash dropped: {:.3} %; replay against the prediction {:.4} %",
        spec.hidden,
        m,
        100.0 * d.baseline_holdout_rel_error,
        100.0 * d.final_holdout_rel_error,
        100.0 * e_pred,
        100.0 * e_base,
        100.0 * e_ext,
        100.0 * e_drop,
        100.0 * e_vs_pred
    );
    println!(
        "the model stepped on the record's samples: {:.3} %",
        100.0 * e_series
    );
    // Measured: width 0.8661 mm against the rig's 0.8704 (−0.50 %); diagnosis
    // 57.708 % → 11.436 % (5.05×), its prediction 11.327 %; the model on the record's samples
    // 11.734 %; replay 57.707 % → 11.396 % (5.06×), backlash dropped 57.744 %; the replayed
    // force against the prediction 0.72 %. Bounds 3× the measured deviations: width 1.5 %,
    // replay against the prediction 2.2 %, the replay's gain within 1 % of the diagnosis's
    // (measured 0.2 %); dropping the play loses at least half of the gain. The play's device
    // walked with the reader's velocity instead of the acceleration's band's
    // (`Motion::v_kin_at`): 12.45 % from the prediction, fails. Without the
    // device's coasting, its own coefficients or the fitted pulse in the plant the replay is
    // 39–106 % (measured: a device that cannot coast, 105.5 %, fails the second assert).
    let hp = |k: &str| param(&d, "backlash", k);
    let hal_sim::bench_rig::Hidden::Backlash { width_m } = spec.hidden else {
        unreachable!()
    };
    assert!(
        (hp("width_m") / width_m - 1.0).abs() < 0.015,
        "width {}",
        hp("width_m")
    );
    assert!(
        e_vs_pred < 0.022,
        "replay against the prediction {e_vs_pred}"
    );
    assert!(
        (g_sim / g_diag - 1.0).abs() < 0.01,
        "replay's gain {g_sim} against the diagnosis's {g_diag}"
    );
    assert!(
        e_base / e_drop < 1.0 + 0.5 * (g_sim - 1.0),
        "dropping backlash keeps the gain: {e_drop}"
    );
}
