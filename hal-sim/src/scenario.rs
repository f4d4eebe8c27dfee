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

use crate::plant::{Bus, Drive, Excitation, Inverter, Losses, Machine, Screw, Sensors};
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
    #[serde(default)]
    pub firmware: FirmwareSpec,
    #[serde(default)]
    pub law: LawSpec,
    #[serde(default)]
    pub record: RecordSpec,
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
        let s: Scenario = toml::from_str(text).map_err(|e| e.to_string())?;
        s.check()?;
        Ok(s)
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
            firmware: FirmwareSpec::default(),
            law: LawSpec {
                r_load_ohm,
                ..LawSpec::default()
            },
            record: RecordSpec::default(),
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

    fn check(&self) -> Result<(), String> {
        if !(self.duration_s.is_finite() && self.duration_s > 0.0 && self.duration_s <= 1e5) {
            return Err("duration_s: must be a positive number of seconds (≤ 1e5)".into());
        }
        if !(self.settle_s >= 0.0 && self.settle_s < self.duration_s) {
            return Err("settle_s: must lie in [0, duration_s)".into());
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
            law: self.law_kind()?,
            r_load_ohm: self.law.r_load_ohm as f32,
            ..Config::default()
        };
        c.validate().map_err(|e| format!("firmware.{e}"))?;
        if let Some(o) = &self.law.opt {
            c.opt = o.params()?;
        }
        for (name, v) in &self.law.set {
            let p = regen_fw::params::find(name)
                .ok_or_else(|| format!("law.set.{name}: unknown parameter"))?;
            p.apply(&mut c, *v as f32, false)
                .map_err(|e| format!("law.set.{name} = {v}: {e}"))?;
        }
        Ok(c)
    }

    /// The drive with recorded files loaded.
    fn loaded_drive(&self) -> Result<Drive, String> {
        let mut d = self.drive.clone();
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

    /// The simulation, recording the chosen channels.
    pub fn build(&self) -> Result<Sim, String> {
        let rig = Rig {
            machine: self.machine,
            screw: self.screw,
            drive: self.loaded_drive()?,
            bus: self.bus,
            inverter: self.inverter,
            losses: self.losses,
            sensors: self.sensors,
        };
        let mut sim = Sim::new(rig, &self.config()?)?;
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
