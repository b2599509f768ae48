//! A simulated board running Adafruit's MotionCal calibration sketch (Adafruit_AHRS
//! `examples/calibration/calibration.ino`), with Adafruit_Sensor_Calibration storing what it
//! receives in an in-memory EEPROM.
//!
//! Each loop (every 10 ms of simulated time) the sketch reads the sensors as `Adafruit_Sensor`
//! events (SI units: the chip counts × nominal sensitivity), prints
//! `Raw:` with its integer scaling (`int(a·8192/9.8)`, `int(ω·57.29578·16)`, `int(B·10)`) and
//! `Uni:` with Arduino's float printing (2 decimals, 4 for the gyro), each ending `\r\n`; then
//! it feeds received bytes through the sketch's packet receiver (wait for 117, 84; collect 68
//! bytes; CRC-16 with 0xA001 from 0xFFFF over all 68 must be 0; otherwise look for 117, 84 inside
//! the buffer and keep the bytes from there). Like the sketch's `receiveCalibration()`, which
//! returns after nearly every byte, it takes one byte per loop, so a packet needs 68 loops
//! (0.68 s) to arrive. Then every 100 loops it prints `Cal1:` (3 decimals) at
//! loop 50 and `Cal2:` (4 decimals) at loop 100. The packet code here is written from the
//! sketch's description, independently of the host's encoder, so each checks the other.
//!
//! The person holding the board follows the twelve-position schedule and then tumbles it for the
//! magnetometer, then rests in the last orientation.

use crate::error::SimError;
use crate::physics::{ImuPhysics, ImuTruth, NominalScale, SensorKind};
use crate::poser::{build_schedule, ScheduleKind};
use crate::recording::{SimConfig, Simulation};
use crate::world::World;

/// Length of the sketch's calibration packet.
pub const PACKET_LEN: usize = 68;
/// Sketch loop period, µs (`delay(10)`; sensor reads are taken as instantaneous).
pub const LOOP_PERIOD_US: u64 = 10_000;
/// Adafruit_Sensor's `SENSORS_RADS_TO_DPS` (a float constant).
const RADS_TO_DPS: f32 = 57.295_78;
/// Text the sketch prints after storing a calibration.
pub const STORED_TEXT: &str = "Wrote calibration";

/// What Adafruit_Sensor_Calibration holds (its public members).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StoredCalibration {
    /// m/s², subtracted from the accelerometer.
    pub accel_zerog: [f32; 3],
    /// rad/s, subtracted from the gyroscope.
    pub gyro_zerorate: [f32; 3],
    /// µT, subtracted from the magnetometer before the soft iron.
    pub mag_hardiron: [f32; 3],
    /// µT, informational.
    pub mag_field: f32,
    /// Row-major 3×3.
    pub mag_softiron: [f32; 9],
}

impl Default for StoredCalibration {
    fn default() -> Self {
        Self {
            accel_zerog: [0.0; 3],
            gyro_zerorate: [0.0; 3],
            mag_hardiron: [0.0; 3],
            mag_field: 0.0,
            mag_softiron: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        }
    }
}

impl StoredCalibration {
    /// What the library's `calibrate()` makes of events in SI units (f32 as on the board).
    pub fn apply(&self, accel: [f32; 3], gyro: [f32; 3], mag: [f32; 3]) -> [[f32; 3]; 3] {
        let m = [0, 1, 2].map(|i| mag[i] - self.mag_hardiron[i]);
        let s = &self.mag_softiron;
        [
            [0, 1, 2].map(|i| accel[i] - self.accel_zerog[i]),
            [0, 1, 2].map(|i| gyro[i] - self.gyro_zerorate[i]),
            [0, 1, 2].map(|r| m[0] * s[3 * r] + m[1] * s[3 * r + 1] + m[2] * s[3 * r + 2]),
        ]
    }
}

/// The sketch's CRC-16 step (reflected polynomial 0xA001).
fn crc16_update(crc: u16, byte: u8) -> u16 {
    let mut crc = crc ^ u16::from(byte);
    for _ in 0..8 {
        crc = if crc & 1 != 0 {
            (crc >> 1) ^ 0xA001
        } else {
            crc >> 1
        };
    }
    crc
}

/// The sketch's byte-at-a-time packet receiver.
#[derive(Debug, Clone)]
pub struct PacketReceiver {
    buffer: [u8; PACKET_LEN],
    count: usize,
}

impl Default for PacketReceiver {
    fn default() -> Self {
        Self {
            buffer: [0; PACKET_LEN],
            count: 0,
        }
    }
}

impl PacketReceiver {
    /// Feeds one byte. Returns whether the sketch's receive function returns after it (it does
    /// after every byte except a full packet that was dropped without a signature inside), and
    /// the calibration when the byte completes a packet whose CRC checks.
    pub fn push(&mut self, byte: u8) -> (bool, Option<StoredCalibration>) {
        if (self.count == 0 && byte != 117) || (self.count == 1 && byte != 84) {
            self.count = 0;
            return (true, None);
        }
        self.buffer[self.count] = byte;
        self.count += 1;
        if self.count < PACKET_LEN {
            return (true, None);
        }
        if self.buffer.iter().fold(0xFFFF, |c, &b| crc16_update(c, b)) == 0 {
            self.count = 0;
            return (true, Some(self.decode()));
        }
        // Look for a signature inside the buffer before discarding it.
        if let Some(start) = (2..PACKET_LEN - 1).find(|&i| self.buffer[i..].starts_with(&[117, 84]))
        {
            self.buffer.copy_within(start.., 0);
            self.count = PACKET_LEN - start;
            return (true, None);
        }
        if self.buffer[PACKET_LEN - 1] == 117 {
            self.buffer[0] = 117;
            self.count = 1;
        } else {
            self.count = 0;
        }
        (false, None)
    }

    fn decode(&self) -> StoredCalibration {
        let f = |i: usize| {
            let at = 2 + 4 * i;
            f32::from_le_bytes([
                self.buffer[at],
                self.buffer[at + 1],
                self.buffer[at + 2],
                self.buffer[at + 3],
            ])
        };
        StoredCalibration {
            accel_zerog: [f(0), f(1), f(2)],
            gyro_zerorate: [f(3), f(4), f(5)],
            mag_hardiron: [f(6), f(7), f(8)],
            mag_field: f(9),
            mag_softiron: [
                f(10),
                f(13),
                f(14),
                f(13),
                f(11),
                f(15),
                f(14),
                f(15),
                f(12),
            ],
        }
    }
}

/// Arduino's `Print::printFloat`: add half a unit of the last digit, then print the integer part
/// and the digits one by one (truncating), `nan`/`inf`/`ovf` for values it cannot print.
pub fn arduino_float(value: f32, digits: u8) -> String {
    let mut number = f64::from(value);
    if number.is_nan() {
        return "nan".into();
    }
    if number.is_infinite() {
        return "inf".into();
    }
    if number.abs() > 4_294_967_040.0 {
        return "ovf".into();
    }
    let mut text = String::new();
    if number < 0.0 {
        text.push('-');
        number = -number;
    }
    let mut rounding = 0.5;
    for _ in 0..digits {
        rounding /= 10.0;
    }
    number += rounding;
    // In range after the ovf check; `as` truncates like the sketch's unsigned long.
    let int_part = number as u64;
    let mut remainder = number - int_part as f64;
    text.push_str(&int_part.to_string());
    if digits > 0 {
        text.push('.');
    }
    for _ in 0..digits {
        remainder *= 10.0;
        let digit = remainder as u32;
        text.push(char::from_digit(digit.min(9), 10).unwrap_or('9'));
        remainder -= f64::from(digit);
    }
    text
}

/// The simulated MotionCal sketch board (no I/O: bytes in, bytes out).
#[derive(Debug)]
pub struct MotionCalBoard {
    poses: World,
    tumble: World,
    physics: ImuPhysics,
    time_us: u64,
    loop_count: u32,
    received: Vec<u8>,
    receiver: PacketReceiver,
    eeprom: Option<StoredCalibration>,
    calibration: StoredCalibration,
    out: Vec<u8>,
    stored_count: u32,
    announced: u32,
    last_events: Option<[[f32; 3]; 3]>,
}

impl MotionCalBoard {
    /// A board with the sensor errors drawn from `seed` (as `SimConfig::new(seed, …)` does).
    pub fn new(seed: u64) -> Result<Self, SimError> {
        let mut config = SimConfig::new(seed, ScheduleKind::Twelve);
        config.sample_rate_hz = 1e6 / LOOP_PERIOD_US as f64;
        let twelve = Simulation::new(&config)?;
        let tumble_schedule = build_schedule(
            ScheduleKind::Tumble,
            &config.poser,
            &config.earth_field,
            seed,
        )?;
        let tumble = World {
            trajectory: tumble_schedule.trajectory,
            ..twelve.world.clone()
        };
        tumble.validate()?;
        Ok(Self {
            poses: twelve.world,
            tumble,
            physics: twelve.physics,
            time_us: 0,
            loop_count: 0,
            received: Vec::new(),
            receiver: PacketReceiver::default(),
            eeprom: None,
            calibration: StoredCalibration::default(),
            out: Vec::new(),
            stored_count: 0,
            announced: 0,
            last_events: None,
        })
    }

    /// The true sensor parameters.
    pub fn truth(&self) -> &ImuTruth {
        self.physics.truth()
    }

    /// The Earth's field magnitude at the simulated site, µT: what a host looks up for the
    /// board's location.
    pub fn site_field_ut(&self) -> f64 {
        self.poses.earth_field.magnitude_ut
    }

    /// Simulated seconds the schedule takes (twelve holds, then the tumble).
    pub fn schedule_duration_s(&self) -> f64 {
        self.poses.trajectory.duration_s() + self.tumble.trajectory.duration_s()
    }

    /// Simulated time, µs.
    pub fn time_us(&self) -> u64 {
        self.time_us
    }

    /// Bytes from the host (read by the sketch in its next loop).
    pub fn receive(&mut self, bytes: &[u8]) {
        self.received.extend_from_slice(bytes);
    }

    /// Bytes the board has printed since the last call.
    pub fn take_output(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.out)
    }

    /// What the in-memory EEPROM holds (`None` until a packet was stored).
    pub fn eeprom(&self) -> Option<StoredCalibration> {
        self.eeprom
    }

    /// Packets stored so far.
    pub fn stored_count(&self) -> u32 {
        self.stored_count
    }

    /// The last sensor events with the stored calibration applied, as an AHRS sketch using the
    /// library would see them (accel m/s², gyro rad/s, mag µT).
    pub fn calibrated_events(&self) -> Option<[[f32; 3]; 3]> {
        self.last_events
            .map(|[a, g, m]| self.calibration.apply(a, g, m))
    }

    /// Runs every sketch loop due up to `t_us`.
    pub fn advance_to(&mut self, t_us: u64) {
        while self.time_us + LOOP_PERIOD_US <= t_us {
            self.time_us += LOOP_PERIOD_US;
            self.run_loop();
        }
    }

    fn events(&mut self) -> [[f32; 3]; 3] {
        let t = self.time_us as f64 * 1e-6;
        let split = self.poses.trajectory.duration_s();
        let state = if t < split {
            self.poses.state(t)
        } else {
            self.tumble.state(t - split)
        };
        let sample = self.physics.sample(&state);
        let si = |kind: SensorKind| {
            let v = sample.sensor(kind).nominal(kind.units_per_count());
            [v.x as f32, v.y as f32, v.z as f32]
        };
        [
            si(SensorKind::Accel),
            si(SensorKind::Gyro),
            si(SensorKind::Mag),
        ]
    }

    fn print_line(&mut self, line: &str) {
        self.out.extend_from_slice(line.as_bytes());
        self.out.extend_from_slice(b"\r\n");
    }

    fn run_loop(&mut self) {
        let [a, g, m] = self.events();
        self.last_events = Some([a, g, m]);
        // `int()` truncates toward zero; `as` does the same and saturates.
        let raw_a = a.map(|v| (f64::from(v * 8192.0) / 9.8) as i32);
        let raw_g = g.map(|v| (v * RADS_TO_DPS * 16.0) as i32);
        let raw_m = m.map(|v| (v * 10.0) as i32);
        let raw: Vec<String> = raw_a
            .iter()
            .chain(&raw_g)
            .chain(&raw_m)
            .map(i32::to_string)
            .collect();
        self.print_line(&format!("Raw:{}", raw.join(",")));
        let uni: Vec<String> = a
            .iter()
            .map(|v| arduino_float(*v, 2))
            .chain(g.iter().map(|v| arduino_float(*v, 4)))
            .chain(m.iter().map(|v| arduino_float(*v, 2)))
            .collect();
        self.print_line(&format!("Uni:{}", uni.join(",")));
        self.loop_count += 1;
        self.receive_calibration();
        if self.loop_count == 50 || self.loop_count > 100 {
            let c = self.calibration;
            let values: Vec<String> = c
                .accel_zerog
                .iter()
                .chain(&c.gyro_zerorate)
                .chain(&c.mag_hardiron)
                .chain(std::iter::once(&c.mag_field))
                .map(|v| arduino_float(*v, 3))
                .collect();
            self.print_line(&format!("Cal1:{}", values.join(",")));
            self.loop_count += 1;
        }
        if self.loop_count >= 100 {
            let soft: Vec<String> = self
                .calibration
                .mag_softiron
                .iter()
                .map(|v| arduino_float(*v, 4))
                .collect();
            self.print_line(&format!("Cal2:{}", soft.join(",")));
            self.loop_count = 0;
        }
    }

    fn receive_calibration(&mut self) {
        let mut taken = 0;
        for &byte in &self.received {
            taken += 1;
            let (returns, stored) = self.receiver.push(byte);
            if let Some(calibration) = stored {
                self.calibration = calibration;
                self.eeprom = Some(calibration);
                self.stored_count += 1;
            }
            if returns {
                break;
            }
        }
        self.received.drain(..taken);
        if self.eeprom.is_some() && self.stored_count > self.announced {
            self.announced = self.stored_count;
            self.print_line(STORED_TEXT);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arduino_float_printing_rounds_half_up_and_keeps_the_sign_of_small_negatives() {
        assert_eq!(arduino_float(9.806, 2), "9.81");
        assert_eq!(arduino_float(-0.001, 2), "-0.00");
        assert_eq!(arduino_float(0.12345, 4), "0.1235");
        assert_eq!(arduino_float(1.0, 3), "1.000");
        assert_eq!(arduino_float(f32::NAN, 2), "nan");
    }
}
