//! Reading long recordings in blocks parsed on two threads: values, labels and errors must be
//! what a plain line-by-line reading of the same text gives (the reference here is
//! `str::split` and `str::parse` on each line), wherever a block or its halves happen to end.

use std::path::{Path, PathBuf};

use imucal::recording::{LoadOptions, Recording};
use rand::{Rng, SeedableRng};

fn scratch(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("imucal-blocks-{}-{test}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temporary directory is writable");
    dir
}

const HEADER: &str = "t_s,ax,ay,az,gx,gy,gz,segment,mx,my,mz,temp_c";

/// `rows` data lines of a 12-column recording (several MiB for 40 000 rows), with comments,
/// blank lines, CRLF line ends and padded fields among them; segment labels change every few
/// hundred rows and recur, so later halves meet labels first seen earlier and new ones.
fn lines(rows: usize, seed: u64) -> Vec<String> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut out = vec![HEADER.to_string()];
    for i in 0..rows {
        if rng.gen_bool(0.002) {
            out.push("# a comment, with commas".to_string());
        }
        if rng.gen_bool(0.002) {
            out.push(String::new());
        }
        let v: [f64; 10] = std::array::from_fn(|_| rng.gen_range(-1.0..1.0));
        let segment = match (i / 700) % 5 {
            0 => "-".to_string(),
            k => format!("part{}", (k * 7 + i / 3500) % 9),
        };
        let mut line = format!(
            "{:.3},{:.5},{:.5}, {:.5} ,{:.6},{:.6},{:.6},{segment},{:.3},{:.3},{:e},{:.2}",
            i as f64 * 0.01,
            9.81 * v[0],
            9.81 * v[1],
            9.81 * v[2],
            0.1 * v[3],
            0.1 * v[4],
            0.1 * v[5],
            50.0 * v[6],
            50.0 * v[7],
            50.0 * v[8],
            25.0 + v[9],
        );
        if rng.gen_bool(0.01) {
            line.push('\r');
        }
        out.push(line);
    }
    out
}

fn write(dir: &Path, name: &str, lines: &[String]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, lines.join("\n") + "\n").expect("temporary file is writable");
    path
}

fn load(path: &Path) -> Result<Recording, String> {
    Recording::load(path, &LoadOptions::default()).map_err(|e| e.to_string())
}

#[test]
fn a_long_recording_reads_as_line_by_line_parsing_gives() {
    let dir = scratch("values");
    let text = lines(40_000, 1);
    let path = write(&dir, "long.csv", &text);
    assert!(std::fs::metadata(&path).expect("written").len() > 3 << 20);
    let rec = load(&path).expect("the recording reads");
    let mut names: Vec<String> = Vec::new();
    let mut row = 0;
    for line in &text[1..] {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        let num = |i: usize| f[i].parse::<f64>().expect("reference number");
        assert_eq!(rec.time[row].to_bits(), num(0).to_bits(), "row {row}");
        let accel = rec.accel.as_ref().expect("accel")[row];
        let gyro = rec.gyro.as_ref().expect("gyro")[row];
        let mag = rec.mag.as_ref().expect("mag").samples[row];
        for (k, col) in [(0, 1), (1, 2), (2, 3)] {
            assert_eq!(accel[k].to_bits(), num(col).to_bits(), "row {row}");
            assert_eq!(gyro[k].to_bits(), num(col + 3).to_bits(), "row {row}");
            assert_eq!(mag[k].to_bits(), num(col + 7).to_bits(), "row {row}");
        }
        assert_eq!(
            rec.temp_c.as_ref().expect("temp")[row].to_bits(),
            num(11).to_bits()
        );
        let labels = rec.labels.as_ref().expect("labels");
        let expected = (f[7] != "-").then(|| {
            names.iter().position(|n| n == f[7]).unwrap_or_else(|| {
                names.push(f[7].to_string());
                names.len() - 1
            })
        });
        assert_eq!(labels.per_row[row], expected, "row {row}");
        row += 1;
    }
    assert_eq!(rec.len(), row);
    assert_eq!(rec.labels.expect("labels").names, names);
}

#[test]
fn the_first_error_in_the_file_is_reported_wherever_the_blocks_are_cut() {
    let dir = scratch("errors");
    let text = lines(40_000, 2);
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let data: Vec<usize> = (2..text.len())
        .filter(|&i| !text[i].trim().is_empty() && !text[i].starts_with('#'))
        .collect();
    for trial in 0..24 {
        let mut broken = text.clone();
        // Two faults on data lines (not the first, which has no time before it); the earlier
        // one (1-based line `first + 1`) must be the one reported.
        let i = rng.gen_range(0..data.len() - 1);
        let first = data[i];
        let second = data[rng.gen_range(i + 1..data.len())];
        let kind = trial % 4;
        for (k, at) in [(kind, first), ((kind + 1) % 4, second)] {
            let mut f: Vec<String> = broken[at].split(',').map(str::to_string).collect();
            match k {
                0 => f[1] = "x".to_string(),
                1 => f[0] = "-5.0".to_string(),
                2 => f.push("1".to_string()),
                _ => f[9] = "1e30".to_string(),
            }
            broken[at] = f.join(",");
        }
        let path = write(&dir, &format!("broken{trial}.csv"), &broken);
        let err = load(&path).expect_err("a broken recording is refused");
        let expected = match kind {
            0 => "is not a finite number",
            1 => "earlier than the previous row's",
            2 => "fields but the header names 12 columns",
            _ => "is larger than any sensor reading",
        };
        let line = format!("line {}", first + 1);
        assert!(
            err.contains(&format!("{line}:")) || err.contains(&format!("{line},")),
            "trial {trial}: expected {line}: {err}"
        );
        assert!(err.contains(expected), "trial {trial}: {err}");
    }
}

#[test]
fn time_going_back_across_any_cut_is_refused_with_the_previous_time() {
    let dir = scratch("seam");
    let text = lines(40_000, 4);
    // One data line goes back in time, at places spread over the file's blocks and halves.
    for start in [5_000, 17_000, 23_000, 33_000] {
        let mut broken = text.clone();
        let at = (start..broken.len())
            .find(|&i| !broken[i].trim().is_empty() && !broken[i].starts_with('#'))
            .expect("a data line");
        let prev = (1..at)
            .rev()
            .find(|&i| !broken[i].trim().is_empty() && !broken[i].starts_with('#'))
            .expect("a data line before");
        let prev_t: f64 = broken[prev]
            .split(',')
            .next()
            .and_then(|t| t.parse().ok())
            .expect("time");
        let rest = broken[at][broken[at].find(',').unwrap_or(0)..].to_string();
        broken[at] = format!("{:.3}{rest}", prev_t - 0.02);
        let err = load(&write(&dir, &format!("back{start}.csv"), &broken)).expect_err("refused");
        assert!(
            err.contains(&format!("line {}: time", at + 1))
                && err.contains(&format!("previous row's {prev_t} s")),
            "{err}"
        );
    }
}

#[test]
fn a_zero_byte_deep_in_a_long_recording_is_refused_at_its_offset() {
    let dir = scratch("zero");
    let text = lines(40_000, 5);
    let bytes = (text.join("\n") + "\n").into_bytes();
    for at in [2_000_000usize, 2_900_017] {
        let mut broken = bytes.clone();
        let at = at.min(broken.len() - 2);
        // Not a line break: keep the line structure.
        let at = if broken[at] == b'\n' { at + 1 } else { at };
        broken[at] = 0;
        let path = dir.join("zero.csv");
        std::fs::write(&path, &broken).expect("temporary file is writable");
        let err = load(&path).expect_err("refused");
        assert!(err.contains(&format!("zero byte at offset {at}")), "{err}");
    }
}
