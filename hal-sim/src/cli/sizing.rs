//! `regen sizing`: the device sizing indices (eq. 6–12), with the paper's 9/4 formula and
//! with the physically consistent 3/2 one.

use crate::analytic::{sizing, DampingFormula, DesignCase};
use crate::plant::{Machine, Screw};

#[derive(clap::Args, Debug)]
pub struct SizingArgs {
    /// K_e as the paper gives it (its "0.77"), V·s/rad.
    #[arg(long, default_value_t = 0.77, allow_negative_numbers = true)]
    pub ke_paper: f64,
}

pub fn run(a: &SizingArgs) -> Result<(), String> {
    if !(a.ke_paper > 0.0 && a.ke_paper <= 100.0) {
        return Err(format!(
            "--ke-paper = {}: must be a finite number in (0, 100] V·s/rad",
            a.ke_paper
        ));
    }
    let m = Machine::default();
    let s = Screw::default();
    let d = DesignCase::default();
    let p = sizing(a.ke_paper, &m, &s, &d, DampingFormula::Paper);
    println!("Reference device, design case m = 400 kg, T = 2 s, 0.5 g, ẋ0 = 0.165 m/s");
    println!("paper formula (9/4, K_e = {}):", a.ke_paper);
    println!(
        "  c_short = {:.0} N·s/m  f_rat = {:.0} N  I_c = {:.1}  I_f = {:.3}  I_v = {:.1}  I_m = {:.1}",
        p.c_short, p.f_rat, p.i_c, p.i_f, p.i_v, p.i_m
    );
    let c = sizing(m.ke_v_s_per_rad, &m, &s, &d, DampingFormula::PerPhasePeak);
    println!(
        "consistent (3/2, per-phase peak K_e = {:.4} V·s/rad, the simulator's):",
        m.ke_v_s_per_rad
    );
    println!(
        "  c_short = {:.0} N·s/m  f_rat = {:.0} N  I_c = {:.1}  I_f = {:.3}  I_v = {:.1}  I_m = {:.1}",
        c.c_short, c.f_rat, c.i_c, c.i_f, c.i_v, c.i_m
    );
    Ok(())
}
