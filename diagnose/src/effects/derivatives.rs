//! The derived velocity's and acceleration's noise and the velocity through the acceleration's band.

use super::*;

/// The noise the record's derivation puts into the derived velocity and acceleration: the
/// position's quantisation error (white, variance q²/12, q the position quantum) through the
/// record's own zero-phase low-passes and central differences (`record::derive_from_x` at the
/// record's `derivative_cutoff_hz` and `velocity_cutoff_hz`), as their responses to a
/// unit position sample. These are the errors in the variables of `lag`'s column, which
/// differences a and v over τ (`Context::lag_noise`).
#[derive(Debug, Clone)]
pub struct DerivNoise {
    /// Variance of the position's error (m²).
    s2: f64,
    /// Responses of a (index 0) and v (index 1) to a unit position sample.
    h: [Vec<f64>; 2],
    /// σ²·Σ h_p[i]·h_q[i + d] for |d| ≤ `DerivNoise::D`: [aa, av, va, vv][d + D].
    k: [Vec<f64>; 4],
}

impl DerivNoise {
    /// Shifts tabulated (beyond: summed when asked).
    const D: isize = 128;

    /// The noise of a record whose v and a are derived from a position of quantum `q` through
    /// low-passes at `fc_v` and `fc` (Hz, `record::derive_from_x`), sampled every `dt` s, over
    /// `n` samples. None when there is no quantum.
    pub fn new(q: f64, fc: f64, fc_v: f64, dt: f64, n: usize) -> Option<DerivNoise> {
        let fs = 1.0 / dt;
        if !(q > 0.0 && fc > 0.0 && fc < 0.5 * fs) {
            return None;
        }
        // the filter's impulse response has decayed to rounding well within 12 periods of its
        // cutoff each way, and a record of n samples holds no more of it than n each way; the
        // tabulated shifts beside it
        let half = (12.0 * fs / fc).ceil().min(n as f64) as usize + Self::D as usize;
        let mut x = vec![0.0; 2 * half + 1];
        x[half] = 1.0;
        let (v, a, _) = crate::record::derive_from_x(&x, fc, Some(fc_v), dt);
        let mut nz = DerivNoise {
            s2: q * q / 12.0,
            h: [a, v],
            k: Default::default(),
        };
        let pairs = [(0, 0), (0, 1), (1, 0), (1, 1)];
        nz.k = pairs.map(|(p, q)| (-Self::D..=Self::D).map(|d| nz.sum(p, q, d)).collect());
        Some(nz)
    }

    pub(crate) fn sum(&self, p: usize, q: usize, d: isize) -> f64 {
        let (hp, hq) = (&self.h[p], &self.h[q]);
        let n = hp.len() as isize;
        let (lo, hi) = ((-d).max(0), (n - d).min(n));
        self.s2
            * (lo..hi)
                .map(|i| hp[i as usize] * hq[(i + d) as usize])
                .sum::<f64>()
    }

    /// E[p(t − m)·q(t − l)] with d = m − l (p, q: 0 the acceleration, 1 the velocity).
    pub fn cov(&self, p: usize, q: usize, d: isize) -> f64 {
        if d.abs() <= Self::D {
            self.k[2 * p + q][(d + Self::D) as usize]
        } else {
            self.sum(p, q, d)
        }
    }

    /// The acceleration's noise after the linear, time-invariant map `g` (a filter applied to
    /// the whole acceleration, e.g. a column built from it), with the acceleration's and the
    /// velocity's own noise at the same sample: the per-row covariance S of (a, v, g·a),
    /// σ²·Σ h_p·h_q over the responses to a unit position sample (g applied to h_a).
    pub fn accel_cov_through(&self, g: impl Fn(&[f64]) -> Vec<f64>) -> [[f64; 3]; 3] {
        let y = g(&self.h[0]);
        let r = [&self.h[0][..], &self.h[1][..], &y[..]];
        let mut s = [[0.0; 3]; 3];
        for p in 0..3 {
            for q in 0..3 {
                s[p][q] = self.s2 * r[p].iter().zip(r[q]).map(|(x, y)| x * y).sum::<f64>();
            }
        }
        s
    }

    /// Covariance of two sums Σ c·s(t − m) of the derived signals ((signal, m, c) terms).
    pub fn cov_sum(&self, x: &[(usize, isize, f64)], y: &[(usize, isize, f64)]) -> f64 {
        let mut s = 0.0;
        for &(p, m, c) in x {
            for &(q, l, e) in y {
                s += c * e * self.cov(p, q, m - l);
            }
        }
        s
    }
}

impl Context<'_> {
    /// The derivative filter's cutoff of the record, Hz: its `derivative_cutoff_hz`, else the
    /// default (`record::default_cutoff`).
    pub fn derivative_cutoff(&self) -> f64 {
        self.rec
            .meta
            .get(crate::record::DERIVATIVE_CUTOFF_KEY)
            .copied()
            .unwrap_or_else(|| crate::record::default_cutoff(1.0 / self.dt))
    }

    /// The velocity through the same band as the acceleration (`record::derive_from_x` at
    /// the record's `derivative_cutoff_hz`), for a model that integrates a motion from v and a
    /// together (the play's device walk): the record's v when it came through that band or was
    /// measured.
    pub fn v_with_a(&self) -> &[f64] {
        self.v_with_a
            .get_or_init(|| crate::record::v_through_accel_band(self.rec).unwrap_or_default());
        let v = self.v_with_a.get().map_or(&[][..], |v| v.as_slice());
        if v.len() == self.rec.len() {
            v
        } else {
            &self.rec.v
        }
    }

    /// The noise of the record's derived v and a (`DerivNoise`), when they are derived from a
    /// quantised position (the record states its derivative cutoff and a quantum shows).
    pub fn deriv_noise(&self) -> Option<&DerivNoise> {
        self.deriv_noise
            .get_or_init(|| {
                let meta = &self.rec.meta;
                let fc = *meta.get(crate::record::DERIVATIVE_CUTOFF_KEY)?;
                let fc_v = meta
                    .get(crate::record::VELOCITY_CUTOFF_KEY)
                    .map_or(fc, |&f| f);
                DerivNoise::new(self.x_quantum, fc, fc_v, self.dt, self.rec.len())
            })
            .as_ref()
    }

    /// The errors-in-variables covariance, per row, of the baseline's inertia and viscous
    /// columns (a, v) and the `compliance` column at `f_hz` (its damping ratio
    /// `compliance_zeta`; `DerivNoise::accel_cov_through`): the derived acceleration's
    /// quantisation noise (`deriv_noise`) through (H − 1), the column's own filter. That noise lies near the derivative filter's
    /// cutoff, above the mode, where H − 1 ≈ −1: the column carries it almost in full, so a
    /// column fitted with a coefficient near the inertia cancels the noise of the inertia's
    /// column (the acceleration low-passed at the mode) whether or not there is a mode. None
    /// when the acceleration has no derivation noise or the frequency identifies no mode.
    pub fn compliance_noise(&self, f_hz: f64) -> Option<[[f64; 3]; 3]> {
        let nz = self.deriv_noise()?;
        let z = self.compliance_zeta(f_hz)?;
        Some(nz.accel_cov_through(|h| {
            compliance_columns_at(h, &[(f_hz, z)], self.dt, None)
                .pop()
                .unwrap_or_default()
        }))
    }

    /// The errors-in-variables covariance, per row, of the baseline's inertia and viscous
    /// columns (a, v) and `lag`'s column at `tau` (its delayed device's coefficients M, Fv
    /// from `lag_coefs`): S = E[ε εᵀ], ε the noise of (a, v, M·(a(t−τ) − a(t)) +
    /// Fv·(v(t−τ) − v(t))), the delayed values interpolated as the column does. The Coulomb
    /// sign's noise is not in it (a sign flips only within its band, near rest). None when
    /// the record has no derivation noise (`deriv_noise`) or no delayed device at τ.
    pub fn lag_noise(&self, tau: f64) -> Option<[[f64; 3]; 3]> {
        let nz = self.deriv_noise()?;
        let th = self.lag_coefs(tau)?;
        let k = tau / self.dt;
        let j = k.floor();
        let al = k - j;
        let j = j as isize;
        let z: Vec<(usize, isize, f64)> = [(0, th[0]), (1, th[1])]
            .into_iter()
            .flat_map(|(p, c)| [(p, j, c * (1.0 - al)), (p, j + 1, c * al), (p, 0, -c)])
            .collect();
        let cols = [vec![(0, 0, 1.0)], vec![(1, 0, 1.0)], z];
        let mut s = [[0.0; 3]; 3];
        for r in 0..3 {
            for c in 0..3 {
                s[r][c] = nz.cov_sum(&cols[r], &cols[c]);
            }
        }
        Some(s)
    }
}
