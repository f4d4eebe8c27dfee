//! The runs of the selection (`selection`): on two or three training / held-out splits of the
//! record, kept where most agree; on each, again with a force of the speed carried, and again
//! without the kinds a run's validation rejected.

use super::*;

/// The diagnosis of a checked record: the selection (with its runs again, `diagnose_split`)
/// on the record's first two training / held-out splits; where they name the same effects,
/// those are the findings, and where they do not, the third split decides: the names at
/// least two of the three give are the findings (`agreed`).
pub(crate) fn diagnose_checked(rec: &Record, opt: &Options, rest: Vec<bool>) -> Diagnosis {
    let mut runs: Vec<Diagnosis> = (0..2)
        .map(|s| diagnose_split(rec, opt, rest.clone(), s))
        .collect();
    if names_of(&runs[0]) != names_of(&runs[1]) {
        runs.push(diagnose_split(rec, opt, rest, 2));
    }
    agreed(runs)
}

/// The selection on the training / held-out split `split` (`holdout_mask`): run once; where
/// its findings leave a smooth force of the speed that no catalogue effect explains (the test
/// before the confounded check), run again with that force carried by nuisance columns
/// (`SPEED_COLUMNS`), choosing among the first selection's kinds only; where its validation
/// rejects findings, run again without their kinds (`RESELECTIONS`).
fn diagnose_split(rec: &Record, opt: &Options, rest: Vec<bool>, split: usize) -> Diagnosis {
    // (the run that carries the force of the speed does not test for it again, and the last
    // run allowed gives its diagnosis whatever its validation drops: the loop ends)
    let mut again = Again {
        speed: None,
        without: Vec::new(),
        notes: Vec::new(),
        rounds_left: RESELECTIONS,
        earlier: None,
        split,
    };
    loop {
        match diagnose_with(rec, opt, rest.clone(), again) {
            Ok(d) => return d,
            Err(next) => again = next,
        }
    }
}

/// What a diagnosis names, sorted: each catalogue name, and each pair of kinds a finding is
/// confounded with (`a / b`, in name order).
fn names_of(d: &Diagnosis) -> Vec<String> {
    let mut names: Vec<String> = d
        .findings
        .iter()
        .filter(|f| f.effect != "unexplained")
        .map(|f| match &f.confounded_with {
            Some(o) => {
                let mut p = [f.effect.as_str(), o.as_str()];
                p.sort_unstable();
                format!("{} / {}", p[0], p[1])
            }
            None => f.effect.clone(),
        })
        .collect();
    names.sort();
    names
}

/// The diagnosis the runs on the splits agree on: the names most of them give (a finding is
/// kept when most splits' selections keep it, as a term is in an ensemble of sparse
/// regressions on resampled data; two runs that name the same effects are a majority of
/// three whatever the third names, so it is made only where they differ). The run reported
/// is the one whose names differ least from those (the earliest split of the runs that
/// differ as little), its verdicts saying how often each name was given.
fn agreed(runs: Vec<Diagnosis>) -> Diagnosis {
    let names: Vec<Vec<String>> = runs.iter().map(names_of).collect();
    let mut all: Vec<&String> = names.iter().flatten().collect();
    all.sort();
    all.dedup();
    let count = |n: &String| names.iter().filter(|r| r.contains(n)).count();
    let kept: Vec<&String> = all
        .iter()
        .copied()
        .filter(|n| 2 * count(n) > runs.len())
        .collect();
    let differ = |r: &Vec<String>| {
        r.iter().filter(|n| !kept.contains(n)).count()
            + kept.iter().filter(|n| !r.contains(n)).count()
    };
    let pick = (0..runs.len())
        .min_by_key(|&i| differ(&names[i]))
        .unwrap_or(0);
    let blocks = (0..runs.len())
        .map(|s| format!("blocks {}", split_blocks(s)))
        .collect::<Vec<_>>()
        .join(" / ");
    let verdict = if runs.len() == 2 {
        format!(
            "the selection on two training / held-out splits of the record (held out: {blocks} \
             of 10) named the same effects on both: the findings are those"
        )
    } else {
        let tally = all
            .iter()
            .map(|n| format!("{n} on {} of {}", count(n), runs.len()))
            .collect::<Vec<_>>()
            .join(", ");
        format!(
            "the selection on two training / held-out splits of the record named different \
             effects, so a third decided (held out: {blocks} of 10): {tally}; reported: the run \
             holding out blocks {} of 10, {}",
            split_blocks(pick),
            if differ(&names[pick]) == 0 {
                "whose findings are those named on most splits"
            } else {
                "whose findings differ least from those named on most splits (no split named \
                 exactly those)"
            }
        )
    };
    let mut d = runs.into_iter().nth(pick).unwrap_or_default();
    d.verdicts.push(verdict);
    d
}

/// Times the selection runs again without the kinds its validation did not keep. A finding
/// the validation rejects (not stable across the record's segments, not apart from another
/// derivation of the motion, from a hum or from a locked ripple) was chosen over the other
/// candidates on the screening window; the candidates it displaced were never weighed
/// without it. So the selection runs again among the kinds not rejected, each of whose
/// findings faces the same validation; the rejected ones' verdicts are kept for the report.
/// Where a run's validation rejects a kind that the run before it kept, the two validations
/// disagree on a finding, and the run before it stands: a run without a rejected kind can
/// lose what that kind's columns held apart from a finding that was kept. (A run that does
/// not choose a kept kind again is given: its selection weighed that kind and preferred
/// others.)
pub const RESELECTIONS: usize = 2;

/// What a run of the selection is given by the runs before it.
pub(crate) struct Again {
    /// The kinds chosen by the run that found a force of the speed beside them: the selection
    /// runs among them with that force carried (`speed_columns`).
    pub(crate) speed: Option<Vec<EffectKind>>,
    /// The kinds the validation of an earlier run did not keep.
    pub(crate) without: Vec<EffectKind>,
    /// Those runs' verdicts on the findings not kept.
    pub(crate) notes: Vec<String>,
    /// Runs without the rejected kinds still allowed.
    pub(crate) rounds_left: usize,
    /// The run before's diagnosis (its `effects` the findings its validation kept).
    pub(crate) earlier: Option<Box<Diagnosis>>,
    /// The training / held-out split the runs are made on (`holdout_mask`).
    pub(crate) split: usize,
}

impl Again {
    /// The run before, where this run's validation rejected a kind (of `rejected`, of the
    /// kinds `chosen` this run chose) that the run before kept: the two validations disagree,
    /// and the run before stands, its verdicts saying so. None otherwise (and then, or when
    /// there was no run before, this run is given).
    pub(crate) fn earlier_standing(
        &mut self,
        chosen: &[EffectKind],
        rejected: &[EffectKind],
    ) -> Option<Diagnosis> {
        let mut d = self.earlier.take()?;
        let disputed: Vec<EffectKind> = rejected
            .iter()
            .copied()
            .filter(|k| d.effects.iter().any(|e| e.kind == *k))
            .collect();
        if disputed.is_empty() {
            return None;
        }
        d.verdicts.push(format!(
            "run again, the selection chose {}, but that run's validation rejected {}, which \
             the validation of the run reported here kept: the two validations disagree, so \
             the findings of the run reported here stand, and {} {} less sure than {} \
             evidence says",
            kind_list(chosen),
            kind_list(&disputed),
            kind_list(&disputed),
            if disputed.len() > 1 { "are" } else { "is" },
            if disputed.len() > 1 { "their" } else { "its" }
        ));
        Some(*d)
    }
}

/// The verdict that the selection runs again without the kinds `rejected` (said before the
/// run's diagnosis is concluded, so that it says it whether the run again is given or this
/// one stands).
pub(crate) fn rerun_note(rejected: &[EffectKind]) -> String {
    format!(
        "the selection ran again without {} (not kept above), among the other candidates",
        kind_list(rejected)
    )
}

/// Kinds' names joined for a verdict (each verdict names at least one: a rejected kind is one
/// its run chose).
fn kind_list(kinds: &[EffectKind]) -> String {
    kinds
        .iter()
        .map(|k| k.name())
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A diagnosis on split `split` naming `names` (`a / b` a finding confounded with b), with a
    /// residual left unexplained when `unexplained`.
    fn run(split: usize, names: &[&str], unexplained: bool) -> Diagnosis {
        let mut findings: Vec<Finding> = names
            .iter()
            .map(|n| match n.split_once(" / ") {
                Some((a, b)) => Finding {
                    effect: a.into(),
                    confounded_with: Some(b.into()),
                    ..Default::default()
                },
                None => Finding {
                    effect: n.to_string(),
                    ..Default::default()
                },
            })
            .collect();
        if unexplained {
            findings.push(Finding {
                effect: "unexplained".into(),
                ..Default::default()
            });
        }
        Diagnosis {
            split,
            findings,
            ..Default::default()
        }
    }

    #[test]
    fn two_splits_that_agree_are_the_findings() {
        let d = agreed(vec![run(0, &["b", "a"], true), run(1, &["a", "b"], false)]);
        assert_eq!(
            (d.split, names_of(&d)),
            (0, vec!["a".to_string(), "b".into()])
        );
        assert!(d
            .verdicts
            .last()
            .unwrap()
            .contains("named the same effects"));
    }

    #[test]
    fn the_majority_of_three_is_kept_and_its_run_reported() {
        // the first split adds a name the other two do not give: the run without it is reported
        let d = agreed(vec![
            run(0, &["a", "c"], false),
            run(1, &["a"], true),
            run(2, &["a"], false),
        ]);
        assert_eq!((d.split, names_of(&d)), (1, vec!["a".to_string()]));
        let v = d.verdicts.last().unwrap();
        assert!(v.contains("a on 3 of 3, c on 1 of 3"), "{v}");
        assert!(
            v.contains("holding out blocks 1, 4, 7 of 10, whose findings are those"),
            "{v}"
        );
        // a name two of three give is kept though the first split misses it
        let d = agreed(vec![
            run(0, &[], true),
            run(1, &["clip"], true),
            run(2, &["clip"], true),
        ]);
        assert_eq!((d.split, names_of(&d)), (1, vec!["clip".to_string()]));
        // a confounded pair is one name whichever kind its finding is
        let d = agreed(vec![
            run(0, &["p / q"], false),
            run(1, &["q / p"], false),
            run(2, &["q"], false),
        ]);
        assert_eq!((d.split, names_of(&d)), (0, vec!["p / q".to_string()]));
    }

    #[test]
    fn no_split_naming_the_majority_reports_the_nearest() {
        // kept: a and b (two of three each); no run names exactly those, each differs by one,
        // so the earliest is reported and the verdict says so
        let d = agreed(vec![
            run(0, &["a"], false),
            run(1, &["a", "b", "c"], false),
            run(2, &["b"], false),
        ]);
        assert_eq!(d.split, 0);
        let v = d.verdicts.last().unwrap();
        assert!(v.contains("no split named exactly those"), "{v}");
        // three splits that name nothing in common keep nothing: the nearest run names least
        let d = agreed(vec![
            run(0, &["a", "b"], false),
            run(1, &["c"], false),
            run(2, &["d"], false),
        ]);
        assert_eq!(d.split, 1);
    }
}
