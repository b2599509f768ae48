//! The noise floor and the chi-square test of a residual against it.
//!
//! Each residual component is weighted by the noise it would show from noise alone (the
//! standard error of the pose mean, propagated through the model: `σ'ᵢ = |∇ₓ(|A(x−b)|/ref)∘σᵢ|`
//! for the norm model, `σᵢ` per axis for the gyroscope; see [`super::dataset`] for `σᵢ` and its
//! correction for correlated samples). If the model is right and the noise is Gaussian,
//! `χ² = Σ(rᵢ/σᵢ)²` follows `χ²(N − p)`; the residual is called consistent with the noise when
//! the upper-tail probability is at least [`CONSISTENCY_ALPHA`].

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
}

/// `ln Γ(x)` for `x > 0` (Lanczos, g = 7, n = 9; relative error below 1e-13).
pub(crate) fn ln_gamma(x: f64) -> f64 {
    const COEF: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let t = x + 7.5;
    let sum = COEF
        .iter()
        .enumerate()
        .skip(1)
        .fold(COEF[0], |acc, (i, c)| acc + c / (x + i as f64));
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + sum.ln()
}

/// Regularised upper incomplete gamma `Q(a, x)` (series for `x < a + 1`, Lentz continued
/// fraction otherwise; Numerical Recipes §6.2).
fn gamma_q(a: f64, x: f64) -> f64 {
    if a.is_nan() || a <= 0.0 || x.is_nan() {
        return f64::NAN;
    }
    if x <= 0.0 {
        return 1.0;
    }
    if x.is_infinite() {
        return 0.0;
    }
    let ln_pre = a * x.ln() - x - ln_gamma(a);
    if x < a + 1.0 {
        let mut term = 1.0 / a;
        let mut sum = term;
        let mut ap = a;
        for _ in 0..10_000 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-15 {
                break;
            }
        }
        (1.0 - sum * ln_pre.exp()).clamp(0.0, 1.0)
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let delta = d * c;
            h *= delta;
            if (delta - 1.0).abs() < 1e-15 {
                break;
            }
        }
        (ln_pre.exp() * h).clamp(0.0, 1.0)
    }
}

/// Upper-tail probability of the chi-square distribution, `P(χ²(dof) ≥ x)`.
pub fn chi2_upper_tail(x: f64, dof: f64) -> f64 {
    if !(x.is_finite() && dof > 0.0) {
        return if x.is_infinite() && x > 0.0 {
            0.0
        } else {
            f64::NAN
        };
    }
    gamma_q(dof / 2.0, x / 2.0)
}

/// Upper-tail probability of the standard normal distribution.
pub fn normal_upper_tail(z: f64) -> f64 {
    0.5 * erfc(z / std::f64::consts::SQRT_2)
}

/// Complementary error function via `Q(1/2, x²)`.
fn erfc(x: f64) -> f64 {
    if x >= 0.0 {
        gamma_q(0.5, x * x)
    } else {
        2.0 - gamma_q(0.5, x * x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chi_square_tail_matches_tabulated_quantiles() {
        // Tabulated: P(χ²(1) ≥ 3.841) = 0.05, P(χ²(10) ≥ 23.209) = 0.01, P(χ²(100) ≥ 124.342) = 0.05.
        // The tables give 4 significant figures, hence the tolerance of 2e-4 on the probability.
        assert!((chi2_upper_tail(3.841_459, 1.0) - 0.05).abs() < 2e-4);
        assert!((chi2_upper_tail(23.209, 10.0) - 0.01).abs() < 2e-4);
        assert!((chi2_upper_tail(124.342, 100.0) - 0.05).abs() < 2e-4);
        // χ²(2) tail is exactly e^(−x/2).
        assert!((chi2_upper_tail(7.0, 2.0) - (-3.5f64).exp()).abs() < 1e-12);
    }

    #[test]
    fn normal_tail_matches_known_values() {
        // Φ̄(1.959964) = 0.025 and Φ̄(2.326348) = 0.01 to the 7 digits given.
        assert!((normal_upper_tail(1.959_964) - 0.025).abs() < 1e-7);
        assert!((normal_upper_tail(2.326_348) - 0.01).abs() < 1e-7);
        assert!((normal_upper_tail(-1.959_964) - 0.975).abs() < 1e-7);
    }

    #[test]
    fn consistency_follows_the_tail_probability() {
        assert!(ChiSquareTest::new(60.0, 70, 9).consistent());
        assert!(!ChiSquareTest::new(200.0, 70, 9).consistent());
        assert!(chi2_upper_tail(f64::NAN, 3.0).is_nan());
    }
}
