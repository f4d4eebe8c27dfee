//! `lag`: the measured force delayed from the motion (parameter: the delay τ, s): the device's
//! force at t − τ, its coefficients fitted on the motion delayed (`Context::lag_coefs`).

use super::*;

pub struct Lag;
pub const LAG: EffectKind = EffectKind(&Lag);

impl EffectModel for Lag {
    fn name(&self) -> &'static str {
        "lag"
    }
    fn scanned(&self) -> bool {
        true
    }
    /// The whole force delayed by τ: the device's force at t − τ minus that force at t; with
    /// the baseline fitted jointly, a gain of 1 makes the model the delayed device force.
    fn columns_on(&self, ctx: &Context, s: &Sig, e: &Effect) -> Vec<(String, Vec<f64>)> {
        let n = s.len();
        let z = match ctx.lag_coefs(e.param) {
            None => vec![0.0; n],
            Some(th) => {
                let k = e.param / ctx.dt;
                let (ra, rv, rs) = (&ctx.rec.a, &ctx.rec.v, &ctx.sgn);
                let at = |j: usize| s.rows.map_or(j, |r| r[j]);
                map(n, |j| {
                    let i = at(j);
                    th[0] * (delayed(ra, i, k) - ra[i])
                        + th[1] * (delayed(rv, i, k) - rv[i])
                        + th[2] * delayed_switch(rv, rs, i, k)
                })
            }
        };
        vec![(format!("{}.delayed_minus_now", self.name()), z)]
    }
    /// One sample to `lag_max` (64 samples, at least 64 ms: a skew beyond is not an
    /// acquisition's), values 15 % apart (`lag_grid_len`): the ±15 % refinement reaches the neighbours, so the optimum is found whatever
    /// coarse value is nearest (a delay and its gain trade against each other on a narrowband
    /// motion, a coarser grid's nearest value took the gain out of its range).
    fn grid(&self, ctx: &Context, cand: &Effect) -> Vec<Effect> {
        logspace(ctx.dt, lag_max(ctx.dt), lag_grid_len(ctx.dt))
            .into_iter()
            .map(|p| Effect::new(cand.kind, p))
            .collect()
    }
    /// A delay between samples (the delayed columns interpolated): an acquisition skew is not
    /// a whole number of samples.
    fn refine(&self, _ctx: &Context, e: &Effect, width: f64) -> Vec<Effect> {
        refine_fine(e, width)
    }
    /// A delay of the force of unit gain (0.8 … 1.25: the whole force delayed).
    fn admissible(&self, _e: &Effect, coef: &[f64], _base: &[f64]) -> bool {
        unit_gain(coef[0])
    }
    fn parameters(
        &self,
        _ctx: &Context,
        e: &Effect,
        coef: &dyn Fn(&str) -> f64,
        _base: &[f64],
    ) -> Vec<(String, f64)> {
        vec![
            ("lag_s".into(), e.param),
            ("gain".into(), coef("delayed_minus_now")),
        ]
    }
    fn describe(&self, _ctx: &Context, e: &Effect) -> String {
        format!("force lags motion by {:.4} s", e.param)
    }
    fn force_delay(&self, e: &Effect) -> Option<f64> {
        Some(e.param)
    }
    /// Its gain's range and its τ are judged on the fit corrected for the derived signals'
    /// noise (`Context::lag_noise`).
    fn derived_noise(&self, ctx: &Context, e: &Effect) -> Option<(NoiseUse, [[f64; 3]; 3])> {
        ctx.lag_noise(e.param).map(|c| (NoiseUse::RankCorrected, c))
    }
}
