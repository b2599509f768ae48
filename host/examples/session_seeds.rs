//! The guided session on the simulated board over several seeds: per seed the simulated session
//! time, the errors at rest after calibration (`|a|` in mg, `|m|` in %), and the gyroscope's
//! scale and misalignment against the board's truth, with the fit's own 1σ, and how far a 360°
//! turn about each axis integrates off before and after calibration.
//!
//! The gyroscope's written `A` maps raw rates into the accelerometer's output frame, which the
//! norm fit leaves as `Qᵀ·body` with `A_acc = Q·R` (upper-triangular gauge), so the truth it is
//! compared with is `Qᵀ·A_true`; `E = A_fit·(Qᵀ·A_true)⁻¹ − I` holds the scale errors on its
//! diagonal and the misalignment angles (radians) off it. The table also gives the
//! misalignment against the frame the calibrated accelerometer actually reads in,
//! `M = A_acc,fit·A_acc,true⁻¹` (`Qᵀ` up to the accelerometer fit's own errors): what a fusion
//! of the two sensors sees. A 360° turn is about one axis, so its error is that axis's scale
//! error (×360°) plus the bias error over the turn; misalignment tilts the turn's axis only.
//!
//! Run: `cargo run --release -p imucal --example session_seeds -- [SEEDS] [FIRST_SEED] [-v]`
//! (default 10 seeds from 1).

use imucal::device::DeviceClient;
use imucal::fit::linalg::orthogonal_factor;
use imucal::fit::{Calibration, Mat3, Vec3};
use imucal::session::gyro_fit::full_turn_error_deg;
use imucal::session::sim_screen::shown_on;
use imucal::session::{run_session, SessionEvent, SessionObserver, SessionOptions, Tapped};
use imucal_hil_sim::serve::{SimOptions, SimServer};

/// Simulated seconds per wall second. The simulated board runs on while the host computes, so
/// the host's fitting time counts ×SPEED in the simulated session time; the table also gives the
/// session time with the fit counted at real time (`session_seconds − (SPEED − 1)·fit time`), what
/// a person with a real board waits. 5 lets the host keep up with the full-rate stream on a
/// loaded machine.
const SPEED: f64 = 5.0;

/// Prints the events that matter for timing when `-v` is given.
struct Log {
    verbose: bool,
    start: std::time::Instant,
}

impl SessionObserver for Log {
    fn event(&mut self, event: &SessionEvent<'_>) {
        if !self.verbose {
            return;
        }
        // Approximate simulated time from the wall clock.
        eprint!("{:6.1} s", self.start.elapsed().as_secs_f64() * SPEED);
        match event {
            SessionEvent::Captured {
                target, samples, ..
            } => eprintln!("  captured {} ({samples} samples)", target.name),
            SessionEvent::CaptureFailed { target, reason } => {
                eprintln!("  failed {}: {reason}", target.name)
            }
            SessionEvent::Note(text) => eprintln!("  note: {text}"),
            SessionEvent::MagPrompt => eprintln!("  magnetometer phase"),
            SessionEvent::RestPrompt => eprintln!("  rest"),
            SessionEvent::MagCoverage { covered, .. } => eprintln!("  mag covered {covered}"),
            SessionEvent::Prompt { target, .. } => eprintln!("  prompt {}", target.name),
            _ => eprint!("\r"),
        }
    }
}

fn matrix(rows: &[[f64; 3]; 3]) -> Mat3 {
    Mat3::from_fn(|r, c| rows[r][c])
}

/// Largest off-diagonal entry of `error`, degrees (a misalignment angle).
fn largest_off_diagonal_deg(error: &Mat3) -> f64 {
    let mut largest: f64 = 0.0;
    for r in 0..3 {
        for c in (0..3).filter(|&c| c != r) {
            largest = largest.max(error[(r, c)].abs().to_degrees());
        }
    }
    largest
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let verbose = args.iter().any(|a| a == "-v");
    let numbers: Vec<u64> = args.iter().filter_map(|a| a.parse().ok()).collect();
    let seeds = numbers.first().copied().unwrap_or(10);
    let first = numbers.get(1).copied().unwrap_or(1);
    println!(
        "seed | session s | session s, fit at 1× | |a| mg | |m| % | gyro scale err % (1σ) | \
         misalign err ° (1σ) | misalign err in accel frame ° | worst err/σ | moves | \
         360° before ° | 360° after °"
    );
    for seed in first..first + seeds {
        let mut sim_options = SimOptions::new(seed);
        sim_options.speed = SPEED;
        let sim = match SimServer::start(sim_options) {
            Ok(sim) => sim,
            Err(e) => {
                println!("{seed} | simulator failed: {e}");
                continue;
            }
        };
        let truth = sim.truth();
        let mut client = match DeviceClient::open(sim.port_path()) {
            Ok(client) => client,
            Err(e) => {
                println!("{seed} | connect failed: {e}");
                continue;
            }
        };
        let options = SessionOptions {
            gravity_mps2: truth.world.gravity_mps2,
            field_ut: Some(Vec3::from(truth.world.field_world_ut).norm()),
            ..SessionOptions::default()
        };
        let mut log = Log {
            verbose,
            start: std::time::Instant::now(),
        };
        // The simulated person reads the prompts off the screen, as with `imucal calibrate --sim`.
        let mut shown = Tapped {
            observer: &mut log,
            tap: shown_on(&sim),
        };
        let outcome = match run_session(&mut client, &options, &mut shown) {
            Ok(outcome) => outcome,
            Err(e) => {
                println!("{seed} | session failed: {e}");
                continue;
            }
        };
        let accel_true = matrix(&truth.imu.accel.a_true);
        let q = orthogonal_factor(&accel_true);
        let gyro_true = matrix(&truth.imu.gyro.a_true);
        let expected = q.transpose() * gyro_true;
        let error = outcome.fit.gyro.cal.a * expected.try_inverse().unwrap_or(Mat3::identity())
            - Mat3::identity();
        let scale_err = (0..3).map(|i| error[(i, i)].abs()).fold(0.0, f64::max) * 100.0;
        let misalign_err = largest_off_diagonal_deg(&error);
        // The frame the calibrated accelerometer actually reads in, `M = A_acc,fit·A_acc,true⁻¹`
        // (≈ Qᵀ, with the accelerometer fit's own errors), its unit taken out.
        let frame = outcome.fit.accel.cal.a * accel_true.try_inverse().unwrap_or(Mat3::identity());
        let frame = frame / frame.determinant().cbrt();
        let in_accel_frame = outcome.fit.gyro.cal.a
            * (frame * gyro_true)
                .try_inverse()
                .unwrap_or(Mat3::identity())
            - Mat3::identity();
        let misalign_accel_frame = largest_off_diagonal_deg(&in_accel_frame);
        // Worst error of an entry in units of its own σ (E's entry ij is A's over expected jj).
        let worst_z = outcome.fit.gyro.std.map_or(f64::NAN, |std| {
            (0..9)
                .map(|k| (k / 3, k % 3))
                .map(|(r, c)| error[(r, c)].abs() * expected[(c, c)].abs() / std.a[(r, c)])
                .fold(0.0, f64::max)
        });
        let b_true = Vec3::from(truth.imu.gyro.b_true);
        let gyro_inverse = gyro_true.try_inverse().unwrap_or(Mat3::identity());
        let raw = |w: &Vec3| gyro_inverse * w + b_true;
        let turn = |cal: &Calibration| {
            (0..3)
                .map(|axis| full_turn_error_deg(cal, raw, axis, 4.0, 119.0))
                .fold(0.0, f64::max)
        };
        let before = turn(&Calibration::identity());
        let after = turn(&outcome.fit.gyro.cal);
        let (scale_sigma, misalign_sigma, moves) =
            outcome
                .gyro_scale
                .as_ref()
                .map_or((f64::NAN, f64::NAN, String::from("-")), |g| {
                    (
                        g.scale_sigma_pct.iter().copied().fold(0.0, f64::max),
                        g.misalignment_sigma_deg,
                        format!("{}/{}", g.moves_used, g.moves_recorded),
                    )
                });
        let at_rest = outcome.after;
        if verbose {
            let bias_error = (outcome.fit.gyro.cal.b - b_true).norm().to_degrees();
            let rms = outcome.gyro_scale.as_ref().map_or(f64::NAN, |g| g.rms_deg);
            eprintln!("  gyro bias error {bias_error:.4} °/s, move residual RMS {rms:.4}°");
            if let Some(g) = &outcome.gyro_scale {
                let [x, y, z] = g.tilt_deg;
                eprintln!("  tilting rotation about X, Y, Z: {x:.0}°, {y:.0}°, {z:.0}°");
                match &g.gravity_only_reason {
                    None => eprintln!(
                        "  reference: gravity and field, {} moves ({:.1} s) with the field, \
                         χ²/ν {:.2}",
                        g.field_moves,
                        g.field_seconds,
                        g.reduced_chi_square.unwrap_or(f64::NAN)
                    ),
                    Some(reason) => eprintln!("  reference: gravity only ({reason})"),
                }
            }
            let std = outcome.fit.gyro.std.map_or(Mat3::zeros(), |s| s.a);
            for r in 0..3 {
                let row: Vec<String> = (0..3)
                    .map(|c| {
                        let (err, sigma) = (error[(r, c)], std[(r, c)] / expected[(c, c)].abs());
                        if r == c {
                            format!("{:+.3} % ({:.3})", err * 100.0, sigma * 100.0)
                        } else {
                            let (e, s) = (err.to_degrees(), sigma.to_degrees());
                            format!("{e:+.3}° ({s:.3})")
                        }
                    })
                    .collect();
                eprintln!("  E row {}: {}", r + 1, row.join("  "));
            }
        }
        println!(
            "{seed} | {:.1} | {:.1} | {:.3} | {:.3} | {scale_err:.3} ({scale_sigma:.3}) | \
             {misalign_err:.3} ({misalign_sigma:.3}) | {misalign_accel_frame:.3} | {worst_z:.1} | {moves} | {before:.2} | {after:.3}",
            outcome.session_seconds,
            outcome.session_seconds - (SPEED - 1.0) * outcome.fit_wall_seconds,
            at_rest.map_or(f64::NAN, |a| a.accel_error_mg),
            at_rest.map_or(f64::NAN, |a| a.mag_error_pct),
        );
    }
}
