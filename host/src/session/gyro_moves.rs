//! The moves between holds as data for the gyroscope's scale and misalignment fit (Tedaldi,
//! Pretto & Menegatti 2014, §IV-B; [`crate::fit::gyro_scale::fit_gyro_scale`]).
//!
//! A move is the raw stream from the end of one hold to the start of the next capture. Its two
//! ends are still (the stream starts as the previous capture ends, and stops once the board has
//! been still for the settle time), and give the gravity direction at the move's first and last
//! sample. Each end averages the calibrated accelerometer over its still stretch, every sample
//! first turned with the integrated gyroscope into the frame of the stretch's sample next to the
//! turn (`Rₛ←ⱼ·aⱼ`), so the hand's sway within the stretch does not blur the direction the
//! integration starts from, and only the turn itself is integrated.
//!
//! How much each body axis was tilted (turned about an axis perpendicular to gravity) tells the
//! person which turn is still missing: a turn about the vertical leaves gravity unchanged and
//! says nothing about the gyroscope's scale.

use nalgebra::UnitQuaternion;

use crate::device::UnitSample;
use crate::fit::gyro_scale::{integrate_rotation, sample_step_s, GyroMotion};
use crate::fit::{Calibration, Mat3, Vec3};

/// Moves needed before the session comments on which axis lacks rotation.
pub const MIN_MOVES_FOR_ADVICE: usize = 4;

/// Longest still stretch at either end of a move averaged for its gravity direction, s: long
/// enough to average the accelerometer's noise (≈95 samples at 119 Hz), short enough to stay
/// within the hold.
const EDGE_MAX_S: f64 = 0.8;

/// Fewest samples in an end's still stretch for the move to be used.
const EDGE_MIN_SAMPLES: usize = 5;

/// An axis whose tilting rotation is below this fraction of the mean of the other two counts
/// as lacking: the scale fit's σ along an axis grows at least as the inverse of its rotation,
/// so under half of the others at least doubles it, and that axis alone then sets how far a
/// full turn integrates off. (This measure counts each move's whole rotation off the starting
/// vertical, so it understates a lack: on the simulated sessions Z at 0.41–0.46 of the others
/// had 3–4 times X's σ.)
pub const LACKING_FRACTION: f64 = 0.5;

/// Rotation from each sample's body frame to the first sample's (`R₀←ⱼ`), integrating `a·rates`.
fn prefix_rotations(a: &Mat3, rates: &[Vec3], dt: f64) -> Vec<UnitQuaternion<f64>> {
    let mut out = Vec::with_capacity(rates.len());
    let mut q = UnitQuaternion::identity();
    out.push(q);
    for pair in rates.windows(2) {
        q *= integrate_rotation(a, pair, dt);
        out.push(q);
    }
    out
}

/// Number of samples from the start of `rates` that turn slower than `still_rate` (rad/s), at
/// most `max`.
fn still_run(rates: impl Iterator<Item = Vec3>, still_rate: f64, max: usize) -> usize {
    rates
        .take(max)
        .take_while(|w| w.norm() < still_rate)
        .count()
}

/// Variance, per component perpendicular to it, of the mean direction of `vectors`
/// (rad²): the scatter of the unit directions about their mean over `n − 1`, halved between the
/// two perpendicular components, over `n`. `None` for fewer than two vectors.
pub(super) fn direction_variance(vectors: &[Vec3]) -> Option<f64> {
    let n = vectors.len();
    if n < 2 {
        return None;
    }
    let mean = vectors.iter().sum::<Vec3>() / n as f64;
    let norm = mean.norm();
    let unit = mean.try_normalize(0.0)?;
    let scatter: f64 = vectors
        .iter()
        .map(|v| {
            let d = (v - mean) / norm;
            (d - unit * unit.dot(&d)).norm_squared()
        })
        .sum();
    Some(scatter / (n - 1) as f64 / 2.0 / n as f64)
}

/// White noise of one gyroscope sample per axis (rad/s) estimated from the still ends:
/// `var(ωₖ₊₁ − ωₖ)/2` removes the slow sway of the hand (it changes little from one sample to
/// the next), leaving the sensor's noise (and any fast tremor, which moves the board alike).
fn rate_noise_of_ends(rates: &[Vec3], head: usize, tail: usize) -> f64 {
    let ends = [
        &rates[..head.min(rates.len())],
        &rates[rates.len().saturating_sub(tail)..],
    ];
    let (mut sum, mut count) = (0.0, 0usize);
    for end in ends {
        for pair in end.windows(2) {
            sum += (pair[1] - pair[0]).norm_squared() / 3.0;
            count += 1;
        }
    }
    if count == 0 {
        return 0.0;
    }
    (sum / count as f64 / 2.0).sqrt()
}

/// The move as a [`GyroMotion`]: gyroscope rates bias-corrected with `bias` (rad/s), gravity
/// directions from `accel` (a calibrated accelerometer) averaged over the still ends, turned
/// with `a` (the current estimate of the gyroscope matrix). `None` when the stream has a gap or
/// an end is not still for at least [`EDGE_MIN_SAMPLES`] samples (rate below `still_rate`).
///
/// Its angle σ adds, per component: the variance of each end's mean gravity direction (the
/// scatter of its sway-corrected samples over their number, [`direction_variance`]); the
/// gyroscope's white noise `σ_ω` (`rate_noise`, rad/s per sample, or estimated from the ends when
/// `None`) integrated over the turn's `N` steps, `σ_ω²·dt²·N` (angle random walk, IEEE Std 952);
/// and the same noise carried into each end's mean by the sway correction, `σ_ω²·dt²·n/3` for an
/// end of `n` samples (the mean of a random walk over `n` steps).
pub fn motion_of(
    samples: &[UnitSample],
    accel: &Calibration,
    a: &Mat3,
    bias: &Vec3,
    still_rate: f64,
    rate_noise: Option<f64>,
) -> Option<GyroMotion> {
    let ends = move_ends(samples, a, bias, still_rate)?;
    gravity_motion(&ends, samples, accel, rate_noise)
}

/// A move's still ends: its even step, bias-corrected rates, the still head and tail lengths,
/// and each sample's rotation into the first sample's frame (`R₀←ⱼ`, integrating `a·rates`).
pub(super) struct MoveEnds {
    pub(super) dt: f64,
    pub(super) rates: Vec<Vec3>,
    pub(super) head: usize,
    pub(super) tail: usize,
    pub(super) to_first: Vec<UnitQuaternion<f64>>,
}

impl MoveEnds {
    /// Last sample of the still head and first of the still tail: only the turn between them
    /// is integrated, so the bias error acts over the turn alone.
    pub(super) fn turn(&self) -> (usize, usize) {
        (self.head - 1, self.rates.len() - self.tail)
    }

    /// `value(j)` of the head's samples, each turned into the frame of the head's last sample,
    /// and of the tail's, each turned into the frame of its first (the sway correction).
    pub(super) fn turned_ends(&self, value: impl Fn(usize) -> Vec3) -> (Vec<Vec3>, Vec<Vec3>) {
        let (start, end) = self.turn();
        let at_start = self.to_first[start].inverse();
        let at_end = self.to_first[end].inverse();
        let head = (0..self.head)
            .map(|j| at_start * self.to_first[j] * value(j))
            .collect();
        let tail = (end..self.rates.len())
            .map(|j| at_end * self.to_first[j] * value(j))
            .collect();
        (head, tail)
    }

    /// The angle variance per component the gyroscope's white noise `sigma_w` (rad/s per
    /// sample) adds: `σ_ω²·dt²·N` over the turn's `N` steps and `σ_ω²·dt²·n/3` through each
    /// end's sway correction.
    pub(super) fn gyro_angle_var(&self, sigma_w: f64) -> f64 {
        let (start, end) = self.turn();
        (sigma_w * self.dt).powi(2) * ((end - start) as f64 + (self.head + self.tail) as f64 / 3.0)
    }

    /// The gyroscope's white noise per sample: `rate_noise`, or estimated from the still ends.
    pub(super) fn rate_noise(&self, rate_noise: Option<f64>) -> f64 {
        rate_noise.unwrap_or_else(|| rate_noise_of_ends(&self.rates, self.head, self.tail))
    }
}

/// The still ends of `samples` (see [`MoveEnds`]); `None` when the stream has a gap or an end is
/// not still for at least [`EDGE_MIN_SAMPLES`] samples.
pub(super) fn move_ends(
    samples: &[UnitSample],
    a: &Mat3,
    bias: &Vec3,
    still_rate: f64,
) -> Option<MoveEnds> {
    let dt = sample_step_s(samples.iter().map(|s| s.t_s))?;
    let rates: Vec<Vec3> = samples.iter().map(|s| Vec3::from(s.gyro) - bias).collect();
    let edge = ((EDGE_MAX_S / dt).round() as usize).max(EDGE_MIN_SAMPLES);
    let head = still_run(rates.iter().copied(), still_rate, edge);
    let tail = still_run(rates.iter().rev().copied(), still_rate, edge);
    if head < EDGE_MIN_SAMPLES || tail < EDGE_MIN_SAMPLES || head + tail >= rates.len() {
        return None;
    }
    let to_first = prefix_rotations(a, &rates, dt);
    Some(MoveEnds {
        dt,
        rates,
        head,
        tail,
        to_first,
    })
}

/// The gravity part of a move (see [`motion_of`]) from its still ends.
pub(super) fn gravity_motion(
    ends: &MoveEnds,
    samples: &[UnitSample],
    accel: &Calibration,
    rate_noise: Option<f64>,
) -> Option<GyroMotion> {
    let (head_gravity, tail_gravity) =
        ends.turned_ends(|j| accel.apply(&Vec3::from(samples[j].accel)));
    let before = head_gravity.iter().sum::<Vec3>() / head_gravity.len() as f64;
    let after = tail_gravity.iter().sum::<Vec3>() / tail_gravity.len() as f64;
    let angle_var = direction_variance(&head_gravity)?
        + direction_variance(&tail_gravity)?
        + ends.gyro_angle_var(ends.rate_noise(rate_noise));
    let (start, end) = ends.turn();
    Some(GyroMotion {
        gravity_before: before,
        gravity_after: after,
        rates: ends.rates.get(start..=end)?.to_vec(),
        dt: ends.dt,
        angle_sigma: Some(angle_var.sqrt()),
    })
}

/// Every usable move as a [`GyroMotion`] (see [`motion_of`]).
pub fn motions_of(
    moves: &[Vec<UnitSample>],
    accel: &Calibration,
    a: &Mat3,
    bias: &Vec3,
    still_rate: f64,
    rate_noise: Option<f64>,
) -> Vec<GyroMotion> {
    moves
        .iter()
        .filter_map(|m| motion_of(m, accel, a, bias, still_rate, rate_noise))
        .collect()
}

/// Tilting rotation about each body axis summed over the moves, degrees: each move's rotation
/// vector (nominal scale, no bias correction: good to a few degrees, enough for advice) without
/// its part about the gravity direction at its start.
pub fn tilt_per_axis_deg(moves: &[Vec<UnitSample>]) -> [f64; 3] {
    let mut total = Vec3::zeros();
    for samples in moves {
        let (Some(dt), Some(first)) = (
            sample_step_s(samples.iter().map(|s| s.t_s)),
            samples.first(),
        ) else {
            continue;
        };
        let rates: Vec<Vec3> = samples.iter().map(|s| Vec3::from(s.gyro)).collect();
        let rotation = integrate_rotation(&Mat3::identity(), &rates, dt).scaled_axis();
        let Some(up) = Vec3::from(first.accel).try_normalize(0.0) else {
            continue;
        };
        let tilting = rotation - up * up.dot(&rotation);
        total += tilting.abs();
    }
    [total.x, total.y, total.z].map(f64::to_degrees)
}

/// Name of body `axis` (0 = X) and a turn between two of the twelve positions that tilts the
/// board about it.
pub(super) fn axis_turn_example(axis: usize) -> (char, &'static str) {
    match axis {
        0 => ('X', "from +Y up to +Z up"),
        1 => ('Y', "from +Z up to +X up"),
        _ => ('Z', "from +X up to +Y up"),
    }
}

/// The axis (0 = X) that still lacks tilting rotation and a sentence naming a turn that supplies
/// it; `None` when every axis has at least [`LACKING_FRACTION`] of the others' mean.
pub fn missing_rotation_advice(tilt_deg: &[f64; 3]) -> Option<(usize, String)> {
    let (axis, least) = tilt_deg
        .iter()
        .copied()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    let others = (tilt_deg.iter().sum::<f64>() - least) / 2.0;
    if others <= 0.0 || least >= LACKING_FRACTION * others {
        return None;
    }
    let (name, example) = axis_turn_example(axis);
    let text = format!(
        "the turns so far have tilted the board {least:.0}° about its {name} axis against \
         {others:.0}° on average about the others; the gyroscope's scale needs turns about \
         {name} as well (e.g. {example}); a turn about the vertical does not count"
    );
    Some((axis, text))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(t_s: f64, accel: Vec3, gyro: Vec3) -> UnitSample {
        UnitSample {
            t_s,
            accel: [accel.x, accel.y, accel.z],
            gyro: [gyro.x, gyro.y, gyro.z],
            mag: [0.0; 3],
            temp_c: 25.0,
        }
    }

    /// The move read through identity calibrations, no bias, still below 0.02 rad/s.
    fn uncalibrated_motion(samples: &[UnitSample]) -> Option<GyroMotion> {
        motion_of(
            samples,
            &Calibration::identity(),
            &Mat3::identity(),
            &Vec3::zeros(),
            0.02,
            None,
        )
    }

    /// A 90° turn about body X at 100 Hz between two still stretches of 0.5 s, +Z up at the
    /// start, read by a gyroscope whose X scale is `gain`.
    fn quarter_turn(gain: f64) -> Vec<UnitSample> {
        let dt = 0.01;
        let turn_s = 1.0;
        let rate = std::f64::consts::FRAC_PI_2 / turn_s;
        let mut out = Vec::new();
        let mut angle: f64 = 0.0;
        for k in 0..=200 {
            let t = k as f64 * dt;
            let w = if (0.5..1.5).contains(&t) { rate } else { 0.0 };
            // Gravity (up) in the body frame after turning by `angle` about X.
            let up = Vec3::new(0.0, angle.sin(), angle.cos()) * 9.8;
            out.push(sample(t, up, Vec3::new(w * gain, 0.0, 0.0)));
            angle += w * dt;
        }
        out
    }

    #[test]
    fn a_quarter_turn_gives_gravity_a_quarter_turn_apart_at_its_still_ends() {
        let motion = uncalibrated_motion(&quarter_turn(1.0)).expect("a usable move");
        let angle = motion
            .gravity_before
            .angle(&motion.gravity_after)
            .to_degrees();
        // The still ends are exact; only the step rate's discretisation (one sample) remains.
        assert!((angle - 90.0).abs() < 1.0, "{angle}");
        assert!((motion.dt - 0.01).abs() < 1e-12);
    }

    /// The quarter turn converted every `period` s on the sensor's clock and read every 0.01 s
    /// by the board, which skips a read that finds no new conversion and stamps each sample with
    /// its read time.
    fn quarter_turn_on_sensor_clock(period: f64) -> Vec<UnitSample> {
        let rate = std::f64::consts::FRAC_PI_2;
        let angle_at = |t: f64| rate * (t.clamp(0.5, 1.5) - 0.5);
        let mut out = Vec::new();
        let mut last_conversion = None;
        for read in 0..=200 {
            let t = read as f64 * 0.01;
            let conversion = (t / period).floor() as i64;
            if last_conversion == Some(conversion) {
                continue;
            }
            last_conversion = Some(conversion);
            let tc = conversion as f64 * period;
            let w = if (0.5..1.5).contains(&tc) { rate } else { 0.0 };
            let angle = angle_at(tc);
            let up = Vec3::new(0.0, angle.sin(), angle.cos()) * 9.8;
            out.push(sample(t, up, Vec3::new(w, 0.0, 0.0)));
        }
        out
    }

    #[test]
    fn a_sensor_slower_than_the_read_timer_gives_moves_at_its_own_period() {
        // 3 % slow: every 33rd read finds no new conversion and is left out.
        let samples = quarter_turn_on_sensor_clock(0.0103);
        assert!(
            samples.windows(2).any(|w| w[1].t_s - w[0].t_s > 0.015),
            "the stream has skipped reads"
        );
        let motion = uncalibrated_motion(&samples).expect("a usable move");
        // The sensor's period from 200 read stamps that lag their conversions by up to 10 ms.
        assert!((motion.dt / 0.0103 - 1.0).abs() < 2e-3, "{}", motion.dt);
        let turned = integrate_rotation(&Mat3::identity(), &motion.rates, motion.dt)
            .angle()
            .to_degrees();
        // Integrated on the read timer's 10 ms instead, the turn would read 3 % (2.7°) short.
        assert!((turned - 90.0).abs() < 0.5, "{turned}");
    }

    #[test]
    fn a_stream_with_a_lost_batch_is_not_used() {
        let mut samples = quarter_turn(1.0);
        samples.drain(80..100);
        let used = uncalibrated_motion(&samples);
        assert!(used.is_none());
    }

    #[test]
    fn turns_about_x_only_name_y_and_z_as_lacking_and_balanced_turns_name_none() {
        let tilt = tilt_per_axis_deg(&[quarter_turn(1.0), quarter_turn(1.0)]);
        // Two quarter turns about X, each perpendicular to the initial +Z up.
        assert!((tilt[0] - 180.0).abs() < 2.0, "{tilt:?}");
        let (axis, advice) = missing_rotation_advice(&[300.0, 280.0, 20.0]).expect("Z lacks");
        assert_eq!(axis, 2);
        assert!(advice.contains("about its Z axis"), "{advice}");
        assert!(missing_rotation_advice(&[300.0, 280.0, 200.0]).is_none());
        // A simulated session's tilts: Z at 0.46 of the others, whose σ it tripled.
        let (axis, _) = missing_rotation_advice(&[885.0, 702.0, 365.0]).expect("Z lacks");
        assert_eq!(axis, 2);
    }
}
