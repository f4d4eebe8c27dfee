//! `cargo xtask figures [--quick]`: run the measurements behind the project's figures (the
//! emulated Cortex-M4 check, the board image's size, the benches, the diagnosis's held-out
//! long run and its real record, the console tests and fuzz)
//! and write them as one table to `docs/figures.md`, so that no figure is typed by hand.
//!
//! Each measurement is a command and the markers of the output lines that carry its figures;
//! the table quotes those lines as printed. A command that fails or prints no such line gives
//! a row saying so (with its exit status and last line), and the others still run: the table
//! is always written. The commands run one after another (the machine is shared; the benches
//! compare figures measured in the same run). Without `--quick` it takes ≈ 30 min on a
//! loaded 2-core machine, most of it the release builds (fat LTO), the board image and the
//! diagnosis's held-out long run; `--quick` skips the board image, QEMU, the benches and the
//! long run (≈ 2 min) and keeps their rows as the previous run wrote them; `--only TEXT`
//! measures the rows whose name contains TEXT (`--only "model diagnosis"`: the diagnosis's
//! time, long run and real record) and keeps the others.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// One measurement: what it is, the target, the command (program, arguments, directory
/// relative to the workspace root), and the markers of the lines to quote.
struct Measure {
    what: &'static str,
    target: &'static str,
    program: &'static str,
    args: &'static [&'static str],
    dir: &'static str,
    markers: &'static [&'static str],
    slow: bool,
}

const MEASURES: &[Measure] = &[
    Measure {
        what: "board image flash and static RAM",
        target: "flash ≤ 96 KiB, RAM ≤ 16 KiB besides the capture buffer",
        program: "cargo",
        args: &["build", "--release"],
        dir: "firmware/board",
        markers: &[],
        slow: true,
    },
    Measure {
        what: "current-loop step on the emulated Cortex-M4; board image size",
        target: "≤ 400 instructions per step; bit identity with the host",
        program: "bash",
        args: &["firmware/m4check/run.sh"],
        dir: ".",
        markers: &[
            "instructions per current-loop step",
            "bit identity",
            "board image:",
        ],
        slow: true,
    },
    Measure {
        what: "closed-loop simulation speed",
        target: "(a) the board's realism slows the loop ≤ 20 %; (b) plant ≤ firmware step per period; (c) ≥ 1,000× real time (one core, 20 kHz, quiet machine)",
        program: "cargo",
        args: &["bench", "-p", "hal-sim", "--bench", "rtf"],
        dir: ".",
        markers: &[
            "  total ",
            "  firmware step",
            "  plant ",
            "  board realism",
            "  ratios:",
            "analytic TMD sweep",
        ],
        slow: true,
    },
    Measure {
        what: "model diagnosis of 10⁶ samples",
        target: "< 1 s (one core)",
        program: "cargo",
        args: &["bench", "-p", "hal-sim", "--bench", "diagnose"],
        dir: ".",
        markers: &["total:", "record:"],
        slow: true,
    },
    Measure {
        what: "model diagnosis on the independent bench rig, held-out records (the long run)",
        target: "≥ 95 % exactly right; ≤ 2 % of effect-free records named; ≥ 90 % of out-of-catalogue effects unexplained (504 held-out records a rig)",
        program: "cargo",
        args: &[
            "test",
            "--release",
            "-p",
            "regen-tests",
            "--test",
            "diagnose_rig",
            "rig_long_run",
            "--",
            "--ignored",
            "--nocapture",
        ],
        dir: ".",
        markers: &[" exactly right (", "targets missed"],
        slow: true,
    },
    Measure {
        what: "model diagnosis of the EMPS ballscrew record (real data)",
        target: "held-out error ≤ 2.9 %, every finding physical",
        program: "cargo",
        args: &[
            "test",
            "-p",
            "regen-tests",
            "--test",
            "diagnose_emps",
            "--",
            "--nocapture",
        ],
        dir: ".",
        markers: &["EMPS estimation:"],
        slow: false,
    },
    Measure {
        what: "console fuzz",
        target: "≥ 10⁶ inputs, no panic, refusals change nothing",
        program: "cargo",
        args: &[
            "run",
            "--release",
            "-p",
            "regen-fw",
            "--example",
            "console_fuzz",
        ],
        dir: ".",
        markers: &["console_fuzz:"],
        slow: false,
    },
    Measure {
        what: "console over the pty: harvested power against the harmonic balance",
        target: "within 1 % at 100 Ω, 306 Ω, 1 kΩ",
        program: "cargo",
        args: &[
            "test",
            "-p",
            "hal-sim",
            "--test",
            "console_pty",
            "--",
            "--nocapture",
        ],
        dir: ".",
        markers: &["R_L ", "stopped:"],
        slow: false,
    },
    Measure {
        what: "flux braking: 72 V TMD (0.5 m/s², 100 Ω), sink and brake lost",
        target: "bus held below derate_start_v with it; bus_over_voltage without",
        program: "cargo",
        args: &[
            "test",
            "-p",
            "regen-tests",
            "--test",
            "flux",
            "--",
            "--nocapture",
        ],
        dir: ".",
        markers: &["flux braking on:", "flux braking off:"],
        slow: false,
    },
    Measure {
        what: "reference TMD in the 72 V class: excitation that fits, optimum, clip",
        target: "optimum = the harmonic balance's; no clip below the closed form's clip speed",
        program: "cargo",
        args: &[
            "test",
            "-p",
            "regen-tests",
            "--test",
            "stage",
            "board_72v_tmd_sweep",
            "--",
            "--nocapture",
        ],
        dir: ".",
        markers: &["72v TMD:"],
        slow: false,
    },
];

/// The lines of `out` that contain one of `markers` (all of `out`'s last line if none given).
fn quoted(out: &str, markers: &[&str]) -> Vec<String> {
    out.lines()
        .filter(|l| markers.iter().any(|m| l.contains(m)))
        .map(|l| l.trim().replace('|', "\\|"))
        .collect()
}

/// The board image's flash (.vector_table + .text + .rodata + .data) and static RAM
/// (.data + .bss + .uninit), from `llvm-size -A`, as `run.sh` sums them.
fn board_size(root: &Path) -> Result<String, String> {
    let img = root.join("firmware/board/target/thumbv7em-none-eabihf/release/regen-board");
    let o = Command::new("llvm-size")
        .arg("-A")
        .arg(&img)
        .output()
        .map_err(|e| format!("llvm-size: {e}"))?;
    if !o.status.success() {
        return Err(format!("llvm-size {}: {}", img.display(), o.status));
    }
    let (mut flash, mut ram) = (0u64, 0u64);
    for l in String::from_utf8_lossy(&o.stdout).lines() {
        let mut w = l.split_whitespace();
        let (Some(name), Some(size)) = (w.next(), w.next().and_then(|s| s.parse::<u64>().ok()))
        else {
            continue;
        };
        match name {
            ".vector_table" | ".text" | ".rodata" => flash += size,
            ".data" => {
                flash += size;
                ram += size
            }
            ".bss" | ".uninit" => ram += size,
            _ => {}
        }
    }
    // The capture's ring and its state (`drive::CAP`), outside the RAM budget.
    let cap = Command::new("llvm-nm")
        .args(["-S", "-C"])
        .arg(&img)
        .output()
        .ok()
        .and_then(|o| {
            String::from_utf8_lossy(&o.stdout).lines().find_map(|l| {
                let w: Vec<&str> = l.split_whitespace().collect();
                let hit = w
                    .get(3)
                    .is_some_and(|n| n.starts_with("regen_board::drive::CAP::"));
                hit.then(|| w.get(1).and_then(|h| u64::from_str_radix(h, 16).ok()))
                    .flatten()
            })
        })
        .unwrap_or(0);
    Ok(format!(
        "flash {flash} bytes ({:.1} KiB), static RAM {ram} bytes: the capture's {cap}, the rest {} ({:.1} KiB)",
        flash as f64 / 1024.0,
        ram - cap,
        (ram - cap) as f64 / 1024.0
    ))
}

/// `cd DIR && ` for a command run outside the workspace root.
fn cd(dir: &str) -> String {
    if dir == "." {
        String::new()
    } else {
        format!("cd {dir} && ")
    }
}

fn root() -> PathBuf {
    // xtask/ is one level below the workspace root.
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

/// The row of the table `text` whose first cell is `what`, if any.
fn previous_row(text: &str, what: &str) -> Option<String> {
    let head = format!("| {what} |");
    text.lines()
        .find(|l| l.starts_with(&head))
        .map(str::to_string)
}

fn figures(quick: bool, only: Option<&str>, out_path: &Path) -> Result<(), String> {
    let root = root();
    let t_all = Instant::now();
    let mut rows = Vec::new();
    let previous = std::fs::read_to_string(out_path).unwrap_or_default();
    for m in MEASURES {
        if (quick && m.slow) || only.is_some_and(|o| !m.what.contains(o)) {
            // The row the previous run wrote, as it was; or a row saying it was skipped.
            if let Some(r) = previous_row(&previous, m.what) {
                rows.push(r);
                continue;
            }
            rows.push(format!(
                "| {} | {} | skipped (`--quick` or `--only`) | `{}{} {}` | |",
                m.what,
                m.target,
                cd(m.dir),
                m.program,
                m.args.join(" ")
            ));
            continue;
        }
        eprintln!("figures: {} …", m.what);
        let t = Instant::now();
        let o = Command::new(m.program)
            .args(m.args)
            .current_dir(root.join(m.dir))
            .output();
        let secs = t.elapsed().as_secs_f64();
        let figure = match o {
            Err(e) => format!("**not measured**: {} could not start: {e}", m.program),
            Ok(o) => {
                let text = format!(
                    "{}\n{}",
                    String::from_utf8_lossy(&o.stdout),
                    String::from_utf8_lossy(&o.stderr)
                );
                let mut lines = quoted(&text, m.markers);
                if m.markers.is_empty() && o.status.success() {
                    match board_size(&root) {
                        Ok(s) => lines.push(s),
                        Err(e) => lines.push(format!("**not measured**: {e}")),
                    }
                }
                if !o.status.success() {
                    let last = text
                        .lines()
                        .rev()
                        .find(|l| !l.trim().is_empty())
                        .unwrap_or("");
                    lines.push(format!(
                        "**failed** ({}): {}",
                        o.status,
                        last.trim().replace('|', "\\|")
                    ));
                } else if lines.is_empty() {
                    lines.push("**not measured**: no figure in the output".into());
                }
                lines.join("<br>")
            }
        };
        rows.push(format!(
            "| {} | {} | {} | `{}{} {}` | {:.0} s |",
            m.what,
            m.target,
            figure,
            cd(m.dir),
            m.program,
            m.args.join(" "),
            secs
        ));
    }
    let host = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|s| s.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    let text = format!(
        "# Figures\n\n\
         Written by `cargo xtask figures{}` (do not edit: run it again) in {:.0} s on {host}, \
         {cores} cores. Each figure is the output line of the command next to it, quoted as \
         printed; speeds depend on the machine and its load (best of several runs where the \
         bench says so).{}\n\n\
         | what | target | measured | command | time |\n| --- | --- | --- | --- | --- |\n{}\n",
        match (quick, only) {
            (_, Some(o)) => format!(" --only '{o}'"),
            (true, None) => " --quick".to_string(),
            (false, None) => String::new(),
        },
        t_all.elapsed().as_secs_f64(),
        if quick || only.is_some() {
            " The rows `--quick` or `--only` does not measure (board image, M4 check, benches, the diagnosis's \
             long run) are kept as \
             the previous run wrote them."
        } else {
            ""
        },
        rows.join("\n")
    );
    std::fs::write(out_path, text).map_err(|e| format!("{}: {e}", out_path.display()))?;
    eprintln!(
        "figures: wrote {} in {:.0} s",
        out_path.display(),
        t_all.elapsed().as_secs_f64()
    );
    Ok(())
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: cargo xtask figures [--quick] [--only TEXT] [--out FILE]  (default docs/figures.md; --only: measure the rows whose name contains TEXT, keep the others)";
    let r = match args.first().map(String::as_str) {
        Some("figures") => {
            let mut quick = false;
            let mut only = None;
            let mut out = root().join("docs/figures.md");
            let mut it = args[1..].iter();
            let mut bad = None;
            while let Some(a) = it.next() {
                match a.as_str() {
                    "--quick" => quick = true,
                    "--only" => match it.next() {
                        Some(t) => only = Some(t.clone()),
                        None => bad = Some("--only: the text of the rows to measure".to_string()),
                    },
                    "--out" => match it.next() {
                        Some(p) => out = PathBuf::from(p),
                        None => bad = Some("--out: a file path".to_string()),
                    },
                    o => bad = Some(format!("unknown argument '{o}'; {usage}")),
                }
            }
            match bad {
                Some(e) => Err(e),
                None => figures(quick, only.as_deref(), &out),
            }
        }
        _ => Err(usage.to_string()),
    };
    if let Err(e) = r {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quick_keeps_the_previous_rows() {
        let t = "# Figures\n\n| what | target |\n| console fuzz | x | 1 |\n| board image flash and static RAM | y | 74372 |\n";
        assert_eq!(
            previous_row(t, "board image flash and static RAM").as_deref(),
            Some("| board image flash and static RAM | y | 74372 |")
        );
        assert_eq!(previous_row(t, "board image"), None);
        assert_eq!(previous_row("", "console fuzz"), None);
    }

    #[test]
    fn quotes_only_marked_lines_and_escapes_pipes() {
        let out = "noise\n  total   190 ns = 263x real time\nconsole_fuzz: 10 inputs | ok\n";
        assert_eq!(
            quoted(out, &["  total ", "console_fuzz:"]),
            [
                "total   190 ns = 263x real time",
                "console_fuzz: 10 inputs \\| ok"
            ]
        );
        assert!(quoted(out, &["absent"]).is_empty());
    }
}
