//! The scenario reader against 10⁵ mutated scenario files (seeded, reproducible): it never
//! panics, and each input gives either a scenario that builds and steps or one clear error
//! (one line, naming where: a key, a line, or a table).

use hal_sim::Scenario;

const BASES: [&str; 3] = [
    "name = \"t\"\nduration_s = 2.0\nsettle_s = 1.0\n[law]\nkind = \"resistor\"\nr_load_ohm = 306.0\n[law.set]\ntrk_period_s = 8.0\n[drive]\nkind = \"structure\"\n[drive.structure]\nmass_kg = 400.0\nstiffness_n_per_m = 3947.84\ndamping_n_s_per_m = 0.0\n[drive.excitation]\nkind = \"sine\"\na0_m_s2 = 1.0\nfreq_hz = 0.5\n[bus]\ncapacitance_f = 1e-3\ninitial_v = 320.0\nsource_v = 320.0\n[record]\nchannels = [\"t\", \"x\", \"force\"]\nevery = 40\n",
    "duration_s = 1.0\n[machine]\nr_ohm = 2.41\nl_h = 6e-3\nke_v_s_per_rad = 0.94\npole_pairs = 5\n[screw]\nlead_m_per_rad = 2.5e-3\nefficiency = 0.9\ncoulomb_n = 40.0\np3 = 0.1\n[drive]\nkind = \"imposed\"\n[drive.motion]\nkind = \"triangle\"\namplitude_m = 0.05\nfreq_hz = 0.25\n[firmware]\ncurrent_bw_hz = 1000.0\ni_max_a = 5.0\n[losses]\nk_sw_s = 5e-8\n[sensors]\ncurrent_noise_a = 0.01\n[inverter]\ndead_time_s = 1e-6\n",
    "duration_s = 1.0\n[drive]\nkind = \"structure\"\n[drive.excitation]\nkind = \"kanai_tajimi\"\ns0 = 0.01\nomega_g = 15.0\nzeta_g = 0.6\nseed = 3\n[law]\nkind = \"resistor\"\n",
];

const POOL: [&str; 24] = [
    "nan",
    "inf",
    "-inf",
    "-400.0",
    "0",
    "0.0",
    "-0.0",
    "1e308",
    "1e-320",
    "1e-50",
    "1e99",
    "-1",
    "3",
    "0.5",
    "1000.0",
    "\"x\"",
    "true",
    "[]",
    "[1.0, 2.0]",
    "{}",
    "18446744073709551615",
    "-9223372036854775808",
    "1e5",
    "2.5e-3",
];

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

fn mutate(r: &mut Rng, base: &str) -> String {
    let mut lines: Vec<String> = base.lines().map(str::to_string).collect();
    for _ in 0..1 + r.below(3) {
        let k = r.below(lines.len());
        match r.below(7) {
            // A value replaced.
            0..=2 => {
                if let Some((key, _)) = lines[k].split_once('=') {
                    lines[k] = format!("{key}= {}", POOL[r.below(POOL.len())]);
                }
            }
            // A number scaled or negated.
            3 => {
                if let Some((key, v)) = lines[k].split_once('=') {
                    if let Ok(x) = v.trim().parse::<f64>() {
                        let f = [-1.0, 1e3, 1e-3, 1e12, 0.0][r.below(5)];
                        lines[k] = format!("{key}= {:?}", x * f);
                    }
                }
            }
            4 => {
                lines.remove(k);
            }
            5 => {
                let l = lines[k].clone();
                lines.insert(k, l);
            }
            // Noise characters somewhere in the line.
            _ => {
                let b = lines[k].as_bytes();
                let at = r.below(b.len() + 1);
                let c = [b'[', b']', b'"', b'=', b'#', b'.', b'x', b' ', b'\\', b'1'][r.below(10)];
                let mut v = b[..at].to_vec();
                v.push(c);
                v.extend_from_slice(&b[at..]);
                lines[k] = String::from_utf8_lossy(&v).into_owned();
            }
        }
        if lines.is_empty() {
            break;
        }
    }
    lines.join("\n")
}

#[test]
fn scenario_reader_survives_1e5_mutations() {
    let mut r = Rng(0x9e37_79b9_7f4a_7c15);
    let (mut ok, mut refused, mut built) = (0usize, 0usize, 0usize);
    for k in 0..100_000 {
        let text = mutate(&mut r, BASES[k % BASES.len()]);
        match std::panic::catch_unwind(|| Scenario::from_toml(&text)) {
            Err(_) => panic!("panic on input {k}:\n{text}"),
            Ok(Err(e)) => {
                refused += 1;
                assert!(
                    !e.is_empty() && !e.contains('\n'),
                    "input {k}: `{e}`\n{text}"
                );
                assert!(
                    e.contains(" = ") || e.contains("line ") || e.contains(": "),
                    "input {k}: no key or line in `{e}`"
                );
            }
            Ok(Ok(sc)) => {
                ok += 1;
                // Every 50th accepted scenario is built and stepped 100 PWM periods.
                if ok % 50 == 0 {
                    let res = std::panic::catch_unwind(|| {
                        sc.build().map(|mut s| {
                            for _ in 0..100 {
                                s.step();
                            }
                        })
                    });
                    match res {
                        Err(_) => panic!("panic building/stepping input {k}:\n{text}"),
                        Ok(Err(e)) => assert!(!e.contains('\n'), "{e}"),
                        Ok(Ok(())) => built += 1,
                    }
                }
            }
        }
    }
    eprintln!("accepted {ok}, refused {refused}, built and stepped {built}");
    assert!(
        ok > 1000 && refused > 1000,
        "{ok} accepted / {refused} refused: the mutations test both sides"
    );
}
