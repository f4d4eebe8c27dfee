//! Commissioning (`measure`, `regen_fw::commission`): the drive measures R, L_d, L_q and K_e
//! of plants drawn off their nameplate; `measure apply` restores the emulated load.

use hal_sim::drive::SimDrive;
use hal_sim::plant::{Drive, Excitation};
use hal_sim::powerup::PlantDraw;
use hal_sim::Scenario;
use regen_fw::commission::Phase;
use regen_fw::Mode;

/// The structure of `sc` excited by a 0.5 Hz sine of `a0` m/s².
fn excite(sc: &mut Scenario, a0: f64) {
    if let Drive::Structure { excitation, .. } = &mut sc.drive {
        *excitation = Excitation::Sine {
            a0_m_s2: a0,
            freq_hz: 0.5,
        };
    }
}

/// The reference TMD (320 V) at `r_l` with the apply test's salient machine (L_q =
/// 1.6·L_d), no record channels.
fn salient_tmd(r_l: f64) -> Scenario {
    let mut sc = Scenario::tmd(r_l);
    sc.record.channels.clear();
    sc.machine.l_q_h = Some(SALIENCY * sc.machine.l_h);
    sc
}

/// The board's reference TMD (`board-72v-tmd-306.toml`: power-up, shunt sampling) at
/// 0.4 m/s² (below the 72 V bus's diode onset), its plant drawn by `seed` within ±`tol`.
fn board(seed: u64, tol: f64) -> Scenario {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../hal-sim/scenarios");
    let mut sc = Scenario::from_file(&dir.join("board-72v-tmd-306.toml")).expect("scenario");
    sc.record.channels.clear();
    excite(&mut sc, 0.4);

    sc.plant_draw = PlantDraw {
        r_rel: tol,
        l_rel: tol,
        ke_rel: tol,
        lq_ratio_max: 1.6,
        seed,
    };
    sc.powerup.seed = seed;
    // The bus-voltage sensor's gain error within its stated tolerance (the firmware's
    // `V_GAIN_TOL`); the current sensors' (±2 %) are the scenario's.
    sc.powerup.vbus_gain_rel = regen_fw::commission::V_GAIN_TOL as f64;
    sc
}

/// Boot (the build's), `mode idle`, `measure`, run until it ends; the measurement.
fn measure(sc: &Scenario) -> (SimDrive, String) {
    let mut d = SimDrive::from_scenario(sc).expect("build");
    exec(&mut d, "mode idle");
    let shown = measure_on(&mut d);
    (d, shown)
}

/// `measure` on `d` (idle), run until it ends (at most 20 s at 20 kHz); `measure show`'s reply.
fn measure_on(d: &mut SimDrive) -> String {
    exec(d, "measure");
    let mut tel = String::new();
    let mut n = 0u64;
    while d.sim().controller().mode() == Mode::Measure && n < 20 * 20_000 {
        d.step(&mut tel);
        n += 1;
    }
    let mut out = String::new();
    let _ = d.execute("measure show", &mut out);
    out
}

/// The tolerance of each measured value (R, L_d, L_q, K_e), relative to the plant's, from
/// the largest error of the 100 salient plants with their sensors' gain errors
/// (`measured_within_tolerance_of_the_plant`): R +2.43 %, L_d −3.54 %, L_q +3.09 %, K_e
/// +1.23 %; each bound 1.3–1.5× that (3× would pass a 5 % error in the arithmetic, which
/// must fail: tried on L_q's quotient and on L_d's, it fails).
const TOL: [f64; 4] = [0.035, 0.045, 0.045, 0.016];

/// Relative errors (measured/plant − 1) of R, L_d, L_q, K_e for `seeds`, each plant drawn
/// within ±20 % of the nameplate.
fn errors(seeds: std::ops::Range<u64>) -> Vec<[[f64; 3]; 4]> {
    use rayon::prelude::*;
    seeds
        .into_par_iter()
        .map(|seed| {
            let sc = board(seed, 0.2);
            let m = sc.plant_machine();
            let (d, out) = measure(&sc);
            let me = *d.sim().controller().measurement();
            assert_eq!(me.phase(), Phase::Done, "seed {seed}: {out}");
            // At 0.4 m/s² nothing is refused (the L pulses within the modulation's reach).
            assert_eq!(me.rl_refused(), None, "seed {seed}: {out}");
            // (measured/plant − 1, stated uncertainty and the repeats' standard error alone,
            // relative to the plant's value)
            let u = me.uncertainty();
            let rel = |s: &regen_fw::commission::Stats, u: f32, y: f64| {
                [
                    s.mean() as f64 / y - 1.0,
                    u as f64 / y,
                    s.sigma() as f64 / y,
                ]
            };
            [
                rel(&me.r, u[0], m.r_ohm),
                rel(&me.ld, u[1], m.l_d()),
                rel(&me.lq, u[2], m.l_q()),
                rel(&me.ke_est, u[3], m.ke_v_s_per_rad),
            ]
        })
        .collect()
}

/// 100 plants off the nameplate by up to ±20 % in R, L_d and K_e, L_q/L_d within [1, 1.6],
/// each on the board's TMD (power-up draws with the current sensors' ±2 % and the bus
/// sensor's ±1 % gain errors, shunt sampling, the structure at 0.4 m/s²): every measured
/// value within `TOL` of the plant's (L_d judged against the plant's L_d, L_q against its
/// L_q), and the stated uncertainty covers the true error as a standard uncertainty does.
#[test]
fn measured_within_tolerance_of_the_plant() {
    let e = errors(0..100);
    let ratio: Vec<f64> = (0..100)
        .map(|s| {
            let m = board(s, 0.2).plant_machine();
            m.l_q() / m.l_d()
        })
        .collect();
    println!(
        "L_q/L_d of the plants: {:.3} … {:.3}",
        ratio.iter().cloned().fold(f64::MAX, f64::min),
        ratio.iter().cloned().fold(f64::MIN, f64::max)
    );
    for (k, name) in ["R", "L_d", "L_q", "K_e"].iter().enumerate() {
        let mut v: Vec<f64> = e.iter().map(|x| x[k][0]).collect();
        v.sort_by(f64::total_cmp);
        let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let mut sig: Vec<f64> = e.iter().map(|x| x[k][1]).collect();
        sig.sort_by(f64::total_cmp);
        // Coverage: the share whose true error lies within 1 and 2 stated uncertainties.
        let within = |c: f64| {
            e.iter().filter(|x| x[k][0].abs() <= c * x[k][1]).count() as f64 / e.len() as f64
        };
        let (c1, c2) = (within(1.0), within(2.0));
        println!(
            "{name}: error mean {:+.3} %, min {:+.3} %, p5 {:+.3} %, median {:+.3} %, p95 {:+.3} %, \
             max {:+.3} %; stated uncertainty median {:.3} % (min {:.3} %, max {:.3} %); \
             coverage {:.0} % within 1 of it, {:.0} % within 2",
            mean * 100.0,
            q(0.0) * 100.0,
            q(0.05) * 100.0,
            q(0.5) * 100.0,
            q(0.95) * 100.0,
            q(1.0) * 100.0,
            sig[sig.len() / 2] * 100.0,
            sig[0] * 100.0,
            sig[sig.len() - 1] * 100.0,
            100.0 * c1,
            100.0 * c2,
        );
        let rep = e.iter().filter(|x| x[k][0].abs() <= x[k][2]).count();
        println!(
            "{name}: the repeats' spread alone covers {rep} of {}",
            e.len()
        );
        // The stated uncertainty is a standard one: 68 % of a normal error within 1 of it,
        // 95 % within 2; 100 plants put the share within ±4.7 % (1) and ±2.2 % (2) of those
        // (binomial): bounds 3 of that. Measured R 68/98 %, L_d 69/98 %, L_q 68/94 %, K_e
        // 71/100 %. The repeats' spread alone (the gain errors left out) covers R 35 %,
        // L_d 43 %, L_q 38 %, K_e 20 % within 1.
        assert!(
            (0.54..=0.82).contains(&c1) && c2 >= 0.88,
            "{name}: coverage {c1} within 1, {c2} within 2"
        );
        assert!(
            q(0.0) > -TOL[k] && q(1.0) < TOL[k],
            "{name}: error {:+.3} % … {:+.3} % beyond ±{} %",
            q(0.0) * 100.0,
            q(1.0) * 100.0,
            TOL[k] * 100.0
        );
    }
}

/// Steps `d` for `s` seconds.
fn run(d: &mut SimDrive, s: f64) {
    let mut tel = String::new();
    let n = (s * d.sim().controller().config().pwm_hz as f64).round() as u64;
    for _ in 0..n {
        d.step(&mut tel);
    }
}

fn exec(d: &mut SimDrive, line: &str) -> String {
    let mut out = String::new();
    d.execute(line, &mut out)
        .unwrap_or_else(|_| panic!("{line}: {out}"));
    out
}

/// The load the structure feels under the resistor law, `(R̂ + R_L)·K_e/K̂_e − R`, for the
/// firmware's `cfg` against the plant `m`.
fn emulated(r_l: f64, cfg: &regen_fw::Config, m: &hal_sim::plant::Machine) -> f64 {
    (cfg.r_phase_ohm as f64 + r_l) * m.ke_v_s_per_rad / cfg.ke_v_s_per_rad as f64 - m.r_ohm
}

/// Run after the measurement before the power is averaged, s: the structure, resonant and
/// lightly damped while the drive idles and measures, comes back to the law's steady state.
const SETTLE_S: f64 = 40.0;

/// L_q/L_d of the apply test's plant: the board draw's largest.
const SALIENCY: f64 = 1.6;

/// The reference TMD (320 V, 1 m/s²) with a salient machine (L_q = 1.6·L_d, the firmware
/// told L_d) at `r_l`, the firmware told K_e and R `err` high: idle, `measure` (unless `meas`
/// is false: then told its machine, `l_phase_h` L_q as `measure apply` writes it), `measure
/// apply`, run; the emulated load before and after, the measurement's reply and the mean
/// power over 4 s after `SETTLE_S`.
fn measured_drive(r_l: f64, err: f64, meas: bool) -> (f64, f64, String, f64) {
    let mut sc = salient_tmd(r_l);
    let m = sc.plant_machine();
    sc.firmware.ke_v_s_per_rad = Some((m.ke_v_s_per_rad * (1.0 + err)) as f32);
    sc.firmware.r_phase_ohm = Some((m.r_ohm * (1.0 + err)) as f32);
    sc.firmware.l_phase_h = Some(if meas { m.l_d() } else { m.l_q() } as f32);
    let mut d = SimDrive::from_scenario(&sc).expect("build");
    let before = emulated(r_l, d.sim().controller().config(), &m);
    exec(&mut d, "mode idle");
    let mut shown = String::new();
    if meas {
        exec(&mut d, "measure");
        while d.sim().controller().mode() == Mode::Measure {
            run(&mut d, 0.01);
        }
        shown = exec(&mut d, "measure show");
        exec(&mut d, "measure apply");
    } else {
        // The same time in idle as the measurement takes.
        let t = regen_fw::commission::Measure::duration_s(d.sim().controller().config());
        run(&mut d, t as f64);
    }
    exec(&mut d, "mode run");
    let after = emulated(r_l, d.sim().controller().config(), &m);
    run(&mut d, SETTLE_S);
    let e0 = d.sim().energy().to_inverter;
    run(&mut d, 4.0);
    (
        before,
        after,
        shown,
        (d.sim().energy().to_inverter - e0) / 4.0,
    )
}

/// After `measure apply` on a drive told K_e and R 15 % high, the structure feels the load
/// it was told, and the power is the drive's that knew its machine, and the harmonic
/// balance's.
#[test]
fn apply_restores_the_load_and_the_power() {
    use hal_sim::analytic::{tmd_power, DampingFormula};
    for (r_l, hb_tol) in [(10.0, 7.3e-3), (306.0, 5.1e-3), (1000.0, 3.4e-3)] {
        let (before, after, shown, p) = measured_drive(r_l, 0.15, true);
        let (_, _, _, p_true) = measured_drive(r_l, 0.0, false);
        let sc = Scenario::tmd(r_l);
        let Drive::Structure { structure, .. } = &sc.drive else {
            unreachable!()
        };
        let hb = tmd_power(
            r_l,
            &sc.plant_machine(),
            &sc.screw,
            structure,
            1.0,
            0.5,
            DampingFormula::PerPhasePeak,
        )
        .p_load;
        let (de, dp, dh) = (after / r_l - 1.0, p / p_true - 1.0, p / hb - 1.0);
        println!(
            "R_L {r_l} ohm:\n{shown}emulated {before:.2} -> {after:.3} ohm ({:+.3} %); power \
             {p:.4} W, the drive that knew its machine {p_true:.4} W ({:+.3} %), harmonic \
             balance {hb:.4} W ({:+.3} %)",
            100.0 * de,
            100.0 * dp,
            100.0 * dh
        );
        // Told 15 % high, the load was 13 % low.
        assert!(before / r_l < 0.9, "R_L {r_l}: {before}");
        // Measured: −0.024 % (10 Ω), −0.009 %, −0.009 %: bound 0.25 %. A 1 % error of the
        // measured K_e alone moves the load by 1 % (and more at 10 Ω, R's share).
        assert!(de.abs() < 2.5e-3, "R_L {r_l}: emulated {after} ohm");
        // Measured: −0.017 % (10 Ω), −0.001 %, +0.009 %: bound 0.25 %.
        assert!(dp.abs() < 2.5e-3, "R_L {r_l}: {p} W against {p_true} W");
        // The closed-loop test's bound of the harmonic balance (`sim_closed_loop.rs`,
        // `tmd_power_matches_harmonic_balance`; 100 Ω's for 306 Ω). Measured: +0.43 %
        // (10 Ω), +0.054 %, −0.106 %.
        assert!(dh.abs() < hb_tol, "R_L {r_l}: {p} W against {hb} W");
    }
}

/// `regen commission`'s sequence against a simulated drive: the console in-process, a wait
/// as simulated time.
struct SimPort(SimDrive);

impl hal_sim::cli::commission::Port for SimPort {
    fn command(&mut self, line: &str) -> Result<Vec<String>, String> {
        let mut out = String::new();
        let _ = self.0.execute(line, &mut out);
        Ok(out
            .split("\r\n")
            .filter(|l| !l.is_empty())
            .map(str::to_string)
            .collect())
    }
    fn wait(&mut self, seconds: f64) {
        run(&mut self.0, seconds);
    }
}

/// `regen commission` on the board's TMD (its plant drawn off the nameplate, the firmware
/// told the nameplate): aligned again, measured, applied; its table lists the four results
/// beside the configured values, and the load it proposes is the harmonic balance's optimum
/// for the plant's own R and K_e.
#[test]
fn regen_commission_on_a_simulated_board() {
    use hal_sim::cli::commission::{commission, load_for, CommissionArgs};
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../hal-sim/scenarios");
    let path = dir.join("board-72v-tmd-306.toml");
    let sc = board(7, 0.2);
    let m = sc.plant_machine();
    let mut port = SimPort(SimDrive::from_scenario(&sc).expect("build"));
    let a = CommissionArgs {
        port: String::new(),
        baud: 115_200,
        apply: true,
        save: true,
        no_align: false,
        scenario: Some(path.clone()),
        model: None,
        timeout: 60.0,
    };
    let rep = commission(&mut port, &a).expect("commission");
    for l in &rep {
        println!("{l}");
    }
    let rows = rep
        .iter()
        .filter(|l| l.contains('%') && !l.starts_with("load"))
        .count();
    assert_eq!(rows, 4, "{rep:?}");
    assert!(rep.iter().any(|l| l.starts_with("ok applied")), "{rep:?}");
    let load = rep
        .iter()
        .find(|l| l.starts_with("load:"))
        .expect("load line");
    let opt: f64 = load
        .split("optimum R_L ")
        .nth(1)
        .and_then(|s| s.split_whitespace().next()?.parse().ok())
        .expect("optimum");
    let file = Scenario::from_file(&path).unwrap();
    let truth = load_for(&file, None, m.r_ohm, m.ke_v_s_per_rad, 306.0).unwrap();
    println!(
        "optimum with the plant's R, K_e: {:.1} ohm; proposed {opt:.1} ohm",
        truth.optimum_ohm
    );
    // The optimum ∝ K_e²/(…): the measured K_e's 0.3 % and R's few % move it by under 1 %
    // (measured: see the print); bound 2 %.
    assert!((opt / truth.optimum_ohm - 1.0).abs() < 0.02);
    let cfg = port.0.sim().controller().config();
    assert!((cfg.ke_v_s_per_rad as f64 / m.ke_v_s_per_rad - 1.0).abs() < TOL[3]);
}

/// The board scenarios' plant as drawn (printed for docs/simulator.md).
#[test]
fn board_scenarios_plants() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../hal-sim/scenarios");
    for f in [
        "board-72v-tmd-306",
        "board-72v-rise-time",
        "board-72v-force-range-1ohm",
    ] {
        let sc = Scenario::from_file(&dir.join(format!("{f}.toml"))).unwrap();
        let (n, p) = (sc.machine, sc.plant_machine());
        println!(
            "{f}: R {:+.2} %, L_d {:+.2} %, L_q/L_d {:.3}, K_e {:+.2} %",
            100.0 * (p.r_ohm / n.r_ohm - 1.0),
            100.0 * (p.l_d() / n.l_d() - 1.0),
            p.l_q() / p.l_d(),
            100.0 * (p.ke_v_s_per_rad / n.ke_v_s_per_rad - 1.0)
        );
        assert!(
            sc.plant_draw.r_rel > 0.0 && p != n,
            "{f}: the plant is the nameplate"
        );
        assert!(p.salient(), "{f}: the plant is not salient");
    }
}

/// The reference TMD (320 V) at `a0` m/s² with the apply test's salient machine (L_q =
/// 1.6·L_d), the firmware told the plant's R, K_e and L_d; idle for `wait` s, then
/// `measure`: the L_d and L_q errors against the plant's, and the r.m.s. electrical speed
/// over the L pulses, rad/s.
fn tmd_l_errors(a0: f64, wait: f64) -> Option<[f64; 3]> {
    let mut sc = salient_tmd(306.0);
    excite(&mut sc, a0);
    let m = sc.plant_machine();
    let mut d = SimDrive::from_scenario(&sc).expect("build");
    exec(&mut d, "mode idle");
    run(&mut d, wait);
    l_errors(&mut d, &m)
}

/// `measure` on `d` (idle) against the plant `m`: the L_d and L_q errors and the r.m.s.
/// electrical speed over the L pulses.
fn l_errors(d: &mut SimDrive, m: &hal_sim::plant::Machine) -> Option<[f64; 3]> {
    exec(d, "measure");
    let mut tel = String::new();
    let (mut w2, mut n) = (0.0, 0.0);
    let we = m.pole_pairs as f64 / d.sim().rig().screw.lead_m_per_rad;
    while d.sim().controller().mode() == Mode::Measure {
        d.step(&mut tel);
        if matches!(
            d.sim().controller().measurement().phase(),
            Phase::Ld | Phase::Lq
        ) {
            let v = d.sim().motion().1 * we;
            w2 += v * v;
            n += 1.0;
        }
    }
    let me = *d.sim().controller().measurement();
    if me.phase() != Phase::Done {
        return None;
    }
    Some([
        me.ld.mean() as f64 / m.l_d() - 1.0,
        me.lq.mean() as f64 / m.l_q() - 1.0,
        (w2 / n).sqrt(),
    ])
}

/// The board's TMD (`board`) at `a0` m/s², plant `seed`: as [`tmd_l_errors`].
fn board_l_errors(a0: f64, seed: u64) -> Option<[f64; 3]> {
    let mut sc = board(seed, 0.2);
    excite(&mut sc, a0);
    let m = sc.plant_machine();
    let mut d = SimDrive::from_scenario(&sc).expect("build");
    exec(&mut d, "mode idle");
    l_errors(&mut d, &m)
}

/// L_d and L_q against the structure's motion: per excitation level (0 … 2 m/s²) the
/// reference TMD (320 V, the salient machine, 8 start times from rest, 0.25 s apart) and 8
/// board plants (72 V, drawn ±20 %, their sensors' gain errors); printed: the r.m.s.
/// electrical speed over the pulses, each axis's error mean ± standard deviation and largest,
/// and the measurements the travel limit or a fault stopped. Judged at 1 m/s², where the
/// cross-coupling's share (`p·L_o·ω·Δi_o` from the other axis's current, which moves during
/// a pulse) was +4.4 % on L_d and +3.6 % on L_q of the TMD (`docs/commissioning.md`).
#[test]
fn l_unbiased_by_the_structures_motion() {
    use rayon::prelude::*;
    // (mean, standard deviation, largest |error|) of column k.
    let st = |e: &[[f64; 3]], k: usize| {
        let v: Vec<f64> = e.iter().map(|x| x[k]).collect();
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        (mean, sd, v.iter().fold(0.0f64, |a, x| a.max(x.abs())))
    };
    println!(
        "| plant | a0 m/s² | r.m.s. ω_e rad/s | L_d error mean ± sd (largest) | L_q error mean ± sd (largest) | stopped |"
    );
    println!("| --- | --- | --- | --- | --- | --- |");
    let mut at_1 = Vec::new();
    for a0 in [0.0, 0.25, 0.5, 1.0, 2.0] {
        let tmd: Vec<Option<[f64; 3]>> = (0..8)
            .into_par_iter()
            .map(|k| tmd_l_errors(a0, 0.25 * k as f64))
            .collect();
        let brd: Vec<Option<[f64; 3]>> = (0..8)
            .into_par_iter()
            .map(|s| board_l_errors(a0, s))
            .collect();
        for (name, e) in [("TMD 320 V", &tmd), ("board 72 V", &brd)] {
            let stopped = e.iter().filter(|x| x.is_none()).count();
            let e: Vec<[f64; 3]> = e.iter().flatten().copied().collect();
            let ((md, sd, xd), (mq, sq, xq), (w, _, _)) = (st(&e, 0), st(&e, 1), st(&e, 2));
            println!(
                "| {name} | {a0} | {w:.0} | {:+.2} ± {:.2} % ({:.2} %) | {:+.2} ± {:.2} % ({:.2} %) | {stopped} of 8 |",
                100.0 * md,
                100.0 * sd,
                100.0 * xd,
                100.0 * mq,
                100.0 * sq,
                100.0 * xq
            );
            if a0 == 1.0 {
                // A stop by travel (the TMD's stroke at 1 m/s² passes `meas_travel_m` while
                // the d current flows) is the measurement's own refusal, not an error.
                assert!(stopped <= 2, "{name}: {stopped} of 8 stopped");
                at_1.extend(e);
            }
        }
    }
    // At 1 m/s² (15 measurements, 7 TMD and 8 board): measured L_d mean +0.41 %, largest
    // |error| 1.68 %; L_q +0.14 %, 1.43 % (the board's spread is its current sensors' ±2 %
    // gains, ±1.1 % at rest). The mean's standard error is ≈ 0.3 % (a standard deviation of
    // ≈ 1.2 % over √15): bound 3 of it, 0.9 %; each error within 3 %, 1.8–2.1× the largest
    // (3× would pass the bias this test is for: +4.4 % mean on the TMD without the term).
    let ((md, _, xd), (mq, _, xq), _) = (st(&at_1, 0), st(&at_1, 1), st(&at_1, 2));
    println!(
        "1 m/s²: L_d mean {:+.2} %, largest {:.2} %; L_q mean {:+.2} %, largest {:.2} %",
        100.0 * md,
        100.0 * xd,
        100.0 * mq,
        100.0 * xq
    );
    assert!(
        md.abs() < 0.009 && mq.abs() < 0.009,
        "mean L_d {md}, L_q {mq}"
    );
    assert!(xd < 0.03 && xq < 0.03, "largest L_d {xd}, L_q {xq}");
}

/// `measure` at `a0` m/s²: on the reference TMD (320 V, the apply test's salient machine, the
/// firmware told the plant's R, K_e and L_d) after `k·0.25 s` idle for k < `n`, else on
/// board plant `k − n` (72 V, drawn ±20 %); per run the `measure show` reply and, if R and L
/// were given, their errors against the plant's in units of their stated uncertainty.
fn strong_motion(a0: f64, k: u64, n: u64) -> (String, Option<[f64; 3]>) {
    let mut sc = if k < n {
        salient_tmd(306.0)
    } else {
        board(k - n, 0.2)
    };
    excite(&mut sc, a0);
    let m = sc.plant_machine();
    let mut d = SimDrive::from_scenario(&sc).expect("build");
    exec(&mut d, "mode idle");
    if k < n {
        run(&mut d, 0.25 * k as f64);
    }
    let shown = measure_on(&mut d);
    let me = *d.sim().controller().measurement();
    if me.phase() != Phase::Done || me.rl_refused().is_some() {
        return (shown, None);
    }
    let u = me.uncertainty();
    let z = |x: f32, y: f64, u: f32| (x as f64 - y) / u as f64;
    (
        shown,
        Some([
            z(me.r.mean(), m.r_ohm, u[0]),
            z(me.ld.mean(), m.l_d(), u[1]),
            z(me.lq.mean(), m.l_q(), u[2]),
        ]),
    )
}

/// Under the structure's strong motion (2 m/s²: the TMD's emf near its bus, the board's
/// beyond it; and 1 m/s²) every R, L_d and L_q `measure` gives lies within 3 of its stated
/// uncertainty of the plant's, or the run is refused or stopped by name (`measure show`
/// says why: `meas_v_limit`, `measure_moving`, a fault). 8 TMD start times and 16 board
/// plants per level. Measured at 2 m/s²: the largest |error|/u 2.5 (R, L_q), at 1 m/s² 2.0;
/// the bound 3 is the brief's (a standard uncertainty's 99.7 %), 1.2× the largest. Without
/// R's cross-coupling term R came out +33 … +74 % (4–7 u) at 2 m/s².
#[test]
fn r_and_l_within_their_uncertainty_under_strong_motion() {
    use rayon::prelude::*;
    let n = 8;
    for a0 in [1.0, 2.0] {
        let runs: Vec<(String, Option<[f64; 3]>)> = (0..n + 16)
            .into_par_iter()
            .map(|k| strong_motion(a0, k, n))
            .collect();
        let mut worst = [0.0f64; 3];
        let mut refused = Vec::new();
        for (k, (shown, z)) in runs.iter().enumerate() {
            match z {
                Some(z) => {
                    for j in 0..3 {
                        worst[j] = worst[j].max(z[j].abs());
                    }
                    assert!(
                        z.iter().all(|z| z.abs() <= 3.0),
                        "{a0} m/s², run {k}: R, L_d, L_q off by {z:.2?} of their uncertainty\n{shown}"
                    );
                }
                None => {
                    // Refused or stopped: by name, one line saying why.
                    let why = shown
                        .lines()
                        .find(|l| l.contains("refused: ") || l.starts_with("error: measure"))
                        .unwrap_or_else(|| panic!("{a0} m/s², run {k}: no reason\n{shown}"));
                    refused.push(why.to_string());
                }
            }
        }
        // Coverage: the share of the values given within 1 and 2 of their uncertainty.
        let given: Vec<f64> = runs.iter().filter_map(|r| r.1).flatten().collect();
        let within = |c: f64| {
            given.iter().filter(|z| z.abs() <= c).count() as f64 / given.len().max(1) as f64
        };
        println!(
            "{a0} m/s²: {} of {} given, largest |error|/u: R {:.2}, L_d {:.2}, L_q {:.2}; \
             coverage {:.0} % within 1, {:.0} % within 2",
            runs.len() - refused.len(),
            runs.len(),
            worst[0],
            worst[1],
            worst[2],
            100.0 * within(1.0),
            100.0 * within(2.0)
        );
        for r in &refused {
            println!("  {r}");
        }
        // Most runs are given (not everything refused): 16 board plants and most TMD starts.
        assert!(refused.len() <= runs.len() / 2, "{a0} m/s²: {refused:?}");
    }
}
