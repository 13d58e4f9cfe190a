//! The diverting pulley as a rotational degree of freedom on the car side, between sheave and car.

/// The diverting pulley as a rotational degree of freedom on the car side, between sheave and car.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DivertingPulley {
    /// Pulley inertia, kg m^2.
    pub inertia_kg_m2: f64,
    /// Pulley radius, m.
    pub radius_m: f64,
    /// Rope length from the sheave to the pulley (fixed during the travel), m.
    pub sheave_to_pulley_m: f64,
}
