//! Encoder eccentricity: an angle error once per revolution, error = a sin(theta + phase).

/// Encoder eccentricity: an angle error once per revolution, error = a sin(theta + phase).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EncoderError {
    /// Angle error amplitude, rad.
    pub eccentricity_rad: f64,
    /// Phase, rad.
    pub phase_rad: f64,
}
