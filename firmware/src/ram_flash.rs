//! A NOR flash in RAM with power-cut injection, for tests and the simulated board.
//!
//! Behaves like NOR: erase sets a whole sector to `0xFF`, a write can only clear bits
//! (`old & new`). Every sector erase and every `WRITE`-byte word written is one *step*; a power cut
//! can be scheduled at any step, which then lands half-done (half the sector erased, or only the
//! high nibble of each byte of the word programmed) and every later operation fails until power is
//! restored. This reproduces a torn write at the finest granularity a real part has.

use embedded_storage::nor_flash::{ErrorType, NorFlash, NorFlashErrorKind, ReadNorFlash};

/// `SIZE` bytes of NOR flash with `ERASE`-byte sectors and `WRITE`-byte program words.
#[derive(Debug, Clone)]
pub struct RamFlash<const SIZE: usize, const ERASE: usize, const WRITE: usize> {
    memory: [u8; SIZE],
    steps: u32,
    power_cut_at: Option<u32>,
    powered: bool,
}

impl<const SIZE: usize, const ERASE: usize, const WRITE: usize> Default
    for RamFlash<SIZE, ERASE, WRITE>
{
    fn default() -> Self {
        Self::new()
    }
}

impl<const SIZE: usize, const ERASE: usize, const WRITE: usize> RamFlash<SIZE, ERASE, WRITE> {
    /// An erased flash with power on and no cut scheduled.
    pub fn new() -> Self {
        Self {
            memory: [0xFF; SIZE],
            steps: 0,
            power_cut_at: None,
            powered: true,
        }
    }

    /// Cut the power during step `step` (counted from the last [`Self::restore_power`]); `None`
    /// never cuts.
    pub fn cut_power_at_step(&mut self, step: Option<u32>) {
        self.power_cut_at = step;
    }

    /// Steps (sector erases and words written) since power was last restored.
    pub fn steps(&self) -> u32 {
        self.steps
    }

    /// Whether the power is on (false after a scheduled cut happened).
    pub fn is_powered(&self) -> bool {
        self.powered
    }

    /// Power on again, as at a reboot: the content stays, the step count and any cut are cleared.
    pub fn restore_power(&mut self) {
        self.powered = true;
        self.steps = 0;
        self.power_cut_at = None;
    }

    /// The raw content.
    pub fn memory(&self) -> &[u8] {
        &self.memory
    }

    /// The raw content, for injecting bit errors.
    pub fn memory_mut(&mut self) -> &mut [u8] {
        &mut self.memory
    }

    /// Count a step; `true` when this step is the one to be cut.
    fn step_is_cut(&mut self) -> bool {
        let cut = self.power_cut_at == Some(self.steps);
        self.steps = self.steps.saturating_add(1);
        if cut {
            self.powered = false;
        }
        cut
    }

    fn range(
        &self,
        offset: u32,
        len: usize,
        align: usize,
    ) -> Result<(usize, usize), NorFlashErrorKind> {
        let start = usize::try_from(offset).map_err(|_| NorFlashErrorKind::OutOfBounds)?;
        let end = start
            .checked_add(len)
            .ok_or(NorFlashErrorKind::OutOfBounds)?;
        if end > SIZE {
            return Err(NorFlashErrorKind::OutOfBounds);
        }
        if align == 0 || !start.is_multiple_of(align) || !len.is_multiple_of(align) {
            return Err(NorFlashErrorKind::NotAligned);
        }
        Ok((start, end))
    }
}

impl<const SIZE: usize, const ERASE: usize, const WRITE: usize> ErrorType
    for RamFlash<SIZE, ERASE, WRITE>
{
    type Error = NorFlashErrorKind;
}

impl<const SIZE: usize, const ERASE: usize, const WRITE: usize> ReadNorFlash
    for RamFlash<SIZE, ERASE, WRITE>
{
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        if !self.powered {
            return Err(NorFlashErrorKind::Other);
        }
        let (start, end) = self.range(offset, bytes.len(), 1)?;
        let source = self
            .memory
            .get(start..end)
            .ok_or(NorFlashErrorKind::OutOfBounds)?;
        bytes.copy_from_slice(source);
        Ok(())
    }

    fn capacity(&self) -> usize {
        SIZE
    }
}

impl<const SIZE: usize, const ERASE: usize, const WRITE: usize> NorFlash
    for RamFlash<SIZE, ERASE, WRITE>
{
    const WRITE_SIZE: usize = WRITE;
    const ERASE_SIZE: usize = ERASE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        if !self.powered {
            return Err(NorFlashErrorKind::Other);
        }
        let len = to.checked_sub(from).ok_or(NorFlashErrorKind::OutOfBounds)? as usize;
        let (start, end) = self.range(from, len, ERASE)?;
        let mut sector = start;
        while sector < end {
            let cut = self.step_is_cut();
            let erased = if cut { ERASE / 2 } else { ERASE };
            if let Some(bytes) = self.memory.get_mut(sector..sector + erased) {
                bytes.fill(0xFF);
            }
            if cut {
                return Err(NorFlashErrorKind::Other);
            }
            sector += ERASE;
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        if !self.powered {
            return Err(NorFlashErrorKind::Other);
        }
        let (start, _) = self.range(offset, bytes.len(), WRITE)?;
        for (word_index, word) in bytes.chunks(WRITE).enumerate() {
            let cut = self.step_is_cut();
            // A torn program leaves the low nibble of every byte unprogrammed (still 1).
            let unprogrammed = if cut { 0x0F } else { 0x00 };
            let word_start = start + word_index * WRITE;
            if let Some(target) = self.memory.get_mut(word_start..word_start + word.len()) {
                for (cell, &new) in target.iter_mut().zip(word) {
                    *cell &= new | unprogrammed;
                }
            }
            if cut {
                return Err(NorFlashErrorKind::Other);
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_only_clear_bits_and_erase_restores_ones() {
        let mut flash = RamFlash::<64, 32, 4>::new();
        flash.write(0, &[0xF0, 0x0F, 0xAA, 0x55]).unwrap();
        flash.write(0, &[0x3C, 0x3C, 0xFF, 0x00]).unwrap();
        assert_eq!(&flash.memory()[..4], &[0x30, 0x0C, 0xAA, 0x00]);
        flash.erase(0, 32).unwrap();
        assert_eq!(&flash.memory()[..4], &[0xFF; 4]);
    }

    #[test]
    fn misaligned_or_out_of_range_requests_are_errors_not_panics() {
        let mut flash = RamFlash::<64, 32, 4>::new();
        assert_eq!(flash.write(2, &[0; 4]), Err(NorFlashErrorKind::NotAligned));
        assert_eq!(
            flash.write(64, &[0; 4]),
            Err(NorFlashErrorKind::OutOfBounds)
        );
        assert_eq!(flash.erase(32, 0), Err(NorFlashErrorKind::OutOfBounds));
        assert_eq!(flash.erase(0, 16), Err(NorFlashErrorKind::NotAligned));
        let mut buf = [0u8; 8];
        assert_eq!(
            flash.read(u32::MAX, &mut buf),
            Err(NorFlashErrorKind::OutOfBounds)
        );
    }

    #[test]
    fn a_cut_step_is_half_done_and_everything_after_fails() {
        let mut flash = RamFlash::<64, 32, 2>::new();
        flash.cut_power_at_step(Some(1));
        assert_eq!(flash.write(0, &[0x00; 4]), Err(NorFlashErrorKind::Other));
        // Word 0 was programmed, word 1 torn (low nibbles still 1), nothing after.
        assert_eq!(&flash.memory()[..6], &[0x00, 0x00, 0x0F, 0x0F, 0xFF, 0xFF]);
        assert!(!flash.is_powered());
        assert_eq!(flash.erase(0, 32), Err(NorFlashErrorKind::Other));
        flash.restore_power();
        flash.erase(0, 32).unwrap();
        assert_eq!(&flash.memory()[..4], &[0xFF; 4]);
    }
}
