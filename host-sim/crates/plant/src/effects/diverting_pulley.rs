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

/// Lumping of the car side with the pulley: the sheave, a massless spring
/// `EA / l_sp` for the fixed rope segment from the sheave to the pulley,
/// the pulley as one coordinate (its rim, in rope metres) of mass
/// `J / r_p^2 + mu l_sp` (the segment's rope runs with the pulley's rim, so
/// its mass is lumped there), then the car-side rope below the pulley, of
/// length `l_c - l_sp`, lumped like any side (`rope_discretization`), down
/// to the car. The segment's weight stays in the out-of-balance torque
/// (Eqn 4 counts the whole car side as hanging; the difference,
/// `mu l_sp g r`, is below 0.03 N m on the rig).
impl DivertingPulley {
    /// Equivalent mass of the pulley in rope coordinates, with the
    /// segment's rope, kg: `J / r_p^2 + mu l_sp` (`mu` in kg/m).
    pub fn equivalent_mass_kg(&self, mu_kg_per_m: f64) -> f64 {
        self.inertia_kg_m2 / (self.radius_m * self.radius_m) + mu_kg_per_m * self.sheave_to_pulley_m
    }

    /// Stiffness of the sheave-to-pulley segment, N/m, for the rope's
    /// `ea_n` (N): `EA / l_sp`.
    pub fn segment_stiffness_n_per_m(&self, ea_n: f64) -> f64 {
        ea_n / self.sheave_to_pulley_m
    }

    /// Car-side rope hanging below the pulley, m, for a car side of
    /// `car_side_length_m` (m): `l_c - l_sp`.
    pub fn rope_below_pulley_m(&self, car_side_length_m: f64) -> f64 {
        car_side_length_m - self.sheave_to_pulley_m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lumping() {
        let p = DivertingPulley { inertia_kg_m2: 0.02, radius_m: 0.1, sheave_to_pulley_m: 0.5 };
        assert!((p.equivalent_mass_kg(0.1) - 2.05).abs() < 1e-12);
        assert!((p.segment_stiffness_n_per_m(1.0e6) - 2.0e6).abs() < 1e-6);
        assert!((p.rope_below_pulley_m(3.0) - 2.5).abs() < 1e-12);
    }
}
