//! Integration tests live in tests/tests/. This library holds what several of them share and
//! what shares nothing with the code under test: the seeded draws of the fault-injection and
//! stage suites.

/// splitmix64: a seeded stream of uniforms.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [lo, hi).
    pub fn uni(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Log-uniform in [lo, hi).
    pub fn log_uni(&mut self, lo: f64, hi: f64) -> f64 {
        self.uni(lo.ln(), hi.ln()).exp()
    }
    /// Uniform in 0 … n−1.
    pub fn pick(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
    /// ±1 with equal odds.
    pub fn sign(&mut self) -> f64 {
        if self.next_u64() & 1 == 0 {
            1.0
        } else {
            -1.0
        }
    }
}

/// The imposed two-sine motion of the closed-form diagnosis records (0.4 Hz ±40 mm and
/// 1.1 Hz ±15 mm, phases 0 and 1 rad; peak speed ≈ 0.2 m/s): position, velocity and
/// acceleration at `t` seconds, in closed form.
pub fn two_sine(t: f64) -> (f64, f64, f64) {
    use std::f64::consts::TAU;
    let (mut x, mut v, mut a) = (0.0, 0.0, 0.0);
    for (amp, f, ph) in [(0.040, 0.4, 0.0), (0.015, 1.1, 1.0)] {
        let w = TAU * f;
        let (s, c) = (w * t + ph).sin_cos();
        x += amp * s;
        v += amp * w * c;
        a -= amp * w * w * s;
    }
    (x, v, a)
}

/// The repository's copy of an EMPS benchmark record (`data/emps/NAME`, see its README). A
/// missing file fails the calling test with its path: the data is part of the repository, so
/// its absence is an error, never a reason to skip or to test something else.
pub fn emps_file(name: &str) -> std::path::PathBuf {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../data/emps")
        .join(name);
    assert!(
        p.is_file(),
        "EMPS record missing: {} (the repository's data/emps/, see its README)",
        p.display()
    );
    p
}

/// Prints a distribution (n, min, p10, median, p90, max) under `name`; returns (min, max).
pub fn stats(name: &str, v: &[f64]) -> (f64, f64) {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let q = |p: f64| s[((s.len() - 1) as f64 * p).round() as usize];
    println!(
        "{name}: n={} min {:.4} p10 {:.4} median {:.4} p90 {:.4} max {:.4}",
        s.len(),
        s[0],
        q(0.1),
        q(0.5),
        q(0.9),
        s[s.len() - 1]
    );
    (s[0], s[s.len() - 1])
}
