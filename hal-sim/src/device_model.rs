//! A diagnosed device model as plant physics: the `[model]` section of a scenario (or a
//! `regen diagnose --model` fragment passed to `regen run --model`).
//!
//! The device force on an imposed motion is the baseline `M·a + Fv·v + Fc·sgn(v) + offset`
//! (sgn linear inside ±`sign_band_m_s`) with each effect the diagnosis names, as physics
//! stepped in time (docs/diagnose.md, "The loop"). Friction effects add to the friction
//! (direction-dependent viscosity, a Coulomb level varying along the stroke or periodically,
//! a Stribeck bump, a level building up with speed, Dahl presliding), `cogging` is a
//! position-periodic force, `compliance` is a mass hung on a spring-damper, and the force path
//! is then scaled when driven (`screw_efficiency`, `reflected_inertia`), interrupted across a
//! play (`backlash`), clipped (`current_limit`) and delayed (`lag`), in that order. Parameter names are the report's.
//!
//! This is the simulator's own implementation of each effect, written from its physical
//! description, not from the diagnosis's regressor columns.

use regen_physics::{PlayWalk, IMPACT_TAPS};
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::f64::consts::TAU;

/// The diagnosed device: baseline and effects, parameters named as in the report.
#[allow(non_snake_case)]
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DeviceModel {
    /// Inertia M, kg (coefficient of a).
    pub inertia_kg: f64,
    /// Viscous friction Fv, N·s/m.
    pub viscous_friction_Ns_per_m: f64,
    /// Coulomb friction Fc, N.
    pub coulomb_friction_N: f64,
    /// Force offset (sensor), N.
    #[serde(default)]
    pub force_offset_N: f64,
    /// Speed inside which the Coulomb sign is linear, m/s.
    pub sign_band_m_s: f64,
    /// Effects, in the order the diagnosis found them.
    #[serde(default, rename = "effect")]
    pub effects: Vec<ModelEffect>,
}

/// One effect of the catalogue as physics (field names are the report's parameter names).
#[allow(non_snake_case)]
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(tag = "name", rename_all = "snake_case", deny_unknown_fields)]
pub enum ModelEffect {
    /// Viscous friction differing by direction (the Coulomb levels restate the baseline:
    /// `coulomb ± offset`, checked).
    DirectionAsymmetricFriction {
        viscous_pos_Ns_per_m: f64,
        viscous_neg_Ns_per_m: f64,
        coulomb_pos_N: f64,
        coulomb_neg_N: f64,
    },
    /// Coulomb level `Fc + s·(x − x_mid) + c·(x − x_mid)²`.
    PositionDependentFriction {
        coulomb_slope_N_per_m: f64,
        coulomb_curvature_N_per_m2: f64,
        x_mid_m: f64,
    },
    /// Coulomb level modulated by `A·sin(2πx/λ + φ)`.
    PositionPeriodicFriction {
        wavelength_m: f64,
        amplitude_N: f64,
        phase_rad: f64,
    },
    /// Direction-independent force `A·sin(2πx/λ + φ)`.
    Cogging {
        wavelength_m: f64,
        amplitude_N: f64,
        phase_rad: f64,
    },
    /// Extra friction at low speed `A·sgn(v)·exp(−(v/vs)²)`.
    Stribeck {
        stribeck_velocity_m_s: f64,
        amplitude_N: f64,
    },
    /// Friction building up with speed (velocity strengthening): the Coulomb level rises by
    /// `friction_rise_N` over the speed `buildup_velocity_m_s`, `ΔF·(1 − exp(−|v|/v_b))·sgn v`.
    VelocityStrengtheningFriction {
        buildup_velocity_m_s: f64,
        friction_rise_N: f64,
    },
    /// The force is multiplied by this ratio while the device is driven (f·v > 0).
    ScrewEfficiency {
        driven_over_driving_force_ratio: f64,
    },
    /// Extra inertia while the device is driven.
    ReflectedInertia { extra_driven_inertia_kg: f64 },
    /// The force is seen `lag_s` late (gain: the fraction of the force delayed).
    Lag { lag_s: f64, gain: f64 },
    /// The drive's force is clipped at ±`limit_N`. With `drive_damping_Ns_per_m` = 0 the drive
    /// produces the whole force (a motor-driven axis; gain: the fraction clipped); with
    /// `drive_damping_Ns_per_m` = c_d > 0 the drive acts as a damper on an imposed motion and
    /// its force c_d·v (part of the viscous term) is what saturates.
    CurrentLimit {
        limit_N: f64,
        #[serde(default = "one")]
        gain: f64,
        #[serde(default)]
        drive_damping_Ns_per_m: f64,
    },
    /// A mass hung on the device through a spring-damper (resonance, damping ratio); its
    /// rigid-body part is in the baseline inertia.
    Compliance {
        resonance_Hz: f64,
        modal_mass_kg: f64,
        damping_ratio: f64,
    },
    /// Play of total width between the motion and the device (the diagnosis's physics,
    /// `regen_physics::PlayWalk`, one implementation): the device (`device_*`, the model's inertia
    /// and friction when absent) moves with a flank while the flank pushes it, leaves it and
    /// coasts (viscous decay, Coulomb deceleration) when the motion decelerates faster, and
    /// carries no force off both flanks (`gain` of its force removed; the offset, a sensor
    /// property, stays); where a flank catches it up it is struck into the motion's velocity:
    /// the force pulse `impact_pulse_kg` per unit relative velocity (v − v_m), tap k the
    /// momentum share of the k-th `impact_tap_s` after the contact, linear between the taps'
    /// centres, as the diagnosis fitted it; without a pulse, the impulse `impact_mass_kg`·(v −
    /// v_m) (M·(v − v_m) without it) within one step.
    Backlash {
        width_m: f64,
        /// The contact's restitution (0 when absent: the flank carries the device on).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        restitution: Option<f64>,
        /// A compliant flank's contact mode with the device's inertia, Hz (absent: a rigid
        /// flank; `PlayWalk::with_contact_hz`): the force it carries at a reversal unloads
        /// through its spring.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        contact_Hz: Option<f64>,
        gain: f64,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        impact_mass_kg: Option<f64>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        device_inertia_kg: Option<f64>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        device_viscous_Ns_per_m: Option<f64>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        device_coulomb_N: Option<f64>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        impact_pulse_kg: Option<[f64; IMPACT_TAPS]>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        impact_tap_s: Option<f64>,
    },
    /// Dahl friction: the Coulomb force builds up over the characteristic displacement after
    /// each reversal instead of switching with the sign of v.
    PreslidingHysteresis {
        characteristic_displacement_m: f64,
        friction_N: f64,
    },
    /// A force proportional to the displacement from a reference position,
    /// `k·(x − x_ref)` (the force at the reference is the baseline's offset).
    Spring {
        stiffness_N_per_m: f64,
        reference_position_m: f64,
    },
}

fn one() -> f64 {
    1.0
}

/// `key = value` in [lo, hi], or the message naming the key, the value and the range.
fn range(key: &str, v: f64, lo: f64, hi: f64, unit: &str) -> Result<(), String> {
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(())
    } else {
        Err(format!(
            "model.{key} = {v}: allowed range [{lo:e}, {hi:e}] {unit}"
        ))
    }
}

impl ModelEffect {
    pub fn name(&self) -> &'static str {
        match self {
            ModelEffect::DirectionAsymmetricFriction { .. } => "direction_asymmetric_friction",
            ModelEffect::PositionDependentFriction { .. } => "position_dependent_friction",
            ModelEffect::PositionPeriodicFriction { .. } => "position_periodic_friction",
            ModelEffect::Cogging { .. } => "cogging",
            ModelEffect::Stribeck { .. } => "stribeck",
            ModelEffect::VelocityStrengtheningFriction { .. } => "velocity_strengthening_friction",
            ModelEffect::ScrewEfficiency { .. } => "screw_efficiency",
            ModelEffect::ReflectedInertia { .. } => "reflected_inertia",
            ModelEffect::Lag { .. } => "lag",
            ModelEffect::CurrentLimit { .. } => "current_limit",
            ModelEffect::Compliance { .. } => "compliance",
            ModelEffect::Backlash { .. } => "backlash",
            ModelEffect::PreslidingHysteresis { .. } => "presliding_hysteresis",
            ModelEffect::Spring { .. } => "spring",
        }
    }

    fn check(&self, i: usize, m: &DeviceModel) -> Result<(), String> {
        let k = |f: &str| format!("effect[{i}] ({}).{f}", self.name());
        const F: f64 = 1e7; // the reader's force bound, N
        match *self {
            ModelEffect::DirectionAsymmetricFriction {
                viscous_pos_Ns_per_m: p,
                viscous_neg_Ns_per_m: n,
                coulomb_pos_N: cp,
                coulomb_neg_N: cn,
            } => {
                range(&k("viscous_pos_Ns_per_m"), p, 0.0, 1e9, "N·s/m")?;
                range(&k("viscous_neg_Ns_per_m"), n, 0.0, 1e9, "N·s/m")?;
                let (fc, off) = (m.coulomb_friction_N, m.force_offset_N);
                let tol = 1e-9 * (fc.abs() + off.abs()) + 1e-12;
                for (key, v, want) in [
                    ("coulomb_pos_N", cp, fc + off),
                    ("coulomb_neg_N", cn, fc - off),
                ] {
                    if (v - want).abs().is_nan() || (v - want).abs() > tol {
                        return Err(format!(
                            "model.{} = {v}: must restate the baseline, coulomb_friction_N {} offset force_offset_N = {want}",
                            k(key),
                            if key == "coulomb_pos_N" { "+" } else { "−" }
                        ));
                    }
                }
            }
            ModelEffect::PositionDependentFriction {
                coulomb_slope_N_per_m: s,
                coulomb_curvature_N_per_m2: c,
                x_mid_m: x,
            } => {
                range(&k("coulomb_slope_N_per_m"), s, -1e9, 1e9, "N/m")?;
                range(&k("coulomb_curvature_N_per_m2"), c, -1e12, 1e12, "N/m²")?;
                range(&k("x_mid_m"), x, -10.0, 10.0, "m")?;
            }
            ModelEffect::PositionPeriodicFriction {
                wavelength_m: l,
                amplitude_N: a,
                phase_rad: p,
            }
            | ModelEffect::Cogging {
                wavelength_m: l,
                amplitude_N: a,
                phase_rad: p,
            } => {
                range(&k("wavelength_m"), l, 1e-7, 20.0, "m")?;
                range(&k("amplitude_N"), a, 0.0, F, "N")?;
                range(&k("phase_rad"), p, -10.0, 10.0, "rad")?;
            }
            ModelEffect::Stribeck {
                stribeck_velocity_m_s: vs,
                amplitude_N: a,
            } => {
                range(&k("stribeck_velocity_m_s"), vs, 1e-9, 20.0, "m/s")?;
                range(&k("amplitude_N"), a, 0.0, F, "N")?;
            }
            ModelEffect::VelocityStrengtheningFriction {
                buildup_velocity_m_s: vb,
                friction_rise_N: df,
            } => {
                range(&k("buildup_velocity_m_s"), vb, 1e-9, 20.0, "m/s")?;
                range(&k("friction_rise_N"), df, 0.0, F, "N")?;
            }
            ModelEffect::ScrewEfficiency {
                driven_over_driving_force_ratio: r,
            } => range(&k("driven_over_driving_force_ratio"), r, 0.0, 10.0, "")?,
            ModelEffect::ReflectedInertia {
                extra_driven_inertia_kg: j,
            } => range(&k("extra_driven_inertia_kg"), j, 0.0, 1e7, "kg")?,
            ModelEffect::Lag { lag_s, gain } => {
                range(&k("lag_s"), lag_s, 0.0, 10.0, "s")?;
                range(&k("gain"), gain, 0.0, 2.0, "")?;
            }
            ModelEffect::CurrentLimit {
                limit_N,
                gain,
                drive_damping_Ns_per_m: cd,
            } => {
                range(&k("limit_N"), limit_N, 0.0, F, "N")?;
                range(&k("gain"), gain, 0.0, 2.0, "")?;
                range(
                    &k("drive_damping_Ns_per_m"),
                    cd,
                    0.0,
                    m.viscous_friction_Ns_per_m,
                    "N·s/m (at most the viscous_friction_Ns_per_m that carries it)",
                )?;
            }
            ModelEffect::Compliance {
                resonance_Hz: f,
                modal_mass_kg: m2,
                damping_ratio: z,
            } => {
                range(&k("resonance_Hz"), f, 1e-3, 1e4, "Hz")?;
                range(&k("modal_mass_kg"), m2, 0.0, 1e7, "kg")?;
                range(&k("damping_ratio"), z, 0.0, 10.0, "")?;
            }
            ModelEffect::Backlash {
                width_m,
                restitution,
                contact_Hz,
                gain,
                impact_mass_kg,
                device_inertia_kg,
                device_viscous_Ns_per_m,
                device_coulomb_N,
                impact_pulse_kg,
                impact_tap_s,
            } => {
                range(&k("width_m"), width_m, 0.0, 1.0, "m")?;
                if let Some(e) = restitution {
                    range(&k("restitution"), e, 0.0, 0.999, "")?;
                }
                if let Some(hz) = contact_Hz {
                    range(&k("contact_Hz"), hz, 1e-3, 1e7, "Hz")?;
                }
                range(&k("gain"), gain, 0.0, 2.0, "")?;
                if let Some(mi) = impact_mass_kg {
                    range(&k("impact_mass_kg"), mi, 0.0, 1e7, "kg")?;
                }
                for (key, val, hi, unit) in [
                    ("device_inertia_kg", device_inertia_kg, 1e7, "kg"),
                    (
                        "device_viscous_Ns_per_m",
                        device_viscous_Ns_per_m,
                        1e9,
                        "N·s/m",
                    ),
                    ("device_coulomb_N", device_coulomb_N, F, "N"),
                    ("impact_tap_s", impact_tap_s, 1.0, "s"),
                ] {
                    if let Some(x) = val {
                        range(&k(key), x, 0.0, hi, unit)?;
                    }
                }
                if let Some(p) = impact_pulse_kg {
                    for (j, x) in p.iter().enumerate() {
                        range(&k(&format!("impact_pulse_kg[{j}]")), *x, -1e7, 1e7, "kg")?;
                    }
                    if impact_tap_s.is_none() {
                        return Err(format!(
                            "{}: impact_pulse_kg needs impact_tap_s (the taps' period, s)",
                            k("impact_pulse_kg")
                        ));
                    }
                }
            }
            ModelEffect::PreslidingHysteresis {
                characteristic_displacement_m: xc,
                friction_N: f,
            } => {
                range(&k("characteristic_displacement_m"), xc, 1e-9, 1.0, "m")?;
                range(&k("friction_N"), f, 0.0, F, "N")?;
            }
            ModelEffect::Spring {
                stiffness_N_per_m: st,
                reference_position_m: x0,
            } => {
                range(&k("stiffness_N_per_m"), st, 0.0, 1e12, "N/m")?;
                range(&k("reference_position_m"), x0, -1e3, 1e3, "m")?;
            }
        }
        Ok(())
    }
}

/// A model fragment file: one `[model]` table (what `regen diagnose --model` writes).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Fragment {
    pub model: DeviceModel,
}

impl Fragment {
    /// Parse a fragment; errors name the key (and the line for TOML errors), the value and
    /// the allowed range.
    pub fn from_toml(text: &str) -> Result<Fragment, String> {
        let f: Fragment = toml::from_str(text).map_err(|e| {
            let line = e
                .span()
                .map(|s| text[..s.start.min(text.len())].lines().count().max(1));
            match line {
                Some(l) => format!("line {l}: {}", e.message()),
                None => e.message().to_string(),
            }
        })?;
        f.model.check()?;
        Ok(f)
    }
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_default()
    }
}

impl DeviceModel {
    /// Every value finite and in its physical range (inertia and friction non-negative).
    pub fn check(&self) -> Result<(), String> {
        range("inertia_kg", self.inertia_kg, 0.0, 1e7, "kg")?;
        range(
            "viscous_friction_Ns_per_m",
            self.viscous_friction_Ns_per_m,
            0.0,
            1e9,
            "N·s/m",
        )?;
        range("coulomb_friction_N", self.coulomb_friction_N, 0.0, 1e7, "N")?;
        range("force_offset_N", self.force_offset_N, -1e7, 1e7, "N")?;
        range("sign_band_m_s", self.sign_band_m_s, 1e-12, 20.0, "m/s")?;
        for (i, e) in self.effects.iter().enumerate() {
            e.check(i, self)?;
        }
        Ok(())
    }

    /// The model without the effect at `index` (the loop test's counter-check).
    pub fn without(&self, index: usize) -> DeviceModel {
        let mut m = self.clone();
        if index < m.effects.len() {
            m.effects.remove(index);
        }
        m
    }

    /// Device force along a whole trajectory sampled every `dt` (x, v, a per sample).
    pub fn force_series(&self, dt: f64, x: &[f64], v: &[f64], a: &[f64]) -> Vec<f64> {
        let n = x.len().min(v.len()).min(a.len());
        if n == 0 {
            return Vec::new();
        }
        let mut st = ModelState::new(self, dt, x[0], v[0]);
        (0..n).map(|i| st.step(x[i], v[i], a[i])).collect()
    }
}

/// The state of a [`DeviceModel`] stepped at a fixed period.
#[derive(Clone, Debug)]
pub struct ModelState {
    m: DeviceModel,
    dt: f64,
    /// Per effect: resonator (y, ẏ), the device behind a play, Dahl state, lag buffer.
    y: Vec<(f64, f64)>,
    play: Vec<Option<PlayWalk>>,
    /// Per effect: the play's impact pulses in progress (time since the contact, relative
    /// velocity), added: a rebounding device is struck again before a pulse has ended.
    pulse: Vec<Vec<(f64, f64)>>,
    dahl: Vec<(f64, f64)>,
    lag: Vec<(usize, VecDeque<f64>)>,
}

impl ModelState {
    /// State at rest at position `x0` moving at `v0` (the hung mass with it, the play
    /// centred, the Dahl state 0), stepped every `dt` seconds.
    pub fn new(m: &DeviceModel, dt: f64, x0: f64, v0: f64) -> Self {
        let ne = m.effects.len();
        ModelState {
            m: m.clone(),
            dt,
            y: vec![(x0, v0); ne],
            play: m
                .effects
                .iter()
                .map(|e| match *e {
                    ModelEffect::Backlash {
                        width_m,
                        restitution,
                        contact_Hz,
                        device_inertia_kg: mi,
                        device_viscous_Ns_per_m: fv,
                        device_coulomb_N: fc,
                        ..
                    } => Some(
                        PlayWalk::new(
                            width_m,
                            mi.unwrap_or(m.inertia_kg),
                            fv.unwrap_or(m.viscous_friction_Ns_per_m),
                            fc.unwrap_or(m.coulomb_friction_N),
                            dt,
                        )
                        .with_restitution(restitution.unwrap_or(0.0))
                        .with_contact_hz(contact_Hz.unwrap_or(0.0)),
                    ),
                    _ => None,
                })
                .collect(),
            pulse: vec![Vec::new(); ne],
            dahl: vec![(0.0, x0); ne],
            lag: m
                .effects
                .iter()
                .map(|e| match e {
                    ModelEffect::Lag { lag_s, .. } => {
                        let k = (lag_s / dt).round().max(0.0) as usize;
                        (k, VecDeque::with_capacity(k + 1))
                    }
                    _ => (0, VecDeque::new()),
                })
                .collect(),
        }
    }

    /// Device force at the next sample (position x, velocity v, acceleration a).
    pub fn step(&mut self, x: f64, v: f64, a: f64) -> f64 {
        self.step_kin(x, v, v, a)
    }

    /// [`ModelState::step`] with the velocity `v_kin` the play's device walks with `a` (the
    /// velocity through the acceleration's band, where `v` came through a wider one:
    /// `Motion::Recorded`'s `v_kin_m_s`, the diagnosis's `Context::v_with_a`).
    pub fn step_kin(&mut self, x: f64, v: f64, v_kin: f64, a: f64) -> f64 {
        let m = &self.m;
        let sg = (v / m.sign_band_m_s).clamp(-1.0, 1.0);
        let mut viscous = m.viscous_friction_Ns_per_m * v;
        let mut coulomb = m.coulomb_friction_N * sg;
        let mut other = m.inertia_kg * a;
        // friction and position effects, and the hung masses
        for (i, e) in m.effects.iter().enumerate() {
            match *e {
                ModelEffect::DirectionAsymmetricFriction {
                    viscous_pos_Ns_per_m: p,
                    viscous_neg_Ns_per_m: n,
                    ..
                } => viscous = if v >= 0.0 { p * v } else { n * v },
                ModelEffect::PositionDependentFriction {
                    coulomb_slope_N_per_m: s,
                    coulomb_curvature_N_per_m2: c,
                    x_mid_m,
                } => {
                    let d = x - x_mid_m;
                    coulomb += (s * d + c * d * d) * sg;
                }
                ModelEffect::PositionPeriodicFriction {
                    wavelength_m,
                    amplitude_N,
                    phase_rad,
                } => coulomb += amplitude_N * (TAU * x / wavelength_m + phase_rad).sin() * sg,
                ModelEffect::Cogging {
                    wavelength_m,
                    amplitude_N,
                    phase_rad,
                } => other += amplitude_N * (TAU * x / wavelength_m + phase_rad).sin(),
                ModelEffect::Spring {
                    stiffness_N_per_m,
                    reference_position_m,
                } => other += stiffness_N_per_m * (x - reference_position_m),
                ModelEffect::Stribeck {
                    stribeck_velocity_m_s: vs,
                    amplitude_N,
                } => coulomb += amplitude_N * sg * (-(v / vs).powi(2)).exp(),
                ModelEffect::VelocityStrengtheningFriction {
                    buildup_velocity_m_s: vb,
                    friction_rise_N,
                } => coulomb += friction_rise_N * sg * (1.0 - (-v.abs() / vb).exp()),
                ModelEffect::PreslidingHysteresis {
                    characteristic_displacement_m: xc,
                    friction_N,
                } => {
                    // Dahl: dz/dx = (1 − z·sgn dx)/x_c, exact over each step
                    let (z, xp) = &mut self.dahl[i];
                    let dx = x - *xp;
                    *xp = x;
                    if dx != 0.0 {
                        let s = dx.signum();
                        *z = s + (*z - s) * (-dx.abs() / xc).exp();
                    }
                    // the friction it carries follows z instead of sgn v
                    coulomb += friction_N * (*z - sg);
                }
                ModelEffect::CurrentLimit {
                    limit_N,
                    gain,
                    drive_damping_Ns_per_m: cd,
                } if cd > 0.0 => {
                    // the drive acts as a damper: its force c_d·v, carried by the viscous term,
                    // saturates at ±limit_N
                    other += gain * ((cd * v).clamp(-limit_N, limit_N) - cd * v);
                }
                ModelEffect::Compliance {
                    resonance_Hz,
                    modal_mass_kg: m2,
                    damping_ratio: z,
                } => {
                    // m2·ÿ = k2·(x − y) + c2·(v − ẏ) (semi-implicit Euler); the device
                    // carries that force, of which m2·a is already in the baseline inertia
                    let w = TAU * resonance_Hz;
                    let (y, yd) = &mut self.y[i];
                    let fs = m2 * w * w * (x - *y) + 2.0 * z * m2 * w * (v - *yd);
                    if m2 > 0.0 {
                        *yd += fs / m2 * self.dt;
                        *y += *yd * self.dt;
                    }
                    other += fs - m2 * a;
                }
                _ => {}
            }
        }
        let mut f = other + viscous + coulomb + m.force_offset_N;
        // the force path: efficiency, play, clip, delay
        for (i, e) in m.effects.iter().enumerate() {
            match *e {
                ModelEffect::ScrewEfficiency {
                    driven_over_driving_force_ratio: r,
                } if f * v > 0.0 => f *= r,
                ModelEffect::ReflectedInertia {
                    extra_driven_inertia_kg: j,
                } if f * v > 0.0 => f += j * a,
                ModelEffect::Backlash {
                    gain,
                    impact_mass_kg,
                    impact_pulse_kg,
                    impact_tap_s,
                    ..
                } => {
                    let Some(walk) = self.play[i].as_mut() else {
                        continue;
                    };
                    let (free, impact) = walk.step(x, v_kin, a, sg);
                    if free {
                        // the force a compliant flank's spring still carries in its place
                        f += gain * (m.force_offset_N - f + walk.spring);
                    }
                    let dt = self.dt;
                    let pulses = &mut self.pulse[i];
                    if let Some((since, v_rel)) = impact {
                        if v_rel != 0.0 {
                            pulses.push((since * dt, v_rel));
                        }
                    }
                    match (impact_pulse_kg, impact_tap_s) {
                        (Some(taps), Some(tap)) if tap > 0.0 => {
                            // the pulse the diagnosis fitted: tap k stands for the force
                            // k + ½ taps after the contact (held at tap 0 before it), linear
                            // between the taps' centres
                            let c = |k: usize| taps.get(k).copied().unwrap_or(0.0);
                            pulses.retain_mut(|(t, vr)| {
                                let u = (*t / tap - 0.5).max(0.0);
                                let k0 = u.floor() as usize;
                                let al = u - k0 as f64;
                                if k0 >= IMPACT_TAPS {
                                    return false;
                                }
                                f += *vr / tap * (c(k0) * (1.0 - al) + c(k0 + 1) * al);
                                *t += dt;
                                true
                            });
                        }
                        _ => {
                            // struck into the motion's velocity within this step
                            for (_, vr) in pulses.drain(..) {
                                f += impact_mass_kg.unwrap_or(gain * m.inertia_kg) * vr / dt;
                            }
                        }
                    }
                }
                ModelEffect::CurrentLimit {
                    limit_N,
                    gain,
                    drive_damping_Ns_per_m,
                } if drive_damping_Ns_per_m <= 0.0 => {
                    f += gain * (f.clamp(-limit_N, limit_N) - f);
                }
                ModelEffect::Lag { gain, .. } => {
                    let (k, buf) = &mut self.lag[i];
                    buf.push_back(f);
                    let old = if buf.len() > *k {
                        buf.pop_front().unwrap_or(f)
                    } else {
                        buf[0]
                    };
                    f += gain * (old - f);
                }
                _ => {}
            }
        }
        f
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn base() -> DeviceModel {
        DeviceModel {
            inertia_kg: 50.0,
            viscous_friction_Ns_per_m: 400.0,
            coulomb_friction_N: 30.0,
            force_offset_N: 2.0,
            sign_band_m_s: 1e-4,
            effects: vec![],
        }
    }

    /// The baseline is the closed form; a lag of gain 1 is the same force k samples late.
    #[test]
    fn baseline_closed_form_and_lag_delays() {
        let dt = 1e-3;
        let n = 2000;
        let (x, v, a): (Vec<f64>, Vec<f64>, Vec<f64>) = (0..n)
            .map(|i| {
                let w = TAU * 1.3;
                let t = i as f64 * dt;
                (
                    0.02 * (w * t).sin(),
                    0.02 * w * (w * t).cos(),
                    -0.02 * w * w * (w * t).sin(),
                )
            })
            .fold((vec![], vec![], vec![]), |mut s, p| {
                s.0.push(p.0);
                s.1.push(p.1);
                s.2.push(p.2);
                s
            });
        let m = base();
        let f = m.force_series(dt, &x, &v, &a);
        for i in 0..n {
            let want = 50.0 * a[i] + 400.0 * v[i] + 30.0 * (v[i] / 1e-4).clamp(-1.0, 1.0) + 2.0;
            assert!((f[i] - want).abs() < 1e-9);
        }
        let mut ml = base();
        ml.effects.push(ModelEffect::Lag {
            lag_s: 0.017,
            gain: 1.0,
        });
        let fl = ml.force_series(dt, &x, &v, &a);
        for i in 17..n {
            assert!((fl[i] - f[i - 17]).abs() < 1e-9, "{i}");
        }
    }

    /// A hung mass far below its resonance moves with the device (no extra force); at the
    /// resonance of a lightly damped one the force is m2·a·(1/(2ζ)) in amplitude.
    #[test]
    fn compliance_resonates() {
        let dt = 1e-4;
        let mut m = base();
        m.inertia_kg = 0.0;
        m.viscous_friction_Ns_per_m = 0.0;
        m.coulomb_friction_N = 0.0;
        m.force_offset_N = 0.0;
        m.effects.push(ModelEffect::Compliance {
            resonance_Hz: 2.0,
            modal_mass_kg: 10.0,
            damping_ratio: 0.05,
        });
        let w = TAU * 2.0;
        let n = 200_000; // 20 s: 40 periods, 5 decay times of 1/(ζω)
        let (mut x, mut v, mut a) = (vec![], vec![], vec![]);
        for i in 0..n {
            let t = i as f64 * dt;
            x.push(0.001 * (w * t).sin());
            v.push(0.001 * w * (w * t).cos());
            a.push(-0.001 * w * w * (w * t).sin());
        }
        let f = m.force_series(dt, &x, &v, &a);
        let peak = f[n - 5000..].iter().fold(0.0f64, |p, v| p.max(v.abs()));
        // |H(jω) − 1| at resonance: |(1 + 2jζ)/(2jζ) − 1| = 1/(2ζ) = 10
        let want = 10.0 * 0.001 * w * w * 10.0;
        assert!((peak / want - 1.0).abs() < 0.02, "{peak} vs {want}");
    }

    /// Clip, play and Dahl state on a ramp out and back (closed forms): the clip holds the
    /// force at ±L (the whole force, or the drive's damping force only); across the play the
    /// force is the offset for `width` of travel after the reversal, then the impact M·v/dt in
    /// the first step of contact; the Dahl state after a travel d from a reversal is 1 − 2·e^(−d/x_c).
    #[test]
    fn clip_play_and_dahl_on_a_reversal() {
        let dt = 1e-3;
        let n = 2000;
        let v0 = 0.01;
        // out for 1 s at +v0, back for 1 s at −v0
        let x: Vec<f64> = (0..n)
            .map(|i| {
                let t = i as f64 * dt;
                if t < 1.0 {
                    v0 * t
                } else {
                    v0 * (2.0 - t)
                }
            })
            .collect();
        let v: Vec<f64> = (0..n).map(|i| if i < 1000 { v0 } else { -v0 }).collect();
        let a = vec![0.0; n];
        let mut m = base();
        m.effects = vec![ModelEffect::CurrentLimit {
            limit_N: 5.0,
            gain: 1.0,
            drive_damping_Ns_per_m: 0.0,
        }];
        let f = m.force_series(dt, &x, &v, &a);
        // 400·0.01 + 30 + 2 = 36 N clipped at 5 N; −36 + 4 → −30 + 2 = −32 → −5
        assert!((f[500] - 5.0).abs() < 1e-12 && (f[1500] + 5.0).abs() < 1e-12);
        m.effects = vec![ModelEffect::Backlash {
            width_m: 0.002,
            restitution: None,
            contact_Hz: None,
            gain: 1.0,
            impact_mass_kg: None,
            device_inertia_kg: None,
            device_viscous_Ns_per_m: None,
            device_coulomb_N: None,
            impact_pulse_kg: None,
            impact_tap_s: None,
        }];
        let f = m.force_series(dt, &x, &v, &a);
        // the play is centred at the start: in contact after 1 mm (100 samples)
        assert!((f[50] - 2.0).abs() < 1e-12, "{}", f[50]);
        assert!(
            (f[500] - 36.0).abs() < 1e-12,
            "{} {:?}",
            f[500],
            &f[95..106]
        );
        // after the reversal at sample 1000 the device leaves the flank (the motion's force on
        // it, −34 N, would pull) and coasts on at 0.01 m/s until its friction stops it:
        // closed form v(t) = (v0 + Fc/Fv)·e^(−t/τ) − Fc/Fv, τ = M/Fv, stopping at
        // t* = τ·ln(1 + Fv·v0/Fc) after τ·(v0 + Fc/Fv)·(1 − e^(−t*/τ)) − Fc/Fv·t* = 76.6 µm,
        // towards the returning motion: the gap, 2 mm less that, at 0.01 m/s, at the offset
        let (tau, vc): (f64, f64) = (50.0 / 400.0, 30.0 / 400.0);
        let ts = tau * (1.0 + 0.01 / vc).ln();
        let coast = tau * (0.01 + vc) * (1.0 - (-ts / tau).exp()) - vc * ts;
        // (the walk leaves the flank from sample 999, the last the flank pushed, 10 µm short
        // of the turn at 1000: one sample later than the continuous motion)
        let k_want = 1000.0 + (0.002 - coast) / 0.01 / dt + 1.0;
        assert!((f[1100] - 2.0).abs() < 1e-12 && (f[1185] - 2.0).abs() < 1e-12);
        assert!((f[1300] + 32.0).abs() < 1e-12, "{}", f[1300]);
        // the first step in contact, within a sample of that instant (the contact falls
        // between samples), carries the impact M·v/dt = 50·(−0.01)/1e-3
        let k = (1186..1200).find(|&i| (f[i] - 2.0).abs() > 1e-9).unwrap();
        assert!((k as f64 - k_want).abs() <= 1.0, "{k} against {k_want}");
        assert!(
            (f[k - 1] - 2.0).abs() < 1e-12 && (f[k] + 32.0 + 500.0).abs() < 1e-9,
            "{}",
            f[k]
        );
        assert!((f[k + 1] + 32.0).abs() < 1e-12);
        // the drive acting as a damper: 300 of the 400 N·s/m clipped at 2 N:
        // 100·0.01 + clip(300·0.01, ±2) + 30 + 2 = 35 N; back: −1 − 2 − 30 + 2 = −31 N
        m.effects = vec![ModelEffect::CurrentLimit {
            limit_N: 2.0,
            gain: 1.0,
            drive_damping_Ns_per_m: 300.0,
        }];
        let f = m.force_series(dt, &x, &v, &a);
        assert!((f[500] - 35.0).abs() < 1e-12 && (f[1500] + 31.0).abs() < 1e-12);
        m.effects = vec![ModelEffect::PreslidingHysteresis {
            characteristic_displacement_m: 0.001,
            friction_N: 10.0,
        }];
        let f = m.force_series(dt, &x, &v, &a);
        // at 1.5 s: 5 mm back from the reversal, z = −1 + (z_r + 1)·e^(−5), z_r ≈ 1
        let z_r = 1.0 - (-10.0f64).exp(); // 10 mm out from z = 0: 1 − e^(−10)
        let z = -1.0 + (z_r + 1.0) * (-5.0f64).exp();
        let want = -4.0 - 30.0 + 2.0 + 10.0 * (z + 1.0);
        assert!((f[1500] - want).abs() < 1e-9, "{} vs {want}", f[1500]);
    }

    #[test]
    fn bad_fragment_names_key_value_range() {
        let t = "[model]\ninertia_kg = -3\nviscous_friction_Ns_per_m = 1\ncoulomb_friction_N = 1\nsign_band_m_s = 1e-4\n";
        let e = Fragment::from_toml(t).unwrap_err();
        assert!(
            e.contains("model.inertia_kg = -3") && e.contains("allowed range"),
            "{e}"
        );
        let t = "[model]\ninertia_kg = 3\nviscous_friction_Ns_per_m = 1\ncoulomb_friction_N = 1\nsign_band_m_s = 1e-4\n[[model.effect]]\nname = \"lag\"\nlag_s = 0.01\ngain = 7\n";
        let e = Fragment::from_toml(t).unwrap_err();
        assert!(e.contains("effect[0] (lag).gain = 7"), "{e}");
        let t = "[model]\ninertia_kg = 3\nviscous_friction_Ns_per_m = 1\ncoulomb_friction_N = 1\nsign_band_m_s = 1e-4\n[[model.effect]]\nname = \"warp_drive\"\n";
        let e = Fragment::from_toml(t).unwrap_err();
        assert!(e.contains("line") && e.contains("warp_drive"), "{e}");
    }
}
