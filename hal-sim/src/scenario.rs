//! Scenario files (TOML): device, what drives it, bus, losses, sensors, the firmware's
//! configuration and law, the duration and what to record.
//!
//! Every table and key is optional except `drive` (defaults: the reference device on a
//! 160 V bus). Unknown keys are refused, and errors name the key and the line. Example:
//!
//! ```toml
//! name = "tmd-306"
//! duration_s = 10.0
//! [law]
//! kind = "resistor"
//! r_load_ohm = 306.0
//! [drive]
//! kind = "structure"
//! [drive.excitation]
//! kind = "sine"
//! a0_m_s2 = 1.0
//! freq_hz = 0.5
//! [record]
//! channels = ["t", "x", "v", "force", "i_q", "v_bus"]
//! every = 20
//! ```

use crate::plant::{Bus, Drive, Excitation, Inverter, Losses, Machine, Motion, Screw, Sensors};
use crate::powerup::PowerUp;
use crate::sim::{Channel, Rig, Sim};
use regen_fw::laws::LawKind;
use regen_fw::Config;
use serde::{Deserialize, Serialize};

/// The command law and its parameters.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LawSpec {
    /// Law name as the console shows it (`resistor`).
    pub kind: String,
    /// Emulated load resistance per phase, Ω (omit or `inf` for open circuit).
    #[serde(default = "inf")]
    pub r_load_ohm: f64,
    /// Any other firmware parameter by its console name (`regen_fw::params`), e.g.
    /// `[law.set] trk_period_s = 8.0`: checked against the registry's range like a console
    /// `set`.
    #[serde(default)]
    pub set: std::collections::BTreeMap<String, f64>,
    /// Host-designed controller of the two-way / one-way laws (`regen study design` prints
    /// it): `a` (N×N), `b` (N×M), `c` (N), `d` (M), row-major.
    #[serde(default)]
    pub opt: Option<OptSpec>,
}

/// The `[law.opt]` table.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct OptSpec {
    pub a: Vec<f32>,
    pub b: Vec<f32>,
    pub c: Vec<f32>,
    pub d: Vec<f32>,
}

impl OptSpec {
    fn params(&self) -> Result<regen_fw::laws::lti::LtiParams, String> {
        let mut p = regen_fw::laws::lti::LtiParams::default();
        let put = |dst: &mut [f32], src: &[f32], what: &str| -> Result<(), String> {
            if src.len() != dst.len() {
                return Err(format!(
                    "law.opt.{what}: {} numbers expected, {} given",
                    dst.len(),
                    src.len()
                ));
            }
            dst.copy_from_slice(src);
            Ok(())
        };
        put(&mut p.a, &self.a, "a")?;
        put(&mut p.b, &self.b, "b")?;
        put(&mut p.c, &self.c, "c")?;
        put(&mut p.d, &self.d, "d")?;
        if !p.is_valid() {
            return Err("law.opt: a coefficient is not finite or out of range".into());
        }
        Ok(p)
    }
}

fn inf() -> f64 {
    f64::INFINITY
}

impl Default for LawSpec {
    fn default() -> Self {
        LawSpec {
            kind: "resistor".into(),
            r_load_ohm: 306.0,
            set: Default::default(),
            opt: None,
        }
    }
}

/// Firmware configuration fields a scenario may set (the rest come from the device: R, L,
/// K_e, pole pairs, lead; and from `regen_fw::Config::default()`).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct FirmwareSpec {
    pub pwm_hz: f32,
    pub current_bw_hz: f32,
    pub speed_bw_hz: f32,
    pub encoder_cpr: u32,
    pub amps_per_count: f32,
    pub volts_per_count: f32,
    pub i_max_a: f32,
    pub i_trip_a: f32,
    pub v_bus_ov: f32,
    pub v_bus_uv: f32,
    pub brake_on_v: f32,
    pub brake_off_v: f32,
    /// Regenerative derating band (between the brake and the over-voltage trip).
    pub derate_start_v: f32,
    pub derate_end_v: f32,
    /// Flux braking's largest d current, A (0 = off), and the regenerated power the bus
    /// takes below `brake_on_v`, W (`inf` = all of it).
    pub flux_brake_a: f32,
    pub max_regen_power_w: f32,
    pub ff_emf: bool,
    pub ff_decouple: bool,
    pub delay_comp: bool,
    /// The firmware's belief of K_e (V·s/rad); default: the device's true value.
    pub ke_v_s_per_rad: Option<f32>,
    /// The firmware's belief of R and L; default: the device's values.
    pub r_phase_ohm: Option<f32>,
    pub l_phase_h: Option<f32>,
}

impl Default for FirmwareSpec {
    /// The firmware defaults, with bus scaling and thresholds for the simulator's 320 V bus:
    /// the reference TMD at 1 kΩ moves at up to 0.5 m/s, about 100 V of phase peak (150 V
    /// with the paper-equivalent K_e), i.e. a bus above √3·150/0.95 ≈ 275 V for linear
    /// modulation over the whole sweep.
    fn default() -> Self {
        let c = Config::default();
        FirmwareSpec {
            pwm_hz: c.pwm_hz,
            current_bw_hz: c.current_bw_hz,
            speed_bw_hz: c.speed_bw_hz,
            encoder_cpr: c.encoder_cpr,
            amps_per_count: c.amps_per_count,
            volts_per_count: 450.0 / 4096.0,
            i_max_a: c.i_max_a,
            i_trip_a: c.i_trip_a,
            v_bus_ov: 420.0,
            v_bus_uv: c.v_bus_uv,
            brake_on_v: 380.0,
            brake_off_v: 370.0,
            derate_start_v: 395.0,
            derate_end_v: 415.0,
            flux_brake_a: c.flux_brake_a,
            max_regen_power_w: c.max_regen_power_w,
            ff_emf: c.ff_emf,
            ff_decouple: c.ff_decouple,
            delay_comp: c.delay_comp,
            ke_v_s_per_rad: None,
            r_phase_ohm: None,
            l_phase_h: None,
        }
    }
}

/// What to record.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct RecordSpec {
    pub channels: Vec<String>,
    /// Keep one PWM period in `every`.
    pub every: u64,
}

impl Default for RecordSpec {
    fn default() -> Self {
        RecordSpec {
            channels: [
                "t",
                "x",
                "v",
                "force",
                "i_q",
                "i_q_ref",
                "v_bus",
                "p_inverter",
            ]
            .iter()
            .map(|s| s.to_string())
            .collect(),
            every: 20,
        }
    }
}

/// A scenario.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    #[serde(default = "default_name")]
    pub name: String,
    #[serde(default = "default_duration")]
    pub duration_s: f64,
    /// Time from which averages (power) are taken, s.
    #[serde(default)]
    pub settle_s: f64,
    #[serde(default)]
    pub machine: Machine,
    #[serde(default)]
    pub screw: Screw,
    pub drive: Drive,
    #[serde(default)]
    pub bus: Bus,
    #[serde(default)]
    pub inverter: Inverter,
    #[serde(default)]
    pub losses: Losses,
    #[serde(default)]
    pub sensors: Sensors,
    /// Power-up models ([`crate::powerup`]): all off by default; on, the build runs the
    /// firmware's boot sequence (offset calibration, alignment) before the run.
    #[serde(default)]
    pub powerup: PowerUp,
    /// The plant's machine drawn off the nameplate `[machine]` ([`crate::powerup::PlantDraw`]):
    /// off by default (the plant is the nameplate).
    #[serde(default)]
    pub plant_draw: crate::powerup::PlantDraw,
    #[serde(default)]
    pub firmware: FirmwareSpec,
    #[serde(default)]
    pub law: LawSpec,
    #[serde(default)]
    pub record: RecordSpec,
    /// A diagnosed device model (`regen diagnose --model`, [`crate::device_model`]): with an
    /// imposed motion, the device's mechanical force is this model's instead of the screw's
    /// (the machine's electromagnetic force still adds to it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<crate::device_model::DeviceModel>,
}

fn default_name() -> String {
    "scenario".into()
}
fn default_duration() -> f64 {
    10.0
}

impl Scenario {
    /// Parse TOML text; the error names the key and line.
    pub fn from_toml(text: &str) -> Result<Scenario, String> {
        let s: Scenario = toml::from_str(text).map_err(|e| toml_error(text, &e))?;
        s.check()?;
        Ok(s)
    }

    /// This scenario with the model of a fragment file (`regen run --model`, the TOML that
    /// `regen diagnose --model` writes: one `[model]` table), checked as the scenario is.
    pub fn with_model_file(mut self, path: &std::path::Path) -> Result<Scenario, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let f = crate::device_model::Fragment::from_toml(&text)
            .map_err(|e| format!("{}: {e}", path.display()))?;
        self.model = Some(f.model);
        self.check()
            .map_err(|e| format!("{}: {e}", path.display()))?;
        Ok(self)
    }

    /// Read and parse a file.
    pub fn from_file(path: &std::path::Path) -> Result<Scenario, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        Self::from_toml(&text).map_err(|e| format!("{}: {e}", path.display()))
    }

    /// The reference TMD (400 kg, 2 s, base sine 1 m/s² at 0.5 Hz) with a resistor law.
    pub fn tmd(r_load_ohm: f64) -> Scenario {
        Scenario {
            name: "tmd".into(),
            // The start-up transient's envelope decays with 2m̄/c̄ ≤ 1.2 s over 10 Ω … 1 kΩ:
            // 8 s leave < 0.1 % of it; then two excitation periods are averaged.
            duration_s: 12.0,
            settle_s: 8.0,
            machine: Machine::default(),
            screw: Screw::default(),
            drive: Drive::Structure {
                structure: Default::default(),
                excitation: crate::plant::Excitation::Sine {
                    a0_m_s2: 1.0,
                    freq_hz: 0.5,
                },
            },
            bus: Bus::default(),
            inverter: Inverter::default(),
            losses: Losses::default(),
            sensors: Sensors::default(),
            powerup: PowerUp::default(),
            plant_draw: Default::default(),
            firmware: FirmwareSpec::default(),
            law: LawSpec {
                r_load_ohm,
                ..LawSpec::default()
            },
            record: RecordSpec::default(),
            model: None,
        }
    }

    /// An imposed motion with a resistor law.
    pub fn imposed(motion: crate::plant::Motion, r_load_ohm: f64, duration_s: f64) -> Scenario {
        Scenario {
            name: "imposed".into(),
            duration_s,
            settle_s: 0.0,
            drive: Drive::Imposed { motion },
            law: LawSpec {
                r_load_ohm,
                ..LawSpec::default()
            },
            ..Scenario::tmd(0.0)
        }
    }

    /// Every value checked for finiteness, sign and physical range (see [`Scenario::physics`])
    /// and the firmware configuration it implies; the error names the key, the value and
    /// the allowed range.
    pub fn check(&self) -> Result<(), String> {
        key_in_range("duration_s", self.duration_s)?;
        in_range(
            "settle_s",
            self.settle_s,
            Lo::Closed(0.0),
            self.duration_s,
            "s",
        )?;
        if self.settle_s >= self.duration_s {
            return Err(format!(
                "settle_s = {}: must lie in [0, duration_s = {}) s",
                self.settle_s, self.duration_s
            ));
        }
        self.physics()?;
        if let Some(m) = &self.model {
            if !matches!(self.drive, Drive::Imposed { .. }) {
                return Err("model: a diagnosed device model needs drive.kind = \"imposed\" (it is the force of the device on a given motion)".into());
            }
            if self.screw.efficiency != 1.0 {
                return Err(format!("screw.efficiency = {}: must be 1 with a [model] (the model replaces the screw's mechanical force; its own `screw_efficiency` effect carries the efficiency)", self.screw.efficiency));
            }
            m.check()?;
        }
        for c in &self.record.channels {
            if Channel::from_name(c).is_none() {
                let all: Vec<&str> = Channel::ALL.iter().map(|c| c.name()).collect();
                return Err(format!(
                    "record.channels: unknown channel `{c}` (known: {})",
                    all.join(", ")
                ));
            }
        }
        self.law_kind()?;
        self.config()?;
        self.powerup.check()?;
        self.plant_draw.check()?;
        Ok(())
    }

    fn law_kind(&self) -> Result<LawKind, String> {
        LawKind::ALL
            .iter()
            .copied()
            .find(|k| k.name() == self.law.kind)
            .ok_or_else(|| format!("law.kind: unknown law `{}`", self.law.kind))
    }

    /// The firmware configuration this scenario runs.
    pub fn config(&self) -> Result<Config, String> {
        let f = &self.firmware;
        let m = &self.machine;
        let mut c = Config {
            r_phase_ohm: f.r_phase_ohm.unwrap_or(m.r_ohm as f32),
            l_phase_h: f.l_phase_h.unwrap_or(m.l_h as f32),
            ke_v_s_per_rad: f.ke_v_s_per_rad.unwrap_or(m.ke_v_s_per_rad as f32),
            pole_pairs: m.pole_pairs.min(255) as u8,
            lead_m_per_rad: self.screw.lead_m_per_rad as f32,
            encoder_cpr: f.encoder_cpr,
            encoder_offset_rad: m.angle_offset_rad as f32,
            amps_per_count: f.amps_per_count,
            volts_per_count: f.volts_per_count,
            pwm_hz: f.pwm_hz,
            current_bw_hz: f.current_bw_hz,
            speed_bw_hz: f.speed_bw_hz,
            ff_emf: f.ff_emf,
            ff_decouple: f.ff_decouple,
            delay_comp: f.delay_comp,
            i_max_a: f.i_max_a,
            i_trip_a: f.i_trip_a,
            v_bus_ov: f.v_bus_ov,
            v_bus_uv: f.v_bus_uv,
            brake_on_v: f.brake_on_v,
            brake_off_v: f.brake_off_v,
            derate_start_v: f.derate_start_v,
            derate_end_v: f.derate_end_v,
            flux_brake_a: f.flux_brake_a,
            max_regen_power_w: f.max_regen_power_w,
            law: self.law_kind()?,
            r_load_ohm: self.law.r_load_ohm as f32,
            ..Config::default()
        };
        c.validate().map_err(|e| {
            let key = if e.field == "r_load_ohm" {
                "law.r_load_ohm".to_string()
            } else {
                format!("firmware.{}", e.field)
            };
            match regen_fw::params::find(e.field) {
                Some(p) => format!(
                    "{key} = {}: {} (allowed [{}, {}] {})",
                    p.get(&c),
                    e.reason,
                    p.min,
                    p.max,
                    p.unit()
                ),
                None => format!("{key}: {}", e.reason),
            }
        })?;
        if let Some(o) = &self.law.opt {
            c.opt = o.params()?;
        }
        for (name, v) in &self.law.set {
            let p = regen_fw::params::find(name)
                .ok_or_else(|| format!("law.set.{name}: unknown parameter"))?;
            f32_value(&format!("law.set.{name}"), *v)?;
            p.apply(&mut c, *v as f32, false).map_err(|e| {
                format!(
                    "law.set.{name} = {v}: {e} (allowed [{}, {}] {})",
                    p.min,
                    p.max,
                    p.unit()
                )
            })?;
        }
        Ok(c)
    }

    /// The plant's values against their physical ranges ([`RANGES`]: each key's range and
    /// why the model holds there).
    pub fn physics(&self) -> Result<(), String> {
        use Lo::Closed;
        let m = &self.machine;
        key_in_range("machine.r_ohm", m.r_ohm)?;
        key_in_range("machine.l_h", m.l_h)?;
        if let Some(l) = m.l_q_h {
            key_in_range("machine.l_q_h", l)?;
        }
        key_in_range("machine.ke_v_s_per_rad", m.ke_v_s_per_rad)?;
        key_in_range("machine.pole_pairs", m.pole_pairs as f64)?;
        key_in_range("machine.angle_offset_rad", m.angle_offset_rad)?;
        let s = &self.screw;
        key_in_range("screw.lead_m_per_rad", s.lead_m_per_rad)?;
        key_in_range("screw.j_kg_m2", s.j_kg_m2)?;
        key_in_range("screw.b_nms", s.b_nms)?;
        key_in_range("screw.efficiency", s.efficiency)?;
        key_in_range("screw.coulomb_n", s.coulomb_n)?;
        key_in_range("screw.viscous_n_s_per_m", s.viscous_n_s_per_m)?;
        key_in_range("screw.p3", s.p3)?;
        key_in_range("screw.p5", s.p5)?;
        key_in_range("screw.p4", s.p4)?;
        key_in_range("screw.p6", s.p6)?;
        key_in_range("screw.ball_m", s.ball_m)?;
        key_in_range("screw.stick_velocity", s.stick_velocity)?;
        match &self.drive {
            Drive::Imposed { motion } => {
                match motion {
                    Motion::Sine {
                        amplitude_m,
                        freq_hz,
                    }
                    | Motion::Triangle {
                        amplitude_m,
                        freq_hz,
                    } => {
                        key_in_range("drive.motion.amplitude_m", *amplitude_m)?;
                        key_in_range("drive.motion.freq_hz", *freq_hz)?;
                    }
                    Motion::Recorded {
                        t_s,
                        x_m,
                        v_m_s,
                        a_m_s2,
                        v_kin_m_s,
                    } => {
                        series("drive.motion", t_s, "x_m", x_m, 10.0)?;
                        for (key, c, bound) in [
                            ("v_m_s", v_m_s, 20.0),
                            ("a_m_s2", a_m_s2, 1e4),
                            ("v_kin_m_s", v_kin_m_s, 20.0),
                        ] {
                            if !c.is_empty() {
                                series("drive.motion", t_s, key, c, bound)?;
                            }
                        }
                    }
                    Motion::Record { path, cutoff_hz } => {
                        if path.trim().is_empty() {
                            return Err("drive.motion.path = \"\": a record file (CSV t_s,x_m,f_N) is needed".into());
                        }
                        if let Some(fc) = cutoff_hz {
                            key_in_range("drive.motion.cutoff_hz", *fc)?;
                        }
                    }
                }
            }
            Drive::Structure {
                structure,
                excitation,
            } => {
                key_in_range("drive.structure.mass_kg", structure.mass_kg)?;
                key_in_range(
                    "drive.structure.stiffness_n_per_m",
                    structure.stiffness_n_per_m,
                )?;
                key_in_range(
                    "drive.structure.damping_n_s_per_m",
                    structure.damping_n_s_per_m,
                )?;
                match excitation {
                    Excitation::Sine { a0_m_s2, freq_hz }
                    | Excitation::Triangle { a0_m_s2, freq_hz } => {
                        key_in_range("drive.excitation.a0_m_s2", *a0_m_s2)?;
                        key_in_range("drive.excitation.freq_hz", *freq_hz)?;
                    }
                    Excitation::KanaiTajimi {
                        s0,
                        omega_g,
                        zeta_g,
                        ..
                    } => {
                        key_in_range("drive.excitation.s0", *s0)?;
                        key_in_range("drive.excitation.omega_g", *omega_g)?;
                        key_in_range("drive.excitation.zeta_g", *zeta_g)?;
                    }
                    Excitation::Recorded { t_s, a_m_s2 } => {
                        series("drive.excitation", t_s, "a_m_s2", a_m_s2, 1e4)?;
                    }
                    Excitation::RecordedCsv { path } => {
                        if path.is_empty() {
                            return Err(
                                "drive.excitation.path = \"\": a CSV file path expected".into()
                            );
                        }
                    }
                }
            }
        }
        let b = &self.bus;
        key_in_range("bus.capacitance_f", b.capacitance_f)?;
        key_in_range("bus.initial_v", b.initial_v)?;
        if let Some(v) = b.source_v {
            key_in_range("bus.source_v", v)?;
        }
        key_in_range("bus.source_r_ohm", b.source_r_ohm)?;
        key_in_range("bus.brake_r_ohm", b.brake_r_ohm)?;
        let period = 1.0 / self.firmware.pwm_hz as f64;
        in_range(
            "inverter.dead_time_s",
            self.inverter.dead_time_s,
            Closed(0.0),
            0.1 * period,
            "s (a tenth of the PWM period)",
        )?;
        let l = &self.losses;
        key_in_range("losses.k_sw_s", l.k_sw_s)?;
        key_in_range("losses.r_on_ohm", l.r_on_ohm)?;
        key_in_range("losses.logic_w", l.logic_w)?;
        key_in_range("losses.logic_min_v", l.logic_min_v)?;
        let n = &self.sensors;
        for (k, o) in n.current_offset_a.iter().enumerate() {
            key_in_range(&format!("sensors.current_offset_a[{k}]"), *o)?;
        }
        key_in_range("sensors.current_noise_a", n.current_noise_a)?;
        key_in_range("sensors.vbus_offset_v", n.vbus_offset_v)?;
        key_in_range("sensors.vbus_noise_v", n.vbus_noise_v)?;
        if self.law.r_load_ohm != f64::INFINITY {
            key_in_range("law.r_load_ohm", self.law.r_load_ohm)?;
            f32_value("law.r_load_ohm", self.law.r_load_ohm)?;
        }
        if self.record.every == 0 {
            return Err("record.every = 0: must be ≥ 1 (keep one PWM period in `every`)".into());
        }
        Ok(())
    }

    /// The drive with recorded files loaded.
    fn loaded_drive(&self) -> Result<Drive, String> {
        let mut d = self.drive.clone();
        if let Drive::Imposed { motion } = &mut d {
            if let Motion::Record { path, cutoff_hz } = motion {
                let r = crate::diagnose::read_csv(std::path::Path::new(path.as_str()), *cutoff_hz)
                    .map_err(|e| format!("drive.motion.path: {e}"))?;
                // the velocity through the acceleration's band too, where the reader's came
                // through a wider one (`record::derive_from_x`): the kinematic pair the play's
                // device walks, as the diagnosis's (`Context::v_with_a`)
                let v_kin_m_s =
                    crate::diagnose::record::v_through_accel_band(&r).unwrap_or_default();
                *motion = Motion::Recorded {
                    t_s: r.t,
                    x_m: r.x,
                    v_m_s: r.v,
                    a_m_s2: r.a,
                    v_kin_m_s,
                };
            }
        }
        if let Drive::Structure { excitation, .. } = &mut d {
            if let Excitation::RecordedCsv { path } = excitation {
                let (t_s, a_m_s2) =
                    crate::plant::read_series_csv(std::path::Path::new(path.as_str()))
                        .map_err(|e| format!("drive.excitation.path: {e}"))?;
                *excitation = Excitation::Recorded { t_s, a_m_s2 };
            }
        }
        Ok(d)
    }

    /// The plant's machine: the nameplate `[machine]` as `[plant_draw]` draws it.
    pub fn plant_machine(&self) -> Machine {
        self.plant_draw.draw(&self.machine)
    }

    /// The simulation, recording the chosen channels.
    pub fn build(&self) -> Result<Sim, String> {
        let rig = Rig {
            machine: self.plant_machine(),
            screw: self.screw,
            drive: self.loaded_drive()?,
            bus: self.bus,
            inverter: self.inverter,
            losses: self.losses,
            sensors: self.sensors,
        };
        let mut sim = Sim::new(rig, &self.config()?)?;
        if let Some(m) = &self.model {
            sim.set_model(m);
        }
        if sim.power_up(&self.powerup)?.is_some() {
            // A boot that fails leaves its fault latched (and the drive in its safe mode)
            // for the run to show.
            let _ = sim.boot();
        }
        let ch: Vec<Channel> = self
            .record
            .channels
            .iter()
            .filter_map(|c| Channel::from_name(c))
            .collect();
        if !ch.is_empty() {
            sim.record(&ch, self.record.every);
        }
        Ok(sim)
    }
}

/// A TOML error on one line: `line N (`the line`): message`.
fn toml_error(text: &str, e: &toml::de::Error) -> String {
    let msg = e.message().trim().replace('\n', " ");
    match e.span() {
        Some(sp) => {
            let start = sp.start.min(text.len());
            let line = text[..start].matches('\n').count() + 1;
            let content = text.lines().nth(line - 1).unwrap_or("").trim();
            let content: String = content.chars().take(60).collect();
            format!("line {line} (`{content}`): {msg}")
        }
        None => msg,
    }
}

/// The lower end of an allowed range.
#[derive(Clone, Copy, Debug)]
pub enum Lo {
    Open(f64),
    Closed(f64),
}

/// A scenario key's allowed range, its unit, and why the model holds there and not beyond.
#[derive(Clone, Copy, Debug)]
pub struct KeyRange {
    pub key: &'static str,
    pub lo: Lo,
    pub hi: f64,
    pub unit: &'static str,
    pub why: &'static str,
}

const fn kr(key: &'static str, lo: Lo, hi: f64, unit: &'static str, why: &'static str) -> KeyRange {
    KeyRange {
        key,
        lo,
        hi,
        unit,
        why,
    }
}

/// Every scenario key with a fixed range, checked by [`Scenario::check`]; the table of
/// `docs/simulator.md` ("Scenario ranges") is [`ranges_markdown`] of it (a test compares).
/// Two ranges depend on another key and are checked beside it: `settle_s` < `duration_s`,
/// `inverter.dead_time_s` ≤ a tenth of the PWM period.
pub const RANGES: &[KeyRange] = {
    use Lo::{Closed, Open};
    &[
        kr("duration_s", Open(0.0), 1e5, "s", "a day of simulated time (2·10⁹ periods at 20 kHz): the ledger's sums keep 1e-8 of the largest flow; longer runs are limited by time and memory, not the model"),
        kr("machine.r_ohm", Open(0.0), 1e3, "Ω", "the per-period solution is exact for any R; 1 kΩ is beyond any machine of this class"),
        kr("machine.l_h", Closed(1e-4), 10.0, "H", "the averaged inverter books the mean current, not the PWM ripple V_bus/(4·L·f_pwm): 40 A peak to peak at 320 V, 20 kHz and 0.1 mH, whose copper loss then goes unbooked (`inverter.switched` books it)"),
        kr("machine.l_q_h", Closed(1e-4), 10.0, "H", "the q axis's, as `machine.l_h` (the d axis's; absent: `l_h`, a non-salient machine); a salient machine's period is integrated in sub-steps of at most τ_min/8 for any L_q/L_d"),
        kr("machine.ke_v_s_per_rad", Open(0.0), 100.0, "V·s/rad", "per-phase peak; the firmware's fixed point holds K_e·ω up to its bus range"),
        kr("machine.pole_pairs", Closed(1.0), 50.0, "", "the firmware's `pole_pairs` range (params.rs); the electrical angle per PWM period is judged by the run's verdict"),
        kr("machine.angle_offset_rad", Closed(-1e3), 1e3, "rad", "an angle: any value, wrapped"),
        kr("screw.lead_m_per_rad", Closed(1e-4), 0.05, "m/rad", "ballscrew leads, 0.6 … 314 mm per turn (reference 16 mm): beyond them the device is not a ballscrew, whose efficiency and eq. 13 friction the model carries"),
        kr("screw.j_kg_m2", Open(0.0), 10.0, "kg·m²", "rotor and screw inertia; the screw is rigid (no axial compliance in the model)"),
        kr("screw.b_nms", Closed(0.0), 1e3, "N·m·s/rad", "rotary viscosity, linear in the speed"),
        kr("screw.efficiency", Closed(0.5), 1.0, "", "below 0.5 a screw is self-locking (friction angle above the lead angle): it cannot be back-driven, while the model's h = 1/η would still pass power both ways"),
        kr("screw.coulomb_n", Closed(0.0), 1e6, "N", "eq. 13's Coulomb level; the regularised sign keeps the step finite at any level"),
        kr("screw.viscous_n_s_per_m", Closed(0.0), 1e8, "N·s/m", "eq. 13's viscous term, linear in the speed"),
        kr("screw.p3", Closed(-1.0), 1.0, "", "relative depth of eq. 13's first ripple: beyond ±1 the friction would change sign with the position, which Coulomb friction does not"),
        kr("screw.p5", Closed(-1.0), 1.0, "", "relative depth of eq. 13's second ripple (as p3)"),
        kr("screw.p4", Closed(-1e3), 1e3, "rad", "a phase: any value"),
        kr("screw.p6", Closed(-1e3), 1e3, "rad", "a phase: any value"),
        kr("screw.ball_m", Open(0.0), 1.0, "m", "the ball pitch of the second ripple"),
        kr("screw.stick_velocity", Open(0.0), 0.01, "m/s", "the Coulomb sign is regularised below it; above 1 cm/s the regularisation would turn Coulomb friction into viscous friction over the structure's own motion (reference TMD: 0.2 m/s peak)"),
        kr("drive.motion.amplitude_m", Closed(0.0), 10.0, "m", "a ballscrew's stroke (the firmware's stroke limits trip first)"),
        kr("drive.motion.freq_hz", Open(0.0), 50.0, "Hz", "the machine's per-period solution holds the speed over a PWM period: at f the speed moves by up to 2π·f/f_pwm of its amplitude within one, 1.6 % at 50 Hz and 20 kHz; structures vibrate below a few Hz"),
        kr("drive.motion.cutoff_hz", Open(0.0), 1e6, "Hz", "the record reader's derivative filter, checked against the record's Nyquist frequency when read"),
        kr("drive.structure.mass_kg", Open(0.0), 1e9, "kg", "a single degree of freedom of any mass"),
        kr("drive.structure.stiffness_n_per_m", Closed(0.0), 1e12, "N/m", "linear spring; the natural frequency is bounded by the excitation's band, not here"),
        kr("drive.structure.damping_n_s_per_m", Closed(0.0), 1e12, "N·s/m", "linear damper"),
        kr("drive.excitation.a0_m_s2", Closed(0.0), 100.0, "m/s²", "10 g: far beyond any device's rating, so the drive's protection answers it (an invalid run); beyond it the excitation is a shock, not a vibration the averaged model integrates"),
        kr("drive.excitation.freq_hz", Open(0.0), 50.0, "Hz", "as drive.motion.freq_hz: the speed held over a PWM period"),
        kr("drive.excitation.s0", Closed(0.0), 1e6, "(m/s²)²/(rad/s)", "the ground's spectral intensity; a0's limit is met through the protection"),
        kr("drive.excitation.omega_g", Open(0.0), 314.0, "rad/s", "the ground filter's corner, 50 Hz at most (as drive.excitation.freq_hz)"),
        kr("drive.excitation.zeta_g", Open(0.0), 10.0, "", "the ground filter's damping"),
        kr("bus.capacitance_f", Open(0.0), 10.0, "F", "the bus is solved exactly per period for any capacitance"),
        kr("bus.initial_v", Closed(0.0), 2000.0, "V", "a 1,200 V-class stage's bus; the firmware's bus ADC and trips are set beside it in [firmware]"),
        kr("bus.source_v", Closed(0.0), 2000.0, "V", "as bus.initial_v"),
        kr("bus.source_r_ohm", Open(0.0), 1e6, "Ω", "the source's resistance: 1 MΩ is no source"),
        kr("bus.brake_r_ohm", Open(0.0), 1e6, "Ω", "the brake resistor"),
        kr("losses.k_sw_s", Closed(0.0), 1e-5, "s", "switching energy per volt-ampere: 10 µs is a fifth of a 20 kHz period, beyond any switch"),
        kr("losses.r_on_ohm", Closed(0.0), 10.0, "Ω", "a switch's on-resistance"),
        kr("losses.logic_w", Closed(0.0), 1e3, "W", "the logic supply's draw"),
        kr("losses.logic_min_v", Closed(0.0), 1e4, "V", "the logic supply's under-voltage lockout"),
        kr("sensors.current_offset_a", Closed(-1e3), 1e3, "A", "per phase; the ADC's codes saturate where the firmware's scaling ends"),
        kr("sensors.current_noise_a", Closed(0.0), 1e3, "A", "Gaussian, per sample; the codes saturate as above"),
        kr("sensors.vbus_offset_v", Closed(-1e3), 1e3, "V", "on the bus reading"),
        kr("sensors.vbus_noise_v", Closed(0.0), 1e3, "V", "Gaussian, per sample"),
        kr("law.r_load_ohm", Closed(0.0), 1e9, "Ω (or inf = open)", "the emulated load per phase; also refused where the firmware's f32 underflows"),
    ]
};

/// `key`'s range in [`RANGES`] (a `[k]` index on the key is ignored for the look-up).
pub fn key_range(key: &str) -> Option<&'static KeyRange> {
    let base = key.split('[').next().unwrap_or(key);
    RANGES.iter().find(|r| r.key == base)
}

/// [`in_range`] with `key`'s range from [`RANGES`].
fn key_in_range(key: &str, v: f64) -> Result<(), String> {
    let r = key_range(key).ok_or_else(|| format!("{key}: no range (internal)"))?;
    in_range(key, v, r.lo, r.hi, r.unit)
}

/// The range as the refusal states it: `(lo, hi] unit`.
fn range_text(r: &KeyRange) -> String {
    let (b, l) = match r.lo {
        Lo::Open(l) => ('(', l),
        Lo::Closed(l) => ('[', l),
    };
    format!("{b}{}, {}]", shown(l), shown(r.hi))
}

/// The Markdown table of [`RANGES`] (key, range, unit, why) that `docs/simulator.md` shows.
pub fn ranges_markdown() -> String {
    let mut t =
        String::from("| key | allowed | unit | why this range |\n| --- | --- | --- | --- |\n");
    for r in RANGES {
        t += &format!(
            "| `{}` | {} | {} | {} |\n",
            r.key,
            range_text(r),
            r.unit,
            r.why.replace('|', "\\|")
        );
    }
    t
}

/// `key = value: must be a finite number in (lo, hi] unit` unless `value` lies there.
fn in_range(key: &str, v: f64, lo: Lo, hi: f64, unit: &str) -> Result<(), String> {
    let (ok_lo, bracket, l) = match lo {
        Lo::Open(l) => (v > l, '(', l),
        Lo::Closed(l) => (v >= l, '[', l),
    };
    if v.is_finite() && ok_lo && v <= hi {
        return Ok(());
    }
    let unit = if unit.is_empty() {
        String::new()
    } else {
        format!(" {unit}")
    };
    Err(format!(
        "{key} = {}: must be a finite number in {bracket}{}, {}]{unit}",
        shown(v),
        shown(l),
        shown(hi)
    ))
}

/// A value as a message shows it: as written for the usual magnitudes, in exponent form
/// beyond them (`1e300`, not its 301 digits).
fn shown(v: f64) -> String {
    if v == 0.0 || !v.is_finite() || (1e-4..1e16).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// A value the firmware takes as `f32`: refused when it underflows to 0 (as overflow is).
fn f32_value(key: &str, v: f64) -> Result<(), String> {
    if v != 0.0 && v.is_finite() && (v.abs() as f32) < f32::MIN_POSITIVE {
        return Err(format!(
            "{key} = {}: too small for the firmware's f32 (|value| ≥ {:e} or 0)",
            shown(v),
            f32::MIN_POSITIVE
        ));
    }
    if v.is_finite() && (v.abs() as f32).is_infinite() {
        return Err(format!(
            "{key} = {}: too large for the firmware's f32 (|value| ≤ {:e})",
            shown(v),
            f32::MAX
        ));
    }
    Ok(())
}

/// A recorded series: at least two samples, equal lengths, finite, times increasing.
fn series(key: &str, t: &[f64], name: &str, y: &[f64], max_abs: f64) -> Result<(), String> {
    if t.len() != y.len() || t.len() < 2 {
        return Err(format!(
            "{key}: t_s ({} values) and {name} ({} values) must have the same length ≥ 2",
            t.len(),
            y.len()
        ));
    }
    for (k, w) in t.windows(2).enumerate() {
        if w[1] <= w[0] || w[1].is_nan() || w[0].is_nan() || !w[1].is_finite() || !w[0].is_finite()
        {
            return Err(format!(
                "{key}.t_s[{}] = {}: times must be finite and increasing (previous {})",
                k + 1,
                w[1],
                w[0]
            ));
        }
    }
    for (k, v) in y.iter().enumerate() {
        in_range(
            &format!("{key}.{name}[{k}]"),
            *v,
            Lo::Closed(-max_abs),
            max_abs,
            "",
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn law_parameters_by_registry_name() {
        let base = "duration_s = 1.0\n[drive]\nkind = \"structure\"\n[drive.excitation]\nkind = \"sine\"\na0_m_s2 = 1.0\nfreq_hz = 0.5\n";
        let ok = Scenario::from_toml(&format!(
            "{base}[law]\nkind = \"tracking\"\nr_load_ohm = 10.0\n[law.set]\ntrk_period_s = 8.0\n"
        ))
        .unwrap();
        let c = ok.config().unwrap();
        assert_eq!(c.trk_period_s, 8.0);
        assert_eq!(c.law, LawKind::Tracking);
        let bad = Scenario::from_toml(&format!(
            "{base}[law]\nkind = \"tracking\"\n[law.set]\ntrk_period_z = 8.0\n"
        ));
        let e = bad.and_then(|s| s.config()).unwrap_err();
        assert!(e.contains("trk_period_z"), "{e}");
        let range = Scenario::from_toml(&format!(
            "{base}[law]\nkind = \"resistor\"\n[law.set]\ncurrent_bw_hz = 1.0e9\n"
        ));
        assert!(range
            .and_then(|s| s.config())
            .unwrap_err()
            .contains("current_bw_hz"));
        let opt = Scenario::from_toml(&format!(
            "{base}[law]\nkind = \"two_way\"\n[law.opt]\na = [1.0]\nb = []\nc = []\nd = []\n"
        ));
        assert!(opt
            .and_then(|s| s.config())
            .unwrap_err()
            .contains("law.opt.a"));
    }

    /// `docs/simulator.md`'s table of the scenario ranges is [`ranges_markdown`], between its
    /// two markers; `REGEN_WRITE_DOCS=1` writes it there.
    #[test]
    fn docs_ranges_table_is_the_code() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/simulator.md");
        let doc = std::fs::read_to_string(path).unwrap();
        let (a, b) = (
            "<!-- scenario ranges: hal_sim::scenario::ranges_markdown -->\n",
            "<!-- end scenario ranges -->",
        );
        let i = doc.find(a).expect("start marker") + a.len();
        let j = doc[i..].find(b).expect("end marker") + i;
        let want = ranges_markdown();
        if std::env::var("REGEN_WRITE_DOCS").is_ok() {
            std::fs::write(path, format!("{}{want}{}", &doc[..i], &doc[j..])).unwrap();
            return;
        }
        assert_eq!(
            &doc[i..j],
            want,
            "docs/simulator.md's ranges differ from RANGES: REGEN_WRITE_DOCS=1 cargo test -p hal-sim --lib docs_ranges"
        );
    }

    /// Every key of [`RANGES`] is checked: a value just outside its range is refused naming
    /// the key and the range, one inside is accepted (on the reference TMD, or an imposed
    /// motion for the motion's keys).
    #[test]
    fn every_range_is_enforced() {
        for r in RANGES {
            let below = match r.lo {
                Lo::Open(l) => l,
                Lo::Closed(l) => l - (l.abs() * 1e-3).max(1e-9),
            };
            let mut above = r.hi + (r.hi.abs() * 1e-3).max(1e-9);
            let mut below = below;
            if r.key == "machine.pole_pairs" {
                (below, above) = (0.0, r.hi + 1.0); // an integer
            }
            for (v, ok) in [(below, false), (above, false), (r.hi, true)] {
                let mut sc = if r.key.starts_with("drive.motion") {
                    Scenario::imposed(
                        crate::plant::Motion::Sine {
                            amplitude_m: 0.05,
                            freq_hz: 0.5,
                        },
                        306.0,
                        1.0,
                    )
                } else {
                    Scenario::tmd(306.0)
                };
                if !set_key(&mut sc, r.key, v) {
                    continue;
                }
                let e = if r.key == "duration_s" {
                    sc.check()
                } else {
                    sc.physics()
                };
                if ok {
                    assert!(e.is_ok(), "{} = {v}: {e:?}", r.key);
                } else {
                    let e = e.expect_err(r.key);
                    assert!(e.starts_with(&format!("{} = ", r.key)), "{e}");
                    assert!(e.contains(&range_text(r)), "{e}");
                }
            }
        }
    }

    /// Set one key of a scenario by its name; false for the keys set otherwise (the record
    /// reader's cutoff, the Kanai–Tajimi keys, the current offsets).
    fn set_key(sc: &mut Scenario, key: &str, v: f64) -> bool {
        use crate::plant::{Drive, Excitation, Motion};
        match key {
            "duration_s" => sc.duration_s = v,
            "machine.r_ohm" => sc.machine.r_ohm = v,
            "machine.l_h" => sc.machine.l_h = v,
            "machine.l_q_h" => sc.machine.l_q_h = Some(v),
            "machine.ke_v_s_per_rad" => sc.machine.ke_v_s_per_rad = v,
            "machine.pole_pairs" => sc.machine.pole_pairs = v as u32,
            "machine.angle_offset_rad" => sc.machine.angle_offset_rad = v,
            "screw.lead_m_per_rad" => sc.screw.lead_m_per_rad = v,
            "screw.j_kg_m2" => sc.screw.j_kg_m2 = v,
            "screw.b_nms" => sc.screw.b_nms = v,
            "screw.efficiency" => sc.screw.efficiency = v,
            "screw.coulomb_n" => sc.screw.coulomb_n = v,
            "screw.viscous_n_s_per_m" => sc.screw.viscous_n_s_per_m = v,
            "screw.p3" => sc.screw.p3 = v,
            "screw.p5" => sc.screw.p5 = v,
            "screw.p4" => sc.screw.p4 = v,
            "screw.p6" => sc.screw.p6 = v,
            "screw.ball_m" => sc.screw.ball_m = v,
            "screw.stick_velocity" => sc.screw.stick_velocity = v,
            "bus.capacitance_f" => sc.bus.capacitance_f = v,
            "bus.initial_v" => sc.bus.initial_v = v,
            "bus.source_v" => sc.bus.source_v = Some(v),
            "bus.source_r_ohm" => sc.bus.source_r_ohm = v,
            "bus.brake_r_ohm" => sc.bus.brake_r_ohm = v,
            "losses.k_sw_s" => sc.losses.k_sw_s = v,
            "losses.r_on_ohm" => sc.losses.r_on_ohm = v,
            "losses.logic_w" => sc.losses.logic_w = v,
            "losses.logic_min_v" => sc.losses.logic_min_v = v,
            "sensors.current_noise_a" => sc.sensors.current_noise_a = v,
            "sensors.vbus_offset_v" => sc.sensors.vbus_offset_v = v,
            "sensors.vbus_noise_v" => sc.sensors.vbus_noise_v = v,
            "law.r_load_ohm" => sc.law.r_load_ohm = v,
            _ => match &mut sc.drive {
                Drive::Imposed {
                    motion:
                        Motion::Sine {
                            amplitude_m,
                            freq_hz,
                        },
                } => match key {
                    "drive.motion.amplitude_m" => *amplitude_m = v,
                    "drive.motion.freq_hz" => *freq_hz = v,
                    _ => return false,
                },
                Drive::Structure {
                    structure,
                    excitation: Excitation::Sine { a0_m_s2, freq_hz },
                } => match key {
                    "drive.structure.mass_kg" => structure.mass_kg = v,
                    "drive.structure.stiffness_n_per_m" => structure.stiffness_n_per_m = v,
                    "drive.structure.damping_n_s_per_m" => structure.damping_n_s_per_m = v,
                    "drive.excitation.a0_m_s2" => *a0_m_s2 = v,
                    "drive.excitation.freq_hz" => *freq_hz = v,
                    _ => return false,
                },
                _ => return false,
            },
        }
        true
    }

    #[test]
    fn out_of_range_values_are_shown_short() {
        let e = in_range("duration_s", 1e300, Lo::Open(0.0), 1e5, "s").unwrap_err();
        assert_eq!(
            e,
            "duration_s = 1e300: must be a finite number in (0, 100000] s"
        );
        let e = in_range("a", -2.5, Lo::Closed(0.0), 1.0, "").unwrap_err();
        assert_eq!(e, "a = -2.5: must be a finite number in [0, 1]");
        let e = in_range("a", 3e-9, Lo::Open(1e-6), 1.0, "").unwrap_err();
        assert!(e.starts_with("a = 3e-9: "), "{e}");
        let e = in_range("a", f64::NAN, Lo::Open(0.0), 1.0, "").unwrap_err();
        assert!(e.starts_with("a = NaN: "), "{e}");
    }

    #[test]
    fn bad_files_name_the_key() {
        let e = Scenario::from_toml("duration_s = 1.0\n[drive]\nkind = \"structure\"\n[drive.excitation]\nkind = \"sine\"\na0_m_s2 = 1.0\nfreq_hz = 0.5\n[machine]\nr_ohmm = 3.0\n").unwrap_err();
        assert!(e.contains("r_ohmm") && e.contains("line"), "{e}");
        let e = Scenario::from_toml("duration_s = -1.0\n[drive]\nkind = \"imposed\"\n[drive.motion]\nkind = \"sine\"\namplitude_m = 0.01\nfreq_hz = 1.0\n").unwrap_err();
        assert!(e.contains("duration_s"), "{e}");
        let e = Scenario::from_toml("[drive]\nkind = \"imposed\"\n[drive.motion]\nkind = \"sine\"\namplitude_m = 0.01\nfreq_hz = 1.0\n[firmware]\ncurrent_bw_hz = 9000.0\n").unwrap_err();
        assert!(e.contains("current_bw_hz"), "{e}");
        let ok = Scenario::from_toml("[drive]\nkind = \"imposed\"\n[drive.motion]\nkind = \"sine\"\namplitude_m = 0.01\nfreq_hz = 1.0\n").unwrap();
        assert_eq!(ok.law.r_load_ohm, 306.0);
    }
}
