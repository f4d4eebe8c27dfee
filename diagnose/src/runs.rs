//! The runs of the selection (`selection`): again with a force of the speed carried, and
//! again without the kinds a run's validation rejected.

use super::*;

/// The diagnosis of a checked record: the selection run once; where its findings leave a
/// smooth force of the speed that no catalogue effect explains (the test before the
/// confounded check), run again with that force carried by nuisance columns
/// (`SPEED_COLUMNS`), choosing among the first selection's kinds only; where its validation
/// rejects findings, run again without their kinds (`RESELECTIONS`).
pub(crate) fn diagnose_checked(rec: &Record, opt: &Options, rest: Vec<bool>) -> Diagnosis {
    // (the run that carries the force of the speed does not test for it again, and the last
    // run allowed gives its diagnosis whatever its validation drops: the loop ends)
    let mut again = Again {
        speed: None,
        without: Vec::new(),
        notes: Vec::new(),
        rounds_left: RESELECTIONS,
        earlier: None,
    };
    loop {
        match diagnose_with(rec, opt, rest.clone(), again) {
            Ok(d) => return d,
            Err(next) => again = next,
        }
    }
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
