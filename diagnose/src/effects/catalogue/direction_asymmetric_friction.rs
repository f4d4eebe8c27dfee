//! `direction_asymmetric_friction`: the viscous coefficient differs with the direction of
//! motion (a Coulomb asymmetry is the offset, which the baseline carries).

use super::*;

pub struct DirectionAsymmetricFriction;
pub const DIRECTION_ASYMMETRIC_FRICTION: EffectKind = EffectKind(&DirectionAsymmetricFriction);

impl EffectModel for DirectionAsymmetricFriction {
    fn name(&self) -> &'static str {
        "direction_asymmetric_friction"
    }
    /// Column |v| (coefficient: half the difference of the two viscous coefficients).
    fn columns_on(&self, _ctx: &Context, s: &Sig, _e: &Effect) -> Vec<(String, Vec<f64>)> {
        vec![(
            format!("{}.abs_v", self.name()),
            map(s.len(), |i| s.v[i].abs()),
        )]
    }
    /// The viscous coefficient stays ≥ 0 in both directions.
    fn admissible(&self, _e: &Effect, coef: &[f64], base: &[f64]) -> bool {
        let fv = base.get(1).copied().unwrap_or(0.0);
        fv - coef[0].abs() >= 0.0
    }
    fn parameters(
        &self,
        _ctx: &Context,
        _e: &Effect,
        coef: &dyn Fn(&str) -> f64,
        base: &[f64],
    ) -> Vec<(String, f64)> {
        let (fv, fc, off) = (base[1], base[2], base[3]);
        vec![
            ("viscous_pos_Ns_per_m".into(), fv + coef("abs_v")),
            ("viscous_neg_Ns_per_m".into(), fv - coef("abs_v")),
            ("coulomb_pos_N".into(), fc + off),
            ("coulomb_neg_N".into(), fc - off),
        ]
    }
    fn describe(&self, _ctx: &Context, _e: &Effect) -> String {
        String::new()
    }
}
