//! `regen ui` end to end at the HTTP and WebSocket level (the browser suite in `ui/tests/`
//! drives the page itself): the per-run token, the Origin and Host checks, one page at a time,
//! bad messages refused with one line and nothing changed, the console's replies over the
//! bridge and their round trip, the harmonic balance served as JSON.

#![cfg(unix)]

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};
use tungstenite::client::IntoClientRequest;
use tungstenite::{Message, WebSocket};

/// A running `regen ui --sim` child, killed on drop.
struct Ui {
    child: Child,
    addr: String,
    token: String,
}

impl Ui {
    fn start() -> Ui {
        let mut child = Command::new(env!("CARGO_BIN_EXE_regen"))
            .args(["ui", "--listen", "127.0.0.1:0", "--speed", "10"])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("spawn regen ui");
        let mut out = BufReader::new(child.stdout.take().unwrap());
        let mut url = String::new();
        while !url.starts_with("open ") {
            url.clear();
            assert!(
                out.read_line(&mut url).unwrap() > 0,
                "regen ui printed no URL"
            );
        }
        // open http://127.0.0.1:PORT/?token=HEX
        let rest = url.trim().strip_prefix("open http://").unwrap();
        let (addr, token) = rest.split_once("/?token=").unwrap();
        Ui {
            child,
            addr: addr.to_string(),
            token: token.to_string(),
        }
    }

    /// A raw HTTP/1.1 GET; the status code and the body's first line.
    fn get(&self, path: &str, extra: &[(&str, &str)]) -> (u16, String) {
        let mut s = TcpStream::connect(&self.addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        let mut req = format!("GET {path} HTTP/1.1\r\n");
        if !extra.iter().any(|(k, _)| *k == "Connection") {
            req += "Connection: close\r\n";
        }
        if !extra.iter().any(|(k, _)| *k == "Host") {
            req += &format!("Host: {}\r\n", self.addr);
        }
        for (k, v) in extra {
            req += &format!("{k}: {v}\r\n");
        }
        req += "\r\n";
        s.write_all(req.as_bytes()).unwrap();
        // Up to the end of the body, or of the head of a 101 (the connection stays open).
        let mut raw = Vec::new();
        let mut b = [0u8; 4096];
        loop {
            let k = s.read(&mut b).unwrap_or(0);
            raw.extend_from_slice(&b[..k]);
            if k == 0 {
                break;
            }
            let Some(h) = raw.windows(4).position(|w| w == b"\r\n\r\n") else {
                continue;
            };
            let head = String::from_utf8_lossy(&raw[..h]).to_ascii_lowercase();
            let len = head
                .lines()
                .find_map(|l| l.strip_prefix("content-length:"))
                .map_or(0, |v| v.trim().parse::<usize>().unwrap());
            if raw.len() >= h + 4 + len {
                break;
            }
        }
        let text = String::from_utf8_lossy(&raw).into_owned();
        let code = text[9..12].parse().unwrap();
        let body = text.split("\r\n\r\n").nth(1).unwrap_or("");
        (code, body.lines().next().unwrap_or("").to_string())
    }

    fn ws_upgrade(&self, token: &str, origin: &str) -> (u16, String) {
        self.get(
            &format!("/ws?token={token}"),
            &[
                ("Origin", origin),
                ("Upgrade", "websocket"),
                ("Connection", "Upgrade"),
                ("Sec-WebSocket-Version", "13"),
                ("Sec-WebSocket-Key", "dGhlIHNhbXBsZSBub25jZQ=="),
            ],
        )
    }

    fn ws(&self) -> Result<WebSocket<TcpStream>, tungstenite::Error> {
        let mut req = format!("ws://{}/ws?token={}", self.addr, self.token)
            .into_client_request()
            .unwrap();
        req.headers_mut()
            .insert("Origin", format!("http://{}", self.addr).parse().unwrap());
        let s = TcpStream::connect(&self.addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        tungstenite::client(req, s)
            .map(|(ws, _)| ws)
            .map_err(|e| match e {
                tungstenite::HandshakeError::Failure(e) => e,
                tungstenite::HandshakeError::Interrupted(_) => panic!("handshake interrupted"),
            })
    }
}

impl Drop for Ui {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Lines from the drive until one satisfies `end` (telemetry and banner lines included).
fn until(ws: &mut WebSocket<TcpStream>, end: impl Fn(&str) -> bool) -> Vec<String> {
    let mut lines = Vec::new();
    let t_end = Instant::now() + Duration::from_secs(10);
    while Instant::now() < t_end {
        if let Message::Text(t) = ws.read().unwrap() {
            for l in t.as_str().split("\r\n").filter(|l| !l.is_empty()) {
                let l = l.trim_start_matches("> ").to_string();
                let done = end(&l);
                lines.push(l);
                if done {
                    return lines;
                }
            }
        }
    }
    panic!("no line ending the reply in 10 s; got {lines:?}")
}

/// The final line of the reply to `cmd` (human `ok …`/`error: …` or machine `R <id> …`).
fn command(ws: &mut WebSocket<TcpStream>, cmd: &str) -> String {
    ws.send(Message::text(format!("{cmd}\n"))).unwrap();
    let is_end = |l: &str| l.starts_with("ok") || l.starts_with("error:") || l.starts_with("R ");
    until(ws, is_end).pop().unwrap()
}

#[test]
fn token_origin_and_host_are_required() {
    let ui = Ui::start();
    let own = format!("http://{}", ui.addr);
    // The page itself is public (no secret in it); the API and the bridge are not.
    assert_eq!(ui.get("/", &[]).0, 200);
    let (c, why) = ui.get("/api/harvest", &[]);
    assert_eq!(c, 403, "{why}");
    assert!(why.contains("token missing or wrong"), "{why}");
    assert_eq!(
        ui.get(&format!("/api/harvest?token={}", ui.token), &[]).0,
        200
    );
    // No token, a wrong one, one a character short: refused before any upgrade.
    for t in ["", "0123", &ui.token[..31], &"0".repeat(32)] {
        let (c, why) = ui.ws_upgrade(t, &own);
        assert_eq!(c, 403, "token {t:?}: {why}");
        assert!(why.contains("token"), "{why}");
    }
    // A foreign page, a look-alike, none.
    for o in [
        "http://evil.example",
        &format!("http://{}.evil.example", ui.addr),
        "null",
        "",
    ] {
        let (c, why) = ui.ws_upgrade(&ui.token, o);
        assert_eq!(c, 403, "origin {o:?}: {why}");
        assert!(why.contains("Origin"), "{why}");
    }
    // A DNS-rebound name (its own Origin matching) is refused by its Host.
    let port = ui.addr.rsplit(':').next().unwrap();
    let evil = format!("evil.example:{port}");
    let (c, why) = ui.get(
        &format!("/ws?token={}", ui.token),
        &[("Host", &evil), ("Origin", &format!("http://{evil}"))],
    );
    assert_eq!(c, 421, "{why}");
    assert!(why.contains("Host"), "{why}");
    assert_eq!(ui.get("/", &[("Host", &evil)]).0, 421);
    // The page's own origin with the token: upgraded.
    assert_eq!(ui.ws_upgrade(&ui.token, &own).0, 101);
}

#[test]
fn one_page_at_a_time_and_bad_messages_change_nothing() {
    let ui = Ui::start();
    let mut ws = ui.ws().unwrap();
    // A second page is refused while the first is open, and admitted once it has closed.
    match ui.ws() {
        Err(tungstenite::Error::Http(r)) => assert_eq!(r.status().as_u16(), 409),
        other => panic!("second page not refused: {:?}", other.map(|_| ())),
    }
    assert!(command(&mut ws, "get r_load_ohm").contains("306"));
    let bad: [Message; 5] = [
        Message::binary(b"set r_load_ohm 100\n".to_vec()),
        Message::text("set r_load_ohm 100"),
        Message::text("set r_load_ohm 100\u{1b}\n"),
        Message::text(format!("set r_load_ohm 100\n{}\n", "1".repeat(200))),
        Message::text("set r_load_ohm 100\n".repeat(300)),
    ];
    for m in bad {
        ws.send(m).unwrap();
        let lines = until(&mut ws, |l| l.starts_with('!'));
        let l = lines.last().unwrap();
        assert!(
            l.starts_with("! refused: ") && l.contains("nothing was sent to the drive"),
            "{l}"
        );
    }
    assert!(command(&mut ws, "get r_load_ohm").contains("306"));
    ws.close(None).unwrap();
    while ws.read().is_ok() {}
    let t0 = Instant::now();
    let mut ws2 = loop {
        match ui.ws() {
            Ok(w) => break w,
            Err(_) if t0.elapsed() < Duration::from_secs(5) => {
                std::thread::sleep(Duration::from_millis(20))
            }
            Err(e) => panic!("the next page is refused after the first closed: {e}"),
        }
    };
    assert!(command(&mut ws2, "get r_load_ohm").contains("306"));
}

#[test]
fn round_trip_over_the_bridge() {
    let ui = Ui::start();
    let mut ws = ui.ws().unwrap();
    let _ = command(&mut ws, "get r_load_ohm");
    let mut ms: Vec<f64> = (0..200)
        .map(|_| {
            let t = Instant::now();
            let r = command(&mut ws, "get r_load_ohm");
            assert!(r.contains("r_load_ohm"), "{r}");
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    ms.sort_by(f64::total_cmp);
    let q = |p: f64| ms[((ms.len() - 1) as f64 * p) as usize];
    println!(
        "round trip over the bridge, 200 commands: min {:.2} ms, median {:.2}, p90 {:.2}, p99 {:.2}, max {:.2}",
        ms[0],
        q(0.5),
        q(0.9),
        q(0.99),
        ms[ms.len() - 1]
    );
    // The server's loop looks at the link every 0.5 ms of wall time: a median of a few ms
    // leaves room for the shared machine; 10 ms is the bound.
    assert!(q(0.5) < 10.0, "median round trip {:.2} ms", q(0.5));
}

#[test]
fn the_harmonic_balance_is_served() {
    let ui = Ui::start();
    let (c, body) = ui.get(&format!("/api/harvest?token={}&r=306,100", ui.token), &[]);
    assert_eq!(c, 200, "{body}");
    let j: serde_json::Value = serde_json::from_str(&body).unwrap();
    assert_eq!(j["available"], true);
    // The reference device's optimum is near 306 Ω (the paper measured 300 Ω; README), its
    // power 23.0 W there (docs/console.md: the closed loop read 23.033 W at 306 Ω).
    let r_opt = j["optimum"]["r_ohm"].as_f64().unwrap();
    assert!((r_opt - 306.0).abs() < 10.0, "optimum {r_opt} Ω");
    let p306 = j["at"][0][1].as_f64().unwrap();
    assert!((p306 - 23.0).abs() < 0.3, "P(306 Ω) = {p306} W");
    assert_eq!(j["curve"].as_array().unwrap().len(), 400);
    let (c, why) = ui.get(&format!("/api/harvest?token={}&r=nan", ui.token), &[]);
    assert_eq!(c, 400);
    assert!(why.contains("r = nan") && why.contains("(0, 1e6]"), "{why}");
}
