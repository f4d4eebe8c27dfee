//! Alignment on a moving structure, and its retry.
//!
//! [`EmfProbe`]: the flying alignment, the back-emf read at zero current in the encoder's
//! frame (its angle there is the commutation offset; its travel against the encoder's counts
//! checks the encoder's direction and counts per turn). `Controller` runs it first in `mode
//! align` and hands over to the d-axis steps once it finds the rotor still
//! (docs/protection.md, "Power-up").
//!
//! [`AlignRetry`]: an alignment that ended in `align_moving` (the probe found no window it
//! could read, or the steps found the rotor moving) is cleared and started again after
//! [`ALIGN_RETRY_S`] in its safe state (the short circuit damps the structure meanwhile), up
//! to [`ALIGN_TRIES`] alignments in all; any other fault, or the last try failing, stays
//! latched for the user. One implementation for its callers: the board's supervision task
//! polls it every 10 ms against a copy of the controller, the simulator's boot sequence and
//! its console drive every period; each puts the returned changes in a [`Pending`] that
//! [`crate::period::Period::apply`] applies between two periods (the fault cleared, then
//! `mode align`).

use crate::control::{Boot, Controller, Fault, Mode};
use crate::period::{Pending, Slot};

/// Alignments at most, the first one included.
pub const ALIGN_TRIES: u32 = 5;
/// Seconds in the safe state between an `align_moving` and the next alignment.
pub const ALIGN_RETRY_S: f32 = 0.5;

/// What [`AlignRetry::poll`] found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Retry {
    /// Nothing to do: no alignment failed, or the fault latched is not one to retry (any
    /// other fault, or `align_moving` on the last try): it stays for the user.
    Nothing,
    /// `align_moving` latched; the next alignment starts once the safe state has lasted
    /// [`ALIGN_RETRY_S`].
    Waiting,
    /// Start the next alignment: [`post`] to the period's mailbox.
    Post,
}

/// The retry's state: alignments retried since the last success or the last manual clear,
/// and the period at which the current `align_moving` was first seen.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AlignRetry {
    retries: u32,
    since: Option<u32>,
}

impl AlignRetry {
    pub const NEW: AlignRetry = AlignRetry {
        retries: 0,
        since: None,
    };

    /// Alignments retried so far (the first one not counted).
    pub fn retries(&self) -> u32 {
        self.retries
    }

    /// Look at the controller (or a copy of it) at period count `period` (the period
    /// routine's wrapping counter, `Period::periods`). Call it at least every few periods;
    /// the wait is measured in periods, so a caller polling every 10 ms starts the next
    /// alignment within 10 ms of the [`ALIGN_RETRY_S`] mark.
    pub fn poll(&mut self, ctl: &Controller, period: u32) -> Retry {
        match ctl.fault() {
            Some(Fault::AlignMoving) if self.retries + 1 < ALIGN_TRIES => {
                let since = *self.since.get_or_insert(period);
                let wait = (ALIGN_RETRY_S * ctl.config().pwm_hz) as u32;
                if period.wrapping_sub(since) < wait {
                    return Retry::Waiting;
                }
                self.since = None;
                self.retries += 1;
                Retry::Post
            }
            Some(_) => {
                self.since = None;
                Retry::Nothing
            }
            None => {
                // Aligned, or the user cleared the fault and chose another mode: the next
                // alignment starts a fresh series.
                if ctl.boot() == Boot::Aligned || ctl.mode() != Mode::Align {
                    self.retries = 0;
                }
                self.since = None;
                Retry::Nothing
            }
        }
    }
}

/// What [`Retry::Post`] asks for, put into the changes `Period::apply` applies between two
/// periods (the clear first): clear `align_moving` (if it is still the latched fault), then
/// `mode align`. A configuration already waiting there stays.
pub fn post(mail: &mut Pending) {
    mail.clear = Slot::Full(Fault::AlignMoving);
    mail.mode = Slot::Full(Mode::Align);
}

/// Supervision ticks (ms) the encoder's emf `K_e·|ω|` must stay below `angle_emf_min_v`,
/// the rotor moving no more than the steps' settle allowance meanwhile, before the probe
/// takes the rotor for still and hands over to the d-axis steps (a reversal of a moving
/// structure is slow for longer, but travels).
pub const STILL_TICKS: u32 = 50;
/// Valid ticks after a start or a gap before the probe sums: the zero-current loop (1 kHz)
/// settles from its zero-voltage start within a few time constants (0.16 ms each).
pub const SETTLE_TICKS: u32 = 3;
/// Ticks summed at least, and the emf's electrical travel at least (one electrical turn),
/// before the probe decides.
pub const MIN_TICKS: u32 = 20;
/// The longest the probe may take, ticks (ms): a structure that moves without ever giving a
/// valid window (its emf above the bus's voltage circle) ends the alignment (`align_moving`).
pub const PROBE_TICKS: u32 = 1_500;
/// The encoder's electrical travel over the emf's must lie within ±this of 1: reversed
/// (−1), half or double counts per turn (0.5, 2) and a pole count of 4 for 5 (0.8) fail.
pub const RATIO_TOL: f32 = 0.1;

/// What one tick of the emf probe sees (the last period's record and the encoder).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ProbeIn {
    /// Speed estimate, rad/s (mechanical).
    pub omega_m: f32,
    /// The zero-current loop's output voltage in the probe's frame, V.
    pub v_d: f32,
    pub v_q: f32,
    /// The output was limited by the voltage circle (then it is not the emf).
    pub saturated: bool,
    /// The probe frame's angle: the encoder's, offset 0.
    pub theta_f: u32,
    /// Encoder position, counts.
    pub position: i32,
}

/// What [`EmfProbe::tick`] decided.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Probe {
    /// Keep probing.
    Continue,
    /// The rotor is (nearly) still: the emf is too small to read; use the d-axis steps.
    Still,
    /// The emf's angle in the encoder's frame: the offset to put in force, and the ratio of
    /// the encoder's electrical travel to the emf's over the window.
    Found { offset: u32, ratio: f32 },
    /// The encoder's travel disagrees with the emf's (`encoder_mismatch`).
    Mismatch { ratio: f32 },
    /// No valid window within [`PROBE_TICKS`]: the emf stayed above the bus (too fast to
    /// hold zero current) or the motion too short between reversals.
    Timeout,
}

/// The flying alignment (docs/protection.md, "Power-up"): with the current held at zero in
/// the encoder's own frame (offset 0), the current loop's output voltage *is* the back-emf
/// (`v = e + R·i + L·di/dt`, the last two zero), whatever the rotor's speed below the bus's
/// voltage circle. Its angle in that frame is the commutation offset: `e = K_e·ω·q̂` of the
/// rotor, so `(v_d, v_q)·sgn ω = K_e·|ω|·(−sin Δ, cos Δ)` with `Δ` the rotor's d axis minus
/// the frame's. Its travel in the stationary frame (the frame's angle plus the voltage's)
/// against the encoder's counts checks the encoder's direction and counts per turn.
///
/// Runs in the supervision tick (1 kHz, `f32`, no libm): one tick resolves the emf's
/// rotation unambiguously up to half an electrical turn per ms (ω_m < 628 rad/s for p = 5).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EmfProbe {
    ticks: u32,
    slow: u32,
    still_pos: i32,
    run: u32,
    n: u32,
    sum_d: f32,
    sum_q: f32,
    /// The emf's stationary travel, angle LSB (2^32 a turn), and the encoder's, counts.
    t_emf: i64,
    t_enc: i64,
    last_psi: u32,
    last_pos: i32,
}

impl EmfProbe {
    pub const NEW: EmfProbe = EmfProbe {
        ticks: 0,
        slow: 0,
        still_pos: 0,
        run: 0,
        n: 0,
        sum_d: 0.0,
        sum_q: 0.0,
        t_emf: 0,
        t_enc: 0,
        last_psi: 0,
        last_pos: 0,
    };

    /// Supervision ticks since the probe began.
    pub fn ticks(&self) -> u32 {
        self.ticks
    }

    /// One supervision tick. `ke` V·s/rad, `e_min` V (`angle_emf_min_v`), `e_per_count` the
    /// encoder's electrical angle per count (angle LSB), `still` the counts a still rotor
    /// may move over [`STILL_TICKS`].
    pub fn tick(
        &mut self,
        s: &ProbeIn,
        ke: f32,
        e_min: f32,
        e_per_count: u32,
        still: i32,
    ) -> Probe {
        self.ticks += 1;
        let w_abs = if s.omega_m < 0.0 {
            -s.omega_m
        } else {
            s.omega_m
        };
        let e_enc = ke * w_abs;
        let moved = s.position.wrapping_sub(self.still_pos).unsigned_abs() > still as u32;
        if e_enc >= e_min || self.slow == 0 || moved {
            // A slow streak starts (or none): counted from here.
            self.slow = (e_enc < e_min) as u32;
            self.still_pos = s.position;
        } else {
            self.slow += 1;
        }
        if self.slow >= STILL_TICKS {
            return Probe::Still;
        }
        let v2 = s.v_d * s.v_d + s.v_q * s.v_q;
        let valid = e_enc >= e_min && !s.saturated && v2 >= 0.25 * e_min * e_min;
        if !valid {
            self.restart();
        } else {
            self.run += 1;
            let psi = s.theta_f.wrapping_add(angle_lsb(atan2(s.v_q, s.v_d)));
            if self.run > SETTLE_TICKS + 1 {
                self.t_emf += psi.wrapping_sub(self.last_psi) as i32 as i64;
                self.t_enc += s.position.wrapping_sub(self.last_pos) as i64;
                let sg = if s.omega_m < 0.0 { -1.0 } else { 1.0 };
                self.sum_d += sg * s.v_d;
                self.sum_q += sg * s.v_q;
                self.n += 1;
            }
            self.last_psi = psi;
            self.last_pos = s.position;
        }
        let turn = 1i64 << 32;
        if self.n >= MIN_TICKS && self.t_emf.abs() >= turn {
            // In f32 (the M4F's FPU; f64 would be software on the board).
            let ratio = self.t_enc as f32 * e_per_count as f32 / self.t_emf as f32;
            let r = ratio - 1.0;
            if !(-RATIO_TOL..=RATIO_TOL).contains(&r) {
                return Probe::Mismatch { ratio };
            }
            let offset = angle_lsb(atan2(-self.sum_d, self.sum_q));
            return Probe::Found { offset, ratio };
        }
        if self.ticks >= PROBE_TICKS {
            return Probe::Timeout;
        }
        Probe::Continue
    }

    /// A gap (a reversal, the voltage circle): the window starts again.
    fn restart(&mut self) {
        *self = EmfProbe {
            ticks: self.ticks,
            slow: self.slow,
            still_pos: self.still_pos,
            ..EmfProbe::NEW
        };
    }
}

/// An angle in radians as angle LSB (2^32 a turn, wrapping; f32's 24 bits: within 2^-24 of
/// a turn).
pub fn angle_lsb(rad: f32) -> u32 {
    (rad * (4_294_967_296.0 / core::f32::consts::TAU)) as i64 as u32
}

/// `atan2(y, x)` in radians, (−π, π], with `+ − × ÷` only (no libm: the same bits on the
/// board and the host); within 1e-5 rad of the true value (test below). `(0, 0)` gives 0.
pub fn atan2(y: f32, x: f32) -> f32 {
    use core::f32::consts::{FRAC_PI_2, PI};
    let (ax, ay) = (if x < 0.0 { -x } else { x }, if y < 0.0 { -y } else { y });
    if ax == 0.0 && ay == 0.0 {
        return 0.0;
    }
    // atan on [0, 1] by a minimax polynomial in t = min/max.
    let (t, swap) = if ay > ax {
        (ax / ay, true)
    } else {
        (ay / ax, false)
    };
    let t2 = t * t;
    let p = t
        * (0.999_977_26
            + t2 * (-0.332_623_47
                + t2 * (0.193_543_46
                    + t2 * (-0.116_432_87 + t2 * (0.052_653_32 + t2 * -0.011_721_2)))));
    let a = if swap { FRAC_PI_2 - p } else { p };
    let a = if x < 0.0 { PI - a } else { a };
    if y < 0.0 {
        -a
    } else {
        a
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atan2_within_1e5_rad_over_the_circle() {
        let mut worst = 0f64;
        for k in 0..100_000 {
            let a = (k as f64 / 100_000.0 - 0.5) * core::f64::consts::TAU;
            for r in [1e-3f64, 1.0, 300.0] {
                let (y, x) = ((r * a.sin()) as f32, (r * a.cos()) as f32);
                let got = atan2(y, x) as f64;
                let want = (y as f64).atan2(x as f64);
                let mut d = (got - want).abs();
                if d > core::f64::consts::PI {
                    d = core::f64::consts::TAU - d; // ±π are the same angle
                }
                worst = worst.max(d);
            }
        }
        assert!(worst < 1e-5, "{worst}");
        assert_eq!(atan2(0.0, 0.0), 0.0);
    }

    /// The probe on a synthetic emf: the rotor's d axis at `true_off` + the encoder's angle
    /// scaled by `k` (1: consistent; −1 reversed; 0.5 half the counts), speed `w` rad/s.
    fn run(true_off: f64, w: f64, k: f64) -> Probe {
        let (ke, p, cpr) = (0.943f64, 5.0f64, 10_000.0f64);
        let e_per = (4_294_967_296.0 * p / cpr) as u32;
        let mut pr = EmfProbe::NEW;
        for n in 0..2_000 {
            let t = n as f64 * 1e-3;
            let th_m = 0.3 + w * t; // the rotor, mechanical
            let count = (th_m * cpr / core::f64::consts::TAU * k).floor();
            let theta_f = ((count as i64 as u64).wrapping_mul(e_per as u64)) as u32;
            let th_f = theta_f as f64 / 4_294_967_296.0 * core::f64::consts::TAU;
            let th_t = p * th_m + true_off; // the true d axis
            let e = ke * w; // on the true q axis (−q for w < 0 by the sign of e)
            let d = th_t - th_f;
            let s = ProbeIn {
                omega_m: (w * k) as f32,
                v_d: (-e * d.sin()) as f32,
                v_q: (e * d.cos()) as f32,
                saturated: false,
                theta_f,
                position: count as i32,
            };
            match pr.tick(&s, ke as f32, 5.0, e_per, 62) {
                Probe::Continue => {}
                r => return r,
            }
        }
        Probe::Timeout
    }

    #[test]
    fn probe_finds_the_offset_and_names_an_inconsistent_encoder() {
        for (off, w) in [(0.7, 30.0), (-2.9, -150.0), (3.1, 8.0), (1.0, 180.0)] {
            let Probe::Found { offset, ratio } = run(off, w, 1.0) else {
                panic!("{off} {w}");
            };
            let want = angle_lsb(off as f32);
            let err = offset.wrapping_sub(want) as i32 as f64 * 360.0 / 4_294_967_296.0;
            // One count of the encoder is 0.18° electrical: the frame's quantisation.
            assert!(err.abs() < 0.2, "{off} {w}: {err}°");
            assert!((ratio - 1.0).abs() < 0.01, "{ratio}");
        }
        for k in [-1.0, 0.5, 2.0, 0.8] {
            let r = run(0.4, 60.0, k);
            assert!(matches!(r, Probe::Mismatch { .. }), "{k}: {r:?}");
        }
        assert_eq!(run(0.4, 0.0, 1.0), Probe::Still);
    }
}
