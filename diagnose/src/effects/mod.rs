//! The catalogue of candidate physical effects. Each is a set of regressor columns added to the
//! linear device model; some carry one nonlinear parameter scanned on a grid. The same
//! functions generate the effects in `synth`, so what is hidden is what is fitted (a lag
//! there is the device's force delayed, whose coefficients `lag` fits itself).

use crate::record::Record;
pub use regen_physics::{play_contact, PlayWalk, IMPACT_TAPS};

mod signals;
pub use signals::*;
mod resonator;
pub use resonator::*;
mod lag;
pub use lag::*;
mod derivatives;
pub use derivatives::*;
mod columns;
pub use columns::*;
mod play;
pub use play::*;
mod dahl;
pub use dahl::*;
mod grid;
pub use grid::*;
mod pairs;
pub use pairs::*;
mod model;
pub use model::*;
mod catalogue;
pub use catalogue::*;

/// An effect with its scanned parameter (0 when it has none) and its second scanned
/// parameter (`backlash`: the contact's restitution e, `PLAY_RESTITUTIONS`; 0 for every other
/// kind).
#[derive(Debug, Clone, PartialEq)]
pub struct Effect {
    pub kind: EffectKind,
    pub param: f64,
    pub param2: f64,
}

impl Effect {
    /// An effect with its parameter and no second one.
    pub fn new(kind: EffectKind, param: f64) -> Self {
        Effect {
            kind,
            param,
            param2: 0.0,
        }
    }

    /// The key of the effect's columns in the selection's caches: its kind and its
    /// parameters' bits (the second folded in; 0 leaves the first's bits as they are).
    pub fn key(&self) -> (usize, u64) {
        (
            self.kind.index(),
            self.param.to_bits() ^ self.param2.to_bits().rotate_left(23),
        )
    }
}

/// Precomputed signals of a record.
pub struct Context<'a> {
    pub rec: &'a Record,
    pub sgn: Vec<f64>,
    pub xn: Vec<f64>,
    pub x_mid: f64,
    pub x_half: f64,
    pub v_eps: f64,
    pub vmax: f64,
    pub dt: f64,
    /// Baseline prediction (set after the baseline fit; used by lag, current limit,
    /// efficiency).
    pub base_pred: Vec<f64>,
    /// Shortest wavelength scanned: the stroke / 400, but at least 8 median position steps.
    pub lambda_min: f64,
    /// Quantiles 80 … 99 % of |baseline prediction| (the current-limit grid of the whole
    /// force, a motor-driven axis).
    pub clip_levels: Vec<f64>,
    /// Speeds scanned as the saturation speed of a drive acting as a damper on an imposed
    /// motion (its force ∝ v saturates above a speed): `speed_levels`.
    pub speed_levels: Vec<f64>,
    /// Motion bandwidth: the highest frequency where the spectrum of the position increments
    /// stands 100× above its noise floor (median of the upper half band). The compliance scan
    /// stops there: a resonance is seen only where the motion has content.
    pub f_motion: f64,
    /// Wavelengths of the peaks of the baseline residual's spectrum over position
    /// (`report::position_spectrum`), added to the periodic candidates' grid: a ripple of many
    /// periods over the stroke decorrelates from a log-grid value a few % off.
    pub spatial_wavelengths: Vec<f64>,
    /// Samples at rest (see `at_rest`), left out of every fit.
    pub rest: Vec<bool>,
    /// Baseline coefficients fitted on the whole record (columns of `base_columns`).
    pub base_th: Vec<f64>,
    /// Position quantum (`position_quantum`): the smallest non-zero step of x_m, 0 when none.
    pub x_quantum: f64,
    /// rms of the baseline residual on the fitted samples.
    pub base_resid_rms: f64,
    /// `compliance_zeta` per resonance frequency (bits of f).
    pub zeta_cache: std::sync::Mutex<std::collections::HashMap<u64, f64>>,
    /// The damping-ratio profile's rows with the baseline columns and the force there (the
    /// same for every frequency: built once).
    pub profile_rows: std::sync::OnceLock<FitRows>,
    /// The training rows the delayed baseline of `lag` is fitted on (built once).
    pub lag_rows: std::sync::OnceLock<FitRows>,
    /// `lag_coefs` per delay (bits of τ).
    pub lag_cache: std::sync::Mutex<std::collections::HashMap<u64, Option<[f64; 3]>>>,
    /// The derived velocity's and acceleration's noise (`DerivNoise`, built once).
    pub deriv_noise: std::sync::OnceLock<Option<DerivNoise>>,
    /// The velocity through the acceleration's band (`Context::v_with_a`, built once).
    pub v_with_a: std::sync::OnceLock<Vec<f64>>,
    /// Samples from the start the candidates are screened on (`crate::SCREEN_WINDOW`, at most
    /// the record's length): the grids of the levels scanned (clip levels, speed levels, the
    /// lowest resonance) and the delayed baseline's rows are taken over them.
    pub window: usize,
    /// The record's training / held-out split (`crate::holdout_mask`): the rows fits within a
    /// column are made on (the delayed baseline, the damping-ratio profile, the device behind
    /// a compliance) are its training rows.
    pub split: usize,
}

/// Rows of a fit on a strided subset of the training samples in motion
/// (`Context::training_rows`), with the columns and the force there: for the delayed
/// baseline (`Context::lag_coefs`: at most `LAG_ROWS` over the record, the columns not
/// delayed — offset, electromagnetic force) and for the damping-ratio profile
/// (`Context::compliance_zeta`: at most `PROFILE_ROWS` over the first `PROFILE_WINDOW`
/// samples, the baseline columns).
#[derive(Debug, Clone, Default)]
pub struct FitRows {
    pub rows: Vec<usize>,
    pub cols: Vec<Vec<f64>>,
    pub f: Vec<f64>,
}

/// Training samples the delayed baseline of `lag` is fitted on (strided).
pub const LAG_ROWS: usize = 20_000;

/// Training samples the damping-ratio profile fits (strided).
pub const PROFILE_ROWS: usize = 4000;
/// Samples from the record's start over which the profile's rows are taken: the profile's
/// resonators run up to its last row, so on a long record they walk this window instead of the
/// whole record (200 s at 1 kHz, at least 50 periods of the lowest mode the compliance grid
/// scans, `MODE_MIN_PERIODS` over a record of up to 20 s; records up to this length are profiled
/// over all their samples).
pub const PROFILE_WINDOW: usize = 200_000;

/// The median of `v` (the upper one of an even count), reordering `v`. `v` is not empty.
pub fn median(v: &mut [f64]) -> f64 {
    let k = v.len() / 2;
    *v.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1
}

/// Half-width (samples) of the window over which `at_rest` looks for motion at a derivative
/// cutoff of fs/20: the span over which the derived velocity averages (`rest_half_window`).
pub const REST_HALF_WINDOW: usize = 20;

/// Half-width (samples) of `at_rest`'s window on a record sampled every `dt`: the span of the
/// derivative filter at its default cutoff (`record::default_cutoff`), fs/fc samples:
/// `REST_HALF_WINDOW` up to 1 kHz, where the cutoff is fs/20, and longer above, where the
/// cutoff stays at its 50 Hz ceiling and the filter averages the velocity over more samples
/// (a fixed count of samples would shrink the window in time, and with it the slowest speed a
/// position quantum resolves over it would rise above the motion's at a high sample rate).
pub fn rest_half_window(dt: f64) -> usize {
    let fs = 1.0 / dt;
    let w = fs / crate::record::default_cutoff(fs);
    if w.is_finite() && w > REST_HALF_WINDOW as f64 {
        // (bounded far above any record's length, so 2·w + 1 cannot overflow)
        w.round().min(1e12) as usize
    } else {
        REST_HALF_WINDOW
    }
}

/// The position's quantum: its smallest non-zero step (0 when the position never moves).
pub fn position_quantum(x: &[f64]) -> f64 {
    let q = x
        .windows(2)
        .map(|p| (p[1] - p[0]).abs())
        .filter(|d| *d > 0.0)
        .fold(f64::MAX, f64::min);
    if q == f64::MAX {
        0.0
    } else {
        q
    }
}

/// The position change `at_rest` takes as no motion: the position quantum
/// (`position_quantum`) plus 3 σ of the position noise, σ from the
/// median absolute second difference (σ·√6 for white noise).
pub fn rest_threshold(x: &[f64]) -> f64 {
    let q = position_quantum(x);
    let mut d2: Vec<f64> = x
        .windows(3)
        .map(|p| (p[2] - 2.0 * p[1] + p[0]).abs())
        .collect();
    let med = median(&mut d2);
    let sigma = med / 0.6745 / 6f64.sqrt();
    q + 3.0 * sigma
}

/// Samples left out of every fit: at rest — the position moves by no more than its own noise
/// over ±`rest_half_window` samples, or the derived speed is below the slowest the sensor
/// resolves over that window (the threshold `rest_threshold`) — or within the window of rest (the zero-phase derivative spreads a start
/// over it) or of the record's ends.
pub fn at_rest(x: &[f64], v: &[f64], dt: f64) -> Vec<bool> {
    let n = x.len();
    let w = rest_half_window(dt);
    if n < 2 * w + 1 {
        return vec![false; n];
    }
    let thr = rest_threshold(x);
    // the slowest speed the sensor resolves: thr over the window
    let v_res = thr / (w as f64 * dt);
    let still: Vec<bool> = (0..n)
        .map(|i| {
            let a = x[i.saturating_sub(w)];
            let b = x[(i + w).min(n - 1)];
            ((x[i] - a).abs() <= thr && (b - x[i]).abs() <= thr) || v[i].abs() < v_res
        })
        .collect();
    // the zero-phase derivative filter spreads a start or a stop over ±w samples: a sample
    // within w of rest has a derived velocity whose sign is not yet (or no longer) the
    // direction of sliding (the friction is still static there), so it is at rest too
    let mut rest = still.clone();
    // the first and last w samples: the zero-phase filter's edges (padding, one-sided
    // differences) make their derived acceleration unreliable
    for i in (0..w).chain(n - w..n) {
        rest[i] = true;
    }
    let mut last_still: Option<usize> = None;
    for i in 0..n {
        if still[i] {
            last_still = Some(i);
        } else if last_still.is_some_and(|j| i - j <= w) {
            rest[i] = true;
        }
    }
    let mut next_still: Option<usize> = None;
    for i in (0..n).rev() {
        if still[i] {
            next_still = Some(i);
        } else if next_still.is_some_and(|j| j - i <= w) {
            rest[i] = true;
        }
    }
    rest
}

/// The Coulomb sign's linear band of a record's velocity `v`: 0.2 % of the peak speed (so
/// derivative noise at rest does not flip the Coulomb term); the diagnosis's `Context::v_eps`
/// and the model fragment's `sign_band_m_s`.
pub fn sign_band(v: &[f64]) -> f64 {
    2e-3 * v.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-12)
}

/// Smoothed sign: exact sign outside ±v_eps, linear inside (`sign_band`).
pub fn sgn(v: f64, v_eps: f64) -> f64 {
    (v / v_eps).clamp(-1.0, 1.0)
}

impl<'a> Context<'a> {
    /// The context of a record screened over its first `crate::screen_window` samples.
    pub fn new(rec: &'a Record) -> Self {
        Self::windowed(rec, crate::screen_window(rec.len()))
    }

    /// The context of a record screened over its first `window` samples (at least 3, at most
    /// the record's length).
    pub fn windowed(rec: &'a Record, window: usize) -> Self {
        Self::windowed_at_rest(rec, window, at_rest(&rec.x, &rec.v, rec.dt()))
    }

    /// `windowed` with the record's samples at rest given (`at_rest` of the record, already
    /// computed by the caller).
    pub fn windowed_at_rest(rec: &'a Record, window: usize, rest: Vec<bool>) -> Self {
        Self::split_at_rest(rec, window, rest, 0)
    }

    /// `windowed_at_rest` on the training / held-out split `split` (`crate::holdout_mask`).
    pub fn split_at_rest(rec: &'a Record, window: usize, rest: Vec<bool>, split: usize) -> Self {
        let vmax = rec.v.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-12);
        let v_eps = sign_band(&rec.v);
        let xmin = rec.x.iter().cloned().fold(f64::MAX, f64::min);
        let xmax = rec.x.iter().cloned().fold(f64::MIN, f64::max);
        let x_mid = 0.5 * (xmin + xmax);
        let x_half = (0.5 * (xmax - xmin)).max(1e-12);
        let mut c = Context {
            rec,
            sgn: rec.v.iter().map(|&v| sgn(v, v_eps)).collect(),
            xn: rec.x.iter().map(|&x| (x - x_mid) / x_half).collect(),
            x_mid,
            x_half,
            v_eps,
            vmax,
            dt: rec.dt(),
            base_pred: Vec::new(),
            lambda_min: 0.0,
            clip_levels: Vec::new(),
            speed_levels: Vec::new(),
            f_motion: 0.0,
            spatial_wavelengths: Vec::new(),
            rest,
            base_th: Vec::new(),
            x_quantum: position_quantum(&rec.x),
            base_resid_rms: 0.0,
            zeta_cache: Default::default(),
            profile_rows: Default::default(),
            lag_rows: Default::default(),
            lag_cache: Default::default(),
            deriv_noise: Default::default(),
            v_with_a: Default::default(),
            window: window.clamp(3.min(rec.len()), rec.len()),
            split,
        };
        c.f_motion = motion_bandwidth(&rec.x, c.dt);
        let stroke = 2.0 * x_half;
        let mut steps: Vec<f64> = rec.x.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
        let med = median(&mut steps);
        c.lambda_min = (stroke / 400.0).max(8.0 * med).min(stroke / 4.0);
        // baseline fit on the whole record gives the force proxy for the pred-based effects
        (c.base_th, c.base_pred) = {
            let cols = base_columns_borrowed(&c);
            let refs: Vec<&[f64]> = cols.iter().map(|(_, v)| &**v).collect();
            let all: Vec<u8> = c
                .rest
                .iter()
                .map(|&r| if r { crate::AT_REST } else { crate::TRAIN })
                .collect();
            let (tr, _) = crate::normals(&refs, &rec.f, &all, 1);
            let th = tr.solve();
            let pred = predict_on(&refs, &th);
            (th, pred)
        };
        let r0: Vec<f64> = rec.f.iter().zip(&c.base_pred).map(|(f, p)| f - p).collect();
        let (ss, nn) = r0
            .iter()
            .zip(&c.rest)
            .filter(|(_, &r)| !r)
            .fold((0.0, 0usize), |(s, k), (e, _)| (s + e * e, k + 1));
        c.base_resid_rms = (ss / nn.max(1) as f64).sqrt();
        c.spatial_wavelengths = crate::report::position_spectrum(rec, &r0)
            .peaks
            .iter()
            .take(4)
            .map(|p| p.wavelength_m)
            .collect();
        // the grids of the scanned levels are those of the samples screened (the screening
        // window, `crate::screen_window`)
        let w = c.window;
        let mut ab: Vec<f64> = c.base_pred[..w].iter().map(|f| f.abs()).collect();
        let last = ab.len() - 1;
        // ascending quantiles: each selection only searches above the previous one
        let mut from = 0;
        c.clip_levels = CLIP_QUANTILES
            .iter()
            .map(|q| {
                let k = ((last as f64 * q) as usize).max(from);
                let v = *ab[from..]
                    .select_nth_unstable_by(k - from, |x, y| x.total_cmp(y))
                    .1;
                from = k;
                v
            })
            .collect();
        c.speed_levels = speed_levels(&rec.v[..w], &c.rest[..w]);
        c
    }
}

pub(crate) fn base_columns(ctx: &Context) -> Vec<(String, Vec<f64>)> {
    base_columns_borrowed(ctx)
        .into_iter()
        .map(|(name, c)| (name.into(), c.into_owned()))
        .collect()
}

/// `base_columns`, those that are the record's own signals borrowed from it.
pub(crate) fn base_columns_borrowed<'c>(
    ctx: &'c Context,
) -> Vec<(&'static str, std::borrow::Cow<'c, [f64]>)> {
    use std::borrow::Cow;
    let r = ctx.rec;
    let mut c = vec![
        ("inertia", Cow::Borrowed(r.a.as_slice())),
        ("viscous", Cow::Borrowed(r.v.as_slice())),
        ("coulomb", Cow::Borrowed(ctx.sgn.as_slice())),
        ("offset", Cow::Owned(vec![1.0; r.len()])),
    ];
    if let Some((name, col, _)) = em_column(r) {
        c.push((name, Cow::Owned(col)));
    }
    c
}

/// Reporting name and unit of a baseline column.
pub fn baseline_term(col: &str) -> (&'static str, &'static str) {
    match col {
        "inertia" => ("inertia", "kg"),
        "viscous" => ("viscous_friction", "N·s/m"),
        "coulomb" => ("coulomb_friction", "N"),
        "offset" => ("force_offset", "N"),
        "em_ke" => ("electromagnetic_force", "V·s/rad (K_e)"),
        "em_force_per_amp" => ("electromagnetic_force", "N/A (i_q gain; no lead given)"),
        "em_ke2" => ("electromagnetic_force", "V²·s²/rad² (K_e²)"),
        _ => ("unknown", ""),
    }
}

/// The electromagnetic-force column of the baseline when the record carries currents or a
/// load resistance (conventions of firmware/src/lib.rs: amplitude-invariant Park transform,
/// per-phase peak K_e, torque T = 3/2·K_e·i_q, axial force on the screw T/l with l the lead
/// in m/rad; the force the device needs from outside then carries −T/l):
/// * `i_q_A`, or phase currents `i_a_A`, `i_b_A` (and `i_c_A`) with `theta_e_rad`: column
///   `−3/2·i_q/l`, coefficient K_e (V·s/rad) — with no `lead_m_per_rev` metadata the column is
///   `−i_q` and its coefficient a force per ampere;
/// * `r_load_ohm` only (an emulated resistor, `i_q = −K_e·ω_m/(R+R_L)`): column
///   `3/2·v/(l²·(R+R_L))`, coefficient K_e², R from `r_s_ohm` metadata (0 when absent). A
///   constant load is exactly collinear with viscous friction and is then left to the
///   viscous term (no column).
///
/// Returns (column name, values, description of the source).
pub fn em_column(r: &Record) -> Option<(&'static str, Vec<f64>, String)> {
    let lead = r.meta.get("lead_m_per_rev").copied().filter(|l| *l > 0.0);
    let l = lead.map(|l| l / std::f64::consts::TAU);
    let iq: Option<(Vec<f64>, &str)> = if let Some(q) = r.extra.get("i_q_A") {
        Some((q.clone(), "i_q_A"))
    } else if let (Some(ia), Some(ib), Some(th)) = (
        r.extra.get("i_a_A"),
        r.extra.get("i_b_A"),
        r.extra.get("theta_e_rad"),
    ) {
        let ic = r.extra.get("i_c_A");
        let q = (0..r.len())
            .map(|i| {
                let al = ia[i];
                let be = match ic {
                    Some(c) => (ib[i] - c[i]) / 3f64.sqrt(),
                    None => (ia[i] + 2.0 * ib[i]) / 3f64.sqrt(),
                };
                let (sn, cs) = th[i].sin_cos();
                -sn * al + cs * be
            })
            .collect();
        Some((q, "Park transform of the phase currents at theta_e_rad"))
    } else {
        None
    };
    if let Some((q, src)) = iq {
        return Some(match l {
            Some(l) => (
                "em_ke",
                q.iter().map(|i| -1.5 * i / l).collect(),
                format!("−3/2·i_q/l from {src}, lead {} m/rev", lead.unwrap()),
            ),
            None => (
                "em_force_per_amp",
                q.iter().map(|i| -i).collect(),
                format!("−i_q from {src} (no lead_m_per_rev: coefficient in N/A)"),
            ),
        });
    }
    let rl = r.extra.get("r_load_ohm")?;
    let l = l?;
    let rs = r.meta.get("r_s_ohm").copied().unwrap_or(0.0);
    let (lo, hi) = rl
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    if lo + rs <= 0.0 || hi - lo <= 1e-9 * hi.abs() {
        return None;
    }
    Some((
        "em_ke2",
        r.v.iter()
            .zip(rl)
            .map(|(v, rl)| 1.5 * v / (l * l * (rs + rl)))
            .collect(),
        format!("3/2·v/(l²·(R+R_L)) from r_load_ohm, R = {rs} Ω"),
    ))
}

/// Baseline columns followed by the columns of each chosen effect.
pub fn build_columns(ctx: &Context, chosen: &[Effect]) -> Vec<(String, Vec<f64>)> {
    let mut cols = base_columns(ctx);
    for e in chosen {
        cols.extend(effect_columns(ctx, e));
    }
    cols
}

/// Σ θ_k col_k.
pub fn predict(cols: &[(String, Vec<f64>)], th: &[f64]) -> Vec<f64> {
    let refs: Vec<&[f64]> = cols.iter().map(|(_, c)| c.as_slice()).collect();
    predict_on(&refs, th)
}

/// Samples `predict_on` sums at a time.
const PREDICT_BLOCK: usize = 2048;

/// `predict` of columns given as slices.
pub(crate) fn predict_on(cols: &[&[f64]], th: &[f64]) -> Vec<f64> {
    let n = cols[0].len();
    let mut p = vec![0.0; n];
    // block by block (each block's sums held in cache while every column is added)
    for (b, pb) in p.chunks_mut(PREDICT_BLOCK).enumerate() {
        let at = b * PREDICT_BLOCK;
        for (c, t) in cols.iter().zip(th) {
            for (pi, ci) in pb.iter_mut().zip(c.get(at..).unwrap_or_default()) {
                *pi += t * ci;
            }
        }
    }
    p
}

#[cfg(test)]
mod tests;
