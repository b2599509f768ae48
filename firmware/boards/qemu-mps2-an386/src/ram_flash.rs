//! Parameter storage for the QEMU board: a RAM region with NOR-flash rules that survives a soft reset.
//!
//! The emulated MPS2 has no programmable flash, so the parameter store lives in a RAM region placed
//! in cortex-m-rt's `.uninit` section, which the startup code neither loads nor zeroes: its contents
//! survive a soft reset (SYSRESETREQ, QEMU's `system_reset`) but not a power cycle (a new QEMU
//! process). A header word tells the two apart; on a cold start the region is erased to 0xFF, like
//! fresh flash. Writes follow NOR rules (a write can only clear bits; erase sets a whole sector to
//! 0xFF), so the firmware's two-slot store behaves as on a real board, whose implementation uses
//! the MCU's internal flash instead.

use core::mem::MaybeUninit;
use core::ptr::{addr_of_mut, read_volatile};
use core::sync::atomic::{AtomicBool, Ordering};

use embedded_storage::nor_flash::{
    check_erase, check_read, check_write, ErrorType, NorFlash, NorFlashErrorKind, ReadNorFlash,
};

/// Bytes of parameter storage: two store slots of one sector each.
pub const CAPACITY: usize = 2 * SLOT_SIZE;
/// Erase granularity, bytes.
pub const SECTOR_SIZE: usize = 1024;
/// Bytes of one parameter-store slot; a full parameter set with the store's header fits in one.
pub const SLOT_SIZE: usize = SECTOR_SIZE;

/// Header value meaning "the region has been initialised since the last power-on".
const WARM_MAGIC: u32 = 0x1A5C_F1A5;

#[repr(C)]
struct Retained {
    magic: u32,
    bytes: [u8; CAPACITY],
}

// Not zeroed or loaded by cortex-m-rt: this is what lets the contents survive a soft reset.
#[link_section = ".uninit.imucal_param_flash"]
static mut RETAINED: MaybeUninit<Retained> = MaybeUninit::uninit();

static TAKEN: AtomicBool = AtomicBool::new(false);

/// How the parameter storage was found at start-up.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum StartKind {
    /// First start since power-on: the storage was erased.
    Cold,
    /// Restart after a soft reset: the storage kept its contents.
    Warm,
}

/// RAM-backed NOR flash; see the module documentation.
#[derive(Debug)]
pub struct RamNorFlash {
    bytes: &'static mut [u8; CAPACITY],
}

impl RamNorFlash {
    /// Claims the retained region; `None` on every call after the first.
    pub fn take() -> Option<(Self, StartKind)> {
        if TAKEN.swap(true, Ordering::AcqRel) {
            return None;
        }
        // SAFETY: `TAKEN` guarantees this is the only reference to `RETAINED` ever created. The
        // region is uninitialised only in the language's sense: RAM always holds some bit pattern
        // (QEMU zeroes it at power-on, hardware leaves noise), and every bit pattern is a valid
        // `u32`/`[u8; N]`. The header is read volatile so the compiler cannot assume a value.
        let retained = unsafe {
            let region = &mut *addr_of_mut!(RETAINED);
            let magic = read_volatile(addr_of_mut!((*region.as_mut_ptr()).magic));
            let retained = region.assume_init_mut();
            (retained, magic == WARM_MAGIC)
        };
        let (region, warm) = retained;
        let kind = if warm {
            StartKind::Warm
        } else {
            region.bytes.fill(0xFF);
            region.magic = WARM_MAGIC;
            StartKind::Cold
        };
        Some((
            RamNorFlash {
                bytes: &mut region.bytes,
            },
            kind,
        ))
    }
}

impl ErrorType for RamNorFlash {
    type Error = NorFlashErrorKind;
}

impl ReadNorFlash for RamNorFlash {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        check_read(self, offset, bytes.len())?;
        let start = offset as usize;
        let src = self
            .bytes
            .get(start..start + bytes.len())
            .ok_or(NorFlashErrorKind::OutOfBounds)?;
        bytes.copy_from_slice(src);
        Ok(())
    }

    fn capacity(&self) -> usize {
        CAPACITY
    }
}

impl NorFlash for RamNorFlash {
    const WRITE_SIZE: usize = 4;
    const ERASE_SIZE: usize = SECTOR_SIZE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        check_erase(self, from, to)?;
        self.bytes
            .get_mut(from as usize..to as usize)
            .ok_or(NorFlashErrorKind::OutOfBounds)?
            .fill(0xFF);
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        check_write(self, offset, bytes.len())?;
        let start = offset as usize;
        let dst = self
            .bytes
            .get_mut(start..start + bytes.len())
            .ok_or(NorFlashErrorKind::OutOfBounds)?;
        // NOR programming can only clear bits.
        for (cell, &byte) in dst.iter_mut().zip(bytes) {
            *cell &= byte;
        }
        Ok(())
    }
}
