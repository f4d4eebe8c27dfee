//! The bench rig's seed ranges and the records they draw, shared by the rig's evaluation
//! (`diagnose_rig.rs`) and its tools (`diagnose_rig_tools.rs`).
#![allow(dead_code)]

use hal_sim::bench_rig::{Hidden, RigSpec, Trajectory};
use std::fmt::Display;
use std::ops::{Range, RangeInclusive};
use std::str::FromStr;

/// The tuning range of rig seeds: the classic long run's (1 + 100,000·kind + j), the widened
/// rig's tuning records (`WIDE_TUNING_BASE` + 100,000·kind + j) and the tools' `RIG_SEEDS`.
pub const TUNING: Range<u64> = 1..100_000_000;
/// The held-out range of rig seeds: the classic rig's (`CLASSIC_HELD_OUT_BASE` +
/// 1,000,000·kind + j) and the widened rig's (`WIDE_HELD_OUT_BASE` + 1,000,000·kind + j).
pub const HELD_OUT: Range<u64> = 1_000_000_000..2_000_000_000;
// the ranges do not overlap (checked when the file compiles)
const _: () = assert!(TUNING.end <= HELD_OUT.start);
pub const CLASSIC_TUNING_BASE: u64 = 1;
/// Seeds a kind has in the tuning range: record j of kind k is the rig's base
/// + `TUNING_STRIDE`·k + j.
pub const TUNING_STRIDE: u64 = 100_000;
pub const WIDE_TUNING_BASE: u64 = 10_000_001;
pub const CLASSIC_HELD_OUT_BASE: u64 = 1_000_000_001;
pub const WIDE_HELD_OUT_BASE: u64 = 1_500_000_001;

/// The EMPS estimation record's measured position (the repository's `data/emps/`; a missing or
/// unreadable file fails the test with its path).
pub fn emps_x() -> Vec<f64> {
    let p = regen_tests::emps_file("emps_estimation.csv");
    hal_sim::diagnose::read_csv(&p, None)
        .unwrap_or_else(|e| panic!("EMPS record {}: {e}", p.display()))
        .x
}

/// The classic rig's trajectory of record `j` of a kind (families in turn; the recorded one is
/// EMPS's position).
pub fn trajectory(j: usize, emps: &[f64], samples: usize) -> Trajectory {
    match j % 5 {
        0 => Trajectory::Multisine,
        1 => Trajectory::RoundedTriangle,
        2 => Trajectory::PointToPoint,
        3 => Trajectory::Narrowband,
        _ => Trajectory::Recorded(emps[..samples.min(emps.len())].to_vec()),
    }
}

/// The classic long run's record of a tuning seed (1 + 100,000·kind + j, 12,000 samples): the
/// tools below take these.
pub fn long_run_spec(seed: u64, emps: &[f64]) -> RigSpec {
    assert!(TUNING.contains(&seed), "the tools take tuning seeds only");
    let kind = Hidden::KINDS[((seed - 1) / TUNING_STRIDE) as usize];
    let j = ((seed - 1) % TUNING_STRIDE) as usize;
    RigSpec::random(seed, kind, trajectory(j, emps, 12_000), 12_000)
}

/// The seeds listed in `RIG_SEEDS` (comma-separated seeds of the classic long run's tuning
/// records, which `long_run_spec` draws; none when unset). Any other entry fails the run with
/// one message naming it and the range.
pub fn env_seeds() -> Vec<u64> {
    let Some(items) = env_items("RIG_SEEDS") else {
        return Vec::new();
    };
    let seeds =
        CLASSIC_TUNING_BASE..CLASSIC_TUNING_BASE + TUNING_STRIDE * Hidden::KINDS.len() as u64;
    items
        .iter()
        .map(|s| match s.parse::<u64>() {
            Ok(seed) if seeds.contains(&seed) => seed,
            _ => panic!(
                "RIG_SEEDS entry \"{s}\": a classic tuning seed from {} to {} expected",
                seeds.start,
                seeds.end - 1
            ),
        })
        .collect()
}

/// The environment variable `key` as a number in `range`, `default` when unset. A value that
/// is not one fails the run with one message naming the key, the value and the range (a typo
/// must not run the default's records unnoticed).
pub fn env_number<T>(key: &str, default: T, range: RangeInclusive<T>) -> T
where
    T: FromStr + PartialOrd + Display,
{
    env_number_set(key, range).unwrap_or(default)
}

/// `env_number` without a default: None when `key` is unset.
pub fn env_number_set<T>(key: &str, range: RangeInclusive<T>) -> Option<T>
where
    T: FromStr + PartialOrd + Display,
{
    let v = env_text(key)?;
    match v.trim().parse::<T>() {
        Ok(x) if range.contains(&x) => Some(x),
        _ => panic!(
            "{key}=\"{v}\": a number from {} to {} expected",
            range.start(),
            range.end()
        ),
    }
}

/// The comma-separated entries of the environment variable `key`, each one of `allowed` (None
/// when unset). An entry not allowed fails the run with one message naming the key, the entry
/// and the entries allowed (a misspelt kind must not narrow the run to nothing).
pub fn env_choice(key: &str, allowed: &[&str]) -> Option<Vec<String>> {
    let items = env_items(key)?;
    for s in &items {
        if !allowed.contains(&s.as_str()) {
            panic!(
                "{key} entry \"{s}\": one of {} expected",
                allowed.join(", ")
            );
        }
    }
    Some(items)
}

/// The kinds `RIG_KINDS` narrows a run to (None when unset): each one of the widened rig's,
/// which hold the classic rig's.
pub fn env_kinds() -> Option<Vec<String>> {
    env_choice("RIG_KINDS", &Hidden::WIDE_KINDS)
}

/// The environment variable `key` (None when unset); a value that is not text fails the run.
fn env_text(key: &str) -> Option<String> {
    match std::env::var(key) {
        Ok(v) => Some(v),
        Err(std::env::VarError::NotPresent) => None,
        Err(std::env::VarError::NotUnicode(v)) => panic!("{key}={v:?}: not text"),
    }
}

/// The trimmed, non-empty comma-separated entries of `key` (None when unset).
pub fn env_items(key: &str) -> Option<Vec<String>> {
    Some(
        env_text(key)?
            .split(',')
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .map(String::from)
            .collect(),
    )
}
