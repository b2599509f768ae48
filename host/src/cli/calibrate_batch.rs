//! `imucal calibrate --port P1 --port P2 …`, `--ports auto` and `--sim-boards N`: the boards
//! mounted together on one fixture, calibrated as one batch (`imucal::session::batch`), with
//! one progress line per board event and a table (or `--json`) per board at the end.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use imucal::device::{list_ports, BoardMatch};
use imucal::history::fleet::count_boards;
use imucal::history::FleetOptions;
use imucal::session::batch::{run_batch, BatchOptions, BatchReport, BoardStatus};
use imucal::session::batch_gate::{GateOptions, OutlierBasis};
use imucal::session::SessionEvent;
use serde::Serialize;

use super::args::CalibrateArgs;
use super::calibrate::{field_reference, interrupt_flag, session_field, session_options, unix_now};
use super::calibrate_sim::Simulated;
use super::write_policy::{check_outputs, Output};

/// Longest wait at the write gate for the slowest board's fit: a whole session's phases.
fn gate_timeout(args: &CalibrateArgs) -> Duration {
    let phases = args.pose_timeout * f64::from(args.rounds.max(1)) * 16.0
        + args.mag_timeout
        + args.rest_timeout;
    Duration::from_secs_f64(phases.clamp(60.0, 24.0 * 3600.0))
}

/// The ports of `--ports auto`: every recognised board.
fn recognised_ports() -> anyhow::Result<Vec<String>> {
    let ports: Vec<String> = list_ports()?
        .into_iter()
        .filter(|p| {
            matches!(
                p.board_match(),
                Some(BoardMatch::Known(_) | BoardMatch::Vendor(_))
            )
        })
        .map(|p| p.path)
        .collect();
    anyhow::ensure!(
        !ports.is_empty(),
        "--ports auto found no recognised board; check the USB cables (`imucal ports` lists what \
         is attached) or name the ports with --port"
    );
    Ok(ports)
}

#[derive(Serialize)]
struct BatchJson<'a> {
    #[serde(flatten)]
    report: &'a BatchReport,
    /// Per board, the simulator's hardware fault (the truth), when simulated.
    simulated_faults: Vec<Option<String>>,
}

/// Run a batch.
pub fn run(args: &CalibrateArgs) -> anyhow::Result<()> {
    // Checked before a simulator starts or a board is opened.
    session_options(args, session_field(None, None))?;
    anyhow::ensure!(
        !args.analyze,
        "--analyze works on one board; calibrate the batch first, then run \
         `imucal calibrate --analyze --port P` on the board to analyse"
    );
    anyhow::ensure!(
        args.resume.is_none(),
        "--resume continues one board's session; resume a board of the batch with \
         `imucal calibrate --resume BATCH_DIR/DEVICE_ID --port P`"
    );
    // Each board's session directory is `out_dir/<device id>`: refused before any board
    // starts when it holds an earlier batch.
    let out_dir = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("imucal-batch-{}", unix_now())));
    check_outputs(&[Output::Dir(&out_dir)], &[], args.force)?;
    let simulated: Vec<Simulated> = match args.sim_boards {
        Some(boards) => {
            if args.sim_faulty > boards {
                return Err(super::UsageError(format!(
                    "--sim-faulty {} is more than --sim-boards {boards}: the faulty boards are \
                     some of the batch; give --sim-faulty {boards} or less, or more --sim-boards",
                    args.sim_faulty
                ))
                .into());
            }
            let healthy = boards - args.sim_faulty;
            (0..boards)
                .map(|i| {
                    let fault = (i >= healthy).then(|| usize::from(i - healthy));
                    Simulated::start_board(args, args.sim_seed + u64::from(i), fault)
                })
                .collect::<anyhow::Result<_>>()?
        }
        None => Vec::new(),
    };
    let ports: Vec<String> = if !simulated.is_empty() {
        simulated.iter().map(Simulated::port).collect()
    } else if args.ports.is_some() {
        recognised_ports()?
    } else {
        args.port.clone()
    };
    let field = session_field(
        field_reference(args)?,
        simulated.first().map(Simulated::field_ut),
    );
    let options = BatchOptions {
        session: session_options(args, field)?,
        accept_outlier: args.accept_outlier,
        accept_poor: args.accept_poor,
        gate: GateOptions {
            db: args.history.db.clone(),
            fleet: FleetOptions::default(),
            timeout: gate_timeout(args),
        },
        out_dir: out_dir.clone(),
        record_history: !args.history.no_history,
        operator: args.history.operator.clone(),
        station: args.history.station.clone(),
        interrupt: Some(interrupt_flag()?),
    };
    say!(
        "Batch of {} on one fixture; sessions in {}",
        count_boards(ports.len()),
        out_dir.display()
    );
    if !simulated.is_empty() {
        say!(
            "Simulated boards (seeds {} to {}, {}× real time), {} with a hardware fault; each \
             simulated person follows its own board's prompts",
            args.sim_seed,
            args.sim_seed + ports.len() as u64 - 1,
            args.speed,
            args.sim_faulty
        );
    }
    let log = |port: &str, line: &str| say!("[{port}] {line}");
    // Each simulated person reads their board's prompts off the screen.
    let show = |port: &str, event: &SessionEvent<'_>| {
        if let Some(sim) = simulated.iter().find(|s| s.port() == port) {
            sim.show(event);
        }
    };
    let report = run_batch(&ports, &options, &log, &show);
    for (sim, board) in simulated.iter().zip(&report.boards) {
        if let Some(dir) = &board.session_dir {
            sim.save_truth(&dir.join("truth.json"))?;
        }
    }
    if args.json {
        let json = BatchJson {
            report: &report,
            simulated_faults: simulated.iter().map(Simulated::fault_text).collect(),
        };
        println!(
            "{}",
            serde_json::to_string_pretty(&json)
                .context("the batch summary could not be encoded")?
        );
    } else {
        print!("{}", batch_table(&report));
    }
    if options
        .interrupt
        .as_ref()
        .is_some_and(|flag| flag.load(std::sync::atomic::Ordering::SeqCst))
    {
        say!(
            "Each stopped board's session is saved in {}/<device id>; continue one with \
             `imucal calibrate --resume {}/<device id> --port <its port>`{}",
            out_dir.display(),
            out_dir.display(),
            if simulated.is_empty() {
                ""
            } else {
                " (a simulated board: --sim --sim-seed <its seed> in place of --port)"
            }
        );
    }
    let not_written = report.boards.len() - report.verified;
    let unrecorded = report
        .boards
        .iter()
        .filter(|b| b.history_error.is_some())
        .count();
    let mut failures = Vec::new();
    if not_written > 0 {
        failures.push(format!(
            "{not_written} of {} not written and verified",
            count_boards(report.boards.len())
        ));
    }
    if unrecorded > 0 {
        failures.push(match unrecorded {
            1 => "1 attempt not recorded".to_string(),
            n => format!("{n} attempts not recorded"),
        });
    }
    anyhow::ensure!(
        failures.is_empty(),
        "{}; the table says why per board",
        failures.join(", ")
    );
    Ok(())
}

/// One line per board: status, verdict, outlier test and its likely cause, time.
fn batch_table(report: &BatchReport) -> String {
    let mut out = format!(
        "\n{:<24} {:<34} {:<20} {:<10} {:<8} {:>7} {:>7}  cause / error\n",
        "port", "device", "status", "verdict", "outlier", "wall s", "cpu s"
    );
    // A cause of several lines (a stopped session says what the board holds and where its
    // data are) keeps its first line in the table and follows it in full.
    let mut details = String::new();
    for board in &report.boards {
        let verdict = board
            .summary
            .as_ref()
            .map(|s| format!("{:?}", s.verdict.level).to_lowercase())
            .unwrap_or_else(|| "-".into());
        let test = match &board.outlier_check {
            Some(c) if c.check.tested => if c.check.outlier { "yes" } else { "no" }.to_string(),
            Some(_) => "untested".into(),
            None => "-".into(),
        };
        let why = board
            .error
            .clone()
            .or_else(|| {
                let outlier_check = board.outlier_check.as_ref()?;
                let check = &outlier_check.check;
                if check.outlier {
                    check.findings.first().map(|f| match outlier_check.basis {
                        // The finding's phrase names the parameter, its value and the bound.
                        OutlierBasis::PartLimits => f.likely_cause.clone(),
                        _ => format!(
                            "{} (z = {:.1}): {}",
                            f.parameter, f.robust_z, f.likely_cause
                        ),
                    })
                } else if !check.tested {
                    check.note.clone()
                } else {
                    None
                }
            })
            .or_else(|| board.history_error.clone())
            .unwrap_or_default();
        let why = match why.split_once('\n') {
            Some((first, _)) => {
                details += &format!("\n{}:\n{why}\n", board.port);
                format!("{first} (in full below)")
            }
            None => why,
        };
        let status = match board.status {
            BoardStatus::Verified => "verified",
            BoardStatus::RefusedOutlier => "refused: outlier",
            BoardStatus::RefusedPoorVerdict => "refused: poor fit",
            BoardStatus::Failed => "failed",
        };
        // A time the platform or a stopped thread could not tell is a dash, not a number.
        let seconds = |value: Option<f64>, decimals: usize| {
            value.map_or_else(|| "—".to_string(), |v| format!("{v:.decimals$}"))
        };
        out += &format!(
            "{:<24} {:<34} {:<20} {:<10} {:<8} {:>7} {:>7}  {why}\n",
            board.port,
            board.device_id.as_deref().unwrap_or("-"),
            status,
            verdict,
            test,
            seconds(board.wall_seconds, 1),
            seconds(board.host_cpu_seconds, 2),
        );
    }
    out += &format!(
        "{} of {} written and verified in {:.1} s\n",
        report.verified,
        count_boards(report.boards.len()),
        report.wall_seconds
    );
    out + &details
}

#[cfg(test)]
mod tests {
    use super::*;
    use imucal::session::batch::{BoardResult, BoardStatus};

    #[test]
    fn a_cause_of_several_lines_keeps_one_table_row_and_follows_in_full() {
        let board = |port: &str, error: &str| BoardResult {
            port: port.into(),
            device_id: None,
            status: BoardStatus::Failed,
            outlier: false,
            outlier_check: None,
            error: Some(error.into()),
            session_dir: None,
            recorded_as: None,
            history_error: None,
            history_write_seconds: None,
            summary: None,
            wall_seconds: Some(1.0),
            host_cpu_seconds: None,
        };
        let report = BatchReport {
            boards: vec![
                board(
                    "/dev/pts/1",
                    "the board stopped answering\nThe board holds its earlier calibration.",
                ),
                board("/dev/pts/2", "no board on the port"),
            ],
            verified: 0,
            wall_seconds: 1.0,
        };
        let table = batch_table(&report);
        let rows: Vec<&str> = table.lines().filter(|l| l.contains(" failed ")).collect();
        assert_eq!(rows.len(), 2, "{table}");
        assert!(
            rows[0].ends_with("the board stopped answering (in full below)"),
            "{table}"
        );
        assert!(rows[1].ends_with("no board on the port"), "{table}");
        assert!(table.ends_with(
            "/dev/pts/1:\nthe board stopped answering\nThe board holds its earlier calibration.\n"
        ));
    }
}
