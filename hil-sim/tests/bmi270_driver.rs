//! The firmware's BMI270 + BMM150 driver against the register-level emulation: the init sequence
//! with the configuration load and INTERNAL_STATUS, then readings in the driver's scales.

use embedded_hal::delay::DelayNs;
use imucal_firmware::bmi270::{self, Bmi270Bmm150, Config, Error};
use imucal_firmware::imu::Imu;
use imucal_hil_sim::bmi270_chip::{Bmi270Chip, CONFIG_IMAGE_LEN};

/// The simulation's time does not advance during init.
struct NoDelay;
impl DelayNs for NoDelay {
    fn delay_ns(&mut self, _ns: u32) {}
}

/// A stand-in configuration image (Bosch's file is not shipped): any bytes the chip expects.
fn image() -> Vec<u8> {
    (0..CONFIG_IMAGE_LEN)
        .map(|i| (i * 7 + i / 256) as u8)
        .collect()
}

fn leaked(bytes: Vec<u8>) -> &'static [u8] {
    Box::leak(bytes.into_boxed_slice())
}

#[test]
fn driver_loads_the_configuration_and_reads_what_the_chip_senses() {
    let file = image();
    let mut chip = Bmi270Chip::new(&file);
    let config = Config {
        config_file: leaked(file),
        max_burst: 64,
    };
    let mut imu = Bmi270Bmm150::new(&mut chip, NoDelay, config);
    imu.init().expect("init succeeds");
    let (chip, _) = imu.release();
    assert_eq!(chip.internal_status(), bmi270::STATUS_INIT_OK);
    chip.set_physical(
        [0.5, -9.80665, 2.0],
        [0.1, -0.2, 1.5],
        [20.0, -35.5, 41.1],
        30.0,
    )
    .unwrap();
    let mut imu = Bmi270Bmm150::new(&mut *chip, NoDelay, config);
    // A fresh driver must init again before reading.
    assert_eq!(imu.read(), Err(Error::NotInitialised));
    imu.init().unwrap();
    let sample = imu.read().unwrap();
    let s = imu.scales();
    // Quantisation: half a count of each scale.
    let check = |counts: [i16; 3], per: f32, truth: [f64; 3]| {
        for i in 0..3 {
            let got = f64::from(counts[i]) * f64::from(per);
            assert!(
                (got - truth[i]).abs() <= 0.5 * f64::from(per) + 1e-9,
                "{got} vs {}",
                truth[i]
            );
        }
    };
    check(sample.accel, s.accel_mps2_per_count, [0.5, -9.80665, 2.0]);
    check(sample.gyro, s.gyro_rads_per_count, [0.1, -0.2, 1.5]);
    check(sample.mag, s.mag_ut_per_count, [20.0, -35.5, 41.1]);
    let temp = f64::from(s.temp_offset_c) + f64::from(sample.temp) * f64::from(s.temp_c_per_count);
    assert!((temp - 30.0).abs() < 1.0 / 512.0);
}

#[test]
fn wrong_configuration_file_is_reported_from_internal_status() {
    let mut chip = Bmi270Chip::new(&image());
    let mut wrong = image();
    wrong[100] ^= 0xFF;
    let config = Config {
        config_file: leaked(wrong),
        max_burst: 32,
    };
    let mut imu = Bmi270Bmm150::new(&mut chip, NoDelay, config);
    assert_eq!(imu.init(), Err(Error::ConfigLoadFailed { status: 0x02 }));
}

#[test]
fn bus_without_a_bmi270_fails_init_with_a_bus_error() {
    // An original (LSM9DS1) board: nothing answers at 0x68.
    let mut chip = imucal_hil_sim::lsm9ds1_chip::Lsm9ds1Chip::default();
    let config = Config {
        config_file: leaked(image()),
        max_burst: 64,
    };
    let mut imu = Bmi270Bmm150::new(&mut chip, NoDelay, config);
    assert!(matches!(imu.init(), Err(Error::Bus(_))));
}
