//! Where the history lives: `sqlite://PATH` or a plain path, a libpq-style `postgres://` URL,
//! or the default SQLite file in the user's data directory.

use std::path::PathBuf;

use super::HistoryError;

/// Environment variable naming the database when `--db` is not given.
pub const DB_ENV: &str = "IMUCAL_DB";

/// File name of the default SQLite database inside the data directory.
const DEFAULT_FILE: &str = "history.sqlite";

/// A parsed database location.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DbLocation {
    /// A SQLite file (created when missing).
    Sqlite(PathBuf),
    /// A PostgreSQL server; the URL as libpq reads it (`postgres://user@host/db`,
    /// `?host=/socket/dir&port=N` for a Unix socket).
    Postgres(String),
}

impl DbLocation {
    /// Parse `url`: `sqlite://PATH` (`sqlite:///abs/path` or `sqlite://relative/path`),
    /// `postgres://…` or `postgresql://…`, or a plain path, which names a SQLite file.
    pub fn parse(url: &str) -> Result<Self, HistoryError> {
        let url = url.trim();
        if let Some(path) = url.strip_prefix("sqlite://") {
            if path.is_empty() {
                return Err(bad_url(url, "the SQLite URL names no file"));
            }
            return Ok(Self::Sqlite(PathBuf::from(path)));
        }
        if url.starts_with("postgres://") || url.starts_with("postgresql://") {
            return Ok(Self::Postgres(url.to_string()));
        }
        if url.is_empty() {
            return Err(bad_url(url, "it names nothing"));
        }
        if url.contains("://") {
            return Err(bad_url(
                url,
                "it is neither a sqlite:// nor a postgres:// URL",
            ));
        }
        Ok(Self::Sqlite(PathBuf::from(url)))
    }

    /// `--db` if given, else `$IMUCAL_DB`, else the default SQLite file
    /// (`$XDG_DATA_HOME/imucal/history.sqlite` or `~/.local/share/imucal/history.sqlite`).
    pub fn resolve(flag: Option<&str>) -> Result<Self, HistoryError> {
        if let Some(url) = flag {
            return Self::parse(url);
        }
        match std::env::var(DB_ENV) {
            Ok(url) if !url.trim().is_empty() => Self::parse(&url),
            _ => Ok(Self::Sqlite(default_data_dir()?.join(DEFAULT_FILE))),
        }
    }

    /// The location for messages, without a password.
    pub fn display(&self) -> String {
        match self {
            Self::Sqlite(path) => format!("sqlite://{}", path.display()),
            Self::Postgres(url) => redact_password(url),
        }
    }
}

/// `$XDG_DATA_HOME/imucal`, or `$HOME/.local/share/imucal`.
pub fn default_data_dir() -> Result<PathBuf, HistoryError> {
    let from = |var: &str| {
        std::env::var_os(var)
            .map(PathBuf::from)
            .filter(|p| p.is_absolute())
    };
    if let Some(dir) = from("XDG_DATA_HOME") {
        return Ok(dir.join("imucal"));
    }
    from("HOME")
        .map(|home| home.join(".local").join("share").join("imucal"))
        .ok_or(HistoryError::NoDataDir)
}

fn bad_url(url: &str, why: &str) -> HistoryError {
    HistoryError::BadUrl {
        url: redact_password(url),
        why: why.to_string(),
    }
}

/// `postgres://user:secret@host/db` → `postgres://user:***@host/db`.
fn redact_password(url: &str) -> String {
    let Some((scheme, rest)) = url.split_once("://") else {
        return url.to_string();
    };
    let authority_end = rest.find(['/', '?']).unwrap_or(rest.len());
    let (authority, tail) = rest.split_at(authority_end);
    match authority.rsplit_once('@') {
        Some((user_info, host)) => match user_info.split_once(':') {
            Some((user, _)) => format!("{scheme}://{user}:***@{host}{tail}"),
            None => url.to_string(),
        },
        None => url.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sqlite_urls_give_absolute_and_relative_paths() {
        assert_eq!(
            DbLocation::parse("sqlite:///var/lib/imucal/h.db").unwrap(),
            DbLocation::Sqlite(PathBuf::from("/var/lib/imucal/h.db"))
        );
        assert_eq!(
            DbLocation::parse("sqlite://h.db").unwrap(),
            DbLocation::Sqlite(PathBuf::from("h.db"))
        );
    }

    #[test]
    fn postgres_urls_with_socket_dir_are_kept_for_libpq_parsing() {
        let url = "postgres://imucal@localhost/line?host=/tmp/pg&port=5433";
        assert_eq!(
            DbLocation::parse(url).unwrap(),
            DbLocation::Postgres(url.into())
        );
    }

    #[test]
    fn other_schemes_are_refused_with_the_accepted_forms_named() {
        let error = DbLocation::parse("mysql://x/y").unwrap_err().to_string();
        assert!(
            error.contains("sqlite://") && error.contains("postgres://"),
            "{error}"
        );
    }

    #[test]
    fn a_plain_path_names_a_sqlite_file() {
        assert_eq!(
            DbLocation::parse("/tmp/station/history.sqlite").unwrap(),
            DbLocation::Sqlite(PathBuf::from("/tmp/station/history.sqlite"))
        );
        assert_eq!(
            DbLocation::parse("history.db").unwrap(),
            DbLocation::Sqlite(PathBuf::from("history.db"))
        );
    }

    #[test]
    fn passwords_are_not_shown() {
        let shown = DbLocation::parse("postgres://u:secret@h/db")
            .unwrap()
            .display();
        assert_eq!(shown, "postgres://u:***@h/db");
    }
}
