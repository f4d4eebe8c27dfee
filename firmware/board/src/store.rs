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
//! Known hardware-only risk: a double word torn by a power loss during its programming can
//! carry an uncorrectable ECC error, which the G474 reports as an NMI on read. Not handled
//! here (the NMI handler is cortex-m-rt's default); see docs/board.md.

use embassy_futures::block_on;
use embassy_stm32::flash::{Async, Bank2Region};
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
