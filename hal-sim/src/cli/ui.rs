//! `regen ui [--sim SCENARIO | --port DEV] [--listen ADDR:PORT]`: the browser UI (docs/ui.md).
//!
//! Serves the page (built from `ui/`, checked in as `hal-sim/ui-dist/` and embedded here, so
//! no Node.js is needed to run it) and bridges the drive's console over a WebSocket at `/ws`:
//! each message from the drive is one or more whole console lines; each message to the drive
//! is one or more whole command lines. The drive is the simulated one (`--sim`: the same
//! [`serve::Server`] loop `regen serve` runs, over a [`WsLink`] instead of a pseudo-terminal)
//! or a board's serial port (`--port`).
//!
//! Safety (docs/ui.md, "What an attacker on the same machine can do"): loopback by default;
//! every request must name a host this server answers for (against DNS rebinding); `/ws` and
//! `/api/*` need the per-run token printed in the URL (compared in constant time); `/ws` needs
//! an `Origin` equal to the page's own; one page drives the drive at a time. A bad WebSocket
//! message gets one line `! refused: …` back and nothing reaches the drive.

use super::serve::{self, Link, Server};
use crate::analytic::{logspace, optimum_load, tmd_power, DampingFormula};
use crate::drive::SimDrive;
use crate::plant::{Drive, Excitation};
use crate::Scenario;
use axum::extract::ws::rejection::WebSocketUpgradeRejection;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{Query, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::Router;
use std::collections::HashMap;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::mpsc;

/// Longest message the page may send, bytes (a few pipelined command lines).
pub const MSG_MAX: usize = 4096;
/// Messages from the drive waiting for the page before the link reports itself full (the
/// server's loop then queues, and past its limit drops telemetry, as a UART would).
const OUT_QUEUE: usize = 4096;

#[derive(clap::Args, Debug)]
pub struct UiArgs {
    /// Simulated drive: a scenario file (TOML), served as `regen serve` does. Default when
    /// --port is not given: the reference TMD at 306 Ω.
    #[arg(long, conflicts_with = "port")]
    pub sim: Option<PathBuf>,
    /// A board's serial port (/dev/ttyACM0, COM3) instead of the simulated drive.
    #[arg(long)]
    pub port: Option<String>,
    /// Baud rate of --port, 50 … 4,000,000.
    #[arg(long, default_value_t = 115_200)]
    pub baud: u32,
    /// Address and port to listen on (port 0: any free one). Loopback unless told otherwise.
    #[arg(long, default_value = "127.0.0.1:8733")]
    pub listen: String,
    /// Simulated seconds per wall-clock second for --sim, (0, 1e6] (1 = real time).
    #[arg(long, default_value = "1", allow_negative_numbers = true)]
    pub speed: String,
}

/// One page's session: what it sends to the drive, and the drive's output for it.
struct Session {
    to_drive: mpsc::UnboundedReceiver<Vec<u8>>,
    from_drive: mpsc::Sender<String>,
}

/// The session the drive is bridged to (at most one page at a time).
#[derive(Clone, Default)]
pub struct Slot(Arc<Mutex<Option<Session>>>);

impl Slot {
    fn lock(&self) -> std::sync::MutexGuard<'_, Option<Session>> {
        self.0.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The live session, dropping one whose page has gone.
    fn live(&self) -> std::sync::MutexGuard<'_, Option<Session>> {
        let mut g = self.lock();
        if g.as_ref().is_some_and(|s| s.from_drive.is_closed()) {
            *g = None;
        }
        g
    }
}

/// The simulated drive's side of the WebSocket bridge: a [`Link`] for [`Server`].
pub struct WsLink {
    slot: Slot,
    pending: Vec<u8>,
}

impl WsLink {
    pub fn new(slot: Slot) -> WsLink {
        WsLink {
            slot,
            pending: Vec::new(),
        }
    }
}

impl Link for WsLink {
    fn read(&mut self, buf: &mut [u8]) -> usize {
        if self.pending.is_empty() {
            let mut g = self.slot.live();
            match g.as_mut().map(|s| s.to_drive.try_recv()) {
                Some(Ok(m)) => self.pending = m,
                _ => return 0,
            }
        }
        let k = self.pending.len().min(buf.len());
        buf[..k].copy_from_slice(&self.pending[..k]);
        self.pending.drain(..k);
        k
    }

    fn connected(&mut self) -> bool {
        let up = self.slot.live().is_some();
        if !up {
            self.pending.clear();
        }
        up
    }

    fn write(&mut self, bytes: &[u8]) -> usize {
        let g = self.slot.live();
        let Some(s) = g.as_ref() else {
            return bytes.len();
        };
        match s
            .from_drive
            .try_send(String::from_utf8_lossy(bytes).into_owned())
        {
            Ok(()) | Err(mpsc::error::TrySendError::Closed(_)) => bytes.len(),
            Err(mpsc::error::TrySendError::Full(_)) => 0,
        }
    }
}

/// Why a message from the page is refused (the line sent back, after `! refused: `).
pub fn check_message(m: &str) -> Result<(), String> {
    if m.len() > MSG_MAX {
        return Err(format!(
            "a message of {} bytes; at most {MSG_MAX} bytes (nothing was sent to the drive)",
            m.len()
        ));
    }
    if !m.ends_with('\n') {
        return Err(
            "a message must be whole command lines, each ending with a line end (\\n); nothing was sent to the drive"
                .into(),
        );
    }
    for (i, line) in m.split_terminator('\n').enumerate() {
        let line = line.strip_suffix('\r').unwrap_or(line);
        if line.len() > regen_fw::console::LINE_MAX {
            return Err(format!(
                "line {} of the message has {} bytes; at most {} (nothing was sent to the drive)",
                i + 1,
                line.len(),
                regen_fw::console::LINE_MAX
            ));
        }
        if let Some(c) = line.chars().find(|c| c.is_control()) {
            return Err(format!(
                "line {} of the message holds the control character U+{:04X}; a line is printable text (nothing was sent to the drive)",
                i + 1,
                c as u32
            ));
        }
    }
    Ok(())
}

/// What the server answers for: the token, the hosts a request may name, the scenario.
pub struct App {
    token: String,
    hosts: Vec<String>,
    /// Any IP literal with this port is a valid host (listening on an unspecified address).
    any_ip_port: Option<u16>,
    slot: Slot,
    harvest: Harvest,
}

/// A response with a status and one line of text.
fn refuse(code: StatusCode, why: impl Into<String>) -> Response {
    (
        code,
        [(header::CONTENT_TYPE, "text/plain; charset=utf-8")],
        why.into() + "\n",
    )
        .into_response()
}

impl App {
    pub fn new(addr: SocketAddr, token: String, slot: Slot, harvest: Harvest) -> App {
        let port = addr.port();
        let mut hosts = vec![addr.to_string()];
        if addr.ip().is_loopback() {
            hosts.push(format!("localhost:{port}"));
        }
        App {
            token,
            hosts,
            any_ip_port: addr.ip().is_unspecified().then_some(port),
            slot,
            harvest,
        }
    }

    /// The request's `Host` if this server answers for it (a DNS-rebound name does not).
    fn host<'a>(&self, h: &'a HeaderMap) -> Result<&'a str, Response> {
        let host = h
            .get(header::HOST)
            .and_then(|v| v.to_str().ok())
            .unwrap_or("");
        let ok = self.hosts.iter().any(|a| a == host)
            || self.any_ip_port.is_some_and(|p| {
                host.parse::<SocketAddr>()
                    .is_ok_and(|s| s.port() == p && !s.ip().is_unspecified())
            });
        if ok {
            Ok(host)
        } else {
            Err(refuse(
                StatusCode::MISDIRECTED_REQUEST,
                format!(
                    "Host '{host}' refused: this server answers only for {}",
                    self.hosts.join(", ")
                ),
            ))
        }
    }

    /// The per-run token, compared in constant time.
    fn token(&self, q: &HashMap<String, String>) -> Result<(), Response> {
        use subtle::ConstantTimeEq;
        let given = q.get("token").map_or("", |s| s.as_str());
        if bool::from(given.as_bytes().ct_eq(self.token.as_bytes())) {
            Ok(())
        } else {
            Err(refuse(
                StatusCode::FORBIDDEN,
                "token missing or wrong: open the URL `regen ui` printed (it holds this run's token)",
            ))
        }
    }
}

type Shared = Arc<App>;

/// The built page (`hal-sim/ui-dist/`, written by `npm run build` in `ui/`).
const ASSETS: &[(&str, &str, &[u8])] = &[
    (
        "/",
        "text/html; charset=utf-8",
        include_bytes!("../../ui-dist/index.html"),
    ),
    (
        "/assets/app.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../../ui-dist/assets/app.js"),
    ),
    (
        "/assets/plot.worker.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../../ui-dist/assets/plot.worker.js"),
    ),
    (
        "/assets/app.css",
        "text/css; charset=utf-8",
        include_bytes!("../../ui-dist/assets/app.css"),
    ),
];

async fn asset(State(app): State<Shared>, uri: axum::http::Uri, h: HeaderMap) -> Response {
    if let Err(r) = app.host(&h) {
        return r;
    }
    let Some((_, mime, body)) = ASSETS.iter().find(|(p, _, _)| *p == uri.path()) else {
        return refuse(
            StatusCode::NOT_FOUND,
            format!("{}: no such page", uri.path()),
        );
    };
    let mut r = (*body).into_response();
    let hd = r.headers_mut();
    hd.insert(header::CONTENT_TYPE, HeaderValue::from_static(mime));
    // The token travels in the URL: never in a Referer; the page in no frame; only its own
    // scripts and its own server.
    hd.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static("no-referrer"),
    );
    hd.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    hd.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(
            "default-src 'self'; connect-src 'self'; img-src 'self' data: blob:; style-src 'self' 'unsafe-inline'; frame-ancestors 'none'",
        ),
    );
    hd.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    r
}

async fn harvest(
    State(app): State<Shared>,
    h: HeaderMap,
    Query(q): Query<HashMap<String, String>>,
) -> Response {
    if let Err(r) = app.host(&h).and_then(|_| app.token(&q)) {
        return r;
    }
    let at = match q.get("r") {
        None => Vec::new(),
        Some(s) => match parse_loads(s) {
            Ok(v) => v,
            Err(e) => return refuse(StatusCode::BAD_REQUEST, e),
        },
    };
    let mut r = app.harvest.json(&at).into_response();
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/json"),
    );
    r
}

/// `r=306,100`: loads in Ω, each finite and in (0, 1e6].
fn parse_loads(s: &str) -> Result<Vec<f64>, String> {
    s.split(',')
        .map(|t| match t.trim().parse::<f64>() {
            Ok(v) if v > 0.0 && v <= 1e6 => Ok(v),
            _ => Err(format!(
                "r = {t}: each load must be a number in (0, 1e6] ohm"
            )),
        })
        .collect()
}

async fn ws(
    State(app): State<Shared>,
    h: HeaderMap,
    Query(q): Query<HashMap<String, String>>,
    up: Result<WebSocketUpgrade, WebSocketUpgradeRejection>,
) -> Response {
    let host = match app.host(&h) {
        Ok(host) => host,
        Err(r) => return r,
    };
    if let Err(r) = app.token(&q) {
        return r;
    }
    let origin = h
        .get(header::ORIGIN)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("");
    if origin != format!("http://{host}") {
        return refuse(
            StatusCode::FORBIDDEN,
            format!("Origin '{origin}' refused: only this page's own (http://{host}) may drive the drive"),
        );
    }
    let up = match up {
        Ok(u) => u,
        Err(e) => return e.into_response(),
    };
    let (to_tx, to_rx) = mpsc::unbounded_channel();
    let (from_tx, from_rx) = mpsc::channel(OUT_QUEUE);
    {
        let mut g = app.slot.live();
        if g.is_some() {
            return refuse(
                StatusCode::CONFLICT,
                "the drive is in use by another page: close it first (one page drives at a time)",
            );
        }
        *g = Some(Session {
            to_drive: to_rx,
            from_drive: from_tx,
        });
    }
    up.max_message_size(64 * 1024)
        .on_upgrade(move |s| session(s, to_tx, from_rx))
}

/// Longest a telemetry-only message is held for more to join it (a frame at 60 Hz is 16.7
/// ms): a 2 kHz stream arrives as about 125 messages a second, not one per simulation pass,
/// and the page's main thread handles that many fewer events. A message with any other line
/// (a reply, a notice) goes at once with everything held before it.
const TEL_HOLD: Duration = Duration::from_millis(8);

/// Whether every line of `text` is a telemetry sample (`T …` in machine mode).
fn telemetry_only(text: &str) -> bool {
    text.split_terminator('\n').all(|l| l.starts_with("T "))
}

/// One page: its lines to the drive (checked), the drive's lines to it (what waits sent as
/// one message; telemetry alone held up to [`TEL_HOLD`]).
async fn session(
    mut s: WebSocket,
    to: mpsc::UnboundedSender<Vec<u8>>,
    mut from: mpsc::Receiver<String>,
) {
    let mut held = String::new();
    let mut since = tokio::time::Instant::now();
    loop {
        let due = since + TEL_HOLD;
        tokio::select! {
            _ = tokio::time::sleep_until(due), if !held.is_empty() => {
                if s.send(Message::Text(std::mem::take(&mut held).into())).await.is_err() {
                    break;
                }
            }
            m = s.recv() => match m {
                Some(Ok(Message::Text(t))) => {
                    match check_message(t.as_str()) {
                        Ok(()) => {
                            if to.send(t.as_bytes().to_vec()).is_err() {
                                break;
                            }
                        }
                        Err(e) => {
                            let line = format!("! refused: {e}\r\n");
                            if s.send(Message::Text(line.into())).await.is_err() {
                                break;
                            }
                        }
                    }
                }
                Some(Ok(Message::Binary(b))) => {
                    let line = format!(
                        "! refused: a binary message of {} bytes; send command lines as text (nothing was sent to the drive)\r\n",
                        b.len()
                    );
                    if s.send(Message::Text(line.into())).await.is_err() {
                        break;
                    }
                }
                Some(Ok(Message::Close(_))) | None | Some(Err(_)) => break,
                Some(Ok(_)) => {}
            },
            o = from.recv() => {
                let Some(text) = o else { break };
                if held.is_empty() {
                    since = tokio::time::Instant::now();
                }
                let mut urgent = !telemetry_only(&text);
                held.push_str(&text);
                while held.len() < 256 * 1024 {
                    match from.try_recv() {
                        Ok(more) => {
                            urgent |= !telemetry_only(&more);
                            held.push_str(&more);
                        }
                        Err(_) => break,
                    }
                }
                let due_now = urgent || held.len() >= 256 * 1024 || since.elapsed() >= TEL_HOLD;
                if due_now && s.send(Message::Text(std::mem::take(&mut held).into())).await.is_err() {
                    break;
                }
            }
        }
    }
}

/// The harmonic balance of the scenario's TMD against the emulated load (`crate::analytic`).
pub struct Harvest {
    model: Option<(Scenario, f64, f64)>,
    name: String,
}

impl Harvest {
    pub fn new(sc: Option<&Scenario>) -> Harvest {
        let model = sc.and_then(|sc| match &sc.drive {
            Drive::Structure {
                excitation: Excitation::Sine { a0_m_s2, freq_hz },
                ..
            } => Some((sc.clone(), *a0_m_s2, *freq_hz)),
            _ => None,
        });
        Harvest {
            model,
            name: sc.map_or("(a board)".into(), |s| s.name.clone()),
        }
    }

    fn p_load(&self, r: f64) -> Option<f64> {
        let (sc, a0, f) = self.model.as_ref()?;
        let Drive::Structure { structure, .. } = &sc.drive else {
            return None;
        };
        Some(
            tmd_power(
                r,
                &sc.machine,
                &sc.screw,
                structure,
                *a0,
                *f,
                DampingFormula::PerPhasePeak,
            )
            .p_load,
        )
    }

    /// `{scenario, available, reason?, curve: [[R, P]…], optimum: {r_ohm, p_w}, at: [[R, P]…]}`.
    pub fn json(&self, at: &[f64]) -> String {
        use serde_json::json;
        if self.model.is_none() {
            return json!({
                "scenario": self.name,
                "available": false,
                "reason": "the harmonic balance needs a simulated structure under a sine excitation (--sim with a sine-excited TMD scenario)",
            })
            .to_string();
        }
        let p = |r: f64| self.p_load(r).unwrap_or(0.0);
        let curve: Vec<[f64; 2]> = logspace(1.0, 1e4, 400)
            .into_iter()
            .map(|r| [r, p(r)])
            .collect();
        let opt = optimum_load(p, 1.0, 1e4);
        let at: Vec<[f64; 2]> = at.iter().map(|&r| [r, p(r)]).collect();
        json!({
            "scenario": self.name,
            "available": true,
            "model": "harmonic balance (hal-sim/src/analytic.rs tmd_power), load power",
            "curve": curve,
            "optimum": {"r_ohm": opt, "p_w": p(opt)},
            "at": at,
        })
        .to_string()
    }
}

/// A fresh per-run token: 128 bits from the operating system, in hex.
fn new_token() -> Result<String, String> {
    let mut b = [0u8; 16];
    getrandom::fill(&mut b).map_err(|e| format!("token: no randomness from the system: {e}"))?;
    Ok(b.iter().map(|x| format!("{x:02x}")).collect())
}

/// The router: `/` and `/assets/*` (the page), `/api/harvest`, `/ws`.
pub fn router(app: App) -> Router {
    Router::new()
        .route("/ws", get(ws))
        .route("/api/harvest", get(harvest))
        .fallback(get(asset))
        .with_state(Arc::new(app))
}

/// A board's serial port bridged to the session: whole lines from the board to the page, the
/// page's lines to the board.
fn serial_bridge(path: &str, baud: u32, slot: Slot) -> Result<(), String> {
    use std::io::{Read, Write};
    let mut port = serialport::new(path, baud)
        .timeout(Duration::from_millis(2))
        .open()
        .map_err(|e| format!("--port {path}: cannot open as a serial port: {e}"))?;
    std::thread::spawn(move || {
        let mut buf = Vec::new();
        let mut chunk = [0u8; 4096];
        while !serve::STOP.load(Ordering::Relaxed) {
            match port.read(&mut chunk) {
                Ok(k) => buf.extend_from_slice(&chunk[..k]),
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                Err(e) => {
                    eprintln!("--port: {e}");
                    serve::STOP.store(true, Ordering::Relaxed);
                    return;
                }
            }
            let mut g = slot.live();
            let Some(s) = g.as_mut() else {
                buf.clear();
                continue;
            };
            if let Some(i) = buf.iter().rposition(|&b| b == b'\n') {
                let lines: Vec<u8> = buf.drain(..=i).collect();
                let _ = s
                    .from_drive
                    .try_send(String::from_utf8_lossy(&lines).into_owned());
            }
            while let Ok(m) = s.to_drive.try_recv() {
                if let Err(e) = port.write_all(&m) {
                    eprintln!("--port: {e}");
                }
            }
        }
    });
    Ok(())
}

pub fn run(a: &UiArgs) -> Result<(), String> {
    let addr: SocketAddr = a.listen.parse().map_err(|_| {
        format!(
            "--listen = {}: must be ADDR:PORT (127.0.0.1:8733)",
            a.listen
        )
    })?;
    let speed = serve::parse_speed(&a.speed)?;
    if !(50..=4_000_000).contains(&a.baud) {
        return Err(format!("--baud = {}: must be in [50, 4000000] Bd", a.baud));
    }
    let slot = Slot::default();
    let (sc, drive) = match &a.port {
        Some(p) => {
            serial_bridge(p, a.baud, slot.clone())?;
            (None, format!("the board on {p}"))
        }
        None => {
            let sc = serve::scenario(a.sim.as_deref())?;
            let d = format!("the simulated drive, scenario {}", sc.name);
            let mut srv = Server::new(
                SimDrive::from_scenario(&sc)?,
                WsLink::new(slot.clone()),
                speed,
            )?;
            std::thread::spawn(move || srv.run(&serve::STOP, None));
            (Some(sc), d)
        }
    };
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| format!("runtime: {e}"))?;
    rt.block_on(async move {
        let l = tokio::net::TcpListener::bind(addr)
            .await
            .map_err(|e| format!("--listen {addr}: {e}"))?;
        let bound = l.local_addr().map_err(|e| e.to_string())?;
        let token = new_token()?;
        let app = App::new(bound, token.clone(), slot, Harvest::new(sc.as_ref()));
        serve::catch_signals()?;
        println!("regen ui: {drive}");
        println!("open http://{bound}/?token={token}");
        if !bound.ip().is_loopback() {
            println!(
                "warning: listening on {bound}, not loopback: anyone who can reach it and has the URL can drive the drive"
            );
        }
        use std::io::Write;
        let _ = std::io::stdout().flush();
        axum::serve(l, router(app))
            .with_graceful_shutdown(async {
                while !serve::STOP.load(Ordering::Relaxed) {
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
            })
            .await
            .map_err(|e| format!("server: {e}"))
    })?;
    // The reader of stdout may be gone by now (a test that started us): not an error.
    use std::io::Write;
    let _ = writeln!(std::io::stdout(), "regen ui: stopped");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_are_whole_printable_lines() {
        assert!(check_message("status\n").is_ok());
        assert!(check_message("#1 status\r\n#2 list\n").is_ok());
        let e = check_message("status").unwrap_err();
        assert!(e.contains("line end"), "{e}");
        let e = check_message("set a\u{7}b 1\n").unwrap_err();
        assert!(e.contains("U+0007") && e.contains("line 1"), "{e}");
        let long = format!("ok\n{}\n", "x".repeat(129));
        let e = check_message(&long).unwrap_err();
        assert!(e.contains("line 2") && e.contains("129 bytes"), "{e}");
        let e = check_message(&"status\n".repeat(600)).unwrap_err();
        assert!(e.contains("4200 bytes"), "{e}");
    }

    #[test]
    fn only_telemetry_is_held() {
        assert!(telemetry_only("T 0.1,2\r\nT 0.2,3\r\n"));
        assert!(!telemetry_only("T 0.1,2\r\nR 4 ok\r\n"));
        assert!(!telemetry_only("N cap ready\r\n"));
        assert!(
            !telemetry_only("0.1,2\r\n"),
            "the human console's telemetry goes at once"
        );
    }

    #[test]
    fn tokens_are_fresh_and_long() {
        let (a, b) = (new_token().unwrap(), new_token().unwrap());
        assert_eq!(a.len(), 32);
        assert_ne!(a, b);
    }
}
