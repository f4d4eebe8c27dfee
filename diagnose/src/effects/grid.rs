//! The candidates' parameter grids, their refinement, and their parameters in words and units.

use super::*;

/// The candidates to screen (one per kind; the grid supplies the parameter).
pub fn catalogue(_ctx: &Context) -> Vec<Effect> {
    EffectKind::ALL
        .iter()
        .map(|&kind| Effect::new(kind, 0.0))
        .collect()
}

/// Highest frequency where the Welch spectrum of the position increments (at most 64
/// segments) stands 100× (in power) above the median of its upper half band, which is the
/// sensor noise floor wherever the motion is band-limited well below fs/4, plus one bin width:
/// the edge is known to the bin width only (a Hann-windowed line between two bins shows in
/// both, its main lobe spans ±2 bins), so the motion still drives a mode up to a bin above
/// the last bin that shows it (rig seed 300006: a 2.643 Hz mode, the last bin 2.686 Hz, the
/// fit's optimum 2.718 Hz was above the scan's top and not bracketed).
pub fn motion_bandwidth(x: &[f64], dt: f64) -> f64 {
    let dx: Vec<f64> = x.windows(2).map(|w| w[1] - w[0]).collect();
    if dx.len() < 64 {
        return 0.0;
    }
    let sp = crate::report::welch_spread(&dx, dt, 64);
    let mut up: Vec<f64> = sp[sp.len() / 2..].iter().map(|p| p.1 * p.1).collect();
    let floor = median(&mut up);
    let bin = sp.get(1).map_or(0.0, |p| p.0);
    sp.iter()
        .rev()
        .find(|p| p.1 * p.1 > 100.0 * floor)
        .map_or(0.0, |p| p.0 + bin)
}

/// Quantiles of |v| (samples in motion) scanned as the speed above which a drive acting as a
/// damper saturates: from a drive clipped over most of the motion to one clipped at its peaks.
pub(crate) const SPEED_QUANTILES: [f64; 12] = [
    0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.85, 0.9, 0.93, 0.96, 0.99,
];

/// The speeds scanned as the saturation speed v_L of a drive acting as a damper (samples in
/// motion, `rest` false): the `SPEED_QUANTILES` of |v| over time, extended below and above
/// their range by the same quantiles of the speeds the motion passes through (|v| weighted by
/// the speed change |Δv| of its sample: each speed counted once per crossing, however long
/// the motion stays at it), sorted. Inside the range of the time quantiles the grid is theirs
/// (on EMPS, cruising at 0.042, 0.082 and 0.125 m/s, a crossing quantile at 0.119 m/s let a
/// drive clip be selected that held on 0/5 segments and displaced a finding).
/// A drive saturates at a speed, and the record resolves it where the motion crosses it; time
/// at a speed says nothing of where the drive saturates: on a motion that cruises at one speed
/// (a rounded triangle's constant-speed flanks) the quantiles over time all lie within 1 % of
/// the cruise speed, and a saturation below it (the rig's clipped drive, 0.45 … 0.8 of the
/// peak speed) lies outside the scanned range (not bracketed, not named). On a sinusoid the
/// crossings are uniform over [0, v̂] (quantile q at q·v̂), the time quantiles at sin(qπ/2)·v̂.
pub fn speed_levels(v: &[f64], rest: &[bool]) -> Vec<f64> {
    let n = v.len();
    // (|v|, |Δv|) of the samples in motion, Δv the central difference of v
    let mut av: Vec<(f64, f64)> = (0..n)
        .filter(|&i| !rest[i])
        .map(|i| {
            let dv = 0.5 * (v[(i + 1).min(n - 1)] - v[i.saturating_sub(1)]);
            (v[i].abs(), dv.abs())
        })
        .collect();
    if av.is_empty() {
        return Vec::new();
    }
    av.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let last = av.len() - 1;
    let mut out: Vec<f64> = SPEED_QUANTILES
        .iter()
        .map(|q| av[(last as f64 * q) as usize].0)
        .collect();
    let (lo, hi) = (out[0], out[out.len() - 1]);
    let total: f64 = av.iter().map(|p| p.1).sum();
    if total > 0.0 {
        let mut cum = 0.0;
        let mut qi = 0;
        for p in &av {
            cum += p.1;
            while qi < SPEED_QUANTILES.len() && cum >= SPEED_QUANTILES[qi] * total {
                // only where they extend the range the time quantiles span
                if p.0 < lo || p.0 > hi {
                    out.push(p.0);
                }
                qi += 1;
            }
        }
    }
    out.retain(|v| *v > 0.0);
    out.sort_unstable_by(|a, b| a.total_cmp(b));
    out.dedup();
    out
}

/// Quantiles of |f̂₀| scanned as current-limit levels.
pub(crate) const CLIP_QUANTILES: [f64; 7] = [0.80, 0.85, 0.9, 0.93, 0.96, 0.98, 0.99];

pub(crate) fn logspace(a: f64, b: f64, n: usize) -> Vec<f64> {
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
        param2: 0.0,
    };
    match cand.kind {
        EffectKind::PositionPeriodicFriction | EffectKind::Cogging => {
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
        EffectKind::Stribeck | EffectKind::VelocityStrengthening => {
            logspace(2.0 * ctx.v_eps, 0.3 * ctx.vmax, 14)
                .into_iter()
                .map(mk)
                .collect()
        }
        // one sample to 64 (a skew beyond 64 ms at 1 kHz is not an acquisition's), 30 values
        // 15 % apart: the ±15 % refinement reaches the neighbours, so the optimum is found
        // whatever coarse value is nearest (a delay and its gain trade against each other on a
        // narrowband motion, a coarser grid's nearest value took the gain out of its range)
        EffectKind::Lag => logspace(ctx.dt, LAG_MAX_SAMPLES * ctx.dt, 30)
            .into_iter()
            .map(mk)
            .collect(),
        // two hypotheses on which force the drive produces, both scanned, the data choosing:
        // the whole force (a motor-driven axis; parameter the level L > 0, N) or the drive's
        // damping force c_d·v on an imposed motion (parameter −v_L < 0, the speed above which
        // it saturates, m/s; L = c_d·v_L)
        EffectKind::CurrentLimit => ctx
            .clip_levels
            .iter()
            .map(|&l| mk(l))
            .chain(ctx.speed_levels.iter().map(|&v| mk(-v)))
            .collect(),
        EffectKind::Backlash | EffectKind::PreslidingHysteresis => {
            let stroke = 2.0 * ctx.x_half;
            // from the position resolution (4 quanta) up: below it no transition is resolved
            let lo = (4.0 * ctx.x_quantum).max(stroke * 1e-6);
            let hi = stroke / 10.0;
            if hi > 1.5 * lo {
                let mut g: Vec<Effect> = logspace(lo, hi, 16).into_iter().map(mk).collect();
                if cand.kind == EffectKind::Backlash {
                    // the play's fit is sharp in its width (a width error moves every contact
                    // by half of it: on the rig the held-out error at ±5 % of the width is 2–5×
                    // the one at the width), sharper than the grid's steps: the width the
                    // impacts show (`impact_travel`) is scanned at 2 % steps over ±20 %
                    if let Some(t) = impact_travel(ctx) {
                        g.extend(
                            (-10..=10)
                                .map(|k| t * (1.0 + 0.02 * k as f64))
                                .filter(|&b| b > lo && b < hi)
                                .map(mk),
                        );
                    }
                }
                g
            } else {
                vec![]
            }
        }
        EffectKind::Compliance => {
            // from 10 periods over the record to the motion bandwidth, and at most half the
            // derivative filter's default cutoff (fs/20): above it the derived acceleration is
            // attenuated by more than 6 % (forward-backward Butterworth-2: 1/(1 + (f/fc)⁴)), so
            // a mode's force cannot be told from the filter's loss
            // (the samples the candidates are screened on: the screening window)
            let t = ctx.dt * ctx.window as f64;
            // and to a quarter of the derivative filter's cutoff when the record states it
            // (the resonator's band then lies where the zero-phase Butterworth-2 passes the
            // derived acceleration within 6 %)
            let cap = ctx
                .rec
                .meta
                .get(crate::record::DERIVATIVE_CUTOFF_KEY)
                .map_or(f64::INFINITY, |fc| 0.25 * fc);
            let hi = ctx.f_motion.min(0.025 / ctx.dt).min(cap);
            let lo = 10.0 / t;
            if hi > 1.5 * lo {
                logspace(lo, hi, 24).into_iter().map(mk).collect()
            } else {
                vec![]
            }
        }
        _ => vec![mk(0.0)],
    }
}

/// The scanned range [lo, hi] of a coarse grid that `best` belongs to: the values of the same
/// sign (the two hypotheses of `current_limit` are two grids, told apart by the sign).
pub fn scan_range(coarse: &[Effect], best: &Effect) -> (f64, f64) {
    coarse
        .iter()
        .filter(|e| (e.param < 0.0) == (best.param < 0.0))
        .fold((f64::MAX, f64::MIN), |(a, b), e| {
            (a.min(e.param), b.max(e.param))
        })
}

/// True when `e` is the `current_limit` of a drive acting as a damper (its force c_d·v
/// clipped) rather than of the whole force.
pub fn drive_clip(e: &Effect) -> bool {
    e.kind == EffectKind::CurrentLimit && e.param < 0.0
}

/// True when a scanned parameter's optimum `p` lies strictly inside the scanned range
/// [`lo`, `hi`] (relative margin 1e-9 for rounding): only then is it bracketed by worse fits
/// on both sides, i.e. identified by the record.
pub fn interior(p: f64, lo: f64, hi: f64) -> bool {
    p > lo + 1e-9 * lo.abs() && p < hi - 1e-9 * hi.abs()
}

/// Local refinement grid around a coarse best value.
pub fn refine(_ctx: &Context, e: &Effect, width: f64) -> Vec<Effect> {
    match e.kind {
        // each compliance value costs a pass of the resonator over the whole record: a
        // coarser refinement (7 values per level) keeps the scan cheap on long records
        EffectKind::Compliance | EffectKind::Backlash | EffectKind::PreslidingHysteresis => (0..=6)
            .map(|i| Effect {
                kind: e.kind,
                param: e.param * (1.0 + width * (i as f64 / 3.0 - 1.0)),
                param2: e.param2,
            })
            .collect(),
        // a lag between samples (the delayed columns interpolated): the rig's delays and an
        // acquisition skew are not whole samples
        EffectKind::PositionPeriodicFriction
        | EffectKind::Cogging
        | EffectKind::Stribeck
        | EffectKind::VelocityStrengthening
        | EffectKind::Lag
        | EffectKind::CurrentLimit => (0..=20)
            .map(|i| Effect {
                kind: e.kind,
                param: e.param * (1.0 + width * (i as f64 / 10.0 - 1.0)),
                param2: 0.0,
            })
            .collect(),

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
        EffectKind::VelocityStrengthening => vec![
            ("buildup_velocity_m_s".into(), e.param),
            ("friction_rise_N".into(), get("sgn_buildup")),
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
        EffectKind::CurrentLimit if e.param < 0.0 => {
            let cd = get("drive_clip_minus_free");
            vec![
                ("limit_N".into(), -e.param * cd),
                ("drive_damping_Ns_per_m".into(), cd),
            ]
        }
        EffectKind::CurrentLimit => vec![
            ("limit_N".into(), e.param),
            ("gain".into(), get("clip_minus_free")),
        ],
        EffectKind::Backlash => {
            let (mi, fvd, fcd) = play_device_coefficients(ctx, ctx.rec.x.len(), e.param, e.param2);
            let (rest, hz) = play_contact(e.param2);
            let mut p = vec![
                ("width_m".into(), e.param),
                ("restitution".into(), rest),
                ("gain".into(), get("free")),
                (
                    "impact_mass_kg".into(),
                    (0..IMPACT_TAPS).map(|k| get(&format!("impact_{k}"))).sum(),
                ),
                ("device_inertia_kg".into(), mi),
                ("device_viscous_Ns_per_m".into(), fvd),
                ("device_coulomb_N".into(), fcd),
            ];
            if hz > 0.0 {
                // a compliant flank: its contact mode with the device's inertia
                p.push(("contact_Hz".into(), hz));
            }
            p
        }
        EffectKind::PreslidingHysteresis => vec![
            ("characteristic_displacement_m".into(), e.param),
            ("friction_N".into(), get("dahl_minus_sgn")),
        ],
        EffectKind::ActuatorLag => {
            vec![("delay_s".into(), get("rate_times_tc") * actuator_tc(ctx))]
        }
        EffectKind::Compliance => vec![
            ("resonance_Hz".into(), e.param),
            ("modal_mass_kg".into(), get("mode_minus_rigid")),
            (
                "damping_ratio".into(),
                ctx.compliance_zeta(e.param).unwrap_or(f64::NAN),
            ),
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
        EffectKind::VelocityStrengthening => format!(
            "the Coulomb level builds up with speed over {:.3e} m/s",
            e.param
        ),
        EffectKind::Lag => format!("force lags motion by {:.4} s", e.param),
        EffectKind::ActuatorLag => {
            "the force channel leads the force: a drive's command, followed through the actuator's delay".into()
        }
        EffectKind::CurrentLimit if e.param < 0.0 => format!(
            "the drive's damping force clipped above {:.3e} m/s (a drive acting as a load)",
            -e.param
        ),
        EffectKind::CurrentLimit => format!("force clipped near {:.1} N", e.param),
        EffectKind::Compliance => format!("resonance near {:.3} Hz", e.param),
        EffectKind::Backlash if e.param2 < 0.0 => format!(
            "play of {:.3e} m after reversals, its flank a spring (contact mode {:.1} Hz)",
            e.param, -e.param2
        ),
        EffectKind::Backlash if e.param2 > 0.0 => format!(
            "play of {:.3e} m after reversals, its contact rebounding (restitution {:.2})",
            e.param, e.param2
        ),
        EffectKind::Backlash => format!("play of {:.3e} m after reversals", e.param),
        EffectKind::PreslidingHysteresis => format!(
            "friction builds up over {:.3e} m after reversals (Dahl)",
            e.param
        ),
        _ => String::new(),
    }
}
