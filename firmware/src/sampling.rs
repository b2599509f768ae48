//! Accounting of the sensor's own conversions against the read timer.
//!
//! The core reads on the MCU timer at the configured output data rate, but the sensor converts
//! on its own oscillator (ODR tolerance of a few per cent on MEMS parts), so the two drift: a
//! read may find no new conversion (a repeat) or a conversion may be overwritten before it is
//! read (a drop). The chip's data-ready bits ([`NewData`]) tell repeats apart; a repeated
//! accelerometer/gyroscope sample is skipped and a repeated magnetometer value is not averaged
//! again. The LSM9DS1 has no accelerometer/gyroscope overrun flag outside its FIFO, so drops are
//! inferred only where the timing makes them certain: a gap of at least 1.5 nominal periods
//! between two reads (half a period is far beyond any ODR tolerance) held at least one
//! conversion that was never read.

use imucal_protocol::ErrorCounters;

use crate::imu::NewData;

/// What the core does with one read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReadVerdict {
    /// The accelerometer/gyroscope sample is new: use it.
    pub use_sample: bool,
    /// Its magnetometer value is a new conversion.
    pub mag_is_new: bool,
}

/// Tracks read times and counts repeats and drops into [`ErrorCounters`].
#[derive(Debug, Clone, Copy, Default)]
pub struct ConversionTracker {
    last_read_us: Option<u64>,
}

impl ConversionTracker {
    /// No read yet.
    pub const fn new() -> Self {
        Self { last_read_us: None }
    }

    /// Account one read at `now_us` with nominal sample period `period_us`.
    pub fn account(
        &mut self,
        new_data: NewData,
        now_us: u64,
        period_us: u64,
        errors: &mut ErrorCounters,
    ) -> ReadVerdict {
        if let Some(last) = self.last_read_us.replace(now_us) {
            let missed = missed_conversions(now_us.saturating_sub(last), period_us);
            errors.missed_samples = errors.missed_samples.saturating_add(missed);
        }
        if !new_data.accel_gyro {
            errors.repeated_samples = errors.repeated_samples.saturating_add(1);
        }
        if !new_data.mag {
            errors.mag_repeats = errors.mag_repeats.saturating_add(1);
        }
        if new_data.mag_overrun {
            errors.mag_overruns = errors.mag_overruns.saturating_add(1);
        }
        ReadVerdict {
            use_sample: new_data.accel_gyro,
            mag_is_new: new_data.mag,
        }
    }
}

/// Conversions certainly missed in a gap of `gap_us` between reads: the whole periods beyond
/// the first, once the gap reaches 1.5 periods (rounded to the nearest whole period).
fn missed_conversions(gap_us: u64, period_us: u64) -> u32 {
    if period_us == 0 || gap_us.saturating_mul(2) < period_us.saturating_mul(3) {
        return 0;
    }
    let periods = gap_us.saturating_add(period_us / 2) / period_us;
    u32::try_from(periods.saturating_sub(1)).unwrap_or(u32::MAX)
}

#[cfg(test)]
mod tests {
    use super::*;

    const FRESH: NewData = NewData::ALL;

    #[test]
    fn regular_fresh_reads_count_nothing() {
        let mut tracker = ConversionTracker::new();
        let mut errors = ErrorCounters::default();
        for i in 0..100u64 {
            // Jitter of ±20 % of a period is not a drop.
            let jitter = if i % 2 == 0 { 0 } else { 1_600 };
            let verdict = tracker.account(FRESH, i * 8_403 + jitter, 8_403, &mut errors);
            assert!(verdict.use_sample && verdict.mag_is_new);
        }
        assert_eq!(errors, ErrorCounters::default());
    }

    #[test]
    fn a_stale_read_is_skipped_and_counted_as_a_repeat() {
        let mut tracker = ConversionTracker::new();
        let mut errors = ErrorCounters::default();
        let stale = NewData {
            accel_gyro: false,
            mag: false,
            mag_overrun: false,
        };
        let verdict = tracker.account(stale, 0, 10_000, &mut errors);
        assert_eq!(
            verdict,
            ReadVerdict {
                use_sample: false,
                mag_is_new: false
            }
        );
        assert_eq!((errors.repeated_samples, errors.mag_repeats), (1, 1));
    }

    #[test]
    fn a_gap_of_three_periods_counts_two_missed_conversions() {
        let mut tracker = ConversionTracker::new();
        let mut errors = ErrorCounters::default();
        tracker.account(FRESH, 0, 10_000, &mut errors);
        tracker.account(FRESH, 30_000, 10_000, &mut errors);
        assert_eq!(errors.missed_samples, 2);
        // 1.4 periods: within tolerance of one period, nothing missed.
        tracker.account(FRESH, 44_000, 10_000, &mut errors);
        assert_eq!(errors.missed_samples, 2);
    }

    #[test]
    fn a_magnetometer_overrun_is_counted() {
        let mut tracker = ConversionTracker::new();
        let mut errors = ErrorCounters::default();
        let overrun = NewData {
            mag_overrun: true,
            ..NewData::ALL
        };
        tracker.account(overrun, 0, 10_000, &mut errors);
        assert_eq!(errors.mag_overruns, 1);
    }
}
