//! The rig's data acquisition as far as the gap needs it: piezoelectric
//! accelerometers with charge amplifiers do not pass the static part, and
//! their high-pass (first order, corner unknown, the measurement format
//! only says "content below about 0.5 Hz is not to be trusted") shapes the
//! slow part of a travel's acceleration: after the acceleration and
//! deceleration stages it leaves an exponential tail that the model, which
//! records true accelerations, does not have. The corner is identified from
//! the data: the model's acceleration (whose rigid-body part follows the
//! measured motion) through a first-order high-pass of each candidate
//! corner, against the measured acceleration, both low-passed below the
//! chain's elastic modes.

use dsp::highpass_zero_phase;

use crate::error::Result;

/// Candidate corners, Hz: none (0) and a geometric grid from 0.05 to 3 Hz.
pub fn candidate_corners_hz() -> Vec<f64> {
    let mut out = vec![0.0];
    let (lo, hi, n) = (0.05f64, 3.0f64, 36);
    out.extend((0..n).map(|i| lo * (hi / lo).powf(i as f64 / (n - 1) as f64)));
    out
}

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

/// The accelerometer high-pass corner (Hz, 0 for none) that brings the
/// model's acceleration `model` closest (least squares below
/// [`COMPARISON_LOWPASS_HZ`]) to the measured `measured`, both at
/// `sample_rate_hz`.
pub fn identify_highpass_hz(measured: &[f64], model: &[f64], sample_rate_hz: f64) -> Result<f64> {
    let n = measured.len().min(model.len());
    let low = |v: &[f64]| -> Result<Vec<f64>> {
        let high = highpass_zero_phase(v, sample_rate_hz, COMPARISON_LOWPASS_HZ)?;
        Ok(v.iter().zip(&high).map(|(a, h)| a - h).collect())
    };
    let target = low(&measured[..n])?;
    let mut best = (0.0, f64::INFINITY);
    for corner in candidate_corners_hz() {
        let shaped = low(&first_order_highpass(&model[..n], sample_rate_hz, corner))?;
        let error: f64 = target.iter().zip(&shaped).map(|(a, b)| (a - b).powi(2)).sum();
        if error < best.1 {
            best = (corner, error);
        }
    }
    Ok(best.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_corner_of_a_first_order_highpass_is_found_back() {
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
        for corner in [0.0, 0.3, 0.8] {
            let measured = first_order_highpass(&a, fs, corner);
            let found = identify_highpass_hz(&measured, &a, fs).unwrap();
            let step = (3.0f64 / 0.05).powf(1.0 / 35.0);
            let tolerance = if corner == 0.0 { 0.0 } else { corner * (step - 1.0) };
            assert!((found - corner).abs() <= tolerance, "{corner} Hz: found {found} Hz");
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
    }
}
