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
            kind: effects::CURRENT_LIMIT,
            param: -0.08,
            param2: 0.0,
        },
        Effect {
            kind: effects::STRIBECK,
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
        let mut part = holdout_mask(n, 0);
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

/// The position, velocity and acceleration at `t` of a sum of tones (frequency in Hz,
/// amplitude in m, phase in rad), in closed form.
pub(crate) fn tones_motion(tones: &[(f64, f64, f64)], t: f64) -> (f64, f64, f64) {
    tones
        .iter()
        .fold((0.0, 0.0, 0.0), |(x, v, a), &(f, amp, ph)| {
            let w = std::f64::consts::TAU * f;
            let (sn, cs) = (w * t + ph).sin_cos();
            (x + amp * sn, v + amp * w * cs, a - amp * w * w * sn)
        })
}

/// A closed-form record: a three-tone motion with its exact velocity and acceleration, and
/// the force M·a + Fv·v + Fc·sign(v) of a device evaluated at t − τ, white noise 0.3 N.
fn delayed_record(m: f64, fv: f64, fc: f64, tau: f64) -> Record {
    let (fs, n) = (1000.0, 12_000);
    let tones = [(0.31, 0.012, 0.3), (0.73, 0.008, 1.9), (1.37, 0.004, 4.1)];
    let motion = |t: f64| tones_motion(&tones, t);
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
/// 0), read with the default derivation (v and a derived from x at the default cutoff).
fn delayed_csv(tau: f64, q: f64) -> Record {
    quantised_csv(&delayed_record(40.0, 300.0, 20.0, tau), q)
}

/// The record `r`'s time and force with its position quantised to `q` (exact when 0), as
/// a CSV read with the default derivation (v and a derived from x at the default cutoff).
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
    println!(
        "slope least squares {}, corrected {}; held-out rss per row {ls_row}, corrected {per_row}",
        ls[0], th[0]
    );
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

/// A record with a current channel: x = A·sin ωt + A/3·sin 3.1ωt, the force M·a + Fv·v +
/// Fc·sgn v − g·i_q (closed form) with a deterministic ±0.3 N noise; the current either
/// follows the speed (`i_q = −v/0.05`, a resistor law) or not (a 1.3 Hz sinusoid).
fn current_record(follows_speed: bool) -> Record {
    let (m, fv, fc, g, amp, w) = (50.0, 100.0, 20.0, 40.0, 0.05, std::f64::consts::TAU * 0.7);
    let mut s = String::from("t_s,x_m,f_N,i_q_A\n");
    let mut seed = 12345u64;
    for i in 0..20_000 {
        let t = i as f64 * 1e-3;
        let x = amp * ((w * t).sin() + (3.1 * w * t).sin() / 3.0);
        let v = amp * w * ((w * t).cos() + 3.1 / 3.0 * (3.1 * w * t).cos());
        let a = -amp * w * w * ((w * t).sin() + 3.1 * 3.1 / 3.0 * (3.1 * w * t).sin());
        let iq = if follows_speed {
            -v / 0.05
        } else {
            3.0 * (std::f64::consts::TAU * 1.3 * t + 1.0).sin()
        };
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let noise = 0.3 * (2.0 * (seed >> 11) as f64 / (1u64 << 53) as f64 - 1.0);
        let f = m * a + fv * v + fc * v.signum() - g * iq + noise;
        s.push_str(&format!("{t},{x},{f},{iq}\n"));
    }
    parse_csv(&s, None).unwrap()
}

/// A current that follows the speed makes the machine's force and viscous friction one
/// column: the diagnosis says the record cannot tell them apart (and the report's summary
/// says so); a current of its own is told apart.
#[test]
fn a_current_that_follows_speed_is_not_told_from_viscous_friction() {
    for follows in [true, false] {
        let rec = current_record(follows);
        let d = diagnose(&rec, &Options::default());
        println!("current follows the speed {follows}: {:?}", d.confounded);
        let pair = d.confounded.iter().any(|(a, b, _)| {
            (a == "viscous_friction" && b == "electromagnetic_force")
                || (b == "viscous_friction" && a == "electromagnetic_force")
        });
        assert_eq!(pair, follows, "{:?}", d.confounded);
        assert_eq!(
            report::summary(&d).contains("cannot tell"),
            follows,
            "{}",
            report::summary(&d)
        );
    }
}

/// The method's parts that judge and report (the selection, the validation, the conclusion,
/// the report) name
/// no effect: every registered effect's name (whole word, any case) and its type name
/// (CamelCase) are absent from their sources (tests excluded), so that an effect is added by
/// its file and its registry line alone. Break: `EffectKind::from_name("lag")` written into
/// `validation.rs` fails it.
#[test]
fn method_names_no_effect() {
    fn sources(p: &std::path::Path, out: &mut Vec<(String, String)>) {
        if p.is_dir() {
            let mut entries: Vec<_> = std::fs::read_dir(p)
                .unwrap_or_else(|e| panic!("{}: {e}", p.display()))
                .filter_map(|e| e.ok().map(|e| e.path()))
                .collect();
            entries.sort();
            for e in entries {
                sources(&e, out);
            }
        } else if p.extension().is_some_and(|x| x == "rs")
            && p.file_name().is_some_and(|f| f != "tests.rs")
        {
            let text =
                std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            out.push((p.display().to_string(), text));
        }
    }
    let src = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    for part in ["selection", "validation", "conclusion", "report"] {
        let dir = src.join(part);
        let file = src.join(format!("{part}.rs"));
        assert!(dir.exists() || file.exists(), "no source for {part}");
        for p in [dir, file] {
            if p.exists() {
                sources(&p, &mut files);
            }
        }
    }
    let word = |c: char| c.is_ascii_alphanumeric() || c == '_';
    let has_word = |text: &str, w: &str| {
        text.match_indices(w).any(|(i, _)| {
            let before = text[..i].chars().next_back().is_none_or(|c| !word(c));
            let after = text[i + w.len()..].chars().next().is_none_or(|c| !word(c));
            before && after
        })
    };
    let mut found = Vec::new();
    for kind in effects::EffectKind::all() {
        let name = kind.name();
        let camel: String = name
            .split('_')
            .map(|w| {
                let mut c = w.chars();
                c.next()
                    .map(|f| f.to_ascii_uppercase().to_string() + c.as_str())
                    .unwrap_or_default()
            })
            .collect();
        for (path, text) in &files {
            if has_word(&text.to_lowercase(), name) || has_word(text, &camel) {
                found.push(format!("{path}: {name}"));
            }
        }
    }
    println!(
        "{} sources checked for {} effects",
        files.len(),
        effects::EffectKind::all().len()
    );
    assert!(found.is_empty(), "effects named: {found:#?}");
}
