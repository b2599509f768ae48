//! The reported 95 % intervals contain the truth about 95 % of the time over simulated
//! recordings with varied noise, pose counts, placement error and tremor (`imucal::coverage`).

use imucal::coverage::coverage;

/// Recordings per method: a few hundred fits in all.
const TRIALS: usize = 120;

#[test]
fn every_method_that_reports_sigma_covers_the_truth_about_95_percent_of_the_time() {
    let rows = coverage(TRIALS, 77);
    for row in &rows {
        // Parameters of one recording share its noise and its scale estimate, so the number of
        // independent draws lies between the recordings and the parameters. With the recordings
        // as n (the conservative choice), the 99.9 % band of a binomial(n, 0.95) proportion is
        // 0.95 ± 3.29·√(0.95·0.05/n): ±6.5 % for n = 120.
        let n = row.trials as f64;
        let band = 3.29 * (0.95 * 0.05 / n).sqrt();
        assert!(
            row.trials >= 30,
            "{}/{}: only {} recordings with σ",
            row.sensor,
            row.method,
            row.trials
        );
        let f = row.fraction();
        assert!(
            (f - 0.95).abs() <= band,
            "{}/{}: {:.1} % of {} parameters covered (band ±{:.1} %)",
            row.sensor,
            row.method,
            100.0 * f,
            row.total,
            100.0 * band
        );
    }
}
