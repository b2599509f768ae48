//! The LSM9DS1's conversions on its own oscillator: outputs latched at the chip's output data
//! rate, which differs from the nominal rate by a relative error (datasheet: the ODR is derived
//! from an internal oscillator, not the host's clock), with the data-ready and overrun flags
//! (STATUS_REG XLDA/GDA/TDA, STATUS_REG_M ZYXDA/ZYXOR) set on conversion and cleared by reading
//! the outputs.

/// Conversion instants of one sensor: index `k` happens at `(k + ½) / (rate · (1 + error))`;
/// the half-period phase keeps conversions off the host's nominal read instants.
#[derive(Debug, Clone, Copy, Default)]
struct ConversionCounter {
    index: Option<u64>,
}

impl ConversionCounter {
    /// Conversions completed since the previous call, at time `t_s` and rate `rate_hz` (`None`:
    /// powered down, which restarts the count).
    fn advance(&mut self, t_s: f64, rate_hz: Option<f64>, odr_error: f64) -> u64 {
        let Some(rate) = rate_hz else {
            self.index = None;
            return 0;
        };
        let effective = rate * (1.0 + odr_error);
        // Finite and non-negative for the times and rates the board uses; the saturating cast
        // keeps a pathological value from wrapping.
        let completed = (t_s * effective + 0.5).floor().max(0.0) as u64;
        let new = match self.index {
            Some(previous) => completed.saturating_sub(previous),
            None => u64::from(completed > 0),
        };
        self.index = Some(completed);
        new
    }
}

/// What the chip's outputs hold between conversions, and its data-ready flags.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct LatchedOutputs {
    /// Accelerometer counts of the latest conversion.
    pub accel: [i16; 3],
    /// Gyroscope counts of the latest conversion.
    pub gyro: [i16; 3],
    /// Temperature counts of the latest conversion.
    pub temp: i16,
    /// Magnetometer counts of the latest conversion.
    pub mag: [i16; 3],
    /// XLDA / GDA / TDA: an accelerometer/gyroscope conversion not yet read.
    pub accel_gyro_ready: bool,
    /// ZYXDA: a magnetometer conversion not yet read.
    pub mag_ready: bool,
    /// ZYXOR: a magnetometer conversion was overwritten before it was read.
    pub mag_overrun: bool,
}

/// The chip's own timebase.
#[derive(Debug, Clone, Copy)]
pub(super) struct ChipClock {
    odr_error: f64,
    accel_gyro: ConversionCounter,
    mag: ConversionCounter,
    pub outputs: LatchedOutputs,
}

/// New conversions found by [`ChipClock::advance`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct NewConversions {
    /// The accelerometer/gyroscope converted at least once.
    pub accel_gyro: bool,
    /// The magnetometer converted at least once.
    pub mag: bool,
}

impl ChipClock {
    /// A timebase whose rates are `1 + odr_error` times the nominal ones.
    pub fn new(odr_error: f64) -> Self {
        Self {
            odr_error,
            accel_gyro: ConversionCounter::default(),
            mag: ConversionCounter::default(),
            outputs: LatchedOutputs::default(),
        }
    }

    /// The relative output data rate error.
    pub fn odr_error(&self) -> f64 {
        self.odr_error
    }

    /// Move to time `t_s`; the caller latches the outputs of the sensors that converted.
    /// A conversion landing on unread data sets the overrun flag (the magnetometer has one;
    /// the accelerometer/gyroscope has none outside the FIFO, so its losses stay invisible).
    pub fn advance(
        &mut self,
        t_s: f64,
        accel_gyro_hz: Option<f64>,
        mag_hz: Option<f64>,
    ) -> NewConversions {
        let accel_gyro = self.accel_gyro.advance(t_s, accel_gyro_hz, self.odr_error);
        let mag = self.mag.advance(t_s, mag_hz, self.odr_error);
        if accel_gyro > 0 {
            self.outputs.accel_gyro_ready = true;
        }
        if mag > 0 {
            if self.outputs.mag_ready || mag > 1 {
                self.outputs.mag_overrun = true;
            }
            self.outputs.mag_ready = true;
        }
        NewConversions {
            accel_gyro: accel_gyro > 0,
            mag: mag > 0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_slow_clock_converts_fewer_times_than_the_nominal_rate() {
        let mut clock = ChipClock::new(-0.005);
        let mut conversions = 0;
        // 10 s of reads at a nominal 100 Hz.
        for k in 1..=1000 {
            if clock
                .advance(f64::from(k) * 0.01, Some(100.0), None)
                .accel_gyro
            {
                conversions += 1;
            }
        }
        // 0.5 % slower: 995 conversions in 10 s, ±1 for the phase.
        assert!((994..=996).contains(&conversions), "{conversions}");
    }

    #[test]
    fn a_second_magnetometer_conversion_before_a_read_is_an_overrun() {
        let mut clock = ChipClock::new(0.0);
        clock.advance(0.01, None, Some(100.0));
        assert!(clock.outputs.mag_ready && !clock.outputs.mag_overrun);
        clock.advance(0.02, None, Some(100.0));
        assert!(clock.outputs.mag_overrun);
    }
}
