//! `imucal record` and `imucal stream` on a board that runs Adafruit's MotionCal calibration
//! sketch: the simulated sketch board (`--sim --sim-protocol motioncal`, in real time) is read
//! through its `Uni:` lines into the recording CSV, timed at the sketch's rate; a board that
//! prints only `Raw:` lines (fed here on a pseudo-terminal) is read with MotionCal's scales.

use std::path::PathBuf;
use std::process::{Command, Output};

fn imucal(args: &[&str], dir: &std::path::Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_imucal"))
        .current_dir(dir)
        .args(args)
        .output()
        .expect("the imucal binary runs")
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("imucal-mc-record-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir writable");
    dir
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// Whether `value` is printed with at most `decimals` decimals (as the sketch's `Uni:` prints).
fn has_decimals(value: f64, decimals: i32) -> bool {
    let scaled = value * 10f64.powi(decimals);
    (scaled - scaled.round()).abs() < 1e-3
}

#[test]
fn record_reads_the_sketch_boards_uni_lines_into_a_recording_at_the_sketch_rate() {
    let dir = scratch("record");
    let out = imucal(
        &[
            "record",
            "--sim",
            "--sim-protocol",
            "motioncal",
            "-o",
            "rec.csv",
            "--seconds",
            "2",
        ],
        &dir,
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("`Uni:`"), "{stderr}");
    let csv = std::fs::read_to_string(dir.join("rec.csv")).expect("the recording was written");
    let mut lines = csv.lines();
    // No temperature: the sketch prints none.
    assert_eq!(lines.next(), Some("t_s,ax,ay,az,gx,gy,gz,mx,my,mz"));
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().expect("numbers")).collect())
        .collect();
    // 2 s of a 100-readings-per-second sketch in real time; the first moments go to opening
    // the port, and the lower bound allows a slow machine.
    assert!(
        rows.len() >= 100 && rows.len() <= 210,
        "{} rows",
        rows.len()
    );
    for (i, row) in rows.iter().enumerate() {
        assert_eq!(row.len(), 10);
        // Counted at --sketch-rate (100/s), printed with six decimals.
        assert!(
            (row[0] - i as f64 * 0.01).abs() < 1e-6,
            "row {i}: t {}",
            row[0]
        );
        // `Uni:` prints 2 decimals (4 for the gyro): the values are the sketch's own, not
        // rescaled `Raw:` counts.
        assert!(
            row[1..4].iter().all(|v| has_decimals(*v, 2)),
            "row {i}: {row:?}"
        );
        assert!(
            row[4..7].iter().all(|v| has_decimals(*v, 4)),
            "row {i}: {row:?}"
        );
        assert!(
            row[7..10].iter().all(|v| has_decimals(*v, 2)),
            "row {i}: {row:?}"
        );
    }
    // Uncalibrated specific force near |g|: the simulated chip's scale (±3 %), cross-axis
    // (±1 %) and bias (±0.3 m/s² per axis) errors stay well inside 1.5 m/s²; the median is
    // taken because the simulated person may be moving the board.
    let mut magnitudes: Vec<f64> = rows.iter().map(|r| norm(&r[1..4])).collect();
    magnitudes.sort_by(f64::total_cmp);
    let median = magnitudes[magnitudes.len() / 2];
    assert!((median - 9.80665).abs() < 1.5, "median |a| {median} m/s²");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn stream_prints_the_sketch_boards_readings_without_a_temperature() {
    let dir = scratch("stream");
    let out = imucal(
        &[
            "stream",
            "--sim",
            "--sim-protocol",
            "motioncal",
            "--seconds",
            "1",
        ],
        &dir,
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let lines: Vec<&str> = stdout.lines().collect();
    assert!(lines.len() >= 40, "{} lines", lines.len());
    assert!(lines[0].starts_with("t     0.0000 s  a "), "{}", lines[0]);
    assert!(lines.iter().all(|l| l.ends_with("µT")), "{}", lines[0]);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_calibrated_stream_from_a_sketch_board_is_refused_with_the_reason() {
    let dir = scratch("calibrated");
    let out = imucal(
        &[
            "stream",
            "--sim",
            "--sim-protocol",
            "motioncal",
            "--calibrated",
            "--seconds",
            "1",
        ],
        &dir,
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("leave out --calibrated"), "{stderr}");
    std::fs::remove_dir_all(&dir).ok();
}

/// Feeds `line` 100 times a second to a pseudo-terminal until `stop`, as a sketch that prints
/// only `Raw:` lines would; returns the port's path and the slave kept open for the host.
fn raw_only_board(
    line: &'static str,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> (String, serialport::TTYPort, std::thread::JoinHandle<()>) {
    use serialport::SerialPort;
    use std::io::Write;
    let (mut master, slave) = serialport::TTYPort::pair().expect("the machine provides ptys");
    let path = slave.name().expect("a pty slave has a path");
    // A write that cannot go out (nobody reads) gives up, so the feeder always sees `stop`.
    master
        .set_timeout(std::time::Duration::from_millis(10))
        .expect("a timeout can be set");
    let feeder = std::thread::spawn(move || {
        while !stop.load(std::sync::atomic::Ordering::Relaxed) {
            let _ = master.write_all(line.as_bytes());
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
    });
    (path, slave, feeder)
}

#[test]
fn a_board_printing_only_raw_lines_is_recorded_with_motioncals_scales() {
    let dir = scratch("raw");
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let (port, _slave, feeder) =
        raw_only_board("Raw:8192,-4096,0,16,-32,0,10,-20,485\r\n", stop.clone());
    let out = imucal(
        &[
            "record",
            "--port",
            &port,
            "--protocol",
            "motioncal",
            "-o",
            "raw.csv",
            "--seconds",
            "1",
        ],
        &dir,
    );
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    feeder.join().expect("the feeder ends");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("`Raw:`"), "{stderr}");
    let csv = std::fs::read_to_string(dir.join("raw.csv")).expect("the recording was written");
    let rows: Vec<Vec<f64>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().expect("numbers")).collect())
        .collect();
    assert!(rows.len() >= 50, "{} rows", rows.len());
    // Adafruit's sketch: 8192 counts per 9.8 m/s²; MotionCal: 16 counts per °/s, 10 per µT.
    let dps = std::f64::consts::PI / 180.0;
    let expected = [9.8, -4.9, 0.0, dps, -2.0 * dps, 0.0, 1.0, -2.0, 48.5];
    for row in &rows {
        for (value, want) in row[1..].iter().zip(expected) {
            // Six printed decimals.
            assert!((value - want).abs() <= 5e-7, "{row:?}");
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}
