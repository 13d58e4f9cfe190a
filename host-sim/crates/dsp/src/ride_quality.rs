//! Lift ride quality of the vertical axis, after ISO 18738-1.
//!
//! [`ride_quality`] takes the vertical acceleration of the car (m/s^2,
//! positive up, zero at rest: the kinematic acceleration, without the 1 g a
//! gravity-sensing accelerometer adds) and reports, for the whole run and
//! for the constant-speed region the caller names, the vibration and motion
//! measures below. Accelerations are reported in mg
//! (1 mg = [`MPS2_PER_MG`] = 9.80665e-3 m/s^2), jerk in m/s^3.
//!
//! # Definitions used
//!
//! * **Vibration**: the acceleration weighted with ISO 2631-1 Wk
//!   ([`super::iso2631::wk_weighting`], weighting of the whole record, so a
//!   region is evaluated with the filter's full history). The band-limiting
//!   high-pass of Wk (0.4 Hz, 2nd order) removes the low-frequency motion
//!   of the run, but not all of it: over the whole run the weighted motion
//!   profile itself (the starts and ends of the acceleration and
//!   deceleration stages) still contributes, and its tail, decaying with
//!   the high-pass poles (time constant about 0.56 s), can still offset the
//!   vibration early in the constant-speed region and so suppress zero
//!   crossings there.
//! * **Half-cycles and peaks**: a zero crossing is a change of sign of the
//!   vibration (samples exactly 0 belong to no half-cycle, so touching zero
//!   without changing sign is no crossing). A half-cycle is the stretch
//!   between two consecutive crossings; its peak is its sample of largest
//!   magnitude, with its sign. The first and last stretches of the
//!   evaluated range are cut by the range boundaries and are discarded.
//! * **Peak-to-peak values**: for every pair of consecutive half-cycles
//!   (overlapping pairs: 1-2, 2-3, 3-4, ...), the difference between the
//!   maximum of the positive one and the minimum of the adjacent negative
//!   one, i.e. the sum of the magnitudes of the two peaks. `n` complete
//!   half-cycles give `n - 1` values. Overlapping pairs make the result
//!   independent of which half-cycle happens to come first.
//! * **Maximum peak-to-peak** (`max_peak_to_peak_mg`): the largest of them.
//! * **A95 peak-to-peak** (`a95_peak_to_peak_mg`): the value that 95 % of
//!   the peak-to-peak values do not exceed, taken as the nearest rank
//!   without interpolation: with the `N` values sorted ascending, the
//!   `ceil(0.95 N)`-th one. That is the smallest observed value that at
//!   least 95 % of the values are less than or equal to. Example: the
//!   values 2, 3, ..., 200 mg (N = 199) give rank 190 and A95 = 191 mg.
//!   With no peak-to-peak value (fewer than two complete half-cycles, e.g.
//!   a vibration-free signal) both are 0 and `peak_to_peak_count` is 0.
//! * **Acceleration**: the acceleration low-passed at
//!   [`ACCELERATION_LOWPASS_HZ`] (10 Hz) by a causal 2nd-order Butterworth
//!   filter (bilinear, pre-warped; unit gain at 0 Hz, -3 dB at 10 Hz),
//!   started in the steady state of the first sample. The travel direction
//!   is the sign of the largest-magnitude velocity obtained by integrating
//!   it over the whole run. Maximum acceleration is the largest low-passed
//!   value in the direction of travel, maximum deceleration the largest
//!   against it, both as magnitudes (0 if there is none).
//! * **Jerk**: the slope of a least-squares straight line fitted to the
//!   low-passed acceleration over a sliding window of [`JERK_FIT_WINDOW_S`]
//!   (0.5 s: `round(0.5 fs) + 1` samples, so its first and last samples
//!   are 0.5 s apart), moved one sample at a time; the maximum jerk is the
//!   largest magnitude over all windows that lie entirely inside the
//!   evaluated range.
//!
//! # Sources
//!
//! The Wk weighting is checked against ISO 2631-1 (see
//! [`super::iso2631`]). The ISO 18738-1:2012 text itself was not available;
//! the measures above (Wk-weighted vibration, peak-to-peak between zero
//! crossings, maximum and A95 peak-to-peak, maximum acceleration and
//! deceleration from the 10 Hz low-passed acceleration, jerk from a 0.5 s
//! fit, whole run and constant-speed region) follow the project issue's
//! summary of it. The order of the 10 Hz low-pass (2) and the overlapping
//! pairing and nearest-rank rule are this module's choices, stated above.

use std::ops::Range;

use super::biquad::Biquad;
use super::iso2631::{check_wk_sample_rate, wk_weighting};
use super::{check_signal, AnalysisError};

/// Acceleration of 1 mg in m/s^2 (a thousandth of the standard gravity
/// 9.80665 m/s^2).
pub const MPS2_PER_MG: f64 = 9.80665e-3;

/// Cutoff (-3 dB) of the low-pass applied before the maximum acceleration,
/// deceleration and jerk are taken, Hz.
pub const ACCELERATION_LOWPASS_HZ: f64 = 10.0;

/// Span of the least-squares line fit that estimates the jerk, s.
pub const JERK_FIT_WINDOW_S: f64 = 0.5;

/// Direction in which the car travels during the run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TravelDirection {
    /// Up (the integrated acceleration, i.e. velocity, is largest positive).
    Up,
    /// Down (the velocity is largest negative).
    Down,
}

/// Ride-quality measures of one range of samples (see the module
/// documentation for the definitions).
#[derive(Debug, Clone, PartialEq)]
pub struct RideQuality {
    /// Evaluated samples (indices into the input signal).
    pub region: Range<usize>,
    /// Largest peak-to-peak value of the Wk-weighted vibration, mg.
    pub max_peak_to_peak_mg: f64,
    /// Value that 95 % of the peak-to-peak values of the Wk-weighted
    /// vibration do not exceed (nearest rank), mg.
    pub a95_peak_to_peak_mg: f64,
    /// Number of peak-to-peak values found in the region (dimensionless).
    pub peak_to_peak_count: usize,
    /// Largest 10 Hz low-passed acceleration in the direction of travel, mg
    /// (magnitude, >= 0).
    pub max_acceleration_mg: f64,
    /// Largest 10 Hz low-passed acceleration against the direction of
    /// travel, mg (magnitude, >= 0).
    pub max_deceleration_mg: f64,
    /// Largest magnitude of the jerk (0.5 s least-squares slope of the
    /// 10 Hz low-passed acceleration), m/s^3.
    pub max_jerk_mps3: f64,
}

/// Result of [`ride_quality`].
#[derive(Debug, Clone, PartialEq)]
pub struct RideQualityReport {
    /// Sample rate of the analysed signal, Hz.
    pub sample_rate_hz: f64,
    /// Travel direction inferred from the integrated acceleration.
    pub direction: TravelDirection,
    /// Length of the jerk fit window, samples (`round(0.5 fs) + 1`).
    pub jerk_window_samples: usize,
    /// Measures over the whole signal.
    pub whole_run: RideQuality,
    /// Measures over the constant-speed region, if one was given.
    pub constant_speed: Option<RideQuality>,
}

/// Ride quality of a vertical car acceleration record after ISO 18738-1.
///
/// * `acceleration_mps2`: vertical acceleration of the car, m/s^2, positive
///   up, zero at rest (no gravity offset: a constant offset would bias the
///   acceleration, deceleration and direction, though not the vibration).
///   At least one jerk window (0.5 s) long; non-finite samples are
///   rejected.
/// * `sample_rate_hz`: sample rate in Hz, finite and at least
///   [`super::iso2631::WK_MIN_SAMPLE_RATE_HZ`] (50 Hz).
/// * `constant_speed`: sample range of the constant-speed stage, if any;
///   it must lie inside the signal (`start < end <= len`) and span at least
///   one jerk window.
///
/// The definitions (vibration, peak-to-peak pairing, A95 rank, 10 Hz
/// low-pass, jerk fit) are in the module documentation.
///
/// # Errors
/// [`AnalysisError::EmptySignal`], [`AnalysisError::NonFinite`] or
/// [`AnalysisError::TooShort`] for a bad signal;
/// [`AnalysisError::InvalidParameter`] for a bad sample rate or
/// `constant_speed` range; [`AnalysisError::NumericOverflow`] if the signal
/// is so large (around 1e300) that a result overflows.
pub fn ride_quality(
    acceleration_mps2: &[f64],
    sample_rate_hz: f64,
    constant_speed: Option<Range<usize>>,
) -> Result<RideQualityReport, AnalysisError> {
    check_wk_sample_rate(sample_rate_hz)?;
    let window = jerk_window_len(sample_rate_hz);
    check_signal(acceleration_mps2, window, "ride quality (one 0.5 s jerk fit window)")?;
    let n = acceleration_mps2.len();
    if let Some(r) = &constant_speed {
        let bad = |value: usize| AnalysisError::InvalidParameter {
            name: "constant_speed",
            value: value as f64,
            expected: "a sample range with start < end <= signal length, at least one 0.5 s jerk window long",
        };
        if r.end > n {
            return Err(bad(r.end));
        }
        if r.start >= r.end {
            return Err(bad(r.start));
        }
        if r.len() < window {
            return Err(bad(r.len()));
        }
    }

    let weighted = wk_weighting(acceleration_mps2, sample_rate_hz)?;
    let lowpassed = lowpass_acceleration(acceleration_mps2, sample_rate_hz);
    if lowpassed.iter().any(|v| !v.is_finite()) {
        return Err(AnalysisError::NumericOverflow { what: "10 Hz low-passed acceleration" });
    }
    let direction = travel_direction(&lowpassed);
    let slopes = sliding_slopes(&lowpassed, window);

    let evaluate = |region: Range<usize>| -> Result<RideQuality, AnalysisError> {
        let (max_pp, a95_pp, count) = vibration_measures(&weighted[region.clone()]);
        let (up, down) =
            lowpassed[region.clone()].iter().fold((0.0_f64, 0.0_f64), |(hi, lo), &v| (hi.max(v), lo.max(-v)));
        let (accel, decel) = match direction {
            TravelDirection::Up => (up, down),
            TravelDirection::Down => (down, up),
        };
        let last_window_start = region.end - window;
        let max_slope = slopes[region.start..=last_window_start].iter().fold(0.0_f64, |m, s| m.max(s.abs()));
        let quality = RideQuality {
            region,
            max_peak_to_peak_mg: max_pp,
            a95_peak_to_peak_mg: a95_pp,
            peak_to_peak_count: count,
            max_acceleration_mg: accel / MPS2_PER_MG,
            max_deceleration_mg: decel / MPS2_PER_MG,
            max_jerk_mps3: max_slope * sample_rate_hz,
        };
        let values = [
            quality.max_peak_to_peak_mg,
            quality.a95_peak_to_peak_mg,
            quality.max_acceleration_mg,
            quality.max_deceleration_mg,
            quality.max_jerk_mps3,
        ];
        if values.iter().all(|v| v.is_finite()) {
            Ok(quality)
        } else {
            Err(AnalysisError::NumericOverflow { what: "ride-quality measures" })
        }
    };

    Ok(RideQualityReport {
        sample_rate_hz,
        direction,
        jerk_window_samples: window,
        whole_run: evaluate(0..n)?,
        constant_speed: constant_speed.map(evaluate).transpose()?,
    })
}

/// Number of samples in the jerk fit window: `round(0.5 s * fs) + 1`, so
/// that its first and last samples are [`JERK_FIT_WINDOW_S`] apart.
pub(crate) fn jerk_window_len(sample_rate_hz: f64) -> usize {
    (JERK_FIT_WINDOW_S * sample_rate_hz).round() as usize + 1
}

/// Acceleration low-passed at [`ACCELERATION_LOWPASS_HZ`] (causal
/// 2nd-order Butterworth, starting in the steady state of the first sample).
/// Requires a non-empty signal and `fs > 20 Hz`.
pub(crate) fn lowpass_acceleration(signal: &[f64], sample_rate_hz: f64) -> Vec<f64> {
    let lp = Biquad::butterworth_lowpass(ACCELERATION_LOWPASS_HZ, sample_rate_hz);
    let mut state = lp.steady_state(signal[0]);
    signal.iter().map(|&x| lp.step(&mut state, x)).collect()
}

/// Travel direction: the sign of the velocity (running sum of the
/// acceleration; the sample interval only scales it) at its largest
/// magnitude. Up when the velocity is zero throughout.
fn travel_direction(acceleration: &[f64]) -> TravelDirection {
    let mut velocity = 0.0;
    let mut extreme: f64 = 0.0;
    for &a in acceleration {
        velocity += a;
        if velocity.abs() > extreme.abs() {
            extreme = velocity;
        }
    }
    if extreme < 0.0 {
        TravelDirection::Down
    } else {
        TravelDirection::Up
    }
}

/// Least-squares slope, in signal units per sample, of every window of `w`
/// consecutive samples: `result[s]` belongs to `x[s..s + w]`, for
/// `s = 0..=x.len() - w`. Requires `2 <= w <= x.len()`.
///
/// slope = `sum_j (j - m) x[s + j] / sum_j (j - m)^2` with `m = (w - 1)/2`
/// and `sum_j (j - m)^2 = w (w^2 - 1) / 12`. The sums `S(s) = sum_j x[s+j]`
/// and `T(s) = sum_j j x[s+j]` are updated as the window moves
/// (`S(s+1) = S(s) - x[s] + x[s+w]`, `T(s+1) = T(s) + w x[s+w] - S(s+1)`)
/// and recomputed directly every `w` steps so that rounding cannot drift.
pub(crate) fn sliding_slopes(x: &[f64], w: usize) -> Vec<f64> {
    let count = x.len() + 1 - w;
    let wf = w as f64;
    let mid = 0.5 * (wf - 1.0);
    let sxx = wf * (wf * wf - 1.0) / 12.0;
    let direct = |s: usize| {
        let window = &x[s..s + w];
        let sum: f64 = window.iter().sum();
        let moment: f64 = window.iter().enumerate().map(|(j, v)| j as f64 * v).sum();
        (sum, moment)
    };
    let mut out = Vec::with_capacity(count);
    let (mut sum, mut moment) = direct(0);
    for s in 0..count {
        if s > 0 {
            if s % w == 0 {
                (sum, moment) = direct(s);
            } else {
                let entering = x[s + w - 1];
                sum += entering - x[s - 1];
                moment += wf * entering - sum;
            }
        }
        out.push((moment - mid * sum) / sxx);
    }
    out
}

/// Signed peaks of the complete half-cycles of `x` (see the module
/// documentation): the stretches between consecutive sign changes, zeros
/// ignored, without the first and last stretch.
fn half_cycle_peaks(x: &[f64]) -> Vec<f64> {
    half_cycle_peaks_indexed(x).into_iter().map(|(_, v)| v).collect()
}

/// [`half_cycle_peaks`] with the index into `x` of each peak.
pub(crate) fn half_cycle_peaks_indexed(x: &[f64]) -> Vec<(usize, f64)> {
    let mut peaks = Vec::new();
    let mut sign = 0.0_f64;
    let mut peak = (0, 0.0_f64);
    let mut at_start = true;
    for (i, &v) in x.iter().enumerate() {
        if v == 0.0 {
            continue;
        }
        let s = v.signum();
        if s == sign {
            if v.abs() > peak.1.abs() {
                peak = (i, v);
            }
        } else {
            // Zero crossing: the running stretch is complete unless it is
            // the one cut by the start of the range.
            if sign != 0.0 {
                if !at_start {
                    peaks.push(peak);
                }
                at_start = false;
            }
            sign = s;
            peak = (i, v);
        }
    }
    peaks
}

/// Nearest-rank 95th percentile of `sorted` (ascending, non-empty): the
/// `ceil(0.95 N)`-th value.
pub(crate) fn a95_nearest_rank(sorted: &[f64]) -> f64 {
    let rank = (95 * sorted.len()).div_ceil(100);
    sorted[rank.max(1) - 1]
}

/// Maximum and A95 peak-to-peak values (mg) and the number of
/// peak-to-peak values of an already weighted vibration signal in m/s^2.
fn vibration_measures(weighted_mps2: &[f64]) -> (f64, f64, usize) {
    let mut values = peak_to_peak_values_mg(weighted_mps2);
    if values.is_empty() {
        return (0.0, 0.0, 0);
    }
    values.sort_by(f64::total_cmp);
    (values[values.len() - 1], a95_nearest_rank(&values), values.len())
}

/// Peak-to-peak values (mg) of consecutive complete half-cycle pairs of a
/// weighted vibration signal in m/s^2.
fn peak_to_peak_values_mg(weighted_mps2: &[f64]) -> Vec<f64> {
    half_cycle_peaks(weighted_mps2).windows(2).map(|p| (p[0] - p[1]).abs() / MPS2_PER_MG).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::iso2631::wk_digital_gain;
    use std::f64::consts::PI;

    #[test]
    fn mg_unit_is_a_thousandth_of_standard_gravity() {
        assert!((9.80665 / MPS2_PER_MG - 1000.0).abs() < 1e-10);
    }

    #[test]
    fn sine_gives_peak_to_peak_of_twice_the_amplitude() {
        // 25 mg at 5 Hz, 1000 Hz sampling: crests fall on samples
        // (k = 50 + 100 m), so every peak is exactly +-25 mg.
        let (fs, f, amp_mg) = (1000.0, 5.0, 25.0);
        let x: Vec<f64> = (0..3000).map(|k| amp_mg * MPS2_PER_MG * (2.0 * PI * f * k as f64 / fs).sin()).collect();
        let values = peak_to_peak_values_mg(&x);
        // 30 half-cycles; the first (k = 1..99) and the last (cut at
        // k = 2999) are discarded: 28 complete ones, 27 pairs.
        assert_eq!(values.len(), 27);
        for v in &values {
            assert!((v - 2.0 * amp_mg).abs() < 1e-9, "{v}");
        }
        let (max, a95, count) = vibration_measures(&x);
        assert_eq!(count, 27);
        assert!((max - 50.0).abs() < 1e-9 && (a95 - 50.0).abs() < 1e-9, "max {max} a95 {a95}");
    }

    /// Half-sine of `amp` (sign included) over 17 samples, crest on the
    /// middle sample, no sample at zero.
    fn half_sine(amp: f64) -> impl Iterator<Item = f64> {
        (0..17).map(move |j| amp * ((j as f64 + 0.5) * PI / 17.0).sin())
    }

    #[test]
    fn cycles_of_1_to_100_mg_give_max_200_and_a95_191() {
        // Cycles c = 1..100 of amplitude c mg (positive then negative
        // half), between a leading negative and a trailing positive 0.5 mg
        // half-cycle that the range boundaries cut off. Peaks: +1, -1, +2,
        // -2, ..., +100, -100; overlapping pairs give 1+1, 1+2, 2+2, ...,
        // 100+100 = 2, 3, ..., 200 mg: N = 199 values.
        let mut x: Vec<f64> = half_sine(-0.5 * MPS2_PER_MG).collect();
        for c in 1..=100 {
            let a = c as f64 * MPS2_PER_MG;
            x.extend(half_sine(a));
            x.extend(half_sine(-a));
        }
        x.extend(half_sine(0.5 * MPS2_PER_MG));
        let mut values = peak_to_peak_values_mg(&x);
        values.sort_by(f64::total_cmp);
        assert_eq!(values.len(), 199);
        for (i, v) in values.iter().enumerate() {
            assert!((v - (i + 2) as f64).abs() < 1e-9, "value {i}: {v}");
        }
        let (max, a95, count) = vibration_measures(&x);
        assert_eq!(count, 199);
        assert!((max - 200.0).abs() < 1e-9, "max {max}");
        // Rank ceil(0.95 * 199) = ceil(189.05) = 190 -> the 190th value, 191 mg.
        assert!((a95 - 191.0).abs() < 1e-9, "a95 {a95}");
        // Independent check of the defining property: at least 95 % of the
        // values are <= A95, fewer than 95 % are <= the next smaller value.
        let at_most = |t: f64| values.iter().filter(|v| **v <= t + 1e-9).count() as f64;
        assert!(at_most(a95) >= 0.95 * 199.0);
        assert!(at_most(a95 - 1.0) < 0.95 * 199.0);
    }

    #[test]
    fn nearest_rank_a95_on_small_sets() {
        let ramp = |n: usize| (1..=n).map(|v| v as f64).collect::<Vec<_>>();
        assert_eq!(a95_nearest_rank(&[7.0]), 7.0);
        assert_eq!(a95_nearest_rank(&ramp(20)), 19.0); // 0.95 * 20 = 19
        assert_eq!(a95_nearest_rank(&ramp(21)), 20.0); // ceil(19.95) = 20
        assert_eq!(a95_nearest_rank(&ramp(100)), 95.0);
        assert_eq!(a95_nearest_rank(&ramp(101)), 96.0); // ceil(95.95) = 96
    }

    #[test]
    fn half_cycles_ignore_zeros_and_drop_cut_ends() {
        // Zeros inside a positive stretch and a touch of zero do not split it.
        let x = [0.5, -1.0, -3.0, 0.0, -2.0, 2.0, 0.0, 4.0, 0.0, 1.0, -1.0, -5.0, 6.0, 7.0];
        // Stretches: [0.5] cut, [-1,-3,-2] -> -3, [2,4,1] -> 4, [-1,-5] -> -5, [6,7] cut.
        assert_eq!(half_cycle_peaks(&x), vec![-3.0, 4.0, -5.0]);
        assert_eq!(peak_to_peak_values_mg(&x).len(), 2);
        assert!(half_cycle_peaks(&[0.0; 10]).is_empty());
        assert!(half_cycle_peaks(&[1.0, -1.0]).is_empty());
        assert_eq!(half_cycle_peaks(&[1.0, -1.0, 1.0]), vec![-1.0]);
        assert_eq!(vibration_measures(&[1.0, -1.0, 1.0]), (0.0, 0.0, 0));
    }

    #[test]
    fn sliding_slopes_match_direct_least_squares() {
        // Deterministic pseudo-random data plus a trend.
        let mut seed: u64 = 12345;
        let x: Vec<f64> = (0..1000)
            .map(|k| {
                seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5 + 0.01 * k as f64
            })
            .collect();
        for w in [2, 3, 37, 100, 1000] {
            let slopes = sliding_slopes(&x, w);
            assert_eq!(slopes.len(), x.len() + 1 - w);
            for (s, slope) in slopes.iter().enumerate() {
                // Direct fit: centred sums.
                let win = &x[s..s + w];
                let tm = (w as f64 - 1.0) / 2.0;
                let mean = win.iter().sum::<f64>() / w as f64;
                let (mut sxy, mut sxx) = (0.0, 0.0);
                for (j, v) in win.iter().enumerate() {
                    sxy += (j as f64 - tm) * (v - mean);
                    sxx += (j as f64 - tm) * (j as f64 - tm);
                }
                assert!((slope - sxy / sxx).abs() < 1e-10, "w {w} s {s}: {slope} vs {}", sxy / sxx);
            }
        }
    }

    /// Smooth (raised-cosine) step from `a0` to `a1` over `t_ramp` s,
    /// starting at `t0` s, evaluated at `t` s.
    fn smooth_step(t: f64, t0: f64, t_ramp: f64, a0: f64, a1: f64) -> f64 {
        let u = ((t - t0) / t_ramp).clamp(0.0, 1.0);
        a0 + (a1 - a0) * 0.5 * (1.0 - (PI * u).cos())
    }

    /// Jerk-limited travel: 1 s rest, 2 s ramp to +acc, 1 s hold, 2 s ramp
    /// to 0, 3 s constant speed, 2 s ramp to -dec, 1 s hold, 2 s ramp to 0,
    /// 1 s rest (15 s). Returns the samples and the constant-speed range.
    fn travel_profile(fs: f64, acc: f64, dec: f64) -> (Vec<f64>, Range<usize>) {
        let n = (15.0 * fs) as usize;
        let x = (0..n)
            .map(|k| {
                let t = k as f64 / fs;
                smooth_step(t, 1.0, 2.0, 0.0, acc) + smooth_step(t, 4.0, 2.0, 0.0, -acc)
                    - smooth_step(t, 9.0, 2.0, 0.0, dec)
                    + smooth_step(t, 12.0, 2.0, 0.0, dec)
            })
            .collect();
        (x, (6.0 * fs) as usize..(9.0 * fs) as usize)
    }

    #[test]
    fn trapezoidal_profile_gives_max_acceleration_and_deceleration() {
        let fs = 1000.0;
        let (acc, dec) = (1.0, 0.8);
        let (x, cs) = travel_profile(fs, acc, dec);
        let r = ride_quality(&x, fs, Some(cs.clone())).unwrap();
        assert_eq!(r.direction, TravelDirection::Up);
        assert_eq!(r.jerk_window_samples, 501);
        // Plateaus 1.0 and 0.8 m/s^2 = 101.97 mg and 81.58 mg; the 10 Hz
        // low-pass has unit DC gain and the smooth ramps do not overshoot
        // it measurably (asserted 0.05 %).
        let (acc_mg, dec_mg) = (acc / 9.80665e-3, dec / 9.80665e-3);
        assert!((r.whole_run.max_acceleration_mg / acc_mg - 1.0).abs() < 5e-4, "{:?}", r.whole_run);
        assert!((r.whole_run.max_deceleration_mg / dec_mg - 1.0).abs() < 5e-4, "{:?}", r.whole_run);
        // Peak jerk of a raised-cosine ramp: pi a / (2 T) = 0.785 m/s^3; the
        // 0.5 s fit averages the sinusoidal jerk over its crest with the
        // parabolic weight of a least-squares slope (variance W^2 / 20), so
        // it reads about (pi/T)^2 W^2 / 40 = 1.5 % low.
        let peak_jerk = PI * acc / 4.0;
        let expected = peak_jerk * (1.0 - (PI / 2.0_f64).powi(2) * 0.25 / 40.0);
        assert!((r.whole_run.max_jerk_mps3 / expected - 1.0).abs() < 2e-3, "{}", r.whole_run.max_jerk_mps3);
        // Constant speed: no jerk, and no acceleration except what the
        // low-pass still lags at the start of the region (t = 6 s, where the
        // ramp to 0 ends). With H = 1 - sqrt(2) s/wc + s^2/wc^2 + ..., the
        // lag there is a''/wc^2 with a'' = (pi/T)^2 acc / 2 (a' = 0).
        let c = r.constant_speed.unwrap();
        assert_eq!(c.region, cs);
        let wc = 2.0 * PI * ACCELERATION_LOWPASS_HZ;
        let lag_mg = (PI / 2.0).powi(2) * acc / 2.0 / (wc * wc) / MPS2_PER_MG;
        assert!((c.max_acceleration_mg / lag_mg - 1.0).abs() < 0.02, "{c:?} vs {lag_mg}");
        assert!(c.max_deceleration_mg < lag_mg, "{c:?}");
        assert!(c.max_jerk_mps3 < 1e-4, "{c:?}");
        assert_eq!(r.whole_run.region, 0..x.len());

        // The same run downwards: signs flip, the roles stay.
        let down: Vec<f64> = x.iter().map(|v| -v).collect();
        let d = ride_quality(&down, fs, None).unwrap();
        assert_eq!(d.direction, TravelDirection::Down);
        assert!(d.constant_speed.is_none());
        assert!((d.whole_run.max_acceleration_mg - r.whole_run.max_acceleration_mg).abs() < 1e-9);
        assert!((d.whole_run.max_deceleration_mg - r.whole_run.max_deceleration_mg).abs() < 1e-9);
        assert!((d.whole_run.max_jerk_mps3 - r.whole_run.max_jerk_mps3).abs() < 1e-9);
    }

    #[test]
    fn linear_acceleration_ramp_gives_its_slope_as_jerk() {
        // 1 s rest, ramp at 0.9 m/s^3 for 2 s, hold 1.8 m/s^2 for 2 s.
        let (fs, jerk) = (1000.0, 0.9);
        let x: Vec<f64> = (0..5000).map(|k| jerk * (k as f64 / fs - 1.0).clamp(0.0, 2.0)).collect();
        let ramp = 1300..2900; // inside the ramp, past the filter's transient
        let r = ride_quality(&x, fs, Some(ramp)).unwrap();
        assert!((r.whole_run.max_jerk_mps3 / jerk - 1.0).abs() < 0.01, "{}", r.whole_run.max_jerk_mps3);
        let c = r.constant_speed.unwrap();
        assert!((c.max_jerk_mps3 / jerk - 1.0).abs() < 1e-4, "{}", c.max_jerk_mps3);
        // The low-pass overshoots the corner at 1.8 m/s^2 by
        // J * integral of (step response - 1) after its first crossing of 1,
        // = J exp(-3 pi / 4) / wc for a 2nd-order Butterworth (1.36e-3 m/s^2).
        let wc = 2.0 * PI * ACCELERATION_LOWPASS_HZ;
        let peak = 1.8 + jerk * (-0.75 * PI).exp() / wc;
        assert!((r.whole_run.max_acceleration_mg * MPS2_PER_MG - peak).abs() < 1e-5, "{:?}", r.whole_run);
        // Falling ramp: the magnitude is reported.
        let neg: Vec<f64> = x.iter().map(|v| -v).collect();
        let rn = ride_quality(&neg, fs, None).unwrap();
        assert!((rn.whole_run.max_jerk_mps3 - r.whole_run.max_jerk_mps3).abs() < 1e-12);
    }

    #[test]
    fn vibration_at_constant_speed_is_weighted_by_wk() {
        // Constant speed throughout with a 10 mg, 8 Hz vibration: in the
        // settled part the Wk-weighted peak-to-peak is 2 * 10 mg * |Wk(8 Hz)|
        // (1.036 in ISO 2631-1 Table 3) for every pair, so max = A95.
        let (fs, f, amp_mg) = (1000.0, 8.0, 10.0);
        let x: Vec<f64> = (0..20_000).map(|k| amp_mg * MPS2_PER_MG * (2.0 * PI * f * k as f64 / fs).sin()).collect();
        let r = ride_quality(&x, fs, Some(5000..19_000)).unwrap();
        let c = r.constant_speed.unwrap();
        let expected = 2.0 * amp_mg * wk_digital_gain(f, fs).unwrap();
        assert!((expected / (2.0 * amp_mg * 1.036) - 1.0).abs() < 0.005);
        // Crest sampling at 125 samples per period: within 1 - cos(pi/125).
        assert!((c.max_peak_to_peak_mg / expected - 1.0).abs() < 1e-3, "{c:?} vs {expected}");
        assert!((c.a95_peak_to_peak_mg / expected - 1.0).abs() < 1e-3, "{c:?} vs {expected}");
        assert!(c.peak_to_peak_count > 2 * 8 * 13);
        assert!(r.whole_run.max_peak_to_peak_mg >= c.max_peak_to_peak_mg);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let fs = 1000.0;
        let x = vec![0.0; 2000];
        assert_eq!(ride_quality(&[], fs, None), Err(AnalysisError::EmptySignal));
        assert_eq!(
            ride_quality(&[0.0; 100], fs, None),
            Err(AnalysisError::TooShort { len: 100, min: 501, what: "ride quality (one 0.5 s jerk fit window)" })
        );
        let mut nan = x.clone();
        nan[7] = f64::NAN;
        assert!(matches!(ride_quality(&nan, fs, None), Err(AnalysisError::NonFinite { index: 7, .. })));
        for bad_fs in [0.0, 10.0, f64::NAN, f64::INFINITY] {
            match ride_quality(&x, bad_fs, None) {
                Err(AnalysisError::InvalidParameter { name, .. }) => assert_eq!(name, "sample_rate_hz"),
                other => panic!("fs {bad_fs}: {other:?}"),
            }
        }
        for range in [0..2001, 600..600, Range { start: 900, end: 100 }, 0..500] {
            match ride_quality(&x, fs, Some(range.clone())) {
                Err(AnalysisError::InvalidParameter { name, .. }) => assert_eq!(name, "constant_speed"),
                other => panic!("range {range:?}: {other:?}"),
            }
        }
        assert!(ride_quality(&x, fs, Some(1499..2000)).is_ok());
        let huge: Vec<f64> = (0..2000).map(|k| if k % 2 == 0 { 1e307 } else { -1e307 }).collect();
        assert!(matches!(ride_quality(&huge, fs, None), Err(AnalysisError::NumericOverflow { .. })));
    }

    #[test]
    #[ignore = "timing report, run with --release -- --ignored --nocapture"]
    fn timing_20_s_at_16384_hz() {
        let fs = 16384.0;
        let (mut x, _) = travel_profile(fs, 1.0, 1.0);
        x.extend(std::iter::repeat_n(0.0, (5.0 * fs) as usize));
        for (k, v) in x.iter_mut().enumerate() {
            *v += 0.02 * (2.0 * PI * 9.3 * k as f64 / fs).sin() + 0.01 * (2.0 * PI * 31.0 * k as f64 / fs).sin();
        }
        assert_eq!(x.len(), 20 * 16384);
        let start = std::time::Instant::now();
        let r = ride_quality(&x, fs, Some((6.0 * fs) as usize..(9.0 * fs) as usize)).unwrap();
        let elapsed = start.elapsed();
        println!("ride_quality, 20 s at 16384 Hz ({} samples): {elapsed:?}\n{r:#?}", x.len());
    }
}
