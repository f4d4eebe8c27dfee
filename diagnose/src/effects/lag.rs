//! Delayed signals (`lag`): the motion and its Coulomb switch `k` samples back, and the rows a delay leaves out.

use super::*;

/// `s` at `k` samples before sample `i` (k ≥ 0, fractional: linear interpolation between the
/// two samples around that time; held at the record's first sample before it).
pub fn delayed(s: &[f64], i: usize, k: f64) -> f64 {
    let t = i as f64 - k;
    if t <= 0.0 || s.len() < 2 {
        return s.first().copied().unwrap_or(0.0);
    }
    // t > 0 (or NaN, 0 either way): the cast's truncation is t's floor
    let j = (t as usize).min(s.len() - 2);
    let al = t - j as f64;
    s[j] + al * (s[j + 1] - s[j])
}

/// The longest delay `lag` scans in samples at the lowest sample rates (`lag_max`).
pub const LAG_MAX_SAMPLES: f64 = 64.0;

/// The longest skew of an acquisition `lag` scans, s (`lag_max`).
pub const LAG_MAX_S: f64 = 0.064;

/// The longest delay `lag` scans on a record sampled every `dt` (its grid's last value):
/// `LAG_MAX_S`, or `LAG_MAX_SAMPLES` samples where they last longer (a skew of a few samples
/// is resolved at any rate; one beyond 64 ms is not an acquisition's).
pub fn lag_max(dt: f64) -> f64 {
    (LAG_MAX_SAMPLES * dt).max(LAG_MAX_S)
}

/// Values of `lag`'s grid from one sample to `lag_max`, log-spaced about 15 % apart: 30 over
/// 64 samples, more over a longer span in samples.
pub fn lag_grid_len(dt: f64) -> usize {
    let ratio = lag_max(dt) / dt;
    ((29.0 * ratio.ln() / LAG_MAX_SAMPLES.ln()).ceil() as usize + 1).max(30)
}

/// The exact sign of the velocity `v` at `k` samples before sample `i` (fractional: the two
/// samples' signs interpolated linearly, so a reversal between them switches in proportion;
/// held at the first sample before the record). The delayed device's Coulomb sign: a delayed
/// sample is used only where the motion τ earlier is not at rest (`Context::lag_rest_rows`),
/// so the sign there is that of a sliding device, whose Coulomb force is the full Fc at any
/// sliding speed (the linear band of `sgn` guards against the derived velocity's noise at
/// rest, not a force law).
pub fn delayed_sign(v: &[f64], i: usize, k: f64) -> f64 {
    let s = |u: f64| {
        if u > 0.0 {
            1.0
        } else if u < 0.0 {
            -1.0
        } else {
            0.0
        }
    };
    let t = i as f64 - k;
    if t <= 0.0 || v.len() < 2 {
        return v.first().copied().map_or(0.0, s);
    }
    // t > 0 (or NaN, 0 either way): the cast's truncation is t's floor
    let j = (t as usize).min(v.len() - 2);
    let al = t - j as f64;
    s(v[j]) + al * (s(v[j + 1]) - s(v[j]))
}

/// The Coulomb switch a delay of `k` samples (fractional) puts at sample `i`: the delayed
/// device's sign (`delayed_sign` of the velocity `v`) minus the record's Coulomb sign `sgn`
/// now (`Context::sgn`, as the baseline's Coulomb column takes it, so that the baseline plus
/// the column at gain 1 is the delayed device's Coulomb force `Fc·sgn v(t − τ)` whatever the
/// speed at t), the Coulomb part of `lag`'s column per unit of the delayed device's Coulomb
/// coefficient. Non-zero for τ after each reversal: the switch's shape, which a
/// `presliding_hysteresis` beside the lag must be told apart from (`diagnose`'s scan refits it
/// with an amplitude of its own).
pub fn delayed_switch(v: &[f64], sgn: &[f64], i: usize, k: f64) -> f64 {
    delayed_sign(v, i, k) - sgn[i]
}

impl Context<'_> {
    /// True when the motion `k` samples before sample `i` (fractional: either sample around
    /// that time) is at rest (`at_rest`), or lies before the record.
    pub fn rest_delayed(&self, i: usize, k: f64) -> bool {
        let t = i as f64 - k;
        if t < 0.0 || !t.is_finite() {
            return true;
        }
        // t ≥ 0 and finite: the cast's truncation is t's floor, its ceiling one more unless t
        // is whole (the casts cost less than the `floor` and `ceil` calls, the same indices)
        let f = t as usize;
        let c = if (f as f64) < t {
            f.saturating_add(1)
        } else {
            f
        };
        let last = self.rest.len().saturating_sub(1);
        let (j, j1) = (f.min(last), c.min(last));
        self.rest[j] || self.rest[j1]
    }

    /// The samples in motion now whose motion `tau` seconds earlier is at rest: indices into
    /// `rows` (into the record when None). Under a force channel delayed by τ the force at t is
    /// the device's at t − τ, so there it is the force of a device at rest (static friction,
    /// anywhere within its breakaway level, no Coulomb sign): the delayed model, and the model
    /// it is compared against, leave these samples out as `at_rest` leaves out the samples
    /// at rest now. So are the samples in motion whose speed now lies inside the Coulomb
    /// sign's band (`sign_band`): the delayed device slides with the exact sign
    /// (`delayed_switch`) and the column's part at t is the baseline's banded sign, so there
    /// the column would carry the band's own error at t (a sliding device's Coulomb force is
    /// the full Fc), which a lag of any τ takes from a record with no delay.
    pub fn lag_rest_rows(&self, tau: f64, rows: Option<&[usize]>) -> Vec<usize> {
        let k = tau / self.dt;
        let at = |j: usize| rows.map_or(j, |r| r[j]);
        let n = rows.map_or(self.rest.len(), |r| r.len());
        (0..n)
            .filter(|&j| {
                let i = at(j);
                !self.rest[i] && (self.rest_delayed(i, k) || self.rec.v[i].abs() < self.v_eps)
            })
            .collect()
    }

    /// Training samples in motion among the first `window` samples, strided to at most `max`
    /// (the rows the delayed baseline of `lag` and the damping-ratio profile are fitted on).
    pub(crate) fn training_rows(&self, window: usize, max: usize) -> Vec<usize> {
        let hold = crate::holdout_mask(self.rec.len(), self.split);
        let cand: Vec<usize> = (0..window)
            .filter(|&i| !self.rest[i] && hold[i] == crate::TRAIN)
            .collect();
        let step = cand.len().div_ceil(max).max(1);
        cand.into_iter().step_by(step).collect()
    }

    /// The delayed baseline of `lag`: the inertia, viscous and Coulomb coefficients of the
    /// baseline fitted with its motion columns (a, v, sgn v) taken `tau` seconds earlier (the
    /// offset and an electromagnetic column as they are), on at most `LAG_ROWS` training
    /// samples in motion (strided). A force channel that lags the motion by τ is the device's
    /// own force at t − τ: these are the device's coefficients, not biased by the delay as
    /// the baseline fitted on the delayed record is. None when the fit is not a device's
    /// (an inertia, viscous or Coulomb coefficient below 0, or fewer than 10 rows): the lag
    /// column is then zero and `lag` is not named at this τ. Cached per τ.
    pub fn lag_coefs(&self, tau: f64) -> Option<[f64; 3]> {
        if let Ok(c) = self.lag_cache.lock() {
            if let Some(th) = c.get(&tau.to_bits()) {
                return *th;
            }
        }
        let lr = self.lag_rows.get_or_init(|| {
            let rows = self.training_rows(self.window, LAG_ROWS);
            let mut cols = vec![vec![1.0; rows.len()]];
            if let Some((_, c, _)) = em_column(self.rec) {
                cols.push(rows.iter().map(|&i| c[i]).collect());
            }
            let f = rows.iter().map(|&i| self.rec.f[i]).collect();
            FitRows { rows, cols, f }
        });
        let k = tau / self.dt;
        let th = if lr.rows.len() < 10 || !k.is_finite() || k < 0.0 {
            None
        } else {
            let r = self.rec;
            let mut all: Vec<Vec<f64>> = [&r.a, &r.v]
                .iter()
                .map(|s| lr.rows.iter().map(|&i| delayed(s, i, k)).collect())
                .collect();
            all.push(lr.rows.iter().map(|&i| delayed_sign(&r.v, i, k)).collect());
            all.extend(lr.cols.iter().cloned());
            let refs: Vec<&[f64]> = all.iter().map(|c| c.as_slice()).collect();
            // the delayed device moves on these rows only where its motion at t − τ does
            let train: Vec<u8> = lr
                .rows
                .iter()
                .map(|&i| {
                    if self.rest_delayed(i, k) {
                        crate::AT_REST
                    } else {
                        crate::TRAIN
                    }
                })
                .collect();
            let nt = crate::normals(&refs, &lr.f, &train, 1).0;
            let th = nt.solve();
            let c = [th[0], th[1], th[2]];
            (nt.n >= 10 && c.iter().all(|v| v.is_finite() && *v >= 0.0) && c[0] > 0.0).then_some(c)
        };
        if let Ok(mut c) = self.lag_cache.lock() {
            c.insert(tau.to_bits(), th);
        }
        th
    }
}
