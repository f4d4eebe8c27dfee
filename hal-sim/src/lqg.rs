//! Host-side design of the two-way optimal harvesting controller (LQG / H2) and the linear
//! analysis used by the studies and the tests.
//!
//! Model (states `s = [x, ẋ, x_f, ẋ_f]`): a TMD of mass `m` (reflected rotor mass added:
//! `m̄ = m + J/l²`), stiffness `k`, viscous damping `c`, on a base whose acceleration `a_g` is
//! Kanai–Tajimi filtered white noise:
//!
//! `m̄·ẍ + c·ẋ + k·x = −m·a_g + β·i_q`, `β = 3/2·K_e/l`,
//! `ẍ_f + 2ζ_g·ω_g·ẋ_f + ω_g²·x_f = −w`, `a_g = −(2ζ_g·ω_g·ẋ_f + ω_g²·x_f)`,
//! `E[w(t)·w(t+τ)] = q_w·δ(τ)`.
//!
//! The harvested power (at the drive's DC side, less conduction loss `R_on`) is
//! `P = −3/2·(K_e/l)·ẋ·i_q − 3/2·(R + R_on)·i_q²`; the design minimises `E[−P]`, a linear-
//! quadratic cost with a cross term and an indefinite state weight (Scruggs' harvesting
//! problem). The Riccati equations are solved by Newton–Kleinman iteration started from the
//! zero gain (the open-loop TMD is stable), each Lyapunov equation by its Kronecker form. The
//! Kalman filter uses measurements `y = [x, ω_m = ẋ/l]` with white noise of stated intensities.
//! The controller handed to the firmware is the observer `ŝ' = (A − LC)ŝ + B·i_applied + L·y`,
//! `i_q* = −K·ŝ`, discretised exactly (zero-order hold) at the law period.

use nalgebra::{DMatrix, DVector};
use regen_fw::laws::lti::{LtiParams, M, N};

/// The linear TMD + transducer + excitation model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinModel {
    /// TMD mass, kg.
    pub m: f64,
    /// Stiffness, N/m.
    pub k: f64,
    /// Viscous damping (screw friction p2), N·s/m.
    pub c: f64,
    /// Rotor + screw inertia, kg·m².
    pub j: f64,
    /// Lead, m/rad.
    pub lead: f64,
    /// Back-emf constant (per-phase peak), V·s/rad.
    pub ke: f64,
    /// Phase resistance, Ω.
    pub r: f64,
    /// Kanai–Tajimi filter frequency, rad/s.
    pub omega_g: f64,
    /// Kanai–Tajimi filter damping.
    pub zeta_g: f64,
    /// White-noise intensity `q_w`, m²/s³.
    pub q_w: f64,
}

impl LinModel {
    /// The reference device on the design-case TMD (400 kg, 2 s period, p2 = 655 N·s/m),
    /// broadband base excitation centred near the TMD frequency.
    pub fn reference() -> LinModel {
        let m = 400.0;
        LinModel {
            m,
            k: m * std::f64::consts::PI.powi(2),
            c: 655.0,
            j: 1.5e-4,
            lead: 0.016 / std::f64::consts::TAU,
            ke: regen_fw::Config::default().ke_v_s_per_rad as f64,
            r: 2.41,
            omega_g: std::f64::consts::PI,
            zeta_g: 0.6,
            q_w: 0.1,
        }
    }

    /// `m + J/l²`.
    pub fn m_bar(&self) -> f64 {
        self.m + self.j / (self.lead * self.lead)
    }

    /// Force per ampere of q current, `3/2·K_e/l`.
    pub fn beta(&self) -> f64 {
        1.5 * self.ke / self.lead
    }

    /// State matrix A (4×4).
    pub fn a(&self) -> DMatrix<f64> {
        let mb = self.m_bar();
        let (wg, zg) = (self.omega_g, self.zeta_g);
        DMatrix::from_row_slice(
            4,
            4,
            &[
                0.0,
                1.0,
                0.0,
                0.0,
                -self.k / mb,
                -self.c / mb,
                self.m * wg * wg / mb,
                self.m * 2.0 * zg * wg / mb,
                0.0,
                0.0,
                0.0,
                1.0,
                0.0,
                0.0,
                -wg * wg,
                -2.0 * zg * wg,
            ],
        )
    }

    /// Input column B (per ampere).
    pub fn b(&self) -> DMatrix<f64> {
        DMatrix::from_column_slice(4, 1, &[0.0, self.beta() / self.m_bar(), 0.0, 0.0])
    }

    /// Noise column G.
    pub fn g(&self) -> DMatrix<f64> {
        DMatrix::from_column_slice(4, 1, &[0.0, 0.0, 0.0, -1.0])
    }

    /// Measurement matrix for `y = [x, ω_m]`.
    pub fn c_meas(&self) -> DMatrix<f64> {
        DMatrix::from_row_slice(2, 4, &[1.0, 0.0, 0.0, 0.0, 0.0, 1.0 / self.lead, 0.0, 0.0])
    }

    /// Stationary mean terminal power (W, less conduction loss `r_on`) and mean i_q² for the
    /// linear feedback `i_q = −K·s` (full state).
    pub fn power_state_feedback(&self, kgain: &DMatrix<f64>, r_on: f64) -> Option<(f64, f64)> {
        let f = self.a() - self.b() * kgain;
        let x = lyap(&f, &(self.g() * self.g().transpose() * self.q_w))?;
        let ci = -kgain.clone();
        let mut cv = DMatrix::zeros(1, 4);
        cv[(0, 1)] = 1.0;
        let e_vi = (&cv * &x * ci.transpose())[(0, 0)];
        let e_ii = (&ci * &x * ci.transpose())[(0, 0)];
        Some((
            -1.5 * self.ke / self.lead * e_vi - 1.5 * (self.r + r_on) * e_ii,
            e_ii,
        ))
    }

    /// Stationary mean power of the emulated resistor `R_L` (analytic, Lyapunov).
    pub fn power_resistor(&self, r_load: f64, r_on: f64) -> f64 {
        let mut k = DMatrix::zeros(1, 4);
        k[(0, 1)] = self.ke / self.lead / (self.r + r_load);
        self.power_state_feedback(&k, r_on)
            .map(|p| p.0)
            .unwrap_or(f64::NAN)
    }

    /// Best fixed resistor (golden-section search on ln R_L over 0.1 Ω … 100 kΩ).
    pub fn best_resistor(&self, r_on: f64) -> (f64, f64) {
        let f = |lr: f64| self.power_resistor(lr.exp(), r_on);
        let (mut a, mut b) = (0.1f64.ln(), 1.0e5f64.ln());
        let gr = (5.0f64.sqrt() - 1.0) / 2.0;
        for _ in 0..80 {
            let c = b - gr * (b - a);
            let d = a + gr * (b - a);
            if f(c) > f(d) {
                b = d;
            } else {
                a = c;
            }
        }
        let r = ((a + b) / 2.0).exp();
        (r, self.power_resistor(r, 0.0))
    }
}

/// Solve `F·X + X·Fᵀ + Q = 0` (F stable) by the Kronecker form.
pub fn lyap(f: &DMatrix<f64>, q: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let n = f.nrows();
    let id = DMatrix::<f64>::identity(n, n);
    let big = id.kronecker(f) + f.kronecker(&id);
    let rhs = DVector::from_iterator(n * n, q.iter().map(|v| -v));
    let sol = big.lu().solve(&rhs)?;
    let x = DMatrix::from_column_slice(n, n, sol.as_slice());
    Some((&x + x.transpose()) * 0.5)
}

/// Continuous algebraic Riccati equation with cross term:
/// `AᵀP + PA − (PB + N)R⁻¹(BᵀP + Nᵀ) + Q = 0`, solved by Newton–Kleinman from the
/// stabilising gain `k0`. Returns `(P, K)` with `K = R⁻¹(BᵀP + Nᵀ)`.
pub fn care(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    nx: &DMatrix<f64>,
    k0: &DMatrix<f64>,
) -> Result<(DMatrix<f64>, DMatrix<f64>), String> {
    let rinv = r
        .clone()
        .try_inverse()
        .ok_or("input weight not invertible")?;
    let mut k = k0.clone();
    for it in 0..100 {
        let acl = a - b * &k;
        if !stable(&acl) {
            return Err(format!("Newton iterate {it} not stabilising"));
        }
        let qk = q - nx * &k - k.transpose() * nx.transpose() + k.transpose() * r * &k;
        // Aclᵀ P + P Acl + Qk = 0  ⇔ lyap(Aclᵀ, Qk)
        let p = lyap(&acl.transpose(), &qk).ok_or("Lyapunov solve failed")?;
        let kn = &rinv * (b.transpose() * &p + nx.transpose());
        let dk = (&kn - &k).norm() / kn.norm().max(1e-300);
        k = kn;
        if dk < 1e-12 {
            let acl = a - b * &k;
            if !stable(&acl) {
                return Err("converged gain not stabilising".into());
            }
            return Ok((p, k));
        }
    }
    Err("Newton–Kleinman did not converge".into())
}

/// All eigenvalues in the open left half plane.
pub fn stable(a: &DMatrix<f64>) -> bool {
    a.clone().complex_eigenvalues().iter().all(|l| l.re < 0.0)
}

/// Design choices of the LQG controller.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LqgSpec {
    pub model: LinModel,
    /// Conduction resistance of the drive, Ω (weighted like the machine's R).
    pub r_on: f64,
    /// Measurement noise intensity of x, m²·s.
    pub v_x: f64,
    /// Measurement noise intensity of ω_m, (rad/s)²·s.
    pub v_w: f64,
    /// Law period, s.
    pub ts: f64,
}

impl LqgSpec {
    /// Defaults for the reference model at a 1 kHz law rate.
    pub fn reference() -> LqgSpec {
        LqgSpec {
            model: LinModel::reference(),
            r_on: 0.0,
            v_x: 1e-8,
            v_w: 1e-4,
            ts: 1e-3,
        }
    }
}

/// A finished design.
#[derive(Clone, Debug)]
pub struct LqgDesign {
    /// State-feedback gain, A per state unit.
    pub k: DMatrix<f64>,
    /// Observer gain (4×2).
    pub l: DMatrix<f64>,
    /// Optimal mean power with full state feedback, W.
    pub p_full_state: f64,
    /// Mean power with the continuous observer in the loop (no measurement noise), W.
    pub p_lqg: f64,
    /// The discrete controller for the firmware.
    pub params: LtiParams,
}

/// Design the two-way optimal controller.
pub fn design(spec: &LqgSpec) -> Result<LqgDesign, String> {
    let m = &spec.model;
    let (a, b, g, c) = (m.a(), m.b(), m.g(), m.c_meas());
    let n = 4;
    let rr = DMatrix::from_element(1, 1, 1.5 * (m.r + spec.r_on));
    let mut nx = DMatrix::zeros(n, 1);
    nx[(1, 0)] = 0.75 * m.ke / m.lead;
    let q = DMatrix::zeros(n, n);
    let (_p, k) = care(&a, &b, &q, &rr, &nx, &DMatrix::zeros(1, n))?;
    // Kalman filter by duality.
    let v = DMatrix::from_row_slice(2, 2, &[spec.v_x, 0.0, 0.0, spec.v_w]);
    let w = &g * g.transpose() * m.q_w;
    let (_s, lt) = care(
        &a.transpose(),
        &c.transpose(),
        &w,
        &v,
        &DMatrix::zeros(n, 2),
        &DMatrix::zeros(2, n),
    )?;
    let l = lt.transpose();
    let p_full_state = m
        .power_state_feedback(&k, spec.r_on)
        .ok_or("closed loop not solvable")?
        .0;
    // Observer in the loop (continuous), 8 states.
    let mut f = DMatrix::zeros(2 * n, 2 * n);
    f.view_mut((0, 0), (n, n)).copy_from(&a);
    f.view_mut((0, n), (n, n)).copy_from(&(-&b * &k));
    f.view_mut((n, 0), (n, n)).copy_from(&(&l * &c));
    f.view_mut((n, n), (n, n))
        .copy_from(&(&a - &b * &k - &l * &c));
    let mut h = DMatrix::zeros(2 * n, 1);
    h.view_mut((0, 0), (n, 1)).copy_from(&g);
    let x = lyap(&f, &(&h * h.transpose() * m.q_w)).ok_or("LQG loop unstable")?;
    let mut ci = DMatrix::zeros(1, 2 * n);
    ci.view_mut((0, n), (1, n)).copy_from(&(-&k));
    let mut cv = DMatrix::zeros(1, 2 * n);
    cv[(0, 1)] = 1.0;
    let p_lqg = -1.5 * m.ke / m.lead * (&cv * &x * ci.transpose())[(0, 0)]
        - 1.5 * (m.r + spec.r_on) * (&ci * &x * ci.transpose())[(0, 0)];
    // Discretise the observer: inputs [x, ω, i_applied].
    let ao = &a - &l * &c;
    let mut bin = DMatrix::zeros(n, M);
    bin.view_mut((0, 0), (n, 2)).copy_from(&l);
    bin.view_mut((0, 2), (n, 1)).copy_from(&b);
    let (phi, gam) = zoh(&ao, &bin, spec.ts);
    let mut params = LtiParams::default();
    for i in 0..n {
        for j in 0..n {
            params.a[i * N + j] = phi[(i, j)] as f32;
        }
        for j in 0..M {
            params.b[i * M + j] = gam[(i, j)] as f32;
        }
        params.c[i] = -k[(0, i)] as f32;
    }
    if !params.is_valid() {
        return Err("design has coefficients beyond the firmware's range".into());
    }
    Ok(LqgDesign {
        k,
        l,
        p_full_state,
        p_lqg,
        params,
    })
}

/// Exact zero-order-hold discretisation `(e^{AT}, ∫₀ᵀ e^{As} ds·B)` by the matrix exponential
/// of the augmented matrix (scaling and squaring with a 16-term Taylor series).
pub fn zoh(a: &DMatrix<f64>, b: &DMatrix<f64>, t: f64) -> (DMatrix<f64>, DMatrix<f64>) {
    let (n, m) = (a.nrows(), b.ncols());
    let mut z = DMatrix::zeros(n + m, n + m);
    z.view_mut((0, 0), (n, n)).copy_from(&(a * t));
    z.view_mut((0, n), (n, m)).copy_from(&(b * t));
    let e = expm(&z);
    (
        e.view((0, 0), (n, n)).into_owned(),
        e.view((0, n), (n, m)).into_owned(),
    )
}

/// Matrix exponential (scaling and squaring, Taylor).
pub fn expm(z: &DMatrix<f64>) -> DMatrix<f64> {
    let norm = z.iter().map(|v| v.abs()).fold(0.0, f64::max) * z.nrows() as f64;
    let mut s = 0;
    while norm / 2f64.powi(s) > 0.5 {
        s += 1;
    }
    let zs = z / 2f64.powi(s);
    let n = z.nrows();
    let mut term = DMatrix::<f64>::identity(n, n);
    let mut sum = term.clone();
    for k in 1..=16 {
        term = &term * &zs / k as f64;
        sum += &term;
    }
    for _ in 0..s {
        sum = &sum * &sum;
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lyapunov_and_riccati_residuals_vanish() {
        let spec = LqgSpec::reference();
        let m = spec.model;
        let d = design(&spec).unwrap();
        // Riccati residual with the returned gain.
        let (a, b) = (m.a(), m.b());
        let rr = DMatrix::from_element(1, 1, 1.5 * m.r);
        let mut nx = DMatrix::zeros(4, 1);
        nx[(1, 0)] = 0.75 * m.ke / m.lead;
        let (p, k) = care(
            &a,
            &b,
            &DMatrix::zeros(4, 4),
            &rr,
            &nx,
            &DMatrix::zeros(1, 4),
        )
        .unwrap();
        let res = a.transpose() * &p + &p * &a
            - (&p * &b + &nx)
                * rr.clone().try_inverse().unwrap()
                * (b.transpose() * &p + nx.transpose());
        assert!(
            res.norm() < 1e-6 * p.norm().max(1.0),
            "residual {}",
            res.norm()
        );
        assert!((&k - &d.k).norm() < 1e-9 * k.norm());
        // LQG optimum cannot beat the full-state optimum, and both beat the best resistor (a
        // resistor is one particular full-state gain).
        let (_, p_r) = m.best_resistor(0.0);
        assert!(
            d.p_full_state >= p_r * (1.0 - 1e-9),
            "{} vs {p_r}",
            d.p_full_state
        );
        assert!(d.p_lqg <= d.p_full_state * (1.0 + 1e-6));
        eprintln!(
            "best R {:?} full {} lqg {} K {} L {}",
            m.best_resistor(0.0),
            d.p_full_state,
            d.p_lqg,
            d.k,
            d.l
        );
    }

    #[test]
    fn zoh_of_integrator_chain() {
        let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 0.0, 0.0]);
        let b = DMatrix::from_column_slice(2, 1, &[0.0, 1.0]);
        let (phi, gam) = zoh(&a, &b, 0.5);
        assert!((phi[(0, 1)] - 0.5).abs() < 1e-14);
        assert!((gam[(0, 0)] - 0.125).abs() < 1e-14 && (gam[(1, 0)] - 0.5).abs() < 1e-14);
    }
}
