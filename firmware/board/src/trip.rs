//! Hardware trips: comparators with DAC thresholds acting on TIM1's break inputs and on the
//! brake chopper, with no CPU in the path (they keep working when the core is halted).
//!
//! | comparator | + input | − input (threshold) | output | action |
//! | --- | --- | --- | --- | --- |
//! | COMP3 | PA0 = I_a amplifier | DAC3_CH1 = `oc` | inverted | TIM1 BRK: all six switches off |
//! | COMP5 | PB13 = I_b amplifier (2nd trace) | DAC4_CH1 = `oc` | inverted | TIM1 BRK |
//! | COMP6 | PB11 = I_c amplifier (2nd trace) | DAC4_CH2 = `oc` | inverted | TIM1 BRK |
//! | COMP1 | PA1 = bus divider (the ADC's) | DAC1_CH1 = `ov` | direct | TIM1 BRK2: all off |
//! | COMP7 | PB14 = second bus divider | DAC2_CH1 = `chop` (0 = forced on) | direct, 70 mV hysteresis | PC8 (AF7) = chopper gate |
//!
//! Thresholds: `regen_fw::io::HwThresholds` (one comparator per phase is all this pinout
//! leaves free: the other comparator inputs carry gate signals or the console). The
//! comparators' DAC choice is RM0440's table of inverting inputs (DACA/DACB per comparator,
//! as ST's HAL names them). PB11/PB13/PB14 are in analog mode from reset, which is what a
//! comparator input needs.
//!
//! Why no hardware short circuit (`docs/board.md`, "Hardware trips"): every break leaves all
//! six switches off (OISx = OISxN = 0, BRK2 can only do that anyway), and the bus is held by
//! the chopper; an active short stays a software decision.
//!
//! Register level (PAC) because embassy-stm32 0.6's `Comp` driver binds and enables a
//! comparator interrupt the drive does not use and has no DAC-as-internal-reference set-up;
//! the break routing is a handful of TIM1 bits next to the ones `pwm.rs` already writes.

use embassy_stm32::pac;
use embassy_stm32::pac::timer::vals::{Bkp, FilterValue, Lock};
use regen_fw::io::HwThresholds;

/// COMP_CSR values (RM0440 §24.6): EN (bit 0), INMSEL (6:4, DACA = 4, DACB = 5), INPSEL 0
/// (INP0: PA0, PB13, PB11, PA1, PB14), POLARITY (bit 15, inverted for the over-current
/// comparators: output high when the current is below −i_hw), HYST (18:16: 1 = 10 mV,
/// 2 = 20 mV, 7 = 70 mV).
const COMP_CSR: [(usize, u32); 5] = [
    (3, 1 | 4 << 4 | 1 << 15 | 1 << 16),
    (5, 1 | 4 << 4 | 1 << 15 | 1 << 16),
    (6, 1 | 4 << 4 | 1 << 15 | 1 << 16),
    (1, 1 | 5 << 4 | 2 << 16),
    (7, 1 | 5 << 4 | 7 << 16),
];

/// Write the thresholds (at arming, and after a configuration change: the DACs are not
/// locked). `chop_forced` holds the chopper on (the software's brake command).
#[inline(never)]
pub fn set_thresholds(t: &HwThresholds, chop_forced: bool) {
    pac::DAC3.dhr12r(0).write(|w| w.set_dhr(t.oc));
    pac::DAC4.dhr12r(0).write(|w| w.set_dhr(t.oc));
    pac::DAC4.dhr12r(1).write(|w| w.set_dhr(t.oc));
    pac::DAC1.dhr12r(0).write(|w| w.set_dhr(t.ov));
    set_chopper(t.chop, chop_forced);
}

/// The chopper comparator's threshold: 0 forces the chopper on (any bus voltage is above
/// it), `chop` leaves it to the comparator.
#[inline(always)]
pub fn set_chopper(chop: u16, forced: bool) {
    pac::DAC2
        .dhr12r(0)
        .write(|w| w.set_dhr(if forced { 0 } else { chop }));
}

/// Set up and arm the hardware trips, with the bridge off (MOE = 0, `pwm::configure` done).
/// Order: DACs, comparators, settle, break sources and filters, flags cleared, breaks
/// enabled, flags checked, LOCK level 1 (DTG, OISx/OISxN, BKE/BKP/BKF, AOE frozen until reset).
/// `false`: a break flag was set again after the settle time and its clearance, i.e. a
/// comparator is active (a real fault, or a threshold or divider wrong); the breaks stay
/// armed, the bridge off, and the flag is left for the loop to latch as a fault.
#[inline(never)]
pub fn arm(t: &HwThresholds) -> bool {
    pac::RCC.ahb2enr().modify(|w| {
        w.set_dac1en(true);
        w.set_dac2en(true);
        w.set_dac3en(true);
        w.set_dac4en(true);
    });
    // (The comparators sit on SYSCFG's clock, which embassy's init enables.)
    // DACs: internal connection only, no buffer (MODEx = 3), HFSEL = 2 (AHB clock above
    // 160 MHz); channel 1 of DAC1–3, both of DAC4.
    const MCR1: u32 = 3 | 2 << 14;
    for (dac, mcr, en) in [
        (pac::DAC1, MCR1, 1u32),
        (pac::DAC2, MCR1, 1),
        (pac::DAC3, MCR1, 1),
        (pac::DAC4, MCR1 | 3 << 16, 1 | 1 << 16),
    ] {
        dac.mcr().write_value(pac::dac::regs::Mcr(mcr));
        dac.cr().write_value(pac::dac::regs::Cr(en));
    }
    set_thresholds(t, false);
    // COMP7's output on PC8, alternate function 7 (the chopper gate).
    pac::GPIOC.afr(1).modify(|w| w.set_afr(0, 7));
    pac::GPIOC
        .moder()
        .modify(|w| w.set_moder(8, pac::gpio::vals::Moder::ALTERNATE));
    for (n, csr) in COMP_CSR {
        comp(n).csr().write_value(pac::comp::regs::Csr(csr));
    }
    // Settle: DAC wake-up (≤ 7.5 µs, buffer off) and comparator start-up (≤ 5 µs): 20 µs.
    cortex_m::asm::delay(crate::board::TIM1_HZ / 50_000);

    let tim = pac::TIM1;
    // Sources: COMP3/5/6 → BRK (over-current), COMP1 → BRK2 (bus over-voltage); no pins.
    tim.af1().write(|w| {
        w.set_bkine(false);
        w.set_bkcmpe(2, true);
        w.set_bkcmpe(4, true);
        w.set_bkcmpe(5, true);
    });
    tim.af2().write(|w| {
        w.set_bk2ine(false);
        w.set_bk2cmpe(0, true);
    });
    // Filters (t_DTS = 5.88 ns): over-current f_DTS/4, N = 6 → 141 ns (past the switching
    // edge's ringing, well inside a shoot-through's destructive time); over-voltage f_DTS/32,
    // N = 8 → 1.5 µs (the bus moves in ms). Active high; AOE stays 0 (software re-enables).
    tim.bdtr().modify(|w| {
        w.set_bkf(0, FilterValue::FDTS_DIV4_N6);
        w.set_bkf(1, FilterValue::FDTS_DIV32_N8);
        w.set_bkp(0, Bkp::ACTIVE_HIGH);
        w.set_bkp(1, Bkp::ACTIVE_HIGH);
    });
    // Boards of this family can flag a break on the first enable (a comparator output
    // glitch at start-up): enable, settle, clear both flags, and check again after a further
    // settle.
    tim.bdtr().modify(|w| {
        w.set_bke(0, true);
        w.set_bke(1, true);
    });
    cortex_m::asm::delay(crate::board::TIM1_HZ / 100_000);
    clear_flags();
    cortex_m::asm::delay(crate::board::TIM1_HZ / 100_000);
    let sr = tim.sr().read();
    tim.bdtr().modify(|w| w.set_lock(Lock::LEVEL1));
    !(sr.bif(0) || sr.bif(1))
}

/// Clear BIF and B2IF (rc_w0): the other defined flags are written 1 (no effect), the
/// reserved bits 0 (their reset value).
fn clear_flags() {
    const FLAGS: u32 = 0x00F3_3FFF; // UIF … CC4OF, SBIF, CC5IF, CC6IF, IDXF … TERRF
    pac::TIM1
        .sr()
        .write_value(pac::timer::regs::SrAdv(FLAGS & !(1 << 7 | 1 << 8)));
}

/// A break taken since the last call, acknowledged: BRK (over-current) first.
#[inline(always)]
pub fn take_trip() -> Option<regen_fw::control::Fault> {
    let sr = pac::TIM1.sr().read();
    if !(sr.bif(0) || sr.bif(1)) {
        return None;
    }
    clear_flags();
    Some(if sr.bif(0) {
        regen_fw::control::Fault::OverCurrent
    } else {
        regen_fw::control::Fault::BusOverVoltage
    })
}

/// COMPn's register block: COMP1_CSR at 0x4001_0200, one word per comparator (RM0440 §24.6).
fn comp(n: usize) -> pac::comp::Comp {
    // SAFETY: the address of a COMPx_CSR of this chip, n in 1..=7 (`COMP_CSR`).
    unsafe { pac::comp::Comp::from_ptr((0x4001_0200 + 4 * (n - 1)) as *mut ()) }
}
