//! A record written by the closed-loop simulator (hal-sim's `Sim` running the unchanged
//! firmware with its emulated-resistor law) is diagnosed like a measured one: the baseline
//! then carries the electromagnetic force f_em = −3/2·K_e·i_q/l (firmware/src/lib.rs
//! conventions), its gain is a K_e estimate, and with it the record's force is explained.

use hal_sim::diagnose::{diagnose, parse_csv, Diagnosis, Options};
use hal_sim::plant::Motion;
use hal_sim::Scenario;
use regen_fw::laws::{Law, Resistor};
use std::fmt::Write as _;

/// Load schedule (Ω), switched every 0.7 s, so that the electromagnetic force is not a fixed
/// multiple of the velocity (with a constant load it is exactly collinear with viscous
/// friction and no record can tell the two apart).
const LOADS: [f64; 3] = [10.0, 40.0, 160.0];

struct SimRecord {
    csv_iq: String,
    csv_abc: String,
    csv_load: String,
    ke: f64,
    reflected_mass: f64,
    viscous: f64,
    coulomb: f64,
    r_s: f64,
}

/// 6 s of imposed sine motion (±8 mm at 1 Hz: at most 1.5 A at the 10 Ω load, below the firmware current limit i_max_a = 1.937 A) with the resistor law, sampled at 1 kHz.
fn closed_loop_record() -> SimRecord {
    let sc = Scenario::imposed(
        Motion::Sine {
            amplitude_m: 0.008,
            freq_hz: 1.0,
        },
        LOADS[0],
        6.0,
    );
    let mut sim = sc.build().expect("scenario builds");
    let r_s = sc.machine.r_ohm;
    let per_sample = (1e-3 / sim.period()).round() as usize;
    let lead_rev = sc.screw.lead_m_per_rad * std::f64::consts::TAU;
    let mut csv_iq = format!(
        "# closed-loop simulator record\n# lead_m_per_rev = {lead_rev}\nt_s,x_m,f_N,i_q_A\n"
    );
    let mut csv_abc = format!(
        "# closed-loop simulator record\n# lead_m_per_rev = {lead_rev}\nt_s,x_m,f_N,i_a_A,i_b_A,i_c_A,theta_e_rad\n"
    );
    let mut csv_load = format!(
        "# closed-loop simulator record\n# lead_m_per_rev = {lead_rev}\n# r_s_ohm = {r_s}\nt_s,x_m,f_N,r_load_ohm\n"
    );
    let mut load = LOADS[0];
    for k in 0..6000 {
        let t = k as f64 * 1e-3;
        let want = LOADS[((t / 0.7) as usize) % LOADS.len()];
        if want != load {
            load = want;
            if let Law::Resistor(r) = sim.controller_mut().law_mut() {
                *r = Resistor::new(r_s as f32, load as f32);
            }
        }
        for _ in 0..per_sample {
            sim.step();
        }
        let (x, _) = sim.motion();
        let (f, _) = sim.force();
        let (_, iq) = sim.i_dq();
        let _ = writeln!(csv_iq, "{:.6},{x:.9e},{f:.6},{iq:.6}", sim.time());
        let _ = writeln!(csv_load, "{:.6},{x:.9e},{f:.6},{load}", sim.time());
        // electrical angle of the d axis as the plant defines it (p·x/l + offset)
        let th = sc.machine.pole_pairs as f64 * x / sc.screw.lead_m_per_rad
            + sc.machine.angle_offset_rad;
        let [ia, ib, ic] = sim.currents();
        let _ = writeln!(
            csv_abc,
            "{:.6},{x:.9e},{f:.6},{ia:.6},{ib:.6},{ic:.6},{th:.9}",
            sim.time()
        );
    }
    assert!(sim.controller().fault().is_none(), "firmware faulted");
    SimRecord {
        csv_iq,
        csv_abc,
        csv_load,
        ke: sc.machine.ke_v_s_per_rad,
        reflected_mass: sc.screw.reflected_mass(),
        viscous: sc.screw.viscous_n_s_per_m,
        coulomb: sc.screw.coulomb_n,
        r_s,
    }
}

fn term(d: &Diagnosis, name: &str) -> f64 {
    d.baseline_terms
        .iter()
        .find(|b| b.effect == name)
        .unwrap_or_else(|| panic!("no baseline term {name}"))
        .value
}

#[test]
fn closed_loop_record_force_is_explained_with_the_electromagnetic_term() {
    let s = closed_loop_record();
    let rec = parse_csv(&s.csv_iq, None).expect("simulator record parses");
    let d = diagnose(&rec, &Options::default());
    println!("{}", hal_sim::diagnose::report::text(&rec, &d));
    let ke = term(&d, "electromagnetic_force");
    println!(
        "K_e fitted {ke:.4} V·s/rad (simulator {:.4}); M {:.2} kg (reflected {:.2}); Fv {:.1} (655); Fc {:.2} (40); error whole record {:.3} %",
        s.ke,
        term(&d, "inertia"),
        s.reflected_mass,
        term(&d, "viscous_friction"),
        term(&d, "coulomb_friction"),
        100.0 * d.final_full_rel_error
    );
    // The electromagnetic force is up to ~0.8 kN against ~0.07 kN of friction: i_q is recorded at the
    // end of each PWM period while the force is the period average, a zero-mean difference,
    // so K_e must come out within 2 % of the simulator's.
    assert!((ke / s.ke - 1.0).abs() < 0.02, "K_e {ke} vs {}", s.ke);
    // With it the force is explained to well under 1 % (no noise in this record beyond
    // the current loop's ripple and the derivative filter).
    assert!(d.final_full_rel_error < 0.01, "{}", d.final_full_rel_error);
    // Friction as configured (Coulomb within 10 %: it is 1-2 % of the force here).
    assert!((term(&d, "viscous_friction") / s.viscous - 1.0).abs() < 0.05);
    assert!((term(&d, "coulomb_friction") / s.coulomb - 1.0).abs() < 0.1);

    // The same record with phase currents and the electrical angle instead of i_q: the
    // diagnosis applies the amplitude-invariant Park transform itself; same bound on K_e.
    let rec = parse_csv(&s.csv_abc, None).expect("phase-current record parses");
    let d3 = diagnose(&rec, &Options::default());
    let ke3 = term(&d3, "electromagnetic_force");
    println!(
        "from i_a/b/c + theta_e: K_e {ke3:.4}; error whole record {:.3} %",
        100.0 * d3.final_full_rel_error
    );
    assert!((ke3 / s.ke - 1.0).abs() < 0.02, "K_e {ke3} vs {}", s.ke);
    assert!(
        d3.final_full_rel_error < 0.01,
        "{}",
        d3.final_full_rel_error
    );

    // The same record with only the load resistance: the term becomes K_e²·3/2·v/(l²(R+R_L)).
    let rec = parse_csv(&s.csv_load, None).expect("load record parses");
    let d2 = diagnose(&rec, &Options::default());
    let ke2 = term(&d2, "electromagnetic_force");
    println!(
        "from r_load_ohm: K_e² {ke2:.4} → K_e {:.4}; error whole record {:.3} %",
        ke2.max(0.0).sqrt(),
        100.0 * d2.final_full_rel_error
    );
    // The resistor law's current follows −K_e·ω/(R+R_L) only up to the current loop's
    // bandwidth and the law's update rate: 5 % on K_e.
    assert!((ke2.sqrt() / s.ke - 1.0).abs() < 0.05, "K_e² {ke2}");
    println!(
        "findings from r_load_ohm: {:?}",
        d2.findings
            .iter()
            .map(|f| (f.effect.as_str(), f.parameters.clone()))
            .collect::<Vec<_>>()
    );
    // Without the current the force is explained less well (the law's current reaches
    // −K_e·ω/(R+R_L) through the firmware's speed estimate and current loop, which the record
    // does not show), but still far better than with no electromagnetic term (the held-out
    // error without the term is reported and must be large).
    assert!(
        d2.final_full_rel_error < 0.05,
        "{}",
        d2.final_full_rel_error
    );
    let without = d2
        .baseline_terms
        .iter()
        .find(|b| b.effect == "electromagnetic_force")
        .unwrap()
        .holdout_rel_error_without;
    assert!(without > 4.0 * d2.baseline_holdout_rel_error, "{without}");
    let _ = s.r_s;
}
