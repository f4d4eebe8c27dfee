//! Measured-record reader: CSV with a header row, `#` comments carrying `# key = value`
//! metadata, required columns `t_s`, `x_m`, `f_N`; velocity and acceleration derived with a
//! zero-phase method when absent (forward-backward 2nd-order Butterworth low-pass of the
//! position, then central differences — the EMPS benchmark's own method).

use std::collections::BTreeMap;
use std::fmt;

/// A parse or validation error, naming the line (1-based) where it was found when there is one.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordError {
    pub line: Option<usize>,
    pub msg: String,
}

impl fmt::Display for RecordError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(l) => write!(f, "line {l}: {}", self.msg),
            None => write!(f, "{}", self.msg),
        }
    }
}
impl std::error::Error for RecordError {}

fn err(line: Option<usize>, msg: impl Into<String>) -> RecordError {
    RecordError {
        line,
        msg: msg.into(),
    }
}

/// One measured record, all SI.
#[derive(Debug, Clone, Default)]
pub struct Record {
    pub t: Vec<f64>,
    pub x: Vec<f64>,
    pub f: Vec<f64>,
    pub v: Vec<f64>,
    pub a: Vec<f64>,
    /// Metadata from `# key = value` comment lines whose value is a number.
    pub meta: BTreeMap<String, f64>,
    /// Optional columns kept by name (e.g. `x_ref_m`, `i_q_A`).
    pub extra: BTreeMap<String, Vec<f64>>,
    /// How v and a were obtained (for the report).
    pub derivative_method: String,
}

impl Record {
    pub fn len(&self) -> usize {
        self.t.len()
    }
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }
    /// Mean sampling period.
    pub fn dt(&self) -> f64 {
        if self.len() < 2 {
            return 0.0;
        }
        (self.t[self.len() - 1] - self.t[0]) / (self.len() - 1) as f64
    }
}

/// Metadata key under which the reader records the cutoff (Hz) of the low-pass the
/// acceleration was derived through (absent when `a_m_s2` is measured).
pub const DERIVATIVE_CUTOFF_KEY: &str = "derivative_cutoff_hz";

/// The pieces of `s` between the occurrences of the ASCII byte `sep` (as `str::split` with
/// that character), found by a plain scan of the bytes: the lines and fields of a record are
/// short, and a scan per piece costs less than a searcher's set-up.
fn split_byte(s: &str, sep: u8) -> impl Iterator<Item = &str> {
    let mut rest = Some(s);
    std::iter::from_fn(move || {
        let r = rest?;
        match r.bytes().position(|b| b == sep) {
            Some(p) => {
                rest = Some(&r[p + 1..]);
                Some(&r[..p])
            }
            None => {
                rest = None;
                Some(r)
            }
        }
    })
}

/// Parse a record from CSV text. `cutoff_hz`: low-pass cutoff for derived v and a
/// (None = `default_cutoff`).
pub fn parse_csv(text: &str, cutoff_hz: Option<f64>) -> Result<Record, RecordError> {
    let mut meta = BTreeMap::new();
    let mut header: Option<Vec<String>> = None;
    let mut cols: Vec<Vec<f64>> = Vec::new();
    let mut header_line = 0;
    let mut first_data_line = Vec::new();
    // lines and fields are split on their bytes (`split_byte`: a newline and a comma are
    // single-byte characters, so every piece is a `str`); a line's trailing `\r` goes with
    // its trim
    for (ln0, raw) in split_byte(text, b'\n').enumerate() {
        let ln = ln0 + 1;
        let line = raw.trim();
        if line.is_empty() {
            continue;
        }
        if let Some(c) = line.strip_prefix('#') {
            if let Some((k, v)) = c.split_once('=') {
                if let Ok(val) = v.trim().parse::<f64>() {
                    meta.insert(k.trim().to_string(), val);
                }
            }
            continue;
        }
        match &header {
            None => {
                let h: Vec<String> = line.split(',').map(|s| s.trim().to_string()).collect();
                for req in ["t_s", "x_m", "f_N"] {
                    if !h.iter().any(|c| c == req) {
                        return Err(err(
                            Some(ln),
                            format!(
                                "header lacks required column `{req}` (found: {})",
                                h.join(",")
                            ),
                        ));
                    }
                }
                // one row per remaining line at most, and a field takes two bytes at least
                // (the reservation stays within 4× the text): no reallocation while reading
                let lines = text.bytes().filter(|&b| b == b'\n').count() + 1;
                let rows = lines.min(text.len() / (2 * h.len()) + 1);
                cols = (0..h.len()).map(|_| Vec::with_capacity(rows)).collect();
                first_data_line.reserve(rows);
                header = Some(h);
                header_line = ln;
            }
            Some(h) => {
                let mut nf = 0;
                for (j, fld) in split_byte(line, b',').enumerate() {
                    nf = j + 1;
                    if j >= h.len() {
                        break;
                    }
                    let val: f64 = fld.trim().parse().map_err(|_| {
                        err(
                            Some(ln),
                            format!("column `{}`: `{}` is not a number", h[j], fld.trim()),
                        )
                    })?;
                    if !val.is_finite() {
                        return Err(err(
                            Some(ln),
                            format!("column `{}` is not finite ({val})", h[j]),
                        ));
                    }
                    cols[j].push(val);
                }
                if nf != h.len() {
                    let nf = line.split(',').count();
                    return Err(err(
                        Some(ln),
                        format!("{nf} fields, header has {}", h.len()),
                    ));
                }
                first_data_line.push(ln);
            }
        }
    }
    let h = header.ok_or_else(|| err(None, "no header row (expected t_s,x_m,f_N,...)"))?;
    let n = cols[0].len();
    if n < 3 {
        return Err(err(
            Some(header_line),
            format!("{n} data row(s): at least 3 samples are needed"),
        ));
    }
    let idx = |name: &str| h.iter().position(|c| c == name);
    // the columns are moved out (each named column is taken once)
    let mut take = |name: &str| idx(name).map(|j| std::mem::take(&mut cols[j]));
    let (Some(t), Some(x), Some(f)) = (take("t_s"), take("x_m"), take("f_N")) else {
        return Err(err(Some(header_line), "header lacks a required column"));
    };
    for i in 1..n {
        if t[i] <= t[i - 1] {
            return Err(err(
                Some(first_data_line[i]),
                format!("time not increasing ({} after {})", t[i], t[i - 1]),
            ));
        }
    }
    let dt = (t[n - 1] - t[0]) / (n - 1) as f64;
    if !(1e-7..=1.0).contains(&dt) {
        return Err(err(
            None,
            format!("mean sample period {dt} s: t_s must be in seconds (1e-7..1 s)"),
        ));
    }
    for i in 0..n {
        if (t[i] - t[i.saturating_sub(1)]) > 20.0 * dt && i > 0 {
            return Err(err(
                Some(first_data_line[i]),
                format!("time gap of {} s (mean period {dt} s)", t[i] - t[i - 1]),
            ));
        }
        if x[i].abs() > 10.0 {
            return Err(err(
                Some(first_data_line[i]),
                format!(
                    "x_m = {} m: displacement over 10 m, units probably not metres",
                    x[i]
                ),
            ));
        }
        if f[i].abs() > 1e7 {
            return Err(err(
                Some(first_data_line[i]),
                format!("f_N = {} N: implausible force, check units", f[i]),
            ));
        }
    }
    let xr =
        x.iter().cloned().fold(f64::MIN, f64::max) - x.iter().cloned().fold(f64::MAX, f64::min);
    if xr == 0.0 {
        return Err(err(None, "x_m never changes: no motion to diagnose"));
    }
    let fs = 1.0 / dt;
    let fc = cutoff_hz.unwrap_or_else(|| default_cutoff(fs));
    check_cutoff(fc, fs)?;
    let (v, a, method) = match (idx("v_m_s"), idx("a_m_s2")) {
        (Some(iv), Some(ia)) => (
            std::mem::take(&mut cols[iv]),
            std::mem::take(&mut cols[ia]),
            "measured v_m_s and a_m_s2".to_string(),
        ),
        (Some(iv), None) => {
            let vf = filtfilt(&cols[iv], fc, fs);
            let a = central_diff(&vf, dt);
            (std::mem::take(&mut cols[iv]), a, format!("measured v_m_s; a = central difference of zero-phase Butterworth-2 ({fc:.3} Hz, forward-backward) v"))
        }
        _ => {
            let (v, a, fc_v) = derive_from_x(&x, fc, None, dt);
            meta.insert(VELOCITY_CUTOFF_KEY.to_string(), fc_v);
            (v, a, derived_method(fc, fc_v))
        }
    };
    if idx("a_m_s2").is_none() {
        // the acceleration is derived through the low-pass: its cutoff bounds the band in
        // which it follows the motion (effects::grid keeps a resonance well below it)
        meta.insert(DERIVATIVE_CUTOFF_KEY.to_string(), fc);
    }
    let mut extra = BTreeMap::new();
    for (j, name) in h.iter().enumerate() {
        if !["t_s", "x_m", "f_N", "v_m_s", "a_m_s2"].contains(&name.as_str()) {
            extra.insert(name.clone(), std::mem::take(&mut cols[j]));
        }
    }
    Ok(Record {
        t,
        x,
        f,
        v,
        a,
        meta,
        extra,
        derivative_method: method,
    })
}

impl Record {
    /// Low-pass the force with the same zero-phase filter as the derived velocity and
    /// acceleration ("parallel filtering", the EMPS benchmark's processing): force content
    /// above the cutoff, which the derived acceleration cannot follow, is removed from both
    /// sides of the model, and relative errors become comparable with figures computed that
    /// way.
    pub fn filter_force(&mut self, cutoff_hz: Option<f64>) {
        if self.len() < 3 {
            return;
        }
        let fs = 1.0 / self.dt();
        let fc = cutoff_hz.unwrap_or_else(|| default_cutoff(fs));
        if check_cutoff(fc, fs).is_err() {
            return;
        }
        self.f = filtfilt(&self.f, fc, fs);
        // a velocity derived from x through a wider band than the force's is brought to the
        // force's band: every column then sees the motion through the one filter the force
        // passed (the model's terms low-passed as the force is)
        if self
            .meta
            .get(VELOCITY_CUTOFF_KEY)
            .is_some_and(|&fv| fv != fc)
        {
            self.v = central_diff(&filtfilt(&self.x, fc, fs), self.dt());
            self.meta.insert(VELOCITY_CUTOFF_KEY.to_string(), fc);
            self.derivative_method = derived_method(fc, fc);
        }
        self.derivative_method.push_str(&format!(
            "; force f_N low-passed by the same filter ({fc:.3} Hz, parallel filtering)"
        ));
    }
}

/// The highest default cutoff of the derivative (and force) filter, Hz (`default_cutoff`).
pub const DEFAULT_CUTOFF_MAX_HZ: f64 = 50.0;

/// The derivative (and force) filter's default cutoff for a record sampled at `fs`: fs/20, at
/// most `DEFAULT_CUTOFF_MAX_HZ`. The band the derived acceleration must follow is the
/// device's motion and the forces it excites (a bench's or a structure's motion below a few
/// hertz, its modes and contacts within tens of hertz), not a share of the sample rate: the
/// noise a quantised position puts into the acceleration grows as fc^2.5, so a cutoff raised
/// with the sample rate buys noise and no band.
pub fn default_cutoff(fs: f64) -> f64 {
    (fs / 20.0).min(DEFAULT_CUTOFF_MAX_HZ)
}

/// The derivative (and force) filter's cutoff must lie strictly between 0 and the Nyquist
/// frequency of the record.
pub fn check_cutoff(fc: f64, fs: f64) -> Result<(), RecordError> {
    if fc.is_finite() && fc > 0.0 && fc < 0.5 * fs {
        Ok(())
    } else {
        Err(err(
            None,
            format!(
                "cutoff_hz = {fc}: allowed range (0, {}) Hz, below half the sample rate {fs} Hz",
                0.5 * fs
            ),
        ))
    }
}

/// Read and parse a file.
pub fn read_csv(path: &std::path::Path, cutoff_hz: Option<f64>) -> Result<Record, RecordError> {
    let text =
        std::fs::read_to_string(path).map_err(|e| err(None, format!("{}: {e}", path.display())))?;
    parse_csv(&text, cutoff_hz).map_err(|e| RecordError {
        line: e.line,
        msg: format!("{}: {}", path.display(), e.msg),
    })
}

/// Velocity and acceleration derived from a position: the acceleration is the central
/// difference of the central difference of the zero-phase Butterworth-2 low-pass of x at `fc`
/// (forward-backward); the velocity the central difference of that low-pass at `fc_v` ≥ `fc`
/// (the same filtered x when equal; None: the record's own `velocity_cutoff`). Returns v, a
/// and the velocity's cutoff. The reader's derivation, and the one `effects::DerivNoise`
/// propagates the position quantum through.
pub fn derive_from_x(x: &[f64], fc: f64, fc_v: Option<f64>, dt: f64) -> (Vec<f64>, Vec<f64>, f64) {
    let fs = 1.0 / dt;
    let va = central_diff(&filtfilt(x, fc, fs), dt);
    let a = central_diff(&va, dt);
    let fc_v = fc_v.unwrap_or_else(|| {
        let vmax = va.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        velocity_cutoff(x, vmax, fc, dt)
    });
    let v = if fc_v > fc {
        central_diff(&filtfilt(x, fc_v, fs), dt)
    } else {
        va
    };
    (v, a, fc_v)
}

/// Metadata key under which the reader records the cutoff (Hz) of the low-pass the velocity
/// was derived through (`velocity_cutoff`; absent when `v_m_s` is measured).
pub const VELOCITY_CUTOFF_KEY: &str = "velocity_cutoff_hz";

/// The reader's `derivative_method` text for v and a derived from x.
fn derived_method(fc: f64, fc_v: f64) -> String {
    format!(
        "a: zero-phase Butterworth-2 low-pass of x_m at {fc:.3} Hz (forward-backward), then \
         central differences twice; v: the same low-pass at {fc_v:.3} Hz (the widest band whose \
         position noise leaves the velocity's within the Coulomb sign's band, fs/4 at most), \
         then a central difference"
    )
}

/// Variance of the derived velocity's noise per unit variance of white position noise: the
/// forward-backward Butterworth-2 at `fc` (amplitude response 1/(1 + (f/fc)⁴)) and a
/// differentiation, (2/fs)·∫₀^∞ (2πf)²/(1 + (f/fc)⁴)² df = (2/fs)·(2π)²·fc³·π/(8√2).
pub fn velocity_noise_gain(fc: f64, fs: f64) -> f64 {
    (2.0 / fs) * (2.0 * std::f64::consts::PI).powi(2) * fc.powi(3) * std::f64::consts::PI
        / (8.0 * std::f64::consts::SQRT_2)
}

/// The velocity's cutoff (Hz) for a position record `x` sampled every `dt` whose
/// acceleration is derived at `fc`: the widest band in which the velocity's noise σ_v (the
/// position's noise σ_x through the low-pass and the differentiation, `velocity_noise_gain`)
/// stays within the Coulomb sign's band (0.2 % of the peak speed `vmax`, `effects::sign_band`):
/// the Coulomb sign is linear in v over the band, so noise of that size averages out there
/// instead of flipping the sign, while the low-pass rounds the motion's turns (a near-stop's
/// minimum speed, by ∝ |a|/fc_v) over a span ∝ 1/fc_v instead of 1/fc. σ_x² is the larger of the quantum's q²/12 (q the smallest
/// non-zero step) and the white noise's variance from the median absolute 4th difference
/// (70·σ² for white noise). At least `fc` (the velocity never narrower than the
/// acceleration's band), at most fs/4 (the central difference there passes 64 % of a
/// derivative: above it the difference is no derivative).
pub fn velocity_cutoff(x: &[f64], vmax: f64, fc: f64, dt: f64) -> f64 {
    let n = x.len();
    let fs = 1.0 / dt;
    if n < 5 {
        return fc;
    }
    let q = x
        .windows(2)
        .map(|p| (p[1] - p[0]).abs())
        .filter(|d| *d > 0.0)
        .fold(f64::MAX, f64::min);
    let q2 = if q == f64::MAX { 0.0 } else { q * q / 12.0 };
    let mut d4: Vec<f64> = x
        .windows(5)
        .map(|p| (p[4] - 4.0 * p[3] + 6.0 * p[2] - 4.0 * p[1] + p[0]).abs())
        .collect();
    let k = d4.len() / 2;
    let med = *d4.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1;
    let w2 = (med / 0.6745).powi(2) / 70.0;
    let s2x = q2.max(w2);
    let target = VELOCITY_NOISE_PER_BAND * 2e-3 * vmax;
    let hi = 0.25 * fs;
    if s2x <= 0.0 {
        return hi.max(fc);
    }
    // σ_v² = s2x·velocity_noise_gain(f), ∝ f³
    let f = (target * target / (s2x * velocity_noise_gain(1.0, fs))).cbrt();
    f.clamp(fc, hi.max(fc))
}

/// The velocity's noise σ_v allowed per Coulomb sign band (`velocity_cutoff`): one.
pub const VELOCITY_NOISE_PER_BAND: f64 = 1.0;

/// The record's velocity through the acceleration's band (`derive_from_x` at its
/// `derivative_cutoff_hz`), where the reader's came through a wider one; None when the
/// reader's velocity is already that one, or was measured.
pub fn v_through_accel_band(r: &Record) -> Option<Vec<f64>> {
    match (
        r.meta.get(DERIVATIVE_CUTOFF_KEY),
        r.meta.get(VELOCITY_CUTOFF_KEY),
    ) {
        (Some(&fc), Some(&fv)) if fv > fc && r.len() >= 3 => {
            Some(derive_from_x(&r.x, fc, Some(fc), r.dt()).0)
        }
        _ => None,
    }
}

/// What the record's derived signals would change by under the other derivations the
/// record supports equally: the acceleration through twice its filter's cutoff (at most fs/4)
/// and through half of it, each less the reader's (the inertial force the filter's band cuts
/// at the motion's turns, and the noise at the top of that band), and the velocity through the
/// acceleration's band less the reader's wider one. Empty for signals the record measured (no
/// `derivative_cutoff_hz`, no `velocity_cutoff_hz` above it).
pub fn derivation_alternatives(r: &Record) -> Vec<Vec<f64>> {
    let mut out = Vec::new();
    let Some(&fc) = r.meta.get(DERIVATIVE_CUTOFF_KEY) else {
        return out;
    };
    if r.len() < 3 {
        return out;
    }
    let dt = r.dt();
    for fc_alt in [(2.0 * fc).min(0.25 / dt), 0.5 * fc] {
        if fc_alt > 0.0 && (fc_alt - fc).abs() > 1e-9 * fc {
            let a = derive_from_x(&r.x, fc_alt, Some(fc_alt), dt).1;
            out.push(a.iter().zip(&r.a).map(|(x, y)| x - y).collect());
        }
    }
    if let Some(v) = v_through_accel_band(r) {
        out.push(v.iter().zip(&r.v).map(|(x, y)| x - y).collect());
    }
    out
}

/// Forward-backward (zero-phase) 2nd-order Butterworth low-pass, bilinear transform with
/// prewarping; the state starts at the first (resp. last) sample so there is no start-up step.
pub fn filtfilt(x: &[f64], fc: f64, fs: f64) -> Vec<f64> {
    let fc = fc.min(0.45 * fs);
    let k = (std::f64::consts::PI * fc / fs).tan();
    let s2 = std::f64::consts::SQRT_2;
    let norm = 1.0 / (1.0 + s2 * k + k * k);
    let b0 = k * k * norm;
    let b1 = 2.0 * b0;
    let b2 = b0;
    let a1 = 2.0 * (k * k - 1.0) * norm;
    let a2 = (1.0 - s2 * k + k * k) * norm;
    let run = |inp: &mut Vec<f64>| {
        let x0 = inp[0];
        let (mut x1, mut x2, mut y1, mut y2) = (x0, x0, x0, x0);
        for s in inp.iter_mut() {
            let xin = *s;
            let y = b0 * xin + b1 * x1 + b2 * x2 - a1 * y1 - a2 * y2;
            x2 = x1;
            x1 = xin;
            y2 = y1;
            y1 = y;
            *s = y;
        }
    };
    // odd reflection padding at both ends (as scipy's filtfilt), so the edges carry no
    // start-up transient: pad = 3 time constants of the filter, at most n-1 samples
    let n = x.len();
    let pad = ((3.0 * fs / fc).ceil() as usize).min(n - 1);
    let mut y = Vec::with_capacity(n + 2 * pad);
    for i in (1..=pad).rev() {
        y.push(2.0 * x[0] - x[i]);
    }
    y.extend_from_slice(x);
    for i in 1..=pad {
        y.push(2.0 * x[n - 1] - x[n - 1 - i]);
    }
    run(&mut y);
    y.reverse();
    run(&mut y);
    y.reverse();
    y[pad..pad + n].to_vec()
}

/// Central differences (one-sided at the ends).
pub fn central_diff(x: &[f64], dt: f64) -> Vec<f64> {
    let n = x.len();
    let mut d = vec![0.0; n];
    for i in 1..n - 1 {
        d[i] = (x[i + 1] - x[i - 1]) / (2.0 * dt);
    }
    d[0] = (x[1] - x[0]) / dt;
    d[n - 1] = (x[n - 1] - x[n - 2]) / dt;
    d
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// A closed-form motion with near-stops, quantised: v(t) = v_min + (V − v_min)·sin²(πt/T),
    /// x its exact integral rounded to the quantum q. Returns (x, exact v).
    fn near_stops(q: f64, dt: f64, n: usize) -> (Vec<f64>, Vec<f64>) {
        let (v_min, vv, tp) = (5e-5, 8e-3, 0.04);
        let w = 2.0 * PI / tp;
        let mut x = Vec::with_capacity(n);
        let mut v = Vec::with_capacity(n);
        for i in 0..n {
            let t = i as f64 * dt;
            // sin²(πt/T) = (1 − cos(wt))/2
            let xe = v_min * t + 0.5 * (vv - v_min) * (t - (w * t).sin() / w);
            x.push((xe / q).round() * q);
            v.push(v_min + 0.5 * (vv - v_min) * (1.0 - (w * t).cos()));
        }
        (x, v)
    }

    /// The largest error of the derived speed's minimum at each near-stop (away from the
    /// record's ends) against the exact 0.05 mm/s.
    fn min_speed_error(v: &[f64], v_true: &[f64]) -> f64 {
        let (n, per) = (v.len(), 40);
        (1..n / per - 1)
            .map(|k| {
                let lo = k * per - per / 2;
                let d = v[lo..lo + per].iter().fold(f64::MAX, |m, x| m.min(x.abs()));
                let e = v_true[lo..lo + per]
                    .iter()
                    .fold(f64::MAX, |m, x| m.min(x.abs()));
                (d - e).abs()
            })
            .fold(0.0, f64::max)
    }

    /// The velocity follows a quantised motion's near-stops (0.05 mm/s between passes at
    /// 8 mm/s every 40 ms, the turn's |a| up to 0.63 m/s², 0.4 µm encoder at 1 kHz: the rig's
    /// recorded motion's turns) to within its noise. Through the acceleration's low-pass at
    /// 50 Hz the minimum is 0.26 mm/s too high (the 25 Hz turn loses 1 − 1/(1 + (25/50)⁴) =
    /// 5.9 % of its 4 mm/s swing, 0.24 mm/s); through `velocity_cutoff`'s band (82 Hz here)
    /// the largest of the 48 near-stops' errors is 0.068 mm/s. Bound 0.1 mm/s (1.5×: the
    /// figure is already the largest of 48). Break: the velocity through the acceleration's
    /// band (`fc_v = fc`) gives 0.26 mm/s.
    #[test]
    fn velocity_follows_a_near_stop_within_its_noise() {
        let dt = 1e-3;
        let (x, v_true) = near_stops(0.4e-6, dt, 2000);
        let fc = 50.0;
        let (v, _, fc_v) = derive_from_x(&x, fc, None, dt);
        let e = min_speed_error(&v, &v_true);
        eprintln!(
            "fc_v {fc_v:.1} Hz, near-stop minimum speed error {:.4} mm/s",
            e * 1e3
        );
        assert!(
            e < 1e-4,
            "near-stop minimum off by {e} m/s (fc_v {fc_v} Hz)"
        );
    }

    /// `derivation_alternatives` carries the inertial force the acceleration's low-pass cuts:
    /// a motion of a slow stroke (0.5 Hz) and four components near and below the cutoff (10,
    /// 25, 35, 45 Hz at 50 Hz, where the filter passes 99.8 % down to 60 %), its exact
    /// acceleration a known in closed form, the position on a 0.1 µm encoder at 1 kHz: a
    /// least-squares combination of the alternatives gives back the lost part a − a_derived
    /// to within 8 % of its rms (measured 3.0 %, of which 0.7 % without the encoder's quantum:
    /// the lost share 1 − 1/(1 + (f/fc)⁴) and the twice-wider filter's gain over the reader's
    /// differ by 7–11 % across the components; bound about 2.5×). Break: without the
    /// acceleration through twice the cutoff 51 % is left.
    #[test]
    fn derivation_alternatives_carry_the_lost_inertial_force() {
        let (dt, n, q) = (1e-3, 8000, 1e-7);
        let comps = [
            (0.5, 0.03),
            (10.0, 1e-4),
            (25.0, 1e-5),
            (35.0, 5e-6),
            (45.0, 3e-6),
        ];
        let mut x = Vec::with_capacity(n);
        let mut a_true = Vec::with_capacity(n);
        for i in 0..n {
            let t = i as f64 * dt;
            let (mut xi, mut ai) = (0.0, 0.0);
            for (k, &(f, amp)) in comps.iter().enumerate() {
                let w = 2.0 * PI * f;
                let ph = 0.7 * k as f64;
                xi += amp * (w * t + ph).sin();
                ai -= amp * w * w * (w * t + ph).sin();
            }
            x.push((xi / q).round() * q);
            a_true.push(ai);
        }
        let t: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
        let mut text = String::from("t_s,x_m,f_N\n");
        for (ti, xi) in t.iter().zip(&x) {
            text.push_str(&format!("{ti},{xi},0\n"));
        }
        let r = parse_csv(&text, Some(50.0)).expect("parses");
        let alt = derivation_alternatives(&r);
        assert_eq!(alt.len(), 3, "two accelerations and a velocity");
        // the lost part and its least-squares fit on the alternatives, away from the ends
        let rows: Vec<usize> = (500..n - 500).collect();
        let e: Vec<f64> = rows.iter().map(|&i| a_true[i] - r.a[i]).collect();
        let cols: Vec<Vec<f64>> = alt
            .iter()
            .map(|c| rows.iter().map(|&i| c[i]).collect())
            .collect();
        let refs: Vec<&[f64]> = cols.iter().map(|c| c.as_slice()).collect();
        let part = vec![crate::TRAIN; rows.len()];
        let (tr, _) = crate::normals(&refs, &e, &part, 1);
        let th = tr.solve();
        let left = (tr.rss(&th) / tr.ff).sqrt();
        eprintln!(
            "lost inertial force left after the alternatives: {:.1} % of its rms",
            100.0 * left
        );
        assert!(left < 0.08, "{left}");
    }

    /// `velocity_noise_gain` is the filter's own: Σ h_v² of the derived velocity's response
    /// to a unit position sample (the closed form of the forward-backward Butterworth-2 with
    /// a continuous differentiation; the central difference passes sin(ω·dt)/(ω·dt) of it and
    /// the bilinear transform warps the band: measured ratios 0.992 at fs/50, 0.956 at fs/20).
    /// Bound 7 % (1.5× the larger deviation: the cutoff found from it is then within 2.5 %,
    /// the cube root).
    /// Break: π/(2√2) (one pass's response) in place of π/(8√2) fails by 4×.
    #[test]
    fn velocity_noise_gain_is_the_filters() {
        let dt = 1e-3;
        for fc in [20.0, 50.0] {
            let half = 2000;
            let mut x = vec![0.0; 2 * half + 1];
            x[half] = 1.0;
            let (v, _, _) = derive_from_x(&x, fc, Some(fc), dt);
            let s: f64 = v.iter().map(|h| h * h).sum();
            let g = velocity_noise_gain(fc, 1.0 / dt);
            eprintln!(
                "fc {fc}: Σh² {s:.4e}, closed form {g:.4e}, ratio {:.4}",
                s / g
            );
            assert!((s / g - 1.0).abs() < 0.07, "fc {fc}: {s} against {g}");
        }
    }
}
