//! The current-loop step: raw sample in, actuation out.
//!
//! Order of one period (20 kHz by default): scale the sample → encoder angle and speed →
//! Clarke → Park → protection checks → command law → current limit → two PI controllers
//! with feed-forward and the bus-voltage limit → inverse Park → space-vector modulation →
//! brake chopper. The step is a pure function of (state, sample, parameters); parameters are
//! replaced only between steps ([`Controller::set_config`]).

use crate::config::{Config, ConfigError, Gains};
use crate::encoder::Encoder;
use crate::frames::{clarke, inverse_park, park, Dq};
use crate::fx::{clamp_sym, mul, Angle, Duty, Q};
use crate::io::{Actuation, RawSample};
use crate::laws::{CommandLaw, Law, LawInput};
use crate::pi::{limit_vector, CurrentPi};
use crate::svpwm::{inv_bus, modulate, CENTRED};

/// Operating mode.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Mode {
    /// Gate drivers off: no control (phases open, diodes may rectify).
    #[default]
    Idle,
    /// The command law runs.
    Run,
    /// Phases shorted through the low-side switches: the machine brakes on its own resistance.
    Short,
    /// Current controlled to zero: open terminals emulated even when the back-emf exceeds
    /// the bus.
    Open,
}

impl Mode {
    /// Console name.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Idle => "idle",
            Mode::Run => "run",
            Mode::Short => "short",
            Mode::Open => "open",
        }
    }
}

pub use crate::protect::Fault;
use crate::protect::{derate_regen, Protection, SUPERVISE_HZ};

/// What the loop measured and commanded in its last period (SI units in fixed point).
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

/// The current controller and everything it owns.
#[derive(Clone, Debug)]
pub struct Controller {
    cfg: Config,
    g: Gains,
    law: Law,
    mode: Mode,
    fault: Option<Fault>,
    enc: Encoder,
    pi: CurrentPi,
    brake: bool,
    tel: Telemetry,
    /// Protection state (protect.rs): derate factor, supervision, fault record.
    prot: Protection,
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
            tel: Telemetry::default(),
            prot: Protection::default(),
        })
    }

    /// Replace the configuration (validated first; on error nothing changes). The law's
    /// state is rebuilt only when a law parameter changed.
    pub fn set_config(&mut self, cfg: &Config) -> Result<(), ConfigError> {
        let g = Gains::new(cfg)?;
        if Law::params_changed(&self.cfg, cfg) {
            self.law = Law::from_config(cfg);
        }
        self.cfg = *cfg;
        self.g = g;
        Ok(())
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
    pub fn set_mode(&mut self, m: Mode) -> Result<(), Fault> {
        if let Some(f) = self.fault {
            // Open dominates: after a later fault that opened the phases, only Idle.
            let opened = self
                .prot
                .record()
                .is_some_and(|r| r.later().any(|g| g.safe_mode() == Mode::Idle));
            if m != Mode::Idle && (m != f.safe_mode() || opened) {
                return Err(f);
            }
        }
        if m != self.mode {
            self.pi.reset();
        }
        self.mode = m;
        Ok(())
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
            let later = self.prot.record().map_or(0, |r| r.later);
            // The first fault's cause and every later one's must be gone.
            for g in core::iter::once(f).chain(
                Fault::ALL
                    .iter()
                    .copied()
                    .filter(|g| later & (1 << g.code()) != 0),
            ) {
                if let Some(why) =
                    self.prot
                        .cause_present(g, &self.cfg, &self.tel, self.enc.implausible)
                {
                    return Err(why);
                }
            }
        }
        self.fault = None;
        self.prot.forget();
        Ok(())
    }

    /// Protection state: fault record with its snapshot, warnings, I²t, derate factor.
    pub fn protection(&self) -> &Protection {
        &self.prot
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
        let v = self
            .prot
            .supervise(&self.cfg, self.mode, &self.tel, self.enc.position);
        if let Some(f) = v.trip {
            let t = self.tel;
            self.trip(f, &t);
        }
    }

    pub fn telemetry(&self) -> &Telemetry {
        &self.tel
    }

    pub fn law_mut(&mut self) -> &mut Law {
        &mut self.law
    }

    /// Zero the position (the travel `x` counts from here).
    pub fn rezero_position(&mut self) {
        self.enc.rezero();
        self.prot.rezero();
    }

    /// Latch `f` (with a snapshot of `t`) and go to its safe state. Open dominates: once a
    /// fault has opened the phases, a later fault never re-enables the gates.
    #[cold]
    fn trip(&mut self, f: Fault, t: &Telemetry) {
        self.prot.latch(f, self.mode, t);
        let open = self.fault.is_some() && self.mode == Mode::Idle;
        if self.fault.is_none() {
            self.fault = Some(f);
        }
        self.mode = if open { Mode::Idle } else { f.safe_mode() };
        self.pi.reset();
    }

    /// One current-loop period.
    ///
    /// Never inlined: on the board it stays a function of this crate, compiled at this crate's
    /// opt-level (`s`), while the rest of the image is built for size (`z`), see
    /// `firmware/board/Cargo.toml`. The call costs a few cycles of the 8,500 of a period.
    #[inline(never)]
    pub fn step(&mut self, s: &RawSample) -> Actuation {
        let g = &self.g;
        // Measurements.
        let cur = |code: u16| {
            g.amps_per_count
                .scale(Q::from_bits((code as i32 - g.adc_zero) << 16))
        };
        let i_abc = [cur(s.i_abc[0]), cur(s.i_abc[1]), cur(s.i_abc[2])];
        let v_bus = g
            .volts_per_count
            .scale(Q::from_bits((s.v_bus as i32) << 16));
        let shaft = self.enc.update(s.encoder, &g.enc);
        let (sin, cos) = shaft.theta_e.sin_cos();
        let i_dq = park(clarke(i_abc[0], i_abc[1], i_abc[2]), sin, cos);
        let e_q = g.ke.scale(shaft.omega_m);

        // Protection (instantaneous).
        let over_i = i_abc.iter().any(|i| i.abs() > g.i_trip);
        let fault = if over_i {
            Some(crate::control::Fault::OverCurrent)
        } else if v_bus > g.v_ov {
            Some(Fault::BusOverVoltage)
        } else if self.enc.implausible {
            Some(Fault::EncoderImplausible)
        } else if self.mode == Mode::Run && v_bus < g.v_uv {
            Some(Fault::BusUnderVoltage)
        } else {
            None
        };
        if let Some(f) = fault {
            // Protection hook (protect.rs): snapshot of this period's measurements.
            let t = Telemetry {
                i_abc,
                i_dq,
                v_bus,
                omega_m: shaft.omega_m,
                x: shaft.x,
                ..self.tel
            };
            self.trip(f, &t);
        }
        let g = &self.g;

        // Brake chopper with hysteresis (independent of mode: it protects the bus).
        self.brake = v_bus > g.brake_on || (self.brake && v_bus > g.brake_off);

        // Current reference.
        let i_ref = match self.mode {
            Mode::Run => {
                let r = self.law.command(&LawInput {
                    omega_m: shaft.omega_m,
                    e_q,
                    x: shaft.x,
                    i_dq,
                    v_bus,
                });
                let r = limit_vector(r, g.i_max).unwrap_or(r);
                // Protection hook (protect.rs): bus derating of a regenerative reference.
                derate_regen(r, shaft.omega_m, self.prot.derate)
            }
            _ => Dq::default(),
        };

        let (duties, enable, v_dq, sat) = match self.mode {
            Mode::Idle => (CENTRED, false, Dq::default(), false),
            Mode::Short => ([Duty::ZERO; 3], true, Dq::default(), false),
            Mode::Run | Mode::Open => {
                let mut ff = Dq::default();
                let w_e = shaft.omega_m.saturating_mul_int(g.pole_pairs);
                if g.ff_emf {
                    ff.q = e_q;
                }
                if g.ff_decouple {
                    let wl = g.l.scale(w_e);
                    ff.d = -mul(wl, i_ref.q);
                    ff.q = ff.q.saturating_add(mul(wl, i_ref.d));
                }
                let err = Dq {
                    d: i_ref.d.saturating_sub(i_dq.d),
                    q: i_ref.q.saturating_sub(i_dq.q),
                };
                let v_max = g.v_lim_per_bus.scale(v_bus);
                let out = self.pi.update(err, ff, &g.pi, v_max);
                let adv = g.advance.mul_wide(w_e.to_bits() as i64) as i32 as u32;
                let (s2, c2) = Angle(shaft.theta_e.0.wrapping_add(adv)).sin_cos();
                let v_ab = inverse_park(out.v, s2, c2);
                (modulate(v_ab, inv_bus(v_bus)), true, out.v, out.saturated)
            }
        };

        let p = mul(v_dq.d, i_dq.d).saturating_add(mul(v_dq.q, i_dq.q));
        self.tel = Telemetry {
            i_abc,
            i_dq,
            i_ref,
            v_dq,
            v_bus,
            omega_m: shaft.omega_m,
            x: shaft.x,
            theta_e: shaft.theta_e,
            p_elec: -(p.saturating_add(p / 2)),
            duties,
            v_saturated: sat,
            brake: self.brake,
        };
        let _ = clamp_sym;
        Actuation {
            duties,
            enable,
            brake: self.brake,
        }
    }
}
