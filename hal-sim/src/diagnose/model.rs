//! The diagnosis's extended model as a scenario fragment (`regen diagnose --model`): the
//! baseline and each kept finding with exactly the parameters the report gives, as the
//! simulator's plant physics ([`crate::device_model`]), loaded by `regen run --model`.

use super::{Diagnosis, Record};
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
    for (e, f) in d.effects.iter().zip(&d.findings) {
        if e.kind == super::EffectKind::ActuatorLag {
            // the recording's force channel (a drive's command ahead of the force), not the
            // device: the plant carries the force the motion needs
            continue;
        }
        // the report's parameters, by their report names, read as the plant's effect
        let mut t = toml::Table::new();
        t.insert("name".into(), toml::Value::String(e.kind.name().into()));
        for (k, v) in &f.parameters {
            t.insert(k.clone(), toml::Value::Float(*v));
        }
        if e.kind == super::EffectKind::Backlash {
            // the impact's force pulse as fitted (whole-record coefficients), per tap
            let taps: Vec<toml::Value> = (0..super::effects::IMPACT_TAPS)
                .map(|k| toml::Value::Float(get(&format!("backlash.impact_{k}")).unwrap_or(0.0)))
                .collect();
            t.insert("impact_pulse_kg".into(), toml::Value::Array(taps));
            t.insert("impact_tap_s".into(), toml::Value::Float(rec.dt()));
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
        sign_band_m_s: super::effects::sign_band(&rec.v),
        effects,
    };
    dm.check()?;
    Ok(dm)
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
    for f in &d.findings {
        let why = match f.effect.as_str() {
            "actuator_lag" => "the record's force channel leads the device's force, not simulated",
            "unexplained" => "no catalogue effect, not simulated",
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
