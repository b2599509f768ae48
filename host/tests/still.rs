//! Still-interval detection on synthetic recordings whose holds are known exactly.

use imucal::fit::Vec3;
use imucal::recording::{LabelKind, Labels, Recording, Units};
use imucal::stats::distributions::chi2_quantile_per_dof;
use imucal::still::{find_still, StillError, StillOptions};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

const RATE: f64 = 100.0;
const SIGMA_A: f64 = 0.02; // m/s², accelerometer white noise
const SIGMA_G: f64 = 0.005; // rad/s, gyroscope white noise

/// Holds of `hold_s` seconds in each of six face directions, joined by 2 s rotations.
fn six_face_recording(seed: u64, hold_s: f64) -> (Recording, Vec<(f64, f64, Vec3)>) {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let na = Normal::new(0.0, SIGMA_A).expect("valid sigma");
    let ng = Normal::new(0.0, SIGMA_G).expect("valid sigma");
    let faces = [
        Vec3::x(),
        -Vec3::x(),
        Vec3::y(),
        -Vec3::y(),
        Vec3::z(),
        -Vec3::z(),
    ];
    let (mut time, mut accel, mut gyro, mut truth) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut t = 0.0;
    for (k, face) in faces.iter().enumerate() {
        let start = t;
        let gravity = face * 9.81;
        while t < start + hold_s {
            time.push(t);
            accel.push(gravity + Vec3::from_fn(|_, _| na.sample(&mut rng)));
            gyro.push(Vec3::from_fn(|_, _| ng.sample(&mut rng)));
            t += 1.0 / RATE;
        }
        truth.push((start, t, gravity));
        let next = faces[(k + 1) % 6] * 9.81;
        let move_start = t;
        while t < move_start + 2.0 {
            let s = (t - move_start) / 2.0;
            let wobble = (s * std::f64::consts::PI).sin();
            let dir = (gravity * (1.0 - s) + next * s + Vec3::new(wobble, -wobble, wobble) * 5.0)
                .normalize();
            time.push(t);
            accel.push(
                dir * 9.81
                    + Vec3::from_fn(|_, _| na.sample(&mut rng))
                    + Vec3::repeat(rng.gen_range(-0.5..0.5)),
            );
            gyro.push(
                Vec3::new(1.5 * wobble, 0.0, -1.0) + Vec3::from_fn(|_, _| ng.sample(&mut rng)),
            );
            t += 1.0 / RATE;
        }
    }
    let rec = Recording {
        source: "synthetic.csv".into(),
        time,
        time_is_index: false,
        time_from_file: true,
        accel: Some(accel),
        gyro: Some(gyro),
        temp_c: None,
        mag: None,
        labels: None,
        ignored_columns: Vec::new(),
        units: Units::default(),
        read_as_imutk: false,
        repeated_rows: 0,
    };
    (rec, truth)
}

#[test]
fn six_synthetic_holds_are_found_with_edges_within_one_window() {
    let (rec, truth) = six_face_recording(7, 5.0);
    let report = find_still(&rec, &StillOptions::default()).expect("detection runs");
    assert_eq!(report.intervals.len(), 6, "{}", report.summary());
    assert_eq!(report.directions.len(), 6);
    let window_s = StillOptions::default().window_s;
    for (hold, (start, end, gravity)) in report.intervals.iter().zip(&truth) {
        // Centred windows trim each edge by up to one window when motion is abrupt.
        assert!(
            hold.t_start >= start - 1e-9 && hold.t_start <= start + window_s,
            "{} vs {start}",
            hold.t_start
        );
        assert!(
            hold.t_end <= end + 1e-9 && hold.t_end >= end - window_s - 0.02,
            "{} vs {end}",
            hold.t_end
        );
        let pose = hold.accel.as_ref().expect("accel pose");
        // Mean of n samples: 4 standard errors (false-failure rate ~6e-5 per axis).
        let tol = 4.0 * SIGMA_A / (pose.n as f64).sqrt();
        for k in 0..3 {
            assert!(
                (pose.mean[k] - gravity[k]).abs() < tol,
                "axis {k}: {} vs {}",
                pose.mean[k],
                gravity[k]
            );
            // Sample variance of ≥ 400 samples is within ±30% of σ² (χ² 1e-5 tails: ±25%).
            assert!(
                (pose.var[k] / (SIGMA_A * SIGMA_A) - 1.0).abs() < 0.3,
                "variance {}",
                pose.var[k]
            );
        }
    }
}

#[test]
fn noise_estimate_recovers_the_white_noise_sigma() {
    let (rec, _) = six_face_recording(11, 8.0);
    let report = find_still(&rec, &StillOptions::default()).expect("detection runs");
    let accel = report
        .noise
        .iter()
        .find(|n| n.sensor == imucal::recording::Sensor::Accel)
        .expect("accel floor");
    // The percentile correction makes the estimate unbiased when most windows are still; with
    // 48 of 60 s still the 10th percentile is the still distribution's 12.5th, a bias of ~1%
    // in σ. Allow 10%.
    for k in 0..3 {
        assert!(
            (accel.sigma[k] / SIGMA_A - 1.0).abs() < 0.1,
            "sigma {}",
            accel.sigma[k]
        );
    }
}

#[test]
fn holds_shorter_than_the_minimum_are_dropped() {
    let (rec, _) = six_face_recording(3, 0.8);
    let report = find_still(&rec, &StillOptions::default()).expect("detection runs");
    assert!(report.intervals.is_empty(), "{}", report.summary());
}

/// The six-face recording of seed 5 (3 s holds) with a `pose` column naming hold `i` `name(i)`.
fn six_faces_labelled_by_pose(
    name: impl Fn(usize) -> String,
) -> (Recording, Vec<(f64, f64, Vec3)>) {
    let (mut rec, truth) = six_face_recording(5, 3.0);
    let per_row = rec
        .time
        .iter()
        .map(|t| truth.iter().position(|(a, b, _)| t >= a && t < b))
        .collect();
    rec.labels = Some(Labels {
        kind: LabelKind::Pose,
        names: (0..6).map(name).collect(),
        per_row,
    });
    (rec, truth)
}

#[test]
fn a_pose_column_gives_one_hold_per_label_without_detection() {
    let (rec, truth) = six_faces_labelled_by_pose(|i| (10 + i).to_string());
    let report = find_still(&rec, &StillOptions::default()).expect("labels are used");
    assert!(report.from_pose_column);
    assert_eq!(report.intervals.len(), 6);
    assert_eq!(report.intervals[2].label, Some(12));
    let (a, b, _) = truth[2];
    let rows = rec.time.iter().filter(|t| **t >= a && **t < b).count();
    assert_eq!(report.intervals[2].accel.as_ref().map(|p| p.n), Some(rows));
}

/// A spike in the accelerometer inside the third hold, and every row labelled by the hold it
/// is in, with text labels (`P12`, `P11`, …) of `kind`.
fn labelled_with_a_spike(kind: LabelKind) -> Recording {
    let (mut rec, truth) = six_face_recording(7, 3.0);
    let per_row: Vec<Option<usize>> = rec
        .time
        .iter()
        .map(|t| truth.iter().position(|(a, b, _)| t >= a && t < b))
        .collect();
    let (a, b, _) = truth[2];
    let middle = rec
        .time
        .iter()
        .position(|t| *t >= (a + b) / 2.0)
        .expect("a row mid-hold");
    if let Some(accel) = rec.accel.as_mut() {
        // Ten times the noise: screened out, yet too small to split the detected hold.
        accel[middle] += Vec3::new(10.0 * SIGMA_A, 0.0, 0.0);
    }
    rec.labels = Some(Labels {
        kind,
        names: (0..6).map(|i| format!("P{}", 12 - i)).collect(),
        per_row,
    });
    rec
}

#[test]
fn a_hold_warning_names_the_label_text_and_column_the_table_shows() {
    for (kind, phrase) in [
        (LabelKind::Pose, "(pose P10)"),
        (LabelKind::Segment, "(segment P10)"),
    ] {
        let rec = labelled_with_a_spike(kind);
        let report = find_still(&rec, &StillOptions::default()).expect("holds");
        let sentences: Vec<String> = report
            .intervals
            .iter()
            .filter_map(|i| i.dropped_sentence())
            .collect();
        assert!(
            sentences.iter().any(|s| s.contains(phrase)),
            "{kind:?}: {sentences:?}"
        );
        assert!(
            sentences.iter().all(|s| !s.contains("(pose 2)")),
            "{sentences:?}"
        );
    }
}

#[test]
fn a_pose_column_without_time_or_rate_asks_for_the_rate_as_detection_does() {
    let (mut rec, _) = six_faces_labelled_by_pose(|i| i.to_string());
    rec.time = (0..rec.len()).map(|i| i as f64).collect();
    rec.time_is_index = true;
    let error = find_still(&rec, &StillOptions::default()).expect_err("row numbers are no seconds");
    assert!(matches!(error, StillError::NoRate(_)));
    assert!(error.to_string().contains("--rate"), "{error}");
}

#[test]
fn detection_without_a_rate_asks_for_one() {
    let (mut rec, _) = six_face_recording(1, 3.0);
    rec.time_is_index = true;
    let error = find_still(&rec, &StillOptions::default()).expect_err("no rate");
    assert!(matches!(error, StillError::NoRate(_)));
    assert!(error.to_string().contains("--rate"));
}

#[test]
fn chi_square_quantile_matches_tabulated_values() {
    // χ²(49) 0.999 quantile = 85.35, χ²(147) 0.999 = 206.6 (tables); Wilson–Hilferty is good to
    // well under 1% at these degrees of freedom.
    assert!((chi2_quantile_per_dof(0.999, 49.0) * 49.0 / 85.351 - 1.0).abs() < 0.005);
    assert!((chi2_quantile_per_dof(0.1, 49.0) * 49.0 / 36.818 - 1.0).abs() < 0.005);
}

#[test]
fn a_gyro_bias_of_several_degrees_per_second_does_not_stop_holds_being_still() {
    // MEMS gyroscope biases are specified up to several °/s; the rest bound judges how much the
    // rate varies within a window, never its mean.
    let (mut rec, truth) = six_face_recording(7, 5.0);
    let bias = Vec3::new(5.0, -4.0, 3.0).map(f64::to_radians);
    for w in rec.gyro.iter_mut().flatten() {
        *w += bias;
    }
    let report = find_still(&rec, &StillOptions::default()).expect("detection runs");
    assert!(report.rate_bound_applied);
    assert_eq!(report.intervals.len(), truth.len(), "{}", report.summary());
}

#[test]
fn a_board_held_by_a_swaying_hand_in_every_pose_is_never_still() {
    // Every hold of the synthetic set gets a 2 Hz sway of 4 °/s amplitude (2.8 °/s standard
    // deviation, above the 1.5 °/s rest bound): a hand holding the board, never at rest. The
    // relative test alone takes the quietest sway for the noise floor and accepts the holds.
    let (mut rec, truth) = six_face_recording(7, 5.0);
    let time = rec.time.clone();
    for (w, t) in rec.gyro.iter_mut().flatten().zip(&time) {
        if truth.iter().any(|(start, end, _)| t >= start && t < end) {
            let sway = 4.0f64.to_radians() * (2.0 * std::f64::consts::PI * 2.0 * t).sin();
            *w += Vec3::new(sway, -sway, 0.5 * sway);
        }
    }
    // Either no hold survives, or detection refuses outright because no window rests.
    match find_still(&rec, &StillOptions::default()) {
        Ok(report) => assert!(report.intervals.is_empty(), "{}", report.summary()),
        Err(e) => assert!(matches!(e, StillError::NeverAtRest { .. }), "{e}"),
    }
}
