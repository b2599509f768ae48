//! `imucal history`: every calibration of one board (or all), with each parameter's change
//! since the board's previous calibration in σ units; and the `--db/--operator/--station`
//! flags with which calibrating commands record what they did.

use std::path::Path;
use std::time::{Duration, UNIX_EPOCH};

use clap::Args;
use imucal::history::plot::parameters_over_time;
use imucal::history::{
    device_changes, record_calibration, CalibrationRecord, DbLocation, HistoryStore, RecordChanges,
};

/// Arguments of `imucal history`.
#[derive(Debug, Args)]
pub struct HistoryArgs {
    /// Only this board (its id as `imucal info` prints it); all boards when left out.
    pub device: Option<String>,
    /// History database: a file path, `sqlite://PATH` or
    /// `postgres://user@host/db[?host=/socket/dir&port=N]`
    /// (default: `$IMUCAL_DB`, else `$XDG_DATA_HOME/imucal/history.sqlite`).
    #[arg(long, value_name = "URL")]
    pub db: Option<String>,
    /// Changes listed per calibration in the table (all are in `--json`).
    #[arg(long, default_value_t = 4, value_parser = super::values::whole_number::<usize>)]
    pub changes: usize,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Flags of commands that record a calibration.
#[derive(Debug, Clone, Default, Args)]
pub struct RecordArgs {
    /// History database to record the calibration in (`imucal fit` records what it writes with
    /// --params-out, nothing else): a file path, `sqlite://PATH` or
    /// `postgres://user@host/db[?host=/socket/dir&port=N]` (default: `$IMUCAL_DB`, else
    /// `$XDG_DATA_HOME/imucal/history.sqlite`).
    #[arg(long, value_name = "URL")]
    pub db: Option<String>,
    /// Who calibrated (kept in the history).
    #[arg(long)]
    pub operator: Option<String>,
    /// Which station or fixture (kept in the history).
    #[arg(long)]
    pub station: Option<String>,
    /// Do not record this calibration in the history.
    #[arg(long, conflicts_with_all = ["db", "operator", "station"])]
    pub no_history: bool,
}

/// Whether `args` name a history database (`--db` or `$IMUCAL_DB`) rather than leaving the
/// default.
fn names_a_database(args: &RecordArgs) -> bool {
    args.db.is_some()
        || std::env::var(imucal::history::DB_ENV).is_ok_and(|url| !url.trim().is_empty())
}

/// Refuse, before a board is opened, a history database named by `--db` or `$IMUCAL_DB` that
/// cannot be read or created: the calibration would be written to the board and then not
/// recorded.
pub fn check_before_writing(args: &RecordArgs) -> anyhow::Result<()> {
    if args.no_history || !names_a_database(args) {
        return Ok(());
    }
    let source = if args.db.is_some() {
        "--db"
    } else {
        imucal::history::DB_ENV
    };
    let refuse = |error: String| {
        anyhow::anyhow!(
            "the history database named by {source} cannot be used, so nothing was started: \
             {error}; fix {source}, or pass --no-history to calibrate without recording"
        )
    };
    let location = DbLocation::resolve(args.db.as_deref()).map_err(|e| refuse(e.to_string()))?;
    match &location {
        // A file not there yet is created when something is recorded (a command may end up
        // recording nothing): only where it would go is checked now.
        DbLocation::Sqlite(path) if !path.exists() => {
            let parent = path.parent().filter(|p| !p.as_os_str().is_empty());
            let existing = parent
                .into_iter()
                .flat_map(Path::ancestors)
                .find(|a| a.exists());
            if let Some(dir) = existing.filter(|d| !d.is_dir()) {
                return Err(refuse(format!(
                    "`{}` cannot be created: `{}` is not a directory",
                    path.display(),
                    dir.display()
                )));
            }
        }
        _ => {
            HistoryStore::open(&location).map_err(|e| refuse(e.to_string()))?;
        }
    }
    Ok(())
}

/// Record `record` with the operator and station of `args`. Call it after the calibration is
/// saved elsewhere: a failure is an error when `--db` or `$IMUCAL_DB` named the database (the
/// station asked for it) and a warning otherwise; either way it says the calibration itself is
/// kept.
pub fn record(args: &RecordArgs, mut record: CalibrationRecord) -> anyhow::Result<()> {
    if args.no_history {
        return Ok(());
    }
    record.operator.clone_from(&args.operator);
    record.station.clone_from(&args.station);
    match record_calibration(args.db.as_deref(), &record) {
        Ok((id, location)) => {
            say!(
                "Recorded as calibration {id} of {} in {}",
                record.device_id,
                location.display()
            );
            Ok(())
        }
        Err(error) if names_a_database(args) => Err(error.into()),
        Err(error) => {
            say!("imucal: warning: {error}");
            Ok(())
        }
    }
}

/// The report's figures of the board calibrated in `session_dir` over its recorded
/// calibrations (`summary.json` names the board), or a note why there are none. A missing
/// default database is not created just to be found empty.
pub fn report_figures(
    db: Option<&str>,
    session_dir: &Path,
) -> Result<Vec<(String, String)>, String> {
    // A MotionCal sketch session has no summary.json: its board reports no id to look up.
    if !session_dir.join("summary.json").exists() {
        return Ok(Vec::new());
    }
    let summary = std::fs::read_to_string(session_dir.join("summary.json"))
        .map_err(|e| format!("no calibration history shown: summary.json unreadable ({e})"))?;
    let summary: serde_json::Value = serde_json::from_str(&summary)
        .map_err(|e| format!("no calibration history shown: summary.json: {e}"))?;
    let Some(device) = summary["device_id"].as_str() else {
        return Ok(Vec::new());
    };
    let location = DbLocation::resolve(db).map_err(|e| e.to_string())?;
    if matches!(&location, DbLocation::Sqlite(path) if !path.exists()) {
        return Ok(Vec::new());
    }
    let records = HistoryStore::open(&location)
        .and_then(|mut store| store.records(Some(device)))
        .map_err(|e| format!("no calibration history shown: {e}"))?;
    if records.len() < 2 {
        return Ok(Vec::new());
    }
    parameters_over_time(&records).map_err(|e| e.to_string())
}

/// `major.minor.patch`.
pub fn firmware_text(version: &imucal_protocol::FirmwareVersion) -> String {
    format!("{}.{}.{}", version.major, version.minor, version.patch)
}

/// Run `imucal history`. A board with no record is an error (exit 1) naming the boards the
/// database does hold, so that a mistyped id is not read as "never calibrated".
pub fn run(args: &HistoryArgs) -> anyhow::Result<()> {
    let mut store = HistoryStore::open_existing_url(args.db.as_deref())?;
    let records = store.records(args.device.as_deref())?;
    let history = device_changes(records);
    if args.json {
        let out = serde_json::json!({
            "database": store.location().display(),
            "device": args.device,
            "records": history,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
    }
    if history.is_empty() {
        let Some(device) = &args.device else {
            if !args.json {
                println!("No calibrations in {}", store.location().display());
            }
            return Ok(());
        };
        let mut boards: Vec<String> = store
            .records(None)?
            .into_iter()
            .map(|r| r.record.device_id)
            .collect();
        boards.sort();
        boards.dedup();
        const LISTED: usize = 8;
        let held = match boards.len() {
            0 => "it holds no calibration yet".to_string(),
            n => format!(
                "it holds {}: {}{}",
                imucal::words::counted(n, "board"),
                boards
                    .iter()
                    .take(LISTED)
                    .map(String::as_str)
                    .collect::<Vec<_>>()
                    .join(", "),
                if n > LISTED { ", …" } else { "" }
            ),
        };
        anyhow::bail!(
            "no calibration of board `{device}` is recorded in {}; {held} (check the id as \
             `imucal info` prints it, or leave it out to list every board)",
            store.location().display()
        );
    }
    if args.json {
        return Ok(());
    }
    println!(
        "{} calibration{} in {}",
        history.len(),
        if history.len() == 1 { "" } else { "s" },
        store.location().display()
    );
    for entry in &history {
        print_entry(entry, args.changes);
    }
    Ok(())
}

/// `2026-11-23T13:40:02Z` of a Unix time in ms.
pub fn utc(unix_ms: i64) -> String {
    let time = UNIX_EPOCH + Duration::from_millis(u64::try_from(unix_ms).unwrap_or(0));
    humantime::format_rfc3339_seconds(time).to_string()
}

fn print_entry(entry: &RecordChanges, shown: usize) {
    let r = &entry.stored.record;
    let who: Vec<String> = [("operator", &r.operator), ("station", &r.station)]
        .iter()
        .filter_map(|(k, v)| v.as_ref().map(|v| format!("{k} {v}")))
        .collect();
    println!(
        "#{:<5} {}  {}  {:<6}  CRC {:#010x}  {:<8} {}",
        entry.stored.id,
        utc(r.recorded_unix_ms),
        r.device_id,
        r.source.as_str(),
        r.params_crc,
        r.verdict.as_ref().map_or("-", |v| v.level.as_str()),
        who.join(", ")
    );
    if let Some(label) = r.board.label() {
        println!("       {label}");
    }
    let skipped = match entry.not_written_between.as_slice() {
        [] => String::new(),
        [one] => format!("; #{one} was not written"),
        many => format!(
            "; {} were not written",
            many.iter()
                .map(|id| format!("#{id}"))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    match entry.previous {
        None if skipped.is_empty() => println!("       first calibration of this board"),
        None => println!("       no earlier set on this board{skipped}"),
        Some(previous) => {
            let changed: Vec<_> = entry.changes.iter().filter(|c| c.change != 0.0).collect();
            // Three significant digits whatever the unit: a bias change of 2e-5 rad/s is not
            // "+0.0000".
            let mut listed: Vec<String> = changed
                .iter()
                .take(shown)
                .map(|c| match c.change_sigma {
                    Some(s) => format!("{} {:+.2e} ({:+.1}σ)", c.parameter, c.change, s),
                    None => format!("{} {:+.2e}", c.parameter, c.change),
                })
                .collect();
            // A change the fits gave no σ for ranks after every one they did; the largest of
            // them is named even when the list is cut before it.
            let unscaled = changed
                .iter()
                .skip(shown)
                .find(|c| c.change_sigma.is_none());
            let mut hidden = changed.len().saturating_sub(shown);
            if let Some(c) = unscaled {
                listed.push(if c.before == 0.0 {
                    format!("{} {:+.2e} (no σ)", c.parameter, c.change)
                } else {
                    format!(
                        "{} {:+.2e} ({:+.2} % of its value; no σ)",
                        c.parameter,
                        c.change,
                        100.0 * c.change / c.before.abs()
                    )
                });
                hidden -= 1;
            }
            if hidden > 0 {
                listed.push(format!(
                    "and {hidden} more (--changes {} lists them)",
                    changed.len()
                ));
            }
            let kinds: Vec<String> = entry.sensor_changes.iter().map(|c| c.sentence()).collect();
            let said: Vec<String> = kinds.into_iter().chain(listed).collect();
            // The comparison is with the set the board held, so an unwritten attempt between
            // does not hide what changed on the board.
            let since = if skipped.is_empty() {
                format!("since #{previous}")
            } else {
                format!("since #{previous}, the set on the board before{skipped}")
            };
            if said.is_empty() {
                println!("       {since}: no parameter changed");
            } else {
                println!("       {since}: {}", said.join(", "));
            }
        }
    }
}
