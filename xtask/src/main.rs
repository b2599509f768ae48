//! Developer tasks for the imucal firmware: `cargo xtask firmware build|size|bench|qemu-test`.
//!
//! - `build`: release ELFs of the QEMU board (`firmware/boards/qemu-mps2-an386`), built with
//!   Debian's `/usr/bin/cargo` from the board directory so its `.cargo/config.toml` applies.
//! - `size`: text/data/bss of the firmware ELF, checked against 48 KiB flash and 16 KiB RAM.
//! - `bench`: instructions per sample of the calibration, counted exactly by a QEMU TCG plugin.
//! - `qemu-test`: the firmware in QEMU, driven over UART0 with the protocol and fed on UART1.
//!
//! Each exits with a non-zero status when a step fails or a target is missed.

mod bench;
mod build;
// The feed format is defined once, in the board crate, and compiled here unchanged.
#[path = "../../firmware/boards/qemu-mps2-an386/src/feed.rs"]
#[allow(dead_code)] // the decoding half is the board's; tests here use it for round trips
mod feed;
mod qemu;
mod qemu_test;

use std::process::ExitCode;

const USAGE: &str = "usage: cargo xtask firmware <build|size|bench|qemu-test>";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args
        .iter()
        .map(String::as_str)
        .collect::<Vec<_>>()
        .as_slice()
    {
        ["firmware", "build"] => build::build().map(|_| ()),
        ["firmware", "size"] => build::build().and_then(|elfs| build::size(&elfs.firmware)),
        ["firmware", "bench"] => build::build().and_then(|elfs| bench::bench(&elfs.bench)),
        ["firmware", "qemu-test"] => build::build().and_then(|elfs| qemu_test::run(&elfs.firmware)),
        _ => Err(format!("unknown command {:?}; {USAGE}", args.join(" "))),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("error: {message}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::feed::{encode, FeedDecoder, FeedFrame, MAX_FEED_FRAME};
    use imucal_protocol::RawSample;

    #[test]
    fn feed_frames_round_trip_at_their_largest_within_max_feed_frame() {
        // The largest sample: u64::MAX time and i16 extremes take the longest varints.
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
        let n = encode(&sample, &mut buf).expect("largest sample fits MAX_FEED_FRAME");
        let mut decoder = FeedDecoder::new();
        let decoded: Vec<_> = buf[..n].iter().filter_map(|&b| decoder.push(b)).collect();
        assert_eq!(decoded, vec![Ok(sample)]);
    }

    #[test]
    fn corrupted_feed_frame_is_dropped_and_the_next_one_decodes() {
        let frame = FeedFrame::Sample {
            t_us: 8403,
            sample: RawSample::default(),
        };
        let mut buf = [0u8; MAX_FEED_FRAME];
        let n = encode(&frame, &mut buf).expect("fits");
        let mut stream = buf[..n].to_vec();
        stream[2] ^= 0x40;
        stream.extend_from_slice(&buf[..n]);
        let mut decoder = FeedDecoder::new();
        let decoded: Vec<_> = stream.iter().filter_map(|&b| decoder.push(b)).collect();
        assert_eq!(decoded.len(), 2);
        assert!(decoded[0].is_err());
        assert_eq!(decoded[1], Ok(frame));
    }
}
