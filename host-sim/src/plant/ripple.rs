//! Torque ripple of the machine as angle-locked shaft torques (paper 3.3):
//! `sum_n A_n cos(n theta_m + phi_n)` over the `[[ripple]]` components, with
//! `theta_m` the mechanical shaft angle. At 0.4 m/s the orders 1, 6, 12, 36
//! and 72 appear at about 1, 6, 12, 36 and 72 Hz.

use crate::config::Ripple;

/// One harmonic of the ripple.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RippleHarmonic {
    /// Mechanical order `n` (per revolution).
    pub mechanical_order: f64,
    /// Amplitude, N m.
    pub amplitude_nm: f64,
    /// Phase, rad.
    pub phase_rad: f64,
}

/// The ripple torque of the machine.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RippleTorque {
    /// Harmonics.
    pub harmonics: Vec<RippleHarmonic>,
}

impl RippleTorque {
    /// The ripple of the rig file's `[[ripple]]` table.
    pub fn from_rig(components: &[Ripple]) -> Self {
        Self {
            harmonics: components
                .iter()
                .map(|r| RippleHarmonic {
                    mechanical_order: r.mechanical_order as f64,
                    amplitude_nm: r.amplitude_nm,
                    phase_rad: r.phase_rad,
                })
                .collect(),
        }
    }

    /// Ripple torque at mechanical angle `theta_m_rad`, N m.
    pub fn torque_nm(&self, theta_m_rad: f64) -> f64 {
        self.harmonics.iter().map(|h| h.amplitude_nm * (h.mechanical_order * theta_m_rad + h.phase_rad).cos()).sum()
    }
}
