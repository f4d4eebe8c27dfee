//! The diagnosis's residual plots (SVG through [`crate::plot`]): against time, position and
//! velocity, and its spectra.

use super::{report, Diagnosis, Record};

/// A scatter plot of `ys` against `xs` (decimated to ~3000 points) through [`crate::plot`].
fn scatter(
    path: &std::path::Path,
    title: &str,
    xl: &str,
    yl: &str,
    xs: &[f64],
    ys: &[f64],
    ylog: bool,
) -> Result<(), String> {
    let step = (xs.len() / 3000).max(1);
    let pts: Vec<(f64, f64)> = xs
        .iter()
        .zip(ys)
        .step_by(step)
        .map(|(x, y)| (*x, *y))
        .collect();
    let mut p = crate::plot::Plot::new(title, xl, yl);
    p.ylog = ylog;
    p.series.push(crate::plot::Series::dots(
        format!("final-model residual ({} points)", pts.len()),
        pts,
    ));
    p.write_svg(path).map(|_| ())
}

/// Write residual plots into `dir`: against time, position, velocity, and its spectrum.
pub fn write_plots(
    dir: &std::path::Path,
    rec: &Record,
    d: &Diagnosis,
) -> Result<Vec<String>, String> {
    let mut out = Vec::new();
    for (name, what, xl, xs) in [
        ("residual_vs_time.svg", "time", "time t (s)", &rec.t),
        (
            "residual_vs_position.svg",
            "position",
            "position x (m)",
            &rec.x,
        ),
        (
            "residual_vs_velocity.svg",
            "velocity",
            "velocity v (m/s)",
            &rec.v,
        ),
    ] {
        let p = dir.join(name);
        scatter(
            &p,
            &format!("diagnosis: final-model force residual against {what}"),
            xl,
            "force residual (N)",
            xs,
            &d.residual,
            false,
        )?;
        out.push(p.display().to_string());
    }
    let sp = report::welch(&d.residual, rec.dt());
    let (f, a): (Vec<f64>, Vec<f64>) = sp.into_iter().skip(1).unzip();
    let p = dir.join("residual_spectrum.svg");
    scatter(
        &p,
        "diagnosis: residual amplitude spectrum (Welch)",
        "frequency (Hz)",
        "amplitude (N, log scale)",
        &f,
        &a,
        true,
    )?;
    out.push(p.display().to_string());
    let ps = &d.position_spectrum;
    if !ps.spectrum.is_empty() {
        let (nu, a): (Vec<f64>, Vec<f64>) = ps.spectrum.iter().cloned().unzip();
        let p = dir.join("residual_spectrum_position.svg");
        scatter(
            &p,
            "diagnosis: residual amplitude over position (wavelength = 1/spatial frequency)",
            "spatial frequency (cycles/m)",
            "amplitude (N, log scale)",
            &nu,
            &a,
            true,
        )?;
        out.push(p.display().to_string());
    }
    Ok(out)
}
