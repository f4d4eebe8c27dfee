//! `reflected_inertia`: extra inertia that acts only while the device is driven (reflected
//! rotor inertia seen through an efficiency < 1).

use super::*;

pub struct ReflectedInertia;
pub const REFLECTED_INERTIA: EffectKind = EffectKind(&ReflectedInertia);

impl EffectModel for ReflectedInertia {
    fn name(&self) -> &'static str {
        "reflected_inertia"
    }
    /// Column a where f̂₀·v > 0 (driven), else 0.
    fn columns_on(&self, _ctx: &Context, s: &Sig, _e: &Effect) -> Vec<(String, Vec<f64>)> {
        let (v, a, bp) = (s.v, s.a, s.bp);
        vec![(
            format!("{}.driven_accel", self.name()),
            map(s.len(), |i| if bp[i] * v[i] > 0.0 { a[i] } else { 0.0 }),
        )]
    }
    /// The extra inertia is positive and at most the baseline inertia.
    fn admissible(&self, _e: &Effect, coef: &[f64], base: &[f64]) -> bool {
        let m = base.first().copied().unwrap_or(0.0);
        coef[0] > 0.0 && coef[0] <= m
    }
    fn parameters(
        &self,
        _ctx: &Context,
        _e: &Effect,
        coef: &dyn Fn(&str) -> f64,
        _base: &[f64],
    ) -> Vec<(String, f64)> {
        vec![("extra_driven_inertia_kg".into(), coef("driven_accel"))]
    }
    fn describe(&self, _ctx: &Context, _e: &Effect) -> String {
        String::new()
    }
}
