//! The append-only store: one code path over either database. It can add a record and read
//! records back; there is deliberately no way to change or remove one.

use serde::Serialize;

use super::location::DbLocation;
use super::postgres::PostgresBackend;
use super::record::CalibrationRecord;
use super::schema::{self, Backend, SCHEMA_VERSION};
use super::sqlite::SqliteBackend;
use super::HistoryError;

/// Key of a stored record.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
pub struct RecordId(pub i64);

impl std::fmt::Display for RecordId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.0)
    }
}

/// A record as read back, with its key.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StoredRecord {
    /// The key (increasing in insertion order).
    pub id: RecordId,
    /// The record.
    #[serde(flatten)]
    pub record: CalibrationRecord,
}

/// An open history database.
pub struct HistoryStore {
    location: DbLocation,
    backend: Box<dyn Backend>,
}

impl HistoryStore {
    /// Open the database at `location`, creating the SQLite file (and its directory) or the
    /// schema when missing.
    pub fn open(location: &DbLocation) -> Result<Self, HistoryError> {
        let shown = location.display();
        let open_failed = |cause: String| HistoryError::Open {
            location: shown.clone(),
            cause,
        };
        let mut backend: Box<dyn Backend> = match location {
            DbLocation::Sqlite(path) => {
                if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                    std::fs::create_dir_all(dir).map_err(|cause| HistoryError::CreateDir {
                        path: dir.display().to_string(),
                        cause,
                    })?;
                }
                Box::new(SqliteBackend::open(path).map_err(open_failed)?)
            }
            DbLocation::Postgres(url) => Box::new(PostgresBackend::open(url).map_err(open_failed)?),
        };
        let found = backend.migrate().map_err(open_failed)?;
        if found > SCHEMA_VERSION {
            return Err(HistoryError::NewerSchema {
                location: shown,
                found,
                known: SCHEMA_VERSION,
            });
        }
        Ok(Self {
            location: location.clone(),
            backend,
        })
    }

    /// Open `--db URL` (or `$IMUCAL_DB`, or the default file).
    pub fn open_url(url: Option<&str>) -> Result<Self, HistoryError> {
        Self::open(&DbLocation::resolve(url)?)
    }

    /// Open `--db URL` (or `$IMUCAL_DB`, or the default file) to read it: a SQLite file that
    /// does not exist is refused ([`HistoryError::Missing`]), not created empty, so a mistyped
    /// path says so instead of showing an empty history and leaving a stray file behind.
    pub fn open_existing_url(url: Option<&str>) -> Result<Self, HistoryError> {
        let location = DbLocation::resolve(url)?;
        if let DbLocation::Sqlite(path) = &location {
            // A path that cannot be checked (permissions) goes on to `open`, which names why.
            if matches!(path.try_exists(), Ok(false)) {
                return Err(HistoryError::Missing {
                    path: path.display().to_string(),
                });
            }
        }
        Self::open(&location)
    }

    /// Where this store is.
    pub fn location(&self) -> &DbLocation {
        &self.location
    }

    /// Append `record`. Refuses a record with a value that is not a finite number (or a
    /// parameter set no board could hold), so the history never holds one.
    pub fn record(&mut self, record: &CalibrationRecord) -> Result<RecordId, HistoryError> {
        let refused = |cause: String| HistoryError::Write {
            location: self.location.display(),
            cause,
        };
        if let Some((name, value)) = record.non_finite() {
            return Err(refused(format!("{name} is {value}, not a finite number")));
        }
        record
            .params
            .to_calibration_set("the parameter set")
            .map_err(|e| refused(e.to_string()))?;
        self.backend
            .insert(&schema::to_row(record))
            .map(RecordId)
            .map_err(|cause| HistoryError::Write {
                location: self.location.display(),
                cause,
            })
    }

    /// Every record (of `device`, if given), oldest first.
    pub fn records(&mut self, device: Option<&str>) -> Result<Vec<StoredRecord>, HistoryError> {
        let rows = self
            .backend
            .select(device)
            .map_err(|cause| HistoryError::Read {
                location: self.location.display(),
                cause,
            })?;
        rows.into_iter()
            .map(|row| {
                schema::from_row(row).map(|(id, record)| StoredRecord {
                    id: RecordId(id),
                    record,
                })
            })
            .collect()
    }

    /// The newest record of every device: the fleet as it is now.
    pub fn latest_per_device(&mut self) -> Result<Vec<StoredRecord>, HistoryError> {
        let mut latest: std::collections::BTreeMap<String, StoredRecord> = Default::default();
        for stored in self.records(None)? {
            // Records come oldest first, so the last one seen per device wins.
            latest.insert(stored.record.device_id.clone(), stored);
        }
        Ok(latest.into_values().collect())
    }
}

/// Record `record` in the database named by `url` (or the default). A failure is returned for
/// the caller to report; the caller has already saved the calibration elsewhere (the session
/// directory or parameter file), so nothing is lost.
pub fn record_calibration(
    url: Option<&str>,
    record: &CalibrationRecord,
) -> Result<(RecordId, DbLocation), HistoryError> {
    let mut store = HistoryStore::open_url(url)?;
    let id = store.record(record)?;
    Ok((id, store.location.clone()))
}
