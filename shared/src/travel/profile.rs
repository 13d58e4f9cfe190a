//! Jerk-limited S-curve travel profile (paper Fig. 3: acceleration,
//! constant-velocity and deceleration stages).
//!
//! Seven phases with jerk `+j, 0, -j, 0, -j, 0, +j`. The plan is computed
//! once per travel; [`SCurve::at`] evaluates it in closed form at any time,
//! so nothing accumulates. Only `f32` add/sub/mul/div are used (bit-identical
//! on the host and the Cortex-M4F); square roots are Newton iterations.

/// Position, speed and acceleration of the reference at one instant (car
/// travel coordinate, positive in the travel direction): m, m/s, m/s^2.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ProfilePoint {
    /// Travelled distance, m.
    pub position_m: f32,
    /// Speed, m/s.
    pub speed_mps: f32,
    /// Acceleration, m/s^2.
    pub accel_mps2: f32,
}

/// Why a profile cannot be planned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProfileError {
    /// Distance, speed, acceleration or jerk not positive and finite.
    NonPositiveLimit,
}

/// A planned S-curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SCurve {
    jerk_mps3: f32,
    /// Start time (s) and state at the start of each of the 7 phases, plus the end.
    starts: [(f32, ProfilePoint); 8],
    jerks: [f32; 7],
    distance_m: f32,
}

/// sqrt by Newton iterations from a power-of-two first guess (x >= 0), f32.
pub fn sqrt_newton(x: f32) -> f32 {
    if x <= 0.0 || x.is_nan() {
        return 0.0;
    }
    let mut guess = 1.0f32;
    while guess * guess < x {
        guess *= 2.0;
    }
    while guess * guess > 4.0 * x {
        guess *= 0.5;
    }
    for _ in 0..8 {
        guess = 0.5 * (guess + x / guess);
    }
    guess
}

/// Peak acceleration and distance of a jerk-limited run-up to `v` and back to 0.
fn run_up(v: f32, a_max: f32, j: f32) -> (f32, f32) {
    let a_peak = if v * j < a_max * a_max { sqrt_newton(v * j) } else { a_max };
    // Accelerating part lasts a/j + v/a at mean speed v/2; twice that to stop.
    let distance = v * (v / a_peak + a_peak / j);
    (a_peak, distance)
}

impl SCurve {
    /// Plans a travel of `distance_m` (> 0) with speed, acceleration and jerk
    /// limits (m/s, m/s^2, m/s^3). Short travels lower the peak speed.
    pub fn plan(distance_m: f32, v_max: f32, a_max: f32, j_max: f32) -> Result<Self, ProfileError> {
        let valid = |x: f32| x > 0.0 && x.is_finite();
        if !(valid(distance_m) && valid(v_max) && valid(a_max) && valid(j_max)) {
            return Err(ProfileError::NonPositiveLimit);
        }
        let mut v_peak = v_max;
        if run_up(v_max, a_max, j_max).1 > distance_m {
            // Bisection on the peak speed: run-up distance grows with speed.
            let (mut lo, mut hi) = (0.0f32, v_max);
            for _ in 0..48 {
                let mid = 0.5 * (lo + hi);
                if run_up(mid, a_max, j_max).1 > distance_m {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            v_peak = lo;
        }
        let (a_peak, run_up_distance) = run_up(v_peak, a_max, j_max);
        let t_jerk = a_peak / j_max;
        let t_accel = (v_peak / a_peak - t_jerk).max(0.0);
        let t_cruise = ((distance_m - run_up_distance) / v_peak).max(0.0);
        let durations = [t_jerk, t_accel, t_jerk, t_cruise, t_jerk, t_accel, t_jerk];
        let jerks = [j_max, 0.0, -j_max, 0.0, -j_max, 0.0, j_max];
        let mut starts = [(0.0f32, ProfilePoint::default()); 8];
        for phase in 0..7 {
            let (t0, p0) = starts[phase];
            starts[phase + 1] = (t0 + durations[phase], evolve(p0, jerks[phase], durations[phase]));
        }
        Ok(Self { jerk_mps3: j_max, starts, jerks, distance_m })
    }

    /// Duration of the travel, s.
    pub fn duration_s(&self) -> f32 {
        self.starts[7].0
    }

    /// Travel distance, m.
    pub fn distance_m(&self) -> f32 {
        self.distance_m
    }

    /// Jerk limit the profile was planned with, m/s^3.
    pub fn jerk_mps3(&self) -> f32 {
        self.jerk_mps3
    }

    /// The reference at `t_s` seconds after the start; before 0 at rest, after
    /// the end at rest at the travel distance.
    pub fn at(&self, t_s: f32) -> ProfilePoint {
        if t_s <= 0.0 {
            return ProfilePoint::default();
        }
        if t_s >= self.duration_s() {
            return ProfilePoint { position_m: self.distance_m, speed_mps: 0.0, accel_mps2: 0.0 };
        }
        let mut phase = 6;
        while self.starts[phase].0 > t_s {
            phase -= 1;
        }
        let (t0, p0) = self.starts[phase];
        evolve(p0, self.jerks[phase], t_s - t0)
    }
}

/// A jerk-limited change of speed (the speed-mode travels): from a point
/// with speed `v0` (m/s) and acceleration `a0` (m/s^2) to a constant speed
/// `v1` (m/s, >= 0). First the acceleration is brought to zero with the jerk
/// limit (the speed keeps changing by `a0 |a0| / 2j`), then the speed goes to
/// `v1` with jerk `+-j`, acceleration up to `a_max` and `-+j` (four phases,
/// some of zero length); after the ramp the reference cruises at `v1`.
/// Positions count from the ramp's start point. Closed form like [`SCurve`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpeedRamp {
    /// Start time (s) and state at the start of each of the 4 phases, plus the end.
    starts: [(f32, ProfilePoint); 5],
    jerks: [f32; 4],
}

impl SpeedRamp {
    /// Plans the change from `from` (position, m; speed, m/s; acceleration,
    /// m/s^2) to speed `v1` (m/s, >= 0) with acceleration and jerk limits
    /// `a_max` (m/s^2) and `j_max` (m/s^3).
    pub fn plan(from: ProfilePoint, v1: f32, a_max: f32, j_max: f32) -> Result<Self, ProfileError> {
        let valid = |x: f32| x > 0.0 && x.is_finite();
        let finite = from.position_m.is_finite() && from.speed_mps.is_finite() && from.accel_mps2.is_finite();
        if !(valid(a_max) && valid(j_max) && finite && v1 >= 0.0 && v1.is_finite()) {
            return Err(ProfileError::NonPositiveLimit);
        }
        // Phase 0: acceleration to zero.
        let a0 = from.accel_mps2;
        let (j0, t0) = if a0 > 0.0 {
            (-j_max, a0 / j_max)
        } else if a0 < 0.0 {
            (j_max, -a0 / j_max)
        } else {
            (0.0, 0.0)
        };
        let level = evolve(from, j0, t0);
        // Phases 1-3: the speed change.
        let dv = v1 - level.speed_mps;
        let (sign, magnitude) = if dv < 0.0 { (-1.0f32, -dv) } else { (1.0f32, dv) };
        let (a_peak, t_const) = if magnitude * j_max < a_max * a_max {
            (sqrt_newton(magnitude * j_max), 0.0)
        } else {
            (a_max, magnitude / a_max - a_max / j_max)
        };
        let t_jerk = a_peak / j_max;
        let durations = [t0, t_jerk, t_const.max(0.0), t_jerk];
        let jerks = [j0, sign * j_max, 0.0, -sign * j_max];
        let mut starts = [(0.0f32, from); 5];
        for phase in 0..4 {
            let (t, p) = starts[phase];
            starts[phase + 1] = (t + durations[phase], evolve(p, jerks[phase], durations[phase]));
        }
        // The end is at `v1` with no acceleration: pin it against rounding.
        starts[4].1.speed_mps = v1;
        starts[4].1.accel_mps2 = 0.0;
        Ok(Self { starts, jerks })
    }

    /// Duration of the change, s.
    pub fn duration_s(&self) -> f32 {
        self.starts[4].0
    }

    /// The point where the change ends (speed `v1`, no acceleration).
    pub fn end(&self) -> ProfilePoint {
        self.starts[4].1
    }

    /// The reference at `t_s` seconds after the start: the start point
    /// before 0, cruising at the final speed after the end.
    pub fn at(&self, t_s: f32) -> ProfilePoint {
        if t_s <= 0.0 {
            return self.starts[0].1;
        }
        let (t_end, end) = self.starts[4];
        if t_s >= t_end {
            return ProfilePoint {
                position_m: end.position_m + end.speed_mps * (t_s - t_end),
                speed_mps: end.speed_mps,
                accel_mps2: 0.0,
            };
        }
        let mut phase = 3;
        while self.starts[phase].0 > t_s {
            phase -= 1;
        }
        let (t0, p0) = self.starts[phase];
        evolve(p0, self.jerks[phase], t_s - t0)
    }
}

/// Why an [`Approach`] cannot be planned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ApproachError {
    /// A limit is not positive and finite, or the start point or the target is not finite.
    NonPositiveLimit,
    /// The target lies closer than the shortest jerk-limited stop from the
    /// start point: the car would pass it.
    CannotStop,
}

/// A jerk-limited way to rest at a new target from a point of a running
/// reference (a distance travel whose remaining distance changed): a
/// [`SpeedRamp`] from the point to a cruise speed, the cruise, and a
/// [`SpeedRamp`] from that speed to rest, ending at the target. The cruise
/// speed is the highest within the speed limit whose two ramps fit in the
/// distance, so a longer distance is run at speed and a shorter one is
/// approached more slowly; a target closer than the shortest stop from the
/// point is refused. Positions count from the start of the travel (the
/// point's own coordinate). Closed form like [`SCurve`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Approach {
    first: SpeedRamp,
    cruise_s: f32,
    last: SpeedRamp,
    target_m: f32,
}

impl Approach {
    /// Largest distance by which the target may lie inside the shortest
    /// stop and still be taken (the stop then ends there), m: 0.1 mm, the
    /// rounding of the planning.
    pub const SLACK_M: f32 = 1.0e-4;

    /// Plans from `from` (position, m; speed, m/s, >= 0 in the travel
    /// direction; acceleration, m/s^2) to rest at `target_m` (m, same
    /// coordinate) with speed, acceleration and jerk limits `v_max` (m/s),
    /// `a_max` (m/s^2) and `j_max` (m/s^3).
    pub fn plan(from: ProfilePoint, target_m: f32, v_max: f32, a_max: f32, j_max: f32) -> Result<Self, ApproachError> {
        let valid = |x: f32| x > 0.0 && x.is_finite();
        if !(valid(v_max) && valid(a_max) && valid(j_max) && target_m.is_finite()) {
            return Err(ApproachError::NonPositiveLimit);
        }
        // The two ramps through cruise speed `v` (no cruise between them).
        let ramps = |v: f32| -> Result<(SpeedRamp, SpeedRamp), ApproachError> {
            let first = SpeedRamp::plan(from, v, a_max, j_max).map_err(|_| ApproachError::NonPositiveLimit)?;
            let last = SpeedRamp::plan(first.end(), 0.0, a_max, j_max).map_err(|_| ApproachError::NonPositiveLimit)?;
            Ok((first, last))
        };
        let (stop, rest) = ramps(0.0)?;
        if rest.end().position_m > target_m + Self::SLACK_M {
            return Err(ApproachError::CannotStop);
        }
        // Bisection on the cruise speed: the two ramps' distance grows with it.
        let (mut lo, mut hi) = (0.0f32, v_max.max(from.speed_mps));
        if ramps(hi)?.1.end().position_m <= target_m {
            lo = hi;
        } else {
            for _ in 0..40 {
                let mid = 0.5 * (lo + hi);
                if ramps(mid)?.1.end().position_m <= target_m {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
        }
        if lo <= 0.0 {
            // Only the shortest stop fits: it ends within the slack of the target.
            return Ok(Self { first: stop, cruise_s: 0.0, last: rest, target_m });
        }
        let (first, last_guess) = ramps(lo)?;
        let cruise_s = ((target_m - last_guess.end().position_m) / lo).max(0.0);
        let cruise_end =
            ProfilePoint { position_m: first.end().position_m + lo * cruise_s, speed_mps: lo, accel_mps2: 0.0 };
        let last = SpeedRamp::plan(cruise_end, 0.0, a_max, j_max).map_err(|_| ApproachError::NonPositiveLimit)?;
        Ok(Self { first, cruise_s, last, target_m })
    }

    /// Duration from the start point to rest, s.
    pub fn duration_s(&self) -> f32 {
        self.first.duration_s() + self.cruise_s + self.last.duration_s()
    }

    /// The target, m.
    pub fn target_m(&self) -> f32 {
        self.target_m
    }

    /// The cruise speed, m/s (0: the shortest stop).
    pub fn cruise_speed_mps(&self) -> f32 {
        self.first.end().speed_mps
    }

    /// The reference at `t_s` seconds after the start point; at rest at the
    /// end of the last ramp afterwards.
    pub fn at(&self, t_s: f32) -> ProfilePoint {
        let cruise_end = self.first.duration_s() + self.cruise_s;
        if t_s < cruise_end {
            self.first.at(t_s)
        } else {
            let p = self.last.at(t_s - cruise_end);
            if t_s - cruise_end >= self.last.duration_s() {
                ProfilePoint { position_m: self.last.end().position_m, speed_mps: 0.0, accel_mps2: 0.0 }
            } else {
                p
            }
        }
    }
}

/// State after `dt` seconds of constant jerk `j` from `p`.
fn evolve(p: ProfilePoint, j: f32, dt: f32) -> ProfilePoint {
    ProfilePoint {
        position_m: p.position_m + p.speed_mps * dt + p.accel_mps2 * dt * dt / 2.0 + j * dt * dt * dt / 6.0,
        speed_mps: p.speed_mps + p.accel_mps2 * dt + j * dt * dt / 2.0,
        accel_mps2: p.accel_mps2 + j * dt,
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    fn check_limits(profile: &SCurve, v: f32, a: f32, j: f32) {
        let dt = 1.0e-3f32;
        let mut t = 0.0f32;
        let mut previous = profile.at(0.0);
        while t < profile.duration_s() + 0.01 {
            t += dt;
            let p = profile.at(t);
            assert!(p.speed_mps <= v * 1.0001 && p.speed_mps >= -1e-5, "speed {p:?} at {t}");
            assert!(p.accel_mps2.abs() <= a * 1.0001, "accel {p:?}");
            let jerk = (p.accel_mps2 - previous.accel_mps2) / dt;
            assert!(jerk.abs() <= j * 1.01, "jerk {jerk} at {t}");
            previous = p;
        }
    }

    #[test]
    fn long_travel_reaches_rated_speed_and_ends_at_rest_on_target() {
        let profile = SCurve::plan(6.6, 0.4, 0.5, 1.0).unwrap();
        check_limits(&profile, 0.4, 0.5, 1.0);
        let mid = profile.at(profile.duration_s() / 2.0);
        assert!((mid.speed_mps - 0.4).abs() < 1e-6);
        let end = profile.starts[7].1;
        assert!((end.position_m - 6.6).abs() < 1e-4 && end.speed_mps.abs() < 1e-5 && end.accel_mps2.abs() < 1e-5);
        // Cruise time from the closed form: (D - v (v/a + a/j)) / v.
        let expected = 2.0 * (0.5 + 0.8) + (6.6 - 0.4 * (0.8 + 0.5)) / 0.4;
        assert!((profile.duration_s() - expected).abs() < 1e-4, "{}", profile.duration_s());
    }

    #[test]
    fn short_travel_lowers_peak_speed() {
        for distance in [0.05f32, 0.2, 0.45] {
            let profile = SCurve::plan(distance, 0.4, 0.5, 1.0).unwrap();
            check_limits(&profile, 0.4, 0.5, 1.0);
            let end = profile.starts[7].1;
            assert!((end.position_m - distance).abs() < 1e-4 * distance.max(1.0), "{end:?}");
        }
    }

    #[test]
    fn rejects_bad_limits() {
        assert_eq!(SCurve::plan(-1.0, 0.4, 0.5, 1.0), Err(ProfileError::NonPositiveLimit));
        assert_eq!(SCurve::plan(1.0, f32::NAN, 0.5, 1.0), Err(ProfileError::NonPositiveLimit));
    }

    fn check_ramp(ramp: &SpeedRamp, a: f32, j: f32) {
        let dt = 1.0e-3f32;
        let mut t = 0.0f32;
        let mut previous = ramp.at(0.0);
        while t < ramp.duration_s() + 0.05 {
            t += dt;
            let p = ramp.at(t);
            assert!(p.accel_mps2.abs() <= a * 1.0001, "accel {p:?} at {t}");
            let jerk = (p.accel_mps2 - previous.accel_mps2) / dt;
            assert!(jerk.abs() <= j * 1.01, "jerk {jerk} at {t}");
            // Position is the integral of the speed (trapezoid over 1 ms).
            let integral = previous.position_m + 0.5 * (previous.speed_mps + p.speed_mps) * dt;
            assert!((p.position_m - integral).abs() < 1e-6, "position {p:?} vs {integral} at {t}");
            previous = p;
        }
    }

    #[test]
    fn a_speed_ramp_from_rest_reaches_the_speed_with_the_limits_and_then_cruises() {
        let ramp = SpeedRamp::plan(ProfilePoint::default(), 0.4, 0.5, 1.0).unwrap();
        check_ramp(&ramp, 0.5, 1.0);
        // Half of the S-curve's run-up: 0.5 s of jerk, 0.3 s at 0.5 m/s^2, 0.5 s of jerk.
        assert!((ramp.duration_s() - 1.3).abs() < 1e-5, "{}", ramp.duration_s());
        // Distance of the run-up: half of v (v/a + a/j).
        assert!((ramp.end().position_m - 0.26).abs() < 1e-5, "{:?}", ramp.end());
        let later = ramp.at(ramp.duration_s() + 2.0);
        assert_eq!(later.speed_mps, 0.4);
        assert!((later.position_m - 1.06).abs() < 1e-5);
        // A small change never reaches the acceleration limit: a_peak = sqrt(dv j).
        let small = SpeedRamp::plan(ProfilePoint::default(), 0.04, 0.5, 1.0).unwrap();
        check_ramp(&small, 0.5, 1.0);
        assert!((small.duration_s() - 2.0 * 0.2).abs() < 1e-5);
    }

    #[test]
    fn a_speed_ramp_from_an_acceleration_first_levels_it_then_slows_down_to_rest() {
        // Mid-acceleration: 0.2 m/s at 0.5 m/s^2, down to crawl then to rest.
        let from = ProfilePoint { position_m: 0.3, speed_mps: 0.2, accel_mps2: 0.5 };
        let ramp = SpeedRamp::plan(from, 0.05, 0.5, 1.0).unwrap();
        check_ramp(&ramp, 0.5, 1.0);
        // The acceleration is levelled first: the speed rises by a^2 / 2j = 0.125.
        let top = ramp.at(0.5);
        assert!((top.speed_mps - 0.325).abs() < 1e-5 && top.accel_mps2.abs() < 1e-5, "{top:?}");
        assert_eq!(ramp.end().speed_mps, 0.05);
        let stop = SpeedRamp::plan(ramp.end(), 0.0, 0.5, 1.0).unwrap();
        check_ramp(&stop, 0.5, 1.0);
        let end = stop.at(stop.duration_s() + 1.0);
        assert_eq!(end.speed_mps, 0.0);
        // From 0.05 m/s: a_peak = sqrt(0.05), distance v a_peak / j... = 0.05 * sqrt(0.05).
        let expected = ramp.end().position_m + 0.05 * sqrt_newton(0.05);
        assert!((end.position_m - expected).abs() < 1e-5, "{end:?} vs {expected}");
        // Monotonic speed down from the top: never below the target on the way.
        let mut t = 0.5;
        while t < ramp.duration_s() {
            assert!(ramp.at(t).speed_mps >= 0.05 - 1e-5);
            t += 0.01;
        }
    }

    #[test]
    fn a_speed_ramp_refuses_bad_limits() {
        let rest = ProfilePoint::default();
        assert_eq!(SpeedRamp::plan(rest, -0.1, 0.5, 1.0), Err(ProfileError::NonPositiveLimit));
        assert_eq!(SpeedRamp::plan(rest, 0.1, 0.0, 1.0), Err(ProfileError::NonPositiveLimit));
        assert_eq!(SpeedRamp::plan(rest, f32::NAN, 0.5, 1.0), Err(ProfileError::NonPositiveLimit));
        let bad = ProfilePoint { speed_mps: f32::INFINITY, ..rest };
        assert_eq!(SpeedRamp::plan(bad, 0.1, 0.5, 1.0), Err(ProfileError::NonPositiveLimit));
    }

    #[test]
    fn newton_sqrt() {
        for x in [1e-6f32, 0.25, 2.0, 1.0e4] {
            assert!((sqrt_newton(x) - x.sqrt()).abs() <= 2.0 * f32::EPSILON * x.sqrt());
        }
    }

    #[test]
    fn an_approach_from_a_running_curve_rests_on_the_new_target_within_the_limits() {
        let curve = SCurve::plan(3.0, 0.4, 0.5, 1.0).unwrap();
        for (t0, target) in [(4.0f32, 2.5f32), (4.0, 3.05), (4.0, 2.2), (0.8, 0.6), (0.8, 1.5), (7.5, 3.2), (8.0, 3.1)]
        {
            let from = curve.at(t0);
            let a = Approach::plan(from, target, 0.4, 0.5, 1.0).unwrap();
            let end = a.at(a.duration_s() + 1.0);
            assert!((end.position_m - target).abs() < 2e-4, "{t0} {target}: {end:?}");
            // Limits, continuity at the start, no overshoot, no reversal.
            let dt = 1.0e-3f32;
            let mut previous = from;
            let mut t = 0.0f32;
            while t < a.duration_s() + 0.05 {
                t += dt;
                let p = a.at(t);
                assert!(p.speed_mps <= 0.4 * 1.0001 && p.speed_mps >= -1e-4, "{t0} {target}: speed {p:?} at {t}");
                assert!(p.accel_mps2.abs() <= 0.5 * 1.0001, "{t0} {target}: accel {p:?} at {t}");
                let jerk = (p.accel_mps2 - previous.accel_mps2) / dt;
                assert!(jerk.abs() <= 1.0 * 1.01, "{t0} {target}: jerk {jerk} at {t}");
                assert!(p.position_m <= target + 2e-4, "{t0} {target}: past the target {p:?} at {t}");
                previous = p;
            }
        }
    }

    #[test]
    fn an_approach_closer_than_the_shortest_stop_is_refused() {
        let curve = SCurve::plan(3.0, 0.4, 0.5, 1.0).unwrap();
        let from = curve.at(4.0); // cruising at 0.4 m/s: 0.26 m to stop
        let shortest = from.position_m + 0.26;
        assert_eq!(Approach::plan(from, shortest - 0.01, 0.4, 0.5, 1.0), Err(ApproachError::CannotStop));
        let a = Approach::plan(from, shortest + 0.001, 0.4, 0.5, 1.0).unwrap();
        assert!((a.at(100.0).position_m - (shortest + 0.001)).abs() < 2e-4);
    }
}
