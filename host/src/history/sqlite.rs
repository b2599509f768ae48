//! The SQLite connection (rusqlite, with SQLite compiled in so no system library is needed).
//! Several processes may write one file: WAL journal and a generous busy timeout make each
//! insert wait for the others instead of failing.

use std::path::Path;
use std::time::{Duration, Instant};

use rusqlite::types::Value;
use rusqlite::{Connection, ErrorCode, TransactionBehavior};

use super::schema::{self, Backend, Dialect, SqlValue, SCHEMA_VERSION, VERSION_TABLE};

/// How long a write waits for other writers before giving up.
const BUSY_TIMEOUT: Duration = Duration::from_secs(30);

/// A SQLite history file.
pub struct SqliteBackend {
    connection: Connection,
}

fn failed(cause: rusqlite::Error) -> String {
    cause.to_string()
}

impl SqliteBackend {
    /// Open (creating when missing) the file at `path`.
    pub fn open(path: &Path) -> Result<Self, String> {
        let connection = Connection::open(path).map_err(failed)?;
        connection.busy_timeout(BUSY_TIMEOUT).map_err(failed)?;
        set_wal_journal(&connection)?;
        Ok(Self { connection })
    }
}

/// Switch to the WAL journal (readers run while one process writes). The switch takes an
/// exclusive lock without going through the busy handler, so several stations opening a new
/// file together see "database is locked" here: wait and retry as the busy timeout would.
fn set_wal_journal(connection: &Connection) -> Result<(), String> {
    let start = Instant::now();
    let mut pause = Duration::from_millis(2);
    loop {
        // The answer row is the mode set; a file system without WAL keeps its own, which works.
        match connection.query_row("PRAGMA journal_mode=WAL", [], |_| Ok(())) {
            Ok(()) => return Ok(()),
            Err(e)
                if matches!(
                    e.sqlite_error_code(),
                    Some(ErrorCode::DatabaseBusy | ErrorCode::DatabaseLocked)
                ) && start.elapsed() < BUSY_TIMEOUT =>
            {
                std::thread::sleep(pause);
                pause = (pause * 2).min(Duration::from_millis(100));
            }
            Err(e) => return Err(failed(e)),
        }
    }
}

fn to_value(value: &SqlValue) -> Value {
    match value {
        SqlValue::Text(t) => Value::Text(t.clone()),
        SqlValue::Int(i) => Value::Integer(*i),
        SqlValue::Null => Value::Null,
    }
}

fn from_value(value: Value) -> SqlValue {
    match value {
        Value::Text(t) => SqlValue::Text(t),
        Value::Integer(i) => SqlValue::Int(i),
        Value::Null => SqlValue::Null,
        // Never written by this schema; shown as text so the row error names it.
        Value::Real(r) => SqlValue::Text(r.to_string()),
        Value::Blob(b) => SqlValue::Text(format!("<{} bytes>", b.len())),
    }
}

impl Backend for SqliteBackend {
    fn migrate(&mut self) -> Result<i64, String> {
        // IMMEDIATE takes the write lock first, so two processes never both create the schema.
        let tx = self
            .connection
            .transaction_with_behavior(TransactionBehavior::Immediate)
            .map_err(failed)?;
        tx.execute(
            &format!("CREATE TABLE IF NOT EXISTS {VERSION_TABLE} (version BIGINT NOT NULL)"),
            [],
        )
        .map_err(failed)?;
        let found: i64 = tx
            .query_row(
                &format!("SELECT COALESCE(MAX(version), 0) FROM {VERSION_TABLE}"),
                [],
                |row| row.get(0),
            )
            .map_err(failed)?;
        if found < SCHEMA_VERSION {
            for statement in schema::upgrade_statements(found, Dialect::Sqlite) {
                tx.execute(&statement, []).map_err(failed)?;
            }
            tx.execute(
                &format!("INSERT INTO {VERSION_TABLE} (version) VALUES ($1)"),
                [SCHEMA_VERSION],
            )
            .map_err(failed)?;
        }
        tx.commit().map_err(failed)?;
        Ok(found)
    }

    fn insert(&mut self, row: &[SqlValue]) -> Result<i64, String> {
        let values = row.iter().map(to_value);
        self.connection
            .query_row(
                &schema::insert_sql(),
                rusqlite::params_from_iter(values),
                |r| r.get(0),
            )
            .map_err(failed)
    }

    fn select(&mut self, device: Option<&str>) -> Result<Vec<Vec<SqlValue>>, String> {
        let mut statement = self
            .connection
            .prepare(&schema::select_sql())
            .map_err(failed)?;
        let width = statement.column_count();
        let rows = statement
            .query_map([device], |r| {
                (0..width)
                    .map(|i| r.get::<_, Value>(i).map(from_value))
                    .collect::<Result<Vec<_>, _>>()
            })
            .map_err(failed)?;
        rows.collect::<Result<Vec<_>, _>>().map_err(failed)
    }
}
