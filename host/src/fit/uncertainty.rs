//! One uncertainty policy for every fit: how the covariance from the Jacobian at the solution is
//! scaled by what the residuals say about the noise, and which factor turns σ into a 95 %
//! interval.
//!
//! The unit covariance `(JᵀJ)⁻¹` (residuals divided by their assumed σ) is multiplied by a
//! variance factor:
//! - **known noise** (per-pose variances): the Birge ratio `R_B² = χ²/ν` (R. T. Birge 1932; the
//!   Particle Data Group's scale factor), ν = N − P residual degrees of freedom; the covariance
//!   is inflated by `max(1, χ²/ν)`. Placement error, tremor, drift between holds and correlated
//!   samples (an effective sample size below n) all show up as `χ²/ν > 1`, whatever the cause.
//! - **unknown noise** (relative weights only): the scale is estimated, factor `χ²/ν`; with
//!   ν = 0 or χ² = 0 there is no estimate and no covariance (never a zero covariance).
//!
//! The 95 % interval is `±k·σ` (GUM's expanded uncertainty, JCGM 100:2008 §6): with unknown noise
//! `k = t_{0.975,ν}` (an estimated scale is itself uncertain: 12 poses and 9 parameters leave
//! ν = 3 and `t = 3.18`); with known noise the interval is the wider of the known-noise one
//! (`1.96·σ₀`) and the estimated-scale one (`t·σ₀·√(χ²/ν)`), so `k` is continuous in `χ²/ν`.

use nalgebra::DMatrix;

/// Two-sided 95 % quantile of the standard normal distribution.
pub const Z_95: f64 = 1.959_963_984_540_054;

/// Whether the residual weights carry the real noise or only relative weights.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoiseLevel {
    /// Residuals are divided by their measured σ (e.g. within-pose variance).
    Known,
    /// Residuals carry an unknown common scale, estimated from their scatter.
    Unknown,
}

/// The variance factor applied to a unit covariance, and the statistics behind it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseScale {
    /// Factor multiplying `(JᵀJ)⁻¹`.
    pub variance_factor: f64,
    /// `k` such that `±k·σ` is the 95 % interval of each parameter.
    pub coverage_factor: f64,
    /// `χ²/ν`, `None` when ν = 0.
    pub reduced_chi_square: Option<f64>,
    /// Residual degrees of freedom ν = N − P (0 when N ≤ P).
    pub dof: usize,
}

/// The scale of the policy in the module comment, for `chi_square` over `residuals` residuals
/// and `params` parameters. `None` when the noise is unknown and cannot be estimated (ν = 0, an
/// exact fit, or a non-finite χ²).
pub fn noise_scale(
    chi_square: f64,
    residuals: usize,
    params: usize,
    noise: NoiseLevel,
) -> Option<NoiseScale> {
    if !(chi_square.is_finite() && chi_square >= 0.0) {
        return None;
    }
    let dof = residuals.saturating_sub(params);
    let reduced = (dof > 0).then(|| chi_square / dof as f64);
    let (variance_factor, coverage_factor) = match (noise, reduced) {
        (NoiseLevel::Known, None) => (1.0, Z_95),
        (NoiseLevel::Known, Some(rc)) => {
            let factor = rc.max(1.0);
            let half_width = Z_95.max(student_t_975(dof) * rc.sqrt());
            (factor, half_width / factor.sqrt())
        }
        (NoiseLevel::Unknown, None) => return None,
        (NoiseLevel::Unknown, Some(rc)) => {
            if rc <= 0.0 {
                return None;
            }
            (rc, student_t_975(dof))
        }
    };
    Some(NoiseScale {
        variance_factor,
        coverage_factor,
        reduced_chi_square: reduced,
        dof,
    })
}

/// A covariance scaled by the policy, with its 95 % coverage factor.
#[derive(Debug, Clone, PartialEq)]
pub struct ScaledCovariance {
    /// The parameter covariance.
    pub covariance: DMatrix<f64>,
    /// `k` such that `±k·σ` is the 95 % interval.
    pub coverage_factor: f64,
}

/// `cov·factor` of [`noise_scale`]; `None` when the unit covariance or the scale is not available.
pub fn scaled_covariance(
    unit_covariance: Option<DMatrix<f64>>,
    chi_square: f64,
    residuals: usize,
    params: usize,
    noise: NoiseLevel,
) -> Option<ScaledCovariance> {
    let scale = noise_scale(chi_square, residuals, params, noise)?;
    unit_covariance.map(|c| ScaledCovariance {
        covariance: c * scale.variance_factor,
        coverage_factor: scale.coverage_factor,
    })
}

/// Upper 97.5 % quantile of Student's t with ν degrees of freedom: tabulated for ν ≤ 5, and the
/// Cornish–Fisher expansion in 1/ν (Abramowitz & Stegun 26.7.5) beyond, within 0.01 % for ν ≥ 6.
pub fn student_t_975(dof: usize) -> f64 {
    match dof {
        0 => f64::INFINITY,
        1 => 12.706_204_736_174_7,
        2 => 4.302_652_729_749_46,
        3 => 3.182_446_305_284_26,
        4 => 2.776_445_105_197_8,
        5 => 2.570_581_835_636_31,
        _ => {
            let z = Z_95;
            let n = dof as f64;
            let (z2, z3) = (z * z, z * z * z);
            let z5 = z3 * z2;
            let z7 = z5 * z2;
            let z9 = z7 * z2;
            z + (z3 + z) / (4.0 * n)
                + (5.0 * z5 + 16.0 * z3 + 3.0 * z) / (96.0 * n * n)
                + (3.0 * z7 + 19.0 * z5 + 17.0 * z3 - 15.0 * z) / (384.0 * n.powi(3))
                + (79.0 * z9 + 776.0 * z7 + 1482.0 * z5 - 1920.0 * z3 - 945.0 * z)
                    / (92_160.0 * n.powi(4))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn student_t_quantiles_match_the_tables() {
        // Tabulated t_{0.975,ν} (e.g. NIST/SEMATECH handbook, table 1.3.6.7.2), 4 digits.
        for (dof, t) in [(3, 3.182), (6, 2.447), (9, 2.262), (15, 2.131), (30, 2.042)] {
            assert!((student_t_975(dof) - t).abs() < 2e-3, "ν = {dof}");
        }
        assert!((student_t_975(100_000) - Z_95).abs() < 1e-4);
    }

    #[test]
    fn known_noise_is_inflated_only_when_the_scatter_exceeds_it() {
        // χ²/ν = 0.5 with ν = 100: the data agree with the noise; factor 1, interval ±1.96σ.
        let s = noise_scale(50.0, 109, 9, NoiseLevel::Known).unwrap();
        assert_eq!(s.variance_factor, 1.0);
        assert_eq!(s.coverage_factor, Z_95);
        // χ²/ν = 9.6 (the Xsens case): σ grows by √9.6 ≈ 3.1, the interval uses t with ν = 100.
        let s = noise_scale(960.0, 109, 9, NoiseLevel::Known).unwrap();
        assert!((s.variance_factor - 9.6).abs() < 1e-12);
        assert!((s.coverage_factor - student_t_975(100)).abs() < 1e-12);
    }

    #[test]
    fn the_coverage_factor_is_continuous_where_the_birge_ratio_crosses_one() {
        let below = noise_scale(2.999_999, 12, 9, NoiseLevel::Known).unwrap();
        let above = noise_scale(3.000_001, 12, 9, NoiseLevel::Known).unwrap();
        assert!((below.coverage_factor - above.coverage_factor).abs() < 1e-5);
        assert!((above.coverage_factor - 3.182).abs() < 1e-3);
    }

    #[test]
    fn unknown_noise_without_degrees_of_freedom_or_scatter_gives_no_covariance() {
        assert!(noise_scale(1.0, 9, 9, NoiseLevel::Unknown).is_none());
        assert!(noise_scale(0.0, 20, 9, NoiseLevel::Unknown).is_none());
        let unit = Some(DMatrix::identity(2, 2));
        assert!(scaled_covariance(unit, 0.0, 20, 2, NoiseLevel::Unknown).is_none());
    }
}
