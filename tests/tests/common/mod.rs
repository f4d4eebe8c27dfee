//! What several diagnosis test files check the same way (`mod common;` in each).
use hal_sim::diagnose::effects::EffectKind;
use hal_sim::diagnose::Diagnosis;

/// Whether the diagnosis names a ripple locked to position (`cogging` or
/// `position_periodic_friction`), at any wavelength.
pub fn names_a_periodic_effect(d: &Diagnosis) -> bool {
    d.effects.iter().any(|e| {
        matches!(
            e.kind,
            EffectKind::Cogging | EffectKind::PositionPeriodicFriction
        )
    })
}

/// Whether the diagnosis names `cogging` within 1 % of the wavelength `lambda` (m).
pub fn names_cogging_at(d: &Diagnosis, lambda: f64) -> bool {
    d.effects
        .iter()
        .any(|e| e.kind == EffectKind::Cogging && (e.param / lambda - 1.0).abs() < 0.01)
}
