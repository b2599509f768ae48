//! The units of the real recordings in `data/real/` (from each set's provenance note), shared by
//! the examples that run over all of them.

use imucal::recording::{AccelUnit, GyroUnit, MagUnit, Units};

/// Units of the known sets (from each set's provenance note); unknown files are read as SI.
pub fn units_of(name: &str) -> Units {
    let (accel, gyro, mag) = if name.starts_with("imutk_")
        || name.starts_with("tsi_")
        || name.starts_with("imucal_ferraris_raw")
    {
        (AccelUnit::Counts, GyroUnit::Counts, MagUnit::Ut)
    } else if name.starts_with("imucal_nilspod") {
        (AccelUnit::Mps2, GyroUnit::Dps, MagUnit::Ut)
    } else if name.starts_with("sf_") {
        (AccelUnit::G, GyroUnit::Dps, MagUnit::Gauss)
    } else if name.starts_with("tsm_") {
        (AccelUnit::Mps2, GyroUnit::Rads, MagUnit::Counts)
    } else if name.starts_with("fusion_") {
        (AccelUnit::G, GyroUnit::Dps, MagUnit::Ut)
    } else if name.starts_with("ck_") {
        (AccelUnit::G, GyroUnit::Rads, MagUnit::Gauss)
    } else {
        (AccelUnit::Mps2, GyroUnit::Rads, MagUnit::Ut)
    };
    Units { accel, gyro, mag }
}

/// Gyroscope counts to rad/s for the sets stored in counts (documented sensitivities: Xsens
/// 1/6258 rad/s per count, MPU-6050 at ±250 °/s (π/180)/131, MaD-Lab raw (π/180)/16.4).
pub fn gyro_counts_to_rads(name: &str) -> Option<f64> {
    let dps = std::f64::consts::PI / 180.0;
    if name.starts_with("imutk_") {
        Some(1.0 / 6258.0)
    } else if name.starts_with("tsi_") {
        Some(dps / 131.0)
    } else if name.starts_with("imucal_ferraris_raw") {
        Some(dps / 16.4)
    } else {
        None
    }
}
