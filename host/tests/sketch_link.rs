//! Board commands against a board running a MotionCal sketch, and over a noisy link: a port
//! that prints the sketch's `Raw:`/`Uni:` lines is named as such with what works for it (and
//! `flash --protocol motioncal` sends a saved packet to it); a sketch session's parameter file
//! is refused by a board running imucal's firmware; a link that loses bytes is named as noisy,
//! with its measured loss, instead of blaming the port or the firmware.

use std::path::Path;
use std::process::{Command, Output};

use imucal::compat::{encode_packet, AdafruitCalibration};
use imucal::device::params_json::Provenance;
use imucal::device::{ParamsFile, MOTIONCAL_SKETCH};
use imucal_hil_sim::board::PersonSchedule;
use imucal_hil_sim::link_faults::LinkFaults;
use imucal_hil_sim::motioncal_serve::MotionCalHandle;
use imucal_hil_sim::serve::{SimHandle, SimOptions, SimServer};
use imucal_protocol::CalibrationSet;

fn scratch(name: &str) -> std::path::PathBuf {
    let dir =
        std::env::temp_dir().join(format!("imucal-sketch-link-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn imucal(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(args)
        .env("IMUCAL_DB", dir.join("history.sqlite"))
        .output()
        .unwrap()
}

fn text(output: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    )
}

/// A sketch session's parameter file: a plausible set, its provenance naming the sketch board.
fn sketch_params(path: &Path) {
    let mut set = CalibrationSet::identity();
    set.accel.b = [0.05, -0.03, 0.02];
    set.gyro.b = [0.01, 0.0, -0.01];
    set.mag.b = [10.0, -5.0, 3.0];
    set.reference.field_ut = 48.0;
    let mut file = ParamsFile::from(&set);
    file.provenance = Some(Provenance {
        tool: Provenance::tool(),
        source: "a guided session on a board running a MotionCal calibration sketch".into(),
        device_id: None,
        methods: Default::default(),
        input_units: Default::default(),
        created_unix_s: 1_760_000_000,
        board_firmware: Some(MOTIONCAL_SKETCH.to_string()),
    });
    std::fs::write(path, file.to_json()).unwrap();
}

#[test]
fn board_commands_on_a_sketch_board_name_the_sketch_and_what_works_for_it() {
    let dir = scratch("commands");
    let sketch = MotionCalHandle::start(3, 1.0).expect("the sketch board starts");
    let port = sketch.port_path().to_string();
    let params = dir.join("params.json");
    sketch_params(&params);
    let got = dir.join("got.json");
    for args in [
        vec!["info", "--port", &port],
        vec![
            "params",
            "get",
            "--port",
            &port,
            "-o",
            got.to_str().unwrap(),
        ],
        vec!["params", "reset", "--port", &port, "--yes"],
        vec!["flash", params.to_str().unwrap(), "--port", &port],
    ] {
        let run = imucal(&dir, &args);
        let said = text(&run);
        assert!(!run.status.success(), "{args:?}: {said}");
        assert!(
            said.contains("runs a MotionCal calibration sketch")
                && said.contains("--protocol motioncal")
                && said.contains("imucal export"),
            "{args:?}: {said}"
        );
        assert!(
            !said.contains("is the board running imucal firmware"),
            "{args:?}: {said}"
        );
    }
}

#[test]
fn flash_with_protocol_motioncal_sends_a_saved_packet_and_checks_the_echo() {
    let dir = scratch("flash-packet");
    let sketch = MotionCalHandle::start(4, 1.0).expect("the sketch board starts");
    let port = sketch.port_path().to_string();
    let cal = AdafruitCalibration {
        accel_zerog: [0.11, -0.07, 0.05],
        gyro_zerorate: [0.012, -0.004, 0.002],
        mag_hardiron: [12.5, -7.25, 30.0],
        mag_field: 47.5,
        mag_softiron: [[1.02, 0.01, 0.0], [0.01, 0.98, -0.02], [0.0, -0.02, 1.0]],
    };
    let packet = dir.join("motioncal.bin");
    std::fs::write(&packet, encode_packet(&cal).unwrap()).unwrap();
    let run = imucal(
        &dir,
        &[
            "flash",
            packet.to_str().unwrap(),
            "--port",
            &port,
            "--protocol",
            "motioncal",
        ],
    );
    let said = text(&run);
    assert!(run.status.success(), "{said}");
    assert!(said.contains("echoed Cal1:/Cal2: matching"), "{said}");
    let stored = sketch.eeprom().expect("the board stored the packet");
    assert_eq!(stored.accel_zerog, cal.accel_zerog);
    assert_eq!(stored.mag_hardiron, cal.mag_hardiron);
    assert_eq!(stored.mag_field, cal.mag_field);
}

#[test]
fn a_sketch_sessions_params_are_refused_by_an_imucal_board_without_force() {
    let dir = scratch("refuse");
    let params = dir.join("params.json");
    sketch_params(&params);
    let shown = params.to_str().unwrap();
    let run = imucal(&dir, &["flash", shown, "--sim", "--sim-seed", "5"]);
    let said = text(&run);
    assert!(!run.status.success(), "{said}");
    assert!(
        said.contains("measured on a board running a MotionCal calibration sketch")
            && said.contains("--force-other-device")
            && said.contains("--protocol motioncal"),
        "{said}"
    );
    let forced = imucal(
        &dir,
        &[
            "flash",
            shown,
            "--sim",
            "--sim-seed",
            "5",
            "--force-other-device",
        ],
    );
    assert!(forced.status.success(), "{}", text(&forced));
    let history = imucal(&dir, &["history", "--json"]);
    let listed = text(&history);
    assert!(listed.contains("MotionCal sketch board"), "{listed}");
}

/// A board lying still behind a link that loses `drop_rate` of its bytes each way.
fn lossy_board(seed: u64, drop_rate: f64) -> SimHandle {
    let mut options = SimOptions::new(seed);
    options.schedule = PersonSchedule::Rest;
    options.board.poser.tremor = false;
    options.speed = 5.0;
    options.faults = LinkFaults {
        drop_rate,
        ..LinkFaults::default()
    };
    SimServer::start(options).expect("the simulator starts")
}

#[test]
fn info_and_flash_over_a_link_losing_two_percent_of_bytes_name_a_noisy_link() {
    let dir = scratch("noisy");
    let board = lossy_board(81, 2e-2);
    let port = board.port_path().to_string();
    let params = dir.join("params.json");
    std::fs::write(
        &params,
        ParamsFile::from(&CalibrationSet::identity()).to_json(),
    )
    .unwrap();
    for args in [
        vec!["info", "--port", &port],
        vec![
            "flash",
            params.to_str().unwrap(),
            "--port",
            &port,
            "--no-history",
        ],
    ] {
        let run = imucal(&dir, &args);
        let said = text(&run);
        if run.status.success() {
            // A lucky run got every reply through; nothing to blame then.
            continue;
        }
        assert!(said.contains("serial link is noisy"), "{args:?}: {said}");
        assert!(said.contains("cable"), "{args:?}: {said}");
        assert!(
            !said.contains("is the board running imucal firmware"),
            "{args:?}: {said}"
        );
    }
}

#[test]
fn a_sketch_session_says_up_front_what_the_board_cannot_apply_judges_it_poor_for_this_firmware_and_marks_its_params(
) {
    let dir = scratch("session");
    let out = dir.join("mc");
    let run = imucal(
        &dir,
        &[
            "calibrate",
            "--sim",
            "--sim-protocol",
            "motioncal",
            "--sim-seed",
            "31",
            "--yes",
            "--speed",
            "20",
            "-o",
            out.to_str().unwrap(),
        ],
    );
    let said = text(&run);
    // Poor for this firmware: not sent without --accept-poor, exit 1.
    assert!(!run.status.success(), "{said}");
    let stderr = String::from_utf8_lossy(&run.stderr);
    let note = stderr
        .find("applies only the accelerometer's and gyroscope's offsets")
        .unwrap_or_else(|| panic!("no note up front: {stderr}"));
    let first_prompt = stderr.find("1/12").unwrap_or(usize::MAX);
    assert!(
        note < first_prompt,
        "the note comes after the first position: {stderr}"
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("motioncal.json")).unwrap())
            .unwrap();
    assert_eq!(summary["verdict"]["level"], "poor", "{summary}");
    let reasons = summary["verdict"]["reasons"].to_string();
    assert!(
        reasons.contains("poor for this firmware") && reasons.contains("mg budget"),
        "{reasons}"
    );
    assert_eq!(summary["sent"], false, "{summary}");
    let params = ParamsFile::load(&out.join("params.json")).unwrap();
    assert!(params.from_sketch_board(), "{:?}", params.provenance);
    // The file is not written to a board running imucal's firmware without being told to.
    let flash = imucal(
        &dir,
        &[
            "flash",
            out.join("params.json").to_str().unwrap(),
            "--sim",
            "--sim-seed",
            "5",
        ],
    );
    let flashed = text(&flash);
    assert!(!flash.status.success(), "{flashed}");
    assert!(
        flashed.contains("MotionCal calibration sketch"),
        "{flashed}"
    );
}

#[test]
fn a_stalled_capture_on_a_lossy_link_names_the_link_with_its_loss_not_the_hold() {
    use imucal::device::LinkStats;
    use imucal::session::SessionError;
    // The counters of the seed-81 session behind a link dropping 1e-3 of its bytes.
    let stats = LinkStats {
        frame_errors: 5_992,
        good_frames: 10_332,
        lost_samples: 119_920,
        received_samples: 205_180,
        ..LinkStats::default()
    };
    let note = stats.noisy_link_note().expect("a noisy link");
    let error = SessionError::NoProgress {
        port: "/dev/ttyACM0".into(),
        waited_s: 180.0,
        missing: "+X+Z up".into(),
        link_note: Some(note),
    }
    .to_string();
    assert!(
        error.contains("Not the hold")
            && error.contains("36.9 %")
            && error.contains("cable")
            && !error.contains("Hold the board still"),
        "{error}"
    );
    // A sound link leaves the advice about the hold.
    let sound = LinkStats {
        good_frames: 16_000,
        received_samples: 300_000,
        ..LinkStats::default()
    };
    assert_eq!(sound.noisy_link_note(), None);
}
