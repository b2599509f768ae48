//! The magnetometer's verdict weighs its residual against its noise, estimated from the stream
//! itself (the χ² of the residual's means over short windows against their standard errors): a
//! recording whose residual is its noise is said to be at the floor, and one whose field
//! changed half way (the board moved near iron) is said to miss something, however many samples
//! agree with the held-out error.

use std::f64::consts::PI;
use std::process::Command;

use imucal::fit::Vec3;
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

const FIELD_UT: f64 = 50.0;
const RATE_HZ: f64 = 100.0;
const NOISE_UT: f64 = 0.4;

/// A hand tumbling the board for 200 s over the whole sphere, read through a soft- and
/// hard-iron distortion with `noise` µT per axis; from half way the hard iron is offset by
/// `shift` more.
fn tumble_csv(shift: Vec3) -> String {
    let mut rng = StdRng::seed_from_u64(3);
    let noise = Normal::new(0.0, NOISE_UT).expect("valid sigma");
    let scale = Vec3::new(1.1, 0.95, 1.02);
    let offset = Vec3::new(20.0, -15.0, 30.0);
    let rows = (200.0 * RATE_HZ) as usize;
    let mut out = String::from("t_s,mx,my,mz\n");
    for i in 0..rows {
        let t = i as f64 / RATE_HZ;
        let polar = PI * (0.5 + 0.48 * (2.0 * PI * t / 67.0).sin());
        let azimuth = 2.0 * PI * t / 7.3;
        let d = Vec3::new(
            polar.sin() * azimuth.cos(),
            polar.sin() * azimuth.sin(),
            polar.cos(),
        );
        let hard = if i < rows / 2 { offset } else { offset + shift };
        let m = (d * FIELD_UT).component_mul(&scale)
            + hard
            + Vec3::from_fn(|_, _| noise.sample(&mut rng));
        out.push_str(&format!("{t:.2},{:.4},{:.4},{:.4}\n", m.x, m.y, m.z));
    }
    out
}

fn mag_verdict(name: &str, csv: &str) -> String {
    let path = std::env::temp_dir().join(format!(
        "imucal-mag-noise-{}-{name}.csv",
        std::process::id()
    ));
    std::fs::write(&path, csv).expect("scratch file");
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(["fit", "--json", "--mag-unit", "ut"])
        .arg(&path)
        .output()
        .expect("the binary runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    json["mag"]["verdict"]
        .as_str()
        .expect("a magnetometer verdict")
        .to_string()
}

#[test]
fn a_magnetometer_fitted_to_its_noise_is_at_the_floor_and_a_field_that_moved_half_way_is_not() {
    // The norm residual of a sample is its noise along the field, 0.4 µT of 50 µT: the fit
    // leaves that and no more, so the windows' means scatter as their standard errors say.
    let steady = mag_verdict("steady", &tumble_csv(Vec3::zeros()));
    assert!(
        steady.contains("residual is at the noise floor"),
        "{steady}"
    );
    // 10 µT of hard iron more from half way: the best single ellipsoid splits the difference
    // and leaves a residual far above the noise of 20-sample means.
    let moved = mag_verdict("moved", &tumble_csv(Vec3::new(10.0, 0.0, 0.0)));
    assert!(
        moved.contains("× the noise of its 20-sample means")
            && moved.contains("the model misses something"),
        "{moved}"
    );
    assert!(moved.contains("held-out error agrees"), "{moved}");
}
