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
