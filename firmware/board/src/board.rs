//! Every board choice in one place: clocks, pins, power-stage scaling, PWM timing, flash
//! layout, interrupt priorities, watchdog. One comment per choice.
//!
//! Target: NUCLEO-G474RE (MB1367) under a three-phase power stage with three low-side shunts
//! and shunt amplifiers, wired on the ST morpho pinout of the X-NUCLEO-IHM08M1 (UM1996), the
//! de-facto motor-control pinout of the Nucleo-64 boards (ST's MCSDK uses it). The IHM08M1
//! itself is a 10–48 V stage; the drive's defaults (`regen_fw::Config`: bus over-voltage trip
//! 95 V, brake at 85 V) need a 100 V-class stage with the same pinout, whose scaling is given
//! below. On the IHM08M1 itself set `amps_per_count`/`volts_per_count` from its shunt, gain and
//! divider (UM1996) with `set` and `save`; nothing else changes.
//!
//! [`take`] is the only place where pins and peripheral instances are named.

use embassy_stm32::adc::{Adc, AdcChannel, AdcConfig, InjectedAdc};
use embassy_stm32::flash::{Async, Bank2Region, Flash};
use embassy_stm32::gpio::OutputType;
use embassy_stm32::pac::adc::vals::Exten;
use embassy_stm32::peripherals::{ADC1, ADC2, IWDG, TIM1, TIM2};
use embassy_stm32::rcc::{self, mux};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::complementary_pwm::{ComplementaryPwm, ComplementaryPwmPin};
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::qei::{self, Qei};
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::usart::{self, BufferedUart};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{bind_interrupts, flash, peripherals, Peripherals};

// ---------------------------------------------------------------------------------------------
// Clocks
// ---------------------------------------------------------------------------------------------

/// System clock 170 MHz from the 24 MHz HSE crystal (X3 on the NUCLEO-G474RE) through the PLL:
/// 24 MHz / M 6 = 4 MHz PLL input (range 2.66–16 MHz), × N 85 = 340 MHz VCO (96–344 MHz),
/// / R 2 = 170 MHz. HSE rather than HSI16: HSI16 is ±1 % over temperature, the crystal tens of
/// ppm, and both the PWM frequency (hence the controller's sampling period `ts`, on which the
/// PI gains, the encoder speed and the energy integral depend) and the UART baud rate come
/// from this clock. Above 150 MHz RM0440 §6.1.5 requires Range 1 boost mode (PWR_CR5.R1MODE=0)
/// and 4 flash wait states (RM0440 §3.3.3); embassy's RCC driver applies both when
/// `boost = true`, in the order RM0440 asks (AHB/2 during the switch).
pub fn rcc_config() -> embassy_stm32::Config {
    let mut c = embassy_stm32::Config::default();
    c.rcc.hse = Some(rcc::Hse {
        freq: Hertz(24_000_000),
        mode: rcc::HseMode::Oscillator,
    });
    c.rcc.pll = Some(rcc::Pll {
        source: rcc::PllSource::HSE,
        prediv: rcc::PllPreDiv::DIV6,
        mul: rcc::PllMul::MUL85,
        divp: None,
        divq: None,
        divr: Some(rcc::PllRDiv::DIV2),
    });
    c.rcc.sys = rcc::Sysclk::PLL1_R;
    c.rcc.boost = true;
    // APB1 and APB2 undivided: TIM1 (APB2) and TIM2 (APB1) count at 170 MHz.
    c.rcc.apb1_pre = rcc::APBPrescaler::DIV1;
    c.rcc.apb2_pre = rcc::APBPrescaler::DIV1;
    // ADC1/2 kernel clock = SYSCLK; embassy divides it to ≤ 60 MHz (170/4 = 42.5 MHz).
    c.rcc.mux.adc12sel = mux::Adcsel::SYS;
    c
}

/// TIM1 counter clock, Hz (APB2 × 1, prescaler 0).
pub const TIM1_HZ: u32 = 170_000_000;

// ---------------------------------------------------------------------------------------------
// PWM (TIM1, centre-aligned, complementary)
// ---------------------------------------------------------------------------------------------
// Pins (IHM08M1 morpho): UH PA8 / UL PA7, VH PA9 / VL PB0, WH PA10 / WL PB1, all AF6 =
// TIM1_CH1..3 and TIM1_CH1N..3N on the G474. They are constructed in `main.rs` from these names.

/// Dead time inserted by TIM1 between a switch turning off and its complement turning on, ns.
/// 500 ns: a typical figure for 100 V-class MOSFETs with bootstrap gate drivers (turn-off delay
/// plus fall time ≈ 150–300 ns, with margin). The control core has no dead-time parameter (it
/// is a hardware property of the stage, not a control setting), so it is a board constant;
/// change it here for another stage. Encoded in BDTR.DTG by [`dtg`] (checked at compile time).
pub const DEAD_TIME_NS: u32 = 500;

/// BDTR.DTG encoding of a dead time (RM0440 §28.6.21, t_DTS = 1/170 MHz = 5.88 ns, CKD = 0):
/// `0xxxxxxx`: DT = DTG·t_DTS (≤ 747 ns); `10xxxxxx`: DT = (64 + DTG[5:0])·2·t_DTS
/// (≤ 1.49 µs). Rounded up (never less dead time than asked).
pub const fn dtg(ns: u32) -> u8 {
    let ticks = (ns as u64 * TIM1_HZ as u64).div_ceil(1_000_000_000);
    if ticks <= 127 {
        ticks as u8
    } else {
        let t2 = ticks.div_ceil(2);
        assert!(
            t2 >= 64 && t2 <= 127,
            "dead time out of the encodable range"
        );
        0x80 | (t2 - 64) as u8
    }
}
const _: () = assert!(dtg(DEAD_TIME_NS) == 85); // 85 × 5.88 ns = 500 ns

/// TIM1 auto-reload for a PWM frequency: centre-aligned, one period = 2·ARR counts. 20 kHz →
/// 4,250 (duty resolution 1/4,250 ≈ 0.024 %). `None` when the frequency does not fit 16 bits
/// (below 1.3 kHz; the configuration refuses < 5 kHz anyway) or is not finite.
pub fn arr_for(pwm_hz: f32) -> Option<u16> {
    if !(pwm_hz.is_finite() && pwm_hz > 0.0) {
        return None;
    }
    let arr = (TIM1_HZ as f32 / (2.0 * pwm_hz) + 0.5) as u32;
    (100..=0xFFFF).contains(&arr).then_some(arr as u16)
}

// ---------------------------------------------------------------------------------------------
// Current and bus-voltage sensing (ADC1 + ADC2, injected, triggered by TIM1 TRGO)
// ---------------------------------------------------------------------------------------------
// Pins (IHM08M1 morpho): phase A current PA0 = ADC12_IN1, phase B current PC1 = ADC12_IN7,
// phase C current PC0 = ADC12_IN6, bus voltage PA1 = ADC12_IN2.
// ADC1 converts [I_a, I_c], ADC2 [I_b, V_bus], both on the same trigger: I_a and I_b are taken
// at the same instant, I_c and V_bus one conversion (25 ADC clocks = 0.59 µs) later.
//
// Scaling of the assumed 100 V stage, which is what `Config::default()` holds:
// * phase current: 10 mΩ shunt × differential gain 6.6 with a 1.65 V offset → 66 mV/A,
//   3.3 V/4096 counts → 50 A / 4096 counts = 0.012207 A/count (`amps_per_count`), zero current
//   at mid-scale 2048 (`adc_zero_code`), range ±25 A (the trip default is 20 A).
// * bus voltage: divider 348 kΩ / 9.76 kΩ (×36.6) → 3.3 V ↔ 120.8 V, i.e. 120 V / 4096 counts
//   = 0.0293 V/count (`volts_per_count`) to within 0.7 %; the over-voltage trip (95 V) is at
//   79 % of the range.
// The current sense is low-side: a phase current is readable only while that phase's low-side
// switch conducts, which is why the sample is taken at the centre of the low-side interval.

/// Sample time of the current channels, ADC clocks (op-amp outputs: low source impedance).
pub const CURRENT_SAMPLE: embassy_stm32::adc::SampleTime =
    embassy_stm32::adc::SampleTime::CYCLES12_5;
/// Sample time of the bus-voltage channel: the divider's ≈ 9.5 kΩ source impedance needs
/// ≥ 40 ADC clocks to settle to ½ LSB against the 5 pF sampling capacitor (RM0440 / DS12288).
pub const VBUS_SAMPLE: embassy_stm32::adc::SampleTime = embassy_stm32::adc::SampleTime::CYCLES47_5;

// ---------------------------------------------------------------------------------------------
// Encoder (TIM2, encoder mode 3, 16-bit)
// ---------------------------------------------------------------------------------------------
// Pins (IHM08M1 encoder connector J3): A = PA15 = TIM2_CH1, B = PB3 = TIM2_CH2 (AF1). TIM2 is
// a 32-bit timer; the QEI driver sets ARR = 0xFFFF so the counter wraps at 2^16, as
// `RawSample::encoder` expects. ×4 decoding (mode 3): `encoder_cpr` counts both edges of
// both channels.

// ---------------------------------------------------------------------------------------------
// Brake chopper
// ---------------------------------------------------------------------------------------------
// The brake-resistor switch is driven by COMP7's output on PC8 (AF7, morpho CN10-2, free on
// the NUCLEO-G474RE and on the IHM08M1 pinout; the IHM08M1 has no brake switch, so this drives
// an external one): on above `brake_on_v` on a second bus divider (PB14), whatever the CPU
// does; the core's brake command forces it on through the comparator's DAC threshold
// (`trip.rs`). From reset until `trip::arm` PC8 is an analog input: the switch's gate driver
// needs a pull-down (chopper off).

// ---------------------------------------------------------------------------------------------
// Console
// ---------------------------------------------------------------------------------------------
/// The ST-LINK V3E virtual COM port of the NUCLEO-G474RE is wired to PA2 (TX) / PA3 (RX)
/// (UM2505). Those pins carry LPUART1 (AF12) and USART2 (AF7); USART2 is used. 115,200 baud:
/// what every terminal defaults to; telemetry is therefore limited to ≈ 11.5 kB/s (lines that
/// do not fit are dropped and counted, see `console.rs`).
pub const CONSOLE_BAUD: u32 = 115_200;

// ---------------------------------------------------------------------------------------------
// Supervision (the parameter store's flash region is `store::STORE_RANGE`)
// ---------------------------------------------------------------------------------------------
/// Independent-watchdog timeout, µs. The supervision task feeds it every 10 ms; a store `save`
/// does not hold the thread-mode executor (its flash operations are awaited, `store.rs`). The
/// timeout covers the feed period many times over, the LSI's tolerance included (29.5–34 kHz:
/// the real timeout can be 6 % shorter), and 100 ms is still short against the structure's vibration
/// period (≥ 1 s): a hung image costs at most a tenth of a cycle before the reset opens the
/// bridge (pins high-impedance, gate-driver pull-downs). The current loop itself is not
/// guarded by the watchdog but by the supervision task (see `supervisor.rs`).
pub const WATCHDOG_TIMEOUT_US: u32 = 100_000;
/// Supervision period, ms (100 Hz).
pub const SUPERVISION_MS: u64 = 10;

// ---------------------------------------------------------------------------------------------
// Construction
// ---------------------------------------------------------------------------------------------

bind_interrupts!(pub struct Irqs {
    USART2 => usart::BufferedInterruptHandler<peripherals::USART2>;
    FLASH => flash::InterruptHandler;
});

/// The drivers, built from the pins chosen above.
pub struct Parts {
    pub pwm: ComplementaryPwm<'static, TIM1>,
    pub adc1: InjectedAdc<'static, ADC1, 2>,
    pub adc2: InjectedAdc<'static, ADC2, 2>,
    pub qei: Qei<'static, TIM2>,
    pub uart: Option<BufferedUart<'static>>,
    pub flash: Bank2Region<'static, Async>,
    pub iwdg: IndependentWatchdog<'static, IWDG>,
}

/// Build every driver. The PWM outputs start with MOE = 0 (`pwm::configure` follows); the
/// injected conversions are armed on TIM1 TRGO.
pub fn take(p: Peripherals) -> Parts {
    let mut pwm = ComplementaryPwm::new(
        p.TIM1,
        Some(PwmPin::new(p.PA8, OutputType::PushPull)),
        Some(ComplementaryPwmPin::new(p.PA7, OutputType::PushPull)),
        Some(PwmPin::new(p.PA9, OutputType::PushPull)),
        Some(ComplementaryPwmPin::new(p.PB0, OutputType::PushPull)),
        Some(PwmPin::new(p.PA10, OutputType::PushPull)),
        Some(ComplementaryPwmPin::new(p.PB1, OutputType::PushPull)),
        None,
        None,
        Hertz(20_000),
        CountingMode::CenterAlignedBothInterrupts,
    );
    pwm.set_master_output_enable(false);

    let qei = Qei::new(p.TIM2, p.PA15, p.PB3, qei::Config::default());

    let adc1 = Adc::new(p.ADC1, AdcConfig::default());
    let adc2 = Adc::new(p.ADC2, AdcConfig::default());
    let adc1 = adc1.setup_injected_conversions(
        [
            (p.PA0.degrade_adc(), CURRENT_SAMPLE),
            (p.PC0.degrade_adc(), CURRENT_SAMPLE),
        ],
        embassy_stm32::triggers::TIM1_TRGO,
        Exten::RISING_EDGE,
        false,
    );
    let adc2 = adc2.setup_injected_conversions(
        [
            (p.PC1.degrade_adc(), CURRENT_SAMPLE),
            (p.PA1.degrade_adc(), VBUS_SAMPLE),
        ],
        embassy_stm32::triggers::TIM1_TRGO,
        Exten::RISING_EDGE,
        true,
    );

    let mut ucfg = usart::Config::default();
    ucfg.baudrate = CONSOLE_BAUD;
    // Ring buffers of the interrupt-driven UART (`take` runs once: the singletons are free).
    let tx = cortex_m::singleton!(: [u8; 512] = [0; 512]);
    let rx = cortex_m::singleton!(: [u8; 128] = [0; 128]);
    let uart = match (tx, rx) {
        (Some(tx), Some(rx)) => BufferedUart::new(p.USART2, p.PA3, p.PA2, tx, rx, Irqs, ucfg).ok(),
        _ => None,
    };

    let flash = Flash::new(p.FLASH, Irqs).into_regions().bank2_region;
    let iwdg = IndependentWatchdog::new(p.IWDG, WATCHDOG_TIMEOUT_US);

    Parts {
        pwm,
        adc1,
        adc2,
        qei,
        uart,
        flash,
        iwdg,
    }
}
