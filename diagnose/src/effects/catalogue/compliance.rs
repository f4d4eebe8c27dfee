//! `compliance`: an unmodelled resonance, a mass hung on the device through a spring-damper
//! (parameter: the resonance frequency f_r, Hz; the damping ratio from the record,
//! `Context::compliance_zeta`). Its variant `COMPLIANCE_BEHIND`: the force measured in front
//! of the compliant part with the device (inertia, drive, friction) behind it, so that the
//! device's viscous force passes through the mode too.

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
    /// With the device behind the compliance, the other damping ratios (`BEHIND_ZETAS`) at the
    /// frequency found.
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
    /// The frequency refined once more at the damping ratio chosen.
    fn variant_refine(&self, centre: &Effect) -> Option<f64> {
        behind(centre).then_some(0.03)
    }
    /// From 10 periods over the screening window to the motion bandwidth, and at most half the
    /// derivative filter's default cutoff (`record::default_cutoff`): above it the derived acceleration is
    /// attenuated by more than 6 % (forward-backward Butterworth-2: 1/(1 + (f/fc)⁴)), so a
    /// mode's force cannot be told from the filter's loss; and to a quarter of the derivative
    /// filter's cutoff when the record states it (24 values, log-spaced). With the device
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
        let lo = 10.0 / t;
        let mut g = Vec::new();
        let behind_p2 = COMPLIANCE_BEHIND + BEHIND_ZETAS[BEHIND_ZETA_GRID];
        for (hi, p2) in [(ctx.f_motion.min(cap), 0.0), (cap, behind_p2)] {
            if hi > 1.5 * lo {
                g.extend(logspace(lo, hi, 24).into_iter().map(|p| Effect {
                    kind: cand.kind,
                    param: p,
                    param2: p2,
                }));
            }
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
            let zeta = behind_zeta(e);
            let d = behind_device(ctx, e.param, zeta).unwrap_or([f64::NAN; 3]);
            return vec![
                ("resonance_Hz".into(), e.param),
                ("gain".into(), coef("device_through_mode")),
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

/// `compliance`'s second parameter for the device behind the compliant part is this plus its
/// damping ratio (0: a mass hung on the device, its damping ratio from the record's profile).
pub const COMPLIANCE_BEHIND: f64 = 1.0;

/// The damping ratios of a mode with the device behind it: its own drive's and friction's
/// damping pass through the mode, so the hung mass's profile does not give it; the grid's
/// frequencies at `BEHIND_ZETA_GRID`'s, the others as variants at the frequency found.
pub const BEHIND_ZETAS: [f64; 6] = [0.03, 0.06, 0.1, 0.2, 0.35, 0.6];
/// The damping ratio of `BEHIND_ZETAS` the frequency grid is scanned at.
pub const BEHIND_ZETA_GRID: usize = 2;

/// True for the variant with the device behind the compliance.
fn behind(e: &Effect) -> bool {
    e.param2 >= COMPLIANCE_BEHIND
}

/// The damping ratio of the variant with the device behind the compliance.
fn behind_zeta(e: &Effect) -> f64 {
    e.param2 - COMPLIANCE_BEHIND
}

/// `compliance` columns of several frequencies on the rows of `s`, the modes' filters in one
/// pass (a frequency whose profile identifies no mode has a zero column). A value with the
/// device behind the compliance has one column instead, (H − 1)·(M·a + Fv·v + Fc·sgn v): the
/// device's force through the mode less the rigid device's (coefficient: 1), its inertia,
/// viscous and Coulomb coefficients fitted through the mode (`behind_device`).
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
                    .and_then(|z| {
                        let t = through_mode(ctx, (e.param, z), s.rows);
                        let d = device_through(ctx, s.rows, &t)?;
                        Some(map(s.len(), |j| {
                            d[0] * t[0][j] + d[1] * t[1][j] + d[2] * t[2][j]
                        }))
                    })
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

/// (H − 1)·a, (H − 1)·v and (H − 1)·sgn v of the mode (f_r, ζ) on `rows` (all when None), H
/// the device's motion behind the compliance over the motion in front of it: a low-pass of
/// damping ratio ζ, the device's drive and friction damping it (the link's own damping, small
/// beside them, left out of its numerator).
fn through_mode(ctx: &Context, mode: (f64, f64), rows: Option<&[usize]>) -> [Vec<f64>; 3] {
    let one = |sig: &[f64]| -> Vec<f64> {
        let kept = resonator_passes(sig, &[mode], ctx.dt, rows)
            .pop()
            .map(|(_, k)| k)
            .unwrap_or_default();
        kept.iter()
            .enumerate()
            .map(|(j, o)| o[0] - rows.map_or(sig[j], |r| sig[r[j]]))
            .collect()
    };
    [one(&ctx.rec.a), one(&ctx.rec.v), one(&ctx.sgn)]
}

/// The device behind a compliance of mode (f_r, ζ): its inertia, viscous and Coulomb
/// coefficients fitted with its motion columns taken through the mode (`device_through`) on
/// the whole record's training samples in motion.
pub(crate) fn behind_device(ctx: &Context, f_r: f64, zeta: f64) -> Option<[f64; 3]> {
    let t = through_mode(ctx, (f_r, zeta), None);
    device_through(ctx, None, &t)
}

/// The device's inertia, viscous and Coulomb coefficients fitted with its motion columns taken
/// through the mode (H·a, H·v, H·sgn v from `t`, the (H − 1) columns on `rows`, and an offset)
/// on the training samples in motion among `rows` (all when None; screening rows lie in the
/// screening window and take its held-out blocks), as `lag`'s delayed device. None when the
/// fit is not a device's (a coefficient below 0, or fewer than 10 rows): the column is then
/// zero and the variant is not named at this frequency.
fn device_through(ctx: &Context, rows: Option<&[usize]>, t: &[Vec<f64>; 3]) -> Option<[f64; 3]> {
    let r = ctx.rec;
    let n = rows.map_or(r.len(), |rw| rw.len());
    let hold = crate::holdout_mask(if rows.is_some() { ctx.window } else { r.len() });
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
    let sigs: [&[f64]; 3] = [&r.a, &r.v, &ctx.sgn];
    let mut cols: Vec<Vec<f64>> = (0..3)
        .map(|k| fit.iter().map(|&j| sigs[k][at(j)] + t[k][j]).collect())
        .collect();
    cols.push(vec![1.0; fit.len()]);
    let f: Vec<f64> = fit.iter().map(|&j| r.f[at(j)]).collect();
    let refs: Vec<&[f64]> = cols.iter().map(|c| c.as_slice()).collect();
    let train = vec![crate::TRAIN; fit.len()];
    let th = crate::normals(&refs, &f, &train, 1).0.solve();
    let d = [th[0], th[1], th[2]];
    d.iter().all(|c| c.is_finite() && *c >= 0.0).then_some(d)
}
