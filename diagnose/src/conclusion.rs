//! The diagnosis's conclusion: the kept findings' model refitted on the whole record, its
//! residual's forces that no catalogue effect explains (spectral peaks over time and over
//! position, a slow change), the verdicts, and the `Diagnosis` that the report reads.

use super::*;

/// The baseline as the selection measured it.
pub(crate) struct Baseline {
    pub terms: Vec<BaselineTerm>,
    pub confounded: Vec<(String, String, f64)>,
    pub holdout: f64,
    pub train: f64,
    /// Its training and held-out normal equations on the whole record.
    pub full: (Normal, Normal),
}

/// The diagnosis of the validated model `selected` beside the `baseline` (`drift` the slow
/// change found on the baseline residual, `dropped_notes` the verdicts on findings not kept).
pub(crate) fn conclude(
    ctx: &effects::Context,
    opt: &Options,
    selected: Selected,
    baseline: Baseline,
    drift: Option<report::SlowChange>,
    speed_force: bool,
    dropped_notes: Vec<String>,
) -> Diagnosis {
    let Selected {
        chosen,
        mut findings,
        cols,
        full,
        stage_models,
        lag_rows_full,
        ho_rel,
    } = selected;
    let Baseline {
        terms: baseline_terms,
        confounded,
        holdout: baseline_holdout,
        train: baseline_train,
        full: base_full,
    } = baseline;
    let rec = ctx.rec;
    let n = rec.len();
    let lag_of = delay_of;
    // Final model refitted on the whole record.
    let tf = full.0.plus(&full.1);
    let sol = tf.solve_full();
    let (fit_rank, fit_condition) = (sol.rank, sol.condition);
    let th_full = sol.th;
    // Each finding's parameters are those of the final model (the coefficients `--model`
    // writes), not of the stage at which it was selected.
    for (k, f) in findings.iter_mut().enumerate().take(chosen.len()) {
        f.parameters = effects::parameters(ctx, &chosen, &cols, &th_full, k);
    }
    let pred = effects::predict(&cols, &th_full);
    // samples at rest are in no fit (static friction is anywhere within its breakaway
    // level): they carry no residual, so they cannot show as a spectral peak either; with a
    // delay, neither do those whose delayed motion is at rest
    let mut rest_final = ctx.rest.clone();
    for &j in &lag_rows_full {
        rest_final[j] = true;
    }
    let residual: Vec<f64> = rec
        .f
        .iter()
        .zip(&pred)
        .zip(&rest_final)
        .map(|((a, b), &r)| if r { 0.0 } else { a - b })
        .collect();
    let final_full = rel(tf.rss(&th_full), tf.ff);
    let tb = base_full.0.plus(&base_full.1);
    let baseline_full = rel(tb.rss(&tb.solve()), tb.ff);
    let whiteness = report::whiteness(&residual);
    let spectrum_peaks = report::spectral_peaks(&residual, rec.dt());
    for pk in spectrum_peaks.iter().filter(|p| p.unexplained) {
        findings.push(Finding {
            effect: "unexplained".into(),
            parameters: vec![("frequency_Hz".into(), pk.freq_hz), ("amplitude_N".into(), pk.amplitude)],
            holdout_rss_drop: 0.0,
            delta_bic: 0.0,
            note: format!(
                "residual spectral peak at {:.3} Hz ({:.1}x the median spectral level) that no catalogue effect explains",
                pk.freq_hz, pk.ratio
            ),
            holdout_rel_error_after: ho_rel,
            consistency: 0.0,
            confounded_with: None,
        });
    }
    // the slow change found on the baseline residual, or one the final residual still shows
    let drift_carried = drift.is_some();
    let slow =
        drift.or_else(|| report::slow_change(&rec.t, &residual, &rest_final, opt.min_holdout_gain));
    if let Some(sc) = slow {
        findings.push(Finding {
            effect: "unexplained".into(),
            parameters: vec![
                ("slope_N_per_s".into(), sc.slope_n_per_s),
                ("change_N".into(), sc.change_n),
                ("largest_departure_N".into(), sc.worst_n),
                ("largest_departure_from_s".into(), sc.worst_from_s),
                ("largest_departure_to_s".into(), sc.worst_to_s),
            ],
            holdout_rss_drop: 0.0,
            delta_bic: 0.0,
            note: format!(
                "the residual's mean changes over time (a drift of the force offset: temperature, a load cell's zero, wear): {:+.3} N/s, {:+.3} N over the record, furthest from its mean by {:+.3} N over {:.2}–{:.2} s (a trend over {} blocks, F = {:.0} against the block means' scatter, bound {:.0}; {:.1} % of the residual power){}; no catalogue effect explains it",
                sc.slope_n_per_s,
                sc.change_n,
                sc.worst_n,
                sc.worst_from_s,
                sc.worst_to_s,
                sc.blocks.len(),
                sc.f_stat,
                sc.f_bound,
                100.0 * sc.power_fraction,
                if drift_carried { "; carried by a trend in time during the search and in the model" } else { "" }
            ),
            holdout_rel_error_after: ho_rel,
            consistency: 0.0,
            confounded_with: None,
        });
    }
    // a force of the speed outside the catalogue, carried by nuisance columns
    // (`SPEED_COLUMNS`): their force at the peak speed and at half of it
    if speed_force {
        let coef = |name: &str| {
            cols.iter()
                .position(|c| c.0 == name)
                .map_or(0.0, |j| th_full[j])
        };
        // the force at the share `u` of the peak speed
        let at = |u: f64| {
            SPEED_COLUMNS
                .iter()
                .zip(SPEED_POWERS)
                .map(|(name, k)| coef(name) * u.powi(k))
                .sum::<f64>()
        };
        let (peak, half) = (at(1.0), at(0.5));
        findings.push(Finding {
            effect: "unexplained".into(),
            parameters: vec![
                ("peak_speed_m_s".into(), ctx.vmax),
                ("force_at_peak_speed_N".into(), peak),
                ("force_at_half_peak_speed_N".into(), half),
            ],
            holdout_rss_drop: 0.0,
            delta_bic: 0.0,
            note: format!(
                "a force of the speed that the findings leave and no catalogue effect explains (smooth odd powers of the speed beyond the baseline's cut the held-out rss by the selection's margin): {:+.3} N at the peak speed {:.3e} m/s, {:+.3} N at half of it, over the baseline's friction; carried by those powers during the search and in the model",
                peak,
                ctx.vmax,
                half
            ),
            holdout_rel_error_after: ho_rel,
            consistency: 0.0,
            confounded_with: None,
        });
    }
    let position_spectrum = report::position_spectrum(rec, &residual);
    for pk in position_spectrum.peaks.iter().filter(|p| p.unexplained) {
        // a residual peak at a wavelength already named is that finding's remainder (a ripple
        // not purely sinusoidal, or whose amplitude varies along the stroke), not a second
        // cause: stated on the finding, not named again
        if let Some(k) = chosen
            .iter()
            .position(|c| effects::at_wavelength(pk.wavelength_m, c))
        {
            let name = chosen[k].kind.name();
            if let Some(f) = findings.iter_mut().find(|f| f.effect == name) {
                f.note.push_str(&format!(
                    "; the residual still shows {:.3} N at {:.4e} m (a ripple not purely sinusoidal or varying along the stroke)",
                    pk.amplitude, pk.wavelength_m
                ));
            }
            continue;
        }
        let matches = if pk.matches.is_empty() {
            String::new()
        } else {
            format!("; its wavelength matches {}", pk.matches)
        };
        findings.push(Finding {
            effect: "unexplained".into(),
            parameters: vec![
                ("wavelength_m".into(), pk.wavelength_m),
                ("cycles_per_m".into(), pk.cycles_per_m),
                ("amplitude_N".into(), pk.amplitude),
            ],
            holdout_rss_drop: 0.0,
            delta_bic: 0.0,
            note: format!(
                "residual periodic in position, wavelength {:.4e} m ({:.1}x the median level of the position spectrum){matches}, that no catalogue effect explains",
                pk.wavelength_m, pk.ratio
            ),
            holdout_rel_error_after: ho_rel,
            consistency: 0.0,
            confounded_with: None,
        });
    }
    let mut verdicts = baseline_verdicts(&ctx.base_th);
    let n_rest = ctx.rest.iter().filter(|r| **r).count();
    if n_rest > 0 {
        verdicts.push(format!(
            "{n_rest} of {n} samples at rest (position still within its noise over ±{} samples), within that window of rest or at the record's ends: left out of every fit (friction at rest is static, anywhere within its breakaway level)",
            effects::rest_half_window(ctx.dt)
        ));
    }
    if let (Some(tau), false) = (lag_of(&chosen), lag_rows_full.is_empty()) {
        verdicts.push(format!(
            "{} samples in motion whose motion {tau:.4} s earlier (the delay) is at rest, or whose speed lies inside the Coulomb sign's band: left out of the fits with the delay and of those it is compared with (the delayed device is at rest there, or the baseline's sign is not the sliding device's)",
            lag_rows_full.len()
        ));
    }
    for f in findings.iter() {
        if let Some(other) = &f.confounded_with {
            verdicts.push(format!(
                "CONFOUNDED: {} ({}) and {other} explain the same residual: the held-out error of the model with either is within the selection's margin ({:.0} %) of the other's, so the record does not tell them apart; the model keeps {} and neither is named",
                f.effect,
                f.note,
                100.0 * opt.min_holdout_gain,
                f.effect
            ));
        }
    }
    verdicts.extend(dropped_notes);
    if fit_rank < cols.len() {
        verdicts.push(format!(
            "RANK-DEFICIENT FIT: the final model's {} columns have numerical rank {fit_rank} (condition number {fit_condition:.3e}): some coefficients are not determined by this record (the minimum-norm solution is reported); the motion does not separate those terms",
            cols.len()
        ));
    }
    Diagnosis {
        n,
        split: ctx.split,
        verdicts,
        derivative_method: rec.derivative_method.clone(),
        baseline_terms,
        confounded,
        baseline_holdout_rel_error: baseline_holdout,
        baseline_train_rel_error: baseline_train,
        baseline_full_rel_error: baseline_full,
        findings,
        final_holdout_rel_error: ho_rel,
        final_full_rel_error: final_full,
        model: cols.iter().map(|c| c.0.clone()).zip(th_full).collect(),
        stage_models,
        effects: chosen,
        residual,
        prediction: pred,
        whiteness,
        spectrum_peaks,
        position_spectrum,
        cross: None,
        fit_rank,
        fit_condition,
    }
}
