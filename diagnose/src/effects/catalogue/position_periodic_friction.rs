//! `position_periodic_friction`: the Coulomb level modulated periodically in position (parameter:
//! the wavelength, m).

use super::*;

pub struct PositionPeriodicFriction;
pub const POSITION_PERIODIC_FRICTION: EffectKind = EffectKind(&PositionPeriodicFriction);

impl EffectModel for PositionPeriodicFriction {
    fn name(&self) -> &'static str {
        "position_periodic_friction"
    }
    fn scanned(&self) -> bool {
        true
    }
    fn columns_on(&self, _ctx: &Context, s: &Sig, e: &Effect) -> Vec<(String, Vec<f64>)> {
        periodic::columns(self.name(), s, e.param, true)
    }
    fn grid(&self, ctx: &Context, cand: &Effect) -> Vec<Effect> {
        periodic::grid(ctx, cand.kind)
    }
    fn refine(&self, _ctx: &Context, e: &Effect, width: f64) -> Vec<Effect> {
        refine_fine(e, width)
    }
    /// The ripple's amplitude is at most the Coulomb level.
    fn admissible(&self, _e: &Effect, coef: &[f64], base: &[f64]) -> bool {
        coef[0].hypot(coef[1]) <= base.get(2).copied().unwrap_or(0.0)
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
