//! The serial console: a line parser and command executor over a [`Controller`] and a
//! [`ParamStore`]. No alloc: output goes to any `core::fmt::Write` sink (a UART buffer on the
//! board, a pty on the host), through `write_str` only — no `write!`, so the board image
//! links none of `core::fmt`'s formatting machinery for it (see `Put`). Every command answers with `ok …` or one line `error: …`; a
//! refused command changes nothing. The executor never panics (fuzzed, see
//! `examples/console_fuzz.rs`).
//!
//! Commands: [`COMMANDS`] (`help [CMD]` prints them).
//!
//! Terminal side, the same on the board's UART and on `regen serve`'s pty: [`Console::banner`]
//! on connection, the prompt [`PROMPT`] after every reply, and [`LineEditor`], which echoes
//! what is typed and edits the line (Backspace/DEL, Ctrl-U, arrow keys ignored), so a plain
//! terminal program (picocom, screen, minicom) needs no local echo. A fault that latches is
//! announced unasked by [`Console::notice`] (`# fault …`, a comment line for CSV readers).
//!
//! Telemetry lines are CSV: a header `# tel t,<ch>,…` then `<t>,<v>,…` per sample (`t` in s
//! since `tel` was started), readable by any CSV plotting tool after dropping `#` lines.
//!
//! Machine mode (`machine on`, `docs/console.md`, "Machine mode"): no echo, prompt, banner or
//! line editing; every line sent starts with a one-letter tag (`R` final reply, `D` data line
//! of a reply, `T` telemetry, `H` telemetry header, `N` notice) and replies carry the command's
//! id (`#ID` in front of the command, `-` without one). A command's text is written once, for
//! both modes: its data lines and its final line go through [`Out`], which tags them.
//!
//! Store rule: `save`, `load` and `defaults` are refused while the bridge is live (`run`,
//! `align`): a configuration is stored between runs, not half way through a run's changes,
//! and `load`/`defaults` change parameters that may not change in `run`. Not for the loop's
//! sake: on the board the store is flash bank 2 while the code runs from bank 1
//! (read-while-write, RM0440 "dual bank"), and the save is awaited in the console's task.

use core::fmt::Write;

use crate::capture::{self, CapPort, Capture, Edge, Settings, State, Trigger};
use crate::config::Config;
use crate::control::{Controller, Mode, ModeError, Telemetry};
use crate::numtext::{self, q_f32, Fixed, Num, NumError};
use crate::params::{self, ParamError, PARAMS};
use crate::protect::Fault;

/// The prompt, written after the banner and after every reply.
pub const PROMPT: &str = "> ";

/// Longest console line, bytes (the board's receive buffer).
pub const LINE_MAX: usize = 128;
// The editor's refusal names the figure as text.
const _: () = assert!(LINE_MAX == 128);

/// The board's reply buffer, bytes: a reply longer than this (`cap dump`) is written in
/// pieces of at most this size ([`Console::dump_more`]).
pub const REPLY_MAX: usize = 6144;

/// Longest command id (`#ID` in machine mode), ASCII letters and digits.
pub const ID_MAX: usize = 8;

/// The command id at the start of a machine-mode line: `#ID` followed by a space or the end,
/// ID 1 to [`ID_MAX`] ASCII letters or digits. `None` when the line has no valid id.
fn id_of(line: &[u8]) -> Option<&[u8]> {
    let rest = line.strip_prefix(b"#")?;
    let n = rest
        .iter()
        .position(|&b| b == b' ' || b == b'\t')
        .unwrap_or(rest.len());
    let id = rest.get(..n)?;
    (!id.is_empty() && id.len() <= ID_MAX && id.iter().all(u8::is_ascii_alphanumeric)).then_some(id)
}

/// A command id as text (at most [`ID_MAX`] ASCII characters).
type Id = heapless::String<ID_MAX>;

fn id_text(b: &[u8]) -> Id {
    let mut id = Id::new();
    for &c in b {
        let _ = id.push(char::from(c));
    }
    id
}

/// Every command: name, arguments, what it does (`help`, `help CMD`, and the usage line of a
/// command given wrong arguments).
pub static COMMANDS: &[(&str, &str, &str)] = &[
    ("help", "[CMD]", "commands, or one's use"),
    (
        "list",
        "[PATTERN]",
        "parameters named *PATTERN*: value, range, default (as `defaults`), rt: settable in run",
    ),
    ("get", "NAME", "a parameter"),
    (
        "set",
        "NAME VALUE",
        "set a parameter (RAM), checked; inf where max is inf",
    ),
    ("save", "", "parameters to flash (not in run)"),
    ("load", "", "parameters saved last (not in run)"),
    (
        "defaults",
        "",
        "this hardware's factory parameters (not in run)",
    ),
    ("status", "", "drive state and measurements"),
    ("faults", "", "latched fault, its snapshot, warnings"),
    ("clear", "", "clear the fault once its cause is gone"),
    (
        "mode",
        "idle|run|short|open|align",
        "idle, open: gates off; run: harvest; short: phases shorted; align: find the angle",
    ),
    ("tel", "CH[,CH..] HZ|off", "stream channels as CSV t,v1,.."),
    (
        "measure",
        "[show|apply]",
        "measure R, L_d, L_q, K_e (idle, calibrated); show them; put them in RAM",
    ),
    (
        "cap",
        "[show|ch|div|pre|trig|arm|now|stop|dump]",
        "capture at the loop rate (help cap)",
    ),
    (
        "machine",
        "on|off",
        "machine-readable mode: tagged lines, #ID command ids",
    ),
];

/// A line from [`LineEditor::feed`].
pub type Line<'a> = &'a str;

/// The console's line editor: assembles received bytes into lines and echoes them, as a
/// terminal's line discipline would. CR, LF or CRLF end a line; Backspace/DEL erase a
/// character, Ctrl-U the line; escape sequences (arrow keys) and other control characters
/// are ignored. A line over [`LINE_MAX`] bytes or not UTF-8 is answered here with one
/// `error:` line and handed on empty (so the caller only writes the prompt).
#[derive(Clone, Debug)]
pub struct LineEditor {
    buf: [u8; LINE_MAX],
    len: usize,
    overlong: bool,
    cr: bool,
    /// Escape sequence state: 1 after ESC, 2 inside `ESC [`.
    esc: u8,
    /// The last line ended, as checked text (a `&str` without `core::str::from_utf8`, which
    /// with its 256-byte table is 0.6 KB of the board's flash).
    text: heapless::String<LINE_MAX>,
    /// Machine mode ([`LineEditor::set_machine`]): no echo, no editing.
    machine: bool,
    /// The last [`HISTORY`] lines entered (non-empty, each once in a row), a ring:
    /// `hist[(head + HISTORY - k) % HISTORY]` is the k-th most recent (k ≥ 1).
    hist: [heapless::String<LINE_MAX>; HISTORY],
    /// Next slot to write; lines stored (≤ [`HISTORY`]).
    head: usize,
    stored: usize,
    /// The history line shown (0: the line being typed).
    shown: usize,
}

/// Lines the editor remembers for the up/down arrow keys.
pub const HISTORY: usize = 4;

impl Default for LineEditor {
    fn default() -> Self {
        LineEditor {
            buf: [0; LINE_MAX],
            len: 0,
            overlong: false,
            cr: false,
            esc: 0,
            text: heapless::String::new(),
            machine: false,
            hist: Default::default(),
            head: 0,
            stored: 0,
            shown: 0,
        }
    }
}

impl LineEditor {
    pub fn new() -> LineEditor {
        LineEditor::default()
    }

    /// Machine mode (follow [`Console::machine`]): nothing is echoed and there is no editing:
    /// CR, LF or CRLF end a line, other control characters are dropped, and the `error:` of
    /// an overlong or non-UTF-8 line is a final reply `R <id> err …` (the id read from the
    /// line's start, `-` without one).
    pub fn set_machine(&mut self, on: bool) {
        self.machine = on;
    }

    /// One received byte; its echo goes to `out`. `Some(line)` when a line ended (empty for
    /// an empty line, or after an overlong / non-UTF-8 line, whose `error:` line is written).
    pub fn feed<W: Write>(&mut self, b: u8, out: &mut W) -> Option<Line<'_>> {
        let cr = core::mem::replace(&mut self.cr, b == b'\r');
        if self.machine {
            self.esc = 0;
            return match b {
                b'\n' if cr => None,
                b'\r' | b'\n' => self.end(out),
                0..=0x1f | 0x7f => None,
                _ => {
                    self.push(b);
                    None
                }
            };
        }
        if self.esc != 0 {
            // ESC X (two bytes) or ESC [ … final byte (0x40..=0x7e); ESC [ A and ESC [ B,
            // the up and down arrow keys, walk the history.
            if self.esc == 2 && (b == b'A' || b == b'B') {
                self.recall(b == b'A', out);
            }
            self.esc =
                if (self.esc == 1 && b == b'[') || (self.esc == 2 && !(0x40..=0x7e).contains(&b)) {
                    2
                } else {
                    0
                };
            return None;
        }
        match b {
            b'\n' if cr => None, // the LF of a CRLF
            b'\r' | b'\n' => {
                out.s("\r\n");
                self.end(out)
            }
            0x08 | 0x7f => {
                self.erase(out);
                None
            }
            0x15 => {
                while self.len > 0 {
                    self.erase(out);
                }
                self.overlong = false;
                None
            }
            0x1b => {
                self.esc = 1;
                None
            }
            0..=0x1f => None,
            _ => {
                if !self.push(b) {
                    return None;
                }
                // Echo whole characters: an ASCII byte at once, a multi-byte one when complete.
                let last = self.buf.get(self.char_start()..self.len).unwrap_or(&[]);
                if let Some((ch, k)) = utf8_first(last) {
                    if k == last.len() {
                        out.s(ch.encode_utf8(&mut [0; 4]));
                    }
                }
                None
            }
        }
    }

    /// Up (`older`) or down the history: the line on the terminal and in the editor becomes
    /// that entry (down past the newest: an empty line).
    fn recall<W: Write>(&mut self, older: bool, out: &mut W) {
        let k = if older {
            (self.shown + 1).min(self.stored)
        } else {
            self.shown.saturating_sub(1)
        };
        if k == self.shown {
            return;
        }
        self.shown = k;
        while self.len > 0 {
            self.erase(out);
        }
        self.overlong = false;
        if k > 0 {
            let e = &self.hist[(self.head + HISTORY - k) % HISTORY];
            let b = e.as_bytes();
            self.buf[..b.len()].copy_from_slice(b);
            self.len = b.len();
            out.s(e.as_str());
        }
    }

    /// Append a received byte; `false` (and the line marked overlong) when it is full.
    fn push(&mut self, b: u8) -> bool {
        if self.len == LINE_MAX {
            self.overlong = true;
            return false;
        }
        self.buf[self.len] = b;
        self.len += 1;
        true
    }

    /// A line ended: its text, or its `error:` line (an overlong or non-UTF-8 line) and an
    /// empty line.
    fn end<W: Write>(&mut self, out: &mut W) -> Option<Line<'_>> {
        let n = core::mem::replace(&mut self.len, 0);
        self.shown = 0;
        let raw = self.buf.get(..n).unwrap_or(&[]);
        let why = if core::mem::replace(&mut self.overlong, false) {
            "line longer than 128 characters"
        } else {
            self.text.clear();
            let mut rest = raw;
            loop {
                if rest.is_empty() {
                    self.remember();
                    return Some(self.text.as_str());
                }
                let Some((ch, k)) = utf8_first(rest) else {
                    break "line is not UTF-8";
                };
                let _ = self.text.push(ch);
                rest = rest.get(k..).unwrap_or(&[]);
            }
        };
        if self.machine {
            out.s("R ")
                .s(id_text(id_of(raw).unwrap_or(b"-")).as_str())
                .s(" err ");
        } else {
            out.s("error: ");
        }
        out.s(why).s("\r\n");
        Some("")
    }

    /// The line just ended (`text`) into the history, unless empty or the same as the newest.
    fn remember(&mut self) {
        self.shown = 0;
        if self.machine || self.text.trim().is_empty() {
            return;
        }
        let newest = (self.head + HISTORY - 1) % HISTORY;
        if self.stored > 0 && self.hist[newest] == self.text {
            return;
        }
        self.hist[self.head] = self.text.clone();
        self.head = (self.head + 1) % HISTORY;
        self.stored = (self.stored + 1).min(HISTORY);
    }

    /// Where the last character starts (its continuation bytes are `0b10xx_xxxx`).
    fn char_start(&self) -> usize {
        let mut i = self.len.saturating_sub(1);
        while i > 0 && self.buf[i] & 0xc0 == 0x80 && self.len - i < 4 {
            i -= 1;
        }
        i
    }

    /// Erase the last character (all its bytes) and on the terminal.
    fn erase<W: Write>(&mut self, out: &mut W) {
        if self.len > 0 {
            self.len = self.char_start();
            out.s("\x08 \x08");
        }
    }
}

/// The first character of `b` and its length in bytes, if `b` starts with a complete UTF-8
/// encoded character by the rules of `core::str::from_utf8` (shortest form, no surrogate,
/// nothing above U+10FFFF; `char::from_u32` checks the last two). The line editor's check,
/// tested against `from_utf8` over every sequence of up to three bytes and a sample of four.
fn utf8_first(b: &[u8]) -> Option<(char, usize)> {
    let &b0 = b.first()?;
    let (n, min, mut c) = match b0 {
        0x00..=0x7f => return Some((char::from(b0), 1)),
        0xc0..=0xdf => (2, 0x80, (b0 & 0x1f) as u32),
        0xe0..=0xef => (3, 0x800, (b0 & 0x0f) as u32),
        0xf0..=0xf7 => (4, 0x1_0000, (b0 & 0x07) as u32),
        _ => return None,
    };
    for &x in b.get(1..n)? {
        if x & 0xc0 != 0x80 {
            return None;
        }
        c = c << 6 | (x & 0x3f) as u32;
    }
    if c < min {
        return None;
    }
    char::from_u32(c).map(|ch| (ch, n))
}

/// What a store did with a `save`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Saved {
    /// Written.
    Done,
    /// Taken for writing by the caller of [`Console::execute`] (the board's flash is written
    /// asynchronously, awaited in the console's task): `execute` writes no reply, the caller
    /// writes it with [`save_reply`] and a line end once the write is done.
    Deferred,
}

/// The reply to a `save`: `ok saved` or `error: save failed: …`, without the line end.
fn save_reply<W: Write>(r: Result<(), &'static str>, out: &mut Out<'_, W>) -> CmdResult {
    match r {
        Ok(()) => {
            out.fin(true).s(" saved");
            Ok(())
        }
        Err(e) => {
            out.fin(false).s("save failed: ").s(e);
            Err(Refused)
        }
    }
}

/// The persistent store as the console sees it.
pub trait ParamStore {
    fn save(&mut self, cfg: &Config) -> Result<Saved, &'static str>;
    fn load(&mut self) -> Result<Config, &'static str>;
    /// What `defaults` restores: the factory configuration of this hardware. On the board
    /// that is [`Config::default`] (its scalings are the board's); a simulated drive returns
    /// its scenario's configuration, so that `defaults` never puts a board's ADC scalings on
    /// other hardware (a wrong bus scaling makes the loop over-drive and motor the machine).
    fn factory(&self) -> Config {
        Config::default()
    }
    /// The configuration the store holds: written by the last successful `save`, or found
    /// at boot (what `load` reads); `None` when it holds none (machine `list`'s `saved=`
    /// then compares with [`ParamStore::factory`]).
    fn held(&self) -> Option<Config> {
        None
    }
}

/// A store that refuses everything (no flash).
pub struct NoStore;
impl ParamStore for NoStore {
    fn save(&mut self, _: &Config) -> Result<Saved, &'static str> {
        Err("no persistent store")
    }
    fn load(&mut self) -> Result<Config, &'static str> {
        Err("no persistent store")
    }
}

/// A telemetry channel: name and unit; its value is [`channel_value`] of its index.
pub type Channel = (&'static str, &'static str);

pub static CHANNELS: &[Channel] = &[
    ("ia", "A"),
    ("ib", "A"),
    ("ic", "A"),
    ("id", "A"),
    ("iq", "A"),
    ("id_ref", "A"),
    ("iq_ref", "A"),
    ("vd", "V"),
    ("vq", "V"),
    ("vbus", "V"),
    ("w", "rad/s"),
    ("x", "m"),
    ("p", "W"),
];

/// The value of channel `i` (an index into [`CHANNELS`]) in telemetry `t`. One function
/// over one `Telemetry` per line, not a reader per channel each deriving the whole
/// telemetry (flash, and time per line).
pub fn channel_value(t: &Telemetry, i: usize) -> f32 {
    let v = match i {
        0 => t.i_abc[0],
        1 => t.i_abc[1],
        2 => t.i_abc[2],
        3 => t.i_dq.d,
        4 => t.i_dq.q,
        5 => t.i_ref.d,
        6 => t.i_ref.q,
        7 => t.v_dq.d,
        8 => t.v_dq.q,
        9 => t.v_bus,
        10 => t.omega_m,
        11 => t.x,
        _ => t.p_elec,
    };
    q_f32(v)
}

const MAX_CH: usize = 8;

/// Console state (telemetry selection, energy integrator, machine mode).
#[derive(Clone, Debug, Default)]
pub struct Console {
    /// Machine mode (`machine on`).
    machine: bool,
    /// The id of the command executed last (machine mode; `-` without one): a deferred
    /// `save`'s reply carries it ([`Console::save_done`]).
    id: Id,
    tel: [u8; MAX_CH],
    n_tel: usize,
    /// Periods between telemetry samples (0 = off).
    tel_every: u32,
    tel_count: u32,
    tel_periods: u64,
    /// Harvested energy since boot, J (compensated sum: exact to f32 rounding however long
    /// the run, see [`Console::tick`]).
    pub energy_j: f32,
    /// The compensation of the energy sum (Kahan).
    energy_c: f32,
    /// Power averaged with a 1 s time constant, W.
    pub p_avg_w: f32,
    /// Mean power over the last whole motion cycle.
    pub cycle: CycleMean,
    /// Code of the fault last announced by [`Console::notice`] (0: none).
    noticed: u8,
    /// The alignment state last announced by [`Console::notice`].
    boot_seen: crate::control::Boot,
    /// The capture's settings (`cap ch|div|pre|trig`), put in force by `cap arm`.
    cap: Settings,
    /// The capture state last announced ([`Console::notice_cap`]).
    cap_seen: State,
    /// A `cap dump` under way ([`Console::dump_more`]).
    dump: Option<Dump>,
}

/// A `cap dump` under way: the next sample and the id its lines carry (the rest, the
/// settings and the codes' units, is the capture's status, read per piece: kept here it would
/// be ≈ 110 bytes of the board's console task).
#[derive(Clone, Debug)]
struct Dump {
    next: u32,
    id: Id,
}

/// The longest line of a `cap dump` (a machine-mode `D` line with an 8-character id, the
/// time and four values is under 100 bytes): [`Console::dump_more`] starts a line only with
/// this much room left in its piece.
pub const DUMP_LINE_MAX: usize = 128;

/// Mean power over whole motion cycles: from one upward zero crossing of the shaft speed to
/// the next (with a hysteresis of ±[`CycleMean::ARM_RAD_S`], so that noise near standstill
/// cannot cut a cycle short). The harvested power of a vibration ripples at twice its
/// frequency; over a whole cycle the mean is exact, whatever the frequency, and it is new
/// once per cycle. For tuning a load over the console.
#[derive(Clone, Copy, Debug, Default)]
pub struct CycleMean {
    armed: bool,
    started: bool,
    /// Energy of the cycle so far, J, and its compensation (Kahan, as the energy counter).
    e_j: f32,
    e_c: f32,
    /// Periods of the cycle so far (exact: an f32 sum of the period drifts by 1e-3 over a
    /// cycle).
    n: u32,
    /// The last whole cycle's mean power (W) and length (s); `None` before the first.
    pub last: Option<(f32, f32)>,
}

impl CycleMean {
    /// Hysteresis of the zero-crossing detection, rad/s of shaft speed (0.4 mm/s of screw
    /// travel at the reference lead).
    pub const ARM_RAD_S: f32 = 1.0;

    /// One period of `ts` seconds with power `p` (W) at shaft speed `omega` (rad/s).
    pub fn add(&mut self, p: f32, omega: f32, ts: f32) {
        if omega < -Self::ARM_RAD_S {
            self.armed = true;
        } else if omega > Self::ARM_RAD_S && self.armed {
            self.armed = false;
            if self.started && self.n > 0 {
                let t = self.n as f32 * ts;
                self.last = Some((self.e_j / t, t));
            }
            self.started = true;
            self.e_j = 0.0;
            self.e_c = 0.0;
            self.n = 0;
        }
        kahan_add(&mut self.e_j, &mut self.e_c, p * ts);
        self.n = self.n.saturating_add(1);
    }
}

/// `*sum += x` with Kahan's compensation `c`: what each addition rounds away is carried to
/// the next, so the sum stays exact to f32 rounding however many small terms it takes.
fn kahan_add(sum: &mut f32, c: &mut f32, x: f32) {
    let y = x - *c;
    let t = *sum + y;
    *c = (t - *sum) - y;
    *sum = t;
}

/// Result of one command: `Ok` after an `ok` line, `Err` after an `error:` line.
pub type CmdResult = Result<(), Refused>;

/// The command was refused (its `error:` line has been written).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Refused;

/// A command's output. In the human console it is written as it is. In machine mode every
/// line is tagged: a data line gets `D <id> ` in front, the final line starts `R <id> ok` or
/// `R <id> err ` ([`Out::fin`]), and a line written with [`Out::raw`] set (the `H` header)
/// goes untouched. So a command's arm writes its text once, for both modes.
pub struct Out<'a, W> {
    w: &'a mut W,
    /// Machine mode.
    pub machine: bool,
    id: &'a str,
    /// At the start of a line.
    bol: bool,
    /// Write lines untagged (the final line, the `H` header).
    pub raw: bool,
}

impl<'a, W: Write> Out<'a, W> {
    pub fn new(w: &'a mut W, machine: bool, id: &'a str) -> Self {
        Out {
            w,
            machine,
            id,
            bol: true,
            raw: false,
        }
    }

    /// Start the final line: `ok` / `error: `, in machine mode `R <id> ok` / `R <id> err `
    /// (on a line of its own). The command's text follows; the line end is written by
    /// [`Console::execute`].
    #[inline(never)]
    pub fn fin(&mut self, ok: bool) -> &mut Self {
        if self.machine {
            if !self.bol {
                self.s("\r\n");
            }
            self.raw = true;
            let id = self.id;
            self.s("R ").s(id).s(if ok { " ok" } else { " err " })
        } else {
            self.s(if ok { "ok" } else { "error: " })
        }
    }
}

impl<W: Write> Write for Out<'_, W> {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        if !self.machine || self.raw {
            self.bol = s.ends_with('\n');
            return self.w.write_str(s);
        }
        // Each line that starts here gets its `D <id> ` (by bytes: no pattern search code).
        let mut rest = s;
        while !rest.is_empty() {
            let end = rest
                .bytes()
                .position(|b| b == b'\n')
                .map_or(rest.len(), |i| i + 1);
            if self.bol {
                self.w.write_str("D ")?;
                self.w.write_str(self.id)?;
                self.w.write_str(" ")?;
            }
            let (line, tail) = rest.split_at(end);
            self.w.write_str(line)?;
            self.bol = line.ends_with('\n');
            rest = tail;
        }
        Ok(())
    }
}

fn parse_f32(s: &str) -> Result<f32, NumError> {
    match s {
        "inf" | "+inf" => Ok(f32::INFINITY),
        // Only the literal `inf` means infinity: a finite literal too large for f32 (1e99)
        // or a spelled-out "infinity"/"nan" is refused, not rounded to ±inf.
        _ => numtext::parse_f32(s),
    }
}

impl Console {
    pub fn new() -> Console {
        Console::default()
    }

    /// Whether telemetry streaming is on.
    pub fn streaming(&self) -> bool {
        self.tel_every != 0
    }

    /// Kahan summation: a period's energy (~1e-3 J) falls below half the f32 resolution of a
    /// total past ~8 kJ; the compensation carries what each addition rounds away.
    fn add_energy(&mut self, de: f32) {
        kahan_add(&mut self.energy_j, &mut self.energy_c, de);
    }

    /// Call once per current-loop period after `ctl.step`: integrates energy and writes a
    /// telemetry line when one is due.
    pub fn tick<W: Write>(&mut self, ctl: &Controller, out: &mut W) {
        let ts = ctl.config().ts();
        let t = ctl.telemetry();
        let p = q_f32(t.p_elec);
        self.add_energy(p * ts);
        if ctl.mode() == Mode::Run {
            self.p_avg_w += (p - self.p_avg_w) * ts.min(1.0);
            self.cycle.add(p, q_f32(t.omega_m), ts);
        } else {
            // Outside `run` no load is emulated: the averages start again in the next run.
            self.p_avg_w = 0.0;
            self.cycle = CycleMean::default();
        }
        if self.tel_every == 0 {
            return;
        }
        self.tel_periods += 1;
        self.tel_count += 1;
        if self.tel_count >= self.tel_every {
            self.tel_count = 0;
            if self.machine {
                out.s("T ");
            }
            out.fixed(self.tel_periods as f32 * ts, 6);
            for &i in &self.tel[..self.n_tel] {
                out.s(",").num(channel_value(&t, i as usize));
            }
            out.s("\r\n");
        }
    }

    /// The start of a line of an unsolicited notice: `N ` in machine mode, `# ` (a comment
    /// for CSV readers) in the human console. A notice in the human console starts with a
    /// line end (the prompt's line) and ends with the prompt ([`Console::prompt`]).
    pub fn note<'w, W: Write>(&self, out: &'w mut W) -> &'w mut W {
        out.s(if self.machine { "N " } else { "# " })
    }

    /// The greeting, on connection (board: at boot): version, drive state, how to get help,
    /// then the prompt.
    pub fn banner<W: Write>(mode: Mode, fault: Option<Fault>, out: &mut W) {
        out.s("\r\nregen-fw ")
            .s(env!("CARGO_PKG_VERSION"))
            .s(" console. drive: mode ")
            .s(mode.name())
            .s(", fault ")
            .s(fault.map_or("none", |f| f.name()))
            .s(". type help\r\n")
            .s(PROMPT);
    }

    /// Announce a fault the moment it is seen latched (call after [`Console::tick`], with
    /// output that is never dropped): `# fault CODE NAME: what; now in mode M (faults: details)`
    /// and the prompt. Once per latched fault; `true` when something was written. Then the
    /// alignment's states, once each: `# aligning`, `# aligned: …` with the angle found and
    /// how, or `# alignment gave up: FAULT` (docs/protection.md, "Power-up").
    pub fn notice<W: Write>(&mut self, ctl: &Controller, out: &mut W) -> bool {
        let wrote = self.notice_fault(ctl, out);
        self.notice_align(ctl, out) | wrote
    }

    fn notice_align<W: Write>(&mut self, ctl: &Controller, out: &mut W) -> bool {
        use crate::control::{AlignMethod, Boot};
        let b = ctl.boot();
        let was = core::mem::replace(&mut self.boot_seen, b);
        if b == was {
            return false;
        }
        match (b, ctl.aligned_by()) {
            (Boot::Aligning, _) => {
                out.s("\r\n# aligning\r\n");
            }
            (Boot::Aligned, by) => {
                let deg = ctl.angle_offset().0 as f32 * (360.0 / 4_294_967_296.0);
                out.s("\r\n# aligned: angle ")
                    .num(deg)
                    .s(" deg electrical, ");
                match by {
                    Some(AlignMethod::Emf { ratio, omega_m }) => out
                        .s("from the emf at ")
                        .num(omega_m)
                        .s(" rad/s (encoder/emf travel ")
                        .num(ratio)
                        .s(")\r\n"),
                    _ => out.s("from the d-axis steps\r\n"),
                };
            }
            _ if was == Boot::Aligning => {
                out.s("\r\n# alignment gave up: ")
                    .s(ctl.fault().map_or("stopped by a mode change", |f| f.name()))
                    .s("\r\n");
            }
            _ => return false,
        }
        out.s(PROMPT);
        true
    }

    fn notice_fault<W: Write>(&mut self, ctl: &Controller, out: &mut W) -> bool {
        let f = ctl.fault();
        let code = f.map_or(0, |f| f.code() + 1);
        if code == self.noticed {
            return false;
        }
        self.noticed = code;
        match f {
            Some(f) => {
                if !self.machine {
                    out.s("\r\n");
                }
                write_fault(self.note(out).s("fault "), "", f);
                self.note(out)
                    .s("now in mode ")
                    .s(ctl.mode().name())
                    .s(" (faults: details)\r\n")
                    .s(self.prompt());
                true
            }
            None => false,
        }
    }

    /// Execute one line. Writes one or more lines to `out`, the last starting `ok` or `error:`.
    /// Never inlined: the board calls it from an async task, whose state machine would
    /// otherwise take a copy of the whole executor (measured: +3.8 KB of flash).
    /// In machine mode a line may start with `#ID ` ([`ID_MAX`] letters or digits at most);
    /// the reply's `D` and `R` lines carry ID (`-` without one).
    pub fn execute<W: Write, S: ParamStore>(
        &mut self,
        line: &str,
        ctl: &mut Controller,
        store: &mut S,
        out: &mut W,
    ) -> CmdResult {
        self.execute_cap(line, ctl, store, None::<&mut Capture<1>>, out)
    }

    /// [`Console::execute`] on a drive with a capture (`cap`; without one `cap` is refused).
    /// A `cap dump` writes its header here and returns without its final line:
    /// [`Console::dump_more`] writes the samples and the final line in pieces.
    #[inline(never)]
    pub fn execute_cap<W: Write, S: ParamStore, C: CapPort>(
        &mut self,
        line: &str,
        ctl: &mut Controller,
        store: &mut S,
        cap: Option<&mut C>,
        out: &mut W,
    ) -> CmdResult {
        // A line received while a `cap dump` is being written: see `dump_interrupt`.
        self.dump_interrupt(line, out);
        let (id, line) = match self.split_id(line) {
            Some(x) => x,
            None => {
                self.id = id_text(b"-");
                self.final_line(
                    false,
                    "command id must be 1 to 8 ASCII letters or digits after #",
                    out,
                );
                return Err(Refused);
            }
        };
        self.id = id_text(id.as_bytes());
        let id = self.id.clone();
        let mut o = Out::new(out, self.machine, &id);
        let r = match self.command(line, ctl, store, cap, &mut o) {
            // An empty line: nothing, in machine mode as well unless it carried an id.
            None if line.trim().is_empty() && self.machine && id != "-" => {
                o.fin(false).s("empty command");
                Some(Err(Refused))
            }
            r => r,
        };
        match r {
            None => Ok(()), // empty line, a deferred save or a dump: nothing yet
            Some(r) => {
                o.raw = true;
                o.s("\r\n"); // the end of the `ok`/`error:` line, in one place (flash)
                r
            }
        }
    }

    /// Machine mode: whether the console reads `#ID` command ids and tags its lines.
    pub fn machine(&self) -> bool {
        self.machine
    }

    /// Switch machine mode (a host that sees a new reader starts it in the human console).
    pub fn set_machine(&mut self, on: bool) {
        self.machine = on;
    }

    /// The prompt after a reply: [`PROMPT`], none in machine mode.
    pub fn prompt(&self) -> &'static str {
        if self.machine {
            ""
        } else {
            PROMPT
        }
    }

    /// A line's command id and the command: in machine mode `#ID CMD…` gives `(ID, CMD…)`,
    /// a line without `#` `("-", line)`, a malformed id `None`; in the human console
    /// `("-", line)`. For a host answering a command of its own in front of the console.
    pub fn split_id<'l>(&self, line: &'l str) -> Option<(&'l str, &'l str)> {
        let t = line.trim_start_matches([' ', '\t']);
        if !self.machine || !t.starts_with('#') {
            return Some(("-", line));
        }
        let id = id_of(t.as_bytes())?;
        let n = id.len() + 1;
        Some((t.get(1..n)?, t.get(n..)?))
    }

    /// A final reply line written by a host for a command of its own (`regen serve`'s
    /// `sim`): `ok TEXT` / `error: TEXT`, in machine mode `R <id> ok TEXT` / `R <id> err
    /// TEXT` with the id [`Console::split_id`] gave; `text` starts with a space after `ok`.
    pub fn host_reply<W: Write>(&self, id: &str, ok: bool, text: &str, out: &mut W) {
        let mut o = Out::new(out, self.machine, id);
        o.fin(ok).s(text);
        o.raw = true;
        o.s("\r\n");
    }

    /// A final reply line for the command executed last (its id in machine mode): the
    /// board's `reply truncated`.
    pub fn final_line<W: Write>(&self, ok: bool, text: &str, out: &mut W) {
        self.host_reply(self.id.as_str(), ok, text, out);
    }

    /// The reply to a deferred `save` ([`Saved::Deferred`]) once the caller has written the
    /// flash: `ok saved` or `error: save failed: …` (tagged with the command's id in
    /// machine mode) and its line end.
    pub fn save_done<W: Write>(&self, r: Result<(), &'static str>, out: &mut W) -> CmdResult {
        let id = self.id.clone();
        let mut o = Out::new(out, self.machine, &id);
        let res = save_reply(r, &mut o);
        o.raw = true;
        o.s("\r\n");
        res
    }

    /// [`Console::execute`] but the last line's end; `None` for an empty line.
    fn command<W: Write, S: ParamStore, C: CapPort>(
        &mut self,
        line: &str,
        ctl: &mut Controller,
        store: &mut S,
        cap: Option<&mut C>,
        out: &mut Out<'_, W>,
    ) -> Option<CmdResult> {
        let machine = out.machine;
        let mut it = line.split_ascii_whitespace();
        let cmd = it.next()?;
        let a1 = it.next();
        let a2 = it.next();
        let extra = it.next().is_some();
        let running = ctl.mode() == Mode::Run;
        // The store rule (docs/console.md): `save`, `load`, `defaults` while the bridge is
        // live, in `run` or `align`, are refused.
        let busy = running || ctl.mode() == Mode::Align;
        // `fail!(.s("…").num(v)…)`: one `error: …` line, refused. `ok!(…)`: one `ok…` line
        // (its line end is written by `execute`).
        // The text is written piece by piece (`Put`), not through `write!`.
        macro_rules! fail {
            ($($t:tt)*) => {{
                out.fin(false) $($t)*;
                return Some(Err(Refused));
            }};
        }
        macro_rules! ok {
            ($($t:tt)*) => {{
                out.fin(true) $($t)*;
                return Some(Ok(()));
            }};
        }
        let nargs = a1.is_some() as usize + a2.is_some() as usize + extra as usize;
        let want = |n: usize| nargs == n;
        match cmd {
            "help" if nargs <= 1 => {
                let mut n = 0;
                for c in COMMANDS {
                    if a1.is_none_or(|a| a == c.0) {
                        out.col(c.0, 9).col(c.1, 20).s(c.2).s("\r\n");
                        n += 1;
                    }
                }
                if n == 0 {
                    fail!(.s("no command '").clip(a1.unwrap_or("")).s("' (help lists them)"))
                }
                if a1 == Some("cap") {
                    for (c, what) in CAP_HELP {
                        out.s("  cap ").col(c, 24).s(what).s("\r\n");
                    }
                }
                if a1.is_none_or(|a| a == "tel" || a == "cap") {
                    out.s("tel channels:");
                    for ch in CHANNELS {
                        out.s(" ").s(ch.0).s("[").s(ch.1).s("]");
                    }
                    out.s("\r\n");
                }
                ok!()
            }
            "list" if nargs <= 1 => {
                let pat = a1.unwrap_or("").as_bytes();
                let hit = |p: &&params::Param| {
                    pat.is_empty() || p.name.as_bytes().windows(pat.len()).any(|w| w == pat)
                };
                let n = PARAMS.iter().filter(hit).count();
                if n == 0 {
                    fail!(.s("no parameter name contains '").clip(a1.unwrap_or("")).s("' (list shows all)"))
                }
                let c = ctl.config();
                // The default column is what `defaults` restores on this hardware.
                let f = store.factory();
                if machine {
                    // `saved=`: against what the flash holds, or the factory configuration.
                    let held = store.held().unwrap_or(f);
                    for p in PARAMS.iter().filter(hit) {
                        let u = p.unit();
                        out.s("name=")
                            .s(p.name)
                            .s(" value=")
                            .num(p.get(c))
                            .s(" unit=")
                            .s(if u.is_empty() { "-" } else { u })
                            .s(" min=")
                            .num(p.min)
                            .s(" max=")
                            .num(p.max)
                            .s(" default=")
                            .num(p.get(&f))
                            .s(if p.runtime { " when=rt" } else { " when=idle" })
                            .s(if p.get(c) != p.get(&held) {
                                " saved=changed\r\n"
                            } else {
                                " saved=yes\r\n"
                            });
                    }
                    ok!(.s(" ").uint(n as u32).s(" params"))
                }
                // Each column as wide as its widest text among the rows shown, then two
                // spaces (a first pass measures them).
                let range_of = |p: &params::Param| {
                    let mut range = heapless::String::<40>::new();
                    let _ = range.push_str(Num(p.min).text().as_str());
                    let _ = range.push_str(" .. ");
                    let _ = range.push_str(Num(p.max).text().as_str());
                    range
                };
                let mut w = [4, 5, 4, 5, 7]; // the headers' lengths
                for p in PARAMS.iter().filter(hit) {
                    for (k, n) in [
                        p.name.len(),
                        Num(p.get(c)).text().as_str().len(),
                        p.unit().len(),
                        range_of(p).len(),
                        Num(p.get(&f)).text().as_str().len(),
                    ]
                    .into_iter()
                    .enumerate()
                    {
                        w[k] = w[k].max(n + 2);
                    }
                }
                out.col("name", w[0])
                    .col("value", w[1])
                    .col("unit", w[2])
                    .col("range", w[3])
                    .col("default", w[4])
                    .s("set  description\r\n");
                for p in PARAMS.iter().filter(hit) {
                    out.col(p.name, w[0])
                        .col(Num(p.get(c)).text().as_str(), w[1])
                        .col(p.unit(), w[2])
                        .col(range_of(p).as_str(), w[3])
                        .col(Num(p.get(&f)).text().as_str(), w[4])
                        .s(if p.runtime { "rt   " } else { "idle " })
                        .s(p.desc())
                        .s("\r\n");
                }
                ok!(.s(" ").uint(n as u32).s(" of ").uint(PARAMS.len() as u32))
            }
            "get" if want(1) => {
                let n = a1.unwrap_or("");
                match params::find(n) {
                    Some(p) => {
                        ok!(.s(" ").s(p.name).s(" = ").num(p.get(ctl.config())).s(" ").s(p.unit()))
                    }
                    None => {
                        fail!(.s("unknown parameter '").clip(n).s("'").hint(nearest(n, PARAMS.iter().map(|p| p.name))).s(" (try list)"))
                    }
                }
            }
            "set" if want(2) => {
                let n = a1.unwrap_or("");
                let vs = a2.unwrap_or("");
                let Some(p) = params::find(n) else {
                    fail!(.s("unknown parameter '").clip(n).s("'").hint(nearest(n, PARAMS.iter().map(|p| p.name))).s(" (try list)"))
                };
                let mut c = *ctl.config();
                // The reason, and for a refused configuration the field it conflicts with.
                let why = match parse_f32(vs) {
                    Err(e) => Err(("", e.as_str())),
                    Ok(v) => match p.apply(&mut c, v, running) {
                        Ok(()) => ctl.set_config(&c).map_err(|e| (e.field, e.reason)),
                        Err(ParamError::Invalid(field, why)) => Err((field, why)),
                        Err(e) => Err(("", e.message())),
                    },
                };
                if let Err((field, why)) = why {
                    fail!(.s(p.name)
                        .s(" ")
                        .clip(vs)
                        .s(": ")
                        .s(field)
                        .s(if field.is_empty() { "" } else { ": " })
                        .s(why)
                        .s("; allowed ")
                        .num(p.min)
                        .s(" .. ")
                        .num(p.max)
                        .s(" ")
                        .s(p.unit())
                        .laws(p.kind == params::Kind::Law)
                        .s(", now ")
                        .num(p.get(ctl.config())))
                }
                ok!(.s(" ").s(p.name).s(" = ").num(p.get(ctl.config())).s(" ").s(p.unit()))
            }
            "save" if want(0) => {
                if busy {
                    fail!(.s("save refused in mode ").s(ctl.mode().name()).s(" (mode idle first): a configuration is stored between runs, not half way through a run's changes"))
                }
                match store.save(ctl.config()) {
                    Ok(Saved::Done) => Some(save_reply(Ok(()), out)),
                    // The caller completes the write and the reply (`save_done`).
                    Ok(Saved::Deferred) => None,
                    Err(e) => Some(save_reply(Err(e), out)),
                }
            }
            "load" | "defaults" if want(0) => {
                if busy {
                    fail!(.s(cmd).s(" refused in mode ").s(ctl.mode().name()).s(" (mode idle first): it changes parameters that may not change while the bridge is live"))
                }
                let c = if cmd == "load" {
                    match store.load() {
                        Ok(c) => c,
                        Err(e) => fail!(.s("load failed: ").s(e)),
                    }
                } else {
                    store.factory()
                };
                match ctl.set_config(&c) {
                    Ok(()) => ok!(.s(" ").s(cmd)),
                    Err(e) => fail!(.s(e.field).s(": ").s(e.reason)),
                }
            }
            "status" if want(0) && machine => {
                let t = ctl.telemetry();
                let run = running;
                out.s("mode=")
                    .s(ctl.mode().name())
                    .s(" boot=")
                    .s(ctl.boot().name())
                    .s(" fault=")
                    .s(ctl.fault().map_or("none", |f| f.name()));
                let cycle = self.cycle.last.filter(|_| run);
                for (key, v, power) in [
                    ("vbus_v", Some(q_f32(t.v_bus)), false),
                    ("speed_rad_s", Some(q_f32(t.omega_m)), false),
                    ("travel_m", Some(q_f32(t.x)), false),
                    ("id_a", Some(q_f32(t.i_dq.d)), false),
                    ("iq_a", Some(q_f32(t.i_dq.q)), false),
                    ("p_w", Some(q_f32(t.p_elec)), true),
                    ("p_avg_w", Some(self.p_avg_w), true),
                    ("p_cycle_w", cycle.map(|c| c.0), true),
                    ("cycle_s", cycle.map(|c| c.1), true),
                    ("energy_j", Some(self.energy_j), false),
                ] {
                    out.s(" ").s(key).s("=");
                    // Power figures mean nothing outside `run` (no load emulated).
                    match v {
                        Some(v) if run || !power => out.num(v),
                        _ => out.s("-"),
                    };
                }
                out.s(" warnings=");
                write_warnings(out, ctl.protection().warnings);
                out.s("\r\n");
                ok!()
            }
            "status" if want(0) => {
                let t = ctl.telemetry();
                let run = running;
                out.col("mode", 10).s(ctl.mode().name());
                out.s("\r\n")
                    .col("fault", 10)
                    .s(ctl.fault().map_or("none", |f| f.name()));
                out.s("\r\n").col("boot", 10).s(ctl.boot().name());
                for (label, v, unit) in [
                    ("vbus", q_f32(t.v_bus), "V"),
                    ("speed", q_f32(t.omega_m), "rad/s"),
                    ("travel", q_f32(t.x), "m"),
                    ("id", q_f32(t.i_dq.d), "A"),
                    ("iq", q_f32(t.i_dq.q), "A"),
                    ("p", q_f32(t.p_elec), "W"),
                    ("p_avg", self.p_avg_w, "W"),
                ] {
                    out.s("\r\n").col(label, 10);
                    // Power figures mean nothing outside `run` (no load emulated).
                    if run || unit != "W" {
                        out.eng(v, unit);
                    } else {
                        out.s("-");
                    }
                }
                out.s("\r\n").col("p_cycle", 10);
                match self.cycle.last {
                    Some((pw, t)) if run => {
                        out.eng(pw, "W").s(" over ").eng(t, "s");
                    }
                    _ => {
                        out.s(if run { "- (no whole cycle yet)" } else { "-" });
                    }
                }
                out.s("\r\n").col("energy", 10).eng(self.energy_j, "J");
                out.s("\r\n").col("warnings", 10);
                write_warnings(out, ctl.protection().warnings);
                out.s("\r\n");
                ok!()
            }
            "faults" if want(0) => {
                let p = ctl.protection();
                out.s("warnings: ");
                write_warnings(out, p.warnings);
                out.s(" i2t=")
                    .fixed(p.i2t(), 4)
                    .s(" force_filt=")
                    .fixed(p.force_n(), 0)
                    .s("N derate=")
                    .fixed(q_f32(p.derate), 3)
                    .s("\r\n");
                match ctl.fault() {
                    Some(f) => {
                        write_fault(out, "fault ", f);
                        out.s("safe state: ").s(safe_words(f.safe_mode())).s("\r\n");
                        if let Some(r) = p.record() {
                            let s = &r.snap;
                            out.s("at t=")
                                .uint(s.t_ms)
                                .s(" ms in mode ")
                                .s(s.mode.name())
                                .s(": ia=")
                                .fixed(q_f32(s.i_abc[0]), 3)
                                .s(" ib=")
                                .fixed(q_f32(s.i_abc[1]), 3)
                                .s(" ic=")
                                .fixed(q_f32(s.i_abc[2]), 3)
                                .s(" A id=")
                                .fixed(q_f32(s.i_dq.d), 3)
                                .s(" iq=")
                                .fixed(q_f32(s.i_dq.q), 3)
                                .s(" A vbus=")
                                .fixed(q_f32(s.v_bus), 2)
                                .s(" V w=")
                                .fixed(q_f32(s.omega_m), 2)
                                .s(" rad/s x=")
                                .fixed(q_f32(s.x), 4)
                                .s(" m force=")
                                .fixed(s.force_n, 0)
                                .s(" N i2t=")
                                .fixed(s.i2t, 4)
                                .s(" derate=")
                                .fixed(s.derate, 3)
                                .s("\r\n");
                            for g in r.later() {
                                write_fault(out, "later: ", g);
                            }
                        }
                        out.s("now in mode ").s(ctl.mode().name()).s("\r\n");
                        ok!(.s(" fault ").s(f.name()).s(" (safe mode ").s(f.safe_mode().name()).s(")"))
                    }
                    None => ok!(.s(" no fault")),
                }
            }
            "clear" if want(0) => match (ctl.fault(), ctl.clear_fault()) {
                (None, _) => ok!(.s(" no fault")),
                (Some(f), Ok(())) => ok!(.s(" cleared ").s(f.name())),
                (Some(f), Err(why)) => fail!(.s(f.name()).s(" not cleared: ").s(why)),
            },
            "mode" if want(1) => {
                let m = match a1.unwrap_or("") {
                    "idle" => Mode::Idle,
                    "run" => Mode::Run,
                    "short" => Mode::Short,
                    "open" => Mode::Open,
                    "align" => Mode::Align,
                    o => fail!(.s("unknown mode '").clip(o).s("' (idle|run|short|open|align)")),
                };
                match ctl.set_mode(m) {
                    Ok(()) => ok!(.s(" mode ").s(m.name())),
                    Err(ModeError::Fault(f)) => {
                        fail!(.s("fault ").s(f.name()).s(" latched: clear it first"))
                    }
                    Err(e) => fail!(.s("mode ").s(m.name()).s(" refused: ").s(e.name())),
                }
            }
            "measure" if nargs <= 1 => Some(crate::commission::command(ctl, a1, out)),
            "cap" => match cap {
                Some(cap) => self.cap_command(line, ctl, cap, out),
                None => fail!(.s("cap: this drive has no capture")),
            },
            "tel" if want(1) && a1 == Some("off") => {
                self.tel_every = 0;
                ok!(.s(" tel off"))
            }
            "tel" if want(2) => {
                let mut sel = [0u8; MAX_CH];
                let mut n = 0;
                // The names between commas (as `split(',')`, by bytes: no pattern search code
                // in the image).
                let mut rest = Some(a1.unwrap_or(""));
                while let Some(list) = rest {
                    let comma = list.bytes().position(|b| b == b',');
                    let name = list.get(..comma.unwrap_or(list.len())).unwrap_or("");
                    rest = comma.and_then(|c| list.get(c + 1..));
                    let Some(i) = channel_of(name) else {
                        fail!(.s("unknown channel '").clip(name).s("' (see help)"))
                    };
                    if n == MAX_CH {
                        fail!(.s("at most ").uint(MAX_CH as u32).s(" channels"))
                    }
                    sel[n] = i;
                    n += 1;
                }
                let rate = match parse_f32(a2.unwrap_or("")) {
                    Ok(r) if r.is_finite() && r > 0.0 => r,
                    _ => fail!(.s("rate must be a positive number of Hz")),
                };
                let pwm = ctl.config().pwm_hz;
                if rate > pwm.min(2_000.0) {
                    fail!(.s("rate must be <= ").num(pwm.min(2_000.0)).s(" Hz"))
                }
                let every = pwm / rate;
                if every > 1.0e8 {
                    fail!(.s("rate too low"))
                }
                self.tel = sel;
                self.n_tel = n;
                self.tel_every = (every as u32).max(1);
                self.tel_count = 0;
                self.tel_periods = 0;
                // The header: a comment line, in machine mode an `H` line.
                out.raw = true;
                out.s(if machine { "H t" } else { "# tel t" });
                for &i in &sel[..n] {
                    if let Some(ch) = CHANNELS.get(i as usize) {
                        out.s(",").s(ch.0);
                    }
                }
                out.s("\r\n");
                out.raw = false;
                ok!(.s(" tel ").num(pwm / self.tel_every as f32).s(" Hz"))
            }
            "machine" if want(1) => {
                let on = match a1 {
                    Some("on") => true,
                    Some("off") => false,
                    _ => fail!(.s("machine on|off")),
                };
                // Switched before the reply: `machine on` is answered in machine form,
                // `machine off` in the human console's.
                self.machine = on;
                out.machine = on;
                ok!(.s(if on { " machine on" } else { " machine off" }))
            }
            _ if COMMANDS.iter().any(|c| c.0 == cmd) => {
                let c = COMMANDS.iter().find(|c| c.0 == cmd).unwrap_or(&COMMANDS[0]);
                fail!(.s("usage: ").s(c.0).s(" ").s(c.1))
            }
            _ => {
                fail!(.s("unknown command '").clip(cmd).s("'").hint(nearest(cmd, COMMANDS.iter().map(|c| c.0))).s(" (see help)"))
            }
        }
    }
}

/// `help cap`: the `cap` commands.
static CAP_HELP: &[(&str, &str)] = &[
    ("show", "the state and settings, one line (also: cap)"),
    (
        "ch CH[,CH..]",
        "1 to 4 channels (not while armed or triggered)",
    ),
    ("div N", "a sample every N-th period, 1 .. 1000"),
    ("pre PCT", "share kept from before the trigger, 0 .. 100 %"),
    (
        "trig fault|cmd",
        "trigger on a fault latching, or on cap now only",
    ),
    (
        "trig CH rise|fall|both L",
        "trigger on CH crossing level L (its unit)",
    ),
    ("arm", "start recording (discards what is held)"),
    ("now", "trigger an armed capture now"),
    ("stop", "back to idle, samples discarded"),
    (
        "dump",
        "a ready capture as CSV: t (s from the trigger), the channels",
    ),
];

/// A `fmt::Write` sink that counts what passes through it.
struct Counted<'a, W> {
    w: &'a mut W,
    n: usize,
}

impl<W: Write> Write for Counted<'_, W> {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        self.n += s.len();
        self.w.write_str(s)
    }
}

/// A channel's index into [`CHANNELS`] by its name.
fn channel_of(name: &str) -> Option<u8> {
    CHANNELS.iter().position(|c| c.0 == name).map(|i| i as u8)
}

impl Console {
    /// `cap …` (the words after `cap` read again from `line`: `cap trig` takes three).
    fn cap_command<W: Write, C: CapPort>(
        &mut self,
        line: &str,
        ctl: &Controller,
        cap: &mut C,
        out: &mut Out<'_, W>,
    ) -> Option<CmdResult> {
        let mut w = line.split_ascii_whitespace();
        let _ = w.next();
        let sub = w.next().unwrap_or("show");
        let args = [w.next(), w.next(), w.next()];
        let extra = w.next().is_some();
        let n = args.iter().filter(|a| a.is_some()).count() + extra as usize;
        let st = cap.status();
        let busy = st.state == State::Armed || st.state == State::Triggered;
        macro_rules! fail {
            ($($t:tt)*) => {{
                out.fin(false) $($t)*;
                return Some(Err(Refused));
            }};
        }
        let a = args[0].unwrap_or("");
        let want = match sub {
            "show" | "arm" | "now" | "stop" | "dump" => 0,
            "ch" | "div" | "pre" => 1,
            "trig" if matches!(a, "fault" | "cmd") => 1,
            "trig" => 3,
            _ => {
                fail!(.s("usage: cap [show|ch|div|pre|trig|arm|now|stop|dump]"))
            }
        };
        if n != want {
            let u = CAP_HELP
                .iter()
                .find(|h| h.0.starts_with(sub))
                .map_or("", |h| h.0);
            fail!(.s("usage: cap ").s(u))
        }
        if busy && matches!(sub, "ch" | "div" | "pre" | "trig") {
            fail!(.s("cap ").s(sub).s(" ").clip(a).s(" refused: capture ").s(st.state.name()).s(" (cap stop first)"))
        }
        let mut set = self.cap;
        match sub {
            "ch" => {
                let mut k = 0;
                let mut rest = Some(a);
                while let Some(list) = rest {
                    let comma = list.bytes().position(|b| b == b',');
                    let name = list.get(..comma.unwrap_or(list.len())).unwrap_or("");
                    rest = comma.and_then(|c| list.get(c + 1..));
                    let Some(i) = channel_of(name) else {
                        fail!(.s("cap ch ").clip(a).s(": unknown channel '").clip(name).s("'; allowed 1 to 4 of").chans())
                    };
                    if k == capture::CH_MAX {
                        fail!(.s("cap ch ").clip(a).s(": more than 4 channels; allowed 1 to 4 of").chans())
                    }
                    set.ch[k] = i;
                    k += 1;
                }
                set.n_ch = k as u8;
            }
            "div" | "pre" => {
                let (max, now) = if sub == "div" {
                    (capture::DIV_MAX as u32, set.div as u32)
                } else {
                    (100, set.pre_pct as u32)
                };
                let min = (sub == "div") as u32;
                let v = match numtext::parse_f32(a) {
                    Ok(v)
                        if v.is_finite()
                            && v >= min as f32
                            && v <= max as f32
                            && v == (v as u32) as f32 =>
                    {
                        v as u32
                    }
                    _ => {
                        fail!(.s("cap ").s(sub).s(" ").clip(a).s(": not an integer in range; allowed ").uint(min).s(" .. ").uint(max).s(if sub == "pre" { " %" } else { "" }).s(", now ").uint(now))
                    }
                };
                if sub == "div" {
                    set.div = v as u16;
                } else {
                    set.pre_pct = v as u8;
                }
            }
            "trig" => {
                set.trig = match (a, args[1], args[2]) {
                    ("fault", None, None) => Trigger::Fault,
                    ("cmd", None, None) => Trigger::Cmd,
                    (name, Some(e), Some(l)) => {
                        let Some(ch) = channel_of(name) else {
                            fail!(.s("cap trig ").clip(name).s(": unknown channel; allowed fault, cmd, or CH rise|fall|both LEVEL with CH one of").chans())
                        };
                        let edge = match e {
                            "rise" => Edge::Rise,
                            "fall" => Edge::Fall,
                            "both" => Edge::Both,
                            _ => {
                                fail!(.s("cap trig ").s(name).s(" ").clip(e).s(": unknown edge; allowed rise, fall, both"))
                            }
                        };
                        let (lo, hi) = capture::level_range(ch, ctl.gains());
                        let unit = CHANNELS.get(ch as usize).map_or("", |c| c.1);
                        match numtext::parse_f32(l) {
                            Ok(v) if v.is_finite() && v >= lo && v <= hi => {
                                Trigger::Level { ch, edge, level: v }
                            }
                            _ => {
                                fail!(.s("cap trig ").s(name).s(" ").s(e).s(" ").clip(l).s(": level out of range; allowed ").num(lo).s(" .. ").num(hi).s(" ").s(unit))
                            }
                        }
                    }
                    _ => fail!(.s("usage: cap trig fault|cmd|CH rise|fall|both LEVEL")),
                };
            }
            "arm" => {
                cap.arm(
                    &self.cap,
                    self.cap.div as f32 / ctl.config().pwm_hz,
                    ctl.gains(),
                );
                self.cap_seen = State::Armed;
            }
            // (`trigger_now` arms the command trigger when the capture is armed.)
            "now" if !cap.trigger_now() => {
                fail!(.s("cap now refused: capture ").s(st.state.name()).s("; allowed only when armed (cap arm)"))
            }
            "stop" => {
                cap.stop();
                self.cap_seen = State::Idle;
            }
            "dump" => {
                if st.state != State::Ready {
                    fail!(.s("cap dump refused: capture ").s(st.state.name()).s("; allowed only when ready (cap arm, then wait for ready)"))
                }
                out.s("# cap dt_s=")
                    .num(st.dt_s)
                    .s(" n=")
                    .uint(st.len)
                    .s(" pre=")
                    .uint(st.pre_n)
                    .s(" trig=")
                    .trig(&st.set.trig)
                    .s("\r\nt");
                for &c in st.set.channels() {
                    out.s(",").s(CHANNELS.get(c as usize).map_or("?", |c| c.0));
                }
                out.s("\r\n");
                self.dump = Some(Dump {
                    next: 0,
                    id: self.id.clone(),
                });
                return None;
            }
            _ => {}
        }
        self.cap = set;
        // The status line, then `ok`.
        let st = cap.status();
        let (shown, dt) = if st.state == State::Idle {
            (self.cap, self.cap.div as f32 / ctl.config().pwm_hz)
        } else {
            (st.set, st.dt_s)
        };
        out.s("cap ").s(st.state.name()).s(" ch=");
        for (k, &c) in shown.channels().iter().enumerate() {
            out.s(if k == 0 { "" } else { "," })
                .s(CHANNELS.get(c as usize).map_or("?", |c| c.0));
        }
        out.s(" div=")
            .uint(shown.div as u32)
            .s(" dt_s=")
            .num(dt)
            .s(" n=")
            .uint(st.held)
            .s(" pre=")
            .uint(shown.pre_pct as u32)
            .s(" trig=")
            .trig(&shown.trig);
        if let Some(k) = st.k_trig {
            // (Periods over the PWM rate: one rounding, 0.4 not 0.39999998.)
            let p = k as f32 * st.set.div as f32;
            out.s(" t_trig_s=").num(p / ctl.config().pwm_hz);
        }
        out.s("\r\n");
        out.fin(true);
        Some(Ok(()))
    }

    /// Whether a `cap dump` is under way ([`Console::dump_more`] has more to write).
    pub fn dumping(&self) -> bool {
        self.dump.is_some()
    }

    /// A line received while a `cap dump` is under way. For a person (not in machine mode)
    /// it ends the dump (`dump_abort`). In machine mode every line is tagged, so
    /// the line is executed and its reply sent between two of the dump's pieces, which go on
    /// under the dump's id; only a line that could change what the dump reads ends it first:
    /// a `cap` command other than `cap [show]` (an `arm` refills the ring, a `stop` or a new
    /// `dump` ends it) and `machine` (the lines' form). `true` if the dump was ended.
    pub fn dump_interrupt<W: Write>(&mut self, line: &str, out: &mut W) -> bool {
        if self.dump.is_none() {
            return false;
        }
        let cmd = self.split_id(line).map_or("", |(_, c)| c);
        let mut w = cmd.split_ascii_whitespace();
        let ends = match (w.next(), w.next()) {
            (Some("cap"), None | Some("show")) => false,
            (Some("cap"), _) | (Some("machine"), _) => true,
            _ => false,
        };
        if !self.machine || ends {
            return self.dump_abort(out);
        }
        false
    }

    /// A byte received while a `cap dump` is under way (the board's console task and `regen
    /// serve` call it for each byte, before the line editor): a person's ends the dump
    /// (`dump_abort`), so a command such as `mode idle` is never kept waiting
    /// behind the dump and no echo lands among its lines; in machine mode nothing (the whole
    /// line decides: [`Console::dump_interrupt`]). `true` if the dump was ended.
    pub fn dump_byte<W: Write>(&mut self, out: &mut W) -> bool {
        !self.machine && self.dump_abort(out)
    }

    /// End a `cap dump` under way, because input came in while it was being written: its
    /// final line in place of `ok N samples`, `error: cap dump stopped after N samples: input
    /// received` (`R <id> err …` in machine mode, under the dump's id). `true` if a dump was
    /// under way (nothing is written otherwise).
    fn dump_abort<W: Write>(&mut self, out: &mut W) -> bool {
        let Some(d) = self.dump.take() else {
            return false;
        };
        let mut o = Out::new(out, self.machine, &d.id);
        o.fin(false)
            .s("cap dump stopped after ")
            .uint(d.next)
            .s(" samples: input received");
        o.raw = true;
        o.s("\r\n");
        true
    }

    /// The next piece of a `cap dump`: whole sample lines (`D <id>` lines in machine mode)
    /// while a line of [`DUMP_LINE_MAX`] bytes still fits in `budget` bytes, and after the
    /// last sample the final line (`ok N samples`). `true` while more is to come; the pieces
    /// written one after the other are the whole reply, whatever the budget.
    pub fn dump_more<W: Write, C: CapPort>(&mut self, cap: &C, budget: usize, out: &mut W) -> bool {
        let Some(mut d) = self.dump.take() else {
            return false;
        };
        let id = d.id.clone();
        let mut c = Counted { w: out, n: 0 };
        let mut o = Out::new(&mut c, self.machine, &id);
        let st = cap.status();
        while d.next < st.len {
            if o.w.n + DUMP_LINE_MAX > budget {
                self.dump = Some(d);
                return true;
            }
            let row = cap.sample(d.next);
            o.fixed((d.next as f32 - st.pre_n as f32) * st.dt_s, 7);
            for (k, v) in row.iter().take(st.set.n_ch as usize).enumerate() {
                o.s(",").num(st.decode.value(k, *v));
            }
            o.s("\r\n");
            d.next += 1;
        }
        if o.w.n + DUMP_LINE_MAX > budget {
            self.dump = Some(d);
            return true;
        }
        o.fin(true).s(" ").uint(st.len).s(" samples");
        o.raw = true;
        o.s("\r\n");
        self.dump = None;
        false
    }

    /// Announce the capture's progress since the last call (`# cap triggered`, `# cap
    /// ready`; `N cap …` in machine mode), each once per capture, in order; `st` is the
    /// capture's state now. `true` when something was written (then the prompt too).
    pub fn notice_cap<W: Write>(&mut self, st: State, out: &mut W) -> bool {
        let was = core::mem::replace(&mut self.cap_seen, st);
        if st <= was {
            return false;
        }
        if !self.machine {
            out.s("\r\n");
        }
        if was < State::Triggered && st >= State::Triggered {
            self.note(out).s("cap triggered\r\n");
        }
        if st == State::Ready {
            self.note(out).s("cap ready\r\n");
        }
        out.s(self.prompt());
        true
    }
}

/// Text output without `core::fmt`'s formatting machinery (`write!` would link `fmt::write`,
/// `Formatter` and its padding, ≈ 3 KB on the board, and spill every argument list on the
/// stack): strings written as they are, numbers through `numtext`. Errors of the sink are
/// ignored here, as `let _ = write!(…)` did (the board's reply buffer records overflow).
trait Put {
    fn s(&mut self, s: &str) -> &mut Self;
    /// A number with the fewest digits that read back ([`Num`]).
    fn num(&mut self, v: f32) -> &mut Self;
    /// A number with `decimals` decimals ([`Fixed`]).
    fn fixed(&mut self, v: f32, decimals: u8) -> &mut Self;
    fn uint(&mut self, v: u32) -> &mut Self;
    /// `s` padded with spaces to `width` characters (a table column; at least one space).
    fn col(&mut self, s: &str, width: usize) -> &mut Self;
    /// `v` in engineering notation: 4 significant digits, an SI prefix (u, m, k, M) and the
    /// unit: `12.58 W`, `-3.390 mA`, `555.7 J`.
    fn eng(&mut self, v: f32, unit: &str) -> &mut Self;
    /// At most 24 characters of user input (keeps errors one short line), control
    /// characters as `?`.
    fn clip(&mut self, s: &str) -> &mut Self;
    /// ` (did you mean NAME?)` when there is a NAME.
    fn hint(&mut self, name: Option<&str>) -> &mut Self;
    /// When `on`: the command laws by code and name, ` (0 resistor, 1 impedance, …)`.
    fn laws(&mut self, on: bool) -> &mut Self;
    /// The channel names, each after a space.
    fn chans(&mut self) -> &mut Self;
    /// A capture trigger as one word: `fault`, `cmd`, `CH,EDGE,LEVEL`.
    fn trig(&mut self, t: &Trigger) -> &mut Self;
}

impl<W: Write> Put for W {
    #[inline(never)] // one copy per sink type: these are called from ~150 places
    fn s(&mut self, s: &str) -> &mut Self {
        let _ = self.write_str(s);
        self
    }
    #[inline(never)] // one copy per sink type: these are called from ~150 places
    fn num(&mut self, v: f32) -> &mut Self {
        self.s(Num(v).text().as_str())
    }
    #[inline(never)] // one copy per sink type: these are called from ~150 places
    fn fixed(&mut self, v: f32, decimals: u8) -> &mut Self {
        self.s(Fixed(v, decimals).text().as_str())
    }
    #[inline(never)] // one copy per sink type: these are called from ~150 places
    fn uint(&mut self, v: u32) -> &mut Self {
        self.s(numtext::uint(v as u64).as_str())
    }
    #[inline(never)]
    fn col(&mut self, s: &str, width: usize) -> &mut Self {
        self.s(s);
        let n = s.len(); // the console's column texts are ASCII
        for _ in n..width.max(n + 1) {
            self.s(" ");
        }
        self
    }
    #[inline(never)]
    fn eng(&mut self, v: f32, unit: &str) -> &mut Self {
        let a = v.abs();
        let (k, prefix) = if a >= 1e6 || a.is_nan() {
            (1e-6, "M")
        } else if a >= 1e3 {
            (1e-3, "k")
        } else if a >= 1.0 || a == 0.0 {
            (1.0, "")
        } else if a >= 1e-3 {
            (1e3, "m")
        } else {
            (1e6, "u")
        };
        let m = v * k;
        // 4 significant digits; a mantissa that rounds up to 1000 keeps 1 decimal.
        let d = if m.abs() >= 99.995 {
            1
        } else if m.abs() >= 9.9995 {
            2
        } else {
            3
        };
        self.fixed(m, d).s(" ").s(prefix).s(unit)
    }
    #[inline(never)]
    fn hint(&mut self, name: Option<&str>) -> &mut Self {
        if let Some(n) = name {
            self.s(" (did you mean ").s(n).s("?)");
        }
        self
    }
    fn chans(&mut self) -> &mut Self {
        for ch in CHANNELS {
            self.s(" ").s(ch.0);
        }
        self
    }
    fn trig(&mut self, t: &Trigger) -> &mut Self {
        match *t {
            Trigger::Fault => self.s("fault"),
            Trigger::Cmd => self.s("cmd"),
            Trigger::Level { ch, edge, level } => self
                .s(CHANNELS.get(ch as usize).map_or("?", |c| c.0))
                .s(",")
                .s(edge.name())
                .s(",")
                .num(level),
        }
    }
    #[inline(never)]
    fn laws(&mut self, on: bool) -> &mut Self {
        if on {
            for (i, k) in crate::laws::LawKind::ALL.iter().enumerate() {
                self.s(if i == 0 { " (" } else { ", " })
                    .uint(*k as u32)
                    .s(" ")
                    .s(k.name());
            }
            self.s(")");
        }
        self
    }
    #[inline(never)] // one copy per sink type: these are called from ~150 places
    fn clip(&mut self, s: &str) -> &mut Self {
        // By bytes (no UTF-8 decoding): a character starts at every byte that is not a
        // continuation byte (0b10xx_xxxx); the control characters are the bytes < 0x20 and
        // 0x7f, and U+0080 … U+009F, encoded C2 80 … C2 9F. Runs of other text are written
        // as they are (whole characters: runs end at character starts), controls as `?`.
        let b = s.as_bytes();
        let (mut start, mut chars, mut i) = (0, 0, 0);
        while i < b.len() {
            let c = b[i];
            if c & 0xc0 != 0x80 {
                if chars == 24 {
                    self.s(s.get(start..i).unwrap_or("")).s("…");
                    return self;
                }
                chars += 1;
            }
            let c1 = c == 0xc2 && matches!(b.get(i + 1), Some(0x80..=0x9f));
            if c < 0x20 || c == 0x7f || c1 {
                self.s(s.get(start..i).unwrap_or("")).s("?");
                i += 1 + c1 as usize;
                start = i;
            } else {
                i += 1;
            }
        }
        self.s(s.get(start..).unwrap_or(""))
    }
}

/// The name in `names` nearest `typed` by edit distance (Levenshtein, by bytes: the names
/// are ASCII), if it is near enough to be a typing slip: at most 2 edits, and fewer than
/// half of the typed length (`pwm` is not a slip of `law`). The first of equally near names.
fn nearest<'n>(typed: &str, names: impl Iterator<Item = &'n str>) -> Option<&'n str> {
    let t = typed.as_bytes();
    if t.len() > 32 {
        return None;
    }
    let mut best: Option<(&str, usize)> = None;
    for n in names {
        let d = edit_distance(t, n.as_bytes());
        if d <= 2 && 2 * d < t.len() && best.is_none_or(|b| d < b.1) {
            best = Some((n, d));
        }
    }
    best.map(|b| b.0)
}

/// Levenshtein distance of `a` (at most 32 bytes) and `b`: one row of the table at a time.
fn edit_distance(a: &[u8], b: &[u8]) -> usize {
    let mut row = [0usize; 33];
    for (j, r) in row.iter_mut().enumerate().take(a.len() + 1) {
        *r = j;
    }
    for (i, &cb) in b.iter().enumerate() {
        let mut diag = row[0];
        row[0] = i + 1;
        for (j, &ca) in a.iter().enumerate() {
            let sub = diag + usize::from(ca != cb);
            diag = row[j + 1];
            row[j + 1] = sub.min(diag + 1).min(row[j] + 1);
        }
    }
    row[a.len()]
}

/// `<lead><code> <name>: <description>` and a line end.
fn write_fault<W: Write>(out: &mut W, lead: &str, f: crate::protect::Fault) {
    out.s(lead)
        .uint(f.code() as u32)
        .s(" ")
        .s(f.name())
        .s(": ")
        .s(f.describe())
        .s("\r\n");
}

fn write_warnings<W: Write>(out: &mut W, w: u8) {
    if w == 0 {
        out.s("none");
        return;
    }
    let mut first = true;
    for (bit, name) in crate::protect::warn::NAMES {
        if w & bit != 0 {
            out.s(if first { "" } else { "," }).s(name);
            first = false;
        }
    }
}

fn safe_words(m: Mode) -> &'static str {
    match m {
        Mode::Short => "short (low-side switches on: phases shorted, no power to the bus)",
        _ => "idle (gates off: no current through the bridge)",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::format;
    use std::string::{String, ToString};
    use std::vec;
    use std::vec::Vec;

    /// The line editor's UTF-8 check against core's: every sequence of one to three bytes,
    /// and four-byte sequences over every lead byte from 0xF0, every second byte and a
    /// sample of the last two. Agreement is exact: one character and its length, or none.
    #[test]
    fn utf8_first_agrees_with_core() {
        let check = |b: &[u8]| {
            let core = core::str::from_utf8(b).ok().and_then(|s| {
                let mut it = s.chars();
                let c = it.next()?;
                it.next().is_none().then_some((c, b.len()))
            });
            let ours = utf8_first(b).filter(|&(_, k)| k == b.len());
            assert_eq!(ours, core, "{b:02x?}");
            // A complete character at the start, whatever follows it.
            if let Some((c, k)) = utf8_first(b) {
                assert_eq!(
                    core::str::from_utf8(&b[..k]).ok(),
                    Some(c.encode_utf8(&mut [0; 4]) as &str)
                );
            }
        };
        for x in 0..=0xff_ffffu32 {
            let [a, b, c, _] = x.to_le_bytes();
            check(&[a]);
            check(&[a, b]);
            check(&[a, b, c]);
        }
        for a in 0xf0..=0xffu8 {
            for b in 0..=0xffu8 {
                for c in [0x00, 0x7f, 0x80, 0x8f, 0x90, 0xbf, 0xc0, 0xff] {
                    for d in [0x00, 0x7f, 0x80, 0x9a, 0xbf, 0xc0, 0xff] {
                        check(&[a, b, c, d]);
                    }
                }
            }
        }
    }

    fn run(con: &mut Console, ctl: &mut Controller, line: &str) -> (CmdResult, String) {
        let mut s = String::new();
        let r = con.execute_cap(
            line,
            ctl,
            &mut NoStore,
            Some(&mut Capture::<16>::new()),
            &mut s,
        );
        (r, s)
    }

    /// A sinusoidal motion at `f` Hz with the power of a resistive load (∝ ω², rippling at
    /// 2f): the whole-cycle mean is the average power, and it is new once per cycle.
    #[test]
    fn cycle_mean_is_the_average_over_whole_cycles() {
        let ts = 5.0e-5f32;
        for (f, w0, p0) in [
            (0.5f32, 40.0f32, 23.0f32),
            (0.1, 8.0, 3.0),
            (2.0, 100.0, 500.0),
        ] {
            let mut c = CycleMean::default();
            let n = (3.5 / f / ts) as usize;
            let mut starts = 0;
            for k in 0..n {
                let th =
                    (core::f64::consts::TAU * ((f as f64 * k as f64 * ts as f64) % 1.0)) as f32;
                let w = w0 * th.sin();
                let p = 2.0 * p0 * th.sin() * th.sin(); // mean p0
                c.add(p, w, ts);
                if c.started && c.n == 1 {
                    starts += 1;
                }
            }
            // 3.5 cycles: armed after the first half cycle, cycles start at 1, 2 and 3; the
            // ones from 1 and 2 are whole.
            assert_eq!(starts, 3, "{f} Hz");
            let (pm, t) = c.last.unwrap();
            // The crossing is found within a period of ts on either end (the hysteresis
            // delays both ends alike): the cycle is 1/f within 2·ts, the mean within the
            // f32 sum's rounding over 4e5 terms (≈ 1e-4) and the end effect 2·ts·f.
            assert!((t - 1.0 / f).abs() < 2.0 * ts, "{f} Hz: cycle {t} s");
            assert!((pm / p0 - 1.0).abs() < 1e-3, "{f} Hz: {pm} W vs {p0} W");
        }
        // Below the hysteresis (a standstill with noise) no cycle is ever counted.
        let mut c = CycleMean::default();
        for k in 0..100_000 {
            c.add(1.0, 0.9 * if k % 2 == 0 { 1.0 } else { -1.0 }, 5e-5);
        }
        assert_eq!(c.last, None);
    }

    /// The energy counter stays exact over a long run: 10^7 periods of 1.15 mJ (the reference
    /// TMD's 23 W at 20 kHz for 500 s, 11.5 kJ), where a plain f32 sum loses each period's
    /// energy below half its resolution (1 mJ past 8 kJ).
    #[test]
    fn energy_counter_is_exact_over_long_runs() {
        let mut con = Console::new();
        let (e, n) = (1.15e-3f32, 10_000_000u32);
        let mut plain = 0.0f32;
        for _ in 0..n {
            con.add_energy(e);
            plain += e;
        }
        let exact = e as f64 * n as f64;
        assert!(
            ((con.energy_j as f64) / exact - 1.0).abs() < 1e-6,
            "{}",
            con.energy_j
        );
        // The plain sum is what this guards against (so the test can fail).
        assert!(((plain as f64) / exact - 1.0).abs() > 1e-2, "{plain}");
    }

    #[test]
    fn set_get_and_errors() {
        let mut ctl = Controller::new(&Config::default()).unwrap();
        let mut con = Console::new();
        let (r, s) = run(&mut con, &mut ctl, "set r_load_ohm 100");
        assert!(r.is_ok(), "{s}");
        assert_eq!(ctl.config().r_load_ohm, 100.0);
        let (_, s) = run(&mut con, &mut ctl, "get r_load_ohm");
        assert_eq!(s, "ok r_load_ohm = 100 ohm\r\n");
        let before = *ctl.config();
        for bad in [
            "set r_load_ohm nan",
            "set r_load_ohm -5",
            "set r_load_ohm",
            "set r_load_ohm 1 2",
            "set nope 1",
            "set r_load_ohm 1e99",
            "set r_load_ohm 1e-50",
            "set r_load_ohm -1e-50",
            "mode brake",
            "help nope",
            "list zzz",
            "help set x",
            "list a b",
            "set pole_pairs 2.5",
            "set current_bw_hz 4000",
            "set law 7",
            "frobnicate",
            "mode fly",
            "tel iq 0",
            "tel iq,zz 10",
            "tel iq nan",
            "get",
        ] {
            let (r, s) = run(&mut con, &mut ctl, bad);
            assert!(r.is_err(), "{bad}: {s}");
            assert!(s.starts_with("error: "), "{bad}: {s}");
            assert_eq!(s.matches('\n').count(), 1, "{bad}: {s}");
            assert_eq!(*ctl.config(), before, "{bad}");
            assert_eq!(ctl.mode(), Mode::Idle);
        }
        // Number text (numtext): the reason is in the reply; a value set reads back as typed.
        // Every refusal of a value names the key, the value, the reason, the range and the
        // current value; underflow is refused as overflow is.
        let (_, s) = run(&mut con, &mut ctl, "set r_load_ohm 1e99");
        assert_eq!(
            s,
            "error: r_load_ohm 1e99: above the f32 range (3.4e38); allowed 0 .. inf ohm, now 100\r\n"
        );
        let (_, s) = run(&mut con, &mut ctl, "set r_load_ohm 1e-50");
        assert_eq!(
            s,
            "error: r_load_ohm 1e-50: below the f32 range (not 0, reads as 0); allowed 0 .. inf ohm, now 100\r\n"
        );
        let (_, s) = run(&mut con, &mut ctl, "set r_load_ohm nan");
        assert_eq!(
            s,
            "error: r_load_ohm nan: not a number; allowed 0 .. inf ohm, now 100\r\n"
        );
        let (_, s) = run(&mut con, &mut ctl, "set current_bw_hz 6000");
        assert_eq!(
            s,
            "error: current_bw_hz 6000: value out of range; allowed 10 .. 5000 Hz, now 1000\r\n"
        );
        // A conflict with another parameter names it.
        let (_, s) = run(&mut con, &mut ctl, "set v_bus_ov 50");
        assert!(
            s.starts_with("error: v_bus_ov 50: ")
                && s.ends_with("; allowed 1 .. 2000 V, now 95\r\n"),
            "{s}"
        );
        let (_, s) = run(&mut con, &mut ctl, "set r_load_ohm 0");
        assert_eq!(s, "ok r_load_ohm = 0 ohm\r\n");
        let (_, s) = run(&mut con, &mut ctl, "set r_load_ohm 100");
        assert_eq!(s, "ok r_load_ohm = 100 ohm\r\n");
        let (_, s) = run(&mut con, &mut ctl, "set r_load_ohm 2.5e-3");
        assert_eq!(s, "ok r_load_ohm = 0.0025 ohm\r\n");
        let (_, s) = run(&mut con, &mut ctl, "set r_load_ohm inf");
        assert_eq!(s, "ok r_load_ohm = inf ohm\r\n");
        assert!(run(&mut con, &mut ctl, "set r_load_ohm 100").0.is_ok());
        assert!(run(&mut con, &mut ctl, "mode run").0.is_ok());
        let (r, _) = run(&mut con, &mut ctl, "set pwm_hz 10000");
        assert!(r.is_err());
        let (r, _) = run(&mut con, &mut ctl, "save");
        assert!(r.is_err());
        let (r, _) = run(&mut con, &mut ctl, "set r_load_ohm 50");
        assert!(r.is_ok());
    }

    #[test]
    fn list_shows_every_param_and_help_ok() {
        let mut ctl = Controller::new(&Config::default()).unwrap();
        let mut con = Console::new();
        let (r, s) = run(&mut con, &mut ctl, "list");
        assert!(r.is_ok());
        // A header, one line per parameter, the `ok` line.
        assert_eq!(s.lines().count(), PARAMS.len() + 2);
        // Aligned: every column (`set`'s included) starts where the header's does, each
        // after a space.
        let lines: Vec<&str> = s.lines().collect();
        let head = lines[0];
        for h in ["value", "unit", "range", "default", "set"] {
            let at = head.find(&format!(" {h}")).unwrap() + 1;
            for l in &lines[1..lines.len() - 1] {
                let b = l.as_bytes();
                assert!(
                    b[at - 1] == b' ' && b[at] != b' ',
                    "column {h} at {at} misaligned:\n{head}\n{l}"
                );
            }
        }
        let (r, s) = run(&mut con, &mut ctl, "help");
        assert!(r.is_ok() && s.ends_with("\r\nok\r\n"), "{s}");
        assert_eq!(s.lines().count(), COMMANDS.len() + 2, "{s}");
        for l in [
            "status",
            "faults",
            "clear",
            "mode short",
            "tel iq,p 100",
            "tel off",
        ] {
            assert!(run(&mut con, &mut ctl, l).0.is_ok(), "{l}");
        }
    }

    /// `help CMD` prints that command's line only; `tel`'s adds the channels.
    #[test]
    fn help_for_one_command() {
        let mut ctl = Controller::new(&Config::default()).unwrap();
        let mut con = Console::new();
        let (r, s) = run(&mut con, &mut ctl, "help set");
        assert!(r.is_ok(), "{s}");
        assert_eq!(s.lines().count(), 2, "{s}");
        assert!(
            s.starts_with("set      NAME VALUE          set a parameter (RAM)"),
            "{s}"
        );
        let (_, s) = run(&mut con, &mut ctl, "help tel");
        assert!(s.contains("\r\ntel channels: ia[A] ib[A]"), "{s}");
        // Every command has its help, and its usage when given wrong arguments.
        for c in COMMANDS {
            let (r, s) = run(&mut con, &mut ctl, &format!("help {}", c.0));
            assert!(r.is_ok() && s.starts_with(c.0), "{s}");
            let (r, s) = run(&mut con, &mut ctl, &format!("{} a b c", c.0));
            assert!(r.is_err(), "{s}");
            assert_eq!(s, format!("error: usage: {} {}\r\n", c.0, c.1));
        }
        let (r, s) = run(&mut con, &mut ctl, "help fly");
        assert!(
            r.is_err() && s == "error: no command 'fly' (help lists them)\r\n",
            "{s}"
        );
    }

    /// `list PATTERN`: the parameters whose name contains it, in registry order, columns
    /// aligned, the default column read from the store's factory configuration (what
    /// `defaults` restores), not from `Config::default()`.
    #[test]
    fn list_filters_by_pattern_and_shows_the_factory_default() {
        struct Factory(Config);
        impl ParamStore for Factory {
            fn save(&mut self, _: &Config) -> Result<Saved, &'static str> {
                Err("no")
            }
            fn load(&mut self) -> Result<Config, &'static str> {
                Err("no")
            }
            fn factory(&self) -> Config {
                self.0
            }
        }
        let f = Config {
            v_bus_ov: 110.0,
            r_load_ohm: 1000.0,
            ..Config::default()
        };
        let mut ctl = Controller::new(&Config::default()).unwrap();
        let mut con = Console::new();
        let mut s = String::new();
        let r = con.execute("list r_", &mut ctl, &mut Factory(f), &mut s);
        assert!(r.is_ok(), "{s}");
        let want: Vec<&str> = PARAMS
            .iter()
            .map(|p| p.name)
            .filter(|n| n.contains("r_"))
            .collect();
        assert!(want.len() >= 4 && want.contains(&"r_load_ohm"), "{want:?}");
        let lines: Vec<&str> = s.lines().collect();
        assert_eq!(lines.len(), want.len() + 2, "{s}");
        assert!(lines[0].starts_with("name "), "{s}");
        for (l, n) in lines[1..].iter().zip(&want) {
            assert!(l.starts_with(&format!("{n} ")), "{l}");
        }
        // Columns aligned: every row's value starts where the header's does.
        let col = lines[0].find("value").unwrap();
        for l in &lines[1..lines.len() - 1] {
            assert!(
                l.as_bytes()[col - 1] == b' ' && l.as_bytes()[col] != b' ',
                "{l}"
            );
        }
        assert_eq!(
            lines.last().unwrap(),
            &format!("ok {} of {}", want.len(), PARAMS.len())
        );
        let mut row = |name: &str| {
            let mut s = String::new();
            let _ = con.execute(&format!("list {name}"), &mut ctl, &mut Factory(f), &mut s);
            s.lines()
                .nth(1)
                .unwrap()
                .split_whitespace()
                .map(str::to_string)
                .collect::<Vec<_>>()
        };
        // name value unit min .. max default rt|idle description…
        let now = std::format!("{}", Config::default().r_load_ohm);
        assert_eq!(
            row("r_load_ohm")[..8],
            ["r_load_ohm", &now, "ohm", "0", "..", "inf", "1000", "rt"]
        );
        assert_eq!(
            row("v_bus_ov")[..8],
            ["v_bus_ov", "95", "V", "1", "..", "2000", "110", "rt"]
        );
        assert_eq!(row("pwm_hz")[7], "idle");
        // What `defaults` restores is what the column showed.
        let mut s = String::new();
        assert!(con
            .execute("defaults", &mut ctl, &mut Factory(f), &mut s)
            .is_ok());
        assert_eq!(ctl.config().v_bus_ov, 110.0);
    }

    /// The line editor: echo, Backspace/DEL (whole UTF-8 characters), Ctrl-U, CR/LF/CRLF,
    /// arrow keys ignored, overlong and non-UTF-8 lines refused with one `error:` line.
    #[test]
    fn line_editor_edits_echoes_and_refuses() {
        fn feed(ed: &mut LineEditor, bytes: &[u8]) -> (Vec<String>, String) {
            let mut echo = String::new();
            let mut lines = Vec::new();
            for &b in bytes {
                if let Some(l) = ed.feed(b, &mut echo) {
                    lines.push(l.to_string());
                }
            }
            (lines, echo)
        }
        let mut ed = LineEditor::new();
        let (l, e) = feed(&mut ed, b"get r_load_ohx\x7fm\r\n");
        assert_eq!(l, ["get r_load_ohm"]);
        assert_eq!(e, "get r_load_ohx\x08 \x08m\r\n");
        // Backspace (0x08) on an empty line does nothing; LF alone ends a line.
        let (l, e) = feed(&mut ed, b"\x08ab\x08\x08\x08c\n");
        assert_eq!(l, ["c"]);
        assert_eq!(e, "ab\x08 \x08\x08 \x08c\r\n");
        // Ctrl-U erases the whole line.
        let (l, e) = feed(&mut ed, b"set x 1\x15status\r");
        assert_eq!(l, ["status"]);
        assert_eq!(e, format!("set x 1{}status\r\n", "\x08 \x08".repeat(7)));
        // A left/right arrow key (ESC [ C, ESC [ D) and other controls are ignored.
        let (l, _) = feed(&mut ed, b"st\x1b[Ca\x01t\x1b[Dus\r");
        assert_eq!(l, ["status"]);
        // A multi-byte character is echoed when complete and erased whole.
        let (l, e) = feed(&mut ed, "aΩ\x7fb\r".as_bytes());
        assert_eq!(l, ["ab"]);
        assert_eq!(e, "aΩ\x08 \x08b\r\n");
        // Two CRs: two (empty) lines; CRLF one.
        let (l, _) = feed(&mut ed, b"\r\r\n");
        assert_eq!(l, ["", ""]);
        // Overlong: not executed (handed on empty), one error line; the next line is fine.
        let long = [b'9'; LINE_MAX + 5];
        let (l, e) = feed(&mut ed, &long);
        assert!(l.is_empty() && e.len() == LINE_MAX, "{}", e.len());
        let (l, e) = feed(&mut ed, b"\r");
        assert_eq!(l, [""]);
        assert_eq!(e, "\r\nerror: line longer than 128 characters\r\n");
        let (l, _) = feed(&mut ed, &[b'x'; LINE_MAX]);
        assert!(l.is_empty());
        let (l, _) = feed(&mut ed, b"\r");
        assert_eq!(l, ["x".repeat(LINE_MAX)]);
        // Ctrl-U also forgets that the line was too long.
        feed(&mut ed, &long);
        let (l, _) = feed(&mut ed, b"\x15ok\r");
        assert_eq!(l, ["ok"]);
        // Not UTF-8: one error line.
        let (l, e) = feed(&mut ed, b"\xff\xfe set\r");
        assert_eq!(l, [""]);
        assert!(e.ends_with("\r\nerror: line is not UTF-8\r\n"), "{e:?}");
    }

    /// The banner, fault notices (once per latched fault, unasked), and power figures blanked
    /// outside `run`.
    #[test]
    fn banner_notice_and_stale_figures() {
        use crate::io::RawSample;
        let mut b = String::new();
        Console::banner(Mode::Idle, None, &mut b);
        assert_eq!(
            b,
            format!(
                "\r\nregen-fw {} console. drive: mode idle, fault none. type help\r\n> ",
                env!("CARGO_PKG_VERSION")
            )
        );
        let cfg = Config::default();
        let mut ctl = Controller::new(&cfg).unwrap();
        let mut con = Console::new();
        assert!(run(&mut con, &mut ctl, "mode run").0.is_ok());
        let code = |v: f32| (v / cfg.volts_per_count + 0.5) as u16;
        let sample = |v: f32| RawSample {
            i_abc: [cfg.adc_zero_code; 3],
            v_bus: code(v),
            encoder: 0,
        };
        let mut out = String::new();
        ctl.step(&sample(60.0));
        con.tick(&ctl, &mut out);
        assert!(!con.notice(&ctl, &mut out) && out.is_empty());
        // A whole cycle's mean, as after a run: shown in run, blanked outside it.
        con.cycle.last = Some((23.0, 2.0));
        let (_, s) = run(&mut con, &mut ctl, "status");
        assert!(s.contains("\r\np_cycle   23.00 W over 2.000 s\r\n"), "{s}");
        ctl.step(&sample(100.0)); // over-voltage: latched, safe state short
        con.tick(&ctl, &mut out);
        assert!(con.notice(&ctl, &mut out));
        assert_eq!(
            out,
            "\r\n# fault 2 bus_over_voltage: bus voltage above v_bus_ov\r\n# now in mode short (faults: details)\r\n> "
        );
        // Once only.
        ctl.step(&sample(100.0));
        assert!(!con.notice(&ctl, &mut out));
        let (_, s) = run(&mut con, &mut ctl, "status");
        assert!(
            s.starts_with("mode      short\r\nfault     bus_over_voltage\r\n"),
            "{s}"
        );
        assert!(
            s.contains("\r\np_cycle   -\r\n") && s.contains("\r\np_avg     -\r\n"),
            "{s}"
        );
        assert!(
            s.contains("\r\nvbus      100.0 V\r\n") || s.contains("vbus      99.9"),
            "{s}"
        );
        assert_eq!(con.cycle.last, None);
        // Cleared and latched again: announced again.
        ctl.step(&sample(60.0));
        assert!(run(&mut con, &mut ctl, "clear").0.is_ok());
        assert!(!con.notice(&ctl, &mut out));
        assert!(run(&mut con, &mut ctl, "mode run").0.is_ok());
        ctl.step(&sample(100.0));
        out.clear();
        assert!(con.notice(&ctl, &mut out) && out.contains("bus_over_voltage"));
    }

    /// Engineering notation: 4 significant digits and an SI prefix.
    #[test]
    fn engineering_notation() {
        for (v, u, want) in [
            (23.0328f32, "W", "23.03 W"),
            (-0.0033874512, "A", "-3.387 mA"),
            (0.069885254, "m", "69.89 mm"),
            (555.7449, "J", "555.7 J"),
            (12345.0, "J", "12.35 kJ"),
            (0.0, "W", "0.000 W"),
            (999.99, "V", "1000.0 V"),
            (2.5e-6, "A", "2.500 uA"),
            (3.2e7, "J", "32.00 MJ"),
        ] {
            let mut s = String::new();
            s.eng(v, u);
            assert_eq!(s, want, "{v}");
        }
    }

    #[test]
    fn telemetry_rate_and_format() {
        let mut ctl = Controller::new(&Config::default()).unwrap();
        let mut con = Console::new();
        let (r, s) = run(&mut con, &mut ctl, "tel iq,p 1000");
        assert!(r.is_ok());
        assert!(s.starts_with("# tel t,iq,p\r\n"));
        let mut out = String::new();
        for _ in 0..200 {
            con.tick(&ctl, &mut out);
        }
        // 200 periods at 20 kHz = 10 ms at 1 kHz → 10 lines of 3 fields.
        assert_eq!(out.lines().count(), 10);
        assert!(out.lines().all(|l| l.split(',').count() == 3));
        // First line at period 20 (1 kHz of 20 kHz): t = 20/20,000 s, six decimals.
        assert!(out.starts_with("0.001000,"), "{out}");
    }

    #[test]
    fn faults_decode_the_snapshot_and_clear_waits_for_the_cause() {
        use crate::io::RawSample;
        let cfg = Config::default();
        let mut ctl = Controller::new(&cfg).unwrap();
        let mut con = Console::new();
        assert!(run(&mut con, &mut ctl, "mode run").0.is_ok());
        let code = |v: f32| (v / cfg.volts_per_count + 0.5) as u16;
        let sample = |v: f32| RawSample {
            i_abc: [cfg.adc_zero_code; 3],
            v_bus: code(v),
            encoder: 0,
        };
        ctl.step(&sample(60.0));
        let (_, s) = run(&mut con, &mut ctl, "clear");
        assert!(s.starts_with("ok no fault"), "{s}");
        // 100 V > v_bus_ov = 95 V: bus_over_voltage, safe state short.
        ctl.step(&sample(100.0));
        assert_eq!(ctl.mode(), Mode::Short);
        let (r, s) = run(&mut con, &mut ctl, "faults");
        assert!(r.is_ok());
        assert!(s.contains("fault 2 bus_over_voltage"), "{s}");
        assert!(s.contains("safe state: short"), "{s}");
        // The snapshot holds the reading that tripped (one ADC count of 29 mV).
        assert!(s.contains("vbus=99.9") || s.contains("vbus=100.0"), "{s}");
        // Still above: clear refused with the reason, fault kept.
        let (r, s) = run(&mut con, &mut ctl, "clear");
        assert!(r.is_err() && s.contains("bus still above"), "{s}");
        assert!(ctl.fault().is_some());
        assert!(run(&mut con, &mut ctl, "mode run").0.is_err());
        // Back in the normal band: clear accepted, run allowed again.
        ctl.step(&sample(60.0));
        let (r, s) = run(&mut con, &mut ctl, "clear");
        assert!(r.is_ok() && s.contains("cleared bus_over_voltage"), "{s}");
        assert!(ctl.fault().is_none());
        assert!(run(&mut con, &mut ctl, "mode run").0.is_ok());
        let (_, s) = run(&mut con, &mut ctl, "status");
        assert!(s.contains("\r\nwarnings  none\r\n"), "{s}");
    }

    #[test]
    fn open_dominates_a_short_after_a_later_over_current() {
        use crate::io::RawSample;
        let cfg = Config::default();
        let mut ctl = Controller::new(&cfg).unwrap();
        let mut con = Console::new();
        assert!(run(&mut con, &mut ctl, "mode run").0.is_ok());
        let vcode = |v: f32| (v / cfg.volts_per_count + 0.5) as u16;
        // Over-voltage: short.
        ctl.step(&RawSample {
            i_abc: [cfg.adc_zero_code; 3],
            v_bus: vcode(100.0),
            encoder: 0,
        });
        assert_eq!(ctl.mode(), Mode::Short);
        // Then 22 A in phase a (> i_trip_a = 20 A) while shorted: the phases open.
        let k = (22.0 / cfg.amps_per_count) as u16;
        ctl.step(&RawSample {
            i_abc: [
                cfg.adc_zero_code + k,
                cfg.adc_zero_code - k / 2,
                cfg.adc_zero_code - k / 2,
            ],
            v_bus: vcode(60.0),
            encoder: 0,
        });
        assert_eq!(ctl.mode(), Mode::Idle);
        assert_eq!(ctl.fault().map(|f| f.name()), Some("bus_over_voltage"));
        // The short may not come back, even though it is the first fault's safe state.
        assert!(run(&mut con, &mut ctl, "mode short").0.is_err());
        let (_, s) = run(&mut con, &mut ctl, "faults");
        assert!(s.contains("later: 1 over_current"), "{s}");
        assert!(s.contains("now in mode idle"), "{s}");
        // Current still high in the last telemetry: clear refused on the later fault.
        let (r, s) = run(&mut con, &mut ctl, "clear");
        assert!(r.is_err() && s.contains("i_trip_a"), "{s}");
    }

    /// The final line of every console example in `docs/console.md`: each `> CMD` line of a
    /// fenced block is run on a fresh drive (`Config::default()`, idle, no store) and the
    /// `ok …` / `error: …` line the block shows after it must be the console's, word for
    /// word. So the doc's refusals and counts come from the code.
    #[test]
    fn docs_examples_match_the_console() {
        let doc = include_str!("../../docs/console.md");
        let mut n = 0;
        let mut in_block = false;
        let lines: Vec<&str> = doc.lines().collect();
        for (i, l) in lines.iter().enumerate() {
            if l.starts_with("```") {
                in_block = !in_block;
                continue;
            }
            let Some(cmd) = l.strip_prefix("> ").filter(|c| in_block && !c.is_empty()) else {
                continue;
            };
            // The reply: the lines up to the next prompt or the block's end; its final line.
            let shown = lines[i + 1..]
                .iter()
                .take_while(|x| !x.starts_with('>') && !x.starts_with("```"))
                .filter(|x| x.starts_with("ok") || x.starts_with("error: "))
                .last();
            let Some(shown) = shown else { continue };
            let mut ctl = Controller::new(&Config::default()).unwrap();
            let mut con = Console::new();
            let (_, got) = run(&mut con, &mut ctl, cmd);
            let last = got.trim_end().lines().last().unwrap_or("");
            assert_eq!(last, *shown, "docs/console.md line {}: > {cmd}", i + 1);
            n += 1;
        }
        std::println!("{n} examples of docs/console.md checked");
        assert!(n >= 10, "{n}");
    }

    /// `cap dump` in the pieces the board's reply buffer takes ([`REPLY_MAX`]): each piece
    /// fits, every line is whole, and the pieces together are the reply written in one piece,
    /// in both modes.
    #[test]
    fn cap_dump_pieces_reassemble_to_the_whole_reply() {
        let mut ctl = Controller::new(&Config::default()).unwrap();
        ctl.set_mode(Mode::Run).unwrap();
        let mut cap = Capture::<{ crate::capture::SAMPLES }>::new();
        let mut con = Console::new();
        let exec = |con: &mut Console,
                    ctl: &mut Controller,
                    cap: &mut Capture<{ crate::capture::SAMPLES }>,
                    l: &str| {
            let mut s = String::new();
            let r = con.execute_cap(l, ctl, &mut NoStore, Some(cap), &mut s);
            assert!(r.is_ok(), "{s}");
            s
        };
        exec(&mut con, &mut ctl, &mut cap, "cap ch ia,vq,x,p");
        exec(&mut con, &mut ctl, &mut cap, "cap arm");
        let z = ctl.config().adc_zero_code;
        for k in 0..1500u16 {
            // Codes that vary, so the lines differ in length.
            let s = crate::io::RawSample {
                i_abc: [z + k % 37, z - k % 11, z],
                v_bus: 2400 + k % 50,
                encoder: k.wrapping_mul(7),
            };
            ctl.step_outputs(&s);
            if k == 300 {
                exec(&mut con, &mut ctl, &mut cap, "cap now");
            }
            let p = ctl.p_elec().to_bits();
            cap.record(&mut ctl, p);
        }
        assert_eq!(cap.state(), State::Ready);
        for machine in [false, true] {
            con.set_machine(machine);
            let whole = |con: &mut Console,
                         ctl: &mut Controller,
                         cap: &mut Capture<{ crate::capture::SAMPLES }>,
                         budget| {
                let line = if con.machine() {
                    "#x1 cap dump"
                } else {
                    "cap dump"
                };
                let mut pieces = std::vec![exec(con, ctl, cap, line)];
                loop {
                    let mut p = String::new();
                    let more = con.dump_more(cap, budget, &mut p);
                    pieces.push(p);
                    if !more {
                        return pieces;
                    }
                }
            };
            let one = whole(&mut con, &mut ctl, &mut cap, usize::MAX);
            let parts = whole(&mut con, &mut ctl, &mut cap, REPLY_MAX);
            assert_eq!(one.len(), 2);
            assert!(parts.len() >= 6, "{} pieces", parts.len());
            assert!(parts
                .iter()
                .all(|p| p.len() <= REPLY_MAX && p.ends_with("\r\n")));
            assert_eq!(parts.concat(), one.concat());
            let text = one.concat();
            std::println!(
                "machine {machine}: {} bytes in {} pieces",
                text.len(),
                parts.len()
            );
            let n = crate::capture::SAMPLES;
            assert_eq!(text.lines().count(), n + 3);
            if machine {
                assert!(text.ends_with(&std::format!("R x1 ok {n} samples\r\n")));
                assert!(text.lines().rev().skip(1).all(|l| l.starts_with("D x1 ")));
            }
            // A person's line after the first piece ends the dump, saying how many samples
            // were sent, and is then executed; in machine mode a `cap` command that changes
            // the capture does the same under the dump's id.
            let head = exec(
                &mut con,
                &mut ctl,
                &mut cap,
                if machine { "#x1 cap dump" } else { "cap dump" },
            );
            let mut first = String::new();
            assert!(con.dump_more(&cap, REPLY_MAX, &mut first));
            let sent = first.lines().count();
            let next = exec(
                &mut con,
                &mut ctl,
                &mut cap,
                if machine { "#x2 cap stop" } else { "cap" },
            );
            assert!(!con.dumping());
            let (end, want) = next.split_once("\r\n").unwrap();
            let tag = if machine { "R x1 err " } else { "error: " };
            assert_eq!(
                end,
                std::format!("{tag}cap dump stopped after {sent} samples: input received")
            );
            assert!(sent > 0 && sent < n && head.lines().count() == 2, "{sent}");
            assert!(
                want.starts_with(if machine {
                    "D x2 cap idle"
                } else {
                    "cap ready"
                }),
                "{want}"
            );
            if !machine {
                continue;
            }
            // Machine mode: a line that leaves the capture alone (`status`, `cap show`) is
            // answered under its own id between two pieces, and the dump goes on under its
            // id to the same whole reply.
            exec(&mut con, &mut ctl, &mut cap, "#x3 cap arm");
            exec(&mut con, &mut ctl, &mut cap, "#x4 cap now");
            for _ in 0..crate::capture::SAMPLES {
                ctl.step_outputs(&crate::io::RawSample {
                    i_abc: [z, z, z],
                    v_bus: 2400,
                    encoder: 0,
                });
                let p = ctl.p_elec().to_bits();
                cap.record(&mut ctl, p);
            }
            assert_eq!(cap.state(), State::Ready);
            let one = whole(&mut con, &mut ctl, &mut cap, usize::MAX).concat();
            let mut pieces = std::vec![exec(&mut con, &mut ctl, &mut cap, "#x1 cap dump")];
            let mut asked = 0;
            loop {
                let mut p = String::new();
                let more = con.dump_more(&cap, REPLY_MAX, &mut p);
                pieces.push(p);
                if !more {
                    break;
                }
                if asked < 2 {
                    let l = ["#y1 status", "#y2 cap show"][asked];
                    let r = exec(&mut con, &mut ctl, &mut cap, l);
                    let id = &l[1..3];
                    assert!(
                        r.lines().all(|l| l.contains(&std::format!(" {id} ")))
                            && r.lines()
                                .last()
                                .unwrap()
                                .starts_with(&std::format!("R {id} ok")),
                        "{r}"
                    );
                    asked += 1;
                }
            }
            assert_eq!(asked, 2);
            assert_eq!(
                pieces.concat(),
                one,
                "the dump, interleaved, is the whole dump"
            );
        }
    }

    /// Refusals name the real range and reason: the laws by code and name, a near name
    /// suggested, the store rule in `align` as in `run`.
    #[test]
    fn refusals_name_range_reason_and_near_names() {
        let mut ctl = Controller::new(&Config::default()).unwrap();
        let mut con = Console::new();
        let (_, s) = run(&mut con, &mut ctl, "set law 7");
        assert_eq!(
            s,
            "error: law 7: value out of range; allowed 0 .. 4 code (0 resistor, 1 impedance, 2 tracking, 3 two_way, 4 one_way), now 0\r\n"
        );
        let (_, s) = run(&mut con, &mut ctl, "get r_load_om");
        assert_eq!(
            s,
            "error: unknown parameter 'r_load_om' (did you mean r_load_ohm?) (try list)\r\n"
        );
        let (_, s) = run(&mut con, &mut ctl, "stauts");
        assert_eq!(
            s,
            "error: unknown command 'stauts' (did you mean status?) (see help)\r\n"
        );
        let (_, s) = run(&mut con, &mut ctl, "frobnicate");
        assert_eq!(s, "error: unknown command 'frobnicate' (see help)\r\n");
        // Too short to be a slip of anything.
        let (_, s) = run(&mut con, &mut ctl, "get x");
        assert_eq!(s, "error: unknown parameter 'x' (try list)\r\n");
        // The store rule holds in `align` as in `run`.
        for m in ["run", "align"] {
            assert!(run(&mut con, &mut ctl, "mode idle").0.is_ok());
            let (r, s) = run(&mut con, &mut ctl, &format!("mode {m}"));
            assert!(r.is_ok(), "{s}");
            for c in ["save", "load", "defaults"] {
                let (r, s) = run(&mut con, &mut ctl, c);
                assert!(
                    r.is_err()
                        && s.starts_with(&format!(
                            "error: {c} refused in mode {m} (mode idle first): "
                        )),
                    "{s}"
                );
            }
        }
    }

    /// The edit distance against the textbook recursion (memoised), over random pairs.
    #[test]
    fn edit_distance_is_levenshtein() {
        fn reference(a: &[u8], b: &[u8]) -> usize {
            let mut m = std::collections::HashMap::new();
            fn go(
                a: &[u8],
                b: &[u8],
                m: &mut std::collections::HashMap<(usize, usize), usize>,
            ) -> usize {
                if a.is_empty() || b.is_empty() {
                    return a.len().max(b.len());
                }
                if let Some(&d) = m.get(&(a.len(), b.len())) {
                    return d;
                }
                let d = (go(&a[1..], &b[1..], m) + usize::from(a[0] != b[0]))
                    .min(go(&a[1..], b, m) + 1)
                    .min(go(a, &b[1..], m) + 1);
                m.insert((a.len(), b.len()), d);
                d
            }
            go(a, b, &mut m)
        }
        let mut x = 0x2545_f491_u32;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x
        };
        for _ in 0..3000 {
            let mut word = |n: u32| -> Vec<u8> {
                (0..next() % n)
                    .map(|_| b"abc_"[(next() % 4) as usize])
                    .collect()
            };
            let (a, b) = (word(33), word(20));
            assert_eq!(edit_distance(&a, &b), reference(&a, &b), "{a:?} {b:?}");
        }
    }

    /// One line the drive sends in machine mode, parsed by the grammar of
    /// `docs/console.md` ("Machine mode"); `Err` names what is wrong.
    #[derive(Debug, PartialEq)]
    enum Tagged {
        R(String, bool, String),
        D(String, String),
        T(Vec<f64>),
        H(Vec<String>),
        N(String),
    }

    fn is_id(id: &str) -> bool {
        id == "-" || (1..=8).contains(&id.len()) && id.bytes().all(|b| b.is_ascii_alphanumeric())
    }

    fn parse_tagged(line: &str) -> Result<Tagged, String> {
        let (tag, rest) = line
            .split_once(' ')
            .ok_or_else(|| format!("no tag: {line:?}"))?;
        let id_text = |r: &str| -> Result<(String, String), String> {
            let (id, text) = r.split_once(' ').unwrap_or((r, ""));
            if !is_id(id) {
                return Err(format!("bad id {id:?} in {line:?}"));
            }
            Ok((id.to_string(), text.to_string()))
        };
        match tag {
            "R" => {
                let (id, text) = id_text(rest)?;
                let (verdict, text) = text.split_once(' ').unwrap_or((&text, ""));
                match verdict {
                    "ok" => Ok(Tagged::R(id, true, text.to_string())),
                    "err" if !text.is_empty() => Ok(Tagged::R(id, false, text.to_string())),
                    _ => Err(format!("bad verdict in {line:?}")),
                }
            }
            "D" => {
                let (id, text) = id_text(rest)?;
                Ok(Tagged::D(id, text))
            }
            "T" => rest
                .split(',')
                .map(|v| v.parse::<f64>().map_err(|e| format!("{e}: {line:?}")))
                .collect::<Result<Vec<_>, _>>()
                .map(Tagged::T),
            "H" if rest.starts_with("t,") || rest == "t" => {
                Ok(Tagged::H(rest.split(',').map(str::to_string).collect()))
            }
            "N" if !rest.is_empty() => Ok(Tagged::N(rest.to_string())),
            _ => Err(format!("unknown tag: {line:?}")),
        }
    }

    /// Every line of `s` (each ending CRLF), parsed.
    fn tagged(s: &str) -> Vec<Tagged> {
        assert!(s.is_empty() || s.ends_with("\r\n"), "{s:?}");
        s.split_terminator("\r\n")
            .map(|l| {
                assert!(!l.contains(['\r', '\n']), "{s:?}");
                parse_tagged(l).unwrap()
            })
            .collect()
    }

    /// A store that holds what was saved last (none at first), saving at once or deferred.
    struct Held {
        held: Option<Config>,
        factory: Config,
        deferred: bool,
    }
    impl ParamStore for Held {
        fn save(&mut self, c: &Config) -> Result<Saved, &'static str> {
            self.held = Some(*c);
            Ok(if self.deferred {
                Saved::Deferred
            } else {
                Saved::Done
            })
        }
        fn load(&mut self) -> Result<Config, &'static str> {
            self.held.ok_or("empty")
        }
        fn factory(&self) -> Config {
            self.factory
        }
        fn held(&self) -> Option<Config> {
            self.held
        }
    }

    /// Machine mode: every line type parses, replies carry their command's id, `list` has
    /// one `key=value` line per parameter with `saved=`, `status` one line, the editor does
    /// not echo, and `machine off` returns to the human console unchanged.
    #[test]
    fn machine_mode_lines_parse_and_carry_ids() {
        let cfg = Config::default();
        let mut ctl = Controller::new(&cfg).unwrap();
        let mut con = Console::new();
        let mut st = Held {
            held: None,
            factory: cfg,
            deferred: false,
        };
        let ex = |con: &mut Console, ctl: &mut Controller, st: &mut Held, l: &str| {
            let mut s = String::new();
            let r = con.execute(l, ctl, st, &mut s);
            (r, s)
        };
        let (r, s) = ex(&mut con, &mut ctl, &mut st, "machine on");
        assert!(r.is_ok() && s == "R - ok machine on\r\n", "{s:?}");
        assert_eq!(con.prompt(), "");
        // A data reply: D lines with the id, then R.
        let (_, s) = ex(&mut con, &mut ctl, &mut st, "#a1 help set");
        let t = tagged(&s);
        assert_eq!(t.len(), 2, "{s}");
        assert!(matches!(&t[0], Tagged::D(id, x) if id == "a1" && x.starts_with("set ")));
        assert_eq!(t[1], Tagged::R("a1".into(), true, "".into()));
        // Refusals: R err with the human text; nothing changed.
        let (r, s) = ex(&mut con, &mut ctl, &mut st, "#7 set r_load_ohm -5");
        assert!(r.is_err());
        assert_eq!(
            s,
            "R 7 err r_load_ohm -5: value out of range; allowed 0 .. inf ohm, now 306\r\n"
        );
        let (r, s) = ex(&mut con, &mut ctl, &mut st, "#toolong123 status");
        assert!(r.is_err() && s.starts_with("R - err command id"), "{s}");
        let (r, s) = ex(&mut con, &mut ctl, &mut st, "#b-1 status");
        assert!(r.is_err() && s.starts_with("R - err command id"), "{s}");
        let (r, s) = ex(&mut con, &mut ctl, &mut st, "#5");
        assert!(r.is_err() && s == "R 5 err empty command\r\n", "{s}");
        let (r, s) = ex(&mut con, &mut ctl, &mut st, "");
        assert!(r.is_ok() && s.is_empty());
        let (_, s) = ex(&mut con, &mut ctl, &mut st, "frob");
        assert_eq!(
            tagged(&s),
            [Tagged::R(
                "-".into(),
                false,
                "unknown command 'frob' (see help)".into()
            )]
        );
        // list: every parameter, fields in the fixed order; saved= against the factory
        // configuration before any save, then the flash.
        let list = |con: &mut Console, ctl: &mut Controller, st: &mut Held| {
            let (r, s) = ex(con, ctl, st, "#L list");
            assert!(r.is_ok(), "{s}");
            let t = tagged(&s);
            assert_eq!(t.len(), PARAMS.len() + 1);
            assert_eq!(
                t[PARAMS.len()],
                Tagged::R("L".into(), true, format!("{} params", PARAMS.len()))
            );
            let mut saved = std::collections::BTreeMap::new();
            for (x, p) in t.iter().zip(PARAMS) {
                let Tagged::D(id, text) = x else {
                    panic!("{x:?}")
                };
                assert_eq!(id, "L");
                let kv: Vec<(&str, &str)> = text
                    .split(' ')
                    .map(|f| f.split_once('=').unwrap())
                    .collect();
                let keys: Vec<&str> = kv.iter().map(|k| k.0).collect();
                assert_eq!(
                    keys,
                    ["name", "value", "unit", "min", "max", "default", "when", "saved"]
                );
                assert_eq!(kv[0].1, p.name);
                assert_eq!(kv[1].1.parse::<f32>().unwrap(), p.get(ctl.config()));
                assert_eq!(kv[3].1.parse::<f32>().unwrap(), p.min);
                assert_eq!(kv[4].1.parse::<f32>().unwrap(), p.max);
                assert_eq!(kv[6].1, if p.runtime { "rt" } else { "idle" });
                saved.insert(p.name, kv[7].1.to_string());
            }
            saved
        };
        // The longest reply the board's buffer must hold (`firmware/board/src/console.rs`,
        // REPLY_MAX): `list` with an 8-character id, every value changed.
        let (_, s) = ex(&mut con, &mut ctl, &mut st, "#12345678 list");
        std::println!("machine list: {} bytes", s.len());
        let s0 = list(&mut con, &mut ctl, &mut st);
        assert!(s0.values().all(|v| v == "yes"), "{s0:?}");
        assert!(ex(&mut con, &mut ctl, &mut st, "set r_load_ohm 100")
            .0
            .is_ok());
        let s1 = list(&mut con, &mut ctl, &mut st);
        for (k, v) in &s1 {
            assert_eq!(v, if *k == "r_load_ohm" { "changed" } else { "yes" }, "{k}");
        }
        let (r, s) = ex(&mut con, &mut ctl, &mut st, "#s save");
        assert!(r.is_ok() && s == "R s ok saved\r\n", "{s}");
        assert!(list(&mut con, &mut ctl, &mut st)
            .values()
            .all(|v| v == "yes"));
        // `defaults` restores the factory's 306 Ω: changed against the flash's 100 Ω.
        assert!(ex(&mut con, &mut ctl, &mut st, "defaults").0.is_ok());
        assert_eq!(list(&mut con, &mut ctl, &mut st)["r_load_ohm"], "changed");
        assert!(ex(&mut con, &mut ctl, &mut st, "load").0.is_ok());
        assert!(list(&mut con, &mut ctl, &mut st)
            .values()
            .all(|v| v == "yes"));
        // A deferred save (the board's): no reply until `save_done`, which carries the id.
        st.deferred = true;
        let (r, s) = ex(&mut con, &mut ctl, &mut st, "#q9 save");
        assert!(r.is_ok() && s.is_empty(), "{s}");
        let mut s = String::new();
        assert!(con.save_done(Ok(()), &mut s).is_ok());
        assert_eq!(s, "R q9 ok saved\r\n");
        let mut s = String::new();
        assert!(con.save_done(Err("flash"), &mut s).is_err());
        assert_eq!(s, "R q9 err save failed: flash\r\n");
        // status: one D line of key=value pairs.
        let (_, s) = ex(&mut con, &mut ctl, &mut st, "#st status");
        let t = tagged(&s);
        let Tagged::D(_, text) = &t[0] else {
            panic!("{s}")
        };
        let keys: Vec<&str> = text
            .split(' ')
            .map(|f| f.split_once('=').unwrap().0)
            .collect();
        assert_eq!(
            keys,
            [
                "mode",
                "boot",
                "fault",
                "vbus_v",
                "speed_rad_s",
                "travel_m",
                "id_a",
                "iq_a",
                "p_w",
                "p_avg_w",
                "p_cycle_w",
                "cycle_s",
                "energy_j",
                "warnings"
            ]
        );
        assert!(
            text.starts_with("mode=idle ") && text.contains(" fault=none "),
            "{text}"
        );
        assert_eq!(t.len(), 2);
        // tel: H line, R, then T lines.
        let (_, s) = ex(&mut con, &mut ctl, &mut st, "#t tel iq,p 2000");
        assert_eq!(
            tagged(&s),
            [
                Tagged::H(vec!["t".into(), "iq".into(), "p".into()]),
                Tagged::R("t".into(), true, "tel 2000 Hz".into())
            ]
        );
        let mut out = String::new();
        for _ in 0..100 {
            con.tick(&ctl, &mut out);
        }
        let t = tagged(&out);
        assert_eq!(t.len(), 10);
        for (k, x) in t.iter().enumerate() {
            let Tagged::T(v) = x else { panic!("{x:?}") };
            assert_eq!(v.len(), 3);
            assert!((v[0] - (k + 1) as f64 * 5e-4).abs() < 1e-9, "{v:?}");
        }
        // A notice: N lines, no prompt.
        use crate::io::RawSample;
        assert!(ex(&mut con, &mut ctl, &mut st, "mode run").0.is_ok());
        let code = (100.0 / cfg.volts_per_count + 0.5) as u16;
        ctl.step(&RawSample {
            i_abc: [cfg.adc_zero_code; 3],
            v_bus: code,
            encoder: 0,
        });
        let mut out = String::new();
        assert!(con.notice(&ctl, &mut out));
        assert_eq!(
            tagged(&out),
            [
                Tagged::N("fault 2 bus_over_voltage: bus voltage above v_bus_ov".into()),
                Tagged::N("now in mode short (faults: details)".into())
            ]
        );
        // faults: D lines then R.
        let (_, s) = ex(&mut con, &mut ctl, &mut st, "#f faults");
        let t = tagged(&s);
        assert!(t[..t.len() - 1]
            .iter()
            .all(|x| matches!(x, Tagged::D(id, _) if id == "f")));
        assert!(
            matches!(t.last(), Some(Tagged::R(id, true, x)) if id == "f" && x.starts_with("fault bus_over_voltage"))
        );
        // Back to the human console: answered in its form.
        let (_, s) = ex(&mut con, &mut ctl, &mut st, "#z machine off");
        assert_eq!(s, "ok machine off\r\n");
        assert_eq!(con.prompt(), PROMPT);
        let (_, s) = ex(&mut con, &mut ctl, &mut st, "#z status");
        assert_eq!(s, "error: unknown command '#z' (see help)\r\n");
    }

    /// History: up/down arrows recall the last lines entered (at most [`HISTORY`], a repeat
    /// stored once), the terminal's line erased and the entry echoed; a recalled line can be
    /// edited; down past the newest gives an empty line.
    #[test]
    fn line_editor_history() {
        fn feed(ed: &mut LineEditor, bytes: &[u8]) -> (Vec<String>, String) {
            let mut echo = String::new();
            let mut lines = Vec::new();
            for &b in bytes {
                if let Some(l) = ed.feed(b, &mut echo) {
                    lines.push(l.to_string());
                }
            }
            (lines, echo)
        }
        const UP: &[u8] = b"\x1b[A";
        const DOWN: &[u8] = b"\x1b[B";
        let mut ed = LineEditor::new();
        // Nothing to recall yet.
        assert_eq!(feed(&mut ed, UP), (vec![], String::new()));
        for l in ["z0", "a1", "b2", "b2", "", "c3", "d4"] {
            feed(&mut ed, format!("{l}\r").as_bytes());
        }
        // Newest first; "b2" once, so the last four are a1 b2 c3 d4 (z0 forgotten).
        let (_, e) = feed(&mut ed, UP);
        assert_eq!(e, "d4");
        let (_, e) = feed(&mut ed, UP);
        assert_eq!(e, "\x08 \x08\x08 \x08c3");
        feed(&mut ed, UP);
        let (_, e) = feed(&mut ed, UP);
        assert!(e.ends_with("a1"), "{e:?}");
        let (_, e) = feed(&mut ed, UP);
        assert_eq!(e, "", "the oldest stays");
        let (l, _) = feed(&mut ed, b"\r");
        assert_eq!(l, ["a1"]);
        // Now b2 c3 d4 a1. Down past the newest: an empty line.
        feed(&mut ed, UP);
        let (_, e) = feed(&mut ed, DOWN);
        assert_eq!(e, "\x08 \x08\x08 \x08");
        // A recalled line edited before Enter: two up is d4, edited to dX.
        let mut keys = UP.to_vec();
        keys.extend(UP);
        keys.extend(b"\x7fX\r");
        let (l, _) = feed(&mut ed, &keys);
        assert_eq!(l, ["dX"]);
        // c3 d4 a1 dX: up three times is d4, down once a1.
        let (l, _) = feed(&mut ed, b"\x1b[A\x1b[A\x1b[A\x1b[B\r");
        assert_eq!(l, ["a1"]);
    }

    /// The line editor in machine mode: no echo, no editing, CR/LF/CRLF end lines, an
    /// overlong or non-UTF-8 line is refused as a final reply with the line's id.
    #[test]
    fn line_editor_machine_mode() {
        let mut ed = LineEditor::new();
        ed.set_machine(true);
        let mut feed = |bytes: &[u8]| {
            let mut echo = String::new();
            let mut lines = Vec::new();
            for &b in bytes {
                if let Some(l) = ed.feed(b, &mut echo) {
                    lines.push(l.to_string());
                }
            }
            (lines, echo)
        };
        assert_eq!(
            feed(b"#1 status\r\n#2 get x\n#3 a\x7fb\r"),
            (
                vec!["#1 status".into(), "#2 get x".into(), "#3 ab".into()],
                String::new()
            )
        );
        let mut long = b"#k7 set x ".to_vec();
        long.extend([b'9'; 200]);
        long.push(b'\n');
        assert_eq!(
            feed(&long),
            (
                vec![String::new()],
                "R k7 err line longer than 128 characters\r\n".into()
            )
        );
        assert_eq!(
            feed(b"\xff get\n"),
            (vec![String::new()], "R - err line is not UTF-8\r\n".into())
        );
    }

    proptest::proptest! {
        /// The byte-wise clip writes what the char-wise definition says: the first 24
        /// characters, control characters (Unicode Cc) as `?`, `…` when more followed.
        #[test]
        fn clip_is_the_char_definition(chars in proptest::collection::vec(proptest::prelude::any::<char>(), 0..40)) {
            let s: String = chars.iter().collect();
            let mut want = String::new();
            for (i, ch) in s.chars().enumerate() {
                if i == 24 {
                    want.push('…');
                    break;
                }
                want.push(if ch.is_control() { '?' } else { ch });
            }
            let mut got = String::new();
            got.clip(&s);
            proptest::prop_assert_eq!(got, want);
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(2000))]
        #[test]
        /// `cap` lines in any order on one capture recording between them: nothing panics,
        /// a refusal is one `error:` line and changes neither the settings nor the capture.
        #[test]
        fn fuzz_cap_never_panics_and_refusals_change_nothing(lines in proptest::collection::vec(
            "cap( (ch|div|pre|trig|arm|now|stop|dump|show|[a-z]{0,3}))?( (ia|iq,vq|w,x,p,ib|iq_ref|fault|cmd|[a-z_,]{0,8}|[-0-9.e]{0,5}))?( (rise|fall|both|[a-z]{0,3}))?( [-0-9.einf]{0,6})?( x)?",
            1..12,
        )) {
            let mut ctl = Controller::new(&Config::default()).unwrap();
            ctl.set_mode(Mode::Run).unwrap();
            let mut cap = Capture::<16>::new();
            let mut con = Console::new();
            let s0 = crate::io::RawSample { i_abc: [2048; 3], v_bus: 2457, encoder: 0 };
            for line in &lines {
                let status = |con: &mut Console, ctl: &mut Controller, cap: &mut Capture<16>| {
                    let mut s = String::new();
                    let _ = con.execute_cap("cap", ctl, &mut NoStore, Some(cap), &mut s);
                    s
                };
                let before = (status(&mut con, &mut ctl, &mut cap), cap.status());
                let mut s = String::new();
                let r = con.execute_cap(line, &mut ctl, &mut NoStore, Some(&mut cap), &mut s);
                while con.dump_more(&cap, REPLY_MAX, &mut s) {}
                if r.is_err() {
                    proptest::prop_assert!(s.starts_with("error: ") && s.matches('\n').count() == 1, "{}", s);
                    proptest::prop_assert_eq!(&(status(&mut con, &mut ctl, &mut cap), cap.status()), &before);
                }
                for _ in 0..7 {
                    ctl.step_outputs(&s0);
                    let p = ctl.p_elec().to_bits();
                    cap.record(&mut ctl, p);
                }
            }
        }

        fn fuzz_never_panics_and_errors_change_nothing(line in "(set|get|mode|tel|save|load|list|status|[a-z]{0,4})( [a-z_,]{0,14})?( [-+0-9.eEinfa]{0,10})?( x)?|\\PC{0,40}") {
            let mut ctl = Controller::new(&Config::default()).unwrap();
            let mut con = Console::new();
            let before = *ctl.config();
            let (r, s) = run(&mut con, &mut ctl, &line);
            if r.is_err() {
                proptest::prop_assert_eq!(*ctl.config(), before);
                proptest::prop_assert!(s.starts_with("error: ") && s.matches('\n').count() == 1);
            }
            proptest::prop_assert!(ctl.config().validate().is_ok());
        }
    }
}
