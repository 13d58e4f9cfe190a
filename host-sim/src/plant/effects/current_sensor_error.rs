//! Gain and offset errors of the phase-current transducers that the controller trusts.

/// Gain and offset errors of the phase-current transducers that the controller trusts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CurrentSensorError {
    /// Offset of the phase-a transducer, A.
    pub offset_a_a: f64,
    /// Offset of the phase-b transducer, A.
    pub offset_b_a: f64,
    /// Relative gain error of phase a, dimensionless.
    pub gain_error_a: f64,
    /// Relative gain error of phase b, dimensionless.
    pub gain_error_b: f64,
}
