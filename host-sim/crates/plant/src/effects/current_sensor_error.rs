//! Gain and offset errors of the phase-current transducers that the controller trusts.

use super::declare::{Effect, Fit, ParamScale::Linear, ParamSpec, Seen};

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

impl Effect for CurrentSensorError {
    const NAME: &'static str = "current_sensor_error";
    const PARAMETERS: &'static [ParamSpec] = &[
        ParamSpec::new("offset_a_a", "A", 0.2, -1.0, 1.0, Linear, true, "offset of the phase-a transducer"),
        ParamSpec::new("offset_b_a", "A", -0.1, -1.0, 1.0, Linear, true, "offset of the phase-b transducer"),
        ParamSpec::new("gain_error_a", "-", 0.01, -0.05, 0.05, Linear, true, "relative gain error of phase a"),
        ParamSpec::new("gain_error_b", "-", -0.01, -0.05, 0.05, Linear, true, "relative gain error of phase b"),
    ];
    const FIT: Fit = Fit::Linear(&[(0, 0.2), (1, 0.2), (2, 0.01), (3, 0.01)]);
    // The torque-driven model takes the true torque from the recorded
    // currents read as the drive's transducer signals.
    const SEEN: Seen = Seen { in_free_decay: false, under_another_drive: true };

    fn from_values(v: &[f64]) -> Self {
        Self { offset_a_a: v[0], offset_b_a: v[1], gain_error_a: v[2], gain_error_b: v[3] }
    }

    fn values(&self) -> Vec<f64> {
        vec![self.offset_a_a, self.offset_b_a, self.gain_error_a, self.gain_error_b]
    }

    fn measured_currents_a(&self, currents_a: [f64; 3]) -> [f64; 3] {
        self.measured_a(currents_a)
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
