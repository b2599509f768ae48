//! The rest phase: wait until the board lies still, then keep the same full-rate stream for the
//! "before" (raw) error at rest. The raw measurement must stay still all through (it also gives
//! the gyroscope's bias without a hand on the board): a measurement during which the board moved
//! is dropped and starts again once the board has lain still for `rest_settle_s` anew.
//!
//! One stream serves the wait and the measurement: the first `rest_settle_s` of stillness are
//! not kept (the end of the turn into the rest, which would bias the gyroscope's mean rate), the
//! next `rest_measure_s` are. Stopping and restarting the stream in between would only add its
//! round trips to the session.

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use imucal_protocol::{StillThresholds, StreamKind};

use super::error::SessionError;
use super::events::{Phase, SessionEvent};
use super::motion::MotionMonitor;
use super::runner::Runner;
use crate::device::{DeviceClient, UnitSample};

/// What one more sample did to a measurement at rest.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RestProgress {
    /// Not measuring yet: still for `still_for_s` of the `settle_s` needed (0 while moving or
    /// before the first full window).
    Settling { still_for_s: f64 },
    /// Measuring: the first sample kept, or the measurement goes on.
    Measuring { first: bool },
    /// The board moved during the measurement: what was kept is dropped.
    Moved,
    /// `measure_s` of stillness are kept.
    Done,
}

/// The measurement at rest on a running stream: the stillness window decides, the first
/// `settle_s` of stillness are not kept, the next `measure_s` are, and any moving window drops
/// what was kept (see the module documentation).
#[derive(Debug, Clone)]
pub struct RestMeasurement {
    monitor: MotionMonitor,
    settle_s: f64,
    measure_s: f64,
    kept: Vec<UnitSample>,
    done: bool,
}

impl RestMeasurement {
    /// A measurement of `measure_s` after `settle_s` of stillness, judged by windows of
    /// `window_s` against `thresholds`.
    pub fn new(window_s: f64, thresholds: StillThresholds, settle_s: f64, measure_s: f64) -> Self {
        Self {
            monitor: MotionMonitor::new(window_s, thresholds),
            settle_s,
            measure_s,
            kept: Vec::new(),
            done: false,
        }
    }

    /// Add the next sample of the stream (ignored once the measurement is done).
    pub fn push(&mut self, sample: &UnitSample) -> RestProgress {
        if self.done {
            return RestProgress::Done;
        }
        // A clock going backwards is a new stream: what was kept belongs to the old one.
        if self.kept.last().is_some_and(|last| sample.t_s < last.t_s) {
            self.kept.clear();
        }
        let state = self.monitor.push(sample);
        match state {
            Some(state) if state.still && state.still_for_s >= self.settle_s => {
                self.kept.push(*sample);
                if covers(&self.kept, self.measure_s) {
                    self.done = true;
                    RestProgress::Done
                } else {
                    RestProgress::Measuring {
                        first: self.kept.len() == 1,
                    }
                }
            }
            Some(state) if !state.still && !self.kept.is_empty() => {
                self.kept.clear();
                RestProgress::Moved
            }
            state => RestProgress::Settling {
                still_for_s: state.map_or(0.0, |s| s.still_for_s),
            },
        }
    }

    /// The samples kept: the whole measurement once [`RestProgress::Done`].
    pub fn into_samples(self) -> Vec<UnitSample> {
        self.kept
    }
}

impl<L: Read + Write> Runner<'_, L> {
    /// Wait for rest and measure the raw full-rate stream there for `rest_measure_s` of board
    /// time without a moment of motion (see the module documentation), within `rest_timeout`.
    pub(super) fn measure_at_rest(&mut self) -> Result<Vec<UnitSample>, SessionError> {
        self.observer.event(&SessionEvent::RestPrompt);
        let options = self.options;
        let mut rest = RestMeasurement::new(
            options.window_s,
            options.thresholds,
            options.rest_settle_s,
            options.rest_measure_s,
        );
        self.client.start_stream(StreamKind::Raw, 1)?;
        let start = Instant::now();
        loop {
            if start.elapsed() > options.rest_timeout {
                self.client.stop_stream()?;
                return Err(SessionError::NotAtRest {
                    port: self.client.port_name().to_string(),
                    needed_s: options.rest_settle_s + options.rest_measure_s,
                    waited_s: start.elapsed().as_secs_f64(),
                });
            }
            let chunk = self.read_chunk()?;
            let mut settling = None;
            for sample in &chunk.samples {
                self.record_mag(sample, Phase::Rest);
                match rest.push(sample) {
                    RestProgress::Settling { still_for_s } => settling = Some(still_for_s),
                    RestProgress::Measuring { first } => {
                        settling = None;
                        if first {
                            self.observer.event(&SessionEvent::Measuring {
                                kind: StreamKind::Raw,
                            });
                        }
                    }
                    RestProgress::Moved => self.observer.event(&SessionEvent::Note(
                        "the board moved during the measurement at rest; it is measured again \
                         once it lies still"
                            .into(),
                    )),
                    RestProgress::Done => {
                        self.client.stop_stream()?;
                        return Ok(rest.into_samples());
                    }
                }
            }
            if let Some(still_for_s) = settling {
                self.observer.event(&SessionEvent::Resting {
                    still_for_s,
                    needed_s: options.rest_settle_s,
                });
            }
        }
    }

    /// Stream `kind` at full rate for `rest_measure_s` of board time.
    pub(super) fn measure(&mut self, kind: StreamKind) -> Result<Vec<UnitSample>, SessionError> {
        // Its stream does not look at the interrupt: an interrupt before it stops here.
        self.check_interrupt()?;
        self.observer.event(&SessionEvent::Measuring { kind });
        stream_for(
            self.client,
            kind,
            self.options.rest_measure_s,
            self.options.read_timeout,
        )
    }
}

/// Whether `samples` span `seconds` of board time; a NaN request counts as covered, so that it
/// ends a measurement at once instead of never.
fn covers(samples: &[UnitSample], seconds: f64) -> bool {
    let span = match (samples.first(), samples.last()) {
        (Some(a), Some(b)) => b.t_s - a.t_s,
        _ => 0.0,
    };
    span >= seconds || seconds.is_nan()
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
        if covers(&samples, seconds) {
            break Ok(());
        }
    };
    let stopped = client.stop_stream();
    result?;
    stopped?;
    Ok(samples)
}

#[cfg(test)]
mod tests {
    use super::*;

    const RATE_HZ: f64 = 100.0;

    /// A sample at `t_s`: lying still, or turning at 1 rad/s about Z (far above the 0.02 rad/s
    /// limit) with alternating rates so that the window's spread shows it.
    fn sample(t_s: f64, turning: bool) -> UnitSample {
        let k = (t_s * RATE_HZ).round() as i64;
        let wobble = if k % 2 == 0 { 1.0 } else { -1.0 };
        UnitSample {
            t_s,
            accel: [0.0, 0.0, 9.81],
            gyro: [0.0, 0.0, if turning { wobble } else { 1e-3 * wobble }],
            mag: [20.0, 0.0, 40.0],
            temp_c: 25.0,
        }
    }

    fn measurement() -> RestMeasurement {
        let thresholds = StillThresholds {
            accel_std_mps2: 0.1,
            gyro_std_rads: 0.02,
        };
        RestMeasurement::new(0.5, thresholds, 0.5, 3.0)
    }

    /// Push samples from `from_s` for `seconds`; the progress of each.
    fn push(
        rest: &mut RestMeasurement,
        from_s: f64,
        seconds: f64,
        turning: bool,
    ) -> Vec<RestProgress> {
        let count = (seconds * RATE_HZ).round() as usize;
        (0..count)
            .map(|k| rest.push(&sample(from_s + k as f64 / RATE_HZ, turning)))
            .collect()
    }

    #[test]
    fn a_board_lying_still_is_measured_after_the_window_and_the_settle_time() {
        let mut rest = measurement();
        let progress = push(&mut rest, 0.0, 10.0, false);
        let done = progress
            .iter()
            .position(|p| *p == RestProgress::Done)
            .expect("done");
        // The window fills at ≈0.45 s (90 % of it), stillness counts from there, 0.5 s of it is
        // not kept, then 3 s are: done at ≈3.95 s, one sample's spacing either way.
        let done_s = done as f64 / RATE_HZ;
        assert!((done_s - 3.95).abs() <= 0.015, "done at {done_s} s");
        let kept = rest.into_samples();
        let span = kept.last().expect("kept").t_s - kept[0].t_s;
        assert!((3.0..3.0 + 1.5 / RATE_HZ).contains(&span), "span {span}");
        assert!(
            kept[0].t_s >= 0.45 + 0.5 - 1e-9,
            "first kept {}",
            kept[0].t_s
        );
    }

    #[test]
    fn a_move_during_the_measurement_drops_it_and_it_starts_again_after_the_settle_time() {
        let mut rest = measurement();
        let before = push(&mut rest, 0.0, 2.0, false);
        assert!(before.contains(&RestProgress::Measuring { first: true }));
        assert!(!before.contains(&RestProgress::Done));
        let knock = push(&mut rest, 2.0, 0.2, true);
        assert_eq!(
            knock.iter().filter(|p| **p == RestProgress::Moved).count(),
            1,
            "one drop per move"
        );
        let after = push(&mut rest, 2.2, 6.0, false);
        assert!(after.contains(&RestProgress::Done));
        let kept = rest.into_samples();
        // The window holds the knock until 2.7 s; then 0.5 s of stillness are not kept (one
        // sample's spacing for the rounding of the window's edge).
        assert!(
            kept[0].t_s >= 3.2 - 1.5 / RATE_HZ,
            "first kept {}",
            kept[0].t_s
        );
        assert!(kept.iter().all(|s| s.gyro[2].abs() < 0.01));
    }

    #[test]
    fn a_board_that_keeps_turning_is_never_measured() {
        let mut rest = measurement();
        let progress = push(&mut rest, 0.0, 10.0, true);
        assert!(progress
            .iter()
            .all(|p| *p == RestProgress::Settling { still_for_s: 0.0 }));
        assert!(rest.into_samples().is_empty());
    }
}
