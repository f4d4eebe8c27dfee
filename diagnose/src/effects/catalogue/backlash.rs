//! `backlash`: play between the imposed motion and the device (parameter: the total width b,
//! m; second parameter: the contact, `PLAY_RESTITUTIONS` or a compliant flank): while the
//! motion crosses the gap after a reversal the device carries no force, then it is struck
//! with its own momentum (`play_columns`).

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
        play_columns(ctx, s.rows, e.param, e.param2)
    }
    fn walks_history(&self) -> bool {
        true
    }
    /// The displacement grid, and the width the impacts show (`impact_travel`) at 2 % steps
    /// over ±20 %: the play's fit is sharp in its width (a width error moves every contact by
    /// half of it: the held-out error at ±5 % of the width is 2–5× the one at the width),
    /// sharper than the grid's steps.
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
        g
    }
    fn refine(&self, _ctx: &Context, e: &Effect, width: f64) -> Vec<Effect> {
        refine_coarse(e, width)
    }
    /// The contact's restitution at the width found (`PLAY_RESTITUTIONS`).
    fn variants(&self, _ctx: &Context, centre: &Effect) -> Vec<Effect> {
        PLAY_RESTITUTIONS
            .iter()
            .filter(|&&e| e != centre.param2)
            .map(|&e| Effect {
                param2: e,
                ..centre.clone()
            })
            .collect()
    }
    /// A compliant, plastic flank (`PLAY_CONTACT_FRACTIONS`) when the rigid, plastic one is the
    /// best restitution (the flank's stiffness refines a play the record shows).
    fn extended_variants(&self, ctx: &Context, centre: &Effect) -> Vec<Effect> {
        if centre.param2 != 0.0 {
            return Vec::new();
        }
        PLAY_CONTACT_FRACTIONS
            .iter()
            .map(|&q| Effect {
                param2: -q / ctx.dt,
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
        if e.param2 < 0.0 {
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
        _e: &Effect,
        model: &[(String, f64)],
        dt: f64,
    ) -> Result<Vec<(String, FragmentValue)>, &'static str> {
        let get = |n: &str| model.iter().find(|(m, _)| m == n).map_or(0.0, |(_, v)| *v);
        let taps = (0..IMPACT_TAPS)
            .map(|k| get(&format!("{}.impact_{k}", self.name())))
            .collect();
        Ok(vec![
            ("impact_pulse_kg".into(), FragmentValue::List(taps)),
            ("impact_tap_s".into(), FragmentValue::Number(dt)),
        ])
    }
    fn tested_at_reversals(&self) -> bool {
        true
    }
    /// Its two physical coefficients' agreement over the segments where it holds
    /// (`play_agreement`): the impact taps are resolved only by the contacts on the fitted
    /// rows.
    fn agreement(&self, fits: &[Vec<f64>], held: &[bool]) -> f64 {
        crate::play_agreement(fits, held)
    }
}
