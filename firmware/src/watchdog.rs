//! Independent watchdog (IWDG, LSI clock): resets the chip unless it is fed
//! within [`TIMEOUT_US`], and it is fed only while the control interrupt is
//! alive, i.e. while its step counter advances at the PWM rate.

use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{peripherals, Peri};

use crate::DRIVE_CONFIG;

/// Watchdog timeout, microseconds (on the nominal 32 kHz LSI, which is
/// +-several percent).
pub const TIMEOUT_US: u32 = 100_000;

/// The started watchdog and the control interrupt's step count at the last
/// check.
pub struct Watchdog {
    iwdg: IndependentWatchdog<'static, peripherals::IWDG>,
    last_steps: u32,
}

impl Watchdog {
    /// Starts the watchdog (it cannot be stopped again); `steps` is the
    /// control interrupt's step count now.
    pub fn start(iwdg: Peri<'static, peripherals::IWDG>, steps: u32) -> Self {
        let mut iwdg = IndependentWatchdog::new(iwdg, TIMEOUT_US);
        iwdg.unleash();
        Self { iwdg, last_steps: steps }
    }

    /// Feeds the watchdog if the control interrupt ran at least half the
    /// steps it should have in `elapsed_us` microseconds since the last check
    /// (`steps`: its step count now). Returns whether it fed.
    pub fn feed_if_alive(&mut self, steps: u32, elapsed_us: u32) -> bool {
        let ran = steps.wrapping_sub(self.last_steps);
        self.last_steps = steps;
        let expected = (elapsed_us as f32 * 1.0e-6 * DRIVE_CONFIG.current_loop_hz) as u32;
        let alive = ran >= expected / 2 && ran > 0;
        if alive {
            self.iwdg.pet();
        }
        alive
    }
}
