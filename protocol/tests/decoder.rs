//! The frame decoder on hostile input: random bytes, random chunking, corruption, truncation,
//! oversize frames and lost delimiters. It must never panic and must recover at the next 0x00.

mod common;

use common::*;
use imucal_protocol::*;
use proptest::prelude::*;

type Blob = heapless::Vec<u8, 480>;

fn blob(bytes: &[u8]) -> Blob {
    Blob::from_slice(bytes).expect("test blob fits")
}

/// Byte payloads biased towards the values that stress COBS (0x00 and long non-zero runs).
fn blob_strategy() -> impl Strategy<Value = Blob> {
    prop::collection::vec(prop_oneof![Just(0u8), Just(0xFFu8), any::<u8>()], 0..=480)
        .prop_map(|v| blob(&v))
}

fn messages() -> impl Strategy<Value = Vec<DeviceMessage>> {
    prop::collection::vec(device_message(), 1..6)
}

fn stream_of(msgs: &[DeviceMessage]) -> Vec<u8> {
    msgs.iter().flat_map(frame).collect()
}

fn oks(msgs: &[DeviceMessage]) -> Vec<Vec<u8>> {
    msgs.iter().map(postcard_bytes).collect()
}

/// Payload bytes of each successfully decoded message, and the number of errors.
fn outcome(results: Vec<Result<DeviceMessage, FrameError>>) -> (Vec<Vec<u8>>, usize) {
    let mut decoded = Vec::new();
    let mut errors = 0;
    for r in results {
        match r {
            Ok(m) => decoded.push(postcard_bytes(&m)),
            Err(_) => errors += 1,
        }
    }
    (decoded, errors)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn random_bytes_never_panic_and_a_following_frame_is_recovered(
        garbage in prop::collection::vec(any::<u8>(), 0..2000),
        msg in device_message(),
    ) {
        let mut decoder: FrameDecoder = FrameDecoder::new();
        let _garbage_results: Vec<_> = decoder.messages::<DeviceMessage>(&garbage).collect();
        let mut tail = vec![0u8];
        tail.extend(frame(&msg));
        let results: Vec<_> = decoder.messages::<DeviceMessage>(&tail).collect();
        // The delimiter may close a garbage frame (an error), then the message follows.
        prop_assert!(results.len() <= 2);
        match results.last() {
            Some(Ok(m)) => prop_assert_eq!(postcard_bytes(m), postcard_bytes(&msg)),
            other => prop_assert!(false, "message not recovered: {other:?}"),
        }
        prop_assert_eq!(decoder.pending(), 0);
    }

    #[test]
    fn random_payload_bytes_round_trip_across_cobs_run_boundaries(payload in blob_strategy()) {
        let bytes = frame(&payload);
        let payload_len = postcard_bytes(&payload).len();
        prop_assert!(bytes.len() <= max_frame_len(payload_len));
        let decoded = decode_all::<Blob>(&bytes);
        prop_assert_eq!(decoded, vec![Ok(payload)]);
    }

    #[test]
    fn every_frame_is_recovered_from_arbitrary_chunking(
        msgs in messages(),
        cuts in prop::collection::vec(any::<prop::sample::Index>(), 0..40),
    ) {
        let stream = stream_of(&msgs);
        let mut cut_points: Vec<usize> = cuts.iter().map(|i| i.index(stream.len() + 1)).collect();
        cut_points.push(0);
        cut_points.push(stream.len());
        cut_points.sort_unstable();
        let mut decoder: FrameDecoder = FrameDecoder::new();
        let mut results = Vec::new();
        for pair in cut_points.windows(2) {
            decoder.feed::<DeviceMessage>(&stream[pair[0]..pair[1]], |r| results.push(r));
        }
        prop_assert_eq!(outcome(results), (oks(&msgs), 0));
    }

    #[test]
    fn byte_at_a_time_equals_all_at_once(msgs in messages()) {
        let stream = stream_of(&msgs);
        let mut decoder: FrameDecoder = FrameDecoder::new();
        let mut payloads = Vec::new();
        for &b in &stream {
            if let Some(r) = decoder.push(b) {
                payloads.push(r.map(<[u8]>::to_vec));
            }
        }
        let expected: Vec<_> = oks(&msgs).into_iter().map(Ok).collect();
        prop_assert_eq!(payloads, expected);
    }

    #[test]
    fn single_bit_flip_is_reported_and_following_frames_recovered(
        before in device_message(),
        victim in device_message(),
        after in device_message(),
        position in any::<prop::sample::Index>(),
        bit in 0u8..8,
    ) {
        let victim_frame = frame(&victim);
        // Flip inside the frame body; a flipped delimiter is the lost-delimiter case below.
        let mut corrupted = victim_frame.clone();
        let at = position.index(victim_frame.len() - 1);
        corrupted[at] ^= 1 << bit;
        let mut stream = frame(&before);
        stream.extend(&corrupted);
        stream.extend(frame(&after));
        let results = decode_all::<DeviceMessage>(&stream);
        let (decoded, errors) = outcome(results);
        prop_assert_eq!(decoded, oks(&[before, after]));
        prop_assert!(errors >= 1, "corruption went unnoticed");
    }

    #[test]
    fn truncated_frame_is_reported_and_next_frame_recovered(
        victim in device_message(),
        next in device_message(),
        cut in any::<prop::sample::Index>(),
    ) {
        let victim_frame = frame(&victim);
        let keep = 1 + cut.index(victim_frame.len() - 2); // at least 1 byte, not the whole body
        let mut stream = victim_frame[..keep].to_vec();
        stream.push(0);
        stream.extend(frame(&next));
        let (decoded, errors) = outcome(decode_all::<DeviceMessage>(&stream));
        prop_assert_eq!(decoded, oks(&[next]));
        prop_assert_eq!(errors, 1);
    }

    #[test]
    fn lost_delimiter_merges_two_frames_into_one_error(
        first in device_message(),
        second in device_message(),
        third in device_message(),
    ) {
        let mut stream = frame(&first);
        stream.pop(); // the delimiter is lost on the line
        stream.extend(frame(&second));
        stream.extend(frame(&third));
        let results = decode_all::<DeviceMessage>(&stream);
        prop_assert_eq!(results.len(), 2);
        prop_assert!(results[0].is_err());
        let (decoded, _) = outcome(results);
        prop_assert_eq!(decoded, oks(&[third]));
    }

    #[test]
    fn encoder_reports_small_buffers_without_panicking(msg in device_message(), shrink in 1usize..64) {
        let full = frame(&msg);
        let mut buf = vec![0u8; full.len().saturating_sub(shrink)];
        prop_assert_eq!(encode_frame(&msg, &mut buf), Err(EncodeError::BufferFull));
        let mut exact = vec![0u8; full.len()];
        prop_assert_eq!(encode_frame(&msg, &mut exact), Ok(full.len()));
        prop_assert_eq!(exact, full);
    }
}

#[test]
fn oversize_frame_reports_overflow_then_resynchronises() {
    let next = DeviceMessage::Event(Event::StillnessChanged {
        still: true,
        t_ms: 5,
    });
    let mut stream = vec![0x42u8; 3 * MAX_FRAME];
    stream.push(0);
    stream.extend(frame(&next));
    let results = decode_all::<DeviceMessage>(&stream);
    assert_eq!(results, vec![Err(FrameError::Overflow), Ok(next)]);
}

#[test]
fn frame_exactly_filling_the_buffer_decodes_and_one_byte_more_overflows() {
    let msg = Request {
        seq: 3,
        body: RequestBody::Ping(0xDEAD_BEEF),
    };
    let bytes = frame(&msg);
    let body_len = bytes.len() - 1; // without the delimiter
                                    // 7 payload bytes + 4 CRC + 1 COBS code byte.
    assert_eq!(body_len, 12, "frame size of this Ping changed");
    let mut exact = FrameDecoder::<12>::new();
    let got: Vec<_> = exact.messages::<Request>(&bytes).collect();
    assert_eq!(got, vec![Ok(msg.clone())]);
    let mut short = FrameDecoder::<11>::new();
    let got: Vec<_> = short.messages::<Request>(&bytes).collect();
    assert_eq!(got, vec![Err(FrameError::Overflow)]);
    // The short decoder is usable again for frames that fit.
    let small = frame(&Request {
        seq: 1,
        body: RequestBody::Status,
    });
    assert!(short.messages::<Request>(&small).all(|r| r.is_ok()));
}

#[test]
fn empty_frames_between_delimiters_are_skipped() {
    let msg = Request {
        seq: 1,
        body: RequestBody::StopStream,
    };
    let mut stream = vec![0, 0, 0];
    stream.extend(frame(&msg));
    stream.extend([0, 0]);
    assert_eq!(decode_all::<Request>(&stream), vec![Ok(msg)]);
}

#[test]
fn empty_payload_frame_is_cobs_of_zero_crc() {
    // postcard encodes () as nothing; CRC-32 of no bytes is 0.
    assert_eq!(frame(&()), vec![1, 1, 1, 1, 1, 0]);
    assert_eq!(decode_all::<()>(&[1, 1, 1, 1, 1, 0]), vec![Ok(())]);
}

#[test]
fn crc_is_iso_hdlc_appended_little_endian() {
    // Check value of CRC-32/ISO-HDLC for "123456789" is 0xCBF43926.
    let payload: [u8; 9] = *b"123456789";
    let mut expected = vec![14u8];
    expected.extend(b"123456789");
    expected.extend([0x26, 0x39, 0xF4, 0xCB, 0]);
    assert_eq!(frame(&payload), expected);
}

#[test]
fn malformed_cobs_too_short_and_bad_crc_are_distinguished() {
    // Code byte 5 promises 4 bytes but only 2 follow.
    assert_eq!(decode_all::<()>(&[5, 1, 2, 0]), vec![Err(FrameError::Cobs)]);
    // Valid COBS, but only 2 bytes: no room for a CRC.
    assert_eq!(
        decode_all::<()>(&[3, 1, 2, 0]),
        vec![Err(FrameError::TooShort)]
    );
    // Four zero bytes claim an empty payload with CRC 0 — correct; a fifth byte breaks the CRC.
    assert_eq!(
        decode_all::<()>(&[2, 7, 1, 1, 1, 1, 0]),
        vec![Err(FrameError::Crc)]
    );
}

#[test]
fn payload_with_trailing_bytes_is_a_decode_error() {
    let bytes = frame(&(7u16, 9u8));
    assert_eq!(decode_all::<u16>(&bytes), vec![Err(FrameError::Decode)]);
    assert_eq!(decode_all::<(u16, u8)>(&bytes), vec![Ok((7, 9))]);
}

#[test]
fn unknown_enum_variant_is_a_decode_error() {
    // A DeviceMessage tag beyond the known variants, with a valid CRC.
    let bytes = frame(&(9u8, 0u8));
    assert_eq!(
        decode_all::<DeviceMessage>(&bytes),
        vec![Err(FrameError::Decode)]
    );
}

#[test]
fn reset_discards_a_partial_frame() {
    let msg = Request {
        seq: 2,
        body: RequestBody::GetParams,
    };
    let bytes = frame(&msg);
    let mut decoder: FrameDecoder = FrameDecoder::new();
    assert!(decoder.push(0x55).is_none());
    assert_eq!(decoder.pending(), 1);
    decoder.reset();
    assert_eq!(decoder.pending(), 0);
    let got: Vec<_> = decoder.messages::<Request>(&bytes).collect();
    assert_eq!(got, vec![Ok(msg)]);
}
