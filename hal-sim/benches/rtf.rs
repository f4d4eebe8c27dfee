//! Closed-loop real-time factor (one core, 20 kHz, averaged inverter) and the analytic
//! sweep's time. `cargo bench -p hal-sim --bench rtf` prints the figures.

use hal_sim::analytic::{logspace, optimum_load, tmd_power, DampingFormula};
use hal_sim::plant::Structure;
use hal_sim::scenario::Scenario;
use std::time::Instant;

fn main() {
    let mut sc = Scenario::tmd(306.0);
    sc.record.channels.clear();
    let sim_s = 20.0;
    let mut best = f64::MAX;
    let mut sim = sc.build().expect("scenario");
    for _ in 0..3 {
        let t = Instant::now();
        sim.run_for(sim_s);
        best = best.min(t.elapsed().as_secs_f64());
    }
    let steps = sim_s / sim.period();
    println!(
        "closed loop (TMD, resistor law, 20 kHz, averaged inverter, one core): {:.0}x real time, {:.1} ns per PWM period; energy residual {:.1e}",
        sim_s / best,
        best / steps * 1e9,
        sim.energy().relative_residual()
    );
    // The firmware's step alone, for the split of the period's cost.
    let mut ctl = regen_fw::Controller::new(&sc.config().unwrap()).unwrap();
    ctl.set_mode(regen_fw::Mode::Run).unwrap();
    let n_ctl = 2_000_000u32;
    let t = Instant::now();
    for k in 0..n_ctl {
        let s = regen_fw::RawSample {
            i_abc: [2048 + (k & 7) as u16, 2040, 2050],
            v_bus: 2900,
            encoder: (k / 4) as u16,
        };
        std::hint::black_box(ctl.step(std::hint::black_box(&s)));
    }
    println!(
        "firmware Controller::step alone on the host: {:.1} ns",
        t.elapsed().as_secs_f64() / n_ctl as f64 * 1e9
    );
    let t = Instant::now();
    let st = Structure::default();
    let mut n = 0;
    let mut acc = 0.0;
    for _ in 0..100 {
        for r in logspace(10.0, 1000.0, 1000) {
            acc += tmd_power(
                r,
                &sc.machine,
                &sc.screw,
                &st,
                1.0,
                0.5,
                DampingFormula::PerPhasePeak,
            )
            .p_load;
            n += 1;
        }
        acc += optimum_load(
            |r| {
                tmd_power(
                    r,
                    &sc.machine,
                    &sc.screw,
                    &st,
                    1.0,
                    0.5,
                    DampingFormula::PerPhasePeak,
                )
                .p_load
            },
            1.0,
            1e4,
        );
    }
    let dt = t.elapsed().as_secs_f64();
    println!(
        "analytic TMD sweep: {:.1} ns per load point; a 1000-point sweep + optimum search in {:.1} µs (checksum {acc:.3})",
        dt / (n as f64 + 100.0 * 200.0) * 1e9,
        dt / 100.0 * 1e6
    );
}
