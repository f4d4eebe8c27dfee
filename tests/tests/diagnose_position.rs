//! The residual's spectrum over position (docs/diagnose.md, "The conclusion and the report"): a force
//! periodic in position hidden in a synthetic record and left in the residual must show as an
//! `unexplained` spatial peak at its wavelength; clean records must show no spatial peak.

mod common;

use hal_sim::diagnose::effects::{self, Effect, EffectKind};
use hal_sim::diagnose::synth::{Rng, SynthSpec};
use hal_sim::diagnose::{diagnose, report, synth, Options};

/// 12 s at 1 kHz as in diagnose_synth: the ±50 mm multi-sine sweeps the stroke many times.
const SAMPLES: usize = 12_000;

#[test]
fn hidden_position_periodic_force_shows_at_its_wavelength() {
    // 8 seeds: a position-periodic force (direction independent `cogging` for even seeds,
    // sign-changing `position_periodic_friction` for odd ones), 15-35 % of the 40 N Coulomb
    // force, wavelength 3-30 mm (or the 16 mm lead for the first two). The catalogue is
    // switched off (max_effects 0) so the periodic force stays in the final residual, which is
    // then the baseline residual: the spatial analysis alone must find it.
    let opt = Options {
        max_effects: 0,
        ..Options::default()
    };
    let mut found = 0;
    let seeds = 8u64;
    for seed in 0..seeds {
        let mut spec = SynthSpec::clean(7000 + seed, SAMPLES);
        let mut rng = Rng::new(seed + 77);
        let lambda = if seed < 2 {
            spec.lead
        } else {
            rng.range(0.003, 0.03)
        };
        let (kind, amp) = hide_ripple(&mut spec, &mut rng, seed, lambda);
        let rec = synth::generate(&spec);
        let d = diagnose(&rec, &opt);
        let ps = &d.position_spectrum;
        let top = ps.peaks.first();
        println!(
            "seed {seed}: hidden {} lambda {lambda:.5} m amp {amp:.2} N; {} bins of {:.2e} m over {:.4} m; top spatial peak {:?}",
            kind.name(),
            ps.bins,
            ps.bin_m,
            ps.span_m,
            top.map(|p| (p.wavelength_m, p.amplitude, p.ratio, p.matches.clone()))
        );
        let top = top.expect("a spatial peak");
        // Tolerance: the spectrum's bins are 1/span apart in spatial frequency and the hidden
        // frequency falls between two bins; the Hann main lobe's maximum is the nearest bin
        // (≤ 0.5/span off) or, with noise and the neighbouring lobe of the trend, the next one:
        // within one resolution step 1/span.
        let dnu = (1.0 / top.wavelength_m - 1.0 / lambda).abs();
        assert!(
            dnu <= 1.0 / ps.span_m,
            "seed {seed}: peak at {} m, hidden {lambda} m",
            top.wavelength_m
        );
        assert!(top.unexplained, "seed {seed}: peak not reported");
        // Amplitude: the hidden sinusoid has amplitude `amp` in each direction; the bin means
        // average it over a bin (sinc loss ≤ 1 − sinc(bin/λ), < 5 % at λ ≥ 8 bins) and the Hann
        // window's scalloping loses up to 15 % between bins: within 0.8-1.1 of `amp`.
        assert!(
            top.amplitude > 0.8 * amp && top.amplitude < 1.1 * amp,
            "seed {seed}: amplitude {} against {amp}",
            top.amplitude
        );
        // The interpolated wavelength (log-parabolic on the Hann lobe, bias a few % of a bin,
        // a bin being ≤ 0.55 of the spatial frequency here) is within 3 % of the hidden one:
        // that is the tolerance the lead / ball matching uses.
        assert!(
            (top.wavelength_m / lambda - 1.0).abs() < 0.03,
            "seed {seed}: interpolated wavelength {} against {lambda}",
            top.wavelength_m
        );
        if lambda == spec.lead {
            assert!(
                top.matches.contains("screw revolution"),
                "seed {seed}: lead not matched: {:?}",
                top.matches
            );
        }
        // A wavelength 6 % or more away from every lead / ball multiple must not be matched.
        let far = [spec.lead, spec.lead / 2.0, spec.lead / 3.0, spec.ball]
            .iter()
            .all(|l| (lambda / l - 1.0).abs() > 0.06);
        if far {
            assert!(
                top.matches.is_empty(),
                "seed {seed}: matched {:?}",
                top.matches
            );
        }
        // Reported as an `unexplained` finding with its wavelength, in the JSON too.
        let f = d
            .findings
            .iter()
            .find(|f| {
                f.effect == "unexplained" && f.parameters.iter().any(|(k, _)| k == "wavelength_m")
            })
            .expect("unexplained spatial finding");
        let wl = f
            .parameters
            .iter()
            .find(|(k, _)| k == "wavelength_m")
            .unwrap()
            .1;
        assert_eq!(wl, top.wavelength_m);
        let js: serde_json::Value = serde_json::from_str(&report::json(&d)).unwrap();
        assert!(js["findings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|f| f["effect"] == "unexplained"
                && f["parameters"]["wavelength_m"]
                    .as_f64()
                    .is_some_and(|w| (w / top.wavelength_m - 1.0).abs() < 1e-15)));
        found += 1;
    }
    println!("hidden position-periodic forces found at their wavelength: {found}/{seeds}");
}

#[test]
fn clean_records_show_no_spatial_peak() {
    // 10 clean seeds through the whole diagnosis: the final residual (noise, quantisation,
    // derivative error) has no structure in position, so no spatial peak may stand 30x above
    // the median (noise alone exceeds it with probability ~1e-9 per bin, see
    // `report::spatial_peaks`).
    let mut with_peak = 0;
    for seed in 0..10u64 {
        let rec = synth::generate(&SynthSpec::clean(5000 + seed, SAMPLES));
        let d = diagnose(&rec, &Options::default());
        let ps = &d.position_spectrum;
        let max_ratio = {
            let mut pw: Vec<f64> = ps.spectrum.iter().map(|s| s.1 * s.1).collect();
            let m = pw.len() / 2;
            let med = *pw.select_nth_unstable_by(m, |a, b| a.total_cmp(b)).1;
            ps.spectrum[2..]
                .iter()
                .map(|s| s.1 * s.1 / med)
                .fold(0.0f64, f64::max)
        };
        println!(
            "clean seed {seed}: {} bins of {:.2e} m, {} directions, peaks {}, highest power/median at k >= 3: {max_ratio:.1}",
            ps.bins,
            ps.bin_m,
            ps.directions,
            ps.peaks.len()
        );
        assert_eq!(ps.directions, 2);
        if !ps.peaks.is_empty() {
            with_peak += 1;
        }
    }
    println!("clean records with a spatial peak: {with_peak}/10");
    assert_eq!(with_peak, 0);
}

#[test]
fn short_wavelength_ripple_is_named_through_the_spatial_seeding() {
    // A ripple of many periods over the stroke (λ 1.5-2.5 mm over ≈ 0.07 m: 30-45 periods)
    // decorrelates from a wavelength a few % off, and the catalogue's log grid is ≈ 13 %
    // apart: whether the coarse grid catches it depends on where λ falls. The baseline
    // residual's spatial peaks seed the grid (as the 2.5 mm ripple on EMPS). Measured:
    // 12/12 named with the seeding, 10/12 without it (two cogging records at
    // 2.01 and 1.99 mm, not named at all), so this test fails without the seeding. 12 seeds,
    // cogging and position_periodic_friction alternately, 15-35 % of Coulomb.
    let seeds = 12u64;
    let mut named = 0;
    for seed in 0..seeds {
        let mut spec = SynthSpec::clean(9100 + seed, SAMPLES);
        let mut rng = Rng::new(seed + 991);
        let lambda = rng.range(0.0015, 0.0025);
        let (kind, amp) = hide_ripple(&mut spec, &mut rng, seed, lambda);
        let rec = synth::generate(&spec);
        let d = diagnose(&rec, &Options::default());
        let got = d.effects.iter().find(|e| e.kind == kind);
        println!(
            "seed {seed}: hidden {} lambda {lambda:.5} m amp {amp:.2} N -> {:?}, held-out {:.2} % -> {:.2} %",
            kind.name(),
            d.effects
                .iter()
                .map(|e| (e.kind.name(), e.param))
                .collect::<Vec<_>>(),
            100.0 * d.baseline_holdout_rel_error,
            100.0 * d.final_holdout_rel_error
        );
        // Tolerance 1 %: over ≈ 35 periods a 1 % wavelength error drifts the phase by a third
        // of a period, which the fit would not accept as the best value; the refinement steps
        // are 0.3 % (±3 % in 20 steps).
        if let Some(e) = got {
            if (e.param / lambda - 1.0).abs() < 0.01 {
                named += 1;
            }
        }
    }
    println!("short-wavelength ripples named at their wavelength: {named}/{seeds}");
    // Every record: the ripple carries ≥ 6 N against 0.5 N noise.
    assert_eq!(named, seeds);
}

/// Hide a position ripple of wavelength `lambda` in `spec`: 15-35 % of the Coulomb force at a
/// random phase, `cogging` on even seeds and `position_periodic_friction` on odd ones.
/// Returns the kind and the amplitude, N.
fn hide_ripple(spec: &mut SynthSpec, rng: &mut Rng, seed: u64, lambda: f64) -> (EffectKind, f64) {
    let amp = rng.range(0.15, 0.35) * spec.coulomb;
    let ph = rng.range(0.0, std::f64::consts::TAU);
    let kind = if seed.is_multiple_of(2) {
        effects::COGGING
    } else {
        effects::POSITION_PERIODIC_FRICTION
    };
    spec.hidden.push((
        Effect {
            kind,
            param: lambda,
            param2: 0.0,
        },
        vec![amp * ph.cos(), amp * ph.sin()],
    ));
    (kind, amp)
}

/// A record of an imposed motion whose position carries a small ripple locked to position
/// (δ·sin(2πx/λ), as a screw's or an encoder's error puts into a position-controlled axis),
/// the force the device's inertia, viscous and Coulomb friction on the true motion (closed
/// form: x = s + δ·sin(ks), v = ṡ(1 + δk·cos ks), a = s̈(1 + δk·cos ks) − δk²ṡ²·sin ks), and
/// optionally a cogging force `cog_n`·sin(2πx/λ). Returns the CSV (x written unquantised,
/// 0.3 N force noise).
fn motion_ripple_record(seed: u64, delta_m: f64, lambda: f64, cog_n: f64) -> String {
    use std::f64::consts::TAU;
    use std::fmt::Write;
    let (m, fv, fc) = (50.0, 300.0, 25.0);
    let k = TAU / lambda;
    let mut rng = Rng::new(seed);
    let mut out = String::from("# motion with a position-locked ripple\nt_s,x_m,f_N\n");
    for i in 0..SAMPLES {
        let t = i as f64 * 1e-3;
        // two sines: 0.4 Hz ±40 mm and 1.1 Hz ±15 mm (peak speed 0.2 m/s)
        let (s, sd, sdd) = regen_tests::two_sine(t);
        let (sn, cs) = (k * s).sin_cos();
        let x = s + delta_m * sn;
        let v = sd * (1.0 + delta_m * k * cs);
        let a = sdd * (1.0 + delta_m * k * cs) - delta_m * k * k * sd * sd * sn;
        let f = m * a + fv * v + fc * v.signum() + cog_n * (k * x).sin() + 0.3 * rng.normal();
        let _ = writeln!(out, "{t:.6},{x:.12e},{f:.6}");
    }
    out
}

/// The inertial force of a motion ripple that lies above the derivative filter's band
/// (λ = 1 mm at up to 0.2 m/s: up to 200 Hz against the 50 Hz cutoff) is a force locked to
/// position in the residual, since the derived acceleration cannot follow it; it is not a
/// catalogue effect and is not named `cogging` (effects::ripple_in_band: where its time
/// frequency lies within half the cutoff the derived acceleration measures the motion and the
/// residual carries no ripple). A cogging force of about the same size at the same wavelength
/// on the same motion is named, its wavelength within 1 %.
#[test]
fn motion_ripple_above_the_acceleration_band_is_not_named() {
    let lambda = 1.0e-3;
    for seed in 0..3u64 {
        // δ = 0.1 µm: M·δ·k²·v² ≈ 1.2 N at the rms speed 0.08 m/s, 4 N at the peak speed
        let art = hal_sim::diagnose::parse_csv(
            &motion_ripple_record(seed + 40, 1.0e-7, lambda, 0.0),
            None,
        )
        .expect("record parses");
        let d = diagnose(&art, &Options::default());
        let names: Vec<(&str, f64)> = d.effects.iter().map(|e| (e.kind.name(), e.param)).collect();
        println!(
            "seed {seed}: motion ripple -> {names:?}, held-out {:.2} % -> {:.2} %; {:?}",
            100.0 * d.baseline_holdout_rel_error,
            100.0 * d.final_holdout_rel_error,
            d.verdicts
        );
        assert!(
            !common::names_a_periodic_effect(&d),
            "seed {seed}: the motion's ripple named {names:?}"
        );
        let cog =
            hal_sim::diagnose::parse_csv(&motion_ripple_record(seed + 40, 0.0, lambda, 1.0), None)
                .expect("record parses");
        let d = diagnose(&cog, &Options::default());
        let names: Vec<(&str, f64)> = d.effects.iter().map(|e| (e.kind.name(), e.param)).collect();
        println!(
            "seed {seed}: 1 N cogging -> {names:?}; {:?}",
            d.findings.iter().map(|f| &f.note).collect::<Vec<_>>()
        );
        assert!(
            common::names_cogging_at(&d, lambda),
            "seed {seed}: the cogging not named: {names:?}"
        );
    }
}

/// `effects::in_band_ripple` and `RippleInBand::locked_to_position` on a ripple whose
/// amplitude is not the same at every speed: 1.5 N·sin(2πx/λ) where |v|/λ lies inside half
/// the derivative filter's cutoff, 0.6 N above it (a force that is not locked to position, as
/// a time ripple seen at λ = v/f or a partly measured inertial ripple), against the same
/// ripple at 1.5 N everywhere. The first is rejected on its difference (0.6 of the ripple
/// expected, far above the third allowed), the second kept (difference within the noise).
#[test]
fn ripple_differing_across_the_band_is_not_locked_to_position() {
    use hal_sim::diagnose::effects::{build_columns, in_band_ripple, ripple_in_band, Context};
    let lambda = 4.0e-3;
    for (above_n, want) in [(0.6, false), (1.5, true)] {
        let mut rec =
            hal_sim::diagnose::parse_csv(&motion_ripple_record(77, 0.0, lambda, 0.0), None)
                .expect("record parses");
        let fc = rec.meta[hal_sim::diagnose::record::DERIVATIVE_CUTOFF_KEY];
        let k = std::f64::consts::TAU / lambda;
        for i in 0..rec.f.len() {
            let amp = if rec.v[i].abs() <= 0.5 * fc * lambda {
                1.5
            } else {
                above_n
            };
            rec.f[i] += amp * (k * rec.x[i]).sin();
        }
        let ctx = Context::new(&rec);
        let e = Effect {
            kind: effects::COGGING,
            param: lambda,
            param2: 0.0,
        };
        let cols = build_columns(&ctx, std::slice::from_ref(&e));
        let mask = ripple_in_band(&ctx, lambda).expect("derived acceleration");
        let inside = mask.iter().filter(|b| **b).count();
        let r = in_band_ripple(&ctx, &cols, (cols.len() - 2, cols.len()), &mask);
        println!(
            "above {above_n} N: {inside}/{} samples in band; {r:?} -> locked {}",
            mask.len(),
            r.locked_to_position(3.0)
        );
        // the fitted amplitudes within 10 % of the hidden ones (0.3 N noise over thousands
        // of samples: the standard error is ≈ 0.01 N)
        assert!((r.amp_in / 1.5 - 1.0).abs() < 0.1, "{r:?}");
        assert!((r.amp_above / above_n - 1.0).abs() < 0.1, "{r:?}");
        assert_eq!(r.locked_to_position(3.0), want, "{r:?}");
    }
}
