//! A normalised second-order IIR section (biquad), shared by the zero-phase
//! high-pass, the ISO 2631-1 weighting and the ride-quality low-pass.

use std::f64::consts::{PI, SQRT_2};

use realfft::num_complex::Complex64;

/// Coefficients of a normalized biquad section (a0 = 1), dimensionless:
/// `H(z) = (b0 + b1 z^-1 + b2 z^-2) / (1 + a1 z^-1 + a2 z^-2)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Biquad {
    pub(crate) b0: f64,
    pub(crate) b1: f64,
    pub(crate) b2: f64,
    pub(crate) a1: f64,
    pub(crate) a2: f64,
}

impl Biquad {
    /// Bilinear transform of the analog section
    /// `(n0 + n1 s + n2 s^2) / (d0 + d1 s + d2 s^2)` (s in rad/s) at
    /// `sample_rate_hz`, pre-warped so that the digital response at
    /// `prewarp_hz` equals the analog response there:
    /// `s = k (1 - z^-1) / (1 + z^-1)` with `k = w_p / tan(w_p / (2 fs))`.
    ///
    /// Requires `0 < prewarp_hz < sample_rate_hz / 2` (checked by callers).
    pub(crate) fn bilinear(num: [f64; 3], den: [f64; 3], prewarp_hz: f64, sample_rate_hz: f64) -> Self {
        let wp = 2.0 * PI * prewarp_hz;
        let k = wp / (wp / (2.0 * sample_rate_hz)).tan();
        // c0 (1 + z^-1)^2 + c1 k (1 - z^-2) + c2 k^2 (1 - z^-1)^2.
        let map = |c: [f64; 3]| {
            let [c0, c1, c2] = c;
            let kk = k * k;
            [c0 + c1 * k + c2 * kk, 2.0 * (c0 - c2 * kk), c0 - c1 * k + c2 * kk]
        };
        let b = map(num);
        let a = map(den);
        Self { b0: b[0] / a[0], b1: b[1] / a[0], b2: b[2] / a[0], a1: a[1] / a[0], a2: a[2] / a[0] }
    }

    /// 2nd-order Butterworth low-pass with -3 dB at `cutoff_hz`, pre-warped
    /// bilinear design (unit DC gain). Requires `0 < cutoff_hz < fs / 2`.
    pub(crate) fn butterworth_lowpass(cutoff_hz: f64, sample_rate_hz: f64) -> Self {
        let wc = 2.0 * PI * cutoff_hz;
        Self::bilinear([1.0, 0.0, 0.0], [1.0, SQRT_2 / wc, 1.0 / (wc * wc)], cutoff_hz, sample_rate_hz)
    }

    /// One sample through the section (transposed direct form II); `state`
    /// holds the two delay elements.
    #[inline]
    pub(crate) fn step(&self, state: &mut [f64; 2], x: f64) -> f64 {
        let y = self.b0 * x + state[0];
        state[0] = self.b1 * x - self.a1 * y + state[1];
        state[1] = self.b2 * x - self.a2 * y;
        y
    }

    /// State of the delay elements after an input constant at `level`
    /// forever (output `dc_gain * level`).
    pub(crate) fn steady_state(&self, level: f64) -> [f64; 2] {
        let y = self.dc_gain() * level;
        [y - self.b0 * level, self.b2 * level - self.a2 * y]
    }

    /// Gain at 0 Hz (dimensionless).
    pub(crate) fn dc_gain(&self) -> f64 {
        (self.b0 + self.b1 + self.b2) / (1.0 + self.a1 + self.a2)
    }

    /// Complex response at `frequency_hz` for the sample rate the section
    /// was designed for.
    pub(crate) fn response(&self, frequency_hz: f64, sample_rate_hz: f64) -> Complex64 {
        let z1 = Complex64::from_polar(1.0, -2.0 * PI * frequency_hz / sample_rate_hz);
        let z2 = z1 * z1;
        (self.b0 + self.b1 * z1 + self.b2 * z2) / (1.0 + self.a1 * z1 + self.a2 * z2)
    }

    /// 2nd-order Butterworth high-pass with -3 dB at `cutoff_hz` (one pass),
    /// designed by the bilinear transform with the cutoff pre-warped so that
    /// the digital filter has exactly |H| = 1/sqrt(2) at `cutoff_hz`.
    ///
    /// Requires `0 < cutoff_hz < sample_rate_hz / 2` (checked by the caller).
    pub(crate) fn butterworth_highpass(sample_rate_hz: f64, cutoff_hz: f64) -> Self {
        let k = (std::f64::consts::PI * cutoff_hz / sample_rate_hz).tan();
        let sqrt2 = std::f64::consts::SQRT_2;
        let norm = 1.0 / (1.0 + sqrt2 * k + k * k);
        Self {
            b0: norm,
            b1: -2.0 * norm,
            b2: norm,
            a1: 2.0 * (k * k - 1.0) * norm,
            a2: (1.0 - sqrt2 * k + k * k) * norm,
        }
    }

    /// Filters `data` in place (transposed direct form II).
    ///
    /// The filter starts in the state left by the past inputs
    /// `x[-1] = past[0]`, `x[-2] = past[1]` (signal units) with the past
    /// outputs at rest at 0. For a high-pass with a double zero at DC that
    /// is the exact steady state after a constant or a ramp through those two
    /// points, so such a history causes no transient.
    pub(crate) fn filter_in_place(&self, data: &mut [f64], past: [f64; 2]) {
        let Self { b0, b1, b2, a1, a2 } = *self;
        let [x_m1, x_m2] = past;
        // z1 = b1 x[-1] + b2 x[-2] - a1 y[-1] - a2 y[-2], z2 = b2 x[-1] - a2 y[-1]
        // with y[-1] = y[-2] = 0.
        let mut z1 = b1 * x_m1 + b2 * x_m2;
        let mut z2 = b2 * x_m1;
        for v in data.iter_mut() {
            let x = *v;
            let y = b0 * x + z1;
            z1 = b1 * x - a1 * y + z2;
            z2 = b2 * x - a2 * y;
            *v = y;
        }
    }
}
