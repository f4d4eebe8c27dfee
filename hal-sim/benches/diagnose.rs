//! Time to diagnose a 1,000,000-sample record (target: under 2 s on one core). Prints the
//! figure; run with `cargo bench -p hal-sim --bench diagnose`.
use hal_sim::diagnose::synth::{self, SynthSpec};
use hal_sim::diagnose::{diagnose, parse_csv, Options};
use std::time::Instant;

fn main() {
    let n = 1_000_000;
    let spec = SynthSpec::random_hidden(42, n, 2);
    let csv = synth::generate_csv(&spec);
    let t0 = Instant::now();
    let rec = parse_csv(&csv, None).expect("parses");
    let t_read = t0.elapsed();
    let t1 = Instant::now();
    let d = diagnose(&rec, &Options::default());
    let t_diag = t1.elapsed();
    let found: Vec<&str> = d.findings.iter().map(|f| f.effect.as_str()).collect();
    let hidden: Vec<&str> = spec.hidden.iter().map(|(e, _)| e.kind.name()).collect();
    println!("record: {n} samples, hidden {hidden:?}, found {found:?}");
    println!(
        "parse + zero-phase derivatives: {:.3} s",
        t_read.as_secs_f64()
    );
    println!(
        "diagnose (fit, screening, refit, residual analysis): {:.3} s",
        t_diag.as_secs_f64()
    );
    println!(
        "total: {:.3} s (target < 2 s, one core)",
        (t_read + t_diag).as_secs_f64()
    );
}
