//! Power-safe parameter store: two slots in NOR flash, the newest valid one is active.
//!
//! Slot image: a 20-byte header — magic `"IMUC"`, format version (u16), reserved (u16), sequence
//! number (u32), payload length (u32), CRC-32/ISO-HDLC over the first 16 header bytes and the
//! payload (u32) — then the payload, padded with `0xFF` to the program size. All little-endian.
//!
//! A write goes to the inactive slot: erase, program every chunk after the first, then the first
//! chunk (header and the start of the payload), read back and compare. The header is programmed
//! at the *start* of that final operation, so a cut inside it can leave a complete header over a
//! payload that is not; what makes the store safe is the CRC over header fields and payload,
//! not the order. The order only means that before the final operation the slot has no magic.
//! Only a slot whose CRC checks counts, so a power cut at any step leaves either the previous set
//! or the new one, never a corrupt one. Sequence numbers compare by serial-number arithmetic
//! (RFC 1982), so wrapping past `u32::MAX` keeps the order.
//!
//! On boot [`ParamStore::load_newest`] offers the valid slots newest first to the caller, who
//! decodes and validates the payload: a newest set that no longer passes (after an update
//! tightened the limits, or a marginal bit that reads back differently the second time) falls
//! back to the older valid slot instead of to nothing. Every read re-checks the CRC.
//!
//! Why not the `sequential-storage` crate: it keeps a key-value map or queue in a log of items,
//! needs `MultiwriteNorFlash` (programming a word twice, which ECC-protected internal flash
//! forbids) and async flash traits, and would change the on-flash format for a single ≤ 1 KiB
//! record that two A/B slots hold with one erase per write. Its test method is what we adopt:
//! random tears and marginal bits over many seeded iterations (`tests/store_random_tears.rs`).

use embedded_storage::nor_flash::{NorFlash, NorFlashError, NorFlashErrorKind};

/// Magic at the start of every slot: ASCII `"IMUC"`.
pub const SLOT_MAGIC: u32 = u32::from_le_bytes(*b"IMUC");
/// Version of the slot layout described in the module documentation.
pub const SLOT_FORMAT_VERSION: u16 = 1;
/// Bytes of header before the payload.
pub const HEADER_LEN: usize = 20;
/// Bytes moved per flash access; program and read sizes must divide it.
const CHUNK: usize = 256;

const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// Why the store could not do what was asked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StoreError {
    /// The flash reported an error.
    Flash(NorFlashErrorKind),
    /// The slot layout does not fit the flash.
    Geometry,
    /// The payload does not fit in one slot.
    TooLarge {
        /// Bytes offered.
        len: usize,
        /// Largest payload a slot holds.
        max: usize,
    },
    /// The slot read back differently from what was written.
    VerifyFailed,
    /// No valid parameter set is stored.
    Empty,
    /// The caller's buffer is smaller than the stored payload.
    BufferTooSmall {
        /// Bytes needed.
        needed: usize,
    },
}

impl core::fmt::Display for StoreError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Flash(kind) => write!(
                f,
                "the flash reported \"{kind}\"; check the slot base and size against the part's memory map"
            ),
            Self::Geometry => write!(
                f,
                "the two slots do not fit the flash: each slot must be a non-zero multiple of the erase size, \
                 start on a sector boundary, fit the capacity together, and the program and read sizes \
                 must divide {CHUNK}; choose another base or slot size"
            ),
            Self::TooLarge { len, max } => write!(
                f,
                "a {len}-byte parameter set does not fit a slot holding {max} bytes; enlarge the slots"
            ),
            Self::VerifyFailed => write!(
                f,
                "the slot read back differently from what was written, so the previous set stays active; \
                 retry, and replace the flash part if it persists"
            ),
            Self::Empty => write!(f, "no valid parameter set is stored; write one first"),
            Self::BufferTooSmall { needed } => {
                write!(f, "the stored parameter set needs a {needed}-byte buffer; pass a larger one")
            }
        }
    }
}

/// Header fields of a valid slot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct SlotInfo {
    index: usize,
    sequence: u32,
    len: usize,
}

/// `true` when sequence `a` is newer than `b` under serial-number arithmetic.
fn is_newer(a: u32, b: u32) -> bool {
    // Casting the wrapped difference to i32 is the RFC 1982 comparison.
    (a.wrapping_sub(b) as i32) > 0
}

/// Two-slot parameter store on a NOR flash.
#[derive(Debug)]
pub struct ParamStore<F: NorFlash> {
    flash: F,
    base: u32,
    slot_size: u32,
    active: Option<SlotInfo>,
}

impl<F: NorFlash> ParamStore<F> {
    /// Open a store whose two slots of `slot_size` bytes start at `base`, and find the active set.
    ///
    /// A slot may span several erase sectors. Fails with [`StoreError::Geometry`] when the layout
    /// does not fit the flash.
    pub fn new(flash: F, base: u32, slot_size: u32) -> Result<Self, StoreError> {
        let erase = F::ERASE_SIZE;
        let fits = slot_size as usize >= HEADER_LEN
            && erase > 0
            && (slot_size as usize).is_multiple_of(erase)
            && (base as usize).is_multiple_of(erase)
            && F::WRITE_SIZE > 0
            && CHUNK.is_multiple_of(F::WRITE_SIZE)
            && F::READ_SIZE > 0
            && CHUNK.is_multiple_of(F::READ_SIZE)
            && slot_size
                .checked_mul(2)
                .and_then(|both| both.checked_add(base))
                .is_some_and(|end| end as usize <= flash.capacity());
        if !fits {
            return Err(StoreError::Geometry);
        }
        let mut store = Self {
            flash,
            base,
            slot_size,
            active: None,
        };
        store.active = store.scan();
        Ok(store)
    }

    /// Largest payload one slot holds.
    pub fn max_payload(&self) -> usize {
        self.slot_size as usize - HEADER_LEN
    }

    /// Sequence number of the active set, if any.
    pub fn active_sequence(&self) -> Option<u32> {
        self.active.map(|slot| slot.sequence)
    }

    /// Length of the active payload, if any.
    pub fn active_len(&self) -> Option<usize> {
        self.active.map(|slot| slot.len)
    }

    /// Give the flash back (e.g. to simulate a reboot by opening a new store on it).
    pub fn into_flash(self) -> F {
        self.flash
    }

    /// Copy the active payload into `out` and return its length; the CRC is checked again.
    pub fn read_active(&mut self, out: &mut [u8]) -> Result<usize, StoreError> {
        let slot = self.active.ok_or(StoreError::Empty)?;
        let target = out
            .get_mut(..slot.len)
            .ok_or(StoreError::BufferTooSmall { needed: slot.len })?;
        match self.check_slot(slot.index, Some(target)) {
            Ok(Some(_)) => Ok(slot.len),
            Ok(None) => Err(StoreError::VerifyFailed),
            Err(error) => Err(error),
        }
    }

    /// Offer the valid slots' payloads to `accept`, newest first, and make the first accepted
    /// one active; returns what `accept` made of it and its sequence number. A slot whose CRC
    /// fails on this read, or whose payload `accept` refuses, is passed over, so a newest set
    /// that no longer validates falls back to the older one. `None` when no slot is accepted.
    pub fn load_newest<T>(
        &mut self,
        buffer: &mut [u8],
        mut accept: impl FnMut(&[u8]) -> Option<T>,
    ) -> Option<(T, u32)> {
        let [first, second] = [0, 1].map(|index| self.check_slot(index, None).ok().flatten());
        let newest_first = match (first, second) {
            (Some(a), Some(b)) if is_newer(a.sequence, b.sequence) => [Some(a), Some(b)],
            (a, b) => [b, a],
        };
        for slot in newest_first.into_iter().flatten() {
            let Some(target) = buffer.get_mut(..slot.len) else {
                continue;
            };
            if self.check_slot(slot.index, Some(target)) != Ok(Some(slot)) {
                continue;
            }
            if let Some(value) = buffer.get(..slot.len).and_then(&mut accept) {
                self.active = Some(slot);
                return Some((value, slot.sequence));
            }
        }
        self.active = None;
        None
    }

    /// Store `payload` as the new active set; on any error the previous set stays active.
    ///
    /// Returns the new sequence number.
    pub fn write(&mut self, payload: &[u8]) -> Result<u32, StoreError> {
        let max = self.max_payload();
        if payload.len() > max {
            return Err(StoreError::TooLarge {
                len: payload.len(),
                max,
            });
        }
        // With no active set, a slot the caller refused may still hold the newest sequence:
        // write after it, into the other slot, so that the order stays right.
        let newest = match self.active {
            Some(slot) => Some(slot),
            None => self.scan(),
        };
        let (index, sequence) = match newest {
            Some(slot) => (1 - slot.index, slot.sequence.wrapping_add(1)),
            None => (0, 1),
        };
        let header = header_bytes(sequence, payload);
        let start = self.slot_start(index);
        self.flash
            .erase(start, start + self.slot_size)
            .map_err(flash_error)?;

        // Program every chunk after the first, then the first (header at its start): until the
        // final operation the slot has no magic; within it, the CRC rejects a partial image.
        let image_len = round_up(HEADER_LEN + payload.len(), F::WRITE_SIZE);
        let chunks = image_len.div_ceil(CHUNK);
        let mut buffer = [0u8; CHUNK];
        for chunk in (1..chunks).chain(core::iter::once(0)) {
            let offset = chunk * CHUNK;
            let len = (image_len - offset).min(CHUNK);
            let Some(bytes) = buffer.get_mut(..len) else {
                return Err(StoreError::Geometry);
            };
            fill_image(bytes, offset, &header, payload);
            self.flash
                .write(start + offset as u32, bytes)
                .map_err(flash_error)?;
        }

        // Read back and compare byte for byte before the new set counts.
        let mut expected = [0u8; CHUNK];
        for chunk in 0..chunks {
            let offset = chunk * CHUNK;
            let len = round_up((image_len - offset).min(CHUNK), F::READ_SIZE).min(CHUNK);
            let (Some(read), Some(want)) = (buffer.get_mut(..len), expected.get_mut(..len)) else {
                return Err(StoreError::Geometry);
            };
            self.flash
                .read(start + offset as u32, read)
                .map_err(flash_error)?;
            // Past the image `fill_image` yields 0xFF, which is what erased flash reads.
            fill_image(want, offset, &header, payload);
            if read != want {
                return Err(StoreError::VerifyFailed);
            }
        }
        let written = SlotInfo {
            index,
            sequence,
            len: payload.len(),
        };
        if self.check_slot(index, None)? != Some(written) {
            return Err(StoreError::VerifyFailed);
        }
        self.active = Some(written);
        Ok(sequence)
    }

    fn slot_start(&self, index: usize) -> u32 {
        // index is 0 or 1 and base + 2·slot_size fits u32 (checked in `new`).
        self.base + self.slot_size * index as u32
    }

    /// The valid slot with the newest sequence; flash errors count as "not valid".
    fn scan(&mut self) -> Option<SlotInfo> {
        let first = self.check_slot(0, None).ok().flatten();
        let second = self.check_slot(1, None).ok().flatten();
        match (first, second) {
            (Some(a), Some(b)) => Some(if is_newer(b.sequence, a.sequence) {
                b
            } else {
                a
            }),
            (a, b) => a.or(b),
        }
    }

    /// Validate slot `index` (magic, version, length, CRC); optionally copy its payload out.
    fn check_slot(
        &mut self,
        index: usize,
        mut payload_out: Option<&mut [u8]>,
    ) -> Result<Option<SlotInfo>, StoreError> {
        let start = self.slot_start(index);
        let slot_size = self.slot_size as usize;
        let mut buffer = [0u8; CHUNK];
        let first_len = round_up(HEADER_LEN, F::READ_SIZE).min(CHUNK);
        let Some(head) = buffer.get_mut(..first_len) else {
            return Err(StoreError::Geometry);
        };
        self.flash.read(start, head).map_err(flash_error)?;
        let field = |at: usize| -> u32 {
            let mut word = [0u8; 4];
            if let Some(bytes) = head.get(at..at + 4) {
                word.copy_from_slice(bytes);
            }
            u32::from_le_bytes(word)
        };
        let magic = field(0);
        let version = (field(4) & 0xFFFF) as u16;
        let sequence = field(8);
        let len = field(12) as usize;
        let stored_crc = field(16);
        if magic != SLOT_MAGIC || version != SLOT_FORMAT_VERSION || len > slot_size - HEADER_LEN {
            return Ok(None);
        }
        let mut digest = CRC32.digest();
        if let Some(header) = head.get(..16) {
            digest.update(header);
        }
        // Stream the payload through the CRC (and into the caller's buffer).
        let mut done = 0;
        while done < len {
            let offset = HEADER_LEN + done;
            // Read an aligned window that covers [offset, offset + take) and fits the buffer.
            // `offset % READ_SIZE < READ_SIZE ≤ CHUNK`, so every pass takes at least one byte.
            let misalignment = offset % F::READ_SIZE;
            let take = (len - done).min(CHUNK - misalignment);
            let aligned = offset - misalignment;
            let window = round_up(offset + take - aligned, F::READ_SIZE);
            let Some(bytes) = buffer.get_mut(..window) else {
                return Err(StoreError::Geometry);
            };
            self.flash
                .read(start + aligned as u32, bytes)
                .map_err(flash_error)?;
            let Some(part) = bytes.get(offset - aligned..offset - aligned + take) else {
                return Err(StoreError::Geometry);
            };
            digest.update(part);
            if let Some(out) = payload_out.as_deref_mut() {
                if let Some(target) = out.get_mut(done..done + take) {
                    target.copy_from_slice(part);
                }
            }
            done += take;
        }
        if digest.finalize() != stored_crc {
            return Ok(None);
        }
        Ok(Some(SlotInfo {
            index,
            sequence,
            len,
        }))
    }
}

fn flash_error<E: NorFlashError>(error: E) -> StoreError {
    StoreError::Flash(error.kind())
}

fn round_up(value: usize, multiple: usize) -> usize {
    value.div_ceil(multiple) * multiple
}

/// The header for `payload` at `sequence`, CRC included.
fn header_bytes(sequence: u32, payload: &[u8]) -> [u8; HEADER_LEN] {
    let mut header = [0u8; HEADER_LEN];
    let mut put = |at: usize, bytes: [u8; 4]| {
        if let Some(target) = header.get_mut(at..at + 4) {
            target.copy_from_slice(&bytes);
        }
    };
    put(0, SLOT_MAGIC.to_le_bytes());
    put(4, u32::from(SLOT_FORMAT_VERSION).to_le_bytes());
    put(8, sequence.to_le_bytes());
    // The length is bounded by the slot size, which is a u32.
    put(12, (payload.len() as u32).to_le_bytes());
    let mut digest = CRC32.digest();
    if let Some(fields) = header.get(..16) {
        digest.update(fields);
    }
    digest.update(payload);
    let crc = digest.finalize();
    if let Some(target) = header.get_mut(16..20) {
        target.copy_from_slice(&crc.to_le_bytes());
    }
    header
}

/// Fill `bytes` with the slot image from byte `offset` on: header, payload, then `0xFF` padding.
fn fill_image(bytes: &mut [u8], offset: usize, header: &[u8; HEADER_LEN], payload: &[u8]) {
    for (i, byte) in bytes.iter_mut().enumerate() {
        let at = offset + i;
        *byte = if at < HEADER_LEN {
            header.get(at).copied().unwrap_or(0xFF)
        } else {
            payload.get(at - HEADER_LEN).copied().unwrap_or(0xFF)
        };
    }
}

#[cfg(test)]
mod tests;
