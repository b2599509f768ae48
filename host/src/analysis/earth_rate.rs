//! The Earth's rotation in the gyroscope's rest model.
//!
//! At rest a gyroscope reads its bias plus the Earth's rate `Ω_E = 7.292115·10⁻⁵ rad/s` (WGS 84)
//! in its own frame. At latitude `φ` that vector has a vertical part `Ω_E·sin φ` (up in the
//! north) and a horizontal part `Ω_E·cos φ` pointing north. The accelerometer gives the up
//! direction of every hold (the specific force at rest is `+g` up), so the vertical part is
//! known in the sensor frame: `ω_vᵢ = Ω_E·sin φ·f̂ᵢ`. The horizontal part needs the heading,
//! which a tumbled board without a reliable magnetometer does not give; it is *not* modelled:
//! it is left in the residual, where it is bounded by `Ω_E·cos φ` (≈ 0.0029 °/s at 45°). Without
//! this term a fitted g-sensitivity absorbs the vertical part: its diagonal becomes
//! `Ω_E·sin φ / g` per m/s², which the firmware would then apply on a moving vehicle.

use crate::fit::Vec3;

/// The Earth's rotation rate, rad/s (WGS 84).
pub const EARTH_RATE: f64 = 7.292_115e-5;

/// The vertical Earth rate at `latitude_deg` in the sensor frame of a hold whose specific force
/// (any unit; only its direction is used) is `force`, in rad/s. Zero for a zero force.
pub fn vertical_earth_rate(latitude_deg: f64, force: &Vec3) -> Vec3 {
    let up = force.try_normalize(0.0).unwrap_or_else(Vec3::zeros);
    up * (EARTH_RATE * latitude_deg.to_radians().sin())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vertical_rate_is_along_up_with_the_sine_of_latitude() {
        // At 30° N the vertical part is half the Earth rate, along the specific force.
        let w = vertical_earth_rate(30.0, &Vec3::new(0.0, 0.0, 9.81));
        assert!((w - Vec3::new(0.0, 0.0, EARTH_RATE / 2.0)).norm() < 1e-18);
        // Upside down the sensor sees it reversed; in the south it changes sign.
        let w = vertical_earth_rate(-30.0, &Vec3::new(0.0, 0.0, -9.81));
        assert!((w - Vec3::new(0.0, 0.0, EARTH_RATE / 2.0)).norm() < 1e-18);
        assert_eq!(vertical_earth_rate(45.0, &Vec3::zeros()), Vec3::zeros());
    }
}
