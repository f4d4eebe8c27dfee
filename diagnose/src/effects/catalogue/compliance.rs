//! `compliance`: an unmodelled resonance, a mass hung on the device through a spring-damper
//! (parameter: the resonance frequency f_r, Hz; the damping ratio from the record,
//! `Context::compliance_zeta`). Its variant `COMPLIANCE_BEHIND`: the force measured in front
//! of the compliant part with the device (inertia, drive, friction) behind it, so that the
//! device's whole force passes through the mode and its own viscous force damps it
//! (`behind_mode`).

use super::*;

pub struct Compliance;
pub const COMPLIANCE: EffectKind = EffectKind(&Compliance);

impl EffectModel for Compliance {
    fn name(&self) -> &'static str {
        "compliance"
    }
    fn scanned(&self) -> bool {
        true
    }
    /// Column (H − 1)·a, H the mode's transfer from the device's acceleration (coefficient: the
    /// modal mass m2).
    fn columns_on(&self, ctx: &Context, s: &Sig, e: &Effect) -> Vec<(String, Vec<f64>)> {
        compliance_batch(ctx, s, std::slice::from_ref(e))
            .pop()
            .unwrap_or_default()
    }
    fn columns_batch(
        &self,
        ctx: &Context,
        s: &Sig,
        effs: &[Effect],
    ) -> Vec<Vec<(String, Vec<f64>)>> {
        compliance_batch(ctx, s, effs)
    }
    fn walks_history(&self) -> bool {
        true
    }
    /// With the device behind the compliance, the link's other damping ratios (`BEHIND_ZETAS`)
    /// at the frequency found.
    fn variants(&self, _ctx: &Context, centre: &Effect) -> Vec<Effect> {
        if !behind(centre) {
            return Vec::new();
        }
        BEHIND_ZETAS
            .iter()
            .map(|z| COMPLIANCE_BEHIND + z)
            .filter(|&p2| p2 != centre.param2)
            .map(|param2| Effect {
                param2,
                ..centre.clone()
            })
            .collect()
    }
    /// With the device behind the compliance, the link's damping ratio bisected in ln ζ_l
    /// around the one chosen: at level L the ratios ×/÷ r^(1/2^(L+1)), r the mean ratio of
    /// neighbouring `BEHIND_ZETAS`, for `BEHIND_ZETA_LEVELS` levels (within the grid's range).
    fn variant_fine(&self, centre: &Effect, level: usize) -> Vec<Effect> {
        if !behind(centre) || level >= BEHIND_ZETA_LEVELS {
            return Vec::new();
        }
        let (lo, hi) = (BEHIND_ZETAS[0], BEHIND_ZETAS[BEHIND_ZETAS.len() - 1]);
        let r = (hi / lo).powf(1.0 / (BEHIND_ZETAS.len() - 1) as f64);
        let q = r.powf(0.5f64.powi(level as i32 + 1));
        let zl = behind_zeta(centre);
        [zl / q, zl * q]
            .into_iter()
            .filter(|z| (lo..=hi).contains(z))
            .map(|z| Effect {
                param2: COMPLIANCE_BEHIND + z,
                ..centre.clone()
            })
            .collect()
    }
    /// The frequency refined once more at the damping ratio chosen.
    fn variant_refine(&self, centre: &Effect) -> Option<f64> {
        behind(centre).then_some(0.03)
    }
    /// From `MODE_MIN_PERIODS` periods over the screening window to the motion bandwidth, and at
    /// most half the derivative filter's default cutoff (`record::default_cutoff`): above it the
    /// derived acceleration is
    /// attenuated by more than 6 % (forward-backward Butterworth-2: 1/(1 + (f/fc)⁴)), so a
    /// mode's force cannot be told from the filter's loss; and to a quarter of the derivative
    /// filter's cutoff when the record states it (24 values, log-spaced, from twice the lowest,
    /// and below it at their spacing). With the device
    /// behind the compliance (`COMPLIANCE_BEHIND`) the mode is driven by the device's own
    /// force, whose friction steps at every reversal: its values reach above the motion
    /// bandwidth, to the same caps (24 more).
    fn grid(&self, ctx: &Context, cand: &Effect) -> Vec<Effect> {
        let t = ctx.dt * ctx.window as f64;
        let cap = ctx
            .rec
            .meta
            .get(crate::record::DERIVATIVE_CUTOFF_KEY)
            .map_or(f64::INFINITY, |fc| 0.25 * fc)
            .min(0.025 / ctx.dt);
        let lo = MODE_MIN_PERIODS / t;
        let mid = 2.0 * lo;
        let mut g = Vec::new();
        let behind_p2 = COMPLIANCE_BEHIND + BEHIND_ZETAS[BEHIND_ZETA_GRID];
        for (hi, p2) in [(ctx.f_motion.min(cap), 0.0), (cap, behind_p2)] {
            let values = if hi > 1.5 * mid {
                // 24 values from twice the lowest, continued below at their spacing (a sharp
                // mode falls between coarser values)
                let r = (hi / mid).powf(1.0 / 23.0);
                let below = (1..)
                    .map(|k| mid / r.powi(k))
                    .take_while(|p| *p >= lo * (1.0 - 1e-9));
                let mut v: Vec<f64> = below.collect();
                v.reverse();
                v.extend(logspace(mid, hi, 24));
                v
            } else if hi > 1.5 * lo {
                logspace(lo, hi, 24)
            } else {
                Vec::new()
            };
            g.extend(values.into_iter().map(|p| Effect {
                kind: cand.kind,
                param: p,
                param2: p2,
            }));
        }
        g
    }
    /// Each value costs a pass of the resonator over the record: 7 values per level.
    fn refine(&self, _ctx: &Context, e: &Effect, width: f64) -> Vec<Effect> {
        refine_coarse(e, width)
    }
    /// A resonance's residual is sharp in frequency: one more level.
    fn refine_widths(&self) -> &'static [f64] {
        &[0.15, 0.03, 0.006]
    }
    /// A positive modal mass (its damping ratio lies in [0.01, 1] by construction); behind
    /// it, the device's whole force through the mode at unit gain (0.8 … 1.25).
    fn admissible(&self, e: &Effect, coef: &[f64], _base: &[f64]) -> bool {
        if behind(e) {
            unit_gain(coef[0])
        } else {
            coef[0] > 0.0
        }
    }
    fn parameters(
        &self,
        ctx: &Context,
        e: &Effect,
        coef: &dyn Fn(&str) -> f64,
        _base: &[f64],
    ) -> Vec<(String, f64)> {
        if behind(e) {
            let zl = behind_zeta(e);
            let (d, zeta) = behind_mode(ctx, e.param, zl, None)
                .map_or(([f64::NAN; 3], f64::NAN), |b| (b.d, b.zeta));
            return vec![
                ("resonance_Hz".into(), e.param),
                ("gain".into(), coef("device_through_mode")),
                ("link_damping_ratio".into(), zl),
                ("damping_ratio".into(), zeta),
                ("device_inertia_kg".into(), d[0]),
                ("device_viscous_Ns_per_m".into(), d[1]),
                ("device_coulomb_N".into(), d[2]),
            ];
        }
        let zeta = ctx.compliance_zeta(e.param).unwrap_or(f64::NAN);
        vec![
            ("resonance_Hz".into(), e.param),
            ("modal_mass_kg".into(), coef("mode_minus_rigid")),
            ("damping_ratio".into(), zeta),
        ]
    }
    fn describe(&self, _ctx: &Context, e: &Effect) -> String {
        if behind(e) {
            format!(
                "resonance near {:.3} Hz, the device behind the compliant part (the force measured in front of it)",
                e.param
            )
        } else {
            format!("resonance near {:.3} Hz", e.param)
        }
    }
    fn fragment(
        &self,
        e: &Effect,
        _model: &[(String, f64)],
        _dt: f64,
    ) -> Result<Vec<(String, FragmentValue)>, &'static str> {
        if behind(e) {
            Err("a device behind its compliance, not simulated")
        } else {
            Ok(Vec::new())
        }
    }
    /// A mode whose column is more than half the derived acceleration's noise is not resolved;
    /// one resolved must carry the margin on fits corrected for that noise
    /// (`Context::compliance_noise`): the column's noise near the derivative cutoff is the
    /// inertia column's (H − 1 ≈ −1 there), so least squares credits a modal mass near the
    /// inertia with the noise it cancels.
    /// (Not with the device behind the compliance: its column is the device's whole force
    /// through the mode, at unit gain, not a modal mass the inertia's noise can buy.)
    fn derived_noise(&self, ctx: &Context, e: &Effect) -> Option<(NoiseUse, [[f64; 3]; 3])> {
        if behind(e) {
            return None;
        }
        ctx.compliance_noise(e.param)
            .map(|c| (NoiseUse::MarginCorrected, c))
    }
}

/// The fewest periods of a mode over the screening window the grid scans (its lowest
/// frequency).
pub const MODE_MIN_PERIODS: f64 = 5.0;

/// `compliance`'s second parameter for the device behind the compliant part is this plus its
/// damping ratio (0: a mass hung on the device, its damping ratio from the record's profile).
pub const COMPLIANCE_BEHIND: f64 = 1.0;

/// The link's own damping ratios with the device behind it (the mode's damping adds the
/// device's, from its fitted coefficients: `behind_mode`); the grid's frequencies at
/// `BEHIND_ZETA_GRID`'s, the others as variants at the frequency found.
pub const BEHIND_ZETAS: [f64; 6] = [0.03, 0.06, 0.1, 0.2, 0.35, 0.6];
/// The levels of `variant_fine`'s bisection of the link's damping ratio: the last steps by
/// r^(1/8) ≈ 1.08, so the ratio is found to about ±4 %, where the link's damping force 2ζ_l·ω·v
/// that its error leaves is 4 % of a force that is itself a fraction ζ_l of the spring's.
pub const BEHIND_ZETA_LEVELS: usize = 3;
/// The damping ratio of `BEHIND_ZETAS` the frequency grid is scanned at.
pub const BEHIND_ZETA_GRID: usize = 2;

/// True for the variant with the device behind the compliance.
fn behind(e: &Effect) -> bool {
    e.param2 >= COMPLIANCE_BEHIND
}

/// The link's damping ratio of the variant with the device behind the compliance.
fn behind_zeta(e: &Effect) -> f64 {
    e.param2 - COMPLIANCE_BEHIND
}

/// `compliance` columns of several frequencies on the rows of `s`, the modes' filters in one
/// pass (a frequency whose profile identifies no mode has a zero column). A value with the
/// device behind the compliance has one column instead, the device's force through the link
/// less the rigid device's (coefficient: 1), its inertia, viscous and Coulomb coefficients and
/// the mode's damping fitted through the link (`behind_mode`).
pub(crate) fn compliance_batch(
    ctx: &Context,
    s: &Sig,
    effs: &[Effect],
) -> Vec<Vec<(String, Vec<f64>)>> {
    let fs: Vec<f64> = effs
        .iter()
        .filter(|e| !behind(e))
        .map(|e| e.param)
        .collect();
    let mut hung_z = ctx.compliance_zetas(&fs).into_iter();
    let zetas: Vec<Option<f64>> = effs
        .iter()
        .map(|e| {
            if behind(e) {
                Some(behind_zeta(e))
            } else {
                hung_z.next().flatten()
            }
        })
        .collect();
    let hung: Vec<(f64, f64)> = effs
        .iter()
        .zip(&zetas)
        .filter(|(e, _)| !behind(e))
        .filter_map(|(e, z)| z.map(|z| (e.param, z)))
        .collect();
    let mut cols = compliance_columns_at(&ctx.rec.a, &hung, ctx.dt, s.rows).into_iter();
    effs.iter()
        .zip(&zetas)
        .map(|(e, z)| {
            if behind(e) {
                let c = z
                    .and_then(|zl| behind_mode(ctx, e.param, zl, s.rows))
                    .map(|b| b.col)
                    .unwrap_or_else(|| vec![0.0; s.len()]);
                return vec![("compliance.device_through_mode".to_string(), c)];
            }
            let c = match z {
                Some(_) => cols.next().unwrap_or_default(),
                None => vec![0.0; s.len()],
            };
            vec![("compliance.mode_minus_rigid".to_string(), c)]
        })
        .collect()
}

/// The total damping ratios of the mode with the device behind it over which `behind_mode`
/// finds the one the device's own damping gives (log-spaced, each 2.2× the last): from a
/// lightly damped link to a device whose drive holds it while the link's spring gives.
const BEHIND_TOTAL_ZETAS: [f64; 8] = [0.03, 0.066, 0.15, 0.32, 0.7, 1.5, 3.3, 7.3];

/// The mode with the device behind the compliant part, as `behind_mode` finds it.
pub(crate) struct BehindMode {
    /// (H − 1)·(M·a + Fv·v) + Fc·(H·s_d − sgn v) on the rows: the device's force through the
    /// link less the rigid device's.
    col: Vec<f64>,
    /// The device's inertia, viscous and Coulomb coefficients.
    pub d: [f64; 3],
    /// The mode's total damping ratio: the link's and the device's own, ζ_l + Fv/(2·M·ω).
    pub zeta: f64,
}

/// The device (inertia M, viscous Fv, Coulomb Fc) behind a link of stiffness k = M·ω² and
/// damping c = 2·ζ_l·M·ω, the force measured on the link's other side. The device's motion is
/// H·x with H = (2ζ_l·ω·s + ω²)/(s² + 2ζ·ω·s + ω²), ζ = ζ_l + Fv/(2·M·ω) (its own viscous
/// force damps the mode), less its friction's response, and the link's force is the device's,
/// H·(M·a + Fv·v) + Fc·H·s_d, s_d the friction over its Coulomb level (for any friction the
/// device feels). The total damping ratio is the one
/// the device's fitted coefficients give: the fits at `BEHIND_TOTAL_ZETAS` (the device's
/// coefficients through each mode on the training samples in motion, `DeviceRows::fit`) give each
/// an implied ζ_l + Fv/(2·M·ω); the value where it crosses the assumed one (interpolated in
/// ln ζ between the bracketing grid values, of the crossings the one of least rss) is the
/// mode's, and the device is fitted there with s_d the (smoothed) sign of its velocity H·v,
/// then refitted `STICK_PASSES` times with s_d the friction of its walk behind the link at the
/// last fit's coefficients (`friction_behind_link`: it sticks where the link's force does not
/// overcome its Coulomb level, so the force through the link there is the spring's), the
/// total damping ratio searched again with that friction (the stuck device does not damp the
/// mode as the smoothed sign does: found with the sign, ζ and M come out 20–90 % high): the
/// first passes step to the ratio the last fit implies, and once two passes bracket the
/// crossing, false position in ln ζ. None when no
/// crossing lies on the grid or the device's fit is not a device's (a coefficient below 0, no
/// inertia, or fewer than 10 rows): the column is then zero.
pub(crate) fn behind_mode(
    ctx: &Context,
    f_r: f64,
    zl: f64,
    rows: Option<&[usize]>,
) -> Option<BehindMode> {
    let r = ctx.rec;
    let w = std::f64::consts::TAU * f_r;
    let through = |sig: &[f64], modes: &[(f64, f64)], rows: Option<&[usize]>| {
        let cap = rows.map_or(sig.len(), |rw| rw.len());
        let mut out: Vec<Vec<f64>> = vec![Vec::with_capacity(cap); modes.len()];
        resonator_each(sig, modes, ctx.dt, rows, |k, lp, bp| {
            out[k].push(lp + 2.0 * zl * bp)
        });
        out
    };
    // the rows the device is fitted on, the same at every damping ratio
    let dr = DeviceRows::new(ctx, rows)?;
    let modes: Vec<(f64, f64)> = BEHIND_TOTAL_ZETAS.iter().map(|&z| (f_r, z)).collect();
    let ha = through(&r.a, &modes, rows);
    let hv = through(&r.v, &modes, rows);
    let hs = through(&ctx.sgn, &modes, rows);
    // per total damping ratio: the device's fit and the damping ratio it implies
    let fits: Vec<Option<([f64; 3], f64, f64)>> = (0..modes.len())
        .map(|k| {
            let (d, rss) = dr.fit([&ha[k], &hv[k], &hs[k]])?;
            let implied = zl + d[1] / (2.0 * d[0] * w);
            (d[0] > 0.0 && implied.is_finite()).then_some((d, rss, implied))
        })
        .collect();
    let lz: Vec<f64> = BEHIND_TOTAL_ZETAS.iter().map(|z| z.ln()).collect();
    let mut best: Option<(f64, f64)> = None;
    for k in 0..modes.len() - 1 {
        let (Some(a), Some(b)) = (&fits[k], &fits[k + 1]) else {
            continue;
        };
        let (ga, gb) = (a.2.ln() - lz[k], b.2.ln() - lz[k + 1]);
        if ga >= 0.0 && gb <= 0.0 && ga > gb {
            let lzeta = lz[k] + ga / (ga - gb) * (lz[k + 1] - lz[k]);
            let rss = a.1.min(b.1);
            if best.is_none_or(|(_, br)| rss < br) {
                best = Some((lzeta.exp(), rss));
            }
        }
    }
    let n = rows.map_or(r.len(), |rw| rw.last().map_or(0, |l| l + 1));
    let at = |j: usize| rows.map_or(j, |rw| rw[j]);
    let m = rows.map_or(n, |rw| rw.len());
    // the device's velocity and acceleration on the rows through the mode of total damping
    // ratio ζ (a filter's output at a row is the same whichever other samples it emits)
    let motion = |zeta: f64| -> Option<(Vec<f64>, Vec<f64>)> {
        let mode = [(f_r, zeta)];
        Some((
            through(&r.v, &mode, rows).pop()?,
            through(&r.a, &mode, rows).pop()?,
        ))
    };
    let mut zeta = best?.0;
    // and at the first ζ its velocity at every sample to the last row (its friction's sign)
    let vd = through(&r.v[..n], &[(f_r, zeta)], None).pop()?;
    let mut hv = map(m, |j| vd[at(j)]);
    let mut ha = through(&r.a, &[(f_r, zeta)], rows).pop()?;
    // the device fitted with its friction's sign through the mode
    let sd: Vec<f64> = vd.iter().map(|&v| sgn(v, ctx.v_eps)).collect();
    let mut hs = through(&sd, &[(f_r, zeta)], rows).pop()?;
    let (mut d, _) = dr.fit([&ha, &hv, &hs])?;
    // then through the friction of its walk behind the link (it sticks where the link's force
    // does not overcome its Coulomb level; at the coefficients of the last fit), the damping
    // ratio found again where the one the fit implies crosses the one assumed (the stuck
    // device does not damp the mode as the smoothed sign does): the first passes step to the
    // implied value, and once two have bracketed the crossing, false position in ln ζ
    // (`STICK_PASSES` fits in all)
    let mut lo: Option<(f64, f64)> = None; // (ln ζ, ln implied − ln ζ) with the gap above 0
    let mut hi: Option<(f64, f64)> = None; // the gap below 0

    // the total damping ratio a fit of the device implies, and the search's range
    let implied = |d: &[f64]| zl + d[1] / (2.0 * d[0] * w);
    let (zmin, zmax) = (
        BEHIND_TOTAL_ZETAS[0],
        BEHIND_TOTAL_ZETAS[BEHIND_TOTAL_ZETAS.len() - 1],
    );
    for pass in 0..STICK_PASSES {
        if !(d[0] > 0.0 && d[2] > 0.0) {
            break;
        }
        if pass > 0 {
            let next = match (lo, hi) {
                (Some((l0, g0)), Some((l1, g1))) => (l0 + g0 / (g0 - g1) * (l1 - l0)).exp(),
                _ => implied(&d),
            };
            if !next.is_finite() || !(zmin..=zmax).contains(&next) {
                break;
            }
            zeta = next;
            (hv, ha) = motion(zeta)?;
        }
        let s = friction_behind_link(&r.x[..n], &r.v[..n], ctx.dt, w, zeta, zl, d[2] / d[0]);
        hs = through(&s, &[(f_r, zeta)], rows).pop()?;
        d = dr.fit([&ha, &hv, &hs])?.0;
        let gap = implied(&d).ln() - zeta.ln();
        if gap.is_nan() {
            break;
        }
        if gap >= 0.0 {
            lo = Some((zeta.ln(), gap));
        } else {
            hi = Some((zeta.ln(), gap));
        }
    }
    if d.iter().any(|c| *c < 0.0) || d[0] <= 0.0 {
        return None;
    }
    let col = map(m, |j| {
        let i = at(j);
        d[0] * (ha[j] - r.a[i]) + d[1] * (hv[j] - r.v[i]) + d[2] * (hs[j] - ctx.sgn[i])
    });
    Some(BehindMode { col, d, zeta })
}

/// Passes of `behind_mode`'s refit of the device through the friction of its walk behind the
/// link (`friction_behind_link`, at the coefficients of the previous fit), each at the total
/// damping ratio of its search.
const STICK_PASSES: usize = 5;

/// The friction force, over its Coulomb level, on a device behind a link (the device's motion
/// walked over the record, semi-implicit Euler at the sample period `dt`), per unit of the
/// device's mass: the link's stiffness ω², its damping 2ζ_l·ω (on the relative velocity),
/// the device's own damping 2(ζ − ζ_l)·ω, its Coulomb level `mu`; the link's end moves
/// with `x`, `v`. Sliding, the friction is ∓1 against the device's velocity; at rest (started
/// at rest, or stopped where its velocity reverses) it holds the link's force while that stays
/// within the Coulomb level (stick: the friction is the link's force over the level, in
/// [−1, 1]) and slides off when it does not. The measured force through the link is then
/// H·(M·a + Fv·v) + Fc·H·s for any friction s the device feels, so this s is the one its column
/// filters.
fn friction_behind_link(
    x: &[f64],
    v: &[f64],
    dt: f64,
    w: f64,
    zeta: f64,
    zl: f64,
    mu: f64,
) -> Vec<f64> {
    let (w2, cl, ct) = (w * w, 2.0 * zl * w, 2.0 * zeta * w);
    let mut xm = x.first().copied().unwrap_or(0.0);
    let mut vm = 0.0f64;
    let mut out = Vec::with_capacity(x.len());
    for (&xi, &vi) in x.iter().zip(v) {
        // the link's force on the device at rest, per unit mass
        let push = w2 * (xi - xm) + cl * vi;
        let s = if vm != 0.0 {
            vm.signum()
        } else if push.abs() <= mu {
            out.push(push / mu);
            continue;
        } else {
            push.signum()
        };
        let vn = (vm + dt * (push - mu * s)) / (1.0 + dt * ct);
        // the device stops where its velocity would turn against the friction that slows it
        vm = if vn * s < 0.0 { 0.0 } else { vn };
        xm += dt * vm;
        out.push(s);
    }
    out
}

/// The rows the device behind the compliance is fitted on (`DeviceRows::fit`): the training
/// samples in motion among `rows` (all when None; screening rows lie in the screening window
/// and take its held-out blocks), as indices into `rows`, with the force there.
struct DeviceRows {
    fit: Vec<usize>,
    f: Vec<f64>,
    train: Vec<u8>,
}

impl DeviceRows {
    /// None with fewer than 10 rows.
    fn new(ctx: &Context, rows: Option<&[usize]>) -> Option<Self> {
        let r = ctx.rec;
        let n = rows.map_or(r.len(), |rw| rw.len());
        let hold =
            crate::holdout_mask(if rows.is_some() { ctx.window } else { r.len() }, ctx.split);
        let at = |j: usize| rows.map_or(j, |rw| rw[j]);
        let fit: Vec<usize> = (0..n)
            .filter(|&j| {
                let i = at(j);
                !ctx.rest[i] && hold.get(i).is_some_and(|h| *h == crate::TRAIN)
            })
            .collect();
        if fit.len() < 10 {
            return None;
        }
        let f = fit.iter().map(|&j| r.f[at(j)]).collect();
        let train = vec![crate::TRAIN; fit.len()];
        Some(DeviceRows { fit, f, train })
    }

    /// The device's inertia, viscous and Coulomb coefficients fitted on its motion through the
    /// mode (`h`: H·a, H·v, H·s_d on the rows, and an offset), as `lag`'s delayed device, with
    /// the fit's rss. None with a coefficient not finite.
    fn fit(&self, h: [&[f64]; 3]) -> Option<([f64; 3], f64)> {
        let mut cols: Vec<Vec<f64>> = (0..3)
            .map(|k| self.fit.iter().map(|&j| h[k][j]).collect())
            .collect();
        cols.push(vec![1.0; self.fit.len()]);
        let refs: Vec<&[f64]> = cols.iter().map(|c| c.as_slice()).collect();
        let nq = crate::normals(&refs, &self.f, &self.train, 1).0;
        let th = nq.solve();
        let d = [th[0], th[1], th[2]];
        d.iter().all(|c| c.is_finite()).then(|| (d, nq.rss(&th)))
    }
}

#[cfg(test)]
mod tests {
    use super::{behind_mode, friction_behind_link};
    use crate::effects::Context;
    use crate::record::Record;

    /// A device (mass M, viscous Fv, Coulomb Fc) behind a link (ω, ζ_l), the link's end moved
    /// on a multisine of five tones (0.15–1.6 Hz, 4–8 mm) for 20 s at 2 kHz, the force through
    /// the link recorded. The device walked at 40 kHz, its friction a bristle state of 10 nm
    /// (Fc·z, z → sgn v + (z − sgn v)·e^(−|v|·h/x_b): it sticks by creeping within the bristles'
    /// travel), exact v and a, no noise.
    fn record_behind(m: f64, fv: f64, fc: f64, f_r: f64, zl: f64, phase: f64) -> Record {
        let (fs, sub, secs) = (2000.0, 20, 20.0);
        let h = 1.0 / (fs * sub as f64);
        let w = std::f64::consts::TAU * f_r;
        let (k, c) = (m * w * w, 2.0 * zl * m * w);
        let tones: Vec<(f64, f64, f64)> = (0..5)
            .map(|j| {
                let j = j as f64;
                (0.15 + 0.36 * j, 8e-3 - 1e-3 * j, phase + 1.7 * j * j)
            })
            .collect();
        let motion = |t: f64| {
            tones
                .iter()
                .fold((0.0, 0.0, 0.0), |(x, v, a), &(fr, am, ph)| {
                    let wt = std::f64::consts::TAU * fr;
                    let arg = wt * t + ph;
                    (
                        x + am * arg.sin(),
                        v + am * wt * arg.cos(),
                        a - am * wt * wt * arg.sin(),
                    )
                })
        };
        let (mut xm, mut vm, mut z) = (motion(0.0).0, motion(0.0).1, 0.0f64);
        let xb = 1e-8;
        let mut rec = Record::default();
        let n = (secs * fs) as usize;
        for i in 0..n * sub {
            let t = i as f64 * h;
            let (x, v, a) = motion(t);
            let fl = k * (x - xm) + c * (v - vm);
            if i % sub == 0 {
                rec.t.push(t);
                rec.x.push(x);
                rec.v.push(v);
                rec.a.push(a);
                rec.f.push(fl);
            }
            if vm != 0.0 {
                let sg = vm.signum();
                z = sg + (z - sg) * (-vm.abs() * h / xb).exp();
            }
            vm += (fl - fv * vm - fc * z) / m * h;
            xm += vm * h;
        }
        rec
    }

    /// The device behind the link found at the link's own frequency and damping ratio: its
    /// inertia, viscous and Coulomb coefficients and the mode's total damping ratio
    /// ζ = ζ_l + Fv/(2·M·ω) against the simulated device's, over eight devices (f_r 4–8 Hz, ζ
    /// 0.26–0.65). Measured: found on 6 of 8 (on two the fits with the friction's smoothed
    /// sign give no crossing); of those, the upper median of the relative errors 2.7 % (ζ) and
    /// 7.6 % (M), the worst 0.7 % (Fv) and 3.7 % (Fc); the worst ζ 15 %, M 29 % (a search not
    /// converged in `STICK_PASSES`). Bounds: at least 6 found, medians 8 % and 20 %, worst Fv
    /// 2 % and Fc 10 % (about 3×). Break tried: the damping ratio left where the fits with the
    /// smoothed sign cross (the walk's friction only refitting the device) gives medians 50 %
    /// (ζ) and 39 % (M), Fv 17 %, Fc 13 %.
    #[test]
    fn the_device_behind_the_link_is_found_with_its_own_damping() {
        let cases = [
            (44.0, 1000.0, 43.0, 7.85, 0.26),
            (70.0, 800.0, 60.0, 5.0, 0.08),
            (40.0, 700.0, 50.0, 6.0, 0.1),
            (25.0, 500.0, 30.0, 7.0, 0.2),
            (80.0, 1500.0, 70.0, 4.5, 0.12),
            (55.0, 900.0, 35.0, 5.5, 0.05),
            (35.0, 800.0, 45.0, 8.0, 0.15),
            (60.0, 1200.0, 65.0, 4.0, 0.25),
        ];
        let mut errs: Vec<[f64; 4]> = Vec::new();
        for (k, &(m, fv, fc, f_r, zl)) in cases.iter().enumerate() {
            let rec = record_behind(m, fv, fc, f_r, zl, 0.3 * k as f64);
            let ctx = Context::new(&rec);
            let zeta = zl + fv / (2.0 * m * std::f64::consts::TAU * f_r);
            let Some(b) = behind_mode(&ctx, f_r, zl, None) else {
                println!("M {m} Fv {fv} Fc {fc} f {f_r} ζ_l {zl} (ζ {zeta:.3}): not found");
                continue;
            };
            let e = [
                b.zeta / zeta - 1.0,
                b.d[0] / m - 1.0,
                b.d[1] / fv - 1.0,
                b.d[2] / fc - 1.0,
            ];
            println!(
                "M {m} Fv {fv} Fc {fc} f {f_r} ζ_l {zl} (ζ {zeta:.3}): ζ {:+.2} %, M {:+.2} %, Fv {:+.2} %, Fc {:+.2} %",
                100.0 * e[0],
                100.0 * e[1],
                100.0 * e[2],
                100.0 * e[3]
            );
            errs.push(e.map(f64::abs));
        }
        assert!(errs.len() >= 6, "found on {} of 8", errs.len());
        let sorted = |q: usize| {
            let mut v: Vec<f64> = errs.iter().map(|e| e[q]).collect();
            v.sort_by(f64::total_cmp);
            v
        };
        let (z, m, fv, fc) = (sorted(0), sorted(1), sorted(2), sorted(3));
        let med = |v: &[f64]| v[v.len() / 2];
        println!(
            "upper medians ζ {:.4} M {:.4}; worst Fv {:.4} Fc {:.4}",
            med(&z),
            med(&m),
            fv[fv.len() - 1],
            fc[fc.len() - 1]
        );
        assert!(med(&z) < 0.08, "ζ: median relative error {:.4}", med(&z));
        assert!(med(&m) < 0.20, "M: median relative error {:.4}", med(&m));
        assert!(fv[fv.len() - 1] < 0.02, "Fv: worst {:.4}", fv[fv.len() - 1]);
        assert!(fc[fc.len() - 1] < 0.10, "Fc: worst {:.4}", fc[fc.len() - 1]);
    }

    /// The link's damping ratio a diagnosis reports, over six devices behind links whose
    /// ratios lie between the values of `BEHIND_ZETAS` (0.045 … 0.28, f_r 4–8 Hz): the
    /// selection's bisection of ζ_l (`variant_fine`) must find each within its last step
    /// (r^(1/8) ≈ 1.08, so ±4 %) and the frequency's trade with it (the ratio comes out low by
    /// 1–11 %), where the grid alone leaves up to half its spacing (±35 %). Measured: found
    /// behind the link on 6 of 6, the relative errors' upper median 6.0 %, the worst 10.7 %.
    /// Bounds: median 12 %, worst 20 % (2× the measured: the grid alone gives 25 % for
    /// a median, so a looser bound would not tell the bisection from its absence). Break
    /// tried: no bisection (`BEHIND_ZETA_LEVELS` 0, the grid's values alone) gives the upper
    /// median 25 % and the worst 33 %: the median's bound fails.
    #[test]
    fn the_link_damping_ratio_is_found_between_the_grid_values() {
        let cases = [
            (44.0, 300.0, 43.0, 7.5, 0.28),
            (70.0, 500.0, 60.0, 5.0, 0.08),
            (40.0, 400.0, 50.0, 6.0, 0.13),
            (25.0, 200.0, 30.0, 7.0, 0.17),
            (80.0, 900.0, 70.0, 4.5, 0.045),
            (55.0, 600.0, 35.0, 5.5, 0.24),
        ];
        let mut errs: Vec<f64> = Vec::new();
        for (k, &(m, fv, fc, f_r, zl)) in cases.iter().enumerate() {
            let rec = record_behind(m, fv, fc, f_r, zl, 0.5 * k as f64);
            let d = crate::diagnose(&rec, &crate::Options::default());
            let found = d
                .findings
                .iter()
                .filter(|f| f.effect == "compliance")
                .find_map(|f| {
                    f.parameters
                        .iter()
                        .find(|(n, _)| n == "link_damping_ratio")
                        .map(|p| p.1)
                });
            println!("ζ_l {zl}: found {found:?}");
            if let Some(z) = found {
                errs.push((z / zl - 1.0).abs());
            }
        }
        errs.sort_by(f64::total_cmp);
        assert_eq!(
            errs.len(),
            cases.len(),
            "found behind the link on {}",
            errs.len()
        );
        let (med, worst) = (errs[errs.len() / 2], errs[errs.len() - 1]);
        println!("upper median {med:.4}, worst {worst:.4}");
        assert!(med < 0.12, "median relative error {med:.4}");
        assert!(worst < 0.20, "worst relative error {worst:.4}");
    }

    /// The link's end pulled from rest at a constant speed V (no link damping): the device
    /// holds, its friction the spring's force ω²·V·t over the Coulomb level μ, until that
    /// reaches μ at t* = μ/(ω²·V), and slides from there on (it never reverses), the friction
    /// at its level. Pulled back, it stops and holds again (its friction following the
    /// spring's force, ω²·Δx/μ over the end's travel Δx, with the device still) until the
    /// spring's force reaches −μ, and slides back. Break tried: the device sliding off at once
    /// (no stick) gives 1 on the first sample and no hold after the reversal.
    #[test]
    fn the_device_behind_the_link_sticks_until_the_spring_overcomes_its_friction() {
        let (dt, w, mu, vel) = (1e-3, std::f64::consts::TAU * 3.0, 2.0, 0.05);
        let n = 2000;
        let t: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
        let x: Vec<f64> = t.iter().map(|t| vel * t).collect();
        let v = vec![vel; n];
        let s = friction_behind_link(&x, &v, dt, w, 0.5, 0.0, mu);
        let t_star = mu / (w * w * vel);
        let k_star = (t_star / dt).floor() as usize;
        for (i, si) in s.iter().enumerate().take(k_star) {
            let want = w * w * vel * t[i] / mu;
            assert!((si - want).abs() < 1e-9, "sample {i}: {si} against {want}");
        }
        assert!(s[k_star + 1..].iter().all(|&si| si == 1.0));
        // and back: the end reverses at its last position
        let x_top = x[n - 1];
        let xb: Vec<f64> = x
            .iter()
            .copied()
            .chain(t.iter().map(|t| x_top - vel * t))
            .collect();
        let vb: Vec<f64> = v
            .iter()
            .copied()
            .chain(std::iter::repeat_n(-vel, n))
            .collect();
        let sb = friction_behind_link(&xb, &vb, dt, w, 0.5, 0.0, mu);
        let turned = sb[n..]
            .iter()
            .position(|&si| si == -1.0)
            .expect("slides back")
            + n;
        let held: Vec<usize> = (n..turned).filter(|&i| sb[i].abs() < 1.0).collect();
        println!(
            "held {} samples after the reversal, the end's travel {:.5} m (2μ/ω² = {:.5} m)",
            held.len(),
            held.len() as f64 * dt * vel,
            2.0 * mu / (w * w)
        );
        assert!(held.len() > 10);
        // one hold, the device still: the friction follows the spring's force
        assert_eq!(held.last().unwrap() - held[0] + 1, held.len());
        assert_eq!(*held.last().unwrap() + 1, turned);
        for p in held.windows(2) {
            let want = w * w * (xb[p[1]] - xb[p[0]]) / mu;
            assert!((sb[p[1]] - sb[p[0]] - want).abs() < 1e-9);
        }
    }
}
