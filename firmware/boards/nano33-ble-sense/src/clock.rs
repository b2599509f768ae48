//! The firmware core's monotonic clock: TIMER1 counting microseconds, extended to 64 bits.
//!
//! TIMER1 runs free at 1 MHz (16 MHz / 2⁴, derived from the 32 MHz crystal once the USB clock
//! set-up has started it, so accurate to tens of ppm) in 32-bit mode with no shortcuts, so it
//! wraps from 0xFFFF_FFFF to 0 every 2³² µs ≈ 71.6 min. [`TimerClock::now_us`] counts the wraps
//! by noticing that a reading is below the previous one ([`WrapExtender`]), which is exact as long
//! as readings are less than 71.6 min apart; the main loop reads it on every turn.

use imucal_firmware::device::Clock;
use nrf52840_hal::pac::TIMER1;
use nrf52840_hal::timer::Timer;

use crate::wrap::WrapExtender;

/// TIMER1 as the core's [`Clock`].
pub struct TimerClock {
    timer: TIMER1,
    extender: WrapExtender,
}

impl TimerClock {
    /// Configures TIMER1 (1 MHz, 32 bit, through the HAL) and starts it free-running from 0.
    pub fn start(timer: TIMER1) -> Self {
        // The HAL sets the prescaler and bit mode; its one-shot shortcuts would stop the count at
        // the compare value, so they are cleared before starting.
        let timer = Timer::one_shot(timer).free();
        timer.shorts.reset();
        timer.tasks_clear.write(|w| w.tasks_clear().set_bit());
        timer.tasks_start.write(|w| w.tasks_start().set_bit());
        Self {
            timer,
            extender: WrapExtender::default(),
        }
    }

    /// The counter, captured into CC[1] (CC[0] is left to the HAL's compare logic).
    fn read_raw(&self) -> u32 {
        self.timer.tasks_capture[1].write(|w| w.tasks_capture().set_bit());
        self.timer.cc[1].read().bits()
    }
}

impl Clock for TimerClock {
    fn now_us(&mut self) -> u64 {
        let raw = self.read_raw();
        self.extender.extend(raw)
    }
}
