//! The current-loop step: raw sample in, actuation out.
//!
//! Order of one period (20 kHz by default): scale the sample → encoder angle and speed →
//! Clarke → Park → protection checks → command law → current limit → two PI controllers
//! with feed-forward and the bus-voltage limit → inverse Park → space-vector modulation →
//! brake chopper. The step is a pure function of (state, sample, parameters); parameters are
//! replaced only between steps ([`Controller::set_config`]).

use crate::config::{Config, ConfigError, Gains, CODE_MAX};
use crate::encoder::Encoder;
use crate::frames::Rotation;
use crate::frames::{inverse_park_bounded, park_bounded, AlphaBeta, Dq};
use crate::fx::{clamp_sym, mul, Angle, Duty, Gain, Q};
use crate::io::{Actuation, RawSample};
use crate::laws::{CommandLaw, Law, LawInput, Resistor};
use crate::period::Slot;
use crate::pi::{limit_vector, CurrentPi, VLimit};
use crate::svpwm::{inv_bus, modulate_scaled, CENTRED};

/// Operating mode.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Mode {
    /// Gate drivers off: no control (phases open, diodes may rectify).
    #[default]
    Idle = 0,
    /// The command law runs.
    Run = 1,
    /// Phases shorted through the low-side switches: the machine brakes on its own resistance.
    Short = 2,
    /// Current controlled to zero: open terminals emulated even when the back-emf exceeds
    /// the bus.
    Open = 3,
    /// Alignment: the back-emf read at zero current while the rotor moves, else d-axis
    /// current at an imposed angle, two steps a quarter of an electrical turn apart
    /// (docs/protection.md); back to Idle when done. (Discriminant 5:
    /// the modes that control current are then the odd ones, one bit for the step to test.)
    Align = 5,
    /// Commissioning (`measure`, [`crate::commission`]): the measurement's own current loop
    /// on the controller's sample and modulation; back to Idle when done. (Even: the step's
    /// control path is not taken.)
    Measure = 4,
}

impl Mode {
    /// Console name.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Idle => "idle",
            Mode::Run => "run",
            Mode::Short => "short",
            Mode::Open => "open",
            Mode::Align => "align",
            Mode::Measure => "measure",
        }
    }
}

pub use crate::protect::Fault;

/// Power-up state of the commutation angle and the current offsets (`status` shows it).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Boot {
    /// The stored `encoder_offset_rad` is trusted: the encoder count is referenced to the
    /// rotor by construction (what [`Controller::new`] assumes; the board calls
    /// [`Controller::require_alignment`] at power-up).
    #[default]
    Stored,
    /// Measuring each phase's zero-current code, gates off (Run refused).
    Calibrating,
    /// Offsets calibrated; the angle is unknown: Run refused until `mode align` succeeds.
    Unaligned,
    /// Alignment running ([`Mode::Align`]).
    Aligning,
    /// Aligned by the power-up procedure.
    Aligned,
}

impl Boot {
    /// Console name.
    pub fn name(self) -> &'static str {
        match self {
            Boot::Stored => "stored",
            Boot::Calibrating => "calibrating",
            Boot::Unaligned => "unaligned",
            Boot::Aligning => "aligning",
            Boot::Aligned => "aligned",
        }
    }
}

/// Why a mode request was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModeError {
    /// A fault is latched (only its safe mode or Idle may be chosen).
    Fault(Fault),
    /// Run (or Align) needs the boot sequence to have reached a state it has not.
    Boot(Boot),
    /// Short refused: at the present speed the short-circuit current could pass
    /// `i_trip_a` ([`Controller::short_peak_a`]).
    ShortCurrent,
}

impl ModeError {
    /// Console words.
    pub fn name(self) -> &'static str {
        match self {
            ModeError::Fault(f) => f.name(),
            ModeError::Boot(Boot::Calibrating) => "calibrating current offsets",
            ModeError::Boot(Boot::Aligning) => "aligning",
            ModeError::Boot(_) => "not aligned: mode align first",
            ModeError::ShortCurrent => {
                "the short-circuit current at this speed could pass i_trip_a: open or run until the speed falls"
            }
        }
    }
}

/// Periods of the boot offset calibration (gates off): 2,048, 102 ms at 20 kHz; the mean
/// of 2,048 codes is exact to the rounding of the sum's quotient (±0.5 code).
pub const CAL_PERIODS: u32 = 2048;

/// How the last successful alignment found the angle ([`Controller::aligned_by`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AlignMethod {
    /// The back-emf at zero current (the rotor moving), with the encoder's travel over the
    /// emf's (1 for a consistent encoder) and the speed then, rad/s.
    Emf { ratio: f32, omega_m: f32 },
    /// The two d-axis steps (the rotor still).
    Steps,
}

/// Offset calibration and alignment state.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct BootState {
    boot: Boot,
    /// Alignment: the emf probe runs (the d-axis steps once it finds the rotor still).
    probe: bool,
    emf: crate::align::EmfProbe,
    /// How the last alignment succeeded.
    by: Option<AlignMethod>,
    /// Calibration sums of the three phase codes and their count.
    sum: [u32; 3],
    n_cal: u32,
    /// Per-phase zero codes of the raw converter (`adc_zero_code` until calibrated).
    zero: [i32; 3],
    /// Alignment: refresh cycles (of [`SLOW_DIV`] periods) in the present step, cycles per
    /// step, the cycle where the settle window starts, which step (0, 1).
    n: u32,
    n_step: u32,
    n_settle: u32,
    step: u8,
    /// Both steps passed: the offset found is in `offset`; the next supervision tick ends
    /// the alignment (Idle, Aligned).
    done: bool,
    /// d-current ramp increment per cycle, the step current and the present d reference
    /// (Q16.16 bits).
    di: i32,
    i_d: i32,
    /// Damping gain during alignment, −1/R (a short circuit's).
    g_short: Gain,
    i_align: i32,
    /// Encoder position at the start, at the settle-window start, at the end of step 0.
    p_start: i32,
    p_settle: i32,
    p_a: i32,
    /// Counts allowed for travel; the quarter turn's expected counts, the counts allowed
    /// for motion in the settle window (an eighth of it) and for the quarter turn's error
    /// (a quarter of it).
    travel: i32,
    quarter: i32,
    settle: i32,
    quarter_tol: i32,
    /// The encoder's electrical angle per count, kept while alignment imposes the angle.
    e_per_count: u32,
    /// The aligned electrical offset, reapplied when the configuration is recompiled.
    offset: Option<Angle>,
    /// A boot fault found in the step, latched by the next supervision tick (≤ 1 ms; the
    /// step commands zero current meanwhile): the latch and its snapshot cost more than the
    /// step's budget.
    pending: Option<Fault>,
}
use crate::protect::{bus_action, Protection, SUPERVISE_HZ};

/// What the loop measured and commanded in its last period (SI units in fixed point), as
/// [`Controller::telemetry`] returns it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Telemetry {
    pub i_abc: [Q; 3],
    pub i_dq: Dq,
    pub i_ref: Dq,
    pub v_dq: Dq,
    pub v_bus: Q,
    pub omega_m: Q,
    pub x: Q,
    pub theta_e: Angle,
    /// Electrical power out of the machine into the drive, `−3/2·(v_d·i_d + v_q·i_q)`, W,
    /// from commanded voltages (positive when harvesting).
    pub p_elec: Q,
    pub duties: [Duty; 3],
    pub v_saturated: bool,
    pub brake: bool,
}

/// What the step stores for telemetry: the raw sample and the values it computes anyway.
/// Scaled phase currents, bus voltage, speed, travel and power are derived on reading
/// ([`Controller::telemetry`]), which is rare compared with the 20 kHz step.
///
/// The words the capture reads (`crate::capture`) are one array, indexed as
/// [`crate::console::CHANNELS`] up to `vbus` ([`W_VBUS`]), then the speed estimate and the
/// count ([`W_VEL`], [`W_POS`]), and a word for the period's power ([`W_P`], which the step
/// does not compute: [`Controller::cap_words_with_power`] puts it there): a sample reads any
/// of them with one indexed load.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct StepRecord {
    /// The phase codes, d/q currents, references and voltages (Q16.16 bits), bus code, the
    /// encoder's speed estimate (counts per period, Q16.16 bits) and multi-turn count, and
    /// the power of the last period a capture sampled.
    w: [i32; CAP_WORDS],
    theta_e: Angle,
    duties: [Duty; 3],
    v_saturated: bool,
}

/// Words of the step's record the capture can read ([`Controller::cap_words_with_power`]).
pub const CAP_WORDS: usize = 13;
/// Indices into [`Controller::cap_words_with_power`]: the phase codes (0 … 2, as `ia`, `ib`,
/// `ic`), the d/q currents, references and voltages (3 … 8, Q16.16 bits, as `id` … `vq`), the
/// bus code (9, as `vbus`), the speed estimate (counts per period, Q16.16 bits), the count and
/// the power (Q16.16 bits, as `p`).
pub const W_ID: usize = 3;
pub const W_IQ: usize = 4;
pub const W_ID_REF: usize = 5;
pub const W_IQ_REF: usize = 6;
pub const W_VD: usize = 7;
pub const W_VQ: usize = 8;
pub const W_VBUS: usize = 9;
pub const W_VEL: usize = 10;
pub const W_POS: usize = 11;
pub const W_P: usize = 12;

impl StepRecord {
    fn dq(&self, k: usize) -> Dq {
        Dq {
            d: Q::from_bits(self.w[k]),
            q: Q::from_bits(self.w[k + 1]),
        }
    }
    #[inline(always)]
    fn set_dq(&mut self, k: usize, v: Dq) {
        self.w[k] = v.d.to_bits();
        self.w[k + 1] = v.q.to_bits();
    }
    fn i_dq(&self) -> Dq {
        self.dq(W_ID)
    }
    fn i_ref(&self) -> Dq {
        self.dq(W_ID_REF)
    }
    fn v_dq(&self) -> Dq {
        self.dq(W_VD)
    }
    /// Word `k`, a phase or bus code of the sample (12-bit, kept as it came).
    fn code(&self, k: usize) -> u16 {
        self.w[k] as u16
    }
}

/// A configuration validated and compiled outside the current loop
/// ([`Controller::compile`]), ready for [`Controller::install`].
#[derive(Clone, Copy, Debug)]
pub struct Compiled {
    cfg: Config,
    g: Gains,
    /// The new law when a law parameter changed (its state starts afresh), else empty.
    law: Slot<Law>,
}

impl Compiled {
    /// Compile `cfg` for a controller whose configuration in force is `old` (all that
    /// [`Controller::compile`] reads of it: whether a law parameter changed), so that a
    /// caller can keep the old configuration alone instead of a whole controller.
    pub fn new(old: &Config, cfg: &Config) -> Result<Compiled, ConfigError> {
        let g = Gains::new(cfg)?;
        let law = if Law::params_changed(old, cfg) {
            Slot::Full(Law::from_config(cfg))
        } else {
            Slot::Empty
        };
        Ok(Compiled { cfg: *cfg, g, law })
    }

    /// The configuration it was compiled from.
    pub fn config(&self) -> &Config {
        &self.cfg
    }
}

/// The current controller and everything it owns.
#[derive(Clone, Debug)]
#[repr(C)]
pub struct Controller {
    // `repr(C)` in this order: the step's fields first, so that each lies within the
    // Thumb-2 load's 12-bit immediate offset of `self` (the configuration, which the step
    // never reads, last).
    g: Gains,
    enc: Encoder,
    pi: CurrentPi,
    /// Slow terms and the tick of their refresh cycle (`REFRESH_ALL` = all at the next step).
    held: HeldTerms,
    rec: StepRecord,
    slow_tick: u8,
    mode: Mode,
    brake: bool,
    fault: Option<Fault>,
    /// Power-up: offset calibration and alignment.
    bs: BootState,
    /// Protection state (protect.rs): derate factor, supervision, fault record.
    prot: Protection,
    /// A latch the step began and [`Controller::complete_latch`] finishes.
    latching: Latching,
    law: Law,
    cfg: Config,
    /// Commissioning: the measurement's state and results.
    meas: crate::commission::Measure,
}

/// A latch begun by the step ([`Controller::step_outputs`]: the faults found, their safe
/// mode and the first fault in force, the period's outputs already safe), finished by
/// [`Controller::complete_latch`] after the actuation: the records with the snapshot, the PI
/// reset and the slow terms for the new mode (≈ 500 instructions that the step's budget has
/// no room for).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Latching {
    /// What the step found (`protect::FOUND_OC` …; 0: no latch pending).
    found: u8,
    /// The mode it found the drive in (the snapshot's).
    before: Mode,
    /// The last period's d/q currents, the snapshot's: the step records its own after the
    /// protection checks (the rest of the snapshot, this period's codes and the encoder as
    /// updated, stays in place until the next step).
    i_dq: Dq,
}

impl Controller {
    /// A controller in [`Mode::Idle`] for a configuration.
    pub fn new(cfg: &Config) -> Result<Controller, ConfigError> {
        let g = Gains::new(cfg)?;
        Ok(Controller {
            cfg: *cfg,
            g,
            law: Law::from_config(cfg),
            mode: Mode::Idle,
            fault: None,
            enc: Encoder::default(),
            pi: CurrentPi::default(),
            brake: false,
            rec: StepRecord {
                // Zero-current codes: the telemetry reads zero before the first step.
                w: {
                    let mut w = [0; CAP_WORDS];
                    w[..3].fill(cfg.adc_zero_code as i32);
                    w
                },
                theta_e: Angle::default(),
                duties: [Duty::ZERO; 3],
                v_saturated: false,
            },
            held: HeldTerms::default(),
            slow_tick: REFRESH_ALL,
            prot: Protection::default(),
            latching: Latching::default(),
            bs: BootState {
                zero: [cfg.adc_zero_code as i32; 3],
                ..BootState::default()
            },
            meas: crate::commission::Measure::default(),
        })
    }

    /// Replace the configuration (validated first; on error nothing changes). The law's
    /// state is rebuilt only when a law parameter changed. Same as [`Controller::compile`]
    /// then [`Controller::install`].
    pub fn set_config(&mut self, cfg: &Config) -> Result<(), ConfigError> {
        let c = self.compile(cfg)?;
        self.install(&c);
        Ok(())
    }

    /// Everything slow of a configuration change, done against this controller without
    /// changing it: validation, the compiled gains and, when a law parameter changed, the new
    /// law. On the board this runs in the console's task on its copy of the controller; the
    /// current loop then only [`Controller::install`]s the result between two steps.
    pub fn compile(&self, cfg: &Config) -> Result<Compiled, ConfigError> {
        Compiled::new(&self.cfg, cfg)
    }

    /// Put a compiled configuration in force: copies of fixed size and the slow terms'
    /// refresh (the same work whatever changed), no validation or gain design. Compile it
    /// against this controller's configuration (or one with the same law parameters).
    #[inline(never)]
    pub fn install(&mut self, c: &Compiled) {
        if let Slot::Full(l) = &c.law {
            self.law = *l;
        }
        self.cfg = c.cfg;
        self.g = c.g;
        self.apply_angle();
        self.refresh_now();
    }

    /// The angle overrides on the compiled encoder constants: the aligned offset, and while
    /// aligning the imposed angle (no angle per count).
    fn apply_angle(&mut self) {
        let e = &mut self.g.enc;
        if let Some(o) = self.bs.offset {
            e.offset = o;
        }
        if self.mode == Mode::Align && self.bs.probe {
            // The probe's frame: the encoder's own angle, offset 0.
            e.offset = Angle(0);
        } else if self.mode == Mode::Align {
            self.bs.e_per_count = e.e_per_count;
            e.e_per_count = 0;
            e.offset = Angle((self.bs.step as u32) << 30);
        }
    }

    /// Power-up: forget the angle and the offsets, go Idle, and calibrate the per-phase zero
    /// codes over the next [`CAL_PERIODS`] Idle periods; Run is refused until `mode align`
    /// has succeeded (docs/protection.md).
    pub fn require_alignment(&mut self) {
        let _ = self.set_mode(Mode::Idle);
        self.bs = BootState {
            boot: Boot::Calibrating,
            zero: self.bs.zero,
            ..BootState::default()
        };
        self.g.enc.offset = Gains::new(&self.cfg).map_or(Angle(0), |g| g.enc.offset);
    }

    /// Power-up state.
    pub fn boot(&self) -> Boot {
        self.bs.boot
    }

    /// The per-phase zero-current codes of the raw converter (calibrated at boot).
    pub fn zero_codes(&self) -> [i32; 3] {
        self.bs.zero
    }

    /// What the converter must subtract from each phase's raw code so that zero current
    /// reads `adc_zero_code`: `zero_codes() − adc_zero_code`. The board programs them into
    /// the ADC's offset registers (STM32G474 `ADC_OFRy`: OFFSET with OFFSETPOS for a
    /// negative one, no instruction in the loop) once the calibration is done; the
    /// simulator applies them in its sample. Zero until calibrated.
    pub fn adc_offsets(&self) -> [i32; 3] {
        let n = self.cfg.adc_zero_code as i32;
        self.bs.zero.map(|z| z - n)
    }

    /// The electrical angle of the d axis at count 0 within the turn in force (the aligned
    /// one once aligned).
    pub fn angle_offset(&self) -> Angle {
        self.g.enc.offset
    }

    /// The configuration in force.
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// Compiled constants in force.
    pub fn gains(&self) -> &Gains {
        &self.g
    }

    /// The compiled constants, for experiments outside the configuration's design rules
    /// (the simulator's P-only current loop, like the reference bench drive's). The next
    /// [`Controller::set_config`] recompiles them.
    pub fn gains_mut(&mut self) -> &mut Gains {
        &mut self.g
    }

    /// Request a mode. Refused (returns the fault) while a fault is latched, except for the
    /// fault's own safe mode and Idle.
    pub fn set_mode(&mut self, m: Mode) -> Result<(), ModeError> {
        if let Some(f) = self.fault {
            // Open dominates: after a later fault that opened the phases, only Idle.
            let opened = self
                .prot
                .record()
                .is_some_and(|r| r.later().any(|g| g.safe_mode() == Mode::Idle));
            if m != Mode::Idle && (m != f.safe_mode() || opened) {
                return Err(ModeError::Fault(f));
            }
        }
        if let Some(f) = self.bs.pending {
            if m != Mode::Idle {
                return Err(ModeError::Fault(f)); // latched at the next supervision tick
            }
        }
        let b = self.bs.boot;
        match m {
            Mode::Run if !matches!(b, Boot::Stored | Boot::Aligned) => {
                return Err(ModeError::Boot(b))
            }
            Mode::Align if b == Boot::Calibrating => return Err(ModeError::Boot(b)),
            Mode::Short if self.mode != Mode::Short && self.short_peak_a() > self.cfg.i_trip_a => {
                return Err(ModeError::ShortCurrent)
            }
            Mode::Measure if !matches!(b, Boot::Stored | Boot::Aligned) => {
                return Err(ModeError::Boot(b))
            }
            _ => {}
        }
        if m != self.mode {
            if self.mode == Mode::Align {
                self.end_align(None);
            }
            if self.mode == Mode::Measure {
                self.meas.fail(crate::commission::Failure::Aborted);
            }
            if m == Mode::Measure {
                let x = crate::numtext::q_f32(self.enc.x(&self.g.enc));
                self.meas.start(&self.cfg, x);
            }
            self.pi.reset();
            self.mode = m;
            if m == Mode::Align {
                self.start_align();
            }
            self.refresh_now();
        }
        Ok(())
    }

    /// A bound on the phase current's peak if the phases were shorted now, from zero
    /// current at the present speed estimate, A, on a machine with the inductances L_d
    /// ([`Config::l_d`]) and L_q (`l_phase_h`), salient or not. In the rotor frame (ω_e =
    /// p·ω_m, ψ = K_e/p, `E = K_e·|ω_m|`) the short's current is `i = i_ss + i_tr`: the steady
    /// state `i_d = −ω_e²·L_q·ψ/D`, `i_q = −R·ω_e·ψ/D` (`D = R² + ω_e²·L_d·L_q`), so
    /// `|i_ss| = E·√(R² + ω_e²·L_q²)/D`, and a transient starting at `−i_ss` whose flux
    /// `Φ = (L_d·i_d, L_q·i_q)` obeys `d|Φ|²/dt = −2R·(L_d·i_d² + L_q·i_q²)` (the rotation's
    /// cross terms cancel in this norm): `|Φ_tr| ≤ |Φ_ss|·e^(−t/τ)`, τ = L_max/R, with
    /// `|Φ_ss| = E·L_q·√(R² + ω_e²·L_d²)/D`, and `|i| ≤ |Φ|/L_min`. From zero the whole flux
    /// grows at most as `d|Φ|/dt ≤ E`, so `|i| ≤ E·t/L_min` up to `t₁`, where that reaches 90 %
    /// of `i_trip_a`, and `|i| ≤ |i_ss| + |Φ_ss|/L_min·τ/(τ + t₁)` after (`e^(−x) ≤
    /// 1/(1 + x)`). Returns the larger of the two (or the first when the second is below it:
    /// the bound is then under 90 % of the trip). Non-salient (L_d = L_q = L) it is
    /// `|i_ss|·(1 + τ/(τ + t₁))`, `|i_ss| = E/√(R² + (ω_e·L)²)`. The speed does not grow
    /// during a short (it brakes), so the bound holds for the whole short.
    pub fn short_peak_a(&self) -> f32 {
        let c = &self.cfg;
        let w = crate::numtext::q_f32(self.enc.omega_m(&self.g.enc));
        let w = if w < 0.0 { -w } else { w };
        let e = c.ke_v_s_per_rad * w;
        let (ld, lq, r) = (c.l_d(), c.l_phase_h, c.r_phase_ohm);
        let (l_min, l_max) = if ld < lq { (ld, lq) } else { (lq, ld) };
        let we = w * c.pole_pairs as f32;
        let d = r * r + we * we * ld * lq;
        let i_ss = e * crate::protect::sqrt_f32(r * r + we * we * lq * lq) / d;
        let phi_ss = e * lq * crate::protect::sqrt_f32(r * r + we * we * ld * ld) / d;
        let i_lim = 0.9 * c.i_trip_a;
        let tau = l_max / r;
        let t1 = if e > 0.0 { i_lim * l_min / e } else { f32::MAX };
        let b = i_ss + phi_ss / l_min * (tau / (tau + t1));
        if b <= i_lim {
            i_lim
        } else {
            b
        }
    }

    /// How the last successful alignment found the angle (None before one, or after the
    /// angle was lost).
    pub fn aligned_by(&self) -> Option<AlignMethod> {
        if self.bs.boot == Boot::Aligned {
            self.bs.by
        } else {
            None
        }
    }

    /// Enter alignment: the emf probe first (zero current in the encoder's frame, offset 0,
    /// [`crate::align::EmfProbe`]); the d-axis steps once it finds the rotor still.
    #[cold]
    fn start_align(&mut self) {
        let (c, b) = (&self.cfg, &mut self.bs);
        b.boot = Boot::Aligning;
        b.probe = true;
        b.emf = crate::align::EmfProbe::NEW;
        b.by = None;
        b.e_per_count = self.g.enc.e_per_count;
        b.offset = None;
        b.step = 0;
        b.done = false;
        b.n = 0;
        b.n_step = ((c.align_time_s * c.pwm_hz) as u32 / SLOW_DIV as u32).max(8);
        b.n_settle = b.n_step - b.n_step / 4;
        b.i_align = crate::numtext::q_of(c.align_i_a).to_bits();
        b.di = (b.i_align / (b.n_step / 2) as i32).max(1);
        b.i_d = 0;
        b.g_short = crate::laws::Resistor::new(c.r_phase_ohm, 0.0).neg_conductance;
        b.p_start = self.enc.position;
        let per_m = c.encoder_cpr as f32 / (c.lead_m_per_rad * core::f32::consts::TAU);
        b.travel = (c.align_travel_m * per_m).min(1e9) as i32;
        b.quarter = (c.encoder_cpr / (4 * c.pole_pairs as u32).max(1)) as i32;
        b.settle = (b.quarter / 8).max(1);
        b.quarter_tol = (b.quarter / 4).max(1);
        // Alignment's own cycle (ticks ALIGN … ALIGN + 3, `step`); the feed-forward and the
        // advance stay zero: the imposed frame does not turn.
        self.held.i_ref = Dq::default();
        self.held.ff = Dq::default();
        self.held.advance = Rotation::default();
        self.held.tick_or = ALIGN;
        self.g.enc.offset = Angle(0);
        self.apply_angle();
    }

    /// The emf probe found the rotor still: the d-axis steps from here (step 0 at the
    /// imposed angle 0, the d current ramping from zero, the travel counted from here).
    #[cold]
    fn start_steps(&mut self) {
        let b = &mut self.bs;
        b.probe = false;
        b.step = 0;
        b.n = 0;
        b.i_d = 0;
        b.p_start = self.enc.position;
        self.held.i_ref = Dq::default();
        self.held.advance = Rotation::default();
        self.pi.reset();
        self.apply_angle();
    }

    /// The supervision tick's part of the emf probe: one tick of it on the last period's
    /// record; what it decides takes effect here (the steps, the angle found) or at the next
    /// tick (a fault, as the step's).
    #[cold]
    fn probe_tick(&mut self, t: &Telemetry) {
        use crate::align::{Probe, ProbeIn};
        use crate::numtext::q_f32;
        let s = ProbeIn {
            omega_m: q_f32(t.omega_m),
            v_d: q_f32(t.v_dq.d),
            v_q: q_f32(t.v_dq.q),
            saturated: t.v_saturated,
            theta_f: t.theta_e.0,
            position: self.enc.position,
        };
        let c = &self.cfg;
        let (ke, e_min) = (c.ke_v_s_per_rad, c.angle_emf_min_v);
        let (per, still) = (self.bs.e_per_count, self.bs.settle);
        match self.bs.emf.tick(&s, ke, e_min, per, still) {
            Probe::Continue => {}
            Probe::Still => self.start_steps(),
            Probe::Found { offset, ratio } => {
                self.bs.by = Some(AlignMethod::Emf {
                    ratio,
                    omega_m: s.omega_m,
                });
                self.bs.offset = Some(Angle(offset));
                self.finish_align();
            }
            Probe::Mismatch { .. } => {
                self.bs.pending = Some(Fault::EncoderMismatch);
                self.held.i_ref = Dq::default();
            }
            Probe::Timeout => {
                self.bs.pending = Some(Fault::AlignMoving);
                self.held.i_ref = Dq::default();
            }
        }
    }

    /// Leave alignment: the angle per count restored, the offset found (or the stored
    /// one's place kept for a failed or aborted alignment, and Unaligned).
    #[cold]
    fn end_align(&mut self, offset: Option<Angle>) {
        let b = &mut self.bs;
        self.g.enc.e_per_count = b.e_per_count;
        b.offset = offset;
        b.boot = if offset.is_some() {
            Boot::Aligned
        } else {
            Boot::Unaligned
        };
        self.g.enc.offset = offset.unwrap_or(Angle(0));
        self.held.i_ref = Dq::default();
    }

    /// Alignment, tick ALIGN: the current reference, the d current of the ramp and the
    /// damping q current. The rotor on the d-axis field is a spring with the structure's mass
    /// on it and little friction (ζ ≈ 0.01 on the reference TMD); the q current of a short
    /// circuit, −K_e·ω_m/R, damps it as the short would (ζ ≈ 0.7 there) while the angles are
    /// close. Zero once a fault is pending.
    #[inline(always)]
    fn align_ref(&mut self) {
        let b = &self.bs;
        self.held.i_ref = if b.pending.is_some() | b.probe {
            Dq::default()
        } else {
            let g = &self.g;
            let e_q = g.k.ke_per_vel.scale(self.enc.vel);
            Dq {
                d: Q::from_bits(b.i_d),
                q: clamp_sym(b.g_short.scale(e_q), g.i_max),
            }
        };
    }

    /// Alignment, tick ALIGN + 1: the next cycle of the step (the d current's ramp) and the
    /// travel check.
    #[inline(always)]
    fn align_ramp(&mut self) {
        let pos = self.enc.position;
        let b = &mut self.bs;
        if b.pending.is_some() | b.done | b.probe {
            return;
        }
        b.n += 1;
        b.i_d = (b.n as i32).saturating_mul(b.di).min(b.i_align);
        if pos.wrapping_sub(b.p_start).unsigned_abs() > b.travel as u32 {
            b.pending = Some(Fault::AlignMoving);
            self.held.i_ref = Dq::default();
        }
    }

    /// Alignment, tick ALIGN + 3: the settle window, the end of a step and the quarter-turn
    /// check; the offset found is put in force by the next supervision tick
    /// ([`Controller::supervise`]), as a fault found here is latched there.
    #[inline(always)]
    fn align_check(&mut self) {
        let pos = self.enc.position;
        let b = &mut self.bs;
        if b.probe {
            // The probe's output angle advance (the frame turns with the encoder).
            return self.refresh_advance();
        }
        if b.pending.is_some() | b.done {
            return;
        }
        if b.n == b.n_settle {
            b.p_settle = pos;
        } else if b.n >= b.n_step {
            // Settled: the last quarter of the step moved less than an eighth of the
            // quarter turn (11° electrical).
            let fault = if pos.wrapping_sub(b.p_settle).abs() > b.settle {
                Fault::AlignMoving
            } else if b.step == 0 {
                b.p_a = pos;
                b.step = 1;
                b.n = b.n_step / 2; // current already at full: hold only
                self.g.enc.offset = Angle(1 << 30);
                return;
            } else if (pos.wrapping_sub(b.p_a) - b.quarter).abs() > b.quarter_tol {
                Fault::AlignCheck
            } else {
                // The d axis sits at +90° electrical at this count.
                let per = b.e_per_count;
                b.offset = Some(Angle(
                    (1u32 << 30).wrapping_sub(self.enc.in_turn.wrapping_mul(per)),
                ));
                b.by = Some(AlignMethod::Steps);
                b.done = true;
                return;
            };
            b.pending = Some(fault);
            self.held.i_ref = Dq::default();
        }
    }

    /// The supervision tick's end of a successful alignment: the offset found in force,
    /// Idle.
    #[cold]
    fn finish_align(&mut self) {
        self.end_align(self.bs.offset);
        self.mode = Mode::Idle;
        self.pi.reset();
    }

    /// Idle period during the boot calibration: sum the phase codes (gates off, so the
    /// currents are zero unless the line back-emf exceeds the bus); after [`CAL_PERIODS`]
    /// the rounded means become the zero codes, or `current_offset` latches.
    #[cold]
    #[inline(never)]
    fn calibrate(&mut self) {
        let w = &self.rec.w;
        let b = &mut self.bs;
        for (sum, &c) in b.sum.iter_mut().zip(&w[..3]) {
            *sum += (c as u32).min(CODE_MAX);
        }
        b.n_cal += 1;
        if b.n_cal < CAL_PERIODS {
            return;
        }
        let nominal = self.cfg.adc_zero_code as i32;
        // The codes were seen through the offsets in force: the raw zero is their mean plus
        // those offsets.
        let z = [0, 1, 2]
            .map(|k| ((b.sum[k] + CAL_PERIODS / 2) / CAL_PERIODS) as i32 + b.zero[k] - nominal);
        let tol = (self.cfg.offset_tol_a / self.cfg.amps_per_count) as i32;
        if z.iter().any(|&c| (c - nominal).abs() > tol) {
            b.n_cal = 0;
            b.sum = [0; 3];
            b.pending = Some(Fault::CurrentOffset);
            b.boot = Boot::Unaligned; // no further sums until the fault is cleared
            return;
        }
        b.zero = z;
        b.boot = Boot::Unaligned;
    }

    pub fn mode(&self) -> Mode {
        self.mode
    }

    pub fn fault(&self) -> Option<Fault> {
        self.fault
    }

    /// Clear a latched fault once its cause is gone (the drive stays in its safe mode until
    /// told otherwise). Refused, with the reason, while the cause persists.
    pub fn clear_fault(&mut self) -> Result<(), &'static str> {
        if let Some(f) = self.fault {
            let tel = self.telemetry();
            let later = self.prot.record().map_or(0, |r| r.later);
            // The first fault's cause and every later one's must be gone.
            for g in core::iter::once(f).chain(
                Fault::ALL
                    .iter()
                    .copied()
                    .filter(|g| later & (1 << g.code()) != 0),
            ) {
                if let Some(why) = self
                    .prot
                    .cause_present(g, &self.cfg, &tel, self.enc.implausible)
                {
                    return Err(why);
                }
            }
        }
        if matches!(self.fault, Some(Fault::CurrentOffset)) {
            self.bs.boot = Boot::Calibrating; // measure again
        }
        if matches!(self.fault, Some(Fault::AngleImplausible)) && self.bs.boot == Boot::Aligned {
            self.bs.boot = Boot::Unaligned; // the angle is not trusted: align again
        }
        self.fault = None;
        self.prot.forget();
        Ok(())
    }

    /// Protection state: fault record with its snapshot, warnings, I²t, derate factor.
    pub fn protection(&self) -> &Protection {
        &self.prot
    }

    /// A trip the hardware took by itself (a comparator through the timer's break input:
    /// the bridge is already off): latched as the software's own trip of that kind, with the
    /// last period's telemetry, and the mode is the one the break holds the gates in, open
    /// (the G4's BRK2 cannot short; a firmware short is opened by BRK), whatever the rule
    /// would choose: the outputs stay off until the firmware re-enables them.
    #[cold]
    pub fn hardware_trip(&mut self, f: Fault) {
        let t = self.telemetry();
        self.trip(f, &t);
        if self.mode != Mode::Idle {
            self.mode = Mode::Idle;
            self.refresh_now();
        }
    }

    /// The board's timer saw the current loop finish after its period ended.
    pub fn report_overrun(&mut self) {
        self.prot.report_overrun();
    }

    /// Current-loop periods per supervision tick: call [`Controller::supervise`] once every
    /// this many [`Controller::step`]s (1 kHz).
    pub fn supervise_every(&self) -> u32 {
        let n = self.cfg.pwm_hz / SUPERVISE_HZ + 0.5;
        (n as u32).max(1)
    }

    /// Decimated protection (1 kHz, see protect.rs): I²t, force rating, stroke, speed and
    /// encoder plausibility, current-sensor consistency, overruns, and the regenerative
    /// derate factor the loop applies. Reads the last period's telemetry; call it between
    /// steps (same execution context as the loop, or with the controller locked).
    pub fn supervise(&mut self) {
        let t = self.telemetry();
        let v = self
            .prot
            .supervise(&self.cfg, self.mode, &t, self.enc.position);
        if self.bs.done && self.mode == Mode::Align {
            self.finish_align();
        }
        if self.mode == Mode::Align && self.bs.probe && self.bs.pending.is_none() {
            self.probe_tick(&t);
        }
        if let Some(f) = self.bs.pending.take() {
            self.trip(f, &t);
        } else if let Some(f) = v.trip {
            self.trip(f, &t);
        } else if self.bs.boot == Boot::Aligned && self.mode == Mode::Run {
            self.trim_angle();
        }
    }

    /// After a power-up alignment, the offset follows the emf's angle (protect.rs): the
    /// d-axis alignment leaves the rotor lagging its field by the structure's load
    /// (asin(F·l/T_align): 18° electrical at 325 N on the reference TMD). Each supervision
    /// tick moves the offset by 1/200 of the error (τ = 0.2 s), at most 2 mrad (2 rad/s):
    /// far slower than the plausibility check latches a large error (20 ms).
    #[cold]
    fn trim_angle(&mut self) {
        let e = self.prot.angle_err;
        let step = (e * (1.0 / 200.0)).clamp(-2e-3, 2e-3);
        // rad → angle LSB (2^32 per turn).
        let d = (step * (4_294_967_296.0 / core::f32::consts::TAU)) as i32;
        if let Some(o) = self.bs.offset.as_mut() {
            o.0 = o.0.wrapping_sub(d as u32);
            self.g.enc.offset = *o;
        }
    }

    /// The last period's electrical power out of the machine, `−3/2·(v_d·i_d + v_q·i_q)`
    /// ([`Telemetry::p_elec`]), alone: the period's energy sum (`crate::period`) reads it
    /// every period without building the whole [`Telemetry`] (its currents, bus voltage,
    /// speed and position conversions: ≈ 180 host instructions a period). Inline on the
    /// host (the simulator's loop); one copy on the board, which [`Controller::telemetry`]
    /// shares (inlined into the interrupt too it cost 108 bytes of flash).
    #[cfg_attr(target_os = "none", inline(never))]
    #[cfg_attr(not(target_os = "none"), inline)]
    pub fn p_elec(&self) -> Q {
        let (v, i) = (self.rec.v_dq(), self.rec.i_dq());
        let p = mul(v.d, i.d).saturating_add(mul(v.q, i.q));
        p.saturating_add(p / 2).saturating_neg()
    }

    /// The words of the last period's record the capture reads (`crate::capture`: indices
    /// [`W_ID`] … [`W_POS`], the phase codes at 0 … 2): what the step stored, no conversion;
    /// and at [`W_P`] `p_bits`, the period's power ([`Controller::p_elec`]'s bits, which the
    /// period computes for its energy sum), put there by this call (one store).
    #[inline(always)]
    pub fn cap_words_with_power(&mut self, p_bits: i32) -> &[i32; CAP_WORDS] {
        self.rec.w[W_P] = p_bits;
        &self.rec.w
    }

    /// Telemetry of the last period (derived here from what the step stored).
    pub fn telemetry(&self) -> Telemetry {
        let (g, r) = (&self.g, &self.rec);
        let amps = |k: usize| amps_of_code(g.amps_per_count, g.adc_zero, r.code(k));
        Telemetry {
            i_abc: [amps(0), amps(1), amps(2)],
            i_dq: r.i_dq(),
            i_ref: r.i_ref(),
            v_dq: r.v_dq(),
            v_bus: volts_of_code(g.volts_per_count, r.code(W_VBUS)),
            omega_m: self.enc.omega_m(&g.enc),
            x: self.enc.x(&g.enc),
            theta_e: r.theta_e,
            p_elec: self.p_elec(),
            duties: r.duties,
            v_saturated: r.v_saturated,
            brake: self.brake,
        }
    }

    pub fn law_mut(&mut self) -> &mut Law {
        if self.mode != Mode::Align {
            self.slow_tick = 0; // the law may change: its terms at the next step (tick 0)
        }
        &mut self.law
    }

    /// Zero the position (the travel `x` counts from here).
    pub fn rezero_position(&mut self) {
        self.enc.rezero();
        self.prot.rezero();
    }

    /// Latch `f` (with a snapshot of `t`) and go to the safe state `protect::next_mode`
    /// decides (open dominates, with its stated exceptions above the diode onset): both halves
    /// of a latch at once.
    #[cold]
    fn trip(&mut self, f: Fault, t: &Telemetry) {
        let above = t.omega_m.to_bits().unsigned_abs() >= self.g.onset_w;
        let before = self.latch_mode(f, self.latched_bits(), above);
        self.latch_record(f, before, t);
    }

    /// The first half of a latch, what the outputs depend on: the fault and the safe mode in
    /// force (`protect::latch_next`), given the faults latched before it (`latched`, bits as
    /// [`Controller::latched_bits`] gives them once their records are written) and whether the
    /// speed estimate is above the diode onset (`above`, `protect::above_onset` as
    /// `Gains::onset_w` decides it). Returns the mode it found the drive in.
    fn latch_mode(&mut self, f: Fault, latched: u32, above: bool) -> Mode {
        let before = self.mode;
        self.mode = crate::protect::latch_next(self.fault.is_some(), latched, before, f, above);
        if self.fault.is_none() {
            self.fault = Some(f);
        }
        before
    }

    /// The second half: the record with the snapshot `t` (taken in mode `before`), then
    /// [`Controller::settle_latch`].
    #[cold]
    fn latch_record(&mut self, f: Fault, before: Mode, t: &Telemetry) {
        self.prot.latch(f, before, t);
        self.settle_latch(before);
    }

    /// After a latch's records: an alignment ended (`before`, the mode the latch found), the
    /// PI reset and the slow terms for the new mode (all of it a function of the state the
    /// records leave: once is as good as twice).
    fn settle_latch(&mut self, before: Mode) {
        if before == Mode::Align {
            self.end_align(None);
        }
        self.pi.reset();
        self.refresh_now();
    }

    /// The latched faults (first and later) as bits `1 << code`.
    fn latched_bits(&self) -> u32 {
        self.prot.record().map_or(0, |r| r.later) | self.fault.map_or(0, |g| 1 << g.code())
    }

    /// Which faults, once the step has seen that one occurred; the first half of their
    /// latch: the mode after all of them (`protect::latch_found`, read from its table,
    /// `protect::step_safe_mode`) and the first fault in force.
    #[cold]
    #[inline(never)]
    fn trip_on(&mut self, s: &RawSample, over_current: bool, over_voltage: bool) {
        use crate::protect::{
            FOUND_ENCODER, FOUND_OC, FOUND_OV, FOUND_RAIL, FOUND_UNDER_V, SPEED_DOUBT,
        };
        if self.latching.found != 0 {
            self.finish_latch(); // a latch left unfinished by a caller: finished first
        }
        let latched = self.latched_bits();
        // At the rail without having passed the trip below it: a false reading.
        let rail = over_voltage & (s.v_bus >= 4095) & (latched & Fault::BusOverVoltage.bit() == 0);
        let mut found = (over_current as u8 * FOUND_OC)
            | (over_voltage as u8 * FOUND_OV)
            | (rail as u8 * FOUND_RAIL);
        if found == 0 {
            found = if self.enc.implausible {
                FOUND_ENCODER
            } else if self.mode == Mode::Run {
                FOUND_UNDER_V
            } else {
                return; // a low bus matters only while running
            };
        }
        // The outputs are safe from this period on (the step continues in the new mode); the
        // records and the slow terms follow after the actuation (`complete_latch`).
        // The speed as the snapshot has it (the encoder as just updated).
        let w = self.enc.omega_m(&self.g.enc);
        let above = w.to_bits().unsigned_abs() >= self.g.onset_w;
        let before = self.mode;
        let has_fault = self.fault.is_some();
        self.mode = crate::protect::step_safe_mode(
            found,
            before,
            has_fault,
            latched & SPEED_DOUBT != 0,
            above,
        );
        if !has_fault {
            self.fault = crate::protect::found_faults(found).map(|(f, _)| f);
        }
        self.latching = Latching {
            found,
            before,
            i_dq: self.rec.i_dq(),
        };
    }

    /// Finish a latch the last step began, nothing otherwise (see [`Latching`]): the fault
    /// records with the snapshot (this period's phase codes and bus, the encoder as that step
    /// updated it, the last period's d/q currents, the mode the step found), the PI reset and
    /// the slow terms for the safe mode. The period routine calls it right after the
    /// actuation ([`crate::period::Period::finish`]); [`Controller::step`] calls it itself.
    #[inline(always)]
    pub fn complete_latch(&mut self) {
        if self.latching.found != 0 {
            self.finish_latch();
        }
    }

    #[cold]
    #[inline(never)]
    fn finish_latch(&mut self) {
        let l = core::mem::take(&mut self.latching);
        // The telemetry's codes are this period's sample (the step records it first).
        let t = Telemetry {
            i_dq: l.i_dq,
            ..self.telemetry()
        };
        if let Some((f, second)) = crate::protect::found_faults(l.found) {
            self.prot.latch(f, l.before, &t);
            if let Some(g) = second {
                // The record exists now: the second fault is added to it (`later`); the mode
                // it found, the first's safe mode, is no snapshot's.
                self.prot.latch(g, self.mode, &t);
            }
            self.settle_latch(l.before);
        }
    }

    /// One current-loop period, complete: [`Controller::step_outputs`] then
    /// [`Controller::complete_latch`]. The period routine calls the two halves with the
    /// actuation between them.
    #[inline]
    pub fn step(&mut self, s: &RawSample) -> Actuation {
        let a = self.step_outputs(s);
        self.complete_latch();
        a
    }

    /// One current-loop period up to its outputs (what the board's interrupt runs before it
    /// writes them). A fault found here is in force at once (its safe mode gives this
    /// period's outputs); its record and slow terms wait for [`Controller::complete_latch`].
    ///
    /// Ranges (the reason most arithmetic below needs no saturation): ADC codes are 12-bit
    /// (larger codes are clamped where they enter arithmetic); `amps_per_count ≤ 1`,
    /// `volts_per_count ≤ 1` and 4096 codes < 30,000 A or V (validated), so `|α|, |β|` <
    /// 2,731 A and `|i_dq|` < 3,614 A (< 2^28 LSB), `V_bus` < 30,000 V; `|i_ref|` ≤
    /// `i_max·(1 + 2^-12)` ≤ 1,001 A.
    ///
    /// Never inlined: on the board it stays a function of this crate, compiled at this crate's
    /// opt-level (`s`), while the rest of the image is built for size (`z`), see
    /// `firmware/board/Cargo.toml`. The call costs a few cycles of the 8,500 of a period.
    #[inline(never)]
    pub fn step_outputs(&mut self, s: &RawSample) -> Actuation {
        let k = &self.g.k;

        // ---- Measurements (scalings folded into constants; the zero code cancels) ----
        // The record of this period starts with its sample, copied first while no other value
        // holds a register, as two words and a half-word (a whole-struct copy becomes a
        // `memcpy` call when the board builds for size).
        self.rec.w[0] = s.i_abc[0] as i32;
        self.rec.w[1] = s.i_abc[1] as i32;
        self.rec.w[2] = s.i_abc[2] as i32;
        self.rec.w[W_VBUS] = s.v_bus as i32;
        // Element by element: `map` becomes a loop through the stack when built for size.
        // The two phases whose low-side shunts conducted at the sample (from the duties in
        // force then: the last step's), the third from the zero sum (`shunt`).
        let [ia, ib, ic] = crate::shunt::two_valid(
            [s.i_abc[0] as i32, s.i_abc[1] as i32, s.i_abc[2] as i32],
            &self.rec.duties,
            k.zero3,
        );
        // Phase over-current on the codes, while they are in registers (protection below).
        let lo = k.i_lo;
        let off = |c: i32| (c as u32).wrapping_sub(lo);
        let over_i = off(ia).max(off(ib)).max(off(ic)) > k.i_span;
        // For 12-bit codes 2a − b − c ∈ ±8190 and b − c ∈ ±4095: the clamps (one SSAT each)
        // change nothing then and bound anything larger.
        // The codes arrive with the boot calibration's per-phase offsets removed by the ADC
        // ([`Controller::adc_offsets`]): the common zero code cancels here.
        let s_alpha = (2 * ia - ib - ic).clamp(-8192, 8191);
        let s_beta = (ib - ic).clamp(-4096, 4095);
        // 8192·apc/3 < 2,731 A: fits.
        let i_ab = AlphaBeta {
            alpha: Q::from_bits(k.alpha_per_code.apply(s_alpha)),
            beta: Q::from_bits(k.beta_per_code.apply(s_beta)),
        };
        let vb = s.v_bus as u32;
        let theta_e = self.enc.update(s.encoder, &self.g.enc);

        // ---- Protection (instantaneous, on raw codes) ----
        // Phase over-current (above), bus over-/under-voltage, implausible encoder step.
        // Further per-step protection hooks in here; the first fault found wins (see
        // `trip_on`).
        let k = &self.g.k;
        let over_v = vb > k.ov;
        // Under-voltage is a fault only in Run: `trip_on` decides (keeps the test cheap).
        let under_v = vb < k.uv;
        // Brake chopper with hysteresis (independent of mode: it protects the bus).
        // (The threshold indexed by the state: one load, no select.)
        self.brake = vb > k.brake[self.brake as usize];
        if over_i | over_v | self.enc.implausible | under_v {
            self.trip_on(s, over_i, over_v);
        }
        // ---- End of protection ----

        let (sin, cos) = theta_e.sin_cos();
        let i_dq = park_bounded(i_ab, sin, cos);
        // The rest of this period's record, written as its values become known (after
        // `trip_on`, whose snapshot takes them from the last period).
        self.rec.set_dq(W_ID, i_dq);
        self.rec.theta_e = theta_e;

        // Run, Open and Align control current: the odd discriminants, one bit to test
        // (`matches!` becomes a range check and a bit-mask test: 4 instructions more).
        if self.mode as u8 & 1 == 0 {
            return self.step_off();
        }
        // Slow terms: the back-emf and the law's current reference (limited to
        // i_max), the feed-forward, the bus terms (the voltage circle, 1/V_bus) and
        // the output-angle advance. For the resistor law they depend on the speed
        // estimate alone, which changes at the rate of the motion and the PLL (≤
        // speed_bw_hz), and the bus voltage moves slowly on its capacitor (a few
        // amperes into millifarads: well under 1 % of the bus in 200 µs); so they are
        // refreshed every SLOW_DIV periods (5 kHz at 20 kHz) and held between, and the
        // PI (1 kHz bandwidth, inside the loop) corrects what the hold leaves. The bus
        // trips above still compare every sample. Other laws keep their own rates and
        // run every period (their `tick_or` keeps the tick at REFRESH_ALL).
        // The four groups are refreshed on different periods of the cycle (back-emf
        // and law on tick 0, feed-forward on tick 1, bus on tick 2, angle advance on
        // tick 3) so that no single period pays for more than one group. A refresh
        // request (configuration or mode change, trip) is served where it is made
        // (`refresh_now`, outside the step's normal path), so no period pays for all of
        // them; `law_mut` makes the next step the law's tick (tick 0).
        // Alignment runs a cycle of its own through the same table (ticks ALIGN … ALIGN + 3:
        // reference, ramp and travel, bus, checks), so that no period of it pays for more
        // than one group either.
        let t = self.slow_tick;
        match t {
            0 => self.refresh_law(i_dq, vb),
            1 => self.refresh_ff(),
            2 | ALIGN_BUS => self.refresh_bus(vb),
            3 => self.refresh_advance(),
            ALIGN => self.align_ref(),
            ALIGN_RAMP => self.align_ramp(),
            ALIGN_CHECK => self.align_check(),
            _ => self.refresh_all(i_dq, vb),
        }
        self.slow_tick = ((t + 1) & (SLOW_DIV - 1)) | self.held.tick_or;
        let h = &self.held;

        // |i_ref| ≤ 1,001 A and |i_dq| < 3,614 A: the differences fit.
        let err = Dq {
            d: Q::from_bits(h.i_ref.d.to_bits().wrapping_sub(i_dq.d.to_bits())),
            q: Q::from_bits(h.i_ref.q.to_bits().wrapping_sub(i_dq.q.to_bits())),
        };
        let out = self.pi.update_within(err, h.ff, &self.g.pi, &h.v_lim);
        self.rec.set_dq(W_ID_REF, h.i_ref);
        self.rec.set_dq(W_VD, out.v);
        self.rec.v_saturated = out.saturated;
        let h = &self.held;

        // Output angle advanced by 1.5 periods of rotation (sample-to-PWM delay): the
        // held rotation (cos a, sin a) applied to (sin θ, cos θ) by the angle-sum
        // formulas, in place of a second table look-up.
        let (s2, c2) = h.advance.rotate(sin, cos);
        // |out.v| ≤ v_max·(1 + 2^-12) < 2^30 LSB (v_max < 0.58·30,000 V).
        // `black_box` is a value barrier only (no effect on the result): without it the
        // step at opt-level 3 is 13 instructions longer at its worst, as the board builds
        // it 2 shorter (`docs/m4check.md`).
        let v_ab = inverse_park_bounded(core::hint::black_box(out.v), s2, c2);
        let duties = modulate_scaled(v_ab, h.inv8);
        self.rec.duties = duties;
        self.record_encoder();
        Actuation {
            duties,
            enable: true,
            brake: self.brake,
        }
    }

    /// The speed estimate and the count into the record, for the capture (last in the step:
    /// earlier, while the step's values fill the registers, the two stores cost spills).
    #[inline(always)]
    fn record_encoder(&mut self) {
        self.rec.w[W_VEL] = self.enc.vel.to_bits();
        self.rec.w[W_POS] = self.enc.position;
    }

    /// The end of a period in Idle or Short: no control, the record says so.
    #[cold]
    #[inline(never)]
    fn step_off(&mut self) -> Actuation {
        self.record_encoder();
        if self.mode == Mode::Measure {
            if let Some(a) = self.measure_step() {
                return a;
            }
            self.mode = Mode::Idle;
        }
        if self.bs.boot == Boot::Calibrating && self.mode == Mode::Idle {
            self.calibrate();
        }
        let (duties, enable) = if self.mode == Mode::Short {
            ([Duty::ZERO; 3], true)
        } else {
            (CENTRED, false)
        };
        self.rec.set_dq(W_ID_REF, Dq::default());
        self.rec.set_dq(W_VD, Dq::default());
        self.rec.duties = duties;
        self.rec.v_saturated = false;
        Actuation {
            duties,
            enable,
            brake: self.brake,
        }
    }

    /// A period of the measurement ([`crate::commission`]): its d/q voltage, advanced by
    /// 1.5 periods of rotation as the loop's, through the modulation; `None` when it is over.
    #[cold]
    #[inline(never)]
    fn measure_step(&mut self) -> Option<Actuation> {
        use crate::numtext::{q_f32, q_of};
        let t = self.telemetry();
        let w = q_f32(t.omega_m);
        let i = [q_f32(t.i_dq.d), q_f32(t.i_dq.q)];
        let v = self
            .meas
            .step(&self.cfg, i, w, q_f32(t.x), q_f32(t.v_bus))?;
        let v = Dq {
            d: q_of(v[0]),
            q: q_of(v[1]),
        };
        let adv = 1.5 * self.cfg.ts() * self.cfg.pole_pairs as f32 * w;
        let adv = (adv * (4_294_967_296.0 / core::f32::consts::TAU)) as i32 as u32;
        let (sin, cos) = Angle(t.theta_e.0.wrapping_add(adv)).sin_cos();
        let v_ab = inverse_park_bounded(v, sin, cos);
        let duties = modulate_scaled(v_ab, (inv_bus(t.v_bus) << 8) as i32);
        let r = self.meas.i_ref();
        self.rec.set_dq(
            W_ID_REF,
            Dq {
                d: q_of(r[0]),
                q: q_of(r[1]),
            },
        );
        self.rec.set_dq(W_VD, v);
        self.rec.duties = duties;
        self.rec.v_saturated = false;
        Some(Actuation {
            duties,
            enable: true,
            brake: self.brake,
        })
    }

    /// The commissioning measurement: its state and results.
    pub fn measurement(&self) -> &crate::commission::Measure {
        &self.meas
    }

    /// Tick 0: back-emf `K_e·ω_e` from the speed estimate, and the resistor law's reference
    /// from it: `i_q* = −clamp(G·e_q, i_max)` with the law's conductance `G = 1/(R + R_L)` in
    /// Run (zero in Open), derated. Ticks 0 … 3 run under the resistor law (`tick_or` = 0);
    /// should `law_mut` have put another law in its place, every term is refreshed instead,
    /// and from then on every period.
    #[inline(always)]
    fn refresh_law(&mut self, i_dq: Dq, vb: u32) {
        let mut law = match &self.law {
            Law::Resistor(r) if self.mode == Mode::Run => *r,
            Law::Resistor(_) => Resistor {
                neg_conductance: Gain::ZERO,
            },
            _ => return self.refresh_all(i_dq, vb),
        };
        let g = &self.g;
        let e_q = g.k.ke_per_vel.scale(self.enc.vel);
        self.held.e_q = e_q;
        // The law itself (`Resistor::command`, inlined: it reads only `e_q`), then the
        // current limit.
        let c = law.command(&LawInput {
            e_q,
            ..LawInput::default()
        });
        let r = Dq {
            d: clamp_sym(c.d, g.i_max),
            q: clamp_sym(c.q, g.i_max),
        };
        self.held.i_ref = derated(r, e_q, &self.prot);
    }

    /// Tick 1: the feed-forward from the held back-emf and reference.
    #[inline(always)]
    fn refresh_ff(&mut self) {
        self.held.ff = feed_forward(&self.g, self.enc.vel, self.held.i_ref, self.held.e_q);
    }

    /// Tick 2: the bus terms, from this period's bus code (4095·vpc < 30,000 V).
    #[inline(always)]
    fn refresh_bus(&mut self, vb: u32) {
        let k = &self.g.k;
        let vb12 = vb.min(CODE_MAX) as i32;
        let v_bus = Q::from_bits(k.volts_per_code.apply(vb12));
        // v_max = m_max/√3·v_bus < 17,321 V, from the same code.
        self.held.v_lim = VLimit::new(Q::from_bits(k.v_max_per_code.apply(vb12)));
        // inv_bus < 2^23: its 2^8 multiple fits an i32 (see `modulate_scaled`).
        self.held.inv8 = (inv_bus(v_bus) << 8) as i32;
    }

    /// Tick 3: the output-angle advance, 1.5 periods of rotation at the speed estimate:
    /// |vel·adv_per_vel| < 2^62; the angle wraps (mod 2^32) by design.
    #[inline(always)]
    fn refresh_advance(&mut self) {
        let adv = ((self.enc.vel.to_bits() as i64 * self.g.k.adv_per_vel as i64) >> 12) as u32;
        self.held.advance = Rotation::of(Angle(adv));
    }

    /// The tick schedule for the law in force; true under the resistor law.
    #[inline(always)]
    fn setup_law(&mut self) -> bool {
        let resistor = matches!(self.law, Law::Resistor(_));
        self.held.tick_or = if resistor { 0 } else { REFRESH_ALL };
        resistor
    }

    /// `REFRESH_ALL`: a law other than the resistor (all its terms every period), or the
    /// resistor law put back by `law_mut` in place of another, or a request served by
    /// `refresh_now` (the law's reference now). (`new` starts with it too, in Idle; `set_mode`
    /// serves the request before any step runs the loop.)
    #[inline(never)]
    fn refresh_all(&mut self, i_dq: Dq, vb: u32) {
        if self.mode == Mode::Align {
            // (Not reached: alignment keeps its own cycle.)
            self.held.tick_or = ALIGN;
            return self.align_ref();
        }
        if self.setup_law() {
            self.refresh_law(i_dq, vb);
            return;
        }
        // Out of line from here: the laws that take this path run far longer anyway.
        let e_q = self.g.k.ke_per_vel.scale(self.enc.vel);
        self.held.e_q = e_q;
        self.held.i_ref = if self.mode == Mode::Run {
            let r = other_law(&mut self.law, &self.enc, &self.g, e_q, i_dq, vb);
            derated(r, e_q, &self.prot)
        } else {
            Dq::default()
        };
        self.refresh_rest(vb);
    }

    /// The feed-forward, bus and advance groups (out of line: one copy besides the step's own
    /// for `refresh_all` and `refresh_now`).
    #[inline(never)]
    fn refresh_rest(&mut self, vb: u32) {
        self.refresh_ff();
        self.refresh_bus(vb);
        self.refresh_advance();
    }

    /// Serve a refresh request (configuration or mode changed, or a trip) at once, outside
    /// the step's normal path: under the resistor law every slow term is recomputed from the
    /// last period's sample and speed, and the next step starts the cycle with the bus terms
    /// from its own sample. Other laws advance their state once per step, so they refresh at
    /// the next step (and every step).
    fn refresh_now(&mut self) {
        if self.mode == Mode::Align {
            // Alignment's own cycle, from its bus terms on.
            self.slow_tick = ALIGN_BUS;
            return;
        }
        if matches!(self.law, Law::Resistor(_)) {
            let (i_dq, vb) = (self.rec.i_dq(), self.rec.w[W_VBUS] as u32);
            self.refresh_all(i_dq, vb);
            self.refresh_rest(vb);
            self.slow_tick = 2;
        } else {
            self.held.tick_or = REFRESH_ALL;
            self.slow_tick = REFRESH_ALL;
        }
    }
}

/// Periods per refresh of the slow terms under the resistor law (a power of two, ≥ 4: the
/// four groups take ticks 0 … 3).
const SLOW_DIV: u8 = 4;
/// `slow_tick` value that refreshes every slow term at the next step (any value ≥ 8 does).
const REFRESH_ALL: u8 = 2 * SLOW_DIV;
/// Alignment's cycle (`tick_or` = ALIGN): its reference, its ramp and travel check, the bus
/// terms, its settle and quarter-turn checks.
const ALIGN: u8 = SLOW_DIV;
const ALIGN_RAMP: u8 = ALIGN + 1;
const ALIGN_BUS: u8 = ALIGN + 2;
const ALIGN_CHECK: u8 = ALIGN + 3;

/// Current reference, feed-forward, bus terms and angle advance, held between refreshes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct HeldTerms {
    i_ref: Dq,
    /// Back-emf `K_e·ω_e` (refreshed with the law; the feed-forward's q term).
    e_q: Q,
    ff: Dq,
    /// The voltage circle (radius m_max/√3·V_bus).
    v_lim: VLimit,
    /// `inv_bus(V_bus)·2^8`.
    inv8: i32,
    advance: Rotation,
    /// 0 under the resistor law (tick cycle), ALIGN while aligning, REFRESH_ALL under the
    /// other laws (every period).
    tick_or: u8,
}

/// Phase current of an ADC code, A, for `Gains::amps_per_count` and `Gains::adc_zero`
/// (telemetry, fault snapshots and the capture's dump; not on the loop's path).
pub fn amps_of_code(amps_per_count: Gain, adc_zero: i32, code: u16) -> Q {
    amps_per_count.scale(Q::from_bits((code as i32 - adc_zero) << 16))
}

/// Bus voltage of an ADC code, V, for `Gains::volts_per_count` (telemetry, fault snapshots
/// and the capture's dump).
pub fn volts_of_code(volts_per_count: Gain, code: u16) -> Q {
    volts_per_count.scale(Q::from_bits((code as i32) << 16))
}

/// Protection hook (protect.rs): bus derating of a regenerative reference (`e_q` has the
/// sign of the speed). At the factor 1 (no derating, the normal case) the product is the
/// reference itself (Q16.16 `x·1 = x` exactly), so it is skipped.
/// Flux braking's d current is added on the same path (`protect::bus_action`): the common
/// path tests one flag, set by the supervision when either is in force.
#[inline(always)]
fn derated(r: Dq, e_q: Q, p: &Protection) -> Dq {
    if p.act {
        bus_action(r, e_q, p)
    } else {
        r
    }
}

/// The feed-forward: back-emf on q, cross-coupling ∓ω_e·L·i (speed estimate `vel`).
#[inline(always)]
fn feed_forward(g: &Gains, vel: Q, i_ref: Dq, e_q: Q) -> Dq {
    let mut ff = Dq {
        d: Q::ZERO,
        q: if g.ff_emf { e_q } else { Q::ZERO },
    };
    if g.ff_decouple {
        let wl = g.k.wl_per_vel.scale(vel);
        // |i_ref.q| ≤ i_max·(1 + 2^-12) (limited by the law terms, then derated by a factor
        // in [0, 1] that only protect.rs sets): its negation fits. (The product's floor then
        // rounds the other way: 1 LSB, 15 µV.)
        ff.d = mul(wl, -i_ref.q);
        if i_ref.d != Q::ZERO {
            ff.q = ff.q.saturating_add(mul(wl, i_ref.d));
        }
    }
    ff
}

/// The laws other than the resistor (dynamic laws, decimated inside), kept out of line so
/// the step's common path stays small; the reference limited to `i_max`.
#[inline(never)]
fn other_law(law: &mut Law, enc: &Encoder, g: &Gains, e_q: Q, i_dq: Dq, vb: u32) -> Dq {
    // Bus: 4095·vpc < 30,000 V.
    let v_bus = Q::from_bits(g.k.volts_per_code.apply(vb.min(CODE_MAX) as i32));
    let r = law.command(&LawInput {
        omega_m: enc.omega_m(&g.enc),
        e_q,
        x: enc.x(&g.enc),
        i_dq,
        v_bus,
    });
    if r.d == Q::ZERO {
        Dq {
            d: Q::ZERO,
            q: clamp_sym(r.q, g.i_max),
        }
    } else {
        limit_vector(r, g.i_max).unwrap_or(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::laws::LawKind;
    use proptest::prelude::*;
    use std::vec;

    /// A configuration anywhere in the validated ranges, at the extremes most of the time
    /// (the ranges the step's no-saturation arguments rely on).
    fn extreme_config() -> impl Strategy<Value = Config> {
        (
            prop::sample::select(vec![1e-5f32, 0.0122, 0.5, 1.0]),
            // Smallest bus scale whose full scale (2 V) still admits the protection thresholds.
            prop::sample::select(vec![5e-4f32, 0.0293, 1.0]),
            prop::sample::select(vec![1e-6f32, 6e-3, 1.0]),
            prop::sample::select(vec![1e-4f32, 0.943, 20.0]),
            prop::sample::select(vec![1u8, 5, 50]),
            prop::sample::select(vec![16u32, 10_000, 16_384]),
            prop::sample::select(vec![5_000.0f32, 20_000.0, 100_000.0]),
            prop::sample::select(vec![0.1f32, 0.95, 1.0]),
            prop::sample::select(vec![0.0f32, 1.937, 1_000.0]),
            prop::sample::select(vec![0.0f32, 2.0, 306.0, f32::INFINITY]),
            prop::sample::select(LawKind::ALL.to_vec()),
            any::<(bool, bool, bool)>(),
        )
            .prop_map(
                |(apc, vpc, l, ke, pp, cpr, pwm, m, imax, rl, law, (fe, fd, dc))| {
                    let d = Config::default();
                    // Bus thresholds inside the ADC's full scale, in the order validation
                    // requires (brake, then derate, then the over-voltage trip).
                    let ov = (0.98 * vpc * 4095.0).min(2_000.0);
                    Config {
                        amps_per_count: apc,
                        volts_per_count: vpc,
                        l_phase_h: l,
                        ke_v_s_per_rad: ke,
                        pole_pairs: pp,
                        encoder_cpr: cpr,
                        pwm_hz: pwm,
                        current_bw_hz: d.current_bw_hz.min(0.09 * pwm),
                        speed_bw_hz: d.speed_bw_hz.min(0.04 * pwm),
                        m_max: m,
                        i_max_a: imax,
                        i_trip_a: 2_000.0,
                        v_bus_ov: ov,
                        v_bus_uv: 0.0,
                        brake_on_v: 0.9 * ov,
                        brake_off_v: 0.85 * ov,
                        derate_start_v: 0.92 * ov,
                        derate_end_v: 0.96 * ov,
                        // Current-sum check above quantisation (validation: ≥ 4 counts).
                        i_sum_tol_a: d.i_sum_tol_a.max(8.0 * apc),
                        // Infinite R_L: refused by the impedance law.
                        r_load_ohm: if matches!(law, LawKind::Impedance) && !rl.is_finite() {
                            1.0
                        } else {
                            rl
                        },
                        law,
                        law_rate_hz: pwm.min(1_000.0),
                        ff_emf: fe,
                        ff_decouple: fd,
                        delay_comp: dc,
                        ..d
                    }
                },
            )
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]

        /// Any raw sample, any validated configuration, every mode: the step never panics
        /// (debug builds check every no-saturation bound the step relies on), duties stay in
        /// [0, 1] and the voltage command stays within the bus circle.
        #[test]
        fn step_never_overflows(cfg in extreme_config(),
                                samples in prop::collection::vec(any::<[u16; 5]>(), 1..40),
                                mode in prop::sample::select(vec![Mode::Run, Mode::Open, Mode::Idle, Mode::Short])) {
            let mut ctl = Controller::new(&cfg).unwrap();
            for x in samples {
                if ctl.fault().is_some() {
                    let _ = ctl.clear_fault();
                }
                let _ = ctl.set_mode(mode);
                let s = RawSample { i_abc: [x[0], x[1], x[2]], v_bus: x[3], encoder: x[4] };
                let a = ctl.step(&s);
                for d in a.duties {
                    prop_assert!(d <= Duty::ONE);
                }
                let t = ctl.telemetry();
                let vb = (x[3].min(4095) as f64) * cfg.volts_per_count as f64;
                let v = (t.v_dq.d.to_num::<f64>().powi(2) + t.v_dq.q.to_num::<f64>().powi(2)).sqrt();
                prop_assert!(v <= vb * cfg.m_max as f64 / 3f64.sqrt() * (1.0 + 3e-4) + 1e-3,
                             "|v| = {} on {} V", v, vb);
            }
        }

        /// The latch's onset decision (`Gains::onset_w`, an integer threshold) is
        /// `protect::above_onset` on the speed as `f32` (`to_num`), for any validated
        /// configuration, at random speeds and at the threshold's neighbours of either sign.
        #[test]
        fn onset_threshold_is_above_onset(cfg in extreme_config(), b in any::<i32>(), d in -2i64..=2) {
            let g = Gains::new(&cfg).unwrap();
            let near = (g.onset_w as i64 + d).clamp(0, i32::MAX as i64) as i32;
            for x in [b, near, near.wrapping_neg()] {
                let w = Q::from_bits(x);
                prop_assert_eq!(
                    x.unsigned_abs() >= g.onset_w,
                    crate::protect::above_onset(&cfg, w.to_num::<f32>()),
                    "bits {} against {}", x, g.onset_w
                );
            }
        }

        /// Codes beyond 12 bits (a wiring or driver fault) give the same currents as the
        /// clamped 12-bit ones would never exceed: the Clarke inputs saturate, not wrap.
        #[test]
        fn clarke_on_codes_matches_scaled_currents(a in 0u16..4096, b in 0u16..4096, c in 0u16..4096) {
            let cfg = Config::default();
            let mut ctl = Controller::new(&cfg).unwrap();
            ctl.step(&RawSample { i_abc: [a, b, c], v_bus: 2458, encoder: 0 });
            let t = ctl.telemetry();
            // The first step's duties in force are zero: all three phases are read (`shunt`).
            let i = t.i_abc.map(|x| x.to_num::<f64>());
            // θ = 0 at count 0 (no offset): d = α, q = β. Two roundings of 2^-16 A each plus
            // the f32 constants (relative 1e-7).
            let alpha = (2.0 * i[0] - i[1] - i[2]) / 3.0;
            let beta = (i[1] - i[2]) / 3f64.sqrt();
            prop_assert!((t.i_dq.d.to_num::<f64>() - alpha).abs() < 1e-4);
            prop_assert!((t.i_dq.q.to_num::<f64>() - beta).abs() < 1e-4);
        }
    }

    proptest! {
        /// A capture's dump and `tel` agree on every channel: over random currents and bus
        /// samples of a drive running the resistor law at a steady encoder speed, random
        /// channel sets recorded every period (`Capture::record` after each step, the ring
        /// wrapped), each sample's code read back through `Decode` is, against
        /// `console::channel_value` of that period's telemetry: the same value for the phase
        /// currents and the bus voltage (ADC codes kept as they came); the telemetry floored
        /// to the channel's step for the d/q values and the power; for the speed, within one
        /// step below; for the travel, within one step plus the speed observer's sub-count
        /// position (its error, which the capture's count leaves out).
        #[test]
        fn capture_dump_is_the_telemetry_channel(
            codes in prop::collection::vec((1900u16..2200, 1900u16..2200, 1900u16..2200, 2300u16..2600), 300..420),
            (c0, speed) in (any::<u16>(), 1u16..5),
            sets in prop::collection::vec(prop::array::uniform4(0u8..13), 3),
        ) {
            use crate::capture::{CapPort, Capture, Settings, Trigger};
            const N: usize = 256;
            let chans = crate::console::CHANNELS;
            let mut ctl = Controller::new(&Config::default()).unwrap();
            ctl.set_mode(Mode::Run).unwrap();
            let mut caps: std::vec::Vec<Capture<N>> = sets
                .iter()
                .map(|&ch| {
                    let mut c = Capture::<N>::new();
                    let set = Settings { ch, n_ch: 4, div: 1, pre_pct: 50, trig: Trigger::Cmd };
                    c.arm(&set, 5e-5, ctl.gains());
                    c
                })
                .collect();
            // Each period's telemetry channels, and the observer's error then (counts).
            let mut want = std::vec::Vec::new();
            for (k, &(a, b, c, v)) in codes.iter().enumerate() {
                let e = c0.wrapping_add(speed.wrapping_mul(k as u16));
                ctl.step(&RawSample { i_abc: [a, b, c], v_bus: v, encoder: e });
                let t = ctl.telemetry();
                let vals: std::vec::Vec<f32> =
                    (0..chans.len()).map(|i| crate::console::channel_value(&t, i)).collect();
                let err = ((ctl.enc.position as i64) << 16) - ctl.enc.pos_est();
                want.push((vals, (err as f64 / 65_536.0).abs()));
                for cap in caps.iter_mut() {
                    let p = ctl.p_elec().to_bits();
                    cap.record(&mut ctl, p);
                }
            }
            let m_per_count = ctl.gains().enc.m_per_count.to_f32() as f64;
            let n = codes.len();
            for (cap, set) in caps.iter().zip(&sets) {
                let dec = cap.status().decode;
                for j in 0..N {
                    let (vals, err) = &want[n - N + j];
                    let row = cap.sample(j as u32);
                    for (slot, &ch) in set.iter().enumerate() {
                        let (got, tel) = (dec.value(slot, row[slot]), vals[ch as usize]);
                        let (name, lsb) = (chans[ch as usize].0, dec.lsb(slot) as f64);
                        let d = tel as f64 - got as f64;
                        let ok = match ch {
                            0..=2 | 9 => got.to_bits() == tel.to_bits(),
                            3..=8 | 12 => d >= 0.0 && d < lsb,
                            // The speed's gain rounds: one Q16.16 LSB beyond the step.
                            10 => d >= 0.0 && d <= lsb + 1.0 / 65_536.0,
                            _ => d.abs() <= lsb + err * m_per_count + 2.0 / 65_536.0,
                        };
                        prop_assert!(ok, "{} sample {}: dump {} tel {} (step {})", name, j, got, tel, lsb);
                    }
                }
            }
        }
    }

    /// Steps at a steady encoder speed (zero currents, 72 V), `n` periods from count `c0`.
    fn spin(ctl: &mut Controller, c0: u16, n: u16) -> u16 {
        let z = ctl.config().adc_zero_code;
        for k in 0..n {
            ctl.step(&RawSample {
                i_abc: [z; 3],
                v_bus: 2458,
                encoder: c0.wrapping_add(3 * k),
            });
        }
        c0.wrapping_add(3 * n)
    }

    /// The step tests one bit for "this mode controls current" (`step`): the odd
    /// discriminants must be exactly Run, Open and Align.
    #[test]
    fn current_controlling_modes_are_the_odd_ones() {
        for m in [Mode::Idle, Mode::Run, Mode::Short, Mode::Open, Mode::Align] {
            let controls = matches!(m, Mode::Run | Mode::Open | Mode::Align);
            assert_eq!(m as u8 & 1 == 1, controls, "{m:?}");
        }
    }

    /// A rotor dragged away during the ramp latches `align_moving` by the travel check, one
    /// alignment cycle (4 periods) and at most one supervision tick (20 periods) after it
    /// passes `align_travel_m`, long before the settle check could (the last quarter of the
    /// step).
    #[test]
    fn alignment_travel_beyond_its_limit_latches_at_once() {
        let cfg = Config::default();
        let mut ctl = Controller::new(&cfg).unwrap();
        ctl.require_alignment();
        let z = cfg.adc_zero_code;
        let mut s = RawSample {
            i_abc: [z; 3],
            v_bus: 2458,
            encoder: 0,
        };
        for _ in 0..CAL_PERIODS {
            ctl.step(&s);
        }
        assert_eq!(ctl.boot(), Boot::Unaligned);
        ctl.set_mode(Mode::Align).unwrap();
        // The rotor still: the emf probe hands over to the steps after STILL_TICKS ticks.
        let mut ticks = 0;
        while ctl.bs.probe {
            for _ in 0..20 {
                ctl.step(&s);
            }
            ctl.supervise();
            ticks += 1;
            assert!(ticks <= crate::align::STILL_TICKS, "{ticks}");
        }
        assert_eq!(ticks, crate::align::STILL_TICKS);
        // 0.004 m at 0.016 m per 10,000 counts: 2,500 counts; passed after 1,251 periods at
        // 2 counts per period.
        let per_m = cfg.encoder_cpr as f64 / (cfg.lead_m_per_rad as f64 * core::f64::consts::TAU);
        let travel = (cfg.align_travel_m as f64 * per_m) as u32;
        let cross = travel / 2 + 1;
        let settle_start = (cfg.align_time_s * cfg.pwm_hz) as u32 * 3 / 4;
        assert!(cross + 24 < settle_start);
        let mut k = 0u32;
        while ctl.fault().is_none() && k < settle_start {
            s.encoder = (2 * k) as u16;
            ctl.step(&s);
            if k % 20 == 19 {
                ctl.supervise();
            }
            k += 1;
        }
        assert_eq!(ctl.fault(), Some(Fault::AlignMoving));
        assert!(
            k >= cross && k <= cross + 4 + 20,
            "latched at period {k}, limit passed at {cross}"
        );
        assert_eq!(ctl.boot(), Boot::Unaligned);
    }

    #[test]
    fn refresh_requests_are_served_at_once() {
        // A configuration change (R_L 306 → 2 Ω) is served by `set_config` itself: the very
        // next step commands the new law's reference, −clamp(G·e_q, i_max) with the speed as
        // it was at the request, and refreshes the bus terms from its own sample (50 V here).
        let cfg = Config::default();
        let mut ctl = Controller::new(&cfg).unwrap();
        ctl.set_mode(Mode::Run).unwrap();
        let c = spin(&mut ctl, 0, 400);
        let vel = ctl.enc.vel;
        let new = Config {
            r_load_ohm: 2.0,
            ..cfg
        };
        ctl.set_config(&new).unwrap();
        let z = cfg.adc_zero_code;
        ctl.step(&RawSample {
            i_abc: [z; 3],
            v_bus: 1707, // 50 V
            encoder: c,
        });
        let g = Gains::new(&new).unwrap();
        let e_q = g.k.ke_per_vel.scale(vel);
        let cond = crate::laws::Resistor::new(new.r_phase_ohm, 2.0).neg_conductance;
        let want = clamp_sym(cond.scale(e_q), g.i_max);
        assert!(want != Q::ZERO);
        assert_eq!(ctl.telemetry().i_ref.q, want);
        let r = ctl.held.v_lim.radius().to_num::<f64>();
        let v = 1707.0 * new.volts_per_count as f64 * new.m_max as f64 / 3f64.sqrt();
        assert!((r - v).abs() < 1e-3, "{r} V vs {v} V");
        // A request the step serves itself (`law_mut`): the next step is the law's tick, its
        // reference the law's for the speed of that step, and the tick cycle resumes.
        let c = spin(&mut ctl, c + 3, 40);
        if let Law::Resistor(r) = ctl.law_mut() {
            r.neg_conductance = cond;
        }
        assert_eq!(ctl.slow_tick, 0);
        spin(&mut ctl, c, 1);
        let e_q = g.k.ke_per_vel.scale(ctl.enc.vel);
        assert_eq!(ctl.telemetry().i_ref.q, clamp_sym(cond.scale(e_q), g.i_max));
        assert!(ctl.slow_tick < SLOW_DIV);
        // Open mode: zero reference from the request on.
        ctl.set_mode(Mode::Open).unwrap();
        spin(&mut ctl, c, 1);
        assert_eq!(ctl.telemetry().i_ref, Dq::default());
    }

    #[test]
    fn trips_on_raw_code_thresholds() {
        // Over-current at |code − zero| > i_trip/amps_per_count = 20/(50/4096) = 1638.4.
        let cfg = Config::default();
        let z = cfg.adc_zero_code;
        let bus = 2458; // 72 V
        for (code, trip) in [
            (z + 1638, false),
            (z + 1639, true),
            (z - 1638, false),
            (z - 1639, true),
        ] {
            let mut ctl = Controller::new(&cfg).unwrap();
            ctl.set_mode(Mode::Run).unwrap();
            ctl.step(&RawSample {
                i_abc: [z, code, z],
                v_bus: bus,
                encoder: 0,
            });
            assert_eq!(ctl.fault() == Some(Fault::OverCurrent), trip, "code {code}");
        }
        // Over-voltage above 95 V = 3242.67 codes; under-voltage below 20 V = 682.67 codes.
        for (v, f) in [
            (3242u16, None),
            (3243, Some(Fault::BusOverVoltage)),
            (683, None),
            (682, Some(Fault::BusUnderVoltage)),
        ] {
            let mut ctl = Controller::new(&cfg).unwrap();
            ctl.set_mode(Mode::Run).unwrap();
            ctl.step(&RawSample {
                i_abc: [z; 3],
                v_bus: v,
                encoder: 0,
            });
            assert_eq!(ctl.fault(), f, "bus code {v}");
        }
        // A low bus is no fault while idle (power-up), nor in the other non-running modes.
        for m in [Mode::Idle, Mode::Open, Mode::Short] {
            let mut ctl = Controller::new(&cfg).unwrap();
            ctl.set_mode(m).unwrap();
            ctl.step(&RawSample {
                i_abc: [z; 3],
                v_bus: 0,
                encoder: 0,
            });
            assert_eq!((ctl.fault(), ctl.mode()), (None, m));
        }
        // Brake: closes above 85 V (2901.3 codes), opens below 82 V (2798.9 codes).
        let mut ctl = Controller::new(&cfg).unwrap();
        let mut brake = |v: u16| {
            ctl.step(&RawSample {
                i_abc: [z; 3],
                v_bus: v,
                encoder: 0,
            })
            .brake
        };
        assert!(!brake(2901));
        assert!(brake(2902));
        assert!(brake(2800));
        assert!(brake(2799));
        assert!(!brake(2798));
    }

    /// The step's half of a latch (`trip_on`: the safe mode read from its table,
    /// `protect::step_safe_mode`) followed by `complete_latch` leaves the controller exactly
    /// (every field, compared through `Debug`) as the general latch does after the same step:
    /// `trip`, the rule applied fault by fault, each with its record, PI reset and slow terms,
    /// on the snapshot the step takes. Every fault the step finds, alone and the two pairs,
    /// from every mode with nothing latched and from Idle and Short with a fault of each kind
    /// latched (current, speed in doubt, over-voltage), below and above the diode onset. The
    /// outputs of the period are the safe state's, the records written only after them.
    #[test]
    fn step_latch_is_the_general_latch() {
        use std::format;
        use Fault::*;
        let cfg = Config::default();
        let z = cfg.adc_zero_code;
        let normal = RawSample {
            i_abc: [z; 3],
            v_bus: 2458, // 72 V
            encoder: 0,
        };
        // Full scale on every phase (25 A against the 20 A trip, whichever two phases the
        // shunt rule reads); 96.7 V against the 95 V trip; the rail; 17.6 V under the 20 V
        // minimum; an encoder jump of 1,000 counts (the limit: 167).
        let (oc, ov, rail, uv, jump) = ([4095u16; 3], 3300u16, 4095u16, 600u16, 1000u16);
        // What the step is given, and the faults the general latch takes in order (the bus
        // at the rail is an over-voltage once one is latched; a low bus trips only in Run).
        type Expect = fn(bool, Mode) -> std::vec::Vec<Fault>;
        type Kind = (&'static str, Option<[u16; 3]>, Option<u16>, u16, Expect);
        let kinds: [Kind; 7] = [
            ("oc", Some(oc), None, 0, |_, _| std::vec![OverCurrent]),
            ("ov", None, Some(ov), 0, |_, _| std::vec![BusOverVoltage]),
            ("rail", None, Some(rail), 0, |o, _| {
                std::vec![if o { BusOverVoltage } else { BusSensor }]
            }),
            ("oc+ov", Some(oc), Some(ov), 0, |_, _| {
                std::vec![OverCurrent, BusOverVoltage]
            }),
            ("oc+rail", Some(oc), Some(rail), 0, |o, _| {
                std::vec![OverCurrent, if o { BusOverVoltage } else { BusSensor }]
            }),
            ("encoder", None, None, jump, |_, _| {
                std::vec![EncoderImplausible]
            }),
            ("uv", None, Some(uv), 0, |_, m| {
                if m == Mode::Run {
                    std::vec![BusUnderVoltage]
                } else {
                    std::vec![]
                }
            }),
        ];
        let mut modes_after = [0usize; 2];
        let mut pairs = 0;
        // 3 and 5 counts per period: 37.7 and 62.8 rad/s, either side of the onset
        // (√3·K_e·ω = 0.9·v_bus_ov: 52.3 rad/s).
        for counts in [3u16, 5] {
            let mut base = Controller::new(&cfg).unwrap();
            base.set_mode(Mode::Run).unwrap();
            let mut s = normal;
            for _ in 0..400 {
                s.encoder = s.encoder.wrapping_add(counts);
                base.step(&s);
            }
            let above = base.enc.omega_m(&base.g.enc).to_bits().unsigned_abs() >= base.g.onset_w;
            assert_eq!(above, counts == 5);
            let mut starts = std::vec::Vec::new();
            for m in [Mode::Run, Mode::Open, Mode::Idle, Mode::Short, Mode::Align] {
                let mut c = base.clone();
                if m == Mode::Align {
                    c.set_mode(Mode::Idle).unwrap();
                }
                if m == Mode::Short {
                    // At these speeds a commanded short is refused (its current could pass
                    // i_trip_a); a fault's latch puts the drive there all the same.
                    c.mode = m;
                    c.refresh_now();
                } else {
                    c.set_mode(m).unwrap();
                }
                starts.push(c);
            }
            for f in [OverForce, EncoderLoss, BusOverVoltage] {
                for m in [Mode::Idle, Mode::Short] {
                    let mut c = base.clone();
                    let t = c.telemetry();
                    c.trip(f, &t);
                    c.mode = m;
                    starts.push(c);
                }
            }
            for pre in &starts {
                let ov_latched = pre.latched_bits() & 1 << BusOverVoltage.code() != 0;
                for (name, i, v, j, expect) in &kinds {
                    let faults = expect(ov_latched, pre.mode);
                    let x = RawSample {
                        i_abc: i.unwrap_or(normal.i_abc),
                        v_bus: v.unwrap_or(normal.v_bus),
                        encoder: s.encoder.wrapping_add(counts).wrapping_add(*j),
                    };
                    let what = format!(
                        "{name} from {:?}, {:?} latched, above {above}",
                        pre.mode, pre.fault
                    );
                    let mut a = pre.clone();
                    let out = a.step_outputs(&x);
                    assert_eq!(
                        a.prot.record(),
                        pre.prot.record(),
                        "{what}: recorded after the outputs"
                    );
                    if faults.is_empty() {
                        assert_eq!((a.mode, a.fault), (pre.mode, pre.fault), "{what}");
                    } else {
                        let safe = match a.mode {
                            Mode::Idle => !out.enable,
                            Mode::Short => out.enable && out.duties == [Duty::ZERO; 3],
                            _ => false,
                        };
                        assert!(safe, "{what}: {:?} with {out:?}", a.mode);
                        modes_after[(a.mode == Mode::Short) as usize] += 1;
                        pairs += (faults.len() == 2) as usize;
                    }
                    a.complete_latch();
                    let mut r = pre.clone();
                    r.step_outputs(&x);
                    (r.mode, r.fault, r.latching) = (pre.mode, pre.fault, Latching::default());
                    let t = Telemetry {
                        i_dq: pre.rec.i_dq(),
                        ..r.telemetry()
                    };
                    for f in faults {
                        r.trip(f, &t);
                    }
                    assert_eq!(format!("{a:?}"), format!("{r:?}"), "{what}");
                }
            }
        }
        // Both safe states reached, and the pairs from every start on both sides.
        assert!(modes_after[0] > 0 && modes_after[1] > 0, "{modes_after:?}");
        assert_eq!(pairs, 2 * 2 * 11);
    }
}
