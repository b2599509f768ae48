//! The board commands of the `imucal` binary against a fake board on a pseudo-terminal.

mod device_fake;

use std::path::PathBuf;
use std::process::{Command, Output};

use device_fake::{scales, FakeConfig, FakeDevice};
use imucal::device::ParamsFile;
use imucal_protocol::CalibrationSet;

fn imucal(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_imucal"))
        .env("IMUCAL_DB", temp_file("history.sqlite"))
        .args(args)
        .output()
        .expect("the imucal binary runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// A file path unique to this test process.
fn temp_file(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("imucal-device-cli-{}-{name}", std::process::id()))
}

#[test]
fn info_prints_identity_scales_and_state() {
    let fake = FakeDevice::start(FakeConfig::default());
    let out = imucal(&["info", "--port", &fake.path]);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(stdout.contains("device id       eeffc000"), "{stdout}");
    assert!(stdout.contains("firmware        0.3.1"), "{stdout}");
    assert!(stdout.contains("sample rate     100 Hz"), "{stdout}");
    assert!(stdout.contains("identity (uncalibrated)"), "{stdout}");
}

#[test]
fn flash_writes_the_parameter_file_and_the_board_holds_it() {
    let fake = FakeDevice::start(FakeConfig::default());
    let mut set = CalibrationSet::identity();
    set.accel.b = [0.25, -0.125, 0.0625];
    set.mag.a[0][1] = 0.015;
    let path = temp_file("flash.json");
    std::fs::write(&path, ParamsFile::from(&set).to_json()).expect("temp dir writable");
    let out = imucal(&[
        "flash",
        path.to_str().expect("utf-8 path"),
        "--port",
        &fake.path,
    ]);
    let _ = std::fs::remove_file(&path);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        text(&out.stdout).contains("verified"),
        "{}",
        text(&out.stdout)
    );
    assert_eq!(fake.state().active, set);
}

#[test]
fn flash_with_a_broken_file_fails_before_touching_the_board() {
    let fake = FakeDevice::start(FakeConfig::default());
    let path = temp_file("broken.json");
    std::fs::write(&path, "{\"format\": 1, \"accel\": ").expect("temp dir writable");
    let out = imucal(&[
        "flash",
        path.to_str().expect("utf-8 path"),
        "--port",
        &fake.path,
    ]);
    let _ = std::fs::remove_file(&path);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("is not a valid parameter file"), "{stderr}");
    assert!(fake.state().requests.is_empty());
}

#[test]
fn record_writes_the_recording_csv_in_units() {
    let fake = FakeDevice::start(FakeConfig::default());
    let path = temp_file("rec.csv");
    let out = imucal(&[
        "record",
        "--port",
        &fake.path,
        "-o",
        path.to_str().expect("utf-8 path"),
        "--seconds",
        "0.9",
    ]);
    let csv = std::fs::read_to_string(&path).unwrap_or_default();
    let _ = std::fs::remove_file(&path);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines[0], "t_s,ax,ay,az,gx,gy,gz,mx,my,mz,temp_c");
    // 0.9 s at one 20-sample batch per 200 ms: 4 batches.
    assert!(lines.len() > 60, "{} rows", lines.len() - 1);
    let first: Vec<f64> = lines[1]
        .split(',')
        .map(|v| v.parse().expect("numbers"))
        .collect();
    let s = scales();
    // Six printed decimals: ±5e-7 rounding.
    assert!(first[0].abs() < 5e-7);
    assert!((first[3] - 16_393.0 * f64::from(s.accel_mps2_per_count)).abs() < 1e-6);
    assert!((first[7] - 1500.0 * f64::from(s.mag_ut_per_count)).abs() < 1e-6);
    assert!((first[10] - 28.0).abs() < 1e-4, "25 °C + 48/16 °C");
    let second_t: f64 = lines[2]
        .split(',')
        .next()
        .unwrap_or("")
        .parse()
        .expect("t_s");
    assert!((second_t - 0.01).abs() < 10e-6, "100 Hz, 10 µs tick");
}

#[test]
fn an_absent_port_fails_with_exit_code_1_and_a_sentence() {
    let out = imucal(&["info", "--port", "/dev/ttyIMUCAL-absent"]);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(
        text(&out.stderr).trim(),
        "imucal: no such port /dev/ttyIMUCAL-absent; run `imucal ports` to list the serial ports"
    );
}

/// Runs `imucal args…`, killing it after `limit`; `None` when it had to be killed.
fn imucal_within(args: &[&str], limit: std::time::Duration) -> Option<Output> {
    let mut child = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .env("IMUCAL_DB", temp_file("history.sqlite"))
        .args(args)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("the imucal binary runs");
    let start = std::time::Instant::now();
    while start.elapsed() < limit {
        if let Ok(Some(_)) = child.try_wait() {
            return child.wait_with_output().ok();
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let _ = child.kill();
    let _ = child.wait();
    None
}

#[test]
fn info_and_flash_return_while_another_program_reads_the_port() {
    let fake = FakeDevice::start(FakeConfig::default());
    // A second reader on the same port, as `cat $PORT &` would be: it takes whatever bytes it
    // can, so the client's poll may report data that is gone by the time it reads.
    let mut thief = std::fs::File::open(&fake.path).expect("the pty opens a second time");
    std::thread::spawn(move || {
        use std::io::Read;
        let mut buf = [0u8; 256];
        while matches!(thief.read(&mut buf), Ok(n) if n > 0) {}
    });
    let path = temp_file("contested.json");
    std::fs::write(
        &path,
        ParamsFile::from(&CalibrationSet::identity()).to_json(),
    )
    .expect("temp dir writable");
    // Connect tries (5) and request tries (3) at 0.5 s reply timeouts, plus 3 s flash timeouts,
    // bound a run at well under 30 s; a run still going after 60 s is hanging.
    let limit = std::time::Duration::from_secs(60);
    let info = imucal_within(&["info", "--port", &fake.path], limit);
    let flash = imucal_within(
        &[
            "flash",
            path.to_str().expect("utf-8 path"),
            "--port",
            &fake.path,
        ],
        limit,
    );
    let _ = std::fs::remove_file(&path);
    for (command, out) in [("info", info), ("flash", flash)] {
        let out = out.unwrap_or_else(|| panic!("`imucal {command}` hung with a second reader"));
        // Either outcome is fine (the other reader may take every reply); a failure says why.
        if !out.status.success() {
            assert!(
                !text(&out.stderr).trim().is_empty(),
                "{command}: silent failure"
            );
        }
    }
}
