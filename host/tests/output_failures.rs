//! Standard output that fails never makes `imucal` panic: a reader that closed the pipe ends the
//! command quietly, a full disk is an error that says so. A standard error that fails loses
//! its messages, not the command's work.

use std::process::{Command, Output, Stdio};

/// `imucal ports` (which always prints, board or not) with standard output sent to `stdout`.
fn ports_into(stdout: impl Into<Stdio>) -> Output {
    Command::new(env!("CARGO_BIN_EXE_imucal"))
        .arg("ports")
        .stdout(stdout)
        .stderr(Stdio::piped())
        .output()
        .expect("the imucal binary runs")
}

#[test]
fn a_reader_that_closed_the_pipe_ends_the_output_quietly() {
    // The read end is closed before the command starts, so its first line meets EPIPE, as under
    // `imucal ports | head -0`.
    let (reader, writer) = std::io::pipe().expect("a pipe");
    drop(reader);
    let out = ports_into(writer);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.is_empty(), "nothing is reported: {stderr}");
}

#[cfg(target_os = "linux")]
#[test]
fn a_full_disk_is_an_error_naming_the_cause() {
    // Every write to /dev/full fails with ENOSPC.
    let full = std::fs::File::options()
        .write(true)
        .open("/dev/full")
        .expect("/dev/full exists on Linux");
    let out = ports_into(full);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("cannot write the output"), "{stderr}");
    assert!(stderr.contains("No space left on device"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

#[test]
fn a_closed_standard_error_loses_the_messages_but_not_the_work() {
    // The fit warns on standard error (outliers dropped from holds) before it writes the
    // parameter file; with the reader of standard error gone, as under `2>&1 | head -0`, it
    // still writes the file and exits as it would have.
    let params = std::env::temp_dir().join(format!(
        "imucal-output-failures-{}-params.json",
        std::process::id()
    ));
    let _ = std::fs::remove_file(&params);
    let recording = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../data/real/imucal_nilspod_ferraris.csv");
    let (reader, writer) = std::io::pipe().expect("a pipe");
    drop(reader);
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .env(
            "IMUCAL_DB",
            std::env::temp_dir().join("imucal-output-failures.sqlite"),
        )
        .args(["fit", "--gyro-unit", "dps", "--no-history", "--params-out"])
        .arg(&params)
        .arg(&recording)
        .stdout(Stdio::null())
        .stderr(writer)
        .output()
        .expect("the imucal binary runs");
    assert!(out.status.success(), "exit status {:?}", out.status);
    assert!(params.is_file(), "the parameter file was written");
}
