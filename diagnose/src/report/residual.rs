//! The residual's analysis: whiteness, the spectra over time and over position, a slow change
//! over the record, the breakdown by direction and power flow.

use crate::Record;
use rustfft::num_complex::Complex;

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

/// The most lags the portmanteau test sums (fewer on a record shorter than four times that).
const WHITENESS_LAGS: usize = 20;

pub fn whiteness(r: &[f64]) -> Whiteness {
    let n = r.len();
    let lags = WHITENESS_LAGS.min(n / 4).max(1);
    let mean = r.iter().sum::<f64>() / n as f64;
    let d: Vec<f64> = r.iter().map(|x| x - mean).collect();
    let var: f64 = d.iter().map(|x| x * x).sum::<f64>();
    // the autocovariances at every shift in one pass over the record, each summed over its
    // samples in order
    let mut cs = [0.0f64; WHITENESS_LAGS + 1];
    let cs = &mut cs[..=lags];
    for i in 1..n {
        let di = d[i];
        for (k, c) in cs.iter_mut().enumerate().take(i.min(lags) + 1).skip(1) {
            *c += di * d[i - k];
        }
    }
    let mut q = 0.0;
    let mut lag1 = 0.0;
    for k in 1..=lags {
        let c = cs[k];
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
    let med = crate::effects::median(&mut pw);
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
    let th = crate::solve_sym(&g, &rhs, 3).th;
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
/// direction of motion is then certain and the low-speed friction transition is left out) is
/// averaged into uniform position bins, separately for each direction of motion (a friction
/// ripple changes sign with the direction, a force ripple does not; analysing each direction and
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
    let med = crate::effects::median(&mut steps);
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
/// longer wavelength is a trend (a friction varying along the stroke), and the detrending
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
    let med = crate::effects::median(&mut sorted);
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
