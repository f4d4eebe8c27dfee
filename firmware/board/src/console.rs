//! The serial console task: `regen_fw::console` over USART2 (ST-LINK virtual COM port).
//!
//! Lines in → `Console::execute` on a *copy* of the controller → reply out; what the command
//! changed is applied to the current loop between two periods (`drive::apply`) before the
//! next line is read. The reply says what the copy accepted; a mode change can still be
//! refused by the loop if a fault latched in the meantime (counted, logged by supervision,
//! visible in `status`).
//!
//! Telemetry. `Console::tick` must see the controller once per period; the task instead wakes
//! every 0.5 ms (the fastest `tel` rate is 2 kHz), copies the controller, and calls `tick` once
//! per period elapsed since the last wake, all against that copy. A telemetry line therefore
//! carries its exact period timestamp but values from the end of the batch (≤ 0.5 ms, i.e.
//! ≤ 10 periods, later). Only the last line of a batch is kept, and a line is dropped (and
//! counted) when the UART is still busy with the previous one, so a stream faster than
//! 115,200 baud thins out instead of backing up. The console's energy counter is overwritten
//! after each batch with the loop's exact per-period integral (`Period::energy_j`).

use core::fmt::Write as _;
use core::sync::atomic::{AtomicU32, Ordering};

use embassy_futures::select::{select, Either};
use embassy_stm32::usart::{BufferedUartRx, BufferedUartTx};
use embassy_time::{Duration, Ticker};
use embedded_io_async::{Read, Write};
use regen_fw::console::{Console, LineEditor};

use crate::drive;
use crate::store::BoardStore;
use regen_fw::period::{Pending, Slot};

/// Telemetry lines dropped because the UART was busy.
pub static TEL_DROPPED: AtomicU32 = AtomicU32::new(0);

/// The longest reply is `list`'s: in machine mode ≈ 5.2 KB (one `key=value` line of ≈ 95
/// bytes per parameter, with an 8-character id: `regen_fw::console` test
/// `machine_mode_lines_parse_and_carry_ids` prints it), ≈ 3.6 KB in the human console (the
/// board's image carries no descriptions); room for about ten more parameters.
/// A longer reply (`cap dump`, ≈ 40 KB) goes out in pieces of this size
/// (`Console::dump_more`).
const REPLY_MAX: usize = regen_fw::console::REPLY_MAX;

/// A `fmt::Write` sink into a fixed buffer that records overflow instead of truncating
/// silently.
struct Buf<const N: usize> {
    b: heapless::Vec<u8, N>,
    overflow: bool,
}

impl<const N: usize> Buf<N> {
    const fn new() -> Self {
        Buf {
            b: heapless::Vec::new(),
            overflow: false,
        }
    }
    fn clear(&mut self) {
        self.b.clear();
        self.overflow = false;
    }
}

impl<const N: usize> core::fmt::Write for Buf<N> {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        if self.b.extend_from_slice(s.as_bytes()).is_err() {
            self.overflow = true;
            return Err(core::fmt::Error);
        }
        Ok(())
    }
}

/// Keeps only the last complete telemetry line written to it.
struct LastLine {
    cur: Buf<160>,
    last: Buf<160>,
    lines: u32,
}

impl core::fmt::Write for LastLine {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        let r = self.cur.write_str(s);
        if s.ends_with('\n') {
            if !self.cur.overflow {
                core::mem::swap(&mut self.cur, &mut self.last);
                self.lines += 1;
            }
            self.cur.clear();
        }
        r
    }
}

/// What `post` needs of the controller before a command: its configuration (all that
/// compiling a change reads), fault and mode. Kept instead of a second whole controller.
struct Before {
    cfg: regen_fw::Config,
    fault: Option<regen_fw::control::Fault>,
    mode: regen_fw::control::Mode,
}

/// Apply the differences between the copy before and after a command to the loop, at once
/// (`drive::apply`), so that the next command's copy includes them (two `set` lines arriving
/// together must not undo each other, and `save` must store what was set before it).
fn post(before: &Before, after: &regen_fw::Controller) {
    let mut p = Pending::default();
    if before.fault.is_some() && after.fault().is_none() {
        p.clear = before.fault.into();
    }
    if after.config().differs(&before.cfg) {
        // Validated and compiled here, in the task (≈ 11,500 instructions: more than a
        // period); `drive::apply` only installs it. `execute` accepted it on the copy, so
        // this cannot fail; if it did, nothing would be applied.
        match regen_fw::Compiled::new(&before.cfg, after.config()) {
            Ok(c) => p.cfg = Slot::Full(c),
            Err(_) => return,
        }
    }
    if after.mode() != before.mode {
        p.mode = Slot::Full(after.mode());
    }
    if !p.is_empty() {
        drive::apply(&mut p);
    }
}

#[embassy_executor::task]
pub async fn console_task(
    mut tx: BufferedUartTx<'static>,
    mut rx: BufferedUartRx<'static>,
    mut store: BoardStore,
    boot_msg: &'static str,
) {
    // Lives in the task's static storage (embassy allocates task futures statically).
    let mut reply_buf: Buf<REPLY_MAX> = Buf::new();
    let reply = &mut reply_buf;
    let mut con = Console::new();
    let mut ed = LineEditor::new();
    let mut tel = LastLine {
        cur: Buf::new(),
        last: Buf::new(),
        lines: 0,
    };
    // From boot: the first batch covers the periods run before this task started (at most
    // one second of them, as after any stall).
    let mut last_period = 0;
    let mut ticker = Ticker::every(Duration::from_micros(500));
    let mut inbuf = [0u8; 32];

    // The boot line, through the reply buffer: one write (one await point less in this
    // task's state machine: flash).
    let _ = reply.write_str("\r\n# regen-board ");
    let _ = reply.write_str(boot_msg);
    let (mode, fault) = drive::snapshot()
        .map_or((regen_fw::control::Mode::Idle, None), |(c, _)| {
            (c.mode(), c.fault())
        });
    Console::banner(mode, fault, reply);
    let _ = tx.write_all(&reply.b).await;

    loop {
        // A `cap dump` under way: its next piece per pass, unless a byte came in, which is
        // read as any other (a person's ends the dump first: `Console::dump_byte`), so a
        // command sent meanwhile (`mode idle`) waits for one piece at most.
        let event = if con.dumping() {
            match embassy_futures::poll_once(rx.read(&mut inbuf)) {
                core::task::Poll::Ready(r) => Either::First(r),
                core::task::Poll::Pending => {
                    reply.clear();
                    if !con.dump_more(&drive::BoardCap, REPLY_MAX, reply) {
                        let _ = reply.write_str(con.prompt());
                    }
                    let _ = tx.write_all(&reply.b).await;
                    continue;
                }
            }
        } else {
            select(rx.read(&mut inbuf), ticker.next()).await
        };
        match event {
            Either::First(Ok(n)) => {
                // The console's line editor echoes and edits; a whole line is executed and
                // its reply, then the prompt, sent before the next line is read.
                reply.clear();
                for &c in &inbuf[..n] {
                    con.dump_byte(reply);
                    ed.set_machine(con.machine());
                    let Some(text) = ed.feed(c, reply) else {
                        continue;
                    };
                    if !text.is_empty() {
                        // One copy of the controller, in a block that ends before the
                        // wait (the task's state keeps no controller across it).
                        match drive::snapshot() {
                            Some((mut ctl, _)) => {
                                let before = Before {
                                    cfg: *ctl.config(),
                                    fault: ctl.fault(),
                                    mode: ctl.mode(),
                                };
                                let _ = con.execute_cap(
                                    text,
                                    &mut ctl,
                                    &mut store,
                                    Some(&mut drive::BoardCap),
                                    reply,
                                );
                                post(&before, &ctl);
                            }
                            None => {
                                let _ = reply.write_str("error: current loop not started\r\n");
                            }
                        }
                    }
                    // A `save`: written here, awaited (the executor runs on), with no copy of
                    // the controller alive across the wait (the task's state stays small).
                    if let Some(r) = store.finish().await {
                        let _ = con.save_done(r, reply);
                    }
                    // A `cap dump`: its header is in the reply; the samples and the final
                    // line follow piece by piece at the top of the loop, then the prompt.
                    if !con.dumping() {
                        let _ = reply.write_str(con.prompt());
                    }
                    if reply.overflow {
                        reply.b.truncate(REPLY_MAX - 40);
                        let _ = reply.write_str("\r\n");
                        con.final_line(false, "reply truncated", reply);
                        let _ = reply.write_str(con.prompt());
                    }
                    let _ = tx.write_all(&reply.b).await;
                    reply.clear();
                }
                let _ = tx.write_all(&reply.b).await; // the echo of a partial line
            }
            Either::First(Err(_)) => {
                // Framing/noise/overrun on the line: what was typed stays in the editor.
            }
            Either::Second(()) => {
                let Some((ctl, c)) = drive::snapshot() else {
                    continue;
                };
                let now = c.periods;
                let n = now.wrapping_sub(last_period);
                last_period = now;
                if n == 0 {
                    continue;
                }
                tel.lines = 0;
                // At most one second of periods per batch (after a long stall the rest is
                // skipped: no line could be sent in time anyway).
                let batch = n.min(ctl.config().pwm_hz as u32);
                for _ in 0..batch {
                    con.tick(&ctl, &mut tel);
                }
                con.energy_j = c.energy_j(&ctl, ctl.config().ts());
                // A fault latched since the last batch: announced at once, never dropped.
                reply.clear();
                let cap = critical_section::with(|cs| drive::CAP.borrow_ref(cs).state());
                if con.notice(&ctl, reply) | con.notice_cap(cap, reply) {
                    let _ = tx.write_all(&reply.b).await;
                }
                if tel.lines > 0 {
                    TEL_DROPPED.fetch_add(tel.lines - 1, Ordering::Relaxed);
                    // Send only if the UART has drained the previous line; else drop it.
                    match embassy_futures::poll_once(tx.flush()) {
                        core::task::Poll::Ready(_) => {
                            let _ = tx.write_all(&tel.last.b).await;
                        }
                        core::task::Poll::Pending => {
                            TEL_DROPPED.fetch_add(1, Ordering::Relaxed);
                        }
                    }
                }
            }
        }
    }
}
