//! The resonator columns (`compliance`): a mass hung on the device through a spring-damper, walked over the record, and the damping ratio the record shows.

use super::*;

/// Damping ratios over which `compliance_zeta` profiles a mode (log-spaced, 0.01 … 0.4).
/// A mode damped by 0.4 or more amplifies its resonance by at most 1/(2ζ) ≈ 1.25: over such a
/// broad band the column is a frequency-dependent inertia that also fits the remainder of
/// other effects (a lag's, on 7/40 synthetic records), so a profile whose optimum lies at the
/// last value does not identify a resonance (`compliance_zeta` gives None).
pub const COMPLIANCE_ZETAS: [f64; 9] = [
    0.01, 0.0159, 0.0252, 0.04, 0.0635, 0.1007, 0.1597, 0.2533, 0.4,
];

/// Second-order resonators (ω = 2π·f, damping ratio ζ per pair) driven by `u`, interleaved
/// up to eight per pass over the record (`resonator_each`). Each is a zero-delay-feedback
/// state-variable filter (bilinear transform prewarped at f, unconditionally stable) started
/// at rest on the first input. Returns per pair the low-pass `ω²/(s²+2ζωs+ω²)·u` and band-pass
/// `ωs/(s²+2ζωs+ω²)·u` outputs at `rows` (all samples when None).
pub fn resonator_batch(
    u: &[f64],
    modes: &[(f64, f64)],
    dt: f64,
    rows: Option<&[usize]>,
) -> Vec<(Vec<f64>, Vec<f64>)> {
    let cap = rows.map_or(u.len(), |r| r.len());
    let mut out = vec![(Vec::with_capacity(cap), Vec::with_capacity(cap)); modes.len()];
    resonator_each(u, modes, dt, rows, |k, lp, bp| {
        out[k].0.push(lp);
        out[k].1.push(bp);
    });
    out
}

/// The resonators of `modes` (as `resonator_batch`) walked over `u`, up to eight per pass
/// (independent recurrences, so a pass is bound by arithmetic throughput rather than by one
/// filter's feedback chain): `emit(k, low-pass, band-pass)` of filter `k` (its index in
/// `modes`) at each row of `rows` (every sample when None), row by row within a pass, the
/// passes in the order of the modes. Each filter's outputs are those of the filter run alone,
/// bit for bit. The rows are taken while they ascend within the input.
#[inline(always)]
pub(crate) fn resonator_each(
    u: &[f64],
    modes: &[(f64, f64)],
    dt: f64,
    rows: Option<&[usize]>,
    mut emit: impl FnMut(usize, f64, f64),
) {
    let ca: Vec<[f64; 3]> = modes
        .iter()
        .map(|&(f, z)| {
            let g = (std::f64::consts::PI * (f * dt).min(0.49)).tan();
            let a1 = 1.0 / (1.0 + g * (g + 2.0 * z));
            [a1, g * a1, g * g * a1]
        })
        .collect();
    let u0 = u.first().copied().unwrap_or(0.0);
    // up to eight filters per pass, two per lane pair, their states held in registers (a pass
    // per filter would walk the record m times; all m at once keeps their states in memory)
    for (c, chunk) in ca.chunks(8).enumerate() {
        let k0 = 8 * c;
        let nf = chunk.len();
        macro_rules! walk {
            ($p:literal) => {
                resonator_walk::<$p>(u, chunk, u0, rows, |lp, bp| {
                    for k in 0..nf {
                        emit(k0 + k, lp[k / 2].lanes()[k % 2], bp[k / 2].lanes()[k % 2]);
                    }
                })
            };
        }
        match nf {
            7 | 8 => walk!(4),
            5 | 6 => walk!(3),
            3 | 4 => walk!(2),
            _ => walk!(1),
        }
    }
}

/// `resonator_each`'s pass for the filters of coefficients `ca` (2·`P` or 2·`P` − 1 of them,
/// each started at rest on `u0`), two per lane pair (`F64x2`: each lane's arithmetic is the
/// scalar one, so each filter's outputs are those of the filter run alone; an odd count's
/// last pair runs the last filter twice): at each row, `emit(low-passes, band-passes)`, lane
/// pair `p` holding filters 2·`p` and 2·`p` + 1. The samples between two rows are stepped
/// without a test per sample. The rows are taken while they ascend within the input (the
/// outputs end at the first that does not).
#[inline(always)]
pub(crate) fn resonator_walk<const P: usize>(
    u: &[f64],
    ca: &[[f64; 3]],
    u0: f64,
    rows: Option<&[usize]>,
    mut emit: impl FnMut(&[F64x2; P], &[F64x2; P]),
) {
    let nf = ca.len().min(2 * P);
    if nf == 0 {
        return;
    }
    let coef =
        |p: usize, c: usize| F64x2::new(ca[(2 * p).min(nf - 1)][c], ca[(2 * p + 1).min(nf - 1)][c]);
    let a1: [F64x2; P] = std::array::from_fn(|p| coef(p, 0));
    let a2: [F64x2; P] = std::array::from_fn(|p| coef(p, 1));
    let a3: [F64x2; P] = std::array::from_fn(|p| coef(p, 2));
    let two = F64x2::splat(2.0);
    let mut ic1 = [F64x2::splat(0.0); P];
    let mut ic2 = [F64x2::splat(u0); P];
    // one sample of every filter: (low-pass, band-pass) lane pairs
    let mut step = |xin: f64| -> ([F64x2; P], [F64x2; P]) {
        let x = F64x2::splat(xin);
        let mut lp = [F64x2::splat(0.0); P];
        let mut bp = [F64x2::splat(0.0); P];
        for p in 0..P {
            let v3 = x - ic2[p];
            let v1 = a1[p] * ic1[p] + a2[p] * v3;
            let v2 = ic2[p] + a2[p] * ic1[p] + a3[p] * v3;
            ic1[p] = two * v1 - ic1[p];
            ic2[p] = two * v2 - ic2[p];
            lp[p] = v2;
            bp[p] = v1;
        }
        (lp, bp)
    };
    match rows {
        None => {
            for &xin in u {
                let (lp, bp) = step(xin);
                emit(&lp, &bp);
            }
        }
        Some(r) => {
            // the next sample to step
            let mut i = 0;
            for &row in r {
                let Some(seg) = u.get(i..=row) else {
                    break;
                };
                let mut last = None;
                for &xin in seg {
                    last = Some(step(xin));
                }
                match last {
                    Some((lp, bp)) => emit(&lp, &bp),
                    None => break,
                }
                i = row + 1;
            }
        }
    }
}

/// Two f64 lanes with lane-wise +, − and × (`resonator_walk`'s independent filters two at a
/// time): the `wide` crate's `f64x2` (SSE2's packed doubles on x86-64, each lane rounded as the
/// scalar operation, no fused multiply-add; plain lanes elsewhere). Each lane's result is the
/// scalar operation's bit for bit (`tests::lane_pairs_are_scalar_arithmetic`).
#[derive(Clone, Copy)]
pub(crate) struct F64x2(wide::f64x2);

impl F64x2 {
    #[inline(always)]
    pub(crate) fn new(lo: f64, hi: f64) -> Self {
        F64x2(wide::f64x2::new([lo, hi]))
    }
    #[inline(always)]
    pub(crate) fn splat(v: f64) -> Self {
        F64x2(wide::f64x2::splat(v))
    }
    /// The two lanes (low, high).
    #[inline(always)]
    pub(crate) fn lanes(self) -> [f64; 2] {
        self.0.to_array()
    }
}

macro_rules! f64x2_op {
    ($tr:ident, $f:ident) => {
        impl std::ops::$tr for F64x2 {
            type Output = F64x2;
            #[inline(always)]
            fn $f(self, o: F64x2) -> F64x2 {
                F64x2(std::ops::$tr::$f(self.0, o.0))
            }
        }
    };
}

f64x2_op!(Add, add);
f64x2_op!(Sub, sub);
f64x2_op!(Mul, mul);

/// The force a modal mass of 1 kg hung on the device through a spring-damper (resonance
/// `f_hz`, damping ratio `zeta`) adds beyond its rigid-body inertia (which the baseline carries):
/// the mass follows y = H·x with H = (2ζωs + ω²)/(s² + 2ζωs + ω²), the spring-damper carries
/// m2·ÿ = m2·H·a, so the column is (H − 1)·a = LP + 2ζ·BP − a. `a` is the acceleration at
/// every sample; the column is returned at `rows` (all when None).
pub fn compliance_columns_at(
    a: &[f64],
    modes: &[(f64, f64)],
    dt: f64,
    rows: Option<&[usize]>,
) -> Vec<Vec<f64>> {
    // each filter's column formed from its outputs at each row (resonator_batch's lp, bp)
    let cap = rows.map_or(a.len(), |r| r.len());
    let mut out = vec![Vec::with_capacity(cap); modes.len()];
    resonator_each(a, modes, dt, rows, |k, lp, bp| {
        let c = &mut out[k];
        let aj = match rows {
            None => a[c.len()],
            Some(r) => a[r[c.len()]],
        };
        c.push(lp + 2.0 * modes[k].1 * bp - aj);
    });
    out
}

impl Context<'_> {
    /// The damping ratio of a mode at `f_hz` that the record shows: the profile of the
    /// least-squares fit of the force by the baseline columns and m2·(H − 1)·a over
    /// `COMPLIANCE_ZETAS`, on at most 4,000 training samples in motion (strided), refined by a
    /// parabola in ln ζ through the best value and its neighbours (clamped to the grid's range),
    /// then inside the grid by a second one over `PROFILE_FINE_STEP` of its step about that vertex.
    /// Cached per frequency: the columns, the report and the stability check use one value.
    /// None when the optimum is at the grid's upper end (no resonance peak: not a mode the
    /// record identifies; the candidate then has a zero column and is not named).
    pub fn compliance_zeta(&self, f_hz: f64) -> Option<f64> {
        let z = self.compliance_zeta_profile(f_hz);
        (z < COMPLIANCE_ZETAS[COMPLIANCE_ZETAS.len() - 1]).then_some(z)
    }

    pub(crate) fn compliance_zeta_profile(&self, f_hz: f64) -> f64 {
        if let Ok(c) = self.zeta_cache.lock() {
            if let Some(z) = c.get(&f_hz.to_bits()) {
                return *z;
            }
        }
        self.compliance_zetas_profiled(&[f_hz])
            .first()
            .copied()
            .unwrap_or(COMPLIANCE_ZETAS[4])
    }

    /// `compliance_zeta` of each frequency of `fs` (None as it gives), those not cached yet
    /// profiled together: the filters of all their damping ratios in one resonator pass (each
    /// filter's outputs are those of the filter run alone, `resonator_batch`), so the values
    /// are each frequency's own profile's.
    pub fn compliance_zetas(&self, fs: &[f64]) -> Vec<Option<f64>> {
        let mut todo: Vec<f64> = Vec::new();
        if let Ok(c) = self.zeta_cache.lock() {
            for &f in fs {
                if !c.contains_key(&f.to_bits()) && !todo.iter().any(|t| t.to_bits() == f.to_bits())
                {
                    todo.push(f);
                }
            }
        }
        if !todo.is_empty() {
            self.compliance_zetas_profiled(&todo);
        }
        fs.iter().map(|&f| self.compliance_zeta(f)).collect()
    }

    /// The damping-ratio profile (`compliance_zeta`) of each frequency of `fs`, its filters
    /// over `COMPLIANCE_ZETAS` for every frequency in one resonator pass; each value cached.
    pub(crate) fn compliance_zetas_profiled(&self, fs: &[f64]) -> Vec<f64> {
        let n = self.rec.len();
        let pr = self.profile_rows.get_or_init(|| {
            let rows = self.training_rows(self.window.min(PROFILE_WINDOW), PROFILE_ROWS);
            let cols: Vec<Vec<f64>> = if rows.len() < 10 || self.base_pred.len() != n {
                Vec::new()
            } else {
                base_columns_borrowed(self)
                    .into_iter()
                    .map(|(_, c)| rows.iter().map(|&i| c[i]).collect())
                    .collect()
            };
            let f = rows.iter().map(|&i| self.rec.f[i]).collect();
            FitRows { rows, cols, f }
        });
        let (rows, base, f) = (&pr.rows, &pr.cols, &pr.f);
        let zs: Vec<f64> = if rows.len() < 10 || self.base_pred.len() != n {
            vec![COMPLIANCE_ZETAS[4]; fs.len()]
        } else {
            let modes: Vec<(f64, f64)> = fs
                .iter()
                .flat_map(|&f_hz| COMPLIANCE_ZETAS.iter().map(move |&z| (f_hz, z)))
                .collect();
            let all = compliance_columns_at(&self.rec.a, &modes, self.dt, Some(rows));
            let coarse: Vec<f64> = all
                .chunks(COMPLIANCE_ZETAS.len())
                .map(|cols| zeta_of_profile(&profile_rss(base, f, cols)))
                .collect();
            // the second parabola about each vertex inside the grid
            let h = PROFILE_FINE_STEP * (COMPLIANCE_ZETAS[1] / COMPLIANCE_ZETAS[0]).ln();
            let inside = |z: f64| {
                z > COMPLIANCE_ZETAS[0] && z < COMPLIANCE_ZETAS[COMPLIANCE_ZETAS.len() - 1]
            };
            let fine_modes: Vec<(f64, f64)> = fs
                .iter()
                .zip(&coarse)
                .filter(|(_, &z)| inside(z))
                .flat_map(|(&f_hz, &z)| [-h, 0.0, h].map(|d| (f_hz, (z.ln() + d).exp())))
                .collect();
            let fine = compliance_columns_at(&self.rec.a, &fine_modes, self.dt, Some(rows));
            let mut fine = fine.chunks(3);
            coarse
                .iter()
                .map(|&z| match inside(z).then(|| fine.next()).flatten() {
                    // the fine columns were taken for the frequencies inside the grid only
                    Some(cols) => {
                        let r = profile_rss(base, f, cols);
                        (z.ln() + vertex_step([r[0], r[1], r[2]], h)).exp()
                    }
                    None => z,
                })
                .collect()
        };
        if let Ok(mut c) = self.zeta_cache.lock() {
            for (f_hz, z) in fs.iter().zip(&zs) {
                c.insert(f_hz.to_bits(), *z);
            }
        }
        zs
    }
}

/// The rss of the joint fit of the baseline columns `base` and each of the mode's columns
/// `cols` (one per damping ratio, at the profile's rows) to the force `f` at those rows.
pub(crate) fn profile_rss(base: &[Vec<f64>], f: &[f64], cols: &[Vec<f64>]) -> Vec<f64> {
    // the joint fit of the baseline columns and the mode's column (what the selection fits),
    // per damping ratio
    let ff: f64 = f.iter().map(|v| v * v).sum();
    let dot = |x: &[f64], y: &[f64]| -> f64 { x.iter().zip(y).map(|(x, y)| x * y).sum() };
    // the baseline columns' products (the same for every damping ratio: once), then per
    // damping ratio the mode column's row and column of the normal equations
    let nb = base.len();
    let m = nb + 1;
    let mut g0 = vec![0.0; m * m];
    let mut bb0 = vec![0.0; m];
    for p in 0..nb {
        for q in p..nb {
            let d = dot(&base[p], &base[q]);
            g0[p * m + q] = d;
            g0[q * m + p] = d;
        }
        bb0[p] = dot(&base[p], f);
    }
    cols.iter()
        .map(|c| {
            let (mut g, mut bb) = (g0.clone(), bb0.clone());
            for p in 0..nb {
                let d = dot(&base[p], c);
                g[p * m + nb] = d;
                g[nb * m + p] = d;
            }
            g[nb * m + nb] = dot(c, c);
            bb[nb] = dot(c, f);
            let th = crate::solve_sym(&g, &bb, m).th;
            let mut r = ff;
            for p in 0..m {
                r -= 2.0 * th[p] * bb[p];
                for q in 0..m {
                    r += th[p] * g[p * m + q] * th[q];
                }
            }
            r
        })
        .collect()
}

/// ln ζ at the vertex of the parabola through the rss at ln ζ − h, ln ζ, ln ζ + h (`y`),
/// moved by at most h (0 where the three do not curve upwards).
fn vertex_step(y: [f64; 3], h: f64) -> f64 {
    let den = y[0] - 2.0 * y[1] + y[2];
    let d = if den > 0.0 {
        0.5 * (y[0] - y[2]) / den
    } else {
        0.0
    };
    d.clamp(-1.0, 1.0) * h
}

/// The damping ratio of `compliance_zeta`'s profile from the rss over `COMPLIANCE_ZETAS`
/// (`profile_rss`): the grid's least, or inside the grid the vertex of the parabola in ln ζ
/// through it and its neighbours.
pub(crate) fn zeta_of_profile(rss: &[f64]) -> f64 {
    let k = (0..rss.len())
        .min_by(|&i, &j| rss[i].total_cmp(&rss[j]))
        .unwrap_or(4);
    if k == 0 || k + 1 == rss.len() {
        COMPLIANCE_ZETAS[k]
    } else {
        let h = (COMPLIANCE_ZETAS[k + 1] / COMPLIANCE_ZETAS[k]).ln();
        (COMPLIANCE_ZETAS[k].ln() + vertex_step([rss[k - 1], rss[k], rss[k + 1]], h)).exp()
    }
}

/// The step (in ln ζ) of the profile's second parabola, about the first's vertex: a quarter
/// of the grid's. The rss is not a parabola in ln ζ over the grid's step (a mode's column
/// changes shape with ζ), so the first vertex lies a few per cent off the optimum; over a
/// quarter step it is close to one.
pub const PROFILE_FINE_STEP: f64 = 0.25;
