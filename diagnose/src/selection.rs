//! The selection: screen every candidate of the effect library on the record's screening window, add, swap and remove effects by their held-out gain and BIC, then fit the findings on the whole record and validate them.

use super::*;

/// Rounds of the swap and backward pass after forward selection (each round tries every
/// finding's removal and replacement, then resumes forward selection).
pub const SWAP_ROUNDS: usize = 4;
/// Nuisance columns of a slow change of the force offset over the record (not a catalogue
/// effect: reported as `unexplained`).
pub const DRIFT_COLUMNS: [&str; 2] = ["drift.t_legendre1", "drift.t_legendre2"];
/// Nuisance columns of a force of the speed outside the catalogue: the odd powers beyond the
/// baseline's (sgn v and v, degrees 0 and 1 of |v| with the sign), sgn v·(|v|/v_max)^k for k =
/// 2, 3 (reported as `unexplained`).
pub const SPEED_COLUMNS: [&str; 2] = ["speed.sgn_v_u2", "speed.sgn_v_u3"];
/// The powers of |v|/v_max of `SPEED_COLUMNS`, in their order.
pub(crate) const SPEED_POWERS: [i32; 2] = [2, 3];

/// The columns `SPEED_COLUMNS` at `rows` (every sample when None; `sgn` the baseline's sign,
/// `vmax` the peak speed).
pub(crate) fn speed_columns(
    ctx: &effects::Context,
    rows: Option<&[usize]>,
) -> Vec<(String, Vec<f64>)> {
    let iv = 1.0 / ctx.vmax.max(1e-300);
    let (v, sgn) = (&ctx.rec.v, &ctx.sgn);
    SPEED_POWERS
        .into_iter()
        .zip(SPEED_COLUMNS)
        .map(|(k, name)| {
            let at = |i: usize| sgn[i] * (v[i].abs() * iv).powi(k);
            let c = match rows {
                Some(r) => r.iter().map(|&i| at(i)).collect(),
                None => (0..v.len()).map(at).collect(),
            };
            (name.to_string(), c)
        })
        .collect()
}

/// One run of the selection on `rec` (`runs`); with `again.speed` a force of the speed outside
/// the catalogue is carried by nuisance columns from the start and the candidates are the
/// kinds it lists; the kinds `again.without` lists are not candidates. `Err` with what the
/// next run is given when, without them, the selection's findings leave that force, or when
/// its validation rejects findings and a run without them is still allowed (the caller runs
/// it again).
pub(crate) fn diagnose_with(
    rec: &Record,
    opt: &Options,
    rest: Vec<bool>,
    mut again: Again,
) -> Result<Diagnosis, Again> {
    let speed = again.speed.as_deref();
    let speed_force = speed.is_some();
    let n = rec.len();
    let ctx = effects::Context::split_at_rest(rec, opt.screen_window.min(n), rest, again.split);
    let mut hold = holdout_mask(n, ctx.split);
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
        holdout_mask(w, ctx.split)
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
    // A set holding a delay τ of the force (`EffectModel::force_delay`) makes the force the device's at t − τ: its fits leave out the
    // samples whose delayed motion is at rest (`Context::lag_rest_rows`), and so does every fit
    // it is compared with (the same rows on both sides of a comparison).
    let lag_of = delay_of;
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
    let spread_base: Vec<Vec<f64>> = cols.iter().map(|(_, v)| gather(&spread_rows, v)).collect();
    let spread = Spread {
        rows: &spread_rows,
        f: &spread_f,
        hold: &spread_hold,
    };
    let baseline_terms = baseline_terms(
        &cols,
        &spread_base,
        &spread,
        &th,
        baseline_holdout,
        opt.min_holdout_gain,
    );
    // Baseline terms the record cannot tell apart: columns whose centred correlation over
    // the samples in motion reaches CONFOUNDED_R (the coefficients' standard errors then grow
    // by 1/√(1 − r²) ≥ 7× over independent columns: only their combination is identified).
    let confounded = confounded_terms(&cols[..n_base], &spread_base, &spread_hold);
    let drift = match drift_test(&ctx, &cols, &th, &full, &full_w, opt.min_holdout_gain) {
        Some((drift, z, extended)) => {
            full = extended;
            sub_cols.extend(z.iter().map(|(_, v)| gather(&sub.rows, v)));
            cols.extend(z);
            Some(drift)
        }
        None => None,
    };
    // A force of the speed outside the catalogue, carried as the drift is when the first
    // selection's findings left it (the test before the confounded check).
    let speed_sub: Vec<Vec<f64>> = speed_columns(&ctx, Some(&sub.rows))
        .into_iter()
        .map(|(_, v)| v)
        .collect();
    if speed_force {
        let speed_cols = speed_columns(&ctx, None);
        let zr = refs(&speed_cols);
        full = extend_normals_dense(&full, &refs(&cols), &zr, &rec.f, &full_w);
        sub_cols.extend(speed_sub.iter().cloned());
        cols.extend(speed_cols);
    }
    // The screening columns of every candidate value are the same in every round: computed
    // once (on the subsample, at most `screen_samples` rows each) and kept.
    type Cache = ScreenColumns;
    let mut cache = Cache::new();
    // and their Gram entries against the base columns, extended as the base grows
    let grams =
        std::cell::RefCell::new(std::collections::HashMap::<(usize, u64), GramCache>::new());
    let whole_fit = whole_fit;
    let mut catalogue = effects::catalogue(&ctx);
    if let Some(kinds) = speed {
        catalogue.retain(|c| kinds.contains(&c.kind));
    }
    catalogue.retain(|c| !again.without.contains(&c.kind));
    // each kind's coarse grid, a function of the record alone: built once, at its first scan
    let coarse_grids: Vec<std::cell::OnceCell<Vec<Effect>>> = catalogue
        .iter()
        .map(|_| std::cell::OnceCell::new())
        .collect();
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
    // delay τ when given
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
            ids.extend((0..k as u64).map(|j| (((e.kind.index() as u64) << 32) | j, e.key().1)));
        }
        ids
    };
    // parameters a set of effects adds (its columns and each scanned parameter)
    let set_k = |set: &[Effect], cache: &mut Cache| -> usize {
        set_cols(set, cache).len() + set.iter().filter(|e| e.kind.scanned()).count()
    };
    // a candidate is added when it cuts the held-out rss by the margin and lowers the BIC
    let passes = |rh: f64, rss_h0: f64, dbic: f64| {
        1.0 - rh / rss_h0.max(1e-300) >= opt.min_holdout_gain && dbic < 0.0
    };
    // a fit of held-out rss `rh` falls short of that margin over one of `r0`
    let short_of_margin = |rh: f64, r0: f64| 1.0 - rh / r0.max(1e-300) < opt.min_holdout_gain;
    // The best candidate to add to a set (every kind not in it, every grid value, refined):
    // (held-out rss of the set, and of the best candidate with its training BIC change).
    // (and the best value of each kind: its held-out rss, BIC change and value)
    let scan = |set: &[Effect], cache: &mut Cache| -> (f64, Option<Scanned>, Vec<Scanned>) {
        let base_cols = set_cols(set, cache);
        let base_refs: Vec<&[f64]> = base_cols.iter().map(|v| v.as_slice()).collect();
        let base_ids = set_ids(set, cache);
        let base = normals(&base_refs, &sub_f, &sub_hold, 1);
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
        // the rows the longest delay scanned leaves out (the delays are ranked on common rows)
        let lag_common = lag_rest_sub(effects::lag_max(ctx.dt));
        // the set's column that carries the derived signals' noise (one effect of one column),
        // with that noise's covariance: every candidate beside it is judged on fits corrected
        // for it, as a noisy candidate is on its own
        let set_noise: Option<(usize, [[f64; 3]; 3])> = {
            let noisy: Vec<_> = set
                .iter()
                .zip(&set_spans)
                .filter_map(|(e, &(a, b))| e.kind.derived_noise(&ctx, e).map(|(_, sn)| (a, b, sn)))
                .collect();
            match noisy.as_slice() {
                [(a, b, sn)] if b - a == 1 => Some((*a, *sn)),
                _ => None,
            }
        };
        let mut best: Option<(f64, f64, Effect)> = None;
        let mut of_kind: Vec<(f64, f64, Effect)> = Vec::new();
        for (cand, coarse) in catalogue.iter().zip(&coarse_grids) {
            if set.iter().any(|c| c.kind == cand.kind) {
                continue;
            }
            let eval = |eff: &Effect, cache: &mut Cache| -> (f64, f64, f64) {
                let z = cache
                    .entry(eff.key())
                    .or_insert_with(|| effects::columns_on(&ctx, &sig, eff));
                let zr: Vec<&[f64]> = z.iter().map(|(_, v)| v.as_slice()).collect();
                let mut grams = grams.borrow_mut();
                let gc = grams.entry(eff.key()).or_default();
                let mut nn =
                    extend_normals_cached(&base, &base_refs, &base_ids, &zr, &sub_f, &sub_w, gc);
                let nb = base_refs.len();
                // the rows of the set's delay, or of the candidate delay: the set is compared with
                // it on the candidate's rows and its gain there carried to the set's rows
                let (mut scale, mut t0) = (1.0, rss_t0);
                let rows_c = match (tau_s, eff.kind.force_delay(eff)) {
                    (Some(_), _) => rows_s.clone(),
                    (None, Some(tau)) => lag_rest_sub(tau),
                    _ => Vec::new(),
                };
                let lag_cand = tau_s.is_none() && eff.kind.force_delay(eff).is_some();
                let all: Vec<&[f64]> = if rows_c.is_empty() && !lag_cand {
                    Vec::new()
                } else {
                    base_refs.iter().chain(&zr).copied().collect()
                };
                // the normals of the fit without the candidate (the set's columns, the first `nb`)
                let base_of = |nn: &(Normal, Normal)| {
                    let idx: Vec<usize> = (0..nb).collect();
                    (nn.0.select(&idx), nn.1.select(&idx))
                };
                // the held-out rss of the fit with the candidate over the baseline's on the
                // same rows, carried to the set's rows
                let ratio = |nn: &(Normal, Normal)| {
                    let (bt, bh) = base_of(nn);
                    let th0 = bt.solve();
                    (rss_h0 / bh.rss(&th0).max(1e-300), bt.rss(&th0))
                };
                if !rows_c.is_empty() {
                    nn = change_rows(&nn, &all, &sub_f, &sub_hold, &rows_c, -1.0);
                    if tau_s.is_none() {
                        (scale, t0) = ratio(&nn);
                    }
                }
                // the delays τ are ranked against each other on the same rows: those every τ
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
                // a delay: its gain's range and its τ are judged on the fit corrected for the
                // derived signals' noise (`lag_corrected`); the held-out rss it is compared
                // with the other candidates by is the least-squares fit's, as theirs
                let mut key = None;
                let mut tc = None;
                // a delay whose least-squares gain is a unit one ranks by its held-out rss, as
                // every candidate; one whose gain only the correction brings into the range
                // ranks after all of those, by the corrected gain's distance from 1
                // (`NoiseUse::RankCorrected`).
                // Every column that carries the derived signals' noise is not resolved where
                // it is more than half that noise on the training rows (`lag_corrected`): its
                // fit would low-pass the baseline's noisy columns, not draw the effect. One
                // resolved must carry the margin on error-free columns: the fits with and
                // without it corrected for that noise (`eiv_fit`, the covariance of the
                // inertia's, the viscous and its column), the held-out rss of each less the
                // noise's share. Least squares credits a column built from the derived
                // signals with the noise it cancels in theirs (a delayed or filtered copy of a
                // noisy acceleration averages its noise), on the held-out rows as on the
                // training rows; the corrected fit does not.
                let noise = eff.kind.derived_noise(&ctx, eff);
                if let Some((use_, sn)) = noise {
                    let Some((c, r1)) = lag_corrected(&nn.0, &nn.1, [0, 1, nb], &sn) else {
                        return (f64::INFINITY, 0.0, f64::INFINITY);
                    };
                    let (bt, bh) = base_of(&nn);
                    // (a fit not determined carries no margin)
                    let Some((_, r0)) = eiv_fit(&bt, &bh, &[0, 1], &sn) else {
                        return (f64::INFINITY, 0.0, f64::INFINITY);
                    };
                    if short_of_margin(r1, r0) {
                        return (f64::INFINITY, 0.0, f64::INFINITY);
                    }
                    if use_ == effects::NoiseUse::RankCorrected
                        && !effects::plausible(eff, &t[nb..], &t[..nb.min(4)])
                    {
                        key = Some(CORRECTED_RANK * (1.0 + (c[nb] - 1.0).abs()));
                        tc = Some(c);
                    }
                }
                // A candidate beside a set whose column carries that noise is judged by the same
                // rule: it must carry the margin on the fits with and without it corrected for
                // the set's noise. Least squares biases the noisy column's coefficient (a
                // delay's gain low) and leaves a part of the force it carries in the residual
                // (a Coulomb switch τ long after each reversal), which a candidate of another
                // kind would take; the corrected fit leaves it with the noisy column.
                else if let Some((j, sn)) = set_noise {
                    let (bt, bh) = base_of(&nn);
                    let (Some((_, r1)), Some((_, r0))) = (
                        eiv_fit(&nn.0, &nn.1, &[0, 1, j], &sn),
                        eiv_fit(&bt, &bh, &[0, 1, j], &sn),
                    ) else {
                        return (f64::INFINITY, 0.0, f64::INFINITY);
                    };
                    if short_of_margin(r1, r0) {
                        return (f64::INFINITY, 0.0, f64::INFINITY);
                    }
                }
                let tp = tc.as_deref().unwrap_or(&t);
                if !effects::plausible(eff, &tp[nb..], &tp[..nb.min(4)])
                    || !eff.kind.consistent_with_force(
                        &ctx,
                        eff,
                        &t[nb..],
                        &t[..nb.min(4)],
                        &sub.bp,
                        &sub.v,
                        &sub_f,
                        ctx.base_resid_rms,
                    )
                {
                    return (f64::INFINITY, 0.0, f64::INFINITY);
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
                if !cand.kind.walks_history() {
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
            let coarse = coarse.get_or_init(|| effects::grid(&ctx, cand));
            // the scanned range: an optimum on its edge is not bracketed (the profile of the
            // fit over the parameter still falls beyond the range the record resolves), so the
            // parameter is not identified and the effect is not named
            // the values `effs` evaluated (their columns filled in one pass) and the best so
            // far kept, ranked by each value's key: its held-out rss, for a delay the corrected
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
            scan(coarse, cache, &mut cb, &mut cb_key);
            if cand.kind.scanned() {
                // a resonance's residual is sharp in frequency: one more level for it
                for &width in cand.kind.refine_widths() {
                    let Some(centre) = cb.as_ref().map(|c| c.2.clone()) else {
                        break;
                    };
                    let fine = effects::refine(&ctx, &centre, width);
                    scan(&fine, cache, &mut cb, &mut cb_key);
                }
            }
            // a second parameter at the best first one, ranked by the held-out key as the
            // first is (`EffectModel::variants`), bisected towards its optimum
            // (`EffectModel::variant_fine`); a further one when that value itself passes
            // the selection, one parameter more, so it must cut the held-out rss by the
            // selection's margin, as an added effect must (`EffectModel::extended_variants`);
            // then the first refined once more at the variant chosen
            if let Some(centre) = cb.as_ref().map(|c| c.2.clone()) {
                let alt = cand.kind.variants(&ctx, &centre);
                scan(&alt, cache, &mut cb, &mut cb_key);
                for level in 0.. {
                    let Some(centre) = cb.as_ref().map(|c| c.2.clone()) else {
                        break;
                    };
                    let fine = cand.kind.variant_fine(&centre, level);
                    if fine.is_empty() {
                        break;
                    }
                    scan(&fine, cache, &mut cb, &mut cb_key);
                }
            }
            let best_passes = cb.as_ref().is_some_and(|c| passes(c.0, rss_h0, c.1));
            if let Some(centre) = cb.as_ref().map(|c| c.2.clone()) {
                let alt = cand.kind.extended_variants(&ctx, &centre);
                if best_passes && !alt.is_empty() {
                    let (mut sb, mut sb_key) = (None, f64::INFINITY);
                    scan(&alt, cache, &mut sb, &mut sb_key);
                    if sb_key <= (1.0 - opt.min_holdout_gain) * cb_key {
                        (cb, cb_key) = (sb, sb_key);
                    }
                }
            }
            if let Some(centre) = cb.as_ref().map(|c| c.2.clone()) {
                if let Some(width) = cand.kind.variant_refine(&centre) {
                    let fine = effects::refine(&ctx, &centre, width);
                    scan(&fine, cache, &mut cb, &mut cb_key);
                }
            }
            if cand.kind.scanned()
                && cb.as_ref().is_some_and(|c| {
                    let (p_lo, p_hi) = effects::scan_range(coarse, &c.2);
                    coarse_len_gt1(p_lo, p_hi) && !effects::interior(c.2.param, p_lo, p_hi)
                })
            {
                cb = None;
            }
            if let Some(c) = cb {
                if c.0.is_finite() {
                    if passes(c.0, rss_h0, c.1) && best.as_ref().is_none_or(|b| c.0 < b.0) {
                        best = Some(c.clone());
                    }
                    of_kind.push(c);
                }
            }
        }
        (rss_h0, best, of_kind)
    };
    let forward = |chosen: &mut Vec<Effect>, cache: &mut Cache| -> bool {
        let mut added = false;
        while chosen.len() < opt.max_effects {
            match scan(chosen, cache) {
                (h0, Some((rh, db, eff)), _) if passes(rh, h0, db) => {
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
    // Finding `k` against the set without it: the set's held-out rss (a delay's gain on its
    // own rows carried to the others' rows, as `scan` does), and the scan of the others (its
    // held-out rss, its best candidate, the best of each kind).
    let without = |chosen: &[Effect], k: usize, cache: &mut Cache| {
        let (ntr, nho) = set_normals(chosen, cache);
        let mut cur = nho.rss(&ntr.solve());
        let others: Vec<Effect> = chosen
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != k)
            .map(|(_, e)| e.clone())
            .collect();
        let (h0, best, of_kind) = scan(&others, cache);
        if chosen[k].kind.force_delay(&chosen[k]).is_some() {
            let (otr, oho) = set_normals_on(&others, lag_of(chosen), cache);
            cur *= h0 / oho.rss(&otr.solve()).max(1e-300);
        }
        (cur, h0, best, of_kind)
    };
    for _ in 0..SWAP_ROUNDS {
        let mut changed = false;
        let mut k = 0;
        while k < chosen.len() {
            let (cur, h0, best, _) = without(&chosen, k, &mut cache);
            match best {
                Some((rh, db, eff))
                    if rh < cur * (1.0 - 1e-9) && passes(rh, h0, db) && eff != chosen[k] =>
                {
                    chosen[k] = eff;
                    changed = true;
                }
                _ if short_of_margin(cur, h0) => {
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
        if let Some(simpler) = chosen[k].kind.simpler(&chosen[k]) {
            let mut rigid = chosen.clone();
            rigid[k] = simpler;
            if whole_holdout(&rigid) <= whole_holdout(&chosen) {
                chosen = rigid;
            }
        }
    }
    // A force of the speed outside the catalogue (a drag growing faster than the speed, a
    // friction curve of another shape) set against the findings by the selection's own rule,
    // on the screening window's held-out blocks and the rows of the set's delay: the smooth odd
    // powers of the speed beyond the baseline's (`SPEED_COLUMNS`: two free parameters, as many
    // as a finding of one column and one scanned parameter). Where they cut the findings'
    // held-out rss by the margin with a BIC decrease, the findings leave a force of the speed
    // unexplained, and what they were chosen on held it: the selection runs again with those
    // columns carried as nuisance columns (as a drift is), among the kinds chosen here, so
    // that each finding is kept only where it carries the margin beside that force. Only
    // where the selection ended by itself: a set cut at `max_effects` leaves what a further
    // finding would take.
    if !speed_force && chosen.len() < opt.max_effects {
        let tau = lag_of(&chosen);
        let k0 = set_k(&chosen, &mut cache);
        let mut c = set_cols(&chosen, &mut cache);
        let fit = |c: &[Vec<f64>]| {
            let r: Vec<&[f64]> = c.iter().map(|v| v.as_slice()).collect();
            let nn = normals(&r, &sub_f, &sub_hold, 1);
            let nn = match tau {
                Some(t) => change_rows(&nn, &r, &sub_f, &sub_hold, &lag_rest_sub(t), -1.0),
                None => nn,
            };
            let th = nn.0.solve();
            (nn.1.rss(&th), nn.0.rss(&th), nn.0.n)
        };
        let (h0, t0, n0) = fit(&c);
        c.extend(speed_sub.iter().cloned());
        let (h1, t1, n1) = fit(&c);
        let dbic = bic(t1, n1, k0 + SPEED_COLUMNS.len()) - bic(t0, n0, k0);
        if passes(h1, h0, dbic) {
            return Err(Again {
                speed: Some(chosen.iter().map(|e| e.kind).collect()),
                ..again
            });
        }
    }
    // Two candidates that explain the same residual, one rule for every pair: each finding is
    // set against the best candidate of another kind scanned without it (the swap pass's
    // scan). Where that candidate passes the selection itself and the finding's held-out rss
    // does not beat it by the selection's margin, the held-out data do not tell the two apart:
    // the finding is kept in the model and reported as confounded with it, not named.
    let mut confounded_with: Vec<Option<&'static str>> = vec![None; chosen.len()];
    for k in 0..chosen.len() {
        let (cur, h0, _, of_kind) = without(&chosen, k, &mut cache);
        let rival = of_kind
            .iter()
            .filter(|(rh, db, e)| e.kind != chosen[k].kind && passes(*rh, h0, *db))
            .min_by(|a, b| a.0.total_cmp(&b.0));
        if let Some((rh, _, e)) = rival {
            if short_of_margin(cur, *rh) {
                confounded_with[k] = Some(e.kind.name());
            }
        }
    }
    // The findings in their order: each one's held-out gain and BIC change on the subsample
    // with the findings before it, then added to the whole record's normal equations.
    let mut ho_rel = baseline_holdout;
    let mut findings = Vec::new();
    let mut stage_models = vec![whole_fit(&full, &cols)];
    // the whole record's samples left out with a delay (once it is in the model)
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
        if let Some(tau) = eff.kind.force_delay(&eff) {
            lag_rows_full = ctx.lag_rest_rows(tau, None);
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
            confounded_with: confounded_with[i].map(str::to_string),
        });
        ho_rel = after;
    }
    // Stability: each finding is tested on STABILITY_SEGMENTS independent consecutive
    // segments of the spread subsample (the whole record; each held out in turn, the model
    // fitted on the others): it holds on a segment when removing it raises that segment's rss
    // by the selection margin (`STABILITY_GAIN_SHARE` of it) and its fit there is physical; it
    // is kept when it holds on STABILITY_MIN segments and its leading coefficient keeps its
    // sign on all of them. Its columns are the whole-record columns (`cols`) at those rows.
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
    let before: Vec<EffectKind> = chosen.iter().map(|e| e.kind).collect();
    let selected = Selected {
        chosen,
        findings,
        cols,
        full,
        stage_models,
        lag_rows_full,
        ho_rel,
    };
    let (selected, dropped_notes) = validate(
        &ctx,
        opt,
        selected,
        &spans,
        n_fixed,
        n_base,
        &spread,
        baseline_holdout,
    );
    let rejected: Vec<EffectKind> = before
        .iter()
        .copied()
        .filter(|k| !selected.chosen.iter().any(|e| e.kind == *k))
        .collect();
    if let Some(d) = again.earlier_standing(&before, &rejected) {
        return Ok(d);
    }
    let rerun = !rejected.is_empty() && again.rounds_left > 0;
    let mut notes = std::mem::take(&mut again.notes);
    notes.extend(dropped_notes);
    if rerun {
        notes.push(rerun_note(&rejected));
    }
    let d = conclude(
        &ctx,
        opt,
        selected,
        Baseline {
            terms: baseline_terms,
            confounded,
            holdout: baseline_holdout,
            train: baseline_train,
            full: base_full,
        },
        drift,
        speed_force,
        notes.clone(),
    );
    if rerun {
        again.without.extend(rejected);
        return Err(Again {
            speed: None,
            notes,
            rounds_left: again.rounds_left - 1,
            earlier: Some(Box::new(d)),
            ..again
        });
    }
    Ok(d)
}

/// The force less the model `cols` with coefficients `th`, 0 at rest.
pub(crate) fn resid_of(
    ctx: &effects::Context,
    cols: &[(String, Vec<f64>)],
    th: &[f64],
) -> Vec<f64> {
    let p = effects::predict(cols, th);
    ctx.rec
        .f
        .iter()
        .zip(&p)
        .zip(&ctx.rest)
        .map(|((a, b), &r)| if r { 0.0 } else { a - b })
        .collect()
}

/// The model `cols` fitted on the whole record (training and held-out normals together).
pub(crate) fn whole_fit(
    full: &(Normal, Normal),
    cols: &[(String, Vec<f64>)],
) -> Vec<(String, f64)> {
    let t = full.0.plus(&full.1).solve();
    cols.iter().map(|c| c.0.clone()).zip(t).collect()
}

/// A candidate as the scan ranks it: its held-out rss, its training BIC change and its value.
pub(crate) type Scanned = (f64, f64, Effect);

/// The delay of the force a set of effects holds (`EffectModel::force_delay`).
pub(crate) fn delay_of(set: &[Effect]) -> Option<f64> {
    set.iter().find_map(|e| e.kind.force_delay(e))
}

/// The screening columns of each candidate value, keyed by its kind and parameter's bits.
pub(crate) type ScreenColumns = std::collections::HashMap<(usize, u64), Vec<(String, Vec<f64>)>>;

/// The column span of each effect of `set` in a design whose first `n_fixed` columns are the
/// fixed terms, followed by each effect's columns in the set's order (`cache` holds them).
pub(crate) fn effect_spans(
    set: &[Effect],
    n_fixed: usize,
    cache: &ScreenColumns,
) -> Vec<(usize, usize)> {
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
/// of it (an efficiency beside a drive's clip can take part of the viscous force and leave the
/// clip's damping above the viscous coefficient).
pub fn set_physical(set: &[Effect], spans: &[(usize, usize)], th: &[f64]) -> bool {
    set.iter().zip(spans).all(|(e, &(a, b))| {
        b <= th.len() && effects::plausible(e, &th[a..b], &th[..4.min(th.len())])
    })
}

/// True when a scanned range has more than one value (an edge can be told from the interior).
pub(crate) fn coarse_len_gt1(lo: f64, hi: f64) -> bool {
    hi > lo
}

pub(crate) fn refs(c: &[(String, Vec<f64>)]) -> Vec<&[f64]> {
    c.iter().map(|(_, v)| v.as_slice()).collect()
}

/// The centred correlation at which two baseline columns are not told apart (|r| ≥ 0.99).
pub const CONFOUNDED_R: f64 = 0.99;

/// Pairs of baseline terms (by their report names) whose columns `spread` (the terms `cols`
/// at the spread rows) correlate at |r| ≥ `CONFOUNDED_R` over the rows in motion, with r.
pub(crate) fn confounded_terms(
    cols: &[(String, Vec<f64>)],
    spread: &[Vec<f64>],
    hold: &[u8],
) -> Vec<(String, String, f64)> {
    let rows: Vec<usize> = (0..hold.len()).filter(|&i| hold[i] != AT_REST).collect();
    let centred: Vec<Vec<f64>> = spread
        .iter()
        .map(|c| {
            let m = rows.iter().map(|&i| c[i]).sum::<f64>() / rows.len().max(1) as f64;
            rows.iter().map(|&i| c[i] - m).collect()
        })
        .collect();
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let mut out = Vec::new();
    for i in 0..centred.len() {
        for j in i + 1..centred.len() {
            let (a, b) = (&centred[i], &centred[j]);
            let r = dot(a, b) / (dot(a, a) * dot(b, b)).sqrt();
            if r.abs() >= CONFOUNDED_R {
                out.push((
                    effects::baseline_term(&cols[i].0).0.to_string(),
                    effects::baseline_term(&cols[j].0).0.to_string(),
                    r,
                ));
            }
        }
    }
    out
}

#[cfg(test)]
#[path = "selection_tests.rs"]
mod speed_force_tests;

/// Baseline term significance: each of the baseline's terms (`cols`, their values `th` on the
/// whole record) dropped in turn and the rest refitted on the spread subsample (`spread_base`,
/// the terms at `spread`'s rows, with its force and held-out split); a term is significant when dropping it makes the
/// held-out rss grow by the same margin an extension must bring (`min_holdout_gain` over the
/// baseline's held-out error `baseline_holdout`).
fn baseline_terms(
    cols: &[(String, Vec<f64>)],
    spread_base: &[Vec<f64>],
    spread: &Spread,
    th: &[f64],
    baseline_holdout: f64,
    min_holdout_gain: f64,
) -> Vec<BaselineTerm> {
    (0..spread_base.len())
        .map(|drop| {
            let keep: Vec<&[f64]> = spread_base
                .iter()
                .enumerate()
                .filter(|(i, _)| *i != drop)
                .map(|(_, c)| c.as_slice())
                .collect();
            let (t2, h2) = normals(&keep, spread.f, spread.hold, 1);
            let th2 = t2.solve();
            let without = rel(h2.rss(&th2), h2.ff);
            let (name, unit) = effects::baseline_term(&cols[drop].0);
            BaselineTerm {
                effect: name.to_string(),
                value: th[drop],
                unit: unit.to_string(),
                holdout_rel_error_without: without,
                significant: without * without
                    > baseline_holdout * baseline_holdout / (1.0 - min_holdout_gain),
            }
        })
        .collect()
}

/// A slow change found by `drift_test`, its two nuisance columns and the whole record's
/// normals extended by them.
type Drift = (
    report::SlowChange,
    Vec<(String, Vec<f64>)>,
    (Normal, Normal),
);

/// A slow change of the residual's mean over the record (a drifting offset: temperature, a
/// load cell's zero) is outside the catalogue. Checked on the baseline residual (`cols` with
/// coefficients `th`; `full` its normals, `full_w` their held-out weights) before the search:
/// when it shows, it is reported as `unexplained` with where it shows and carried during the
/// search and in the final fit by two nuisance columns (the record's time as Legendre
/// polynomials of degree 1 and 2 on [−1, 1]), so that no catalogue effect takes it (a drift
/// correlates with whatever the motion does slowly: a position, a direction, a dwell) and the
/// effects are fitted on the rest. Returns the slow change found, those two columns and
/// `full` extended by them.
fn drift_test(
    ctx: &effects::Context,
    cols: &[(String, Vec<f64>)],
    th: &[f64],
    full: &(Normal, Normal),
    full_w: &HoldWeights,
    min_holdout_gain: f64,
) -> Option<Drift> {
    let rec = ctx.rec;
    let n = rec.len();
    let (t0, t1) = (rec.t[0], rec.t[n - 1]);
    let tn: Vec<f64> = rec
        .t
        .iter()
        .map(|t| 2.0 * (t - t0) / (t1 - t0).max(1e-300) - 1.0)
        .collect();
    let p2: Vec<f64> = tn.iter().map(|t| 1.5 * t * t - 0.5).collect();
    let z = vec![
        (DRIFT_COLUMNS[0].to_string(), tn),
        (DRIFT_COLUMNS[1].to_string(), p2),
    ];
    let zr: Vec<&[f64]> = z.iter().map(|(_, v)| v.as_slice()).collect();
    let extend = || extend_normals_dense(full, &refs(cols), &zr, &rec.f, full_w);
    // (the normals extended by the trend, when the joint fit below has built them)
    let mut extended = None;
    let drift = report::slow_change(
        &rec.t,
        &resid_of(ctx, cols, th),
        &ctx.rest,
        min_holdout_gain,
    )
    .or_else(|| {
        // the baseline's coefficients fitted beside the trend: a Coulomb term or an offset
        // that took part of a drift (a direction or a dwell that correlates with time: the
        // moves of a point-to-point record running one way early and the other way late)
        // does not hide it; the residual tested is the force minus the baseline's part of
        // that joint fit (the trend left in it), the test the same
        let normals = extended.insert(extend());
        let joint = normals.0.solve();
        report::slow_change(
            &rec.t,
            &resid_of(ctx, cols, &joint[..cols.len()]),
            &ctx.rest,
            min_holdout_gain,
        )
    })?;
    let extended = extended.unwrap_or_else(extend);
    Some((drift, z, extended))
}
