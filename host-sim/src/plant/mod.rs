//! The nominal plant of the seed paper: the 5-DOF rope chain with car,
//! counterweight and sheave (`mechanics`, `rope`, `modes`), the PMSM in the dq
//! frame (`pmsm`) behind an averaged inverter (`inverter`), the angle-locked
//! torque ripple (`ripple`) and the drive's sensors (`sensors`).
//!
//! Sign convention: every mechanical coordinate is positive in the direction
//! of the rope when the car goes up (counterweight down, sheave edge towards
//! the counterweight side, car up). Positive shaft torque lifts the car.
//! The paper's Eqn 3 counts the sheave angle the other way; the equations
//! are the same with that sign flipped.

pub mod effects;
pub mod free_decay;
pub mod inverter;
pub mod mechanics;
pub mod modes;
pub mod pmsm;
pub mod ripple;
pub mod rope;
pub mod sensors;

pub use mechanics::{Chain, ChainState};
pub use rope::ChainParams;

use shared::SensorFrame;

use crate::config::RigConfig;
use inverter::{alpha_beta_v, phase_voltages_v};
use pmsm::{park_v, phase_currents_a, PmsmParams};
use ripple::RippleTorque;
use rope::{CAR, CW, DOF, SHEAVE};
use sensors::Sensors;

/// Size of the plant's state vector: 5 positions, 5 velocities, `i_d`, `i_q`.
pub const STATE_LEN: usize = 2 * DOF + 2;

/// What the controller's outputs do to the plant, held between updates.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlantInputs {
    /// PWM compare values, counts.
    pub pwm_compare: [u16; 3],
    /// Gate drivers enabled.
    pub pwm_enabled: bool,
    /// Brake applied (holds the sheave).
    pub brake_engaged: bool,
}

/// Values a data-acquisition system would see, at the plant's current time.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlantObservation {
    /// Car acceleration, m/s^2, positive up.
    pub car_acceleration_mps2: f64,
    /// Counterweight acceleration, m/s^2, positive up.
    pub counterweight_acceleration_mps2: f64,
    /// Phase currents in the inverter legs (the machine's, plus an injected
    /// phase-to-phase short's), A.
    pub phase_currents_a: [f64; 3],
    /// Electromagnetic torque of the machine, N m.
    pub motor_torque_nm: f64,
    /// Ripple torque, N m.
    pub ripple_torque_nm: f64,
    /// Shaft speed, rad/s (positive: car up).
    pub shaft_speed_radps: f64,
    /// Shaft angle from the start, rad.
    pub shaft_angle_rad: f64,
    /// Counterweight-side rope length, m.
    pub counterweight_side_length_m: f64,
    /// Car displacement from the start, m (positive up).
    pub car_position_m: f64,
}

/// A phase-to-phase short between two inverter outputs (fault injection):
/// a path of `resistance_ohm` and `inductance_h` that the averaged leg
/// voltages drive, `L di/dt = v_from - v_to - R i`. Its current flows out of
/// leg `from` and into leg `to`, through their current sensors, and not
/// through the machine.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhaseShort {
    /// Leg the short current leaves (0 = a, 1 = b, 2 = c).
    pub from: usize,
    /// Leg it enters.
    pub to: usize,
    /// Resistance of the short, ohm.
    pub resistance_ohm: f64,
    /// Inductance of the short, H.
    pub inductance_h: f64,
}

/// Faults of the power stage, the machine, the load and the brake (fault
/// injection; all off by default).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlantFaults {
    /// A phase-to-phase short at the inverter outputs.
    pub phase_short: Option<PhaseShort>,
    /// An open machine phase (0 = a, 1 = b, 2 = c): its current is zero and
    /// the other two carry the same current in opposite directions.
    /// Modelled in the stationary frame with `L = (L_d + L_q)/2` (exact for
    /// the rig's surface magnets, `L_d = L_q`).
    pub open_phase: Option<usize>,
    /// The brake stays applied whatever the drive commands.
    pub brake_stuck_closed: bool,
    /// Extra vertical force on the car, N, positive up (a load change: `-dm g`).
    pub car_extra_force_n: f64,
}

/// The whole plant: chain, machine, ripple, inverter and sensors.
#[derive(Clone, Debug)]
pub struct Plant {
    /// The rope chain (Eqn 1-6).
    pub chain: Chain,
    /// The machine.
    pub pmsm: PmsmParams,
    /// Angle-locked torque ripple.
    pub ripple: RippleTorque,
    /// Sensor scaling.
    pub sensors: Sensors,
    /// DC-bus voltage, V.
    pub dc_bus_v: f64,
    /// PWM timer period, counts.
    pub pwm_period_counts: u16,
    /// Injected faults (none in the nominal plant).
    pub faults: PlantFaults,
    state: [f64; STATE_LEN],
    inputs: PlantInputs,
    v_alpha_beta: (f64, f64),
    phase_v: [f64; 3],
    short_current_a: f64,
    time_s: f64,
}

impl Plant {
    /// The nominal plant of `rig` with a car of `m_car_kg`, at rest at
    /// counterweight-side rope length `lw_start_m`, brake applied, PWM off.
    pub fn new(rig: &RigConfig, m_car_kg: f64, lw_start_m: f64) -> Self {
        Self {
            chain: Chain::new(ChainParams::from_rig(rig, m_car_kg), lw_start_m),
            pmsm: PmsmParams::from_rig(rig),
            ripple: RippleTorque::from_rig(&rig.ripple),
            sensors: Sensors::from_rig(rig),
            dc_bus_v: rig.inverter.dc_bus_v,
            pwm_period_counts: rig.pwm_period_counts(),
            faults: PlantFaults::default(),
            state: [0.0; STATE_LEN],
            inputs: PlantInputs { brake_engaged: true, ..PlantInputs::default() },
            v_alpha_beta: (0.0, 0.0),
            phase_v: [0.0; 3],
            short_current_a: 0.0,
            time_s: 0.0,
        }
    }

    /// Simulated time, s.
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// Mechanical state.
    pub fn chain_state(&self) -> ChainState {
        split(&self.state).0
    }

    /// Inputs now in force.
    pub fn inputs(&self) -> PlantInputs {
        self.inputs
    }

    /// Applies new controller outputs. Switching the PWM off opens every
    /// switch (currents to zero, see [`inverter`]); engaging the brake stops
    /// the sheave.
    pub fn set_inputs(&mut self, mut inputs: PlantInputs) {
        inputs.brake_engaged |= self.faults.brake_stuck_closed;
        if !inputs.pwm_enabled {
            self.state[2 * DOF] = 0.0;
            self.state[2 * DOF + 1] = 0.0;
            self.short_current_a = 0.0;
        }
        if inputs.brake_engaged && !self.inputs.brake_engaged {
            self.state[DOF + SHEAVE] = 0.0;
        }
        self.phase_v = phase_voltages_v(inputs.pwm_compare, self.pwm_period_counts, self.dc_bus_v);
        self.v_alpha_beta = alpha_beta_v(self.phase_v);
        self.inputs = inputs;
    }

    /// Opens machine phase `phase` (0 = a, 1 = b, 2 = c) from now on, or
    /// closes it again (`None`); the present current is projected onto what
    /// the remaining two phases can carry.
    pub fn set_open_phase(&mut self, phase: Option<usize>) {
        self.faults.open_phase = phase.map(|p| p.min(2));
        if let Some(p) = self.faults.open_phase {
            let theta_e = self.pmsm.pole_pairs * self.shaft_angle_rad(&self.state);
            let (id, iq) = (self.state[2 * DOF], self.state[2 * DOF + 1]);
            let (s, c) = theta_e.sin_cos();
            let (alpha, beta) = (id * c - iq * s, id * s + iq * c);
            let n = open_phase_direction(p);
            let i_n = alpha * n.0 + beta * n.1;
            self.state[2 * DOF] = i_n * (n.0 * c + n.1 * s);
            self.state[2 * DOF + 1] = i_n * (-n.0 * s + n.1 * c);
        }
    }

    /// Current in the phase-to-phase short, A (zero without one).
    pub fn short_current_a(&self) -> f64 {
        self.short_current_a
    }

    fn shaft_angle_rad(&self, state: &[f64; STATE_LEN]) -> f64 {
        state[SHEAVE] / self.chain.params.sheave_radius_m
    }

    /// Time derivative of the state vector.
    fn derivative(&self, y: &[f64; STATE_LEN]) -> [f64; STATE_LEN] {
        let (chain_state, id, iq) = split(y);
        let r = self.chain.params.sheave_radius_m;
        let theta_m = y[SHEAVE] / r;
        let omega_m = y[DOF + SHEAVE] / r;
        let p = self.pmsm.pole_pairs;
        let (did, diq) = match (self.inputs.pwm_enabled, self.faults.open_phase) {
            (false, _) => (0.0, 0.0),
            (true, None) => {
                let (vd, vq) = park_v(self.v_alpha_beta.0, self.v_alpha_beta.1, p * theta_m);
                self.pmsm.current_derivative(id, iq, vd, vq, p * omega_m)
            }
            (true, Some(phase)) => self.open_phase_current_derivative(phase, id, iq, p * theta_m, p * omega_m),
        };
        let torque = self.pmsm.torque_nm(id, iq) + self.ripple.torque_nm(theta_m);
        let mut accel = self.chain.acceleration_mps2(&chain_state, torque, self.inputs.brake_engaged);
        if self.faults.car_extra_force_n != 0.0 {
            let lw = self.chain.counterweight_side_length_m(&chain_state).clamp(
                mechanics::MIN_ROPE_LENGTH_M,
                self.chain.params.rope_total_length_m - mechanics::MIN_ROPE_LENGTH_M,
            );
            accel[CAR] += self.faults.car_extra_force_n / self.chain.params.masses_kg(lw)[CAR];
        }
        let mut dy = [0.0; STATE_LEN];
        dy[..DOF].copy_from_slice(&chain_state.velocity_mps);
        if self.inputs.brake_engaged {
            dy[SHEAVE] = 0.0;
        }
        dy[DOF..2 * DOF].copy_from_slice(&accel);
        dy[2 * DOF] = did;
        dy[2 * DOF + 1] = diq;
        dy
    }

    /// `(d/dt i_d, d/dt i_q)` (A/s) with phase `phase` open: the current is
    /// `i_n n`, `n` the unit vector of the stationary frame perpendicular to
    /// that phase's axis, and `L di_n/dt = v.n - R i_n - e.n` with the
    /// back-EMF `e = w_e psi (-sin, cos)`, `L = (L_d + L_q)/2`.
    fn open_phase_current_derivative(&self, phase: usize, id: f64, iq: f64, theta_e: f64, omega_e: f64) -> (f64, f64) {
        let (s, c) = theta_e.sin_cos();
        let n = open_phase_direction(phase);
        let i_n = (id * c - iq * s) * n.0 + (id * s + iq * c) * n.1;
        let m = &self.pmsm;
        let l = 0.5 * (m.ld_h + m.lq_h);
        let v_n = self.v_alpha_beta.0 * n.0 + self.v_alpha_beta.1 * n.1;
        let e_n = omega_e * m.flux_linkage_wb * (-s * n.0 + c * n.1);
        let di_n = (v_n - m.resistance_ohm * i_n - e_n) / l;
        let (dalpha, dbeta) = (di_n * n.0, di_n * n.1);
        // Park of the derivative plus the rotation of the frame.
        (dalpha * c + dbeta * s + omega_e * iq, -dalpha * s + dbeta * c - omega_e * id)
    }

    /// Integrates over `duration_s` with the inputs held, in equal classical
    /// Runge-Kutta (RK4) steps no longer than `max_step_s`; a phase-to-phase
    /// short's current follows its exact first-order solution.
    pub fn advance(&mut self, duration_s: f64, max_step_s: f64) {
        if duration_s <= 0.0 {
            return;
        }
        let steps = (duration_s / max_step_s).ceil().max(1.0) as usize;
        let h = duration_s / steps as f64;
        for _ in 0..steps {
            self.state = rk4_step(&self.state, h, |y| self.derivative(y));
        }
        if let (Some(short), true) = (self.faults.phase_short, self.inputs.pwm_enabled) {
            let r = short.resistance_ohm.max(1e-6);
            let settled = (self.phase_v[short.from.min(2)] - self.phase_v[short.to.min(2)]) / r;
            let decay = (-duration_s * r / short.inductance_h.max(1e-9)).exp();
            self.short_current_a = settled + (self.short_current_a - settled) * decay;
        }
        self.time_s += duration_s;
    }

    /// The sensor readings the drive takes now.
    pub fn sensor_frame(&self) -> SensorFrame {
        let o = self.observe();
        SensorFrame {
            phase_current_codes: o.phase_currents_a.map(|i| self.sensors.current_code(i)),
            encoder_count: self.sensors.encoder_count(o.shaft_angle_rad),
            dc_bus_code: self.sensors.dc_bus_code(self.dc_bus_v),
            time_us: Sensors::time_us(self.time_s),
        }
    }

    /// Currents in the inverter legs (what the phase-current sensors
    /// measure): the machine's plus a phase-to-phase short's, A.
    fn leg_currents_a(&self, mut machine_a: [f64; 3]) -> [f64; 3] {
        if let Some(short) = self.faults.phase_short {
            machine_a[short.from.min(2)] += self.short_current_a;
            machine_a[short.to.min(2)] -= self.short_current_a;
        }
        machine_a
    }

    /// What the rig's instruments see now.
    pub fn observe(&self) -> PlantObservation {
        let (chain_state, id, iq) = split(&self.state);
        let theta_m = self.shaft_angle_rad(&self.state);
        let dy = self.derivative(&self.state);
        let r = self.chain.params.sheave_radius_m;
        PlantObservation {
            car_acceleration_mps2: dy[DOF + CAR],
            counterweight_acceleration_mps2: -dy[DOF + CW],
            phase_currents_a: self.leg_currents_a(phase_currents_a(id, iq, self.pmsm.pole_pairs * theta_m)),
            motor_torque_nm: self.pmsm.torque_nm(id, iq),
            ripple_torque_nm: self.ripple.torque_nm(theta_m),
            shaft_speed_radps: chain_state.velocity_mps[SHEAVE] / r,
            shaft_angle_rad: theta_m,
            counterweight_side_length_m: self.chain.counterweight_side_length_m(&chain_state),
            car_position_m: chain_state.position_m[CAR],
        }
    }
}

/// Unit vector `(alpha, beta)` perpendicular to the axis of `phase` (the
/// direction of the current the other two phases can carry).
fn open_phase_direction(phase: usize) -> (f64, f64) {
    let half_sqrt3 = 0.5 * 3f64.sqrt();
    match phase {
        0 => (0.0, 1.0),
        1 => (half_sqrt3, 0.5),
        _ => (half_sqrt3, -0.5),
    }
}

fn split(y: &[f64; STATE_LEN]) -> (ChainState, f64, f64) {
    let mut chain = ChainState::default();
    chain.position_m.copy_from_slice(&y[..DOF]);
    chain.velocity_mps.copy_from_slice(&y[DOF..2 * DOF]);
    (chain, y[2 * DOF], y[2 * DOF + 1])
}

/// One classical fourth-order Runge-Kutta step of `y' = f(y)` over `h`.
pub fn rk4_step<const N: usize>(y: &[f64; N], h: f64, f: impl Fn(&[f64; N]) -> [f64; N]) -> [f64; N] {
    let shifted = |base: &[f64; N], k: &[f64; N], scale: f64| -> [f64; N] {
        let mut out = *base;
        for i in 0..N {
            out[i] += scale * k[i];
        }
        out
    };
    let k1 = f(y);
    let k2 = f(&shifted(y, &k1, h / 2.0));
    let k3 = f(&shifted(y, &k2, h / 2.0));
    let k4 = f(&shifted(y, &k3, h));
    let mut out = *y;
    for i in 0..N {
        out[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    }
    out
}
