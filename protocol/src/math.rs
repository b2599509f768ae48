//! Square roots for `no_std` code without libm (this crate and the firmware core): Newton's
//! iteration from a bit-level first guess. Meant for load-time checks and reports, not for a
//! per-sample path.

/// `√x` for `f32`; NaN for negative or NaN input.
pub fn sqrt_f32(x: f32) -> f32 {
    if x.is_nan() || x < 0.0 {
        return f32::NAN;
    }
    if x == 0.0 || x.is_infinite() {
        return x;
    }
    // Halving the biased exponent gives a first guess within a factor of about 1.06 for normal
    // numbers; Newton then doubles the correct bits each step. Eight steps also cover subnormals.
    let mut y = f32::from_bits((x.to_bits() >> 1) + (127 << 22));
    for _ in 0..8 {
        y = 0.5 * (y + x / y);
    }
    y
}

/// `√x` for `f64`; NaN for negative or NaN input.
pub fn sqrt_f64(x: f64) -> f64 {
    if x.is_nan() || x < 0.0 {
        return f64::NAN;
    }
    if x == 0.0 || x.is_infinite() {
        return x;
    }
    let mut y = f64::from_bits((x.to_bits() >> 1) + (1023 << 51));
    for _ in 0..10 {
        y = 0.5 * (y + x / y);
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn newton_square_roots_match_std_to_one_ulp() {
        for x in [1e-30f32, 1e-40, 1e-6, 0.5, 2.0, 3.0, 1e6, 1.7e38] {
            let reference = x.sqrt();
            // Newton's fixed point is within one rounding of the exact root.
            assert!(
                (sqrt_f32(x) - reference).abs() <= reference * f32::EPSILON,
                "{x}"
            );
        }
        for x in [1e-300f64, 1e-310, 0.5, 2.0, 21.0, 1e300] {
            let reference = x.sqrt();
            assert!(
                (sqrt_f64(x) - reference).abs() <= reference * f64::EPSILON,
                "{x}"
            );
        }
        assert!(sqrt_f32(-1.0).is_nan());
        assert!(sqrt_f64(f64::NAN).is_nan());
        assert_eq!(sqrt_f64(0.0), 0.0);
    }
}
