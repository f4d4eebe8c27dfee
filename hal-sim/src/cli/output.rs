//! CSV and SVG output (the SVG is written directly: no font or plotting dependency).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Write CSV rows under a header.
pub fn write_csv(path: &Path, header: &[&str], rows: &[Vec<f64>]) -> Result<(), String> {
    let mut s = header.join(",");
    s.push('\n');
    for r in rows {
        let line: Vec<String> = r.iter().map(|v| format!("{v:.6e}")).collect();
        s.push_str(&line.join(","));
        s.push('\n');
    }
    write(path, &s)
}

pub fn write(path: &Path, text: &str) -> Result<(), String> {
    if let Some(d) = path.parent() {
        std::fs::create_dir_all(d).map_err(|e| format!("{}: {e}", d.display()))?;
    }
    std::fs::write(path, text).map_err(|e| format!("{}: {e}", path.display()))
}

/// One curve: name, points, and whether to draw markers instead of a line.
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    pub markers: bool,
}

/// A line plot with linear or log x axis.
pub fn plot_svg(
    path: &Path,
    title: &str,
    xlabel: &str,
    ylabel: &str,
    series: &[Series],
    logx: bool,
) -> Result<PathBuf, String> {
    let (w, h, ml, mr, mt, mb) = (800.0, 500.0, 80.0, 30.0, 40.0, 60.0);
    let tx = |x: f64| if logx { x.max(1e-300).log10() } else { x };
    let pts = series
        .iter()
        .flat_map(|s| s.points.iter())
        .filter(|p| p.0.is_finite() && p.1.is_finite());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in pts {
        x0 = x0.min(tx(x));
        x1 = x1.max(tx(x));
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if x0 >= x1 {
        x1 = x0 + 1.0;
    }
    if y0 >= y1 {
        y1 = y0 + 1.0;
    }
    let pad = 0.05 * (y1 - y0);
    let (y0, y1) = (y0 - pad, y1 + pad);
    let px = |x: f64| ml + (tx(x) - x0) / (x1 - x0) * (w - ml - mr);
    let py = |y: f64| h - mb - (y - y0) / (y1 - y0) * (h - mt - mb);
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let _ = writeln!(
        s,
        r#"<text x="{}" y="24" text-anchor="middle" font-size="15">{}</text>"#,
        w / 2.0,
        esc(title)
    );
    let _ = writeln!(
        s,
        r#"<rect x="{ml}" y="{mt}" width="{}" height="{}" fill="none" stroke="black"/>"#,
        w - ml - mr,
        h - mt - mb
    );
    for k in 0..=5 {
        let f = k as f64 / 5.0;
        let xv = x0 + f * (x1 - x0);
        let label = if logx { 10f64.powf(xv) } else { xv };
        let xp = ml + f * (w - ml - mr);
        let _ = writeln!(
            s,
            r##"<line x1="{xp}" y1="{mt}" x2="{xp}" y2="{}" stroke="#ddd"/><text x="{xp}" y="{}" text-anchor="middle">{}</text>"##,
            h - mb,
            h - mb + 16.0,
            fmt(label)
        );
        let yv = y0 + f * (y1 - y0);
        let yp = py(yv);
        let _ = writeln!(
            s,
            r##"<line x1="{ml}" y1="{yp}" x2="{}" y2="{yp}" stroke="#ddd"/><text x="{}" y="{}" text-anchor="end">{}</text>"##,
            w - mr,
            ml - 6.0,
            yp + 4.0,
            fmt(yv)
        );
    }
    let _ = writeln!(
        s,
        r#"<text x="{}" y="{}" text-anchor="middle">{}</text>"#,
        w / 2.0,
        h - 15.0,
        esc(xlabel)
    );
    let _ = writeln!(
        s,
        r#"<text x="18" y="{}" text-anchor="middle" transform="rotate(-90 18 {})">{}</text>"#,
        h / 2.0,
        h / 2.0,
        esc(ylabel)
    );
    const COLOURS: [&str; 6] = [
        "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b",
    ];
    for (k, se) in series.iter().enumerate() {
        let col = COLOURS[k % COLOURS.len()];
        let good: Vec<&(f64, f64)> = se
            .points
            .iter()
            .filter(|p| p.0.is_finite() && p.1.is_finite())
            .collect();
        if se.markers {
            for p in &good {
                let _ = writeln!(
                    s,
                    r#"<circle cx="{:.2}" cy="{:.2}" r="4" fill="none" stroke="{col}" stroke-width="2"/>"#,
                    px(p.0),
                    py(p.1)
                );
            }
        } else if !good.is_empty() {
            let d: Vec<String> = good
                .iter()
                .map(|p| format!("{:.2},{:.2}", px(p.0), py(p.1)))
                .collect();
            let _ = writeln!(
                s,
                r#"<polyline points="{}" fill="none" stroke="{col}" stroke-width="1.5"/>"#,
                d.join(" ")
            );
        }
        let ly = mt + 18.0 + 16.0 * k as f64;
        let _ = writeln!(
            s,
            r#"<text x="{}" y="{ly}" fill="{col}">{}</text>"#,
            ml + 10.0,
            esc(&se.name)
        );
    }
    s.push_str("</svg>\n");
    write(path, &s)?;
    Ok(path.to_path_buf())
}

fn esc(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

fn fmt(v: f64) -> String {
    if v != 0.0 && (v.abs() >= 1e4 || v.abs() < 1e-2) {
        format!("{v:.2e}")
    } else {
        format!("{v:.3}")
    }
}
