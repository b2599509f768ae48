//! `imucal calibrate`: the guided calibration on a board (`--port`) or on the simulated board
//! started in-process behind a pseudo-terminal (`--sim`), which the host then opens with the
//! same serial-port code as real hardware. The session itself is `imucal::session`; this file
//! is its user interface: pictures and prompts, indicatif bars for stillness, hold progress and
//! coverage (plain lines with `--yes` or when stderr is not a terminal), the result, the
//! before/after table, and the session directory. With `--analyze` the residual analysis of the
//! session's poses follows, and the effects it accepts are written as the firmware's extended
//! terms (`imucal::session::extend`).

use std::io::{BufRead, IsTerminal, Write};
use std::path::PathBuf;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::Context;
use clap::Args;
use imucal::analysis::report;
use imucal::device::ParamsFile;
use imucal::device::{choose_port, list_ports, DeviceClient};
use imucal::session::{
    analyse_poses, extend_set, rest_errors, run_session, save_session, stream_for, summary,
    RestErrors, SessionEvent, SessionFit, SessionObserver, SessionOptions, SessionOutcome,
    VerdictLevel,
};
use imucal_protocol::StreamKind;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Arguments of `imucal calibrate`.
#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// Serial port of the board (default: the only likely board from `imucal ports`).
    #[arg(long, short = 'p', conflicts_with = "sim")]
    pub port: Option<String>,
    /// Calibrate the simulated board, started in-process on a pseudo-terminal.
    #[arg(long)]
    pub sim: bool,
    /// Simulator: seed of the board's errors, noise and the simulated person.
    #[arg(long, default_value_t = 1, requires = "sim")]
    pub sim_seed: u64,
    /// Simulator: switch a hidden effect on (repeatable), `[sensor.]name[=size]`.
    #[arg(long = "sim-effect", requires = "sim")]
    pub sim_effects: Vec<String>,
    /// Simulator: sensor chip, lsm9ds1 (Nano 33 BLE Sense) or bmi270 (BMI270 + BMM150, Rev2).
    #[arg(long, value_enum, default_value = "lsm9ds1", requires = "sim")]
    #[cfg(feature = "sim")]
    pub sim_chip: imucal_hil_sim::board::SensorChip,
    /// Simulator: simulated seconds per wall second.
    #[arg(long, default_value_t = 15.0, requires = "sim")]
    pub speed: f64,
    /// Simulator: die temperature, `constant` (the person's ambient) or `sweep[:LOW:HIGH:PERIOD]`
    /// (°C, °C, s; `sweep` alone is 10–40 °C every 90 s).
    #[arg(long, default_value = "constant", requires = "sim")]
    pub sim_temperature: String,
    /// Capture the twelve positions this many times over (the simulated person repeats them).
    /// Spreading the poses over time and temperature lets `--analyze` see temperature effects;
    /// the accelerometer's analysis needs at least two rounds.
    #[arg(long, default_value_t = 1)]
    pub rounds: u8,
    /// After the base fit, analyse the residual of the session's poses; the effects the firmware
    /// can apply (bias temperature polynomial, scale temperature coefficient, non-linearity, gyro
    /// g-sensitivity) that the analysis accepts are added to the set, written, verified and
    /// checked at rest again; the written set is saved as params.json (the base set as
    /// params-base.json) and the analysis as analysis.json.
    ///
    /// Example: imucal calibrate --sim --sim-temperature sweep
    /// --sim-effect accel.bias_temperature=2 --rounds 3 --analyze --yes
    #[arg(long, verbatim_doc_comment)]
    pub analyze: bool,
    /// Unattended: write without asking, and print plain progress lines.
    #[arg(long, short = 'y')]
    pub yes: bool,
    /// Print the machine-readable summary (JSON) on stdout instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Session directory (default: `imucal-session-<unix time>` here).
    #[arg(long, short = 'o')]
    pub out: Option<PathBuf>,
    /// Where to record the calibration.
    #[command(flatten)]
    pub history: super::history::RecordArgs,
    /// Local gravity, m/s².
    #[arg(long, default_value_t = 9.806_65)]
    pub gravity: f64,
    /// Local field magnitude, µT (e.g. from a geomagnetic model). Without it the magnetometer
    /// keeps its mean sensitivity (with `--sim`: the simulated site's field).
    #[arg(long)]
    pub field_ut: Option<f64>,
    /// Where the board is (latitude, longitude in degrees, optional altitude in m): the World
    /// Magnetic Model's field there today is the magnetometer reference unless --field-ut is given.
    #[arg(long, value_name = "LAT,LON[,ALT_M]", allow_hyphen_values = true)]
    pub location: Option<imucal::geomag::Location>,
    /// Still time averaged per position, s.
    #[arg(long, default_value_t = 1.5)]
    pub hold: f64,
    /// Longest wait for the next position, s.
    #[arg(long, default_value_t = 180.0)]
    pub pose_timeout: f64,
    /// Longest magnetometer phase, s.
    #[arg(long, default_value_t = 180.0)]
    pub mag_timeout: f64,
    /// Longest wait for the board to lie still at the end, s.
    #[arg(long, default_value_t = 120.0)]
    pub rest_timeout: f64,
}

fn duration_arg(name: &str, seconds: f64) -> anyhow::Result<Duration> {
    anyhow::ensure!(
        seconds.is_finite() && seconds > 0.0,
        "{name} is {seconds}, but it must be a number of seconds greater than zero"
    );
    Ok(Duration::from_secs_f64(seconds))
}

/// The terminal interface of a session.
struct Terminal {
    plain: bool,
    yes: bool,
    port: String,
    bar: ProgressBar,
    last_line: Option<Instant>,
    last_coverage: usize,
}

impl Terminal {
    fn new(plain: bool, yes: bool, port: String) -> Self {
        let bar = if plain {
            ProgressBar::hidden()
        } else {
            let bar = ProgressBar::with_draw_target(Some(100), ProgressDrawTarget::stderr());
            bar.set_style(
                ProgressStyle::with_template("{prefix:>10} [{bar:30}] {msg}")
                    .unwrap_or_else(|_| ProgressStyle::default_bar())
                    .progress_chars("=> "),
            );
            bar
        };
        Self {
            plain,
            yes,
            port,
            bar,
            last_line: None,
            last_coverage: usize::MAX,
        }
    }

    fn line(&self, text: &str) {
        if self.plain {
            eprintln!("{text}");
        } else {
            self.bar.println(text);
        }
    }

    /// Plain mode: at most one progress line every two seconds.
    fn throttled(&mut self, text: &str) {
        if self
            .last_line
            .is_none_or(|t| t.elapsed() >= Duration::from_secs(2))
        {
            self.last_line = Some(Instant::now());
            eprintln!("{text}");
        }
    }

    fn bar(&mut self, prefix: &str, length: u64, position: u64, message: String) {
        if self.plain {
            self.throttled(&format!("  {prefix}: {message}"));
        } else {
            self.bar.set_prefix(prefix.to_string());
            self.bar.set_length(length.max(1));
            self.bar.set_position(position.min(length));
            self.bar.set_message(message);
        }
    }
}

fn stillness_text(still: bool, accel_std: f64, gyro_std: f64) -> String {
    format!(
        "{} (accel σ {:.3} m/s², gyro σ {:.4} rad/s)",
        if still { "still " } else { "moving" },
        accel_std,
        gyro_std
    )
}

fn triple(values: [f64; 3], precision: usize) -> String {
    let parts: Vec<String> = values
        .iter()
        .map(|v| format!("{v:>+.precision$}"))
        .collect();
    format!("[{}]", parts.join(", "))
}

fn sigmas(values: [f64; 3], precision: usize) -> String {
    let parts: Vec<String> = values.iter().map(|v| format!("{v:.precision$}")).collect();
    format!("[{}]", parts.join(", "))
}

fn describe_fit(fit: &SessionFit) -> Vec<String> {
    let u = &fit.uncertainties;
    let mg = 1000.0 / imucal::session::solve::STANDARD_GRAVITY;
    let accel_b = [0, 1, 2].map(|i| fit.accel.cal.b[i] * mg);
    let accel_scale = [0, 1, 2].map(|i| (fit.accel.cal.a[(i, i)] - 1.0) * 1e6);
    let gyro_b = [0, 1, 2].map(|i| fit.gyro.cal.b[i].to_degrees());
    let mag_b = [0, 1, 2].map(|i| fit.mag.cal.b[i]);
    let source = match fit.field_source {
        imucal::session::FieldSource::Given => "given",
        imucal::session::FieldSource::MeanRadius => "the sensor's mean radius",
    };
    let mut lines = vec![
        "Fit (LM norm model, gyro bias from the holds, LM ellipsoid + dip alignment):".to_string(),
        format!(
            "  accelerometer  offset {} mg ± {}",
            triple(accel_b, 2),
            sigmas(u.accel_bias_mg, 3)
        ),
        format!(
            "                 scale  {} ppm ± {}",
            triple(accel_scale, 0),
            sigmas(u.accel_scale_ppm, 0)
        ),
        format!(
            "                 expected |a| error ± {:.3} mg (1σ, worst direction)",
            u.accel_norm_mg
        ),
        format!(
            "  gyroscope      bias   {} °/s ± {}",
            triple(gyro_b, 3),
            sigmas(u.gyro_bias_dps, 4)
        ),
        format!(
            "                 scale  {} (diagonal of A; 1 = nominal)",
            triple([0, 1, 2].map(|i| fit.gyro.cal.a[(i, i)]), 4)
        ),
        format!(
            "  magnetometer   offset {} µT ± {}",
            triple(mag_b, 2),
            sigmas(u.mag_bias_ut, 3)
        ),
        format!(
            "                 expected |m| error ± {:.3} % (1σ); field {:.2} µT ({source}); \
             aligned to the accelerometer ± {:.3}°",
            u.mag_norm_pct, fit.field_ut, u.alignment_deg
        ),
    ];
    let verdict = match fit.verdict.level {
        VerdictLevel::Good => "good",
        VerdictLevel::Marginal => "marginal",
        VerdictLevel::Poor => "poor",
    };
    lines.push(format!("  verdict: {verdict}"));
    lines.extend(fit.verdict.reasons.iter().map(|r| format!("    - {r}")));
    lines
}

impl SessionObserver for Terminal {
    fn event(&mut self, event: &SessionEvent<'_>) {
        match event {
            SessionEvent::Prompt {
                target,
                captured,
                total,
            } => {
                self.last_line = None;
                self.line(&format!(
                    "\nPosition {}/{total}: hold the board {} (any order is fine)",
                    captured + 1,
                    target.name
                ));
                for row in target.picture() {
                    if !row.is_empty() {
                        self.line(&row);
                    }
                }
            }
            SessionEvent::Motion {
                state,
                at,
                needed,
                settle_s,
            } => {
                let place = match (at, needed) {
                    (Some(t), true) => format!("in {}", t.name),
                    (Some(t), false) => format!("in {} (already captured)", t.name),
                    (None, _) => "between positions".to_string(),
                };
                let progress = (state.still_for_s / settle_s * 100.0) as u64;
                self.bar(
                    "stillness",
                    100,
                    if *needed { progress } else { 0 },
                    format!(
                        "{} {place}",
                        stillness_text(state.still, state.accel_std_mps2, state.gyro_std_rads)
                    ),
                );
            }
            SessionEvent::Capturing { target, progress } => {
                let fraction = progress.elapsed.as_secs_f64() / progress.timeout.as_secs_f64();
                let still = match progress.still {
                    Some(true) => "still",
                    Some(false) => "moving",
                    None => "waiting",
                };
                self.bar(
                    "holding",
                    100,
                    (fraction * 100.0) as u64,
                    format!("averaging {} ({still}), keep it there", target.name),
                );
            }
            SessionEvent::Captured {
                target,
                samples,
                captured,
                total,
            } => self.line(&format!(
                "  captured {} ({samples} samples) — {captured}/{total}",
                target.name
            )),
            SessionEvent::CaptureFailed { target, reason } => {
                self.line(&format!("  {} not captured: {reason}", target.name));
            }
            SessionEvent::Note(text) => self.line(&format!("Note: {text}")),
            SessionEvent::MagPrompt => {
                self.last_line = None;
                self.line(
                    "\nMagnetometer: turn the board slowly through all directions (roll, pitch \
                     and yaw), away from steel, magnets and cables.",
                );
            }
            SessionEvent::MagCoverage {
                covered,
                regions,
                samples,
                empty,
            } => {
                let shown: Vec<&str> = empty.iter().take(6).map(String::as_str).collect();
                let more = empty.len().saturating_sub(shown.len());
                let missing = if empty.is_empty() {
                    "every direction reached".to_string()
                } else if more > 0 {
                    format!("still empty: {} and {more} more", shown.join(" "))
                } else {
                    format!("still empty: {}", shown.join(" "))
                };
                let message = format!("{covered}/{regions} directions, {samples} samples; {missing}");
                if self.plain && *covered != self.last_coverage {
                    self.last_coverage = *covered;
                    self.last_line = None;
                }
                self.bar("coverage", *regions as u64, *covered as u64, message);
            }
            SessionEvent::RestPrompt => {
                self.last_line = None;
                self.line("\nPut the board down and leave it still for the final check.");
            }
            SessionEvent::Resting {
                still_for_s,
                needed_s,
            } => self.bar(
                "rest",
                100,
                (still_for_s / needed_s * 100.0) as u64,
                format!("still for {still_for_s:.1} of {needed_s:.1} s"),
            ),
            SessionEvent::Measuring { kind } => {
                let what = match kind {
                    StreamKind::Raw => "raw readings at rest (before)",
                    StreamKind::Calibrated => "calibrated readings at rest (after)",
                };
                self.line(&format!("Measuring {what}…"));
            }
            SessionEvent::Fitted(fit) => {
                self.bar.finish_and_clear();
                for line in describe_fit(fit) {
                    self.line(&line);
                }
            }
            SessionEvent::Verified(status) => self.line(&format!(
                "Written to {}, committed, read back and compared: CRC {:#010x} (store sequence {})",
                self.port, status.active_crc, status.active_seq
            )),
        }
    }

    fn confirm_write(&mut self, fit: &SessionFit) -> bool {
        if self.yes || !std::io::stdin().is_terminal() {
            return true;
        }
        let advice = if fit.verdict.level == VerdictLevel::Poor {
            " (the verdict is poor)"
        } else {
            ""
        };
        eprint!(
            "Write these parameters to the board on {}{advice}? [Y/n] ",
            self.port
        );
        let _ = std::io::stderr().flush();
        let mut answer = String::new();
        if std::io::stdin().lock().read_line(&mut answer).is_err() {
            return false;
        }
        !matches!(answer.trim().to_lowercase().as_str(), "n" | "no")
    }
}

fn before_after_table(outcome: &SessionOutcome) -> String {
    let before = &outcome.before;
    let after = outcome.after.as_ref();
    let show = |value: Option<f64>, unit: &str, precision: usize| {
        value.map_or("—".to_string(), |v| format!("{v:.precision$} {unit}"))
    };
    let mut text = String::new();
    text.push_str(&format!(
        "{:<16}{:>14}{:>14}{:>12}\n",
        "at rest", "before", "after", "target"
    ));
    text.push_str(&format!(
        "{:<16}{:>14}{:>14}{:>12}\n",
        "|a| error",
        show(Some(before.accel_error_mg), "mg", 2),
        show(after.map(|a| a.accel_error_mg), "mg", 3),
        "< 2 mg"
    ));
    text.push_str(&format!(
        "{:<16}{:>14}{:>14}{:>12}\n",
        "|m| error",
        show(Some(before.mag_error_pct), "%", 2),
        show(after.map(|a| a.mag_error_pct), "%", 3),
        "< 0.5 %"
    ));
    text.push_str(&format!(
        "{:<16}{:>14}{:>14}{:>12}\n",
        "gyro rate",
        show(Some(before.gyro_rate_dps), "°/s", 3),
        show(after.map(|a| a.gyro_rate_dps), "°/s", 4),
        ""
    ));
    text
}

/// `--analyze`: the residual analysis of the poses, and the extended set written and checked at
/// rest when it adds anything. Returns the at-rest errors with the extended set, if written.
fn close_the_loop(
    client: &mut DeviceClient,
    options: &SessionOptions,
    outcome: &SessionOutcome,
    dir: &std::path::Path,
    json: bool,
) -> anyhow::Result<Option<RestErrors>> {
    let analysis = analyse_poses(&outcome.poses, options.gravity_mps2);
    std::fs::write(
        dir.join("analysis.json"),
        serde_json::to_string_pretty(&report::to_json(&analysis))?,
    )
    .with_context(|| format!("could not write {}", dir.join("analysis.json").display()))?;
    if !json {
        eprintln!(
            "\nResidual analysis of the {} poses:\n{}",
            outcome.poses.len(),
            report::to_text(&analysis)
        );
    }
    let extended = extend_set(&outcome.fit.set, &analysis);
    for effect in &extended.left_out {
        eprintln!("Note: {effect} was accepted but the firmware has no term for it; not written");
    }
    if !extended.extended() {
        eprintln!("The analysis accepted no effect the firmware applies; the base set stays.");
        return Ok(None);
    }
    eprintln!("Extended terms added: {}", extended.added.join(", "));
    let base_path = dir.join("params-base.json");
    std::fs::write(&base_path, ParamsFile::from(&outcome.fit.set).to_json())
        .with_context(|| format!("could not write {}", base_path.display()))?;
    let params_path = dir.join("params.json");
    std::fs::write(&params_path, ParamsFile::from(&extended.set).to_json())
        .with_context(|| format!("could not write {}", params_path.display()))?;
    if !outcome.written {
        eprintln!(
            "The base set was not written, so neither is the extended one; `imucal flash {}` \
             writes it",
            params_path.display()
        );
        return Ok(None);
    }
    let status = client.write_params_verified(&extended.set)?;
    eprintln!(
        "Extended set written, committed, read back and compared: CRC {:#010x} (store \
         sequence {})",
        status.active_crc, status.active_seq
    );
    let samples = stream_for(
        client,
        StreamKind::Calibrated,
        options.rest_measure_s,
        options.read_timeout,
    )?;
    let errors = rest_errors(&samples, outcome.fit.gravity_mps2, outcome.fit.field_ut)
        .context("no calibrated samples arrived for the check at rest")?;
    Ok(Some(errors))
}

fn unix_now() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

/// The die temperature profile of `--sim-temperature`.
#[cfg(feature = "sim")]
fn temperature_profile(
    text: &str,
) -> anyhow::Result<Option<imucal_hil_sim::world::TemperatureProfile>> {
    use imucal_hil_sim::world::TemperatureProfile;
    if text == "constant" {
        return Ok(None);
    }
    let values: Option<Vec<f64>> = match text.strip_prefix("sweep") {
        Some("") => Some(vec![10.0, 40.0, 90.0]),
        Some(rest) => rest
            .strip_prefix(':')
            .and_then(|r| r.split(':').map(|n| n.parse().ok()).collect()),
        None => None,
    };
    match values.as_deref() {
        Some(&[low_c, high_c, period_s])
            if [low_c, high_c, period_s].iter().all(|v| v.is_finite())
                && low_c < high_c
                && period_s > 0.0 =>
        {
            Ok(Some(TemperatureProfile::Sweep {
                low_c,
                high_c,
                period_s,
            }))
        }
        _ => anyhow::bail!(
            "--sim-temperature {text} is not understood; give `constant`, `sweep`, or \
             `sweep:LOW:HIGH:PERIOD` with LOW < HIGH in °C and PERIOD > 0 in s, e.g. sweep:10:40:90"
        ),
    }
}

/// The simulated board of `--sim`.
#[cfg(feature = "sim")]
struct Simulated {
    handle: imucal_hil_sim::serve::SimHandle,
}

#[cfg(feature = "sim")]
impl Simulated {
    fn start(args: &CalibrateArgs) -> anyhow::Result<Self> {
        use imucal_hil_sim::serve::{SimOptions, SimServer};
        let mut options = SimOptions::new(args.sim_seed);
        options.speed = args.speed;
        options.board.sensor = args.sim_chip;
        options.board.temperature = temperature_profile(&args.sim_temperature)?;
        if args.rounds > 1 {
            options.schedule = imucal_hil_sim::board::PersonSchedule::Rounds(args.rounds);
        }
        options.effects = args
            .sim_effects
            .iter()
            .map(|text| text.parse())
            .collect::<Result<_, _>>()
            .context("a --sim-effect is not understood")?;
        let handle = SimServer::start(options).context("the simulated board could not start")?;
        Ok(Self { handle })
    }

    fn port(&self) -> String {
        self.handle.port_path().to_string()
    }

    /// The simulated site's field, µT: it stands for a value looked up for the location.
    fn field_ut(&self) -> f64 {
        let field = self.handle.truth().world.field_world_ut;
        field.iter().map(|v| v * v).sum::<f64>().sqrt()
    }

    fn save_truth(&self, path: &std::path::Path) -> anyhow::Result<()> {
        imucal_hil_sim::recording::write_truth_file(&self.handle.truth(), path)
            .context("the simulator's truth could not be saved")
    }
}

/// Without the simulator there is no simulated board (`start` explains).
#[cfg(not(feature = "sim"))]
enum Simulated {}

#[cfg(not(feature = "sim"))]
impl Simulated {
    fn start(_args: &CalibrateArgs) -> anyhow::Result<Self> {
        anyhow::bail!(
            "this imucal was built without the simulator; rebuild with the default features \
             (cargo build -p imucal) to use --sim, or give --port"
        )
    }

    fn port(&self) -> String {
        match *self {}
    }

    fn field_ut(&self) -> f64 {
        match *self {}
    }

    fn save_truth(&self, _path: &std::path::Path) -> anyhow::Result<()> {
        match *self {}
    }
}

/// Run `imucal calibrate`.
pub fn run(args: &CalibrateArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.gravity.is_finite() && args.gravity > 0.0,
        "--gravity is {}, but it must be a positive number of m/s²",
        args.gravity
    );
    if let Some(field) = args.field_ut {
        anyhow::ensure!(
            field.is_finite() && field > 0.0,
            "--field-ut is {field}, but it must be a positive number of µT"
        );
    }
    let simulated = if args.sim {
        Some(Simulated::start(args)?)
    } else {
        None
    };
    let port = match (&simulated, &args.port) {
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

    let options = SessionOptions {
        gravity_mps2: args.gravity,
        field_ut,
        hold: duration_arg("--hold", args.hold)?,
        pose_timeout: duration_arg("--pose-timeout", args.pose_timeout)?,
        mag_timeout: duration_arg("--mag-timeout", args.mag_timeout)?,
        rest_timeout: duration_arg("--rest-timeout", args.rest_timeout)?,
        rounds: usize::from(args.rounds),
        ..SessionOptions::default()
    };
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

#[cfg(all(test, feature = "sim"))]
mod tests {
    use super::temperature_profile;
    use imucal_hil_sim::world::TemperatureProfile;

    #[test]
    fn sweep_profiles_are_read_with_defaults_or_given_numbers() {
        let sweep = |low_c, high_c, period_s| {
            Some(TemperatureProfile::Sweep {
                low_c,
                high_c,
                period_s,
            })
        };
        assert_eq!(temperature_profile("constant").ok(), Some(None));
        assert_eq!(
            temperature_profile("sweep").ok(),
            Some(sweep(10.0, 40.0, 90.0))
        );
        assert_eq!(
            temperature_profile("sweep:-5:55.5:120").ok(),
            Some(sweep(-5.0, 55.5, 120.0))
        );
    }

    #[test]
    fn malformed_or_inverted_sweeps_are_refused_with_an_example() {
        for bad in [
            "sweepx:1:2:3",
            "sweep:40:10:90",
            "sweep:10:40:0",
            "sweep:10:40",
            "sweep:10:NaN:90",
            "hot",
        ] {
            let error = temperature_profile(bad).expect_err(bad).to_string();
            assert!(error.contains("sweep:10:40:90"), "{bad}: {error}");
        }
    }
}
