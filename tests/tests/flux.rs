//! Flux braking (`regen_fw::protect::flux_brake_id`, docs/protection.md "Bus management") in
//! the board's 72 V class: the reference TMD (`board-72v-tmd-306.toml`) at 0.5 m/s² and an
//! emulated 100 Ω, i.e. a harmonic-balance velocity amplitude of 0.056 m/s, half the
//! 0.112 m/s diode onset; at 8 s the bus's source is lost and the brake resistor opens
//! (nothing but the drive's own losses takes the harvest), the stage model under the
//! firmware.
//!
//! * With flux braking (`flux_brake_a` = 1.9 A, the default) the bus is held in the band
//!   between `brake_on_v` and `derate_start_v`: no fault, the damping (i_q) kept, so the TMD
//!   keeps its amplitude.
//! * Power balance once the bus is held (from 4 s after the loss to the end): the winding
//!   burns `3/2·R·i_d²` (the firmware's i_d), what the resistor law would send to the bus
//!   less the drive's own losses (ledger) and the capacitor's change; the law's power is the
//!   harmonic balance's closed form (`analytic::tmd_power`, load power).
//! * Without it (`flux_brake_a` = 0, same run) the bus climbs into the derating band, the
//!   derating takes the damping away, the TMD's amplitude grows past the onset and the bus
//!   trips (`bus_over_voltage`).

use hal_sim::analytic::{tmd_power, DampingFormula};
use hal_sim::cli::sweep::set_param;
use hal_sim::faults::{FaultSim, Inject};
use hal_sim::plant::Drive;
use hal_sim::scenario::Scenario;
use hal_sim::stage::StageSpec;
use regen_fw::protect::Fault;

const A0: f64 = 0.5;
const R_LOAD: f64 = 100.0;
const T_LOSS: f64 = 8.0;
const T_END: f64 = 20.0;

fn scenario(flux_a: f32) -> Scenario {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../hal-sim/scenarios");
    let mut sc = Scenario::from_file(&dir.join("board-72v-tmd-306.toml")).expect("scenario");
    sc.record.channels.clear();
    sc.law.r_load_ohm = R_LOAD;
    set_param(&mut sc, "a0_m_s2", A0).expect("a0_m_s2");
    sc.firmware.flux_brake_a = flux_a;
    sc
}

#[derive(Debug, Default)]
struct Out {
    bus_peak: f64,
    speed_peak_after: f64,
    fault: Option<(Fault, f64)>,
    /// Mean 3/2·R·i_d² over the balance window, W.
    burn_w: f64,
    /// Mean drive losses (switching, conduction, logic) and capacitor power over it, W.
    drive_w: f64,
    cap_w: f64,
    /// The most flux braking's d current reached, A (negative).
    id_min: f64,
}

fn run(flux_a: f32) -> Out {
    let sc = scenario(flux_a);
    let sim = sc.build().expect("build");
    let cfg = *sim.controller().config();
    let spec = StageSpec::from_config(&cfg, 100.0);
    let r = cfg.r_phase_ohm as f64;
    let c_bus = sc.bus.capacitance_f;
    let mut fs =
        FaultSim::new(sim, Inject::LoadDisconnect { brake_open: true }, T_LOSS, 1).with_stage(spec);
    let t_win = T_LOSS + 4.0;
    let mut o = Out::default();
    let (mut n, mut e0, mut v0) = (0u64, None, 0.0);
    let drive = |fs: &FaultSim| {
        let e = fs.sim.energy();
        e.switching_loss + e.conduction_loss + e.logic_loss
    };
    while fs.sim.time() < T_END {
        fs.step().expect("step");
        let t = fs.sim.time();
        if t < T_LOSS {
            continue;
        }
        o.bus_peak = o.bus_peak.max(fs.sim.v_bus());
        o.speed_peak_after = o.speed_peak_after.max(fs.sim.motion().1.abs());
        if o.fault.is_none() {
            o.fault = fs.sim.controller().fault().map(|f| (f, t));
        }
        let id = fs.sim.controller().telemetry().i_dq.d.to_num::<f64>();
        o.id_min = o.id_min.min(id);
        if t >= t_win {
            if e0.is_none() {
                e0 = Some(drive(&fs));
                v0 = fs.sim.v_bus();
            }
            o.burn_w += 1.5 * r * id * id;
            n += 1;
        }
    }
    let dt = n as f64 * fs.sim.period();
    o.burn_w /= n.max(1) as f64;
    o.drive_w = (drive(&fs) - e0.unwrap_or(0.0)) / dt;
    o.cap_w = 0.5 * c_bus * (fs.sim.v_bus().powi(2) - v0 * v0) / dt;
    o
}

#[test]
fn flux_braking_holds_the_bus() {
    let sc = scenario(1.9);
    let Drive::Structure { structure: st, .. } = sc.drive.clone() else {
        panic!("a structure")
    };
    let hb = tmd_power(
        R_LOAD,
        &sc.machine,
        &sc.screw,
        &st,
        A0,
        0.5,
        DampingFormula::PerPhasePeak,
    );
    let cfg = sc.config().expect("config");
    let onset = 72.0 / (3f64.sqrt() * sc.machine.ke_v_s_per_rad) * sc.screw.lead_m_per_rad;
    let (on, off) = rayon::join(|| run(1.9), || run(0.0));
    let want = hb.p_load - on.drive_w - on.cap_w;
    println!(
        "TMD {A0} m/s², {R_LOAD} Ω: harmonic balance {:.3} m/s (onset {onset:.3}), load power {:.3} W",
        hb.velocity_amp, hb.p_load
    );
    println!(
        "flux braking on: bus peak {:.2} V, speed peak {:.3} m/s, fault {:?}, i_d down to {:.2} A; \
         burnt 3/2·R·i_d² {:.3} W against load power − drive losses − capacitor {:.3} − {:.3} − {:.3} = {:.3} W ({:+.1} %)",
        on.bus_peak, on.speed_peak_after, on.fault, on.id_min, on.burn_w, hb.p_load, on.drive_w,
        on.cap_w, want, 100.0 * (on.burn_w / want - 1.0)
    );
    println!(
        "flux braking off: bus peak {:.2} V, speed peak {:.3} m/s, fault {:?}",
        off.bus_peak, off.speed_peak_after, off.fault
    );
    assert!(on.fault.is_none(), "{:?}", on.fault);
    // Held in the band where flux braking takes a growing share (85 … 88 V): measured
    // 86.97 V, under the derating and the trip.
    assert!(on.bus_peak < cfg.derate_start_v as f64, "{}", on.bus_peak);
    assert!(on.id_min < -0.1, "flux braking acted");
    // Measured +0.075 W: +0.029 W with ideal sensors (the TMD's amplitude and the current
    // ripple about the balance's sinusoid), the rest from the scenario's drawn per-phase
    // gain errors (±2 %, the board's sensing), which bias the firmware's i_d and so its
    // i_d² by up to 4 % (0.043 W); bounded at 2×, 0.15 W (5 % of the load power).
    assert!(
        (on.burn_w - want).abs() < 0.15,
        "{} W against {want} W",
        on.burn_w
    );
    // The damping is kept: the speed stays at the balance's amplitude (measured peak +5.4 %,
    // bounded at 3×).
    assert!(on.speed_peak_after < 1.16 * hb.velocity_amp);
    assert!(
        matches!(off.fault, Some((Fault::BusOverVoltage, _))),
        "{:?}",
        off.fault
    );
}
