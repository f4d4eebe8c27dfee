//! The power stage's hardware protection paths, modelled apart from the firmware: what the
//! STM32G474's comparators, DACs and TIM1 break inputs do to the gates whatever the firmware
//! commands, and the pins' state while the MCU is in reset. Design (`docs/protection.md`,
//! "Hardware paths"):
//!
//! The settings are the `board` helper's (`/work/notes/stage-design.md`,
//! `regen_fw::io::HwThresholds` on that branch):
//!
//! * **Phase over-current** (BRK, all six switches off): one comparator per phase, one-sided
//!   (a phase current below `−oc_hw_a`: the direction a shoot-through or a phase-to-DC+ short
//!   drives through a low-side shunt; Σi = 0, so a phase above `+2·oc_hw_a` trips another),
//!   `oc_hw_a = min(1.1·i_trip_a, 0.95·adc_zero_code·amps_per_count)` (22 A on the board).
//!   The low-side shunt's conduction window is not modelled (the comparator sees the true
//!   current at every period's end).
//! * **Bus over-voltage** (BRK2): `(v_bus_ov + v_abs_max)/2`; the G4's BRK2 can only force
//!   all six off ([`Brk2Idle::Open`], the board's choice); [`Brk2Idle::Short`] (low sides on,
//!   not realisable through BRK2 on the G4) is kept as a variant for comparison.
//! * **Brake chopper** driven by a comparator with hysteresis (`brake_on_v` /
//!   `brake_off_v`) through its output pin (COMP7 → PC8 on the board), OR-ed with the
//!   firmware's command, independent of the CPU but dead in reset ([`Chopper::Comparator`]);
//!   [`Chopper::External`] is the clamp outside the MCU the board needs for the reset gap.
//! * **Digital filters** of the break inputs: a comparator output must stay high `filter_s`
//!   (BRK, 0.16 µs) or `filter2_s` (BRK2, 1.5 µs) before the break acts; **arming** only
//!   `settle_s` after enable, with the break flags cleared then (comparators of this family
//!   glitch on enable).
//! * **Reset**: every gate and the chopper pin low (pulled down): all switches off, no
//!   chopper, comparators and DACs unconfigured, until the firmware has booted and re-armed.
//!
//! Time resolution: the simulator advances one PWM period at a time; a comparator compares the
//! plant's true bus and phase currents at the end of each period and the break acts from the
//! next one (latency ≤ one period + `filter_s`, against microseconds on the board: the
//! model is slower than the hardware, so the fault-injection bounds are conservative).
//! Glitches shorter than a period ([`Stage::glitch`]) are resolved by their length against
//! `filter_s`.

use regen_fw::fx::Duty;
use regen_fw::io::Actuation;
use regen_fw::Config;

/// What BRK2 (bus over-voltage) does to the gates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Brk2Idle {
    /// Low sides on, high sides off: an active short circuit in hardware (no power reaches
    /// the bus, no angle needed; phase current `K_e·ω/|R + jωpL|` < `K_e/(pL)`).
    Short,
    /// All off: the body diodes rectify above the onset; only the chopper protects the bus.
    Open,
}

/// Who drives the brake chopper.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Chopper {
    /// The firmware's `Actuation::brake` (stops with the CPU).
    Firmware,
    /// A comparator output pin of the MCU (works while the core is halted, not in reset),
    /// OR-ed with the firmware's pin.
    Comparator,
    /// A comparator outside the MCU (works in reset too), OR-ed with the firmware's pin.
    External,
}

/// The stage's rating and the hardware paths' settings.
#[derive(Clone, Copy, Debug)]
pub struct StageSpec {
    /// Absolute maximum of the bus (capacitor/MOSFET rating), V.
    pub v_abs_max: f64,
    /// Peak phase current the stage is rated for (stated peak), A.
    pub i_peak_a: f64,
    /// Over-current comparator threshold, A.
    pub oc_hw_a: f64,
    /// Bus over-voltage comparator threshold, V.
    pub ov_hw_v: f64,
    /// Chopper comparator: on above, off below (hysteresis), V.
    pub brake_on_v: f64,
    pub brake_off_v: f64,
    pub brk2: Brk2Idle,
    pub chopper: Chopper,
    /// BRK's digital filter (+ comparator delay), s.
    pub filter_s: f64,
    /// BRK2's digital filter, s.
    pub filter2_s: f64,
    /// Comparator/DAC settling before the breaks are armed (flags cleared then), s.
    pub settle_s: f64,
    /// From the watchdog's reset to the firmware running again (boot, clocks, peripherals), s.
    pub boot_s: f64,
    /// Independent watchdog timeout: a core stopped this long is reset, s.
    pub iwdg_s: f64,
}

impl StageSpec {
    /// The hardware settings as the board derives them from the firmware's configuration,
    /// for a stage of absolute maximum `v_abs_max`.
    pub fn from_config(cfg: &Config, v_abs_max: f64) -> StageSpec {
        let i_sc = cfg.ke_v_s_per_rad as f64
            / (cfg.pole_pairs as f64 * cfg.l_d().min(cfg.l_phase_h) as f64);
        let range = cfg.adc_zero_code as f64 * cfg.amps_per_count as f64;
        let oc = (1.1 * cfg.i_trip_a as f64).min(0.95 * range);
        StageSpec {
            v_abs_max,
            // The short's own current with its full DC offset (2·K_e/(pL)) is the highest
            // current the stage carries by design; the OC comparator's threshold plus one
            // period of the steepest rise bounds everything else.
            i_peak_a: (2.0 * i_sc).max(oc),
            oc_hw_a: oc,
            ov_hw_v: 0.5 * (cfg.v_bus_ov as f64 + v_abs_max),
            brake_on_v: cfg.brake_on_v as f64,
            brake_off_v: cfg.brake_off_v as f64,
            brk2: Brk2Idle::Open,
            chopper: Chopper::Comparator,
            filter_s: 0.16e-6,
            filter2_s: 1.5e-6,
            settle_s: 40e-6,
            boot_s: 5e-3,
            iwdg_s: 5e-3,
        }
    }
}

/// The MCU as the stage sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Cpu {
    Running,
    /// The core stopped (lockup, debugger): the timer keeps the last compare values, the
    /// comparators and breaks keep working.
    Halted,
    /// In reset or booting until `until_s`: pins at their reset state, nothing armed.
    Reset {
        until_s: f64,
    },
}

/// The comparators' thresholds with the DACs' multiplier applied (only the MCU's comparators
/// have a DAC: an external chopper's are the spec's).
#[derive(Clone, Copy, Debug)]
struct Thresholds {
    /// The chopper's threshold while it is off (on above it) and while it is on (off below).
    chopper: [f64; 2],
    ov_v: f64,
    oc_a: f64,
}

impl Thresholds {
    fn new(s: &StageSpec, dac_scale: f64) -> Thresholds {
        let chop = if s.chopper == Chopper::External {
            1.0
        } else {
            dac_scale
        };
        Thresholds {
            chopper: [s.brake_on_v * chop, s.brake_off_v * chop],
            ov_v: s.ov_hw_v * dac_scale,
            oc_a: s.oc_hw_a * dac_scale,
        }
    }
}

/// The stage's state.
#[derive(Clone, Debug)]
pub struct Stage {
    /// The settings ([`Stage::spec`]); fixed for the stage's life, the thresholds derive
    /// from them.
    spec: StageSpec,
    pub cpu: Cpu,
    /// Break inputs armed (after settling, flags cleared).
    pub armed: bool,
    /// Latched break events (cleared only by the firmware re-enabling the outputs).
    pub brk: bool,
    pub brk2: bool,
    pub chopper_on: bool,
    /// Time the breaks were enabled (arming `settle_s` later).
    enabled_at: f64,
    /// Pending output glitch on a break comparator: its length, s, and whether it is on the
    /// bus comparator (BRK2) or a phase comparator (BRK).
    glitch: Option<(f64, bool)>,
    /// The comparators' thresholds as the DACs set them ([`Thresholds::new`]; a wrong DAC
    /// code, fault injection: [`Stage::set_dac_scale`]).
    thr: Thresholds,
    /// The last actuation the firmware gave the timer (held while the core is halted).
    last: Actuation,
    /// Time of the first break action, s.
    pub first_break_s: Option<f64>,
}

impl Stage {
    /// The stage as the firmware leaves it after power-up at time `t`: comparators and DACs
    /// enabled, the breaks armed `settle_s` later.
    pub fn new(spec: StageSpec, t: f64) -> Stage {
        Stage {
            spec,
            cpu: Cpu::Running,
            armed: false,
            brk: false,
            brk2: false,
            chopper_on: false,
            enabled_at: t,
            glitch: None,
            thr: Thresholds::new(&spec, 1.0),
            last: Actuation::OFF,
            first_break_s: None,
        }
    }

    /// A comparator output pulse of `len_s` (enable transient, ringing); `bus` picks the bus
    /// comparator, else a phase comparator.
    pub fn glitch(&mut self, len_s: f64, bus: bool) {
        self.glitch = Some((len_s, bus));
    }

    /// The stage's rating and settings.
    pub fn spec(&self) -> &StageSpec {
        &self.spec
    }

    /// Every DAC threshold multiplied by `scale` (a wrong code), from now on.
    pub fn set_dac_scale(&mut self, scale: f64) {
        self.thr = Thresholds::new(&self.spec, scale);
    }

    /// The core stops now.
    pub fn halt(&mut self) {
        if self.cpu == Cpu::Running {
            self.cpu = Cpu::Halted;
        }
    }

    /// The watchdog resets the MCU at `t`: pins to their reset state until `t + boot_s`.
    pub fn reset(&mut self, t: f64) {
        self.cpu = Cpu::Reset {
            until_s: t + self.spec.boot_s,
        };
        self.armed = false;
        self.brk = false;
        self.brk2 = false;
        self.chopper_on = false;
        self.glitch = None;
    }

    /// Whether the core runs the firmware this period (at time `t`). Ends a reset whose boot
    /// time has passed: the caller then constructs a fresh controller (power-up), and the
    /// breaks are enabled again (armed `settle_s` later).
    pub fn cpu_runs(&mut self, t: f64) -> bool {
        if let Cpu::Reset { until_s } = self.cpu {
            if t >= until_s {
                self.cpu = Cpu::Running;
                self.enabled_at = t;
                return true;
            }
            return false;
        }
        self.cpu == Cpu::Running
    }

    /// Whether a reset has just ended (the caller must power the controller up).
    pub fn in_reset(&self) -> bool {
        matches!(self.cpu, Cpu::Reset { .. })
    }

    /// The comparators see the plant's true bus `v_bus` and phase currents `i` at time `t`
    /// (end of a period); latches the breaks and sets the chopper.
    pub fn observe(&mut self, t: f64, v_bus: f64, i: [f64; 3]) {
        let (s, thr) = (&self.spec, &self.thr);
        // Chopper comparator (not a break: no filter; its own hysteresis). An MCU comparator
        // is dead in reset, an external one is not.
        let in_reset = self.in_reset();
        let live = s.chopper == Chopper::External || !in_reset;
        self.chopper_on = live && v_bus > thr.chopper[self.chopper_on as usize];
        if in_reset {
            return;
        }
        if !self.armed && t >= self.enabled_at + s.settle_s {
            // Armed after settling, with the flags set by the enable transient cleared.
            self.armed = true;
            self.glitch = None;
        }
        let ov = v_bus > thr.ov_v;
        // One-sided: a phase current below −oc (`min` skips a NaN, as the comparison
        // would fail on it).
        let oc = -i[0].min(i[1]).min(i[2]) > thr.oc_a;
        // A real crossing lasts a whole period (≫ the filters); a glitch only its length.
        let (g_oc, g_ov) = match self.glitch.take() {
            Some((len, true)) => (false, len >= s.filter2_s),
            Some((len, false)) => (len >= s.filter_s, false),
            None => (false, false),
        };
        if self.armed {
            if (oc || g_oc) && !self.brk {
                self.brk = true;
                self.first_break_s.get_or_insert(t);
            }
            if (ov || g_ov) && !self.brk2 {
                self.brk2 = true;
                self.first_break_s.get_or_insert(t);
            }
        }
    }

    /// What reaches the gates in the next period, from the firmware's actuation `fw`
    /// (ignored unless the core runs): reset pins, then the breaks (BRK over BRK2), then the
    /// chopper.
    pub fn gate(&mut self, fw: &Actuation) -> Actuation {
        let mut out = match self.cpu {
            Cpu::Running => {
                self.last = *fw;
                *fw
            }
            Cpu::Halted => self.last,
            Cpu::Reset { .. } => Actuation::OFF,
        };
        if self.in_reset() {
            out.brake = self.spec.chopper == Chopper::External && self.chopper_on;
            return out;
        }
        if self.brk {
            out.enable = false;
        } else if self.brk2 {
            match self.spec.brk2 {
                Brk2Idle::Short => {
                    out.enable = true;
                    out.duties = [Duty::ZERO; 3];
                }
                Brk2Idle::Open => out.enable = false,
            }
        }
        if self.spec.chopper != Chopper::Firmware {
            out.brake |= self.chopper_on;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec() -> StageSpec {
        StageSpec::from_config(&Config::default(), 100.0)
    }

    #[test]
    fn thresholds_follow_the_configuration() {
        let c = Config::default();
        let s = spec();
        let range = c.adc_zero_code as f64 * c.amps_per_count as f64;
        assert!((s.oc_hw_a - (1.1 * c.i_trip_a as f64).min(0.95 * range)).abs() < 1e-9);
        assert!((s.oc_hw_a - 22.0).abs() < 1e-4, "the board's 22 A");
        assert!((s.ov_hw_v - 0.5 * (c.v_bus_ov as f64 + 100.0)).abs() < 1e-9);
    }

    #[test]
    fn breaks_act_whatever_the_firmware_commands() {
        let s = spec();
        let run = Actuation {
            enable: true,
            ..Actuation::OFF
        };
        let mut st = Stage::new(
            StageSpec {
                brk2: Brk2Idle::Short,
                ..s
            },
            0.0,
        );
        st.observe(1e-3, s.ov_hw_v + 1.0, [0.0; 3]);
        let g = st.gate(&run);
        assert!(g.enable && g.duties == [Duty::ZERO; 3], "BRK2 short");
        st.observe(1.5e-3, 0.0, [s.oc_hw_a + 1.0, 0.0, 0.0]);
        assert!(!st.brk, "one-sided: a positive current does not trip");
        st.observe(2e-3, 0.0, [-s.oc_hw_a - 1.0, 0.0, 0.0]);
        assert!(!st.gate(&run).enable, "BRK over BRK2: open");
        // Latched: the cause gone, still off.
        st.observe(3e-3, 0.0, [0.0; 3]);
        assert!(!st.gate(&run).enable);
    }

    #[test]
    fn filter_and_arming_reject_glitches() {
        let s = spec();
        let run = Actuation {
            enable: true,
            ..Actuation::OFF
        };
        // A long enable transient before arming: cleared at arming.
        let mut st = Stage::new(s, 0.0);
        st.glitch(5e-6, true);
        st.observe(s.settle_s * 0.5, 0.0, [0.0; 3]);
        st.observe(1e-3, 0.0, [0.0; 3]);
        assert!(!st.brk2 && st.gate(&run).duties != [Duty::ZERO; 3]);
        // Armed: a pulse shorter than the filter is ignored, a longer one trips.
        st.glitch(0.5 * s.filter2_s, true);
        st.observe(2e-3, 0.0, [0.0; 3]);
        assert!(!st.brk2);
        st.glitch(2.0 * s.filter2_s, true);
        st.observe(3e-3, 0.0, [0.0; 3]);
        assert!(st.brk2);
    }

    #[test]
    fn halted_core_keeps_its_last_output_and_reset_opens_everything() {
        let s = spec();
        let run = Actuation {
            enable: true,
            brake: true,
            ..Actuation::OFF
        };
        let mut st = Stage::new(s, 0.0);
        st.gate(&run);
        st.halt();
        assert!(st.gate(&Actuation::OFF).enable, "timer keeps running");
        st.observe(1e-3, s.brake_on_v + 1.0, [0.0; 3]);
        assert!(
            st.gate(&Actuation::OFF).brake,
            "chopper from its comparator"
        );
        st.reset(2e-3);
        st.observe(2.5e-3, s.v_abs_max, [0.0; 3]);
        let g = st.gate(&run);
        assert!(!g.enable && !st.brk2, "reset: all off, nothing armed");
        assert!(!g.brake, "the MCU's comparator is dead in reset");
        let mut ext = Stage::new(
            StageSpec {
                chopper: Chopper::External,
                ..s
            },
            0.0,
        );
        ext.reset(2e-3);
        ext.observe(2.6e-3, s.v_abs_max, [0.0; 3]);
        assert!(ext.gate(&run).brake, "an external one is not");
        assert!(!st.cpu_runs(2e-3 + 0.5 * s.boot_s));
        assert!(st.cpu_runs(2e-3 + s.boot_s));
    }
}
