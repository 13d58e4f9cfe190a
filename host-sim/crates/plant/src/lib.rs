//! The nominal plant of the seed paper: the 5-DOF rope chain with car,
//! counterweight and sheave (`mechanics`, `rope`, `modes`), the PMSM in the dq
//! frame (`pmsm`) behind an averaged inverter (`inverter`), the angle-locked
//! torque ripple (`ripple`) and the drive's sensors (`sensors`); with the
//! library of unmodelled effects (`effects`) switched on through
//! [`Plant::with_effects`], the chain becomes a longer line of masses and
//! springs (`line`) and the inverter and sensors get their errors.
//!
//! State: positions and velocities of the line's nodes, then `i_d`, `i_q`,
//! in a fixed array of [`MAX_STATE_LEN`] of which the first
//! `2 * nodes + 2` are used (12 for the nominal plant, laid out as before:
//! `u_w, u_1, u_sh, u_2, u_c`, their velocities, `i_d`, `i_q`).
//!
//! Sign convention: every mechanical coordinate is positive in the direction
//! of the rope when the car goes up (counterweight down, sheave edge towards
//! the counterweight side, car up). Positive shaft torque lifts the car.
//! The paper's Eqn 3 counts the sheave angle the other way; the equations
//! are the same with that sign flipped.
//!
//! In the data flow config -> plant <-> controller -> recording -> analysis
//! -> diagnosis this crate is the plant: it reads the rig (`rig-config`) and
//! never knows which controller drives it: it depends on the rig
//! description alone, takes the inverter's inputs ([`PlantInputs`]) and
//! hands out its sensors' readings ([`SensorReadings`]).

#![warn(missing_docs)]

pub mod angle;
pub mod effects;
pub mod exact;
mod fast;
pub mod free_decay;
pub mod inverter;
pub mod line;
pub mod mechanics;
pub mod modes;
pub mod pmsm;
pub mod ripple;
pub mod rope;
pub mod sensors;
pub mod spring_line;
pub mod step_rates;

pub use mechanics::{Chain, ChainState};
pub use rope::ChainParams;

use angle::AngleSeries;
use effects::Effects;
use inverter::{alpha_beta_v, phase_voltages_v};
use line::{BrakeAction, Line, MAX_NODES};
use pmsm::{park_v, phase_currents_a, phase_currents_cs_a, PmsmParams};
use rig_config::RigConfig;
use ripple::RippleTorque;
use rope::{CAR, CW, DOF, ROPE_CAR, ROPE_CW, SHEAVE};
use sensors::Sensors;

/// Size of the nominal plant's state vector: 5 positions, 5 velocities, `i_d`, `i_q`.
pub const STATE_LEN: usize = 2 * DOF + 2;

/// Largest state vector, with every degree of freedom the effects add.
pub const MAX_STATE_LEN: usize = 2 * MAX_NODES + 2;

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

/// How [`Plant::advance`] integrates: both are classical RK4 in equal steps
/// no longer than the step asked for and [`Plant::stable_step_s`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Integrator {
    /// The default: masses, springs and the out-of-balance torque evaluated
    /// once per step at the step's predicted midpoint (second order in the
    /// slow change of the rope lengths), the angle-locked terms from Taylor
    /// polynomials ([`angle::AngleSeries`]); on the nominal 5-DOF chain
    /// [`Plant::advance_until`] discretises it exactly ([`exact`]).
    #[default]
    Fast,
    /// The plant as it was first written: every stage re-evaluates masses
    /// and springs at its own sheave position and the angle-locked terms
    /// with `sin_cos`. The yardstick of the fast one's accuracy (tests).
    Reference,
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
    /// The effects of the library switched on (none: the nominal plant).
    /// Set at construction ([`Plant::with_effects`]): the line's layout
    /// follows from them.
    effects: Effects,
    /// The chain as a line of masses and springs.
    line: Line,
    /// PWM frequency, Hz (dead time).
    pub pwm_hz: f64,
    /// Clamp angle of the elastic brake (`brake_stop`), rad.
    clamp_angle_rad: f64,
    state: [f64; MAX_STATE_LEN],
    inputs: PlantInputs,
    v_alpha_beta: (f64, f64),
    phase_v: [f64; 3],
    /// [`Plant::stable_step_s`] where it was last evaluated ([`Plant::advance`]).
    step_bound: Option<StepBound>,
    /// The general line's RK4 work space, kept between calls.
    rk4_work: Vec<f64>,
    /// Compare values, timer period and bus voltage (bits) that `phase_v`
    /// and `v_alpha_beta` were computed for.
    phase_v_key: Option<([u16; 3], u16, u64)>,
    short_current_a: f64,
    time_s: f64,
    /// How [`Plant::advance`] integrates.
    integrator: Integrator,
    /// Taylor polynomials of the angle-locked terms ([`Integrator::Fast`]).
    angle: AngleSeries,
    /// The nominal chain's exact half-period discretisation ([`Integrator::Fast`]).
    exact: exact::ExactStep,
}

/// [`Plant::stable_step_s`] evaluated at one sheave position.
#[derive(Clone, Debug)]
struct StepBound {
    /// Sheave position, m.
    u_m: f64,
    /// The brake clamp was in force.
    clamped: bool,
    /// Distance from `u_m` (m) over which the bound is taken as holding to 1.1 %.
    reach_m: f64,
    /// The chain it was evaluated for.
    chain: Chain,
    /// The bound, s.
    stable_step_s: f64,
}

/// What the drive's sensors hand to whichever controller closes the loop,
/// in their own units: ADC codes, encoder counts, microseconds. The closed
/// loop turns them into its controller's frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SensorReadings {
    /// ADC codes of the phase currents a, b, c (mid-scale is 0 A).
    pub phase_current_codes: [u16; 3],
    /// Free-running quadrature counter (wraps modulo 2^32), counts.
    pub encoder_count: u32,
    /// ADC code of the DC-bus voltage.
    pub dc_bus_code: u16,
    /// Time stamp of the sample (wraps modulo 2^32), microseconds.
    pub time_us: u32,
}

impl Plant {
    /// The nominal plant of `rig` with a car of `m_car_kg`, at rest at
    /// counterweight-side rope length `lw_start_m`, brake applied, PWM off.
    pub fn new(rig: &RigConfig, m_car_kg: f64, lw_start_m: f64) -> Self {
        Self::with_effects(rig, m_car_kg, lw_start_m, &Effects::none())
    }

    /// The plant of `rig` with the library's `effects` switched on, a car of
    /// `m_car_kg` (kg), at rest at counterweight-side rope length
    /// `lw_start_m` (m), brake applied, PWM off. With `brake_stop` the
    /// clamp starts pre-deflected so that it carries the out-of-balance
    /// torque (the plant starts at rest).
    pub fn with_effects(rig: &RigConfig, m_car_kg: f64, lw_start_m: f64, effects: &Effects) -> Self {
        let chain = Chain::new(ChainParams::from_rig(rig, m_car_kg), lw_start_m);
        let line = Line::new(effects);
        let clamp_angle_rad = match &effects.brake_stop {
            Some(b) => {
                let lever = effects.sheave_eccentricity.map_or(1.0, |e| e.lever_ratio(0.0));
                let lumped = line.lumped(&chain, 0.0);
                b.preloaded_clamp_angle_rad(0.0, chain.params.out_of_balance_torque_nm(lumped.lw_m) * lever)
            }
            None => 0.0,
        };
        Self {
            chain,
            pmsm: PmsmParams::from_rig(rig),
            ripple: RippleTorque::from_rig(&rig.ripple),
            sensors: Sensors::from_rig(rig),
            dc_bus_v: rig.inverter.dc_bus_v,
            pwm_period_counts: rig.pwm_period_counts(),
            faults: PlantFaults::default(),
            effects: *effects,
            line,
            pwm_hz: rig.inverter.pwm_hz,
            clamp_angle_rad,
            state: [0.0; MAX_STATE_LEN],
            inputs: PlantInputs { brake_engaged: true, ..PlantInputs::default() },
            v_alpha_beta: (0.0, 0.0),
            phase_v: [0.0; 3],
            phase_v_key: None,
            step_bound: None,
            rk4_work: Vec::new(),
            short_current_a: 0.0,
            time_s: 0.0,
            integrator: Integrator::Fast,
            angle: AngleSeries::default(),
            exact: exact::ExactStep::default(),
        }
    }

    /// Chooses how [`Plant::advance`] integrates from now on.
    pub fn set_integrator(&mut self, integrator: Integrator) {
        self.integrator = integrator;
        let theta = self.shaft_angle_rad(&self.state);
        self.angle.refresh(theta, &self.ripple, self.pmsm.pole_pairs);
    }

    /// How [`Plant::advance`] integrates.
    pub fn integrator(&self) -> Integrator {
        self.integrator
    }

    /// The effects switched on.
    pub fn effects(&self) -> &Effects {
        &self.effects
    }

    /// The line of masses and springs the chain is simulated as.
    pub fn line(&self) -> &Line {
        &self.line
    }

    /// Number of mechanical coordinates (5 for the nominal chain).
    pub fn nodes(&self) -> usize {
        self.line.layout.nodes
    }

    fn state_len(&self) -> usize {
        2 * self.nodes() + 2
    }

    /// Positions (m) and velocities (m/s) of every node of the line, in
    /// [`line::Layout`] order.
    pub fn node_state(&self) -> (&[f64], &[f64]) {
        let n = self.nodes();
        (&self.state[..n], &self.state[n..2 * n])
    }

    /// Sets the positions (m) and velocities (m/s) of the line's nodes (for
    /// tests and initial conditions); extra or missing values are ignored.
    pub fn set_node_state(&mut self, position_m: &[f64], velocity_mps: &[f64]) {
        let n = self.nodes();
        for (slot, v) in self.state[..n].iter_mut().zip(position_m) {
            *slot = *v;
        }
        for (slot, v) in self.state[n..2 * n].iter_mut().zip(velocity_mps) {
            *slot = *v;
        }
    }

    /// Clamp angle of the elastic brake, rad (`brake_stop`; meaningless without it).
    pub fn clamp_angle_rad(&self) -> f64 {
        self.clamp_angle_rad
    }

    /// True while the brake is applied through the elastic clamp of
    /// `brake_stop` (the only time the clamp acts on the sheave).
    pub(crate) fn clamped(&self) -> bool {
        self.inputs.brake_engaged && self.effects.brake_stop.is_some()
    }

    /// Mechanical energy, J: [`Line::mechanical_energy_j`] with the clamp's
    /// when the brake is applied through `brake_stop`.
    pub fn mechanical_energy_j(&self) -> f64 {
        let (position, velocity) = self.node_state();
        let clamp = self.clamped().then_some(self.clamp_angle_rad);
        self.line.mechanical_energy_j(&self.chain, position, velocity, clamp)
    }

    /// Simulated time, s.
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// Mechanical state in the nominal chain's five coordinates. With
    /// effects that add coordinates it is a projection: counterweight,
    /// the middle rope node of each side, the sheave and the car body.
    pub fn chain_state(&self) -> ChainState {
        let layout = &self.line.layout;
        let n = layout.nodes;
        let mut chain = ChainState::default();
        let picks = [
            (CW, layout.counterweight()),
            (ROPE_CW, layout.middle_cw_rope()),
            (SHEAVE, layout.sheave),
            (ROPE_CAR, layout.middle_car_rope()),
            (CAR, layout.body),
        ];
        for (to, from) in picks {
            chain.position_m[to] = self.state[from];
            chain.velocity_mps[to] = self.state[n + from];
        }
        chain
    }

    /// Inputs now in force.
    pub fn inputs(&self) -> PlantInputs {
        self.inputs
    }

    /// Applies new controller outputs. Switching the PWM off opens every
    /// switch (currents to zero, see [`inverter`]); engaging the brake stops
    /// the sheave.
    ///
    /// With `brake_stop` the brake clamps the sheave elastically at the
    /// angle it has when the brake engages instead of stopping it.
    pub fn set_inputs(&mut self, mut inputs: PlantInputs) {
        inputs.brake_engaged |= self.faults.brake_stuck_closed;
        let n = self.nodes();
        if !inputs.pwm_enabled {
            self.state[2 * n] = 0.0;
            self.state[2 * n + 1] = 0.0;
            self.short_current_a = 0.0;
        }
        if inputs.brake_engaged && !self.inputs.brake_engaged {
            let sheave = self.line.layout.sheave;
            if self.effects.brake_stop.is_some() {
                self.clamp_angle_rad = self.state[sheave] / self.chain.params.sheave_radius_m;
            } else {
                self.state[n + sheave] = 0.0;
            }
        }
        // The voltages of the same compare values, timer period and bus are
        // the ones in force (two of a PWM period's three calls change only
        // the brake or nothing).
        let key = (inputs.pwm_compare, self.pwm_period_counts, self.dc_bus_v.to_bits());
        if self.phase_v_key != Some(key) {
            self.phase_v = phase_voltages_v(inputs.pwm_compare, self.pwm_period_counts, self.dc_bus_v);
            self.v_alpha_beta = alpha_beta_v(self.phase_v);
            self.phase_v_key = Some(key);
        }
        self.inputs = inputs;
    }

    /// Opens machine phase `phase` (0 = a, 1 = b, 2 = c) from now on, or
    /// closes it again (`None`); the present current is projected onto what
    /// the remaining two phases can carry.
    pub fn set_open_phase(&mut self, phase: Option<usize>) {
        self.faults.open_phase = phase.map(|p| p.min(2));
        if let Some(p) = self.faults.open_phase {
            let theta_e = self.pmsm.pole_pairs * self.shaft_angle_rad(&self.state);
            let n = self.nodes();
            let (id, iq) = (self.state[2 * n], self.state[2 * n + 1]);
            let (s, c) = theta_e.sin_cos();
            let (alpha, beta) = (id * c - iq * s, id * s + iq * c);
            let n = open_phase_direction(p);
            let i_n = alpha * n.0 + beta * n.1;
            let nodes = self.nodes();
            self.state[2 * nodes] = i_n * (n.0 * c + n.1 * s);
            self.state[2 * nodes + 1] = i_n * (-n.0 * s + n.1 * c);
        }
    }

    /// Current in the phase-to-phase short, A (zero without one).
    pub fn short_current_a(&self) -> f64 {
        self.short_current_a
    }

    fn shaft_angle_rad(&self, state: &[f64]) -> f64 {
        state[self.line.layout.sheave] / self.chain.params.sheave_radius_m
    }

    /// Stationary-frame voltages (V) applied to the machine: the averaged
    /// inverter's, plus the dead time's error (`dead_time`) for the machine
    /// currents `(i_d, i_q)` (A) at electrical angle `theta_e` (rad).
    fn machine_v_alpha_beta(&self, id: f64, iq: f64, theta_e: f64) -> (f64, f64) {
        match &self.effects.dead_time {
            None => self.v_alpha_beta,
            Some(_) => {
                let (s, c) = theta_e.sin_cos();
                self.machine_v_alpha_beta_cs(id, iq, c, s)
            }
        }
    }

    /// [`Self::machine_v_alpha_beta`] with `cos` and `sin` of the
    /// electrical angle given, V.
    fn machine_v_alpha_beta_cs(&self, id: f64, iq: f64, c: f64, s: f64) -> (f64, f64) {
        match &self.effects.dead_time {
            None => self.v_alpha_beta,
            Some(d) => {
                let errors = d.phase_voltage_errors_v(phase_currents_cs_a(id, iq, c, s), self.dc_bus_v, self.pwm_hz);
                let (ea, eb) = alpha_beta_v(errors);
                (self.v_alpha_beta.0 + ea, self.v_alpha_beta.1 + eb)
            }
        }
    }

    /// Time derivative `dy` of the state vector `y` (the first
    /// `2 * nodes + 2` entries of each).
    fn derivative(&self, y: &[f64], dy: &mut [f64]) {
        let n = self.nodes();
        let sheave = self.line.layout.sheave;
        let r = self.chain.params.sheave_radius_m;
        let theta_m = y[sheave] / r;
        let omega_m = y[n + sheave] / r;
        let p = self.pmsm.pole_pairs;
        // One sin_cos of the shaft angle serves the ripple harmonics and,
        // for a whole number of pole pairs, the Park transform.
        let (s_m, c_m) = theta_m.sin_cos();
        let ripple_nm = self.ripple.torque_at(theta_m, s_m, c_m);
        let (torque, brake) = self.motor_and_brake(y, dy, p * theta_m, p * omega_m, ripple_nm, |id, iq| {
            let (va, vb) = self.machine_v_alpha_beta(id, iq, p * theta_m);
            if p.fract() == 0.0 && p > 0.0 && p <= 64.0 {
                let (c, s) = ripple::unit_power(c_m, s_m, p as u32);
                (va * c + vb * s, -va * s + vb * c)
            } else {
                park_v(va, vb, p * theta_m)
            }
        });
        self.line.accelerations(
            &self.chain,
            &y[..n],
            &y[n..2 * n],
            torque,
            brake,
            self.faults.car_extra_force_n,
            &mut dy[n..2 * n],
        );
    }

    /// The motor-and-brake part of the plant's derivative, one place for
    /// the reference integrator ([`Self::derivative`]) and the fast one:
    /// writes the nodes' velocities into `dy[..n]` (the sheave's zeroed
    /// when the brake holds it rigidly) and `d/dt (i_d, i_q)` into
    /// `dy[2n..2n + 2]`, and returns the shaft torque (the machine's plus
    /// `ripple_nm`, N m) and the brake's action, for the line's
    /// accelerations. `theta_e`, `omega_e`: the electrical angle (rad) and
    /// speed (rad/s); `vdq(i_d, i_q)`: the machine's d-q voltages (V) with
    /// the PWM on and every phase connected.
    pub(crate) fn motor_and_brake(
        &self,
        y: &[f64],
        dy: &mut [f64],
        theta_e: f64,
        omega_e: f64,
        ripple_nm: f64,
        vdq: impl FnOnce(f64, f64) -> (f64, f64),
    ) -> (f64, BrakeAction) {
        let n = self.nodes();
        let (id, iq) = (y[2 * n], y[2 * n + 1]);
        let (did, diq) = match (self.inputs.pwm_enabled, self.faults.open_phase) {
            (false, _) => (0.0, 0.0),
            (true, None) => {
                let (vd, vq) = vdq(id, iq);
                self.pmsm.current_derivative(id, iq, vd, vq, omega_e)
            }
            (true, Some(phase)) => self.open_phase_current_derivative(phase, id, iq, theta_e, omega_e),
        };
        let torque = self.pmsm.torque_nm(id, iq) + ripple_nm;
        let brake = match (self.inputs.brake_engaged, self.effects.brake_stop.is_some()) {
            (false, _) => BrakeAction::Released,
            (true, false) => BrakeAction::Held,
            (true, true) => BrakeAction::Clamped { angle_rad: self.clamp_angle_rad },
        };
        dy[..n].copy_from_slice(&y[n..2 * n]);
        if brake == BrakeAction::Held {
            dy[self.line.layout.sheave] = 0.0;
        }
        dy[2 * n] = did;
        dy[2 * n + 1] = diq;
        (torque, brake)
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
        let v_alpha_beta = self.machine_v_alpha_beta(id, iq, theta_e);
        let v_n = v_alpha_beta.0 * n.0 + v_alpha_beta.1 * n.1;
        let e_n = omega_e * m.flux_linkage_wb * (-s * n.0 + c * n.1);
        let di_n = (v_n - m.resistance_ohm * i_n - e_n) / l;
        let (dalpha, dbeta) = (di_n * n.0, di_n * n.1);
        // Park of the derivative plus the rotation of the frame.
        (dalpha * c + dbeta * s + omega_e * iq, -dalpha * s + dbeta * c - omega_e * id)
    }

    /// Longest RK4 step (s) that keeps `h omega_max <= 1` for the line now
    /// ([`Line::omega_max_radps`]).
    pub fn stable_step_s(&self) -> f64 {
        let clamped = self.clamped();
        1.0 / self.line.omega_max_radps(&self.chain, self.state[self.line.layout.sheave], clamped)
    }

    /// True when [`Self::stable_step_s`] is known to be longer than
    /// `max_step_s` (s) without evaluating it: the bound evaluated last
    /// (kept in `step_bound`, evaluated anew here when it does not apply)
    /// for the same chain and brake, with the sheave within 1 % of the
    /// shorter rope side from where it was evaluated, and `max_step_s` at
    /// most 0.9 of it. The line's rates scale at most like `1 / l` with the
    /// rope lengths, so they change by less than 1.1 % over that distance:
    /// the step is then `max_step_s` whichever way it is taken.
    fn step_bound_allows(&mut self, max_step_s: f64) -> bool {
        let clamped = self.clamped();
        let u = self.state[self.line.layout.sheave];
        let holds = |b: &StepBound| {
            b.clamped == clamped && (u - b.u_m).abs() <= b.reach_m && b.chain == self.chain && u.is_finite()
        };
        if !self.step_bound.as_ref().is_some_and(holds) {
            let lw = self.line.counterweight_side_length_m(&self.chain, u);
            let shorter = lw.min(self.chain.params.car_side_length_m(lw));
            self.step_bound = Some(StepBound {
                u_m: u,
                clamped,
                reach_m: 0.01 * shorter.max(0.0),
                chain: self.chain.clone(),
                stable_step_s: self.stable_step_s(),
            });
        }
        self.step_bound.as_ref().is_some_and(|b| max_step_s <= 0.9 * b.stable_step_s)
    }

    /// Number of equal steps over `duration_s` (s), each no longer than
    /// `max_step_s` (s) nor than [`Self::stable_step_s`]. Where the bound
    /// kept by [`Self::step_bound_allows`] (within 1.1 % of the bound here)
    /// gives the same count 5 % either side of it, that count is the exact
    /// bound's (the count falls as the step grows), and the bound is not
    /// evaluated anew.
    fn step_count(&mut self, duration_s: f64, max_step_s: f64) -> usize {
        if self.step_bound_allows(max_step_s) {
            return step_count_of(duration_s, max_step_s);
        }
        let u = self.state[self.line.layout.sheave];
        if let Some(b) = self.step_bound.as_ref().filter(|b| u.is_finite() && b.stable_step_s.is_finite()) {
            let shortest = step_count_of(duration_s, max_step_s.min(0.95 * b.stable_step_s));
            let longest = step_count_of(duration_s, max_step_s.min(1.05 * b.stable_step_s));
            if shortest == longest {
                return shortest;
            }
        }
        // `min` keeps `max_step_s` if the bound is NaN (a diverged state).
        step_count_of(duration_s, max_step_s.min(self.stable_step_s()))
    }

    /// Integrates over `duration_s` with the inputs held, in equal classical
    /// Runge-Kutta (RK4) steps no longer than `max_step_s` nor than
    /// [`Self::stable_step_s`] (so any `max_step_s` is stable); a
    /// phase-to-phase short's current follows its exact first-order
    /// solution.
    pub fn advance(&mut self, duration_s: f64, max_step_s: f64) {
        if duration_s <= 0.0 {
            return;
        }
        let steps = self.step_count(duration_s, max_step_s);
        let h = duration_s / steps as f64;
        match self.integrator {
            Integrator::Fast => self.advance_fast(steps, h),
            Integrator::Reference => {
                let len = self.state_len();
                let mut state = self.state;
                let mut scratch = Rk4Scratch::new();
                for _ in 0..steps {
                    scratch.step(&mut state[..len], h, |y, dy| self.derivative(y, dy));
                }
                self.state = state;
            }
        }
        if let (Some(short), true) = (self.faults.phase_short, self.inputs.pwm_enabled) {
            let r = short.resistance_ohm.max(1e-6);
            let settled = (self.phase_v[short.from.min(2)] - self.phase_v[short.to.min(2)]) / r;
            let decay = (-duration_s * r / short.inductance_h.max(1e-9)).exp();
            self.short_current_a = settled + (self.short_current_a - settled) * decay;
        }
        self.time_s += duration_s;
    }

    /// Advances to the time `t_end_s` (s) with the inputs held and hands
    /// `on_sample(t, observation)` the plant's observation at each time of
    /// `sample_times_s` (s, ascending, from now and before `t_end_s`).
    ///
    /// With [`Integrator::Fast`] on the nominal plant the whole interval is
    /// one exact step ([`exact`]: the chain's linear part discretised
    /// exactly, the samples from interpolants); otherwise, and with
    /// [`Integrator::Reference`], it is [`Plant::advance`] (steps of at most
    /// `max_step_s`, s) to each sample time, [`Plant::observe`] there, and
    /// [`Plant::advance`] to the end.
    pub fn advance_until(
        &mut self,
        t_end_s: f64,
        max_step_s: f64,
        sample_times_s: &[f64],
        mut on_sample: impl FnMut(f64, &PlantObservation),
    ) {
        let h = t_end_s - self.time_s;
        // At most 8 samples per interval (two at 16384 Hz in a half PWM period).
        let mut offsets = [0.0; 8];
        if self.integrator == Integrator::Fast && sample_times_s.len() <= offsets.len() && self.exact_ready(h) {
            for (o, t) in offsets.iter_mut().zip(sample_times_s) {
                *o = t - self.time_s;
            }
            let mut call = |i: usize, o: &PlantObservation| on_sample(sample_times_s[i], o);
            self.advance_exact(h, &offsets[..sample_times_s.len()], &mut call);
            self.time_s += h;
            return;
        }
        for &t in sample_times_s {
            self.advance(t - self.time_s, max_step_s);
            on_sample(t, &self.observe());
        }
        self.advance(t_end_s - self.time_s, max_step_s);
    }

    /// The sensor readings a drive takes now, through the effects that are
    /// on (the transducers' errors, the encoder's).
    pub fn sensor_readings(&self) -> SensorReadings {
        let shaft_angle_rad = self.shaft_angle_rad(&self.state);
        let phase_currents_a = self.leg_currents_a(self.machine_phase_currents_a());
        let currents = self.effects.measured_currents_a(phase_currents_a);
        let angle = self.effects.measured_angle_rad(shaft_angle_rad);
        SensorReadings {
            phase_current_codes: currents.map(|i| self.sensors.current_code(i)),
            encoder_count: self.sensors.encoder_count(angle),
            dc_bus_code: self.sensors.dc_bus_code(self.dc_bus_v),
            time_us: Sensors::time_us(self.time_s),
        }
    }

    /// The machine's phase currents now, A.
    fn machine_phase_currents_a(&self) -> [f64; 3] {
        let n = self.nodes();
        let (id, iq) = (self.state[2 * n], self.state[2 * n + 1]);
        let theta_m = self.shaft_angle_rad(&self.state);
        match self.integrator {
            Integrator::Fast => {
                let (c, s) = self.angle.park(theta_m, self.pmsm.pole_pairs);
                phase_currents_cs_a(id, iq, c, s)
            }
            Integrator::Reference => phase_currents_a(id, iq, self.pmsm.pole_pairs * theta_m),
        }
    }

    /// True when every state value is finite and the counterweight-side
    /// rope length lies inside the rope (ends excluded): the plant is in
    /// its valid range.
    pub fn in_valid_range(&self) -> bool {
        let lw = self.line.counterweight_side_length_m(&self.chain, self.state[self.line.layout.sheave]);
        self.state[..self.state_len()].iter().all(|x| x.is_finite())
            && lw > 0.0
            && lw < self.chain.params.rope_total_length_m
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

    /// What the rig's instruments see now (the car's accelerometer is on
    /// the car body: the frame's body with `car_frame_mode`).
    pub fn observe(&self) -> PlantObservation {
        if self.integrator == Integrator::Fast {
            return self.observe_fast();
        }
        let n = self.nodes();
        let layout = &self.line.layout;
        let (id, iq) = (self.state[2 * n], self.state[2 * n + 1]);
        let theta_m = self.shaft_angle_rad(&self.state);
        let mut dy = [0.0; MAX_STATE_LEN];
        self.derivative(&self.state, &mut dy);
        let r = self.chain.params.sheave_radius_m;
        PlantObservation {
            car_acceleration_mps2: dy[n + layout.body],
            counterweight_acceleration_mps2: -dy[n + layout.counterweight()],
            phase_currents_a: self.leg_currents_a(phase_currents_a(id, iq, self.pmsm.pole_pairs * theta_m)),
            motor_torque_nm: self.pmsm.torque_nm(id, iq),
            ripple_torque_nm: self.ripple.torque_nm(theta_m),
            shaft_speed_radps: self.state[n + layout.sheave] / r,
            shaft_angle_rad: theta_m,
            counterweight_side_length_m: self.line.counterweight_side_length_m(&self.chain, self.state[layout.sheave]),
            car_position_m: self.state[layout.body],
        }
    }
}

/// Number of equal steps of at most `step_s` (s) over `duration_s` (s):
/// at least 1, at most 1e7, 1 when it is not a number.
fn step_count_of(duration_s: f64, step_s: f64) -> usize {
    let steps = (duration_s / step_s).ceil();
    if steps.is_nan() {
        1
    } else {
        steps.clamp(1.0, 1.0e7) as usize
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

/// The plant's one ODE integrator: a classical fourth-order Runge-Kutta
/// step of `y' = f(y)` over `h`, in place; `f(y, dy)` writes the
/// derivative of `y` into `dy` (both of `y.len()` values). `work` is the
/// step's work space, at least `5 * y.len()` values (four stages and the
/// shifted state), reused from step to step by the callers: [`Rk4`] on the
/// heap, [`Rk4Scratch`] in a fixed array. [`rk4_step_in_time`] for a derivative that depends on the time.
pub fn rk4_step_in(y: &mut [f64], h: f64, work: &mut [f64], mut f: impl FnMut(&[f64], &mut [f64])) {
    rk4_step_in_time(y, h, work, |_, y, dy| f(y, dy));
}

/// The RK4's work space holds its four stages and the shifted state for a
/// state of `len` values: at least `5 * len` (a caller's bug otherwise).
fn check_work_space(work: &[f64], len: usize) {
    assert!(
        work.len() >= 5 * len,
        "RK4 work space of {} values for a state of {len}: at least {}",
        work.len(),
        5 * len
    );
}

/// [`rk4_step_in`] for `y' = f(t, y)`: `f(frac, y, dy)` is also given the
/// stage's time as a fraction of the step (0, 1/2, 1/2, 1).
pub fn rk4_step_in_time(y: &mut [f64], h: f64, work: &mut [f64], mut f: impl FnMut(f64, &[f64], &mut [f64])) {
    let len = y.len();
    check_work_space(work, len);
    let (k1, rest) = work.split_at_mut(len);
    let (k2, rest) = rest.split_at_mut(len);
    let (k3, rest) = rest.split_at_mut(len);
    let (k4, rest) = rest.split_at_mut(len);
    let tmp = &mut rest[..len];
    f(0.0, y, k1);
    for i in 0..len {
        tmp[i] = y[i] + h / 2.0 * k1[i];
    }
    f(0.5, tmp, k2);
    for i in 0..len {
        tmp[i] = y[i] + h / 2.0 * k2[i];
    }
    f(0.5, tmp, k3);
    for i in 0..len {
        tmp[i] = y[i] + h * k3[i];
    }
    f(1.0, tmp, k4);
    for i in 0..len {
        y[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    }
}

/// [`rk4_step_in_time`] for a second-order system `x'' = a(t, x, v)`:
/// `y` holds the `n` positions then the `n` velocities, and `f(frac, y,
/// acc)` writes only the `n` accelerations of the stage state `y`. The
/// positions' stage derivatives are the stage velocities themselves, kept
/// where the stage states lie instead of copied: the state after the step
/// is [`rk4_step_in_time`]'s with `dy = (v, a)`, bit for bit, in the same
/// `5 * y.len()` values of `work`. Where `first` holds them, the
/// accelerations at `y` itself (the first stage, `f(0, y)`, which a caller
/// that records them has already worked out) are taken from it: one
/// evaluation of `f` fewer.
pub fn rk4_second_order_step_from(
    y: &mut [f64],
    h: f64,
    work: &mut [f64],
    first: Option<&[f64]>,
    mut f: impl FnMut(f64, &[f64], &mut [f64]),
) {
    let len = y.len();
    let n = len / 2;
    assert!(len == 2 * n, "a second-order state holds positions and velocities: {len} values");
    check_work_space(work, len);
    let (s2, rest) = work.split_at_mut(len);
    let (s3, rest) = rest.split_at_mut(len);
    let (s4, rest) = rest.split_at_mut(len);
    let (a1, rest) = rest.split_at_mut(n);
    let (a2, rest) = rest.split_at_mut(n);
    let (a3, rest) = rest.split_at_mut(n);
    let a4 = &mut rest[..n];
    let a1: &[f64] = match first {
        Some(given) => &given[..n],
        None => {
            f(0.0, y, a1);
            a1
        }
    };
    stage(y, y, a1, h / 2.0, s2);
    f(0.5, s2, a2);
    stage(y, s2, a2, h / 2.0, s3);
    f(0.5, s3, a3);
    stage(y, s3, a3, h, s4);
    f(1.0, s4, a4);
    let (x, v) = y.split_at_mut(n);
    let (v2, v3, v4) = (&s2[n..], &s3[n..], &s4[n..]);
    for i in 0..n {
        x[i] += h / 6.0 * (v[i] + 2.0 * v2[i] + 2.0 * v3[i] + v4[i]);
    }
    for i in 0..n {
        v[i] += h / 6.0 * (a1[i] + 2.0 * a2[i] + 2.0 * a3[i] + a4[i]);
    }
}

/// One stage state of [`rk4_second_order_step_from`]: `y` moved over
/// `step` (s) at the velocities of `from` and the accelerations `acc`,
/// into `out`.
#[inline]
fn stage(y: &[f64], from: &[f64], acc: &[f64], step: f64, out: &mut [f64]) {
    let n = acc.len();
    for i in 0..n {
        out[i] = y[i] + step * from[n + i];
    }
    for i in 0..n {
        out[n + i] = y[n + i] + step * acc[i];
    }
}

/// [`rk4_step_in`] with its work space on the heap, for a state of any
/// length chosen at run time (the free decay's chain); the work space grows
/// to the longest state stepped and is reused.
#[derive(Clone, Debug, Default)]
pub struct Rk4 {
    work: Vec<f64>,
}

impl Rk4 {
    /// An integrator with no work space yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// The work space for a state of `len` values, grown to it if shorter.
    fn space(&mut self, len: usize) -> &mut [f64] {
        if self.work.len() < 5 * len {
            self.work.resize(5 * len, 0.0);
        }
        &mut self.work
    }

    /// One step of `y' = f(y)` over `h`, in place ([`rk4_step_in`]).
    pub fn step(&mut self, y: &mut [f64], h: f64, f: impl FnMut(&[f64], &mut [f64])) {
        rk4_step_in(y, h, self.space(y.len()), f);
    }

    /// One step of `y' = f(t, y)` over `h`, in place ([`rk4_step_in_time`]).
    pub fn step_in_time(&mut self, y: &mut [f64], h: f64, f: impl FnMut(f64, &[f64], &mut [f64])) {
        rk4_step_in_time(y, h, self.space(y.len()), f);
    }

    /// One step of the second-order system `x'' = a(x, v)` over `h`, in
    /// place ([`rk4_second_order_step_from`]): `f(y, acc)` writes the
    /// accelerations of the positions-then-velocities `y`; `first`, where
    /// given, holds those at `y` itself.
    pub fn step_second_order(
        &mut self,
        y: &mut [f64],
        h: f64,
        first: Option<&[f64]>,
        mut f: impl FnMut(&[f64], &mut [f64]),
    ) {
        rk4_second_order_step_from(y, h, self.space(y.len()), first, |_, y, acc| f(y, acc));
    }
}

/// [`rk4_step_in`]'s work space for a plant state (at most
/// [`MAX_STATE_LEN`] values) in a fixed array, reused over many steps.
pub struct Rk4Scratch {
    work: [f64; 5 * MAX_STATE_LEN],
}

impl Default for Rk4Scratch {
    fn default() -> Self {
        Self::new()
    }
}

impl Rk4Scratch {
    /// A zeroed work space.
    pub fn new() -> Self {
        Self { work: [0.0; 5 * MAX_STATE_LEN] }
    }

    /// One step of `y' = f(y)` over `h`, in place ([`rk4_step_in`]); `y`
    /// of at most [`MAX_STATE_LEN`] values.
    pub fn step(&mut self, y: &mut [f64], h: f64, f: impl FnMut(&[f64], &mut [f64])) {
        let len = y.len();
        assert!(len <= MAX_STATE_LEN, "state of {len} values: at most {MAX_STATE_LEN}");
        rk4_step_in(y, h, &mut self.work, f);
    }
}

#[cfg(test)]
mod rk4_tests {
    use super::*;

    /// The harmonic oscillator `x'' = -x`: every form of the one integrator
    /// gives the same state bit for bit, within RK4's error of the exact
    /// solution after one period.
    #[test]
    fn every_form_of_the_integrator_is_the_same_step() {
        let f = |y: &[f64], dy: &mut [f64]| {
            dy[0] = y[1];
            dy[1] = -y[0];
        };
        let h = std::f64::consts::TAU / 200.0;
        let (mut a, mut b) = ([1.0, 0.0], [1.0, 0.0]);
        let (mut heap, mut stack) = (Rk4::new(), Rk4Scratch::new());
        for _ in 0..200 {
            heap.step(&mut a, h, f);
            stack.step(&mut b, h, f);
        }
        assert_eq!(a, b);
        assert!((a[0] - 1.0).abs() < 1e-6 && a[1].abs() < 1e-6, "{a:?}");
    }

    /// A damped, driven chain of three masses: the second-order form, with
    /// its first stage worked out or given, gives the general step's state
    /// bit for bit over many steps.
    #[test]
    fn the_second_order_form_is_the_same_step() {
        let acc = |t: f64, y: &[f64], a: &mut [f64]| {
            let (x, v) = y.split_at(3);
            a[0] = -4.0 * x[0] + 1.5 * (x[1] - x[0]) - 0.1 * v[0] + (3.0 * t).sin();
            a[1] = -1.5 * (x[1] - x[0]) + 2.5 * (x[2] - x[1]) - 0.2 * v[1];
            a[2] = -2.5 * (x[2] - x[1]) - 0.05 * v[2] * v[2].abs();
        };
        let h = 0.013;
        let start = [0.3, -0.1, 0.2, 0.0, 0.5, -0.25];
        let (mut general, mut second, mut given) = (start, start, start);
        let (mut w1, mut w2, mut w3) = ([0.0; 30], [f64::NAN; 30], [f64::NAN; 30]);
        for k in 0..500 {
            let t0 = k as f64 * h;
            rk4_step_in_time(&mut general, h, &mut w1, |frac, y, dy| {
                dy[..3].copy_from_slice(&y[3..]);
                acc(t0 + frac * h, y, &mut dy[3..]);
            });
            rk4_second_order_step_from(&mut second, h, &mut w2, None, |frac, y, a| acc(t0 + frac * h, y, a));
            let mut first = [0.0; 3];
            acc(t0, &given, &mut first);
            rk4_second_order_step_from(&mut given, h, &mut w3, Some(&first), |frac, y, a| acc(t0 + frac * h, y, a));
        }
        assert_eq!(general, second);
        assert_eq!(general, given);
        assert!(general.iter().any(|v| v.abs() > 1e-3), "{general:?}");
    }

    /// `y' = t` from 0 over one step of `h`: RK4 integrates it exactly with
    /// the stage times it is given.
    #[test]
    fn the_time_form_gives_each_stage_its_time() {
        let h = 0.5;
        let mut y = [0.0];
        Rk4::new().step_in_time(&mut y, h, |frac, _, dy| dy[0] = frac * h);
        assert_eq!(y[0], h * h / 2.0);
    }
}

#[cfg(test)]
mod step_count_tests {
    use super::*;
    use crate::effects::EffectKind;

    /// The step count taken from the kept bound is the exact bound's, along
    /// 0.4 m of the rope's short end (the 21-node line, the clamp applied
    /// and released, the sheave 0.1 mm further at each count, durations
    /// across a PWM half period).
    #[test]
    fn the_kept_bound_gives_the_exact_step_count() {
        let rig = RigConfig::embedded_default().unwrap();
        let mut effects = Effects::none();
        effects.set(EffectKind::RopeDiscretization, &[8.0]).unwrap();
        for kind in [EffectKind::DivertingPulley, EffectKind::CarFrameMode, EffectKind::BrakeStop] {
            effects.set(kind, &kind.defaults()).unwrap();
        }
        let max_step_s = 0.25 / rig.control.current_loop_hz;
        let (mut kept, mut checked) = (0, 0);
        for brake in [false, true] {
            let mut plant = Plant::with_effects(&rig, 70.5, 1.0, &effects);
            plant.set_inputs(PlantInputs { brake_engaged: brake, ..plant.inputs() });
            let sheave = plant.line.layout.sheave;
            for k in 0..4000 {
                plant.state[sheave] = -0.2 + 1.0e-4 * k as f64;
                let duration_s = max_step_s * (0.1 + 3.9 * ((k * 7) % 13) as f64 / 13.0);
                let exact = step_count_of(duration_s, max_step_s.min(plant.stable_step_s()));
                let allowed = plant.step_bound_allows(max_step_s);
                assert_eq!(plant.step_count(duration_s, max_step_s), exact, "at {k}");
                checked += 1;
                kept += usize::from(!allowed);
            }
        }
        println!("the bound limits the step in {kept} of {checked}");
        assert!(kept > 100, "the bound limits the step in {kept} of {checked}");
    }
}
