//! Thresholds that split a bimodal sample: Otsu's method (N. Otsu, "A threshold selection
//! method from gray-level histograms", IEEE Trans. SMC 9(1), 1979), the cut of a 256-bin
//! histogram that maximises the between-class variance `w₀·w₁·(μ₀ − μ₁)²`.

/// Otsu's threshold (maximum between-class variance) of `values` over a 256-bin histogram.
pub fn otsu(values: &[f64]) -> Option<f64> {
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !(lo.is_finite() && hi.is_finite() && hi > lo) {
        return None;
    }
    const BINS: usize = 256;
    let width = (hi - lo) / BINS as f64;
    let mut hist = [0usize; BINS];
    for v in values {
        let bin = (((v - lo) / width) as usize).min(BINS - 1);
        hist[bin] += 1;
    }
    let total = values.len() as f64;
    let centre = |i: usize| lo + (i as f64 + 0.5) * width;
    let sum_all: f64 = hist
        .iter()
        .enumerate()
        .map(|(i, &c)| c as f64 * centre(i))
        .sum();
    let (mut w0, mut sum0, mut best, mut best_t) = (0.0, 0.0, -1.0, None);
    for (i, &count) in hist.iter().enumerate().take(BINS - 1) {
        w0 += count as f64;
        sum0 += count as f64 * centre(i);
        let w1 = total - w0;
        if w0 == 0.0 || w1 == 0.0 {
            continue;
        }
        let between = w0 * w1 * (sum0 / w0 - (sum_all - sum0) / w1).powi(2);
        if between > best {
            best = between;
            best_t = Some(lo + (i as f64 + 1.0) * width);
        }
    }
    best_t
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn otsu_splits_two_separated_clusters_between_them() {
        let values: Vec<f64> = (0..100)
            .map(|i| {
                if i < 60 {
                    (i % 5) as f64 * 0.1
                } else {
                    10.0 + (i % 5) as f64 * 0.1
                }
            })
            .collect();
        let t = otsu(&values).unwrap_or(f64::NAN);
        assert!(t > 0.4 && t < 10.0, "threshold {t}");
        assert_eq!(otsu(&[1.0, 1.0]), None);
    }
}
