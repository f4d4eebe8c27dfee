//! The effect library: one file per effect, each implementing `EffectModel`, and the registry
//! listing them. Adding an effect is a file here and a line in `REGISTRY` (with its `mod`).
//!
//! The baseline terms (inertia, viscous, Coulomb, offset, the electromagnetic force) are
//! always in the model and are reported with their significance, not searched for.

use super::*;

mod actuator_lag;
mod backlash;
mod cogging;
mod compliance;
mod current_limit;
mod direction_asymmetric_friction;
mod lag;
mod periodic;
mod position_dependent_friction;
mod position_periodic_friction;
mod presliding_hysteresis;
mod reflected_inertia;
mod screw_efficiency;
mod spring;
mod stribeck;
mod velocity_strengthening_friction;

pub use actuator_lag::{actuator_tc, ACTUATOR_LAG};
pub use backlash::BACKLASH;
pub use cogging::COGGING;
pub use compliance::COMPLIANCE;
pub use current_limit::{drive_clip, CURRENT_LIMIT};
pub use direction_asymmetric_friction::DIRECTION_ASYMMETRIC_FRICTION;
pub use lag::LAG;
pub use position_dependent_friction::POSITION_DEPENDENT_FRICTION;
pub use position_periodic_friction::POSITION_PERIODIC_FRICTION;
pub use presliding_hysteresis::PRESLIDING_HYSTERESIS;
pub use reflected_inertia::REFLECTED_INERTIA;
pub use screw_efficiency::SCREW_EFFICIENCY;
pub use spring::SPRING;
pub use stribeck::STRIBECK;
pub use velocity_strengthening_friction::VELOCITY_STRENGTHENING;

/// Every effect of the library, in the order the selection screens them.
pub static REGISTRY: [EffectKind; 15] = [
    DIRECTION_ASYMMETRIC_FRICTION,
    POSITION_DEPENDENT_FRICTION,
    POSITION_PERIODIC_FRICTION,
    COGGING,
    STRIBECK,
    SCREW_EFFICIENCY,
    LAG,
    CURRENT_LIMIT,
    REFLECTED_INERTIA,
    COMPLIANCE,
    BACKLASH,
    PRESLIDING_HYSTERESIS,
    ACTUATOR_LAG,
    VELOCITY_STRENGTHENING,
    SPRING,
];

/// `g` at `0..n`.
pub(crate) fn map(n: usize, g: impl Fn(usize) -> f64) -> Vec<f64> {
    (0..n).map(g).collect()
}

/// A gain of the whole force: 0.8 … 1.25.
pub(crate) fn unit_gain(g: f64) -> bool {
    (0.8..=1.25).contains(&g)
}

/// 21 values over ±`width` (relative) around `e`'s parameter (second parameter 0).
pub(crate) fn refine_fine(e: &Effect, width: f64) -> Vec<Effect> {
    (0..=20)
        .map(|i| Effect {
            kind: e.kind,
            param: e.param * (1.0 + width * (i as f64 / 10.0 - 1.0)),
            param2: 0.0,
        })
        .collect()
}

/// 7 values over ±`width` (relative) around `e`'s parameter (its second parameter kept): for
/// an effect whose every value costs a walk over the record.
pub(crate) fn refine_coarse(e: &Effect, width: f64) -> Vec<Effect> {
    (0..=6)
        .map(|i| Effect {
            kind: e.kind,
            param: e.param * (1.0 + width * (i as f64 / 3.0 - 1.0)),
            param2: e.param2,
        })
        .collect()
}

/// Speeds from twice the sign band to 0.3 of the peak speed (14, log-spaced).
pub(crate) fn speed_grid(ctx: &Context, kind: EffectKind) -> Vec<Effect> {
    logspace(2.0 * ctx.v_eps, 0.3 * ctx.vmax, 14)
        .into_iter()
        .map(|p| Effect::new(kind, p))
        .collect()
}

/// The displacements scanned after a reversal: from the position resolution (4 quanta; below
/// it no transition is resolved) to a tenth of the stroke.
pub(crate) fn displacement_range(ctx: &Context) -> (f64, f64) {
    let stroke = 2.0 * ctx.x_half;
    ((4.0 * ctx.x_quantum).max(stroke * 1e-6), stroke / 10.0)
}

/// 16 displacements over `displacement_range`, log-spaced (none when the range is too short).
pub(crate) fn displacement_grid(ctx: &Context, kind: EffectKind) -> Vec<Effect> {
    let (lo, hi) = displacement_range(ctx);
    if hi > 1.5 * lo {
        logspace(lo, hi, 16)
            .into_iter()
            .map(|p| Effect::new(kind, p))
            .collect()
    } else {
        vec![]
    }
}
