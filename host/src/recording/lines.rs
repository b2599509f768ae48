//! Reading a text input once, as a stream of lines, with bounded memory.
//!
//! Every recording reader takes its lines from a [`LineReader`]: the input (a file, a FIFO, a
//! process substitution, or standard input for `-`) is opened once and read in fixed-size chunks,
//! so memory stays proportional to what the caller keeps, not to the input's size. Input that is
//! not text is refused early: a UTF-16 byte-order mark or a zero byte in the first KiB (where any
//! binary file or device such as `/dev/zero` shows itself), invalid UTF-8 or a zero byte on any
//! later line, and a line longer than [`MAX_LINE_BYTES`] (a recording's longest line, its header,
//! is well under a KiB; a file without line breaks is not a recording).

use std::fs::File;
use std::io::{ErrorKind, Read};
use std::path::Path;

use super::{display, RecordingError};

/// Longest line accepted, in bytes.
pub const MAX_LINE_BYTES: usize = 64 * 1024;

/// Bytes inspected for binary content before any line is parsed.
const SNIFF_BYTES: usize = 1024;

/// Size of each read from the input.
const CHUNK_BYTES: usize = 256 * 1024;

/// The path that names standard input.
pub const STDIN_PATH: &str = "-";

/// Lines of one input, read in chunks.
pub struct LineReader<'a> {
    input: Box<dyn Read + 'a>,
    path: String,
    buf: Vec<u8>,
    /// Start of the unread bytes in `buf`.
    start: usize,
    /// End of the valid bytes in `buf`.
    end: usize,
    /// Bytes dropped from the front of `buf` so far (for error offsets).
    consumed: u64,
    eof: bool,
    sniffed: bool,
    line_no: usize,
    /// Size of the input in bytes when known (a regular file).
    input_len: Option<u64>,
}

impl<'a> LineReader<'a> {
    /// Open `path` (or standard input when it is `-`) for reading once.
    pub fn open(path: &Path) -> Result<Self, RecordingError> {
        if path.as_os_str() == STDIN_PATH {
            return Ok(Self::new(Box::new(std::io::stdin()), display(path)));
        }
        let file = File::open(path).map_err(|cause| RecordingError::Io {
            path: display(path),
            cause,
        })?;
        let input_len = file
            .metadata()
            .ok()
            .filter(|m| m.is_file())
            .map(|m| m.len());
        let mut reader = Self::new(Box::new(file), display(path));
        reader.input_len = input_len;
        Ok(reader)
    }

    /// Lines of `input`; `path` names it in errors.
    pub fn new(input: Box<dyn Read + 'a>, path: String) -> Self {
        Self {
            input,
            path,
            buf: vec![0; CHUNK_BYTES],
            start: 0,
            end: 0,
            consumed: 0,
            eof: false,
            sniffed: false,
            line_no: 0,
            input_len: None,
        }
    }

    /// Size of the input in bytes, when it is a regular file (to size buffers for its rows).
    pub fn input_len(&self) -> Option<u64> {
        self.input_len
    }

    /// The name of the input, as shown in errors.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// The next line without its line break, with its 1-based number; `None` at the end.
    pub fn next_line(&mut self) -> Result<Option<(usize, &str)>, RecordingError> {
        let (from, to) = match self.find_line()? {
            Some(range) => range,
            None => return Ok(None),
        };
        self.line_no += 1;
        let mut line = &self.buf[from..to];
        if let [rest @ .., b'\r'] = line {
            line = rest;
        }
        if let Some(at) = memchr::memchr(0, line) {
            return Err(self.not_text(format!(
                "it holds binary data (a zero byte at offset {})",
                self.offset_of(from + at)
            )));
        }
        match std::str::from_utf8(line) {
            Ok(text) => Ok(Some((self.line_no, text))),
            Err(e) => {
                let at = from + e.valid_up_to();
                Err(self.not_text(format!(
                    "it holds bytes that are not UTF-8 text (byte 0x{:02X} at offset {})",
                    self.buf[at],
                    self.offset_of(at)
                )))
            }
        }
    }

    /// The next run of whole lines, about `want` bytes or more when the lines allow (everything
    /// up to the last line break read, or to the end of the input); `None` at the end. The
    /// lines are not checked for text: the caller checks them as [`Self::next_line`] does and
    /// then reports how many lines the run held with [`Self::count_lines`].
    pub fn next_block(&mut self, want: usize) -> Result<Option<(u64, &[u8])>, RecordingError> {
        loop {
            if !self.eof && self.end - self.start < want {
                self.fill()?;
                continue;
            }
            let pending = &self.buf[self.start..self.end];
            let to = match memchr::memrchr(b'\n', pending) {
                Some(at) => self.start + at + 1,
                None if pending.len() > MAX_LINE_BYTES => {
                    return Err(RecordingError::LineTooLong {
                        path: self.path.clone(),
                        line: self.line_no + 1,
                        limit: MAX_LINE_BYTES,
                    })
                }
                None if self.eof => self.end,
                None => {
                    self.fill()?;
                    continue;
                }
            };
            if to == self.start {
                return Ok(None);
            }
            let from = self.start;
            self.start = to;
            return Ok(Some((self.offset_of(from), &self.buf[from..to])));
        }
    }

    /// Up to `want` bytes of the input not yet handed out, without consuming them (fewer at the
    /// end of the input), so that a format can be told from the first lines of input read only
    /// once, such as standard input.
    pub fn peek(&mut self, want: usize) -> Result<&[u8], RecordingError> {
        while !self.eof && self.end - self.start < want {
            self.fill()?;
        }
        Ok(&self.buf[self.start..self.end.min(self.start + want)])
    }

    /// Number of the last line handed out.
    pub fn line_no(&self) -> usize {
        self.line_no
    }

    /// Count `lines` more lines as read (those of a run from [`Self::next_block`]).
    pub fn count_lines(&mut self, lines: usize) {
        self.line_no += lines;
    }

    /// Byte range in `buf` of the next line (line break excluded), consuming it.
    fn find_line(&mut self) -> Result<Option<(usize, usize)>, RecordingError> {
        let mut searched = self.start;
        loop {
            if let Some(at) = memchr::memchr(b'\n', &self.buf[searched..self.end]) {
                let line = (self.start, searched + at);
                self.start = searched + at + 1;
                return Ok(Some(line));
            }
            if self.end - self.start > MAX_LINE_BYTES {
                return Err(RecordingError::LineTooLong {
                    path: self.path.clone(),
                    line: self.line_no + 1,
                    limit: MAX_LINE_BYTES,
                });
            }
            if self.eof {
                if self.start == self.end {
                    return Ok(None);
                }
                let line = (self.start, self.end);
                self.start = self.end;
                return Ok(Some(line));
            }
            let kept = self.end - self.start;
            self.fill()?;
            searched = self.start + kept;
        }
    }

    /// Move the unread bytes to the front and read one more chunk (checking the first KiB).
    fn fill(&mut self) -> Result<(), RecordingError> {
        if self.start > 0 {
            self.buf.copy_within(self.start..self.end, 0);
            self.consumed += self.start as u64;
            self.end -= self.start;
            self.start = 0;
        }
        if self.buf.len() - self.end < CHUNK_BYTES / 2 {
            self.buf.resize(self.end + CHUNK_BYTES, 0);
        }
        let target = if self.sniffed {
            self.end + 1
        } else {
            SNIFF_BYTES
        };
        // A pipe may deliver less than asked for: read until the sniff window is full.
        while self.end < target.min(self.buf.len()) {
            match self.input.read(&mut self.buf[self.end..]) {
                Ok(0) => {
                    self.eof = true;
                    break;
                }
                Ok(n) => self.end += n,
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(cause) => {
                    return Err(RecordingError::Io {
                        path: self.path.clone(),
                        cause,
                    })
                }
            }
        }
        if !self.sniffed {
            self.sniffed = true;
            self.sniff()?;
        }
        Ok(())
    }

    /// Refuse input whose first KiB shows it is not UTF-8 text.
    fn sniff(&self) -> Result<(), RecordingError> {
        let head = &self.buf[..self.end.min(SNIFF_BYTES)];
        if head.starts_with(&[0xFF, 0xFE]) || head.starts_with(&[0xFE, 0xFF]) {
            return Err(self.not_text(
                "it is UTF-16 text (it starts with a UTF-16 byte-order mark)".to_string(),
            ));
        }
        if let Some(at) = memchr::memchr(0, head) {
            return Err(self.not_text(format!("it holds binary data (a zero byte at offset {at})")));
        }
        Ok(())
    }

    fn offset_of(&self, index: usize) -> u64 {
        self.consumed + index as u64
    }

    fn not_text(&self, detail: String) -> RecordingError {
        RecordingError::NotText {
            path: self.path.clone(),
            detail,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reader(bytes: &[u8]) -> LineReader<'_> {
        LineReader::new(Box::new(bytes), "test".into())
    }

    fn all_lines(mut r: LineReader<'_>) -> Result<Vec<(usize, String)>, RecordingError> {
        let mut out = Vec::new();
        while let Some((n, l)) = r.next_line()? {
            out.push((n, l.to_string()));
        }
        Ok(out)
    }

    #[test]
    fn lines_are_numbered_and_stripped_of_their_breaks_with_or_without_a_final_newline() {
        let lines = all_lines(reader(b"a,b\r\n\n1,2\n3,4")).expect("text");
        let expected = [(1, "a,b"), (2, ""), (3, "1,2"), (4, "3,4")];
        assert_eq!(lines.len(), expected.len());
        for ((n, l), (en, el)) in lines.iter().zip(expected) {
            assert_eq!((*n, l.as_str()), (en, el));
        }
    }

    #[test]
    fn lines_spanning_many_chunks_are_read_whole() {
        let row = "1.25,2.5,-3.75\n".repeat(100_000);
        let lines = all_lines(reader(row.as_bytes())).expect("text");
        assert_eq!(lines.len(), 100_000);
        assert!(lines.iter().all(|(_, l)| l == "1.25,2.5,-3.75"));
    }

    #[test]
    fn a_zero_byte_in_the_first_kib_is_refused_as_binary() {
        let err = all_lines(reader(b"t_s,ax\n\0\0\0")).unwrap_err();
        assert!(err.to_string().contains("zero byte at offset 7"), "{err}");
    }

    #[test]
    fn invalid_utf8_later_in_the_file_names_its_offset() {
        let mut text = "t_s,ax\n".to_string() + &"0.5,1\n".repeat(1000);
        text.push_str("0.5,\u{e9}\n");
        let mut bytes = text.into_bytes();
        let at = bytes.len() - 3;
        bytes[at] = 0xE9; // Latin-1 é, not UTF-8
        bytes.truncate(at + 1);
        bytes.push(b'\n');
        let err = all_lines(reader(&bytes)).unwrap_err();
        assert!(
            err.to_string().contains(&format!("0xE9 at offset {at}")),
            "{err}"
        );
    }

    #[test]
    fn a_line_longer_than_the_limit_is_refused_without_reading_further() {
        let long = "1".repeat(MAX_LINE_BYTES + 10);
        let err = all_lines(reader(long.as_bytes())).unwrap_err();
        assert!(
            matches!(err, RecordingError::LineTooLong { line: 1, .. }),
            "{err}"
        );
    }
}
