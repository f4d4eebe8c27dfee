//! Persistent parameter store: an append log of records over two pages of any async NOR flash
//! (`embedded-storage-async`; on the board embassy-stm32's interrupt-driven bank-2 flash,
//! awaited in the console's task, so a page erase never blocks the executor).
//!
//! Keyed by the parameter registry: a record holds the registry's entries as `(id, value)`,
//! `id` = [`param_id`] of the entry's name (a 16-bit hash, distinct over the registry: tested),
//! the value's `f32` bits. A firmware whose registry gained an entry loads the entries it finds
//! and keeps the factory value for the new one; an entry it no longer has is skipped. Every
//! value read is checked against its registry range and the whole against [`Config::validate`].
//!
//! Record, in 8-byte double words (the G474's program unit, each programmed once after an
//! erase), little-endian 32-bit halves:
//! `[HEADER, seq] [n, !n] [id_0, value_0] … [id_{n−1}, value_{n−1}] [crc32, COMMIT]`, `crc32`
//! over the bytes of every double word before it. The last double word is written last, by a
//! write of its own.
//!
//! Power-loss argument. A record counts only if its header, count, CRC and commit word are all
//! right, so a save cut at any byte (or a double word torn by the cut and zeroed at the next
//! boot, `firmware/board/src/store.rs`) leaves the previous record the newest valid one, and a
//! completed save makes the new one newest; a record is read whole or not at all: never a mix.
//! A save appends after the last programmed double word of the active page (a torn record is
//! skipped, never programmed again); when the active page is full, the *other* page (which holds
//! no newest record) is erased and the record written there: an interrupted erase destroys only
//! older records. Wear: records fill a page before any erase, and the two pages alternate.
//! Tested by cutting the power after every byte written over many saves in a row, side by side
//! with `sequential-storage`'s map on the same flash and the same cuts (`tests` below;
//! `docs/console.md` has the comparison and why this store is the one the board runs).

use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

use crate::config::Config;
use crate::params::PARAMS;

const HEADER: u32 = 0x5247_5031; // "RGP1": the record format
const COMMIT: u32 = 0x0000_C0DE;
/// Page (erase unit) bytes; the store uses two.
pub const PAGE: u32 = 2048;
const DW: usize = 8;
const PAGE_DW: usize = PAGE as usize / DW;
/// Longest record the reader accepts (entries), above the registry's size.
const MAX_ENTRIES: usize = 120;
const _: () = assert!(PARAMS.len() <= MAX_ENTRIES && PARAMS.len() + 3 <= PAGE_DW / 2);

/// Why boot fell back to defaults.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StoreFault {
    /// No valid record (blank flash, or every record torn or corrupt).
    Empty,
    /// The newest record reads back whole but a value is outside its registry range or the
    /// configuration fails `Config::validate`.
    Invalid,
}

impl StoreFault {
    pub fn message(self) -> &'static str {
        match self {
            StoreFault::Empty => "store empty",
            StoreFault::Invalid => "stored parameters invalid",
        }
    }
}

/// A registry entry's key in a record: FNV-1a (32 bit) of its name, folded to 16 bits.
pub const fn param_id(name: &str) -> u16 {
    let b = name.as_bytes();
    let mut h: u32 = 0x811C_9DC5;
    let mut i = 0;
    while i < b.len() {
        h ^= b[i] as u32;
        h = h.wrapping_mul(0x0100_0193);
        i += 1;
    }
    (h ^ (h >> 16)) as u16
}

/// CRC-32 (IEEE, reflected), bitwise: slow but tiny, run outside the current loop only.
fn crc32(mut crc: u32, bytes: &[u8]) -> u32 {
    for &b in bytes {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    crc
}

fn halves(d: [u8; DW]) -> (u32, u32) {
    (
        u32::from_le_bytes([d[0], d[1], d[2], d[3]]),
        u32::from_le_bytes([d[4], d[5], d[6], d[7]]),
    )
}

fn dw(lo: u32, hi: u32) -> [u8; DW] {
    let mut d = [0; DW];
    d[..4].copy_from_slice(&lo.to_le_bytes());
    d[4..].copy_from_slice(&hi.to_le_bytes());
    d
}

/// Reads that complete at once (memory-mapped flash, RAM): the store scans and loads with
/// them, so only its erases and programs are awaited (and its future stays small).
pub trait ReadNow {
    /// `bytes.len()` bytes from byte `offset`; bytes outside the flash read as erased.
    fn read_now(&self, offset: u32, bytes: &mut [u8]);
}

/// The store: two pages of `flash` from byte offset `base`.
pub struct Store<S> {
    pub flash: S,
    pub base: u32,
}

/// A valid record: page, double-word index, sequence number, entries.
#[derive(Clone, Copy)]
struct Found {
    page: usize,
    at: usize,
    seq: u32,
    n: usize,
}

impl<S: ReadNow> Store<S> {
    fn read_dw(&self, page: usize, at: usize) -> [u8; DW] {
        let mut d = [0u8; DW];
        let off = self.base + page as u32 * PAGE + (at * DW) as u32;
        self.flash.read_now(off, &mut d);
        d
    }

    /// The record at (page, at) if it is whole and right: its sequence number and entries.
    fn valid_at(&self, page: usize, at: usize) -> Option<(u32, usize)> {
        let d0 = self.read_dw(page, at);
        let (h, seq) = halves(d0);
        if h != HEADER || at + 3 > PAGE_DW {
            return None;
        }
        let d1 = self.read_dw(page, at + 1);
        let (n, not_n) = halves(d1);
        let n = n as usize;
        if not_n != !(n as u32) || n > MAX_ENTRIES || at + n + 3 > PAGE_DW {
            return None;
        }
        let mut crc = crc32(crc32(!0, &d0), &d1);
        for i in 0..n {
            crc = crc32(crc, &self.read_dw(page, at + 2 + i));
        }
        let (c, commit) = halves(self.read_dw(page, at + 2 + n));
        (commit == COMMIT && c == !crc).then_some((seq, n))
    }

    /// The newest valid record, and the first free double word of each page (after the last
    /// one that is not erased).
    fn scan(&self) -> (Option<Found>, [usize; 2]) {
        let mut best: Option<Found> = None;
        let mut free = [0usize; 2];
        for (page, fr) in free.iter_mut().enumerate() {
            *fr = (0..PAGE_DW)
                .rev()
                .find(|&at| self.read_dw(page, at) != [0xFF; DW])
                .map_or(0, |at| at + 1);
            let mut at = 0;
            while at < *fr {
                match self.valid_at(page, at) {
                    Some((seq, n)) => {
                        if best.is_none_or(|b| seq.wrapping_sub(b.seq) as i32 > 0) {
                            best = Some(Found { page, at, seq, n });
                        }
                        at += n + 3;
                    }
                    None => at += 1,
                }
            }
        }
        (best, free)
    }

    /// Read the configuration at boot: the newest record's, or `Config::default()` and why.
    pub fn load(&self) -> (Config, Option<StoreFault>) {
        let Some(r) = self.scan().0 else {
            return (Config::default(), Some(StoreFault::Empty));
        };
        let mut cfg = Config::default();
        let mut in_range = true;
        for i in 0..r.n {
            let (id, bits) = halves(self.read_dw(r.page, r.at + 2 + i));
            let v = f32::from_bits(bits);
            if let Some(p) = PARAMS.iter().find(|p| u32::from(param_id(p.name)) == id) {
                in_range &= p.check(v).is_ok();
                p.set(&mut cfg, v);
            }
        }
        if in_range && cfg.validate().is_ok() {
            (cfg, None)
        } else {
            (Config::default(), Some(StoreFault::Invalid))
        }
    }
}

impl<S: ReadNow + NorFlash> Store<S> {
    /// Append a record for `cfg` (erasing the other page first when the active one is full).
    pub async fn save(&mut self, cfg: &Config) -> Result<(), &'static str> {
        let n = PARAMS.len();
        let len = n + 3;
        let (best, free) = self.scan();
        let (mut page, seq) = match best {
            Some(b) => (b.page, b.seq.wrapping_add(1)),
            None => (0, 1),
        };
        let mut at = free[page];
        // The active page full: the other one, erased. No valid record anywhere but something
        // programmed in page 0: start clean.
        let full = at + len > PAGE_DW;
        let failed = |_| "flash write failed";
        if full || (best.is_none() && at > 0) {
            page ^= full as usize;
            let from = self.base + page as u32 * PAGE;
            self.flash.erase(from, from + PAGE).await.map_err(failed)?;
            at = 0;
        }
        let mut rec = [0u8; (PARAMS.len() + 2) * DW];
        rec[..DW].copy_from_slice(&dw(HEADER, seq));
        rec[DW..2 * DW].copy_from_slice(&dw(n as u32, !(n as u32)));
        for (p, d) in PARAMS.iter().zip(rec[2 * DW..].chunks_exact_mut(DW)) {
            d.copy_from_slice(&dw(param_id(p.name).into(), p.get(cfg).to_bits()));
        }
        let crc = !crc32(!0, &rec);
        let off = self.base + page as u32 * PAGE + (at * DW) as u32;
        // The body, then the CRC and commit word by a write of their own.
        self.flash.write(off, &rec).await.map_err(failed)?;
        self.flash
            .write(off + rec.len() as u32, &dw(crc, COMMIT))
            .await
            .map_err(failed)
    }
}

/// A NOR flash in RAM with the STM32G474's geometry: `P` pages of 2 KiB, read by the byte,
/// programmed in 8-byte double words, each once after an erase (the G474 refuses a second
/// program of a double word, its ECC, unless the new value is all zeros: RM0440, PROGERR). A power-cut budget in bytes: the write that
/// reaches it programs the bytes before the cut and fails, and from then on every operation
/// fails and changes nothing (an erase in progress leaves the first half of its page erased).
#[derive(Clone)]
pub struct MemFlash<const P: usize> {
    pub mem: [[u8; 2048]; P],
    /// Bytes that may still be programmed before the power is cut (`None`: never).
    pub budget: Option<usize>,
    /// Bytes programmed since the budget was set (or since creation).
    pub written: usize,
    /// Erases per page.
    pub erases: [u32; P],
    /// Programs of a double word that was not erased with a value other than zero (refused,
    /// as by the G474).
    pub reprograms: u32,
    /// The double word (page, byte offset) whose program the power cut interrupted.
    pub torn: Option<(usize, usize)>,
    dead: bool,
}

/// The simulated power failed, or the operation was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MemFlashError(pub NorFlashErrorKind);

impl NorFlashError for MemFlashError {
    fn kind(&self) -> NorFlashErrorKind {
        self.0
    }
}

impl<const P: usize> Default for MemFlash<P> {
    fn default() -> Self {
        MemFlash {
            mem: [[0xFF; 2048]; P],
            budget: None,
            written: 0,
            erases: [0; P],
            reprograms: 0,
            torn: None,
            dead: false,
        }
    }
}

impl<const P: usize> MemFlash<P> {
    /// Restore the power (after a cut): the contents stay as the cut left them.
    pub fn power_on(&mut self) {
        self.dead = false;
        self.budget = None;
    }
    /// Whether the power was cut.
    pub fn is_dead(&self) -> bool {
        self.dead
    }
    fn locate(&self, offset: u32, len: usize) -> Option<(usize, usize)> {
        let (page, at) = (offset as usize / 2048, offset as usize % 2048);
        (page < P && at + len <= 2048).then_some((page, at))
    }
}

const OTHER: MemFlashError = MemFlashError(NorFlashErrorKind::Other);

impl<const P: usize> ErrorType for MemFlash<P> {
    type Error = MemFlashError;
}

impl<const P: usize> ReadNow for MemFlash<P> {
    fn read_now(&self, offset: u32, bytes: &mut [u8]) {
        for (i, b) in bytes.iter_mut().enumerate() {
            let o = offset as usize + i;
            *b = self.mem.get(o / 2048).map_or(0xFF, |p| p[o % 2048]);
        }
    }
}

impl<const P: usize> ReadNorFlash for MemFlash<P> {
    const READ_SIZE: usize = 1;
    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        let (page, at) = self
            .locate(offset, bytes.len())
            .ok_or(MemFlashError(NorFlashErrorKind::OutOfBounds))?;
        bytes.copy_from_slice(&self.mem[page][at..at + bytes.len()]);
        Ok(())
    }
    fn capacity(&self) -> usize {
        P * 2048
    }
}

impl<const P: usize> NorFlash for MemFlash<P> {
    const WRITE_SIZE: usize = 8;
    const ERASE_SIZE: usize = 2048;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        if self.dead {
            return Err(OTHER);
        }
        if !from.is_multiple_of(2048)
            || !to.is_multiple_of(2048)
            || to < from
            || to as usize > P * 2048
        {
            return Err(MemFlashError(NorFlashErrorKind::NotAligned));
        }
        for page in (from / 2048) as usize..(to / 2048) as usize {
            if self.budget == Some(self.written) {
                // Power lost during this erase: half of the page erased.
                self.mem[page][..1024].fill(0xFF);
                self.dead = true;
                return Err(OTHER);
            }
            self.mem[page].fill(0xFF);
            self.erases[page] += 1;
        }
        Ok(())
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        if self.dead {
            return Err(OTHER);
        }
        if !offset.is_multiple_of(8) || !bytes.len().is_multiple_of(8) {
            return Err(MemFlashError(NorFlashErrorKind::NotAligned));
        }
        let (page, at) = self
            .locate(offset, bytes.len())
            .ok_or(MemFlashError(NorFlashErrorKind::OutOfBounds))?;
        for (k, dw) in bytes.chunks_exact(8).enumerate() {
            let o = at + 8 * k;
            let cell = &self.mem[page][o..o + 8];
            // RM0440 PROGERR: a double word that is not erased may only be programmed with
            // all zeros.
            if cell.iter().any(|&b| b != 0xFF) && dw.iter().any(|&b| b != 0) {
                self.reprograms += 1;
                return Err(OTHER);
            }
            for (i, &b) in dw.iter().enumerate() {
                if self.budget == Some(self.written) {
                    self.dead = true;
                    self.torn = Some((page, o));
                    return Err(OTHER);
                }
                self.mem[page][o + i] &= b; // NOR programming only clears bits
                self.written += 1;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    //! The store and `sequential-storage`'s map (the crate the board would otherwise run), on
    //! the same flash, under the same tests.
    use super::*;
    use embassy_futures::block_on;

    /// Two pages, as the board's store region.
    type F = MemFlash<2>;

    /// The configuration as one `sequential-storage` map item (key 1) holding the registry's
    /// `(id, value)` entries: the same keying as [`Store`], over the crate's map.
    mod crate_map {
        use super::super::*;
        use sequential_storage::cache::{Cache, Uncached};
        use sequential_storage::map::{MapConfig, MapStorage, SerializationError, Value};

        const ITEM_BYTES: usize = 4 + 6 * PARAMS.len();
        pub const BUF: usize = (1 + ITEM_BYTES).div_ceil(8) * 8;
        pub type Map<S> = MapStorage<u8, S, Cache<Uncached, Uncached, Uncached, u8>>;

        pub fn map<S: NorFlash>(flash: S) -> Map<S> {
            MapStorage::new(
                flash,
                const { MapConfig::new(0..2 * PAGE) },
                Cache::new_uncached(),
            )
        }

        struct Item(Config, bool);
        impl<'a> Value<'a> for Item {
            fn serialize_into(&self, buf: &mut [u8]) -> Result<usize, SerializationError> {
                let b = buf
                    .get_mut(..ITEM_BYTES)
                    .ok_or(SerializationError::BufferTooSmall)?;
                b[..2].copy_from_slice(&1u16.to_le_bytes());
                b[2..4].copy_from_slice(&(PARAMS.len() as u16).to_le_bytes());
                for (p, e) in PARAMS.iter().zip(b[4..].chunks_exact_mut(6)) {
                    e[..2].copy_from_slice(&param_id(p.name).to_le_bytes());
                    e[2..].copy_from_slice(&p.get(&self.0).to_bits().to_le_bytes());
                }
                Ok(ITEM_BYTES)
            }
            fn deserialize_from(buf: &'a [u8]) -> Result<(Self, usize), SerializationError> {
                let n = buf.get(2..4).ok_or(SerializationError::InvalidFormat)?;
                let len = 4 + 6 * u16::from_le_bytes([n[0], n[1]]) as usize;
                let e = buf.get(4..len).ok_or(SerializationError::InvalidFormat)?;
                let (mut cfg, mut ok) = (Config::default(), true);
                for e in e.chunks_exact(6) {
                    let id = u16::from_le_bytes([e[0], e[1]]);
                    let v = f32::from_bits(u32::from_le_bytes([e[2], e[3], e[4], e[5]]));
                    if let Some(p) = PARAMS.iter().find(|p| param_id(p.name) == id) {
                        ok &= p.check(v).is_ok();
                        p.set(&mut cfg, v);
                    }
                }
                Ok((Item(cfg, ok), len))
            }
        }

        pub async fn load<S: NorFlash>(m: &mut Map<S>) -> (Config, Option<StoreFault>) {
            match m.fetch_item::<Item>(&mut [0; BUF], &1).await {
                Ok(Some(Item(c, true))) if c.validate().is_ok() => (c, None),
                Ok(Some(_)) => (Config::default(), Some(StoreFault::Invalid)),
                Ok(None) => (Config::default(), Some(StoreFault::Empty)),
                Err(_) => (Config::default(), Some(StoreFault::Empty)),
            }
        }

        pub async fn save<S: NorFlash>(m: &mut Map<S>, c: &Config) -> Result<(), &'static str> {
            m.store_item(&mut [0; BUF], &1, &Item(*c, true))
                .await
                .map_err(|_| "store failed")
        }
    }

    #[derive(Clone, Copy, Debug, PartialEq)]
    enum Kind {
        /// [`Store`], this module's append log.
        Log,
        /// `sequential-storage`'s map.
        Map,
    }
    const KINDS: [Kind; 2] = [Kind::Log, Kind::Map];

    fn cfg(r: f32) -> Config {
        Config {
            r_load_ohm: r,
            ..Config::default()
        }
    }

    fn boot(k: Kind, f: &F) -> (Config, Option<StoreFault>) {
        match k {
            Kind::Log => Store {
                flash: f.clone(),
                base: 0,
            }
            .load(),
            Kind::Map => block_on(crate_map::load(&mut crate_map::map(f.clone()))),
        }
    }

    fn save_on(k: Kind, f: F, c: &Config) -> (F, Result<(), &'static str>) {
        match k {
            Kind::Log => {
                let mut s = Store { flash: f, base: 0 };
                let r = block_on(s.save(c));
                (s.flash, r)
            }
            Kind::Map => {
                let mut m = crate_map::map(f);
                let r = block_on(crate_map::save(&mut m, c));
                (m.destroy().0, r)
            }
        }
    }

    #[test]
    fn param_ids_are_distinct() {
        for (i, a) in PARAMS.iter().enumerate() {
            for b in &PARAMS[i + 1..] {
                assert_ne!(param_id(a.name), param_id(b.name), "{} {}", a.name, b.name);
            }
        }
    }

    #[test]
    fn empty_corrupt_and_invalid_boot_to_defaults_with_fault() {
        for k in KINDS {
            let f = F::default();
            assert_eq!(boot(k, &f), (Config::default(), Some(StoreFault::Empty)));
            let (f, r) = save_on(k, f, &cfg(100.0));
            r.unwrap();
            assert_eq!(boot(k, &f), (cfg(100.0), None), "{k:?}");
            // One bit of the stored r_load_ohm cleared: the record's CRC fails, none older.
            let mut g = f.clone();
            let pat = 100.0f32.to_bits().to_le_bytes();
            let (p, i) = (0..2)
                .find_map(|p| g.mem[p].windows(4).position(|w| w == pat).map(|i| (p, i)))
                .expect("value in flash");
            g.mem[p][i + 3] &= !0x02;
            assert_eq!(boot(k, &g).1, Some(StoreFault::Empty), "{k:?}");
            // A value outside its registry range, stored whole: refused as invalid.
            let bad = Config {
                r_load_ohm: -5.0,
                ..Config::default()
            };
            let (h, r) = save_on(k, f, &bad);
            r.unwrap();
            assert_eq!(boot(k, &h), (Config::default(), Some(StoreFault::Invalid)));
        }
        // Garbage in both pages: empty, and a save starts clean.
        let mut g = F::default();
        for (p, page) in g.mem.iter_mut().enumerate() {
            for (i, b) in page.iter_mut().enumerate() {
                *b = ((i as u32)
                    .wrapping_mul(2_654_435_761)
                    .wrapping_add(p as u32 * 97)
                    >> 13) as u8;
            }
        }
        assert_eq!(boot(Kind::Log, &g).1, Some(StoreFault::Empty));
        let (g, r) = save_on(Kind::Log, g, &cfg(3.0));
        r.unwrap();
        assert_eq!(boot(Kind::Log, &g), (cfg(3.0), None));
    }

    /// The record format as `Store`'s docs state it, written here from those words: an entry
    /// the firmware does not know is skipped; one it lacks keeps its factory value.
    #[test]
    fn registry_changes_are_tolerated() {
        let r_load = PARAMS.iter().position(|p| p.name == "r_load_ohm").unwrap();
        let mut entries: std::vec::Vec<(u32, f32)> = PARAMS
            .iter()
            .map(|p| (param_id(p.name) as u32, p.get(&cfg(55.0))))
            .collect();
        entries[r_load].0 = 0xFFFF; // an entry this registry does not have
        entries.pop(); // and one missing (the last)
        let mut rec = std::vec::Vec::new();
        let le = |v: &mut std::vec::Vec<u8>, a: u32, b: u32| {
            v.extend_from_slice(&a.to_le_bytes());
            v.extend_from_slice(&b.to_le_bytes());
        };
        le(&mut rec, u32::from_le_bytes(*b"1PGR"), 1);
        let n = entries.len() as u32;
        le(&mut rec, n, !n);
        for (id, v) in &entries {
            le(&mut rec, *id, v.to_bits());
        }
        let crc = !crc32(!0, &rec);
        le(&mut rec, crc, 0xC0DE);
        let mut f = F::default();
        f.mem[0][..rec.len()].copy_from_slice(&rec);
        assert!(PARAMS.iter().all(|p| param_id(p.name) != 0xFFFF));
        // r_load_ohm and the last entry at their factory values, the rest as stored (here
        // the factory values too, so the whole is the default configuration).
        assert_eq!(boot(Kind::Log, &f), (Config::default(), None));
        // The same record with r_load_ohm's id: 55 Ω read.
        let mut g = F::default();
        let at = 16 + 8 * r_load;
        rec[at..at + 4].copy_from_slice(&(param_id("r_load_ohm") as u32).to_le_bytes());
        let body = rec.len() - 8;
        let crc = !crc32(!0, &rec[..body]);
        rec[body..body + 4].copy_from_slice(&crc.to_le_bytes());
        g.mem[1][..rec.len()].copy_from_slice(&rec);
        assert_eq!(boot(Kind::Log, &g), (cfg(55.0), None));
    }

    /// Cut the power after every byte written (and during every erase) of a save, after
    /// 0 … 7 earlier saves and for the first two saves that erase a page (so that cuts land
    /// in appends, page switches, migrations and erases); then boot: the old or the new
    /// configuration, never anything else, also when the double word the cut tore is zeroed
    /// (what the board does after an ECC error on it); and the store works after. Both stores.
    #[test]
    fn power_cut_after_every_byte_leaves_old_or_new() {
        for k in KINDS {
            let (cases, zeroed, saves) = power_cuts(k);
            std::println!(
                "{k:?}: {cases} power cuts over {saves} saves (2 of them erasing a page), \
                 {zeroed} inside a double word also zeroed: all old or new"
            );
            // Every byte a save writes is a cut, and a save writes at least 6 bytes per
            // parameter (the log a double word, the map's item 6 and its header); the first
            // 8 saves are all cut (fewer when the second erase comes sooner: then all of
            // them): a cut skipped anywhere leaves fewer.
            let cut = (saves as usize).min(8);
            assert!(
                cases >= cut * PARAMS.len() * 6 && zeroed > cases / 2,
                "{cases} {zeroed} {saves}"
            );
        }
    }

    fn power_cuts(k: Kind) -> (usize, usize, u32) {
        let mut base = F::default();
        let (mut cases, mut zeroed, mut erasing) = (0usize, 0usize, 0usize);
        let mut n_prev = 0u32;
        while erasing < 2 {
            assert!(n_prev < 100, "{k:?}: no page erased in {n_prev} saves");
            let old = boot(k, &base);
            let new = cfg(500.0 + n_prev as f32);
            let mut probe = base.clone();
            probe.written = 0;
            let (probe, r) = save_on(k, probe, &new);
            r.unwrap();
            let total = probe.written;
            let erases = probe.erases != base.erases;
            erasing += erases as usize;
            if n_prev < 8 || erases {
                for cut in 0..=total {
                    let mut f = base.clone();
                    f.written = 0;
                    f.budget = Some(cut);
                    let (mut f, r) = save_on(k, f, &new);
                    let dead = f.is_dead();
                    assert_eq!(r.is_ok(), !dead, "{k:?} n_prev {n_prev} cut {cut}");
                    f.power_on();
                    let b = boot(k, &f);
                    let why =
                        |b| std::format!("{k:?} n_prev {n_prev}: cut at {cut}/{total}: {b:?}");
                    if dead {
                        assert!(b == old || b == (new, None), "{}", why(b));
                        if let Some((p, o)) = f.torn {
                            let mut z = f.clone();
                            z.mem[p][o..o + 8].fill(0);
                            let bz = boot(k, &z);
                            assert!(bz == old || bz == (new, None), "zeroed {}", why(bz));
                            zeroed += 1;
                        }
                    } else {
                        assert_eq!(b, (new, None), "{}", why(b));
                    }
                    let (f, r) = save_on(k, f, &cfg(7.0));
                    assert!(
                        r.is_ok(),
                        "{k:?} n_prev {n_prev} cut {cut}: then save {r:?}"
                    );
                    assert_eq!(boot(k, &f), (cfg(7.0), None));
                    assert_eq!(f.reprograms, 0, "{k:?}");
                    cases += 1;
                }
            }
            base = save_on(k, base, &new).0;
            assert_eq!(boot(k, &base), (new, None));
            n_prev += 1;
        }
        (cases, zeroed, n_prev)
    }

    #[test]
    fn wear_alternates_pages() {
        let mut f = F::default();
        for i in 0..60 {
            f = save_on(Kind::Log, f, &cfg(1.0 + i as f32)).0;
            assert_eq!(boot(Kind::Log, &f).0, cfg(1.0 + i as f32));
        }
        // Records per page, then one erase per page filled, the pages alternating.
        let per = PAGE_DW / (PARAMS.len() + 3);
        assert!(f.erases[0].abs_diff(f.erases[1]) <= 1, "{:?}", f.erases);
        assert!(
            (f.erases[0] + f.erases[1]) as usize <= 60 / per + 1,
            "{:?}",
            f.erases
        );
    }
    /// The executor keeps running while a save waits on the flash: the watchdog feeder (the
    /// board's supervision task, every 10 ms) and a save run together on a virtual clock, the
    /// flash taking the G474's times (DS12288: page erase 22 ms typical, double-word program
    /// 82 µs). Awaited operations leave the feeder on time; the same save with every flash
    /// operation run to completion in place (as `block_on` did) holds it for an erase.
    #[test]
    fn watchdog_is_fed_during_saves() {
        for k in KINDS {
            let (async_gap, async_save) = feed_gaps(k, false);
            let (blocking_gap, blocking_save) = feed_gaps(k, true);
            std::println!(
                "{k:?}: longest save {:.1} ms; longest gap between watchdog feeds: awaited \
                 flash {:.3} ms, blocking flash {:.3} ms (feed period 10 ms)",
                async_save as f64 / 1e3,
                async_gap as f64 / 1e3,
                blocking_gap as f64 / 1e3
            );
            assert_eq!(async_save, blocking_save);
            assert!(
                async_save >= ERASE_US,
                "no save erased a page: {async_save} µs"
            );
            // Awaited: the feeder runs on its tick whatever the flash does.
            assert_eq!(async_gap, FEED_US);
            // Blocking: an erase holds the feeder (the model bites).
            assert!(blocking_gap >= ERASE_US, "{blocking_gap}");
        }
    }

    const FEED_US: u64 = 10_000;
    const ERASE_US: u64 = 22_000;
    const PROGRAM_US: u64 = 82;

    /// Virtual time (µs) and the earliest time a pending future asked to be woken at.
    struct Clock {
        now: core::cell::Cell<u64>,
        wake: core::cell::Cell<u64>,
    }

    struct Until<'a>(&'a Clock, u64);
    impl core::future::Future for Until<'_> {
        type Output = ();
        fn poll(
            self: core::pin::Pin<&mut Self>,
            _: &mut core::task::Context<'_>,
        ) -> core::task::Poll<()> {
            if self.0.now.get() >= self.1 {
                core::task::Poll::Ready(())
            } else {
                self.0.wake.set(self.0.wake.get().min(self.1));
                core::task::Poll::Pending
            }
        }
    }

    /// [`MemFlash`] whose operations take time: awaited on the clock, or (`blocking`) passed
    /// in place, the executor frozen meanwhile.
    struct Timed<'a> {
        f: F,
        clock: &'a Clock,
        blocking: bool,
    }
    impl Timed<'_> {
        async fn take(&self, us: u64) {
            let end = self.clock.now.get() + us;
            if self.blocking {
                self.clock.now.set(end);
            } else {
                Until(self.clock, end).await
            }
        }
    }
    impl ReadNow for Timed<'_> {
        fn read_now(&self, offset: u32, bytes: &mut [u8]) {
            self.f.read_now(offset, bytes)
        }
    }
    impl ErrorType for Timed<'_> {
        type Error = MemFlashError;
    }
    impl ReadNorFlash for Timed<'_> {
        const READ_SIZE: usize = 1;
        async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
            self.f.read(offset, bytes).await
        }
        fn capacity(&self) -> usize {
            self.f.capacity()
        }
    }
    impl NorFlash for Timed<'_> {
        const WRITE_SIZE: usize = 8;
        const ERASE_SIZE: usize = 2048;
        async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
            self.take(ERASE_US * u64::from((to - from) / 2048)).await;
            self.f.erase(from, to).await
        }
        async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
            self.take(PROGRAM_US * (bytes.len() / 8) as u64).await;
            self.f.write(offset, bytes).await
        }
    }

    /// 30 saves in a row (several page erases) beside a feeder, on store `k`; the longest gap
    /// between two feeds and the longest save, µs.
    fn feed_gaps(k: Kind, blocking: bool) -> (u64, u64) {
        use core::future::Future;
        use core::task::{Context, Poll, Waker};
        let clock = Clock {
            now: 0.into(),
            wake: u64::MAX.into(),
        };
        let stop = core::cell::Cell::new(false);
        let gap = core::cell::Cell::new(0u64);
        let longest = core::cell::Cell::new(0u64);
        let saves = async {
            let flash = Timed {
                f: F::default(),
                clock: &clock,
                blocking,
            };
            let mut log = Store { flash, base: 0 };
            let mut map = crate_map::map(Timed {
                f: F::default(),
                clock: &clock,
                blocking,
            });
            for i in 0..30 {
                let t0 = clock.now.get();
                let c = cfg(10.0 + i as f32);
                match k {
                    Kind::Log => log.save(&c).await.unwrap(),
                    Kind::Map => crate_map::save(&mut map, &c).await.unwrap(),
                }
                longest.set(longest.get().max(clock.now.get() - t0));
                // The console task awaits its next line between two saves.
                Until(&clock, clock.now.get() + 1_000).await;
            }
            let last = match k {
                Kind::Log => log.load(),
                Kind::Map => crate_map::load(&mut map).await,
            };
            assert_eq!(last, (cfg(39.0), None));
            stop.set(true);
        };
        let feeder = async {
            let mut last = 0;
            let mut tick = FEED_US;
            while !stop.get() {
                Until(&clock, tick).await;
                let now = clock.now.get();
                gap.set(gap.get().max(now - last));
                last = now;
                tick = now + FEED_US;
            }
            gap.set(gap.get().max(clock.now.get() - last));
        };
        let (mut a, mut b) = (core::pin::pin!(saves), core::pin::pin!(feeder));
        let mut cx = Context::from_waker(Waker::noop());
        let (mut a_done, mut b_done) = (false, false);
        while !(a_done && b_done) {
            clock.wake.set(u64::MAX);
            a_done = a_done || a.as_mut().poll(&mut cx) == Poll::Ready(());
            b_done = b_done || b.as_mut().poll(&mut cx) == Poll::Ready(());
            let w = clock.wake.get();
            if w != u64::MAX && !(a_done && b_done) {
                clock.now.set(clock.now.get().max(w));
            }
        }
        (gap.get(), longest.get())
    }
}
