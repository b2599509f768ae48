//! Files that are not usable recordings (empty, header only, one row, binary, Latin-1, UTF-16, NaN,
//! infinity, garbage, missing columns, absurd values): every command that reads a recording
//! exits with a failing code, does not panic, and names the cause and the fix.

use std::process::Command;

struct Outcome {
    success: bool,
    stderr: String,
}

fn imucal(args: &[&str]) -> Outcome {
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(args)
        .output()
        .expect("the binary runs");
    Outcome {
        success: out.status.success(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

fn write(name: &str, bytes: &[u8]) -> String {
    let dir = std::env::temp_dir().join(format!("imucal-input-files-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temporary directory is writable");
    let path = dir.join(name);
    std::fs::write(&path, bytes).expect("scratch file is writable");
    path.display().to_string()
}

/// Run `fit`, `still` and `analyze` on `path`; each must fail cleanly with every phrase.
fn assert_every_command_refuses(path: &str, phrases: &[&str]) {
    for command in ["fit", "still", "analyze"] {
        let outcome = imucal(&[command, path]);
        assert!(!outcome.success, "`{command}` accepted {path}");
        assert!(
            !outcome.stderr.contains("panicked"),
            "`{command}` panicked: {}",
            outcome.stderr
        );
        for phrase in phrases {
            assert!(
                outcome.stderr.contains(phrase),
                "`{command}`: missing `{phrase}` in: {}",
                outcome.stderr
            );
        }
    }
}

#[test]
fn an_empty_file_asks_for_a_header_line() {
    let path = write("empty.csv", b"");
    assert_every_command_refuses(&path, &["is empty", "starts with a header line"]);
}

#[test]
fn a_header_only_file_says_it_has_no_rows() {
    let path = write("header.csv", b"t_s,ax,ay,az\n");
    assert_every_command_refuses(&path, &["has a header but no data rows"]);
}

#[test]
fn a_one_row_file_has_no_still_interval() {
    let path = write("one_row.csv", b"t_s,ax,ay,az\n0,0,0,9.81\n");
    for command in ["fit", "still"] {
        let outcome = imucal(&[command, &path]);
        assert!(!outcome.success && !outcome.stderr.contains("panicked"));
        assert!(
            outcome.stderr.contains("no still interval") && outcome.stderr.contains("(0.0 s long)"),
            "{}",
            outcome.stderr
        );
    }
}

#[test]
fn a_missing_file_names_the_path_and_says_to_check_it() {
    let path = write("placeholder.csv", b"");
    let missing = format!("{path}.absent");
    assert_every_command_refuses(&missing, &["cannot read", "check the path"]);
    // The operating-system cause is printed once, not repeated by the error chain.
    let outcome = imucal(&["fit", &missing]);
    assert_eq!(
        outcome.stderr.matches("os error").count(),
        1,
        "{}",
        outcome.stderr
    );
}

#[test]
fn binary_files_are_refused_as_not_text() {
    // Random bytes (fixed by a linear congruential generator), a PNG signature, UTF-16.
    let mut state: u32 = 12345;
    let random: Vec<u8> = (0..4096)
        .map(|_| {
            state = state.wrapping_mul(1_103_515_245).wrapping_add(12_345);
            (state >> 16) as u8
        })
        .collect();
    let png = b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR\0\0\0\x10";
    // Latin-1 text: no zero bytes, but 0xB5 (µ) is not valid UTF-8.
    let latin1 = b"t_s,mx,my,mz\n0,20,30,40 \xb5T\n".to_vec();
    let utf16: Vec<u8> = [0xFF, 0xFE]
        .into_iter()
        .chain(
            "t_s,ax,ay,az\n0,0,0,9.8\n"
                .encode_utf16()
                .flat_map(u16::to_le_bytes),
        )
        .collect();
    for (name, bytes, cause) in [
        ("random.csv", random.as_slice(), "binary data"),
        ("image.csv", png.as_slice(), "binary data"),
        ("latin1.csv", latin1.as_slice(), "not UTF-8 text"),
        ("utf16.csv", utf16.as_slice(), "UTF-16"),
    ] {
        let path = write(name, bytes);
        assert_every_command_refuses(
            &path,
            &["is not a text recording", cause, "save it as CSV (UTF-8)"],
        );
    }
}

#[test]
fn non_finite_numbers_name_line_column_and_fix() {
    for (name, value) in [("nan.csv", "NaN"), ("inf.csv", "inf"), ("word.csv", "abc")] {
        let text = format!("t_s,ax,ay,az\n0,0,0,9.8\n0.01,0,{value},9.8\n");
        let path = write(name, text.as_bytes());
        let expected = format!("line 3, column `ay`: `{value}` is not a finite number");
        assert_every_command_refuses(&path, &[&expected, "correct or delete that row"]);
    }
}

#[test]
fn values_too_large_for_any_sensor_are_refused_before_they_overflow() {
    // 1e300 is finite but its square overflows the variance of a hold.
    let path = write("huge.csv", b"t_s,ax,ay,az\n0,1e300,0,9.8\n");
    assert_every_command_refuses(
        &path,
        &[
            "larger than any sensor reading",
            "correct or delete that row",
        ],
    );
}

#[test]
fn garbage_text_is_refused_with_the_expected_column_names() {
    let path = write(
        "garbage.csv",
        b"lorem ipsum dolor sit amet\nconsectetur adipiscing\n",
    );
    assert_every_command_refuses(
        &path,
        &[
            "no sensor columns found",
            "name the columns in the first line",
        ],
    );
}

#[test]
fn a_missing_column_names_the_column() {
    let path = write("missing.csv", b"t_s,ax,ay,gx,gy,gz\n0,0,0,0,0,0\n");
    assert_every_command_refuses(&path, &["column `ax` is present but `az` is not"]);
}

#[test]
fn a_row_with_too_few_fields_names_the_line() {
    let path = write("short_row.csv", b"t_s,ax,ay,az\n0,0,0,9.8\n0.01,0,0\n");
    assert_every_command_refuses(&path, &["line 3: 3 fields but the header names 4 columns"]);
}
