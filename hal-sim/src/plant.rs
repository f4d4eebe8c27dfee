//! The plant: machine, screw (inertia, viscosity, efficiency, friction), what drives the screw
//! (imposed motion or a structure with base excitation), the DC bus with its source/sink and
//! brake resistor, the drive's losses and the sensors.
//!
//! Every part is a plain parameter struct (serde, so scenario files can name every field) plus
//! the few pure functions the simulation step needs. Units are SI throughout.

use crate::fastmath::{Gauss, SinCos};
use serde::{Deserialize, Serialize};
use std::f64::consts::{PI, TAU};

/// Electrical machine and ballscrew of the device.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct Machine {
    /// Phase resistance, line-to-neutral, Ω.
    pub r_ohm: f64,
    /// Phase inductance of the d axis, line-to-neutral, H; with `l_q_h` absent the machine is
    /// non-salient and this is both axes' (L_d = L_q).
    pub l_h: f64,
    /// Phase inductance of the q axis, line-to-neutral, H (a salient machine: the dq voltage
    /// equations with their cross-coupling and the reluctance torque, `crate::sim`); absent:
    /// `l_h`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub l_q_h: Option<f64>,
    /// Back-emf constant, per-phase PEAK, V·s/rad mechanical (`e_q = K_e·ω_m`,
    /// `T = 3/2·K_e·i_q`). Default: the firmware's, 0.77·√(3/2) = 0.943 (see the doc of
    /// `regen_fw::Config::ke_v_s_per_rad` and `docs/simulator.md` §K_e).
    pub ke_v_s_per_rad: f64,
    /// Pole pairs.
    pub pole_pairs: u32,
    /// Electrical angle of the d axis at mechanical angle 0 (rad).
    pub angle_offset_rad: f64,
}

impl Default for Machine {
    fn default() -> Self {
        Machine {
            r_ohm: 2.41,
            l_h: 6.0e-3,
            l_q_h: None,
            ke_v_s_per_rad: regen_fw::Config::default().ke_v_s_per_rad as f64,
            pole_pairs: 5,
            angle_offset_rad: 0.0,
        }
    }
}

impl Machine {
    /// The d axis's inductance, H.
    pub fn l_d(&self) -> f64 {
        self.l_h
    }
    /// The q axis's inductance, H (`l_q_h`, else `l_h`).
    pub fn l_q(&self) -> f64 {
        self.l_q_h.unwrap_or(self.l_h)
    }
    /// L_d ≠ L_q.
    pub fn salient(&self) -> bool {
        self.l_q() != self.l_h
    }
}

/// Ballscrew and shaft (eq. 1–3 and 13 of the reference).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct Screw {
    /// Lead, m/rad.
    pub lead_m_per_rad: f64,
    /// Rotary inertia of motor shaft + screw, kg·m².
    pub j_kg_m2: f64,
    /// Rotary viscosity, N·m·s/rad.
    pub b_nms: f64,
    /// Conversion efficiency η ∈ (0, 1]; 1 disables the quadrant-dependent h(f·ẋ).
    pub efficiency: f64,
    /// Coulomb friction p1, N.
    pub coulomb_n: f64,
    /// Linear viscous friction p2, N·s/m.
    pub viscous_n_s_per_m: f64,
    /// Ripple amplitudes p3 (one per screw revolution) and p5 (one per ball diameter), and
    /// phases p4, p6 (rad).
    pub p3: f64,
    pub p4: f64,
    pub p5: f64,
    pub p6: f64,
    /// Ball diameter r, m (λ2 = 2π/r).
    pub ball_m: f64,
    /// Velocity below which the Coulomb term is linearised (regularised sign), m/s.
    pub stick_velocity: f64,
}

impl Default for Screw {
    fn default() -> Self {
        Screw {
            lead_m_per_rad: 0.016 / TAU,
            j_kg_m2: 1.50e-4,
            b_nms: 0.0,
            efficiency: 1.0,
            coulomb_n: 40.0,
            viscous_n_s_per_m: 655.0,
            p3: 0.0,
            p4: 0.0,
            p5: 0.0,
            p6: 0.0,
            ball_m: 1.7e-3,
            stick_velocity: 1e-4,
        }
    }
}

impl Screw {
    /// Reflected mass J/l², kg.
    pub fn reflected_mass(&self) -> f64 {
        self.j_kg_m2 / (self.lead_m_per_rad * self.lead_m_per_rad)
    }
    /// Reflected viscosity B/l², N·s/m.
    pub fn reflected_viscosity(&self) -> f64 {
        self.b_nms / (self.lead_m_per_rad * self.lead_m_per_rad)
    }
    /// Friction force f_d(x, ẋ) of eq. 13 (regularised sign near zero speed).
    pub fn friction(&self, x: f64, v: f64) -> f64 {
        let sgn = (v / self.stick_velocity).clamp(-1.0, 1.0);
        let mut ripple = 1.0;
        if self.p3 != 0.0 {
            ripple += self.p3 * (x / self.lead_m_per_rad + self.p4).sin();
        }
        if self.p5 != 0.0 {
            ripple += self.p5 * (TAU / self.ball_m * x + self.p6).sin();
        }
        self.coulomb_n * ripple * sgn + self.viscous_n_s_per_m * v
    }
    /// h(f·ẋ): 1/η when power flows into the device, η otherwise.
    pub fn h(&self, power_in: bool) -> f64 {
        if power_in {
            1.0 / self.efficiency
        } else {
            self.efficiency
        }
    }
}

/// An imposed motion of the screw (the bench's hydraulic actuator).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Motion {
    /// x = A·sin(2π f t).
    Sine { amplitude_m: f64, freq_hz: f64 },
    /// Symmetric triangle of amplitude A (constant speed 4·A·f), starting at 0 going up.
    Triangle { amplitude_m: f64, freq_hz: f64 },
    /// Recorded trajectory: times (s) and positions (m), linearly interpolated; with
    /// `v_m_s` given, the position is the cubic Hermite curve through the samples with those
    /// velocities, and velocity and acceleration are linearly interpolated from `v_m_s`,
    /// `a_m_s2` (else the slope of the position segments and 0).
    Recorded {
        t_s: Vec<f64>,
        x_m: Vec<f64>,
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        v_m_s: Vec<f64>,
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        a_m_s2: Vec<f64>,
        /// The velocity through the acceleration's band, where `v_m_s` came through a wider
        /// one (a record read by the diagnosis's reader): the pair with `a_m_s2` that a model
        /// integrating a motion from v and a together walks (the play's device,
        /// [`Motion::v_kin_at`]); empty: `v_m_s`.
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        v_kin_m_s: Vec<f64>,
    },
    /// The motion of a record in the `diagnose` schema (CSV `t_s, x_m, f_N`, docs/diagnose.md),
    /// replayed: read when the scenario is built, velocity and acceleration derived by the
    /// diagnosis's reader (zero-phase Butterworth-2 at `cutoff_hz`, default fs/20 at most 50 Hz, then central
    /// differences) or taken from its `v_m_s`, `a_m_s2` columns, so the replay moves as the
    /// diagnosis saw the record move.
    Record {
        path: String,
        #[serde(default)]
        cutoff_hz: Option<f64>,
    },
}

impl Motion {
    /// [`Motion::at`] for a caller stepping through time: a sine's sin/cos is rotated from
    /// the previous call's (`rot`, one per sequence of times; see [`SinCos`]).
    #[inline]
    pub fn at_tracked(&self, rot: &mut SinCos, t: f64) -> (f64, f64, f64) {
        match self {
            Motion::Sine {
                amplitude_m: a,
                freq_hz: f,
            } => {
                let w = TAU * f;
                let (s, c) = rot.at(w * t);
                (a * s, a * w * c, -a * w * w * s)
            }
            _ => self.at(t),
        }
    }

    /// The velocity through the acceleration's band at time t (`Motion::Recorded`'s
    /// `v_kin_m_s`, linearly interpolated), when the motion carries one; else `v`.
    pub fn v_kin_at(&self, t: f64, v: f64) -> f64 {
        match self {
            Motion::Recorded { t_s, v_kin_m_s, .. }
                if v_kin_m_s.len() >= 2 && v_kin_m_s.len() == t_s.len() =>
            {
                if t > t_s[t_s.len() - 1] {
                    return 0.0;
                }
                let (k, tt, dt) = recorded_segment(t_s, t);
                v_kin_m_s[k] + (v_kin_m_s[k + 1] - v_kin_m_s[k]) * tt / dt
            }
            _ => v,
        }
    }

    /// (x, ẋ, ẍ) at time t.
    pub fn at(&self, t: f64) -> (f64, f64, f64) {
        match self {
            Motion::Sine {
                amplitude_m: a,
                freq_hz: f,
            } => {
                let w = TAU * f;
                let (s, c) = (w * t).sin_cos();
                (a * s, a * w * c, -a * w * w * s)
            }
            Motion::Triangle {
                amplitude_m: a,
                freq_hz: f,
            } => {
                let ph = (t * f + 0.25).rem_euclid(1.0); // 0.25 → x = 0 rising at t = 0
                let v = 4.0 * a * f;
                if ph < 0.5 {
                    (a * (4.0 * ph - 1.0), v, 0.0)
                } else {
                    (a * (3.0 - 4.0 * ph), -v, 0.0)
                }
            }
            Motion::Recorded {
                t_s,
                x_m,
                v_m_s,
                a_m_s2,
                ..
            } => {
                let n = t_s.len().min(x_m.len());
                if n < 2 {
                    return (x_m.first().copied().unwrap_or(0.0), 0.0, 0.0);
                }
                let (k, tt, dt) = recorded_segment(&t_s[..n], t);
                let v = (x_m[k + 1] - x_m[k]) / dt;
                let after = t > t_s[n - 1];
                let lerp = |c: &[f64]| {
                    if after || c.len() < n {
                        0.0
                    } else {
                        c[k] + (c[k + 1] - c[k]) * tt / dt
                    }
                };
                if v_m_s.len() >= n && !after {
                    // cubic Hermite position through the samples with the given velocities
                    // (a smooth path: a drive's encoder and emf see no velocity steps)
                    let s = tt / dt;
                    let (s2, s3) = (s * s, s * s * s);
                    let x = (2.0 * s3 - 3.0 * s2 + 1.0) * x_m[k]
                        + (s3 - 2.0 * s2 + s) * dt * v_m_s[k]
                        + (3.0 * s2 - 2.0 * s3) * x_m[k + 1]
                        + (s3 - s2) * dt * v_m_s[k + 1];
                    return (x, lerp(v_m_s), lerp(a_m_s2));
                }
                (x_m[k] + v * tt, if after { 0.0 } else { v }, lerp(a_m_s2))
            }
            // Replaced by `Recorded` when the scenario is built.
            Motion::Record { .. } => (0.0, 0.0, 0.0),
        }
    }
}

/// The segment of recorded times `t_s` (at least 2) that holds time t: its first sample k,
/// the time into it (clamped to the segment) and its length.
fn recorded_segment(t_s: &[f64], t: f64) -> (usize, f64, f64) {
    let n = t_s.len();
    let k = match t_s.binary_search_by(|p| p.total_cmp(&t)) {
        Ok(k) => k.min(n - 2),
        Err(k) => k.saturating_sub(1).min(n - 2),
    };
    let dt = t_s[k + 1] - t_s[k];
    (k, (t - t_s[k]).clamp(0.0, dt), dt)
}

/// Base (ground) acceleration driving a structure.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Excitation {
    /// a(t) = a0·sin(2π f t).
    Sine { a0_m_s2: f64, freq_hz: f64 },
    /// Symmetric triangle wave of peak a0.
    Triangle { a0_m_s2: f64, freq_hz: f64 },
    /// Kanai–Tajimi filtered white noise: ground acceleration of a soil layer (ω_g, ζ_g)
    /// excited by seeded white noise of one-sided spectral density `s0` ((m/s²)²/(rad/s)).
    KanaiTajimi {
        s0: f64,
        omega_g: f64,
        zeta_g: f64,
        seed: u64,
    },
    /// Recorded ground acceleration, linearly interpolated (zero outside).
    Recorded { t_s: Vec<f64>, a_m_s2: Vec<f64> },
    /// Recorded ground acceleration from a CSV file of `t_s,a_m_s2` rows (an optional header
    /// line; `#` comments), read when the scenario is built (see [`read_series_csv`]).
    RecordedCsv { path: String },
}

/// Read a two-column CSV time series (`t, value`): optional header, `#` comments, times
/// strictly increasing, every value finite. Errors name the file and line.
pub fn read_series_csv(path: &std::path::Path) -> Result<(Vec<f64>, Vec<f64>), String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let (mut t, mut v) = (Vec::new(), Vec::new());
    for (n, line) in text.lines().enumerate() {
        let l = line.trim();
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let cols: Vec<&str> = l.split(',').map(str::trim).collect();
        let parsed: Option<Vec<f64>> = cols.iter().map(|c| c.parse::<f64>().ok()).collect();
        let Some(p) = parsed else {
            if t.is_empty() && n == 0 {
                continue; // header
            }
            return Err(format!(
                "{}:{}: not two numbers: `{l}`",
                path.display(),
                n + 1
            ));
        };
        if p.len() != 2 || !p.iter().all(|x| x.is_finite()) {
            return Err(format!(
                "{}:{}: expected two finite numbers `t,value`, got `{l}`",
                path.display(),
                n + 1
            ));
        }
        if let Some(&last) = t.last() {
            if p[0] <= last {
                return Err(format!("{}:{}: time not increasing", path.display(), n + 1));
            }
        }
        t.push(p[0]);
        v.push(p[1]);
    }
    if t.len() < 2 {
        return Err(format!("{}: fewer than two samples", path.display()));
    }
    Ok((t, v))
}

/// A sine excitation a(t) = a0·sin(w·t) with w = 2π·f taken once ([`Excitation::sine`]):
/// [`Excitation::next`]'s sine, which a caller may hold instead of the excitation (the
/// simulator's common period, `crate::sim`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SineExcitation {
    a0: f64,
    w: f64,
}

impl SineExcitation {
    /// [`Excitation::next`] of the sine: its value at the step's middle, t + dt/2.
    #[inline(always)]
    pub fn next(self, st: &mut ExcitationState, t: f64, dt: f64) -> f64 {
        self.a0 * st.rot.at(self.w * (t + dt / 2.0)).0
    }
}

/// State of an excitation: noise filter and generator, the sine's incremental sin/cos, the
/// recorded series' cursor.
#[derive(Clone, Debug, Default)]
pub struct ExcitationState {
    rng: u64,
    xg: f64,
    vg: f64,
    gauss: Gauss,
    rot: SinCos,
    /// (dt, √(π·s0/dt)) of the last Kanai–Tajimi step.
    kt_scale: (f64, f64),
    cursor: usize,
}

impl Excitation {
    pub fn state(&self) -> ExcitationState {
        let seed = match self {
            Excitation::KanaiTajimi { seed, .. } => *seed,
            _ => 0,
        };
        ExcitationState {
            rng: seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1,
            ..Default::default()
        }
    }

    /// Ground acceleration over the step [t, t+dt] (held constant over the step).
    #[inline(always)]
    pub fn next(&self, st: &mut ExcitationState, t: f64, dt: f64) -> f64 {
        match self.sine() {
            Some(sine) => sine.next(st, t, dt),
            None => self.next_other(st, t, dt),
        }
    }

    /// A sine's constants ([`SineExcitation`]); `None` for every other kind.
    #[inline(always)]
    pub fn sine(&self) -> Option<SineExcitation> {
        match self {
            Excitation::Sine { a0_m_s2, freq_hz } => Some(SineExcitation {
                a0: *a0_m_s2,
                w: TAU * freq_hz,
            }),
            _ => None,
        }
    }

    /// [`Excitation::next`] for everything but the sine, out of line so that the common
    /// period stays compact.
    #[inline(never)]
    fn next_other(&self, st: &mut ExcitationState, t: f64, dt: f64) -> f64 {
        match self {
            Excitation::Sine { .. } => self.next(st, t, dt),
            Excitation::Triangle { a0_m_s2, freq_hz } => {
                let ph = ((t + dt / 2.0) * freq_hz + 0.25).rem_euclid(1.0);
                if ph < 0.5 {
                    a0_m_s2 * (4.0 * ph - 1.0)
                } else {
                    a0_m_s2 * (3.0 - 4.0 * ph)
                }
            }
            Excitation::KanaiTajimi {
                s0,
                omega_g,
                zeta_g,
                ..
            } => {
                // White noise w of two-sided density s0/2 per rad/s held over dt: variance
                // π·s0/dt. Filter: ẍg + 2ζω ẋg + ω² xg = −w; a = −(2ζω ẋg + ω² xg).
                if st.kt_scale.0 != dt {
                    st.kt_scale = (dt, (PI * s0 / dt).sqrt());
                }
                let g = st.gauss.sample(&mut st.rng) * st.kt_scale.1;
                let acc = -g - 2.0 * zeta_g * omega_g * st.vg - omega_g * omega_g * st.xg;
                st.vg += acc * dt;
                st.xg += st.vg * dt;
                -(2.0 * zeta_g * omega_g * st.vg + omega_g * omega_g * st.xg)
            }
            // Replaced by `Recorded` when the scenario is built.
            Excitation::RecordedCsv { .. } => 0.0,
            Excitation::Recorded { t_s, a_m_s2 } => {
                let n = t_s.len().min(a_m_s2.len());
                let tm = t + dt / 2.0;
                if n < 2 || tm < t_s[0] || tm > t_s[n - 1] {
                    return 0.0;
                }
                // Runs step forward: try the last segment and the next before searching.
                let c = st.cursor.min(n - 2);
                let k = if t_s[c] <= tm && tm < t_s[c + 1] {
                    c
                } else if c + 2 < n && t_s[c + 1] <= tm && tm < t_s[c + 2] {
                    c + 1
                } else {
                    t_s[..n]
                        .partition_point(|p| *p <= tm)
                        .saturating_sub(1)
                        .min(n - 2)
                };
                st.cursor = k;
                let f = (tm - t_s[k]) / (t_s[k + 1] - t_s[k]);
                a_m_s2[k] + f * (a_m_s2[k + 1] - a_m_s2[k])
            }
        }
    }
}

/// A single-degree-of-freedom structure (or TMD) with the device between mass and base:
/// `m·ẍ + c·ẋ + k·x + f_device = m·a_g(t)` (x relative to the base).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct Structure {
    pub mass_kg: f64,
    pub stiffness_n_per_m: f64,
    /// Structural damping besides the device, N·s/m.
    pub damping_n_s_per_m: f64,
}

impl Default for Structure {
    /// The reference TMD: 400 kg, natural period 2 s (k = m·π²), no damping of its own.
    fn default() -> Self {
        Structure {
            mass_kg: 400.0,
            stiffness_n_per_m: 400.0 * PI * PI,
            damping_n_s_per_m: 0.0,
        }
    }
}

/// DC bus: capacitor, a stiff source/sink (battery or supply through a resistance; `None`
/// = none), a brake resistor switched by the firmware's chopper output.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct Bus {
    pub capacitance_f: f64,
    pub initial_v: f64,
    /// Source/sink EMF, V, and its internal resistance, Ω (absorbs regenerated power).
    pub source_v: Option<f64>,
    pub source_r_ohm: f64,
    /// Brake resistor, Ω.
    pub brake_r_ohm: f64,
}

impl Default for Bus {
    fn default() -> Self {
        Bus {
            capacitance_f: 1.0e-3,
            initial_v: 320.0,
            source_v: Some(320.0),
            source_r_ohm: 0.1,
            brake_r_ohm: 50.0,
        }
    }
}

/// The inverter model.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct Inverter {
    /// Resolve the centre-aligned PWM pattern within each period (seven constant-voltage
    /// segments, each solved exactly) instead of the per-period average.
    pub switched: bool,
    /// Dead time per edge, s: during it the leg's diode conducts, so a phase whose current
    /// flows out of the leg (i > 0) loses `dead_time` of high time per period, one whose
    /// current flows in gains it (current sign at the start of the period).
    pub dead_time_s: f64,
}

impl Default for Inverter {
    fn default() -> Self {
        Inverter {
            switched: false,
            dead_time_s: 0.0,
        }
    }
}

/// Drive losses: switching `k_sw·f_pwm·V_bus·Σ|i_k|`, conduction `R_on·Σi_k²`, logic supply.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct Losses {
    /// Switching energy per (volt·ampere) per PWM period, s ((t_rise + t_fall)/2).
    pub k_sw_s: f64,
    /// On-resistance of one switch, Ω.
    pub r_on_ohm: f64,
    /// Logic supply, W (taken from the bus while the gates are enabled or not).
    pub logic_w: f64,
    /// The logic supply's under-voltage lockout, V: with the bus below it the supply draws
    /// nothing (a converter does not hold its power into a collapsing input; a constant
    /// power drawn from a bus near zero would drive it negative).
    pub logic_min_v: f64,
}

impl Default for Losses {
    fn default() -> Self {
        Losses {
            k_sw_s: 50e-9,
            r_on_ohm: 0.02,
            logic_w: 2.0,
            logic_min_v: 10.0,
        }
    }
}

/// Sensor imperfections.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct Sensors {
    /// Current-sensor offset, A, per phase.
    pub current_offset_a: [f64; 3],
    /// RMS current noise, A.
    pub current_noise_a: f64,
    /// Bus-voltage offset, V, and RMS noise, V.
    pub vbus_offset_v: f64,
    pub vbus_noise_v: f64,
    /// Noise seed.
    pub seed: u64,
    /// Current sampling as the board does it (`crate::sampling`; off by default).
    pub shunt: crate::sampling::ShuntSampling,
}

impl Default for Sensors {
    fn default() -> Self {
        Sensors {
            current_offset_a: [0.0; 3],
            current_noise_a: 0.0,
            vbus_offset_v: 0.0,
            vbus_noise_v: 0.0,
            seed: 1,
            shunt: Default::default(),
        }
    }
}

impl Sensors {
    /// A normal deviate from the sensors' generator (xorshift64* state, ziggurat; see
    /// [`crate::fastmath::Gauss`]).
    pub fn noise(state: &mut u64) -> f64 {
        Gauss::default().sample(state)
    }
}

/// What moves the screw.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Drive {
    /// The screw follows a motion (the bench's actuator).
    Imposed { motion: Motion },
    /// The device sits in a structure under base excitation.
    Structure {
        #[serde(default)]
        structure: Structure,
        excitation: Excitation,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangle_and_sine_are_consistent() {
        let m = Motion::Triangle {
            amplitude_m: 0.05,
            freq_hz: 0.25,
        };
        assert!(m.at(0.0).0.abs() < 1e-12);
        assert!((m.at(1.0).0 - 0.05).abs() < 1e-12); // quarter period
        assert!((m.at(3.0).0 + 0.05).abs() < 1e-12);
        assert!((m.at(0.5).1 - 0.05).abs() < 1e-12);
        let s = Motion::Sine {
            amplitude_m: 0.075,
            freq_hz: 0.1,
        };
        let (x, v, _) = s.at(0.0);
        assert!(x.abs() < 1e-12 && (v - 0.075 * TAU * 0.1).abs() < 1e-12);
    }

    #[test]
    fn friction_is_odd_in_speed_without_ripple() {
        let s = Screw::default();
        assert!((s.friction(0.0, 0.1) + s.friction(0.0, -0.1)).abs() < 1e-9);
        assert!((s.friction(0.0, 0.1) - (40.0 + 65.5)).abs() < 1e-9);
    }
}
