//! The production line end to end: `imucal calibrate --sim-boards 8 --sim-faulty 1 --yes --json`
//! on an empty history. With no fleet to compare with, each board is compared with the other
//! seven of its batch (median/MAD with the spread pooled over a sensor's axes). Seven boards are
//! written and verified, the faulty one (a gross accelerometer offset) is refused before its
//! write as an outlier with its cause in words, all eight attempts are recorded (the refused one
//! marked as not written), and `imucal fleet --json` lists the faulty board as an outlier
//! without counting its set in the fleet. Runs on SQLite, and on
//! PostgreSQL when `IMUCAL_TEST_PG_URL` is set.

mod history_support;

use std::path::Path;
use std::process::Command;

use history_support::{databases, scratch_dir, url};
use imucal::history::{BoardWrite, HistoryStore};

/// Simulated seconds per wall second. The simulated person holds a position for at most 20 s
/// simulated before moving on, so at 20× eight boards' host threads had one wall second to
/// capture it, which a loaded machine missed; 10× (the speed of the production-line figures)
/// gives two.
const SPEED: &str = "10";

/// `imucal calibrate --sim-boards BOARDS --sim-faulty 1 --json` into `db` and `out_dir`, which
/// must fail (the faulty board is not written): its JSON report and its standard error.
fn failing_batch(boards: &str, db: &str, out_dir: &Path) -> (serde_json::Value, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(["calibrate", "--sim-boards", boards, "--sim-faulty", "1"])
        .args(["--speed", SPEED, "--yes", "--json", "--db", db, "--out"])
        .arg(out_dir)
        .output()
        .expect("imucal runs");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "{stderr}");
    let report = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("JSON on stdout ({e}): {stderr}"));
    (report, stderr)
}

#[test]
fn a_batch_of_eight_on_an_empty_history_verifies_seven_and_refuses_the_faulty_one() {
    for location in databases("batch") {
        let db = url(&location);
        let out_dir = scratch_dir("batch-sessions");
        // One board is refused, so the batch as a whole reports failure.
        let (report, stderr) = failing_batch("8", &db, &out_dir);
        let boards = report["boards"].as_array().expect("boards");
        assert_eq!(boards.len(), 8, "{report}");
        assert_eq!(report["verified"], 7, "{report}\n{stderr}");
        let faults = report["simulated_faults"].as_array().expect("faults");
        for (board, fault) in boards.iter().zip(faults) {
            let expected = if fault.is_null() {
                "verified"
            } else {
                "refused_outlier"
            };
            assert_eq!(board["status"], expected, "{board}\n{stderr}");
            assert_eq!(board["outlier_check"]["basis"], "batch", "{board}");
            assert!(board["recorded_as"].is_number(), "{board}");
        }
        let faulty = &boards[7];
        let finding = &faulty["outlier_check"]["findings"][0];
        assert_eq!(finding["parameter"], "accel.b.x", "{faulty}");
        assert!(
            finding["likely_cause"]
                .as_str()
                .is_some_and(|c| c.contains("gross accelerometer offset on axis x")),
            "{finding}"
        );
        assert!(
            stderr.contains("OUTLIER") && stderr.contains("accelerometer offset"),
            "{stderr}"
        );
        // The refused board's parameters were saved but not written.
        let dir = out_dir.join(faulty["device_id"].as_str().expect("device id"));
        assert!(dir.join("params.json").is_file(), "{}", dir.display());
        assert_eq!(faulty["summary"]["verified"], false, "{faulty}");
        // Its summary, on disk too, says it is not on the board and why; so does its report.
        let saved: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(dir.join("summary.json")).expect("summary.json"),
        )
        .expect("summary.json parses");
        for summary in [&faulty["summary"], &saved] {
            assert_eq!(summary["written"], false, "{summary}");
            assert_eq!(
                summary["not_written_because"], "outlier against the other boards of the batch",
                "{summary}"
            );
        }
        let page = out_dir.join("faulty-report");
        let report_run = Command::new(env!("CARGO_BIN_EXE_imucal"))
            .args(["report"])
            .arg(&dir)
            .arg("-o")
            .arg(&page)
            .output()
            .expect("imucal report runs");
        assert!(report_run.status.success(), "{report_run:?}");
        let html = std::fs::read_to_string(page.join("report.html")).expect("the report page");
        assert!(
            html.contains(
                "NOT WRITTEN to the board (outlier against the other boards of the batch)"
            ),
            "the report does not say the set is not on the board"
        );

        let recorded = HistoryStore::open(&location)
            .expect("open")
            .records(None)
            .expect("read");
        assert_eq!(recorded.len(), 8);
        let refused = recorded
            .iter()
            .find(|r| r.record.device_id == faulty["device_id"])
            .expect("the refused attempt is recorded");
        assert_eq!(
            refused.record.board,
            BoardWrite::NotWritten {
                reason: "outlier against the other boards of the batch".into()
            }
        );

        let fleet = Command::new(env!("CARGO_BIN_EXE_imucal"))
            .args(["fleet", "--db", &db, "--json"])
            .output()
            .expect("imucal fleet runs");
        let fleet_err = String::from_utf8_lossy(&fleet.stderr);
        assert!(fleet.status.success(), "{fleet_err}");
        let fleet: serde_json::Value = serde_json::from_slice(&fleet.stdout).expect("JSON");
        // The refused set is on no board: tested and listed, not counted.
        assert_eq!(fleet["boards"], 7, "{fleet}");
        let results = fleet["results"].as_array().expect("results");
        for listed in results {
            let is_faulty = listed["device_id"] == faulty["device_id"];
            assert_eq!(listed["outlier"], is_faulty, "{listed}");
        }
        let listed = results
            .iter()
            .find(|b| b["device_id"] == faulty["device_id"])
            .expect("the faulty board is in the fleet");
        assert_eq!(listed["findings"][0]["parameter"], "accel.b.x", "{listed}");
        assert_eq!(
            listed["not_written"], "outlier against the other boards of the batch",
            "{listed}"
        );
    }
}

#[test]
fn a_first_batch_too_small_to_compare_holds_each_board_to_the_datasheet_bounds() {
    // Three boards on an empty history: no fleet, and too few for the within-batch test. The
    // faulty one (0.3 g of accelerometer offset, beyond the widest datasheet's 0.25 g) must not
    // be written; the two sound ones are.
    let location = databases("first_batch")
        .into_iter()
        .next()
        .expect("a SQLite database");
    let db = url(&location);
    let out_dir = scratch_dir("first-batch-sessions");
    let (report, stderr) = failing_batch("3", &db, &out_dir);
    let boards = report["boards"].as_array().expect("boards");
    let faults = report["simulated_faults"].as_array().expect("faults");
    assert_eq!(report["verified"], 2, "{report}\n{stderr}");
    for (board, fault) in boards.iter().zip(faults) {
        assert_eq!(board["outlier_check"]["basis"], "part_limits", "{board}");
        if fault.is_null() {
            assert_eq!(board["status"], "verified", "{board}\n{stderr}");
        } else {
            assert_eq!(board["status"], "refused_outlier", "{board}\n{stderr}");
            let finding = &board["outlier_check"]["findings"][0];
            assert_eq!(finding["parameter"], "accel.b.x", "{board}");
            assert!(
                finding["likely_cause"]
                    .as_str()
                    .is_some_and(|c| c.contains("beyond the ±2.4517 m/s² of every common part")),
                "{finding}"
            );
        }
    }
}

/// The table and progress lines of a small batch with a board that fails: the failed row shows
/// its own wall and CPU time (never NaN), a verified write names its CRC in hex and the store
/// sequence in words, and counts of boards agree in number ("1 board", "3 boards").
#[test]
fn a_small_batch_with_a_failed_board_prints_figures_crcs_and_counts_in_words() {
    let dir = scratch_dir("batch-table");
    let db = format!("sqlite://{}", dir.join("history.sqlite").display());
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(["calibrate", "--sim-boards", "3", "--sim-faulty", "1"])
        .args(["--sim-seed", "20", "--speed", SPEED, "--yes", "--db", &db])
        // The faulty board never reaches a position; its session fails after this long.
        .args(["--pose-timeout", "40", "--out"])
        .arg(dir.join("sessions"))
        .output()
        .expect("imucal runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(!stdout.contains("NaN"), "{stdout}");
    let failed = stdout
        .lines()
        .find(|l| l.contains(" failed "))
        .unwrap_or_else(|| panic!("a failed row: {stdout}\n{stderr}"));
    // port, device, status, verdict, outlier, wall s, cpu s.
    let columns: Vec<&str> = failed.split_whitespace().collect();
    let wall: f64 = columns[5].parse().expect("wall seconds");
    let cpu: f64 = columns[6].parse().expect("CPU seconds");
    assert!(wall >= 40.0 && cpu > 0.0 && cpu < wall, "{failed}");
    let verified: Vec<&str> = stderr
        .lines()
        .filter(|l| l.contains("] written and verified"))
        .collect();
    assert_eq!(verified.len(), 2, "{stderr}");
    for line in verified {
        let crc = line
            .split("CRC 0x")
            .nth(1)
            .and_then(|rest| rest.get(..8))
            .unwrap_or_else(|| panic!("a hex CRC: {line}"));
        assert!(crc.chars().all(|c| c.is_ascii_hexdigit()), "{line}");
        assert!(line.ends_with(", store sequence 1"), "{line}");
    }
    assert!(!stderr.contains("ParamStatus"), "{stderr}");
    // The two boards that reached the write gate had too few to compare with (a fleet of
    // one), so they were held to the datasheet bounds, which they pass.
    assert_eq!(
        stdout
            .lines()
            .filter(|l| l.split_whitespace().nth(2) == Some("verified"))
            .count(),
        2,
        "{stdout}"
    );
    assert!(
        !format!("{stdout}{stderr}").contains(" 1 boards"),
        "{stdout}{stderr}"
    );
    assert!(
        stdout.contains("2 of 3 boards written and verified"),
        "{stdout}"
    );
    assert!(
        stderr.contains("1 of 3 boards not written and verified"),
        "{stderr}"
    );
}

#[test]
fn a_terminated_batch_saves_every_boards_measurements_and_says_how_to_continue() {
    let dir = scratch_dir("batch-term");
    let out_dir = dir.join("batch");
    let child = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(["calibrate", "--sim-boards", "2", "--yes", "--no-history"])
        .arg("-o")
        .arg(&out_dir)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("imucal runs");
    // Stop once a board has saved two positions (each session saves after every pose).
    let poses_saved = || {
        std::fs::read_dir(&out_dir)
            .into_iter()
            .flatten()
            .flatten()
            .filter_map(|e| imucal::session::save::load_poses(&e.path().join("poses.json")).ok())
            .map(|p| p.len())
            .max()
            .unwrap_or(0)
    };
    let started = std::time::Instant::now();
    while poses_saved() < 2 {
        assert!(started.elapsed().as_secs() < 300, "no pose saved in 300 s");
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    // SIGTERM, as `timeout` or a closed session sends it: the same as a Ctrl-C.
    let status = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(status.success());
    let out = child.wait_with_output().expect("imucal ends");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("--resume"), "{stderr}");
    let boards: Vec<_> = std::fs::read_dir(&out_dir)
        .expect("the batch directory")
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.is_dir())
        .collect();
    assert_eq!(boards.len(), 2, "{boards:?}");
    for board in boards {
        let progress = imucal::session::load_progress(&board).expect("progress.json");
        assert!(
            progress.stopped_because.contains("stopped by the user"),
            "{progress:?}"
        );
        // What was streamed is on disk: the moves between the holds and the magnetometer.
        let moves = imucal::session::save::load_moves(&board.join("moves.csv")).expect("moves");
        assert!(!moves.is_empty(), "{}", board.display());
        assert_eq!(
            imucal::session::save::load_mag_samples(&board.join("mag_samples.csv"))
                .expect("magnetometer samples")
                .len(),
            progress.mag_samples
        );
    }
}
