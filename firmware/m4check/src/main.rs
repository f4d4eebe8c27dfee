//! Replays `vectors.bin` through the controller on a Cortex-M4 (QEMU `mps2-an386`), prints
//! the digest of all outputs, and exits with status 0. `regen_step` is the one function
//! `../../shared/tools/qemu-insn/count.sh` counts: one full current-loop period.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use regen_fw::selftest::{replay, STEP_BYTES};
use regen_fw::{Actuation, Config, Controller, Mode, RawSample};

static VECTORS: &[u8] = include_bytes!("../vectors.bin");

/// One current-loop period: read currents → Clarke → Park → law → limits → two PI →
/// inverse Park → modulation (exactly `Controller::step`).
#[no_mangle]
#[inline(never)]
pub fn regen_step(ctl: &mut Controller, s: &RawSample) -> Actuation {
    ctl.step(s)
}

/// One protection supervision tick (1 kHz, every `supervise_every()` = 20 steps), counted
/// separately from the step.
#[no_mangle]
#[inline(never)]
pub fn regen_supervise(ctl: &mut Controller) {
    ctl.supervise()
}

#[entry]
fn main() -> ! {
    let cfg = Config::default();
    let mut ctl = match Controller::new(&cfg) {
        Ok(c) => c,
        Err(_) => exit(3),
    };
    if ctl.set_mode(Mode::Run).is_err() {
        exit(4);
    }
    let half = VECTORS.len() / STEP_BYTES / 2;
    let every = ctl.supervise_every() as usize;
    let mut k = 0usize;
    let mut bad_cfg = false;
    let (digest, steps) = replay(&mut ctl, VECTORS, |c, s| {
        if k == half
            && c.set_config(&Config {
                r_load_ohm: 2.0,
                ..cfg
            })
            .is_err()
        {
            bad_cfg = true;
        }
        k += 1;
        let a = regen_step(c, s);
        // On a copy: the recorded sequence starts at speed with the observer at rest, a
        // start-up current transient (−10 A for a few ms) that the force check rightly trips
        // on; the step's digest stays that of the loop alone.
        if k.is_multiple_of(every) {
            regen_supervise(&mut c.clone());
        }
        a
    });
    if bad_cfg {
        exit(5);
    }
    hprintln!("digest={:016x} steps={}", digest, steps);
    exit(0)
}

fn exit(code: i32) -> ! {
    if code == 0 {
        debug::exit(debug::EXIT_SUCCESS);
    } else {
        debug::exit(debug::EXIT_FAILURE);
    }
    loop {}
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    hprintln!("panic");
    debug::exit(debug::EXIT_FAILURE);
    loop {}
}
