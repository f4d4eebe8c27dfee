//! What the two forces periodic in position share (`cogging`, `position_periodic_friction`):
//! their columns, wavelength grid, parameters, reading and in-band test.

use super::*;

/// Columns sin(2πx/λ)·g, cos(2πx/λ)·g, g = sgn v for a friction, 1 for a force.
pub(crate) fn columns(name: &str, s: &Sig, lambda: f64, friction: bool) -> Vec<(String, Vec<f64>)> {
    let n = s.len();
    let k = 2.0 * std::f64::consts::PI / lambda;
    let mut sn_c = Vec::with_capacity(n);
    let mut cs_c = Vec::with_capacity(n);
    for i in 0..n {
        // `libm`'s port of fdlibm's `sincos`: with the release build's fat LTO it costs the
        // same as a hand-inlined fdlibm kernel
        let (sn, cs) = libm::sincos(k * s.x[i]);
        let g = if friction { s.sgn[i] } else { 1.0 };
        sn_c.push(sn * g);
        cs_c.push(cs * g);
    }
    vec![(format!("{name}.sin"), sn_c), (format!("{name}.cos"), cs_c)]
}

/// Wavelengths from `Context::lambda_min` to 1/1.5 of the stroke (40, log-spaced), the screw
/// lead and the ball diameter when the record states them, and the baseline residual's peaks
/// over position.
pub(crate) fn grid(ctx: &Context, kind: EffectKind) -> Vec<Effect> {
    let mk = |p: f64| Effect::new(kind, p);
    let stroke = 2.0 * ctx.x_half;
    // shortest wavelength: 8 encoder-noise-free samples per period at the median step
    let mut g: Vec<Effect> = logspace(ctx.lambda_min, stroke / 1.5, 40)
        .into_iter()
        .map(mk)
        .collect();
    for key in ["lead_m_per_rev", "ball_diameter_m"] {
        if let Some(&l) = ctx.rec.meta.get(key) {
            if l > 0.0 && l < stroke {
                g.push(mk(l));
            }
        }
    }
    for &l in &ctx.spatial_wavelengths {
        if l >= ctx.lambda_min && l < stroke / 1.5 {
            g.push(mk(l));
        }
    }
    g
}

/// Wavelength, amplitude and phase.
pub(crate) fn parameters(e: &Effect, coef: &dyn Fn(&str) -> f64) -> Vec<(String, f64)> {
    let (s, c) = (coef("sin"), coef("cos"));
    vec![
        ("wavelength_m".into(), e.param),
        ("amplitude_N".into(), s.hypot(c)),
        ("phase_rad".into(), c.atan2(s)),
    ]
}

/// The wavelength, matched to the screw lead or the ball pass when the record states them.
pub(crate) fn describe(ctx: &Context, e: &Effect) -> String {
    let mut s = format!("wavelength {:.4e} m", e.param);
    for (key, what) in [
        ("lead_m_per_rev", "one screw revolution"),
        ("ball_diameter_m", "ball pass"),
    ] {
        if let Some(&l) = ctx.rec.meta.get(key) {
            for (mult, lbl) in [(1.0, ""), (0.5, "half of "), (1.0 / 3.0, "a third of ")] {
                if (e.param / (l * mult) - 1.0).abs() < 0.03 {
                    s.push_str(&format!(", matches {lbl}{what} ({key} = {l})"));
                }
            }
        }
    }
    s
}

/// The in-band test of a ripple (`ripple_in_band`).
pub(crate) fn in_band(ctx: &Context, e: &Effect) -> Option<(Vec<bool>, InBandWords)> {
    ripple_in_band(ctx, e.param).map(|m| {
        (
            m,
            InBandWords {
                not: "a force locked to position",
                band: "inside the derived acceleration's band (|v|/λ ≤ half its cutoff)",
                outside: "above it",
            },
        )
    })
}
