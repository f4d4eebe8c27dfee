//! Regression check: on broadband (Kanai–Tajimi) base excitation with zero drive losses, the
//! two-way optimal law beats the best fixed resistor; the one-way law sits in between or near
//! the resistor. Compact model (`hal_sim::study`), firmware laws in fixed point.

use hal_sim::lqg::{self, LqgSpec};
use hal_sim::study::{broadband_run_with, study_config, LossModel};
use regen_fw::laws::LawKind;
use regen_fw::Config;

#[test]
fn two_way_beats_best_fixed_resistor_on_broadband() {
    let spec = LqgSpec::reference();
    let model = spec.model;
    let d = lqg::design(&spec).unwrap();
    let (r_best, p_r_an) = model.best_resistor(0.0);
    eprintln!(
        "analytic: best resistor {r_best:.1} Ω {p_r_an:.3} W; full-state optimum {:.3} W; LQG {:.3} W (+{:.1} %)",
        d.p_full_state,
        d.p_lqg,
        (d.p_lqg / p_r_an - 1.0) * 100.0
    );
    let secs = 1200.0;
    let runs = [
        study_config(LawKind::Resistor, r_best as f32),
        Config {
            opt: d.params,
            ..study_config(LawKind::TwoWay, 0.0)
        },
        Config {
            opt: d.params,
            ..study_config(LawKind::OneWay, 0.0)
        },
    ];
    let p: Vec<f64> = std::thread::scope(|s| {
        let h: Vec<_> = runs
            .iter()
            .map(|c| {
                s.spawn(move || {
                    broadband_run_with(model, c, LossModel::NONE, 42, 30.0, secs, &mut |_| {})
                        .expect("broadband run")
                        .p_terminal
                })
            })
            .collect();
        h.into_iter().map(|h| h.join().unwrap()).collect()
    });
    eprintln!(
        "simulated {secs} s, same noise: resistor {:.3} W, two-way {:.3} W ({:+.1} %), one-way {:.3} W ({:+.1} %)",
        p[0],
        p[1],
        (p[1] / p[0] - 1.0) * 100.0,
        p[2],
        (p[2] / p[0] - 1.0) * 100.0
    );
    // The simulations agree with the stationary analytic means. Statistical error of a 1200 s
    // mean of a process with ~1 s correlation time and a power CV of ~1.5: about
    // 1.5·√(2/1200) ≈ 6 %; 15 % is 2.5 σ. (The analytic LQG mean uses the continuous observer
    // without measurement noise; the firmware's 1 kHz ZOH observer differs by far less.)
    assert!(
        (p[0] / p_r_an - 1.0).abs() < 0.15,
        "resistor {} vs {p_r_an}",
        p[0]
    );
    assert!(
        (p[1] / d.p_lqg - 1.0).abs() < 0.15,
        "two-way {} vs {}",
        p[1],
        d.p_lqg
    );
    // The regression check proper. Same noise sequence for both, so the sampling error of the
    // ratio is much smaller than that of each mean; the analytic advantage is +45 % with the
    // default K_e = 0.943 (+26 % with the 0.513 reading), the test asks for 13 %.
    assert!(p[1] > 1.13 * p[0], "two-way {} vs resistor {}", p[1], p[0]);
}
