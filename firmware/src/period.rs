//! The current loop's period: everything that runs at the PWM rate around
//! [`Controller::step`], written once for the board's ADC interrupt and the simulator.
//!
//! One period ([`Period::run`]):
//! 1. sample ([`DriveIo::sample`]); [`Period::step`]: add the last period's electrical power
//!    to the exact energy sum, then step up to the outputs ([`Controller::step_outputs`]);
//! 2. actuate ([`DriveIo::apply`]): the duties are written before any slower work;
//! 3. [`Period::finish`]: a fault latch the step began finished ([`Controller::complete_latch`]:
//!    its record and slow terms; the outputs just written are already the safe state's), a
//!    hardware trip latched as a fault ([`PeriodHw::tripped`]), protection supervision on
//!    every `supervise_every()`-th period (the first period included), the capture's sample
//!    ([`crate::capture`]), the period count, and
//!    the overrun check last ([`PeriodHw::overran`]: the next sample was ready before this
//!    period's work was done), which the controller counts against `overrun_max` and trips on
//!    at its next supervision.
//!
//! The console's changes ([`Pending`]: a fault to clear, a configuration compiled in the
//! console's task by [`Controller::compile`], a mode) are not the period's work: they are
//! applied between two periods by [`Period::apply`], with the loop locked (the board's
//! console task, right after a period; the simulator, after [`Period::finish`]), so no step
//! serves them and a step never sees half a change.
//!
//! The simulator calls [`Period::step`] and [`Period::finish`] itself, with its fault-injection
//! hooks on the sample and the actuation in between; a test in `hal-sim` (`sim.rs`,
//! `split_step_is_exactly_one_step`) pins that sequence to [`Period::run`].

use crate::capture::Capture;
use crate::config::Config;
use crate::control::{Compiled, Controller, Fault, Mode};
use crate::io::{Actuation, DriveIo, RawSample};

/// What the period needs from the hardware besides [`DriveIo`].
pub trait PeriodHw {
    /// A trip the hardware took since the last call (comparator → timer break), if any;
    /// the flag is acknowledged by the call.
    fn tripped(&mut self) -> Option<Fault> {
        None
    }
    /// The next period's sample is already complete: this period's work ended late.
    fn overran(&mut self) -> bool {
        false
    }
    /// A new configuration is in force (the hardware thresholds follow it);
    /// `pwm_hz_changed`: reprogram the timer (an idle-only parameter).
    fn installed(&mut self, _cfg: &Config, _pwm_hz_changed: bool) {}
}

/// An optional value whose empty state is all zero bytes (`repr(C, u8)`: tag 0, no niche), so
/// a static holding one is zero-initialised (`.bss`) and costs no flash. An `Option<T>` keeps
/// `None` in a niche of `T` (an enum or `bool` value no `T` has), which is not zero: on the
/// board an `Option` of the loop state and of the mailbox's configuration put 1.6 KB of
/// initial values in flash (`.data`).
#[repr(C, u8)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Slot<T> {
    #[default]
    Empty,
    Full(T),
}

impl<T> Slot<T> {
    pub fn is_empty(&self) -> bool {
        matches!(self, Slot::Empty)
    }
    pub fn get(&self) -> Option<&T> {
        match self {
            Slot::Full(v) => Some(v),
            Slot::Empty => None,
        }
    }
    pub fn get_mut(&mut self) -> Option<&mut T> {
        match self {
            Slot::Full(v) => Some(v),
            Slot::Empty => None,
        }
    }
}

impl<T: Copy> Slot<T> {
    pub fn value(&self) -> Option<T> {
        self.get().copied()
    }
    /// `self` if full, else `other` (as `Option::or`).
    pub fn or(self, other: Slot<T>) -> Slot<T> {
        if self.is_empty() {
            other
        } else {
            self
        }
    }
}

impl<T> From<Option<T>> for Slot<T> {
    fn from(o: Option<T>) -> Self {
        match o {
            Some(v) => Slot::Full(v),
            None => Slot::Empty,
        }
    }
}

/// Changes the console (or the supervision's alignment retry) makes, applied between two
/// periods by [`Period::apply`].
#[derive(Clone, Copy, Debug, Default)]
pub struct Pending {
    /// Clear this fault (only if it is still the latched one).
    pub clear: Slot<Fault>,
    /// A configuration compiled against the loop's (its law parameters included).
    pub cfg: Slot<Compiled>,
    pub mode: Slot<Mode>,
}

impl Pending {
    pub const EMPTY: Pending = Pending {
        clear: Slot::Empty,
        cfg: Slot::Empty,
        mode: Slot::Empty,
    };

    pub fn is_empty(&self) -> bool {
        self.clear.is_empty() && self.cfg.is_empty() && self.mode.is_empty()
    }
}

/// The period's own state: supervision countdown, exact energy sum and counters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Period {
    /// Periods until the next supervision (0: this one; `supervise_every()` is at most 100,
    /// `pwm_hz` ≤ 100 kHz: a `u16`, so that `summed` fits beside it in the struct's 24 bytes).
    countdown: u16,
    /// Σ `p_elec` over all periods but the last, Q16.16 watt·periods (saturating; 2^47
    /// W·periods); the last one's is still the controller's ([`Period::energy_bits`]) unless
    /// `summed`.
    energy: i64,
    /// The last period's power is in `energy` already: [`Period::finish`] computed it for an
    /// active capture and added it there.
    summed: bool,
    /// Periods run (wraps).
    pub periods: u32,
    /// Periods whose work ended after the next sample was ready.
    pub overruns: u32,
    /// Posted mode changes the controller refused (a fault latched in between).
    pub mode_refused: u32,
}

impl Period {
    pub const NEW: Period = Period {
        countdown: 0,
        energy: 0,
        summed: false,
        periods: 0,
        overruns: 0,
        mode_refused: 0,
    };

    /// One whole period against the hardware (the board's interrupt body).
    #[inline(always)]
    pub fn run<IO: DriveIo + PeriodHw, const N: usize>(
        &mut self,
        ctl: &mut Controller,
        io: &mut IO,
        cap: &mut Capture<N>,
    ) -> Actuation {
        let s = io.sample();
        let a = self.step(ctl, &s);
        io.apply(&a);
        self.finish(ctl, io, cap);
        a
    }

    /// The energy sum and the step up to its outputs. The sum takes the last period's power
    /// (its step's record, [`Controller::p_elec`]) before this period's step, whose inputs are
    /// long known by then; added after the step, it would wait for the step's last values
    /// (the PI's voltages), and hold up the work behind it (in the simulator, the next
    /// period's plant: the closed loop 3 % slower, `docs/simulator.md`, "Speed"). The same sum:
    /// [`Period::energy_bits`] adds the last period's power when read. While a capture is
    /// active, [`Period::finish`] has added it already (`summed`).
    #[inline(always)]
    pub fn step(&mut self, ctl: &mut Controller, s: &RawSample) -> Actuation {
        self.energy = self.energy_bits(ctl);
        self.summed = false;
        ctl.step_outputs(s)
    }

    /// The controller `ctl` is about to be replaced (a reboot of the MCU's model with the
    /// period kept): its last period's power goes into the sum now, since the next step adds
    /// the new controller's (nothing yet: no step, no power).
    pub fn bank(&mut self, ctl: &Controller) {
        self.energy = self.energy_bits(ctl);
        self.summed = true;
    }

    /// After the actuation: the step's latch finished, hardware trip, supervision, the
    /// capture's sample ([`Capture::record`]: after the latches, so a fault latched in this
    /// period is in this period's sample), counters, overrun. While a capture is armed or
    /// triggered it gets the power, the one value it may record that the step does not store,
    /// from here: the energy sum's computation of this period's power, done and added now
    /// instead of at the next period's start (the same value: nothing between the two changes
    /// the step's record), so the period computes it once either way.
    #[inline(always)]
    pub fn finish<H: PeriodHw, const N: usize>(
        &mut self,
        ctl: &mut Controller,
        hw: &mut H,
        cap: &mut Capture<N>,
    ) {
        ctl.complete_latch();
        if let Some(f) = hw.tripped() {
            ctl.hardware_trip(f);
        }
        if self.countdown == 0 {
            ctl.supervise();
            self.countdown = ctl.supervise_every().saturating_sub(1).min(u16::MAX as u32) as u16;
        } else {
            self.countdown -= 1;
        }
        if cap.active() {
            let p = ctl.p_elec().to_bits();
            self.energy = self.energy.saturating_add(p as i64);
            self.summed = true;
            cap.record(ctl, p);
        }
        self.periods = self.periods.wrapping_add(1);
        if hw.overran() {
            self.overruns = self.overruns.wrapping_add(1);
            ctl.report_overrun();
        }
    }

    /// The console's changes, in the order clear, configuration, mode; the mailbox is left
    /// empty. Call it between two periods with the loop locked: on the board the console's
    /// task, right after a period's interrupt (`firmware/board/src/drive.rs`, `apply`); in
    /// the simulator after [`Period::finish`]. A configuration is installed with fixed-size
    /// copies and the slow terms' refresh ([`Controller::install`], the same work whatever
    /// changed: 1,217 instructions as the board builds it, ≈ 9 µs, `docs/m4check.md`).
    /// The empty mailbox's check is inline (the simulator calls this every period), the
    /// changes out of line.
    #[inline(always)]
    pub fn apply<H: PeriodHw>(&mut self, ctl: &mut Controller, mail: &mut Pending, hw: &mut H) {
        if !mail.is_empty() {
            self.apply_changes(ctl, mail, hw);
        }
    }

    #[inline(never)]
    fn apply_changes<H: PeriodHw>(&mut self, ctl: &mut Controller, mail: &mut Pending, hw: &mut H) {
        if let Slot::Full(f) = mail.clear {
            // The console's copy checked the cause is gone; if it came back since, the
            // controller refuses and the fault stays latched (the console shows it).
            if ctl.fault() == Some(f) {
                let _ = ctl.clear_fault();
            }
        }
        if let Slot::Full(c) = &mail.cfg {
            let old_hz = ctl.config().pwm_hz;
            ctl.install(c);
            hw.installed(c.config(), c.config().pwm_hz != old_hz);
        }
        if let Slot::Full(m) = mail.mode {
            if ctl.set_mode(m).is_err() {
                self.mode_refused = self.mode_refused.wrapping_add(1);
            }
        }
        mail.clear = Slot::Empty;
        mail.cfg = Slot::Empty;
        mail.mode = Slot::Empty;
    }

    /// Σ `p_elec` over all periods, Q16.16 watt·periods: the sum and the last period's power,
    /// still in `ctl`, the controller this period steps.
    #[inline(always)]
    pub fn energy_bits(&self, ctl: &Controller) -> i64 {
        if self.summed {
            return self.energy;
        }
        self.energy.saturating_add(ctl.p_elec().to_bits() as i64)
    }

    /// Energy since the start, J, for a period `ts` in seconds (`ctl` as in
    /// [`Period::energy_bits`]).
    pub fn energy_j(&self, ctl: &Controller, ts: f32) -> f32 {
        self.energy_bits(ctl) as f32 / 65_536.0 * ts
    }

    /// Periods until the next supervision (0: the next period supervises).
    pub fn countdown(&self) -> u32 {
        self.countdown as u32
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::vec::Vec;

    /// A drive whose encoder turns at a fixed rate and whose current codes follow a fixed
    /// pattern, recording what the period does to the hardware.
    struct Mock {
        n: u32,
        counts_per_period: u16,
        /// `overran()` answers true on periods where `n % every == phase` (every = 0: never).
        overrun_every: u32,
        /// `tripped()` reports this once, at the end of this period.
        trip_at: Option<(u32, Fault)>,
        overran_calls: u32,
        applied: Vec<Actuation>,
        pwm: Vec<f32>,
    }

    impl Mock {
        fn new(counts_per_period: u16, overrun_every: u32) -> Mock {
            Mock {
                n: 0,
                counts_per_period,
                overrun_every,
                overran_calls: 0,
                trip_at: None,
                applied: Vec::new(),
                pwm: Vec::new(),
            }
        }
    }

    impl DriveIo for Mock {
        fn sample(&mut self) -> RawSample {
            let k = self.n as i32;
            // Codes around the zero code (a few counts of ripple): currents the PI answers.
            let w = |p: i32| (2048 + ((k * 7 + p) % 23) - 11) as u16;
            RawSample {
                i_abc: [w(0), w(8), w(16)],
                v_bus: 2457, // 72 V at the default 0.0293 V/count
                encoder: (self.n as u16).wrapping_mul(self.counts_per_period),
            }
        }
        fn apply(&mut self, out: &Actuation) {
            self.applied.push(*out);
            self.n += 1;
        }
        fn now_us(&self) -> u64 {
            self.n as u64 * 50
        }
    }

    impl PeriodHw for Mock {
        fn tripped(&mut self) -> Option<Fault> {
            match self.trip_at {
                Some((k, f)) if k + 1 == self.n => Some(f),
                _ => None,
            }
        }
        fn overran(&mut self) -> bool {
            self.overran_calls += 1;
            self.overrun_every != 0 && (self.n - 1).is_multiple_of(self.overrun_every)
        }
        fn installed(&mut self, cfg: &Config, pwm_hz_changed: bool) {
            if pwm_hz_changed {
                self.pwm.push(cfg.pwm_hz);
            }
        }
    }

    /// One period, then the mailbox applied between it and the next, as the board's console
    /// task and the simulator do.
    fn run(per: &mut Period, ctl: &mut Controller, mail: &mut Pending, io: &mut Mock) {
        per.run(ctl, io, &mut crate::capture::Capture::<4>::new());
        per.apply(ctl, mail, io);
    }

    /// A running controller against the mock, whose currents follow no machine: the angle
    /// plausibility check (which would rightly find its emf off the q axis) is set beyond any
    /// emf the mock's speed gives, so these tests see the period's mechanics only.
    fn running() -> Controller {
        let cfg = Config {
            angle_emf_min_v: 2_000.0,
            ..Config::default()
        };
        let mut ctl = Controller::new(&cfg).unwrap();
        ctl.set_mode(Mode::Run).unwrap();
        ctl
    }

    /// An overrun on every period: the controller's leaky bucket (+overruns −1 per
    /// supervision tick, trip above `overrun_max`) must trip at the first tick where
    /// (N−1)·k > overrun_max, N = periods per tick, k = ticks after the first — which can only
    /// happen at that exact period if supervision runs on periods 0, N, 2N, … and the overruns
    /// reach the controller.
    #[test]
    fn overruns_trip_at_the_supervision_cadence() {
        let mut ctl = running();
        let n = ctl.supervise_every();
        assert_eq!(n, 20, "20 kHz / 1 kHz");
        let m = Config::default().overrun_max as u32;
        // Ticks at periods 0, N, 2N…; the tick at period kN sees N overruns (those of periods
        // (k−1)N … kN−1), minus one: bucket = k(N−1).
        let k = m / (n - 1) + 1;
        let trip_period = k * n;
        let (mut per, mut mail, mut io) = (Period::NEW, Pending::EMPTY, Mock::new(3, 1));
        for p in 0..=trip_period {
            assert_eq!(ctl.fault(), None, "tripped early, before period {p}");
            run(&mut per, &mut ctl, &mut mail, &mut io);
        }
        assert_eq!(ctl.fault(), Some(Fault::LoopOverrun));
        assert_eq!(per.overruns, trip_period + 1);
        assert_eq!(per.periods, trip_period + 1);
        assert_eq!(io.overran_calls, trip_period + 1);
    }

    /// One overrun per supervision tick is what the bucket tolerates: it never trips.
    #[test]
    fn one_overrun_per_tick_does_not_trip() {
        let mut ctl = running();
        let n = ctl.supervise_every();
        let (mut per, mut mail, mut io) = (Period::NEW, Pending::EMPTY, Mock::new(3, n));
        for _ in 0..100 * n {
            run(&mut per, &mut ctl, &mut mail, &mut io);
        }
        assert_eq!(ctl.fault(), None);
        assert_eq!(per.overruns, 100);
    }

    /// The sum is exact: every period's `p_elec` (Q16.16) added as an integer, compared with
    /// an f64 sum of the telemetry read after each period (exact too: integers < 2^53).
    #[test]
    fn energy_sum_is_exact() {
        use crate::capture::{CapPort, Settings, Trigger};
        let mut ctl = running();
        let (mut per, mut mail, mut io) = (Period::NEW, Pending::EMPTY, Mock::new(5, 0));
        let mut sum = 0.0f64;
        let mut nonzero = 0;
        // A capture armed (never triggered) over the middle third: the period adds each
        // period's power at its end then, at the next period's start otherwise; the sum must
        // not see the difference.
        let mut cap = crate::capture::Capture::<4>::new();
        let set = Settings {
            ch: [4, 12, 0, 0],
            n_ch: 2,
            div: 3,
            pre_pct: 50,
            trig: Trigger::Cmd,
        };
        for k in 0..20_000 {
            if k == 7_000 {
                cap.arm(&set, 1.5e-4, ctl.gains());
            }
            if k == 14_000 {
                assert!(cap.active());
                cap.stop();
            }
            per.run(&mut ctl, &mut io, &mut cap);
            per.apply(&mut ctl, &mut mail, &mut io);
            let p = ctl.telemetry().p_elec.to_num::<f64>();
            nonzero += (p != 0.0) as u32;
            sum += p * 65_536.0;
        }
        assert!(
            nonzero > 10_000,
            "the run must carry power ({nonzero} periods)"
        );
        assert_eq!(per.energy_bits(&ctl) as f64, sum);
        let ts = ctl.config().ts();
        let j = sum / 65_536.0 * ts as f64;
        // energy_j: one rounding to f32 of the sum and one of the product: ≤ 2·2^−24.
        assert!((per.energy_j(&ctl, ts) as f64 / j - 1.0).abs() <= 2.0 * f32::EPSILON as f64 / 2.0);
    }

    /// A configuration, a mode and a fault clearance posted in the mailbox take effect after
    /// the step of the period they were posted in, never inside it: the outputs equal a
    /// controller stepped, then changed with `set_config`/`set_mode` between the two steps.
    #[test]
    fn mailbox_applies_between_steps_only() {
        let mut a = running();
        let mut b = a.clone();
        let (mut per, mut mail, mut io) = (Period::NEW, Pending::EMPTY, Mock::new(7, 0));
        let mut refio = Mock::new(7, 0);
        for _ in 0..400 {
            run(&mut per, &mut a, &mut mail, &mut io);
            let s = refio.sample();
            let o = b.step(&s);
            refio.apply(&o);
        }
        let mut cfg = *a.config();
        cfg.r_load_ohm *= 0.5; // a law parameter: the law is rebuilt
        cfg.current_bw_hz *= 0.8; // a gain
        let c = a.compile(&cfg).unwrap();
        mail.cfg = Slot::Full(c);
        mail.mode = Slot::Full(Mode::Run);
        assert_eq!(a.config().r_load_ohm, b.config().r_load_ohm);
        // The period it was posted in steps with the old configuration …
        run(&mut per, &mut a, &mut mail, &mut io);
        let s = refio.sample();
        let o = b.step(&s);
        refio.apply(&o);
        assert_eq!(io.applied.last(), refio.applied.last());
        assert!(mail.is_empty());
        assert_eq!(a.config().r_load_ohm, cfg.r_load_ohm);
        // … and the change is in force from the next step on, as `set_config` between them.
        b.set_config(&cfg).unwrap();
        b.set_mode(Mode::Run).unwrap();
        for _ in 0..400 {
            run(&mut per, &mut a, &mut mail, &mut io);
            let s = refio.sample();
            let o = b.step(&s);
            refio.apply(&o);
        }
        assert_eq!(io.applied, refio.applied);
        assert!(
            io.pwm.is_empty(),
            "pwm_hz unchanged: the timer is left alone"
        );
    }

    /// A PWM-frequency change reaches the timer once, with the new value.
    #[test]
    fn pwm_change_reprograms_the_timer_once() {
        let mut ctl = Controller::new(&Config::default()).unwrap();
        let (mut per, mut mail, mut io) = (Period::NEW, Pending::EMPTY, Mock::new(0, 0));
        let mut cfg = *ctl.config();
        cfg.pwm_hz = 16_000.0;
        mail.cfg = Slot::Full(ctl.compile(&cfg).unwrap());
        for _ in 0..3 {
            run(&mut per, &mut ctl, &mut mail, &mut io);
        }
        assert_eq!(io.pwm, [16_000.0]);
        assert_eq!(ctl.supervise_every(), 16);
    }

    /// A mode the controller refuses (a fault latched before the mailbox was applied) is
    /// counted, and the fault stays.
    #[test]
    fn refused_mode_is_counted() {
        let mut ctl = running();
        let (mut per, mut mail, mut io) = (Period::NEW, Pending::EMPTY, Mock::new(3, 1));
        while ctl.fault().is_none() {
            run(&mut per, &mut ctl, &mut mail, &mut io);
        }
        let f = ctl.fault();
        mail.mode = Slot::Full(Mode::Run);
        run(&mut per, &mut ctl, &mut mail, &mut io);
        assert_eq!(per.mode_refused, 1);
        assert_eq!(ctl.fault(), f);
    }

    /// An over-current the step finds: the period it is found in already writes the safe
    /// state (bridge open: the over-current's), and by the end of that period (after the
    /// actuation) the fault is recorded with the snapshot as the step saw it: this period's
    /// phase codes, the last period's d/q currents, the mode it found (Run).
    #[test]
    fn step_fault_is_safe_in_its_period_and_recorded_by_its_end() {
        let mut ctl = running();
        let (mut per, mut mail, mut io) = (Period::NEW, Pending::EMPTY, Mock::new(7, 0));
        for _ in 0..300 {
            run(&mut per, &mut ctl, &mut mail, &mut io);
        }
        let last = ctl.telemetry();
        let mut s = io.sample();
        // Full scale on every phase (whichever two the shunt rule reads): 2,047 codes above
        // the zero code, 24.99 A at 50/4096 A per code, against the 20 A trip.
        s.i_abc = [4095; 3];
        let a = per.step(&mut ctl, &s);
        assert_eq!(ctl.fault(), Some(Fault::OverCurrent));
        assert_eq!(ctl.mode(), Mode::Idle);
        assert!(
            !a.enable,
            "the bridge opens in the period the fault is found"
        );
        assert!(
            ctl.protection().record().is_none(),
            "the record is written after the actuation"
        );
        io.apply(&a);
        per.finish(&mut ctl, &mut io, &mut crate::capture::Capture::<4>::new());
        let r = ctl
            .protection()
            .record()
            .expect("recorded by the period's end");
        assert_eq!(
            (r.fault, r.later, r.snap.mode),
            (Fault::OverCurrent, 0, Mode::Run)
        );
        let cfg = Config::default();
        let amps = (4095.0 - cfg.adc_zero_code as f64) * cfg.amps_per_count as f64;
        for i in r.snap.i_abc {
            // The gain's rounding: relative 2^-24 of 25 A, plus one LSB.
            assert!((i.to_num::<f64>() - amps).abs() < 1e-4, "{i} A vs {amps} A");
        }
        assert_eq!(r.snap.i_dq, last.i_dq);
    }

    /// A hardware trip reported at the end of period k latches its fault there: period k
    /// ran as commanded, period k + 1 opens the bridge.
    #[test]
    fn hardware_trip_latches_and_opens() {
        let mut ctl = running();
        let (mut per, mut mail, mut io) = (Period::NEW, Pending::EMPTY, Mock::new(7, 0));
        io.trip_at = Some((50, Fault::OverCurrent));
        for _ in 0..52 {
            run(&mut per, &mut ctl, &mut mail, &mut io);
        }
        assert!(io.applied[50].enable);
        assert!(!io.applied[51].enable);
        assert_eq!(ctl.fault(), Some(Fault::OverCurrent));
        assert_eq!(ctl.mode(), Fault::OverCurrent.safe_mode());
    }
}
