//! The statistics the history needs: the median, and tail probabilities and quantiles of
//! Student's t distribution for outlier thresholds that follow from a stated false-alarm rate
//! (the tail from [`crate::stats::distributions::student_t_upper_tail`]).

use crate::stats::distributions::student_t_upper_tail;

/// Median of `values` (reordered); `None` when empty.
pub fn median(values: &mut [f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let n = values.len();
    Some(if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    })
}

/// `P(T > t)` for Student's t with `dof` degrees of freedom, `t ≥ 0`.
pub fn t_upper_tail(t: f64, dof: f64) -> f64 {
    student_t_upper_tail(t, dof)
}

/// The `t` with `P(T > t) = upper` (0 < upper < 0.5), by bisection on [`t_upper_tail`].
pub fn t_upper_quantile(upper: f64, dof: f64) -> f64 {
    let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
    while t_upper_tail(hi, dof) > upper && hi < 1e12 {
        hi *= 2.0;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if t_upper_tail(mid, dof) > upper {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo < 1e-12 * hi {
            break;
        }
    }
    0.5 * (lo + hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_odd_and_even_counts() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&mut [4.0, 1.0, 2.0, 3.0]), Some(2.5));
        assert_eq!(median(&mut []), None);
    }

    #[test]
    fn t_tail_matches_tables() {
        // Tabulated: t(10) 0.975 quantile 2.228139; t(1) is Cauchy, P(T>1) = 1/4.
        assert!((t_upper_tail(2.228_139, 10.0) - 0.025).abs() < 1e-6);
        assert!((t_upper_tail(1.0, 1.0) - 0.25).abs() < 1e-12);
    }

    #[test]
    fn t_quantile_tends_to_the_normal_for_many_degrees_of_freedom() {
        // Normal 0.975 quantile 1.959964; normal 1 − 1e-6 quantile 4.753424.
        assert!((t_upper_quantile(0.025, 1e7) - 1.959_964).abs() < 1e-5);
        assert!((t_upper_quantile(1e-6, 1e7) - 4.753_424).abs() < 1e-4);
        // t(5) 0.999 quantile 5.893430 (tables).
        assert!((t_upper_quantile(0.001, 5.0) - 5.893_430).abs() < 1e-5);
    }
}
