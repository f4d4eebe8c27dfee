//! The power-up alignment's retry: an alignment that found the rotor moving (`align_moving`:
//! the structure kept the screw turning) is cleared and started again after
//! [`ALIGN_RETRY_S`] in its safe state (the short circuit damps the structure meanwhile), up
//! to [`ALIGN_TRIES`] alignments in all; any other fault, or the last try failing, stays
//! latched for the user.
//!
//! One implementation for both callers: the board's supervision task polls it every 10 ms
//! against a copy of the controller, the simulator's boot sequence every period; each puts
//! the returned changes in a [`Pending`] that [`crate::period::Period::apply`] applies between
//! two periods (the fault cleared, then `mode align`).

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
