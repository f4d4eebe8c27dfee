//! The selection's test of the drag growing faster than linearly with speed (outside the catalogue).

use super::*;

/// A closed-form record of a device with a drag growing with the square of the speed
/// (outside the catalogue): a three-tone motion of random frequencies, amplitudes and
/// phases with its exact velocity and acceleration, the force M·a + Fv·v + Fc·sgn v +
/// c2·v·|v| and white noise of 0.3 N. Its own generator (xorshift, a sum of 12 uniforms for
/// the noise). Returns the record and the drag's force at the record's peak speed.
fn drag_record(seed: u64, with_drag: bool) -> (Record, f64) {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut uniform = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let tones: Vec<(f64, f64, f64)> = (0..3)
        .map(|k| {
            let f = (0.2 + 0.3 * uniform()) * (1.0 + 1.3 * k as f64);
            let amp = (0.004 + 0.01 * uniform()) / (1.0 + k as f64);
            (f, amp, std::f64::consts::TAU * uniform())
        })
        .collect();
    let (m, fv, fc) = (
        20.0 + 40.0 * uniform(),
        100.0 + 300.0 * uniform(),
        10.0 + 20.0 * uniform(),
    );
    let (fs, n) = (1000.0, 12_000);
    let motion = |t: f64| crate::tests::tones_motion(&tones, t);
    let vmax = (0..n)
        .map(|i| motion(i as f64 / fs).1.abs())
        .fold(0.0, f64::max);
    // the drag's force at the peak speed: 30 … 80 N
    let at_peak = if with_drag {
        30.0 + 50.0 * uniform()
    } else {
        0.0
    };
    let c2 = at_peak / (vmax * vmax);
    let mut rec = Record::default();
    for i in 0..n {
        let t = i as f64 / fs;
        let (x, v, a) = motion(t);
        let noise = (0..12).map(|_| uniform()).sum::<f64>() - 6.0;
        rec.t.push(t);
        rec.x.push(x);
        rec.v.push(v);
        rec.a.push(a);
        rec.f
            .push(m * a + fv * v + fc * v.signum() + c2 * v * v.abs() + 0.3 * noise);
    }
    (rec, at_peak)
}

/// The force at the peak speed and at half of it the diagnosis gives a force of the speed
/// it carries (`SPEED_COLUMNS`), if it carries one.
fn speed_force(d: &Diagnosis) -> Option<(f64, f64)> {
    let param = |name: &str| {
        d.findings
            .iter()
            .filter(|f| f.effect == "unexplained")
            .flat_map(|f| &f.parameters)
            .find(|p| p.0 == name)
            .map(|p| p.1)
    };
    Some((
        param("force_at_peak_speed_N")?,
        param("force_at_half_peak_speed_N")?,
    ))
}

/// Over eight records with a drag growing with the square of the speed, the diagnosis
/// names no catalogue effect and carries a force of the speed whose value at the peak
/// speed is the drag's; over the same eight motions and devices without the drag it
/// carries none and names nothing. Breaks: the selection not run again names a friction
/// curve of the speed on the drag records; the test firing on every record gives the
/// drag-free ones a speed force; the force at the peak speed 5 % low; the force at half
/// of it with each power of the share one lower; each fails.
#[test]
fn a_drag_of_the_speed_squared_is_unexplained_and_no_catalogue_name() {
    let (mut errs, mut errs_half) = (Vec::new(), Vec::new());
    for seed in 1..=8u64 {
        let (rec, at_peak) = drag_record(seed, true);
        let d = diagnose(&rec, &Options::default());
        assert!(
            d.catalogue_names().is_empty(),
            "record {seed}: drag named {:?}",
            d.catalogue_names()
        );
        let (peak, half) =
            speed_force(&d).unwrap_or_else(|| panic!("record {seed}: no speed force"));
        errs.push(peak / at_peak - 1.0);
        // the drag at half the peak speed is a quarter of its peak force
        errs_half.push(half / (0.25 * at_peak) - 1.0);
        let (rec0, _) = drag_record(seed, false);
        let d0 = diagnose(&rec0, &Options::default());
        assert!(
            d0.catalogue_names().is_empty() && speed_force(&d0).is_none(),
            "record {seed} without drag: {:?}, speed force {:?}",
            d0.catalogue_names(),
            speed_force(&d0)
        );
    }
    let mean = |e: &[f64]| e.iter().sum::<f64>() / e.len() as f64;
    let spread = |e: &[f64]| {
        let m = mean(e);
        e.iter().fold(0.0f64, |w, x| w.max((x - m).abs()))
    };
    // Measured: at the peak speed every error +0.4 … +2.5 % (mean +1.2 %, each within
    // 1.3 % of the mean), at half of it +0.7 … +4.5 % (mean +2.2 %, within 2.3 %). The
    // means are bounded at about twice their measured value and the spread at 3× its own,
    // so a 5 % error in the reported force fails the first mean, and a wrong power of the
    // speed (a factor 2 at half the peak speed) the second.
    for (at, e, mean_max, spread_max) in [
        ("the peak speed", &errs, 0.025, 0.04),
        ("half the peak speed", &errs_half, 0.045, 0.07),
    ] {
        println!(
            "speed force at {at}, relative error per record: {e:.4?}, mean {:+.4}, spread {:.4}",
            mean(e),
            spread(e)
        );
        assert!(mean(e).abs() < mean_max, "mean at {at} {:+.4}", mean(e));
        assert!(spread(e) < spread_max, "spread at {at} {:.4}", spread(e));
    }
}
