//! Fault injection: a layer around [`Sim`] that, from a chosen moment, falsifies the sample
//! on its way to the firmware (current, bus and encoder sensors stuck, open, noisy, offset,
//! glitching or running away), changes the plant at run time (bus load disconnected, brake
//! resistor open, excitation beyond the rating) or reports current-loop overruns. The
//! simulation itself is unchanged: the layer uses [`Sim::step_with`], [`Sim::set_bus`] and
//! [`Sim::set_drive`].

use crate::plant::{Drive, Excitation};
use crate::sim::Sim;
use crate::stage::{Stage, StageSpec};
use regen_fw::io::{Actuation, RawSample};

/// What goes wrong.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Inject {
    /// The phase's ADC code freezes at its value at the moment of injection.
    CurrentStuck { phase: usize },
    /// The phase's sensor line opens: the code sits at a rail (0 or 4095).
    CurrentOpen { phase: usize, high: bool },
    /// Gaussian noise of `sigma_a` (A rms) added to the phase's reading.
    CurrentNoise { phase: usize, sigma_a: f64 },
    /// The phase's zero offset jumps by `offset_a`.
    CurrentOffset { phase: usize, offset_a: f64 },
    /// The bus-voltage sensor reads 0 (line open).
    BusSensorOpen,
    /// The bus-voltage sensor reads full scale.
    BusSensorRail,
    /// The bus-voltage reading freezes at its value at the moment of injection.
    BusSensorStuck,
    /// Gaussian noise of `sigma_v` (V rms) on the bus-voltage reading.
    BusSensorNoise { sigma_v: f64 },
    /// The encoder count jitters by a uniform ±`counts` every period (no net drift).
    EncoderNoise { counts: u16 },
    /// The encoder counter stops (cable cut, coupling slipped).
    EncoderStuck,
    /// The counter jumps by `counts` once and keeps the offset (a noise burst or a slip).
    EncoderGlitch { counts: i32 },
    /// The counter runs away by `counts_per_step` every period (a broken channel counting
    /// noise).
    EncoderRunaway { counts_per_step: i32 },
    /// The bus source/sink is disconnected (no load for regenerated power); with
    /// `brake_open` the brake resistor is open too.
    LoadDisconnect { brake_open: bool },
    /// The structure's base excitation is multiplied by `factor`.
    Overexcite { factor: f64 },
    /// The board reports a current-loop overrun every `every` periods.
    Overrun { every: u32 },
    /// The emulated load is switched to `r_load_ohm` (an overload the law commands: the
    /// current goes to its clip).
    Overload { r_load_ohm: f32 },
    /// The MCU core stops for good (lockup that recurs at every boot): the timer keeps its
    /// last compare values and only the stage's hardware paths act until the independent
    /// watchdog resets the MCU (`iwdg_s`); from then on the pins stay at their reset state
    /// ([`crate::stage`]; needs [`FaultSim::with_stage`]).
    McuHalt,
    /// The core stops and the watchdog resets the MCU `timeout_s` later: pins at their reset
    /// state (all off) for the stage's boot time, then a fresh controller as at power-up
    /// ([`Sim::power_up`]) and the breaks re-armed.
    WatchdogReset { timeout_s: f64 },
    /// The comparators and breaks are enabled again (as at power-up) with an output
    /// transient of `enable_s` on the bus (or a phase) comparator, then a ringing pulse of
    /// `ring_s` every `ring_every` periods.
    ComparatorFalseTrip {
        enable_s: f64,
        ring_s: f64,
        ring_every: u32,
        bus: bool,
    },
    /// Every DAC threshold of the stage multiplied by `scale` (a wrong code).
    DacWrong { scale: f64 },
}

impl Inject {
    /// Short name (suite reports).
    pub fn name(&self) -> &'static str {
        match self {
            Inject::CurrentStuck { .. } => "current_stuck",
            Inject::CurrentOpen { .. } => "current_open",
            Inject::CurrentNoise { .. } => "current_noise",
            Inject::CurrentOffset { .. } => "current_offset",
            Inject::BusSensorOpen => "bus_sensor_open",
            Inject::BusSensorRail => "bus_sensor_rail",
            Inject::BusSensorStuck => "bus_sensor_stuck",
            Inject::BusSensorNoise { .. } => "bus_sensor_noise",
            Inject::EncoderNoise { .. } => "encoder_noise",
            Inject::EncoderStuck => "encoder_stuck",
            Inject::EncoderGlitch { .. } => "encoder_glitch",
            Inject::EncoderRunaway { .. } => "encoder_runaway",
            Inject::LoadDisconnect { brake_open: false } => "load_disconnect",
            Inject::LoadDisconnect { brake_open: true } => "load_disconnect_brake_open",
            Inject::Overexcite { .. } => "overexcite",
            Inject::Overrun { .. } => "overrun",
            Inject::Overload { .. } => "overload",
            Inject::McuHalt => "mcu_halt",
            Inject::WatchdogReset { .. } => "watchdog_reset",
            Inject::ComparatorFalseTrip { .. } => "comparator_false_trip",
            Inject::DacWrong { .. } => "dac_wrong",
        }
    }
}

/// A simulation with one fault injected at `at_s`.
pub struct FaultSim {
    pub sim: Sim,
    pub inject: Inject,
    pub at_s: f64,
    active: bool,
    frozen: u16,
    enc_offset: u16,
    rng: u64,
    counts_per_amp: f64,
    counts_per_volt: f64,
    k: u64,
    /// The power stage's hardware paths, when modelled ([`FaultSim::with_stage`]).
    pub stage: Option<Stage>,
}

impl FaultSim {
    /// Wrap `sim`; `seed` drives the injected noise.
    pub fn new(sim: Sim, inject: Inject, at_s: f64, seed: u64) -> FaultSim {
        let counts_per_amp = 1.0 / sim.controller().config().amps_per_count as f64;
        let counts_per_volt = 1.0 / sim.controller().config().volts_per_count as f64;
        FaultSim {
            sim,
            inject,
            at_s,
            active: false,
            frozen: 0,
            enc_offset: 0,
            rng: seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1,
            counts_per_amp,
            counts_per_volt,
            k: 0,
            stage: None,
        }
    }

    /// Model the power stage's hardware paths ([`crate::stage`]) under the firmware, enabled
    /// at the simulation's present time.
    pub fn with_stage(mut self, spec: StageSpec) -> FaultSim {
        self.stage = Some(Stage::new(spec, self.sim.time()));
        self
    }

    /// Whether the fault is in force.
    pub fn active(&self) -> bool {
        self.active
    }

    /// Plant changes at the moment of injection.
    fn start(&mut self) -> Result<(), String> {
        match self.inject {
            Inject::LoadDisconnect { brake_open } => {
                let mut b = self.sim.rig().bus;
                b.source_v = None;
                if brake_open {
                    b.brake_r_ohm = f64::INFINITY;
                }
                self.sim.set_bus(b)?;
            }
            Inject::Overexcite { factor } => {
                let mut d = self.sim.rig().drive.clone();
                if let Drive::Structure { excitation, .. } = &mut d {
                    match excitation {
                        Excitation::Sine { a0_m_s2, .. } | Excitation::Triangle { a0_m_s2, .. } => {
                            *a0_m_s2 *= factor
                        }
                        Excitation::KanaiTajimi { s0, .. } => *s0 *= factor * factor,
                        _ => return Err("overexcite: sine, triangle or Kanai–Tajimi only".into()),
                    }
                } else {
                    return Err("overexcite needs a structure".into());
                }
                self.sim.set_drive(d)?;
            }
            Inject::Overload { r_load_ohm } => {
                let mut c = *self.sim.controller().config();
                c.r_load_ohm = r_load_ohm;
                self.sim
                    .controller_mut()
                    .set_config(&c)
                    .map_err(|e| e.to_string())?;
            }
            Inject::McuHalt | Inject::WatchdogReset { .. } => {
                self.stage
                    .as_mut()
                    .ok_or("mcu_halt / watchdog_reset need the stage model")?
                    .halt();
            }
            Inject::ComparatorFalseTrip { enable_s, bus, .. } => {
                let t = self.sim.time();
                let spec = *self.stage.as_ref().ok_or("needs the stage model")?.spec();
                let mut st = Stage::new(spec, t);
                st.glitch(enable_s, bus);
                self.stage = Some(st);
            }
            Inject::DacWrong { scale } => {
                self.stage
                    .as_mut()
                    .ok_or("needs the stage model")?
                    .set_dac_scale(scale);
            }
            _ => {}
        }
        Ok(())
    }

    /// One PWM period.
    pub fn step(&mut self) -> Result<(), String> {
        if !self.active && self.sim.time() >= self.at_s - 0.5 * self.sim.period() {
            self.active = true;
            self.start()?;
        }
        if self.stage.is_some() {
            return self.step_staged();
        }
        if !self.active {
            self.sim.step();
            return Ok(());
        }
        self.inject_step();
        Ok(())
    }

    /// One period with the stage model between the firmware and the plant.
    fn step_staged(&mut self) -> Result<(), String> {
        let t = self.sim.time();
        let Some(st) = self.stage.as_mut() else {
            return Ok(());
        };
        if st.cpu == crate::stage::Cpu::Halted {
            match self.inject {
                Inject::WatchdogReset { timeout_s } if t >= self.at_s + timeout_s => st.reset(t),
                Inject::McuHalt if t >= self.at_s + st.spec().iwdg_s => {
                    st.reset(t);
                    st.cpu = crate::stage::Cpu::Reset {
                        until_s: f64::INFINITY,
                    };
                }
                _ => {}
            }
        }
        let rebooting = st.in_reset();
        if st.cpu_runs(t) {
            if rebooting {
                self.sim.reboot()?;
            }
            if let Inject::ComparatorFalseTrip {
                ring_s,
                ring_every,
                bus,
                ..
            } = self.inject
            {
                if self.active && (self.k + 1).is_multiple_of(ring_every.max(1) as u64) {
                    st.glitch(ring_s, bus);
                }
            }
            if self.active {
                self.inject_step();
            } else {
                let st = self.stage.as_mut().expect("checked");
                self.sim.step_with(|_| {}, |a| *a = st.gate(a));
            }
        } else {
            let _ = self.sim.take_sample();
            let out = st.gate(&Actuation::OFF);
            self.sim.apply_and_advance(&out);
        }
        let (t, vb, i) = (self.sim.time(), self.sim.v_bus(), self.sim.currents());
        if let Some(st) = self.stage.as_mut() {
            let was = (st.brk, st.brk2);
            st.observe(t, vb, i);
            // A break latched while the core runs sets the timer's flag, which the firmware's
            // period reads (the board's `trip::take_trip`): the fault latches and the mode
            // follows the gates the break holds off. A halted core never reads it; a reset
            // clears it.
            if st.cpu == crate::stage::Cpu::Running {
                if st.brk && !was.0 {
                    self.sim.report_break(regen_fw::protect::Fault::OverCurrent);
                } else if st.brk2 && !was.1 {
                    self.sim
                        .report_break(regen_fw::protect::Fault::BusOverVoltage);
                }
            }
        }
        Ok(())
    }

    /// One period with the injected fault in force (the firmware running).
    fn inject_step(&mut self) {
        self.k += 1;
        let first = self.k == 1;
        if let Inject::Overrun { every } = self.inject {
            if self.k.is_multiple_of(every.max(1) as u64) {
                self.sim.controller_mut().report_overrun();
            }
        }
        let inj = self.inject;
        let (frozen, enc_offset, rng, cpa, cpv, stage) = (
            &mut self.frozen,
            &mut self.enc_offset,
            &mut self.rng,
            self.counts_per_amp,
            self.counts_per_volt,
            &mut self.stage,
        );
        self.sim.step_with(
            |s: &mut RawSample| match inj {
                Inject::CurrentStuck { phase } => {
                    if first {
                        *frozen = s.i_abc[phase];
                    }
                    s.i_abc[phase] = *frozen;
                }
                Inject::CurrentOpen { phase, high } => s.i_abc[phase] = if high { 4095 } else { 0 },
                Inject::CurrentNoise { phase, sigma_a } => {
                    let c = s.i_abc[phase] as f64 + sigma_a * cpa * gauss(rng);
                    s.i_abc[phase] = c.round().clamp(0.0, 4095.0) as u16;
                }
                Inject::CurrentOffset { phase, offset_a } => {
                    let c = s.i_abc[phase] as f64 + offset_a * cpa;
                    s.i_abc[phase] = c.round().clamp(0.0, 4095.0) as u16;
                }
                Inject::BusSensorOpen => s.v_bus = 0,
                Inject::BusSensorRail => s.v_bus = 4095,
                Inject::BusSensorStuck => {
                    if first {
                        *frozen = s.v_bus;
                    }
                    s.v_bus = *frozen;
                }
                Inject::BusSensorNoise { sigma_v } => {
                    let c = s.v_bus as f64 + sigma_v * cpv * gauss(rng);
                    s.v_bus = c.round().clamp(0.0, 4095.0) as u16;
                }
                Inject::EncoderNoise { counts } => {
                    let n = 2 * counts as u64 + 1;
                    let j = (uniform(rng) * n as f64) as i64 - counts as i64;
                    s.encoder = s.encoder.wrapping_add(j as u16);
                }
                Inject::EncoderStuck => {
                    if first {
                        *frozen = s.encoder;
                    }
                    s.encoder = *frozen;
                }
                Inject::EncoderGlitch { counts } => {
                    if first {
                        *enc_offset = counts as u16;
                    }
                    s.encoder = s.encoder.wrapping_add(*enc_offset);
                }
                Inject::EncoderRunaway { counts_per_step } => {
                    *enc_offset = enc_offset.wrapping_add(counts_per_step as u16);
                    s.encoder = s.encoder.wrapping_add(*enc_offset);
                }
                Inject::LoadDisconnect { .. }
                | Inject::Overexcite { .. }
                | Inject::Overrun { .. }
                | Inject::Overload { .. }
                | Inject::McuHalt
                | Inject::WatchdogReset { .. }
                | Inject::ComparatorFalseTrip { .. }
                | Inject::DacWrong { .. } => {}
            },
            |a| {
                if let Some(st) = stage.as_mut() {
                    *a = st.gate(a);
                }
            },
        );
    }
}

/// A uniform deviate in [0, 1) (xorshift64*).
fn uniform(s: &mut u64) -> f64 {
    *s ^= *s >> 12;
    *s ^= *s << 25;
    *s ^= *s >> 27;
    (s.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
}

/// A standard normal deviate (xorshift64* + Box–Muller).
fn gauss(s: &mut u64) -> f64 {
    let mut u = || {
        *s ^= *s >> 12;
        *s ^= *s << 25;
        *s ^= *s >> 27;
        ((s.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    let (a, b) = (u(), u());
    (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
}
