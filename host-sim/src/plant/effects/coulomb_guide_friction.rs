//! Dry (Coulomb) friction at the guide shoes of car and counterweight, besides the viscous part.

/// Dry (Coulomb) friction at the guide shoes of car and counterweight, besides the viscous part.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoulombGuideFriction {
    /// Friction force at each guide, N.
    pub friction_n: f64,
    /// Speed over which the force builds up (tanh law), m/s.
    pub slip_speed_mps: f64,
}
