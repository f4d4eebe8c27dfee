//! `position_dependent_friction`: the Coulomb level varies slowly along the stroke (linear and
//! quadratic in position).

use super::*;

pub struct PositionDependentFriction;
pub const POSITION_DEPENDENT_FRICTION: EffectKind = EffectKind(&PositionDependentFriction);

impl EffectModel for PositionDependentFriction {
    fn name(&self) -> &'static str {
        "position_dependent_friction"
    }
    /// Columns x̃·sgn v and x̃²·sgn v, x̃ the position scaled to [−1, 1] over the stroke.
    fn columns_on(&self, _ctx: &Context, s: &Sig, _e: &Effect) -> Vec<(String, Vec<f64>)> {
        let name = self.name();
        let (xn, sg) = (s.xn, s.sgn);
        vec![
            (format!("{name}.x_sgn"), map(s.len(), |i| xn[i] * sg[i])),
            (
                format!("{name}.x2_sgn"),
                map(s.len(), |i| xn[i] * xn[i] * sg[i]),
            ),
        ]
    }
    /// The Coulomb level stays ≥ 0 over the whole stroke (Coulomb + s·x̃ + c·x̃² on
    /// x̃ ∈ [−1, 1]: ends and the vertex).
    fn admissible(&self, _e: &Effect, coef: &[f64], base: &[f64]) -> bool {
        let fc = base.get(2).copied().unwrap_or(0.0);
        let f = |x: f64| fc + coef[0] * x + coef[1] * x * x;
        let mut ok = f(-1.0) >= 0.0 && f(1.0) >= 0.0;
        if coef[1] != 0.0 {
            let xv = -coef[0] / (2.0 * coef[1]);
            if (-1.0..=1.0).contains(&xv) {
                ok &= f(xv) >= 0.0;
            }
        }
        ok
    }
    fn parameters(
        &self,
        ctx: &Context,
        _e: &Effect,
        coef: &dyn Fn(&str) -> f64,
        _base: &[f64],
    ) -> Vec<(String, f64)> {
        vec![
            ("coulomb_slope_N_per_m".into(), coef("x_sgn") / ctx.x_half),
            (
                "coulomb_curvature_N_per_m2".into(),
                coef("x2_sgn") / (ctx.x_half * ctx.x_half),
            ),
            ("x_mid_m".into(), ctx.x_mid),
        ]
    }
    fn describe(&self, _ctx: &Context, _e: &Effect) -> String {
        String::new()
    }
}
