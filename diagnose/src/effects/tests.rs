use super::*;

/// `speed_levels` against closed forms. A sinusoid v = v̂·sin(ωt) over whole periods: the
/// time quantile q of |v| is v̂·sin(qπ/2), the crossing quantile (|v| weighted by |Δv|)
/// q·v̂; the time quantiles are in the grid, and the crossing quantiles below the lowest
/// time quantile (q = 0.2, 0.3: below sin(0.1π) = 0.309), none inside their range
/// (within 0.5 % of v̂: 20,000 samples per period). A
/// motion cruising at v̂ for 90 % of the time with linear ramps (a triangle's flanks): the
/// time quantiles all lie at v̂, the crossing quantiles at q·v̂, so the grid still reaches
/// down to 0.2·v̂. No two neighbours of either grid lie more than `SPEED_GAP` apart (values
/// inserted log-spaced: the sinusoid's 0.02 → 0.03 and 0.0309 → 0.0454 get one each, so the
/// grid holds the 12 time quantiles, 2 crossing quantiles and two inserted values). Break:
/// without the crossing quantiles the cruise grid's lowest value is v̂ (and the sinusoid
/// misses q·v̂); without the insertion the cruise grid's 0.2·v̂ → 0.3·v̂ is a gap of 1.5.
#[test]
fn speed_levels_span_the_speeds_crossed() {
    let n = 100_000;
    let v: Vec<f64> = (0..n)
        .map(|i| 0.1 * (std::f64::consts::TAU * 5.0 * i as f64 / n as f64).sin())
        .collect();
    let rest = vec![false; n];
    let g = speed_levels(&v, &rest);
    let has = |g: &[f64], x: f64| g.iter().any(|y| (y - x).abs() < 5e-4);
    let gaps_within = |g: &[f64]| {
        g.windows(2)
            .all(|w| w[1] / w[0] <= SPEED_GAP * (1.0 + 1e-12))
    };
    assert_eq!(g.len(), SPEED_QUANTILES.len() + 4, "{g:?}");
    assert!(gaps_within(&g), "{g:?}");
    for q in SPEED_QUANTILES {
        if q < 0.309 {
            assert!(has(&g, 0.1 * q), "crossing quantile {q}: {g:?}");
        }
        assert!(
            has(&g, 0.1 * (q * std::f64::consts::FRAC_PI_2).sin()),
            "time quantile {q}"
        );
    }
    // cruise: ramps of 500 samples, 9,000 at v̂, both directions
    let mut v = Vec::new();
    for s in [1.0, -1.0, 1.0, -1.0] {
        v.extend((0..500).map(|i| s * 0.1 * i as f64 / 500.0));
        v.extend(std::iter::repeat_n(s * 0.1, 9000));
        v.extend((0..500).map(|i| s * 0.1 * (500 - i) as f64 / 500.0));
    }
    let g = speed_levels(&v, &vec![false; v.len()]);
    let lo = g.iter().cloned().fold(f64::MAX, f64::min);
    assert!((lo / 0.02 - 1.0).abs() < 0.01, "lowest speed scanned {lo}");
    for q in SPEED_QUANTILES {
        assert!(has(&g, 0.1 * q), "cruise crossing quantile {q}: {g:?}");
    }
    assert!(gaps_within(&g), "{g:?}");
}

/// Monotone motion from z = 0: the Dahl state is the closed form 1 − exp(−x/x_c); after a
/// reversal at x_r with state z_r, z = −1 + (z_r + 1)·exp(−(x_r − x)/x_c). `dahl_at` gives
/// the same values at the requested rows (the skipped exponentials change nothing).
#[test]
fn dahl_matches_closed_form() {
    let xc = 2e-4;
    let mut x: Vec<f64> = (0..3000).map(|i| 1e-6 * i as f64).collect();
    let xr = *x.last().unwrap();
    x.extend((1..3000).map(|i| xr - 1e-6 * i as f64));
    let z = dahl(&x, xc);
    let zr = 1.0 - (-xr / xc).exp();
    for (i, &xi) in x.iter().enumerate() {
        let want = if i < 3000 {
            1.0 - (-xi / xc).exp()
        } else {
            -1.0 + (zr + 1.0) * (-(xr - xi) / xc).exp()
        };
        assert!((z[i] - want).abs() < 1e-12, "{i}: {} vs {want}", z[i]);
    }
    let rows: Vec<usize> = (0..x.len()).step_by(7).collect();
    let za = dahl_at(&x, xc, &rows);
    assert_eq!(za.len(), rows.len());
    for (k, &r) in rows.iter().enumerate() {
        assert_eq!(za[k], z[r]);
    }
}

/// Monotone motion by steps of many different sizes (more than the decay factors kept per
/// value, so that step sizes share a memo slot): still the closed form 1 − exp(−x/x_c).
#[test]
fn dahl_closed_form_with_irregular_steps() {
    let mut x = vec![0.0];
    for i in 0..4000u64 {
        let step = 1e-7 * (1 + (i * 7919) % 97) as f64;
        x.push(x[x.len() - 1] + step);
    }
    for xc in [3e-6, 4e-5] {
        let z = dahl(&x, xc);
        for (i, &xi) in x.iter().enumerate() {
            let want = 1.0 - (-xi / xc).exp();
            assert!((z[i] - want).abs() < 1e-12, "{i}: {} vs {want}", z[i]);
        }
    }
}

/// Resonance frequencies (Hz at a 1 ms step) and damping ratios of the resonator tests.
const RESONATOR_MODES: [(f64, f64); 9] = [
    (0.5, 0.01),
    (1.1, 0.1),
    (2.3, 0.4),
    (4.7, 0.05),
    (9.1, 0.2),
    (17.0, 0.02),
    (33.0, 0.0159),
    (61.0, 0.2533),
    (120.0, 0.04),
];

/// The resonators interleaved in a pass (six, three lane pairs) give, mode by
/// mode, exactly the resonator run alone, on every sample and at chosen rows.
#[test]
fn batched_resonators_match_single_ones() {
    let u: Vec<f64> = (0..5000)
        .map(|i| (0.013 * i as f64).sin() + 0.3 * (0.21 * i as f64).cos())
        .collect();
    let modes = &RESONATOR_MODES[..6];
    let rows: Vec<usize> = (3..u.len()).step_by(29).collect();
    for r in [None, Some(rows.as_slice())] {
        let b = resonator_batch(&u, modes, 1e-3, r);
        for (k, &m) in modes.iter().enumerate() {
            let one = resonator_batch(&u, &[m], 1e-3, r).pop();
            assert_eq!(Some(&b[k]), one.as_ref(), "mode {m:?}");
        }
    }
}

/// `resonator_batch` (its filters two to a lane pair, `F64x2`) gives each filter's outputs
/// bit for bit as the scalar recurrence written out here, for every count of filters per
/// pass (1 to 9: a lone filter, an odd pair, several passes); and the lane pair's +, −, ×
/// are the scalar operations lane by lane (operands whose sums and products round).
#[test]
fn lane_pairs_are_scalar_arithmetic() {
    let xs = [0.1, -3.7e-5, 1.0 / 3.0, 2.5e12, -7.25, 1e-300];
    for &a in &xs {
        for &b in &xs {
            let (p, q) = (F64x2::new(a, b), F64x2::new(b, a));
            assert_eq!(
                (p + q).lanes().map(f64::to_bits),
                [a + b, b + a].map(f64::to_bits)
            );
            assert_eq!(
                (p - q).lanes().map(f64::to_bits),
                [a - b, b - a].map(f64::to_bits)
            );
            assert_eq!(
                (p * q).lanes().map(f64::to_bits),
                [a * b, b * a].map(f64::to_bits)
            );
        }
    }
    let u: Vec<f64> = (0..3000)
        .map(|i| (0.017 * i as f64).sin() + 0.4 * (0.23 * i as f64).cos())
        .collect();
    let all = RESONATOR_MODES;
    let dt = 1e-3;
    let scalar = |f: f64, z: f64| -> (Vec<f64>, Vec<f64>) {
        let g = (std::f64::consts::PI * (f * dt).min(0.49)).tan();
        let a1 = 1.0 / (1.0 + g * (g + 2.0 * z));
        let (a2, a3) = (g * a1, g * g * a1);
        let (mut ic1, mut ic2) = (0.0, u[0]);
        let (mut lp, mut bp) = (Vec::new(), Vec::new());
        for &x in &u {
            let v3 = x - ic2;
            let v1 = a1 * ic1 + a2 * v3;
            let v2 = ic2 + a2 * ic1 + a3 * v3;
            ic1 = 2.0 * v1 - ic1;
            ic2 = 2.0 * v2 - ic2;
            lp.push(v2);
            bp.push(v1);
        }
        (lp, bp)
    };
    let want: Vec<(Vec<f64>, Vec<f64>)> = all.iter().map(|&(f, z)| scalar(f, z)).collect();
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<u64>>();
    // at chosen rows (the first sample, a stride, neighbours, the last sample): the same
    // outputs at those samples
    let rows: Vec<usize> = [0, 1, 2]
        .into_iter()
        .chain((17..u.len() - 1).step_by(37))
        .chain([u.len() - 1])
        .collect();
    let at = |v: &[f64]| rows.iter().map(|&i| v[i].to_bits()).collect::<Vec<u64>>();
    for m in 1..=all.len() {
        let got = resonator_batch(&u, &all[..m], dt, None);
        assert_eq!(got.len(), m);
        for (k, (g, w)) in got.iter().zip(&want).enumerate() {
            assert_eq!(bits(&g.0), bits(&w.0), "low-pass of filter {k} of {m}");
            assert_eq!(bits(&g.1), bits(&w.1), "band-pass of filter {k} of {m}");
        }
        let got = resonator_batch(&u, &all[..m], dt, Some(&rows));
        assert_eq!(got.len(), m);
        for (k, (g, w)) in got.iter().zip(&want).enumerate() {
            assert_eq!(
                bits(&g.0),
                at(&w.0),
                "low-pass of filter {k} of {m} at rows"
            );
            assert_eq!(
                bits(&g.1),
                at(&w.1),
                "band-pass of filter {k} of {m} at rows"
            );
        }
    }
}

/// `compliance_columns_at` (each column formed from its filter's outputs at each row) gives,
/// mode by mode, LP + 2ζ·BP − a from `resonator_batch`'s low-pass and band-pass, bit for
/// bit, on every sample and at chosen rows, for the nine modes (passes of eight and one).
/// Breaks: the band-pass taken at the low-pass's index, or each mode given the next
/// mode's ζ, fail it.
#[test]
fn compliance_columns_are_the_resonators_outputs() {
    let u: Vec<f64> = (0..4000)
        .map(|i| (0.011 * i as f64).sin() + 0.5 * (0.19 * i as f64).cos())
        .collect();
    let modes = RESONATOR_MODES;
    let rows: Vec<usize> = (0..u.len()).step_by(13).collect();
    for r in [None, Some(rows.as_slice())] {
        let cols = compliance_columns_at(&u, &modes, 1e-3, r);
        let res = resonator_batch(&u, &modes, 1e-3, r);
        assert_eq!(cols.len(), modes.len());
        for (k, ((c, (lp, bp)), &(_, z))) in cols.iter().zip(&res).zip(&modes).enumerate() {
            let want: Vec<u64> = (0..lp.len())
                .map(|j| {
                    let aj = r.map_or(u[j], |rw| u[rw[j]]);
                    (lp[j] + 2.0 * z * bp[j] - aj).to_bits()
                })
                .collect();
            let got: Vec<u64> = c.iter().map(|v| v.to_bits()).collect();
            assert_eq!(got, want, "mode {k}");
        }
    }
}

/// The one-pass walk over several characteristic displacements gives, value by value,
/// exactly the single-value walk (Dahl states on a quantised path with reversals and
/// standstills: a state settled for one value and not for another).
#[test]
fn batched_walks_match_single_ones() {
    let q = 1.6e-6;
    let x: Vec<f64> = (0..20_000)
        .map(|i| {
            let t = i as f64 * 1e-3;
            let p = 2e-3 * (2.1 * t).sin() + 3e-4 * (13.0 * t).sin();
            (p / q).round() * q
        })
        .collect();
    let rows: Vec<usize> = (5..x.len()).step_by(37).collect();
    let xcs = [2.0 * q, 1e-5, 1e-4, 1e-3, 1e-2];
    let zb = dahl_batch_at(&x, &xcs, &rows);
    for (k, &xc) in xcs.iter().enumerate() {
        let z = dahl(&x, xc);
        for (j, &r) in rows.iter().enumerate() {
            assert_eq!(zb[k][j].to_bits(), z[r].to_bits(), "xc {xc}, row {r}");
        }
    }
}

/// A device that cannot coast (infinite Coulomb friction: it stops where the flank leaves
/// it) follows the play operator bit for bit: `play_device` and `play_output` are the same
/// play (sine with reversals, exact velocity).
#[test]
fn play_device_without_coasting_is_the_play_operator() {
    let dt = 1e-3;
    let (x, v, a): (Vec<f64>, Vec<f64>, Vec<f64>) = (0..6000)
        .map(|i| {
            let t = i as f64 * dt;
            let (w1, w2) = (2.3, 7.1);
            (
                0.02 * (w1 * t).sin() + 0.002 * (w2 * t).sin(),
                0.02 * w1 * (w1 * t).cos() + 0.002 * w2 * (w2 * t).cos(),
                -0.02 * w1 * w1 * (w1 * t).sin() - 0.002 * w2 * w2 * (w2 * t).sin(),
            )
        })
        .fold((vec![], vec![], vec![]), |mut o, (x, v, a)| {
            o.0.push(x);
            o.1.push(v);
            o.2.push(a);
            o
        });
    let sg: Vec<f64> = v.iter().map(|v| v.signum()).collect();
    for b in [1e-4, 1e-3, 4e-3] {
        let d = play_device(&x, &v, &a, &sg, dt, b, 10.0, 50.0, f64::INFINITY, 0.0);
        let p = play_output(&x, b);
        for i in 0..x.len() {
            assert_eq!(d.xm[i].to_bits(), p[i].to_bits(), "b {b}, sample {i}");
        }
        assert!(d.impacts.len() >= 4, "{}", d.impacts.len());
    }
}

/// The device left by a motion that stops dead coasts the closed-form distance: with
/// viscous friction only v0·M/Fv (the trapezoid over the exact exponential decay is within
/// (dt/τ)²/12 of it), with Coulomb friction only v0²·M/(2·Fc) (exact: the velocity falls
/// linearly and the step where it stops is cut at the stop); no force passes while it
/// coasts, and the motion's return strikes it with the relative velocity.
#[test]
fn play_device_coasts_the_closed_form_distance() {
    let (dt, v0, b, m) = (1e-3, 0.01, 4e-3, 10.0);
    let n = 3000;
    let k0 = 1000;
    let x: Vec<f64> = (0..n).map(|i| v0 * dt * (i.min(k0) as f64)).collect();
    let v: Vec<f64> = (0..n).map(|i| if i < k0 { v0 } else { 0.0 }).collect();
    let a: Vec<f64> = (0..n)
        .map(|i| if i == k0 { -v0 / dt } else { 0.0 })
        .collect();
    let sg: Vec<f64> = v.iter().map(|v| v.signum()).collect();
    // started centred, the motion takes up half the gap and strikes the device at rest
    for (fv, fc, want) in [
        (100.0, 0.0, v0 * m / 100.0),
        (0.0, 0.5, v0 * v0 * m / (2.0 * 0.5)),
    ] {
        let mut v1 = v.clone();
        v1[0] = 0.0;
        let d = play_device(&x, &v1, &a, &sg, dt, b, m, fv, fc, 0.0);
        let stop = x[k0 - 1] - 0.5 * b; // left the flank after sample k0 − 1
        let got = d.xm[n - 1] - stop;
        assert!(
            (got / want - 1.0).abs() < 1e-4,
            "fv {fv} fc {fc}: coasted {got} m, closed form {want} m"
        );
        assert!(d.free[k0] && d.free[n - 1] && !d.free[k0 - 1]);
        // one impact: at rest, struck at v0 after half the gap
        assert_eq!(d.impacts.len(), 1);
        let (i, _, vr) = d.impacts[0];
        assert_eq!(vr, v0);
        assert!((x[i] - 0.5 * b).abs() <= v0 * dt * 1.0001, "{}", x[i]);
    }
}

/// A compliant flank unloads as Hooke's spring: a device (M 10 kg, Coulomb 20 N) carried
/// on the + flank at 10 mm/s, the motion then decelerating at A = 0.5 m/s² through its
/// reversal (M·A below the friction, so the device stops with the flank), the play
/// 0.2 mm wide. As the motion
/// stops, the flank's spring carries the device's sliding force M·(−A) + Fc = 15 N; the
/// device then stays (static friction) and the spring force falls as 15 N − k·u with the
/// retreat u, k = M·(2π·50 Hz)², to 0 at u = 15 N / k = 15.2 µm, where the device is
/// free (forces and stiffness from the closed form, not the walk). A rigid flank
/// releases it on the reversal's sample; so does a flank of 10⁶ Hz (the rigid walk's
/// free samples, one for one).
#[test]
fn compliant_flank_unloads_as_its_spring() {
    let (dt, v0, acc, b, m, fc, hz) = (1e-4, 0.01, 0.5, 2e-4, 10.0, 20.0, 50.0);
    let n = 2000;
    let t1 = 0.05;
    let (mut x, mut v, mut a) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    for i in 0..n {
        let t = i as f64 * dt;
        let u = (t - t1).max(0.0);
        v[i] = v0 - acc * u;
        x[i] = v0 * t - 0.5 * acc * u * u;
        a[i] = if t > t1 { -acc } else { 0.0 };
    }
    let sg: Vec<f64> = v
        .iter()
        .map(|&v| if v == 0.0 { 0.0 } else { v.signum() })
        .collect();
    // started centred: the + flank takes the device on within 25 ms
    let k = m * (2.0 * std::f64::consts::PI * hz).powi(2);
    let hold = m * (-acc) + fc;
    let walk = |c: f64| play_device(&x, &v, &a, &sg, dt, b, m, 0.0, fc, -c);
    let soft = walk(hz);
    let rigid = walk(0.0);
    let stiff = walk(1e6);
    assert!(rigid.spring.is_empty() && soft.spring.len() == n);
    // the last sample moving forward, and the flank's position there
    let last = (0..n).rev().find(|&i| v[i] > 0.0).unwrap();
    assert!(!soft.free[last] && !rigid.free[last]);
    assert!(rigid.free[last + 1]);
    let mut released = None;
    // up to the − flank, which the device meets at a retreat of b + hold/k
    for i in (last + 1..n).take_while(|&i| x[last] - x[i] < b) {
        let u = x[last] - x[i];
        let want = (hold - k * u).max(0.0);
        assert!(
            (soft.spring[i] - want).abs() < 1e-6 * hold,
            "sample {i}: retreat {u}: spring {} N, Hooke {want} N",
            soft.spring[i]
        );
        assert!(soft.free[i], "{i}");
        if released.is_none() && want == 0.0 {
            released = Some(u);
        }
    }
    // released past hold/k, within a sample's retreat of it
    let u = released.expect("the spring unloads");
    let step = acc * (n as f64 * dt) * dt;
    assert!(
        u >= hold / k && u - hold / k <= step,
        "{u} m for {} m",
        hold / k
    );
    assert_eq!(stiff.free, rigid.free);
}

/// A rebounding contact (restitution e) against the closed-form flight: a viscous device
/// (M, Fv; τ = M/Fv) at rest is struck by a flank moving at V; thrown at w = V + e·v_r it
/// flies ahead, v_m = w·e^(−u/τ), and the flank catches it again where
/// w·τ·(1 − e^(−u/τ)) = V·u (solved here by bisection), at v_r = V − w·e^(−u/τ); each
/// contact's instant (the walk's interpolated one) and relative velocity, the first three,
/// are the walk's. No force
/// passes in flight; once the flank's push returns the device within a step it stays on
/// the flank. At e = 0 the walk is the plastic one bit for bit.
#[test]
fn play_device_rebounds_as_the_closed_form_flight() {
    let (dt, vf, b, m, fv, e) = (1e-4, 0.05, 2e-3, 60.0, 300.0, 0.3);
    let tau = m / fv;
    let n = 8000;
    let x: Vec<f64> = (0..n).map(|i| vf * dt * i as f64).collect();
    let mut v = vec![vf; n];
    v[0] = 0.0; // the device starts at rest, centred
    let a = vec![0.0; n];
    let sg = vec![1.0; n];
    let d = play_device(&x, &v, &a, &sg, dt, b, m, fv, 0.0, e);
    // closed form: first contact after half the gap at V; then flights
    let flight = |w: f64| {
        let g = |u: f64| w * tau * (1.0 - (-u / tau).exp()) - vf * u;
        let (mut lo, mut hi) = (1e-9, 10.0 * tau);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if g(mid) > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let u = 0.5 * (lo + hi);
        (u, vf - w * (-u / tau).exp())
    };
    let mut want = vec![(0.5 * b / vf, vf)];
    for _ in 0..2 {
        let (t, vr) = *want.last().unwrap();
        let (u, vr2) = flight(vf + e * vr);
        want.push((t + u, vr2));
    }
    assert!(d.impacts.len() >= 3, "{:?}", d.impacts);
    for (k, (&(i, since, vr), &(tw, vw))) in d.impacts.iter().zip(&want).enumerate() {
        let t = (i as f64 - since) * dt;
        println!(
            "contact {k}: t {t:.6} s (closed form {tw:.6}, {:+.3e} s), v_r {vr:.6} m/s ({vw:.6}, {:+.3e})",
            t - tw,
            vr / vw - 1.0
        );
        // measured 0, 6e-9, 5e-8 s: bound 3× the largest
        assert!((t - tw).abs() < 1.5e-7, "contact {k}: {t} s against {tw} s");
        // v_r is taken at the sample, the device's velocity (≤ V·(1 + e)) decayed by at
        // most one step's dt/τ after the contact: measured 0, 5e-6, 1.4e-5 m/s
        assert!(
            (vr - vw).abs() <= vf * (1.0 + e) * dt / tau,
            "contact {k}: {vr} against {vw}"
        );
    }
    // in flight between the first two contacts no force passes; at the end on the flank
    let mid = ((want[0].0 + want[1].0) / (2.0 * dt)) as usize;
    assert!(d.free[mid] && !d.free[n - 1]);
    // e = 0: the plastic walk, bit for bit
    let p0 = play_device(&x, &v, &a, &sg, dt, b, m, fv, 0.0, 0.0);
    let mut w = PlayWalk::new(b, m, fv, 0.0, dt);
    for i in 0..n {
        let (free, _) = w.step(x[i], v[i], a[i], sg[i]);
        assert_eq!((w.xm.to_bits(), free), (p0.xm[i].to_bits(), p0.free[i]));
    }
    assert_eq!(p0.impacts.len(), 1);
}

/// The impact's momentum rule: (1 + e)·M for a restitution e in [0, 1], the lower bound
/// halved (`impact_consistent`); no impact, or one of the wrong sign, is no play.
#[test]
fn impact_momentum_rule() {
    let m = 40.0;
    assert!(impact_consistent(&[10.0, 10.0, 20.0], m));
    assert!(impact_consistent(&[20.0; 4], m));
    assert!(!impact_consistent(&[20.0; 5], m));
    assert!(!impact_consistent(&[5.0, 5.0, 5.0], m));
    assert!(!impact_consistent(&[-40.0], m));
    assert!(!impact_consistent(&[40.0], -1.0));
    let base = [m, 300.0, 30.0, 0.0];
    let e = Effect {
        kind: BACKLASH,
        param: 1e-3,
        param2: 0.0,
    };
    let mut coef = vec![1.0];
    coef.extend([m / IMPACT_TAPS as f64; IMPACT_TAPS]);
    assert!(plausible(&e, &coef, &base));
    coef[0] = 1.3;
    assert!(!plausible(&e, &coef, &base));
    coef[0] = 1.0;
    for c in coef.iter_mut().skip(1) {
        *c = 0.0;
    }
    assert!(!plausible(&e, &coef, &base));
}

/// `compliance_zetas` (the profiles of several frequencies in one resonator pass) gives
/// each frequency's `compliance_zeta` profiled alone on a fresh context, bit for bit, a
/// repeated frequency included. The record: a chirp (0.5 to 40 Hz over 20 s, 1 kHz) with a
/// 2 kg modal mass on a 12 Hz, ζ 0.05 spring-damper integrated by its own semi-implicit
/// Euler steps (not the resonator of the profile), beside inertia, viscous and Coulomb
/// friction. Breaks: the columns split per frequency one short (chunks of 8) or the
/// frequencies' values cached in reverse order fail it.
#[test]
fn batched_zeta_profiles_match_single_ones() {
    let (fs_hz, n) = (1000.0, 20_000);
    let dt = 1.0 / fs_hz;
    let (w0, z0, m2) = (std::f64::consts::TAU * 12.0, 0.05, 2.0);
    let (mut y, mut yd) = (0.0, 0.0);
    let mut rec = Record::default();
    for i in 0..n {
        let t = i as f64 * dt;
        // phase of a linear chirp 0.5 → 40 Hz over 20 s
        let ph = std::f64::consts::TAU * (0.5 * t + 0.25 * 39.5 / 20.0 * t * t);
        let fr = 0.5 + 39.5 / 20.0 * t;
        let amp = 2e-3 / (1.0 + 0.1 * fr);
        let x = amp * ph.sin();
        let v = amp * std::f64::consts::TAU * fr * ph.cos();
        let a = -amp * (std::f64::consts::TAU * fr).powi(2) * ph.sin();
        let ydd = -2.0 * z0 * w0 * (yd - v) - w0 * w0 * (y - x);
        yd += ydd * dt;
        y += yd * dt;
        rec.t.push(t);
        rec.x.push(x);
        rec.v.push(v);
        rec.a.push(a);
        rec.f
            .push(3.0 * a + 50.0 * v + 4.0 * v.signum() + m2 * (ydd - a));
    }
    let freqs = [12.0, 5.0, 30.0, 12.0, 2.0, 80.0];
    let batched = Context::new(&rec).compliance_zetas(&freqs);
    let single: Vec<Option<f64>> = freqs
        .iter()
        .map(|&f| Context::new(&rec).compliance_zeta(f))
        .collect();
    let bits = |v: &[Option<f64>]| v.iter().map(|z| z.map(f64::to_bits)).collect::<Vec<_>>();
    assert_eq!(bits(&batched), bits(&single));
    // profiled, not the fallback: distinct values, a mode identified at 12 Hz
    assert!(single[0].is_some(), "{single:?}");
    assert_ne!(single[0], single[1], "{single:?}");
}

/// The rotated sinusoid of `sinusoid_energy` against the same projection summed with a
/// `sin_cos` at every sample's time: 10⁵ samples at 1 kHz, times printed to 1 µs (as the
/// records' are), every seventh sample at rest, a 6.9 Hz sinusoid and a 2 Hz one with a
/// ramp. Measured relative differences 10⁻¹⁴ at 6.9 and 2 Hz, 2.1·10⁻¹⁰ at 6.89 Hz (off
/// the peak, where the energy is small); asserted 6·10⁻¹⁰ (3× the largest). Broken (the rotation's sine term's sign flipped, or the step taken as 1.01·dt)
/// it fails.
#[test]
fn sinusoid_energy_is_the_direct_sum() {
    let n = 100_000;
    let dt = 1e-3;
    let t: Vec<f64> = (0..n)
        .map(|i| ((i as f64 * dt) * 1e6).round() / 1e6)
        .collect();
    let rest: Vec<bool> = (0..n).map(|i| i % 7 == 3).collect();
    let r: Vec<f64> = t
        .iter()
        .map(|&t| {
            3.0 * (std::f64::consts::TAU * 6.9 * t + 0.4).sin()
                + (std::f64::consts::TAU * 2.0 * t).cos()
                + 0.01 * t
        })
        .collect();
    let direct = |f: f64| {
        let w = std::f64::consts::TAU * f;
        let (mut ss, mut cc, mut sc, mut rs, mut rc) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for i in 0..n {
            if rest[i] {
                continue;
            }
            let (s, c) = (w * t[i]).sin_cos();
            ss += s * s;
            cc += c * c;
            sc += s * c;
            rs += r[i] * s;
            rc += r[i] * c;
        }
        (cc * rs * rs - 2.0 * sc * rs * rc + ss * rc * rc) / (ss * cc - sc * sc)
    };
    for f in [6.9, 6.9005, 6.89, 2.0, 11.3] {
        let (a, b) = (sinusoid_energy(&t, &r, &rest, dt, f), direct(f));
        let rel = (a / b - 1.0).abs();
        println!("{f} Hz: relative difference {rel:e}");
        assert!(rel < 6e-10, "{f} Hz: {a} against {b} ({rel:e})");
    }
}

/// `nonnegative_device` on exact forces of a device (columns a, v, sgn v, 1) over a motion at
/// several speeds: a physical device's coefficients come back as they are; forces whose least
/// squares need a negative viscous coefficient give the viscous one at 0 and the inertia and
/// Coulomb of the least squares on (a, sgn v, 1), solved here by Cramer's rule. Break: the
/// fallback removed (None for a negative coefficient) fails the second case.
#[test]
fn device_fit_holds_friction_non_negative() {
    let n = 4000;
    let rows: Vec<[f64; 4]> = (0..n)
        .map(|i| {
            let t = i as f64 / n as f64;
            let v = 0.1 * (std::f64::consts::TAU * 3.0 * t).sin()
                + 0.02 * (std::f64::consts::TAU * 7.0 * t).sin();
            let a = 0.1 * std::f64::consts::TAU * 3.0 * (std::f64::consts::TAU * 3.0 * t).cos();
            [a, v, v.signum(), 1.0]
        })
        .collect();
    let normals = |f: &dyn Fn(&[f64; 4]) -> f64| {
        let (mut g, mut b, mut ff) = ([0.0; 16], [0.0; 4], 0.0);
        for r in &rows {
            ff += f(r) * f(r);
            for j in 0..4 {
                b[j] += r[j] * f(r);
                for k in 0..4 {
                    g[j * 4 + k] += r[j] * r[k];
                }
            }
        }
        let nq = crate::Normal {
            m: 4,
            g: g.to_vec(),
            b: b.to_vec(),
            ff,
            n: rows.len(),
        };
        (g, b, nq)
    };
    let (_, _, nq) = normals(&|r| 10.0 * r[0] + 30.0 * r[1] + 20.0 * r[2] + 1.0);
    let (m, fv, fc) = nonnegative_device(&nq).expect("a physical device");
    assert!((m - 10.0).abs() < 1e-6 && (fv - 30.0).abs() < 1e-6 && (fc - 20.0).abs() < 1e-6);
    let f = |r: &[f64; 4]| 10.0 * r[0] - 50.0 * r[1] + 20.0 * r[2] + 1.0;
    let (g, b, nq) = normals(&f);
    let (m, fv, fc) = nonnegative_device(&nq).expect("the viscous coefficient held at 0");
    // the least squares on (a, sgn v, 1) by Cramer's rule
    let idx = [0usize, 2, 3];
    let a3: Vec<Vec<f64>> = idx
        .iter()
        .map(|&j| idx.iter().map(|&k| g[j * 4 + k]).collect())
        .collect();
    let b3: Vec<f64> = idx.iter().map(|&j| b[j]).collect();
    let det = |m: &Vec<Vec<f64>>| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(&a3);
    let with = |c: usize| {
        let mut m = a3.clone();
        for r in 0..3 {
            m[r][c] = b3[r];
        }
        det(&m) / d
    };
    let (m_ref, fc_ref) = (with(0), with(1));
    println!("held at Fv = 0: M {m:.4} (Cramer {m_ref:.4}), Fc {fc:.4} (Cramer {fc_ref:.4})");
    assert_eq!(fv, 0.0);
    assert!((m - m_ref).abs() < 1e-6 * m_ref.abs() && (fc - fc_ref).abs() < 1e-6 * fc_ref.abs());
    assert!(
        fc_ref > 0.0 && fc_ref < 20.0,
        "the Coulomb level takes part of the negative viscous force"
    );
}

/// `at_rest` on a quantised ramp slower than a quantum per `REST_HALF_WINDOW` samples: 200
/// ramps drawn at 2 … 20 kHz (the derivative cutoff at its 50 Hz ceiling), quanta 0.1 … 30 µm,
/// at speeds of one quantum per 3 … 9 ms against a 50 Hz filter's 20 ms span (over ±20 ms the ramp
/// moves 2.2–6.7 quanta, more than the threshold of one quantum for a noise-free encoder), 4000
/// samples or more: no sample but the record's ends is at rest (measured 0 of every draw; the
/// bound is 0, the rule is exact for these ramps). At 0.1 … 1 kHz the window is 20 samples.
/// Break: `at_rest` over a fixed 20 samples (2 ms at 10 kHz, under one quantum of these
/// ramps) leaves every sample at rest and the first assert fails.
#[test]
fn rest_window_spans_the_derivative_filter() {
    let mut rng = crate::synth::Rng::new(5);
    for _ in 0..200 {
        let fs = rng.range(2e3, 2e4);
        let dt = 1.0 / fs;
        let q = rng.range(1e-7, 3e-5);
        // one quantum per 3 … 9 ms
        let u = q / rng.range(3e-3, 9e-3);
        let n = (fs * 0.5) as usize + 4000;
        let x: Vec<f64> = (0..n)
            .map(|i| (u * i as f64 * dt / q).floor() * q)
            .collect();
        let v = vec![u; n];
        let w = rest_half_window(dt);
        let rest = at_rest(&x, &v, dt);
        let inner = rest[w..n - w].iter().filter(|r| **r).count();
        assert_eq!(
            inner, 0,
            "fs {fs:.0} Hz, quantum {q:.2e} m, speed {u:.2e} m/s"
        );
    }
    for fs in [100.0, 500.0, 999.0, 1000.0] {
        assert_eq!(rest_half_window(1.0 / fs), REST_HALF_WINDOW, "{fs}");
    }
    // a record's times as close as f64 allows: the window far longer than the record, no
    // overflow (every sample then moving as far as the window can tell)
    let x: Vec<f64> = (0..100).map(|i| i as f64).collect();
    assert!(at_rest(&x, &x, 1e-300).iter().all(|r| !r));
}

/// `compliance_zeta` finds a mode's damping ratio between the profile's grid values: 24
/// devices with a modal mass (1 … 5 kg) on a spring-damper (2 … 20 Hz, ζ log-uniform over
/// 0.03 … 0.18, so mostly off the grid) driven by a linear chirp (0.5 → 40 Hz over 20 s,
/// 1 kHz, its velocity and acceleration exact), the mode integrated by the test's own
/// semi-implicit Euler steps, ten per sample (not the resonator of the profile), beside
/// inertia and viscous friction, no noise. The relative error of ζ: median and worst over the
/// devices. Measured: median 0.28 %, worst 1.12 %; bounds 0.8 % and 3 %, about 3× each (the
/// test's own integration is not the resonator's bilinear filter). Broken: the coarse
/// parabola alone (`PROFILE_FINE_STEP`'s second one skipped) gives median 2.5 %, worst 10 %,
/// and the test fails.
#[test]
fn the_damping_ratio_is_found_between_the_profile_grid() {
    let (fs_hz, n, sub) = (1000.0, 20_000, 10);
    let dt = 1.0 / fs_hz;
    let mut rng = crate::synth::Rng::new(7);
    let mut errs = Vec::new();
    for _ in 0..24 {
        let f0 = 2.0 * 10f64.powf(rng.uniform());
        let z0 = 0.03 * 6f64.powf(rng.uniform());
        let m2 = 1.0 + 4.0 * rng.uniform();
        let w0 = std::f64::consts::TAU * f0;
        // a linear chirp of constant amplitude, its velocity and acceleration exact
        let motion = |t: f64| {
            let (amp, k) = (2e-4, 39.5 / 20.0);
            let ph = std::f64::consts::TAU * (0.5 * t + 0.5 * k * t * t);
            let w = std::f64::consts::TAU * (0.5 + k * t);
            let (s, c) = ph.sin_cos();
            (
                amp * s,
                amp * w * c,
                -amp * w * w * s + amp * std::f64::consts::TAU * k * c,
            )
        };
        let (mut y, mut yd) = (0.0, 0.0);
        let mut rec = Record::default();
        for i in 0..n {
            let t = i as f64 * dt;
            let (x, v, a) = motion(t);
            let ydd = -2.0 * z0 * w0 * (yd - v) - w0 * w0 * (y - x);
            rec.t.push(t);
            rec.x.push(x);
            rec.v.push(v);
            rec.a.push(a);
            rec.f.push(3.0 * a + 50.0 * v + m2 * (ydd - a));
            for k in 0..sub {
                let (xs, vs, _) = motion(t + k as f64 * dt / sub as f64);
                let ydd = -2.0 * z0 * w0 * (yd - vs) - w0 * w0 * (y - xs);
                yd += ydd * dt / sub as f64;
                y += yd * dt / sub as f64;
            }
        }
        let z = Context::new(&rec).compliance_zeta(f0);
        let e = z.map_or(f64::INFINITY, |z| (z / z0 - 1.0).abs());
        println!(
            "f {f0:.2} Hz, ζ {z0:.4}, m {m2:.2} kg: found {z:?} ({:+.2} %)",
            100.0 * e
        );
        errs.push(e);
    }
    errs.sort_by(f64::total_cmp);
    let (median, worst) = (errs[errs.len() / 2], errs[errs.len() - 1]);
    println!(
        "ζ error: median {:.2} %, worst {:.2} %",
        100.0 * median,
        100.0 * worst
    );
    assert!(
        median < 0.008 && worst < 0.03,
        "median {median}, worst {worst}"
    );
}
