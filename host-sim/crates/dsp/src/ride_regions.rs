//! Regions of a lift run for the ride-quality report (ISO 18738-1): the
//! standstill before and after the motion, the acceleration, the
//! constant-speed region and the deceleration, found either from a recorded
//! speed ([`regions_from_speed`]) or, when a recording has none (the
//! `EVIMP1` export of an analyzer), from the vertical acceleration itself
//! ([`regions_from_acceleration`]).
//!
//! # Rules, with their constants
//!
//! * **Constant-speed region**: the longest run of samples whose speed is
//!   at least [`CONSTANT_SPEED_FRACTION`] (95 %) of the run's largest speed.
//!   The ISO 18738-1 text was not available to this project; 95 % of the
//!   maximum velocity is the bound this module uses for the "constant speed"
//!   (rated speed) region of the standard, stated here so that a reader
//!   holding the standard can check it. A run shorter than
//!   [`MIN_CONSTANT_SPEED_S`] (one 0.5 s jerk window) is no region.
//! * **From a speed signal** (any unit, either sign): `|speed|` averaged
//!   over a centred [`SPEED_SMOOTHING_S`] (0.1 s) window; the motion spans
//!   from the first to the last sample above [`MOTION_SPEED_FRACTION`]
//!   (2 %) of its maximum.
//! * **From the vertical acceleration** (m/s^2, any constant offset):
//!   1. the acceleration averaged over a centred [`MOTION_SMOOTHING_S`]
//!      (0.5 s) window, minus its median over the record (the offset: a lift
//!      run is mostly standstill and constant speed, where the acceleration
//!      is zero); the motion spans from the first to the last sample where
//!      its magnitude exceeds [`MOTION_ACCELERATION_FRACTION`] (5 %) of its
//!      largest magnitude, widened by half the averaging window on each side
//!      (the averaging spreads the start of a jerk ramp over that much);
//!   2. the velocity is the running sum of the acceleration (rectangle
//!      rule, `v[k] = sum (a - b) / fs`) over the motion widened by
//!      [`INTEGRATION_MARGIN_S`] (0.5 s) on each side, zero outside it; the
//!      offset `b` is the constant that makes the mean velocity over the
//!      last [`INTEGRATION_MARGIN_S`] of that span zero: the car is at rest
//!      there, so a constant sensor offset is taken off exactly, and the
//!      vibration's own velocity, which a single sample would carry, averages
//!      out over the window;
//!   3. the constant-speed region is that of the rule above on `|v|`
//!      averaged over a centred [`VELOCITY_SMOOTHING_S`] (0.25 s) window,
//!      which takes out the velocity's vibration (at 4 Hz a 40 mg vibration
//!      moves the velocity by 1.6 cm/s, 1 % of a 1.5 m/s cruise) and moves
//!      the edges of a jerk-limited cruise inwards by less than 10 ms.
//!
//! Acceleration and deceleration are what lies between the motion's edges
//! and the constant-speed region; without a constant-speed region the
//! motion is split at the largest speed.

use std::ops::Range;

use super::{check_sample_rate, check_signal, AnalysisError};

/// Fraction of the largest speed at or above which the run is at constant
/// speed (see the module documentation); dimensionless.
pub const CONSTANT_SPEED_FRACTION: f64 = 0.95;
/// Shortest constant-speed region, s (one ISO 18738-1 jerk fit window).
pub const MIN_CONSTANT_SPEED_S: f64 = 0.5;
/// Centred moving average applied to `|speed|`, s.
pub const SPEED_SMOOTHING_S: f64 = 0.1;
/// The car moves while its smoothed speed exceeds this fraction of its
/// largest smoothed speed; dimensionless.
pub const MOTION_SPEED_FRACTION: f64 = 0.02;
/// Centred moving average applied to the acceleration to find the motion, s.
pub const MOTION_SMOOTHING_S: f64 = 0.5;
/// The car moves between the first and last samples whose averaged
/// acceleration (offset removed) exceeds this fraction of its largest
/// magnitude; dimensionless.
pub const MOTION_ACCELERATION_FRACTION: f64 = 0.05;
/// Margin added to each side of the motion for the velocity integration,
/// and the closing window at rest whose mean velocity is zero, s.
pub const INTEGRATION_MARGIN_S: f64 = 0.5;
/// Centred moving average applied to `|v|` before the constant-speed rule,
/// when the velocity is integrated from the acceleration, s.
pub const VELOCITY_SMOOTHING_S: f64 = 0.25;
/// Smallest largest-magnitude of the averaged acceleration that counts as a
/// motion, m/s^2 (1 mg: below it the record is a standstill).
pub const MIN_MOTION_ACCELERATION_MPS2: f64 = 9.80665e-3;

/// Where the regions of a run come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RegionSource {
    /// A recorded speed signal.
    Speed,
    /// The vertical acceleration, integrated (no speed was recorded).
    IntegratedAcceleration,
}

impl RegionSource {
    /// A short description for reports.
    pub fn describe(self) -> &'static str {
        match self {
            RegionSource::Speed => "the recorded speed",
            RegionSource::IntegratedAcceleration => "the integrated vertical acceleration",
        }
    }
}

/// Regions of a run as sample index ranges. `start`, `acceleration`,
/// (`constant_speed`,) `deceleration` and `stop` are contiguous and cover
/// every sample; any of `start`, `stop` may be empty.
#[derive(Debug, Clone, PartialEq)]
pub struct RideRegions {
    /// What the regions were found from.
    pub source: RegionSource,
    /// Standstill before the motion.
    pub start: Range<usize>,
    /// From the start of the motion to the constant-speed region (or to the
    /// largest speed).
    pub acceleration: Range<usize>,
    /// The constant-speed region, if the run has one.
    pub constant_speed: Option<Range<usize>>,
    /// From the constant-speed region (or the largest speed) to the end of
    /// the motion.
    pub deceleration: Range<usize>,
    /// Standstill after the motion.
    pub stop: Range<usize>,
}

impl RideRegions {
    /// The motion: from the start of the acceleration to the end of the
    /// deceleration.
    pub fn motion(&self) -> Range<usize> {
        self.acceleration.start..self.deceleration.end
    }
}

/// Centred moving average of `x` (or of `|x|` with `abs`) over `window`
/// samples, shrinking to the available samples near the ends.
fn moving_average(x: &[f64], window: usize, abs: bool) -> Vec<f64> {
    let half = window / 2;
    let mut prefix = Vec::with_capacity(x.len() + 1);
    let mut acc = 0.0;
    prefix.push(acc);
    for v in x {
        acc += if abs { v.abs() } else { *v };
        prefix.push(acc);
    }
    (0..x.len())
        .map(|i| {
            let (lo, hi) = (i.saturating_sub(half), (i + half + 1).min(x.len()));
            (prefix[hi] - prefix[lo]) / (hi - lo) as f64
        })
        .collect()
}

/// Samples in `seconds` at `fs`, at least 1.
fn samples(seconds: f64, fs: f64) -> usize {
    ((seconds * fs).round() as usize).max(1)
}

/// Longest run of `speed` (non-negative) at or above
/// [`CONSTANT_SPEED_FRACTION`] of its maximum inside `within`, if it lasts
/// at least [`MIN_CONSTANT_SPEED_S`].
fn constant_speed_run(speed: &[f64], within: Range<usize>, fs: f64) -> Option<Range<usize>> {
    let max = speed[within.clone()].iter().copied().fold(0.0, f64::max);
    if max <= 0.0 {
        return None;
    }
    let level = CONSTANT_SPEED_FRACTION * max;
    let best = crate::stages::longest_run(within, |i| speed[i] >= level);
    (best.len() >= samples(MIN_CONSTANT_SPEED_S, fs)).then_some(best)
}

/// The regions from the motion `motion` and the speed magnitude `speed`.
fn assemble(source: RegionSource, n: usize, motion: Range<usize>, speed: &[f64], fs: f64) -> RideRegions {
    let constant = constant_speed_run(speed, motion.clone(), fs);
    let (acc_end, dec_start) = match &constant {
        Some(c) => (c.start, c.end),
        None => {
            let peak = motion.clone().max_by(|&a, &b| speed[a].total_cmp(&speed[b])).unwrap_or(motion.start);
            (peak, peak)
        }
    };
    RideRegions {
        source,
        start: 0..motion.start,
        acceleration: motion.start..acc_end,
        constant_speed: constant,
        deceleration: dec_start..motion.end,
        stop: motion.end..n,
    }
}

/// Regions of a run from its recorded speed (see the module documentation).
///
/// * `speed`: speed of the car or machine, any unit, either sign, finite.
/// * `sample_rate_hz`: Hz, finite and > 0.
///
/// # Errors
/// [`AnalysisError::EmptySignal`], [`AnalysisError::NonFinite`] for a bad
/// signal, [`AnalysisError::InvalidParameter`] for a bad sample rate or a
/// speed that is zero throughout.
pub fn regions_from_speed(speed: &[f64], sample_rate_hz: f64) -> Result<RideRegions, AnalysisError> {
    check_sample_rate(sample_rate_hz)?;
    check_signal(speed, 1, "a run's speed signal")?;
    let s = moving_average(speed, samples(SPEED_SMOOTHING_S, sample_rate_hz), true);
    let max = s.iter().copied().fold(0.0, f64::max);
    if !(max > 0.0 && max.is_finite()) {
        return Err(AnalysisError::InvalidParameter {
            name: "speed",
            value: max,
            expected: "a run: a finite speed signal that is not zero throughout",
        });
    }
    let threshold = MOTION_SPEED_FRACTION * max;
    let first = s.iter().position(|&v| v > threshold).unwrap_or(0);
    let last = s.iter().rposition(|&v| v > threshold).map_or(s.len(), |i| i + 1);
    Ok(assemble(RegionSource::Speed, s.len(), first..last, &s, sample_rate_hz))
}

/// The motion of a run from its vertical acceleration (rule 1 of the module
/// documentation).
fn motion_from_acceleration(acc: &[f64], fs: f64) -> Result<Range<usize>, AnalysisError> {
    let window = samples(MOTION_SMOOTHING_S, fs);
    let smooth = moving_average(acc, window, false);
    let mut sorted = smooth.clone();
    let mid = sorted.len() / 2;
    let median = *sorted.select_nth_unstable_by(mid, f64::total_cmp).1;
    let peak = smooth.iter().fold(0.0_f64, |m, v| m.max((v - median).abs()));
    if !(peak.is_finite() && peak >= MIN_MOTION_ACCELERATION_MPS2) {
        return Err(AnalysisError::InvalidParameter {
            name: "acceleration",
            value: peak,
            expected: "a run: a vertical acceleration whose 0.5 s average departs from its median by at least 1 mg",
        });
    }
    let threshold = MOTION_ACCELERATION_FRACTION * peak;
    let above = |v: &f64| (v - median).abs() > threshold;
    let first = smooth.iter().position(above).unwrap_or(0);
    let last = smooth.iter().rposition(above).map_or(smooth.len(), |i| i + 1);
    let half = window / 2;
    Ok(first.saturating_sub(half)..(last + half).min(acc.len()))
}

/// The span the velocity is integrated over: `motion` widened by
/// [`INTEGRATION_MARGIN_S`] on each side, within `n` samples.
fn integration_span(motion: Range<usize>, fs: f64, n: usize) -> Range<usize> {
    let margin = samples(INTEGRATION_MARGIN_S, fs);
    motion.start.saturating_sub(margin)..(motion.end + margin).min(n)
}

/// Offset of the acceleration `acc` (m/s^2, sampled at `fs` Hz) of a run
/// whose motion is `motion` (at rest before and after): rule 2 of the module
/// documentation, m/s^2; 0 for an empty motion.
pub fn motion_offset(acc: &[f64], fs: f64, motion: Range<usize>) -> f64 {
    let span = integration_span(motion, fs, acc.len());
    if span.is_empty() {
        return 0.0;
    }
    // v_b[k] = S[k] - b (k - start + 1) / fs; the closing window's mean of
    // v_b is zero for b = mean(S) fs / mean(k - start + 1).
    let window = samples(INTEGRATION_MARGIN_S, fs).min(span.len());
    let mut sum = 0.0;
    let (mut s_mean, mut k_mean) = (0.0, 0.0);
    for (i, k) in span.clone().enumerate() {
        sum += acc[k] / fs;
        if i + window >= span.len() {
            s_mean += sum;
            k_mean += (i + 1) as f64;
        }
    }
    s_mean * fs / k_mean
}

/// Vertical velocity, m/s, of a run whose acceleration `acc` (m/s^2) is
/// sampled at `fs` Hz and whose motion (at rest before and after) is
/// `motion`: rule 2 of the module documentation, the running sum of the
/// acceleration minus [`motion_offset`] over the widened motion. Zero
/// outside that span.
pub fn velocity_from_acceleration(acc: &[f64], fs: f64, motion: Range<usize>) -> Vec<f64> {
    let offset = motion_offset(acc, fs, motion.clone());
    let mut v = vec![0.0; acc.len()];
    let mut sum = 0.0;
    for k in integration_span(motion, fs, acc.len()) {
        sum += (acc[k] - offset) / fs;
        v[k] = sum;
    }
    v
}

/// `|v|` averaged over a centred [`VELOCITY_SMOOTHING_S`] window: the speed
/// the constant-speed rule is applied to (rule 3 of the module
/// documentation), in the unit of `v`.
pub fn smoothed_speed(v: &[f64], fs: f64) -> Vec<f64> {
    moving_average(v, samples(VELOCITY_SMOOTHING_S, fs), true)
}

/// Regions of a run from its vertical acceleration alone (see the module
/// documentation), and the velocity they were found from (m/s).
///
/// * `acceleration_mps2`: vertical acceleration of the car, m/s^2, either
///   sign convention, any constant offset; finite.
/// * `sample_rate_hz`: Hz, finite and > 0.
///
/// # Errors
/// [`AnalysisError::EmptySignal`], [`AnalysisError::NonFinite`] for a bad
/// signal, [`AnalysisError::InvalidParameter`] for a bad sample rate or an
/// acceleration without a motion (its 0.5 s average never departs from its
/// median by [`MIN_MOTION_ACCELERATION_MPS2`]).
pub fn regions_from_acceleration(
    acceleration_mps2: &[f64],
    sample_rate_hz: f64,
) -> Result<(RideRegions, Vec<f64>), AnalysisError> {
    check_sample_rate(sample_rate_hz)?;
    check_signal(acceleration_mps2, 1, "a run's vertical acceleration")?;
    let motion = motion_from_acceleration(acceleration_mps2, sample_rate_hz)?;
    let v = velocity_from_acceleration(acceleration_mps2, sample_rate_hz, motion.clone());
    let speed = smoothed_speed(&v, sample_rate_hz);
    let regions = assemble(RegionSource::IntegratedAcceleration, v.len(), motion, &speed, sample_rate_hz);
    Ok((regions, v))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_signals::gaussian;

    /// Jerk-limited run: `rest` s at rest, a ramp with jerk `j` (m/s^3) to
    /// acceleration `a` and speed `v`, `cruise` s at `v`, the mirror ramp
    /// down, `rest` s at rest. Returns the acceleration and the exact times
    /// (s) of the motion's start and end and of the instants the speed
    /// reaches and leaves 95 % of `v`.
    struct Run {
        acc: Vec<f64>,
        speed: Vec<f64>,
        motion_s: (f64, f64),
        constant_s: (f64, f64),
    }

    fn run(fs: f64, v: f64, a: f64, j: f64, rest: f64, cruise: f64) -> Run {
        let tj = a / j;
        let ta = v / a - tj;
        assert!(ta >= 0.0);
        let ramp = 2.0 * tj + ta;
        // Acceleration and speed `tau` s into the ramp up.
        let up = |tau: f64| -> (f64, f64) {
            if tau <= 0.0 {
                (0.0, 0.0)
            } else if tau < tj {
                (j * tau, 0.5 * j * tau * tau)
            } else if tau < tj + ta {
                (a, 0.5 * j * tj * tj + a * (tau - tj))
            } else if tau < ramp {
                let r = ramp - tau;
                (j * r, v - 0.5 * j * r * r)
            } else {
                (0.0, v)
            }
        };
        let (t1, t2) = (rest + ramp, rest + ramp + cruise);
        let total = t2 + ramp + rest;
        let (mut acc, mut speed) = (Vec::new(), Vec::new());
        for k in 0..(total * fs) as usize {
            let t = k as f64 / fs;
            let (a_k, v_k) = if t < t2 {
                up(t - rest)
            } else {
                let (a_d, v_d) = up(t2 + ramp - t);
                (-a_d, v_d)
            };
            acc.push(a_k);
            speed.push(v_k);
        }
        // The speed reaches 0.95 v at r = sqrt(2 * 0.05 v / j) before the
        // end of the ramp (on the last jerk phase when r < tj).
        let r = (2.0 * (1.0 - CONSTANT_SPEED_FRACTION) * v / j).sqrt();
        assert!(r < tj);
        Run { acc, speed, motion_s: (rest, t2 + ramp), constant_s: (t1 - r, t2 + r) }
    }

    #[test]
    fn regions_from_acceleration_find_the_known_boundaries_of_a_run() {
        // A 1.5 m/s lift: 0.9 m/s^2, 1.2 m/s^3; 3 s rest, 8 s cruise, at
        // 256 Hz, with a 4 mg sensor offset, a 9 Hz vibration of 10 mg and
        // 2 mg of white noise.
        let fs = 256.0;
        let r = run(fs, 1.5, 0.9, 1.2, 3.0, 8.0);
        let noise = gaussian(r.acc.len(), 7);
        let acc: Vec<f64> = r
            .acc
            .iter()
            .enumerate()
            .map(|(k, a)| {
                let t = k as f64 / fs;
                a + 0.04 + 0.098 * (2.0 * std::f64::consts::PI * 9.0 * t).sin() + 0.0196 * noise[k]
            })
            .collect();
        let (reg, v) = regions_from_acceleration(&acc, fs).unwrap();
        assert_eq!(reg.source, RegionSource::IntegratedAcceleration);
        let c = reg.constant_speed.clone().unwrap();
        let (c0, c1) = (c.start as f64 / fs, c.end as f64 / fs);
        // Boundaries within 20 ms of the exact 95 % instants.
        assert!((c0 - r.constant_s.0).abs() < 0.02, "start {c0} vs {}", r.constant_s.0);
        assert!((c1 - r.constant_s.1).abs() < 0.02, "end {c1} vs {}", r.constant_s.1);
        // The motion contains the true one and exceeds it by at most 0.35 s:
        // half the averaging window (0.25 s) and the averaged acceleration's
        // early rise (at the true start it is already 8 % of the plateau).
        let (m0, m1) = (reg.motion().start as f64 / fs, reg.motion().end as f64 / fs);
        assert!(m0 <= r.motion_s.0 + 0.1 && m0 > r.motion_s.0 - 0.35, "motion start {m0} vs {}", r.motion_s.0);
        assert!(m1 >= r.motion_s.1 - 0.1 && m1 < r.motion_s.1 + 0.35, "motion end {m1} vs {}", r.motion_s.1);
        // The velocity peaks at 1.5 m/s within 1 %.
        let vmax = v.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        assert!((vmax / 1.5 - 1.0).abs() < 0.01, "{vmax}");
        // The regions partition the record.
        assert_eq!(reg.start.end, reg.acceleration.start);
        assert_eq!(reg.acceleration.end, c.start);
        assert_eq!(c.end, reg.deceleration.start);
        assert_eq!(reg.deceleration.end, reg.stop.start);
        assert_eq!(reg.stop.end, acc.len());
        // Downwards (negated) the same regions.
        let down: Vec<f64> = acc.iter().map(|a| -a).collect();
        let (reg_d, _) = regions_from_acceleration(&down, fs).unwrap();
        assert_eq!(reg_d.constant_speed, reg.constant_speed);
    }

    #[test]
    fn regions_from_speed_find_the_known_boundaries_of_a_run() {
        let fs = 1000.0;
        let r = run(fs, 0.4, 0.5, 1.0, 1.0, 5.0);
        let reg = regions_from_speed(&r.speed, fs).unwrap();
        assert_eq!(reg.source, RegionSource::Speed);
        let c = reg.constant_speed.clone().unwrap();
        // The 0.1 s average shifts the edges by less than its half width.
        assert!((c.start as f64 / fs - r.constant_s.0).abs() < 0.05, "{c:?}");
        assert!((c.end as f64 / fs - r.constant_s.1).abs() < 0.05, "{c:?}");
        // Motion starts where the averaged speed passes 2 % of 0.4 m/s:
        // 0.5 j t^2 = 0.008 -> t = 0.126 s, less up to the half window.
        let m0 = reg.motion().start as f64 / fs - r.motion_s.0;
        assert!(m0 > 0.0 && m0 < 0.13, "{m0}");
        // A negative speed (down travel) gives the same regions.
        let neg: Vec<f64> = r.speed.iter().map(|v| -v).collect();
        assert_eq!(regions_from_speed(&neg, fs).unwrap(), reg);
    }

    #[test]
    fn a_run_too_short_to_cruise_has_no_constant_speed_region() {
        // Triangular speed: ramps up and straight down, no cruise.
        let fs = 500.0;
        let speed: Vec<f64> = (0..3000).map(|k| (1.0 - ((k as f64 / fs) - 3.0).abs() / 2.0).max(0.0)).collect();
        let reg = regions_from_speed(&speed, fs).unwrap();
        // 95 % of the peak lasts 0.2 s: less than a jerk window.
        assert!(reg.constant_speed.is_none(), "{reg:?}");
        // Split at the peak (t = 3 s).
        assert!((reg.acceleration.end as f64 / fs - 3.0).abs() < 0.01, "{reg:?}");
    }

    #[test]
    fn standstill_and_bad_inputs_are_errors() {
        let still = vec![0.01; 1000];
        assert!(matches!(regions_from_acceleration(&still, 256.0), Err(AnalysisError::InvalidParameter { .. })));
        assert!(matches!(regions_from_speed(&[0.0; 100], 256.0), Err(AnalysisError::InvalidParameter { .. })));
        assert!(matches!(regions_from_speed(&[], 256.0), Err(AnalysisError::EmptySignal)));
        assert!(matches!(regions_from_acceleration(&[0.0, f64::NAN], 256.0), Err(AnalysisError::NonFinite { .. })));
        assert!(regions_from_acceleration(&[0.0, 1.0], 0.0).is_err());
    }
}
