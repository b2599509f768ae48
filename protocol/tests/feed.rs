//! The sensor feed's frames: their size bound and their recovery from corruption.

use imucal_protocol::feed::{encode, FeedDecoder, FeedFrame, MAX_FEED_FRAME};
use imucal_protocol::{RawSample, SensorScales};

fn decode_all(bytes: &[u8]) -> Vec<Result<FeedFrame, imucal_protocol::FrameError>> {
    let mut decoder = FeedDecoder::new();
    bytes.iter().filter_map(|&b| decoder.push(b)).collect()
}

#[test]
fn largest_sample_frame_round_trips_within_max_feed_frame() {
    // u64::MAX time and i16 extremes take the longest varints.
    let sample = FeedFrame::Sample {
        t_us: u64::MAX,
        sample: RawSample {
            accel: [i16::MIN; 3],
            gyro: [i16::MAX; 3],
            mag: [i16::MIN; 3],
            temp: i16::MAX,
        },
    };
    let mut buf = [0u8; MAX_FEED_FRAME];
    let n = encode(&sample, &mut buf).expect("the largest sample fits MAX_FEED_FRAME");
    assert_eq!(decode_all(&buf[..n]), vec![Ok(sample)]);
}

#[test]
fn scales_frame_round_trips_within_max_feed_frame() {
    // Every bit pattern of an f32 field is 4 fixed bytes, so any values give the same length.
    let scales = FeedFrame::Scales(SensorScales {
        accel_mps2_per_count: 0.122e-3 * 9.806_65,
        gyro_rads_per_count: 17.5e-3 * core::f32::consts::PI / 180.0,
        mag_ut_per_count: 0.029,
        temp_c_per_count: 1.0 / 16.0,
        temp_offset_c: 25.0,
        accel_range_mps2: 4.0 * 9.806_65,
        gyro_range_rads: 500.0 * core::f32::consts::PI / 180.0,
        mag_range_ut: 800.0,
        sample_rate_hz: 119.0,
    });
    let mut buf = [0u8; MAX_FEED_FRAME];
    let n = encode(&scales, &mut buf).expect("a Scales frame fits MAX_FEED_FRAME");
    assert_eq!(decode_all(&buf[..n]), vec![Ok(scales)]);
}

#[test]
fn corrupted_frame_is_dropped_and_the_next_one_decodes() {
    let frame = FeedFrame::Sample {
        t_us: 8403,
        sample: RawSample::default(),
    };
    let mut buf = [0u8; MAX_FEED_FRAME];
    let n = encode(&frame, &mut buf).expect("fits");
    let mut stream = buf[..n].to_vec();
    stream[2] ^= 0x40;
    stream.extend_from_slice(&buf[..n]);
    let decoded = decode_all(&stream);
    assert_eq!(decoded.len(), 2);
    assert!(decoded[0].is_err(), "{:?}", decoded[0]);
    assert_eq!(decoded[1], Ok(frame));
}
