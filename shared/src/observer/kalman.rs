//! Extended Kalman filter on the reduced chain ([`super::model`]), one
//! measurement update and one Riccati step per 2 kHz tick.
//!
//! Augmented state (18 entries, SI units):
//!
//! * 0-5: the mechanical states of [`super::model`] (m, m/s);
//! * 6: `kappa`, the rope stiffness over its nominal value (dimensionless,
//!   random walk): an EA off by 20 % detunes the car mode by 10 %, which near
//!   the 12th ripple order changes the car response several-fold, so the
//!   filter identifies it as the travel sweeps the rope lengths;
//! * 7: a slowly varying shaft disturbance torque `d_0`, N m (random walk);
//! * 8-17: `a_n, b_n` of the angle-locked ripple `sum a_n cos(n theta) +
//!   b_n sin(n theta)` for the orders of [`ChainModel::ripple_orders`], N m
//!   (random walks; the observer knows the orders, not the amplitudes).
//!
//! Measurement: the sheave-edge position from the encoder, `theta r`, with the
//! variance of a uniform quantisation step, `q^2 / 12`. Input: the machine
//! torque `Kt i_q` (N m) minus the out-of-balance torque of Eqn 4.
//!
//! Determinism: only `f32` add, subtract, multiply and divide (through
//! nalgebra's matrix products and plain loops) and the integer sine table of
//! [`crate::trig`], so the chip and the host compute the same bits.
//!
//! Cost: the covariance is kept exactly symmetric (every update writes both
//! halves with the same value) and only one triangle is computed; the
//! Riccati step uses the structure of the transition matrix (the identity
//! below its first six rows, a rank-one disturbance block `gamma h^T / r`),
//! about 1 300 multiply-adds a tick instead of 2 600 for the dense products.

use nalgebra::SVector;

use super::model::{
    discretise, ChainModel, Matrix6, ModelError, ReducedChain, Vector6, CAR_STRETCH, CW_STRETCH, MAX_HARMONICS,
    MECHANICAL_STATES, SHEAVE_POSITION, SHEAVE_SPEED,
};
use crate::trig::sin_cos;

/// Length of the augmented state.
pub const STATES: usize = MECHANICAL_STATES + 2 + 2 * MAX_HARMONICS;
/// Index of the stiffness scale `kappa`.
pub const EA_SCALE: usize = MECHANICAL_STATES;
/// Index of the slow disturbance torque `d_0`, N m.
pub const DISTURBANCE_BIAS: usize = MECHANICAL_STATES + 1;
/// Index of the first ripple coefficient `a_1`, N m.
pub const FIRST_HARMONIC: usize = MECHANICAL_STATES + 2;
const DISTURBANCE_STATES: usize = STATES - DISTURBANCE_BIAS;

type StateVector = SVector<f32, STATES>;
/// The covariance, `p[i][j]` its entry `(i, j)`; exactly symmetric.
type Covariance = [[f32; STATES]; STATES];

/// Noise intensities, initial uncertainty and numerical settings of the
/// filter. The defaults are the tuning of the README's figures.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObserverTuning {
    /// Filter rate: one [`ChainObserver::update`] per period, Hz.
    pub update_hz: f32,
    /// White-noise intensity of unmodelled sheave-edge acceleration, m^2/s^3.
    pub sheave_acceleration_noise: f32,
    /// Random-walk intensity of the stiffness scale, 1/s.
    pub ea_scale_noise_per_s: f32,
    /// Random-walk intensity of the slow disturbance torque, N^2 m^2/s.
    pub disturbance_noise: f32,
    /// Random-walk intensity of each ripple coefficient, N^2 m^2/s.
    pub ripple_noise: f32,
    /// Initial standard deviation of the stiffness scale (dimensionless).
    pub ea_scale_initial_sd: f32,
    /// Initial standard deviation of the disturbance and ripple coefficients, N m.
    pub disturbance_initial_sd_nm: f32,
    /// Lower bound of the stiffness scale (dimensionless, > 0).
    pub ea_scale_min: f32,
    /// Upper bound of the stiffness scale (dimensionless).
    pub ea_scale_max: f32,
    /// Ticks between two re-discretisations of the model (rope lengths and
    /// stiffness scale change slowly), at least 1.
    pub reschedule_ticks: u32,
    /// Terms of the discretisation series ([`discretise`]).
    pub series_terms: usize,
}

impl Default for ObserverTuning {
    fn default() -> Self {
        Self {
            update_hz: 2000.0,
            sheave_acceleration_noise: 1.0e-4,
            ea_scale_noise_per_s: 1.0e-4,
            disturbance_noise: 1.0,
            ripple_noise: 1.0,
            ea_scale_initial_sd: 0.2,
            disturbance_initial_sd_nm: 1.0,
            ea_scale_min: 0.5,
            ea_scale_max: 2.0,
            reschedule_ticks: 8,
            series_terms: 8,
        }
    }
}

impl ObserverTuning {
    /// Checks every field; the error names the first one out of range.
    pub fn validate(&self) -> Result<(), ModelError> {
        let positive = |v: f32| v.is_finite() && v > 0.0;
        let non_negative = |v: f32| v.is_finite() && v >= 0.0;
        let checks = [
            (positive(self.update_hz), "update_hz", "a finite rate > 0 Hz"),
            (non_negative(self.sheave_acceleration_noise), "sheave_acceleration_noise", "a finite value >= 0"),
            (non_negative(self.ea_scale_noise_per_s), "ea_scale_noise_per_s", "a finite value >= 0"),
            (non_negative(self.disturbance_noise), "disturbance_noise", "a finite value >= 0"),
            (non_negative(self.ripple_noise), "ripple_noise", "a finite value >= 0"),
            (non_negative(self.ea_scale_initial_sd), "ea_scale_initial_sd", "a finite value >= 0"),
            (non_negative(self.disturbance_initial_sd_nm), "disturbance_initial_sd_nm", "a finite value >= 0"),
            (positive(self.ea_scale_min), "ea_scale_min", "a finite value > 0"),
            (
                self.ea_scale_max.is_finite() && self.ea_scale_max >= self.ea_scale_min,
                "ea_scale_max",
                "a finite value >= ea_scale_min",
            ),
            (self.reschedule_ticks >= 1, "reschedule_ticks", "at least 1"),
            ((2..=20).contains(&self.series_terms), "series_terms", "2 to 20 terms"),
        ];
        for (ok, field, expected) in checks {
            if !ok {
                return Err(ModelError { field, expected });
            }
        }
        Ok(())
    }
}

/// What the observer estimates after one tick (filtered: it includes that
/// tick's encoder reading).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ObserverEstimate {
    /// Car acceleration, m/s^2, positive up.
    pub car_acceleration_mps2: f32,
    /// Dynamic force of the car-side rope on the car (tension change from
    /// the static tension at rest), N.
    pub car_rope_force_n: f32,
    /// Dynamic force of the counterweight-side rope on the counterweight, N.
    pub counterweight_rope_force_n: f32,
    /// Shaft disturbance torque (everything the machine torque and the model
    /// do not explain: ripple, friction error), N m, positive lifts the car.
    pub shaft_disturbance_torque_nm: f32,
    /// Estimated rope `EA`, N.
    pub rope_ea_n: f32,
    /// Sheave-edge speed, m/s (positive: car up).
    pub sheave_speed_mps: f32,
    /// Counterweight-side rope length from the encoder (Eqn 3), m.
    pub counterweight_side_length_m: f32,
}

/// The reduced 5-DOF observer: call [`ChainObserver::start`] when the brake
/// lifts (the chain is at its static equilibrium then), then
/// [`ChainObserver::update`] once per speed-loop period.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChainObserver {
    model: ChainModel,
    tuning: ObserverTuning,
    dt_s: f32,
    metres_per_count: f32,
    /// `2^48 / counts_per_rev`: binary angle per encoder count, Q16.
    binary_angle_per_count_q16: u64,
    m_car_kg: f32,
    lw_start_m: f32,
    started: bool,
    last_count: u32,
    counts: i64,
    start_counts: i64,
    /// Encoder position (counts) of the zero of state 0.
    origin_counts: i64,
    last_torque_nm: f32,
    x: StateVector,
    p: Covariance,
    phi: Matrix6,
    psi: Matrix6,
    /// `Psi b`: the response of the mechanical states to the sheave force
    /// over one tick, 1/kg s (changes with `psi`).
    gamma: Vector6,
    chain: ReducedChain,
    ticks_to_schedule: u32,
    restarts: u32,
    estimate: ObserverEstimate,
}

impl ChainObserver {
    /// An observer of `model` with `tuning`; checks both.
    pub fn new(model: ChainModel, tuning: ObserverTuning) -> Result<Self, ModelError> {
        model.validate()?;
        tuning.validate()?;
        let chain = model.reduced(0.5 * model.rope_total_length_m, model.m_cw_kg, 1.0);
        let mut observer = Self {
            model,
            tuning,
            dt_s: 1.0 / tuning.update_hz,
            metres_per_count: model.metres_per_count(),
            binary_angle_per_count_q16: (1u64 << 48) / model.encoder_counts_per_rev as u64,
            m_car_kg: model.m_cw_kg,
            lw_start_m: 0.5 * model.rope_total_length_m,
            started: false,
            last_count: 0,
            counts: 0,
            start_counts: 0,
            origin_counts: 0,
            last_torque_nm: 0.0,
            x: StateVector::zeros(),
            p: [[0.0; STATES]; STATES],
            phi: Matrix6::identity(),
            psi: Matrix6::zeros(),
            gamma: Vector6::zeros(),
            chain,
            ticks_to_schedule: 0,
            restarts: 0,
            estimate: ObserverEstimate::default(),
        };
        observer.reset_filter();
        Ok(observer)
    }

    /// Starts a travel: the chain at rest in its static equilibrium (brake
    /// just lifted), counterweight-side length `lw_start_m` (m), car mass
    /// `m_car_kg` (kg, load weighing), encoder counter `encoder_count` now.
    /// A length outside the rope or a mass that is not positive is clamped
    /// (to the model's range, and to the counterweight mass).
    pub fn start(&mut self, lw_start_m: f32, m_car_kg: f32, encoder_count: u32) {
        let (lw, _) = self.model.rope_lengths_m(lw_start_m);
        self.lw_start_m = lw;
        self.m_car_kg = if m_car_kg.is_finite() && m_car_kg > 0.0 { m_car_kg } else { self.model.m_cw_kg };
        self.last_count = encoder_count;
        self.counts = 0;
        self.start_counts = 0;
        self.origin_counts = 0;
        self.last_torque_nm = self.model.out_of_balance_torque_nm(lw, self.m_car_kg);
        self.started = true;
        self.reset_filter();
    }

    fn reset_filter(&mut self) {
        self.x = StateVector::zeros();
        self.x[EA_SCALE] = 1.0;
        let t = &self.tuning;
        let step = self.metres_per_count;
        let mut p: Covariance = [[0.0; STATES]; STATES];
        // At rest: position within a count, speeds and stretches tiny.
        for (i, row) in p.iter_mut().enumerate().take(MECHANICAL_STATES) {
            row[i] = if i % 2 == 0 { step * step } else { 1.0e-6 };
        }
        p[EA_SCALE][EA_SCALE] = t.ea_scale_initial_sd * t.ea_scale_initial_sd;
        let d2 = t.disturbance_initial_sd_nm * t.disturbance_initial_sd_nm;
        p[DISTURBANCE_BIAS][DISTURBANCE_BIAS] = d2;
        for (slot, &order) in self.model.ripple_orders.iter().enumerate() {
            if order != 0 {
                let i = FIRST_HARMONIC + 2 * slot;
                p[i][i] = d2;
                p[i + 1][i + 1] = d2;
            }
        }
        self.p = p;
        self.ticks_to_schedule = 0;
        self.estimate = self.outputs(&self.disturbance_regressor());
    }

    /// True once [`ChainObserver::start`] has been called.
    pub fn is_started(&self) -> bool {
        self.started
    }

    /// How often the filter found a non-finite value and restarted itself
    /// from rest at the current position (0 in normal operation).
    pub fn restarts(&self) -> u32 {
        self.restarts
    }

    /// The last estimate.
    pub fn estimate(&self) -> ObserverEstimate {
        self.estimate
    }

    /// Posterior variance of the stiffness scale (dimensionless), from the
    /// diagonal of the covariance.
    pub fn ea_scale_variance(&self) -> f32 {
        self.p[EA_SCALE][EA_SCALE]
    }

    /// Counterweight-side rope length from the encoder (Eqn 3), m.
    fn counterweight_side_length_m(&self) -> f32 {
        self.lw_start_m + (self.counts - self.start_counts) as f32 * self.metres_per_count
    }

    /// `[1, cos(n_1 theta), sin(n_1 theta), ...]`: the regressor of the
    /// disturbance states at the encoder angle (unused slots 0).
    fn disturbance_regressor(&self) -> SVector<f32, DISTURBANCE_STATES> {
        let cpr = self.model.encoder_counts_per_rev;
        let within_rev = self.last_count % cpr;
        let mut h = SVector::<f32, DISTURBANCE_STATES>::zeros();
        h[0] = 1.0;
        for (slot, &order) in self.model.ripple_orders.iter().enumerate() {
            if order == 0 {
                continue;
            }
            let product = within_rev as u64 * order as u64;
            // The same remainder; in 32 bits (one hardware division on the
            // chip instead of a 64-bit library call) whenever it fits.
            let nth = match u32::try_from(product) {
                Ok(p) => (p % cpr) as u64,
                Err(_) => product % cpr as u64,
            };
            let angle = ((nth * self.binary_angle_per_count_q16) >> 16) as u32;
            let (sin, cos) = sin_cos(angle);
            const Q30: f32 = 1.0 / (1u32 << 30) as f32;
            h[1 + 2 * slot] = cos.to_bits() as f32 * Q30;
            h[2 + 2 * slot] = sin.to_bits() as f32 * Q30;
        }
        h
    }

    /// The estimate of the current state; `h` is
    /// [`ChainObserver::disturbance_regressor`] at the current count.
    fn outputs(&self, h: &SVector<f32, DISTURBANCE_STATES>) -> ObserverEstimate {
        let mech: Vector6 = self.x.fixed_rows::<MECHANICAL_STATES>(0).into_owned();
        let c = &self.chain;
        let disturbance = self.x.fixed_rows::<DISTURBANCE_STATES>(DISTURBANCE_BIAS).dot(h);
        ObserverEstimate {
            car_acceleration_mps2: c.car_acceleration_mps2(&mech),
            car_rope_force_n: c.car_stiffness_n_per_m * mech[CAR_STRETCH],
            counterweight_rope_force_n: c.cw_stiffness_n_per_m * mech[CW_STRETCH],
            shaft_disturbance_torque_nm: disturbance,
            rope_ea_n: self.x[EA_SCALE] * self.model.rope_ea_n,
            sheave_speed_mps: mech[SHEAVE_SPEED],
            counterweight_side_length_m: self.counterweight_side_length_m(),
        }
    }

    /// Riccati step without the noise, `P <- F P F^T`, with `F` the identity
    /// but for its first six rows `[Phi | s | gamma h^T / r]` (`s` the
    /// derivative of the mechanical prediction with respect to the stiffness
    /// scale, `h` the disturbance regressor). Rows 6-17 of `F P` are those
    /// of `P`, so only rows 0-5 of `F P` are computed, with the disturbance
    /// block as one row `w = (h / r)^T P_{7.., :}` scaled by `gamma`; the
    /// 6 x 6 corner `F P F^T` is symmetric, one triangle is computed.
    fn riccati_step(&mut self, s: &Vector6, h: &SVector<f32, DISTURBANCE_STATES>) {
        const M: usize = MECHANICAL_STATES;
        let r = self.model.sheave_radius_m;
        let hr: [f32; DISTURBANCE_STATES] = core::array::from_fn(|d| h[d] / r);
        let gamma = self.gamma;
        let phi = &self.phi;
        let p = &self.p;
        // w = (h / r)^T P_{7.., :}
        let mut w = [0.0f32; STATES];
        for (c, row) in hr.iter().zip(&p[DISTURBANCE_BIAS..]) {
            for (wk, pk) in w.iter_mut().zip(row) {
                *wk += c * pk;
            }
        }
        // Rows 0-5 of F P.
        let mut fp = [[0.0f32; STATES]; M];
        for (i, fp_row) in fp.iter_mut().enumerate() {
            let phi_row: [f32; M] = core::array::from_fn(|m| phi[(i, m)]);
            for (k, out) in fp_row.iter_mut().enumerate() {
                let mut acc = 0.0;
                for (f, p_row) in phi_row.iter().zip(&p[..M]) {
                    acc += f * p_row[k];
                }
                *out = acc + s[i] * p[EA_SCALE][k] + gamma[i] * w[k];
            }
        }
        // u = (rows 0-5 of F P)_{:, 7..} h / r
        let u: [f32; M] = core::array::from_fn(|i| {
            let mut acc = 0.0;
            for (f, c) in fp[i][DISTURBANCE_BIAS..].iter().zip(&hr) {
                acc += f * c;
            }
            acc
        });
        let p = &mut self.p;
        for (i, fp_row) in fp.iter().enumerate() {
            for k in M..STATES {
                p[i][k] = fp_row[k];
                p[k][i] = fp_row[k];
            }
            for j in i..M {
                let mut acc = 0.0;
                for m in 0..M {
                    acc += fp_row[m] * phi[(j, m)];
                }
                let v = acc + fp_row[EA_SCALE] * s[j] + u[i] * gamma[j];
                p[i][j] = v;
                p[j][i] = v;
            }
        }
    }

    /// One tick: `encoder_count` is the free-running (wrapping) encoder
    /// counter now; `motor_torque_nm` the machine torque `Kt i_q` (N m, from
    /// the measured q current) that acts until the next tick. A non-finite
    /// torque is replaced by the last finite one, a torque beyond
    /// `+-1e5 N m` is clamped. Before [`ChainObserver::start`] the observer
    /// only follows the encoder and returns zeros.
    pub fn update(&mut self, encoder_count: u32, motor_torque_nm: f32) -> ObserverEstimate {
        // Modular difference of a wrapping counter.
        let delta = encoder_count.wrapping_sub(self.last_count) as i32;
        self.last_count = encoder_count;
        self.counts = self.counts.saturating_add(delta as i64);
        if !self.started {
            return self.estimate;
        }
        if motor_torque_nm.is_finite() {
            self.last_torque_nm = motor_torque_nm.clamp(-1.0e5, 1.0e5);
        }

        // Measurement update, H = e_0 (sheave-edge position): the gain is
        // column 0 of P over the innovation variance, and P loses
        // `gain p_0^T`, symmetric: one triangle computed, both halves written.
        let measured_m = (self.counts - self.origin_counts) as f32 * self.metres_per_count;
        let step = self.metres_per_count;
        let p0 = self.p[SHEAVE_POSITION];
        let inverse_innovation_var = 1.0 / (p0[SHEAVE_POSITION] + step * step / 12.0);
        let innovation = measured_m - self.x[SHEAVE_POSITION];
        let gain: [f32; STATES] = core::array::from_fn(|i| p0[i] * inverse_innovation_var);
        for (x, g) in self.x.iter_mut().zip(gain) {
            *x += g * innovation;
        }
        for (j, &p0j) in p0.iter().enumerate() {
            for (i, &g) in gain[..=j].iter().enumerate() {
                let v = self.p[i][j] - g * p0j;
                self.p[i][j] = v;
                self.p[j][i] = v;
            }
        }
        self.x[EA_SCALE] = self.x[EA_SCALE].max(self.tuning.ea_scale_min).min(self.tuning.ea_scale_max);

        // Keep state 0 within one count of the origin: f32 resolves the
        // stretch of the ropes next to a small position, not next to metres.
        let shift = (self.x[SHEAVE_POSITION] / step) as i32;
        self.origin_counts += shift as i64;
        self.x[SHEAVE_POSITION] -= shift as f32 * step;

        let lw = self.counterweight_side_length_m();
        let kappa = self.x[EA_SCALE];
        if self.ticks_to_schedule == 0 {
            self.chain = self.model.reduced(lw, self.m_car_kg, kappa);
            let (psi, phi) = discretise(&self.chain.system_matrix(), self.dt_s, self.tuning.series_terms);
            self.psi = psi;
            self.phi = phi;
            self.gamma = psi * self.chain.sheave_force_input();
            self.ticks_to_schedule = self.tuning.reschedule_ticks;
        }
        self.ticks_to_schedule -= 1;
        let h = self.disturbance_regressor();
        self.estimate = self.outputs(&h);

        // Prediction to the next tick.
        let r = self.model.sheave_radius_m;
        let mech: Vector6 = self.x.fixed_rows::<MECHANICAL_STATES>(0).into_owned();
        let disturbance = self.x.fixed_rows::<DISTURBANCE_STATES>(DISTURBANCE_BIAS).dot(&h);
        let force_n = (self.last_torque_nm - self.model.out_of_balance_torque_nm(lw, self.m_car_kg) + disturbance) / r;
        let gamma = self.gamma;
        let stiffness_column: Vector6 = self.psi * self.chain.dynamics_per_stiffness_scale(&mech, kappa);
        let next = self.phi * mech + gamma * force_n;
        self.x.fixed_rows_mut::<MECHANICAL_STATES>(0).copy_from(&next);
        self.riccati_step(&stiffness_column, &h);

        let t = &self.tuning;
        let dt = self.dt_s;
        self.p[SHEAVE_SPEED][SHEAVE_SPEED] += t.sheave_acceleration_noise * dt;
        self.p[EA_SCALE][EA_SCALE] += t.ea_scale_noise_per_s * dt;
        self.p[DISTURBANCE_BIAS][DISTURBANCE_BIAS] += t.disturbance_noise * dt;
        for (slot, &order) in self.model.ripple_orders.iter().enumerate() {
            if order != 0 {
                let i = FIRST_HARMONIC + 2 * slot;
                self.p[i][i] += t.ripple_noise * dt;
                self.p[i + 1][i + 1] += t.ripple_noise * dt;
            }
        }

        // P is symmetric: its upper triangle holds every value.
        let finite = self.x.iter().all(|v| v.is_finite())
            && self.p.iter().enumerate().all(|(i, row)| row[i..].iter().all(|v| v.is_finite()));
        if !finite || self.p[0][0] < 0.0 {
            self.restarts = self.restarts.saturating_add(1);
            self.origin_counts = self.counts;
            self.reset_filter();
        }
        self.estimate
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::super::model::tests::rig_model;
    use super::*;
    use std::println;
    use std::vec::Vec;

    /// The 3-mass chain in f64 with a true EA of `ea_scale` times nominal, a
    /// 12th-order ripple and a constant friction error on the shaft, under a
    /// speed controller that drives the car up at 0.4 m/s from `lw = 1 m`.
    /// Returns per 2 kHz tick: (encoder count, machine torque N m, true car
    /// acceleration m/s^2, true disturbance torque N m).
    fn simulate_own_model(ea_scale: f64, seconds: f64) -> Vec<(u32, f32, f64, f64)> {
        let m = rig_model();
        let (m_car, lw0) = (58.0, 1.0);
        let r = m.sheave_radius_m as f64;
        let mu = m.rope_mass_per_length_kg_per_m as f64;
        let lt = m.rope_total_length_m as f64;
        let disturbance = |theta: f64| 3.5 * libm_free_cos(12.0 * theta + 0.7) + 1.5;
        let derivative = |x: &[f64; 6], torque: f64| -> [f64; 6] {
            let lw = lw0 + x[0];
            let lc = lt - lw;
            let (kc, kw) = (ea_scale * m.rope_ea_n as f64 / lc, ea_scale * m.rope_ea_n as f64 / lw);
            let mc = m_car + mu * lc / 2.0;
            let mw = m.m_cw_kg as f64 + mu * lw / 2.0;
            let msh = m.sheave_inertia_kg_m2 as f64 / (r * r) + mu * lt / 2.0;
            let oob = (m_car - m.m_cw_kg as f64 + mu * (lc - lw)) * m.gravity_mps2 as f64 * r;
            let force = (torque + disturbance(x[0] / r) - oob) / r;
            let [_, v, ec, vc, ew, vw] = *x;
            [
                v,
                (force - m.c_sheave_nms_per_rad as f64 / (r * r) * v - kc * ec - kw * ew) / msh,
                v - vc,
                (kc * ec - m.c_car_kg_per_s as f64 * vc) / mc,
                v - vw,
                (kw * ew - m.c_cw_kg_per_s as f64 * vw) / mw,
            ]
        };
        let dt = 1.0 / 2000.0;
        let substeps = 20;
        let h = dt / substeps as f64;
        let mut x = [0.0f64; 6];
        let mut integral = 0.0;
        let mut out = Vec::new();
        for k in 0..(seconds / dt) as usize {
            let t = k as f64 * dt;
            let speed_ref = (0.5 * t).min(0.4);
            let lw = lw0 + x[0];
            let oob = (m_car - m.m_cw_kg as f64 + mu * (lt - 2.0 * lw)) * m.gravity_mps2 as f64 * r;
            integral += (speed_ref - x[1]) * dt;
            let torque = oob + 400.0 * (speed_ref - x[1]) * r * 40.0 + 4000.0 * integral * r;
            let theta = x[0] / r;
            let count = libm_free_floor(theta / core::f64::consts::TAU * m.encoder_counts_per_rev as f64);
            let d = derivative(&x, torque);
            let car_acc = d[3];
            out.push((count as i64 as u32, torque as f32, car_acc, disturbance(theta)));
            for _ in 0..substeps {
                let add = |a: &[f64; 6], k: &[f64; 6], s: f64| core::array::from_fn::<f64, 6, _>(|i| a[i] + s * k[i]);
                let k1 = derivative(&x, torque);
                let k2 = derivative(&add(&x, &k1, h / 2.0), torque);
                let k3 = derivative(&add(&x, &k2, h / 2.0), torque);
                let k4 = derivative(&add(&x, &k3, h), torque);
                x = core::array::from_fn(|i| x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]));
            }
        }
        out
    }

    // std's f64 methods are available to the test build (std is linked).
    fn libm_free_cos(x: f64) -> f64 {
        x.cos()
    }
    fn libm_free_floor(x: f64) -> f64 {
        x.floor()
    }

    fn rms(values: impl Iterator<Item = f64>) -> f64 {
        let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v * v, n + 1));
        (sum / n as f64).sqrt()
    }

    #[test]
    fn converges_on_data_of_its_own_model_and_identifies_ea() {
        let mut results = Vec::new();
        for ea_scale in [1.0, 1.15, 0.85] {
            let data = simulate_own_model(ea_scale, 8.0);
            let mut observer = ChainObserver::new(rig_model(), ObserverTuning::default()).unwrap();
            observer.start(1.0, 58.0, data[0].0);
            let estimates: Vec<ObserverEstimate> = data.iter().map(|&(c, tq, _, _)| observer.update(c, tq)).collect();
            // Last 3 s (constant speed from 0.8 s on).
            let tail = data.len() - 6000..data.len();
            let truth =
                rms(tail.clone().map(|i| data[i].2 - data[tail.start..].iter().map(|d| d.2).sum::<f64>() / 6000.0));
            let error = rms(tail.clone().map(|i| estimates[i].car_acceleration_mps2 as f64 - data[i].2));
            let torque_error = rms(tail.clone().map(|i| estimates[i].shaft_disturbance_torque_nm as f64 - data[i].3));
            let ea = observer.estimate().rope_ea_n as f64 / 1.0e6;
            println!(
                "EA x{ea_scale}: car acceleration error RMS {error:.4} m/s^2 of {truth:.4} m/s^2 ({:.2} %), \
                 disturbance torque error RMS {torque_error:.3} N m, EA scale {ea:.4}",
                100.0 * error / truth
            );
            results.push((ea_scale, error / truth, torque_error, ea));
        }
        for (ea_scale, ratio, torque_error, ea) in results {
            assert!(ratio < 0.10, "EA x{ea_scale}: car acceleration error {:.1} % of the vibration", 100.0 * ratio);
            // The ripple is 3.5 N m (2.5 N m RMS).
            assert!(torque_error < 1.0, "EA x{ea_scale}: disturbance torque error {torque_error} N m");
            assert!((ea - ea_scale).abs() < 0.03, "EA x{ea_scale}: estimated scale {ea}");
        }
    }

    #[test]
    fn extreme_inputs_give_finite_estimates() {
        let mut observer = ChainObserver::new(rig_model(), ObserverTuning::default()).unwrap();
        // Before start: zeros, no NaN.
        let e = observer.update(12345, f32::NAN);
        assert_eq!(e.car_acceleration_mps2, 0.0);
        assert!(e.counterweight_side_length_m.is_finite());
        observer.start(f32::NAN, -5.0, u32::MAX - 3);
        let inputs = [
            (u32::MAX, f32::NAN),
            (5, f32::INFINITY),
            (5, f32::NEG_INFINITY),
            (1 << 31, 1.0e30),
            (0, -1.0e30),
            (7, f32::MIN_POSITIVE),
            (u32::MAX / 3, 0.0),
        ];
        for k in 0..2000 {
            let (count, torque) = inputs[k % inputs.len()];
            let e = observer.update(count.wrapping_add(k as u32), torque);
            let values = [
                e.car_acceleration_mps2,
                e.car_rope_force_n,
                e.counterweight_rope_force_n,
                e.shaft_disturbance_torque_nm,
                e.rope_ea_n,
                e.sheave_speed_mps,
                e.counterweight_side_length_m,
            ];
            assert!(values.iter().all(|v| v.is_finite()), "tick {k}: {e:?}");
        }
        println!("after 2000 ticks of garbage: {:?}, restarts {}", observer.estimate(), observer.restarts());
        let ea = observer.estimate().rope_ea_n;
        assert!((0.5e6..=2.0e6).contains(&ea), "EA estimate {ea} outside the tuning bounds");
    }

    /// The structured Riccati step against `F P F^T` with the dense `F`,
    /// in f64, on the covariance of a converged filter; the covariance stays
    /// exactly symmetric.
    #[test]
    fn riccati_step_is_the_dense_product_and_keeps_p_symmetric() {
        let data = simulate_own_model(1.1, 2.0);
        let mut observer = ChainObserver::new(rig_model(), ObserverTuning::default()).unwrap();
        observer.start(1.0, 58.0, data[0].0);
        for &(count, torque, _, _) in &data {
            observer.update(count, torque);
            assert!((0..STATES).all(|i| (0..STATES).all(|j| observer.p[i][j].to_bits() == observer.p[j][i].to_bits())));
        }
        let s = Vector6::from_fn(|i, _| 1.0e-4 * (i as f32 - 2.5));
        let h = observer.disturbance_regressor();
        let r = observer.model.sheave_radius_m as f64;
        let f: [[f64; STATES]; STATES] = core::array::from_fn(|i| {
            core::array::from_fn(|k| match k {
                _ if i >= MECHANICAL_STATES => f64::from(u8::from(i == k)),
                k if k < MECHANICAL_STATES => observer.phi[(i, k)] as f64,
                EA_SCALE => s[i] as f64,
                k => observer.gamma[i] as f64 * h[k - DISTURBANCE_BIAS] as f64 / r,
            })
        });
        let p = observer.p.map(|row| row.map(f64::from));
        let fp: Vec<Vec<f64>> =
            (0..STATES).map(|i| (0..STATES).map(|k| (0..STATES).map(|m| f[i][m] * p[m][k]).sum()).collect()).collect();
        let fpf: Vec<Vec<f64>> =
            (0..STATES).map(|i| (0..STATES).map(|j| (0..STATES).map(|k| fp[i][k] * f[j][k]).sum()).collect()).collect();
        observer.riccati_step(&s, &h);
        let mut worst: f64 = 0.0;
        for i in 0..STATES {
            for j in 0..STATES {
                let v = observer.p[i][j];
                assert_eq!(v.to_bits(), observer.p[j][i].to_bits(), "({i}, {j})");
                let scale = (fpf[i][i] * fpf[j][j]).sqrt();
                worst = worst.max((v as f64 - fpf[i][j]).abs() / scale);
            }
        }
        println!("largest difference to the dense f64 product, relative to sqrt(P_ii P_jj): {worst:.2e}");
        assert!(worst < 1.0e-4, "{worst}");
    }

    #[test]
    fn bad_tuning_is_named() {
        let tuning = ObserverTuning { reschedule_ticks: 0, ..ObserverTuning::default() };
        assert_eq!(ChainObserver::new(rig_model(), tuning).unwrap_err().field, "reschedule_ticks");
        let tuning = ObserverTuning { ea_scale_max: 0.1, ..ObserverTuning::default() };
        assert_eq!(ChainObserver::new(rig_model(), tuning).unwrap_err().field, "ea_scale_max");
        let tuning = ObserverTuning { update_hz: f32::NAN, ..ObserverTuning::default() };
        assert_eq!(ChainObserver::new(rig_model(), tuning).unwrap_err().field, "update_hz");
    }
}
