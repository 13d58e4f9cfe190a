//! The plant's default integrator, [`super::Integrator::Fast`]: classical
//! RK4 like [`super::Integrator::Reference`], with what changes slowly evaluated once per
//! step instead of at every stage.
//!
//! - Masses, springs, damping and the out-of-balance torque (functions of
//!   the rope lengths, so of the sheave position) are evaluated once per
//!   step at the step's predicted midpoint `u_sh + v_sh h / 2`. The rope
//!   lengths change by `v h` (at most 12.5 um at 0.4 m/s in a 31 us step,
//!   1.25e-5 of the shortest 1 m side); the midpoint rule makes the error
//!   of holding them second order in that change, about 1e-10 of the
//!   elastic forces.
//! - The ripple torque and the Park rotation come from Taylor polynomials
//!   of the shaft angle ([`super::angle::AngleSeries`]), exact to a few ulps.
//! - The line's forces are [`super::line::Line::accelerations_with`]'s (the
//!   one derivative of the line, [`super::spring_line`]), with the masses
//!   inverted once per step.
//!
//! On the nominal 5-DOF chain [`Plant::advance_until`] takes the exact
//! discretisation ([`super::exact`]) instead, where [`Plant::nominal_path`]
//! allows it.

use super::line::{Coefficients, Lumped};
use super::pmsm::phase_currents_cs_a;
use super::rope::{CAR, DOF};
use super::{rk4_step_in, Plant, PlantObservation, MAX_STATE_LEN};

impl Plant {
    /// True when the plant is the nominal chain that the exact
    /// discretisation ([`super::exact`]) holds: the 5-DOF layout, no
    /// mechanical effect beyond the lumped values (a force at the guides,
    /// the brake clamp while the brake is applied, the eccentric sheave), no
    /// dead time, no open phase. The brake clamp acts only while the brake
    /// is applied: released, the plant with it is the nominal chain.
    pub(crate) fn nominal_path(&self) -> bool {
        let e = &self.effects;
        self.line.layout.nodes == DOF
            && self.line.layout.body == CAR
            && !e.acts_at_guides()
            && !self.clamped()
            && e.sheave_eccentricity.is_none()
            && e.dead_time.is_none()
            && self.faults.open_phase.is_none()
    }

    /// `steps` RK4 steps of `h` (s) with [`super::Integrator::Fast`].
    pub(crate) fn advance_fast(&mut self, steps: usize, h: f64) {
        let len = self.state_len();
        // The RK4's work space is kept from call to call (no zeroing of a
        // fresh one each time), with the state stepped in its first `len`
        // values: only the used part of the state is copied out and back.
        let mut work = std::mem::take(&mut self.rk4_work);
        if work.len() < 6 * len {
            work.resize(6 * len, 0.0);
        }
        let (state, rk4_work) = work.split_at_mut(len);
        state.copy_from_slice(&self.state[..len]);
        // One buffer of masses and springs, refilled at each step.
        let mut lumped = Lumped::zeroed();
        for _ in 0..steps {
            let theta = self.shaft_angle_rad(state);
            self.angle.ensure(theta, &self.ripple, self.pmsm.pole_pairs);
            self.midpoint_lumped_into(state, h, &mut lumped);
            let step = self.line.coefficients(&self.chain, &lumped);
            rk4_step_in(state, h, rk4_work, |y, dy| self.line_step_derivative(&step, y, dy));
        }
        self.state[..len].copy_from_slice(state);
        self.rk4_work = work;
        let theta = self.shaft_angle_rad(&self.state);
        self.angle.ensure(theta, &self.ripple, self.pmsm.pole_pairs);
    }

    /// Masses, springs and damping at the predicted midpoint of a step of
    /// `h` (s) from the node positions and velocities in `y`.
    fn midpoint_lumped(&self, y: &[f64], h: f64) -> Lumped {
        let mut out = Lumped::zeroed();
        self.midpoint_lumped_into(y, h, &mut out);
        out
    }

    /// [`Plant::midpoint_lumped`] written into `out` ([`super::line::Line::lumped_into`]).
    fn midpoint_lumped_into(&self, y: &[f64], h: f64, out: &mut Lumped) {
        let (n, sheave) = (self.nodes(), self.line.layout.sheave);
        self.line.lumped_into(&self.chain, y[sheave] + 0.5 * h * y[n + sheave], out);
    }

    /// Time derivative `dy` of the state `y` with the line's coefficients
    /// over the step `step`: the motor and brake ([`Plant::motor_and_brake`])
    /// with the angle-locked terms from the polynomials, the line's
    /// accelerations ([`super::line::Line::accelerations_with`]).
    fn line_step_derivative(&self, step: &Coefficients, y: &[f64], dy: &mut [f64]) {
        let n = self.nodes();
        let sheave = self.line.layout.sheave;
        let r = self.chain.params.sheave_radius_m;
        let theta_m = y[sheave] / r;
        let omega_m = y[n + sheave] / r;
        let p = self.pmsm.pole_pairs;
        let (ripple, c, s) = self.angle.eval(theta_m, &self.ripple, p);
        let (torque, brake) = self.motor_and_brake(y, dy, p * theta_m, p * omega_m, ripple, |id, iq| {
            let (va, vb) = self.machine_v_alpha_beta_cs(id, iq, c, s);
            (va * c + vb * s, -va * s + vb * c)
        });
        let (position, velocity) = (&y[..n], &y[n..2 * n]);
        let extra = self.faults.car_extra_force_n;
        self.line.accelerations_with(step, position, velocity, torque, brake, extra, &mut dy[n..2 * n]);
    }

    /// [`Plant::observe`] with [`super::Integrator::Fast`]: masses and springs at
    /// the sheave's position now, the angle-locked terms from the
    /// polynomials.
    pub(crate) fn observe_fast(&self) -> PlantObservation {
        let n = self.nodes();
        let layout = &self.line.layout;
        let (id, iq) = (self.state[2 * n], self.state[2 * n + 1]);
        let theta_m = self.shaft_angle_rad(&self.state);
        let (ripple, c, s) = self.angle.eval(theta_m, &self.ripple, self.pmsm.pole_pairs);
        let lumped = self.midpoint_lumped(&self.state, 0.0);
        let mut dy = [0.0; MAX_STATE_LEN];
        self.line_step_derivative(&self.line.coefficients(&self.chain, &lumped), &self.state, &mut dy);
        let (car, cw) = (dy[n + layout.body], dy[n + layout.counterweight()]);
        let r = self.chain.params.sheave_radius_m;
        PlantObservation {
            car_acceleration_mps2: car,
            counterweight_acceleration_mps2: -cw,
            phase_currents_a: self.leg_currents_a(phase_currents_cs_a(id, iq, c, s)),
            motor_torque_nm: self.pmsm.torque_nm(id, iq),
            ripple_torque_nm: ripple,
            shaft_speed_radps: self.state[n + layout.sheave] / r,
            shaft_angle_rad: theta_m,
            counterweight_side_length_m: self.line.counterweight_side_length_m(&self.chain, self.state[layout.sheave]),
            car_position_m: self.state[layout.body],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{SHEAVE, STATE_LEN};
    use super::*;
    use rig_config::RigConfig;

    /// The fast derivative of the nominal line (the angle-locked terms from
    /// the polynomials) equals the reference one (masses and springs at the
    /// same position) to rounding, at states away from rest, brake released
    /// and held, PWM on.
    #[test]
    fn nominal_derivative_matches_the_reference() {
        let rig = RigConfig::embedded_default().unwrap();
        for (m_car, lw, seed) in [(70.5, 1.3, 1.0), (33.0, 7.2, -2.0), (45.5, 4.0, 0.5)] {
            for brake in [false, true] {
                let mut plant = Plant::new(&rig, m_car, lw);
                plant.set_inputs(super::super::PlantInputs {
                    pwm_compare: [700, 1500, 2600],
                    pwm_enabled: true,
                    brake_engaged: brake,
                });
                let mut y = [0.0; MAX_STATE_LEN];
                for (i, slot) in y[..STATE_LEN].iter_mut().enumerate() {
                    *slot = seed * if i < DOF { 1e-4 * (i as f64 + 0.3).sin() } else { 0.3 * (i as f64 * 1.7).cos() };
                }
                y[SHEAVE] = 0.37 * seed;
                plant.state = y;
                plant.set_integrator(super::super::Integrator::Fast);
                let mut reference = [0.0; MAX_STATE_LEN];
                plant.derivative(&y, &mut reference);
                let lumped = plant.midpoint_lumped(&y, 0.0);
                let mut fast = [0.0; MAX_STATE_LEN];
                plant.line_step_derivative(&plant.line.coefficients(&plant.chain, &lumped), &y, &mut fast);
                for i in 0..STATE_LEN {
                    let scale = reference[i].abs().max(1.0);
                    assert!((fast[i] - reference[i]).abs() < 1e-9 * scale, "{i}: {} vs {}", fast[i], reference[i]);
                }
            }
        }
    }
}
