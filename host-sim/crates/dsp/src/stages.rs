//! Stages of a travel from the machine speed signal (seed paper, section
//! 3.3: "the velocity profile is composed of acceleration and deceleration
//! stages and a constant velocity stage"; Fig. 4 averages the torque ripple
//! over the constant velocity stage).
//!
//! The input is the drive's filtered encoder speed estimate (rad/s), which
//! carries quantization noise and the speed ripple of the torque ripple
//! (1 Hz imbalance, 12 Hz radial force, ...). The rules, with their
//! constants:
//!
//! 1. Smoothing: `s = |speed|` averaged over a centred 1 s window
//!    ([`SMOOTHING_WINDOW_S`]; near the ends over the samples available).
//!    A 1 s boxcar cancels a ripple at 1 Hz and its harmonics and averages
//!    the quantization noise.
//! 2. Cruise level: `v_c` = median of `s` over the samples with
//!    `s >= 0.9 max(s)` ([`TOP_FRACTION`]); the cruise dominates those
//!    samples even for a short cruise, the end of the ramps only adds a
//!    few.
//! 3. Rough stage: the longest run of samples with `|s - v_c| <= 0.02 v_c`
//!    ([`BAND_FRACTION`]).
//! 4. Edges: the constant-speed stage runs from the first to the last
//!    sample of that run with `s >= 0.99 v_c` ([`EDGE_FRACTION`]).
//!
//! Why rule 4: the smoothed speed reaches the cruise level only when the
//! whole window has left the ramp. If the cruise starts at `t1` after a
//! jerk-limited ramp (jerk `J`, rad/s^3), `s` at `t1 + W/2 - tau` is short of
//! `v_c` by `J tau^3 / (6 W)` (W the window). It first reaches
//! `0.99 v_c` at `tau = (0.06 v_c W / J)^(1/3)`, which is inside the cruise
//! while `tau < W/2`, i.e. while `J W^2 / 48 > 0.01 v_c` plus the noise left
//! in `s`. For the reference rig (0.4 m/s, 1 m/s^3 on a 65 mm sheave:
//! `v_c` = 6.15 rad/s, `J` = 15.4 rad/s^3) `tau` = 0.29 s: the stage starts
//! about 0.2 s after the true cruise start and ends about 0.2 s before the
//! true cruise end, 97 % of a 15 s cruise. The same holds at the end of the
//! cruise by symmetry. A much gentler jerk (below about `0.5 v_c / W^2`) or
//! speed noise left after smoothing above about 1 % of `v_c` can move an
//! edge up to half a window into the ramp.

use std::ops::Range;

use super::{check_sample_rate, check_signal, AnalysisError};

/// Length of the centred moving average applied to `|speed|`, s.
pub const SMOOTHING_WINDOW_S: f64 = 1.0;
/// Samples with smoothed speed at or above this fraction of the maximum
/// smoothed speed define the cruise level (their median); dimensionless.
pub const TOP_FRACTION: f64 = 0.9;
/// Half-width of the band around the cruise level that the rough stage stays
/// in, as a fraction of the cruise level; dimensionless.
pub const BAND_FRACTION: f64 = 0.02;
/// The stage's first and last samples are the first and last of the rough
/// stage at or above this fraction of the cruise level; dimensionless.
pub const EDGE_FRACTION: f64 = 0.99;
/// Shortest constant-speed stage [`constant_speed_stage`] accepts, s: the
/// smoothing window (a shorter stage is the ramps' meeting, not a cruise;
/// about one shaft revolution at the reference rig's 6.15 rad/s, over which
/// the order-1 ripple averages out).
pub const MIN_STAGE_S: f64 = SMOOTHING_WINDOW_S;
/// Length of the centred moving average used to decide whether the machine
/// moves ([`travel_phases`]), s.
pub const MOTION_WINDOW_S: f64 = 0.1;
/// The machine is taken as moving while its briefly smoothed speed exceeds
/// this fraction of the cruise level ([`travel_phases`]); dimensionless.
pub const MOTION_FRACTION: f64 = 0.02;

/// Phases of a travel as sample index ranges into the speed signal.
///
/// The five ranges are contiguous, in this order, and together cover every
/// sample: `start.start == 0`, each range ends where the next begins, and
/// `stop.end` is the signal length. Any of them except `constant` may be
/// empty (a recording that begins or ends while the car moves).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TravelPhases {
    /// Standstill before the travel.
    pub start: Range<usize>,
    /// From the start of the motion to the constant-speed stage.
    pub acceleration: Range<usize>,
    /// The constant-speed stage, as [`constant_speed_stage`] finds it.
    pub constant: Range<usize>,
    /// From the end of the constant-speed stage to the end of the motion.
    pub deceleration: Range<usize>,
    /// Standstill after the travel.
    pub stop: Range<usize>,
}

/// Centred moving average of `|x|` over `window` samples (odd: `window`
/// rounded up to odd), shrinking to the available samples near the ends.
fn smoothed_abs(x: &[f64], window: usize) -> Vec<f64> {
    let half = window / 2;
    let mut prefix = Vec::with_capacity(x.len() + 1);
    prefix.push(0.0);
    let mut acc = 0.0;
    for v in x {
        acc += v.abs();
        prefix.push(acc);
    }
    (0..x.len())
        .map(|i| {
            let lo = i.saturating_sub(half);
            let hi = (i + half + 1).min(x.len());
            (prefix[hi] - prefix[lo]) / (hi - lo) as f64
        })
        .collect()
}

/// Samples in `seconds` at `sample_rate_hz`, at least 1 and at most `len`.
fn window_samples(seconds: f64, sample_rate_hz: f64, len: usize) -> usize {
    ((seconds * sample_rate_hz).round() as usize).clamp(1, len.max(1))
}

/// Cruise level (rad/s) and constant-speed stage of the smoothed speed `s`.
fn stage_of_smoothed(s: &[f64]) -> Result<(f64, Range<usize>), AnalysisError> {
    if s.iter().any(|v| !v.is_finite()) {
        return Err(AnalysisError::NumericOverflow { what: "smoothed speed" });
    }
    let max = s.iter().copied().fold(0.0, f64::max);
    if max <= 0.0 {
        return Err(AnalysisError::InvalidParameter {
            name: "speed_radps",
            value: 0.0,
            expected: "a travel: a speed signal that is not zero throughout",
        });
    }
    let mut top: Vec<f64> = s.iter().copied().filter(|&v| v >= TOP_FRACTION * max).collect();
    let mid = top.len() / 2;
    let (_, &mut median, _) = top.select_nth_unstable_by(mid, f64::total_cmp);
    let level = median;

    // Longest run within the band (the first one on a tie).
    let band = BAND_FRACTION * level;
    let best = longest_run(0..s.len(), |i| (s[i] - level).abs() <= band);
    // The median sample itself is in the band, so the run is not empty.
    let edge = EDGE_FRACTION * level;
    let first = best.clone().find(|&i| s[i] >= edge);
    let last = best.clone().rev().find(|&i| s[i] >= edge);
    let stage = match (first, last) {
        (Some(a), Some(b)) => a..b + 1,
        _ => best,
    };
    Ok((level, stage))
}

/// Constant-speed stage of a travel: sample indices into `speed_radps`.
///
/// * `speed_radps`: machine speed, rad/s (any unit works: only ratios are
///   used), either sign (a down travel has negative speed), at least one
///   sample, finite.
/// * `sample_rate_hz`: sample rate in Hz, finite and > 0.
///
/// The stage is found by the rules of the module documentation: 1 s centred
/// smoothing of `|speed|`, cruise level = median of the smoothed samples
/// above 90 % of the maximum, longest run within ±2 % of that level, trimmed
/// to the first and last samples at or above 99 % of it. For a jerk-limited
/// profile the result lies inside the true constant-speed interval and
/// misses about 0.2 s at each end (the module documentation gives the
/// condition). If the travel has several constant-speed stages, the longest
/// is returned.
///
/// # Errors
/// [`AnalysisError::EmptySignal`] or [`AnalysisError::NonFinite`] for a bad
/// signal, [`AnalysisError::InvalidParameter`] for a bad sample rate or a
/// speed that is zero throughout, [`AnalysisError::NumericOverflow`] for
/// speeds near the f64 limit, [`AnalysisError::NoConstantSpeedStage`] when
/// the stage found is shorter than [`MIN_STAGE_S`] (a travel cut before
/// its cruise, or one too short to have one: what such a stage would give
/// is a ramp's average, not a constant-speed figure).
pub fn constant_speed_stage(speed_radps: &[f64], sample_rate_hz: f64) -> Result<Range<usize>, AnalysisError> {
    check_sample_rate(sample_rate_hz)?;
    check_signal(speed_radps, 1, "a travel's speed signal")?;
    let window = window_samples(SMOOTHING_WINDOW_S, sample_rate_hz, speed_radps.len());
    let s = smoothed_abs(speed_radps, window);
    let stage = stage_of_smoothed(&s)?.1;
    let stage_s = stage.len() as f64 / sample_rate_hz;
    if stage_s < MIN_STAGE_S {
        return Err(AnalysisError::NoConstantSpeedStage { stage_s, min_s: MIN_STAGE_S });
    }
    Ok(stage)
}

/// All phases of a travel: standstill, acceleration, constant speed,
/// deceleration, standstill (sample index ranges into `speed_radps`).
///
/// * `speed_radps`, `sample_rate_hz`: as for [`constant_speed_stage`].
///
/// The constant-speed stage is that of [`constant_speed_stage`]. The motion
/// spans from the first to the last sample at which `|speed|`, averaged over
/// a centred 0.1 s window ([`MOTION_WINDOW_S`]), exceeds 2 % of the cruise
/// level ([`MOTION_FRACTION`]); before it is `start`, after it `stop`. For a
/// jerk-limited start from rest (jerk `J`) the motion start is found about
/// `sqrt(0.04 v_c / J)` after the true one (0.13 s on the reference rig),
/// the motion end as much before the true end. Acceleration and
/// deceleration are what lies between the motion edges and the
/// constant-speed stage, including the parts of the ramps' ends that the
/// constant-speed rule leaves out.
///
/// # Errors
/// Those of [`constant_speed_stage`].
pub fn travel_phases(speed_radps: &[f64], sample_rate_hz: f64) -> Result<TravelPhases, AnalysisError> {
    check_sample_rate(sample_rate_hz)?;
    check_signal(speed_radps, 1, "a travel's speed signal")?;
    let n = speed_radps.len();
    let window = window_samples(SMOOTHING_WINDOW_S, sample_rate_hz, n);
    let (level, constant) = stage_of_smoothed(&smoothed_abs(speed_radps, window))?;
    let motion = smoothed_abs(speed_radps, window_samples(MOTION_WINDOW_S, sample_rate_hz, n));
    let threshold = MOTION_FRACTION * level;
    let first = motion.iter().position(|&v| v > threshold).unwrap_or(constant.start).min(constant.start);
    let end = motion.iter().rposition(|&v| v > threshold).map_or(constant.end, |i| i + 1).max(constant.end);
    Ok(TravelPhases {
        start: 0..first,
        acceleration: first..constant.start,
        constant: constant.clone(),
        deceleration: constant.end..end,
        stop: end..n,
    })
}

/// The longest run of consecutive indices in `within` where `inside`
/// holds (the first one on a tie; empty when it never holds).
pub(crate) fn longest_run(within: std::ops::Range<usize>, inside: impl Fn(usize) -> bool) -> std::ops::Range<usize> {
    let (mut best, mut run_start) = (within.start..within.start, None);
    for i in within.clone() {
        match (inside(i), run_start) {
            (true, None) => run_start = Some(i),
            (false, Some(r)) => {
                if i - r > best.len() {
                    best = r..i;
                }
                run_start = None;
            }
            _ => {}
        }
    }
    if let Some(r) = run_start {
        if within.end - r > best.len() {
            best = r..within.end;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_signals::gaussian;
    use std::f64::consts::PI;

    /// Jerk-limited (S-curve) speed profile, rad/s: rest for `t_rest`, ramp
    /// up with jerk `j` to acceleration `a` and speed `v`, cruise for
    /// `t_cruise`, the mirror-image ramp down, rest for `t_rest`. Returns the
    /// samples and the true cruise interval in s.
    struct Profile {
        speed: Vec<f64>,
        cruise_s: (f64, f64),
        motion_s: (f64, f64),
    }

    fn s_curve(fs: f64, v: f64, a: f64, j: f64, t_rest: f64, t_cruise: f64) -> Profile {
        let tj = a / j;
        let ta = v / a - tj; // constant-acceleration time (>= 0 for these tests)
        assert!(ta >= 0.0);
        let t_ramp = 2.0 * tj + ta;
        // Speed on the way up, `tau` s after the start of the motion.
        let up = |tau: f64| {
            if tau <= 0.0 {
                0.0
            } else if tau < tj {
                0.5 * j * tau * tau
            } else if tau < tj + ta {
                0.5 * j * tj * tj + a * (tau - tj)
            } else if tau < t_ramp {
                let r = t_ramp - tau;
                v - 0.5 * j * r * r
            } else {
                v
            }
        };
        let t1 = t_rest + t_ramp;
        let t2 = t1 + t_cruise;
        let total = t2 + t_ramp + t_rest;
        let speed = (0..(total * fs) as usize)
            .map(|k| {
                let t = k as f64 / fs;
                if t < t2 {
                    up(t - t_rest)
                } else {
                    up(t2 + t_ramp - t)
                }
            })
            .collect();
        Profile { speed, cruise_s: (t1, t2), motion_s: (t_rest, t2 + t_ramp) }
    }

    /// Encoder speed estimate of the true speed `w` (rad/s): the angle is
    /// quantized to `counts` per revolution, differenced at `rate_hz`,
    /// low-passed (first order, `cutoff_hz`) and held between updates. Then
    /// a speed ripple at 1 Hz and 12 Hz proportional to the speed and white
    /// noise are added.
    fn measured(w: &[f64], fs: f64, ripple: (f64, f64), noise_rms: f64, seed: u64) -> Vec<f64> {
        let (counts, rate_hz, cutoff_hz) = (16384.0, 2000.0, 80.0);
        let quantum = 2.0 * PI / counts;
        let per_update = (fs / rate_hz).round() as usize;
        let alpha = 1.0 - (-2.0 * PI * cutoff_hz / rate_hz).exp();
        let v_max = w.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let noise = gaussian(w.len(), seed);
        let (mut angle, mut last_count, mut estimate) = (0.0, 0.0, 0.0);
        let mut out = Vec::with_capacity(w.len());
        for (k, &wk) in w.iter().enumerate() {
            angle += wk / fs;
            if k % per_update == 0 {
                let count = (angle / quantum).floor();
                let raw = (count - last_count) * quantum * rate_hz;
                last_count = count;
                estimate += alpha * (raw - estimate);
            }
            let t = k as f64 / fs;
            let rel = wk.abs() / v_max;
            let rip = rel * v_max * (ripple.0 * (2.0 * PI * t + 0.3).sin() + ripple.1 * (2.0 * PI * 12.0 * t).sin());
            out.push(estimate + rip + noise_rms * noise[k]);
        }
        out
    }

    /// Checks the detected stage against the true cruise interval and
    /// returns (margin at the start s, margin at the end s, coverage).
    fn check_inside(stage: &Range<usize>, fs: f64, cruise_s: (f64, f64)) -> (f64, f64, f64) {
        let start_s = stage.start as f64 / fs;
        let end_s = (stage.end - 1) as f64 / fs;
        let (t1, t2) = cruise_s;
        assert!(start_s >= t1 && end_s <= t2, "stage {start_s}..{end_s} s not inside cruise {t1}..{t2} s");
        (start_s - t1, t2 - end_s, (end_s - start_s) / (t2 - t1))
    }

    #[test]
    fn rig_travel_stage_is_inside_the_cruise_and_covers_90_percent() {
        // Reference rig: 0.4 m/s, 0.5 m/s^2, 1 m/s^3 at the 65 mm sheave,
        // 15 s cruise, recorded at 16384 Hz; up and down travels, ripple of
        // 1.5 % at 1 Hz and 1 % at 12 Hz, several noise seeds.
        let fs = 16384.0;
        let r = 0.065;
        let p = s_curve(fs, 0.4 / r, 0.5 / r, 1.0 / r, 1.0, 15.0);
        for (sign, seed) in [(1.0, 1), (-1.0, 2), (1.0, 3)] {
            let w: Vec<f64> = p.speed.iter().map(|v| sign * v).collect();
            let y = measured(&w, fs, (0.015, 0.01), 0.02, seed);
            let stage = constant_speed_stage(&y, fs).unwrap();
            let (m1, m2, coverage) = check_inside(&stage, fs, p.cruise_s);
            assert!(coverage >= 0.9, "coverage {coverage}");
            eprintln!("sign {sign} seed {seed}: margins {m1:.3} s / {m2:.3} s, coverage {coverage:.4}");
        }
    }

    #[test]
    fn short_and_gentle_travels_stay_inside_the_cruise() {
        // Shorter cruise and different dynamics: inside, and covering all
        // but about 0.5 s.
        let fs = 4096.0;
        for (v, a, j, cruise, ripple) in [
            (6.15, 7.7, 15.4, 4.0, (0.015, 0.01)),
            (6.15, 4.0, 6.0, 8.0, (0.005, 0.02)),
            (3.0, 5.0, 20.0, 3.0, (0.03, 0.01)),
        ] {
            let p = s_curve(fs, v, a, j, 2.0, cruise);
            let y = measured(&p.speed, fs, ripple, 0.01 * v, 11);
            let stage = constant_speed_stage(&y, fs).unwrap();
            let (m1, m2, coverage) = check_inside(&stage, fs, p.cruise_s);
            assert!(m1 + m2 < 0.6, "v {v} j {j}: margins {m1} + {m2} s");
            eprintln!("v {v} j {j} cruise {cruise}: margins {m1:.3} s / {m2:.3} s, coverage {coverage:.4}");
        }
    }

    #[test]
    fn a_travel_cut_before_its_cruise_or_without_one_has_no_stage() {
        let fs = 4096.0;
        let r = 0.065;
        let p = s_curve(fs, 0.4 / r, 0.5 / r, 1.0 / r, 0.3, 10.0);
        let y = measured(&p.speed, fs, (0.015, 0.01), 0.02, 7);
        // Cut at 0.49 s, in the run-up: no stage (it used to find one on the ramp).
        let cut = &y[..(0.49 * fs) as usize];
        assert!(matches!(constant_speed_stage(cut, fs), Err(AnalysisError::NoConstantSpeedStage { .. })));
        // Cut after 0.4 s of cruise: still too short.
        let cut = &y[..((p.cruise_s.0 + 0.4) * fs) as usize];
        assert!(matches!(constant_speed_stage(cut, fs), Err(AnalysisError::NoConstantSpeedStage { .. })));
        // The whole travel has one.
        assert!(constant_speed_stage(&y, fs).is_ok());
        // A travel whose ramps meet (0.2 s of cruise) has none.
        let p = s_curve(fs, 0.4 / r, 0.5 / r, 1.0 / r, 0.5, 0.2);
        let y = measured(&p.speed, fs, (0.015, 0.01), 0.02, 8);
        assert!(matches!(constant_speed_stage(&y, fs), Err(AnalysisError::NoConstantSpeedStage { .. })));
    }

    #[test]
    fn travel_phases_partition_the_record() {
        let fs = 16384.0;
        let r = 0.065;
        let p = s_curve(fs, 0.4 / r, 0.5 / r, 1.0 / r, 1.5, 10.0);
        let y = measured(&p.speed, fs, (0.015, 0.01), 0.02, 5);
        let ph = travel_phases(&y, fs).unwrap();
        assert_eq!(ph.start.start, 0);
        assert_eq!(ph.start.end, ph.acceleration.start);
        assert_eq!(ph.acceleration.end, ph.constant.start);
        assert_eq!(ph.constant.end, ph.deceleration.start);
        assert_eq!(ph.deceleration.end, ph.stop.start);
        assert_eq!(ph.stop.end, y.len());
        assert_eq!(ph.constant, constant_speed_stage(&y, fs).unwrap());
        let motion_start = ph.acceleration.start as f64 / fs;
        let motion_end = ph.deceleration.end as f64 / fs;
        eprintln!("motion {motion_start:.3}..{motion_end:.3} s, true {:?}", p.motion_s);
        assert!(motion_start >= p.motion_s.0 && motion_start - p.motion_s.0 < 0.2, "motion start {motion_start}");
        assert!(motion_end <= p.motion_s.1 && p.motion_s.1 - motion_end < 0.2, "motion end {motion_end}");
    }

    #[test]
    fn moving_average_is_centred_and_shrinks_at_the_ends() {
        let x = [1.0, -2.0, 3.0, -4.0, 5.0];
        let s = smoothed_abs(&x, 3);
        let expected = [1.5, 2.0, 3.0, 4.0, 4.5];
        for (a, b) in s.iter().zip(expected) {
            assert!((a - b).abs() < 1e-15);
        }
        assert_eq!(smoothed_abs(&x, 1), vec![1.0, 2.0, 3.0, 4.0, 5.0]);
    }

    #[test]
    fn bad_inputs_are_errors() {
        assert_eq!(constant_speed_stage(&[], 100.0), Err(AnalysisError::EmptySignal));
        assert!(matches!(
            constant_speed_stage(&[1.0, f64::NAN], 100.0),
            Err(AnalysisError::NonFinite { index: 1, .. })
        ));
        assert!(matches!(
            constant_speed_stage(&[1.0, 2.0], 0.0),
            Err(AnalysisError::InvalidParameter { name: "sample_rate_hz", .. })
        ));
        assert!(matches!(
            travel_phases(&[0.0; 100], 100.0),
            Err(AnalysisError::InvalidParameter { name: "speed_radps", .. })
        ));
        assert!(matches!(constant_speed_stage(&[1e308, 1e308], 1.0), Err(AnalysisError::NumericOverflow { .. })));
        // A constant speed is one stage over the whole record.
        assert_eq!(constant_speed_stage(&[2.0; 50], 10.0), Ok(0..50));
        // ... if it lasts long enough to be one.
        assert!(matches!(
            constant_speed_stage(&[2.0; 9], 10.0),
            Err(AnalysisError::NoConstantSpeedStage { min_s, .. }) if min_s == MIN_STAGE_S
        ));
        assert_eq!(travel_phases(&[-2.0; 50], 10.0).unwrap().constant, 0..50);
    }
}
