//! The folded f32 path against the protocol's f64 reference model, term by term and at the edges.

use super::*;
use imucal_protocol::{model, BiasTemperature, NominalSample, Nonlinearity, SensorKind};

fn scales() -> SensorScales {
    imucal_protocol::SensorScales::EXAMPLE_LSM9DS1
}

/// A set using every extended term, with magnitudes of a poor but real MEMS part.
fn extended_set() -> CalibrationSet {
    let mut set = CalibrationSet::identity();
    set.accel.a = [
        [1.02, 0.01, -0.005],
        [0.003, 0.98, 0.012],
        [-0.004, 0.006, 1.01],
    ];
    set.accel.b = [0.12, -0.3, 0.05];
    set.accel.t_ref_c = 25.0;
    set.accel.bias_temp = Some(BiasTemperature {
        coeffs: [[2e-3, -1e-3, 5e-4], [1e-5, 0.0, -2e-5], [1e-7, 3e-7, 0.0]],
    });
    set.accel.scale_temp = Some([1e-4, -2e-4, 5e-5]);
    set.accel.nonlinearity = Some(Nonlinearity {
        quadratic: [1e-3, -5e-4, 2e-4],
        cubic: [1e-5, 0.0, -2e-5],
    });
    set.gyro.a = [[1.01, -0.02, 0.0], [0.015, 0.99, 0.004], [0.0, 0.01, 1.03]];
    set.gyro.b = [0.01, -0.02, 0.005];
    set.gyro.t_ref_c = 30.0;
    set.gyro.bias_temp = Some(BiasTemperature {
        coeffs: [[1e-4, -2e-4, 3e-5], [0.0; 3], [0.0; 3]],
    });
    set.gyro_g_sensitivity = Some([[1e-4, 2e-5, 0.0], [0.0, -2e-4, 1e-5], [3e-5, 0.0, 5e-5]]);
    set.mag.a = [
        [1.0 / 48.0, 0.001, 0.0],
        [0.0, 1.0 / 52.0, -0.0005],
        [0.0, 0.0, 1.0 / 45.0],
    ];
    set.mag.b = [30.0, -12.0, 80.0];
    set.mag.scale_temp = Some([0.0, 0.0, 3e-4]);
    set
}

/// The protocol's f64 reference model on the same sample in nominal units.
fn reference(set: &CalibrationSet, raw: &RawSample) -> [[f64; 3]; 3] {
    let s = scales();
    let nominal =
        |counts: [i16; 3], per_count: f32| counts.map(|c| f64::from(c) * f64::from(per_count));
    let out = model::apply(
        set,
        &NominalSample {
            accel: nominal(raw.accel, s.accel_mps2_per_count),
            gyro: nominal(raw.gyro, s.gyro_rads_per_count),
            mag: nominal(raw.mag, s.mag_ut_per_count),
            temp_c: f64::from(s.temp_offset_c)
                + f64::from(s.temp_c_per_count) * f64::from(raw.temp),
        },
    );
    [out.accel, out.gyro, out.mag]
}

/// Deterministic spread of samples over the whole count range and −40…85 °C.
fn samples() -> impl Iterator<Item = RawSample> {
    let mut state = 0x2545_f491_u32;
    core::iter::repeat_with(move || {
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            (state >> 16) as u16 as i16
        };
        RawSample {
            accel: [next(), next(), next()],
            gyro: [next(), next(), next()],
            mag: [next(), next(), next()],
            // 1/16 °C per count around 25 °C: −40…85 °C is −1040…960 counts.
            temp: next() % 1000,
        }
    })
    .take(20_000)
}

/// Largest error relative to the sensor's full scale over all samples.
fn worst_error_of_full_scale(set: &CalibrationSet) -> f64 {
    let correction = Correction::new(set, &scales()).unwrap();
    let s = scales();
    let full_scale = [s.accel_range_mps2, s.gyro_range_rads, s.mag_range_ut].map(f64::from);
    let mut worst = 0.0f64;
    for raw in samples() {
        let ours = correction.apply(&raw);
        let truth = reference(set, &raw);
        for (sensor, (values, fs)) in [ours.accel, ours.gyro, ours.mag]
            .iter()
            .zip(full_scale)
            .enumerate()
        {
            for axis in 0..3 {
                let error = (f64::from(values[axis]) - truth[sensor][axis]).abs() / fs;
                worst = worst.max(error);
            }
        }
    }
    worst
}

#[test]
fn linear_set_equals_a_times_x_minus_b_in_f64() {
    let mut set = CalibrationSet::identity();
    set.accel.a = [
        [1.02, 0.01, -0.005],
        [0.003, 0.98, 0.012],
        [-0.004, 0.006, 1.01],
    ];
    set.accel.b = [0.12, -0.3, 0.05];
    set.mag.a = [
        [1.0 / 48.0, 0.001, 0.0],
        [0.0, 1.0 / 52.0, -0.0005],
        [0.0, 0.0, 1.0 / 45.0],
    ];
    set.mag.b = [30.0, -12.0, 80.0];
    // f32 carries 2^-24 ≈ 6e-8 relative; folding and the 3-term dot product add a few
    // roundings of full-scale-sized terms, so 1e-6 of full scale bounds the error.
    let worst = worst_error_of_full_scale(&set);
    assert!(worst < 1e-6, "worst error {worst:e} of full scale");
}

#[test]
fn every_extended_term_matches_the_f64_model() {
    // As above, plus the cubic temperature and non-linearity terms, each a few more
    // roundings: 2e-6 of full scale.
    let worst = worst_error_of_full_scale(&extended_set());
    assert!(worst < 2e-6, "worst error {worst:e} of full scale");
}

#[test]
fn the_extended_terms_change_the_output_measurably() {
    // Guards the test above against a reference that ignores the terms as well.
    let extended = Correction::new(&extended_set(), &scales()).unwrap();
    let mut plain_set = extended_set();
    plain_set.accel.bias_temp = None;
    plain_set.accel.scale_temp = None;
    plain_set.accel.nonlinearity = None;
    plain_set.gyro_g_sensitivity = None;
    let plain = Correction::new(&plain_set, &scales()).unwrap();
    let raw = RawSample {
        accel: [20_000, -10_000, 16_000],
        gyro: [100, 200, -300],
        mag: [0; 3],
        temp: 800, // 75 °C, 50 °C above the accelerometer reference
    };
    let difference = (extended.apply(&raw).accel[0] - plain.apply(&raw).accel[0]).abs();
    assert!(
        difference > 0.05,
        "extended terms moved the output by only {difference}"
    );
}

#[test]
fn scale_temperature_alone_scales_about_the_sensors_own_reference() {
    // s = 1e-4/°C about T_ref = 25 °C, no bias polynomial: y = (1 + s·(T − 25))·σ·c, so no
    // scale change at all at 25 °C (format 1 took T_ref = 0 here and scaled by 1.0025).
    let s = scales();
    let mut set = CalibrationSet::identity();
    set.accel.t_ref_c = 25.0;
    set.accel.scale_temp = Some([1e-4; 3]);
    let correction = Correction::new(&set, &s).unwrap();
    let counts = [16_384i16, -8_192, 4_000];
    // 10…40 °C in 1 °C steps: 16 counts per °C around 25 °C at 0 counts.
    for temp_c in 10..=40 {
        let raw = RawSample {
            accel: counts,
            temp: ((temp_c - 25) * 16) as i16,
            ..RawSample::default()
        };
        let out = correction.apply(&raw).accel;
        let gain = 1.0 + 1e-4 * f64::from(temp_c - 25);
        for axis in 0..3 {
            let expected = gain * f64::from(counts[axis]) * f64::from(s.accel_mps2_per_count);
            // f32 rounding of a ≈10 m/s² product: a few 1e-7 relative.
            let error = (f64::from(out[axis]) - expected).abs();
            assert!(
                error <= 1e-6 * expected.abs(),
                "{temp_c} °C axis {axis}: {error:e}"
            );
            if temp_c == 25 {
                let nominal = f32::from(counts[axis]) * s.accel_mps2_per_count;
                assert_eq!(out[axis], nominal, "no scale change at T_ref");
            }
        }
    }
}

#[test]
fn temperatures_beyond_the_validated_span_get_its_edge_correction() {
    let s = scales();
    let set = extended_set();
    let correction = Correction::new(&set, &s).unwrap();
    // Thermometer rails: i16::MAX counts is 2073 °C, i16::MIN is −2023 °C.
    for rail in [i16::MIN, i16::MAX] {
        let raw = RawSample {
            accel: [12_000, -3_000, 9_000],
            gyro: [400, -200, 100],
            mag: [1_000, 2_000, -3_000],
            temp: rail,
        };
        let ours = correction.apply(&raw);
        let truth = reference(&set, &raw);
        for (values, truth) in [ours.accel, ours.gyro, ours.mag].iter().zip(truth) {
            for axis in 0..3 {
                let error = (f64::from(values[axis]) - truth[axis]).abs();
                assert!(error <= 1e-5 * truth[axis].abs().max(1.0), "{error:e}");
            }
        }
    }
}

#[test]
fn identity_gives_nominal_units() {
    let correction = Correction::identity(&scales());
    let raw = RawSample {
        accel: [1000, -2000, 16_384],
        gyro: [-5, 0, 5],
        mag: [100, 200, 300],
        temp: -16,
    };
    let out = correction.apply(&raw);
    assert_eq!(out.accel[2], 16_384.0 * scales().accel_mps2_per_count);
    assert_eq!(out.gyro[0], -5.0 * scales().gyro_rads_per_count);
    assert_eq!(out.temp_c, 24.0);
}

#[test]
fn only_sets_with_a_nonzero_extended_term_leave_the_plain_path() {
    // The accuracy tests above go through whichever path a set selects; this pins which.
    let s = scales();
    assert!(Correction::identity(&s).is_plain());
    let mut zero_terms = extended_set();
    for sensor in [
        &mut zero_terms.accel,
        &mut zero_terms.gyro,
        &mut zero_terms.mag,
    ] {
        sensor.bias_temp = sensor.bias_temp.map(|_| BiasTemperature {
            coeffs: [[0.0; 3]; 3],
        });
        sensor.scale_temp = sensor.scale_temp.map(|_| [0.0; 3]);
        sensor.nonlinearity = sensor.nonlinearity.map(|_| Nonlinearity {
            quadratic: [0.0; 3],
            cubic: [0.0; 3],
        });
    }
    zero_terms.gyro_g_sensitivity = Some([[0.0; 3]; 3]);
    assert!(Correction::new(&zero_terms, &s).unwrap().is_plain());
    assert!(!Correction::new(&extended_set(), &s).unwrap().is_plain());
    let mut only_g_sensitivity = zero_terms;
    only_g_sensitivity.gyro_g_sensitivity = extended_set().gyro_g_sensitivity;
    assert!(!Correction::new(&only_g_sensitivity, &s).unwrap().is_plain());
}

#[test]
fn zero_extended_terms_give_the_same_output_as_none() {
    // A set whose extended terms are present but zero takes the plain path, and must
    // calibrate exactly as the same set without them (both are the plain path's arithmetic).
    let s = scales();
    let mut plain = extended_set();
    for sensor in [&mut plain.accel, &mut plain.gyro, &mut plain.mag] {
        sensor.bias_temp = None;
        sensor.scale_temp = None;
        sensor.nonlinearity = None;
    }
    plain.gyro_g_sensitivity = None;
    let mut zero_terms = plain;
    zero_terms.accel.scale_temp = Some([0.0; 3]);
    zero_terms.gyro_g_sensitivity = Some([[0.0; 3]; 3]);
    let a = Correction::new(&plain, &s).unwrap();
    let b = Correction::new(&zero_terms, &s).unwrap();
    for raw in samples().take(1000) {
        assert_eq!(a.apply(&raw), b.apply(&raw));
    }
}

#[test]
fn an_invalid_set_is_refused_with_its_reason() {
    let mut set = CalibrationSet::identity();
    set.gyro.b[1] = f32::NAN;
    assert_eq!(
        Correction::new(&set, &scales()),
        Err(InvalidParamsReason::NonFinite(
            imucal_protocol::ParamField::Offset(SensorKind::Gyro)
        ))
    );
}

#[test]
fn extreme_counts_and_temperatures_stay_finite() {
    let correction = Correction::new(&extended_set(), &scales()).unwrap();
    for v in [i16::MIN, i16::MAX] {
        let out = correction.apply(&RawSample {
            accel: [v; 3],
            gyro: [v; 3],
            mag: [v; 3],
            temp: v,
        });
        let all = out
            .accel
            .iter()
            .chain(&out.gyro)
            .chain(&out.mag)
            .chain([&out.temp_c]);
        assert!(all.into_iter().all(|x| x.is_finite()), "{out:?}");
    }
}
