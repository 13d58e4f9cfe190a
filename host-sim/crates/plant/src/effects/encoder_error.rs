//! Encoder eccentricity: an angle error once per revolution, error = a sin(theta + phase).

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
