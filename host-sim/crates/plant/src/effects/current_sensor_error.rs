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

impl CurrentSensorError {
    /// The currents (A) the drive's transducers report for the leg
    /// currents `true_a` (A): `(1 + g_x) i_x + o_x` for phases a and b,
    /// phase c exact.
    pub fn measured_a(&self, true_a: [f64; 3]) -> [f64; 3] {
        [
            (1.0 + self.gain_error_a) * true_a[0] + self.offset_a_a,
            (1.0 + self.gain_error_b) * true_a[1] + self.offset_b_a,
            true_a[2],
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gain_and_offset_on_a_and_b_only() {
        let e = CurrentSensorError { offset_a_a: 0.2, offset_b_a: -0.1, gain_error_a: 0.01, gain_error_b: -0.02 };
        let m = e.measured_a([10.0, -4.0, -6.0]);
        assert!((m[0] - 10.3).abs() < 1e-12);
        assert!((m[1] - (-4.0 * 0.98 - 0.1)).abs() < 1e-12);
        assert_eq!(m[2], -6.0);
    }
}
