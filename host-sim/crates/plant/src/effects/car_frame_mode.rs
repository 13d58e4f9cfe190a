//! A flexible mode of the car frame between the rope hitch and the accelerometer (the paper's 235 Hz).

use super::declare::{
    Effect, Fit, Neutral,
    ParamScale::{Linear, Log},
    ParamSpec, Seen,
};

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

impl Effect for CarFrameMode {
    const NAME: &'static str = "car_frame_mode";
    const PARAMETERS: &'static [ParamSpec] = &[
        ParamSpec::new("frequency_hz", "Hz", 235.0, 80.0, 500.0, Log, true, "frame mode with the hitch held")
            .neutral_at(Neutral::AboveRange),
        ParamSpec::new("damping_ratio", "-", 0.02, 0.005, 0.2, Log, true, "modal damping ratio")
            .neutral_at(Neutral::AboveRange),
        ParamSpec::new(
            "mass_fraction",
            "-",
            0.3,
            0.02,
            0.8,
            Linear,
            false,
            "share of the car mass on the accelerometer side",
        )
        .neutral_at(Neutral::AboveRange),
    ];
    const FIT: Fit = Fit::Grid { axes: &[(0, &[120.0, 200.0, 330.0]), (1, &[0.015, 0.05])], screened: false };
    const SEEN: Seen = Seen { in_free_decay: true, under_another_drive: true };

    fn from_values(v: &[f64]) -> Self {
        Self { frequency_hz: v[0], damping_ratio: v[1], mass_fraction: v[2] }
    }

    fn values(&self) -> Vec<f64> {
        vec![self.frequency_hz, self.damping_ratio, self.mass_fraction]
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
