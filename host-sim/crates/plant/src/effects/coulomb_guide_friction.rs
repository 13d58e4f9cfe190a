//! Dry (Coulomb) friction at the guide shoes of car and counterweight, besides the viscous part.

use super::declare::{
    Effect, Fit,
    ParamScale::{Linear, Log},
    ParamSpec, Seen,
};

/// Dry (Coulomb) friction at the guide shoes of car and counterweight, besides the viscous part.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoulombGuideFriction {
    /// Friction force at each guide, N.
    pub friction_n: f64,
    /// Speed over which the force builds up (tanh law), m/s.
    pub slip_speed_mps: f64,
}

impl CoulombGuideFriction {
    /// Friction force (N) on a body moving at `velocity_mps` (m/s, in any
    /// coordinate; the force is in the same one): `-F tanh(v / v_slip)`.
    pub fn force_n(&self, velocity_mps: f64) -> f64 {
        -self.friction_n * (velocity_mps / self.slip_speed_mps).tanh()
    }

    /// Largest slope `|dF/dv| / m` (1/s) the friction gives a body of
    /// `mass_kg` (kg): `F / (v_slip m)`, the rate an explicit integrator's
    /// step must resolve.
    pub fn stiffness_rate_per_s(&self, mass_kg: f64) -> f64 {
        self.friction_n / (self.slip_speed_mps * mass_kg)
    }
}

impl Effect for CoulombGuideFriction {
    const NAME: &'static str = "coulomb_guide_friction";
    const PARAMETERS: &'static [ParamSpec] = &[
        ParamSpec::new(
            "friction_n",
            "N",
            20.0,
            0.0,
            150.0,
            Linear,
            true,
            "dry friction force at each guide (car and counterweight)",
        ),
        ParamSpec::new(
            "slip_speed_mps",
            "m/s",
            0.002,
            1.0e-3,
            0.05,
            Log,
            false,
            "speed over which the friction force builds up (tanh)",
        ),
    ];
    const FIT: Fit = Fit::Linear(&[(0, 40.0)]);
    const SEEN: Seen = Seen { in_free_decay: true, under_another_drive: true };

    fn from_values(v: &[f64]) -> Self {
        Self { friction_n: v[0], slip_speed_mps: v[1] }
    }

    fn values(&self) -> Vec<f64> {
        vec![self.friction_n, self.slip_speed_mps]
    }

    const AT_GUIDES: bool = true;

    fn guide_force_n(&self, velocity_mps: f64) -> f64 {
        self.force_n(velocity_mps)
    }

    fn guide_force_rate_per_s(&self, mass_kg: f64) -> f64 {
        self.stiffness_rate_per_s(mass_kg)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn friction_opposes_the_motion_and_saturates() {
        let f = CoulombGuideFriction { friction_n: 20.0, slip_speed_mps: 0.002 };
        assert!((f.force_n(0.4) + 20.0).abs() < 1e-9);
        assert!((f.force_n(-0.4) - 20.0).abs() < 1e-9);
        assert_eq!(f.force_n(0.0), 0.0);
        assert!((f.force_n(0.001) + 20.0 * 0.5f64.tanh()).abs() < 1e-12);
        assert!((f.stiffness_rate_per_s(10.0) - 1000.0).abs() < 1e-9);
    }
}
