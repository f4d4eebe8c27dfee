//! Model diagnosis: fit the baseline device model to a measured record, show what it gets
//! wrong, name the cause from a catalogue of physical effects, extend the model and measure
//! the gain on held-out data. See docs/diagnose.md.

// Numerical kernels index several arrays in step; iterator rewrites would obscure them.
#![allow(clippy::needless_range_loop)]

pub mod cli;
pub mod effects;
pub mod model;
pub mod record;
pub mod report;
pub mod synth;

pub use effects::{Effect, EffectKind};
pub use record::{parse_csv, read_csv, Record, RecordError};

/// Options of a diagnosis run.
#[derive(Debug, Clone)]
pub struct Options {
    /// Held-out relative rss improvement a candidate must bring to be kept (fraction, e.g. 0.02
    /// = the held-out residual sum of squares falls by at least 2 %), on top of a BIC decrease.
    pub min_holdout_gain: f64,
    /// Maximum number of effects added.
    pub max_effects: usize,
    /// Samples used for screening candidates (strided subsample of the record); the final
    /// refit uses every sample.
    pub screen_samples: usize,
    /// Samples from the record's start the candidates are screened on (`SCREEN_WINDOW`; the
    /// whole record when it is shorter).
    pub screen_window: usize,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            min_holdout_gain: 0.02,
            max_effects: 6,
            screen_samples: 10_000,
            screen_window: SCREEN_WINDOW,
        }
    }
}

/// Samples from the record's start over which candidates are screened (forward selection and
/// swap pass: the screening subsample is strided over them, with their own held-out blocks,
/// `holdout_mask` of the window). A column that walks the record's history (resonator, Dahl
/// state, the device behind a play) is walked up to its last screening row, so on a long
/// record every scanned value walks this window instead of the whole record (50 s at 1 kHz,
/// five times the 10,000 screening rows; the damping-ratio profile's rows lie in it too).
/// What is kept is checked and reported on the whole record: the stability segments (a
/// finding selected in the window must hold on segments of the whole record, four of five
/// lying outside it), the final fit and every reported error. Records up to this length are
/// screened over all their samples, exactly as without the window.
pub const SCREEN_WINDOW: usize = 50_000;

/// Samples screened on a record of `n` samples by default: `n`, at most `SCREEN_WINDOW`.
pub fn screen_window(n: usize) -> usize {
    n.min(SCREEN_WINDOW)
}

/// Part of the record a sample belongs to: training.
pub const TRAIN: u8 = 0;
/// Held out (validation).
pub const HELD_OUT: u8 = 1;
/// Left out of every fit (the device is at rest: friction is static, anywhere within its
/// breakaway level, and carries no Coulomb sign).
pub const AT_REST: u8 = 2;

/// Training / held-out split: the record is cut into 10 consecutive blocks and every third
/// block (indices 2, 5, 8) is held out, so both parts span the whole trajectory.
pub fn holdout_mask(n: usize) -> Vec<u8> {
    (0..n)
        .map(|i| {
            if (i * 10 / n) % 3 == 2 {
                HELD_OUT
            } else {
                TRAIN
            }
        })
        .collect()
}

/// Accumulated normal equations of a column set against the force on one part of the record.
#[derive(Debug, Clone)]
pub struct Normal {
    pub m: usize,
    pub g: Vec<f64>,
    pub b: Vec<f64>,
    pub ff: f64,
    pub n: usize,
}

impl Normal {
    fn new(m: usize) -> Self {
        Normal {
            m,
            g: vec![0.0; m * m],
            b: vec![0.0; m],
            ff: 0.0,
            n: 0,
        }
    }
    /// Least squares solution (see `solve_sym`: SVD, minimum norm when rank deficient).
    pub fn solve(&self) -> Vec<f64> {
        solve_sym(&self.g, &self.b, self.m).th
    }
    /// Least squares solution with its rank and condition number.
    pub fn solve_full(&self) -> LsSolution {
        solve_sym(&self.g, &self.b, self.m)
    }
    /// Normal equations of a subset of the columns (indices into this set, in order).
    pub fn select(&self, idx: &[usize]) -> Normal {
        let k = idx.len();
        let mut g = vec![0.0; k * k];
        for (r, &i) in idx.iter().enumerate() {
            for (c, &j) in idx.iter().enumerate() {
                g[r * k + c] = self.g[i * self.m + j];
            }
        }
        Normal {
            m: k,
            g,
            b: idx.iter().map(|&i| self.b[i]).collect(),
            ff: self.ff,
            n: self.n,
        }
    }
    /// Normal equations of the union of two parts.
    pub fn plus(&self, o: &Normal) -> Normal {
        Normal {
            m: self.m,
            g: self.g.iter().zip(&o.g).map(|(a, b)| a + b).collect(),
            b: self.b.iter().zip(&o.b).map(|(a, b)| a + b).collect(),
            ff: self.ff + o.ff,
            n: self.n + o.n,
        }
    }
    /// Residual sum of squares of coefficients `th` on this part.
    pub fn rss(&self, th: &[f64]) -> f64 {
        let m = self.m;
        let mut r = self.ff;
        for i in 0..m {
            r -= 2.0 * th[i] * self.b[i];
            for j in 0..m {
                r += th[i] * self.g[i * m + j] * th[j];
            }
        }
        r.max(0.0)
    }
}

/// Rank of a `lag` τ whose gain only the errors-in-variables correction brings into the unit
/// range, scaled by (1 + |corrected gain − 1|): above any held-out rss, so such a τ is taken
/// only when no τ's least-squares gain is a unit one.
const CORRECTED_RANK: f64 = 1e200;

/// The errors-in-variables corrected fit of `lag` (Fuller 1987, §2.2): the training normal
/// equations with the derived signals' noise taken out, (XᵀX − n·S)·θ = Xᵀf, S
/// (`Context::lag_noise`) the per-row noise covariance of the columns at `idx` (inertia,
/// viscous, the lag's column). Least squares on noisy columns biases the lag's gain low (its
/// column differences the derived a and v over τ, whose noise it carries in full); this fit
/// does not. Gives the corrected coefficients and the held-out rss they leave on error-free
/// columns (the held-out rss less n_h·θᵀSθ, the noise's share): the criterion that chooses τ
/// (the uncorrected held-out rss falls with a longer τ, whose column carries less noise per
/// signal). None when the noise is more than half of the lag column's energy on the training
/// rows (the correction more than doubles the gain: the record does not resolve τ). The
/// scan asks the same of a `compliance` column (idx[2] the mode's, S `Context::compliance_noise`).
pub fn lag_corrected(
    tr: &Normal,
    ho: &Normal,
    idx: [usize; 3],
    s: &[[f64; 3]; 3],
) -> Option<(Vec<f64>, f64)> {
    let z = idx[2] * tr.m + idx[2];
    let left = tr.g[z] - tr.n as f64 * s[2][2];
    if left.is_nan() || left < 0.5 * tr.g[z] {
        return None;
    }
    eiv_fit(tr, ho, &idx, s)
}

/// The errors-in-variables corrected least squares (Fuller 1987, §2.2) on the columns at
/// `idx` (at most 3) with per-row noise covariance `s` (its leading idx.len() rows and
/// columns): the coefficients of (XᵀX − n·S)·θ = Xᵀf and the held-out rss they leave on
/// error-free columns (the held-out rss less n_h·θᵀSθ). None when either is not finite.
pub fn eiv_fit(
    tr: &Normal,
    ho: &Normal,
    idx: &[usize],
    s: &[[f64; 3]; 3],
) -> Option<(Vec<f64>, f64)> {
    let m = tr.m;
    let mut g = tr.g.clone();
    let n = tr.n as f64;
    for (r, &i) in idx.iter().enumerate().take(3) {
        for (c, &j) in idx.iter().enumerate().take(3) {
            g[i * m + j] -= n * s[r][c];
        }
    }
    let th = solve_sym(&g, &tr.b, m).th;
    let mut q = 0.0;
    for (r, &i) in idx.iter().enumerate().take(3) {
        for (c, &j) in idx.iter().enumerate().take(3) {
            q += th[i] * s[r][c] * th[j];
        }
    }
    let rss = ho.rss(&th) - ho.n as f64 * q;
    (th.iter().all(|v| v.is_finite()) && rss.is_finite()).then_some((th, rss.max(0.0)))
}

/// Singular values of the scaled Gram matrix below this fraction of the largest are treated
/// as zero (a design-matrix direction with a singular value below 1e-5 of the largest: columns
/// collinear to within the rounding of the accumulated sums, whose coefficient the data does
/// not determine).
pub const RCOND: f64 = 1e-10;

/// A least-squares solution with its numerical quality.
#[derive(Debug, Clone, PartialEq)]
pub struct LsSolution {
    /// Coefficients (minimum-norm among the solutions when the columns are rank deficient).
    pub th: Vec<f64>,
    /// Numerical rank of the column set (singular values of the scaled Gram matrix above
    /// `RCOND` times the largest).
    pub rank: usize,
    /// Condition number of the column set (design matrix, columns scaled to unit norm):
    /// sqrt of the ratio of the extreme singular values of the scaled Gram matrix kept in the
    /// rank (∞ when no column carries energy).
    pub condition: f64,
}

/// Solve the normal equations G th = b (G symmetric positive semi-definite, m x m) by the
/// singular value decomposition of nalgebra: columns scaled to unit diagonal (so the
/// threshold is independent of the units), singular values below `RCOND` of the largest
/// dropped (pseudo-inverse: the minimum-norm least-squares solution), rank and condition
/// number reported. A column with no energy gets coefficient 0.
pub fn solve_sym(g: &[f64], b: &[f64], m: usize) -> LsSolution {
    let d: Vec<f64> = (0..m)
        .map(|i| {
            let v = g[i * m + i];
            if v > 0.0 && v.is_finite() {
                1.0 / v.sqrt()
            } else {
                0.0
            }
        })
        .collect();
    if m == 0 {
        return LsSolution {
            th: vec![],
            rank: 0,
            condition: 1.0,
        };
    }
    let a = nalgebra::DMatrix::from_fn(m, m, |i, j| g[i * m + j] * d[i] * d[j]);
    let rhs = nalgebra::DVector::from_fn(m, |i, _| b[i] * d[i]);
    if !(a.iter().all(|v| v.is_finite()) && rhs.iter().all(|v| v.is_finite())) {
        return LsSolution {
            th: vec![0.0; m],
            rank: 0,
            condition: f64::INFINITY,
        };
    }
    // a bounded number of iterations: None (no convergence) is stated as rank 0, never a panic
    let Some(svd) = nalgebra::linalg::SVD::try_new(a, true, true, f64::EPSILON, 10_000) else {
        return LsSolution {
            th: vec![0.0; m],
            rank: 0,
            condition: f64::INFINITY,
        };
    };
    let smax = svd.singular_values.max();
    if smax <= 0.0 {
        return LsSolution {
            th: vec![0.0; m],
            rank: 0,
            condition: f64::INFINITY,
        };
    }
    let tol = RCOND * smax;
    let kept: Vec<f64> = svd
        .singular_values
        .iter()
        .copied()
        .filter(|s| *s > tol)
        .collect();
    let smin = kept.iter().copied().fold(f64::MAX, f64::min);
    let x = match svd.solve(&rhs, tol) {
        Ok(x) => x,
        Err(_) => nalgebra::DVector::zeros(m),
    };
    LsSolution {
        th: (0..m).map(|i| x[i] * d[i]).collect(),
        rank: kept.len(),
        condition: (smax / smin).sqrt(),
    }
}

/// Normal equations of `cols` against `f` on the training (mask false) and held-out (mask
/// true) samples, visiting every `stride`-th sample.
/// `part` holds `TRAIN`, `HELD_OUT` or `AT_REST` (in neither) per sample.
pub fn normals(cols: &[&[f64]], f: &[f64], part: &[u8], stride: usize) -> (Normal, Normal) {
    // up to 10 columns (the baseline, a drift and the findings' columns of a record): the
    // same sums with the column count known when compiled (`normals_k`)
    match cols.len() {
        1 => normals_k::<1>(cols, f, part, stride),
        2 => normals_k::<2>(cols, f, part, stride),
        3 => normals_k::<3>(cols, f, part, stride),
        4 => normals_k::<4>(cols, f, part, stride),
        5 => normals_k::<5>(cols, f, part, stride),
        6 => normals_k::<6>(cols, f, part, stride),
        7 => normals_k::<7>(cols, f, part, stride),
        8 => normals_k::<8>(cols, f, part, stride),
        9 => normals_k::<9>(cols, f, part, stride),
        10 => normals_k::<10>(cols, f, part, stride),
        _ => normals_any(cols, f, part, stride),
    }
}

/// `normals` for `M` columns: each sum takes the same products in the same order as
/// `normals_any`, so the result is the same bit for bit (`tests::normals_k_matches_any`); the
/// loops over the columns are unrolled and the sums kept in fixed arrays.
fn normals_k<const M: usize>(
    cols: &[&[f64]],
    f: &[f64],
    part: &[u8],
    stride: usize,
) -> (Normal, Normal) {
    let n = f.len();
    let c: [&[f64]; M] = std::array::from_fn(|k| &cols[k][..n]);
    let part = &part[..n];
    let mut g = [[[0.0f64; M]; M]; 2];
    let mut b = [[0.0f64; M]; 2];
    let mut ff = [0.0f64; 2];
    let mut cnt = [0usize; 2];
    let mut i = 0;
    while i < n {
        let s = match part[i] {
            TRAIN => 0,
            HELD_OUT => 1,
            _ => {
                i += stride;
                continue;
            }
        };
        let row: [f64; M] = std::array::from_fn(|k| c[k][i]);
        let fi = f[i];
        let (g, b) = (&mut g[s], &mut b[s]);
        for p in 0..M {
            let rp = row[p];
            b[p] += rp * fi;
            for q in p..M {
                g[p][q] += rp * row[q];
            }
        }
        ff[s] += fi * fi;
        cnt[s] += 1;
        i += stride;
    }
    let out = |s: usize| {
        let mut nm = Normal::new(M);
        for p in 0..M {
            for q in 0..M {
                nm.g[p * M + q] = if q >= p { g[s][p][q] } else { g[s][q][p] };
            }
            nm.b[p] = b[s][p];
        }
        nm.ff = ff[s];
        nm.n = cnt[s];
        nm
    };
    (out(0), out(1))
}

/// `normals` for any number of columns.
fn normals_any(cols: &[&[f64]], f: &[f64], part: &[u8], stride: usize) -> (Normal, Normal) {
    let m = cols.len();
    let mut tr = Normal::new(m);
    let mut ho = Normal::new(m);
    let mut row = vec![0.0; m];
    let n = f.len();
    let mut i = 0;
    while i < n {
        for (k, c) in cols.iter().enumerate() {
            row[k] = c[i];
        }
        let nm = match part[i] {
            TRAIN => &mut tr,
            HELD_OUT => &mut ho,
            _ => {
                i += stride;
                continue;
            }
        };
        for p in 0..m {
            let rp = row[p];
            nm.b[p] += rp * f[i];
            for q in p..m {
                nm.g[p * m + q] += rp * row[q];
            }
        }
        nm.ff += f[i] * f[i];
        nm.n += 1;
        i += stride;
    }
    for nm in [&mut tr, &mut ho] {
        for p in 0..m {
            for q in 0..p {
                nm.g[p * m + q] = nm.g[q * m + p];
            }
        }
    }
    (tr, ho)
}

/// Training / held-out weights (1/0 and 0/1) of the samples, and the runs of consecutive
/// training or held-out samples (samples at rest in neither).
pub struct HoldWeights {
    pub train: Vec<f64>,
    pub hold: Vec<f64>,
    /// (start, end, held out) of each run of samples of one part.
    pub runs: Vec<(usize, usize, bool)>,
}

impl HoldWeights {
    pub fn new(part: &[u8]) -> Self {
        let mut runs: Vec<(usize, usize, bool)> = Vec::new();
        for (i, &h) in part.iter().enumerate() {
            if h != TRAIN && h != HELD_OUT {
                continue;
            }
            let held = h == HELD_OUT;
            match runs.last_mut() {
                Some(r) if r.1 == i && r.2 == held => r.1 = i + 1,
                _ => runs.push((i, i + 1, held)),
            }
        }
        HoldWeights {
            train: part.iter().map(|&h| (h == TRAIN) as u8 as f64).collect(),
            hold: part.iter().map(|&h| (h == HELD_OUT) as u8 as f64).collect(),
            runs,
        }
    }
}

/// (Σ a·b·w_train, Σ a·b·w_held) over contiguous slices, four partial sums each (independent
/// accumulation chains, so the loop runs at arithmetic throughput): sample i goes to partial
/// sum i mod 4 (the last len mod 4 samples to the first), the four summed pairwise. Only the
/// runs of training and held-out samples are visited, each product added to its part's sums
/// alone: the weighted sum over every sample adds the same products in the same order plus
/// zeros, so the result is the same bit for bit (`tests::dot2_runs_match_weighted_sums`).
fn dot2(a: &[f64], b: &[f64], w: &HoldWeights) -> (f64, f64) {
    dot2_k(a, [b], w)[0]
}

/// `dot2` of `a` with each of `K` columns of one length in one pass over `a` (its loads shared,
/// 4·K independent chains): each column's partial sums take the same products in the same
/// order as `dot2` alone, so each result is `dot2`'s bit for bit.
#[inline(always)]
fn dot2_k<const K: usize>(a: &[f64], bs: [&[f64]; K], w: &HoldWeights) -> [(f64, f64); K] {
    let n = bs
        .iter()
        .fold(a.len().min(w.train.len()), |n, b| n.min(b.len()));
    let a = &a[..n];
    let bs = bs.map(|b| &b[..n]);
    let mut acc = [[[0.0f64; 4]; 2]; K];
    let m = n / 4 * 4;
    let lane = |i: usize| if i < m { i % 4 } else { 0 };
    for &(s, e, held) in &w.runs {
        let e = e.min(n);
        let mut loc = acc.map(|p| p[held as usize]);
        let mut i = s;
        while i < e && i % 4 != 0 {
            for k in 0..K {
                loc[k][lane(i)] += a[i] * bs[k][i];
            }
            i += 1;
        }
        let body = e.min(m);
        while i + 4 <= body {
            let ai = &a[i..i + 4];
            for k in 0..K {
                let bi = &bs[k][i..i + 4];
                for l in 0..4 {
                    loc[k][l] += ai[l] * bi[l];
                }
            }
            i += 4;
        }
        while i < e {
            for k in 0..K {
                loc[k][lane(i)] += a[i] * bs[k][i];
            }
            i += 1;
        }
        for k in 0..K {
            acc[k][held as usize] = loc[k];
        }
    }
    acc.map(|[t, h]| ((t[0] + t[1]) + (t[2] + t[3]), (h[0] + h[1]) + (h[2] + h[3])))
}

/// `dot2` of `a` with each column of `bs`, four (then two, then one) columns per pass over `a`
/// (`dot2_k`): the same results as `dot2` column by column, bit for bit.
fn dot2_many(a: &[f64], bs: &[&[f64]], w: &HoldWeights) -> Vec<TrainHold> {
    let mut out = Vec::with_capacity(bs.len());
    let mut rest = bs;
    // the columns of one pass must have one length (`dot2_k` takes the shortest)
    let same = |c: &[&[f64]]| c.iter().all(|b| b.len() == c[0].len());
    while !rest.is_empty() {
        let take = if rest.len() >= 4 && same(&rest[..4]) {
            out.extend(dot2_k(a, [rest[0], rest[1], rest[2], rest[3]], w));
            4
        } else if rest.len() >= 2 && same(&rest[..2]) {
            out.extend(dot2_k(a, [rest[0], rest[1]], w));
            2
        } else {
            out.push(dot2(a, rest[0], w));
            1
        };
        rest = &rest[take..];
    }
    out
}

/// Normal equations of `p` columns copied into the top-left block of `m`-column ones.
fn embed(src: &Normal, p: usize, m: usize) -> Normal {
    let mut dst = Normal::new(m);
    for i in 0..p {
        dst.g[i * m..i * m + p].copy_from_slice(&src.g[i * p..i * p + p]);
        dst.b[i] = src.b[i];
    }
    dst.ff = src.ff;
    dst.n = src.n;
    dst
}

/// Extend normal equations of base columns (already accumulated) with extra columns `z` over
/// every sample: only the cross terms are computed (O(N·k·(p+k))), each new Gram entry one
/// contiguous weighted dot product (training and held-out parts at once).
pub fn extend_normals_dense(
    base: &(Normal, Normal),
    bcols: &[&[f64]],
    z: &[&[f64]],
    f: &[f64],
    w: &HoldWeights,
) -> (Normal, Normal) {
    let p = bcols.len();
    let k = z.len();
    let m = p + k;
    let mut out = (embed(&base.0, p, m), embed(&base.1, p, m));
    for c in 0..k {
        let row = p + c;
        let others: Vec<&[f64]> = bcols.iter().chain(&z[..=c]).chain([&f]).copied().collect();
        let prods = dot2_many(z[c], &others, w);
        for (j, &(t, h)) in prods[..row + 1].iter().enumerate() {
            out.0.g[row * m + j] = t;
            out.0.g[j * m + row] = t;
            out.1.g[row * m + j] = h;
            out.1.g[j * m + row] = h;
        }
        let (t, h) = prods[row + 1];
        out.0.b[row] = t;
        out.1.b[row] = h;
    }
    out
}

/// The Gram entries of a candidate's columns already computed against base columns (each
/// base column's identity, given by the caller, with its training and held-out products),
/// against each other and against the force. A candidate screened again on another base (a
/// later round, or the swap pass's sets without one finding) needs only the products with the
/// base columns it has not met (the others are the same sums over the same rows).
#[derive(Debug, Default, Clone)]
pub struct GramCache {
    /// Per candidate column: per base column met (its identity), the products.
    cross: Vec<Vec<(ColumnId, TrainHold)>>,
    /// Per candidate column c: products with candidate columns 0..=c, then with the force.
    own: Vec<(Vec<TrainHold>, TrainHold)>,
}

/// A column's identity within one diagnosis: two columns with the same identity hold the
/// same values (the caller's promise; `diagnose_checked` names a fixed term by its index and
/// an effect's column by its kind, parameter and index). Not an address: columns rebuilt for
/// another set reuse freed memory.
pub type ColumnId = (u64, u64);
/// A sum over the training and over the held-out samples.
type TrainHold = (f64, f64);

/// `extend_normals_dense` keeping the products already computed in `gc` (see `GramCache`): the
/// result is the same, entry by entry (`tests::cached_gram_matches_dense`). Products with a base
/// column whose identity (`bids`, one per column of `bcols`) is not in the cache are computed
/// and kept.
pub fn extend_normals_cached(
    base: &(Normal, Normal),
    bcols: &[&[f64]],
    bids: &[ColumnId],
    z: &[&[f64]],
    f: &[f64],
    w: &HoldWeights,
    gc: &mut GramCache,
) -> (Normal, Normal) {
    let p = bcols.len();
    let k = z.len();
    let m = p + k;
    if gc.own.len() != k {
        gc.own = (0..k)
            .map(|c| {
                let others: Vec<&[f64]> = z[..=c].iter().chain([&f]).copied().collect();
                let mut zz = dot2_many(z[c], &others, w);
                let zf = zz.pop().unwrap_or_default();
                (zz, zf)
            })
            .collect();
        gc.cross = vec![Vec::new(); k];
    }
    let mut out = (embed(&base.0, p, m), embed(&base.1, p, m));
    for c in 0..k {
        let row = p + c;
        let cr = &mut gc.cross[c];
        // the products with the base columns not met yet, in one batch
        let (new_ids, new_cols): (Vec<ColumnId>, Vec<&[f64]>) = bids
            .iter()
            .zip(bcols)
            .filter(|(id, _)| !cr.iter().any(|e| e.0 == **id))
            .map(|(id, bc)| (*id, *bc))
            .unzip();
        for (id, th) in new_ids.into_iter().zip(dot2_many(z[c], &new_cols, w)) {
            cr.push((id, th));
        }
        let prods: Vec<TrainHold> = bids
            .iter()
            .zip(bcols)
            .map(|(id, _)| cr.iter().find(|e| e.0 == *id).map_or((0.0, 0.0), |e| e.1))
            .collect();
        let (zz, zf) = &gc.own[c];
        for (j, &(t, h)) in prods.iter().chain(zz.iter()).enumerate() {
            out.0.g[row * m + j] = t;
            out.0.g[j * m + row] = t;
            out.1.g[row * m + j] = h;
            out.1.g[j * m + row] = h;
        }
        out.0.b[row] = zf.0;
        out.1.b[row] = zf.1;
    }
    out
}

/// Normal equations `nn` of `cols` with the contributions of the samples `rows` (indices into
/// the columns, each counted in its part of `part`) removed (`sign` −1) or added back (+1): the
/// same sums as `normals` over the other samples, at the cost of the rows changed.
pub fn change_rows(
    nn: &(Normal, Normal),
    cols: &[&[f64]],
    f: &[f64],
    part: &[u8],
    rows: &[usize],
    sign: f64,
) -> (Normal, Normal) {
    let mut out = nn.clone();
    let m = cols.len();
    for &i in rows {
        let nm = match part[i] {
            TRAIN => &mut out.0,
            HELD_OUT => &mut out.1,
            _ => continue,
        };
        // each product once for both of its entries: (s·c_p)·c_q is s·(c_p·c_q) exactly for
        // s = ±1, so g[q][p] gets the bits it would get from its own product
        for p in 0..m {
            let rp = sign * cols[p][i];
            nm.b[p] += rp * f[i];
            nm.g[p * m + p] += rp * cols[p][i];
            for q in p + 1..m {
                let t = rp * cols[q][i];
                nm.g[p * m + q] += t;
                nm.g[q * m + p] += t;
            }
        }
        nm.ff += sign * f[i] * f[i];
        if sign < 0.0 {
            nm.n -= 1;
        } else {
            nm.n += 1;
        }
    }
    out
}

/// Relative error ‖f − f̂‖₂/‖f‖₂ from rss and ‖f‖².
pub fn rel(rss: f64, ff: f64) -> f64 {
    if ff > 0.0 {
        (rss / ff).sqrt()
    } else {
        0.0
    }
}

/// Bayesian information criterion of a least-squares fit (Gaussian residual).
pub fn bic(rss: f64, n: usize, k: usize) -> f64 {
    let n = n.max(1) as f64;
    n * (rss / n).max(1e-300).ln() + k as f64 * n.ln()
}

/// One kept finding.
#[derive(Debug, Clone)]
pub struct Finding {
    /// Catalogue name or `unexplained`.
    pub effect: String,
    /// Named fitted parameters.
    pub parameters: Vec<(String, f64)>,
    /// Held-out rss fraction removed, BIC change, and free text.
    pub holdout_rss_drop: f64,
    pub delta_bic: f64,
    pub note: String,
    pub holdout_rel_error_after: f64,
    /// Fraction of the independent segments of the record on which the finding held (see
    /// `STABILITY_SEGMENTS`); 0 for `unexplained`.
    pub consistency: f64,
}

/// A baseline term with its significance (held-out error when it is dropped).
#[derive(Debug, Clone)]
pub struct BaselineTerm {
    pub effect: String,
    pub value: f64,
    pub unit: String,
    pub holdout_rel_error_without: f64,
    pub significant: bool,
}

/// Everything the diagnosis produced.
#[derive(Debug, Clone, Default)]
pub struct Diagnosis {
    pub n: usize,
    /// Stated verdicts, reported first: a record the diagnosis cannot use, a baseline that is
    /// not physical (with what it suggests), samples left out at rest.
    pub verdicts: Vec<String>,
    pub derivative_method: String,
    pub baseline_terms: Vec<BaselineTerm>,
    pub baseline_holdout_rel_error: f64,
    pub baseline_train_rel_error: f64,
    /// Baseline refitted on the whole record, error on the whole record (comparable with
    /// published figures that fit and evaluate on the same record).
    pub baseline_full_rel_error: f64,
    pub findings: Vec<Finding>,
    pub final_holdout_rel_error: f64,
    pub final_full_rel_error: f64,
    /// Final model: column names and coefficients (fitted on the whole record).
    pub model: Vec<(String, f64)>,
    /// The model after each stage, refitted on the whole record: index 0 the baseline,
    /// index k the baseline with the first k findings (the cross-check evaluates each).
    pub stage_models: Vec<Vec<(String, f64)>>,
    pub effects: Vec<Effect>,
    pub residual: Vec<f64>,
    pub prediction: Vec<f64>,
    pub whiteness: report::Whiteness,
    pub spectrum_peaks: Vec<report::Peak>,
    /// Spectrum of the final residual over position (binned per direction of motion).
    pub position_spectrum: report::PositionSpectrum,
    /// Error of the final model on a second record (cross-test), when given.
    pub cross: Option<CrossCheck>,
    /// Numerical rank of the final model's columns on the whole record (= `model.len()` when
    /// every coefficient is determined by the data).
    pub fit_rank: usize,
    /// Condition number of the final model's design matrix (columns scaled to unit norm).
    pub fit_condition: f64,
}

impl Diagnosis {
    /// The catalogue names among the findings, in order (`unexplained` left out).
    pub fn catalogue_names(&self) -> Vec<&str> {
        self.findings
            .iter()
            .filter(|f| f.effect != "unexplained")
            .map(|f| f.effect.as_str())
            .collect()
    }
}

#[derive(Debug, Clone)]
pub struct CrossCheck {
    pub baseline_rel_error: f64,
    pub final_rel_error: f64,
    /// Per finding: relative error on the second record with effects up to this one.
    pub after_each: Vec<(String, f64)>,
    /// Per finding: true when it makes the second record's error worse than the stage before.
    pub worsens: Vec<bool>,
}

/// Independent segments of the record over which each finding's stability is checked.
pub const STABILITY_SEGMENTS: usize = 5;
/// Segments (of `STABILITY_SEGMENTS`) on which a finding must hold to be kept.
pub const STABILITY_MIN: usize = 4;
/// Rounds of the swap and backward pass after forward selection (each round tries every
/// finding's removal and replacement, then resumes forward selection).
pub const SWAP_ROUNDS: usize = 4;
/// Nuisance columns of a slow change of the force offset over the record (not a catalogue
/// effect: reported as `unexplained`).
pub const DRIFT_COLUMNS: [&str; 2] = ["drift.t_legendre1", "drift.t_legendre2"];
/// Agreement of a finding's coefficients across the stability segments: its jackknife t
/// (the segment fits' mean coefficient vector over the jackknife standard error of their
/// projections on it) must reach this. With 5 leave-one-segment-out fits, t ≥ 3 means the
/// coefficient is determined to within a third of its value by every part of the record (a
/// two-sided 4 % level for a t variable with 4 degrees of freedom); a fit that the segments
/// scatter around zero or across a wide range is not the same effect throughout the record.
pub const AGREEMENT_T: f64 = 3.0;

/// Jackknife t of coefficient vectors fitted with one segment left out each: |θ̄| over the
/// jackknife standard error √((S−1)/S·Σ(p_i − p̄)²) of the projections p_i = θ_i·θ̄/|θ̄|
/// (0 when there are fewer than 3 fits or θ̄ = 0; ∞ when they agree exactly).
pub fn jackknife_t(fits: &[Vec<f64>]) -> f64 {
    let s = fits.len();
    if s < 3 {
        return 0.0;
    }
    let m = fits[0].len();
    let mean: Vec<f64> = (0..m)
        .map(|j| fits.iter().map(|f| f[j]).sum::<f64>() / s as f64)
        .collect();
    let norm = mean.iter().map(|v| v * v).sum::<f64>().sqrt();
    if !(norm > 0.0 && norm.is_finite()) {
        return 0.0;
    }
    let p: Vec<f64> = fits
        .iter()
        .map(|f| f.iter().zip(&mean).map(|(a, b)| a * b).sum::<f64>() / norm)
        .collect();
    let pm = p.iter().sum::<f64>() / s as f64;
    let se = ((s - 1) as f64 / s as f64 * p.iter().map(|v| (v - pm).powi(2)).sum::<f64>()).sqrt();
    if se > 0.0 {
        norm / se
    } else {
        f64::INFINITY
    }
}

/// `jackknife_t` of the segment fits on which a finding holds (`held`): the fits that
/// determined its coefficients.
pub fn agreement_of_held(fits: &[Vec<f64>], held: &[bool]) -> f64 {
    let kept: Vec<Vec<f64>> = fits
        .iter()
        .zip(held)
        .filter(|(_, h)| **h)
        .map(|(f, _)| f.clone())
        .collect();
    jackknife_t(&kept)
}

/// A play's agreement across the segment fits where it holds (`agreement_of_held`), asked of
/// its two physical coefficients, each on its own: the free force's gain (the device's own
/// force, 1) and the impact's momentum per unit relative velocity (the sum of the taps,
/// (1 + e)·M); the smaller of their jackknife t. The taps one by one are the contact pulse's
/// shape sampled from each contact's interpolated instant: a contact the walk places a sample
/// off in one segment moves the pulse between neighbouring taps and leaves their sum, so the
/// shape scatters across segments while the momentum it carries does not (rounded triangle
/// 600007: t = 3.0 on the taps, 8.7 on the momentum, 122 on the gain).
pub fn play_agreement(fits: &[Vec<f64>], held: &[bool]) -> f64 {
    let gain: Vec<Vec<f64>> = fits.iter().map(|f| f[..1].to_vec()).collect();
    let momentum: Vec<Vec<f64>> = fits.iter().map(|f| vec![f[1..].iter().sum()]).collect();
    agreement_of_held(&gain, held).min(agreement_of_held(&momentum, held))
}

/// Samples in motion the diagnosis needs at least (training and held-out together).
pub const MIN_MOVING: usize = 200;

/// Run the diagnosis on a record. A record or options it cannot use give a diagnosis with no
/// finding and the reason as its first verdict (never a panic); `try_diagnose` returns it as
/// an error instead.
pub fn diagnose(rec: &Record, opt: &Options) -> Diagnosis {
    match try_diagnose(rec, opt) {
        Ok(d) => d,
        Err(e) => Diagnosis {
            n: rec.len(),
            verdicts: vec![e],
            ..Default::default()
        },
    }
}

/// Check a record and options, then diagnose.
pub fn try_diagnose(rec: &Record, opt: &Options) -> Result<Diagnosis, String> {
    if !(0.0..1.0).contains(&opt.min_holdout_gain) {
        return Err(format!(
            "option min_holdout_gain = {}: allowed range [0, 1)",
            opt.min_holdout_gain
        ));
    }
    if opt.max_effects > EffectKind::ALL.len() {
        return Err(format!(
            "option max_effects = {}: allowed range 0 ..= {}",
            opt.max_effects,
            EffectKind::ALL.len()
        ));
    }
    if !(100..=10_000_000).contains(&opt.screen_samples) {
        return Err(format!(
            "option screen_samples = {}: allowed range 100 ..= 10000000",
            opt.screen_samples
        ));
    }
    if opt.screen_window < 100 {
        return Err(format!(
            "option screen_window = {}: allowed range 100 ..= {}",
            opt.screen_window,
            usize::MAX
        ));
    }
    let n = rec.len();
    let lens = [rec.x.len(), rec.f.len(), rec.v.len(), rec.a.len()];
    if n < 3 || lens.iter().any(|&l| l != n) {
        return Err(format!(
            "record: {n} time samples (x {}, f {}, v {}, a {}): at least 3, all columns of equal length",
            lens[0], lens[1], lens[2], lens[3]
        ));
    }
    let finite = |c: &[f64]| c.iter().all(|v| v.is_finite());
    if !(finite(&rec.t) && finite(&rec.x) && finite(&rec.f) && finite(&rec.v) && finite(&rec.a))
        || rec.extra.values().any(|c| c.len() != n || !finite(c))
    {
        return Err("record: a column holds a non-finite value or has a different length".into());
    }
    let dt = rec.dt();
    if !(dt > 0.0 && dt.is_finite()) {
        return Err(format!("record: mean sample period {dt} s is not positive"));
    }
    let rest = effects::at_rest(&rec.x, &rec.v, dt);
    let moving = rest.iter().filter(|r| !**r).count();
    if moving < MIN_MOVING {
        return Err(format!(
            "record: {moving} of {n} samples in motion (the rest at rest or at the ends): at least {MIN_MOVING} are needed; no finding can be stated"
        ));
    }
    let hold = holdout_mask(n);
    let (mut tr_n, mut ho_n) = (0, 0);
    for (h, r) in hold.iter().zip(&rest) {
        if !r {
            if *h == HELD_OUT {
                ho_n += 1;
            } else {
                tr_n += 1;
            }
        }
    }
    if tr_n < MIN_MOVING / 2 || ho_n < MIN_MOVING / 4 {
        return Err(format!(
            "record: {tr_n} training and {ho_n} held-out samples in motion: at least {} and {} are needed",
            MIN_MOVING / 2,
            MIN_MOVING / 4
        ));
    }
    Ok(diagnose_checked(rec, opt, rest))
}

fn diagnose_checked(rec: &Record, opt: &Options, rest: Vec<bool>) -> Diagnosis {
    let n = rec.len();
    let ctx = effects::Context::windowed_at_rest(rec, opt.screen_window.min(n), rest);
    let mut hold = holdout_mask(n);
    for (h, &r) in hold.iter_mut().zip(&ctx.rest) {
        if r {
            *h = AT_REST;
        }
    }
    let stride = n.div_ceil(opt.screen_samples).max(1);
    // The spread subsample: every `stride`-th sample of the whole record (the baseline terms'
    // significance and the stability segments).
    let spread_rows: Vec<usize> = (0..n).step_by(stride).collect();
    // The screening window (`screen_window`): the first `w` samples, with their own held-out
    // blocks; the whole record when it is not longer than `SCREEN_WINDOW` (then the screening
    // rows are the spread rows and the split is the record's).
    let w = ctx.window;
    let screen_hold: Vec<u8> = if w == n {
        hold.clone()
    } else {
        holdout_mask(w)
            .into_iter()
            .zip(&ctx.rest)
            .map(|(h, &r)| if r { AT_REST } else { h })
            .collect()
    };
    let mut chosen: Vec<Effect> = Vec::new();
    let mut cols = effects::build_columns(&ctx, &chosen);
    let n_base = cols.len();
    let mut full = normals(&refs(&cols), &rec.f, &hold, 1);
    let base_full = full.clone();
    let (tr, ho) = full.clone();
    let th = tr.solve();
    // Screening subsample (strided over the screening window), gathered into contiguous arrays
    // once.
    let sub = effects::SubSignals::new(
        &ctx,
        (0..w).step_by(w.div_ceil(opt.screen_samples)).collect(),
    );
    let sig = sub.sig();
    let gather = |rows: &[usize], v: &[f64]| -> Vec<f64> { rows.iter().map(|&i| v[i]).collect() };
    let sub_f = gather(&sub.rows, &rec.f);
    let sub_hold: Vec<u8> = sub.rows.iter().map(|&i| screen_hold[i]).collect();
    let sub_w = HoldWeights::new(&sub_hold);
    let mut full_w = HoldWeights::new(&hold);
    // A set holding a `lag` τ makes the force the device's at t − τ: its fits leave out the
    // samples whose delayed motion is at rest (`Context::lag_rest_rows`), and so does every fit
    // it is compared with (the same rows on both sides of a comparison).
    let lag_of = |set: &[Effect]| {
        set.iter()
            .find(|e| e.kind == EffectKind::Lag)
            .map(|e| e.param)
    };
    // (the same rows every time a τ comes back: kept per τ)
    let lag_rest_kept = std::cell::RefCell::new(std::collections::HashMap::new());
    let lag_rest_sub = |tau: f64| -> Vec<usize> {
        lag_rest_kept
            .borrow_mut()
            .entry(tau.to_bits())
            .or_insert_with(|| ctx.lag_rest_rows(tau, Some(&sub.rows)))
            .clone()
    };
    let mut sub_cols: Vec<Vec<f64>> = cols.iter().map(|(_, v)| gather(&sub.rows, v)).collect();
    let spread_f = gather(&spread_rows, &rec.f);
    let spread_hold: Vec<u8> = spread_rows.iter().map(|&i| hold[i]).collect();
    let baseline_holdout = rel(ho.rss(&th), ho.ff);
    let baseline_train = rel(tr.rss(&th), tr.ff);
    // Baseline term significance: drop each in turn (on the spread subsample).
    let spread_base: Vec<Vec<f64>> = cols.iter().map(|(_, v)| gather(&spread_rows, v)).collect();
    let mut baseline_terms = Vec::new();
    for drop in 0..n_base {
        let keep: Vec<&[f64]> = spread_base
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != drop)
            .map(|(_, c)| c.as_slice())
            .collect();
        let (t2, h2) = normals(&keep, &spread_f, &spread_hold, 1);
        let th2 = t2.solve();
        let without = rel(h2.rss(&th2), h2.ff);
        let (name, unit) = effects::baseline_term(&cols[drop].0);
        baseline_terms.push(BaselineTerm {
            effect: name.to_string(),
            value: th[drop],
            unit: unit.to_string(),
            holdout_rel_error_without: without,
            // kept when dropping it makes the held-out rss grow by the same margin an
            // extension must bring
            significant: without * without
                > baseline_holdout * baseline_holdout / (1.0 - opt.min_holdout_gain),
        });
    }
    // A slow change of the residual's mean over the record (a drifting offset: temperature,
    // a load cell's zero) is outside the catalogue. Checked on the baseline residual before
    // the search: when it shows, it is reported as `unexplained` with where it shows and
    // carried during the search and in the final fit by two nuisance columns (the record's
    // time as Legendre polynomials of degree 1 and 2 on [−1, 1]), so that no catalogue effect
    // takes it (a drift correlates with whatever the motion does slowly: a position, a
    // direction, a dwell) and the effects are fitted on the rest.
    let resid_of = |cols: &[(String, Vec<f64>)], th: &[f64]| -> Vec<f64> {
        let p = effects::predict(cols, th);
        rec.f
            .iter()
            .zip(&p)
            .zip(&ctx.rest)
            .map(|((a, b), &r)| if r { 0.0 } else { a - b })
            .collect()
    };
    let (t0, t1) = (rec.t[0], rec.t[n - 1]);
    let tn: Vec<f64> = rec
        .t
        .iter()
        .map(|t| 2.0 * (t - t0) / (t1 - t0).max(1e-300) - 1.0)
        .collect();
    let z = vec![
        (DRIFT_COLUMNS[0].to_string(), tn.clone()),
        (
            DRIFT_COLUMNS[1].to_string(),
            tn.iter().map(|t| 1.5 * t * t - 0.5).collect(),
        ),
    ];
    let zr: Vec<&[f64]> = z.iter().map(|(_, v)| v.as_slice()).collect();
    let drift = report::slow_change(
        &rec.t,
        &resid_of(&cols, &th),
        &ctx.rest,
        opt.min_holdout_gain,
    )
    .or_else(|| {
        // the baseline's coefficients fitted beside the trend: a Coulomb term or an offset
        // that took part of a drift (a direction or a dwell that correlates with time: the
        // moves of a point-to-point record running one way early and the other way late)
        // does not hide it; the residual tested is the force minus the baseline's part of
        // that joint fit (the trend left in it), the test the same
        let joint = extend_normals_dense(&full, &refs(&cols), &zr, &rec.f, &full_w)
            .0
            .solve();
        report::slow_change(
            &rec.t,
            &resid_of(&cols, &joint[..cols.len()]),
            &ctx.rest,
            opt.min_holdout_gain,
        )
    });
    if drift.is_some() {
        full = extend_normals_dense(&full, &refs(&cols), &zr, &rec.f, &full_w);
        sub_cols.extend(z.iter().map(|(_, v)| gather(&sub.rows, v)));
        cols.extend(z);
    }
    // The screening columns of every candidate value are the same in every round: computed
    // once (on the subsample, at most `screen_samples` rows each) and kept.
    type Cache = ScreenColumns;
    let mut cache = Cache::new();
    // and their Gram entries against the base columns, extended as the base grows
    let grams =
        std::cell::RefCell::new(std::collections::HashMap::<(usize, u64), GramCache>::new());
    let whole_fit = |full: &(Normal, Normal), cols: &[(String, Vec<f64>)]| {
        let t = full.0.plus(&full.1).solve();
        cols.iter().map(|c| c.0.clone()).zip(t).collect::<Vec<_>>()
    };
    let catalogue = effects::catalogue(&ctx);
    let n_fixed = sub_cols.len();
    // the screening columns of the fixed terms and of a set of effects (from the cache)
    let set_cols = |set: &[Effect], cache: &mut Cache| -> Vec<Vec<f64>> {
        let mut c = sub_cols.clone();
        for e in set {
            let z = cache
                .entry(e.key())
                .or_insert_with(|| effects::columns_on(&ctx, &sig, e));
            c.extend(z.iter().map(|(_, v)| v.clone()));
        }
        c
    };
    // training and held-out normals of the fixed terms and a set of effects, on the rows of a
    // lag τ when given
    let set_normals_on =
        |set: &[Effect], tau: Option<f64>, cache: &mut Cache| -> (Normal, Normal) {
            let c = set_cols(set, cache);
            let r: Vec<&[f64]> = c.iter().map(|v| v.as_slice()).collect();
            let nn = normals(&r, &sub_f, &sub_hold, 1);
            match tau {
                Some(t) => change_rows(&nn, &r, &sub_f, &sub_hold, &lag_rest_sub(t), -1.0),
                None => nn,
            }
        };
    let set_normals = |set: &[Effect], cache: &mut Cache| set_normals_on(set, lag_of(set), cache);
    // the identities of those columns (for the Gram cache): a fixed term by its index, an
    // effect's column by its kind, its parameter's bits and its index
    let set_ids = |set: &[Effect], cache: &mut Cache| -> Vec<ColumnId> {
        let mut ids: Vec<ColumnId> = (0..n_fixed as u64).map(|i| (u64::MAX, i)).collect();
        for e in set {
            let k = cache
                .entry(e.key())
                .or_insert_with(|| effects::columns_on(&ctx, &sig, e))
                .len();
            ids.extend((0..k as u64).map(|j| (((e.kind as u64) << 32) | j, e.key().1)));
        }
        ids
    };
    // parameters a set of effects adds (its columns and each scanned parameter)
    let set_k = |set: &[Effect], cache: &mut Cache| -> usize {
        set_cols(set, cache).len() + set.iter().filter(|e| e.kind.scanned()).count()
    };
    // Whether candidate columns `zr` cut the held-out rss of the set's columns `base_refs`
    // with `companions` beside them (their own coefficients) by the margin, on the screening
    // rows without `rows`.
    // (the comparison itself, on normal equations `nw` whose first `nb` columns are the set's
    // with its companions)
    let carries_over = |nw: &(Normal, Normal), nb: usize| -> bool {
        let idx: Vec<usize> = (0..nb).collect();
        let (st, sh) = (nw.0.select(&idx), nw.1.select(&idx));
        let with = nw.1.rss(&nw.0.solve());
        1.0 - with / sh.rss(&st.solve()).max(1e-300) >= opt.min_holdout_gain
    };
    let carries_beyond =
        |base_refs: &[&[f64]], companions: &[&[f64]], zr: &[&[f64]], rows: &[usize]| -> bool {
            let all: Vec<&[f64]> = base_refs
                .iter()
                .chain(companions)
                .chain(zr)
                .copied()
                .collect();
            let mut nw = normals(&all, &sub_f, &sub_hold, 1);
            if !rows.is_empty() {
                nw = change_rows(&nw, &all, &sub_f, &sub_hold, rows, -1.0);
            }
            carries_over(&nw, base_refs.len() + companions.len())
        };
    // Whether candidate columns `zr` cut the held-out rss of the set's columns `base_refs`
    // with the Coulomb switch of a delay `tau` beside them (its own coefficient) by the
    // margin, on the screening rows without the lag's `rows`.
    let carries_beyond_switch =
        |base_refs: &[&[f64]], zr: &[&[f64]], tau: f64, rows: &[usize]| -> bool {
            let k = tau / ctx.dt;
            let parts: Vec<Vec<f64>> = [&rec.a, &rec.v]
                .iter()
                .map(|s| {
                    sub.rows
                        .iter()
                        .map(|&i| effects::delayed(s, i, k) - s[i])
                        .collect()
                })
                .chain([sub
                    .rows
                    .iter()
                    .map(|&i| effects::delayed_switch(&rec.v, &ctx.sgn, i, k))
                    .collect()])
                .collect();
            let parts: Vec<&[f64]> = parts.iter().map(|c| c.as_slice()).collect();
            carries_beyond(base_refs, &parts, zr, rows)
        };
    // The Coulomb column with the exact sign of the velocity on the screening rows (0 at
    // v = 0), when a sample in motion slides inside the sign's linear band
    // (`effects::sign_band`): there the device's Coulomb force is whole while the baseline's
    // column, linear in v, draws only part of it.
    let exact_sign: Option<Vec<f64>> = {
        let z: Vec<f64> = sub
            .v
            .iter()
            .map(|&v| if v == 0.0 { 0.0 } else { v.signum() })
            .collect();
        z.iter()
            .zip(&sub.sgn)
            .zip(&sub_hold)
            .any(|((&e, &s), &h)| e != s && h != AT_REST)
            .then_some(z)
    };
    // a candidate is added when it cuts the held-out rss by the margin and lowers the BIC
    let passes = |rh: f64, rss_h0: f64, dbic: f64| {
        1.0 - rh / rss_h0.max(1e-300) >= opt.min_holdout_gain && dbic < 0.0
    };
    // The best candidate to add to a set (every kind not in it, every grid value, refined):
    // (held-out rss of the set, and of the best candidate with its training BIC change).
    let scan = |set: &[Effect], cache: &mut Cache| -> (f64, Option<(f64, f64, Effect)>) {
        let base_cols = set_cols(set, cache);
        let base_refs: Vec<&[f64]> = base_cols.iter().map(|v| v.as_slice()).collect();
        let base_ids = set_ids(set, cache);
        let base = normals(&base_refs, &sub_f, &sub_hold, 1);
        // the set's columns with the exact sign in the Coulomb column (the third), their
        // identities and normal equations, once per set (the Stribeck band rule below extends
        // them by each candidate's columns, the candidate's products with the other columns
        // kept in its Gram cache)
        let es_base = exact_sign.as_ref().map(|es| {
            let mut b = base_refs.clone();
            b[2] = es.as_slice();
            let mut ids = base_ids.clone();
            ids[2] = (u64::MAX - 1, 2);
            let nw = normals(&b, &sub_f, &sub_hold, 1);
            (b, ids, nw)
        });
        let tau_s = lag_of(set);
        let rows_s = tau_s.map(lag_rest_sub).unwrap_or_default();
        let base_fit = if rows_s.is_empty() {
            base.clone()
        } else {
            change_rows(&base, &base_refs, &sub_f, &sub_hold, &rows_s, -1.0)
        };
        let th_b = base_fit.0.solve();
        let rss_h0 = base_fit.1.rss(&th_b);
        let rss_t0 = base_fit.0.rss(&th_b);
        let k0 = base_refs.len() + set.iter().filter(|e| e.kind.scanned()).count();
        // where each effect of the set sits among the base columns (after the fixed terms)
        let set_spans = effect_spans(set, n_fixed, &*cache);
        // the rows the longest delay scanned leaves out (`lag`'s τ are ranked on common rows)
        let lag_common = lag_rest_sub(effects::LAG_MAX_SAMPLES * ctx.dt);
        let mut best: Option<(f64, f64, Effect)> = None;
        for cand in &catalogue {
            if set.iter().any(|c| c.kind == cand.kind)
                || effects::same_channel_timing(cand.kind, set)
            {
                continue;
            }
            let eval = |eff: &Effect, cache: &mut Cache| -> (f64, f64, f64) {
                // one cause, one name: a wavelength already named (cogging or periodic
                // friction, within 3 %) is not named again under the other periodic name; a
                // Stribeck bump inside the presliding build-up is the build-up's shape
                if effects::same_wavelength(eff, set)
                    || effects::stribeck_within_presliding(eff, set, &ctx)
                {
                    return (f64::INFINITY, 0.0, f64::INFINITY);
                }
                let z = cache
                    .entry(eff.key())
                    .or_insert_with(|| effects::columns_on(&ctx, &sig, eff));
                let zr: Vec<&[f64]> = z.iter().map(|(_, v)| v.as_slice()).collect();
                let mut grams = grams.borrow_mut();
                let gc = grams.entry(eff.key()).or_default();
                let mut nn =
                    extend_normals_cached(&base, &base_refs, &base_ids, &zr, &sub_f, &sub_w, gc);
                let nb = base_refs.len();
                // the rows of the set's lag, or of the candidate lag: the set is compared with
                // it on the candidate's rows and its gain there carried to the set's rows
                let (mut scale, mut t0) = (1.0, rss_t0);
                let rows_c = match (tau_s, eff.kind) {
                    (Some(_), _) => rows_s.clone(),
                    (None, EffectKind::Lag) => lag_rest_sub(eff.param),
                    _ => Vec::new(),
                };
                let lag_cand = tau_s.is_none() && eff.kind == EffectKind::Lag;
                let all: Vec<&[f64]> = if rows_c.is_empty() && !lag_cand {
                    Vec::new()
                } else {
                    base_refs.iter().chain(&zr).copied().collect()
                };
                // the held-out rss of the fit with the candidate over the baseline's on the
                // same rows, carried to the set's rows
                let ratio = |nn: &(Normal, Normal)| {
                    let idx: Vec<usize> = (0..nb).collect();
                    let (bt, bh) = (nn.0.select(&idx), nn.1.select(&idx));
                    let th0 = bt.solve();
                    (rss_h0 / bh.rss(&th0).max(1e-300), bt.rss(&th0))
                };
                if !rows_c.is_empty() {
                    nn = change_rows(&nn, &all, &sub_f, &sub_hold, &rows_c, -1.0);
                    if tau_s.is_none() {
                        (scale, t0) = ratio(&nn);
                    }
                }
                // `lag`'s τ are ranked against each other on the same rows: those every τ
                // scanned can fit (the rows the longest τ leaves out as well). Each τ leaves
                // out the samples whose motion τ earlier is at rest, the first τ of each move,
                // where the force is the dwell's and an undelayed baseline is furthest from
                // it: on each τ's own rows a longer τ would be compared with a baseline
                // relieved of more of its worst rows, and rank behind a shorter one that fits
                // no better. Computed last (`common_key`), for a τ that is still a candidate
                // and whose rank the noise-corrected fit does not set.
                let common_key = || {
                    let extra: Vec<usize> = lag_common
                        .iter()
                        .filter(|j| rows_c.binary_search(j).is_err())
                        .copied()
                        .collect();
                    let nc = change_rows(&nn, &all, &sub_f, &sub_hold, &extra, -1.0);
                    nc.1.rss(&nc.0.solve()) * ratio(&nc).0
                };
                let t = nn.0.solve();
                // a set is a device's only when every effect in it stays physical with the
                // candidate beside it (the stability check asks the same of the whole set)
                if !set_physical(set, &set_spans, &t) {
                    return (f64::INFINITY, 0.0, f64::INFINITY);
                }
                // `lag`: its gain's range and its τ are judged on the fit corrected for the
                // derived signals' noise (`lag_corrected`); the held-out rss it is compared
                // with the other candidates by is the least-squares fit's, as theirs
                let mut key = None;
                let mut tc = None;
                // a delay whose least-squares gain is a unit one ranks by its held-out rss, as
                // every candidate; one whose gain only the correction brings into the range
                // ranks after all of those, by the corrected gain's distance from 1; a τ whose
                // column is more than half noise is not resolved by either fit
                if eff.kind == EffectKind::Lag {
                    if let Some(sn) = ctx.lag_noise(eff.param) {
                        match lag_corrected(&nn.0, &nn.1, [0, 1, nb], &sn) {
                            Some(_) if effects::plausible(eff, &t[nb..], &t[..nb.min(4)]) => {}
                            Some((c, _)) => {
                                key = Some(CORRECTED_RANK * (1.0 + (c[nb] - 1.0).abs()));
                                tc = Some(c);
                            }
                            None => return (f64::INFINITY, 0.0, f64::INFINITY),
                        }
                    }
                }
                // `compliance`: a mode whose column is more than half the derived
                // acceleration's noise on the training rows is not resolved (as a `lag` τ):
                // its fit would low-pass the inertia's noisy column, not draw a mode. A mode
                // resolved must carry the margin on error-free columns: the fits with and
                // without it corrected for that noise (`eiv_fit`, the covariance of the
                // inertia's, the viscous and the mode's columns `Context::compliance_noise`),
                // the held-out rss of each less the noise's share. The column's noise near the
                // derivative cutoff is the inertia column's noise (H − 1 ≈ −1 there), so least
                // squares credits a modal mass near the inertia with the noise it cancels on
                // the held-out rows as on the training rows; the corrected fit does not.
                if eff.kind == EffectKind::Compliance {
                    if let Some(sn) = ctx.compliance_noise(eff.param) {
                        let Some((_, r1)) = lag_corrected(&nn.0, &nn.1, [0, 1, nb], &sn) else {
                            return (f64::INFINITY, 0.0, f64::INFINITY);
                        };
                        let idx: Vec<usize> = (0..nb).collect();
                        let (bt, bh) = (nn.0.select(&idx), nn.1.select(&idx));
                        // (a fit not determined carries no margin)
                        let Some((_, r0)) = eiv_fit(&bt, &bh, &[0, 1], &sn) else {
                            return (f64::INFINITY, 0.0, f64::INFINITY);
                        };
                        if 1.0 - r1 / r0.max(1e-300) < opt.min_holdout_gain {
                            return (f64::INFINITY, 0.0, f64::INFINITY);
                        }
                    }
                }
                let tp = tc.as_deref().unwrap_or(&t);
                if !effects::plausible(eff, &tp[nb..], &tp[..nb.min(4)])
                    || (eff.kind == EffectKind::CurrentLimit
                        && !effects::clip_consistent(
                            &ctx,
                            eff,
                            &t[nb..],
                            &t[..nb.min(4)],
                            &sub.bp,
                            &sub.v,
                            &sub_f,
                            ctx.base_resid_rms,
                        ))
                {
                    return (f64::INFINITY, 0.0, f64::INFINITY);
                }
                // a presliding transition beside a lag: the delay shifts the Coulomb switch
                // by τ, and the lag's one gain (set by its inertial and viscous parts too,
                // whose derived signals' noise biases it low) can leave part of that switch,
                // a transition after each reversal that a Dahl state also draws; the
                // presliding must carry the margin on top of the delayed switch given an
                // amplitude of its own (`effects::delayed_switch`), on the lag's rows.
                // Likewise a resonance beside a lag: the mode's column (H − 1)·a, a
                // frequency-dependent inertia, draws what the one gain leaves of the delayed
                // inertial and viscous parts, M·(a(t − τ) − a(t)) and Fv·(v(t − τ) − v(t)),
                // so it must carry the margin on top of the three parts given amplitudes of
                // their own
                if let (EffectKind::PreslidingHysteresis | EffectKind::Compliance, Some(tau)) =
                    (eff.kind, tau_s)
                {
                    if !carries_beyond_switch(&base_refs, &zr, tau, &rows_s) {
                        return (f64::INFINITY, 0.0, f64::INFINITY);
                    }
                }
                // a Stribeck bump where the motion slides inside the Coulomb sign's linear
                // band: the part of the Coulomb force the band leaves out (sign(v) − v/v_eps,
                // a friction above the baseline's column at the lowest speeds) is a bump too;
                // a Dahl state that has reached the direction of sliding draws it exactly
                // (z − sgn v = sign v − v/v_eps there); either must carry the margin against
                // the baseline with the exact sign (its Coulomb column, the third, replaced)
                if let (
                    EffectKind::Stribeck | EffectKind::PreslidingHysteresis,
                    Some((b, ids, nw)),
                ) = (eff.kind, &es_base)
                {
                    let mut nw = extend_normals_cached(nw, b, ids, &zr, &sub_f, &sub_w, gc);
                    if !rows_s.is_empty() {
                        let all: Vec<&[f64]> = b.iter().chain(&zr).copied().collect();
                        nw = change_rows(&nw, &all, &sub_f, &sub_hold, &rows_s, -1.0);
                    }
                    if !carries_over(&nw, b.len()) {
                        return (f64::INFINITY, 0.0, f64::INFINITY);
                    }
                }
                let rt = nn.0.rss(&t);
                let k_extra = z.len() + eff.kind.scanned() as usize;
                let dbic = bic(rt, nn.0.n, k0 + k_extra) - bic(t0, nn.0.n, k0);
                let rh = nn.1.rss(&t) * scale;
                let key = match key {
                    None if lag_cand => Some(common_key()),
                    k => k,
                };
                (rh, dbic, key.unwrap_or(rh))
            };
            // fill the cache for a list of values in one pass over the record (the effects
            // whose columns walk the record's history: resonators, Dahl states, play)
            let prefill = |effs: &[Effect], cache: &mut Cache| {
                if !matches!(
                    cand.kind,
                    EffectKind::Compliance
                        | EffectKind::PreslidingHysteresis
                        | EffectKind::Backlash
                ) {
                    return;
                }
                let missing: Vec<Effect> = effs
                    .iter()
                    .filter(|e| !cache.contains_key(&e.key()))
                    .cloned()
                    .collect();
                for (e, c) in missing
                    .iter()
                    .zip(effects::columns_batch(&ctx, &sig, &missing))
                {
                    cache.insert(e.key(), c);
                }
            };
            let coarse = effects::grid(&ctx, cand);
            // the scanned range: an optimum on its edge is not bracketed (the profile of the
            // fit over the parameter still falls beyond the range the record resolves), so the
            // parameter is not identified and the effect is not named
            // the values `effs` evaluated (their columns filled in one pass) and the best so
            // far kept, ranked by each value's key: its held-out rss, for `lag` the corrected
            // fit's
            let scan = |effs: &[Effect],
                        cache: &mut Cache,
                        cb: &mut Option<(f64, f64, Effect)>,
                        cb_key: &mut f64| {
                prefill(effs, cache);
                for eff in effs {
                    let (rh, db, key) = eval(eff, cache);
                    if cb.is_none() || key < *cb_key {
                        *cb = Some((rh, db, eff.clone()));
                        *cb_key = key;
                    }
                }
            };
            let mut cb: Option<(f64, f64, Effect)> = None;
            let mut cb_key = f64::INFINITY;
            scan(&coarse, cache, &mut cb, &mut cb_key);
            if cand.kind.scanned() {
                // a resonance's residual is sharp in frequency: one more level for it
                let widths: &[f64] = if cand.kind == EffectKind::Compliance {
                    &[0.15, 0.03, 0.006]
                } else {
                    &[0.15, 0.03]
                };
                for &width in widths {
                    let Some(centre) = cb.as_ref().map(|c| c.2.clone()) else {
                        break;
                    };
                    let fine = effects::refine(&ctx, &centre, width);
                    scan(&fine, cache, &mut cb, &mut cb_key);
                }
            }
            if cand.kind == EffectKind::Backlash {
                // the contact's restitution at the width found (`effects::PLAY_RESTITUTIONS`),
                // ranked by the held-out key as the width is; the width refined once more at
                // a restitution other than 0 (a rebounding device's contacts move with it)
                if let Some(centre) = cb.as_ref().map(|c| c.2.clone()) {
                    let alt: Vec<Effect> = effects::PLAY_RESTITUTIONS
                        .iter()
                        .filter(|&&e| e != centre.param2)
                        .map(|&e| Effect {
                            param2: e,
                            ..centre.clone()
                        })
                        .collect();
                    scan(&alt, cache, &mut cb, &mut cb_key);
                }
                // a compliant, plastic flank (`effects::PLAY_CONTACT_FRACTIONS`) when the
                // rigid, plastic one is the best restitution and itself passes the selection
                // (the flank's stiffness refines a play the record shows; on a record without
                // one it is not walked); the spring is one parameter more, so it must cut the
                // rigid flank's held-out rss by the selection's margin, as an added effect must
                let rigid_passes = cb.as_ref().is_some_and(|c| passes(c.0, rss_h0, c.1));
                if let Some(centre) = cb.as_ref().map(|c| c.2.clone()) {
                    if centre.param2 == 0.0 && rigid_passes {
                        let alt: Vec<Effect> = effects::PLAY_CONTACT_FRACTIONS
                            .iter()
                            .map(|&q| Effect {
                                param2: -q / ctx.dt,
                                ..centre.clone()
                            })
                            .collect();
                        let (mut sb, mut sb_key) = (None, f64::INFINITY);
                        scan(&alt, cache, &mut sb, &mut sb_key);
                        if sb_key <= (1.0 - opt.min_holdout_gain) * cb_key {
                            (cb, cb_key) = (sb, sb_key);
                        }
                    }
                }
                if let Some(centre) = cb.as_ref().map(|c| c.2.clone()) {
                    if centre.param2 != 0.0 {
                        let fine = effects::refine(&ctx, &centre, 0.03);
                        scan(&fine, cache, &mut cb, &mut cb_key);
                    }
                }
            }
            if cand.kind.scanned()
                && cb.as_ref().is_some_and(|c| {
                    let (p_lo, p_hi) = effects::scan_range(&coarse, &c.2);
                    coarse_len_gt1(p_lo, p_hi) && !effects::interior(c.2.param, p_lo, p_hi)
                })
            {
                cb = None;
            }
            if let Some(c) = cb {
                if c.0.is_finite() && best.as_ref().is_none_or(|b| c.0 < b.0) {
                    best = Some(c);
                }
            }
        }
        (rss_h0, best)
    };
    let forward = |chosen: &mut Vec<Effect>, cache: &mut Cache| -> bool {
        let mut added = false;
        while chosen.len() < opt.max_effects {
            match scan(chosen, cache) {
                (h0, Some((rh, db, eff))) if passes(rh, h0, db) => {
                    chosen.push(eff);
                    added = true;
                }
                _ => break,
            }
        }
        added
    };
    forward(&mut chosen, &mut cache);
    // Swap and backward pass (forward selection alone is greedy: an effect taken first can
    // hold the place of the right one, e.g. a delayed Coulomb switch taken as presliding):
    // each kept finding is removed in turn and the best candidate is scanned on the others
    // (its own kind included, so its parameter is re-scanned with every other effect in the
    // model); the set with the lower held-out rss is kept, the replacement passing the same
    // margin and BIC rule as in the forward pass. A finding that no longer carries the margin
    // on top of the others is removed. Then forward selection resumes; repeated until the
    // set no longer changes (each change lowers the held-out rss or removes a finding, so it
    // ends; at most `SWAP_ROUNDS` rounds).
    for _ in 0..SWAP_ROUNDS {
        let mut changed = false;
        let mut k = 0;
        while k < chosen.len() {
            let (ntr, nho) = set_normals(&chosen, &mut cache);
            let mut cur = nho.rss(&ntr.solve());
            let others: Vec<Effect> = chosen
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != k)
                .map(|(_, e)| e.clone())
                .collect();
            let (h0, best) = scan(&others, &mut cache);
            if chosen[k].kind == EffectKind::Lag {
                // the lag's gain on its own rows, carried to the others' rows (as `scan` does)
                let (otr, oho) = set_normals_on(&others, lag_of(&chosen), &mut cache);
                cur *= h0 / oho.rss(&otr.solve()).max(1e-300);
            }
            match best {
                Some((rh, db, eff))
                    if rh < cur * (1.0 - 1e-9) && passes(rh, h0, db) && eff != chosen[k] =>
                {
                    chosen[k] = eff;
                    changed = true;
                }
                _ if 1.0 - cur / h0.max(1e-300) < opt.min_holdout_gain => {
                    chosen.remove(k);
                    changed = true;
                    continue;
                }
                _ => {}
            }
            k += 1;
        }
        changed |= forward(&mut chosen, &mut cache);
        if !changed {
            break;
        }
    }
    // A compliant flank is chosen on the screening window; the whole record must bear it out:
    // where the rigid flank at the same width fits the whole record's held-out part as well or
    // better, the rigid flank is kept (the stiffness refines a play, it is not a second cause).
    let whole_holdout = |set: &[Effect]| -> f64 {
        let z: Vec<(String, Vec<f64>)> = set
            .iter()
            .flat_map(|e| effects::effect_columns(&ctx, e))
            .collect();
        let zr: Vec<&[f64]> = z.iter().map(|(_, v)| v.as_slice()).collect();
        let n = extend_normals_dense(
            &base_full,
            &refs(&cols[..n_base]),
            &zr,
            &rec.f,
            &HoldWeights::new(&hold),
        );
        n.1.rss(&n.0.solve())
    };
    for k in 0..chosen.len() {
        if chosen[k].kind == EffectKind::Backlash && chosen[k].param2 < 0.0 {
            let mut rigid = chosen.clone();
            rigid[k].param2 = 0.0;
            if whole_holdout(&rigid) <= whole_holdout(&chosen) {
                chosen = rigid;
            }
        }
    }
    // The findings in their order: each one's held-out gain and BIC change on the subsample
    // with the findings before it, then added to the whole record's normal equations.
    let mut ho_rel = baseline_holdout;
    let mut findings = Vec::new();
    let mut stage_models = vec![whole_fit(&full, &cols)];
    // the whole record's samples left out with the lag (once it is in the model)
    let mut lag_rows_full: Vec<usize> = Vec::new();
    for i in 0..chosen.len() {
        let (t0, h0) = set_normals_on(&chosen[..i], lag_of(&chosen[..=i]), &mut cache);
        let (t1, h1) = set_normals(&chosen[..=i], &mut cache);
        let (th0, th1) = (t0.solve(), t1.solve());
        let drop = 1.0 - h1.rss(&th1) / h0.rss(&th0).max(1e-300);
        let dbic = bic(t1.rss(&th1), t1.n, set_k(&chosen[..=i], &mut cache))
            - bic(t0.rss(&th0), t0.n, set_k(&chosen[..i], &mut cache));
        let eff = chosen[i].clone();
        let z = effects::effect_columns(&ctx, &eff);
        {
            let zr: Vec<&[f64]> = z.iter().map(|(_, v)| v.as_slice()).collect();
            full = extend_normals_dense(&full, &refs(&cols), &zr, &rec.f, &full_w);
        }
        cols.extend(z);
        if eff.kind == EffectKind::Lag {
            lag_rows_full = ctx.lag_rest_rows(eff.param, None);
            full = change_rows(&full, &refs(&cols), &rec.f, &hold, &lag_rows_full, -1.0);
            let mut part = hold.clone();
            for &j in &lag_rows_full {
                part[j] = AT_REST;
            }
            full_w = HoldWeights::new(&part);
        }
        stage_models.push(whole_fit(&full, &cols));
        let th_cur = full.0.solve();
        let after = rel(full.1.rss(&th_cur), full.1.ff);
        let params = effects::parameters(&ctx, &chosen[..=i], &cols, &th_cur, i);
        findings.push(Finding {
            effect: eff.kind.name().to_string(),
            parameters: params,
            holdout_rss_drop: drop,
            delta_bic: dbic,
            note: effects::describe(&ctx, &eff),
            holdout_rel_error_after: after,
            consistency: 0.0,
        });
        ho_rel = after;
    }
    // Stability: each finding is tested on STABILITY_SEGMENTS independent consecutive
    // segments of the spread subsample (the whole record; each held out in turn, the model
    // fitted on the others): it holds on a segment when removing it raises that segment's rss
    // by at least half the selection margin and its fit there is physical; it is kept when it
    // holds on STABILITY_MIN segments and its leading coefficient keeps its sign on all of
    // them. Its columns are the whole-record columns (`cols`) at those rows.
    let n_sub = spread_f.len();
    let mut spans = Vec::new();
    let mut at = n_fixed;
    for e in &chosen {
        let k = match cache.get(&e.key()) {
            Some(zs) => zs.len(),
            None => effects::columns_on(&ctx, &sig, e).len(),
        };
        spans.push((at, at + k));
        at += k;
    }
    let sub_all: Vec<Vec<f64>> = cols.iter().map(|(_, v)| gather(&spread_rows, v)).collect();
    let sub_refs: Vec<&[f64]> = sub_all.iter().map(|v| v.as_slice()).collect();
    let mut holds = vec![0usize; chosen.len()];
    let mut signs = vec![(0usize, 0usize); chosen.len()];
    let mut seg_coefs: Vec<Vec<Vec<f64>>> = vec![Vec::new(); chosen.len()];
    let mut seg_held: Vec<Vec<bool>> = vec![Vec::new(); chosen.len()];
    // A lag's rows whose delayed motion is at rest (or inside the Coulomb sign's band) are left
    // out of the segments' fits, as of its other fits, except where a play is chosen: those
    // rows, right after the reversals, are where its contacts lie, and a play tested without
    // them holds nowhere (its impact taps fit to zero). A play, and a lag beside it, are
    // tested on every row in motion; every other finding beside a lag on the lag's rows (a
    // presliding's build-up there would take the delayed device's).
    let lag_rest: Vec<usize> = lag_of(&chosen)
        .map(|t| ctx.lag_rest_rows(t, Some(&spread_rows)))
        .unwrap_or_default();
    let mut lag_hold = spread_hold.clone();
    for &j in &lag_rest {
        lag_hold[j] = AT_REST;
    }
    let with_play = chosen.iter().any(|e| e.kind == EffectKind::Backlash);
    let on_every_row = |k: EffectKind| {
        with_play && !lag_rest.is_empty() && matches!(k, EffectKind::Backlash | EffectKind::Lag)
    };
    let segment_fit = |hold: &[u8], sgi: usize| {
        let part: Vec<u8> = (0..n_sub)
            .map(|j| {
                if hold[j] == AT_REST {
                    AT_REST
                } else if j * STABILITY_SEGMENTS / n_sub == sgi {
                    HELD_OUT
                } else {
                    TRAIN
                }
            })
            .collect();
        let (tr, ho) = normals(&sub_refs, &spread_f, &part, 1);
        let th = tr.solve();
        (tr, ho, th)
    };
    for sgi in 0..STABILITY_SEGMENTS {
        let on_lag_rows = segment_fit(&lag_hold, sgi);
        let on_all_rows = chosen
            .iter()
            .any(|e| on_every_row(e.kind))
            .then(|| segment_fit(&spread_hold, sgi));
        for (k, &(a, b)) in spans.iter().enumerate() {
            let (tr, ho, th) = match &on_all_rows {
                Some(f) if on_every_row(chosen[k].kind) => f,
                _ => &on_lag_rows,
            };
            if ho.n < 10 {
                continue;
            }
            let rss_with = ho.rss(th);
            let keep: Vec<usize> = (0..sub_refs.len()).filter(|i| *i < a || *i >= b).collect();
            let (t2, h2) = (tr.select(&keep), ho.select(&keep));
            let rss_without = h2.rss(&t2.solve());
            // (`lag`'s range on its least-squares fit or, failing that, on its fit corrected for
            // the derived signals' noise, as in the scan)
            let corrected = match chosen[k].kind {
                EffectKind::Lag => ctx
                    .lag_noise(chosen[k].param)
                    .map(|sn| lag_corrected(tr, ho, [0, 1, a], &sn).map(|c| c.0)),
                _ => None,
            };
            let phys = match &corrected {
                Some(None) => false,
                Some(Some(tc)) => {
                    effects::plausible(&chosen[k], &th[a..b], &th[..4.min(n_base)])
                        || effects::plausible(&chosen[k], &tc[a..b], &tc[..4.min(n_base)])
                }
                None => effects::plausible(&chosen[k], &th[a..b], &th[..4.min(n_base)]),
            };
            let held = phys && rss_with < rss_without * (1.0 - 0.5 * opt.min_holdout_gain);
            if held {
                holds[k] += 1;
            }
            seg_held[k].push(held);
            seg_coefs[k].push(th[a..b].to_vec());
            if th[a] > 0.0 {
                signs[k].0 += 1;
            } else {
                signs[k].1 += 1;
            }
        }
    }
    // A play's impact taps are the contact pulse's shape, resolved only by the contacts on the
    // fitted rows: on a record with few reversals a fit without them leaves the taps in their
    // null space (alternating ±10³ kg, their sum off the impact's momentum) and that segment
    // does not hold (its impact outside the momentum rule or its held-out rss not lowered).
    // The play's agreement is asked of the segments where it holds (`agreement_of_held`), at
    // least STABILITY_MIN of them; every other effect's of all five.
    let agreement: Vec<f64> = seg_coefs
        .iter()
        .zip(&seg_held)
        .zip(&chosen)
        .map(|((c, h), e)| {
            if e.kind == EffectKind::Backlash {
                play_agreement(c, h)
            } else {
                jackknife_t(c)
            }
        })
        .collect();
    // A periodic finding names a ripple: the residual it explains (the whole-record residual
    // with its own contribution added back) must show that ripple as a peak of the spectrum
    // over position (30× the median level, the `unexplained` criterion) within the 3 % of
    // `same_wavelength`. Wavelengths longer than a third of the stroke are not resolved as
    // peaks there (fewer than 3 periods) and are not checked.
    let ripple_shows: Vec<bool> = {
        let periodic = |k: EffectKind| {
            matches!(
                k,
                EffectKind::Cogging | EffectKind::PositionPeriodicFriction
            )
        };
        let th_now = full.0.plus(&full.1).solve();
        let resid_now = if chosen.iter().any(|e| periodic(e.kind)) {
            resid_of(&cols, &th_now)
        } else {
            Vec::new()
        };
        chosen
            .iter()
            .enumerate()
            .map(|(k, e)| {
                if !periodic(e.kind) || e.param > 2.0 * ctx.x_half / 3.0 {
                    return true;
                }
                let (a, b) = spans[k];
                let mut r = resid_now.clone();
                for j in a..b {
                    for ((ri, c), &rest) in r.iter_mut().zip(&cols[j].1).zip(&ctx.rest) {
                        if !rest {
                            *ri += th_now[j] * c;
                        }
                    }
                }
                report::position_spectrum(rec, &r).peaks.iter().any(|p| {
                    let probe = Effect {
                        kind: e.kind,
                        param: p.wavelength_m,
                        param2: 0.0,
                    };
                    effects::same_wavelength(&probe, std::slice::from_ref(e))
                })
            })
            .collect()
    };
    // A periodic finding names a force locked to position: it must be carried by the samples
    // where its time frequency |v|/λ lies inside the band where the derived acceleration
    // follows the motion (`effects::ripple_in_band`). Above that band a ripple of the motion
    // itself leaves M·(a − a_derived) in the residual at the same wavelength, an inertial
    // force the record does not measure; inside it that artefact vanishes and a force ripple
    // does not. The in-band part of its columns must stand AGREEMENT_T standard errors out of
    // the noise (Wald statistic ≥ AGREEMENT_T²: χ² with 2 degrees of freedom, 1 %).
    let ripple_measured: Vec<Option<effects::RippleInBand>> = chosen
        .iter()
        .enumerate()
        .map(|(k, e)| {
            // a friction building up with speed likewise: carried by the samples where its
            // column changes within that band (`effects::buildup_in_band`), with one rise there
            // and at the stops the motion passes faster
            let mask = match e.kind {
                EffectKind::Cogging | EffectKind::PositionPeriodicFriction => {
                    effects::ripple_in_band(&ctx, e.param)
                }
                EffectKind::VelocityStrengthening => effects::buildup_in_band(&ctx, e.param),
                _ => None,
            };
            mask.map(|mask| effects::in_band_ripple(&ctx, &cols, spans[k], &mask))
        })
        .collect();
    for (k, r) in ripple_measured.iter().enumerate() {
        if let (Some(r), Some(f)) = (r, findings.get_mut(k)) {
            let above = if r.amp_above > 0.0 {
                format!(
                    "above it {:.3} N (differing by {:.0} %, Wald {:.1})",
                    r.amp_above,
                    100.0 * r.rel_diff,
                    r.wald_diff
                )
            } else {
                "no sample above it".to_string()
            };
            f.note.push_str(&format!(
                "; inside the derived acceleration's band {:.3} N (Wald {:.1}), {above}",
                r.amp_in, r.wald
            ));
        }
    }
    let ripple_locked: Vec<bool> = ripple_measured
        .iter()
        .map(|r| r.is_none_or(|r| r.locked_to_position(AGREEMENT_T)))
        .collect();
    // A periodic finding names a force locked to position, not to the reversals: beside a
    // ripple locked to the last reversal whose sign follows the direction of motion (what a
    // reversal excites: a mode's ringing, a friction transient; on a motion that turns at the
    // same positions it is the position ripple's part odd about the stroke's centre) its
    // columns must stand AGREEMENT_T standard errors out of the noise
    // (`effects::ripple_apart_from_reversals`).
    let ripple_reversal: Vec<Option<f64>> = chosen
        .iter()
        .enumerate()
        .map(|(k, e)| {
            matches!(
                e.kind,
                EffectKind::Cogging | EffectKind::PositionPeriodicFriction
            )
            .then(|| effects::ripple_apart_from_reversals(&ctx, &cols, spans[k], e.param))
        })
        .collect();
    for (k, w) in ripple_reversal.iter().enumerate() {
        if let (Some(w), Some(f)) = (w, findings.get_mut(k)) {
            f.note.push_str(&format!(
                "; beside a ripple locked to the last reversal Wald {w:.1}"
            ));
        }
    }
    let ripple_apart: Vec<bool> = ripple_reversal
        .iter()
        .map(|w| w.is_none_or(|w| w >= AGREEMENT_T * AGREEMENT_T))
        .collect();
    // A friction of the speed or a ripple of the position names a force of the motion, not
    // one at a fixed time frequency: where the residual's spectrum holds a peak standing out
    // of the residual (`effects::hum_in_residual`: a hum of the supply, a machine nearby),
    // the finding's columns must stand AGREEMENT_T standard errors out of the noise beside
    // that sinusoid (`effects::finding_apart_from_hum`).
    let hum_kind = |k: EffectKind| {
        matches!(
            k,
            EffectKind::Stribeck | EffectKind::Cogging | EffectKind::PositionPeriodicFriction
        )
    };
    // The hum is sought in the residual of the fixed terms and the finding alone: another
    // finding of the set (a resonance at the hum's frequency) may carry it until it is dropped.
    let hum: Vec<Option<(f64, f64)>> = chosen
        .iter()
        .enumerate()
        .map(|(k, e)| {
            if !hum_kind(e.kind) {
                return None;
            }
            let idx: Vec<usize> = (0..n_fixed).chain(spans[k].0..spans[k].1).collect();
            let own: Vec<(String, Vec<f64>)> = idx.iter().map(|&j| cols[j].clone()).collect();
            let th = full.0.plus(&full.1).select(&idx).solve();
            let f = effects::hum_in_residual(&ctx, &resid_of(&own, &th))?;
            Some((f, effects::finding_apart_from_hum(&ctx, &cols, spans[k], f)))
        })
        .collect();
    for (k, h) in hum.iter().enumerate() {
        if let (Some((hz, w)), Some(f)) = (h, findings.get_mut(k)) {
            f.note.push_str(&format!(
                "; beside the residual's force at {hz:.3} Hz Wald {w:.1}"
            ));
        }
    }
    let hum_apart: Vec<bool> = hum
        .iter()
        .map(|h| h.is_none_or(|(_, w)| w >= AGREEMENT_T * AGREEMENT_T))
        .collect();
    let kept: Vec<usize> = (0..chosen.len())
        .filter(|&k| {
            holds[k] >= STABILITY_MIN
                && (signs[k].0 == 0 || signs[k].1 == 0)
                && agreement[k] >= AGREEMENT_T
                && ripple_shows[k]
                && ripple_locked[k]
                && ripple_apart[k]
                && hum_apart[k]
        })
        .collect();
    // one cause, one name: a position ripple whose time frequency on the motion lies in the
    // band of a mode kept is that mode's ringing (`effects::ripple_at_mode`): the mode is named
    let modes: Vec<Effect> = kept
        .iter()
        .filter(|&&k| chosen[k].kind == EffectKind::Compliance)
        .map(|&k| chosen[k].clone())
        .collect();
    let at_mode: Vec<bool> = chosen
        .iter()
        .map(|e| effects::ripple_at_mode(e, &modes, &ctx))
        .collect();
    let kept: Vec<usize> = kept.into_iter().filter(|&k| !at_mode[k]).collect();
    let mut dropped_notes = Vec::new();
    if kept.len() < chosen.len() {
        for k in (0..chosen.len()).filter(|k| !kept.contains(k)) {
            if let (false, Some(r)) = (ripple_locked[k], ripple_measured[k]) {
                // a friction of the speed is tested where its build-up is followed, a ripple
                // where its time frequency is: the same split, worded for each
                let (not, band, outside) = if chosen[k].kind == EffectKind::VelocityStrengthening {
                    (
                        "a friction of the speed",
                        "where its build-up is slow enough for the derived signals (e^(−|v|/v_b)·|a|/v_b ≤ π·fc)",
                        "at the stops the motion passes faster",
                    )
                } else {
                    (
                        "a force locked to position",
                        "inside the derived acceleration's band (|v|/λ ≤ half its cutoff)",
                        "above it",
                    )
                };
                dropped_notes.push(format!(
                    "{} ({}) selected, but it is not {not}: {band} {:.3} N (Wald {:.1}, at least {:.0} needed), {outside}, where the inertial force is not measured, {:.3} N (differing by {:.0} %, Wald {:.1}; at most {:.0} % or Wald {:.0}): not kept",
                    chosen[k].kind.name(),
                    effects::describe(&ctx, &chosen[k]),
                    r.amp_in,
                    r.wald,
                    AGREEMENT_T * AGREEMENT_T,
                    r.amp_above,
                    100.0 * r.rel_diff,
                    r.wald_diff,
                    100.0 / AGREEMENT_T,
                    AGREEMENT_T * AGREEMENT_T,
                ));
                continue;
            }
            if at_mode[k] {
                dropped_notes.push(format!(
                    "{} ({}) selected, but on most of the motion its time frequency lies in the band of the resonance named (a ripple at the speed the motion keeps and the mode's ringing after each turn, locked to the turn's position, are the same force): not kept",
                    chosen[k].kind.name(),
                    effects::describe(&ctx, &chosen[k]),
                ));
                continue;
            }
            if let (false, Some(wald)) = (ripple_apart[k], ripple_reversal[k]) {
                dropped_notes.push(format!(
                    "{} ({}) selected, but it is not apart from a ripple locked to the last reversal (where the motion turns at the same positions, such a ripple and the position ripple's part odd about the stroke's centre are the same force): beside it Wald {wald:.1} (at least {:.0} needed): not kept",
                    chosen[k].kind.name(),
                    effects::describe(&ctx, &chosen[k]),
                    AGREEMENT_T * AGREEMENT_T,
                ));
                continue;
            }
            if let (false, Some((hz, wald))) = (hum_apart[k], hum[k]) {
                dropped_notes.push(format!(
                    "{} ({}) selected, but it is not apart from the residual's force at {hz:.3} Hz (a force at one time frequency, which no function of the motion is): beside it Wald {wald:.1} (at least {:.0} needed): not kept",
                    chosen[k].kind.name(),
                    effects::describe(&ctx, &chosen[k]),
                    AGREEMENT_T * AGREEMENT_T,
                ));
                continue;
            }
            if !ripple_shows[k] {
                dropped_notes.push(format!(
                    "{} ({}) selected, but the residual it explains shows no peak at its wavelength in the spectrum over position (no ripple stands 30× above the spectrum's median within 3 %): not kept",
                    chosen[k].kind.name(),
                    effects::describe(&ctx, &chosen[k]),
                ));
                continue;
            }
            dropped_notes.push(format!(
                "{} ({}) selected on the whole record, held on {}/{} independent segments (at least {STABILITY_MIN} needed){}, its coefficients agreeing across them to t = {:.1} (at least {AGREEMENT_T} needed): not kept",
                chosen[k].kind.name(),
                effects::describe(&ctx, &chosen[k]),
                holds[k],
                STABILITY_SEGMENTS,
                if signs[k].0 > 0 && signs[k].1 > 0 { ", its coefficient changing sign" } else { "" },
                agreement[k]
            ));
        }
        // a lag not kept gives its left-out samples back to the fits
        if !lag_rows_full.is_empty() && kept.iter().all(|&k| chosen[k].kind != EffectKind::Lag) {
            full = change_rows(&full, &refs(&cols), &rec.f, &hold, &lag_rows_full, 1.0);
            lag_rows_full.clear();
        }
        // rebuild the model from the kept findings (sub-blocks of the accumulated normals)
        let mut idx: Vec<usize> = (0..n_fixed).collect();
        let mut new_chosen = Vec::new();
        let mut new_findings = Vec::new();
        let mut new_stages = vec![stage_models[0].clone()];
        let mut new_cols: Vec<(String, Vec<f64>)> = cols[..n_fixed].to_vec();
        for &k in &kept {
            let (a, b) = spans[k];
            idx.extend(a..b);
            new_cols.extend(cols[a..b].iter().cloned());
            new_chosen.push(chosen[k].clone());
            let (t, h) = (full.0.select(&idx), full.1.select(&idx));
            new_stages.push(whole_fit(&(t.clone(), h.clone()), &new_cols));
            let th_cur = t.solve();
            let mut fnd = findings[k].clone();
            fnd.holdout_rel_error_after = rel(h.rss(&th_cur), h.ff);
            fnd.parameters =
                effects::parameters(&ctx, &new_chosen, &new_cols, &th_cur, new_chosen.len() - 1);
            new_findings.push(fnd);
        }
        full = (full.0.select(&idx), full.1.select(&idx));
        cols = new_cols;
        chosen = new_chosen;
        findings = new_findings;
        stage_models = new_stages;
        ho_rel = findings
            .last()
            .map_or(baseline_holdout, |f| f.holdout_rel_error_after);
        holds = kept.iter().map(|&k| holds[k]).collect();
    }
    for (f, h) in findings.iter_mut().zip(&holds) {
        f.consistency = *h as f64 / STABILITY_SEGMENTS as f64;
    }
    // Final model refitted on the whole record.
    let tf = full.0.plus(&full.1);
    let sol = tf.solve_full();
    let (fit_rank, fit_condition) = (sol.rank, sol.condition);
    let th_full = sol.th;
    // Each finding's parameters are those of the final model (the coefficients `--model`
    // writes), not of the stage at which it was selected.
    for (k, f) in findings.iter_mut().enumerate().take(chosen.len()) {
        f.parameters = effects::parameters(&ctx, &chosen, &cols, &th_full, k);
    }
    let pred = effects::predict(&cols, &th_full);
    // samples at rest are in no fit (static friction is anywhere within its breakaway
    // level): they carry no residual, so they cannot show as a spectral peak either; with a
    // lag, neither do those whose delayed motion is at rest
    let mut rest_final = ctx.rest.clone();
    for &j in &lag_rows_full {
        rest_final[j] = true;
    }
    let residual: Vec<f64> = rec
        .f
        .iter()
        .zip(&pred)
        .zip(&rest_final)
        .map(|((a, b), &r)| if r { 0.0 } else { a - b })
        .collect();
    let final_full = rel(tf.rss(&th_full), tf.ff);
    let tb = base_full.0.plus(&base_full.1);
    let baseline_full = rel(tb.rss(&tb.solve()), tb.ff);
    let whiteness = report::whiteness(&residual);
    let spectrum_peaks = report::spectral_peaks(&residual, rec.dt());
    for pk in spectrum_peaks.iter().filter(|p| p.unexplained) {
        findings.push(Finding {
            effect: "unexplained".into(),
            parameters: vec![("frequency_Hz".into(), pk.freq_hz), ("amplitude_N".into(), pk.amplitude)],
            holdout_rss_drop: 0.0,
            delta_bic: 0.0,
            note: format!(
                "residual spectral peak at {:.3} Hz ({:.1}x the median spectral level) that no catalogue effect explains",
                pk.freq_hz, pk.ratio
            ),
            holdout_rel_error_after: ho_rel,
            consistency: 0.0,
        });
    }
    // the slow change found on the baseline residual, or one the final residual still shows
    let drift_carried = drift.is_some();
    let slow =
        drift.or_else(|| report::slow_change(&rec.t, &residual, &rest_final, opt.min_holdout_gain));
    if let Some(sc) = slow {
        findings.push(Finding {
            effect: "unexplained".into(),
            parameters: vec![
                ("slope_N_per_s".into(), sc.slope_n_per_s),
                ("change_N".into(), sc.change_n),
                ("largest_departure_N".into(), sc.worst_n),
                ("largest_departure_from_s".into(), sc.worst_from_s),
                ("largest_departure_to_s".into(), sc.worst_to_s),
            ],
            holdout_rss_drop: 0.0,
            delta_bic: 0.0,
            note: format!(
                "the residual's mean changes over time (a drift of the force offset: temperature, a load cell's zero, wear): {:+.3} N/s, {:+.3} N over the record, furthest from its mean by {:+.3} N over {:.2}–{:.2} s (a trend over {} blocks, F = {:.0} against the block means' scatter, bound {:.0}; {:.1} % of the residual power){}; no catalogue effect explains it",
                sc.slope_n_per_s,
                sc.change_n,
                sc.worst_n,
                sc.worst_from_s,
                sc.worst_to_s,
                sc.blocks.len(),
                sc.f_stat,
                sc.f_bound,
                100.0 * sc.power_fraction,
                if drift_carried { "; carried by a trend in time during the search and in the model" } else { "" }
            ),
            holdout_rel_error_after: ho_rel,
            consistency: 0.0,
        });
    }
    let position_spectrum = report::position_spectrum(rec, &residual);
    for pk in position_spectrum.peaks.iter().filter(|p| p.unexplained) {
        // a residual peak at a wavelength already named is that finding's remainder (a ripple
        // not purely sinusoidal, or whose amplitude varies along the stroke), not a second
        // cause: stated on the finding, not named again
        let probe = Effect {
            kind: EffectKind::Cogging,
            param: pk.wavelength_m,
            param2: 0.0,
        };
        if let Some(k) = chosen.iter().position(|c| {
            matches!(
                c.kind,
                EffectKind::Cogging | EffectKind::PositionPeriodicFriction
            ) && effects::same_wavelength(&probe, std::slice::from_ref(c))
        }) {
            let name = chosen[k].kind.name();
            if let Some(f) = findings.iter_mut().find(|f| f.effect == name) {
                f.note.push_str(&format!(
                    "; the residual still shows {:.3} N at {:.4e} m (a ripple not purely sinusoidal or varying along the stroke)",
                    pk.amplitude, pk.wavelength_m
                ));
            }
            continue;
        }
        let matches = if pk.matches.is_empty() {
            String::new()
        } else {
            format!("; its wavelength matches {}", pk.matches)
        };
        findings.push(Finding {
            effect: "unexplained".into(),
            parameters: vec![
                ("wavelength_m".into(), pk.wavelength_m),
                ("cycles_per_m".into(), pk.cycles_per_m),
                ("amplitude_N".into(), pk.amplitude),
            ],
            holdout_rss_drop: 0.0,
            delta_bic: 0.0,
            note: format!(
                "residual periodic in position, wavelength {:.4e} m ({:.1}x the median level of the position spectrum){matches}, that no catalogue effect explains",
                pk.wavelength_m, pk.ratio
            ),
            holdout_rel_error_after: ho_rel,
            consistency: 0.0,
        });
    }
    let mut verdicts = baseline_verdicts(&ctx.base_th);
    let n_rest = ctx.rest.iter().filter(|r| **r).count();
    if n_rest > 0 {
        verdicts.push(format!(
            "{n_rest} of {n} samples at rest (position still within its noise over ±{} samples), within that window of rest or at the record's ends: left out of every fit (friction at rest is static, anywhere within its breakaway level)",
            effects::REST_HALF_WINDOW
        ));
    }
    if let (Some(tau), false) = (lag_of(&chosen), lag_rows_full.is_empty()) {
        verdicts.push(format!(
            "{} samples in motion whose motion {tau:.4} s earlier (the lag) is at rest, or whose speed lies inside the Coulomb sign's band: left out of the fits with the lag and of those it is compared with (the delayed device is at rest there, or the baseline's sign is not the sliding device's)",
            lag_rows_full.len()
        ));
    }
    verdicts.extend(dropped_notes);
    if fit_rank < cols.len() {
        verdicts.push(format!(
            "RANK-DEFICIENT FIT: the final model's {} columns have numerical rank {fit_rank} (condition number {fit_condition:.3e}): some coefficients are not determined by this record (the minimum-norm solution is reported); the motion does not separate those terms",
            cols.len()
        ));
    }
    Diagnosis {
        n,
        verdicts,
        derivative_method: rec.derivative_method.clone(),
        baseline_terms,
        baseline_holdout_rel_error: baseline_holdout,
        baseline_train_rel_error: baseline_train,
        baseline_full_rel_error: baseline_full,
        findings,
        final_holdout_rel_error: ho_rel,
        final_full_rel_error: final_full,
        model: cols.iter().map(|c| c.0.clone()).zip(th_full).collect(),
        stage_models,
        effects: chosen,
        residual,
        prediction: pred,
        whiteness,
        spectrum_peaks,
        position_spectrum,
        cross: None,
        fit_rank,
        fit_condition,
    }
}

/// The shape checks of `try_diagnose` alone (lengths, finiteness, sample period).
fn try_diagnose_shape(rec: &Record) -> Result<(), String> {
    let n = rec.len();
    let lens = [rec.x.len(), rec.f.len(), rec.v.len(), rec.a.len()];
    let finite = |c: &[f64]| c.iter().all(|v| v.is_finite());
    if n < 3
        || lens.iter().any(|&l| l != n)
        || !(finite(&rec.t) && finite(&rec.x) && finite(&rec.f) && finite(&rec.v) && finite(&rec.a))
        || rec.extra.values().any(|c| c.len() != n || !finite(c))
    {
        return Err(
            "record: fewer than 3 samples, columns of different lengths or non-finite values"
                .into(),
        );
    }
    Ok(())
}

/// Physical checks of the baseline (inertia, viscous and Coulomb friction are non-negative),
/// each failed one stated with what it suggests.
pub fn baseline_verdicts(th: &[f64]) -> Vec<String> {
    let mut v = Vec::new();
    let get = |i: usize| th.get(i).copied().unwrap_or(0.0);
    if get(0) < 0.0 {
        v.push(format!(
            "NON-PHYSICAL BASELINE: inertia {:.4e} kg < 0. The force falls with acceleration: on periodic motion a stiffness (force ∝ x, in antiphase with a) fits as a negative mass, so a spring, a resonance above the motion band or a position-dependent force dominates; the catalogue's names are not reliable on this record",
            get(0)
        ));
    }
    if get(1) < 0.0 {
        v.push(format!(
            "NON-PHYSICAL BASELINE: viscous friction {:.4e} N·s/m < 0. The device delivers power in proportion to speed: an active drive (a motor pushing with the motion) or a force channel that leads or lags the position",
            get(1)
        ));
    }
    if get(2) < 0.0 {
        v.push(format!(
            "NON-PHYSICAL BASELINE: Coulomb friction {:.4e} N < 0. The force steps against friction at reversals: play (the force drops at reversals), an active drive or a sign convention of f_N opposite to x_m",
            get(2)
        ));
    }
    v
}

/// Evaluate the diagnosed model on a second record: refit nothing, use the coefficients of
/// the whole-record fit, effects in order of discovery.
pub fn cross_check(d: &mut Diagnosis, other: &Record) {
    if d.stage_models.len() != d.effects.len() + 1 || try_diagnose_shape(other).is_err() {
        // nothing was fitted, or the second record cannot be evaluated
        d.cross = None;
        return;
    }
    let ctx = effects::Context::new(other);
    let ffo: f64 = other.f.iter().map(|v| v * v).sum();
    let err_of = |k: usize| -> f64 {
        // baseline + first k effects, with that stage's coefficients (whole first record)
        let cols = effects::build_columns(&ctx, &d.effects[..k]);
        let mut pred = vec![0.0; other.len()];
        for (name, c) in &cols {
            if let Some((_, th)) = d.stage_models[k].iter().find(|(n, _)| n == name) {
                for (p, v) in pred.iter_mut().zip(c) {
                    *p += th * v;
                }
            }
        }
        let rss: f64 = other
            .f
            .iter()
            .zip(&pred)
            .map(|(a, b)| (a - b) * (a - b))
            .sum();
        rel(rss, ffo)
    };
    let base = err_of(0);
    let after_each: Vec<(String, f64)> = (1..=d.effects.len())
        .map(|k| (d.effects[k - 1].kind.name().to_string(), err_of(k)))
        .collect();
    let worsens = after_each
        .iter()
        .scan(base, |prev, (_, e)| {
            let w = *e > *prev;
            *prev = *e;
            Some(w)
        })
        .collect();
    d.cross = Some(CrossCheck {
        baseline_rel_error: base,
        final_rel_error: err_of(d.effects.len()),
        after_each,
        worsens,
    });
}

/// The screening columns of each candidate value, keyed by its kind and parameter's bits.
type ScreenColumns = std::collections::HashMap<(usize, u64), Vec<(String, Vec<f64>)>>;

/// The column span of each effect of `set` in a design whose first `n_fixed` columns are the
/// fixed terms, followed by each effect's columns in the set's order (`cache` holds them).
fn effect_spans(set: &[Effect], n_fixed: usize, cache: &ScreenColumns) -> Vec<(usize, usize)> {
    let mut at = n_fixed;
    set.iter()
        .map(|e| {
            let k = cache.get(&e.key()).map_or(0, |z| z.len());
            at += k;
            (at - k, at)
        })
        .collect()
}

/// Every effect of `set` (at `spans` in the coefficients `th`, the baseline's first) inside its
/// physical range (`effects::plausible`): an effect added beside others can move their fit out
/// of it (on the rig's clipped multisine 100051 a `screw_efficiency` beside the drive's clip
/// took part of the viscous force and left the clip's damping above the viscous coefficient).
pub fn set_physical(set: &[Effect], spans: &[(usize, usize)], th: &[f64]) -> bool {
    set.iter().zip(spans).all(|(e, &(a, b))| {
        b <= th.len() && effects::plausible(e, &th[a..b], &th[..4.min(th.len())])
    })
}

/// True when a scanned range has more than one value (an edge can be told from the interior).
fn coarse_len_gt1(lo: f64, hi: f64) -> bool {
    hi > lo
}

fn refs(c: &[(String, Vec<f64>)]) -> Vec<&[f64]> {
    c.iter().map(|(_, v)| v.as_slice()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The first finding's `lag_s` and `gain` (0 where it has none: a lag test's first
    /// finding is the lag it expects).
    fn first_lag(d: &Diagnosis) -> (f64, f64) {
        let p = |k: &str| {
            d.findings
                .first()?
                .parameters
                .iter()
                .find(|p| p.0 == k)
                .map(|p| p.1)
        };
        (p("lag_s").unwrap_or(0.0), p("gain").unwrap_or(0.0))
    }

    /// `change_rows` forms each product of a row once for its two entries of the Gram matrix:
    /// the result is, bit for bit, each entry's own products written out here (every entry
    /// p, q accumulating sign·c_p·c_q over the rows, in the rows' order), for removal and
    /// addition, starting from a Gram matrix that is not symmetric in its last bits. Break:
    /// the lower triangle's update left out fails.
    #[test]
    fn change_rows_is_each_entrys_own_sum() {
        let n = 40;
        let cols: Vec<Vec<f64>> = (0..5)
            .map(|c| {
                (0..n)
                    .map(|i| ((i * 7 + c * 13) as f64 * 0.37).sin() * (1.0 + c as f64) / 3.0)
                    .collect()
            })
            .collect();
        let refs: Vec<&[f64]> = cols.iter().map(|c| c.as_slice()).collect();
        let f: Vec<f64> = (0..n).map(|i| (i as f64 * 0.11).cos() * 7.3).collect();
        let part: Vec<u8> = (0..n)
            .map(|i| if i % 4 == 3 { HELD_OUT } else { TRAIN })
            .collect();
        let mut nn = normals(&refs, &f, &part, 1);
        nn.0.g[1] += 1e-13; // g[0][1] and g[1][0] no longer equal
        let rows: Vec<usize> = (0..n).filter(|i| i % 3 != 1).collect();
        for sign in [-1.0, 1.0] {
            let got = change_rows(&nn, &refs, &f, &part, &rows, sign);
            let mut want = nn.clone();
            let m = refs.len();
            for &i in &rows {
                let nm = if part[i] == TRAIN {
                    &mut want.0
                } else {
                    &mut want.1
                };
                for p in 0..m {
                    for q in 0..m {
                        nm.g[p * m + q] += sign * refs[p][i] * refs[q][i];
                    }
                }
            }
            for (g, w) in [(&got.0.g, &want.0.g), (&got.1.g, &want.1.g)] {
                let gb: Vec<u64> = g.iter().map(|x| x.to_bits()).collect();
                let wb: Vec<u64> = w.iter().map(|x| x.to_bits()).collect();
                assert_eq!(gb, wb, "sign {sign}");
            }
        }
    }

    /// `set_physical` checks every effect of a set in its own span: baseline M 40 kg, Fv 300,
    /// Fc 20 N, offset 0, then a drive's clip (damping c_d) and a Stribeck bump. The clip is a
    /// device's only with Fv/2 ≤ c_d ≤ Fv, the bump only positive; either one out of range
    /// makes the set non-physical, whichever candidate stands beside it. Break: `all` taken
    /// as `any` (one physical effect enough) passes the clip of 350 > 300 beside a physical
    /// bump and fails the second assertion.
    #[test]
    fn set_physical_checks_each_effect_in_its_span() {
        let set = [
            Effect {
                kind: EffectKind::CurrentLimit,
                param: -0.08,
                param2: 0.0,
            },
            Effect {
                kind: EffectKind::Stribeck,
                param: 0.004,
                param2: 0.0,
            },
        ];
        let spans = [(4, 5), (5, 6)];
        let th = |cd: f64, bump: f64| vec![40.0, 300.0, 20.0, 0.0, cd, bump, 0.3];
        assert!(set_physical(&set, &spans, &th(250.0, 5.0)));
        assert!(!set_physical(&set, &spans, &th(350.0, 5.0)));
        assert!(!set_physical(&set, &spans, &th(100.0, 5.0)));
        assert!(!set_physical(&set, &spans, &th(250.0, -5.0)));
        assert!(set_physical(&[], &[], &th(350.0, -5.0)));
    }

    /// Gram matrix and right-hand side of columns `c` against `y`.
    fn normal_eq(c: &[Vec<f64>], y: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let m = c.len();
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let g = (0..m * m).map(|k| dot(&c[k / m], &c[k % m])).collect();
        let b = c.iter().map(|ci| dot(ci, y)).collect();
        (g, b)
    }

    /// A play's agreement is that of the segment fits where it holds: one fit without the
    /// record's contacts (taps in their null space) spoils the jackknife t of all five, not
    /// that of the four that hold. Broken (all five taken) it fails.
    #[test]
    fn agreement_is_asked_of_the_segments_that_hold() {
        // four segment fits of a play (gain, three taps) agreeing within 1 %, and one fit
        // without the record's contacts: its taps in their null space (±2,000 kg)
        let good = |e: f64| vec![1.0 + e, 15.0 * (1.0 + e), 22.0 * (1.0 - e), 8.0];
        let mut fits: Vec<Vec<f64>> = [0.01, -0.01, 0.005, 0.0].iter().map(|e| good(*e)).collect();
        fits.insert(0, vec![1.0, 0.0, 2000.0, -2000.0]);
        let held = [false, true, true, true, true];
        let all = jackknife_t(&fits);
        let of_held = agreement_of_held(&fits, &held);
        assert!(all < AGREEMENT_T, "all five: t = {all}");
        assert!(
            of_held > 10.0 * AGREEMENT_T,
            "the four that hold: t = {of_held}"
        );
        assert_eq!(of_held, jackknife_t(&fits[1..]));
    }

    /// A play's agreement is that of its gain and its impact's momentum, not of the pulse's
    /// shape: five segment fits (gain, three taps) agreeing within 1 %, one of them with its
    /// contact a sample later (the pulse moved to the next taps, its sum kept), agree on the
    /// gain and the momentum (t = 70.7 each) though not on the taps (t = 1.9); fits whose
    /// momentum scatters by ±70 % do not agree. Broken (the taps' `agreement_of_held`, or the
    /// gain's alone) it fails.
    #[test]
    fn play_agreement_is_that_of_its_gain_and_momentum() {
        let e = [0.01, -0.01, 0.005, 0.0, -0.005];
        let pulse = |e: f64, late: bool| {
            let p = if late {
                [0.0, 50.0, 10.0]
            } else {
                [50.0, 10.0, 0.0]
            };
            std::iter::once(1.0 + e)
                .chain(p.iter().map(|t| t * (1.0 + e)))
                .collect::<Vec<f64>>()
        };
        let fits: Vec<Vec<f64>> = e
            .iter()
            .enumerate()
            .map(|(k, &ei)| pulse(ei, k == 4))
            .collect();
        let held = [true; 5];
        let taps = agreement_of_held(&fits, &held);
        let play = play_agreement(&fits, &held);
        assert!(taps < AGREEMENT_T, "taps: t = {taps}");
        assert!(play > 20.0 * AGREEMENT_T, "gain and momentum: t = {play}");
        // the momentum scattering (×1, 0.3, 1.7, 0.5, 1.5) with the gain agreeing
        let scattered: Vec<Vec<f64>> = [1.0, 0.3, 1.7, 0.5, 1.5]
            .iter()
            .zip(&e)
            .map(|(k, ei)| vec![1.0 + ei, 60.0 * k, 0.0, 0.0])
            .collect();
        let t = play_agreement(&scattered, &held);
        assert!(t < AGREEMENT_T, "scattered momentum: t = {t}");
    }

    /// The jackknife t of leave-one-segment-out fits against its closed form: scalar fits
    /// 1.0, 1.1, 0.9, 1.0, 1.0 have mean 1 and Σ(θ_i − θ̄)² = 0.02, so se = √(4/5·0.02) and
    /// t = 1/se = 7.906; two-column fits are projected on their mean (fits along one
    /// direction give the scalar result times its norm over the same spread); fits scattered
    /// around zero give t below `AGREEMENT_T`.
    #[test]
    fn jackknife_t_matches_closed_form() {
        let f: Vec<Vec<f64>> = [1.0, 1.1, 0.9, 1.0, 1.0].iter().map(|v| vec![*v]).collect();
        let want = 1.0 / (0.8f64 * 0.02).sqrt();
        assert!(
            (jackknife_t(&f) / want - 1.0).abs() < 1e-12,
            "{}",
            jackknife_t(&f)
        );
        // the same along (3, 4)/5 · 5: norm 5 × mean 1, projections 5 × the scalars
        let g: Vec<Vec<f64>> = f.iter().map(|v| vec![3.0 * v[0], 4.0 * v[0]]).collect();
        assert!(
            (jackknife_t(&g) / want - 1.0).abs() < 1e-12,
            "{}",
            jackknife_t(&g)
        );
        let z: Vec<Vec<f64>> = [0.5, -0.4, 0.3, -0.2, 0.1]
            .iter()
            .map(|v| vec![*v])
            .collect();
        assert!(jackknife_t(&z) < AGREEMENT_T, "{}", jackknife_t(&z));
        assert_eq!(jackknife_t(&f[..2]), 0.0);
    }

    /// Straight line through noisy points: the closed-form slope Sxy/Sxx and intercept
    /// ȳ − slope·x̄, with columns of very different scale (x in µm-sized units, offset 1).
    #[test]
    fn line_fit_matches_closed_form() {
        let x: Vec<f64> = (0..50).map(|i| 1e-6 * i as f64).collect();
        let y: Vec<f64> = x
            .iter()
            .enumerate()
            .map(|(i, &x)| 3.0 + 2.5e5 * x + if i % 2 == 0 { 0.1 } else { -0.07 })
            .collect();
        let n = x.len() as f64;
        let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
        let sxy: f64 = x.iter().zip(&y).map(|(a, b)| (a - mx) * (b - my)).sum();
        let sxx: f64 = x.iter().map(|a| (a - mx) * (a - mx)).sum();
        let slope = sxy / sxx;
        let icpt = my - slope * mx;
        let (g, b) = normal_eq(&[vec![1.0; x.len()], x.clone()], &y);
        let s = solve_sym(&g, &b, 2);
        assert_eq!(s.rank, 2);
        // both within rounding of the closed form (relative 1e-9: the normal equations square
        // the design's condition, here about 1.7e2, so about 3e4 ulp of headroom)
        assert!((s.th[0] / icpt - 1.0).abs() < 1e-9, "{:?} vs {icpt}", s.th);
        assert!(
            (s.th[1] / slope - 1.0).abs() < 1e-9,
            "{:?} vs {slope}",
            s.th
        );
    }

    /// Two unit-norm columns at cosine c: the design's condition number is
    /// sqrt((1 + c)/(1 − c)) (eigenvalues 1 ± c of the Gram matrix).
    #[test]
    fn condition_number_matches_closed_form() {
        for c in [0.0, 0.5, 0.9, 0.999] {
            let g = [1.0, c, c, 1.0];
            let s = solve_sym(&g, &[1.0, 0.0], 2);
            let want = ((1.0 + c) / (1.0 - c)).sqrt();
            assert!(
                (s.condition / want - 1.0).abs() < 1e-9,
                "{c}: {s:?} vs {want}"
            );
            // and the solution is the inverse Gram's first column: (1, −c)/(1 − c²)
            assert!((s.th[0] - 1.0 / (1.0 - c * c)).abs() < 1e-6 * s.th[0].abs());
            assert!((s.th[1] + c / (1.0 - c * c)).abs() < 1e-6 * s.th[0].abs());
        }
    }

    /// The same column twice: rank 1, the minimum-norm solution splits the coefficient
    /// equally (no 1e30 pivot, no blow-up); a column of zeros gets 0; a NaN gives rank 0.
    #[test]
    fn rank_deficient_is_minimum_norm() {
        let u: Vec<f64> = (0..20).map(|i| (i as f64 * 0.7).sin()).collect();
        let y: Vec<f64> = u.iter().map(|v| 4.0 * v).collect();
        let (g, b) = normal_eq(&[u.clone(), u.clone(), vec![0.0; 20]], &y);
        let s = solve_sym(&g, &b, 3);
        assert_eq!(s.rank, 1, "{s:?}");
        assert!(
            (s.th[0] - 2.0).abs() < 1e-9 && (s.th[1] - 2.0).abs() < 1e-9,
            "{s:?}"
        );
        assert_eq!(s.th[2], 0.0);
        let s = solve_sym(&[f64::NAN], &[1.0], 1);
        assert_eq!((s.th[0], s.rank), (0.0, 0));
    }

    /// The Gram entries kept across a growing base (`extend_normals_cached`) are those
    /// `extend_normals_dense` computes from scratch, bit for bit, round after round; a base
    /// column replaced by another is recomputed.
    /// The weighted sums `dot2` stands for, over every sample (four partial sums, the last
    /// len mod 4 samples to the first).
    fn dot2_weighted(a: &[f64], b: &[f64], wt: &[f64], wh: &[f64]) -> (f64, f64) {
        let n = a.len();
        let (mut t, mut h) = ([0.0f64; 4], [0.0f64; 4]);
        let m = n / 4 * 4;
        for i in 0..n {
            let l = if i < m { i % 4 } else { 0 };
            let p = a[i] * b[i];
            t[l] += p * wt[i];
            h[l] += p * wh[i];
        }
        ((t[0] + t[1]) + (t[2] + t[3]), (h[0] + h[1]) + (h[2] + h[3]))
    }

    #[test]
    fn dot2_runs_match_weighted_sums() {
        let mut s = 12345u64;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for n in [1usize, 3, 4, 5, 17, 1000, 1003] {
            let a: Vec<f64> = (0..n).map(|_| rnd() * 1e3).collect();
            let b: Vec<f64> = (0..n).map(|_| rnd()).collect();
            // blocks of the holdout mask with samples at rest scattered, runs of any length
            let mut part = holdout_mask(n);
            for p in part.iter_mut() {
                if rnd() > 0.3 {
                    *p = AT_REST;
                }
            }
            let w = HoldWeights::new(&part);
            let (t, h) = dot2(&a, &b, &w);
            let (t0, h0) = dot2_weighted(&a, &b, &w.train, &w.hold);
            assert_eq!(
                (t.to_bits(), h.to_bits()),
                (t0.to_bits(), h0.to_bits()),
                "n = {n}"
            );
            // several columns in one pass (four, two and one at a time): each the same sums
            let bs: Vec<Vec<f64>> = (0..7)
                .map(|_| (0..n).map(|_| rnd() * 10.0).collect())
                .collect();
            let br: Vec<&[f64]> = bs.iter().map(|v| v.as_slice()).collect();
            let many = dot2_many(&a, &br, &w);
            assert_eq!(many.len(), bs.len());
            for (b, (t, h)) in bs.iter().zip(many) {
                let (t0, h0) = dot2_weighted(&a, b, &w.train, &w.hold);
                assert_eq!(
                    (t.to_bits(), h.to_bits()),
                    (t0.to_bits(), h0.to_bits()),
                    "n = {n}, batched"
                );
            }
        }
    }

    /// `normals` with the column count known when compiled gives, entry by entry, the sums of
    /// the loop for any count (1 to 10 columns, samples at rest scattered, strides 1 and 3).
    #[test]
    fn normals_k_matches_any() {
        let n = 1003;
        let col = |s: f64| -> Vec<f64> { (0..n).map(|i| (s * i as f64).sin() + 0.1 * s).collect() };
        let f = col(0.37);
        let part: Vec<u8> = (0..n)
            .map(|i| [TRAIN, HELD_OUT, AT_REST][i % 7 % 3])
            .collect();
        let cs: Vec<Vec<f64>> = (0..10).map(|k| col(0.011 + 0.013 * k as f64)).collect();
        for m in 1..=10 {
            let r: Vec<&[f64]> = cs[..m].iter().map(|v| v.as_slice()).collect();
            for stride in [1, 3] {
                let (a, b) = (
                    normals(&r, &f, &part, stride),
                    normals_any(&r, &f, &part, stride),
                );
                for (x, y) in [(&a.0, &b.0), (&a.1, &b.1)] {
                    assert_eq!(x.g, y.g, "m = {m}");
                    assert_eq!(x.b, y.b, "m = {m}");
                    assert_eq!((x.ff.to_bits(), x.n, x.m), (y.ff.to_bits(), y.n, y.m));
                }
            }
        }
    }

    #[test]
    fn cached_gram_matches_dense() {
        let n = 1000;
        let col = |s: f64| -> Vec<f64> { (0..n).map(|i| (s * i as f64).sin() + 0.1 * s).collect() };
        let f = col(0.37);
        let part: Vec<u8> = (0..n)
            .map(|i| [TRAIN, HELD_OUT, AT_REST][i % 7 % 3])
            .collect();
        let w = HoldWeights::new(&part);
        let mut base_cols: Vec<Vec<f64>> = vec![col(0.011), col(0.023)];
        let mut ids: Vec<ColumnId> = vec![(0, 0), (0, 1)];
        let z = [col(0.05), col(0.071)];
        let zr: Vec<&[f64]> = z.iter().map(|v| v.as_slice()).collect();
        let mut gc = GramCache::default();
        for round in 0..4 {
            if round == 3 {
                base_cols[1] = col(0.029);
                ids[1] = (1, 1);
            }
            let br: Vec<&[f64]> = base_cols.iter().map(|v| v.as_slice()).collect();
            let base = normals(&br, &f, &part, 1);
            let dense = extend_normals_dense(&base, &br, &zr, &f, &w);
            let cached = extend_normals_cached(&base, &br, &ids, &zr, &f, &w, &mut gc);
            for (a, b) in [(&dense.0, &cached.0), (&dense.1, &cached.1)] {
                assert_eq!(a.g, b.g, "round {round}");
                assert_eq!(a.b, b.b, "round {round}");
                assert_eq!((a.ff, a.n), (b.ff, b.n));
            }
            base_cols.push(col(0.1 + round as f64));
            ids.push((2, round));
        }
        // the swap pass's sets: one column left out of the middle, then the whole set again
        // (the products met before are reused, whatever their position in the base)
        for drop in [Some(2), None, Some(1), None] {
            let keep: Vec<usize> = (0..ids.len()).filter(|&j| Some(j) != drop).collect();
            let br: Vec<&[f64]> = keep.iter().map(|&j| base_cols[j].as_slice()).collect();
            let bid: Vec<ColumnId> = keep.iter().map(|&j| ids[j]).collect();
            let base = normals(&br, &f, &part, 1);
            let dense = extend_normals_dense(&base, &br, &zr, &f, &w);
            let cached = extend_normals_cached(&base, &br, &bid, &zr, &f, &w, &mut gc);
            for (a, b) in [(&dense.0, &cached.0), (&dense.1, &cached.1)] {
                assert_eq!(a.g, b.g, "without {drop:?}");
                assert_eq!(a.b, b.b, "without {drop:?}");
            }
        }
    }

    /// A unit move over `tm` at constant acceleration then deceleration (a triangular
    /// speed): its position, velocity and acceleration at the move's fraction `s` ∈ [0, 1]
    /// of `tm` (at rest at the end for s ≥ 1).
    pub(super) fn triangular_speed(s: f64, tm: f64) -> (f64, f64, f64) {
        if s >= 1.0 {
            (1.0, 0.0, 0.0)
        } else if s < 0.5 {
            (2.0 * s * s, 4.0 * s / tm, 4.0 / (tm * tm))
        } else {
            let r = 1.0 - s;
            (1.0 - 2.0 * r * r, 4.0 * r / tm, -4.0 / (tm * tm))
        }
    }

    /// Force noise of unit variance for the test records (xorshift64*, the sum of 12
    /// uniforms − 6), seeded: shares nothing with the diagnosis.
    pub(super) fn unit_noise(mut seed: u64) -> impl FnMut() -> f64 {
        move || {
            (0..12)
                .map(|_| {
                    seed ^= seed >> 12;
                    seed ^= seed << 25;
                    seed ^= seed >> 27;
                    (seed.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
                })
                .sum::<f64>()
                - 6.0
        }
    }

    /// A closed-form record: a three-tone motion with its exact velocity and acceleration, and
    /// the force M·a + Fv·v + Fc·sign(v) of a device evaluated at t − τ, white noise 0.3 N.
    fn delayed_record(m: f64, fv: f64, fc: f64, tau: f64) -> Record {
        let (fs, n) = (1000.0, 12_000);
        let tones = [(0.31, 0.012, 0.3), (0.73, 0.008, 1.9), (1.37, 0.004, 4.1)];
        let motion = |t: f64| {
            tones
                .iter()
                .fold((0.0, 0.0, 0.0), |(x, v, a), &(f, amp, ph)| {
                    let w = std::f64::consts::TAU * f;
                    let (sn, cs) = (w * t + ph).sin_cos();
                    (x + amp * sn, v + amp * w * cs, a - amp * w * w * sn)
                })
        };
        let mut noise = unit_noise(0x9E37_79B9_7F4A_7C15);
        let mut rec = Record::default();
        for i in 0..n {
            let t = i as f64 / fs;
            let (x, v, a) = motion(t);
            let (_, vd, ad) = motion(t - tau);
            rec.t.push(t);
            rec.x.push(x);
            rec.v.push(v);
            rec.a.push(a);
            rec.f
                .push(m * ad + fv * vd + fc * vd.signum() + 0.3 * noise());
        }
        rec
    }

    /// A force channel delayed by τ = 12.5 samples (not a whole number) on a closed-form
    /// record (`delayed_record`). The delayed baseline (`lag_coefs` at the true τ) gives the
    /// device's M, Fv, Fc (the baseline fitted on the delayed record does not), and the
    /// diagnosis names `lag` alone, its delay and its unit gain within the bounds below.
    #[test]
    fn lag_is_the_whole_force_delayed() {
        let (m, fv, fc, tau) = (40.0, 300.0, 20.0, 0.0125);
        let rec = delayed_record(m, fv, fc, tau);
        let ctx = effects::Context::new(&rec);
        let th = ctx.lag_coefs(tau).expect("a device's coefficients");
        let dev = [th[0] / m - 1.0, th[1] / fv - 1.0, th[2] / fc - 1.0];
        println!(
            "delayed baseline {th:?}: {dev:?}; baseline {:?}",
            &ctx.base_th[..3]
        );
        // measured: +0.21 %, +0.05 %, −0.02 % (the noise); asserted 0.6 % (3× the largest)
        assert!(dev.iter().all(|d| d.abs() < 6e-3), "{dev:?}");
        // the bias it removes: the baseline fitted on the delayed record has an inertia 21 %
        // below M (measured 31.6 kg)
        assert!(ctx.base_th[0] < 0.9 * m, "{}", ctx.base_th[0]);
        let d = diagnose(&rec, &Options::default());
        let names = d.catalogue_names();
        let (lag, gain) = first_lag(&d);
        println!(
            "{names:?}: lag {lag} s ({:+.3} %), gain {gain}",
            100.0 * (lag / tau - 1.0)
        );
        assert_eq!(names, ["lag"], "{:?}", d.verdicts);
        // measured: lag −1.91 % (refined on the screening subsample), gain +0.19 %; asserted
        // 5 % and 3 % (3× the largest measured, rounded up)
        assert!((lag / tau - 1.0).abs() < 0.05, "lag {lag}");
        assert!((gain - 1.0).abs() < 0.03, "gain {gain}");
    }

    /// `delayed_record`'s motion and force (M = 40 kg, Fv = 300 N·s/m, Fc = 20 N, white
    /// noise 0.3 N) delayed by `tau`, as a CSV whose position is quantised to `q` (exact when
    /// 0), read with the default derivation (v and a derived from x at fs/20).
    fn delayed_csv(tau: f64, q: f64) -> Record {
        quantised_csv(&delayed_record(40.0, 300.0, 20.0, tau), q)
    }

    /// The record `r`'s time and force with its position quantised to `q` (exact when 0), as
    /// a CSV read with the default derivation (v and a derived from x at fs/20).
    fn quantised_csv(r: &Record, q: f64) -> Record {
        let mut s = String::from("t_s,x_m,f_N\n");
        for i in 0..r.len() {
            let x = if q > 0.0 {
                (r.x[i] / q).round() * q
            } else {
                r.x[i]
            };
            s.push_str(&format!("{},{x},{}\n", r.t[i], r.f[i]));
        }
        parse_csv(&s, None).expect("parses")
    }

    /// The errors in the variables of `lag`'s column (`Context::lag_noise`) against the noise
    /// the derivation of a quantised position gives: the same record read with its position
    /// quantised to 6.4 µm (the rig's coarsest encoder) and exact; the quantised minus the
    /// exact derived a and v, and the lag's column built from them at the delayed device's
    /// coefficients, give the measured covariances.
    #[test]
    fn lag_noise_is_the_derivation_noise() {
        let (tau, q) = (0.0125, 6.4e-6);
        let (rq, r0) = (delayed_csv(tau, q), delayed_csv(tau, 0.0));
        let ctx = effects::Context::new(&rq);
        let s = ctx.lag_noise(tau).expect("a derivation noise");
        let th = ctx.lag_coefs(tau).expect("a delayed device");
        let ea: Vec<f64> = rq.a.iter().zip(&r0.a).map(|(a, b)| a - b).collect();
        let ev: Vec<f64> = rq.v.iter().zip(&r0.v).map(|(a, b)| a - b).collect();
        let k = tau / ctx.dt;
        let rows = 200..rq.len() - 200;
        let e: Vec<[f64; 3]> = rows
            .map(|i| {
                let z = th[0] * (effects::delayed(&ea, i, k) - ea[i])
                    + th[1] * (effects::delayed(&ev, i, k) - ev[i]);
                [ea[i], ev[i], z]
            })
            .collect();
        let cov = |r: usize, c: usize| e.iter().map(|x| x[r] * x[c]).sum::<f64>() / e.len() as f64;
        let ratio: Vec<f64> = [(0, 0), (1, 1), (2, 2), (2, 0), (2, 1)]
            .iter()
            .map(|&(r, c)| s[r][c] / cov(r, c))
            .collect();
        println!("predicted / measured (aa, vv, zz, za, zv): {ratio:?}");
        // measured: 0.94, 0.93, 0.90, 0.91, 0.82 (the quantisation error of a motion crossing
        // 1–4 quanta per sample is not quite white); asserted within 30 % (1.7× the largest
        // deviation: the cross terms' sign, a shift's direction, fail it: the shift reversed
        // gives −0.48 for zv)
        for r in &ratio {
            assert!((r - 1.0).abs() < 0.3, "{ratio:?}");
        }
    }

    /// On the same record with its position quantised to 6.4 µm the least-squares gain of
    /// `lag` is biased low by the derived signals' noise, its τ long; `lag` is named alone
    /// with its delay, τ and the range of its gain judged on the corrected fit
    /// (`lag_corrected`).
    #[test]
    fn lag_is_named_through_the_derived_noise() {
        let tau = 0.0125;
        let rec = delayed_csv(tau, 3.2e-6);
        let d = diagnose(&rec, &Options::default());
        let names = d.catalogue_names();
        let (lag, gain) = first_lag(&d);
        println!(
            "{names:?}: lag {lag} s ({:+.3} %), gain {gain}; {:?}",
            100.0 * (lag / tau - 1.0),
            d.verdicts
        );
        assert_eq!(names, ["lag"], "{:?}", d.verdicts);
        // measured: lag +1.27 %, least-squares gain 0.63 (below the unit range: without the
        // correction nothing is named); asserted 5 % (as `lag_is_the_whole_force_delayed`)
        assert!((lag / tau - 1.0).abs() < 0.05, "lag {lag}");
    }

    /// The errors-in-variables fit (`eiv_fit`) in closed form: f = 2·x + force noise (unit
    /// variance) regressed on x + e (x and e white, unit variance, with an offset column):
    /// least squares attenuates the slope by var x / (var x + var e) = 1/2, to 1; the fit
    /// corrected by S = var e = 1 gives 2, and its held-out rss per row less θ²·S the force
    /// noise's variance, 1 (least squares leaves 2² − 2²/2 + 1 = 3 there).
    #[test]
    fn eiv_fit_undoes_the_attenuation() {
        let n = 40_000;
        let (mut nx, mut ne, mut nf) = (unit_noise(7), unit_noise(11), unit_noise(13));
        let (mut x, mut f) = (Vec::new(), Vec::new());
        for _ in 0..n {
            let xt = nx();
            x.push(xt + ne());
            f.push(2.0 * xt + nf());
        }
        let ones = vec![1.0; n];
        let part: Vec<u8> = (0..n)
            .map(|i| if i % 5 == 4 { HELD_OUT } else { TRAIN })
            .collect();
        let (tr, ho) = normals(&[&x, &ones], &f, &part, 1);
        let s = [[1.0, 0.0, 0.0], [0.0; 3], [0.0; 3]];
        let ls = tr.solve();
        let (th, rss) = eiv_fit(&tr, &ho, &[0], &s).expect("a corrected fit");
        let per_row = rss / ho.n as f64;
        let ls_row = ho.rss(&ls) / ho.n as f64;
        println!("slope least squares {}, corrected {}; held-out rss per row {ls_row}, corrected {per_row}", ls[0], th[0]);
        // measured: slope 0.984 (least squares), 1.976 (corrected); rss per row 2.99,
        // corrected 0.966 (the sample's own variances, 40,000 rows); bounds 3× the measured
        // deviations from 1, 2 and 1. Break: S × 2 (the Gram left singular) gives slope 0;
        // the θᵀSθ term dropped, rss per row 4.87
        assert!((th[0] - 2.0).abs() < 0.075, "slope {}", th[0]);
        assert!((per_row - 1.0).abs() < 0.1, "rss per row {per_row}");
        assert!((ls[0] - 1.0).abs() < 0.05, "least squares {}", ls[0]);
    }

    /// The `compliance` column's noise (`Context::compliance_noise`, the derived
    /// acceleration's quantisation noise through the column's filter H − 1) against the
    /// noise the derivation gives: `delayed_record` (undelayed) read with its position
    /// quantised to 6.4 µm and exact; the column built from the quantised minus the exact
    /// derived a gives the measured variance, at modes across the grid's range.
    #[test]
    fn compliance_noise_is_the_derivation_noise() {
        let (rq, r0) = (delayed_csv(0.0, 6.4e-6), delayed_csv(0.0, 0.0));
        let ctx = effects::Context::new(&rq);
        let nz = ctx.deriv_noise().expect("a derivation noise");
        let ea: Vec<f64> = rq.a.iter().zip(&r0.a).map(|(a, b)| a - b).collect();
        let mut ratio = Vec::new();
        for (f, z) in [(3.0, 0.05), (8.0, 0.3), (15.0, 0.1)] {
            let col = |s: &[f64]| {
                effects::compliance_columns_at(s, &[(f, z)], ctx.dt, None)
                    .pop()
                    .unwrap_or_default()
            };
            let e = col(&ea);
            let rows = 200..e.len() - 200;
            let measured = e[rows.clone()].iter().map(|y| y * y).sum::<f64>() / rows.len() as f64;
            ratio.push(nz.accel_cov_through(col)[2][2] / measured);
        }
        println!("predicted / measured at 3, 8, 15 Hz: {ratio:?}");
        // measured: 0.926, 0.936, 0.942 (the quantisation error of a motion crossing 1–4
        // quanta per sample is not quite white, as for `lag_noise_is_the_derivation_noise`);
        // asserted within 22 % (3× the largest deviation, 7.4 %). Break: the velocity's
        // response in place of the acceleration's gives 3.2e-5.
        for r in &ratio {
            assert!((r - 1.0).abs() < 0.22, "{ratio:?}");
        }
    }

    /// The record of moves `motion(t)` = (x, v, a, direction of the last move, moving) sampled
    /// at `fs` for `n` samples, position quantised to 1 µm, exact v and a; the force the
    /// device's at t − τ: M·a + Fv·v + Fc·sign(v) while it slides, while it rests a static
    /// friction of 0.6·Fc in the direction of its last move; white noise 0.3 N.
    fn delayed_device_on(
        motion: impl Fn(f64) -> (f64, f64, f64, f64, bool),
        (fs, n): (f64, usize),
        m: f64,
        fv: f64,
        fc: f64,
        tau: f64,
    ) -> Record {
        let mut noise = unit_noise(0x2545_F491_4F6C_DD1D);
        let mut rec = Record::default();
        for i in 0..n {
            let t = i as f64 / fs;
            let (x, v, a, _, _) = motion(t);
            let (_, vd, ad, dir, moving) = motion(t - tau);
            let dev = if moving {
                m * ad + fv * vd + fc * vd.signum()
            } else {
                0.6 * fc * dir
            };
            rec.t.push(t);
            rec.x.push((x * 1e6).round() * 1e-6);
            rec.v.push(v);
            rec.a.push(a);
            rec.f.push(dev + 0.3 * noise());
        }
        rec
    }

    /// A point-to-point record in closed form: moves of ±`amp` over 0.5 s at constant
    /// acceleration then deceleration (a triangular speed, which passes through the Coulomb
    /// sign's ±0.2 % band within a sample), each followed by a 0.6 s dwell, position quantised
    /// to 1 µm, exact v and a; the force is the
    /// device's at t − τ, M·a + Fv·v + Fc·sign(v) while it slides and, while it rests, a static
    /// friction of 0.6·Fc in the direction of its last move (anywhere within its breakaway
    /// level: what a stopped device's bristles hold), white noise 0.3 N.
    fn delayed_moves(m: f64, fv: f64, fc: f64, tau: f64) -> Record {
        let (fs, n, amp, tm, td) = (1000.0, 12_000, 0.04, 0.5, 0.6);
        // position, velocity, acceleration and the direction of the last move at time t
        let motion = |t: f64| {
            let t = t.max(0.0);
            let k = (t / (tm + td)).floor();
            let dir = if k as i64 % 2 == 0 { 1.0 } else { -1.0 };
            let x0 = if k as i64 % 2 == 0 { 0.0 } else { amp };
            let s = ((t - k * (tm + td)) / tm).min(1.0);
            let (p, dp, ddp) = triangular_speed(s, tm);
            let moving = s < 1.0 && s > 0.0;
            (
                x0 + dir * amp * p,
                dir * amp * dp,
                dir * amp * ddp,
                dir,
                moving,
            )
        };
        delayed_device_on(motion, (fs, n), m, fv, fc, tau)
    }

    /// A force channel delayed by τ = 25 ms on point-to-point moves (`delayed_moves`): during
    /// the first τ of each move the force is still the dwell's static friction. The samples
    /// whose motion τ earlier is at rest (`Context::lag_rest_rows`) are left out of the lag's
    /// fits and of the baseline it is compared with, and `lag` is named alone with its delay
    /// and unit gain. With the rule removed (no row left out) the lag's gain on the held-out
    /// samples falls below the margin and nothing is named.
    #[test]
    fn lag_leaves_out_the_delayed_rest() {
        let (m, fv, fc, tau) = (40.0, 300.0, 20.0, 0.025);
        let rec = delayed_moves(m, fv, fc, tau);
        let ctx = effects::Context::new(&rec);
        let rows = ctx.lag_rest_rows(tau, None);
        let d = diagnose(&rec, &Options::default());
        let names = d.catalogue_names();
        let (lag, gain) = first_lag(&d);
        println!(
            "{} samples left out at τ; {names:?}: lag {lag} s ({:+.3} %), gain {gain}; held-out {:.3} % -> {:.3} %",
            rows.len(),
            100.0 * (lag / tau - 1.0),
            100.0 * d.baseline_holdout_rel_error,
            100.0 * d.final_holdout_rel_error
        );
        // measured: 275 samples (11 move starts, 25 each), lag +0.039 %, gain −0.52 %;
        // asserted: more than half of them, lag within 0.12 % and gain within 1.6 % (3× the
        // measured deviations)
        assert!(rows.len() > 5 * 25, "{}", rows.len());
        assert_eq!(names, ["lag"], "{:?}", d.verdicts);
        assert!((lag / tau - 1.0).abs() < 1.2e-3, "lag {lag}");
        assert!((gain - 1.0).abs() < 1.6e-2, "gain {gain}");
    }

    /// Point-to-point moves that settle as a servo does: each move a critically damped step
    /// of ±`amp`, x = x₀ ± amp·(1 − (1 + t/T)·e^(−t/T)) (normalised to reach amp at its end),
    /// T = 50 ms, stopped after 12·T and followed by a 0.6 s dwell; exact v and a, position
    /// quantised to 1 µm. The speed falls through the Coulomb sign's ±0.2 % band of the peak
    /// speed from t ≈ 9.5·T on (0.59 mm/s down to 0.06 mm/s over the move's last ≈ 120 ms,
    /// moving by more than the quantum over `at_rest`'s window): a sliding device's Coulomb
    /// force is Fc·sign(v) there as anywhere. The force is the device's at t − τ (the dwell's
    /// static friction 0.6·Fc while it rests), white noise 0.3 N.
    fn delayed_settling_moves(m: f64, fv: f64, fc: f64, tau: f64) -> Record {
        let (fs, n, amp, tt, td) = (1000.0, 12_000, 0.04, 0.05f64, 0.6);
        let tm = 12.0 * tt;
        let p_end = 1.0 - (1.0 + tm / tt) * (-tm / tt).exp();
        let motion = |t: f64| {
            let t = t.max(0.0);
            let k = (t / (tm + td)).floor();
            let dir = if k as i64 % 2 == 0 { 1.0 } else { -1.0 };
            let x0 = if k as i64 % 2 == 0 { 0.0 } else { amp };
            let s = t - k * (tm + td);
            let g = amp / p_end;
            if s >= tm {
                return (x0 + dir * amp, 0.0, 0.0, dir, false);
            }
            let e = (-s / tt).exp();
            (
                x0 + dir * g * (1.0 - (1.0 + s / tt) * e),
                dir * g * s / (tt * tt) * e,
                dir * g / (tt * tt) * (1.0 - s / tt) * e,
                dir,
                s > 0.0,
            )
        };
        delayed_device_on(motion, (fs, n), m, fv, fc, tau)
    }

    /// The delayed device's Coulomb sign is the exact sign of v(t − τ) (`effects::delayed_sign`):
    /// on moves whose slow ends lie inside the Coulomb sign's linear band
    /// (`delayed_settling_moves`, τ = 20 ms, Fc 80 N) the delayed device's coefficients
    /// (`lag_coefs` at the true τ) are the device's.
    #[test]
    fn lag_slides_with_the_exact_sign_at_slow_speed() {
        let (m, fv, fc, tau) = (40.0, 300.0, 80.0, 0.02);
        let rec = delayed_settling_moves(m, fv, fc, tau);
        let ctx = effects::Context::new(&rec);
        let th = ctx.lag_coefs(tau).expect("a device's coefficients");
        let dev = [th[0] / m - 1.0, th[1] / fv - 1.0, th[2] / fc - 1.0];
        let d = diagnose(&rec, &Options::default());
        let names = d.catalogue_names();
        let (lag, gain) = first_lag(&d);
        println!(
            "delayed baseline {th:?}: {dev:?}; {names:?}: lag {lag} s ({:+.3} %), gain {gain}; held-out {:.3} % -> {:.3} %",
            100.0 * (lag / tau - 1.0),
            100.0 * d.baseline_holdout_rel_error,
            100.0 * d.final_holdout_rel_error
        );
        // measured: −0.007 %, −0.006 %, +0.006 % (M, Fv, Fc); asserted 0.02 % (3× the
        // largest). With the banded sign delayed instead the Coulomb coefficient takes the
        // band's shortfall over the slow ends (the break below the docs' "Delay" states)
        assert!(dev.iter().all(|d| d.abs() < 2e-4), "{dev:?}");
        // the names are printed, not asserted: over these long slow ends (≈ 120 ms per move
        // inside the band) the baseline's banded sign falls short of the device's Coulomb
        // force, and with those samples left out of the lag's fits (`lag_rest_rows`) the
        // diagnosis names `presliding_hysteresis` for that shortfall
    }

    /// The same settling moves with no delay (`delayed_settling_moves`, τ = 0): the baseline's
    /// banded sign falls short of the sliding device's Coulomb force over the moves' slow ends,
    /// which the lag's column (the exact sign at t − τ, the banded one at t) would carry at
    /// any τ; the samples whose speed lies in the band are left out of the lag's fits
    /// (`Context::lag_rest_rows`), and no `lag` is named.
    #[test]
    fn lag_is_not_the_sign_band_of_an_undelayed_record() {
        let rec = delayed_settling_moves(40.0, 300.0, 80.0, 0.0);
        let d = diagnose(&rec, &Options::default());
        println!("{:?}: {:?}", d.catalogue_names(), d.verdicts);
        assert!(
            d.findings.iter().all(|f| f.effect != "lag"),
            "{:?}",
            d.verdicts
        );
    }

    /// The delayed baseline must be a device's: a force channel delayed on a device whose
    /// viscous coefficient is negative (an active drive pushing with the motion, −300 N·s/m)
    /// has no delayed device's coefficients at the true delay and is not named `lag` (with the
    /// rule removed, `lag_coefs` gives Fv = −300 and the test fails).
    #[test]
    fn lag_needs_a_physical_delayed_device() {
        let rec = delayed_record(40.0, -300.0, 20.0, 0.0125);
        let ctx = effects::Context::new(&rec);
        assert_eq!(ctx.lag_coefs(0.0125), None);
        let d = diagnose(&rec, &Options::default());
        assert!(
            d.findings.iter().all(|f| f.effect != "lag"),
            "{:?}",
            d.verdicts
        );
    }
}

#[cfg(test)]
mod actuator_lag_tests {
    use super::*;

    /// A record whose force channel is a command leading the force the motion needs by `tau`
    /// (negative: a force that lags), in closed form: x = A·sin ωt + A/3·sin 3.1ωt, the force
    /// M·a + Fv·v + Fc·sgn v evaluated at t + tau, plus a deterministic ±0.3 N noise.
    fn record(tau: f64) -> Record {
        let (m, fv, fc, amp, w) = (50.0, 100.0, 20.0, 0.05, std::f64::consts::TAU * 0.7);
        let force = |t: f64| {
            let v = amp * w * ((w * t).cos() + 3.1 / 3.0 * (3.1 * w * t).cos());
            let a = -amp * w * w * ((w * t).sin() + 3.1 * 3.1 / 3.0 * (3.1 * w * t).sin());
            m * a + fv * v + fc * v.signum()
        };
        let mut s = String::from("t_s,x_m,f_N\n");
        let mut seed = 12345u64;
        for i in 0..20_000 {
            let t = i as f64 * 1e-3;
            let x = amp * ((w * t).sin() + (3.1 * w * t).sin() / 3.0);
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let noise = 0.3 * (2.0 * (seed >> 11) as f64 / (1u64 << 53) as f64 - 1.0);
            s.push_str(&format!("{t},{x},{}\n", force(t + tau) + noise));
        }
        parse_csv(&s, None).unwrap()
    }

    fn delay(d: &Diagnosis) -> Option<f64> {
        d.findings
            .iter()
            .find(|f| f.effect == "actuator_lag")
            .map(|f| f.parameters[0].1)
    }

    /// A command 0.4 ms ahead of the force (EMPS: 0.38–0.40 ms) is named with its delay; a
    /// force 0.4 ms behind the motion (a lagging sensor) is not (the sign rule:
    /// `effects::plausible` keeps 0 < ω_c·τ ≤ 1).
    #[test]
    fn command_ahead_of_the_force_is_named_with_its_delay() {
        let tau = 4e-4;
        let rec = record(tau);
        let d = diagnose(&rec, &Options::default());
        let got = delay(&d).expect("actuator_lag named");
        // the record's channel, not the device: stated in the fragment's header, not a plant
        // effect (the fragment still loads)
        let frag = model::fragment_toml(&rec, &d);
        assert!(frag.contains("#   actuator_lag (delay_s = "), "{frag}");
        let m = model::device_model(&rec, &d).expect("the fragment is a device model");
        assert_eq!(m.effects.len(), d.effects.len() - 1, "{frag}");
        println!("delay {got:e} s for {tau:e} s");
        // measured 0.433 ms (8 % high: the derivative filter's smoothing and the baseline
        // fitted on the shifted force bias the first-order column); 10 % is the bound, a
        // half-sample error in the column (a backward difference) reads 0.198 ms
        assert!((got / tau - 1.0).abs() < 0.1, "{got}");
        let d = diagnose(&record(-tau), &Options::default());
        assert_eq!(delay(&d), None, "a lagging force named actuator_lag");
    }
}

#[cfg(test)]
mod stribeck_band_tests {
    use super::*;

    /// Point-to-point moves in closed form: eight moves of 0.76–92 mm over 0.55–1.0 s
    /// (triangular speed, peaks 1.65 mm/s … 0.30 m/s), each followed by a 0.6 s dwell; the two
    /// slow ones (peaks 1.65 and 6.0 mm/s) slide partly inside the Coulomb sign's linear band
    /// (±0.2 % of the peak speed, ±0.59 mm/s); position quantised to 0.4 µm, exact v and a.
    /// The force while it slides is M·a + Fv·v + Fc·sign(v) + offset plus a Stribeck bump
    /// `bump`·exp(−(v/v_s)²)·sign(v); at rest a static friction of 0.6·Fc in the direction of
    /// the last move; white noise 0.3 N.
    fn moves(bump: f64, vs: f64) -> Record {
        moves_with(bump, vs, 0.0)
    }

    /// `moves` with the Coulomb force built up along the path as a Dahl state over `xc`
    /// (`Fc·z`, z → sign(dx) + (z − sign(dx))·e^(−|dx|/xc) over each step of the unquantised
    /// position; `xc` = 0: Fc·sign(v)).
    fn moves_with(bump: f64, vs: f64, xc: f64) -> Record {
        let (m, fv, fc, off) = (50.0, 640.0, 40.0, 5.0);
        let (fs, n, td) = (1000.0, 12_000, 0.6);
        // (travel, duration) of the moves, each followed by a dwell of `td`
        let seq = [
            (0.018, 0.55),
            (0.012, 0.77),
            (-0.021, 1.0),
            (0.00076, 0.92),
            (-0.092, 0.62),
            (0.033, 0.84),
            (-0.054, 0.64),
            (0.0018, 0.6),
        ];
        let motion = |t: f64| {
            let mut tc = t;
            let mut x0 = 0.0;
            let mut dir = -1.0;
            for &(amp, tm) in &seq {
                let amp: f64 = amp;
                if tc < tm + td {
                    let s = (tc / tm).min(1.0);
                    let (p, dp, ddp) = super::tests::triangular_speed(s, tm);
                    let moving = s > 0.0 && s < 1.0;
                    return (x0 + amp * p, amp * dp, amp * ddp, amp.signum(), moving);
                }
                x0 += amp;
                dir = amp.signum();
                tc -= tm + td;
            }
            (x0, 0.0, 0.0, dir, false)
        };
        let mut noise = super::tests::unit_noise(0x5DEE_CE66_D1CE_4E5B);
        let mut rec = Record::default();
        let (mut z, mut x_prev) = (0.0f64, 0.0f64);
        for i in 0..n {
            let t = i as f64 / fs;
            let (x, v, a, dir, moving) = motion(t);
            let dx = x - x_prev;
            x_prev = x;
            if dx != 0.0 && xc > 0.0 {
                z = dx.signum() + (z - dx.signum()) * (-dx.abs() / xc).exp();
            }
            let dev = if moving {
                let sg = v.signum();
                let coulomb = if xc > 0.0 { z } else { sg };
                m * a + fv * v + fc * coulomb + bump * (-(v / vs).powi(2)).exp() * sg
            } else {
                0.6 * fc * dir
            };
            rec.t.push(t);
            rec.x.push((x * 2.5e6).round() / 2.5e6);
            rec.v.push(v);
            rec.a.push(a);
            rec.f.push(dev + off + 0.3 * noise());
        }
        rec
    }

    /// A Stribeck bump of 20 N over v_s = 5 mm/s on moves of which two slide inside the
    /// Coulomb sign's linear band is named (first): against the baseline with the exact sign
    /// it carries the margin. The same moves without the bump are named nothing. Break: the
    /// rule refusing every Stribeck (`if true || !carries_beyond(..)`) fails on the first
    /// record (measured: `presliding_hysteresis` named instead). The rule's own case, an
    /// effect-free record whose band deficit a Stribeck takes, is the rig's point-to-point
    /// record 33 (`diagnose_rig`'s `coulomb_band_is_not_stribeck`, which fails without the
    /// rule); this closed form does not draw a `stribeck` without the rule.
    #[test]
    fn stribeck_beside_the_sign_band_is_named() {
        let d = diagnose(&moves(20.0, 5e-3), &Options::default());
        println!("bump: {:?}", d.catalogue_names());
        assert_eq!(
            d.catalogue_names().first().copied(),
            Some("stribeck"),
            "{:?}",
            d.verdicts
        );
        let d = diagnose(&moves(0.0, 5e-3), &Options::default());
        println!(
            "no bump: {:?}, held-out {:.2} % -> {:.2} %",
            d.catalogue_names(),
            100.0 * d.baseline_holdout_rel_error,
            100.0 * d.final_holdout_rel_error
        );
        assert!(d.catalogue_names().is_empty(), "{:?}", d.verdicts);
    }
    /// A presliding build-up (the Coulomb force as a Dahl state over x_c = 0.4 mm, no Stribeck
    /// bump) on the same moves, two of which slide inside the Coulomb sign's linear band, is
    /// named `presliding_hysteresis` alone with its displacement: the band rule asks it to
    /// carry the margin against the baseline with the exact sign, which a build-up over
    /// 0.4 mm does. Measured x_c 4.0008e-4 m (+0.02 %); bound 0.06 %, three times that (the
    /// refinement's step is 1 %, so a value off the grid's optimum fails it). The rule's own
    /// case, an effect-free record whose band deficit a µm Dahl state takes, is the rig's
    /// point-to-point record 38 (`diagnose_rig`'s `coulomb_band_is_not_presliding`, which fails
    /// without the rule).
    #[test]
    fn presliding_beside_the_sign_band_is_named() {
        let d = diagnose(&moves_with(0.0, 5e-3, 4e-4), &Options::default());
        let xc = d
            .findings
            .first()
            .and_then(|f| f.parameters.first())
            .map_or(f64::NAN, |p| p.1);
        println!("presliding: {:?}, x_c {xc:.5e} m", d.catalogue_names());
        assert_eq!(
            d.catalogue_names(),
            vec!["presliding_hysteresis"],
            "{:?}",
            d.verdicts
        );
        assert!((xc / 4e-4 - 1.0).abs() < 6e-4, "x_c {xc:e}");
    }
}
