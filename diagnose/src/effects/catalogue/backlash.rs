//! `backlash`: play between the imposed motion and the device (parameter: the total width b,
//! m; second parameter: the contact, `PLAY_RESTITUTIONS` or a compliant flank): while the
//! motion crosses the gap after a reversal the device carries no force, then it is struck
//! with its own momentum (`play_columns`). Or, as its own variant (`PLAY_FRICTION_BEHIND`),
//! play with no impact: the inertia moves with the motion in front of the gap and only the
//! friction and the drive's damping sit behind it, on a light part that stops as soon as the
//! flank leaves it (`play_friction_columns`): across the gap the friction force drops out, and
//! taking up the play exchanges no momentum the record shows.

use super::*;

pub struct Backlash;
pub const BACKLASH: EffectKind = EffectKind(&Backlash);

impl EffectModel for Backlash {
    fn name(&self) -> &'static str {
        "backlash"
    }
    fn scanned(&self) -> bool {
        true
    }
    fn columns_on(&self, ctx: &Context, s: &Sig, e: &Effect) -> Vec<(String, Vec<f64>)> {
        if friction_behind(e) {
            play_friction_columns(ctx, s.rows, e.param)
        } else {
            play_columns(ctx, s.rows, e.param, e.param2)
        }
    }
    fn walks_history(&self) -> bool {
        true
    }
    /// The displacement grid, and the width the impacts show (`impact_travel`) at 2 % steps
    /// over ±20 %: the play's fit is sharp in its width (a width error moves every contact by
    /// half of it: the held-out error at ±5 % of the width is 2–5× the one at the width),
    /// sharper than the grid's steps.
    /// Each width with the whole device behind the gap and with only its friction behind it
    /// (`PLAY_FRICTION_BEHIND`).
    fn grid(&self, ctx: &Context, cand: &Effect) -> Vec<Effect> {
        let mut g = displacement_grid(ctx, cand.kind);
        let (lo, hi) = displacement_range(ctx);
        if !g.is_empty() {
            if let Some(t) = impact_travel(ctx) {
                g.extend(
                    (-10..=10)
                        .map(|k| t * (1.0 + 0.02 * k as f64))
                        .filter(|&b| b > lo && b < hi)
                        .map(|p| Effect::new(cand.kind, p)),
                );
            }
        }
        let behind: Vec<Effect> = g
            .iter()
            .map(|e| Effect {
                param2: PLAY_FRICTION_BEHIND,
                ..e.clone()
            })
            .collect();
        g.extend(behind);
        g
    }
    fn refine(&self, _ctx: &Context, e: &Effect, width: f64) -> Vec<Effect> {
        refine_coarse(e, width)
    }
    /// The contact's restitution at the width found (`PLAY_RESTITUTIONS`).
    fn variants(&self, _ctx: &Context, centre: &Effect) -> Vec<Effect> {
        if friction_behind(centre) {
            return Vec::new();
        }
        PLAY_RESTITUTIONS
            .iter()
            .filter(|&&e| e != centre.param2)
            .map(|&e| Effect {
                param2: e,
                ..centre.clone()
            })
            .collect()
    }
    /// A compliant, plastic flank (`PLAY_CONTACT_CUTOFF_MULTIPLES` of the derivative cutoff)
    /// when the rigid, plastic one is the best restitution (the flank's stiffness refines a
    /// play the record shows).
    fn extended_variants(&self, ctx: &Context, centre: &Effect) -> Vec<Effect> {
        if centre.param2 != 0.0 {
            return Vec::new();
        }
        let fc = ctx.derivative_cutoff();
        PLAY_CONTACT_CUTOFF_MULTIPLES
            .iter()
            .map(|&q| Effect {
                param2: -q * fc,
                ..centre.clone()
            })
            .collect()
    }
    /// The width refined once more at a contact other than the rigid, plastic one (a
    /// rebounding device's contacts move with it).
    fn variant_refine(&self, centre: &Effect) -> Option<f64> {
        (centre.param2 != 0.0).then_some(0.03)
    }
    /// A compliant flank's rigid counterpart at the same width.
    fn simpler(&self, e: &Effect) -> Option<Effect> {
        (e.param2 < 0.0).then(|| Effect {
            param2: 0.0,
            ..e.clone()
        })
    }
    /// Unit gain of the force that stops across the gap (0.8 … 1.25: the device's own force)
    /// and an impact of the device's momentum (`impact_consistent`).
    fn admissible(&self, e: &Effect, coef: &[f64], base: &[f64]) -> bool {
        if friction_behind(e) {
            return unit_gain(coef[0]);
        }
        let m = base.first().copied().unwrap_or(0.0);
        e.param2.is_finite()
            && e.param2 < 1.0
            && unit_gain(coef[0])
            && impact_consistent(&coef[1..], m)
    }
    fn parameters(
        &self,
        ctx: &Context,
        e: &Effect,
        coef: &dyn Fn(&str) -> f64,
        _base: &[f64],
    ) -> Vec<(String, f64)> {
        if friction_behind(e) {
            let (fv, fc) = play_friction_coefficients(ctx, ctx.rec.x.len(), e.param);
            return vec![
                ("width_m".into(), e.param),
                ("gain".into(), coef("free")),
                ("inertia_behind_kg".into(), 0.0),
                ("device_viscous_Ns_per_m".into(), fv),
                ("device_coulomb_N".into(), fc),
            ];
        }
        let (mi, fvd, fcd) = play_device_coefficients(ctx, ctx.rec.x.len(), e.param, e.param2);
        let (rest, hz) = play_contact(e.param2);
        let mut p = vec![
            ("width_m".into(), e.param),
            ("restitution".into(), rest),
            ("gain".into(), coef("free")),
            (
                "impact_mass_kg".into(),
                (0..IMPACT_TAPS).map(|k| coef(&format!("impact_{k}"))).sum(),
            ),
            ("device_inertia_kg".into(), mi),
            ("device_viscous_Ns_per_m".into(), fvd),
            ("device_coulomb_N".into(), fcd),
        ];
        if hz > 0.0 {
            // a compliant flank: its contact mode with the device's inertia
            p.push(("contact_Hz".into(), hz));
        }
        p
    }
    fn describe(&self, _ctx: &Context, e: &Effect) -> String {
        if friction_behind(e) {
            format!(
                "play of {:.3e} m after reversals, its friction behind the gap and the inertia in front (no impact)",
                e.param
            )
        } else if e.param2 < 0.0 {
            format!(
                "play of {:.3e} m after reversals, its flank a spring (contact mode {:.1} Hz)",
                e.param, -e.param2
            )
        } else if e.param2 > 0.0 {
            format!(
                "play of {:.3e} m after reversals, its contact rebounding (restitution {:.2})",
                e.param, e.param2
            )
        } else {
            format!("play of {:.3e} m after reversals", e.param)
        }
    }
    /// The impact's force pulse as fitted (whole-record coefficients), per tap.
    fn fragment(
        &self,
        e: &Effect,
        model: &[(String, f64)],
        dt: f64,
    ) -> Result<Vec<(String, FragmentValue)>, &'static str> {
        if friction_behind(e) {
            return Err("play with the inertia in front of the gap, not simulated");
        }
        let get = |n: &str| model.iter().find(|(m, _)| m == n).map_or(0.0, |(_, v)| *v);
        let taps = (0..IMPACT_TAPS)
            .map(|k| get(&format!("{}.impact_{k}", self.name())))
            .collect();
        Ok(vec![
            ("impact_pulse_kg".into(), FragmentValue::List(taps)),
            (
                "impact_tap_s".into(),
                FragmentValue::Number(dt * tap_samples(dt) as f64),
            ),
        ])
    }
    fn tested_at_reversals(&self) -> bool {
        true
    }
    /// Its two physical coefficients' agreement over the segments where it holds
    /// (`play_agreement`): the impact taps are resolved only by the contacts on the fitted
    /// rows.
    fn agreement(&self, fits: &[Vec<f64>], held: &[bool]) -> f64 {
        if fits.first().is_some_and(|f| f.len() == 1) {
            // the friction behind the gap: its gain alone
            return crate::agreement_of_held(fits, held);
        }
        crate::play_agreement(fits, held)
    }
}

/// `backlash`'s second parameter for play with only the friction (and the drive's damping)
/// behind the gap (outside the restitutions' [0, 1) and the compliant flanks' negative codes).
pub const PLAY_FRICTION_BEHIND: f64 = 2.0;

/// True for the variant with the friction behind the gap and the inertia in front.
fn friction_behind(e: &Effect) -> bool {
    e.param2 == PLAY_FRICTION_BEHIND
}

/// The viscous and Coulomb coefficients of the friction behind a play of width `b` (walked by
/// the play operator over the first `end` samples): the baseline (inertia, viscous, Coulomb,
/// offset) fitted on the samples in motion where a flank carries the light side; the
/// baseline's own when that fit is not of full rank or not physical.
pub fn play_friction_coefficients(ctx: &Context, end: usize, b: f64) -> (f64, f64) {
    let r = ctx.rec;
    let end = end.min(r.x.len()).min(ctx.sgn.len());
    let held = play_output(&r.x[..end], b);
    let base = (
        ctx.base_th.get(1).copied().unwrap_or(0.0),
        ctx.base_th.get(2).copied().unwrap_or(0.0),
    );
    let mut g = [0.0; 16];
    let mut bv = [0.0; 4];
    for i in 0..end {
        if ctx.rest[i] || !on_flank(&r.x, &held, i, b) {
            continue;
        }
        let c = [r.a[i], r.v[i], ctx.sgn[i], 1.0];
        for j in 0..4 {
            bv[j] += c[j] * r.f[i];
            for k in 0..4 {
                g[j * 4 + k] += c[j] * c[k];
            }
        }
    }
    let sol = crate::solve_sym(&g, &bv, 4);
    let t = &sol.th;
    if sol.rank == 4 && t[1] >= 0.0 && t[2] >= 0.0 && t[1].is_finite() && t[2].is_finite() {
        (t[1], t[2])
    } else {
        base
    }
}

/// True when the play operator's output `held` at sample `i` lies on a flank of the motion `x`
/// (the light side carried: its friction passes).
fn on_flank(x: &[f64], held: &[f64], i: usize, b: f64) -> bool {
    ((x[i] - held[i]).abs() - 0.5 * b).abs() <= 1e-9 * b.max(1e-12)
}

/// The force play of width `b` with only the friction behind the gap changes, on the rows of
/// `s`: column `free` is −(Fv·v + Fc·sgn v) where the motion crosses the gap (the play
/// operator, `play_output`: the light side stops where the flank leaves it), 0 on a flank;
/// coefficient 1 when the friction is the device's (`play_friction_coefficients`).
pub fn play_friction_columns(
    ctx: &Context,
    rows: Option<&[usize]>,
    b: f64,
) -> Vec<(String, Vec<f64>)> {
    let r = ctx.rec;
    let n = r.x.len();
    let len = rows.map_or(n, |r| r.len());
    let mut col = vec![0.0; len];
    if n >= 3 && b > 0.0 {
        let end = match rows {
            Some(rw) => rw.last().map_or(0, |l| l + 1).max(ctx.window).min(n),
            None => n,
        };
        let (fv, fc) = play_friction_coefficients(ctx, end, b);
        let held = play_output(&r.x[..end], b);
        let at = |j: usize| rows.map_or(j, |rw| rw[j]);
        for (j, c) in col.iter_mut().enumerate() {
            let i = at(j);
            if i < end && !on_flank(&r.x, &held, i, b) {
                *c = -(fv * r.v[i] + fc * ctx.sgn[i]);
            }
        }
    }
    vec![(format!("{}.free", BACKLASH.name()), col)]
}
