//! PJRC MotionCal's serial formats, as a board running Adafruit's calibration sketch speaks them.
//!
//! Checked against the public sources: MotionCal `imuread.h` (`G_PER_COUNT` = 1/8192 g,
//! `DEG_PER_SEC_PER_COUNT` = 1/16 °/s, `UT_PER_COUNT` = 0.1 µT), MotionCal `rawdata.c`
//! (`send_calibration`: signature 117, 84, floats least significant byte first, CRC-16 with the
//! reflected polynomial 0xA001 from 0xFFFF, low byte first), Adafruit_AHRS
//! `examples/calibration/calibration.ino` (the `Raw:` line scales accel as m/s²·8192/**9.8**,
//! gyro as rad/s·(180/π)·16, mag as µT·10, each truncated by `int()`; `Uni:` prints the same
//! readings in SI with 2 decimals, 4 for the gyro; `Cal1:`/`Cal2:` echo what is stored; lines end
//! with `println`, i.e. `\r\n`; the 68-byte receiver and its float order) and
//! Adafruit_Sensor_Calibration `Adafruit_Sensor_Calibration.cpp` (`crc16_update`).
//!
//! Packet layout (68 bytes): `117, 84`, then 16 `f32` little-endian — accel zero-g ×3 (m/s²),
//! gyro zero-rate ×3 (rad/s), hard iron ×3 (µT), field (µT), soft iron `[0][0] [1][1] [2][2]
//! [0][1] [0][2] [1][2]` — then CRC-16/MODBUS of bytes 0–65, low byte first. The CRC over all 68
//! bytes is then 0, which is how the sketch checks it.

use super::adafruit::AdafruitCalibration;
use super::CompatError;
use thiserror::Error;

/// First two bytes of a calibration packet.
pub const PACKET_SIGNATURE: [u8; 2] = [117, 84];
/// Length of a calibration packet, bytes.
pub const PACKET_LEN: usize = 68;
/// Number of `f32` values a packet carries.
const PACKET_FLOATS: usize = 16;

/// MotionCal's accelerometer unit: g per `Raw:` count.
pub const G_PER_COUNT: f64 = 1.0 / 8192.0;
/// MotionCal's gyroscope unit: °/s per `Raw:` count.
pub const DPS_PER_COUNT: f64 = 1.0 / 16.0;
/// MotionCal's magnetometer unit: µT per `Raw:` count.
pub const UT_PER_COUNT: f64 = 0.1;
/// The "g" Adafruit's sketch divides by when it makes `Raw:` accel counts (m/s²·8192/9.8).
pub const ADAFRUIT_SKETCH_G_MPS2: f64 = 9.8;
/// Standard gravity, m/s², for boards whose `Raw:` counts are true 1/8192 g counts.
pub const STANDARD_G_MPS2: f64 = 9.806_65;

/// CRC-16/MODBUS: reflected polynomial 0xA001, initial value 0xFFFF, no final xor.
pub fn crc16_modbus(bytes: &[u8]) -> u16 {
    bytes.iter().fold(0xFFFF_u16, |crc, &byte| {
        let mut crc = crc ^ u16::from(byte);
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xA001
            } else {
                crc >> 1
            };
        }
        crc
    })
}

/// Why a received packet was refused.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
pub enum PacketError {
    /// Not 68 bytes.
    #[error("a calibration packet has {PACKET_LEN} bytes, this one has {0}")]
    Length(usize),
    /// Does not start with 117, 84.
    #[error("a calibration packet starts with 117, 84; this one starts with {0}, {1}")]
    Signature(u8, u8),
    /// The CRC does not match: the bytes were damaged on the way.
    #[error("the packet's CRC is {found:#06x} but its bytes give {computed:#06x}; resend it")]
    Crc {
        /// CRC carried by the packet.
        found: u16,
        /// CRC of bytes 0–65.
        computed: u16,
    },
    /// A value is NaN or infinite.
    #[error("value {0} of the packet is not a finite number; the sender is broken")]
    NotFinite(usize),
}

/// The 68-byte packet MotionCal sends, carrying `cal` (whose soft iron must be symmetric).
pub fn encode_packet(cal: &AdafruitCalibration) -> Result<[u8; PACKET_LEN], CompatError> {
    cal.check_finite()?;
    let s = &cal.mag_softiron;
    for (row, col) in [(0, 1), (0, 2), (1, 2)] {
        let gap = (s[row][col] - s[col][row]).abs();
        if gap > 1e-6 * s[row][col].abs().max(1.0) {
            return Err(CompatError::NotSymmetric { row, col, gap });
        }
    }
    let values: [f32; PACKET_FLOATS] = [
        cal.accel_zerog[0],
        cal.accel_zerog[1],
        cal.accel_zerog[2],
        cal.gyro_zerorate[0],
        cal.gyro_zerorate[1],
        cal.gyro_zerorate[2],
        cal.mag_hardiron[0],
        cal.mag_hardiron[1],
        cal.mag_hardiron[2],
        cal.mag_field,
        s[0][0],
        s[1][1],
        s[2][2],
        s[0][1],
        s[0][2],
        s[1][2],
    ];
    let mut packet = [0u8; PACKET_LEN];
    packet[..2].copy_from_slice(&PACKET_SIGNATURE);
    for (chunk, value) in packet[2..PACKET_LEN - 2].chunks_exact_mut(4).zip(values) {
        chunk.copy_from_slice(&value.to_le_bytes());
    }
    let crc = crc16_modbus(&packet[..PACKET_LEN - 2]);
    packet[PACKET_LEN - 2..].copy_from_slice(&crc.to_le_bytes());
    Ok(packet)
}

/// Reads a 68-byte packet back, checking its signature, CRC and values.
pub fn decode_packet(bytes: &[u8]) -> Result<AdafruitCalibration, PacketError> {
    let packet: &[u8; PACKET_LEN] = bytes
        .try_into()
        .map_err(|_| PacketError::Length(bytes.len()))?;
    if packet[..2] != PACKET_SIGNATURE {
        return Err(PacketError::Signature(packet[0], packet[1]));
    }
    let computed = crc16_modbus(&packet[..PACKET_LEN - 2]);
    let found = u16::from_le_bytes([packet[PACKET_LEN - 2], packet[PACKET_LEN - 1]]);
    if computed != found {
        return Err(PacketError::Crc { found, computed });
    }
    let mut v = [0f32; PACKET_FLOATS];
    for (i, (value, chunk)) in v
        .iter_mut()
        .zip(packet[2..PACKET_LEN - 2].chunks_exact(4))
        .enumerate()
    {
        *value = f32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]);
        if !value.is_finite() {
            return Err(PacketError::NotFinite(i));
        }
    }
    Ok(AdafruitCalibration {
        accel_zerog: [v[0], v[1], v[2]],
        gyro_zerorate: [v[3], v[4], v[5]],
        mag_hardiron: [v[6], v[7], v[8]],
        mag_field: v[9],
        mag_softiron: [
            [v[10], v[13], v[14]],
            [v[13], v[11], v[15]],
            [v[14], v[15], v[12]],
        ],
    })
}

/// How a board scaled its `Raw:` accelerometer counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RawAccelScaling {
    /// Adafruit's sketch: counts = m/s²·8192/9.8.
    #[default]
    AdafruitSketch,
    /// PJRC's sketches: counts of 1/8192 g (standard gravity).
    StandardG,
}

impl RawAccelScaling {
    /// m/s² per `Raw:` accelerometer count.
    pub fn mps2_per_count(self) -> f64 {
        match self {
            Self::AdafruitSketch => ADAFRUIT_SKETCH_G_MPS2 * G_PER_COUNT,
            Self::StandardG => STANDARD_G_MPS2 * G_PER_COUNT,
        }
    }
}

/// One reading of the nine sensor axes in SI units: m/s², rad/s, µT.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SketchReading {
    /// Accelerometer, m/s².
    pub accel: [f64; 3],
    /// Gyroscope, rad/s.
    pub gyro: [f64; 3],
    /// Magnetometer, µT.
    pub mag: [f64; 3],
}

impl SketchReading {
    /// A `Raw:` line's counts in SI units with MotionCal's scales and `scaling` for the accel.
    pub fn from_raw(counts: [i32; 9], scaling: RawAccelScaling) -> Self {
        Self::from_counts(counts.map(f64::from), scaling)
    }

    /// [`SketchReading::from_raw`] of counts read as numbers (a saved log's `Raw:` lines): the
    /// one conversion live readings and saved logs share.
    pub fn from_counts(counts: [f64; 9], scaling: RawAccelScaling) -> Self {
        let accel = scaling.mps2_per_count();
        let gyro = DPS_PER_COUNT.to_radians();
        let at = |i: usize, k: f64| counts[i] * k;
        Self {
            accel: [at(0, accel), at(1, accel), at(2, accel)],
            gyro: [at(3, gyro), at(4, gyro), at(5, gyro)],
            mag: [
                at(6, UT_PER_COUNT),
                at(7, UT_PER_COUNT),
                at(8, UT_PER_COUNT),
            ],
        }
    }

    /// A `Uni:` line's nine values.
    pub fn from_uni(v: [f64; 9]) -> Self {
        Self {
            accel: [v[0], v[1], v[2]],
            gyro: [v[3], v[4], v[5]],
            mag: [v[6], v[7], v[8]],
        }
    }
}

/// One line a MotionCal-compatible board prints.
#[derive(Debug, Clone, PartialEq)]
pub enum SketchLine {
    /// `Raw:` nine integer counts (accel, gyro, mag).
    Raw([i32; 9]),
    /// `Uni:` nine SI values (m/s², rad/s, µT).
    Uni([f64; 9]),
    /// `Cal1:` accel zero-g ×3, gyro zero-rate ×3, hard iron ×3, field.
    Cal1([f64; 10]),
    /// `Cal2:` soft iron, 9 values row-major.
    Cal2([f64; 9]),
    /// Any other text (the sketch's messages, e.g. "Wrote calibration").
    Text(String),
}

/// Why a tagged line could not be read.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
#[error("malformed `{tag}` line `{line}`: {reason}; check the board's baud rate and sketch")]
pub struct LineError {
    /// The tag (`Raw:` …).
    pub tag: &'static str,
    /// The line as received.
    pub line: String,
    /// What is wrong.
    pub reason: String,
}

fn fields<T: std::str::FromStr, const N: usize>(
    tag: &'static str,
    line: &str,
    body: &str,
) -> Result<[T; N], LineError> {
    let error = |reason: String| LineError {
        tag,
        line: line.to_owned(),
        reason,
    };
    let parts: Vec<&str> = body.split(',').map(str::trim).collect();
    if parts.len() != N {
        return Err(error(format!("{} values, expected {N}", parts.len())));
    }
    let values: Vec<T> = parts
        .iter()
        .map(|p| {
            p.parse()
                .map_err(|_| error(format!("`{p}` is not a number")))
        })
        .collect::<Result<_, _>>()?;
    values
        .try_into()
        .map_err(|_| error(format!("expected {N} values")))
}

fn finite<const N: usize>(
    tag: &'static str,
    line: &str,
    v: [f64; N],
) -> Result<[f64; N], LineError> {
    match v.iter().position(|x| !x.is_finite()) {
        None => Ok(v),
        Some(i) => Err(LineError {
            tag,
            line: line.to_owned(),
            reason: format!("value {i} is not finite"),
        }),
    }
}

/// The `N` finite numbers after `tag`.
fn numbers<const N: usize>(
    tag: &'static str,
    line: &str,
    body: &str,
) -> Result<[f64; N], LineError> {
    finite(tag, line, fields(tag, line, body)?)
}

/// Reads one line (without its line ending).
pub fn parse_line(line: &str) -> Result<SketchLine, LineError> {
    let line = line.trim_matches(|c| c == '\r' || c == '\n');
    if let Some(body) = line.strip_prefix("Raw:") {
        Ok(SketchLine::Raw(fields("Raw:", line, body)?))
    } else if let Some(body) = line.strip_prefix("Uni:") {
        Ok(SketchLine::Uni(numbers("Uni:", line, body)?))
    } else if let Some(body) = line.strip_prefix("Cal1:") {
        Ok(SketchLine::Cal1(numbers("Cal1:", line, body)?))
    } else if let Some(body) = line.strip_prefix("Cal2:") {
        Ok(SketchLine::Cal2(numbers("Cal2:", line, body)?))
    } else {
        Ok(SketchLine::Text(line.to_owned()))
    }
}

/// The tag of the first line in `bytes` that a MotionCal sketch prints and parses as one
/// (`Raw:`, `Uni:`, `Cal1:`, `Cal2:`), or `None`: what tells, on a port that answers none of
/// imucal's requests, a board running such a sketch. Two such lines are asked for, so a stray
/// byte run that happens to spell a tag does not count.
pub fn sketch_tag_in(bytes: &[u8]) -> Option<&'static str> {
    let mut first = None;
    let mut count = 0;
    for line in LineSplitter::new().push(bytes) {
        let tag = match parse_line(&line) {
            Ok(SketchLine::Raw(_)) => "Raw:",
            Ok(SketchLine::Uni(_)) => "Uni:",
            Ok(SketchLine::Cal1(_)) => "Cal1:",
            Ok(SketchLine::Cal2(_)) => "Cal2:",
            _ => continue,
        };
        first.get_or_insert(tag);
        count += 1;
        if count >= 2 {
            return first;
        }
    }
    None
}

/// Splits a byte stream into lines at `\n`, `\r` or `\r\n` (MotionCal ends a line at `\r`,
/// the sketch's `println` sends `\r\n`); empty lines are skipped.
#[derive(Debug, Default, Clone)]
pub struct LineSplitter {
    partial: Vec<u8>,
}

/// Longest line kept; longer ones are noise (wrong baud rate) and are dropped.
const MAX_LINE: usize = 512;

impl LineSplitter {
    /// An empty splitter.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds received bytes; returns the lines they complete, oldest first (lossy UTF-8).
    pub fn push(&mut self, bytes: &[u8]) -> Vec<String> {
        let mut lines = Vec::new();
        for &b in bytes {
            if b == b'\r' || b == b'\n' {
                if !self.partial.is_empty() {
                    lines.push(String::from_utf8_lossy(&self.partial).into_owned());
                    self.partial.clear();
                }
            } else if self.partial.len() < MAX_LINE {
                self.partial.push(b);
            } else {
                self.partial.clear();
            }
        }
        lines
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_of_the_standard_check_string_is_the_modbus_check_value() {
        // CRC-16/MODBUS catalogue check value for "123456789".
        assert_eq!(crc16_modbus(b"123456789"), 0x4B37);
    }

    #[test]
    fn lines_split_at_cr_lf_and_crlf_across_chunks() {
        let mut s = LineSplitter::new();
        assert_eq!(s.push(b"Raw:1,2"), Vec::<String>::new());
        assert_eq!(s.push(b",3\r\nUni:4\rX\n"), vec!["Raw:1,2,3", "Uni:4", "X"]);
    }

    #[test]
    fn raw_line_with_a_missing_value_is_refused_with_its_text() {
        let error = parse_line("Raw:1,2,3,4,5,6,7,8").unwrap_err();
        assert!(
            error.to_string().contains("8 values, expected 9"),
            "{error}"
        );
        assert!(parse_line("Uni:1,2,3,4,5,6,7,8,nan").is_err());
    }

    #[test]
    fn adafruit_raw_counts_invert_the_sketch_scaling() {
        // 8192 counts = 9.8 m/s² in Adafruit's sketch, 1/16 °/s and 0.1 µT per count.
        let r = SketchReading::from_raw(
            [8192, 0, -8192, 16, 0, 0, 500, 0, -10],
            RawAccelScaling::AdafruitSketch,
        );
        assert!((r.accel[0] - 9.8).abs() < 1e-12 && (r.accel[2] + 9.8).abs() < 1e-12);
        assert!((r.gyro[0] - 1f64.to_radians()).abs() < 1e-12);
        assert!((r.mag[0] - 50.0).abs() < 1e-12 && (r.mag[2] + 1.0).abs() < 1e-12);
    }
}
