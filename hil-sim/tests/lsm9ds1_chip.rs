//! The real LSM9DS1 driver from imucal-firmware against the emulated chip: values set on the chip
//! come back through the driver's counts and scales at every full scale, saturation clamps, and
//! the emulated bus behaves like the chip's (addresses, auto-increment rules, protected registers).
//!
//! The emulation has its own copy of the datasheet tables, so these tests also cross-check the
//! driver's register encodings and sensitivities against it.
// Register values are written with their bit fields grouped (e.g. ODR_FS_BW as 0b011_10_000).
#![allow(clippy::unusual_byte_groupings)]

use embedded_hal::i2c::{Error as _, ErrorKind, I2c, NoAcknowledgeSource};
use imucal_firmware::imu::{Imu, RawSample, SensorScales};
use imucal_firmware::lsm9ds1::{
    AccelRange, Config, Error, GyroRange, Lsm9ds1, MagAxes, MagRange, SdoLevel,
};
use imucal_hil_sim::lsm9ds1_chip::{Lsm9ds1Chip, Lsm9ds1ChipError};

const G: f64 = 9.806_65;
const DEG: f64 = std::f64::consts::PI / 180.0;

/// Rounding to the nearest count leaves at most half a count; the driver's `f32` sensitivity adds
/// a relative error below 1e-6, i.e. under 0.04 count at 32768 counts.
const READBACK_TOLERANCE_COUNTS: f64 = 0.5 + 0.04;

/// Fractions of full scale used as inputs: near both ends, mid-range and small, with digits that
/// do not land on count boundaries.
const FRACTIONS: [[f64; 3]; 2] = [[0.9987, -0.4321, 0.0123], [-0.9991, 0.6173, -0.000_37]];

fn full_scales(config: &Config) -> (f64, f64, f64) {
    (
        config.accel_range.full_scale_g() as f64 * G,
        config.gyro_range.full_scale_dps() as f64 * DEG,
        config.mag_range.full_scale_gauss() as f64 * 100.0,
    )
}

fn read_through_driver(chip: &mut Lsm9ds1Chip, config: Config) -> (RawSample, SensorScales) {
    let mut imu = Lsm9ds1::new(chip, config);
    imu.init()
        .expect("the emulated chip accepts the driver's init");
    let sample = imu.read().expect("the emulated chip answers a sample read");
    (sample, imu.scales())
}

fn assert_within_counts(actual_counts: i16, per_count: f32, expected: f64, what: &str) {
    let actual = f64::from(actual_counts) * f64::from(per_count);
    let error_counts = (actual - expected).abs() / f64::from(per_count);
    assert!(
        error_counts <= READBACK_TOLERANCE_COUNTS,
        "{what}: read {actual} for {expected} ({error_counts:.3} counts off)"
    );
}

#[test]
fn driver_reads_back_what_was_set_within_half_a_count_at_every_full_scale() {
    for accel_range in AccelRange::ALL {
        for gyro_range in GyroRange::ALL {
            for mag_range in MagRange::ALL {
                let config = Config {
                    accel_range,
                    gyro_range,
                    mag_range,
                    ..Config::default()
                };
                let (accel_fs, gyro_fs, mag_fs) = full_scales(&config);
                for (fractions, temp_c) in FRACTIONS.into_iter().zip([31.3, -7.77]) {
                    let accel = fractions.map(|f| f * accel_fs);
                    let gyro = fractions.map(|f| f * gyro_fs);
                    let mag = fractions.map(|f| f * mag_fs);
                    let mut chip = Lsm9ds1Chip::default();
                    chip.set_physical(accel, gyro, mag, temp_c)
                        .expect("finite inputs");
                    let (sample, scales) = read_through_driver(&mut chip, config);
                    let what = format!("{config:?}");
                    for axis in 0..3 {
                        assert_within_counts(
                            sample.accel[axis],
                            scales.accel_mps2_per_count,
                            accel[axis],
                            &format!("accel[{axis}] {what}"),
                        );
                        assert_within_counts(
                            sample.gyro[axis],
                            scales.gyro_rads_per_count,
                            gyro[axis],
                            &format!("gyro[{axis}] {what}"),
                        );
                        assert_within_counts(
                            sample.mag[axis],
                            scales.mag_ut_per_count,
                            mag[axis],
                            &format!("mag[{axis}] {what}"),
                        );
                    }
                    let temp_read = f64::from(scales.temp_offset_c)
                        + f64::from(sample.temp) * f64::from(scales.temp_c_per_count);
                    // Half a count of 1/16 °C.
                    assert!(
                        (temp_read - temp_c).abs() <= 0.5 / 16.0,
                        "temperature {temp_read} for {temp_c}"
                    );
                }
            }
        }
    }
}

#[test]
fn raw_mag_axes_report_the_chip_x_opposite_to_the_accel_gyro_x() {
    let config = Config {
        mag_axes: MagAxes::Raw,
        ..Config::default()
    };
    let field_ut = [21.7, -4.2, 43.9];
    let mut chip = Lsm9ds1Chip::default();
    chip.set_physical([0.0, 0.0, G], [0.0; 3], field_ut, 25.0)
        .expect("finite inputs");
    let (sample, scales) = read_through_driver(&mut chip, config);
    let expected = [-field_ut[0], field_ut[1], field_ut[2]];
    for (counts, field) in sample.mag.into_iter().zip(expected) {
        assert_within_counts(counts, scales.mag_ut_per_count, field, "raw mag");
    }
}

/// Saturation count of a full scale: the nominal range in counts, within the 16-bit limits.
fn saturation_counts(full_scale: f64, per_count: f64) -> (i16, i16) {
    let limit = (full_scale / per_count).round();
    (
        limit.min(f64::from(i16::MAX)) as i16,
        (-limit).max(f64::from(i16::MIN)) as i16,
    )
}

#[test]
fn saturation_clamps_at_the_full_scale_or_the_16_bit_limit() {
    // Datasheet table 3, written here independently of both the driver and the emulation.
    let accel = [(2.0, 0.061), (4.0, 0.122), (8.0, 0.244), (16.0, 0.732)];
    let gyro = [(245.0, 8.75), (500.0, 17.50), (2000.0, 70.0)];
    let mag = [(4.0, 0.14), (8.0, 0.29), (12.0, 0.43), (16.0, 0.58)];
    for (i, accel_range) in AccelRange::ALL.into_iter().enumerate() {
        let gyro_index = i.min(GyroRange::ALL.len() - 1);
        let config = Config {
            accel_range,
            gyro_range: GyroRange::ALL[gyro_index],
            mag_range: MagRange::ALL[i],
            ..Config::default()
        };
        let (accel_fs_g, accel_mg) = accel[i];
        let (gyro_fs_dps, gyro_mdps) = gyro[gyro_index];
        let (mag_fs_gauss, mag_mgauss) = mag[i];
        let accel_limits = saturation_counts(accel_fs_g, accel_mg * 1e-3);
        let gyro_limits = saturation_counts(gyro_fs_dps, gyro_mdps * 1e-3);
        let mag_limits = saturation_counts(mag_fs_gauss, mag_mgauss * 1e-3);

        // Three times full scale, positive on X and Z and negative on Y; mag X sensed negated.
        let over = [3.0, -3.0, 3.0];
        let mut chip = Lsm9ds1Chip::default();
        chip.set_physical(
            over.map(|s| s * accel_fs_g * G),
            over.map(|s| s * gyro_fs_dps * DEG),
            over.map(|s| s * mag_fs_gauss * 100.0),
            400.0,
        )
        .expect("finite inputs");
        let raw = Config {
            mag_axes: MagAxes::Raw,
            ..config
        };
        let (sample, _) = read_through_driver(&mut chip, raw);
        let (high, low) = accel_limits;
        assert_eq!(sample.accel, [high, low, high], "{config:?}");
        let (high, low) = gyro_limits;
        assert_eq!(sample.gyro, [high, low, high], "{config:?}");
        let (high, low) = mag_limits;
        assert_eq!(sample.mag, [low, low, high], "{config:?}");
        // 12-bit temperature output.
        assert_eq!(sample.temp, 2047);
    }
}

#[test]
fn full_scale_16_g_saturates_at_16_g_not_at_the_16_bit_limit() {
    let config = Config {
        accel_range: AccelRange::G16,
        ..Config::default()
    };
    let mut chip = Lsm9ds1Chip::default();
    chip.set_physical([20.0 * G, -20.0 * G, 0.0], [0.0; 3], [0.0; 3], 25.0)
        .expect("finite inputs");
    let (sample, scales) = read_through_driver(&mut chip, config);
    // 0.732 mg/count puts 16 g at 21858 counts, far below 32767.
    for (axis, sign) in [(0, 1.0), (1, -1.0)] {
        assert_within_counts(
            sample.accel[axis],
            scales.accel_mps2_per_count,
            sign * f64::from(scales.accel_range_mps2),
            "16 g saturation",
        );
    }
}

#[test]
fn driver_with_the_wrong_sdo_level_gets_no_acknowledge() {
    let mut chip = Lsm9ds1Chip::default();
    let config = Config {
        sdo_accel_gyro: SdoLevel::Low,
        ..Config::default()
    };
    let mut imu = Lsm9ds1::new(&mut chip, config);
    let error = imu.init().expect_err("nothing answers at 0x6A");
    assert_eq!(
        error,
        Error::Bus(Lsm9ds1ChipError::NoDeviceAtAddress { address: 0x6A })
    );
    let Error::Bus(bus_error) = error else {
        unreachable!("matched above")
    };
    assert_eq!(
        bus_error.kind(),
        ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address)
    );
}

#[test]
fn chip_at_the_sdo_low_addresses_works_with_the_matching_driver() {
    let mut chip = Lsm9ds1Chip::new(SdoLevel::Low, SdoLevel::Low);
    chip.set_physical([0.0, 0.0, G], [0.1, 0.0, 0.0], [20.0, 0.0, 40.0], 25.0)
        .expect("finite inputs");
    let config = Config {
        sdo_accel_gyro: SdoLevel::Low,
        sdo_mag: SdoLevel::Low,
        ..Config::default()
    };
    let (sample, scales) = read_through_driver(&mut chip, config);
    assert_within_counts(sample.accel[2], scales.accel_mps2_per_count, G, "accel z");
    assert_within_counts(sample.mag[0], scales.mag_ut_per_count, 20.0, "mag x");
}

#[test]
fn outputs_read_zero_until_init_powers_the_sensors_up() {
    let mut chip = Lsm9ds1Chip::default();
    chip.set_physical([1.0, 2.0, 3.0], [0.1, 0.2, 0.3], [10.0, 20.0, 30.0], 40.0)
        .expect("finite inputs");
    let mut bytes = [0xAAu8; 6];
    chip.write_read(0x6B, &[0x28], &mut bytes).expect("ack");
    assert_eq!(bytes, [0; 6], "accelerometer powered down at reset");
    chip.write_read(0x1E, &[0xA8], &mut bytes).expect("ack");
    assert_eq!(bytes, [0; 6], "magnetometer in power-down at reset");
    assert_eq!(chip.accel_gyro_rate_hz(), None);
    assert_eq!(chip.mag_rate_hz(), None);

    Lsm9ds1::new(&mut chip, Config::default())
        .init()
        .expect("init");
    assert_eq!(chip.accel_gyro_rate_hz(), Some(119.0));
    assert_eq!(chip.mag_rate_hz(), Some(80.0));
    chip.write_read(0x6B, &[0x28], &mut bytes).expect("ack");
    assert_ne!(bytes, [0; 6]);
}

#[test]
fn mag_multi_byte_read_advances_only_with_bit_7_of_the_sub_address() {
    let mut chip = Lsm9ds1Chip::default();
    chip.set_physical([0.0; 3], [0.0; 3], [-30.0, 20.0, 10.0], 25.0)
        .expect("finite inputs");
    Lsm9ds1::new(&mut chip, Config::default())
        .init()
        .expect("init");
    let mut with_bit = [0u8; 6];
    chip.write_read(0x1E, &[0xA8], &mut with_bit).expect("ack");
    let mut without_bit = [0u8; 6];
    chip.write_read(0x1E, &[0x28], &mut without_bit)
        .expect("ack");
    assert_eq!(without_bit, [with_bit[0]; 6], "pointer stays on OUT_X_L_M");
    // −30 µT on the A/G X is +30 µT on the element's X: 30 / 0.014 µT per count.
    let x = i16::from_le_bytes([with_bit[0], with_bit[1]]);
    assert_eq!(x, (30.0f64 / 0.014).round() as i16);
}

#[test]
fn accel_gyro_multi_byte_read_advances_only_with_if_add_inc() {
    let mut chip = Lsm9ds1Chip::default();
    chip.set_physical([1.0, 2.0, 3.0], [0.0; 3], [0.0; 3], 25.0)
        .expect("finite inputs");
    Lsm9ds1::new(&mut chip, Config::default())
        .init()
        .expect("init");
    // CTRL_REG8 = BDU only: IF_ADD_INC off.
    chip.write(0x6B, &[0x22, 0x40]).expect("ack");
    let mut bytes = [0u8; 6];
    chip.write_read(0x6B, &[0x28], &mut bytes).expect("ack");
    assert_eq!(bytes, [bytes[0]; 6]);
}

#[test]
fn writes_to_reserved_read_only_or_unavailable_settings_are_refused() {
    let mut chip = Lsm9ds1Chip::default();
    assert_eq!(
        chip.write(0x6B, &[0x25, 0x00]),
        Err(Lsm9ds1ChipError::ReservedRegisterWrite {
            address: 0x6B,
            register: 0x25
        })
    );
    assert_eq!(
        chip.write(0x1E, &[0x0F, 0x00]),
        Err(Lsm9ds1ChipError::ReadOnlyRegisterWrite {
            address: 0x1E,
            register: 0x0F
        })
    );
    // FS_G = 10 is "n.a." in the datasheet.
    assert_eq!(
        chip.write(0x6B, &[0x10, 0b011_10_000]),
        Err(Lsm9ds1ChipError::UnavailableSetting {
            address: 0x6B,
            register: 0x10,
            value: 0b011_10_000
        })
    );
    assert_eq!(
        chip.register(0x6B, 0x10),
        Some(0),
        "refused value not stored"
    );
    assert_eq!(chip.register(0x6B, 0x0F), Some(0x68));
    assert_eq!(chip.register(0x1E, 0x0F), Some(0x3D));
}

#[test]
fn soft_resets_restore_the_power_on_registers() {
    let mut chip = Lsm9ds1Chip::default();
    Lsm9ds1::new(&mut chip, Config::default())
        .init()
        .expect("init");
    assert_ne!(chip.register(0x6B, 0x10), Some(0));
    chip.write(0x6B, &[0x22, 0x01]).expect("SW_RESET");
    assert_eq!(chip.register(0x6B, 0x10), Some(0));
    assert_eq!(chip.register(0x6B, 0x22), Some(0x04));
    chip.write(0x1E, &[0x21, 0x04]).expect("SOFT_RST");
    assert_eq!(chip.register(0x1E, 0x22), Some(0x03));
}

#[test]
fn mag_offset_registers_are_subtracted_from_the_output() {
    let mut chip = Lsm9ds1Chip::default();
    // +14 µT on the element's X (A/G X negated) is 1000 counts at 0.014 µT per count.
    chip.set_physical([0.0; 3], [0.0; 3], [-14.0, 0.0, 0.0], 25.0)
        .expect("finite inputs");
    Lsm9ds1::new(&mut chip, Config::default())
        .init()
        .expect("init");
    // OFFSET_X_REG_M = 250 counts, written with the auto-increment bit.
    chip.write(0x1E, &[0x85, 250, 0]).expect("offset write");
    let mut bytes = [0u8; 2];
    chip.write_read(0x1E, &[0xA8], &mut bytes).expect("ack");
    assert_eq!(i16::from_le_bytes(bytes), 1000 - 250);
}

#[test]
fn non_finite_physical_input_is_rejected_and_leaves_the_state() {
    let mut chip = Lsm9ds1Chip::default();
    Lsm9ds1::new(&mut chip, Config::default())
        .init()
        .expect("init");
    chip.set_physical([0.0; 3], [0.2, 0.0, 0.0], [0.0; 3], 25.0)
        .expect("finite inputs");
    let gyro_x_low = chip.register(0x6B, 0x18);
    let error = chip
        .set_physical([0.0; 3], [f64::NAN, 0.0, 0.0], [0.0; 3], 25.0)
        .expect_err("NaN is not a rate");
    assert_eq!(error.quantity, "gyroscope");
    let error = chip
        .set_physical([0.0; 3], [0.0; 3], [0.0; 3], f64::INFINITY)
        .expect_err("infinity is not a temperature");
    assert!(error.to_string().contains("temperature"));
    assert_eq!(chip.register(0x6B, 0x18), gyro_x_low);
}
