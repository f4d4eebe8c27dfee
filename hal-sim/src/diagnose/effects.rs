//! The catalogue of candidate physical effects. Each is a set of regressor columns added to the
//! linear device model; some carry one nonlinear parameter scanned on a grid. The same
//! functions generate the effects in `synth`, so what is hidden is what is fitted.

use super::record::Record;

/// Catalogue entries (the baseline terms inertia, viscous, Coulomb and offset are always in
/// the model and are reported with their significance, not searched for).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EffectKind {
    /// Viscous coefficient differs with the direction of motion (Coulomb asymmetry is the
    /// offset, which the baseline carries).
    DirectionAsymmetricFriction,
    /// Coulomb level varies slowly along the stroke (linear and quadratic in position).
    PositionDependentFriction,
    /// Coulomb level modulated periodically in position (parameter: wavelength, m).
    PositionPeriodicFriction,
    /// Force periodic in position, independent of direction (parameter: wavelength, m).
    Cogging,
    /// Extra friction at low speed decaying as exp(-(v/vs)^2) (parameter: vs, m/s).
    Stribeck,
    /// Force scaled differently when the device is driven (f·v > 0) than when it drives.
    ScrewEfficiency,
    /// Measured force delayed from the motion (parameter: lag, s).
    Lag,
    /// Force clipped at a level (parameter: limit, N).
    CurrentLimit,
    /// Extra inertia that acts only while the device is driven (reflected rotor inertia
    /// seen through an efficiency < 1).
    ReflectedInertia,
}

impl EffectKind {
    pub const ALL: [EffectKind; 9] = [
        EffectKind::DirectionAsymmetricFriction,
        EffectKind::PositionDependentFriction,
        EffectKind::PositionPeriodicFriction,
        EffectKind::Cogging,
        EffectKind::Stribeck,
        EffectKind::ScrewEfficiency,
        EffectKind::Lag,
        EffectKind::CurrentLimit,
        EffectKind::ReflectedInertia,
    ];
    pub fn name(self) -> &'static str {
        match self {
            EffectKind::DirectionAsymmetricFriction => "direction_asymmetric_friction",
            EffectKind::PositionDependentFriction => "position_dependent_friction",
            EffectKind::PositionPeriodicFriction => "position_periodic_friction",
            EffectKind::Cogging => "cogging",
            EffectKind::Stribeck => "stribeck",
            EffectKind::ScrewEfficiency => "screw_efficiency",
            EffectKind::Lag => "lag",
            EffectKind::CurrentLimit => "current_limit",
            EffectKind::ReflectedInertia => "reflected_inertia",
        }
    }
    pub fn from_name(s: &str) -> Option<Self> {
        Self::ALL.iter().copied().find(|k| k.name() == s)
    }
    /// True when the effect carries a scanned nonlinear parameter (counted in the BIC).
    pub fn scanned(self) -> bool {
        matches!(
            self,
            EffectKind::PositionPeriodicFriction
                | EffectKind::Cogging
                | EffectKind::Stribeck
                | EffectKind::Lag
                | EffectKind::CurrentLimit
        )
    }
}

/// An effect with its scanned parameter (0 when it has none).
#[derive(Debug, Clone, PartialEq)]
pub struct Effect {
    pub kind: EffectKind,
    pub param: f64,
}

/// Precomputed signals of a record.
pub struct Context<'a> {
    pub rec: &'a Record,
    pub sgn: Vec<f64>,
    pub xn: Vec<f64>,
    pub x_mid: f64,
    pub x_half: f64,
    pub v_eps: f64,
    pub vmax: f64,
    pub dt: f64,
    /// Baseline prediction (set after the baseline fit; used by lag, current limit,
    /// efficiency).
    pub base_pred: Vec<f64>,
}

/// Smoothed sign: exact sign outside ±v_eps, linear inside (v_eps = 0.2 % of the peak speed,
/// so derivative noise at rest does not flip the Coulomb term).
pub fn sgn(v: f64, v_eps: f64) -> f64 {
    (v / v_eps).clamp(-1.0, 1.0)
}

impl<'a> Context<'a> {
    pub fn new(rec: &'a Record) -> Self {
        let vmax = rec.v.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-12);
        let v_eps = 2e-3 * vmax;
        let xmin = rec.x.iter().cloned().fold(f64::MAX, f64::min);
        let xmax = rec.x.iter().cloned().fold(f64::MIN, f64::max);
        let x_mid = 0.5 * (xmin + xmax);
        let x_half = (0.5 * (xmax - xmin)).max(1e-12);
        let mut c = Context {
            rec,
            sgn: rec.v.iter().map(|&v| sgn(v, v_eps)).collect(),
            xn: rec.x.iter().map(|&x| (x - x_mid) / x_half).collect(),
            x_mid,
            x_half,
            v_eps,
            vmax,
            dt: rec.dt(),
            base_pred: Vec::new(),
        };
        // baseline fit on the whole record gives the force proxy for the pred-based effects
        let cols = base_columns(&c);
        let refs: Vec<&[f64]> = cols.iter().map(|(_, v)| v.as_slice()).collect();
        let all = vec![false; rec.len()];
        let (tr, _) = super::normals(&refs, &rec.f, &all, 1);
        c.base_pred = predict(&cols, &tr.solve());
        c
    }
}

fn base_columns(ctx: &Context) -> Vec<(String, Vec<f64>)> {
    let r = ctx.rec;
    vec![
        ("inertia".into(), r.a.clone()),
        ("viscous".into(), r.v.clone()),
        ("coulomb".into(), ctx.sgn.clone()),
        ("offset".into(), vec![1.0; r.len()]),
    ]
}

/// Baseline columns followed by the columns of each chosen effect.
pub fn build_columns(ctx: &Context, chosen: &[Effect]) -> Vec<(String, Vec<f64>)> {
    let mut cols = base_columns(ctx);
    for e in chosen {
        cols.extend(effect_columns(ctx, e, None));
    }
    cols
}

/// Σ θ_k col_k.
pub fn predict(cols: &[(String, Vec<f64>)], th: &[f64]) -> Vec<f64> {
    let n = cols[0].1.len();
    let mut p = vec![0.0; n];
    for ((_, c), t) in cols.iter().zip(th) {
        for (pi, ci) in p.iter_mut().zip(c) {
            *pi += t * ci;
        }
    }
    p
}

/// Unit-coefficient shape of an effect for synthesis and fitting: the regressor columns, at
/// the sample indices `rows` (all samples when None).
pub fn effect_columns(
    ctx: &Context,
    e: &Effect,
    rows: Option<&[usize]>,
) -> Vec<(String, Vec<f64>)> {
    let r = ctx.rec;
    let all: Vec<usize>;
    let idx: &[usize] = match rows {
        Some(x) => x,
        None => {
            all = (0..r.len()).collect();
            &all
        }
    };
    let name = e.kind.name();
    let col = |suffix: &str, v: Vec<f64>| (format!("{name}.{suffix}"), v);
    let bp = &ctx.base_pred;
    let map = |g: &dyn Fn(usize) -> f64| idx.iter().map(|&i| g(i)).collect::<Vec<f64>>();
    match e.kind {
        EffectKind::DirectionAsymmetricFriction => vec![col("abs_v", map(&|i| r.v[i].abs()))],
        EffectKind::PositionDependentFriction => vec![
            col("x_sgn", map(&|i| ctx.xn[i] * ctx.sgn[i])),
            col("x2_sgn", map(&|i| ctx.xn[i] * ctx.xn[i] * ctx.sgn[i])),
        ],
        EffectKind::PositionPeriodicFriction | EffectKind::Cogging => {
            let k = 2.0 * std::f64::consts::PI / e.param;
            let fr = e.kind == EffectKind::PositionPeriodicFriction;
            let mut s = Vec::with_capacity(idx.len());
            let mut c = Vec::with_capacity(idx.len());
            for &i in idx {
                let (sn, cs) = (k * r.x[i]).sin_cos();
                let g = if fr { ctx.sgn[i] } else { 1.0 };
                s.push(sn * g);
                c.push(cs * g);
            }
            vec![col("sin", s), col("cos", c)]
        }
        EffectKind::Stribeck => vec![col(
            "sgn_exp",
            map(&|i| ctx.sgn[i] * (-(r.v[i] / e.param).powi(2)).exp()),
        )],
        EffectKind::ScrewEfficiency => vec![col(
            "driven_force",
            map(&|i| if bp[i] * r.v[i] > 0.0 { bp[i] } else { 0.0 }),
        )],
        EffectKind::ReflectedInertia => vec![col(
            "driven_accel",
            map(&|i| if bp[i] * r.v[i] > 0.0 { r.a[i] } else { 0.0 }),
        )],
        EffectKind::Lag => {
            let k = ((e.param / ctx.dt).round() as usize).max(1);
            vec![col(
                "delayed_minus_now",
                map(&|i| bp[i.saturating_sub(k)] - bp[i]),
            )]
        }
        EffectKind::CurrentLimit => {
            let l = e.param;
            vec![col("clip_minus_free", map(&|i| bp[i].clamp(-l, l) - bp[i]))]
        }
    }
}

/// The candidates to screen (one per kind; the grid supplies the parameter).
pub fn catalogue(_ctx: &Context) -> Vec<Effect> {
    EffectKind::ALL
        .iter()
        .map(|&kind| Effect { kind, param: 0.0 })
        .collect()
}

fn logspace(a: f64, b: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| a * (b / a).powf(i as f64 / (n - 1).max(1) as f64))
        .collect()
}

/// Coarse grid of parameter values for a candidate (a single entry when not scanned). The
/// selection refines the best coarse value locally.
pub fn grid(ctx: &Context, cand: &Effect) -> Vec<Effect> {
    let mk = |p: f64| Effect {
        kind: cand.kind,
        param: p,
    };
    match cand.kind {
        EffectKind::PositionPeriodicFriction | EffectKind::Cogging => {
            let stroke = 2.0 * ctx.x_half;
            // shortest wavelength: 8 encoder-noise-free samples per period at the median step
            let mut steps: Vec<f64> = ctx.rec.x.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
            let k = steps.len() / 2;
            let med = *steps.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1;
            let lmin = (stroke / 400.0).max(8.0 * med).min(stroke / 4.0);
            let mut g: Vec<Effect> = logspace(lmin, stroke / 1.5, 40)
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
            g
        }
        EffectKind::Stribeck => logspace(2.0 * ctx.v_eps, 0.3 * ctx.vmax, 14)
            .into_iter()
            .map(mk)
            .collect(),
        EffectKind::Lag => [1usize, 2, 3, 4, 6, 8, 11, 16, 22, 32, 45, 64]
            .iter()
            .map(|&k| mk(k as f64 * ctx.dt))
            .collect(),
        EffectKind::CurrentLimit => {
            let mut a: Vec<f64> = ctx.base_pred.iter().map(|f| f.abs()).collect();
            a.sort_by(|x, y| x.total_cmp(y));
            [0.80, 0.85, 0.9, 0.93, 0.96, 0.98, 0.99]
                .iter()
                .map(|q| mk(a[((a.len() - 1) as f64 * q) as usize]))
                .collect()
        }
        _ => vec![mk(0.0)],
    }
}

/// Local refinement grid around a coarse best value.
pub fn refine(ctx: &Context, e: &Effect, width: f64) -> Vec<Effect> {
    match e.kind {
        EffectKind::PositionPeriodicFriction
        | EffectKind::Cogging
        | EffectKind::Stribeck
        | EffectKind::CurrentLimit => (0..=20)
            .map(|i| Effect {
                kind: e.kind,
                param: e.param * (1.0 + width * (i as f64 / 10.0 - 1.0)),
            })
            .collect(),
        EffectKind::Lag => {
            let k = (e.param / ctx.dt).round() as i64;
            let w = ((k as f64 * width).ceil() as i64).max(1);
            (k - w..=k + w)
                .filter(|&j| j >= 1)
                .map(|j| Effect {
                    kind: e.kind,
                    param: j as f64 * ctx.dt,
                })
                .collect()
        }
        _ => vec![],
    }
}

/// Physical parameters of the `idx`-th chosen effect from the fitted coefficients.
pub fn parameters(
    ctx: &Context,
    chosen: &[Effect],
    cols: &[(String, Vec<f64>)],
    th: &[f64],
    idx: usize,
) -> Vec<(String, f64)> {
    let e = &chosen[idx];
    let prefix = format!("{}.", e.kind.name());
    let coef: Vec<(String, f64)> = cols
        .iter()
        .zip(th)
        .filter(|((n, _), _)| n.starts_with(&prefix))
        .map(|((n, _), t)| (n[prefix.len()..].to_string(), *t))
        .collect();
    let get = |s: &str| coef.iter().find(|c| c.0 == s).map(|c| c.1).unwrap_or(0.0);
    let fv = th[1];
    let fc = th[2];
    let off = th[3];
    match e.kind {
        EffectKind::DirectionAsymmetricFriction => vec![
            ("viscous_pos_Ns_per_m".into(), fv + get("abs_v")),
            ("viscous_neg_Ns_per_m".into(), fv - get("abs_v")),
            ("coulomb_pos_N".into(), fc + off),
            ("coulomb_neg_N".into(), fc - off),
        ],
        EffectKind::PositionDependentFriction => vec![
            ("coulomb_slope_N_per_m".into(), get("x_sgn") / ctx.x_half),
            (
                "coulomb_curvature_N_per_m2".into(),
                get("x2_sgn") / (ctx.x_half * ctx.x_half),
            ),
            ("x_mid_m".into(), ctx.x_mid),
        ],
        EffectKind::PositionPeriodicFriction | EffectKind::Cogging => {
            let (s, c) = (get("sin"), get("cos"));
            vec![
                ("wavelength_m".into(), e.param),
                ("amplitude_N".into(), s.hypot(c)),
                ("phase_rad".into(), c.atan2(s)),
            ]
        }
        EffectKind::Stribeck => vec![
            ("stribeck_velocity_m_s".into(), e.param),
            ("amplitude_N".into(), get("sgn_exp")),
        ],
        EffectKind::ScrewEfficiency => vec![(
            "driven_over_driving_force_ratio".into(),
            1.0 + get("driven_force"),
        )],
        EffectKind::ReflectedInertia => {
            vec![("extra_driven_inertia_kg".into(), get("driven_accel"))]
        }
        EffectKind::Lag => vec![
            ("lag_s".into(), e.param),
            ("gain".into(), get("delayed_minus_now")),
        ],
        EffectKind::CurrentLimit => vec![
            ("limit_N".into(), e.param),
            ("gain".into(), get("clip_minus_free")),
        ],
    }
}

/// One-line physical reading of an effect (wavelength matched to screw lead / ball size).
pub fn describe(ctx: &Context, e: &Effect) -> String {
    match e.kind {
        EffectKind::PositionPeriodicFriction | EffectKind::Cogging => {
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
        EffectKind::Stribeck => format!("Stribeck velocity {:.3e} m/s", e.param),
        EffectKind::Lag => format!("force lags motion by {:.4} s", e.param),
        EffectKind::CurrentLimit => format!("force clipped near {:.1} N", e.param),
        _ => String::new(),
    }
}
