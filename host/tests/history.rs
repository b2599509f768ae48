//! The calibration history store, on SQLite and (with `IMUCAL_TEST_PG_URL`) PostgreSQL:
//! records come back whole, the database refuses changes, changes are in σ units, failures
//! are reported, and concurrent writers from several processes lose nothing.

mod history_support;

use std::process::{Command, Stdio};

use history_support::{board_record, databases, url};
use imucal::history::{
    device_changes, CalibrationRecord, DbLocation, HistoryError, HistoryStore, RecordVerdict,
    SensorChange, TemperatureSpan,
};

fn full_record() -> CalibrationRecord {
    let mut record = board_record(7);
    record.firmware_version = Some("1.2.3".into());
    record.temperatures = Some(TemperatureSpan {
        min_c: 24.5,
        mean_c: 25.0,
        max_c: 26.25,
    });
    record.verdict = Some(RecordVerdict {
        level: "marginal".into(),
        reasons: vec!["only 5 directions".into()],
    });
    record.operator = Some("Ann O'Neil".into());
    record.station = Some("line 2; fixture \"B\"".into());
    record
}

#[test]
fn a_sensor_the_record_did_not_calibrate_has_no_parameters_to_compare() {
    let mut record = board_record(7);
    assert!(record.parameters().contains_key("accel.A.xx"));
    record
        .params
        .not_fitted
        .insert("accel".into(), "only one face up".into());
    let parameters = record.parameters();
    // Its placeholder identity is no measurement: no change against the previous record, no
    // fleet statistic.
    assert!(
        !parameters.keys().any(|k| k.starts_with("accel.")),
        "{parameters:?}"
    );
    assert!(parameters.contains_key("gyro.b.x") && parameters.contains_key("mag.A.zz"));
}

#[test]
fn a_record_reads_back_with_every_field_and_increasing_ids() {
    for location in databases("roundtrip") {
        let mut store = HistoryStore::open(&location).expect("open");
        let record = full_record();
        let first = store.record(&record).expect("write");
        let second = store.record(&board_record(8)).expect("write");
        assert!(second > first, "{}", location.display());
        let back = store.records(Some(&record.device_id)).expect("read");
        assert_eq!(back.len(), 1, "{}", location.display());
        assert_eq!(back[0].id, first);
        assert_eq!(back[0].record, record, "{}", location.display());
        assert_eq!(store.records(None).expect("read all").len(), 2);
    }
}

#[test]
fn the_database_itself_refuses_update_delete_and_truncate() {
    for location in databases("append_only") {
        let mut store = HistoryStore::open(&location).expect("open");
        store.record(&board_record(1)).expect("write");
        let attempts = [
            "UPDATE imucal_calibrations SET device_id = 'x'",
            "DELETE FROM imucal_calibrations",
        ];
        match &location {
            DbLocation::Sqlite(path) => {
                let raw = rusqlite::Connection::open(path).expect("raw open");
                for sql in attempts {
                    let error = raw.execute(sql, []).expect_err(sql).to_string();
                    assert!(error.contains("append-only"), "{sql}: {error}");
                }
            }
            DbLocation::Postgres(url) => {
                let mut raw = postgres::Client::connect(url, postgres::NoTls).expect("raw");
                for sql in attempts.iter().chain(&["TRUNCATE imucal_calibrations"]) {
                    let error = raw.batch_execute(sql).expect_err(sql);
                    let message = error.as_db_error().map(|e| e.message().to_string());
                    assert!(
                        message.as_deref().unwrap_or("").contains("append-only"),
                        "{sql}: {error}"
                    );
                }
            }
        }
        assert_eq!(store.records(None).expect("read").len(), 1);
    }
}

#[test]
fn changes_since_the_previous_calibration_are_in_combined_sigma() {
    for location in databases("changes") {
        let mut store = HistoryStore::open(&location).expect("open");
        let before = board_record(3);
        let mut after = before.clone();
        after.recorded_unix_ms += 86_400_000;
        // Offset moved by 0.05 m/s²; σ 1 mg·g before and 2 mg·g after.
        after.params.accel.b[0] += 0.05;
        after
            .sigma
            .insert("accel.b.x".into(), 2.0 * before.sigma["accel.b.x"]);
        store.record(&before).expect("write");
        store.record(&after).expect("write");
        let history = device_changes(store.records(None).expect("read"));
        assert_eq!(history.len(), 2);
        assert!(history[0].changes.is_empty() && history[0].previous.is_none());
        let change = &history[1].changes[0];
        assert_eq!(change.parameter, "accel.b.x", "largest change first");
        let sigma = before.sigma["accel.b.x"] * 5f64.sqrt();
        assert!((change.change - 0.05).abs() < 1e-12);
        let expected = 0.05 / sigma;
        assert!(
            (change.change_sigma.expect("both have σ") - expected).abs() < 1e-9,
            "{change:?} vs {expected}"
        );
        // A parameter without σ in one record has no σ-scaled change.
        let noise = history[1]
            .changes
            .iter()
            .find(|c| c.parameter == "gyro.noise.x")
            .expect("noise compared");
        assert_eq!(noise.change_sigma, None);
        assert_eq!(noise.change, 0.0);
    }
}

#[test]
fn changes_are_measured_against_the_set_on_the_board_not_an_unwritten_attempt() {
    for location in databases("since_on_board") {
        let mut store = HistoryStore::open(&location).expect("open");
        let first = board_record(6);
        // A refused attempt far off, then a good set close to the first.
        let mut refused = first.clone();
        refused.recorded_unix_ms += 3_600_000;
        refused.params.accel.b[0] += 2.0;
        refused.board = imucal::history::BoardWrite::NotWritten {
            reason: "outlier against the fleet".into(),
        };
        let mut second = first.clone();
        second.recorded_unix_ms += 7_200_000;
        second.params.accel.b[0] += 0.01;
        for record in [&first, &refused, &second] {
            store.record(record).expect("write");
        }
        let history = device_changes(store.records(None).expect("read"));
        let ids: Vec<_> = history.iter().map(|h| h.stored.id).collect();
        assert_eq!(
            history[1].previous,
            Some(ids[0]),
            "the refused one vs the board's set"
        );
        assert_eq!(
            history[2].previous,
            Some(ids[0]),
            "the unwritten attempt is skipped"
        );
        assert_eq!(history[2].not_written_between, vec![ids[1]]);
        let change = history[2]
            .changes
            .iter()
            .find(|c| c.parameter == "accel.b.x")
            .expect("offset compared");
        // 0.01 m/s² since the set on the board, not −1.99 since the refused attempt.
        assert!((change.change - 0.01).abs() < 1e-12, "{change:?}");
    }
}

#[test]
fn a_sensor_fitted_anew_or_from_another_unit_is_named_and_not_compared() {
    for location in databases("sensor_changes") {
        let mut store = HistoryStore::open(&location).expect("open");
        let mut before = board_record(4);
        before
            .params
            .not_fitted
            .insert("gyro".into(), "never rested".into());
        let mut after = board_record(4);
        after.recorded_unix_ms += 86_400_000;
        // The accelerometer fitted from raw counts this time: A and b map counts.
        after.params.accel.input_unit = Some("counts".into());
        after.params.accel.b = [120.0, -80.0, 40.0];
        store.record(&before).expect("write");
        store.record(&after).expect("write");
        let history = device_changes(store.records(None).expect("read"));
        let latest = &history[1];
        assert_eq!(
            latest.sensor_changes,
            vec![
                SensorChange::InputUnitChanged {
                    sensor: "accel".into(),
                    before: "nominal units".into(),
                    after: "counts".into(),
                },
                SensorChange::NowFitted {
                    sensor: "gyro".into()
                },
            ],
            "{}",
            location.display()
        );
        // Neither sensor's parameters are differences of like with like.
        assert!(
            !latest
                .changes
                .iter()
                .any(|c| c.parameter.starts_with("accel.") || c.parameter.starts_with("gyro.")),
            "{:?}",
            latest.changes
        );
        assert!(latest
            .changes
            .iter()
            .any(|c| c.parameter.starts_with("mag.")));
        assert_eq!(
            latest.sensor_changes[1].sentence(),
            "gyro now calibrated",
            "what `history` prints"
        );
    }
}

#[test]
fn failed_opens_and_writes_say_what_and_how_to_fix() {
    let dir = history_support::scratch_dir("failures");
    let blocker = dir.join("not-a-dir");
    std::fs::write(&blocker, "x").expect("file");
    let error = HistoryStore::open(&DbLocation::Sqlite(blocker.join("h.sqlite")))
        .err()
        .expect("a file as directory");
    assert!(matches!(error, HistoryError::CreateDir { .. }), "{error}");

    let error = HistoryStore::open_url(Some("postgres://nobody@/none?host=/nonexistent&port=1"))
        .err()
        .expect("no server");
    let text = error.to_string();
    assert!(
        matches!(error, HistoryError::Open { .. }) && text.contains("server is running"),
        "{text}"
    );

    for location in databases("bad_values") {
        let mut store = HistoryStore::open(&location).expect("open");
        let mut record = board_record(4);
        record.params.mag.b[2] = f64::NAN;
        let error = store.record(&record).expect_err("NaN refused");
        let text = error.to_string();
        assert!(
            text.contains("mag.b.z is NaN") && text.contains("still holds it"),
            "{text}"
        );
        assert!(store.records(None).expect("read").is_empty());
    }
}

#[test]
fn reading_a_history_that_does_not_exist_says_so_and_creates_nothing() {
    let dir = history_support::scratch_dir("missing");
    let path = dir.join("typo").join("history.sqlite");
    let url = format!("sqlite://{}", path.display());
    let error = HistoryStore::open_existing_url(Some(&url))
        .err()
        .expect("a missing file refused");
    let text = error.to_string();
    assert!(
        matches!(error, HistoryError::Missing { .. }) && text.contains("--db"),
        "{text}"
    );
    assert!(!path.exists() && !dir.join("typo").exists());
    // Once something is recorded there, reading works.
    HistoryStore::open_url(Some(&url))
        .expect("open to record")
        .record(&board_record(1))
        .expect("recorded");
    let mut store = HistoryStore::open_existing_url(Some(&url)).expect("now it exists");
    assert_eq!(store.records(None).expect("read").len(), 1);
}

/// Records each writer process adds.
const PER_WRITER: u64 = 25;
/// Writer processes.
const WRITERS: u64 = 6;
/// Set in a child process: the database URL and the writer's number.
const CHILD_ENV: &str = "IMUCAL_TEST_HISTORY_WRITER";

/// Runs only as a child of the concurrency test (it is ignored otherwise).
#[test]
#[ignore = "run by concurrent_writers_in_separate_processes_lose_no_record"]
fn writer_process() {
    let Ok(job) = std::env::var(CHILD_ENV) else {
        return;
    };
    let (writer, url) = job.split_once(' ').expect("`N URL`");
    let writer: u64 = writer.parse().expect("writer number");
    let mut store = HistoryStore::open_url(Some(url)).expect("child open");
    for i in 0..PER_WRITER {
        let mut record = board_record(1000 * writer + i);
        record.station = Some(format!("writer {writer}"));
        store.record(&record).expect("child write");
    }
}

#[test]
fn concurrent_writers_in_separate_processes_lose_no_record() {
    let exe = std::env::current_exe().expect("test binary");
    for location in databases("concurrent") {
        let url = url(&location);
        let children: Vec<_> = (0..WRITERS)
            .map(|writer| {
                Command::new(&exe)
                    .args(["--exact", "writer_process", "--ignored"])
                    .env(CHILD_ENV, format!("{writer} {url}"))
                    .stdout(Stdio::piped())
                    .stderr(Stdio::piped())
                    .spawn()
                    .expect("spawn writer")
            })
            .collect();
        for child in children {
            let out = child.wait_with_output().expect("writer ran");
            assert!(
                out.status.success(),
                "a writer failed on {}: {}{}",
                location.display(),
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
        }
        let mut store = HistoryStore::open(&location).expect("open");
        let records = store.records(None).expect("read");
        assert_eq!(
            records.len() as u64,
            WRITERS * PER_WRITER,
            "{}",
            location.display()
        );
        let mut ids: Vec<i64> = records.iter().map(|r| r.id.0).collect();
        ids.sort_unstable();
        ids.dedup();
        assert_eq!(ids.len() as u64, WRITERS * PER_WRITER, "unique keys");
        for writer in 0..WRITERS {
            let station = format!("writer {writer}");
            let mine = records
                .iter()
                .filter(|r| r.record.station.as_deref() == Some(station.as_str()))
                .count() as u64;
            assert_eq!(mine, PER_WRITER, "{station} on {}", location.display());
        }
    }
}

/// Stations that open a new SQLite file at the same moment all get in: switching the file to
/// the WAL journal is retried while another opener holds the lock (SQLite reports "database is
/// locked" there without waiting). Twenty fresh files make the race near certain to be hit.
#[test]
fn stations_opening_a_new_sqlite_file_together_all_get_in() {
    let dir = history_support::scratch_dir("open_together");
    for round in 0..20u64 {
        let path = dir.join(format!("history{round}.sqlite"));
        let openers: Vec<_> = (0..WRITERS)
            .map(|writer| {
                let location = DbLocation::Sqlite(path.clone());
                std::thread::spawn(move || {
                    let mut store = HistoryStore::open(&location).map_err(|e| e.to_string())?;
                    store
                        .record(&board_record(100 * round + writer))
                        .map_err(|e| e.to_string())
                })
            })
            .collect();
        for opener in openers {
            let outcome = opener.join().expect("opener thread");
            assert!(outcome.is_ok(), "round {round}: {outcome:?}");
        }
    }
}

#[test]
fn a_boards_history_plots_each_parameter_group_over_time() {
    let mut first = board_record(5);
    first.recorded_unix_ms = 0;
    let mut second = first.clone();
    second.recorded_unix_ms = 2 * 86_400_000;
    second.params.mag.b[0] += 30.0;
    let location = &databases("plot")[0];
    let mut store = HistoryStore::open(location).expect("open");
    store.record(&first).expect("write");
    store.record(&second).expect("write");
    let records = store.records(None).expect("read");
    let series = imucal::history::plot::parameter_series(&records, "mag.b.x");
    assert_eq!(series.len(), 2);
    assert_eq!(series[1].0, 2.0, "days since the first calibration");
    assert!((series[1].1 - series[0].1 - 30.0).abs() < 1e-9);
    let figures = imucal::history::plot::parameters_over_time(&records).expect("plots");
    let titles: Vec<&str> = figures.iter().map(|(t, _)| t.as_str()).collect();
    assert_eq!(
        titles,
        [
            "Accelerometer offset",
            "Accelerometer gain (diagonal of A)",
            "Gyroscope offset",
            "Magnetometer offset",
            "Magnetometer gain (diagonal of A)"
        ]
    );
    for (title, svg) in &figures {
        assert!(
            svg.starts_with("<svg") && svg.contains("polyline"),
            "{title}"
        );
    }
}

/// A database as a build of schema version 1 left it, holding `record`.
fn write_version_1_database(location: &DbLocation, record: &CalibrationRecord) {
    use imucal::history::schema::{
        migration_v1, to_row, Dialect, SqlValue, COLUMNS, TABLE, VERSION_TABLE,
    };
    // Version 1 had the first 15 columns.
    let row: Vec<SqlValue> = to_row(record).into_iter().take(15).collect();
    let names: Vec<&str> = COLUMNS[..15].iter().map(|(name, _)| *name).collect();
    let params: Vec<String> = (1..=15).map(|i| format!("${i}")).collect();
    let insert = format!(
        "INSERT INTO {TABLE} ({}) VALUES ({})",
        names.join(", "),
        params.join(", ")
    );
    let version = [
        format!("CREATE TABLE {VERSION_TABLE} (version BIGINT NOT NULL)"),
        format!("INSERT INTO {VERSION_TABLE} (version) VALUES (1)"),
    ];
    match location {
        DbLocation::Sqlite(path) => {
            let connection = rusqlite::Connection::open(path).expect("create SQLite file");
            for statement in version.iter().cloned().chain(migration_v1(Dialect::Sqlite)) {
                connection
                    .execute(&statement, [])
                    .expect("version 1 schema");
            }
            let values = row.iter().map(|v| match v {
                SqlValue::Text(t) => rusqlite::types::Value::Text(t.clone()),
                SqlValue::Int(i) => rusqlite::types::Value::Integer(*i),
                SqlValue::Null => rusqlite::types::Value::Null,
            });
            connection
                .execute(&insert, rusqlite::params_from_iter(values))
                .expect("version 1 row");
        }
        DbLocation::Postgres(url) => {
            let mut client = postgres::Client::connect(url, postgres::NoTls).expect("connect");
            for statement in version
                .iter()
                .cloned()
                .chain(migration_v1(Dialect::Postgres))
            {
                client.batch_execute(&statement).expect("version 1 schema");
            }
            let null: Option<&str> = None;
            let params: Vec<&(dyn postgres::types::ToSql + Sync)> = row
                .iter()
                .map(|v| match v {
                    SqlValue::Text(t) => t as &(dyn postgres::types::ToSql + Sync),
                    SqlValue::Int(i) => i as &(dyn postgres::types::ToSql + Sync),
                    SqlValue::Null => &null as &(dyn postgres::types::ToSql + Sync),
                })
                .collect();
            client.execute(&insert, &params).expect("version 1 row");
        }
    }
}

#[test]
fn a_version_1_history_upgrades_on_open_keeping_its_records_as_written_sets() {
    for location in databases("upgrade_v1") {
        let old = board_record(8);
        write_version_1_database(&location, &old);
        let mut store = HistoryStore::open(&location).expect("a version 1 history opens");
        let records = store.records(None).expect("read");
        assert_eq!(records.len(), 1, "{}", location.display());
        // Version 1 recorded only sets that were written.
        assert_eq!(records[0].record, old, "{}", location.display());
        assert_eq!(
            records[0].record.board,
            imucal::history::BoardWrite::Written
        );
        let mut refused = board_record(9);
        refused.board = imucal::history::BoardWrite::NotWritten {
            reason: "poor verdict".into(),
        };
        store.record(&refused).expect("a version 2 record is added");
        drop(store);
        // Opening again finds version 2 and changes nothing.
        let mut store = HistoryStore::open(&location).expect("the upgraded history opens again");
        let records = store.records(None).expect("read");
        assert_eq!(records.len(), 2);
        assert_eq!(records[1].record, refused, "{}", location.display());
    }
}

#[test]
fn the_history_command_gives_crcs_as_hex_and_fails_naming_the_boards_for_an_unknown_one() {
    let dir = history_support::scratch_dir("cli-unknown");
    let url = format!("sqlite://{}", dir.join("history.sqlite").display());
    let mut store = HistoryStore::open_url(Some(&url)).expect("open");
    let record = board_record(3);
    store.record(&record).expect("recorded");
    let history = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_imucal"))
            .args(["history", "--db", &url])
            .args(args)
            .output()
            .expect("imucal history runs")
    };
    let out = history(&["--json"]);
    assert!(out.status.success());
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    // As `info`, the session files and the table print it.
    assert_eq!(
        json["records"][0]["params_crc"],
        format!("{:#010x}", record.params_crc).as_str(),
        "{json}"
    );
    // A mistyped id is an error that lists the boards there are, in both forms.
    for args in [&["0123"][..], &["0123", "--json"][..]] {
        let out = history(args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(
            stderr.contains("no calibration of board `0123`"),
            "{stderr}"
        );
        assert!(stderr.contains(&record.device_id), "{stderr}");
    }
    // The board that is there is listed.
    assert!(history(&[&record.device_id]).status.success());
}

#[test]
fn a_large_change_the_fits_gave_no_sigma_for_is_named_in_the_default_list() {
    let dir = history_support::scratch_dir("cli-unscaled");
    let url = format!("sqlite://{}", dir.join("history.sqlite").display());
    let mut store = HistoryStore::open_url(Some(&url)).expect("open");
    let before = board_record(3);
    let mut after = before.clone();
    after.recorded_unix_ms += 86_400_000;
    // Small changes of the accelerometer's gains and one offset, which have σ, and a 5 %
    // gyroscope gain change that neither record has a σ for.
    for k in 0..3 {
        after.params.accel.a[k][k] += 1e-6;
    }
    after.params.accel.b[1] += 1e-6;
    after.params.gyro.a[0][0] *= 1.05;
    after.sigma.remove("gyro.A.xx");
    let mut before_no_gyro_sigma = before.clone();
    before_no_gyro_sigma.sigma.remove("gyro.A.xx");
    store.record(&before_no_gyro_sigma).expect("write");
    store.record(&after).expect("write");
    let history = device_changes(store.records(None).expect("read"));
    let changes = &history[1].changes;
    let gyro = changes
        .iter()
        .position(|c| c.parameter == "gyro.A.xx")
        .expect("compared");
    // Ranked first among those without σ, after every one with σ.
    assert!(changes[..gyro].iter().all(|c| c.change_sigma.is_some()));
    assert!(changes[gyro + 1..].iter().all(|c| c.change_sigma.is_none()));
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(["history", "--db", &url, &before.device_id])
        .output()
        .expect("imucal history runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    assert!(
        stdout.contains("gyro.A.xx") && stdout.contains("+5.00 % of its value; no σ"),
        "{stdout}"
    );
}
