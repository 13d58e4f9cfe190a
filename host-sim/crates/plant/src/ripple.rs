//! Torque ripple of the machine as angle-locked shaft torques (paper 3.3):
//! `sum_n A_n cos(n theta_m + phi_n)` over the `[[ripple]]` components, with
//! `theta_m` the mechanical shaft angle. At 0.4 m/s the orders 1, 6, 12, 36
//! and 72 appear at about 1, 6, 12, 36 and 72 Hz.

use rig_config::Ripple;

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
    ///
    /// Whole orders (the rig file's) take `e^{i n theta}` as a power of
    /// `e^{i theta}` (one `sin_cos` for all harmonics: the plant evaluates
    /// this four times per integration step); others call `cos`.
    pub fn torque_nm(&self, theta_m_rad: f64) -> f64 {
        let (s, c) = theta_m_rad.sin_cos();
        self.torque_at(theta_m_rad, s, c)
    }

    /// [`RippleTorque::torque_nm`] with `(sin, cos)` of the angle given, N m.
    pub fn torque_at(&self, theta_m_rad: f64, s: f64, c: f64) -> f64 {
        self.harmonics
            .iter()
            .map(|h| {
                let n = h.mechanical_order;
                let angle_cos = if n.fract() == 0.0 && n.abs() <= 1024.0 {
                    let (pc, ps) = unit_power(c, s, n.abs() as u32);
                    let ps = if n < 0.0 { -ps } else { ps };
                    let (fs, fc) = if h.phase_rad == 0.0 { (0.0, 1.0) } else { h.phase_rad.sin_cos() };
                    pc * fc - ps * fs
                } else {
                    (n * theta_m_rad + h.phase_rad).cos()
                };
                h.amplitude_nm * angle_cos
            })
            .sum()
    }
}

/// `(cos, sin)` of `n theta` from `(cos theta, sin theta)` by binary powers
/// of the unit complex number (error about `n` ulp).
pub fn unit_power(c: f64, s: f64, mut n: u32) -> (f64, f64) {
    let (mut rc, mut rs) = (1.0, 0.0);
    let (mut bc, mut bs) = (c, s);
    while n > 0 {
        if n & 1 == 1 {
            (rc, rs) = (rc * bc - rs * bs, rc * bs + rs * bc);
        }
        (bc, bs) = (bc * bc - bs * bs, 2.0 * bc * bs);
        n >>= 1;
    }
    (rc, rs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whole_orders_by_powers_match_cos() {
        let r = RippleTorque {
            harmonics: [1.0, 6.0, 12.0, 36.0, 72.0, 2.5]
                .iter()
                .enumerate()
                .map(|(i, &n)| RippleHarmonic {
                    mechanical_order: n,
                    amplitude_nm: 1.0 + i as f64,
                    phase_rad: 0.3 * i as f64,
                })
                .collect(),
        };
        for k in 0..2000 {
            let theta = -50.0 + 0.0731 * k as f64;
            let direct: f64 =
                r.harmonics.iter().map(|h| h.amplitude_nm * (h.mechanical_order * theta + h.phase_rad).cos()).sum();
            assert!((r.torque_nm(theta) - direct).abs() < 1e-11, "theta {theta}");
        }
    }
}
