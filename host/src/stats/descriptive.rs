//! Descriptive statistics of samples: mean and unbiased variance, nearest-rank percentiles,
//! median and median absolute deviation, moving-window variances, and the quantisation step of
//! integer data.

use super::Vec3;

/// Per-axis mean of `x` (zero for no samples).
pub fn mean(x: &[Vec3]) -> Vec3 {
    x.iter().sum::<Vec3>() / x.len().max(1) as f64
}

/// Mean `x̄ = Σxᵢ/n` and unbiased per-axis variance `s² = Σ(xᵢ − x̄)²/(n − 1)` (zero for one
/// sample) of the samples, with their count; `None` for no samples. Two passes, so large
/// offsets do not cancel digits.
pub fn mean_variance<'a>(
    samples: impl Iterator<Item = &'a Vec3> + Clone,
) -> Option<(Vec3, Vec3, usize)> {
    let n = samples.clone().count();
    if n == 0 {
        return None;
    }
    let m = samples.clone().sum::<Vec3>() / n as f64;
    let var = if n > 1 {
        samples
            .map(|x| (x - m).component_mul(&(x - m)))
            .sum::<Vec3>()
            / (n - 1) as f64
    } else {
        Vec3::zeros()
    };
    Some((m, var, n))
}

/// Value at fraction `p` of a list (nearest rank).
pub fn percentile(values: &mut [f64], p: f64) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let rank = (((values.len() - 1) as f64 * p).round() as usize).min(values.len() - 1);
    // Selection, not a sort: linear time, and the same order statistic.
    *values.select_nth_unstable_by(rank, f64::total_cmp).1
}

/// [`percentile`] of values that are all greater than zero, given as their bit patterns
/// ([`f64::to_bits`]). For such values the bit patterns, read as unsigned integers, are in the
/// order of [`f64::total_cmp`], so selecting on the integers gives the same order statistic, bit
/// for bit, with a plain integer comparison instead of the float's total-order key at every step.
pub fn percentile_of_positive_bits(bits: &mut [u64], p: f64) -> f64 {
    if bits.is_empty() {
        return 0.0;
    }
    let rank = (((bits.len() - 1) as f64 * p).round() as usize).min(bits.len() - 1);
    f64::from_bits(*bits.select_nth_unstable(rank).1)
}

/// Median of a list: the middle value, or the mean of the two middle values for an even count
/// (0 when empty).
pub fn median(values: &mut [f64]) -> f64 {
    let n = values.len();
    if n == 0 {
        return 0.0;
    }
    // Selection, not a sort: the upper middle value, then the largest of the values below it.
    let (below, upper, _) = values.select_nth_unstable_by(n / 2, f64::total_cmp);
    let upper = *upper;
    if n % 2 == 1 {
        upper
    } else {
        let lower = below.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        0.5 * (lower + upper)
    }
}

/// Median absolute deviation scaled to a standard deviation, `1.4826·median|xᵢ − median(x)|`
/// (consistent for Gaussian data: `1/Φ⁻¹(3/4) = 1.4826`; Rousseeuw & Croux 1993). Unlike the
/// sample standard deviation, up to half of the values can be outliers without moving it.
pub fn mad_sigma(values: &[f64]) -> f64 {
    let mut sorted = values.to_vec();
    let centre = median(&mut sorted);
    let mut deviations: Vec<f64> = values.iter().map(|v| (v - centre).abs()).collect();
    1.482_6 * median(&mut deviations)
}

/// Per-window variance of each axis for windows starting at `0..=n−w` (two-pass per window
/// via prefix sums of values centred on the global mean, which keeps large raw offsets from
/// cancelling digits). Only the last `w + 1` prefix sums are kept (a ring), not all `n + 1`:
/// the same sums in the same order, without two more arrays the length of the recording.
pub fn window_variances(x: &[Vec3], w: usize) -> Vec<Vec3> {
    let mut out = Vec::with_capacity((x.len() + 1).saturating_sub(w));
    for_each_window_variance(x, w, |v| out.push(v));
    out
}

/// [`window_variances`] handed to `each` in window order instead of collected: a caller that
/// reduces them as they come needs no array the length of the recording.
pub fn for_each_window_variance(x: &[Vec3], w: usize, each: impl FnMut(Vec3)) {
    sliding_variances(x.len(), |i| x[i], w, each);
}

/// Axis `k` of [`for_each_window_variance`], bit for bit (each axis of the vector form is
/// computed by the same operations in the same order, alone), at a third of its cost.
pub fn for_each_axis_window_variance(x: &[Vec3], k: usize, w: usize, each: impl FnMut(f64)) {
    sliding_variances(x.len(), |i| x[i][k], w, each);
}

/// What the sliding variance needs of a value: one number, or one vector of axes treated
/// alike and independently.
trait Lanes: Copy + std::ops::Add<Output = Self> + std::ops::Sub<Output = Self> {
    fn zero() -> Self;
    /// Each lane squared.
    fn squared(self) -> Self;
    /// Each lane divided by `d`.
    fn over(self, d: f64) -> Self;
    /// Each lane `(v/d).max(0)`: rounding can leave a tiny negative sum of squares.
    fn unbiased_over(self, d: f64) -> Self;
}

impl Lanes for f64 {
    fn zero() -> Self {
        0.0
    }
    fn squared(self) -> Self {
        self * self
    }
    fn over(self, d: f64) -> Self {
        self / d
    }
    fn unbiased_over(self, d: f64) -> Self {
        (self / d).max(0.0)
    }
}

impl Lanes for Vec3 {
    fn zero() -> Self {
        Vec3::zeros()
    }
    fn squared(self) -> Self {
        self.component_mul(&self)
    }
    fn over(self, d: f64) -> Self {
        self / d
    }
    fn unbiased_over(self, d: f64) -> Self {
        self.map(|v| (v / d).max(0.0))
    }
}

/// The windowed variances of the `n` values `value(i)` (see [`window_variances`]).
fn sliding_variances<T: Lanes>(
    n: usize,
    value: impl Fn(usize) -> T,
    w: usize,
    mut each: impl FnMut(T),
) {
    if n < w || w < 2 {
        return;
    }
    let mean = (0..n)
        .fold(T::zero(), |acc, i| acc + value(i))
        .over(n as f64);
    let wf = w as f64;
    // Slot `i % (w + 1)` holds the prefix sums of the first `i` values. The slot is counted
    // along rather than divided out: two integer divisions per row cost more than the sums.
    let mut s1 = vec![T::zero(); w + 1];
    let mut s2 = vec![T::zero(); w + 1];
    let (mut p1, mut p2) = (T::zero(), T::zero());
    let next_slot = |slot: usize| if slot == w { 0 } else { slot + 1 };
    let mut slot = 0;
    for i in 0..=n {
        if i > 0 {
            let d = value(i - 1) - mean;
            p1 = p1 + d;
            p2 = p2 + d.squared();
        }
        if i >= w {
            // The window starts at row `i − w`, whose slot `(i − w) % (w + 1)` is the one after
            // `i`'s; it is read before slot `i % (w + 1)` is overwritten.
            let start = next_slot(slot);
            let sum = p1 - s1[start];
            let sq = p2 - s2[start];
            each((sq - sum.squared().over(wf)).unbiased_over(wf - 1.0));
        }
        s1[slot] = p1;
        s2[slot] = p2;
        slot = next_slot(slot);
    }
}

/// Smallest positive step between consecutive samples on each axis (the quantisation step
/// for integer or fixed-point data), used as a floor for the noise estimate.
pub fn quantisation_step(x: &[Vec3]) -> Vec3 {
    let mut step = Vec3::repeat(f64::INFINITY);
    for w in x.windows(2) {
        for k in 0..3 {
            let d = (w[1][k] - w[0][k]).abs();
            if d > 0.0 && d < step[k] {
                step[k] = d;
            }
        }
    }
    step.map(|s| if s.is_finite() { s } else { 0.0 })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_variances_equal_the_direct_unbiased_variance() {
        // A large offset must not cost digits: 1e6 + {0, 1, 2, 3}, variance 5/3 exactly.
        let x: Vec<Vec3> = (0..6).map(|i| Vec3::repeat(1e6 + (i % 4) as f64)).collect();
        let v = window_variances(&x, 4);
        assert_eq!(v.len(), 3);
        assert!((v[0].x - 5.0 / 3.0).abs() < 1e-9);
        let direct = mean_variance(x[1..5].iter()).map(|(_, var, _)| var.x);
        assert!((v[1].x - direct.unwrap_or(f64::NAN)).abs() < 1e-9);
    }

    #[test]
    fn ring_window_variances_equal_the_full_prefix_sums_bit_for_bit() {
        // The form with every prefix sum kept, as it was first written.
        fn reference(x: &[Vec3], w: usize) -> Vec<Vec3> {
            let n = x.len();
            let mean = x.iter().sum::<Vec3>() / n as f64;
            let mut s1 = vec![Vec3::zeros(); n + 1];
            let mut s2 = vec![Vec3::zeros(); n + 1];
            for (i, v) in x.iter().enumerate() {
                let d = v - mean;
                s1[i + 1] = s1[i] + d;
                s2[i + 1] = s2[i] + d.component_mul(&d);
            }
            let wf = w as f64;
            (0..=n - w)
                .map(|s| {
                    let sum = s1[s + w] - s1[s];
                    let sq = s2[s + w] - s2[s];
                    (sq - sum.component_mul(&sum) / wf).map(|v| (v / (wf - 1.0)).max(0.0))
                })
                .collect()
        }
        let mut state: u64 = 0x9E37_79B9_7F4A_7C15;
        let mut next = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let x: Vec<Vec3> = (0..2000)
            .map(|i| Vec3::new(9.8 + next(), 1e4 * (i as f64 * 0.01).sin(), next() - 0.5))
            .collect();
        for w in [2, 5, 50, 1999, 2000, 2001] {
            let got = window_variances(&x, w);
            if w > x.len() {
                assert!(got.is_empty());
                continue;
            }
            let want = reference(&x, w);
            assert_eq!(got.len(), want.len());
            for (g, e) in got.iter().zip(&want) {
                for k in 0..3 {
                    assert_eq!(g[k].to_bits(), e[k].to_bits(), "w = {w}");
                }
            }
        }
    }

    #[test]
    fn one_axis_of_the_window_variances_equals_that_axis_of_the_vector_form_bit_for_bit() {
        // Still detection selects its noise percentile from one axis at a time: it must see
        // exactly the values the three-axis form gives, offsets and rounding included.
        let x: Vec<Vec3> = (0..3000)
            .map(|i| {
                let t = i as f64 * 0.013;
                Vec3::new(
                    1e6 + (t * 7.0).sin(),
                    -9.81 + 1e-3 * (t * 31.0).cos(),
                    ((i * 7919) % 13) as f64,
                )
            })
            .collect();
        for w in [2, 5, 51, 2999, 3000, 3001] {
            let vector = window_variances(&x, w);
            for k in 0..3 {
                let mut axis = Vec::new();
                for_each_axis_window_variance(&x, k, w, |v| axis.push(v.to_bits()));
                let want: Vec<u64> = vector.iter().map(|v| v[k].to_bits()).collect();
                assert_eq!(axis, want, "w = {w}, axis {k}");
            }
        }
    }

    #[test]
    fn median_and_mad_ignore_a_gross_outlier() {
        let mut values = vec![1.0, 2.0, 3.0, 4.0, 1e5];
        assert_eq!(median(&mut values), 3.0);
        // |x − 3| = {2, 1, 0, 1, ~1e5}: median 1, so σ = 1.4826.
        assert!((mad_sigma(&[1.0, 2.0, 3.0, 4.0, 1e5]) - 1.4826).abs() < 1e-12);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
    }

    #[test]
    fn median_and_percentile_by_selection_equal_the_sorted_order_statistics() {
        let mut state: u64 = 0x2545_F491_4F6C_DD1D;
        for n in 1..60 {
            let values: Vec<f64> = (0..n)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    // Few distinct values, so ties are common.
                    (state % 17) as f64 - 8.0
                })
                .collect();
            let mut sorted = values.clone();
            sorted.sort_by(f64::total_cmp);
            let expected_median = if n % 2 == 1 {
                sorted[n / 2]
            } else {
                0.5 * (sorted[n / 2 - 1] + sorted[n / 2])
            };
            assert_eq!(median(&mut values.clone()), expected_median, "n = {n}");
            for p in [0.0, 0.1, 0.5, 0.9, 1.0] {
                let rank = ((n - 1) as f64 * p).round() as usize;
                assert_eq!(
                    percentile(&mut values.clone(), p),
                    sorted[rank],
                    "n = {n}, p = {p}"
                );
            }
        }
    }

    #[test]
    fn percentile_on_positive_bits_equals_the_float_percentile_bit_for_bit() {
        let mut state: u64 = 0x0123_4567_89AB_CDEF;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        // Ties, subnormals, huge values and infinity among ordinary positive numbers.
        let pool = [
            f64::MIN_POSITIVE,
            5e-324,
            1e-300,
            1.0,
            2.5,
            1e300,
            f64::INFINITY,
        ];
        for n in (1..80).chain([1000, 4097]) {
            let values: Vec<f64> = (0..n)
                .map(|_| {
                    let r = next();
                    if r % 3 == 0 {
                        pool[(r >> 8) as usize % pool.len()]
                    } else {
                        ((r >> 11) as f64 / (1u64 << 53) as f64 + 1e-9) * 10f64.powi((r % 7) as i32)
                    }
                })
                .collect();
            for p in [0.0, 0.001, 0.1, 0.5, 0.9, 0.999, 1.0] {
                let want = percentile(&mut values.clone(), p);
                let mut bits: Vec<u64> = values.iter().map(|v| v.to_bits()).collect();
                let got = percentile_of_positive_bits(&mut bits, p);
                assert_eq!(got.to_bits(), want.to_bits(), "n = {n}, p = {p}");
            }
        }
        assert_eq!(percentile_of_positive_bits(&mut [], 0.5), 0.0);
    }

    #[test]
    fn quantisation_step_is_the_smallest_nonzero_change() {
        let x = [
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(3.0, 0.5, 1.0),
            Vec3::new(5.0, 0.0, 1.0),
        ];
        assert_eq!(quantisation_step(&x), Vec3::new(2.0, 0.5, 0.0));
    }
}
