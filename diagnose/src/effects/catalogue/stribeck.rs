//! `stribeck`: extra friction at low speed decaying as exp(−(v/v_s)²) (parameter: v_s, m/s).

use super::*;

pub struct Stribeck;
pub const STRIBECK: EffectKind = EffectKind(&Stribeck);

impl EffectModel for Stribeck {
    fn name(&self) -> &'static str {
        "stribeck"
    }
    fn scanned(&self) -> bool {
        true
    }
    /// Column sgn v·exp(−(v/v_s)²) (coefficient: the bump's amplitude, N).
    fn columns_on(&self, _ctx: &Context, s: &Sig, e: &Effect) -> Vec<(String, Vec<f64>)> {
        let iv = 1.0 / e.param;
        let (v, sg) = (s.v, s.sgn);
        vec![(
            format!("{}.sgn_exp", self.name()),
            map(s.len(), |i| sg[i] * (-(v[i] * iv).powi(2)).exp()),
        )]
    }
    fn grid(&self, ctx: &Context, cand: &Effect) -> Vec<Effect> {
        speed_grid(ctx, cand.kind)
    }
    fn refine(&self, _ctx: &Context, e: &Effect, width: f64) -> Vec<Effect> {
        refine_fine(e, width)
    }
    /// The bump is positive (static friction above Coulomb) and the Coulomb level it stands on
    /// (the baseline's, fitted beside it) is not negative: a bump above a negative sliding
    /// friction is a friction curve rising with speed, not Stribeck's.
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
            ("stribeck_velocity_m_s".into(), e.param),
            ("amplitude_N".into(), coef("sgn_exp")),
        ]
    }
    fn describe(&self, _ctx: &Context, e: &Effect) -> String {
        format!("Stribeck velocity {:.3e} m/s", e.param)
    }
    fn apart_from_hum(&self) -> bool {
        true
    }
}
