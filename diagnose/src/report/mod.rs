//! The report: the residual's analysis (`residual`), the opening summary in plain sentences,
//! the text report and the JSON report.

use super::{Diagnosis, Record};
use std::fmt::Write as _;

mod residual;
pub use residual::*;

/// `v` with four significant digits: fixed point from 0.001 to 99,999, scientific
/// notation outside (5e-6 is `5.000e-6`, not `0.000005`).
pub fn sig(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let mag = v.abs().log10().floor();
    if (-3.0..5.0).contains(&mag) {
        format!("{v:.*}", (3.0 - mag).max(0.0) as usize)
    } else {
        format!("{v:.3e}")
    }
}

/// The held-out error each finding takes away (percentage points of the force's energy):
/// the error before it (the baseline's, or the finding's before) less the error after it.
pub fn explained(d: &Diagnosis) -> Vec<f64> {
    let mut before = d.baseline_holdout_rel_error;
    d.findings
        .iter()
        .map(|f| {
            let x = before - f.holdout_rel_error_after;
            before = f.holdout_rel_error_after;
            x
        })
        .collect()
}

/// The report's opening: what the model gets wrong, the likely causes by what they explain
/// (with their size), the gain, and what the second record says, in plain sentences.
pub fn summary(d: &Diagnosis) -> String {
    let mut s = String::new();
    if d.residual.is_empty() {
        return s;
    }
    let pct = |x: f64| 100.0 * x;
    let _ = writeln!(
        s,
        "The baseline model (inertia, viscous and Coulomb friction, a force offset{}) misses {:.2} % of the force on the samples it was not fitted on (the held-out error: residual energy over force energy).",
        if d.baseline_terms.iter().any(|b| b.effect == "electromagnetic_force") {
            ", the machine's force"
        } else {
            ""
        },
        pct(d.baseline_holdout_rel_error)
    );
    let gain = explained(d);
    let mut order: Vec<usize> = (0..d.findings.len()).collect();
    order.sort_by(|&a, &b| gain[b].total_cmp(&gain[a]));
    let named: Vec<String> = order
        .iter()
        .filter(|&&i| d.findings[i].effect != "unexplained")
        .map(|&i| {
            let f = &d.findings[i];
            let p: Vec<String> = f
                .parameters
                .iter()
                .take(2)
                .map(|(k, v)| format!("{k} = {}", sig(*v)))
                .collect();
            let name = match &f.confounded_with {
                Some(other) => format!(
                    "{} or {other}, which the record does not tell apart",
                    f.effect
                ),
                None => f.effect.clone(),
            };
            format!(
                "{name} ({}) takes away {:.2} points",
                p.join(", "),
                pct(gain[i])
            )
        })
        .collect();
    if named.is_empty() {
        let _ = writeln!(s, "No effect of the catalogue explains what it misses.");
    } else {
        let _ = writeln!(
            s,
            "Likely causes, by what they explain: {}. With them the held-out error is {:.2} % (a gain of {:.2} points).",
            named.join("; "),
            pct(d.final_holdout_rel_error),
            pct(d.baseline_holdout_rel_error - d.final_holdout_rel_error)
        );
    }
    for f in d.findings.iter().filter(|f| f.effect == "unexplained") {
        let _ = writeln!(
            s,
            "Outside the catalogue (no effect named): {}.",
            f.note.trim()
        );
    }
    let weak: Vec<&str> = d
        .baseline_terms
        .iter()
        .filter(|b| !b.significant)
        .map(|b| b.effect.as_str())
        .collect();
    if !weak.is_empty() {
        let _ = writeln!(
            s,
            "The record does not identify {}: leaving it out does not raise the held-out error beyond the noise.",
            weak.join(", ")
        );
    }
    for (a, b, r) in &d.confounded {
        let _ = writeln!(
            s,
            "The record cannot tell {a} from {b}: their columns move together (correlation {r:.4} over the samples in motion), so only their combination is identified, not each value.",
        );
    }
    if let Some(c) = &d.cross {
        let worse: Vec<&str> = c
            .after_each
            .iter()
            .zip(&c.worsens)
            .filter(|(_, w)| **w)
            .map(|((e, _), _)| e.as_str())
            .collect();
        let _ = writeln!(
            s,
            "On the second record the baseline misses {:.2} %, the extended model {:.2} %{}.",
            pct(c.baseline_rel_error),
            pct(c.final_rel_error),
            if worse.is_empty() {
                String::new()
            } else {
                format!(
                    "; {} makes it worse and is left out of the --model fragment",
                    worse.join(", ")
                )
            }
        );
    }
    s
}

/// The statistics the report prints, each with a test that finds it in the report's text and
/// its explanation in plain words (`statistics`).
pub const STATISTICS: [(&str, &str); 6] = [
    (
        "held-out",
        "held-out error: the record is cut into 10 blocks and blocks 2, 5 and 8 are never fitted; the error is the residual's energy over the force's energy on those blocks. A finding is worth its place only if it lowers this error, which a model that merely memorises the fitted blocks does not.",
    ),
    (
        "rss drop",
        "rss drop: by how much a finding cuts the held-out residual sum of squares (the held-out error squared, before the division); the selection asks at least 2 % (--min-gain).",
    ),
    (
        "dBIC",
        "dBIC: the change of the Bayesian information criterion, n·ln(rss/n) + k·ln(n) on the fitted samples (k the parameters, a scanned one included). Negative means the fit improves by more than its extra parameters cost; the selection asks dBIC < 0 as well as the held-out drop.",
    ),
    (
        "segments",
        "held on % of segments: the record is cut into 5 consecutive segments and each is held out in turn with the model fitted on the others; a finding holds on a segment when removing it raises that segment's error by the selection's margin and its fit there is physical. It is kept when it holds on 4 of 5 with its coefficients agreeing (jackknife t ≥ 3: determined to within a third of their value by every part of the record).",
    ),
    (
        "Wald",
        "Wald: the rise of the residual sum of squares when a finding's columns are removed from a fit, over the residual variance. For columns that carry nothing it is χ²-distributed with as many degrees of freedom as columns; the diagnosis asks at least 9 (three standard errors).",
    ),
    (
        "derived acceleration's band",
        "the derived acceleration's band: velocity and acceleration are derived from the position by a zero-phase low-pass filter (cutoff fs/20, at most 50 Hz, unless stated); above about half that cutoff the derived acceleration loses more than 6 %, so an inertial force M·a there is not measured and may look like an effect. A finding tested 'inside the band' is measured where the derived signals follow the motion.",
    ),
];

/// The plain-words explanation of each statistic in `STATISTICS` that `text` (a report)
/// uses, once each, in the order of their first use (empty when it uses none).
pub fn statistics(text: &str) -> String {
    let mut used: Vec<(usize, &str)> = STATISTICS
        .iter()
        .filter_map(|(key, words)| text.find(key).map(|at| (at, *words)))
        .collect();
    used.sort_by_key(|u| u.0);
    let mut s = String::new();
    if !used.is_empty() {
        let _ = writeln!(s, "How to read the statistics:");
        for (_, words) in used {
            let _ = writeln!(s, "  - {words}");
        }
    }
    s
}

/// `text` followed by the explanation of the statistics it uses (`statistics`).
pub fn text_explained(rec: &Record, d: &Diagnosis) -> String {
    let mut s = text(rec, d);
    let words = statistics(&s);
    s.push_str(&words);
    s
}

/// Human-readable report: the summary's sentences, then the details.
pub fn text(rec: &Record, d: &Diagnosis) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Model diagnosis: {} samples, dt = {:.3e} s",
        d.n,
        rec.dt()
    );
    s.push_str(&summary(d));
    if d.residual.len() == rec.len() {
        let _ = writeln!(s, "Details:");
    }
    for v in &d.verdicts {
        let _ = writeln!(s, "VERDICT: {v}");
    }
    if d.residual.len() != rec.len() {
        // the record could not be diagnosed: the verdict is the report
        return s;
    }
    let _ = writeln!(s, "  derivatives: {}", d.derivative_method);
    let _ = writeln!(s, "  split: 10 blocks, blocks 2,5,8 held out (30 %)");
    let em = d
        .baseline_terms
        .iter()
        .any(|b| b.effect == "electromagnetic_force");
    let _ = writeln!(
        s,
        "Baseline f = M·a + Fv·v + Fc·sgn(v) + offset{}:",
        if em { " + electromagnetic force" } else { "" }
    );
    for b in &d.baseline_terms {
        let _ = writeln!(
            s,
            "  {:<18} {:>12} {:<6} held-out error without it {:6.2} % {}",
            b.effect,
            sig(b.value),
            b.unit,
            100.0 * b.holdout_rel_error_without,
            if b.significant {
                "(significant)"
            } else {
                "(not significant)"
            }
        );
    }
    let _ = writeln!(
        s,
        "  relative error: train {:.2} %, held-out {:.2} %, whole record (fit on all) {:.2} %",
        100.0 * d.baseline_train_rel_error,
        100.0 * d.baseline_holdout_rel_error,
        100.0 * d.baseline_full_rel_error
    );
    let _ = writeln!(s, "Findings (forward selection: held-out rss drop >= 2 % and BIC decrease), in the order the selection added them:");
    if d.findings.is_empty() {
        let _ = writeln!(s, "  none: the baseline explains the record");
    }
    for f in &d.findings {
        let _ = write!(
            s,
            "  {:<30} held-out error after {:6.3} %  rss drop {:5.1} %  dBIC {:9.1}{}",
            f.effect,
            100.0 * f.holdout_rel_error_after,
            100.0 * f.holdout_rss_drop,
            f.delta_bic,
            if f.effect == "unexplained" {
                String::new()
            } else {
                format!("  held on {:.0} % of segments", 100.0 * f.consistency)
            }
        );
        let _ = writeln!(s, "  {}", f.note);
        if let Some(other) = &f.confounded_with {
            let _ = writeln!(
                s,
                "      confounded with {other}: the record does not tell the two apart (not named)"
            );
        }
        for (k, v) in &f.parameters {
            let _ = writeln!(s, "      {k} = {}", sig(*v));
        }
    }
    let _ = writeln!(
        s,
        "Final: held-out {:.3} % (baseline {:.3} %), whole record {:.3} % (baseline {:.3} %)",
        100.0 * d.final_holdout_rel_error,
        100.0 * d.baseline_holdout_rel_error,
        100.0 * d.final_full_rel_error,
        100.0 * d.baseline_full_rel_error
    );
    let base: Vec<String> = d
        .model
        .iter()
        .filter(|(n, _)| !n.contains('.'))
        .map(|(n, v)| {
            let (name, unit) = super::effects::baseline_term(n);
            format!("{name} {} {unit}", sig(*v))
        })
        .collect();
    let _ = writeln!(
        s,
        "Extended model fitted on the whole record (what --model writes; the findings' parameters above are of this fit): {}",
        base.join(", ")
    );
    let _ = writeln!(
        s,
        "Residual by direction / power quadrant (rms N, samples):"
    );
    for (l, r, c) in breakdown(rec, &d.residual) {
        let _ = writeln!(s, "  {l:<24} {r:10.4} {c}");
    }
    let w = &d.whiteness;
    let _ = writeln!(s, "Whiteness (Ljung-Box, {} lags): Q = {:.1}, 99 % bound {:.1}, autocorrelation at one sample {:.3}: {}", w.lags, w.q, w.q_crit, w.lag1_autocorr, if w.white { "white" } else { "coloured" });
    for p in &d.spectrum_peaks {
        let _ = writeln!(
            s,
            "  spectral peak {:.3} Hz amplitude {:.4} N ({:.0}x median){}",
            p.freq_hz,
            p.amplitude,
            p.ratio,
            if p.unexplained { " UNEXPLAINED" } else { "" }
        );
    }
    let ps = &d.position_spectrum;
    if ps.directions == 0 {
        let _ = writeln!(
            s,
            "Spectrum over position: not computed (too little motion above {:.3e} m/s)",
            ps.v_min
        );
    } else {
        let _ = writeln!(
            s,
            "Spectrum over position: {} bins of {:.3e} m over {:.4} m, |v| > {:.3e} m/s, {} direction(s); resolution {:.2} cycles/m; {}",
            ps.bins,
            ps.bin_m,
            ps.span_m,
            ps.v_min,
            ps.directions,
            1.0 / ps.span_m,
            if ps.peaks.is_empty() { "no peak 30x above the median" } else { "peaks:" }
        );
    }
    for p in &ps.peaks {
        let _ = writeln!(
            s,
            "  spatial peak wavelength {:.4e} m ({:.2} cycles/m) amplitude {:.4} N ({:.0}x median){}{}",
            p.wavelength_m,
            p.cycles_per_m,
            p.amplitude,
            p.ratio,
            if p.matches.is_empty() { String::new() } else { format!(", matches {}", p.matches) },
            if p.unexplained { " UNEXPLAINED" } else { "" }
        );
    }
    if let Some(c) = &d.cross {
        let _ = writeln!(
            s,
            "Cross-check on second record: baseline {:.3} %, final {:.3} %",
            100.0 * c.baseline_rel_error,
            100.0 * c.final_rel_error
        );
        for ((e, v), w) in c.after_each.iter().zip(&c.worsens) {
            let _ = writeln!(
                s,
                "  after {e:<30} {:.3} %{}",
                100.0 * v,
                if *w {
                    "  WORSENS the second record"
                } else {
                    ""
                }
            );
        }
    }
    s
}

/// Machine-readable report (serde_json; a non-finite number is written as `null`). Keys:
/// docs/diagnose.md, "The conclusion and the report".
pub fn json(d: &Diagnosis) -> String {
    use serde_json::{json, Map, Value};
    let num = |v: f64| Value::from(v); // NaN and ±inf become null
    let w = &d.whiteness;
    let ps = &d.position_spectrum;
    let report = json!({
        "samples": d.n,
        "verdicts": d.verdicts,
        "baseline_holdout_rel_error": num(d.baseline_holdout_rel_error),
        "final_holdout_rel_error": num(d.final_holdout_rel_error),
        "baseline_full_rel_error": num(d.baseline_full_rel_error),
        "final_full_rel_error": num(d.final_full_rel_error),
        "confounded": d.confounded.iter().map(|(a, b, r)| json!({
            "terms": [a, b],
            "correlation": num(*r),
        })).collect::<Vec<_>>(),
        "baseline_terms": d.baseline_terms.iter().map(|b| json!({
            "effect": b.effect,
            "value": num(b.value),
            "unit": b.unit,
            "holdout_rel_error_without": num(b.holdout_rel_error_without),
            "significant": b.significant,
        })).collect::<Vec<_>>(),
        "findings": d.findings.iter().map(|f| json!({
            "effect": f.effect,
            "parameters": f.parameters.iter().map(|(k, v)| (k.clone(), num(*v))).collect::<Map<_, _>>(),
            "evidence": {
                "holdout_rss_drop": num(f.holdout_rss_drop),
                "delta_bic": num(f.delta_bic),
                "consistency": num(f.consistency),
                "note": f.note,
            },
            "holdout_rel_error_after": num(f.holdout_rel_error_after),
            "confounded_with": f.confounded_with,
        })).collect::<Vec<_>>(),
        "whiteness": {
            "ljung_box_q": num(w.q),
            "q_crit_99": num(w.q_crit),
            "lags": w.lags,
            "white": w.white,
        },
        "position_spectrum": {
            "bins": ps.bins,
            "bin_m": num(ps.bin_m),
            "span_m": num(ps.span_m),
            "v_min_m_s": num(ps.v_min),
            "directions": ps.directions,
            "peaks": ps.peaks.iter().map(|p| json!({
                "wavelength_m": num(p.wavelength_m),
                "amplitude_N": num(p.amplitude),
                "ratio": num(p.ratio),
                "matches": p.matches,
                "unexplained": p.unexplained,
            })).collect::<Vec<_>>(),
        },
        "cross_check": d.cross.as_ref().map(|c| json!({
            "baseline_rel_error": num(c.baseline_rel_error),
            "final_rel_error": num(c.final_rel_error),
            "after_each": c.after_each.iter().zip(&c.worsens).map(|((e, v), w)| json!({
                "effect": e,
                "rel_error": num(*v),
                "worsens": w,
            })).collect::<Vec<_>>(),
        })),
    });
    let mut s = serde_json::to_string_pretty(&report).unwrap_or_default();
    s.push('\n');
    s
}

#[cfg(test)]
mod tests;
