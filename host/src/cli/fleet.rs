//! `imucal fleet`: population statistics per parameter over the newest calibration of every
//! board, and the boards that are robust outliers with the likely cause.

use clap::Args;
use imucal::history::fleet::count_boards;
use imucal::history::{fleet_report, FleetError, FleetOptions, HistoryStore};

use super::UsageError;

/// Arguments of `imucal fleet`.
#[derive(Debug, Args)]
pub struct FleetArgs {
    /// History database: a file path, `sqlite://PATH` or
    /// `postgres://user@host/db[?host=/socket/dir&port=N]`
    /// (default: `$IMUCAL_DB`, else `$XDG_DATA_HOME/imucal/history.sqlite`).
    #[arg(long, value_name = "URL")]
    pub db: Option<String>,
    /// Probability that a fault-free board is flagged (sets the threshold).
    #[arg(long, default_value_t = FleetOptions::default().false_alarm_per_board)]
    pub false_alarm: f64,
    /// Fewest values a parameter's spread may rest on: its own (one per board), or in a small
    /// fleet those of its sensor's axes of the same kind pooled.
    #[arg(
        long,
        default_value_t = FleetOptions::default().min_spread_values,
        value_parser = super::values::whole_number::<usize>
    )]
    pub min_spread_values: usize,
    /// Print JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

/// Smallest false-alarm rate accepted: its threshold is already tens of thousands of robust
/// standard deviations for a fleet of a few boards.
const MIN_FALSE_ALARM: f64 = 1e-12;

/// Run `imucal fleet`.
pub fn run(args: &FleetArgs) -> anyhow::Result<()> {
    if !(MIN_FALSE_ALARM..1.0).contains(&args.false_alarm) {
        let why = if args.false_alarm >= 1.0 {
            "a probability of 1 or more would flag every board"
        } else {
            "below that the threshold lies beyond any distance a calibration can measure, and no \
             board could ever be flagged"
        };
        return Err(UsageError(format!(
            "--false-alarm is {}, but it must be a probability from {MIN_FALSE_ALARM:e} to below \
             1: {why}; give e.g. --false-alarm 0.001 (the default)",
            imucal::device::params_json::shown_value(args.false_alarm)
        ))
        .into());
    }
    if args.min_spread_values < 3 {
        return Err(UsageError(format!(
            "--min-spread-values is {}, but a median and MAD need at least 3 values; give 3 or \
             more (the default is {})",
            args.min_spread_values,
            FleetOptions::default().min_spread_values
        ))
        .into());
    }
    let options = FleetOptions {
        false_alarm_per_board: args.false_alarm,
        min_spread_values: args.min_spread_values,
    };
    let mut store = match HistoryStore::open_existing_url(args.db.as_deref()) {
        Ok(store) => store,
        Err(error) if args.json => {
            let out = serde_json::json!({ "error": error.to_string(), "boards": null });
            println!("{}", serde_json::to_string_pretty(&out)?);
            return Err(error.into());
        }
        Err(error) => return Err(error.into()),
    };
    let report = match fleet_report(&mut store, &options) {
        Ok(report) => report,
        // A script reading --json gets an object with the reason, and the failing status.
        Err(error) if args.json => {
            let out = serde_json::json!({
                "database": store.location().display().to_string(),
                "error": error.to_string(),
                "boards": match &error {
                    FleetError::TooFewBoards { boards, .. } => Some(*boards),
                    _ => None,
                },
            });
            println!("{}", serde_json::to_string_pretty(&out)?);
            return Err(error.into());
        }
        Err(error) => return Err(error.into()),
    };
    if args.json {
        let mut out = serde_json::to_value(&report)?;
        out["database"] = store.location().display().into();
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    println!(
        "Fleet of {} (the set on each board) in {}\nMethod: {}\nThreshold |z| > {:.2} at most (false-alarm rate {} per board)\n",
        count_boards(report.boards),
        store.location().display(),
        report.method,
        report.threshold_z,
        report.false_alarm_per_board
    );
    println!(
        "{:<16} {:>6} {:>13} {:>11} {:>7} {:>13} {:>13}",
        "parameter", "boards", "median", "robust sd", "|z| >", "min", "max"
    );
    for p in &report.parameters {
        let sd = if p.log_scale {
            format!("×{:.3}", p.robust_sd.exp())
        } else {
            format!("{:.4e}", p.robust_sd)
        };
        println!(
            "{:<16} {:>6} {:>13.6} {:>11} {:>7.1} {:>13.6} {:>13.6}",
            p.parameter, p.boards, p.median, sd, p.threshold_z, p.min, p.max
        );
    }
    if !report.untested.is_empty() {
        // One entry per sensor and kind of axis parameters (`mag.b` for `mag.b.x`, `.y`, `.z`);
        // a parameter without axes (`accel.residual`) under its own name.
        let mut groups: Vec<(String, usize, usize)> = Vec::new();
        for u in &report.untested {
            let group = match u.parameter.rsplit_once('.') {
                Some((group, _)) if group.contains('.') => group.to_string(),
                _ => u.parameter.clone(),
            };
            match groups
                .iter_mut()
                .find(|(g, _, needed)| *g == group && *needed == u.needed)
            {
                Some(entry) => entry.1 = entry.1.max(u.boards),
                None => groups.push((group, u.boards, u.needed)),
            }
        }
        let text: Vec<String> = groups
            .iter()
            .map(|(g, boards, needed)| format!("{g} (on {boards} of the {needed} boards needed)"))
            .collect();
        println!("not tested, too few boards have them: {}", text.join(", "));
    }
    for board in report.results.iter().filter(|b| !b.not_compared.is_empty()) {
        println!(
            "{}: not compared with the fleet: {} (its parameters map raw counts, the fleet's \
             the nominal units)",
            board.device_id,
            board.not_compared.join(", ")
        );
    }
    let offline = |b: &&imucal::history::fleet::BoardResult| {
        b.device_id
            .starts_with(imucal::history::RECORDING_DEVICE_PREFIX)
    };
    let recordings = report.results.iter().filter(offline).count();
    if recordings > 0 {
        println!(
            "\n{recordings} recording{} fitted offline without a board named tested against \
             the fleet but not counted in it (`fit --params-out --device ID` records one as \
             that board's)",
            if recordings == 1 { "" } else { "s" }
        );
    }
    let attempts = report
        .results
        .iter()
        .filter(|b| b.not_written.is_some() && !offline(b))
        .count();
    if attempts > 0 {
        println!(
            "\n{attempts} newer attempt{} not written to {} tested against the fleet but \
             not counted in it",
            if attempts == 1 { "" } else { "s" },
            if attempts == 1 {
                "its board is"
            } else {
                "their boards are"
            }
        );
    }
    let outliers: Vec<_> = report.results.iter().filter(|b| b.outlier).collect();
    println!("\n{} outlying", count_boards(outliers.len()));
    for board in outliers {
        match &board.not_written {
            Some(_) if offline(&board) => println!(
                "{} (calibration #{}, a recording fitted offline, on no board)",
                board.device_id, board.record_id
            ),
            Some(why) => println!(
                "{} (calibration #{}, NOT WRITTEN to the board: {why})",
                board.device_id, board.record_id
            ),
            None => println!("{} (calibration #{})", board.device_id, board.record_id),
        }
        for f in &board.findings {
            println!(
                "  {:<14} {:>12.5} (fleet {:.5}), z = {:+.1}: {}",
                f.parameter, f.value, f.fleet_median, f.robust_z, f.likely_cause
            );
        }
    }
    Ok(())
}
