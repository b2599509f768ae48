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
