//! Persistent parameter store: the configuration as one item of a `sequential-storage` map.
//!
//! The map (`sequential_storage::map::MapStorage`, over any `embedded-storage-async`
//! [`NorFlash`]) gives CRC-checked items, power-fail-safe replacement of an item by a newer one
//! with the same key, wear levelling over its pages and repair after an interrupted operation.
//! On the board it runs over embassy-stm32's interrupt-driven flash (`Bank2Region<Async>`,
//! 8-byte writes), awaited in the console's task: a page erase no longer blocks the executor.
//!
//! Keyed by the parameter registry: the configuration is stored under [`CONFIG_KEY`] as the
//! list of the registry's entries, each as `(id, value)` with `id` = [`param_id`] of the
//! entry's name (a 16-bit hash, distinct over the registry: tested) and the value's `f32` bits.
//! A firmware whose registry gained an entry loads the entries it finds and keeps the factory
//! value for the new one; an entry the firmware no longer has is skipped. Every value read is
//! checked against its registry range and the whole against [`Config::validate`].
//!
//! Old or new, never a mix: the whole configuration is one item, written with its CRC after the
//! previous one; a save cut at any byte leaves the previous item as the newest valid one, a
//! completed save makes the new one newest (tested by cutting power after every byte written,
//! over many saves in a row, `tests` below).
//!
//! The parameter-store tests exercise the map on [`MemFlash`], a RAM NOR flash with the G474's
//! geometry (8-byte write granule programmed once per erase, 2 KiB pages) and a power-cut
//! budget counted in bytes; the simulated drive (`hal-sim`) uses it as its flash.

use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};
use sequential_storage::cache::{Cache, Uncached};
pub use sequential_storage::map::MapConfig;
use sequential_storage::map::{MapStorage, SerializationError, Value};

use crate::config::Config;
use crate::params::PARAMS;

/// The map key of the configuration item.
pub const CONFIG_KEY: u8 = 1;
/// Item format (first half-word of the value); a different format is not read.
const FORMAT: u16 = 1;
/// Bytes of one registry entry in the item: id (u16) and value (f32), little-endian.
const ENTRY: usize = 6;
/// Bytes of the configuration item's value.
pub const ITEM_BYTES: usize = 4 + ENTRY * PARAMS.len();
/// The data buffer the map needs: key (1 byte) and value, rounded up to the 8-byte granule.
pub const BUF_BYTES: usize = (1 + ITEM_BYTES).div_ceil(8) * 8;
const _: () = assert!(BUF_BYTES > ITEM_BYTES && BUF_BYTES.is_multiple_of(8));

/// The map the store runs on.
pub type Map<S> = MapStorage<u8, S, Cache<Uncached, Uncached, Uncached, u8>>;

/// The map over a region of `flash` (`region` page aligned, at least two pages: build it as
/// `const { MapConfig::new(range) }` and a bad range is a compile error).
pub const fn map<S: NorFlash>(flash: S, region: MapConfig<S>) -> Map<S> {
    MapStorage::new(flash, region, Cache::new_uncached())
}

/// Why boot fell back to defaults.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StoreFault {
    /// No configuration item (blank flash, or none that reads back whole).
    Empty,
    /// The newest item reads back whole but a value is outside its registry range or the
    /// configuration fails `Config::validate`.
    Invalid,
    /// The flash could not be read, or the map is corrupt beyond the crate's repair.
    Unreadable,
}

impl StoreFault {
    pub fn message(self) -> &'static str {
        match self {
            StoreFault::Empty => "store empty",
            StoreFault::Invalid => "stored parameters invalid",
            StoreFault::Unreadable => "store unreadable",
        }
    }
}

/// A registry entry's key in the stored item: FNV-1a (32 bit) of its name, folded to 16 bits.
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

/// The configuration item's value: the configuration read back, and whether every stored
/// value passed its registry range.
struct Item {
    cfg: Config,
    in_range: bool,
}

impl<'a> Value<'a> for Item {
    fn serialize_into(&self, buf: &mut [u8]) -> Result<usize, SerializationError> {
        let b = buf
            .get_mut(..ITEM_BYTES)
            .ok_or(SerializationError::BufferTooSmall)?;
        b[..2].copy_from_slice(&FORMAT.to_le_bytes());
        b[2..4].copy_from_slice(&(PARAMS.len() as u16).to_le_bytes());
        for (p, e) in PARAMS.iter().zip(b[4..].chunks_exact_mut(ENTRY)) {
            e[..2].copy_from_slice(&param_id(p.name).to_le_bytes());
            e[2..].copy_from_slice(&(p.get)(&self.cfg).to_bits().to_le_bytes());
        }
        Ok(ITEM_BYTES)
    }

    fn deserialize_from(buf: &'a [u8]) -> Result<(Self, usize), SerializationError> {
        let word = |i: usize| buf.get(i..i + 2).map(|s| u16::from_le_bytes([s[0], s[1]]));
        let (Some(FORMAT), Some(n)) = (word(0), word(2)) else {
            return Err(SerializationError::InvalidFormat);
        };
        let len = 4 + ENTRY * n as usize;
        let entries = buf.get(4..len).ok_or(SerializationError::InvalidFormat)?;
        let mut cfg = Config::default();
        let mut in_range = true;
        for e in entries.chunks_exact(ENTRY) {
            let id = u16::from_le_bytes([e[0], e[1]]);
            let v = f32::from_bits(u32::from_le_bytes([e[2], e[3], e[4], e[5]]));
            if let Some(p) = PARAMS.iter().find(|p| param_id(p.name) == id) {
                in_range &= p.check(v).is_ok();
                (p.set)(&mut cfg, v);
            }
        }
        Ok((Item { cfg, in_range }, len))
    }
}

/// Read the configuration at boot: the newest stored one, or `Config::default()` and the
/// reason.
pub async fn load<S: NorFlash>(
    m: &mut Map<S>,
    buf: &mut [u8; BUF_BYTES],
) -> (Config, Option<StoreFault>) {
    match m.fetch_item::<Item>(buf, &CONFIG_KEY).await {
        Ok(Some(it)) if it.in_range && it.cfg.validate().is_ok() => (it.cfg, None),
        Ok(Some(_)) | Err(sequential_storage::Error::SerializationError(_)) => {
            (Config::default(), Some(StoreFault::Invalid))
        }
        Ok(None) => (Config::default(), Some(StoreFault::Empty)),
        Err(_) => (Config::default(), Some(StoreFault::Unreadable)),
    }
}

/// Store `cfg` as the newest configuration.
pub async fn save<S: NorFlash>(
    m: &mut Map<S>,
    buf: &mut [u8; BUF_BYTES],
    cfg: &Config,
) -> Result<(), &'static str> {
    let item = Item {
        cfg: *cfg,
        in_range: true,
    };
    m.store_item(buf, &CONFIG_KEY, &item)
        .await
        .map_err(|e| match e {
            sequential_storage::Error::Storage { .. } => "flash write failed",
            sequential_storage::Error::FullStorage => "store full",
            _ => "store corrupt",
        })
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
    use super::*;
    use embassy_futures::block_on;

    /// Four pages, as the board's store region.
    type F = MemFlash<4>;
    const RANGE: core::ops::Range<u32> = 0..4 * 2048;

    fn cfg(r: f32) -> Config {
        Config {
            r_load_ohm: r,
            ..Config::default()
        }
    }

    fn boot(f: &F) -> (Config, Option<StoreFault>) {
        let mut m = map(f.clone(), const { MapConfig::new(RANGE) });
        block_on(load(&mut m, &mut [0; BUF_BYTES]))
    }

    fn save_on(f: F, c: &Config) -> (F, Result<(), &'static str>) {
        let mut m = map(f, const { MapConfig::new(RANGE) });
        let r = block_on(save(&mut m, &mut [0; BUF_BYTES], c));
        (m.destroy().0, r)
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
        let f = F::default();
        assert_eq!(boot(&f), (Config::default(), Some(StoreFault::Empty)));
        let (f, r) = save_on(f, &cfg(100.0));
        r.unwrap();
        assert_eq!(boot(&f), (cfg(100.0), None));
        // One bit of the stored r_load_ohm flipped: the item's CRC fails, nothing newer.
        let mut g = f.clone();
        let pos = find(&g, &100.0f32.to_bits().to_le_bytes()).expect("value in flash");
        g.mem[pos.0][pos.1] ^= 0x01;
        assert_ne!(boot(&g).0, cfg(100.0));
        assert!(boot(&g).1.is_some());
        // A value outside its registry range, stored whole: refused as invalid.
        let bad = Config {
            r_load_ohm: -5.0,
            ..Config::default()
        };
        let (h, r) = save_on(f, &bad);
        r.unwrap();
        assert_eq!(boot(&h), (Config::default(), Some(StoreFault::Invalid)));
    }

    fn find(f: &F, pat: &[u8]) -> Option<(usize, usize)> {
        (0..4).find_map(|p| {
            f.mem[p]
                .windows(pat.len())
                .position(|w| w == pat)
                .map(|i| (p, i))
        })
    }

    /// An entry the firmware does not know is skipped; one it lacks keeps its factory value.
    #[test]
    fn registry_changes_are_tolerated() {
        let stored = Config {
            r_load_ohm: 55.0,
            ..Config::default()
        };
        let mut item = [0u8; ITEM_BYTES];
        let n = Item {
            cfg: stored,
            in_range: true,
        }
        .serialize_into(&mut item)
        .unwrap();
        assert_eq!(n, ITEM_BYTES);
        // The r_load_ohm entry's id replaced by one no registry entry has: skipped, so the
        // configuration read keeps the factory value there.
        let i = PARAMS.iter().position(|p| p.name == "r_load_ohm").unwrap();
        let at = 4 + ENTRY * i;
        let mut unknown = item;
        unknown[at..at + 2].copy_from_slice(&0xFFFFu16.to_le_bytes());
        assert!(PARAMS.iter().all(|p| param_id(p.name) != 0xFFFF));
        let (it, used) = Item::deserialize_from(&unknown).unwrap();
        assert_eq!((it.cfg, it.in_range, used), (Config::default(), true, n));
        // An item written by a firmware with one entry fewer (the last): the rest is read.
        let mut short = item;
        short[2..4].copy_from_slice(&(PARAMS.len() as u16 - 1).to_le_bytes());
        let (it, used) = Item::deserialize_from(&short[..n - ENTRY]).unwrap();
        let mut want = stored;
        let last = &PARAMS[PARAMS.len() - 1];
        (last.set)(&mut want, (last.get)(&Config::default()));
        assert_eq!((it.cfg, used), (want, n - ENTRY));
        // Another format: not read.
        let mut other = item;
        other[0] = 9;
        assert!(Item::deserialize_from(&other).is_err());
        assert!(Item::deserialize_from(&item[..3]).is_err());
        assert!(Item::deserialize_from(&item[..n - 1]).is_err());
    }

    /// Cut the power after every byte written (and during every erase) of a save, after
    /// 0 … 7 earlier saves and before the first two saves that erase a page (so that cuts land
    /// in appends, page switches, migrations and erases); then
    /// boot: the old or the new configuration, never anything else; the store works after.
    #[test]
    fn power_cut_after_every_byte_leaves_old_or_new() {
        let mut base = F::default();
        let (mut cases, mut zeroed, mut erasing) = (0usize, 0usize, 0usize);
        let mut n_prev = 0u32;
        while erasing < 2 {
            assert!(n_prev < 100, "no page erased in {n_prev} saves");
            let old = boot(&base);
            let new = cfg(500.0 + n_prev as f32);
            // Bytes of an uninterrupted save, and whether it erases a page.
            let mut probe = base.clone();
            probe.written = 0;
            let (probe, r) = save_on(probe, &new);
            r.unwrap();
            let total = probe.written;
            assert!(total >= ITEM_BYTES, "{total}");
            let erases = probe.erases != base.erases;
            erasing += erases as usize;
            // Every save of the first eight (appends, the first page switches), then the ones
            // that migrate and erase.
            if n_prev >= 8 && !erases {
                base = save_on(base, &new).0;
                n_prev += 1;
                continue;
            }
            for k in 0..=total {
                let mut f = base.clone();
                f.written = 0;
                f.budget = Some(k);
                let (mut f, r) = save_on(f, &new);
                let cut = f.is_dead();
                assert_eq!(r.is_ok(), !cut, "n_prev {n_prev} k {k}");
                f.power_on();
                let b = boot(&f);
                if cut {
                    assert!(
                        b == old || b == (new, None),
                        "n_prev {n_prev}: cut after {k} of {total} bytes: {b:?}"
                    );
                    // On the G474 a double word cut part way may read with an ECC error;
                    // the board then zeroes it at boot (`board/src/store.rs`): old or new too.
                    if let Some((p, o)) = f.torn {
                        let mut z = f.clone();
                        z.mem[p][o..o + 8].fill(0);
                        let bz = boot(&z);
                        assert!(
                            bz == old || bz == (new, None),
                            "n_prev {n_prev}: cut after {k} of {total} bytes, zeroed: {bz:?}"
                        );
                        zeroed += 1;
                    }
                } else {
                    assert_eq!(b, (new, None), "n_prev {n_prev} k {k}");
                }
                // The store still works after the cut, and never reprograms a double word.
                let (f, r) = save_on(f, &cfg(7.0));
                assert!(
                    r.is_ok(),
                    "n_prev {n_prev} k {k}/{total}: save after the cut: {r:?}, reprograms {}",
                    f.reprograms
                );
                assert_eq!(boot(&f), (cfg(7.0), None));
                assert_eq!(f.reprograms, 0);
                cases += 1;
            }
            base = save_on(base, &new).0;
            assert_eq!(boot(&base), (new, None));
            n_prev += 1;
        }
        std::println!(
            "{cases} power cuts over {n_prev} saves ({erasing} erasing a page), {zeroed} inside \
             a double word also zeroed"
        );
        assert!(
            cases >= 10 * ITEM_BYTES && zeroed > cases / 2,
            "{cases} {zeroed}"
        );
    }

    #[test]
    fn wear_is_spread_over_the_pages() {
        let mut f = F::default();
        for i in 0..200 {
            f = save_on(f, &cfg(1.0 + i as f32)).0;
            assert_eq!(boot(&f).0, cfg(1.0 + i as f32));
        }
        let (lo, hi) = (
            f.erases.iter().min().unwrap(),
            f.erases.iter().max().unwrap(),
        );
        assert!(hi - lo <= 1, "{:?}", f.erases);
        // Items per page: (2048 − page markers) / item; erases ≈ saves / items per page.
        let per_page = 2048 / (ITEM_BYTES + 16);
        let total: u32 = f.erases.iter().sum();
        assert!(total as usize <= 200 / (per_page - 1) + 4, "{:?}", f.erases);
    }

    /// The executor keeps running while a save waits on the flash: the watchdog feeder (the
    /// board's supervision task, every 10 ms) and a save run together on a virtual clock, the
    /// flash taking the G474's times (DS12288: page erase 22 ms typical, double-word program
    /// 82 µs). Awaited operations leave the feeder on time; the same save with every flash
    /// operation run to completion in place (as `block_on` did) holds it for an erase.
    #[test]
    fn watchdog_is_fed_during_saves() {
        let (async_gap, async_save) = feed_gaps(false);
        let (blocking_gap, blocking_save) = feed_gaps(true);
        std::println!(
            "longest save {:.1} ms; longest gap between watchdog feeds: awaited flash {:.3} ms, \
             blocking flash {:.3} ms (feed period 10 ms)",
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

    /// 30 saves in a row (several page erases) beside a feeder; the longest gap between two
    /// feeds and the longest save, µs.
    fn feed_gaps(blocking: bool) -> (u64, u64) {
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
            let mut m = map(flash, const { MapConfig::new(RANGE) });
            let mut buf = [0; BUF_BYTES];
            for i in 0..30 {
                let t0 = clock.now.get();
                save(&mut m, &mut buf, &cfg(10.0 + i as f32)).await.unwrap();
                longest.set(longest.get().max(clock.now.get() - t0));
                // The console task awaits its next line between two saves.
                Until(&clock, clock.now.get() + 1_000).await;
            }
            assert_eq!(load(&mut m, &mut buf).await, (cfg(39.0), None));
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
