//! Zero-phase high-pass filtering.
//!
//! [`highpass_zero_phase`] removes the static part and slow drift of a signal
//! (for example the DC offset and gravity-free drift of a piezoelectric
//! accelerometer) without shifting the phase of the content above the cutoff.

use super::biquad::Biquad;
use super::{check_sample_rate, check_signal, AnalysisError};

/// Number of filter time constants used as edge padding.
const PAD_TIME_CONSTANTS: f64 = 3.0;
/// Smallest edge padding in samples (limited by the signal length).
const MIN_PAD_SAMPLES: usize = 300;

/// Least-squares straight line through `samples` (index 0, 1, 2, ...):
/// returns (value at index 0, slope per sample), in signal units.
fn line_fit(samples: impl ExactSizeIterator<Item = f64> + Clone) -> (f64, f64) {
    let m = samples.len();
    if m < 2 {
        return (samples.clone().next().unwrap_or(0.0), 0.0);
    }
    let mid = 0.5 * (m - 1) as f64;
    let mean = samples.clone().map(|v| v / m as f64).sum::<f64>();
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (j, v) in samples.enumerate() {
        let dj = j as f64 - mid;
        sxy += dj * (v - mean);
        sxx += dj * dj;
    }
    let slope = sxy / sxx;
    (mean - slope * mid, slope)
}

/// Length of the odd-reflection padding at each end, in samples:
/// three decay time constants of the filter's poles, at least
/// [`MIN_PAD_SAMPLES`], and at most `len - 1` (the signal must be longer
/// than the padding to be reflected).
fn padding_len(sample_rate_hz: f64, cutoff_hz: f64, len: usize) -> usize {
    // Butterworth poles at w_c * exp(+-j 3 pi / 4): envelope decays with
    // time constant tau = 1 / (w_c cos(pi/4)) = sqrt(2) / (2 pi f_c).
    let tau_s = std::f64::consts::SQRT_2 / (2.0 * std::f64::consts::PI * cutoff_hz);
    // `as` saturates for huge values, so a tiny cutoff cannot overflow.
    let pad = (PAD_TIME_CONSTANTS * tau_s * sample_rate_hz).ceil() as usize;
    pad.max(MIN_PAD_SAMPLES).min(len.saturating_sub(1))
}

/// Zero-phase 2nd-order Butterworth high-pass filter (like MATLAB `filtfilt`).
///
/// * `signal`: uniformly sampled input, any unit; the output has the same unit.
/// * `sample_rate_hz`: sample rate in Hz, finite and > 0.
/// * `cutoff_hz`: cutoff in Hz, `0 < cutoff_hz < sample_rate_hz / 2`.
///
/// The single-pass filter is a 2nd-order Butterworth high-pass designed with
/// the bilinear transform and frequency pre-warping, so its magnitude is
/// `|H(f)|^2 = W^4 / (1 + W^4)` with `W = tan(pi f / fs) / tan(pi fc / fs)`.
/// It is run forward and then backward over the signal, so the overall
/// response is `|H(f)|^2` (0.5 = -6 dB at the cutoff) with zero phase shift.
/// Constants and linear ramps are removed entirely (double zero at DC).
///
/// To keep the edges from ringing, the signal is extended at both ends by an
/// odd (point) reflection, three time constants of the filter long
/// (`3 sqrt(2) / (2 pi fc)` seconds, at least 300 samples, at most the
/// signal length minus one). The reflection centre is the level of the local
/// trend at the end sample (least-squares line over one cutoff period
/// `1 / fc`, or the whole signal if shorter) rather than the end sample
/// itself: MATLAB's reflection about the end sample shifts the mean of the
/// padding by twice the vibration's instantaneous value at that sample, which
/// the high-pass turns into a slow transient of that size; about the trend level
/// the padding continues the slow part of the signal (level and slope) and
/// only the vibration phase jumps. The forward pass starts in the steady
/// state of the local trend line continued before the padding, the backward
/// pass from rest. With this, a tone of frequency `f` cut at an arbitrary
/// phase keeps its amplitude up to the first and last sample within about
/// `fc / f` of that amplitude (reflection about the end sample: up to the
/// full amplitude). The output has the same length as the input.
///
/// # Errors
/// [`AnalysisError::EmptySignal`] or [`AnalysisError::NonFinite`] for a bad
/// signal, [`AnalysisError::InvalidParameter`] for a bad sample rate or
/// cutoff, [`AnalysisError::NumericOverflow`] if the signal is so large
/// (around 1e300) that the filter overflows.
pub fn highpass_zero_phase(signal: &[f64], sample_rate_hz: f64, cutoff_hz: f64) -> Result<Vec<f64>, AnalysisError> {
    check_highpass(signal, sample_rate_hz, cutoff_hz)?;

    let n = signal.len();
    let pad = padding_len(sample_rate_hz, cutoff_hz, n);
    // Local trend (straight line over one cutoff period) at each end: its
    // value at the end sample is the centre of the odd reflection, and its
    // slope sets the initial state of the forward pass.
    let fit_len = (sample_rate_hz / cutoff_hz).ceil().min(n as f64) as usize;
    let fit_len = fit_len.max(1);
    let (start_level, start_slope) = line_fit(signal[..fit_len].iter().copied());
    let (end_level, _) = line_fit(signal[n - fit_len..].iter().rev().copied());

    let mut buf = Vec::with_capacity(n + 2 * pad);
    buf.extend((1..=pad).rev().map(|i| 2.0 * start_level - signal[i]));
    buf.extend_from_slice(signal);
    buf.extend((1..=pad).map(|i| 2.0 * end_level - signal[n - 1 - i]));

    let biquad = Biquad::butterworth_highpass(sample_rate_hz, cutoff_hz);
    // Forward pass: history = the local trend line continued before the
    // padding (the reflection maps that line onto itself), so only the
    // vibration in the padding is new to the filter.
    let trend_at = |index: f64| start_level + start_slope * index;
    let first_index = -(pad as f64);
    biquad.filter_in_place(&mut buf, [trend_at(first_index - 1.0), trend_at(first_index - 2.0)]);
    // The forward pass has removed constants and ramps, so the backward
    // pass starts from rest.
    buf.reverse();
    biquad.filter_in_place(&mut buf, [0.0, 0.0]);
    buf.reverse();

    buf.truncate(pad + n);
    buf.drain(..pad);
    if buf.iter().any(|v| !v.is_finite()) {
        return Err(AnalysisError::NumericOverflow { what: "high-pass filter output" });
    }
    Ok(buf)
}

/// The complementary zero-phase low-pass: `signal` less its
/// [`highpass_zero_phase`] at `cutoff_hz` (Hz), the same length, what lies
/// below the cutoff (constants and ramps kept).
///
/// # Errors
/// Those of [`highpass_zero_phase`].
pub fn lowpass_complement_zero_phase(
    signal: &[f64],
    sample_rate_hz: f64,
    cutoff_hz: f64,
) -> Result<Vec<f64>, AnalysisError> {
    let high = highpass_zero_phase(signal, sample_rate_hz, cutoff_hz)?;
    Ok(signal.iter().zip(&high).map(|(a, h)| a - h).collect())
}

/// The checks of a high-pass's inputs: the sample rate, a cutoff with
/// `0 < cutoff_hz < sample_rate_hz / 2`, a finite non-empty signal.
fn check_highpass(signal: &[f64], sample_rate_hz: f64, cutoff_hz: f64) -> Result<(), AnalysisError> {
    check_sample_rate(sample_rate_hz)?;
    if !(cutoff_hz.is_finite() && cutoff_hz > 0.0 && cutoff_hz < 0.5 * sample_rate_hz) {
        return Err(AnalysisError::InvalidParameter {
            name: "cutoff_hz",
            value: cutoff_hz,
            expected: "a finite cutoff with 0 < cutoff_hz < sample_rate_hz / 2",
        });
    }
    check_signal(signal, 1, "high-pass filtering")
}

/// 2nd-order Butterworth high-pass of `signal` with -3 dB at `cutoff_hz`,
/// in one causal pass (as an analogue AC coupling filters: the phase is
/// not undone), the filter settled on the first sample's level so that a
/// constant input gives 0 from the first sample on.
///
/// # Errors
/// As [`highpass_zero_phase`] for a bad signal, sample rate or cutoff.
pub fn highpass_causal(signal: &[f64], sample_rate_hz: f64, cutoff_hz: f64) -> Result<Vec<f64>, AnalysisError> {
    check_highpass(signal, sample_rate_hz, cutoff_hz)?;
    let mut out = signal.to_vec();
    // A constant history at the first value: the double zero at DC leaves
    // no transient from it.
    Biquad::butterworth_highpass(sample_rate_hz, cutoff_hz).filter_in_place(&mut out, [signal[0], signal[0]]);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn causal_highpass_starts_settled_and_is_3_db_down_at_its_cutoff() {
        let fs = 1000.0;
        // A constant gives 0 from the first sample on.
        let flat = highpass_causal(&[2.5; 100], fs, 1.0).unwrap();
        assert!(flat.iter().all(|v| v.abs() < 1e-12), "{flat:?}");
        // A sine at the cutoff passes at 1/sqrt(2) once settled.
        let x: Vec<f64> = (0..20_000).map(|k| (std::f64::consts::TAU * k as f64 / fs).sin()).collect();
        let y = highpass_causal(&x, fs, 1.0).unwrap();
        let rms = |v: &[f64]| (v.iter().map(|a| a * a).sum::<f64>() / v.len() as f64).sqrt();
        let gain = rms(&y[10_000..]) / rms(&x[10_000..]);
        assert!((gain - 0.5f64.sqrt()).abs() < 2e-3, "{gain}");
        assert!(highpass_causal(&x, fs, 600.0).is_err());
        assert!(highpass_causal(&[], fs, 1.0).is_err());
    }

    /// The complementary low-pass keeps a slow tone and a ramp, removes a
    /// fast tone, and adds back to the signal with the high-pass; its bad
    /// inputs are the high-pass's.
    #[test]
    fn complementary_lowpass_keeps_what_lies_below_the_cutoff() {
        let fs = 1000.0;
        let n = 10_000;
        let slow = sine(fs, 0.5, 1.0, 0.3, n);
        let fast = sine(fs, 80.0, 0.4, 1.1, n);
        let x: Vec<f64> = (0..n).map(|k| slow[k] + fast[k] + 1e-3 * k as f64).collect();
        let low = lowpass_complement_zero_phase(&x, fs, 10.0).unwrap();
        let high = highpass_zero_phase(&x, fs, 10.0).unwrap();
        for k in 1000..n - 1000 {
            assert!((low[k] - slow[k] - 1e-3 * k as f64).abs() < 1e-3, "{k}: {}", low[k]);
            assert!((low[k] + high[k] - x[k]).abs() < 1e-12);
        }
        assert!(lowpass_complement_zero_phase(&x, fs, 600.0).is_err());
        assert!(lowpass_complement_zero_phase(&[], fs, 1.0).is_err());
    }
    use std::f64::consts::PI;

    fn sine(fs: f64, f: f64, amp: f64, phase: f64, n: usize) -> Vec<f64> {
        (0..n).map(|k| amp * (2.0 * PI * f * k as f64 / fs + phase).sin()).collect()
    }

    /// Least-squares amplitude of the in-phase (sin) and quadrature (cos)
    /// components of `y` at frequency `f` over samples `range`, which must
    /// span an integer number of periods.
    fn project(y: &[f64], fs: f64, f: f64, phase: f64, range: std::ops::Range<usize>) -> (f64, f64) {
        let len = range.len() as f64;
        let (mut s, mut c) = (0.0, 0.0);
        for k in range {
            let arg = 2.0 * PI * f * k as f64 / fs + phase;
            s += y[k] * arg.sin();
            c += y[k] * arg.cos();
        }
        (2.0 * s / len, 2.0 * c / len)
    }

    /// Independent expression of the zero-phase magnitude |H|^2 of a
    /// pre-warped 2nd-order Butterworth high-pass.
    fn filtfilt_gain(fs: f64, fc: f64, f: f64) -> f64 {
        let w = (PI * f / fs).tan() / (PI * fc / fs).tan();
        w.powi(4) / (1.0 + w.powi(4))
    }

    #[test]
    fn coefficients_match_analog_prototype_at_cutoff_and_dc() {
        let (fs, fc) = (1000.0, 50.0);
        let q = Biquad::butterworth_highpass(fs, fc);
        let h = |f: f64| {
            // Evaluate H(e^{jw}) with complex arithmetic by hand.
            let w = 2.0 * PI * f / fs;
            let (c1, s1) = (w.cos(), -w.sin());
            let (c2, s2) = ((2.0 * w).cos(), -(2.0 * w).sin());
            let num = (q.b0 + q.b1 * c1 + q.b2 * c2, q.b1 * s1 + q.b2 * s2);
            let den = (1.0 + q.a1 * c1 + q.a2 * c2, q.a1 * s1 + q.a2 * s2);
            ((num.0 * num.0 + num.1 * num.1) / (den.0 * den.0 + den.1 * den.1)).sqrt()
        };
        assert!((h(fc) - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-12);
        assert!(h(0.0) < 1e-12);
        assert!((h(fs / 2.0 - 1e-9) - 1.0).abs() < 1e-6);
        assert_eq!(q.b0 + q.b1 + q.b2, 0.0);
    }

    #[test]
    fn sine_far_above_cutoff_passes_with_unit_gain_and_zero_phase() {
        let (fs, fc, f) = (1000.0, 0.5, 20.0);
        let phase = 0.3;
        let x = sine(fs, f, 1.0, phase, 10_000);
        let y = highpass_zero_phase(&x, fs, fc).unwrap();
        assert_eq!(y.len(), x.len());
        // Middle: sample-wise equality (gain 1, no phase shift).
        for k in 3000..7000 {
            assert!((y[k] - x[k]).abs() < 1e-3, "k = {k}: {} vs {}", y[k], x[k]);
        }
        // Same with the DC-free projection: in-phase 1, quadrature 0.
        let (a, b) = project(&y, fs, f, phase, 3000..7000);
        assert!((a - 1.0).abs() < 1e-3, "in-phase {a}");
        assert!(b.abs() < 1e-3, "quadrature {b}");
    }

    #[test]
    fn edges_do_not_ring_with_offset_and_sine() {
        // DC offset plus a tone cut at an arbitrary phase at both ends: the
        // output must match the tone up to the very first and last samples,
        // within about fc / f of its amplitude (asserted with margin).
        let (fs, fc) = (1000.0, 0.5);
        for f in [5.0, 20.0, 80.0] {
            let mut worst: f64 = 0.0;
            for i in 0..16 {
                let phase = i as f64 * PI / 8.0;
                let tone = sine(fs, f, 1.0, phase, 10_013);
                let x: Vec<f64> = tone.iter().map(|v| v + 5.0).collect();
                let y = highpass_zero_phase(&x, fs, fc).unwrap();
                let max_err = y.iter().zip(&tone).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
                worst = worst.max(max_err);
            }
            assert!(worst < 1.5 * fc / f, "f {f}: max edge error {worst}");
        }
    }

    #[test]
    fn decaying_oscillation_starting_at_its_peak_keeps_its_envelope() {
        // Free-decay-like record: offset + ramp + 8 Hz oscillation starting
        // at its maximum, decaying with 2 s time constant; 0.5 Hz cutoff.
        let (fs, fc) = (2000.0, 0.5);
        let n = 16_000;
        let osc: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 / fs;
                (-t / 2.0).exp() * (2.0 * PI * 8.0 * t).cos()
            })
            .collect();
        let x: Vec<f64> = osc.iter().enumerate().map(|(k, v)| v - 2.0 + 0.05 * k as f64 / fs).collect();
        let y = highpass_zero_phase(&x, fs, fc).unwrap();
        let max_err = y.iter().zip(&osc).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(max_err < 0.005, "max error {max_err}");
    }

    #[test]
    fn sine_at_cutoff_is_attenuated_to_half() {
        let (fs, fc) = (1000.0, 5.0);
        let x = sine(fs, fc, 2.0, 0.0, 20_000);
        let y = highpass_zero_phase(&x, fs, fc).unwrap();
        let expected = 2.0 * filtfilt_gain(fs, fc, fc);
        assert!((filtfilt_gain(fs, fc, fc) - 0.5).abs() < 1e-12);
        // Sample-wise in the middle: y = 0.5 x (zero phase).
        for k in 8000..12000 {
            assert!((y[k] - 0.5 * x[k]).abs() < 0.01 * expected, "k = {k}: {} vs {}", y[k], 0.5 * x[k]);
        }
        let (a, b) = project(&y, fs, fc, 0.0, 8000..12000);
        assert!((a / expected - 1.0).abs() < 0.01, "amplitude {a}");
        assert!(b.abs() < 0.01 * expected, "quadrature {b}");
    }

    #[test]
    fn magnitude_follows_squared_butterworth_response() {
        let (fs, fc) = (1000.0, 4.0);
        for &f in &[2.0, 3.0, 4.0, 6.0, 10.0, 40.0] {
            let x = sine(fs, f, 1.0, 0.0, 40_000);
            let y = highpass_zero_phase(&x, fs, fc).unwrap();
            // 10 s in the middle = integer number of periods for these f.
            let (a, b) = project(&y, fs, f, 0.0, 15_000..25_000);
            let g = filtfilt_gain(fs, fc, f);
            assert!((a - g).abs() < 0.005 * g + 1e-6, "f = {f}: {a} vs {g}");
            assert!(b.abs() < 0.005 * g + 1e-6, "f = {f}: quadrature {b}");
        }
    }

    #[test]
    fn constant_is_removed_everywhere() {
        let x = vec![3.7; 5000];
        let y = highpass_zero_phase(&x, 1000.0, 1.0).unwrap();
        let max = y.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        assert!(max < 1e-9, "residual {max}");
    }

    #[test]
    fn slow_ramp_is_removed() {
        // 1 + 0.2 t over 20 s: a 4-unit rise, far below the 1 Hz cutoff.
        let fs = 500.0;
        let x: Vec<f64> = (0..10_000).map(|k| 1.0 + 0.2 * k as f64 / fs).collect();
        let y = highpass_zero_phase(&x, fs, 1.0).unwrap();
        let max_mid = y[2000..8000].iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let max_all = y.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        assert!(max_mid < 1e-6, "middle residual {max_mid}");
        // Edges: the reflection about the trend line continues the ramp
        // exactly and the filter starts in its ramp steady state.
        assert!(max_all < 1e-9, "edge residual {max_all}");
    }

    #[test]
    fn line_fit_recovers_level_and_slope() {
        let x: Vec<f64> = (0..50).map(|j| 2.5 - 0.125 * j as f64).collect();
        let (c, b) = line_fit(x.iter().copied());
        assert!((c - 2.5).abs() < 1e-12 && (b + 0.125).abs() < 1e-12);
        // Reversed: level at the last sample, slope per sample backwards.
        let (c, b) = line_fit(x.iter().rev().copied());
        assert!((c - (2.5 - 0.125 * 49.0)).abs() < 1e-12 && (b - 0.125).abs() < 1e-12);
        // Symmetric noise around a line does not move the fit:
        // residuals +1, -1, -1, +1 are orthogonal to 1 and j - 1.5.
        let y = [1.0 + 1.0, 2.0 - 1.0, 3.0 - 1.0, 4.0 + 1.0];
        let (c, b) = line_fit(y.iter().copied());
        assert!((c - 1.0).abs() < 1e-12 && (b - 1.0).abs() < 1e-12);
        assert_eq!(line_fit([7.0].iter().copied()), (7.0, 0.0));
    }

    #[test]
    fn padding_is_three_time_constants_limited_by_length() {
        // fc = 1 Hz, fs = 1000 Hz: tau = sqrt(2)/(2 pi) s = 225.08 samples.
        assert_eq!(padding_len(1000.0, 1.0, 100_000), 676);
        assert_eq!(padding_len(1000.0, 100.0, 100_000), MIN_PAD_SAMPLES);
        assert_eq!(padding_len(1000.0, 1.0, 50), 49);
        assert_eq!(padding_len(1000.0, 1e-300, 10), 9);
        // Short signals still work (pad limited by length).
        let y = highpass_zero_phase(&[1.0, 2.0, 3.0], 100.0, 1.0).unwrap();
        assert_eq!(y.len(), 3);
        assert!(y.iter().all(|v| v.is_finite()));
        let y1 = highpass_zero_phase(&[4.0], 100.0, 1.0).unwrap();
        assert_eq!(y1, vec![0.0]);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let x = [0.0, 1.0, 2.0];
        assert_eq!(highpass_zero_phase(&[], 100.0, 1.0), Err(AnalysisError::EmptySignal));
        assert!(matches!(
            highpass_zero_phase(&[0.0, f64::NAN], 100.0, 1.0),
            Err(AnalysisError::NonFinite { index: 1, .. })
        ));
        for (fs, fc, name) in [
            (0.0, 1.0, "sample_rate_hz"),
            (f64::INFINITY, 1.0, "sample_rate_hz"),
            (100.0, 0.0, "cutoff_hz"),
            (100.0, 50.0, "cutoff_hz"),
            (100.0, f64::NAN, "cutoff_hz"),
        ] {
            match highpass_zero_phase(&x, fs, fc) {
                Err(AnalysisError::InvalidParameter { name: n, .. }) => assert_eq!(n, name),
                other => panic!("fs {fs} fc {fc}: {other:?}"),
            }
        }
        assert!(matches!(
            highpass_zero_phase(&[1e308, -1e308, 1e308, -1e308], 100.0, 1.0),
            Err(AnalysisError::NumericOverflow { .. })
        ));
    }
}
