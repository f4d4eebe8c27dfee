//! `compliance`: an unmodelled resonance, a mass hung on the device through a spring-damper
//! (parameter: the resonance frequency f_r, Hz; the damping ratio from the record,
//! `Context::compliance_zeta`). Its variant `COMPLIANCE_BEHIND`: the force measured in front
//! of the compliant part with the device (inertia, drive, friction) behind it, so that the
//! device's viscous force passes through the mode too.

use super::*;

pub struct Compliance;
pub const COMPLIANCE: EffectKind = EffectKind(&Compliance);

impl EffectModel for Compliance {
    fn name(&self) -> &'static str {
        "compliance"
    }
    fn scanned(&self) -> bool {
        true
    }
    /// Column (H − 1)·a, H the mode's transfer from the device's acceleration (coefficient: the
    /// modal mass m2).
    fn columns_on(&self, ctx: &Context, s: &Sig, e: &Effect) -> Vec<(String, Vec<f64>)> {
        compliance_batch(ctx, s, std::slice::from_ref(e))
            .pop()
            .unwrap_or_default()
    }
    fn columns_batch(
        &self,
        ctx: &Context,
        s: &Sig,
        effs: &[Effect],
    ) -> Vec<Vec<(String, Vec<f64>)>> {
        compliance_batch(ctx, s, effs)
    }
    fn walks_history(&self) -> bool {
        true
    }
    /// The device behind the compliance (`COMPLIANCE_BEHIND`) at the frequency found, ranked
    /// by the held-out rss as the frequency is.
    fn variants(&self, _ctx: &Context, centre: &Effect) -> Vec<Effect> {
        if behind(centre) {
            return Vec::new();
        }
        vec![Effect {
            param2: COMPLIANCE_BEHIND,
            ..centre.clone()
        }]
    }
    /// From 10 periods over the screening window to the motion bandwidth, and at most half the
    /// derivative filter's default cutoff (fs/20): above it the derived acceleration is
    /// attenuated by more than 6 % (forward-backward Butterworth-2: 1/(1 + (f/fc)⁴)), so a
    /// mode's force cannot be told from the filter's loss; and to a quarter of the derivative
    /// filter's cutoff when the record states it (24 values, log-spaced).
    fn grid(&self, ctx: &Context, cand: &Effect) -> Vec<Effect> {
        let t = ctx.dt * ctx.window as f64;
        let cap = ctx
            .rec
            .meta
            .get(crate::record::DERIVATIVE_CUTOFF_KEY)
            .map_or(f64::INFINITY, |fc| 0.25 * fc);
        let hi = ctx.f_motion.min(0.025 / ctx.dt).min(cap);
        let lo = 10.0 / t;
        if hi > 1.5 * lo {
            logspace(lo, hi, 24)
                .into_iter()
                .map(|p| Effect::new(cand.kind, p))
                .collect()
        } else {
            vec![]
        }
    }
    /// Each value costs a pass of the resonator over the record: 7 values per level.
    fn refine(&self, _ctx: &Context, e: &Effect, width: f64) -> Vec<Effect> {
        refine_coarse(e, width)
    }
    /// A resonance's residual is sharp in frequency: one more level.
    fn refine_widths(&self) -> &'static [f64] {
        &[0.15, 0.03, 0.006]
    }
    /// A positive modal mass (its damping ratio lies in [0.01, 1] by construction); behind
    /// it, a device of positive viscous friction.
    fn admissible(&self, e: &Effect, coef: &[f64], _base: &[f64]) -> bool {
        coef[0] > 0.0 && (!behind(e) || coef.get(1).is_some_and(|c| *c >= 0.0))
    }
    fn parameters(
        &self,
        ctx: &Context,
        e: &Effect,
        coef: &dyn Fn(&str) -> f64,
        _base: &[f64],
    ) -> Vec<(String, f64)> {
        let mut p = vec![
            ("resonance_Hz".into(), e.param),
            ("modal_mass_kg".into(), coef("mode_minus_rigid")),
            (
                "damping_ratio".into(),
                ctx.compliance_zeta(e.param).unwrap_or(f64::NAN),
            ),
        ];
        if behind(e) {
            p.push(("viscous_behind_Ns_per_m".into(), coef("viscous_through_mode")));
        }
        p
    }
    fn describe(&self, _ctx: &Context, e: &Effect) -> String {
        if behind(e) {
            format!(
                "resonance near {:.3} Hz, the device behind the compliant part (the force measured in front of it)",
                e.param
            )
        } else {
            format!("resonance near {:.3} Hz", e.param)
        }
    }
    fn fragment(
        &self,
        e: &Effect,
        _model: &[(String, f64)],
        _dt: f64,
    ) -> Result<Vec<(String, FragmentValue)>, &'static str> {
        if behind(e) {
            Err("a device behind its compliance, not simulated")
        } else {
            Ok(Vec::new())
        }
    }
    /// A mode whose column is more than half the derived acceleration's noise is not resolved;
    /// one resolved must carry the margin on fits corrected for that noise
    /// (`Context::compliance_noise`): the column's noise near the derivative cutoff is the
    /// inertia column's (H − 1 ≈ −1 there), so least squares credits a modal mass near the
    /// inertia with the noise it cancels.
    fn derived_noise(&self, ctx: &Context, e: &Effect) -> Option<(NoiseUse, [[f64; 3]; 3])> {
        ctx.compliance_noise(e.param)
            .map(|c| (NoiseUse::MarginCorrected, c))
    }
}

/// `compliance`'s second parameter for the device behind the compliant part (0: a mass hung
/// on the device).
pub const COMPLIANCE_BEHIND: f64 = 1.0;

/// True for the variant with the device behind the compliance.
fn behind(e: &Effect) -> bool {
    e.param2 == COMPLIANCE_BEHIND
}

/// `compliance` columns of several frequencies on the rows of `s`, the modes' filters in one
/// pass (a frequency whose profile identifies no mode has a zero column); a value with the
/// device behind the compliance adds (H − 1)·v, the device's viscous force through the mode
/// (coefficient: its viscous friction), from a second pass over the velocity.
pub(crate) fn compliance_batch(
    ctx: &Context,
    s: &Sig,
    effs: &[Effect],
) -> Vec<Vec<(String, Vec<f64>)>> {
    let fs: Vec<f64> = effs.iter().map(|e| e.param).collect();
    let zetas = ctx.compliance_zetas(&fs);
    let modes: Vec<(f64, f64)> = effs
        .iter()
        .zip(&zetas)
        .filter_map(|(e, z)| z.map(|z| (e.param, z)))
        .collect();
    let mut cols = compliance_columns_at(&ctx.rec.a, &modes, ctx.dt, s.rows).into_iter();
    let behind_modes: Vec<(f64, f64)> = effs
        .iter()
        .zip(&zetas)
        .filter(|(e, _)| behind(e))
        .filter_map(|(e, z)| z.map(|z| (e.param, z)))
        .collect();
    let mut vcols = if behind_modes.is_empty() {
        Vec::new()
    } else {
        compliance_columns_at(&ctx.rec.v, &behind_modes, ctx.dt, s.rows)
    }
    .into_iter();
    effs.iter()
        .zip(&zetas)
        .map(|(e, z)| {
            let (c, cv) = match z {
                Some(_) => (
                    cols.next().unwrap_or_default(),
                    behind(e).then(|| vcols.next().unwrap_or_default()),
                ),
                None => (vec![0.0; s.len()], behind(e).then(|| vec![0.0; s.len()])),
            };
            let mut out = vec![("compliance.mode_minus_rigid".to_string(), c)];
            if let Some(cv) = cv {
                out.push(("compliance.viscous_through_mode".to_string(), cv));
            }
            out
        })
        .collect()
}
