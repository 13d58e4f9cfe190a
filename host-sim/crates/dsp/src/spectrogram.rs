//! Short-time Fourier transform spectrogram (power spectral density over
//! time), used to follow the natural frequencies of the rope system while the
//! rope lengths change during a travel.

use realfft::RealFftPlanner;

use super::{check_sample_rate, check_signal, hann_periodic, AnalysisError};

/// Smallest window length in samples.
const MIN_WINDOW_SAMPLES: usize = 4;
/// PSD values below this (in unit^2/Hz) are clamped before taking the
/// logarithm so that an exactly zero bin gives -3000 dB instead of -inf.
const PSD_FLOOR: f64 = 1e-300;

/// Spectrogram: power spectral density per time segment.
///
/// `psd_db[i][k]` is the one-sided power spectral density of segment `i` at
/// frequency `frequency_hz[k]`, as `10 log10(PSD)` in dB re 1 unit^2/Hz,
/// where unit is the unit of the analysed signal (for an acceleration in
/// m/s^2: dB re 1 (m/s^2)^2/Hz). Every row has `frequency_hz.len()` entries
/// and there is one row per entry of `times_s`. All values are finite (an
/// exactly zero PSD is clamped to -3000 dB).
#[derive(Debug, Clone, PartialEq)]
pub struct Spectrogram {
    /// Segment centre times in s, measured like the sample times (sample `k`
    /// is at `k / sample_rate_hz`), ascending.
    pub times_s: Vec<f64>,
    /// Bin frequencies in Hz, ascending from 0 Hz.
    pub frequency_hz: Vec<f64>,
    /// PSD in dB re 1 unit^2/Hz, indexed `[time_index][frequency_index]`.
    pub psd_db: Vec<Vec<f64>>,
}

/// Spectrogram of `signal` by the short-time Fourier transform.
///
/// * `signal`: uniformly sampled, any unit (the PSD is in unit^2/Hz).
/// * `sample_rate_hz`: sample rate in Hz, finite and > 0.
/// * `window_s`: segment length in s; `round(window_s * sample_rate_hz)`
///   samples, at least 4 and at most the signal length. The frequency
///   resolution is `1 / window_s` Hz.
/// * `overlap`: fraction of a segment shared with the next one, in
///   `[0, 1)`; the hop is `round(window * (1 - overlap))` samples, at least 1.
/// * `max_frequency_hz`: highest frequency kept, in Hz,
///   `0 < max_frequency_hz <= sample_rate_hz / 2`.
///
/// Each segment (the signal is used as is, its mean is not removed) is
/// multiplied by a periodic Hann window `w` and transformed; the one-sided
/// PSD is `P[k] = c |X[k]|^2 / (fs sum(w^2))` with `c = 2` except at 0 Hz
/// and the Nyquist frequency (`c = 1`). With this density scaling the
/// integral of the PSD over 0..fs/2 equals the window-weighted mean square
/// of the segment, `sum(w^2 x^2) / sum(w^2)` (for a stationary signal: its
/// mean square; for a sinusoid of amplitude `A`: `A^2 / 2`). Segments start
/// at sample 0 and advance by the hop; samples after the last full segment
/// are not used. `times_s` holds the centre time of each segment.
///
/// # Errors
/// [`AnalysisError::EmptySignal`] or [`AnalysisError::NonFinite`] for a bad
/// signal, [`AnalysisError::TooShort`] when the signal is shorter than one
/// window, [`AnalysisError::InvalidParameter`] for a bad sample rate, window,
/// overlap or maximum frequency, [`AnalysisError::NumericOverflow`] for
/// signal values near the f64 limit.
pub fn stft_spectrogram(
    signal: &[f64],
    sample_rate_hz: f64,
    window_s: f64,
    overlap: f64,
    max_frequency_hz: f64,
) -> Result<Spectrogram, AnalysisError> {
    check_sample_rate(sample_rate_hz)?;
    crate::check_window(window_s, overlap)?;
    let nyquist_hz = 0.5 * sample_rate_hz;
    if !(max_frequency_hz.is_finite() && max_frequency_hz > 0.0 && max_frequency_hz <= nyquist_hz) {
        return Err(AnalysisError::InvalidParameter {
            name: "max_frequency_hz",
            value: max_frequency_hz,
            expected: "a frequency with 0 < max_frequency_hz <= sample_rate_hz / 2",
        });
    }
    check_signal(signal, 1, "a spectrogram")?;

    let window_samples = (window_s * sample_rate_hz).round();
    if window_samples < MIN_WINDOW_SAMPLES as f64 {
        return Err(AnalysisError::InvalidParameter {
            name: "window_s",
            value: window_s,
            expected: "a window of at least 4 samples (window_s * sample_rate_hz >= 4)",
        });
    }
    let n = signal.len();
    if window_samples > n as f64 {
        return Err(AnalysisError::TooShort {
            len: n,
            min: window_samples.min(usize::MAX as f64) as usize,
            what: "one spectrogram window (window_s * sample_rate_hz samples)",
        });
    }
    let nwin = window_samples as usize;
    let hop = ((nwin as f64) * (1.0 - overlap)).round().max(1.0) as usize;
    let segments = 1 + (n - nwin) / hop;

    let df = sample_rate_hz / nwin as f64;
    let bins_kept = (0..=nwin / 2).take_while(|&k| k as f64 * df <= max_frequency_hz * (1.0 + 1e-12)).count();
    let frequency_hz: Vec<f64> = (0..bins_kept).map(|k| k as f64 * df).collect();

    let window = hann_periodic(nwin);
    let window_power: f64 = window.iter().map(|w| w * w).sum();
    let scale = 1.0 / (sample_rate_hz * window_power);

    let mut planner = RealFftPlanner::<f64>::new();
    let fft = planner.plan_fft_forward(nwin);
    let mut input = fft.make_input_vec();
    let mut output = fft.make_output_vec();
    let mut scratch = fft.make_scratch_vec();

    let mut times_s = Vec::with_capacity(segments);
    let mut psd_db = Vec::with_capacity(segments);
    for seg in 0..segments {
        let start = seg * hop;
        for ((dst, &x), &w) in input.iter_mut().zip(&signal[start..start + nwin]).zip(&window) {
            *dst = x * w;
        }
        fft.process_with_scratch(&mut input, &mut output, &mut scratch)
            .map_err(|e| AnalysisError::Fft { message: e.to_string() })?;
        let row: Vec<f64> = output[..bins_kept]
            .iter()
            .enumerate()
            .map(|(k, c)| {
                // 0 Hz and (for even lengths) the Nyquist bin have no mirror.
                let single_sided = if k == 0 || 2 * k == nwin { 1.0 } else { 2.0 };
                let psd = single_sided * c.norm_sqr() * scale;
                10.0 * psd.max(PSD_FLOOR).log10()
            })
            .collect();
        if row.iter().any(|v| !v.is_finite()) {
            return Err(AnalysisError::NumericOverflow { what: "spectrogram power spectral density" });
        }
        psd_db.push(row);
        times_s.push((start as f64 + 0.5 * (nwin - 1) as f64) / sample_rate_hz);
    }

    Ok(Spectrogram { times_s, frequency_hz, psd_db })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// Deterministic pseudo-random samples in [-1, 1) (xorshift64*).
    fn noise(n: usize, seed: u64) -> Vec<f64> {
        let mut state = seed.max(1);
        (0..n)
            .map(|_| {
                state ^= state >> 12;
                state ^= state << 25;
                state ^= state >> 27;
                let v = state.wrapping_mul(0x2545_F491_4F6C_DD1D);
                2.0 * ((v >> 11) as f64 / (1u64 << 53) as f64) - 1.0
            })
            .collect()
    }

    fn peak_frequency(s: &Spectrogram, row: usize) -> f64 {
        let k = s.psd_db[row].iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).map(|(k, _)| k).unwrap();
        s.frequency_hz[k]
    }

    #[test]
    fn psd_integral_equals_window_weighted_mean_square() {
        // Parseval: sum_k PSD[k] * df == sum(w^2 x^2) / sum(w^2), checked
        // against a window and sums computed here independently.
        let fs = 1000.0;
        let n = 5000;
        let x: Vec<f64> = noise(n, 42)
            .iter()
            .enumerate()
            .map(|(k, v)| 0.3 * v + 1.5 * (2.0 * PI * 60.3 * k as f64 / fs).sin() + 0.2)
            .collect();
        for (window_s, overlap) in [(0.5, 0.5), (0.301, 0.75), (1.0, 0.0)] {
            let s = stft_spectrogram(&x, fs, window_s, overlap, fs / 2.0).unwrap();
            let nwin = (window_s * fs).round() as usize;
            let hop = ((nwin as f64) * (1.0 - overlap)).round() as usize;
            assert_eq!(s.times_s.len(), 1 + (n - nwin) / hop);
            assert_eq!(s.frequency_hz.len(), nwin / 2 + 1);
            let df = fs / nwin as f64;
            let w: Vec<f64> = (0..nwin).map(|j| (PI * j as f64 / nwin as f64).sin().powi(2)).collect();
            let w2: f64 = w.iter().map(|v| v * v).sum();
            for (i, row) in s.psd_db.iter().enumerate() {
                let start = i * hop;
                let ms: f64 = (0..nwin).map(|j| (w[j] * x[start + j]).powi(2)).sum::<f64>() / w2;
                let integral: f64 = row.iter().map(|db| 10f64.powf(db / 10.0) * df).sum();
                assert!((integral / ms - 1.0).abs() < 1e-9, "window {window_s} segment {i}: {integral} vs {ms}");
                let centre = (start as f64 + (nwin as f64 - 1.0) / 2.0) / fs;
                assert!((s.times_s[i] - centre).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn sine_power_is_half_amplitude_squared() {
        let fs = 2000.0;
        let a = 0.7;
        let x: Vec<f64> = (0..8000).map(|k| a * (2.0 * PI * 123.4 * k as f64 / fs + 0.3).sin()).collect();
        let s = stft_spectrogram(&x, fs, 0.5, 0.5, 1000.0).unwrap();
        let df = s.frequency_hz[1];
        assert!((df - 2.0).abs() < 1e-12);
        for row in &s.psd_db {
            let p: f64 = row.iter().map(|db| 10f64.powf(db / 10.0) * df).sum();
            assert!((p / (a * a / 2.0) - 1.0).abs() < 0.01, "power {p}");
        }
    }

    #[test]
    fn stepped_tone_peak_is_found_in_each_segment() {
        let fs = 1024.0;
        let steps = [(0.0, 2.0, 50.0), (2.0, 4.0, 120.0), (4.0, 6.0, 80.0)];
        let n = (6.0 * fs) as usize;
        let mut phase = 0.0;
        let x: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 / fs;
                let f = steps.iter().find(|s| t >= s.0 && t < s.1).unwrap().2;
                phase += 2.0 * PI * f / fs;
                phase.sin()
            })
            .collect();
        let window_s = 0.25;
        let s = stft_spectrogram(&x, fs, window_s, 0.5, 200.0).unwrap();
        assert!(*s.frequency_hz.last().unwrap() <= 200.0);
        assert!(200.0 - s.frequency_hz.last().unwrap() < s.frequency_hz[1]);
        let mut checked = 0;
        for (i, &t) in s.times_s.iter().enumerate() {
            // Only segments entirely inside one step.
            let half = window_s / 2.0;
            if let Some(step) = steps.iter().find(|s| t - half >= s.0 && t + half <= s.1) {
                let f = peak_frequency(&s, i);
                assert!((f - step.2).abs() <= 2.0 + 1e-9, "t {t}: peak {f} expected {}", step.2);
                checked += 1;
            }
        }
        assert!(checked >= 30, "only {checked} segments checked");
    }

    #[test]
    fn chirp_peak_tracks_instantaneous_frequency() {
        // f(t) = 20 + 30 t Hz over 8 s; 0.5 s windows: the peak bin must be
        // within one bin (2 Hz) plus the sweep across half a window of
        // f at the segment centre.
        let fs = 2048.0;
        let n = (8.0 * fs) as usize;
        let x: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 / fs;
                (2.0 * PI * (20.0 * t + 15.0 * t * t)).sin()
            })
            .collect();
        let s = stft_spectrogram(&x, fs, 0.5, 0.75, 400.0).unwrap();
        for (i, &t) in s.times_s.iter().enumerate() {
            let f_inst = 20.0 + 30.0 * t;
            let f = peak_frequency(&s, i);
            assert!((f - f_inst).abs() <= 2.0, "t {t}: peak {f} vs {f_inst}");
        }
        assert!(s.times_s.len() > 50);
    }

    #[test]
    fn zero_signal_gives_floor_not_infinity() {
        let s = stft_spectrogram(&[0.0; 256], 100.0, 0.64, 0.5, 50.0).unwrap();
        assert!(s.psd_db.iter().flatten().all(|v| *v == -3000.0));
    }

    #[test]
    fn bad_inputs_are_errors() {
        let x = vec![0.0; 1000];
        let param = |r: Result<Spectrogram, AnalysisError>| match r {
            Err(AnalysisError::InvalidParameter { name, .. }) => name,
            other => panic!("unexpected {other:?}"),
        };
        assert_eq!(param(stft_spectrogram(&x, 0.0, 1.0, 0.5, 10.0)), "sample_rate_hz");
        assert_eq!(param(stft_spectrogram(&x, 100.0, 0.0, 0.5, 10.0)), "window_s");
        assert_eq!(param(stft_spectrogram(&x, 100.0, 0.02, 0.5, 10.0)), "window_s");
        assert_eq!(param(stft_spectrogram(&x, 100.0, 1.0, 1.0, 10.0)), "overlap");
        assert_eq!(param(stft_spectrogram(&x, 100.0, 1.0, -0.1, 10.0)), "overlap");
        assert_eq!(param(stft_spectrogram(&x, 100.0, 1.0, 0.5, 50.1)), "max_frequency_hz");
        assert_eq!(param(stft_spectrogram(&x, 100.0, 1.0, 0.5, f64::NAN)), "max_frequency_hz");
        assert!(matches!(
            stft_spectrogram(&x, 100.0, 20.0, 0.5, 10.0),
            Err(AnalysisError::TooShort { len: 1000, min: 2000, .. })
        ));
        assert_eq!(stft_spectrogram(&[], 100.0, 1.0, 0.5, 10.0), Err(AnalysisError::EmptySignal));
        let mut y = x.clone();
        y[17] = f64::NAN;
        assert!(matches!(stft_spectrogram(&y, 100.0, 1.0, 0.5, 10.0), Err(AnalysisError::NonFinite { index: 17, .. })));
    }
}
