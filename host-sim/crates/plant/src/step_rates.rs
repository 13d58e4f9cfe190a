//! How many RK4 steps a sample of a chain takes: every rate of the chain up
//! to the compared bands' top within an accuracy bound on `h w`, the
//! chain's highest rate (above the bands: a discretised rope's top modes, a
//! clamped sheave's) within RK4's stability only, where RK4 damps it
//! numerically.

use std::f64::consts::TAU;

/// Largest product `h w` any rate may take: RK4 is stable on the imaginary
/// axis up to `2 sqrt(2)` (about 2.83); kept below it by a margin.
pub const STABLE_RATE_PER_STEP: f64 = 2.5;

/// Largest step-rate products `h w` of an RK4 integration, within the
/// compared bands and above them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepRates {
    /// For every rate up to [`StepRates::band_top_hz`] (the accuracy bound).
    pub within_bands: f64,
    /// For the chain's highest rate (at most [`STABLE_RATE_PER_STEP`]).
    pub highest: f64,
    /// Top of the compared bands, Hz.
    pub band_top_hz: f64,
}

impl StepRates {
    /// One bound `rate` for every rate, the highest included (the bands'
    /// top the largest finite frequency).
    pub const fn uniform(rate: f64) -> Self {
        Self { within_bands: rate, highest: rate, band_top_hz: f64::MAX }
    }

    /// RK4 steps per sample of `h_s` (s) for a chain whose highest rate is
    /// `omega_radps` (rad/s): every rate up to the bands' top within
    /// `within_bands`, the highest within `highest`; at least one.
    pub fn steps(&self, omega_radps: f64, h_s: f64) -> usize {
        let band_radps = TAU * self.band_top_hz;
        let needed = (omega_radps.min(band_radps) / self.within_bands).max(omega_radps / self.highest);
        ((h_s * needed).ceil() as usize).max(1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A rate inside the bands takes the accuracy bound, one above them
    /// the stability bound, and the band's own top rate whichever needs
    /// more: against the rule written out by hand.
    #[test]
    fn steps_follow_the_bound_of_the_rates_band() {
        let rates = StepRates { within_bands: 0.25, highest: 2.0, band_top_hz: 500.0 };
        let h = 1.0 / 4096.0;
        // 100 Hz: all within the bands.
        assert_eq!(rates.steps(TAU * 100.0, h), (h * TAU * 100.0 / 0.25).ceil() as usize);
        // 10 kHz: the band's top at 0.25 (4 steps) against 10 kHz at 2 (8).
        assert_eq!(rates.steps(TAU * 10_000.0, h), 8);
        // 2 kHz: the band's top at 0.25 needs more than 2 kHz at 2.
        assert_eq!(rates.steps(TAU * 2_000.0, h), (h * TAU * 500.0 / 0.25).ceil() as usize);
        assert_eq!(StepRates::uniform(1.0).steps(TAU * 10_000.0, h), (h * TAU * 10_000.0).ceil() as usize);
        assert_eq!(rates.steps(0.0, h), 1);
    }
}
