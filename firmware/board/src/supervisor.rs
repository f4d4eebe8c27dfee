//! Supervision at 100 Hz: feeds the independent watchdog, checks that the current-loop
//! interrupt runs once per PWM period, and logs faults and counters with defmt.
//!
//! Loop check. The interrupt counts its periods (the period routine's `periods`); the expected count over a
//! window is `Δt·pwm_hz` from embassy's clock (TIM15, independent of TIM1 and the ADCs).
//! * No period at all during one supervision interval (10 ms = 200 periods at 20 kHz): the
//!   loop is dead (ADC trigger lost, interrupt disabled, a peripheral hung). The bridge is
//!   opened at once from here (MOE = 0) and the watchdog is no longer fed, so the image resets
//!   within its timeout and boots again into `idle`.
//! * Fewer periods than expected by more than 1 % + 2 over a 1 s window: periods were missed
//!   (the interrupt was held off longer than a period). Logged, with the overrun count (the
//!   interrupt's own check: the next sample was ready before it finished).

use embassy_stm32::peripherals::IWDG;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_time::{Duration, Instant, Ticker};

use crate::board::SUPERVISION_MS;
use crate::drive;

#[embassy_executor::task]
pub async fn supervisor_task(mut wdg: IndependentWatchdog<'static, IWDG>) {
    let mut ticker = Ticker::every(Duration::from_millis(SUPERVISION_MS));
    // The loop starts before this task: its first tick sees periods run.
    let mut last_n = 0;
    let mut win_t = Instant::now();
    let mut win_n = last_n;
    let mut last_fault = None;
    let mut last_overruns = 0;
    let mut last_refused = 0;
    let mut last_dropped = 0;
    let mut dead = false;
    let mut retry = regen_fw::align::AlignRetry::NEW;
    wdg.unleash();
    loop {
        ticker.next().await;
        let Some((ctl, c)) = drive::snapshot() else {
            continue;
        };
        let n = c.periods;
        if n == last_n && !dead {
            crate::pwm::force_off();
            dead = true;
            defmt::error!(
                "current loop dead: no period in {} ms; bridge opened, watchdog reset follows",
                SUPERVISION_MS
            );
        }
        last_n = n;
        if !dead {
            wdg.pet();
        }

        let now = Instant::now();
        let dt = now - win_t;
        if dt >= Duration::from_secs(1) {
            let expected = dt.as_micros() as f32 * 1e-6 * ctl.config().pwm_hz;
            let got = n.wrapping_sub(win_n) as f32;
            if got + 2.0 < expected * 0.99 {
                defmt::warn!(
                    "current loop missed periods: {} of {} expected in {} ms",
                    got,
                    expected,
                    dt.as_millis()
                );
            }
            win_t = now;
            win_n = n;
        }

        // An alignment that found the rotor moving: retried after its wait in the safe state
        // (`regen_fw::align`, the simulator's boot runs the same), applied between two periods.
        if retry.poll(&ctl, n) == regen_fw::align::Retry::Post {
            let mut mail = regen_fw::period::Pending::EMPTY;
            regen_fw::align::post(&mut mail);
            drive::apply(&mut mail);
            defmt::warn!(
                "alignment found the rotor moving: try {} of {}",
                retry.retries() + 1,
                regen_fw::align::ALIGN_TRIES
            );
        }

        let f = ctl.fault();
        if f != last_fault {
            match f {
                Some(f) => defmt::error!("fault {}: drive in {}", f.name(), ctl.mode().name()),
                None => defmt::info!("fault cleared"),
            }
            last_fault = f;
        }
        let o = c.overruns;
        if o != last_overruns {
            defmt::warn!(
                "current-loop overruns: {} (total {})",
                o.wrapping_sub(last_overruns),
                o
            );
            last_overruns = o;
        }
        let r = c.mode_refused;
        if r != last_refused {
            defmt::warn!("a console mode change was refused by the loop (fault latched)");
            last_refused = r;
        }
        let d = crate::console::TEL_DROPPED.load(core::sync::atomic::Ordering::Relaxed);
        if d.wrapping_sub(last_dropped) >= 1000 {
            defmt::info!("telemetry lines dropped (UART busy): {}", d);
            last_dropped = d;
        }
    }
}
