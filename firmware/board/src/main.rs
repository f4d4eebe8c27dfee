//! STM32G474RE board image of the regenerative servo drive.
//!
//! * `board`: clocks (170 MHz, boost), pins, scaling, flash layout, watchdog — every choice.
//! * `pwm`: TIM1 centre-aligned complementary PWM, dead time, sampling instant, gate enable.
//! * `drive`: the current loop in the ADC interrupt (highest priority), `DriveIo` for the board.
//! * `console`: `regen_fw::console` over USART2 (ST-LINK VCP), telemetry.
//! * `store`: `regen_fw::store` (an append log of records) on two pages of flash bank 2.
//! * `supervisor`: watchdog, loop-alive and overrun checks, fault logs.
//!
//! The control core `regen-fw` is linked unchanged: the interrupt runs the same period
//! routine (`regen_fw::period::Period`) the simulator runs.
#![no_std]
#![no_main]

mod board;
mod console;
mod drive;
mod pwm;
mod store;
mod supervisor;
mod trip;

use defmt_rtt as _;
use embassy_stm32::interrupt::{InterruptExt, Priority};
use embassy_stm32::{interrupt, pac};
use regen_fw::store::StoreFault;
use regen_fw::{Config, Controller};

/// The current-loop interrupt: ADC1 and ADC2 share this vector; only ADC2's end of injected
/// sequence is enabled, so it fires once per PWM period.
#[interrupt]
fn ADC1_2() {
    drive::on_sample();
}

/// A panic: the bridge opens first (the last duties must not stay applied), then the return
/// addresses of the panic's first frames go to the defmt log and the image stops in a
/// HardFault; the watchdog resets it. Neither the message nor the `Location` is read: reading
/// either keeps, for every panic site of the image, its arguments, its message and file path
/// strings and the `core::fmt` code that formats them (6.7 KB of flash, measured; with both
/// unread the compiler folds every panic path into this handler). The site is found from the
/// logged addresses: `addr2line -e target/thumbv7em-none-eabihf/release/regen-board ADDR`
/// (the image keeps its debug information, `debug = 2`).
#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    pwm::force_off();
    let ra = return_addresses();
    defmt::error!(
        "panicked; return addresses {:#x} (addr2line -e regen-board)",
        ra
    );
    cortex_m::asm::udf()
}

/// The link registers saved in the first four frame records above the caller, walked
/// through the frame pointer (r7: the thumbv7em target keeps frame pointers, each record is
/// the caller's r7 then its lr); a record outside RAM or misaligned ends the walk (0 after it).
#[inline(always)]
fn return_addresses() -> [u32; 4] {
    const RAM: core::ops::Range<u32> = 0x2000_0000..0x2002_0000 - 8;
    let mut fp: u32;
    // SAFETY: reads r7, changes nothing.
    unsafe {
        core::arch::asm!("mov {}, r7", out(reg) fp, options(nomem, nostack, preserves_flags))
    };
    let mut ra = [0u32; 4];
    for r in &mut ra {
        if fp & 3 != 0 || !RAM.contains(&fp) {
            break;
        }
        // SAFETY: an aligned address inside SRAM (checked above): readable, whatever it holds.
        unsafe {
            *r = ((fp + 4) as *const u32).read_volatile();
            fp = (fp as *const u32).read_volatile();
        }
    }
    ra
}

/// A fault (and a panic, which ends in a HardFault) opens the bridge first: the
/// current loop no longer runs, and the last duties must not stay applied. The watchdog then
/// resets the image within its timeout.
#[cortex_m_rt::exception]
unsafe fn HardFault(_ef: &cortex_m_rt::ExceptionFrame) -> ! {
    pwm::force_off();
    loop {
        cortex_m::asm::nop();
    }
}

/// NMI: on the G474 a flash double-ECC error (a double word torn by a power cut during a
/// store save) or an HSE failure. Bridge off, note the ECC address, reset (`store.rs`).
#[cortex_m_rt::exception]
unsafe fn NonMaskableInt() {
    pwm::force_off();
    store::note_ecc_and_reset()
}

#[embassy_executor::main]
async fn main(spawner: embassy_executor::Spawner) {
    let p = embassy_stm32::init(board::rcc_config());
    let parts = board::take(p);

    // Every other interrupt below the current loop: the loop preempts the UART, flash and
    // embassy's time driver (TIM15, sharing its vector with TIM1's break), never the reverse.
    for irq in [
        interrupt::USART2,
        interrupt::FLASH,
        interrupt::TIM1_BRK_TIM15,
    ] {
        irq.set_priority(Priority::P2);
    }

    // Parameters: the store, or defaults with a reported fault.
    let (flash, recovered) = store::BoardStore::open(parts.flash).await;
    if recovered {
        defmt::warn!("store: a double word torn by a power cut during a save was zeroed");
    }
    let (cfg, boot_msg): (Config, &'static str) = match flash.fault {
        None => (flash.held, "parameters loaded from flash"),
        Some(StoreFault::Empty) => {
            defmt::warn!("parameter store empty: defaults in use");
            (
                Config::default(),
                "store empty: DEFAULT parameters (fault store_empty)",
            )
        }
        Some(StoreFault::Invalid) => {
            defmt::warn!("stored parameters invalid: defaults in use");
            (
                Config::default(),
                "stored parameters invalid: DEFAULT parameters (fault store_invalid)",
            )
        }
    };
    let (mut ctl, cfg) = match Controller::new(&cfg) {
        Ok(c) => (c, cfg),
        Err(e) => {
            defmt::error!(
                "stored configuration refused ({}: {}): defaults",
                e.field,
                e.reason
            );
            let d = Config::default();
            match Controller::new(&d) {
                Ok(c) => (c, d),
                Err(_) => {
                    defmt::error!("default configuration refused: drive stays off");
                    return;
                }
            }
        }
    };

    // Power-up: the rotor sits at an unknown angle and the amplifiers' zero codes are not
    // known: Idle, the offsets calibrated over the first periods (gates off; the loop then
    // programs them into the converters), Run refused until `mode align` has succeeded.
    ctl.require_alignment();

    let Some(arr) = board::arr_for(cfg.pwm_hz) else {
        defmt::error!(
            "pwm_hz {} not realisable on TIM1: drive stays off",
            cfg.pwm_hz
        );
        return;
    };
    // The driver owns the PWM pins and TIM1's clock: dropping it would switch both off, so it
    // is kept for the program's life (the loop drives TIM1 through its registers).
    core::mem::forget(parts.pwm);
    let Some(pwm) = pwm::configure(arr) else {
        defmt::error!("TIM1 does not count: drive stays off");
        return;
    };
    defmt::info!("TIM1: ARR {}, update at {}", arr, pwm.at);

    // Hardware trips (comparators → TIM1 breaks, chopper), armed with the bridge off. A break
    // flagged at arming is left set: the loop's first period latches it as a fault.
    let thr = regen_fw::io::HwThresholds::of(&cfg);
    if !trip::arm(&thr) {
        defmt::error!("hardware trip at arming (comparator active): latched by the loop");
    }
    critical_section::with(|cs| {
        *drive::LOOP.borrow_ref_mut(cs) = regen_fw::Slot::Full(drive::LoopState {
            ctl,
            per: regen_fw::Period::NEW,
            io: drive::BoardIo {
                adc1: parts.adc1,
                adc2: parts.adc2,
                qei: parts.qei,
                pwm,
                chop: thr.chop,
                brake: false,
                offsets: [0; 3],
            },
        });
    });
    // Discard a sequence completed before the loop state existed, then start the loop.
    pac::ADC1.isr().write(|w| w.set_jeos(true));
    pac::ADC2.isr().write(|w| w.set_jeos(true));
    interrupt::ADC1_2.set_priority(Priority::P0);
    // SAFETY: the handler only touches state behind critical-section mutexes and atomics.
    unsafe { interrupt::ADC1_2.enable() };
    defmt::info!("current loop running at {} Hz, mode idle", cfg.pwm_hz);

    match supervisor::supervisor_task(parts.iwdg) {
        Ok(t) => spawner.spawn(t),
        Err(_) => defmt::error!("supervision task not started"),
    }
    match parts.uart {
        Some(uart) => {
            let (tx, rx) = uart.split();
            match console::console_task(tx, rx, flash, boot_msg) {
                Ok(t) => spawner.spawn(t),
                Err(_) => defmt::error!("console task not started"),
            }
        }
        None => {
            defmt::error!("console UART not available: running without console");
        }
    }
}
