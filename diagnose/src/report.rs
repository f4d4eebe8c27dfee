//! Residual analysis (whiteness, spectrum, breakdowns), the text report and the JSON report.

use super::{Diagnosis, Record};
use rustfft::num_complex::Complex;
use std::fmt::Write as _;

/// Ljung-Box whiteness test on the residual (decimated so that lags cover 1 % of the record).
#[derive(Debug, Clone, Default)]
pub struct Whiteness {
    pub lags: usize,
    pub q: f64,
    /// Chi-square 99 % point for `lags` degrees of freedom (Wilson-Hilferty approximation).
    pub q_crit: f64,
    pub lag1_autocorr: f64,
    pub white: bool,
}

pub fn whiteness(r: &[f64]) -> Whiteness {
    let n = r.len();
    let lags = 20usize.min(n / 4).max(1);
    let mean = r.iter().sum::<f64>() / n as f64;
    let var: f64 = r.iter().map(|x| (x - mean).powi(2)).sum::<f64>();
    let mut q = 0.0;
    let mut lag1 = 0.0;
    for k in 1..=lags {
        let mut c = 0.0;
        for i in k..n {
            c += (r[i] - mean) * (r[i - k] - mean);
        }
        let rho = if var > 0.0 { c / var } else { 0.0 };
        if k == 1 {
            lag1 = rho;
        }
        q += rho * rho / (n - k) as f64;
    }
    q *= n as f64 * (n as f64 + 2.0);
    let h = lags as f64;
    let z = 2.326;
    let q_crit = h * (1.0 - 2.0 / (9.0 * h) + z * (2.0 / (9.0 * h)).sqrt()).powi(3);
    Whiteness {
        lags,
        q,
        q_crit,
        lag1_autocorr: lag1,
        white: q < q_crit,
    }
}

/// A spectral peak of the residual.
#[derive(Debug, Clone)]
pub struct Peak {
    pub freq_hz: f64,
    pub amplitude: f64,
    /// Power over the median power of the spectrum.
    pub ratio: f64,
    pub unexplained: bool,
}

/// A forward FFT of one length (rustfft, planned once) with its buffers: `X_k = Σ x_n·
/// e^(−2πi·kn/N)` of a real sequence.
pub struct RealFft {
    fft: std::sync::Arc<dyn rustfft::Fft<f64>>,
    buf: Vec<Complex<f64>>,
    scratch: Vec<Complex<f64>>,
}

impl RealFft {
    pub fn new(n: usize) -> Self {
        let fft = rustfft::FftPlanner::new().plan_fft_forward(n);
        let scratch = vec![Complex::default(); fft.get_inplace_scratch_len()];
        RealFft {
            fft,
            buf: vec![Complex::default(); n],
            scratch,
        }
    }
    /// The transform of `x` (length n).
    pub fn run(&mut self, x: &[f64]) -> &[Complex<f64>] {
        for (b, &v) in self.buf.iter_mut().zip(x) {
            *b = Complex::new(v, 0.0);
        }
        self.fft
            .process_with_scratch(&mut self.buf, &mut self.scratch);
        &self.buf
    }
}

/// Welch power spectrum (Hann, 50 % overlap, segments of up to 4096 samples). Returns
/// (frequency Hz, amplitude N of a sinusoid at that bin).
pub fn welch(r: &[f64], dt: f64) -> Vec<(f64, f64)> {
    welch_spread(r, dt, usize::MAX)
}

/// The Welch segment's length for a record of `n` samples: 4096, halved while longer than
/// the record, at least 16 (its bins are 1/(segment·dt) apart).
pub fn welch_segment(n: usize) -> usize {
    let mut seg = 4096usize;
    while seg > n && seg > 16 {
        seg /= 2;
    }
    seg
}

/// Welch spectrum averaging at most `max_segments` segments spread evenly over the record
/// (each segment's mean removed).
pub fn welch_spread(r: &[f64], dt: f64, max_segments: usize) -> Vec<(f64, f64)> {
    let seg = welch_segment(r.len());
    let win: Vec<f64> = (0..seg)
        .map(|i| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / seg as f64).cos())
        .collect();
    let wsum: f64 = win.iter().sum();
    let mut p = vec![0.0; seg / 2];
    let total = if r.len() >= seg {
        (r.len() - seg) / (seg / 2) + 1
    } else {
        0
    };
    let used = total.min(max_segments.max(1));
    let mut re = vec![0.0; seg];
    let mut fft = RealFft::new(seg);
    for j in 0..used {
        let s = if used > 1 {
            (j * (total - 1) / (used - 1)) * (seg / 2)
        } else {
            0
        };
        let m = r[s..s + seg].iter().sum::<f64>() / seg as f64;
        for i in 0..seg {
            re[i] = (r[s + i] - m) * win[i];
        }
        let x = fft.run(&re);
        for k in 0..seg / 2 {
            p[k] += x[k].norm_sqr();
        }
    }
    (0..seg / 2)
        .map(|k| {
            (
                k as f64 / (seg as f64 * dt),
                2.0 * (p[k] / used.max(1) as f64).sqrt() / wsum,
            )
        })
        .collect()
}

/// Local maxima of the residual spectrum standing 30x above its median power (white noise
/// averaged over Welch segments stays far below: its maximum over 2048 bins is about
/// ln(2048) ≈ 8 times the mean for a single segment, less when averaged). A peak is
/// `unexplained` when its amplitude is also at least 0.5 % of the force rms... applied by the
/// caller through `rms_f`.
pub fn spectral_peaks(r: &[f64], dt: f64) -> Vec<Peak> {
    let sp = welch(r, dt);
    if sp.len() < 8 {
        return vec![];
    }
    let mut pw: Vec<f64> = sp.iter().skip(1).map(|s| s.1 * s.1).collect();
    let med = super::effects::median(&mut pw);
    let rms = (r.iter().map(|x| x * x).sum::<f64>() / r.len() as f64).sqrt();
    let mut peaks = Vec::new();
    for i in 2..sp.len() - 1 {
        let p = sp[i].1 * sp[i].1;
        if p > sp[i - 1].1.powi(2) && p >= sp[i + 1].1.powi(2) && p > 30.0 * med {
            peaks.push(Peak {
                freq_hz: sp[i].0,
                amplitude: sp[i].1,
                ratio: p / med.max(1e-300),
                unexplained: sp[i].1 > 0.2 * rms,
            });
        }
    }
    peaks.sort_by(|a, b| b.ratio.total_cmp(&a.ratio));
    peaks.truncate(8);
    peaks
}

/// A slow change of the residual's mean over the record (a drifting offset or gain, a
/// temperature): the residual against time, by blocks.
#[derive(Debug, Clone, PartialEq)]
pub struct SlowChange {
    /// Block centres (s from the record's start) and the residual mean in each (N).
    pub blocks: Vec<(f64, f64)>,
    /// Slope of the trend at the record's middle (N/s) and the change of the trend from the
    /// record's start to its end (N).
    pub slope_n_per_s: f64,
    pub change_n: f64,
    /// Block whose mean departs most from the record's mean: its start and end (s) and the
    /// departure (N).
    pub worst_from_s: f64,
    pub worst_to_s: f64,
    pub worst_n: f64,
    /// F statistic of the trend against the block means' scatter about it, and its bound.
    pub f_stat: f64,
    pub f_bound: f64,
    /// Power of the trend over the residual power.
    pub power_fraction: f64,
}

/// Blocks the record is cut into for the slow-change check.
pub const SLOW_BLOCKS: usize = 10;

/// 99.9 % points of the F distribution with (2, d) degrees of freedom, d = 2 … 7 (tables;
/// e.g. F(2, 7) = 21.69).
const F2_999: [f64; 6] = [999.0, 148.5, 61.25, 37.12, 27.00, 21.69];

/// The residual's mean against time (samples where `skip` is true, at rest, left out): the
/// record is cut into `SLOW_BLOCKS` consecutive blocks and a trend (Legendre polynomials of
/// degree ≤ 2 in time) is fitted to the block means. The residual's mean changes slowly
/// over the record when the trend stands out of the block means' own scatter about it (F
/// test with (2, B − 3) degrees of freedom at 99.9 %: the scatter holds whatever the motion
/// puts into a block's mean, a move in one direction, a dwell, so a change locked to the
/// motion is not taken for a drift) and the trend carries at least `min_fraction` of the
/// residual power (the margin a catalogue effect must bring). None when it does not, or when
/// fewer than 5 blocks hold samples in motion.
pub fn slow_change(t: &[f64], r: &[f64], skip: &[bool], min_fraction: f64) -> Option<SlowChange> {
    let n = r.len().min(t.len()).min(skip.len());
    if n < SLOW_BLOCKS * 8 {
        return None;
    }
    let (t0, t1) = (t[0], t[n - 1]);
    let span = (t1 - t0).max(1e-300);
    // (centre s, mean N, count, from s, to s)
    let mut blocks = Vec::new();
    for b in 0..SLOW_BLOCKS {
        let (lo, hi) = (b * n / SLOW_BLOCKS, (b + 1) * n / SLOW_BLOCKS);
        let (sum, k) = (lo..hi)
            .filter(|&i| !skip[i])
            .fold((0.0, 0usize), |(s, k), i| (s + r[i], k + 1));
        // a block needs samples in motion for its mean to mean anything
        if k >= 8 {
            blocks.push((
                0.5 * (t[lo] + t[hi - 1]) - t0,
                sum / k as f64,
                k,
                t[lo] - t0,
                t[hi - 1] - t0,
            ));
        }
    }
    if blocks.len() < 5 {
        return None;
    }
    // least squares of the block means on 1, P1(τ), P2(τ), τ = time mapped to [−1, 1]
    let tau = |c: f64| 2.0 * c / span - 1.0;
    let row = |c: f64| {
        let x = tau(c);
        [1.0, x, 1.5 * x * x - 0.5]
    };
    let mut g = [0.0; 9];
    let mut rhs = [0.0; 3];
    for b in &blocks {
        let z = row(b.0);
        for i in 0..3 {
            rhs[i] += z[i] * b.1;
            for j in 0..3 {
                g[i * 3 + j] += z[i] * z[j];
            }
        }
    }
    let th = super::solve_sym(&g, &rhs, 3).th;
    let fit = |c: f64| {
        let z = row(c);
        th[0] * z[0] + th[1] * z[1] + th[2] * z[2]
    };
    let nb = blocks.len();
    let mean_b = blocks.iter().map(|b| b.1).sum::<f64>() / nb as f64;
    let ss_trend: f64 = blocks.iter().map(|b| (fit(b.0) - mean_b).powi(2)).sum();
    let ss_res: f64 = blocks.iter().map(|b| (b.1 - fit(b.0)).powi(2)).sum();
    let f_stat = (ss_trend / 2.0) / (ss_res / (nb - 3) as f64).max(1e-300);
    let f_bound = F2_999[(nb - 3).min(7) - 2];
    // the trend's power over the samples in motion against the residual power
    let cnt: f64 = blocks.iter().map(|b| b.2 as f64).sum();
    let mean_c = blocks.iter().map(|b| b.1 * b.2 as f64).sum::<f64>() / cnt;
    let p_trend = blocks
        .iter()
        .map(|b| (fit(b.0) - mean_c).powi(2) * b.2 as f64)
        .sum::<f64>()
        / cnt;
    let (ss, k) = (0..n)
        .filter(|&i| !skip[i])
        .fold((0.0, 0usize), |(s, k), i| (s + r[i] * r[i], k + 1));
    let p_all = ss / k.max(1) as f64;
    let power_fraction = if p_all > 0.0 { p_trend / p_all } else { 0.0 };
    if !(f_stat >= f_bound && power_fraction >= min_fraction) {
        return None;
    }
    // where it shows: the block furthest from the mean
    let worst = blocks
        .iter()
        .max_by(|a, b| (a.1 - mean_c).abs().total_cmp(&(b.1 - mean_c).abs()))?;
    Some(SlowChange {
        blocks: blocks.iter().map(|b| (b.0, b.1)).collect(),
        // d/dt of th1·τ at the middle (P2' = 3τ = 0 there)
        slope_n_per_s: th[1] * 2.0 / span,
        change_n: 2.0 * th[1],
        worst_from_s: worst.3,
        worst_to_s: worst.4,
        worst_n: worst.1 - mean_c,
        f_stat,
        f_bound,
        power_fraction,
    })
}

/// A peak of the residual's spectrum over position.
#[derive(Debug, Clone)]
pub struct SpatialPeak {
    pub wavelength_m: f64,
    /// Spatial frequency, cycles per metre (1/wavelength).
    pub cycles_per_m: f64,
    /// Amplitude (N) of a sinusoid in position at this wavelength: rms over the two directions
    /// of motion of the per-direction amplitude.
    pub amplitude: f64,
    /// Power over the median power of the position spectrum.
    pub ratio: f64,
    /// Screw length the wavelength matches within the spatial resolution, if any.
    pub matches: String,
    pub unexplained: bool,
}

/// The residual's spectrum over position (see `position_spectrum`).
#[derive(Debug, Clone, Default)]
pub struct PositionSpectrum {
    /// Number of position bins over the span (a power of two), and their width (m).
    pub bins: usize,
    pub bin_m: f64,
    /// Span covered by the binned samples (m); the spatial resolution is 1/span cycles/m.
    pub span_m: f64,
    /// Speed threshold: only samples with |v| above it are binned (m/s).
    pub v_min: f64,
    /// Directions of motion analysed (0, 1 or 2).
    pub directions: usize,
    /// (spatial frequency cycles/m, amplitude N), k = 1 … bins/2.
    pub spectrum: Vec<(f64, f64)>,
    pub peaks: Vec<SpatialPeak>,
}

/// Spectrum of the residual `r` over position. The record is sampled uniformly in time, not
/// in x, so the residual of the samples moving faster than 5 % of the peak speed (the
/// direction of motion is then certain and the Coulomb/Stribeck transition is left out) is
/// averaged into uniform position bins, separately for each direction of motion (a friction
/// ripple changes sign with the direction, cogging does not; analysing each direction and
/// adding the powers catches both without cancellation). Bin width: the span over a power of
/// two, at least 2 median per-sample travels of the moving samples, so that a pass at the
/// median speed puts a sample in every bin and the bins stay far wider than the encoder
/// quantum; at most 4096 bins. Empty bins are filled by linear interpolation between the
/// nearest filled ones (held at the ends); a direction with fewer than half its bins filled
/// is skipped. Each direction's bin means are detrended (least-squares line), Hann-windowed
/// and transformed ([`RealFft`]); amplitude of a sinusoid = 2|X_k|/Σw as in `welch`. One pass over
/// the record plus O(bins·log bins).
pub fn position_spectrum(rec: &Record, r: &[f64]) -> PositionSpectrum {
    let n = rec.len().min(r.len());
    let dt = rec.dt();
    let vmax = rec.v[..n].iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let v_min = 0.05 * vmax;
    let mut out = PositionSpectrum {
        v_min,
        ..Default::default()
    };
    let (mut x0, mut x1) = (f64::MAX, f64::MIN);
    let mut moving = 0usize;
    for i in 0..n {
        if rec.v[i].abs() > v_min {
            x0 = x0.min(rec.x[i]);
            x1 = x1.max(rec.x[i]);
            moving += 1;
        }
    }
    if moving < 64 || x1 <= x0 || dt.is_nan() || dt <= 0.0 {
        return out;
    }
    // median travel per sample of the moving samples (strided to at most ~100k samples)
    let stride = (n / 100_000).max(1);
    let mut steps: Vec<f64> = (0..n)
        .step_by(stride)
        .map(|i| rec.v[i].abs())
        .filter(|&v| v > v_min)
        .map(|v| v * dt)
        .collect();
    if steps.is_empty() {
        return out;
    }
    let med = super::effects::median(&mut steps);
    let span = x1 - x0;
    let fit = (span / (2.0 * med)).max(1.0);
    let mut nb = 16usize;
    while nb * 2 <= 4096 && (nb * 2) as f64 <= fit {
        nb *= 2;
    }
    let h = span / nb as f64;
    let mut sum = [vec![0.0; nb], vec![0.0; nb]];
    let mut cnt = [vec![0u32; nb], vec![0u32; nb]];
    let mut r2 = 0.0;
    for i in 0..n {
        let v = rec.v[i];
        if v.abs() > v_min {
            let b = (((rec.x[i] - x0) / h) as usize).min(nb - 1);
            let d = usize::from(v < 0.0);
            sum[d][b] += r[i];
            cnt[d][b] += 1;
            r2 += r[i] * r[i];
        }
    }
    let rms = (r2 / moving as f64).sqrt();
    let win: Vec<f64> = (0..nb)
        .map(|i| 0.5 - 0.5 * (std::f64::consts::TAU * i as f64 / nb as f64).cos())
        .collect();
    let wsum: f64 = win.iter().sum();
    let mut pw = vec![0.0; nb / 2 + 1];
    let mut dirs = 0usize;
    let mut re = vec![0.0; nb];
    let mut fft = RealFft::new(nb);
    for d in 0..2 {
        let filled: Vec<usize> = (0..nb).filter(|&b| cnt[d][b] > 0).collect();
        if filled.len() * 2 < nb {
            continue;
        }
        let mean = |b: usize| sum[d][b] / cnt[d][b] as f64;
        // fill: hold before the first and after the last filled bin, interpolate between
        for b in 0..=filled[0] {
            re[b] = mean(filled[0]);
        }
        for w in filled.windows(2) {
            let (a, c) = (w[0], w[1]);
            let (ya, yc) = (mean(a), mean(c));
            for b in a..=c {
                re[b] = ya + (yc - ya) * (b - a) as f64 / (c - a) as f64;
            }
        }
        let last = *filled.last().unwrap();
        for b in last..nb {
            re[b] = mean(last);
        }
        // least-squares line removed
        let xm = (nb as f64 - 1.0) / 2.0;
        let ym = re.iter().sum::<f64>() / nb as f64;
        let (mut sxy, mut sxx) = (0.0, 0.0);
        for (b, y) in re.iter().enumerate() {
            let xb = b as f64 - xm;
            sxy += xb * (y - ym);
            sxx += xb * xb;
        }
        let slope = sxy / sxx;
        for b in 0..nb {
            re[b] = (re[b] - ym - slope * (b as f64 - xm)) * win[b];
        }
        let x = fft.run(&re);
        for k in 1..=nb / 2 {
            let a = 2.0 * x[k].norm() / wsum;
            pw[k] += a * a;
        }
        dirs += 1;
    }
    out.bins = nb;
    out.bin_m = h;
    out.span_m = span;
    out.directions = dirs;
    if dirs == 0 {
        return out;
    }
    for p in pw.iter_mut() {
        *p /= dirs as f64;
    }
    out.spectrum = (1..=nb / 2)
        .map(|k| (k as f64 / span, pw[k].sqrt()))
        .collect();
    out.peaks = spatial_peaks(&pw, span, rms, &rec.meta);
    out
}

/// Local maxima of the position power spectrum `pw` (index k = k cycles over the span)
/// standing 30× above its median power, at k ≥ 3 (at least three periods in the span: a
/// longer wavelength is a trend, `position_dependent_friction`'s domain, and the detrending
/// and the window's main lobe reach k ≤ 2). Noise alone: a direction's bin means, if
/// independent, give an exponentially distributed power per bin whose median is ln 2 of its
/// mean, so P(power > 30·median) = 2^-30 ≈ 1e-9 per bin (less with two directions added),
/// about 2e-6 over 2048 bins; what passes is structure, not noise (the criterion of the time
/// spectrum). A peak is `unexplained` when its amplitude is also above 20 % of the moving
/// samples' residual rms (a sinusoid of that amplitude carries ≥ 2 % of the residual power).
/// The peak's spatial frequency is interpolated between bins (log-parabolic on the Hann main
/// lobe, which is close to Gaussian: on the synthetic tests within 0.5 % of the hidden
/// wavelength); its wavelength is matched to the lead (and half, a third of it) and the ball
/// diameter within 3 %, the tolerance the catalogue's `describe` uses.
fn spatial_peaks(
    pw: &[f64],
    span: f64,
    rms: f64,
    meta: &std::collections::BTreeMap<String, f64>,
) -> Vec<SpatialPeak> {
    let top = pw.len() - 1;
    if top < 8 {
        return vec![];
    }
    let mut sorted: Vec<f64> = pw[1..].to_vec();
    let med = super::effects::median(&mut sorted);
    let mut peaks = Vec::new();
    for k in 3..top {
        let p = pw[k];
        if p > pw[k - 1] && p >= pw[k + 1] && p > 30.0 * med {
            // Gaussian (log-parabolic) interpolation between the three bins: the Hann main
            // lobe is close to a Gaussian, so the offset is a small fraction of a bin.
            let (l0, l1, l2) = (
                pw[k - 1].max(1e-300).ln(),
                p.ln(),
                pw[k + 1].max(1e-300).ln(),
            );
            let den = l0 - 2.0 * l1 + l2;
            let delta = if den < 0.0 {
                (0.5 * (l0 - l2) / den).clamp(-0.5, 0.5)
            } else {
                0.0
            };
            let nu = (k as f64 + delta) / span;
            let mut matches = String::new();
            for (key, what) in [
                ("lead_m_per_rev", "one screw revolution"),
                ("ball_diameter_m", "ball pass"),
            ] {
                if let Some(&l) = meta.get(key).filter(|l| **l > 0.0) {
                    for (mult, lbl) in [(1.0, ""), (0.5, "half of "), (1.0 / 3.0, "a third of ")] {
                        if matches.is_empty() && (nu * l * mult - 1.0).abs() < 0.03 {
                            matches = format!("{lbl}{what} ({key} = {l})");
                        }
                    }
                }
            }
            peaks.push(SpatialPeak {
                wavelength_m: 1.0 / nu,
                cycles_per_m: nu,
                amplitude: p.sqrt(),
                ratio: p / med.max(1e-300),
                matches,
                unexplained: p.sqrt() > 0.2 * rms,
            });
        }
    }
    peaks.sort_by(|a, b| b.ratio.total_cmp(&a.ratio));
    peaks.truncate(8);
    peaks
}

/// Residual rms by direction of motion and power quadrant.
pub fn breakdown(rec: &Record, r: &[f64]) -> Vec<(String, f64, usize)> {
    let mut acc = [(0.0, 0usize); 4];
    let labels = [
        "v>0, f·v>0 (driven)",
        "v>0, f·v<0 (driving)",
        "v<0, f·v>0 (driven)",
        "v<0, f·v<0 (driving)",
    ];
    for i in 0..rec.len() {
        let d =
            if rec.v[i] >= 0.0 { 0 } else { 2 } + if rec.f[i] * rec.v[i] >= 0.0 { 0 } else { 1 };
        acc[d].0 += r[i] * r[i];
        acc[d].1 += 1;
    }
    labels
        .iter()
        .zip(acc)
        .map(|(l, (s, c))| (l.to_string(), (s / c.max(1) as f64).sqrt(), c))
        .collect()
}

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
            format!(
                "{} ({}) takes away {:.2} points",
                f.effect,
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
            "  {:<18} {:>12.5} {:<6} held-out error without it {:6.2} % {}",
            b.effect,
            b.value,
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
    let _ = writeln!(s, "Whiteness (Ljung-Box, {} lags): Q = {:.1}, 99 % bound {:.1}, lag-1 autocorrelation {:.3}: {}", w.lags, w.q, w.q_crit, w.lag1_autocorr, if w.white { "white" } else { "coloured" });
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
/// docs/diagnose.md, "Output".
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
mod tests {
    use super::*;

    /// Seeded Gaussian noise (Box-Muller on a xorshift), shared by nothing under test.
    fn gauss(n: usize, seed: u64) -> Vec<f64> {
        let mut st = seed | 1;
        let mut u = || {
            st ^= st << 13;
            st ^= st >> 7;
            st ^= st << 17;
            ((st >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        (0..n)
            .map(|_| (-2.0 * u().ln()).sqrt() * (std::f64::consts::TAU * u()).cos())
            .collect()
    }

    /// A linear drift of D = 20 N over 12 s under white noise σ = 1 N (1 kHz): found, and the
    /// change over the record is D within 3 standard errors of the least-squares slope of the
    /// 10 block means (closed form: se(change) = 2·σ_b/√Σ τ_b², σ_b = σ/√1200, τ_b =
    /// ±0.1 … ±0.9, Σ τ_b² = 3.3: 0.032 N, so the bound is 0.1 N, 0.5 % of D: a 2 % error in
    /// the change fails it). The samples marked at rest
    /// (here every 7th, carrying a large value that must be ignored) are left out.
    #[test]
    fn slow_change_finds_a_drift_and_its_size() {
        let n = 12_000;
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 1e-3).collect();
        let skip: Vec<bool> = (0..n).map(|i| i % 7 == 0).collect();
        let d = 20.0;
        let e = gauss(n, 42);
        let r: Vec<f64> = (0..n)
            .map(|i| {
                if skip[i] {
                    1e3
                } else {
                    d * (t[i] / t[n - 1] - 0.5) + e[i]
                }
            })
            .collect();
        let sc = slow_change(&t, &r, &skip, 0.02).expect("a 20 N drift under 1 N noise");
        assert!((sc.change_n - d).abs() < 0.1, "{sc:?}");
        assert!(
            (sc.slope_n_per_s - d / t[n - 1]).abs() < 0.1 / 12.0,
            "{sc:?}"
        );
        // the departure is largest at an end of the record
        assert!(sc.worst_from_s < 1.3 || sc.worst_to_s > 10.7, "{sc:?}");
        // the same drift reversed: the sign follows
        let rn: Vec<f64> = r.iter().map(|v| -v).collect();
        let sn = slow_change(&t, &rn, &skip, 0.02).expect("reversed");
        assert!((sn.change_n + d).abs() < 0.1, "{sn:?}");
    }

    /// No slow change: white noise; a force locked to the motion that leaves one block's mean
    /// far from the others (a single 5 N departure in any one block: the trend over 10 blocks
    /// then has F ≤ 4.75 against the scatter, closed form, below the bound 21.7); a 0.5 Hz
    /// sinusoid of 3 N (the motion's band). A drift too small to carry 2 % of the residual
    /// power (0.2 N under 1 N noise: 0.3 %) is not reported either.
    #[test]
    fn slow_change_ignores_noise_motion_locked_blocks_and_small_drifts() {
        let n = 12_000;
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 1e-3).collect();
        let skip = vec![false; n];
        for seed in 1..=20u64 {
            let e = gauss(n, seed);
            assert_eq!(slow_change(&t, &e, &skip, 0.02), None, "noise, seed {seed}");
        }
        let e = gauss(n, 7);
        for blk in 0..SLOW_BLOCKS {
            let r: Vec<f64> = (0..n)
                .map(|i| e[i] + if i * SLOW_BLOCKS / n == blk { 5.0 } else { 0.0 })
                .collect();
            assert_eq!(slow_change(&t, &r, &skip, 0.02), None, "block {blk}");
        }
        let r: Vec<f64> = (0..n)
            .map(|i| e[i] + 3.0 * (std::f64::consts::TAU * 0.5 * t[i]).sin())
            .collect();
        assert_eq!(slow_change(&t, &r, &skip, 0.02), None, "0.5 Hz");
        let r: Vec<f64> = (0..n).map(|i| e[i] + 0.2 * (t[i] / 12.0 - 0.5)).collect();
        assert_eq!(slow_change(&t, &r, &skip, 0.02), None, "0.2 N drift");
    }

    /// rustfft against the direct DFT `X_k = Σ x_n·e^(−2πi·kn/N)` (shares nothing with it),
    /// on a power of two and on an odd length: within 1e-12 of Σ|x| (measured ≈ 1e-15,
    /// rounding of N log N against N terms).
    #[test]
    fn fft_matches_direct_dft() {
        let mut st = 0x1234_5678_9abc_def1u64;
        let mut rnd = || {
            st ^= st << 13;
            st ^= st >> 7;
            st ^= st << 17;
            (st >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for n in [256usize, 243] {
            let x: Vec<f64> = (0..n).map(|_| rnd()).collect();
            let l1: f64 = x.iter().map(|v| v.abs()).sum();
            let mut f = RealFft::new(n);
            let got = f.run(&x).to_vec();
            let mut worst = 0.0f64;
            for (k, g) in got.iter().enumerate() {
                let (mut re, mut im) = (0.0, 0.0);
                for (j, v) in x.iter().enumerate() {
                    let ph = -std::f64::consts::TAU * ((k * j) % n) as f64 / n as f64;
                    re += v * ph.cos();
                    im += v * ph.sin();
                }
                worst = worst.max((g.re - re).hypot(g.im - im));
            }
            assert!(worst < 1e-12 * l1, "n {n}: {worst:e} vs Σ|x| {l1}");
        }
    }
}

#[cfg(test)]
mod summary_tests {
    use super::*;
    use crate::{CrossCheck, Finding};

    /// Four significant digits whatever the magnitude (closed forms).
    #[test]
    fn parameters_keep_their_significant_digits() {
        for (v, s) in [
            (5e-6, "5.000e-6"),
            (-0.5, "-0.5000"),
            (0.001, "0.001000"),
            (123.456, "123.5"),
            (12345.0, "12345"),
            (123456.0, "1.235e5"),
            (0.0, "0"),
        ] {
            assert_eq!(sig(v), s, "{v}");
        }
    }

    fn finding(effect: &str, after: f64) -> Finding {
        Finding {
            effect: effect.into(),
            parameters: vec![("x_m".into(), 5e-6)],
            holdout_rel_error_after: after,
            note: "where it shows".into(),
            ..Finding::default()
        }
    }

    /// The summary names the causes by what they explain (not in the order the selection
    /// added them), their size, the gain, what is outside the catalogue, what the record
    /// cannot identify and what the second record contradicts.
    #[test]
    fn the_summary_orders_causes_by_what_they_explain() {
        let d = Diagnosis {
            residual: vec![0.0; 10],
            baseline_holdout_rel_error: 0.10,
            baseline_terms: vec![crate::BaselineTerm {
                effect: "viscous_friction".into(),
                value: 1.0,
                unit: "N·s/m".into(),
                holdout_rel_error_without: 0.1,
                significant: false,
            }],
            // `lag` added first takes 1 point, `backlash` then 6
            findings: vec![
                finding("lag", 0.09),
                finding("backlash", 0.03),
                finding("unexplained", 0.03),
            ],
            final_holdout_rel_error: 0.03,
            cross: Some(CrossCheck {
                baseline_rel_error: 0.1,
                final_rel_error: 0.05,
                after_each: vec![("lag".into(), 0.11), ("backlash".into(), 0.05)],
                worsens: vec![true, false],
            }),
            ..Diagnosis::default()
        };
        let s = summary(&d);
        println!("{s}");
        let (b, l) = (s.find("backlash (").unwrap(), s.find("lag (").unwrap());
        assert!(b < l, "{s}");
        assert!(
            s.contains("backlash (x_m = 5.000e-6) takes away 6.00 points"),
            "{s}"
        );
        assert!(
            s.contains("lag (x_m = 5.000e-6) takes away 1.00 points"),
            "{s}"
        );
        assert!(
            s.contains("held-out error is 3.00 % (a gain of 7.00 points)"),
            "{s}"
        );
        assert!(s.contains("Outside the catalogue (no effect named): where it shows."));
        assert!(s.contains("does not identify viscous_friction"), "{s}");
        assert!(s.contains("lag makes it worse"), "{s}");
    }
}
