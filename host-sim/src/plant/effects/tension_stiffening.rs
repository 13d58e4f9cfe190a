//! Tension stiffening: the rope's EA grows with its tension, EA = EA0 (T / T_ref)^alpha.

/// Tension stiffening: the rope's EA grows with its tension, EA = EA0 (T / T_ref)^alpha.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TensionStiffening {
    /// Exponent, dimensionless.
    pub alpha: f64,
    /// Tension at which EA equals the configured EA0, N.
    pub reference_tension_n: f64,
}
