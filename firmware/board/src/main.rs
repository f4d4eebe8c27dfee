//! STM32G474RE board image — SKELETON ONLY (see docs/board.md, "NOT done"): it initialises
//! embassy and nothing else. The drive (PWM, ADC, current-loop interrupt, encoder, console,
//! supervision) is not implemented yet.
#![no_std]
#![no_main]
use {defmt_rtt as _, panic_probe as _};

#[embassy_executor::main]
async fn main(_s: embassy_executor::Spawner) {
    let _p = embassy_stm32::init(Default::default());
    defmt::info!("regen-board skeleton: drive not implemented");
}
