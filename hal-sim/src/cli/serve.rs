//! `regen serve [SCENARIO] [--speed X]`: a simulated drive on a pseudo-terminal.
//!
//! The scenario's closed loop runs in real time (or `--speed X` times faster, `max` = as fast
//! as the machine can) and the firmware's console ([`crate::drive::SimDrive`]: the unchanged
//! executor, the controller of the simulation and a simulated flash store) answers on a
//! pseudo-terminal whose path is printed, so `picocom`, `screen`, `minicom` or `regen client`
//! connect to it as to a board's serial port.
//!
//! Terminal side: the firmware's own [`LineEditor`] (echo, Backspace/DEL, Ctrl-U) assembles
//! the lines, the console greets each new reader with [`Console::banner`], writes the prompt
//! after every reply and announces a latched fault unasked ([`Console::notice`]), exactly as
//! the board does over its UART. A new reader starts in the human console; `machine on`
//! switches to the machine-readable mode (no echo, prompt or banner; tagged lines).
//!
//! Loop: read what arrived (non-blocking) and execute each complete line between two control
//! periods, run a chunk of periods (0.5 ms of wall time at the requested speed, at most 2000
//! periods), queue the telemetry lines they produced, write what the pty takes, then sleep
//! until wall time catches up with `simulated time / speed`. A simulation that cannot keep up
//! runs as fast as it can (`sim` and the final summary show the real factor).
//!
//! Output policy, as a UART with a bounded transmit queue: command replies are always queued;
//! a telemetry line is dropped (and counted) when the queue holds more than
//! [`QUEUE_LIMIT`] bytes, i.e. when the reader does not keep up; while no one has the pty open
//! the output is discarded (no stale backlog for the next reader).
//!
//! Link: the loop ([`Server`]) talks to its reader through a [`Link`]: the pseudo-terminal
//! here ([`Pty`]), the WebSocket bridge of `regen ui` (`super::ui`). Both run this one loop.
//!
//! PTY choice: `serialport::TTYPort::pair()` (posix_openpt, grantpt, unlockpt, ptsname and raw
//! mode on the slave, without unsafe code, on Linux, macOS and the BSDs; the same crate as
//! the client). The slave end is closed at once, so the pty's buffer only fills when someone
//! reads it. The master is then read and written with non-blocking `read`/`write` (nix)
//! rather than through the `TTYPort` I/O, which polls with a timeout and reports a hang-up
//! even when input is still pending.

use crate::drive::SimDrive;
use crate::Scenario;
use nix::errno::Errno;
use regen_fw::console::{Console, LineEditor};
use serialport::SerialPort;
use std::os::unix::io::{AsRawFd, RawFd};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Longest accepted console line (the board's receive buffer), bytes.
pub const MAX_LINE: usize = regen_fw::console::LINE_MAX;
/// Output queue size beyond which telemetry lines are dropped, bytes.
pub const QUEUE_LIMIT: usize = 256 * 1024;
/// Most control periods between two looks at the pty.
const MAX_CHUNK: u64 = 2000;

#[derive(clap::Args, Debug)]
pub struct ServeArgs {
    /// Scenario file (TOML). Default: the reference TMD at 306 Ω (as
    /// hal-sim/scenarios/tmd-306.toml). Its duration is ignored: see --duration.
    pub scenario: Option<PathBuf>,
    /// Simulated seconds per wall-clock second, (0, 1e6]: 1 = real time, 20 = twenty times
    /// faster; `max` = as fast as the machine can.
    #[arg(long, default_value = "1", allow_negative_numbers = true)]
    pub speed: String,
    /// Stop after this many simulated seconds, (0, 1e9] (default: run until Ctrl-C).
    #[arg(long, allow_negative_numbers = true)]
    pub duration: Option<f64>,
    /// Also create a symbolic link to the pseudo-terminal at this path (a stable name for
    /// scripts), removed on exit.
    #[arg(long)]
    pub link: Option<PathBuf>,
}

/// Highest finite `--speed`.
pub const SPEED_MAX: f64 = 1e6;
/// Longest `--duration`, simulated s.
pub const DURATION_MAX: f64 = 1e9;

/// `--speed`: a number in (0, [`SPEED_MAX`]] or `max` (infinite: as fast as possible).
pub fn parse_speed(s: &str) -> Result<f64, String> {
    if s == "max" {
        return Ok(f64::INFINITY);
    }
    match s.trim().parse::<f64>() {
        Ok(v) if v > 0.0 && v <= SPEED_MAX => Ok(v),
        _ => Err(format!(
            "--speed = {s}: must be in (0, {SPEED_MAX:e}] simulated s per wall-clock s, or `max`"
        )),
    }
}

/// What a run did.
#[derive(Clone, Copy, Debug)]
pub struct Summary {
    pub sim_s: f64,
    pub wall_s: f64,
    pub lines: u64,
    pub dropped_tel_lines: u64,
}

/// The byte link between a served drive and its reader, read and written without blocking.
pub trait Link {
    /// Bytes received since the last call, into `buf`; 0 when none is pending.
    fn read(&mut self, buf: &mut [u8]) -> usize;
    /// Whether a reader is there now (a new one gets the banner; without one, output is
    /// discarded).
    fn connected(&mut self) -> bool;
    /// Write from `bytes` what the link takes now; the count taken (all of them when the
    /// reader is gone: the bytes go nowhere, as on an unplugged UART).
    fn write(&mut self, bytes: &[u8]) -> usize;
    /// Drop what the link still holds for a reader that left (no stale backlog for the next).
    fn discard(&mut self) {}
}

/// The master end of a pseudo-terminal, non-blocking.
pub struct Pty {
    /// Owns the master end (closed on drop).
    _master: serialport::TTYPort,
    fd: RawFd,
    path: String,
}

impl Pty {
    /// Open a pseudo-terminal; its slave end is closed at once.
    pub fn open() -> Result<Pty, String> {
        let (master, slave) =
            serialport::TTYPort::pair().map_err(|e| format!("pseudo-terminal: {e}"))?;
        let path = slave
            .name()
            .ok_or("pseudo-terminal: the slave has no name")?;
        drop(slave);
        let fd = master.as_raw_fd();
        nix::fcntl::fcntl(
            fd,
            nix::fcntl::FcntlArg::F_SETFL(nix::fcntl::OFlag::O_NONBLOCK),
        )
        .map_err(|e| format!("pseudo-terminal: {e}"))?;
        Ok(Pty {
            _master: master,
            fd,
            path,
        })
    }

    /// The pseudo-terminal to connect to.
    pub fn path(&self) -> &str {
        &self.path
    }
}

impl Link for Pty {
    fn read(&mut self, buf: &mut [u8]) -> usize {
        loop {
            match nix::unistd::read(self.fd, buf) {
                Ok(k) => return k,
                Err(Errno::EINTR) => continue,
                // EAGAIN: nothing pending; EIO: no one has the slave open.
                Err(_) => return 0,
            }
        }
    }

    /// Whether someone has the slave end open (the master reports no hang-up).
    fn connected(&mut self) -> bool {
        use nix::poll::{poll, PollFd, PollFlags};
        let mut p = [PollFd::new(self.fd, PollFlags::POLLOUT)];
        !(matches!(poll(&mut p, 0), Ok(n) if n > 0)
            && p[0]
                .revents()
                .is_some_and(|r| r.contains(PollFlags::POLLHUP)))
    }

    fn write(&mut self, bytes: &[u8]) -> usize {
        loop {
            match nix::unistd::write(self.fd, bytes) {
                Ok(k) => return k,
                Err(Errno::EINTR) => continue,
                Err(Errno::EAGAIN) => return 0,
                // EIO: no one has the slave open.
                Err(_) => return bytes.len(),
            }
        }
    }

    fn discard(&mut self) {
        let _ = nix::sys::termios::tcflush(self.fd, nix::sys::termios::FlushArg::TCOFLUSH);
    }
}

/// A simulated drive served over a [`Link`].
pub struct Server<L: Link> {
    drive: SimDrive,
    link: L,
    speed: f64,
    ed: LineEditor,
    /// Whether a reader was there at the last look (a new one gets the banner).
    connected: bool,
    out: Vec<u8>,
    out_pos: usize,
    lines: u64,
    dropped: u64,
}

impl<L: Link> Server<L> {
    /// Serve `drive` over `link` at `speed` (simulated s per wall s; infinite = as fast as
    /// possible).
    pub fn new(drive: SimDrive, link: L, speed: f64) -> Result<Server<L>, String> {
        if speed.is_nan() || speed <= 0.0 {
            return Err(format!("speed = {speed}: must be > 0"));
        }
        Ok(Server {
            drive,
            link,
            speed,
            ed: LineEditor::new(),
            connected: false,
            out: Vec::new(),
            out_pos: 0,
            lines: 0,
            dropped: 0,
        })
    }

    pub fn link(&self) -> &L {
        &self.link
    }

    pub fn drive(&self) -> &SimDrive {
        &self.drive
    }

    /// Serve until `stop` is set or `duration` simulated seconds have passed.
    pub fn run(&mut self, stop: &AtomicBool, duration: Option<f64>) -> Summary {
        let ts = self.drive.sim().period();
        let chunk = if self.speed.is_finite() {
            ((self.speed * 0.5e-3 / ts).ceil() as u64).clamp(1, MAX_CHUNK)
        } else {
            MAX_CHUNK
        };
        let n_max = duration.map(|d| (d / ts).round().max(0.0) as u64);
        let wall0 = Instant::now();
        let mut n: u64 = 0;
        let mut tel = String::new();
        while !stop.load(Ordering::Relaxed) && n_max.is_none_or(|m| n < m) {
            // A new reader is greeted before anything it sent is read: its first command
            // (`machine on`) must not be undone by the greeting's reset of the console.
            self.look_for_reader();
            self.poll_input();
            let k = n_max.map_or(chunk, |m| chunk.min(m - n));
            tel.clear();
            for _ in 0..k {
                self.drive.step(&mut tel);
            }
            n += k;
            self.queue_telemetry(&tel);
            tel.clear();
            if self.drive.notice(&mut tel) {
                self.out.extend_from_slice(tel.as_bytes());
            }
            // A `cap dump` under way: one piece per pass, as the board's console task sends
            // one between reads, so a line typed meanwhile is read without waiting for it.
            if self.drive.dumping() {
                tel.clear();
                if !self.drive.dump_more(&mut tel) {
                    tel.push_str(self.drive.console().prompt());
                }
                self.out.extend_from_slice(tel.as_bytes());
            }
            self.flush();
            if self.speed.is_finite() {
                let target = n as f64 * ts / self.speed;
                let ahead = target - wall0.elapsed().as_secs_f64();
                if ahead > 0.0 {
                    std::thread::sleep(Duration::from_secs_f64(ahead.min(2e-3)));
                }
            }
        }
        // Last replies out (a reader may still be waiting for one).
        let t_end = Instant::now() + Duration::from_millis(200);
        while self.out_pos < self.out.len() && Instant::now() < t_end {
            self.flush();
            std::thread::sleep(Duration::from_millis(1));
        }
        Summary {
            sim_s: n as f64 * ts,
            wall_s: wall0.elapsed().as_secs_f64(),
            lines: self.lines,
            dropped_tel_lines: self.dropped,
        }
    }

    fn poll_input(&mut self) {
        let mut buf = [0u8; 512];
        loop {
            let k = self.link.read(&mut buf);
            if k == 0 {
                return;
            }
            for &b in &buf[..k] {
                self.byte(b);
            }
        }
    }

    /// One received byte, through the console's line editor; a complete line is executed and
    /// answered, then the prompt (after a `cap dump`'s last piece, [`Self::run`]). As on the
    /// board, a person's byte received while a dump is under way ends it first; in machine
    /// mode the line decides ([`regen_fw::console::Console::dump_interrupt`]).
    fn byte(&mut self, b: u8) {
        let mut text = String::new();
        self.drive.dump_byte(&mut text);
        self.ed.set_machine(self.drive.console().machine());
        if let Some(line) = self.ed.feed(b, &mut text) {
            if !line.is_empty() {
                let line = line.to_string();
                let _ = self.drive.execute(&line, &mut text);
                self.lines += 1;
            }
            if !self.drive.dumping() {
                text.push_str(self.drive.console().prompt());
            }
        }
        self.out.extend_from_slice(text.as_bytes());
    }

    fn queue_telemetry(&mut self, tel: &str) {
        for l in tel.split_inclusive('\n') {
            if self.out.len() - self.out_pos + l.len() > QUEUE_LIMIT {
                self.dropped += 1;
            } else {
                self.out.extend_from_slice(l.as_bytes());
            }
        }
    }

    /// Whether a reader is there; a new one gets the human console (as after a board's reset)
    /// and the banner first, before anything queued.
    fn look_for_reader(&mut self) {
        let up = self.link.connected();
        if up && !self.connected {
            self.drive.set_machine(false);
            let ctl = self.drive.sim().controller();
            let mut b = String::new();
            Console::banner(ctl.mode(), ctl.fault(), &mut b);
            self.out.splice(self.out_pos..self.out_pos, b.bytes());
        }
        self.connected = up;
    }

    /// Write what is queued to the reader found by the last [`Self::look_for_reader`].
    fn flush(&mut self) {
        let up = self.connected;
        if self.out_pos < self.out.len() && !up {
            // No reader: the output goes nowhere, as on an unplugged UART, and what the link
            // still holds is dropped so the next reader gets no stale backlog.
            self.link.discard();
            self.out.clear();
            self.out_pos = 0;
            return;
        }
        while self.out_pos < self.out.len() {
            let k = self.link.write(&self.out[self.out_pos..]);
            if k == 0 {
                break;
            }
            self.out_pos += k;
        }
        if self.out_pos == self.out.len() {
            self.out.clear();
            self.out_pos = 0;
        } else if self.out_pos > QUEUE_LIMIT {
            self.out.drain(..self.out_pos);
            self.out_pos = 0;
        }
    }
}

pub(crate) static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: nix::libc::c_int) {
    STOP.store(true, Ordering::Relaxed);
}

/// Ctrl-C (SIGINT) and SIGTERM set [`STOP`] instead of killing the process, so the run ends
/// with its summary and the link is removed.
pub(crate) fn catch_signals() -> Result<(), String> {
    use nix::sys::signal::{sigaction, SaFlags, SigAction, SigHandler, SigSet, Signal};
    let act = SigAction::new(
        SigHandler::Handler(on_signal),
        SaFlags::SA_RESTART,
        SigSet::empty(),
    );
    for s in [Signal::SIGINT, Signal::SIGTERM] {
        // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
        unsafe { sigaction(s, &act) }.map_err(|e| format!("signal handler: {e}"))?;
    }
    Ok(())
}

/// The scenario file at `path`, or the reference TMD at 306 Ω (as
/// hal-sim/scenarios/tmd-306.toml).
pub fn scenario(path: Option<&std::path::Path>) -> Result<Scenario, String> {
    match path {
        Some(p) => Scenario::from_file(p),
        None => {
            let mut s = Scenario::tmd(306.0);
            s.name = "tmd-306".into();
            Ok(s)
        }
    }
}

pub fn run(a: &ServeArgs) -> Result<(), String> {
    let speed = parse_speed(&a.speed)?;
    if let Some(d) = a.duration {
        if !(d > 0.0 && d <= DURATION_MAX) {
            return Err(format!(
                "--duration = {d}: must be in (0, {DURATION_MAX:e}] simulated s"
            ));
        }
    }
    let sc = scenario(a.scenario.as_deref())?;
    let drive = SimDrive::from_scenario(&sc)?;
    let mut srv = Server::new(drive, Pty::open()?, speed)?;
    catch_signals()?;
    if let Some(l) = &a.link {
        let _ = std::fs::remove_file(l);
        std::os::unix::fs::symlink(srv.link().path(), l)
            .map_err(|e| format!("--link {}: {e}", l.display()))?;
    }
    let speed = if speed.is_finite() {
        format!("{speed}× real time")
    } else {
        "as fast as possible".into()
    };
    println!(
        "regen serve: scenario {} at {speed}, console on {}",
        sc.name,
        srv.link().path()
    );
    println!(
        "connect with: picocom {} (or screen, minicom, regen client); Ctrl-C stops",
        a.link
            .as_deref()
            .map_or(srv.link().path().into(), |l| l.display().to_string())
    );
    use std::io::Write;
    let _ = std::io::stdout().flush();
    let s = srv.run(&STOP, a.duration);
    if let Some(l) = &a.link {
        let _ = std::fs::remove_file(l);
    }
    let e = srv.drive().sim().energy();
    println!(
        "stopped: {:.3} s simulated in {:.3} s ({:.1}× real time), {} lines executed, {} telemetry lines dropped",
        s.sim_s,
        s.wall_s,
        s.sim_s / s.wall_s.max(1e-9),
        s.lines,
        s.dropped_tel_lines
    );
    println!(
        "plant: {:.3} J into the load, energy residual {:.3e} ({:.4} % of the largest flow)",
        e.to_inverter,
        e.residual(),
        100.0 * e.relative_residual()
    );
    if let Some(f) = srv.drive().sim().controller().fault() {
        println!("firmware fault latched: {}", f.name());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_new_readers_first_command_is_not_undone_by_its_greeting() {
        let sc = scenario(None).unwrap();
        // A reader there from the start, its first lines already waiting.
        let link = Scripted {
            script: vec![("", "machine on\n#1 status\n")],
            from: 0,
            output: Vec::new(),
        };
        let mut srv =
            Server::new(SimDrive::from_scenario(&sc).unwrap(), link, f64::INFINITY).unwrap();
        srv.run(&AtomicBool::new(false), Some(1e-3));
        let out = String::from_utf8_lossy(&srv.link().output).into_owned();
        assert!(srv.drive().console().machine(), "{out}");
        let banner = out.find("console.").expect("the banner");
        let ok = out.find("R - ok").expect("machine on answered");
        assert!(banner < ok, "{out}");
        assert!(
            out.contains("R 1 ok"),
            "status answered in machine form: {out}"
        );
    }

    /// A reader that sends each of its lines once the output holds the text the line waits
    /// for (after where the previous line was sent).
    struct Scripted {
        script: Vec<(&'static str, &'static str)>,
        from: usize,
        output: Vec<u8>,
    }

    impl Link for Scripted {
        fn read(&mut self, buf: &mut [u8]) -> usize {
            let Some(&(wait, line)) = self.script.first() else {
                return 0;
            };
            let seen = String::from_utf8_lossy(&self.output[self.from..]).contains(wait);
            if !seen || buf.len() < line.len() {
                return 0;
            }
            buf[..line.len()].copy_from_slice(line.as_bytes());
            self.script.remove(0);
            self.from = self.output.len();
            line.len()
        }
        fn connected(&mut self) -> bool {
            true
        }
        fn write(&mut self, bytes: &[u8]) -> usize {
            self.output.extend_from_slice(bytes);
            bytes.len()
        }
    }

    /// A `cap dump` is written one piece per pass of the serving loop, and a line typed while
    /// it is under way is not kept waiting: its first byte ends the dump (`error: cap dump
    /// stopped after N samples: input received`, N the sample lines written), then the line
    /// (`mode idle`) is executed and answered. A dump nobody interrupts ends `ok 1024
    /// samples`, then the prompt.
    #[test]
    fn a_line_during_a_cap_dump_ends_it_and_is_executed() {
        let sc = scenario(None).unwrap();
        let n = regen_fw::capture::SAMPLES;
        let link = Scripted {
            script: vec![
                ("console.", "cap ch ia,iq\ncap arm\ncap now\n"),
                ("# cap ready", "cap dump\n"),
                ("\r\nt,ia,iq\r\n", "mode idle\n"),
                ("ok", "cap dump\n"),
            ],
            from: 0,
            output: Vec::new(),
        };
        let mut srv =
            Server::new(SimDrive::from_scenario(&sc).unwrap(), link, f64::INFINITY).unwrap();
        srv.run(&AtomicBool::new(false), Some(2.0));
        let out = String::from_utf8_lossy(&srv.link().output).into_owned();
        assert!(srv.link().script.is_empty(), "a line never sent:\n{out}");
        let at = |from: usize, what: &str| {
            from + out[from..]
                .find(what)
                .unwrap_or_else(|| panic!("no {what:?} after byte {from}:\n{out}"))
        };
        // The first dump: its header, whole sample lines, the line that ends it.
        let h1 = at(0, "\r\nt,ia,iq\r\n") + "\r\nt,ia,iq\r\n".len();
        let stop = at(h1, "error: cap dump stopped after ");
        let rows = out[h1..stop].lines().count();
        let said: usize = out[stop..].split(' ').nth(5).unwrap().parse().unwrap();
        std::println!("the dump stopped after {rows} of {n} samples");
        assert!(rows >= 1 && rows < n, "{rows} rows before the line");
        assert_eq!(said, rows, "{}", &out[stop..stop + 80]);
        assert!(
            out[h1..stop].lines().all(|l| l.split(',').count() == 3),
            "a partial or foreign line among the samples"
        );
        assert!(!out[h1..stop].contains("samples"));
        // Then the line itself, answered, and in force.
        let ok = at(stop, "ok");
        assert!(out[stop..ok].contains("mode idle"), "{}", &out[stop..ok]);
        assert_eq!(
            srv.drive().sim().controller().mode(),
            regen_fw::control::Mode::Idle
        );
        // The second dump, left alone: every sample, `ok N samples`, then the prompt.
        let h2 = at(ok, "\r\nt,ia,iq\r\n") + "\r\nt,ia,iq\r\n".len();
        let end = at(h2, &format!("ok {n} samples\r\n"));
        assert_eq!(out[h2..end].lines().count(), n);
        assert!(out[end..].contains(srv.drive().console().prompt()));
    }
}
