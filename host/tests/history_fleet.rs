//! The fleet outlier test on a history seeded with simulated boards, some with hardware faults:
//! exactly the faulty boards are flagged, each with its cause; the check before writing flags a
//! faulty newcomer and passes a healthy one; `imucal fleet` and `imucal history` print them.

mod history_support;

use std::process::Command;

use history_support::{board_record, databases, url};
use imucal::history::fleet::FleetModel;
use imucal::history::{
    fleet_report, is_outlier_against_fleet, BoardWrite, CalibrationRecord, FleetOptions,
    HistoryStore,
};

/// Healthy boards in the seeded fleet.
const HEALTHY: u64 = 56;

/// A hardware fault, applied to a healthy board's record, and the words its cause must contain.
struct Fault {
    name: &'static str,
    apply: fn(&mut CalibrationRecord),
    cause: &'static str,
}

const FAULTS: [Fault; 4] = [
    Fault {
        // A cracked y axis reads 0.2 g off (the healthy range is ±0.03 g).
        name: "accel offset",
        apply: |r| r.params.accel.b[1] += 2.0,
        cause: "accelerometer offset on axis y",
    },
    Fault {
        // A damaged z axis with 25 % too little gain (healthy: ±3 %).
        name: "accel gain",
        apply: |r| r.params.accel.a[2][2] *= 1.25,
        cause: "gain error on axis z",
    },
    Fault {
        // A small magnet a few cm away adds hundreds of µT of hard iron (healthy: ±50 µT).
        name: "magnet",
        apply: |r| {
            for (b, shift) in r.params.mag.b.iter_mut().zip([320.0, -150.0, 410.0]) {
                *b += shift;
            }
        },
        cause: "magnet near the board",
    },
    Fault {
        // A damaged gyro x axis with five times the noise.
        name: "gyro noise",
        apply: |r| {
            if let Some(n) = r.noise.get_mut("gyro.noise.x") {
                *n *= 5.0;
            }
        },
        cause: "excess gyroscope noise on axis x",
    },
];

/// Seeds 56 healthy and 4 faulty boards; returns the faulty boards' ids with their faults.
fn seed(store: &mut HistoryStore) -> Vec<(String, &'static Fault)> {
    let mut faulty = Vec::new();
    for seed in 0..HEALTHY + FAULTS.len() as u64 {
        let mut record = board_record(seed);
        if let Some(fault) = seed.checked_sub(HEALTHY).map(|i| &FAULTS[i as usize]) {
            (fault.apply)(&mut record);
            faulty.push((record.device_id.clone(), fault));
        }
        store.record(&record).expect("seed write");
    }
    faulty
}

#[test]
fn of_sixty_simulated_boards_exactly_the_faulty_ones_are_flagged_with_their_cause() {
    for location in databases("fleet") {
        let mut store = HistoryStore::open(&location).expect("open");
        let faulty = seed(&mut store);
        let report = fleet_report(&mut store, &FleetOptions::default()).expect("fleet");
        assert_eq!(report.boards, 60);
        // 1e-3 false alarms per board over ~45 parameters and ν ≈ 22: z* between 5 and 7.
        assert!(
            (5.0..7.0).contains(&report.threshold_z),
            "{}",
            report.threshold_z
        );
        let flagged: Vec<&str> = report
            .results
            .iter()
            .filter(|b| b.outlier)
            .map(|b| b.device_id.as_str())
            .collect();
        let mut expected: Vec<&str> = faulty.iter().map(|(id, _)| id.as_str()).collect();
        let mut got = flagged.clone();
        expected.sort_unstable();
        got.sort_unstable();
        assert_eq!(got, expected, "{}", location.display());
        for (id, fault) in &faulty {
            let board = report
                .results
                .iter()
                .find(|b| &b.device_id == id)
                .expect("listed");
            let cause = &board.findings[0].likely_cause;
            assert!(cause.contains(fault.cause), "{}: {cause}", fault.name);
        }
        // A healthy board's largest distance stays well inside the threshold.
        let healthy_max = report
            .results
            .iter()
            .filter(|b| !b.outlier)
            .map(|b| b.max_abs_z)
            .fold(0.0, f64::max);
        assert!(healthy_max < report.threshold_z, "{healthy_max}");
    }
}

#[test]
fn a_new_board_is_checked_against_the_fleet_before_writing() {
    for location in databases("precheck") {
        let mut store = HistoryStore::open(&location).expect("open");
        seed(&mut store);
        let options = FleetOptions::default();
        let healthy = board_record(500);
        let check = is_outlier_against_fleet(&healthy, &mut store, &options).expect("check");
        assert!(check.tested && !check.outlier, "{check:?}");
        assert_eq!(check.fleet_boards, 60);

        let mut magnet = board_record(501);
        (FAULTS[2].apply)(&mut magnet);
        let check = is_outlier_against_fleet(&magnet, &mut store, &options).expect("check");
        assert!(check.outlier, "{check:?}");
        assert!(check.findings[0].parameter.starts_with("mag.b"));

        // A board compared with itself does not count: its own old record is left out.
        let again = is_outlier_against_fleet(&board_record(0), &mut store, &options).expect("");
        assert_eq!(again.fleet_boards, 59);
    }
}

#[test]
fn too_small_a_fleet_is_not_tested_and_says_so() {
    for location in databases("small_fleet") {
        let mut store = HistoryStore::open(&location).expect("open");
        for seed in 0..5 {
            store.record(&board_record(seed)).expect("write");
        }
        let options = FleetOptions::default();
        let error = fleet_report(&mut store, &options).expect_err("5 boards");
        assert!(error.to_string().contains("at least 7"), "{error}");
        let check = is_outlier_against_fleet(&board_record(9), &mut store, &options).expect("");
        assert!(!check.tested && !check.outlier);
        assert!(check.note.expect("why").contains("5 boards"));
    }
}

fn imucal(args: &[&str]) -> serde_json::Value {
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(args)
        .output()
        .expect("imucal runs");
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("JSON on stdout")
}

#[test]
fn fleet_and_history_commands_list_outliers_and_changes_as_json() {
    for location in databases("cli") {
        let mut store = HistoryStore::open(&location).expect("open");
        let faulty = seed(&mut store);
        let db = url(&location);
        let fleet = imucal(&["fleet", "--db", &db, "--json"]);
        let outliers: Vec<&str> = fleet["results"]
            .as_array()
            .expect("results")
            .iter()
            .filter(|b| b["outlier"] == true)
            .map(|b| b["device_id"].as_str().expect("id"))
            .collect();
        assert_eq!(outliers.len(), faulty.len(), "{fleet}");

        let device = &faulty[0].0;
        let mut again = board_record(HEALTHY);
        again.recorded_unix_ms += 1000;
        // A gyroscope bias change far below the table's old four decimals.
        again.params.gyro.b[0] += 2e-5;
        store.record(&again).expect("second calibration");
        // The table lists the largest change, in three significant digits, and says how many
        // more there are.
        let table = |shown: &str| {
            let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
                .args(["history", device, "--db", &db, "--changes", shown])
                .output()
                .expect("imucal runs");
            String::from_utf8_lossy(&out.stdout).into_owned()
        };
        let one = table("1");
        assert!(
            one.contains("accel.b.y -2.00e0 (")
                && one.contains("and 1 more (--changes 2 lists them)"),
            "{one}"
        );
        let two = table("2");
        assert!(
            two.contains("gyro.b.x +2.00e-5") && !two.contains(" more "),
            "{two}"
        );
        let history = imucal(&["history", device, "--db", &db, "--json"]);
        let records = history["records"].as_array().expect("records");
        assert_eq!(records.len(), 2);
        // The repaired board's y offset came back by 2 m/s², i.e. 2/(√2·1 mg·g) ≈ 144 σ.
        let change = &records[1]["changes"][0];
        assert_eq!(change["parameter"], "accel.b.y");
        let sigma = change["change_sigma"].as_f64().expect("σ");
        assert!(
            (sigma + 2.0 / (2f64.sqrt() * 9.806_65e-3)).abs() < 1.0,
            "{sigma}"
        );
    }
}

/// A first batch on an empty history: seven healthy boards and one faulty one, drawn from the
/// simulator's population. Too few for a spread per parameter, so offsets, gains, cross-axis
/// terms and noise are compared with their sensor's axes pooled; the fault is found with its cause.
#[test]
fn in_a_fleet_of_eight_the_faulty_board_is_found_with_the_axes_pooled() {
    for (i, fault) in FAULTS.iter().enumerate() {
        let records: Vec<CalibrationRecord> = (0..8)
            .map(|b| {
                let mut record = board_record(1000 + 8 * i as u64 + b);
                if b == 7 {
                    (fault.apply)(&mut record);
                }
                record
            })
            .collect();
        let refs: Vec<&CalibrationRecord> = records.iter().collect();
        let model = FleetModel::fit(&refs[..7], &FleetOptions::default()).expect("seven boards");
        for healthy in &records[..7] {
            assert!(model.outlying(healthy).is_empty(), "{}", fault.name);
        }
        let findings = model.outlying(&records[7]);
        assert!(!findings.is_empty(), "{}", fault.name);
        assert!(
            findings[0].likely_cause.contains(fault.cause),
            "{}: {}",
            fault.name,
            findings[0].likely_cause
        );
    }
}

#[test]
fn a_set_fitted_from_raw_counts_is_not_compared_with_a_fleet_in_nominal_units() {
    // Seven healthy boards in m/s², and one whose accelerometer set maps raw counts
    // (16384 per g): its offset in counts is thousands of the fleet's m/s² away.
    let records: Vec<CalibrationRecord> = (0..8)
        .map(|b| {
            let mut record = board_record(2000 + b);
            if b == 7 {
                record.params.accel.input_unit = Some("counts".into());
                record.params.accel.b = [703.0, -361.0, -1834.0];
                for k in 0..3 {
                    record.params.accel.a[k][k] = 9.80665 / 16384.0;
                }
            }
            record
        })
        .collect();
    let refs: Vec<&CalibrationRecord> = records.iter().collect();
    let model = FleetModel::fit(&refs, &FleetOptions::default()).expect("eight boards");
    for healthy in &records[..7] {
        assert!(model.outlying(healthy).is_empty());
    }
    let findings = model.outlying(&records[7]);
    assert!(
        findings.iter().all(|f| !f.parameter.starts_with("accel.")),
        "{findings:?}"
    );
    // The same numbers declared in m/s² are a gross fault: what protects the board above is
    // that its unit is known, not that its values are near.
    let mut mislabelled = records[7].clone();
    mislabelled.params.accel.input_unit = None;
    assert!(model
        .outlying(&mislabelled)
        .iter()
        .any(|f| f.parameter.starts_with("accel.")));
}

/// The pooled small-fleet test keeps its stated false-alarm rate: over 300 batches of eight
/// healthy boards (2 400 boards, each compared with the other seven), the expected number of
/// flagged boards at 0.1 % per board is 2.4; more than 10 (Poisson tail below 10⁻⁴) would mean
/// the threshold is too tight for the pooled spread.
#[test]
fn healthy_boards_of_small_batches_are_rarely_flagged() {
    let mut flagged = 0;
    for batch in 0..300u64 {
        let records: Vec<CalibrationRecord> =
            (0..8).map(|b| board_record(5000 + 8 * batch + b)).collect();
        for i in 0..8 {
            let others: Vec<&CalibrationRecord> = records
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .map(|(_, r)| r)
                .collect();
            let model = FleetModel::fit(&others, &FleetOptions::default()).expect("seven boards");
            flagged += usize::from(!model.outlying(&records[i]).is_empty());
        }
    }
    eprintln!("{flagged} of 2400 healthy boards flagged");
    assert!(flagged <= 10, "{flagged} of 2400 healthy boards flagged");
}

#[test]
fn six_boards_are_too_few_to_test() {
    let records: Vec<CalibrationRecord> = (0..6).map(|b| board_record(900 + b)).collect();
    let refs: Vec<&CalibrationRecord> = records.iter().collect();
    let error = FleetModel::fit(&refs, &FleetOptions::default()).expect_err("too few");
    assert!(error.to_string().contains("at least 7"), "{error}");
}

/// Attempts refused before their write are tested against the fleet and listed with the
/// reason, but the fleet's statistics count only the sets on boards; `imucal history` says
/// plainly that such a set was not written, and why.
#[test]
fn sets_not_written_are_labelled_and_not_counted_in_the_fleet() {
    for location in databases("not_written") {
        let mut store = HistoryStore::open(&location).expect("open");
        seed(&mut store);
        let refusal = BoardWrite::NotWritten {
            reason: "outlier against the fleet".into(),
        };
        // A new board refused as an outlier (a magnet near it), and a healthy board of the
        // fleet whose later attempt was refused: its earlier set stays on it.
        let mut newcomer = board_record(HEALTHY + 100);
        (FAULTS[2].apply)(&mut newcomer);
        newcomer.board = refusal.clone();
        store.record(&newcomer).expect("write");
        let mut retry = board_record(3);
        retry.recorded_unix_ms += 1000;
        (FAULTS[0].apply)(&mut retry);
        retry.board = refusal.clone();
        let retry_id = store.record(&retry).expect("write");

        let report = fleet_report(&mut store, &FleetOptions::default()).expect("report");
        assert_eq!(report.boards, 60, "the 60 sets on boards only");
        let offsets = report
            .parameters
            .iter()
            .find(|p| p.parameter == "mag.b.x")
            .expect("magnetometer offsets are compared");
        assert_eq!(offsets.boards, 60);
        let newcomer_result: Vec<_> = report
            .results
            .iter()
            .filter(|b| b.device_id == newcomer.device_id)
            .collect();
        assert_eq!(newcomer_result.len(), 1);
        assert!(newcomer_result[0].outlier);
        assert_eq!(
            newcomer_result[0].not_written.as_deref(),
            Some("outlier against the fleet")
        );
        let retried: Vec<_> = report
            .results
            .iter()
            .filter(|b| b.device_id == retry.device_id)
            .map(|b| (b.outlier, b.not_written.is_some()))
            .collect();
        assert_eq!(
            retried.len(),
            2,
            "the set on the board and the refused attempt"
        );
        assert!(retried.contains(&(false, false)) && retried.contains(&(true, true)));

        // The check before a write compares with the sets on boards only.
        let check = is_outlier_against_fleet(
            &board_record(HEALTHY + 101),
            &mut store,
            &FleetOptions::default(),
        )
        .expect("check");
        assert_eq!(check.fleet_boards, 60);

        let db = url(&location);
        let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
            .args(["history", &newcomer.device_id, "--db", &db])
            .output()
            .expect("imucal runs");
        let table = String::from_utf8_lossy(&out.stdout);
        assert!(
            table.contains("NOT WRITTEN to the board: outlier against the fleet"),
            "{table}"
        );
        // A good set after the refused attempt is compared with the set the board held, and
        // the history says the attempt between was skipped.
        let mut again = board_record(3);
        again.recorded_unix_ms += 2000;
        store.record(&again).expect("write");
        let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
            .args(["history", &retry.device_id, "--db", &db])
            .output()
            .expect("imucal runs");
        let table = String::from_utf8_lossy(&out.stdout);
        let since = table
            .lines()
            .rfind(|l| l.contains("since #"))
            .expect("the last record is compared");
        assert!(
            since.contains(&format!(
                "the set on the board before; #{retry_id} was not written"
            )) && since.contains("no parameter changed"),
            "{table}"
        );
    }
}

#[test]
fn one_recording_fitted_nine_ways_is_no_fleet_of_outliers_because_each_fit_records_its_sigma() {
    // The same boards' data, fitted with slightly different still-detection settings: the
    // parameters differ within their own uncertainty, which `fit --params-out` records, so the
    // fleet weighs them by it and flags none. Without the σ the tiny spread between the fits
    // made µg differences "gross offsets".
    let dir = history_support::scratch_dir("fit-sigma-fleet");
    let db = format!("sqlite://{}", dir.join("history.sqlite").display());
    let recording = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../data/real/imucal_nilspod_ferraris.csv");
    let variants: [&[&str]; 9] = [
        &["--window", "0.5"],
        &["--window", "0.4"],
        &["--window", "0.6"],
        &["--window", "0.7"],
        &["--min-hold", "2"],
        &["--min-hold", "1.5"],
        &["--window", "0.3"],
        &["--window", "0.8"],
        &["--still-margin", "100"],
    ];
    for (i, variant) in variants.iter().enumerate() {
        let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
            .args(["fit", "--gyro-unit", "dps", "--db", &db])
            .args(*variant)
            .arg("--params-out")
            .arg(dir.join(format!("p{i}.json")))
            .args(["--device", &format!("board{i}")])
            .arg(&recording)
            .output()
            .expect("imucal runs");
        assert!(
            out.status.success(),
            "{variant:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let history = imucal(&["history", "--db", &db, "board0", "--json"]);
    let sigma = &history["records"][0]["sigma"];
    for name in ["accel.b.x", "accel.A.xx", "gyro.b.z"] {
        assert!(
            sigma[name].as_f64().is_some_and(|s| s > 0.0),
            "{name}: {history}"
        );
    }
    let fleet = imucal(&["fleet", "--db", &db, "--json"]);
    let results = fleet["results"].as_array().expect("results");
    assert_eq!(results.len(), 9, "{fleet}");
    assert!(results.iter().all(|b| b["outlier"] == false), "{fleet}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_false_alarm_rate_too_small_to_flag_anything_is_refused() {
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args([
            "fleet",
            "--db",
            "sqlite:///nonexistent/never.sqlite",
            "--false-alarm",
            "1e-300",
        ])
        .output()
        .expect("imucal runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("--false-alarm is 1e-300") && stderr.contains("1e-12"),
        "{stderr}"
    );
}

#[test]
fn matrix_entries_a_model_does_not_estimate_are_not_pooled_and_sensors_on_too_few_boards_are_named()
{
    // Twenty boards whose gyroscope was fitted for its offset only (A exactly the identity),
    // of which five also have a magnetometer: too few for its spread.
    let records: Vec<CalibrationRecord> = (0..20)
        .map(|b| {
            let mut record = board_record(3000 + b);
            record.params.gyro.a = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
            if b >= 5 {
                record
                    .params
                    .not_fitted
                    .insert("mag".into(), "not in the recording".into());
            }
            record
        })
        .collect();
    let refs: Vec<&CalibrationRecord> = records.iter().collect();
    let model = FleetModel::fit(&refs, &FleetOptions::default()).expect("twenty boards");
    let mut store = HistoryStore::open(&databases("fixed_entries")[0]).expect("store");
    for record in &records {
        store.record(record).expect("recorded");
    }
    let report = fleet_report(&mut store, &FleetOptions::default()).expect("a report");
    let tested: Vec<&str> = report
        .parameters
        .iter()
        .map(|p| p.parameter.as_str())
        .collect();
    assert!(
        !tested.iter().any(|p| p.starts_with("gyro.A")),
        "placeholders pooled as measurements: {tested:?}"
    );
    assert!(tested.contains(&"gyro.b.x") && tested.contains(&"accel.A.xy"));
    assert!(
        report
            .untested
            .iter()
            .any(|u| u.parameter == "mag.b.x" && u.boards == 5),
        "{:?}",
        report.untested
    );
    // A board whose gyroscope A was estimated is still compared on the entries it has.
    assert!(model
        .distances(&board_record(3100))
        .iter()
        .all(|f| !f.parameter.starts_with("gyro.A")));
}

#[test]
fn a_recording_fitted_without_a_board_is_tested_against_the_fleet_but_not_counted_in_it() {
    let mut store = HistoryStore::open(&databases("offline_recording")[0]).expect("store");
    for b in 0..8 {
        store.record(&board_record(4000 + b)).expect("recorded");
    }
    // What `fit --params-out` records for a recording fitted without --device.
    let mut offline = board_record(4100);
    offline.device_id = format!("{}nilspod", imucal::history::RECORDING_DEVICE_PREFIX);
    store.record(&offline).expect("recorded");
    let report = fleet_report(&mut store, &FleetOptions::default()).expect("a report");
    assert_eq!(report.boards, 8, "the recording is no board");
    let result = report
        .results
        .iter()
        .find(|r| r.device_id == offline.device_id)
        .expect("the recording is tested");
    assert!(
        result
            .not_written
            .as_deref()
            .is_some_and(|why| why.contains("on no board")),
        "{result:?}"
    );
}

#[test]
fn residuals_too_few_boards_have_are_named_in_full_with_the_boards_their_own_spread_needs() {
    // Nine boards: enough for the offsets with their axes pooled (7), too few for a residual,
    // which has no axes to pool and needs its own spread of 20.
    let location = &databases("untested_residuals")[0];
    let mut store = HistoryStore::open(location).expect("store");
    for b in 0..9 {
        store.record(&board_record(5000 + b)).expect("recorded");
    }
    let report = fleet_report(&mut store, &FleetOptions::default()).expect("a report");
    let residual = report
        .untested
        .iter()
        .find(|u| u.parameter == "accel.residual")
        .expect("the residual is untested");
    assert_eq!((residual.boards, residual.needed), (9, 20));
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(["fleet", "--db", &url(location)])
        .output()
        .expect("imucal runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    assert!(
        stdout.contains("accel.residual (on 9 of the 20 boards needed)")
            && stdout.contains("mag.residual (on 9 of the 20 boards needed)"),
        "{stdout}"
    );
    assert!(!stdout.contains("accel (on"), "{stdout}");
}

#[test]
fn an_offset_moved_on_every_axis_is_flagged_by_its_length_though_no_axis_is() {
    let records: Vec<CalibrationRecord> = (0..40).map(|b| board_record(3000 + b)).collect();
    let refs: Vec<&CalibrationRecord> = records.iter().collect();
    let model = FleetModel::fit(&refs, &FleetOptions::default()).expect("forty boards");
    let mut board = board_record(3100);
    let z_of = |record: &CalibrationRecord, name: &str| {
        let found = model.distances(record);
        let f = found.iter().find(|f| f.parameter == name).expect("tested");
        (f.robust_z, f.threshold_z)
    };
    // Each axis moved to 80 % of its own threshold: a magnet by the magnetometer moves all three.
    for (axis, name) in ["mag.b.x", "mag.b.y", "mag.b.z"].iter().enumerate() {
        let (z0, _) = z_of(&board, name);
        board.params.mag.b[axis] += 1.0;
        let (z1, threshold) = z_of(&board, name);
        let per_ut = z1 - z0;
        board.params.mag.b[axis] += (0.8 * threshold - z1) / per_ut;
    }
    let findings = model.outlying(&board);
    assert!(
        findings
            .iter()
            .all(|f| !f.parameter.starts_with("mag.b.") || f.parameter == "mag.b.length"),
        "no axis alone is beyond its threshold: {findings:?}"
    );
    let length = findings
        .iter()
        .find(|f| f.parameter == "mag.b.length")
        .unwrap_or_else(|| panic!("the offset's length is flagged: {findings:?}"));
    assert!(
        length.likely_cause.contains("magnet"),
        "{}",
        length.likely_cause
    );
    // The healthy fleet is not flagged by the length test.
    let flagged = records
        .iter()
        .filter(|r| {
            model
                .outlying(r)
                .iter()
                .any(|f| f.parameter.ends_with(".length"))
        })
        .count();
    assert_eq!(flagged, 0, "healthy boards flagged by an offset's length");
}

#[test]
fn a_flashed_sets_finding_names_a_hand_edited_or_foreign_file_among_its_causes() {
    let records: Vec<CalibrationRecord> = (0..8).map(|b| board_record(4000 + b)).collect();
    let refs: Vec<&CalibrationRecord> = records.iter().collect();
    let model = FleetModel::fit(&refs, &FleetOptions::default()).expect("eight boards");
    let mut flashed = board_record(4100);
    flashed.source = imucal::history::RecordSource::Flash;
    flashed.params.accel.a[0][0] = 1.5;
    let findings = model.outlying(&flashed);
    assert!(!findings.is_empty(), "A.xx = 1.5 is flagged");
    assert!(
        findings[0]
            .likely_cause
            .contains("hand-edited or foreign file"),
        "{}",
        findings[0].likely_cause
    );
    let mut guided = flashed.clone();
    guided.source = imucal::history::RecordSource::Guided;
    assert!(!model.outlying(&guided)[0]
        .likely_cause
        .contains("hand-edited"));
}

#[test]
fn fleet_json_with_too_few_boards_prints_an_object_with_the_reason_and_fails() {
    let dir = std::env::temp_dir().join(format!("imucal-fleet-json-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    let db = format!("sqlite://{}", dir.join("h.sqlite").display());
    {
        let location = imucal::history::DbLocation::parse(&db).expect("url");
        let mut store = HistoryStore::open(&location).expect("open");
        for seed in 0..3 {
            store.record(&board_record(seed)).expect("write");
        }
    }
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(["fleet", "--db", &db, "--json"])
        .output()
        .expect("imucal runs");
    assert_eq!(out.status.code(), Some(1));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON on stdout");
    assert_eq!(json["boards"], 3);
    assert!(
        json["error"]
            .as_str()
            .expect("a reason")
            .contains("at least"),
        "{json}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn fleet_option_values_out_of_range_exit_2_naming_the_cause_and_the_fix() {
    for (args, words) in [
        (&["--false-alarm", "1.5"][..], "would flag every board"),
        (
            &["--false-alarm", "1e-300"][..],
            "no board could ever be flagged",
        ),
        (&["--min-spread-values", "0"][..], "give 3 or more"),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
            .args(["fleet", "--db", "sqlite:///nonexistent/never.sqlite"])
            .args(args)
            .output()
            .expect("imucal runs");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(words), "{args:?}: {stderr}");
    }
}
