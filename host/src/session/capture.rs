//! The positions phase: watch the raw stream for the board to be still in a needed orientation,
//! have the board average a pose there, and keep the stream of each move between holds (the
//! gyroscope's scale fit integrates it). The next orientation prompted is the one that most
//! reduces the worst-direction error of the accelerometer fit ([`plan`]); each hold lasts until
//! its mean is as good as the fit needs ([`hold`]). After the twelve, corner positions are asked
//! for when the fit's covariance says they help, and no more of them once it meets its target.

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use imucal_protocol::ErrorCode;

use super::error::SessionError;
use super::events::{Phase, SessionEvent};
use super::gyro_moves;
use super::runner::{names, Runner};
use super::solve::{self, CapturedPose};
use super::targets::{self, Target};
use super::{hold, plan};
use crate::device::{DeviceError, PoseRequest};
use crate::fit::norm_lm::fit_accel_lm;
use crate::fit::{Pose, Vec3};

/// When a capture phase is done, and what it prompts for.
pub(super) struct CaptureGoal<'e> {
    /// Most targets captured.
    pub most: usize,
    /// Whether the poses captured so far suffice (asked after each capture).
    pub enough: &'e dyn Fn(&[CapturedPose]) -> bool,
    /// Index of the target prompted for while it is needed; otherwise the prompt names the
    /// one that helps the accelerometer fit most ([`plan`]). Any needed target counts.
    pub prompt_first: Option<usize>,
    /// The count of positions the prompts show as their total, when the phase asks for one
    /// position at a time up to more (the gyroscope's turns); otherwise this call's own.
    pub shown_total: Option<usize>,
}

impl CaptureGoal<'_> {
    /// Up to `most` targets, the accelerometer's choice prompted, never enough before.
    pub(super) fn up_to(most: usize) -> Self {
        CaptureGoal {
            most,
            enough: &|_| false,
            prompt_first: None,
            shown_total: None,
        }
    }
}

impl<L: Read + Write> Runner<'_, L> {
    /// Capture the targets of `targets` not yet in `captured` as `goal` says. Returns `false`
    /// when `timeout` passed without progress and `give_up_quietly` is set.
    pub(super) fn capture_targets(
        &mut self,
        targets: &[Target],
        captured: &mut Vec<CapturedPose>,
        timeout: Duration,
        give_up_quietly: bool,
        goal: &CaptureGoal<'_>,
    ) -> Result<bool, SessionError> {
        let (most, enough) = (goal.most, goal.enough);
        let start = captured.len();
        let total = start
            + most.min(
                targets
                    .iter()
                    .filter(|t| !captured.iter().any(|c| c.target.index == t.index))
                    .count(),
            );
        // What the prompts count to: never below the position being asked for.
        let shown_total = goal.shown_total.unwrap_or(total).max(total);
        // Every target in, `most` of them, or enough by the goal's own measure.
        let finished = |captured: &[CapturedPose]| {
            captured.len() >= total
                || targets
                    .iter()
                    .all(|t| captured.iter().any(|c| c.target.index == t.index))
                || enough(captured)
        };
        self.start_watching()?;
        let mut last_progress = Instant::now();
        let mut prompted = None;
        // The prompt changes only with the poses captured: (poses when chosen, target index).
        let mut choice: Option<(usize, usize)> = None;
        // The capture starts right after the last watched sample.
        let mut last_sample_s = 0.0;
        loop {
            let needed: Vec<&Target> = targets
                .iter()
                .filter(|t| !captured.iter().any(|c| c.target.index == t.index))
                .collect();
            if finished(captured) {
                return Ok(true);
            }
            if choice.is_none_or(|(count, _)| count != captured.len()) {
                let first = goal
                    .prompt_first
                    .filter(|index| needed.iter().any(|t| t.index == *index));
                choice = first
                    .or_else(|| {
                        plan::most_informative(captured, &needed, self.options.gravity_mps2)
                            .map(|t| t.index)
                    })
                    .map(|index| (captured.len(), index));
            }
            let Some(next) = choice
                .and_then(|(_, index)| needed.iter().find(|t| t.index == index))
                .or(needed.first())
            else {
                return Ok(true);
            };
            if prompted != Some(next.index) {
                self.observer.event(&SessionEvent::Prompt {
                    target: next,
                    captured: captured.len(),
                    total: shown_total,
                });
                prompted = Some(next.index);
            }
            if last_progress.elapsed() > timeout {
                self.client.stop_stream()?;
                if give_up_quietly {
                    return Ok(false);
                }
                return Err(SessionError::NoProgress {
                    port: self.client.port_name().to_string(),
                    waited_s: timeout.as_secs_f64(),
                    missing: names(&needed),
                    link_note: self.client.stats().noisy_link_note(),
                });
            }
            let chunk = self.read_chunk()?;
            let mut latest = None;
            self.current_move_lost |= chunk.lost_before > 0;
            self.current_move.extend_from_slice(&chunk.samples);
            for sample in &chunk.samples {
                self.record_mag(sample, Phase::Positions);
                last_sample_s = sample.t_s;
                if let Some(state) = self.monitor.push(sample) {
                    latest = Some(state);
                }
            }
            let Some(state) = latest else {
                continue;
            };
            let at = targets::target_at(targets, &state.up);
            let wanted = at.filter(|t| needed.iter().any(|n| n.index == t.index));
            self.observer.event(&SessionEvent::Motion {
                state,
                at,
                needed: wanted.is_some(),
                settle_s: self.options.settle_s,
            });
            let Some(target) = wanted else {
                continue;
            };
            if !(state.still && state.still_for_s >= self.options.settle_s) {
                continue;
            }
            self.client.stop_stream()?;
            let request = PoseRequest {
                min_still: hold::hold_length(
                    &self.current_move,
                    self.options.window_s,
                    self.options.budgets.accel_mg,
                    self.options.hold,
                ),
                thresholds: self.options.thresholds,
                timeout: self.options.capture_timeout,
            };
            self.finish_move();
            let observer = &mut *self.observer;
            let hold_s = request.min_still.as_secs_f64();
            let result = self.client.capture_pose(&request, &mut |progress| {
                observer.event(&SessionEvent::Capturing {
                    target,
                    progress: *progress,
                    hold_s,
                });
            });
            // The next prompt is the stream starting again: it starts before the journal and
            // the screen are updated, so the person is not kept waiting on them.
            let mut restarted = false;
            match result {
                Ok(stats) => {
                    let up = Vec3::from(stats.accel_mean.map(f64::from));
                    let landed = targets::target_at(targets, &up)
                        .filter(|t| !captured.iter().any(|c| c.target.index == t.index));
                    match landed {
                        Some(actual) => {
                            captured.push(CapturedPose {
                                target: actual.clone(),
                                stats,
                                t_s: last_sample_s + 0.5 * f64::from(stats.duration_ms) * 1e-3,
                            });
                            if !finished(captured) {
                                self.start_watching()?;
                                restarted = true;
                            }
                            last_progress = Instant::now();
                            if let Some(pose) = captured.last() {
                                self.journal.pose(pose)?;
                            }
                            self.observer.event(&SessionEvent::Captured {
                                target: actual,
                                samples: stats.n,
                                captured: captured.len(),
                                total: shown_total,
                            });
                            self.tell_missing_rotation(captured);
                        }
                        None => self.observer.event(&SessionEvent::CaptureFailed {
                            target,
                            reason: "the board ended up in another orientation during the \
                                     capture; the pose was discarded"
                                .into(),
                        }),
                    }
                }
                Err(DeviceError::Device { code, .. })
                    if matches!(
                        code,
                        ErrorCode::NotStill | ErrorCode::Timeout | ErrorCode::Saturated
                    ) =>
                {
                    let reason = match code {
                        ErrorCode::Saturated => {
                            "a reading hit the sensor's range; hold the board without knocking it"
                        }
                        _ => "the board did not stay still long enough; hold it steadier",
                    };
                    self.observer.event(&SessionEvent::CaptureFailed {
                        target,
                        reason: reason.into(),
                    });
                }
                Err(other) => return Err(other.into()),
            }
            if !restarted && !finished(captured) {
                self.start_watching()?;
            }
        }
    }

    /// After the twelve: ask for corner positions if the covariance says they help.
    pub(super) fn extra_positions(
        &mut self,
        captured: &mut Vec<CapturedPose>,
    ) -> Result<String, SessionError> {
        let target_mg = self.options.budgets.accel_mg / 4.0;
        let predicted = expected_norm_error_mg(captured, self.options.gravity_mps2);
        if !predicted.is_finite() {
            return Ok(
                "the accelerometer fit of the positions failed or gave no covariance, so the \
                 benefit of extra positions could not be judged; none were asked for"
                    .into(),
            );
        }
        if predicted <= target_mg {
            return Ok(format!(
                "the {} positions so far give an expected |a| error of {predicted:.3} mg (1σ), \
                 within the {target_mg:.2} mg target (a quarter of the {:.1} mg budget); no extra \
                 positions needed (the final fit adds the session's later holds and states its \
                 own σ)",
                captured.len(),
                self.options.budgets.accel_mg
            ));
        }
        if self.options.max_extra_poses == 0 {
            return Ok(format!(
                "the expected |a| error is {predicted:.3} mg (1σ), above the {target_mg:.2} mg \
                 target, but extra positions are switched off"
            ));
        }
        // Any corner helps; the prompt names the one that helps most ([`plan`]), and the
        // phase ends as soon as the expected error meets the target.
        let corners = corners_left(captured);
        let gravity = self.options.gravity_mps2;
        let most = self.options.max_extra_poses;
        let before = captured.len();
        let enough =
            move |poses: &[CapturedPose]| expected_norm_error_mg(poses, gravity) <= target_mg;
        self.observer.event(&SessionEvent::Note(format!(
            "the expected |a| error is {predicted:.3} mg (1σ), above the {target_mg:.2} mg \
             target: up to {most} corner positions will help (any corner; the phase ends once \
             the target is met)"
        )));
        let complete = self.capture_targets(
            &corners,
            captured,
            self.options.extra_pose_timeout,
            true,
            &CaptureGoal {
                most,
                enough: &enough,
                prompt_first: None,
                shown_total: None,
            },
        )?;
        if complete {
            self.client.stop_stream()?;
        }
        let added = captured.len() - before;
        let now = expected_norm_error_mg(captured, gravity);
        Ok(if complete {
            format!(
                "the expected |a| error with {before} positions was {predicted:.3} mg (1σ), above \
                 the {target_mg:.2} mg target; {added} corner positions were added, giving \
                 {now:.3} mg"
            )
        } else {
            format!(
                "the expected |a| error with {before} positions was {predicted:.3} mg (1σ), above \
                 the {target_mg:.2} mg target; {added} corner positions were held before the \
                 {:.0} s limit ({now:.3} mg), so the fit goes on with what there is",
                self.options.extra_pose_timeout.as_secs_f64()
            )
        })
    }

    /// Say which of the board's axes the moves so far have hardly turned about (a turn about
    /// the vertical does not count: the gyroscope's scale fit cannot see it).
    fn tell_missing_rotation(&mut self, captured: &[CapturedPose]) {
        if captured.len() < gyro_moves::MIN_MOVES_FOR_ADVICE {
            return;
        }
        let tilt = gyro_moves::tilt_per_axis_deg(&self.moves);
        let advice = gyro_moves::missing_rotation_advice(&tilt);
        let axis = advice.as_ref().map(|(axis, _)| *axis);
        // Said once per lacking axis, not after every capture.
        if axis != self.lacking_axis {
            if let Some((_, text)) = advice {
                self.observer.event(&SessionEvent::Note(text));
            }
            self.lacking_axis = axis;
        }
    }
}

/// The corner positions not held yet, numbered after every target in `captured`. A corner is
/// told by its direction, not its number: a resumed session holds corners numbered by the run
/// that captured them.
fn corners_left(captured: &[CapturedPose]) -> Vec<Target> {
    let first = captured
        .iter()
        .map(|c| c.target.index + 1)
        .max()
        .unwrap_or(0)
        .max(captured.len())
        .max(12);
    targets::corner_positions(first)
        .into_iter()
        .filter(|t| !captured.iter().any(|c| c.target.up.dot(&t.up) > 0.99))
        .collect()
}

/// The accelerometer norm fit's expected `|a|` error in its worst direction, mg (1σ), for
/// `captured`; infinite when the fit fails or gives no covariance.
fn expected_norm_error_mg(captured: &[CapturedPose], gravity: f64) -> f64 {
    let poses: Vec<Pose> = captured
        .iter()
        .map(|p| solve::pose_of(&p.stats, solve::accel_of))
        .collect();
    fit_accel_lm(&poses, gravity)
        .ok()
        .and_then(|fit| solve::max_norm_sigma(&fit))
        .map_or(f64::INFINITY, |s| s * 1000.0 / solve::STANDARD_GRAVITY)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::session::plan::tests::pose;
    use crate::session::targets::{corner_positions, twelve_positions};

    #[test]
    fn each_corner_lowers_the_expected_norm_error_left_by_the_twelve() {
        let g = 9.8;
        let mut poses: Vec<CapturedPose> = twelve_positions().iter().map(|t| pose(t, g)).collect();
        let mut before = expected_norm_error_mg(&poses, g);
        assert!(before.is_finite() && before > 0.0, "{before}");
        for corner in corner_positions(12).iter().take(4) {
            poses.push(pose(corner, g));
            let after = expected_norm_error_mg(&poses, g);
            assert!(
                after < before,
                "{after} mg after a corner, {before} mg before"
            );
            before = after;
        }
    }

    #[test]
    fn corners_held_before_a_resume_are_not_asked_for_again() {
        let g = 9.8;
        // A resumed session: the twelve and two corners, numbered 12 and 13 by the first run.
        let mut poses: Vec<CapturedPose> = twelve_positions().iter().map(|t| pose(t, g)).collect();
        let held: Vec<Target> = corner_positions(12).into_iter().take(2).collect();
        poses.extend(held.iter().map(|t| pose(t, g)));
        let left = corners_left(&poses);
        assert_eq!(left.len(), 6);
        for corner in &held {
            assert!(
                left.iter().all(|t| t.name != corner.name),
                "{} is asked for again",
                corner.name
            );
        }
        // Their numbers follow every target so far.
        assert!(left.iter().all(|t| t.index >= 14));
    }
}
