//! The parameter store on the G474: `regen_fw::store` (an append log of records) over the last
//! two 2 KiB pages of flash bank 2, through embassy-stm32's interrupt-driven flash
//! (`Bank2Region<Async>`, 8-byte double-word writes), awaited in the console's task.
//!
//! Stalls. Erases and programs are awaited: while a page erase runs (22 ms typical, 40 ms worst
//! case, DS12288) the executor runs the other tasks, the supervision task's watchdog feed among
//! them (host test `regen_fw::store::tests::watchdog_is_fed_during_saves`). With the image in
//! bank 1 and the store in bank 2 the flash is read-while-write, so the current-loop interrupt
//! keeps fetching code and constants meanwhile (embassy turns the data cache off during the
//! operation: constant loads take the 4 wait states). The core's console refuses `save` in
//! mode `run`.
//!
//! Torn double words. A power cut while a double word is being programmed can leave it with an
//! uncorrectable ECC error; the G474 raises an NMI when it is read, which would otherwise turn
//! every boot (the store scans its pages) into a reset loop. The NMI handler
//! ([`note_ecc_and_reset`]) records FLASH_ECCR's bank and address in RAM that survives a reset
//! and resets; at the next boot [`recover_ecc`] programs that double word to zero (the one value
//! the G474 accepts over a programmed double word, RM0440 PROGERR; its ECC is then consistent).
//! The store reads the zeroed word as part of a torn record and skips it, as it skips a record
//! cut part way (host test `regen_fw::store::tests::power_cut_after_every_byte_leaves_old_or_new`):
//! the previous configuration stays the newest valid one.

use core::mem::MaybeUninit;
use core::ops::Range;
use core::ptr::addr_of_mut;

use embassy_stm32::flash::{Async, Bank2Region};
use embassy_stm32::pac;
use embedded_storage_async::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
use regen_fw::console::{ParamStore, Saved};
use regen_fw::store::{ReadNow, Store, StoreFault, PAGE};
use regen_fw::Config;

/// The store's region, as offsets into embassy's `Bank2Region` (bank 2 starts at
/// 0x0804_0000 in dual-bank mode, DBANK = 1, the factory option): its last two 2 KiB pages,
/// 0x0807_F000 … 0x0807_FFFF. The image (< 64 KiB) lies entirely in bank 1.
pub const STORE_RANGE: Range<u32> = 0x4_0000 - 2 * PAGE..0x4_0000;

/// Absolute address of bank 2 (dual-bank mode).
const BANK2_BASE: u32 = 0x0804_0000;

/// Bank 2 through embassy's async driver, read straight from the memory map.
pub struct BoardFlash(pub Bank2Region<'static, Async>);

impl ReadNow for BoardFlash {
    fn read_now(&self, offset: u32, bytes: &mut [u8]) {
        for (i, b) in bytes.iter_mut().enumerate() {
            let off = offset + i as u32;
            *b = if off < 0x4_0000 {
                // SAFETY: inside bank 2, memory-mapped flash.
                unsafe { ((BANK2_BASE + off) as *const u8).read_volatile() }
            } else {
                0xFF
            };
        }
    }
}

impl ErrorType for BoardFlash {
    type Error = embassy_stm32::flash::Error;
}

impl ReadNorFlash for BoardFlash {
    const READ_SIZE: usize = 1;
    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        self.read_now(offset, bytes);
        Ok(())
    }
    fn capacity(&self) -> usize {
        0x4_0000
    }
}

impl NorFlash for BoardFlash {
    const WRITE_SIZE: usize = 8;
    const ERASE_SIZE: usize = PAGE as usize;
    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        self.0.write(offset, bytes).await
    }
    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        self.0.erase(from, to).await
    }
}

/// The store as the console task holds it.
///
/// The two configurations (what the flash holds, what a `save` asked for) are plain fields,
/// exchanged by `swap` after a successful write: moving a `Config` out of an `Option` and into
/// a `Result` across the save's await made the compiler copy it through the task's state with
/// `memmove` (1.6 KB of flash for that routine alone).
pub struct BoardStore {
    pub store: Store<BoardFlash>,
    /// What the flash holds (read at boot, replaced by each successful save): `load` returns
    /// it without reading the flash again; the store is the flash's only writer. Meaningful
    /// when `fault` is `None`.
    pub held: Config,
    /// Why the flash holds no configuration (`None`: `held` is it).
    pub fault: Option<StoreFault>,
    /// A `save` taken by [`ParamStore::save`] (when `requested`), written by the task
    /// ([`BoardStore::finish`]).
    request: Config,
    requested: bool,
}

impl BoardStore {
    /// Open the store over `region` and read the configuration it holds (after recovering a
    /// torn double word, if the last reset came from one).
    pub async fn open(mut region: Bank2Region<'static, Async>) -> (BoardStore, bool) {
        let recovered = recover_ecc(&mut region).await;
        let store = Store {
            flash: BoardFlash(region),
            base: STORE_RANGE.start,
        };
        let (held, fault) = store.load();
        let s = BoardStore {
            store,
            held,
            fault,
            request: held,
            requested: false,
        };
        (s, recovered)
    }

    /// Write the pending `save`, if any; its result.
    pub async fn finish(&mut self) -> Option<Result<(), &'static str>> {
        if !core::mem::take(&mut self.requested) {
            return None;
        }
        let r = self.store.save(&self.request).await;
        if r.is_ok() {
            core::mem::swap(&mut self.held, &mut self.request);
            self.fault = None;
        }
        Some(r)
    }
}

impl ParamStore for BoardStore {
    fn save(&mut self, cfg: &Config) -> Result<Saved, &'static str> {
        self.request = *cfg;
        self.requested = true;
        Ok(Saved::Deferred)
    }
    fn load(&mut self) -> Result<Config, &'static str> {
        match self.fault {
            None => Ok(self.held),
            Some(f) => Err(f.message()),
        }
    }
    fn held(&self) -> Option<Config> {
        self.fault.is_none().then_some(self.held)
    }
}

const ECC_MAGIC: u32 = 0xECC0_5AFE;

/// `[ECC_MAGIC, bank2 << 31 | byte offset in bank]`, kept across a reset (`.uninit` is not
/// initialised by the start-up code).
#[link_section = ".uninit.regen_ecc"]
static mut ECC_NOTE: MaybeUninit<[u32; 2]> = MaybeUninit::uninit();

/// From the NMI handler: note a flash double-ECC error, then reset.
pub fn note_ecc_and_reset() -> ! {
    let e = pac::FLASH.eccr().read();
    if e.eccd() {
        let where_ = e.addr_ecc() | if e.bk_ecc() { 1 << 31 } else { 0 };
        // SAFETY: single word-aligned volatile store to a static only this function and
        // `recover_ecc` (at boot, before interrupts run) touch.
        unsafe {
            addr_of_mut!(ECC_NOTE)
                .cast::<[u32; 2]>()
                .write_volatile([ECC_MAGIC, where_])
        };
        pac::FLASH.eccr().modify(|w| w.set_eccd(true)); // write 1 to clear
    }
    cortex_m::peripheral::SCB::sys_reset()
}

/// At boot, before the store is read: if the last reset came from an ECC error inside the
/// store's region, program that double word to zero. Whether one was.
async fn recover_ecc(region: &mut Bank2Region<'static, Async>) -> bool {
    // SAFETY: see `note_ecc_and_reset`; any bit pattern is a valid `[u32; 2]`.
    let note = unsafe {
        let p = addr_of_mut!(ECC_NOTE).cast::<[u32; 2]>();
        let n = p.read_volatile();
        p.write_volatile([0, 0]);
        n
    };
    if note[0] != ECC_MAGIC || note[1] >> 31 == 0 {
        return false;
    }
    // ADDR_ECC is the byte offset of the failing double word in its bank (RM0440 §3.7.9).
    let off = note[1] & 0x7_FFF8;
    if !STORE_RANGE.contains(&off) {
        return false;
    }
    // The note's offset is relative to bank 2's start, as the region's offsets are.
    region.write(off, &[0; 8]).await.is_ok()
}
