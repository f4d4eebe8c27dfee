//! The validation of findings: stability across segments, agreement of parameters, the baseline's verdicts and the cross-check on a second record.

use super::*;

/// Independent segments of the record over which each finding's stability is checked.
pub const STABILITY_SEGMENTS: usize = 5;
/// Segments (of `STABILITY_SEGMENTS`) on which a finding must hold to be kept.
pub const STABILITY_MIN: usize = 4;
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

/// A play's agreement across the segment fits where it holds (`agreement_of_held`), asked of
/// its two physical coefficients, each on its own: the free force's gain (the device's own
/// force, 1) and the impact's momentum per unit relative velocity (the sum of the taps,
/// (1 + e)·M); the smaller of their jackknife t. The taps one by one are the contact pulse's
/// shape sampled from each contact's interpolated instant: a contact the walk places a sample
/// off in one segment moves the pulse between neighbouring taps and leaves their sum, so the
/// shape scatters across segments while the momentum it carries does not (rounded triangle
/// 600007: t = 3.0 on the taps, 8.7 on the momentum, 122 on the gain).
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
            "NON-PHYSICAL BASELINE: inertia {:.4e} kg < 0. The force falls with acceleration: on periodic motion a stiffness (force ∝ x, in antiphase with a) fits as a negative mass, so a spring, a resonance above the motion band or a position-dependent force dominates; the catalogue's names are not reliable on this record",
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
