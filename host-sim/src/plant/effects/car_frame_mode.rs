//! A flexible mode of the car frame between the rope hitch and the accelerometer (the paper's 235 Hz).

/// A flexible mode of the car frame between the rope hitch and the accelerometer (the paper's 235 Hz).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CarFrameMode {
    /// Frame mode with the hitch held, Hz.
    pub frequency_hz: f64,
    /// Modal damping ratio, dimensionless.
    pub damping_ratio: f64,
    /// Share of the car mass on the accelerometer side of the frame spring, dimensionless.
    pub mass_fraction: f64,
}
