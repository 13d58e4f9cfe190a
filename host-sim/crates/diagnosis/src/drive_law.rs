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
/// Candidate time constants of the rig drive's speed-estimate filter, s.
pub const ESTIMATE_LAGS_S: [f64; 8] = [0.0, 0.0005, 0.001, 0.002, 0.004, 0.008, 0.016, 0.032];
/// Candidate dead times of the rig drive's speed estimate (a counting
/// window, a speed loop slower than the samples), s.
pub const ESTIMATE_DELAYS_S: [f64; 8] = [0.0, 0.0005, 0.001, 0.002, 0.003, 0.004, 0.006, 0.008];
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

/// The dead time and lag (of [`ESTIMATE_DELAYS_S`] and
/// [`ESTIMATE_LAGS_S`]) that bring the encoder's speed over `range`
/// closest to the drive's estimate in [`FIT_BAND_HZ`], s.
fn estimate_dynamics_s(data: &ControllerData, range: std::ops::Range<usize>) -> Result<(f64, f64)> {
    let fs = data.sample_rate_hz;
    let encoder = central_difference(&data.shaft_angle_rad[range.clone()], fs);
    let estimate = fit_band(&data.speed_estimate_radps[range], fs)?;
    let mut best = ((0.0, 0.0), f64::INFINITY);
    for dead in ESTIMATE_DELAYS_S {
        let delayed = delay(&encoder, (dead * fs).round() as usize);
        for tau in ESTIMATE_LAGS_S {
            let lagged = fit_band(&lag(&delayed, fs, tau), fs)?;
            let error: f64 = lagged.iter().zip(&estimate).map(|(a, b)| (a - b).powi(2)).sum();
            if error < best.1 {
                best = ((dead, tau), error);
            }
        }
    }
    Ok(best.0)
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
        assert_eq!((found.estimate_delay_s, found.estimate_lag_s), (0.002, 0.004), "{found:?}");
        assert!(found.dynamic_fit > 0.999, "{found:?}");
        // Without the reference: the constant-speed stage alone.
        let found = identify_speed_controller(&ControllerData { reference_radps: None, ..data }).unwrap();
        assert!((found.kp_nms_per_rad - 15.0).abs() < 0.3, "{found:?}");
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
