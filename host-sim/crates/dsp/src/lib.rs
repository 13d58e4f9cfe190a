//! Signal analysis for recorded and simulated signals.
//!
//! All functions take uniformly sampled signals as `&[f64]` together with the
//! sample rate in Hz. Units of the signal are whatever the caller uses (for an
//! accelerometer m/s^2, for a phase current A); the documentation of each
//! function states how the output units follow from the signal units.
//!
//! Every function checks its inputs and returns an [`AnalysisError`] instead
//! of panicking; non-finite samples (NaN, ±inf) are rejected so that a NaN
//! never travels into a result.
//!
//! In the data flow config -> plant <-> controller -> recording -> analysis
//! -> diagnosis this crate is the analysis's signal processing: it knows
//! sampled signals only, neither the plant, the drive nor the recording
//! format, and depends on no other crate of the project. The analyses that
//! need the plant model (identification, the travel's torque balance) are in
//! the `diagnosis` crate.

#![warn(missing_docs)]

mod biquad;
pub mod burg;
pub mod chi_square;
pub mod difference;
pub mod dq0;
pub mod filter;
pub mod iso18738;
pub mod iso2631;
pub mod ride_quality;
pub mod ride_regions;
pub mod sine_fit;
pub mod spectrogram;
pub mod spectrum;
pub mod stages;
pub mod welch;

#[cfg(test)]
pub(crate) mod test_signals {
    //! Signals shared by the analysis tests.

    use std::f64::consts::PI;

    /// Deterministic standard normal samples (xorshift64* + Box-Muller).
    pub(crate) fn gaussian(n: usize, seed: u64) -> Vec<f64> {
        let mut state = seed.max(1);
        let mut uniform = move || {
            state ^= state >> 12;
            state ^= state << 25;
            state ^= state >> 27;
            // In (0, 1]: never 0, so the logarithm below is finite.
            ((state.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 + 1.0) / (1u64 << 53) as f64
        };
        (0..n).map(|_| (-2.0 * uniform().ln()).sqrt() * (2.0 * PI * uniform()).cos()).collect()
    }
}

pub use burg::{burg, burg_spectrogram, burg_tapered, decimate, select_order, ArModel, OrderCriterion};
pub use chi_square::{signal_power_interval, signal_power_limit};
pub use difference::central_difference;
pub use dq0::{dq_currents, machine_torque_nm};
pub use filter::{highpass_causal, highpass_zero_phase, lowpass_complement_zero_phase};
pub use iso18738::{
    ride_report, Axis, AxisFigures, MotionFigures, MotionSource, RegionFigures, RideInput, RideReport, SoundFigures,
};
pub use iso2631::{
    wd_digital_gain, wd_gain, wd_weighting, weighting, weighting_digital_gain, weighting_gain, wk_digital_gain,
    wk_gain, wk_weighting, Weighting,
};
pub use ride_quality::{ride_quality, RideQuality, RideQualityReport, TravelDirection};
pub use ride_regions::{
    regions_from_acceleration, regions_from_speed, velocity_from_acceleration, RegionSource, RideRegions,
};
pub use sine_fit::sine_fit;
pub use spectrogram::{stft_spectrogram, Spectrogram};
pub use spectrum::{amplitude_spectrum, AmplitudeSpectrum, SpectralPeak};
pub use stages::{constant_speed_stage, travel_phases, TravelPhases};
pub use welch::{welch_psd, Psd};

/// Checks the window length (s, finite, > 0) and overlap (fraction in
/// `[0, 1)`) of a segmented analysis.
pub(crate) fn check_window(window_s: f64, overlap: f64) -> Result<(), AnalysisError> {
    if !(window_s.is_finite() && window_s > 0.0) {
        return Err(AnalysisError::InvalidParameter {
            name: "window_s",
            value: window_s,
            expected: "a finite window length > 0 s",
        });
    }
    if !(overlap.is_finite() && (0.0..1.0).contains(&overlap)) {
        return Err(AnalysisError::InvalidParameter {
            name: "overlap",
            value: overlap,
            expected: "a fraction with 0 <= overlap < 1",
        });
    }
    Ok(())
}

/// `x` for a message: plain decimals for everyday magnitudes, scientific
/// notation for the very small and very large (never 300 zeros).
fn readable(x: f64) -> String {
    if x == 0.0 || !x.is_finite() || (1e-4..1e9).contains(&x.abs()) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// The message of [`AnalysisError::TooShort`]: a count of cycles is no
/// count of samples ("found 0 decaying cycles of the first mode", never
/// "the signal has 0 samples").
fn too_short_message(len: usize, min: usize, what: &str) -> String {
    if what.split_whitespace().any(|w| w == "cycles") {
        format!("the signal holds {len} {what}; expected at least {min}")
    } else {
        format!("the signal has {len} samples; expected at least {min} for {what}")
    }
}

/// Error returned by the analysis functions when an input is unusable.
///
/// Each variant names what was wrong and what was expected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AnalysisError {
    /// The signal has no samples; at least one sample is required.
    #[error("the signal is empty; expected at least one sample")]
    EmptySignal,
    /// The signal has fewer samples (or, when `what` names cycles, fewer
    /// such cycles) than the operation needs.
    #[error("{}", too_short_message(*len, *min, what))]
    TooShort {
        /// Number of samples in the signal (or of the cycles `what` names).
        len: usize,
        /// Smallest number the operation accepts.
        min: usize,
        /// What needs that many samples, or the cycles counted (a phrase
        /// with the word `cycles`: "decaying cycles of the first mode"),
        /// for the message.
        what: &'static str,
    },
    /// A sample is NaN or infinite.
    #[error("signal sample {index} is {value}; expected a finite number")]
    NonFinite {
        /// Zero-based index of the first non-finite sample.
        index: usize,
        /// The offending value (NaN or ±inf).
        value: f64,
    },
    /// A parameter is out of its valid range or not finite.
    #[error("invalid parameter `{name}` = {}; expected {expected}", readable(*value))]
    InvalidParameter {
        /// Name of the parameter, as in the function signature.
        name: &'static str,
        /// The value that was passed (converted to f64 for integer parameters).
        value: f64,
        /// Human-readable description of the accepted range.
        expected: &'static str,
    },
    /// The mode searched for lies at the top edge of the search band: the
    /// band may have cut the true mode off.
    #[error(
        "the first mode found, {frequency_hz:.3} Hz, lies at the top of the search band ({band_top_hz:.3} Hz); \
         expected a band that holds the mode with room above it (raise the band's top)"
    )]
    ModeAtBandEdge {
        /// Frequency of the line found, Hz.
        frequency_hz: f64,
        /// Top of the search band, Hz.
        band_top_hz: f64,
    },
    /// The speed of a travel holds no constant-speed stage long enough for
    /// the analyses of the stage (a travel cut short, or too short to
    /// settle at a steady speed).
    #[error(
        "the longest constant-speed stage of the speed signal lasts {stage_s:.3} s; expected at least {min_s} s \
         (the stage detector's smoothing window, about one shaft revolution of the reference rig, over which \
         the torque ripple averages out): is the travel cut short, or too short to reach a steady speed?"
    )]
    NoConstantSpeedStage {
        /// Length of the longest stage found, s.
        stage_s: f64,
        /// Shortest stage accepted, s.
        min_s: f64,
    },
    /// The oscillation's amplitude does not decay: a negative damping is
    /// not physical (a disturbance, or not a free decay).
    #[error(
        "the amplitude of the first mode does not decay (logarithmic decrement {decrement:.4}); expected a free \
         decay, whose damping is positive"
    )]
    NotDecaying {
        /// Logarithmic decrement per cycle fitted to the peaks.
        decrement: f64,
    },
    /// Finite inputs produced a non-finite intermediate result because the
    /// signal magnitude is extreme (around 1e150 and above).
    #[error("{what} overflowed f64; expected signal magnitudes well below 1e150")]
    NumericOverflow {
        /// Which result overflowed.
        what: &'static str,
    },
    /// The FFT library refused a transform (an internal inconsistency; the
    /// message is the library's).
    #[error("FFT failed: {message}; expected buffers of the planned length")]
    Fft {
        /// Message of the FFT library.
        message: String,
    },
}

/// Checks that `signal` has at least `min_len` samples and that every sample
/// is finite.
pub(crate) fn check_signal(signal: &[f64], min_len: usize, what: &'static str) -> Result<(), AnalysisError> {
    if signal.is_empty() {
        return Err(AnalysisError::EmptySignal);
    }
    if signal.len() < min_len {
        return Err(AnalysisError::TooShort { len: signal.len(), min: min_len, what });
    }
    if let Some((index, &value)) = signal.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(AnalysisError::NonFinite { index, value });
    }
    Ok(())
}

/// Checks that a sample rate (Hz) is finite and strictly positive.
pub(crate) fn check_sample_rate(sample_rate_hz: f64) -> Result<(), AnalysisError> {
    if sample_rate_hz.is_finite() && sample_rate_hz > 0.0 {
        Ok(())
    } else {
        Err(AnalysisError::InvalidParameter {
            name: "sample_rate_hz",
            value: sample_rate_hz,
            expected: "a finite sample rate > 0 Hz",
        })
    }
}

/// Periodic ("DFT-even") Hann window of length `n`:
/// `w[k] = 0.5 - 0.5 cos(2 pi k / n)`. Dimensionless.
pub(crate) fn hann_periodic(n: usize) -> Vec<f64> {
    let nf = n as f64;
    (0..n).map(|k| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * k as f64 / nf).cos()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_signal_reports_first_non_finite_index() {
        let s = [0.0, 1.0, f64::INFINITY, f64::NAN];
        match check_signal(&s, 1, "test") {
            Err(AnalysisError::NonFinite { index, value }) => {
                assert_eq!(index, 2);
                assert_eq!(value, f64::INFINITY);
            }
            other => panic!("unexpected result {other:?}"),
        }
        assert_eq!(check_signal(&[], 1, "test"), Err(AnalysisError::EmptySignal));
        assert_eq!(check_signal(&[1.0, 2.0], 3, "test"), Err(AnalysisError::TooShort { len: 2, min: 3, what: "test" }));
    }

    #[test]
    fn a_count_of_cycles_is_not_reported_as_a_count_of_samples() {
        let cycles = AnalysisError::TooShort { len: 0, min: 3, what: "decaying cycles of the first mode" };
        assert_eq!(cycles.to_string(), "the signal holds 0 decaying cycles of the first mode; expected at least 3");
        let samples = AnalysisError::TooShort { len: 1, min: 2, what: "an amplitude spectrum" };
        assert_eq!(samples.to_string(), "the signal has 1 samples; expected at least 2 for an amplitude spectrum");
    }

    #[test]
    fn hann_window_is_periodic_and_has_coherent_gain_one_half() {
        let w = hann_periodic(64);
        assert_eq!(w[0], 0.0);
        assert!((w[32] - 1.0).abs() < 1e-15);
        // Periodic symmetry: w[k] == w[n - k].
        for k in 1..64 {
            assert!((w[k] - w[64 - k]).abs() < 1e-15);
        }
        let sum: f64 = w.iter().sum();
        assert!((sum / 64.0 - 0.5).abs() < 1e-14);
        let sum_sq: f64 = w.iter().map(|v| v * v).sum();
        assert!((sum_sq / 64.0 - 0.375).abs() < 1e-14);
    }

    #[test]
    fn error_messages_name_the_parameter_and_expectation() {
        let e = check_sample_rate(-1.0).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("sample_rate_hz"), "{msg}");
        assert!(msg.contains("> 0 Hz"), "{msg}");
        assert!(check_sample_rate(f64::NAN).is_err());
        assert!(check_sample_rate(1.0).is_ok());
    }
}
