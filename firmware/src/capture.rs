//! Capture at the loop rate (`cap`, `docs/console.md`, "Capture"): up to [`CH_MAX`] of
//! `tel`'s channels recorded every `div`-th period into a static ring of `i16` samples, with a
//! trigger (a fault latching, a command, a channel crossing a level) and a share of the
//! samples kept from before it.
//!
//! [`Capture::record`] runs in the period routine ([`crate::period::Period::finish`], after
//! the outputs are written and the period's latch and supervision are done, so a fault that
//! latched in this period is seen in this period's sample). Each channel is stored with a
//! fixed scale: the Q16.16 bits of its value shifted right by [`SHIFT`] and saturated to
//! `i16` (one `asr` and one `ssat`), i.e. a step of `2^(SHIFT − 16)` in the channel's unit
//! ([`lsb`]). A level trigger compares in the same codes.
//!
//! States: `idle` → `arm` → `armed` (the ring fills; the trigger is looked for once
//! `pre` samples are held) → `triggered` (the rest of the ring fills) → `ready` (the
//! ring holds `N` samples, `pre` of them before the trigger sample, read oldest first by
//! [`CapPort::sample`]; the period no longer writes it).
//!
//! The console reaches a capture through [`CapPort`]: on the host (the simulator) the
//! capture itself, on the board a handle that locks the loop for each call.

use crate::control::Controller;

/// Channels a capture records at most.
pub const CH_MAX: usize = 4;

/// Samples of the G474's capture ring (and the simulator's): 50 ms of 4 channels at 20 kHz.
pub const SAMPLES: usize = 1000;

/// The right shift from a channel's Q16.16 bits to its `i16` code, by index into
/// [`crate::console::CHANNELS`]: currents 2⁻¹⁰ A (±32 A), voltages 2⁻⁶ V (±512 V), speed
/// 2⁻⁸ rad/s (±128 rad/s), travel 2⁻¹⁶ m (±0.5 m), power 2⁻⁶ W (±512 W).
pub const SHIFT: [u8; 13] = [6, 6, 6, 6, 6, 6, 6, 10, 10, 10, 8, 0, 10];

/// One code of channel `ch` in its unit (`2^(SHIFT − 16)`).
pub fn lsb(ch: u8) -> f32 {
    let s = SHIFT.get(ch as usize).copied().unwrap_or(0);
    (1u32 << s) as f32 / 65_536.0
}

/// A channel's Q16.16 bits as its stored code: shifted, saturated to `i16`.
#[inline(always)]
fn code(bits: i32, shift: u8) -> i32 {
    (bits >> shift).clamp(i16::MIN as i32, i16::MAX as i32)
}

/// The edge a level trigger fires on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Edge {
    Rise,
    Fall,
    Both,
}

impl Edge {
    pub fn name(self) -> &'static str {
        match self {
            Edge::Rise => "rise",
            Edge::Fall => "fall",
            Edge::Both => "both",
        }
    }
}

/// What starts the post-trigger part.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Trigger {
    /// A fault latching (a fault already latched when armed does not count).
    Fault,
    /// Only `cap now`.
    Cmd,
    /// Channel `ch` crossing `level` (its unit) on `edge`.
    Level { ch: u8, edge: Edge, level: f32 },
}

/// A capture's settings (`cap ch`, `cap div`, `cap pre`, `cap trig`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// Channel indices into [`crate::console::CHANNELS`]; the first `n_ch` are used.
    pub ch: [u8; CH_MAX],
    pub n_ch: u8,
    /// Record every `div`-th period, 1 … [`DIV_MAX`].
    pub div: u16,
    /// Share of the ring kept from before the trigger, 0 … 100 %.
    pub pre_pct: u8,
    pub trig: Trigger,
}

/// Largest `div`.
pub const DIV_MAX: u16 = 1000;

impl Default for Settings {
    /// `iq_ref,iq` every period, 20 % before a `cap now`.
    fn default() -> Self {
        Settings {
            ch: [6, 4, 0, 0],
            n_ch: 2,
            div: 1,
            pre_pct: 20,
            trig: Trigger::Cmd,
        }
    }
}

impl Settings {
    /// The channels in use.
    pub fn channels(&self) -> &[u8] {
        self.ch.get(..self.n_ch as usize).unwrap_or(&[])
    }
}

/// Where a capture is.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord)]
pub enum State {
    #[default]
    Idle = 0,
    Armed = 1,
    Triggered = 2,
    Ready = 3,
}

impl State {
    pub fn name(self) -> &'static str {
        match self {
            State::Idle => "idle",
            State::Armed => "armed",
            State::Triggered => "triggered",
            State::Ready => "ready",
        }
    }
}

/// A capture as the console shows it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Status {
    pub state: State,
    /// The settings in force (those of the last `arm`; the default before one).
    pub set: Settings,
    /// Samples held (the ring's length once it has wrapped).
    pub held: u32,
    /// The ring's length.
    pub len: u32,
    /// Samples kept from before the trigger sample.
    pub pre_n: u32,
    /// The trigger sample's index counted from the arm (its first sample 0), once triggered.
    pub k_trig: Option<u32>,
    /// Time between samples, s (`div` periods).
    pub dt_s: f32,
}

/// The console's way to a capture.
pub trait CapPort {
    fn status(&self) -> Status;
    /// Start a capture with `set`, `dt_s` s between its samples (`div` periods; any samples
    /// held are discarded).
    fn arm(&mut self, set: &Settings, dt_s: f32);
    /// Trigger an armed capture (at its next sample once the pre-trigger share is held);
    /// `false` unless armed.
    fn trigger_now(&mut self) -> bool;
    /// Back to idle, samples discarded.
    fn stop(&mut self);
    /// Sample `k` of a ready capture, oldest first (0 … `len − 1`): the codes of its channels.
    fn sample(&self, k: u32) -> [i16; CH_MAX];
}

/// The capture: its state and a ring of `N` samples.
#[derive(Clone, Debug)]
pub struct Capture<const N: usize> {
    state: State,
    set: Settings,
    /// Shifts of the channels in use, and of the level trigger's channel.
    shift: [u8; CH_MAX],
    n_ch: u8,
    /// Periods until the next sample (1: this one).
    count: u16,
    /// Next ring slot written.
    w: u32,
    /// Samples recorded since the arm (saturating).
    k: u32,
    pre_n: u32,
    /// Samples still to record after the trigger sample.
    left: u32,
    /// `cap now` pending.
    now: bool,
    /// The level trigger: channel, shift, level code, edge (0 rise, 1 fall, 2 both); the
    /// channel's code at the last sample.
    lv_ch: u8,
    lv_shift: u8,
    lv_code: i32,
    lv_edge: u8,
    lv_prev: i32,
    kind: u8,
    /// A fault was latched at the last sample.
    fault_prev: bool,
    k_trig: u32,
    dt_s: f32,
    buf: [[i16; CH_MAX]; N],
}

/// Trigger kinds as [`Capture::record`] tests them.
const K_FAULT: u8 = 0;
const K_CMD: u8 = 1;
const K_LEVEL: u8 = 2;

impl<const N: usize> Default for Capture<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Capture<N> {
    /// An idle capture, all zero bytes (a static one is zero-initialised: no flash); its
    /// settings are the first `arm`'s.
    pub const fn new() -> Self {
        Capture {
            state: State::Idle,
            set: Settings {
                ch: [0; CH_MAX],
                n_ch: 0,
                div: 0,
                pre_pct: 0,
                trig: Trigger::Fault,
            },
            shift: [0; CH_MAX],
            n_ch: 0,
            count: 0,
            w: 0,
            k: 0,
            pre_n: 0,
            left: 0,
            now: false,
            lv_ch: 0,
            lv_shift: 0,
            lv_code: 0,
            lv_edge: 0,
            lv_prev: 0,
            kind: K_FAULT,
            fault_prev: false,
            k_trig: 0,
            dt_s: 0.0,
            buf: [[0; CH_MAX]; N],
        }
    }

    pub fn state(&self) -> State {
        self.state
    }

    /// Samples kept from before the trigger for `pct` % of `N` (at most `N − 1`: the trigger
    /// sample is always held).
    pub fn pre_samples(pct: u8) -> u32 {
        ((N as u32 * pct.min(100) as u32) / 100).min(N as u32 - 1)
    }

    /// One period (the period routine, after its outputs): a sample when one is due, the
    /// trigger, the state. Does nothing unless armed or triggered.
    #[inline(always)]
    pub fn record(&mut self, ctl: &Controller) {
        if self.state == State::Idle || self.state == State::Ready {
            return;
        }
        self.count -= 1;
        if self.count != 0 {
            return;
        }
        self.count = self.set.div;
        self.take(ctl);
    }

    /// A sample and its trigger test (out of line: the period's common path is the test
    /// above).
    #[inline(never)]
    fn take(&mut self, ctl: &Controller) {
        // All four slots, unrolled (a loop over `n_ch` costs more than the unused reads; the
        // slots past `n_ch` are never shown).
        let (c, sh) = (&self.set.ch, &self.shift);
        let row = [
            code(ctl.channel_bits(c[0]), sh[0]) as i16,
            code(ctl.channel_bits(c[1]), sh[1]) as i16,
            code(ctl.channel_bits(c[2]), sh[2]) as i16,
            code(ctl.channel_bits(c[3]), sh[3]) as i16,
        ];
        let w = self.w as usize;
        if let Some(r) = self.buf.get_mut(w) {
            *r = row;
        }
        self.w = if w + 1 >= N { 0 } else { w as u32 + 1 };
        let k = self.k;
        self.k = k.saturating_add(1);
        if self.state == State::Triggered {
            self.left -= 1;
            if self.left == 0 {
                self.state = State::Ready;
            }
            return;
        }
        // Armed: the trigger's condition against the last sample's.
        let fired = match self.kind {
            K_FAULT => {
                let f = ctl.fault().is_some();
                let edge = f && !self.fault_prev && k > 0;
                self.fault_prev = f;
                edge
            }
            K_CMD => self.now,
            _ => {
                let c = code(ctl.channel_bits(self.lv_ch), self.lv_shift);
                let (p, l) = (self.lv_prev, self.lv_code);
                self.lv_prev = c;
                let rise = p < l && c >= l;
                let fall = p > l && c <= l;
                k > 0
                    && match self.lv_edge {
                        0 => rise,
                        1 => fall,
                        _ => rise | fall,
                    }
            }
        };
        if fired && k >= self.pre_n {
            self.k_trig = k;
            self.left = N as u32 - 1 - self.pre_n;
            self.state = if self.left == 0 {
                State::Ready
            } else {
                State::Triggered
            };
        }
    }
}

impl<const N: usize> CapPort for Capture<N> {
    fn status(&self) -> Status {
        Status {
            state: self.state,
            set: self.set,
            held: self.k.min(N as u32),
            len: N as u32,
            pre_n: self.pre_n,
            k_trig: (self.state >= State::Triggered).then_some(self.k_trig),
            dt_s: self.dt_s,
        }
    }

    fn arm(&mut self, set: &Settings, dt_s: f32) {
        self.set = *set;
        self.set.div = set.div.clamp(1, DIV_MAX);
        self.n_ch = set.n_ch.min(CH_MAX as u8);
        // The slots past `n_ch` read `id` (one load: [`Capture::take`] reads all four).
        for c in self.set.ch.iter_mut().skip(self.n_ch as usize) {
            *c = 3;
        }
        for (s, &c) in self.shift.iter_mut().zip(set.ch.iter()) {
            *s = SHIFT.get(c as usize).copied().unwrap_or(0);
        }
        self.count = 1;
        self.w = 0;
        self.k = 0;
        self.pre_n = Self::pre_samples(set.pre_pct);
        self.left = 0;
        self.now = false;
        self.fault_prev = false;
        self.k_trig = 0;
        self.dt_s = dt_s;
        match set.trig {
            Trigger::Fault => self.kind = K_FAULT,
            Trigger::Cmd => self.kind = K_CMD,
            Trigger::Level { ch, edge, level } => {
                self.kind = K_LEVEL;
                self.lv_ch = ch;
                self.lv_shift = SHIFT.get(ch as usize).copied().unwrap_or(0);
                self.lv_code = level_code(ch, level);
                self.lv_edge = edge as u8;
            }
        }
        self.state = State::Armed;
    }

    fn trigger_now(&mut self) -> bool {
        if self.state != State::Armed {
            return false;
        }
        self.now = true;
        self.kind = K_CMD;
        true
    }

    fn stop(&mut self) {
        self.state = State::Idle;
        self.k = 0;
        self.w = 0;
    }

    fn sample(&self, k: u32) -> [i16; CH_MAX] {
        let i = (self.w as usize + k as usize) % N.max(1);
        self.buf.get(i).copied().unwrap_or([0; CH_MAX])
    }
}

/// A level in channel `ch`'s unit as its code (rounded; saturated to `i16`).
pub fn level_code(ch: u8, level: f32) -> i32 {
    let c = level / lsb(ch);
    let c = if c >= 0.0 { c + 0.5 } else { c - 0.5 };
    (c as i32).clamp(i16::MIN as i32, i16::MAX as i32)
}

/// The largest level a channel's codes represent, its unit (`32767 · lsb`).
pub fn level_max(ch: u8) -> f32 {
    i16::MAX as f32 * lsb(ch)
}
