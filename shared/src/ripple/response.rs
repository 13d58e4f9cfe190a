//! Frequency response of the closed speed loop to a torque at the shaft: the
//! model behind the phase correction of the learning compensators.
//!
//! The mechanics are the paper's 5-DOF chain (Eqn 6): counterweight -
//! `k_w` - rope mass `mu l_w` - `k_w` - sheave - `k_c` - rope mass `mu l_c` -
//! `k_c` - car, with `k = 2EA/l` per half side (Eqn 1-2) and the guide and
//! sheave damping of Eqn 12-13. Each side is folded into the dynamic
//! stiffness it presents at the sheave edge, so the receptance of the sheave
//! costs a few complex divisions instead of a 5x5 solve. Around it: the
//! speed PI on the encoder tracking loop, the position loop, and the
//! speed-loop sample-and-hold as a first-order Pade delay.

use super::complex::Complex;
use crate::config::DriveConfig;
use crate::observer::ChainModel;
use crate::speed_loop::{speed_pi_gains, POSITION_GAIN_PER_S};

/// Dynamic stiffness `(-w^2 m + j w c)` of a mass `m_kg` with viscous damping
/// `c_kg_per_s` to ground, N/m.
fn mass(omega_radps: f32, m_kg: f32, c_kg_per_s: f32) -> Complex {
    Complex::new(-omega_radps * omega_radps * m_kg, omega_radps * c_kg_per_s)
}

/// A spring `k` (N/m) in series with dynamic stiffness `z` (N/m): `k z / (k + z)`.
/// Returns it with the displacement ratio `u_far / u_near = k / (k + z)`.
fn through_spring(k_n_per_m: f32, z: Complex) -> (Complex, Complex) {
    let k = Complex::new(k_n_per_m, 0.0);
    let ratio = k / (k + z);
    (z * ratio, ratio)
}

/// One rope side seen from the sheave edge: end mass, spring `2EA/l`, rope
/// mass `mu l`, spring `2EA/l` (Eqn 1-2, 6). Returns the dynamic stiffness at
/// the sheave edge (N/m) and the end mass's displacement per sheave-edge
/// displacement.
fn rope_side(
    omega_radps: f32,
    config: &ChainModel,
    length_m: f32,
    end_mass_kg: f32,
    end_damping_kg_per_s: f32,
) -> (Complex, Complex) {
    let length_m = length_m.max(0.01);
    let k = 2.0 * config.rope_ea_n / length_m;
    let end = mass(omega_radps, end_mass_kg, end_damping_kg_per_s);
    let (z1, ratio_end) = through_spring(k, end);
    let z2 = z1 + mass(omega_radps, config.rope_mass_per_length_kg_per_m * length_m, 0.0);
    let (z3, ratio_rope) = through_spring(k, z2);
    (z3, ratio_end * ratio_rope)
}

/// The chain's response at one frequency, from a torque at the shaft.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChainResponse {
    /// Shaft speed per shaft torque, open speed loop (the mobility), rad/s per N m.
    pub shaft_mobility: Complex,
    /// Car displacement per sheave-edge displacement (dimensionless).
    pub car_per_sheave: Complex,
}

/// Eqn 6 at angular frequency `omega_radps` (signed: a negative frequency
/// gives the conjugate), car mass `m_car_kg`, counterweight-side rope length
/// `lw_m`.
pub fn chain_response(config: &ChainModel, m_car_kg: f32, lw_m: f32, omega_radps: f32) -> ChainResponse {
    let w = if omega_radps < 0.0 { -omega_radps } else { omega_radps };
    let r = config.sheave_radius_m;
    let lc_m = config.rope_total_length_m - lw_m;
    let (z_car, car_per_sheave) = rope_side(w, config, lc_m, m_car_kg, config.c_car_kg_per_s);
    let (z_cw, _) = rope_side(w, config, lw_m, config.m_cw_kg, config.c_cw_kg_per_s);
    let z_sheave = mass(w, config.sheave_inertia_kg_m2 / (r * r), config.c_sheave_nms_per_rad / (r * r));
    // Sheave edge: F = Z u with F = T / r and u = theta r, so theta / T = 1 / (r^2 Z).
    let receptance = (z_sheave + z_car + z_cw).scale(r * r).recip();
    let mut shaft_mobility = Complex::new(0.0, w) * receptance;
    let mut car_per_sheave = car_per_sheave;
    if omega_radps < 0.0 {
        shaft_mobility = shaft_mobility.conj();
        car_per_sheave = car_per_sheave.conj();
    }
    ChainResponse { shaft_mobility, car_per_sheave }
}

/// The closed speed loop's responses to a shaft torque at one frequency.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoopResponse {
    /// Speed error at the speed PI's input (`speed_ref - speed estimate`, the
    /// position loop included) per shaft torque, rad/s per N m.
    pub speed_error_per_torque: Complex,
    /// Car acceleration per shaft torque, m/s^2 per N m.
    pub car_acceleration_per_torque: Complex,
}

/// The closed-loop responses at `omega_radps` (signed) of the drive
/// `config` on the chain `chain`, for a travel with a car of `m_car_kg` at
/// rope length `lw_m`, the speed loop tuned on `inertia_kg_m2` as
/// [`crate::speed_loop::SpeedLoop::new`] does.
pub fn loop_response(
    config: &DriveConfig,
    chain: &ChainModel,
    m_car_kg: f32,
    lw_m: f32,
    inertia_kg_m2: f32,
    omega_radps: f32,
) -> LoopResponse {
    let response = chain_response(chain, m_car_kg, lw_m, omega_radps);
    let s = Complex::new(0.0, omega_radps);
    let (kp, ki) = speed_pi_gains(config, inertia_kg_m2);
    let wn = core::f32::consts::TAU * config.speed_estimator_bandwidth_hz;
    // Tracking loop (speed_estimator): w_hat / w = wn^2 / (s^2 + 2 wn s + wn^2).
    let wn2 = Complex::new(wn * wn, 0.0);
    let estimator = wn2 / (s * s + s.scale(2.0 * wn) + wn2);
    // Half a speed period of sample-and-hold plus one of computation: 1.5 Ts as (1 - s T/2) / (1 + s T/2).
    let half_delay = s.scale(0.75 / config.speed_loop_hz);
    let delay = (Complex::ONE - half_delay) / (Complex::ONE + half_delay);
    // Speed error = -(estimator + K_pos / s) w (the position loop reads the raw counts).
    let feedback = estimator + Complex::new(POSITION_GAIN_PER_S, 0.0) * s.recip();
    let pi = Complex::new(kp, 0.0) + Complex::new(ki, 0.0) * s.recip();
    let y = response.shaft_mobility;
    let speed_per_torque = y / (Complex::ONE + pi * feedback * delay * y);
    // Car: u_c = ratio * u_sheave = ratio * r * theta, a = s^2 u_c = s * ratio * r * w.
    let car = s * response.car_per_sheave.scale(chain.sheave_radius_m) * speed_per_torque;
    LoopResponse { speed_error_per_torque: -(feedback * speed_per_torque), car_acceleration_per_torque: car }
}
