//! Encoder eccentricity: an angle error once per revolution, error = a sin(theta + phase).

use super::declare::{
    Effect, Fit,
    ParamScale::{Angle, Linear},
    ParamSpec, Seen,
};
use std::f64::consts::TAU;

/// Encoder eccentricity: an angle error once per revolution, error = a sin(theta + phase).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EncoderError {
    /// Angle error amplitude, rad.
    pub eccentricity_rad: f64,
    /// Phase, rad.
    pub phase_rad: f64,
}

impl EncoderError {
    /// The angle the encoder reads (rad) at the true mechanical angle
    /// `theta_rad` (rad): `theta + a sin(theta + phase)`.
    pub fn measured_angle_rad(&self, theta_rad: f64) -> f64 {
        theta_rad + self.eccentricity_rad * (theta_rad + self.phase_rad).sin()
    }
}

impl Effect for EncoderError {
    const NAME: &'static str = "encoder_error";
    const PARAMETERS: &'static [ParamSpec] = &[
        ParamSpec::new(
            "eccentricity_rad",
            "rad",
            0.002,
            0.0,
            0.01,
            Linear,
            true,
            "angle error amplitude, once per revolution",
        ),
        ParamSpec::new("phase_rad", "rad", 0.0, 0.0, TAU, Angle, true, "phase: error = a sin(theta + phase)"),
    ];
    const FIT: Fit = Fit::Polar { amplitude: 0, phase: 1, probe: 0.002 };
    const SEEN: Seen = Seen { in_free_decay: false, under_another_drive: true };

    fn from_values(v: &[f64]) -> Self {
        Self { eccentricity_rad: v[0], phase_rad: v[1] }
    }

    fn values(&self) -> Vec<f64> {
        vec![self.eccentricity_rad, self.phase_rad]
    }

    fn measured_angle_rad(&self, angle_rad: f64) -> f64 {
        EncoderError::measured_angle_rad(self, angle_rad)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_is_once_per_revolution() {
        let e = EncoderError { eccentricity_rad: 0.002, phase_rad: 0.3 };
        let theta = 1.0;
        let err = e.measured_angle_rad(theta) - theta;
        assert!((err - 0.002 * 1.3f64.sin()).abs() < 1e-15);
        let next = e.measured_angle_rad(theta + std::f64::consts::TAU) - theta - std::f64::consts::TAU;
        assert!((next - err).abs() < 1e-12);
    }
}
