//! `regen_fw::store::Flash` on the G474's internal flash: two 2 KiB pages at the end of bank 2.
//!
//! Word mapping. The store's model is a NOR flash of 32-bit words, each programmed once after
//! an erase. The G474 programs 64-bit double words, each once after an erase (8 ECC bits per
//! double word: a second program of the same double word is refused with PROGERR). So logical
//! word `i` of a page is the double word at byte `8·i`, programmed as `[v, !v]`: 256 logical
//! words per page (6 records of the 40-word layout). Reading returns `v` when the two halves
//! are complementary, `0xFFFF_FFFF` when the double word is erased, and `0` (which breaks the
//! record's CRC) otherwise. Writing a double word that is not erased is refused (the store then
//! reports a failed save; its records stay consistent, see `regen_fw::store`). Every program
//! and erase is verified by reading back.
//!
//! Stalls. Erase and program go through embassy's *interrupt-driven* flash driver, run to
//! completion with `block_on` in the console task: interrupts stay enabled (embassy's blocking
//! driver would hold a critical section for the whole 22–40 ms page erase, i.e. stop the current
//! loop for up to 800 periods). With the image in bank 1 and the store in bank 2 the flash is
//! read-while-write, so the current-loop interrupt keeps fetching code and constants during
//! an erase (the driver turns the flash data cache off meanwhile: constant loads take the
//! 4 wait states, the instruction cache and prefetch are unaffected). The thread-mode executor
//! is blocked for the save (≤ 45 ms): the watchdog timeout accounts for it (`board.rs`).
//! The core's console additionally refuses `save` in mode `run`.
//!
//! Torn double words. A power cut while a double word is being programmed can leave it with an
//! uncorrectable ECC error; the G474 raises an NMI when it is read, which would otherwise turn
//! every boot (the store scan reads the page) into a reset loop. The NMI handler
//! ([`note_ecc_and_reset`]) records FLASH_ECCR's bank and address in RAM that survives a reset
//! and resets; at the next boot [`recover_ecc`] erases the store page holding that address
//! before the scan. The records in that page are lost (the store then boots from the other
//! page's newest record, or defaults with the usual fault), not the drive.

use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;

use embassy_futures::block_on;
use embassy_stm32::flash::{Async, Bank2Region};
use embassy_stm32::pac;
use regen_fw::store::{Flash, PowerLost};

use crate::board::{STORE_PAGE_BYTES, STORE_PAGE_OFFSETS};

/// Absolute address of bank 2 (dual-bank mode).
const BANK2_BASE: u32 = 0x0804_0000;

pub struct BoardFlash {
    pub region: Bank2Region<'static, Async>,
}

impl BoardFlash {
    fn offset(&self, sector: usize, word: usize) -> Option<u32> {
        let page = *STORE_PAGE_OFFSETS.get(sector)?;
        (word < self.sector_words()).then_some(page + 8 * word as u32)
    }

    fn read_dw(&self, off: u32) -> (u32, u32) {
        let p = (BANK2_BASE + off) as *const u32;
        // SAFETY: `off` is inside one of the two store pages of bank 2 (checked by `offset`),
        // memory-mapped flash, aligned to 8 bytes.
        unsafe { (p.read_volatile(), p.add(1).read_volatile()) }
    }
}

impl Flash for BoardFlash {
    fn sector_words(&self) -> usize {
        (STORE_PAGE_BYTES / 8) as usize
    }

    fn read(&self, sector: usize, word: usize) -> u32 {
        let Some(off) = self.offset(sector, word) else {
            return !0;
        };
        match self.read_dw(off) {
            (lo, hi) if lo == !0 && hi == !0 => !0,
            (lo, hi) if hi == !lo => lo,
            _ => 0,
        }
    }

    fn write(&mut self, sector: usize, word: usize, v: u32) -> Result<(), PowerLost> {
        let off = self.offset(sector, word).ok_or(PowerLost)?;
        if self.read_dw(off) != (!0, !0) {
            return Err(PowerLost);
        }
        let mut b = [0u8; 8];
        b[..4].copy_from_slice(&v.to_le_bytes());
        b[4..].copy_from_slice(&(!v).to_le_bytes());
        block_on(self.region.write(off, &b)).map_err(|_| PowerLost)?;
        // Read back: the driver's interrupt clears the error flags before the waiting future
        // looks at them, so a failed program is caught here rather than trusted.
        if self.read_dw(off) != (v, !v) {
            return Err(PowerLost);
        }
        Ok(())
    }

    fn erase(&mut self, sector: usize) -> Result<(), PowerLost> {
        let page = *STORE_PAGE_OFFSETS.get(sector).ok_or(PowerLost)?;
        block_on(self.region.erase(page, page + STORE_PAGE_BYTES)).map_err(|_| PowerLost)?;
        // Verify the erase (same reason as the write read-back).
        let all_ones =
            (0..self.sector_words()).all(|w| self.read_dw(page + 8 * w as u32) == (!0, !0));
        if all_ones {
            Ok(())
        } else {
            Err(PowerLost)
        }
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

/// At boot, before the store is read: if the last reset came from an ECC error inside a store
/// page, erase that page. Returns the page erased.
pub fn recover_ecc(f: &mut BoardFlash) -> Option<usize> {
    // SAFETY: see `note_ecc_and_reset`; any bit pattern is a valid `[u32; 2]`.
    let note = unsafe {
        let p = addr_of_mut!(ECC_NOTE).cast::<[u32; 2]>();
        let n = p.read_volatile();
        p.write_volatile([0, 0]);
        n
    };
    if note[0] != ECC_MAGIC || note[1] >> 31 == 0 {
        return None;
    }
    // ADDR_ECC is the byte offset of the failing double word in its bank (RM0440 §3.7.9).
    let off = note[1] & 0x7_FFFF;
    let sector = STORE_PAGE_OFFSETS
        .iter()
        .position(|&p| (p..p + STORE_PAGE_BYTES).contains(&off))?;
    f.erase(sector).ok().map(|_| sector)
}
