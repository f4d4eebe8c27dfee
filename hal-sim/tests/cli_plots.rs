//! Every plot the tools write, rendered (resvg, with the DejaVu Sans file under
//! tests/fonts/) and checked: at least five tick labels, each a round number, and data drawn
//! (more than 50 coloured pixels: a series of 100 one-pixel dots makes about 150). With `REGEN_FIGURES=DIR` the PNGs are kept there
//! (docs/figures/ is made so).

use std::path::{Path, PathBuf};
use std::process::Command;

fn regen(args: &[&str]) {
    let o = Command::new(env!("CARGO_BIN_EXE_regen"))
        .args(args)
        .output()
        .expect("spawn regen");
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// The text of every `<text>` element.
fn texts(svg: &str) -> Vec<String> {
    svg.split("<text")
        .skip(1)
        .filter_map(|t| {
            let body = t.split_once('>')?.1;
            Some(
                body.split("</text>")
                    .next()?
                    .replace("&amp;", "&")
                    .replace("&lt;", "<")
                    .replace("&gt;", ">")
                    .trim()
                    .to_string(),
            )
        })
        .collect()
}

/// Round: at most two significant digits, or three ending in 5 (0.25, 150, 2e-5, -40000),
/// written independently of the plot module's own check.
fn round(v: f64) -> bool {
    if v == 0.0 {
        return true;
    }
    let e = v.abs().log10().floor();
    let m = v.abs() / 10f64.powf(e); // 1 ≤ m < 10
    let two = m * 10.0;
    let three = m * 100.0;
    (two - two.round()).abs() < 1e-6
        || ((three - three.round()).abs() < 1e-6 && three.round() as i64 % 5 == 0)
}

fn render(svg: &str, png: Option<&Path>) -> usize {
    let mut opt = resvg::usvg::Options::default();
    opt.fontdb_mut()
        .load_font_data(include_bytes!("fonts/DejaVuSans.ttf").to_vec());
    opt.fontdb_mut().set_sans_serif_family("DejaVu Sans");
    let tree = resvg::usvg::Tree::from_str(svg, &opt).expect("valid SVG");
    let size = tree.size().to_int_size();
    let mut pix = resvg::tiny_skia::Pixmap::new(size.width(), size.height()).unwrap();
    resvg::render(
        &tree,
        resvg::tiny_skia::Transform::default(),
        &mut pix.as_mut(),
    );
    if let Some(p) = png {
        pix.save_png(p).expect("write PNG");
    }
    // Coloured (not grey) pixels: the data; axes, grid and text are grey or black.
    pix.pixels()
        .iter()
        .filter(|p| {
            let (r, g, b) = (p.red() as i32, p.green() as i32, p.blue() as i32);
            (r - g).abs().max((g - b).abs()).max((r - b).abs()) > 60
        })
        .count()
}

fn check_dir(dir: &Path, keep: &Option<PathBuf>, prefix: &str) -> usize {
    let mut n = 0;
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_none_or(|x| x != "svg") {
            continue;
        }
        let svg = std::fs::read_to_string(&p).unwrap();
        let labels: Vec<f64> = texts(&svg)
            .iter()
            .filter_map(|t| t.replace('−', "-").parse::<f64>().ok())
            .collect();
        assert!(
            labels.len() >= 5,
            "{}: {} tick labels",
            p.display(),
            labels.len()
        );
        for v in &labels {
            assert!(
                round(*v),
                "{}: tick label {v} is not a round number",
                p.display()
            );
        }
        let png = keep.as_ref().map(|d| {
            d.join(format!(
                "{prefix}{}.png",
                p.file_stem().unwrap().to_string_lossy()
            ))
        });
        let coloured = render(&svg, png.as_deref());
        assert!(coloured > 50, "{}: {coloured} data pixels", p.display());
        n += 1;
    }
    n
}

#[test]
fn every_plot_has_round_ticks_and_data() {
    let d = std::env::temp_dir().join(format!("regen-plots-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    let keep = std::env::var_os("REGEN_FIGURES").map(PathBuf::from);
    if let Some(k) = &keep {
        std::fs::create_dir_all(k).unwrap();
    }
    let sc = d.join("tmd.toml");
    std::fs::write(&sc, "name = \"tmd\"\nduration_s = 4.0\nsettle_s = 2.0\n[law]\nkind = \"resistor\"\nr_load_ohm = 306.0\n[drive]\nkind = \"structure\"\n[drive.excitation]\nkind = \"sine\"\na0_m_s2 = 1.0\nfreq_hz = 0.5\n[record]\nchannels = [\"t\", \"x\", \"v\", \"force\", \"i_d\", \"i_q\", \"i_q_ref\", \"v_bus\", \"p_inverter\"]\nevery = 20\n").unwrap();
    let sc = sc.to_str().unwrap();
    let run = d.join("run");
    regen(&[
        "run",
        sc,
        "--out",
        run.to_str().unwrap(),
        "--window",
        "1,1.5",
    ]);
    let sweep = d.join("sweep");
    let so = sweep.to_str().unwrap();
    regen(&[
        "sweep",
        sc,
        "--out",
        so,
        "--values",
        "20,50,100,306,600,1000",
    ]);
    regen(&[
        "sweep",
        sc,
        "--out",
        so,
        "--param",
        "a0_m_s2",
        "--values",
        "0.5,1,2,50",
    ]);
    // A synthetic record: inertia, viscous and Coulomb friction on a 2 Hz stroke, 1 kHz.
    let mut rec = String::from("t_s,x_m,f_N\n");
    let w = std::f64::consts::TAU * 2.0;
    for k in 0..4000 {
        let t = k as f64 * 1e-3;
        let (x, v, a) = (
            0.01 * (w * t).sin(),
            0.01 * w * (w * t).cos(),
            -0.01 * w * w * (w * t).sin(),
        );
        rec += &format!(
            "{t},{x},{}\n",
            20.0 * a + 200.0 * v + 5.0 * v.signum() + 0.3 * (400.0 * x).sin()
        );
    }
    let rp = d.join("rec.csv");
    std::fs::write(&rp, rec).unwrap();
    let diag = d.join("diag");
    regen(&[
        "diagnose",
        rp.to_str().unwrap(),
        "--plots",
        diag.to_str().unwrap(),
    ]);
    // The regime map at the device's rated current (1.94 A): the strongest excitations clip,
    // and the map marks those points.
    let study = d.join("study");
    regen(&[
        "study",
        "regimes",
        "--out",
        study.to_str().unwrap(),
        "--points",
        "6",
        "--secs",
        "20",
        "--i-max",
        "1.94",
    ]);
    let map = std::fs::read_to_string(study.join("regimes.svg")).unwrap();
    let legend = texts(&map);
    for want in [
        "one-way nets most",
        "two-way nets most",
        "no law nets power",
        "a law at its current limit in ≥ 1 % of the periods",
    ] {
        assert!(
            legend.iter().any(|t| t == want),
            "`{want}` not in {legend:?}"
        );
    }
    let n = check_dir(&run, &keep, "run-")
        + check_dir(&sweep, &keep, "")
        + check_dir(&diag, &None, "")
        + check_dir(&study, &keep, "study-");
    assert!(n >= 10, "{n} plots checked");
}

/// The figures shown in the README and docs/laws.md, from the real commands with their
/// defaults (the main job; `study regimes` at the device's rated current), checked like the
/// others: `REGEN_FIGURES=$PWD/docs/figures cargo test -p hal-sim --test cli_plots -- --ignored`
/// (≈ 1 min).
#[test]
#[ignore]
fn docs_figures_from_the_real_commands() {
    let d = std::env::temp_dir().join(format!("regen-docs-plots-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    let keep = std::env::var_os("REGEN_FIGURES").map(PathBuf::from);
    if let Some(k) = &keep {
        std::fs::create_dir_all(k).unwrap();
    }
    let o = Command::new(env!("CARGO_BIN_EXE_regen"))
        .current_dir(&d)
        .output()
        .expect("spawn regen");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let study = d.join("study");
    regen(&[
        "study",
        "regimes",
        "--out",
        study.to_str().unwrap(),
        "--i-max",
        "1.937",
    ]);
    let n = check_dir(&d.join("regen-out"), &keep, "") + check_dir(&study, &keep, "study-");
    assert_eq!(n, 2, "{n} plots checked");
}

/// The x axis's tick labels: (x position px, value, characters), from the numeric `<text>`
/// elements centred on their position (the y axis's are right-aligned).
fn x_ticks(svg: &str) -> Vec<(f64, f64, usize)> {
    svg.split("<text")
        .skip(1)
        .filter_map(|t| {
            let (tag, body) = t.split_once('>')?;
            if !tag.contains("text-anchor=\"middle\"") {
                return None;
            }
            let x: f64 = tag.split("x=\"").nth(1)?.split('"').next()?.parse().ok()?;
            let text = body.split("</text>").next()?.trim();
            let v: f64 = text.replace('−', "-").parse().ok()?;
            Some((x, v, text.chars().count()))
        })
        .collect()
}

/// The diagnosis's plots, before (the baseline model) and after (the extended one), on a
/// simulated record (`regen run --record-diagnose` of an imposed 0.5 Hz stroke with eq. 13's
/// first ripple, 30 % deep, at one screw revolution) and on the EMPS record
/// (`data/emps/emps_estimation.csv`): each rendered and checked as every plot is (round ticks,
/// data drawn), and: drawn as lines (no dots), each curve once in the legend, the spectra on
/// log axes (frequency over at least two decades), the peaks and wavelengths the report
/// names labelled. `REGEN_FIGURES=DIR` keeps the PNGs as `diagnose-sim-*.png` and
/// `diagnose-emps-*.png` (docs/diagnose.md shows them).
#[test]
fn diagnosis_plots_before_and_after() {
    let d = std::env::temp_dir().join(format!("regen-diag-plots-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    let keep = std::env::var_os("REGEN_FIGURES").map(PathBuf::from);
    if let Some(k) = &keep {
        std::fs::create_dir_all(k).unwrap();
    }
    let sc = d.join("bench.toml");
    std::fs::write(&sc, "name = \"bench\"\nduration_s = 20.0\n[screw]\np3 = 0.3\n[law]\nkind = \"resistor\"\nr_load_ohm = 50.0\n[drive]\nkind = \"imposed\"\n[drive.motion]\nkind = \"sine\"\namplitude_m = 0.05\nfreq_hz = 0.5\n[record]\nchannels = [\"t\", \"x\", \"v\", \"force\"]\nevery = 20\n").unwrap();
    let rec = d.join("sim.csv");
    regen(&[
        "run",
        sc.to_str().unwrap(),
        "-q",
        "--out",
        d.join("run").to_str().unwrap(),
        "--record-diagnose",
        rec.to_str().unwrap(),
    ]);
    let emps = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../data/emps/emps_estimation.csv"
    );
    for (name, record, labels) in [
        (
            "sim",
            rec.to_str().unwrap(),
            &["position_periodic_friction λ 16 mm"][..],
        ),
        (
            "emps",
            emps,
            &["cogging λ 2.5 mm", "λ 5.39 mm, unexplained", "1.71 Hz"][..],
        ),
    ] {
        let out = d.join(name);
        regen(&["diagnose", record, "--plots", out.to_str().unwrap()]);
        let n = check_dir(&out, &keep, &format!("diagnose-{name}-"));
        assert_eq!(n, 6, "{name}: {n} plots");
        let mut all = Vec::new();
        for e in std::fs::read_dir(&out).unwrap() {
            let p = e.unwrap().path();
            let svg = std::fs::read_to_string(&p).unwrap();
            let t = texts(&svg);
            // Lines: no dot of a scatter (plotters draws dots and circle markers as
            // <circle>).
            assert!(!svg.contains("<circle"), "{}: dots", p.display());
            // Each curve once in the legend.
            for who in ["baseline model (before)", "extended model (after)"] {
                let k = t.iter().filter(|x| *x == who).count();
                assert!(k <= 1, "{}: `{who}` {k} times", p.display());
            }
            let stem = p.file_stem().unwrap().to_string_lossy().to_string();
            // No two x tick labels overdrawn: centres at least their half-widths apart (about
            // 7 px per character at the tick font), plus 4 px.
            let mut xt = x_ticks(&svg);
            xt.sort_by(|a, b| a.0.total_cmp(&b.0));
            for w in xt.windows(2) {
                let need = 3.5 * (w[0].2 + w[1].2) as f64 + 4.0;
                assert!(
                    w[1].0 - w[0].0 >= need,
                    "{}: x ticks {w:?} overdrawn",
                    p.display()
                );
            }
            if stem.starts_with("residual_spectrum") {
                let pos: Vec<f64> = xt.iter().map(|t| t.1).filter(|v| *v > 0.0).collect();
                let span = pos.iter().fold(0.0f64, |m, v| m.max(*v))
                    / pos.iter().fold(f64::INFINITY, |m, v| m.min(*v));
                assert!(span >= 100.0, "{}: x ticks {xt:?}", p.display());
                assert!(t.iter().any(|x| x.contains("log scale")), "{}", p.display());
            } else {
                let k = t
                    .iter()
                    .filter(|x| x.as_str() == "extended model (after)" || x.starts_with("after"))
                    .count();
                assert!(k >= 1, "{}: no after curve in {t:?}", p.display());
            }
            all.extend(t);
        }
        for l in labels {
            assert!(all.iter().any(|t| t == l), "{name}: `{l}` not labelled");
        }
        println!("{name}: 6 plots rendered; labels {labels:?}");
    }
}
