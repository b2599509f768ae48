//! The end-to-end part of `qemu-test`: `imucal calibrate` run unattended against the firmware in
//! QEMU while the simulator's world feeds UART1, and its result compared with the simulator's
//! truth.
//!
//! The host tool opens a second pseudo-terminal owned by this program; a relay thread copies
//! bytes between it and the board's UART0 pty. The relay only moves bytes: the simulated person
//! sees nothing of the session and follows timed holds (see `imucal_hil_sim::feed`); the one
//! thing taken from the link is the moment the host tool first sends, which stands for the user
//! starting the program and then picking up the board.
//!
//! Parameters are compared in quantities that do not depend on the fit's gauge: the offset `b`
//! directly, and `A` through `M = A_fit·A_true⁻¹`, which is a rotation when the fit is exact
//! (the accelerometer fit fixes `A` upper-triangular, the truth is a general matrix): its
//! singular values must be 1 (scale) and the magnetometer's rotation must equal the
//! accelerometer's (the host aligns the magnetometer to the accelerometer frame).

use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use imucal_hil_sim::feed::FeedControl;
use imucal_hil_sim::physics::SensorTruth;
use imucal_hil_sim::Truth;
use nalgebra::{Matrix3, Vector3};
use serde_json::Value;
use serialport::{SerialPort, TTYPort};

/// Gaussian errors exceed 5σ with probability 5.7·10⁻⁷: a tolerance of 5σ makes a false failure
/// negligible while a real error of a few σ of the noise floor still shows in the figures.
pub const SIGMAS: f64 = 5.0;
/// Accuracy targets at rest of the end-to-end calibration: |a| error in mg and |m| error in %.
pub const ACCEL_TARGET_MG: f64 = 2.0;
/// See [`ACCEL_TARGET_MG`].
pub const MAG_TARGET_PCT: f64 = 0.5;
/// Standard gravity, m/s² (the unit of mg).
const G: f64 = 9.806_65;

/// Builds the host tool in release mode and returns the path of its binary.
pub fn build_host_tool(repo: &Path) -> Result<PathBuf, String> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let output = Command::new(cargo)
        .current_dir(repo)
        .args([
            "build",
            "--release",
            "-p",
            "imucal",
            "--bin",
            "imucal",
            "--message-format=json-render-diagnostics",
        ])
        .stderr(Stdio::inherit())
        .output()
        .map_err(|e| format!("could not run cargo to build the host tool: {e}"))?;
    if !output.status.success() {
        return Err(format!(
            "building the host tool (cargo build --release -p imucal) failed with {}; see the \
             compiler messages above",
            output.status
        ));
    }
    String::from_utf8_lossy(&output.stdout)
        .lines()
        .filter_map(|line| serde_json::from_str::<Value>(line).ok())
        .filter(|m| m["reason"] == "compiler-artifact" && m["target"]["name"] == "imucal")
        .find_map(|m| m["executable"].as_str().map(PathBuf::from))
        .ok_or_else(|| "cargo built the host tool but reported no `imucal` executable".into())
}

/// Copies bytes between the board's UART0 pty and the host tool's pty until stopped.
pub struct Relay {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<Result<RelayCounts, String>>>,
    /// Path of the host tool's side.
    pub host_path: String,
    _host_slave: TTYPort,
}

/// Bytes moved by the relay.
#[derive(Debug, Clone, Copy, Default)]
pub struct RelayCounts {
    /// Board to host tool.
    pub to_host: u64,
    /// Host tool to board.
    pub to_board: u64,
}

impl Relay {
    /// Starts relaying `board` (a clone of the board's pty master); calls `control.start()` when
    /// the host tool first sends.
    pub fn start(board: TTYPort, control: Arc<FeedControl>) -> Result<Self, String> {
        // Our slave handle stays open so that the master never hangs up; it holds no lock
        // (unlike `set_exclusive`, which takes a shared one), so the tool's exclusive open works.
        let (host_master, host_slave) =
            TTYPort::pair().map_err(|e| format!("could not create a pseudo-terminal pair: {e}"))?;
        let host_path = host_slave
            .name()
            .ok_or("the host tool's pseudo-terminal has no path")?;
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let thread = std::thread::spawn(move || relay_loop(board, host_master, &control, &flag));
        Ok(Self {
            stop,
            thread: Some(thread),
            host_path,
            _host_slave: host_slave,
        })
    }

    /// Stops relaying and returns the counts.
    pub fn finish(mut self) -> Result<RelayCounts, String> {
        self.stop.store(true, Ordering::Relaxed);
        self.thread.take().map_or(Ok(RelayCounts::default()), |t| {
            t.join()
                .unwrap_or_else(|_| Err("the relay thread panicked".into()))
        })
    }
}

impl Drop for Relay {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

fn relay_loop(
    mut board: TTYPort,
    mut host: TTYPort,
    control: &FeedControl,
    stop: &AtomicBool,
) -> Result<RelayCounts, String> {
    let poll = Duration::from_millis(2);
    board
        .set_timeout(poll)
        .and_then(|()| host.set_timeout(poll))
        .map_err(|e| format!("setting the relay's pty timeouts failed: {e}"))?;
    let mut counts = RelayCounts::default();
    let mut bytes = [0u8; 4096];
    while !stop.load(Ordering::Relaxed) {
        let n = read_some(&mut board, &mut bytes)?;
        if n > 0 {
            // Bytes nobody reads are dropped after a while, as on a real serial line.
            if write_some(&mut host, &bytes[..n]) {
                counts.to_host += n as u64;
            }
        }
        let n = read_some(&mut host, &mut bytes)?;
        if n > 0 {
            control.start();
            if write_some(&mut board, &bytes[..n]) {
                counts.to_board += n as u64;
            }
        }
    }
    Ok(counts)
}

fn read_some(port: &mut TTYPort, bytes: &mut [u8]) -> Result<usize, String> {
    match port.read(bytes) {
        Ok(n) => Ok(n),
        Err(e)
            if matches!(
                e.kind(),
                std::io::ErrorKind::TimedOut
                    | std::io::ErrorKind::WouldBlock
                    | std::io::ErrorKind::Interrupted
            ) =>
        {
            Ok(0)
        }
        // EIO on a master whose slave is closed (the tool has not opened it yet or has exited).
        Err(e) if e.raw_os_error() == Some(5) => Ok(0),
        Err(e) => Err(format!("the relay could not read a pty: {e}")),
    }
}

fn write_some(port: &mut TTYPort, bytes: &[u8]) -> bool {
    let deadline = Instant::now() + Duration::from_millis(200);
    let mut rest = bytes;
    while !rest.is_empty() && Instant::now() < deadline {
        match port.write(rest) {
            Ok(n) => rest = rest.get(n..).unwrap_or_default(),
            Err(_) => std::thread::sleep(Duration::from_millis(1)),
        }
    }
    rest.is_empty()
}

/// A finished run of the host tool.
pub struct ToolRun {
    /// Whether it exited with success.
    pub success: bool,
    /// Its exit status, described.
    pub status: String,
    /// Standard output (the JSON summary).
    pub stdout: String,
    /// The last lines of its standard error (progress and errors).
    pub stderr_tail: Vec<String>,
    /// Wall time, s.
    pub wall_s: f64,
}

/// Runs the host tool with `args`, echoing its progress lines, killing it after `limit`.
pub fn run_tool(binary: &Path, args: &[String], limit: Duration) -> Result<ToolRun, String> {
    let started = Instant::now();
    let mut child = Command::new(binary)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("could not start {}: {e}", binary.display()))?;
    let stdout = child.stdout.take().map(|mut out| {
        std::thread::spawn(move || {
            let mut text = String::new();
            let _ = out.read_to_string(&mut text);
            text
        })
    });
    let stderr = child.stderr.take().map(|err| {
        std::thread::spawn(move || {
            let mut tail = Vec::new();
            for line in BufReader::new(err).lines().map_while(Result::ok) {
                println!("        | {line}");
                tail.push(line);
                if tail.len() > 40 {
                    tail.remove(0);
                }
            }
            tail
        })
    });
    let status = wait_with_limit(&mut child, limit, started)?;
    Ok(ToolRun {
        success: status.as_ref().is_some_and(|s| s.success()),
        status: status.map_or_else(
            || format!("stopped after the {} s limit", limit.as_secs()),
            |s| s.to_string(),
        ),
        stdout: stdout.and_then(|t| t.join().ok()).unwrap_or_default(),
        stderr_tail: stderr.and_then(|t| t.join().ok()).unwrap_or_default(),
        wall_s: started.elapsed().as_secs_f64(),
    })
}

fn wait_with_limit(
    child: &mut Child,
    limit: Duration,
    started: Instant,
) -> Result<Option<std::process::ExitStatus>, String> {
    loop {
        match child.try_wait() {
            Ok(Some(status)) => return Ok(Some(status)),
            Ok(None) if started.elapsed() < limit => std::thread::sleep(Duration::from_millis(50)),
            Ok(None) => {
                // Our own child, stopped by its handle.
                let _ = child.kill();
                let _ = child.wait();
                return Ok(None);
            }
            Err(e) => return Err(format!("waiting for the host tool failed: {e}")),
        }
    }
}

/// A fitted sensor from the summary's `params`.
#[derive(Debug, Clone, Copy)]
pub struct FittedSensor {
    /// `A`.
    pub a: Matrix3<f64>,
    /// `b`.
    pub b: Vector3<f64>,
}

fn numbers<const N: usize>(value: &Value, what: &str) -> Result<[f64; N], String> {
    let items = value
        .as_array()
        .filter(|a| a.len() == N)
        .ok_or_else(|| format!("{what} is not a list of {N} numbers in the summary"))?;
    let mut out = [0.0; N];
    for (slot, item) in out.iter_mut().zip(items) {
        *slot = item
            .as_f64()
            .ok_or_else(|| format!("{what} holds a non-number"))?;
    }
    Ok(out)
}

/// Reads `params.<sensor>` (`A` row-major, `b`) from the summary.
pub fn fitted_sensor(summary: &Value, sensor: &str) -> Result<FittedSensor, String> {
    let s = &summary["params"][sensor];
    let rows: [Value; 3] = [s["A"][0].clone(), s["A"][1].clone(), s["A"][2].clone()];
    let mut a = Matrix3::zeros();
    for (r, row) in rows.iter().enumerate() {
        let row = numbers::<3>(row, &format!("params.{sensor}.A[{r}]"))?;
        for (c, v) in row.iter().enumerate() {
            a[(r, c)] = *v;
        }
    }
    let b = numbers::<3>(&s["b"], &format!("params.{sensor}.b"))?;
    Ok(FittedSensor {
        a,
        b: Vector3::from(b),
    })
}

/// A number of the summary, or why it is missing.
pub fn number(summary: &Value, path: &[&str]) -> Result<f64, String> {
    let mut v = summary;
    for key in path {
        v = &v[*key];
    }
    v.as_f64()
        .ok_or_else(|| format!("`{}` is missing from the summary", path.join(".")))
}

/// Three numbers of the summary (an uncertainty per axis).
pub fn triple(summary: &Value, path: &[&str]) -> Result<[f64; 3], String> {
    let mut v = summary;
    for key in path {
        v = &v[*key];
    }
    numbers::<3>(v, &format!("`{}`", path.join(".")))
}

/// `M = A_fit·A_true⁻¹` split into its singular values and its nearest rotation.
pub struct GaugeFree {
    /// Singular values of `M` (1 for an exact scale).
    pub singular_values: Vector3<f64>,
    /// The rotation nearest to `M`.
    pub rotation: Matrix3<f64>,
}

/// Compares a fitted `A` with the true one independently of the fit's rotation gauge.
pub fn gauge_free(fitted: &Matrix3<f64>, truth: &SensorTruth) -> GaugeFree {
    let m = fitted * truth.a_inverse();
    let svd = m.svd(true, true);
    let rotation = match (svd.u, svd.v_t) {
        (Some(u), Some(v_t)) => u * v_t,
        _ => Matrix3::identity(),
    };
    GaugeFree {
        singular_values: svd.singular_values,
        rotation,
    }
}

/// Angle between two rotations, degrees.
pub fn rotation_angle_deg(a: &Matrix3<f64>, b: &Matrix3<f64>) -> f64 {
    let r = a.transpose() * b;
    ((r.trace() - 1.0) / 2.0)
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

/// Compares a fitted offset with the truth, per axis, against `SIGMAS` × σ (σ per axis, with a
/// floor); returns the worst error in σ or the first axis outside.
pub fn check_offset(
    name: &str,
    unit: &str,
    fitted: &Vector3<f64>,
    truth: &Vector3<f64>,
    sigma: [f64; 3],
    floor: f64,
) -> Result<String, String> {
    let mut worst: f64 = 0.0;
    let mut text = Vec::new();
    for k in 0..3 {
        let s = if sigma[k].is_finite() {
            sigma[k].max(floor)
        } else {
            return Err(format!(
                "{name}: the fit reported no uncertainty for axis {k}"
            ));
        };
        let error = fitted[k] - truth[k];
        worst = worst.max(error.abs() / s);
        text.push(format!("{error:+.1e}"));
        if error.abs() > SIGMAS * s {
            return Err(format!(
                "{name} axis {k}: fitted {:.5} {unit}, true {:.5} {unit}, error {error:+.5} {unit} \
                 exceeds {SIGMAS}σ = {:.5} {unit}",
                fitted[k],
                truth[k],
                SIGMAS * s
            ));
        }
    }
    Ok(format!(
        "{name} error ({}) {unit}, worst {worst:.1}σ",
        text.join(", ")
    ))
}

/// The figures the end-to-end check reports; everything is derived from the truth's noise and
/// the session's own uncertainties.
pub fn compare_with_truth(summary: &Value, truth: &Truth) -> Vec<(String, Result<String, String>)> {
    let mut checks = Vec::new();
    let imu = &truth.imu;
    let rate = imu.sample_rate_hz;

    // Accelerometer offset: σ per axis from the fit's covariance (built from the measured pose
    // noise), floored at the white-noise standard error of all twelve 1.5 s holds.
    let accel = fitted_sensor(summary, "accel");
    let floor_a = imu.accel.noise_sigma / (12.0 * 1.5 * rate).sqrt();
    checks.push((
        "accelerometer offset b matches the truth".into(),
        accel.as_ref().map_err(Clone::clone).and_then(|fit| {
            let sigma =
                triple(summary, &["uncertainties", "accel_bias_mg"])?.map(|mg| mg * G / 1000.0);
            check_offset("b", "m/s²", &fit.b, &imu.accel.b(), sigma, floor_a)
        }),
    ));
    let accel_gauge = accel
        .as_ref()
        .ok()
        .map(|fit| gauge_free(&fit.a, &imu.accel));
    checks.push((
        "accelerometer scale (singular values of A_fit·A_true⁻¹) matches the truth".into(),
        match &accel_gauge {
            None => Err("no fitted accelerometer matrix".into()),
            Some(gauge) => number(summary, &["uncertainties", "accel_norm_mg"]).and_then(|mg| {
                // |a| σ in mg over a 1 g reading is a relative scale σ.
                let sigma = (mg / 1000.0).max(floor_a / G);
                check_scale(&gauge.singular_values, sigma)
            }),
        },
    ));

    // Gyroscope offset: the fit's σ (inflated by the scatter of the pose means), floored at the
    // white-noise standard error of twelve 1.5 s holds.
    let floor_g = imu.gyro.noise_sigma / (12.0 * 1.5 * rate).sqrt();
    checks.push((
        "gyroscope offset b matches the truth".into(),
        fitted_sensor(summary, "gyro").and_then(|fit| {
            let sigma = triple(summary, &["uncertainties", "gyro_bias_dps"])?.map(f64::to_radians);
            check_offset("b", "rad/s", &fit.b, &imu.gyro.b(), sigma, floor_g)
        }),
    ));

    // Magnetometer: offset and scale against the fit's σ (from the tumble's residual scatter),
    // floored at the white-noise error of 1500 samples; rotation against the accelerometer's.
    let mag = fitted_sensor(summary, "mag");
    let floor_m = imu.mag.noise_sigma / 1500.0_f64.sqrt();
    checks.push((
        "magnetometer offset b matches the truth".into(),
        mag.as_ref().map_err(Clone::clone).and_then(|fit| {
            let sigma = triple(summary, &["uncertainties", "mag_bias_ut"])?;
            check_offset("b", "µT", &fit.b, &imu.mag.b(), sigma, floor_m)
        }),
    ));
    let mag_gauge = mag.as_ref().ok().map(|fit| gauge_free(&fit.a, &imu.mag));
    checks.push((
        "magnetometer scale and alignment to the accelerometer match the truth".into(),
        match (&mag_gauge, &accel_gauge) {
            (Some(m), Some(a)) => {
                let pct = number(summary, &["uncertainties", "mag_norm_pct"]);
                let align = number(summary, &["uncertainties", "alignment_deg"]);
                pct.and_then(|pct| {
                    let sigma = (pct / 100.0).max(floor_m / truth.world.earth_field.magnitude_ut);
                    let scale = check_scale(&m.singular_values, sigma)?;
                    let align = align?;
                    let angle = rotation_angle_deg(&m.rotation, &a.rotation);
                    // A floor of 0.05°: the alignment's σ does not include the accelerometer's
                    // own gauge rotation error, a few µrad for offsets of ~0.1 mg.
                    let limit = SIGMAS * align.max(0.01);
                    if angle > limit.max(0.05) {
                        return Err(format!(
                            "{scale}; the magnetometer frame is {angle:.3}° from the \
                             accelerometer's, more than {:.3}° ({SIGMAS}σ)",
                            limit.max(0.05)
                        ));
                    }
                    Ok(format!(
                        "{scale}; frame {angle:.3}° from the accelerometer's (σ {align:.3}°)"
                    ))
                })
            }
            _ => Err("no fitted magnetometer or accelerometer matrix".into()),
        },
    ));
    checks
}

fn check_scale(singular_values: &Vector3<f64>, sigma: f64) -> Result<String, String> {
    let worst = singular_values
        .iter()
        .map(|s| (s - 1.0).abs())
        .fold(0.0, f64::max);
    let text = format!(
        "singular values ({:.6}, {:.6}, {:.6}), worst {:.1} ppm against {SIGMAS}σ = {:.1} ppm",
        singular_values[0],
        singular_values[1],
        singular_values[2],
        worst * 1e6,
        SIGMAS * sigma * 1e6
    );
    if worst > SIGMAS * sigma {
        Err(text)
    } else {
        Ok(text)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use imucal_hil_sim::feed::{FeedOptions, FeedWorld};

    #[test]
    fn a_rotated_exact_fit_has_unit_singular_values_and_its_rotation() {
        let truth = FeedWorld::new(&FeedOptions::new(4))
            .expect("valid options")
            .truth();
        let rotation = nalgebra::Rotation3::from_euler_angles(0.1, -0.2, 0.3).into_inner();
        let fitted = rotation * truth.imu.accel.a();
        let gauge = gauge_free(&fitted, &truth.imu.accel);
        // Exact inputs: only f64 rounding (1e-15) separates the values from 1.
        for s in gauge.singular_values.iter() {
            assert!((s - 1.0).abs() < 1e-12, "singular value {s}");
        }
        assert!(rotation_angle_deg(&gauge.rotation, &rotation) < 1e-6);
    }

    #[test]
    fn a_scale_error_shows_as_a_singular_value_and_fails_its_check() {
        let truth = FeedWorld::new(&FeedOptions::new(4))
            .expect("valid options")
            .truth();
        let mut fitted = truth.imu.mag.a();
        fitted.row_mut(1).scale_mut(1.002);
        let gauge = gauge_free(&fitted, &truth.imu.mag);
        let worst = gauge
            .singular_values
            .iter()
            .map(|s| (s - 1.0).abs())
            .fold(0.0, f64::max);
        // A 0.2 % row scale is a 0.2 % singular value (the other two stay at 1).
        assert!((worst - 0.002).abs() < 1e-9, "worst {worst}");
        assert!(check_scale(&gauge.singular_values, 1e-4).is_err());
        assert!(check_scale(&gauge.singular_values, 1e-3).is_ok());
    }

    #[test]
    fn offsets_outside_five_sigma_fail_with_the_axis_named() {
        let truth = Vector3::new(0.1, -0.2, 0.3);
        let close = Vector3::new(0.1004, -0.2, 0.3);
        assert!(check_offset("b", "m/s²", &close, &truth, [1e-4; 3], 0.0).is_ok());
        let far = Vector3::new(0.1, -0.2, 0.301);
        let error =
            check_offset("b", "m/s²", &far, &truth, [1e-4; 3], 0.0).expect_err("10σ is outside");
        assert!(error.contains("axis 2"), "{error}");
    }

    #[test]
    fn summary_params_are_read_as_row_major_matrices() {
        let summary: Value = serde_json::json!({
            "params": {"accel": {"A": [[1.0, 2.0, 3.0], [0.0, 1.0, 0.5], [0.0, 0.0, 1.0]],
                                 "b": [0.1, 0.2, 0.3]}}
        });
        let fit = fitted_sensor(&summary, "accel").expect("well-formed");
        assert_eq!(fit.a[(0, 2)], 3.0);
        assert_eq!(fit.a[(1, 2)], 0.5);
        assert_eq!(fit.b, Vector3::new(0.1, 0.2, 0.3));
        assert!(fitted_sensor(&summary, "gyro").is_err());
    }
}
