//! `imucal calibrate --protocol motioncal` (and `--sim --sim-protocol motioncal`): the guided
//! session on a board that runs Adafruit's or PJRC's MotionCal calibration sketch
//! (`imucal::session::motioncal`), with the same screen as imucal's own boards; the simulated
//! sketch board runs in-process behind a pseudo-terminal.

use std::io::IsTerminal;
use std::time::Duration;

use anyhow::Context;
use imucal::compat::motioncal::RawAccelScaling;
use imucal::compat::MotionCalClient;
use imucal::session::motioncal::{
    run_motioncal_session, save_motioncal_readings, save_motioncal_session, MotionCalOptions,
    MotionCalOutcome,
};

use super::args::CalibrateArgs;
use super::board::given_or_only_board;
use super::calibrate::{
    checked_session_dir, field_reference, interrupt_flag, session_field, session_options,
};
use super::calibrate_view::Terminal;
use super::write_policy::{not_asked, WriteDecision, WritePolicy};

/// Longest wait for the board's `Cal1:`/`Cal2:` echo (Adafruit's sketch prints it every 1.5 s).
const ECHO_TIMEOUT: Duration = Duration::from_secs(10);

/// Run the session on a MotionCal sketch board.
pub fn run(args: &CalibrateArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        !args.is_batch(),
        "a batch (--sim-boards, several --port, or --ports auto) needs boards running imucal's \
         firmware; calibrate MotionCal sketch boards one at a time with one --port"
    );
    anyhow::ensure!(
        args.resume.is_none(),
        "--resume continues sessions of imucal's firmware; a MotionCal sketch session is short, \
         start it again"
    );
    let dir = checked_session_dir(args)?;
    let given_field = field_reference(args)?;
    // Checked before a simulated board starts.
    session_options(args, session_field(given_field, None))?;
    let simulated = if args.sim {
        Some(SimulatedSketch::start(args)?)
    } else {
        None
    };
    let port = match &simulated {
        Some(sim) => sim.port(),
        None => given_or_only_board(args.port.first().map(String::as_str))?,
    };
    // As with imucal's firmware: without a given field the simulated site's stands for the one
    // a user would look up for the location.
    let field = session_field(
        given_field,
        simulated.as_ref().map(SimulatedSketch::site_field_ut),
    );
    if simulated.is_some() {
        say!(
            "Simulated MotionCal sketch board (seed {}, {}× real time) on {port}; field {:.2} µT{}",
            args.sim_seed,
            args.speed,
            field.0.unwrap_or_default(),
            if given_field.is_some() {
                " (given)"
            } else {
                " (the simulated site's, as if looked up for the location)"
            }
        );
    }
    let options = MotionCalOptions {
        session: session_options(args, field)?,
        sample_rate_hz: args.sketch_rate_hz(),
        accept_poor: args.accept_poor,
        echo_timeout: ECHO_TIMEOUT,
        interrupt: Some(interrupt_flag()?),
    };
    let mut client = MotionCalClient::open(&port, RawAccelScaling::AdafruitSketch)?;
    say!(
        "Connected to {port}: a MotionCal sketch board ({} readings/s assumed). It cannot detect \
         stillness or average poses, so this computer does both from its readings.",
        args.sketch_rate_hz()
    );
    let plain = args.yes || !std::io::stderr().is_terminal();
    let policy = WritePolicy {
        yes: args.yes,
        accept_poor: args.accept_poor,
    };
    let mut terminal = Terminal::new(plain, policy, port.clone()).with_json_events(args.json);
    let mut readings = Vec::new();
    let run = run_motioncal_session(&mut client, &options, &mut terminal, &mut readings);
    terminal.bar.finish_and_clear();
    let outcome = match run {
        Ok(outcome) => outcome,
        Err(stop) => {
            // What was read is kept: the readings are a recording `imucal fit` reads.
            if !readings.is_empty() {
                match save_motioncal_readings(&readings, &dir) {
                    Ok(path) => say!(
                        "The {} read before the stop are saved in {} (the recording format: \
                         `imucal fit {}` fits them offline)",
                        imucal::words::counted(readings.len(), "reading"),
                        path.display(),
                        path.display()
                    ),
                    Err(e) => say!(
                        "The {} read before the stop could not be saved in {}: {e}",
                        imucal::words::counted(readings.len(), "reading"),
                        dir.display()
                    ),
                }
            }
            return Err(stop.into());
        }
    };

    save_motioncal_session(&outcome, &readings, &dir).with_context(|| {
        format!(
            "the session directory `{}` could not be written",
            dir.display()
        )
    })?;
    if let Some(sim) = &simulated {
        sim.save_eeprom(&dir.join("sim-eeprom.json"))?;
    }
    print_result(&outcome, &dir);
    if !args.history.no_history {
        say!(
            "Not recorded in the calibration history: a MotionCal sketch board reports no id to \
             record it under (imucal's firmware does)"
        );
    }
    if args.json {
        let summary = std::fs::read_to_string(dir.join("motioncal.json"))
            .context("the session summary could not be read back")?;
        println!("{summary}");
    }
    let poor = outcome.fit.verdict.level == imucal::session::solve::VerdictLevel::Poor;
    if outcome.echo.is_none() && poor && !args.accept_poor {
        anyhow::bail!(
            "the verdict is poor for what this board applies, so the packet was not sent; it is \
             saved as {packet}: `imucal flash {packet} --port {port} --protocol motioncal` sends \
             it (it still corrects the offsets), or run again with --accept-poor",
            packet = dir.join("motioncal.bin").display()
        );
    }
    if terminal.decision == Some(WriteDecision::NoOneToAsk) {
        let packet = dir.join("motioncal.bin");
        return Err(not_asked(
            "The packet",
            &format!(
                "send the saved packet yourself (`stty -F {port} raw 115200`, then `cat {} > \
                 {port}`)",
                packet.display()
            ),
        ));
    }
    Ok(())
}

fn print_result(outcome: &MotionCalOutcome, dir: &std::path::Path) {
    let fit = &outcome.fit;
    let u = &fit.uncertainties;
    println!();
    println!(
        "Readings: {} from {} lines ({} unreadable), {:.1} s of the sketch; {} positions, {} of 26 \
         magnetometer directions",
        outcome.readings,
        if outcome.unified_lines { "Uni:" } else { "Raw:" },
        outcome.malformed_lines,
        outcome.session_seconds,
        outcome.poses.len(),
        outcome.coverage.covered(1)
    );
    println!(
        "imucal's fit: |a| expected error {:.3} mg, |m| {:.3} %, verdict {}{}",
        u.accel_norm_mg,
        u.mag_norm_pct,
        fit.verdict.level.name(),
        if fit.verdict.reasons.is_empty() {
            String::new()
        } else {
            format!(" ({})", fit.verdict.reasons.join("; "))
        }
    );
    print!("{}", outcome.limitations.describe());
    let cal = &outcome.conversion.calibration;
    println!(
        "{}: accel offsets {:?} m/s², gyro offsets {:?} rad/s, hard iron {:?} µT, field {:.2} µT",
        if outcome.echo.is_some() {
            "Sent to the board"
        } else {
            "The packet (not sent)"
        },
        cal.accel_zerog,
        cal.gyro_zerorate,
        cal.mag_hardiron,
        cal.mag_field
    );
    match &outcome.echo {
        Some(echo) => println!(
            "The board echoed Cal1:/Cal2: matching the packet (largest difference {:.2e}, within \
             its print precision)",
            echo.max_difference
        ),
        None => println!("Not sent: the board keeps its previous calibration."),
    }
    println!(
        "Saved {} (motioncal.bin is the packet; params.json the full model for `imucal export`)",
        dir.display()
    );
}

/// The simulated sketch board of `--sim --sim-protocol motioncal`.
#[cfg(feature = "sim")]
struct SimulatedSketch {
    handle: imucal_hil_sim::motioncal_serve::MotionCalHandle,
}

#[cfg(feature = "sim")]
impl SimulatedSketch {
    fn start(args: &CalibrateArgs) -> anyhow::Result<Self> {
        let handle =
            imucal_hil_sim::motioncal_serve::MotionCalHandle::start(args.sim_seed, args.speed)
                .context("the simulated sketch board could not start")?;
        Ok(Self { handle })
    }

    fn port(&self) -> String {
        self.handle.port_path().to_string()
    }

    /// The simulated site's field, µT.
    fn site_field_ut(&self) -> f64 {
        self.handle.site_field_ut()
    }

    /// What the simulated board's EEPROM holds, as JSON (null when nothing was stored).
    fn save_eeprom(&self, path: &std::path::Path) -> anyhow::Result<()> {
        let value = self.handle.eeprom().map(|e| {
            serde_json::json!({
                "accel_zerog": e.accel_zerog,
                "gyro_zerorate": e.gyro_zerorate,
                "mag_hardiron": e.mag_hardiron,
                "mag_field": e.mag_field,
                "mag_softiron": e.mag_softiron,
                "stored_count": self.handle.stored_count(),
            })
        });
        let text =
            serde_json::to_string_pretty(&value).context("the EEPROM could not be encoded")?;
        std::fs::write(path, text).with_context(|| format!("could not write `{}`", path.display()))
    }
}

/// Without the simulator there is no simulated board (`start` explains).
#[cfg(not(feature = "sim"))]
enum SimulatedSketch {}

#[cfg(not(feature = "sim"))]
impl SimulatedSketch {
    fn start(_args: &CalibrateArgs) -> anyhow::Result<Self> {
        anyhow::bail!(
            "this imucal was built without the simulator; rebuild with the default features \
             (cargo build -p imucal) to use --sim, or give --port"
        )
    }

    fn port(&self) -> String {
        match *self {}
    }

    fn site_field_ut(&self) -> f64 {
        match *self {}
    }

    fn save_eeprom(&self, _path: &std::path::Path) -> anyhow::Result<()> {
        match *self {}
    }
}
