//! The inverter's dead time distorts the phase voltages.

/// The inverter's dead time distorts the phase voltages.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeadTime {
    /// Dead time per switching edge, s.
    pub dead_time_s: f64,
    /// Phase current over which the voltage error reaches its full value, A.
    pub current_threshold_a: f64,
}
