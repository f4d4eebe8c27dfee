//! Each effect's regressor columns over the record, and whether a fit of them is physical.

use super::*;

/// Columns of several effects of one kind on the rows of `s` (the compliance filters of all
/// the values in one pass).
pub fn columns_batch(ctx: &Context, s: &Sig, effs: &[Effect]) -> Vec<Vec<(String, Vec<f64>)>> {
    let Some(kind) = effs.first().map(|e| e.kind) else {
        return Vec::new();
    };
    let params: Vec<f64> = effs.iter().map(|e| e.param).collect();
    if effs.iter().any(|e| e.kind != kind) {
        return effs.iter().map(|e| columns_on(ctx, s, e)).collect();
    }
    match (kind, s.rows) {
        (EffectKind::Compliance, _) => compliance_batch(ctx, s, effs),
        (EffectKind::PreslidingHysteresis, Some(r)) => dahl_batch_at(&ctx.rec.x, &params, r)
            .into_iter()
            .map(|z| dahl_columns(&z, s.sgn))
            .collect(),
        _ => effs.iter().map(|e| columns_on(ctx, s, e)).collect(),
    }
}

/// `presliding_hysteresis` column `z − sgn v` (coefficient: the Coulomb force Fc·z carries).
pub(crate) fn dahl_columns(z: &[f64], sg: &[f64]) -> Vec<(String, Vec<f64>)> {
    let name = EffectKind::PreslidingHysteresis.name();
    vec![(
        format!("{name}.dahl_minus_sgn"),
        z.iter().zip(sg).map(|(z, s)| z - s).collect(),
    )]
}

/// `compliance` columns of several frequencies on the rows of `s`, the modes' filters in one
/// pass (a frequency whose profile identifies no mode has a zero column).
pub(crate) fn compliance_batch(
    ctx: &Context,
    s: &Sig,
    effs: &[Effect],
) -> Vec<Vec<(String, Vec<f64>)>> {
    let fs: Vec<f64> = effs.iter().map(|e| e.param).collect();
    let zetas = ctx.compliance_zetas(&fs);
    let modes: Vec<(f64, f64)> = effs
        .iter()
        .zip(&zetas)
        .filter_map(|(e, z)| z.map(|z| (e.param, z)))
        .collect();
    let mut cols = compliance_columns_at(&ctx.rec.a, &modes, ctx.dt, s.rows).into_iter();
    zetas
        .iter()
        .map(|z| {
            let c = match z {
                Some(_) => cols.next().unwrap_or_default(),
                None => vec![0.0; s.len()],
            };
            vec![("compliance.mode_minus_rigid".to_string(), c)]
        })
        .collect()
}

/// Unit-coefficient shape of an effect for synthesis and fitting: the regressor columns at
/// every sample of the record.
pub fn effect_columns(ctx: &Context, e: &Effect) -> Vec<(String, Vec<f64>)> {
    columns_on(ctx, &Sig::full(ctx), e)
}

/// The regressor columns of an effect on the rows of `s`.
pub fn columns_on(ctx: &Context, s: &Sig, e: &Effect) -> Vec<(String, Vec<f64>)> {
    let n = s.len();
    let name = e.kind.name();
    let col = |suffix: &str, v: Vec<f64>| (format!("{name}.{suffix}"), v);
    let map = |g: &dyn Fn(usize) -> f64| (0..n).map(g).collect::<Vec<f64>>();
    let (x, v, a, sg, xn, bp) = (s.x, s.v, s.a, s.sgn, s.xn, s.bp);
    match e.kind {
        EffectKind::DirectionAsymmetricFriction => vec![col("abs_v", map(&|i| v[i].abs()))],
        EffectKind::PositionDependentFriction => vec![
            col("x_sgn", map(&|i| xn[i] * sg[i])),
            col("x2_sgn", map(&|i| xn[i] * xn[i] * sg[i])),
        ],
        EffectKind::PositionPeriodicFriction | EffectKind::Cogging => {
            let k = 2.0 * std::f64::consts::PI / e.param;
            let fr = e.kind == EffectKind::PositionPeriodicFriction;
            let mut sn_c = Vec::with_capacity(n);
            let mut cs_c = Vec::with_capacity(n);
            for i in 0..n {
                // `libm`'s port of fdlibm's `sincos`: with the release build's fat LTO it costs the
                // same as a hand-inlined fdlibm kernel (docs/diagnose.md, "Speed")
                let (sn, cs) = libm::sincos(k * x[i]);
                let g = if fr { sg[i] } else { 1.0 };
                sn_c.push(sn * g);
                cs_c.push(cs * g);
            }
            vec![col("sin", sn_c), col("cos", cs_c)]
        }
        EffectKind::Stribeck => {
            let iv = 1.0 / e.param;
            vec![col(
                "sgn_exp",
                map(&|i| sg[i] * (-(v[i] * iv).powi(2)).exp()),
            )]
        }
        EffectKind::VelocityStrengthening => {
            // the Coulomb level builds up over v_b: (1 − exp(−|v|/v_b))·sgn v, coefficient ΔF
            // (the baseline's Coulomb coefficient is then the level at low speed)
            let iv = 1.0 / e.param;
            vec![col(
                "sgn_buildup",
                map(&|i| sg[i] * (1.0 - (-(v[i].abs() * iv)).exp())),
            )]
        }
        EffectKind::ScrewEfficiency => vec![col(
            "driven_force",
            map(&|i| if bp[i] * v[i] > 0.0 { bp[i] } else { 0.0 }),
        )],
        EffectKind::ReflectedInertia => vec![col(
            "driven_accel",
            map(&|i| if bp[i] * v[i] > 0.0 { a[i] } else { 0.0 }),
        )],
        EffectKind::ActuatorLag => {
            // τ_c·df̂₀/dt (central differences of the full-record baseline prediction), so
            // the coefficient is ω_c·τ
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
                None => map(&|i| d(i)),
                Some(r) => map(&|j| d(r[j])),
            };
            vec![col("rate_times_tc", z)]
        }
        EffectKind::Lag => {
            // the whole force delayed by τ: the device's force at t − τ (its coefficients
            // fitted on the motion delayed, `lag_coefs`) minus that force at t; with the
            // baseline fitted jointly, a gain of 1 makes the model the delayed device force
            let z = match ctx.lag_coefs(e.param) {
                None => vec![0.0; n],
                Some(th) => {
                    let k = e.param / ctx.dt;
                    let (ra, rv, rs) = (&ctx.rec.a, &ctx.rec.v, &ctx.sgn);
                    let at = |j: usize| s.rows.map_or(j, |r| r[j]);
                    map(&|j| {
                        let i = at(j);
                        th[0] * (delayed(ra, i, k) - ra[i])
                            + th[1] * (delayed(rv, i, k) - rv[i])
                            + th[2] * delayed_switch(rv, rs, i, k)
                    })
                }
            };
            vec![col("delayed_minus_now", z)]
        }
        EffectKind::CurrentLimit if e.param < 0.0 => {
            // the drive's damping force c_d·v clipped at ±c_d·v_L: c_d·(clip(v, ±v_L) − v),
            // coefficient c_d (N·s/m, part of the viscous term)
            let vl = -e.param;
            vec![col(
                "drive_clip_minus_free",
                map(&|i| v[i].clamp(-vl, vl) - v[i]),
            )]
        }
        EffectKind::CurrentLimit => {
            let l = e.param;
            vec![col("clip_minus_free", map(&|i| bp[i].clamp(-l, l) - bp[i]))]
        }
        EffectKind::Backlash => play_columns(ctx, s.rows, e.param, e.param2),
        EffectKind::PreslidingHysteresis => {
            // Dahl: dz/dx = (1 − z·sgn dx)/x_c, exact over each position step; the Coulomb
            // force becomes Fc·z: column z − sgn v (coefficient Fc)
            let z = match s.rows {
                None => dahl(&ctx.rec.x, e.param),
                Some(r) => dahl_at(&ctx.rec.x, e.param, r),
            };
            dahl_columns(&z, sg)
        }
        EffectKind::Compliance => {
            // A modal mass m2 hung on the device through a spring-damper (resonance f_r,
            // damping ratio ζ from `compliance_zeta`): column (H − 1)·a, coefficient m2
            columns_batch(ctx, s, std::slice::from_ref(e))
                .pop()
                .unwrap_or_default()
        }
    }
}

/// Physical admissibility of an effect's fitted coefficients `coef` given the baseline
/// coefficients `base` (inertia, viscous, Coulomb, offset, ...) fitted with it. A fit outside
/// the effect's physical range is not that effect and is not named:
/// * `direction_asymmetric_friction`: the viscous coefficient stays ≥ 0 in both directions;
/// * `position_dependent_friction`: the Coulomb level stays ≥ 0 over the whole stroke;
/// * `position_periodic_friction`: the ripple amplitude is at most the Coulomb level;
/// * `stribeck`: the bump is positive (static friction above Coulomb);
/// * `screw_efficiency`: the driven/driving force ratio lies in [0.5, 2] (an efficiency of 0.5
///   … 1, whichever way the power flows);
/// * `reflected_inertia`: the extra inertia is positive and at most the baseline inertia;
/// * `lag`: a delay of the force of unit gain (0.8 … 1.25: the whole force delayed);
/// * `current_limit` of the whole force: the clip has unit gain (0.8 … 1.25); of the drive's
///   damping force: the drive's damping c_d lies between half the fitted viscous coefficient
///   (a drive emulating a damper carries most of the damping) and all of it — the level
///   itself is checked against the measured force by the selection (`clip_consistent`);
/// * `compliance`: a positive modal mass (its damping ratio lies in [0.01, 1] by
///   construction, `compliance_zeta`);
/// * `presliding_hysteresis`: the friction force it carries is positive and at most 1.5× the
///   Coulomb level;
/// * `backlash`: unit gain of the force that stops across the gap (0.8 … 1.25: the device's
///   own force) and an impact of the device's momentum (`impact_consistent`);
/// * `actuator_lag`: 0 < ω_c·τ ≤ 1 (a delay of the force behind its command: the recorded
///   force leads; a recorded force that lags the motion is `lag`'s, and beyond ω_c·τ = 1 the
///   first-order column no longer is the delay, `actuator_tc`).
///
/// Every parameter must also be finite.
pub fn plausible(e: &Effect, coef: &[f64], base: &[f64]) -> bool {
    let kind = e.kind;
    if coef.iter().chain(base).any(|c| !c.is_finite()) {
        return false;
    }
    if drive_clip(e) {
        // the drive's damping is part of the fitted viscous term (c_d ≤ Fv), and a drive that
        // acts as a damper is the damper: it carries at least half of the viscous force (a
        // viscous term that saturates in a smaller part is friction, not a drive)
        let fv = base.get(1).copied().unwrap_or(0.0);
        return coef[0] >= 0.5 * fv && coef[0] <= fv && coef[0] > 0.0;
    }
    let unit = |g: f64| (0.8..=1.25).contains(&g);
    let fv = base.get(1).copied().unwrap_or(0.0);
    let fc = base.get(2).copied().unwrap_or(0.0);
    let m = base.first().copied().unwrap_or(0.0);
    match kind {
        EffectKind::DirectionAsymmetricFriction => fv - coef[0].abs() >= 0.0,
        EffectKind::PositionDependentFriction => {
            // Coulomb + s·x̃ + c·x̃² on x̃ ∈ [−1, 1]: ends and the vertex
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
        EffectKind::PositionPeriodicFriction => coef[0].hypot(coef[1]) <= fc,
        EffectKind::Cogging => true,
        EffectKind::Stribeck => coef[0] > 0.0,
        EffectKind::VelocityStrengthening => coef[0] > 0.0 && fc >= 0.0,
        EffectKind::ScrewEfficiency => (-0.5..=1.0).contains(&coef[0]),
        EffectKind::ReflectedInertia => coef[0] > 0.0 && coef[0] <= m,
        EffectKind::Lag | EffectKind::CurrentLimit => unit(coef[0]),
        EffectKind::Backlash => {
            e.param2.is_finite()
                && e.param2 < 1.0
                && unit(coef[0])
                && impact_consistent(&coef[1..], m)
        }
        EffectKind::Compliance => coef[0] > 0.0,
        EffectKind::PreslidingHysteresis => coef[0] > 0.0 && coef[0] <= 1.5 * fc.max(0.0),
        EffectKind::ActuatorLag => coef[0] > 0.0 && coef[0] <= 1.0,
    }
}

/// The time constant τ_c = 1/ω_c of the derivative filter's cutoff (the record's
/// `derivative_cutoff_hz`, else the default fs/20) that scales the `actuator_lag` column: its
/// coefficient ω_c·τ is at most 1, where the first-order expansion f(t + τ) ≈ f + τ·ḟ holds
/// over the band the derived signals carry (its error (ωτ)²/2 stays below half the term).
pub fn actuator_tc(ctx: &Context) -> f64 {
    let fc = ctx
        .rec
        .meta
        .get(crate::record::DERIVATIVE_CUTOFF_KEY)
        .copied()
        .unwrap_or(0.05 / ctx.dt);
    1.0 / (2.0 * std::f64::consts::PI * fc)
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
