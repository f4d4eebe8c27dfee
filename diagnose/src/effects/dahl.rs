//! Rate-independent friction hysteresis (`presliding_hysteresis`): the Dahl walk over the record.

/// Dahl friction state (−1 … 1) along the path `x` with characteristic displacement `xc`:
/// z → sgn(dx) + (z − sgn(dx))·exp(−|dx|/xc) over each step (exact for the model).
pub fn dahl(x: &[f64], xc: f64) -> Vec<f64> {
    let mut out = Vec::with_capacity(x.len());
    dahl_walk(x, &[xc], x.len(), |_, z| out.push(z[0]));
    out
}

/// The Dahl state of `dahl` at the given ascending sample indices only (the path is walked up
/// to the last of them; no full-length array).
pub fn dahl_at(x: &[f64], xc: f64, rows: &[usize]) -> Vec<f64> {
    dahl_batch_at(x, &[xc], rows).swap_remove(0)
}

/// `dahl_at` for several characteristic displacements in one pass over the path.
pub fn dahl_batch_at(x: &[f64], xcs: &[f64], rows: &[usize]) -> Vec<Vec<f64>> {
    let mut out = vec![Vec::with_capacity(rows.len()); xcs.len()];
    let mut k = 0;
    let end = rows.last().map_or(0, |r| r + 1).min(x.len());
    dahl_walk(x, xcs, end, |i, z| {
        while k < rows.len() && rows[k] == i {
            for (o, &zi) in out.iter_mut().zip(z) {
                o.push(zi);
            }
            k += 1;
        }
    });
    out
}

/// Step sizes whose decay factor `dahl_walk` keeps per characteristic displacement.
pub(crate) const DAHL_SLOTS: usize = 16;

/// Walk the Dahl states of the characteristic displacements `xcs` over the first `end`
/// samples of `x`, calling `emit(i, z)` per sample with each one's state.
/// Once a state has converged to the direction of motion it equals ±1 exactly (the remaining
/// deviation rounds away below half an ulp of 1) and stays there while the direction holds, so
/// the exponential is evaluated only in the transitions after reversals.
pub(crate) fn dahl_walk(x: &[f64], xcs: &[f64], end: usize, mut emit: impl FnMut(usize, &[f64])) {
    let m = xcs.len();
    let mut z = vec![0.0f64; m];
    let mut prev = x.first().copied().unwrap_or(0.0);
    let ixc: Vec<f64> = xcs.iter().map(|xc| 1.0 / xc.max(1e-300)).collect();
    // a quantised position repeats its step sizes: the decay factors of the step sizes seen
    // are kept (direct-mapped on the step's leading bits, DAHL_SLOTS per value) and reused
    // when a step repeats (the same value, so the result is identical)
    let mut memo = vec![(f64::NAN, 0.0); m * DAHL_SLOTS];
    // states equal to the direction of the last step, all of them: nothing to update while
    // the direction holds
    let mut settled = false;
    let mut dir = 0.0;
    for (i, &xi) in x[..end].iter().enumerate() {
        let dx = xi - prev;
        prev = xi;
        if dx != 0.0 {
            let s = dx.signum();
            if !(settled && s == dir) {
                let adx = dx.abs();
                let b = adx.to_bits();
                let slot = ((b >> 48) ^ (b >> 52)) as usize % DAHL_SLOTS;
                settled = true;
                for k in 0..m {
                    if z[k] != s {
                        let e = &mut memo[k * DAHL_SLOTS + slot];
                        if adx != e.0 {
                            *e = (adx, (-adx * ixc[k]).exp());
                        }
                        z[k] = s + (z[k] - s) * e.1;
                        settled &= z[k] == s;
                    }
                }
                dir = s;
            }
        }
        emit(i, &z);
    }
}
