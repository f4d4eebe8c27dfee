//! Evidence that tells a finding from another force that explains the same residual: the
//! in-band test, a ripple locked to the reversals, a hum.

use super::*;

/// True when `wavelength` lies within 3 % of the wavelength of the periodic effect `c`.
pub fn at_wavelength(wavelength: f64, c: &Effect) -> bool {
    c.kind
        .spatial_wavelength(c)
        .is_some_and(|lc| (wavelength / lc - 1.0).abs() < 0.03)
}

/// The samples (true) at which a position ripple of wavelength `lambda` lies well inside the
/// band where the derived acceleration follows the motion: its time frequency |v|/λ at most
/// half the derivative filter's cutoff (the forward-backward Butterworth-2 passes 1/(1 + (f/fc)⁴):
/// at most 6 % lost). Above it the record's inertial force M·a is not measured, and a ripple of
/// the motion locked to position leaves M·(a − a_derived) in the residual at that wavelength.
/// `None` when the acceleration is measured (no derivative cutoff in the metadata).
pub fn ripple_in_band(ctx: &Context, lambda: f64) -> Option<Vec<bool>> {
    let fc = *ctx.rec.meta.get(crate::record::DERIVATIVE_CUTOFF_KEY)?;
    Some(
        ctx.rec
            .v
            .iter()
            .map(|v| v.abs() <= 0.5 * fc * lambda)
            .collect(),
    )
}

/// The samples (true) at which a friction building up over the speed `v_b` changes slowly
/// enough for the derived signals to follow it: the column (1 − e^(−|v|/v_b))·sgn v changes at
/// the rate e^(−|v|/v_b)·|a|/v_b (per unit of its swing), at most π·fc, the rate of a unit
/// ripple at half the derivative filter's cutoff (`ripple_in_band`'s band). Where the motion
/// passes below v_b faster (a stop or near-stop within a few derivative filter time constants)
/// the column is a transient in time at the stop, where the record's inertial force and any
/// other effect's transient (a play's gap, a delayed Coulomb switch) are not measured either.
/// Where the build-up is complete (|v| ≫ v_b) the column is constant and in band. `None` when
/// the acceleration is measured (no derivative cutoff in the metadata).
pub fn buildup_in_band(ctx: &Context, v_b: f64) -> Option<Vec<bool>> {
    let fc = *ctx.rec.meta.get(crate::record::DERIVATIVE_CUTOFF_KEY)?;
    let iv = 1.0 / v_b;
    Some(
        ctx.rec
            .v
            .iter()
            .zip(&ctx.rec.a)
            .map(|(v, a)| (-(v.abs() * iv)).exp() * a.abs() * iv <= std::f64::consts::PI * fc)
            .collect(),
    )
}

/// The samples (true) at which the baseline's prediction f̂₀ (`base_pred`, whose inertial
/// part M·a is the derived acceleration's) changes slowly enough for the derived signals to
/// follow it: its rate |df̂₀/dt| (central differences) at most π·fc times its peak |f̂₀| over
/// the samples in motion, the rate of a ripple of that amplitude at half the derivative
/// filter's cutoff (`ripple_in_band`'s band). Where f̂₀ changes faster (the motion's turns,
/// the Coulomb switch at a reversal) the derived acceleration loses the inertial force
/// (1/(1 + (f/fc)⁴)) and the force the record measures there is not the one the baseline's
/// columns carry; a column built from f̂₀ (a scaled or differentiated prediction) there
/// fits that loss (the in-band test of a column differentiated from f̂₀). `None` when the
/// acceleration is measured (no derivative cutoff in the metadata) or no sample is in
/// motion.
pub fn prediction_in_band(ctx: &Context) -> Option<Vec<bool>> {
    let fc = *ctx.rec.meta.get(crate::record::DERIVATIVE_CUTOFF_KEY)?;
    let p = &ctx.base_pred;
    let n = p.len();
    let peak = p
        .iter()
        .zip(&ctx.rest)
        .filter(|(_, r)| !**r)
        .fold(0.0f64, |m, (f, _)| m.max(f.abs()));
    if n < 3 || peak <= 0.0 || !peak.is_finite() {
        return None;
    }
    // the largest change per sample: π·fc·peak·dt
    let lim = std::f64::consts::PI * fc * peak * ctx.dt;
    Some(
        (0..n)
            .map(|i| {
                let (lo, hi) = (i.saturating_sub(1), (i + 1).min(n - 1));
                (p[hi] - p[lo]).abs() <= lim * (hi - lo) as f64
            })
            .collect(),
    )
}

/// The design's columns without the finding's span `a..b` (the model the finding is tested
/// beside).
pub(crate) fn refs_without(cols: &[(String, Vec<f64>)], (a, b): (usize, usize)) -> Vec<&[f64]> {
    cols.iter()
        .enumerate()
        .filter(|(j, _)| *j < a || *j >= b)
        .map(|(_, c)| c.1.as_slice())
        .collect()
}

/// A periodic finding's ripple on the samples where it lies inside the acceleration's band
/// (`ripple_in_band`): the model (`cols`, the finding's columns at `span`) refitted on the
/// samples in motion with the finding's columns split into their in-band and out-of-band
/// parts. Returns the Wald statistic of the in-band pair (the rise of the rss when it is
/// removed over the residual variance: χ² with 2 degrees of freedom when it carries nothing)
/// and the in-band and out-of-band amplitudes, and the Wald statistic of their difference
/// (the rise of the rss when both parts are one column again: χ² with 2 degrees of freedom
/// when the ripple has one amplitude and phase at every speed; 0 when no sample lies above
/// the band).
pub fn in_band_ripple(
    ctx: &Context,
    cols: &[(String, Vec<f64>)],
    span: (usize, usize),
    in_band: &[bool],
) -> RippleInBand {
    let (a, b) = span;
    let split = |inside: bool| -> Vec<Vec<f64>> {
        cols[a..b]
            .iter()
            .map(|(_, c)| {
                c.iter()
                    .zip(in_band)
                    .map(|(v, &ib)| if ib == inside { *v } else { 0.0 })
                    .collect()
            })
            .collect()
    };
    let (cin, cout) = (split(true), split(false));
    let mut refs = refs_without(cols, (a, b));
    let m0 = refs.len();
    refs.extend(cout.iter().map(|c| c.as_slice()));
    refs.extend(cin.iter().map(|c| c.as_slice()));
    let part: Vec<u8> = ctx
        .rest
        .iter()
        .map(|&r| if r { crate::AT_REST } else { crate::TRAIN })
        .collect();
    let (tr, _) = crate::normals(&refs, &ctx.rec.f, &part, 1);
    let th = tr.solve();
    let rss = tr.rss(&th);
    let k = b - a;
    let keep: Vec<usize> = (0..m0 + k).collect();
    let t2 = tr.select(&keep);
    let rss_without = t2.rss(&t2.solve());
    let dof = tr.n.saturating_sub(refs.len()).max(1) as f64;
    let var = (rss / dof).max(f64::MIN_POSITIVE);
    let wald = (rss_without - rss) / var;
    // the two parts merged again (column out_j + in_j): G' = Tᵀ·G·T, b' = Tᵀ·b
    let m = m0 + 2 * k;
    let src = |r: usize| -> Vec<usize> {
        if r < m0 {
            vec![r]
        } else {
            vec![r, r + k]
        }
    };
    let mut merged = tr.select(&(0..m0 + k).collect::<Vec<_>>());
    for r in 0..m0 + k {
        merged.b[r] = src(r).iter().map(|&i| tr.b[i]).sum();
        for c in 0..m0 + k {
            merged.g[r * (m0 + k) + c] = src(r)
                .iter()
                .flat_map(|&i| src(c).into_iter().map(move |j| (i, j)))
                .map(|(i, j)| tr.g[i * m + j])
                .sum();
        }
    }
    let above = cout.iter().any(|c| c.iter().any(|v| *v != 0.0));
    let wald_diff = if above {
        (merged.rss(&merged.solve()) - rss) / var
    } else {
        0.0
    };
    let amp = |s: &[f64]| s.iter().map(|c| c * c).sum::<f64>().sqrt();
    let (ain, aout) = (&th[m0 + k..], &th[m0..m0 + k]);
    let diff: Vec<f64> = ain.iter().zip(aout).map(|(a, b)| a - b).collect();
    RippleInBand {
        wald,
        amp_in: amp(ain),
        amp_above: amp(aout),
        wald_diff,
        rel_diff: amp(&diff) / amp(ain).max(amp(aout)).max(f64::MIN_POSITIVE),
    }
}

/// `in_band_ripple`'s evidence.
#[derive(Debug, Clone, Copy, Default)]
pub struct RippleInBand {
    /// Wald statistic of the in-band part (χ², 2 degrees of freedom, when it carries nothing).
    pub wald: f64,
    /// Amplitude of the ripple fitted on the samples inside the band, N.
    pub amp_in: f64,
    /// Amplitude of the ripple fitted on the samples above the band, N (0 when none is).
    pub amp_above: f64,
    /// Wald statistic of the difference between the two (0 when no sample lies above).
    pub wald_diff: f64,
    /// |A_in − A_above| / max(|A_in|, |A_above|), the coefficient vectors (amplitude and phase).
    pub rel_diff: f64,
}

impl RippleInBand {
    /// The ripple is a force locked to position: the samples where the acceleration is measured
    /// carry it (Wald ≥ t²), and where some lie above the band it has the same amplitude and
    /// phase there: a difference both significant (Wald ≥ t²) and larger than 1/t of the
    /// ripple rejects it (t = `AGREEMENT_T`: a coefficient determined to within a third of its
    /// value, as the segments' agreement asks).
    pub fn locked_to_position(&self, t: f64) -> bool {
        self.wald >= t * t && !(self.wald_diff >= t * t && self.rel_diff > 1.0 / t)
    }
}

/// Travel since the last reversal and the direction of motion at each sample: `(u, d)`, d = ±1
/// the sign of the velocity beyond ±v_eps (held through the band), u = |x − x_r|, x_r the
/// position where the motion last turned (the extreme reached in the previous direction; the
/// first sample's position before the first reversal).
pub fn travel_since_reversal(ctx: &Context) -> (Vec<f64>, Vec<f64>) {
    let (x, v) = (&ctx.rec.x, &ctx.rec.v);
    let mut d = v
        .iter()
        .find(|v| v.abs() > ctx.v_eps)
        .map_or(1.0, |v| v.signum());
    let mut x_r = x.first().copied().unwrap_or(0.0);
    let mut ext = x_r;
    let mut u = Vec::with_capacity(x.len());
    let mut dir = Vec::with_capacity(x.len());
    for (&xi, &vi) in x.iter().zip(v) {
        if vi.abs() > ctx.v_eps && vi.signum() != d {
            d = vi.signum();
            x_r = ext;
            ext = xi;
        }
        if (xi - ext) * d > 0.0 {
            ext = xi;
        }
        u.push((xi - x_r).abs());
        dir.push(d);
    }
    (u, dir)
}

/// A periodic finding's ripple against a ripple locked to the last reversal. A force that the
/// reversals excite (a mode's ringing, a friction transient, the inertial force the derived
/// acceleration misses at a reversal) is a function of the travel (or time) since the last
/// reversal whose sign follows the new direction of motion: on a motion that always turns at
/// the same positions (a triangle of one stroke), x = x_r + d·u, so the part of a position
/// ripple sin(2πx/λ + φ) that is odd about the stroke's centre is exactly such a force,
/// d·sin(2πu/λ + φ'), and the record cannot tell the two apart; where the turning points
/// vary they differ. The model (`cols`, the finding's columns at `span`) is refitted on the
/// samples in motion with d·sin(2πu/λ), d·cos(2πu/λ) beside it; returns the Wald statistic of
/// the finding's columns there (the rise of the rss when they are removed over the residual
/// variance: χ² with 2 degrees of freedom when the reversal-locked ripple carries all that
/// the record tells of the position ripple).
pub fn ripple_apart_from_reversals(
    ctx: &Context,
    cols: &[(String, Vec<f64>)],
    span: (usize, usize),
    lambda: f64,
) -> f64 {
    let (u, d) = travel_since_reversal(ctx);
    let k = std::f64::consts::TAU / lambda;
    let (rs, rc): (Vec<f64>, Vec<f64>) = u
        .iter()
        .zip(&d)
        .map(|(u, d)| {
            let (sn, cs) = (k * u).sin_cos();
            (d * sn, d * cs)
        })
        .unzip();
    wald_beside(ctx, cols, span, [&rs, &rc])
}

/// The Wald statistic of a finding's columns (`cols` at `span`) in the model refitted on the
/// samples in motion with the two columns `extra` beside it: the rise of the rss when the
/// finding's columns are removed over the residual variance (χ² with 2 degrees of freedom
/// when `extra` carries all that the record tells of the finding).
pub(crate) fn wald_beside(
    ctx: &Context,
    cols: &[(String, Vec<f64>)],
    span: (usize, usize),
    extra: [&[f64]; 2],
) -> f64 {
    let (a, b) = span;
    let mut refs = refs_without(cols, (a, b));
    refs.extend(extra);
    let m0 = refs.len();
    refs.extend(cols[a..b].iter().map(|c| c.1.as_slice()));
    let part: Vec<u8> = ctx
        .rest
        .iter()
        .map(|&r| if r { crate::AT_REST } else { crate::TRAIN })
        .collect();
    let (tr, _) = crate::normals(&refs, &ctx.rec.f, &part, 1);
    let rss = tr.rss(&tr.solve());
    let t2 = tr.select(&(0..m0).collect::<Vec<_>>());
    let rss_without = t2.rss(&t2.solve());
    let dof = tr.n.saturating_sub(refs.len()).max(1) as f64;
    let var = (rss / dof).max(f64::MIN_POSITIVE);
    (rss_without - rss) / var
}

/// The strongest force at one time frequency in the residual `r` (zero at rest): the highest
/// spectral peak that `report::spectral_peaks` flags `unexplained` (30× the spectrum's
/// median, its amplitude a fifth of the residual's rms), as the report names it. Its
/// frequency is refined on the samples in motion to the least-squares sinusoid's best within
/// one Welch bin of the peak (steps of 1/20 bin, then a golden section within a step: a
/// step's error alone, 0.006 Hz, drifts the phase by 0.07 period over 12 s, and leaves a
/// fifth of a hum correlated with whatever the motion does). None when no such peak stands.
pub fn hum_in_residual(ctx: &Context, r: &[f64]) -> Option<f64> {
    let peak = crate::report::spectral_peaks(r, ctx.dt)
        .into_iter()
        .find(|p| p.unexplained)?;
    let seg = crate::report::welch_segment(r.len());
    let bin = 1.0 / (seg as f64 * ctx.dt);
    let energy = |f: f64| sinusoid_energy(&ctx.rec.t, r, &ctx.rest, ctx.dt, f);
    let step = bin / 20.0;
    let best = (-20..=20)
        .map(|i| peak.freq_hz + step * i as f64)
        .filter(|f| *f > 0.0)
        .map(|f| (f, energy(f)))
        .max_by(|a, b| a.1.total_cmp(&b.1))?
        .0;
    // then the golden section within a step either side (the energy is one lobe there: its
    // main lobe is 1/T_record wide, 4 steps over a 12 s record), one new evaluation a step
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut lo, mut hi) = (best - step, best + step);
    let (mut a, mut b) = (hi - g * (hi - lo), lo + g * (hi - lo));
    let (mut ea, mut eb) = (energy(a), energy(b));
    for _ in 0..30 {
        if ea < eb {
            lo = a;
            (a, ea) = (b, eb);
            b = lo + g * (hi - lo);
            eb = energy(b);
        } else {
            hi = b;
            (b, eb) = (a, ea);
            a = hi - g * (hi - lo);
            ea = energy(a);
        }
    }
    Some(0.5 * (lo + hi))
}

/// Samples between two evaluations of the sinusoid at a sample's own time in
/// `sinusoid_energy` (a rotation by the sampling step in between).
pub(crate) const SINUSOID_ANCHOR: usize = 256;

/// The energy of `r`'s projection on span{sin 2πft, cos 2πft} over the samples in motion,
/// bᵀ·G⁻¹·b. The sinusoid is evaluated at each `SINUSOID_ANCHOR`-th sample's own time and
/// rotated by the mean sampling step `dt` between (the record's times are uniform to their
/// printed digits: a 1 µs rounding is 6·10⁻⁵ rad at 10 Hz, and the rotation's own rounding
/// over 256 steps ≈ 10⁻¹⁴), so that an evaluation over 10⁶ samples costs 4·10³ sine-cosine
/// pairs instead of 10⁶ (`sinusoid_energy_is_the_direct_sum` pins it to the sum with a
/// `sin_cos` per sample).
pub fn sinusoid_energy(t: &[f64], r: &[f64], rest: &[bool], dt: f64, f: f64) -> f64 {
    let w = std::f64::consts::TAU * f;
    let (sd, cd) = (w * dt).sin_cos();
    let (mut ss, mut cc, mut sc, mut rs, mut rc) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let n = t.len().min(r.len()).min(rest.len());
    for start in (0..n).step_by(SINUSOID_ANCHOR) {
        let end = (start + SINUSOID_ANCHOR).min(n);
        let (mut s, mut c) = (w * t[start]).sin_cos();
        for i in start..end {
            if !rest[i] {
                ss += s * s;
                cc += c * c;
                sc += s * c;
                rs += r[i] * s;
                rc += r[i] * c;
            }
            (s, c) = (s * cd + c * sd, c * cd - s * sd);
        }
    }
    let det = ss * cc - sc * sc;
    if det <= 0.0 {
        return 0.0;
    }
    (cc * rs * rs - 2.0 * sc * rs * rc + ss * rc * rc) / det
}

/// A finding of a force of the motion (a friction of the speed, a ripple of the position)
/// against a force at one time frequency `f_hz` (`hum_in_residual`: a hum of the supply, a
/// machine nearby): the Wald statistic of the finding's columns with sin(2πft), cos(2πft)
/// beside them (`wald_beside`). A motion that passes the same speeds or positions at moments
/// spread over the hum's phase decorrelates the two; where the record shows the finding only
/// through the hum (a few moves, the near-stops of a recorded motion), its columns carry
/// nothing beside it.
pub fn finding_apart_from_hum(
    ctx: &Context,
    cols: &[(String, Vec<f64>)],
    span: (usize, usize),
    f_hz: f64,
) -> f64 {
    let w = std::f64::consts::TAU * f_hz;
    let (hs, hc): (Vec<f64>, Vec<f64>) = ctx.rec.t.iter().map(|t| (w * t).sin_cos()).unzip();
    wald_beside(ctx, cols, span, [&hs, &hc])
}

#[cfg(test)]
mod prediction_band_tests {
    use super::*;

    /// A 1 kHz record (the derivative cutoff fs/20 = 50 Hz) of a device on a 0.5 Hz sinusoid
    /// of 20 mm, its force M·a + c·v + Fc·sgn v exact (the position unquantised). Returns the
    /// parsed record (v and a derived).
    fn sine_record(fc_n: f64) -> Record {
        let (fs, n, m, c) = (1000.0, 8000, 30.0, 200.0);
        let mut csv = String::from("t_s,x_m,f_N\n");
        for i in 0..n {
            let t = i as f64 / fs;
            let w = std::f64::consts::TAU * 0.5;
            let (x, v, a) = (
                0.02 * (w * t).sin(),
                0.02 * w * (w * t).cos(),
                -0.02 * w * w * (w * t).sin(),
            );
            let f = m * a + c * v + fc_n * v.signum();
            csv.push_str(&format!("{t},{x:.12e},{f:.12e}\n"));
        }
        crate::record::parse_csv(&csv, None).expect("record parses")
    }

    /// Without a Coulomb switch the prediction of a 0.5 Hz motion changes far inside the
    /// derived signals' band: every sample in motion is in band. With a Coulomb level the
    /// switch at each reversal is a step: the samples out of band are the few around the
    /// reversals (within 10 ms of one: the sign's linear band and the central difference),
    /// and there are some. Breaks: the limit ×10 (π·fc·10) leaves no sample out of band; the
    /// comparison reversed marks every sample in motion out of band; each fails.
    #[test]
    fn prediction_out_of_band_only_at_the_coulomb_switch() {
        let rec = sine_record(0.0);
        let ctx = Context::new(&rec);
        let band = prediction_in_band(&ctx).expect("derived acceleration");
        let moving: Vec<usize> = (0..rec.len()).filter(|&i| !ctx.rest[i]).collect();
        let out = moving.iter().filter(|&&i| !band[i]).count();
        println!(
            "no Coulomb: {out} of {} samples in motion out of band",
            moving.len()
        );
        assert_eq!(out, 0);
        let rec = sine_record(10.0);
        let ctx = Context::new(&rec);
        let band = prediction_in_band(&ctx).expect("derived acceleration");
        let out: Vec<usize> = (20..rec.len() - 20).filter(|&i| !band[i]).collect();
        // reversals of the 0.5 Hz sinusoid at t = 0.5 s + k·1 s
        let far = out
            .iter()
            .filter(|&&i| {
                let t = i as f64 / 1000.0;
                ((t - 0.5) - (t - 0.5).round()).abs() > 0.010
            })
            .count();
        println!(
            "Coulomb 10 N: {} samples out of band, {far} beyond 10 ms of a reversal",
            out.len()
        );
        assert!(!out.is_empty());
        assert_eq!(far, 0);
    }
}
