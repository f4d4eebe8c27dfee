//! Closed-form models: the sizing indices (eq. 6–12) and the harmonic-balance TMD power with
//! Coulomb friction (eq. 14–23, without the stray π of eq. 22–23).

use crate::plant::{Machine, Screw, Structure};
use std::f64::consts::PI;

/// How the electrical damping is computed from K_e.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DampingFormula {
    /// The paper's `c = 9·K_e²/(4·l²·(R+R_L))` (eq. 6, 16).
    Paper,
    /// What three wye-connected phases with per-phase PEAK back-emf constant K_e dissipate:
    /// `c = 3·K_e²/(2·l²·(R+R_L))` (the simulator's model).
    PerPhasePeak,
}

impl DampingFormula {
    /// Electrical damping for a total circuit resistance `r_total` (Ω), N·s/m.
    pub fn damping(self, ke: f64, lead: f64, r_total: f64) -> f64 {
        let k = match self {
            DampingFormula::Paper => 9.0 / 4.0,
            DampingFormula::PerPhasePeak => 1.5,
        };
        k * ke * ke / (lead * lead * r_total)
    }
}

/// Design case of the sizing indices.
#[derive(Clone, Copy, Debug)]
pub struct DesignCase {
    pub mass_kg: f64,
    pub period_s: f64,
    /// Base acceleration, m/s².
    pub a0_m_s2: f64,
    /// Design velocity ẋ0, m/s.
    pub velocity_m_s: f64,
    /// Diode drop, V.
    pub v_diode: f64,
    /// Rated torque, N·m, and screw force rating, N.
    pub torque_rated_nm: f64,
    pub screw_rated_n: f64,
}

impl Default for DesignCase {
    fn default() -> Self {
        DesignCase {
            mass_kg: 400.0,
            period_s: 2.0,
            a0_m_s2: 0.5 * 9.81,
            velocity_m_s: 0.165,
            v_diode: 1.4,
            torque_rated_nm: 2.74,
            screw_rated_n: f64::INFINITY,
        }
    }
}

/// Sizing indices.
#[derive(Clone, Copy, Debug)]
pub struct Sizing {
    pub c_short: f64,
    pub f_rat: f64,
    pub i_c: f64,
    pub i_f: f64,
    pub i_v: f64,
    pub i_m: f64,
}

/// Sizing indices (eq. 6–12) with the chosen damping formula and K_e value `ke`.
pub fn sizing(ke: f64, m: &Machine, s: &Screw, d: &DesignCase, formula: DampingFormula) -> Sizing {
    let l = s.lead_m_per_rad;
    let c_short = formula.damping(ke, l, m.r_ohm);
    let k = d.mass_kg * (2.0 * PI / d.period_s).powi(2);
    let f_rat = d.screw_rated_n.min(d.torque_rated_nm / l);
    Sizing {
        c_short,
        f_rat,
        i_c: c_short / (2.0 * (k * d.mass_kg).sqrt()),
        i_f: f_rat / (d.mass_kg * d.a0_m_s2),
        i_v: 3.0 * ke * d.velocity_m_s / (2.0 * d.v_diode * l),
        i_m: d.mass_kg * l * l / s.j_kg_m2,
    }
}

/// Steady-state harmonic-balance answer for the TMD with an emulated resistor.
#[derive(Clone, Copy, Debug)]
pub struct TmdPower {
    pub r_load: f64,
    /// Electrical damping c_e, N·s/m.
    pub c_e: f64,
    /// Velocity amplitude Ẋ, m/s.
    pub velocity_amp: f64,
    /// Average power in the load resistors, W.
    pub p_load: f64,
    /// Average power converted by the machine (load + copper), W.
    pub p_elec: f64,
}

/// TMD `m̄ẍ + c̄ẋ + kx + F_c·sgn ẋ = m·a0·sin ω0 t` (eq. 14), `m̄ = m + J/l²`,
/// `c̄ = c + B/l² + c_e`, Coulomb friction by its equivalent damping `4F_c/(πẊ)` (eq. 17–20):
/// `(K² + c̄²)Ẋ² + 2c̄(4F_c/π)Ẋ + (4F_c/π)² − (m·a0)² = 0` with `K = (k − m̄ω²)/ω`, positive
/// root (zero when friction holds the mass). Load power `c_e·Ẋ²/2 · R_L/(R+R_L)` (W).
pub fn tmd_power(
    r_load: f64,
    machine: &Machine,
    screw: &Screw,
    st: &Structure,
    a0: f64,
    freq_hz: f64,
    formula: DampingFormula,
) -> TmdPower {
    let l = screw.lead_m_per_rad;
    let w = 2.0 * PI * freq_hz;
    let r_tot = machine.r_ohm + r_load;
    let c_e = if r_load.is_finite() {
        formula.damping(machine.ke_v_s_per_rad, l, r_tot)
    } else {
        0.0
    };
    let mbar = st.mass_kg + screw.reflected_mass();
    let cbar = st.damping_n_s_per_m + screw.viscous_n_s_per_m + screw.reflected_viscosity() + c_e;
    let kk = (st.stiffness_n_per_m - mbar * w * w) / w;
    let fc = 4.0 * screw.coulomb_n / PI;
    let f0 = st.mass_kg * a0;
    let qa = kk * kk + cbar * cbar;
    let qb = 2.0 * cbar * fc;
    let qc = fc * fc - f0 * f0;
    let disc = (qb * qb - 4.0 * qa * qc).max(0.0);
    let vel = ((-qb + disc.sqrt()) / (2.0 * qa)).max(0.0);
    let p_elec = 0.5 * c_e * vel * vel;
    TmdPower {
        r_load,
        c_e,
        velocity_amp: vel,
        p_load: if r_load.is_finite() {
            p_elec * r_load / r_tot
        } else {
            0.0
        },
        p_elec,
    }
}

/// Load giving the largest analytic power, by golden-section search on log R_L in [lo, hi].
pub fn optimum_load(mut f: impl FnMut(f64) -> f64, lo: f64, hi: f64) -> f64 {
    let (mut a, mut b) = (lo.ln(), hi.ln());
    let gr = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..100 {
        let c = b - gr * (b - a);
        let d = a + gr * (b - a);
        if f(c.exp()) > f(d.exp()) {
            b = d;
        } else {
            a = c;
        }
    }
    ((a + b) / 2.0).exp()
}

/// Log-spaced values from `lo` to `hi`, `n` of them.
pub fn logspace(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| (lo.ln() + (hi.ln() - lo.ln()) * k as f64 / (n.max(2) - 1) as f64).exp())
        .collect()
}
