//! Each effect's regressor columns over the record, and whether a fit of them is physical.

use super::*;

/// Columns of several effects of one kind on the rows of `s` (an effect that walks the
/// record's history fills all its values in one pass, `EffectModel::columns_batch`).
pub fn columns_batch(ctx: &Context, s: &Sig, effs: &[Effect]) -> Vec<Vec<(String, Vec<f64>)>> {
    let Some(kind) = effs.first().map(|e| e.kind) else {
        return Vec::new();
    };
    if effs.iter().any(|e| e.kind != kind) {
        return effs.iter().map(|e| columns_on(ctx, s, e)).collect();
    }
    kind.columns_batch(ctx, s, effs)
}

/// Unit-coefficient shape of an effect for synthesis and fitting: the regressor columns at
/// every sample of the record.
pub fn effect_columns(ctx: &Context, e: &Effect) -> Vec<(String, Vec<f64>)> {
    columns_on(ctx, &Sig::full(ctx), e)
}

/// The regressor columns of an effect on the rows of `s`.
pub fn columns_on(ctx: &Context, s: &Sig, e: &Effect) -> Vec<(String, Vec<f64>)> {
    e.kind.columns_on(ctx, s, e)
}

/// Physical admissibility of an effect's fitted coefficients `coef` given the baseline
/// coefficients `base` (inertia, viscous, Coulomb, offset, ...) fitted with it: every
/// parameter finite and the effect's own range (`EffectModel::admissible`). A fit outside the
/// effect's physical range is not that effect and is not named.
pub fn plausible(e: &Effect, coef: &[f64], base: &[f64]) -> bool {
    if coef.iter().chain(base).any(|c| !c.is_finite()) {
        return false;
    }
    e.kind.admissible(e, coef, base)
}

/// The `backlash` impact carries the device's momentum: the sum of its pulse's coefficients
/// (momentum per unit relative velocity) lies between half the inertia `m` and twice it. An
/// impact transfers (1 + e)·M·v, e the restitution (0 plastic … 1 elastic), so 1 … 2·M; the
/// lower bound is halved for what the taps do not resolve (a pulse longer than
/// `IMPACT_TAPS`, the contact instant's interpolation; 0.89 … 1.08·M measured on the rig's
/// 60 Hz, ζ 0.5 contact). Presliding friction and a force with no play show no impact: the
/// fitted pulse is then near 0 and the play is not named.
pub fn impact_consistent(taps: &[f64], m: f64) -> bool {
    let p: f64 = taps.iter().sum();
    m > 0.0 && p >= 0.5 * m && p <= 2.0 * m
}

/// A clip level is consistent with the measured force when, on the samples it clips (baseline
/// prediction beyond ±L), the measured force does not exceed L: its 90th percentile of |f|
/// there stays below L plus 3× the baseline residual rms (noise and model error).
///
/// For the drive's damping force (`drive_clip`, coefficient c_d, level L = c_d·v_L) the clipped
/// component is measured as the force minus the rest of the model: f − (f̂₀ − Fv₀·v) −
/// (Fv − c_d)·v (the baseline's inertia, Coulomb and offset, and the viscous part that is not
/// the drive's, Fv₀ the baseline's viscous coefficient, Fv the one fitted with the clip), on the
/// samples faster than v_L.
#[allow(clippy::too_many_arguments)]
pub fn clip_consistent(
    ctx: &Context,
    e: &Effect,
    coef: &[f64],
    base: &[f64],
    bp: &[f64],
    v: &[f64],
    f: &[f64],
    resid_rms: f64,
) -> bool {
    if !drive_clip(e) {
        return clip_level_consistent(e.param, bp, f, resid_rms);
    }
    let (vl, cd) = (-e.param, coef.first().copied().unwrap_or(0.0));
    let fv0 = ctx.base_th.get(1).copied().unwrap_or(0.0);
    let fv = base.get(1).copied().unwrap_or(0.0);
    let drive: Vec<f64> = v.iter().map(|v| cd * v).collect();
    let meas: Vec<f64> = (0..f.len())
        .map(|i| f[i] - (bp[i] - fv0 * v[i]) - (fv - cd) * v[i])
        .collect();
    clip_level_consistent(cd * vl, &drive, &meas, resid_rms)
}

/// `clip_consistent` for a level `l` of a component predicted as `bp` and measured as `f`.
pub(crate) fn clip_level_consistent(l: f64, bp: &[f64], f: &[f64], resid_rms: f64) -> bool {
    let mut over: Vec<f64> = bp
        .iter()
        .zip(f)
        .filter(|(p, _)| p.abs() > l)
        .map(|(_, f)| f.abs())
        .collect();
    if over.is_empty() {
        return false;
    }
    let k = (over.len() * 9 / 10).min(over.len() - 1);
    let q = *over.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1;
    q <= l + 3.0 * resid_rms
}
