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
//! - The nominal 5-DOF line (no mechanical effect that changes its
//!   arithmetic, no dead time, no open phase) takes a fixed-size path:
//!   `[f64; 12]` state, spring tensions instead of the general line's
//!   loops, no allocation, no dynamic dispatch.

use super::line::{BrakeAction, Lumped, MAX_NODES};
use super::pmsm::phase_currents_cs_a;
use super::rope::{CAR, DOF, SHEAVE};
use super::{rk4_step, rk4_step_in, Plant, PlantObservation, MAX_STATE_LEN, STATE_LEN};

/// The nominal line's coefficients over one step (or at one instant).
struct NominalStep<'a> {
    /// The plant (machine, ripple, inputs, angle polynomials).
    plant: &'a Plant,
    /// `1 / m_i`, 1/kg.
    inv_mass: [f64; DOF],
    /// Spring `i` joins nodes `i` and `i + 1`, N/m.
    spring: [f64; DOF - 1],
    /// Viscous damping on absolute velocities, kg/s.
    damping: [f64; DOF],
    /// `1 / r`, 1/m.
    inv_r: f64,
    /// Out-of-balance torque of Eqn 4, N m.
    out_of_balance_nm: f64,
    /// The brake holds the sheave rigidly.
    held: bool,
}

impl<'a> NominalStep<'a> {
    /// The coefficients of `plant` with its line lumped as `lumped`.
    fn new(plant: &'a Plant, lumped: &Lumped) -> Self {
        let p = &plant.chain.params;
        let mut inv_mass = [0.0; DOF];
        let mut spring = [0.0; DOF - 1];
        let mut damping = [0.0; DOF];
        for i in 0..DOF {
            inv_mass[i] = 1.0 / lumped.masses_kg[i];
            damping[i] = lumped.damping_kg_per_s[i];
        }
        spring.copy_from_slice(&lumped.springs_n_per_m[..DOF - 1]);
        Self {
            plant,
            inv_mass,
            spring,
            damping,
            inv_r: 1.0 / p.sheave_radius_m,
            out_of_balance_nm: p.out_of_balance_torque_nm(lumped.lw_m),
            held: plant.inputs.brake_engaged,
        }
    }

    /// Time derivative of the nominal state `y` (positions m, velocities
    /// m/s, `i_d`, `i_q` A).
    fn derivative(&self, y: &[f64; STATE_LEN]) -> [f64; STATE_LEN] {
        let plant = self.plant;
        let pole_pairs = plant.pmsm.pole_pairs;
        let theta = y[SHEAVE] * self.inv_r;
        let (ripple, c, s) = plant.angle.eval(theta, &plant.ripple, pole_pairs);
        let mut dy = [0.0; STATE_LEN];
        // The nominal path has no dead time: the inverter's voltages.
        let (va, vb) = plant.v_alpha_beta;
        let omega_e = pole_pairs * y[DOF + SHEAVE] * self.inv_r;
        let (torque, _) = plant.motor_and_brake(y, &mut dy, pole_pairs * theta, omega_e, ripple, |_, _| {
            (va * c + vb * s, -va * s + vb * c)
        });
        let (u, v) = (&y[..DOF], &y[DOF..2 * DOF]);
        // Spring tensions (extension times stiffness), N.
        let k = &self.spring;
        let t = [k[0] * (u[1] - u[0]), k[1] * (u[2] - u[1]), k[2] * (u[3] - u[2]), k[3] * (u[4] - u[3])];
        let force = [
            t[0],
            t[1] - t[0],
            t[2] - t[1] + (torque - self.out_of_balance_nm) * self.inv_r,
            t[3] - t[2],
            -t[3] + plant.faults.car_extra_force_n,
        ];
        for i in 0..DOF {
            dy[DOF + i] = (force[i] - self.damping[i] * v[i]) * self.inv_mass[i];
        }
        if self.held {
            dy[DOF + SHEAVE] = 0.0;
        }
        dy
    }
}

/// The general line's coefficients over one step: the lumped values with
/// the masses inverted once, the out-of-balance torque evaluated once, and
/// the forces written as spring tensions (no division, no branch per node
/// in the stages). With `sheave_eccentricity` the line's own
/// [`super::line::Line::accelerations_of`] runs instead (its lever ratio
/// changes at every stage).
struct LineStep<'a> {
    /// The lumped values (for the eccentric sheave's path).
    lumped: &'a Lumped,
    /// `1 / m_i`, 1/kg (the first `nodes`).
    inv_mass: [f64; MAX_NODES],
    /// Out-of-balance torque of Eqn 4, N m.
    out_of_balance_nm: f64,
}

impl<'a> LineStep<'a> {
    fn new(plant: &Plant, lumped: &'a Lumped) -> Self {
        let mut inv_mass = [0.0; MAX_NODES];
        // A side's rope elements share one mass: one division each run of
        // equal masses.
        let mut last = (f64::NAN, f64::NAN);
        for (inv, &m) in inv_mass.iter_mut().zip(&lumped.masses_kg).take(plant.nodes()) {
            if m != last.0 {
                last = (m, 1.0 / m);
            }
            *inv = last.1;
        }
        let out_of_balance_nm = plant.chain.params.out_of_balance_torque_nm(lumped.lw_m);
        Self { lumped, inv_mass, out_of_balance_nm }
    }
}

impl Plant {
    /// Node accelerations (m/s^2) into `accel` as
    /// [`super::line::Line::accelerations_of`] gives them (to rounding), with
    /// the step's coefficients `step`, and the velocities copied into
    /// `rates` (`out = (rates, accel)`; a copy in the loop rather than a
    /// library call for a few dozen values).
    #[allow(clippy::too_many_arguments)]
    fn line_accelerations(
        &self,
        step: &LineStep,
        position: &[f64],
        velocity: &[f64],
        shaft_torque_nm: f64,
        brake: BrakeAction,
        car_extra_force_n: f64,
        out: (&mut [f64], &mut [f64]),
    ) {
        let (rates, accel) = out;
        let line = &self.line;
        let lumped = step.lumped;
        if line.effects.sheave_eccentricity.is_some() {
            rates.copy_from_slice(&velocity[..rates.len()]);
            line.accelerations_of(
                &self.chain,
                lumped,
                position,
                velocity,
                shaft_torque_nm,
                brake,
                car_extra_force_n,
                accel,
            );
            return;
        }
        let layout = &line.layout;
        let n = layout.nodes;
        let sheave = layout.sheave;
        let r = self.chain.params.sheave_radius_m;
        let mut torque = shaft_torque_nm;
        if let BrakeAction::Clamped { angle_rad } = brake {
            if let Some(clamp) = &line.effects.brake_stop {
                torque += clamp.torque_nm(position[sheave] / r, angle_rad, velocity[sheave] / r);
            }
        }
        let (k, c, inv_m) = (&lumped.springs_n_per_m[..n], &lumped.damping_kg_per_s[..n], &step.inv_mass[..n]);
        let (x, v, a) = (&position[..n], &velocity[..n], &mut accel[..n]);
        // Net spring force on node i: tension of spring i minus that of i - 1.
        let rates = &mut rates[..n];
        let mut below = 0.0;
        for i in 0..n - 1 {
            let tension = k[i] * (x[i + 1] - x[i]);
            a[i] = (tension - below - c[i] * v[i]) * inv_m[i];
            rates[i] = v[i];
            below = tension;
        }
        a[n - 1] = (-below - c[n - 1] * v[n - 1]) * inv_m[n - 1];
        rates[n - 1] = v[n - 1];
        a[sheave] += (torque - step.out_of_balance_nm) / r * inv_m[sheave];
        if line.effects.acts_at_guides() {
            for i in [0, layout.hitch] {
                a[i] += line.effects.guide_force_n(v[i]) * inv_m[i];
            }
        }
        if layout.body != layout.hitch && lumped.frame_damping_kg_per_s != 0.0 {
            let f = lumped.frame_damping_kg_per_s * (v[layout.body] - v[layout.hitch]);
            a[layout.hitch] += f * inv_m[layout.hitch];
            a[layout.body] -= f * inv_m[layout.body];
        }
        if brake == BrakeAction::Held {
            a[sheave] = 0.0;
        }
        if car_extra_force_n != 0.0 {
            a[layout.body] += car_extra_force_n * inv_m[layout.body];
        }
    }

    /// True when the fixed-size nominal path applies: the 5-DOF layout, no
    /// mechanical effect beyond the lumped values (a force at the guides,
    /// the brake clamp, the eccentric sheave), no dead time, no open phase.
    pub(crate) fn nominal_path(&self) -> bool {
        let e = &self.effects;
        self.line.layout.nodes == DOF
            && self.line.layout.body == CAR
            && !e.acts_at_guides()
            && e.brake_stop.is_none()
            && e.sheave_eccentricity.is_none()
            && e.dead_time.is_none()
            && self.faults.open_phase.is_none()
    }

    /// `steps` RK4 steps of `h` (s) with [`super::Integrator::Fast`].
    pub(crate) fn advance_fast(&mut self, steps: usize, h: f64) {
        if self.nominal_path() {
            self.advance_nominal(steps, h);
        } else {
            self.advance_line(steps, h);
        }
        let theta = self.shaft_angle_rad(&self.state);
        self.angle.ensure(theta, &self.ripple, self.pmsm.pole_pairs);
    }

    /// Masses, springs and damping at the predicted midpoint of a step of
    /// `h` (s) from the node positions and velocities in `y`.
    fn midpoint_lumped(&self, y: &[f64], h: f64) -> Lumped {
        let (n, sheave) = (self.nodes(), self.line.layout.sheave);
        self.line.lumped(&self.chain, y[sheave] + 0.5 * h * y[n + sheave])
    }

    /// The fixed-size nominal path.
    fn advance_nominal(&mut self, steps: usize, h: f64) {
        let mut y = [0.0; STATE_LEN];
        y.copy_from_slice(&self.state[..STATE_LEN]);
        for _ in 0..steps {
            let theta = y[SHEAVE] / self.chain.params.sheave_radius_m;
            self.angle.ensure(theta, &self.ripple, self.pmsm.pole_pairs);
            let lumped = self.midpoint_lumped(&y, h);
            let step = NominalStep::new(self, &lumped);
            y = rk4_step(&y, h, |x| step.derivative(x));
        }
        self.state[..STATE_LEN].copy_from_slice(&y);
    }

    /// The general line.
    fn advance_line(&mut self, steps: usize, h: f64) {
        let len = self.state_len();
        let mut state = self.state;
        // The RK4's work space is kept from call to call (no zeroing of a
        // fresh one each time).
        let mut work = std::mem::take(&mut self.rk4_work);
        if work.len() < 5 * len {
            work.resize(5 * len, 0.0);
        }
        for _ in 0..steps {
            let theta = self.shaft_angle_rad(&state);
            self.angle.ensure(theta, &self.ripple, self.pmsm.pole_pairs);
            let lumped = self.midpoint_lumped(&state, h);
            let step = LineStep::new(self, &lumped);
            rk4_step_in(&mut state[..len], h, &mut work, |y, dy| self.line_step_derivative(&step, y, dy));
        }
        self.rk4_work = work;
        self.state = state;
    }

    /// Time derivative `dy` of the general line's state `y` with its masses
    /// and springs `lumped` (the first `2 * nodes + 2` entries of each).
    fn line_derivative(&self, lumped: &Lumped, y: &[f64], dy: &mut [f64]) {
        self.line_step_derivative(&LineStep::new(self, lumped), y, dy);
    }

    /// [`Self::line_derivative`] with the step's coefficients `step`.
    fn line_step_derivative(&self, step: &LineStep, y: &[f64], dy: &mut [f64]) {
        let n = self.nodes();
        let sheave = self.line.layout.sheave;
        let r = self.chain.params.sheave_radius_m;
        let theta_m = y[sheave] / r;
        let omega_m = y[n + sheave] / r;
        let p = self.pmsm.pole_pairs;
        let (ripple, c, s) = self.angle.eval(theta_m, &self.ripple, p);
        let (torque, brake) = self.motor_and_brake_currents(y, dy, p * theta_m, p * omega_m, ripple, |id, iq| {
            let (va, vb) = self.machine_v_alpha_beta_cs(id, iq, c, s);
            (va * c + vb * s, -va * s + vb * c)
        });
        let (position, velocity) = (&y[..n], &y[n..2 * n]);
        let extra = self.faults.car_extra_force_n;
        let (rates, rest) = dy.split_at_mut(n);
        self.line_accelerations(step, position, velocity, torque, brake, extra, (&mut rates[..n], &mut rest[..n]));
        // The nodes' velocities as their positions' rates (copied in the
        // accelerations' loop), the sheave's zero when the brake holds it.
        if brake == BrakeAction::Held {
            rates[self.line.layout.sheave] = 0.0;
        }
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
        let (car, cw) = if self.nominal_path() {
            let mut y = [0.0; STATE_LEN];
            y.copy_from_slice(&self.state[..STATE_LEN]);
            let dy = NominalStep::new(self, &lumped).derivative(&y);
            (dy[DOF + CAR], dy[DOF])
        } else {
            let mut dy = [0.0; MAX_STATE_LEN];
            self.line_derivative(&lumped, &self.state, &mut dy);
            (dy[n + layout.body], dy[n + layout.counterweight()])
        };
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
    use super::*;
    use rig_config::RigConfig;

    /// The fast derivative of the nominal line equals the reference one
    /// (masses and springs at the same position) to rounding, at states
    /// away from rest, brake released and held, PWM on.
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
                let mut fixed = [0.0; STATE_LEN];
                fixed.copy_from_slice(&y[..STATE_LEN]);
                let fast = NominalStep::new(&plant, &lumped).derivative(&fixed);
                let mut general = [0.0; MAX_STATE_LEN];
                plant.line_derivative(&lumped, &y, &mut general);
                for i in 0..STATE_LEN {
                    let scale = reference[i].abs().max(1.0);
                    assert!((fast[i] - reference[i]).abs() < 1e-9 * scale, "{i}: {} vs {}", fast[i], reference[i]);
                    assert!(
                        (general[i] - reference[i]).abs() < 1e-9 * scale,
                        "{i}: {} vs {}",
                        general[i],
                        reference[i]
                    );
                }
            }
        }
    }
}
