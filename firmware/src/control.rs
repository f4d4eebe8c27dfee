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

/// A latched fault.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fault {
    /// A phase current exceeded `i_trip_a`.
    OverCurrent,
    /// The bus voltage exceeded `v_bus_ov`.
    BusOverVoltage,
    /// The bus voltage fell below `v_bus_uv` while running.
    BusUnderVoltage,
    /// The encoder count jumped by more than a plausible amount in one period.
    EncoderImplausible,
}

impl Fault {
    /// Console name.
    pub fn name(self) -> &'static str {
        match self {
            Fault::OverCurrent => "over_current",
            Fault::BusOverVoltage => "bus_over_voltage",
            Fault::BusUnderVoltage => "bus_under_voltage",
            Fault::EncoderImplausible => "encoder_implausible",
        }
    }

    /// The state the drive goes to on this fault. Over-current and under-voltage open the
    /// phases (the fault may be in the bridge, and nothing controls the current without a
    /// bus); over-voltage and encoder faults short them (no power reaches the bus, and the
    /// short needs no angle), which also brakes the structure hardest.
    pub fn safe_mode(self) -> Mode {
        match self {
            Fault::OverCurrent | Fault::BusUnderVoltage => Mode::Idle,
            Fault::BusOverVoltage | Fault::EncoderImplausible => Mode::Short,
        }
    }
}

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
            if m != Mode::Idle && m != f.safe_mode() {
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

    /// Clear a latched fault (the drive stays in its safe mode until told otherwise).
    pub fn clear_fault(&mut self) {
        self.fault = None;
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
    }

    fn trip(&mut self, f: Fault) {
        if self.fault.is_none() {
            self.fault = Some(f);
        }
        self.mode = f.safe_mode();
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
            self.trip(f);
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
                limit_vector(r, g.i_max).unwrap_or(r)
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
