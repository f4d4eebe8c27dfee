//! `clear` refuses, by name, while a latched fault's cause persists (docs/protection.md,
//! "cleared when"), on the served drive (`SimDrive`, the console `regen serve` runs), for the
//! two ways `over_force` arises once the gates are off and the filtered force has decayed:
//! - the current limit lets the law command more than the trip (`f_trip_n` lowered below
//!   `3/2·K_e·i_max_a/lead`): the law would command it again at the next speed peak, so
//!   `clear` names `i_max_a` until the limit's force is within the clear level;
//! - for a trip at a speed beyond the rating, the structure moving faster than the drive can
//!   control (back-emf above the voltage circle): the current follows the emf, so `clear`
//!   names the motion until it has been slower for 2.5–5 s; a trip within the rating leaves
//!   the motion out (the reference TMD runs with its peaks past the circle).
//!
//! Then `clear` is accepted and `mode run` holds without a fault.

use hal_sim::drive::SimDrive;
use hal_sim::plant::Motion;
use hal_sim::Scenario;

/// Run `s` seconds of simulated time, collecting fault notices.
fn run(d: &mut SimDrive, s: f64, notes: &mut String) {
    let mut tel = String::new();
    let n = (s / d.sim().period()).round() as u64;
    for _ in 0..n {
        d.step(&mut tel);
        tel.clear();
        d.notice(notes);
    }
}

/// The last line of the console's reply to `line`.
fn exec(d: &mut SimDrive, line: &str) -> String {
    let mut out = String::new();
    let _ = d.execute(line, &mut out);
    out.trim_end().lines().last().unwrap_or("").to_string()
}

const KE: f64 = 0.943;

fn lead() -> f64 {
    hal_sim::plant::Screw::default().lead_m_per_rad
}

/// The reference machine's rating on the 320 V bus: K_e·ω = m_max·V_bus/√3 (m_max 0.95),
/// m/s of travel.
fn rating_m_s() -> f64 {
    0.95 * 320.0 / 3f64.sqrt() / KE * lead()
}

/// A symmetric triangle of amplitude `amp` at `v_fast` m/s until `t_switch`, then at `v_slow`,
/// sampled every ms (linear between samples): the imposed motion, as a recorded trajectory.
fn two_speed_triangle(amp: f64, v_fast: f64, v_slow: f64, t_switch: f64, t_end: f64) -> Motion {
    let (mut t_s, mut x_m) = (vec![], vec![]);
    let (mut x, mut dir) = (0.0_f64, 1.0_f64);
    let dt = 1e-3;
    for k in 0..=((t_end / dt).round() as usize) {
        let t = k as f64 * dt;
        t_s.push(t);
        x_m.push(x);
        let v = if t < t_switch { v_fast } else { v_slow };
        x += dir * v * dt;
        if x.abs() >= amp {
            x = amp.copysign(x);
            dir = -dir;
        }
    }
    Motion::Recorded {
        t_s,
        x_m,
        v_m_s: vec![],
        a_m_s2: vec![],
        v_kin_m_s: vec![],
    }
}

/// Imposed sine of 0.3 m/s peak (118 rad/s, within the rating) at 306 Ω: the law's force
/// peaks near 200 N; force trips of 100–160 N are passed at every peak, while the default
/// current limit (1.937 A) allows 1,076 N.
#[test]
fn clear_of_over_force_waits_for_the_current_limit() {
    for f_trip in [100.0, 120.0, 140.0, 160.0] {
        let amp = 0.075;
        let motion = Motion::Sine {
            amplitude_m: amp,
            freq_hz: 0.3 / (std::f64::consts::TAU * amp),
        };
        let mut d = SimDrive::from_scenario(&Scenario::imposed(motion, 306.0, 100.0)).unwrap();
        let mut notes = String::new();
        run(&mut d, 0.5, &mut notes);
        let set = exec(&mut d, &format!("set f_trip_n {f_trip}"));
        assert_eq!(set, format!("ok f_trip_n = {f_trip} N"));
        run(&mut d, 2.0, &mut notes);
        assert!(
            notes.contains("# fault 5 over_force"),
            "f_trip {f_trip}: {notes}"
        );
        // Every 0.1 s over two motion periods (1.57 s each): the currents are off, the
        // filtered force decays within 0.1 s, the limit stays.
        for k in 0..32 {
            run(&mut d, 0.1, &mut notes);
            let r = exec(&mut d, "clear");
            assert!(
                r.starts_with("error: over_force not cleared:") && r.contains("i_max_a"),
                "f_trip {f_trip}, clear {k}: {r}"
            );
            assert!(exec(&mut d, "mode run").starts_with("error:"), "{k}");
        }
        // The limit's force at 0.85 f_trip, below the clear level (0.9 f_trip).
        let i_max = 0.85 * f_trip * lead() / (1.5 * KE);
        let set = exec(&mut d, &format!("set i_max_a {i_max:.4}"));
        assert!(set.starts_with("ok i_max_a"), "{set}");
        assert_eq!(exec(&mut d, "clear"), "ok cleared over_force");
        assert_eq!(exec(&mut d, "mode run"), "ok mode run");
        notes.clear();
        run(&mut d, 4.0, &mut notes);
        println!(
            "f_trip {f_trip} N: clear refused 32 of 32 times over 3.2 s naming i_max_a; \
             i_max_a {i_max:.4} A: cleared, 4 s in run: {}",
            if notes.contains("# fault") {
                "fault"
            } else {
                "no fault"
            }
        );
        assert!(!notes.contains("# fault"), "f_trip {f_trip}: {notes}");
    }
}

/// Imposed triangles 5–15 % above the rating (the rating's speed is 186 rad/s, 0.474 m/s; the
/// diode onset 228 rad/s lies beyond them, so the open bridge carries no current), then at
/// 60 % of it: over_force latches at the default limits; `clear` names the motion while it
/// is fast and for 2.5 s after it slowed, and is accepted within 5 s of it (the peak
/// windows); `mode run` then holds.
#[test]
fn clear_of_over_force_waits_for_the_motion() {
    let rating = rating_m_s();
    for over in [1.05, 1.10, 1.15] {
        let t_switch = 4.0;
        let motion = two_speed_triangle(0.3, over * rating, 0.6 * rating, t_switch, 30.0);
        let mut d = SimDrive::from_scenario(&Scenario::imposed(motion, 306.0, 30.0)).unwrap();
        let mut notes = String::new();
        run(&mut d, 1.0, &mut notes);
        assert!(notes.contains("# fault 5 over_force"), "{over}: {notes}");
        let (mut refused_fast, mut refused_after, mut cleared_at) = (0, 0, None);
        while d.sim().time() < t_switch + 6.0 {
            run(&mut d, 0.1, &mut notes);
            let t = d.sim().time();
            let r = exec(&mut d, "clear");
            if r.starts_with("error: over_force not cleared:") {
                assert!(r.contains("passed the rating"), "{over} at {t:.1} s: {r}");
                assert!(exec(&mut d, "mode run").starts_with("error:"));
                if t < t_switch {
                    refused_fast += 1;
                } else {
                    refused_after += 1;
                }
                continue;
            }
            assert_eq!(r, "ok cleared over_force", "{over} at {t:.1} s");
            cleared_at = Some(t - t_switch);
            break;
        }
        let after = cleared_at.expect("clear accepted within 6 s of the slowdown");
        println!(
            "{over:.2}× the rating: clear refused {refused_fast} times while fast, \
             {refused_after} times after the slowdown, accepted {after:.1} s after it"
        );
        // Every try while fast refused (30 tries from 1 s to 4 s), none accepted before the
        // first window ends (2.5 s), every one accepted after both windows (5 s + 0.1 s).
        assert_eq!(refused_fast, 30, "{over}");
        assert!((2.5..=5.1).contains(&after), "{over}: {after}");
        assert_eq!(exec(&mut d, "mode run"), "ok mode run");
        notes.clear();
        run(&mut d, 3.0, &mut notes);
        assert!(!notes.contains("# fault"), "{over}: {notes}");
    }
}

/// A trip within the rating leaves the motion out: the reference TMD (`Scenario::tmd(306)`,
/// whose peaks in `run` pass the voltage circle, 198 rad/s against 186, without a trip) trips
/// a lowered force limit (100 N) at about 60 rad/s; in idle its amplitude grows past the
/// rating; with the limit put back (1,300 N) `clear` is accepted and `mode run` holds.
#[test]
fn clear_after_a_trip_within_the_rating_ignores_the_motion() {
    let mut d = SimDrive::from_scenario(&Scenario::tmd(306.0)).unwrap();
    let mut notes = String::new();
    run(&mut d, 3.0, &mut notes);
    assert_eq!(exec(&mut d, "set f_trip_n 100"), "ok f_trip_n = 100 N");
    run(&mut d, 1.5, &mut notes);
    assert!(notes.contains("# fault 5 over_force"), "{notes}");
    let rec = d.sim().controller().protection().record().unwrap();
    let w_trip = rec.snap.omega_m.to_num::<f64>().abs();
    run(&mut d, 3.0, &mut notes);
    let peak = d.sim().controller().protection().speed_peak() as f64;
    let rating = 0.95 * d.sim().channel(hal_sim::Channel::VBus) / 3f64.sqrt() / KE;
    println!("tripped at {w_trip:.0} rad/s; idle peak {peak:.0} rad/s, rating {rating:.0} rad/s");
    assert!(w_trip < rating, "the trip must lie within the rating");
    assert!(peak > rating, "the idle motion must pass the rating");
    assert_eq!(exec(&mut d, "set f_trip_n 1300"), "ok f_trip_n = 1300 N");
    assert_eq!(exec(&mut d, "clear"), "ok cleared over_force");
    assert_eq!(exec(&mut d, "mode run"), "ok mode run");
    notes.clear();
    run(&mut d, 4.0, &mut notes);
    assert!(!notes.contains("# fault"), "{notes}");
}
