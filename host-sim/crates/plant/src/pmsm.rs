//! Permanent-magnet synchronous machine in the rotor (dq) frame:
//!
//! `L_d di_d/dt = v_d - R i_d + w_e L_q i_q`,
//! `L_q di_q/dt = v_q - R i_q - w_e (L_d i_d + psi)`,
//! `tau = 1.5 p (psi i_q + (L_d - L_q) i_d i_q)`, with `w_e = p w_m` (Eqn 7).

use rig_config::RigConfig;

/// Machine parameters, SI.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PmsmParams {
    /// Pole pairs `p`.
    pub pole_pairs: f64,
    /// Stator resistance, ohm.
    pub resistance_ohm: f64,
    /// d inductance, H.
    pub ld_h: f64,
    /// q inductance, H.
    pub lq_h: f64,
    /// Magnet flux linkage, Wb.
    pub flux_linkage_wb: f64,
}

impl PmsmParams {
    /// The machine of `rig`.
    pub fn from_rig(rig: &RigConfig) -> Self {
        let m = &rig.motor;
        Self {
            pole_pairs: m.pole_pairs as f64,
            resistance_ohm: m.stator_resistance_ohm,
            ld_h: m.ld_h,
            lq_h: m.lq_h,
            flux_linkage_wb: m.flux_linkage_wb,
        }
    }

    /// Time derivatives of `(i_d, i_q)`, A/s, for the voltages `(v_d, v_q)` (V)
    /// at electrical speed `omega_e` (rad/s).
    pub fn current_derivative(&self, id_a: f64, iq_a: f64, vd_v: f64, vq_v: f64, omega_e_radps: f64) -> (f64, f64) {
        let did = (vd_v - self.resistance_ohm * id_a + omega_e_radps * self.lq_h * iq_a) / self.ld_h;
        let diq =
            (vq_v - self.resistance_ohm * iq_a - omega_e_radps * (self.ld_h * id_a + self.flux_linkage_wb)) / self.lq_h;
        (did, diq)
    }

    /// Electromagnetic torque, N m.
    pub fn torque_nm(&self, id_a: f64, iq_a: f64) -> f64 {
        1.5 * self.pole_pairs * (self.flux_linkage_wb * iq_a + (self.ld_h - self.lq_h) * id_a * iq_a)
    }
}

/// Phase currents (A) of the dq currents at electrical angle `theta_e` (rad):
/// inverse Park then inverse Clarke (amplitude invariant).
pub fn phase_currents_a(id_a: f64, iq_a: f64, theta_e_rad: f64) -> [f64; 3] {
    let (s, c) = theta_e_rad.sin_cos();
    phase_currents_cs_a(id_a, iq_a, c, s)
}

/// [`phase_currents_a`] with `cos` and `sin` of the electrical angle given, A.
pub fn phase_currents_cs_a(id_a: f64, iq_a: f64, c: f64, s: f64) -> [f64; 3] {
    let alpha = id_a * c - iq_a * s;
    let beta = id_a * s + iq_a * c;
    let half_sqrt3 = 0.5 * 3f64.sqrt();
    [alpha, -0.5 * alpha + half_sqrt3 * beta, -0.5 * alpha - half_sqrt3 * beta]
}

/// Park transform of stationary voltages `(v_alpha, v_beta)` (V) at `theta_e` (rad).
pub fn park_v(v_alpha: f64, v_beta: f64, theta_e_rad: f64) -> (f64, f64) {
    let (s, c) = theta_e_rad.sin_cos();
    (v_alpha * c + v_beta * s, -v_alpha * s + v_beta * c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steady_state_matches_the_voltage_equations() {
        let p = PmsmParams { pole_pairs: 6.0, resistance_ohm: 1.2, ld_h: 0.015, lq_h: 0.015, flux_linkage_wb: 0.45 };
        let (iq, we) = (12.0, 36.9);
        let vd = -we * p.lq_h * iq;
        let vq = p.resistance_ohm * iq + we * p.flux_linkage_wb;
        let (did, diq) = p.current_derivative(0.0, iq, vd, vq, we);
        assert!(did.abs() < 1e-9 && diq.abs() < 1e-9);
        assert!((p.torque_nm(0.0, iq) - 4.05 * iq).abs() < 1e-9);
        let abc = phase_currents_a(0.0, iq, 0.3);
        assert!((abc.iter().sum::<f64>()).abs() < 1e-12);
    }
}
