//! Board commands: `ports`, `info`, `flash`, with `stream` and `record` in `device_stream.rs`
//! and `params` in `params.rs`. Thin wrappers over `imucal::device`; `--sim` puts the simulated
//! board of `board.rs` behind the port.

use std::path::PathBuf;

use clap::{Args, Subcommand};
use imucal::device::{list_ports, DeviceClient, ParamsFile};
use imucal_protocol::{CalibrationSet, SensorSet, StreamKind, Welcome};

use super::board::{connect, describe_params, BoardProtocol, PortArgs};
use super::device_stream::{record, stream, RecordArgs, StreamArgs};
use super::params::ParamsCommand;

/// Commands that talk to a board.
#[derive(Debug, Subcommand)]
pub enum DeviceCommand {
    /// List serial ports, mark likely IMU boards, and say which port would be used.
    #[command(after_help = "Example:\n  imucal ports")]
    Ports,
    /// Connect to a board and show its identity, sensors, scales, state and parameters.
    #[command(after_help = "Examples:\n  imucal info\n  imucal info --port /dev/ttyACM0")]
    Info(PortArgs),
    /// Write a calibration parameter file to a board, commit it and verify it by reading back.
    #[command(
        after_help = "Example:\n  imucal flash board42.params.json --port /dev/ttyACM0\n\n\
        The file is the JSON written by `imucal calibrate` or `imucal fit --params-out` \
        (docs/PARAMS_FORMAT.md; formats 1 and 2 are read). Sensors it does not calibrate keep \
        the board's own calibration."
    )]
    Flash(FlashArgs),
    /// Print the board's samples as they arrive (raw counts in units, or calibrated).
    #[command(
        after_help = "Examples:\n  imucal stream --port /dev/ttyACM0 --seconds 5\n  \
        imucal stream --calibrated --csv --seconds 10 > check.csv\n  \
        imucal stream --port /dev/ttyACM0 --protocol motioncal      (a MotionCal sketch board)\n  \
        imucal stream --sim --seconds 5"
    )]
    Stream(StreamArgs),
    /// Record the raw stream (in m/s², rad/s, µT, °C) to a recording CSV for `imucal fit`.
    #[command(
        after_help = "Examples:\n  imucal record --port /dev/ttyACM0 -o rest.csv --seconds 60\n  \
        imucal record --port /dev/ttyACM0 --protocol motioncal -o sketch.csv --seconds 60\n\n\
        Columns: t_s,ax,ay,az,gx,gy,gz,mx,my,mz,temp_c (sensors the board lacks are left out; a \
        MotionCal sketch prints no temperature, and its times are counted at --sketch-rate)."
    )]
    Record(RecordArgs),
    /// Read the board's active parameters into a file, or reset them to identity.
    #[command(subcommand)]
    Params(ParamsCommand),
}

/// Arguments of `imucal flash`.
#[derive(Debug, Args)]
pub struct FlashArgs {
    /// Parameter file (JSON written by `imucal calibrate`).
    pub params: PathBuf,
    /// Which port to use.
    #[command(flatten)]
    pub port: PortArgs,
    /// Set this sensor to identity instead of keeping the board's calibration when the file
    /// leaves it out (repeatable).
    #[arg(long, value_enum, value_name = "SENSOR")]
    pub reset: Vec<SensorArg>,
    /// Write the file even though it was made for another board (or other sensors or ranges).
    #[arg(long)]
    pub force_other_device: bool,
    /// What the board at --port runs: imucal's firmware, or a sketch for MotionCal (Adafruit's
    /// calibration sketch), which is sent the file's 68-byte calibration packet (a
    /// `motioncal.bin`, or what the sketch can apply of a params.json) and checked by its echo.
    #[arg(long, value_enum, default_value = "imucal", conflicts_with = "sim")]
    pub protocol: BoardProtocol,
    /// Simulator: what the simulated board runs, imucal's firmware or Adafruit's MotionCal
    /// calibration sketch.
    #[arg(long, value_enum, default_value = "imucal", requires = "sim")]
    pub sim_protocol: BoardProtocol,
    /// Write the file even though a parameter is past a bound of every common part's datasheet
    /// (a damaged sensor, or a hand-edited file), as `calibrate --accept-outlier` does.
    #[arg(long)]
    pub accept_outlier: bool,
    /// Where to record the flash.
    #[command(flatten)]
    pub history: super::history::RecordArgs,
}

/// A sensor a parameter file calibrates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SensorArg {
    /// Accelerometer.
    Accel,
    /// Gyroscope.
    Gyro,
    /// Magnetometer.
    Mag,
}

impl SensorArg {
    /// The key of the sensor in a parameter file.
    pub fn key(self) -> &'static str {
        match self {
            SensorArg::Accel => "accel",
            SensorArg::Gyro => "gyro",
            SensorArg::Mag => "mag",
        }
    }
}

/// Runs a board command.
pub fn run(command: &DeviceCommand) -> anyhow::Result<()> {
    match command {
        DeviceCommand::Ports => ports(),
        DeviceCommand::Info(args) => info(args),
        DeviceCommand::Flash(args) => flash(args),
        DeviceCommand::Stream(args) => stream(args),
        DeviceCommand::Record(args) => record(args),
        DeviceCommand::Params(command) => super::params::run(command),
    }
}

fn ports() -> anyhow::Result<()> {
    let ports = list_ports()?;
    if ports.is_empty() {
        println!(
            "no serial ports found (plug the board in; a simulator's pty is given with --port)"
        );
    }
    for port in &ports {
        let mark = match port.board_match() {
            Some(found) => format!("  <- {}", found.describe()),
            None => String::new(),
        };
        println!("{:<16} {}{mark}", port.path, port.describe());
    }
    match imucal::device::choose_port_with_reason(&ports) {
        Ok((port, why)) => println!("without --port, imucal uses {}: {why}", port.path),
        Err(reason) => println!("without --port, imucal cannot choose: {reason}"),
    }
    Ok(())
}

fn sensor_list(sensors: &SensorSet) -> String {
    let names: Vec<&str> = [
        (sensors.accel, "accelerometer"),
        (sensors.gyro, "gyroscope"),
        (sensors.mag, "magnetometer"),
        (sensors.temp, "temperature"),
    ]
    .into_iter()
    .filter_map(|(present, name)| present.then_some(name))
    .collect();
    if names.is_empty() {
        "none".to_string()
    } else {
        names.join(", ")
    }
}

fn info(args: &PortArgs) -> anyhow::Result<()> {
    let (mut client, _board) = connect(args)?;
    let rtt = client.ping()?;
    let status = client.status()?;
    let params = client.get_params()?;
    let w = *client.welcome();
    let s = w.scales;
    let fw = w.firmware_version;
    println!("port            {}", client.port_name());
    println!("device id       {}", w.device_id);
    println!("firmware        {}.{}.{}", fw.major, fw.minor, fw.patch);
    println!(
        "protocol        board {}.{}, in use {}.{}",
        w.protocol_major,
        w.protocol_minor,
        client.protocol().major,
        client.protocol().minor
    );
    println!("sensors         {}", sensor_list(&w.sensors));
    println!("sample rate     {} Hz", s.sample_rate_hz);
    println!(
        "accelerometer   {:e} m/s² per count, range ±{} m/s²",
        s.accel_mps2_per_count, s.accel_range_mps2
    );
    println!(
        "gyroscope       {:e} rad/s per count, range ±{} rad/s",
        s.gyro_rads_per_count, s.gyro_range_rads
    );
    println!(
        "magnetometer    {:e} µT per count, range ±{} µT",
        s.mag_ut_per_count, s.mag_range_ut
    );
    println!(
        "temperature     {} °C per count, {} °C at 0",
        s.temp_c_per_count, s.temp_offset_c
    );
    println!("uptime          {:.1} s", status.uptime_ms as f64 / 1000.0);
    println!(
        "state           {}, {}",
        match status.streaming {
            Some(StreamKind::Raw) => "streaming raw",
            Some(StreamKind::Calibrated) => "streaming calibrated",
            None => "not streaming",
        },
        if status.still { "still" } else { "moving" }
    );
    let e = status.errors;
    println!(
        "error counters  rx frames {}, dropped samples {}, sensor {}, flash {}",
        e.rx_frame_errors, e.dropped_samples, e.sensor_errors, e.flash_errors
    );
    println!(
        "parameters      {} (CRC {:#010x}, store sequence {})",
        describe_params(&params),
        status.active_crc,
        status.active_seq
    );
    println!(
        "link            round trip {:.1} ms",
        rtt.as_secs_f64() * 1e3
    );
    Ok(())
}

fn flash(args: &FlashArgs) -> anyhow::Result<()> {
    let shown = args.params.display().to_string();
    let protocol = if args.port.sim {
        args.sim_protocol
    } else {
        args.protocol
    };
    if protocol == BoardProtocol::Motioncal {
        return flash_sketch(args, &shown);
    }
    let file = ParamsFile::load(&args.params)?;
    if let (Some(why), true) = (file.holds_nothing(), args.reset.is_empty()) {
        anyhow::bail!("`{shown}` is not written: {why}");
    }
    let counts: Vec<String> = file
        .non_nominal_inputs()
        .iter()
        .map(|(sensor, unit)| format!("{sensor} ({unit})"))
        .collect();
    if !counts.is_empty() {
        anyhow::bail!(
            "`{shown}` calibrates {} from raw data without a known scale, but the board applies \
             calibrations to m/s², rad/s and µT; refit with the data's unit (--accel-unit, \
             --gyro-unit, --mag-unit, or --gyro-scale) or use `imucal export` for firmware \
             that reads raw counts",
            counts.join(", ")
        );
    }
    let mut set = file.to_calibration_set(&shown)?;
    hold_to_part_limits(&file, &shown, args.accept_outlier)?;
    super::history::check_before_writing(&args.history)?;
    let (mut client, _board) = connect(&args.port)?;
    let measured_on = check_binding(&file, client.welcome(), &shown, args.force_other_device)?;
    let kept = merge_with_active(&mut client, &file, &mut set, &args.reset, &shown)?;
    // A write that committed is recorded even when its read-back could not be completed
    // (the board's status shows the new set's CRC); the command still fails then.
    let (status, unsettled) = match client.write_params_settled(&set) {
        Ok(report) => {
            if let Some(recovered) = &report.recovered {
                say!("imucal: note: {recovered}");
            }
            println!(
                "wrote {shown} to {} (CRC {:#010x}, store sequence {}), committed, and verified \
                 by reading it back",
                client.port_name(),
                report.status.active_crc,
                report.status.active_seq
            );
            (report.status, None)
        }
        Err(imucal::device::DeviceError::WriteUnsettled {
            committed: Some(status),
            port,
            state,
            cause,
        }) => {
            let error = imucal::device::DeviceError::WriteUnsettled {
                committed: Some(status),
                port,
                state,
                cause,
            };
            (status, Some(error))
        }
        Err(error) => return Err(error.into()),
    };
    let welcome = client.welcome();
    let mut record = imucal::history::CalibrationRecord::new(
        &welcome.device_id.to_string(),
        imucal::history::RecordSource::Flash,
        file.as_written(&set, &kept),
        status.active_crc,
    );
    record.firmware_version = Some(super::history::firmware_text(&welcome.firmware_version));
    if let Some(measured_on) = measured_on {
        record.board = imucal::history::BoardWrite::FromOtherBoard { measured_on };
    }
    super::history::record(&args.history, record)?;
    match unsettled {
        Some(error) => {
            say!("imucal: note: the write is recorded in the history, as the board's status shows the new set active");
            Err(error.into())
        }
        None => Ok(()),
    }
}

/// The bounds `calibrate` holds a set to ([`imucal::history::part_limits`]): a refusing one
/// refuses the file unless `accept`, a warning one is said.
fn hold_to_part_limits(file: &ParamsFile, shown: &str, accept: bool) -> anyhow::Result<()> {
    use imucal::history::part_limits::{beyond_part_limits_of, refusal_phrase, warning_phrases};
    let findings = beyond_part_limits_of(file);
    for warning in warning_phrases(&findings) {
        say!("imucal: warning: `{shown}`: {warning}");
    }
    match refusal_phrase(&findings) {
        Some(why) if accept => {
            say!("imucal: warning: writing `{shown}` although {why} (--accept-outlier)");
            Ok(())
        }
        Some(why) => anyhow::bail!(
            "`{shown}` is not written: {why}; check the board (or the file, if it was edited by \
             hand), or pass --accept-outlier to write it anyway"
        ),
        None => Ok(()),
    }
}

/// Longest wait for a sketch board's `Cal1:`/`Cal2:` echo (Adafruit's sketch prints it every
/// 1.5 s).
const SKETCH_ECHO_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(10);

/// `flash --protocol motioncal`: sends the file's calibration packet to a MotionCal sketch
/// board and checks the board's echo of it. Nothing is recorded in the history: the sketch
/// reports no id to record it under.
fn flash_sketch(args: &FlashArgs, shown: &str) -> anyhow::Result<()> {
    use imucal::compat::motioncal::RawAccelScaling;
    use imucal::compat::MotionCalClient;
    anyhow::ensure!(
        args.reset.is_empty(),
        "--reset sets sensors of imucal's firmware to identity; a MotionCal sketch takes a whole \
         packet, so leave out --reset"
    );
    let (calibration, note) = imucal::compat::sketch_calibration_of_file(&args.params)?;
    if let Some(note) = note {
        say_part!("{note}");
    }
    let board = args.port.open_board(BoardProtocol::Motioncal)?;
    let mut client = MotionCalClient::open(&board.path, RawAccelScaling::AdafruitSketch)?;
    let echo = client.send_calibration(&calibration, SKETCH_ECHO_TIMEOUT)?;
    println!(
        "sent {shown} to {} as MotionCal's calibration packet; the board echoed Cal1:/Cal2: \
         matching it (largest difference {:.2e}, within its print precision)",
        board.path, echo.max_difference
    );
    if !args.history.no_history {
        say!(
            "imucal: note: not recorded in the calibration history: a MotionCal sketch board \
             reports no id to record it under"
        );
    }
    Ok(())
}

/// Refuses a file made for another board unless `force`; notes a file that names no board.
/// Returns the other board's id when `force` lets its file through.
fn check_binding(
    file: &ParamsFile,
    welcome: &Welcome,
    shown: &str,
    force: bool,
) -> anyhow::Result<Option<String>> {
    let board = welcome.device_id.to_string();
    let mut mismatches = match &file.device {
        Some(device) => {
            for note in device.notes(welcome) {
                say!("imucal: note: {note}");
            }
            device.mismatches(welcome)
        }
        // No ranges to compare: the set itself must still be one this board's parts can have.
        None => file.beyond_the_board(welcome),
    };
    let sketch = file.from_sketch_board();
    if sketch {
        mismatches.push(format!(
            "it was measured on a board running a MotionCal calibration sketch (the sketch's \
             readings, scales and axes), not on imucal's firmware of device {board}; send it to \
             that sketch board with `imucal flash {shown} --port PORT --protocol motioncal`"
        ));
    }
    match file.device_id() {
        // Where the file came from is not known (a `device` block may have been removed), so
        // only its provenance, when it has one, is quoted.
        None if mismatches.is_empty() && !sketch => say!(
            "imucal: note: `{shown}` names no board (no `device` block, no device id{}); its \
             set fits the board's sensors and ranges, writing it to device {board}",
            file.provenance
                .as_ref()
                .map_or(String::new(), |p| format!("; fitted from {}", p.source))
        ),
        None => {}
        Some(id) if file.device.is_none() && id != board => mismatches.push(format!(
            "it was fitted for device {id}, but the board is device {board}"
        )),
        Some(_) => {}
    }
    if mismatches.is_empty() {
        return Ok(None);
    }
    if force {
        say!(
            "imucal: warning: writing `{shown}` although {} (--force-other-device)",
            mismatches.join("; ")
        );
        if sketch {
            return Ok(Some("a MotionCal sketch board".to_string()));
        }
        return Ok(file
            .device_id()
            .filter(|id| *id != board)
            .map(str::to_string));
    }
    anyhow::bail!(
        "`{shown}` is not for this board: {}; calibrate this board, or pass \
         --force-other-device to write it anyway",
        mismatches.join("; ")
    )
}

/// Sensors the file leaves out (absent or not fitted) keep the board's active calibration,
/// with its residual and reference magnitude, unless `reset` names them; then they become
/// identity. Returns the keys of the sensors kept.
fn merge_with_active(
    client: &mut DeviceClient,
    file: &ParamsFile,
    set: &mut CalibrationSet,
    reset: &[SensorArg],
    shown: &str,
) -> anyhow::Result<Vec<&'static str>> {
    let left_out: Vec<SensorArg> = [SensorArg::Accel, SensorArg::Gyro, SensorArg::Mag]
        .into_iter()
        .filter(|s| file.left_out().iter().any(|(key, _)| *key == s.key()))
        .collect();
    let identity = CalibrationSet::identity();
    for sensor in reset {
        if !left_out.contains(sensor) {
            anyhow::bail!(
                "--reset {0} conflicts with `{shown}`, which calibrates the {0}; leave out \
                 --reset {0} or remove {0} from the file",
                sensor.key()
            );
        }
    }
    let kept: Vec<SensorArg> = left_out
        .iter()
        .copied()
        .filter(|s| !reset.contains(s))
        .collect();
    let active = if kept.is_empty() {
        identity
    } else {
        client.get_params()?
    };
    for sensor in &left_out {
        let source = if kept.contains(sensor) {
            &active
        } else {
            &identity
        };
        let why = file
            .not_fitted
            .get(sensor.key())
            .map_or("it is not in the file".to_string(), |w| {
                format!("not fitted: {w}")
            });
        match sensor {
            SensorArg::Accel => {
                set.accel = source.accel;
                set.residuals.accel_rms = source.residuals.accel_rms;
                set.reference.gravity_mps2 = source.reference.gravity_mps2;
            }
            SensorArg::Gyro => {
                set.gyro = source.gyro;
                set.gyro_g_sensitivity = source.gyro_g_sensitivity;
                set.residuals.gyro_rms = source.residuals.gyro_rms;
            }
            SensorArg::Mag => {
                set.mag = source.mag;
                set.residuals.mag_rms = source.residuals.mag_rms;
                // The file's field is a placeholder when it fitted no magnetometer.
                set.reference.field_ut = source.reference.field_ut;
            }
        }
        let what = if kept.contains(sensor) {
            "keeps its current calibration (--reset to set it to identity)"
        } else {
            "is set to identity (--reset)"
        };
        say!(
            "imucal: note: `{shown}` has no {} calibration ({why}); the board's {} {what}",
            sensor.key(),
            sensor.key()
        );
    }
    Ok(kept.iter().map(|s| s.key()).collect())
}
