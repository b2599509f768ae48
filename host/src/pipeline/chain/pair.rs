//! Choosing between two estimators of the same unknowns (min/max and the axis-aligned ellipsoid)
//! by a paired t test on their leave-one-pose-out errors.
//!
//! On the `n` poses both models were refit without, `dᵢ = e²_min/max,i − e²_axis-aligned,i` is
//! the difference of their squared held-out norm residuals on the same pose. Their mean `d̄` is
//! exactly the difference of the two LOPO mean squares, and
//!
//! `t = d̄ / (s_d/√n)`, `s_d² = Σ(dᵢ − d̄)²/(n − 1)`, two-sided `p = 2·P(T_{n−1} ≥ |t|)`
//!
//! (Student's paired t test). Pairing removes what the poses share — how far each pose sits from
//! the others, its drift, its temperature — which dominates each model's own standard error and
//! makes an unpaired comparison of two such correlated scores blind to a consistent difference
//! and easily fooled by one outlying pose.

use crate::stats::distributions::student_t_upper_tail;

/// Significance level of the two-sided paired test: one model replaces the mean of the pair only
/// when a difference as large would arise by chance in fewer than 1 in 20 sets of poses where
/// they predict equally well. Two-sided because neither estimator is expected to be the better
/// one beforehand; the conventional 5 % because wrongly averaging costs little (the mean does no
/// worse than the average of the two, see the chain's module comment), so the test need not be
/// stricter than usual, while wrongly picking one bets the calibration on noise.
pub const PAIR_ALPHA: f64 = 0.05;

/// The paired comparison of the two 6-unknown models on their common held-out poses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairTest {
    /// Held-out poses compared.
    pub folds: usize,
    /// Mean of the per-pose differences of squared residuals, first minus second model (equal
    /// to the difference of their LOPO mean squares).
    pub mean_difference: f64,
    /// The paired t statistic (infinite when every pose differs by the same non-zero amount).
    pub t: f64,
    /// Two-sided p value with `folds − 1` degrees of freedom.
    pub p_value: f64,
}

impl PairTest {
    /// Whether the difference is significant at [`PAIR_ALPHA`].
    pub fn significant(&self) -> bool {
        self.p_value < PAIR_ALPHA
    }

    /// The p value for a sentence: three decimals, or `< 0.001`.
    pub fn p_text(&self) -> String {
        if self.p_value < 1e-3 {
            "< 0.001".into()
        } else {
            format!("= {:.3}", self.p_value)
        }
    }
}

/// Paired t test of `first` against `second` (squared errors on the same poses, in order).
/// `None` when the lengths differ or fewer than two pairs leave no degree of freedom.
pub fn paired_t(first: &[f64], second: &[f64]) -> Option<PairTest> {
    if first.len() != second.len() || first.len() < 2 {
        return None;
    }
    let d: Vec<f64> = first.iter().zip(second).map(|(a, b)| a - b).collect();
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    let var = d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let se = (var / n).sqrt();
    let t = if se > 0.0 {
        mean / se
    } else if mean == 0.0 {
        0.0
    } else {
        mean.signum() * f64::INFINITY
    };
    let p_value = (2.0 * student_t_upper_tail(t.abs(), n - 1.0)).min(1.0);
    Some(PairTest {
        folds: d.len(),
        mean_difference: mean,
        t,
        p_value,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_p_value_matches_the_t_distribution() {
        // d = 1, 2, 3, 4, 5: mean 3, sd √2.5, t = 3/(√2.5/√5) = 3√2 ≈ 4.2426 with 4 degrees
        // of freedom; two-sided p = 1 − t(4+t²)^(−1/2)·… closed form for ν = 4:
        // P(|T| ≥ t) = 1 − (t/√(4+t²))·(1 + 2/(4+t²)) = 1 − (√18/√22)(1 + 2/22).
        let first = [1.0, 2.0, 3.0, 4.0, 5.0];
        let second = [0.0; 5];
        let test = paired_t(&first, &second).expect("five pairs");
        let t = 18f64.sqrt();
        assert!((test.t - t).abs() < 1e-12);
        let want = 1.0 - (18f64 / 22.0).sqrt() * (1.0 + 2.0 / 22.0);
        assert!(
            (test.p_value - want).abs() < 1e-9,
            "{} vs {want}",
            test.p_value
        );
        assert!(test.significant());
        assert_eq!(test.mean_difference, 3.0);
    }

    #[test]
    fn differences_of_both_signs_are_not_significant() {
        let first = [1.0, 3.0, 2.0, 5.0];
        let second = [2.0, 1.0, 3.0, 4.0];
        let test = paired_t(&first, &second).expect("four pairs");
        assert!(!test.significant(), "{test:?}");
        // And swapping the models flips the sign, not the p value.
        let swapped = paired_t(&second, &first).expect("four pairs");
        assert_eq!(swapped.p_value, test.p_value);
        assert_eq!(swapped.t, -test.t);
    }

    #[test]
    fn identical_models_and_too_few_pairs() {
        let same = paired_t(&[1.0, 2.0, 3.0], &[1.0, 2.0, 3.0]).expect("three pairs");
        assert_eq!(same.p_value, 1.0);
        assert!(paired_t(&[1.0], &[0.0]).is_none());
        assert!(paired_t(&[1.0, 2.0], &[0.0]).is_none());
        // A constant non-zero difference on every pose is as significant as it gets.
        let constant = paired_t(&[2.0, 3.0, 4.0], &[1.0, 2.0, 3.0]).expect("three pairs");
        assert_eq!(constant.p_value, 0.0);
    }
}
