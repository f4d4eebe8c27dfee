//! Never a panic: the reader and the whole pipeline (read, diagnose, cross-check, text, JSON
//! and model reports) on seeded random inputs — nonsense text, CSV that parses but makes no
//! physical sense (short, constant, one-way, all at rest, huge or tiny values), absurd options
//! and cutoffs. Every input must give a record or an error, and every record a diagnosis
//! (possibly with a verdict instead of findings). `FUZZ_N` sets the count (the long run:
//! `FUZZ_N=100000 cargo test -p regen-tests --test diagnose_fuzz -- --nocapture`).

use hal_sim::bench_rig::RigRng;
use hal_sim::diagnose::{cross_check, diagnose, parse_csv, report, Options};

fn num(r: &mut RigRng) -> String {
    match r.pick(12) {
        0 => "nan".into(),
        1 => "inf".into(),
        2 => "-1e308".into(),
        3 => "".into(),
        4 => "abc".into(),
        5 => format!("{}", r.uni(-1e8, 1e8)),
        6 => "0".into(),
        _ => format!("{:.6}", r.uni(-1.0, 1.0)),
    }
}

/// A random text: nonsense, a broken CSV, or a CSV of some physically odd kind.
fn input(r: &mut RigRng) -> String {
    let mut s = String::new();
    match r.pick(8) {
        0 => {
            // bytes of random printable text and separators
            for _ in 0..r.pick(200) {
                s.push([',', '\n', '#', '=', '1', '.', 'e', '-', 'x', ' '][r.pick(10)]);
            }
        }
        1 => {
            // header and random fields
            s.push_str(
                [
                    "t_s,x_m,f_N\n",
                    "t_s,x_m\n",
                    "x_m,f_N,t_s,v_m_s\n",
                    "t_s,x_m,f_N,i_q_A\n",
                ][r.pick(4)],
            );
            for _ in 0..r.pick(40) {
                let k = 1 + r.pick(5);
                let f: Vec<String> = (0..k).map(|_| num(r)).collect();
                s.push_str(&f.join(","));
                s.push('\n');
            }
        }
        k => {
            // a well-formed record of an odd kind
            let n = match r.pick(4) {
                0 => 3 + r.pick(10),
                1 => 10 + r.pick(300),
                2 => 300 + r.pick(1500),
                _ => 3 + r.pick(60),
            };
            let dt = [1e-3, 1e-7, 0.5, 1e-4][r.pick(4)];
            let kind = k;
            if r.pick(3) == 0 {
                s.push_str(&format!("# lead_m_per_rev = {}\n", num(r)));
            }
            s.push_str("t_s,x_m,f_N\n");
            let amp = [1e-9, 1e-3, 0.05, 5.0][r.pick(4)];
            let fq = r.uni(0.01, 50.0);
            for i in 0..n {
                let t = i as f64 * dt;
                let x = match kind {
                    2 => 0.01,    // constant position
                    3 => amp * t, // one-way motion
                    4 => {
                        if i < n / 2 {
                            0.0
                        } else {
                            1e-6
                        }
                    } // one step, otherwise at rest
                    5 => amp * (std::f64::consts::TAU * fq * t).sin(),
                    6 => (amp * (std::f64::consts::TAU * fq * t).sin() / 1e-5).round() * 1e-5,
                    _ => amp * r.uni(-1.0, 1.0), // noise
                };
                let f = match r.pick(3) {
                    0 => 0.0,
                    1 => r.uni(-1e6, 1e6),
                    _ => 100.0 * x + r.gauss(),
                };
                s.push_str(&format!("{t},{x:e},{f}\n"));
            }
        }
    }
    s
}

#[test]
fn reader_and_pipeline_never_panic() {
    let n: usize = std::env::var("FUZZ_N")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(3000);
    let mut r = RigRng::new(0xF022);
    let (mut parsed, mut diagnosed, mut verdict_only) = (0, 0, 0);
    let mut prev: Option<hal_sim::diagnose::Record> = None;
    for case in 0..n {
        let text = input(&mut r);
        let cutoff = match r.pick(6) {
            0 => Some(-5.0),
            1 => Some(f64::NAN),
            2 => Some(1e9),
            3 => Some(r.uni(0.1, 100.0)),
            _ => None,
        };
        let opt = Options {
            min_holdout_gain: if r.pick(10) == 0 {
                r.uni(-2.0, 2.0)
            } else {
                0.02
            },
            max_effects: if r.pick(10) == 0 { r.pick(40) } else { 6 },
            screen_samples: if r.pick(10) == 0 {
                r.pick(1000)
            } else {
                10_000
            },
            ..Options::default()
        };
        let res = std::panic::catch_unwind(|| {
            let Ok(rec) = parse_csv(&text, cutoff) else {
                return (false, false, false);
            };
            let d = diagnose(&rec, &opt);
            let _ = report::text(&rec, &d);
            let _ = report::json(&d);
            let _ = report::model_toml(&rec, &d);
            (
                true,
                !d.verdicts.is_empty() && d.findings.is_empty(),
                d.residual.len() == rec.len(),
            )
        });
        match res {
            Ok((p, v, dd)) => {
                parsed += p as usize;
                verdict_only += v as usize;
                diagnosed += dd as usize;
            }
            Err(_) => {
                panic!("case {case} panicked; input:\n{text}\ncutoff {cutoff:?}, options {opt:?}")
            }
        }
        if case % 97 == 0 {
            if let Ok(rec) = parse_csv(&text, None) {
                if let Some(p) = &prev {
                    let mut d = diagnose(p, &Options::default());
                    cross_check(&mut d, &rec);
                    let _ = report::text(p, &d);
                }
                prev = Some(rec);
            }
        }
    }
    println!("{n} inputs: {parsed} parsed, {diagnosed} diagnosed to the end, {verdict_only} with a verdict and no finding; no panic");
}

/// The first rows of the EMPS estimation record (short, partly at rest, one-way): a
/// diagnosis or a verdict, never a panic.
#[test]
fn emps_prefixes_never_panic() {
    let p = regen_tests::emps_file("emps_estimation.csv");
    let text = std::fs::read_to_string(&p)
        .unwrap_or_else(|e| panic!("EMPS record {} unreadable: {e}", p.display()));
    let lines: Vec<&str> = text.lines().collect();
    let mut n_ok = 0;
    for k in (4..700).step_by(13) {
        let t = lines[..k.min(lines.len())].join("\n");
        if let Ok(rec) = parse_csv(&t, None) {
            let d = diagnose(&rec, &Options::default());
            let _ = report::text(&rec, &d);
            n_ok += 1;
        }
    }
    println!("{n_ok} EMPS prefixes diagnosed or given a verdict");
}
