//! `compliance`: an unmodelled resonance, a mass hung on the device through a spring-damper
//! (parameter: the resonance frequency f_r, Hz; the damping ratio from the record,
//! `Context::compliance_zeta`).

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
    /// A positive modal mass (its damping ratio lies in [0.01, 1] by construction).
    fn admissible(&self, _e: &Effect, coef: &[f64], _base: &[f64]) -> bool {
        coef[0] > 0.0
    }
    fn parameters(
        &self,
        ctx: &Context,
        e: &Effect,
        coef: &dyn Fn(&str) -> f64,
        _base: &[f64],
    ) -> Vec<(String, f64)> {
        vec![
            ("resonance_Hz".into(), e.param),
            ("modal_mass_kg".into(), coef("mode_minus_rigid")),
            (
                "damping_ratio".into(),
                ctx.compliance_zeta(e.param).unwrap_or(f64::NAN),
            ),
        ]
    }
    fn describe(&self, _ctx: &Context, e: &Effect) -> String {
        format!("resonance near {:.3} Hz", e.param)
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

/// `compliance` columns of several frequencies on the rows of `s`, the modes' filters in one
/// pass (a frequency whose profile identifies no mode has a zero column).
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
    zetas
        .iter()
        .map(|z| {
            let c = match z {
                Some(_) => cols.next().unwrap_or_default(),
                None => vec![0.0; s.len()],
            };
            vec![("compliance.mode_minus_rigid".to_string(), c)]
        })
        .collect()
}
