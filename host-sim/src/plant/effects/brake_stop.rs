//! The brake clamps the sheave at the end of the travel through an elastic clamp.

/// The brake clamps the sheave at the end of the travel through an elastic clamp.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BrakeStop {
    /// Torsional stiffness of the clamp, N m/rad.
    pub clamp_stiffness_nm_per_rad: f64,
    /// Damping of the clamp, N m s/rad.
    pub clamp_damping_nms_per_rad: f64,
}
