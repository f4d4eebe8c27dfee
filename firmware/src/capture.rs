//! Capture at the loop rate (`cap`, `docs/console.md`, "Capture"): up to [`CH_MAX`] of
//! `tel`'s channels recorded every `div`-th period into a static ring, with a trigger (a
//! fault latching, a command, a channel crossing a level) and a share of the samples kept
//! from before it.
//!
//! [`Capture::record`] runs in the period routine ([`crate::period::Period::finish`], after
//! the outputs are written and the period's latch and supervision are done, so a fault that
//! latched in this period is seen in this period's sample). A sample stores what the step
//! already stored ([`Controller::cap_words_with_power`]), converted to nothing: each channel
//! is resolved when the capture is armed ([`source`]) to a word of the step's record and a
//! right shift; the sample holds the word as it is (an indexed load and a store), and its code
//! is that word shifted and saturated to `i16` when it is read ([`CapPort::sample`]; the level
//! trigger's channel in the sample itself): the phase currents' and the bus voltage's ADC
//! codes as they came,
//! the d/q currents, references and voltages as their Q16.16 bits shifted, the speed as the
//! encoder's speed estimate (counts per period) shifted, the travel as the encoder's count
//! shifted, and the power, which the step does not compute, as the period computes it for its
//! energy sum ([`Capture::record`] puts it into the record's power word). `cap dump` converts
//! each code to the channel's unit with the gains in force at the arm ([`Decode`]), by the
//! functions `tel` uses: a phase current or the bus voltage is exactly `tel`'s value; a d/q
//! value or the power is `tel`'s value floored to the channel's step ([`lsb`]); the speed is
//! `tel`'s formula on the speed estimate floored to the step; the travel is `tel`'s formula on
//! the count floored to the step (without the speed observer's sub-count part, which `tel`'s
//! travel adds). A level trigger compares in the same codes, by the signs of their differences
//! (no branch).
//!
//! States: `idle` → `arm` → `armed` (the ring fills; the trigger is looked for once
//! `pre` samples are held) → `triggered` (the rest of the ring fills) → `ready` (the
//! ring holds `N` samples, `pre` of them before the trigger sample, read oldest first by
//! [`CapPort::sample`]; the period no longer writes it).
//!
//! The console reaches a capture through [`CapPort`]: on the host (the simulator) the
//! capture itself, on the board a handle that locks the loop for each call.

use crate::config::Gains;
use crate::control::{
    amps_of_code, volts_of_code, Controller, CAP_WORDS, W_P, W_POS, W_VBUS, W_VEL,
};
use crate::fx::{sat_i32, Gain, Q};
use crate::numtext::q_f32;

// The sample indexes the record's words by a [`Word`] (13 values) without a bounds check.
const _: () = assert!(CAP_WORDS == 13);

/// Channels a capture records at most.
pub const CH_MAX: usize = 4;

/// Samples of the G474's capture ring (and the simulator's): 51.2 ms of 4 channels at 20 kHz,
/// 16 KiB of 32-bit words (a power of two: the ring's index is the sample count's low bits).
/// A 32 KiB G431 beside the rest of the image's static RAM (≈ 16 KiB) holds 512 (8 KiB):
/// 25.6 ms at 20 kHz.
pub const SAMPLES: usize = 1024;

/// Channel indices into [`crate::console::CHANNELS`] the capture treats apart: the phase
/// currents (0 … 2) and the bus voltage are ADC codes, the speed and the travel the encoder's
/// estimate and count (any other channel is the power, computed).
const CH_VBUS: u8 = W_VBUS as u8;
const CH_W: u8 = 10;
const CH_X: u8 = 11;

/// The right shift of a d/q current (2⁻¹⁰ A, ±32 A), a d/q voltage and the power (2⁻⁶ V,
/// ±512 V; 2⁻⁶ W, ±512 W) from their Q16.16 bits.
const SHIFT_I: u8 = 6;
const SHIFT_V: u8 = 10;

/// The finest step of the speed and travel channels: the largest shift of the speed estimate
/// (count) whose step is at most 2⁻⁸ rad/s (2⁻¹⁶ m). With the default encoder (10,000
/// counts, 20 kHz, 16 mm lead): 3.07 mrad/s (±100 rad/s) and 12.8 µm (±0.42 m).
const STEP_W: f32 = 1.0 / 256.0;
const STEP_X: f32 = 1.0 / 65_536.0;

/// Where a channel's code comes from: a word of [`Controller::cap_words_with_power`] and its
/// right shift.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Source {
    pub word: u8,
    pub shift: u8,
}

/// A number below 13 or 17 as a value the compiler knows the range of (an enum's
/// discriminant): a word index into the 13 of [`Controller::cap_words_with_power`] and a
/// shift below 32 need no bounds check or mask in [`Capture::take`].
macro_rules! small {
    ($name:ident, $($v:ident = $n:expr),+) => {
        #[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
        #[repr(u8)]
        enum $name {
            #[default]
            $($v = $n),+
        }
        impl $name {
            /// `n` if it is one of the values, else the first.
            fn of(n: u8) -> $name {
                [$($name::$v),+].into_iter().find(|v| *v as u8 == n).unwrap_or_default()
            }
        }
    };
}
small!(
    Word,
    W0 = 0,
    W1 = 1,
    W2 = 2,
    W3 = 3,
    W4 = 4,
    W5 = 5,
    W6 = 6,
    W7 = 7,
    W8 = 8,
    W9 = 9,
    W10 = 10,
    W11 = 11,
    W12 = 12
);
small!(
    Shift,
    S0 = 0,
    S1 = 1,
    S2 = 2,
    S3 = 3,
    S4 = 4,
    S5 = 5,
    S6 = 6,
    S7 = 7,
    S8 = 8,
    S9 = 9,
    S10 = 10,
    S11 = 11,
    S12 = 12,
    S13 = 13,
    S14 = 14,
    S15 = 15,
    S16 = 16
);

/// The largest shift `s ≤ 16` with `unit·2^s ≤ step` (0 when even one unit is coarser).
fn finest_shift(unit: f32, step: f32) -> u8 {
    let mut s = 0;
    while s < 16 && unit * (2u32 << s) as f32 <= step {
        s += 1;
    }
    s
}

/// Channel `ch`'s source for the compiled gains `g`.
pub fn source(ch: u8, g: &Gains) -> Source {
    let (word, shift) = match ch {
        0..=2 | CH_VBUS => (ch, 0),
        3..=6 => (ch, SHIFT_I),
        7 | 8 => (ch, SHIFT_V),
        CH_W => (
            W_VEL as u8,
            // Counts per period (2⁻¹⁶ per LSB) times rad/s per count per period.
            finest_shift(g.enc.rad_s_per_count_step.to_f32() / 65_536.0, STEP_W),
        ),
        CH_X => (
            W_POS as u8,
            finest_shift(g.enc.m_per_count.to_f32(), STEP_X),
        ),
        _ => (W_P as u8, SHIFT_V),
    };
    Source { word, shift }
}

/// A channel's Q16.16 bits (or code) as its stored code: shifted, saturated to `i16`.
#[inline(always)]
fn code(bits: i32, shift: u8) -> i32 {
    (bits >> shift).clamp(i16::MIN as i32, i16::MAX as i32)
}

/// The code of word `w` of the step's record at shift `s` (an indexed load, `asr`, `ssat`).
#[inline(always)]
fn read(words: &[i32; CAP_WORDS], w: Word, s: Shift) -> i32 {
    code(words[w as usize], s as u8)
}

/// How the stored codes read in their units: the gains in force at the arm, the channels and
/// their shifts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Decode {
    ch: [u8; CH_MAX],
    shift: [u8; CH_MAX],
    amps_per_count: Gain,
    adc_zero: i32,
    volts_per_count: Gain,
    rad_s_per_count_step: Gain,
    m_per_count: Gain,
}

impl Decode {
    const NONE: Decode = Decode {
        ch: [0; CH_MAX],
        shift: [0; CH_MAX],
        amps_per_count: Gain::ZERO,
        adc_zero: 0,
        volts_per_count: Gain::ZERO,
        rad_s_per_count_step: Gain::ZERO,
        m_per_count: Gain::ZERO,
    };

    /// For the channels `ch` and the compiled gains `g`.
    pub fn new(ch: [u8; CH_MAX], g: &Gains) -> Decode {
        Decode {
            ch,
            shift: ch.map(|c| source(c, g).shift),
            amps_per_count: g.amps_per_count,
            adc_zero: g.adc_zero,
            volts_per_count: g.volts_per_count,
            rad_s_per_count_step: g.enc.rad_s_per_count_step,
            m_per_count: g.enc.m_per_count,
        }
    }

    /// Slot `k`'s code `c` in its channel's unit (`tel`'s conversions: see the module's
    /// documentation for what each channel's value is).
    pub fn value(&self, k: usize, c: i16) -> f32 {
        let (ch, sh) = (self.ch[k % CH_MAX], self.shift[k % CH_MAX] as u32);
        let c32 = c as i32;
        let q = match ch {
            // The codes are 12-bit: the `i16` holds them as they came.
            0..=2 => amps_of_code(self.amps_per_count, self.adc_zero, c as u16),
            CH_VBUS => volts_of_code(self.volts_per_count, c as u16),
            // (Shifts ≤ 16 of an `i16`: the products fit.)
            CH_W => self
                .rad_s_per_count_step
                .scale(Q::from_bits(((c32 as i64) << sh) as i32)),
            // The travel of a count (the speed observer's position at that count, `Encoder::x`).
            CH_X => Q::from_bits(sat_i32(
                self.m_per_count.mul_wide((c32 as i64) << (16 + sh)),
            )),
            _ => Q::from_bits(c32 << sh),
        };
        q_f32(q)
    }

    /// One code of slot `k`'s channel, its unit (near a level; the speed's and the currents'
    /// gains are rounded to their fixed point).
    pub fn lsb(&self, k: usize) -> f32 {
        let (ch, sh) = (self.ch[k % CH_MAX], self.shift[k % CH_MAX]);
        lsb_of(
            ch,
            sh,
            self.amps_per_count.to_f32(),
            self.volts_per_count.to_f32(),
            self.rad_s_per_count_step.to_f32(),
            self.m_per_count.to_f32(),
        )
    }
}

/// One code of channel `ch` at shift `sh`, its unit.
fn lsb_of(ch: u8, sh: u8, apc: f32, vpc: f32, w: f32, x: f32) -> f32 {
    let two = (1u32 << sh) as f32;
    match ch {
        0..=2 => apc,
        CH_VBUS => vpc,
        CH_W => w / 65_536.0 * two,
        CH_X => x * two,
        _ => two / 65_536.0,
    }
}

/// One code of channel `ch` in its unit for the gains `g` (`2^(shift − 16)` for a Q16.16
/// channel, a count's for an ADC code).
pub fn lsb(ch: u8, g: &Gains) -> f32 {
    let sh = source(ch, g).shift;
    let e = &g.enc;
    lsb_of(
        ch,
        sh,
        g.amps_per_count.to_f32(),
        g.volts_per_count.to_f32(),
        e.rad_s_per_count_step.to_f32(),
        e.m_per_count.to_f32(),
    )
}

/// The code a level trigger on channel `ch` compares with (rounded; within the codes the
/// channel holds).
pub fn level_code(ch: u8, level: f32, g: &Gains) -> i32 {
    let zero = if ch <= 2 { g.adc_zero as f32 } else { 0.0 };
    let c = level / lsb(ch, g) + zero;
    let c = if c >= 0.0 { c + 0.5 } else { c - 0.5 };
    (c as i32).clamp(i16::MIN as i32, i16::MAX as i32)
}

/// The levels channel `ch`'s codes represent, its unit: the 12-bit ADC's range for a phase
/// current or the bus voltage, else `±32767·lsb`.
pub fn level_range(ch: u8, g: &Gains) -> (f32, f32) {
    let l = lsb(ch, g);
    match ch {
        0..=2 => {
            let z = g.adc_zero as f32;
            (-z * l, (crate::config::CODE_MAX as f32 - z) * l)
        }
        CH_VBUS => (0.0, crate::config::CODE_MAX as f32 * l),
        _ => (-(i16::MAX as f32) * l, i16::MAX as f32 * l),
    }
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
    /// The samples' codes in their units.
    pub decode: Decode,
}

/// The console's way to a capture.
pub trait CapPort {
    fn status(&self) -> Status;
    /// Start a capture with `set`, `dt_s` s between its samples (`div` periods), its channels
    /// resolved for the compiled gains `g` (any samples held are discarded).
    fn arm(&mut self, set: &Settings, dt_s: f32, g: &Gains);
    /// Trigger an armed capture (at its next sample once the pre-trigger share is held);
    /// `false` unless armed.
    fn trigger_now(&mut self) -> bool;
    /// Back to idle, samples discarded.
    fn stop(&mut self);
    /// Sample `k` of a ready capture, oldest first (0 … `len − 1`): the codes of its channels
    /// ([`Status::decode`] reads them).
    fn sample(&self, k: u32) -> [i16; CH_MAX];
}

/// The capture: its state and a ring of `N` samples (`N` a power of two: the ring index is
/// the sample count's low bits). (`repr(C)`: what a sample reads first and the ring last,
/// each field within a load's immediate offset of the capture's address.)
#[derive(Clone, Debug)]
#[repr(C)]
pub struct Capture<const N: usize> {
    /// The state and, while armed, the filling or the trigger's kind.
    phase: Phase,
    /// `cap now` pending.
    now: bool,
    /// A fault was latched at the last sample (true at the arm: a fault latched before the
    /// first sample does not count).
    fault_prev: bool,
    /// The channels' sources: words of [`Controller::cap_words_with_power`] and shifts.
    word: [Word; CH_MAX],
    shift: [Shift; CH_MAX],
    /// The level trigger's channel's source.
    lv_word: Word,
    lv_shift: Shift,
    /// Periods to pass before the next sample (0: this one).
    wait: u16,
    /// `div − 1`: the wait after a sample.
    skip: u16,
    /// The phase a trigger starts: triggered, or ready when no sample follows the trigger's.
    fire_phase: Phase,
    /// The trigger's phase (level, command or fault), which follows [`Phase::Fill`].
    trig_phase: Phase,
    /// Samples recorded since the arm, the next one into ring slot `k mod N`; past 2^31 it
    /// counts on modulo 2^31 above 2^31 ([`next_k`]), so it never falls below `N` again.
    k: u32,
    pre_n: u32,
    /// Samples still to record after the trigger sample.
    left: u32,
    /// `N − 1 − pre_n`: `left` at the trigger.
    post_n: u32,
    /// The level trigger: its level code for each edge ([`NO_EDGE`] apart for an edge it
    /// does not fire on); the channel's code at the last sample (the level's own at the arm:
    /// no crossing into the first sample).
    lv_rise: i32,
    lv_fall: i32,
    lv_prev: i32,
    set: Settings,
    dt_s: f32,
    decode: Decode,
    /// The samples: each the four slots' record words as the step stored them (shifted and
    /// saturated to codes when read, [`Capture::sample`]).
    buf: [[i32; CH_MAX]; N],
}

/// The sample count after `k`: `k + 1`, but from 2^31 on modulo 2^31 above 2^31 (the ring's
/// slot, `k mod N`, unchanged: `N` divides 2^31).
#[inline(always)]
fn next_k(k: u32) -> u32 {
    k.wrapping_add(1) | (k & 1 << 31)
}

/// A level no code reaches (codes are `i16`): the level of an edge a trigger does not fire on.
const NO_EDGE: i32 = 1 << 20;

/// A capture's phase: its [`State`], and while armed the pre-trigger share's filling or
/// the trigger's kind (what [`Capture::record`] dispatches on: one byte, one table jump; an
/// enum, so the jump needs no range check).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
enum Phase {
    Idle = 0,
    Ready = 1,
    /// Armed, a level trigger.
    Level = 2,
    Triggered = 3,
    /// Armed, a command trigger (or `cap now` given).
    Cmd = 4,
    /// Armed, a fault trigger.
    Fault = 5,
    /// Armed, the pre-trigger share not yet held: no trigger is looked for.
    Fill = 6,
}

impl<const N: usize> Default for Capture<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Capture<N> {
    const POW2: () = assert!(N.is_power_of_two(), "a capture ring of 2^n samples");

    /// An idle capture, all zero bytes (a static one is zero-initialised: no flash); its
    /// settings are the first `arm`'s.
    pub const fn new() -> Self {
        #[allow(clippy::let_unit_value)]
        let () = Self::POW2;
        Capture {
            phase: Phase::Idle,
            now: false,
            fault_prev: false,
            word: [Word::W0; CH_MAX],
            shift: [Shift::S0; CH_MAX],
            lv_word: Word::W0,
            lv_shift: Shift::S0,
            wait: 0,
            skip: 0,
            fire_phase: Phase::Idle,
            trig_phase: Phase::Idle,
            k: 0,
            pre_n: 0,
            left: 0,
            post_n: 0,
            lv_rise: 0,
            lv_fall: 0,
            lv_prev: 0,
            set: Settings {
                ch: [0; CH_MAX],
                n_ch: 0,
                div: 0,
                pre_pct: 0,
                trig: Trigger::Fault,
            },
            dt_s: 0.0,
            decode: Decode::NONE,
            buf: [[0; CH_MAX]; N],
        }
    }

    pub fn state(&self) -> State {
        match self.phase {
            Phase::Idle => State::Idle,
            Phase::Ready => State::Ready,
            Phase::Triggered => State::Triggered,
            Phase::Level | Phase::Cmd | Phase::Fault | Phase::Fill => State::Armed,
        }
    }

    /// Samples kept from before the trigger for `pct` % of `N` (at most `N − 1`: the trigger
    /// sample is always held).
    pub fn pre_samples(pct: u8) -> u32 {
        ((N as u32 * pct.min(100) as u32) / 100).min(N as u32 - 1)
    }

    /// Armed or triggered: [`Capture::record`] has work (one compare).
    #[inline(always)]
    pub fn active(&self) -> bool {
        self.phase as u8 >= Phase::Level as u8
    }

    /// One period (the period routine, after its outputs): a sample when one is due, the
    /// trigger, the state, with `p_bits` the period's electrical power (Q16.16 bits of
    /// [`Controller::p_elec`], which the period computes for its energy sum; put into the
    /// record's power word, which a slot or the level trigger may read). Does nothing unless
    /// [`Capture::active`].
    #[inline(always)]
    pub fn record(&mut self, ctl: &mut Controller, p_bits: i32) {
        if !self.active() {
            return;
        }
        if self.wait != 0 {
            self.wait -= 1;
            return;
        }
        self.wait = self.skip;
        self.take(ctl, p_bits);
    }

    /// A sample and its trigger test.
    #[inline(always)]
    fn take(&mut self, ctl: &mut Controller, p_bits: i32) {
        // All four slots, unrolled (a loop over `n_ch` costs more than the unused reads; the
        // slots past `n_ch` are never shown): the words as they are, into slot `k mod N` (no
        // bounds check), one by one (a copy of the array is a `memcpy` call at opt-level z).
        let words = ctl.cap_words_with_power(p_bits);
        let c = &self.word;
        let k = self.k;
        let slot = &mut self.buf[k as usize & (N - 1)];
        slot[0] = words[c[0] as usize];
        slot[1] = words[c[1] as usize];
        slot[2] = words[c[2] as usize];
        slot[3] = words[c[3] as usize];
        self.k = next_k(k);
        // One table jump on the phase. Armed: the trigger's condition against the last
        // sample's; filling: at its last sample what the first trigger test compares with;
        // triggered: the samples still to come.
        match self.phase {
            Phase::Level => {
                let c = read(words, self.lv_word, self.lv_shift);
                let (p, lr, lf) = (self.lv_prev, self.lv_rise, self.lv_fall);
                self.lv_prev = c;
                // Codes within ±2^15, levels within ±2^15 or ±NO_EDGE: the differences'
                // signs are the comparisons. Rising: p < lr ≤ c; falling: p > lf ≥ c; each in
                // the sign bit (never for a level at ∓NO_EDGE: p < −NO_EDGE, p > NO_EDGE).
                let rise = (p - lr) & !(c - lr);
                let fall = (lf - p) & !(lf - c);
                if (rise | fall) < 0 {
                    self.fire();
                }
            }
            Phase::Cmd => {
                if self.now {
                    self.fire();
                }
            }
            Phase::Fault => {
                let f = ctl.fault().is_some();
                if f & !self.fault_prev {
                    self.fire();
                }
                self.fault_prev = f;
            }
            Phase::Fill => {
                // (The level's channel and the fault latch: the trigger's kind is not tested.)
                if k + 1 == self.pre_n {
                    self.lv_prev = read(words, self.lv_word, self.lv_shift);
                    self.fault_prev = ctl.fault().is_some();
                    self.phase = self.trig_phase;
                }
            }
            Phase::Triggered => {
                self.left -= 1;
                if self.left == 0 {
                    self.phase = Phase::Ready;
                }
            }
            Phase::Idle | Phase::Ready => {}
        }
    }

    /// The trigger: the post-trigger part starts with this sample (the pre-trigger share is
    /// held: the trigger is looked for only after `Phase::Fill`). (The trigger sample's index is
    /// `k` less the samples recorded after it, which `left` tells: [`Capture::k_trig`].)
    #[inline(always)]
    fn fire(&mut self) {
        self.left = self.post_n;
        self.phase = self.fire_phase;
    }

    /// The trigger sample's index counted from the arm, once triggered: the samples held
    /// after it are `post_n − left`.
    fn k_trig(&self) -> u32 {
        let after = self.post_n - self.left;
        self.k.saturating_sub(after + 1)
    }
}

impl<const N: usize> CapPort for Capture<N> {
    fn status(&self) -> Status {
        Status {
            state: self.state(),
            set: self.set,
            held: self.k.min(N as u32),
            len: N as u32,
            pre_n: self.pre_n,
            k_trig: (self.state() >= State::Triggered).then_some(self.k_trig()),
            dt_s: self.dt_s,
            decode: self.decode,
        }
    }

    fn arm(&mut self, set: &Settings, dt_s: f32, g: &Gains) {
        self.set = *set;
        self.set.div = set.div.clamp(1, DIV_MAX);
        let n_ch = set.n_ch.min(CH_MAX as u8) as usize;
        // The slots past `n_ch` read `ia`'s code (one load: [`Capture::take`] reads all four).
        for c in self.set.ch.iter_mut().skip(n_ch) {
            *c = 0;
        }
        for (k, &c) in self.set.ch.iter().enumerate() {
            let s = source(c, g);
            self.word[k] = Word::of(s.word);
            self.shift[k] = Shift::of(s.shift);
        }
        self.decode = Decode::new(self.set.ch, g);
        self.wait = 0;
        self.skip = self.set.div - 1;
        self.k = 0;
        let pre_n = Self::pre_samples(set.pre_pct);
        self.pre_n = pre_n;
        self.post_n = N as u32 - 1 - pre_n;
        self.fire_phase = if self.post_n == 0 {
            Phase::Ready
        } else {
            Phase::Triggered
        };
        self.left = 0;
        self.now = false;
        self.fault_prev = true;
        self.dt_s = dt_s;
        self.trig_phase = match set.trig {
            Trigger::Fault => Phase::Fault,
            Trigger::Cmd => Phase::Cmd,
            Trigger::Level { .. } => Phase::Level,
        };
        self.phase = if pre_n == 0 {
            self.trig_phase
        } else {
            Phase::Fill
        };
        // (The channel is read at the last pre-trigger sample too: `ia`'s when not a level.)
        self.lv_word = Word::W0;
        self.lv_shift = Shift::S0;
        if let Trigger::Level { ch, edge, level } = set.trig {
            let s = source(ch, g);
            self.lv_word = Word::of(s.word);
            self.lv_shift = Shift::of(s.shift);
            let l = level_code(ch, level, g);
            self.lv_rise = if edge == Edge::Fall { -NO_EDGE } else { l };
            self.lv_fall = if edge == Edge::Rise { NO_EDGE } else { l };
            self.lv_prev = l;
        }
    }

    fn trigger_now(&mut self) -> bool {
        if self.state() != State::Armed {
            return false;
        }
        self.now = true;
        if self.phase == Phase::Fill {
            self.trig_phase = Phase::Cmd;
        } else {
            self.phase = Phase::Cmd;
        }
        true
    }

    fn stop(&mut self) {
        self.phase = Phase::Idle;
        self.k = 0;
    }

    fn sample(&self, k: u32) -> [i16; CH_MAX] {
        // The next slot written is the oldest once the ring is full (as it is when ready).
        let i = (self.k as usize).wrapping_add(k as usize) & (N - 1);
        let (s, sh) = (&self.buf[i], &self.shift);
        [0, 1, 2, 3].map(|j| code(s[j], sh[j] as u8) as i16)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;
    use crate::io::RawSample;
    use proptest::prelude::*;

    proptest! {
        /// A level trigger on the bus voltage fires at the first sample whose voltage has
        /// reached the level on its edge (the previous one short of it), once the pre-trigger
        /// share is held, and never into the first sample: over random walks of the bus code,
        /// levels at a code's voltage, each edge, pre-trigger shares from none to all but one
        /// sample of the ring, the trigger sample's index (`k_trig`) is the first crossing
        /// into a sample at or after the share found from the voltages themselves.
        #[test]
        fn level_trigger_fires_at_the_first_crossing(
            start in 2300u16..3100,
            steps in prop::collection::vec(-40i32..=40, 20..200),
            above in 0u16..20,
            edge in prop::sample::select(std::vec![Edge::Rise, Edge::Fall, Edge::Both]),
            pre_pct in prop::sample::select(std::vec![0u8, 0, 2, 10, 30, 60, 100]),
        ) {
            let cfg = Config::default();
            let vpc = cfg.volts_per_count as f64;
            let mut ctl = Controller::new(&cfg).unwrap();
            let mut codes = std::vec![start];
            for d in steps {
                let c = (*codes.last().unwrap() as i32 + d).clamp(2300, 3100);
                codes.push(c as u16);
            }
            // A code's voltage near the start (a crossing is likely): reached is crossed.
            let level = ((start + above) as f64 - 10.0) * vpc;
            let mut cap = Capture::<64>::new();
            let set = Settings { ch: [9, 0, 0, 0], n_ch: 1, div: 1, pre_pct,
                trig: Trigger::Level { ch: 9, edge, level: level as f32 } };
            cap.arm(&set, 5e-5, ctl.gains());
            let z = cfg.adc_zero_code;
            for &c in &codes {
                ctl.step(&RawSample { i_abc: [z; 3], v_bus: c, encoder: 0 });
                let p = ctl.p_elec().to_bits();
                    cap.record(&mut ctl, p);
                if cap.state() != State::Armed {
                    break;
                }
            }
            let v: std::vec::Vec<f64> = codes.iter().map(|&c| c as f64 * vpc).collect();
            // The share: ⌊64·pct/100⌋ samples, at most 63.
            let pre = (64 * pre_pct as usize / 100).min(63);
            let want = (pre.max(1)..v.len()).find(|&k| {
                // (Relative 1e-9: the level's own rounding to f32.)
                let (below, above) = (|x: f64| x < level * (1.0 - 1e-9), |x: f64| x > level * (1.0 + 1e-9));
                let rise = below(v[k - 1]) && !below(v[k]);
                let fall = above(v[k - 1]) && !above(v[k]);
                match edge { Edge::Rise => rise, Edge::Fall => fall, Edge::Both => rise || fall }
            });
            prop_assert_eq!(cap.status().k_trig, want.map(|k| k as u32));
        }
    }

    /// A level trigger compares in codes: the code of a level, read back as the dump reads it,
    /// is that level to within half a step, on every channel over its whole range (the phase
    /// currents' codes offset by the zero code, the speed and travel steps from the encoder),
    /// for the default encoder and a coarse and a fine one.
    #[test]
    fn level_codes_read_back_as_their_levels() {
        let mut worst = 0.0f32;
        for (cpr, lead) in [(10_000, 0.016), (1_000, 0.05), (16_384, 0.004)] {
            let cfg = Config {
                encoder_cpr: cpr,
                lead_m_per_rad: lead / core::f32::consts::TAU,
                ..Config::default()
            };
            let g = Gains::new(&cfg).unwrap();
            for ch in 0..13u8 {
                let d = Decode::new([ch; CH_MAX], &g);
                let (lo, hi) = level_range(ch, &g);
                let l = lsb(ch, &g);
                assert!(lo < hi && l > 0.0, "channel {ch}: {lo} .. {hi}, step {l}");
                for i in 0..=400 {
                    let lv = lo + (hi - lo) * i as f32 / 400.0;
                    let back = d.value(0, level_code(ch, lv, &g) as i16);
                    // Half a step, and the f32 and Q16.16 roundings of the conversions.
                    let tol = 0.5 * l + 1e-5 * lv.abs() + 1.0 / 65_536.0;
                    assert!(
                        (back - lv).abs() <= tol,
                        "channel {ch} (cpr {cpr}): level {lv} reads back {back} (step {l})"
                    );
                    worst = worst.max(((back - lv).abs() - 1.0 / 65_536.0).max(0.0) / l);
                }
            }
        }
        std::println!("worst level read back, beyond one Q16.16 LSB: {worst:.3} steps");
    }
}
