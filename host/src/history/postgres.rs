//! The PostgreSQL connection (the synchronous `postgres` client, no TLS: a station talks to a
//! server on the plant network or a local Unix socket). The URL is read by libpq's rules, so
//! `postgres://user@host/db?host=/socket/dir&port=N` reaches a server on a Unix socket.

use postgres::types::ToSql;
use postgres::{Client, NoTls};

use super::schema::{
    self, Backend, ColumnKind, Dialect, SqlValue, COLUMNS, SCHEMA_VERSION, VERSION_TABLE,
};

/// Key of the advisory lock that serialises schema creation between stations.
const MIGRATION_LOCK: i64 = 0x14D5_5CA1;

/// A PostgreSQL history database.
pub struct PostgresBackend {
    client: Client,
}

fn failed(cause: postgres::Error) -> String {
    // The server's own message (e.g. `role "x" does not exist`) is the useful part.
    match cause.as_db_error() {
        Some(db) => format!("{}: {}", db.severity(), db.message()),
        None => cause.to_string(),
    }
}

impl PostgresBackend {
    /// Connect to `url`.
    pub fn open(url: &str) -> Result<Self, String> {
        let client = Client::connect(url, NoTls).map_err(failed)?;
        Ok(Self { client })
    }
}

/// Nullable columns are all text.
static NULL_TEXT: Option<&str> = None;

impl Backend for PostgresBackend {
    fn migrate(&mut self) -> Result<i64, String> {
        let mut tx = self.client.transaction().map_err(failed)?;
        // Stations starting together must not both create the schema.
        tx.execute("SELECT pg_advisory_xact_lock($1)", &[&MIGRATION_LOCK])
            .map_err(failed)?;
        tx.batch_execute(&format!(
            "CREATE TABLE IF NOT EXISTS {VERSION_TABLE} (version BIGINT NOT NULL)"
        ))
        .map_err(failed)?;
        let found: i64 = tx
            .query_one(
                &format!("SELECT COALESCE(MAX(version), 0) FROM {VERSION_TABLE}"),
                &[],
            )
            .map_err(failed)?
            .try_get(0)
            .map_err(failed)?;
        if found < SCHEMA_VERSION {
            for statement in schema::upgrade_statements(found, Dialect::Postgres) {
                tx.batch_execute(&statement).map_err(failed)?;
            }
            tx.execute(
                &format!("INSERT INTO {VERSION_TABLE} (version) VALUES ($1)"),
                &[&SCHEMA_VERSION],
            )
            .map_err(failed)?;
        }
        tx.commit().map_err(failed)?;
        Ok(found)
    }

    fn insert(&mut self, row: &[SqlValue]) -> Result<i64, String> {
        let params: Vec<&(dyn ToSql + Sync)> = row
            .iter()
            .map(|value| match value {
                SqlValue::Text(t) => t as &(dyn ToSql + Sync),
                SqlValue::Int(i) => i as &(dyn ToSql + Sync),
                SqlValue::Null => &NULL_TEXT as &(dyn ToSql + Sync),
            })
            .collect();
        self.client
            .query_one(&schema::insert_sql(), &params)
            .map_err(failed)?
            .try_get(0)
            .map_err(failed)
    }

    fn select(&mut self, device: Option<&str>) -> Result<Vec<Vec<SqlValue>>, String> {
        let rows = self
            .client
            .query(&schema::select_sql(), &[&device])
            .map_err(failed)?;
        rows.iter()
            .map(|row| {
                let mut values = vec![SqlValue::Int(row.try_get(0).map_err(failed)?)];
                for (i, (_, kind)) in COLUMNS.iter().enumerate() {
                    let value = match kind {
                        ColumnKind::Int => SqlValue::Int(row.try_get(i + 1).map_err(failed)?),
                        ColumnKind::Text | ColumnKind::OptText => row
                            .try_get::<_, Option<String>>(i + 1)
                            .map_err(failed)?
                            .map_or(SqlValue::Null, SqlValue::Text),
                    };
                    values.push(value);
                }
                Ok(values)
            })
            .collect()
    }
}
