//! `regen client PORT [COMMAND...] [--script FILE]`: send console commands to a board's serial
//! port or to the pseudo-terminal of `regen serve`, print the replies, and fail (exit status 1)
//! on an `error:` reply or when a reply does not come in time.
//!
//! The console protocol (docs/console.md): every command ends with one line that starts with
//! `ok` or `error:`; lines before it belong to the reply (`list`, `status`, the `# tel`
//! header). Telemetry data lines (`t,v1,…`: they start with a digit or a sign) may arrive at
//! any time while streaming is on; [`is_telemetry`] tells them apart.
//!
//! The console echoes what it receives and writes a prompt (`> `) after each reply. The client
//! strips the prompt from the start of every line and skips empty lines; the echo of the
//! command it sent (computed with the firmware's own [`LineEditor`]) marks where the reply
//! starts, and what came before it (a banner, a late line of an earlier reply) is dropped.

use regen_fw::console::{LineEditor, PROMPT};
use serialport::SerialPort;
use std::io::Read;
use std::path::PathBuf;
use std::time::{Duration, Instant};

#[derive(clap::Args, Debug)]
pub struct ClientArgs {
    /// Serial port: a board's (/dev/ttyACM0, COM3) or the pseudo-terminal `regen serve` printed.
    pub port: String,
    /// Commands, one per argument: `regen client /dev/pts/3 "set r_load_ohm 306" status`.
    pub commands: Vec<String>,
    /// Baud rate, 50 … 4,000,000 (ignored by a pseudo-terminal).
    #[arg(long, default_value_t = 115_200)]
    pub baud: u32,
    /// Commands from a file, one per line; blank lines and `#` comments are skipped. Run after
    /// the COMMAND arguments.
    #[arg(long)]
    pub script: Option<PathBuf>,
    /// Seconds to wait for each reply's `ok`/`error:` line, (0, 3600].
    #[arg(long, default_value_t = 2.0, allow_negative_numbers = true)]
    pub timeout: f64,
    /// After the last command, keep printing what arrives (telemetry) for this many seconds,
    /// [0, 86400].
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub listen: f64,
    /// Go on after an error reply (the exit status is still 1).
    #[arg(long)]
    pub keep_going: bool,
}

/// Whether a received line is a telemetry data line (`t,v1,…`), not part of a reply.
pub fn is_telemetry(line: &str) -> bool {
    line.starts_with(|c: char| c.is_ascii_digit() || c == '-' || c == '+' || c == '.')
}

/// Whether a line ends a reply, and how.
fn verdict(line: &str) -> Option<bool> {
    if line == "ok" || line.starts_with("ok ") {
        Some(true)
    } else if line.starts_with("error:") {
        Some(false)
    } else {
        None
    }
}

/// The answer to one command.
#[derive(Clone, Debug, Default)]
pub struct Reply {
    /// Every line received for it, in order, its final `ok …`/`error: …` line last
    /// (telemetry lines that arrived meanwhile included: see [`is_telemetry`]).
    pub lines: Vec<String>,
}

impl Reply {
    /// The final line.
    pub fn last(&self) -> &str {
        self.lines.last().map_or("", |s| s.as_str())
    }
    pub fn is_ok(&self) -> bool {
        verdict(self.last()) == Some(true)
    }
    /// The reply's lines without telemetry.
    pub fn body(&self) -> impl Iterator<Item = &str> {
        self.lines
            .iter()
            .map(|s| s.as_str())
            .filter(|l| !is_telemetry(l))
    }
}

/// Why a command failed.
#[derive(Clone, Debug)]
pub enum ClientError {
    /// The port failed.
    Io(String),
    /// No `ok`/`error:` line in time; what did arrive.
    Timeout { command: String, partial: Reply },
}

impl std::fmt::Display for ClientError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ClientError::Io(e) => write!(f, "port: {e}"),
            ClientError::Timeout { command, .. } => {
                write!(f, "no reply to '{command}' in time")
            }
        }
    }
}

/// A console connection over a serial port.
pub struct Client {
    port: Box<dyn SerialPort>,
    buf: Vec<u8>,
    /// How long [`Client::command`] waits for the final line.
    pub timeout: Duration,
}

impl Client {
    /// Open `path` at `baud` (8N1, no flow control) and drop whatever was pending.
    pub fn open(path: &str, baud: u32, timeout: Duration) -> Result<Client, String> {
        let port = serialport::new(path, baud)
            .timeout(Duration::from_millis(20))
            .open()
            .map_err(|e| format!("port {path}: cannot open as a serial port: {e}"))?;
        let _ = port.clear(serialport::ClearBuffer::All);
        Ok(Client {
            port,
            buf: Vec::new(),
            timeout,
        })
    }

    /// The next complete non-empty line (without its CR/LF and any leading prompts), or
    /// `None` at `deadline`.
    pub fn read_line(&mut self, deadline: Instant) -> Result<Option<String>, ClientError> {
        loop {
            if let Some(i) = self.buf.iter().position(|&b| b == b'\n') {
                let raw: Vec<u8> = self.buf.drain(..=i).collect();
                let s = String::from_utf8_lossy(&raw);
                let mut t = s.trim_end_matches(['\r', '\n']);
                while let Some(r) = t.strip_prefix(PROMPT) {
                    t = r;
                }
                if t.is_empty() {
                    continue;
                }
                return Ok(Some(t.to_string()));
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
            let mut chunk = [0u8; 4096];
            match self.port.read(&mut chunk) {
                Ok(k) => self.buf.extend_from_slice(&chunk[..k]),
                Err(e)
                    if e.kind() == std::io::ErrorKind::TimedOut
                        || e.kind() == std::io::ErrorKind::WouldBlock
                        || e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(ClientError::Io(e.to_string())),
            }
        }
    }

    /// Send one command line and collect its reply (an `error:` reply is an `Ok(Reply)`
    /// with `is_ok() == false`). A line with a control character is not sent.
    pub fn command(&mut self, line: &str) -> Result<Reply, ClientError> {
        let line = line.trim();
        if line.chars().any(|c| c.is_control()) {
            return Err(ClientError::Io(format!(
                "'{}': a command is one line without control characters",
                line.escape_debug()
            )));
        }
        self.send_raw(line.as_bytes())
    }

    /// Send `bytes` followed by LF as one line, unchecked (a test's malformed input), and
    /// collect the reply like [`Client::command`].
    pub fn send_raw(&mut self, bytes: &[u8]) -> Result<Reply, ClientError> {
        let line = String::from_utf8_lossy(bytes).into_owned();
        let mut bytes = bytes.to_vec();
        bytes.push(b'\n');
        let echo = echo_of(&bytes);
        let mut seen = echo.is_empty();
        self.port
            .write_all(&bytes)
            .and_then(|_| self.port.flush())
            .map_err(|e| ClientError::Io(e.to_string()))?;
        let deadline = Instant::now() + self.timeout;
        let mut reply = Reply::default();
        while let Some(l) = self.read_line(deadline)? {
            if !seen {
                seen = l == echo;
                if is_telemetry(&l) {
                    reply.lines.push(l);
                }
                continue;
            }
            let end = !is_telemetry(&l) && verdict(&l).is_some();
            reply.lines.push(l);
            if end {
                return Ok(reply);
            }
        }
        Err(ClientError::Timeout {
            command: line,
            partial: reply,
        })
    }
}

/// The echo the console's line editor gives for `bytes`: its first line, without the line end.
pub fn echo_of(bytes: &[u8]) -> String {
    let mut ed = LineEditor::new();
    let mut e = String::new();
    for &b in bytes {
        if ed.feed(b, &mut e).is_some() {
            break;
        }
    }
    e.split("\r\n").next().unwrap_or("").to_string()
}

/// Whether a script line or a command argument is a command: blank ones and `#` comments are
/// skipped (the console answers a blank line with nothing, so waiting for its reply would
/// only time out).
fn is_command(line: &str) -> bool {
    let l = line.trim();
    !l.is_empty() && !l.starts_with('#')
}

/// The command list of a script: one per line, blank lines and `#` comments skipped.
pub fn script_commands(text: &str) -> Vec<String> {
    text.lines()
        .filter(|l| is_command(l))
        .map(|l| l.trim().to_string())
        .collect()
}

/// The checks of the command line's numbers (comparisons written to refuse NaN).
#[allow(clippy::neg_cmp_op_on_partial_ord)]
fn check_args(a: &ClientArgs) -> Result<(), String> {
    if !(a.timeout > 0.0 && a.timeout <= 3600.0) {
        return Err(format!("--timeout = {}: must be in (0, 3600] s", a.timeout));
    }
    if !(a.listen >= 0.0 && a.listen <= 86_400.0) {
        return Err(format!("--listen = {}: must be in [0, 86400] s", a.listen));
    }
    if !(50..=4_000_000).contains(&a.baud) {
        return Err(format!("--baud = {}: must be in [50, 4000000] Bd", a.baud));
    }
    Ok(())
}

pub fn run(a: &ClientArgs) -> Result<(), String> {
    check_args(a)?;
    let mut cmds: Vec<String> = a
        .commands
        .iter()
        .filter(|c| is_command(c))
        .cloned()
        .collect();
    if let Some(p) = &a.script {
        let text =
            std::fs::read_to_string(p).map_err(|e| format!("--script {}: {e}", p.display()))?;
        cmds.extend(script_commands(&text));
    }
    if cmds.is_empty() && a.listen == 0.0 {
        return Err(
            "nothing to do: give commands (`regen client PORT status`), --script FILE or --listen S"
                .into(),
        );
    }
    let mut c = Client::open(&a.port, a.baud, Duration::from_secs_f64(a.timeout))?;
    let mut refused = 0;
    for cmd in &cmds {
        match c.command(cmd) {
            Ok(r) => {
                for l in &r.lines {
                    println!("{l}");
                }
                if !r.is_ok() {
                    refused += 1;
                    if !a.keep_going {
                        // The `error:` line is printed: exit status 1 without repeating it.
                        std::process::exit(1);
                    }
                }
            }
            Err(e) => {
                if let ClientError::Timeout { partial, .. } = &e {
                    for l in &partial.lines {
                        println!("{l}");
                    }
                }
                return Err(e.to_string());
            }
        }
    }
    let end = Instant::now() + Duration::from_secs_f64(a.listen);
    while let Some(l) = c.read_line(end).map_err(|e| e.to_string())? {
        println!("{l}");
    }
    if refused > 0 {
        // Each `error:` line is printed above.
        std::process::exit(1);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn script_skips_comments_and_blank_lines() {
        let s = "# set up\n\nset r_load_ohm 306\n  status  \n#tel p 10\n";
        assert_eq!(script_commands(s), ["set r_load_ohm 306", "status"]);
    }

    #[test]
    fn telemetry_and_verdict_lines() {
        assert!(is_telemetry("0.010000,23.1"));
        assert!(is_telemetry("-1,2"));
        assert!(!is_telemetry("# tel t,p"));
        assert!(!is_telemetry("mode=run fault=none"));
        assert_eq!(verdict("ok"), Some(true));
        assert_eq!(verdict("ok r_load_ohm = 306 ohm"), Some(true));
        assert_eq!(verdict("okay"), None);
        assert_eq!(
            verdict("error: unknown command 'x' (see help)"),
            Some(false)
        );
        assert_eq!(verdict("r_load_ohm = 306 ohm [0 .. inf] …"), None);
    }

    #[test]
    fn echo_is_the_line_editors() {
        assert_eq!(echo_of(b"status\n"), "status");
        assert_eq!(
            echo_of(b"get r_load_ohx\x7fm\r\n"),
            "get r_load_ohx\x08 \x08m"
        );
        assert_eq!(echo_of(b"\xff\xfe set\n"), " set");
    }
}
