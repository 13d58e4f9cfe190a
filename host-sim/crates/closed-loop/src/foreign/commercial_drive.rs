//! A second drive for the simulator: a generic commercial elevator drive,
//! not the project's drive core. Users whose rig runs such a drive simulate
//! it with this model; the project tests its diagnosis against recordings
//! made with it.
//!
//! It is plain `f64` host code (it never runs on the chip) and sees the
//! plant only as the drive core does: ADC codes of the phase currents and
//! of the DC bus, the encoder counter, and it writes PWM compare values and
//! the brake output ([`DriveController`]). What differs from the drive core:
//!
//! - **Current loop**: dq PI with cross-coupling decoupling and back-EMF
//!   feed-forward, gains by pole-zero cancellation for its own bandwidth
//!   (`Kp = L wc`, `Ki = R wc`), conditional-integration anti-windup, the
//!   voltage limited to a circle of `0.95 V_dc / sqrt 3` (d first), inverse
//!   Park at the angle one PWM period ahead, min-max space-vector modulation.
//! - **Speed estimate**: M/T method over the encoder counts (count
//!   difference over the time between the latest count edges, edges time
//!   stamped at the PWM sample that sees them) every speed-loop period of
//!   [`SPEED_LOOP_PERIOD_S`], then a first-order low-pass of its own time
//!   constant. No tracking observer.
//! - **Speed loop**: PI with `Kp = J_est wc` and integral time `Ti`
//!   (`Ki = Kp / Ti`), `J_est` the system inertia at the shaft from the load
//!   weighing; optional inertia feed-forward `J_est alpha_ref`; no
//!   out-of-balance feed-forward during the travel and no position loop (the
//!   travel is the integral of its speed profile: the landing error is the
//!   integral of the speed error).
//! - **Pre-torque**: the out-of-balance torque of Eqn 4 from the load
//!   weighing (with its error) ramped in with the brake applied, then loaded
//!   into the speed integrator; or none (the speed loop catches the car at
//!   the brake lift).
//! - **Sequence**: pre-torque ramp (brake applied) -> brake lift, speed held
//!   at zero for the brake lift delay -> its own jerk-limited profile (its
//!   own rated speed, acceleration and jerk) -> zero speed held until the
//!   estimate is below 1 % of rated speed, for the brake drop delay -> brake
//!   applied, torque ramped down -> PWM off. It reports these as the
//!   drive core's states (`PreTorque`, `BrakeLift`, `Travel`, `Hold`,
//!   `BrakeSet`, `Idle`), so the closed loop and the recordings treat both
//!   drives alike.
//! - **Electrical angle**: the rotor may stand at any electrical angle when
//!   the drive powers up; the drive knows it from its commissioning (the
//!   encoder offset), so its electrical angle is `offset + p theta_enc`.
//!   [`crate::foreign::simulate_commercial_travel`] puts the simulated
//!   rotor there.
//! - **Protection**: over-current (the rig's trip level) and over-speed
//!   (1.25 times its rated speed) trip it.

use drive_core::config::Direction;
use drive_core::controller::Telemetry;
use drive_core::supervisor::Fault;
use drive_core::{ControlOutput, DriveState, SensorFrame, TravelCommand};

use super::params::{foreign_params, ParamError, ParamKind};
use crate::{DriveController, SimError};
use rig_config::RigConfig;

/// Period of the speed loop and of the M/T speed estimate, s (a whole
/// number of PWM periods nearest to it).
pub const SPEED_LOOP_PERIOD_S: f64 = 1.0e-3;
/// Speed below which the drive considers the car stopped, as a fraction of
/// its rated shaft speed.
pub const ZERO_SPEED_FRACTION: f64 = 0.01;
/// Longest wait for zero speed at the end of a travel before the brake is
/// dropped anyway, s.
pub const ZERO_SPEED_TIMEOUT_S: f64 = 3.0;
/// Over-speed trip as a multiple of the drive's rated shaft speed.
pub const OVERSPEED_FACTOR: f64 = 1.25;
/// Fraction of the linear modulation limit `V_dc / sqrt 3` the current loop uses.
pub const MODULATION_LIMIT: f64 = 0.95;
/// Without an encoder edge for this long, the M/T estimate is zero, s.
pub const MT_STANDSTILL_S: f64 = 0.1;

foreign_params! {
    /// Parameters of the commercial drive, with units, defaults and ranges
    /// ([`ForeignDrive::PARAMS`]). The drive is stable on the reference rig
    /// (car 33-70.5 kg, full travels both ways) over the whole ranges.
    pub struct ForeignDrive in "drive" {
        /// Closed-loop bandwidth of the dq current loop, Hz.
        current_bandwidth_hz: f64 = 500.0, [250.0, 1000.0], "Hz", ParamKind::Real;
        /// Crossover of the speed loop (proportional gain `J_est 2 pi f`), Hz.
        speed_bandwidth_hz: f64 = 4.0, [2.0, 8.0], "Hz", ParamKind::Real;
        /// Integral time of the speed PI (`Ki = Kp / Ti`), s.
        speed_integral_time_s: f64 = 0.2, [0.08, 0.4], "s", ParamKind::Real;
        /// Time constant of the first-order filter on the M/T speed estimate, s.
        speed_filter_time_constant_s: f64 = 0.004, [0.001, 0.01], "s", ParamKind::Real;
        /// Pre-torque from the load weighing before the brake lifts (1 on, 0 off).
        pre_torque: bool = 1.0, [0.0, 1.0], "-", ParamKind::Switch { p_on: 0.7 };
        /// Error of the load weighing, % of the car mass (positive: reads heavy).
        weighing_error_pct: f64 = 0.0, [-10.0, 10.0], "%", ParamKind::Real;
        /// Inertia torque feed-forward from the profile's acceleration (1 on, 0 off).
        inertia_feedforward: bool = 1.0, [0.0, 1.0], "-", ParamKind::Switch { p_on: 0.5 };
        /// Start: ramp time of the pre-torque with the brake applied, s.
        start_torque_ramp_s: f64 = 0.2, [0.05, 0.5], "s", ParamKind::Real;
        /// Start: time from the brake lift command to the start of the profile, s.
        brake_lift_delay_s: f64 = 0.3, [0.1, 0.8], "s", ParamKind::Real;
        /// Stop: time at zero speed before the brake drops, s.
        brake_drop_delay_s: f64 = 0.2, [0.05, 0.5], "s", ParamKind::Real;
        /// Stop: ramp time of the torque down to zero once the brake is applied, s.
        stop_torque_ramp_s: f64 = 0.2, [0.05, 0.5], "s", ParamKind::Real;
        /// Rated speed of the drive's profile (sheave edge), m/s.
        rated_speed_mps: f64 = 0.4, [0.3, 0.5], "m/s", ParamKind::Real;
        /// Acceleration of the drive's profile, m/s^2.
        accel_mps2: f64 = 0.5, [0.3, 0.8], "m/s^2", ParamKind::Real;
        /// Jerk of the drive's profile, m/s^3.
        jerk_mps3: f64 = 1.0, [0.5, 2.0], "m/s^3", ParamKind::Real;
        /// Electrical angle of the rotor d axis from the phase-a axis when the drive powers up (the encoder offset its commissioning found), deg.
        rotor_start_angle_deg: f64 = 0.0, [0.0, 360.0], "deg", ParamKind::Real;
    }
}

/// A jerk-limited (S-curve) travel profile in `f64`: jerk `+-j`, then
/// acceleration `a`, speed `v` (each reduced when the distance is too short
/// to reach it), symmetric deceleration; position, speed and acceleration
/// in the travel direction, m, m/s, m/s^2.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SCurve {
    /// Segments: duration (s) and jerk (m/s^3), with the state at their start
    /// (position m, speed m/s, acceleration m/s^2).
    segments: [(f64, f64, [f64; 3]); 7],
    distance_m: f64,
}

impl SCurve {
    /// The profile over `distance_m` (> 0) with at most speed `v`,
    /// acceleration `a` and jerk `j` (all > 0).
    pub fn plan(distance_m: f64, v: f64, a: f64, j: f64) -> Self {
        // Distance to reach speed `v` from rest (and to stop from it): the
        // average speed of a symmetric S is v/2.
        let ramp = |v: f64| -> (f64, f64, f64) {
            if v >= a * a / j {
                let (tj, tc) = (a / j, v / a - a / j);
                (tj, tc, v * (2.0 * tj + tc) / 2.0)
            } else {
                let tj = (v / j).sqrt();
                (tj, 0.0, v * tj)
            }
        };
        let mut peak = v;
        if 2.0 * ramp(v).2 > distance_m {
            let (mut lo, mut hi) = (0.0, v);
            for _ in 0..200 {
                let mid = 0.5 * (lo + hi);
                if 2.0 * ramp(mid).2 > distance_m {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            peak = lo;
        }
        let (tj, tc, d) = ramp(peak);
        let cruise = ((distance_m - 2.0 * d) / peak).max(0.0);
        let raw = [(tj, j), (tc, 0.0), (tj, -j), (cruise, 0.0), (tj, -j), (tc, 0.0), (tj, j)];
        let mut state = [0.0; 3];
        let segments = raw.map(|(duration, jerk)| {
            let start = state;
            state = advance(state, jerk, duration);
            (duration, jerk, start)
        });
        Self { segments, distance_m }
    }

    /// Duration, s.
    pub fn duration_s(&self) -> f64 {
        self.segments.iter().map(|s| s.0).sum()
    }

    /// Travel distance, m.
    pub fn distance_m(&self) -> f64 {
        self.distance_m
    }

    /// `(position m, speed m/s, acceleration m/s^2)` at `t_s` (s) from the
    /// start; before it at rest at 0, after it at rest at the distance.
    pub fn at(&self, t_s: f64) -> (f64, f64, f64) {
        if t_s <= 0.0 {
            return (0.0, 0.0, 0.0);
        }
        let mut start = 0.0;
        for &(duration, jerk, state) in &self.segments {
            if t_s < start + duration {
                let s = advance(state, jerk, t_s - start);
                return (s[0], s[1], s[2]);
            }
            start += duration;
        }
        (self.distance_m, 0.0, 0.0)
    }
}

/// The state `[position, speed, acceleration]` after `dt` (s) of constant jerk.
fn advance(s: [f64; 3], jerk: f64, dt: f64) -> [f64; 3] {
    [
        s[0] + s[1] * dt + s[2] * dt * dt / 2.0 + jerk * dt * dt * dt / 6.0,
        s[1] + s[2] * dt + jerk * dt * dt / 2.0,
        s[2] + jerk * dt,
    ]
}

/// M/T speed estimate: the count difference between the latest edges of
/// two speed-loop periods over the time between them, the edges time
/// stamped at the PWM sample that first sees them; then a first-order
/// low-pass.
#[derive(Clone, Copy, Debug, PartialEq)]
struct MtSpeed {
    radians_per_count: f64,
    /// Latest count edge: step index and position, counts.
    last_edge: Option<(u64, i64)>,
    /// Edge the previous estimate ended on.
    reference_edge: Option<(u64, i64)>,
    last_position: i64,
    step_s: f64,
    /// Filter coefficient per speed-loop period, dimensionless.
    alpha: f64,
    raw_radps: f64,
    filtered_radps: f64,
}

impl MtSpeed {
    fn new(counts_per_rev: u32, step_s: f64, tick_s: f64, time_constant_s: f64) -> Self {
        Self {
            radians_per_count: std::f64::consts::TAU / counts_per_rev.max(1) as f64,
            last_edge: None,
            reference_edge: None,
            last_position: 0,
            step_s,
            alpha: tick_s / (time_constant_s + tick_s),
            raw_radps: 0.0,
            filtered_radps: 0.0,
        }
    }

    /// One PWM sample `step` with the accumulated position, counts.
    fn sample(&mut self, step: u64, position: i64) {
        if position != self.last_position {
            self.last_edge = Some((step, position));
            self.last_position = position;
        }
    }

    /// One speed-loop period ending at PWM sample `step`.
    fn update(&mut self, step: u64) {
        match (self.reference_edge, self.last_edge) {
            (Some((k0, x0)), Some((k1, x1))) if k1 > k0 => {
                self.raw_radps = (x1 - x0) as f64 * self.radians_per_count / ((k1 - k0) as f64 * self.step_s);
                self.reference_edge = self.last_edge;
            }
            (Some((k0, _)), _) => {
                // No new edge: the speed is at most one count over the time since the last.
                let since = (step.saturating_sub(k0)) as f64 * self.step_s;
                let bound = self.radians_per_count / since.max(self.step_s);
                self.raw_radps = if since > MT_STANDSTILL_S {
                    0.0
                } else {
                    self.raw_radps.signum() * self.raw_radps.abs().min(bound)
                };
            }
            (None, edge) => self.reference_edge = edge,
        }
        self.filtered_radps += self.alpha * (self.raw_radps - self.filtered_radps);
    }
}

/// What the drive knows of the rig from its commissioning, SI.
#[derive(Clone, Copy, Debug, PartialEq)]
struct RigKnowledge {
    pole_pairs: f64,
    resistance_ohm: f64,
    ld_h: f64,
    lq_h: f64,
    flux_linkage_wb: f64,
    torque_constant_nm_per_a: f64,
    max_current_a: f64,
    overcurrent_a: f64,
    counts_per_rev: u32,
    current_lsb_a: f64,
    current_zero_code: f64,
    dc_bus_v_per_code: f64,
    period_counts: u16,
    sheave_radius_m: f64,
    sheave_inertia_kg_m2: f64,
    m_cw_kg: f64,
    rope_mass_per_length_kg_per_m: f64,
    rope_total_length_m: f64,
    gravity_mps2: f64,
}

/// One travel as the drive planned it.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Plan {
    /// +1 car up, -1 car down.
    sign: f64,
    profile: SCurve,
    /// Shaft inertia from the load weighing, kg m^2.
    inertia_kg_m2: f64,
    /// Pre-torque (Eqn 4 with the weighed mass), N m; 0 without pre-torque.
    pre_torque_nm: f64,
}

/// The commercial drive: a [`DriveController`] for the closed loop.
#[derive(Clone, Debug)]
pub struct CommercialDrive {
    params: ForeignDrive,
    rig: RigKnowledge,
    step_s: f64,
    speed_divider: u64,
    tick_s: f64,
    rotor_offset_rad: f64,
    state: DriveState,
    state_time_s: f64,
    step: u64,
    last_count: Option<u32>,
    position_counts: i64,
    speed: MtSpeed,
    plan: Option<Plan>,
    id_integral_v: f64,
    iq_integral_v: f64,
    speed_integral_nm: f64,
    torque_nm: f64,
    ramp_from_nm: f64,
    zero_speed_since_s: Option<f64>,
    telemetry: Telemetry,
}

impl CommercialDrive {
    /// The drive with `params` for the machine, sensors and mechanics of `rig`.
    ///
    /// # Errors
    /// [`ParamError::OutOfRange`] naming the first parameter outside its range.
    pub fn new(rig: &RigConfig, params: &ForeignDrive) -> Result<Self, ParamError> {
        params.validate()?;
        let mo = &rig.motor;
        let inv = &rig.inverter;
        let m = &rig.mechanics;
        let half = (1u64 << (inv.adc_bits - 1)) as f64;
        let knowledge = RigKnowledge {
            pole_pairs: mo.pole_pairs as f64,
            resistance_ohm: mo.stator_resistance_ohm,
            ld_h: mo.ld_h,
            lq_h: mo.lq_h,
            flux_linkage_wb: mo.flux_linkage_wb,
            torque_constant_nm_per_a: mo.torque_constant_nm_per_a(),
            max_current_a: mo.rated_current_a,
            overcurrent_a: mo.overcurrent_trip_a,
            counts_per_rev: inv.encoder_counts_per_rev,
            current_lsb_a: inv.current_sense_full_scale_a / half,
            current_zero_code: half,
            dc_bus_v_per_code: inv.dc_bus_sense_full_scale_v / ((1u64 << inv.adc_bits) - 1) as f64,
            period_counts: rig.pwm_period_counts(),
            sheave_radius_m: m.sheave_radius_m,
            sheave_inertia_kg_m2: m.sheave_inertia_kg_m2,
            m_cw_kg: m.m_cw_kg,
            rope_mass_per_length_kg_per_m: m.rope_mass_per_length_kg_per_m,
            rope_total_length_m: m.rope_total_length_m,
            gravity_mps2: m.gravity_mps2,
        };
        let step_s = 1.0 / rig.control.current_loop_hz;
        let speed_divider = (SPEED_LOOP_PERIOD_S / step_s).round().max(1.0) as u64;
        let tick_s = speed_divider as f64 * step_s;
        Ok(Self {
            params: *params,
            rig: knowledge,
            step_s,
            speed_divider,
            tick_s,
            rotor_offset_rad: params.rotor_start_angle_deg.to_radians(),
            state: DriveState::Idle,
            state_time_s: 0.0,
            step: 0,
            last_count: None,
            position_counts: 0,
            speed: MtSpeed::new(inv.encoder_counts_per_rev, step_s, tick_s, params.speed_filter_time_constant_s),
            plan: None,
            id_integral_v: 0.0,
            iq_integral_v: 0.0,
            speed_integral_nm: 0.0,
            torque_nm: 0.0,
            ramp_from_nm: 0.0,
            zero_speed_since_s: None,
            telemetry: Telemetry::default(),
        })
    }

    /// The parameters.
    pub fn params(&self) -> &ForeignDrive {
        &self.params
    }

    /// Current state.
    pub fn state(&self) -> DriveState {
        self.state
    }

    /// The drive's rated shaft speed, rad/s.
    fn rated_shaft_speed_radps(&self) -> f64 {
        self.params.rated_speed_mps / self.rig.sheave_radius_m
    }

    /// Eqn 4 for a car of `m_car_kg` at counterweight-side length `lw_m`, N m
    /// (positive lifts the car).
    fn out_of_balance_torque_nm(&self, m_car_kg: f64, lw_m: f64) -> f64 {
        let k = &self.rig;
        let lc_m = k.rope_total_length_m - lw_m;
        (m_car_kg - k.m_cw_kg + k.rope_mass_per_length_kg_per_m * (lc_m - lw_m)) * k.gravity_mps2 * k.sheave_radius_m
    }

    fn enter(&mut self, state: DriveState) {
        self.state = state;
        self.state_time_s = 0.0;
    }

    fn trip(&mut self, fault: Fault) {
        if !matches!(self.state, DriveState::Tripped(_)) {
            self.enter(DriveState::Tripped(fault));
            self.plan = None;
            self.torque_nm = 0.0;
        }
    }

    /// Speed PI plus feed-forward `ff_nm` for the reference `speed_ref_radps`,
    /// limited to the rated current; N m.
    fn speed_pi(&mut self, speed_ref_radps: f64, ff_nm: f64, inertia_kg_m2: f64) -> f64 {
        let kp = inertia_kg_m2 * std::f64::consts::TAU * self.params.speed_bandwidth_hz;
        let ki = kp / self.params.speed_integral_time_s;
        let error = speed_ref_radps - self.speed.filtered_radps;
        let limit = self.rig.max_current_a * self.rig.torque_constant_nm_per_a;
        self.speed_integral_nm += ki * error * self.tick_s;
        let proportional = kp * error + ff_nm;
        let torque = (proportional + self.speed_integral_nm).clamp(-limit, limit);
        // Anti-windup: the integrator holds what the limit leaves.
        self.speed_integral_nm = (torque - proportional).clamp(-limit, limit);
        torque
    }

    /// One speed-loop period: estimate, protection, sequence, torque.
    fn speed_tick(&mut self) {
        self.speed.update(self.step);
        let speed = self.speed.filtered_radps;
        if speed.abs() > OVERSPEED_FACTOR * self.rated_shaft_speed_radps() {
            self.trip(Fault::OverSpeed);
        }
        self.state_time_s += self.tick_s;
        let t = self.state_time_s;
        let p = self.params;
        let (mut speed_ref, mut ref_speed_mps, mut ff) = (0.0, 0.0, 0.0);
        let Some(plan) = self.plan else {
            self.torque_nm = 0.0;
            self.telemetry.speed_radps = speed as f32;
            return;
        };
        let r = self.rig.sheave_radius_m;
        match self.state {
            DriveState::PreTorque => {
                self.torque_nm = plan.pre_torque_nm * (t / p.start_torque_ramp_s).min(1.0);
                if t >= p.start_torque_ramp_s {
                    self.speed_integral_nm = plan.pre_torque_nm;
                    self.enter(DriveState::BrakeLift);
                }
            }
            DriveState::BrakeLift => {
                self.torque_nm = self.speed_pi(0.0, 0.0, plan.inertia_kg_m2);
                if t >= p.brake_lift_delay_s {
                    self.enter(DriveState::Travel);
                }
            }
            DriveState::Travel => {
                let (_, v, a) = plan.profile.at(t);
                ref_speed_mps = plan.sign * v;
                speed_ref = ref_speed_mps / r;
                if p.inertia_feedforward {
                    ff = plan.inertia_kg_m2 * plan.sign * a / r;
                }
                self.torque_nm = self.speed_pi(speed_ref, ff, plan.inertia_kg_m2);
                if t >= plan.profile.duration_s() {
                    self.zero_speed_since_s = None;
                    self.enter(DriveState::Hold);
                }
            }
            DriveState::Hold => {
                self.torque_nm = self.speed_pi(0.0, 0.0, plan.inertia_kg_m2);
                if speed.abs() < ZERO_SPEED_FRACTION * self.rated_shaft_speed_radps() {
                    self.zero_speed_since_s.get_or_insert(t);
                } else {
                    self.zero_speed_since_s = None;
                }
                let settled = self.zero_speed_since_s.is_some_and(|since| t - since >= p.brake_drop_delay_s);
                if settled || t >= ZERO_SPEED_TIMEOUT_S {
                    self.ramp_from_nm = self.torque_nm;
                    self.enter(DriveState::BrakeSet);
                }
            }
            DriveState::BrakeSet => {
                self.torque_nm = self.ramp_from_nm * (1.0 - t / p.stop_torque_ramp_s).max(0.0);
                if t >= p.stop_torque_ramp_s {
                    self.torque_nm = 0.0;
                    self.plan = None;
                    self.enter(DriveState::Idle);
                }
            }
            DriveState::Idle | DriveState::Tripped(_) => self.torque_nm = 0.0,
        }
        let tel = &mut self.telemetry;
        tel.speed_radps = speed as f32;
        tel.speed_ref_radps = speed_ref as f32;
        tel.ref_speed_mps = ref_speed_mps as f32;
        tel.torque_ff_nm = ff as f32;
        tel.torque_ref_nm = self.torque_nm as f32;
    }

    /// One current-loop step: compare values for the phase currents `abc`
    /// (A) and the DC bus `dc_bus_v` (V).
    fn current_loop(&mut self, abc: [f64; 3], dc_bus_v: f64) -> [u16; 3] {
        let k = self.rig;
        let cpr = k.counts_per_rev.max(1) as i64;
        let within = self.position_counts.rem_euclid(cpr) as f64 / cpr as f64;
        let theta_e = self.rotor_offset_rad + k.pole_pairs * std::f64::consts::TAU * within;
        let omega_e = k.pole_pairs * self.speed.filtered_radps;
        let alpha = (2.0 * abc[0] - abc[1] - abc[2]) / 3.0;
        let beta = (abc[1] - abc[2]) / 3f64.sqrt();
        let (s, c) = theta_e.sin_cos();
        let (id, iq) = (alpha * c + beta * s, -alpha * s + beta * c);
        let iq_ref = (self.torque_nm / k.torque_constant_nm_per_a).clamp(-k.max_current_a, k.max_current_a);
        let wc = std::f64::consts::TAU * self.params.current_bandwidth_hz;
        let (ed, eq) = (0.0 - id, iq_ref - iq);
        let vd_wanted = k.ld_h * wc * ed + self.id_integral_v - omega_e * k.lq_h * iq;
        let vq_wanted = k.lq_h * wc * eq + self.iq_integral_v + omega_e * (k.ld_h * id + k.flux_linkage_wb);
        let v_max = MODULATION_LIMIT * dc_bus_v.max(1.0) / 3f64.sqrt();
        let vd = vd_wanted.clamp(-v_max, v_max);
        let vq_max = (v_max * v_max - vd * vd).max(0.0).sqrt();
        let vq = vq_wanted.clamp(-vq_max, vq_max);
        let ki_ts = k.resistance_ohm * wc * self.step_s;
        if vd == vd_wanted {
            self.id_integral_v += ki_ts * ed;
        }
        if vq == vq_wanted {
            self.iq_integral_v += ki_ts * eq;
        }
        self.telemetry.id_a = id as f32;
        self.telemetry.iq_a = iq as f32;
        self.telemetry.iq_ref_a = iq_ref as f32;
        // The voltage acts about one period after the sample.
        let (s, c) = (theta_e + omega_e * self.step_s).sin_cos();
        let (va, vb) = (vd * c - vq * s, vd * s + vq * c);
        modulate(va, vb, dc_bus_v.max(1.0), k.period_counts)
    }
}

/// Compare values (0..=`period_counts`) of min-max space-vector modulation
/// for the stationary voltage `(v_alpha, v_beta)` (V) on `dc_bus_v` (V).
pub fn modulate(v_alpha: f64, v_beta: f64, dc_bus_v: f64, period_counts: u16) -> [u16; 3] {
    let h = 0.5 * 3f64.sqrt();
    let phases = [v_alpha, -0.5 * v_alpha + h * v_beta, -0.5 * v_alpha - h * v_beta];
    let max = phases.iter().copied().fold(f64::MIN, f64::max);
    let min = phases.iter().copied().fold(f64::MAX, f64::min);
    let zero_sequence = -(max + min) / 2.0;
    let period = period_counts as f64;
    phases.map(|v| ((0.5 + (v + zero_sequence) / dc_bus_v).clamp(0.0, 1.0) * period).round() as u16)
}

impl DriveController for CommercialDrive {
    fn command_travel(&mut self, command: TravelCommand) -> Result<(), SimError> {
        if self.state != DriveState::Idle {
            return Err(SimError::Refused(drive_core::controller::CommandError::NotIdle));
        }
        let distance = command.distance_m as f64;
        let lw_start = command.lw_start_m as f64;
        let lw_end = lw_start + command.direction.sign() as f64 * distance;
        let inside = |lw: f64| lw > 0.0 && lw < self.rig.rope_total_length_m;
        let m = command.m_car_kg as f64;
        if !(distance > 0.0 && inside(lw_start) && inside(lw_end) && m > 0.0 && m.is_finite()) {
            return Err(SimError::Refused(drive_core::controller::CommandError::OutOfRange));
        }
        let p = self.params;
        let weighed = m * (1.0 + p.weighing_error_pct / 100.0);
        let k = self.rig;
        let r = k.sheave_radius_m;
        let inertia = k.sheave_inertia_kg_m2
            + (k.m_cw_kg + weighed + k.rope_mass_per_length_kg_per_m * k.rope_total_length_m) * r * r;
        self.plan = Some(Plan {
            sign: if command.direction == Direction::Up { 1.0 } else { -1.0 },
            profile: SCurve::plan(distance, p.rated_speed_mps, p.accel_mps2, p.jerk_mps3),
            inertia_kg_m2: inertia,
            pre_torque_nm: if p.pre_torque { self.out_of_balance_torque_nm(weighed, lw_start) } else { 0.0 },
        });
        self.id_integral_v = 0.0;
        self.iq_integral_v = 0.0;
        self.speed_integral_nm = 0.0;
        self.torque_nm = 0.0;
        self.enter(DriveState::PreTorque);
        Ok(())
    }

    fn step(&mut self, sensors: &SensorFrame) -> Result<ControlOutput, SimError> {
        let delta = match self.last_count {
            Some(last) => sensors.encoder_count.wrapping_sub(last) as i32,
            None => 0,
        };
        self.last_count = Some(sensors.encoder_count);
        self.position_counts += delta as i64;
        self.speed.sample(self.step, self.position_counts);
        let k = self.rig;
        let abc = sensors.phase_current_codes.map(|code| (code as f64 - k.current_zero_code) * k.current_lsb_a);
        if abc.iter().any(|i| i.abs() > k.overcurrent_a) {
            self.trip(Fault::OverCurrent);
        }
        if self.step % self.speed_divider == 0 {
            self.speed_tick();
        }
        self.step += 1;
        let pwm_enabled = self.state.pwm_enabled();
        let brake_released = self.state.brake_released();
        let pwm_compare = if pwm_enabled {
            self.current_loop(abc, sensors.dc_bus_code as f64 * k.dc_bus_v_per_code)
        } else {
            self.id_integral_v = 0.0;
            self.iq_integral_v = 0.0;
            self.telemetry.id_a = 0.0;
            self.telemetry.iq_a = 0.0;
            self.telemetry.iq_ref_a = 0.0;
            [0; 3]
        };
        self.telemetry.angle_rad =
            (self.position_counts as f64 * std::f64::consts::TAU / k.counts_per_rev.max(1) as f64) as f32;
        Ok(ControlOutput { pwm_compare, pwm_enabled, brake_released, state: self.state, telemetry: self.telemetry })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn s_curve_reaches_the_distance_within_its_limits() {
        for (d, v, a, j) in [(6.6, 0.4, 0.5, 1.0), (6.6, 0.5, 0.8, 0.5), (0.05, 0.4, 0.5, 1.0), (0.3, 0.3, 0.8, 2.0)] {
            let s = SCurve::plan(d, v, a, j);
            let n = 20_000;
            let (mut vmax, mut amax, mut last) = (0.0f64, 0.0f64, (0.0, 0.0, 0.0));
            for k in 0..=n {
                let p = s.at(s.duration_s() * k as f64 / n as f64);
                vmax = vmax.max(p.1);
                amax = amax.max(p.2.abs());
                assert!(p.0 >= last.0 - 1e-12, "position goes back");
                last = p;
            }
            let end = s.at(s.duration_s() - 1e-12);
            assert!((end.0 - d).abs() < 1e-6 * d.max(1.0) && end.1.abs() < 1e-6, "{d}: {end:?}");
            assert!(vmax <= v * (1.0 + 1e-9) && amax <= a * (1.0 + 1e-9), "{vmax} {amax}");
        }
        // Long enough to cruise at the rated speed.
        let s = SCurve::plan(6.6, 0.4, 0.5, 1.0);
        assert!((s.at(0.5 * s.duration_s()).1 - 0.4).abs() < 1e-12);
    }

    #[test]
    fn mt_estimate_of_a_constant_speed() {
        let (pwm_s, ticks) = (1.0 / 16_000.0, 16u64);
        let mut mt = MtSpeed::new(16_384, pwm_s, ticks as f64 * pwm_s, 0.004);
        let speed = 6.15;
        for k in 0..32_000u64 {
            let counts = (speed * k as f64 * pwm_s / std::f64::consts::TAU * 16_384.0).floor() as i64;
            mt.sample(k, counts);
            if k % ticks == 0 {
                mt.update(k);
            }
        }
        assert!((mt.filtered_radps - speed).abs() < 0.02 * speed, "{}", mt.filtered_radps);
        // Standstill: no edge for a while gives zero.
        for k in 32_000..36_000u64 {
            mt.sample(k, 1_000_000);
            if k % ticks == 0 {
                mt.update(k);
            }
        }
        assert!(mt.filtered_radps.abs() < 1e-3, "{}", mt.filtered_radps);
    }

    #[test]
    fn modulation_reproduces_line_voltages() {
        let c = modulate(30.0, -20.0, 100.0, 5312);
        let v = |i: usize| c[i] as f64 / 5312.0 * 100.0;
        let h = 0.5 * 3f64.sqrt();
        assert!((v(0) - v(1) - (30.0 - (-15.0 - 20.0 * h))).abs() < 0.05);
    }

    #[test]
    fn parameters_are_checked_by_name_and_range() {
        let mut p = ForeignDrive::default();
        assert!(p.validate().is_ok());
        p.set_from(&["speed_bandwidth_hz=6", "pre_torque=0"]).unwrap();
        assert_eq!((p.speed_bandwidth_hz, p.pre_torque), (6.0, false));
        let err = p.set("speed_bandwidth_hz", 30.0).unwrap_err().to_string();
        assert!(err.contains("speed_bandwidth_hz") && err.contains("[2, 8]"), "{err}");
        let err = p.set("gain", 1.0).unwrap_err().to_string();
        assert!(err.contains("gain") && err.contains("current_bandwidth_hz"), "{err}");
        let err = p.set("pre_torque", 0.5).unwrap_err().to_string();
        assert!(err.contains("0 (off) or 1 (on)"), "{err}");
        use rand::SeedableRng;
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        for _ in 0..100 {
            ForeignDrive::random(&mut rng).validate().unwrap();
        }
    }
}
