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

    #[test]
    fn newton_sqrt() {
        for x in [1e-6f32, 0.25, 2.0, 1.0e4] {
            assert!((sqrt_newton(x) - x.sqrt()).abs() <= 2.0 * f32::EPSILON * x.sqrt());
        }
    }
}
