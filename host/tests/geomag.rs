//! The World Magnetic Model lookup against the official WMM2025 test values (WMM2025
//! Technical Report, Table 6), and the parsing of `--location`.

use imucal::geomag::{date_of_unix_seconds, local_field, Date, Location, Month, RadiusCheck};

/// (height km, latitude °, longitude °, F nT, I °, D °) on 2025-01-01 (decimal year 2025.0).
const WMM2025_TABLE_6: [(f64, f64, f64, f64, f64, f64); 6] = [
    (0.0, 80.0, 0.0, 55178.5, 83.21, 1.28),
    (0.0, 0.0, 120.0, 41064.3, -14.93, -0.16),
    (0.0, -80.0, -120.0, 54698.2, -72.00, 68.78),
    (100.0, 80.0, 0.0, 52964.9, 83.26, 0.85),
    (100.0, 0.0, 120.0, 39032.1, -15.08, -0.15),
    (100.0, -80.0, -120.0, 52035.0, -72.19, 68.21),
];

#[test]
fn field_matches_the_official_wmm2025_test_values() {
    let date = Date::from_calendar_date(2025, Month::January, 1).expect("valid date");
    for (height_km, lat, lon, f_nt, inc, dec) in WMM2025_TABLE_6 {
        let field = local_field(&Location::new(lat, lon, height_km * 1000.0).unwrap(), date)
            .expect("inside the model");
        // The table prints F to 0.1 nT and angles to 0.01°; the synthesis runs in f32
        // (7 digits of 55 000 nT ≈ 0.01 nT), so half the printed step plus f32 rounding.
        assert!(
            (field.total_ut * 1000.0 - f_nt).abs() < 0.1,
            "F at {lat},{lon},{height_km} km: {} nT, table {f_nt} nT",
            field.total_ut * 1000.0
        );
        assert!(
            (field.inclination_deg - inc).abs() < 0.01,
            "I {}",
            field.inclination_deg
        );
        assert!(
            (field.declination_deg - dec).abs() < 0.01,
            "D {}",
            field.declination_deg
        );
        assert_eq!(field.model, "WMM2025");
    }
}

#[test]
fn location_text_parses_with_and_without_altitude_and_refuses_bad_ranges() {
    let place: Location = "46.05,14.51,295".parse().unwrap();
    assert_eq!(place, Location::new(46.05, 14.51, 295.0).unwrap());
    let sea: Location = " -33.9 , 18.4 ".parse().unwrap();
    assert_eq!(sea.altitude_m, 0.0);
    let swapped = "14.51,200".parse::<Location>().unwrap_err().to_string();
    assert!(swapped.contains("longitude 200"), "{swapped}");
    let garbage = "Ljubljana".parse::<Location>().unwrap_err().to_string();
    assert!(garbage.contains("LAT,LON"), "{garbage}");
    assert!("91,0".parse::<Location>().is_err());
    assert!("0,0,900000".parse::<Location>().is_err());
}

#[test]
fn dates_outside_the_bundled_models_are_refused_with_a_way_out() {
    let date = Date::from_calendar_date(2031, Month::June, 1).unwrap();
    let error = local_field(&Location::new(0.0, 0.0, 0.0).unwrap(), date).unwrap_err();
    assert!(error.to_string().contains("--field-ut"), "{error}");
}

#[test]
fn radius_check_flags_a_gauss_reading_taken_for_microtesla() {
    let date = Date::from_calendar_date(2026, Month::March, 1).unwrap();
    let field = local_field(&"46.05,14.51".parse().unwrap(), date).unwrap();
    // Central Europe: about 48 µT (WMM2025 map); a wide bracket, the point is the check below.
    assert!((45.0..51.0).contains(&field.total_ut), "{}", field.total_ut);
    assert!(RadiusCheck::new(field.total_ut * 1.08, &field).plausible);
    let gauss_as_ut = RadiusCheck::new(field.total_ut / 100.0, &field);
    assert!(!gauss_as_ut.plausible);
    assert!(gauss_as_ut.sentence().contains("--mag-unit"));
}

#[test]
fn unix_time_maps_to_the_utc_calendar_date() {
    // 1 763 700 000 s = 20 413 days + 18 000 s after 1970-01-01: 2025-11-21 05:20 UTC.
    assert_eq!(
        date_of_unix_seconds(1_763_700_000),
        Date::from_calendar_date(2025, Month::November, 21).ok()
    );
    assert_eq!(
        date_of_unix_seconds(-1),
        Date::from_calendar_date(1969, Month::December, 31).ok()
    );
}

/// `calibrate --location` takes the magnetometer reference from the model and writes it into the
/// parameter set (f32 on the wire, hence the tolerance).
#[test]
fn calibrate_location_writes_the_modelled_field_as_the_reference() {
    let location: imucal::geomag::Location = "48.14,11.58".parse().expect("valid location");
    let field = imucal::geomag::local_field_today(&location)
        .expect("location inside the model")
        .total_ut;
    let dir = std::env::temp_dir().join(format!("imucal-location-{}", std::process::id()));
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args([
            "calibrate",
            "--sim",
            "--yes",
            "--json",
            "--speed",
            "30",
            "--no-history",
        ])
        .args(["--location", "48.14,11.58", "-o"])
        .arg(&dir)
        .output()
        .expect("run imucal");
    let _ = std::fs::remove_dir_all(&dir);
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "calibrate failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_str(&text).expect("summary JSON");
    let written = json["params"]["reference"]["field_ut"]
        .as_f64()
        .expect("reference field in the written set");
    assert!(
        (written - field).abs() < 1e-4 * field,
        "wrote {written} µT, model {field} µT"
    );
    assert_eq!(json["verified"], true);
    assert_eq!(json["field_source"], "given");
    // The fit's description names the field as the reference it was given, not as the user's.
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("µT (reference)"), "{stderr}");
}

/// Without `--field-ut` or `--location` a simulated session stands the simulated site's field in
/// for the one a user would look up; its summary says so rather than that a field was given.
#[test]
fn a_simulated_session_without_a_given_field_records_the_simulated_site_as_its_source() {
    let dir = std::env::temp_dir().join(format!("imucal-sim-site-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args([
            "calibrate",
            "--sim",
            "--yes",
            "--json",
            "--speed",
            "60",
            "--no-history",
            "-o",
        ])
        .arg(&dir)
        .output()
        .expect("run imucal");
    let saved = std::fs::read_to_string(dir.join("summary.json"));
    let _ = std::fs::remove_dir_all(&dir);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "calibrate failed: {stderr}");
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("summary JSON");
    assert_eq!(
        json["field_source"], "simulated_site",
        "{}",
        json["field_source"]
    );
    let saved: serde_json::Value =
        serde_json::from_str(&saved.expect("summary.json")).expect("summary.json is JSON");
    assert_eq!(saved["field_source"], "simulated_site");
    assert!(stderr.contains("µT (the simulated site's)"), "{stderr}");
}
