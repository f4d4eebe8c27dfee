//! The current loop: the ADC end-of-injected-sequence interrupt (highest priority) runs one
//! `regen_fw::io::run_period` per PWM period against [`BoardIo`], the board's `DriveIo`.
//!
//! Sharing with the thread-mode tasks:
//! * The controller and the hardware handles live in [`LOOP`], a critical-section mutex. The
//!   interrupt is the highest-priority code, so its own critical section costs nothing; a task
//!   holds the lock only to copy the controller (880 bytes, ≈ 2 µs) — it never runs console
//!   commands inside it.
//! * Console commands run on a copy of the controller; what they changed (configuration, mode,
//!   cleared fault) is posted to [`PENDING`] and applied by the interrupt right after its next
//!   step, so parameters change between steps only and a step never sees half a change.
//! * Counters ([`PERIODS`], [`OVERRUNS`]) are atomics read by the supervision task.

use core::cell::RefCell;
use core::sync::atomic::{AtomicU32, Ordering};

use critical_section::Mutex;
use embassy_stm32::adc::InjectedAdc;
use embassy_stm32::gpio::Output;
use embassy_stm32::pac;
use embassy_stm32::peripherals::TIM2;
use embassy_stm32::peripherals::{ADC1, ADC2};
use embassy_stm32::timer::qei::Qei;
use regen_fw::config::Config;
use regen_fw::control::{Controller, Fault, Mode};
use regen_fw::io::{run_period, Actuation, DriveIo, RawSample};

use crate::board;
use crate::pwm::Pwm;

/// The board's hardware boundary.
pub struct BoardIo {
    /// ADC1 injected sequence [I_a, I_c].
    pub adc1: InjectedAdc<'static, ADC1, 2>,
    /// ADC2 injected sequence [I_b, V_bus] (its end of sequence raises the interrupt).
    pub adc2: InjectedAdc<'static, ADC2, 2>,
    pub qei: Qei<'static, TIM2>,
    pub pwm: Pwm,
    pub brake: Output<'static>,
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
        if out.brake {
            self.brake.set_high();
        } else {
            self.brake.set_low();
        }
    }

    fn now_us(&self) -> u64 {
        embassy_time::Instant::now().as_micros()
    }
}

/// Everything the interrupt owns.
pub struct LoopState {
    pub ctl: Controller,
    pub io: BoardIo,
}

pub static LOOP: Mutex<RefCell<Slot<LoopState>>> = Mutex::new(RefCell::new(Slot::Empty));

/// An optional value whose empty state is all zero bytes (`repr(C, u8)`: tag 0, no niche), so
/// a static holding one is zero-initialised (`.bss`) and costs no flash. An `Option<T>` keeps
/// `None` in a niche of `T` (an enum or `bool` value no `T` has), which is not zero: the
/// `Option<LoopState>` and the mailbox's `Option<Config>` put 1.6 KB of initial values in
/// flash (`.data`).
#[repr(C, u8)]
#[derive(Clone, Copy, Debug, Default)]
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

/// Changes posted by the console for the interrupt to apply between two steps.
#[derive(Clone, Copy, Debug, Default)]
pub struct Pending {
    /// Clear this fault (only if it is still the latched one).
    pub clear: Slot<Fault>,
    pub cfg: Slot<Config>,
    pub mode: Slot<Mode>,
}

impl Pending {
    pub fn is_empty(&self) -> bool {
        self.clear.is_empty() && self.cfg.is_empty() && self.mode.is_empty()
    }
}

pub static PENDING: Mutex<RefCell<Pending>> = Mutex::new(RefCell::new(Pending {
    clear: Slot::Empty,
    cfg: Slot::Empty,
    mode: Slot::Empty,
}));

/// Current-loop periods run since boot (wraps).
pub static PERIODS: AtomicU32 = AtomicU32::new(0);
/// Periods since the last protection supervision tick.
static SUPERVISE_COUNT: AtomicU32 = AtomicU32::new(0);
/// Periods whose computation was not finished before the next sample was ready.
pub static OVERRUNS: AtomicU32 = AtomicU32::new(0);
/// A posted mode change was refused by the controller (fault latched in between).
pub static MODE_REFUSED: AtomicU32 = AtomicU32::new(0);
/// Sum of `p_elec` over all periods, in Q16.16 watt·periods, low and high words (the
/// console's energy counter is recomputed from it: exact, not from sampled power).
pub static ENERGY_LO: AtomicU32 = AtomicU32::new(0);
pub static ENERGY_HI: AtomicU32 = AtomicU32::new(0);

/// Copy of the controller for a task (briefly locks out the interrupt: ≈ 2 µs).
pub fn snapshot() -> Option<Controller> {
    critical_section::with(|cs| LOOP.borrow_ref(cs).get().map(|s| s.ctl.clone()))
}

/// Energy since boot, J.
pub fn energy_j(ts: f32) -> f32 {
    let (lo, hi) = critical_section::with(|_| {
        (
            ENERGY_LO.load(Ordering::Relaxed),
            ENERGY_HI.load(Ordering::Relaxed),
        )
    });
    let acc = ((hi as u64) << 32 | lo as u64) as i64;
    acc as f32 / 65_536.0 * ts
}

/// The current-loop interrupt body (called from the `ADC1_2` handler).
#[inline(always)]
pub fn on_sample() {
    critical_section::with(|cs| {
        let mut guard = LOOP.borrow_ref_mut(cs);
        let Some(st) = guard.get_mut() else {
            // Not started yet: acknowledge the conversions and leave the bridge as it is (off).
            pac::ADC1.isr().write(|w| w.set_jeos(true));
            pac::ADC2.isr().write(|w| w.set_jeos(true));
            return;
        };
        run_period(&mut st.ctl, &mut st.io);

        // Protection supervision (I²t, force, stroke, speed, sensors, derating) at 1 kHz, in
        // the loop's own context so it never races the step: ≈ 500 instructions one period in
        // `supervise_every()` (20 at 20 kHz).
        let n = SUPERVISE_COUNT.load(Ordering::Relaxed) + 1;
        if n >= st.ctl.supervise_every() {
            SUPERVISE_COUNT.store(0, Ordering::Relaxed);
            st.ctl.supervise();
        } else {
            SUPERVISE_COUNT.store(n, Ordering::Relaxed);
        }

        // Exact energy: Σ p_elec (Q16.16) per period, 64-bit.
        let p = st.ctl.telemetry().p_elec.to_bits() as i64;
        let acc = ((ENERGY_HI.load(Ordering::Relaxed) as u64) << 32
            | ENERGY_LO.load(Ordering::Relaxed) as u64) as i64;
        let acc = acc.saturating_add(p) as u64;
        ENERGY_LO.store(acc as u32, Ordering::Relaxed);
        ENERGY_HI.store((acc >> 32) as u32, Ordering::Relaxed);

        // Console changes, between this step and the next (copied out only when present:
        // the mailbox holds a 264-byte configuration).
        let mut q = PENDING.borrow_ref_mut(cs);
        if q.is_empty() {
            PERIODS.fetch_add(1, Ordering::Relaxed);
            check_overrun(&mut st.ctl);
            return;
        }
        let p = core::mem::take(&mut *q);
        drop(q);
        if let Some(f) = p.clear.value() {
            // The console's copy checked the cause is gone; if it came back since, the
            // controller refuses and the fault stays latched (the console shows it).
            if st.ctl.fault() == Some(f) {
                let _ = st.ctl.clear_fault();
            }
        }
        if let Some(c) = p.cfg.value() {
            let old_hz = st.ctl.config().pwm_hz;
            // Validated by the console on its copy: the same check cannot fail here, and if it
            // did nothing would change.
            if st.ctl.set_config(&c).is_ok() && c.pwm_hz != old_hz {
                if let Some(arr) = board::arr_for(c.pwm_hz) {
                    st.io.pwm.set_arr(arr);
                }
            }
        }
        if let Some(m) = p.mode.value() {
            if st.ctl.set_mode(m).is_err() {
                MODE_REFUSED.fetch_add(1, Ordering::Relaxed);
            }
        }
        PERIODS.fetch_add(1, Ordering::Relaxed);
        check_overrun(&mut st.ctl);
    });
}

/// Overrun: the next sequence already finished (its flag is set again) before this period's
/// work is done.
#[inline(always)]
fn check_overrun(ctl: &mut Controller) {
    if pac::ADC2.isr().read().jeos() {
        OVERRUNS.fetch_add(1, Ordering::Relaxed);
        // The controller counts them against `overrun_limit` (protect.rs) and trips.
        ctl.report_overrun();
    }
}
