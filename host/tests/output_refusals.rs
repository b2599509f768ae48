//! Every command that writes a file checks its outputs before it opens a board or fits
//! anything: an existing file or a non-empty session directory is refused with a sentence
//! naming `--force` (and another name), an output that is also an input is refused even with
//! `--force`, and an output in a place that cannot be written is refused up front. The board
//! port given is one that does not exist, so a command that got past its check would fail on
//! the port instead.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const NO_BOARD: &str = "/dev/imucal-no-such-port";

fn imucal(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_imucal"))
        .current_dir(dir)
        .env("IMUCAL_DB", dir.join("history.sqlite"))
        .args(args)
        .output()
        .expect("the imucal binary runs")
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("imucal-refusals-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir writable");
    dir
}

/// The command failed with `expected` in its message, before it touched the (missing) board.
fn refused(out: &Output, expected: &[&str]) {
    refused_with(out, 1, expected);
}

/// [`refused`] with the exit status `code` (2 for an option value the command cannot take).
fn refused_with(out: &Output, code: i32, expected: &[&str]) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(code), "{stderr}");
    for part in expected {
        assert!(stderr.contains(part), "missing {part:?} in: {stderr}");
    }
    assert!(
        !stderr.contains(NO_BOARD),
        "the port was opened first: {stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
}

#[test]
fn calibrate_into_an_earlier_session_is_refused_before_the_board_is_opened() {
    let dir = scratch("session");
    std::fs::create_dir_all(dir.join("earlier")).unwrap();
    std::fs::write(dir.join("earlier/params.json"), "{}").unwrap();
    let out = imucal(
        &["calibrate", "--port", NO_BOARD, "--yes", "-o", "earlier"],
        &dir,
    );
    refused(&out, &["`earlier` already holds files", "--force"]);
    assert_eq!(
        std::fs::read_to_string(dir.join("earlier/params.json")).unwrap(),
        "{}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn calibrate_checks_gravity_and_field_as_fit_does_before_the_board_is_opened() {
    let dir = scratch("references");
    // Before, `calibrate` took any positive value (gravity 5 m/s² ran a whole session and wrote
    // its result); `fit` refused it.
    for (flag, value, expected) in [
        ("--gravity", "5", "--gravity 5 is outside 9.7–9.9 m/s²"),
        (
            "--field-ut",
            "99999",
            "--field-ut 99999 is outside 1–5000 µT",
        ),
    ] {
        let out = imucal(
            &["calibrate", "--port", NO_BOARD, "--yes", flag, value],
            &dir,
        );
        refused_with(&out, 2, &[expected]);
        let fit = imucal(&["fit", "none.csv", flag, value], &dir);
        refused_with(&fit, 2, &[expected]);
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn calibrate_into_a_file_is_refused_before_the_board_is_opened_even_with_force() {
    let dir = scratch("keep");
    std::fs::write(dir.join("keep.csv"), "t_s\n").unwrap();
    for extra in [&[][..], &["--force"][..]] {
        let mut args = vec!["calibrate", "--port", NO_BOARD, "--yes", "-o", "keep.csv"];
        args.extend_from_slice(extra);
        refused(
            &imucal(&args, &dir),
            &["`keep.csv` exists and is not a directory"],
        );
    }
    assert_eq!(
        std::fs::read_to_string(dir.join("keep.csv")).unwrap(),
        "t_s\n"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn record_and_params_get_onto_an_existing_file_are_refused_before_the_board_is_opened() {
    let dir = scratch("existing");
    std::fs::write(dir.join("old.csv"), "kept").unwrap();
    for args in [
        &[
            "record",
            "--port",
            NO_BOARD,
            "-o",
            "old.csv",
            "--seconds",
            "1",
        ][..],
        &["params", "get", "--port", NO_BOARD, "-o", "old.csv"][..],
    ] {
        refused(
            &imucal(args, &dir),
            &["`old.csv` already exists", "choose another name", "--force"],
        );
    }
    assert_eq!(
        std::fs::read_to_string(dir.join("old.csv")).unwrap(),
        "kept"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn export_onto_its_own_input_is_refused_even_with_force() {
    let dir = scratch("own-input");
    let params = imucal::device::ParamsFile::from(&imucal_protocol::CalibrationSet::identity());
    std::fs::write(dir.join("p.json"), params.to_json()).unwrap();
    // Another spelling of the same file is the same file.
    let out = imucal(
        &[
            "export", "p.json", "--format", "json", "-o", "./p.json", "--force",
        ],
        &dir,
    );
    refused(&out, &["is also the input `p.json`", "choose another name"]);
    assert_eq!(
        std::fs::read_to_string(dir.join("p.json")).unwrap(),
        params.to_json()
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn export_replaces_an_existing_file_only_with_force() {
    let dir = scratch("force");
    let params = imucal::device::ParamsFile::from(&imucal_protocol::CalibrationSet::identity());
    std::fs::write(dir.join("p.json"), params.to_json()).unwrap();
    std::fs::write(dir.join("cal.h"), "old").unwrap();
    let args = ["export", "p.json", "-o", "cal.h"];
    refused(&imucal(&args, &dir), &["`cal.h` already exists", "--force"]);
    assert_eq!(std::fs::read_to_string(dir.join("cal.h")).unwrap(), "old");
    let forced = imucal(&[&args[..], &["--force"]].concat(), &dir);
    assert!(
        forced.status.success(),
        "{}",
        String::from_utf8_lossy(&forced.stderr)
    );
    let header = std::fs::read_to_string(dir.join("cal.h")).unwrap();
    assert!(header.contains("static const float"), "{header}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn fit_params_out_onto_the_recording_is_refused_before_the_recording_is_read() {
    let dir = scratch("fit");
    // Not a valid recording: reading it would fail with another message.
    std::fs::write(dir.join("rec.csv"), "not a recording").unwrap();
    let out = imucal(&["fit", "rec.csv", "--params-out", "rec.csv"], &dir);
    refused(&out, &["is also the input `rec.csv`"]);
    assert_eq!(
        std::fs::read_to_string(dir.join("rec.csv")).unwrap(),
        "not a recording"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A hard link is the input under a name of its own: neither its path nor a link resolves to
/// the input's, so only the file's identity tells them apart.
#[cfg(unix)]
#[test]
fn an_output_hard_linked_to_an_input_is_refused_even_with_force() {
    let dir = scratch("hard-link");
    std::fs::create_dir(dir.join("rec")).unwrap();
    std::fs::write(dir.join("rec/n.csv"), "not a recording").unwrap();
    std::fs::hard_link(dir.join("rec/n.csv"), dir.join("hard.json")).unwrap();
    let fit = imucal(
        &[
            "fit",
            "rec/n.csv",
            "--gyro-unit",
            "dps",
            "--params-out",
            "hard.json",
            "--force",
        ],
        &dir,
    );
    refused(&fit, &["`hard.json` is also the input `rec/n.csv`"]);
    std::fs::create_dir(dir.join("out")).unwrap();
    std::fs::hard_link(dir.join("rec/n.csv"), dir.join("out/report.html")).unwrap();
    let report = imucal(&["report", "rec/n.csv", "-o", "out", "--force"], &dir);
    refused(&report, &["is also the input `rec/n.csv`"]);
    let params = imucal::device::ParamsFile::from(&imucal_protocol::CalibrationSet::identity());
    std::fs::write(dir.join("p.json"), params.to_json()).unwrap();
    std::fs::hard_link(dir.join("p.json"), dir.join("p.h")).unwrap();
    let export = imucal(&["export", "p.json", "-o", "p.h", "--force"], &dir);
    refused(&export, &["`p.h` is also the input `p.json`"]);
    assert_eq!(
        std::fs::read_to_string(dir.join("rec/n.csv")).unwrap(),
        "not a recording"
    );
    assert_eq!(
        std::fs::read_to_string(dir.join("p.json")).unwrap(),
        params.to_json()
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn report_next_to_an_earlier_report_is_refused_unless_forced() {
    let dir = scratch("report");
    std::fs::create_dir_all(dir.join("out")).unwrap();
    std::fs::write(dir.join("out/report.html"), "earlier").unwrap();
    std::fs::write(dir.join("rec.csv"), "not a recording").unwrap();
    let out = imucal(&["report", "rec.csv", "-o", "out"], &dir);
    refused(&out, &["report.html` already exists", "--force"]);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn an_output_whose_directory_is_a_file_or_missing_is_refused_up_front() {
    let dir = scratch("nowhere");
    std::fs::write(dir.join("file"), "").unwrap();
    let under_file = imucal(&["record", "--port", NO_BOARD, "-o", "file/out.csv"], &dir);
    refused(
        &under_file,
        &[
            "`file` is not a directory",
            "choose a place you can write to",
        ],
    );
    let missing = imucal(
        &["params", "get", "--port", NO_BOARD, "-o", "missing/p.json"],
        &dir,
    );
    refused(
        &missing,
        &["the directory `missing` of `missing/p.json` does not exist"],
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A directory no file can be created in: `/proc` refuses new files even to root, for whom
/// permission bits do not count.
#[cfg(target_os = "linux")]
#[test]
fn an_output_in_an_unwritable_directory_is_refused_up_front() {
    let dir = scratch("unwritable");
    let out = imucal(
        &["record", "--port", NO_BOARD, "-o", "/proc/imucal-out.csv"],
        &dir,
    );
    refused(
        &out,
        &[
            "cannot be written",
            "`/proc`",
            "choose a place you can write to",
        ],
    );
    std::fs::remove_dir_all(&dir).ok();
}
