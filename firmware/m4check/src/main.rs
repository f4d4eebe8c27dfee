//! Replays `vectors.bin` through the controller on a Cortex-M4 (QEMU `mps2-an386`), prints
//! the digest of all outputs, and exits with status 0. `regen_step` is the function
//! `../../shared/tools/qemu-insn/count.sh` counts for the target: one full current-loop
//! period. `run.sh` also counts the supervision tick, the configuration change, a step after
//! `law_mut` and the pieces below.
#![no_std]
#![no_main]

use core::hint::black_box;
use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use regen_fw::capture::{CapPort, Capture, Edge, Settings, State, Trigger, SAMPLES};
use regen_fw::control::{Boot, Fault};
use regen_fw::encoder::{Encoder, EncoderGains};
use regen_fw::frames::{inverse_park_bounded, park_bounded, AlphaBeta, Dq, Rotation};
use regen_fw::fx::{Angle, Duty, Gain, Q};
use regen_fw::pi::{CurrentPi, PiGains, PiOutput};
use regen_fw::selftest::{replay, STEP_BYTES};
use regen_fw::svpwm::{inv_bus, modulate_limited};
use regen_fw::{
    Actuation, Compiled, Config, Controller, Mode, Pending, Period, PeriodHw, RawSample, Slot,
};

static VECTORS: &[u8] = include_bytes!("../vectors.bin");

/// One current-loop period up to its outputs: read currents → Clarke → Park → law → limits
/// → two PI → inverse Park → modulation (exactly `Controller::step_outputs`, what the
/// board's interrupt runs before it writes the outputs).
#[no_mangle]
#[inline(never)]
pub fn regen_step(ctl: &mut Controller, s: &RawSample) -> Actuation {
    ctl.step_outputs(s)
}

/// A step right after a refresh request the step serves itself (`law_mut`), counted on
/// copies of the controller every 1,000 steps; the recorded run itself has none (its
/// configuration change is served by `set_config`).
#[no_mangle]
#[inline(never)]
pub fn regen_step_refresh(ctl: &mut Controller, s: &RawSample) -> Actuation {
    // (`black_box`: keeps this function distinct from `regen_step`, which the linker would
    // otherwise fold into one.)
    ctl.step_outputs(black_box(s))
}

/// A step that finds an instantaneous fault (phase b's code `code`, the bus code `bus`: an
/// over-current or an over-voltage): the fault and its safe mode in force, the period's
/// outputs the safe state's. Counted on copies of the controller every 1,000 steps of the
/// replay, not in the digest.
#[no_mangle]
#[inline(never)]
pub fn regen_step_trip(ctl: &mut Controller, s: RawSample, code: u16, bus: u16) -> Actuation {
    // (By value, and more arguments: a body of its own, not folded with the other steps.)
    let mut s = s;
    s.i_abc[1] = black_box(code);
    s.v_bus = black_box(bus);
    ctl.step_outputs(&s)
}

/// The same with both in one period (an over-current and an over-voltage): both faults and
/// the safe mode after them in force, the outputs the safe state's.
#[no_mangle]
#[inline(never)]
pub fn regen_step_trip2(ctl: &mut Controller, s: RawSample, code: u16, bus: u16) -> Actuation {
    // (The arguments in another order: a body of its own.)
    let mut s = s;
    s.v_bus = black_box(bus);
    s.i_abc[1] = black_box(code);
    ctl.step_outputs(&s)
}

/// The rest of a one-fault latch after the outputs are written (`Period::finish` →
/// `Controller::complete_latch`): the record with its snapshot, the PI reset, the slow terms.
#[no_mangle]
#[inline(never)]
pub fn regen_trip_finish(ctl: &mut Controller) {
    ctl.complete_latch()
}

/// The rest of the two-fault latch (both records, one PI reset and slow terms).
#[no_mangle]
#[inline(never)]
pub fn regen_trip_finish2(ctl: &mut Controller, _two: u32) {
    // (A second argument: a body of its own.)
    ctl.complete_latch()
}

/// The configuration change of the recorded run (R_L 306 → 2 Ω halfway) done at once, as
/// `set_config` does: validation, the gains, and the slow terms refreshed. Counted on a copy;
/// the loop itself takes the change as `regen_compile` (the console's task) then
/// `regen_install` (between two steps).
#[no_mangle]
#[inline(never)]
pub fn regen_set_config(ctl: &mut Controller, cfg: &Config) -> bool {
    ctl.set_config(cfg).is_ok()
}

/// The slow half of a configuration change, outside the loop (the board's console task):
/// validation, gains, the law when its parameters changed.
#[no_mangle]
#[inline(never)]
pub fn regen_compile(ctl: &Controller, cfg: &Config) -> Option<Compiled> {
    ctl.compile(cfg).ok()
}

/// The swap between two periods, as the board's console task makes it with the loop locked
/// (`drive::apply` → `Period::apply` → `Controller::install`): fixed-size copies and the
/// slow terms' refresh (the board's comparator thresholds, `PeriodHw::installed`, not
/// included).
#[no_mangle]
#[inline(never)]
pub fn regen_install(per: &mut Period, ctl: &mut Controller, mail: &mut Pending) {
    per.apply(ctl, mail, &mut NoHw)
}

/// The first step after that swap (counted on a copy of the controller): the interrupt
/// serves no change, so this is a step like any other.
#[no_mangle]
#[inline(never)]
pub fn regen_step_swapped(ctl: &mut Controller, s: &RawSample, _k: usize) -> Actuation {
    // (A third argument: a body of its own, not folded with `regen_step`.)
    ctl.step_outputs(black_box(s))
}

/// The period's hardware besides `DriveIo`, with nothing to do.
struct NoHw;
impl PeriodHw for NoHw {}

/// A step of the power-up sequence (offset calibration in Idle, alignment), counted on a
/// controller of its own before the replay (`boot_paths`): not in the digest.
#[no_mangle]
#[inline(never)]
pub fn regen_step_boot(ctl: &mut Controller, s: RawSample) -> Actuation {
    // (The sample by value: a body of its own, so the linker does not fold this function
    // with `regen_step_refresh` and count their calls together.)
    ctl.step_outputs(black_box(&s))
}

/// The boot paths: calibration (2,048 Idle periods), then two alignments with 20 ms steps,
/// each begun by the emf probe on a still rotor (50 ms, then the steps), the first followed
/// by an encoder that turns the quarter turn (aligned), the second by one that runs away
/// (align_moving), each step through `regen_step_boot`.
fn boot_paths(cfg: &Config) {
    let cfg = Config {
        align_time_s: 0.02,
        ..*cfg
    };
    let Ok(mut ctl) = Controller::new(&cfg) else {
        exit(6)
    };
    ctl.require_alignment();
    let z = cfg.adc_zero_code;
    let mut s = RawSample {
        i_abc: [z, z + 3, z - 2],
        v_bus: 2458,
        encoder: 7,
    };
    for _ in 0..regen_fw::control::CAL_PERIODS + 2 {
        black_box(regen_step_boot(&mut ctl, s));
    }
    for run in 0..2u16 {
        let _ = ctl.clear_fault();
        if ctl.set_mode(Mode::Align).is_err() {
            exit(7);
        }
        // The probe hands over to the steps at the 50th supervision tick (period 999).
        let st = 20 * regen_fw::align::STILL_TICKS as u16;
        for k in 0..st + 1000 {
            if ctl.mode() != Mode::Align {
                break;
            }
            // The rotor still through the probe, then 400 periods per step: the quarter turn
            // (500 counts) in the second one.
            // (The second run continues from the first one's count: a runaway, not a jump the
            // encoder check would take for a glitch.)
            s.encoder = if run == 0 {
                7u16.wrapping_add(k.saturating_sub(st + 400).min(100) * 5)
            } else {
                507u16.wrapping_add(k.saturating_sub(st))
            };
            black_box(regen_step_boot(&mut ctl, s));
            // Supervision every 20 periods, as the period routine runs it: it latches a boot
            // fault the step found and ends a successful alignment.
            if k % 20 == 19 {
                ctl.supervise();
            }
        }
        // The first run aligns, the second latches align_moving.
        let ok = if run == 0 {
            ctl.boot() == Boot::Aligned
        } else {
            ctl.fault() == Some(Fault::AlignMoving)
        };
        if !ok {
            exit(8);
        }
    }
}

/// One period of the commissioning measurement (`measure`, `regen_fw::commission`): not the
/// running step, counted on its own (`measure_path`): not in the digest.
#[no_mangle]
#[inline(never)]
pub fn regen_step_measure(ctl: &mut Controller, s: RawSample, n: u32) -> Actuation {
    // (The period's number through `black_box`: a body of its own, so the linker does not
    // fold this function with `regen_step_boot`, whose count would then include these.)
    black_box(n);
    ctl.step_outputs(black_box(&s))
}

/// A whole measurement against a machine of its own (R = 2 Ω, L = 5 mH, the rotor still:
/// K_e refused for want of motion, the rest measured), each period through
/// `regen_step_measure`; the machine's currents from the voltage the step commanded (the
/// Euler step of `L·di/dt = v − R·i` per d/q axis) back into phase codes at the step's angle.
fn measure_path(cfg: &Config) {
    let cfg = Config {
        meas_ke_time_s: 0.1,
        meas_r_time_s: 0.01,
        ..*cfg
    };
    let Ok(mut ctl) = Controller::new(&cfg) else {
        exit(9)
    };
    if ctl.set_mode(Mode::Measure).is_err() {
        exit(10);
    }
    let (r, l, ts) = (2.0f32, 5e-3f32, 1.0 / cfg.pwm_hz);
    let mut i = [0.0f32; 2];
    let z = cfg.adc_zero_code as f32;
    let mut s = RawSample {
        i_abc: [cfg.adc_zero_code; 3],
        v_bus: 2458,
        encoder: 7,
    };
    let mut n = 0u32;
    while ctl.mode() == Mode::Measure && n < 100_000 {
        black_box(regen_step_measure(&mut ctl, s, n));
        let t = ctl.telemetry();
        let v = [t.v_dq.d.to_num::<f32>(), t.v_dq.q.to_num::<f32>()];
        for k in 0..2 {
            i[k] += (v[k] - r * i[k]) * ts / l;
        }
        let (sn, cs) = t.theta_e.sin_cos();
        let (sn, cs) = (sn.to_num::<f32>(), cs.to_num::<f32>());
        let a = i[0] * cs - i[1] * sn;
        let b = i[0] * sn + i[1] * cs;
        let ph = [a, -0.5 * a + 0.866_025_4 * b, -0.5 * a - 0.866_025_4 * b];
        for (code, p) in s.i_abc.iter_mut().zip(ph) {
            *code = (z + p / cfg.amps_per_count + 0.5) as u16;
        }
        n += 1;
        if n.is_multiple_of(20) {
            ctl.supervise();
        }
    }
    let m = ctl.measurement();
    if m.phase() != regen_fw::commission::Phase::Done {
        exit(11);
    }
    let rel = m.r.mean() / r - 1.0;
    if !(rel > -0.05 && rel < 0.05) {
        exit(12);
    }
}

/// The running step with a capture armed: the step to its outputs, then the capture's
/// sample as the period takes it after the outputs (`Period::finish` → `Capture::record`),
/// counted together on a copy of the controller every step of the replay, for each capture of
/// `capture_settings` (the count is the worst over them). `p` is the period's power
/// (`Controller::p_elec` after this step, computed on another copy): the period's energy sum
/// computes it in every period,
/// with or without a capture (counted apart, `regen_period_power`): while a capture is
/// active it is computed after the outputs instead of at the next period's start
/// (`Period::finish`), as here.
#[no_mangle]
#[inline(never)]
pub fn regen_step_cap(
    ctl: &mut Controller,
    s: &RawSample,
    cap: &mut Capture<SAMPLES>,
    p: i32,
) -> Actuation {
    let a = ctl.step_outputs(s);
    if cap.active() {
        cap.record(ctl, p);
    }
    a
}

/// The period's electrical power for its energy sum (`Period::step`, or `Period::finish`
/// while a capture is active).
#[no_mangle]
#[inline(never)]
pub fn regen_period_power(ctl: &Controller) -> i32 {
    ctl.p_elec().to_bits()
}

/// The capture's sample alone (`Capture::record`, each capture of `capture_settings`).
#[no_mangle]
#[inline(never)]
pub fn regen_cap_record(ctl: &mut Controller, cap: &mut Capture<SAMPLES>, p: i32) {
    if cap.active() {
        cap.record(ctl, p)
    }
}

/// The capture's sample for the load step's channels (`iq,iq_ref`, trigger `cmd`, never
/// given: armed for the whole replay).
#[no_mangle]
#[inline(never)]
pub fn regen_cap_record_iq(ctl: &mut Controller, cap: &mut Capture<SAMPLES>, p: i32, _k: u32) {
    // (A fourth argument: a body of its own.)
    if cap.active() {
        cap.record(ctl, p)
    }
}

/// The captures counted, each armed again once ready: their samples go through the same
/// function (`regen_cap_record`, and `regen_step_cap` after the step), so the count is the
/// worst over them all, whichever is dearest. Every slot is read whatever `n_ch`, and any
/// channel costs the same (an indexed load of the step's record, the power included, which
/// the sample puts into the record's power word); the trigger kinds cost differently. 0: four
/// channels (`p`, `w`, `x`, `ia`) and a level trigger on phase a's current crossing zero on
/// either edge, no pre-trigger share: it fires at the first crossing (that sample also starts
/// the post-trigger part) and at the electrical frequency after each re-arm, so armed, firing
/// and triggered samples are all counted; 1: a fault trigger (none latches in the replay: its
/// armed sample); 2: a command trigger, given every 700 periods; 3: a level trigger on the
/// power (its rising edge through 0 W); 4: one channel and a level trigger on the bus voltage
/// (its falling edge at 36 V).
const CAPS: usize = 5;
/// The captures of the replay: `CAPS` counted alone, `CAPS` counted with the step, the load
/// step's.
static mut RINGS: [Capture<SAMPLES>; 2 * CAPS + 1] = [const { Capture::new() }; 2 * CAPS + 1];
fn capture_settings(j: usize) -> Settings {
    let trig = match j {
        0 => Trigger::Level {
            ch: 0,
            edge: Edge::Both,
            level: 0.0,
        },
        1 => Trigger::Fault,
        2 => Trigger::Cmd,
        3 => Trigger::Level {
            ch: 12,
            edge: Edge::Rise,
            level: 0.0,
        },
        _ => Trigger::Level {
            ch: 9,
            edge: Edge::Fall,
            level: 36.0,
        },
    };
    Settings {
        ch: if j == 0 {
            [12, 10, 11, 0]
        } else {
            [0, 3, 7, 12]
        },
        n_ch: if j == 4 { 1 } else { 4 },
        div: 1,
        pre_pct: if j == 0 { 0 } else { 10 },
        trig,
    }
}

/// One protection supervision tick (1 kHz, every `supervise_every()` = 20 steps), counted
/// separately from the step.
#[no_mangle]
#[inline(never)]
pub fn regen_supervise(ctl: &mut Controller) {
    ctl.supervise()
}

// Pieces of the step, each counted on its own (`count.sh ELF piece_…`) with the values of
// the same recorded run; each count includes a call and its argument passing.

#[no_mangle]
#[inline(never)]
pub fn piece_encoder(e: &mut Encoder, raw: u16, g: &EncoderGains) -> Angle {
    e.update(raw, g)
}

#[no_mangle]
#[inline(never)]
pub fn piece_sin_cos(a: Angle) -> (Q, Q) {
    a.sin_cos()
}

#[no_mangle]
#[inline(never)]
pub fn piece_rotate(r: &Rotation, s: Q, c: Q) -> (Q, Q) {
    r.rotate(s, c)
}

#[no_mangle]
#[inline(never)]
pub fn piece_park(v: AlphaBeta, s: Q, c: Q) -> Dq {
    park_bounded(v, s, c)
}

#[no_mangle]
#[inline(never)]
pub fn piece_inverse_park(v: Dq, s: Q, c: Q) -> AlphaBeta {
    inverse_park_bounded(v, s, c)
}

#[no_mangle]
#[inline(never)]
pub fn piece_pi(pi: &mut CurrentPi, err: Dq, ff: Dq, g: &PiGains, v_max: Q) -> PiOutput {
    pi.update(err, ff, g, v_max)
}

#[no_mangle]
#[inline(never)]
pub fn piece_svpwm(v: AlphaBeta, v_bus: Q) -> [Duty; 3] {
    modulate_limited(v, inv_bus(v_bus))
}

#[no_mangle]
#[inline(never)]
pub fn piece_gain(g: Gain, x: Q) -> Q {
    g.scale(x)
}

/// Runs the pieces on the values of the step just taken (results discarded).
fn pieces(ctl: &Controller, s: &RawSample, enc: &mut Encoder, pi: &mut CurrentPi) {
    let g = ctl.gains();
    let t = ctl.telemetry();
    let th = black_box(piece_encoder(enc, s.encoder, &g.enc));
    let (sn, cs) = piece_sin_cos(t.theta_e);
    black_box(piece_rotate(&Rotation::of(Angle(th.0 >> 12)), sn, cs));
    let i_ab = AlphaBeta {
        alpha: t.i_abc[0],
        beta: t.i_abc[1],
    };
    black_box(piece_park(i_ab, sn, cs));
    let err = Dq {
        d: t.i_ref.d - t.i_dq.d,
        q: t.i_ref.q - t.i_dq.q,
    };
    let ff = Dq {
        d: Q::ZERO,
        q: g.ke.scale(t.omega_m),
    };
    let v_max = g.v_lim_per_bus.scale(t.v_bus);
    let o = piece_pi(pi, err, ff, &g.pi, v_max);
    black_box(piece_gain(g.k.ke_per_vel, Q::from_bits(th.0 as i32 >> 8)));
    let v_ab = piece_inverse_park(o.v, sn, cs);
    black_box(piece_svpwm(v_ab, t.v_bus));
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
    boot_paths(&cfg);
    measure_path(&cfg);
    let half = VECTORS.len() / STEP_BYTES / 2;
    let every = ctl.supervise_every() as usize;
    let mut k = 0usize;
    let mut bad_cfg = false;
    let mut enc = Encoder::default();
    let mut pi = CurrentPi::default();
    // The eleven captures (16 KiB each) in static RAM, not on the stack.
    // SAFETY: `main` runs once, on the only thread, and takes the only reference.
    let rings = unsafe { &mut *core::ptr::addr_of_mut!(RINGS) };
    let (caps, rest) = rings.split_at_mut(CAPS);
    let (caps_step, rest) = rest.split_at_mut(CAPS);
    let cap_iq = &mut rest[0];
    for (j, c) in caps.iter_mut().chain(caps_step.iter_mut()).enumerate() {
        c.arm(&capture_settings(j % CAPS), cfg.ts(), ctl.gains());
    }
    let mut fired = 0u32;
    cap_iq.arm(
        &Settings {
            ch: [4, 6, 0, 0],
            n_ch: 2,
            div: 1,
            pre_pct: 20,
            trig: Trigger::Cmd,
        },
        cfg.ts(),
        ctl.gains(),
    );
    let (digest, steps) = replay(&mut ctl, VECTORS, |c, s| {
        if k == half {
            let new = Config {
                r_load_ohm: 2.0,
                ..cfg
            };
            black_box(regen_set_config(&mut c.clone(), &new));
            match regen_compile(c, &new) {
                Some(compiled) => {
                    let mut mail = Pending::EMPTY;
                    mail.cfg = Slot::Full(compiled);
                    let mut per = Period::NEW;
                    regen_install(&mut per, c, &mut mail);
                    black_box(regen_step_swapped(&mut c.clone(), s, k));
                }
                None => bad_cfg = true,
            }
        }
        if k % 1000 == 500 {
            let mut copy = c.clone();
            let _ = copy.law_mut();
            black_box(regen_step_refresh(&mut copy, s));
            // Full-scale phase current (over-current), a bus code above the 95 V trip (3,243)
            // and both, each latched by the step on a copy.
            for (code, bus) in [(4095, s.v_bus), (s.i_abc[1], 3300), (4095, 3300)] {
                let mut copy = c.clone();
                let both = code == 4095 && bus == 3300;
                let a = if both {
                    black_box(regen_step_trip2(&mut copy, *s, code, bus))
                } else {
                    black_box(regen_step_trip(&mut copy, *s, code, bus))
                };
                // Safe in the period found: the bridge open, or the phases shorted (all
                // low-side switches on).
                let safe = !a.enable || a.duties.iter().all(|d| *d == Duty::ZERO);
                if copy.fault().is_none() || !safe {
                    bad_cfg = true;
                }
                if both {
                    regen_trip_finish2(&mut copy, 2);
                } else {
                    regen_trip_finish(&mut copy);
                }
                // Both faults recorded when both were found (the over-voltage as a later one
                // when the over-current is the record's).
                let ov = Fault::BusOverVoltage.code();
                let recorded = copy.protection().record().is_some_and(|r| {
                    !both || r.fault == Fault::BusOverVoltage || r.later & 1 << ov != 0
                });
                if !recorded {
                    bad_cfg = true;
                }
            }
        }
        // The step with each capture armed, on a copy (the same step as the one below), and
        // each capture's sample alone (each capture armed again once ready).
        let p_next = {
            let mut copy = c.clone();
            copy.step_outputs(s);
            copy.p_elec().to_bits()
        };
        let p = regen_period_power(c);
        for j in 0..CAPS {
            let (cs, cr) = (&mut caps_step[j], &mut caps[j]);
            if j == 2 && k % 700 == 350 {
                cs.trigger_now();
                cr.trigger_now();
            }
            black_box(regen_step_cap(&mut c.clone(), s, cs, p_next));
            regen_cap_record(c, cr, p);
            for cp in [cs, cr] {
                if cp.state() == State::Ready {
                    cp.arm(&capture_settings(j), c.config().ts(), c.gains());
                    fired += (j == 0) as u32;
                }
            }
        }
        regen_cap_record_iq(c, cap_iq, p, k as u32);
        if cap_iq.state() != State::Armed {
            bad_cfg = true;
        }
        k += 1;
        let a = regen_step(c, s);
        c.complete_latch();
        // On a copy: the recorded sequence starts at speed with the observer at rest, a
        // start-up current transient (−10 A for a few ms) that the force check rightly trips
        // on; the step's digest stays that of the loop alone.
        if k.is_multiple_of(every) {
            regen_supervise(&mut c.clone());
        }
        pieces(c, s, &mut enc, &mut pi);
        a
    });
    // Both captures fired and filled several times (phase a's current crosses zero at the
    // electrical frequency).
    if bad_cfg || fired < 4 {
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
    loop {
        cortex_m::asm::wfi();
    }
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    hprintln!("panic");
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}
