//! An eccentric traction sheave: its radius varies with angle, r = r0 (1 + e cos(theta + phase)).

/// An eccentric traction sheave: its radius varies with angle, r = r0 (1 + e cos(theta + phase)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SheaveEccentricity {
    /// Relative radius variation e, dimensionless.
    pub eccentricity: f64,
    /// Angle of the largest radius, rad.
    pub phase_rad: f64,
}
