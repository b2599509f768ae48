//! The session directory and the machine-readable summary.
//!
//! Files: `params.json` (the [`ParamsFile`] format, so `imucal flash params.json` writes it
//! again), `poses.json` (every `PoseStats` with the orientation it was taken for and the board
//! time of the hold; [`load_poses`] reads it back for `imucal analyze SESSION_DIR`),
//! `mag_samples.csv` (`t_s,mx,my,mz,temp_c,phase`, raw µT on the board's clock), `moves.csv`
//! (every sample of the moves between the holds that the gyroscope's scale fit integrates, in
//! the recording format with a `segment` per move; [`load_moves`] reads it back, so a resumed
//! session keeps them) and `summary.json` (the [`SessionSummary`], as printed by
//! `imucal calibrate --json`).

use std::path::{Path, PathBuf};

use imucal_protocol::PoseStats;
use serde::{Deserialize, Serialize};

use super::gyro_fit::GyroScale;
use super::rest::RestErrors;
use super::solve::{CapturedPose, FieldSource, Uncertainties, Verdict, VerdictLevel};
use super::targets::Target;
use super::{MagSample, Phase, SessionError, SessionOutcome};
use crate::device::{ParamsFile, UnitSample};
use crate::fit::Vec3;

/// The summary of a session (`--json` and `summary.json`).
#[derive(Debug, Clone, Serialize)]
pub struct SessionSummary {
    /// Whether the written set was read back and matched (CRC and every value).
    pub verified: bool,
    /// Whether the fitted set was written to the board.
    pub written: bool,
    /// Why it was not written (`poor verdict`, `declined at the prompt`, `outlier against the
    /// fleet`, …); `null` when it was.
    pub not_written_because: Option<String>,
    /// `| |ā| − g |` at rest with the set on the board at the end, mg: the extended set when
    /// `--analyze` wrote one (`null` when nothing was written, or when the extended set's check
    /// at rest failed).
    pub accel_rest_error_mg: Option<f64>,
    /// `| |m̄| − H |` at rest with the set on the board at the end, % of `H` (as above).
    pub mag_rest_error_pct: Option<f64>,
    /// `|ω̄|` at rest with the set on the board at the end, °/s (as above).
    pub gyro_rest_error_dps: Option<f64>,
    /// Board time from the first prompt to the verified write, s (simulated on a simulated
    /// board).
    pub session_seconds: f64,
    /// Wall time of the same span, s.
    pub wall_seconds: f64,
    /// The set the board holds at the end of the session: the extended set when `--analyze`
    /// wrote one over the base set, else the fitted set (also when it was not written; then
    /// `verified` is false).
    pub params: ParamsFile,
    /// CRC-32 of `params`.
    pub params_crc: String,
    /// CRC-32 of the base set the session wrote first, when `--analyze` then replaced it with
    /// the extended set (`params-base.json`); `null` otherwise.
    pub base_params_crc: Option<String>,
    /// Errors at rest without calibration (raw readings).
    pub before: RestErrors,
    /// Errors at rest with the fitted set as first written (the base set, when `--analyze`
    /// then replaced it; see `on_board_after`).
    pub after: Option<RestErrors>,
    /// The set on the board when the session ended: the extended set `--analyze` wrote, or the
    /// base set (then equal to `after`); `null` when nothing was written.
    pub on_board_after: Option<RestErrors>,
    /// The at-rest targets the set on the board misses, one sentence each
    /// ([`RestErrors::missed_targets`]); empty when it meets them or nothing was written.
    pub missed_targets: Vec<String>,
    /// The port.
    pub port: String,
    /// The board's id.
    pub device_id: String,
    /// Poses captured.
    pub poses: usize,
    /// Why extra positions were or were not asked for.
    pub extra_positions: String,
    /// Magnetometer samples fitted from the tumble (before thinning) and regions covered.
    pub mag_tumble_samples: usize,
    /// Regions of the sphere with enough samples (the session's minimum per region, as its
    /// screen counted them), of 26.
    pub mag_regions_covered: usize,
    /// Reference field, µT, and where it came from.
    pub field_ut: f64,
    /// Where the reference field came from.
    pub field_source: FieldSource,
    /// Local gravity used, m/s².
    pub gravity_mps2: f64,
    /// One-sigma uncertainties of the set in `params` (with `--analyze`'s extended set, its
    /// replaced sensors' figures come from the analysis's final model).
    pub uncertainties: Uncertainties,
    /// The base set's uncertainties when `--analyze` replaced it with the extended set;
    /// `null` otherwise.
    pub base_uncertainties: Option<Uncertainties>,
    /// The verdict.
    pub verdict: Verdict,
    /// Findings that do not change the verdict (positions left out of the magnetometer's
    /// alignment, and why).
    pub notes: Vec<String>,
    /// The gyroscope's scale factors and misalignment with their σ (`null` when only the bias
    /// could be calibrated).
    pub gyro_scale: Option<GyroScale>,
    /// Calibrated samples per second of board time at rest; `null` when no calibrated stream
    /// was measured (nothing written).
    pub stream_rate_hz: Option<f64>,
    /// Samples lost in transit.
    pub lost_samples: u64,
    /// A noisy link's measured loss and what to check; absent when the link was sound.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub link_note: Option<String>,
}

/// `verdict` with the targets the set on the board missed at rest ([`RestErrors::missed_targets`],
/// measured with the calibrated stream after the write) among its reasons: a set that misses
/// its own target is at best marginal, whatever its expected errors promised.
pub fn verdict_with_missed_targets(verdict: &Verdict, missed: &[String]) -> Verdict {
    let mut verdict = verdict.clone();
    for target in missed {
        verdict.reasons.push(format!(
            "the set on the board misses its target at rest: {target} (measured with the \
             calibrated stream after the write)"
        ));
        if verdict.level == VerdictLevel::Good {
            verdict.level = VerdictLevel::Marginal;
        }
    }
    verdict
}

/// The summary of `outcome`.
pub fn summary(outcome: &SessionOutcome) -> SessionSummary {
    let missed = outcome
        .after
        .map(|a| a.missed_targets(outcome.fit.budgets))
        .unwrap_or_default();
    let tumble = outcome
        .mag_samples
        .iter()
        .filter(|m| m.phase == super::Phase::Tumble)
        .count();
    SessionSummary {
        verified: outcome.verified,
        written: outcome.written,
        not_written_because: match (outcome.written, &outcome.not_written_because) {
            (true, _) => None,
            (false, Some(why)) => Some(why.clone()),
            (false, None) => Some("not written".to_string()),
        },
        accel_rest_error_mg: outcome.after.map(|a| a.accel_error_mg),
        mag_rest_error_pct: outcome.after.map(|a| a.mag_error_pct),
        gyro_rest_error_dps: outcome.after.map(|a| a.gyro_rate_dps),
        session_seconds: outcome.session_seconds,
        wall_seconds: outcome.wall_seconds,
        params: ParamsFile::from(&outcome.fit.set),
        params_crc: format!("{:#010x}", outcome.fit.set.crc32()),
        base_params_crc: None,
        before: outcome.before,
        after: outcome.after,
        on_board_after: outcome.after,
        missed_targets: missed.clone(),
        port: outcome.port.clone(),
        device_id: outcome.device_id.clone(),
        poses: outcome.poses.len(),
        extra_positions: outcome.extra_positions_note.clone(),
        mag_tumble_samples: tumble,
        mag_regions_covered: outcome.coverage.covered(outcome.mag_min_per_region),
        field_ut: outcome.fit.field_ut,
        field_source: outcome.fit.field_source,
        gravity_mps2: outcome.fit.gravity_mps2,
        uncertainties: outcome.fit.uncertainties,
        base_uncertainties: None,
        gyro_scale: outcome.gyro_scale.clone(),
        verdict: verdict_with_missed_targets(&outcome.fit.verdict, &missed),
        notes: outcome.fit.notes.clone(),
        stream_rate_hz: (outcome.stream_rate_hz > 0.0).then_some(outcome.stream_rate_hz),
        lost_samples: outcome.lost_samples,
        link_note: outcome.link_note.clone(),
    }
}

#[derive(Serialize)]
struct PoseRecord<'a> {
    target: &'a str,
    target_index: usize,
    target_up: [f64; 3],
    t_s: f64,
    stats: &'a PoseStats,
}

/// A pose as read back; files written before the index and time were saved lack them.
#[derive(Deserialize)]
struct PoseRecordIn {
    target: String,
    #[serde(default)]
    target_index: Option<usize>,
    target_up: [f64; 3],
    #[serde(default)]
    t_s: Option<f64>,
    stats: PoseStats,
}

/// Read the poses of a session directory's `poses.json`. A file without hold times (written by
/// an older version) gets one second per pose in file order, which keeps the capture order the
/// analysis compares temperature with.
pub fn load_poses(path: &Path) -> Result<Vec<CapturedPose>, SessionError> {
    let load_error = |reason: String| SessionError::Load {
        path: path.display().to_string(),
        reason,
    };
    let text = std::fs::read_to_string(path).map_err(|e| load_error(e.to_string()))?;
    let records: Vec<PoseRecordIn> =
        serde_json::from_str(&text).map_err(|e| load_error(e.to_string()))?;
    Ok(records
        .into_iter()
        .enumerate()
        .map(|(i, r)| CapturedPose {
            target: Target {
                index: r.target_index.unwrap_or(i),
                up: Vec3::from(r.target_up),
                name: r.target,
            },
            stats: r.stats,
            t_s: r.t_s.unwrap_or(i as f64),
        })
        .collect())
}

/// Write `text` to `path` through a temporary file and a rename, so a session file is never
/// left half-written when the program is stopped mid-write.
pub(super) fn write_file(path: &Path, text: &str) -> Result<PathBuf, SessionError> {
    let save_error = |cause| SessionError::Save {
        path: path.display().to_string(),
        cause,
    };
    let mut partial = path.as_os_str().to_owned();
    partial.push(".partial");
    let partial = PathBuf::from(partial);
    std::fs::write(&partial, text).map_err(save_error)?;
    std::fs::rename(&partial, path).map_err(save_error)?;
    Ok(path.to_path_buf())
}

/// Create the session directory `dir` if missing.
pub(super) fn create_dir(dir: &Path) -> Result<(), SessionError> {
    std::fs::create_dir_all(dir).map_err(|cause| SessionError::Save {
        path: dir.display().to_string(),
        cause,
    })
}

fn json_text<T: Serialize>(value: &T) -> String {
    // Plain data of numbers, strings and fixed keys; non-finite numbers become null.
    serde_json::to_string_pretty(value).unwrap_or_default()
}

/// The text of `poses.json` for `poses`.
pub(super) fn poses_json(poses: &[CapturedPose]) -> String {
    let records: Vec<PoseRecord<'_>> = poses
        .iter()
        .map(|p| PoseRecord {
            target: &p.target.name,
            target_index: p.target.index,
            target_up: [p.target.up.x, p.target.up.y, p.target.up.z],
            t_s: p.t_s,
            stats: &p.stats,
        })
        .collect();
    json_text(&records)
}

/// The text of `mag_samples.csv` for `samples`.
pub(super) fn mag_csv(samples: &[MagSample]) -> String {
    let mut csv = String::from("t_s,mx,my,mz,temp_c,phase\n");
    for m in samples {
        csv.push_str(&format!(
            "{:.6},{:.4},{:.4},{:.4},{:.3},{}\n",
            m.t_s,
            m.mag[0],
            m.mag[1],
            m.mag[2],
            m.temp_c,
            m.phase.name()
        ));
    }
    csv
}

fn load_error(path: &Path, reason: String) -> SessionError {
    SessionError::Load {
        path: path.display().to_string(),
        reason,
    }
}

/// The text of the session CSV file `path`, refused unless its first line is `header`.
fn read_with_header(path: &Path, header: &str) -> Result<String, SessionError> {
    let text = std::fs::read_to_string(path).map_err(|e| load_error(path, e.to_string()))?;
    match text.lines().next() {
        Some(first) if first.trim() == header => Ok(text),
        _ => Err(load_error(
            path,
            format!("its first line is not the header {header}"),
        )),
    }
}

/// Read the samples of a session directory's `mag_samples.csv` ([`mag_csv`]'s columns), e.g.
/// to continue an unfinished session without losing them.
pub fn load_mag_samples(path: &Path) -> Result<Vec<MagSample>, SessionError> {
    let load_error = |reason: String| load_error(path, reason);
    let text = read_with_header(path, "t_s,mx,my,mz,temp_c,phase")?;
    text.lines()
        .enumerate()
        .skip(1)
        .filter(|(_, line)| !line.trim().is_empty())
        .map(|(i, line)| {
            let fields: Vec<&str> = line.split(',').map(str::trim).collect();
            let number = |k: usize| fields.get(k).and_then(|f| f.parse::<f64>().ok());
            let phase = fields.get(5).and_then(|name| Phase::from_name(name));
            match (
                fields.len(),
                number(0),
                number(1),
                number(2),
                number(3),
                number(4),
                phase,
            ) {
                (6, Some(t_s), Some(mx), Some(my), Some(mz), Some(temp_c), Some(phase)) => {
                    Ok(MagSample {
                        t_s,
                        mag: [mx, my, mz],
                        temp_c,
                        phase,
                    })
                }
                _ => Err(load_error(format!(
                    "line {} is not six comma-separated values ending in a phase name: {line}",
                    i + 1
                ))),
            }
        })
        .collect()
}

/// Header of `moves.csv`: the recording format's columns in nominal units (m/s², rad/s, µT,
/// °C on the board's clock) and the move each row belongs to.
const MOVES_HEADER: &str = "t_s,ax,ay,az,gx,gy,gz,mx,my,mz,temp_c,segment";

/// The text of `moves.csv` for `moves`: one row per sample, `segment` `move-N` numbering the
/// moves from 1. Values are written in the shortest form that reads back to the same `f64`,
/// so a resumed session fits exactly what the first run measured.
pub(super) fn moves_csv(moves: &[Vec<UnitSample>]) -> String {
    let mut csv = String::with_capacity(32 + 160 * moves.iter().map(Vec::len).sum::<usize>());
    csv.push_str(MOVES_HEADER);
    csv.push('\n');
    for (k, samples) in moves.iter().enumerate() {
        let label = format!("move-{}", k + 1);
        for u in samples {
            push_row(&mut csv, u, Some(&label));
        }
    }
    csv
}

/// Header of a session's `readings.csv`: the recording format's columns in nominal units,
/// without a temperature (a board that reports none).
const READINGS_HEADER: &str = "t_s,ax,ay,az,gx,gy,gz,mx,my,mz";

/// The text of `readings.csv`: every reading of a session in the recording format, so that
/// `imucal fit` reads it. The temperature column is left out: it is written only for boards
/// that measure one, which the callers of this one do not.
pub fn readings_csv(readings: &[UnitSample]) -> String {
    let mut csv = String::with_capacity(32 + 150 * readings.len());
    csv.push_str(READINGS_HEADER);
    csv.push('\n');
    for u in readings {
        push_row(&mut csv, u, None);
    }
    csv
}

/// One row of the recording format: time, the three sensors, then `temp_c` and `label` when
/// a label is given (the moves' form), in the shortest form that reads back to the same `f64`.
fn push_row(csv: &mut String, u: &UnitSample, label: Option<&str>) {
    use std::fmt::Write as _;
    let [ax, ay, az] = u.accel;
    let [gx, gy, gz] = u.gyro;
    let [mx, my, mz] = u.mag;
    // Writing to a String cannot fail.
    let _ = write!(
        csv,
        "{},{ax},{ay},{az},{gx},{gy},{gz},{mx},{my},{mz}",
        u.t_s
    );
    if let Some(label) = label {
        let _ = write!(csv, ",{},{label}", u.temp_c);
    }
    csv.push('\n');
}

/// Read the moves of a session directory's `moves.csv` ([`moves_csv`]'s columns), in order.
pub fn load_moves(path: &Path) -> Result<Vec<Vec<UnitSample>>, SessionError> {
    let load_error = |reason: String| load_error(path, reason);
    let text = read_with_header(path, MOVES_HEADER)?;
    let lines = text.lines().enumerate().skip(1);
    let mut moves: Vec<Vec<UnitSample>> = Vec::new();
    let mut names: Vec<String> = Vec::new();
    for (i, line) in lines.filter(|(_, line)| !line.trim().is_empty()) {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        let values: Option<Vec<f64>> = match fields.as_slice() {
            [numbers @ .., _] if fields.len() == 12 => numbers
                .iter()
                .map(|f| f.parse::<f64>().ok().filter(|v| v.is_finite()))
                .collect(),
            _ => None,
        };
        let (Some(v), Some(segment)) = (values, fields.last()) else {
            return Err(load_error(format!(
                "line {} is not eleven finite numbers and a move name: {line}",
                i + 1
            )));
        };
        let sample = UnitSample {
            t_s: v[0],
            accel: [v[1], v[2], v[3]],
            gyro: [v[4], v[5], v[6]],
            mag: [v[7], v[8], v[9]],
            temp_c: v[10],
        };
        match (names.last(), moves.last_mut()) {
            (Some(last), Some(samples)) if last == segment => samples.push(sample),
            _ if names.iter().any(|n| n == segment) => {
                return Err(load_error(format!(
                    "line {}: the rows of {segment} are not together (each move's rows are \
                     consecutive)",
                    i + 1
                )))
            }
            _ => {
                names.push((*segment).to_string());
                moves.push(vec![sample]);
            }
        }
    }
    Ok(moves)
}

/// Write the session directory `dir` (created if missing); returns the files written.
pub fn save_session(outcome: &SessionOutcome, dir: &Path) -> Result<Vec<PathBuf>, SessionError> {
    create_dir(dir)?;
    let written = vec![
        write_file(
            &dir.join("params.json"),
            &ParamsFile::from(&outcome.fit.set).to_json(),
        )?,
        write_file(&dir.join("poses.json"), &poses_json(&outcome.poses))?,
        write_file(&dir.join("mag_samples.csv"), &mag_csv(&outcome.mag_samples))?,
        write_file(&dir.join(MOVES_FILE), &moves_csv(&outcome.moves))?,
        write_file(&dir.join("summary.json"), &json_text(&summary(outcome)))?,
    ];
    finish(dir)?;
    Ok(written)
}

/// The name of the moves file of a session directory ([`moves_csv`]).
pub const MOVES_FILE: &str = "moves.csv";

/// The name of the progress file of an unfinished session directory.
pub const PROGRESS_FILE: &str = "progress.json";

/// Mark `dir` as a finished session (its `progress.json` no longer applies).
pub(super) fn finish(dir: &Path) -> Result<(), SessionError> {
    match std::fs::remove_file(dir.join(PROGRESS_FILE)) {
        Err(cause) if cause.kind() != std::io::ErrorKind::NotFound => Err(SessionError::Save {
            path: dir.join(PROGRESS_FILE).display().to_string(),
            cause,
        }),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::recording::Sensor;

    fn stats_json(n: u32) -> serde_json::Value {
        serde_json::to_value(PoseStats {
            n,
            accel_mean: [0.0, 0.0, 9.81],
            accel_var: [4e-4; 3],
            gyro_mean: [0.0; 3],
            gyro_var: [1e-5; 3],
            mag_mean: [20.0, 0.0, 40.0],
            mag_var: [0.1; 3],
            temp_mean_c: 25.0,
            temp_min_c: 24.9,
            temp_max_c: 25.1,
            duration_ms: 1500,
        })
        .unwrap_or_default()
    }

    fn temp_file(name: &str, text: &str) -> PathBuf {
        let path = std::env::temp_dir().join(format!("imucal-{}-{name}", std::process::id()));
        std::fs::write(&path, text).expect("the temporary file is writable");
        path
    }

    #[test]
    fn poses_with_index_and_time_are_read_back_as_saved() {
        let text = serde_json::json!([{
            "target": "-Z up", "target_index": 5, "target_up": [0.0, 0.0, -1.0],
            "t_s": 12.5, "stats": stats_json(180)
        }])
        .to_string();
        let path = temp_file("poses-new.json", &text);
        let poses = load_poses(&path).expect("the file is read");
        let _ = std::fs::remove_file(&path);
        assert_eq!(poses.len(), 1);
        assert_eq!((poses[0].target.index, poses[0].t_s), (5, 12.5));
        assert_eq!(poses[0].target.name, "-Z up");
        assert_eq!(poses[0].stats.n, 180);
    }

    #[test]
    fn poses_without_hold_times_get_their_file_order_as_time() {
        let text = serde_json::json!([
            { "target": "+Z up", "target_up": [0.0, 0.0, 1.0], "stats": stats_json(150) },
            { "target": "-Z up", "target_up": [0.0, 0.0, -1.0], "stats": stats_json(160) }
        ])
        .to_string();
        let path = temp_file("poses-old.json", &text);
        let poses = load_poses(&path).expect("the file is read");
        let _ = std::fs::remove_file(&path);
        let order: Vec<(usize, f64)> = poses.iter().map(|p| (p.target.index, p.t_s)).collect();
        assert_eq!(order, vec![(0, 0.0), (1, 1.0)]);
    }

    #[test]
    fn saved_magnetometer_samples_are_read_back_as_written() {
        let samples = vec![
            MagSample {
                t_s: 1.25,
                mag: [20.5, -3.25, 41.0],
                temp_c: 24.5,
                phase: Phase::Positions,
            },
            MagSample {
                t_s: 9.5,
                mag: [-18.0, 7.5, -40.25],
                temp_c: 25.0,
                phase: Phase::Tumble,
            },
        ];
        let path = temp_file("mag.csv", &mag_csv(&samples));
        let read = load_mag_samples(&path).expect("the file is read");
        let _ = std::fs::remove_file(&path);
        assert_eq!(read, samples);
    }

    #[test]
    fn a_broken_magnetometer_file_is_an_error_naming_the_line() {
        let path = temp_file("mag-broken.csv", "t_s,mx,my,mz,temp_c,phase\n1,2,3\n");
        let error = load_mag_samples(&path).expect_err("a short line is refused");
        let _ = std::fs::remove_file(&path);
        assert!(error.to_string().contains("line 2"), "{error}");
    }

    fn unit_sample(k: u32) -> UnitSample {
        // Values as the board gives them: counts times a scale that is not a short decimal.
        let c = f64::from(k);
        UnitSample {
            t_s: 12.0 + c * 0.01,
            accel: [c * 0.000_598_550_4, -9.81 + c * 1e-3, 0.1],
            gyro: [c * 0.000_152_716_1, -1.0 / 3.0, std::f64::consts::PI * 1e-3],
            mag: [20.0 + c * 0.146_484_375, -5.0, 41.0],
            temp_c: 25.0 + c / 7.0,
        }
    }

    #[test]
    fn saved_moves_are_read_back_bit_for_bit_and_in_order() {
        let moves = vec![
            (0..40).map(unit_sample).collect::<Vec<_>>(),
            (40..41).map(unit_sample).collect(),
            (41..90).map(unit_sample).collect(),
        ];
        let path = temp_file("moves.csv", &moves_csv(&moves));
        let read = load_moves(&path).expect("the file is read");
        let _ = std::fs::remove_file(&path);
        assert_eq!(read, moves);
        let path = temp_file("moves-none.csv", &moves_csv(&[]));
        let read = load_moves(&path).expect("a file of no moves is read");
        let _ = std::fs::remove_file(&path);
        assert!(read.is_empty());
    }

    #[test]
    fn saved_readings_are_a_recording_read_back_bit_for_bit() {
        let readings: Vec<UnitSample> = (0..5).map(unit_sample).collect();
        let path = temp_file("readings.csv", &readings_csv(&readings));
        let recording = crate::recording::Recording::load(&path, &Default::default())
            .expect("the readings are a recording");
        let _ = std::fs::remove_file(&path);
        assert_eq!(recording.len(), 5);
        assert!(
            recording.temp_c.is_none(),
            "no temperature column is written"
        );
        for (k, u) in readings.iter().enumerate() {
            assert_eq!(recording.time[k], u.t_s);
            for (sensor, value) in [
                (Sensor::Accel, u.accel),
                (Sensor::Gyro, u.gyro),
                (Sensor::Mag, u.mag),
            ] {
                let read = recording.samples(sensor).expect("every sensor is written")[k];
                assert_eq!(<[f64; 3]>::from(read), value, "{sensor:?} row {k}");
            }
        }
    }

    #[test]
    fn a_broken_moves_file_is_an_error_naming_the_cause() {
        let header = MOVES_HEADER;
        let row = |segment: &str| format!("1,0,0,9.8,0,0,0,20,0,40,25,{segment}\n");
        for (name, text, expected) in [
            ("moves-header.csv", "t_s,ax\n".to_string(), "header"),
            (
                "moves-short.csv",
                format!("{header}\n1,2,3,move-1\n"),
                "line 2",
            ),
            (
                "moves-nan.csv",
                format!("{header}\n{}", row("move-1").replace("9.8", "NaN")),
                "line 2",
            ),
            (
                "moves-split.csv",
                format!(
                    "{header}\n{}{}{}",
                    row("move-1"),
                    row("move-2"),
                    row("move-1")
                ),
                "not together",
            ),
        ] {
            let path = temp_file(name, &text);
            let error = load_moves(&path).expect_err("a broken file is refused");
            let _ = std::fs::remove_file(&path);
            assert!(error.to_string().contains(expected), "{name}: {error}");
        }
    }

    #[test]
    fn a_broken_poses_file_is_an_error_naming_the_file() {
        let path = temp_file("poses-broken.json", "[{\"target\": 3}");
        let error = load_poses(&path).expect_err("a broken file is refused");
        let _ = std::fs::remove_file(&path);
        let message = error.to_string();
        assert!(message.contains(&path.display().to_string()), "{message}");
        assert!(message.contains("poses.json"), "{message}");
    }
}
