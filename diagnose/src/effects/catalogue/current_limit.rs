//! `current_limit`: the force clipped at a level. Two hypotheses on which force the drive
//! produces, both scanned, the data choosing: the whole force (a motor-driven axis; parameter
//! the level L > 0, N) or the drive's damping force c_d·v on an imposed motion (parameter
//! −v_L < 0, the speed above which it saturates, m/s; L = c_d·v_L; `drive_clip`).

use super::*;

pub struct CurrentLimit;
pub const CURRENT_LIMIT: EffectKind = EffectKind(&CurrentLimit);

impl EffectModel for CurrentLimit {
    fn name(&self) -> &'static str {
        "current_limit"
    }
    fn scanned(&self) -> bool {
        true
    }
    fn columns_on(&self, _ctx: &Context, s: &Sig, e: &Effect) -> Vec<(String, Vec<f64>)> {
        let name = self.name();
        let (v, bp) = (s.v, s.bp);
        if e.param < 0.0 {
            // the drive's damping force c_d·v clipped at ±c_d·v_L: c_d·(clip(v, ±v_L) − v),
            // coefficient c_d (N·s/m, part of the viscous term)
            let vl = -e.param;
            vec![(
                format!("{name}.drive_clip_minus_free"),
                map(s.len(), |i| v[i].clamp(-vl, vl) - v[i]),
            )]
        } else {
            let l = e.param;
            vec![(
                format!("{name}.clip_minus_free"),
                map(s.len(), |i| bp[i].clamp(-l, l) - bp[i]),
            )]
        }
    }
    /// The levels of |f̂₀| (`Context::clip_levels`) and the negated saturation speeds
    /// (`Context::speed_levels`).
    fn grid(&self, ctx: &Context, cand: &Effect) -> Vec<Effect> {
        ctx.clip_levels
            .iter()
            .map(|&l| Effect::new(cand.kind, l))
            .chain(ctx.speed_levels.iter().map(|&v| Effect::new(cand.kind, -v)))
            .collect()
    }
    fn refine(&self, _ctx: &Context, e: &Effect, width: f64) -> Vec<Effect> {
        refine_fine(e, width)
    }
    /// Of the whole force: the clip has unit gain (0.8 … 1.25). Of the drive's damping force:
    /// c_d lies between half the fitted viscous coefficient (a drive emulating a damper
    /// carries most of the damping) and all of it. The level itself is checked against the
    /// measured force (`consistent_with_force`).
    fn admissible(&self, e: &Effect, coef: &[f64], base: &[f64]) -> bool {
        if drive_clip(e) {
            let fv = base.get(1).copied().unwrap_or(0.0);
            return coef[0] >= 0.5 * fv && coef[0] <= fv && coef[0] > 0.0;
        }
        unit_gain(coef[0])
    }
    fn consistent_with_force(
        &self,
        ctx: &Context,
        e: &Effect,
        coef: &[f64],
        base: &[f64],
        bp: &[f64],
        v: &[f64],
        f: &[f64],
        resid_rms: f64,
    ) -> bool {
        clip_consistent(ctx, e, coef, base, bp, v, f, resid_rms)
    }
    fn parameters(
        &self,
        _ctx: &Context,
        e: &Effect,
        coef: &dyn Fn(&str) -> f64,
        _base: &[f64],
    ) -> Vec<(String, f64)> {
        if e.param < 0.0 {
            let cd = coef("drive_clip_minus_free");
            vec![
                ("limit_N".into(), -e.param * cd),
                ("drive_damping_Ns_per_m".into(), cd),
            ]
        } else {
            vec![
                ("limit_N".into(), e.param),
                ("gain".into(), coef("clip_minus_free")),
            ]
        }
    }
    fn describe(&self, _ctx: &Context, e: &Effect) -> String {
        if e.param < 0.0 {
            format!(
                "the drive's damping force clipped above {:.3e} m/s (a drive acting as a load)",
                -e.param
            )
        } else {
            format!("force clipped near {:.1} N", e.param)
        }
    }
}

/// True when `e` is the `current_limit` of a drive acting as a damper (its force c_d·v
/// clipped) rather than of the whole force.
pub fn drive_clip(e: &Effect) -> bool {
    e.kind == CURRENT_LIMIT && e.param < 0.0
}
