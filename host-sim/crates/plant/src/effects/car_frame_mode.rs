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

impl CarFrameMode {
    /// Mass at the rope hitch (guides act there), kg, of a car of `m_car_kg`
    /// (kg): `(1 - beta) m`.
    pub fn hitch_mass_kg(&self, m_car_kg: f64) -> f64 {
        (1.0 - self.mass_fraction) * m_car_kg
    }

    /// Mass of the body that carries the accelerometer, kg: `beta m`.
    pub fn body_mass_kg(&self, m_car_kg: f64) -> f64 {
        self.mass_fraction * m_car_kg
    }

    /// Frame spring between hitch and body, N/m: `k = beta m (2 pi f)^2`
    /// (the body rings at `f` with the hitch held).
    pub fn stiffness_n_per_m(&self, m_car_kg: f64) -> f64 {
        let w = std::f64::consts::TAU * self.frequency_hz;
        self.body_mass_kg(m_car_kg) * w * w
    }

    /// Frame damper between hitch and body, kg/s: `2 zeta sqrt(k beta m)`.
    pub fn damping_kg_per_s(&self, m_car_kg: f64) -> f64 {
        2.0 * self.damping_ratio * (self.stiffness_n_per_m(m_car_kg) * self.body_mass_kg(m_car_kg)).sqrt()
    }

    /// Natural frequency (Hz) of hitch and body on the frame spring when
    /// both are free: `f / sqrt(1 - beta)` (reduced mass `beta (1 - beta) m`).
    pub fn free_free_frequency_hz(&self) -> f64 {
        self.frequency_hz / (1.0 - self.mass_fraction).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_and_spring() {
        let f = CarFrameMode { frequency_hz: 235.0, damping_ratio: 0.02, mass_fraction: 0.3 };
        assert!((f.hitch_mass_kg(70.5) + f.body_mass_kg(70.5) - 70.5).abs() < 1e-12);
        let w = (f.stiffness_n_per_m(70.5) / f.body_mass_kg(70.5)).sqrt();
        assert!((w / std::f64::consts::TAU - 235.0).abs() < 1e-9);
        let c = f.damping_kg_per_s(70.5);
        assert!((c / (2.0 * f.body_mass_kg(70.5) * w) - 0.02).abs() < 1e-12);
    }
}
