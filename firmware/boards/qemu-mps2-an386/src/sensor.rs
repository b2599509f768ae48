//! The board's IMU and clock, both driven by the sensor feed on UART1.
//!
//! Time on this board is the feed's time: the clock reads the world time stamped on the newest
//! sample. Under QEMU the core's own timers (SysTick) follow host wall-clock time and the host's
//! scheduling, which drift against the simulator's world; deriving the clock from the feed keeps
//! pose durations, stillness windows and timeouts in the same time base as the simulated motion,
//! and makes runs repeatable. The clock therefore only advances while the feed runs, as a chip's
//! data-ready interrupt only fires while the chip samples. Each clock reading advances by at most
//! one sample, so the core, which reads the clock once per `poll()`, sees every fed sample.

use core::cell::RefCell;

use imucal_protocol::feed::{FeedDecoder, FeedFrame};
use imucal_protocol::{RawSample, SensorScales};

use crate::uart::CmsdkUart;

/// Receive state of the feed: the UART, the frame decoder and the newest values.
#[derive(Debug)]
pub struct FeedReceiver {
    uart: CmsdkUart,
    decoder: FeedDecoder,
    scales: Option<SensorScales>,
    latest: Option<(u64, RawSample)>,
    samples_received: u32,
    frames_dropped: u32,
}

impl FeedReceiver {
    /// Receives the feed on `uart`.
    pub fn new(uart: CmsdkUart) -> Self {
        Self {
            uart,
            decoder: FeedDecoder::new(),
            scales: None,
            latest: None,
            samples_received: 0,
            frames_dropped: 0,
        }
    }

    /// Decodes waiting bytes up to the end of the next sample frame; returns whether one arrived.
    ///
    /// Stopping after one sample lets the core take every sample even when it falls behind: the
    /// rest waits in QEMU's socket (which pushes back on the feeder) instead of being skipped.
    pub fn pump(&mut self) -> bool {
        while let Some(byte) = self.uart.try_read_byte() {
            match self.decoder.push(byte) {
                Some(Ok(FeedFrame::Scales(scales))) => self.scales = Some(scales),
                Some(Ok(FeedFrame::Sample { t_us, sample })) => {
                    self.latest = Some((t_us, sample));
                    self.samples_received = self.samples_received.wrapping_add(1);
                    return true;
                }
                Some(Err(_)) => self.frames_dropped = self.frames_dropped.wrapping_add(1),
                None => {}
            }
        }
        false
    }

    /// The chip configuration announced by the feed, once it has arrived.
    pub fn scales(&self) -> Option<SensorScales> {
        self.scales
    }

    /// The newest sample and its world time in µs.
    pub fn latest(&self) -> Option<(u64, RawSample)> {
        self.latest
    }

    /// Samples received since start-up (wrapping).
    pub fn samples_received(&self) -> u32 {
        self.samples_received
    }

    /// Frames dropped as corrupt or unknown since start-up (wrapping).
    pub fn frames_dropped(&self) -> u32 {
        self.frames_dropped
    }

    /// Bytes lost by the UART because they were not read in time.
    pub fn rx_overruns(&self) -> u32 {
        self.uart.rx_overruns()
    }
}

/// Why the feed-driven IMU has no sample to give.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum FeedImuError {
    /// No sample has arrived on UART1 yet: start the feeder (it must connect to QEMU's UART1 socket).
    NoSampleYet,
    /// The feed state is being updated at the same moment (re-entrant call); try again.
    Busy,
}

/// The feed state shared by the board's IMU and clock.
pub type SharedFeed = RefCell<FeedReceiver>;

/// The board's IMU: returns the newest sample of the feed, as a chip returns its output registers.
#[derive(Debug, Clone, Copy)]
pub struct FeedImu<'a> {
    feed: &'a SharedFeed,
    scales: SensorScales,
}

impl<'a> FeedImu<'a> {
    /// An IMU over `feed` reporting `scales` (those the feed announced at start-up).
    pub fn new(feed: &'a SharedFeed, scales: SensorScales) -> Self {
        Self { feed, scales }
    }
}

impl imucal_firmware::imu::Imu for FeedImu<'_> {
    type Error = FeedImuError;

    fn scales(&self) -> SensorScales {
        self.scales
    }

    /// The sample whose time the clock last reported (the clock drains the UART, so a sample
    /// and its timestamp always belong together).
    fn read(&mut self) -> Result<RawSample, FeedImuError> {
        let feed = self.feed.try_borrow().map_err(|_| FeedImuError::Busy)?;
        feed.latest()
            .map(|(_, sample)| sample)
            .ok_or(FeedImuError::NoSampleYet)
    }
}

/// The board's clock: the world time of the newest feed sample; see the module documentation.
#[derive(Debug, Clone, Copy)]
pub struct FeedClock<'a> {
    feed: &'a SharedFeed,
}

impl<'a> FeedClock<'a> {
    /// A clock over `feed`.
    pub fn new(feed: &'a SharedFeed) -> Self {
        Self { feed }
    }
}

impl imucal_firmware::device::Clock for FeedClock<'_> {
    /// Microseconds of world time after draining the feed; 0 before the first sample.
    fn now_us(&mut self) -> u64 {
        match self.feed.try_borrow_mut() {
            Ok(mut feed) => {
                feed.pump();
                feed.latest().map_or(0, |(t_us, _)| t_us)
            }
            // Only reachable re-entrantly; the last time read is equally valid then.
            Err(_) => self
                .feed
                .try_borrow()
                .ok()
                .and_then(|feed| feed.latest())
                .map_or(0, |(t_us, _)| t_us),
        }
    }
}
