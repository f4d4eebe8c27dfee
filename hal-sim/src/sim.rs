//! The closed loop: the firmware's [`Controller`], unchanged, against the plant through
//! [`DriveIo`], one PWM period per [`Sim::step`].
//!
//! Timing of one period `k` (length `T = 1/f_pwm`): the sample is taken at `t_k` (the
//! controller's "centre of the period"), the controller computes an actuation, and that
//! actuation is applied over `[t_{k+1}, t_{k+2}]` (one-period PWM delay; the firmware's
//! delay compensation advances its angle by 1.5 T, the middle of that interval). Over
//! `[t_k, t_{k+1}]` the previous actuation is in force.
//!
//! Averaged inverter: phase `x` sits at `d_x·V_bus` above the negative rail during the whole
//! period; the star point floats, so the machine sees `v_xn = v_x − mean(v)`. The electrical
//! ODE `L di/dt = −R i + v − e` is solved exactly over the period (zero-order hold on `v`, the
//! emf evaluated at the mid-period angle and speed), in the stationary αβ frame with
//! amplitude-invariant Clarke, so one period costs two exponentials' worth of arithmetic
//! (the factor `exp(−RT/L)` is computed once).

use crate::fastmath::{floor_wrap_u16, Gauss, SinCos};
use crate::plant::{
    Bus, Drive, Excitation, ExcitationState, Inverter, Losses, Machine, Screw, Sensors,
    SineExcitation,
};
use crate::powerup::IndexPulse;
use crate::sampling::ShuntPre;
use regen_fw::capture::Capture;
use regen_fw::fx::Duty;
use regen_fw::io::{Actuation, DriveIo, RawSample};
use regen_fw::{Config, Controller, Mode, Pending, Period, PeriodHw};
use std::f64::consts::TAU;

const SQRT3_2: f64 = 0.866_025_403_784_438_6;

/// Energy ledger of a run, J (all cumulative from the start).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Energy {
    /// Work done on the system from outside: by the actuator (imposed motion) or by the base
    /// excitation (structure).
    pub external_work: f64,
    /// Work done on the device at its mechanical terminal, ∫f·ẋ dt.
    pub device_work: f64,
    /// Friction (eq. 13), rotary viscosity and screw efficiency losses.
    pub friction_loss: f64,
    pub viscous_b_loss: f64,
    pub screw_loss: f64,
    /// Converted to electricity by the machine, ∫−T·ω dt.
    pub electromechanical: f64,
    /// Winding (copper) loss.
    pub copper_loss: f64,
    /// Delivered by the machine to the inverter, ∫−v·i dt (the emulated load's energy).
    pub to_inverter: f64,
    /// Drive losses: switching, conduction, logic supply. (With the gates off the winding's
    /// current flows through the body diodes into the bus: `to_inverter`.)
    pub switching_loss: f64,
    pub conduction_loss: f64,
    pub logic_loss: f64,
    /// Brake resistor, source resistance, and the energy into the source/sink EMF (negative
    /// when the source supplies).
    pub brake: f64,
    pub source_r_loss: f64,
    pub sink: f64,
    /// Structural damping (besides the device).
    pub structure_damping: f64,
    /// Stored energies at the start and now: structure kinetic + potential, rotor kinetic,
    /// magnetic, bus capacitor.
    pub stored_start: f64,
    pub stored_now: f64,
}

impl Energy {
    /// Sum of everything the external work went into.
    pub fn accounted(&self) -> f64 {
        self.friction_loss
            + self.viscous_b_loss
            + self.screw_loss
            + self.copper_loss
            + self.switching_loss
            + self.conduction_loss
            + self.logic_loss
            + self.brake
            + self.source_r_loss
            + self.sink
            + self.structure_damping
            + (self.stored_now - self.stored_start)
    }
    /// External work minus everything accounted for.
    pub fn residual(&self) -> f64 {
        self.external_work - self.accounted()
    }
    /// Residual relative to the largest energy flow of the run.
    pub fn relative_residual(&self) -> f64 {
        let scale = [
            self.external_work.abs(),
            self.device_work.abs(),
            self.copper_loss,
            self.to_inverter.abs(),
            self.sink.abs(),
            self.friction_loss,
            self.logic_loss,
        ]
        .into_iter()
        .fold(1e-12, f64::max);
        self.residual() / scale
    }
}

/// The ledger's flows as the period accumulates them: sums over periods of each flow's
/// mean power over its period, W, scaled by the period `T` only when the ledger is read
/// ([`Sim::energy`]). Copper and conduction losses share one sum (of the mean of
/// i_α² + i_β²), and the logic supply is its power summed over the periods (nothing
/// below its lockout).
/// The mechanical flows are kept as the few products they are made of: with the device force
/// f = h·inner + f_d (`inner` = electromagnetic + viscous + inertial force, h ∈ {h_in, h_out}),
/// f·v̄ = h·inner·v̄ + f_d·v̄ and the screw's loss is (h − 1)·inner·v̄, so one sum of inner·v̄
/// per value of h gives both; the rotary viscosity and the structure's damping are both a
/// constant times v̂·v̄ (v̂ the mid-period estimate, v̄ the period's mean velocity).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Flows {
    /// Base excitation's work (structure: m·a_g·v̄); an imposed motion's is the device's.
    external_work: f64,
    friction_loss: f64,
    /// Σ inner·v̄ with h = h_in ([0]) and h = h_out ([1]), N·m/s.
    inner: [f64; 2],
    /// Σ v̂·v̄, m²/s².
    vv: f64,
    electromechanical: f64,
    /// Σ mean(i_α² + i_β²), A² (copper loss = 3/2·R·T·Σ, conduction = 3/2·R_on·T·(Σ − the
    /// gates-off part)).
    i2: f64,
    /// The part of `i2` from periods with the gates off: the current then flows through the
    /// body diodes, whose drop is not modelled, not through the switches' R_on.
    i2_off: f64,
    to_inverter: f64,
    switching_loss: f64,
    /// The bus's flows, W, of the constants before the last plant change ([`Flows::bank`]);
    /// since then the sums below, whose constants (the brake's and the source's
    /// conductances, the source's EMF) are applied when the ledger is read.
    brake: f64,
    source_r_loss: f64,
    sink: f64,
    /// Σ mean(V²) over the periods with the brake open ([0]) and closed ([1]), V².
    v2: [f64; 2],
    /// Σ mean(V − v_s) and Σ mean((V − v_s)²) over the periods (source/sink present), V, V².
    dv: f64,
    dv2: f64,
    /// Σ the logic supply's power over the periods, W (nothing below its lockout).
    logic: f64,
    /// The last period's bus flows, not yet in the sums above ([`Flows::settle`]).
    due: BusDue,
}

/// What the bus's flows of one period are computed from: the voltage at its start, the
/// current injected over it and the brake's state. The period records them and the next one
/// sums them ([`Flows::settle`]): they depend on the period's division, its last result, and
/// summed right after it they held up the next period's work (the closed loop 5–7 % slower,
/// `docs/simulator.md`, "Speed"), while one period later their inputs are long known.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct BusDue {
    vb0: f64,
    i_inj: f64,
    brake: usize,
    set: bool,
}

impl Flows {
    /// The bus's flows since the last bank, W (summed mean powers).
    fn bus(&self, p: &Pre) -> (f64, f64, f64) {
        let vs = p.vs;
        (
            self.brake + p.bus[0].g_brake * self.v2[0] + p.bus[1].g_brake * self.v2[1],
            self.source_r_loss + p.g_source * self.dv2,
            self.sink + vs * p.g_source * self.dv,
        )
    }

    /// The last period's bus flows ([`BusDue`]) into the sums, with the constants `p` of that
    /// period: the means over it of V² and, with a source, of V − v_s and (V − v_s)², from
    /// V(t) = V∞ + d0·e^(−g·t/C) (exact for the held injection).
    #[inline(always)]
    fn settle(&mut self, p: &Pre) {
        if !self.due.set {
            return;
        }
        let BusDue {
            vb0, i_inj, brake, ..
        } = self.due;
        self.due.set = false;
        let bk = &p.bus[brake];
        if bk.gt > 0.0 {
            let vinf = (i_inj + p.i_source) * bk.inv_gt;
            let d0 = vb0 - vinf;
            let d0k = d0 * bk.ak;
            let d0k2 = d0 * d0 * bk.ak2;
            let v2_mean = vinf * vinf + 2.0 * vinf * d0k + d0k2;
            if let Some(vs) = p.source_v {
                // Source current (vs − V)·g: its EMF's energy and the loss in its resistance,
                // from δ = V∞ − vs and the decaying part (V − vs = δ + d0·e^(−t/τ)), so that
                // the mean of (V − vs)² involves no cancellation of large terms.
                // (Their constants applied when the ledger is read: `Flows::bus`.)
                let dl = vinf - vs;
                self.dv += dl + d0k;
                self.dv2 += dl * dl + 2.0 * dl * d0k + d0k2;
            }
            self.v2[brake] += v2_mean;
        }
        // No conductance on the bus (brake open, no source): nothing flows out of it.
    }

    /// Fold the bus's sums into its flows with the constants `p` in force until now (before
    /// a plant change replaces them).
    fn bank(&mut self, p: &Pre) {
        self.settle(p);
        (self.brake, self.source_r_loss, self.sink) = self.bus(p);
        (self.v2, self.dv, self.dv2) = ([0.0; 2], 0.0, 0.0);
    }
}

/// A channel the recorder can keep.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Channel {
    T,
    X,
    V,
    Force,
    ForceEm,
    Ia,
    Ib,
    Ic,
    Id,
    Iq,
    IqRef,
    VBus,
    PInverter,
    Brake,
}

impl Channel {
    pub const ALL: &'static [Channel] = &[
        Channel::T,
        Channel::X,
        Channel::V,
        Channel::Force,
        Channel::ForceEm,
        Channel::Ia,
        Channel::Ib,
        Channel::Ic,
        Channel::Id,
        Channel::Iq,
        Channel::IqRef,
        Channel::VBus,
        Channel::PInverter,
        Channel::Brake,
    ];
    pub fn name(self) -> &'static str {
        match self {
            Channel::T => "t",
            Channel::X => "x",
            Channel::V => "v",
            Channel::Force => "force",
            Channel::ForceEm => "force_em",
            Channel::Ia => "i_a",
            Channel::Ib => "i_b",
            Channel::Ic => "i_c",
            Channel::Id => "i_d",
            Channel::Iq => "i_q",
            Channel::IqRef => "i_q_ref",
            Channel::VBus => "v_bus",
            Channel::PInverter => "p_inverter",
            Channel::Brake => "brake",
        }
    }
    pub fn from_name(s: &str) -> Option<Channel> {
        Self::ALL.iter().copied().find(|c| c.name() == s)
    }
}

/// Recorded traces: one row per kept period.
#[derive(Clone, Debug, Default)]
pub struct Recorder {
    pub channels: Vec<Channel>,
    /// Keep one period in `every`.
    pub every: u64,
    pub rows: Vec<Vec<f64>>,
}

impl Recorder {
    /// The column of one channel.
    pub fn column(&self, c: Channel) -> Option<Vec<f64>> {
        let k = self.channels.iter().position(|x| *x == c)?;
        Some(self.rows.iter().map(|r| r[k]).collect())
    }
    /// FNV-1a (64-bit) of the recorded values' IEEE-754 bits, little-endian, row by row:
    /// what `regen run` prints so that another implementation can check the same bits.
    pub fn digest(&self) -> u64 {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for b in self
            .rows
            .iter()
            .flatten()
            .flat_map(|v| v.to_bits().to_le_bytes())
        {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
        h
    }
    /// CSV text (header line + rows).
    pub fn to_csv(&self) -> String {
        let mut s = self
            .channels
            .iter()
            .map(|c| c.name())
            .collect::<Vec<_>>()
            .join(",");
        s.push('\n');
        for r in &self.rows {
            let line: Vec<String> = r.iter().map(|v| format!("{v:.6e}")).collect();
            s.push_str(&line.join(","));
            s.push('\n');
        }
        s
    }
}

/// The controller as the MCU constructs it at power-up (one place for [`Sim::new`] and a
/// reboot, [`Sim::power_up`]): validated configuration, then Run.
fn power_up_controller(cfg: &Config) -> Result<Controller, String> {
    let mut ctl = Controller::new(cfg).map_err(|e| format!("firmware config: {e}"))?;
    ctl.set_mode(Mode::Run).map_err(|f| f.name().to_string())?;
    Ok(ctl)
}

/// Seconds of the boot sequence ([`Sim::boot`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BootTimes {
    pub calibrate_s: f64,
    /// From the first alignment's start to the last one's end (retries included).
    pub align_s: f64,
    pub tries: u32,
}

/// Alignment attempts of [`Sim::boot`], and the seconds in the safe state between them
/// (the firmware's retry, `regen_fw::align`, which the board runs too).
pub use regen_fw::align::{ALIGN_RETRY_S, ALIGN_TRIES};

/// Everything that defines a simulated rig.
#[derive(Clone, Debug)]
pub struct Rig {
    pub machine: Machine,
    pub screw: Screw,
    pub drive: Drive,
    pub bus: Bus,
    pub inverter: Inverter,
    pub losses: Losses,
    pub sensors: Sensors,
}

/// The plant's state and the last quantities of one period.
#[derive(Clone, Debug, Default)]
struct State {
    t: f64,
    x: f64,
    v: f64,
    /// A structure's position and velocity at the middle of the next period, estimated from
    /// the last period's acceleration held (`x + v·T/2 + a·T²/8`, `v + a·T/2`; see
    /// [`Sim::advance`]).
    xm: f64,
    vm: f64,
    i_ab: [f64; 2],
    v_bus: f64,
    force: f64,
    force_em: f64,
    p_inv: f64,
    /// The αβ emf at the middle of the last period (the shunt sampling's ripple).
    e_ab: [f64; 2],
}

/// Closed-loop simulation.
pub struct Sim {
    rig: Rig,
    ctl: Controller,
    /// The controller's configuration (its scalings are folded into `pre`).
    #[allow(dead_code)]
    cfg: Config,
    s: State,
    active: Actuation,
    pending: Actuation,
    /// The actuation of the period that ended last (the shunt windows' opening).
    before: Actuation,
    /// Shunt sampling (`crate::sampling`).
    shunt: ShuntPre,
    exc: ExcitationState,
    noise: u64,
    gauss: Gauss,
    /// Constants of the run (see [`Pre`]).
    pre: Pre,
    /// Incremental sin/cos of the electrical angle, of an imposed sine at mid-period and at
    /// the period's end, and of the two friction ripples (see [`SinCos`]).
    rot_theta: SinCos,
    rot_motion: [SinCos; 2],
    rot_ripple: [SinCos; 2],
    /// The ledger's flows (see [`Flows`]); the stored energies are evaluated when it is read.
    flows: Flows,
    stored_start: f64,
    steps: u64,
    rec: Option<Recorder>,
    /// Periods until the recorder keeps the next row.
    rec_countdown: u64,
    ts: f64,
    /// The firmware's period around the step (`regen_fw::period`: supervision countdown,
    /// exact energy sum, overrun count) and the console's changes it applies between two
    /// periods, as the board's console task does.
    per: Period,
    mail: Pending,
    /// The capture the period records into (`regen_fw::capture`, the board's size).
    cap: Box<Capture<{ regen_fw::capture::SAMPLES }>>,
    /// The power-up models were applied ([`Sim::power_up`]): a reboot calibrates and aligns.
    powered_up: bool,
    /// A break the stage model latched, not yet read by the period (the timer's break flag,
    /// [`Sim::report_break`]).
    break_flag: Option<regen_fw::protect::Fault>,
    /// The encoder's index channel ([`crate::powerup`]) and its capture at the last sample.
    index: IndexPulse,
    index_capture: Option<u16>,
    /// A diagnosed device model replacing the screw's mechanical force on an imposed motion
    /// ([`Sim::set_model`]).
    model: Option<Box<crate::device_model::ModelState>>,
}

impl Sim {
    /// A closed loop of `rig` driven by a controller with configuration `cfg` (the controller
    /// starts in [`Mode::Run`]).
    pub fn new(rig: Rig, cfg: &Config) -> Result<Sim, String> {
        let ctl = power_up_controller(cfg)?;
        let ts = 1.0 / cfg.pwm_hz as f64;
        let m = &rig.machine;
        if !(m.r_ohm > 0.0 && m.l_h > 0.0 && m.l_q() > 0.0 && rig.screw.lead_m_per_rad > 0.0) {
            return Err("machine: r_ohm, l_h, l_q_h and lead must be positive".into());
        }
        if !(rig.screw.efficiency > 0.0 && rig.screw.efficiency <= 1.0) {
            return Err("screw.efficiency must lie in (0, 1]".into());
        }
        let b = &rig.bus;
        if !(b.capacitance_f > 0.0 && b.source_r_ohm > 0.0 && b.brake_r_ohm > 0.0) {
            return Err("bus: capacitance_f, source_r_ohm and brake_r_ohm must be positive".into());
        }
        if !(b.initial_v.is_finite() && b.initial_v >= 0.0) {
            return Err("bus.initial_v must be a finite voltage ≥ 0".into());
        }
        let (x0, v0) = match &rig.drive {
            Drive::Imposed { motion } => {
                let (x, v, _) = motion.at(0.0);
                (x, v)
            }
            Drive::Structure { .. } => (0.0, 0.0),
        };
        let exc = match &rig.drive {
            Drive::Structure { excitation, .. } => excitation.state(),
            _ => Excitation::Sine {
                a0_m_s2: 0.0,
                freq_hz: 0.0,
            }
            .state(),
        };
        let shunt = ShuntPre::new(&rig.sensors.shunt, &rig.inverter, m.r_ohm, l_sigma(m), ts)?;
        let mut sim = Sim {
            pre: Pre::new(&rig, cfg, ts),
            gauss: Gauss::default(),
            rot_theta: SinCos::default(),
            rot_motion: Default::default(),
            rot_ripple: Default::default(),
            rec_countdown: 0,
            noise: rig.sensors.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1,
            s: State {
                x: x0,
                v: v0,
                xm: x0 + v0 * ts / 2.0,
                vm: v0,
                v_bus: rig.bus.initial_v,
                ..Default::default()
            },
            rig,
            cfg: *cfg,
            ctl,
            active: Actuation::OFF,
            pending: Actuation::OFF,
            before: Actuation::OFF,
            shunt,
            exc,
            flows: Flows::default(),
            stored_start: 0.0,
            steps: 0,
            rec: None,
            ts,
            per: Period::NEW,
            mail: Pending::EMPTY,
            cap: Box::new(Capture::new()),
            powered_up: false,
            break_flag: None,
            index: IndexPulse::default(),
            index_capture: None,
            model: None,
        };
        // The encoder is incremental: the firmware's angle is referenced to the first count
        // (`Boot::Stored`), so the rotor's electrical angle is zero there: an imposed motion
        // starting away from x = 0 puts the rotor's angle origin at its first count.
        let x_c = (x0 * sim.pre.counts_per_m).floor() / sim.pre.counts_per_m;
        if x_c != 0.0 {
            sim.pre.theta_offset -= x_c * sim.pre.theta_per_m;
        }
        sim.stored_start = sim.stored();
        Ok(sim)
    }

    /// Replace the screw's mechanical force (inertia, friction, efficiency) by a diagnosed
    /// device model, stepped at the mid-period motion ([`crate::device_model`]); the
    /// machine's electromagnetic force adds to it. Imposed motion only (a structure's
    /// dynamics would need the model's inertia in its implicit step): ignored otherwise. The
    /// model's mechanical work is booked in the ledger as the friction's.
    pub fn set_model(&mut self, m: &crate::device_model::DeviceModel) {
        if let Drive::Imposed { motion } = &self.rig.drive {
            let (x, v, _) = motion.at(self.s.t + self.ts / 2.0);
            self.model = Some(Box::new(crate::device_model::ModelState::new(
                m, self.ts, x, v,
            )));
        }
    }

    /// The MCU boots again (after a watchdog reset, `crate::stage`): a fresh controller,
    /// constructed exactly as at power-up ([`Sim::new`]); the plant keeps its state. With the
    /// power-up models on ([`Sim::power_up`]) the fresh controller calibrates and needs
    /// alignment again ([`Controller::require_alignment`], then [`Sim::boot`]).
    pub fn reboot(&mut self) -> Result<(), String> {
        let cfg = *self.ctl.config();
        let ctl = power_up_controller(&cfg)?;
        self.per.bank(&self.ctl);
        self.ctl = ctl;
        self.break_flag = None; // the reset clears the timer's flags
        if self.powered_up {
            self.ctl.require_alignment();
        }
        Ok(())
    }

    /// Replace the bus (fault injection: load disconnected, brake resistor changed), keeping
    /// its present voltage. Refused like [`Sim::new`] for non-positive parts.
    pub fn set_bus(&mut self, bus: Bus) -> Result<(), String> {
        if !(bus.capacitance_f > 0.0 && bus.source_r_ohm > 0.0 && bus.brake_r_ohm > 0.0) {
            return Err("bus: capacitance_f, source_r_ohm and brake_r_ohm must be positive".into());
        }
        // The stored energy ½CV² is evaluated from the state: a new capacitance would
        // create energy in the ledger.
        if bus.capacitance_f != self.rig.bus.capacitance_f {
            return Err("bus: the capacitance cannot change during a run".into());
        }
        self.rig.bus = bus;
        // The per-run constants hold the bus's decay factors and source current.
        self.rebuild_pre();
        Ok(())
    }

    /// The per-run constants again after a plant change, keeping the sensors' power-up state
    /// ([`Sim::power_up`], [`Sim::set_adc_offsets`]: the encoder's start, the per-phase
    /// offsets and gains, the converter's offset registers) and the rotor angle's origin
    /// (the power-up's random angle, or an imposed motion's first count, [`Sim::new`]), which
    /// no plant change moves (`a_bus_change_keeps_the_rotor_angle`).
    fn rebuild_pre(&mut self) {
        self.flows.bank(&self.pre);
        let old = &self.pre;
        let mut pre = Pre::new(&self.rig, &self.cfg, self.ts);
        pre.enc_start = old.enc_start;
        pre.counts_per_amp_k = old.counts_per_amp_k;
        pre.counts_per_volt = old.counts_per_volt;
        pre.code_base = old.code_base;
        pre.adc_offsets = old.adc_offsets;
        pre.theta_offset = old.theta_offset;
        self.pre = pre;
    }

    /// Replace what drives the screw (fault injection: excitation beyond the rating). A
    /// structure must stay the same structure (its stored energy is in the ledger).
    pub fn set_drive(&mut self, drive: Drive) -> Result<(), String> {
        match (&self.rig.drive, &drive) {
            (
                Drive::Structure { structure: a, .. },
                Drive::Structure {
                    structure: b,
                    excitation,
                },
            ) => {
                if a != b {
                    return Err("drive: the structure cannot change during a run".into());
                }
                self.exc = excitation.state();
            }
            _ => return Err("drive: only the excitation of a structure can change".into()),
        }
        self.rig.drive = drive;
        self.rebuild_pre();
        Ok(())
    }

    /// Record the given channels every `every` periods.
    pub fn record(&mut self, channels: &[Channel], every: u64) {
        // Rows at step counts that are multiples of `every`, as before.
        self.rec_countdown = every.max(1) - self.steps % every.max(1);
        self.rec = Some(Recorder {
            channels: channels.to_vec(),
            every: every.max(1),
            rows: Vec::new(),
        });
    }
    pub fn recorder(&self) -> Option<&Recorder> {
        self.rec.as_ref()
    }
    pub fn take_recorder(&mut self) -> Option<Recorder> {
        self.rec.take()
    }
    pub fn controller(&self) -> &Controller {
        &self.ctl
    }
    pub fn controller_mut(&mut self) -> &mut Controller {
        &mut self.ctl
    }
    /// The capture the period records into (`cap` on the console).
    pub fn capture(&self) -> &Capture<{ regen_fw::capture::SAMPLES }> {
        &self.cap
    }
    pub fn capture_mut(&mut self) -> &mut Capture<{ regen_fw::capture::SAMPLES }> {
        &mut self.cap
    }
    pub fn rig(&self) -> &Rig {
        &self.rig
    }
    /// The energy ledger now (its stored energies evaluated from the state).
    pub fn energy(&self) -> Energy {
        let p = &self.pre;
        let mut f = self.flows;
        f.settle(p);
        let f = &f;
        let ts = self.ts;
        let device = (p.h_in * f.inner[0] + p.h_out * f.inner[1] + f.friction_loss) * ts;
        let (brake, source_r_loss, sink) = f.bus(p);
        Energy {
            external_work: if matches!(self.rig.drive, Drive::Imposed { .. }) {
                device
            } else {
                f.external_work * ts
            },
            device_work: device,
            friction_loss: f.friction_loss * ts,
            viscous_b_loss: p.br * ts * f.vv,
            screw_loss: ((p.h_in - 1.0) * f.inner[0] + (p.h_out - 1.0) * f.inner[1]) * ts,
            electromechanical: f.electromechanical * ts,
            copper_loss: p.copper * f.i2,
            to_inverter: f.to_inverter * ts,
            switching_loss: f.switching_loss * ts,
            conduction_loss: p.r_on_15 * ts * (f.i2 - f.i2_off),
            logic_loss: f.logic * ts,
            brake: brake * ts,
            source_r_loss: source_r_loss * ts,
            sink: sink * ts,
            structure_damping: p.damping * ts * f.vv,
            stored_start: self.stored_start,
            stored_now: self.stored(),
        }
    }
    pub fn time(&self) -> f64 {
        self.s.t
    }
    pub fn period(&self) -> f64 {
        self.ts
    }
    /// Position, velocity of the screw.
    pub fn motion(&self) -> (f64, f64) {
        (self.s.x, self.s.v)
    }
    /// Force on the device (sense of ẋ) and its electromagnetic part, averaged over the
    /// last period, N.
    pub fn force(&self) -> (f64, f64) {
        (self.s.force, self.s.force_em)
    }
    /// Phase currents now, A.
    pub fn currents(&self) -> [f64; 3] {
        let [a, b] = self.s.i_ab;
        [a, -0.5 * a + SQRT3_2 * b, -0.5 * a - SQRT3_2 * b]
    }
    /// Rotor-frame currents of the plant now (true angle), A.
    pub fn i_dq(&self) -> (f64, f64) {
        let th = self.theta_e(self.s.x);
        let (s, c) = th.sin_cos();
        let [a, b] = self.s.i_ab;
        (c * a + s * b, -s * a + c * b)
    }
    pub fn v_bus(&self) -> f64 {
        self.s.v_bus
    }
    /// Power from the machine into the inverter over the last period, W.
    pub fn p_inverter(&self) -> f64 {
        self.s.p_inv
    }

    fn theta_e(&self, x: f64) -> f64 {
        let m = &self.rig.machine;
        m.pole_pairs as f64 * x / self.rig.screw.lead_m_per_rad + m.angle_offset_rad
    }

    fn stored(&self) -> f64 {
        let jr = self.rig.screw.reflected_mass();
        let [a, b] = self.s.i_ab;
        let m = &self.rig.machine;
        let magnetic = if m.salient() {
            let (id, iq) = self.i_dq();
            0.75 * (m.l_d() * id * id + m.l_q() * iq * iq)
        } else {
            0.75 * m.l_h * (a * a + b * b)
        };
        let mut e = 0.5 * jr * self.s.v * self.s.v
            + magnetic
            + 0.5 * self.rig.bus.capacitance_f * self.s.v_bus * self.s.v_bus;
        if let Drive::Structure { structure: st, .. } = &self.rig.drive {
            e += 0.5 * st.mass_kg * self.s.v * self.s.v
                + 0.5 * st.stiffness_n_per_m * self.s.x * self.s.x;
        }
        e
    }

    /// Apply the power-up models ([`crate::powerup`]) of `p` (nothing when none is on): the
    /// rotor's angle and the encoder's start value, the current sensors' offsets and gains
    /// drawn from `p.seed`; the controller is told it powered up
    /// ([`Controller::require_alignment`]: Idle, offsets to calibrate, alignment needed);
    /// with `p.index` the encoder's index channel is modelled from now on (alone it needs no
    /// boot). Returns the draw when the firmware must boot ([`PowerUp::any`]), else `None`.
    /// Refused (nothing changed) for values out of range.
    ///
    /// [`PowerUp::any`]: crate::powerup::PowerUp::any
    pub fn power_up(
        &mut self,
        p: &crate::powerup::PowerUp,
    ) -> Result<Option<crate::powerup::Draw>, String> {
        p.check()?;
        let d = p.draw();
        if p.index {
            let th0 = if p.random_angle { d.theta_m0 } else { 0.0 };
            let lead = self.rig.screw.lead_m_per_rad;
            self.index = IndexPulse::new(th0, d.index_m, lead, self.s.x);
            self.index_capture = None;
        }
        if !p.any() {
            return Ok(None);
        }
        if p.random_angle {
            let m = &mut self.rig.machine;
            // The rotor's electrical angle at the plant's zero position (the encoder's
            // count 0 within its first turn is wherever the counter starts).
            let th = (m.pole_pairs as f64 * d.theta_m0).rem_euclid(std::f64::consts::TAU);
            m.angle_offset_rad = th;
            self.pre.theta_offset = th;
            self.pre.enc_start = d.encoder_start;
        }
        let cpa = self.pre.counts_per_amp;
        for k in 0..3 {
            self.pre.code_base[k] += d.offset_a[k] * cpa;
            self.pre.counts_per_amp_k[k] = cpa * (1.0 + d.gain_rel[k]);
        }
        self.pre.counts_per_volt *= 1.0 + d.vbus_gain_rel;
        self.ctl.require_alignment();
        self.powered_up = true;
        Ok(Some(d))
    }

    /// The firmware's boot sequence as the board runs it: Idle periods until the offsets are
    /// calibrated, then `mode align` until it ends, then `mode run`; each bounded in time.
    /// An alignment that finds the rotor moving (`align_moving`) is retried up to
    /// [`ALIGN_TRIES`] times after [`ALIGN_RETRY_S`] in its safe state (the short circuit
    /// damps the structure meanwhile). Returns the times and tries, or the fault or refusal
    /// that stopped it (the drive left in its safe mode).
    pub fn boot(&mut self) -> Result<BootTimes, String> {
        self.boot_with(|_| {})
    }

    /// [`Sim::boot`] with every sample passed through `inject` (fault injection).
    pub fn boot_with(
        &mut self,
        mut inject: impl FnMut(&mut RawSample),
    ) -> Result<BootTimes, String> {
        use regen_fw::Boot;
        let t0 = self.s.t;
        let n_cal = regen_fw::control::CAL_PERIODS as u64 + 2;
        for _ in 0..n_cal {
            if self.ctl.boot() != Boot::Calibrating {
                break;
            }
            self.step_with(&mut inject, |_| {});
        }
        self.set_adc_offsets(self.ctl.adc_offsets());
        // A boot fault found in the step latches at the next supervision tick.
        for _ in 0..self.ctl.supervise_every() {
            self.step_with(&mut inject, |_| {});
        }
        if let Some(f) = self.ctl.fault() {
            return Err(f.name().to_string());
        }
        let t1 = self.s.t;
        // The user's `mode align` (the board's console), then the retries the board's
        // supervision runs (`regen_fw::align`, the same code), posted to the mailbox.
        let mut retry = regen_fw::align::AlignRetry::NEW;
        let align = self.ctl.boot() != Boot::Stored && self.ctl.boot() != Boot::Aligned;
        if align {
            self.ctl
                .set_mode(Mode::Align)
                .map_err(|e| e.name().to_string())?;
        }
        // Each alignment: the emf probe (at most PROBE_TICKS ms), two steps of align_time_s
        // (the second holds for half of it), the wait in the safe state, and margin.
        let per_try = (regen_fw::align::PROBE_TICKS as f64 * 1e-3 / self.ts) as u64
            + (3.0 * self.ctl.config().align_time_s as f64 / self.ts) as u64
            + (ALIGN_RETRY_S as f64 / self.ts) as u64
            + 10;
        let mut n = 0;
        while self.ctl.boot() != Boot::Stored && self.ctl.boot() != Boot::Aligned {
            match retry.poll(&self.ctl, self.per.periods) {
                regen_fw::align::Retry::Post => regen_fw::align::post(&mut self.mail),
                regen_fw::align::Retry::Waiting => {}
                regen_fw::align::Retry::Nothing => {
                    if let Some(f) = self.ctl.fault() {
                        return Err(f.name().to_string());
                    }
                }
            }
            n += 1;
            if n > per_try * ALIGN_TRIES as u64 {
                return Err("alignment did not end".to_string());
            }
            self.step_with(&mut inject, |_| {});
        }
        let tries = if align { 1 + retry.retries() } else { 0 };
        let t2 = self.s.t;
        self.ctl
            .set_mode(Mode::Run)
            .map_err(|e| e.name().to_string())?;
        Ok(BootTimes {
            calibrate_s: t1 - t0,
            align_s: t2 - t1,
            tries,
        })
    }

    /// The converter's per-phase offset registers (codes subtracted from each phase's raw
    /// code), as the board programs the ADC's with [`Controller::adc_offsets`].
    pub fn set_adc_offsets(&mut self, o: [i32; 3]) {
        for (k, ok) in o.iter().enumerate() {
            self.pre.code_base[k] -= (ok - self.pre.adc_offsets[k]) as f64;
        }
        self.pre.adc_offsets = o;
    }

    /// The encoder counter's value at the index pulse the rotor passed between the previous
    /// sample and the last one ([`Sim::take_sample`], [`Sim::step`]), as the encoder timer's
    /// index capture holds it; `None` without a pulse in that period or without the index
    /// model (`[powerup] index`). The last passage if several.
    pub fn index_capture(&self) -> Option<u16> {
        self.index_capture
    }

    /// The d/q currents the controller measured in its last step, A (its telemetry).
    pub fn i_dq_measured(&self) -> (f64, f64) {
        let i = self.ctl.telemetry().i_dq;
        (i.d.to_num::<f64>(), i.q.to_num::<f64>())
    }

    /// The controller's electrical angle of its last step minus the rotor's at that
    /// sample, rad in (−π, π] (the sample was taken at the start of the period just
    /// simulated, the position then `x − v·Ts` to first order).
    pub fn angle_error(&self) -> f64 {
        let th_c = self.ctl.telemetry().theta_e.0 as f64 / 4_294_967_296.0 * std::f64::consts::TAU;
        let th = self.theta_e(self.s.x - self.s.v * self.ts);
        let e = (th_c - th).rem_euclid(std::f64::consts::TAU);
        if e > std::f64::consts::PI {
            e - std::f64::consts::TAU
        } else {
            e
        }
    }

    /// One PWM period: sample, plant advance (on the actuation in force), controller step.
    pub fn step(&mut self) {
        self.step_with(|_| {}, |_| {})
    }

    /// One PWM period with the sample and the actuation passed through `on_sample` and
    /// `on_actuation` on their way (fault injection, `crate::faults`).
    #[inline(always)]
    pub fn step_with(
        &mut self,
        on_sample: impl FnOnce(&mut RawSample),
        on_actuation: impl FnOnce(&mut Actuation),
    ) {
        // The firmware's period (`regen_fw::period::Period::run`, the board's interrupt body)
        // with the hooks between its parts: the controller and the plant live in one struct,
        // so the sequence is written out here; `split_step_is_exactly_one_step` pins it to
        // `Period::run`.
        let mut sample = PlantIo(self).sample();
        on_sample(&mut sample);
        // The plant's period runs on the actuation the last step wrote (in force over this
        // period), not on this step's: it is advanced before the step, so that the
        // controller's integer work overlaps the plant's floating-point chains (the closed
        // loop ≈ 8 % faster than the plant after the step, `docs/simulator.md`, "Speed"; the
        // same bits: `split_step_is_exactly_one_step`).
        self.advance_period();
        let mut out = self.per.step(&mut self.ctl, &sample);
        on_actuation(&mut out);
        PlantIo(self).apply(&out);
        let mut hw = SimTimer(self.break_flag.take());
        self.per.finish(&mut self.ctl, &mut hw, &mut self.cap);
        // The console's changes between this period and the next, as the board's console
        // task applies them right after a period (`Period::apply`).
        self.per.apply(&mut self.ctl, &mut self.mail, &mut hw);
        self.end_period();
    }

    /// The power stage's break latched (`crate::stage`: a comparator through the timer's
    /// break input): the timer's flag, read by the next period's end as the board's period
    /// routine reads TIM1's (`PeriodHw::tripped`) and latched as `fault`
    /// ([`regen_fw::Controller::hardware_trip`]). An over-current break (BRK) keeps
    /// precedence over a bus one (BRK2) reported in the same period, as on the board.
    pub fn report_break(&mut self, fault: regen_fw::protect::Fault) {
        if self.break_flag != Some(regen_fw::protect::Fault::OverCurrent) {
            self.break_flag = Some(fault);
        }
    }

    /// The period's state: energy sum, period and overrun counts, supervision countdown.
    pub fn loop_period(&self) -> &Period {
        &self.per
    }

    /// The console's changes, applied between this period and the next ([`Period::apply`],
    /// as the board's console task applies them). A `pwm_hz` change through it does not change the plant's period.
    pub fn mailbox(&mut self) -> &mut Pending {
        &mut self.mail
    }

    /// The plant side of [`Sim::step`] without the controller, first half: the sample the
    /// converters and the encoder take now (advances the sensor-noise generator). With
    /// [`Sim::apply_and_advance`] it drives the plant open loop or from a controller held
    /// outside (`take_sample`, compute, `apply_and_advance` is exactly one `step`).
    pub fn take_sample(&mut self) -> RawSample {
        PlantIo(self).sample()
    }

    /// Second half: `out` becomes the pending actuation (in force over the next period) and
    /// the plant advances one period.
    pub fn apply_and_advance(&mut self, out: &Actuation) {
        PlantIo(self).apply(out);
        self.finish_period();
    }

    fn finish_period(&mut self) {
        self.advance_period();
        self.end_period();
    }

    /// The plant over the period, on the actuation in force (the one written a period ago).
    #[inline(always)]
    fn advance_period(&mut self) {
        let act = self.active;
        self.advance(&act);
        self.before = act;
    }

    /// The pending actuation in force from the next period, the period's count and the
    /// recorder's row.
    #[inline(always)]
    fn end_period(&mut self) {
        self.active = self.pending;
        self.steps += 1;
        if self.rec.is_some() {
            self.rec_countdown -= 1;
            if self.rec_countdown == 0 {
                self.keep_row();
            }
        }
    }

    #[cold]
    fn keep_row(&mut self) {
        if let Some(rec) = &self.rec {
            let row: Vec<f64> = rec.channels.iter().map(|c| self.channel(*c)).collect();
            if let Some(r) = self.rec.as_mut() {
                self.rec_countdown = r.every;
                r.rows.push(row);
            }
        }
    }

    /// Run for `seconds` of simulated time.
    pub fn run_for(&mut self, seconds: f64) {
        let n = (seconds / self.ts).round() as u64;
        for _ in 0..n {
            self.step();
        }
    }

    /// The value of a channel now.
    pub fn channel(&self, c: Channel) -> f64 {
        match c {
            Channel::T => self.s.t,
            Channel::X => self.s.x,
            Channel::V => self.s.v,
            Channel::Force => self.s.force,
            Channel::ForceEm => self.s.force_em,
            Channel::Ia => self.currents()[0],
            Channel::Ib => self.currents()[1],
            Channel::Ic => self.currents()[2],
            Channel::Id => self.i_dq().0,
            Channel::Iq => self.i_dq().1,
            Channel::IqRef => self.ctl.telemetry().i_ref.q.to_num::<f64>(),
            Channel::VBus => self.s.v_bus,
            Channel::PInverter => self.s.p_inv,
            Channel::Brake => self.active.brake as u8 as f64,
        }
    }

    /// The sample the converters and the encoder take now: [`Sim::sample_as`], the ideal
    /// converters' and the shunt sampling's inline, the sensors' noise out of line.
    #[inline(always)]
    fn sample_now(&mut self) -> RawSample {
        if self.pre.noisy {
            self.sample_general()
        } else if self.shunt.on {
            self.sample_as::<true, false>()
        } else {
            self.sample_as::<false, false>()
        }
    }

    #[inline(never)]
    fn sample_general(&mut self) -> RawSample {
        self.sample_as::<true, true>()
    }

    /// The sample; `SHUNT` and `NOISE` compile in the shunt sampling and the sensors' noise
    /// (each then taken when the run has it), so that the ideal converters' sample has
    /// neither test.
    #[inline(always)]
    fn sample_as<const SHUNT: bool, const NOISE: bool>(&mut self) -> RawSample {
        let mut i = self.currents();
        if SHUNT && self.shunt.on {
            i = self.shunt_read(i);
        }
        let p = &self.pre;
        let mut c: [f64; 3] =
            core::array::from_fn(|k| i[k] * p.counts_per_amp_k[k] + p.code_base[k]);
        let mut vc = self.s.v_bus * p.counts_per_volt + p.vcode_base;
        if NOISE && p.noisy {
            self.add_noise(&mut c, &mut vc);
        }
        if self.index.on {
            if self.index.still_inside(self.s.x) {
                self.index_capture = None;
            } else {
                self.sample_index();
            }
        }
        // Code = (i + offset)/(A per count) + zero code, rounded to nearest in the positive
        // code domain (the cast truncates; below 0 it clamps anyway).
        RawSample {
            i_abc: [adc_code(c[0]), adc_code(c[1]), adc_code(c[2])],
            v_bus: adc_code(vc),
            // Wraps at 2^16 like the hardware counter.
            encoder: floor_wrap_u16(self.s.x * self.pre.counts_per_m)
                .wrapping_add(self.pre.enc_start),
        }
    }

    /// The phase currents through the shunts at the converters' instants (`crate::sampling`:
    /// the common case inline, the general model out of line).
    #[inline(always)]
    fn shunt_read(&self, i: [f64; 3]) -> [f64; 3] {
        let [ea, eb] = self.s.e_ab;
        let e = [ea, -0.5 * ea + SQRT3_2 * eb, -0.5 * ea - SQRT3_2 * eb];
        self.shunt
            .read(i, e, self.s.v_bus, &self.before, &self.active)
    }

    /// The index channel at this sample: the counter's value where the mark passed.
    #[inline(never)]
    fn sample_index(&mut self) {
        self.index_capture = self
            .index
            .pass(self.s.x)
            .map(|x| floor_wrap_u16(x * self.pre.counts_per_m).wrapping_add(self.pre.enc_start));
    }

    /// The sensors' noise (in counts) on the three current codes, then on the bus code.
    #[inline(always)]
    fn add_noise(&mut self, c: &mut [f64; 3], vc: &mut f64) {
        let p = &self.pre;
        if p.noise_i_counts > 0.0 {
            for c in c.iter_mut() {
                *c += p.noise_i_counts * self.gauss.sample(&mut self.noise);
            }
        }
        if p.noise_v_counts > 0.0 {
            *vc += p.noise_v_counts * self.gauss.sample(&mut self.noise);
        }
    }

    /// One plant period under the actuation `act`: [`Sim::advance_as`] specialised to the
    /// common period ([`Pre::common`]), inline in its callers (the closed loop's period and
    /// `apply_and_advance`), or general, out of line.
    #[inline(always)]
    fn advance(&mut self, act: &Actuation) {
        if self.pre.common {
            self.advance_as::<true>(act)
        } else {
            self.advance_general(act)
        }
    }

    #[inline(never)]
    fn advance_general(&mut self, act: &Actuation) {
        self.advance_as::<false>(act)
    }

    /// One plant period. `COMMON` (only when [`Pre::common`] holds) makes what the common
    /// period's configuration fixes known at compile time — a structure under a sine
    /// excitation (its constants in [`Pre::exc_sine`]), the plain averaged inverter, no
    /// friction ripple, a source on the bus — so that its tests and the other cases' code
    /// drop out; the arithmetic is the same (`common_period_is_the_general_one`).
    ///
    /// The period's work is ordered by its chains, not by its parts: the next period's
    /// motion (position → rotor angle → emf → mean q current → acceleration → next
    /// position) is the longest chain from one period to the next, so the mechanics come
    /// right after the mean currents and before the drive losses and the bus, which they do
    /// not need. The results do not depend on the order (each operation keeps its operands).
    #[inline(always)]
    fn advance_as<const COMMON: bool>(&mut self, act: &Actuation) {
        let ts = self.ts;
        let p = &self.pre;
        let t0 = self.s.t;
        // Mid-period motion estimate (exact for imposed motion; a structure's was made at the
        // end of the last period).
        let (xm, vm_est, am_imposed) = match (&self.rig.drive, COMMON) {
            (Drive::Imposed { motion }, false) => {
                motion.at_tracked(&mut self.rot_motion[0], t0 + ts / 2.0)
            }
            _ => (self.s.xm, self.s.vm, 0.0),
        };
        let w = vm_est * p.inv_lead;
        let (sn, cs) = self.rot_theta.at(xm * p.theta_per_m + p.theta_offset);
        let kw = p.ke * w;
        let e = [-kw * sn, kw * cs];
        self.s.e_ab = e;
        // A structure's base excitation (it depends on nothing else of the period).
        let ag = match (&self.rig.drive, COMMON) {
            (_, true) => p.exc_sine.next(&mut self.exc, t0, ts),
            (Drive::Structure { excitation, .. }, false) => excitation.next(&mut self.exc, t0, ts),
            (Drive::Imposed { .. }, false) => 0.0,
        };
        self.s.t = t0 + ts;

        // Electrical period: the averaged inverter inline, everything else out of line.
        let vb0 = self.s.v_bus;
        let fl = &mut self.flows;
        let (
            Elec {
                i_avg,
                i2_avg,
                p_inv,
            },
            iq_avg,
        ) = if act.enable && (COMMON || p.plain_average) {
            let dv = duty_clarke(act);
            let v = [dv[0] * vb0, dv[1] * vb0];
            let iq = mean_iq(p, (sn, cs), kw, v, self.s.i_ab);
            (averaged_period(&e, dv, vb0, p, &mut self.s.i_ab), iq)
        } else if !COMMON && act.enable && p.salient {
            salient_period(
                act,
                vb0,
                p,
                ts,
                (sn, cs),
                w * p.pole_pairs,
                &mut self.s.i_ab,
            )
        } else {
            let el = other_period(act, vb0, &e, p, ts, &mut self.s.i_ab);
            if !act.enable {
                fl.i2_off += el.i2_avg;
            }
            let iq = -sn * el.i_avg[0] + cs * el.i_avg[1];
            (el, iq)
        };
        fl.i2 += i2_avg;
        let f_e = p.force_per_iq * iq_avg; // −T/l, T = 3/2·K_e·i_q
        fl.to_inverter -= p_inv;

        // Mechanics (before the drive losses and the bus, which they do not need).
        let (jr, br) = (p.jr, p.br);
        // Friction f_d(x, ẋ) of eq. 13 at the mid-period estimate (as `Screw::friction`).
        let fd = {
            let sgn = (vm_est * p.inv_stick).clamp(-1.0, 1.0);
            let c = if !COMMON && p.ripple {
                p.coulomb * ripple(p, &mut self.rot_ripple, xm)
            } else {
                p.coulomb
            };
            c * sgn + p.viscous * vm_est
        };
        match (&self.rig.drive, COMMON) {
            (Drive::Imposed { motion }, false) => {
                let (x1, v1m, _) = motion.at_tracked(&mut self.rot_motion[1], t0 + ts);
                let vm = vm_est;
                let (inner, fd) = match self.model.as_deref_mut() {
                    None => (f_e + jr * am_imposed + br * vm, fd),
                    Some(m) => (
                        f_e,
                        m.step_kin(xm, vm, motion.v_kin_at(t0 + ts / 2.0, vm), am_imposed),
                    ),
                };
                let out = ((inner + fd) * vm < 0.0) as usize;
                let h = if out == 0 { p.h_in } else { p.h_out };
                let f = h * inner + fd;
                fl.friction_loss += fd * vm;
                fl.vv += vm * vm;
                fl.inner[out] += inner * vm;
                fl.electromechanical += f_e * vm;
                self.s.x = x1;
                self.s.v = v1m;
                self.s.force = f;
            }
            _ => {
                // A structure (the imposed motion's arm is above).
                let (x0, v0) = (self.s.x, self.s.v);
                let mag = p.mass * ag;
                let rhs0 = mag - p.damping * vm_est - p.stiffness * xm;
                let f_eb = f_e + br * vm_est;
                let mut h = p.h_in;
                // (rhs0 − h·f_eb − fd)/(m + h·J/l²) with the electromagnetic force's term
                // last (`iq_avg` arrives last: the critical path).
                let mut a =
                    (rhs0 - fd - h * (br * vm_est)) * p.inv_mass_h[0] - p.accel_per_iq * iq_avg;
                let mut inner = f_eb + jr * a;
                let mut out = 0;
                if p.lossy_screw && (h * inner + fd) * vm_est < 0.0 {
                    h = p.h_out;
                    a = (rhs0 - h * f_eb - fd) * p.inv_mass_h[1];
                    inner = f_eb + jr * a;
                    out = 1;
                }
                let f = h * inner + fd;
                // The period's end with `a` held, and the next period's mid-point estimate,
                // each one product and sum after `a`.
                let vm = v0 + a * p.half_ts;
                self.s.x = (x0 + v0 * ts) + a * p.ts2_2;
                self.s.v = v0 + a * ts;
                self.s.xm = (x0 + v0 * p.ts_3_2) + a * p.ts2_9_8;
                self.s.vm = v0 + a * p.ts_3_2;
                fl.external_work += mag * vm;
                fl.friction_loss += fd * vm;
                fl.vv += vm_est * vm;
                fl.inner[out] += inner * vm;
                fl.electromechanical += f_e * vm;
                self.s.force = f;
            }
        }
        // Drive losses and bus.
        let (p_sw, p_cond) = if act.enable {
            let ph = [
                i_avg[0],
                -0.5 * i_avg[0] + SQRT3_2 * i_avg[1],
                -0.5 * i_avg[0] - SQRT3_2 * i_avg[1],
            ];
            (
                p.k_sw_f * vb0 * (ph[0].abs() + ph[1].abs() + ph[2].abs()),
                p.r_on_15 * i2_avg,
            )
        } else {
            (0.0, 0.0)
        };
        fl.switching_loss += p_sw;
        let p_logic = if vb0 >= p.logic_min_v { p.logic_w } else { 0.0 };
        fl.logic += p_logic;
        // Summed in the order the terms arrive (the bus voltage's path through the period:
        // the conduction loss, from the mean of i², comes last).
        let p_draw = ((p_logic + p_inv) + p_sw) + p_cond;
        let bk = &p.bus[act.brake as usize];
        // Injection current such that ∫V·i_inj dt equals the energy the inverter drew, by one
        // fixed-point step from the guess i₀ = −p/max(V, 1) (the rest, second order, shows in
        // the ledger's residual): the mean of V over the period is α + β·i, linear in the
        // injection, so i = −p/max(α + β·i₀, 1) = −p·V_ref/max(α·V_ref − β·p, V_ref), one
        // division.
        let vref = vb0.max(1.0);
        let alpha = bk.iv_c + bk.iv_a * vb0;
        let den = (alpha * vref - bk.iv_b * p_draw).max(vref);
        let i_inj = -p_draw * vref / den;
        // The bus over the period (exact for the held injection): the end voltage now, the
        // flows by the next period (`Flows::settle`).
        let v1 = if COMMON || bk.gt > 0.0 {
            // V∞ + d0·k = (k·V0 + (1 − k)·i_s/g) + (1 − k)/g·i_inj, with V∞ = (i_inj + i_s)/g
            // and d0 = V0 − V∞: one product and sum after the division.
            (vb0 * bk.k + bk.v_src) + bk.v_per_inj * i_inj
        } else {
            vb0 + i_inj * p.ts_per_c
        };
        // The last period's bus flows, whose inputs are long known (summed here rather
        // than at the period's start: the closed loop 2 % faster), then this period's due.
        fl.settle(p);
        fl.due = BusDue {
            vb0,
            i_inj,
            brake: act.brake as usize,
            set: true,
        };
        self.s.v_bus = v1;

        self.s.force_em = f_e;
        self.s.p_inv = -p_inv;
    }
}

/// A 12-bit converter's code for the value `c` (counts + ½): `c` clamped to [0, 4095] and
/// truncated (NaN reads 0). The comparisons map to one `maxsd` and one `minsd`, the
/// truncation to one `cvttsd2si` (an `as` conversion would add the saturation and NaN code
/// the clamp already made unnecessary: ≈ 30 instructions a period over the four codes).
/// `adc_code_is_the_truncation` pins it to `c as i32` after the clamp.
#[inline(always)]
fn adc_code(c: f64) -> u16 {
    let c = if c > 0.0 { c } else { 0.0 };
    let c = if c < 4095.0 { c } else { 4095.0 };
    // SAFETY: `c` is finite and within [0, 4095] (a NaN fails `c > 0.0` and reads 0), so its
    // truncation is an i32: the condition `to_int_unchecked` requires.
    unsafe { c.to_int_unchecked::<i32>() as u16 }
}

/// Value of the duty's least significant bit (`Duty` = U1F15).
const DUTY_LSB: f64 = 1.0 / (1u32 << Duty::FRAC_NBITS) as f64;

/// The averaged inverter's αβ voltages per volt of bus from the duties' bits: `clarke` of
/// the duties (each at most 1), with the Clarke combinations taken exactly on the integer
/// bits and one product each by `LSB/3` and `LSB/√3`; times V_bus, the phase voltages'
/// transform to a rounding or two (`duty_clarke_is_clarke_of_the_duties` pins it against
/// `clarke`, 4 ulp), in a third of the instructions (no three conversions, clamps and
/// products before the transform).
#[inline(always)]
fn duty_clarke(act: &Actuation) -> [f64; 2] {
    const ONE: u32 = 1 << Duty::FRAC_NBITS;
    let [a, b, c] = act.duties.map(|d| (d.to_bits() as u32).min(ONE) as i32);
    [
        (2 * a - b - c) as f64 * (DUTY_LSB / 3.0),
        (b - c) as f64 * (DUTY_LSB / (2.0 * SQRT3_2)),
    ]
}

/// The position ripple factor of eq. 13's Coulomb term, 1 + p3·sin(x/l + p4) +
/// p5·sin(2π/r·x + p6).
#[inline(never)]
fn ripple(p: &Pre, rot: &mut [SinCos; 2], x: f64) -> f64 {
    let mut r = 1.0;
    if p.p3 != 0.0 {
        r += p.p3 * rot[0].at(x * p.inv_lead + p.p4).0;
    }
    if p.p5 != 0.0 {
        r += p.p5 * rot[1].at(p.lambda2 * x + p.p6).0;
    }
    r
}

/// Amplitude-invariant Clarke transform of three phase quantities.
#[inline(always)]
fn clarke(p: [f64; 3]) -> [f64; 2] {
    [
        (2.0 * p[0] - p[1] - p[2]) * (1.0 / 3.0),
        (p[1] - p[2]) * (1.0 / (2.0 * SQRT3_2)),
    ]
}

/// One period's electrical sums: mean α/β currents (A), mean of i_α² + i_β² (A²), mean power
/// from the bus into the machine (W).
#[derive(Default)]
struct Elec {
    i_avg: [f64; 2],
    i2_avg: f64,
    p_inv: f64,
}

impl Elec {
    /// One constant-voltage segment (αβ voltage `v` against the emf `e`) of length f·T,
    /// with a = exp(−f·T/τ), g = (1 − a)·τ/T, g2 = (1 − a²)·τ/(2T): the exact solution of
    /// `L di/dt = −R i + v − e` and its integrals.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn segment(
        &mut self,
        e: &[f64; 2],
        inv_r: f64,
        v: [f64; 2],
        f: f64,
        a: f64,
        g: f64,
        g2: f64,
        i_ab: &mut [f64; 2],
    ) {
        for k in 0..2 {
            let u = (v[k] - e[k]) * inv_r;
            let dlt = i_ab[k] - u;
            i_ab[k] = u + dlt * a;
            let int_i = u * f + dlt * g; // ∫i dt / T
            self.i_avg[k] += int_i;
            self.i2_avg += u * u * f + 2.0 * u * dlt * g + dlt * dlt * g2;
            self.p_inv += 1.5 * v[k] * int_i;
        }
    }
}

/// The averaged inverter's period (αβ phase voltages `dv·vb`, held over the whole period):
/// the exact solution of [`Elec::segment`] with f = 1 written out for the one segment, so
/// that nothing is accumulated from zero. Written affine in the bus voltage `vb`
/// (u = (v − e)/R = vb·dv/R − e/R, the mean current (1 − g)·u + g·i(t_k)), so that the
/// bus voltage's path through the period (voltage → current → drawn power → the bus's end
/// voltage, the next period's input) is a few operations long.
#[inline(always)]
fn averaged_period(e: &[f64; 2], dv: [f64; 2], vb: f64, p: &Pre, i_ab: &mut [f64; 2]) -> Elec {
    let w = [dv[0] * p.inv_r, dv[1] * p.inv_r];
    let u0 = [-e[0] * p.inv_r, -e[1] * p.inv_r];
    let i0 = *i_ab;
    let u = [vb * w[0] + u0[0], vb * w[1] + u0[1]];
    let dlt = [i0[0] - u[0], i0[1] - u[1]];
    *i_ab = [u[0] + dlt[0] * p.decay, u[1] + dlt[1] * p.decay];
    let g = p.g_avg;
    let i_avg = [
        vb * (w[0] * p.one_m_g) + (u0[0] * p.one_m_g + g * i0[0]),
        vb * (w[1] * p.one_m_g) + (u0[1] * p.one_m_g + g * i0[1]),
    ];
    let v15 = [vb * (1.5 * dv[0]), vb * (1.5 * dv[1])];
    Elec {
        i_avg,
        i2_avg: (u[0] * u[0] + u[1] * u[1])
            + 2.0 * g * (u[0] * dlt[0] + u[1] * dlt[1])
            + p.g2_avg * (dlt[0] * dlt[0] + dlt[1] * dlt[1]),
        p_inv: v15[0] * i_avg[0] + v15[1] * i_avg[1],
    }
}

/// The averaged period's mean q current ([`averaged_period`]'s `i_avg` projected on
/// q = (−sin θ, cos θ)) straight from the exact solution's two terms:
/// i_avg = (1 − g)·u + g·i(t_k) with u = (v − e)/R, and e_q = K_e·ω (`kw`) since
/// e = K_e·ω·(−sin θ, cos θ) and sin² + cos² = 1. The same value to the rounding and the
/// angle pair's norm (≈ 1e-13), with fewer operations between the angle and the force: the
/// period's critical path runs position → angle → emf → current → force → acceleration →
/// position. `mean_q_current_is_the_projection` pins it to the projection.
#[inline(always)]
fn mean_iq(p: &Pre, (sn, cs): (f64, f64), kw: f64, v: [f64; 2], i0: [f64; 2]) -> f64 {
    // Grouped by the angle's sine and cosine, which arrive last.
    let a = p.g_u * v[1] + p.g_avg * i0[1];
    let b = p.g_u * v[0] + p.g_avg * i0[0];
    (cs * a - sn * b) - p.g_u * kw
}

/// Every electrical period but the plain averaged one: gates disabled, dead time, the
/// switched inverter. Out of line so that the common period stays compact.
#[inline(never)]
fn other_period(
    act: &Actuation,
    vb0: f64,
    e: &[f64; 2],
    p: &Pre,
    ts: f64,
    i_ab: &mut [f64; 2],
) -> Elec {
    let mut el = Elec::default();
    if act.enable {
        let d: [f64; 3] = if p.dead > 0.0 {
            dead_time_duties(act, p.dead, i_ab)
        } else {
            core::array::from_fn(|k| (act.duties[k].to_bits() as f64 * DUTY_LSB).min(1.0))
        };
        if p.switched {
            switched_period(&mut el, &d, vb0, e, p, ts, i_ab);
        } else {
            el = averaged_period(e, clarke(d), vb0, p, i_ab);
        }
    } else {
        el = diode_period(vb0, e, p, ts, i_ab);
    }
    el
}

/// Most conduction-set changes one period of the gates-off model resolves (each is a
/// current reaching zero); the rest of a period that needed more keeps the last set.
const DIODE_EVENTS: usize = 12;

/// Gates off: the six body diodes are an uncontrolled three-phase bridge. A phase carrying
/// current is tied to the rail its diode conducts to (to the bus when its current flows out
/// of the machine, i < 0; to the negative rail when it flows in), the star point floats where
/// the conducting phases put it, and an open phase starts to conduct when its open-circuit
/// terminal voltage (star point + its emf) leaves [0, V_bus]. So a current left in the
/// machine when the gates open returns its energy to the bus through the diodes, and an emf
/// whose line-to-line peak exceeds the bus drives a rectified current into the bus (braking
/// the shaft), with no current at all below that.
///
/// With the emf and the bus held over the period (as in the averaged model), the conduction
/// set changes only when a current reaches zero, and between those events each current is
/// the exact exponential solution of `L di/dt = v_x − v_n − R·i − e_x`: the period is
/// integrated event to event, with the zero crossings found in closed form. Diode drops are
/// neglected.
#[inline(never)]
fn diode_period(vb: f64, e: &[f64; 2], p: &Pre, ts: f64, i_ab: &mut [f64; 2]) -> Elec {
    let e_ph = [
        e[0],
        -0.5 * e[0] + SQRT3_2 * e[1],
        -0.5 * e[0] - SQRT3_2 * e[1],
    ];
    let [ia, ib] = *i_ab;
    let mut i = [ia, -0.5 * ia + SQRT3_2 * ib, -0.5 * ia - SQRT3_2 * ib];
    let emax = e_ph[0].max(e_ph[1]).max(e_ph[2]);
    let emin = e_ph[0].min(e_ph[1]).min(e_ph[2]);
    if i == [0.0; 3] && emax - emin <= vb {
        return Elec::default(); // blocked: no current flows.
    }
    let tau = p.tau;
    let (mut i_int, mut i2_int, mut p_int) = ([0.0f64; 3], 0.0f64, 0.0f64);
    let mut left = ts;
    for _ in 0..DIODE_EVENTS {
        // The conducting phases, each with the direction of its current (−1: out of the
        // machine into the upper diode, terminal at the bus; +1: in through the lower diode,
        // terminal at 0).
        let mut dir = i.map(|c| {
            if c > 0.0 {
                1.0
            } else if c < 0.0 {
                -1.0
            } else {
                0.0
            }
        });
        if dir == [0.0; 3] {
            if emax - emin <= vb {
                break;
            }
            // Conduction starts between the highest emf (into the bus) and the lowest.
            let hi = (0..3).fold(0, |m, x| if e_ph[x] > e_ph[m] { x } else { m });
            let lo = (0..3).fold(0, |m, x| if e_ph[x] < e_ph[m] { x } else { m });
            dir[hi] = -1.0;
            dir[lo] = 1.0;
        }
        let term = |d: f64| if d < 0.0 { vb } else { 0.0 };
        // Star point from the conducting phases (their currents sum to zero); an open phase
        // whose terminal would leave the rails joins them.
        let mut vn = 0.0;
        for _ in 0..2 {
            let on = (0..3).filter(|&x| dir[x] != 0.0);
            let n = on.clone().count() as f64;
            vn = on.map(|x| term(dir[x]) - e_ph[x]).sum::<f64>() / n;
            let mut joined = false;
            for x in 0..3 {
                let vt = vn + e_ph[x];
                if dir[x] == 0.0 && (vt > vb || vt < 0.0) {
                    dir[x] = if vt > vb { -1.0 } else { 1.0 };
                    joined = true;
                }
            }
            if !joined {
                break;
            }
        }
        // Each conducting current i(t) = u + d·e^(−t/τ); the first to reach zero ends the
        // segment (e^(−t/τ) = −u/d, when u is of the other sign).
        let u = core::array::from_fn::<f64, 3, _>(|x| {
            if dir[x] != 0.0 {
                (term(dir[x]) - vn - e_ph[x]) * p.inv_r
            } else {
                0.0
            }
        });
        let d = core::array::from_fn::<f64, 3, _>(|x| i[x] - u[x]);
        let mut t = left;
        let mut ends = None;
        for x in 0..3 {
            if dir[x] != 0.0 && u[x] * dir[x] < 0.0 {
                let tx = -tau * (-u[x] / d[x]).ln();
                if tx < t {
                    t = tx.max(0.0);
                    ends = Some(x);
                }
            }
        }
        let a = (-t / tau).exp();
        let (g, g2) = (tau * (1.0 - a), 0.5 * tau * (1.0 - a * a));
        for x in 0..3 {
            if dir[x] == 0.0 {
                continue;
            }
            i[x] = u[x] + d[x] * a;
            let int = u[x] * t + d[x] * g;
            i_int[x] += int;
            i2_int += u[x] * u[x] * t + 2.0 * u[x] * d[x] * g + d[x] * d[x] * g2;
            p_int += term(dir[x]) * int;
        }
        left -= t;
        match ends {
            Some(x) => {
                // Exactly zero; the others sum to zero with it (Σu = Σd = 0 over the set).
                i[x] = 0.0;
                let live = i.iter().filter(|&&c| c != 0.0).count();
                if live < 2 {
                    i = [0.0; 3];
                }
            }
            None => break,
        }
        if left <= 0.0 {
            break;
        }
    }
    *i_ab = [i[0], (i[1] - i[2]) / (2.0 * SQRT3_2)];
    // Σi² = 3/2·(i_α² + i_β²) for currents that sum to zero.
    let inv_ts = 1.0 / ts;
    Elec {
        i_avg: clarke(i_int.map(|v| v * inv_ts)),
        i2_avg: i2_int * (2.0 / 3.0) * inv_ts,
        p_inv: p_int * inv_ts,
    }
}

/// Duties with the dead time: a phase whose current flows out of the leg (i > 0) loses
/// `dead` (fraction of the period) of high time, one whose current flows in gains it.
fn dead_time_duties(act: &Actuation, dead: f64, i_ab: &[f64; 2]) -> [f64; 3] {
    let [a, b] = *i_ab;
    let i_ph = [a, -0.5 * a + SQRT3_2 * b, -0.5 * a - SQRT3_2 * b];
    core::array::from_fn(|k| {
        let d = act.duties[k].to_bits() as f64 * DUTY_LSB;
        let d = if i_ph[k] != 0.0 {
            d - dead * i_ph[k].signum()
        } else {
            d
        };
        d.clamp(0.0, 1.0)
    })
}

/// The switched inverter: the centre-aligned pattern (phase k high over
/// [T/2·(1 − d_k), T/2·(1 + d_k)]) resolved into its constant-voltage segments.
#[inline(never)]
fn switched_period(
    el: &mut Elec,
    d: &[f64; 3],
    vb0: f64,
    e: &[f64; 2],
    p: &Pre,
    ts: f64,
    i_ab: &mut [f64; 2],
) {
    let tau = p.tau;
    let (segs, n) = pattern_segments(d, ts, vb0);
    for &(dt, v_ab) in &segs[..n] {
        let a = (-dt / tau).exp();
        el.segment(
            e,
            p.inv_r,
            v_ab,
            dt * p.inv_ts,
            a,
            (1.0 - a) * tau * p.inv_ts,
            (1.0 - a * a) * tau / 2.0 * p.inv_ts,
            i_ab,
        );
    }
}

/// The centre-aligned pattern (phase k at `vb0` over [T/2·(1 − d_k), T/2·(1 + d_k)], else at
/// 0) as its constant-voltage segments in time order: each one's length and αβ voltage, and
/// how many there are (at most 7; empty ones left out).
#[inline]
fn pattern_segments(d: &[f64; 3], ts: f64, vb0: f64) -> ([(f64, [f64; 2]); 7], usize) {
    let mut edges = [0.0; 8];
    for k in 0..3 {
        edges[1 + 2 * k] = 0.5 * ts * (1.0 - d[k]);
        edges[2 + 2 * k] = 0.5 * ts * (1.0 + d[k]);
    }
    edges[7] = ts;
    edges.sort_by(|a, b| a.total_cmp(b));
    let mut segs = [(0.0f64, [0.0f64; 2]); 7];
    let mut n = 0;
    for w in edges.windows(2) {
        let dt = w[1] - w[0];
        if dt <= 0.0 {
            continue;
        }
        let tm = 0.5 * (w[0] + w[1]);
        let ph: [f64; 3] = core::array::from_fn(|k| {
            if (tm - 0.5 * ts).abs() < 0.5 * ts * d[k] {
                vb0
            } else {
                0.0
            }
        });
        segs[n] = (dt, clarke(ph));
        n += 1;
    }
    (segs, n)
}

/// The one inductance of the models that take one: a non-salient machine's `l_h`, a salient
/// one's mean (L_d + L_q)/2 (its gates-off period, [`diode_period`], and the shunt's ripple
/// over the ADC's first microsecond, `crate::sampling`).
fn l_sigma(m: &crate::plant::Machine) -> f64 {
    if m.salient() {
        0.5 * (m.l_d() + m.l_q())
    } else {
        m.l_h
    }
}

/// A salient machine's period with the gates on (averaged, with dead time, or switched):
/// each constant-voltage segment integrated in the rotor frame, where with the speed held
/// over the period the machine is
/// `L_d di_d/dt = v_d − R i_d + ω_e L_q i_q`, `L_q di_q/dt = v_q − R i_q − ω_e (L_d i_d + ψ)`,
/// the αβ voltage turned into it at the rotor's angle θ(t) = θ_mid + ω_e (t − T/2) (the emf
/// exact for the held speed), by classical Runge–Kutta in sub-steps of at most τ_min/8 and
/// 0.05 rad of ω_e·t (relative error per sub-step below 3e-7: (h/τ)⁵/120), the period's
/// integrals (mean αβ currents, i², i_q, i_d·i_q) by the same stages. Returns the sums and the
/// q current whose `force_per_iq` is the period's mean torque
/// `3/2·(K_e i_q + p (L_d − L_q) i_d i_q)`: mean(i_q) + rel_per_iq·mean(i_d·i_q).
#[inline(never)]
fn salient_period(
    act: &Actuation,
    vb0: f64,
    p: &Pre,
    ts: f64,
    (sn, cs): (f64, f64),
    w_e: f64,
    i_ab: &mut [f64; 2],
) -> (Elec, f64) {
    let d: [f64; 3] = if p.dead > 0.0 {
        dead_time_duties(act, p.dead, i_ab)
    } else {
        core::array::from_fn(|k| (act.duties[k].to_bits() as f64 * DUTY_LSB).min(1.0))
    };
    // The period's constant-voltage segments: one (averaged) or the centre-aligned pattern's.
    let (segs, n_seg) = if p.switched {
        pattern_segments(&d, ts, vb0)
    } else {
        let v = clarke(d);
        let mut segs = [(0.0f64, [0.0f64; 2]); 7];
        segs[0] = (ts, [v[0] * vb0, v[1] * vb0]);
        (segs, 1)
    };
    // The rotor frame at the period's start.
    let (s0, c0) = (0.5 * w_e * ts).sin_cos();
    let (mut s, mut c) = (sn * c0 - cs * s0, cs * c0 + sn * s0);
    let [a, b] = *i_ab;
    let mut i = [c * a + s * b, -s * a + c * b];
    let rate = p.steps_per_s.max(w_e.abs() * 20.0);
    // Integrals over the period: i_α, i_β, i², i_q, i_d·i_q.
    let mut acc = [0.0f64; 5];
    let mut p_inv = 0.0;
    let f = |(s, c): (f64, f64), v: [f64; 2], i: [f64; 2]| {
        let vd = c * v[0] + s * v[1];
        let vq = -s * v[0] + c * v[1];
        [
            (vd - p.r * i[0] + w_e * p.lq * i[1]) * p.inv_ld,
            (vq - p.r * i[1] - w_e * (p.ld * i[0] + p.psi)) * p.inv_lq,
        ]
    };
    let g = |(s, c): (f64, f64), i: [f64; 2]| {
        [
            c * i[0] - s * i[1],
            s * i[0] + c * i[1],
            i[0] * i[0] + i[1] * i[1],
            i[1],
            i[0] * i[1],
        ]
    };
    for &(len, v) in &segs[..n_seg] {
        let n = ((len * rate).ceil() as usize).max(1);
        let h = len / n as f64;
        let (sh, ch) = (0.5 * w_e * h).sin_cos();
        let mut seg = [0.0f64; 2];
        for _ in 0..n {
            let a0 = (s, c);
            let a1 = (s * ch + c * sh, c * ch - s * sh);
            let a2 = (a1.0 * ch + a1.1 * sh, a1.1 * ch - a1.0 * sh);
            let k1 = f(a0, v, i);
            let y2 = [i[0] + 0.5 * h * k1[0], i[1] + 0.5 * h * k1[1]];
            let k2 = f(a1, v, y2);
            let y3 = [i[0] + 0.5 * h * k2[0], i[1] + 0.5 * h * k2[1]];
            let k3 = f(a1, v, y3);
            let y4 = [i[0] + h * k3[0], i[1] + h * k3[1]];
            let k4 = f(a2, v, y4);
            let (g1, g2, g3, g4) = (g(a0, i), g(a1, y2), g(a1, y3), g(a2, y4));
            for k in 0..5 {
                let q = h / 6.0 * (g1[k] + 2.0 * (g2[k] + g3[k]) + g4[k]);
                acc[k] += q;
                if k < 2 {
                    seg[k] += q;
                }
            }
            for k in 0..2 {
                i[k] += h / 6.0 * (k1[k] + 2.0 * (k2[k] + k3[k]) + k4[k]);
            }
            (s, c) = a2;
        }
        p_inv += 1.5 * (v[0] * seg[0] + v[1] * seg[1]);
    }
    *i_ab = [c * i[0] - s * i[1], s * i[0] + c * i[1]];
    let inv_ts = 1.0 / ts;
    (
        Elec {
            i_avg: [acc[0] * inv_ts, acc[1] * inv_ts],
            i2_avg: acc[2] * inv_ts,
            p_inv: p_inv * inv_ts,
        },
        (acc[3] + p.rel_per_iq * acc[4]) * inv_ts,
    )
}

/// The bus's per-period constants with the brake open ([0]) or closed ([1]).
#[derive(Clone, Copy, Debug, Default)]
struct BusK {
    /// Total conductance (source + brake), S, and its inverse (0 if none).
    gt: f64,
    inv_gt: f64,
    /// k = exp(−gt·T/C), ak = (1 − k)·C/(gt·T), ak2 = (1 − k²)·C/(2·gt·T): with
    /// V(t) = V∞ + d0·exp(−gt·t/C), the means over the period of V − V∞ and (V − V∞)² are
    /// d0·ak and d0²·ak2.
    k: f64,
    ak: f64,
    ak2: f64,
    /// (1 − k)·i_source/gt and (1 − k)/gt: the end voltage k·V0 + v_src + v_per_inj·i_inj.
    v_src: f64,
    v_per_inj: f64,
    g_brake: f64,
    /// Mean of V over the period = iv_c + iv_a·V(start) + iv_b·i_injected.
    iv_a: f64,
    iv_b: f64,
    iv_c: f64,
}

/// Everything of the plant that is constant over a run, computed once in [`Sim::new`], so
/// that a period costs no division or transcendental call beyond the bus's two divisions.
#[derive(Clone, Debug, Default)]
struct Pre {
    // Sensors.
    counts_per_amp: f64,
    /// Codes per ampere of each phase (`counts_per_amp` with its gain error,
    /// [`crate::powerup`]).
    counts_per_amp_k: [f64; 3],
    code_base: [f64; 3],
    /// The encoder counter's value at the plant's zero position ([`crate::powerup`]).
    enc_start: u16,
    /// The converter's offset registers in force ([`Sim::set_adc_offsets`]).
    adc_offsets: [i32; 3],
    noise_i_counts: f64,
    counts_per_volt: f64,
    vcode_base: f64,
    noise_v_counts: f64,
    counts_per_m: f64,
    // T/2, T²/2, 3T/2 and 9T²/8 (a structure's step and mid-period estimate).
    half_ts: f64,
    ts2_2: f64,
    ts_3_2: f64,
    ts2_9_8: f64,
    // Machine and inverter.
    inv_ts: f64,
    inv_lead: f64,
    theta_per_m: f64,
    theta_offset: f64,
    ke: f64,
    inv_r: f64,
    tau: f64,
    decay: f64,
    g_avg: f64,
    /// 1 − g_avg, and (1 − g_avg)/R: the mean current's part from the held voltage.
    one_m_g: f64,
    g_u: f64,
    g2_avg: f64,
    copper: f64,
    force_per_iq: f64,
    /// A salient machine ([`salient_period`]): L_d ≠ L_q, their inverses, the pole pairs,
    /// the flux linkage ψ = K_e/p (V·s/rad electrical), p·(L_d − L_q)/K_e (the reluctance
    /// torque's share per A² of i_d·i_q, in amperes of i_q) and the sub-steps per second
    /// the time constants ask for (8/τ_min, at least 2 a period).
    salient: bool,
    inv_ld: f64,
    inv_lq: f64,
    ld: f64,
    lq: f64,
    r: f64,
    pole_pairs: f64,
    psi: f64,
    rel_per_iq: f64,
    steps_per_s: f64,
    switched: bool,
    dead: f64,
    // Losses.
    k_sw_f: f64,
    r_on_15: f64,
    logic_w: f64,
    logic_min_v: f64,
    // Bus.
    bus: [BusK; 2],
    i_source: f64,
    g_source: f64,
    source_v: Option<f64>,
    /// T/C (the bus without any conductance).
    ts_per_c: f64,
    // Screw.
    jr: f64,
    br: f64,
    inv_stick: f64,
    coulomb: f64,
    viscous: f64,
    p3: f64,
    p4: f64,
    p5: f64,
    p6: f64,
    lambda2: f64,
    h_in: f64,
    h_out: f64,
    lossy_screw: bool,
    inv_mass_h: [f64; 2],
    /// h_in·(3/2·K_e/l)/(m + h_in·J/l²): a structure's acceleration per ampere of i_q.
    accel_per_iq: f64,
    // Structure (zero for an imposed motion).
    mass: f64,
    damping: f64,
    stiffness: f64,
    // Options: sensor noise on; the plain averaged inverter (no dead time, not switched);
    // friction ripple.
    noisy: bool,
    plain_average: bool,
    ripple: bool,
    /// The source's EMF (0 without a source).
    vs: f64,
    /// A structure's sine excitation (zero for any other drive).
    exc_sine: SineExcitation,
    /// The common period ([`Sim::advance_as`]): a structure under a sine excitation, the
    /// plain averaged inverter, no friction ripple, a source on the bus.
    common: bool,
}

impl Pre {
    fn new(rig: &Rig, cfg: &Config, ts: f64) -> Pre {
        let m = &rig.machine;
        let sc = &rig.screw;
        let sn = &rig.sensors;
        let b = &rig.bus;
        let l = sc.lead_m_per_rad;
        let counts_per_amp = 1.0 / cfg.amps_per_count as f64;
        let counts_per_volt = 1.0 / cfg.volts_per_count as f64;
        // A salient machine's gates-off and shunt models take the mean inductance (its own
        // period is `salient_period`).
        let l_one = l_sigma(m);
        let tau = l_one / m.r_ohm;
        let decay = (-m.r_ohm / l_one * ts).exp();
        let gs = if b.source_v.is_some() {
            1.0 / b.source_r_ohm
        } else {
            0.0
        };
        let i_source = b.source_v.map_or(0.0, |vs| vs / b.source_r_ohm);
        let bus_k = |gb: f64| {
            let gt = gs + gb;
            if gt > 0.0 {
                let tc = b.capacitance_f / gt;
                let k = (-gt * ts / b.capacitance_f).exp();
                let ak = (1.0 - k) * tc / ts;
                BusK {
                    gt,
                    inv_gt: 1.0 / gt,
                    k,
                    ak,
                    ak2: (1.0 - k * k) * tc / 2.0 / ts,
                    v_src: (1.0 - k) * i_source / gt,
                    v_per_inj: (1.0 - k) / gt,
                    g_brake: gb,
                    iv_a: ak,
                    iv_b: (1.0 - ak) / gt,
                    iv_c: i_source / gt * (1.0 - ak),
                }
            } else {
                BusK {
                    k: 1.0,
                    iv_a: 1.0,
                    iv_b: ts / (2.0 * b.capacitance_f),
                    ..Default::default()
                }
            }
        };
        let jr = sc.reflected_mass();
        // The dead-time correction applies when `dead` > 0 (as `other_period` tests it).
        let dead_time = rig.inverter.dead_time_s / ts > 0.0;
        let st = match &rig.drive {
            Drive::Structure { structure, .. } => *structure,
            Drive::Imposed { .. } => crate::plant::Structure {
                mass_kg: 0.0,
                stiffness_n_per_m: 0.0,
                damping_n_s_per_m: 0.0,
            },
        };
        let mass = st.mass_kg;
        let exc_sine = match &rig.drive {
            Drive::Structure { excitation, .. } => excitation.sine(),
            Drive::Imposed { .. } => None,
        };
        let ripple = sc.p3 != 0.0 || sc.p5 != 0.0;
        let plain_average = !rig.inverter.switched && !dead_time && !m.salient();
        Pre {
            counts_per_amp,
            counts_per_amp_k: [counts_per_amp; 3],
            enc_start: 0,
            adc_offsets: [0; 3],
            code_base: core::array::from_fn(|k| {
                sn.current_offset_a[k] * counts_per_amp + cfg.adc_zero_code as f64 + 0.5
            }),
            noise_i_counts: sn.current_noise_a.max(0.0) * counts_per_amp,
            counts_per_volt,
            vcode_base: sn.vbus_offset_v * counts_per_volt + 0.5,
            noise_v_counts: sn.vbus_noise_v.max(0.0) * counts_per_volt,
            counts_per_m: cfg.encoder_cpr as f64 / (l * TAU),
            half_ts: ts / 2.0,
            ts2_2: ts * ts / 2.0,
            ts_3_2: 1.5 * ts,
            ts2_9_8: 9.0 * ts * ts / 8.0,
            inv_ts: 1.0 / ts,
            inv_lead: 1.0 / l,
            theta_per_m: m.pole_pairs as f64 / l,
            theta_offset: m.angle_offset_rad,
            ke: m.ke_v_s_per_rad,
            inv_r: 1.0 / m.r_ohm,
            tau,
            decay,
            g_avg: (1.0 - decay) * tau / ts,
            one_m_g: 1.0 - (1.0 - decay) * tau / ts,
            g_u: (1.0 - (1.0 - decay) * tau / ts) / m.r_ohm,
            g2_avg: (1.0 - decay * decay) * tau / 2.0 / ts,
            copper: 1.5 * m.r_ohm * ts,
            force_per_iq: -1.5 * m.ke_v_s_per_rad / l,
            salient: m.salient(),
            inv_ld: 1.0 / m.l_d(),
            inv_lq: 1.0 / m.l_q(),
            ld: m.l_d(),
            lq: m.l_q(),
            r: m.r_ohm,
            pole_pairs: m.pole_pairs as f64,
            psi: m.ke_v_s_per_rad / m.pole_pairs as f64,
            rel_per_iq: m.pole_pairs as f64 * (m.l_d() - m.l_q()) / m.ke_v_s_per_rad,
            steps_per_s: (8.0 * m.r_ohm / m.l_d().min(m.l_q())).max(2.0 / ts),
            switched: rig.inverter.switched,
            dead: rig.inverter.dead_time_s / ts,
            k_sw_f: rig.losses.k_sw_s * cfg.pwm_hz as f64,
            r_on_15: rig.losses.r_on_ohm * 1.5,
            logic_w: rig.losses.logic_w,
            logic_min_v: rig.losses.logic_min_v,
            bus: [bus_k(0.0), bus_k(1.0 / b.brake_r_ohm)],
            i_source,
            g_source: gs,
            source_v: b.source_v,
            ts_per_c: ts / b.capacitance_f,
            mass,
            damping: st.damping_n_s_per_m,
            stiffness: st.stiffness_n_per_m,
            noisy: sn.current_noise_a > 0.0 || sn.vbus_noise_v > 0.0,
            plain_average,
            ripple,
            vs: b.source_v.unwrap_or(0.0),
            exc_sine: exc_sine.unwrap_or_default(),
            common: exc_sine.is_some() && plain_average && !ripple && b.source_v.is_some(),
            jr,
            br: sc.reflected_viscosity(),
            inv_stick: 1.0 / sc.stick_velocity,
            coulomb: sc.coulomb_n,
            viscous: sc.viscous_n_s_per_m,
            p3: sc.p3,
            p4: sc.p4,
            p5: sc.p5,
            p6: sc.p6,
            lambda2: TAU / sc.ball_m,
            h_in: sc.h(true),
            h_out: sc.h(false),
            lossy_screw: sc.efficiency < 1.0,
            inv_mass_h: [
                1.0 / (mass + sc.h(true) * jr),
                1.0 / (mass + sc.h(false) * jr),
            ],
            accel_per_iq: sc.h(true) * (-1.5 * m.ke_v_s_per_rad / l) / (mass + sc.h(true) * jr),
        }
    }
}

/// Make the controller's current loop proportional-only (integral gain zero), like the
/// reference bench's analog drive. Call again after every `set_config`.
pub fn p_only(ctl: &mut Controller) {
    let pi = &mut ctl.gains_mut().pi;
    *pi = regen_fw::pi::PiGains::new(pi.kp(), 0.0);
}

/// The plant side of the hardware boundary.
struct PlantIo<'a>(&'a mut Sim);

/// The simulator's timer as the period sees it: never late (the simulated loop has no
/// clock), PWM frequency fixed by the plant's period; its break flag is the one the stage
/// model reported ([`Sim::report_break`]).
struct SimTimer(Option<regen_fw::protect::Fault>);
impl PeriodHw for SimTimer {
    fn tripped(&mut self) -> Option<regen_fw::protect::Fault> {
        self.0.take()
    }
}

impl DriveIo for PlantIo<'_> {
    #[inline(always)]
    fn sample(&mut self) -> RawSample {
        self.0.sample_now()
    }
    fn apply(&mut self, out: &Actuation) {
        self.0.pending = *out;
    }
    fn now_us(&self) -> u64 {
        (self.0.s.t * 1e6) as u64
    }
}

#[cfg(test)]
mod tests {
    use super::Channel;
    use crate::scenario::Scenario;

    #[test]
    fn index_pulse_once_per_revolution_at_the_seeded_angle() {
        use crate::plant::Motion;
        use crate::powerup::PowerUp;
        use std::f64::consts::TAU;
        // A triangle of ±50 mm at 0.5 Hz (0.1 m/s) on the reference screw's 16 mm lead: 12.5
        // revolutions per cycle, the marks at x_k = (k + index_m/2π − θ_m0/2π)·2π·l.
        let (amp, f) = (0.05, 0.5);
        let sc = Scenario::imposed(
            Motion::Triangle {
                amplitude_m: amp,
                freq_hz: f,
            },
            306.0,
            2.0,
        );
        // Off by default: no capture ever.
        let mut sim = sc.build().unwrap();
        for _ in 0..20_000 {
            sim.step();
            assert_eq!(sim.index_capture(), None);
        }
        let pu = PowerUp {
            random_angle: true,
            index: true,
            seed: 5,
            ..PowerUp::default()
        };
        let d = pu.draw();
        let mut sim = sc.build().unwrap();
        sim.power_up(&pu).unwrap().unwrap();
        let l = sim.rig().screw.lead_m_per_rad;
        let cpr = sc.config().unwrap().encoder_cpr as f64;
        let counts_per_m = cpr / (TAU * l);
        let ts = sim.period();
        let v_max = 4.0 * amp * f;
        let mut caps = Vec::new();
        let mut x_prev = sim.motion().0;
        for _ in 0..(2.0 / ts) as usize {
            let s = sim.take_sample();
            let x = sim.motion().0;
            if let Some(c) = sim.index_capture() {
                // The rotor is at the mark within one period's travel of the sample.
                let rot = (d.theta_m0 + x / l - d.index_m).rem_euclid(TAU);
                let off = rot.min(TAU - rot);
                assert!(off <= v_max * ts / l * 1.0001, "{off} rad from the mark");
                // The captured count is the counter's within that travel (±1 count).
                let dc = s.encoder.wrapping_sub(c) as i16 as f64;
                assert!(dc.abs() <= v_max * ts * counts_per_m + 1.0, "{dc} counts");
                caps.push((x_prev, x, c));
            }
            x_prev = x;
            sim.apply_and_advance(&regen_fw::io::Actuation::OFF);
        }
        // One pulse per mark passed (closed form: the integers k between the revolutions at
        // the ends of each monotone stretch), over one period of the triangle: up 0 → A,
        // down A → −A, up −A → 0.
        let rev = |x: f64| (d.theta_m0 - d.index_m) / TAU + x / (TAU * l);
        let passed =
            |a: f64, b: f64| (rev(a).max(rev(b)).floor() - rev(a).min(rev(b)).floor()) as usize;
        let want = passed(0.0, amp) + passed(amp, -amp) + passed(-amp, 0.0);
        assert_eq!(caps.len(), want, "{caps:?}");
        assert!(want >= 12, "{want}");
        // Every capture is the same mark: counts apart by whole revolutions (mod 2^16), ±1.
        let c0 = caps[0].2;
        for &(_, _, c) in &caps {
            let dc = c.wrapping_sub(c0) as f64;
            let k = (-40..=40)
                .map(|k| ((k as f64 * cpr).rem_euclid(65_536.0) - dc).abs())
                .map(|e| e.min(65_536.0 - e))
                .fold(f64::MAX, f64::min);
            assert!(
                k <= 1.0,
                "capture {c} not a whole number of revolutions from {c0}"
            );
        }
    }

    /// A configuration the console posts (`set r_load_ohm 100`, compiled outside the loop)
    /// while period k is under way is installed between period k and k + 1: period k runs
    /// with the old one, every later period as if `set_config` had been called at that
    /// boundary, and the change shows (the run differs from an unchanged one).
    #[test]
    fn console_change_is_in_force_from_the_next_period() {
        let sc = Scenario::tmd(306.0);
        let (mut a, mut b, mut c) = (
            sc.build().unwrap(),
            sc.build().unwrap(),
            sc.build().unwrap(),
        );
        for _ in 0..4_000 {
            a.step();
            b.step();
            c.step();
        }
        let cfg = regen_fw::Config {
            r_load_ohm: 100.0,
            ..*a.ctl.config()
        };
        a.mailbox().cfg = regen_fw::Slot::Full(a.ctl.compile(&cfg).unwrap());
        a.step();
        b.step();
        c.step();
        assert_eq!(
            a.ctl.telemetry(),
            c.ctl.telemetry(),
            "period k: the old configuration"
        );
        assert_eq!(a.ctl.config().r_load_ohm, 100.0, "installed after period k");
        b.ctl.set_config(&cfg).unwrap();
        for _ in 0..4_000 {
            a.step();
            b.step();
            c.step();
        }
        assert_eq!(a.ctl.telemetry(), b.ctl.telemetry());
        assert_eq!(a.motion(), b.motion());
        assert_eq!(a.energy(), b.energy());
        assert_ne!(a.motion(), c.motion(), "the change shows");
    }

    #[test]
    fn split_step_is_exactly_one_step() {
        // `take_sample` + the controller held outside + `apply_and_advance` must reproduce
        // `step` bit for bit (the benchmark's replay and open-loop users rely on it), with the
        // sensor noise on so that the generator's use is compared too.
        let mut sc = Scenario::tmd(306.0);
        sc.sensors.current_noise_a = 0.02;
        sc.sensors.vbus_noise_v = 0.2;
        // Every plant channel (i_q_ref is the controller's telemetry, held outside in `b`).
        let ch: Vec<Channel> = Channel::ALL
            .iter()
            .copied()
            .filter(|c| *c != Channel::IqRef)
            .collect();
        let mut a = sc.build().unwrap();
        let mut b = sc.build().unwrap();
        a.record(&ch, 20);
        b.record(&ch, 20);
        let mut ctl = regen_fw::Controller::new(&sc.config().unwrap()).unwrap();
        ctl.set_mode(regen_fw::Mode::Run).unwrap();
        // `b` driven through the board's period routine (`Period::run`) from outside.
        struct Split<'a>(&'a mut super::Sim);
        impl regen_fw::DriveIo for Split<'_> {
            fn sample(&mut self) -> regen_fw::RawSample {
                self.0.take_sample()
            }
            fn apply(&mut self, out: &regen_fw::Actuation) {
                self.0.apply_and_advance(out)
            }
            fn now_us(&self) -> u64 {
                0
            }
        }
        impl regen_fw::PeriodHw for Split<'_> {}
        let mut per = regen_fw::Period::NEW;
        for _ in 0..20_000 {
            a.step();
            per.run(
                &mut ctl,
                &mut Split(&mut b),
                &mut regen_fw::capture::Capture::<4>::new(),
            );
        }
        assert_eq!(a.loop_period(), &per);
        assert_eq!(a.ctl.fault(), ctl.fault());
        assert_eq!(a.motion(), b.motion());
        assert_eq!(a.energy(), b.energy());
        assert!(a.energy().external_work > 0.0);
        let (ra, rb) = (a.recorder().unwrap(), b.recorder().unwrap());
        assert_eq!(ra.rows.len(), 20_000 / 20);
        assert!(ra.rows == rb.rows, "recorded rows differ");
    }

    #[test]
    fn mean_q_current_is_the_projection() {
        // Random periods (angle, speed, voltages, starting currents) of the reference machine:
        // the shortcut against the projection of the exact solution's mean current.
        let sc = crate::Scenario::tmd(306.0);
        let sim = sc.build().unwrap();
        let p = &sim.pre;
        let mut rng = 7u64;
        let mut u = |span: f64| span * (2.0 * crate::fastmath::uniform(&mut rng) - 1.0);
        let mut worst: f64 = 0.0;
        for _ in 0..100_000 {
            let th = u(4.0);
            let (sn, cs) = th.sin_cos();
            let kw = p.ke * u(300.0);
            let e = [-kw * sn, kw * cs];
            let v = [u(200.0), u(200.0)];
            let i0 = [u(20.0), u(20.0)];
            let mut i = i0;
            let el = super::averaged_period(&e, [v[0] / 100.0, v[1] / 100.0], 100.0, p, &mut i);
            let want = -sn * el.i_avg[0] + cs * el.i_avg[1];
            let got = super::mean_iq(p, (sn, cs), kw, v, i0);
            // relative to the operands' scale (voltages/R and currents): rounding only
            let scale = 200.0 * p.inv_r + 20.0;
            worst = worst.max((got - want).abs() / scale);
        }
        assert!(worst < 1e-14, "worst relative difference {worst:e}");
    }

    #[test]
    fn adc_code_is_the_truncation() {
        // The code as the clamp and an `as` conversion take it: both sides of every code,
        // the code's own value, exact halves, the ends, beyond them, ±∞ and NaN.
        let want = |c: f64| {
            let c = if c > 0.0 { c } else { 0.0 };
            (if c < 4095.0 { c } else { 4095.0 }) as i32 as u16
        };
        let mut xs = vec![
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            -1e300,
            1e300,
            -0.0,
        ];
        for k in -3..4100 {
            let k = k as f64;
            xs.extend([k, k + 0.5, k - 1e-12, k + 1e-12, k + 0.999_999_999_999]);
            xs.extend([k.next_up(), k.next_down()]);
        }
        for x in xs {
            assert_eq!(super::adc_code(x), want(x), "{x}");
        }
    }

    #[test]
    fn duty_clarke_is_clarke_of_the_duties() {
        // Against the transform of the phase voltages d_k·V_bus as floats (`clarke`), over
        // seeded duties (a quarter of them beyond 1, clamped) and bus voltages: within 4 ulp
        // of the larger voltage (each side rounds at most three times).
        use regen_fw::fx::Duty;
        use regen_fw::io::Actuation;
        let mut s = 0x1234_5678_9abc_def1u64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        for _ in 0..200_000 {
            let mut a = Actuation::OFF;
            a.enable = true;
            for d in a.duties.iter_mut() {
                *d = Duty::from_bits((next() % 40_960) as u16);
            }
            let vb = (next() % 400_000) as f64 * 1e-3;
            let d = a
                .duties
                .map(|d| (d.to_bits() as f64 * super::DUTY_LSB).min(1.0) * vb);
            let want = super::clarke(d);
            let dv = super::duty_clarke(&a);
            let got = [dv[0] * vb, dv[1] * vb];
            let tol = 4.0 * f64::EPSILON * vb.max(1e-300);
            for k in 0..2 {
                assert!((got[k] - want[k]).abs() <= tol, "{got:?} {want:?}");
            }
        }
    }

    #[test]
    fn common_period_is_the_general_one() {
        // The common period (`Sim::advance_as::<true>`, `Sim::sample_as::<false, false>`)
        // against the general code on the same run, bit for bit (`Debug` prints every f64
        // exactly): the closed loop of the reference TMD, then open-loop periods with random
        // duties (some beyond 1), the gates off and the brake closed.
        use regen_fw::fx::Duty;
        use regen_fw::io::Actuation;
        let sc = Scenario::tmd(306.0);
        let mut a = sc.build().unwrap();
        let mut b = sc.build().unwrap();
        assert!(a.pre.common, "the reference TMD's period is the common one");
        b.pre.common = false;
        let bits = |s: &super::Sim| format!("{:?} {:?} {:?}", s.s, s.flows, s.energy());
        for _ in 0..20_000 {
            let sample = a.sample_as::<false, false>();
            assert_eq!(sample, a.sample_as::<true, true>());
            a.step();
            b.step();
        }
        assert_eq!(bits(&a), bits(&b));
        let mut st = 0x2545_f491_4f6c_dd1du64;
        for k in 0..20_000 {
            st ^= st << 13;
            st ^= st >> 7;
            st ^= st << 17;
            let act = Actuation {
                duties: [0, 1, 2].map(|j| Duty::from_bits(((st >> (16 * j)) % 36_000) as u16)),
                enable: k % 7 != 0,
                brake: k % 5 == 0,
            };
            assert_eq!(a.take_sample(), b.take_sample());
            a.apply_and_advance(&act);
            b.apply_and_advance(&act);
        }
        assert_eq!(bits(&a), bits(&b));
        assert!(a.energy().brake > 0.0 && a.flows.i2_off > 0.0);
    }

    #[test]
    fn ledger_closes_across_a_bus_change() {
        // The bus's flows are summed without their constants, which a bus change replaces
        // (`Flows::bank`): the load disconnected mid-run (no source/sink any more, the
        // brake chopper takes the energy) must not lose the energy the source took before.
        // Measured: residual −5.5e-9 of the largest flow (the ledger's own discretisation,
        // as in every closed-loop run); bound 3×. Without the bank the source's 146 J vanish
        // from the ledger (residual ≈ 0.27).
        let sc = Scenario::tmd(306.0);
        let mut sim = sc.build().unwrap();
        sim.run_for(8.0);
        let before = sim.energy();
        assert!(before.sink > 1.0, "the source took {} J", before.sink);
        let mut b = sim.rig().bus;
        b.source_v = None;
        sim.set_bus(b).unwrap();
        // Its flows carry over unchanged at the change.
        let at = sim.energy();
        assert_eq!(
            (at.sink, at.brake, at.source_r_loss),
            (before.sink, before.brake, before.source_r_loss)
        );
        sim.run_for(3.0);
        let e = sim.energy();
        assert!(e.brake > before.brake, "the brake took nothing");
        let r = e.relative_residual();
        eprintln!("relative residual {r:.2e}");
        assert!(r.abs() < 1.7e-8, "residual {r:e}");
    }

    #[test]
    fn a_bus_change_keeps_the_rotor_angle() {
        // An imposed motion starting 12.3 mm from the origin (the rotor's angle origin is
        // moved to its first count, `Sim::new`), moving at 0.1 m/s under a 50 Ω law: a bus
        // change (the same bus) rebuilds the run's constants and must not move the angle's
        // origin, which would leave the firmware's commutation off by 12.3 mm of rotor angle
        // (without the rotor angle kept: 6,995 N against 496 N after 0.2 s).
        use crate::plant::Motion;
        let t: Vec<f64> = (0..=100).map(|k| k as f64 * 0.01).collect();
        let x: Vec<f64> = t.iter().map(|t| 0.0123 + 0.1 * t).collect();
        let m = Motion::Recorded {
            t_s: t,
            x_m: x,
            v_m_s: vec![],
            a_m_s2: vec![],
            v_kin_m_s: vec![],
        };
        let sc = Scenario::imposed(m, 50.0, 1.0);
        let mut a = sc.build().unwrap();
        let mut b = sc.build().unwrap();
        let bus = b.rig().bus;
        b.set_bus(bus).unwrap();
        for _ in 0..4000 {
            a.step();
            b.step();
        }
        assert!(a.force().0 > 100.0, "the law brakes: {:?}", a.force());
        assert_eq!(a.force(), b.force());
        assert_eq!(a.energy(), b.energy());
    }

    #[test]
    fn a_reboot_keeps_the_firmware_energy_sum() {
        // The period's sum takes each period's power at the next period's step
        // (`Period::step`): a reboot between two periods replaces the controller that still
        // holds the last period's power, which `Period::bank` folds in first. The sum read
        // right after the reboot is the sum read right before it (without the bank: short
        // by the last period's power).
        let mut sim = Scenario::tmd(306.0).build().unwrap();
        sim.run_for(8.0);
        let before = sim.loop_period().energy_bits(sim.controller());
        assert!(
            sim.controller().p_elec().to_bits() != 0,
            "the last period carries power"
        );
        sim.reboot().unwrap();
        assert_eq!(sim.loop_period().energy_bits(sim.controller()), before);
        // And the fresh controller's first period adds nothing before its own step's power.
        sim.step();
        assert_eq!(
            sim.loop_period().energy_bits(sim.controller()) - before,
            sim.controller().p_elec().to_bits() as i64
        );
    }
}
