//! Tilting turns for the gyroscope: Tedaldi's method (2014, §IV-B) sees a rotation only through
//! the change of the gravity direction, so each body axis needs tilting rotation about it. After
//! the positions, the host fits the gyroscope's `A` to the moves so far against gravity alone
//! (the accelerometer fitted on the positions, the bias from the holds' means) and, while an
//! entry's σ from that fit's own residuals is over a third of its budget (the verdict's 3σ),
//! asks for the corner position whose shortest turn from the current position tilts the board
//! most about the axis that entry's column needs, up to
//! [`super::options::SessionOptions::max_gyro_moves`] of them. The final fit adds the field and
//! the rest's bias, so this is a guide, not its σ. When the fit fails the host falls back on the
//! tilt each axis got ([`super::gyro_moves::missing_rotation_advice`]). On the twelve positions
//! the weak axis is usually body Z; four turns cost ≈ 15 s of a ≈ 60 s session.

use std::io::{Read, Write};

use super::capture::CaptureGoal;
use super::error::SessionError;
use super::events::SessionEvent;
use super::gyro_fit::{fit_against_gravity, GyroBudgets};
use super::gyro_moves::{axis_turn_example, missing_rotation_advice, tilt_per_axis_deg};
use super::runner::Runner;
use super::solve::{self, CapturedPose};
use super::targets::{self, Target};
use crate::device::UnitSample;
use crate::fit::gyro_scale::MIN_MOTIONS;
use crate::fit::norm_lm::fit_accel_lm;
use crate::fit::{Mat3, Vec3};

impl<L: Read + Write> Runner<'_, L> {
    /// Ask for tilting turns about the axis the moves lack (see the module documentation);
    /// returns the note that says what was done.
    pub(super) fn gyro_turns(
        &mut self,
        captured: &mut Vec<CapturedPose>,
    ) -> Result<String, SessionError> {
        // At least as many turns as the scale fit lacks moves (a resumed session that kept
        // none has to make them all).
        let most = self
            .options
            .max_gyro_moves
            .max(MIN_MOTIONS.saturating_sub(self.moves.len()));
        let mut added = 0;
        // The prompts count to every turn the phase may ask for, not one more at a time.
        let phase_total = captured.len() + most;
        loop {
            let tilt = tilt_per_axis_deg(&self.moves);
            // No moves at all (a resumed session that kept none) is asked for below; moves that
            // are there but could not be integrated are a fault of the stream.
            if !self.moves.is_empty() && tilt.iter().sum::<f64>() <= 0.0 {
                return Ok(format!(
                    "none of the {} moves between the holds could be integrated (a gap in the \
                     stream or time stamps that do not increase), so the gyroscope's scale \
                     cannot be calibrated from them",
                    self.moves.len()
                ));
            }
            let relative = predicted_relative_sigma(
                captured,
                &self.moves,
                self.options.gravity_mps2,
                f64::from(self.options.thresholds.gyro_std_rads),
            );
            let lacking = match &relative {
                Some(relative) => lacking_rotation(relative, &self.options.gyro_budgets),
                // Too few moves for the scale fit at all (a resumed session whose moves were
                // lost): more turns, about the axis turned least.
                None if self.moves.len() < MIN_MOTIONS => too_few_moves(&tilt, self.moves.len()),
                None => missing_rotation_advice(&tilt),
            };
            let Some((axis, advice)) = lacking else {
                let after = match added {
                    0 => String::new(),
                    n => format!(" after {n} extra turns"),
                };
                let [x, y, z] = tilt;
                return Ok(match relative {
                    Some(relative) => {
                        let scale = [0, 1, 2].map(|i| relative[(i, i)] * 100.0);
                        let angle = (0..9)
                            .filter(|k| k / 3 != k % 3)
                            .map(|k| relative[(k / 3, k % 3)])
                            .fold(0.0, f64::max)
                            .to_degrees();
                        format!(
                            "the moves tilted the board {x:.0}°, {y:.0}° and {z:.0}° about its X, \
                             Y and Z axes{after}: against gravity alone they give the \
                             gyroscope's scale ±{:.3}, ±{:.3} and ±{:.3} % and its \
                             misalignment ±{angle:.3}° at most (1σ), within a third of the \
                             budgets",
                            scale[0], scale[1], scale[2]
                        )
                    }
                    None => format!(
                        "the moves tilted the board {x:.0}°, {y:.0}° and {z:.0}° about its X, Y \
                         and Z axes: every axis turned enough for the gyroscope's scale{after}"
                    ),
                });
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
                    shown_total: Some(phase_total),
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

/// 1σ of the gyroscope's `A` relative to its diagonal (`σ(A_rc)/|A_cc|`: the scale error on the
/// diagonal, the misalignment angle in radians off it) from the session's fit of the moves so
/// far against gravity alone ([`fit_against_gravity`]), with the accelerometer fitted on `captured` and the gyroscope's bias
/// from the holds' means, its covariance from the fit's own residuals. `None` when a fit fails.
/// The axis turned least and a sentence asking for turns about it, when there are fewer than
/// [`MIN_MOTIONS`] moves, the fewest the gyroscope's scale fit takes.
fn too_few_moves(tilt_deg: &[f64; 3], moves: usize) -> Option<(usize, String)> {
    let (axis, _) = tilt_deg
        .iter()
        .copied()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    let (name, example) = axis_turn_example(axis);
    Some((
        axis,
        format!(
            "the gyroscope's scale needs at least {MIN_MOTIONS} moves between holds and there \
             are {moves}; turn the board between positions, about {name} first (e.g. {example})"
        ),
    ))
}

fn predicted_relative_sigma(
    captured: &[CapturedPose],
    moves: &[Vec<UnitSample>],
    gravity: f64,
    still_rate: f64,
) -> Option<Mat3> {
    let poses: Vec<_> = captured
        .iter()
        .map(|p| solve::pose_of(&p.stats, solve::accel_of))
        .collect();
    let accel = fit_accel_lm(&poses, gravity).ok()?;
    let bias = captured
        .iter()
        .map(|p| solve::pose_of(&p.stats, solve::gyro_of).mean)
        .sum::<Vec3>()
        / captured.len().max(1) as f64;
    let (fit, _) = fit_against_gravity(moves, &accel.cal, &bias, still_rate, None).ok()?;
    let std = fit.std?;
    let relative = Mat3::from_fn(|r, c| std.a[(r, c)] / fit.cal.a[(c, c)].abs());
    relative.iter().all(|s| s.is_finite()).then_some(relative)
}

/// The body axis whose rotation the fit most needs, with a sentence naming a turn that supplies
/// it; `None` when every entry of `relative` ([`predicted_relative_sigma`]) is within a third
/// of its budget (the verdict's 3σ). Rotation about axis `c` is what pins column `c` of `A`:
/// its scale and the misalignments of the other outputs to it.
fn lacking_rotation(relative: &Mat3, budgets: &GyroBudgets) -> Option<(usize, String)> {
    let scale_allowed = budgets.scale_pct / 100.0 / 3.0;
    let angle_allowed = budgets.misalignment_deg.to_radians() / 3.0;
    let need =
        |r: usize, c: usize| relative[(r, c)] / if r == c { scale_allowed } else { angle_allowed };
    let (r, c) = (0..9)
        .map(|k| (k / 3, k % 3))
        .max_by(|a, b| need(a.0, a.1).total_cmp(&need(b.0, b.1)))?;
    if need(r, c) <= 1.0 {
        return None;
    }
    let (name, example) = axis_turn_example(c);
    let what = if r == c {
        format!(
            "{name} scale at ±{:.3} % (1σ), over the {:.3} %",
            relative[(r, c)] * 100.0,
            scale_allowed * 100.0
        )
    } else {
        format!(
            "misalignment of its {} axis to {name} at ±{:.3}° (1σ), over the {:.3}°",
            ['X', 'Y', 'Z'][r],
            relative[(r, c)].to_degrees(),
            angle_allowed.to_degrees()
        )
    };
    Some((
        c,
        format!(
            "against gravity alone, the moves so far leave the gyroscope's {what} its budget \
             allows at 3σ; turns that tilt the board about {name} help (e.g. {example}); a turn \
             about the vertical does not count"
        ),
    ))
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

    #[test]
    fn too_few_moves_ask_for_turns_about_the_axis_turned_least() {
        let (axis, text) = too_few_moves(&[40.0, 3.0, 25.0], 2).expect("asked");
        assert_eq!(axis, 1);
        assert!(
            text.contains("at least 5 moves") && text.contains("there are 2"),
            "{text}"
        );
        assert!(text.contains("about Y first"), "{text}");
        // No moves at all (a resumed session that kept none): the first axis.
        assert_eq!(too_few_moves(&[0.0; 3], 0).map(|(a, _)| a), Some(0));
    }

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
    fn turns_are_asked_about_the_axis_whose_column_most_exceeds_its_share_of_the_budgets() {
        let budgets = GyroBudgets::default();
        // Z's scale at 0.045 % against 0.033 % allowed; X's misalignment to Y at 1.3× its share.
        let mut relative = Mat3::from_diagonal(&Vec3::new(0.0001, 0.0002, 0.00045));
        relative[(0, 1)] = (0.05_f64 / 3.0 * 1.3).to_radians();
        let (axis, text) = lacking_rotation(&relative, &budgets).expect("an axis lacks");
        assert_eq!(axis, 2, "{text}");
        assert!(text.contains("Z scale at ±0.045 %"), "{text}");
        relative[(2, 2)] = 0.0003;
        let (axis, text) = lacking_rotation(&relative, &budgets).expect("Y's column lacks");
        assert_eq!(axis, 1, "{text}");
        assert!(text.contains("misalignment of its X axis to Y"), "{text}");
        relative[(0, 1)] = 0.0;
        assert!(lacking_rotation(&relative, &budgets).is_none());
    }

    #[test]
    fn no_turn_is_chosen_when_no_corner_is_left() {
        assert!(best_turn(&Vec3::z(), &[], 2).is_none());
    }
}
