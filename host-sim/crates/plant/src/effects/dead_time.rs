//! The inverter's dead time distorts the phase voltages.

use super::declare::{
    Effect, Fit,
    ParamScale::{Linear, Log},
    ParamSpec, Seen,
};

/// The inverter's dead time distorts the phase voltages.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeadTime {
    /// Dead time per switching edge, s.
    pub dead_time_s: f64,
    /// Phase current over which the voltage error reaches its full value, A.
    pub current_threshold_a: f64,
}

impl DeadTime {
    /// Phase-to-neutral voltage errors (V) of the dead time for the machine
    /// phase currents `currents_a` (A, positive into the machine) on a bus
    /// of `dc_bus_v` (V) switched at `pwm_hz` (Hz): each leg loses
    /// `(T_d f_pwm) V_dc tanh(i_x / i_th)` (during the dead time the diode
    /// that conducts is set by the current's sign), and the star point
    /// floats, so the mean of the three is removed.
    pub fn phase_voltage_errors_v(&self, currents_a: [f64; 3], dc_bus_v: f64, pwm_hz: f64) -> [f64; 3] {
        let amplitude = self.dead_time_s * pwm_hz * dc_bus_v;
        let leg = currents_a.map(|i| -amplitude * (i / self.current_threshold_a).tanh());
        let mean = (leg[0] + leg[1] + leg[2]) / 3.0;
        leg.map(|v| v - mean)
    }

    /// Amplitude (V) of the fundamental of the phase voltage error for
    /// sinusoidal currents much larger than the threshold: the error is a
    /// six-step wave of height `4/3 dV`, `dV = T_d f_pwm V_dc`, whose
    /// fundamental is `(4/pi) dV`, opposing the current.
    pub fn fundamental_drop_v(&self, dc_bus_v: f64, pwm_hz: f64) -> f64 {
        4.0 / std::f64::consts::PI * self.dead_time_s * pwm_hz * dc_bus_v
    }
}

impl Effect for DeadTime {
    const NAME: &'static str = "dead_time";
    const PARAMETERS: &'static [ParamSpec] = &[
        ParamSpec::new("dead_time_s", "s", 1.0e-6, 0.0, 5.0e-6, Linear, true, "dead time per switching edge"),
        ParamSpec::new(
            "current_threshold_a",
            "A",
            0.3,
            0.01,
            5.0,
            Log,
            false,
            "current over which the error reaches its full value",
        ),
    ];
    const FIT: Fit = Fit::Linear(&[(0, 0.3e-6)]);
    // The recorded currents, and so the torque that drives the diagnosis's
    // model under another drive, carry it.
    const SEEN: Seen = Seen { in_free_decay: false, under_another_drive: false };

    fn from_values(v: &[f64]) -> Self {
        Self { dead_time_s: v[0], current_threshold_a: v[1] }
    }

    fn values(&self) -> Vec<f64> {
        vec![self.dead_time_s, self.current_threshold_a]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_oppose_the_currents_with_zero_mean() {
        let d = DeadTime { dead_time_s: 1.0e-6, current_threshold_a: 0.3 };
        let e = d.phase_voltage_errors_v([10.0, -5.0, -5.0], 100.0, 16000.0);
        // Legs: -1.6, +1.6, +1.6 (V) (tanh saturated); mean 0.533.
        let dv = 1.6 * (10.0f64 / 0.3).tanh();
        assert!((e[0] + dv * 4.0 / 3.0).abs() < 1e-9, "{e:?}");
        assert!((e[1] - dv * 2.0 / 3.0).abs() < 1e-6);
        assert!(e.iter().sum::<f64>().abs() < 1e-12);
        assert!((d.fundamental_drop_v(100.0, 16000.0) - 2.037).abs() < 1e-3);
    }
}
