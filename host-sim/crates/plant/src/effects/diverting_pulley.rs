//! The diverting pulley as a rotational degree of freedom on the car side, between sheave and car.

use super::declare::{
    Effect, Fit, Neutral,
    ParamScale::{Linear, Log},
    ParamSpec, Seen,
};

/// The diverting pulley as a rotational degree of freedom on the car side, between sheave and car.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DivertingPulley {
    /// Pulley inertia, kg m^2.
    pub inertia_kg_m2: f64,
    /// Pulley radius, m.
    pub radius_m: f64,
    /// Rope length from the sheave to the pulley (fixed during the travel), m.
    pub sheave_to_pulley_m: f64,
    /// Damping ratio of the pulley's own mode on the sheave-to-pulley
    /// segment (its bearing and the rope's losses where it bends over the
    /// pulley), -: the pulley's rim is damped by `2 zeta sqrt(k_sp m_p)`
    /// on its absolute velocity.
    pub damping_ratio: f64,
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
    /// Mass of the pulley's rim in rope coordinates, kg: `J / r_p^2`
    /// (what the rope's motion tells of the pulley: not the inertia and
    /// the radius apart).
    pub fn rim_mass_kg(&self) -> f64 {
        self.inertia_kg_m2 / (self.radius_m * self.radius_m)
    }

    /// Equivalent mass of the pulley in rope coordinates, with the
    /// segment's rope, kg: `J / r_p^2 + mu l_sp` (`mu` in kg/m).
    pub fn equivalent_mass_kg(&self, mu_kg_per_m: f64) -> f64 {
        self.rim_mass_kg() + mu_kg_per_m * self.sheave_to_pulley_m
    }

    /// Stiffness of the sheave-to-pulley segment, N/m, for the rope's
    /// `ea_n` (N): `EA / l_sp`.
    pub fn segment_stiffness_n_per_m(&self, ea_n: f64) -> f64 {
        ea_n / self.sheave_to_pulley_m
    }

    /// Viscous damping on the pulley's rim, kg/s, for the segment's
    /// stiffness `segment_n_per_m` (N/m) and the pulley's equivalent mass
    /// `mass_kg` (kg): `2 zeta sqrt(k_sp m_p)`. Without it the pulley's own
    /// mode (about `sqrt(k_sp / m_p) / 2 pi`, 80-110 Hz on a lab rig) rings
    /// undamped between two springs.
    pub fn damping_kg_per_s(&self, segment_n_per_m: f64, mass_kg: f64) -> f64 {
        2.0 * self.damping_ratio * (segment_n_per_m * mass_kg).sqrt()
    }

    /// Car-side rope hanging below the pulley, m, for a car side of
    /// `car_side_length_m` (m): `l_c - l_sp`.
    pub fn rope_below_pulley_m(&self, car_side_length_m: f64) -> f64 {
        car_side_length_m - self.sheave_to_pulley_m
    }
}

impl Effect for DivertingPulley {
    const NAME: &'static str = "diverting_pulley";
    const PARAMETERS: &'static [ParamSpec] = &[
        ParamSpec::new("inertia_kg_m2", "kg m^2", 0.02, 0.002, 0.2, Log, true, "pulley inertia"),
        ParamSpec::new("radius_m", "m", 0.065, 0.02, 0.3, Linear, false, "pulley radius"),
        ParamSpec::new(
            "sheave_to_pulley_m",
            "m",
            0.5,
            0.05,
            0.9,
            Linear,
            false,
            "rope length from the sheave to the pulley",
        ),
        // How strongly the pulley's own mode is damped says nothing on
        // whether there is a pulley: its inertia does.
        ParamSpec::new("damping_ratio", "-", 0.02, 0.002, 0.5, Log, true, "damping ratio of the pulley's own mode")
            .neutral_at(Neutral::NotAStrength),
    ];
    // The pulley's own mode is as strong as it is undamped: its damping is
    // searched with its inertia.
    const FIT: Fit = Fit::Grid { axes: &[(0, &[0.004, 0.012, 0.035, 0.1]), (3, &[0.005, 0.02, 0.08])], screened: true };
    const SEEN: Seen = Seen { in_free_decay: false, under_another_drive: true };

    fn from_values(v: &[f64]) -> Self {
        Self { inertia_kg_m2: v[0], radius_m: v[1], sheave_to_pulley_m: v[2], damping_ratio: v[3] }
    }

    fn values(&self) -> Vec<f64> {
        vec![self.inertia_kg_m2, self.radius_m, self.sheave_to_pulley_m, self.damping_ratio]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lumping() {
        let p = DivertingPulley { inertia_kg_m2: 0.02, radius_m: 0.1, sheave_to_pulley_m: 0.5, damping_ratio: 0.1 };
        assert!((p.equivalent_mass_kg(0.1) - 2.05).abs() < 1e-12);
        assert!((p.segment_stiffness_n_per_m(1.0e6) - 2.0e6).abs() < 1e-6);
        assert!((p.rope_below_pulley_m(3.0) - 2.5).abs() < 1e-12);
        // 2 x 0.1 x sqrt(2e6 N/m x 2 kg) = 400 kg/s.
        assert!((p.damping_kg_per_s(2.0e6, 2.0) - 400.0).abs() < 1e-9);
    }
}
