//! `presliding_hysteresis`: rate-independent friction hysteresis at reversals (Dahl model: the
//! friction builds up over a characteristic displacement instead of switching with the sign of
//! v; parameter: that displacement x_c, m).

use super::*;

pub struct PreslidingHysteresis;
pub const PRESLIDING_HYSTERESIS: EffectKind = EffectKind(&PreslidingHysteresis);

impl EffectModel for PreslidingHysteresis {
    fn name(&self) -> &'static str {
        "presliding_hysteresis"
    }
    fn scanned(&self) -> bool {
        true
    }
    /// Dahl: dz/dx = (1 − z·sgn dx)/x_c, exact over each position step; the Coulomb force
    /// becomes Fc·z: column z − sgn v (coefficient Fc).
    fn columns_on(&self, ctx: &Context, s: &Sig, e: &Effect) -> Vec<(String, Vec<f64>)> {
        let z = match s.rows {
            None => dahl(&ctx.rec.x, e.param),
            Some(r) => dahl_at(&ctx.rec.x, e.param, r),
        };
        dahl_columns(&z, s.sgn)
    }
    fn columns_batch(
        &self,
        ctx: &Context,
        s: &Sig,
        effs: &[Effect],
    ) -> Vec<Vec<(String, Vec<f64>)>> {
        match s.rows {
            Some(r) => {
                let params: Vec<f64> = effs.iter().map(|e| e.param).collect();
                dahl_batch_at(&ctx.rec.x, &params, r)
                    .into_iter()
                    .map(|z| dahl_columns(&z, s.sgn))
                    .collect()
            }
            None => effs.iter().map(|e| self.columns_on(ctx, s, e)).collect(),
        }
    }
    fn walks_history(&self) -> bool {
        true
    }
    fn grid(&self, ctx: &Context, cand: &Effect) -> Vec<Effect> {
        displacement_grid(ctx, cand.kind)
    }
    fn refine(&self, _ctx: &Context, e: &Effect, width: f64) -> Vec<Effect> {
        refine_coarse(e, width)
    }
    /// The friction force it carries is positive and at most 1.5× the Coulomb level.
    fn admissible(&self, _e: &Effect, coef: &[f64], base: &[f64]) -> bool {
        let fc = base.get(2).copied().unwrap_or(0.0);
        coef[0] > 0.0 && coef[0] <= 1.5 * fc.max(0.0)
    }
    fn parameters(
        &self,
        _ctx: &Context,
        e: &Effect,
        coef: &dyn Fn(&str) -> f64,
        _base: &[f64],
    ) -> Vec<(String, f64)> {
        vec![
            ("characteristic_displacement_m".into(), e.param),
            ("friction_N".into(), coef("dahl_minus_sgn")),
        ]
    }
    fn describe(&self, _ctx: &Context, e: &Effect) -> String {
        format!(
            "friction builds up over {:.3e} m after reversals (Dahl)",
            e.param
        )
    }
}

/// `presliding_hysteresis` column `z − sgn v` (coefficient: the Coulomb force Fc·z carries).
pub(crate) fn dahl_columns(z: &[f64], sg: &[f64]) -> Vec<(String, Vec<f64>)> {
    let name = PreslidingHysteresis.name();
    vec![(
        format!("{name}.dahl_minus_sgn"),
        z.iter().zip(sg).map(|(z, s)| z - s).collect(),
    )]
}
