//! The candidates' parameter grids, their refinement, and their parameters in words and units.

use super::*;

/// The candidates to screen (one per kind; the grid supplies the parameter).
pub fn catalogue(_ctx: &Context) -> Vec<Effect> {
    EffectKind::all()
        .iter()
        .map(|&kind| Effect::new(kind, 0.0))
        .collect()
}

/// Highest frequency where the Welch spectrum of the position increments (at most 64
/// segments) stands 100× (in power) above the median of its upper half band, which is the
/// sensor noise floor wherever the motion is band-limited well below fs/4, plus one bin width:
/// the edge is known to the bin width only (a Hann-windowed line between two bins shows in
/// both, its main lobe spans ±2 bins), so the motion still drives a mode up to a bin above
/// the last bin that shows it (a 2.643 Hz mode whose last bin showing it was 2.686 Hz had its
/// fit's optimum at 2.718 Hz, above the scan's top and not bracketed).
pub fn motion_bandwidth(x: &[f64], dt: f64) -> f64 {
    let dx: Vec<f64> = x.windows(2).map(|w| w[1] - w[0]).collect();
    if dx.len() < 64 {
        return 0.0;
    }
    let sp = crate::report::welch_spread(&dx, dt, 64);
    let mut up: Vec<f64> = sp[sp.len() / 2..].iter().map(|p| p.1 * p.1).collect();
    let floor = median(&mut up);
    let bin = sp.get(1).map_or(0.0, |p| p.0);
    sp.iter()
        .rev()
        .find(|p| p.1 * p.1 > 100.0 * floor)
        .map_or(0.0, |p| p.0 + bin)
}

/// Quantiles of |v| (samples in motion) scanned as the speed above which a drive acting as a
/// damper saturates: from a drive clipped over most of the motion to one clipped at its peaks.
pub(crate) const SPEED_QUANTILES: [f64; 12] = [
    0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.85, 0.9, 0.93, 0.96, 0.99,
];

/// The speeds scanned as the saturation speed v_L of a drive acting as a damper (samples in
/// motion, `rest` false): the `SPEED_QUANTILES` of |v| over time, extended below and above
/// their range by the same quantiles of the speeds the motion passes through (|v| weighted by
/// the speed change |Δv| of its sample: each speed counted once per crossing, however long
/// the motion stays at it), sorted. Inside the range of the time quantiles the grid is theirs
/// (on EMPS, cruising at 0.042, 0.082 and 0.125 m/s, a crossing quantile at 0.119 m/s let a
/// drive clip be selected that held on 0/5 segments and displaced a finding).
/// A drive saturates at a speed, and the record resolves it where the motion crosses it; time
/// at a speed says nothing of where the drive saturates: on a motion that cruises at one speed
/// (a rounded triangle's constant-speed flanks) the quantiles over time all lie within 1 % of
/// the cruise speed, and a saturation below it (the rig's clipped drive, 0.45 … 0.8 of the
/// peak speed) lies outside the scanned range (not bracketed, not named). On a sinusoid the
/// crossings are uniform over [0, v̂] (quantile q at q·v̂), the time quantiles at sin(qπ/2)·v̂.
pub fn speed_levels(v: &[f64], rest: &[bool]) -> Vec<f64> {
    let n = v.len();
    // (|v|, |Δv|) of the samples in motion, Δv the central difference of v
    let mut av: Vec<(f64, f64)> = (0..n)
        .filter(|&i| !rest[i])
        .map(|i| {
            let dv = 0.5 * (v[(i + 1).min(n - 1)] - v[i.saturating_sub(1)]);
            (v[i].abs(), dv.abs())
        })
        .collect();
    if av.is_empty() {
        return Vec::new();
    }
    av.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let last = av.len() - 1;
    let mut out: Vec<f64> = SPEED_QUANTILES
        .iter()
        .map(|q| av[(last as f64 * q) as usize].0)
        .collect();
    let (lo, hi) = (out[0], out[out.len() - 1]);
    let total: f64 = av.iter().map(|p| p.1).sum();
    if total > 0.0 {
        let mut cum = 0.0;
        let mut qi = 0;
        for p in &av {
            cum += p.1;
            while qi < SPEED_QUANTILES.len() && cum >= SPEED_QUANTILES[qi] * total {
                // only where they extend the range the time quantiles span
                if p.0 < lo || p.0 > hi {
                    out.push(p.0);
                }
                qi += 1;
            }
        }
    }
    out.retain(|v| *v > 0.0);
    out.sort_unstable_by(|a, b| a.total_cmp(b));
    out.dedup();
    // no gap wider than `SPEED_GAP` between neighbours (log-spaced values inserted): the
    // refinement (±15 %) of either neighbour reaches every speed between them. A motion that
    // cruises at a few speeds puts its time quantiles on them, and a saturation between two
    // cruise speeds was reached by no refinement.
    let mut filled = Vec::with_capacity(out.len());
    for w in out.windows(2) {
        let k = (((w[1] / w[0]).ln() / SPEED_GAP.ln()).ceil() as usize).max(1);
        filled.extend(&logspace(w[0], w[1], k + 1)[..k]);
    }
    filled.extend(out.last());
    filled
}

/// The widest ratio between neighbouring speeds of `speed_levels`: 1.3, twice the 15 %
/// refinement's reach less its overlap.
pub(crate) const SPEED_GAP: f64 = 1.3;

/// Quantiles of |f̂₀| scanned as current-limit levels.
pub(crate) const CLIP_QUANTILES: [f64; 7] = [0.80, 0.85, 0.9, 0.93, 0.96, 0.98, 0.99];

pub(crate) fn logspace(a: f64, b: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| a * (b / a).powf(i as f64 / (n - 1).max(1) as f64))
        .collect()
}

/// Coarse grid of parameter values for a candidate (a single entry when not scanned). The
/// selection refines the best coarse value locally.
pub fn grid(ctx: &Context, cand: &Effect) -> Vec<Effect> {
    cand.kind.grid(ctx, cand)
}

/// The scanned range [lo, hi] of a coarse grid that `best` belongs to: the values of the same
/// sign (the two hypotheses of `current_limit` are two grids, told apart by the sign) and, when
/// the coarse grid holds `best`'s second parameter, of that second parameter (an effect's
/// variants scanned as grids of their own, `EffectModel::grid`).
pub fn scan_range(coarse: &[Effect], best: &Effect) -> (f64, f64) {
    let own = coarse.iter().any(|e| e.param2 == best.param2);
    coarse
        .iter()
        .filter(|e| (e.param < 0.0) == (best.param < 0.0))
        .filter(|e| !own || e.param2 == best.param2)
        .fold((f64::MAX, f64::MIN), |(a, b), e| {
            (a.min(e.param), b.max(e.param))
        })
}

/// True when a scanned parameter's optimum `p` lies strictly inside the scanned range
/// [`lo`, `hi`] (relative margin 1e-9 for rounding): only then is it bracketed by worse fits
/// on both sides, i.e. identified by the record.
pub fn interior(p: f64, lo: f64, hi: f64) -> bool {
    p > lo + 1e-9 * lo.abs() && p < hi - 1e-9 * hi.abs()
}

/// Local refinement grid around a coarse best value.
pub fn refine(ctx: &Context, e: &Effect, width: f64) -> Vec<Effect> {
    e.kind.refine(ctx, e, width)
}

/// Physical parameters of the `idx`-th chosen effect from the fitted coefficients (the
/// baseline's first, `th`).
pub fn parameters(
    ctx: &Context,
    chosen: &[Effect],
    cols: &[(String, Vec<f64>)],
    th: &[f64],
    idx: usize,
) -> Vec<(String, f64)> {
    let e = &chosen[idx];
    let prefix = format!("{}.", e.kind.name());
    let coef: Vec<(String, f64)> = cols
        .iter()
        .zip(th)
        .filter(|((n, _), _)| n.starts_with(&prefix))
        .map(|((n, _), t)| (n[prefix.len()..].to_string(), *t))
        .collect();
    let get = |s: &str| coef.iter().find(|c| c.0 == s).map(|c| c.1).unwrap_or(0.0);
    e.kind.parameters(ctx, e, &get, &th[..4])
}

/// One-line physical reading of an effect.
pub fn describe(ctx: &Context, e: &Effect) -> String {
    e.kind.describe(ctx, e)
}
