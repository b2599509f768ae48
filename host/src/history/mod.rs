//! The calibration history of a production line: every calibration of every board, kept
//! append-only, compared over time (per board) and across boards (the fleet).
//!
//! Storage is SQLite (a file per station, by default `$XDG_DATA_HOME/imucal/history.sqlite`) or
//! a PostgreSQL server shared by several stations. Both run the same SQL text through one
//! [`schema::Backend`] trait ([`schema`] holds the table, its migration and the statements); only
//! the key column and the append-only triggers are written per dialect.
//!
//! Crates: `rusqlite` (SQLite compiled in, no system library) and the synchronous `postgres`
//! client. `sqlx`'s `Any` driver would give one connection type, but it needs an async runtime
//! in a tool that is otherwise synchronous and builds several times longer (macros, both
//! drivers' async stacks, TLS); the two small synchronous clients behind one trait give the
//! same single code path for the store's logic at a fraction of the build.
//!
//! Append-only: the store has no update or delete, and the database refuses them too (triggers
//! that abort `UPDATE`, `DELETE` and, on PostgreSQL, `TRUNCATE`). A failed write returns a
//! [`HistoryError`] for the caller to report; callers save the session directory or parameter
//! file first, so a calibration is never lost with the database.

pub mod changes;
pub mod fleet;
pub mod location;
pub mod part_limits;
pub mod plot;
pub mod postgres;
pub mod record;
pub mod schema;
pub mod sqlite;
pub mod stats;
pub mod store;

pub use changes::{device_changes, ParameterChange, RecordChanges, SensorChange};
pub use fleet::{
    fleet_report, is_outlier_against_fleet, Finding, FleetCheck, FleetError, FleetOptions,
    FleetReport,
};
pub use location::{DbLocation, DB_ENV};
pub use record::{
    BoardWrite, CalibrationRecord, RecordSource, RecordVerdict, TemperatureSpan,
    RECORDING_DEVICE_PREFIX,
};
pub use store::{record_calibration, HistoryStore, RecordId, StoredRecord};

/// Why the history could not be opened, written or read.
#[derive(Debug, thiserror::Error)]
pub enum HistoryError {
    /// The `--db` value is not a database URL.
    #[error("`{url}` is not a history database: {why}; use a file path, sqlite://PATH or postgres://user@host/db (add ?host=/socket/dir&port=N for a Unix socket)")]
    BadUrl {
        /// The URL (password hidden).
        url: String,
        /// What is wrong.
        why: String,
    },
    /// No data directory for the default database.
    #[error("neither XDG_DATA_HOME nor HOME is set, so there is no default history database; pass --db sqlite://PATH")]
    NoDataDir,
    /// The directory of the SQLite file could not be created.
    #[error("cannot create the history directory `{path}` ({cause}); check its permissions or pass --db sqlite://PATH elsewhere")]
    CreateDir {
        /// The directory.
        path: String,
        /// The operating system's error.
        cause: std::io::Error,
    },
    /// The database could not be opened or its schema created.
    #[error("cannot open the history database {location}: {cause}; check the URL, that the server is running and that this user may connect and create tables")]
    Open {
        /// The database.
        location: String,
        /// The database's message.
        cause: String,
    },
    /// A command that only reads found no SQLite file where the history should be.
    #[error("there is no history database at `{path}`: nothing has been recorded there yet (`imucal calibrate`, `imucal flash` and `imucal fit --params-out` record into it); pass --db, or set IMUCAL_DB, to name the database your station records into")]
    Missing {
        /// The file looked for.
        path: String,
    },
    /// The database was created by a newer imucal.
    #[error("the history database {location} has schema version {found}, this imucal knows up to {known}; update imucal on this station")]
    NewerSchema {
        /// The database.
        location: String,
        /// Version found.
        found: i64,
        /// Newest version this build knows.
        known: i64,
    },
    /// A record could not be written.
    #[error("the calibration was not recorded in the history database {location}: {cause}; the session directory or parameter file still holds it, record it again once the database is reachable")]
    Write {
        /// The database.
        location: String,
        /// The database's message.
        cause: String,
    },
    /// Records could not be read.
    #[error("cannot read the history database {location}: {cause}")]
    Read {
        /// The database.
        location: String,
        /// The database's message.
        cause: String,
    },
    /// A stored record cannot be understood.
    #[error("history record {id} is damaged ({what}); it was written by another program or edited by hand")]
    Corrupt {
        /// The record's key.
        id: i64,
        /// What is wrong.
        what: String,
    },
}
