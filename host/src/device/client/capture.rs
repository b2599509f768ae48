//! Pose capture: the board averages a still pose on request, with the resend rules of
//! [`DeviceClient::capture_pose`] for lost requests and replies.

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use imucal_protocol::{ErrorCode, PoseStats, RequestBody, ResponseBody, StillThresholds};

use super::{deadline_after, DeviceClient};
use crate::device::DeviceError;

/// What a pose capture is waiting on, reported to the progress callback.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseProgress {
    /// Time since the request was sent.
    pub elapsed: Duration,
    /// The capture's timeout.
    pub timeout: Duration,
    /// Whether the board last reported itself still (`None` until it says).
    pub still: Option<bool>,
}

/// Parameters of a pose capture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseRequest {
    /// Minimum duration of still data to average.
    pub min_still: Duration,
    /// What counts as still.
    pub thresholds: StillThresholds,
    /// Give up after this long.
    pub timeout: Duration,
}

/// Where a pose capture's resending stands (see [`DeviceClient::capture_pose`]).
#[derive(Debug, Clone, Copy)]
struct CaptureResend {
    /// When the request was last sent.
    sent_at: Instant,
    /// Sends so far, the first included.
    sends: u32,
    /// Resends that may have started a new capture.
    restarts: u32,
    /// Whether a `Busy` since the last send showed the capture running.
    running: bool,
    /// Whether the first send found another capture running, not yet seen to end.
    busy_elsewhere: bool,
    /// Whether a `Busy` answered since the last send.
    busy_answered: bool,
    /// Frame errors counted at the last send.
    frame_errors: u64,
}

impl<L: Read + Write> DeviceClient<L> {
    /// Asks the board to average a still pose; `progress` is called about every read poll
    /// and on each stillness change while the board waits for stillness and averages.
    ///
    /// A lost request or reply is recovered by resending with the same `seq`: every reply
    /// timeout until a `Busy` answer shows the capture running, then only after a lost frame (at
    /// most `tries − 1` times, each may start a new capture). A `Busy` to the first send (another
    /// capture runs) is waited out by resending until that capture ends.
    pub fn capture_pose(
        &mut self,
        pose: &PoseRequest,
        progress: &mut dyn FnMut(&PoseProgress),
    ) -> Result<PoseStats, DeviceError> {
        let to_ms = |d: Duration| u32::try_from(d.as_millis()).unwrap_or(u32::MAX);
        let body = RequestBody::CapturePose {
            min_still_ms: to_ms(pose.min_still),
            thresholds: pose.thresholds,
            timeout_ms: to_ms(pose.timeout),
        };
        let seq = self.take_seq();
        let bad_before = self.stats.frame_errors;
        self.send_request(seq, &body)?;
        let start = Instant::now();
        let one_capture = pose.timeout.saturating_add(self.options.flash_timeout);
        let mut deadline = deadline_after(one_capture);
        let mut resend = CaptureResend {
            sent_at: start,
            sends: 1,
            restarts: 0,
            running: false,
            busy_elsewhere: false,
            busy_answered: false,
            frame_errors: self.stats.frame_errors,
        };
        let reply = loop {
            let waited = self.wait_reply(
                seq,
                deadline.min(Instant::now() + Duration::from_millis(100)),
            )?;
            progress(&PoseProgress {
                elapsed: start.elapsed(),
                timeout: pose.timeout,
                still: self.still,
            });
            match waited {
                // Busy to the first send: another capture runs (perhaps one a resend started
                // just as the previous capture ended); resend until it is over.
                Some(ResponseBody::Error(ErrorCode::Busy)) if resend.sends == 1 => {
                    resend.busy_elsewhere = true;
                    continue;
                }
                // Busy to a resend: the capture an earlier send started is still running.
                Some(ResponseBody::Error(ErrorCode::Busy)) => {
                    resend.running = !resend.busy_elsewhere;
                    resend.busy_answered = true;
                    continue;
                }
                Some(reply) => break reply,
                None => {}
            }
            let now = Instant::now();
            if now >= deadline && resend.busy_elsewhere {
                return Err(DeviceError::Device {
                    port: self.port.clone(),
                    request: "CapturePose",
                    code: ErrorCode::Busy,
                });
            }
            if now >= deadline {
                return Err(DeviceError::NoAnswer {
                    port: self.port.clone(),
                    request: "CapturePose",
                    tries: resend.sends,
                    bad_frames: self.stats.frame_errors.saturating_sub(bad_before),
                });
            }
            if let Some(restart) = self.capture_resend_due(&resend, now, pose.timeout) {
                if resend.busy_elsewhere && resend.sends > 1 && !resend.busy_answered {
                    // The last resend drew no Busy: the other capture is over and ours runs.
                    resend.busy_elsewhere = false;
                    deadline = deadline.max(deadline_after(one_capture));
                }
                if restart {
                    // The board may start a whole new capture.
                    resend.restarts += 1;
                    deadline = deadline.max(deadline_after(one_capture));
                }
                self.stats.retries += 1;
                self.send_request(seq, &body)?;
                resend = CaptureResend {
                    sent_at: now,
                    sends: resend.sends + 1,
                    running: false,
                    busy_answered: false,
                    frame_errors: self.stats.frame_errors,
                    ..resend
                };
            }
        };
        match reply {
            ResponseBody::PoseStats(stats) => Ok(stats),
            ResponseBody::Error(code) => Err(DeviceError::Device {
                port: self.port.clone(),
                request: "CapturePose",
                code,
            }),
            other => Err(self.unexpected("CapturePose", &other)),
        }
    }

    /// Whether a pose capture should be resent now (`Some(true)`: one that may start a new
    /// capture, because the running one may have ended with a lost reply).
    ///
    /// Until a `Busy` has confirmed that the capture runs, the request is resent every reply
    /// timeout: the request or the `Busy` may have been lost. Once confirmed, it is resent only
    /// when the reply may have been lost, at most `tries − 1` times: after a lost frame and a
    /// reply timeout of silence, or after silence longer than the board's own capture timeout
    /// `capture` and a reply timeout (the board has answered by then, so its reply was lost
    /// whole, without a frame error to show for it). Resending on a short silence alone could
    /// start a second capture just as the first ends, leaving the board busy for the next one.
    fn capture_resend_due(
        &self,
        resend: &CaptureResend,
        now: Instant,
        capture: Duration,
    ) -> Option<bool> {
        let silent = now.saturating_duration_since(resend.sent_at);
        if silent < self.options.reply_timeout {
            return None;
        }
        if !resend.running {
            return Some(false);
        }
        let frame_lost = self.stats.frame_errors > resend.frame_errors;
        let overdue = silent >= capture.saturating_add(self.options.reply_timeout);
        let reply_may_be_lost = frame_lost || overdue;
        (reply_may_be_lost && resend.restarts + 1 < self.options.tries.max(1)).then_some(true)
    }
}
