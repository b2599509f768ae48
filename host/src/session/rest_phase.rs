//! The rest phase: wait until the board lies still, then stream at full rate for the "before"
//! (raw) and "after" (calibrated) errors at rest.

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use imucal_protocol::StreamKind;

use super::error::SessionError;
use super::events::{Phase, SessionEvent};
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
