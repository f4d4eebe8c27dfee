//! The serial console: a line parser and command executor over a [`Controller`] and a
//! [`ParamStore`]. No alloc: output goes to any `core::fmt::Write` sink (a UART buffer on the
//! board, a pty on the host). Every command answers with `ok …` or one line `error: …`; a
//! refused command changes nothing. The executor never panics (fuzzed, see
//! `examples/console_fuzz.rs`).
//!
//! Commands: `help`, `list`, `get NAME`, `set NAME VALUE`, `save`, `load`, `defaults`,
//! `status`, `faults`, `clear`, `mode idle|run|short|open`, `tel CH[,CH…] RATE_HZ`, `tel off`.
//!
//! Telemetry lines are CSV: a header `# tel t,<ch>,…` then `<t>,<v>,…` per sample (`t` in s
//! since `tel` was started), readable by any CSV plotting tool after dropping `#` lines.
//!
//! Store rule: `save` is refused while the mode is `run` (a flash page erase stalls the core
//! for ~20 ms on the G474, i.e. 400 current-loop periods); `load` and `defaults` are refused in
//! `run` as well because they change non-runtime parameters.

use core::fmt::Write;

use crate::config::Config;
use crate::control::{Controller, Mode};
use crate::numtext::{self, Fixed, Num, NumError};
use crate::params::{self, PARAMS};

/// The persistent store as the console sees it.
pub trait ParamStore {
    fn save(&mut self, cfg: &Config) -> Result<(), &'static str>;
    fn load(&mut self) -> Result<Config, &'static str>;
    /// What `defaults` restores: the factory configuration of this hardware. On the board
    /// that is [`Config::default`] (its scalings are the board's); a simulated drive returns
    /// its scenario's configuration, so that `defaults` never puts a board's ADC scalings on
    /// other hardware (a wrong bus scaling makes the loop over-drive and motor the machine).
    fn factory(&self) -> Config {
        Config::default()
    }
}

/// A store that refuses everything (no flash).
pub struct NoStore;
impl ParamStore for NoStore {
    fn save(&mut self, _: &Config) -> Result<(), &'static str> {
        Err("no persistent store")
    }
    fn load(&mut self) -> Result<Config, &'static str> {
        Err("no persistent store")
    }
}

/// Telemetry channels: name, unit, reader.
/// A telemetry channel: name, unit, reader.
pub type Channel = (&'static str, &'static str, fn(&Controller) -> f32);

pub static CHANNELS: &[Channel] = &[
    ("ia", "A", |c| c.telemetry().i_abc[0].to_num()),
    ("ib", "A", |c| c.telemetry().i_abc[1].to_num()),
    ("ic", "A", |c| c.telemetry().i_abc[2].to_num()),
    ("id", "A", |c| c.telemetry().i_dq.d.to_num()),
    ("iq", "A", |c| c.telemetry().i_dq.q.to_num()),
    ("id_ref", "A", |c| c.telemetry().i_ref.d.to_num()),
    ("iq_ref", "A", |c| c.telemetry().i_ref.q.to_num()),
    ("vd", "V", |c| c.telemetry().v_dq.d.to_num()),
    ("vq", "V", |c| c.telemetry().v_dq.q.to_num()),
    ("vbus", "V", |c| c.telemetry().v_bus.to_num()),
    ("w", "rad/s", |c| c.telemetry().omega_m.to_num()),
    ("x", "m", |c| c.telemetry().x.to_num()),
    ("p", "W", |c| c.telemetry().p_elec.to_num()),
];

const MAX_CH: usize = 8;

/// Console state (telemetry selection, energy integrator).
#[derive(Clone, Debug, Default)]
pub struct Console {
    tel: [u8; MAX_CH],
    n_tel: usize,
    /// Periods between telemetry samples (0 = off).
    tel_every: u32,
    tel_count: u32,
    tel_periods: u64,
    /// Harvested energy since boot, J.
    pub energy_j: f32,
    /// Power averaged with a 1 s time constant, W.
    pub p_avg_w: f32,
}

/// Result of one command: `Ok` after an `ok` line, `Err` after an `error:` line.
pub type CmdResult = Result<(), Refused>;

/// The command was refused (its `error:` line has been written).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Refused;

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

    /// Call once per current-loop period after `ctl.step`: integrates energy and writes a
    /// telemetry line when one is due.
    pub fn tick<W: Write>(&mut self, ctl: &Controller, out: &mut W) {
        let ts = ctl.config().ts();
        let p: f32 = ctl.telemetry().p_elec.to_num();
        self.energy_j += p * ts;
        self.p_avg_w += (p - self.p_avg_w) * ts.min(1.0);
        if self.tel_every == 0 {
            return;
        }
        self.tel_periods += 1;
        self.tel_count += 1;
        if self.tel_count >= self.tel_every {
            self.tel_count = 0;
            let _ = write!(out, "{}", Fixed(self.tel_periods as f32 * ts, 6));
            for &i in &self.tel[..self.n_tel] {
                if let Some(ch) = CHANNELS.get(i as usize) {
                    let _ = write!(out, ",{}", Num((ch.2)(ctl)));
                }
            }
            let _ = out.write_str("\r\n");
        }
    }

    /// Execute one line. Writes one or more lines to `out`, the last starting `ok` or `error:`.
    pub fn execute<W: Write, S: ParamStore>(
        &mut self,
        line: &str,
        ctl: &mut Controller,
        store: &mut S,
        out: &mut W,
    ) -> CmdResult {
        let mut it = line.split_ascii_whitespace();
        let cmd = match it.next() {
            Some(c) => c,
            None => return Ok(()), // empty line: nothing
        };
        let a1 = it.next();
        let a2 = it.next();
        let extra = it.next().is_some();
        let running = ctl.mode() == Mode::Run;
        macro_rules! fail {
            ($($t:tt)*) => {{
                let _ = out.write_str("error: ");
                let _ = write!(out, $($t)*);
                let _ = out.write_str("\r\n");
                return Err(Refused);
            }};
        }
        macro_rules! ok {
            ($($t:tt)*) => {{
                let _ = out.write_str("ok");
                let _ = write!(out, $($t)*);
                let _ = out.write_str("\r\n");
                return Ok(());
            }};
        }
        let nargs = a1.is_some() as usize + a2.is_some() as usize + extra as usize;
        let want = |n: usize| nargs == n;
        match cmd {
            "help" if want(0) => {
                let _ = out.write_str(
                    "commands: help | list | get NAME | set NAME VALUE | save | load | defaults\r\n\
                     | status | faults | clear | mode idle|run|short|open | tel CH[,CH..] HZ | tel off\r\n",
                );
                let _ = out.write_str("tel channels:");
                for ch in CHANNELS {
                    let _ = write!(out, " {}[{}]", ch.0, ch.1);
                }
                let _ = out.write_str("\r\n");
                ok!("")
            }
            "list" if want(0) => {
                let c = ctl.config();
                for p in PARAMS {
                    let _ = write!(
                        out,
                        "{} = {} {} [{} .. {}] default {} {} - {}\r\n",
                        p.name,
                        Num((p.get)(c)),
                        p.unit,
                        Num(p.min),
                        Num(p.max),
                        Num(p.default_value()),
                        if p.runtime { "rt" } else { "idle-only" },
                        p.desc
                    );
                }
                ok!("")
            }
            "get" if want(1) => {
                let n = a1.unwrap_or("");
                match params::find(n) {
                    Some(p) => ok!(" {} = {} {}", p.name, Num((p.get)(ctl.config())), p.unit),
                    None => fail!("unknown parameter '{}' (try list)", Clip(n)),
                }
            }
            "set" if want(2) => {
                let n = a1.unwrap_or("");
                let Some(p) = params::find(n) else {
                    fail!("unknown parameter '{}' (try list)", Clip(n))
                };
                let v = match parse_f32(a2.unwrap_or("")) {
                    Ok(v) => v,
                    Err(e) => fail!("'{}' {}", Clip(a2.unwrap_or("")), e),
                };
                let mut c = *ctl.config();
                if let Err(e) = p.apply(&mut c, v, running) {
                    fail!("{}: {}", p.name, e)
                }
                if let Err(e) = ctl.set_config(&c) {
                    fail!("{}", e)
                }
                ok!(" {} = {} {}", p.name, Num((p.get)(ctl.config())), p.unit)
            }
            "save" if want(0) => {
                if running {
                    fail!(
                        "save refused while running (mode idle first): flash erase stalls the loop"
                    )
                }
                match store.save(ctl.config()) {
                    Ok(()) => ok!(" saved"),
                    Err(e) => fail!("save failed: {}", e),
                }
            }
            "load" | "defaults" if want(0) => {
                if running {
                    fail!("{} refused while running (mode idle first)", cmd)
                }
                let c = if cmd == "load" {
                    match store.load() {
                        Ok(c) => c,
                        Err(e) => fail!("load failed: {}", e),
                    }
                } else {
                    store.factory()
                };
                match ctl.set_config(&c) {
                    Ok(()) => ok!(" {}", cmd),
                    Err(e) => fail!("{}", e),
                }
            }
            "status" if want(0) => {
                let t = ctl.telemetry();
                let _ = write!(
                    out,
                    "mode={} fault={} vbus={}V w={}rad/s x={}m id={}A iq={}A p={}W p_avg={}W energy={}J warnings=",
                    ctl.mode().name(),
                    ctl.fault().map(|f| f.name()).unwrap_or("none"),
                    Num(t.v_bus.to_num()),
                    Num(t.omega_m.to_num()),
                    Num(t.x.to_num()),
                    Num(t.i_dq.d.to_num()),
                    Num(t.i_dq.q.to_num()),
                    Num(t.p_elec.to_num()),
                    Num(self.p_avg_w),
                    Num(self.energy_j)
                );
                write_warnings(out, ctl.protection().warnings);
                let _ = out.write_str("\r\n");
                ok!("")
            }
            "faults" if want(0) => {
                let p = ctl.protection();
                let _ = write!(out, "warnings: ");
                write_warnings(out, p.warnings);
                let _ = write!(
                    out,
                    " i2t={} force_filt={}N derate={}\r\n",
                    Fixed(p.i2t(), 4),
                    Fixed(p.force_n(), 0),
                    Fixed(p.derate.to_num::<f32>(), 3)
                );
                match ctl.fault() {
                    Some(f) => {
                        let _ = write!(
                            out,
                            "fault {} {}: {}\r\nsafe state: {}\r\n",
                            f.code(),
                            f.name(),
                            f.describe(),
                            safe_words(f.safe_mode())
                        );
                        if let Some(r) = p.record() {
                            let s = &r.snap;
                            let _ = write!(
                                out,
                                "at t={} ms in mode {}: ia={} ib={} ic={} A id={} iq={} A vbus={} V w={} rad/s x={} m force={} N i2t={} derate={}\r\n",
                                s.t_ms,
                                s.mode.name(),
                                Fixed(s.i_abc[0].to_num::<f32>(), 3),
                                Fixed(s.i_abc[1].to_num::<f32>(), 3),
                                Fixed(s.i_abc[2].to_num::<f32>(), 3),
                                Fixed(s.i_dq.d.to_num::<f32>(), 3),
                                Fixed(s.i_dq.q.to_num::<f32>(), 3),
                                Fixed(s.v_bus.to_num::<f32>(), 2),
                                Fixed(s.omega_m.to_num::<f32>(), 2),
                                Fixed(s.x.to_num::<f32>(), 4),
                                Fixed(s.force_n, 0),
                                Fixed(s.i2t, 4),
                                Fixed(s.derate, 3)
                            );
                            for g in r.later() {
                                let _ = write!(
                                    out,
                                    "later: {} {}: {}\r\n",
                                    g.code(),
                                    g.name(),
                                    g.describe()
                                );
                            }
                        }
                        let _ = write!(out, "now in mode {}\r\n", ctl.mode().name());
                        ok!(" fault {} (safe mode {})", f.name(), f.safe_mode().name())
                    }
                    None => ok!(" no fault"),
                }
            }
            "clear" if want(0) => match (ctl.fault(), ctl.clear_fault()) {
                (None, _) => ok!(" no fault"),
                (Some(f), Ok(())) => ok!(" cleared {}", f.name()),
                (Some(f), Err(why)) => fail!("{} not cleared: {}", f.name(), why),
            },
            "mode" if want(1) => {
                let m = match a1.unwrap_or("") {
                    "idle" => Mode::Idle,
                    "run" => Mode::Run,
                    "short" | "brake" => Mode::Short,
                    "open" => Mode::Open,
                    o => fail!("unknown mode '{}' (idle|run|short|open)", Clip(o)),
                };
                match ctl.set_mode(m) {
                    Ok(()) => ok!(" mode {}", m.name()),
                    Err(f) => fail!("fault {} latched: clear it first", f.name()),
                }
            }
            "tel" if want(1) && a1 == Some("off") => {
                self.tel_every = 0;
                ok!(" tel off")
            }
            "tel" if want(2) => {
                let mut sel = [0u8; MAX_CH];
                let mut n = 0;
                for name in a1.unwrap_or("").split(',') {
                    let Some(i) = CHANNELS.iter().position(|c| c.0 == name) else {
                        fail!("unknown channel '{}' (see help)", Clip(name))
                    };
                    if n == MAX_CH {
                        fail!("at most {} channels", MAX_CH)
                    }
                    sel[n] = i as u8;
                    n += 1;
                }
                let rate = match parse_f32(a2.unwrap_or("")) {
                    Ok(r) if r.is_finite() && r > 0.0 => r,
                    _ => fail!("rate must be a positive number of Hz"),
                };
                let pwm = ctl.config().pwm_hz;
                if rate > pwm.min(2_000.0) {
                    fail!("rate must be <= {} Hz", Num(pwm.min(2_000.0)))
                }
                let every = pwm / rate;
                if every > 1.0e8 {
                    fail!("rate too low")
                }
                self.tel = sel;
                self.n_tel = n;
                self.tel_every = (every as u32).max(1);
                self.tel_count = 0;
                self.tel_periods = 0;
                let _ = out.write_str("# tel t");
                for &i in &sel[..n] {
                    let _ = write!(out, ",{}", CHANNELS[i as usize].0);
                }
                let _ = out.write_str("\r\n");
                ok!(" tel {} Hz", Num(pwm / self.tel_every as f32))
            }
            "help" | "list" | "get" | "set" | "save" | "load" | "defaults" | "status"
            | "faults" | "clear" | "mode" | "tel" => {
                fail!("wrong arguments for '{}' (see help)", cmd)
            }
            _ => fail!("unknown command '{}' (see help)", Clip(cmd)),
        }
    }
}

fn write_warnings<W: Write>(out: &mut W, w: u8) {
    if w == 0 {
        let _ = out.write_str("none");
        return;
    }
    let mut first = true;
    for (bit, name) in crate::protect::warn::NAMES {
        if w & bit != 0 {
            let _ = write!(out, "{}{}", if first { "" } else { "," }, name);
            first = false;
        }
    }
}

fn safe_words(m: Mode) -> &'static str {
    match m {
        Mode::Short => "short (low-side switches on: phases shorted, no power to the bus)",
        _ => "open (gates off: no current through the bridge)",
    }
}

/// Echo at most 24 characters of user input (keeps errors one short line).
struct Clip<'a>(&'a str);
impl core::fmt::Display for Clip<'_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        for (i, ch) in self.0.chars().enumerate() {
            if i == 24 {
                return f.write_str("…");
            }
            let ch = if ch.is_control() { '?' } else { ch };
            f.write_char(ch)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::string::String;

    fn run(con: &mut Console, ctl: &mut Controller, line: &str) -> (CmdResult, String) {
        let mut s = String::new();
        let r = con.execute(line, ctl, &mut NoStore, &mut s);
        (r, s)
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
        let (_, s) = run(&mut con, &mut ctl, "set r_load_ohm 1e99");
        assert_eq!(s, "error: '1e99' is out of the f32 range\r\n");
        let (_, s) = run(&mut con, &mut ctl, "set r_load_ohm nan");
        assert_eq!(s, "error: 'nan' is not a number\r\n");
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
        assert_eq!(s.lines().count(), PARAMS.len() + 1);
        let (r, s) = run(&mut con, &mut ctl, "help");
        assert!(r.is_ok() && s.ends_with("\r\nok\r\n"), "{s}");
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
        assert!(s.contains("warnings=none"), "{s}");
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

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(2000))]
        #[test]
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
