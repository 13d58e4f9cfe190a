//! Speed loop: PI on the shaft speed plus the torque feed-forwards, giving
//! the q-current reference.
//!
//! Feed-forwards (paper section 2.2): the out-of-balance torque of Eqn 4,
//! `tau_e = (m_c - m_w + mu (l_c - l_w)) g r` (sign: positive torque lifts the
//! car), from the load weighing, and the inertia torque `J alpha_ref` with
//! `J = I + (m_w + m_c + mu l_t) r^2`.

use crate::config::DriveConfig;
use crate::fixed::{mul, q16, Q16};
use crate::pi::{Pi, PiGains};

/// Position-loop gain on the car position error, 1/s: the controller adds
/// `POSITION_GAIN_PER_S * (position_ref - position)` (m/s) to the profile's
/// speed before the speed loop; the ripple compensation's loop response
/// (`ripple::response`) models the same outer loop.
pub const POSITION_GAIN_PER_S: f32 = 2.0;

/// Eqn 4: out-of-balance torque that holds the car, N m (positive lifts the car).
pub fn out_of_balance_torque_nm(config: &DriveConfig, m_car_kg: f32, lw_m: f32) -> f32 {
    let lc_m = config.rope_total_length_m - lw_m;
    (m_car_kg - config.m_cw_kg + config.rope_mass_per_length_kg_per_m * (lc_m - lw_m))
        * config.gravity_mps2
        * config.sheave_radius_m
}

/// Inertia of the whole roped system seen at the shaft, kg m^2.
pub fn equivalent_inertia_kg_m2(config: &DriveConfig, m_car_kg: f32) -> f32 {
    let r = config.sheave_radius_m;
    config.sheave_inertia_kg_m2
        + (config.m_cw_kg + m_car_kg + config.rope_mass_per_length_kg_per_m * config.rope_total_length_m) * r * r
}

/// Speed PI gains `(Kp, Ki)` for the closed-loop bandwidth of `config` on
/// the inertia `inertia_kg_m2`: `Kp = J wc` (N m s/rad), `Ki = Kp wc / 4`
/// (N m/rad): PI zero a quarter of the crossover, phase margin about 76 degrees.
pub fn speed_pi_gains(config: &DriveConfig, inertia_kg_m2: f32) -> (f32, f32) {
    let wc = core::f32::consts::TAU * config.speed_loop_bandwidth_hz;
    let kp = inertia_kg_m2 * wc;
    (kp, kp * wc / 4.0)
}

/// Speed PI with torque output and conversion to q current.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpeedLoop {
    pi: Pi,
    torque_limit_nm: Q16,
    inverse_torque_constant: Q16,
}

impl SpeedLoop {
    /// Gains for the closed-loop `bandwidth` of the config on the inertia
    /// `inertia_kg_m2`: `Kp = J wc`, `Ki = Kp wc / 4` (PI zero a quarter of the
    /// crossover, phase margin about 76 degrees).
    pub fn new(config: &DriveConfig, inertia_kg_m2: f32) -> Self {
        let (kp, ki) = speed_pi_gains(config, inertia_kg_m2);
        let ts = 1.0 / config.speed_loop_hz;
        let kt = config.torque_constant_nm_per_a();
        Self {
            pi: Pi::new(PiGains { kp: q16(kp), ki_ts: q16(ki * ts) }),
            torque_limit_nm: q16(config.max_current_a * kt),
            inverse_torque_constant: q16(1.0 / kt),
        }
    }

    /// Empties the integrator.
    pub fn reset(&mut self) {
        self.pi.reset();
    }

    /// Torque demand (N m) and the q-current reference (A) for the speed
    /// error `speed_ref - speed` (rad/s) and the feed-forward torque (N m).
    pub fn step(&mut self, speed_ref_radps: Q16, speed_radps: Q16, torque_ff_nm: Q16) -> (Q16, Q16) {
        let error = speed_ref_radps.saturating_sub(speed_radps);
        let torque = self.pi.update(error, torque_ff_nm, -self.torque_limit_nm, self.torque_limit_nm);
        (torque, mul(torque, self.inverse_torque_constant))
    }
}
