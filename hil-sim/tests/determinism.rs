//! Determinism: the same seed gives byte-identical CSV and truth, from the library and the binary.

use std::process::Command;

use imucal_hil_sim::poser::ScheduleKind;
use imucal_hil_sim::recording::{truth_json, write_csv, CSV_HEADER};
use imucal_hil_sim::{simulate_recording, SimConfig};

fn csv_bytes(seed: u64) -> (Vec<u8>, String) {
    let mut config = SimConfig::new(seed, ScheduleKind::Sweep);
    config.poser.sweep_repeats = 1;
    config.effects = [
        "bias_temperature",
        "bias_random_walk",
        "gyro.g_sensitivity=2",
        "bias_step",
    ]
    .iter()
    .map(|e| e.parse().unwrap())
    .collect();
    let recording = simulate_recording(&config).unwrap();
    let mut bytes = Vec::new();
    write_csv(&recording, &mut bytes).unwrap();
    (bytes, truth_json(&recording.truth).unwrap())
}

#[test]
fn same_seed_gives_identical_csv_and_truth_bytes() {
    let (csv_a, truth_a) = csv_bytes(41);
    let (csv_b, truth_b) = csv_bytes(41);
    assert_eq!(csv_a, csv_b);
    assert_eq!(truth_a, truth_b);
    let (csv_c, _) = csv_bytes(42);
    assert_ne!(
        csv_a, csv_c,
        "a different seed must give a different recording"
    );
}

#[test]
fn csv_has_the_documented_header_and_empty_pose_while_moving() {
    let (csv, _) = csv_bytes(43);
    let text = String::from_utf8(csv).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(CSV_HEADER));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert!(rows.iter().all(|r| r.len() == 12));
    let moving = rows.iter().filter(|r| r[11].is_empty()).count();
    let labels: std::collections::BTreeSet<usize> = rows
        .iter()
        .filter(|r| !r[11].is_empty())
        .map(|r| r[11].parse().unwrap())
        .collect();
    assert!(moving > 0);
    // One sweep repeat is twelve holds, labelled 0..=11.
    assert_eq!(labels, (0..12).collect());
}

#[test]
fn binary_record_writes_the_same_bytes_for_the_same_seed() {
    let exe = env!("CARGO_BIN_EXE_imucal-hil-sim");
    let dir = std::env::temp_dir().join(format!("imucal-hil-sim-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let run = |name: &str| {
        let csv = dir.join(format!("{name}.csv"));
        let truth = dir.join(format!("{name}.json"));
        let status = Command::new(exe)
            .args([
                "record",
                "--seed",
                "5",
                "--schedule",
                "tumble",
                "--effect",
                "mag.bias_drift=2",
            ])
            .arg("-o")
            .arg(&csv)
            .arg("--truth")
            .arg(&truth)
            .output()
            .unwrap();
        assert!(
            status.status.success(),
            "{}",
            String::from_utf8_lossy(&status.stderr)
        );
        (std::fs::read(csv).unwrap(), std::fs::read(truth).unwrap())
    };
    let first = run("first");
    let second = run("second");
    std::fs::remove_dir_all(&dir).ok();
    assert_eq!(first, second);
    assert!(first.0.starts_with(CSV_HEADER.as_bytes()));
}

#[test]
fn binary_rejects_bad_input_with_a_sentence_and_shows_an_example_in_help() {
    let exe = env!("CARGO_BIN_EXE_imucal-hil-sim");
    let help = Command::new(exe)
        .args(["record", "--help"])
        .output()
        .unwrap();
    assert!(String::from_utf8_lossy(&help.stdout).contains("Example:"));
    let bad = Command::new(exe)
        .args(["record", "--rate=-5", "-o", "/nonexistent/x.csv"])
        .output()
        .unwrap();
    assert!(!bad.status.success());
    let message = String::from_utf8_lossy(&bad.stderr);
    assert!(message.contains("sample rate"), "{message}");
}
