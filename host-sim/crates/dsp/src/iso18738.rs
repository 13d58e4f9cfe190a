//! Lift ride quality of all axes after ISO 18738-1: the report an analyzer
//! (EVA-625 and its kind) prints for one run.
//!
//! [`ride_report`] takes the car's accelerations (vertical z, horizontal x
//! and y, m/s^2) and, when recorded, the A-weighted sound level (dB(A)),
//! with the run's regions ([`super::ride_regions`]), and reports in mg:
//!
//! * **Vibration** per axis, whole run and constant-speed region: the
//!   maximum and A95 peak-to-peak of the weighted acceleration, z weighted
//!   with ISO 2631-1 Wk, x and y with Wd (band limiting included:
//!   [`super::iso2631`]). Peak-to-peak values, half-cycles and the
//!   nearest-rank A95 are those of [`super::ride_quality`] (its module
//!   documentation gives the definitions); the weighting runs over the whole
//!   record, so a region is evaluated with the filter's full history.
//! * **Motion**, from the vertical acceleration low-passed at 10 Hz
//!   ([`super::ride_quality::ACCELERATION_LOWPASS_HZ`]): the maximum
//!   acceleration is its largest magnitude in the acceleration region, the
//!   maximum deceleration its largest magnitude in the deceleration region
//!   (so no travel direction is needed: a file that records none gets
//!   none), the maximum jerk the largest magnitude of the 0.5 s
//!   least-squares slope over the whole run; the largest velocity and the
//!   distance travelled from the integrated acceleration
//!   ([`super::ride_regions::velocity_from_acceleration`]), the offset
//!   taken off the acceleration being the one that integration takes off.
//! * **Sound**, when recorded, whole run and constant-speed region: the
//!   largest sample level and the A95 level (nearest rank, as for the
//!   vibration: the `ceil(0.95 N)`-th of the `N` sorted sample levels), in
//!   dB(A). The levels are taken as the analyzer recorded them (already
//!   A-weighted and time-weighted by its sound level meter).
//!
//! The ISO 18738-1 text was not available to this project: the quantities
//! above follow the summary of the standard the project's work item gives
//! (vibration on three axes with Wk and Wd, max and A95 peak-to-peak, whole
//! run and constant-speed region; acceleration, deceleration, jerk; A95 and
//! max sound); the constant-speed bound is stated in
//! [`super::ride_regions`].

use std::ops::Range;

use super::iso2631::{check_wk_sample_rate, weighting, Weighting};
use super::ride_quality::{
    a95_nearest_rank, half_cycle_peaks_indexed, jerk_window_len, lowpass_acceleration, sliding_slopes, MPS2_PER_MG,
};
use super::ride_regions::{motion_offset, smoothed_speed, velocity_from_acceleration, RideRegions};
use super::{check_signal, AnalysisError};

/// An axis of the car: z vertical, x and y horizontal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Axis {
    /// Horizontal, front to back (ISO 18738-1 x).
    X,
    /// Horizontal, side to side (ISO 18738-1 y).
    Y,
    /// Vertical (ISO 18738-1 z).
    Z,
}

impl Axis {
    /// `X`, `Y` or `Z`.
    pub fn name(self) -> &'static str {
        match self {
            Axis::X => "X",
            Axis::Y => "Y",
            Axis::Z => "Z",
        }
    }

    /// The ISO 2631-1 weighting of the axis: Wk for z, Wd for x and y.
    pub fn weighting(self) -> Weighting {
        match self {
            Axis::Z => Weighting::Wk,
            Axis::X | Axis::Y => Weighting::Wd,
        }
    }
}

/// The signals of one run, all sampled at `sample_rate_hz` and of the same
/// length.
#[derive(Debug, Clone, Copy)]
pub struct RideInput<'a> {
    /// Sample rate, Hz (finite, at least 50 Hz).
    pub sample_rate_hz: f64,
    /// Vertical acceleration, m/s^2 (positive up; a constant offset such as
    /// a sensor bias does not change the vibration, and the motion figures
    /// take it off: [`super::ride_regions::motion_offset`]).
    pub z_mps2: &'a [f64],
    /// Horizontal acceleration x, m/s^2, if recorded.
    pub x_mps2: Option<&'a [f64]>,
    /// Horizontal acceleration y, m/s^2, if recorded.
    pub y_mps2: Option<&'a [f64]>,
    /// A-weighted sound level, dB(A), if recorded.
    pub sound_dba: Option<&'a [f64]>,
    /// Vertical speed of the car as the drive records it (shaft speed times
    /// sheave radius), m/s, positive up, if recorded. When given, the
    /// motion figures (velocity, distance, acceleration and deceleration)
    /// come from it: accelerometers that do not measure DC (piezoelectric,
    /// the measurement format's) cannot give them by integration.
    pub speed_mps: Option<&'a [f64]>,
}

/// Vibration of one axis over one region.
#[derive(Debug, Clone, PartialEq)]
pub struct AxisFigures {
    /// The axis.
    pub axis: Axis,
    /// Largest peak-to-peak value of the weighted acceleration, mg.
    pub max_peak_to_peak_mg: f64,
    /// Sample index of the later peak of the largest pair (0 without one).
    pub max_at: usize,
    /// Nearest-rank 95th percentile of the peak-to-peak values, mg.
    pub a95_peak_to_peak_mg: f64,
    /// Number of peak-to-peak values (dimensionless).
    pub peak_to_peak_count: usize,
}

/// Sound level over one region.
#[derive(Debug, Clone, PartialEq)]
pub struct SoundFigures {
    /// Largest sample level, dB(A).
    pub max_dba: f64,
    /// Sample index of the largest level.
    pub max_at: usize,
    /// Nearest-rank 95th percentile of the sample levels, dB(A).
    pub a95_dba: f64,
}

/// The figures of one region.
#[derive(Debug, Clone, PartialEq)]
pub struct RegionFigures {
    /// Evaluated samples.
    pub region: Range<usize>,
    /// Vibration of each recorded axis, in the order X, Y, Z.
    pub axes: Vec<AxisFigures>,
    /// Sound, if recorded.
    pub sound: Option<SoundFigures>,
}

/// Motion figures of a run with regions.
#[derive(Debug, Clone, PartialEq)]
pub struct MotionFigures {
    /// Largest magnitude of the 10 Hz low-passed vertical acceleration in
    /// the acceleration region, mg.
    pub max_acceleration_mg: f64,
    /// Largest magnitude of it in the deceleration region, mg.
    pub max_deceleration_mg: f64,
    /// Largest magnitude of the vertical velocity averaged over 0.25 s
    /// ([`super::ride_regions::smoothed_speed`]), m/s.
    pub max_velocity_mps: f64,
    /// Distance travelled: the magnitude of the displacement (integral of
    /// the velocity; a lift run goes one way), m.
    pub distance_m: f64,
    /// Where the velocity came from.
    pub source: MotionSource,
}

/// The signal the motion figures were computed from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MotionSource {
    /// The recorded speed ([`RideInput::speed_mps`]): velocity as recorded,
    /// acceleration its derivative low-passed like the acceleration.
    RecordedSpeed,
    /// The vertical acceleration, its offset over the standstills removed,
    /// integrated over the motion.
    IntegratedAcceleration,
}

impl MotionSource {
    /// A short description for reports.
    pub fn describe(self) -> &'static str {
        match self {
            MotionSource::RecordedSpeed => "recorded speed (acceleration: its derivative, 10 Hz low-pass)",
            MotionSource::IntegratedAcceleration => {
                "integrated vertical acceleration (offset of the standstills removed)"
            }
        }
    }
}

/// Result of [`ride_report`].
#[derive(Debug, Clone, PartialEq)]
pub struct RideReport {
    /// Sample rate, Hz.
    pub sample_rate_hz: f64,
    /// Figures over the whole record.
    pub whole_run: RegionFigures,
    /// Figures over the constant-speed region, if the regions have one.
    pub constant_speed: Option<RegionFigures>,
    /// Acceleration, deceleration, velocity and distance, when regions were
    /// given.
    pub motion: Option<MotionFigures>,
    /// Largest magnitude of the jerk over the whole run (0.5 s least-squares
    /// slope of the 10 Hz low-passed vertical acceleration), m/s^3.
    pub max_jerk_mps3: f64,
    /// The weighted accelerations, m/s^2, per recorded axis (X, Y, Z order).
    pub weighted_mps2: Vec<(Axis, Vec<f64>)>,
    /// The vertical velocity, m/s (zero outside the motion), when regions
    /// were given.
    pub velocity_mps: Option<Vec<f64>>,
}

/// Checks the signals of `input` (lengths, finiteness, sample rate).
fn check_input(input: &RideInput<'_>) -> Result<(), AnalysisError> {
    check_wk_sample_rate(input.sample_rate_hz)?;
    let window = jerk_window_len(input.sample_rate_hz);
    check_signal(input.z_mps2, window, "ride quality (one 0.5 s jerk fit window)")?;
    let n = input.z_mps2.len();
    for (name, signal) in [
        ("x_mps2", input.x_mps2),
        ("y_mps2", input.y_mps2),
        ("sound_dba", input.sound_dba),
        ("speed_mps", input.speed_mps),
    ] {
        if let Some(s) = signal {
            if s.len() != n {
                return Err(AnalysisError::InvalidParameter {
                    name,
                    value: s.len() as f64,
                    expected: "as many samples as the vertical acceleration z_mps2",
                });
            }
            check_signal(s, 1, "ride quality")?;
        }
    }
    Ok(())
}

/// Checks that `regions` lie inside `n` samples.
fn check_regions(regions: &RideRegions, n: usize) -> Result<(), AnalysisError> {
    if regions.stop.end != n || regions.motion().start > regions.motion().end {
        return Err(AnalysisError::InvalidParameter {
            name: "regions",
            value: regions.stop.end as f64,
            expected: "regions of this signal: contiguous ranges ending at its last sample",
        });
    }
    Ok(())
}

/// Vibration figures of `weighted` (m/s^2) over `region`.
fn axis_figures(axis: Axis, weighted: &[f64], region: &Range<usize>) -> AxisFigures {
    let peaks = half_cycle_peaks_indexed(&weighted[region.clone()]);
    let pairs: Vec<(usize, f64)> =
        peaks.windows(2).map(|p| (region.start + p[1].0, (p[0].1 - p[1].1).abs() / MPS2_PER_MG)).collect();
    let Some(&(max_at, max)) = pairs.iter().max_by(|a, b| a.1.total_cmp(&b.1)) else {
        return AxisFigures {
            axis,
            max_peak_to_peak_mg: 0.0,
            max_at: 0,
            a95_peak_to_peak_mg: 0.0,
            peak_to_peak_count: 0,
        };
    };
    let mut values: Vec<f64> = pairs.iter().map(|p| p.1).collect();
    values.sort_by(f64::total_cmp);
    AxisFigures {
        axis,
        max_peak_to_peak_mg: max,
        max_at,
        a95_peak_to_peak_mg: a95_nearest_rank(&values),
        peak_to_peak_count: values.len(),
    }
}

/// Sound figures of the levels `sound` (dB(A)) over `region` (non-empty).
fn sound_figures(sound: &[f64], region: &Range<usize>) -> SoundFigures {
    let slice = &sound[region.clone()];
    let (i, max) = slice.iter().enumerate().fold((0, f64::NEG_INFINITY), |m, (i, &v)| if v > m.1 { (i, v) } else { m });
    let mut sorted = slice.to_vec();
    sorted.sort_by(f64::total_cmp);
    SoundFigures { max_dba: max, max_at: region.start + i, a95_dba: a95_nearest_rank(&sorted) }
}

/// The figures of `region` from the weighted signals and the sound.
fn region_figures(weighted: &[(Axis, Vec<f64>)], sound: Option<&[f64]>, region: Range<usize>) -> RegionFigures {
    RegionFigures {
        axes: weighted.iter().map(|(axis, w)| axis_figures(*axis, w, &region)).collect(),
        sound: sound.map(|s| sound_figures(s, &region)),
        region,
    }
}

/// Largest magnitude of `x` over `range` (0 for an empty range).
fn max_abs(x: &[f64], range: Range<usize>) -> f64 {
    x[range].iter().fold(0.0, |m, v| m.max(v.abs()))
}

/// The ride-quality report of one run after ISO 18738-1 (see the module
/// documentation).
///
/// * `input`: the signals (z required; x, y, sound when recorded), at least
///   one 0.5 s jerk window long.
/// * `regions`: the run's regions ([`super::ride_regions`]); `None` gives the
///   whole run only, without motion figures.
///
/// # Errors
/// [`AnalysisError::EmptySignal`], [`AnalysisError::NonFinite`],
/// [`AnalysisError::TooShort`] for a bad signal,
/// [`AnalysisError::InvalidParameter`] for a bad sample rate, signals of
/// different lengths or regions of another signal,
/// [`AnalysisError::NumericOverflow`] for signals near the f64 limit.
pub fn ride_report(input: &RideInput<'_>, regions: Option<&RideRegions>) -> Result<RideReport, AnalysisError> {
    check_input(input)?;
    let (fs, n) = (input.sample_rate_hz, input.z_mps2.len());
    if let Some(r) = regions {
        check_regions(r, n)?;
    }
    let axes = [(Axis::X, input.x_mps2), (Axis::Y, input.y_mps2), (Axis::Z, Some(input.z_mps2))];
    let weighted = axes
        .iter()
        .filter_map(|(axis, s)| s.map(|s| weighting(axis.weighting(), s, fs).map(|w| (*axis, w))))
        .collect::<Result<Vec<_>, _>>()?;
    let lowpassed = lowpass_acceleration(input.z_mps2, fs);
    let slopes = sliding_slopes(&lowpassed, jerk_window_len(fs));
    let max_jerk_mps3 = slopes.iter().fold(0.0_f64, |m, s| m.max(s.abs())) * fs;
    let velocity = regions.map(|r| match input.speed_mps {
        Some(speed) => speed.to_vec(),
        None => velocity_from_acceleration(input.z_mps2, fs, r.motion()),
    });
    let motion = regions.zip(velocity.as_ref()).map(|(r, v)| {
        let (level, source) = match input.speed_mps {
            Some(speed) => {
                (lowpass_acceleration(&crate::central_difference(speed, fs), fs), MotionSource::RecordedSpeed)
            }
            None => {
                let offset = motion_offset(input.z_mps2, fs, r.motion());
                (lowpassed.iter().map(|v| v - offset).collect(), MotionSource::IntegratedAcceleration)
            }
        };
        MotionFigures {
            max_acceleration_mg: max_abs(&level, r.acceleration.clone()) / MPS2_PER_MG,
            max_deceleration_mg: max_abs(&level, r.deceleration.clone()) / MPS2_PER_MG,
            max_velocity_mps: max_abs(&smoothed_speed(v, fs), 0..n),
            distance_m: (v.iter().sum::<f64>() / fs).abs(),
            source,
        }
    });
    let report = RideReport {
        sample_rate_hz: fs,
        whole_run: region_figures(&weighted, input.sound_dba, 0..n),
        constant_speed: regions
            .and_then(|r| r.constant_speed.clone())
            .map(|c| region_figures(&weighted, input.sound_dba, c)),
        motion,
        max_jerk_mps3,
        weighted_mps2: weighted,
        velocity_mps: velocity,
    };
    check_finite(&report)?;
    Ok(report)
}

/// [`AnalysisError::NumericOverflow`] when a figure of `report` is not
/// finite.
fn check_finite(report: &RideReport) -> Result<(), AnalysisError> {
    let mut values = vec![report.max_jerk_mps3];
    for r in std::iter::once(&report.whole_run).chain(report.constant_speed.as_ref()) {
        values.extend(r.axes.iter().flat_map(|a| [a.max_peak_to_peak_mg, a.a95_peak_to_peak_mg]));
    }
    if let Some(m) = &report.motion {
        values.extend([m.max_acceleration_mg, m.max_deceleration_mg, m.max_velocity_mps, m.distance_m]);
    }
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(AnalysisError::NumericOverflow { what: "ride-quality figures" })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::iso2631::{wd_gain, wk_gain};
    use crate::ride_regions::regions_from_acceleration;
    use std::f64::consts::PI;

    fn sine(n: usize, fs: f64, f: f64, amp: f64) -> Vec<f64> {
        (0..n).map(|k| amp * (2.0 * PI * f * k as f64 / fs).sin()).collect()
    }

    #[test]
    fn each_axis_is_weighted_with_its_weighting() {
        // The same 10 mg, 2 Hz sine on all axes: at 2 Hz ISO 2631-1 Table 3
        // gives Wd = 0.890 and Wk = 0.531, so the settled peak-to-peak is
        // 2 * 10 mg * factor (within the crest sampling, 1 - cos(pi/128)).
        let fs = 256.0;
        let n = (30.0 * fs) as usize;
        let s = sine(n, fs, 2.0, 10.0 * MPS2_PER_MG);
        let input = RideInput {
            sample_rate_hz: fs,
            z_mps2: &s,
            x_mps2: Some(&s),
            y_mps2: Some(&s),
            sound_dba: None,
            speed_mps: None,
        };
        let report = ride_report(&input, None).unwrap();
        assert!(report.motion.is_none() && report.constant_speed.is_none());
        let axes = &report.whole_run.axes;
        assert_eq!(axes.iter().map(|a| a.axis).collect::<Vec<_>>(), vec![Axis::X, Axis::Y, Axis::Z]);
        for a in axes {
            let table = if a.axis == Axis::Z { 0.531 } else { 0.890 };
            let analog = if a.axis == Axis::Z { wk_gain(2.0) } else { wd_gain(2.0) };
            assert!((analog / table - 1.0).abs() < 0.002);
            // A95 over the whole run: the start transient is a small share.
            assert!((a.a95_peak_to_peak_mg / (20.0 * table) - 1.0).abs() < 0.01, "{a:?}");
        }
    }

    #[test]
    fn sound_max_and_a95_follow_the_nearest_rank() {
        // Levels 1..=200 dB(A) in a shuffled order (a 256 Hz record of 200
        // samples plus padding at 30 dB): A95 over the 200 is the 190th, 190.
        let fs = 256.0;
        let n = 1000;
        let mut sound = vec![30.0; n];
        for k in 0..200 {
            sound[100 + (k * 37) % 200] = (k + 1) as f64;
        }
        let z = vec![0.0; n];
        let input = RideInput {
            sample_rate_hz: fs,
            z_mps2: &z,
            x_mps2: None,
            y_mps2: None,
            sound_dba: Some(&sound),
            speed_mps: None,
        };
        let report = ride_report(&input, None).unwrap();
        let s = report.whole_run.sound.unwrap();
        assert_eq!(s.max_dba, 200.0);
        assert_eq!(sound[s.max_at], 200.0);
        // All 1000: 800 samples at 30 and 1..=200; rank 950 -> the 950th
        // sorted value: 29 values below 30, then 800 + 1 at 30 (the level
        // 30 itself), so ranks 30..=830 are 30 and rank 950 is 150.
        assert_eq!(s.a95_dba, 150.0);
    }

    #[test]
    fn motion_figures_of_a_run_from_its_acceleration() {
        // 1 m/s, 0.8 m/s^2, 1 m/s^3 run with 2 s rest: plateaus of
        // 0.8 m/s^2 = 81.6 mg; distance v (t_ramp + t_cruise) for a
        // symmetric S-curve.
        let fs = 256.0;
        let (v, a, j) = (1.0, 0.8, 1.0);
        let (tj, ta) = (a / j, v / a - a / j);
        let ramp = 2.0 * tj + ta;
        let (rest, cruise) = (2.0, 4.0);
        let acc_at = |tau: f64| {
            if tau <= 0.0 || tau >= ramp {
                0.0
            } else if tau < tj {
                j * tau
            } else if tau < tj + ta {
                a
            } else {
                j * (ramp - tau)
            }
        };
        let total = 2.0 * (rest + ramp) + cruise;
        let z: Vec<f64> = (0..(total * fs) as usize)
            .map(|k| {
                let t = k as f64 / fs;
                // A 4 mg sensor offset, which the figures take off.
                acc_at(t - rest) - acc_at(t - rest - ramp - cruise) + 4.0 * MPS2_PER_MG
            })
            .collect();
        let (regions, _) = regions_from_acceleration(&z, fs).unwrap();
        let input =
            RideInput { sample_rate_hz: fs, z_mps2: &z, x_mps2: None, y_mps2: None, sound_dba: None, speed_mps: None };
        let report = ride_report(&input, Some(&regions)).unwrap();
        let m = report.motion.unwrap();
        let plateau_mg = a / MPS2_PER_MG;
        assert!((m.max_acceleration_mg / plateau_mg - 1.0).abs() < 0.002, "{m:?}");
        assert!((m.max_deceleration_mg / plateau_mg - 1.0).abs() < 0.002, "{m:?}");
        assert!((m.max_velocity_mps - v).abs() < 0.005, "{m:?}");
        // Distance of the S-curve: v * (ramp + cruise).
        let distance = v * (ramp + cruise);
        assert!((m.distance_m / distance - 1.0).abs() < 0.005, "{} vs {distance}", m.distance_m);
        // Jerk 1 m/s^3 on linear ramps of 0.8 s (longer than the 0.5 s fit).
        assert!((report.max_jerk_mps3 - j).abs() < 0.01, "{}", report.max_jerk_mps3);
        assert!(report.constant_speed.is_some());
        assert_eq!(m.source, MotionSource::IntegratedAcceleration);

        // The same run through an AC-coupled accelerometer (2nd-order 1 Hz
        // high-pass, no DC), with the drive's speed recorded: the motion
        // figures come from the speed and stay right; integrating the
        // high-passed acceleration would not.
        let mut z_ac: Vec<f64> = z.iter().map(|x| x - 4.0 * MPS2_PER_MG).collect();
        crate::biquad::Biquad::butterworth_highpass(fs, 1.0).filter_in_place(&mut z_ac, [0.0; 2]);
        let speed: Vec<f64> = z
            .iter()
            .scan(0.0, |v, x| {
                *v += (x - 4.0 * MPS2_PER_MG) / fs;
                Some(*v)
            })
            .collect();
        let integrated = ride_report(&RideInput { z_mps2: &z_ac, speed_mps: None, ..input }, Some(&regions))
            .unwrap()
            .motion
            .unwrap();
        assert!((integrated.distance_m / distance - 1.0).abs() > 0.2, "{integrated:?}");
        let from_speed = ride_report(&RideInput { z_mps2: &z_ac, speed_mps: Some(&speed), ..input }, Some(&regions))
            .unwrap()
            .motion
            .unwrap();
        assert_eq!(from_speed.source, MotionSource::RecordedSpeed);
        assert!((from_speed.max_velocity_mps - v).abs() < 0.005, "{from_speed:?}");
        assert!((from_speed.distance_m / distance - 1.0).abs() < 0.005, "{from_speed:?}");
        assert!((from_speed.max_acceleration_mg / plateau_mg - 1.0).abs() < 0.01, "{from_speed:?}");
        assert!((from_speed.max_deceleration_mg / plateau_mg - 1.0).abs() < 0.01, "{from_speed:?}");
    }

    #[test]
    fn bad_inputs_are_errors() {
        let z = vec![0.0; 1000];
        let short = vec![0.0; 999];
        let input = RideInput {
            sample_rate_hz: 256.0,
            z_mps2: &z,
            x_mps2: Some(&short),
            y_mps2: None,
            sound_dba: None,
            speed_mps: None,
        };
        match ride_report(&input, None) {
            Err(AnalysisError::InvalidParameter { name, .. }) => assert_eq!(name, "x_mps2"),
            other => panic!("{other:?}"),
        }
        let mut nan = z.clone();
        nan[3] = f64::NAN;
        let input = RideInput {
            sample_rate_hz: 256.0,
            z_mps2: &z,
            x_mps2: None,
            y_mps2: None,
            sound_dba: Some(&nan),
            speed_mps: None,
        };
        assert!(matches!(ride_report(&input, None), Err(AnalysisError::NonFinite { index: 3, .. })));
        let input = RideInput {
            sample_rate_hz: 10.0,
            z_mps2: &z,
            x_mps2: None,
            y_mps2: None,
            sound_dba: None,
            speed_mps: None,
        };
        assert!(ride_report(&input, None).is_err());
    }
}
