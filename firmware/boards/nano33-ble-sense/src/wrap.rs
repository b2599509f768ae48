//! 64-bit time from successive readings of a wrapping 32-bit counter (the board's TIMER1).
//!
//! Depends on nothing but `core`, so the host-side `xtask` compiles this file unchanged to test it.

/// 64-bit count from successive readings of a counter that wraps from `u32::MAX` to 0.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct WrapExtender {
    wraps: u32,
    last: u32,
}

impl WrapExtender {
    /// The 64-bit count of a new reading, which must be less than one wrap (2³² counts) after the
    /// previous one.
    pub fn extend(&mut self, raw: u32) -> u64 {
        if raw < self.last {
            // Wrapping the wrap count would take 2³² wraps (35 000 years at 1 MHz); saturating
            // keeps the clock from ever going back.
            self.wraps = self.wraps.saturating_add(1);
        }
        self.last = raw;
        (u64::from(self.wraps) << 32) | u64::from(raw)
    }
}

#[cfg(test)]
mod tests {
    use super::WrapExtender;

    #[test]
    fn reading_after_the_counter_wraps_continues_past_two_to_the_32() {
        let mut clock = WrapExtender::default();
        assert_eq!(clock.extend(0xFFFF_FFF0), 0xFFFF_FFF0);
        assert_eq!(clock.extend(0x10), (1 << 32) + 0x10);
        assert_eq!(clock.extend(0x11), (1 << 32) + 0x11);
    }

    #[test]
    fn extended_count_equals_the_true_count_over_many_wraps_with_irregular_reads() {
        // True 64-bit time advancing by steps up to just under one wrap, as a main loop that is
        // sometimes slow would read it; the extension must be exact at every read.
        let mut clock = WrapExtender::default();
        let mut truth: u64 = 0;
        let mut step: u64 = 1;
        for _ in 0..10_000 {
            // A deterministic spread of steps from 1 µs up to 2³² − 1 µs.
            step = step
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407)
                % (1 << 32);
            let advance = step.max(1);
            truth += advance;
            assert_eq!(clock.extend(truth as u32), truth);
        }
        assert!(
            truth > 1000 * (1u64 << 32),
            "the test must cover many wraps"
        );
    }

    #[test]
    fn repeated_reading_of_the_same_value_does_not_count_a_wrap() {
        let mut clock = WrapExtender::default();
        assert_eq!(clock.extend(500), 500);
        assert_eq!(clock.extend(500), 500);
    }
}
