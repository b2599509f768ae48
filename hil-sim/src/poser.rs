//! Schedules a person following the calibration prompts would produce.
//!
//! - `twelve`: the twelve positions of seed 003 (Chen et al. 2012, §2.2): the six faces up, then
//!   the XY, YZ and XZ planes at 45° and 135° to the horizontal; each held for a few seconds.
//! - `tumble`: a slow turn through all directions for the magnetometer; the field direction in
//!   the body frame follows a spiral from pole to pole (Rakhmanov, Saff & Zhou 1994 spacing), so
//!   it covers the sphere.
//! - `sweep`: the twelve positions repeated while the temperature goes up and down.
//!
//! People are imprecise: every hold is placed a few degrees off its nominal attitude and at a
//! random heading, and may carry hand tremor (a slow sway near 0.3 Hz of a few tenths of a degree
//! and physiological tremor near 10 Hz of a few thousandths of a degree). Everything is drawn
//! from the seed, so a schedule is reproducible.

use std::f64::consts::PI;

use nalgebra::{Unit, UnitQuaternion, Vector3};
use rand::Rng;
use rand_chacha::rand_core::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::error::{require_non_negative, require_positive, SimError};
use crate::world::{
    EarthField, TemperatureProfile, Trajectory, TrajectoryBuilder, Tremor, TremorComponent,
};

/// Which schedule to produce.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ScheduleKind {
    /// Twelve static positions.
    Twelve,
    /// Slow tumble through all directions.
    Tumble,
    /// Twelve positions repeated over a temperature cycle.
    Sweep,
}

impl std::str::FromStr for ScheduleKind {
    type Err = SimError;

    fn from_str(s: &str) -> Result<Self, SimError> {
        match s {
            "twelve" => Ok(ScheduleKind::Twelve),
            "tumble" => Ok(ScheduleKind::Tumble),
            "sweep" => Ok(ScheduleKind::Sweep),
            other => Err(SimError::UnknownSchedule(other.to_string())),
        }
    }
}

impl ScheduleKind {
    /// Name as used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            ScheduleKind::Twelve => "twelve",
            ScheduleKind::Tumble => "tumble",
            ScheduleKind::Sweep => "sweep",
        }
    }
}

/// How the person moves.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoserOptions {
    /// Length of each static hold, s.
    pub hold_s: f64,
    /// Whether holds carry hand tremor.
    pub tremor: bool,
    /// Largest deviation of a hold from its nominal attitude, degrees.
    pub placement_error_deg: f64,
    /// Largest change of heading between holds, degrees (either way).
    pub heading_spread_deg: f64,
    /// Peak turning rate between holds, °/s.
    pub turn_peak_rate_dps: f64,
    /// Peak turning rate while tumbling, °/s.
    pub tumble_peak_rate_dps: f64,
    /// Number of spiral waypoints of the tumble.
    pub tumble_waypoints: usize,
    /// Temperature of the twelve-position and tumble schedules, °C.
    pub ambient_c: f64,
    /// How many times the sweep repeats the twelve positions.
    pub sweep_repeats: usize,
    /// Number of full temperature cycles of the sweep.
    pub sweep_cycles: usize,
    /// Lowest temperature of the sweep, °C.
    pub sweep_low_c: f64,
    /// Highest temperature of the sweep, °C.
    pub sweep_high_c: f64,
}

impl Default for PoserOptions {
    fn default() -> Self {
        Self {
            hold_s: 4.0,
            tremor: true,
            placement_error_deg: 3.0,
            heading_spread_deg: 30.0,
            turn_peak_rate_dps: 150.0,
            tumble_peak_rate_dps: 60.0,
            tumble_waypoints: 48,
            ambient_c: 25.0,
            sweep_repeats: 6,
            sweep_cycles: 2,
            sweep_low_c: 5.0,
            sweep_high_c: 45.0,
        }
    }
}

impl PoserOptions {
    fn validate(&self) -> Result<(), SimError> {
        require_positive("hold duration (s)", self.hold_s)?;
        require_non_negative("placement error (degrees)", self.placement_error_deg)?;
        require_non_negative("heading spread (degrees)", self.heading_spread_deg)?;
        require_positive("turn peak rate (°/s)", self.turn_peak_rate_dps)?;
        require_positive("tumble peak rate (°/s)", self.tumble_peak_rate_dps)?;
        require_positive("tumble waypoints", self.tumble_waypoints as f64)?;
        require_positive("sweep repeats", self.sweep_repeats as f64)?;
        require_positive("sweep cycles", self.sweep_cycles as f64)?;
        crate::error::require_finite("ambient temperature (°C)", self.ambient_c)?;
        crate::error::require_finite("sweep low temperature (°C)", self.sweep_low_c)?;
        crate::error::require_finite("sweep high temperature (°C)", self.sweep_high_c)?;
        Ok(())
    }
}

/// A motion and the temperature it happens at.
#[derive(Debug, Clone, PartialEq)]
pub struct Schedule {
    /// Which schedule this is.
    pub kind: ScheduleKind,
    /// The board's motion.
    pub trajectory: Trajectory,
    /// Die temperature over time.
    pub temperature: TemperatureProfile,
}

/// The body-frame direction that points up in each of the twelve positions of seed 003: the six
/// faces (+Z, −Z, +X, −X, +Y, −Y up), then the XY, YZ and XZ planes at 45° and 135°.
pub fn twelve_position_up_directions() -> [Vector3<f64>; 12] {
    let h = std::f64::consts::FRAC_1_SQRT_2;
    [
        Vector3::new(0.0, 0.0, 1.0),
        Vector3::new(0.0, 0.0, -1.0),
        Vector3::new(1.0, 0.0, 0.0),
        Vector3::new(-1.0, 0.0, 0.0),
        Vector3::new(0.0, 1.0, 0.0),
        Vector3::new(0.0, -1.0, 0.0),
        Vector3::new(h, h, 0.0),
        Vector3::new(-h, h, 0.0),
        Vector3::new(0.0, h, h),
        Vector3::new(0.0, -h, h),
        Vector3::new(h, 0.0, h),
        Vector3::new(-h, 0.0, h),
    ]
}

/// Orientation (body to world) that puts body direction `up` along world +Z, then turns it by
/// `heading` about the vertical.
pub fn orientation_with_up(up: &Vector3<f64>, heading_rad: f64) -> UnitQuaternion<f64> {
    let tilt = UnitQuaternion::rotation_between(up, &Vector3::z()).unwrap_or_else(|| {
        // `up` is straight down: any half-turn about a horizontal axis brings it up.
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), PI)
    });
    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), heading_rad) * tilt
}

/// A random unit vector, uniform on the sphere.
fn random_unit(rng: &mut ChaCha8Rng) -> Vector3<f64> {
    let z: f64 = rng.gen_range(-1.0..=1.0);
    let phi: f64 = rng.gen_range(0.0..2.0 * PI);
    let r = (1.0 - z * z).max(0.0).sqrt();
    Vector3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Hand tremor for one hold: one slow sway and one physiological tremor component.
fn hand_tremor(rng: &mut ChaCha8Rng) -> Tremor {
    let mut component = |amplitude_deg: (f64, f64), frequency_hz: (f64, f64)| TremorComponent {
        axis: random_unit(rng).into(),
        amplitude_rad: rng
            .gen_range(amplitude_deg.0..=amplitude_deg.1)
            .to_radians(),
        frequency_hz: rng.gen_range(frequency_hz.0..=frequency_hz.1),
        phase_rad: rng.gen_range(0.0..2.0 * PI),
    };
    let sway = component((0.1, 0.3), (0.2, 0.5));
    let physiological = component((0.002, 0.006), (8.0, 12.0));
    Tremor {
        components: vec![sway, physiological],
        edge_ramp_s: 0.3,
    }
}

/// Minimum-jerk turn length for a peak rate: the peak of `ṡ` is 1.875 times the mean.
fn turn_duration_s(from: &UnitQuaternion<f64>, to: &UnitQuaternion<f64>, peak_dps: f64) -> f64 {
    let angle = from.angle_to(to);
    (1.875 * angle / peak_dps.to_radians()).max(0.6)
}

/// Append the twelve positions (turning to each, then holding) to `builder`.
fn twelve_positions(
    mut builder: TrajectoryBuilder,
    options: &PoserOptions,
    rng: &mut ChaCha8Rng,
    first: bool,
) -> Result<TrajectoryBuilder, SimError> {
    let mut heading: f64 = rng.gen_range(-PI..PI);
    for (i, up) in twelve_position_up_directions().iter().enumerate() {
        heading += rng.gen_range(-1.0..=1.0) * options.heading_spread_deg.to_radians();
        let error =
            random_unit(rng) * rng.gen_range(0.0..=1.0) * options.placement_error_deg.to_radians();
        let target = UnitQuaternion::from_scaled_axis(error) * orientation_with_up(up, heading);
        if !(first && i == 0) {
            let duration = turn_duration_s(&builder.current(), &target, options.turn_peak_rate_dps);
            builder = builder.turn_to(target, duration)?;
        } else {
            builder = TrajectoryBuilder::new(target);
        }
        let tremor = options.tremor.then(|| hand_tremor(rng));
        builder = builder.hold(options.hold_s, tremor)?;
    }
    Ok(builder)
}

/// The eight corner directions `(±1, ±1, ±1)/√3` in a Gray-code order: each differs from the
/// one before in one sign, a 70.5° turn.
pub fn corner_up_directions() -> [Vector3<f64>; 8] {
    let s = 1.0 / 3.0_f64.sqrt();
    [
        (1.0, 1.0, 1.0),
        (1.0, 1.0, -1.0),
        (1.0, -1.0, -1.0),
        (1.0, -1.0, 1.0),
        (-1.0, -1.0, 1.0),
        (-1.0, -1.0, -1.0),
        (-1.0, 1.0, -1.0),
        (-1.0, 1.0, 1.0),
    ]
    .map(|(x, y, z)| Vector3::new(x, y, z) * s)
}

/// A position as a person holds it.
#[derive(Debug, Clone)]
pub struct PlacedHold {
    /// Orientation, body to world (placement error and heading included).
    pub orientation: UnitQuaternion<f64>,
    /// Hand tremor, if the person has any.
    pub tremor: Option<Tremor>,
}

/// The eight corner positions as a person holds them,
/// placed and headed like the twelve ([`PoserOptions`]), drawn from `seed` on a stream of its
/// own so the twelve positions of a seed stay as they were.
pub fn corner_holds(options: &PoserOptions, seed: u64) -> Result<Vec<PlacedHold>, SimError> {
    options.validate()?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(3);
    let mut heading: f64 = rng.gen_range(-PI..PI);
    Ok(corner_up_directions()
        .iter()
        .map(|up| {
            heading += rng.gen_range(-1.0..=1.0) * options.heading_spread_deg.to_radians();
            let error = random_unit(&mut rng)
                * rng.gen_range(0.0..=1.0)
                * options.placement_error_deg.to_radians();
            PlacedHold {
                orientation: UnitQuaternion::from_scaled_axis(error)
                    * orientation_with_up(up, heading),
                tremor: options.tremor.then(|| hand_tremor(&mut rng)),
            }
        })
        .collect())
}

/// Waypoints whose body-frame field direction follows a pole-to-pole spiral.
fn tumble_waypoints(count: usize, field: &EarthField) -> Vec<UnitQuaternion<f64>> {
    let field_world = field.world_vector_ut();
    let field_dir = if field_world.norm() > 0.0 {
        field_world.normalize()
    } else {
        Vector3::new(0.5, 0.0, -(3.0_f64.sqrt()) / 2.0)
    };
    // W maps body +Z onto the field direction.
    let w = UnitQuaternion::rotation_between(&Vector3::z(), &field_dir)
        .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), PI));
    let axis = Unit::new_normalize(field_dir);
    let n = count.max(2);
    let mut azimuth: f64 = 0.0;
    (0..n)
        .map(|k| {
            // Rakhmanov–Saff–Zhou spiral, kept slightly off the poles.
            let h = -0.98 + 1.96 * k as f64 / (n - 1) as f64;
            let polar = h.acos();
            if k > 0 {
                azimuth += 3.6 / ((n as f64) * (1.0 - h * h)).sqrt();
            }
            // S maps +Z to the wanted body direction u; then R = W·Sᵀ gives Rᵀ·ĥ = u.
            let s = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), azimuth)
                * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), polar);
            // A slow twist about the field varies gravity's direction too.
            let twist = UnitQuaternion::from_axis_angle(&axis, 0.3 * k as f64);
            twist * w * s.inverse()
        })
        .collect()
}

/// A body-frame field direction counts as shown when one within this angle was, degrees: about
/// a quarter of the ≈45° spacing of the 26 direction regions a host's coverage guidance names,
/// so that a region only grazed by a turn still gets its own visit.
pub const SEEN_ANGLE_DEG: f64 = 12.0;

/// The 26 body-frame directions of a cube's faces, edges and corners (unit).
fn cube_directions() -> Vec<Vector3<f64>> {
    let mut out = Vec::with_capacity(26);
    for x in [-1.0, 0.0, 1.0] {
        for y in [-1.0, 0.0, 1.0] {
            for z in [-1.0, 0.0, 1.0] {
                if let Some(d) = Vector3::new(x, y, z).try_normalize(0.0) {
                    out.push(d);
                }
            }
        }
    }
    out
}

/// The orientations a person who follows "still missing" guidance turns through, starting at
/// `from` (body to world): for each of the 26 cube directions more than [`SEEN_ANGLE_DEG`] from
/// every body-frame field direction in `seen`, the smallest turn that shows the field
/// (`field_world`, unit) along it, each time the nearest one next; then `waypoints` (the whole
/// spiral, in case the host wants more).
pub fn fill_in_tumble(
    waypoints: &[UnitQuaternion<f64>],
    seen: &[Vector3<f64>],
    field_world: &Vector3<f64>,
    from: &UnitQuaternion<f64>,
) -> Vec<UnitQuaternion<f64>> {
    let cos_seen = SEEN_ANGLE_DEG.to_radians().cos();
    let mut missing: Vec<Vector3<f64>> = cube_directions()
        .into_iter()
        .filter(|d| seen.iter().all(|s| s.dot(d) < cos_seen))
        .collect();
    let mut plan = Vec::with_capacity(missing.len() + waypoints.len());
    let mut here = *from;
    while !missing.is_empty() {
        let shown = here.inverse() * field_world;
        let nearest = missing
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.dot(&shown).total_cmp(&b.1.dot(&shown)))
            .map_or(0, |(i, _)| i);
        let wanted = missing.swap_remove(nearest);
        // q = here·r with r turning `wanted` onto `shown` gives q⁻¹·field = wanted.
        let turn = UnitQuaternion::rotation_between(&wanted, &shown).unwrap_or_else(|| {
            // Opposite directions: half a turn about any axis perpendicular to them.
            let axis = wanted
                .cross(&Vector3::x())
                .try_normalize(1e-6)
                .unwrap_or_else(Vector3::y);
            UnitQuaternion::from_axis_angle(&Unit::new_normalize(axis), PI)
        });
        here *= turn;
        plan.push(here);
    }
    plan.extend_from_slice(waypoints);
    plan
}

/// Build the schedule `kind` with `seed`. `field` orients the tumble so that the field sweeps the
/// body sphere.
pub fn build_schedule(
    kind: ScheduleKind,
    options: &PoserOptions,
    field: &EarthField,
    seed: u64,
) -> Result<Schedule, SimError> {
    options.validate()?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(2);
    let ambient = TemperatureProfile::Constant {
        temp_c: options.ambient_c,
    };
    match kind {
        ScheduleKind::Twelve => {
            let builder = twelve_positions(
                TrajectoryBuilder::new(UnitQuaternion::identity()),
                options,
                &mut rng,
                true,
            )?;
            Ok(Schedule {
                kind,
                trajectory: builder.build()?,
                temperature: ambient,
            })
        }
        ScheduleKind::Tumble => {
            let waypoints = tumble_waypoints(options.tumble_waypoints, field);
            let start = waypoints
                .first()
                .copied()
                .unwrap_or_else(UnitQuaternion::identity);
            let still = 2.0;
            let mut builder = TrajectoryBuilder::new(start).hold(still, None)?;
            for target in waypoints.iter().skip(1) {
                let duration =
                    turn_duration_s(&builder.current(), target, options.tumble_peak_rate_dps);
                builder = builder.turn_to(*target, duration)?;
            }
            builder = builder.hold(still, None)?;
            Ok(Schedule {
                kind,
                trajectory: builder.build()?,
                temperature: ambient,
            })
        }
        ScheduleKind::Sweep => {
            let mut builder = TrajectoryBuilder::new(UnitQuaternion::identity());
            for repeat in 0..options.sweep_repeats {
                builder = twelve_positions(builder, options, &mut rng, repeat == 0)?;
            }
            let trajectory = builder.build()?;
            let period_s = trajectory.duration_s() / options.sweep_cycles as f64;
            Ok(Schedule {
                kind,
                trajectory,
                temperature: TemperatureProfile::Sweep {
                    low_c: options.sweep_low_c,
                    high_c: options.sweep_high_c,
                    period_s,
                },
            })
        }
    }
}

#[cfg(test)]
mod fill_in_tests {
    use super::*;

    #[test]
    fn every_missing_direction_is_shown_by_one_turn_of_the_plan() {
        let field = Vector3::new(0.5, 0.0, -(3.0_f64.sqrt()) / 2.0);
        // Only +Z and its neighbourhood seen so far.
        let seen = vec![Vector3::z()];
        let plan = fill_in_tumble(&[], &seen, &field, &UnitQuaternion::identity());
        // 26 cube directions, of which +Z itself (0°) is seen and none other within 12°.
        assert_eq!(plan.len(), 25);
        for d in cube_directions().iter().filter(|d| d.z < 0.99) {
            let shown = plan
                .iter()
                .any(|q| (q.inverse() * field).dot(d) > 1.0 - 1e-9);
            assert!(shown, "{d:?} not shown");
        }
    }
}
