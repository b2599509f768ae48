//! Sensor scales of an LSM9DS1-class part (±2 g, ±245 °/s, ±4 gauss, 100 Hz), shared by the
//! unit tests so that one fixture describes one sensor.

use imucal_protocol::SensorScales;

/// The scales the unit tests convert counts with.
pub(crate) fn lsm9ds1_like() -> SensorScales {
    SensorScales {
        accel_mps2_per_count: 0.000_598_5,
        gyro_rads_per_count: 0.000_152_7,
        mag_ut_per_count: 0.014,
        temp_c_per_count: 1.0 / 16.0,
        temp_offset_c: 25.0,
        accel_range_mps2: 19.6,
        gyro_range_rads: 4.36,
        mag_range_ut: 400.0,
        sample_rate_hz: 100.0,
    }
}
