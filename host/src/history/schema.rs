//! The history's table, its migrations and the SQL both databases run. The statements are the
//! same text for SQLite and PostgreSQL (`$N` parameters, `CAST`, `RETURNING`); only the key
//! column and the append-only triggers differ per dialect.

use super::record::{BoardWrite, CalibrationRecord, RecordSource};
use super::HistoryError;
use crate::device::ParamsFile;

/// The table of calibrations.
pub const TABLE: &str = "imucal_calibrations";

/// A value bound to or read from a statement.
#[derive(Debug, Clone, PartialEq)]
pub enum SqlValue {
    /// Text.
    Text(String),
    /// 64-bit integer.
    Int(i64),
    /// SQL `NULL` (only in nullable text columns).
    Null,
}

/// Column types used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ColumnKind {
    /// `TEXT NOT NULL`.
    Text,
    /// `TEXT` (nullable).
    OptText,
    /// `BIGINT NOT NULL`.
    Int,
}

/// The data columns in storage order (the key `id` comes first in every `SELECT`).
pub const COLUMNS: [(&str, ColumnKind); 16] = [
    ("device_id", ColumnKind::Text),
    ("recorded_unix_ms", ColumnKind::Int),
    ("tool_version", ColumnKind::Text),
    ("firmware_version", ColumnKind::OptText),
    ("source", ColumnKind::Text),
    ("params_crc", ColumnKind::Int),
    ("params_json", ColumnKind::Text),
    ("sigma_json", ColumnKind::Text),
    ("residuals_json", ColumnKind::Text),
    ("noise_json", ColumnKind::Text),
    ("temperatures_json", ColumnKind::OptText),
    ("verdict_json", ColumnKind::OptText),
    ("operator", ColumnKind::OptText),
    ("station", ColumnKind::OptText),
    ("verdict_level", ColumnKind::OptText),
    // Schema version 2.
    ("board_write_json", ColumnKind::OptText),
];

/// Columns of schema version 1 (the first of [`COLUMNS`]).
const COLUMNS_V1: usize = 15;

/// What a database connection must do; both databases run the statements of
/// this module, so the store's logic is shared. Errors are the database's message.
pub trait Backend {
    /// Create or upgrade the schema; returns the version found before.
    fn migrate(&mut self) -> Result<i64, String>;
    /// Insert one row in [`COLUMNS`] order; returns its key.
    fn insert(&mut self, row: &[SqlValue]) -> Result<i64, String>;
    /// Every row (`id` first), or those of one device, oldest first.
    fn select(&mut self, device: Option<&str>) -> Result<Vec<Vec<SqlValue>>, String>;
}

/// Which SQL dialect a migration is written for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dialect {
    /// SQLite 3.35 or later.
    Sqlite,
    /// PostgreSQL 11 or later.
    Postgres,
}

/// Schema version this build writes and reads.
pub const SCHEMA_VERSION: i64 = 2;

/// The statements that create schema version 1 in `dialect`.
pub fn migration_v1(dialect: Dialect) -> Vec<String> {
    let key = match dialect {
        Dialect::Sqlite => "id INTEGER PRIMARY KEY AUTOINCREMENT",
        Dialect::Postgres => "id BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY",
    };
    let columns: Vec<String> = COLUMNS[..COLUMNS_V1]
        .iter()
        .map(|(name, kind)| {
            let ty = match kind {
                ColumnKind::Text => "TEXT NOT NULL",
                ColumnKind::OptText => "TEXT",
                ColumnKind::Int => "BIGINT NOT NULL",
            };
            format!("{name} {ty}")
        })
        .collect();
    let mut statements = vec![
        format!(
            "CREATE TABLE IF NOT EXISTS {TABLE} ({key}, {})",
            columns.join(", ")
        ),
        format!(
            "CREATE INDEX IF NOT EXISTS {TABLE}_device ON {TABLE} (device_id, recorded_unix_ms)"
        ),
    ];
    // Append-only: the database itself refuses to change or remove a record.
    let refusal = "the calibration history is append-only";
    match dialect {
        Dialect::Sqlite => {
            for action in ["UPDATE", "DELETE"] {
                statements.push(format!(
                    "CREATE TRIGGER IF NOT EXISTS {TABLE}_no_{} BEFORE {action} ON {TABLE} \
                     BEGIN SELECT RAISE(ABORT, '{refusal}'); END",
                    action.to_lowercase()
                ));
            }
        }
        Dialect::Postgres => {
            statements.push(format!(
                "CREATE OR REPLACE FUNCTION {TABLE}_refuse() RETURNS trigger LANGUAGE plpgsql AS \
                 $$ BEGIN RAISE EXCEPTION '{refusal}'; END $$"
            ));
            statements.push(format!(
                "CREATE TRIGGER {TABLE}_no_change BEFORE UPDATE OR DELETE ON {TABLE} \
                 FOR EACH ROW EXECUTE FUNCTION {TABLE}_refuse()"
            ));
            statements.push(format!(
                "CREATE TRIGGER {TABLE}_no_truncate BEFORE TRUNCATE ON {TABLE} \
                 FOR EACH STATEMENT EXECUTE FUNCTION {TABLE}_refuse()"
            ));
        }
    }
    statements
}

/// The statements that upgrade schema version 1 to 2: whether each set went onto its board.
pub fn migration_v2() -> Vec<String> {
    vec![format!(
        "ALTER TABLE {TABLE} ADD COLUMN {} TEXT",
        COLUMNS[COLUMNS_V1].0
    )]
}

/// The statements that bring a database at schema version `found` (0: empty) to
/// [`SCHEMA_VERSION`], in order; none when it is there already.
pub fn upgrade_statements(found: i64, dialect: Dialect) -> Vec<String> {
    let mut statements = Vec::new();
    if found < 1 {
        statements.extend(migration_v1(dialect));
    }
    if found < 2 {
        statements.extend(migration_v2());
    }
    statements
}

/// The table holding the schema version.
pub const VERSION_TABLE: &str = "imucal_schema_version";

/// `INSERT … RETURNING id` of one record.
pub fn insert_sql() -> String {
    let names: Vec<&str> = COLUMNS.iter().map(|(name, _)| *name).collect();
    let params: Vec<String> = (1..=COLUMNS.len()).map(|i| format!("${i}")).collect();
    format!(
        "INSERT INTO {TABLE} ({}) VALUES ({}) RETURNING id",
        names.join(", "),
        params.join(", ")
    )
}

/// `SELECT id, …` of every record, or of the device given as `$1`, oldest first.
pub fn select_sql() -> String {
    let names: Vec<&str> = COLUMNS.iter().map(|(name, _)| *name).collect();
    format!(
        "SELECT id, {} FROM {TABLE} WHERE (CAST($1 AS TEXT) IS NULL OR device_id = $1) \
         ORDER BY recorded_unix_ms, id",
        names.join(", ")
    )
}

fn json<T: serde::Serialize>(value: &T) -> String {
    // Serialising these plain data types cannot fail; an empty object keeps the row valid.
    serde_json::to_string(value).unwrap_or_else(|_| "{}".into())
}

fn opt_text(value: Option<String>) -> SqlValue {
    value.map_or(SqlValue::Null, SqlValue::Text)
}

/// The values of `record` in [`COLUMNS`] order.
pub fn to_row(record: &CalibrationRecord) -> Vec<SqlValue> {
    vec![
        SqlValue::Text(record.device_id.clone()),
        SqlValue::Int(record.recorded_unix_ms),
        SqlValue::Text(record.tool_version.clone()),
        opt_text(record.firmware_version.clone()),
        SqlValue::Text(record.source.as_str().into()),
        SqlValue::Int(i64::from(record.params_crc)),
        SqlValue::Text(record.params.to_json()),
        SqlValue::Text(json(&record.sigma)),
        SqlValue::Text(json(&record.residuals)),
        SqlValue::Text(json(&record.noise)),
        opt_text(record.temperatures.as_ref().map(json)),
        opt_text(record.verdict.as_ref().map(json)),
        opt_text(record.operator.clone()),
        opt_text(record.station.clone()),
        opt_text(record.verdict.as_ref().map(|v| v.level.clone())),
        SqlValue::Text(json(&record.board)),
    ]
}

/// Reads the columns of one row in order, naming the column in any error.
struct RowReader {
    id: i64,
    values: std::vec::IntoIter<SqlValue>,
}

impl RowReader {
    fn next(&mut self, name: &str) -> Result<SqlValue, HistoryError> {
        self.values
            .next()
            .ok_or_else(|| corrupt(self.id, format!("column {name} is missing")))
    }

    fn opt_text(&mut self, name: &str) -> Result<Option<String>, HistoryError> {
        match self.next(name)? {
            SqlValue::Text(t) => Ok(Some(t)),
            SqlValue::Null => Ok(None),
            SqlValue::Int(i) => Err(corrupt(self.id, format!("{name} is the number {i}"))),
        }
    }

    fn text(&mut self, name: &str) -> Result<String, HistoryError> {
        self.opt_text(name)?
            .ok_or_else(|| corrupt(self.id, format!("{name} is NULL")))
    }

    fn int(&mut self, name: &str) -> Result<i64, HistoryError> {
        match self.next(name)? {
            SqlValue::Int(i) => Ok(i),
            other => Err(corrupt(
                self.id,
                format!("{name} is {other:?}, not a number"),
            )),
        }
    }

    fn json<T: serde::de::DeserializeOwned>(&mut self, name: &str) -> Result<T, HistoryError> {
        let text = self.text(name)?;
        serde_json::from_str(&text).map_err(|e| corrupt(self.id, format!("{name}: {e}")))
    }

    fn opt_json<T: serde::de::DeserializeOwned>(
        &mut self,
        name: &str,
    ) -> Result<Option<T>, HistoryError> {
        let id = self.id;
        self.opt_text(name)?
            .map(|text| {
                serde_json::from_str(&text).map_err(|e| corrupt(id, format!("{name}: {e}")))
            })
            .transpose()
    }
}

/// A row read back (`id` first, then [`COLUMNS`]) as the record id and the record.
pub fn from_row(values: Vec<SqlValue>) -> Result<(i64, CalibrationRecord), HistoryError> {
    let mut values = values.into_iter();
    let id = match values.next() {
        Some(SqlValue::Int(id)) => id,
        other => return Err(corrupt(0, format!("the key is {other:?}"))),
    };
    let mut row = RowReader { id, values };
    let device_id = row.text("device_id")?;
    let recorded_unix_ms = row.int("recorded_unix_ms")?;
    let tool_version = row.text("tool_version")?;
    let firmware_version = row.opt_text("firmware_version")?;
    let source_name = row.text("source")?;
    let source = RecordSource::parse(&source_name)
        .ok_or_else(|| corrupt(id, format!("unknown source `{source_name}`")))?;
    let params_crc = u32::try_from(row.int("params_crc")?)
        .map_err(|_| corrupt(id, "params_crc is not a 32-bit CRC".into()))?;
    let params_text = row.text("params_json")?;
    let params = ParamsFile::from_json(&params_text, &format!("history record {id}"))
        .map_err(|e| corrupt(id, e.to_string()))?;
    let sigma = row.json("sigma_json")?;
    let residuals = row.json("residuals_json")?;
    let noise = row.json("noise_json")?;
    let temperatures = row.opt_json("temperatures_json")?;
    let verdict: Option<super::RecordVerdict> = row.opt_json("verdict_json")?;
    let operator = row.opt_text("operator")?;
    let station = row.opt_text("station")?;
    let _level = row.opt_text("verdict_level")?;
    // Version 1 rows kept a refused batch attempt's reason in the verdict only.
    let board = row.opt_json("board_write_json")?.unwrap_or_else(|| {
        verdict
            .iter()
            .flat_map(|v| &v.reasons)
            .find_map(|r| r.strip_prefix("not written: "))
            .map_or(BoardWrite::Written, |reason| BoardWrite::NotWritten {
                reason: reason.to_string(),
            })
    });
    Ok((
        id,
        CalibrationRecord {
            device_id,
            recorded_unix_ms,
            tool_version,
            firmware_version,
            source,
            params,
            params_crc,
            sigma,
            residuals,
            noise,
            temperatures,
            verdict,
            operator,
            station,
            board,
        },
    ))
}

fn corrupt(id: i64, what: String) -> HistoryError {
    HistoryError::Corrupt { id, what }
}
