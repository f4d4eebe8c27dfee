//! What several diagnosis test files check the same way (`mod common;` in each).
use hal_sim::diagnose::effects;
use hal_sim::diagnose::Diagnosis;

/// Whether the diagnosis names a ripple locked to position (`cogging` or
/// `position_periodic_friction`), at any wavelength.
pub fn names_a_periodic_effect(d: &Diagnosis) -> bool {
    d.effects
        .iter()
        .any(|e| e.kind == effects::COGGING || e.kind == effects::POSITION_PERIODIC_FRICTION)
}

/// Whether the diagnosis names `cogging` within 1 % of the wavelength `lambda` (m).
pub fn names_cogging_at(d: &Diagnosis, lambda: f64) -> bool {
    d.effects
        .iter()
        .any(|e| e.kind == effects::COGGING && (e.param / lambda - 1.0).abs() < 0.01)
}
