//! Commissioning (`measure`, `regen_fw::commission`): the drive measures R, L_d, L_q and K_e
//! of plants drawn off their nameplate; `measure apply` restores the emulated load.

use hal_sim::drive::SimDrive;
use hal_sim::plant::{Drive, Excitation};
use hal_sim::powerup::PlantDraw;
use hal_sim::Scenario;
use regen_fw::commission::Phase;
use regen_fw::Mode;

/// The board's reference TMD (`board-72v-tmd-306.toml`: power-up, shunt sampling) at
/// 0.4 m/s² (below the 72 V bus's diode onset), its plant drawn by `seed` within ±`tol`.
fn board(seed: u64, tol: f64) -> Scenario {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../hal-sim/scenarios");
    let mut sc = Scenario::from_file(&dir.join("board-72v-tmd-306.toml")).expect("scenario");
    sc.record.channels.clear();
    if let Drive::Structure { excitation, .. } = &mut sc.drive {
        *excitation = Excitation::Sine {
            a0_m_s2: 0.4,
            freq_hz: 0.5,
        };
    }
    sc.plant_draw = PlantDraw {
        r_rel: tol,
        l_rel: tol,
        ke_rel: tol,
        seed,
    };
    sc.powerup.seed = seed;
    sc
}

/// Boot (the build's), `mode idle`, `measure`, run until it ends; the measurement.
fn measure(sc: &Scenario) -> (SimDrive, String) {
    let mut d = SimDrive::from_scenario(sc).expect("build");
    let mut out = String::new();
    d.execute("mode idle", &mut out).expect("idle");
    out.clear();
    d.execute("measure", &mut out)
        .unwrap_or_else(|_| panic!("{out}"));
    let mut tel = String::new();
    let mut n = 0u64;
    while d.sim().controller().mode() == Mode::Measure && n < 20 * 20_000 {
        d.step(&mut tel);
        n += 1;
    }
    out.clear();
    let _ = d.execute("measure show", &mut out);
    (d, out)
}

#[test]
fn explore() {
    let sc = board(3, 0.2);
    let m = sc.plant_machine();
    let (d, out) = measure(&sc);
    println!("{out}");
    println!("plant R {} L {} Ke {}", m.r_ohm, m.l_h, m.ke_v_s_per_rad);
    let me = d.sim().controller().measurement();
    assert_eq!(me.phase(), Phase::Done, "{:?}", me.failure());
}
