//! `imucal report`: a session directory with a known calibration gives calibrated data on the
//! reference sphere, and the page is self-contained with every figure present.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::process::Command;

use imucal::device::ParamsFile;
use imucal::fit::{Mat3, Vec3};
use imucal::report::{from_session_dir, render_html, up_label, ReportData, SensorParameters};
use imucal_protocol::CalibrationSet;

const FIELD_UT: f64 = 48.0;
const GRAVITY: f64 = 9.80665;
/// The gyroscope's bias in the session's parameters, rad/s: the poses read it at rest.
const GYRO_BIAS_RADS: [f64; 3] = [0.01, -0.02, 0.005];

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("imucal-report-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temporary directory");
    dir
}

/// Evenly spread unit directions (Fibonacci sphere).
fn directions(n: usize) -> Vec<Vec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = golden * i as f64;
            Vec3::new(r * phi.cos(), r * phi.sin(), z)
        })
        .collect()
}

/// A session directory whose raw data is exactly the inverse of its parameters.
fn write_session(dir: &std::path::Path) {
    let mag_a = Mat3::new(1.08, 0.03, -0.02, 0.0, 0.94, 0.05, 0.0, 0.0, 1.02);
    let mag_b = Vec3::new(12.5, -30.0, 7.0);
    let accel_a = Mat3::new(1.01, 0.002, 0.0, 0.0, 0.99, -0.003, 0.0, 0.0, 1.005);
    let accel_b = Vec3::new(0.12, -0.05, 0.08);
    let mut set = CalibrationSet::identity();
    set.gyro.b = GYRO_BIAS_RADS.map(|v| v as f32);
    set.mag.a = [0, 1, 2].map(|r| [0, 1, 2].map(|c| mag_a[(r, c)] as f32));
    set.mag.b = [0, 1, 2].map(|i| mag_b[i] as f32);
    set.accel.a = [0, 1, 2].map(|r| [0, 1, 2].map(|c| accel_a[(r, c)] as f32));
    set.accel.b = [0, 1, 2].map(|i| accel_b[i] as f32);
    set.reference.field_ut = FIELD_UT as f32;
    set.reference.gravity_mps2 = GRAVITY as f32;
    std::fs::write(dir.join("params.json"), ParamsFile::from(&set).to_json()).unwrap();

    let mag_inv = mag_a.try_inverse().unwrap();
    let mut csv = String::from("t_s,mx,my,mz,temp_c,phase\n");
    for (i, u) in directions(600).iter().enumerate() {
        let raw = mag_b + mag_inv * (u * FIELD_UT);
        writeln!(
            csv,
            "{:.3},{:.6},{:.6},{:.6},{:.2},tumble",
            i as f64 * 0.05,
            raw.x,
            raw.y,
            raw.z,
            25.0 + i as f64 * 0.01
        )
        .unwrap();
    }
    std::fs::write(dir.join("mag_samples.csv"), csv).unwrap();

    let accel_inv = accel_a.try_inverse().unwrap();
    let poses: Vec<serde_json::Value> = directions(12)
        .iter()
        .map(|u| {
            let raw = accel_b + accel_inv * (u * GRAVITY);
            serde_json::json!({"target": up_label(u), "target_up": [u.x, u.y, u.z],
                "stats": {"n": 200, "accel_mean": [raw.x, raw.y, raw.z],
                    "gyro_mean": GYRO_BIAS_RADS, "temp_mean_c": 26.0}})
        })
        .collect();
    std::fs::write(
        dir.join("poses.json"),
        serde_json::to_string(&poses).unwrap(),
    )
    .unwrap();
    let summary = serde_json::json!({
        "verdict": {"level": "good", "reasons": []},
        "uncertainties": {"accel_bias_mg": [0.1, 0.1, 0.2], "mag_norm_pct": 0.05},
        "accel_rest_error_mg": 0.4
    });
    std::fs::write(dir.join("summary.json"), summary.to_string()).unwrap();
}

#[test]
fn session_report_puts_calibrated_samples_on_the_reference_sphere() {
    let dir = scratch("session");
    write_session(&dir);
    let data = from_session_dir(&dir).expect("a complete session directory");
    let mag = data.mag.as_ref().expect("magnetometer samples");
    assert_eq!(mag.calibrated.len(), 600);
    // Raw values are written to 1e-6 µT and the parameters narrowed to f32 (relative 6e-8 on
    // entries near 1), so |y| may deviate by about 48 µT · 1e-7 + 1e-6: 1e-5 µT bounds both.
    for y in &mag.calibrated {
        assert!((y.norm() - FIELD_UT).abs() < 1e-5, "|y| = {}", y.norm());
    }
    let accel = data.accel.as_ref().expect("accelerometer poses");
    assert_eq!(accel.calibrated.len(), 12);
    for a in &accel.calibrated {
        assert!((a.norm() - GRAVITY).abs() < 1e-5, "|a| = {}", a.norm());
    }
    assert_eq!(data.verdict_level, "good");
    let html = render_html(&data).expect("renders");
    // 3 raw + 3 calibrated projections, 2 histograms, 2 against time and temperature, coverage,
    // accelerometer bars before and after (its poses share one temperature, so no plot
    // against it), gyroscope rates before and after.
    assert_eq!(html.matches("<svg").count(), 15, "figures in the page");
    assert!(html.contains("Verdict: good"));
    assert!(
        html.contains("0.000 % after"),
        "after-calibration RMS is zero to print precision"
    );
    for outside in ["<script", "<link", "@import", "url(", "src=\"http"] {
        assert!(
            !html.contains(outside),
            "the page refers to outside resources via {outside}"
        );
    }
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_missing_session_file_is_named_and_empty_data_is_refused() {
    let dir = scratch("missing");
    let error = from_session_dir(&dir).unwrap_err().to_string();
    assert!(error.contains("params.json"), "{error}");
    let empty = render_html(&ReportData::default()).unwrap_err().to_string();
    assert!(
        empty.contains("no accelerometer or gyroscope poses and no magnetometer samples"),
        "{empty}"
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn report_command_fits_a_real_recording_and_checks_the_radius_against_the_model() {
    let out = scratch("cli");
    let recording = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../data/real/sf_mpu6050_hmc5883l_full_sphere.csv"
    );
    let status = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args([
            "report",
            recording,
            "--accel-unit",
            "g",
            "--gyro-unit",
            "dps",
            "--mag-unit",
            "gauss",
        ])
        .args(["--location", "46.05,14.51", "-o"])
        .arg(&out)
        .output()
        .expect("imucal runs");
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    let html = std::fs::read_to_string(out.join("report.html")).expect("report.html written");
    // The HMC5883L data reads about 0.53 gauss = 53 µT; the model gives about 48 µT there,
    // so the radius check must call it plausible (within 20 %).
    assert!(
        html.contains("is within 20 % of the modelled field"),
        "radius note missing"
    );
    assert!(html.contains("WMM2025: F = "));
    assert!(html.matches("<svg").count() >= 9);
    // The board is never still in this recording: the accelerometer and gyroscope are not
    // fitted, and the headline says so instead of "fitted".
    assert!(
        html.contains("<p class=\"verdict marginal\">Verdict: partly fitted</p>"),
        "headline"
    );
    assert!(html.contains("not fitted: "), "reason missing");
    let _ = std::fs::remove_dir_all(out);
}

/// The report's coverage uses the cells, the centre, the samples and the minimum per region of
/// the session's screen: samples of the moves between positions count, the final rest does not.
#[test]
fn the_report_counts_coverage_in_the_same_regions_as_the_session_screen() {
    use imucal::report::region_coverage;
    use imucal::session::coverage::{sphere_centre, Coverage, REGIONS};
    use imucal::session::SessionOptions;

    let dir = scratch("regions");
    write_session(&dir);
    let bias = Vec3::new(12.5, -30.0, 7.0);
    let raw = |u: &Vec3| bias + u * FIELD_UT;
    // Moves between positions reach the upper part, the tumble the +X half below it; the rest
    // lies still at the -X-Y-Z corner, which nothing else reaches.
    let all = directions(800);
    let positions: Vec<Vec3> = all.iter().filter(|u| u.z > 0.2).map(raw).collect();
    let tumble: Vec<Vec3> = all
        .iter()
        .filter(|u| u.z <= 0.2 && u.x > 0.0)
        .map(raw)
        .collect();
    let rest: Vec<Vec3> = (0..60)
        .map(|_| raw(&Vec3::new(-1.0, -1.0, -1.0).normalize()))
        .collect();
    let mut csv = String::from("t_s,mx,my,mz,temp_c,phase\n");
    let rows = [
        ("positions", &positions),
        ("tumble", &tumble),
        ("rest", &rest),
    ];
    let mut t = 0.0;
    for (phase, samples) in rows {
        for m in samples {
            t += 0.01;
            writeln!(csv, "{t:.3},{:.6},{:.6},{:.6},25.0,{phase}", m.x, m.y, m.z).unwrap();
        }
    }
    std::fs::write(dir.join("mag_samples.csv"), csv).unwrap();

    // What the magnetometer phase counts on screen: every sample up to its end.
    let min = SessionOptions::default().mag_min_per_region;
    let seen: Vec<Vec3> = positions.iter().chain(&tumble).copied().collect();
    let screen = Coverage::of(&seen, &sphere_centre(&seen).expect("a centre"));
    let with_rest: Vec<Vec3> = seen.iter().chain(&rest).copied().collect();
    let rest_counted = Coverage::of(&with_rest, &sphere_centre(&with_rest).expect("a centre"));
    // The rest would fill a region of its own if it were counted.
    assert_eq!(rest_counted.covered(min), screen.covered(min) + 1);
    assert!(screen.covered(min) < REGIONS);

    let data = from_session_dir(&dir).expect("a complete session directory");
    let mag = data.mag.as_ref().expect("magnetometer samples");
    let report = region_coverage(mag).expect("countable");
    assert_eq!(report.counts, screen.counts);
    // The plots and the headline rest on the samples the fit used, the positions' and the
    // tumble's, not on the tumble alone (a short one when the positions covered the sphere).
    assert_eq!(mag.raw.len(), positions.len() + tumble.len());
    let html = render_html(&data).expect("renders");
    let empty = screen.empty_regions(min);
    assert!(empty.contains(&"-X-Y-Z".to_string()));
    let expected = format!(
        "{} of {REGIONS} directions with at least {min} samples",
        screen.covered(min)
    );
    assert!(html.contains(&expected), "{expected}");
    assert!(html.contains(&format!("empty: {}", empty.join(" "))));
    // The map labels every region with its count.
    assert!(html.contains(&format!("-X-Y-Z {}", screen.counts[0])));
    let _ = std::fs::remove_dir_all(dir);
}

/// The figures of a page, each its SVG text.
fn figures(html: &str) -> Vec<&str> {
    html.split("<svg").skip(1).collect()
}

#[test]
fn every_plot_but_the_coverage_map_has_a_legend() {
    let dir = scratch("legends");
    write_session(&dir);
    let html = render_html(&from_session_dir(&dir).expect("session")).expect("renders");
    let legends = [
        "raw samples",
        "calibrated samples",
        "before calibration",
        "after calibration",
        "x axis",
    ];
    let mut checked = 0;
    for svg in figures(&html) {
        // The coverage map explains its colours in its caption.
        if svg.contains("field directions in the session") {
            continue;
        }
        assert!(
            legends.iter().any(|l| svg.contains(l)),
            "a figure has no legend: {}",
            &svg[..svg.len().min(300)]
        );
        checked += 1;
    }
    assert_eq!(checked, 14);
    // The outlines are named too, in each projection's legend.
    let in_figures = |name: &str| figures(&html).iter().filter(|f| f.contains(name)).count();
    assert_eq!(in_figures("fitted ellipsoid"), 3);
    assert_eq!(in_figures("reference sphere"), 3);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn poses_are_labelled_by_the_side_that_points_up_and_many_labels_stand_vertical() {
    let dir = scratch("labels");
    write_session(&dir);
    let data = from_session_dir(&dir).expect("session");
    let accel = data.accel.as_ref().expect("poses");
    assert_eq!(accel.labels.len(), 12);
    assert!(
        accel.labels.iter().all(|l| l.ends_with(" up")),
        "{:?}",
        accel.labels
    );
    let html = render_html(&data).expect("renders");
    for label in &accel.labels {
        assert!(
            html.contains(&format!(">\n{label}\n</text>")),
            "{label} not drawn"
        );
    }
    // Twelve short labels fit side by side; twenty stand vertical.
    use imucal::report::plots::pose_bars;
    let short: Vec<String> = (0..12).map(|i| format!("+Z up #{i}")).collect();
    let flat = pose_bars("t", "mg", &[1.0; 12], &short, false).expect("draws");
    assert!(!flat.contains("rotate(90"));
    let many: Vec<String> = (0..20).map(|i| format!("+Z up #{i}")).collect();
    let vertical = pose_bars("t", "mg", &[1.0; 20], &many, false).expect("draws");
    assert_eq!(vertical.matches("rotate(90").count(), 20);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn the_gyroscope_section_shows_each_axis_rate_at_rest_before_and_after_and_the_scale_fit() {
    let dir = scratch("gyro");
    write_session(&dir);
    let mut summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    // The correction 1/1.013 on x: the sensor reads 1.3 % high.
    summary["gyro_scale"] = serde_json::json!({
        "scale": [1.0 / 1.013, 1.0, 1.0], "scale_sigma_pct": [0.02, 0.02, 0.03],
        "misalignment_deg": 0.04, "misalignment_sigma_deg": 0.01, "moves_recorded": 14,
        "moves_used": 12, "rms_deg": 0.05, "tilt_deg": [700.0, 650.0, 400.0]});
    std::fs::write(dir.join("summary.json"), summary.to_string()).unwrap();
    // The written set holds that correction too (its errors are what both tables show).
    let params_path = dir.join("params.json");
    let mut params: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&params_path).unwrap()).unwrap();
    params["gyro"]["A"][0][0] = serde_json::json!(1.0 / 1.013);
    std::fs::write(&params_path, params.to_string()).unwrap();
    let data = from_session_dir(&dir).expect("session");
    let gyro = data.gyro.as_ref().expect("the poses carry gyroscope means");
    for (raw, calibrated) in gyro.raw_dps.iter().zip(&gyro.calibrated_dps) {
        for i in 0..3 {
            assert!((raw[i] - GYRO_BIAS_RADS[i].to_degrees()).abs() < 1e-6);
            // The bias in the set removes the rate at rest.
            assert!(calibrated[i].abs() < 1e-6, "{calibrated:?}");
        }
    }
    let html = render_html(&data).expect("renders");
    assert!(html.contains("<h2>Gyroscope</h2>"));
    assert!(html.contains("gyroscope before calibration: rate at rest per pose"));
    assert!(html.contains("gyroscope after calibration: residual rate at rest per pose"));
    assert!(
        html.contains("+1.300 % ± 0.0200 %"),
        "scale error as the sensor reads"
    );
    assert!(html.contains("12 of 14"));
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_constant_temperature_is_said_in_words_instead_of_plotted() {
    let dir = scratch("constant-temperature");
    write_session(&dir);
    let html = render_html(&from_session_dir(&dir).expect("session")).expect("renders");
    // The poses all read 26 °C; the magnetometer samples span 25–31 °C and keep their plot.
    assert!(!html.contains("accelerometer |a| error against pose temperature"));
    assert!(html.contains("Temperature constant at 26.0 °C during the accelerometer poses"));
    assert!(html.contains("magnetometer norm error against temperature"));
    let _ = std::fs::remove_dir_all(dir);
}

fn minimal_data(verdict: &str) -> ReportData {
    let dir = scratch(&format!("badge-{verdict}"));
    write_session(&dir);
    let mut data = from_session_dir(&dir).expect("session");
    let _ = std::fs::remove_dir_all(dir);
    data.verdict_level = verdict.to_string();
    data
}

#[test]
fn the_badge_is_neutral_when_nothing_was_checked_and_coloured_for_the_session_levels() {
    for (level, class) in [
        ("good", "good"),
        ("marginal", "marginal"),
        ("poor", "poor"),
        ("fitted", "neutral"),
        ("partly fitted", "marginal"),
        ("fitted, with findings", "marginal"),
        ("not fitted", "poor"),
        ("unknown", "neutral"),
    ] {
        let html = render_html(&minimal_data(level)).expect("renders");
        assert!(
            html.contains(&format!(
                "<p class=\"verdict {class}\">Verdict: {level}</p>"
            )),
            "{level}"
        );
    }
}

#[test]
fn values_not_estimated_are_written_in_words_never_nan() {
    let dir = scratch("nan");
    write_session(&dir);
    let mut summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    // serde_json writes a NaN as null.
    summary["uncertainties"]["accel_norm_mg"] = serde_json::Value::Null;
    std::fs::write(dir.join("summary.json"), summary.to_string()).unwrap();
    let mut data = from_session_dir(&dir).expect("session");
    data.parameters.push(SensorParameters {
        name: "gyroscope (not estimated)".to_string(),
        unit_in: "rad/s".to_string(),
        unit_out: "rad/s".to_string(),
        a: Mat3::identity() * f64::NAN,
        b: Vec3::new(f64::NAN, 0.0, 0.0),
        std: None,
        to_nominal: Some(1.0),
    });
    let html = render_html(&data).expect("renders");
    assert!(!html.contains("NaN"), "NaN in the page");
    assert!(!html.contains("null"), "null in the page");
    assert!(html.contains("unknown / not estimated"));
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn scale_errors_and_axis_angles_are_shown_apart_from_the_unit_conversion() {
    let mut data = minimal_data("fitted");
    // Data in g reading 1.3 % high on x: A alone (9.68…) hides the error in the conversion.
    data.parameters = vec![SensorParameters {
        name: "accelerometer".to_string(),
        unit_in: "g".to_string(),
        unit_out: "m/s²".to_string(),
        a: Mat3::from_diagonal(&Vec3::new(GRAVITY / 1.013, GRAVITY, GRAVITY)),
        b: Vec3::zeros(),
        std: None,
        to_nominal: Some(GRAVITY),
    }];
    let html = render_html(&data).expect("renders");
    assert!(html.contains("<td>+1.300 %</td>"), "scale error of x");
    assert!(
        html.contains("1 g = 9.80665 m/s²"),
        "the conversion named apart"
    );
    assert!(html.contains("axes off 90° by"));
}

#[test]
fn every_column_of_a_parameter_table_uses_one_number_format() {
    use imucal::report::ColumnFormat;
    // 0.97 and 0.0063 print fixed; a column holding 8e-5 prints every value scientific.
    assert_eq!(
        ColumnFormat::for_column(&[0.97, 0.0063, -0.0079]),
        ColumnFormat::Fixed
    );
    assert_eq!(
        ColumnFormat::for_column(&[1.006, 0.0, -8.0e-5]),
        ColumnFormat::Scientific
    );
    // A column of small values only (counts to m/s²) would keep three digits fixed.
    assert_eq!(
        ColumnFormat::for_column(&[6.0179e-4, 1.2e-6, 0.0]),
        ColumnFormat::Scientific
    );
    let mut data = minimal_data("fitted");
    data.parameters[0].a = Mat3::new(1.006, 0.015, -8.0e-5, 0.0, 1.013, 2.0e-3, 0.0, 0.0, 0.978);
    let html = render_html(&data).expect("renders");
    // The third column is scientific throughout, the first two fixed.
    assert!(html.contains("-8.0000e-5"));
    assert!(html.contains("2.0000e-3"));
    assert!(html.contains("9.7800e-1"));
    assert!(html.contains("1.006000"));
}

#[test]
fn uncertainties_are_named_in_words_with_their_units_and_long_text_wraps() {
    let mut data = minimal_data("good");
    data.analysis = Some(format!("{}\n", "a long line of analysis text ".repeat(20)));
    let html = render_html(&data).expect("renders");
    assert!(html.contains("<th>accelerometer offset, per axis x, y, z</th>"));
    assert!(html.contains("± 0.100 mg, ± 0.100 mg, ± 0.200 mg"));
    assert!(html.contains("one standard deviation (±)"));
    assert!(html.contains("expected error of |m| in the worst direction"));
    assert!(
        !html.contains("accel_bias_mg"),
        "a field name instead of words"
    );
    assert!(html.contains("white-space:pre-wrap"));
}

#[test]
fn with_analyze_the_report_shows_the_extended_terms_and_the_checks_of_both_sets() {
    let dir = scratch("extended");
    write_session(&dir);
    let mut params: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("params.json")).unwrap()).unwrap();
    params["accel"]["bias_temp"] = serde_json::json!({
        "coeffs": [[6.6e-3, 5.7e-3, 8.8e-3], [-1.3e-4, -2.0e-4, 2.5e-4], [0.0, 0.0, 0.0]]});
    std::fs::write(dir.join("params.json"), params.to_string()).unwrap();
    let check = |a: f64| {
        serde_json::json!({"accel_error_mg": a, "mag_error_pct": 0.05,
        "gyro_rate_dps": 0.01})
    };
    let mut summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    summary["before"] = check(48.5);
    summary["after"] = check(11.6);
    summary["on_board_after"] = check(0.47);
    std::fs::write(dir.join("summary.json"), summary.to_string()).unwrap();
    std::fs::write(
        dir.join(imucal::report::ANALYSIS_TEXT_FILE),
        "accel — base model lm\nExtended terms added: accel bias_temperature (degree 2)\n",
    )
    .unwrap();
    let html = render_html(&from_session_dir(&dir).expect("session")).expect("renders");
    assert!(html.contains("<th>after, base set</th>"));
    assert!(html.contains("<th>after, extended set (on the board)</th>"));
    assert!(html.contains("11.600 mg") && html.contains("0.470 mg"));
    assert!(html.contains("Extended terms on the board"));
    assert!(html.contains("m/s²/°C²"));
    assert!(html.contains("Extended terms added: accel bias_temperature"));
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_gyroscope_only_recording_gets_a_report_of_the_bias_fit_finds() {
    // Three seconds at rest with a known bias: `fit` calibrates the bias, so `report` must show
    // it rather than refuse the recording for having no accelerometer.
    let dir = scratch("gyro-only");
    let bias = [0.010, -0.020, 0.005];
    let mut csv = String::from("t_s,gx,gy,gz\n");
    for i in 0..300 {
        // A deterministic ±1 mrad/s wobble stands in for noise.
        let wobble = 0.001 * f64::from(i % 7 - 3) / 3.0;
        let _ = writeln!(
            csv,
            "{:.2},{:.6},{:.6},{:.6}",
            f64::from(i) / 100.0,
            bias[0] + wobble,
            bias[1] - wobble,
            bias[2] + wobble / 2.0
        );
    }
    let recording = dir.join("gyro.csv");
    std::fs::write(&recording, csv).expect("recording written");
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(["report", &recording.display().to_string(), "--force"])
        .output()
        .expect("the imucal binary runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let html = std::fs::read_to_string(dir.join("gyro_report/report.html")).expect("report");
    assert!(
        html.contains("Gyroscope") && html.contains("gyro-bias"),
        "{html}"
    );
    // The fitted bias is in the parameter table, printed `value ± σ` (the wobble's mean is
    // below 2e-4 rad/s).
    let shown: Vec<f64> = html
        .split("<span class=std> ± ")
        .filter_map(|before| before.rsplit('>').next()?.parse().ok())
        .collect();
    for b in bias {
        assert!(
            shown.iter().any(|v| (v - b).abs() < 2e-4),
            "bias {b} not among {shown:?}"
        );
    }
    let _ = std::fs::remove_dir_all(dir);
}

/// The `progress.json` of a session `calibrate` stopped in `stage`.
fn write_progress(dir: &std::path::Path, stage: &str) {
    let progress = serde_json::json!({
        "device_id": "03000000004d49530000000000000000",
        "stage": "stopped",
        "stopped_because": format!("the session was stopped by the user (Ctrl-C) (during stage `{stage}`)"),
        "board_holds": "its earlier calibration: nothing was written",
        "poses": 12,
        "mag_samples": 600,
        "params_crc": null
    });
    std::fs::write(dir.join("progress.json"), progress.to_string()).unwrap();
}

#[test]
fn a_session_with_a_motioncal_sketch_is_reported_and_says_why_samples_and_checks_are_missing() {
    // `calibrate --sim-protocol motioncal` saves its readings as `readings.csv` (a recording),
    // not `mag_samples.csv`, and no summary.json; its verdict is in motioncal.json.
    let dir = scratch("motioncal");
    write_session(&dir);
    std::fs::remove_file(dir.join("mag_samples.csv")).unwrap();
    std::fs::remove_file(dir.join("summary.json")).unwrap();
    let summary = serde_json::json!({
        "verdict": {"level": "marginal", "reasons": ["the sketch applies no misalignment"]},
        "poses": 12
    });
    std::fs::write(dir.join("motioncal.json"), summary.to_string()).unwrap();
    let data = from_session_dir(&dir).expect("a MotionCal session is reported");
    assert!(data.mag.is_none());
    assert_eq!(data.accel.as_ref().map(|a| a.calibrated.len()), Some(12));
    assert_eq!(data.verdict_level, "marginal");
    let notes = data.notes.join("\n");
    assert!(notes.contains("readings.csv is missing"), "{notes}");
    assert!(notes.contains("MotionCal sketch"), "{notes}");
    // Its figures are what the library applies: the offsets only, for the accelerometer.
    assert!(notes.contains("what the sketch board applies"), "{notes}");
    let set = imucal::device::ParamsFile::load(&dir.join("params.json"))
        .and_then(|p| p.to_calibration_set("params.json"))
        .expect("the session's set");
    let accel = data.accel.as_ref().expect("poses");
    for (raw, shown) in accel.raw_mps2.iter().zip(&accel.calibrated) {
        for k in 0..3 {
            let offset_only = raw[k] - f64::from(set.accel.b[k]);
            assert!((shown[k] - offset_only).abs() < 1e-9, "{shown} vs {raw}");
        }
    }
    // The sketch prints no temperature: none is shown for its poses.
    assert!(accel.temp_c.iter().all(Option::is_none));
    render_html(&data).expect("renders");

    // With its readings, the magnetometer is plotted from them; the sketch gives no temperature.
    let mut readings = String::from("t_s,ax,ay,az,gx,gy,gz,mx,my,mz\n");
    for k in 0..40 {
        let angle = f64::from(k) * 0.3;
        readings.push_str(&format!(
            "{},0,0,9.8,0,0,0,{},{},{}\n",
            f64::from(k) * 0.01,
            30.0 * angle.cos(),
            30.0 * angle.sin(),
            20.0 * (0.5 * angle).sin()
        ));
    }
    std::fs::write(dir.join("readings.csv"), readings).unwrap();
    let data = from_session_dir(&dir).expect("a MotionCal session with readings is reported");
    let mag = data
        .mag
        .as_ref()
        .expect("the readings' magnetometer is plotted");
    assert_eq!(mag.raw.len(), 40);
    assert!(mag.temp_c.is_none(), "the sketch prints no temperature");
    assert!(
        !data.notes.join("\n").contains("readings.csv"),
        "{:?}",
        data.notes
    );
    render_html(&data).expect("renders");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn an_unfinished_session_is_reported_when_fitted_and_otherwise_refused_saying_how_to_finish() {
    // Stopped after the fit: reported, saying that it did not finish.
    let dir = scratch("unfinished-fitted");
    write_session(&dir);
    std::fs::remove_file(dir.join("summary.json")).unwrap();
    write_progress(&dir, "after");
    let data = from_session_dir(&dir).expect("a fitted unfinished session is reported");
    let notes = data.notes.join("\n");
    assert!(notes.contains("did not finish"), "{notes}");
    assert!(notes.contains("stage `after`"), "{notes}");
    let _ = std::fs::remove_dir_all(dir);

    // Stopped before the fit: poses.json is there, params.json is not.
    let dir = scratch("unfinished-positions");
    write_session(&dir);
    std::fs::remove_file(dir.join("summary.json")).unwrap();
    std::fs::remove_file(dir.join("params.json")).unwrap();
    write_progress(&dir, "positions");
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .arg("report")
        .arg(&dir)
        .output()
        .expect("run imucal");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("stopped before its calibration was fitted"),
        "{stderr}"
    );
    assert!(stderr.contains("no params.json to report"), "{stderr}");
    assert!(
        !stderr.contains("poses.json"),
        "poses.json is there: {stderr}"
    );
    assert!(stderr.contains("--resume"), "{stderr}");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn poses_of_a_raw_count_recording_are_named_by_the_side_that_is_up_not_by_the_offset() {
    // IMU-TK's Xsens recording is in raw counts on an offset of about 32768 per axis: named from
    // the raw means, every pose was "+X+Y+Z up".
    let dir = scratch("raw-count-labels");
    let recording =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/real/imutk_xsens_multipos.csv");
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .arg("report")
        .arg(&recording)
        .args(["--accel-unit", "counts", "--gyro-unit", "counts", "-o"])
        .arg(dir.join("out"))
        .output()
        .expect("imucal runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let html = std::fs::read_to_string(dir.join("out").join("report.html")).expect("the page");
    let sides: std::collections::BTreeSet<&str> = ["+X", "-X", "+Y", "-Y", "+Z", "-Z"]
        .into_iter()
        .filter(|side| html.contains(&format!("{side} up")))
        .collect();
    // The recording holds the board with each of its six faces up.
    assert_eq!(sides.len(), 6, "{sides:?}");
    assert!(
        !html.contains("+X+Y+Z up #2"),
        "every pose named by the offset"
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn an_output_path_ending_in_html_is_the_report_file_and_any_other_a_directory() {
    let dir = scratch("out-file");
    let session = dir.join("session");
    std::fs::create_dir_all(&session).unwrap();
    write_session(&session);
    let report = |out: &std::path::Path| {
        let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
            .env("IMUCAL_DB", dir.join("no-history.sqlite"))
            .arg("report")
            .arg(&session)
            .arg("-o")
            .arg(out)
            .output()
            .expect("run imucal");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let file = dir.join("rep.html");
    let stdout = report(&file);
    assert!(file.is_file(), "`-o rep.html` is the report itself");
    assert!(stdout.contains(&file.display().to_string()), "{stdout}");
    assert!(std::fs::read_to_string(&file).unwrap().contains("<svg"));

    let reports = dir.join("reports");
    report(&reports);
    assert!(
        reports.join("report.html").is_file(),
        "a directory stays one"
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_batch_directory_is_a_usage_error_naming_each_boards_session_and_the_command_to_report_it() {
    // `calibrate --sim-boards N -o b1` writes one session directory per device id in b1.
    let batch = scratch("batch");
    let boards = [
        "0000000000000000000000000000000a",
        "0000000000000000000000000000000b",
    ];
    for board in boards {
        let session = batch.join(board);
        std::fs::create_dir_all(&session).unwrap();
        write_session(&session);
    }
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .env("IMUCAL_DB", batch.join("no-history.sqlite"))
        .arg("report")
        .arg(&batch)
        .output()
        .expect("run imucal");
    let stderr = String::from_utf8_lossy(&out.stderr);
    // The command line names the wrong directory: exit status 2, as other usage errors.
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("directory of a batch"), "{stderr}");
    assert!(!stderr.contains("  "), "one sentence: {stderr}");
    for board in boards {
        let command = format!("`imucal report {}`", batch.join(board).display());
        assert!(stderr.contains(&command), "{command}: {stderr}");
    }
    assert!(!batch.join("report.html").exists(), "nothing was written");
    let _ = std::fs::remove_dir_all(batch);
}

#[test]
fn a_report_of_a_recording_without_times_plots_against_the_sample_number() {
    // A magnetometer on an offset sphere, with neither a time column nor --rate.
    let dir = scratch("untimed");
    let mut text = String::from("mx,my,mz\n");
    for (i, d) in directions(600).iter().enumerate() {
        let wobble = 1.0 + 0.01 * (7.1 * i as f64).sin();
        let _ = writeln!(
            text,
            "{:.4},{:.4},{:.4}",
            40.0 * wobble * d.x + 12.0,
            45.0 * wobble * d.y - 7.0,
            50.0 * wobble * d.z + 3.0
        );
    }
    let recording = dir.join("untimed.csv");
    std::fs::write(&recording, text).expect("writable");
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .env("IMUCAL_DB", dir.join("no-history.sqlite"))
        .arg("report")
        .arg(&recording)
        .args(["--field-ut", "48", "-o"])
        .arg(dir.join("r.html"))
        .output()
        .expect("run imucal");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let html = std::fs::read_to_string(dir.join("r.html")).expect("the report is written");
    assert!(
        html.contains("magnetometer norm error against sample number"),
        "the plot's title names the sample number"
    );
    // The SVG writes a label's text on a line of its own.
    assert!(
        html.contains(">\nsample\n</text>"),
        "the axis is labelled `sample`"
    );
    assert!(!html.contains("time (s)"), "no axis claims seconds");
    let _ = std::fs::remove_dir_all(dir);
}
