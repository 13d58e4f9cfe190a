//! The rig's data acquisition as far as the gap needs it: piezoelectric
//! accelerometers with charge amplifiers do not pass the static part, and
//! their high-pass (order and corner unknown: a sensor and its amplifier
//! give one pole, an acquisition's own AC coupling or a filter another; the
//! measurement format only says "content below about 0.5 Hz is not to be
//! trusted") shapes the slow part of a travel's acceleration: after the
//! acceleration and deceleration stages it leaves a tail that the model,
//! which records true accelerations, does not have. Order and corner are
//! identified from the data: the model's acceleration (whose rigid-body
//! part follows the measured motion) through each candidate high-pass
//! ([`candidates`]: none, first order, second-order Butterworth), against
//! the measured acceleration, both low-passed below the chain's elastic
//! modes.

use dsp::{highpass_causal, lowpass_complement_zero_phase};

use crate::error::Result;

/// Candidate corners, Hz: a geometric grid from 0.05 to 3 Hz.
pub fn candidate_corners_hz() -> Vec<f64> {
    let (lo, hi, n) = (0.05f64, 3.0f64, 36);
    (0..n).map(|i| lo * (hi / lo).powf(i as f64 / (n - 1) as f64)).collect()
}

/// The accelerometers' high-pass as the diagnosis models it.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Highpass {
    /// 0: none; 1: first order (RC); 2: second-order Butterworth.
    pub order: u32,
    /// Corner (-3 dB), Hz; 0 with order 0.
    pub corner_hz: f64,
}

impl Highpass {
    /// No high-pass: the slow acceleration passes.
    pub const NONE: Self = Self { order: 0, corner_hz: 0.0 };

    /// `signal` sampled at `sample_rate_hz` through the filter, causally
    /// (bilinear transform, corner pre-warped), from a state at rest on the
    /// first sample's level, as an analogue AC coupling that has settled.
    pub fn apply(&self, signal: &[f64], sample_rate_hz: f64) -> Result<Vec<f64>> {
        Ok(match self.order {
            _ if signal.is_empty() => Vec::new(),
            0 => signal.to_vec(),
            1 => first_order_highpass(signal, sample_rate_hz, self.corner_hz),
            _ => highpass_causal(signal, sample_rate_hz, self.corner_hz)?,
        })
    }

    /// In words, for the report.
    pub fn text(&self) -> String {
        match self.order {
            0 => "none (the slow acceleration passes)".to_string(),
            1 => format!("first order, corner {:.3} Hz", self.corner_hz),
            o => format!("order {o} (Butterworth), corner {:.3} Hz", self.corner_hz),
        }
    }
}

/// The candidate high-passes: none, and first and second order at each of
/// [`candidate_corners_hz`].
pub fn candidates() -> Vec<Highpass> {
    let corners = candidate_corners_hz();
    std::iter::once(Highpass::NONE)
        .chain([1, 2].into_iter().flat_map(|order| corners.iter().map(move |&corner_hz| Highpass { order, corner_hz })))
        .collect()
}

/// Fraction of the sample rate from which a rig's data acquisition's
/// anti-alias filter may already act (the measurement format does not
/// promise a flat response up to Nyquist): the compared bands
/// ([`crate::compare::FOREIGN_TOP_FRACTION`]) and an accelerometer's noise
/// floor ([`crate::signals::noise_band_hz`]) stay below it.
pub const ANTI_ALIAS_START_FRACTION: f64 = 0.2;

/// The comparison is made below this frequency, Hz (the rigid-body motion;
/// the elastic modes of the reference chain start near 8 Hz).
pub const COMPARISON_LOWPASS_HZ: f64 = 3.0;

/// A first-order (RC) high-pass of corner `corner_hz` (none for 0) applied
/// causally to `signal` sampled at `sample_rate_hz`, as an analogue charge
/// amplifier does (bilinear transform).
pub fn first_order_highpass(signal: &[f64], sample_rate_hz: f64, corner_hz: f64) -> Vec<f64> {
    if corner_hz <= 0.0 {
        return signal.to_vec();
    }
    let k = (std::f64::consts::PI * corner_hz / sample_rate_hz).tan();
    let (b, a1) = (1.0 / (1.0 + k), (1.0 - k) / (1.0 + k));
    let mut out = Vec::with_capacity(signal.len());
    let (mut x_prev, mut y_prev) = (signal.first().copied().unwrap_or(0.0), 0.0);
    for &x in signal {
        let y = b * (x - x_prev) + a1 * y_prev;
        out.push(y);
        x_prev = x;
        y_prev = y;
    }
    out
}

/// The accelerometer high-pass ([`candidates`]) that brings the model's
/// acceleration `model` closest (least squares below
/// [`COMPARISON_LOWPASS_HZ`]) to the measured `measured`, both at
/// `sample_rate_hz`.
pub fn identify_highpass(measured: &[f64], model: &[f64], sample_rate_hz: f64) -> Result<Highpass> {
    let n = measured.len().min(model.len());
    let low = |v: &[f64]| -> Result<Vec<f64>> {
        Ok(lowpass_complement_zero_phase(v, sample_rate_hz, COMPARISON_LOWPASS_HZ)?)
    };
    let target = low(&measured[..n])?;
    // The zero-phase low-pass and the candidate commute (both linear and
    // time-invariant, up to the ends): the model is low-passed once.
    let model_low = low(&model[..n])?;
    let mut best = (Highpass::NONE, f64::INFINITY);
    for candidate in candidates() {
        let shaped = candidate.apply(&model_low, sample_rate_hz)?;
        let error: f64 = target.iter().zip(&shaped).map(|(a, b)| (a - b).powi(2)).sum();
        if error < best.1 {
            best = (candidate, error);
        }
    }
    Ok(best.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_order_and_corner_of_a_highpass_are_found_back() {
        // A travel-like acceleration: +0.5 m/s^2 for 1.5 s, cruise 3 s,
        // -0.5 m/s^2 for 1.5 s, at 512 Hz.
        let fs = 512.0;
        let a: Vec<f64> = (0..(8.0 * fs) as usize)
            .map(|k| {
                let t = k as f64 / fs;
                if (0.5..2.0).contains(&t) {
                    0.5
                } else if (5.0..6.5).contains(&t) {
                    -0.5
                } else {
                    0.0
                }
            })
            .collect();
        let step = (3.0f64 / 0.05).powf(1.0 / 35.0);
        for truth in [
            Highpass::NONE,
            Highpass { order: 1, corner_hz: 0.3 },
            Highpass { order: 1, corner_hz: 0.8 },
            Highpass { order: 2, corner_hz: 0.5 },
            Highpass { order: 2, corner_hz: 1.0 },
        ] {
            let measured = truth.apply(&a, fs).unwrap();
            let found = identify_highpass(&measured, &a, fs).unwrap();
            let tolerance = truth.corner_hz * (step - 1.0);
            assert!(
                found.order == truth.order && (found.corner_hz - truth.corner_hz).abs() <= tolerance,
                "{truth:?}: found {found:?}"
            );
        }
    }

    #[test]
    fn the_filter_has_its_corner_where_it_should() {
        // Gain of a 1 Hz sine through a 1 Hz corner: 1/sqrt(2).
        let fs = 1000.0;
        let x: Vec<f64> = (0..20_000).map(|k| (std::f64::consts::TAU * k as f64 / fs).sin()).collect();
        let y = first_order_highpass(&x, fs, 1.0);
        let rms = |v: &[f64]| (v.iter().map(|a| a * a).sum::<f64>() / v.len() as f64).sqrt();
        let gain = rms(&y[10_000..]) / rms(&x[10_000..]);
        assert!((gain - 0.5f64.sqrt()).abs() < 2e-3, "{gain}");
        let second = Highpass { order: 2, corner_hz: 1.0 };
        let y = second.apply(&x, fs).unwrap();
        let gain = rms(&y[10_000..]) / rms(&x[10_000..]);
        assert!((gain - 0.5f64.sqrt()).abs() < 2e-3, "second order: {gain}");
        // A decade below the corner a second order passes 1/100, a first 1/10.
        let slow: Vec<f64> = (0..400_000).map(|k| (std::f64::consts::TAU * 0.1 * k as f64 / fs).sin()).collect();
        let y = second.apply(&slow, fs).unwrap();
        let gain = rms(&y[200_000..]) / rms(&slow[200_000..]);
        assert!((gain - 0.01).abs() < 2e-4, "second order at a tenth of its corner: {gain}");
    }
}
