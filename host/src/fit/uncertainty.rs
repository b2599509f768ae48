//! One uncertainty policy for every fit: how the covariance from the Jacobian at the solution is
//! scaled by what the residuals say about the noise.
//!
//! The unit covariance `(JᵀJ)⁻¹` (residuals divided by their assumed σ) is multiplied by a
//! variance factor:
//! - **known noise** (per-pose variances): the Birge ratio `R_B² = χ²/ν` (R. T. Birge 1932),
//!   ν = N − P residual degrees of freedom, tests whether the scatter matches the assumed noise.
//!   The 95 % interval reported is the wider of the known-noise interval (factor 1) and the
//!   interval with the scale estimated from the residuals (factor `χ²/ν`, Student-t with ν
//!   degrees of freedom): `max(1, w_ν·χ²/ν)`. Placement error, tremor and correlated samples
//!   all show up as `χ²/ν > 1`, whatever their cause.
//! - **unknown noise** (relative weights only): the scale is estimated, factor `w_ν·χ²/ν`; with
//!   ν = 0 or χ² = 0 there is no estimate and no covariance (never a zero covariance).
//!
//! `w_ν = (t_{0.975,ν}/z_{0.975})²` widens σ so that `±1.96σ` is the Student-t 95 % interval: an
//! estimated scale with few degrees of freedom is itself uncertain (with 12 poses and 9
//! parameters ν = 3 and `t = 3.18`). The reported σ are thus "95 %-calibrated": use `±1.96σ`.

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
    /// `χ²/ν`, `None` when ν = 0.
    pub reduced_chi_square: Option<f64>,
    /// Residual degrees of freedom ν = N − P (0 when N ≤ P).
    pub dof: usize,
}

/// The variance factor of the policy in the module comment, for `chi_square` over `residuals`
/// residuals and `params` parameters. `None` when the noise is unknown and cannot be estimated
/// (ν = 0, or an exact fit, or a non-finite χ²).
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
    let estimated = reduced.map(|r| r * t_widening(dof));
    let variance_factor = match noise {
        NoiseLevel::Known => estimated.map_or(1.0, |e| e.max(1.0)),
        NoiseLevel::Unknown => estimated.filter(|e| *e > 0.0)?,
    };
    Some(NoiseScale {
        variance_factor,
        reduced_chi_square: reduced,
        dof,
    })
}

/// `cov·factor` of [`noise_scale`]; `None` when the scale is not available.
pub fn scaled_covariance(
    unit_covariance: Option<DMatrix<f64>>,
    chi_square: f64,
    residuals: usize,
    params: usize,
    noise: NoiseLevel,
) -> Option<DMatrix<f64>> {
    let scale = noise_scale(chi_square, residuals, params, noise)?;
    unit_covariance.map(|c| c * scale.variance_factor)
}

/// `(t_{0.975,ν}/z_{0.975})²`: the variance widening that makes `±1.96σ` a 95 % interval when σ
/// is estimated with ν degrees of freedom (1 for ν = 0, where nothing is estimated).
pub fn t_widening(dof: usize) -> f64 {
    if dof == 0 {
        return 1.0;
    }
    (student_t_975(dof) / Z_95).powi(2)
}

/// Upper 97.5 % quantile of Student's t with ν degrees of freedom: exact for ν = 1, 2, and the
/// Cornish–Fisher expansion in 1/ν (Abramowitz & Stegun 26.7.5) beyond, within 0.1 % for ν ≥ 3.
pub fn student_t_975(dof: usize) -> f64 {
    match dof {
        0 => f64::INFINITY,
        1 => 12.706_204_736_174_7,
        2 => 4.302_652_729_749_46,
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
        for (dof, t) in [(3, 3.182), (5, 2.571), (9, 2.262), (15, 2.131), (30, 2.042)] {
            assert!((student_t_975(dof) - t).abs() < 2e-3, "ν = {dof}");
        }
        assert!((student_t_975(100_000) - Z_95).abs() < 1e-4);
    }

    #[test]
    fn known_noise_is_inflated_only_when_the_scatter_exceeds_it() {
        // χ²/ν = 0.5 with ν = 100: the data agree with the noise; factor 1.
        let s = noise_scale(50.0, 109, 9, NoiseLevel::Known).unwrap();
        assert_eq!(s.variance_factor, 1.0);
        // χ²/ν = 9.6 (the Xsens case): σ grows by about √9.6 ≈ 3.1 (×t widening, ν = 100).
        let s = noise_scale(960.0, 109, 9, NoiseLevel::Known).unwrap();
        assert!((s.variance_factor / (9.6 * t_widening(100)) - 1.0).abs() < 1e-12);
        assert!(s.variance_factor > 9.6 && s.variance_factor < 10.0);
    }

    #[test]
    fn unknown_noise_without_degrees_of_freedom_or_scatter_gives_no_covariance() {
        assert!(noise_scale(1.0, 9, 9, NoiseLevel::Unknown).is_none());
        assert!(noise_scale(0.0, 20, 9, NoiseLevel::Unknown).is_none());
        let unit = Some(DMatrix::identity(2, 2));
        assert!(scaled_covariance(unit, 0.0, 20, 2, NoiseLevel::Unknown).is_none());
    }
}
