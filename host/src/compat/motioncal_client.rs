//! Talking to a board that runs a MotionCal-compatible sketch: read its lines as readings, send
//! a calibration packet and check the board's `Cal1:`/`Cal2:` echo against what was sent.
//!
//! Readings prefer `Uni:` lines (SI values as the sketch computed them); a board that prints only
//! `Raw:` lines is read from those, with MotionCal's scales. The sketch echoes its stored
//! calibration periodically (Adafruit's `calibration.ino`: `Cal1:` every 100 loops, `Cal2:` 50
//! loops later, 3 and 4 decimals), so the check waits for a `Cal1:`/`Cal2:` pair that matches
//! the packet within that print precision.

use std::collections::VecDeque;
use std::io::{ErrorKind, Read, Write};
use std::time::{Duration, Instant};

use serialport::SerialPort;
use thiserror::Error;

use super::adafruit::AdafruitCalibration;
use super::motioncal::{
    encode_packet, parse_line, LineSplitter, RawAccelScaling, SketchLine, SketchReading,
};
use super::CompatError;
use crate::device::{open_port, DeviceError};

/// Half a unit of the last decimal `Cal1:` prints (3 decimals).
const CAL1_PRINT_TOLERANCE: f64 = 0.5e-3;
/// Half a unit of the last decimal `Cal2:` prints (4 decimals).
const CAL2_PRINT_TOLERANCE: f64 = 0.5e-4;
/// What the board prints when its storage refused the calibration (Adafruit's sketch).
const SAVE_FAILED_TEXT: &str = "Couldn't save calibration";

/// Why talking to the board failed.
#[derive(Debug, Error)]
pub enum MotionCalError {
    /// The port could not be opened.
    #[error(transparent)]
    Port(#[from] DeviceError),
    /// Reading or writing failed.
    #[error(
        "the serial link failed ({0}); check the cable and that no other program has the port"
    )]
    Io(#[from] std::io::Error),
    /// Nothing usable arrived in time.
    #[error(
        "no {what} from the board within {seconds:.1} s; check that it runs a MotionCal-compatible \
         sketch (it prints `Raw:` lines at 115200 baud)"
    )]
    Timeout {
        /// What was awaited.
        what: &'static str,
        /// How long, s.
        seconds: f64,
    },
    /// The calibration could not be put in a packet.
    #[error(transparent)]
    Compat(#[from] CompatError),
    /// The board said it could not store the calibration.
    #[error(
        "the board could not save the calibration (it printed \"{0}\"); check its EEPROM or flash \
         file system, then send again"
    )]
    SaveFailed(String),
    /// The board echoed other values than were sent.
    #[error(
        "the board echoed {field} = {echoed} but {sent} was sent (print precision {tolerance}); \
         the packet was not stored as sent, send it again"
    )]
    EchoMismatch {
        /// Which value.
        field: String,
        /// Value sent.
        sent: f64,
        /// Value echoed.
        echoed: f64,
        /// Allowed difference.
        tolerance: f64,
    },
}

/// Outcome of a verified send.
#[derive(Debug, Clone, PartialEq)]
pub struct EchoCheck {
    /// The packet sent.
    pub packet: [u8; super::motioncal::PACKET_LEN],
    /// The `Cal1:` values echoed.
    pub cal1: [f64; 10],
    /// The `Cal2:` values echoed.
    pub cal2: [f64; 9],
    /// Largest difference between sent and echoed values.
    pub max_difference: f64,
}

/// A board running a MotionCal-compatible sketch, over any byte link.
pub struct MotionCalClient<L: Read + Write = Box<dyn SerialPort>> {
    link: L,
    splitter: LineSplitter,
    lines: VecDeque<String>,
    scaling: RawAccelScaling,
    pending_raw: Option<[i32; 9]>,
    uni_seen: bool,
    malformed: u64,
}

impl MotionCalClient<Box<dyn SerialPort>> {
    /// Opens the serial port at `path` (115200 baud).
    pub fn open(path: &str, scaling: RawAccelScaling) -> Result<Self, MotionCalError> {
        Ok(Self::new(open_port(path)?, scaling))
    }
}

impl<L: Read + Write> MotionCalClient<L> {
    /// A client on `link`; `scaling` says how the board's `Raw:` accel counts were made.
    pub fn new(link: L, scaling: RawAccelScaling) -> Self {
        Self {
            link,
            splitter: LineSplitter::new(),
            lines: VecDeque::new(),
            scaling,
            pending_raw: None,
            uni_seen: false,
            malformed: 0,
        }
    }

    /// Lines that started with a known tag but could not be read (noise, wrong baud rate).
    pub fn malformed_lines(&self) -> u64 {
        self.malformed
    }

    /// Whether the board prints `Uni:` lines (readings come from them then).
    pub fn has_unified_lines(&self) -> bool {
        self.uni_seen
    }

    /// The next line, or `None` when none completes within `timeout`.
    pub fn next_line(&mut self, timeout: Duration) -> Result<Option<SketchLine>, MotionCalError> {
        let deadline = Instant::now() + timeout;
        loop {
            while let Some(text) = self.lines.pop_front() {
                match parse_line(&text) {
                    Ok(line) => return Ok(Some(line)),
                    Err(_) => self.malformed += 1,
                }
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
            let mut buffer = [0u8; 1024];
            match self.link.read(&mut buffer) {
                Ok(0) => std::thread::sleep(Duration::from_millis(1)),
                Ok(n) => self.lines.extend(self.splitter.push(&buffer[..n])),
                Err(e)
                    if matches!(
                        e.kind(),
                        ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted
                    ) => {}
                Err(e) => return Err(e.into()),
            }
        }
    }

    /// The next reading in SI units (from `Uni:` when the board prints them, else `Raw:`).
    pub fn next_reading(
        &mut self,
        timeout: Duration,
    ) -> Result<Option<SketchReading>, MotionCalError> {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let Some(line) = self.next_line(left)? else {
                return Ok(None);
            };
            match line {
                SketchLine::Uni(values) => {
                    self.uni_seen = true;
                    self.pending_raw = None;
                    return Ok(Some(SketchReading::from_uni(values)));
                }
                SketchLine::Raw(counts) => {
                    // Two `Raw:` lines without a `Uni:` between: the board prints no `Uni:`.
                    let previous = self.pending_raw.replace(counts);
                    if let (Some(previous), false) = (previous, self.uni_seen) {
                        return Ok(Some(SketchReading::from_raw(previous, self.scaling)));
                    }
                }
                _ => {}
            }
        }
    }

    /// `count` readings, failing when the board stays silent for `gap`.
    pub fn collect_readings(
        &mut self,
        count: usize,
        gap: Duration,
    ) -> Result<Vec<SketchReading>, MotionCalError> {
        let mut readings = Vec::with_capacity(count);
        while readings.len() < count {
            match self.next_reading(gap)? {
                Some(r) => readings.push(r),
                None => {
                    return Err(MotionCalError::Timeout {
                        what: "sensor readings",
                        seconds: gap.as_secs_f64(),
                    })
                }
            }
        }
        Ok(readings)
    }

    /// Sends `cal` as a MotionCal packet and waits up to `timeout` for the board to echo it.
    pub fn send_calibration(
        &mut self,
        cal: &AdafruitCalibration,
        timeout: Duration,
    ) -> Result<EchoCheck, MotionCalError> {
        let packet = encode_packet(cal)?;
        self.link.write_all(&packet)?;
        self.link.flush()?;
        let sent1 = cal1_values(cal);
        let sent2 = cal.mag_softiron.iter().flatten().map(|v| f64::from(*v));
        let sent2: Vec<f64> = sent2.collect();
        let deadline = Instant::now() + timeout;
        let mut cal1: Option<[f64; 10]> = None;
        let mut last_mismatch = None;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let Some(line) = self.next_line(left)? else {
                return Err(last_mismatch.unwrap_or(MotionCalError::Timeout {
                    what: "Cal1:/Cal2: echo of the calibration",
                    seconds: timeout.as_secs_f64(),
                }));
            };
            match line {
                SketchLine::Text(text) if text.contains(SAVE_FAILED_TEXT) => {
                    return Err(MotionCalError::SaveFailed(text));
                }
                SketchLine::Cal1(values) => {
                    cal1 = compare("Cal1", &sent1, &values, CAL1_PRINT_TOLERANCE)
                        .map_err(|e| last_mismatch = Some(e))
                        .ok()
                        .map(|()| values);
                }
                SketchLine::Cal2(values) => {
                    let Some(echo1) = cal1 else { continue };
                    match compare("Cal2", &sent2, &values, CAL2_PRINT_TOLERANCE) {
                        Ok(()) => {
                            let diff = |s: &[f64], e: &[f64]| {
                                s.iter()
                                    .zip(e)
                                    .map(|(a, b)| (a - b).abs())
                                    .fold(0.0, f64::max)
                            };
                            return Ok(EchoCheck {
                                packet,
                                cal1: echo1,
                                cal2: values,
                                max_difference: diff(&sent1, &echo1).max(diff(&sent2, &values)),
                            });
                        }
                        Err(e) => last_mismatch = Some(e),
                    }
                }
                _ => {}
            }
        }
    }

    /// The link, e.g. to close it.
    pub fn into_link(self) -> L {
        self.link
    }
}

/// The ten `Cal1:` values of `cal` in the order the sketch prints them.
fn cal1_values(cal: &AdafruitCalibration) -> [f64; 10] {
    let mut v = [0.0; 10];
    let parts = cal
        .accel_zerog
        .iter()
        .chain(&cal.gyro_zerorate)
        .chain(&cal.mag_hardiron)
        .chain(std::iter::once(&cal.mag_field));
    for (out, value) in v.iter_mut().zip(parts) {
        *out = f64::from(*value);
    }
    v
}

fn compare(tag: &str, sent: &[f64], echoed: &[f64], print: f64) -> Result<(), MotionCalError> {
    for (i, (s, e)) in sent.iter().zip(echoed).enumerate() {
        // The board prints an f32, so allow its rounding on top of the printed decimals.
        let tolerance = print + s.abs() * 1e-6;
        if (s - e).abs() > tolerance {
            return Err(MotionCalError::EchoMismatch {
                field: format!("{tag} value {i}"),
                sent: *s,
                echoed: *e,
                tolerance,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A board that has printed `input`; what the host writes is kept.
    struct Recorded {
        input: std::io::Cursor<Vec<u8>>,
        written: Vec<u8>,
    }

    impl Read for Recorded {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            self.input.read(buf)
        }
    }

    impl Write for Recorded {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.written.extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    fn client(text: &str) -> MotionCalClient<Recorded> {
        let link = Recorded {
            input: std::io::Cursor::new(text.as_bytes().to_vec()),
            written: Vec::new(),
        };
        MotionCalClient::new(link, RawAccelScaling::AdafruitSketch)
    }

    #[test]
    fn a_board_without_uni_lines_is_read_from_raw_and_noise_is_counted() {
        let mut c =
            client("Raw:8192,0,0,16,0,0,10,0,0\r\nRaw:1,2\r\nRaw:0,8192,0,0,0,0,0,10,0\r\n");
        let first = c.next_reading(Duration::from_millis(50)).unwrap().unwrap();
        assert!((first.accel[0] - 9.8).abs() < 1e-12);
        assert!(!c.has_unified_lines());
        assert_eq!(c.malformed_lines(), 1);
    }

    #[test]
    fn uni_lines_are_preferred_over_raw() {
        let mut c = client("Raw:1,1,1,1,1,1,1,1,1\r\nUni:0.10,0.20,9.81,0.0100,0,0,20.00,0,40\r\n");
        let r = c.next_reading(Duration::from_millis(50)).unwrap().unwrap();
        assert_eq!(r.accel, [0.1, 0.2, 9.81]);
        assert!(c.has_unified_lines());
    }

    #[test]
    fn an_echo_of_other_values_is_a_mismatch_naming_the_value() {
        let cal = AdafruitCalibration::identity();
        let mut c = client("Cal1:0.000,0.000,0.000,0.000,0.000,0.000,5.000,0.000,0.000,0.000\r\n");
        let error = c
            .send_calibration(&cal, Duration::from_millis(50))
            .unwrap_err();
        assert!(
            matches!(&error, MotionCalError::EchoMismatch { field, .. } if field == "Cal1 value 6"),
            "{error}"
        );
        assert_eq!(
            c.into_link().written.len(),
            super::super::motioncal::PACKET_LEN
        );
    }
}
