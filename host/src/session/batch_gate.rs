//! The write gate of a batch: every board's fit waits here before it is written, so that each
//! board can be compared with the fleet in the history store and, when that fleet is too small
//! for the robust test, with the other boards of the same batch (leave-one-out, the same
//! median/MAD test of [`crate::history::fleet`]: with few boards it pools the spread over a
//! sensor's axes of one kind, and its threshold widens with fewer values; seven other boards
//! are the fewest it tests with).
//!
//! With neither (a new line's first, small batch), each board is held to the bounds of every
//! common part's datasheet ([`crate::history::part_limits`]), which catch gross faults only.
//!
//! Boards that fail before their fit ("depart") do not hold the others; a board that never comes
//! (hung link) is waited for at most [`WriteGate::new`]'s timeout, after which the boards present
//! are compared as they are.

use std::sync::{Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use serde::Serialize;

use crate::history::fleet::{count_boards, FleetModel};
use crate::history::part_limits::beyond_part_limits;
use crate::history::{
    is_outlier_against_fleet, CalibrationRecord, Finding, FleetCheck, FleetOptions, HistoryStore,
};

/// What a board was compared with before its parameters were written.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum OutlierBasis {
    /// The boards in the history store.
    Fleet,
    /// The other boards of this batch (the fleet was too small).
    Batch,
    /// Neither was possible: the bounds of every common part's datasheet
    /// ([`crate::history::part_limits`]).
    PartLimits,
    /// No test was possible; `note` says why.
    None,
}

/// The outlier test of one board before its write.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OutlierCheck {
    /// What the board was compared with.
    pub basis: OutlierBasis,
    /// The test (`tested` false when none was possible; its note says why).
    #[serde(flatten)]
    pub check: FleetCheck,
}

/// Settings of the gate.
#[derive(Debug, Clone)]
pub struct GateOptions {
    /// History database URL (`None`: the default store).
    pub db: Option<String>,
    /// The fleet test's settings.
    pub fleet: FleetOptions,
    /// Longest wait for the slowest board's fit.
    pub timeout: Duration,
}

#[derive(Default)]
struct GateState {
    records: Vec<Option<CalibrationRecord>>,
    departed: Vec<bool>,
    checks: Option<Vec<Option<OutlierCheck>>>,
}

/// The gate shared by a batch's board threads.
pub struct WriteGate {
    options: GateOptions,
    state: Mutex<GateState>,
    changed: Condvar,
}

impl WriteGate {
    /// A gate for `boards` boards.
    pub fn new(boards: usize, options: GateOptions) -> Self {
        Self {
            options,
            state: Mutex::new(GateState {
                records: vec![None; boards],
                departed: vec![false; boards],
                checks: None,
            }),
            changed: Condvar::new(),
        }
    }

    fn lock(&self) -> MutexGuard<'_, GateState> {
        // A board thread that panicked holds no invariant of the state: keep going.
        self.state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Board `index` has no fit and will not come (its session failed).
    pub fn depart(&self, index: usize) {
        let mut state = self.lock();
        if let Some(d) = state.departed.get_mut(index) {
            *d = true;
        }
        self.changed.notify_all();
    }

    /// Board `index` presents `record` (its fit, not yet written) and waits for the others; the
    /// result is its outlier test.
    pub fn arrive(&self, index: usize, record: CalibrationRecord) -> OutlierCheck {
        let deadline = Instant::now() + self.options.timeout;
        let mut state = self.lock();
        if let Some(slot) = state.records.get_mut(index) {
            *slot = Some(record);
        }
        self.changed.notify_all();
        while state.checks.is_none() && !all_in(&state) {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                break;
            }
            state = self
                .changed
                .wait_timeout(state, left)
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .0;
        }
        if state.checks.is_none() {
            let checks = self.check_all(&state.records);
            state.checks = Some(checks);
            self.changed.notify_all();
        }
        state
            .checks
            .as_ref()
            .and_then(|c| c.get(index).cloned().flatten())
            .unwrap_or_else(|| untested("this board's fit did not reach the test".into()))
    }

    fn check_all(&self, records: &[Option<CalibrationRecord>]) -> Vec<Option<OutlierCheck>> {
        let present: Vec<&CalibrationRecord> = records.iter().flatten().collect();
        let mut store = HistoryStore::open_url(self.options.db.as_deref());
        records
            .iter()
            .map(|record| {
                let record = record.as_ref()?;
                let fleet = match &mut store {
                    Ok(store) => is_outlier_against_fleet(record, store, &self.options.fleet)
                        .map_err(|e| e.to_string()),
                    Err(e) => Err(e.to_string()),
                };
                Some(match fleet {
                    Ok(check) if check.tested => OutlierCheck {
                        basis: OutlierBasis::Fleet,
                        check,
                    },
                    Ok(check) => self.within_batch(record, &present, check.note),
                    Err(why) => self.within_batch(record, &present, Some(why)),
                })
            })
            .collect()
    }

    /// Leave-one-out comparison with the other boards of the batch, or why none was made.
    fn within_batch(
        &self,
        record: &CalibrationRecord,
        present: &[&CalibrationRecord],
        fleet_note: Option<String>,
    ) -> OutlierCheck {
        let others: Vec<&CalibrationRecord> = present
            .iter()
            .copied()
            .filter(|r| r.device_id != record.device_id)
            .collect();
        let fleet_note = fleet_note.unwrap_or_else(|| "no fleet test".into());
        match FleetModel::fit(&others, &self.options.fleet) {
            Ok(model) => {
                let findings = model.outlying(record);
                OutlierCheck {
                    basis: OutlierBasis::Batch,
                    check: FleetCheck {
                        tested: true,
                        outlier: !findings.is_empty(),
                        fleet_boards: others.len(),
                        threshold_z: model.threshold_z(),
                        findings,
                        note: Some(format!(
                            "fleet too small ({fleet_note}); compared with the other {} of \
                             this batch",
                            count_boards(others.len())
                        )),
                    },
                }
            }
            Err(why) => held_to_part_limits(
                record,
                format!("no fleet test was possible: {fleet_note}; nor within the batch: {why}"),
            ),
        }
    }
}

/// A board with nothing to be compared with, held to the bounds of every common part's
/// datasheet: a gross fault is not written on the first boards of a line.
fn held_to_part_limits(record: &CalibrationRecord, why_not_compared: String) -> OutlierCheck {
    // Findings that only warn (a magnet by the magnetometer) lower the verdict instead.
    let findings: Vec<Finding> = beyond_part_limits(record)
        .into_iter()
        .filter(|f| f.refuses)
        .map(|f| Finding {
            likely_cause: f.phrase(),
            fleet_median: f.kind.nominal(),
            // In units of the bound: 1 is at it.
            robust_z: f.times_limit(),
            threshold_z: 1.0,
            parameter: f.parameter,
            value: f.value,
        })
        .collect();
    OutlierCheck {
        basis: OutlierBasis::PartLimits,
        check: FleetCheck {
            tested: true,
            outlier: !findings.is_empty(),
            fleet_boards: 0,
            threshold_z: 1.0,
            findings,
            note: Some(format!(
                "{why_not_compared}; held to the bounds of every common part's datasheet \
                 instead (accelerometer offset and gain, gyroscope offset, magnetometer offset \
                 against its range), which catch gross faults only"
            )),
        },
    }
}

fn all_in(state: &GateState) -> bool {
    state
        .records
        .iter()
        .zip(&state.departed)
        .all(|(record, departed)| record.is_some() || *departed)
}

fn untested(note: String) -> OutlierCheck {
    OutlierCheck {
        basis: OutlierBasis::None,
        check: FleetCheck {
            tested: false,
            outlier: false,
            fleet_boards: 0,
            threshold_z: 0.0,
            findings: Vec::new(),
            note: Some(note),
        },
    }
}
