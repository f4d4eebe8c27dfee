//! `cogging`: a force periodic in position, independent of the direction of motion (parameter:
//! the wavelength, m).

use super::*;

pub struct Cogging;
pub const COGGING: EffectKind = EffectKind(&Cogging);

impl EffectModel for Cogging {
    fn name(&self) -> &'static str {
        "cogging"
    }
    fn scanned(&self) -> bool {
        true
    }
    fn columns_on(&self, _ctx: &Context, s: &Sig, e: &Effect) -> Vec<(String, Vec<f64>)> {
        periodic::columns(self.name(), s, e.param, false)
    }
    fn grid(&self, ctx: &Context, cand: &Effect) -> Vec<Effect> {
        periodic::grid(ctx, cand.kind)
    }
    fn refine(&self, _ctx: &Context, e: &Effect, width: f64) -> Vec<Effect> {
        refine_fine(e, width)
    }
    /// Any amplitude.
    fn admissible(&self, _e: &Effect, _coef: &[f64], _base: &[f64]) -> bool {
        true
    }
    fn parameters(
        &self,
        _ctx: &Context,
        e: &Effect,
        coef: &dyn Fn(&str) -> f64,
        _base: &[f64],
    ) -> Vec<(String, f64)> {
        periodic::parameters(e, coef)
    }
    fn describe(&self, ctx: &Context, e: &Effect) -> String {
        periodic::describe(ctx, e)
    }
    fn spatial_wavelength(&self, e: &Effect) -> Option<f64> {
        Some(e.param)
    }
    fn in_band(&self, ctx: &Context, e: &Effect) -> Option<(Vec<bool>, InBandWords)> {
        periodic::in_band(ctx, e)
    }
    fn apart_from_hum(&self) -> bool {
        true
    }
}
