//! The phase currents as the board's converters take them: each channel at its own instant
//! of the ADC sequence, through a low-side shunt that carries the phase current only while
//! that phase's low side conducts, and an amplifier that settles after the shunt's window
//! opens.
//!
//! **Instants.** The timer's update event (the sample instant `t_k` of [`crate::sim`], the
//! centre of the interval where all three low sides are on) triggers ADC1 [I_a, I_c] and
//! ADC2 [I_b, V_bus] (`firmware/board/src/board.rs`). A channel is held at the end of its
//! sampling time: I_a and I_b at `s/f` after the trigger, I_c at `(2s + c)/f` (`s` sampling
//! clocks, `c` conversion clocks, `f` the ADC clock): 0.29 µs and 0.88 µs with the board's
//! 12.5 + 12.5 clocks at 42.5 MHz. The trigger's latency (a few ADC clocks) is neglected, and
//! the bus voltage is read as at `t_k` (its capacitor moves by parts per million in 2 µs).
//!
//! **Current at the instant.** Between `t_k` and its channel's instant the phase's current
//! follows its switching, not the period's average: each phase stays at the negative rail
//! until its high side takes over at `h_x = (1 − d_x)·T/2` after `t_k`, plus the dead time
//! when its current flows out of the leg (`i_x > 0`: the low-side diode keeps it at the rail;
//! with `i_x < 0` the high-side diode lifts it at once). So, with the star point at the mean
//! of the three terminals, `i_x(δ) = i_x + (V_bus·(a_x − mean a) − δ·(e_x + R·i_x))/L` with
//! `a_x = max(0, δ − h_x)`: the first-order solution (δ ≤ 1 µs against L/R of milliseconds:
//! relative error below 1e-6). `i_x` is the plant's current at `t_k`, which the averaged
//! inverter and the switched one agree on at the centre of the zero vector, and `e` its
//! emf at the middle of the period just ended.
//!
//! **Shunt window.** The shunt of phase x conducts from the low side's turn-on (the dead
//! time after the high side's turn-off, `−(1 − d_x⁻)·T/2 + dead`, with the duty `d⁻` of the
//! period before `t_k`; at `−(1 − d_x⁻)·T/2` when `i_x > 0`, through the low-side diode) to
//! `h_x` (with the duty `d` in force after `t_k`). Outside that window no current flows
//! through it. The amplifier is first order with time constant `settle_s`, starting from
//! zero when the window opens (it has decayed while the high side conducted; pessimistic
//! for very low duties, whose window covers nearly the whole period anyway) and decaying
//! towards zero after the window closes: a channel taken at `δ` reads
//! * `i_x(δ)·(1 − e^(−(δ − t_open)/τ))` inside the window,
//! * `i_x(h_x)·(1 − e^(−(h_x − t_open)/τ))·e^(−(δ − h_x)/τ)` after it.
//!
//! With the gates off the phases are not switched and the currents are read as at `t_k`
//! (not modelled: the diodes' conduction through the shunts).

use crate::plant::Inverter;
use regen_fw::fx::Duty;
use regen_fw::io::Actuation;
use serde::{Deserialize, Serialize};

/// `[sensors.shunt]`: current sensing as the board does it (off: every phase current read
/// ideally, at `t_k`).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ShuntSampling {
    /// Sample each channel at its instant of the ADC sequence through its low-side shunt
    /// window (the model above).
    pub enabled: bool,
    /// The shunt amplifier's time constant, s (the IHM08M1's op-amp stage with its output
    /// filter: ≈ 0.2 µs).
    pub settle_s: f64,
    /// ADC kernel clock, Hz (170 MHz / 4).
    pub adc_clock_hz: f64,
    /// Sampling time of a current channel, ADC clocks (`board::CURRENT_SAMPLE`).
    pub sample_clocks: f64,
    /// Conversion time, ADC clocks (12.5 for 12 bits).
    pub conversion_clocks: f64,
}

impl Default for ShuntSampling {
    fn default() -> Self {
        ShuntSampling {
            enabled: false,
            settle_s: 0.2e-6,
            adc_clock_hz: 42.5e6,
            sample_clocks: 12.5,
            conversion_clocks: 12.5,
        }
    }
}

/// The model's constants for a run.
#[derive(Clone, Debug, Default)]
pub(crate) struct ShuntPre {
    pub on: bool,
    /// Instants of I_a/I_b and of I_c after `t_k`, s.
    t_ab: f64,
    t_c: f64,
    half_ts: f64,
    dead: f64,
    inv_tau: f64,
    inv_l: f64,
    r: f64,
    /// The fast path's bounds on the duties' bits ([`ShuntPre::read`]): with every duty in
    /// force after `t_k` at most `now_max` and every duty before it at most `before_max`, all
    /// three instants lie inside every window, more than 30 amplifier time constants after it
    /// opened and before any high side takes over.
    fast: bool,
    now_max: u16,
    before_max: u16,
    /// The late window's settling factor for each duty above `before_max` (its bits, up to
    /// 1), each sign of the current and each instant: `settled((δ − t_open)/τ)` as the
    /// general model evaluates it, or −1 where the window has not opened by δ (reading 0).
    /// Layout `[(instant·2 + pos)·n + bits − before_max − 1]`, n = `ONE − before_max`.
    late: Vec<f64>,
    /// The held reading's decay after a window that closed before its instant (a duty above
    /// `now_max`): `exp(−(δ − h)/τ)` as the general model evaluates it, h the high side's
    /// take-over for the duty's bits (up to 1) and the current's sign, at each instant (NaN
    /// where the window is still open at δ). Layout `[(instant·2 + pos)·m + bits − now_max
    /// − 1]`, m = `ONE − now_max`.
    hold: Vec<f64>,
}

/// The bits of duty 1 (U1F15).
const ONE: u16 = 1 << 15;

impl ShuntPre {
    /// Checks every value (the key, the value and the allowed range in the message).
    pub fn new(
        s: &ShuntSampling,
        inv: &Inverter,
        r_ohm: f64,
        l_h: f64,
        ts: f64,
    ) -> Result<ShuntPre, String> {
        let check = |key: &str, v: f64, lo: f64, hi: f64| {
            if v.is_finite() && v >= lo && v <= hi {
                Ok(v)
            } else {
                Err(format!(
                    "sensors.shunt.{key} = {v}: must lie in [{lo:e}, {hi:e}]"
                ))
            }
        };
        let settle = check("settle_s", s.settle_s, 1e-9, 1e-4)?;
        let f = check("adc_clock_hz", s.adc_clock_hz, 1e5, 1e9)?;
        let sc = check("sample_clocks", s.sample_clocks, 1.5, 1000.0)?;
        let cc = check("conversion_clocks", s.conversion_clocks, 1.0, 100.0)?;
        let t_c = (2.0 * sc + cc) / f;
        if t_c >= ts / 2.0 {
            return Err(format!(
                "sensors.shunt: the I_c instant ({:.3} µs after the trigger, from sample_clocks, conversion_clocks and adc_clock_hz) must lie within half a PWM period ({:.3} µs)",
                t_c * 1e6,
                ts / 2.0 * 1e6
            ));
        }
        let mut p = ShuntPre {
            on: s.enabled,
            t_ab: sc / f,
            t_c,
            half_ts: ts / 2.0,
            dead: inv.dead_time_s.max(0.0),
            inv_tau: 1.0 / settle,
            inv_l: 1.0 / l_h,
            r: r_ohm,
            fast: false,
            now_max: 0,
            before_max: 0,
            late: Vec::new(),
            hold: Vec::new(),
        };
        // The largest duty bits for which the general model's own expressions (rounding
        // included, monotone in the duty) put the instants inside the windows: no high side
        // has taken over at the last instant (`h` without the dead time, the earlier case),
        // and the window opened (with the dead time, the later case) more than 30 time
        // constants before the first instant (so `settled` is exactly 1). None: no duty
        // qualifies (an ADC sequence too slow for any window), no fast path.
        let last = |cond: &dyn Fn(f64) -> bool| {
            (0..=Duty::from_num(1).to_bits())
                .take_while(|&b| cond(duty_of(Duty::from_bits(b))))
                .last()
        };
        let now_max = last(&|d| (1.0 - d) * p.half_ts >= p.t_c);
        let before_max = last(&|d| {
            let open = -(1.0 - d) * p.half_ts + p.dead;
            (p.t_ab - open) * p.inv_tau > 30.0
        });
        // (Only for a run that samples through the shunts: the table is ≈ 0.24 MB.)
        if let (true, Some(n), Some(b)) = (s.enabled, now_max, before_max) {
            (p.fast, p.now_max, p.before_max) = (true, n, b);
            let mut late = Vec::with_capacity(4 * (ONE - b) as usize);
            for dl in [p.t_ab, p.t_c] {
                for pos in [false, true] {
                    for bits in b + 1..=ONE {
                        let t0 = p.open_of(bits, true, pos);
                        late.push(if dl <= t0 {
                            -1.0
                        } else {
                            settled((dl - t0) * p.inv_tau)
                        });
                    }
                }
            }
            p.late = late;
            let mut hold = Vec::with_capacity(4 * (ONE - n) as usize);
            for dl in [p.t_ab, p.t_c] {
                for pos in [false, true] {
                    for bits in n + 1..=ONE {
                        let t1 = p.close_of(bits, pos);
                        hold.push(if dl > t1 {
                            (-(dl - t1) * p.inv_tau).exp()
                        } else {
                            f64::NAN
                        });
                    }
                }
            }
            p.hold = hold;
        }
        Ok(p)
    }

    /// The three current channels' readings, A: `i` and `e` the phase currents and emfs at
    /// `t_k`, `before` and `now` the actuations in force before and after `t_k`.
    ///
    /// The common period (every duty within the bounds computed in [`ShuntPre::new`]) is
    /// the general model with its window terms at their values there (no high time, the
    /// amplifier settled: factors exactly 0 and 1), inline and without branches per phase;
    /// with the duties after `t_k` within their bound but one before it above its own (a
    /// window that opened late), the settling factors are applied out of line
    /// ([`ShuntPre::settle`]). `fast_path_is_the_general_model` pins both to
    /// [`ShuntPre::read_general`] bit for bit.
    #[inline(always)]
    pub fn read(
        &self,
        i: [f64; 3],
        e: [f64; 3],
        v_bus: f64,
        before: &Actuation,
        now: &Actuation,
    ) -> [f64; 3] {
        let max3 = |a: &Actuation| {
            let [x, y, z] = a.duties.map(|d| d.to_bits());
            x.max(y).max(z)
        };
        if self.fast && now.enable && max3(now) <= self.now_max {
            // No high side has taken over at either instant: no high time, every window
            // still open.
            let at = |x: usize, dl: f64| i[x] - dl * (e[x] + self.r * i[x]) * self.inv_l;
            let mut r = [at(0, self.t_ab), at(1, self.t_ab), at(2, self.t_c)];
            let b = if before.enable { max3(before) } else { 0 };
            if b > self.before_max {
                // A window that opened late (a high duty before t_k): its amplifier settles.
                self.settle(&mut r, i, before);
            }
            return r;
        }
        self.read_general(i, e, v_bus, before, now)
    }

    /// [`ShuntPre::read_general`]'s factor on each channel whose window is open at its
    /// instant and closes after it (`r` the readings without it): a table load and a
    /// product per phase, inline (in a voltage-limited run most periods take it).
    #[inline(always)]
    fn settle(&self, r: &mut [f64; 3], i: [f64; 3], before: &Actuation) {
        let n = (ONE - self.before_max) as usize;
        for (x, instant) in [(0, 0), (1, 0), (2, 1)] {
            let bits = before.duties[x].to_bits().min(ONE);
            if bits > self.before_max {
                let k = (instant * 2 + (i[x] > 0.0) as usize) * n
                    + (bits - self.before_max - 1) as usize;
                let f = self.late[k];
                r[x] = if f < 0.0 { 0.0 } else { r[x] * f };
            }
        }
    }

    /// Where a phase's shunt window closes (its high side takes over) for the duty's `bits`
    /// in force after `t_k` (its current positive: `pos`), s after `t_k`.
    #[inline(always)]
    fn close_of(&self, bits: u16, pos: bool) -> f64 {
        (1.0 - duty_of(Duty::from_bits(bits))) * self.half_ts + if pos { self.dead } else { 0.0 }
    }

    /// The amplifier's settled fraction at instant `inst` (0: I_a/I_b, 1: I_c, at `dl`) on
    /// phase `x`, whose window opened at `t0` < `dl` from the duty before `t_k`: from the
    /// `late` table where it holds the value (a late window), else [`settled`].
    #[inline(always)]
    fn settled_at(
        &self,
        x: usize,
        inst: usize,
        pos: bool,
        before: &Actuation,
        dl: f64,
        t0: f64,
    ) -> f64 {
        let bits = before.duties[x].to_bits().min(ONE);
        if self.fast && before.enable && bits > self.before_max {
            let n = (ONE - self.before_max) as usize;
            self.late[(inst * 2 + pos as usize) * n + (bits - self.before_max - 1) as usize]
        } else {
            settled((dl - t0) * self.inv_tau)
        }
    }

    /// The held reading's decay `exp(−(dl − t1)/τ)` at instant `inst` on phase `x`, whose
    /// window closed at `t1` < `dl`: from the `hold` table (a duty above `now_max`, the only
    /// duties whose window closes before an instant, when the tables exist).
    #[inline(always)]
    fn decay_at(&self, x: usize, inst: usize, pos: bool, now: &Actuation, dl: f64, t1: f64) -> f64 {
        let bits = now.duties[x].to_bits().min(ONE);
        if self.fast && bits > self.now_max {
            let m = (ONE - self.now_max) as usize;
            self.hold[(inst * 2 + pos as usize) * m + (bits - self.now_max - 1) as usize]
        } else {
            (-(dl - t1) * self.inv_tau).exp()
        }
    }

    /// Where phase `x`'s shunt window opened (its current positive: `pos`), s after `t_k`.
    #[inline(always)]
    fn open(&self, x: usize, pos: bool, before: &Actuation) -> f64 {
        self.open_of(before.duties[x].to_bits(), before.enable, pos)
    }

    /// [`ShuntPre::open`] from the duty's bits and whether the gates were enabled.
    #[inline(always)]
    fn open_of(&self, bits: u16, enabled: bool, pos: bool) -> f64 {
        let low_on = if enabled {
            -(1.0 - duty_of(Duty::from_bits(bits))) * self.half_ts
        } else {
            -self.half_ts
        };
        low_on + if pos { 0.0 } else { self.dead }
    }

    /// The model in full (any duties, the gates off).
    #[inline(never)]
    pub fn read_general(
        &self,
        i: [f64; 3],
        e: [f64; 3],
        v_bus: f64,
        before: &Actuation,
        now: &Actuation,
    ) -> [f64; 3] {
        if !now.enable {
            return i;
        }
        let pos: [bool; 3] = core::array::from_fn(|x| i[x] > 0.0);
        // High side takes over (shunt window closes) at h, the window opened at `open`.
        let h: [f64; 3] = core::array::from_fn(|x| self.close_of(now.duties[x].to_bits(), pos[x]));
        let open: [f64; 3] = core::array::from_fn(|x| self.open(x, pos[x], before));
        // The terminals' high time up to each instant (all zero while no high side has
        // taken over, the common case) and its mean.
        let high = |dl: f64| {
            let a = h.map(|hy| (dl - hy).max(0.0));
            let m = (a[0] + a[1] + a[2]) * (1.0 / 3.0);
            [a[0] - m, a[1] - m, a[2] - m]
        };
        let (a_ab, a_c) = (high(self.t_ab), high(self.t_c));
        let at = |x: usize, dl: f64, ax: f64| {
            i[x] + (v_bus * ax - dl * (e[x] + self.r * i[x])) * self.inv_l
        };
        // The amplifier's settling and the held reading's decay come from the tables where
        // they hold them (`settled_at`, `decay_at`: the same expressions, evaluated in
        // `ShuntPre::new`), so that a period at the modulation limit calls no exponential
        // but for a window both opened late and closed early.
        let read = |x: usize, inst: usize, dl: f64, ax: f64| {
            let (t0, t1) = (open[x], h[x]);
            if dl <= t0 {
                0.0
            } else if dl <= t1 {
                at(x, dl, ax) * self.settled_at(x, inst, pos[x], before, dl, t0)
            } else {
                // Held at the window's end (no high time of its own yet then).
                let a1 = high(t1)[x];
                at(x, t1, a1)
                    * settled((t1 - t0) * self.inv_tau)
                    * self.decay_at(x, inst, pos[x], now, dl, t1)
            }
        };
        [
            read(0, 0, self.t_ab, a_ab[0]),
            read(1, 0, self.t_ab, a_ab[1]),
            read(2, 1, self.t_c, a_c[2]),
        ]
    }
}

/// The amplifier's settled fraction after `k` time constants, 1 − e^(−k): exactly 1 past
/// k = 30 (below 1e-13), without the exponential.
#[inline(always)]
fn settled(k: f64) -> f64 {
    if k > 30.0 {
        1.0
    } else {
        1.0 - (-k).exp()
    }
}

/// A duty's value, clamped to 1 (U1F15 reaches 2).
#[inline(always)]
fn duty_of(d: Duty) -> f64 {
    (d.to_bits() as f64 * (1.0 / 32768.0)).min(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn act(d: [f64; 3]) -> Actuation {
        Actuation {
            duties: d.map(Duty::from_num),
            enable: true,
            brake: false,
        }
    }

    fn pre() -> ShuntPre {
        let inv = Inverter {
            switched: false,
            dead_time_s: 0.5e-6,
        };
        let on = ShuntSampling {
            enabled: true,
            ..Default::default()
        };
        ShuntPre::new(&on, &inv, 2.41, 6e-3, 50e-6).unwrap()
    }

    #[test]
    fn instants_are_the_boards_sequence() {
        let p = pre();
        // 12.5 clocks at 42.5 MHz; 37.5 clocks (sample, conversion, sample).
        assert!((p.t_ab - 12.5 / 42.5e6).abs() < 1e-15);
        assert!((p.t_c - 37.5 / 42.5e6).abs() < 1e-15);
    }

    #[test]
    fn mid_duties_read_the_current_plus_the_zero_vector_ripple() {
        let p = pre();
        let (i, e) = ([3.0, -1.0, -2.0], [10.0, -4.0, -6.0]);
        let a = act([0.5, 0.4, 0.6]);
        let r = p.read(i, e, 72.0, &a, &a);
        // All low sides on over both instants: di/dt = −(e + R·i)/L (closed form).
        for (x, dl) in [(0, p.t_ab), (1, p.t_ab), (2, p.t_c)] {
            let want = i[x] - dl * (e[x] + 2.41 * i[x]) / 6e-3;
            assert!((r[x] - want).abs() < 1e-12, "{x}: {} vs {want}", r[x]);
        }
    }

    #[test]
    fn a_closed_window_reads_no_current_and_a_fresh_one_settles() {
        let p = pre();
        let i = [3.0, -1.0, -2.0];
        // Phase c at 0.99 (i_c < 0: no dead time added): its low side is off from 0.25 µs,
        // before its 0.88 µs instant, so the settled amplifier decays for 0.63 µs. Phase a
        // was at 0.99 before t_k with i_a > 0 (low-side diode from −0.25 µs): 0.54 µs of
        // settling at its 0.29 µs instant.
        let r = p.read(
            i,
            [0.0; 3],
            72.0,
            &act([0.99, 0.5, 0.2]),
            &act([0.5, 0.5, 0.99]),
        );
        let settle_a = 1.0 - (-(0.25e-6 + p.t_ab) / 0.2e-6).exp();
        assert!((r[0] / (i[0] * settle_a) - 1.0).abs() < 1e-3, "{r:?}");
        let h = (1.0 - Duty::from_num(0.99).to_num::<f64>()) * 25e-6; // the U1F15 duty's
        let keep =
            (1.0 - (-(h + 0.8 * 25e-6 - 0.5e-6) / 0.2e-6).exp()) * (-(p.t_c - h) / 0.2e-6).exp();
        assert!((r[2] / (i[2] * keep) - 1.0).abs() < 1e-3, "{r:?} {keep}");
        assert!(r[2].abs() < 0.1 * i[2].abs());
    }

    /// The general model with every exponential evaluated in place (no table): what
    /// `read_general` computes.
    fn reference(
        p: &ShuntPre,
        i: [f64; 3],
        e: [f64; 3],
        v_bus: f64,
        before: &Actuation,
        now: &Actuation,
    ) -> [f64; 3] {
        if !now.enable {
            return i;
        }
        let pos: [bool; 3] = core::array::from_fn(|x| i[x] > 0.0);
        let h: [f64; 3] = core::array::from_fn(|x| {
            (1.0 - duty_of(now.duties[x])) * p.half_ts + if pos[x] { p.dead } else { 0.0 }
        });
        let open: [f64; 3] = core::array::from_fn(|x| p.open(x, pos[x], before));
        let high = |dl: f64| {
            let a = h.map(|hy| (dl - hy).max(0.0));
            let m = (a[0] + a[1] + a[2]) * (1.0 / 3.0);
            [a[0] - m, a[1] - m, a[2] - m]
        };
        let (a_ab, a_c) = (high(p.t_ab), high(p.t_c));
        let at =
            |x: usize, dl: f64, ax: f64| i[x] + (v_bus * ax - dl * (e[x] + p.r * i[x])) * p.inv_l;
        let read = |x: usize, dl: f64, ax: f64| {
            let (t0, t1) = (open[x], h[x]);
            if dl <= t0 {
                0.0
            } else if dl <= t1 {
                at(x, dl, ax) * settled((dl - t0) * p.inv_tau)
            } else {
                let a1 = high(t1)[x];
                at(x, t1, a1) * settled((t1 - t0) * p.inv_tau) * (-(dl - t1) * p.inv_tau).exp()
            }
        };
        [
            read(0, p.t_ab, a_ab[0]),
            read(1, p.t_ab, a_ab[1]),
            read(2, p.t_c, a_c[2]),
        ]
    }

    #[test]
    fn general_model_tables_are_the_exponentials() {
        // `read_general` with its settling and decay tables against the model evaluating
        // every exponential in place, bit for bit, over duties drawn around both bounds and
        // up to the U1F15 range's top (held windows on every phase, late windows, both),
        // both current signs and the gates either way; the held case must occur.
        let p = pre();
        let mut st = 0x0bad_cafe_1234_5678u64;
        let mut u = move || {
            st ^= st << 13;
            st ^= st >> 7;
            st ^= st << 17;
            (st >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut held = 0;
        for n in 0..200_000 {
            let duty = |lo: u16, u: &mut dyn FnMut() -> f64| {
                let b = if n % 3 == 0 {
                    u() * 40_000.0
                } else {
                    lo as f64 + u() * (40_000.0 - lo as f64)
                };
                Duty::from_bits(b as u16)
            };
            let before = Actuation {
                duties: [0; 3].map(|_| duty(p.before_max - 50, &mut u)),
                enable: u() < 0.9,
                brake: false,
            };
            let now = Actuation {
                duties: [0; 3].map(|_| duty(p.now_max - 50, &mut u)),
                enable: u() < 0.95,
                brake: false,
            };
            let i = [0; 3].map(|_| (u() - 0.5) * 40.0);
            let e = [0; 3].map(|_| (u() - 0.5) * 600.0);
            let vb = u() * 100.0;
            let (a, b) = (
                p.read_general(i, e, vb, &before, &now),
                reference(&p, i, e, vb, &before, &now),
            );
            assert_eq!(
                a.map(f64::to_bits),
                b.map(f64::to_bits),
                "{i:?} {e:?} {vb} {before:?} {now:?}"
            );
            let c = now.duties[2].to_bits().min(ONE);
            held += (now.enable && c > p.now_max && p.close_of(c, i[2] > 0.0) < p.t_c) as u32;
        }
        assert!(held > 50_000, "held {held}");
    }

    #[test]
    fn fast_path_is_the_general_model() {
        // Random currents, emfs, buses and duties (before and after t_k, each enabled or not),
        // half of them drawn near the fast path's duty bounds: `read` equals `read_general`
        // bit for bit, and each of its three cases (all within the bounds, a late window,
        // the general model) is exercised.
        let p = pre();
        assert!(
            p.fast && p.now_max > 20_000 && p.before_max > 20_000,
            "{p:?}"
        );
        let mut st = 0x1234_5678_9abc_def1u64;
        let mut u = move || {
            st ^= st << 13;
            st ^= st >> 7;
            st ^= st << 17;
            (st >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut fast, mut late, mut slow) = (0, 0, 0);
        for n in 0..200_000 {
            let (nm, bm) = (p.now_max, p.before_max);
            let duty = |near: u16, u: &mut dyn FnMut() -> f64| {
                let b = if n % 2 == 0 {
                    near as f64 + (u() - 0.5) * 64.0
                } else {
                    u() * 33_000.0
                };
                Duty::from_bits(b.max(0.0) as u16)
            };
            let before = Actuation {
                duties: [0; 3].map(|_| duty(bm, &mut u)),
                enable: u() < 0.9,
                brake: false,
            };
            let now = Actuation {
                duties: [0; 3].map(|_| duty(nm, &mut u)),
                enable: u() < 0.9,
                brake: false,
            };
            let i = [0; 3].map(|_| (u() - 0.5) * 40.0);
            let e = [0; 3].map(|_| (u() - 0.5) * 600.0);
            let vb = u() * 500.0;
            let (a, b) = (
                p.read(i, e, vb, &before, &now),
                p.read_general(i, e, vb, &before, &now),
            );
            assert_eq!(
                a.map(f64::to_bits),
                b.map(f64::to_bits),
                "{i:?} {e:?} {vb} {before:?} {now:?}"
            );
            let m = |x: &Actuation| x.duties.iter().map(|d| d.to_bits()).max().unwrap();
            let bmax = if before.enable { m(&before) } else { 0 };
            match (now.enable && m(&now) <= nm, bmax <= bm) {
                (true, true) => fast += 1,
                (true, false) => late += 1,
                _ => slow += 1,
            }
        }
        assert!(
            fast > 20_000 && late > 20_000 && slow > 20_000,
            "fast {fast}, late window {late}, general {slow}"
        );
        // The bounds are the tight ones: one bit above either, the general model's window
        // terms change the readings (a high side takes over before I_c's instant; the
        // amplifier has not settled to the last bit at I_a's).
        let (i, e) = ([3.0, -1.0, -2.0], [10.0, -4.0, -6.0]);
        let mid = Duty::from_bits(16_384);
        let act = |x: usize, dx: u16| {
            let mut duties = [mid; 3];
            duties[x] = Duty::from_bits(dx);
            Actuation {
                duties,
                enable: true,
                brake: false,
            }
        };
        let plain = |x: usize, dl: f64| i[x] - dl * (e[x] + p.r * i[x]) * p.inv_l;
        // (phase b, i_b < 0: no dead time added to its high side's take-over)
        let g = p.read_general(i, e, 72.0, &act(1, 16_384), &act(1, p.now_max + 1));
        assert_ne!(g[2], plain(2, p.t_c), "now_max + 1 still inside");
        // i_a < 0 at a duty one bit above `before_max`: its window opened with the dead time.
        let i_neg = [-3.0, 1.0, 2.0];
        let g = p.read_general(i_neg, e, 72.0, &act(0, p.before_max + 1), &act(0, 16_384));
        let plain_a = i_neg[0] - p.t_ab * (e[0] + p.r * i_neg[0]) * p.inv_l;
        assert_ne!(g[0], plain_a, "before_max + 1 still settled");
    }

    #[test]
    fn bad_values_are_refused_by_name() {
        let s = ShuntSampling {
            settle_s: f64::NAN,
            ..Default::default()
        };
        let e = ShuntPre::new(&s, &Inverter::default(), 1.0, 1e-3, 50e-6).unwrap_err();
        assert!(
            e.contains("sensors.shunt.settle_s") && e.contains("NaN"),
            "{e}"
        );
        let s = ShuntSampling {
            sample_clocks: 1000.0,
            ..Default::default()
        };
        let e = ShuntPre::new(&s, &Inverter::default(), 1.0, 1e-3, 50e-6).unwrap_err();
        assert!(e.contains("half a PWM period"), "{e}");
    }
}
