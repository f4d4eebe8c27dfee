//! The validation of findings: stability across segments, agreement of parameters, the baseline's verdicts and the cross-check on a second record.

use super::*;

/// Independent segments of the record over which each finding's stability is checked.
pub const STABILITY_SEGMENTS: usize = 5;
/// Segments (of `STABILITY_SEGMENTS`) on which a finding must hold to be kept.
pub const STABILITY_MIN: usize = 4;
/// The share of the selection's margin (`Options::min_holdout_gain`) by which a finding must
/// lower a segment's held-out rss to hold on it: the whole margin, the evidence the selection
/// asks of it on the whole record asked again of each segment on its own. A finding that
/// carries the margin on the whole record only through some of its segments (a force the
/// baseline misses in part of the motion, fitted by columns that follow it there) does not
/// hold on the others.
pub const STABILITY_GAIN_SHARE: f64 = 1.0;
/// Agreement of a finding's coefficients across the stability segments: its jackknife t
/// (the segment fits' mean coefficient vector over the jackknife standard error of their
/// projections on it) must reach this. With 5 leave-one-segment-out fits, t ≥ 3 means the
/// coefficient is determined to within a third of its value by every part of the record (a
/// two-sided 4 % level for a t variable with 4 degrees of freedom); a fit that the segments
/// scatter around zero or across a wide range is not the same effect throughout the record.
pub const AGREEMENT_T: f64 = 3.0;

/// Jackknife t of coefficient vectors fitted with one segment left out each: |θ̄| over the
/// jackknife standard error √((S−1)/S·Σ(p_i − p̄)²) of the projections p_i = θ_i·θ̄/|θ̄|
/// (0 when there are fewer than 3 fits or θ̄ = 0; ∞ when they agree exactly).
pub fn jackknife_t(fits: &[Vec<f64>]) -> f64 {
    let s = fits.len();
    if s < 3 {
        return 0.0;
    }
    let m = fits[0].len();
    let mean: Vec<f64> = (0..m)
        .map(|j| fits.iter().map(|f| f[j]).sum::<f64>() / s as f64)
        .collect();
    let norm = mean.iter().map(|v| v * v).sum::<f64>().sqrt();
    if !(norm > 0.0 && norm.is_finite()) {
        return 0.0;
    }
    let p: Vec<f64> = fits
        .iter()
        .map(|f| f.iter().zip(&mean).map(|(a, b)| a * b).sum::<f64>() / norm)
        .collect();
    let pm = p.iter().sum::<f64>() / s as f64;
    let se = ((s - 1) as f64 / s as f64 * p.iter().map(|v| (v - pm).powi(2)).sum::<f64>()).sqrt();
    if se > 0.0 {
        norm / se
    } else {
        f64::INFINITY
    }
}

/// `jackknife_t` of the segment fits on which a finding holds (`held`): the fits that
/// determined its coefficients.
pub fn agreement_of_held(fits: &[Vec<f64>], held: &[bool]) -> f64 {
    let kept: Vec<Vec<f64>> = fits
        .iter()
        .zip(held)
        .filter(|(_, h)| **h)
        .map(|(f, _)| f.clone())
        .collect();
    jackknife_t(&kept)
}

/// The model as the selection leaves it, fitted on the whole record: what the validation
/// tests and prunes.
pub(crate) struct Selected {
    pub chosen: Vec<Effect>,
    pub findings: Vec<Finding>,
    pub cols: Vec<(String, Vec<f64>)>,
    /// Training and held-out normal equations of `cols` on the whole record.
    pub full: (Normal, Normal),
    pub stage_models: Vec<Vec<(String, f64)>>,
    /// The whole record's samples left out with a delay of the force.
    pub lag_rows_full: Vec<usize>,
    /// Held-out relative error of the model.
    pub ho_rel: f64,
}

/// The spread subsample the stability segments are cut from: its rows, the force there and
/// each row's part (training, held out, at rest).
pub(crate) struct Spread<'a> {
    pub rows: &'a [usize],
    pub f: &'a [f64],
    pub hold: &'a [u8],
}

/// The validation of the findings selected: stability across independent segments, agreement
/// of their coefficients, and the evidence every finding must carry for what it names (a force
/// locked to position inside the band the derived signals follow, apart from the reversals
/// and from a force at one time frequency).
/// Findings that fail are removed and the model rebuilt without them; returns the model and
/// the verdicts on the findings not kept. `spans` are each finding's columns in `cols`, after
/// the `n_fixed` fixed terms (the first `n_base` the baseline's).
#[allow(clippy::too_many_arguments)]
pub(crate) fn validate(
    ctx: &effects::Context,
    opt: &Options,
    selected: Selected,
    spans: &[(usize, usize)],
    n_fixed: usize,
    n_base: usize,
    spread: &Spread,
    baseline_holdout: f64,
) -> (Selected, Vec<String>) {
    let Selected {
        mut chosen,
        mut findings,
        mut cols,
        mut full,
        mut stage_models,
        mut lag_rows_full,
        mut ho_rel,
    } = selected;
    let rec = ctx.rec;
    let (spread_rows, spread_f, spread_hold) = (spread.rows, spread.f, spread.hold);
    let spans = spans.to_vec();
    let n_sub = spread_f.len();
    let gather = |rows: &[usize], v: &[f64]| -> Vec<f64> { rows.iter().map(|&i| v[i]).collect() };
    let resid_of = |cols: &[(String, Vec<f64>)], th: &[f64]| resid_of(ctx, cols, th);
    let lag_of = delay_of;
    let hold = {
        let mut h = holdout_mask(rec.len(), ctx.split);
        for (h, &r) in h.iter_mut().zip(&ctx.rest) {
            if r {
                *h = AT_REST;
            }
        }
        h
    };
    let sub_all: Vec<Vec<f64>> = cols.iter().map(|(_, v)| gather(spread_rows, v)).collect();
    let sub_refs: Vec<&[f64]> = sub_all.iter().map(|v| v.as_slice()).collect();
    let mut holds = vec![0usize; chosen.len()];
    let mut signs = vec![(0usize, 0usize); chosen.len()];
    let mut seg_coefs: Vec<Vec<Vec<f64>>> = vec![Vec::new(); chosen.len()];
    let mut seg_held: Vec<Vec<bool>> = vec![Vec::new(); chosen.len()];
    // A delay's rows whose delayed motion is at rest (or inside the Coulomb sign's band) are left
    // out of the segments' fits, as of its other fits, except where a play is chosen: those
    // rows, right after the reversals, are where its contacts lie, and a play tested without
    // them holds nowhere (its impact taps fit to zero). A play, and a delay beside it, are
    // tested on every row in motion; every other finding beside a delay on the delay's rows (a
    // presliding's build-up there would take the delayed device's).
    let lag_rest: Vec<usize> = lag_of(&chosen)
        .map(|t| ctx.lag_rest_rows(t, Some(spread_rows)))
        .unwrap_or_default();
    let mut lag_hold = spread_hold.to_vec();
    for &j in &lag_rest {
        lag_hold[j] = AT_REST;
    }
    let with_play = chosen.iter().any(|e| e.kind.tested_at_reversals());
    let on_every_row = |e: &Effect| {
        with_play
            && !lag_rest.is_empty()
            && (e.kind.tested_at_reversals() || e.kind.force_delay(e).is_some())
    };
    let segment_fit = |hold: &[u8], sgi: usize| {
        let part: Vec<u8> = (0..n_sub)
            .map(|j| {
                if hold[j] == AT_REST {
                    AT_REST
                } else if j * STABILITY_SEGMENTS / n_sub == sgi {
                    HELD_OUT
                } else {
                    TRAIN
                }
            })
            .collect();
        let (tr, ho) = normals(&sub_refs, spread_f, &part, 1);
        let th = tr.solve();
        (tr, ho, th)
    };
    for sgi in 0..STABILITY_SEGMENTS {
        let on_lag_rows = segment_fit(&lag_hold, sgi);
        let on_all_rows = chosen
            .iter()
            .any(on_every_row)
            .then(|| segment_fit(spread_hold, sgi));
        for (k, &(a, b)) in spans.iter().enumerate() {
            let (tr, ho, th) = match &on_all_rows {
                Some(f) if on_every_row(&chosen[k]) => f,
                _ => &on_lag_rows,
            };
            if ho.n < 10 {
                continue;
            }
            let rss_with = ho.rss(th);
            let rss_without = rss_without_span(tr, ho, sub_refs.len(), (a, b));
            // (a delay's range on its least-squares fit or, failing that, on its fit corrected for
            // the derived signals' noise, as in the scan)
            let corrected = match chosen[k].kind.derived_noise(ctx, &chosen[k]) {
                Some((effects::NoiseUse::RankCorrected, sn)) => {
                    Some(lag_corrected(tr, ho, [0, 1, a], &sn).map(|c| c.0))
                }
                _ => None,
            };
            let phys = match &corrected {
                Some(None) => false,
                Some(Some(tc)) => {
                    effects::plausible(&chosen[k], &th[a..b], &th[..4.min(n_base)])
                        || effects::plausible(&chosen[k], &tc[a..b], &tc[..4.min(n_base)])
                }
                None => effects::plausible(&chosen[k], &th[a..b], &th[..4.min(n_base)]),
            };
            let held = phys
                && rss_with < rss_without * (1.0 - STABILITY_GAIN_SHARE * opt.min_holdout_gain);
            if held {
                holds[k] += 1;
            }
            seg_held[k].push(held);
            seg_coefs[k].push(th[a..b].to_vec());
            if th[a] > 0.0 {
                signs[k].0 += 1;
            } else {
                signs[k].1 += 1;
            }
        }
    }
    // A play's impact taps are the contact pulse's shape, resolved only by the contacts on the
    // fitted rows: on a record with few reversals a fit without them leaves the taps in their
    // null space (alternating ±10³ kg, their sum off the impact's momentum) and that segment
    // does not hold (its impact outside the momentum rule or its held-out rss not lowered).
    // The play's agreement is asked of the segments where it holds (`agreement_of_held`), at
    // least STABILITY_MIN of them; every other effect's of all five.
    let agreement: Vec<f64> = seg_coefs
        .iter()
        .zip(&seg_held)
        .zip(&chosen)
        .map(|((c, h), e)| e.kind.agreement(c, h))
        .collect();
    // A periodic finding names a ripple: the residual it explains (the whole-record residual
    // with its own contribution added back) must show that ripple as a peak of the spectrum
    // over position (30× the median level, the `unexplained` criterion) within the 3 % of
    // `effects::at_wavelength`. Wavelengths longer than a third of the stroke are not resolved as
    // peaks there (fewer than 3 periods) and are not checked.
    let ripple_shows: Vec<bool> = {
        let th_now = full.0.plus(&full.1).solve();
        let resid_now = if chosen
            .iter()
            .any(|e| e.kind.spatial_wavelength(e).is_some())
        {
            resid_of(&cols, &th_now)
        } else {
            Vec::new()
        };
        chosen
            .iter()
            .enumerate()
            .map(|(k, e)| {
                let Some(lambda) = e.kind.spatial_wavelength(e) else {
                    return true;
                };
                if lambda > 2.0 * ctx.x_half / 3.0 {
                    return true;
                }
                let (a, b) = spans[k];
                let mut r = resid_now.clone();
                for j in a..b {
                    for ((ri, c), &rest) in r.iter_mut().zip(&cols[j].1).zip(&ctx.rest) {
                        if !rest {
                            *ri += th_now[j] * c;
                        }
                    }
                }
                report::position_spectrum(rec, &r)
                    .peaks
                    .iter()
                    .any(|p| effects::at_wavelength(p.wavelength_m, e))
            })
            .collect()
    };
    // A periodic finding names a force locked to position: it must be carried by the samples
    // where its time frequency |v|/λ lies inside the band where the derived acceleration
    // follows the motion (`effects::ripple_in_band`). Above that band a ripple of the motion
    // itself leaves M·(a − a_derived) in the residual at the same wavelength, an inertial
    // force the record does not measure; inside it that artefact vanishes and a force ripple
    // does not. The in-band part of its columns must stand AGREEMENT_T standard errors out of
    // the noise (Wald statistic ≥ AGREEMENT_T²: χ² with 2 degrees of freedom, 1 %).
    let ripple_measured: Vec<Option<(effects::RippleInBand, effects::InBandWords)>> = chosen
        .iter()
        .enumerate()
        .map(|(k, e)| {
            // a friction building up with speed likewise: carried by the samples where its
            // column changes within that band (`effects::buildup_in_band`), with one rise there
            // and at the stops the motion passes faster
            e.kind
                .in_band(ctx, e)
                .map(|(mask, words)| (effects::in_band_ripple(ctx, &cols, spans[k], &mask), words))
        })
        .collect();
    for (k, r) in ripple_measured.iter().enumerate() {
        if let (Some((r, _)), Some(f)) = (r, findings.get_mut(k)) {
            let above = if r.amp_above > 0.0 {
                format!(
                    "above it {:.3} N (differing by {:.0} %, Wald {:.1})",
                    r.amp_above,
                    100.0 * r.rel_diff,
                    r.wald_diff
                )
            } else {
                "no sample above it".to_string()
            };
            f.note.push_str(&format!(
                "; inside the derived acceleration's band {:.3} N (Wald {:.1}), {above}",
                r.amp_in, r.wald
            ));
        }
    }
    let ripple_locked: Vec<bool> = ripple_measured
        .iter()
        .map(|r| r.is_none_or(|(r, _)| r.locked_to_position(AGREEMENT_T)))
        .collect();
    // A periodic finding names a force locked to position, not to the reversals: beside a
    // ripple locked to the last reversal whose sign follows the direction of motion (what a
    // reversal excites: a mode's ringing, a friction transient; on a motion that turns at the
    // same positions it is the position ripple's part odd about the stroke's centre) its
    // columns must stand AGREEMENT_T standard errors out of the noise
    // (`effects::ripple_apart_from_reversals`).
    let ripple_reversal: Vec<Option<f64>> = chosen
        .iter()
        .enumerate()
        .map(|(k, e)| {
            e.kind
                .spatial_wavelength(e)
                .map(|l| effects::ripple_apart_from_reversals(ctx, &cols, spans[k], l))
        })
        .collect();
    for (k, w) in ripple_reversal.iter().enumerate() {
        if let (Some(w), Some(f)) = (w, findings.get_mut(k)) {
            f.note.push_str(&format!(
                "; beside a ripple locked to the last reversal Wald {w:.1}"
            ));
        }
    }
    let ripple_apart: Vec<bool> = ripple_reversal
        .iter()
        .map(|w| w.is_none_or(|w| w >= AGREEMENT_T * AGREEMENT_T))
        .collect();
    // A friction of the speed or a ripple of the position names a force of the motion, not
    // one at a fixed time frequency: where the residual's spectrum holds a peak standing out
    // of the residual (`effects::hum_in_residual`: a hum of the supply, a machine nearby),
    // the finding's columns must stand AGREEMENT_T standard errors out of the noise beside
    // that sinusoid (`effects::finding_apart_from_hum`).
    // The hum is sought in the residual of the fixed terms and the finding alone: another
    // finding of the set (a resonance at the hum's frequency) may carry it until it is dropped.
    let hum: Vec<Option<(f64, f64)>> = chosen
        .iter()
        .enumerate()
        .map(|(k, e)| {
            if !e.kind.apart_from_hum() {
                return None;
            }
            let idx: Vec<usize> = (0..n_fixed).chain(spans[k].0..spans[k].1).collect();
            let own: Vec<(String, Vec<f64>)> = idx.iter().map(|&j| cols[j].clone()).collect();
            let th = full.0.plus(&full.1).select(&idx).solve();
            let f = effects::hum_in_residual(ctx, &resid_of(&own, &th))?;
            Some((f, effects::finding_apart_from_hum(ctx, &cols, spans[k], f)))
        })
        .collect();
    for (k, h) in hum.iter().enumerate() {
        if let (Some((hz, w)), Some(f)) = (h, findings.get_mut(k)) {
            f.note.push_str(&format!(
                "; beside the residual's force at {hz:.3} Hz Wald {w:.1}"
            ));
        }
    }
    let hum_apart: Vec<bool> = hum
        .iter()
        .map(|h| h.is_none_or(|(_, w)| w >= AGREEMENT_T * AGREEMENT_T))
        .collect();
    // A finding names a force of the device, not a difference between derivations of its
    // motion: beside what the derived signals would change by under the other derivations the
    // record supports (`record::derivation_alternatives`: the acceleration through twice and
    // half its cutoff, the velocity through the acceleration's band) and of its Coulomb sign (a
    // band a quarter as wide, the sign of the position's steps), carried as nuisance columns with free coefficients, it must still cut
    // the held-out rss of the spread subsample by the selection's margin. What those columns
    // explain is the baseline's own modelling error, which any candidate whose columns change
    // at the motion's turns would otherwise be credited with.
    let beside_derivation: Vec<Option<f64>> = if chosen.is_empty() {
        Vec::new()
    } else {
        let mut alt: Vec<Vec<f64>> = record::derivation_alternatives(rec)
            .iter()
            .map(|c| gather(spread_rows, c))
            .collect();
        alt.push(
            spread_rows
                .iter()
                .map(|&i| {
                    effects::sgn(rec.v[i], 0.25 * ctx.v_eps) - effects::sgn(rec.v[i], ctx.v_eps)
                })
                .collect(),
        );
        // the Coulomb sign as the position's steps give it: a friction switching over the
        // shortest displacement the record resolves (`effects::displacement_range`)
        let x_res = effects::displacement_range(ctx).0;
        if x_res > 0.0 {
            let z = effects::dahl(&rec.x, x_res);
            alt.push(spread_rows.iter().map(|&i| z[i] - ctx.sgn[i]).collect());
        }
        let m = sub_refs.len();
        let mut all_refs = sub_refs.clone();
        all_refs.extend(alt.iter().map(|c| c.as_slice()));
        let (tr, ho) = normals(&all_refs, spread_f, &lag_hold, 1);
        let rss_with = ho.rss(&tr.solve());
        spans
            .iter()
            .map(|&(a, b)| {
                let rss_without = rss_without_span(&tr, &ho, m + alt.len(), (a, b));
                (rss_without > 0.0).then(|| 1.0 - rss_with / rss_without)
            })
            .collect()
    };
    let derivation_apart: Vec<bool> = (0..chosen.len())
        .map(|k| {
            beside_derivation
                .get(k)
                .copied()
                .flatten()
                .is_none_or(|g| g >= opt.min_holdout_gain)
        })
        .collect();
    let kept: Vec<usize> = (0..chosen.len())
        .filter(|&k| {
            holds[k] >= STABILITY_MIN
                && (signs[k].0 == 0 || signs[k].1 == 0)
                && agreement[k] >= AGREEMENT_T
                && ripple_shows[k]
                && ripple_locked[k]
                && ripple_apart[k]
                && hum_apart[k]
                && derivation_apart[k]
        })
        .collect();
    let mut dropped_notes = Vec::new();
    if kept.len() < chosen.len() {
        for k in (0..chosen.len()).filter(|k| !kept.contains(k)) {
            if let (false, Some((r, words))) = (ripple_locked[k], ripple_measured[k]) {
                // a friction of the speed is tested where its build-up is followed, a ripple
                // where its time frequency is: the same split, worded for each
                let effects::InBandWords { not, band, outside } = words;
                dropped_notes.push(format!(
                    "{} ({}) selected, but it is not {not}: {band} {:.3} N (Wald {:.1}, at least {:.0} needed), {outside}, where the inertial force is not measured, {:.3} N (differing by {:.0} %, Wald {:.1}; at most {:.0} % or Wald {:.0}): not kept",
                    chosen[k].kind.name(),
                    effects::describe(ctx, &chosen[k]),
                    r.amp_in,
                    r.wald,
                    AGREEMENT_T * AGREEMENT_T,
                    r.amp_above,
                    100.0 * r.rel_diff,
                    r.wald_diff,
                    100.0 / AGREEMENT_T,
                    AGREEMENT_T * AGREEMENT_T,
                ));
                continue;
            }
            if let (false, Some(wald)) = (ripple_apart[k], ripple_reversal[k]) {
                dropped_notes.push(format!(
                    "{} ({}) selected, but it is not apart from a ripple locked to the last reversal (where the motion turns at the same positions, such a ripple and the position ripple's part odd about the stroke's centre are the same force): beside it Wald {wald:.1} (at least {:.0} needed): not kept",
                    chosen[k].kind.name(),
                    effects::describe(ctx, &chosen[k]),
                    AGREEMENT_T * AGREEMENT_T,
                ));
                continue;
            }
            if let (false, Some((hz, wald))) = (hum_apart[k], hum[k]) {
                dropped_notes.push(format!(
                    "{} ({}) selected, but it is not apart from the residual's force at {hz:.3} Hz (a force at one time frequency, which no function of the motion is): beside it Wald {wald:.1} (at least {:.0} needed): not kept",
                    chosen[k].kind.name(),
                    effects::describe(ctx, &chosen[k]),
                    AGREEMENT_T * AGREEMENT_T,
                ));
                continue;
            }
            if !derivation_apart[k] {
                dropped_notes.push(format!(
                    "{} ({}) selected, but beside what the derived signals would change by under another derivation of the motion (its acceleration through twice or half the filter's cutoff, its velocity through the acceleration's band, its Coulomb sign a quarter as wide or from the position's steps) it cuts the held-out rss by {:.2} % (at least {:.0} % needed): the baseline's modelling error of the motion, not a force of the device: not kept",
                    chosen[k].kind.name(),
                    effects::describe(ctx, &chosen[k]),
                    100.0 * beside_derivation[k].unwrap_or(0.0),
                    100.0 * opt.min_holdout_gain,
                ));
                continue;
            }
            if !ripple_shows[k] {
                dropped_notes.push(format!(
                    "{} ({}) selected, but the residual it explains shows no peak at its wavelength in the spectrum over position (no ripple stands 30× above the spectrum's median within 3 %): not kept",
                    chosen[k].kind.name(),
                    effects::describe(ctx, &chosen[k]),
                ));
                continue;
            }
            dropped_notes.push(format!(
                "{} ({}) selected on the whole record, held on {}/{} independent segments (at least {STABILITY_MIN} needed){}, its coefficients agreeing across them to t = {:.1} (at least {AGREEMENT_T} needed): not kept",
                chosen[k].kind.name(),
                effects::describe(ctx, &chosen[k]),
                holds[k],
                STABILITY_SEGMENTS,
                if signs[k].0 > 0 && signs[k].1 > 0 { ", its coefficient changing sign" } else { "" },
                agreement[k]
            ));
        }
        // a delay not kept gives its left-out samples back to the fits
        if !lag_rows_full.is_empty()
            && kept
                .iter()
                .all(|&k| chosen[k].kind.force_delay(&chosen[k]).is_none())
        {
            full = change_rows(&full, &refs(&cols), &rec.f, &hold, &lag_rows_full, 1.0);
            lag_rows_full.clear();
        }
        // rebuild the model from the kept findings (sub-blocks of the accumulated normals)
        let mut idx: Vec<usize> = (0..n_fixed).collect();
        let mut new_chosen = Vec::new();
        let mut new_findings = Vec::new();
        let mut new_stages = vec![stage_models[0].clone()];
        let mut new_cols: Vec<(String, Vec<f64>)> = cols[..n_fixed].to_vec();
        for &k in &kept {
            let (a, b) = spans[k];
            idx.extend(a..b);
            new_cols.extend(cols[a..b].iter().cloned());
            new_chosen.push(chosen[k].clone());
            let (t, h) = (full.0.select(&idx), full.1.select(&idx));
            new_stages.push(whole_fit(&(t.clone(), h.clone()), &new_cols));
            let th_cur = t.solve();
            let mut fnd = findings[k].clone();
            fnd.holdout_rel_error_after = rel(h.rss(&th_cur), h.ff);
            fnd.parameters =
                effects::parameters(ctx, &new_chosen, &new_cols, &th_cur, new_chosen.len() - 1);
            new_findings.push(fnd);
        }
        full = (full.0.select(&idx), full.1.select(&idx));
        cols = new_cols;
        chosen = new_chosen;
        findings = new_findings;
        stage_models = new_stages;
        ho_rel = findings
            .last()
            .map_or(baseline_holdout, |f| f.holdout_rel_error_after);
        holds = kept.iter().map(|&k| holds[k]).collect();
    }
    for (f, h) in findings.iter_mut().zip(&holds) {
        f.consistency = *h as f64 / STABILITY_SEGMENTS as f64;
    }
    let selected = Selected {
        chosen,
        findings,
        cols,
        full,
        stage_models,
        lag_rows_full,
        ho_rel,
    };
    (selected, dropped_notes)
}

/// The held-out rss of the fit on `tr` (normal equations of `n` columns) with the columns
/// `a..b` (a finding's) left out.
fn rss_without_span(tr: &Normal, ho: &Normal, n: usize, (a, b): (usize, usize)) -> f64 {
    let keep: Vec<usize> = (0..n).filter(|i| *i < a || *i >= b).collect();
    ho.select(&keep).rss(&tr.select(&keep).solve())
}

/// A play's agreement across the segment fits where it holds (`agreement_of_held`), asked of
/// its two physical coefficients, each on its own: the free force's gain (the device's own
/// force, 1) and the impact's momentum per unit relative velocity (the sum of the taps,
/// (1 + e)·M); the smaller of their jackknife t. The taps one by one are the contact pulse's
/// shape sampled from each contact's interpolated instant: a contact the walk places a sample
/// off in one segment moves the pulse between neighbouring taps and leaves their sum, so the
/// shape scatters across segments while the momentum it carries does not (on a rounded
/// triangle of the rig: t = 3.0 on the taps, 8.7 on the momentum, 122 on the gain).
pub fn play_agreement(fits: &[Vec<f64>], held: &[bool]) -> f64 {
    let gain: Vec<Vec<f64>> = fits.iter().map(|f| f[..1].to_vec()).collect();
    let momentum: Vec<Vec<f64>> = fits.iter().map(|f| vec![f[1..].iter().sum()]).collect();
    agreement_of_held(&gain, held).min(agreement_of_held(&momentum, held))
}

/// Physical checks of the baseline (inertia, viscous and Coulomb friction are non-negative),
/// each failed one stated with what it suggests.
pub fn baseline_verdicts(th: &[f64]) -> Vec<String> {
    let mut v = Vec::new();
    let get = |i: usize| th.get(i).copied().unwrap_or(0.0);
    if get(0) < 0.0 {
        v.push(format!(
            "NON-PHYSICAL BASELINE: inertia {:.4e} kg < 0. The force falls with acceleration: on periodic motion a stiffness (force ∝ x, in antiphase with a) fits as a negative mass, so a stiffness, a resonance above the motion band or a position-dependent force dominates; the catalogue's names are not reliable on this record",
            get(0)
        ));
    }
    if get(1) < 0.0 {
        v.push(format!(
            "NON-PHYSICAL BASELINE: viscous friction {:.4e} N·s/m < 0. The device delivers power in proportion to speed: an active drive (a motor pushing with the motion) or a force channel that leads or lags the position",
            get(1)
        ));
    }
    if get(2) < 0.0 {
        v.push(format!(
            "NON-PHYSICAL BASELINE: Coulomb friction {:.4e} N < 0. The force steps against friction at reversals: play (the force drops at reversals), an active drive or a sign convention of f_N opposite to x_m",
            get(2)
        ));
    }
    v
}

/// Evaluate the diagnosed model on a second record: refit nothing, use the coefficients of
/// the whole-record fit, effects in order of discovery.
pub fn cross_check(d: &mut Diagnosis, other: &Record) {
    if d.stage_prediction(other, 0).is_none() {
        // nothing was fitted, or the second record cannot be evaluated
        d.cross = None;
        return;
    }
    let ffo: f64 = other.f.iter().map(|v| v * v).sum();
    // baseline + first k effects, with that stage's coefficients (whole first record)
    let err_of = |k: usize| -> f64 {
        let pred = d.stage_prediction(other, k).unwrap_or_default();
        let rss: f64 = other
            .f
            .iter()
            .zip(&pred)
            .map(|(a, b)| (a - b) * (a - b))
            .sum();
        rel(rss, ffo)
    };
    let base = err_of(0);
    let after_each: Vec<(String, f64)> = (1..=d.effects.len())
        .map(|k| (d.effects[k - 1].kind.name().to_string(), err_of(k)))
        .collect();
    let worsens = after_each
        .iter()
        .scan(base, |prev, (_, e)| {
            let w = *e > *prev;
            *prev = *e;
            Some(w)
        })
        .collect();
    d.cross = Some(CrossCheck {
        baseline_rel_error: base,
        final_rel_error: err_of(d.effects.len()),
        after_each,
        worsens,
    });
}
