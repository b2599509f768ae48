//! libFuzzer target: arbitrary bytes into the protocol's `FrameDecoder`, decoded as both
//! directions' message types.
//!
//! Checks: no panic; the decoder never holds more than its buffer; feeding in chunks (size from
//! the first input byte) yields exactly what feeding byte by byte yields; every message that
//! decodes re-encodes into a frame that decodes to the same postcard bytes.
#![no_main]

use imucal_protocol::{
    decode_payload, encode_frame, DeviceMessage, FrameDecoder, Request, MAX_FRAME,
};
use libfuzzer_sys::fuzz_target;

/// Postcard bytes of a message, so that NaN fields compare equal to themselves.
fn to_bytes<T: serde::Serialize>(value: &T) -> Vec<u8> {
    let mut buffer = [0u8; 1024];
    postcard::to_slice(value, &mut buffer)
        .map(|used| used.to_vec())
        .unwrap_or_default()
}

/// Re-encode `message`, decode the frame again, and require the same bytes.
fn round_trips<T>(message: &T)
where
    T: serde::Serialize + serde::de::DeserializeOwned,
{
    let mut frame = [0u8; MAX_FRAME];
    let len = encode_frame(message, &mut frame).expect("a decoded message fits a frame");
    let mut decoder = FrameDecoder::<MAX_FRAME>::new();
    let again: Vec<_> = decoder.messages::<T>(&frame[..len]).collect();
    assert_eq!(again.len(), 1, "one frame in, one message out");
    let again = again
        .into_iter()
        .next()
        .and_then(Result::ok)
        .expect("round trip");
    assert_eq!(to_bytes(&again), to_bytes(message));
}

fuzz_target!(|data: &[u8]| {
    let Some((&chunk, stream)) = data.split_first() else {
        return;
    };
    let chunk = usize::from(chunk).max(1);

    // Byte by byte: the reference.
    let mut reference = FrameDecoder::<MAX_FRAME>::new();
    let mut payloads: Vec<Result<Vec<u8>, _>> = Vec::new();
    for &byte in stream {
        if let Some(frame) = reference.push(byte) {
            payloads.push(frame.map(<[u8]>::to_vec));
        }
        assert!(reference.pending() <= MAX_FRAME);
    }

    // In chunks, through the typed iterators of both directions.
    let mut requests = FrameDecoder::<MAX_FRAME>::new();
    let mut events = FrameDecoder::<MAX_FRAME>::new();
    let mut decoded = 0;
    for piece in stream.chunks(chunk) {
        // Each iterator must run to the end, or it leaves bytes unseen.
        let as_requests: Vec<_> = requests.messages::<Request>(piece).collect();
        let as_replies: Vec<_> = events.messages::<DeviceMessage>(piece).collect();
        assert_eq!(as_requests.len(), as_replies.len());
        for (message, reply) in as_requests.into_iter().zip(as_replies) {
            let expected = payloads.get(decoded).expect("same number of frames");
            match expected {
                Ok(payload) => {
                    assert_eq!(message.is_ok(), decode_payload::<Request>(payload).is_ok());
                    assert_eq!(
                        reply.is_ok(),
                        decode_payload::<DeviceMessage>(payload).is_ok()
                    );
                    let _ = Request::peek_seq(payload);
                }
                Err(error) => {
                    assert_eq!(message.as_ref().err(), Some(error));
                    assert_eq!(reply.as_ref().err(), Some(error));
                }
            }
            if let Ok(request) = &message {
                round_trips(request);
            }
            if let Ok(reply) = &reply {
                round_trips(reply);
            }
            decoded += 1;
        }
    }
    assert_eq!(decoded, payloads.len());
});
