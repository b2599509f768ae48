//! Shared by the history tests: the databases to run against (a fresh SQLite file always, a
//! fresh PostgreSQL database when `IMUCAL_TEST_PG_URL` names a server) and realistic records
//! of simulated boards.
#![allow(dead_code)]

use std::path::PathBuf;

use imucal::device::params_json::{ReferenceJson, ResidualsJson, SensorJson};
use imucal::device::{ParamsFile, PARAMS_FILE_FORMAT};
use imucal::history::{CalibrationRecord, DbLocation, RecordSource};
use imucal_hil_sim::physics::{ImuErrorRanges, ImuTruth, SensorTruth};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

/// Environment variable naming an administrative PostgreSQL URL (with a `?` query, e.g.
/// `postgres://postgres@/postgres?host=/tmp/pg&port=54329`); each test creates its own
/// database on that server.
pub const PG_ENV: &str = "IMUCAL_TEST_PG_URL";

/// A fresh directory for `test`.
pub fn scratch_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("imucal-history-{test}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch directory");
    dir
}

/// Fresh, empty databases for `test`: SQLite, and PostgreSQL when [`PG_ENV`] is set.
pub fn databases(test: &str) -> Vec<DbLocation> {
    let mut out = vec![DbLocation::Sqlite(scratch_dir(test).join("history.sqlite"))];
    if let Ok(admin) = std::env::var(PG_ENV) {
        // An unquoted SQL identifier: letters, digits and underscores only.
        let name: String = format!("imucal_{test}_{}", std::process::id())
            .to_lowercase()
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
            .collect();
        let mut client = postgres::Client::connect(&admin, postgres::NoTls)
            .unwrap_or_else(|e| panic!("{PG_ENV}={admin}: cannot connect: {e}"));
        client
            .batch_execute(&format!("DROP DATABASE IF EXISTS {name}"))
            .expect("drop old test database");
        client
            .batch_execute(&format!("CREATE DATABASE {name}"))
            .expect("create test database");
        let separator = if admin.contains('?') { '&' } else { '?' };
        out.push(DbLocation::Postgres(format!(
            "{admin}{separator}dbname={name}"
        )));
    }
    out
}

/// The URL of `location` as `--db` takes it.
pub fn url(location: &DbLocation) -> String {
    match location {
        DbLocation::Sqlite(path) => format!("sqlite://{}", path.display()),
        DbLocation::Postgres(url) => url.clone(),
    }
}

fn sensor(truth: &SensorTruth, sigma_b: f64, sigma_a: f64, rng: &mut impl Rng) -> SensorJson {
    // The fitted set is the truth plus the fit's own estimation error.
    let b = Normal::new(0.0, sigma_b).expect("σ > 0");
    let a = Normal::new(0.0, sigma_a).expect("σ > 0");
    SensorJson {
        a: truth.a_true.map(|row| row.map(|v| v + a.sample(rng))),
        b: truth.b_true.map(|v| v + b.sample(rng)),
        t_ref_c: Some(25.0),
        bias_temp: None,
        scale_temp: None,
        nonlinearity: None,
        input_unit: None,
    }
}

/// One-sigma fit uncertainties used for simulated records: accelerometer offset 1 mg and gain
/// 200 ppm, gyroscope offset 0.01 °/s, magnetometer offset 0.2 µT (a good guided session).
pub const SIGMA: [(&str, f64); 4] = [
    ("accel.b", 1e-3 * 9.806_65),
    ("accel.A", 2e-4),
    ("gyro.b", 1.745e-4),
    ("mag.b", 0.2),
];

/// A realistic record of the board drawn with `seed` by the simulator's truth generator (the
/// consumer-MEMS ranges of `ImuErrorRanges::default`), fitted with the uncertainties of
/// [`SIGMA`]. Noise varies ±15 % (log-normal) from part to part, as datasheet noise does.
pub fn board_record(seed: u64) -> CalibrationRecord {
    let truth = ImuTruth::draw(seed, &ImuErrorRanges::default(), &[], 100.0, 0.0)
        .expect("default ranges are valid");
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed ^ 0x5eed);
    let sigma = |prefix: &str| {
        SIGMA
            .iter()
            .find(|(p, _)| *p == prefix)
            .map_or(0.0, |s| s.1)
    };
    let params = ParamsFile {
        format: PARAMS_FILE_FORMAT,
        created_unix_s: 0,
        accel: sensor(&truth.accel, sigma("accel.b"), sigma("accel.A"), &mut rng),
        gyro: sensor(&truth.gyro, sigma("gyro.b"), 1e-4, &mut rng),
        mag: sensor(&truth.mag, sigma("mag.b"), 1e-3, &mut rng),
        gyro_g_sensitivity: None,
        reference: ReferenceJson {
            gravity_mps2: 9.806_65,
            field_ut: 48.5,
        },
        residuals: ResidualsJson {
            accel_rms: 0.01 * part_factor(&mut rng),
            gyro_rms: 0.0,
            mag_rms: 0.3 * part_factor(&mut rng),
        },
        not_fitted: Default::default(),
        device: None,
        absent_sensors: Vec::new(),
        provenance: None,
    };
    let device = format!("{seed:032x}");
    let mut record = CalibrationRecord::new(&device, RecordSource::Guided, params, seed as u32);
    for axis in ["x", "y", "z"] {
        record
            .sigma
            .insert(format!("accel.b.{axis}"), sigma("accel.b"));
        record
            .sigma
            .insert(format!("accel.A.{axis}{axis}"), sigma("accel.A"));
        record
            .sigma
            .insert(format!("gyro.b.{axis}"), sigma("gyro.b"));
        record.sigma.insert(format!("mag.b.{axis}"), sigma("mag.b"));
        for (name, s) in [
            ("accel", truth.accel.noise_sigma),
            ("gyro", truth.gyro.noise_sigma),
            ("mag", truth.mag.noise_sigma),
        ] {
            record
                .noise
                .insert(format!("{name}.noise.{axis}"), s * part_factor(&mut rng));
        }
    }
    record
}

/// Log-normal part-to-part factor, σ(ln) = 0.15.
fn part_factor(rng: &mut impl Rng) -> f64 {
    let z: f64 = Normal::new(0.0, 1.0).expect("σ > 0").sample(rng);
    (0.15 * z).exp()
}
