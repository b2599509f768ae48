//! Worst-case encoded sizes: sample batches stay within the 24-bytes-per-sample budget and the
//! largest messages fit one frame.

mod common;

use common::*;
use imucal_protocol::*;

/// A header whose varints take their maximum lengths.
fn worst_header() -> BatchHeader {
    BatchHeader {
        first_index: u32::MAX,
        t0_us: u64::MAX - u64::from(u16::MAX) * u64::from(u32::MAX),
        tick_us: u32::MAX,
    }
}

/// Samples of all-0xFF bytes: no zeros, so COBS needs its maximum number of code bytes.
fn worst_raw_sample() -> RawSample {
    RawSample {
        accel: [-1; 3],
        gyro: [-1; 3],
        mag: [-1; 3],
        temp: -1,
    }
}

fn full_raw_batch(sample: RawSample, header: BatchHeader) -> SampleBatch {
    let mut batch = SampleBatch::new(header);
    let mut ticks = u16::MAX - RAW_BATCH_CAPACITY as u16;
    while !batch.is_full() {
        batch.push(&sample, header.time_us(ticks)).unwrap();
        ticks += 1;
    }
    batch
}

#[test]
fn full_raw_batch_costs_at_most_24_bytes_per_sample() {
    let batch = full_raw_batch(worst_raw_sample(), worst_header());
    assert_eq!(batch.len(), RAW_BATCH_CAPACITY);
    let msg = DeviceMessage::Event(Event::SampleBatch(batch));
    let payload = postcard_bytes(&msg).len();
    assert_eq!(
        payload,
        2 + 20 + 1 + RAW_BATCH_CAPACITY * PACKED_SAMPLE_BYTES
    );
    let wire = frame(&msg).len();
    assert_eq!(wire, 470, "documented worst case in the crate docs");
    assert!(wire <= MAX_FRAME);
    assert!(
        wire <= 24 * RAW_BATCH_CAPACITY,
        "{wire} bytes for {RAW_BATCH_CAPACITY} samples"
    );
}

#[test]
fn raw_batch_wire_size_is_independent_of_sample_values() {
    let header = BatchHeader {
        first_index: 0,
        t0_us: 0,
        tick_us: 1000,
    };
    let small = full_raw_batch(RawSample::default(), header);
    let large = full_raw_batch(
        RawSample {
            accel: [i16::MIN; 3],
            gyro: [i16::MAX; 3],
            mag: [i16::MIN; 3],
            temp: i16::MAX,
        },
        header,
    );
    let len = |b: SampleBatch| postcard_bytes(&Event::SampleBatch(b)).len();
    assert_eq!(len(small), len(large));
}

#[test]
fn full_calibrated_batch_fits_a_frame() {
    let mut batch = CalibratedBatch::new(worst_header());
    let sample = CalibratedSample {
        accel: [f32::from_bits(u32::MAX); 3],
        gyro: [f32::from_bits(u32::MAX); 3],
        mag: [f32::from_bits(u32::MAX); 3],
        temp_c: f32::from_bits(u32::MAX),
    };
    let t = worst_header().time_us(u16::MAX);
    while !batch.is_full() {
        batch.push(&sample, t).unwrap();
    }
    assert_eq!(batch.len(), CALIBRATED_BATCH_CAPACITY);
    let wire = frame(&DeviceMessage::Event(Event::CalibratedBatch(batch))).len();
    assert_eq!(wire, 460, "documented worst case in the crate docs");
}

fn worst_calibration_set() -> CalibrationSet {
    let nan = f32::from_bits(u32::MAX);
    let sensor = SensorCalibration {
        a: [[nan; 3]; 3],
        b: [nan; 3],
        t_ref_c: nan,
        bias_temp: Some(BiasTemperature {
            coeffs: [[nan; 3]; 3],
        }),
        scale_temp: Some([nan; 3]),
        nonlinearity: Some(Nonlinearity {
            quadratic: [nan; 3],
            cubic: [nan; 3],
        }),
    };
    CalibrationSet {
        format_version: u16::MAX,
        created_unix_s: u64::MAX,
        accel: sensor,
        gyro: sensor,
        mag: sensor,
        gyro_g_sensitivity: Some([[nan; 3]; 3]),
        reference: ReferenceMagnitudes {
            gravity_mps2: nan,
            field_ut: nan,
        },
        residuals: FitResiduals {
            accel_rms: nan,
            gyro_rms: nan,
            mag_rms: nan,
        },
    }
}

#[test]
fn params_max_encoded_is_the_exact_worst_case() {
    assert_eq!(
        postcard_bytes(&worst_calibration_set()).len(),
        PARAMS_MAX_ENCODED
    );
}

#[test]
fn largest_requests_and_responses_fit_a_frame() {
    let set = worst_calibration_set();
    let write = Request {
        seq: u16::MAX,
        body: RequestBody::WriteParams { set, crc: u32::MAX },
    };
    let params = DeviceMessage::Response(Response {
        seq: u16::MAX,
        body: ResponseBody::Params(set),
    });
    let log = DeviceMessage::Event(Event::Log(LogMessage::new(
        LogLevel::Error,
        &"\u{7f}".repeat(LOG_TEXT_MAX),
    )));
    for len in [frame(&write).len(), frame(&params).len(), frame(&log).len()] {
        assert!(len <= MAX_FRAME, "{len} > {MAX_FRAME}");
    }
}

#[test]
fn batch_push_rejects_full_batches_and_unrepresentable_times() {
    let header = BatchHeader {
        first_index: 0,
        t0_us: 1_000,
        tick_us: 10,
    };
    let mut batch = SampleBatch::new(header);
    let s = RawSample::default();
    assert_eq!(batch.push(&s, 999), Err(BatchError::BeforeStart));
    let last_ok = 1_000 + 10 * u64::from(u16::MAX) + 9;
    assert_eq!(batch.push(&s, last_ok), Ok(()));
    assert_eq!(
        batch.get(0).map(|(_, t)| t),
        Some(1_000 + 10 * u64::from(u16::MAX))
    );
    assert_eq!(batch.push(&s, last_ok + 1), Err(BatchError::SpanExceeded));
    while !batch.is_full() {
        batch.push(&s, 1_015).unwrap();
    }
    assert_eq!(
        batch.get(1).map(|(_, t)| t),
        Some(1_010),
        "times round down to a tick"
    );
    assert_eq!(batch.push(&s, 1_000), Err(BatchError::Full));
    assert!(batch.get(RAW_BATCH_CAPACITY).is_none());
    batch.reset(BatchHeader {
        tick_us: 0,
        ..header
    });
    assert!(batch.is_empty());
    assert_eq!(batch.push(&s, 1_000), Err(BatchError::ZeroTick));

    let mut calibrated = CalibratedBatch::new(header);
    assert_eq!(
        calibrated.push(&CalibratedSample::default(), 0),
        Err(BatchError::BeforeStart)
    );
}
