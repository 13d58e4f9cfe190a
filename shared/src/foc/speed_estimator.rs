//! Shaft position and speed from the quadrature encoder.
//!
//! The hardware counter is a free-running `u32` modulo 2^32; the difference
//! of two readings modulo 2^32 is the signed count increment (valid while the
//! shaft turns less than 2^31 counts between two steps), accumulated into a
//! saturating 64-bit position. Speed comes from a second-order tracking loop
//! (PLL) on that position, run at the speed-loop rate:
//!
//! `e = x - x_hat`, `w_hat += wn^2 Ts e`, `x_hat += (w_hat + 2 zeta wn e) Ts`,
//!
//! which filters the count quantisation with natural frequency `wn`, zeta = 1.

use fixed::types::I32F32;

use crate::fixed::Q16;

/// Encoder position accumulator and speed tracking loop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpeedEstimator {
    last_count: Option<u32>,
    /// The count at the revolution's zero of an absolute encoder, if any
    /// ([`SpeedEstimator::set_absolute_origin`]).
    absolute_origin: Option<u32>,
    position_counts: i64,
    /// Position modulo one revolution, `0..counts_per_rev`, counts.
    revolution_counts: u32,
    counts_per_rev: u32,
    position_estimate: I32F32,
    speed_counts_per_s: I32F32,
    /// `speed_counts_per_s` in rad/s, updated with it.
    speed_radps: Q16,
    ki_ts: I32F32,
    kp: I32F32,
    ts: I32F32,
    radians_per_count: I32F32,
}

impl SpeedEstimator {
    /// A tracking loop at `rate_hz` with natural frequency `bandwidth_hz`, for
    /// an encoder of `counts_per_rev` counts per mechanical revolution.
    pub fn new(rate_hz: f32, bandwidth_hz: f32, counts_per_rev: u32) -> Self {
        let ts = 1.0 / rate_hz;
        let wn = core::f32::consts::TAU * bandwidth_hz;
        let sat = I32F32::saturating_from_num;
        Self {
            last_count: None,
            absolute_origin: None,
            position_counts: 0,
            revolution_counts: 0,
            counts_per_rev: counts_per_rev.max(1),
            position_estimate: I32F32::ZERO,
            speed_counts_per_s: I32F32::ZERO,
            speed_radps: Q16::ZERO,
            ki_ts: sat(wn * wn * ts),
            kp: sat(2.0 * wn),
            ts: sat(ts),
            radians_per_count: sat(core::f32::consts::TAU / counts_per_rev.max(1) as f32),
        }
    }

    /// Makes the encoder absolute: the revolution position
    /// ([`SpeedEstimator::revolution_counts`]) of the first reading is that
    /// reading less `origin_counts` (modulo one revolution; the difference
    /// taken as a signed count) instead of 0. Before the first reading.
    pub fn set_absolute_origin(&mut self, origin_counts: u32) {
        self.absolute_origin = Some(origin_counts);
    }

    /// Takes a new counter reading; returns the signed increment since the
    /// previous reading, counts (0 for the first reading).
    pub fn count(&mut self, raw_count: u32) -> i32 {
        let delta = match self.last_count {
            // Modular difference of a wrapping hardware counter, then signed.
            Some(last) => raw_count.wrapping_sub(last) as i32,
            None => {
                if let Some(origin) = self.absolute_origin {
                    let from_origin = raw_count.wrapping_sub(origin) as i32 as i64;
                    self.revolution_counts = from_origin.rem_euclid(self.counts_per_rev as i64) as u32;
                }
                0
            }
        };
        self.last_count = Some(raw_count);
        self.position_counts = self.position_counts.saturating_add(delta as i64);
        // Within one revolution: no division unless the step crosses the zero mark.
        let within = self.revolution_counts as i64 + delta as i64;
        let cpr = self.counts_per_rev as i64;
        self.revolution_counts = if (0..cpr).contains(&within) { within } else { within.rem_euclid(cpr) } as u32;
        delta
    }

    /// Position within the current revolution, `0..counts_per_rev`, counts.
    pub fn revolution_counts(&self) -> u32 {
        self.revolution_counts
    }

    /// Accumulated position since start, counts.
    pub fn position_counts(&self) -> i64 {
        self.position_counts
    }

    /// Advances the tracking loop by one speed-loop period.
    pub fn update(&mut self) {
        let measured = I32F32::saturating_from_num(self.position_counts);
        let error = measured.saturating_sub(self.position_estimate);
        self.speed_counts_per_s = self.speed_counts_per_s.saturating_add(self.ki_ts.saturating_mul(error));
        let rate = self.speed_counts_per_s.saturating_add(self.kp.saturating_mul(error));
        self.position_estimate = self.position_estimate.saturating_add(rate.saturating_mul(self.ts));
        self.speed_radps = Q16::saturating_from_num(self.speed_counts_per_s.saturating_mul(self.radians_per_count));
    }

    /// Estimated shaft speed, rad/s (positive: car up).
    pub fn speed_radps(&self) -> Q16 {
        self.speed_radps
    }

    /// Shaft angle travelled since start, rad.
    pub fn angle_rad(&self) -> f32 {
        // Saturated to i32 counts (131 072 revolutions of this encoder) so the
        // conversion is one instruction on the Cortex-M4F.
        let counts = self.position_counts.clamp(i32::MIN as i64, i32::MAX as i64) as i32;
        counts as f32 * self.radians_per_count.to_num::<f32>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_absolute_origin_places_the_first_reading_within_the_revolution() {
        // Incremental: the first reading is the revolution's zero.
        let mut e = SpeedEstimator::new(2000.0, 20.0, 1000);
        e.count(12_345);
        assert_eq!(e.revolution_counts(), 0);
        // Absolute: the first reading less the origin, on either side of it.
        for (origin, raw, within) in [(100, 350, 250), (100, 2_450, 350), (300, 100, 800), (0, u32::MAX, 999)] {
            let mut e = SpeedEstimator::new(2000.0, 20.0, 1000);
            e.set_absolute_origin(origin);
            assert_eq!(e.count(raw), 0, "the first reading moves nothing");
            assert_eq!(e.revolution_counts(), within, "origin {origin}, reading {raw}");
            assert_eq!(e.position_counts(), 0, "the position is counted from the first reading");
            e.count(raw.wrapping_add(5));
            assert_eq!(e.revolution_counts(), (within + 5) % 1000);
        }
    }

    #[test]
    fn revolution_position_is_the_position_modulo_one_revolution() {
        let mut estimator = SpeedEstimator::new(2000.0, 40.0, 1000);
        let mut raw = 0u32;
        let mut seed = 12345u32;
        for _ in 0..20_000 {
            seed = seed.wrapping_mul(1_103_515_245).wrapping_add(12_345);
            let delta = (seed >> 16) as i32 % 2501 - 1250; // -1250..=1250 counts, several revolutions
            raw = raw.wrapping_add(delta as u32);
            estimator.count(raw);
            assert_eq!(estimator.revolution_counts() as i64, estimator.position_counts().rem_euclid(1000));
        }
    }

    #[test]
    fn tracks_a_constant_speed_through_counter_wrap() {
        let cpr = 16_384u32;
        let mut estimator = SpeedEstimator::new(2000.0, 40.0, cpr);
        let speed = 6.15f64; // rad/s
        let start = u32::MAX - 40_000; // wraps during the run
        for k in 0..4000u32 {
            let t = k as f64 / 2000.0;
            let counts = (speed * t / core::f64::consts::TAU * cpr as f64).floor() as u32;
            estimator.count(start.wrapping_add(counts));
            estimator.update();
        }
        let got = estimator.speed_radps().to_num::<f64>();
        assert!((got - speed).abs() < 0.01 * speed, "{got}");
        assert!(estimator.position_counts() > 0);
    }
}
