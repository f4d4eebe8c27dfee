//! The power stage with its hardware paths (`hal_sim::stage`) under the unchanged firmware,
//! in both voltage classes: the board's 72 V bus with a 100 V-class stage, and the
//! simulator's 320 V bus with a 450 V stage.
//!
//! * `gates_off_sweep`: gates off, no sink, imposed speed swept 0 … ω_max: the peak bus
//!   against speed (CSV and SVG in `CARGO_TARGET_TMPDIR`, copied to `docs/figures/`), the
//!   onset checked against `√3·K_e·ω = V_bus`, the peak against the line emf.
//! * `stage_faults` (CI: `STAGE_SEEDS`, default 6 per kind and class) and
//!   `stage_faults_long` (`--ignored`, `STAGE_SEEDS`, default 1,000): every kind on the
//!   stage. Every run: nothing panics; the true bus under the stage's absolute maximum; the
//!   true phase currents under the stated peak `2·K_e/(p·L)` (the short's own current with
//!   its full offset, the highest the stage carries by design); no unsafe state left latched
//!   at the end (see [`unsafe_at_end`]); the kind's own expectation. Prints the time to the
//!   safe state per kind, its worst case, the bus and current peaks.
//!
//! The brake resistor of both classes is sized so the chopper holds the bus at any speed:
//! `R_b = brake_off_v·p·L/K_e` (the rectified current of an open bridge is bounded by the
//! machine's short-circuit current `K_e/(p·L)`; at that current `R_b` drops `brake_off_v`).

use hal_sim::faults::{FaultSim, Inject};
use hal_sim::plant::Motion;
use hal_sim::plot::{Plot, Series};
use hal_sim::scenario::Scenario;
use hal_sim::stage::{Cpu, StageSpec};
use rayon::prelude::*;
use regen_fw::io::Actuation;
use regen_fw::protect::Fault;
use regen_fw::Mode;
use regen_tests::Rng;

#[derive(Clone, Copy, Debug)]
struct Class {
    name: &'static str,
    v_bus: f64,
    v_abs: f64,
    ov: f32,
    brake: (f32, f32),
    derate: (f32, f32),
    volts_full_scale: f32,
}

impl Class {
    /// The diode onset √3·K_e·ω = V_bus as a linear speed, m/s, for the scenario's machine.
    fn onset(&self, sc: &Scenario) -> f64 {
        self.v_bus / (3f64.sqrt() * sc.machine.ke_v_s_per_rad) * sc.screw.lead_m_per_rad
    }
}

const C72: Class = Class {
    name: "72v",
    v_bus: 72.0,
    v_abs: 100.0,
    ov: 95.0,
    brake: (85.0, 82.0),
    derate: (88.0, 93.0),
    volts_full_scale: 120.0,
};

const C320: Class = Class {
    name: "320v",
    v_bus: 320.0,
    v_abs: 450.0,
    ov: 420.0,
    brake: (380.0, 370.0),
    derate: (395.0, 415.0),
    volts_full_scale: 450.0,
};

/// Short-circuit current K_e/(p·L) of the scenario's machine, A.
fn i_sc(sc: &Scenario) -> f64 {
    sc.machine.ke_v_s_per_rad / (sc.machine.pole_pairs as f64 * sc.machine.l_h)
}

/// A scenario of class `c`: imposed `motion`, emulated load `r_load` Ω.
fn scenario(c: &Class, motion: Motion, r_load: f64) -> Scenario {
    let mut sc = Scenario::imposed(motion, r_load, 1.0);
    sc.record.channels.clear();
    sc.bus.initial_v = c.v_bus;
    sc.bus.source_v = Some(c.v_bus);
    sc.bus.brake_r_ohm = c.brake.1 as f64 / i_sc(&sc);
    let f = &mut sc.firmware;
    f.v_bus_ov = c.ov;
    (f.brake_on_v, f.brake_off_v) = c.brake;
    (f.derate_start_v, f.derate_end_v) = c.derate;
    f.volts_per_count = c.volts_full_scale / 4096.0;
    sc.sensors.current_noise_a = 0.02;
    sc.sensors.vbus_noise_v = 0.2;
    sc
}

/// Constant speed `v` m/s from t = 0 for `t_s` (a triangle's rising quarter).
fn constant_speed(v: f64, t_s: f64) -> Motion {
    let f = 0.25 / t_s;
    Motion::Triangle {
        amplitude_m: v / (4.0 * f),
        freq_hz: f,
    }
}

// ---------------------------------------------------------------------------------------
// Gates off, no sink: the peak bus against speed.

/// Peak bus of class `c` at imposed speed `v` with the gates off and no sink (no source, no
/// brake): the plant alone under `Actuation::OFF`, as a halted MCU in reset leaves it.
fn gates_off_peak(c: &Class, v: f64) -> f64 {
    let t_run = 0.5;
    let mut sc = scenario(c, constant_speed(v, t_run), 1.0);
    sc.bus.source_v = None;
    sc.bus.brake_r_ohm = f64::INFINITY;
    sc.sensors.current_noise_a = 0.0;
    sc.sensors.vbus_noise_v = 0.0;
    let mut sim = sc.build().expect("scenario");
    let n = (t_run / sim.period()).round() as u64;
    let mut peak = 0.0f64;
    for _ in 0..n {
        let _ = sim.take_sample();
        sim.apply_and_advance(&Actuation::OFF);
        peak = peak.max(sim.v_bus());
    }
    peak
}

#[test]
fn gates_off_sweep() {
    let mut rows = Vec::new();
    let mut plots = Vec::new();
    for c in [C72, C320] {
        let sc = scenario(&c, constant_speed(0.1, 1.0), 1.0);
        let (ke, lead) = (sc.machine.ke_v_s_per_rad, sc.screw.lead_m_per_rad);
        let w_max = sc.config().expect("config").omega_max_rad_s as f64;
        // The onset by the formula √3·K_e·ω = V_bus, as a linear speed.
        let v_onset = c.v_bus / (3f64.sqrt() * ke) * lead;
        let n = 48;
        let pts: Vec<(f64, f64)> = (0..=n)
            .into_par_iter()
            .map(|k| {
                let v = (k as f64 / n as f64) * w_max * lead;
                (v, gates_off_peak(&c, v))
            })
            .collect();
        // The onset at every sweep point: the bus rises (by more than 0.1 V) exactly where
        // the line emf exceeds it (points within 1 % of the onset are not judged: the
        // capacitor charges there too slowly to decide in the run's time).
        let step = w_max * lead / n as f64;
        for &(v, p) in &pts {
            let e = 3f64.sqrt() * ke * v / lead;
            if (e / c.v_bus - 1.0).abs() > 0.01 {
                assert_eq!(
                    p > c.v_bus + 0.1,
                    e > c.v_bus,
                    "{}: at {v:.4} m/s the bus peaks at {p:.2} V, line emf {e:.2} V",
                    c.name
                );
            }
        }
        let first = pts
            .iter()
            .find(|p| p.1 > c.v_bus + 0.1)
            .expect("an onset below ω_max")
            .0;
        println!(
            "{}: onset by formula {:.4} m/s, first sweep point above the bus {:.4} m/s (step {:.4})",
            c.name, v_onset, first, step
        );
        // Above the onset the capacitor charges to the line-to-line emf peak √3·K_e·ω (no
        // diode drop modelled); the worst relative deviation is printed and bounded.
        let mut worst = 0.0f64;
        for &(v, p) in &pts {
            let e = 3f64.sqrt() * ke * v / lead;
            // Near the onset the capacitor charges slowly ((e − V)/|Z| → 0): judged from
            // 1.25·V_bus on.
            if e > 1.25 * c.v_bus {
                worst = worst.max((p - e).abs() / e);
            }
            rows.push(vec![
                if c.v_bus < 100.0 { 72.0 } else { 320.0 },
                v,
                v / lead,
                p,
                e.max(c.v_bus),
            ]);
        }
        println!(
            "{}: peak bus vs √3·K_e·ω above the onset: worst {:.3} %; at ω_max {:.0} V (stage max {:.0} V)",
            c.name,
            100.0 * worst,
            pts.last().unwrap().1,
            c.v_abs
        );
        // Measured 0.9 % (the capacitor still charging at the sweep's highest speeds within
        // 0.15 s, and the bus ripple): bounded at 3 %.
        assert!(
            worst < 0.03,
            "{}: peak bus off the line emf by {worst}",
            c.name
        );
        let over = pts.iter().find(|p| p.1 > c.v_abs).map(|p| p.0);
        println!(
            "{}: open bridge, no sink: the bus passes the stage's {:.0} V at {:?} m/s",
            c.name, c.v_abs, over
        );
        plots.push(Series::markers(
            format!("{} bus, peak", c.name),
            pts.clone(),
        ));
        plots.push(Series::line(
            format!("{} onset {:.3} m/s", c.name, v_onset),
            vec![(v_onset, 0.0), (v_onset, c.v_abs)],
        ));
        plots.push(Series::line(
            format!("{} stage maximum", c.name),
            vec![(0.0, c.v_abs), (w_max * lead, c.v_abs)],
        ));
    }
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"));
    hal_sim::cli::output::write_csv(
        &dir.join("gates_off_sweep.csv"),
        &[
            "class_v",
            "speed_m_s",
            "omega_rad_s",
            "peak_bus_v",
            "line_emf_or_bus_v",
        ],
        &rows,
    )
    .expect("csv");
    let mut plot = Plot::new(
        "Gates off, no sink: peak bus against imposed speed",
        "imposed speed (m/s)",
        "peak bus voltage (V)",
    );
    plot.series = plots;
    let p = plot
        .write_svg(&dir.join("gates_off_sweep.svg"))
        .expect("svg");
    println!("written {} and gates_off_sweep.csv", p.display());
}

// ---------------------------------------------------------------------------------------
// Open above the onset: the firmware's own rule, without the stage.

/// The drive open (idle) at an imposed speed above the diode onset, source lost, the 50 Ω
/// brake of the simulator's default bus (undersized for the rectified power): the case
/// `docs/protection.md` left open (320 V, 1.0 m/s: 475 V over the 450 V maximum). The
/// firmware alone, no stage model: over-voltage while open above the onset must short, and
/// the bus stay under the stage's maximum. Returns (bus peak, final mode).
fn open_above_onset(c: &Class, v: f64) -> (f64, Mode, Option<Fault>) {
    let t_run = 0.6;
    let mut sc = scenario(c, constant_speed(v, t_run), 1.0);
    sc.bus.source_v = None;
    sc.bus.brake_r_ohm = 50.0;
    let mut sim = sc.build().expect("scenario");
    sim.controller_mut().set_mode(Mode::Idle).expect("idle");
    let n = (t_run / sim.period()).round() as u64;
    let mut peak = 0.0f64;
    for _ in 0..n {
        sim.step();
        peak = peak.max(sim.v_bus());
    }
    if let Some(r) = sim.controller().protection().record() {
        println!("  later: {:?}", r.later().collect::<Vec<_>>());
    }
    (peak, sim.controller().mode(), sim.controller().fault())
}

#[test]
fn open_above_onset_shorts() {
    for c in [C72, C320] {
        let onset = c.onset(&scenario(&c, constant_speed(0.1, 1.0), 1.0));
        for k in [1.2, 1.6, 2.0, 3.0] {
            let v = k * onset;
            if v > 1.6 {
                continue; // beyond ω_max
            }
            let (peak, mode, fault) = open_above_onset(&c, v);
            println!(
                "{}: open at {v:.3} m/s ({k}× onset): bus peak {peak:.1} V, then {mode:?}, first fault {:?}",
                c.name,
                fault.map(|f| f.name())
            );
            assert!(peak < c.v_abs, "{}: bus {peak:.1} V at {v:.3} m/s", c.name);
            if peak >= c.ov as f64 {
                assert_eq!(mode, Mode::Short, "{}: left open at {v:.3} m/s", c.name);
            }
        }
    }
}

// ---------------------------------------------------------------------------------------
// Fault injection on the stage.

const KINDS: &[&str] = &[
    "mcu_halt",
    "watchdog_reset",
    "comparator_false_trip",
    "bus_divider_rail",
    "bus_divider_open",
    "dac_wrong_low",
    "dac_wrong_high",
    "brake_open_source_lost",
    "source_lost_full_power",
    "current_open",
    "encoder_stuck",
    "encoder_runaway",
    "overrun",
    // The other kinds of faults.rs, with the safety checks only here (their names and times
    // are checked there, in the 320 V class).
    "current_stuck",
    "current_noise",
    "current_offset",
    "bus_sensor_stuck",
    "bus_sensor_noise",
    "encoder_glitch",
    "encoder_noise",
    "overload",
];

struct Case {
    sc: Scenario,
    inject: Inject,
    at_s: f64,
    duration_s: f64,
    speed: f64,
}

fn case(c: &Class, kind: &str, seed: u64) -> Case {
    let mut rng = Rng(seed ^ 0x5A5A_0000 ^ (c.v_bus as u64) << 40);
    let at_s = rng.uni(0.1, 0.3);
    let duration_s = at_s + 0.3;
    // The drive runs below the diode onset: above it the line emf exceeds the bus, the
    // current loop is voltage-limited and the current is no longer controlled (the runs
    // above it are `open_above_onset`). Speeds 0.2 … 0.95 × the onset.
    let onset = c.onset(&scenario(c, constant_speed(0.1, 1.0), 1.0));
    let top = 0.95 * onset;
    let mut speed = rng.uni(0.2 * onset, top);
    let mut r_load = rng.log_uni(1.0, 1000.0);
    let inject = match kind {
        "mcu_halt" => Inject::McuHalt,
        "watchdog_reset" => Inject::WatchdogReset {
            timeout_s: rng.uni(1e-3, 10e-3),
        },
        // Ringing shorter than each break's filter (assumed: 0.02–0.12 µs on a shunt
        // amplifier against BRK's 0.16 µs, 0.1–1.2 µs on the bus divider against BRK2's
        // 1.5 µs); the enable transient (1–8 µs) ends within the arming's settling.
        "comparator_false_trip" => {
            let bus = rng.next_u64() & 1 == 0;
            Inject::ComparatorFalseTrip {
                enable_s: rng.uni(1e-6, 8e-6),
                ring_s: if bus {
                    rng.uni(0.1e-6, 1.2e-6)
                } else {
                    rng.uni(0.02e-6, 0.12e-6)
                },
                ring_every: 1 + (rng.next_u64() % 20) as u32,
                bus,
            }
        }
        "bus_divider_rail" => Inject::BusSensorRail,
        "bus_divider_open" => Inject::BusSensorOpen,
        "dac_wrong_low" => Inject::DacWrong {
            scale: rng.uni(0.3, 0.7),
        },
        "dac_wrong_high" => Inject::DacWrong {
            scale: rng.uni(1.3, 3.0),
        },
        "brake_open_source_lost" => Inject::LoadDisconnect { brake_open: true },
        "source_lost_full_power" => {
            // The highest power of the class: its top speed at the matched load.
            speed = top;
            r_load = 2.41;
            Inject::LoadDisconnect { brake_open: false }
        }
        "current_open" => Inject::CurrentOpen {
            phase: (rng.next_u64() % 3) as usize,
            high: rng.next_u64() & 1 == 0,
        },
        "encoder_stuck" => {
            // The emf check's range: not voltage-limited, emf well above its tolerance:
            // 0.5 … 0.8 × the onset.
            speed = rng.uni(0.5, 0.8) * onset;
            Inject::EncoderStuck
        }
        "encoder_runaway" => Inject::EncoderRunaway {
            counts_per_step: 200 + (rng.next_u64() % 800) as i32,
        },
        "overrun" => Inject::Overrun {
            every: 1 + (rng.next_u64() % 10) as u32,
        },
        "current_stuck" => Inject::CurrentStuck {
            phase: (rng.next_u64() % 3) as usize,
        },
        "current_noise" => Inject::CurrentNoise {
            phase: (rng.next_u64() % 3) as usize,
            sigma_a: rng.uni(1.0, 3.0),
        },
        "current_offset" => Inject::CurrentOffset {
            phase: (rng.next_u64() % 3) as usize,
            offset_a: rng.uni(1.0, 3.0) * if rng.next_u64() & 1 == 0 { 1.0 } else { -1.0 },
        },
        "bus_sensor_stuck" => Inject::BusSensorStuck,
        "bus_sensor_noise" => Inject::BusSensorNoise {
            sigma_v: rng.uni(0.5, 2.0) * c.v_bus / 100.0,
        },
        "encoder_glitch" => Inject::EncoderGlitch {
            counts: (2000 + (rng.next_u64() % 20000) as i32)
                * if rng.next_u64() & 1 == 0 { 1 } else { -1 },
        },
        "encoder_noise" => Inject::EncoderNoise {
            counts: 1 + (rng.next_u64() % 10) as u16,
        },
        "overload" => Inject::Overload {
            r_load_ohm: rng.uni(0.0, 1.0) as f32,
        },
        k => panic!("unknown kind {k}"),
    };
    let amp = rng.uni(0.05, 0.1);
    let mut sc = scenario(
        c,
        Motion::Triangle {
            amplitude_m: amp,
            freq_hz: speed / (4.0 * amp),
        },
        r_load,
    );
    // Imposed speeds beyond the rating in some kinds: the force check is not under test.
    sc.law.set.insert("f_trip_n".into(), f64::INFINITY);
    sc.sensors.seed = rng.next_u64();
    Case {
        sc,
        inject,
        at_s,
        duration_s,
        speed,
    }
}

/// The outcome of one run.
#[derive(Debug, Default, Clone)]
struct Outcome {
    /// Injection to the first protective action (firmware fault, break, reset), s.
    t_safe: Option<f64>,
    /// Injection to the first period whose step reads the injected phase's current
    /// (`current_open`: a phase whose duty in force at the sample exceeds
    /// `shunt::UNREAD_ABOVE` is reconstructed, not read, as on the board), s.
    t_read: Option<f64>,
    v_peak: f64,
    i_peak: f64,
}

/// An unsafe state left latched at the end of a run, if any: the firmware controlling
/// (run/open) with a fault latched; a short held only by a bus reading at the rail; a core
/// halted with its PWM still running; the true bus above the OV trip and still rising.
fn unsafe_at_end(fs: &FaultSim, ov: f64, rising: f64) -> Option<String> {
    let ctl = fs.sim.controller();
    let st = fs.stage.as_ref().expect("stage");
    let cpu_runs = st.cpu == Cpu::Running;
    if cpu_runs && ctl.fault().is_some() && matches!(ctl.mode(), Mode::Run | Mode::Open) {
        return Some(format!("controlling with {:?} latched", ctl.fault()));
    }
    if cpu_runs && ctl.mode() == Mode::Short && ctl.fault() == Some(Fault::BusSensor) {
        return Some("short held by a rail reading".into());
    }
    if st.cpu == Cpu::Halted {
        return Some("core halted, PWM running".into());
    }
    // Above the trip and still charging over the last 5 ms (with no sink a charged bus keeps
    // its voltage: that alone is not a state the drive holds; a short opened by an
    // over-current below the onset dumps the winding's energy, ≤ 3/2·L·I_sc²/(C·V) ≈ 14 V
    // at 420 V, into the bus once: over in a few periods).
    if fs.sim.v_bus() > ov && rising > 0.5 {
        return Some(format!(
            "bus {:.1} V above the trip at the end, rising {rising:.1} V in 5 ms",
            fs.sim.v_bus()
        ));
    }
    None
}

fn run(c: &Class, kind: &str, seed: u64) -> Result<Outcome, String> {
    let k = case(c, kind, seed);
    let mut sim = k.sc.build()?;
    // As a board starts: idle with the speed observer tracking, run after 50 ms.
    sim.controller_mut()
        .set_mode(Mode::Idle)
        .map_err(|f| f.name().to_string())?;
    let spec = StageSpec::from_config(sim.controller().config(), c.v_abs);
    let ts = sim.period();
    let i_stated = 2.0 * i_sc(&k.sc);
    let mut fs = FaultSim::new(sim, k.inject, k.at_s, seed).with_stage(spec);
    // The nominal end, extended (by up to 0.3 s) to 50 ms after the first protective
    // action, so the end state is judged after the transients it starts.
    let n = ((k.duration_s + 0.3) / ts).round() as u64;
    let mut o = Outcome::default();
    let mut rebooted = false;
    let mut started = false;
    let mut v_hist = std::collections::VecDeque::new();
    for _ in 0..n {
        let t_now = fs.sim.time();
        if t_now >= k.duration_s && o.t_safe.is_none_or(|t| t_now >= k.at_s + t + 0.05) {
            break;
        }
        if !started && fs.sim.time() >= 0.05 {
            started = true;
            fs.sim
                .controller_mut()
                .set_mode(Mode::Run)
                .map_err(|f| f.name().to_string())?;
        }
        // The duties in force at this period's sample: the last step's output.
        let d_prev = fs.sim.controller().telemetry().duties;
        let t_before = fs.sim.time();
        fs.step()?;
        let t = fs.sim.time();
        if let Inject::CurrentOpen { phase, .. } = k.inject {
            if fs.active()
                && o.t_read.is_none()
                && d_prev[phase].to_bits() <= regen_fw::shunt::UNREAD_ABOVE
            {
                o.t_read = Some((t_before - k.at_s).max(0.0));
            }
        }
        if !fs.active() {
            if let Some(f) = fs.sim.controller().fault() {
                return Err(format!("{} before the injection at t = {t:.4}", f.name()));
            }
        }
        v_hist.push_back(fs.sim.v_bus());
        if v_hist.len() > 100 {
            v_hist.pop_front();
        }
        let vb = fs.sim.v_bus();
        let i = fs.sim.currents().iter().fold(0.0f64, |m, x| m.max(x.abs()));
        o.v_peak = o.v_peak.max(vb);
        o.i_peak = o.i_peak.max(i);
        if vb.is_nan() || vb >= c.v_abs {
            return Err(format!("bus {vb:.1} V ≥ {} V at t = {t:.4}", c.v_abs));
        }
        if i > i_stated {
            return Err(format!(
                "phase current {i:.1} A > {i_stated:.1} A at t = {t:.4}"
            ));
        }
        let st = fs.stage.as_ref().expect("stage");
        rebooted |= st.in_reset();
        if fs.active() && o.t_safe.is_none() {
            let acted = fs.sim.controller().fault().is_some() || st.brk || st.brk2 || st.in_reset();
            if acted {
                o.t_safe = Some(t - k.at_s);
            }
        }
    }
    let rising = v_hist.back().unwrap_or(&0.0) - v_hist.front().unwrap_or(&0.0);
    if let Some(u) = unsafe_at_end(&fs, c.ov as f64, rising) {
        return Err(format!("unsafe at the end: {u}"));
    }
    let st = fs.stage.as_ref().expect("stage");
    let ctl = fs.sim.controller();
    // Each kind's own expectation.
    let got =
        format!(
        "got {:?} (later {:?}) in {:?}, brk {} brk2 {}, t_safe {:?}, bus peak {:.1} V, {:.3} m/s",
        ctl.fault(),
        ctl.protection().record().map(|r| r.later().collect::<Vec<_>>()),
        ctl.mode(),
        st.brk,
        st.brk2,
        o.t_safe,
        o.v_peak,
        k.speed
    );
    let need = |ok: bool, what: &str| {
        if ok {
            Ok(())
        } else {
            Err(format!("{what}: {got}"))
        }
    };
    match kind {
        "mcu_halt" => need(
            o.t_safe.is_some_and(|t| t <= spec.iwdg_s + 2.0 * ts),
            "pins at reset within the watchdog timeout",
        )?,
        "watchdog_reset" => need(rebooted && st.cpu == Cpu::Running, "rebooted and running")?,
        "comparator_false_trip" | "dac_wrong_high" => need(
            !st.brk && !st.brk2 && ctl.fault().is_none(),
            "no trip from a glitch or a high threshold",
        )?,
        "bus_divider_rail" => need(
            ctl.fault() == Some(Fault::BusSensor)
                && ctl.mode() == Mode::Idle
                && o.t_safe.is_some_and(|t| t <= 2.0 * ts),
            "bus_sensor, open, within 2 periods",
        )?,
        "bus_divider_open" => need(
            ctl.fault() == Some(Fault::BusUnderVoltage) && o.t_safe.is_some_and(|t| t <= 2.0 * ts),
            "bus_under_voltage within 2 periods",
        )?,
        "dac_wrong_low" => need(
            st.brk2
                && o.t_safe.is_some_and(|t| t <= 2.0 * ts)
                && latched(ctl, Fault::BusOverVoltage)
                && ctl.mode() == Mode::Idle,
            "BRK2 within 2 periods, reported to the firmware: bus_over_voltage, open",
        )?,
        "source_lost_full_power" => need(
            ctl.fault().is_none() && o.v_peak < c.derate.0 as f64,
            "no fault, the bus held below the derating band",
        )?,
        // Within 2 periods of the first step that reads the open phase: while its duty is
        // above the shunt's window limit it is reconstructed from the other two, and the
        // failed sensor is neither seen nor fed back (without this rule 2 of 100 seeds per
        // class failed the bare 2-period bound, at 11 and 4 periods).
        "current_open" => need(
            ctl.fault() == Some(Fault::OverCurrent)
                && o.t_safe
                    .zip(o.t_read)
                    .is_some_and(|(t, r)| t <= r + 2.0 * ts),
            "over_current within 2 periods of the phase's first read",
        )?,
        "encoder_runaway" => need(
            matches!(
                ctl.fault(),
                Some(Fault::SpeedImplausible | Fault::EncoderImplausible)
            ) && o.t_safe.is_some_and(|t| t <= 2.1e-3),
            "speed_ or encoder_implausible within 2.1 ms",
        )?,
        "overrun" => need(
            ctl.fault() == Some(Fault::LoopOverrun) && o.t_safe.is_some_and(|t| t <= 12.1e-3),
            "loop_overrun within 12.1 ms",
        )?,
        "encoder_stuck" => need(
            ctl.fault().is_some() && o.t_safe.is_some_and(|t| t <= 40e-3),
            "a fault within 40 ms",
        )?,
        _ => {}
    }
    Ok(o)
}

/// `f` is latched, first or later.
fn latched(ctl: &regen_fw::Controller, f: Fault) -> bool {
    ctl.fault() == Some(f)
        || ctl
            .protection()
            .record()
            .is_some_and(|r| r.later().any(|g| g == f))
}

/// A break the stage takes reaches the firmware as the board's period routine reads it
/// (the timer's flag → `Controller::hardware_trip`): the named fault latches within two
/// periods of the comparator's crossing and the mode is open, as the break holds the gates,
/// both from Run (a bus comparator pulse longer than BRK2's filter, then a phase one longer
/// than BRK's) and from the firmware's own short (opened by BRK: the mode says open, not
/// short). Breaks on purpose: no report (the mode stays run) or a report as the rule's
/// trip (bus over-voltage → short while BRK2 holds the gates off) fail it.
#[test]
fn breaks_reach_the_firmware() {
    for (bus, from_short, want) in [
        (true, false, Fault::BusOverVoltage),
        (false, false, Fault::OverCurrent),
        (false, true, Fault::OverCurrent),
    ] {
        let sc = scenario(&C72, constant_speed(0.05, 0.2), 30.0);
        let sim = sc.build().expect("scenario");
        let spec = StageSpec::from_config(sim.controller().config(), C72.v_abs);
        let ts = sim.period();
        // An injection that never comes: the stage alone under the firmware.
        let mut fs = FaultSim::new(sim, Inject::Overrun { every: 1 }, 1e9, 1).with_stage(spec);
        while fs.sim.time() < 0.1 {
            fs.step().expect("step");
        }
        assert_eq!(fs.sim.controller().mode(), Mode::Run);
        if from_short {
            fs.sim
                .controller_mut()
                .set_mode(Mode::Short)
                .expect("short");
            fs.step().expect("step");
        }
        fs.stage.as_mut().expect("stage").glitch(
            if bus {
                2.0 * spec.filter2_s
            } else {
                2.0 * spec.filter_s
            },
            bus,
        );
        let t0 = fs.sim.time();
        while fs.sim.controller().fault().is_none() && fs.sim.time() < t0 + 10.0 * ts {
            fs.step().expect("step");
        }
        let st = fs.stage.as_ref().expect("stage");
        let ctl = fs.sim.controller();
        let dt = fs.sim.time() - t0;
        println!(
            "break {} from {}: {:?} in {:?} after {:.0} µs",
            if bus { "BRK2" } else { "BRK" },
            if from_short { "short" } else { "run" },
            ctl.fault(),
            ctl.mode(),
            dt * 1e6
        );
        assert!(if bus { st.brk2 } else { st.brk });
        assert_eq!(ctl.fault(), Some(want));
        assert_eq!(ctl.mode(), Mode::Idle, "the mode agrees with the gates");
        // Observed at the end of the glitch's period, read at the end of the next one.
        assert!(dt <= 2.0 * ts + 1e-9, "{dt}");
        // The bridge stays off until the firmware re-enables it.
        fs.step().expect("step");
        assert_eq!(fs.sim.controller().mode(), Mode::Idle);
    }
}

fn suite(seeds: u64) {
    let mut failed = Vec::new();
    for c in [C72, C320] {
        println!(
            "class {} (bus {} V, trip {} V, stage max {} V, stated peak current 2·K_e/(pL)):",
            c.name, c.v_bus, c.ov, c.v_abs
        );
        println!("  kind                      runs  pass  worst t_safe      bus peak  I peak");
        let only = std::env::var("STAGE_KIND").ok();
        for kind in KINDS.iter().filter(|k| {
            only.as_deref()
                .is_none_or(|o| o.split(',').any(|o| o == **k))
        }) {
            let res: Vec<(u64, Result<Outcome, String>)> = (0..seeds)
                .into_par_iter()
                .map(|s| {
                    let r = std::panic::catch_unwind(|| run(&c, kind, s))
                        .unwrap_or_else(|_| Err("panicked".into()));
                    (s, r)
                })
                .collect();
            let ok: Vec<(u64, &Outcome)> = res
                .iter()
                .filter_map(|(s, r)| r.as_ref().ok().map(|o| (*s, o)))
                .collect();
            let worst = ok
                .iter()
                .filter_map(|(s, o)| o.t_safe.map(|t| (t, *s)))
                .fold(None::<(f64, u64)>, |m, x| match m {
                    Some(m) if m.0 >= x.0 => Some(m),
                    _ => Some(x),
                });
            let vp = ok.iter().map(|(_, o)| o.v_peak).fold(0.0, f64::max);
            let ip = ok.iter().map(|(_, o)| o.i_peak).fold(0.0, f64::max);
            let w = match worst {
                Some((t, s)) => format!(
                    "{:7.3} ms (seed {s}, {:.2} m/s)",
                    1e3 * t,
                    case(&c, kind, s).speed
                ),
                None => "—".into(),
            };
            println!(
                "  {kind:24} {:5} {:5}  {w:28} {vp:6.1} V {ip:5.1} A",
                res.len(),
                ok.len()
            );
            for (s, r) in &res {
                if let Err(e) = r {
                    failed.push(format!("{} {kind} seed {s}: {e}", c.name));
                }
            }
        }
    }
    let mut seen = std::collections::BTreeSet::new();
    for f in failed
        .iter()
        .filter(|f| seen.insert(f.split(" seed").next().unwrap_or("").to_string()))
    {
        println!("FAIL {f}");
    }
    assert!(failed.is_empty(), "{} runs failed", failed.len());
}

fn seeds(default: u64) -> u64 {
    std::env::var("STAGE_SEEDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

#[test]
fn stage_faults() {
    suite(seeds(6));
}

#[test]
#[ignore]
fn stage_faults_long() {
    suite(seeds(1000));
}

// ---------------------------------------------------------------------------------------
// The board's voltage class: its scenario family.

/// The `board-72v-*` scenarios load, run without a fault, and keep the bus under the 100 V
/// stage. Prints, for each, the peak speed against the diode onset (0.112 m/s), the share
/// of periods the current loop spends at its voltage limit and the mean inverter power over
/// the run's last part: what fits below the bus and where the emulated load clips.
#[test]
fn board_72v_scenarios() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../hal-sim/scenarios");
    for name in [
        "board-72v-force-range-1ohm",
        "board-72v-rise-time",
        "board-72v-tmd-306",
    ] {
        let sc = Scenario::from_file(&dir.join(format!("{name}.toml"))).expect("scenario");
        let onset = C72.onset(&sc);
        let mut sim = sc.build().expect("build");
        let n = (sc.duration_s / sim.period()).round() as u64;
        let (mut v_pk, mut bus_pk, mut sat, mut p, mut np) = (0.0f64, 0.0f64, 0u64, 0.0, 0u64);
        for _ in 0..n {
            sim.step();
            v_pk = v_pk.max(sim.motion().1.abs());
            bus_pk = bus_pk.max(sim.v_bus());
            sat += sim.controller().telemetry().v_saturated as u64;
            if sim.time() >= sc.settle_s {
                p += sim.p_inverter();
                np += 1;
            }
        }
        println!(
            "{name}: peak speed {v_pk:.3} m/s (onset {onset:.3}), voltage-limited {:.1} % of periods, bus peak {bus_pk:.1} V, mean inverter power {:.2} W, fault {:?}",
            100.0 * sat as f64 / n as f64,
            p / np.max(1) as f64,
            sim.controller().fault().map(|f| f.name())
        );
        assert!(bus_pk < C72.v_abs, "{name}: bus {bus_pk:.1} V");
        assert!(sim.controller().fault().is_none(), "{name}: a fault");
    }
}

// ---------------------------------------------------------------------------------------
// The chopper alone holds an open bridge at any speed.

/// Gates off (the breaks' state, a halted core after its handler), source lost, the chopper
/// driven by its comparator through the stage model, the brake resistor sized from the
/// short-circuit current (`R_b = brake_off_v·p·L/K_e`): the bus stays under the stage's
/// maximum at every speed up to ω_max, in both classes. With the default 50 Ω it does not
/// (the sweep prints the first speed it fails at).
#[test]
fn chopper_holds_open_bridge_to_omega_max() {
    for c in [C72, C320] {
        let sc0 = scenario(&c, constant_speed(0.1, 1.0), 1.0);
        let lead = sc0.screw.lead_m_per_rad;
        let w_max = sc0.config().expect("config").omega_max_rad_s as f64;
        let peak_at = |v: f64, r_b: Option<f64>| {
            let t_run = 0.3;
            let mut sc = scenario(&c, constant_speed(v, t_run), 1.0);
            sc.bus.source_v = None;
            if let Some(r) = r_b {
                sc.bus.brake_r_ohm = r;
            }
            let mut sim = sc.build().expect("scenario");
            let spec = StageSpec::from_config(sim.controller().config(), c.v_abs);
            let mut st = hal_sim::stage::Stage::new(spec, 0.0);
            st.halt();
            let n = (t_run / sim.period()).round() as u64;
            let mut peak = 0.0f64;
            for _ in 0..n {
                let _ = sim.take_sample();
                let out = st.gate(&Actuation::OFF);
                sim.apply_and_advance(&out);
                st.observe(sim.time(), sim.v_bus(), sim.currents());
                peak = peak.max(sim.v_bus());
            }
            peak
        };
        let speeds: Vec<f64> = (1..=16).map(|k| k as f64 / 16.0 * w_max * lead).collect();
        let sized: Vec<f64> = speeds.par_iter().map(|&v| peak_at(v, None)).collect();
        let worst = sized.iter().copied().fold(0.0, f64::max);
        let fails_50 = speeds
            .par_iter()
            .map(|&v| (v, peak_at(v, Some(50.0))))
            .collect::<Vec<_>>()
            .into_iter()
            .find(|p| p.1 >= c.v_abs);
        println!(
            "{}: chopper with R_b = {:.2} Ω: worst bus {worst:.1} V up to ω_max (stage {} V); with 50 Ω the bus passes the stage at {:?}",
            c.name,
            sc0.bus.brake_r_ohm,
            c.v_abs,
            fails_50.map(|p| format!("{:.3} m/s ({:.0} V)", p.0, p.1))
        );
        assert!(worst < c.v_abs, "{}: {worst:.1} V", c.name);
    }
}

/// The speed amplitude at which the emulated load `r_load` clips in class `c`: the voltage the
/// resistor law needs, `|v| = e·√(R_L² + (ω_e·L)²)/(R + R_L)` (back-emf `e = K_e·ω` less
/// `R·i`, with `i = e/(R + R_L)`, and the reactance's drop), reaches the loop's circle
/// `m_max·V_bus/√3`, m/s. (Fixed point in ω: ω_e·L is ≈ 1 Ω there against R_L ≥ 10 Ω.)
fn clip_speed(c: &Class, sc: &Scenario, r_load: f64) -> f64 {
    let m = &sc.machine;
    let m_max = sc.config().expect("config").m_max as f64;
    let v_max = m_max * c.v_bus / 3f64.sqrt();
    let mut w = 0.0;
    for _ in 0..20 {
        let x = m.pole_pairs as f64 * w * m.l_h;
        w = v_max * (m.r_ohm + r_load) / (m.ke_v_s_per_rad * (r_load * r_load + x * x).sqrt());
    }
    w * sc.screw.lead_m_per_rad
}

/// The reference TMD sweep in the 72 V class (`board-72v-tmd-306.toml` at 0.5 Hz) at the
/// excitation that fits the bus: the largest `a₀` (to 0.01 m/s²) whose harmonic-balance
/// velocity at the balance's optimal load stays at 0.8 of that load's clip speed
/// ([`clip_speed`]; 20 % for the bus ripple, the PI's headroom and the friction's
/// harmonics). At each load of the reference grid (10 Ω … 1 kΩ, then 1.5 and 3 kΩ):
/// closed-loop power against the harmonic balance (`analytic::tmd_power`, which knows no
/// bus), and the share of periods the current loop spends at its voltage limit. Where the
/// balance's velocity is below 0.9 of the clip speed the loop must match the balance and
/// never be voltage-limited; above the clip speed it must be (the closed form says where
/// the emulated load clips). The simulated optimum must be the balance's grid optimum.
/// Figure and CSV in `CARGO_TARGET_TMPDIR` (`board_72v_tmd_sweep.{svg,csv}`, copied to
/// docs/figures/).
#[test]
fn board_72v_tmd_sweep() {
    use hal_sim::analytic::{tmd_power, DampingFormula};
    use hal_sim::cli::sweep::set_param;
    use hal_sim::plant::Drive;
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../hal-sim/scenarios");
    let base = Scenario::from_file(&dir.join("board-72v-tmd-306.toml")).expect("scenario");
    let onset = C72.onset(&base);
    let Drive::Structure { structure: st, .. } = base.drive.clone() else {
        panic!("a structure")
    };
    let hb = |r: f64, a0: f64| {
        tmd_power(
            r,
            &base.machine,
            &base.screw,
            &st,
            a0,
            0.5,
            DampingFormula::PerPhasePeak,
        )
    };
    // The balance's optimal load (golden section on ln R_L; it moves little with a₀ through
    // the friction).
    let r_opt = |a0: f64| {
        let (mut lo, mut hi) = (10f64.ln(), 10_000f64.ln());
        let g = 0.5 * (5f64.sqrt() - 1.0);
        for _ in 0..60 {
            let (x1, x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
            if hb(x1.exp(), a0).p_load > hb(x2.exp(), a0).p_load {
                hi = x2;
            } else {
                lo = x1;
            }
        }
        (0.5 * (lo + hi)).exp()
    };
    let fits = |a0: f64| {
        let r = r_opt(a0);
        hb(r, a0).velocity_amp <= 0.8 * clip_speed(&C72, &base, r)
    };
    let mut a0 = 0.01;
    while fits(a0 + 0.01) {
        a0 += 0.01;
    }
    let a0 = (a0 * 100.0f64).round() / 100.0;
    let ro = r_opt(a0);
    // Where the emulated load clips: the balance's velocity meets the clip speed (bisection
    // on ln R_L above the optimum, where the velocity rises with R_L).
    let (mut lo, mut hi) = (ro.ln(), 1e5f64.ln());
    for _ in 0..60 {
        let m = 0.5 * (lo + hi);
        if hb(m.exp(), a0).velocity_amp < clip_speed(&C72, &base, m.exp()) {
            lo = m;
        } else {
            hi = m;
        }
    }
    let r_clip = lo.exp();
    println!(
        "72v TMD: a0 = {a0} m/s² (balance optimum {ro:.0} Ω, {:.3} m/s against its clip speed {:.3} m/s; onset {onset:.3} m/s); the emulated load clips from {r_clip:.0} Ω",
        hb(ro, a0).velocity_amp,
        clip_speed(&C72, &base, ro)
    );
    let mut loads = hal_sim::cli::sweep::DEFAULT_LOADS.to_vec();
    loads.extend([1500.0, 3000.0]);
    // (R_L, simulated power, balance power, balance velocity, clip speed, voltage-limited share)
    let rows: Vec<(f64, f64, f64, f64, f64, f64)> = loads
        .par_iter()
        .map(|&r| {
            let mut sc = base.clone();
            sc.record.channels.clear();
            sc.law.r_load_ohm = r;
            set_param(&mut sc, "a0_m_s2", a0).expect("a0_m_s2");
            let mut sim = sc.build().expect("build");
            let n = (sc.duration_s / sim.period()).round() as u64;
            let n_settle = (sc.settle_s / sim.period()).round() as u64;
            let (mut e0, mut sat) = (0.0, 0u64);
            for k in 1..=n {
                sim.step();
                if k == n_settle {
                    e0 = sim.energy().to_inverter;
                }
                if k > n_settle {
                    sat += sim.controller().telemetry().v_saturated as u64;
                }
            }
            assert!(sim.controller().fault().is_none(), "{r} Ω: a fault");
            let span = (n - n_settle) as f64 * sim.period();
            let p = (sim.energy().to_inverter - e0) / span;
            let a = hb(r, a0);
            (
                r,
                p,
                a.p_load,
                a.velocity_amp,
                clip_speed(&C72, &base, r),
                sat as f64 / (n - n_settle) as f64,
            )
        })
        .collect();
    let mut worst: f64 = 0.0;
    for &(r, p, pa, v, vc, sat) in &rows {
        let dev = p / pa - 1.0;
        println!(
            "72v TMD {a0} m/s² R_L {r:6.0} Ω: sim {p:6.3} W, harmonic balance {pa:6.3} W ({:+.2} %), balance velocity {v:.3} m/s, clip speed {vc:.3} m/s, voltage-limited {:.1} %",
            100.0 * dev,
            100.0 * sat
        );
        if v < 0.9 * vc {
            worst = worst.max(dev.abs());
            assert_eq!(sat, 0.0, "{r} Ω: voltage-limited below the clip speed");
        } else if v > vc {
            assert!(
                sat > 0.05,
                "{r} Ω: clips by the closed form, not in the loop ({sat})"
            );
        }
    }
    let best = rows
        .iter()
        .fold(rows[0], |b, x| if x.1 > b.1 { *x } else { b });
    let best_hb = rows
        .iter()
        .fold(rows[0], |b, x| if x.2 > b.2 { *x } else { b });
    println!(
        "72v TMD: best simulated load {:.0} Ω, {:.3} W; balance's grid optimum {:.0} Ω, {:.3} W; worst deviation below the clip {:.2} %",
        best.0,
        best.1,
        best_hb.0,
        best_hb.2,
        100.0 * worst
    );
    assert_eq!(best.0, best_hb.0, "optimum");
    // Below the clip the deviation falls steadily with the speed, +3.42 % at 10 Ω
    // (0.006 m/s) to +0.24 % at 400 Ω: most likely the balance's replacing the Coulomb
    // friction by its equivalent damping 4F_c/(πẊ), coarsest where the friction is a large
    // share of the force (not isolated). Bounded at 3× the worst (10 %), and at the optimum, where the loop matters,
    // at 3× its +0.42 % (1.3 %).
    assert!(worst < 0.10, "{worst}");
    let dev_opt = (best_hb.1 / best_hb.2 - 1.0).abs();
    assert!(dev_opt < 0.013, "at the optimum: {dev_opt}");
    let out = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"));
    let csv: Vec<Vec<f64>> = rows
        .iter()
        .map(|r| vec![a0, r.0, r.1, r.2, r.3, r.4, r.5])
        .collect();
    hal_sim::cli::output::write_csv(
        &out.join("board_72v_tmd_sweep.csv"),
        &[
            "a0_m_s2",
            "r_load_ohm",
            "sim_power_w",
            "harmonic_balance_w",
            "hb_velocity_m_s",
            "clip_speed_m_s",
            "voltage_limited_share",
        ],
        &csv,
    )
    .expect("csv");
    let mut plot = Plot::new(
        format!("Reference TMD on the 72 V bus, a0 = {a0} m/s² at 0.5 Hz"),
        "load resistance R_L (Ω, log scale)",
        "mean harvested power (W)",
    );
    plot.xlog = true;
    let pmax = rows.iter().map(|r| r.1.max(r.2)).fold(0.0, f64::max);
    plot.series = vec![
        Series::markers(
            "closed loop (firmware on the simulator)",
            rows.iter().map(|r| (r.0, r.1)).collect(),
        ),
        Series::line(
            "harmonic balance (no bus)",
            rows.iter().map(|r| (r.0, r.2)).collect(),
        ),
        Series::line(
            format!("emulated load clips from {r_clip:.0} Ω"),
            vec![(r_clip, 0.0), (r_clip, 1.05 * pmax)],
        ),
    ];
    let p = plot
        .write_svg(&out.join("board_72v_tmd_sweep.svg"))
        .expect("svg");
    println!("written {} and board_72v_tmd_sweep.csv", p.display());
}
