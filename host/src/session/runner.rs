//! The state a running session carries between its phases: the device, the options, the user
//! interface, the stillness monitor, and what the stream delivered (magnetometer samples for the
//! sphere fit, and the raw stream of each move between two holds for the gyroscope's scale).

use std::io::{Read, Write};
use std::time::{SystemTime, UNIX_EPOCH};

use imucal_protocol::StreamKind;

use super::error::SessionError;
use super::events::{MagSample, Phase, SessionObserver};
use super::motion::MotionMonitor;
use super::options::SessionOptions;
use super::targets::Target;
use crate::device::{DeviceClient, SampleChunk, UnitSample};

/// A session in progress.
pub(super) struct Runner<'a, L: Read + Write> {
    pub(super) client: &'a mut DeviceClient<L>,
    pub(super) options: &'a SessionOptions,
    pub(super) observer: &'a mut dyn SessionObserver,
    pub(super) monitor: MotionMonitor,
    pub(super) mag: Vec<MagSample>,
    /// The raw stream since watching for a position last started (the move in progress).
    pub(super) current_move: Vec<UnitSample>,
    /// Finished moves, each from the end of one hold to the start of the next capture.
    pub(super) moves: Vec<Vec<UnitSample>>,
    /// The axis the moves were last said to lack rotation about.
    pub(super) lacking_axis: Option<usize>,
}

/// Seconds since the Unix epoch (0 if the clock is before it).
pub(super) fn unix_now() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

/// The targets' names, comma separated.
pub(super) fn names(targets: &[&Target]) -> String {
    targets
        .iter()
        .map(|t| t.name.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

impl<'a, L: Read + Write> Runner<'a, L> {
    pub(super) fn new(
        client: &'a mut DeviceClient<L>,
        options: &'a SessionOptions,
        observer: &'a mut dyn SessionObserver,
    ) -> Self {
        Self {
            monitor: MotionMonitor::new(options.window_s, options.thresholds),
            client,
            options,
            observer,
            mag: Vec::new(),
            current_move: Vec::new(),
            moves: Vec::new(),
            lacking_axis: None,
        }
    }

    pub(super) fn read_chunk(&mut self) -> Result<SampleChunk, SessionError> {
        match self.client.next_samples(self.options.read_timeout)? {
            Some(chunk) => Ok(chunk),
            None => Err(SessionError::NoSamples {
                port: self.client.port_name().to_string(),
                waited_s: self.options.read_timeout.as_secs_f64(),
            }),
        }
    }

    pub(super) fn record_mag(&mut self, sample: &UnitSample, phase: Phase) {
        self.mag.push(MagSample {
            t_s: sample.t_s,
            mag: sample.mag,
            temp_c: sample.temp_c,
            phase,
        });
    }

    /// Start the raw stream and a fresh stillness window (and a fresh move recording).
    pub(super) fn start_watching(&mut self) -> Result<(), SessionError> {
        self.monitor.reset();
        self.current_move.clear();
        self.client
            .start_stream(StreamKind::Raw, self.options.decimation)?;
        Ok(())
    }

    /// Keep the move in progress as finished (the stream stops for a capture).
    pub(super) fn finish_move(&mut self) {
        let samples = std::mem::take(&mut self.current_move);
        if samples.len() >= 2 {
            self.moves.push(samples);
        }
    }

    pub(super) fn board_time_s(&mut self) -> Result<f64, SessionError> {
        Ok(self.client.status()?.uptime_ms as f64 * 1e-3)
    }
}
