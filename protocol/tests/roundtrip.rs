//! Every message type survives encode → frame → decoder unchanged, bit for bit.

mod common;

use common::*;
use imucal_protocol::*;
use proptest::prelude::*;
use serde::de::DeserializeOwned;
use serde::Serialize;

/// Encodes `msg`, decodes the frame, and checks the result is the same message, comparing the
/// postcard encodings so that floats (NaN payloads and signed zeros included) match bitwise.
fn assert_round_trip<T>(msg: &T) -> Result<(), TestCaseError>
where
    T: Serialize + DeserializeOwned + core::fmt::Debug,
{
    let bytes = frame(msg);
    prop_assert!(bytes.len() <= MAX_FRAME);
    prop_assert_eq!(bytes.iter().filter(|&&b| b == 0).count(), 1);
    prop_assert_eq!(bytes.last(), Some(&0));
    let decoded = decode_all::<T>(&bytes);
    prop_assert_eq!(decoded.len(), 1);
    match &decoded[0] {
        Ok(value) => {
            prop_assert_eq!(postcard_bytes(value), postcard_bytes(msg));
            prop_assert_eq!(format!("{value:?}"), format!("{msg:?}"));
        }
        Err(e) => prop_assert!(false, "decode failed: {e}"),
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn host_messages_round_trip(msg in request()) {
        assert_round_trip::<HostMessage>(&msg)?;
    }

    #[test]
    fn device_messages_round_trip(msg in device_message()) {
        assert_round_trip::<DeviceMessage>(&msg)?;
    }

    #[test]
    fn calibration_sets_round_trip_with_extreme_floats(set in calibration_set()) {
        assert_round_trip(&set)?;
    }

    #[test]
    fn raw_batch_returns_pushed_samples_and_times(
        header in batch_header(),
        samples in prop::collection::vec((raw_sample(), any::<u16>()), 1..=RAW_BATCH_CAPACITY),
    ) {
        let header = BatchHeader { t0_us: header.t0_us % (1 << 60), ..header };
        let mut batch = SampleBatch::new(header);
        for (sample, ticks) in &samples {
            batch.push(sample, header.time_us(*ticks)).map_err(|e| TestCaseError::fail(e.to_string()))?;
        }
        let decoded = decode_all::<Event>(&frame(&Event::SampleBatch(batch)));
        let Some(Ok(Event::SampleBatch(decoded))) = decoded.into_iter().next() else {
            return Err(TestCaseError::fail("raw batch did not decode"));
        };
        prop_assert_eq!(decoded.header(), &header);
        let got: Vec<_> = decoded.iter().collect();
        let want: Vec<_> = samples.iter().map(|(s, ticks)| (*s, header.time_us(*ticks))).collect();
        prop_assert_eq!(got, want);
    }

    #[test]
    fn calibrated_batch_returns_pushed_samples_and_times(
        header in batch_header(),
        samples in prop::collection::vec((calibrated_sample(), any::<u16>()), 1..=CALIBRATED_BATCH_CAPACITY),
    ) {
        let header = BatchHeader { t0_us: header.t0_us % (1 << 60), ..header };
        let mut batch = CalibratedBatch::new(header);
        for (sample, ticks) in &samples {
            batch.push(sample, header.time_us(*ticks)).map_err(|e| TestCaseError::fail(e.to_string()))?;
        }
        prop_assert_eq!(batch.len(), samples.len());
        for (i, (sample, ticks)) in samples.iter().enumerate() {
            let Some((got, t_us)) = batch.get(i) else {
                return Err(TestCaseError::fail("sample missing"));
            };
            prop_assert_eq!(postcard_bytes(&got), postcard_bytes(sample));
            prop_assert_eq!(t_us, header.time_us(*ticks));
        }
        assert_round_trip(&Event::CalibratedBatch(batch))?;
    }
}

#[test]
fn crc32_of_set_matches_crc_of_its_postcard_encoding() {
    let mut set = CalibrationSet::identity();
    set.created_unix_s = 1_700_000_000;
    set.accel.b = [0.1, -0.2, 0.3];
    set.gyro_g_sensitivity = Some([[1e-4; 3]; 3]);
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
    assert_eq!(set.crc32(), crc.checksum(&postcard_bytes(&set)));
    assert_ne!(set.crc32(), CalibrationSet::identity().crc32());
}

#[test]
fn crc32_distinguishes_sets_differing_in_one_float_bit() {
    let set = CalibrationSet::identity();
    let mut changed = set;
    changed.mag.a[2][2] = f32::from_bits(changed.mag.a[2][2].to_bits() ^ 1);
    assert_ne!(set.crc32(), changed.crc32());
}

#[test]
fn identity_set_has_unit_matrices_zero_offsets_and_no_extended_terms() {
    let set = CalibrationSet::identity();
    assert_eq!(set.format_version, PARAMS_FORMAT_VERSION);
    for sensor in [set.accel, set.gyro, set.mag] {
        for (r, row) in sensor.a.iter().enumerate() {
            for (c, v) in row.iter().enumerate() {
                assert_eq!(*v, if r == c { 1.0 } else { 0.0 });
            }
        }
        assert_eq!(sensor.b, [0.0; 3]);
        assert!(sensor.bias_temp.is_none());
        assert!(sensor.scale_temp.is_none());
        assert!(sensor.nonlinearity.is_none());
    }
    assert!(set.gyro_g_sensitivity.is_none());
}

#[test]
fn log_message_truncates_at_a_character_boundary() {
    let text = "é".repeat(LOG_TEXT_MAX); // 2 bytes per char
    let log = LogMessage::new(LogLevel::Warn, &text);
    assert_eq!(log.text.len(), LOG_TEXT_MAX);
    assert!(log.text.chars().all(|c| c == 'é'));
    let odd = format!("a{text}");
    let log = LogMessage::new(LogLevel::Info, &odd);
    assert_eq!(log.text.len(), LOG_TEXT_MAX - 1);
}

#[test]
fn device_id_from_u64_prints_little_endian_hex() {
    let id = DeviceId::from_u64(0x0102_0304_0506_0708);
    assert_eq!(
        id.to_string(),
        "0807060504030201".to_string() + &"00".repeat(8)
    );
}

#[test]
fn peek_seq_reads_sequence_of_request_with_unknown_body() {
    let payload = postcard_bytes(&Request {
        seq: 40_000,
        body: RequestBody::Ping(7),
    });
    // Replace the body's variant index with one no version knows.
    let mut unknown = payload.clone();
    let seq_len = payload.len() - 2; // Ping(7): variant 1 byte + varint 1 byte
    unknown[seq_len] = 0x7F;
    assert_eq!(decode_payload::<Request>(&unknown), Err(FrameError::Decode));
    assert_eq!(Request::peek_seq(&unknown), Some(40_000));
    assert_eq!(Request::peek_seq(&[]), None);
}
