//! `screw_efficiency`: the force scaled differently when the device is driven (f·v > 0) than
//! when it drives.

use super::*;

pub struct ScrewEfficiency;
pub const SCREW_EFFICIENCY: EffectKind = EffectKind(&ScrewEfficiency);

impl EffectModel for ScrewEfficiency {
    fn name(&self) -> &'static str {
        "screw_efficiency"
    }
    /// Column f̂₀ where f̂₀·v > 0 (the baseline prediction while driven), else 0.
    fn columns_on(&self, _ctx: &Context, s: &Sig, _e: &Effect) -> Vec<(String, Vec<f64>)> {
        let (v, bp) = (s.v, s.bp);
        vec![(
            format!("{}.driven_force", self.name()),
            map(s.len(), |i| if bp[i] * v[i] > 0.0 { bp[i] } else { 0.0 }),
        )]
    }
    /// The driven/driving force ratio lies in [0.5, 2] (an efficiency of 0.5 … 1, whichever
    /// way the power flows).
    fn admissible(&self, _e: &Effect, coef: &[f64], _base: &[f64]) -> bool {
        (-0.5..=1.0).contains(&coef[0])
    }
    fn parameters(
        &self,
        _ctx: &Context,
        _e: &Effect,
        coef: &dyn Fn(&str) -> f64,
        _base: &[f64],
    ) -> Vec<(String, f64)> {
        vec![(
            "driven_over_driving_force_ratio".into(),
            1.0 + coef("driven_force"),
        )]
    }
    fn describe(&self, _ctx: &Context, _e: &Effect) -> String {
        String::new()
    }
}
