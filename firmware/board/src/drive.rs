//! The current loop: the ADC end-of-injected-sequence interrupt (highest priority) runs one
//! `regen_fw::period::Period::run` per PWM period against [`BoardIo`], the board's `DriveIo`
//! and `PeriodHw` (everything at the PWM rate around the step is in that routine, tested on
//! the host; this file is only the peripherals and the sharing).
//!
//! Sharing with the thread-mode tasks:
//! * The controller and the hardware handles live in [`LOOP`], a critical-section mutex. The
//!   interrupt is the highest-priority code, so its own critical section costs nothing; a task
//!   holds the lock only to copy the controller (880 bytes, ≈ 2 µs) — it never runs console
//!   commands inside it.
//! * Console commands run on a copy of the controller; what they changed (configuration
//!   compiled in the task, mode, cleared fault) is applied to the loop's controller by the
//!   task itself ([`apply`]), between two periods, right after one: no step serves a change
//!   and a step never sees half of one.
//! * The period's counters and energy sum live in [`LoopState`]; tasks copy them under the
//!   same lock ([`counters`]).

use core::cell::RefCell;

use critical_section::Mutex;
use embassy_stm32::adc::InjectedAdc;
use embassy_stm32::pac;
use embassy_stm32::peripherals::TIM2;
use embassy_stm32::peripherals::{ADC1, ADC2};
use embassy_stm32::timer::qei::Qei;
use embassy_time::{Duration, Instant};
use regen_fw::capture::{CapPort, Capture, Settings, Status};
use regen_fw::config::{Config, Gains};
use regen_fw::control::{Controller, Fault};
use regen_fw::io::{Actuation, DriveIo, HwThresholds, RawSample};
use regen_fw::period::{Pending, Period, PeriodHw, Slot};

use crate::board;
use crate::pwm::Pwm;
use crate::trip;

/// The board's hardware boundary.
pub struct BoardIo {
    /// ADC1 injected sequence [I_a, I_c].
    pub adc1: InjectedAdc<'static, ADC1, 2>,
    /// ADC2 injected sequence [I_b, V_bus] (its end of sequence raises the interrupt).
    pub adc2: InjectedAdc<'static, ADC2, 2>,
    pub qei: Qei<'static, TIM2>,
    pub pwm: Pwm,
    /// The chopper comparator's threshold code, and whether the software forces it on.
    pub chop: u16,
    pub brake: bool,
    /// The current offsets programmed into the converters (`Controller::adc_offsets` once
    /// written, see [`set_adc_offsets`]).
    pub offsets: [i32; 3],
}

impl DriveIo for BoardIo {
    fn sample(&mut self) -> RawSample {
        // ADC2's sequence is the longer one (47.5-clock bus-voltage sample), so ADC1's has
        // finished when ADC2's interrupt fires; the reads also clear both JEOS flags.
        let [ia, ic] = self.adc1.read_injected_samples();
        let [ib, vbus] = self.adc2.read_injected_samples();
        RawSample {
            i_abc: [ia, ib, ic],
            v_bus: vbus,
            encoder: self.qei.count(),
        }
    }

    fn apply(&mut self, out: &Actuation) {
        self.pwm.write(&out.duties, out.enable);
        // The software's brake command overrides the chopper's comparator (`trip.rs`).
        self.brake = out.brake;
        trip::set_chopper(self.chop, out.brake);
    }

    fn now_us(&self) -> u64 {
        embassy_time::Instant::now().as_micros()
    }
}

impl PeriodHw for BoardIo {
    /// The next sequence already finished (its flag is set again) before this period's work
    /// is done.
    #[inline(always)]
    fn overran(&mut self) -> bool {
        pac::ADC2.isr().read().jeos()
    }

    #[inline(always)]
    fn tripped(&mut self) -> Option<Fault> {
        trip::take_trip()
    }

    /// The comparators' thresholds follow the configuration; `pwm_hz` is an idle-only
    /// parameter (the bridge is off when it changes).
    fn installed(&mut self, cfg: &Config, pwm_hz_changed: bool) {
        let t = HwThresholds::of(cfg);
        self.chop = t.chop;
        trip::set_thresholds(&t, self.brake);
        if pwm_hz_changed {
            if let Some(arr) = board::arr_for(cfg.pwm_hz) {
                self.pwm.set_arr(arr);
            }
        }
    }
}

/// Everything the interrupt owns.
pub struct LoopState {
    pub ctl: Controller,
    pub per: Period,
    pub io: BoardIo,
}

pub static LOOP: Mutex<RefCell<Slot<LoopState>>> = Mutex::new(RefCell::new(Slot::Empty));

/// Samples of the board's capture ring (`regen_fw::capture`): 1,024 × 4 channels × 4 bytes.
pub const CAP_SAMPLES: usize = regen_fw::capture::SAMPLES;

/// The capture the period records into (zero-initialised, in `.bss`). The console task
/// reaches it through [`BoardCap`], locking the loop for each call.
pub static CAP: Mutex<RefCell<Capture<CAP_SAMPLES>>> = Mutex::new(RefCell::new(Capture::new()));

/// The console's way to [`CAP`] (`regen_fw::capture::CapPort`): each call in a critical
/// section of its own (a sample's four codes or the settings: a few dozen cycles), so a
/// `cap dump` reads the ready ring line by line while the loop runs (a ready capture is not
/// written).
pub struct BoardCap;

impl CapPort for BoardCap {
    fn status(&self) -> Status {
        critical_section::with(|cs| CAP.borrow_ref(cs).status())
    }
    fn arm(&mut self, set: &Settings, dt_s: f32, g: &Gains) {
        critical_section::with(|cs| CAP.borrow_ref_mut(cs).arm(set, dt_s, g))
    }
    fn trigger_now(&mut self) -> bool {
        critical_section::with(|cs| CAP.borrow_ref_mut(cs).trigger_now())
    }
    fn stop(&mut self) {
        critical_section::with(|cs| CAP.borrow_ref_mut(cs).stop())
    }
    fn sample(&self, k: u32) -> [i16; regen_fw::capture::CH_MAX] {
        critical_section::with(|cs| CAP.borrow_ref(cs).sample(k))
    }
}

/// Periods the loop has run; `None` before it starts.
fn periods() -> Option<u32> {
    critical_section::with(|cs| LOOP.borrow_ref(cs).get().map(|s| s.per.periods))
}

/// Apply a task's changes to the loop (`regen_fw::period::Period::apply`: clear, compiled
/// configuration, mode) between two periods: as soon as a period's interrupt is seen to have
/// run, with the loop locked for the application only. Its longest part, a configuration's
/// install, is 1,217 instructions as the board builds it (≈ 9 µs at 170 MHz, `run.sh`);
/// started right after a period it ends ≈ 30 µs before the next sample. Should another
/// interrupt or a late start make the current-loop interrupt wait for it, that interrupt is
/// delayed by at most the application and does the same: the ADC's injected results stay in
/// their registers until the next trigger, a period later, and the duties it writes are
/// preloaded and taken at the next update event, which is that next trigger (`pwm.rs`), so a
/// delay of 9 µs plus its own work (≈ 3 µs, ≈ 7 µs with supervision) changes no output and
/// no sampling instant. Does nothing before the loop starts. The mailbox is left empty.
pub fn apply(mail: &mut Pending) {
    let Some(p0) = periods() else {
        return;
    };
    // At most two periods at the slowest PWM (5 kHz): a stopped loop is no reason to wait.
    let t0 = Instant::now();
    while periods() == Some(p0) && t0.elapsed() < Duration::from_micros(400) {}
    critical_section::with(|cs| {
        if let Some(st) = LOOP.borrow_ref_mut(cs).get_mut() {
            st.per.apply(&mut st.ctl, mail, &mut st.io);
        }
    });
}

/// Copy of the controller and of the period's counters and energy sum for a task (briefly
/// locks out the interrupt: ≈ 2 µs); `None` before the loop starts.
pub fn snapshot() -> Option<(Controller, Period)> {
    critical_section::with(|cs| LOOP.borrow_ref(cs).get().map(|s| (s.ctl.clone(), s.per)))
}

/// The current-loop interrupt body (called from the `ADC1_2` handler).
#[inline(always)]
pub fn on_sample() {
    critical_section::with(|cs| {
        let mut guard = LOOP.borrow_ref_mut(cs);
        // The interrupt is enabled only once the loop state is in place (`main.rs`), and it
        // is never taken out: this `else` cannot run.
        let Some(st) = guard.get_mut() else {
            return;
        };
        st.per
            .run(&mut st.ctl, &mut st.io, &mut CAP.borrow_ref_mut(cs));
        // Calibrated offsets are removed by the converters, as the simulator's sample does
        // (`Sim::set_adc_offsets`): written here, right after a sample, the period the
        // calibration ends (the next trigger is a period away).
        let o = st.ctl.adc_offsets();
        if o != st.io.offsets && set_adc_offsets(o) {
            st.io.offsets = o;
        }
    });
}

/// Program the converters' offset registers (RM0440 ADC_OFRy) so that each phase's code
/// reads `raw − o[k]`: OFR1 of ADC1 for I_a and OFR2 for I_c, OFR1 of ADC2 for I_b, each on
/// the channel its injected rank converts (read back from JSQR), saturated to 0 … 4095
/// (SATEN) as the simulator clamps its codes. OFRy may only be written with no injected
/// conversion running: the injected conversions are stopped (JADSTP), written, and started
/// again (JADSTART) for the next trigger. `false` (nothing written) if a stop did not
/// complete within ≈ 2 µs; the caller tries again the next period.
#[inline(never)]
fn set_adc_offsets(o: [i32; 3]) -> bool {
    use embassy_stm32::pac::adc::vals::Adstp;
    let adcs = [pac::ADC1, pac::ADC2];
    for adc in adcs {
        adc.cr().modify(|w| w.set_jadstp(Adstp::STOP));
    }
    for adc in adcs {
        let mut n = 0;
        while adc.cr().read().jadstart() {
            n += 1;
            if n > 256 {
                return false;
            }
        }
    }
    // Each written with constant register indices (no index check left in the image).
    #[inline(always)]
    fn write(adc: pac::adc::Adc, rank: usize, reg: usize, v: i32) {
        let ch = adc.jsqr().read().jsq(rank);
        adc.ofr(reg).write(|w| {
            w.set_offset(v.unsigned_abs().min(0xFFF) as u16);
            w.set_offsetpos(v < 0);
            w.set_saten(true);
            w.set_offset1_ch(ch);
            w.set_offset_en(v != 0);
        });
    }
    write(pac::ADC1, 0, 0, o[0]); // I_a: ADC1 rank 1
    write(pac::ADC2, 0, 0, o[1]); // I_b: ADC2 rank 1
    write(pac::ADC1, 1, 1, o[2]); // I_c: ADC1 rank 2
    for adc in adcs {
        adc.cr().modify(|w| w.set_jadstart(true));
    }
    true
}
