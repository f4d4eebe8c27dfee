//! A simulated drive as its serial console sees it: the closed-loop [`Sim`] (the firmware's
//! `Controller` against the plant), the firmware's console executor
//! ([`regen_fw::console::Console`], unchanged) and a simulated two-page NOR flash behind the
//! firmware's parameter store ([`regen_fw::store`]).
//!
//! As on the board, a console line is executed *between* two control periods (the board runs
//! the console outside the current-loop interrupt), and [`Console::tick`] runs after every
//! [`Sim::step`] (energy integration, telemetry decimation).
//!
//! Two things differ from the board, both because the simulated hardware is fixed when the
//! simulation is built:
//! * `pwm_hz` is the plant's period too. A command that would change it (`set pwm_hz`,
//!   `load`/`defaults` of a different rate) is refused with one `error:` line and changes
//!   nothing: it is executed on a copy of the controller and console first, and committed only
//!   if the rate is unchanged.
//! * The sensor scalings the plant uses (`amps_per_count`, `volts_per_count`, `adc_zero_code`,
//!   `encoder_cpr`) are the scenario's hardware: changing them on the console changes the
//!   firmware's *belief*, as it would on a board, not the simulated sensors.
//!
//! One host-only command is added in front of the console: `sim` (simulated time, the plant's
//! own ledger of harvested energy and the energy balance residual), answered with `ok …`.

use crate::sim::Sim;
use crate::Scenario;
use regen_fw::config::Config;
use regen_fw::console::{CmdResult, Console, ParamStore, Refused, Saved};
use regen_fw::store::{MemFlash, Store};

/// The simulated drive's store: the firmware's store (`regen_fw::store`) on a simulated flash
/// of two 2 KiB pages, as the board's, run to completion (the host's flash takes no time); its
/// factory configuration (`defaults`) is the scenario's, i.e. this simulated hardware's.
struct SimStore {
    store: Store<MemFlash<2>>,
    factory: Config,
}

impl ParamStore for SimStore {
    fn save(&mut self, cfg: &Config) -> Result<Saved, &'static str> {
        embassy_futures::block_on(self.store.save(cfg)).map(|()| Saved::Done)
    }
    fn load(&mut self) -> Result<Config, &'static str> {
        match self.store.load() {
            (c, None) => Ok(c),
            (_, Some(f)) => Err(f.message()),
        }
    }
    fn factory(&self) -> Config {
        self.factory
    }
    fn held(&self) -> Option<Config> {
        match self.store.load() {
            (c, None) => Some(c),
            _ => None,
        }
    }
}

/// The simulated drive.
pub struct SimDrive {
    sim: Sim,
    console: Console,
    store: SimStore,
    /// Plant energy into the inverter at the last `sim` command (for its interval average).
    mark: (f64, f64),
    /// The alignment's retry, as the board's supervision task runs it (`regen_fw::align`).
    retry: regen_fw::align::AlignRetry,
}

impl SimDrive {
    /// Wrap a built simulation (its controller keeps its mode: `Sim::new` starts in `run`).
    pub fn new(sim: Sim) -> SimDrive {
        let factory = *sim.controller().config();
        SimDrive {
            sim,
            console: Console::new(),
            store: SimStore {
                store: Store {
                    flash: MemFlash::default(),
                    base: 0,
                },
                factory,
            },
            mark: (0.0, 0.0),
            retry: regen_fw::align::AlignRetry::NEW,
        }
    }

    /// Build a scenario's simulation (without its recorder: a served drive runs for ever).
    pub fn from_scenario(sc: &Scenario) -> Result<SimDrive, String> {
        let mut sc = sc.clone();
        sc.record.channels.clear();
        Ok(SimDrive::new(sc.build()?))
    }

    pub fn sim(&self) -> &Sim {
        &self.sim
    }

    pub fn console(&self) -> &Console {
        &self.console
    }

    /// Switch the console's machine mode (a new reader starts in the human console).
    pub fn set_machine(&mut self, on: bool) {
        self.console.set_machine(on);
    }

    /// One control period; telemetry lines due are appended to `out`.
    pub fn step<W: std::fmt::Write>(&mut self, out: &mut W) {
        let n = self.sim.loop_period().periods;
        if self.retry.poll(self.sim.controller(), n) == regen_fw::align::Retry::Post {
            regen_fw::align::post(self.sim.mailbox());
        }
        self.sim.step();
        self.console.tick(self.sim.controller(), out);
    }

    /// Announce a fault latched since the last call ([`Console::notice`]); `true` when
    /// something was written.
    pub fn notice(&mut self, out: &mut String) -> bool {
        let f = self.console.notice(self.sim.controller(), out);
        self.console.notice_cap(self.sim.capture().state(), out) | f
    }

    /// Execute one console line (between two periods). Writes the reply, whose last line is
    /// `ok …` or `error: …`, to `out`; a `cap dump` writes its header only, its samples and
    /// final line follow in pieces ([`SimDrive::dump_more`]). A line while a dump is under
    /// way ends that dump first unless the console keeps it going (machine mode:
    /// [`regen_fw::console::Console::dump_interrupt`]).
    pub fn execute(&mut self, line: &str, out: &mut String) -> CmdResult {
        self.console.dump_interrupt(line, out);
        // In machine mode a line may carry a command id (`#ID sim`); a malformed one is the
        // console's to refuse.
        let (id, cmd) = self.console.split_id(line).unwrap_or(("-", ""));
        let mut words = cmd.split_ascii_whitespace();
        if words.next() == Some("sim") {
            if words.next().is_some() {
                self.console
                    .host_reply(id, false, "wrong arguments for 'sim' (no arguments)", out);
                return Err(Refused);
            }
            let text = self.sim_status();
            self.console.host_reply(id, true, &text, out);
            return Ok(());
        }
        let pwm = self.sim.controller().config().pwm_hz;
        // Transaction: run the command on copies; commit unless it changed the PWM rate.
        let mut ctl = self.sim.controller().clone();
        let mut con = self.console.clone();
        let mut reply = String::new();
        let r = con.execute_cap(
            line,
            &mut ctl,
            &mut self.store,
            Some(self.sim.capture_mut()),
            &mut reply,
        );
        if ctl.config().pwm_hz != pwm {
            let text = format!(
                "pwm_hz is the simulated hardware's period, fixed at {pwm} Hz by the scenario"
            );
            self.console.host_reply(id, false, &text, out);
            return Err(Refused);
        }
        *self.sim.controller_mut() = ctl;
        self.console = con;
        out.push_str(&reply);
        r
    }

    /// Whether a `cap dump` is under way ([`SimDrive::dump_more`] has more to write).
    pub fn dumping(&self) -> bool {
        self.console.dumping()
    }

    /// The next piece of a `cap dump` under way, as the board's console task writes it (at
    /// most the board's reply buffer, [`regen_fw::console::REPLY_MAX`], of whole lines; the
    /// last piece ends with the final line); `true` while more is to come.
    pub fn dump_more(&mut self, out: &mut String) -> bool {
        self.console
            .dump_more(self.sim.capture(), regen_fw::console::REPLY_MAX, out)
    }

    /// A byte received while a `cap dump` is under way: a person's ends it, with an `error:`
    /// line saying how many samples were written ([`Console::dump_byte`]); `true` if it did.
    pub fn dump_byte(&mut self, out: &mut String) -> bool {
        self.console.dump_byte(out)
    }

    /// `sim`: simulated time, the plant's harvested energy (into the inverter, the emulated
    /// load's energy) since start and its average since the previous `sim`, and the relative
    /// energy-balance residual.
    fn sim_status(&mut self) -> String {
        let e = self.sim.energy();
        let t = self.sim.time();
        let (t0, e0) = self.mark;
        let p = if t > t0 {
            (e.to_inverter - e0) / (t - t0)
        } else {
            0.0
        };
        self.mark = (t, e.to_inverter);
        format!(
            " t={t:.6}s e_load={:.6}J p_load_avg={p:.6}W since t={t0:.6}s residual={:.3e}",
            e.to_inverter,
            e.relative_residual()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `defaults` restores the scenario's configuration (this hardware's scalings), not the
    /// board's `Config::default()`: with the board's bus scaling on the scenario's bus the
    /// loop would misread the bus voltage and motor the machine.
    #[test]
    fn defaults_restore_the_scenarios_hardware() {
        let sc = Scenario::tmd(306.0);
        let mut d = SimDrive::from_scenario(&sc).unwrap();
        let factory = *d.sim().controller().config();
        assert_ne!(
            factory.volts_per_count,
            Config::default().volts_per_count,
            "the test needs a scenario whose bus scaling differs from the board's"
        );
        let mut out = String::new();
        for line in ["mode idle", "set r_load_ohm 100", "defaults"] {
            out.clear();
            d.execute(line, &mut out)
                .unwrap_or_else(|_| panic!("{line}: {out}"));
        }
        assert_eq!(*d.sim().controller().config(), factory);
    }
}
