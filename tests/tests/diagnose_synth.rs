//! Hidden-effect tests: seeded synthetic bench records with one or two catalogue effects hidden
//! at random (random parameters), and clean records. The diagnosis must name the hidden
//! effects, report nothing on clean records, and cut the held-out error.

use hal_sim::diagnose::synth::SynthSpec;
use hal_sim::diagnose::{diagnose, synth, Options};

/// 12 s at 1 kHz: the slowest excitation component (0.2 Hz) completes more than two periods;
/// short enough for the test suite.
const SAMPLES: usize = 12_000;

fn extension_names(d: &hal_sim::diagnose::Diagnosis) -> Vec<String> {
    d.catalogue_names().into_iter().map(String::from).collect()
}

#[test]
fn hidden_effects_are_named_and_error_is_cut() {
    // 40 seeds: 20 with one hidden effect, 20 with two.
    let seeds = 40u64;
    let mut detected = 0usize;
    let mut hidden_total = 0usize;
    let mut all_named = 0usize;
    let mut cuts = Vec::new();
    let mut spurious_records = 0usize;
    for seed in 0..seeds {
        let n_hidden = 1 + (seed % 2) as usize;
        let spec = SynthSpec::random_hidden(1000 + seed, SAMPLES, n_hidden);
        let rec = synth::generate(&spec);
        let d = diagnose(&rec, &Options::default());
        let names = extension_names(&d);
        let want: Vec<&str> = spec.hidden.iter().map(|(e, _)| e.kind.name()).collect();
        let hits = want
            .iter()
            .filter(|w| names.iter().any(|n| n == *w))
            .count();
        detected += hits;
        hidden_total += want.len();
        if hits == want.len() {
            all_named += 1;
        }
        if names.iter().any(|n| !want.contains(&n.as_str())) {
            spurious_records += 1;
        }
        let cut = d.baseline_holdout_rel_error / d.final_holdout_rel_error;
        cuts.push(cut);
        println!(
            "seed {seed}: hidden {want:?} params {:?} -> found {names:?}, held-out {:.2} % -> {:.2} % (cut {cut:.1}x)",
            spec.hidden.iter().map(|(e, c)| (e.param, c.clone())).collect::<Vec<_>>(),
            100.0 * d.baseline_holdout_rel_error,
            100.0 * d.final_holdout_rel_error
        );
    }
    let rate = detected as f64 / hidden_total as f64;
    cuts.sort_by(|a, b| a.total_cmp(b));
    let median_cut = cuts[cuts.len() / 2];
    println!("records with an extra (not hidden) effect named: {spurious_records}/{seeds}");
    println!(
        "detection rate {detected}/{hidden_total} = {:.1} %, records with every hidden effect named {all_named}/{seeds}, median held-out error cut {median_cut:.1}x",
        100.0 * rate
    );
    // Bound: 85 % of hidden effects named. With 60 hidden effects, a diagnosis whose true
    // per-effect rate were 70 % would pass this with probability below 1 % (binomial tail),
    // so a lucky pass is unlikely.
    assert!(rate >= 0.85, "detection rate {rate}");
    // Each hidden effect carries 10-35 % of the Coulomb force against 0.5 N sensor noise, so
    // naming it must remove most of the structured error: the median held-out error must fall
    // by at least 2x.
    assert!(median_cut >= 2.0, "median cut {median_cut}");
    // Extra names beside the hidden ones (e.g. reflected_inertia beside screw_efficiency, both
    // living on the driven quadrants) are tolerated on at most a quarter of the records.
    assert!(
        spurious_records * 4 <= seeds as usize,
        "{spurious_records} records with extra effects"
    );
}

#[test]
fn clean_records_give_no_finding() {
    let seeds = 20u64;
    let mut false_pos = 0;
    for seed in 0..seeds {
        let rec = synth::generate(&SynthSpec::clean(5000 + seed, SAMPLES));
        let d = diagnose(&rec, &Options::default());
        let names = extension_names(&d);
        let unexplained = d.findings.len() - names.len();
        println!(
            "clean seed {seed}: findings {names:?}, unexplained {unexplained}, baseline held-out {:.2} %",
            100.0 * d.baseline_holdout_rel_error
        );
        if !d.findings.is_empty() {
            false_pos += 1;
        }
    }
    println!("false positives on clean records: {false_pos}/{seeds}");
    // Bound: at most 1 of 20 clean records (5 %) may carry any finding.
    assert!(false_pos <= 1, "{false_pos} clean records with findings");
}

#[test]
fn hidden_compliance_is_named() {
    // 16 seeds: 8 with the resonance alone, 8 beside one other random effect. The modal
    // mass, resonance and damping ratio found are printed beside the hidden ones.
    let seeds = 16u64;
    let mut named = 0usize;
    let mut others_named = 0usize;
    let mut others = 0usize;
    let mut extra_records = 0usize;
    let mut cuts = Vec::new();
    for seed in 0..seeds {
        let n_other = (seed % 2) as usize;
        let spec = SynthSpec::with_compliance(3000 + seed, SAMPLES, n_other);
        let rec = synth::generate(&spec);
        let d = diagnose(&rec, &Options::default());
        let names = extension_names(&d);
        let want: Vec<&str> = spec.hidden.iter().map(|(e, _)| e.kind.name()).collect();
        let found = d
            .findings
            .iter()
            .find(|f| f.effect == "compliance")
            .map(|f| f.parameters.clone());
        if found.is_some() {
            named += 1;
        }
        if names.iter().any(|n| !want.contains(&n.as_str())) {
            extra_records += 1;
        }
        for w in want.iter().filter(|w| **w != "compliance") {
            others += 1;
            if names.iter().any(|n| n == w) {
                others_named += 1;
            }
        }
        let cut = d.baseline_holdout_rel_error / d.final_holdout_rel_error;
        cuts.push(cut);
        println!(
            "seed {seed}: hidden {want:?} {:?} -> found {names:?} {found:?}, held-out {:.2} % -> {:.2} % (cut {cut:.1}x)",
            spec.hidden.iter().map(|(e, c)| (e.param, c.clone())).collect::<Vec<_>>(),
            100.0 * d.baseline_holdout_rel_error,
            100.0 * d.final_holdout_rel_error
        );
    }
    cuts.sort_by(|a, b| a.total_cmp(b));
    let median_cut = cuts[cuts.len() / 2];
    println!(
        "compliance named in {named}/{seeds} records, other hidden effects named {others_named}/{others}, records with an extra name {extra_records}/{seeds}, median held-out cut {median_cut:.1}x"
    );
    // Bound: 14 of 16 (87.5 %). A diagnosis whose true rate were 60 % would reach it with
    // probability about 2 % (binomial tail), so a lucky pass is unlikely.
    assert!(named * 16 >= 14 * seeds as usize, "{named}/{seeds}");
    // The other effects: 6/8 measured with the resonance hidden as the physical
    // mode (`effects::compliance_columns_at` at its own damping ratio). The two missed are
    // built on the baseline's force proxy f̂₀, which carries none of the mode: a 4.6 ms lag
    // taken by `presliding_hysteresis`, a `screw_efficiency` taken by `reflected_inertia`.
    // Bound 6/8: no margin below the measured figure (a seeded set, the figure moves only
    // with the code).
    assert!(others_named * 8 >= 6 * others, "{others_named}/{others}");
    assert!(median_cut >= 2.0, "median cut {median_cut}");
}
