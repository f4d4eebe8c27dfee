//! Protection: fault codes, the safe state of each fault, the snapshot taken at a trip, the
//! decimated supervision (I²t, force rating, stroke, speed and encoder plausibility,
//! current-sensor consistency, loop overrun) and the DC-bus regenerative derating.
//!
//! Split by urgency (see `docs/protection.md`):
//! * **In the current loop** ([`crate::Controller::step`], every period): phase over-current,
//!   bus over- and under-voltage, encoder jump (compares on values the loop has anyway), and
//!   one multiply applying the precomputed derate factor to a regenerative q-current
//!   reference ([`derate_regen`]).
//! * **Supervision** ([`crate::Controller::supervise`], [`SUPERVISE_HZ`] = 1 kHz): everything
//!   that is a filter, an integral or a persistence count. It reads the loop's last telemetry,
//!   runs in `f32` (the Cortex-M4F has a single-precision FPU; `+ − × ÷` are correctly rounded
//!   IEEE-754, so host and board agree bit for bit) and never calls libm.
//!
//! Faults latch: the first one is kept with a [`Snapshot`] of the measurements; later ones
//! are added to a bit mask. A fault is cleared only by command and only once its cause is gone
//! ([`Protection::cause_present`]).

use crate::config::Config;
use crate::control::{Mode, Telemetry};
use crate::frames::Dq;
use crate::fx::{mul, Q};
use crate::numtext::q_f32;

/// Rate of [`crate::Controller::supervise`], Hz.
pub const SUPERVISE_HZ: f32 = 1_000.0;

/// Encoder/emf mismatch: the back-emf the current loop needs may exceed `K_e·|ω|` by this
/// fraction (plus `enc_emf_tol_v`) before it counts as a mismatch (model error in K_e, R, L).
pub const EMF_REL_TOL: f32 = 0.5;
/// Supervision ticks (ms) the emf mismatch must accumulate to trip (leaky count).
pub const EMF_TICKS: u16 = 20;
/// Supervision ticks (ms) the phase-current sum must accumulate to trip (leaky count).
pub const ISUM_TICKS: u16 = 5;
/// Supervision ticks (net, leaky) of an emf off the q axis before `angle_implausible`: 20 ms,
/// a tenth of a period of the fastest structural motion (5 Hz) while the PI (1 kHz) and the
/// emf settle within a few ms.
pub const ANGLE_TICKS: u16 = 20;
/// I²t state (1 = the machine's rated temperature rise) below which a trip may be cleared.
pub const I2T_CLEAR: f32 = 0.8;
/// The filtered force must fall below this fraction of `f_trip_n` to clear an over-force trip.
pub const FORCE_CLEAR: f32 = 0.9;
/// Supervision ticks of each of the two windows whose larger speed maximum is the recent
/// peak speed ([`Protection::speed_peak`]): the last 2.5 s to 5 s. |ω| peaks twice per
/// motion period, so the windows hold the peak of any motion whose period is at most 5 s
/// (0.2 Hz and up).
pub const PEAK_TICKS: u32 = 2_500;

/// A latched fault. The discriminant is its code (console, logs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Fault {
    /// A phase current exceeded `i_trip_a` (instantaneous, in the loop).
    OverCurrent = 1,
    /// The bus voltage exceeded `v_bus_ov` (instantaneous).
    BusOverVoltage = 2,
    /// The bus voltage fell below `v_bus_uv` while running (instantaneous).
    BusUnderVoltage = 3,
    /// The encoder count jumped by more than a plausible amount in one period (instantaneous).
    EncoderImplausible = 4,
    /// The filtered electromagnetic force exceeded `f_trip_n` (the device rating).
    OverForce = 5,
    /// The machine's I²t thermal estimate reached its rated temperature rise.
    MachineI2t = 6,
    /// The voltage the current loop needs says the machine turns while the encoder says
    /// otherwise (encoder stuck, disconnected or slipping).
    EncoderLoss = 7,
    /// The measured speed exceeds `omega_max_rad_s`.
    SpeedImplausible = 8,
    /// The travel left `[x_min_m, x_max_m]`.
    StrokeLimit = 9,
    /// The current loop overran its period too often (`overrun_max`).
    LoopOverrun = 10,
    /// The three phase currents do not sum to zero (sensor stuck, offset jump, noise).
    CurrentSensor = 11,
    /// The bus reading jumped to the ADC's rail: a sensor or divider fault, not an
    /// over-voltage (a true bus passes `v_bus_ov`, below the rail, first).
    BusSensor = 12,
    /// The back-emf the current loop needs lies more than `angle_tol_deg` from the q axis of
    /// the angle in use (commutation angle wrong: the law would motor).
    AngleImplausible = 13,
    /// Alignment: the rotor moved too fast for the emf probe (its emf above the bus) for
    /// 1.5 s, or, still enough for the d-axis steps, did not settle or travelled beyond
    /// `align_travel_m` (rotor driven by the structure).
    AlignMoving = 14,
    /// Power-up alignment: the quarter-turn check step moved the rotor by the wrong angle
    /// (rotor blocked, encoder dead or reversed, wrong pole count or counts per turn).
    AlignCheck = 15,
    /// Boot calibration: a phase's zero-current code lies more than `offset_tol_a` from
    /// `adc_zero_code`.
    CurrentOffset = 16,
    /// Alignment's emf probe: the encoder's electrical travel disagrees with the back-emf's
    /// (encoder reversed, wrong counts per turn or pole count).
    EncoderMismatch = 17,
}

impl Fault {
    /// Every fault, in code order.
    pub const ALL: &'static [Fault] = &[
        Fault::OverCurrent,
        Fault::BusOverVoltage,
        Fault::BusUnderVoltage,
        Fault::EncoderImplausible,
        Fault::OverForce,
        Fault::MachineI2t,
        Fault::EncoderLoss,
        Fault::SpeedImplausible,
        Fault::StrokeLimit,
        Fault::LoopOverrun,
        Fault::CurrentSensor,
        Fault::BusSensor,
        Fault::AngleImplausible,
        Fault::AlignMoving,
        Fault::AlignCheck,
        Fault::CurrentOffset,
        Fault::EncoderMismatch,
    ];

    /// Numeric code.
    pub fn code(self) -> u8 {
        self as u8
    }

    /// Fault from its code.
    pub fn from_code(c: u8) -> Option<Fault> {
        Self::ALL.iter().copied().find(|f| f.code() == c)
    }

    /// Console name.
    pub fn name(self) -> &'static str {
        match self {
            Fault::OverCurrent => "over_current",
            Fault::BusOverVoltage => "bus_over_voltage",
            Fault::BusUnderVoltage => "bus_under_voltage",
            Fault::EncoderImplausible => "encoder_implausible",
            Fault::OverForce => "over_force",
            Fault::MachineI2t => "machine_i2t",
            Fault::EncoderLoss => "encoder_loss",
            Fault::SpeedImplausible => "speed_implausible",
            Fault::StrokeLimit => "stroke_limit",
            Fault::LoopOverrun => "loop_overrun",
            Fault::CurrentSensor => "current_sensor",
            Fault::BusSensor => "bus_sensor",
            Fault::AngleImplausible => "angle_implausible",
            Fault::AlignMoving => "align_moving",
            Fault::AlignCheck => "align_check",
            Fault::CurrentOffset => "current_offset",
            Fault::EncoderMismatch => "encoder_mismatch",
        }
    }

    /// One sentence for the console (`faults`).
    pub fn describe(self) -> &'static str {
        match self {
            Fault::OverCurrent => "a phase current exceeded i_trip_a",
            Fault::BusOverVoltage => "bus voltage above v_bus_ov",
            Fault::BusUnderVoltage => "bus voltage below v_bus_uv while running",
            Fault::EncoderImplausible => "encoder count jumped implausibly in one period",
            Fault::OverForce => "force above the device rating f_trip_n",
            Fault::MachineI2t => "machine I2t thermal estimate at its rated temperature rise",
            Fault::EncoderLoss => {
                "back-emf seen by the current loop disagrees with the encoder speed"
            }
            Fault::SpeedImplausible => "speed above omega_max_rad_s",
            Fault::StrokeLimit => "travel outside x_min_m .. x_max_m",
            Fault::LoopOverrun => "current loop overran its period too often",
            Fault::CurrentSensor => "phase currents do not sum to zero (sensor fault)",
            Fault::BusSensor => "bus reading at ADC rail",
            Fault::AngleImplausible => "back-emf off the q axis by more than angle_tol_deg",
            Fault::AlignMoving => {
                "rotor moved during alignment (emf above the bus, or not settled for the steps)"
            }
            Fault::AlignCheck => "alignment check step moved the rotor by the wrong angle",
            Fault::CurrentOffset => "a phase's zero-current code beyond offset_tol_a",
            Fault::EncoderMismatch => {
                "encoder travel disagrees with the back-emf's (direction, counts per turn, poles)"
            }
        }
    }

    /// The state the drive goes to (argued per fault in `docs/protection.md`).
    /// * Open (gates off, [`Mode::Idle`]): over-current (the fault may be in the bridge; no
    ///   current through it), under-voltage (no bus, no controlled switching), over-force and
    ///   I²t (a short would brake harder and keep heating: its current reaches
    ///   `K_e/(p·L)`), loop overrun (the loop that would supervise a short is the one that is
    ///   late) and current-sensor faults (the over-current check itself is blind).
    /// * Shorted ([`Mode::Short`], low sides on): over-voltage (no energy reaches the bus),
    ///   encoder faults and implausible speed (the short needs no angle), stroke limit (brake
    ///   hardest before the end stop), a wrong angle and a failed alignment (the short damps
    ///   the structure without an angle, so a moving structure slows down for a retry).
    pub const fn safe_mode(self) -> Mode {
        match self {
            Fault::OverCurrent
            | Fault::BusUnderVoltage
            | Fault::OverForce
            | Fault::MachineI2t
            | Fault::LoopOverrun
            | Fault::CurrentSensor
            | Fault::BusSensor
            | Fault::CurrentOffset => Mode::Idle,
            Fault::BusOverVoltage
            | Fault::EncoderImplausible
            | Fault::EncoderLoss
            | Fault::SpeedImplausible
            | Fault::StrokeLimit
            | Fault::AngleImplausible
            | Fault::AlignMoving
            | Fault::AlignCheck
            | Fault::EncoderMismatch => Mode::Short,
        }
    }

    pub(crate) const fn bit(self) -> u32 {
        1 << self as u8
    }
}

/// Measurements at the moment of a trip.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Snapshot {
    /// Supervision ticks (ms) since start.
    pub t_ms: u32,
    /// Mode the drive was in.
    pub mode: Mode,
    pub i_abc: [Q; 3],
    pub i_dq: Dq,
    pub v_bus: Q,
    pub omega_m: Q,
    pub x: Q,
    /// Filtered electromagnetic force, N.
    pub force_n: f32,
    /// I²t state (1 = rated temperature rise).
    pub i2t: f32,
    /// Regenerative derate factor in force.
    pub derate: f32,
}

/// The latched fault record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Record {
    pub fault: Fault,
    pub snap: Snapshot,
    /// Faults that tripped after the first one (bit `code`).
    pub later: u32,
}

impl Record {
    /// Later faults, in code order.
    pub fn later(&self) -> impl Iterator<Item = Fault> + '_ {
        Fault::ALL
            .iter()
            .copied()
            .filter(|f| self.later & f.bit() != 0)
    }
}

/// Non-latching conditions (shown by `status` and `faults`).
pub mod warn {
    /// The regenerative current is being derated (bus between `derate_start_v` and
    /// `derate_end_v`).
    pub const DERATING: u8 = 1;
    /// The brake chopper is closed.
    pub const BRAKING: u8 = 2;
    /// The I²t estimate is above [`super::I2T_CLEAR`].
    pub const HOT: u8 = 4;
    /// Flux braking burns regenerated power in the winding.
    pub const FLUX: u8 = 8;
    /// Names, bit by bit.
    pub const NAMES: [(u8, &str); 4] = [
        (DERATING, "derating"),
        (BRAKING, "braking"),
        (HOT, "hot"),
        (FLUX, "flux_braking"),
    ];
}

/// What a supervision tick decided.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Verdict {
    pub trip: Option<Fault>,
}

/// Order in which faults found in the same supervision tick are reported (cause first).
const PRIORITY: [Fault; 8] = [
    Fault::CurrentSensor,
    Fault::SpeedImplausible,
    Fault::EncoderLoss,
    Fault::AngleImplausible,
    Fault::LoopOverrun,
    Fault::StrokeLimit,
    Fault::OverForce,
    Fault::MachineI2t,
];

/// Protection state owned by the controller.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Protection {
    /// Factor applied to a regenerative q-current reference (1 = none), Q16.16 in [0, 1].
    pub derate: Q,
    /// Flux braking's d-current reference (≤ 0), A ([`flux_brake_id`]).
    pub flux_id: Q,
    /// A bus action in force (`derate` ≠ 1 or `flux_id` ≠ 0): the one flag the loop tests
    /// before applying either ([`bus_action`]).
    pub act: bool,
    /// Overruns reported since the last supervision tick.
    overruns: u16,
    /// Leaky overrun bucket: + overruns, − 1 per tick.
    bucket: u16,
    ticks: u32,
    /// Low-pass filtered electromagnetic force (signed, so current noise averages out), N.
    force_filt: f32,
    /// Encoder position at the last tick, counts, and the speed over the tick, rad/s.
    last_pos: i32,
    primed: bool,
    omega_raw: f32,
    /// The largest |ω_m| of the current window and of the one before ([`PEAK_TICKS`]), rad/s.
    peak: [f32; 2],
    /// The speed when the latched record was taken: the larger of the loop's estimate and
    /// the 1 ms count difference (the estimate lags a motion that starts at speed), rad/s.
    trip_speed: f32,
    /// I²t state: per-unit winding temperature rise, settles at (|i|/i2t_cont_a)².
    i2t: f32,
    emf_count: u16,
    /// Leaky count of ticks with the emf off the q axis (angle plausibility).
    angle_count: u16,
    /// The loop's angle minus the rotor's from the emf, rad (small-angle; 0 when not judged
    /// this tick or beyond `angle_tol_deg`).
    pub angle_err: f32,
    isum_count: u16,
    isum_now: bool,
    record: Option<Record>,
    /// [`warn`] bits.
    pub warnings: u8,
}

impl Default for Protection {
    fn default() -> Self {
        Protection {
            derate: Q::ONE,
            flux_id: Q::ZERO,
            act: false,
            overruns: 0,
            bucket: 0,
            ticks: 0,
            force_filt: 0.0,
            last_pos: 0,
            primed: false,
            omega_raw: 0.0,
            peak: [0.0; 2],
            trip_speed: 0.0,
            i2t: 0.0,
            emf_count: 0,
            angle_count: 0,
            angle_err: 0.0,
            isum_count: 0,
            isum_now: false,
            record: None,
            warnings: 0,
        }
    }
}

/// The bus actions on a current reference, when [`Protection::act`] says one is in force
/// (out of line: the loop's common path pays only the flag's test): the derate factor on a
/// regenerative q current ([`derate_regen`]) and flux braking's d current added.
#[cold]
#[inline(never)]
pub fn bus_action(r: Dq, omega_m: Q, p: &Protection) -> Dq {
    let r = derate_regen(r, omega_m, p.derate);
    Dq {
        d: r.d.saturating_add(p.flux_id),
        q: r.q,
    }
}

/// √x for x ≥ 0 (0 for anything else, NaN included; +∞ for +∞) in `f32` without libm:
/// [`crate::fx::sqrt_newton`]'s four Newton steps (below 1 ULP), with correctly rounded
/// `+ ÷ ×` only, so host and board agree bit for bit.
pub(crate) fn sqrt_f32(x: f32) -> f32 {
    if x.is_nan() || x <= 0.0 {
        return 0.0;
    }
    if x == f32::INFINITY {
        return x;
    }
    crate::fx::sqrt_newton::<4>(x)
}

/// Flux braking's d current, A (≤ 0), from the bus voltage `v_bus`, the shaft speed `omega`
/// (rad/s) and the q current `i_q` (A) of the last period.
///
/// The power the machine sends to the bus at a d current `i_d` is (amplitude-invariant
/// frame, steady state: the `ω_e·L` cross terms carry no power)
/// `P = −3/2·(e_q·i_q + R·i_q²) − 3/2·R·i_d² = P₀ − 3/2·R·i_d²`, `e_q = K_e·ω`. The bus takes
/// `P_acc = min(P₀, max_regen_power_w)·w(v_bus)`, `w` = 1 up to `brake_on_v` falling linearly
/// to 0 at `derate_start_v` (the chopper has not held the bus: a growing share is burnt, all
/// of it from `derate_start_v` on, where the derating starts too), so
/// `i_d² = (P₀ − P_acc)/(3/2·R)` burns the rest, bounded by
/// * `flux_brake_a` (0 = off) and the current limit: `i_d² ≤ i_max_a² − i_q²`;
/// * the voltage circle (at 0.9 of `m_max·V_bus/√3`, margin for the PI): with
///   `v_d = R·i_d − ω_e·L·i_q`, `v_q = R·i_q + ω_e·L·i_d + e_q`, `|v|² ≤ v_lim²` is a quadratic
///   in `i_d` whose lower root bounds it. The sign is negative (against the magnet's flux):
///   it lowers `v_q` at any speed's sign, so flux braking never needs more voltage than
///   the loop has; where even `i_d = 0` does not fit, the `i_d` of least voltage is the
///   bound.
pub fn flux_brake_id(cfg: &Config, v_bus: f32, omega: f32, i_q: f32) -> f32 {
    if cfg.flux_brake_a.is_nan() || cfg.flux_brake_a <= 0.0 {
        return 0.0;
    }
    let w = if v_bus <= cfg.brake_on_v {
        1.0
    } else if v_bus >= cfg.derate_start_v {
        0.0
    } else {
        (cfg.derate_start_v - v_bus) / (cfg.derate_start_v - cfg.brake_on_v)
    };
    let r = cfg.r_phase_ohm;
    let e = cfg.ke_v_s_per_rad * omega;
    let p0 = -1.5 * (e * i_q + r * i_q * i_q);
    let cap = if p0 < cfg.max_regen_power_w {
        p0
    } else {
        cfg.max_regen_power_w
    };
    let p_acc = if w > 0.0 { cap * w } else { 0.0 };
    let excess = p0 - p_acc;
    if excess.is_nan() || excess <= 0.0 {
        return 0.0;
    }
    let want = excess / (1.5 * r);
    let fb = cfg.flux_brake_a;
    let room = cfg.i_max_a * cfg.i_max_a - i_q * i_q;
    let mut lim = if room < fb * fb { room } else { fb * fb };
    // The voltage circle: v_d = R·i_d − ω_e·L_q·i_q, v_q = R·i_q + ω_e·L_d·i_d + e.
    let we = cfg.pole_pairs as f32 * omega;
    let (xd, xq) = (we * cfg.l_d(), we * cfg.l_phase_h);
    let v_lim = 0.9 * cfg.m_max * v_bus * crate::config::INV_SQRT3;
    let (a0, b0) = (-xq * i_q, r * i_q + e);
    let a = r * r + xd * xd;
    let b = r * a0 + xd * b0;
    let c = a0 * a0 + b0 * b0 - v_lim * v_lim;
    let disc = b * b - a * c;
    let lo = if disc >= 0.0 {
        (-b - sqrt_f32(disc)) / a
    } else {
        -b / a
    };
    let v_room = if lo < 0.0 { lo * lo } else { 0.0 };
    if v_room < lim {
        lim = v_room;
    }
    let i2 = if want < lim { want } else { lim };
    -sqrt_f32(i2)
}

/// Apply the derate factor to a current reference: the q component is scaled when it
/// sends power to the bus (`i_q·ω < 0`, `P = −3/2·K_e·ω·i_q > 0`); a motoring reference
/// (two-way laws) is left alone, since it takes energy out of the bus. Per period: a sign test
/// and one multiply.
#[inline(always)]
pub fn derate_regen(r: Dq, omega_m: Q, derate: Q) -> Dq {
    if (r.q.to_bits() ^ omega_m.to_bits()) < 0 {
        Dq {
            d: r.d,
            q: mul(r.q, derate),
        }
    } else {
        r
    }
}

/// f_e = 3/2·K_e·i_q/l, N (sign of the torque).
fn force_of(cfg: &Config, i_q: f32) -> f32 {
    1.5 * cfg.ke_v_s_per_rad * i_q / cfg.lead_m_per_rad
}

fn abs(x: f32) -> f32 {
    if x < 0.0 {
        -x
    } else {
        x
    }
}

impl Protection {
    /// Report one current-loop overrun (the board's timer saw the loop finish late).
    pub fn report_overrun(&mut self) {
        self.overruns = self.overruns.saturating_add(1);
    }

    /// The latched record.
    pub fn record(&self) -> Option<&Record> {
        self.record.as_ref()
    }

    /// Supervision ticks (ms) since start.
    pub fn ticks(&self) -> u32 {
        self.ticks
    }

    /// The I²t state (per unit of the rated temperature rise).
    pub fn i2t(&self) -> f32 {
        self.i2t
    }

    /// The filtered force magnitude, N.
    pub fn force_n(&self) -> f32 {
        abs(self.force_filt)
    }

    /// Shaft speed over the last tick from the raw encoder count, rad/s.
    pub fn omega_raw(&self) -> f32 {
        self.omega_raw
    }

    /// The encoder was re-zeroed: the next tick measures no speed across the jump.
    pub fn rezero(&mut self) {
        self.primed = false;
    }

    /// Latch `f` with a snapshot built from the given measurements.
    pub fn latch(&mut self, f: Fault, mode: Mode, t: &Telemetry) {
        match &mut self.record {
            Some(r) => {
                if r.fault != f {
                    r.later |= f.bit();
                }
            }
            None => {
                let w = abs(q_f32(t.omega_m));
                let raw = abs(self.omega_raw);
                self.trip_speed = if raw > w { raw } else { w };
                self.record = Some(Record {
                    fault: f,
                    snap: Snapshot {
                        t_ms: self.ticks,
                        mode,
                        i_abc: t.i_abc,
                        i_dq: t.i_dq,
                        v_bus: t.v_bus,
                        omega_m: t.omega_m,
                        x: t.x,
                        force_n: abs(self.force_filt),
                        i2t: self.i2t,
                        derate: q_f32(self.derate),
                    },
                    later: 0,
                })
            }
        }
    }

    /// Forget the record (the controller checked the cause is gone).
    pub fn forget(&mut self) {
        self.record = None;
        self.angle_count = 0;
    }

    /// One supervision tick over the loop's last telemetry and the encoder's multi-turn
    /// count.
    pub fn supervise(
        &mut self,
        cfg: &Config,
        mode: Mode,
        t: &Telemetry,
        enc_position: i32,
    ) -> Verdict {
        let dt = 1.0 / SUPERVISE_HZ;
        self.ticks = self.ticks.wrapping_add(1);
        let v_bus: f32 = q_f32(t.v_bus);
        let omega: f32 = q_f32(t.omega_m);
        let i_d: f32 = q_f32(t.i_dq.d);
        let i_q: f32 = q_f32(t.i_dq.q);
        let controlled = matches!(mode, Mode::Run | Mode::Open);
        if self.ticks.is_multiple_of(PEAK_TICKS) {
            self.peak = [abs(omega), self.peak[0]];
        } else if abs(omega) > self.peak[0] {
            self.peak[0] = abs(omega);
        }
        // Faults found this tick (bit per code); the reported one is chosen by cause
        // priority at the end: a sensor that lies (current sum, encoder) before what is
        // computed from it (force, I²t), so that a fault is named by its cause.
        let mut found: u32 = 0;
        let mut set = |f: Fault| found |= f.bit();

        // Bus management: derate factor, linear from 1 at derate_start_v to 0 at
        // derate_end_v.
        let span = cfg.derate_end_v - cfg.derate_start_v;
        let k = (cfg.derate_end_v - v_bus) / span;
        let k = if k >= 1.0 {
            1.0
        } else if k > 0.0 {
            k
        } else {
            0.0
        };
        self.derate = crate::numtext::q_of(k);
        // Flux braking: the d current that burns what the bus cannot take.
        let id = if controlled {
            flux_brake_id(cfg, v_bus, omega, i_q)
        } else {
            0.0
        };
        self.flux_id = crate::numtext::q_of(id);
        self.act = self.derate != Q::ONE || self.flux_id != Q::ZERO;

        // I²t: dθ/dt = ((|i|/I_cont)² − θ)/τ (first-order winding temperature rise, per unit
        // of the rise at the continuous current), forward Euler at 1 kHz (τ ≥ 0.1 s ≫ 1 ms).
        let ic = cfg.i2t_cont_a;
        let load = (i_d * i_d + i_q * i_q) / (ic * ic);
        self.i2t += (load - self.i2t) * (dt / cfg.i2t_tau_s);
        if self.i2t >= 1.0 {
            set(Fault::MachineI2t);
        }

        // Phase-current consistency: the star point floats, so i_a + i_b + i_c = 0.
        let s: f32 = q_f32(t.i_abc[0]) + q_f32(t.i_abc[1]) + q_f32(t.i_abc[2]);
        self.isum_now = s > cfg.i_sum_tol_a || s < -cfg.i_sum_tol_a;
        self.isum_count = leaky(self.isum_count, self.isum_now);
        if self.isum_count >= ISUM_TICKS {
            set(Fault::CurrentSensor);
        }

        // Force: f_e low-pass filtered (τ = f_filter_s; signed, so that current noise
        // averages out; the force changes sign only when the motion reverses, ≪ 1/τ); not in
        // Short, where the force is the short circuit's own, accepted when choosing the short.
        let f = force_of(cfg, i_q);
        let a = dt / (cfg.f_filter_s + dt);
        self.force_filt += (f - self.force_filt) * a;
        // While the phase currents disagree (below), the force computed from them is not
        // trusted: the sensor check decides within ISUM_TICKS ticks, to the same open state.
        if mode != Mode::Short && self.isum_count == 0 && abs(self.force_filt) > cfg.f_trip_n {
            set(Fault::OverForce);
        }

        // Loop overrun: leaky bucket, one overrun per ms sustained is tolerated.
        self.bucket = self.bucket.saturating_add(self.overruns).saturating_sub(1);
        self.overruns = 0;
        if self.bucket as f32 > cfg.overrun_max as f32 {
            set(Fault::LoopOverrun);
        }

        // Speed from the raw count over the tick (no observer lag; one count per tick is
        // 2π/cpr·1 kHz, 0.6 rad/s at 10,000 cpr).
        let d = enc_position.wrapping_sub(self.last_pos);
        self.omega_raw = if self.primed {
            d as f32 * (core::f32::consts::TAU / cfg.encoder_cpr as f32) * SUPERVISE_HZ
        } else {
            0.0
        };
        self.last_pos = enc_position;
        self.primed = true;

        if controlled {
            // Stroke.
            let x: f32 = q_f32(t.x);
            if x < cfg.x_min_m || x > cfg.x_max_m {
                set(Fault::StrokeLimit);
            }
            // Speed plausibility, on the raw count (the observer lags a runaway count).
            if abs(self.omega_raw) > cfg.omega_max_rad_s {
                set(Fault::SpeedImplausible);
            }
        }
        // Encoder against the back-emf the loop needs: e = v − R·i − ω_e·L·(−i_q, i_d)
        // (steady state in the rotor frame). With the encoder stuck, the true emf rotates in
        // the frozen frame and the PI output follows it, so |e| ≫ K_e·|ω_enc|. Only while
        // the loop controls current and is not voltage-limited (then v is not what the
        // machine needs).
        let mismatch = if controlled && !t.v_saturated {
            let we = omega * cfg.pole_pairs as f32;
            let r = cfg.r_phase_ohm;
            let ed = q_f32(t.v_dq.d) - r * i_d + we * cfg.l_phase_h * i_q;
            let eq = q_f32(t.v_dq.q) - r * i_q - we * cfg.l_d() * i_d;
            let w_abs = if omega < 0.0 { -omega } else { omega };
            let lim = cfg.ke_v_s_per_rad * w_abs * (1.0 + EMF_REL_TOL) + cfg.enc_emf_tol_v;
            let e2 = ed * ed + eq * eq;
            // Angle plausibility: the emf must lie within angle_tol_deg of +q (for ω > 0; of
            // −q for ω < 0), judged once the encoder's emf exceeds angle_emf_min_v:
            // eq·sgn ω < cos(tol)·|e|, squared to avoid a root.
            let eqs = if omega < 0.0 { -eq } else { eq };
            let c = cos_deg(cfg.angle_tol_deg);
            let off_q = eqs < 0.0 || eqs * eqs < c * c * e2;
            let judged = cfg.ke_v_s_per_rad * w_abs > cfg.angle_emf_min_v;
            // The loop's angle minus the rotor's, small-angle: the emf (0, E) of the rotor
            // frame reads (E·sin ε, E·cos ε) in the loop's.
            self.angle_err = if judged && !off_q {
                let eds = if omega < 0.0 { -ed } else { ed };
                eds / eqs
            } else {
                0.0
            };
            (e2 > lim * lim, judged && off_q)
        } else {
            self.angle_err = 0.0;
            (false, false)
        };
        self.angle_count = leaky(self.angle_count, mismatch.1);
        if self.angle_count >= ANGLE_TICKS {
            set(Fault::AngleImplausible);
        }
        let mismatch = mismatch.0;
        self.emf_count = leaky(self.emf_count, mismatch);
        if self.emf_count >= EMF_TICKS {
            set(Fault::EncoderLoss);
        }

        let mut w = 0;
        if self.derate < Q::ONE {
            w |= warn::DERATING;
        }
        if t.brake {
            w |= warn::BRAKING;
        }
        if self.flux_id != Q::ZERO {
            w |= warn::FLUX;
        }
        if self.i2t > I2T_CLEAR {
            w |= warn::HOT;
        }
        self.warnings = w;
        let trip = PRIORITY.iter().copied().find(|f| found & f.bit() != 0);
        Verdict { trip }
    }

    /// Why `f` may not be cleared yet (None: its cause is gone), judged on the last
    /// telemetry and the supervision state.
    /// The recent peak speed ([`PEAK_TICKS`]): the largest |ω_m| of the last 2.5 s to 5 s,
    /// rad/s.
    pub fn speed_peak(&self) -> f32 {
        if self.peak[0] > self.peak[1] {
            self.peak[0]
        } else {
            self.peak[1]
        }
    }

    /// The recent peak speed's back-emf `K_e·ω` above the voltage circle `m_max·v_bus/√3`
    /// at the bus `v_bus`: beyond it the current loop cannot hold the current.
    fn above_circle(&self, cfg: &Config, v_bus: f32) -> bool {
        cfg.ke_v_s_per_rad * self.speed_peak() > cfg.m_max * v_bus * (1.0 / 1.732_050_8)
    }

    /// The latched trip's speed beyond the rating: `K_e·|ω|` above the voltage circle of
    /// the snapshot's bus.
    fn tripped_beyond_rating(&self, cfg: &Config) -> bool {
        self.record.is_some_and(|r| {
            cfg.ke_v_s_per_rad * self.trip_speed
                > cfg.m_max * q_f32(r.snap.v_bus) * (1.0 / 1.732_050_8)
        })
    }

    pub fn cause_present(
        &self,
        f: Fault,
        cfg: &Config,
        t: &Telemetry,
        encoder_implausible: bool,
    ) -> Option<&'static str> {
        let v: f32 = q_f32(t.v_bus);
        match f {
            Fault::OverCurrent => t
                .i_abc
                .iter()
                .any(|i| q_f32(*i).abs() >= cfg.i_trip_a)
                .then_some("a phase current is still above i_trip_a"),
            Fault::BusOverVoltage => {
                (v > cfg.derate_start_v).then_some("bus still above derate_start_v")
            }
            Fault::BusUnderVoltage => (v < cfg.v_bus_uv).then_some("bus still below v_bus_uv"),
            Fault::EncoderImplausible => encoder_implausible.then_some("encoder still jumping"),
            // Three causes: the currents still flowing (the open bridge's diodes above the
            // onset); a current limit whose force passes the clear level (the law would
            // command it again in `run` once the speed asks for it); for a trip at a speed
            // beyond the rating, a motion whose back-emf passed the voltage circle within the
            // last 2.5–5 s (the loop could not hold the current there: it followed the emf,
            // and its force with it). A trip within the rating leaves the motion out: a
            // resistor-law drive runs with its peaks past the circle (the reference TMD at
            // 306 Ω: 198 rad/s against 186) without such a trip.
            Fault::OverForce => {
                if abs(self.force_filt) > FORCE_CLEAR * cfg.f_trip_n {
                    Some("filtered force still above 0.9 f_trip_n")
                } else if force_of(cfg, cfg.i_max_a) > FORCE_CLEAR * cfg.f_trip_n {
                    Some(
                        "i_max_a's force 3/2·K_e·i_max_a/lead is above 0.9 f_trip_n: run would \
                         trip again; lower i_max_a or raise f_trip_n",
                    )
                } else if self.tripped_beyond_rating(cfg) && self.above_circle(cfg, v) {
                    Some(
                        "the speed passed the rating K_e·|w| = m_max·vbus/√3 in the last 2.5 s: \
                         run would trip again; wait until it moves slower",
                    )
                } else {
                    None
                }
            }
            Fault::MachineI2t => {
                (self.i2t > I2T_CLEAR).then_some("machine still hot (I2t above 0.8)")
            }
            Fault::EncoderLoss => {
                (self.emf_count > 0).then_some("emf/encoder mismatch detector not yet decayed")
            }
            Fault::SpeedImplausible => (abs(self.omega_raw) > cfg.omega_max_rad_s)
                .then_some("speed still above omega_max_rad_s"),
            Fault::StrokeLimit => {
                let x: f32 = q_f32(t.x);
                (x < cfg.x_min_m || x > cfg.x_max_m).then_some("travel still outside the stroke")
            }
            Fault::LoopOverrun => (self.bucket > 0).then_some("overruns still being reported"),
            Fault::CurrentSensor => (self.isum_now || self.isum_count > 0)
                .then_some("phase currents still do not sum to zero"),
            Fault::BusSensor => {
                (v >= cfg.volts_per_count * 4095.0).then_some("bus reading at rail")
            }
            // Cleared, the drive must align again (the controller forgets its angle); a
            // cleared offset fault recalibrates (the controller restarts the calibration).
            Fault::AngleImplausible
            | Fault::AlignMoving
            | Fault::AlignCheck
            | Fault::EncoderMismatch => None,
            Fault::CurrentOffset => None,
        }
    }
}

/// The line-to-line emf `√3·K_e·|ω_m|` reaches 0.9·`v_bus_ov`: an open bridge would
/// rectify into the bus up to the trip (10 % margin for the speed estimate).
pub fn above_onset(cfg: &Config, omega_m: f32) -> bool {
    1.732_050_8 * cfg.ke_v_s_per_rad * abs(omega_m) >= 0.9 * cfg.v_bus_ov
}

/// [`above_onset`] as a threshold on the magnitude of a Q16.16 speed's bits: the least `u`
/// with `above_onset(cfg, u·2^-16)` (2^31 + 1 if none), found by bisection. `above_onset` of a
/// speed `q` is `|bits(q)| ≥ onset_bits(cfg)`: its value depends on |ω| only, and grows
/// with it (the conversion to `f32` and the product rounded to nearest are non-decreasing),
/// so one threshold decides it; a property test pins the two. The step's latch compares
/// integers instead of converting and multiplying floats.
pub fn onset_bits(cfg: &Config) -> u32 {
    let above = |u: u32| above_onset(cfg, u as f32 * (1.0 / 65_536.0));
    let (mut lo, mut hi) = (0u32, 1u32 << 31); // the answer is in (lo, hi] or none
    if above(0) {
        return 0;
    }
    if !above(hi) {
        return hi + 1;
    }
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if above(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    hi
}

/// Faults after which the measured speed is not trusted (bits `1 << code`): encoder
/// implausible, encoder loss, speed implausible, encoder mismatch.
pub const SPEED_DOUBT: u32 = 1 << 4 | 1 << 7 | 1 << 8 | 1 << 17;

/// The safe state when fault `f` arrives in `mode` with `latched` faults already latched
/// (`docs/protection.md`, "The rule"): a fresh fault goes to its own safe state; open
/// dominates a later fault, except that
/// * over-voltage while open above the onset shorts (the open bridge is what charges the
///   bus; the short stops every watt and needs no angle);
/// * nothing opens a short above the onset (opening would rectify into the bus): not an
///   over-current (the short's own current, bounded by `K_e/(p·L)`, under the stage's
///   hardware trip), nor the current-sensor fault that current causes when it passes the
///   ADC's range, nor the force or I²t the short costs; below the onset they open;
/// * a bus reading at the rail opens, from any state: a false over-voltage must not hold a
///   short (a true one is caught by the stage's own comparator on its own divider).
pub const fn next_mode(latched: bool, mode: Mode, f: Fault, above_onset: bool) -> Mode {
    match (f, mode) {
        (Fault::BusSensor, _) => Mode::Idle,
        (Fault::BusOverVoltage, Mode::Idle) if above_onset => Mode::Short,
        (_, Mode::Short) if above_onset => Mode::Short,
        (_, Mode::Idle) if latched => Mode::Idle,
        _ => f.safe_mode(),
    }
}

/// The rule as a latch applies it: fault `f` arriving in `mode`, a fault latched before it
/// or not (`has_fault`), the faults latched before it as bits `1 << code` (`latched`), and
/// the speed estimate above the diode onset or not (`above`). With the encoder or the speed
/// in doubt (`f` or a latched fault in [`SPEED_DOUBT`]) the bus decides: over-voltage while
/// open is the rectification itself (above the onset); nothing else is taken as above it.
pub const fn latch_next(has_fault: bool, latched: u32, mode: Mode, f: Fault, above: bool) -> Mode {
    let onset = if (latched | f.bit()) & SPEED_DOUBT != 0 {
        matches!(f, Fault::BusOverVoltage)
    } else {
        above
    };
    next_mode(has_fault, mode, f, onset)
}

/// What the current-loop step found in one period, as one number (`found`, 1 … 7; 0:
/// nothing): bit 0 a phase over-current ([`FOUND_OC`]), bit 1 the bus above its trip
/// ([`FOUND_OV`]), bit 2 with it that reading taken for a sensor fault ([`FOUND_RAIL`]: at
/// the rail without having passed the trip below it); with neither, the encoder's jump
/// ([`FOUND_ENCODER`]) or, in Run, the bus below its minimum ([`FOUND_UNDER_V`]).
pub const FOUND_OC: u8 = 1;
/// See [`FOUND_OC`].
pub const FOUND_OV: u8 = 2;
/// See [`FOUND_OC`] (only with [`FOUND_OV`]).
pub const FOUND_RAIL: u8 = 4;
/// See [`FOUND_OC`] (alone).
pub const FOUND_ENCODER: u8 = 4;
/// See [`FOUND_OC`] (alone).
pub const FOUND_UNDER_V: u8 = 5;

/// The faults a step's `found` ([`FOUND_OC`]) latches, in the order of precedence: the first,
/// and the bus fault an over-current must not hide (open above the onset, the diode
/// currents pass the current trip while they charge the bus). None for 0.
pub const fn found_faults(found: u8) -> Option<(Fault, Option<Fault>)> {
    use Fault::*;
    match found {
        1 => Some((OverCurrent, None)),
        2 => Some((BusOverVoltage, None)),
        3 => Some((OverCurrent, Some(BusOverVoltage))),
        4 => Some((EncoderImplausible, None)),
        5 => Some((BusUnderVoltage, None)),
        6 => Some((BusSensor, None)),
        7 => Some((OverCurrent, Some(BusSensor))),
        _ => None,
    }
}

/// The mode after latching the faults a step found (`found`), one after the other by
/// [`latch_next`], in `mode`, with `latched` (bits) latched before and a fault latched or not
/// (`has_fault`). `mode` when nothing was found.
pub const fn latch_found(
    found: u8,
    has_fault: bool,
    latched: u32,
    mode: Mode,
    above: bool,
) -> Mode {
    match found_faults(found) {
        None => mode,
        Some((f, None)) => latch_next(has_fault, latched, mode, f, above),
        Some((f, Some(g))) => {
            let m = latch_next(has_fault, latched, mode, f, above);
            latch_next(true, latched | f.bit(), m, g, above)
        }
    }
}

/// A mode from its discriminant (`Mode as u8`).
const fn mode_of(d: usize) -> Option<Mode> {
    match d {
        0 => Some(Mode::Idle),
        1 => Some(Mode::Run),
        2 => Some(Mode::Short),
        3 => Some(Mode::Open),
        4 => Some(Mode::Measure),
        5 => Some(Mode::Align),
        _ => None,
    }
}

/// [`latch_found`] tabulated for the step (bit `i` of the 512: 1 = Short, 0 = Idle; the index
/// as [`step_safe_mode`] forms it), evaluated when the firmware is compiled: the latched
/// faults enter only through whether one is latched and whether one is in [`SPEED_DOUBT`],
/// so one of that set stands for them. Every result is Idle or Short (checked here: a
/// compile error otherwise).
const STEP_SHORT: [u32; 16] = {
    let mut t = [0u32; 16];
    let mut i = 0;
    while i < 512 {
        if let Some(mode) = mode_of(i >> 3 & 7) {
            let latched = if i & 2 != 0 {
                Fault::EncoderImplausible.bit()
            } else {
                0
            };
            match latch_found((i >> 6) as u8, i & 4 != 0, latched, mode, i & 1 != 0) {
                Mode::Short => t[i >> 5] |= 1 << (i & 31),
                Mode::Idle => {}
                // (Nothing found leaves the mode: those entries are never read.)
                _ if i >> 6 == 0 => {}
                _ => panic!("a step's latch leads to Idle or Short only"),
            }
        }
        i += 1;
    }
    t
};

/// [`latch_found`] for the current-loop step, as one bit of a table ([`STEP_SHORT`]): the
/// faults found (`found`, 1 … 7), the mode found, a fault latched or not (`has_fault`), one in
/// [`SPEED_DOUBT`] latched or not (`doubt`), the speed estimate above the onset or not.
/// A handful of instructions where the rule itself, applied once per fault, costs ≈ 40 per
/// fault on the board's build (`docs/m4check.md`).
#[inline(always)]
pub fn step_safe_mode(found: u8, mode: Mode, has_fault: bool, doubt: bool, above: bool) -> Mode {
    let i = ((found & 7) as usize) << 6
        | (mode as usize) << 3
        | (has_fault as usize) << 2
        | (doubt as usize) << 1
        | above as usize;
    if STEP_SHORT[i >> 5] >> (i & 31) & 1 != 0 {
        Mode::Short
    } else {
        Mode::Idle
    }
}

/// Leaky persistence count: +1 when the condition holds, −1 otherwise (floor 0).
/// cos of an angle in degrees in [0, 90] (Taylor series to x^10: error < 1e-7 there).
fn cos_deg(deg: f32) -> f32 {
    let x = deg * (core::f32::consts::PI / 180.0);
    let x2 = x * x;
    1.0 - x2 / 2.0 * (1.0 - x2 / 12.0 * (1.0 - x2 / 30.0 * (1.0 - x2 / 56.0 * (1.0 - x2 / 90.0))))
}

fn leaky(n: u16, cond: bool) -> u16 {
    if cond {
        n.saturating_add(1)
    } else {
        n.saturating_sub(1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fx::q;

    fn tel() -> Telemetry {
        Telemetry {
            v_bus: q(60.0),
            ..Telemetry::default()
        }
    }

    #[test]
    fn the_rule_fault_to_safe_state() {
        use Fault::*;
        // Fresh faults: their own safe state.
        for f in Fault::ALL {
            assert_eq!(next_mode(false, Mode::Run, *f, false), f.safe_mode());
        }
        // Open dominates below the onset...
        assert_eq!(
            next_mode(true, Mode::Idle, BusOverVoltage, false),
            Mode::Idle
        );
        assert_eq!(next_mode(true, Mode::Short, OverCurrent, false), Mode::Idle);
        // ...but not above it: OV while open shorts, the short's own OC keeps it.
        assert_eq!(
            next_mode(true, Mode::Idle, BusOverVoltage, true),
            Mode::Short
        );
        for f in [
            OverCurrent,
            CurrentSensor,
            OverForce,
            MachineI2t,
            BusUnderVoltage,
        ] {
            assert_eq!(next_mode(true, Mode::Short, f, true), Mode::Short);
        }
        assert_eq!(next_mode(true, Mode::Idle, EncoderLoss, true), Mode::Idle);
        // A rail reading never holds a short.
        for m in [Mode::Run, Mode::Short, Mode::Idle] {
            assert_eq!(next_mode(true, m, BusSensor, true), Mode::Idle);
        }
        assert_eq!(
            SPEED_DOUBT,
            EncoderImplausible.bit()
                | EncoderLoss.bit()
                | SpeedImplausible.bit()
                | EncoderMismatch.bit()
        );
        // The onset: √3·K_e·ω = 0.9·v_bus_ov.
        let c = Config::default();
        let w = 0.9 * c.v_bus_ov / (1.732_050_8 * c.ke_v_s_per_rad);
        assert!(above_onset(&c, 1.001 * w) && above_onset(&c, -1.001 * w));
        assert!(!above_onset(&c, 0.999 * w));
    }

    /// The step's table (`step_safe_mode`) is the rule applied fault by fault
    /// (`latch_found`) for every `found`, every mode, the faults latched before (none, each
    /// alone, every pair, with or without a fault in force) and either side of the onset.
    #[test]
    fn step_table_is_the_rule_fault_by_fault() {
        let modes = [
            Mode::Idle,
            Mode::Run,
            Mode::Short,
            Mode::Open,
            Mode::Align,
            Mode::Measure,
        ];
        let mut sets = std::vec![0u32];
        for (i, f) in Fault::ALL.iter().enumerate() {
            sets.push(f.bit());
            for g in &Fault::ALL[i + 1..] {
                sets.push(f.bit() | g.bit());
            }
        }
        let mut n = 0;
        for found in 1..=7u8 {
            for m in modes {
                for &latched in &sets {
                    for has_fault in [false, true] {
                        for above in [false, true] {
                            let doubt = latched & SPEED_DOUBT != 0;
                            assert_eq!(
                                step_safe_mode(found, m, has_fault, doubt, above),
                                latch_found(found, has_fault, latched, m, above),
                                "found {found}, {m:?}, latched {latched:#x}, {has_fault} {above}"
                            );
                            n += 1;
                        }
                    }
                }
            }
        }
        assert_eq!(n, 7 * 6 * 154 * 4);
    }

    /// The two faults a step can find in one period, against the safe-state table
    /// (docs/protection.md, "The rule"), by hand: an over-current opens; the over-voltage with
    /// it shorts above the onset (the open bridge is what charges the bus), stays open below
    /// it; a rail reading with it opens from anywhere; a short above the onset stays.
    #[test]
    fn two_faults_in_one_period_by_the_table() {
        use Fault::*;
        let (oc_ov, oc_rail) = (FOUND_OC | FOUND_OV, FOUND_OC | FOUND_OV | FOUND_RAIL);
        assert_eq!(
            found_faults(oc_ov),
            Some((OverCurrent, Some(BusOverVoltage)))
        );
        assert_eq!(found_faults(oc_rail), Some((OverCurrent, Some(BusSensor))));
        for m in [Mode::Run, Mode::Open, Mode::Align, Mode::Idle] {
            assert_eq!(step_safe_mode(oc_ov, m, false, false, false), Mode::Idle);
            assert_eq!(step_safe_mode(oc_ov, m, false, false, true), Mode::Short);
            assert_eq!(step_safe_mode(oc_rail, m, false, false, true), Mode::Idle);
        }
        // In a short (an earlier fault's) above the onset: kept; below it: opened.
        assert_eq!(
            step_safe_mode(oc_ov, Mode::Short, true, false, true),
            Mode::Short
        );
        assert_eq!(
            step_safe_mode(FOUND_OC, Mode::Short, true, false, true),
            Mode::Short
        );
        assert_eq!(
            step_safe_mode(oc_ov, Mode::Short, true, false, false),
            Mode::Idle
        );
        // The speed in doubt (an encoder fault latched, its short in force): the bus decides,
        // the over-voltage shorts at any speed.
        assert_eq!(
            step_safe_mode(oc_ov, Mode::Short, true, true, false),
            Mode::Short
        );
        assert_eq!(
            step_safe_mode(oc_ov, Mode::Idle, true, true, false),
            Mode::Short
        );
    }

    #[test]
    fn codes_and_names_are_unique_and_round_trip() {
        for (i, f) in Fault::ALL.iter().enumerate() {
            assert_eq!(Fault::from_code(f.code()), Some(*f));
            assert!(Fault::ALL[i + 1..].iter().all(|g| g.name() != f.name()));
            assert!(f.bit() != 0);
        }
        assert_eq!(Fault::from_code(0), None);
    }

    #[test]
    fn derate_scales_only_regenerative_q_current() {
        let half = q(0.5);
        let r = Dq {
            d: q(0.3),
            q: q(-2.0),
        };
        // ω > 0, i_q < 0: regenerating → halved.
        assert_eq!(derate_regen(r, q(10.0), half).q, q(-1.0));
        assert_eq!(derate_regen(r, q(10.0), half).d, q(0.3));
        // ω < 0, i_q < 0: motoring → untouched.
        assert_eq!(derate_regen(r, q(-10.0), half), r);
    }

    /// Flux braking over a grid of bus voltages, speeds (both signs) and q currents, judged
    /// by the machine's steady-state voltage equations written out here (cross terms
    /// included, which the function's power balance drops): the d current is never
    /// positive, keeps |i_dq| within i_max_a and the voltage within 0.9 of the circle; where
    /// neither bound is reached, the bus receives exactly the power it takes
    /// (`P = −3/2·(v_d·i_d + v_q·i_q)` = `max_regen_power_w·w(v_bus)`, 1e-4 relative + 1 mW:
    /// f32 rounding of a difference of terms ≤ 100 W); off (0 A) gives none. Breaks: the
    /// factor 3/2 dropped, the current bound or the voltage bound removed each fail it.
    #[test]
    fn flux_braking_burns_what_the_bus_cannot_take() {
        // Non-salient, then salient (L_q = l_phase_h = 1.6·L_d = 1.6·l_d_h).
        for l_d_h in [0.0f32, 6.0e-3] {
            let cfg = Config {
                max_regen_power_w: 20.0,
                l_phase_h: if l_d_h > 0.0 { 9.6e-3 } else { 6.0e-3 },
                l_d_h,
                ..Config::default()
            };
            let salient = l_d_h > 0.0;
            let (r, ld, lq, p, ke) = (
                cfg.r_phase_ohm as f64,
                cfg.l_d() as f64,
                cfg.l_phase_h as f64,
                cfg.pole_pairs as f64,
                cfg.ke_v_s_per_rad as f64,
            );
            let (mut balanced, mut by_i, mut by_v) = (0, 0, 0);
            for vb in [80.0f32, 85.0, 86.0, 87.0, 88.0, 90.0] {
                for w in [-60.0f32, -30.0, -10.0, -2.0, 0.0, 3.0, 15.0, 40.0, 55.0] {
                    for iq in [-1.9f32, -1.2, -0.6, -0.2, 0.0, 0.3, 1.5] {
                        let id = flux_brake_id(&cfg, vb, w, iq) as f64;
                        let (wf, iqf) = (w as f64, iq as f64);
                        assert!(id <= 0.0);
                        let (xd, xq) = (p * wf * ld, p * wf * lq);
                        let vd = r * id - xq * iqf;
                        let vq = r * iqf + xd * id + ke * wf;
                        let v = (vd * vd + vq * vq).sqrt();
                        let v_lim = 0.9 * cfg.m_max as f64 * vb as f64 / 3f64.sqrt();
                        let i_lim = cfg.i_max_a as f64;
                        let i = (id * id + iqf * iqf).sqrt();
                        if id == 0.0 {
                            continue;
                        }
                        assert!(i <= i_lim * (1.0 + 1e-5), "{vb} {w} {iq}: |i| {i}");
                        // Within the circle, or (already outside at i_d = 0) nearer to it.
                        let v0 = ((xq * iqf).powi(2) + (r * iqf + ke * wf).powi(2)).sqrt();
                        assert!(
                            v <= v_lim * (1.0 + 1e-4) || v < v0,
                            "{vb} {w} {iq}: |v| {v}"
                        );
                        let wv = ((cfg.derate_start_v - vb) / (cfg.derate_start_v - cfg.brake_on_v))
                            .clamp(0.0, 1.0) as f64;
                        let p0 = -1.5 * (r * iqf + ke * wf) * iqf;
                        let p_acc = p0.min(cfg.max_regen_power_w as f64) * wv;
                        let p_bus = -1.5 * (vd * id + vq * iqf);
                        if i >= i_lim * (1.0 - 1e-4) {
                            by_i += 1;
                            assert!(p_bus >= p_acc - 1e-3);
                        } else if v >= v_lim * (1.0 - 1e-4) {
                            by_v += 1;
                            assert!(p_bus >= p_acc - 1e-3);
                        } else if salient {
                            // The reluctance power 3/2·ω_e·(L_d − L_q)·i_d·i_q goes to the shaft,
                            // not in the function's balance: judged on the bounds only.
                            balanced += 1;
                        } else {
                            balanced += 1;
                            assert!(
                                (p_bus - p_acc).abs() <= 1e-4 * p_acc + 1e-3,
                                "{vb} {w} {iq}: bus gets {p_bus} W, takes {p_acc} W"
                            );
                        }
                    }
                }
            }
            assert!(
                balanced > 10 && by_i > 3 && by_v > 0,
                "{balanced} {by_i} {by_v}"
            );
        }
        let off = Config {
            flux_brake_a: 0.0,
            max_regen_power_w: 20.0,
            ..Config::default()
        };
        assert_eq!(flux_brake_id(&off, 90.0, 40.0, -1.0), 0.0);
        let (r, ke) = (off.r_phase_ohm as f64, off.ke_v_s_per_rad as f64);
        // The default takes everything below brake_on_v, a falling share above, nothing
        // from derate_start_v on (10 rad/s, −0.3 A: 3.9 W, 1.04 A of d current at most).
        let d = Config::default();
        let at = |v: f32| flux_brake_id(&d, v, 10.0, -0.3) as f64;
        let p0 = -1.5 * (r * -0.3 + ke * 10.0) * -0.3;
        assert_eq!(at(d.brake_on_v), 0.0);
        let mid = 0.5 * (d.brake_on_v + d.derate_start_v);
        assert!((1.5 * r * at(mid).powi(2) / (0.5 * p0) - 1.0).abs() < 1e-4);
        assert!((1.5 * r * at(d.derate_start_v).powi(2) / p0 - 1.0).abs() < 1e-4);
    }

    #[test]
    fn sqrt_without_libm() {
        for x in [0.0f32, 1e-12, 0.25, 2.0, 3.7, 1e3, 5.5e7, 3e30] {
            let y = sqrt_f32(x);
            assert!(
                (y as f64 - (x as f64).sqrt()).abs() <= 2e-7 * (x as f64).sqrt(),
                "{x}"
            );
        }
        assert_eq!(sqrt_f32(-1.0), 0.0);
        assert_eq!(sqrt_f32(f32::NAN), 0.0);
    }

    #[test]
    fn derate_factor_is_linear_between_start_and_end() {
        let cfg = Config::default();
        let mut p = Protection::default();
        for (v, want) in [
            (cfg.derate_start_v - 1.0, 1.0),
            (cfg.derate_end_v + 1.0, 0.0),
            (0.5 * (cfg.derate_start_v + cfg.derate_end_v), 0.5),
        ] {
            let t = Telemetry {
                v_bus: q(v),
                ..tel()
            };
            p.supervise(&cfg, Mode::Run, &t, 0);
            // Q16.16 and the bus reading's f32 rounding: 1e-4.
            assert!((p.derate.to_num::<f32>() - want).abs() < 1e-4, "{v}");
        }
    }

    #[test]
    fn i2t_trips_after_the_first_order_time() {
        // At I = 2·I_cont from cold, θ(t) = 4·(1 − e^(−t/τ)) reaches 1 at t = τ·ln(4/3).
        let cfg = Config {
            i2t_tau_s: 1.0,
            // 2·I_cont is also 2.2× the force rating: that check is not the one under test.
            f_trip_n: f32::INFINITY,
            ..Config::default()
        };
        let i = 2.0 * cfg.i2t_cont_a;
        let t = Telemetry {
            i_dq: Dq { d: q(0.0), q: q(i) },
            ..tel()
        };
        let mut p = Protection::default();
        let mut n = 0;
        loop {
            n += 1;
            match p.supervise(&cfg, Mode::Idle, &t, 0).trip {
                None => assert!(n < 10_000),
                Some(f) => {
                    assert_eq!(f, Fault::MachineI2t);
                    break;
                }
            }
        }
        let want = cfg.i2t_tau_s * (4.0f32 / 3.0).ln() * SUPERVISE_HZ;
        // Forward Euler at dt/τ = 1e-3 and the Q16.16 current: within 1 % (+1 tick).
        assert!((n as f32 - want).abs() < 0.01 * want + 1.0, "{n} vs {want}");
        assert!(p
            .cause_present(Fault::MachineI2t, &cfg, &t, false)
            .is_some());
    }

    #[test]
    fn overrun_bucket_tolerates_one_per_tick_and_trips_on_bursts() {
        let cfg = Config::default();
        let mut p = Protection::default();
        for _ in 0..1000 {
            p.report_overrun();
            assert!(p.supervise(&cfg, Mode::Run, &tel(), 0).trip.is_none());
        }
        for _ in 0..=cfg.overrun_max + 1 {
            p.report_overrun();
        }
        assert_eq!(
            p.supervise(&cfg, Mode::Run, &tel(), 0).trip,
            Some(Fault::LoopOverrun)
        );
    }
}
