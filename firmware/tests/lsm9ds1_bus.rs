//! The LSM9DS1 driver against recorded I²C transactions: the exact init sequence, decoding of a
//! sample, the datasheet sensitivity table in SI units, and error paths.
//!
//! Expected register bytes are written out by hand from the datasheet bit fields, independently of
//! the driver's own tables.
// Register values are written with their bit fields grouped (e.g. ODR_FS_BW as 0b011_10_000).
#![allow(clippy::unusual_byte_groupings)]

use embedded_hal::i2c::{ErrorKind, NoAcknowledgeSource};
use embedded_hal_mock::eh1::i2c::{Mock as I2cMock, Transaction as I2cTransaction};
use imucal_firmware::imu::{Imu, RawSample};
use imucal_firmware::lsm9ds1::{
    AccelGyroDataRate, AccelRange, Config, Error, GyroRange, Lsm9ds1, MagAxes, MagDataRate,
    MagPerformance, MagRange, SdoLevel,
};

const AG: u8 = 0x6B;
const MAG: u8 = 0x1E;
const G: f64 = 9.806_65;
const DEG: f64 = std::f64::consts::PI / 180.0;

/// `f32` sensitivities come from a handful of `f32` products: a relative error of a few ulp.
const F32_RELATIVE_TOLERANCE: f64 = 1e-6;

fn assert_relative(actual: f32, expected: f64, what: &str) {
    let relative = (f64::from(actual) - expected).abs() / expected.abs();
    assert!(
        relative < F32_RELATIVE_TOLERANCE,
        "{what}: {actual} differs from {expected} by {relative:e} (relative)"
    );
}

fn who_am_i(ag_address: u8, mag_address: u8) -> Vec<I2cTransaction> {
    vec![
        I2cTransaction::write_read(ag_address, vec![0x0F], vec![0x68]),
        I2cTransaction::write_read(mag_address, vec![0x0F], vec![0x3D]),
    ]
}

/// Init transactions for the A/G and M devices, given the three configuration-dependent bytes of
/// each: (CTRL_REG6_XL, CTRL_REG1_G) and (CTRL_REG1_M, CTRL_REG2_M, CTRL_REG4_M).
fn init_sequence(
    ag_address: u8,
    mag_address: u8,
    ctrl_reg6_xl: u8,
    ctrl_reg1_g: u8,
    mag_ctrl: [u8; 3],
) -> Vec<I2cTransaction> {
    let [ctrl_reg1_m, ctrl_reg2_m, ctrl_reg4_m] = mag_ctrl;
    let mut t = who_am_i(ag_address, mag_address);
    t.extend([
        I2cTransaction::write(ag_address, vec![0x22, 0x44]), // CTRL_REG8: BDU | IF_ADD_INC
        I2cTransaction::write(ag_address, vec![0x23, 0x00]), // CTRL_REG9
        I2cTransaction::write(ag_address, vec![0x11, 0x00]), // CTRL_REG2_G
        I2cTransaction::write(ag_address, vec![0x12, 0x00]), // CTRL_REG3_G
        I2cTransaction::write(ag_address, vec![0x1E, 0x38]), // CTRL_REG4: gyro XYZ on
        I2cTransaction::write(ag_address, vec![0x1F, 0x38]), // CTRL_REG5_XL: accel XYZ on
        I2cTransaction::write(ag_address, vec![0x20, ctrl_reg6_xl]),
        I2cTransaction::write(ag_address, vec![0x21, 0x00]), // CTRL_REG7_XL
        I2cTransaction::write(ag_address, vec![0x10, ctrl_reg1_g]),
        I2cTransaction::write(mag_address, vec![0x20, ctrl_reg1_m]),
        I2cTransaction::write(mag_address, vec![0x21, ctrl_reg2_m]),
        I2cTransaction::write(mag_address, vec![0x22, 0x00]), // CTRL_REG3_M: continuous
        I2cTransaction::write(mag_address, vec![0x23, ctrl_reg4_m]),
        I2cTransaction::write(mag_address, vec![0x24, 0x40]), // CTRL_REG5_M: BDU
    ]);
    t
}

/// Default configuration: 119 Hz (011), ±4 g (FS_XL 10), ±500 °/s (FS_G 01); magnetometer
/// TEMP_COMP, ultra-high performance (11), 80 Hz (111), ±4 gauss (00).
fn default_init_sequence() -> Vec<I2cTransaction> {
    init_sequence(
        AG,
        MAG,
        0b011_10_000,
        0b011_01_000,
        [0b1_11_111_00, 0x00, 0b11_00],
    )
}

/// A sample burst: temperature+status+gyroscope, accelerometer, magnetometer (with bit 7).
fn sample_reads(temp_status_gyro: [u8; 9], accel: [u8; 6], mag: [u8; 6]) -> Vec<I2cTransaction> {
    vec![
        I2cTransaction::write_read(AG, vec![0x15], temp_status_gyro.to_vec()),
        I2cTransaction::write_read(AG, vec![0x28], accel.to_vec()),
        // STATUS_REG_M (0x27, ZYXDA set) then the axes, one auto-incremented burst.
        I2cTransaction::write_read(MAG, vec![0xA7], [&[0x08][..], &mag[..]].concat()),
    ]
}

/// Temperature −16 (0xFFF0), status 0x07, gyro (0x1234, −2, 32767).
const TEMP_STATUS_GYRO: [u8; 9] = [0xF0, 0xFF, 0x07, 0x34, 0x12, 0xFE, 0xFF, 0xFF, 0x7F];
/// Accelerometer (1000, −1000, 8192).
const ACCEL: [u8; 6] = [0xE8, 0x03, 0x18, 0xFC, 0x00, 0x20];
/// Magnetometer (−32768, 258, −300).
const MAG_BYTES: [u8; 6] = [0x00, 0x80, 0x02, 0x01, 0xD4, 0xFE];

#[test]
fn init_checks_both_ids_then_writes_the_datasheet_configuration() {
    let config = Config {
        accel_range: AccelRange::G8,
        gyro_range: GyroRange::Dps2000,
        mag_range: MagRange::Gauss12,
        accel_gyro_rate: AccelGyroDataRate::Hz238,
        mag_rate: MagDataRate::Hz40,
        mag_performance: MagPerformance::High,
        ..Config::default()
    };
    // ODR 238 Hz = 100, FS_XL 8 g = 11, FS_G 2000 °/s = 11; TEMP_COMP | OM 10 | DO 110,
    // FS 12 gauss = 10, OMZ 10.
    let expectations = init_sequence(
        AG,
        MAG,
        0b100_11_000,
        0b100_11_000,
        [0b1_10_110_00, 0b0_10_00000, 0b10_00],
    );
    let mut bus = I2cMock::new(&expectations);
    let mut imu = Lsm9ds1::new(bus.clone(), config);
    assert_eq!(imu.init(), Ok(()));
    bus.done();
}

#[test]
fn init_uses_the_sdo_low_addresses_and_the_non_monotonic_16_g_code() {
    let config = Config {
        accel_range: AccelRange::G16,
        gyro_range: GyroRange::Dps245,
        mag_range: MagRange::Gauss16,
        accel_gyro_rate: AccelGyroDataRate::Hz14_9,
        mag_rate: MagDataRate::Hz0_625,
        mag_performance: MagPerformance::LowPower,
        sdo_accel_gyro: SdoLevel::Low,
        sdo_mag: SdoLevel::Low,
        ..Config::default()
    };
    // ODR 14.9 Hz = 001, FS_XL 16 g = 01 (not 11), FS_G 245 °/s = 00; TEMP_COMP | OM 00 | DO 000,
    // FS 16 gauss = 11, OMZ 00.
    let expectations = init_sequence(
        0x6A,
        0x1C,
        0b001_01_000,
        0b001_00_000,
        [0b1_00_000_00, 0b0_11_00000, 0b00_00],
    );
    let mut bus = I2cMock::new(&expectations);
    let mut imu = Lsm9ds1::new(bus.clone(), config);
    assert_eq!(imu.init(), Ok(()));
    bus.done();
}

#[test]
fn default_init_matches_the_nano_33_ble_sense_sequence() {
    let expectations = default_init_sequence();
    let mut bus = I2cMock::new(&expectations);
    let mut imu = Lsm9ds1::new(bus.clone(), Config::default());
    assert_eq!(imu.init(), Ok(()));
    bus.done();
}

#[test]
fn read_decodes_little_endian_counts_and_aligns_mag_x_to_the_accel_gyro_frame() {
    let mut expectations = default_init_sequence();
    expectations.extend(sample_reads(TEMP_STATUS_GYRO, ACCEL, MAG_BYTES));
    let mut bus = I2cMock::new(&expectations);
    let mut imu = Lsm9ds1::new(bus.clone(), Config::default());
    imu.init().expect("init against the recorded bus");
    let sample = imu.read().expect("read against the recorded bus");
    assert_eq!(
        sample,
        RawSample {
            accel: [1000, -1000, 8192],
            gyro: [0x1234, -2, 32767],
            // −(−32768) does not fit an i16: the negation saturates at +32767.
            mag: [32767, 258, -300],
            temp: -16,
        }
    );
    // −16 counts at 16 counts/°C below the 25 °C zero point.
    let scales = imu.scales();
    let temp_c = scales.temp_offset_c + f32::from(sample.temp) * scales.temp_c_per_count;
    assert_relative(temp_c, 24.0, "temperature");
    bus.done();
}

#[test]
fn raw_mag_axes_keep_the_chip_x_sign() {
    let config = Config {
        mag_axes: MagAxes::Raw,
        ..Config::default()
    };
    let mut expectations = default_init_sequence();
    expectations.extend(sample_reads(TEMP_STATUS_GYRO, ACCEL, MAG_BYTES));
    let mut bus = I2cMock::new(&expectations);
    let mut imu = Lsm9ds1::new(bus.clone(), config);
    imu.init().expect("init against the recorded bus");
    let sample = imu.read().expect("read against the recorded bus");
    assert_eq!(sample.mag, [-32768, 258, -300]);
    bus.done();
}

#[test]
fn scales_match_the_datasheet_sensitivity_table_in_si_units() {
    let accel = [(2.0, 0.061), (4.0, 0.122), (8.0, 0.244), (16.0, 0.732)];
    let gyro = [(245.0, 8.75), (500.0, 17.50), (2000.0, 70.0)];
    let mag = [(4.0, 0.14), (8.0, 0.29), (12.0, 0.43), (16.0, 0.58)];
    for (range, (full_scale_g, mg_per_count)) in AccelRange::ALL.into_iter().zip(accel) {
        let scales = Config {
            accel_range: range,
            ..Config::default()
        }
        .scales();
        assert_relative(
            scales.accel_mps2_per_count,
            mg_per_count * 1e-3 * G,
            "accel sensitivity",
        );
        assert_relative(scales.accel_range_mps2, full_scale_g * G, "accel range");
    }
    for (range, (full_scale_dps, mdps_per_count)) in GyroRange::ALL.into_iter().zip(gyro) {
        let scales = Config {
            gyro_range: range,
            ..Config::default()
        }
        .scales();
        assert_relative(
            scales.gyro_rads_per_count,
            mdps_per_count * 1e-3 * DEG,
            "gyro sensitivity",
        );
        assert_relative(scales.gyro_range_rads, full_scale_dps * DEG, "gyro range");
    }
    for (range, (full_scale_gauss, mgauss_per_count)) in MagRange::ALL.into_iter().zip(mag) {
        let scales = Config {
            mag_range: range,
            ..Config::default()
        }
        .scales();
        // 1 gauss = 100 µT.
        assert_relative(
            scales.mag_ut_per_count,
            mgauss_per_count * 0.1,
            "mag sensitivity",
        );
        assert_relative(scales.mag_range_ut, full_scale_gauss * 100.0, "mag range");
    }
    let scales = Config::default().scales();
    assert_relative(
        scales.temp_c_per_count,
        1.0 / 16.0,
        "temperature sensitivity",
    );
    assert_relative(scales.temp_offset_c, 25.0, "temperature offset");
    assert_relative(scales.sample_rate_hz, 119.0, "sample rate");
}

#[test]
fn wrong_accel_gyro_who_am_i_is_an_error_and_nothing_is_written() {
    let expectations = [I2cTransaction::write_read(AG, vec![0x0F], vec![0x69])];
    let mut bus = I2cMock::new(&expectations);
    let mut imu = Lsm9ds1::new(bus.clone(), Config::default());
    let error = imu.init().expect_err("0x69 is not the LSM9DS1");
    assert_eq!(
        error,
        Error::WrongAccelGyroId {
            address: AG,
            found: 0x69
        }
    );
    let message = error.to_string();
    assert!(
        message.contains("0x69") && message.contains("SDO_A/G"),
        "{message}"
    );
    // A failed init leaves the driver refusing to read.
    assert_eq!(imu.read(), Err(Error::NotInitialised));
    bus.done();
}

#[test]
fn wrong_mag_who_am_i_is_an_error_and_nothing_is_written() {
    let expectations = [
        I2cTransaction::write_read(AG, vec![0x0F], vec![0x68]),
        I2cTransaction::write_read(MAG, vec![0x0F], vec![0x00]),
    ];
    let mut bus = I2cMock::new(&expectations);
    let mut imu = Lsm9ds1::new(bus.clone(), Config::default());
    assert_eq!(
        imu.init(),
        Err(Error::WrongMagId {
            address: MAG,
            found: 0x00
        })
    );
    bus.done();
}

#[test]
fn bus_error_during_init_propagates() {
    let nack = ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address);
    let expectations = [I2cTransaction::write_read(AG, vec![0x0F], vec![0x00]).with_error(nack)];
    let mut bus = I2cMock::new(&expectations);
    let mut imu = Lsm9ds1::new(bus.clone(), Config::default());
    assert_eq!(imu.init(), Err(Error::Bus(nack)));
    bus.done();
}

#[test]
fn bus_error_during_a_sample_read_propagates() {
    let mut expectations = default_init_sequence();
    expectations.extend([
        I2cTransaction::write_read(AG, vec![0x15], TEMP_STATUS_GYRO.to_vec()),
        I2cTransaction::write_read(AG, vec![0x28], vec![0; 6]).with_error(ErrorKind::Bus),
    ]);
    let mut bus = I2cMock::new(&expectations);
    let mut imu = Lsm9ds1::new(bus.clone(), Config::default());
    imu.init().expect("init against the recorded bus");
    assert_eq!(imu.read(), Err(Error::Bus(ErrorKind::Bus)));
    bus.done();
}

#[test]
fn read_before_init_is_refused_without_bus_traffic() {
    let mut bus = I2cMock::new(&[]);
    let mut imu = Lsm9ds1::new(bus.clone(), Config::default());
    assert_eq!(imu.read(), Err(Error::NotInitialised));
    bus.done();
}
