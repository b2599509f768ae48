//! Plausibility checks on a recording before it is fitted: the declared units against the
//! magnitudes the data shows at rest, a stated field magnitude against the data, holds that
//! saturate or move, and pose sets that cannot determine a calibration.
//!
//! The unit checks use physics that holds whatever the sensor: at rest an accelerometer reads
//! 1 g; the Earth's field is 22–67 µT everywhere on the surface (World Magnetic Model); and a
//! gyroscope integrated between two holds turns at least as far as the gravity direction does.
//! The field radius comes from an algebraic sphere fit `|m|² = 2·c·m + d` (seed 004's
//! ellipsoid least squares with equal axes). Refusals are sentences naming cause and fix;
//! findings that only cast doubt are returned as warnings.

use nalgebra::{Matrix4, Vector4};

use crate::fit::{validate, Vec3};
use crate::recording::{AccelUnit, GyroUnit, MagUnit, Recording, Sensor, STANDARD_GRAVITY};
use crate::still::StillReport;

/// Rest magnitudes between 0.5 g and 2 g are taken as 1 g: wide enough for any uncalibrated
/// scale and offset, far narrower than the factor 9.8 between g and m/s².
const G_BAND: (f64, f64) = (0.5, 2.0);
/// A plausible field radius in µT: the Earth's 22–67 µT widened by a factor of about two for
/// indoor disturbance and uncalibrated sensitivity.
const UT_BAND: (f64, f64) = (10.0, 150.0);
/// Largest zero-rate offset in common MEMS gyroscope datasheets (MPU-6050: ±20 °/s), in rad/s.
const MAX_GYRO_OFFSET_RADS: f64 = 0.35;
/// A hold is moving when its variance is this many times that of the median hold. For holds
/// of n ≥ 30 samples the variance averaged over three axes scatters by √(2/(3(n−1))) ≤ 15 %
/// while still, so a factor of 10 is never reached by chance and leaves room for tremor.
pub const MOTION_RATIO: f64 = 10.0;
/// A hold is saturated on an axis when at least this fraction of its samples sit exactly at the
/// recording's extreme value on that axis (noise spreads a real hold over several values).
/// The premise is tested per axis: when the median hold repeats its previous sample in at least
/// `SATURATED_FRACTION²` of its pairs, as independent draws with that fraction on one value
/// would, the readings are quantised coarser than their noise and a pile on one value is no
/// sign of a rail (a logger writing g to two decimals).
pub const SATURATED_FRACTION: f64 = 0.5;
/// Distinct gravity directions an accelerometer fit needs: the six faces of the board.
pub const MIN_DIRECTIONS: usize = 6;
/// Fewest magnetometer samples accepted: the general ellipsoid has 9 unknowns.
pub const MIN_MAG_SAMPLES: usize = 12;

/// Largest distance of the samples from zero, in sphere radii, of a magnetometer that was
/// turned. Turned, the samples lie on a sphere of the field's radius about the hard-iron
/// offset, which a working sensor keeps within its range: at most about 16 fields for common
/// parts (±8 gauss against a 0.5 gauss field), so their distance from zero is at most about 17
/// radii. Not turned, the fitted sphere has the radius of the noise, hundreds of times smaller.
const NOT_TURNED_RATIO: f64 = 20.0;
/// Poses or samples whose directions all lie within this angle of a plane are refused.
pub const MIN_SPREAD_DEG: f64 = validate::MIN_SPREAD_DEG;
/// A stated field further than this fraction from the data's field draws a warning: an
/// uncalibrated magnetometer's sensitivity is within about ±10 %.
pub const FIELD_WARN_FRACTION: f64 = 0.2;
/// A stated field more than this factor from the data's field is refused: no disturbance
/// doubles or halves the field in every orientation, but a wrong unit or a typo does.
pub const FIELD_REFUSE_FACTOR: f64 = 2.0;

/// Why a recording is refused before fitting. Each message names the cause and the fix.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InputError {
    /// The accelerometer's magnitude at rest does not match its declared unit.
    #[error("the accelerometer reads about {magnitude:.3} at rest, which {looks_like}, but it is read as {declared} (--accel-unit, else a unit written in the header, else mps2); pass --accel-unit {fix}")]
    AccelUnit {
        /// Median magnitude of all samples, in the file's numbers.
        magnitude: f64,
        /// What that magnitude looks like.
        looks_like: &'static str,
        /// Declared unit flag.
        declared: &'static str,
        /// Unit flag to pass instead.
        fix: &'static str,
    },
    /// The gyroscope's readings do not match its declared unit.
    #[error("{evidence}, so the gyroscope data is not in {declared}; {fix}")]
    GyroUnit {
        /// What was measured.
        evidence: String,
        /// Declared unit.
        declared: &'static str,
        /// What to pass instead.
        fix: String,
    },
    /// The magnetometer's field magnitude does not match its declared unit.
    #[error("the magnetometer's field in the data is about {radius:.3} ({how}), which {looks_like}, but it is read as {declared} (--mag-unit, else a unit written in the header, else ut); pass --mag-unit {fix}")]
    MagUnit {
        /// Field magnitude in the file's numbers.
        radius: f64,
        /// How it was measured.
        how: &'static str,
        /// What that magnitude looks like.
        looks_like: &'static str,
        /// Declared unit flag.
        declared: &'static str,
        /// Unit flag to pass instead.
        fix: &'static str,
    },
    /// `--field-ut` is far from the field the data shows.
    #[error("the magnetometer data shows a field of {data_ut:.1} µT but --field-ut is {field_ut}, a factor {factor:.2} apart; no local disturbance explains that (the Earth's field is 22–67 µT), so check --field-ut (the local field, e.g. from a geomagnetic model) and --mag-unit")]
    FieldContradicts {
        /// Field radius of the data in µT.
        data_ut: f64,
        /// Stated field in µT.
        field_ut: f64,
        /// Larger over smaller.
        factor: f64,
    },
    /// No still interval was found, and the time column advances too slowly to show one.
    #[error(
        "no still interval in `{path}`: its time column advances {step_s:.4} s per row, so no \
             hold of a few seconds can show in it; the time is most likely in milliseconds or \
             microseconds: write it in seconds, or declare its unit (with --columns, map the \
             time column as `t_ms=…`, `t_us=…` or `t_ns=…`; a CSV read as it is can map \
             `t_ms=t_s` and each sensor column to itself; IMU-TK files take --imutk-time-unit)"
    )]
    NoStillSlowClock {
        /// File concerned.
        path: String,
        /// Median step of the time column, seconds.
        step_s: f64,
    },
    /// No still interval was found.
    #[error("no still interval in `{path}` ({duration:.1} s long): the board was never still for {shortest_s} s ({option}); hold it still for 2–3 s in each orientation, or lower {option}")]
    NoStill {
        /// File concerned.
        path: String,
        /// Length of the recording in seconds.
        duration: f64,
        /// Shortest stillness that could have been found: the longer of the window and the
        /// shortest hold kept.
        shortest_s: f64,
        /// The option that sets it (`--min-hold`, or `--window`, which the stillness test
        /// needs still as a whole).
        option: &'static str,
    },
    /// The stillness test's window is longer than the recording.
    #[error("no still interval in `{path}`: the stillness test's window (--window {window_s} s) is longer than the whole recording ({duration:.1} s), so no window of it can be judged; use a window of about 0.5 s (the default)")]
    WindowTooLong {
        /// File concerned.
        path: String,
        /// The window, seconds.
        window_s: f64,
        /// Length of the recording in seconds.
        duration: f64,
    },
    /// Every hold was excluded for saturation or motion.
    #[error("every hold of `{path}` was left out ({reasons}); record the holds again with the board still and within the sensor's range")]
    NoUsableHold {
        /// File concerned.
        path: String,
        /// Why, summarised.
        reasons: String,
    },
    /// Too few distinct gravity directions among the holds.
    #[error("the accelerometer has only {} among {}{repeats}; a fit needs at least {needed} (the six faces of the board, each up once), so add holds with other faces up", crate::words::counted(*distinct, "distinct gravity direction"), crate::words::counted(*holds, "hold"))]
    TooFewDirections {
        /// Holds with accelerometer data.
        holds: usize,
        /// Distinct directions among them.
        distinct: usize,
        /// Directions needed.
        needed: usize,
        /// Note on repeated directions (may be empty).
        repeats: String,
    },
    /// The poses or samples do not span three dimensions.
    #[error("the {sensor} data cannot determine a calibration: {detail}")]
    Degenerate {
        /// Sensor concerned.
        sensor: Sensor,
        /// What is missing and what to add.
        detail: String,
    },
    /// Every axis reads the same number in every row: the sensor is not measuring.
    #[error("the {sensor} reads ({}, {}, {}) in every one of its {count} rows, so it is not measuring (stuck, asleep, unpowered, absent from the log, or its columns filled with a constant) or its readings are rounded far coarser than its noise; check the sensor, the column mapping and the logged resolution, and record again", value[0], value[1], value[2])]
    Stuck {
        /// Sensor concerned.
        sensor: Sensor,
        /// The reading it repeats, in the file's unit.
        value: [f64; 3],
        /// Rows of the sensor's data.
        count: usize,
    },
    /// Too few magnetometer samples.
    #[error("only {count} magnetometer samples; an ellipsoid fit needs at least {needed}, so record longer while turning the board in all directions")]
    TooFewMagSamples {
        /// Samples present.
        count: usize,
        /// Samples needed.
        needed: usize,
    },
}

/// Fewest rows over which an axis that never changes is taken as stuck. A working sensor's
/// noise moves its reading by at least one count now and then: even with noise of a quarter
/// count, 95 % of readings fall on one value, and 100 in a row do so with probability
/// 0.95⁹⁹ < 1 %. Shorter series are too few to tell.
pub const MIN_ROWS_FOR_STUCK: usize = 100;

/// Refuses a sensor whose three axes each read exactly one number in at least
/// [`MIN_ROWS_FOR_STUCK`] rows: its calibration would be fitted to a constant (a gyroscope's
/// bias with zero noise, RMS 0) and look perfect. One or two such axes are a warning only: a
/// reading logged coarser than its noise (a gyroscope in whole °/s at rest) keeps one value on
/// an axis whose offset is near a whole step, and cannot be told from a dead axis. Stops at the
/// first row that differs, so a working sensor costs a few comparisons.
pub fn check_not_stuck(samples: &[Vec3], sensor: Sensor) -> Result<Option<String>, InputError> {
    let Some(first) = samples.first() else {
        return Ok(None);
    };
    if samples.len() < MIN_ROWS_FOR_STUCK {
        return Ok(None);
    }
    // Bitwise equality: a column of NaN is as stuck as one of zeros.
    let constant: Vec<usize> = (0..3)
        .filter(|&k| samples.iter().all(|s| s[k].to_bits() == first[k].to_bits()))
        .collect();
    let columns = sensor.columns();
    match constant.len() {
        0 => Ok(None),
        3 => Err(InputError::Stuck {
            sensor,
            value: [first.x, first.y, first.z],
            count: samples.len(),
        }),
        _ => {
            let named: Vec<String> = constant
                .iter()
                .map(|&k| format!("{} ({})", columns[k], first[k]))
                .collect();
            Ok(Some(format!(
                "the {sensor} column{} {} never change{} over {} rows: either the readings are \
                 rounded coarser than the sensor's noise or that axis is dead; its calibration \
                 on that axis rests on the rounding",
                if named.len() > 1 { "s" } else { "" },
                named.join(" and "),
                if named.len() > 1 { "" } else { "s" },
                samples.len()
            )))
        }
    }
}

/// Median of a list (the upper middle value; 0 when empty). Selection, not a sort: the
/// accelerometer's unit check takes it over every sample of a long recording.
fn median(mut values: Vec<f64>) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let middle = values.len() / 2;
    *values.select_nth_unstable_by(middle, f64::total_cmp).1
}

fn in_band(value: f64, band: (f64, f64)) -> bool {
    value >= band.0 && value <= band.1
}

/// Slowest row rate, Hz, at which a recording can show a hold: a hand holds a pose for 2–3 s,
/// and the stillness test needs several samples in a window of half a second.
pub const SLOWEST_PLAUSIBLE_RATE_HZ: f64 = 1.0;

/// Warnings about a recording's time stamps (`time` in seconds, as read from the file):
/// - rows that repeat the time stamp of the row before: a logger that writes a row per sensor
///   per tick, or a clock coarser than the sampling. The rate is then taken from the steps
///   between distinct stamps ([`crate::recording::median_rate`]), which may not be the rate of
///   the rows, and the still windows, set in seconds, hold a different number of rows;
/// - a rate below [`SLOWEST_PLAUSIBLE_RATE_HZ`]: most often milliseconds in a `t_s` column, which
///   makes every hold a thousand times longer than it was and every move too slow to see (the
///   still detection then finds nothing and says so, without this cause);
/// - gaps longer than [`crate::still::BREAK_S`], where the still detection breaks the recording.
pub fn time_stamp_warnings(time: &[f64]) -> Vec<String> {
    let mut warnings = Vec::new();
    let mut repeats = time.windows(2).filter(|w| w[1] == w[0]);
    if let Some(first) = repeats.next() {
        let count = 1 + repeats.count();
        warnings.push(format!(
            "{count} of {} rows repeat the time stamp of the row before (the first at t = {} \
             s): the rate is taken from the steps between distinct time stamps; if the logger \
             writes a row per sensor per tick, merge them into one row per sample, and if its \
             clock is coarser than its rate, record the time with more digits",
            time.len(),
            first[0]
        ));
    }
    // Gaps the still detector breaks the recording at: a logger's dropout, or pieces recorded
    // apart and joined. Holds never span one, so the user should know they are there.
    let break_s = crate::still::BREAK_S;
    let gaps: Vec<(f64, f64)> = time
        .windows(2)
        .filter(|w| w[1] - w[0] > break_s)
        .map(|w| (w[0], w[1] - w[0]))
        .collect();
    if let Some(&(at, longest)) = gaps.iter().max_by(|a, b| a.1.total_cmp(&b.1)) {
        warnings.push(format!(
            "{} in the time stamps longer than {break_s} s (the longest {longest:.3} s, after \
             t = {at} s): the recording is read as separate pieces and no hold spans a gap; if \
             the logger dropped data there, the pieces may not belong together",
            crate::words::counted(gaps.len(), "gap")
        ));
    }
    if let Some(rate) = crate::recording::median_rate(time) {
        if rate < SLOWEST_PLAUSIBLE_RATE_HZ {
            warnings.push(format!(
                "the time column advances {:.4} s per row ({rate:.4} Hz), slower than any \
                 inertial recording that shows holds of a few seconds; if it holds milliseconds, \
                 write it in seconds, or read the file as it is with --columns mapping `t_ms=t_s` \
                 and each sensor column to itself (`t_us`, `t_ns` for finer units)",
                1.0 / rate
            ));
        }
    }
    warnings
}

/// Check the declared accelerometer unit against the median magnitude of all samples, which is
/// 1 g at rest and stays near it during hand motion (the median ignores brief accelerations).
pub fn check_accel_unit(samples: &[Vec3], declared: AccelUnit) -> Result<(), InputError> {
    if samples.is_empty() || declared == AccelUnit::Counts {
        return Ok(());
    }
    let magnitude = median(samples.iter().map(|v| v.norm()).collect());
    let mps2_band = (G_BAND.0 * STANDARD_GRAVITY, G_BAND.1 * STANDARD_GRAVITY);
    let (fits, declared_flag) = match declared {
        AccelUnit::Mps2 => (in_band(magnitude, mps2_band), "mps2"),
        _ => (in_band(magnitude, G_BAND), "g"),
    };
    if fits {
        return Ok(());
    }
    let (looks_like, fix) = if in_band(magnitude, G_BAND) {
        ("looks like g", "g")
    } else if in_band(magnitude, mps2_band) {
        ("looks like m/s²", "mps2")
    } else if magnitude > mps2_band.1 {
        (
            "is more than 2 g in any unit, so it looks like raw counts",
            "counts",
        )
    } else {
        (
            "is below 1 g in any unit, so it looks like raw counts of a coarse sensor",
            "counts",
        )
    };
    Err(InputError::AccelUnit {
        magnitude,
        looks_like,
        declared: declared_flag,
        fix,
    })
}

/// Check the declared gyroscope unit. Between consecutive holds, the angle the gyroscope turns
/// (its path length `Σ|ω − bias|·dt`, bias from the earlier hold) is at least the angle
/// between the two gravity directions, and within a small factor of it for deliberate moves;
/// a unit wrong by 180/π shows as a ratio of 57 or 1/57. Without such moves, only a rest level
/// above the largest MEMS zero-rate offset is evidence (a small one fits either unit, so that
/// direction cannot be told and is not claimed). Raw counts have no scale to check.
pub fn check_gyro_unit(recording: &Recording, still: &StillReport) -> Result<(), InputError> {
    let (Some(gyro), Some(to_rads)) = (&recording.gyro, recording.units.gyro.to_si()) else {
        return Ok(());
    };
    let declared = recording.units.gyro;
    let declared_name = recording.units.gyro.symbol();
    if let Some((ratio, moves)) = turn_ratio(recording, still, gyro, to_rads) {
        let evidence = format!(
            "between holds the gyroscope turns {ratio:.3} times as far as the gravity direction does (median of {moves} moves; in the right unit it is between 1 and a few)"
        );
        let fix = match declared {
            GyroUnit::Rads if (20.0..400.0).contains(&ratio) => {
                Some("a factor near 57 (180/π) means °/s: pass --gyro-unit dps")
            }
            GyroUnit::Dps if (0.0025..0.05).contains(&ratio) => {
                Some("a factor near 1/57 (π/180) means rad/s: pass --gyro-unit rads")
            }
            _ if ratio > 10.0 => {
                Some("the data looks like raw counts: pass --gyro-unit counts (and --gyro-scale if the rad/s per count is known)")
            }
            _ if ratio < 0.5 => Some(
                "check --gyro-unit and that the gyroscope and accelerometer columns were recorded together",
            ),
            _ => None,
        };
        // Times from --rate scale every turn angle by the rate's error: name it first.
        let rate_given = !recording.time_from_file && !recording.time_is_index;
        return match fix {
            Some(fix) => Err(InputError::GyroUnit {
                evidence,
                declared: declared_name,
                fix: if rate_given {
                    format!(
                        "the times come from --rate, and a rate off by that factor turns the \
                         gyroscope as far: check --rate first; else {fix}"
                    )
                } else {
                    fix.to_string()
                },
            }),
            None => Ok(()),
        };
    }
    let rest = median(
        still
            .intervals
            .iter()
            .filter_map(|i| i.gyro.as_ref().map(|p| p.mean.norm() * to_rads))
            .collect(),
    );
    if rest > MAX_GYRO_OFFSET_RADS {
        let fix = match declared {
            GyroUnit::Rads => "pass --gyro-unit dps or --gyro-unit counts",
            _ => "pass --gyro-unit counts",
        };
        return Err(InputError::GyroUnit {
            evidence: format!(
                "at rest the gyroscope reads {:.3} rad/s in the declared unit, more than the largest zero-rate offset of MEMS gyroscopes (20 °/s = 0.35 rad/s)",
                rest
            ),
            declared: declared_name,
            fix: fix.to_string(),
        });
    }
    Ok(())
}

/// Median over moves of (gyroscope path length) / (angle between gravity directions), for moves
/// of at least 20° with no gap in the time stamps; `None` without two such moves.
fn turn_ratio(
    recording: &Recording,
    still: &StillReport,
    gyro: &[Vec3],
    to_rads: f64,
) -> Option<(f64, usize)> {
    if recording.time_is_index {
        return None;
    }
    let time = &recording.time;
    let steps: Vec<f64> = time.windows(2).map(|w| w[1] - w[0]).collect();
    let typical_step = median(steps.iter().copied().filter(|d| *d > 0.0).collect());
    if typical_step <= 0.0 {
        return None;
    }
    let centre = accel_centre(recording, still);
    let mut ratios = Vec::new();
    for pair in still.intervals.windows(2) {
        let [before, after] = pair else { continue };
        let (Some(a0), Some(a1), Some(g0)) = (&before.accel, &after.accel, &before.gyro) else {
            continue;
        };
        let (Some(d0), Some(d1)) = (
            (a0.mean - centre).try_normalize(1e-12),
            (a1.mean - centre).try_normalize(1e-12),
        ) else {
            continue;
        };
        let gravity_turn = d0.dot(&d1).clamp(-1.0, 1.0).acos();
        if gravity_turn < 20f64.to_radians() || after.start < before.end {
            continue;
        }
        let rows = before.end.max(1)..after.start.min(gyro.len());
        let gap = rows
            .clone()
            .any(|i| steps.get(i - 1).is_none_or(|dt| *dt > 5.0 * typical_step));
        if gap || rows.is_empty() {
            continue;
        }
        let path: f64 = rows
            .map(|i| (gyro[i] - g0.mean).norm() * to_rads * steps[i - 1])
            .sum();
        ratios.push(path / gravity_turn);
    }
    (ratios.len() >= 2).then(|| (median(ratios.clone()), ratios.len()))
}

/// Zero for accelerometers in physical units; the per-axis midrange of the hold means for
/// raw counts, whose offset can be as large as the signal.
fn accel_centre(recording: &Recording, still: &StillReport) -> Vec3 {
    if !recording.units.is_counts(Sensor::Accel) {
        return Vec3::zeros();
    }
    let means: Vec<Vec3> = still
        .intervals
        .iter()
        .filter_map(|i| i.accel.as_ref().map(|p| p.mean))
        .collect();
    if means.is_empty() {
        return Vec3::zeros();
    }
    let lo = means
        .iter()
        .fold(Vec3::repeat(f64::INFINITY), |a, m| a.inf(m));
    let hi = means
        .iter()
        .fold(Vec3::repeat(f64::NEG_INFINITY), |a, m| a.sup(m));
    (lo + hi) / 2.0
}

/// Refuse magnetometer samples that do not cover the sphere: too few, in one patch (the board
/// was not turned), or all directions (seen from the per-axis median) within
/// [`MIN_SPREAD_DEG`] of a plane, as when the board is only turned flat on a table. Returns
/// the radius of the sphere fitted to them, for [`check_mag_field`].
pub fn check_mag_coverage(points: &[Vec3]) -> Result<Option<f64>, InputError> {
    if points.len() < MIN_MAG_SAMPLES {
        return Err(InputError::TooFewMagSamples {
            count: points.len(),
            needed: MIN_MAG_SAMPLES,
        });
    }
    // Samples of a board that was not turned sit in one small patch far from zero: a sphere
    // fitted to them has the radius of the noise. The ratio is the same in any unit, so this
    // is told apart from a unit mix-up (which the field check would report).
    let radius = sphere_radius(points);
    let centre = validate::median_centre(points);
    if let Some(radius) = radius {
        let distance = centre.norm();
        if distance > NOT_TURNED_RATIO * radius {
            return Err(InputError::Degenerate {
                sensor: Sensor::Mag,
                detail: format!(
                    "its samples sit in one patch of radius {radius:.3e}, {distance:.3e} from \
                     zero (in the data's unit): the board was not turned while they were \
                     recorded; turn it slowly through all orientations"
                ),
            });
        }
    }
    validate::check_spread_of(directions_from(points, centre), MIN_SPREAD_DEG)
        .map_err(|e| InputError::Degenerate {
            sensor: Sensor::Mag,
            detail: format!(
                "{}; turn the board through all orientations, not only about one axis",
                strip_fit_prefix(&e.to_string())
            ),
        })
        .map(|()| radius)
}

/// Unit directions of `points` from `centre`, computed as they are read.
fn directions_from(points: &[Vec3], centre: Vec3) -> impl Iterator<Item = Vec3> + '_ {
    points
        .iter()
        .filter_map(move |p| (p - centre).try_normalize(1e-300))
}

fn strip_fit_prefix(message: &str) -> String {
    message
        .trim_start_matches("the data cannot determine the calibration: ")
        .to_string()
}

/// Radius of the algebraic least-squares sphere through `points` (centred and scaled first
/// for conditioning); `None` when the normal equations are singular or the radius imaginary.
pub fn sphere_radius(points: &[Vec3]) -> Option<f64> {
    let n = points.len() as f64;
    if points.len() < 4 {
        return None;
    }
    let mean = points.iter().sum::<Vec3>() / n;
    let scale = (points
        .iter()
        .map(|p| (p - mean).norm_squared())
        .sum::<f64>()
        / n)
        .sqrt();
    if !(scale.is_finite() && scale > 0.0) {
        return None;
    }
    let mut normal = Matrix4::<f64>::zeros();
    let mut rhs = Vector4::<f64>::zeros();
    for p in points {
        let q = (p - mean) / scale;
        let row = Vector4::new(2.0 * q.x, 2.0 * q.y, 2.0 * q.z, 1.0);
        normal += row * row.transpose();
        rhs += row * q.norm_squared();
    }
    let solution = normal.cholesky()?.solve(&rhs);
    let centre = Vec3::new(solution[0], solution[1], solution[2]);
    let radius_squared = solution[3] + centre.norm_squared();
    (radius_squared > 0.0 && radius_squared.is_finite()).then(|| radius_squared.sqrt() * scale)
}

/// Check the declared magnetometer unit and a stated field magnitude against the data, from
/// the `radius` of the sphere fitted to its samples ([`check_mag_coverage`] returns it: the
/// radius is only trusted on samples that cover the sphere). Returns warnings; refuses a unit
/// the field radius contradicts, and a field more than [`FIELD_REFUSE_FACTOR`] from the data's.
pub fn check_mag_field(
    radius: Option<f64>,
    declared: MagUnit,
    field_ut: Option<f64>,
) -> Result<Vec<String>, InputError> {
    let Some(to_ut) = declared.to_si() else {
        return Ok(Vec::new());
    };
    let Some(radius) = radius else {
        return Ok(Vec::new());
    };
    let gauss_band = (UT_BAND.0 / 100.0, UT_BAND.1 / 100.0);
    let (fits, declared_flag, native) = match declared {
        MagUnit::Gauss => (in_band(radius, gauss_band), "gauss", gauss_band),
        _ => (in_band(radius, UT_BAND), "ut", UT_BAND),
    };
    if !fits {
        let (looks_like, fix) = if in_band(radius, gauss_band) {
            (
                "looks like gauss (the Earth's field is 0.22–0.67 gauss)",
                "gauss",
            )
        } else if in_band(radius, UT_BAND) {
            ("looks like µT (the Earth's field is 22–67 µT)", "ut")
        } else if radius > native.1 {
            (
                "is far above the Earth's field in that unit, so it looks like raw counts",
                "counts",
            )
        } else {
            (
                "is far below the Earth's field in that unit, so the unit is not known here",
                "counts",
            )
        };
        return Err(InputError::MagUnit {
            radius,
            how: "radius of a sphere fitted to the samples",
            looks_like,
            declared: declared_flag,
            fix,
        });
    }
    let mut warnings = Vec::new();
    if let Some(field) = field_ut {
        let data_ut = radius * to_ut;
        let factor = (data_ut / field).max(field / data_ut);
        if factor > FIELD_REFUSE_FACTOR {
            return Err(InputError::FieldContradicts {
                data_ut,
                field_ut: field,
                factor,
            });
        }
        if (data_ut / field - 1.0).abs() > FIELD_WARN_FRACTION {
            warnings.push(format!(
                "the magnetometer data shows a field of {data_ut:.1} µT, {:.0} % from --field-ut {field}; the output is scaled to {field} µT as asked, but if the sensor's own scale is right the field where it was recorded is disturbed (steel, magnets, electronics): record away from them or check --field-ut",
                100.0 * (data_ut / field - 1.0).abs()
            ));
        }
    }
    Ok(warnings)
}

/// Refuse a recording in which no still interval was found.
pub fn require_still(
    recording: &Recording,
    still: &StillReport,
    options: &crate::still::StillOptions,
) -> Result<(), InputError> {
    if !still.intervals.is_empty() {
        return Ok(());
    }
    // A clock in ms or µs read as seconds makes every hold too long and every move too slow to
    // see: that, not the holds, is then the cause to name.
    if recording.time_from_file {
        if let Some(rate) = crate::recording::median_rate(&recording.time) {
            if rate < SLOWEST_PLAUSIBLE_RATE_HZ {
                return Err(InputError::NoStillSlowClock {
                    path: recording.source.display().to_string(),
                    step_s: 1.0 / rate,
                });
            }
        }
    }
    let duration = match (recording.time.first(), recording.time.last()) {
        (Some(first), Some(last)) if !recording.time_is_index => last - first,
        _ => 0.0,
    };
    let path = recording.source.display().to_string();
    // Only a window the recording could have held at its default length is to blame; a
    // recording shorter than that is too short, whatever the window.
    if options.window_s > duration && crate::still::StillOptions::default().window_s <= duration {
        return Err(InputError::WindowTooLong {
            path,
            window_s: options.window_s,
            duration,
        });
    }
    let (shortest_s, option) = if options.window_s > options.min_hold_s {
        (options.window_s, "--window")
    } else {
        (options.min_hold_s, "--min-hold")
    };
    Err(InputError::NoStill {
        path,
        duration,
        shortest_s,
        option,
    })
}

/// Per axis, the fraction of the consecutive sample pairs of `rows` that are equal; `None` for
/// fewer than two samples.
fn repeat_fractions(rows: &[usize], samples: &[Vec3]) -> Option<Vec3> {
    let values: Vec<&Vec3> = rows.iter().filter_map(|&r| samples.get(r)).collect();
    let pairs = values.len().checked_sub(1).filter(|&p| p > 0)?;
    let mut equal = Vec3::zeros();
    for w in values.windows(2) {
        for k in 0..3 {
            equal[k] += f64::from(u8::from(w[0][k] == w[1][k]));
        }
    }
    Some(equal / pairs as f64)
}

/// Leave out holds that are saturated (an axis pinned at the recording's extreme value in at
/// least [`SATURATED_FRACTION`] of the hold's samples, on an axis that shows noise in the
/// median hold) or, for holds from a `pose` column, moving (variance [`MOTION_RATIO`] times
/// that of the median hold on the accelerometer or gyroscope). Directions are clustered again.
/// Returns one sentence per hold left out; refuses when none is left.
pub fn screen_holds(
    recording: &Recording,
    still: &mut StillReport,
    direction_angle_deg: f64,
) -> Result<Vec<String>, InputError> {
    let mut reasons: Vec<Option<String>> = vec![None; still.intervals.len()];
    for sensor in [Sensor::Accel, Sensor::Gyro] {
        let Some(samples) = recording.samples(sensor) else {
            continue;
        };
        let lo = samples
            .iter()
            .fold(Vec3::repeat(f64::INFINITY), |a, m| a.inf(m));
        let hi = samples
            .iter()
            .fold(Vec3::repeat(f64::NEG_INFINITY), |a, m| a.sup(m));
        let typical_var: Vec<f64> = (0..3)
            .map(|k| {
                median(
                    still
                        .intervals
                        .iter()
                        .filter_map(|i| i.pose(sensor).map(|p| p.var[k]))
                        .collect(),
                )
            })
            .collect();
        // Per axis: whether holds spread over several values, so a pile can mean a rail.
        let repeats: Vec<Vec3> = still
            .intervals
            .iter()
            .filter_map(|i| repeat_fractions(&i.rows(recording), samples))
            .collect();
        let noise_resolved: Vec<bool> = (0..3)
            .map(|k| {
                !repeats.is_empty()
                    && median(repeats.iter().map(|r| r[k]).collect())
                        < SATURATED_FRACTION * SATURATED_FRACTION
            })
            .collect();
        for (interval, reason) in still.intervals.iter().zip(reasons.iter_mut()) {
            if reason.is_some() {
                continue;
            }
            let rows = interval.rows(recording);
            if rows.len() < 2 {
                continue;
            }
            // Samples at each axis's largest and smallest value, counted in one pass.
            let mut at_rails = [[0usize; 2]; 3];
            for v in rows.iter().filter_map(|&r| samples.get(r)) {
                for (k, counts) in at_rails.iter_mut().enumerate() {
                    counts[0] += usize::from(v[k] == hi[k]);
                    counts[1] += usize::from(v[k] == lo[k]);
                }
            }
            for (k, axis) in ["x", "y", "z"].into_iter().enumerate() {
                if !(hi[k] > lo[k] && typical_var[k] > 0.0 && noise_resolved[k]) {
                    continue;
                }
                for ((rail, which), at_rail) in [(hi[k], "largest"), (lo[k], "smallest")]
                    .into_iter()
                    .zip(at_rails[k])
                {
                    let fraction = at_rail as f64 / rows.len() as f64;
                    // Pinned means repeated: one sample at the extreme is only the extreme.
                    if reason.is_none() && at_rail >= 2 && fraction >= SATURATED_FRACTION {
                        *reason = Some(format!(
                            "the {sensor} {axis} axis sits at {rail} (the {which} value in the recording) in {:.0} % of its samples, so it is saturated at the end of its range; set the sensor to a larger full-scale range and hold that orientation again",
                            100.0 * fraction
                        ));
                    }
                }
            }
            if still.from_pose_column && reason.is_none() {
                if let Some(pose) = interval.pose(sensor) {
                    let axes: Vec<f64> = (0..3)
                        .filter(|&k| typical_var[k] > 0.0)
                        .map(|k| pose.var[k] / typical_var[k])
                        .collect();
                    let ratio = axes.iter().sum::<f64>() / axes.len().max(1) as f64;
                    if ratio > MOTION_RATIO {
                        *reason = Some(format!(
                            "the {sensor} varied {ratio:.0} times as much as in the median hold, so the board moved during the capture; hold it still for the whole capture, or relabel the rows"
                        ));
                    }
                }
            }
        }
    }
    let messages: Vec<String> = still
        .intervals
        .iter()
        .zip(&reasons)
        .filter_map(|(interval, reason)| {
            let reason = reason.as_ref()?;
            Some(format!("{} is left out: {reason}", interval.name()))
        })
        .collect();
    if !still.intervals.is_empty() && reasons.iter().all(Option::is_some) {
        let mut kinds: Vec<&str> = reasons
            .iter()
            .flatten()
            .map(|r| {
                if r.contains("saturated") {
                    "saturated"
                } else {
                    "moving"
                }
            })
            .collect();
        kinds.sort_unstable();
        kinds.dedup();
        return Err(InputError::NoUsableHold {
            path: recording.source.display().to_string(),
            reasons: format!(
                "{} holds, all {}",
                still.intervals.len(),
                kinds.join(" or ")
            ),
        });
    }
    still.retain_intervals(recording, direction_angle_deg, |index, _| {
        reasons.get(index).is_some_and(Option::is_some)
    });
    Ok(messages)
}

/// Refuse accelerometer holds that cannot determine a calibration: fewer than
/// [`MIN_DIRECTIONS`] distinct gravity directions (repeats of a direction do not count), or
/// directions all within [`MIN_SPREAD_DEG`] of a plane.
pub fn check_accel_poses(still: &StillReport) -> Result<(), InputError> {
    let holds = still.intervals.iter().filter(|i| i.accel.is_some()).count();
    let distinct = still.directions.len();
    if distinct < MIN_DIRECTIONS {
        let repeated = holds.saturating_sub(distinct);
        let repeats = if repeated > 0 {
            format!(" ({repeated} of them repeat a direction already held)")
        } else {
            String::new()
        };
        return Err(InputError::TooFewDirections {
            holds,
            distinct,
            needed: MIN_DIRECTIONS,
            repeats,
        });
    }
    validate::check_spread(&still.directions, MIN_SPREAD_DEG).map_err(|e| InputError::Degenerate {
        sensor: Sensor::Accel,
        detail: strip_fit_prefix(&e.to_string()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaps_the_still_detection_breaks_at_are_counted_and_the_longest_named() {
        // 100 Hz with a 1000 s dropout after t = 14.99 s and a 2 s one later.
        let mut time: Vec<f64> = (0..1500).map(|i| f64::from(i) * 0.01).collect();
        time.extend((0..500).map(|i| 1015.0 + f64::from(i) * 0.01));
        time.extend((0..500).map(|i| 1022.0 + f64::from(i) * 0.01));
        let warnings = time_stamp_warnings(&time);
        assert_eq!(warnings.len(), 1, "{warnings:?}");
        assert!(
            warnings[0].starts_with("2 gaps in the time stamps longer than 1 s (the longest 1000.010 s, after t = 14.99 s)"),
            "{warnings:?}"
        );
        let steady: Vec<f64> = (0..2000).map(|i| f64::from(i) * 0.01).collect();
        assert!(time_stamp_warnings(&steady).is_empty());
    }

    #[test]
    fn sphere_radius_of_points_on_an_offset_sphere_is_its_radius() {
        // Exact points on a sphere: the algebraic fit is exact up to rounding.
        let centre = Vec3::new(120.0, -40.0, 15.0);
        let points: Vec<Vec3> = (0..200)
            .map(|i| {
                let z = -1.0 + 2.0 * (i as f64 + 0.5) / 200.0;
                let phi = i as f64 * 2.399963;
                let r = (1.0 - z * z).sqrt();
                centre + 48.5 * Vec3::new(r * phi.cos(), r * phi.sin(), z)
            })
            .collect();
        let radius = sphere_radius(&points).unwrap_or(f64::NAN);
        assert!((radius - 48.5).abs() < 1e-9, "{radius}");
    }

    #[test]
    fn a_sensor_with_one_reading_in_every_row_is_stuck_and_one_constant_axis_is_a_warning() {
        let mut samples = vec![Vec3::new(0.0, 0.25, 1.0); MIN_ROWS_FOR_STUCK];
        let error = check_not_stuck(&samples, Sensor::Gyro).expect_err("stuck");
        assert!(
            error
                .to_string()
                .contains("reads (0, 0.25, 1) in every one of its 100 rows"),
            "{error}"
        );
        for (i, s) in samples.iter_mut().enumerate() {
            s.x = i as f64;
        }
        let warning = check_not_stuck(&samples, Sensor::Mag)
            .expect("one axis moving is not refused")
            .expect("a warning");
        assert!(
            warning.contains("columns my (0.25) and mz (1) never change"),
            "{warning}"
        );
        // One reading one count apart on each axis is a working sensor.
        samples[MIN_ROWS_FOR_STUCK - 1].y = 0.26;
        samples[0].z = f64::NAN;
        assert_eq!(check_not_stuck(&samples, Sensor::Mag), Ok(None));
        // A sensor of NaN is stuck; fewer rows than the bound are too few to tell.
        let nan = vec![Vec3::new(f64::NAN, f64::NAN, 2.0); MIN_ROWS_FOR_STUCK];
        assert!(check_not_stuck(&nan, Sensor::Accel).is_err());
        assert_eq!(check_not_stuck(&nan[1..], Sensor::Accel), Ok(None));
    }

    #[test]
    fn accelerometer_in_g_declared_as_mps2_is_refused_with_the_g_flag() {
        let samples = vec![Vec3::new(0.01, -0.02, 0.99); 10];
        let error = check_accel_unit(&samples, AccelUnit::Mps2).expect_err("g read as m/s²");
        assert!(error.to_string().contains("pass --accel-unit g"), "{error}");
        assert!(check_accel_unit(&samples, AccelUnit::G).is_ok());
    }
}
