//! Shared bench for the device tests: a fake IMU, an in-memory link, a step
//! clock and a RAM flash around a real [`Device`], a seeded PRNG, an independent COBS/CRC frame
//! builder (so raw payloads with unknown variants or truncated bodies can be framed), and
//! generators of plausible and hostile calibration sets.
#![allow(dead_code, reason = "each test binary uses a different subset")]

use std::cell::Cell;
use std::rc::Rc;

use imucal_firmware::device::{Device, DeviceInfo};
use imucal_firmware::imu::{RawSample, SensorScales};
use imucal_firmware::ram_flash::RamFlash;
use imucal_firmware::store::ParamStore;
use imucal_protocol::{
    encode_frame, BiasTemperature, CalibrationSet, DeviceId, DeviceMessage, Event, FirmwareVersion,
    FrameDecoder, Nonlinearity, Request, RequestBody, ResponseBody, SensorSet, MAX_FRAME,
};
pub use imucal_test_kit::shared::{FixedImu, MemoryLink, StepClock};

/// Sample period of the fake IMU, µs (100 Hz).
pub const PERIOD_US: u64 = 10_000;
/// Bytes the device reads per `poll()` at most (its flood limit, `MAX_RX_BYTES_PER_POLL`).
pub const RX_BYTES_PER_POLL: usize = 256;
/// Parameter slot size used by every bench: two slots of two 1 KiB sectors.
pub const SLOT_SIZE: u32 = 2048;

/// The flash of every bench: 8 KiB, 1 KiB sectors, 4-byte program words.
pub type Flash = RamFlash<8192, 1024, 4>;
/// The device under test.
pub type BenchDevice = Device<FixedImu, MemoryLink, Flash, StepClock, 32>;

/// xorshift64* — small, fast and deterministic; quality is ample for choosing test inputs.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    /// A generator from a non-zero seed (zero is mapped to a fixed non-zero state).
    pub fn new(seed: u64) -> Self {
        Self(if seed == 0 {
            0x9E37_79B9_7F4A_7C15
        } else {
            seed
        })
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// The next 32 random bits.
    pub fn next_u32(&mut self) -> u32 {
        (self.next_u64() >> 32) as u32
    }

    /// Uniform in `0..n` (`n > 0`); the modulo bias is below 2⁻³² for the sizes used here.
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }

    /// `true` with probability `p`.
    pub fn chance(&mut self, p: f64) -> bool {
        self.unit() < p
    }

    /// Uniform in `[0, 1)`.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `[low, high)`.
    pub fn range(&mut self, low: f64, high: f64) -> f32 {
        (low + (high - low) * self.unit()) as f32
    }

    /// A random byte.
    pub fn byte(&mut self) -> u8 {
        self.next_u64() as u8
    }

    /// `len` random bytes, with 0x00 made frequent when `zeros` (to cut frames).
    pub fn bytes(&mut self, len: usize, zeros: bool) -> Vec<u8> {
        (0..len)
            .map(|_| {
                if zeros && self.chance(0.02) {
                    0
                } else {
                    self.byte()
                }
            })
            .collect()
    }

    /// A float that is often an extreme: NaN, ±∞, ±0, limits, subnormals, or any bit pattern.
    pub fn hostile_f32(&mut self) -> f32 {
        const SPECIAL: [f32; 10] = [
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            0.0,
            -0.0,
            f32::MAX,
            f32::MIN,
            f32::MIN_POSITIVE,
            1.0e-45,
            -1.0e30,
        ];
        if self.chance(0.5) {
            SPECIAL[self.below(SPECIAL.len())]
        } else {
            f32::from_bits(self.next_u32())
        }
    }
}

/// LSM9DS1 at ±2 g, ±245 °/s, ±4 gauss, 100 Hz: the scales every bench device reports.
pub fn scales() -> SensorScales {
    SensorScales {
        accel_mps2_per_count: 0.061e-3 * 9.806_65,
        gyro_rads_per_count: 8.75e-3 * core::f32::consts::PI / 180.0,
        mag_ut_per_count: 0.014,
        temp_c_per_count: 1.0 / 16.0,
        temp_offset_c: 25.0,
        accel_range_mps2: 2.0 * 9.806_65,
        gyro_range_rads: 245.0 * core::f32::consts::PI / 180.0,
        mag_range_ut: 400.0,
        sample_rate_hz: 1.0e6 / PERIOD_US as f32,
    }
}

/// Identity of the bench board.
pub fn info() -> DeviceInfo {
    DeviceInfo {
        device_id: DeviceId::from_u64(0x0123_4567_89AB_CDEF),
        firmware_version: FirmwareVersion {
            major: 0,
            minor: 1,
            patch: 0,
        },
        sensors: SensorSet {
            accel: true,
            gyro: true,
            mag: true,
            temp: true,
        },
    }
}

/// A board still and flat: 1 g on z, small offsets elsewhere, 30 °C.
pub const STILL_SAMPLE: RawSample = RawSample {
    accel: [100, -200, 16_384],
    gyro: [30, -12, 5],
    mag: [2_000, -1_500, 3_000],
    temp: 80,
};

/// Replies and events the device sent, decoded.
#[derive(Debug, Default)]
pub struct Received {
    /// Responses as `(seq, body)`.
    pub responses: Vec<(u16, ResponseBody)>,
    /// Unsolicited events.
    pub events: Vec<Event>,
    /// Frames from the device that did not decode (must stay 0).
    pub bad_frames: usize,
}

/// A device on the bench with the host side of its link.
pub struct Bench {
    /// The device under test.
    pub device: BenchDevice,
    /// The clock's current time, µs.
    pub time: Rc<Cell<u64>>,
    /// The sample the IMU returns.
    pub sample: Rc<Cell<RawSample>>,
    /// The link's two queues.
    pub link: MemoryLink,
    decoder: FrameDecoder<MAX_FRAME>,
    next_seq: u16,
}

impl Bench {
    /// A device on an erased flash.
    pub fn new() -> Self {
        Self::boot(Flash::new())
    }

    /// Boot a device on `flash` (its power state and any scheduled cut are left as they are).
    pub fn boot(flash: Flash) -> Self {
        let time = Rc::new(Cell::new(1_000_000));
        let sample = Rc::new(Cell::new(STILL_SAMPLE));
        let imu = FixedImu {
            sample: sample.clone(),
            scales: scales(),
        };
        let link = MemoryLink::default();
        let store = ParamStore::new(flash, 0, SLOT_SIZE).expect("bench slot layout fits the flash");
        let device = Device::new(imu, link.clone(), store, StepClock(time.clone()), info())
            .expect("100 Hz is a valid rate");
        Self {
            device,
            time,
            sample,
            link,
            decoder: FrameDecoder::new(),
            next_seq: 0xFFF0,
        }
    }

    /// Power off, power on: the same flash with power restored, a fresh device.
    pub fn reboot(self) -> Self {
        let mut flash = self.into_flash();
        flash.restore_power();
        Self::boot(flash)
    }

    /// The device's flash, as it is now.
    pub fn into_flash(self) -> Flash {
        let (_, _, store, _) = self.device.into_parts();
        store.into_flash()
    }

    /// Queue raw bytes for the device.
    pub fn push_bytes(&mut self, bytes: &[u8]) {
        self.link.to_device.borrow_mut().extend(bytes);
    }

    /// Bytes still waiting for the device.
    pub fn pending_input(&self) -> usize {
        self.link.to_device.borrow().len()
    }

    /// Advance the clock one sample period and poll once; returns the bytes the poll consumed.
    pub fn step(&mut self) -> usize {
        let before = self.pending_input();
        self.time.set(self.time.get() + PERIOD_US);
        self.device.poll();
        before - self.pending_input()
    }

    /// Poll until every queued byte is consumed, checking the flood limit and progress of each
    /// poll (a poll that returns without reading available input would be a stall); returns the
    /// number of polls.
    pub fn drain(&mut self) -> usize {
        let mut polls = 0;
        loop {
            let waiting = self.pending_input();
            let consumed = self.step();
            polls += 1;
            assert!(
                consumed <= RX_BYTES_PER_POLL,
                "one poll read {consumed} bytes, above the flood limit"
            );
            if waiting == 0 {
                return polls;
            }
            assert!(consumed > 0, "a poll made no progress on {waiting} bytes");
        }
    }

    /// Poll `count` sample periods with no input, then discard the output.
    pub fn run_polls(&mut self, count: usize) {
        for _ in 0..count {
            self.step();
        }
        let received = self.collect();
        assert_eq!(received.bad_frames, 0, "device frames must decode");
    }

    /// The next sequence id (it wraps past `u16::MAX` after a few requests on purpose).
    pub fn next_seq(&mut self) -> u16 {
        self.next_seq = self.next_seq.wrapping_add(1);
        self.next_seq
    }

    /// Decode and clear everything the device sent.
    pub fn collect(&mut self) -> Received {
        let bytes: Vec<u8> = std::mem::take(&mut *self.link.from_device.borrow_mut());
        let mut received = Received::default();
        for message in self.decoder.messages::<DeviceMessage>(&bytes) {
            match message {
                Ok(DeviceMessage::Response(r)) => received.responses.push((r.seq, r.body)),
                Ok(DeviceMessage::Event(e)) => received.events.push(e),
                Err(_) => received.bad_frames += 1,
            }
        }
        received
    }

    /// Send `bytes`, drain them, and return the only response (panics on anything else).
    pub fn exchange(&mut self, bytes: &[u8]) -> Option<(u16, ResponseBody)> {
        self.push_bytes(bytes);
        self.drain();
        let received = self.collect();
        assert_eq!(received.bad_frames, 0, "device frames must decode");
        assert!(received.responses.len() <= 1, "{:?}", received.responses);
        received.responses.into_iter().next()
    }

    /// Send a well-formed request and return the body of its reply (which must echo the seq).
    pub fn request(&mut self, body: RequestBody) -> ResponseBody {
        let seq = self.next_seq();
        let frame = request_frame(seq, &body);
        let (echoed, reply) = self
            .exchange(&frame)
            .unwrap_or_else(|| panic!("no reply to {body:?}"));
        assert_eq!(echoed, seq, "the reply must echo the request's seq");
        reply
    }

    /// The active set as the device reports it over the link.
    pub fn get_params(&mut self) -> CalibrationSet {
        match self.request(RequestBody::GetParams) {
            ResponseBody::Params(set) => set,
            other => panic!("GetParams answered {other:?}"),
        }
    }

    /// Stage and commit `set`; returns the commit's reply, or the write's reply if it failed.
    pub fn write_and_commit(&mut self, set: &CalibrationSet) -> ResponseBody {
        let crc = set.crc32();
        match self.request(RequestBody::WriteParams { set: *set, crc }) {
            ResponseBody::ParamStatus(_) => self.request(RequestBody::CommitParams { crc }),
            failed => failed,
        }
    }
}

impl Default for Bench {
    fn default() -> Self {
        Self::new()
    }
}

/// CRC-32/ISO-HDLC, the frame CRC of the protocol.
const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// Frame arbitrary payload bytes: `COBS(payload ‖ crc32_le(payload)) ‖ 0x00`, written here
/// independently of the protocol crate so that payloads it would never produce can be sent.
pub fn frame_payload(payload: &[u8]) -> Vec<u8> {
    let mut data = payload.to_vec();
    data.extend(CRC32.checksum(payload).to_le_bytes());
    let mut out = Vec::with_capacity(data.len() + data.len() / 254 + 2);
    let mut code_at = 0;
    out.push(0);
    let mut code = 1u8;
    for &byte in &data {
        if byte == 0 {
            out[code_at] = code;
            code_at = out.len();
            out.push(0);
            code = 1;
        } else {
            out.push(byte);
            code += 1;
            if code == 0xFF {
                out[code_at] = code;
                code_at = out.len();
                out.push(0);
                code = 1;
            }
        }
    }
    out[code_at] = code;
    out.push(0);
    out
}

/// Postcard bytes of a request.
pub fn request_payload(seq: u16, body: &RequestBody) -> Vec<u8> {
    let request = Request {
        seq,
        body: body.clone(),
    };
    let mut buffer = [0u8; MAX_FRAME];
    let used = postcard::to_slice(&request, &mut buffer).expect("every request fits a frame");
    used.to_vec()
}

/// A request framed by the protocol crate's encoder.
pub fn request_frame(seq: u16, body: &RequestBody) -> Vec<u8> {
    let mut buffer = [0u8; MAX_FRAME];
    let len = encode_frame(
        &Request {
            seq,
            body: body.clone(),
        },
        &mut buffer,
    )
    .expect("every request fits a frame");
    buffer[..len].to_vec()
}

/// A plausible fitted set: small scale and cross-axis errors, offsets of a real part.
pub fn fitted_set() -> CalibrationSet {
    let mut set = CalibrationSet::identity();
    set.created_unix_s = 1_790_000_000;
    set.accel.a = [
        [1.02, 0.01, -0.005],
        [0.003, 0.98, 0.012],
        [-0.004, 0.006, 1.01],
    ];
    set.accel.b = [0.12, -0.3, 0.05];
    set.gyro.a = [[1.01, -0.02, 0.0], [0.015, 0.99, 0.004], [0.0, 0.01, 1.03]];
    set.gyro.b = [0.004, -0.002, 0.001];
    set.mag.a = [
        [1.0 / 48.0, 0.001, 0.0],
        [0.0, 1.0 / 52.0, -0.0005],
        [0.0, 0.0, 1.0 / 45.0],
    ];
    set.mag.b = [30.0, -12.0, 80.0];
    set
}

/// A random set near the validation limits, usually valid: gains 0.6–1.8, cross-axis up to
/// ±0.2, offsets up to 90 % of the range, every extended term present half the time and sized
/// up to the limit, reference temperatures over the −55…125 °C die range.
pub fn random_plausible_set(rng: &mut Rng) -> CalibrationSet {
    let s = scales();
    let mut set = CalibrationSet::identity();
    set.created_unix_s = rng.next_u64() >> rng.below(64);
    let ranges = [s.accel_range_mps2, s.gyro_range_rads, s.mag_range_ut];
    let sensors = [&mut set.accel, &mut set.gyro, &mut set.mag];
    for (sensor, range) in sensors.into_iter().zip(ranges) {
        for (row, values) in sensor.a.iter_mut().enumerate() {
            for (col, value) in values.iter_mut().enumerate() {
                *value = if row == col {
                    rng.range(0.6, 1.8)
                } else {
                    rng.range(-0.2, 0.2)
                };
            }
        }
        for b in &mut sensor.b {
            *b = rng.range(-0.9, 0.9) * range;
        }
        sensor.t_ref_c = rng.range(-55.0, 125.0);
        let dt = 125.0f32;
        if rng.chance(0.5) {
            let mut coeffs = [[0.0f32; 3]; 3];
            for (degree, row) in coeffs.iter_mut().enumerate() {
                for c in row {
                    // Each degree may use a third of the range at |ΔT| = 125 °C.
                    *c = rng.range(-1.0, 1.0) * range / 3.0 / dt.powi(degree as i32 + 1);
                }
            }
            sensor.bias_temp = Some(BiasTemperature { coeffs });
        }
        if rng.chance(0.5) {
            sensor.scale_temp = Some([0; 3].map(|_| rng.range(-0.5, 0.5) / dt));
        }
        if rng.chance(0.5) {
            // |q|·r + |k|·r² ≤ ½ with each term at most ¼.
            sensor.nonlinearity = Some(Nonlinearity {
                quadratic: [0; 3].map(|_| rng.range(-0.25, 0.25) / range),
                cubic: [0; 3].map(|_| rng.range(-0.25, 0.25) / (range * range)),
            });
        }
    }
    // The magnetometer is usually fitted to the unit field: gain about 1/50.
    if rng.chance(0.5) {
        for row in &mut set.mag.a {
            for value in row {
                *value /= 50.0;
            }
        }
    }
    if rng.chance(0.5) {
        let mut k = [[0.0f32; 3]; 3];
        for value in k.iter_mut().flatten() {
            *value = rng.range(-0.01, 0.01);
        }
        set.gyro_g_sensitivity = Some(k);
    }
    set.reference.gravity_mps2 = rng.range(9.77, 9.84);
    set.reference.field_ut = if rng.chance(0.5) {
        1.0
    } else {
        rng.range(25.0, 65.0)
    };
    set.residuals.accel_rms = rng.range(0.0, 0.1);
    set.residuals.gyro_rms = rng.range(0.0, 0.01);
    set.residuals.mag_rms = rng.range(0.0, 2.0);
    set
}

/// Mutable references to every `f32` of `set`, in declaration order (with all optional terms
/// present this is 107 fields).
pub fn float_fields(set: &mut CalibrationSet) -> Vec<&mut f32> {
    let mut fields: Vec<&mut f32> = Vec::new();
    for sensor in [&mut set.accel, &mut set.gyro, &mut set.mag] {
        fields.extend(sensor.a.iter_mut().flatten());
        fields.extend(sensor.b.iter_mut());
        fields.push(&mut sensor.t_ref_c);
        if let Some(t) = sensor.bias_temp.as_mut() {
            fields.extend(t.coeffs.iter_mut().flatten());
        }
        if let Some(s) = sensor.scale_temp.as_mut() {
            fields.extend(s.iter_mut());
        }
        if let Some(n) = sensor.nonlinearity.as_mut() {
            fields.extend(n.quadratic.iter_mut());
            fields.extend(n.cubic.iter_mut());
        }
    }
    if let Some(k) = set.gyro_g_sensitivity.as_mut() {
        fields.extend(k.iter_mut().flatten());
    }
    fields.push(&mut set.reference.gravity_mps2);
    fields.push(&mut set.reference.field_ut);
    fields.push(&mut set.residuals.accel_rms);
    fields.push(&mut set.residuals.gyro_rms);
    fields.push(&mut set.residuals.mag_rms);
    fields
}

/// A valid set with every optional term present (small, realistic values), so that
/// [`float_fields`] reaches every float the format has.
pub fn full_set() -> CalibrationSet {
    let mut set = fitted_set();
    for sensor in [&mut set.accel, &mut set.gyro, &mut set.mag] {
        sensor.t_ref_c = 25.0;
        sensor.bias_temp = Some(BiasTemperature {
            coeffs: [[1e-3, -2e-3, 5e-4], [1e-5, 0.0, -1e-5], [0.0, 1e-7, 0.0]],
        });
        sensor.scale_temp = Some([1e-4, -2e-4, 5e-5]);
        sensor.nonlinearity = Some(Nonlinearity {
            quadratic: [1e-4, 0.0, -1e-4],
            cubic: [0.0, 1e-6, 0.0],
        });
    }
    set.gyro_g_sensitivity = Some([[1e-4, 0.0, 0.0], [0.0, -2e-4, 0.0], [0.0, 0.0, 5e-5]]);
    set
}

/// Raw samples at the corners of the input space: every sensor on either rail or at zero, with
/// the die temperature at both ends of its `i16` range and in the middle.
pub fn corner_samples() -> Vec<RawSample> {
    let levels = [i16::MIN, -1, 0, i16::MAX];
    let mut samples = Vec::new();
    for temp in [i16::MIN, 0, i16::MAX] {
        for &x in &levels {
            for &y in &levels {
                samples.push(RawSample {
                    accel: [x, y, x],
                    gyro: [y, x, y],
                    mag: [x, x, y],
                    temp,
                });
            }
        }
    }
    samples
}
