//! `velocity_strengthening_friction`: friction that builds up with speed (a ballscrew's rolling
//! and lubricant-film drag grow with speed at low speed): the Coulomb level rises by ΔF > 0 over
//! a characteristic speed v_b, `ΔF·(1 − exp(−|v|/v_b))·sgn v` (parameter: v_b, m/s). The
//! opposite of `stribeck`, whose static friction lies above the Coulomb level.

use super::*;

pub struct VelocityStrengthening;
pub const VELOCITY_STRENGTHENING: EffectKind = EffectKind(&VelocityStrengthening);

impl EffectModel for VelocityStrengthening {
    fn name(&self) -> &'static str {
        "velocity_strengthening_friction"
    }
    fn scanned(&self) -> bool {
        true
    }
    /// Column (1 − exp(−|v|/v_b))·sgn v, coefficient ΔF (the baseline's Coulomb coefficient
    /// is then the level at low speed).
    fn columns_on(&self, _ctx: &Context, s: &Sig, e: &Effect) -> Vec<(String, Vec<f64>)> {
        let iv = 1.0 / e.param;
        let (v, sg) = (s.v, s.sgn);
        vec![(
            format!("{}.sgn_buildup", self.name()),
            map(s.len(), |i| sg[i] * (1.0 - (-(v[i].abs() * iv)).exp())),
        )]
    }
    fn grid(&self, ctx: &Context, cand: &Effect) -> Vec<Effect> {
        speed_grid(ctx, cand.kind)
    }
    fn refine(&self, _ctx: &Context, e: &Effect, width: f64) -> Vec<Effect> {
        refine_fine(e, width)
    }
    /// A rise (ΔF > 0) above a Coulomb level ≥ 0.
    fn admissible(&self, _e: &Effect, coef: &[f64], base: &[f64]) -> bool {
        coef[0] > 0.0 && base.get(2).copied().unwrap_or(0.0) >= 0.0
    }
    fn parameters(
        &self,
        _ctx: &Context,
        e: &Effect,
        coef: &dyn Fn(&str) -> f64,
        _base: &[f64],
    ) -> Vec<(String, f64)> {
        vec![
            ("buildup_velocity_m_s".into(), e.param),
            ("friction_rise_N".into(), coef("sgn_buildup")),
        ]
    }
    fn describe(&self, _ctx: &Context, e: &Effect) -> String {
        format!(
            "the Coulomb level builds up with speed over {:.3e} m/s",
            e.param
        )
    }
    /// Carried by the samples where its column changes within the band the derived signals
    /// follow (`buildup_in_band`), with one rise there and at the stops the motion passes
    /// faster.
    fn in_band(&self, ctx: &Context, e: &Effect) -> Option<(Vec<bool>, InBandWords)> {
        buildup_in_band(ctx, e.param).map(|m| {
            (
                m,
                InBandWords {
                    not: "a friction of the speed",
                    band: "where its build-up is slow enough for the derived signals (e^(−|v|/v_b)·|a|/v_b ≤ π·fc)",
                    outside: "at the stops the motion passes faster",
                },
            )
        })
    }
}
