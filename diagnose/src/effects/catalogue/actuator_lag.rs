//! `actuator_lag`: the force channel is the drive's command (a controller's output × gain),
//! which the force follows through the actuator's delay τ (the output's zero-order hold, half a
//! sample on average, and the current loop): the recorded force leads the force the motion
//! needs, f_cmd(t) = f(t + τ) ≈ f + τ·ḟ (coefficient: τ, as ω_c·τ, ω_c = 2π × the derivative
//! filter's cutoff, `actuator_tc`).

use super::*;

pub struct ActuatorLag;
pub const ACTUATOR_LAG: EffectKind = EffectKind(&ActuatorLag);

impl EffectModel for ActuatorLag {
    fn name(&self) -> &'static str {
        "actuator_lag"
    }
    /// Column τ_c·df̂₀/dt (central differences of the full-record baseline prediction), so
    /// the coefficient is ω_c·τ.
    fn columns_on(&self, ctx: &Context, s: &Sig, _e: &Effect) -> Vec<(String, Vec<f64>)> {
        let full = &ctx.base_pred;
        let last = full.len().saturating_sub(1);
        let k = actuator_tc(ctx) / ctx.dt;
        let d = |i: usize| {
            let (lo, hi) = (i.saturating_sub(1), (i + 1).min(last));
            if hi > lo {
                k * (full[hi] - full[lo]) / (hi - lo) as f64
            } else {
                0.0
            }
        };
        let z = match s.rows {
            None => map(s.len(), d),
            Some(r) => map(s.len(), |j| d(r[j])),
        };
        vec![(format!("{}.rate_times_tc", self.name()), z)]
    }
    /// 0 < ω_c·τ ≤ 1: a delay of the force behind its command (the recorded force leads; a
    /// recorded force that lags the motion is `lag`'s, and beyond ω_c·τ = 1 the first-order
    /// column no longer is the delay).
    fn admissible(&self, _e: &Effect, coef: &[f64], _base: &[f64]) -> bool {
        coef[0] > 0.0 && coef[0] <= 1.0
    }
    fn parameters(
        &self,
        ctx: &Context,
        _e: &Effect,
        coef: &dyn Fn(&str) -> f64,
        _base: &[f64],
    ) -> Vec<(String, f64)> {
        vec![("delay_s".into(), coef("rate_times_tc") * actuator_tc(ctx))]
    }
    fn describe(&self, _ctx: &Context, _e: &Effect) -> String {
        "the force channel leads the force: a drive's command, followed through the actuator's delay".into()
    }
    /// Carried by the samples where the baseline's prediction, the column's source, lies inside
    /// the derived signals' band (`prediction_in_band`), with one amplitude there and
    /// outside it: outside, the derived acceleration loses the inertial force and a column
    /// built from the prediction fits that loss.
    fn in_band(&self, ctx: &Context, _e: &Effect) -> Option<(Vec<bool>, InBandWords)> {
        prediction_in_band(ctx).map(|m| {
            (
                m,
                InBandWords {
                    not: "a force channel leading the force",
                    band: "where the baseline's prediction changes slowly enough for the derived signals (|df̂₀/dt| ≤ π·fc·max|f̂₀|)",
                    outside: "at the turns and reversals the motion passes faster",
                },
            )
        })
    }
    /// The recording's force channel, not the device: the plant carries the force the motion
    /// needs.
    fn fragment(
        &self,
        _e: &Effect,
        _model: &[(String, f64)],
        _dt: f64,
    ) -> Result<Vec<(String, FragmentValue)>, &'static str> {
        Err("the record's force channel leads the device's force, not simulated")
    }
}

/// The time constant τ_c = 1/ω_c of the derivative filter's cutoff (the record's
/// `derivative_cutoff_hz`, else the default, `record::default_cutoff`) that scales the `actuator_lag` column: its
/// coefficient ω_c·τ is at most 1, where the first-order expansion f(t + τ) ≈ f + τ·ḟ holds
/// over the band the derived signals carry (its error (ωτ)²/2 stays below half the term).
pub fn actuator_tc(ctx: &Context) -> f64 {
    1.0 / (2.0 * std::f64::consts::PI * ctx.derivative_cutoff())
}
