//! The diagnosis's plots (SVG through [`crate::plot`]), each before and after: the baseline
//! model's (before, [`Diagnosis::stage_prediction`] of stage 0) and the extended model's
//! (after, the diagnosis's final prediction):
//! - `force_vs_time.svg`: the measured force and both predictions over a window of the record;
//! - `residual_vs_time.svg`: both residuals over the whole record (each pixel column's
//!   minimum and maximum, so that no excursion is lost to decimation);
//! - `residual_vs_position.svg`, `residual_vs_velocity.svg`: both residuals' means in bins
//!   of position (per direction of motion: a friction ripple changes sign with it) and of
//!   velocity;
//! - `residual_spectrum.svg`: both residuals' amplitude spectra (Welch) on log axes, the peaks
//!   the report names marked and labelled with their frequency, and any frequency a finding
//!   names (a resonance, a contact);
//! - `residual_spectrum_position.svg`: both residuals' spectra over position, log axes, the
//!   wavelengths the findings name (cogging, a periodic friction) and the unexplained ones
//!   marked.

use super::{report, Diagnosis, Record};
use crate::plot::{Mark, Plot, Series};
use std::path::Path;

/// Columns of a plot's frame, about: the envelope's resolution.
const COLUMNS: usize = 800;
/// Bins of the residual-against-position and -velocity means.
const BINS: usize = 120;
/// Peaks labelled on a spectrum, at most (the strongest).
const MAX_PEAKS: usize = 6;
/// Least distance between two labelled peaks, decades of frequency.
const MIN_SPACING: f64 = 0.09;

/// Each of `n` equal slices of the samples as its minimum and maximum, in time order: a
/// line through them draws the signal's envelope as a column of pixels would show it.
fn envelope(t: &[f64], y: &[f64], n: usize) -> Vec<(f64, f64)> {
    let per = t.len().div_ceil(n.max(1)).max(1);
    let mut out = Vec::with_capacity(2 * n);
    for (ts, ys) in t.chunks(per).zip(y.chunks(per)) {
        let (mut lo, mut hi) = (0, 0);
        for (k, v) in ys.iter().enumerate() {
            if *v < ys[lo] {
                lo = k;
            }
            if *v > ys[hi] {
                hi = k;
            }
        }
        let (a, b) = if lo <= hi { (lo, hi) } else { (hi, lo) };
        out.push((ts[a], ys[a]));
        if b != a {
            out.push((ts[b], ys[b]));
        }
    }
    out
}

/// The mean of `y` in `BINS` equal bins of `x` over the samples `keep` selects (empty bins
/// left out): (bin centre, mean).
fn binned(x: &[f64], y: &[f64], keep: impl Fn(usize) -> bool) -> Vec<(f64, f64)> {
    let idx: Vec<usize> = (0..x.len())
        .filter(|&k| keep(k) && x[k].is_finite())
        .collect();
    let lo = idx.iter().map(|&k| x[k]).fold(f64::INFINITY, f64::min);
    let hi = idx.iter().map(|&k| x[k]).fold(f64::NEG_INFINITY, f64::max);
    if idx.len() < 2 || hi <= lo {
        return Vec::new();
    }
    let w = (hi - lo) / BINS as f64;
    let mut sum = vec![(0.0, 0usize); BINS];
    for &k in &idx {
        let b = (((x[k] - lo) / w) as usize).min(BINS - 1);
        sum[b].0 += y[k];
        sum[b].1 += 1;
    }
    sum.iter()
        .enumerate()
        .filter(|(_, s)| s.1 > 0)
        .map(|(b, s)| (lo + (b as f64 + 0.5) * w, s.0 / s.1 as f64))
        .collect()
}

/// The amplitude of a spectrum at the bin nearest to `f`.
fn at(sp: &[(f64, f64)], f: f64) -> Option<(f64, f64)> {
    sp.iter()
        .min_by(|a, b| (a.0 - f).abs().total_cmp(&(b.0 - f).abs()))
        .map(|p| (f, p.1))
}

/// Three significant digits, as a label shows them (`1.7`, `0.0123`, `2.5e+04` → `25000`).
fn g3(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let digits = (2.0 - v.abs().log10().floor()).max(0.0) as usize;
    let s = format!("{v:.digits$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// The strongest peaks, at most `MAX_PEAKS`, each at least `MIN_SPACING` decades of
/// frequency from a stronger one kept (on a log axis of about three decades over 800 px: 24
/// px, and the plot staggers neighbouring labels over three heights), so no two labels
/// overlap.
fn strongest(mut marks: Vec<((f64, f64), String)>) -> Vec<Mark> {
    marks.sort_by(|a, b| b.0 .1.total_cmp(&a.0 .1));
    let mut kept: Vec<((f64, f64), String)> = Vec::new();
    for m in marks {
        let far = kept
            .iter()
            .all(|k| (k.0 .0.log10() - m.0 .0.log10()).abs() >= MIN_SPACING);
        if far && kept.len() < MAX_PEAKS {
            kept.push(m);
        }
    }
    kept.into_iter()
        .map(|(at, label)| Mark::Peak { at, label })
        .collect()
}

fn write(p: &Plot, dir: &Path, name: &str, out: &mut Vec<String>) -> Result<(), String> {
    let path = dir.join(name);
    p.write_svg(&path)?;
    out.push(path.display().to_string());
    Ok(())
}

const BEFORE: &str = "baseline model (before)";
const AFTER: &str = "extended model (after)";

/// Write the diagnosis's plots into `dir` (see the module's documentation); returns their
/// paths.
pub fn write_plots(dir: &Path, rec: &Record, d: &Diagnosis) -> Result<Vec<String>, String> {
    let n = rec.len();
    let base = d
        .stage_prediction(rec, 0)
        .ok_or("the diagnosis fitted no model: nothing to plot")?;
    let fin = &d.prediction;
    let r0: Vec<f64> = (0..n).map(|k| rec.f[k] - base[k]).collect();
    let r1: Vec<f64> = (0..n).map(|k| rec.f[k] - fin[k]).collect();
    let mut out = Vec::new();

    // The measured force and both predictions over a tenth of the record (2 s at least), in
    // its middle.
    let (t0, t1) = (rec.t[0], rec.t[n - 1]);
    let len = ((t1 - t0) / 10.0).max(2.0).min(t1 - t0);
    let a = 0.5 * (t0 + t1 - len);
    let (ka, kb) = (
        rec.t.partition_point(|&t| t < a),
        rec.t.partition_point(|&t| t <= a + len),
    );
    let win = |y: &[f64]| envelope(&rec.t[ka..kb], &y[ka..kb], COLUMNS);
    let mut p = Plot::new(
        format!(
            "diagnosis: measured force and the models' predictions, {:.1} … {:.1} s",
            a,
            a + len
        ),
        "time t (s)",
        "force f (N)",
    );
    p.series.push(Series::line("measured", win(&rec.f)));
    p.series.push(Series::line(BEFORE, win(&base)));
    p.series.push(Series::line(AFTER, win(fin)));
    p.colours = vec![(0x33, 0x33, 0x33), (0xd6, 0x27, 0x28), (0x1f, 0x77, 0xb4)];
    write(&p, dir, "force_vs_time.svg", &mut out)?;

    // Both residuals over the whole record.
    let mut p = Plot::new(
        "diagnosis: force residual (measured − predicted) over the record",
        "time t (s)",
        "force residual (N)",
    );
    p.series
        .push(Series::line(BEFORE, envelope(&rec.t, &r0, COLUMNS)));
    p.series
        .push(Series::line(AFTER, envelope(&rec.t, &r1, COLUMNS)));
    p.colours = vec![(0xd6, 0x27, 0x28), (0x1f, 0x77, 0xb4)];
    write(&p, dir, "residual_vs_time.svg", &mut out)?;

    // Against position, per direction of motion (samples moving faster than 5 % of the peak
    // speed: the direction is then certain), and against velocity.
    let vmax = rec.v.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut p = Plot::new(
        "diagnosis: mean force residual against position, per direction of motion",
        "position x (m)",
        "mean force residual (N)",
    );
    for (r, who) in [(&r0, "before"), (&r1, "after")] {
        for (sign, dir_name) in [(1.0, "moving +x"), (-1.0, "moving −x")] {
            let pts = binned(&rec.x, r, |k| sign * rec.v[k] > 0.05 * vmax);
            p.series
                .push(Series::line(format!("{who}, {dir_name}"), pts));
        }
    }
    p.colours = vec![
        (0xd6, 0x27, 0x28),
        (0xff, 0x9e, 0x4a),
        (0x1f, 0x77, 0xb4),
        (0x17, 0xbe, 0xcf),
    ];
    write(&p, dir, "residual_vs_position.svg", &mut out)?;
    let mut p = Plot::new(
        "diagnosis: mean force residual against velocity",
        "velocity v (m/s)",
        "mean force residual (N)",
    );
    p.series
        .push(Series::line(BEFORE, binned(&rec.v, &r0, |_| true)));
    p.series
        .push(Series::line(AFTER, binned(&rec.v, &r1, |_| true)));
    p.colours = vec![(0xd6, 0x27, 0x28), (0x1f, 0x77, 0xb4)];
    write(&p, dir, "residual_vs_velocity.svg", &mut out)?;

    // Spectra on log axes (the zero-frequency bin left out).
    let dt = rec.dt();
    let s0: Vec<(f64, f64)> = report::welch(&r0, dt).into_iter().skip(1).collect();
    let s1: Vec<(f64, f64)> = report::welch(&r1, dt).into_iter().skip(1).collect();
    let mut peaks: Vec<((f64, f64), String)> = d
        .spectrum_peaks
        .iter()
        .map(|pk| {
            let what = if pk.unexplained { ", unexplained" } else { "" };
            (
                (pk.freq_hz, pk.amplitude),
                format!("{} Hz{what}", g3(pk.freq_hz)),
            )
        })
        .collect();
    for f in &d.findings {
        for (name, v) in &f.parameters {
            if name.ends_with("_Hz") && *v > 0.0 {
                if let Some(q) = at(&s0, *v) {
                    peaks.push((q, format!("{} {} Hz", f.effect, g3(*v))));
                }
            }
        }
    }
    let mut p = Plot::new(
        "diagnosis: force residual's amplitude spectrum (Welch)",
        "frequency f (Hz, log scale)",
        "residual amplitude (N, log scale)",
    );
    p.xlog = true;
    p.ylog = true;
    p.series.push(Series::line(BEFORE, s0.clone()));
    p.series.push(Series::line(AFTER, s1));
    p.colours = vec![(0xd6, 0x27, 0x28), (0x1f, 0x77, 0xb4)];
    p.marks = strongest(peaks);
    p.peak_legend = "peak the report names".into();
    write(&p, dir, "residual_spectrum.svg", &mut out)?;

    let ps1 = &d.position_spectrum;
    if !ps1.spectrum.is_empty() {
        let ps0 = report::position_spectrum(rec, &r0);
        // A finding's wavelength on the baseline's curve (the ripple it takes away); one the
        // report leaves unexplained on the extended model's.
        let mut peaks: Vec<((f64, f64), String)> = Vec::new();
        for f in &d.findings {
            for (name, v) in &f.parameters {
                if name != "wavelength_m" || *v <= 0.0 {
                    continue;
                }
                let (curve, label) = if f.effect == "unexplained" {
                    (&ps1.spectrum, format!("λ {} mm, unexplained", g3(1e3 * v)))
                } else {
                    (&ps0.spectrum, format!("{} λ {} mm", f.effect, g3(1e3 * v)))
                };
                if let Some(q) = at(curve, 1.0 / v) {
                    peaks.push((q, label));
                }
            }
        }
        let mut p = Plot::new(
            "diagnosis: force residual's amplitude over position (wavelength = 1/spatial frequency)",
            "spatial frequency (cycles/m, log scale)",
            "residual amplitude (N, log scale)",
        );
        p.xlog = true;
        p.ylog = true;
        p.series.push(Series::line(BEFORE, ps0.spectrum.clone()));
        p.series.push(Series::line(AFTER, ps1.spectrum.clone()));
        p.colours = vec![(0xd6, 0x27, 0x28), (0x1f, 0x77, 0xb4)];
        p.marks = strongest(peaks);
        p.peak_legend = "wavelength the report names".into();
        write(&p, dir, "residual_spectrum_position.svg", &mut out)?;
    }
    Ok(out)
}
