//! Tools on the bench rig's tuning records (ignored tests run by hand with `RIG_SEEDS`): the
//! diagnosis with the rig's true derivatives, the play's width profile, an effect at rest, the
//! specs of the records.

use hal_sim::bench_rig::Hidden;
use hal_sim::diagnose::{diagnose, parse_csv, Options};

mod rig_seeds;
use rig_seeds::*;

/// Records of the long run (`long_run_spec`, any family) diagnosed with the rig's true velocity
/// and acceleration given as `v_m_s`, `a_m_s2` beside the derived ones (`RIG_SEEDS=S1,S2,…
/// cargo test -p regen-tests --test diagnose_rig_tools rig_true_acceleration -- --ignored
/// --nocapture`; `RIG_TRUE=v` or `RIG_TRUE=a` gives only that one the rig's, the other derived):
/// the inertial error M·(a − a_derived) at the reversals and what the diagnosis names without
/// the derived signals' errors. The derived record's options: `RIG_CUT=Hz` the derivative
/// filter's cutoff (`--cutoff-hz`), `RIG_VBAND=1` its velocity through the acceleration's band
/// (`record::v_through_accel_band`), `RIG_FF=1` its force through the same filter
/// (`--filter-force`).
#[test]
#[ignore]
fn rig_true_acceleration() {
    let emps = emps_x();
    for seed in env_seeds() {
        let kind = Hidden::KINDS[((seed - 1) / TUNING_STRIDE) as usize];
        let spec = long_run_spec(seed, &emps);
        let (v_true, a_true) = spec.true_motion();
        let text = spec.csv();
        // read up to 1 MHz (above any rig's rate); each record's own rate bounds it
        // (`check_cutoff`, through `parse_csv`: 0, or a cutoff at or above a record's Nyquist
        // rate, is refused for that record)
        let cut: Option<f64> = env_number_set("RIG_CUT", 0.0..=1e6);
        let mut rec = match parse_csv(&text, cut) {
            Ok(r) => r,
            Err(e) => {
                println!("seed {seed} ({} Hz): RIG_CUT: {e}", spec.fs);
                continue;
            }
        };
        if std::env::var("RIG_VBAND").is_ok() {
            use hal_sim::diagnose::record::{
                v_through_accel_band, DERIVATIVE_CUTOFF_KEY, VELOCITY_CUTOFF_KEY,
            };
            if let (Some(v), Some(&fc)) = (
                v_through_accel_band(&rec),
                rec.meta.get(DERIVATIVE_CUTOFF_KEY),
            ) {
                rec.v = v;
                rec.meta.insert(VELOCITY_CUTOFF_KEY.to_string(), fc);
            }
        }
        if std::env::var("RIG_FF").is_ok() {
            rec.filter_force(cut);
        }
        let err: Vec<f64> = rec
            .a
            .iter()
            .zip(&a_true)
            .map(|(ad, at)| spec.mass_kg * (at - ad))
            .collect();
        let amax = a_true.iter().fold(0.0f64, |m, a| m.max(a.abs()));
        // reversals: where |a| exceeds a fifth of its peak
        let (mut e_rev, mut n_rev, mut e_all) = (0.0, 0usize, 0.0);
        for (e, a) in err.iter().zip(&a_true).skip(100).take(err.len() - 200) {
            e_all += e * e;
            if a.abs() > 0.2 * amax {
                e_rev += e * e;
                n_rev += 1;
            }
        }
        let m = (err.len() - 200) as f64;
        println!(
            "{kind} seed {seed}: quantum {:.1e} m, mass {:.1} kg, peak a {amax:.2} m/s², M·(a − a_derived) rms {:.3} N overall, {:.3} N on the {n_rev} reversal samples; noise {:.2} N, effect {:.2} N rms",
            spec.quantum_m,
            spec.mass_kg,
            (e_all / m).sqrt(),
            (e_rev / n_rev.max(1) as f64).sqrt(),
            spec.noise_n,
            spec.effect_rms_n
        );
        let mut lines = text.lines();
        let mut with_a = String::new();
        for l in lines.by_ref() {
            if l.starts_with('#') {
                with_a.push_str(l);
                with_a.push('\n');
            } else {
                with_a.push_str(l);
                with_a.push_str(",v_m_s,a_m_s2\n");
                break;
            }
        }
        // RIG_TRUE=v (or a): only that signal the rig's, the other the record's derived one
        let only = env_choice("RIG_TRUE", &["v", "a"]).unwrap_or_default();
        let v_in = if only == ["a"] { &rec.v } else { &v_true };
        let a_in = if only == ["v"] { &rec.a } else { &a_true };
        for ((l, v), a) in lines.zip(v_in).zip(a_in) {
            with_a.push_str(&format!("{l},{v:.9e},{a:.9e}\n"));
        }
        let rec2 = parse_csv(&with_a, None).expect("record with a parses");
        for (label, r) in [("derived a", &rec), ("true a", &rec2)] {
            let d = diagnose(r, &Options::default());
            println!(
                "    {label}: {:?} held-out {:.2} % -> {:.2} %",
                d.catalogue_names(),
                100.0 * d.baseline_holdout_rel_error,
                100.0 * d.final_holdout_rel_error
            );
            if std::env::var("RIG_EVIDENCE").is_ok() {
                for f in &d.findings {
                    println!(
                        "      {} {:?}: held-out rss -{:.2} %, held on {:.0} %",
                        f.effect,
                        f.parameters,
                        100.0 * f.holdout_rss_drop,
                        100.0 * f.consistency
                    );
                }
            }
        }
    }
}

/// The play's joint fit profiled over its width on records of the long run's backlash kind
/// (`RIG_SEEDS=S1,S2 cargo test -p regen-tests --test diagnose_rig
/// rig_play_width_profile -- --ignored --nocapture`): the play's columns
/// (`effects::play_columns_with`) at the rig's width × (1 + 0.02k), k = −10 … 10, fitted with
/// the baseline's columns on the training part; per width the held-out rss against the
/// baseline's, the free force's gain and the impact's sum (kg), with the device the diagnosis
/// fits (`play_device_coefficients`) and with the rig's own (inertia, drive damping plus
/// viscous friction, Coulomb). It separates what the device's fit costs from what the walk
/// lacks. The trajectory of a seed is the classic long run's (`long_run_spec`).
#[test]
#[ignore]
fn rig_play_width_profile() {
    use hal_sim::diagnose::effects::{
        impact_travel, play_columns_with, play_device_coefficients, Context,
    };
    use hal_sim::diagnose::{holdout_mask, normals, AT_REST};
    let emps = emps_x();
    for seed in env_seeds()
        .into_iter()
        .filter(|s| (600_001..700_000).contains(s))
    {
        let spec = long_run_spec(seed, &emps);
        let Hidden::Backlash { width_m } = spec.hidden else {
            println!("seed {seed}: not a play record");
            continue;
        };
        let rec = parse_csv(&spec.csv(), None).expect("rig record parses");
        let ctx = Context::new(&rec);
        let n = rec.len();
        let mut part = holdout_mask(n, 0);
        for (p, &r) in part.iter_mut().zip(&ctx.rest) {
            if r {
                *p = AT_REST;
            }
        }
        let ones = vec![1.0; n];
        let fit = |extra: &[(String, Vec<f64>)]| -> (f64, Vec<f64>) {
            let mut cols: Vec<&[f64]> = vec![&rec.a, &rec.v, &ctx.sgn, &ones];
            cols.extend(extra.iter().map(|c| c.1.as_slice()));
            let (tr, ho) = normals(&cols, &rec.f, &part, 1);
            let th = tr.solve();
            (ho.rss(&th), th)
        };
        let (rss0, th0) = fit(&[]);
        let rig = (
            spec.mass_kg,
            spec.drive_damping + spec.viscous,
            spec.coulomb,
        );
        // the contact's restitution walked (`RIG_E`, default 0: the plastic contact)
        let e: f64 = env_number("RIG_E", 0.0, 0.0..=1.0);
        let fitted = play_device_coefficients(&ctx, n, width_m, e);
        // the device walked once more, from the one fitted (None: that fit fails)
        let refit = hal_sim::diagnose::effects::play_device_fit(
            &ctx,
            &hal_sim::diagnose::effects::play_device(
                &rec.x, &rec.v, &rec.a, &ctx.sgn, ctx.dt, width_m, fitted.0, fitted.1, fitted.2, e,
            ),
        );
        println!(
            "seed {seed} ({}): width {:.4e} m, impacts' width {:?}; baseline M {:.1} Fv {:.1} Fc {:.1}; device fitted {:.1} {:.1} {:.2}, rig's {:.1} {:.1} {:.2} (Fv/M {:.1} s⁻¹)",
            spec.trajectory.name(),
            width_m,
            impact_travel(&ctx).map(|t| t / width_m),
            th0[0],
            th0[1],
            th0[2],
            fitted.0,
            fitted.1,
            fitted.2,
            rig.0,
            rig.1,
            rig.2,
            rig.1 / rig.0
        );
        for k in -10..=10 {
            let b = width_m * (1.0 + 0.02 * k as f64);
            let mut line = format!("  {:+3} %:", 2 * k);
            for dev in [None, Some(rig)].into_iter().chain(refit.map(Some)) {
                let cols = play_columns_with(&ctx, None, b, e, dev);
                let (rss, th) = fit(&cols);
                line.push_str(&format!(
                    "  held-out rss {:6.2} %, gain {:+.2}, impact {:6.1} kg;",
                    100.0 * rss / rss0,
                    th[4],
                    th[5..].iter().sum::<f64>()
                ));
            }
            println!("{line}");
        }
    }
}

/// Where a record's hidden effect acts (`RIG_SEEDS=S1,S2,… cargo test -p regen-tests --test
/// diagnose_rig rig_effect_at_rest -- --ignored --nocapture`; trajectories as in the long
/// run): the force the effect changes (the record with and without it: the same motion and
/// noise) split into the samples the diagnosis leaves out as at rest (`effects::at_rest`) and
/// those in motion, which are all a column can fit.
#[test]
#[ignore]
fn rig_effect_at_rest() {
    let emps = emps_x();
    for seed in env_seeds() {
        let kind = Hidden::KINDS[((seed - 1) / TUNING_STRIDE) as usize];
        let spec = long_run_spec(seed, &emps);
        let mut free = spec.clone();
        free.hidden = Hidden::None;
        let rec = parse_csv(&spec.csv(), None).expect("rig record parses");
        let rec0 = parse_csv(&free.csv(), None).expect("rig record parses");
        let ctx = hal_sim::diagnose::effects::Context::new(&rec);
        let (mut e_rest, mut n_rest, mut e_move, mut n_move) = (0.0, 0usize, 0.0, 0usize);
        for ((a, b), &r) in rec.f.iter().zip(&rec0.f).zip(&ctx.rest) {
            let d = (a - b) * (a - b);
            if r {
                e_rest += d;
                n_rest += 1;
            } else {
                e_move += d;
                n_move += 1;
            }
        }
        println!(
            "{kind} {} seed {seed}: effect {:.2} N rms; at rest ({n_rest} samples) {:.2} N rms, {:.0} % of its energy; in motion ({n_move}) {:.2} N rms; noise {:.2} N",
            spec.trajectory.name(),
            spec.effect_rms_n,
            (e_rest / n_rest.max(1) as f64).sqrt(),
            100.0 * e_rest / (e_rest + e_move).max(1e-300),
            (e_move / n_move.max(1) as f64).sqrt(),
            spec.noise_n
        );
    }
}

/// The long run's records as the rig draws them, without the diagnosis (`RIG_N=56 cargo test
/// -p regen-tests --test diagnose_rig_tools rig_specs -- --ignored --nocapture`; `RIG_KINDS` and
/// `RIG_SEEDS` as in the long run): family (and the one asked for), motion draw, hidden
/// effect, its rms over the samples in motion, the force noise, observable. Two rules'
/// outputs diffed list the records whose spec a change of the rule moved.
#[test]
#[ignore]
fn rig_specs() {
    let emps = emps_x();
    let n: u64 = env_number("RIG_N", 56, 0..=TUNING_STRIDE);
    let only = env_kinds();
    let seeds = env_seeds();
    for (ki, kind) in Hidden::KINDS.iter().enumerate() {
        if only.as_ref().is_some_and(|o| !o.iter().any(|k| k == kind)) {
            continue;
        }
        for j in 0..n {
            let seed = CLASSIC_TUNING_BASE + ki as u64 * TUNING_STRIDE + j;
            if !seeds.is_empty() && !seeds.contains(&seed) {
                continue;
            }
            let s = long_run_spec(seed, &emps);
            println!(
                "{kind:>20} seed {seed}: {} (asked for {}, draw {}) {:?} rms {:.2} N, noise {:.2} N, observable {}",
                s.trajectory.name(),
                s.requested,
                s.motion_draw,
                s.hidden,
                s.effect_rms_n,
                s.noise_n,
                s.observable
            );
        }
    }
}

/// The widened rig's tuning records (`RIG_WIDE=kind:j,kind:j …`, record j of the kind in the
/// tuning range) without the diagnosis's selection: sample rate, quantum, the samples the
/// diagnosis leaves out as at rest (`effects::at_rest`) against the rig's own rest set, and the
/// rest rule's threshold (the quantum and 3σ of the position noise) as a speed over its
/// window, beside the record's peak speed.
#[test]
#[ignore]
fn rig_wide_rest() {
    use hal_sim::bench_rig::RigSpec;
    let emps = emps_x();
    for item in env_items("RIG_WIDE").unwrap_or_default() {
        let parsed = item.split_once(':').and_then(|(kind, j)| {
            let k = Hidden::WIDE_KINDS.iter().position(|x| *x == kind)?;
            let j = j.parse::<u64>().ok().filter(|j| *j < TUNING_STRIDE)?;
            Some((kind, k, j))
        });
        let Some((kind, k, j)) = parsed else {
            panic!(
                "RIG_WIDE entry \"{item}\": kind:record expected, the kind one of {} and the record from 0 to {}",
                Hidden::WIDE_KINDS.join(", "),
                TUNING_STRIDE - 1
            );
        };
        let seed = WIDE_TUNING_BASE + TUNING_STRIDE * k as u64 + j;
        assert!(TUNING.contains(&seed));
        let spec = RigSpec::widened(seed, kind, Some((&emps, 1000.0)));
        let rec = parse_csv(&spec.csv(), None).expect("rig record parses");
        let rest = hal_sim::diagnose::effects::at_rest(&rec.x, &rec.v, rec.dt());
        let rig_rest = spec.rest();
        let thr = hal_sim::diagnose::effects::rest_threshold(&rec.x);
        let vmax = rec.v.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        println!(
            "{kind} {j} ({}, {} Hz, {} samples): quantum {:.2e} m, threshold {thr:.2e} m = {:.3e} m/s over the window; peak speed {vmax:.3e} m/s; at rest: diagnosis {}, rig {}",
            spec.trajectory.name(),
            spec.fs,
            spec.samples,
            spec.quantum_m,
            thr / (hal_sim::diagnose::effects::rest_half_window(rec.dt()) as f64 * rec.dt()),
            rest.iter().filter(|r| **r).count(),
            rig_rest.iter().filter(|r| **r).count()
        );
    }
}
