//! Instruction-count bench of the firmware's hot paths, run under QEMU with the counting plugin of
//! `cargo xtask firmware bench`.
//!
//! Each measured region lies between calls of [`imucal_bench_start`] and [`imucal_bench_stop`];
//! the plugin prints the instructions executed in between. The regions run in the order of
//! [`REGIONS`], each for [`ITERATIONS`] iterations: an empty loop (the loop's own overhead), the
//! calibration `Correction::apply` with a plain `A·(x − b)` set and with every extended term, and
//! `Device::poll` taking one sample per call while streaming calibrated batches into a RAM sink.
//! Per-sample costs are (region − empty) / ITERATIONS.
//!
//! The empty and apply loops differ only by the call of `apply`: both take their sample from a
//! table made at compile time, so the figure is the call, its arguments and `apply` itself. The
//! poll region makes its samples inside `poll` (through the IMU), so its figure includes that.
#![no_std]
#![no_main]

use core::hint::black_box;

use cortex_m_rt::entry;
use defmt_semihosting as _;
use imucal_board_qemu_mps2_an386::{exit, ram_flash::RamNorFlash, ram_flash::SLOT_SIZE};
use imucal_firmware::apply::Correction;
use imucal_firmware::device::{Device, DeviceInfo};
use imucal_firmware::store::ParamStore;
use imucal_protocol::{
    encode_frame, BiasTemperature, CalibrationSet, DeviceId, FirmwareVersion, Nonlinearity,
    RawSample, Request, RequestBody, SensorCalibration, SensorScales, SensorSet, StreamKind,
};
use imucal_test_kit::bare::{CountingImu, SinkLink, SteppingClock};

/// Names of the measured regions, in the order they run (the bench driver reads the same list).
pub const REGIONS: [&str; 4] = ["empty", "apply-plain", "apply-extended", "poll-streaming"];
/// Iterations per region; a multiple of the calibrated batch size (10) so batches are whole.
pub const ITERATIONS: u32 = 200;

/// An LSM9DS1 at ±4 g, ±500 °/s, ±8 gauss and 119 Hz (sensitivities from its datasheet).
const SCALES: SensorScales = SensorScales {
    accel_mps2_per_count: 0.122e-3 * 9.806_65,
    gyro_rads_per_count: 17.5e-3 * core::f32::consts::PI / 180.0,
    mag_ut_per_count: 0.029,
    temp_c_per_count: 1.0 / 16.0,
    temp_offset_c: 25.0,
    accel_range_mps2: 4.0 * 9.806_65,
    gyro_range_rads: 500.0 * core::f32::consts::PI / 180.0,
    mag_range_ut: 800.0,
    sample_rate_hz: 119.0,
};

/// Start of a measured region; the plugin matches this function's first instruction.
#[no_mangle]
#[inline(never)]
pub extern "C" fn imucal_bench_start() {
    cortex_m::asm::nop();
}

/// End of a measured region; a different body from the start marker so the linker cannot merge them.
#[no_mangle]
#[inline(never)]
pub extern "C" fn imucal_bench_stop() {
    cortex_m::asm::nop();
    cortex_m::asm::nop();
}

/// A calibration with full matrices and offsets, non-trivial so nothing folds away.
fn plain_set() -> CalibrationSet {
    let sensor = |scale: f32, offset: f32| SensorCalibration {
        a: [
            [scale, 0.01, -0.02],
            [0.003, scale * 0.98, 0.015],
            [-0.01, 0.02, scale * 1.03],
        ],
        b: [offset, -offset * 0.5, offset * 0.25],
        ..SensorCalibration::identity()
    };
    CalibrationSet {
        accel: sensor(1.01, 0.12),
        gyro: sensor(0.99, 0.004),
        mag: sensor(1.05, 12.0),
        ..CalibrationSet::identity()
    }
}

/// The plain set plus every extended term: cubic bias temperature, scale temperature,
/// non-linearity on every sensor, and gyro g-sensitivity.
fn extended_set() -> CalibrationSet {
    let mut set = plain_set();
    for (sensor, unit) in [
        (&mut set.accel, 1.0e-3),
        (&mut set.gyro, 1.0e-5),
        (&mut set.mag, 1.0e-2),
    ] {
        sensor.t_ref_c = 25.0;
        sensor.bias_temp = Some(BiasTemperature {
            coeffs: [[unit; 3], [unit * 1.0e-2; 3], [unit * 1.0e-4; 3]],
        });
        sensor.scale_temp = Some([1.0e-4, -2.0e-4, 1.5e-4]);
        sensor.nonlinearity = Some(Nonlinearity {
            quadratic: [1.0e-5; 3],
            cubic: [1.0e-7; 3],
        });
    }
    set.gyro_g_sensitivity = Some([[1.0e-4, 0.0, 0.0], [0.0, 1.0e-4, 0.0], [0.0, 0.0, 1.0e-4]]);
    set
}

/// A sample that varies with `i` (period [`SAMPLE_PERIOD`]), so the compiler cannot hoist the
/// work out of a loop.
const fn sample(i: u32) -> RawSample {
    let v = (i % SAMPLE_PERIOD as u32) as i16;
    RawSample {
        accel: [120 + v, -340 - v, 8190 + v],
        gyro: [12 - v, 7 + v, -3],
        mag: [1500 + v, -800, 400 - v],
        temp: 80 + v,
    }
}

/// Period of [`sample`].
const SAMPLE_PERIOD: usize = 97;

/// One period of [`sample`], made at compile time: the apply regions read their input from
/// here, so that making a sample is not counted as part of calibrating it.
static SAMPLES: [RawSample; SAMPLE_PERIOD] = {
    let mut samples = [RawSample {
        accel: [0; 3],
        gyro: [0; 3],
        mag: [0; 3],
        temp: 0,
    }; SAMPLE_PERIOD];
    let mut i = 0;
    while i < SAMPLE_PERIOD {
        samples[i] = sample(i as u32);
        i += 1;
    }
    samples
};

/// The empty region: each iteration picks its sample from [`SAMPLES`] and makes it observable,
/// exactly as [`measure_apply`] does before calibrating it, so that subtracting this region
/// leaves the calibration: the call, its arguments and `Correction::apply` itself. Out of line,
/// like `measure_apply`, so both loops get a small stack frame and the same addressing.
#[inline(never)]
fn measure_empty() {
    imucal_bench_start();
    for i in 0..ITERATIONS {
        black_box(&SAMPLES[i as usize % SAMPLE_PERIOD]);
    }
    imucal_bench_stop();
}

/// One `Correction::apply` per iteration; the output stays where `apply` wrote it and is only
/// made observable, so no copy of it is counted.
#[inline(never)]
fn measure_apply(correction: &Correction) {
    // Hides which kind of correction was loaded, so nothing is specialised for the bench.
    let correction = black_box(correction);
    imucal_bench_start();
    for i in 0..ITERATIONS {
        let raw = black_box(&SAMPLES[i as usize % SAMPLE_PERIOD]);
        let calibrated = correction.apply(raw);
        black_box(&calibrated);
    }
    imucal_bench_stop();
}

#[entry]
fn main() -> ! {
    // Empty region: the loop and the sample generation without the work.
    measure_empty();

    for set in [plain_set(), extended_set()] {
        match Correction::new(&set, &SCALES) {
            Ok(correction) => measure_apply(&correction),
            Err(_) => {
                defmt::error!("the bench calibration set was rejected by validation");
                exit(false)
            }
        }
    }

    // The main loop with a calibrated stream running: one sample per poll, batches sent.
    let Some((flash, _)) = RamNorFlash::take() else {
        exit(false)
    };
    let Ok(store) = ParamStore::new(flash, 0, SLOT_SIZE as u32) else {
        exit(false)
    };
    let start_stream = Request {
        seq: 1,
        body: RequestBody::StartStream {
            kind: StreamKind::Calibrated,
            decimation: 1,
        },
    };
    let mut request = [0u8; 32];
    let Ok(len) = encode_frame(&start_stream, &mut request) else {
        exit(false)
    };
    let link = SinkLink::<32>::new(request.get(..len).unwrap_or(&[]));
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
    let clock = SteppingClock {
        now_us: 0,
        step_us: (1.0e6 / SCALES.sample_rate_hz) as u64 + 1,
    };
    let imu = CountingImu {
        count: 0,
        scales: SCALES,
        sample,
    };
    let Ok(mut device) = Device::<_, _, _, _>::new(imu, link, store, clock, info) else {
        exit(false)
    };
    // The first poll takes the StartStream request and its Ack; measure steady streaming after it.
    device.poll();
    imucal_bench_start();
    for _ in 0..ITERATIONS {
        device.poll();
    }
    imucal_bench_stop();
    let (_, link, _, _) = device.into_parts();
    // Each calibrated sample carries ten f32 values, so a running stream sends at least 40 bytes
    // per sample; fewer means the stream never started and the figure would be meaningless.
    if link.bytes_out < ITERATIONS * 40 {
        defmt::error!(
            "only {=u32} bytes streamed: the calibrated stream did not start",
            link.bytes_out
        );
        exit(false)
    }
    defmt::info!("streamed {=u32} bytes", link.bytes_out);
    exit(true)
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    exit(false)
}
