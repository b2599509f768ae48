//! The chi-square test of a weighted residual against the noise floor.
//!
//! Each residual component is weighted by the noise it would show from noise alone (the
//! standard error of the pose mean, propagated through the model: `σ'ᵢ = |∇ₓ(|A(x−b)|/ref)∘σᵢ|`
//! for the norm model, `σᵢ` per axis for the gyroscope; see [`crate::pipeline::observations`] for `σᵢ` and its
//! correction for correlated samples). If the model is right and the noise is Gaussian,
//! `χ² = Σ(rᵢ/σᵢ)²` follows `χ²(N − p)`; the residual is called consistent with the noise when
//! the upper-tail probability is at least [`CONSISTENCY_ALPHA`].

use super::distributions::chi2_upper_tail;

/// Significance level of the consistency test: a residual is declared above the floor only
/// when noise alone would produce a larger χ² less than 1 % of the time.
pub const CONSISTENCY_ALPHA: f64 = 0.01;

/// Result of the chi-square test.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChiSquareTest {
    /// `Σ(rᵢ/σᵢ)²`.
    pub chi2: f64,
    /// Degrees of freedom `N − p`.
    pub dof: f64,
    /// `P(χ²(dof) ≥ chi2)`.
    pub p_value: f64,
}

impl ChiSquareTest {
    /// Test a weighted cost with `residuals` components and `params` fitted parameters.
    pub fn new(chi2: f64, residuals: usize, params: usize) -> Self {
        let dof = residuals.saturating_sub(params).max(1) as f64;
        Self {
            chi2,
            dof,
            p_value: chi2_upper_tail(chi2, dof),
        }
    }

    /// Whether the residual is consistent with the noise (see [`CONSISTENCY_ALPHA`]).
    pub fn consistent(&self) -> bool {
        self.p_value >= CONSISTENCY_ALPHA
    }

    /// `χ²/dof`: about 1 at the floor.
    pub fn reduced(&self) -> f64 {
        self.chi2 / self.dof
    }

    /// `p = 3.20e-6`, or `p < 1e-300` where the tail probability underflows.
    pub fn p_text(&self) -> String {
        if self.p_value > 0.0 {
            format!("p = {:.2e}", self.p_value)
        } else {
            "p < 1e-300".to_string()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn consistency_follows_the_tail_probability() {
        // χ²(61) has mean 61 and standard deviation 11: 60 is typical, 200 is far in the tail.
        assert!(ChiSquareTest::new(60.0, 70, 9).consistent());
        assert!(!ChiSquareTest::new(200.0, 70, 9).consistent());
        assert!(chi2_upper_tail(f64::NAN, 3.0).is_nan());
    }
}
