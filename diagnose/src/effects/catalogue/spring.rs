//! `spring`: a force proportional to the displacement, k·(x − x_ref) (a mount, a centring
//! spring, a strut; the stiffness a passive friction damper shows beside its hysteresis). The
//! column is the displacement from the stroke's middle; the force at that position is the
//! baseline's offset, so the rest position is not told apart from a force offset.

use super::*;

pub struct Spring;
pub const SPRING: EffectKind = EffectKind(&Spring);

impl EffectModel for Spring {
    fn name(&self) -> &'static str {
        "spring"
    }
    /// Column x − x_mid (coefficient: the stiffness k, N/m).
    fn columns_on(&self, ctx: &Context, s: &Sig, _e: &Effect) -> Vec<(String, Vec<f64>)> {
        let x = s.x;
        vec![(
            format!("{}.x_from_mid", self.name()),
            map(s.len(), |i| x[i] - ctx.x_mid),
        )]
    }
    /// A passive spring: a positive stiffness.
    fn admissible(&self, _e: &Effect, coef: &[f64], _base: &[f64]) -> bool {
        coef[0] > 0.0
    }
    fn parameters(
        &self,
        ctx: &Context,
        _e: &Effect,
        coef: &dyn Fn(&str) -> f64,
        _base: &[f64],
    ) -> Vec<(String, f64)> {
        vec![
            ("stiffness_N_per_m".into(), coef("x_from_mid")),
            ("reference_position_m".into(), ctx.x_mid),
        ]
    }
    fn describe(&self, ctx: &Context, _e: &Effect) -> String {
        format!(
            "a force proportional to the displacement from {:.4e} m (the force there is in the offset)",
            ctx.x_mid
        )
    }
}
