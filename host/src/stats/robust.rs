//! Screening of gross outliers (a spike, a corrupted read) from a set of samples that should
//! scatter about one value: median and MAD with a Bonferroni bound; and from a stream taken
//! while turning, by the same bound on the deviations from a running median
//! ([`screen_stream`]).
//!
//! Centre `m = median(x)`, scale `σ̂ = 1.4826·median|xᵢ − m|` (Rousseeuw & Croux 1993): both
//! ignore up to half the values being wrong, unlike the mean and standard deviation a spike
//! drags along. A value is dropped when `|xᵢ − m| > k·σ` with `k = Φ⁻¹(1 − α/(2N))` for `N`
//! tests (every value of every axis): by Bonferroni's inequality a set of Gaussian values loses
//! any value with probability at most `α` ([`FAMILY_FALSE_DROP`]), whatever its size. So clean
//! data keeps its plain mean and variance, while a spike of any size is removed whole; a robust
//! M-estimate (Huber) would also bound the spike's pull, but keeps no account of what was
//! rejected, which the warnings name.
//!
//! Two guards keep the bound from biting on clean data: `σ̂` of few values can come out small
//! by chance (its standard error is `1.166σ/√n` for Gaussian data), so `σ = σ̂/(1 − 2·1.166/√n)`
//! (at most twice `σ̂`), the value two standard errors below which `σ̂` rarely falls; and a
//! quantised sensor whose readings mostly repeat has `σ̂ = 0`, so `σ` is at least the data's
//! resolution (one step: a reading a few steps from the median is noise, not a spike).

use super::descriptive::{mad_sigma, quantisation_step};
use super::distributions::normal_quantile;
use super::Vec3;

/// Probability that a clean set of Gaussian samples loses any sample to the screen.
pub const FAMILY_FALSE_DROP: f64 = 0.01;

/// Fewer values than this are not screened: the median and MAD of a handful say little.
pub const MIN_SCREENED: usize = 10;

/// Asymptotic standard error of the normalised MAD, in units of `σ/√n`, for Gaussian data.
const MAD_STANDARD_ERROR: f64 = 1.166;

/// What the screen decided for a set of samples.
#[derive(Debug, Clone, PartialEq)]
pub struct Screening {
    /// Per sample: kept (`true`) or dropped.
    pub keep: Vec<bool>,
    /// Number of samples dropped.
    pub dropped: usize,
    /// The bound `k`, in standard deviations.
    pub bound_sigmas: f64,
    /// Largest deviation of a dropped sample from the median, in standard deviations (0 when
    /// nothing was dropped).
    pub worst_sigmas: f64,
}

impl Screening {
    /// Everything kept (too few values to screen).
    fn keep_all(n: usize) -> Self {
        Self {
            keep: vec![true; n],
            dropped: 0,
            bound_sigmas: f64::INFINITY,
            worst_sigmas: 0.0,
        }
    }

    /// The verdict on samples whose largest deviations, in standard deviations, are `worst`:
    /// those beyond `bound` are dropped.
    fn from_worst(worst: &[f64], bound: f64) -> Self {
        let keep: Vec<bool> = worst.iter().map(|z| *z <= bound).collect();
        let dropped = keep.iter().filter(|k| !**k).count();
        let worst_sigmas = worst
            .iter()
            .filter(|z| **z > bound)
            .fold(0.0_f64, |a, z| a.max(*z));
        Self {
            keep,
            dropped,
            bound_sigmas: bound,
            worst_sigmas,
        }
    }

    /// The kept values of `values` (the slice the screening was computed on).
    pub fn kept<T: Copy>(&self, values: &[T]) -> Vec<T> {
        values
            .iter()
            .zip(&self.keep)
            .filter(|(_, k)| **k)
            .map(|(v, _)| *v)
            .collect()
    }
}

/// Bound `k = Φ⁻¹(1 − α/(2·tests))` in standard deviations.
pub fn bonferroni_bound(tests: usize) -> f64 {
    normal_quantile(1.0 - FAMILY_FALSE_DROP / (2.0 * tests.max(1) as f64))
}

/// Centre and guarded scale (see the module comment) of the values `values()` yields, with
/// `resolution` as the scale's floor. The medians are selected in `scratch` (filled in the
/// values' order, its old contents dropped), one buffer for both and for every axis instead of
/// two copies of the values per axis.
fn centre_and_scale<I: Iterator<Item = f64>>(
    values: impl Fn() -> I,
    resolution: f64,
    scratch: &mut Vec<i64>,
) -> (f64, f64) {
    let key = |v: f64| total_order_key(v.to_bits() as i64);
    scratch.clear();
    scratch.extend(values().map(key));
    let n = scratch.len();
    let centre = median_of_keys(scratch);
    scratch.clear();
    scratch.extend(values().map(|v| key((v - centre).abs())));
    let mad = 1.482_6 * median_of_keys(scratch);
    let shrink = (1.0 - 2.0 * MAD_STANDARD_ERROR / (n as f64).sqrt()).max(0.5);
    (centre, (mad / shrink).max(resolution))
}

/// [`screen_axes_by`] of axes given as vectors of equal lengths.
#[cfg(test)]
fn screen_axes(axes: &[Vec<f64>], resolution: &[f64]) -> Screening {
    let n = axes.first().map_or(0, Vec::len);
    screen_axes_by(axes.len(), n, |k| axes[k].iter().copied(), resolution)
}

/// Screen `axes` axes of `n` samples each, the values of axis `k` in sample order being
/// `values(k)`, with one Bonferroni bound over all their values; a sample is dropped when any
/// axis is beyond it. The values are read where they are, not copied into a vector per axis,
/// and as iterators rather than by index, so that the passes over them need no bounds checks.
fn screen_axes_by<I: Iterator<Item = f64>>(
    axes: usize,
    n: usize,
    values: impl Fn(usize) -> I,
    resolution: &[f64],
) -> Screening {
    if n < MIN_SCREENED {
        return Screening::keep_all(n);
    }
    let mut screen = AxisScreen::new(axes, n);
    for (k, &floor) in (0..axes).zip(resolution) {
        screen.add_axis(|| values(k), floor);
    }
    screen.finish()
}

/// The screen of [`screen_axes_by`] fed one axis at a time, so that values computed per axis
/// (a stream's deviations) need only one axis in memory at once.
struct AxisScreen {
    /// The Bonferroni bound over every value of every axis.
    bound: f64,
    /// Per sample, its largest deviation so far in standard deviations.
    worst: Vec<f64>,
    /// Selection buffer of [`centre_and_scale`], shared by the axes.
    scratch: Vec<i64>,
}

impl AxisScreen {
    /// A screen of `axes` axes of `n` samples each (at least [`MIN_SCREENED`]).
    fn new(axes: usize, n: usize) -> Self {
        Self {
            bound: bonferroni_bound(n * axes),
            worst: vec![0.0; n],
            scratch: Vec::with_capacity(n),
        }
    }

    /// Screen the axis whose values in sample order are `values()` (one per sample), its
    /// scale floored at `floor`.
    fn add_axis<I: Iterator<Item = f64>>(&mut self, values: impl Fn() -> I, floor: f64) {
        let (centre, sigma) = centre_and_scale(&values, floor, &mut self.scratch);
        if !(sigma > 0.0 && sigma.is_finite()) {
            return;
        }
        for (w, v) in self.worst.iter_mut().zip(values()) {
            // A non-finite reading is dropped: it would poison every statistic.
            let z = if v.is_finite() {
                (v - centre).abs() / sigma
            } else {
                f64::INFINITY
            };
            *w = w.max(z);
        }
    }

    /// What the screen decided over the axes added.
    fn finish(self) -> Screening {
        Screening::from_worst(&self.worst, self.bound)
    }
}

/// Screen scalar values; `resolution` is the smallest meaningful difference (0 when unknown).
pub fn screen_scalars(values: &[f64], resolution: f64) -> Screening {
    screen_axes_by(1, values.len(), |_| values.iter().copied(), &[resolution])
}

/// Screen 3-vector samples axis by axis (one bound over the `3n` tests), each axis's scale
/// floored at its quantisation step.
pub fn screen_vectors(samples: &[Vec3]) -> Screening {
    let step = quantisation_step(samples);
    screen_axes_by(
        3,
        samples.len(),
        |k| samples.iter().map(move |v| v[k]),
        &[step.x, step.y, step.z],
    )
}

/// Half-width of the running median of [`screen_stream`]: six neighbours follow a turning
/// board's smooth path, and a spike of up to two samples cannot move their median far.
const STREAM_HALF_WINDOW: usize = 3;

// `screen_stream`'s interior takes the six neighbours of a window of seven by position.
const _: () = assert!(STREAM_HALF_WINDOW == 3);

/// Screen a stream of 3-vector samples taken while the board turns (the magnetometer's
/// tumble), where no single value is expected: each sample's deviation from the median of the
/// six around it (Hampel's identifier; Pearson, "Outliers in process modeling and
/// identification", IEEE TCST 10(1), 2002), screened axis by axis like [`screen_vectors`] with
/// one robust scale per axis for the whole stream. A smooth path leaves the deviations at the
/// noise; a spike stands out by its own size.
///
/// Rows that repeat the reading before them (a logger writing a slower sensor into faster rows,
/// each reading held until the next) are one reading: screened once, and their rows share its
/// verdict. Screened row by row, the neighbours of a held reading would mostly be itself, the
/// scale would collapse to the resolution, and every change of reading would look like a spike.
pub fn screen_stream(samples: &[Vec3]) -> Screening {
    let repeats = samples
        .windows(2)
        .filter(|w| same_reading(&w[0], &w[1]))
        .count();
    if repeats == 0 {
        return screen_distinct_stream(samples);
    }
    let mut distinct: Vec<Vec3> = Vec::with_capacity(samples.len() - repeats);
    let mut run_lengths: Vec<usize> = Vec::with_capacity(samples.len() - repeats);
    for s in samples {
        match (distinct.last(), run_lengths.last_mut()) {
            (Some(last), Some(length)) if same_reading(last, s) => *length += 1,
            _ => {
                distinct.push(*s);
                run_lengths.push(1);
            }
        }
    }
    let screened = screen_distinct_stream(&distinct);
    let keep: Vec<bool> = screened
        .keep
        .iter()
        .zip(&run_lengths)
        .flat_map(|(&k, &length)| std::iter::repeat_n(k, length))
        .collect();
    let dropped = keep.iter().filter(|k| !**k).count();
    Screening {
        keep,
        dropped,
        ..screened
    }
}

/// Whether two rows carry the same reading, bit for bit.
fn same_reading(a: &Vec3, b: &Vec3) -> bool {
    a.iter()
        .zip(b.iter())
        .all(|(x, y)| x.to_bits() == y.to_bits())
}

/// [`screen_stream`] of a stream without repeated rows.
fn screen_distinct_stream(samples: &[Vec3]) -> Screening {
    let n = samples.len();
    if n < MIN_SCREENED.max(2 * STREAM_HALF_WINDOW + 1) {
        return Screening::keep_all(n);
    }
    let step = quantisation_step(samples);
    // One axis's deviations at a time, in one buffer: the axes are screened independently
    // under the common bound.
    let mut screen = AxisScreen::new(3, n);
    let mut deviations = Vec::with_capacity(n);
    for (k, floor) in [step.x, step.y, step.z].into_iter().enumerate() {
        // The screen's selection buffer holds the axis's keys until its medians need it.
        stream_deviations(samples, k, &mut screen.scratch, &mut deviations);
        screen.add_axis(|| deviations.iter().copied(), floor);
    }
    screen.finish()
}

/// Spread of a deviation from the median of six neighbours over that of one sample's noise:
/// the median of six normal values has a variance of about 0.215 σ², so the deviation's is
/// about 1.215 σ².
const NEIGHBOUR_DEVIATION_SPREAD: f64 = 1.102;

/// Raw samples per run of [`stream_noise`], and the most runs it takes.
const NOISE_RUN: usize = 2000;
const NOISE_RUNS: usize = 20;

/// A stream's noise per sample and axis, as a standard deviation: the robust spread of each
/// sample's deviation from the median of its six neighbours (on a smooth turn that is the
/// sensor's noise; the path's curvature between neighbours adds a little, so it errs high),
/// combined with the quantisation's own `step/√12`, which a spread of whole steps misses when
/// the noise is below one step. Rows that repeat the reading before them (a logger writing a
/// slower sensor into faster rows) are read once: repeats would make neighbours equal the
/// sample. At most [`NOISE_RUNS`] evenly spaced runs of [`NOISE_RUN`] rows are used, which
/// fix the spread to about 1 % at a fixed cost. `None` when too few distinct readings.
pub fn stream_noise(samples: &[Vec3]) -> Option<Vec3> {
    let n = samples.len();
    let runs = n.div_ceil(NOISE_RUN).clamp(1, NOISE_RUNS);
    let length = n.min(NOISE_RUN);
    let mut deviations: [Vec<f64>; 3] = Default::default();
    let mut step = Vec3::repeat(f64::INFINITY);
    let (mut keys, mut out) = (Vec::new(), Vec::new());
    for run in 0..runs {
        let start = if runs > 1 {
            run * (n - length) / (runs - 1)
        } else {
            0
        };
        let mut distinct: Vec<Vec3> = samples[start..start + length].to_vec();
        distinct.dedup_by(|a, b| same_reading(a, b));
        if distinct.len() < 2 * STREAM_HALF_WINDOW + 1 {
            continue;
        }
        let run_step = quantisation_step(&distinct);
        for k in 0..3 {
            if run_step[k] > 0.0 {
                step[k] = step[k].min(run_step[k]);
            }
            stream_deviations(&distinct, k, &mut keys, &mut out);
            deviations[k].extend(out.iter().copied().filter(|d| d.is_finite()));
        }
    }
    if deviations.iter().any(|d| d.len() < MIN_SCREENED) {
        return None;
    }
    let sigma = |k: usize| {
        let spread = mad_sigma(&deviations[k]) / NEIGHBOUR_DEVIATION_SPREAD;
        let quantum = if step[k].is_finite() { step[k] } else { 0.0 };
        (spread * spread + quantum * quantum / 12.0).sqrt()
    };
    Some(Vec3::new(sigma(0), sigma(1), sigma(2)))
}

/// Each sample's deviation on axis `k` from the median of its neighbours (see
/// [`screen_stream`]), into `out` (its old contents dropped); `keys` is scratch space for the
/// axis's [`total_order_key`]s, each computed once rather than in every window that holds it.
fn stream_deviations(samples: &[Vec3], k: usize, keys: &mut Vec<i64>, out: &mut Vec<f64>) {
    let n = samples.len();
    let h = STREAM_HALF_WINDOW;
    // The neighbours without the sample itself: on a steady turn the sample would be its own
    // window's median, and the deviations would collapse to 0. They live on the stack: one
    // heap vector per sample and axis cost more than the median itself on a long stream.
    let at_edge = |i: usize| {
        let mut neighbours = [0.0; 2 * STREAM_HALF_WINDOW];
        let mut len = 0;
        for j in (i.saturating_sub(h)..(i + h + 1).min(n)).filter(|&j| j != i) {
            neighbours[len] = samples[j][k];
            len += 1;
        }
        samples[i][k] - small_median(&mut neighbours[..len])
    };
    out.clear();
    out.extend((0..h).map(at_edge));
    // The interior: the same six neighbours, from one window of keys.
    keys.clear();
    keys.extend(
        samples
            .iter()
            .map(|v| total_order_key(v[k].to_bits() as i64)),
    );
    out.extend(
        keys.windows(2 * h + 1)
            .zip(&samples[h..])
            .map(|(w, x)| x[k] - median_of_six_keys([w[0], w[1], w[2], w[4], w[5], w[6]])),
    );
    out.extend((n - h..n).map(at_edge));
}

/// [`median`] of the values whose [`total_order_key`]s are `keys`, bit for bit: the keys are
/// in [`f64::total_cmp`]'s order, so selection on them finds the same upper middle value (an
/// order statistic of a total order is one bit pattern), and the lower middle is taken as
/// `median` takes it, by [`f64::max`] over the same values below it. Integer comparisons
/// instead of the float's total-order key at every step of the selection.
///
/// [`median`]: super::descriptive::median
fn median_of_keys(keys: &mut [i64]) -> f64 {
    let n = keys.len();
    if n == 0 {
        return 0.0;
    }
    let value = |k: i64| f64::from_bits(total_order_key(k) as u64);
    let (below, upper, _) = keys.select_nth_unstable(n / 2);
    let upper = value(*upper);
    if n % 2 == 1 {
        upper
    } else {
        let lower = below
            .iter()
            .map(|k| value(*k))
            .fold(f64::NEG_INFINITY, f64::max);
        0.5 * (lower + upper)
    }
}

/// [`median`] of a handful of values, bit for bit: a sort in the same total order
/// ([`f64::total_cmp`]) puts the same value at the upper middle as selection does, and the lower
/// middle is taken as [`median`] takes it (the largest by [`f64::max`] of the values below).
///
/// [`median`]: super::descriptive::median
fn small_median(values: &mut [f64]) -> f64 {
    let n = values.len();
    if n == 0 {
        return 0.0;
    }
    if let Ok(six) = <&mut [f64; 6]>::try_from(&mut *values) {
        sort_six(six);
    } else {
        insertion_sort(values);
    }
    let upper = values[n / 2];
    if n % 2 == 1 {
        upper
    } else {
        let lower = values[..n / 2]
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max);
        0.5 * (lower + upper)
    }
}

/// [`small_median`] of the six values whose [`total_order_key`]s are `keys`, bit for bit: the
/// same network on the keys, then the same upper middle and the same lower middle by
/// [`f64::max`].
fn median_of_six_keys(mut keys: [i64; 6]) -> f64 {
    sort_six_keys(&mut keys);
    let value = |k: i64| f64::from_bits(total_order_key(k) as u64);
    let upper = value(keys[3]);
    let lower = [keys[0], keys[1], keys[2]]
        .map(value)
        .into_iter()
        .fold(f64::NEG_INFINITY, f64::max);
    0.5 * (lower + upper)
}

/// The key of a value with `bits` in [`f64::total_cmp`]'s order as a signed integer (the same
/// map that function uses; applying it twice gives the bits back).
fn total_order_key(bits: i64) -> i64 {
    bits ^ (((bits >> 63) as u64) >> 1) as i64
}

/// Sort six values in [`f64::total_cmp`]'s order with a 12-comparator network on their integer
/// keys: no data-dependent branches, unlike a comparison sort, on the interior of every stream.
fn sort_six(values: &mut [f64; 6]) {
    let mut keys = values.map(|v| total_order_key(v.to_bits() as i64));
    sort_six_keys(&mut keys);
    *values = keys.map(|k| f64::from_bits(total_order_key(k) as u64));
}

/// [`SIX_NETWORK`] applied to six keys.
fn sort_six_keys(keys: &mut [i64; 6]) {
    for (a, b) in SIX_NETWORK {
        let (lo, hi) = (keys[a].min(keys[b]), keys[a].max(keys[b]));
        keys[a] = lo;
        keys[b] = hi;
    }
}

/// An optimal sorting network for six inputs (Knuth, TAOCP vol. 3, §5.3.4).
const SIX_NETWORK: [(usize, usize); 12] = [
    (0, 5),
    (1, 3),
    (2, 4),
    (1, 2),
    (3, 4),
    (0, 3),
    (2, 5),
    (0, 1),
    (2, 3),
    (4, 5),
    (1, 2),
    (3, 4),
];

/// Sort a few values in [`f64::total_cmp`]'s order.
fn insertion_sort(values: &mut [f64]) {
    let n = values.len();
    for i in 1..n {
        let mut j = i;
        while j > 0 && values[j - 1].total_cmp(&values[j]).is_gt() {
            values.swap(j - 1, j);
            j -= 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::descriptive::median;

    /// A smooth turn through a sphere of radius 50 with white noise `sigma` per axis, each
    /// reading written `repeat` times.
    fn noisy_turn(sigma: f64, repeat: usize) -> Vec<Vec3> {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let noise = Normal::new(0.0, sigma).expect("valid sigma");
        (0..20_000)
            .map(|i| {
                let t = f64::from(i) / 100.0;
                let (polar, azimuth) = (1.5 + 0.5 * (t / 9.0).sin(), t * 0.8);
                50.0 * Vec3::new(
                    polar.sin() * azimuth.cos(),
                    polar.sin() * azimuth.sin(),
                    polar.cos(),
                ) + Vec3::from_fn(|_, _| noise.sample(&mut rng))
            })
            .flat_map(|v| std::iter::repeat_n(v, repeat))
            .collect()
    }

    #[test]
    fn stream_noise_finds_the_noise_of_a_turn_and_ignores_repeated_rows() {
        // 20 runs of 2000 rows: about 40 000 deviations per axis, so the spread is known to a
        // few per cent; 10 % covers that and the curvature's share.
        for repeat in [1, 8] {
            let noise = stream_noise(&noisy_turn(0.4, repeat)).expect("enough readings");
            for k in 0..3 {
                assert!(
                    (noise[k] / 0.4 - 1.0).abs() < 0.1,
                    "repeat {repeat}: {noise:?}"
                );
            }
        }
        assert!(stream_noise(&[Vec3::zeros(); 500]).is_none());
    }

    #[test]
    fn a_stream_of_held_readings_loses_only_its_spike_with_all_its_rows() {
        // Each reading held for 5 rows (a 20 Hz magnetometer in 100 Hz rows). Screened row by
        // row, most samples equalled their neighbours' median and every change of reading was
        // called a spike (43 % of a real recording's rows). One reading made a spike: its 5
        // rows go, nothing else, as on the stream read once per reading.
        let mut held = noisy_turn(0.4, 5);
        for row in &mut held[5000..5005] {
            row.x += 40.0;
        }
        let screening = screen_stream(&held);
        assert_eq!(screening.dropped, 5, "{screening:?}");
        assert!(screening.keep[..5000].iter().all(|k| *k));
        assert!(screening.keep[5000..5005].iter().all(|k| !*k));
        let mut once: Vec<Vec3> = held.clone();
        once.dedup_by(|a, b| same_reading(a, b));
        let alone = screen_stream(&once);
        assert_eq!(alone.dropped, 1);
        assert_eq!(alone.bound_sigmas, screening.bound_sigmas);
    }

    /// Standard normal numbers from a seeded generator.
    fn gaussian(seed: u64, n: usize) -> Vec<f64> {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        (0..n).map(|_| StandardNormal.sample(&mut rng)).collect()
    }

    fn noisy_vectors(seed: u64, n: usize, sigma: f64) -> Vec<Vec3> {
        let (x, y, z) = (
            gaussian(seed, n),
            gaussian(seed + 1, n),
            gaussian(seed + 2, n),
        );
        (0..n)
            .map(|i| {
                Vec3::new(
                    20.0 + sigma * x[i],
                    -5.0 + sigma * y[i],
                    40.0 + sigma * z[i],
                )
            })
            .collect()
    }

    #[test]
    fn small_median_equals_median_by_selection_bit_for_bit() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(17);
        // Few distinct values (ties), signed zeros and wide magnitudes, every length up to six.
        let pool = [0.0, -0.0, 1.0, -1.0, 2.5, 1e300, -3e-300, 7.0];
        for _ in 0..20_000 {
            let len = rng.gen_range(0..=2 * STREAM_HALF_WINDOW);
            let values: Vec<f64> = (0..len)
                .map(|_| {
                    if rng.gen_bool(0.5) {
                        pool[rng.gen_range(0..pool.len())]
                    } else {
                        rng.gen_range(-10.0..10.0)
                    }
                })
                .collect();
            let expected = median(&mut values.clone());
            let got = small_median(&mut values.clone());
            assert_eq!(got.to_bits(), expected.to_bits(), "{values:?}");
        }
    }

    /// Ties, signed zeros, infinities, NaNs of both signs and wide magnitudes: the values on
    /// which orders and maxima of floats disagree.
    const SPECIAL_VALUES: [f64; 11] = [
        0.0,
        -0.0,
        1.0,
        -1.0,
        2.5,
        1e300,
        -3e-300,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NAN,
        -f64::NAN,
    ];

    #[test]
    fn median_of_six_keys_equals_median_by_selection_bit_for_bit() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(23);
        // Drawn mostly from the special values: sets with three NaNs below the middle too.
        let pool = SPECIAL_VALUES;
        for _ in 0..20_000 {
            let values: [f64; 6] = std::array::from_fn(|_| {
                if rng.gen_bool(0.7) {
                    pool[rng.gen_range(0..pool.len())]
                } else {
                    rng.gen_range(-10.0..10.0)
                }
            });
            let keys = values.map(|v| total_order_key(v.to_bits() as i64));
            let expected = median(&mut values.to_vec());
            let got = median_of_six_keys(keys);
            assert_eq!(got.to_bits(), expected.to_bits(), "{values:?}");
        }
    }

    #[test]
    fn median_of_keys_equals_median_by_selection_bit_for_bit() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(29);
        let pool = SPECIAL_VALUES;
        for _ in 0..5_000 {
            let len = rng.gen_range(0..=300);
            let rare = rng.gen_bool(0.2);
            let values: Vec<f64> = (0..len)
                .map(|_| {
                    if rng.gen_bool(if rare { 0.02 } else { 0.6 }) {
                        pool[rng.gen_range(0..pool.len())]
                    } else {
                        rng.gen_range(-10.0..10.0)
                    }
                })
                .collect();
            let expected = median(&mut values.clone());
            let mut keys: Vec<i64> = values
                .iter()
                .map(|v| total_order_key(v.to_bits() as i64))
                .collect();
            let got = median_of_keys(&mut keys);
            assert_eq!(got.to_bits(), expected.to_bits(), "{values:?}");
        }
    }

    #[test]
    fn the_six_input_network_sorts_every_zero_one_input() {
        // The 0-1 principle: a comparator network that sorts all 2⁶ inputs of zeros and ones
        // sorts every input.
        for mask in 0u32..64 {
            let mut values: [f64; 6] = std::array::from_fn(|i| f64::from((mask >> i) & 1));
            sort_six(&mut values);
            assert!(
                values.windows(2).all(|w| w[0] <= w[1]),
                "{mask:06b}: {values:?}"
            );
        }
    }

    #[test]
    fn stream_screen_equals_the_screen_with_heap_medians() {
        // The screen as it was written first: a heap vector of neighbours and `median` per
        // sample and axis.
        fn reference(samples: &[Vec3]) -> Screening {
            let n = samples.len();
            let axes: Vec<Vec<f64>> = (0..3)
                .map(|k| {
                    (0..n)
                        .map(|i| {
                            let lo = i.saturating_sub(STREAM_HALF_WINDOW);
                            let hi = (i + STREAM_HALF_WINDOW + 1).min(n);
                            let mut neighbours: Vec<f64> = (lo..hi)
                                .filter(|&j| j != i)
                                .map(|j| samples[j][k])
                                .collect();
                            samples[i][k] - median(&mut neighbours)
                        })
                        .collect()
                })
                .collect();
            let step = quantisation_step(samples);
            screen_axes(&axes, &[step.x, step.y, step.z])
        }
        let mut samples = noisy_vectors(5, 3000, 0.4);
        // A turn, a spike and a run of repeated (quantised) readings.
        for (i, s) in samples.iter_mut().enumerate() {
            s.x += (i as f64 * 0.01).sin() * 30.0;
        }
        samples[1234].z = 5e3;
        for s in &mut samples[2000..2100] {
            *s = Vec3::new(1.0, 2.0, 3.0);
        }
        let got = screen_distinct_stream(&samples);
        assert_eq!(got, reference(&samples));
        assert!(!got.keep[1234]);
        // Read once per reading, the stuck run is one reading off the turn's path: all its
        // rows go, with the spike.
        let once = screen_stream(&samples);
        assert!(!once.keep[1234]);
        assert!(once.keep[2000..2100].iter().all(|k| !*k));
    }

    #[test]
    fn vector_screen_equals_the_screen_of_copied_axes_bit_for_bit() {
        // The screen as it was written first: a vector per axis, and a sorted copy and a vector
        // of deviations per axis for the two medians.
        fn reference(samples: &[Vec3]) -> Screening {
            fn centre_and_scale(values: &[f64], resolution: f64) -> (f64, f64) {
                let mut sorted = values.to_vec();
                let centre = median(&mut sorted);
                let mut deviations: Vec<f64> = values.iter().map(|v| (v - centre).abs()).collect();
                let mad = 1.482_6 * median(&mut deviations);
                let shrink =
                    (1.0 - 2.0 * MAD_STANDARD_ERROR / (values.len() as f64).sqrt()).max(0.5);
                (centre, (mad / shrink).max(resolution))
            }
            let step = quantisation_step(samples);
            let axes: Vec<Vec<f64>> = (0..3)
                .map(|k| samples.iter().map(|s| s[k]).collect())
                .collect();
            let resolution = [step.x, step.y, step.z];
            let n = samples.len();
            if n < MIN_SCREENED {
                return Screening::keep_all(n);
            }
            let bound = bonferroni_bound(n * axes.len());
            let mut worst = vec![0.0_f64; n];
            for (values, &floor) in axes.iter().zip(&resolution) {
                let (centre, sigma) = centre_and_scale(values, floor);
                if !(sigma > 0.0 && sigma.is_finite()) {
                    continue;
                }
                for (w, v) in worst.iter_mut().zip(values) {
                    let z = if v.is_finite() {
                        (v - centre).abs() / sigma
                    } else {
                        f64::INFINITY
                    };
                    *w = w.max(z);
                }
            }
            Screening::from_worst(&worst, bound)
        }
        fn same(a: &Screening, b: &Screening) -> bool {
            a.keep == b.keep
                && a.dropped == b.dropped
                && a.bound_sigmas.to_bits() == b.bound_sigmas.to_bits()
                && a.worst_sigmas.to_bits() == b.worst_sigmas.to_bits()
        }
        for (seed, n) in [(1, 0), (2, 9), (3, 10), (4, 11), (5, 400), (6, 1501)] {
            let mut samples = noisy_vectors(seed, n, 0.2);
            if n > 100 {
                // Spikes, a non-finite read and a stretch of repeated (quantised) readings.
                samples[n / 3].x = 1e4;
                samples[n / 2].z = -7e2;
                samples[n / 5].y = f64::NAN;
                for s in &mut samples[n - 60..n - 10] {
                    *s = Vec3::new(20.0, -5.0, 40.0);
                }
            }
            let got = screen_vectors(&samples);
            assert!(same(&got, &reference(&samples)), "n = {n}");
            let quantised: Vec<Vec3> = samples.iter().map(|s| s.map(|v| v.round())).collect();
            assert!(
                same(&screen_vectors(&quantised), &reference(&quantised)),
                "n = {n}"
            );
        }
    }

    #[test]
    fn the_bound_grows_with_the_number_of_tests_as_bonferroni_says() {
        // Φ⁻¹(1 − 0.01/2) = 2.5758 for one test; Φ⁻¹(1 − 0.01/6000) = 4.648 for 3000.
        assert!((bonferroni_bound(1) - 2.5758).abs() < 1e-3);
        assert!((bonferroni_bound(3000) - 4.648).abs() < 2e-3);
    }

    #[test]
    fn one_huge_spike_in_a_hold_is_dropped_and_nothing_else() {
        let mut samples = noisy_vectors(3, 800, 0.3);
        samples[417].y = 1e5;
        let screening = screen_vectors(&samples);
        assert_eq!(screening.dropped, 1);
        assert!(!screening.keep[417]);
        assert!(screening.worst_sigmas > 1e4, "{}", screening.worst_sigmas);
    }

    #[test]
    fn clean_gaussian_holds_lose_a_sample_in_about_one_percent_of_cases() {
        // 200 clean holds of 500 samples: at α = 1 % the expected count of holds losing any
        // sample is 2 (the guard on σ̂ makes it smaller); more than 8 would mean the bound is
        // far looser than stated (Poisson(2) exceeds 8 with probability < 3e-4).
        let losing = (0..200)
            .filter(|seed| screen_vectors(&noisy_vectors(10 * seed, 500, 1.0)).dropped > 0)
            .count();
        assert!(losing <= 8, "{losing} of 200 clean holds lost samples");
    }

    #[test]
    fn quantised_readings_that_mostly_repeat_are_not_screened_down_to_one_value() {
        // 0.15 µT steps, 80 % of readings on the median, the rest one or two steps away:
        // MAD = 0, but nothing within a few steps is an outlier.
        let values: Vec<f64> = (0..200)
            .map(|i| match i % 10 {
                0 => 0.15,
                1 => -0.15,
                2 if i % 20 == 2 => 0.30,
                _ => 0.0,
            })
            .collect();
        let screening = screen_scalars(&values, 0.15);
        assert_eq!(screening.dropped, 0);
    }

    #[test]
    fn a_spike_in_a_turning_stream_is_dropped_and_the_smooth_path_kept() {
        // A 48 µT field turning at up to 2 rad/s, sampled at 100 Hz with 0.3 µT noise.
        let noise = [gaussian(1, 3000), gaussian(2, 3000), gaussian(3, 3000)];
        let mut samples: Vec<Vec3> = (0..3000)
            .map(|i| {
                let t = i as f64 / 100.0;
                let (a, b) = (2.0 * (0.3 * t).sin() * t / 10.0, 0.7 * t);
                Vec3::new(a.cos() * b.cos(), a.cos() * b.sin(), a.sin()) * 48.0
                    + Vec3::new(noise[0][i], noise[1][i], noise[2][i]) * 0.3
            })
            .collect();
        samples[1234].x = 1e5;
        let screening = screen_stream(&samples);
        assert!(!screening.keep[1234]);
        assert_eq!(screening.dropped, 1, "{}", screening.bound_sigmas);
    }

    #[test]
    fn a_non_finite_reading_is_dropped_and_too_few_values_are_left_alone() {
        let mut values = gaussian(5, 50);
        values[7] = f64::NAN;
        let screening = screen_scalars(&values, 0.0);
        assert_eq!(screening.dropped, 1);
        assert!(!screening.keep[7]);
        let few = [1.0, 2.0, 1e9];
        assert_eq!(screen_scalars(&few, 0.0).dropped, 0);
    }
}
