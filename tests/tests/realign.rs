//! Alignment and re-alignment on a moving structure (docs/protection.md, "Power-up"): the emf
//! probe at zero current while the rotor moves, the d-axis steps when it is still; from seeded
//! rotor angles and speeds up to the drive's rating (the speed whose emf reaches the voltage
//! circle, `m_max·V_bus/√3`: above it no current can be controlled at all), on imposed
//! motions, on the reference TMD at rest and on `hal-sim/scenarios/tmd-306.toml`'s motion
//! after a `mode idle`; encoders that disagree with the emf latch `encoder_mismatch`; `mode
//! short` is refused where its current could trip and trips nothing where it is accepted; the
//! console path `idle → align → aligned → run` on tmd-306 while it moves.

use hal_sim::drive::SimDrive;
use hal_sim::plant::{Drive, Excitation, Motion};
use hal_sim::powerup::PowerUp;
use hal_sim::{Channel, Scenario, Sim};
use regen_fw::align::{post, AlignRetry, Retry};
use regen_fw::control::{AlignMethod, Fault};
use regen_fw::{Boot, Mode};

fn powerup(seed: u64) -> PowerUp {
    PowerUp {
        random_angle: true,
        offset_a: 0.15,
        gain_rel: 0.02,
        seed,
        ..PowerUp::default()
    }
}

/// The seeded uniform draw in [0, 1) for test inputs (an LCG of its own: nothing shared with
/// the simulator's or the firmware's generators).
fn unit(seed: u64, k: u64) -> f64 {
    let mut z = seed
        .wrapping_mul(6_364_136_223_846_793_005)
        .wrapping_add(k.wrapping_mul(1_442_695_040_888_963_407));
    z ^= z >> 33;
    z = z.wrapping_mul(0xff51_afd7_ed55_8ccd);
    z ^= z >> 33;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

/// The rating: the speed whose emf `K_e·ω` reaches the voltage circle `m_max·V_bus/√3` of
/// the scenario's bus, rad/s (186 rad/s at 320 V for the reference machine).
fn rating(sc: &Scenario) -> f64 {
    let sim = sc.build().unwrap();
    let c = sim.controller().config();
    c.m_max as f64 * sc.bus.initial_v / 3f64.sqrt() / c.ke_v_s_per_rad as f64
}

fn lead() -> f64 {
    hal_sim::plant::Screw::default().lead_m_per_rad
}

fn stats(name: &str, v: &[f64]) -> (f64, f64) {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let q = |p: f64| s[((s.len() - 1) as f64 * p).round() as usize];
    println!(
        "{name}: n={} min {:.4} p10 {:.4} median {:.4} p90 {:.4} max {:.4}",
        s.len(),
        s[0],
        q(0.1),
        q(0.5),
        q(0.9),
        s[s.len() - 1]
    );
    (s[0], s[s.len() - 1])
}

/// `mode align` now, then periods until aligned, with the board's retry (`regen_fw::align`,
/// polled every period as `SimDrive` does). Returns the time it took, or the fault.
fn align(sim: &mut Sim, t_max: f64) -> Result<f64, Fault> {
    sim.controller_mut().set_mode(Mode::Align).unwrap();
    let t0 = sim.time();
    let mut retry = AlignRetry::NEW;
    while sim.controller().boot() != Boot::Aligned {
        match retry.poll(sim.controller(), sim.loop_period().periods) {
            Retry::Post => post(sim.mailbox()),
            Retry::Waiting => {}
            Retry::Nothing => {
                if let Some(f) = sim.controller().fault() {
                    return Err(f);
                }
            }
        }
        assert!(sim.time() - t0 < t_max, "no end in {t_max} s");
        sim.step();
    }
    Ok(sim.time() - t0)
}

/// One result of the suite.
struct Row {
    kind: &'static str,
    speed: f64,
    t_align: f64,
    err_deg: f64,
    emf: bool,
}

/// After alignment: the angle error, then `mode run` for `run_s` without any fault.
fn check_after(sim: &mut Sim, kind: &'static str, seed: u64, t_align: f64, run_s: f64) -> Row {
    // One period in the angle found (the last one's record is the probe's frame).
    sim.step();
    let speed = (sim.channel(Channel::V) / lead()).abs();
    let err_deg = sim.angle_error().to_degrees();
    let emf = matches!(sim.controller().aligned_by(), Some(AlignMethod::Emf { .. }));
    sim.controller_mut()
        .set_mode(Mode::Run)
        .unwrap_or_else(|e| panic!("{kind} seed {seed}: run refused: {}", e.name()));
    sim.run_for(run_s);
    assert_eq!(sim.controller().fault(), None, "{kind} seed {seed}");
    assert_eq!(sim.controller().mode(), Mode::Run, "{kind} seed {seed}");
    Row {
        kind,
        speed,
        t_align,
        err_deg,
        emf,
    }
}

fn tmd306() -> Scenario {
    let p = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../hal-sim/scenarios/tmd-306.toml"
    );
    let mut sc = Scenario::from_file(std::path::Path::new(p)).unwrap();
    sc.record.channels.clear();
    sc
}

/// An imposed triangle at `v` m/s (amplitude 0.4 m: a quarter cycle lasts 0.4/v s, longer
/// than the calibration and the alignment at every speed tested).
fn triangle(v: f64) -> Scenario {
    let a = 0.4;
    let mut sc = Scenario::imposed(
        Motion::Triangle {
            amplitude_m: a,
            freq_hz: v / (4.0 * a),
        },
        306.0,
        10.0,
    );
    sc.record.channels.clear();
    sc
}

#[test]
fn realignment_from_seeded_angles_and_speeds_up_to_the_rating() {
    let w_rate = rating(&tmd306());
    println!("rating: {w_rate:.1} rad/s ({:.3} m/s)", w_rate * lead());
    let mut rows: Vec<Row> = vec![];
    // (a) Imposed constant speeds from 3 % to 97 % of the rating, power-up at a seeded angle.
    for seed in 0..40 {
        let w = w_rate * (0.03 + 0.94 * unit(seed, 1));
        let mut sim = triangle(w * lead()).build().unwrap();
        sim.power_up(&powerup(seed)).unwrap();
        let b = sim
            .boot()
            .unwrap_or_else(|f| panic!("triangle seed {seed} at {w:.1} rad/s: {f}"));
        rows.push(check_after(&mut sim, "triangle", seed, b.align_s, 0.2));
    }
    // (b) Imposed sines (reversals during the alignment), peak speed up to 97 % of the
    // rating, 0.2 … 2 Hz; the alignment starts at a seeded phase after the calibration.
    for seed in 0..30 {
        let f = 0.2 + 1.8 * unit(seed, 2);
        let w_pk = w_rate * (0.1 + 0.87 * unit(seed, 3));
        let amp = w_pk * lead() / (std::f64::consts::TAU * f);
        let mut sc = Scenario::imposed(
            Motion::Sine {
                amplitude_m: amp.min(0.45),
                freq_hz: f,
            },
            306.0,
            20.0,
        );
        sc.record.channels.clear();
        let mut sim = sc.build().unwrap();
        sim.power_up(&powerup(100 + seed)).unwrap();
        sim.run_for(0.15 + unit(seed, 4) / f);
        let t = align(&mut sim, 8.0).unwrap_or_else(|e| panic!("sine seed {seed}: {e:?}"));
        rows.push(check_after(&mut sim, "sine", seed, t, 0.2));
    }
    // (c) tmd-306's motion: booted at a seeded angle, harvesting for a seeded 2 … 10 s, then
    // the user's `mode idle`, a seeded pause, `mode align`, `mode run`.
    let sc = tmd306();
    for seed in 0..30 {
        let mut sim = sc.build().unwrap();
        sim.power_up(&powerup(200 + seed)).unwrap();
        sim.boot()
            .unwrap_or_else(|f| panic!("tmd-306 seed {seed}: {f}"));
        sim.run_for(2.0 + 8.0 * unit(seed, 5));
        sim.controller_mut().set_mode(Mode::Idle).unwrap();
        sim.run_for(0.3 * unit(seed, 6));
        let t = align(&mut sim, 8.0).unwrap_or_else(|e| panic!("tmd-306 seed {seed}: {e:?}"));
        rows.push(check_after(&mut sim, "tmd-306", seed, t, 1.0));
    }
    // (d) The reference TMD at rest (no excitation): the d-axis steps.
    for seed in 0..10 {
        let mut sc = Scenario::tmd(306.0);
        sc.record.channels.clear();
        if let Drive::Structure { excitation, .. } = &mut sc.drive {
            *excitation = Excitation::Sine {
                a0_m_s2: 0.0,
                freq_hz: 0.5,
            };
        }
        let mut sim = sc.build().unwrap();
        sim.power_up(&powerup(300 + seed)).unwrap();
        let b = sim
            .boot()
            .unwrap_or_else(|f| panic!("at rest seed {seed}: {f}"));
        rows.push(check_after(&mut sim, "at rest", seed, b.align_s, 0.2));
    }
    assert!(rows.len() >= 100);
    for kind in ["triangle", "sine", "tmd-306", "at rest"] {
        let r: Vec<&Row> = rows.iter().filter(|r| r.kind == kind).collect();
        let n_emf = r.iter().filter(|r| r.emf).count();
        println!("{kind}: {} alignments, {n_emf} by the emf", r.len());
        stats(
            &format!("{kind}: speed at the end, rad/s"),
            &r.iter().map(|r| r.speed).collect::<Vec<_>>(),
        );
        stats(
            &format!("{kind}: time to align, s"),
            &r.iter().map(|r| r.t_align).collect::<Vec<_>>(),
        );
        stats(
            &format!("{kind}: angle error after alignment, deg"),
            &r.iter().map(|r| r.err_deg).collect::<Vec<_>>(),
        );
    }
    let emf: Vec<&Row> = rows.iter().filter(|r| r.emf).collect();
    let steps: Vec<&Row> = rows.iter().filter(|r| !r.emf).collect();
    let (e_lo, e_hi) = stats(
        "all by the emf: angle error, deg",
        &emf.iter().map(|r| r.err_deg).collect::<Vec<_>>(),
    );
    let (_, t_emf) = stats(
        "all by the emf: time to align, s",
        &emf.iter().map(|r| r.t_align).collect::<Vec<_>>(),
    );
    // Every constant-speed and tmd-306 case aligned by the emf; every one at rest by the
    // steps (a sine may meet a reversal either way).
    for r in &rows {
        match r.kind {
            "triangle" | "tmd-306" => assert!(r.emf, "{} at {}", r.kind, r.speed),
            "at rest" => assert!(!r.emf),
            _ => {}
        }
    }
    assert!(!steps.is_empty() && emf.len() >= 90, "{}", emf.len());
    // Stated: by the emf, the angle within ±0.8° electrical (measured ±0.26°: the encoder's
    // count is 0.18°, the rest the loop's noise; 3× margin) and aligned within 0.5 s of
    // `mode align` (measured ≤ 0.18 s: 23 ms without a reversal, a reversal or the settle
    // after the calibration adds up to 0.15 s; 3× margin).
    assert!(e_lo > -0.8 && e_hi < 0.8, "{e_lo} … {e_hi}");
    assert!(t_emf < 0.5, "{t_emf}");
}
