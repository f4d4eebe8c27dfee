//! Least squares on the record: normal equations over the training and held-out samples, their solution, the errors-in-variables and lag corrections, the relative error and the BIC.

use super::*;

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
pub(crate) const CORRECTED_RANK: f64 = 1e200;

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
pub(crate) fn normals_k<const M: usize>(
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
pub(crate) fn normals_any(
    cols: &[&[f64]],
    f: &[f64],
    part: &[u8],
    stride: usize,
) -> (Normal, Normal) {
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
pub(crate) fn dot2(a: &[f64], b: &[f64], w: &HoldWeights) -> (f64, f64) {
    dot2_k(a, [b], w)[0]
}

/// `dot2` of `a` with each of `K` columns of one length in one pass over `a` (its loads shared,
/// 4·K independent chains): each column's partial sums take the same products in the same
/// order as `dot2` alone, so each result is `dot2`'s bit for bit.
#[inline(always)]
pub(crate) fn dot2_k<const K: usize>(
    a: &[f64],
    bs: [&[f64]; K],
    w: &HoldWeights,
) -> [(f64, f64); K] {
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
pub(crate) fn dot2_many(a: &[f64], bs: &[&[f64]], w: &HoldWeights) -> Vec<TrainHold> {
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
pub(crate) fn embed(src: &Normal, p: usize, m: usize) -> Normal {
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
pub(crate) type TrainHold = (f64, f64);

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
