//! The diagnosis's extended model as a scenario fragment (`regen diagnose --model`): the
//! baseline and each kept finding with exactly the parameters the report gives, as the
//! simulator's plant physics ([`crate::device_model`]), loaded by `regen run --model`.

use super::{effects, Diagnosis, Record};
use crate::device_model::{DeviceModel, Fragment, ModelEffect};

/// The extended model of a diagnosis as plant physics, or why it cannot be one (nothing
/// fitted, a non-physical baseline, a parameter outside its range).
pub fn device_model(rec: &Record, d: &Diagnosis) -> Result<DeviceModel, String> {
    let get = |name: &str| d.model.iter().find(|(n, _)| n == name).map(|(_, v)| *v);
    let (Some(m), Some(fv), Some(fc), Some(off)) = (
        get("inertia"),
        get("viscous"),
        get("coulomb"),
        get("offset"),
    ) else {
        return Err("no model was fitted (see the report's verdict)".into());
    };
    let mut effects = Vec::new();
    for (i, (e, f)) in d.effects.iter().zip(&d.findings).enumerate() {
        if worsens_cross_check(d, i) {
            // a finding the second record contradicts is not a device model
            continue;
        }
        // the effect's own entries beside the report's parameters, or why the plant does not
        // express it (the record's channel, not the device: left out)
        let Ok(extra) = e.kind.fragment(e, &d.model, rec.dt()) else {
            continue;
        };
        // the report's parameters, by their report names, read as the plant's effect
        let mut t = toml::Table::new();
        t.insert("name".into(), toml::Value::String(e.kind.name().into()));
        for (k, v) in &f.parameters {
            t.insert(k.clone(), toml::Value::Float(*v));
        }
        for (k, v) in extra {
            let v = match v {
                effects::FragmentValue::Number(x) => toml::Value::Float(x),
                effects::FragmentValue::List(xs) => {
                    toml::Value::Array(xs.into_iter().map(toml::Value::Float).collect())
                }
            };
            t.insert(k, v);
        }
        let eff: ModelEffect = toml::Value::Table(t)
            .try_into()
            .map_err(|err| format!("{}: {err}", e.kind.name()))?;
        effects.push(eff);
    }
    let dm = DeviceModel {
        inertia_kg: m,
        viscous_friction_Ns_per_m: fv,
        coulomb_friction_N: fc,
        force_offset_N: off,
        sign_band_m_s: effects::sign_band(&rec.v),
        effects,
    };
    dm.check()?;
    Ok(dm)
}

/// Whether the cross-check's second record is worse with finding `i` than without it.
fn worsens_cross_check(d: &Diagnosis, i: usize) -> bool {
    d.cross
        .as_ref()
        .is_some_and(|c| c.worsens.get(i).copied().unwrap_or(false))
}

/// The fragment file: a comment header (what the simulator cannot express) and the
/// `[model]` table; a model that cannot be plant physics is written as comments only, with
/// the reason, so that `regen run --model` refuses it by name.
pub fn fragment_toml(rec: &Record, d: &Diagnosis) -> String {
    let mut s = String::from(
        "# device model from `regen diagnose` (docs/diagnose.md, \"The loop\"): the baseline and\n# each kept finding with the report's parameters; `regen run SCENARIO --model THIS` runs it\n# on an imposed motion (e.g. drive.motion = { kind = \"record\", path = \"RECORD.csv\" }).\n",
    );
    let mut outside = Vec::new();
    for (n, v) in &d.model {
        if n.starts_with("em_") {
            outside.push(format!(
                "{n} = {v:e}: the electromagnetic force is the simulated machine's (machine.ke_v_s_per_rad and the law), not the model's"
            ));
        }
    }
    for (i, f) in d.findings.iter().enumerate() {
        let not_plant = d
            .effects
            .get(i)
            .and_then(|e| e.kind.fragment(e, &d.model, rec.dt()).err());
        let why = match (not_plant, f.effect.as_str()) {
            (Some(why), _) => why,
            (None, "unexplained") => "no catalogue effect, not simulated",
            (None, _) if i < d.effects.len() && worsens_cross_check(d, i) => {
                "worsens the cross-check's second record, left out"
            }
            _ => continue,
        };
        let p: Vec<String> = f
            .parameters
            .iter()
            .map(|(k, v)| format!("{k} = {v:e}"))
            .collect();
        outside.push(format!("{} ({}): {why}", f.effect, p.join(", ")));
    }
    if !outside.is_empty() {
        s.push_str("# not expressed by the simulator's plant:\n");
        for o in &outside {
            s.push_str(&format!("#   {o}\n"));
        }
    }
    match device_model(rec, d) {
        Ok(m) => s.push_str(&Fragment { model: m }.to_toml()),
        Err(e) => s.push_str(&format!("# no model: {e}\n")),
    }
    s
}

#[cfg(test)]
mod actuator_lag_tests {
    use super::super::*;
    use super::{device_model, fragment_toml};

    /// A record whose force channel is a command leading the force the motion needs by `tau`
    /// (negative: a force that lags), in closed form: x = A·sin ωt + A/3·sin 3.1ωt, the force
    /// M·a + Fv·v + Fc·sgn v evaluated at t + tau, plus a deterministic ±0.3 N noise.
    fn record(tau: f64) -> Record {
        let (m, fv, fc, amp, w) = (50.0, 100.0, 20.0, 0.05, std::f64::consts::TAU * 0.7);
        let force = |t: f64| {
            let v = amp * w * ((w * t).cos() + 3.1 / 3.0 * (3.1 * w * t).cos());
            let a = -amp * w * w * ((w * t).sin() + 3.1 * 3.1 / 3.0 * (3.1 * w * t).sin());
            m * a + fv * v + fc * v.signum()
        };
        let mut s = String::from("t_s,x_m,f_N\n");
        let mut seed = 12345u64;
        for i in 0..20_000 {
            let t = i as f64 * 1e-3;
            let x = amp * ((w * t).sin() + (3.1 * w * t).sin() / 3.0);
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let noise = 0.3 * (2.0 * (seed >> 11) as f64 / (1u64 << 53) as f64 - 1.0);
            s.push_str(&format!("{t},{x},{}\n", force(t + tau) + noise));
        }
        parse_csv(&s, None).unwrap()
    }

    fn delay(d: &Diagnosis) -> Option<f64> {
        d.findings
            .iter()
            .find(|f| f.effect == "actuator_lag")
            .map(|f| f.parameters[0].1)
    }

    /// A command 0.4 ms ahead of the force (EMPS: 0.38–0.40 ms) is named with its delay; a
    /// force 0.4 ms behind the motion (a lagging sensor) is not (the sign rule:
    /// `effects::plausible` keeps 0 < ω_c·τ ≤ 1).
    #[test]
    fn command_ahead_of_the_force_is_named_with_its_delay() {
        let tau = 4e-4;
        let rec = record(tau);
        let d = diagnose(&rec, &Options::default());
        let got = delay(&d).expect("actuator_lag named");
        // the record's channel, not the device: stated in the fragment's header, not a plant
        // effect (the fragment still loads)
        let frag = fragment_toml(&rec, &d);
        assert!(frag.contains("#   actuator_lag (delay_s = "), "{frag}");
        let m = device_model(&rec, &d).expect("the fragment is a device model");
        assert_eq!(m.effects.len(), d.effects.len() - 1, "{frag}");
        println!("delay {got:e} s for {tau:e} s");
        // measured 0.433 ms (8 % high: the derivative filter's smoothing and the baseline
        // fitted on the shifted force bias the first-order column); 10 % is the bound, a
        // half-sample error in the column (a backward difference) reads 0.198 ms
        assert!((got / tau - 1.0).abs() < 0.1, "{got}");
        let d = diagnose(&record(-tau), &Options::default());
        assert_eq!(delay(&d), None, "a lagging force named actuator_lag");
    }
}

#[cfg(test)]
mod cross_check_tests {
    use super::fragment_toml;
    use crate::device_model::Fragment;
    use crate::diagnose::*;

    /// A diagnosis of a baseline and one `cogging` finding (the parameters the report gives),
    /// with a cross-check that says whether the finding worsens the second record.
    fn diagnosis(worsens: bool) -> (Record, Diagnosis) {
        let mut s = String::from("t_s,x_m,f_N\n");
        for i in 0..1000 {
            let t = i as f64 * 1e-3;
            s.push_str(&format!("{t},{},{}\n", 0.01 * (6.0 * t).sin(), t.cos()));
        }
        let rec = parse_csv(&s, None).unwrap();
        let base = [
            ("inertia", 20.0),
            ("viscous", 100.0),
            ("coulomb", 15.0),
            ("offset", 0.5),
        ];
        let d = Diagnosis {
            model: base.iter().map(|(n, v)| (n.to_string(), *v)).collect(),
            effects: vec![Effect::new(effects::COGGING, 0.004)],
            findings: vec![Finding {
                effect: "cogging".into(),
                parameters: vec![
                    ("wavelength_m".into(), 0.004),
                    ("amplitude_N".into(), 3.0),
                    ("phase_rad".into(), 0.2),
                ],
                ..Finding::default()
            }],
            cross: Some(CrossCheck {
                baseline_rel_error: 0.05,
                final_rel_error: if worsens { 0.06 } else { 0.04 },
                after_each: vec![("cogging".into(), if worsens { 0.06 } else { 0.04 })],
                worsens: vec![worsens],
            }),
            ..Diagnosis::default()
        };
        (rec, d)
    }

    /// A finding the second record contradicts is named in the fragment's header and left out
    /// of its `[model]`; one the second record bears out is in it.
    #[test]
    fn a_finding_that_worsens_the_cross_check_stays_out_of_the_model() {
        for worsens in [false, true] {
            let (rec, d) = diagnosis(worsens);
            let frag = fragment_toml(&rec, &d);
            let m = Fragment::from_toml(&frag).expect("a model").model;
            println!("worsens {worsens}:\n{frag}");
            assert_eq!(m.effects.len(), usize::from(!worsens), "{frag}");
            assert_eq!(
                frag.contains("cogging (wavelength_m = 4e-3"),
                worsens,
                "{frag}"
            );
        }
    }
}

#[cfg(test)]
mod spring_tests {
    use super::device_model;
    use crate::diagnose::*;

    /// A record in closed form: x = A·sin ωt + A/3·sin 2.7ωt about `x0`, the force
    /// M·a + Fv·v + Fc·sgn v + k·(x − x0) + a deterministic ±0.5 N noise (a seeded LCG).
    fn record(k: f64, x0: f64, seed: u64) -> Record {
        let (m, fv, fc, amp, w) = (40.0, 300.0, 25.0, 0.04, std::f64::consts::TAU * 0.6);
        let mut s = String::from("t_s,x_m,f_N\n");
        let mut st = seed
            .wrapping_mul(2862933555777941757)
            .wrapping_add(3037000493);
        for i in 0..12_000 {
            let t = i as f64 * 1e-3;
            let x = amp * ((w * t).sin() + (2.7 * w * t).sin() / 3.0);
            let v = amp * w * ((w * t).cos() + 0.9 * (2.7 * w * t).cos());
            let a = -amp * w * w * ((w * t).sin() + 2.43 * (2.7 * w * t).sin());
            st = st
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let noise = 0.5 * (2.0 * (st >> 11) as f64 / (1u64 << 53) as f64 - 1.0);
            let f = m * a + fv * v + fc * v.signum() + k * x + noise;
            s.push_str(&format!("{t},{},{f}\n", x + x0));
        }
        parse_csv(&s, None).unwrap()
    }

    /// A hidden spring (its force at the stroke's end 0.5–1.5× the Coulomb level) is named
    /// `spring` with its stiffness, and the fragment carries it as plant physics; with no
    /// spring hidden none is named. Measured relative stiffness errors over 6 records
    /// 1·10⁻⁵ … 7.4·10⁻⁴ (printed); the bound 2.2·10⁻³ is 3× the largest. Break: the column's
    /// sign flipped (−(x − x_mid): the admissible k > 0 then refuses every fit) fails the
    /// naming.
    #[test]
    fn a_spring_is_named_with_its_stiffness() {
        let mut errs = Vec::new();
        for seed in 0..6u64 {
            let k = 25.0 * (0.5 + 0.2 * seed as f64) / 0.05;
            let rec = record(k, 0.1 * seed as f64, seed);
            let d = diagnose(&rec, &Options::default());
            let f = d
                .findings
                .iter()
                .find(|f| f.effect == "spring")
                .unwrap_or_else(|| panic!("seed {seed}: {:?}", d.catalogue_names()));
            let got = f.parameters[0].1;
            errs.push((got / k - 1.0).abs());
            let m = device_model(&rec, &d).expect("a device model");
            assert!(m.effects.iter().any(|e| e.name() == "spring"), "{m:?}");
        }
        println!("stiffness errors {errs:?}");
        assert!(errs.iter().all(|e| *e < 2.2e-3), "{errs:?}");
        let d = diagnose(&record(0.0, 0.0, 9), &Options::default());
        assert!(
            !d.catalogue_names().contains(&"spring"),
            "{:?}",
            d.catalogue_names()
        );
    }
}
