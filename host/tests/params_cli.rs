//! `imucal params get` and `imucal params reset` against the simulated board (the firmware core
//! behind a pseudo-terminal, kept running by this test between the commands): the saved file is
//! bound to the board and flashes back to the very same set (same CRC), another board refuses
//! it, a reset leaves the identity set verified, and a reset nobody confirmed changes nothing.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use imucal::device::{DeviceClient, DeviceError, ParamsFile};
use imucal_hil_sim::board::PersonSchedule;
use imucal_hil_sim::serve::{SimHandle, SimOptions, SimServer};
use imucal_protocol::CalibrationSet;

fn board(seed: u64) -> SimHandle {
    let mut options = SimOptions::new(seed);
    options.schedule = PersonSchedule::Rest;
    SimServer::start(options).expect("the simulator starts")
}

fn imucal(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_imucal"))
        .current_dir(dir)
        .env("IMUCAL_DB", dir.join("history.sqlite"))
        .args(args)
        .stdin(Stdio::null())
        .output()
        .expect("the imucal binary runs")
}

fn succeeded(out: &Output) -> String {
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("imucal-params-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir writable");
    dir
}

/// A calibration with extended terms in every sensor, within the board's limits.
fn calibrated_set() -> CalibrationSet {
    let mut set = CalibrationSet::identity();
    set.created_unix_s = 1_763_700_000;
    set.accel.a = [[1.01, 0.002, 0.0], [0.0, 0.99, -0.003], [0.001, 0.0, 1.02]];
    set.accel.b = [0.25, -0.125, 0.0625];
    set.accel.t_ref_c = 27.5;
    set.accel.scale_temp = Some([1e-4, -2e-4, 5e-5]);
    set.gyro.b = [0.01, 0.02, -0.03];
    set.gyro_g_sensitivity = Some([[1e-4, 0.0, 0.0], [0.0, -2e-4, 0.0], [0.0, 0.0, 3e-4]]);
    set.mag.a[0][1] = 0.015;
    set.mag.b = [12.0, -3.5, 40.0];
    set.reference.field_ut = 48.5;
    set.residuals.accel_rms = 0.004;
    set
}

/// Connects to the simulated board. The pty may still be held exclusively for a moment by the
/// link a previous client (or `imucal` process) just closed: that is waited out, briefly.
fn connect(port: &str) -> DeviceClient {
    for _ in 0..100 {
        match DeviceClient::open(port) {
            Err(DeviceError::PortBusy { .. }) => {
                std::thread::sleep(std::time::Duration::from_millis(20));
            }
            other => return other.expect("connect to the simulator"),
        }
    }
    panic!("{port} stayed busy for 2 s");
}

/// Writes `set` to the board straight through the library (the link is closed on return).
fn write_directly(sim: &SimHandle, set: &CalibrationSet) {
    let mut client = connect(sim.port_path());
    client
        .write_params_verified(set)
        .expect("the set is written");
}

/// The board's active CRC and set, read directly (the link is closed again on return).
fn active(sim: &SimHandle) -> (u32, CalibrationSet) {
    let mut client = connect(sim.port_path());
    let crc = client.status().expect("status").active_crc;
    (crc, client.get_params().expect("params"))
}

#[test]
fn a_saved_set_is_bound_to_its_board_and_flashes_back_with_the_same_crc() {
    let dir = scratch("round-trip");
    let sim = board(21);
    let set = calibrated_set();
    write_directly(&sim, &set);
    let (crc_before, _) = active(&sim);
    assert_eq!(crc_before, set.crc32());

    let port = sim.port_path();
    succeeded(&imucal(
        &["params", "get", "--port", port, "-o", "saved.json"],
        &dir,
    ));
    let file = ParamsFile::load(&dir.join("saved.json")).expect("a valid parameter file");
    let (_, board_set) = active(&sim);
    let device_id = connect(port).welcome().device_id.to_string();
    assert_eq!(file.device_id(), Some(device_id.as_str()));
    assert_eq!(file.to_calibration_set("saved.json").unwrap(), board_set);

    // Reset, then the saved file restores exactly the set the board held.
    succeeded(&imucal(&["params", "reset", "--port", port, "--yes"], &dir));
    assert_eq!(active(&sim).0, CalibrationSet::identity().crc32());
    let flashed = succeeded(&imucal(&["flash", "saved.json", "--port", port], &dir));
    assert!(flashed.contains("verified"), "{flashed}");
    assert_eq!(active(&sim).0, crc_before);

    // Another board (another device id) refuses it.
    let other = board(22);
    let refused = imucal(&["flash", "saved.json", "--port", other.port_path()], &dir);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert_eq!(refused.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("is not for this board"), "{stderr}");
    assert_eq!(active(&other).0, CalibrationSet::identity().crc32());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_reset_leaves_the_identity_set_verified_by_read_back() {
    let dir = scratch("reset");
    let sim = board(23);
    write_directly(&sim, &calibrated_set());
    let out = succeeded(&imucal(
        &["params", "reset", "--port", sim.port_path(), "--yes"],
        &dir,
    ));
    let identity = CalibrationSet::identity();
    assert!(out.contains("verified by reading it back"), "{out}");
    assert!(
        out.contains(&format!("{:#010x}", identity.crc32())),
        "{out}"
    );
    let (crc, set) = active(&sim);
    assert_eq!(crc, identity.crc32());
    assert_eq!(set, identity);
    // The history's newest record of the board is the reset, so its fleet and changes no
    // longer describe the erased set.
    let records = imucal::history::HistoryStore::open(&imucal::history::DbLocation::Sqlite(
        dir.join("history.sqlite"),
    ))
    .and_then(|mut store| store.records(None))
    .expect("the history reads back");
    let newest = &records.last().expect("the reset is recorded").record;
    assert_eq!(newest.source, imucal::history::RecordSource::Reset);
    assert_eq!(newest.params_crc, identity.crc32());
    assert_eq!(
        newest.params.fitted_sensors().len(),
        0,
        "every sensor reset"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_reset_without_confirmation_on_a_non_terminal_is_refused_and_changes_nothing() {
    let dir = scratch("unconfirmed");
    let sim = board(24);
    let set = calibrated_set();
    write_directly(&sim, &set);
    let out = imucal(&["params", "reset", "--port", sim.port_path()], &dir);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("pass --yes"), "{stderr}");
    assert_eq!(active(&sim).0, set.crc32());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn params_get_with_sim_reads_the_fresh_simulated_board() {
    let dir = scratch("sim");
    let out = succeeded(&imucal(
        &["params", "get", "--sim", "-o", "fresh.json"],
        &dir,
    ));
    assert!(out.contains("identity (uncalibrated)"), "{out}");
    let file = ParamsFile::load(&dir.join("fresh.json")).expect("a valid parameter file");
    assert_eq!(
        file.to_calibration_set("fresh.json").unwrap().crc32(),
        CalibrationSet::identity().crc32()
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_flash_whose_read_back_answers_are_lost_is_verified_after_all_and_recorded() {
    use imucal_hil_sim::link_faults::ParamTamper;
    let dir = scratch("lost-read-back");
    let mut options = SimOptions::new(23);
    options.schedule = PersonSchedule::Rest;
    // Every try of the read-back after the commit is lost: the board committed the set.
    options.faults.param_tamper = Some(ParamTamper::LoseRepliesAfterCommit { skip: 1, lose: 3 });
    let sim = SimServer::start(options).expect("the simulator starts");
    let port = sim.port_path();
    succeeded(&imucal(
        &["params", "get", "--port", port, "-o", "a.json"],
        &dir,
    ));
    let text = std::fs::read_to_string(dir.join("a.json")).expect("saved");
    let mut json: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    json["accel"]["b"][0] = serde_json::json!(0.05);
    std::fs::write(dir.join("b.json"), json.to_string()).expect("writable");
    let out = imucal(&["flash", "b.json", "--port", port], &dir);
    let stdout = succeeded(&out);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stdout.contains("verified by reading it back"), "{stdout}");
    assert!(stderr.contains("the new set is active"), "{stderr}");
    let (crc, _) = active(&sim);
    let device_id = connect(port).welcome().device_id.to_string();
    let history = succeeded(&imucal(&["history", &device_id], &dir));
    assert!(
        history.contains(&format!("{crc:08x}")),
        "the history holds the flashed set {crc:#010x}:\n{history}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
