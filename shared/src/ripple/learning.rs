//! Iterative learning across travels (`Strategy::Learning`): harmonic coefficients
//! stored per revolution of the shaft, by absolute position, and corrected
//! after each travel by the residual measured over that revolution.
//!
//! Each sample of a travel adds `conj(G) E` and `|G|^2` to its bin (`E` the
//! demodulated error, `G` the model response, see [`super::RippleCompensator`]).
//! After the travel, per harmonic, the residual ripple `T + U` (N m) is
//! estimated by least squares over the whole travel, `R_all = sum conj(G) E /
//! (sum |G|^2 + eps)`, and per bin shrunk toward it where the bin saw little:
//! `R_b = (sum_b conj(G) E + lambda_b R_all) / (sum_b |G|^2 + lambda_b)` with
//! `lambda_b = floor^2 n_b`. So a stretch of the travel where the encoder
//! hardly sees an order (an anti-resonance of the sheave, where the car
//! vibrates most) learns what the rest of the travel found, and a stretch
//! that sees it well learns its own correction. Update:
//! `U_b <- U_b - gain R_b`. With a model error `G / G_model = rho e^{j phi}`
//! each travel multiplies the residual by `1 - gain rho e^{j phi}`: it
//! converges when that is under 1 in magnitude, for `gain = 0.8` any `rho`
//! in (0, 2.5) with `phi = 0`, and any `|phi| < 45 degrees` for `rho` up to 1.7.

use super::complex::Complex;
use super::harmonics::MAX_HARMONICS;

/// Number of one-revolution bins.
pub const BINS: usize = 48;
/// Bin of the power-up position (the bins span +-24 revolutions from it).
const BIN_OFFSET: i64 = (BINS / 2) as i64;
/// Learning gain per travel (dimensionless).
pub const LEARNING_GAIN: f32 = 0.8;

/// Per-revolution harmonic coefficients and the residual sums of the travel in progress.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LearningTable {
    /// Coefficients per bin and harmonic, N m.
    torque_nm: [[Complex; MAX_HARMONICS]; BINS],
    /// Sums of `conj(G) E` of this travel.
    weighted_sum: [[Complex; MAX_HARMONICS]; BINS],
    /// Sums of `|G|^2` of this travel.
    weight_sum: [[f32; MAX_HARMONICS]; BINS],
    /// Samples in each bin this travel.
    samples: [u16; BINS],
}

impl Default for LearningTable {
    fn default() -> Self {
        Self {
            torque_nm: [[Complex::ZERO; MAX_HARMONICS]; BINS],
            weighted_sum: [[Complex::ZERO; MAX_HARMONICS]; BINS],
            weight_sum: [[0.0; MAX_HARMONICS]; BINS],
            samples: [0; BINS],
        }
    }
}

impl LearningTable {
    /// Back to [`LearningTable::default`], in place.
    pub fn clear(&mut self) {
        self.torque_nm = [[Complex::ZERO; MAX_HARMONICS]; BINS];
        self.weighted_sum = [[Complex::ZERO; MAX_HARMONICS]; BINS];
        self.weight_sum = [[0.0; MAX_HARMONICS]; BINS];
        self.samples = [0; BINS];
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

    /// Adds a sample of harmonic `k` at `position_counts`: `weighted` =
    /// `conj(G) E`, `weight` = `|G|^2`.
    pub fn accumulate(&mut self, k: usize, position_counts: i64, counts_per_rev: u32, weighted: Complex, weight: f32) {
        let (below, above, f) = locate(position_counts, counts_per_rev);
        let bin = if f < 0.5 { below } else { above };
        self.weighted_sum[bin][k] = self.weighted_sum[bin][k] + weighted;
        self.weight_sum[bin][k] += weight;
        if k == 0 {
            self.samples[bin] = self.samples[bin].saturating_add(1);
        }
    }

    /// End of a travel: every bin with at least `min_samples` samples
    /// learns (see the module documentation; `floor` is the response floor
    /// in the units of `G`); the sums are cleared. Coefficients of harmonic
    /// `k` are limited to `limits_nm[k]` in magnitude.
    pub fn end_travel(&mut self, harmonics: usize, min_samples: u16, limits_nm: &[f32; MAX_HARMONICS], floor: f32) {
        let floor2 = floor * floor;
        for (k, &limit_nm) in limits_nm.iter().enumerate().take(harmonics.min(MAX_HARMONICS)) {
            let (mut num, mut den, mut n) = (Complex::ZERO, 0.0f32, 0.0f32);
            for b in 0..BINS {
                num = num + self.weighted_sum[b][k];
                den += self.weight_sum[b][k];
                n += self.samples[b] as f32;
            }
            if n == 0.0 {
                continue;
            }
            // A whisker of regularisation: an order blind everywhere learns slowly, not noise.
            let overall = num.scale(1.0 / (den + 0.01 * floor2 * n));
            for b in 0..BINS {
                let samples = self.samples[b];
                if samples >= min_samples && samples > 0 {
                    let lambda = floor2 * samples as f32;
                    let residual =
                        (self.weighted_sum[b][k] + overall.scale(lambda)).scale(1.0 / (self.weight_sum[b][k] + lambda));
                    let next = self.torque_nm[b][k] - residual.scale(LEARNING_GAIN);
                    self.torque_nm[b][k] = limit(next, limit_nm);
                }
            }
        }
        self.samples = [0; BINS];
        self.weighted_sum = [[Complex::ZERO; MAX_HARMONICS]; BINS];
        self.weight_sum = [[0.0; MAX_HARMONICS]; BINS];
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
        // A residual X = 1 - 0.5j everywhere between 0 and 3 revolutions, seen
        // through G = 0.1j: conj(G) E = |G|^2 X.
        let g = Complex::new(0.0, 0.1);
        let x = Complex::new(1.0, -0.5);
        for p in (0..3000).step_by(10) {
            table.accumulate(0, p, cpr, g.conj() * g * x, g.norm_sqr());
        }
        table.end_travel(1, 10, &[100.0; MAX_HARMONICS], 0.01);
        let u = table.torque_at(0, 1500, cpr);
        // Learned -0.8 X, less the whisker of regularisation (0.01 floor^2 / |G|^2 = 1e-4).
        assert!((u + x.scale(0.8)).norm_sqr() < 1e-6, "{u:?}");
        // Outside the learned span the coefficient falls to zero over one bin.
        assert_eq!(table.torque_at(0, -5000, cpr), Complex::ZERO);
        let half = table.torque_at(0, 3000, cpr);
        assert!(half.re < -0.3 && half.re > -0.81, "{half:?}");
    }

    #[test]
    fn limit_keeps_direction_and_caps_magnitude() {
        let z = limit(Complex::new(30.0, 40.0), 10.0);
        assert_eq!(z, Complex::new(7.5, 10.0) * Complex::new(0.5, 0.0));
        assert_eq!(limit(Complex::new(f32::NAN, 0.0), 1.0), Complex::ZERO);
        assert_eq!(limit(Complex::new(0.3, 0.4), 1.0), Complex::new(0.3, 0.4));
    }
}
