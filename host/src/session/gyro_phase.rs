//! Tilting turns for the gyroscope: Tedaldi's method (2014, §IV-B) sees a rotation only through
//! the change of the gravity direction, so each body axis needs tilting rotation about it. When
//! the moves between the positions (and the accelerometer's corners) leave one axis with less
//! than [`super::gyro_moves::LACKING_FRACTION`] of the others' tilting rotation (the advice the
//! person is shown, [`super::gyro_moves::missing_rotation_advice`]), the host asks for the
//! corner position whose shortest turn from the current position tilts the board most about
//! that axis, up to [`super::options::SessionOptions::max_gyro_moves`] of them. On the twelve
//! positions the lacking axis is usually body Z.

use std::io::{Read, Write};

use super::capture::CaptureGoal;
use super::error::SessionError;
use super::events::SessionEvent;
use super::gyro_moves::{missing_rotation_advice, tilt_per_axis_deg};
use super::runner::Runner;
use super::solve::{self, CapturedPose};
use super::targets::{self, Target};
use crate::fit::Vec3;

impl<L: Read + Write> Runner<'_, L> {
    /// Ask for tilting turns about the axis the moves lack (see the module documentation);
    /// returns the note that says what was done.
    pub(super) fn gyro_turns(
        &mut self,
        captured: &mut Vec<CapturedPose>,
    ) -> Result<String, SessionError> {
        let most = self.options.max_gyro_moves;
        let mut added = 0;
        loop {
            let tilt = tilt_per_axis_deg(&self.moves);
            if tilt.iter().sum::<f64>() <= 0.0 {
                return Ok(format!(
                    "none of the {} moves between the holds could be integrated (a gap in the \
                     stream or time stamps that do not increase), so the gyroscope's scale \
                     cannot be calibrated from them",
                    self.moves.len()
                ));
            }
            let Some((axis, advice)) = missing_rotation_advice(&tilt) else {
                return Ok(format!(
                    "the moves tilted the board {:.0}°, {:.0}° and {:.0}° about its X, Y and Z \
                     axes: every axis turned enough for the gyroscope's scale{}",
                    tilt[0],
                    tilt[1],
                    tilt[2],
                    match added {
                        0 => String::new(),
                        n => format!(" after {n} extra turns"),
                    }
                ));
            };
            if added >= most {
                return Ok(format!("{advice} ({added} extra turns were asked for)."));
            }
            let Some(from) = captured.last().map(up_of) else {
                return Ok(advice);
            };
            // Numbered after every target so far, so none is taken for one already captured.
            let first = captured
                .iter()
                .map(|c| c.target.index + 1)
                .max()
                .unwrap_or(0)
                .max(12);
            let left: Vec<Target> = targets::corner_positions(first)
                .into_iter()
                .filter(|t| !captured.iter().any(|c| c.target.up.dot(&t.up) > 0.99))
                .collect();
            let Some(target) = best_turn(&from, &left, axis) else {
                return Ok(format!("{advice}; no corner position is left to turn to"));
            };
            self.observer.event(&SessionEvent::Note(format!(
                "{advice}. Next, {}: the turn there tilts the board about its {} axis",
                target.name,
                ['X', 'Y', 'Z'][axis]
            )));
            let before = captured.len();
            // The corner named tilts most, but any corner the person turns to adds a move.
            let complete = self.capture_targets(
                &left,
                captured,
                self.options.extra_pose_timeout,
                true,
                &CaptureGoal {
                    prompt_first: Some(target.index),
                    ..CaptureGoal::up_to(1)
                },
            )?;
            self.client.stop_stream()?;
            if !complete || captured.len() == before {
                return Ok(format!(
                    "{advice}; no corner was held within {:.0} s",
                    self.options.extra_pose_timeout.as_secs_f64()
                ));
            }
            added += 1;
        }
    }
}

/// The measured up direction of a captured pose (unit).
fn up_of(pose: &CapturedPose) -> Vec3 {
    solve::pose_of(&pose.stats, solve::accel_of)
        .mean
        .try_normalize(0.0)
        .unwrap_or(pose.target.up)
}

/// The target whose shortest turn from `from` tilts the board most about body `axis`: the
/// turn's angle times the share of its axis (perpendicular to both up directions, so a tilt,
/// never a turn about the vertical) along body `axis`.
fn best_turn(from: &Vec3, targets: &[Target], axis: usize) -> Option<Target> {
    let tilt = |t: &Target| {
        let cross = from.cross(&t.up);
        let angle = cross.norm().atan2(from.dot(&t.up));
        cross
            .try_normalize(1e-9)
            .map_or(0.0, |n| angle * n[axis].abs())
    };
    targets
        .iter()
        .max_by(|a, b| tilt(a).total_cmp(&tilt(b)))
        .filter(|t| tilt(t) > 0.0)
        .cloned()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Angle about body `axis` of the shortest turn from `from` to `to`, radians.
    fn about(from: &Vec3, to: &Vec3, axis: usize) -> f64 {
        let cross = from.cross(to);
        let angle = cross.norm().atan2(from.dot(to));
        cross
            .try_normalize(1e-9)
            .map_or(0.0, |n| angle * n[axis].abs())
    }

    #[test]
    fn the_turn_chosen_for_an_axis_tilts_about_it_more_than_any_other_corner() {
        let corners = targets::corner_positions(12);
        for from in [
            Vec3::new(-1.0, 0.0, 1.0).normalize(),
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(1.0, 1.0, 0.0).normalize(),
        ] {
            for axis in 0..3 {
                if from[axis].abs() > 0.999 {
                    // A turn away from up about a horizontal axis cannot be about up itself.
                    assert!(best_turn(&from, &corners, axis).is_none());
                    continue;
                }
                let chosen = best_turn(&from, &corners, axis).expect("a corner");
                let best = about(&from, &chosen.up, axis);
                assert!(best > 0.5, "{} turns {best} rad about {axis}", chosen.name);
                for other in &corners {
                    assert!(about(&from, &other.up, axis) <= best + 1e-12);
                }
            }
        }
    }

    #[test]
    fn no_turn_is_chosen_when_no_corner_is_left() {
        assert!(best_turn(&Vec3::z(), &[], 2).is_none());
    }
}
