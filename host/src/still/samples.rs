//! The samples of one sensor inside a hold, with gross outliers screened out
//! ([`crate::stats::robust`]: median/MAD with a Bonferroni bound). Every statistic of a hold —
//! the pose means the fits use and the observations the residual analysis uses — starts here,
//! so a spike is dropped, and named, in one place.

use crate::fit::Vec3;
use crate::recording::{Recording, Sensor};
use crate::stats::robust::screen_vectors;

/// Samples of one sensor that the screen dropped from a hold.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DroppedSamples {
    /// Which sensor.
    pub sensor: Sensor,
    /// How many samples were dropped.
    pub dropped: usize,
    /// How many samples the hold had before screening.
    pub total: usize,
    /// Largest deviation of a dropped sample from the hold's median, in robust standard
    /// deviations.
    pub worst_sigmas: f64,
    /// The screen's bound, in robust standard deviations.
    pub bound_sigmas: f64,
}

impl DroppedSamples {
    /// What was dropped, e.g. `1 of 113 mag samples (up to 4.1e5 σ, bound 4.2 σ)`.
    pub fn phrase(&self) -> String {
        format!(
            "{} of {} {} samples (up to {:.2e} σ, bound {:.1} σ)",
            self.dropped, self.total, self.sensor, self.worst_sigmas, self.bound_sigmas
        )
    }
}

/// The screened samples of a hold and what was dropped.
#[derive(Debug, Clone, PartialEq)]
pub struct HoldSamples {
    /// The samples kept, in time order.
    pub kept: Vec<Vec3>,
    /// What was dropped, when anything was.
    pub dropped: Option<DroppedSamples>,
}

/// The screened samples of `sensor` in a hold: main-stream `rows` for the accelerometer and
/// gyroscope, the magnetometer's own samples within `[t_start, t_end]`. `None` when the
/// recording has no such sensor.
pub fn hold_samples(
    recording: &Recording,
    rows: &[usize],
    t_start: f64,
    t_end: f64,
    sensor: Sensor,
) -> Option<HoldSamples> {
    let raw: Vec<Vec3> = match sensor {
        Sensor::Accel | Sensor::Gyro => {
            let all = recording.samples(sensor)?;
            rows.iter().filter_map(|&i| all.get(i).copied()).collect()
        }
        Sensor::Mag => {
            let mag = recording.mag.as_ref()?;
            // Time stamps are non-decreasing (the reader refuses any that go back), so the
            // samples inside the hold are one contiguous run found by two binary searches, not
            // a scan of the whole stream per hold.
            let first = mag.time.partition_point(|t| *t < t_start);
            let last = mag.time.partition_point(|t| *t <= t_end).max(first);
            mag.samples.get(first..last)?.to_vec()
        }
    };
    let screening = screen_vectors(&raw);
    let dropped = (screening.dropped > 0).then_some(DroppedSamples {
        sensor,
        dropped: screening.dropped,
        total: raw.len(),
        worst_sigmas: screening.worst_sigmas,
        bound_sigmas: screening.bound_sigmas,
    });
    // Nothing dropped: the samples themselves are what was kept, without a copy.
    let kept = if dropped.is_some() {
        screening.kept(&raw)
    } else {
        raw
    };
    Some(HoldSamples { kept, dropped })
}
