//! How a board's parameters moved between consecutive calibrations, in units of the combined
//! one-sigma uncertainty of both fits: `(x₂ − x₁) / √(σ₁² + σ₂²)`. A change of a few σ is within
//! what two honest fits of the same board disagree by; tens of σ mean the board changed (a
//! knock, re-soldering, a new magnetised part) or one of the fits was poor.
//!
//! Parameters are compared only where both records calibrated the sensor from the same input
//! unit: a sensor fitted in one record and not in the other is listed as such (its placeholder
//! identity is no measurement), and one fitted from raw counts in one and from nominal units in
//! the other has `A` and `b` in different units, so a difference of the two says nothing.

use std::collections::BTreeMap;

use serde::Serialize;

use super::store::{RecordId, StoredRecord};

/// The change of one parameter since the board's previous calibration.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParameterChange {
    /// The parameter (see [`super::CalibrationRecord::parameters`]).
    pub parameter: String,
    /// Value before.
    pub before: f64,
    /// Value now.
    pub after: f64,
    /// `after − before`, in the parameter's unit.
    pub change: f64,
    /// The change in combined σ, when both records have a σ for it.
    pub change_sigma: Option<f64>,
}

impl ParameterChange {
    /// `|after − before| / |before|`, or the absolute change when `before` is 0 (an offset that
    /// was exactly zero, or a cross term).
    pub fn relative(&self) -> f64 {
        if self.before == 0.0 {
            self.change.abs()
        } else {
            (self.change / self.before).abs()
        }
    }
}

/// One record of a board with its changes since the board's previous record.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RecordChanges {
    /// The record.
    #[serde(flatten)]
    pub stored: StoredRecord,
    /// The same board's latest earlier record whose set went onto the board: the set the board
    /// held before this record. Records never written are skipped (see `not_written_between`).
    pub previous: Option<RecordId>,
    /// The same board's records after `previous` (or from its first record) whose set was
    /// never written to the board, oldest first.
    pub not_written_between: Vec<RecordId>,
    /// Every parameter both records have, largest change in σ first (then unscaled ones).
    pub changes: Vec<ParameterChange>,
    /// Sensors this record calibrates and the previous one did not, and the reverse, and those
    /// whose input unit changed: none of their parameters is in `changes`.
    pub sensor_changes: Vec<SensorChange>,
}

/// How a sensor's calibration changed in kind since the board's previous record.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(tag = "change", rename_all = "snake_case")]
pub enum SensorChange {
    /// Calibrated now, not in the previous record.
    NowFitted {
        /// `accel`, `gyro` or `mag`.
        sensor: String,
    },
    /// Calibrated in the previous record, not now.
    NoLongerFitted {
        /// `accel`, `gyro` or `mag`.
        sensor: String,
    },
    /// Calibrated in both, from different input units (`counts` or the nominal unit).
    InputUnitChanged {
        /// `accel`, `gyro` or `mag`.
        sensor: String,
        /// The previous record's input unit.
        before: String,
        /// This record's.
        after: String,
    },
}

impl SensorChange {
    /// The change in words, e.g. "gyro now calibrated".
    pub fn sentence(&self) -> String {
        match self {
            Self::NowFitted { sensor } => format!("{sensor} now calibrated"),
            Self::NoLongerFitted { sensor } => format!("{sensor} no longer calibrated"),
            Self::InputUnitChanged {
                sensor,
                before,
                after,
            } => format!(
                "{sensor} fitted from {after} instead of {before} (its parameters are in other \
                 units, not compared)"
            ),
        }
    }

    fn sensor(&self) -> &str {
        match self {
            Self::NowFitted { sensor }
            | Self::NoLongerFitted { sensor }
            | Self::InputUnitChanged { sensor, .. } => sensor,
        }
    }
}

/// The input unit of `sensor` in `record`: `counts`, or `nominal` (m/s², rad/s or µT).
fn input_unit<'a>(record: &'a StoredRecord, sensor: &str) -> &'a str {
    record
        .record
        .params
        .non_nominal_inputs()
        .into_iter()
        .find(|(s, _)| *s == sensor)
        .map_or("nominal units", |(_, unit)| unit)
}

/// The sensors whose calibration changed in kind between `before` and `after`.
fn sensor_changes(before: &StoredRecord, after: &StoredRecord) -> Vec<SensorChange> {
    let (was, now) = (
        before.record.params.fitted_sensors(),
        after.record.params.fitted_sensors(),
    );
    ["accel", "gyro", "mag"]
        .into_iter()
        .filter_map(|sensor| {
            let sensor_name = sensor.to_string();
            match (was.contains(&sensor), now.contains(&sensor)) {
                (false, true) => Some(SensorChange::NowFitted {
                    sensor: sensor_name,
                }),
                (true, false) => Some(SensorChange::NoLongerFitted {
                    sensor: sensor_name,
                }),
                (true, true) => {
                    let (unit_before, unit_after) =
                        (input_unit(before, sensor), input_unit(after, sensor));
                    (unit_before != unit_after).then(|| SensorChange::InputUnitChanged {
                        sensor: sensor_name,
                        before: unit_before.to_string(),
                        after: unit_after.to_string(),
                    })
                }
                (false, false) => None,
            }
        })
        .collect()
}

/// `records` (oldest first, any devices) with each one's changes since the set the same device
/// held before it (its latest earlier record that was written to the board).
pub fn device_changes(records: Vec<StoredRecord>) -> Vec<RecordChanges> {
    #[derive(Default)]
    struct Board {
        on_board: Option<StoredRecord>,
        not_written: Vec<RecordId>,
    }
    let mut boards: BTreeMap<String, Board> = BTreeMap::new();
    let mut out = Vec::with_capacity(records.len());
    for stored in records {
        let board = boards.entry(stored.record.device_id.clone()).or_default();
        let before = board.on_board.as_ref();
        let sensors = before
            .map(|b| sensor_changes(b, &stored))
            .unwrap_or_default();
        let changes = before
            .map(|b| parameter_changes(b, &stored, &sensors))
            .unwrap_or_default();
        let previous = before.map(|b| b.id);
        let not_written_between = board.not_written.clone();
        if stored.record.board.on_board() {
            board.on_board = Some(stored.clone());
            board.not_written.clear();
        } else {
            board.not_written.push(stored.id);
        }
        out.push(RecordChanges {
            previous,
            not_written_between,
            stored,
            changes,
            sensor_changes: sensors,
        });
    }
    out
}

/// The changes of the parameters both records have, leaving out the sensors of `sensors`
/// (their units differ).
fn parameter_changes(
    before: &StoredRecord,
    after: &StoredRecord,
    sensors: &[SensorChange],
) -> Vec<ParameterChange> {
    let old = before.record.parameters();
    let mut changes: Vec<ParameterChange> = after
        .record
        .parameters()
        .into_iter()
        .filter(|(parameter, _)| {
            let sensor = parameter.split('.').next().unwrap_or("");
            !sensors.iter().any(|c| c.sensor() == sensor)
        })
        .filter_map(|(parameter, now)| {
            let was = *old.get(&parameter)?;
            let sigma = match (
                before.record.sigma.get(&parameter),
                after.record.sigma.get(&parameter),
            ) {
                (Some(a), Some(b)) => Some(a.hypot(*b)).filter(|s| *s > 0.0),
                _ => None,
            };
            Some(ParameterChange {
                change: now - was,
                change_sigma: sigma.map(|s| (now - was) / s),
                before: was,
                after: now,
                parameter,
            })
        })
        .collect();
    // Those with a σ by its multiple; those without (a fit that gave none) after them, by
    // their relative size, so that a 5 % gain change is not listed after a change of 1e-9.
    changes.sort_by(|a, b| match (a.change_sigma, b.change_sigma) {
        (Some(x), Some(y)) => y.abs().total_cmp(&x.abs()),
        (Some(_), None) => std::cmp::Ordering::Less,
        (None, Some(_)) => std::cmp::Ordering::Greater,
        (None, None) => b.relative().total_cmp(&a.relative()),
    });
    changes
}
