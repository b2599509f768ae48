//! The parameter store's flash: two 4 KiB pages at the top of the nRF52840's flash.
//!
//! The region is reserved in both memory layouts (`PARAMS`, 0xFE000..0x100000, in
//! `memory-bootloader.x` and `memory-no-bootloader.x`) and exported to the program as the linker
//! symbols `_imucal_params_start` / `_imucal_params_end`; nothing is linked into it,
//! so flashing a new firmware keeps the stored calibration. The HAL's NVMC driver provides the
//! embedded-storage `NorFlash` implementation (4 KiB erase pages, 4-byte word writes), which is
//! what the firmware core's two-slot store needs.

use core::sync::atomic::{AtomicBool, Ordering};

use nrf52840_hal::nvmc::Nvmc;
use nrf52840_hal::pac::NVMC;

/// Erase page of the nRF52840's flash, bytes (product specification, NVMC chapter).
pub const PAGE_SIZE: usize = 4096;
/// Bytes of one parameter-store slot: one page.
pub const SLOT_SIZE: usize = PAGE_SIZE;

/// The parameter flash as the core's store sees it.
pub type ParamFlash = Nvmc<NVMC>;

/// Why the parameter flash could not be opened.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum ParamFlashError {
    /// The region was handed out already; it is taken once, at start-up.
    AlreadyTaken,
    /// The linker region is not two whole, page-aligned pages: fix `PARAMS` in the memory layout.
    BadRegion {
        /// Start address given by the linker.
        start: usize,
        /// Length in bytes given by the linker.
        len: usize,
    },
}

impl core::fmt::Display for ParamFlashError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::AlreadyTaken => write!(
                f,
                "the parameter flash was already taken; open it once at start-up and pass it on"
            ),
            Self::BadRegion { start, len } => write!(
                f,
                "the PARAMS region at {start:#x} ({len} bytes) is not two page-aligned 4 KiB \
                 pages; fix PARAMS in the memory layout (memory-*.x)"
            ),
        }
    }
}

static TAKEN: AtomicBool = AtomicBool::new(false);

extern "C" {
    static _imucal_params_start: u8;
    static _imucal_params_end: u8;
}

/// The reserved region as the HAL's flash driver; fails on a second call or a bad linker region.
pub fn take(nvmc: NVMC) -> Result<ParamFlash, ParamFlashError> {
    if TAKEN.swap(true, Ordering::AcqRel) {
        return Err(ParamFlashError::AlreadyTaken);
    }
    let start = core::ptr::addr_of!(_imucal_params_start) as usize;
    let end = core::ptr::addr_of!(_imucal_params_end) as usize;
    let len = end.wrapping_sub(start);
    // The HAL asserts page alignment; checking here turns that panic into an error.
    if end < start || len != 2 * SLOT_SIZE || !start.is_multiple_of(PAGE_SIZE) {
        return Err(ParamFlashError::BadRegion { start, len });
    }
    #[allow(unsafe_code)]
    // SAFETY: `start..end` is the PARAMS region of the memory layout: readable flash that no
    // section is linked into, so no other Rust object lives there. `TAKEN` makes this the only
    // reference ever created to it. The flash only changes through the returned NVMC driver,
    // which owns the NVMC peripheral, so the `&mut` is never aliased by another writer.
    let storage = unsafe { core::slice::from_raw_parts_mut(start as *mut u8, len) };
    Ok(Nvmc::new(nvmc, storage))
}
