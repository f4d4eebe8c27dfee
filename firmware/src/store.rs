//! Persistent parameter store: versioned, checksummed, wear-levelled, power-loss safe.
//!
//! Equivalent, argued here, of `sequential-storage`'s queue (which we did not have time to
//! integrate): two flash sectors used as a ping-pong append log of records.
//!
//! Record layout (32-bit words, little-endian on the board):
//! `[MAGIC_VERSION, seq, n, value_0 … value_{n-1}, crc32, COMMIT]`, where `value_i` is the
//! `f32` bit pattern of registry entry `i` ([`crate::params::PARAMS`] order), `seq` increases
//! by one per save, and `crc32` covers every word from `MAGIC_VERSION` to the last value.
//!
//! Power-loss argument. NOR flash words are written one at a time and an erased word reads
//! `0xFFFF_FFFF`. A save appends a record after the last one, writing `COMMIT` last; a record
//! counts only if its `COMMIT` word is present *and* its CRC matches, so a save cut at any
//! word leaves the previous record as the newest valid one (old parameters), and a completed
//! save makes the new one newest (new parameters); a mix is impossible because a record is
//! read whole or not at all. When the active sector is full, the *other* sector (which holds
//! no newest record) is erased and the record written there: an interrupted erase destroys
//! only older records. Wear-levelling: records append through a sector before any erase, and
//! the two sectors alternate, so each erase serves `SECTOR_WORDS / record_len` saves.
//!
//! Boot: [`boot`] returns the newest valid record's configuration, or `Config::default()` and
//! a [`StoreFault`] when the store is empty, corrupt, or its record fails validation (e.g.
//! written by an older firmware with a different registry: the version word changes with the
//! registry length).

use crate::config::Config;
use crate::console::ParamStore;
use crate::params::PARAMS;

const MAGIC: u32 = 0x5247_0000; // "RG"
/// Store format version, bumped when the layout changes.
pub const VERSION: u32 = 1;
const COMMIT: u32 = 0x0000_C0DE;

/// A NOR flash of two sectors, word addressed.
pub trait Flash {
    /// Words per sector.
    fn sector_words(&self) -> usize;
    fn read(&self, sector: usize, word: usize) -> u32;
    /// Program one word (may only clear bits). `Err` = power lost.
    fn write(&mut self, sector: usize, word: usize, v: u32) -> Result<(), PowerLost>;
    /// Erase a sector to all ones. `Err` = power lost (sector content undefined).
    fn erase(&mut self, sector: usize) -> Result<(), PowerLost>;
}

/// The simulated power failed during a flash operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PowerLost;

/// Why boot fell back to defaults.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StoreFault {
    /// No valid record (blank flash or every record torn/corrupt).
    Empty,
    /// The newest record has a valid CRC but its values are refused by `Config::validate`.
    Invalid,
}

fn rec_len() -> usize {
    3 + PARAMS.len() + 2
}

fn header() -> u32 {
    MAGIC | (VERSION << 8) | (PARAMS.len() as u32 & 0xFF)
}

/// CRC-32 (IEEE, reflected), bitwise: slow but tiny, and only run outside the current loop.
pub fn crc32(words: impl Iterator<Item = u32>) -> u32 {
    let mut crc = !0u32;
    for w in words {
        for b in w.to_le_bytes() {
            crc ^= b as u32;
            for _ in 0..8 {
                crc = if crc & 1 != 0 {
                    (crc >> 1) ^ 0xEDB8_8320
                } else {
                    crc >> 1
                };
            }
        }
    }
    !crc
}

/// A valid record found at (sector, word) with its sequence number.
#[derive(Clone, Copy, Debug)]
struct Found {
    sector: usize,
    at: usize,
    seq: u32,
}

fn valid_at<F: Flash>(f: &F, s: usize, at: usize) -> Option<u32> {
    let n = rec_len();
    if at + n > f.sector_words() || f.read(s, at) != header() {
        return None;
    }
    if f.read(s, at + n - 1) != COMMIT || f.read(s, at + 2) != PARAMS.len() as u32 {
        return None;
    }
    let crc = crc32((at..at + n - 2).map(|i| f.read(s, i)));
    (crc == f.read(s, at + n - 2)).then(|| f.read(s, at + 1))
}

/// Scan both sectors: newest valid record, and the first free word of each sector
/// (after the last word that is not erased).
fn scan<F: Flash>(f: &F) -> (Option<Found>, [usize; 2]) {
    let n = rec_len();
    let mut best: Option<Found> = None;
    let mut free = [0usize; 2];
    for (s, fr) in free.iter_mut().enumerate() {
        let w = f.sector_words();
        *fr = (0..w)
            .rev()
            .find(|&i| f.read(s, i) != !0)
            .map_or(0, |i| i + 1);
        let mut at = 0;
        while at + n <= w {
            if let Some(seq) = valid_at(f, s, at) {
                if best.is_none_or(|b| seq.wrapping_sub(b.seq) as i32 > 0) {
                    best = Some(Found { sector: s, at, seq });
                }
            }
            at += n;
        }
    }
    (best, free)
}

fn decode<F: Flash>(f: &F, r: Found) -> Result<Config, StoreFault> {
    let mut c = Config::default();
    for (i, p) in PARAMS.iter().enumerate() {
        let v = f32::from_bits(f.read(r.sector, r.at + 3 + i));
        p.check(v).map_err(|_| StoreFault::Invalid)?;
        (p.set)(&mut c, v);
    }
    c.validate().map_err(|_| StoreFault::Invalid)?;
    Ok(c)
}

/// Read the configuration at boot; defaults and a fault if there is none usable.
pub fn boot<F: Flash>(f: &F) -> (Config, Option<StoreFault>) {
    match scan(f).0 {
        None => (Config::default(), Some(StoreFault::Empty)),
        Some(r) => match decode(f, r) {
            Ok(c) => (c, None),
            Err(e) => (Config::default(), Some(e)),
        },
    }
}

/// Append a record for `cfg`. Records sit at multiples of the record length; the next slot
/// is the first whole slot after the last non-erased word of the active sector.
pub fn save<F: Flash>(f: &mut F, cfg: &Config) -> Result<(), PowerLost> {
    let n = rec_len();
    let (best, free) = scan(f);
    let (mut s, seq) = match best {
        Some(b) => (b.sector, b.seq.wrapping_add(1)),
        None => (0, 1),
    };
    let mut at = free[s].div_ceil(n) * n;
    // The active sector full: the other one, erased. No valid record anywhere but garbage in
    // sector 0: start clean. (One erase call site: the board's erase is inlined.)
    let full = at + n > f.sector_words();
    if full || (best.is_none() && free[s] > 0) {
        s ^= full as usize;
        f.erase(s)?;
        at = 0;
    }
    let mut words = [0u32; 64];
    let body = 3 + PARAMS.len();
    if n > words.len() {
        return Ok(()); // unreachable with the registry's size; checked by a test
    }
    words[0] = header();
    words[1] = seq;
    words[2] = PARAMS.len() as u32;
    for (i, p) in PARAMS.iter().enumerate() {
        words[3 + i] = (p.get)(cfg).to_bits();
    }
    words[body] = crc32(words[..body].iter().copied());
    words[body + 1] = COMMIT;
    for (i, w) in words[..n].iter().enumerate() {
        f.write(s, at + i, *w)?;
    }
    Ok(())
}

/// A [`ParamStore`] over a [`Flash`].
pub struct FlashStore<F: Flash>(pub F);

impl<F: Flash> ParamStore for FlashStore<F> {
    fn save(&mut self, cfg: &Config) -> Result<(), &'static str> {
        save(&mut self.0, cfg).map_err(|_| "flash write failed")
    }
    fn load(&mut self) -> Result<Config, &'static str> {
        match boot(&self.0) {
            (c, None) => Ok(c),
            (_, Some(StoreFault::Empty)) => Err("store empty or corrupt"),
            (_, Some(StoreFault::Invalid)) => Err("stored parameters invalid"),
        }
    }
}

/// A simulated NOR flash of two sectors of `W` words, with a power-cut budget: after
/// `budget` operations (word writes or erases) every operation fails with [`PowerLost`] and
/// changes nothing more (an interrupted erase leaves the sector half erased).
#[derive(Clone)]
pub struct SimFlash<const W: usize> {
    pub mem: [[u32; W]; 2],
    pub budget: Option<usize>,
    pub ops: usize,
    pub erases: [u32; 2],
}

impl<const W: usize> Default for SimFlash<W> {
    fn default() -> Self {
        SimFlash {
            mem: [[!0; W]; 2],
            budget: None,
            ops: 0,
            erases: [0; 2],
        }
    }
}

impl<const W: usize> SimFlash<W> {
    fn spend(&mut self) -> Result<(), PowerLost> {
        if let Some(b) = self.budget {
            if self.ops >= b {
                return Err(PowerLost);
            }
        }
        self.ops += 1;
        Ok(())
    }
}

impl<const W: usize> Flash for SimFlash<W> {
    fn sector_words(&self) -> usize {
        W
    }
    fn read(&self, s: usize, w: usize) -> u32 {
        self.mem
            .get(s)
            .and_then(|m| m.get(w))
            .copied()
            .unwrap_or(!0)
    }
    fn write(&mut self, s: usize, w: usize, v: u32) -> Result<(), PowerLost> {
        self.spend()?;
        if let Some(x) = self.mem.get_mut(s).and_then(|m| m.get_mut(w)) {
            *x &= v; // NOR programming only clears bits
        }
        Ok(())
    }
    fn erase(&mut self, s: usize) -> Result<(), PowerLost> {
        let cut = self.spend().is_err();
        if let Some(m) = self.mem.get_mut(s) {
            let upto = if cut { W / 2 } else { W };
            m[..upto].iter_mut().for_each(|x| *x = !0);
            if !cut {
                self.erases[s] += 1;
            }
        }
        if cut {
            Err(PowerLost)
        } else {
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    type F = SimFlash<100>; // about 3 records per sector: exercises sector switching quickly

    fn cfg(r: f32) -> Config {
        Config {
            r_load_ohm: r,
            ..Config::default()
        }
    }

    #[test]
    fn empty_and_corrupt_boot_to_defaults_with_fault() {
        let mut f = F::default();
        assert_eq!(boot(&f), (Config::default(), Some(StoreFault::Empty)));
        save(&mut f, &cfg(100.0)).unwrap();
        assert_eq!(boot(&f), (cfg(100.0), None));
        f.mem[0][5] ^= 1; // flip one bit of a value
        assert_eq!(boot(&f), (Config::default(), Some(StoreFault::Empty)));
        let mut g = F::default();
        g.mem[0]
            .iter_mut()
            .enumerate()
            .for_each(|(i, x)| *x = (i as u32).wrapping_mul(2_654_435_761));
        assert_eq!(boot(&g).1, Some(StoreFault::Empty));
        assert!(rec_len() <= 64);
    }

    #[test]
    fn power_cut_at_every_step_leaves_old_or_new() {
        // Several saves in a row so that cuts land in appends, sector switches and erases.
        for n_prev in 0..8u32 {
            let mut base = F::default();
            for i in 0..n_prev {
                save(&mut base, &cfg(10.0 + i as f32)).unwrap();
            }
            let old = boot(&base);
            let new = cfg(500.0);
            // Count the operations of an uninterrupted save.
            let mut probe = base.clone();
            probe.ops = 0;
            save(&mut probe, &new).unwrap();
            let steps = probe.ops;
            assert!(steps >= rec_len());
            for k in 0..=steps {
                let mut f = base.clone();
                f.ops = 0;
                f.budget = Some(k);
                let r = save(&mut f, &new);
                assert_eq!(r.is_ok(), k == steps, "n_prev {n_prev} k {k}");
                f.budget = None;
                let b = boot(&f);
                if k == steps {
                    assert_eq!(b, (new, None));
                } else {
                    assert_eq!(b, old, "n_prev {n_prev} cut after {k} of {steps}");
                }
                // And the store still works after the cut.
                save(&mut f, &cfg(7.0)).unwrap();
                assert_eq!(boot(&f), (cfg(7.0), None));
            }
        }
    }

    #[test]
    fn wear_levelling_alternates_sectors() {
        let mut f = F::default();
        for i in 0..60 {
            save(&mut f, &cfg(1.0 + i as f32)).unwrap();
            assert_eq!(boot(&f).0, cfg(1.0 + i as f32));
        }
        let per = 100 / rec_len();
        // 60 saves, `per` per sector fill → about 60/per erases shared by both sectors.
        assert!(f.erases[0].abs_diff(f.erases[1]) <= 1, "{:?}", f.erases);
        assert!((f.erases[0] + f.erases[1]) as usize <= 60 / per + 1);
    }
}
