//! `imucal fit` reads any input once, as a stream, with bounded memory: an endless binary device
//! is refused at once with a sentence, and a FIFO or standard input (`-`) reads like a file.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("imucal-input-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temporary directory is writable");
    dir
}

/// A magnetometer recording on an offset, scaled sphere (deterministic, 600 samples).
fn mag_recording() -> String {
    let mut text = String::from("t_s,mx,my,mz\n");
    for i in 0..600 {
        let t = f64::from(i);
        let z = 1.0 - 2.0 * (t + 0.5) / 600.0;
        let phi = t * 2.399_963_229_728_653;
        let r = (1.0 - z * z).sqrt();
        let wobble = 1.0 + 0.01 * (7.1 * t).sin();
        text += &format!(
            "{:.2},{:.4},{:.4},{:.4}\n",
            t * 0.02,
            40.0 * wobble * r * phi.cos() + 12.0,
            45.0 * wobble * r * phi.sin() - 7.0,
            50.0 * wobble * z + 3.0
        );
    }
    text
}

/// Run `imucal fit ARGS --sensor mag --json` with `stdin` as its input; the parsed JSON, or the
/// error text.
fn fit_mag(input: &str, stdin: Option<&str>) -> Result<Value, String> {
    fit_mag_with(input, stdin, &[])
}

/// [`fit_mag`] with `extra` arguments.
fn fit_mag_with(input: &str, stdin: Option<&str>, extra: &[&str]) -> Result<Value, String> {
    let mut child = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(["fit", input, "--sensor", "mag", "--json"])
        .args(extra)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the binary runs");
    let mut pipe = child.stdin.take().expect("stdin is piped");
    if let Some(text) = stdin {
        pipe.write_all(text.as_bytes())
            .expect("the child reads its input");
    }
    drop(pipe);
    let out = child.wait_with_output().expect("the binary finishes");
    if out.status.success() {
        serde_json::from_slice(&out.stdout).map_err(|e| e.to_string())
    } else {
        Err(String::from_utf8_lossy(&out.stderr).into_owned())
    }
}

fn offset(json: &Value) -> Vec<f64> {
    json["mag"]["b"]
        .as_array()
        .expect("b is an array")
        .iter()
        .map(|v| v.as_f64().expect("a number"))
        .collect()
}

fn file_fit() -> Value {
    // One file per call: tests run in parallel, and one writing the file while another reads
    // it made the reader see it empty.
    static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
    let path = scratch(&format!("file-{call}")).join("mag.csv");
    std::fs::write(&path, mag_recording()).expect("writable");
    fit_mag(&path.display().to_string(), None).expect("a plain file fits")
}

#[test]
fn dev_zero_is_refused_within_seconds_with_a_sentence_naming_binary_data() {
    let start = Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(["fit", "/dev/zero"])
        .output()
        .expect("the binary runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("is not a text recording") && stderr.contains("zero byte at offset 0"),
        "{stderr}"
    );
    // Reading stops at the first KiB; before streaming this grew to gigabytes over seconds. The
    // bound is generous for a loaded machine: the point is that it ends.
    assert!(
        start.elapsed() < Duration::from_secs(20),
        "{:?}",
        start.elapsed()
    );
}

#[test]
fn standard_input_is_read_for_a_dash_and_fits_like_the_file() {
    let from_file = file_fit();
    let from_stdin = fit_mag("-", Some(&mag_recording())).expect("stdin fits");
    assert_eq!(offset(&from_stdin), offset(&from_file));
}

#[cfg(unix)]
#[test]
fn a_fifo_is_read_once_and_fits_like_the_file() {
    let fifo = scratch("fifo").join("mag.fifo");
    let _ = std::fs::remove_file(&fifo);
    let made = Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .expect("mkfifo runs");
    assert!(made.success(), "mkfifo failed");
    let writer = {
        let fifo: PathBuf = fifo.clone();
        std::thread::spawn(move || write_fifo(&fifo))
    };
    let from_fifo = fit_mag(&fifo.display().to_string(), None).expect("the FIFO fits");
    writer.join().expect("the writer finishes");
    assert_eq!(offset(&from_fifo), offset(&file_fit()));
}

fn write_fifo(path: &Path) {
    // Opening blocks until the reader opens; a second open by the reader would block forever.
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .open(path)
        .expect("the FIFO opens for writing");
    f.write_all(mag_recording().as_bytes())
        .expect("the reader takes the whole recording");
}

#[test]
fn a_semicolon_separated_file_is_refused_with_the_columns_option_that_reads_it() {
    let path = scratch("semicolon").join("mag.csv");
    std::fs::write(&path, mag_recording().replace(',', ";")).expect("writable");
    let path = path.display().to_string();
    let error = fit_mag(&path, None).expect_err("a semicolon header is not imucal's CSV");
    let mapping = "t_s=t_s,mx=mx,my=my,mz=mz";
    assert!(error.contains("separated by `;`"), "{error}");
    assert!(error.contains(&format!("--columns {mapping}")), "{error}");
    // The option it names reads the file, and the fit is the comma file's.
    let json = fit_mag_with(&path, None, &["--columns", mapping]).expect("the option reads it");
    for (a, b) in offset(&json).iter().zip(offset(&file_fit())) {
        assert!((a - b).abs() <= 1e-9 * b.abs().max(1.0), "{a} vs {b}");
    }
}

#[test]
fn standard_input_without_magnetometer_columns_points_to_mag_file() {
    // A recording whose magnetometer is in a file of its own: next to a file it is found as
    // `<name>_mag.csv`, but standard input has no name to put it next to.
    let accel = "t_s,ax,ay,az\n0.00,0,0,9.8\n0.01,0,0,9.8\n0.02,0,0,9.8\n";
    let error = fit_mag("-", Some(accel)).expect_err("no magnetometer data");
    assert!(
        error.contains("standard input has no mag data")
            && error.contains("cannot be found for standard input")
            && error.contains("--mag-file"),
        "{error}"
    );
    assert!(!error.contains("`-`"), "{error}");
    let mag = scratch("stdin-mag").join("rec_mag.csv");
    std::fs::write(&mag, mag_recording()).expect("writable");
    let named = fit_mag_with(
        "-",
        Some(accel),
        &["--mag-file", &mag.display().to_string()],
    );
    assert_eq!(
        offset(&named.expect("--mag-file fits")),
        offset(&file_fit())
    );
}

/// A MotionCal serial log of [`mag_recording`]'s field (as 0.1 µT counts) after the banner a
/// sketch prints, so that only its `Raw:` lines tell it from a CSV file.
fn motioncal_log() -> String {
    let mut text = String::from("Adafruit AHRS calibration sketch\n");
    for line in mag_recording().lines().skip(1) {
        let v: Vec<f64> = line
            .split(',')
            .map(|f| f.parse().expect("a number"))
            .collect();
        text += &format!(
            "Raw:0,0,8192,0,0,0,{:.0},{:.0},{:.0}\n",
            v[1] * 10.0,
            v[2] * 10.0,
            v[3] * 10.0
        );
    }
    text
}

#[test]
fn a_motioncal_log_on_standard_input_is_read_as_the_same_log_by_path() {
    let path = scratch("motioncal").join("log.txt");
    std::fs::write(&path, motioncal_log()).expect("writable");
    let from_file = fit_mag(path.to_str().expect("utf-8 path"), None).expect("the log fits");
    let from_stdin = fit_mag("-", Some(&motioncal_log())).expect("the log on stdin fits");
    assert_eq!(offset(&from_stdin), offset(&from_file));
}
