//! The rig drive's speed controller, identified from its own input and
//! output. A foreign drive's gains are unknown, but the recording holds
//! what its speed loop saw (the speed reference, when recorded, and the
//! drive's own speed estimate) and what it answered (the torque from the
//! measured currents). A controller is a fixed map from the first to the
//! second, so a least-squares fit of
//!
//! `T = T0 + Kp e + Ki integral(e) + Kff d(omega_ref)/dt`, `e = omega_ref - omega_est`
//!
//! over the motion is not biased by the loop around it (the regressors are
//! the controller's own inputs, not the plant's response). Without a
//! recorded reference the fit runs over the constant-speed stage, the
//! reference there being the estimate's mean. The fit's share of the
//! torque's vibration (4-40 Hz) says whether the law holds; below
//! [`MIN_DYNAMIC_FIT`] the drive is not a PI on its estimate and none is
//! assumed.
//!
//! The speed estimate's dynamics behind the encoder are identified beside
//! it: the dead time and first-order lag that bring the encoder's speed
//! closest to the drive's estimate in the same band.

use nalgebra::{DMatrix, DVector};

use crate::error::{bail, DiagnosisError, Result};
use dsp::{central_difference, highpass_zero_phase};

/// Band in which the controller's fit and the estimate's lag are judged,
/// Hz: above the speed reference's content and the lowest ripple orders,
/// below the anti-alias and the speed estimate's quantisation.
pub const FIT_BAND_HZ: (f64, f64) = (4.0, 40.0);
/// Step of the candidate dead times of the rig drive's speed estimate (a
/// counting window, a speed loop slower than the samples), s: a quarter
/// of a millisecond, an eighth of a cycle at [`FIT_BAND_HZ`]'s top.
pub const ESTIMATE_DELAY_STEP_S: f64 = 0.00025;
/// Longest candidate dead time of the speed estimate, s.
pub const ESTIMATE_DELAY_MAX_S: f64 = 0.008;
/// Shortest nonzero candidate time constant of the speed estimate's
/// filter, s; the candidates rise from it in quarter octaves (19 % each)
/// up to [`ESTIMATE_LAG_MAX_S`], and zero (no filter) is one of them.
pub const ESTIMATE_LAG_MIN_S: f64 = 0.00025;
/// Longest candidate time constant of the speed estimate's filter, s.
pub const ESTIMATE_LAG_MAX_S: f64 = 0.032;
/// Rate (Hz, at least) at which the estimate's dynamics are searched: the
/// signals compared are band-limited to [`FIT_BAND_HZ`], so every
/// `fs / SEARCH_RATE_HZ`-th sample carries them, and a dead time between
/// those samples is read by linear interpolation.
pub const SEARCH_RATE_HZ: f64 = 1024.0;
/// Smallest share of the torque's variance in [`FIT_BAND_HZ`] the
/// identified law must explain (1 - residual / torque variance) for the
/// drive to count as a PI on its speed estimate.
pub const MIN_DYNAMIC_FIT: f64 = 0.8;

/// The rig drive's speed loop as the data show it.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct SpeedController {
    /// Proportional gain on the speed error, N m s/rad.
    pub kp_nms_per_rad: f64,
    /// Integral gain on the speed error, N m/rad.
    pub ki_nm_per_rad: f64,
    /// Time constant of the speed estimate's lag behind the shaft, s.
    pub estimate_lag_s: f64,
    /// Dead time of the speed estimate behind the shaft, s.
    pub estimate_delay_s: f64,
    /// Share of the torque's variance in [`FIT_BAND_HZ`] the law explains
    /// (0-1).
    pub dynamic_fit: f64,
}

/// What the identification reads of a travel, at one sample rate.
pub struct ControllerData<'a> {
    /// Machine torque from the measured currents, N m.
    pub torque_nm: &'a [f64],
    /// Measured shaft angle, rad.
    pub shaft_angle_rad: &'a [f64],
    /// The drive's own speed estimate, rad/s.
    pub speed_estimate_radps: &'a [f64],
    /// The speed reference at the shaft, rad/s, when the recording has it.
    pub reference_radps: Option<&'a [f64]>,
    /// Samples in which the rig moves.
    pub motion: std::ops::Range<usize>,
    /// Samples of the constant-speed stage.
    pub constant_speed: std::ops::Range<usize>,
    /// Sample rate, Hz.
    pub sample_rate_hz: f64,
}

/// First-order lag of time constant `tau_s` applied to `x` at `fs` Hz.
pub fn lag(x: &[f64], fs: f64, tau_s: f64) -> Vec<f64> {
    if tau_s <= 0.0 {
        return x.to_vec();
    }
    let a = (-1.0 / (fs * tau_s)).exp();
    let mut y = x.first().copied().unwrap_or(0.0);
    x.iter()
        .map(|v| {
            y = a * y + (1.0 - a) * v;
            y
        })
        .collect()
}

/// First-order lag of time constant `tau_s` (s) applied to `x` at `fs`
/// Hz, exact for an input linear between its samples: unlike [`lag`]
/// (the input held over a sample), its delay does not depend on the
/// rate, so a lag found at one rate is the lag at another.
fn lag_of_linear_input(x: &[f64], fs: f64, tau_s: f64) -> Vec<f64> {
    if tau_s <= 0.0 {
        return x.to_vec();
    }
    let a = (-1.0 / (fs * tau_s)).exp();
    // The response to a unit ramp over one sample, beyond the step's.
    let ramp = 1.0 - fs * tau_s * (1.0 - a);
    let mut y = x.first().copied().unwrap_or(0.0);
    let mut previous = y;
    x.iter()
        .map(|&v| {
            y = a * y + (1.0 - a) * previous + ramp * (v - previous);
            previous = v;
            y
        })
        .collect()
}

/// `x` band-passed to [`FIT_BAND_HZ`] (zero phase).
fn fit_band(x: &[f64], fs: f64) -> Result<Vec<f64>> {
    let above = highpass_zero_phase(x, fs, FIT_BAND_HZ.0)?;
    let top = highpass_zero_phase(&above, fs, FIT_BAND_HZ.1.min(0.4 * fs))?;
    Ok(above.iter().zip(&top).map(|(a, t)| a - t).collect())
}

/// `x` delayed by `samples` (the first value held before).
pub fn delay(x: &[f64], samples: usize) -> Vec<f64> {
    let first = x.first().copied().unwrap_or(0.0);
    (0..x.len()).map(|k| if k >= samples { x[k - samples] } else { first }).collect()
}

/// The dead time and lag that bring the encoder's speed over `range`
/// closest to the drive's estimate in [`FIT_BAND_HZ`], s: every dead time
/// in steps of [`ESTIMATE_DELAY_STEP_S`] up to [`ESTIMATE_DELAY_MAX_S`]
/// with every time constant of [`estimate_lag_candidates_s`]. Both
/// signals are band-passed first (the band-pass, the delay and the lag
/// commute) and compared at [`SEARCH_RATE_HZ`].
fn estimate_dynamics_s(data: &ControllerData, range: std::ops::Range<usize>) -> Result<(f64, f64)> {
    let fs = data.sample_rate_hz;
    let stride = ((fs / SEARCH_RATE_HZ).floor() as usize).max(1);
    let every = |x: Vec<f64>| -> Vec<f64> { x.into_iter().step_by(stride).collect() };
    let encoder = every(fit_band(&central_difference(&data.shaft_angle_rad[range.clone()], fs), fs)?);
    let estimate = every(fit_band(&data.speed_estimate_radps[range], fs)?);
    let rate = fs / stride as f64;
    let lags = estimate_lag_candidates_s();
    let steps = (ESTIMATE_DELAY_MAX_S / ESTIMATE_DELAY_STEP_S).round() as usize;
    let mut best = ((0.0, 0.0), f64::INFINITY);
    for step in 0..=steps {
        let dead = step as f64 * ESTIMATE_DELAY_STEP_S;
        let delayed = fractional_delay(&encoder, dead * rate);
        for &tau in &lags {
            let lagged = lag_of_linear_input(&delayed, rate, tau);
            let error: f64 = lagged.iter().zip(&estimate).map(|(a, b)| (a - b).powi(2)).sum();
            if error < best.1 {
                best = ((dead, tau), error);
            }
        }
    }
    Ok(best.0)
}

/// The candidate time constants of the speed estimate's filter, s: zero,
/// then [`ESTIMATE_LAG_MIN_S`] rising in quarter octaves up to
/// [`ESTIMATE_LAG_MAX_S`].
pub fn estimate_lag_candidates_s() -> Vec<f64> {
    let steps = (4.0 * (ESTIMATE_LAG_MAX_S / ESTIMATE_LAG_MIN_S).log2()).round() as i32;
    std::iter::once(0.0).chain((0..=steps).map(|k| ESTIMATE_LAG_MIN_S * 2f64.powf(f64::from(k) / 4.0))).collect()
}

/// `x` delayed by `samples` (>= 0, fractional: linear interpolation
/// between neighbours; the first value held before).
fn fractional_delay(x: &[f64], samples: f64) -> Vec<f64> {
    let (whole, part) = (samples.floor() as usize, samples - samples.floor());
    let first = x.first().copied().unwrap_or(0.0);
    let at = |k: usize| if k >= whole { x[k - whole] } else { first };
    let before = |k: usize| if k > whole { x[k - whole - 1] } else { first };
    (0..x.len()).map(|k| (1.0 - part) * at(k) + part * before(k)).collect()
}

/// The fit's regressors over `range`: a constant, the speed error, its
/// integral and, with a recorded reference, the reference's rate.
fn regressors(data: &ControllerData, range: std::ops::Range<usize>) -> Vec<Vec<f64>> {
    let fs = data.sample_rate_hz;
    let estimate = &data.speed_estimate_radps[range.clone()];
    let reference: Vec<f64> = match data.reference_radps {
        Some(r) => r[range.clone()].to_vec(),
        None => vec![estimate.iter().sum::<f64>() / estimate.len() as f64; estimate.len()],
    };
    let error: Vec<f64> = reference.iter().zip(estimate).map(|(r, w)| r - w).collect();
    let mut integral = Vec::with_capacity(error.len());
    let mut sum = 0.0;
    for e in &error {
        sum += e / fs;
        integral.push(sum);
    }
    let mut columns = vec![vec![1.0; error.len()], error, integral];
    if data.reference_radps.is_some() {
        columns.push(central_difference(&reference, fs));
    }
    columns
}

/// Identifies the rig drive's [`SpeedController`] (see the module docs).
/// Refused, with the reason, when the data are too short or the law does
/// not hold.
pub fn identify_speed_controller(data: &ControllerData) -> Result<SpeedController> {
    let fs = data.sample_rate_hz;
    let range = if data.reference_radps.is_some() { data.motion.clone() } else { data.constant_speed.clone() };
    let n_all = data.torque_nm.len().min(data.speed_estimate_radps.len()).min(data.shaft_angle_rad.len());
    if range.end > n_all || data.reference_radps.is_some_and(|r| r.len() < range.end) {
        bail!("the speed controller's fit range ends past the recording");
    }
    if range.len() < (2.0 * fs) as usize {
        bail!(
            "{:.2} s of {}; the speed controller's fit needs at least 2 s",
            range.len() as f64 / fs,
            if data.reference_radps.is_some() { "motion" } else { "constant speed (no reference recorded)" }
        );
    }
    let columns = regressors(data, range.clone());
    let torque = &data.torque_nm[range.clone()];
    let x = DMatrix::from_fn(torque.len(), columns.len(), |i, j| columns[j][i]);
    let scale: Vec<f64> = columns.iter().map(|c| c.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-300)).collect();
    let xs = DMatrix::from_fn(x.nrows(), x.ncols(), |i, j| x[(i, j)] / scale[j]);
    let coefficients = xs
        .clone()
        .svd(true, true)
        .solve(&DVector::from_column_slice(torque), 1e-12)
        .map_err(|e| DiagnosisError::Message(format!("the speed controller's least squares failed: {e}")))?;
    let coefficient = |j: usize| coefficients[j] / scale[j];
    let predicted: Vec<f64> = (xs * &coefficients).iter().copied().collect();
    let (torque_band, predicted_band) = (fit_band(torque, fs)?, fit_band(&predicted, fs)?);
    let power: f64 = torque_band.iter().map(|t| t * t).sum();
    let residual: f64 = torque_band.iter().zip(&predicted_band).map(|(t, p)| (t - p).powi(2)).sum();
    let dynamic_fit = if power > 0.0 { 1.0 - residual / power } else { 0.0 };
    let (estimate_delay_s, estimate_lag_s) = estimate_dynamics_s(data, range)?;
    let controller = SpeedController {
        kp_nms_per_rad: coefficient(1),
        ki_nm_per_rad: coefficient(2),
        estimate_lag_s,
        estimate_delay_s,
        dynamic_fit,
    };
    if dynamic_fit.is_nan()
        || dynamic_fit < MIN_DYNAMIC_FIT
        || controller.kp_nms_per_rad <= 0.0
        || controller.ki_nm_per_rad < 0.0
    {
        bail!(
            "the torque is not a PI of the speed error: Kp {:.3} N m s/rad, Ki {:.3} N m/rad explain {:.0} % of \
             its vibration ({}-{} Hz; at least {:.0} % and positive gains expected)",
            controller.kp_nms_per_rad,
            controller.ki_nm_per_rad,
            100.0 * dynamic_fit,
            FIT_BAND_HZ.0,
            FIT_BAND_HZ.1,
            100.0 * MIN_DYNAMIC_FIT
        );
    }
    Ok(controller)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    /// A PI drive (Kp 15 N m s/rad, Ki 90 N m/rad, inertia feed-forward)
    /// on an estimate 2 ms late and lagging a wobbling shaft by 4 ms.
    fn pi_drive(fs: f64, n: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>) {
        let reference: Vec<f64> = (0..n).map(|k| 6.0 * (k as f64 / fs / 2.0).min(1.0)).collect();
        let speed: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 / fs;
                reference[k] + [7.0, 13.0, 23.0, 31.0].iter().map(|f| 0.05 * (TAU * f * t + f).sin()).sum::<f64>()
            })
            .collect();
        let mut angle = vec![0.0; n];
        for k in 1..n {
            angle[k] = angle[k - 1] + 0.5 * (speed[k] + speed[k - 1]) / fs;
        }
        let estimate = lag(&delay(&speed, (0.002 * fs) as usize), fs, 0.004);
        let rate = central_difference(&reference, fs);
        let mut integral = 0.0;
        let torque: Vec<f64> = (0..n)
            .map(|k| {
                let e = reference[k] - estimate[k];
                integral += e / fs;
                25.0 + 15.0 * e + 90.0 * integral + 0.7 * rate[k]
            })
            .collect();
        (torque, angle, estimate, reference)
    }

    #[test]
    fn a_pi_speed_loop_behind_a_lagged_estimate_is_identified() {
        let fs = 4096.0;
        let n = 8 * 4096;
        let (torque, angle, estimate, reference) = pi_drive(fs, n);
        let data = ControllerData {
            torque_nm: &torque,
            shaft_angle_rad: &angle,
            speed_estimate_radps: &estimate,
            reference_radps: Some(&reference),
            motion: 0..n,
            constant_speed: 2 * 4096..n,
            sample_rate_hz: fs,
        };
        let found = identify_speed_controller(&data).unwrap();
        assert!((found.kp_nms_per_rad - 15.0).abs() < 0.05, "{found:?}");
        assert!((found.ki_nm_per_rad - 90.0).abs() < 0.5, "{found:?}");
        // 8 samples (1.95 ms; the drive's filter, holding its input over
        // a sample, is 0.12 ms faster than a lag of a continuous input)
        // and 4 ms: within a step of the candidates.
        assert!((found.estimate_delay_s - 0.00183).abs() <= ESTIMATE_DELAY_STEP_S, "{found:?}");
        assert!((found.estimate_lag_s / 0.004 - 1.0).abs() < 0.19, "{found:?}");
        assert!(found.dynamic_fit > 0.999, "{found:?}");
        // Without the reference: the constant-speed stage alone.
        let found = identify_speed_controller(&ControllerData { reference_radps: None, ..data }).unwrap();
        assert!((found.kp_nms_per_rad - 15.0).abs() < 0.3, "{found:?}");
    }

    /// The lag of a linearly interpolated input answers a sine as the
    /// continuous lag does, `1 / (1 + j w tau)`, at any rate.
    #[test]
    fn the_lag_of_a_linear_input_is_the_continuous_lag_at_any_rate() {
        let (f, tau) = (20.0, 0.005);
        for fs in [1024.0, 4096.0, 16384.0] {
            let n = (2.0 * fs) as usize;
            let x: Vec<f64> = (0..n).map(|k| (TAU * f * k as f64 / fs).sin()).collect();
            let y = lag_of_linear_input(&x, fs, tau);
            // The steady state's sine and cosine parts over the last second.
            let (mut s, mut c) = (0.0, 0.0);
            for k in n / 2..n {
                let phase = TAU * f * k as f64 / fs;
                s += y[k] * phase.sin();
                c += y[k] * phase.cos();
            }
            let (s, c) = (2.0 * s / (n / 2) as f64, 2.0 * c / (n / 2) as f64);
            let w = TAU * f * tau;
            let (gain, phase) = (1.0 / (1.0 + w * w).sqrt(), -w.atan());
            assert!(((s * s + c * c).sqrt() - gain).abs() < 2e-3 * gain, "{fs} Hz: {s} {c}");
            assert!((c.atan2(s) - phase).abs() < 2e-3, "{fs} Hz: {} against {phase}", c.atan2(s));
        }
    }

    #[test]
    fn a_torque_that_ignores_the_speed_is_refused() {
        let fs = 4096.0;
        let n = 8 * 4096;
        let (_, angle, estimate, reference) = pi_drive(fs, n);
        let torque: Vec<f64> = (0..n).map(|k| 30.0 + (TAU * 11.0 * k as f64 / fs).sin()).collect();
        let data = ControllerData {
            torque_nm: &torque,
            shaft_angle_rad: &angle,
            speed_estimate_radps: &estimate,
            reference_radps: Some(&reference),
            motion: 0..n,
            constant_speed: 2 * 4096..n,
            sample_rate_hz: fs,
        };
        let error = identify_speed_controller(&data).unwrap_err().to_string();
        assert!(error.contains("not a PI"), "{error}");
    }
}
