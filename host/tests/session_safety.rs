//! Nothing a session measured is lost: a guided session on the simulated board that stops early
//! (the board vanishes after the commit, the read-back is corrupted, the user interrupts) saves
//! what it measured, says what the board holds, and can be resumed without asking again for the
//! positions already captured.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use imucal::device::DeviceClient;
use imucal::fit::Vec3;
use imucal::session::{
    load_mag_samples, load_moves, load_poses, load_progress, run_session_with, save_session,
    SessionControl, SessionError, SessionEvent, SessionObserver, SessionOptions, MOVES_FILE,
    PROGRESS_FILE,
};
use imucal_hil_sim::board::PersonSchedule;
use imucal_hil_sim::link_faults::ParamTamper;
use imucal_hil_sim::serve::{SimHandle, SimOptions, SimServer};

/// Simulated seconds per wall second, as in `calibrate_sim.rs`: the serving loop keeps up with
/// the full-rate stream on a loaded machine.
const SPEED: f64 = 5.0;

/// What the test does to the board or the session, and when.
enum Sabotage {
    /// Close the board's port once the set is verified (during the "after" measurement).
    VanishAfterCommit,
    /// None by the observer (the board's link corrupts every parameter read-back: the commit
    /// succeeds, the verification after it fails).
    Nothing,
    /// Raise the interrupt flag once this many positions are captured (in the round).
    InterruptAfter(usize),
    /// Raise the interrupt flag at this many captures in all (every round counted).
    InterruptAtCapture(usize),
    /// Raise the interrupt flag when the set is fitted (no samples are read until the write).
    InterruptWhenFitted,
    /// Raise the interrupt flag when the written set is verified (before the check at rest).
    InterruptWhenVerified,
}

struct Saboteur<'a> {
    sim: &'a SimHandle,
    sabotage: Sabotage,
    interrupt: Arc<AtomicBool>,
    prompted: Vec<String>,
    captures: usize,
}

impl SessionObserver for Saboteur<'_> {
    fn event(&mut self, event: &SessionEvent<'_>) {
        if let SessionEvent::Captured { .. } = event {
            self.captures += 1;
        }
        match (event, &self.sabotage) {
            (SessionEvent::Prompt { target, .. }, _) => self.prompted.push(target.name.clone()),
            (SessionEvent::Captured { .. }, Sabotage::InterruptAtCapture(n))
                if self.captures >= *n =>
            {
                self.interrupt.store(true, Ordering::SeqCst);
            }
            (SessionEvent::Verified(_), Sabotage::VanishAfterCommit) => self.sim.vanish(),
            (SessionEvent::Captured { captured, .. }, Sabotage::InterruptAfter(n))
                if captured >= n =>
            {
                self.interrupt.store(true, Ordering::SeqCst);
            }
            (SessionEvent::Fitted(_), Sabotage::InterruptWhenFitted)
            | (SessionEvent::Verified(_), Sabotage::InterruptWhenVerified) => {
                self.interrupt.store(true, Ordering::SeqCst);
            }
            _ => {}
        }
    }
}

fn board(seed: u64) -> SimHandle {
    board_with_tamper(seed, None)
}

/// A board whose link can tamper with parameter sets (the tamper is set at start: a link
/// started without faults is a plain pipe).
fn board_with_tamper(seed: u64, tamper: Option<ParamTamper>) -> SimHandle {
    let mut options = SimOptions::new(seed);
    options.speed = SPEED;
    options.faults.param_tamper = tamper;
    SimServer::start(options).expect("the simulator starts")
}

fn options_for(sim: &SimHandle) -> SessionOptions {
    let truth = sim.truth();
    SessionOptions {
        gravity_mps2: truth.world.gravity_mps2,
        field_ut: Some(Vec3::from(truth.world.field_world_ut).norm()),
        ..SessionOptions::default()
    }
}

fn session_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("imucal-safety-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// Run a session on `sim` under `sabotage`, saving into `dir`.
fn sabotaged_session(
    sim: &SimHandle,
    sabotage: Sabotage,
    dir: &Path,
) -> (
    Result<imucal::session::SessionOutcome, SessionError>,
    Vec<String>,
) {
    sabotaged_session_with(sim, &options_for(sim), sabotage, dir)
}

/// A session on `sim` with `options` that resumes what `dir` saved (`poses`, `mag`, `moves`),
/// run to its end; with the names of the positions it prompted for.
fn resumed_session(
    sim: &SimHandle,
    options: &SessionOptions,
    dir: &Path,
    poses: Vec<imucal::session::CapturedPose>,
    mag: Vec<imucal::session::MagSample>,
    moves: Vec<Vec<imucal::device::UnitSample>>,
) -> (imucal::session::SessionOutcome, Vec<String>) {
    let mut observer = Saboteur {
        sim,
        sabotage: Sabotage::InterruptAfter(usize::MAX),
        interrupt: Arc::new(AtomicBool::new(false)),
        prompted: Vec::new(),
        captures: 0,
    };
    let control = SessionControl {
        save_dir: Some(dir.to_path_buf()),
        resume: poses,
        resume_mag: mag,
        resume_moves: moves,
        interrupt: None,
    };
    let mut client = DeviceClient::open(sim.port_path()).expect("connect to the simulator");
    let outcome = run_session_with(&mut client, options, &mut observer, &control)
        .expect("the resumed session completes");
    (outcome, observer.prompted)
}

/// [`sabotaged_session`] with the session's `options`.
fn sabotaged_session_with(
    sim: &SimHandle,
    options: &SessionOptions,
    sabotage: Sabotage,
    dir: &Path,
) -> (
    Result<imucal::session::SessionOutcome, SessionError>,
    Vec<String>,
) {
    let interrupt = Arc::new(AtomicBool::new(false));
    let mut observer = Saboteur {
        sim,
        sabotage,
        interrupt: Arc::clone(&interrupt),
        prompted: Vec::new(),
        captures: 0,
    };
    let control = SessionControl {
        save_dir: Some(dir.to_path_buf()),
        interrupt: Some(interrupt),
        ..SessionControl::default()
    };
    let mut client = DeviceClient::open(sim.port_path()).expect("connect to the simulator");
    let result = run_session_with(&mut client, options, &mut observer, &control);
    (result, observer.prompted)
}

#[test]
fn a_board_lost_after_the_commit_leaves_the_session_saved_and_says_its_set_cannot_be_read() {
    let sim = board(31);
    let dir = session_dir("vanish");
    let (result, _) = sabotaged_session(&sim, Sabotage::VanishAfterCommit, &dir);
    let error = result.expect_err("the after measurement cannot finish without the board");
    let message = error.to_string();
    assert!(
        matches!(&error, SessionError::Stopped { board_holds, .. }
            if board_holds.contains("could not be read back")),
        "{message}"
    );
    assert!(message.contains(&dir.display().to_string()), "{message}");
    // Everything measured before the loss is on disk: twelve positions, the fitted set, and
    // the progress file naming the stage and the board's state.
    let poses = load_poses(&dir.join("poses.json")).expect("the poses are saved");
    assert!(poses.len() >= 12, "{} poses saved", poses.len());
    assert!(dir.join("params.json").is_file());
    let progress = load_progress(&dir).expect("the progress is saved");
    assert_eq!(progress.stage, "stopped");
    assert!(
        progress.stopped_because.contains("stage `after`"),
        "{}",
        progress.stopped_because
    );
    assert!(progress.params_crc.is_some());
    assert!(progress.mag_samples > 0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_corrupted_read_back_after_the_commit_says_the_board_holds_the_new_set() {
    let sim = board_with_tamper(32, Some(ParamTamper::FlipReadBack { bit: 20 }));
    let dir = session_dir("readback");
    let (result, _) = sabotaged_session(&sim, Sabotage::Nothing, &dir);
    let error = result.expect_err("the verification sees the corrupted read-back");
    let message = error.to_string();
    let progress = load_progress(&dir).expect("the progress is saved");
    let crc = progress
        .params_crc
        .clone()
        .expect("the fitted set is saved");
    // The board committed the set: its status (not the tampered read-back) shows the new CRC.
    assert!(
        matches!(&error, SessionError::Stopped { board_holds, .. }
            if board_holds.starts_with("the new set") && board_holds.contains(&crc)),
        "{message}"
    );
    assert!(progress.board_holds.starts_with("the new set"));
    assert!(
        progress.stopped_because.contains("stage `writing`"),
        "{}",
        progress.stopped_because
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_interrupt_between_reads_stops_at_the_next_stage_and_saves() {
    // Interrupted while fitting: nothing is written, and the session stops as usual.
    let sim = board(34);
    let dir = session_dir("fitted");
    let (result, _) = sabotaged_session(&sim, Sabotage::InterruptWhenFitted, &dir);
    let error = result.expect_err("the interrupt stops the session before the write");
    assert!(
        matches!(&error, SessionError::Stopped { cause, board_holds, .. }
            if matches!(**cause, SessionError::Interrupted)
                && board_holds.contains("nothing was written")),
        "{error}"
    );
    let progress = load_progress(&dir).expect("the progress is saved");
    assert_eq!(progress.stage, "stopped");
    assert!(
        progress.stopped_because.contains("stage `fitted`"),
        "{}",
        progress.stopped_because
    );
    assert!(progress.params_crc.is_some() && progress.mag_samples > 0);
    let _ = std::fs::remove_dir_all(&dir);

    // Interrupted once the set is verified: the check at rest is not run, and the board is
    // said to hold the new set.
    let sim = board(35);
    let dir = session_dir("verified");
    let (result, _) = sabotaged_session(&sim, Sabotage::InterruptWhenVerified, &dir);
    let error = result.expect_err("the interrupt stops the check at rest");
    assert!(
        matches!(&error, SessionError::Stopped { cause, board_holds, .. }
            if matches!(**cause, SessionError::Interrupted)
                && board_holds.starts_with("the new set")),
        "{error}"
    );
    let progress = load_progress(&dir).expect("the progress is saved");
    assert!(
        progress.stopped_because.contains("stage `after`"),
        "{}",
        progress.stopped_because
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_interrupted_session_keeps_its_poses_and_samples_and_resumes_without_asking_for_them_again() {
    let sim = board(33);
    let dir = session_dir("resume");
    let (result, _) = sabotaged_session(&sim, Sabotage::InterruptAfter(5), &dir);
    let error = result.expect_err("the interrupt stops the session");
    assert!(
        matches!(&error, SessionError::Stopped { cause, board_holds, .. }
            if matches!(**cause, SessionError::Interrupted)
                && board_holds.contains("nothing was written")),
        "{error}"
    );
    let first = load_poses(&dir.join("poses.json")).expect("the poses are saved");
    assert_eq!(first.len(), 5, "the poses captured before the interrupt");
    assert!(load_progress(&dir).is_ok());
    let first_mag = load_mag_samples(&dir.join("mag_samples.csv")).expect("the samples are saved");
    assert!(!first_mag.is_empty());
    // The moves between the five holds: the gyroscope's scale is fitted from them.
    let first_moves = load_moves(&dir.join(MOVES_FILE)).expect("the moves are saved");
    assert!(first_moves.len() >= 3, "{} moves", first_moves.len());

    // Resume on the same board: the five positions are neither prompted for nor captured again.
    let (outcome, prompted) = resumed_session(
        &sim,
        &options_for(&sim),
        &dir,
        first.clone(),
        first_mag.clone(),
        first_moves.clone(),
    );
    for pose in &first {
        assert!(
            !prompted.contains(&pose.target.name),
            "{} was asked for again",
            pose.target.name
        );
        let again = outcome
            .poses
            .iter()
            .filter(|p| p.target.index == pose.target.index)
            .count();
        assert_eq!(again, 1, "{} captured once", pose.target.name);
    }
    assert!(outcome.poses.len() >= 12 && outcome.verified);
    // The samples of the first run are kept ahead of the new ones, on disk too.
    assert!(outcome.mag_samples.len() > first_mag.len());
    assert_eq!(outcome.mag_samples[..first_mag.len()], first_mag[..]);
    // The first run's moves are fitted with the new ones, read back bit for bit.
    assert!(outcome.moves.len() > first_moves.len());
    assert_eq!(outcome.moves[..first_moves.len()], first_moves[..]);
    let gyro = outcome
        .gyro_scale
        .as_ref()
        .expect("the gyroscope's scale is fitted");
    assert_eq!(gyro.moves_recorded, outcome.moves.len());
    save_session(&outcome, &dir).expect("the finished session is saved");
    let saved = load_mag_samples(&dir.join("mag_samples.csv")).expect("the samples are saved");
    assert_eq!(saved.len(), outcome.mag_samples.len());
    let saved_moves = load_moves(&dir.join(MOVES_FILE)).expect("the moves are saved");
    assert_eq!(saved_moves, outcome.moves);
    assert!(
        !dir.join(PROGRESS_FILE).exists(),
        "a finished session has no progress file"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `imucal calibrate --sim` in `dir` with the history in a temporary database.
fn calibrate_command(dir: &Path) -> std::process::Command {
    let mut command = std::process::Command::new(env!("CARGO_BIN_EXE_imucal"));
    command
        .args([
            "calibrate",
            "--sim",
            "--sim-seed",
            "5",
            "--yes",
            "--speed",
            "10",
        ])
        .arg("-o")
        .arg(dir)
        .env("IMUCAL_DB", dir.with_extension("db"));
    command
}

/// The command `imucal` says continues the session, from its error output, as a user would
/// paste it (the session directory in the tests needs no quoting).
fn printed_resume_command(stderr: &str) -> std::process::Command {
    let line = stderr
        .split("Continue with `")
        .nth(1)
        .and_then(|rest| rest.split('`').next())
        .unwrap_or_else(|| panic!("no command to continue with: {stderr}"));
    let mut words = line.split_whitespace();
    assert_eq!(words.next(), Some("imucal"), "{line}");
    let mut command = std::process::Command::new(env!("CARGO_BIN_EXE_imucal"));
    command.args(words);
    command
}

#[test]
fn ctrl_c_stops_the_binary_saves_the_poses_and_says_the_board_keeps_its_set() {
    let dir = session_dir("sigint");
    let child = calibrate_command(&dir)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("run imucal");
    // Interrupt once the first positions are on disk (the session saves after every pose).
    let started = std::time::Instant::now();
    while load_poses(&dir.join("poses.json")).map_or(0, |p| p.len()) < 2 {
        assert!(
            started.elapsed().as_secs() < 300,
            "no pose was saved within 300 s"
        );
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let interrupt = || {
        std::process::Command::new("kill")
            .args(["-INT", &child.id().to_string()])
            .status()
            .expect("send SIGINT")
    };
    assert!(interrupt().success());
    // `timeout` and a kill of the process group deliver one Ctrl-C twice: it stops the session
    // once, as one Ctrl-C, and does not quit without saving.
    std::thread::sleep(std::time::Duration::from_millis(50));
    let _ = interrupt();
    let out = child.wait_with_output().expect("imucal ends");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(
        out.status.code(),
        Some(1),
        "an interrupted session fails: {stderr}"
    );
    assert!(stderr.contains("stopped by the user"), "{stderr}");
    assert!(stderr.contains("nothing was written"), "{stderr}");
    assert!(stderr.contains("--resume"), "{stderr}");
    let progress = load_progress(&dir).expect("the progress is saved");
    assert!(progress.poses >= 2, "{progress:?}");
    let saved = load_poses(&dir.join("poses.json")).expect("the poses are saved");
    assert_eq!(saved.len(), progress.poses);
    let saved_mag = load_mag_samples(&dir.join("mag_samples.csv")).expect("the samples are saved");
    assert_eq!(saved_mag.len(), progress.mag_samples);

    // The command printed continues the session as pasted (the same simulated board, by its
    // seed), does not ask for the saved positions again, and keeps the saved samples: the
    // simulated person, like a user reading the list of positions already captured, skips them.
    let out = printed_resume_command(&stderr)
        .env("IMUCAL_DB", dir.with_extension("db"))
        .output()
        .expect("run imucal");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("already captured"), "{stderr}");
    for pose in &saved {
        assert!(
            !stderr.contains(&format!("hold the board {} ", pose.target.name)),
            "{} is asked for again: {stderr}",
            pose.target.name
        );
    }
    let kept = load_poses(&dir.join("poses.json")).expect("the poses are saved");
    assert_eq!(kept[..saved.len()], saved[..]);
    assert!(kept.len() >= 12, "{} poses", kept.len());
    let mag = load_mag_samples(&dir.join("mag_samples.csv")).expect("the samples are saved");
    assert!(mag.len() > saved_mag.len());
    assert_eq!(mag[..saved_mag.len()], saved_mag[..]);
    // The fresh simulated board's clock restarted at 0: the session's times still increase
    // across the two runs, so drift and temperature are analysed in the order measured.
    assert!(
        stderr.contains("it restarted, so this run's times continue"),
        "{stderr}"
    );
    let increasing = |times: &[f64]| times.windows(2).all(|w| w[1] >= w[0]);
    let pose_times: Vec<f64> = kept.iter().map(|p| p.t_s).collect();
    assert!(increasing(&pose_times), "{pose_times:?}");
    let mag_times: Vec<f64> = mag.iter().map(|m| m.t_s).collect();
    assert!(increasing(&mag_times));
    let moves = load_moves(&dir.join(MOVES_FILE)).expect("the moves are saved");
    let move_starts: Vec<f64> = moves
        .iter()
        .filter_map(|m| m.first())
        .map(|s| s.t_s)
        .collect();
    assert!(increasing(&move_starts), "{move_starts:?}");
    assert!(!dir.join(PROGRESS_FILE).exists(), "the session is finished");
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_file(dir.with_extension("db"));
}

#[test]
fn without_yes_and_without_a_terminal_to_ask_nothing_is_written_to_the_board() {
    let dir = session_dir("no-one-to-ask");
    // Input from nowhere: nobody can answer "write these parameters?".
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(["calibrate", "--sim", "--sim-seed", "7", "--speed", "30"])
        .args(["--no-history", "-o"])
        .arg(&dir)
        .stdin(std::process::Stdio::null())
        .output()
        .expect("imucal runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("nobody to ask") && stderr.contains("--yes"),
        "{stderr}"
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).expect("saved"))
            .expect("JSON");
    assert_eq!(summary["written"], false, "{summary}");
    assert_eq!(
        summary["not_written_because"], "no --yes, and no terminal to ask",
        "{summary}"
    );
    // No calibrated stream was measured: no rate, rather than 0 Hz.
    assert!(summary["stream_rate_hz"].is_null(), "{summary}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_session_resumed_in_its_second_round_asks_only_for_that_rounds_missing_positions() {
    let mut sim_options = SimOptions::new(36);
    sim_options.speed = SPEED;
    sim_options.schedule = PersonSchedule::Rounds(2);
    let sim = SimServer::start(sim_options).expect("the simulator starts");
    let options = SessionOptions {
        rounds: 2,
        ..options_for(&sim)
    };
    let dir = session_dir("rounds");
    // Stopped three positions into the second round.
    let (stopped, _) =
        sabotaged_session_with(&sim, &options, Sabotage::InterruptAtCapture(15), &dir);
    assert!(stopped.is_err(), "the interrupt stops the session");
    let first = load_poses(&dir.join("poses.json")).expect("the poses are saved");
    assert_eq!(first.len(), 15, "twelve, then three of the second round");
    let second_round: Vec<String> = first[12..].iter().map(|p| p.target.name.clone()).collect();

    let (outcome, prompted) = resumed_session(
        &sim,
        &options,
        &dir,
        first,
        load_mag_samples(&dir.join("mag_samples.csv")).expect("samples saved"),
        load_moves(&dir.join(MOVES_FILE)).expect("moves saved"),
    );
    // Captured twice already: neither prompted for nor captured a third time.
    for name in &second_round {
        assert!(
            !prompted.contains(name),
            "{name} was asked for a third time"
        );
    }
    let twelve_captures = outcome.poses.iter().filter(|p| p.target.index < 12).count();
    assert_eq!(twelve_captures, 24, "two rounds of the twelve positions");
    let _ = std::fs::remove_dir_all(&dir);
}
