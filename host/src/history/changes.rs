//! How a board's parameters moved between consecutive calibrations, in units of the combined
//! one-sigma uncertainty of both fits: `(x₂ − x₁) / √(σ₁² + σ₂²)`. A change of a few σ is within
//! what two honest fits of the same board disagree by; tens of σ mean the board changed (a
//! knock, re-soldering, a new magnetised part) or one of the fits was poor.

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

/// One record of a board with its changes since the board's previous record.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RecordChanges {
    /// The record.
    #[serde(flatten)]
    pub stored: StoredRecord,
    /// The previous record of the same board, if any.
    pub previous: Option<RecordId>,
    /// Every parameter both records have, largest change in σ first (then unscaled ones).
    pub changes: Vec<ParameterChange>,
}

/// `records` (oldest first, any devices) with each one's changes since the same device's
/// previous record.
pub fn device_changes(records: Vec<StoredRecord>) -> Vec<RecordChanges> {
    let mut previous: BTreeMap<String, StoredRecord> = BTreeMap::new();
    let mut out = Vec::with_capacity(records.len());
    for stored in records {
        let before = previous.insert(stored.record.device_id.clone(), stored.clone());
        let changes = before
            .as_ref()
            .map(|b| parameter_changes(b, &stored))
            .unwrap_or_default();
        out.push(RecordChanges {
            previous: before.map(|b| b.id),
            stored,
            changes,
        });
    }
    out
}

fn parameter_changes(before: &StoredRecord, after: &StoredRecord) -> Vec<ParameterChange> {
    let old = before.record.parameters();
    let mut changes: Vec<ParameterChange> = after
        .record
        .parameters()
        .into_iter()
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
    changes.sort_by(|a, b| {
        let key = |c: &ParameterChange| c.change_sigma.map_or(-1.0, f64::abs);
        key(b).total_cmp(&key(a))
    });
    changes
}
