//! Real data: the EMPS ballscrew benchmark (Janot, Gautier, Brunot 2019), the repository's copy
//! in `data/emps/` (a missing file fails the test with its path). Published reference (README
//! there): symmetric friction model 4.08 % relative force error on the estimation record,
//! direction-dependent 3.11 %.

use hal_sim::diagnose::{cross_check, diagnose, read_csv, Options};
use regen_tests::emps_file;

#[test]
fn emps_finds_coulomb_and_asymmetric_friction_within_published_error() {
    let est = read_csv(&emps_file("emps_estimation.csv"), None).expect("estimation record parses");
    let val =
        read_csv(&emps_file("emps_validation_pulses.csv"), None).expect("validation record parses");
    let mut d = diagnose(&est, &Options::default());
    cross_check(&mut d, &val);
    println!("{}", hal_sim::diagnose::report::text(&est, &d));
    let coulomb = d
        .baseline_terms
        .iter()
        .find(|b| b.effect == "coulomb_friction")
        .unwrap();
    assert!(coulomb.significant, "Coulomb friction not significant");
    // Published Coulomb level 20.39 N; our derivative filter differs from the benchmark's, so
    // allow 10 %.
    assert!(
        (coulomb.value - 20.39).abs() < 2.0,
        "Fc = {}",
        coulomb.value
    );
    assert!(
        d.findings
            .iter()
            .any(|f| f.effect == "direction_asymmetric_friction"),
        "direction-asymmetric friction found"
    );
    // The published coefficients are those of the published model, the baseline and the
    // direction-dependent friction alone: compared on the diagnosis limited to that model's
    // size. (The final model's viscous coefficients move with its other terms: the friction
    // building up with speed takes part of the viscous force.)
    let d1 = diagnose(
        &est,
        &Options {
            max_effects: 1,
            ..Options::default()
        },
    );
    let asym = d1
        .findings
        .iter()
        .find(|f| f.effect == "direction_asymmetric_friction")
        .expect("direction-asymmetric friction found first");
    let p = |k: &str| asym.parameters.iter().find(|(n, _)| n == k).unwrap().1;
    println!(
        "published model's size: viscous {:.1} / {:.1} N·s/m (published 166.71 / 240.42)",
        p("viscous_pos_Ns_per_m"),
        p("viscous_neg_Ns_per_m")
    );
    // Published: viscous +166.71 / -240.42 N·s/m; measured 168.0 / 241.5 (+0.77 %, +0.45 %:
    // the published fit uses the parallel-filtered force, this one the raw force with the
    // derivative filter); asserted 2.5 %, about 3× the larger deviation.
    assert!((p("viscous_pos_Ns_per_m") / 166.71 - 1.0).abs() < 0.025);
    assert!((p("viscous_neg_Ns_per_m") / 240.42 - 1.0).abs() < 0.025);
    // Relative error of the diagnosed model fitted on the whole estimation record, as the
    // published figures are: must come within both published figures.
    println!(
        "EMPS estimation: baseline {:.2} % (published symmetric 4.08 %), diagnosed {:.2} % (published asymmetric 3.11 %); held-out {:.2} % -> {:.2} %",
        100.0 * d.baseline_full_rel_error,
        100.0 * d.final_full_rel_error,
        100.0 * d.baseline_holdout_rel_error,
        100.0 * d.final_holdout_rel_error
    );
    assert!(
        d.final_full_rel_error < 0.0311,
        "{}",
        d.final_full_rel_error
    );
    assert!(
        d.final_holdout_rel_error < 0.0408,
        "{}",
        d.final_holdout_rel_error
    );
    // The target, held-out error on the raw force ≤ 2.9 % with only physically
    // consistent findings: measured 2.24 %, asserted at the target (without
    // `velocity_strengthening_friction` the diagnosis reaches 2.92 % and fails it).
    assert!(
        d.final_holdout_rel_error <= 0.029,
        "{}",
        d.final_holdout_rel_error
    );
    // The friction's speed dependence is named as such, not as a position dependence: this
    // trajectory slows down towards the ends of the stroke (x̃²·sgn v correlates with |v| at
    // −0.72), and without the speed effect `position_dependent_friction` and a 114 mm
    // `position_periodic_friction` took it. The level builds up with speed (rise > 0, on a
    // low-speed Coulomb level ≥ 0).
    let names = d.catalogue_names();
    assert!(
        !names.iter().any(|n| matches!(
            *n,
            "position_dependent_friction" | "position_periodic_friction"
        )),
        "a position effect named on the speed dependence: {names:?}"
    );
    let vs = d
        .findings
        .iter()
        .find(|f| f.effect == "velocity_strengthening_friction")
        .unwrap_or_else(|| panic!("no velocity_strengthening_friction: {names:?}"));
    let q = |k: &str| vs.parameters.iter().find(|(n, _)| n == k).unwrap().1;
    println!(
        "velocity strengthening: rise {:.2} N over {:.2} mm/s",
        q("friction_rise_N"),
        1e3 * q("buildup_velocity_m_s")
    );
    assert!(q("friction_rise_N") > 0.0);
    // the fragment (`--model`) carries it for the simulator's plant
    let toml = hal_sim::diagnose::report::model_toml(&est, &d);
    let m = hal_sim::device_model::Fragment::from_toml(&toml)
        .expect("the EMPS fragment loads")
        .model;
    assert!(
        m.effects
            .iter()
            .any(|e| e.name() == "velocity_strengthening_friction"),
        "{toml}"
    );
    let c = d.cross.as_ref().unwrap();
    println!(
        "EMPS validation (cross-test, coefficients from estimation): baseline {:.2} %, diagnosed {:.2} %",
        100.0 * c.baseline_rel_error,
        100.0 * c.final_rel_error
    );
    // The findings must hold on the validation record: the extended model is not worse there.
    assert!(c.final_rel_error <= c.baseline_rel_error);
    // One cause, one name: no wavelength (catalogue or `unexplained`) reported twice within
    // 3 % (the 2.50 mm ripple shows as `cogging` and in the residual's position spectrum)
    let wl: Vec<f64> = d
        .findings
        .iter()
        .filter_map(|f| {
            f.parameters
                .iter()
                .find(|(n, _)| n == "wavelength_m")
                .map(|p| p.1)
        })
        .collect();
    for (i, a) in wl.iter().enumerate() {
        for b in &wl[i + 1..] {
            assert!(
                (a / b - 1.0).abs() >= 0.03,
                "wavelength named twice: {a} and {b}"
            );
        }
    }
}

/// The validation record's force pulses (a 1 Hz square wave of 5 V added to the controller
/// output, so `f_N` steps by gtau·5 V = 176 N at each edge) excite force content the derived
/// acceleration cannot follow. Two facts are checked: (1) the raw-force residual is
/// concentrated right after the pulse edges, and (2) with the benchmark's processing
/// (force low-passed by the same zero-phase filter as the derivatives, "parallel filtering")
/// the cross-test error comes within the published 5.98 %.
#[test]
fn emps_validation_pulses_where_the_model_misses_and_parallel_filtering() {
    let val =
        read_csv(&emps_file("emps_validation_pulses.csv"), None).expect("validation record parses");
    // (1) diagnose the validation record itself (raw force) and locate its residual
    let dv = diagnose(&val, &Options::default());
    let pulses = val.extra.get("pulses_N").expect("pulses_N column");
    let mut near = vec![false; val.len()];
    let mut edges = 0;
    for i in 1..val.len() {
        if pulses[i] != pulses[i - 1] {
            edges += 1;
            for n in near.iter_mut().skip(i).take(30) {
                *n = true;
            }
        }
    }
    let rms = |sel: bool| {
        let (s, c) = dv
            .residual
            .iter()
            .zip(&near)
            .filter(|(_, n)| **n == sel)
            .fold((0.0, 0usize), |(s, c), (r, _)| (s + r * r, c + 1));
        ((s / c as f64).sqrt(), c)
    };
    let (r_near, n_near) = rms(true);
    let (r_far, n_far) = rms(false);
    let share = r_near * r_near * n_near as f64
        / (r_near * r_near * n_near as f64 + r_far * r_far * n_far as f64);
    println!(
        "validation record diagnosed on its own: baseline {:.2} %, diagnosed {:.2} % (whole record); findings {:?}",
        100.0 * dv.baseline_full_rel_error,
        100.0 * dv.final_full_rel_error,
        dv.findings.iter().map(|f| f.effect.as_str()).collect::<Vec<_>>()
    );
    println!(
        "residual rms within 30 ms after the {edges} pulse edges {r_near:.2} N ({n_near} samples) vs {r_far:.2} N elsewhere; {:.0} % of the residual energy in {:.0} % of the samples",
        100.0 * share,
        100.0 * n_near as f64 / val.len() as f64
    );
    // Where it shows: right after the edges the residual rms is several times what it is
    // elsewhere (a residual uniform in time would give equal rms; measured 4.7x: 26.8 N
    // within 30 ms of the 49 edges against 5.7 N elsewhere).
    assert!(edges >= 40, "{edges} pulse edges");
    assert!(r_near > 2.5 * r_far, "{r_near} vs {r_far}");

    // (2) parallel filtering on both records
    let mut est =
        read_csv(&emps_file("emps_estimation.csv"), None).expect("estimation record parses");
    est.filter_force(None);
    let mut valf = val.clone();
    valf.filter_force(None);
    let mut d = diagnose(&est, &Options::default());
    cross_check(&mut d, &valf);
    let c = d.cross.as_ref().unwrap();
    println!(
        "parallel filtering: estimation baseline {:.2} % (published 4.08 %), diagnosed {:.2} % (published asymmetric 3.11 %); validation cross-test baseline {:.2} % (published 5.98 %), diagnosed {:.2} %",
        100.0 * d.baseline_full_rel_error,
        100.0 * d.final_full_rel_error,
        100.0 * c.baseline_rel_error,
        100.0 * c.final_rel_error
    );
    println!(
        "parallel filtering: held-out {:.2} % -> {:.2} %",
        100.0 * d.baseline_holdout_rel_error,
        100.0 * d.final_holdout_rel_error
    );
    for v in &d.verdicts {
        println!("  verdict: {v}");
    }
    for f in &d.findings {
        println!(
            "  finding {} {:?} held-out after {:.3} %, consistency {:.0} %",
            f.effect,
            f.parameters,
            100.0 * f.holdout_rel_error_after,
            100.0 * f.consistency
        );
    }
    for (name, e) in &c.after_each {
        println!("  validation after {name}: {:.2} %", 100.0 * e);
    }
    // Our filter (Butterworth-2 at 50 Hz) is not the benchmark's decimation filter, so the
    // published figures are matched within 10 % of their value, not exactly.
    assert!(d.baseline_full_rel_error < 1.1 * 0.0408);
    assert!(c.baseline_rel_error < 1.1 * 0.0598);
    assert!(d.final_full_rel_error < 0.0311);
    // the findings hold on the validation record: the diagnosed model is better there too
    assert!(c.final_rel_error < c.baseline_rel_error);
}
