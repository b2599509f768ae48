use super::*;
use crate::params::{BiasTemperature, Nonlinearity};
use std::string::ToString;

fn scales() -> SensorScales {
    SensorScales::EXAMPLE_LSM9DS1
}

fn diag(x: f32, y: f32, z: f32) -> [[f32; 3]; 3] {
    [[x, 0.0, 0.0], [0.0, y, 0.0], [0.0, 0.0, z]]
}

/// Makes a valid set invalid.
type Corruption = fn(&mut CalibrationSet);

fn reject(corrupt: Corruption) -> Option<InvalidParamsReason> {
    let mut set = CalibrationSet::identity();
    corrupt(&mut set);
    validate(&set, &scales()).err()
}

#[test]
fn identity_and_a_realistic_set_pass() {
    assert_eq!(validate(&CalibrationSet::identity(), &scales()), Ok(()));
    let mut set = CalibrationSet::identity();
    set.accel.a = [[1.02, 0.01, -0.005], [0.0, 0.98, 0.012], [0.0, 0.0, 1.01]];
    set.accel.b = [0.12, -0.3, 0.05];
    set.mag.a = diag(1.0 / 48.0, 1.0 / 52.0, 1.0 / 45.0);
    set.mag.b = [30.0, -12.0, 80.0];
    set.gyro_g_sensitivity = Some([[1e-4, 0.0, 0.0], [0.0, -2e-4, 0.0], [0.0, 0.0, 5e-5]]);
    assert_eq!(validate(&set, &scales()), Ok(()));
}

#[test]
fn frobenius_condition_number_matches_the_diagonal_case() {
    // diag(1, 2, 4): ‖A‖_F = √21, ‖A⁻¹‖_F = √(1 + 1/4 + 1/16) = √21/4 → κ_F = 21/4.
    let kappa = condition_frobenius(&diag(1.0, 2.0, 4.0));
    assert!((kappa - 21.0 / 4.0).abs() < 1e-12);
    assert_eq!(condition_frobenius(&diag(1.0, 1.0, 0.0)), f64::INFINITY);
    // Identity: κ_F = 3 (its smallest possible value).
    assert!((condition_frobenius(&diag(1.0, 1.0, 1.0)) - 3.0).abs() < 1e-12);
}

#[test]
fn nan_anywhere_is_non_finite_and_names_its_field() {
    let cases: [(Corruption, ParamField); 6] = [
        (
            |s| s.accel.a[1][2] = f32::NAN,
            ParamField::Matrix(SensorKind::Accel),
        ),
        (
            |s| s.mag.b[0] = f32::INFINITY,
            ParamField::Offset(SensorKind::Mag),
        ),
        (|s| s.residuals.gyro_rms = f32::NAN, ParamField::Residuals),
        (
            |s| s.gyro_g_sensitivity = Some([[0.0, f32::NAN, 0.0]; 3]),
            ParamField::GyroGSensitivity,
        ),
        (
            |s| s.gyro.t_ref_c = f32::NAN,
            ParamField::ReferenceTemperature(SensorKind::Gyro),
        ),
        (
            |s| {
                s.gyro.bias_temp = Some(BiasTemperature {
                    coeffs: [[0.0, f32::NEG_INFINITY, 0.0]; 3],
                })
            },
            ParamField::BiasTemperature(SensorKind::Gyro),
        ),
    ];
    for (corrupt, field) in cases {
        let reason = reject(corrupt);
        assert_eq!(reason, Some(InvalidParamsReason::NonFinite(field)));
        let sentence = reason.map(|r| r.to_string()).unwrap_or_default();
        assert!(sentence.starts_with(&field.to_string()), "{sentence}");
    }
}

#[test]
fn condition_bound_separates_stretch_ratios_of_ten_and_thirty_one() {
    // diag(1, 1, 1/r) has κ₂ = r; gain stays within limits for both.
    let mut set = CalibrationSet::identity();
    set.accel.a = diag(1.2, 1.2, 0.12);
    assert_eq!(validate(&set, &scales()), Ok(()));
    set.accel.a = diag(1.5, 1.5, 1.5 / 31.0);
    let ill = Err(InvalidParamsReason::IllConditioned(SensorKind::Accel));
    assert_eq!(validate(&set, &scales()), ill);
    // Singular but with a plausible gain.
    set.accel.a = [[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    assert_eq!(validate(&set, &scales()), ill);
}

#[test]
fn an_accelerometer_or_gyroscope_matrix_that_reverses_an_axis_is_refused_as_mirrored() {
    let with = |kind: SensorKind, a: [[f32; 3]; 3]| {
        let mut set = CalibrationSet::identity();
        match kind {
            SensorKind::Accel => set.accel.a = a,
            SensorKind::Gyro => set.gyro.a = a,
            SensorKind::Mag => set.mag.a = a,
        }
        validate(&set, &scales())
    };
    for kind in [SensorKind::Accel, SensorKind::Gyro] {
        // One axis reversed: as well conditioned and scaled as the identity, det = −1.
        assert_eq!(
            with(kind, diag(1.0, 1.0, -1.0)),
            Err(InvalidParamsReason::MirroredAxes(kind))
        );
        // Two axes reversed is a half turn about the third: a rotation, accepted.
        assert_eq!(with(kind, diag(-1.0, -1.0, 1.0)), Ok(()), "{kind:?}");
    }
    // A magnetometer frame that is a reflection of the accelerometer's (the LSM9DS1's) is
    // mapped into it by a matrix with det < 0.
    assert_eq!(with(SensorKind::Mag, diag(-1.0, 1.0, 1.0)), Ok(()));
    let sentence = InvalidParamsReason::MirroredAxes(SensorKind::Gyro).to_string();
    assert!(
        sentence.starts_with("gyro.A") && sentence.contains("axis mapping"),
        "{sentence}"
    );
}

#[test]
fn wrong_units_offsets_and_extended_terms_are_refused_with_the_field() {
    use InvalidParamsReason::*;
    // A fit in g instead of m/s²: gain 1/9.8.
    assert_eq!(
        reject(|s| s.accel.a = diag(0.102, 0.102, 0.102)),
        Some(GainOutOfRange(SensorKind::Accel))
    );
    // The host's classic unit slip the other way: a gain of 9.8.
    assert_eq!(
        reject(|s| s.accel.a = diag(9.8, 9.8, 9.8)),
        Some(GainOutOfRange(SensorKind::Accel))
    );
    assert_eq!(
        reject(|s| s.gyro.b = [0.0, 5.0, 0.0]),
        Some(OffsetOutOfRange(SensorKind::Gyro))
    );
    assert_eq!(
        reject(|s| s.accel.scale_temp = Some([0.0, 0.005, 0.0])),
        Some(ExtendedTermOutOfRange(ParamField::ScaleTemperature(
            SensorKind::Accel
        )))
    );
    assert_eq!(
        reject(|s| {
            s.accel.nonlinearity = Some(Nonlinearity {
                quadratic: [0.03, 0.0, 0.0],
                cubic: [0.0; 3],
            })
        }),
        Some(ExtendedTermOutOfRange(ParamField::Nonlinearity(
            SensorKind::Accel
        )))
    );
    assert_eq!(
        reject(|s| {
            // 0.01 m/s² per °C² → 156 m/s² at 125 °C: beyond the ±19.6 m/s² range.
            s.accel.bias_temp = Some(BiasTemperature {
                coeffs: [[0.0; 3], [0.01, 0.0, 0.0], [0.0; 3]],
            })
        }),
        Some(ExtendedTermOutOfRange(ParamField::BiasTemperature(
            SensorKind::Accel
        )))
    );
    assert_eq!(
        reject(|s| s.gyro_g_sensitivity = Some([[0.02, 0.0, 0.0]; 3])),
        Some(ExtendedTermOutOfRange(ParamField::GyroGSensitivity))
    );
    assert_eq!(
        reject(|s| s.format_version = 99),
        Some(UnsupportedFormat { found: 99 })
    );
}

#[test]
fn an_absurd_reference_temperature_is_refused_even_without_temperature_terms() {
    // 1e30 °C would make ΔT³ overflow to infinity in any implementation of the model.
    let reason = reject(|s| s.mag.t_ref_c = 1e30);
    assert_eq!(
        reason,
        Some(InvalidParamsReason::ReferenceTemperatureOutOfRange(
            SensorKind::Mag
        ))
    );
    let sentence = reason.map(|r| r.to_string()).unwrap_or_default();
    assert!(
        sentence.contains("mag.t_ref_c") && sentence.contains("-55…125 °C"),
        "{sentence}"
    );
}

#[test]
fn sentences_name_the_field_and_the_limit() {
    let gain = InvalidParamsReason::GainOutOfRange(SensorKind::Gyro).to_string();
    assert!(gain.contains("gyro.A") && gain.contains("0.5…2"), "{gain}");
    let kappa = InvalidParamsReason::IllConditioned(SensorKind::Accel).to_string();
    assert!(kappa.contains("accel.A") && kappa.contains("30"), "{kappa}");
    let scale = InvalidParamsReason::ExtendedTermOutOfRange(ParamField::ScaleTemperature(
        SensorKind::Accel,
    ))
    .to_string();
    assert!(
        scale.contains("accel.scale_temp") && scale.contains("50 %"),
        "{scale}"
    );
}

#[test]
fn unknown_boards_are_checked_against_the_widest_supported_ranges() {
    // An offset of 30 m/s² is beyond a ±2 g board but possible on a ±16 g one.
    let mut set = CalibrationSet::identity();
    set.accel.b = [30.0, 0.0, 0.0];
    assert_eq!(
        validate(&set, &scales()),
        Err(InvalidParamsReason::OffsetOutOfRange(SensorKind::Accel))
    );
    assert_eq!(
        validate_for_ranges(&set, &FullScale::WIDEST_SUPPORTED),
        Ok(())
    );
}
