//! The brake clamps the sheave at the end of the travel through an elastic clamp.

use super::declare::{
    Effect, Fit, Neutral,
    ParamScale::{Linear, Log},
    ParamSpec, Seen,
};

/// The brake clamps the sheave at the end of the travel through an elastic clamp.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BrakeStop {
    /// Torsional stiffness of the clamp, N m/rad.
    pub clamp_stiffness_nm_per_rad: f64,
    /// Damping of the clamp, N m s/rad.
    pub clamp_damping_nms_per_rad: f64,
}

impl BrakeStop {
    /// Torque (N m) of the clamped brake on the sheave at angle `theta_rad`
    /// (rad) and speed `omega_radps` (rad/s), clamped at `clamp_angle_rad`:
    /// `-k (theta - theta_clamp) - c omega`.
    pub fn torque_nm(&self, theta_rad: f64, clamp_angle_rad: f64, omega_radps: f64) -> f64 {
        -self.clamp_stiffness_nm_per_rad * (theta_rad - clamp_angle_rad) - self.clamp_damping_nms_per_rad * omega_radps
    }

    /// Clamp angle (rad) at which the clamp holds `holding_torque_nm` (N m)
    /// with the sheave at `theta_rad` (rad): the plant starts at rest with
    /// the brake carrying the out-of-balance torque, so its clamp is
    /// pre-deflected by `tau / k`.
    pub fn preloaded_clamp_angle_rad(&self, theta_rad: f64, holding_torque_nm: f64) -> f64 {
        theta_rad + holding_torque_nm / self.clamp_stiffness_nm_per_rad
    }

    /// Natural frequency (Hz) of a rigid sheave of `inertia_kg_m2` (kg m^2)
    /// on the clamp alone: `sqrt(k / I) / 2 pi`.
    pub fn clamp_frequency_hz(&self, inertia_kg_m2: f64) -> f64 {
        (self.clamp_stiffness_nm_per_rad / inertia_kg_m2).sqrt() / std::f64::consts::TAU
    }
}

impl Effect for BrakeStop {
    const NAME: &'static str = "brake_stop";
    const PARAMETERS: &'static [ParamSpec] = &[
        ParamSpec::new(
            "clamp_stiffness_nm_per_rad",
            "N m/rad",
            3.0e4,
            1.0e3,
            1.0e6,
            Log,
            true,
            "torsional stiffness of the clamped brake",
        )
        // The nominal plant's brake holds the sheave rigidly: the clamp
        // vanishes as it stiffens.
        .neutral_at(Neutral::AboveRange),
        ParamSpec::new(
            "clamp_damping_nms_per_rad",
            "N m s/rad",
            5.0,
            0.0,
            1000.0,
            Linear,
            true,
            "damping of the clamped brake",
        )
        // How long the clamp rings, not how strong it is: no value of it
        // is the nominal plant's rigid brake.
        .neutral_at(Neutral::NotAStrength),
    ];
    // The clamp's damping sets how long the sheave rings on it: fitted with
    // the stiffness (on the reference rig's sheave, 0.34 kg m^2, the
    // damping grid spans damping ratios 0.01 to 0.77 at 2e5 N m/rad; the
    // range reaches critical damping at 7.4e5 N m/rad).
    const FIT: Fit = Fit::Grid { axes: &[(0, &[4.0e3, 3.0e4, 2.0e5]), (1, &[5.0, 50.0, 400.0])], screened: true };
    // It acts while the brake holds, where another drive's start and stop
    // sequence is not compared.
    const SEEN: Seen = Seen { in_free_decay: false, under_another_drive: false };

    fn from_values(v: &[f64]) -> Self {
        Self { clamp_stiffness_nm_per_rad: v[0], clamp_damping_nms_per_rad: v[1] }
    }

    fn values(&self) -> Vec<f64> {
        vec![self.clamp_stiffness_nm_per_rad, self.clamp_damping_nms_per_rad]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_clamp_is_a_torsion_spring_and_damper() {
        let b = BrakeStop { clamp_stiffness_nm_per_rad: 3.0e4, clamp_damping_nms_per_rad: 5.0 };
        assert!((b.torque_nm(0.001, 0.0, 0.0) + 30.0).abs() < 1e-9);
        assert!((b.torque_nm(0.0, 0.0, 2.0) + 10.0).abs() < 1e-12);
        let c = b.preloaded_clamp_angle_rad(0.0, 24.0);
        assert!((b.torque_nm(0.0, c, 0.0) - 24.0).abs() < 1e-9);
    }
}
