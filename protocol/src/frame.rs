//! Framing: postcard payload + CRC-32, COBS-encoded, terminated by a 0x00 delimiter.
//!
//! The encoder streams the message straight into the caller's buffer; the decoder buffers one
//! frame at a time in a fixed array, decodes COBS in place and never allocates or panics.

use core::marker::PhantomData;

use crc::{Crc, CRC_32_ISO_HDLC};
use postcard::ser_flavors::Flavor;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::error::{EncodeError, FrameError};

/// Largest encoded frame in bytes, including the COBS overhead and the 0x00 delimiter.
pub const MAX_FRAME: usize = 512;

/// Bytes of the CRC-32 that follows each payload (little-endian).
pub const CRC_BYTES: usize = 4;

/// Largest postcard payload that still fits [`MAX_FRAME`] once encoded.
pub const MAX_PAYLOAD: usize = 504;

const _: () = assert!(max_frame_len(MAX_PAYLOAD) <= MAX_FRAME);
const _: () = assert!(max_frame_len(MAX_PAYLOAD + 1) > MAX_FRAME);

/// Worst-case encoded frame length (including delimiter) for a payload of `payload_len` bytes.
///
/// COBS adds one code byte per started run of 254 non-zero bytes: at most `n / 254 + 1` for
/// `n = payload_len + CRC_BYTES` bytes of input.
pub const fn max_frame_len(payload_len: usize) -> usize {
    let n = payload_len + CRC_BYTES;
    n + n / 254 + 1 + 1
}

static CRC32: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);

/// CRC-32 (ISO-HDLC) of a value's postcard encoding, computed without a buffer.
///
/// Types whose encoding cannot fail (no sequences of unknown length) always yield their CRC;
/// for others a serialisation failure yields the CRC of the bytes produced before it.
pub(crate) fn crc32_of<T: Serialize + ?Sized>(value: &T) -> u32 {
    let mut digest = CRC32.digest();
    // The digest flavor never fails, and the types hashed here have fixed layouts.
    let _ = postcard::serialize_with_flavor(value, DigestFlavor(&mut digest));
    digest.finalize()
}

struct DigestFlavor<'a, 'c>(&'a mut crc::Digest<'c, u32>);

impl Flavor for DigestFlavor<'_, '_> {
    type Output = ();

    fn try_extend(&mut self, data: &[u8]) -> postcard::Result<()> {
        self.0.update(data);
        Ok(())
    }

    fn try_push(&mut self, data: u8) -> postcard::Result<()> {
        self.0.update(&[data]);
        Ok(())
    }

    fn finalize(self) -> postcard::Result<()> {
        Ok(())
    }
}

/// Streaming COBS encoder into a slice, computing the payload's CRC on the way.
struct CobsCrcWriter<'a> {
    out: &'a mut [u8],
    code_pos: usize,
    write_pos: usize,
    code: u8,
    digest: crc::Digest<'static, u32>,
}

impl<'a> CobsCrcWriter<'a> {
    fn new(out: &'a mut [u8]) -> Self {
        Self {
            out,
            code_pos: 0,
            write_pos: 1,
            code: 1,
            digest: CRC32.digest(),
        }
    }

    fn put(&mut self, pos: usize, byte: u8) -> postcard::Result<()> {
        let slot = self
            .out
            .get_mut(pos)
            .ok_or(postcard::Error::SerializeBufferFull)?;
        *slot = byte;
        Ok(())
    }

    fn close_block(&mut self) -> postcard::Result<()> {
        self.put(self.code_pos, self.code)?;
        self.code_pos = self.write_pos;
        self.write_pos += 1;
        self.code = 1;
        Ok(())
    }

    fn cobs_push(&mut self, byte: u8) -> postcard::Result<()> {
        if byte == 0 {
            return self.close_block();
        }
        self.put(self.write_pos, byte)?;
        self.write_pos += 1;
        self.code += 1;
        if self.code == 0xFF {
            self.close_block()?;
        }
        Ok(())
    }
}

impl Flavor for CobsCrcWriter<'_> {
    type Output = usize;

    fn try_extend(&mut self, data: &[u8]) -> postcard::Result<()> {
        self.digest.update(data);
        data.iter().try_for_each(|&b| self.cobs_push(b))
    }

    fn try_push(&mut self, data: u8) -> postcard::Result<()> {
        self.try_extend(&[data])
    }

    fn finalize(mut self) -> postcard::Result<usize> {
        let digest = core::mem::replace(&mut self.digest, CRC32.digest());
        for byte in digest.finalize().to_le_bytes() {
            self.cobs_push(byte)?;
        }
        self.put(self.code_pos, self.code)?;
        self.put(self.write_pos, 0)?;
        Ok(self.write_pos + 1)
    }
}

/// Encodes `msg` as one frame into `buf`; returns the frame length including the delimiter.
///
/// A buffer of [`MAX_FRAME`] bytes holds any message of this protocol.
pub fn encode_frame<T: Serialize + ?Sized>(msg: &T, buf: &mut [u8]) -> Result<usize, EncodeError> {
    postcard::serialize_with_flavor(msg, CobsCrcWriter::new(buf)).map_err(|e| match e {
        postcard::Error::SerializeBufferFull => EncodeError::BufferFull,
        _ => EncodeError::Serialize,
    })
}

/// Decodes a payload (postcard bytes, CRC already removed); trailing bytes are an error.
pub fn decode_payload<'de, T: Deserialize<'de>>(payload: &'de [u8]) -> Result<T, FrameError> {
    match postcard::take_from_bytes(payload) {
        Ok((value, [])) => Ok(value),
        _ => Err(FrameError::Decode),
    }
}

/// Decodes COBS in place over `buf` (which holds no zero bytes); returns the decoded length.
fn cobs_decode_in_place(buf: &mut [u8]) -> Result<usize, FrameError> {
    let len = buf.len();
    let mut read = 0;
    let mut write = 0;
    while let Some(&code) = buf.get(read) {
        read += 1;
        let run = usize::from(code).saturating_sub(1);
        let end = read + run;
        if code == 0 || end > len {
            return Err(FrameError::Cobs);
        }
        buf.copy_within(read..end, write);
        write += run;
        read = end;
        if code != 0xFF && read < len {
            // Decoded output never overtakes the input, so `write < read <= len`.
            let slot = buf.get_mut(write).ok_or(FrameError::Cobs)?;
            *slot = 0;
            write += 1;
        }
    }
    Ok(write)
}

/// Incremental frame decoder with a fixed buffer of `N` bytes (one encoded frame without its
/// delimiter).
///
/// Feed it any chunks of the byte stream. Each 0x00 ends a frame: the decoder then yields the
/// payload or a [`FrameError`], and starts afresh, so after garbage, corruption or a lost
/// delimiter it resynchronises at the next 0x00. Empty frames (consecutive delimiters) are
/// skipped silently, so a sender may emit a 0x00 first to flush a partial frame at the receiver.
#[derive(Debug, Clone)]
pub struct FrameDecoder<const N: usize = MAX_FRAME> {
    buf: [u8; N],
    len: usize,
    overflowed: bool,
}

impl<const N: usize> FrameDecoder<N> {
    /// An empty decoder.
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            len: 0,
            overflowed: false,
        }
    }

    /// Discards any partly received frame.
    pub fn reset(&mut self) {
        self.len = 0;
        self.overflowed = false;
    }

    /// Number of bytes of an unfinished frame held (0 right after a delimiter).
    pub fn pending(&self) -> usize {
        self.len
    }

    /// Consumes one byte; at a delimiter returns the frame's payload (CRC checked) or its error.
    pub fn push(&mut self, byte: u8) -> Option<Result<&[u8], FrameError>> {
        if byte != 0 {
            match self.buf.get_mut(self.len) {
                Some(slot) => {
                    *slot = byte;
                    self.len += 1;
                }
                None => self.overflowed = true,
            }
            return None;
        }
        let len = core::mem::take(&mut self.len);
        if core::mem::take(&mut self.overflowed) {
            return Some(Err(FrameError::Overflow));
        }
        if len == 0 {
            return None;
        }
        Some(Self::check_frame(self.buf.get_mut(..len)?))
    }

    fn check_frame(frame: &mut [u8]) -> Result<&[u8], FrameError> {
        let decoded_len = cobs_decode_in_place(frame)?;
        let decoded = frame.get(..decoded_len).ok_or(FrameError::Cobs)?;
        let payload_len = decoded_len
            .checked_sub(CRC_BYTES)
            .ok_or(FrameError::TooShort)?;
        let (payload, crc) = decoded.split_at(payload_len);
        let mut crc_le = [0u8; CRC_BYTES];
        crc_le.copy_from_slice(crc);
        if CRC32.checksum(payload) == u32::from_le_bytes(crc_le) {
            Ok(payload)
        } else {
            Err(FrameError::Crc)
        }
    }

    /// Consumes all of `bytes`, calling `on_message` for each completed frame decoded as `T`.
    pub fn feed<T: DeserializeOwned>(
        &mut self,
        bytes: &[u8],
        mut on_message: impl FnMut(Result<T, FrameError>),
    ) {
        for message in self.messages(bytes) {
            on_message(message);
        }
    }

    /// An iterator over the frames completed by `bytes`, each decoded as `T`.
    ///
    /// Bytes not yet consumed when the iterator is dropped are not seen by the decoder, so
    /// iterate to the end (or use [`FrameDecoder::feed`]).
    pub fn messages<'d, 'b, T: DeserializeOwned>(
        &'d mut self,
        bytes: &'b [u8],
    ) -> Messages<'d, 'b, T, N> {
        Messages {
            decoder: self,
            bytes,
            _message: PhantomData,
        }
    }
}

impl<const N: usize> Default for FrameDecoder<N> {
    fn default() -> Self {
        Self::new()
    }
}

/// Iterator returned by [`FrameDecoder::messages`].
pub struct Messages<'d, 'b, T, const N: usize> {
    decoder: &'d mut FrameDecoder<N>,
    bytes: &'b [u8],
    _message: PhantomData<fn() -> T>,
}

impl<T: DeserializeOwned, const N: usize> Iterator for Messages<'_, '_, T, N> {
    type Item = Result<T, FrameError>;

    fn next(&mut self) -> Option<Self::Item> {
        while let Some((&byte, rest)) = self.bytes.split_first() {
            self.bytes = rest;
            if let Some(frame) = self.decoder.push(byte) {
                return Some(frame.and_then(decode_payload::<T>));
            }
        }
        None
    }
}
