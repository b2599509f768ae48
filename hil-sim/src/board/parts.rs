//! Hardware the firmware core owns but the simulation must also reach: the I²C bus to the emulated
//! LSM9DS1 (the world sets what the chip senses), the parameter flash (power cuts, reboots) and the
//! microsecond timer (simulated time). Each is a cheap handle to state shared with the board.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use embedded_hal::i2c::{ErrorType as I2cErrorType, I2c, Operation};
use embedded_storage::nor_flash::{ErrorType, NorFlash, NorFlashErrorKind, ReadNorFlash};
use imucal_firmware::device::Clock;
use imucal_firmware::ram_flash::RamFlash;

use crate::lsm9ds1_chip::{Lsm9ds1Chip, Lsm9ds1ChipError};

/// Flash size of the simulated board: two 4 KiB sectors, one per parameter slot.
pub const FLASH_SIZE: usize = 8192;
/// Erase sector of the simulated flash (the nRF52840's 4 KiB page).
pub const FLASH_SECTOR: usize = 4096;
/// Program word of the simulated flash (the nRF52840 writes 32-bit words).
pub const FLASH_WORD: usize = 4;
/// The RAM flash behind the board's parameter store.
pub type BoardFlash = RamFlash<FLASH_SIZE, FLASH_SECTOR, FLASH_WORD>;

fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    // Every update below is a single assignment or a whole flash operation, so a panic elsewhere
    // leaves nothing half-changed.
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The I²C bus with the emulated chip on it.
#[derive(Debug, Clone)]
pub struct SharedChip(Arc<Mutex<Lsm9ds1Chip>>);

impl SharedChip {
    /// A bus with `chip` on it.
    pub fn new(chip: Lsm9ds1Chip) -> Self {
        Self(Arc::new(Mutex::new(chip)))
    }

    /// Run `f` on the chip (to set its physical inputs or read its registers).
    pub fn with<R>(&self, f: impl FnOnce(&mut Lsm9ds1Chip) -> R) -> R {
        f(&mut lock(&self.0))
    }
}

impl I2cErrorType for SharedChip {
    type Error = Lsm9ds1ChipError;
}

impl I2c for SharedChip {
    fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        lock(&self.0).transaction(address, operations)
    }
}

/// The parameter flash, shared so that a power cut can be scheduled while the firmware owns it.
#[derive(Debug, Clone)]
pub struct SharedFlash(Arc<Mutex<BoardFlash>>);

impl SharedFlash {
    /// An erased flash.
    pub fn new() -> Self {
        Self(Arc::new(Mutex::new(BoardFlash::new())))
    }

    /// Run `f` on the flash.
    pub fn with<R>(&self, f: impl FnOnce(&mut BoardFlash) -> R) -> R {
        f(&mut lock(&self.0))
    }
}

impl Default for SharedFlash {
    fn default() -> Self {
        Self::new()
    }
}

impl ErrorType for SharedFlash {
    type Error = NorFlashErrorKind;
}

impl ReadNorFlash for SharedFlash {
    const READ_SIZE: usize = BoardFlash::READ_SIZE;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        lock(&self.0).read(offset, bytes)
    }

    fn capacity(&self) -> usize {
        FLASH_SIZE
    }
}

impl NorFlash for SharedFlash {
    const WRITE_SIZE: usize = FLASH_WORD;
    const ERASE_SIZE: usize = FLASH_SECTOR;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        lock(&self.0).erase(from, to)
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        lock(&self.0).write(offset, bytes)
    }
}

/// The firmware's microsecond timer, showing simulated time.
#[derive(Debug, Clone, Default)]
pub struct SimClock(Arc<AtomicU64>);

impl SimClock {
    /// Set simulated time, µs; never moves backwards.
    pub fn set_us(&self, t_us: u64) {
        self.0.fetch_max(t_us, Ordering::Relaxed);
    }

    /// Simulated time, µs.
    pub fn get_us(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }
}

impl Clock for SimClock {
    fn now_us(&mut self) -> u64 {
        self.get_us()
    }
}
