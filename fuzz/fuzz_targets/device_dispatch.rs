//! libFuzzer target: arbitrary bytes into a whole firmware `Device` through `poll()`.
//!
//! The input is a program of operations so the fuzzer reaches past the CRC: `0` raw bytes to
//! the link, `1` a payload framed with a valid CRC (so any postcard body reaches the request
//! decoder and the dispatcher), `2` a new IMU sample, `3` idle polls, `4` a calibration set
//! decoded from the input, written with its correct CRC and committed. Checks: no panic; no poll
//! reads more than the 256-byte flood limit or stalls on available input; the active parameter
//! set changes only in a step that delivered an intact `CommitParams` or `ResetParams`, and then
//! validates and gives finite output at every corner of the input space; device output always
//! decodes; the device answers `Ping` at the end.
#![no_main]

use std::cell::Cell;
use std::rc::Rc;

use imucal_firmware::apply::Correction;
use imucal_firmware::device::{Device, DeviceInfo};
use imucal_firmware::imu::{RawSample, SensorScales};
use imucal_firmware::ram_flash::RamFlash;
use imucal_firmware::store::ParamStore;
use imucal_protocol::validate;
use imucal_protocol::{
    decode_payload, encode_frame, CalibrationSet, DeviceId, DeviceMessage, FirmwareVersion,
    FrameDecoder, Request, RequestBody, Response, ResponseBody, SensorSet, MAX_FRAME,
};
use imucal_test_kit::shared::{FixedImu, MemoryLink as Link, StepClock};
use libfuzzer_sys::fuzz_target;

const FLOOD_LIMIT: usize = 256;
const PERIOD_US: u64 = 10_000;

fn scales() -> SensorScales {
    SensorScales {
        accel_mps2_per_count: 0.061e-3 * 9.806_65,
        gyro_rads_per_count: 8.75e-3 * core::f32::consts::PI / 180.0,
        mag_ut_per_count: 0.014,
        temp_c_per_count: 1.0 / 16.0,
        temp_offset_c: 25.0,
        accel_range_mps2: 2.0 * 9.806_65,
        gyro_range_rads: 245.0 * core::f32::consts::PI / 180.0,
        mag_range_ut: 400.0,
        sample_rate_hz: 100.0,
    }
}

type Flash = RamFlash<8192, 1024, 4>;

struct Bench {
    device: Device<FixedImu, Link, Flash, StepClock, 32>,
    link: Link,
    time: Rc<Cell<u64>>,
    sample: Rc<Cell<RawSample>>,
    shadow: FrameDecoder<MAX_FRAME>,
    replies: FrameDecoder<MAX_FRAME>,
}

impl Bench {
    fn new() -> Self {
        let time = Rc::new(Cell::new(1_000_000));
        let sample = Rc::new(Cell::new(RawSample {
            accel: [100, -200, 16_384],
            gyro: [30, -12, 5],
            mag: [2_000, -1_500, 3_000],
            temp: 80,
        }));
        let link = Link::default();
        let store = ParamStore::new(Flash::new(), 0, 2048).expect("layout fits");
        let info = DeviceInfo {
            device_id: DeviceId::from_u64(1),
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
        };
        let device = Device::new(
            FixedImu {
                sample: sample.clone(),
                scales: scales(),
            },
            link.clone(),
            store,
            StepClock(time.clone()),
            info,
        )
        .expect("valid rate");
        Self {
            device,
            link,
            time,
            sample,
            shadow: FrameDecoder::new(),
            replies: FrameDecoder::new(),
        }
    }

    fn poll(&mut self) -> usize {
        let before = self.link.to_device.borrow().len();
        self.time.set(self.time.get() + PERIOD_US);
        self.device.poll();
        before - self.link.to_device.borrow().len()
    }

    /// Deliver `bytes`, poll until consumed, check every invariant, and return the replies.
    fn deliver(&mut self, bytes: &[u8]) -> Vec<Response> {
        let mut commits = false;
        for &byte in bytes {
            if let Some(Ok(payload)) = self.shadow.push(byte) {
                commits |= decode_payload::<Request>(payload).is_ok_and(|r| {
                    matches!(
                        r.body,
                        RequestBody::CommitParams { .. } | RequestBody::ResetParams
                    )
                });
            }
        }
        let before = to_bytes(self.device.active_params());
        self.link.to_device.borrow_mut().extend(bytes);
        loop {
            let waiting = self.link.to_device.borrow().len();
            let consumed = self.poll();
            assert!(consumed <= FLOOD_LIMIT, "read {consumed} bytes in one poll");
            if waiting == 0 {
                break;
            }
            assert!(consumed > 0, "stalled on {waiting} bytes");
        }
        let responses = self.check_output();
        let active = *self.device.active_params();
        if to_bytes(&active) != before {
            assert!(commits, "active set changed without a commit");
            assert_eq!(validate(&active, &scales()), Ok(()));
            check_corners(&active);
        }
        responses
    }

    fn check_output(&mut self) -> Vec<Response> {
        let bytes = std::mem::take(&mut *self.link.from_device.borrow_mut());
        let mut responses = Vec::new();
        for message in self.replies.messages::<DeviceMessage>(&bytes) {
            match message.expect("device output decodes") {
                DeviceMessage::Response(response) => responses.push(response),
                DeviceMessage::Event(_) => {}
            }
        }
        responses
    }
}

fn to_bytes<T: serde::Serialize>(value: &T) -> Vec<u8> {
    let mut buffer = [0u8; 1024];
    postcard::to_slice(value, &mut buffer)
        .map(|used| used.to_vec())
        .unwrap_or_default()
}

fn check_corners(set: &CalibrationSet) {
    let correction = Correction::new(set, &scales()).expect("the active set validates");
    let levels = [i16::MIN, -1, 0, i16::MAX];
    for temp in [i16::MIN, 0, i16::MAX] {
        for &x in &levels {
            for &y in &levels {
                let out = correction.apply(&RawSample {
                    accel: [x, y, x],
                    gyro: [y, x, y],
                    mag: [x, x, y],
                    temp,
                });
                let values = out.accel.iter().chain(&out.gyro).chain(&out.mag);
                assert!(
                    values.clone().all(|v| v.is_finite()),
                    "{out:?} under {set:?}"
                );
            }
        }
    }
}

const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// `0x00 ‖ COBS(payload ‖ crc32_le(payload)) ‖ 0x00`.
fn frame_payload(payload: &[u8]) -> Vec<u8> {
    let mut data = payload.to_vec();
    data.extend(CRC32.checksum(payload).to_le_bytes());
    let mut out = vec![0, 0];
    let mut code_at = 1;
    let mut code = 1u8;
    for &byte in &data {
        if byte != 0 {
            out.push(byte);
            code += 1;
        }
        if byte == 0 || code == 0xFF {
            out[code_at] = code;
            code_at = out.len();
            out.push(0);
            code = 1;
        }
    }
    out[code_at] = code;
    out.push(0);
    out
}

/// The fuzz input, consumed from the front.
struct Input<'a>(&'a [u8]);

impl<'a> Input<'a> {
    /// The next `n` bytes (fewer at the end).
    fn take(&mut self, n: usize) -> &'a [u8] {
        let (head, tail) = self.0.split_at(n.min(self.0.len()));
        self.0 = tail;
        head
    }
}

fuzz_target!(|data: &[u8]| {
    let mut bench = Bench::new();
    let mut input = Input(data);
    while let [op] = input.take(1) {
        match op % 5 {
            0 => {
                let len = input.take(1).first().copied().unwrap_or(0);
                let bytes = input.take(usize::from(len)).to_vec();
                let _ = bench.deliver(&bytes);
            }
            1 => {
                let len = match input.take(2) {
                    [low, high] => usize::from(u16::from_le_bytes([*low, *high])) % 600,
                    _ => 0,
                };
                let payload = input.take(len).to_vec();
                let _ = bench.deliver(&frame_payload(&payload));
            }
            2 => {
                let mut words = [0i16; 10];
                for word in &mut words {
                    if let [low, high] = input.take(2) {
                        *word = i16::from_le_bytes([*low, *high]);
                    }
                }
                let [ax, ay, az, gx, gy, gz, mx, my, mz, temp] = words;
                bench.sample.set(RawSample {
                    accel: [ax, ay, az],
                    gyro: [gx, gy, gz],
                    mag: [mx, my, mz],
                    temp,
                });
            }
            4 => {
                // A set decoded from the input, sent with its correct CRC and committed, so the
                // fuzzer explores set contents past the CRC check.
                let Ok((set, rest)) = postcard::take_from_bytes::<CalibrationSet>(input.0) else {
                    continue;
                };
                input.0 = rest;
                let crc = set.crc32();
                let mut bytes = vec![0];
                for body in [
                    RequestBody::WriteParams { set, crc },
                    RequestBody::CommitParams { crc },
                ] {
                    let mut frame = [0u8; MAX_FRAME];
                    let request = Request { seq: 1, body };
                    let len = encode_frame(&request, &mut frame).expect("requests fit");
                    bytes.extend_from_slice(&frame[..len]);
                }
                let _ = bench.deliver(&bytes);
            }
            _ => {
                let polls = input.take(1).first().copied().unwrap_or(0);
                for _ in 0..polls {
                    bench.poll();
                }
                bench.check_output();
            }
        }
    }
    // Still answering.
    let mut frame = [0u8; MAX_FRAME];
    let ping = Request {
        seq: 7,
        body: RequestBody::Ping(0xC0FFEE),
    };
    let len = encode_frame(&ping, &mut frame).expect("ping fits");
    let mut bytes = vec![0];
    bytes.extend_from_slice(&frame[..len]);
    let responses = bench.deliver(&bytes);
    let pong = responses
        .iter()
        .find(|r| r.seq == 7 && r.body == ResponseBody::Pong(0xC0FFEE));
    assert!(pong.is_some(), "no pong in {responses:?}");
});
