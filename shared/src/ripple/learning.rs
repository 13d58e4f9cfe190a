//! Iterative learning across travels (strategy 3): harmonic coefficients
//! stored per revolution of the shaft, by absolute position, and corrected
//! after each travel by the residual measured over that revolution.
//!
//! Update (after a travel, per bin `b` and harmonic `n` with samples):
//! `U_b,n <- U_b,n - gain * mean(R_b,n)`, with `R` the residual ripple
//! estimate `T + U` (N m) of [`super::RippleCompensator`]. With a residual
//! model error `G / G_model = rho e^{j phi}` each travel multiplies the
//! residual by `1 - gain rho e^{j phi}`: it converges when
//! `|1 - gain rho e^{j phi}| < 1`, for `gain = 0.7` any `rho` in (0, 2.8)
//! with `phi = 0`, and any `|phi| < 45 degrees` for `rho` up to 2.

use super::complex::Complex;
use super::harmonics::MAX_HARMONICS;

/// Number of one-revolution bins.
pub const BINS: usize = 48;
/// Bin of the power-up position (the bins span +-24 revolutions from it).
const BIN_OFFSET: i64 = (BINS / 2) as i64;
/// Learning gain per travel (dimensionless).
pub const LEARNING_GAIN: f32 = 0.7;

/// Per-revolution harmonic coefficients and the residual sums of the travel in progress.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LearningTable {
    /// Coefficients per bin and harmonic, N m.
    torque_nm: [[Complex; MAX_HARMONICS]; BINS],
    /// Residual sums of this travel, N m.
    residual_sum_nm: [[Complex; MAX_HARMONICS]; BINS],
    /// Samples in each bin this travel.
    samples: [u16; BINS],
}

impl Default for LearningTable {
    fn default() -> Self {
        Self {
            torque_nm: [[Complex::ZERO; MAX_HARMONICS]; BINS],
            residual_sum_nm: [[Complex::ZERO; MAX_HARMONICS]; BINS],
            samples: [0; BINS],
        }
    }
}

/// Bin index and the fraction of the way to the next bin centre, for a
/// position in counts from power-up.
fn locate(position_counts: i64, counts_per_rev: u32) -> (usize, usize, f32) {
    let cpr = counts_per_rev.max(1) as i64;
    // Bin centres at (b - offset + 0.5) revolutions.
    let shifted = position_counts.saturating_add(BIN_OFFSET * cpr).saturating_sub(cpr / 2);
    let below = shifted.div_euclid(cpr).clamp(0, BINS as i64 - 1) as usize;
    let above = (below + 1).min(BINS - 1);
    let fraction = if shifted < 0 || below == BINS - 1 { 0.0 } else { shifted.rem_euclid(cpr) as f32 / cpr as f32 };
    (below, above, fraction)
}

impl LearningTable {
    /// Coefficient of harmonic `k` at `position_counts`, linearly
    /// interpolated between bin centres, N m.
    pub fn torque_at(&self, k: usize, position_counts: i64, counts_per_rev: u32) -> Complex {
        let (below, above, f) = locate(position_counts, counts_per_rev);
        self.torque_nm[below][k].scale(1.0 - f) + self.torque_nm[above][k].scale(f)
    }

    /// Adds a residual sample of harmonic `k` (N m) to the bin of `position_counts`.
    pub fn accumulate(&mut self, k: usize, position_counts: i64, counts_per_rev: u32, residual_nm: Complex) {
        let (below, above, f) = locate(position_counts, counts_per_rev);
        let bin = if f < 0.5 { below } else { above };
        self.residual_sum_nm[bin][k] = self.residual_sum_nm[bin][k] + residual_nm;
        if k == 0 {
            self.samples[bin] = self.samples[bin].saturating_add(1);
        }
    }

    /// End of a travel: every bin with at least `min_samples` samples
    /// learns; the sums are cleared. Coefficients are limited to
    /// `limit_nm` in magnitude.
    pub fn end_travel(&mut self, harmonics: usize, min_samples: u16, limit_nm: f32) {
        for b in 0..BINS {
            let n = self.samples[b];
            if n >= min_samples && n > 0 {
                let inverse = 1.0 / n as f32;
                for k in 0..harmonics.min(MAX_HARMONICS) {
                    let mean = self.residual_sum_nm[b][k].scale(inverse);
                    let next = self.torque_nm[b][k] - mean.scale(LEARNING_GAIN);
                    self.torque_nm[b][k] = limit(next, limit_nm);
                }
            }
            self.samples[b] = 0;
            self.residual_sum_nm[b] = [Complex::ZERO; MAX_HARMONICS];
        }
    }

    /// Forgets harmonic `k` everywhere (back-off).
    pub fn clear_harmonic(&mut self, k: usize) {
        for bin in self.torque_nm.iter_mut() {
            bin[k] = Complex::ZERO;
        }
    }
}

/// `z` halved until its magnitude is at most `limit` (so it ends in
/// `(limit / 2, limit]` when it was larger); non-finite gives zero.
pub fn limit(z: Complex, limit: f32) -> Complex {
    if !z.is_finite() {
        return Complex::ZERO;
    }
    let mut z = z;
    let mut guard = 0;
    while z.norm_sqr() > limit * limit && guard < 160 {
        z = z.scale(0.5);
        guard += 1;
    }
    z
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_between_bin_centres_and_learns_the_mean_residual() {
        let cpr = 1000;
        let mut table = LearningTable::default();
        // A constant residual of 1 N m everywhere between 0 and 3 revolutions.
        for p in (0..3000).step_by(10) {
            table.accumulate(0, p, cpr, Complex::new(1.0, -0.5));
        }
        table.end_travel(1, 10, 100.0);
        let u = table.torque_at(0, 1500, cpr);
        assert!((u - Complex::new(-0.7, 0.35)).norm_sqr() < 1e-10, "{u:?}");
        // Outside the learned span the coefficient falls to zero over one bin.
        assert_eq!(table.torque_at(0, -5000, cpr), Complex::ZERO);
        let half = table.torque_at(0, 3000, cpr);
        assert!(half.re < -0.3 && half.re > -0.71, "{half:?}");
    }

    #[test]
    fn limit_keeps_direction_and_caps_magnitude() {
        let z = limit(Complex::new(30.0, 40.0), 10.0);
        assert_eq!(z, Complex::new(7.5, 10.0) * Complex::new(0.5, 0.0));
        assert_eq!(limit(Complex::new(f32::NAN, 0.0), 1.0), Complex::ZERO);
        assert_eq!(limit(Complex::new(0.3, 0.4), 1.0), Complex::new(0.3, 0.4));
    }
}
