//! TIM1 register set-up beyond what embassy's `ComplementaryPwm` does (it has enabled the
//! clock, the pins' alternate functions and centre-aligned counting), and the per-period duty
//! and gate writes of the current loop.
//!
//! Timing (one PWM period = 2·ARR counts, up then down):
//! * Repetition counter RCR = 1: the update event (UEV) happens once per period, at either the
//!   counter top (overflow) or bottom (underflow); RM0440 §28.3.3 says which one depends on
//!   when RCR was written relative to the counter start, so [`configure`] *observes* it
//!   (counting direction just after the first UEV) instead of trusting the write order.
//! * TRGO = UEV (MMS = 010) starts the injected ADC conversions, so the sample is taken at the
//!   UEV, i.e. once per period at the same point.
//! * The output mode is chosen so that the UEV is the centre of the interval where all three
//!   low-side switches conduct (the only time low-side shunts show the phase currents):
//!   UEV at the top → PWM mode 1 (high side on while CNT < CCR, centred on the bottom);
//!   UEV at the bottom → PWM mode 2 (high side on while CNT ≥ CCR, centred on the top).
//! * CCR and ARR are preloaded (OCxPE, ARPE): the duties written by the loop after a sample are
//!   loaded at the next UEV, the next sampling instant, so every high-side pulse is symmetric
//!   and the sample-to-output delay is one period plus half a pulse (the core's 1.5-period
//!   angle advance, `delay_comp`, compensates it).
//! * Gate enable = BDTR.MOE. MOE = 0 with OSSI = 1 and OISx = OISxN = 0 drives all six gate
//!   signals to their inactive level (every switch off) after the dead time; MOE = 1 restores
//!   the PWM. AOE = 0: only software sets MOE.

use embassy_stm32::pac;
use embassy_stm32::pac::timer::vals;
use regen_fw::fx::Duty;

use crate::board;

/// Result of the start-up timing observation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum UpdateAt {
    /// UEV at the counter top: PWM mode 1.
    Top,
    /// UEV at the counter bottom: PWM mode 2.
    Bottom,
}

/// The PWM state the loop needs to write duties.
#[derive(Clone, Copy, Debug)]
pub struct Pwm {
    /// Auto-reload value in force (after the next UEV).
    pub arr: u16,
    /// Which edge the UEV is on (selects the duty → CCR mapping).
    pub at: UpdateAt,
}

fn tim() -> pac::timer::TimAdv {
    pac::TIM1
}

/// Configure TIM1 for the drive. Call with the timer already set up by `ComplementaryPwm`
/// (centre-aligned, pins on). Leaves MOE = 0 (bridge off), duties centred. Returns `None` if
/// no update event was seen within 2 ms (the timer is not counting).
pub fn configure(arr: u16) -> Option<Pwm> {
    let t = tim();
    // Under a debugger: a halted core stops TIM1, and RM0440 §28.3.21 then disables the outputs
    // as if MOE were reset (no frozen duties on a live bridge at a breakpoint); the watchdog
    // is frozen too, so a halt does not reset the image.
    pac::DBGMCU.apb2fzr().modify(|w| w.set_tim1(true));
    pac::DBGMCU.apb1lfzr().modify(|w| w.set_iwdg(true));
    // Stop, then set everything while stopped.
    t.cr1().modify(|w| w.set_cen(false));
    t.bdtr().modify(|w| {
        w.set_moe(false);
        w.set_aoe(false);
        w.set_ossi(vals::Ossi::IDLE_LEVEL);
        w.set_ossr(vals::Ossr::IDLE_LEVEL);
        w.set_dtg(board::dtg(board::DEAD_TIME_NS));
    });
    // Idle levels: every output inactive (low) when MOE = 0.
    t.cr2().modify(|w| {
        for n in 0..4 {
            w.set_ois(n, false);
        }
        for n in 0..3 {
            w.set_oisn(n, false);
        }
        w.set_mms(vals::Mms::UPDATE);
    });
    t.cr1().modify(|w| {
        w.set_arpe(true);
        w.set_cms(vals::Cms::CENTER_ALIGNED3);
    });
    t.psc().write_value(0);
    t.arr().write(|w| w.set_arr(arr));
    t.rcr().write(|w| w.set_rep(1));
    for n in 0..3 {
        t.ccmr_output(n / 2).modify(|w| {
            w.set_ocm(n % 2, vals::Ocm::PWM_MODE1);
            w.set_ocpe(n % 2, true);
        });
        t.ccr(n).write(|w| w.set_ccr(arr / 2));
    }
    // Channel 4 unused: its output stays disabled.
    t.ccer().modify(|w| {
        for n in 0..3 {
            w.set_cce(n, true);
            w.set_ccne(n, true);
            w.set_ccp(n, false);
            w.set_ccnp(n, false);
        }
        w.set_cce(3, false);
    });
    t.cnt().write(|w| w.set_cnt(0));
    // UG: load ARR, CCR and the repetition counter into the shadow registers.
    t.egr().write(|w| w.set_ug(true));
    t.sr().modify(|w| w.set_uif(false));
    t.cr1().modify(|w| w.set_cen(true));
    // Observe the first update event: ≥ 42,500 polls of ≥ 4 cycles = ≥ 1 ms, i.e. ≥ 5 periods
    // at the lowest PWM frequency the configuration accepts (5 kHz).
    let mut n = 0u32;
    while !t.sr().read().uif() {
        n += 1;
        if n > board::TIM1_HZ / 500 / 8 {
            return None;
        }
    }
    // Just after an overflow the counter runs down, just after an underflow up.
    let at = if t.cr1().read().dir() == vals::Dir::DOWN {
        UpdateAt::Top
    } else {
        UpdateAt::Bottom
    };
    t.sr().modify(|w| w.set_uif(false));
    if at == UpdateAt::Bottom {
        for n in 0..3 {
            t.ccmr_output(n / 2)
                .modify(|w| w.set_ocm(n % 2, vals::Ocm::PWM_MODE2));
        }
    }
    Some(Pwm { arr, at })
}

impl Pwm {
    /// CCR value for a duty (fraction of the period the high side conducts).
    #[inline(always)]
    pub fn ccr(&self, d: Duty) -> u16 {
        // Duty is U1F15: 0 … 32,768 = 0 … 1. High-side time = CCR/ARR (mode 1) or
        // (ARR − CCR)/ARR (mode 2). Rounded to nearest, saturated to [0, ARR].
        let arr = self.arr as u32;
        let on = ((d.to_bits() as u32).min(1 << 15) * arr + (1 << 14)) >> 15;
        match self.at {
            UpdateAt::Top => on as u16,
            UpdateAt::Bottom => (arr - on) as u16,
        }
    }

    /// Write the three duties (loaded at the next update event) and the gate enable (now).
    #[inline(always)]
    pub fn write(&self, duties: &[Duty; 3], enable: bool) {
        let t = tim();
        for (n, d) in duties.iter().enumerate() {
            t.ccr(n).write(|w| w.set_ccr(self.ccr(*d)));
        }
        let moe = t.bdtr().read().moe();
        if moe != enable {
            t.bdtr().modify(|w| w.set_moe(enable));
        }
    }

    /// Change the PWM frequency (ARR, preloaded: takes effect at the next update event, with the
    /// duties computed for it). Only called while the bridge is off (`pwm_hz` is an idle-only
    /// parameter).
    pub fn set_arr(&mut self, arr: u16) {
        tim().arr().write(|w| w.set_arr(arr));
        self.arr = arr;
    }
}

/// Open the bridge now, from any context (supervision on a dead loop).
pub fn force_off() {
    tim().bdtr().modify(|w| w.set_moe(false));
}
