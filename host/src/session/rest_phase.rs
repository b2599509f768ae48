//! The rest phase: wait until the board lies still, then stream at full rate for the "before"
//! (raw) and "after" (calibrated) errors at rest. The raw measurement must stay still all
//! through (it also gives the gyroscope's bias without a hand on the board): one during which
//! the board moved is taken again once it lies still.

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use imucal_protocol::StreamKind;

use super::error::SessionError;
use super::events::{Phase, SessionEvent};
use super::motion::MotionMonitor;
use super::runner::Runner;
use crate::device::{DeviceClient, UnitSample};

impl<L: Read + Write> Runner<'_, L> {
    pub(super) fn wait_for_rest(&mut self) -> Result<(), SessionError> {
        self.observer.event(&SessionEvent::RestPrompt);
        self.start_watching()?;
        let start = Instant::now();
        loop {
            if start.elapsed() > self.options.rest_timeout {
                self.client.stop_stream()?;
                return Err(SessionError::NotAtRest {
                    port: self.client.port_name().to_string(),
                    needed_s: self.options.rest_settle_s,
                    waited_s: self.options.rest_timeout.as_secs_f64(),
                });
            }
            let chunk = self.read_chunk()?;
            let mut latest = None;
            for sample in &chunk.samples {
                self.record_mag(sample, Phase::Rest);
                if let Some(state) = self.monitor.push(sample) {
                    latest = Some(state);
                }
            }
            if let Some(state) = latest {
                self.observer.event(&SessionEvent::Resting {
                    still_for_s: state.still_for_s,
                    needed_s: self.options.rest_settle_s,
                });
                if state.still_for_s >= self.options.rest_settle_s {
                    self.client.stop_stream()?;
                    return Ok(());
                }
            }
        }
    }

    /// Wait for rest and measure the raw stream there ([`Self::measure`]) until a measurement
    /// stays still all through, within `rest_timeout` overall.
    pub(super) fn measure_at_rest(&mut self) -> Result<Vec<UnitSample>, SessionError> {
        let start = Instant::now();
        loop {
            self.wait_for_rest()?;
            let samples = self.measure(StreamKind::Raw)?;
            let mut monitor = MotionMonitor::new(self.options.window_s, self.options.thresholds);
            let moved = samples
                .iter()
                .filter_map(|s| monitor.push(s))
                .any(|state| !state.still);
            if !moved {
                return Ok(samples);
            }
            if start.elapsed() > self.options.rest_timeout {
                return Err(SessionError::NotAtRest {
                    port: self.client.port_name().to_string(),
                    needed_s: self.options.rest_settle_s + self.options.rest_measure_s,
                    waited_s: start.elapsed().as_secs_f64(),
                });
            }
            self.observer.event(&SessionEvent::Note(
                "the board moved during the measurement at rest; it is measured again once it \
                 lies still"
                    .into(),
            ));
        }
    }

    /// Stream `kind` at full rate for `rest_measure_s` of board time.
    pub(super) fn measure(&mut self, kind: StreamKind) -> Result<Vec<UnitSample>, SessionError> {
        self.observer.event(&SessionEvent::Measuring { kind });
        stream_for(
            self.client,
            kind,
            self.options.rest_measure_s,
            self.options.read_timeout,
        )
    }
}

/// Stream `kind` at full rate until `seconds` of board time are covered, then stop the stream;
/// `read_timeout` is the longest wait for each sample batch.
pub fn stream_for<L: Read + Write>(
    client: &mut DeviceClient<L>,
    kind: StreamKind,
    seconds: f64,
    read_timeout: Duration,
) -> Result<Vec<UnitSample>, SessionError> {
    client.start_stream(kind, 1)?;
    let mut samples: Vec<UnitSample> = Vec::new();
    let result = loop {
        match client.next_samples(read_timeout) {
            Ok(Some(chunk)) => samples.extend_from_slice(&chunk.samples),
            Ok(None) => {
                break Err(SessionError::NoSamples {
                    port: client.port_name().to_string(),
                    waited_s: read_timeout.as_secs_f64(),
                })
            }
            Err(e) => break Err(e.into()),
        }
        let span = match (samples.first(), samples.last()) {
            (Some(a), Some(b)) => b.t_s - a.t_s,
            _ => 0.0,
        };
        // NaN (a non-finite request) ends the stream at once instead of never.
        if span >= seconds || seconds.is_nan() {
            break Ok(());
        }
    };
    let stopped = client.stop_stream();
    result?;
    stopped?;
    Ok(samples)
}
