//! The bench rig's seed ranges and the records they draw, shared by the rig's evaluation
//! (`diagnose_rig.rs`) and its tools (`diagnose_rig_tools.rs`).
#![allow(dead_code)]

use hal_sim::bench_rig::{Hidden, RigSpec, Trajectory};
use std::ops::Range;

/// The tuning range of rig seeds: the classic long run's (1 + 100,000·kind + j), the widened
/// rig's tuning records (`WIDE_TUNING_BASE` + 100,000·kind + j) and the tools' `RIG_SEEDS`.
pub const TUNING: Range<u64> = 1..100_000_000;
/// The held-out range of rig seeds: the classic rig's (`CLASSIC_HELD_OUT_BASE` +
/// 1,000,000·kind + j) and the widened rig's (`WIDE_HELD_OUT_BASE` + 1,000,000·kind + j).
pub const HELD_OUT: Range<u64> = 1_000_000_000..2_000_000_000;
// the ranges do not overlap (checked when the file compiles)
const _: () = assert!(TUNING.end <= HELD_OUT.start);
pub const CLASSIC_TUNING_BASE: u64 = 1;
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
    let kind = Hidden::KINDS[((seed - 1) / 100_000) as usize];
    let j = ((seed - 1) % 100_000) as usize;
    RigSpec::random(seed, kind, trajectory(j, emps, 12_000), 12_000)
}

/// The seeds listed in `RIG_SEEDS` (comma-separated).
pub fn env_seeds() -> Vec<u64> {
    std::env::var("RIG_SEEDS")
        .unwrap_or_default()
        .split(',')
        .filter_map(|s| s.trim().parse().ok())
        .collect()
}
