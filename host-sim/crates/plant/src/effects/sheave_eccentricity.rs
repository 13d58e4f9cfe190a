//! An eccentric traction sheave: its radius varies with angle, r = r0 (1 + e cos(theta + phase)).

use super::declare::{
    Effect, Fit,
    ParamScale::{Angle, Linear},
    ParamSpec, Seen,
};
use std::f64::consts::TAU;

/// An eccentric traction sheave: its radius varies with angle, r = r0 (1 + e cos(theta + phase)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SheaveEccentricity {
    /// Relative radius variation e, dimensionless.
    pub eccentricity: f64,
    /// Angle of the largest radius, rad.
    pub phase_rad: f64,
}

impl SheaveEccentricity {
    /// Rolling radius (m) at sheave angle `theta_rad` (rad) of a sheave of
    /// nominal radius `r0_m` (m): `r = r0 (1 + e cos(theta + phase))`.
    pub fn radius_m(&self, r0_m: f64, theta_rad: f64) -> f64 {
        r0_m * (1.0 + self.eccentricity * (theta_rad + self.phase_rad).cos())
    }

    /// Rope displacement (m) at the sheave after it has turned `theta_rad`
    /// (rad) from 0: the integral of [`Self::radius_m`],
    /// `g = r0 (theta + e (sin(theta + phase) - sin(phase)))`. One
    /// revolution moves the rope by `2 pi r0` whatever `e`.
    pub fn rope_displacement_m(&self, r0_m: f64, theta_rad: f64) -> f64 {
        r0_m * (theta_rad + self.eccentricity * ((theta_rad + self.phase_rad).sin() - self.phase_rad.sin()))
    }

    /// Lever-arm ratio `r(theta) / r0` (dimensionless) = `dg/du_sh` with
    /// `u_sh = r0 theta`: the factor on every rope force acting on the
    /// sheave coordinate (Lagrange: the generalised force of a rope force
    /// `F` at the rope end `g(theta)` is `F dg/du_sh`).
    pub fn lever_ratio(&self, theta_rad: f64) -> f64 {
        1.0 + self.eccentricity * (theta_rad + self.phase_rad).cos()
    }
}

impl Effect for SheaveEccentricity {
    const NAME: &'static str = "sheave_eccentricity";
    const PARAMETERS: &'static [ParamSpec] = &[
        ParamSpec::new(
            "eccentricity",
            "-",
            0.005,
            0.0,
            0.02,
            Linear,
            true,
            "relative radius variation: r = r0 (1 + e cos(theta + phase))",
        ),
        ParamSpec::new("phase_rad", "rad", 0.0, 0.0, TAU, Angle, true, "angle of the largest radius"),
    ];
    const FIT: Fit = Fit::Polar { amplitude: 0, phase: 1, probe: 0.005 };
    const SEEN: Seen = Seen { in_free_decay: false, under_another_drive: true };

    fn from_values(v: &[f64]) -> Self {
        Self { eccentricity: v[0], phase_rad: v[1] }
    }

    fn values(&self) -> Vec<f64> {
        vec![self.eccentricity, self.phase_rad]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    #[test]
    fn displacement_integrates_the_radius() {
        let s = SheaveEccentricity { eccentricity: 0.01, phase_rad: 0.7 };
        let r0 = 0.065;
        assert_eq!(s.rope_displacement_m(r0, 0.0), 0.0);
        assert!((s.rope_displacement_m(r0, TAU) - TAU * r0).abs() < 1e-15);
        for theta in [0.0, 1.0, 2.5, 4.0] {
            let h = 1e-6;
            let slope = (s.rope_displacement_m(r0, theta + h) - s.rope_displacement_m(r0, theta - h)) / (2.0 * h);
            assert!((slope - s.radius_m(r0, theta)).abs() < 1e-9);
            assert!((s.lever_ratio(theta) * r0 - s.radius_m(r0, theta)).abs() < 1e-15);
        }
    }
}
