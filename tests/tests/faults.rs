//! Fault-injection suite: for each fault kind, many seeded scenarios (motion or excitation
//! level, emulated load, fault parameters, moment of injection) on the closed-loop simulator
//! with the unchanged firmware. For every run: nothing panics, the drive reaches its safe
//! state within the kind's stated time, the true bus voltage stays under its absolute
//! maximum, the true phase currents stay within their limit, the energy ledger closes, and
//! the fault is reported with the right name (or, for the bus-management kinds, no fault
//! and the right warning). Prints how many runs of each kind passed; all must.
//!
//! `cargo test -p regen-tests --test faults -- --nocapture` (CI: 24 seeds per kind under the
//! resistor law, and 12 per kind and law for the law-independent kinds under the four other
//! laws); `FAULT_SEEDS=500 cargo test --release -p regen-tests --test faults -- --ignored
//! --nocapture` for the long runs (print the same tables and the worst times).
//!
//! Limits (docs/protection.md):
//! * **Bus absolute maximum 450 V**: the simulated drive's bus ADC full scale
//!   (`volts_per_count·4096`), taken as the capacitor/MOSFET rating of the 320 V sim bus
//!   (OV trip 420 V, brake 370–380 V, derating 395–415 V).
//! * **Phase current limit** `i_trip + 2·Ts·(2/3·V_bus,peak + K_e·ω_peak)/L`: the trip
//!   compares every sample, a sample over the trip acts one period later (PWM delay), so the
//!   current can exceed the trip level by at most two periods of its steepest possible rise
//!   (full bus across the phase plus the emf), with the run's own peaks.

use hal_sim::faults::{FaultSim, Inject};
use hal_sim::plant::{Drive, Excitation, Motion};
use hal_sim::scenario::Scenario;
use rayon::prelude::*;
use regen_fw::protect::{Fault, EMF_TICKS, ISUM_TICKS, SUPERVISE_HZ};
use regen_fw::Mode;
use regen_tests::Rng;

const V_ABS_MAX: f64 = 450.0;

/// What a run must show.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Expect {
    /// This fault latched within `bound_s` of the reference moment.
    Trip { fault: Fault, bound_s: f64 },
    /// No fault; the bus stays below the OV trip; the warning bit was seen.
    Manage { warning: u8 },
    /// No fault at all.
    Nothing,
}

struct Case {
    sc: Scenario,
    inject: Inject,
    at_s: f64,
    duration_s: f64,
    expect: Expect,
    /// For kinds whose moment is set by the physics, not the injection: measure from the
    /// first period the plant meets this condition (true force above f_trip; or the first of
    /// stroke and force).
    from_plant: Option<PlantCond>,
    /// Expected trip time from the injection for the I²t kind (checked to 5 % + 10 ms).
    i2t_predicted_s: Option<f64>,
}

#[derive(Clone, Copy, Debug)]
enum PlantCond {
    Force(f64),
    /// Excitation beyond the rating: whichever the plant meets first decides the right
    /// fault: the true travel outside ±lim (stroke_limit), or the true electromagnetic force,
    /// filtered like the firmware's (τ = f_filter_s), above f_trip (over_force: once the emf
    /// exceeds what the bus can oppose, the current and the force leave the rated clip).
    /// The firmware filters the 1 kHz-sampled, ADC-quantised q current, the test the plant's
    /// period-mean force: they agree within a few % when the loop saturates, so over_force
    /// is right once the test's filtered force passed 0.95·f_trip before the stroke, and
    /// required once it passed 1.05·f_trip; stroke_limit otherwise. Within `AMBIGUOUS_S`
    /// of each other either name is right.
    StrokeOrForce {
        lim: f64,
        f_trip: f64,
        tau: f64,
    },
}

const AMBIGUOUS_S: f64 = 0.003;

/// The imposed bench motion at constant speed (triangle), at `v` m/s.
fn imposed(rng: &mut Rng, r_min: f64, r_max: f64) -> Scenario {
    let amp = rng.uni(0.05, 0.1);
    let v = rng.uni(0.12, 0.35);
    let mut sc = Scenario::imposed(
        Motion::Triangle {
            amplitude_m: amp,
            freq_hz: v / (4.0 * amp),
        },
        rng.log_uni(r_min, r_max),
        1.0,
    );
    sc.record.channels.clear();
    sc.sensors.current_noise_a = 0.02;
    sc.sensors.vbus_noise_v = 0.2;
    sc.sensors.seed = rng.next_u64();
    sc
}

fn set(sc: &mut Scenario, name: &str, v: f64) {
    sc.law.set.insert(name.into(), v);
}

const KINDS: &[&str] = &[
    "current_open",
    "current_stuck",
    "current_noise",
    "current_offset",
    "current_offset_small",
    "bus_sensor_open",
    "bus_sensor_rail",
    "bus_sensor_stuck",
    "bus_sensor_noise",
    "encoder_stuck",
    "encoder_glitch",
    "encoder_runaway",
    "encoder_noise",
    "load_disconnect",
    "load_disconnect_brake_open",
    "overexcite_stroke",
    "overload_force",
    "overload_i2t",
    "overrun",
    "overrun_tolerated",
];

fn case(kind: &str, seed: u64) -> Case {
    let mut rng = Rng(seed ^ 0xA5A5_0000 ^ (kind.len() as u64) << 40);
    for b in kind.bytes() {
        rng.0 = rng.0.rotate_left(5) ^ b as u64;
    }
    let at_s = rng.uni(0.15, 0.5);
    let ts = 1.0 / 20_000.0;
    let tick = 1.0 / SUPERVISE_HZ as f64;
    // Instantaneous checks: the falsified sample trips in its own period (≤ 1 period after
    // the injection instant), the safe actuation is applied from the next one.
    let instant = 2.0 * ts;
    let mut from_plant = None;
    let mut i2t_predicted_s = None;
    let (sc, inject, expect, post) = match kind {
        "current_open" => (
            imposed(&mut rng, 5.0, 300.0),
            Inject::CurrentOpen {
                phase: rng.pick(3),
                high: rng.next_u64() & 1 == 0,
            },
            Expect::Trip {
                fault: Fault::OverCurrent,
                bound_s: instant,
            },
            0.1,
        ),
        // A frozen phase with ≥ 1.4 A flowing (R_L ≤ 30 Ω at ≥ 0.12 m/s): |i_true − c| >
        // 0.5 A for at least 72 % of each electrical period (a sine of amplitude I stays
        // within 0.5 A of its peak for acos(1 − 0.5/I)/π ≤ 28 % of it), so the leaky count
        // rises by ≥ 0.44 per tick on average: ISUM_TICKS/0.44 ≈ 12 ms plus one electrical
        // period (≤ 27 ms at 0.12 m/s) plus a tick: 40 ms; stated 60 ms for the triangle's
        // reversals (the current passes through zero once per stroke).
        "current_stuck" => (
            imposed(&mut rng, 3.0, 30.0),
            Inject::CurrentStuck { phase: rng.pick(3) },
            Expect::Trip {
                fault: Fault::CurrentSensor,
                bound_s: 0.06,
            },
            0.2,
        ),
        // σ ≥ 1 A: P(|n| > 0.5 A) ≥ 0.62, the leaky count drifts up ≥ 0.23 per tick, 5 ticks
        // in ≈ 22 ms on average; 100 ms leaves four times that for the random walk.
        "current_noise" => (
            imposed(&mut rng, 5.0, 300.0),
            Inject::CurrentNoise {
                phase: rng.pick(3),
                sigma_a: rng.uni(1.0, 3.0),
            },
            Expect::Trip {
                fault: Fault::CurrentSensor,
                bound_s: 0.1,
            },
            0.2,
        ),
        // |offset| ≥ 1 A = 2× the 0.5 A tolerance: the sum is over it every tick, the count
        // reaches ISUM_TICKS in ISUM_TICKS ticks, +1 tick of phase.
        "current_offset" => (
            imposed(&mut rng, 5.0, 300.0),
            Inject::CurrentOffset {
                phase: rng.pick(3),
                offset_a: rng.sign() * rng.uni(1.0, 3.0),
            },
            Expect::Trip {
                fault: Fault::CurrentSensor,
                bound_s: (ISUM_TICKS as f64 + 1.0) * tick + instant,
            },
            0.1,
        ),
        // An offset under the tolerance (≤ 0.3 A with 0.02 A noise and 1.5 LSB of rounding,
        // < 0.4 A) is torque ripple, not a fault: the drive keeps running.
        "current_offset_small" => (
            imposed(&mut rng, 5.0, 300.0),
            Inject::CurrentOffset {
                phase: rng.pick(3),
                offset_a: rng.sign() * rng.uni(0.05, 0.3),
            },
            Expect::Nothing,
            0.3,
        ),
        "bus_sensor_open" => (
            imposed(&mut rng, 5.0, 300.0),
            Inject::BusSensorOpen,
            Expect::Trip {
                fault: Fault::BusUnderVoltage,
                bound_s: instant,
            },
            0.1,
        ),
        "bus_sensor_rail" => (
            imposed(&mut rng, 5.0, 300.0),
            Inject::BusSensorRail,
            // A reading at the rail without passing the trip first: a sensor fault (open),
            // not an over-voltage (a short held by a false reading would brake hard for
            // nothing).
            Expect::Trip {
                fault: Fault::BusSensor,
                bound_s: instant,
            },
            0.1,
        ),
        // A bus reading frozen while the source holds the bus, or noisy (2–8 V rms against
        // the 100 V margins to the OV and UV trips, 12σ): the modulation is scaled by a
        // wrong or noisy bus, which the current loop's integral absorbs; no fault. (Frozen
        // with the source lost is a double fault the ADC cannot see: the board's bus
        // comparator is the protection, docs/protection.md.)
        "bus_sensor_stuck" => (
            imposed(&mut rng, 5.0, 300.0),
            Inject::BusSensorStuck,
            Expect::Nothing,
            0.3,
        ),
        "bus_sensor_noise" => (
            imposed(&mut rng, 5.0, 300.0),
            Inject::BusSensorNoise {
                sigma_v: rng.uni(2.0, 8.0),
            },
            Expect::Nothing,
            0.3,
        ),
        // ±1–10 counts of jitter per period (≤ 0.03 rad electrical): the PLL filters it, the
        // 1 ms raw speed errs by at most 2·10 counts = 12.6 rad/s, far under ω_max; no fault.
        "encoder_noise" => (
            imposed(&mut rng, 5.0, 300.0),
            Inject::EncoderNoise {
                counts: 1 + rng.pick(10) as u16,
            },
            Expect::Nothing,
            0.3,
        ),
        // After the stop the PLL speed decays within ≈ 2/ω_b = 3 ms (100 Hz); the true emf
        // (≥ 44 V at 0.12 m/s) then exceeds the allowance (10 V + 50 %) every tick: EMF_TICKS
        // ticks; the triangle's reversal costs at most one tick of count: 20 + 3 + 2 ms,
        // stated 40 ms.
        "encoder_stuck" => (
            imposed(&mut rng, 5.0, 300.0),
            Inject::EncoderStuck,
            Expect::Trip {
                fault: Fault::EncoderLoss,
                bound_s: EMF_TICKS as f64 * tick + 0.02,
            },
            0.2,
        ),
        // A jump of more than 20,000 rpm's worth of counts in one period (167 at 10,000
        // cpr and 20 kHz).
        "encoder_glitch" => (
            imposed(&mut rng, 5.0, 300.0),
            Inject::EncoderGlitch {
                counts: (rng.sign() * rng.uni(200.0, 5_000.0)) as i32,
            },
            Expect::Trip {
                fault: Fault::EncoderImplausible,
                bound_s: instant,
            },
            0.1,
        ),
        // 70–160 counts per period on top of the true motion (≤ 0.35 m/s = 4.4 counts per
        // period): ≥ 65.6 counts per period = 824 rad/s, above ω_max = 628 rad/s. The check
        // uses the raw count over each 1 ms tick: the first whole tick after the injection
        // sees it, ≤ 2 ticks; stated 3 ms. (A runaway that stays under ω_max, as 60 counts
        // against a reverse stroke would, is not implausible: the wrong angle then drives
        // the current out of its clip and the force check opens the drive.)
        "encoder_runaway" => (
            imposed(&mut rng, 5.0, 300.0),
            Inject::EncoderRunaway {
                counts_per_step: (rng.sign() * rng.uni(70.0, 160.0)) as i32,
            },
            Expect::Trip {
                fault: Fault::SpeedImplausible,
                bound_s: 2.0 * tick + instant,
            },
            0.1,
        ),
        "load_disconnect" => {
            let mut sc = imposed(&mut rng, 3.0, 100.0);
            sc.bus.initial_v = rng.uni(330.0, 365.0);
            sc.bus.source_v = Some(sc.bus.initial_v);
            (
                sc,
                Inject::LoadDisconnect { brake_open: false },
                Expect::Manage {
                    warning: regen_fw::protect::warn::BRAKING,
                },
                0.6,
            )
        }
        "load_disconnect_brake_open" => {
            let mut sc = imposed(&mut rng, 3.0, 100.0);
            sc.bus.initial_v = rng.uni(350.0, 385.0);
            sc.bus.source_v = Some(sc.bus.initial_v);
            (
                sc,
                Inject::LoadDisconnect { brake_open: true },
                Expect::Manage {
                    warning: regen_fw::protect::warn::DERATING,
                },
                0.6,
            )
        }
        // The reference TMD driven 4–8× beyond its design excitation: the rated clip holds
        // the force, the travel grows to the stroke end. Measured from the first period the
        // true travel is outside the stroke: the PLL position follows a ramp without lag
        // (type 2) and the check runs every tick: 1 tick + 1 ms of PLL transient.
        "overexcite_stroke" => {
            let r = rng.log_uni(30.0, 1000.0);
            let a0 = rng.uni(0.5, 1.5);
            let mut sc = Scenario::tmd(r);
            sc.record.channels.clear();
            if let Drive::Structure { excitation, .. } = &mut sc.drive {
                *excitation = Excitation::Sine {
                    a0_m_s2: a0,
                    freq_hz: 0.5,
                };
            }
            let lim = rng.uni(0.04, 0.1);
            set(&mut sc, "x_min_m", -lim);
            set(&mut sc, "x_max_m", lim);
            from_plant = Some(PlantCond::StrokeOrForce {
                lim,
                f_trip: 1_300.0,
                tau: 0.01,
            });
            (
                sc,
                Inject::Overexcite {
                    factor: rng.uni(5.0, 10.0) / a0,
                },
                Expect::Trip {
                    fault: Fault::StrokeLimit,
                    bound_s: 2.0 * tick + instant,
                },
                3.0,
            )
        }
        // The current limit set 2–3× above the rating (i_max), the load stepped to 1–3 Ω at
        // a speed where it asks more: the force sits at 1.65–2.5× f_trip. From the first
        // period the true force exceeds f_trip, the filter (τ = 10 ms) needs
        // τ·ln(F/(F − f_trip)) ≤ 9.3 ms after the force settles (≤ 2 ms for the current
        // loop and its rise through the trip level), + 1 tick: stated 20 ms.
        "overload_force" => {
            let mut sc = imposed(&mut rng, 300.0, 1000.0);
            sc.firmware.i_max_a = (rng.uni(2.0, 3.0) * 1.937) as f32;
            from_plant = Some(PlantCond::Force(1_300.0));
            (
                sc,
                Inject::Overload {
                    r_load_ohm: rng.uni(1.0, 3.0) as f32,
                },
                Expect::Trip {
                    fault: Fault::OverForce,
                    bound_s: 0.02,
                },
                0.3,
            )
        }
        // A machine with a continuous current of 1.0–1.5 A behind the default clip
        // (1.937 A, within the force rating): from cold, I²t reaches 1 at
        // τ·ln(θ∞/(θ∞ − 1)), θ∞ = (i_max/I_cont)².
        "overload_i2t" => {
            let mut sc = imposed(&mut rng, 300.0, 1000.0);
            let ic = rng.uni(1.0, 1.5);
            let tau = rng.uni(0.2, 1.0);
            set(&mut sc, "i2t_cont_a", ic);
            set(&mut sc, "i2t_tau_s", tau);
            let th = (1.937f64 / ic).powi(2);
            let t = tau * (th / (th - 1.0)).ln();
            i2t_predicted_s = Some(t);
            (
                sc,
                Inject::Overload {
                    r_load_ohm: rng.uni(0.5, 2.0) as f32,
                },
                Expect::Trip {
                    fault: Fault::MachineI2t,
                    bound_s: 1.05 * t + 0.01,
                },
                t + 0.2,
            )
        }
        // One overrun every 1–10 periods: the bucket gains 20/n − 1 ≥ 1 per tick, trips past
        // overrun_max = 10 in ≤ 11 ticks (+1).
        "overrun" => (
            imposed(&mut rng, 5.0, 300.0),
            Inject::Overrun {
                every: 1 + rng.pick(10) as u32,
            },
            Expect::Trip {
                fault: Fault::LoopOverrun,
                bound_s: 12.0 * tick + instant,
            },
            0.1,
        ),
        // One every 25–100 periods: under the tolerated one per ms, no fault.
        "overrun_tolerated" => (
            imposed(&mut rng, 5.0, 300.0),
            Inject::Overrun {
                every: 25 + rng.pick(76) as u32,
            },
            Expect::Nothing,
            0.3,
        ),
        k => panic!("unknown kind {k}"),
    };
    Case {
        duration_s: at_s + post,
        sc,
        inject,
        at_s,
        expect,
        from_plant,
        i2t_predicted_s,
    }
}

/// One run: Ok(time from the reference moment to the safe state, s; 0 when no trip) or the
/// reason it failed.
fn run(c: &Case) -> Result<f64, String> {
    let sim = c.sc.build()?;
    let cfg = *sim.controller().config();
    let ts = sim.period();
    let l = c.sc.screw.lead_m_per_rad;
    let mut fs = FaultSim::new(sim, c.inject, c.at_s, 7);
    let n = (c.duration_s / ts).round() as u64;
    let (mut v_peak, mut w_peak, mut i_peak) = (0.0f64, 0.0f64, 0.0f64);
    let mut t_ref: Option<f64> = None;
    let mut t_trip: Option<f64> = None;
    let mut warn_seen = 0u8;
    // Plant-side first crossings for StrokeOrForce, and the filtered true force.
    let (mut f_filt, mut t_stroke, mut t_force, mut t_force_hi) =
        (0.0f64, None::<f64>, None::<f64>, None::<f64>);
    // First period after the injection with the true electromagnetic force above f_trip.
    let mut t_true_over_force = None::<f64>;
    for _ in 0..n {
        fs.step()?;
        let sim = &fs.sim;
        let t = sim.time();
        let vb = sim.v_bus();
        v_peak = v_peak.max(vb);
        w_peak = w_peak.max(sim.motion().1.abs() / l);
        i_peak = sim.currents().iter().fold(i_peak, |m, i| m.max(i.abs()));
        if vb >= V_ABS_MAX {
            return Err(format!("bus {vb:.1} V ≥ {V_ABS_MAX} V at t = {t:.4}"));
        }
        if !vb.is_finite() {
            return Err("non-finite bus voltage".into());
        }
        let ctl = sim.controller();
        warn_seen |= ctl.protection().warnings;
        if fs.active() && t_true_over_force.is_none() && sim.force().1.abs() > cfg.f_trip_n as f64 {
            t_true_over_force = Some(t);
        }
        if fs.active() && t_ref.is_none() {
            t_ref = match c.from_plant {
                None => Some(c.at_s),
                Some(PlantCond::Force(f)) => (sim.force().1.abs() > f).then_some(t),
                Some(PlantCond::StrokeOrForce { .. }) => None,
            };
        }
        if let (true, Some(PlantCond::StrokeOrForce { lim, f_trip, tau })) =
            (fs.active(), c.from_plant)
        {
            f_filt += (sim.force().1 - f_filt) * ts / (tau + ts);
            if t_stroke.is_none() && sim.motion().0.abs() > lim {
                t_stroke = Some(t);
            }
            if t_force.is_none() && f_filt.abs() > 0.95 * f_trip {
                t_force = Some(t);
            }
            if t_force_hi.is_none() && f_filt.abs() > 1.05 * f_trip {
                t_force_hi = Some(t);
            }
        }
        match (ctl.fault(), t_trip) {
            (Some(f), None) => {
                if !fs.active() {
                    return Err(format!("{} before the injection at t = {t:.4}", f.name()));
                }
                t_trip = Some(t);
            }
            (None, Some(_)) => return Err("fault cleared by itself".into()),
            _ => {}
        }
        // Once tripped, the drive stays in a safe state: the fault's own, or open if a
        // later fault required it (open dominates).
        if let Some(f) = ctl.fault() {
            let m = ctl.mode();
            let later = ctl.protection().record().map_or(0, |r| r.later);
            let ok = m == f.safe_mode() || (m == Mode::Idle && later != 0);
            if !ok {
                return Err(format!(
                    "{}: mode {} is not its safe state {}",
                    f.name(),
                    m.name(),
                    f.safe_mode().name()
                ));
            }
        }
    }
    let sim = &fs.sim;
    let i_lim = cfg.i_trip_a as f64
        + 2.0 * ts * (2.0 / 3.0 * v_peak + cfg.ke_v_s_per_rad as f64 * w_peak) / c.sc.machine.l_h;
    if i_peak > i_lim {
        return Err(format!("phase current {i_peak:.2} A > limit {i_lim:.2} A"));
    }
    let e = sim.energy();
    if e.relative_residual().abs() > 5e-3 {
        return Err(format!("energy residual {:.2e}", e.relative_residual()));
    }
    let got = sim.controller().fault();
    let mut expect = c.expect;
    if let Some(PlantCond::StrokeOrForce { .. }) = c.from_plant {
        let never = f64::INFINITY;
        let (s, lo, hi) = (
            t_stroke.unwrap_or(never),
            t_force.unwrap_or(never),
            t_force_hi.unwrap_or(never),
        );
        let force_ok = lo < s + AMBIGUOUS_S;
        let stroke_ok = s < never && s < hi + AMBIGUOUS_S;
        let first = match got {
            Some(Fault::OverForce) if force_ok => Some((Fault::OverForce, lo)),
            Some(Fault::StrokeLimit) if stroke_ok => Some((Fault::StrokeLimit, s)),
            _ if s <= lo && s < never => Some((Fault::StrokeLimit, s)),
            _ if lo < never => Some((Fault::OverForce, lo)),
            _ => None,
        };
        let Some((fault, t)) = first else {
            return Err("the plant met neither the stroke nor the force condition".into());
        };
        t_ref = Some(t);
        expect = Expect::Trip {
            fault,
            bound_s: match fault {
                // 1 tick + PLL transient (see the case).
                Fault::StrokeLimit => 3e-3,
                // From the 0.95·f_trip crossing: until the 1.05 one, + 1 tick + 2 ms.
                _ => (hi.min(lo + 0.05) - lo) + 3e-3,
            },
        };
    }
    match expect {
        Expect::Trip { fault, bound_s } => {
            let Some(g) = got else {
                return Err(format!("no fault (expected {})", fault.name()));
            };
            // A lost or wrong angle puts the current loop in a wrong frame: with a law that
            // holds its current command (a clip, an inductive load) the true current can
            // leave its clip before the angle check decides, and the force check then opens
            // the drive first. That is right when the true force did pass f_trip first.
            let angle_fault = matches!(
                fault,
                Fault::EncoderLoss | Fault::EncoderImplausible | Fault::SpeedImplausible
            );
            let force_first = t_true_over_force.is_some_and(|tf| t_trip.is_some_and(|tt| tf <= tt));
            if g != fault && !(angle_fault && g == Fault::OverForce && force_first) {
                return Err(format!(
                    "reported {} (expected {}; plant stroke at {:?} s, force at {:?}/{:?} s; trip at {:?} s)",
                    g.name(),
                    fault.name(),
                    t_stroke,
                    t_force,
                    t_force_hi,
                    t_trip
                ));
            }
            let tr = t_ref.ok_or("tripped before the plant condition")?;
            let dt = t_trip.unwrap_or(tr) - tr;
            if dt > bound_s {
                return Err(format!(
                    "{}: safe state after {:.2} ms > {:.2} ms",
                    fault.name(),
                    dt * 1e3,
                    bound_s * 1e3
                ));
            }
            if let Some(p) = c.i2t_predicted_s {
                if (dt - p).abs() > 0.05 * p + 0.01 {
                    return Err(format!(
                        "I2t trip after {:.3} s, first-order model {:.3} s",
                        dt, p
                    ));
                }
            }
            Ok(dt.max(0.0))
        }
        Expect::Manage { warning } => {
            if let Some(g) = got {
                return Err(format!("{} tripped (bus management expected)", g.name()));
            }
            if v_peak >= cfg.v_bus_ov as f64 {
                return Err(format!("bus {v_peak:.1} V reached the OV trip"));
            }
            if warn_seen & warning == 0 {
                return Err(format!("warning {warning} never raised (seen {warn_seen})"));
            }
            // Where the bus must stay: with the brake, below the derating band (the chopper
            // decides every period and its 50 Ω take ≥ 2.7 kW at 370 V, ≥ 7× the 376 W the
            // clip can regenerate at 0.35 m/s); without it, near the end of the band (the
            // factor is 0 there) plus: 1 ms of the fastest rise (P/(C·V) ≤ 1 V/ms), the
            // sensor noise (0.2 V rms, 4σ) and one ADC count (0.11 V), ≈ 2 V; and the
            // triangle's instantaneous reversals, where the true emf flips while the speed
            // observer lags ≈ 3 ms (100 Hz): the current loop's transient then returns up to
            // ≈ 1.5 J to the bus, 3.6 V on 1 mF at 415 V. Cap: end of band + 6 V, still 5 V
            // under the trip (measured: ≤ 3.5 V over the band, 200 seeds).
            let cap = if warning == regen_fw::protect::warn::BRAKING {
                cfg.derate_start_v as f64
            } else {
                cfg.derate_end_v as f64 + 6.0
            };
            if v_peak > cap {
                return Err(format!("bus peak {v_peak:.1} V above {cap:.1} V"));
            }
            // Reported: the bus peak relative to the end of the derating band, V (×1e-3 so
            // that the table's "ms" column shows volts for these kinds).
            Ok((v_peak - cfg.derate_end_v as f64) * 1e-3)
        }
        Expect::Nothing => match got {
            Some(g) => Err(format!("{} tripped (none expected)", g.name())),
            None => Ok(0.0),
        },
    }
}

fn suite(seeds: u64) {
    suite_over(KINDS, &[None], seeds);
}

/// Runs every kind of `kinds` under every law of `laws` (`None`: the case's own, the
/// resistor law) for `seeds` seeds; prints a row per kind and law; all runs must pass.
fn suite_over(kinds: &[&str], laws: &[Option<OtherLaw>], seeds: u64) {
    let rows: Vec<(&str, Option<OtherLaw>)> = kinds
        .iter()
        .flat_map(|k| laws.iter().map(move |l| (*k, *l)))
        .collect();
    let jobs: Vec<(usize, u64)> = (0..rows.len())
        .flat_map(|k| (0..seeds).map(move |s| (k, s)))
        .collect();
    let t0 = std::time::Instant::now();
    let results: Vec<(usize, u64, Result<f64, String>)> = jobs
        .par_iter()
        .map(|&(k, s)| {
            let r = std::panic::catch_unwind(|| {
                let (kind, law) = rows[k];
                let mut c = case(kind, s);
                if let Some(l) = law {
                    l.apply(&mut c.sc);
                }
                run(&c)
            })
            .unwrap_or_else(|p| {
                Err(format!(
                    "panic: {}",
                    p.downcast_ref::<String>()
                        .cloned()
                        .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                        .unwrap_or_default()
                ))
            });
            (k, s, r)
        })
        .collect();
    println!(
        "fault-injection suite: {} runs in {:.1} s",
        results.len(),
        t0.elapsed().as_secs_f64()
    );
    println!(
        "{:<28} {:>6} {:>6} {:>12}   (worst: ms to the safe state; for load_disconnect*: bus peak − derate_end_v, V)",
        "kind", "passed", "runs", "worst"
    );
    let mut failures = Vec::new();
    for (k, (kind, law)) in rows.iter().enumerate() {
        let name = match law {
            Some(l) => format!("{kind}/{}", l.name()),
            None => kind.to_string(),
        };
        let mine: Vec<_> = results.iter().filter(|r| r.0 == k).collect();
        let ok = mine.iter().filter(|r| r.2.is_ok()).count();
        let worst = mine
            .iter()
            .filter_map(|r| r.2.as_ref().ok())
            .fold(f64::NEG_INFINITY, |m, t| m.max(*t));
        println!(
            "{:<28} {:>6} {:>6} {:>12.2}",
            name,
            ok,
            mine.len(),
            worst * 1e3
        );
        for r in mine {
            if let Err(e) = &r.2 {
                failures.push(format!("{name} seed {}: {e}", r.1));
            }
        }
    }
    for f in failures.iter().take(30) {
        println!("FAIL {f}");
    }
    assert!(failures.is_empty(), "{} runs failed", failures.len());
}

#[test]
fn every_injected_fault_reaches_its_safe_state() {
    suite(24);
}

/// The command laws besides the resistor, as the fault cases run them. The injected faults
/// below are the law-independent ones: sensor, encoder and overrun faults are caught by
/// checks on the samples and the loop, which no law changes, so every case's expectation
/// (fault, bound or no fault) holds as argued for the resistor law. What this adds: no law
/// masks a fault, trips falsely, or keeps the drive out of its safe state.
#[derive(Clone, Copy, Debug)]
enum OtherLaw {
    /// R_L in series with 20 mH: 4–14 Ω of reactance at the cases' 235–685 rad/s electrical.
    Impedance,
    /// Optimal-load tracking from the case's R_L, default dither and period.
    Tracking,
    /// A host-designed LTI controller, here the plain damper i_q* = −0.01 A per rad/s of
    /// shaft speed (0.5–1.4 A at the cases' 0.12–0.35 m/s: inside the 1.94 A clip), for
    /// the two-way law and, clipped to harvesting, the one-way law.
    TwoWay,
    OneWay,
}

impl OtherLaw {
    const ALL: [OtherLaw; 4] = [
        OtherLaw::Impedance,
        OtherLaw::Tracking,
        OtherLaw::TwoWay,
        OtherLaw::OneWay,
    ];

    fn name(self) -> &'static str {
        match self {
            OtherLaw::Impedance => "impedance",
            OtherLaw::Tracking => "tracking",
            OtherLaw::TwoWay => "two_way",
            OtherLaw::OneWay => "one_way",
        }
    }

    fn apply(self, sc: &mut Scenario) {
        sc.law.kind = self.name().into();
        match self {
            OtherLaw::Impedance => set(sc, "l_load_h", 0.02),
            OtherLaw::Tracking => {}
            OtherLaw::TwoWay | OtherLaw::OneWay => {
                let mut d = vec![0.0f32; regen_fw::laws::lti::M];
                d[1] = -0.01;
                sc.law.opt = Some(hal_sim::scenario::OptSpec {
                    a: vec![0.0; regen_fw::laws::lti::N * regen_fw::laws::lti::N],
                    b: vec![0.0; regen_fw::laws::lti::N * regen_fw::laws::lti::M],
                    c: vec![0.0; regen_fw::laws::lti::N],
                    d,
                });
            }
        }
    }
}

/// The kinds whose physics is sized for the resistor law (the current it carries, the bus
/// power, the overload it is switched to, the TMD's excitation); every other kind's detection
/// does not depend on the law (see [`OtherLaw`]).
const RESISTOR_SIZED_KINDS: &[&str] = &[
    "current_stuck",
    "load_disconnect",
    "load_disconnect_brake_open",
    "overexcite_stroke",
    "overload_force",
    "overload_i2t",
];

fn law_independent_kinds() -> Vec<&'static str> {
    let kinds: Vec<_> = KINDS
        .iter()
        .copied()
        .filter(|k| !RESISTOR_SIZED_KINDS.contains(k))
        .collect();
    assert_eq!(kinds.len(), 14);
    kinds
}

#[test]
fn every_law_reaches_the_safe_state() {
    let laws: Vec<Option<OtherLaw>> = OtherLaw::ALL.iter().copied().map(Some).collect();
    suite_over(&law_independent_kinds(), &laws, 12);
}

/// The long variant of the other laws: `FAULT_SEEDS` (default 200) seeds per kind and law.
#[test]
#[ignore]
fn fault_injection_laws_long() {
    let n = std::env::var("FAULT_SEEDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(200);
    let laws: Vec<Option<OtherLaw>> = OtherLaw::ALL.iter().copied().map(Some).collect();
    suite_over(&law_independent_kinds(), &laws, n);
}

/// The long variant: `FAULT_SEEDS` (default 200) seeds per kind.
#[test]
#[ignore]
fn fault_injection_long() {
    let n = std::env::var("FAULT_SEEDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(200);
    suite(n);
}

#[test]
#[ignore]
fn debug_trace() {
    // A trace printer for one case: SEED=n KIND=name [LAW=name] cargo test -p regen-tests
    // --test faults debug_trace -- --ignored --nocapture
    let seed: u64 = std::env::var("SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let kind = std::env::var("KIND").unwrap_or_else(|_| "encoder_stuck".into());
    let mut c = case(&kind, seed);
    // LAW=impedance|tracking|two_way|one_way runs the case under that law.
    if let Ok(name) = std::env::var("LAW") {
        let law = OtherLaw::ALL.into_iter().find(|l| l.name() == name);
        law.expect("LAW: impedance, tracking, two_way or one_way")
            .apply(&mut c.sc);
    }
    let sim = c.sc.build().unwrap();
    let mut fs = FaultSim::new(sim, c.inject, c.at_s, 7);
    let n = (c.duration_s / fs.sim.period()).round() as u64;
    for k in 0..n {
        fs.step().unwrap();
        let s = &fs.sim;
        let ctl = s.controller();
        if k % 100 == 0 || (ctl.fault().is_some() && k % 5 == 0) {
            println!(
                "wraw={:.0} t={:.4} x={:.4} v={:.3} fem={:.0} fw_f={:.0} iq={:.2} iqref={:.2} sat={} vbus={:.1} mode={} fault={:?}",
                ctl.protection().omega_raw(),
                s.time(),
                s.motion().0,
                s.motion().1,
                s.force().1,
                ctl.protection().force_n(),
                ctl.telemetry().i_dq.q.to_num::<f64>(),
                ctl.telemetry().i_ref.q.to_num::<f64>(),
                ctl.telemetry().v_saturated,
                s.v_bus(),
                ctl.mode().name(),
                ctl.fault().map(|f| f.name())
            );
        }
        // Stop 50 ms after the trip.
        let t_trip = ctl.protection().record().map(|r| r.snap.t_ms as f64 * 1e-3);
        if t_trip.is_some_and(|t| s.time() > t + 0.05) {
            break;
        }
    }
}
