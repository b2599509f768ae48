//! `imucal calibrate`: the guided calibration on a board (`--port`) or on the simulated board
//! started in-process behind a pseudo-terminal (`--sim`), which the host then opens with the
//! same serial-port code as real hardware. The session itself is `imucal::session`; this file
//! is its user interface: pictures and prompts, indicatif bars for stillness, hold progress and
//! coverage (plain lines with `--yes` or when stderr is not a terminal), the result, the
//! before/after table, and the session directory. With `--analyze` the residual analysis of the
//! session's poses follows, and the effects it accepts are written as the firmware's extended
//! terms (`imucal::session::extend`). The screen is `calibrate_view.rs`, the `--analyze` step
//! `calibrate_extend.rs`, the simulated board `calibrate_sim.rs`, several
//! boards at once `calibrate_batch.rs`.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use anyhow::Context;
use imucal::device::{choose_port, list_ports, DeviceClient};
use imucal::session::{run_session, save_session, summary, SessionOptions};

use super::args::CalibrateArgs;
use super::calibrate_extend::close_the_loop;
use super::calibrate_sim::Simulated;
use super::calibrate_view::{before_after_table, Terminal};

fn duration_arg(name: &str, seconds: f64) -> anyhow::Result<Duration> {
    anyhow::ensure!(
        seconds.is_finite() && seconds > 0.0,
        "{name} is {seconds}, but it must be a number of seconds greater than zero"
    );
    Ok(Duration::from_secs_f64(seconds))
}

pub(super) fn unix_now() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

/// The session's settings from the flags, with the magnetometer's reference `field_ut`.
pub(super) fn session_options(
    args: &CalibrateArgs,
    field_ut: Option<f64>,
) -> anyhow::Result<SessionOptions> {
    anyhow::ensure!(
        args.gravity.is_finite() && args.gravity > 0.0,
        "--gravity is {}, but it must be a positive number of m/s²",
        args.gravity
    );
    if let Some(field) = field_ut {
        anyhow::ensure!(
            field.is_finite() && field > 0.0,
            "--field-ut is {field}, but it must be a positive number of µT"
        );
    }
    Ok(SessionOptions {
        gravity_mps2: args.gravity,
        field_ut,
        hold: duration_arg("--hold", args.hold)?,
        pose_timeout: duration_arg("--pose-timeout", args.pose_timeout)?,
        mag_timeout: duration_arg("--mag-timeout", args.mag_timeout)?,
        rest_timeout: duration_arg("--rest-timeout", args.rest_timeout)?,
        rounds: usize::from(args.rounds),
        ..SessionOptions::default()
    })
}

/// Run `imucal calibrate`.
pub fn run(args: &CalibrateArgs) -> anyhow::Result<()> {
    // Checked before a simulator starts or a board is opened.
    session_options(args, args.field_ut)?;
    if args.sim_boards.is_some() || args.ports.is_some() || args.port.len() > 1 {
        return super::calibrate_batch::run(args);
    }
    let simulated = if args.sim {
        Some(Simulated::start(args)?)
    } else {
        None
    };
    let port = match (&simulated, args.port.first()) {
        (Some(sim), _) => sim.port(),
        (None, Some(port)) => port.clone(),
        (None, None) => choose_port(&list_ports()?)?.path.clone(),
    };
    let modelled = args
        .location
        .as_ref()
        .map(imucal::geomag::local_field_today)
        .transpose()
        .context("the field at --location could not be modelled")?;
    if let (Some(model), None) = (&modelled, args.field_ut) {
        eprintln!(
            "Reference field from the World Magnetic Model at --location: {:.2} µT, dip {:.1}°",
            model.total_ut, model.inclination_deg
        );
    }
    let field_ut = args
        .field_ut
        .or(modelled.as_ref().map(|m| m.total_ut))
        .or(simulated.as_ref().map(Simulated::field_ut));
    if simulated.is_some() {
        eprintln!(
            "Simulated board (seed {}, {}× real time) on {port}; field {:.2} µT{}",
            args.sim_seed,
            args.speed,
            field_ut.unwrap_or_default(),
            if args.field_ut.is_some() || modelled.is_some() {
                " (given)"
            } else {
                " (the simulated site's, as if looked up for the location)"
            }
        );
    }

    let options = session_options(args, field_ut)?;
    let mut client = DeviceClient::open(&port)?;
    let welcome = *client.welcome();
    eprintln!(
        "Connected to {port}: device {}, firmware {}.{}.{}, {} Hz",
        welcome.device_id,
        welcome.firmware_version.major,
        welcome.firmware_version.minor,
        welcome.firmware_version.patch,
        welcome.scales.sample_rate_hz
    );
    let plain = args.yes || !std::io::stderr().is_terminal();
    let mut terminal = Terminal::new(plain, args.yes, port.clone());
    let outcome = run_session(&mut client, &options, &mut terminal)?;
    terminal.bar.finish_and_clear();

    let dir = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("imucal-session-{}", unix_now())));
    save_session(&outcome, &dir)?;
    if let Some(sim) = &simulated {
        sim.save_truth(&dir.join("truth.json"))?;
    }
    // Recorded only once the session directory holds the calibration.
    let mut record =
        imucal::history::CalibrationRecord::from_session(&summary(&outcome), &outcome.poses);
    record.firmware_version = Some(super::history::firmware_text(&welcome.firmware_version));
    // A failed write is returned after the summary is printed, so nothing is hidden.
    let recorded = super::history::record(&args.history, record);
    let closed = if args.analyze {
        Some(close_the_loop(
            &mut client,
            &options,
            &outcome,
            &dir,
            args.json,
        )?)
    } else {
        None
    };

    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&summary(&outcome))
                .context("the summary could not be encoded")?
        );
    } else {
        println!();
        print!("{}", before_after_table(&outcome));
        if let Some(Some(extended)) = &closed {
            println!(
                "With the extended set at rest: |a| error {:.3} mg, |m| error {:.3} %, gyro rate \
                 {:.4} °/s",
                extended.accel_error_mg, extended.mag_error_pct, extended.gyro_rate_dps
            );
        }
        println!(
            "Session: {:.1} s {} ({:.1} s wall), {} positions, {} of 26 magnetometer \
             directions; verified: {}",
            outcome.session_seconds,
            if args.sim {
                "simulated"
            } else {
                "on the board's clock"
            },
            outcome.wall_seconds,
            outcome.poses.len(),
            outcome.coverage.covered(1),
            if outcome.verified {
                "yes"
            } else {
                "no (not written)"
            }
        );
        println!(
            "Saved {} (`imucal flash {}` writes the parameters again)",
            dir.display(),
            dir.join("params.json").display()
        );
    }
    recorded
}
