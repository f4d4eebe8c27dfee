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
        + check_dir(&diag, &keep, "diagnose-")
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
