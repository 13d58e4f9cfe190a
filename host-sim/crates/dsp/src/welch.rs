//! Averaged power spectral density by Welch's method (seed paper, Fig. 4:
//! "torque ripple average power spectral density in the constant velocity
//! stage"), with the amplitude of a spectral line read back from the PSD.

use realfft::RealFftPlanner;

use super::{check_sample_rate, check_signal, hann_periodic, AnalysisError};

/// Smallest segment length in samples.
const MIN_SEGMENT_SAMPLES: usize = 4;
/// Half-width of the periodic Hann window's main lobe, in bins: a sinusoid
/// puts more than 99.9 % of its power into the peak bin and the two bins on
/// either side of it, wherever it falls between bins.
const MAIN_LOBE_HALF_WIDTH_BINS: usize = 2;

/// One-sided power spectral density.
///
/// `density[k]` is the power spectral density at `frequency_hz[k]` in
/// unit^2/Hz, where unit is the unit of the analysed signal (for a torque in
/// N m: (N m)^2/Hz). Frequencies are ascending from 0 Hz in steps of
/// `sample_rate_hz / segment_len` up to at most the Nyquist frequency; the two
/// vectors have the same length. The sum of `density[k] * df` over all bins
/// is the (segment-averaged, window-weighted) variance of the signal.
#[derive(Debug, Clone, PartialEq)]
pub struct Psd {
    /// Bin frequencies in Hz, ascending from 0 Hz, equally spaced.
    pub frequency_hz: Vec<f64>,
    /// One-sided power spectral density per bin, unit^2/Hz.
    pub density: Vec<f64>,
}

/// One-sided PSD of `signal` by Welch's method (averaged modified
/// periodograms).
///
/// * `signal`: uniformly sampled, any unit (the PSD is in unit^2/Hz).
/// * `sample_rate_hz`: sample rate in Hz, finite and > 0.
/// * `segment_len`: samples per segment, at least 4 and at most the signal
///   length; the frequency resolution (bin spacing) is
///   `sample_rate_hz / segment_len` Hz.
/// * `overlap`: fraction of a segment shared with the next one, in
///   `[0, 1)`; the hop is `round(segment_len * (1 - overlap))` samples, at
///   least 1 (0.5 is the usual choice for the Hann window).
///
/// Segments start at sample 0 and advance by the hop; samples after the last
/// full segment are not used. From each segment its own mean is removed
/// (like `scipy.signal.welch`'s default `detrend="constant"`: a DC level,
/// such as the load torque under a torque ripple, then does not leak into the
/// lowest bins), the result is multiplied by a periodic Hann window `w` and
/// transformed. The segment's one-sided periodogram is
/// `P[k] = c |X[k]|^2 / (fs sum(w^2))` with `c = 2` except at 0 Hz and the
/// Nyquist frequency (`c = 1`), and the PSD is the plain mean of the
/// segments' periodograms. With this density scaling the integral of the PSD
/// (`sum(density) * df`) is the mean over segments of
/// `sum(w^2 (x - mean)^2) / sum(w^2)`: for a stationary signal its variance,
/// for a sinusoid of amplitude `A` well above the bin spacing `A^2 / 2`.
///
/// # Errors
/// [`AnalysisError::EmptySignal`] or [`AnalysisError::NonFinite`] for a bad
/// signal, [`AnalysisError::TooShort`] when the signal is shorter than one
/// segment, [`AnalysisError::InvalidParameter`] for a bad sample rate,
/// segment length or overlap, [`AnalysisError::NumericOverflow`] for signal
/// values near the f64 limit.
pub fn welch_psd(signal: &[f64], sample_rate_hz: f64, segment_len: usize, overlap: f64) -> Result<Psd, AnalysisError> {
    check_sample_rate(sample_rate_hz)?;
    if segment_len < MIN_SEGMENT_SAMPLES {
        return Err(AnalysisError::InvalidParameter {
            name: "segment_len",
            value: segment_len as f64,
            expected: "a segment of at least 4 samples",
        });
    }
    if !(overlap.is_finite() && (0.0..1.0).contains(&overlap)) {
        return Err(AnalysisError::InvalidParameter {
            name: "overlap",
            value: overlap,
            expected: "a fraction with 0 <= overlap < 1",
        });
    }
    check_signal(signal, segment_len, "one Welch segment (segment_len samples)")?;

    let n = signal.len();
    let hop = ((segment_len as f64) * (1.0 - overlap)).round().max(1.0) as usize;
    let segments = 1 + (n - segment_len) / hop;

    let window = hann_periodic(segment_len);
    let window_power: f64 = window.iter().map(|w| w * w).sum();
    let scale = 1.0 / (sample_rate_hz * window_power * segments as f64);

    let mut planner = RealFftPlanner::<f64>::new();
    let fft = planner.plan_fft_forward(segment_len);
    let mut input = fft.make_input_vec();
    let mut output = fft.make_output_vec();
    let mut scratch = fft.make_scratch_vec();
    let bins = output.len();
    let mut density = vec![0.0; bins];

    for seg in 0..segments {
        let chunk = &signal[seg * hop..seg * hop + segment_len];
        let mean = chunk.iter().map(|v| v / segment_len as f64).sum::<f64>();
        for ((dst, &x), &w) in input.iter_mut().zip(chunk).zip(&window) {
            *dst = (x - mean) * w;
        }
        fft.process_with_scratch(&mut input, &mut output, &mut scratch)
            .map_err(|e| AnalysisError::Fft { message: e.to_string() })?;
        for (acc, c) in density.iter_mut().zip(&output) {
            *acc += c.norm_sqr();
        }
    }
    for (k, d) in density.iter_mut().enumerate() {
        // 0 Hz and (for even lengths) the Nyquist bin have no mirror image.
        let single_sided = if k == 0 || 2 * k == segment_len { 1.0 } else { 2.0 };
        *d *= single_sided * scale;
    }
    if density.iter().any(|d| !d.is_finite()) {
        return Err(AnalysisError::NumericOverflow { what: "Welch power spectral density" });
    }
    let df = sample_rate_hz / segment_len as f64;
    let frequency_hz = (0..bins).map(|k| k as f64 * df).collect();
    Ok(Psd { frequency_hz, density })
}

impl Psd {
    /// Bin spacing in Hz (0 when there are fewer than two bins).
    pub fn bin_width_hz(&self) -> f64 {
        match self.frequency_hz.as_slice() {
            [f0, f1, ..] => f1 - f0,
            _ => 0.0,
        }
    }

    /// Integral of the density over `lo_hz <= f <= hi_hz` (Hz), in unit^2:
    /// the sum of `density[k] * df` over the bins in that band (the power of
    /// the signal in the band). Returns `None` when a bound is not finite or
    /// `lo_hz > hi_hz`; an empty band gives `Some(0.0)`.
    pub fn band_power(&self, lo_hz: f64, hi_hz: f64) -> Option<f64> {
        if !(lo_hz.is_finite() && hi_hz.is_finite() && lo_hz <= hi_hz) {
            return None;
        }
        let df = self.bin_width_hz();
        Some(
            self.frequency_hz
                .iter()
                .zip(&self.density)
                .filter(|(f, _)| **f >= lo_hz && **f <= hi_hz)
                .map(|(_, d)| d * df)
                .sum(),
        )
    }

    /// Frequency (Hz) and peak amplitude (signal units) of the spectral line
    /// (sinusoid) with the largest density within `f_hz ± halfwidth_hz`.
    ///
    /// The line's bins are the largest bin in that search band and the two
    /// bins on either side of it (the main lobe of the Hann window used by
    /// [`welch_psd`], clipped to the spectrum; the search band does not limit
    /// them). Its power is their integral `sum(density * df)` (unit^2),
    /// the amplitude `sqrt(2 * power)`, and the frequency the power-weighted
    /// mean of their frequencies. For a sinusoid of amplitude `A` more than
    /// three bins from 0 Hz and the Nyquist frequency, and from other lines,
    /// the main lobe holds more than 99.9 % of `A^2 / 2`, so the amplitude is
    /// within 0.05 % plus the contribution of the noise floor under the five
    /// bins; the frequency is within a few hundredths of a bin. A line whose
    /// frequency wanders by more than about a bin while the segments are
    /// averaged (angle-locked ripple under a varying speed) spreads beyond
    /// the main lobe, and that power is not counted: choose the segment
    /// length accordingly.
    ///
    /// Returns `None` when `f_hz` or `halfwidth_hz` is not finite, when
    /// `halfwidth_hz < 0`, when the two vectors differ in length or have fewer
    /// than two bins, or when no bin lies in the search band.
    pub fn line_amplitude(&self, f_hz: f64, halfwidth_hz: f64) -> Option<(f64, f64)> {
        let valid = f_hz.is_finite() && halfwidth_hz.is_finite() && halfwidth_hz >= 0.0;
        let n = self.density.len();
        if !valid || self.frequency_hz.len() != n || n < 2 {
            return None;
        }
        let (lo, hi) = (f_hz - halfwidth_hz, f_hz + halfwidth_hz);
        let (peak, _) = self
            .frequency_hz
            .iter()
            .zip(&self.density)
            .enumerate()
            .filter(|(_, (f, d))| **f >= lo && **f <= hi && d.is_finite())
            .max_by(|a, b| a.1 .1.total_cmp(b.1 .1))?;
        let first = peak.saturating_sub(MAIN_LOBE_HALF_WIDTH_BINS);
        let last = (peak + MAIN_LOBE_HALF_WIDTH_BINS).min(n - 1);
        let df = self.bin_width_hz();
        let (mut power, mut moment) = (0.0, 0.0);
        for k in first..=last {
            power += self.density[k] * df;
            moment += self.density[k] * df * self.frequency_hz[k];
        }
        let frequency = if power > 0.0 { moment / power } else { self.frequency_hz[peak] };
        let amplitude = (2.0 * power).sqrt();
        (frequency.is_finite() && amplitude.is_finite()).then_some((frequency, amplitude))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_signals::gaussian;
    use std::f64::consts::PI;

    fn variance(x: &[f64]) -> f64 {
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / x.len() as f64
    }

    fn integral(psd: &Psd) -> f64 {
        psd.density.iter().sum::<f64>() * psd.bin_width_hz()
    }

    #[test]
    fn parseval_white_noise() {
        let fs = 1000.0;
        let x: Vec<f64> = gaussian(1 << 18, 7).iter().map(|v| 0.3 * v + 2.0).collect();
        let var = variance(&x);
        for (seg, overlap) in [(1024, 0.5), (4096, 0.75), (1000, 0.0)] {
            let psd = welch_psd(&x, fs, seg, overlap).unwrap();
            assert_eq!(psd.frequency_hz.len(), seg / 2 + 1);
            assert!((psd.bin_width_hz() - fs / seg as f64).abs() < 1e-12);
            let ratio = integral(&psd) / var;
            eprintln!("white noise, segment {seg}, overlap {overlap}: integral / variance = {ratio:.5}");
            assert!((ratio - 1.0).abs() < 0.01, "segment {seg} overlap {overlap}: integral / variance = {ratio}");
            // White noise: flat at 2 var / fs (one-sided) on average.
            let mid = &psd.density[seg / 8..3 * seg / 8];
            let mean_level = mid.iter().sum::<f64>() / mid.len() as f64;
            assert!((mean_level / (2.0 * var / fs) - 1.0).abs() < 0.02, "level {mean_level}");
        }
    }

    #[test]
    fn parseval_sum_of_sines() {
        let fs = 16384.0;
        let tones = [(1.0, 2.0, 0.1), (12.0, 3.5, 1.3), (36.0, 0.3, 2.0), (72.3, 0.5, 0.7)];
        let x: Vec<f64> = (0..(20.0 * fs) as usize)
            .map(|k| {
                let t = k as f64 / fs;
                50.0 + tones.iter().map(|(f, a, ph)| a * (2.0 * PI * f * t + ph).sin()).sum::<f64>()
            })
            .collect();
        let var = variance(&x);
        let expected: f64 = tones.iter().map(|(_, a, _)| a * a / 2.0).sum();
        assert!((var / expected - 1.0).abs() < 1e-3);
        let psd = welch_psd(&x, fs, 4 * 16384, 0.5).unwrap();
        let ratio = integral(&psd) / var;
        eprintln!("sum of sines: integral / variance = {ratio:.5}");
        assert!((ratio - 1.0).abs() < 0.01, "integral / variance = {ratio}");
    }

    #[test]
    fn line_amplitude_and_frequency_of_sinusoids_in_noise() {
        let fs = 16384.0;
        let n = (20.0 * fs) as usize;
        let noise = gaussian(n, 99);
        let tones = [(12.37, 3.5), (36.0, 0.3), (72.81, 0.5), (1.02, 2.0)];
        let x: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 / fs;
                -20.0 + 0.05 * noise[k] + tones.iter().map(|(f, a)| a * (2.0 * PI * f * t + f).sin()).sum::<f64>()
            })
            .collect();
        // 4 s segments: 0.25 Hz bins, so 1 Hz is four bins from 0 Hz.
        let psd = welch_psd(&x, fs, 4 * 16384, 0.5).unwrap();
        for (f, a) in tones {
            let (f_est, a_est) = psd.line_amplitude(f, 0.5).unwrap();
            eprintln!("{f} Hz: amplitude error {:+.5}, frequency error {:+.5}", a_est / a - 1.0, f_est / f - 1.0);
            assert!((a_est / a - 1.0).abs() < 0.02, "{f} Hz: amplitude {a_est} vs {a}");
            assert!((f_est / f - 1.0).abs() < 0.005, "{f} Hz: frequency {f_est}");
        }
        // Band power of the 12.37 Hz line: A^2 / 2.
        let p = psd.band_power(11.5, 13.5).unwrap();
        assert!((p / (3.5 * 3.5 / 2.0) - 1.0).abs() < 0.01, "band power {p}");
        assert!(psd.line_amplitude(f64::NAN, 1.0).is_none());
        assert!(psd.line_amplitude(10.0, -1.0).is_none());
        assert!(psd.line_amplitude(1e6, 1.0).is_none());
    }

    #[test]
    fn line_amplitude_between_bins_is_accurate_without_noise() {
        // Offsets of 0, 1/4 and 1/2 bin: amplitude within 0.1 %, frequency
        // within 0.05 bin.
        let (fs, seg) = (1024.0, 1024);
        for offset in [0.0, 0.25, 0.5] {
            let f = 100.0 + offset;
            let x: Vec<f64> = (0..64 * seg).map(|k| 1.7 * (2.0 * PI * f * k as f64 / fs).cos()).collect();
            let psd = welch_psd(&x, fs, seg, 0.5).unwrap();
            let (f_est, a_est) = psd.line_amplitude(f, 2.0).unwrap();
            eprintln!(
                "offset {offset} bin: amplitude error {:+.6}, frequency error {:+.4} Hz",
                a_est / 1.7 - 1.0,
                f_est - f
            );
            assert!((a_est / 1.7 - 1.0).abs() < 1e-3, "offset {offset}: amplitude {a_est}");
            assert!((f_est - f).abs() < 0.05, "offset {offset}: frequency {f_est}");
        }
    }

    #[test]
    fn segment_mean_is_removed() {
        let psd = welch_psd(&[5.0; 4096], 100.0, 256, 0.5).unwrap();
        assert!(psd.density.iter().all(|d| d.abs() < 1e-25), "{:?}", &psd.density[..4]);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let x = vec![0.0; 100];
        let name = |r: Result<Psd, AnalysisError>| match r {
            Err(AnalysisError::InvalidParameter { name, .. }) => name,
            other => panic!("unexpected {other:?}"),
        };
        assert_eq!(name(welch_psd(&x, 0.0, 16, 0.5)), "sample_rate_hz");
        assert_eq!(name(welch_psd(&x, 10.0, 3, 0.5)), "segment_len");
        assert_eq!(name(welch_psd(&x, 10.0, 16, 1.0)), "overlap");
        assert_eq!(name(welch_psd(&x, 10.0, 16, f64::NAN)), "overlap");
        assert!(matches!(welch_psd(&x, 10.0, 101, 0.5), Err(AnalysisError::TooShort { len: 100, min: 101, .. })));
        assert_eq!(welch_psd(&[], 10.0, 16, 0.5), Err(AnalysisError::EmptySignal));
        let mut y = x.clone();
        y[3] = f64::NEG_INFINITY;
        assert!(matches!(welch_psd(&y, 10.0, 16, 0.5), Err(AnalysisError::NonFinite { index: 3, .. })));
        let big: Vec<f64> = (0..64).map(|k| if k % 2 == 0 { 1e300 } else { -1e300 }).collect();
        assert!(matches!(welch_psd(&big, 10.0, 16, 0.5), Err(AnalysisError::NumericOverflow { .. })));
    }
}
