//! Streaming: start and stop the sample stream, wait for events, and turn sample batches into
//! samples in units while counting the ones lost in transit.

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use imucal_protocol::{Event, RequestBody, ResponseBody, StreamKind};

use super::{deadline_after, DeviceClient};
use crate::device::samples::SampleChunk;
use crate::device::{DeviceError, UnitSample};

/// Maximum log lines kept when skipped over by [`DeviceClient::next_samples`].
const LOG_KEEP: usize = 64;

impl<L: Read + Write> DeviceClient<L> {
    /// Starts a sample stream; batches then arrive as events.
    pub fn start_stream(&mut self, kind: StreamKind, decimation: u16) -> Result<(), DeviceError> {
        self.gaps.reset();
        match self.request(RequestBody::StartStream { kind, decimation })? {
            ResponseBody::Ack => Ok(()),
            other => Err(self.unexpected("StartStream", &other)),
        }
    }

    /// Stops the sample stream. Batches already in flight are discarded.
    pub fn stop_stream(&mut self) -> Result<(), DeviceError> {
        match self.request(RequestBody::StopStream)? {
            ResponseBody::Ack => {
                self.events
                    .retain(|e| !matches!(e, Event::SampleBatch(_) | Event::CalibratedBatch(_)));
                Ok(())
            }
            other => Err(self.unexpected("StopStream", &other)),
        }
    }

    /// The next event, waiting up to `timeout`; `None` when none arrived.
    pub fn next_event(&mut self, timeout: Duration) -> Result<Option<Event>, DeviceError> {
        let deadline = deadline_after(timeout);
        loop {
            if let Some(event) = self.events.pop_front() {
                return Ok(Some(event));
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
            // No request is waiting: seq None means every reply is stale.
            self.pump(None, deadline)?;
        }
    }

    /// The next batch of stream samples in units, waiting up to `timeout`. Other events are
    /// skipped (stillness still updates [`Self::is_still`]; log lines go to
    /// [`Self::drain_logs`]).
    pub fn next_samples(&mut self, timeout: Duration) -> Result<Option<SampleChunk>, DeviceError> {
        let deadline = deadline_after(timeout);
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let Some(event) = self.next_event(left)? else {
                return Ok(None);
            };
            let scales = self.welcome.scales;
            match event {
                Event::SampleBatch(batch) => {
                    let lost = self.gaps.observe(batch.header(), batch.len());
                    self.stats.lost_samples += u64::from(lost);
                    self.stats.received_samples += batch.len() as u64;
                    return Ok(Some(SampleChunk::from_raw(&batch, &scales, lost)));
                }
                Event::CalibratedBatch(batch) => {
                    let lost = self.gaps.observe(batch.header(), batch.len());
                    self.stats.lost_samples += u64::from(lost);
                    self.stats.received_samples += batch.len() as u64;
                    return Ok(Some(SampleChunk::from_calibrated(&batch, lost)));
                }
                Event::Log(line) => {
                    if self.logs.len() >= LOG_KEEP {
                        self.logs.pop_front();
                    }
                    self.logs.push_back(line);
                }
                Event::StillnessChanged { .. } => {}
            }
        }
    }

    /// Streams `kind` for `duration` and returns every sample, calling `on_chunk` per batch
    /// (for progress or writing as it comes). The stream is stopped afterwards, also on error.
    pub fn collect_samples(
        &mut self,
        kind: StreamKind,
        duration: Duration,
        on_chunk: &mut dyn FnMut(&SampleChunk),
    ) -> Result<Vec<UnitSample>, DeviceError> {
        self.start_stream(kind, 1)?;
        let mut samples = Vec::new();
        let deadline = deadline_after(duration);
        let result = loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                break Ok(());
            }
            match self.next_samples(left) {
                Ok(Some(chunk)) => {
                    on_chunk(&chunk);
                    samples.extend_from_slice(&chunk.samples);
                }
                Ok(None) => break Ok(()),
                Err(e) => break Err(e),
            }
        };
        let stopped = self.stop_stream();
        result?;
        stopped?;
        Ok(samples)
    }
}
