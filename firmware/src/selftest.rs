//! Replay of a recorded input sequence through the controller, folded into a digest.
//!
//! The host and the Cortex-M4 (`firmware/m4check`) run this same function over the same
//! recorded samples; equal digests mean bit-identical outputs at every step.
//!
//! Record format: little-endian `u16` × 5 per step: `i_a, i_b, i_c, v_bus, encoder`.

use crate::control::Controller;
use crate::io::{Actuation, RawSample};

/// Bytes per recorded step.
pub const STEP_BYTES: usize = 10;

/// FNV-1a, 64 bit.
#[derive(Clone, Copy, Debug)]
pub struct Fnv(pub u64);

impl Default for Fnv {
    fn default() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv {
    /// Fold one 32-bit word.
    #[inline]
    pub fn word(&mut self, w: u32) {
        for b in w.to_le_bytes() {
            self.0 ^= b as u64;
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
}

/// Decode step `k` of a record (None past the end).
pub fn sample_at(rec: &[u8], k: usize) -> Option<RawSample> {
    let b = rec.get(k * STEP_BYTES..(k + 1) * STEP_BYTES)?;
    let u = |i: usize| u16::from_le_bytes([b[2 * i], b[2 * i + 1]]);
    Some(RawSample {
        i_abc: [u(0), u(1), u(2)],
        v_bus: u(3),
        encoder: u(4),
    })
}

/// Fold everything the controller output in one step: the actuation and the telemetry.
pub fn fold(h: &mut Fnv, a: &Actuation, ctl: &Controller) {
    for d in a.duties {
        h.word(d.to_bits() as u32);
    }
    h.word(a.enable as u32 | (a.brake as u32) << 1);
    let t = ctl.telemetry();
    for v in [
        t.i_dq.d, t.i_dq.q, t.i_ref.d, t.i_ref.q, t.v_dq.d, t.v_dq.q, t.omega_m, t.x, t.p_elec,
    ] {
        h.word(v.to_bits() as u32);
    }
    h.word(t.theta_e.0);
}

/// Replay `rec` through `ctl`, calling `step` for each sample (so a target can count the
/// instructions of its own step function). Returns (digest, steps).
pub fn replay(
    ctl: &mut Controller,
    rec: &[u8],
    mut step: impl FnMut(&mut Controller, &RawSample) -> Actuation,
) -> (u64, usize) {
    let mut h = Fnv::default();
    let mut k = 0;
    while let Some(s) = sample_at(rec, k) {
        let a = step(ctl, &s);
        fold(&mut h, &a, ctl);
        k += 1;
    }
    (h.0, k)
}
