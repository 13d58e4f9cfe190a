//! The drive controller: one [`Controller::step`] per PWM period.
//!
//! Inputs are exactly what the firmware reads from the hardware (phase-current
//! and DC-bus ADC codes, the encoder counter, a microsecond time stamp);
//! outputs are what it writes (three PWM compare values, PWM enable, brake).
//! Nothing here knows whether it runs on the chip or in the simulator.
//!
//! Travel sequence: `Idle` -> `PreTorque` (brake applied, q current ramps to
//! the out-of-balance torque of Eqn 4) -> `BrakeLift` (brake released,
//! position held) -> `Travel` (S-curve) -> `Hold` (position held at the
//! landing) -> `BrakeSet` (brake applied, torque kept) -> `Idle` (PWM off).
//! Any fault latches `Tripped`: PWM off, brake applied, until [`Controller::reset`].
//!
//! Two kinds of travel share that sequence. A distance travel
//! ([`Controller::command_travel`]) follows an S-curve planned once to its
//! target. A speed travel ([`Controller::command_speed_travel`], the lift
//! controller's speed mode) has no target: it ramps (jerk-limited,
//! [`SpeedRamp`]) to the commanded speed and runs at it until told to change
//! speed ([`Controller::command_speed`], e.g. down to crawl at the
//! deceleration point) or to stop ([`Controller::command_stop`]: a ramp to
//! rest, then `Hold`); it stops by itself, with the same ramp, where going on
//! would take the car beyond the end of the shaft it was given.

use crate::config::{Direction, DriveConfig};
use crate::current_loop::{current_from_code, CurrentLoop, CurrentLoopParams};
use crate::fixed::{mul_int, q16, Q16};
use crate::observer::{ChainModel, ObserverEstimate, ObserverInput, ObserverLink, ObserverOutput, ObserverRequest};
use crate::park_clarke::Abc;
use crate::profile::{Approach, ApproachError, ProfileError, ProfilePoint, SCurve, SpeedRamp};
use crate::ripple::harmonics::HarmonicTable;
use crate::ripple::{LearningInput, RippleCompensator, Strategy};
use crate::speed_estimator::SpeedEstimator;
use crate::speed_loop::{equivalent_inertia_kg_m2, out_of_balance_torque_nm, SpeedLoop, POSITION_GAIN_PER_S};
use crate::supervisor::{Fault, MonitorLimits, MonitorSample, Supervisor, SupervisorLimits};
use crate::trig::Angle;

/// Duration of the pre-torque ramp with the brake applied, s.
pub const PRE_TORQUE_S: f32 = 0.2;
/// Time allowed for the brake to lift before the profile starts, s.
pub const BRAKE_LIFT_S: f32 = 0.15;
/// Position hold at the landing before the brake is set, s.
pub const HOLD_S: f32 = 0.3;
/// Time allowed for the brake to set before the PWM is switched off, s.
pub const BRAKE_SET_S: f32 = 0.2;

/// A [`Q16`] as `f32`: one integer conversion and a multiplication by a
/// power of two (rounded to nearest like any `i32 -> f32` conversion).
fn to_f32(value: Q16) -> f32 {
    value.to_bits() as f32 * (1.0 / 65536.0)
}

/// What the firmware reads in one PWM period.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SensorFrame {
    /// ADC codes of the phase currents a, b, c (mid-scale is 0 A).
    pub phase_current_codes: [u16; 3],
    /// Free-running quadrature counter (wraps modulo 2^32), counts.
    pub encoder_count: u32,
    /// ADC code of the DC-bus voltage.
    pub dc_bus_code: u16,
    /// Time stamp of the sample (wraps modulo 2^32), microseconds.
    pub time_us: u32,
}

/// Drive state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DriveState {
    /// PWM off, brake applied, waiting for a travel command.
    Idle,
    /// Brake applied, torque building up to the holding torque.
    PreTorque,
    /// Brake released, holding the start position.
    BrakeLift,
    /// Following the S-curve.
    Travel,
    /// Holding the landing position.
    Hold,
    /// Brake applied, torque kept while it sets.
    BrakeSet,
    /// A fault is latched: PWM off, brake applied.
    Tripped(Fault),
}

impl DriveState {
    /// Whether the inverter switches in this state: every state between the
    /// travel command and the brake set, none when idle or tripped.
    pub fn pwm_enabled(self) -> bool {
        matches!(
            self,
            DriveState::PreTorque
                | DriveState::BrakeLift
                | DriveState::Travel
                | DriveState::Hold
                | DriveState::BrakeSet
        )
    }

    /// Whether the brake is released (lifted) in this state.
    pub fn brake_released(self) -> bool {
        matches!(self, DriveState::BrakeLift | DriveState::Travel | DriveState::Hold)
    }

    /// Numeric code of the state for frames and recordings: 0 idle, 1
    /// pre-torque, 2 brake lift, 3 travel, 4 hold, 5 brake set, 100 + the
    /// fault's reason code when tripped.
    pub fn code(self) -> u8 {
        match self {
            DriveState::Idle => 0,
            DriveState::PreTorque => 1,
            DriveState::BrakeLift => 2,
            DriveState::Travel => 3,
            DriveState::Hold => 4,
            DriveState::BrakeSet => 5,
            DriveState::Tripped(fault) => 100 + fault.code(),
        }
    }

    /// The state of a [`DriveState::code`], if it is one.
    pub fn from_code(code: u8) -> Option<Self> {
        Some(match code {
            0 => DriveState::Idle,
            1 => DriveState::PreTorque,
            2 => DriveState::BrakeLift,
            3 => DriveState::Travel,
            4 => DriveState::Hold,
            5 => DriveState::BrakeSet,
            c if c > 100 => DriveState::Tripped(Fault::from_code(c - 100)?),
            _ => return None,
        })
    }
}

/// Values for logging and recordings, in the units named.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Telemetry {
    /// Measured d current, A.
    pub id_a: f32,
    /// Measured q current, A.
    pub iq_a: f32,
    /// q-current reference, A.
    pub iq_ref_a: f32,
    /// Estimated shaft speed, rad/s (positive: car up).
    pub speed_radps: f32,
    /// Shaft speed reference, rad/s (positive: car up).
    pub speed_ref_radps: f32,
    /// Reference speed of a sheave-edge point, m/s (positive: car up).
    pub ref_speed_mps: f32,
    /// Shaft angle since power-up from the encoder, rad.
    pub angle_rad: f32,
    /// Feed-forward torque (Eqn 4 plus inertia), N m.
    pub torque_ff_nm: f32,
    /// Torque demand of the speed loop including feed-forward, N m.
    pub torque_ref_nm: f32,
}

/// What the firmware writes in one PWM period.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControlOutput {
    /// Timer compare values of phases a, b, c, counts (0..=period).
    pub pwm_compare: [u16; 3],
    /// Gate drivers enabled; false is the safe state (all switches off).
    pub pwm_enabled: bool,
    /// Brake released; false (the fail-safe default) applies the brake.
    pub brake_released: bool,
    /// State after this step.
    pub state: DriveState,
    /// Logged values.
    pub telemetry: Telemetry,
}

/// A travel request with the load weighing of the car.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TravelCommand {
    /// Car direction.
    pub direction: Direction,
    /// Travel distance, m (> 0).
    pub distance_m: f32,
    /// Car mass from the load weighing, kg.
    pub m_car_kg: f32,
    /// Counterweight-side rope length at the start, m.
    pub lw_start_m: f32,
}

/// Why a travel command was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CommandError {
    /// The drive is not idle (travelling or tripped).
    NotIdle,
    /// Distance or limits do not give a profile.
    Profile(ProfileError),
    /// The travel would take `lw` outside `(0, l_t)` or the car mass is not positive.
    OutOfRange,
}

/// A speed travel request (the lift controller's speed mode: crawl,
/// inspection, re-levelling, the travel speeds) with the load weighing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpeedTravelCommand {
    /// Car direction.
    pub direction: Direction,
    /// Car speed to run at, m/s (in `(0, rated speed]`).
    pub speed_mps: f32,
    /// Car mass from the load weighing, kg.
    pub m_car_kg: f32,
    /// Counterweight-side rope length at the start, m.
    pub lw_start_m: f32,
    /// Counterweight-side rope length the car must not pass in its
    /// direction (the last landing), m: the drive starts its stop ramp in
    /// time to come to rest there at the latest.
    pub lw_limit_m: f32,
}

/// Why a speed change or a stop of a speed travel was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpeedCommandError {
    /// No speed travel runs (idle, tripped, a distance travel, or the
    /// travel is already stopping).
    NoSpeedTravel,
    /// The speed is not in `(0, rated speed]` m/s.
    OutOfRange,
}

/// Why a new remaining distance of a distance travel was refused (the
/// travel goes on to the target it had).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RetargetError {
    /// No distance travel runs before its end (idle, tripped, a speed
    /// travel, or the car already holding at its target).
    NoDistanceTravel,
    /// The car cannot stop within that distance from its reference now
    /// with the acceleration and jerk limits: it would pass the target.
    CannotStop,
    /// The distance is not finite and non-negative, or the target is
    /// outside the rope lengths `(0, l_t)`.
    OutOfRange,
}

/// A changed remaining distance closer than this to the target planned,
/// m (5 mm), leaves the plan as it is: a lift controller repeats the
/// remaining distance in every message, measured on the car, whose ropes
/// stretch and spring back during the travel by 1-3 mm against the
/// sheave's count on the reference rig (the plan would chase them and
/// land by that much off); rope slip beyond it is followed.
pub const RETARGET_DEADBAND_M: f32 = 0.005;

/// The reference of a speed travel: the ramp running and where it may go.
#[derive(Clone, Copy, Debug, PartialEq)]
struct SpeedReference {
    /// The ramp running, in the travel coordinate (m from the start).
    ramp: SpeedRamp,
    /// Time in `Travel` at which the ramp starts, s.
    ramp_start_s: f32,
    /// The ramp ends at rest: the travel ends with it.
    stopping: bool,
    /// Distance the car may travel from its start, m.
    limit_m: f32,
}

impl SpeedReference {
    /// The reference at time `t_s` in `Travel`.
    fn at(&self, t_s: f32) -> ProfilePoint {
        self.ramp.at(t_s - self.ramp_start_s)
    }
}

/// What a travel follows.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Reference {
    /// An S-curve to the target.
    Distance(SCurve),
    /// A distance travel whose target changed during the profile: the
    /// approach from the reference of that instant (`start_s`, s in `Travel`).
    Retarget { approach: Approach, start_s: f32 },
    /// A commanded speed.
    Speed(SpeedReference),
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Travel {
    command: TravelCommand,
    reference: Reference,
    start_counts: i64,
    /// Holding torque at the start (Eqn 4), N m.
    holding_torque_nm: f32,
    inertia_kg_m2: f32,
}

/// The drive controller.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Controller {
    config: DriveConfig,
    current_loop: CurrentLoop,
    speed_loop: SpeedLoop,
    estimator: SpeedEstimator,
    supervisor: Supervisor,
    state: DriveState,
    travel: Option<Travel>,
    state_ticks: u32,
    step_count: u32,
    last_time_us: Option<u32>,
    iq_ref: Q16,
    telemetry: Telemetry,
    current_lsb_a: Q16,
    dc_bus_v_per_code: Q16,
    speed_divider: u32,
    /// `2^48 / counts_per_rev`: binary angle per encoder count, Q16.
    binary_angle_per_count_q16: u64,
    /// Torque-ripple compensation (q-current feed-forward by shaft angle), if installed.
    compensation: Option<RippleCompensator>,
    /// The link to the chain observer's task, if the observer is in use
    /// (inputs published at the speed-loop ticks with the brake released;
    /// see [`crate::observer::task`] for the schedule).
    observer: Option<ObserverLink>,
    /// Speed-loop ticks since power-up (wraps): the observer's schedule.
    speed_ticks: u32,
    /// The encoder counter of the latest step (what the observer reads), counts.
    last_encoder_count: u32,
    /// Fault checks: the latest current-loop sample, for the supervisor's
    /// consistency checks (faults 8-11) at the next speed-loop tick.
    loop_sample: LoopSample,
}

/// Fault checks: what the supervisor's consistency checks need from one
/// current-loop step, kept in fixed point (converted at the speed-loop rate).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct LoopSample {
    pwm_enabled: bool,
    current_sum: Q16,
    current: crate::park_clarke::Dq,
    voltage: crate::park_clarke::Dq,
    iq_ref: Q16,
    speed_e: Q16,
}

impl Controller {
    /// A controller in `Idle` for the drive described by `config`.
    pub fn new(config: &DriveConfig) -> Self {
        let rated = config.rated_shaft_speed_radps();
        let overspeed = config.overspeed_factor * rated;
        let counts_per_step =
            overspeed / core::f32::consts::TAU * config.encoder_counts_per_rev as f32 / config.current_loop_hz;
        let limits = SupervisorLimits {
            overcurrent_a: q16(config.overcurrent_trip_a),
            current_sum_a: q16(config.current_sum_limit_a),
            overspeed_radps: q16(overspeed),
            dc_bus_under_v: q16(config.dc_bus_undervoltage_v),
            dc_bus_over_v: q16(config.dc_bus_overvoltage_v),
            adc_max_code: config.adc_max_code(),
            // Four times the over-speed increment, plus quantisation.
            max_counts_per_step: (4.0 * counts_per_step) as i32 + 2,
            max_step_interval_us: (2.5e6 / config.current_loop_hz) as u32,
            monitors: MonitorLimits::new(
                1.0 / config.speed_loop_hz,
                config.current_sum_limit_a,
                config.max_current_a,
                rated,
                config.pole_pairs as f32,
                config.stator_resistance_ohm,
                config.ld_h,
                config.lq_h,
                config.flux_linkage_wb,
            ),
        };
        Self {
            config: *config,
            current_loop: CurrentLoop::new(CurrentLoopParams::from_config(config)),
            speed_loop: SpeedLoop::new(config, equivalent_inertia_kg_m2(config, config.m_cw_kg)),
            estimator: SpeedEstimator::new(
                config.speed_loop_hz,
                config.speed_estimator_bandwidth_hz,
                config.encoder_counts_per_rev,
            ),
            supervisor: Supervisor::new(limits),
            state: DriveState::Idle,
            travel: None,
            state_ticks: 0,
            step_count: 0,
            last_time_us: None,
            iq_ref: Q16::ZERO,
            telemetry: Telemetry::default(),
            current_lsb_a: q16(config.current_lsb_a()),
            dc_bus_v_per_code: q16(config.dc_bus_sense_full_scale_v / config.adc_max_code() as f32),
            speed_divider: config.speed_loop_divider(),
            binary_angle_per_count_q16: (1u64 << 48) / config.encoder_counts_per_rev.max(1) as u64,
            compensation: None,
            observer: None,
            speed_ticks: 0,
            last_encoder_count: 0,
            loop_sample: LoopSample::default(),
        }
    }

    /// Installs a torque-ripple compensator, or removes it (between travels).
    pub fn set_compensation(&mut self, compensation: Option<RippleCompensator>) {
        self.compensation = compensation;
    }

    /// The torque-ripple compensator and what it has learned, if installed.
    pub fn compensation(&self) -> Option<&RippleCompensator> {
        self.compensation.as_ref()
    }

    /// Installs ripple compensation `strategy` for the orders of `table`
    /// (the `Strategy::Table` table, N m) on the drive's chain model `chain`, with the
    /// link to the chain observer's task when the strategy is
    /// [`Strategy::CarObserver`] (the caller runs the task:
    /// [`crate::observer::ObserverTask`]). [`Strategy::Off`] removes the
    /// link and leaves a compensator that does nothing (no current, no
    /// learning), kept for the next installation. The one setup the chip
    /// (PIL) and the host share. A compensator already there is installed
    /// again in place ([`RippleCompensator::reinstall`]: the same state as
    /// a new one, without building a second 8 KB copy), so that the
    /// firmware's control interrupt can do it within a PWM period.
    pub fn install_compensation(&mut self, strategy: Strategy, table: &HarmonicTable, chain: &ChainModel) {
        self.observer = (strategy == Strategy::CarObserver).then(ObserverLink::default);
        match self.compensation.as_mut() {
            Some(compensator) => compensator.reinstall(chain, table, strategy),
            None => {
                let mut compensator = RippleCompensator::new(&self.config, chain, &table.orders[..table.len], strategy);
                compensator.set_table(*table);
                self.compensation = Some(compensator);
            }
        }
    }

    /// Uses the chain observer, or stops using it (between travels): with
    /// `true`, the controller publishes the observer's inputs from the next
    /// brake lift on and `Strategy::CarObserver` learns from the car
    /// acceleration its task hands back. A new link (nothing pending, no
    /// deadline counted) either way.
    pub fn set_observer(&mut self, used: bool) {
        self.observer = used.then(ObserverLink::default);
    }

    /// Whether the chain observer is in use (a task must serve its link).
    pub fn uses_observer(&self) -> bool {
        self.observer.is_some()
    }

    /// Whether an input waits for the observer's task (published at this
    /// step's speed-loop tick and not taken yet).
    pub fn observer_input_waiting(&self) -> bool {
        self.observer.is_some_and(|link| link.is_waiting())
    }

    /// The observer's input waiting for its task, taken (the task's side of the link).
    pub fn take_observer_input(&mut self) -> Option<ObserverInput> {
        self.observer.as_mut().and_then(ObserverLink::take)
    }

    /// The observer task hands back the output of an input it took.
    pub fn deliver_observer_output(&mut self, output: ObserverOutput) {
        if let Some(link) = self.observer.as_mut() {
            link.deliver(output);
        }
    }

    /// Speed-loop ticks in which the observer's estimate of the previous
    /// tick was not back from its task (missed deadlines), since the
    /// observer was installed.
    pub fn observer_missed_deadlines(&self) -> u32 {
        self.observer.map_or(0, |link| link.missed_deadlines())
    }

    /// The observer's estimate in use (car acceleration m/s^2, rope forces N,
    /// shaft disturbance N m): the latest one its task handed back in time,
    /// if the observer is in use and has given one since the brake lifted.
    pub fn observer_estimate(&self) -> Option<ObserverEstimate> {
        self.observer.and_then(|link| link.estimate())
    }

    /// Current state.
    pub fn state(&self) -> DriveState {
        self.state
    }

    /// Fault checks: the supervisor's low-passed consistency quantities now
    /// (faults 8-11), for diagnostics and margin tests.
    pub fn monitor_levels(&self) -> crate::supervisor::MonitorLevels {
        self.supervisor.monitor_levels()
    }

    /// Fault checks: the supervisor's limits in force.
    pub fn supervisor_limits(&self) -> &SupervisorLimits {
        self.supervisor.limits()
    }

    /// Starts a travel; accepted only in `Idle`.
    pub fn command_travel(&mut self, command: TravelCommand) -> Result<(), CommandError> {
        if self.state != DriveState::Idle {
            return Err(CommandError::NotIdle);
        }
        let c = &self.config;
        let lw_end = command.lw_start_m + command.direction.sign() * command.distance_m;
        let inside = |lw: f32| lw > 0.0 && lw < c.rope_total_length_m;
        let positive_mass = command.m_car_kg > 0.0 && command.m_car_kg.is_finite();
        if !inside(command.lw_start_m) || !inside(lw_end) || !positive_mass {
            return Err(CommandError::OutOfRange);
        }
        let profile = SCurve::plan(command.distance_m, c.rated_speed_mps, c.max_accel_mps2, c.max_jerk_mps3)
            .map_err(CommandError::Profile)?;
        let inertia_kg_m2 = equivalent_inertia_kg_m2(c, command.m_car_kg);
        self.speed_loop = SpeedLoop::new(c, inertia_kg_m2);
        self.travel = Some(Travel {
            command,
            reference: Reference::Distance(profile),
            start_counts: self.estimator.position_counts(),
            holding_torque_nm: out_of_balance_torque_nm(c, command.m_car_kg, command.lw_start_m),
            inertia_kg_m2,
        });
        self.enter(DriveState::PreTorque);
        Ok(())
    }

    /// Starts a speed travel; accepted only in `Idle`. The ramp to the
    /// speed starts when the brake is lifted.
    pub fn command_speed_travel(&mut self, command: SpeedTravelCommand) -> Result<(), CommandError> {
        if self.state != DriveState::Idle {
            return Err(CommandError::NotIdle);
        }
        let c = &self.config;
        let sign = command.direction.sign();
        let inside = |lw: f32| lw > 0.0 && lw < c.rope_total_length_m;
        let positive_mass = command.m_car_kg > 0.0 && command.m_car_kg.is_finite();
        let speed_ok = command.speed_mps > 0.0 && command.speed_mps <= c.rated_speed_mps;
        // Room ahead in the travel direction, m.
        let limit_m = sign * (command.lw_limit_m - command.lw_start_m);
        let room = limit_m > 0.0;
        if !inside(command.lw_start_m) || !inside(command.lw_limit_m) || !positive_mass || !speed_ok || !room {
            return Err(CommandError::OutOfRange);
        }
        let ramp = SpeedRamp::plan(ProfilePoint::default(), command.speed_mps, c.max_accel_mps2, c.max_jerk_mps3)
            .map_err(CommandError::Profile)?;
        let inertia_kg_m2 = equivalent_inertia_kg_m2(c, command.m_car_kg);
        self.speed_loop = SpeedLoop::new(c, inertia_kg_m2);
        let travel = TravelCommand {
            direction: command.direction,
            distance_m: limit_m,
            m_car_kg: command.m_car_kg,
            lw_start_m: command.lw_start_m,
        };
        self.travel = Some(Travel {
            command: travel,
            reference: Reference::Speed(SpeedReference { ramp, ramp_start_s: 0.0, stopping: false, limit_m }),
            start_counts: self.estimator.position_counts(),
            holding_torque_nm: out_of_balance_torque_nm(c, command.m_car_kg, command.lw_start_m),
            inertia_kg_m2,
        });
        self.enter(DriveState::PreTorque);
        Ok(())
    }

    /// Changes the speed of the running speed travel to `speed_mps` (m/s,
    /// in `(0, rated speed]`): a jerk-limited ramp from the reference now.
    pub fn command_speed(&mut self, speed_mps: f32) -> Result<(), SpeedCommandError> {
        if !(speed_mps > 0.0 && speed_mps <= self.config.rated_speed_mps) {
            return Err(SpeedCommandError::OutOfRange);
        }
        // The speed it is already going to: nothing to re-plan (a lift
        // controller repeats its command every message).
        if let Some(Travel { reference: Reference::Speed(s), .. }) = self.travel {
            if !s.stopping && s.ramp.end().speed_mps == speed_mps && self.state.pwm_enabled() {
                return Ok(());
            }
        }
        self.replan_speed(speed_mps)
    }

    /// Stops the running speed travel: a jerk-limited ramp to rest from the
    /// reference now, then `Hold` and the brake as at the end of any travel.
    /// A stop of a travel already stopping changes nothing.
    pub fn command_stop(&mut self) -> Result<(), SpeedCommandError> {
        match self.travel.map(|t| t.reference) {
            Some(Reference::Speed(s)) if s.stopping => Ok(()),
            _ => self.replan_speed(0.0),
        }
    }

    /// Changes the running distance travel's target to `remaining_m` (m, not
    /// negative) ahead of the car's position `age_s` seconds ago (the
    /// remaining distance the lift controller measured when it started its
    /// message, e.g. after rope slip; `age_s` in `[0, 1)`: the car's
    /// measured position now less the reference speed times `age_s`). Before
    /// the profile starts, the S-curve is planned again to the new total
    /// distance; during it, the rest of the travel is planned again from
    /// the reference now ([`Approach`]: acceleration and jerk within the
    /// limits, at most the rated speed, at rest on the target, never past
    /// it). `Ok(true)`: planned again; `Ok(false)`: the new target is
    /// within [`RETARGET_DEADBAND_M`] of the planned one, nothing changed.
    /// A target closer than the shortest stop is refused
    /// ([`RetargetError::CannotStop`]) and the travel keeps its target.
    pub fn command_remaining_distance(&mut self, remaining_m: f32, age_s: f32) -> Result<bool, RetargetError> {
        if !(remaining_m >= 0.0 && remaining_m.is_finite() && (0.0..1.0).contains(&age_s)) {
            return Err(RetargetError::OutOfRange);
        }
        let state = self.state;
        let t = self.state_time_s();
        let c = self.config;
        let moved_counts = self.estimator.position_counts();
        let Some(travel) = self.travel.as_mut() else {
            return Err(RetargetError::NoDistanceTravel);
        };
        let sign = travel.command.direction.sign();
        let moved_m = moved_counts.saturating_sub(travel.start_counts) as f32 * core::f32::consts::TAU
            / c.encoder_counts_per_rev as f32
            * c.sheave_radius_m;
        // The reference speed now (m/s, in the travel direction): the car
        // moved about `v age_s` since the master measured the distance.
        let speed_mps = match (state, travel.reference) {
            (DriveState::Travel, Reference::Distance(profile)) => profile.at(t).speed_mps,
            (DriveState::Travel, Reference::Retarget { approach, start_s }) => approach.at(t - start_s).speed_mps,
            _ => 0.0,
        };
        // The new target in the travel coordinate (m from the start, positive in its direction).
        let target_m = sign * moved_m + remaining_m - speed_mps * age_s;
        let planned_m = match travel.reference {
            Reference::Distance(profile) => profile.distance_m(),
            Reference::Retarget { approach, .. } => approach.target_m(),
            Reference::Speed(_) => return Err(RetargetError::NoDistanceTravel),
        };
        // The target it has (also while holding there at the end).
        let change = target_m - planned_m;
        if (if change < 0.0 { -change } else { change }) < RETARGET_DEADBAND_M {
            return Ok(false);
        }
        if !matches!(state, DriveState::PreTorque | DriveState::BrakeLift | DriveState::Travel) {
            return Err(RetargetError::NoDistanceTravel);
        }
        let lw_end = travel.command.lw_start_m + sign * target_m;
        if !(target_m > 0.0 && lw_end > 0.0 && lw_end < c.rope_total_length_m) {
            return Err(RetargetError::OutOfRange);
        }
        let (v, a, j) = (c.rated_speed_mps, c.max_accel_mps2, c.max_jerk_mps3);
        travel.reference = match (state, travel.reference) {
            (DriveState::Travel, Reference::Distance(profile)) => {
                let approach = Approach::plan(profile.at(t), target_m, v, a, j).map_err(retarget_error)?;
                Reference::Retarget { approach, start_s: t }
            }
            (DriveState::Travel, Reference::Retarget { approach, start_s }) => {
                let approach = Approach::plan(approach.at(t - start_s), target_m, v, a, j).map_err(retarget_error)?;
                Reference::Retarget { approach, start_s: t }
            }
            // Before the profile runs: the whole S-curve to the new distance.
            _ => Reference::Distance(SCurve::plan(target_m, v, a, j).map_err(|_| RetargetError::OutOfRange)?),
        };
        travel.command.distance_m = target_m;
        Ok(true)
    }

    /// The distance travel's target, m from its start in its direction
    /// (changed by [`Controller::command_remaining_distance`]); `None`
    /// without a distance travel.
    pub fn distance_target_m(&self) -> Option<f32> {
        match self.travel.map(|t| t.reference) {
            Some(Reference::Distance(profile)) => Some(profile.distance_m()),
            Some(Reference::Retarget { approach, .. }) => Some(approach.target_m()),
            _ => None,
        }
    }

    /// A new ramp to `speed_mps` (0: stop) from the reference of the latest speed-loop tick.
    fn replan_speed(&mut self, speed_mps: f32) -> Result<(), SpeedCommandError> {
        let running = matches!(self.state, DriveState::PreTorque | DriveState::BrakeLift | DriveState::Travel);
        let t = self.state_time_s();
        let state = self.state;
        let c = self.config;
        let Some(Travel { reference: Reference::Speed(s), .. }) = self.travel.as_mut() else {
            return Err(SpeedCommandError::NoSpeedTravel);
        };
        if !running || s.stopping {
            return Err(SpeedCommandError::NoSpeedTravel);
        }
        // Before the profile runs, the ramp starts from rest when it does.
        let (from, start) = if state == DriveState::Travel { (s.at(t), t) } else { (ProfilePoint::default(), 0.0) };
        s.ramp = SpeedRamp::plan(from, speed_mps, c.max_accel_mps2, c.max_jerk_mps3)
            .map_err(|_| SpeedCommandError::OutOfRange)?;
        s.ramp_start_s = start;
        s.stopping = speed_mps == 0.0;
        Ok(())
    }

    /// After the caller held the steps back on purpose (the firmware pauses
    /// the idle drive while it writes its flash): the next step's interval
    /// is not a missed deadline. Nothing else changes.
    pub fn resume_after_pause(&mut self) {
        self.last_time_us = None;
    }

    /// Takes the rotor's electrical angle from an absolute encoder: the
    /// count `origin_counts` is electrical angle zero (and the shaft
    /// angle's zero), from the first step on, wherever the rotor is then
    /// (after a reset of the chip alone, the machine may have turned).
    /// Without it the first step's count is electrical zero (the rotor held
    /// there by the alignment). Before the first step.
    ///
    /// # Errors
    /// An origin outside one revolution (`counts_per_rev` or more): a
    /// stored offset that cannot be this encoder's.
    pub fn set_encoder_origin(&mut self, origin_counts: u32) -> Result<(), u32> {
        if origin_counts >= self.config.encoder_counts_per_rev {
            return Err(origin_counts);
        }
        self.estimator.set_absolute_origin(origin_counts);
        Ok(())
    }

    /// Clears a latched fault (explicit operator action); back to `Idle`.
    pub fn reset(&mut self) {
        self.supervisor.reset();
        self.enter(DriveState::Idle);
        self.travel = None;
    }

    fn enter(&mut self, state: DriveState) {
        match (self.state, state) {
            (DriveState::PreTorque, DriveState::BrakeLift) => {
                if let (Some(link), Some(t)) = (self.observer.as_mut(), self.travel) {
                    let moved_m = self.estimator.position_counts().saturating_sub(t.start_counts) as f32
                        * core::f32::consts::TAU
                        / self.config.encoder_counts_per_rev as f32
                        * self.config.sheave_radius_m;
                    link.publish(
                        self.speed_ticks,
                        ObserverRequest::Start {
                            lw_m: t.command.lw_start_m + moved_m,
                            m_car_kg: t.command.m_car_kg,
                            encoder_count: self.last_encoder_count,
                        },
                    );
                }
            }
            (DriveState::BrakeLift, DriveState::Travel) => {
                if let Some(c) = self.compensation.as_mut() {
                    c.start_travel();
                }
            }
            (DriveState::Travel, _) => {
                if let Some(c) = self.compensation.as_mut() {
                    c.end_travel();
                }
            }
            _ => {}
        }
        self.state = state;
        self.state_ticks = 0;
    }

    fn state_time_s(&self) -> f32 {
        self.state_ticks as f32 / self.config.speed_loop_hz
    }

    /// Electrical angle of the rotor from the encoder: `p` times the
    /// position within the revolution, as a binary angle. One 32-bit
    /// multiply-and-remainder and one 64-bit multiply: no 64-bit division.
    fn electrical_angle(&self) -> Angle {
        let cpr = self.config.encoder_counts_per_rev.max(1);
        let electrical = self.estimator.revolution_counts() * self.config.pole_pairs as u32 % cpr;
        ((electrical as u64 * self.binary_angle_per_count_q16) >> 16) as u32
    }

    /// Shaft angle within the revolution from the encoder, as a binary angle.
    fn shaft_angle(&self) -> Angle {
        ((self.estimator.revolution_counts() as u64 * self.binary_angle_per_count_q16) >> 16) as u32
    }

    /// The speed travel's reference at `t_s` in `Travel`; first, when
    /// running on at it would not leave room to stop before the limit, the
    /// ramp to rest from the reference at `t_s` (the travel ends there).
    fn speed_reference_at(&mut self, s: SpeedReference, t_s: f32) -> ProfilePoint {
        let p = s.at(t_s);
        if s.stopping {
            return p;
        }
        let (a, j) = (self.config.max_accel_mps2, self.config.max_jerk_mps3);
        let Ok(stop) = SpeedRamp::plan(p, 0.0, a, j) else {
            return p;
        };
        if stop.end().position_m < s.limit_m {
            return p;
        }
        if let Some(Travel { reference: Reference::Speed(running), .. }) = self.travel.as_mut() {
            *running = SpeedReference { ramp: stop, ramp_start_s: t_s, stopping: true, limit_m: s.limit_m };
        }
        p
    }

    /// Whether the travel's reference has come to its end at `t_s` in `Travel`.
    fn reference_ended(&self, t_s: f32) -> bool {
        match self.travel.map(|t| t.reference) {
            Some(Reference::Distance(profile)) => t_s >= profile.duration_s(),
            Some(Reference::Retarget { approach, start_s }) => t_s - start_s >= approach.duration_s(),
            Some(Reference::Speed(s)) => s.stopping && t_s - s.ramp_start_s >= s.ramp.duration_s(),
            None => true,
        }
    }

    /// One PWM period: [`Controller::step_to_output`], then
    /// [`Controller::finish_step`].
    pub fn step(&mut self, frame: &SensorFrame) -> ControlOutput {
        let output = self.step_to_output(frame);
        self.finish_step();
        output
    }

    /// The part of a PWM period that can wait until its outputs are
    /// driven: the learning of the speed-loop tick's ripple compensation
    /// (`RippleCompensator::finish_tick`; it changes only what the next
    /// tick reads). A step that is not finished is finished by the next.
    pub fn finish_step(&mut self) {
        if let Some(c) = self.compensation.as_mut() {
            c.finish_tick();
        }
    }

    /// The part of a PWM period up to its outputs (the compares to write
    /// before the valley); [`Controller::finish_step`] does the rest.
    pub fn step_to_output(&mut self, frame: &SensorFrame) -> ControlOutput {
        if let Some(last) = self.last_time_us {
            // Modular difference of a wrapping microsecond timer.
            self.supervisor.check_step_interval(frame.time_us.wrapping_sub(last));
        }
        self.last_time_us = Some(frame.time_us);
        self.last_encoder_count = frame.encoder_count;

        let codes = frame.phase_current_codes;
        let zero = self.config.adc_zero_code();
        let currents = codes.map(|code| current_from_code(code, zero, self.current_lsb_a));
        self.supervisor.check_currents(codes, currents);
        let dc_bus_v = mul_int(frame.dc_bus_code as i32, self.dc_bus_v_per_code);
        self.supervisor.check_dc_bus(dc_bus_v);
        let delta = self.estimator.count(frame.encoder_count);
        self.supervisor.check_encoder_step(delta);

        if self.step_count % self.speed_divider == 0 {
            self.speed_tick();
            // Fault checks: loop consistency (supervisor faults 8-11) on the
            // latest current-loop sample, before the trip is acted on below.
            self.check_loop_consistency();
        }
        self.step_count = self.step_count.wrapping_add(1);

        if let Some(fault) = self.supervisor.fault() {
            if self.state != DriveState::Tripped(fault) {
                self.enter(DriveState::Tripped(fault));
                self.current_loop.reset();
                self.speed_loop.reset();
                self.iq_ref = Q16::ZERO;
            }
        }

        let pwm_enabled = self.state.pwm_enabled();
        let brake_released = self.state.brake_released();
        let mut pwm_compare = [0u16; 3];
        if pwm_enabled {
            let speed_e =
                Q16::from_bits(self.estimator.speed_radps().to_bits().saturating_mul(self.config.pole_pairs as i32));
            // Ripple compensation while the car follows the profile.
            let iq_ref = match (&self.compensation, self.state) {
                (Some(c), DriveState::Travel) => self.iq_ref.saturating_add(c.iq_a(self.shaft_angle())),
                _ => self.iq_ref,
            };
            let out = self.current_loop.step(
                Abc { a: currents[0], b: currents[1], c: currents[2] },
                self.electrical_angle(),
                speed_e,
                iq_ref,
                dc_bus_v,
            );
            pwm_compare = out.compare;
            self.telemetry.id_a = to_f32(out.current.d);
            self.telemetry.iq_a = to_f32(out.current.q);
            // Fault checks: keep this step's sample for the consistency checks.
            self.loop_sample = LoopSample {
                pwm_enabled: true,
                current_sum: currents[0].saturating_add(currents[1]).saturating_add(currents[2]),
                current: out.current,
                voltage: out.voltage,
                iq_ref,
                speed_e,
            };
        } else {
            self.current_loop.reset();
            self.telemetry.id_a = 0.0;
            self.telemetry.iq_a = 0.0;
            // Fault checks: with the PWM off only the current sum is checked.
            self.loop_sample = LoopSample {
                current_sum: currents[0].saturating_add(currents[1]).saturating_add(currents[2]),
                ..LoopSample::default()
            };
        }
        self.telemetry.iq_ref_a = to_f32(self.iq_ref);
        self.telemetry.angle_rad = self.estimator.angle_rad();
        ControlOutput { pwm_compare, pwm_enabled, brake_released, state: self.state, telemetry: self.telemetry }
    }

    /// Fault checks: the supervisor's consistency checks (faults 8-11: current
    /// sum, current tracking, back-EMF against the encoder, speed following)
    /// on the latest current-loop sample and this tick's speed reference.
    fn check_loop_consistency(&mut self) {
        let s = self.loop_sample;
        let brake_released = self.state.brake_released();
        self.supervisor.check_consistency(&MonitorSample {
            pwm_enabled: s.pwm_enabled,
            brake_released,
            current_sum_a: to_f32(s.current_sum),
            id_a: to_f32(s.current.d),
            iq_a: to_f32(s.current.q),
            iq_ref_a: to_f32(s.iq_ref),
            vd_v: to_f32(s.voltage.d),
            vq_v: to_f32(s.voltage.q),
            speed_e_radps: to_f32(s.speed_e),
            speed_ref_radps: self.telemetry.speed_ref_radps,
            speed_radps: self.telemetry.speed_radps,
        });
    }

    /// The travel's reference at `t` s into the state, in the car-up
    /// coordinate: position (m), speed (m/s), acceleration (m/s^2). At rest
    /// after the travel (hold, brake set) the end position; otherwise zero.
    fn travel_reference(&mut self, travel: &Travel, sign: f32, t: f32) -> (f32, f32, f32) {
        match self.state {
            DriveState::Travel => {
                let p = match travel.reference {
                    Reference::Distance(profile) => profile.at(t),
                    Reference::Retarget { approach, start_s } => approach.at(t - start_s),
                    Reference::Speed(s) => self.speed_reference_at(s, t),
                };
                (sign * p.position_m, sign * p.speed_mps, sign * p.accel_mps2)
            }
            DriveState::Hold | DriveState::BrakeSet => {
                let end = match travel.reference {
                    Reference::Distance(profile) => profile.distance_m(),
                    Reference::Retarget { approach, .. } => approach.at(approach.duration_s()).position_m,
                    Reference::Speed(s) => s.ramp.end().position_m,
                };
                (sign * end, 0.0, 0.0)
            }
            _ => (0.0, 0.0, 0.0),
        }
    }

    /// The observer's schedule: the estimate its task computed from the
    /// previous tick's input, then this tick's input (`kt`: torque constant,
    /// N·m/A). None while the brake sets or without a started observer.
    fn observer_exchange(&mut self, kt: f32) -> Option<ObserverEstimate> {
        match self.observer.as_mut() {
            Some(link) if self.state != DriveState::BrakeSet && link.is_started() => {
                let estimate = link.consume(self.speed_ticks).and_then(|o| o.estimate);
                link.publish(
                    self.speed_ticks,
                    ObserverRequest::Update {
                        encoder_count: self.last_encoder_count,
                        motor_torque_nm: kt * self.telemetry.iq_a,
                    },
                );
                estimate
            }
            _ => None,
        }
    }

    /// Speed-loop period: estimator, over-speed check, sequence, q-current reference.
    fn speed_tick(&mut self) {
        self.speed_ticks = self.speed_ticks.wrapping_add(1);
        self.estimator.update();
        let speed = self.estimator.speed_radps();
        self.supervisor.check_speed(speed);
        self.state_ticks = self.state_ticks.saturating_add(1);
        self.telemetry.speed_radps = to_f32(speed);

        let Some(travel) = self.travel else {
            self.iq_ref = Q16::ZERO;
            self.telemetry.speed_ref_radps = 0.0;
            self.telemetry.ref_speed_mps = 0.0;
            return;
        };
        let c = self.config;
        let r = c.sheave_radius_m;
        let sign = travel.command.direction.sign();
        let kt = c.torque_constant_nm_per_a();
        let t = self.state_time_s();

        // Reference in the car-up coordinate: position (m), speed (m/s), accel (m/s^2).
        let (position_ref, speed_ref, accel_ref) = self.travel_reference(&travel, sign, t);
        let moved_counts = self.estimator.position_counts().saturating_sub(travel.start_counts);
        let position_m = moved_counts as f32 * core::f32::consts::TAU / c.encoder_counts_per_rev as f32 * r;
        let lw_m = travel.command.lw_start_m + position_m;
        let torque_ff =
            out_of_balance_torque_nm(&c, travel.command.m_car_kg, lw_m) + travel.inertia_kg_m2 * accel_ref / r;
        let speed_ref_radps = (speed_ref + POSITION_GAIN_PER_S * (position_ref - position_m)) / r;

        self.telemetry.torque_ff_nm = torque_ff;
        self.telemetry.speed_ref_radps = speed_ref_radps;
        self.telemetry.ref_speed_mps = speed_ref;

        match self.state {
            DriveState::PreTorque => {
                let ramp = (t / PRE_TORQUE_S).min(1.0);
                let torque = travel.holding_torque_nm * ramp;
                self.telemetry.torque_ref_nm = torque;
                self.iq_ref = q16(torque / kt);
                if t >= PRE_TORQUE_S {
                    self.speed_loop.reset();
                    self.enter(DriveState::BrakeLift);
                }
            }
            DriveState::BrakeLift | DriveState::Travel | DriveState::Hold | DriveState::BrakeSet => {
                let speed_ref_q16 = q16(speed_ref_radps);
                let shaft_angle = self.shaft_angle();
                let estimate = self.observer_exchange(kt);
                if let (Some(c), DriveState::Travel) = (self.compensation.as_mut(), self.state) {
                    c.speed_tick(&LearningInput {
                        shaft_angle,
                        position_counts: self.estimator.position_counts(),
                        speed_radps: to_f32(speed),
                        speed_error_radps: to_f32(speed_ref_q16.saturating_sub(speed)),
                        car_acceleration_mps2: estimate.map(|e| e.car_acceleration_mps2),
                        rope_ea_n: estimate.map(|e| e.rope_ea_n),
                        m_car_kg: travel.command.m_car_kg,
                        lw_m,
                        inertia_kg_m2: travel.inertia_kg_m2,
                    });
                }
                let (torque, iq) = self.speed_loop.step(speed_ref_q16, speed, q16(torque_ff));
                self.telemetry.torque_ref_nm = to_f32(torque);
                self.iq_ref = iq;
                let next = match self.state {
                    DriveState::BrakeLift if t >= BRAKE_LIFT_S => Some(DriveState::Travel),
                    DriveState::Travel if self.reference_ended(t) => Some(DriveState::Hold),
                    DriveState::Hold if t >= HOLD_S => Some(DriveState::BrakeSet),
                    DriveState::BrakeSet if t >= BRAKE_SET_S => Some(DriveState::Idle),
                    _ => None,
                };
                if let Some(next) = next {
                    self.enter(next);
                    if next == DriveState::Idle {
                        self.travel = None;
                        self.iq_ref = Q16::ZERO;
                    }
                }
            }
            DriveState::Idle | DriveState::Tripped(_) => self.iq_ref = Q16::ZERO,
        }
    }
}

fn retarget_error(e: ApproachError) -> RetargetError {
    match e {
        ApproachError::CannotStop => RetargetError::CannotStop,
        ApproachError::NonPositiveLimit => RetargetError::OutOfRange,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::supervisor::Fault;

    /// The reference rig's drive parameters (as `configs/rig.toml` gives them).
    fn rig() -> DriveConfig {
        crate::config::reference_rig()
    }

    /// A healthy idle frame at step `k`: zero currents, 100 V bus.
    fn frame(k: u32) -> SensorFrame {
        SensorFrame {
            phase_current_codes: [2048; 3],
            encoder_count: 0,
            dc_bus_code: 2048, // 100.0 V on a 200 V / 4095 scale
            time_us: k * 62 + k / 2,
        }
    }

    fn travel() -> TravelCommand {
        TravelCommand { direction: Direction::Up, distance_m: 1.0, m_car_kg: 70.5, lw_start_m: 2.0 }
    }

    #[test]
    fn idle_is_safe_and_a_command_builds_holding_torque_with_the_brake_applied() {
        let mut c = Controller::new(&rig());
        let out = c.step(&frame(0));
        assert_eq!(out.state, DriveState::Idle);
        assert!(!out.pwm_enabled && !out.brake_released);
        c.command_travel(travel()).unwrap();
        assert_eq!(c.command_travel(travel()), Err(CommandError::NotIdle));
        let mut last = out;
        for k in 1..3200 {
            last = c.step(&frame(k));
        }
        // Just before the end of the 0.2 s ramp (3199 of 3200 steps): the q
        // reference is within a ramp step of Eqn 4 / Kt, brake still applied.
        let expected = out_of_balance_torque_nm(&rig(), 70.5, 2.0) / rig().torque_constant_nm_per_a();
        assert!(last.pwm_enabled && !last.brake_released, "{last:?}");
        assert!(
            (last.telemetry.iq_ref_a - expected).abs() < 0.005 * expected,
            "{} vs {expected}",
            last.telemetry.iq_ref_a
        );
    }

    #[test]
    fn an_over_current_trips_in_the_same_step_and_latches_until_reset() {
        let mut c = Controller::new(&rig());
        c.step(&frame(0));
        c.command_travel(travel()).unwrap();
        for k in 1..100 {
            c.step(&frame(k));
        }
        let mut bad = frame(100);
        bad.phase_current_codes = [2048 + 1300, 2048 - 650, 2048 - 650]; // 31.7 A on phase a
        let out = c.step(&bad);
        assert_eq!(out.state, DriveState::Tripped(Fault::OverCurrent));
        assert!(!out.pwm_enabled && !out.brake_released && out.pwm_compare == [0; 3]);
        for k in 101..2000 {
            let out = c.step(&frame(k));
            assert_eq!(out.state, DriveState::Tripped(Fault::OverCurrent), "recovered by itself at step {k}");
        }
        assert_eq!(c.command_travel(travel()), Err(CommandError::NotIdle));
        c.reset();
        assert_eq!(c.step(&frame(2000)).state, DriveState::Idle);
    }

    #[test]
    fn each_implausible_reading_trips_with_its_reason() {
        type Spoil = fn(&mut SensorFrame);
        let cases: [(Spoil, Fault); 5] = [
            (|f| f.dc_bus_code = 1000, Fault::DcBusUnderVoltage),
            (|f| f.dc_bus_code = 3000, Fault::DcBusOverVoltage),
            (|f| f.phase_current_codes[1] = 0, Fault::CurrentSensorImplausible),
            (|f| f.encoder_count = 500, Fault::EncoderImplausible),
            (|f| f.time_us += 1000, Fault::DeadlineMissed),
        ];
        for (spoil, fault) in cases {
            let mut c = Controller::new(&rig());
            for k in 0..10 {
                c.step(&frame(k));
            }
            let mut bad = frame(10);
            spoil(&mut bad);
            assert_eq!(c.step(&bad).state, DriveState::Tripped(fault));
        }
    }

    #[test]
    fn electrical_angle_is_pole_pairs_times_the_shaft_angle() {
        for counts_per_rev in [16_384u32, 10_000] {
            let mut config = rig();
            config.encoder_counts_per_rev = counts_per_rev;
            let mut c = Controller::new(&config);
            for raw in [0u32, 1, 1234, 16_383, 16_384, 99_999, u32::MAX - 7] {
                c.estimator.count(raw);
                let shaft = c.estimator.position_counts().rem_euclid(counts_per_rev as i64) as f64;
                let turns = (shaft * 6.0 / counts_per_rev as f64).fract();
                let got = c.electrical_angle() as f64 / 4_294_967_296.0;
                assert!((got - turns).abs() < 1e-9, "cpr {counts_per_rev}, raw {raw}: {got} vs {turns}");
            }
        }
    }

    /// With the encoder's origin set (an absolute encoder at its stored
    /// offset) the electrical angle of the first step is the count's less
    /// the origin, wherever the rotor is; without it the first count is
    /// electrical zero. An origin of a whole revolution or more is refused.
    #[test]
    fn an_absolute_encoder_origin_gives_the_angle_from_the_first_step() {
        let config = rig();
        let cpr = config.encoder_counts_per_rev;
        let turns = |c: &Controller| c.electrical_angle() as f64 / 4_294_967_296.0;
        for (origin, first) in [(0u32, 0u32), (0, 1_000), (700, 1_000), (700, 100), (0, u32::MAX - 40)] {
            let mut c = Controller::new(&config);
            c.set_encoder_origin(origin).unwrap();
            c.step(&SensorFrame { encoder_count: first, ..frame(0) });
            let from_origin = (first.wrapping_sub(origin) as i32 as i64).rem_euclid(cpr as i64) as f64;
            let expected = (from_origin * config.pole_pairs as f64 / cpr as f64).fract();
            assert!((turns(&c) - expected).abs() < 1e-9, "origin {origin}, first {first}: {} vs {expected}", turns(&c));
            let mut incremental = Controller::new(&config);
            incremental.step(&SensorFrame { encoder_count: first, ..frame(0) });
            assert_eq!(turns(&incremental), 0.0, "without an origin the first count is electrical zero");
        }
        assert_eq!(Controller::new(&config).set_encoder_origin(cpr), Err(cpr));
    }

    #[test]
    fn a_travel_outside_the_rig_is_refused() {
        let mut c = Controller::new(&rig());
        let mut command = travel();
        command.distance_m = 7.0; // lw would reach 9 m > l_t
        assert_eq!(c.command_travel(command), Err(CommandError::OutOfRange));
        command = travel();
        command.m_car_kg = f32::NAN;
        assert_eq!(c.command_travel(command), Err(CommandError::OutOfRange));
    }

    /// The car as the drive wants it: the encoder follows the shaft speed
    /// reference of each step exactly (currents stay at zero, below the
    /// supervisor's tracking checks). Returns every output and the car
    /// position (m, up positive) after each step.
    struct IdealCar {
        k: u32,
        position_m: f64,
    }

    impl IdealCar {
        fn step(&mut self, c: &mut Controller) -> (ControlOutput, f64) {
            let config = rig();
            let counts = self.position_m / config.sheave_radius_m as f64 / core::f64::consts::TAU
                * config.encoder_counts_per_rev as f64;
            let mut f = frame(self.k);
            f.encoder_count = counts.round() as i64 as u32;
            let out = c.step(&f);
            self.k += 1;
            let speed_mps = out.telemetry.speed_ref_radps as f64 * config.sheave_radius_m as f64;
            if out.brake_released {
                self.position_m += speed_mps / config.current_loop_hz as f64;
            }
            (out, self.position_m)
        }

        /// Steps for `seconds`; the outputs at the speed-loop ticks.
        fn run(&mut self, c: &mut Controller, seconds: f32) -> std::vec::Vec<ControlOutput> {
            let n = (seconds * rig().current_loop_hz) as u32;
            let mut ticks = std::vec::Vec::new();
            for _ in 0..n {
                let out = self.step(c).0;
                if (self.k - 1) % rig().speed_loop_divider() == 0 {
                    ticks.push(out);
                }
            }
            ticks
        }
    }

    extern crate std;

    fn speed_travel(direction: Direction, speed_mps: f32, lw_start_m: f32, lw_limit_m: f32) -> SpeedTravelCommand {
        SpeedTravelCommand { direction, speed_mps, m_car_kg: 70.5, lw_start_m, lw_limit_m }
    }

    /// Acceleration and jerk of the reference speed over speed-loop ticks
    /// (differences over 8 ticks, 4 ms: a few roundings of the f32 speed
    /// make 1e-7 m/s, 0.8 % of the jerk limit over that spacing).
    fn assert_limits(ticks: &[ControlOutput]) {
        let config = rig();
        let n = 8;
        let dt = n as f32 / config.speed_loop_hz;
        let v: std::vec::Vec<f32> = ticks.iter().map(|o| o.telemetry.ref_speed_mps).collect();
        let a: std::vec::Vec<f32> = (n..v.len()).map(|i| (v[i] - v[i - n]) / dt).collect();
        for i in n..a.len() {
            assert!(a[i].abs() <= config.max_accel_mps2 * 1.001, "acceleration {} at tick {i}", a[i]);
            let jerk = (a[i] - a[i - n]) / dt;
            assert!(jerk.abs() <= config.max_jerk_mps3 * 1.02, "jerk {jerk} at tick {i}");
        }
    }

    #[test]
    fn a_speed_travel_runs_at_its_speed_crawls_and_stops_on_command() {
        let config = rig();
        let mut c = Controller::new(&config);
        let mut car = IdealCar { k: 0, position_m: 0.0 };
        car.run(&mut c, 0.01);
        c.command_speed_travel(speed_travel(Direction::Up, 0.4, 2.0, 7.0)).unwrap();
        assert_eq!(c.command_speed_travel(speed_travel(Direction::Up, 0.4, 2.0, 7.0)), Err(CommandError::NotIdle));
        // Pre-torque and brake lift, then the run-up: v/a + a/j = 1.3 s; then 2 s at speed.
        let mut ticks = car.run(&mut c, PRE_TORQUE_S + BRAKE_LIFT_S + 0.01);
        assert_eq!(c.state(), DriveState::Travel);
        ticks.extend(car.run(&mut c, 1.25));
        assert!(ticks.last().unwrap().telemetry.ref_speed_mps < 0.4);
        ticks.extend(car.run(&mut c, 2.0));
        assert!(ticks[ticks.len() - 3000..].iter().all(|o| o.telemetry.ref_speed_mps == 0.4), "runs at V");
        // Deceleration point: down to crawl, 1 s there; the command repeated
        // (as every message of the lift controller repeats it) changes nothing.
        c.command_speed(0.05).unwrap();
        for _ in 0..10 {
            ticks.extend(car.run(&mut c, 0.015));
            c.command_speed(0.05).unwrap();
        }
        ticks.extend(car.run(&mut c, 2.35));
        assert_eq!(ticks.last().unwrap().telemetry.ref_speed_mps, 0.05);
        assert_eq!(c.state(), DriveState::Travel);
        let before_stop = car.position_m;
        c.command_stop().unwrap();
        assert_eq!(c.command_stop(), Ok(()), "a second stop changes nothing");
        assert_eq!(c.command_speed(0.4), Err(SpeedCommandError::NoSpeedTravel), "stopping");
        // Stop from crawl: 2 sqrt(v/j) = 0.447 s, then hold and brake set.
        ticks.extend(car.run(&mut c, 0.44));
        assert_eq!(c.state(), DriveState::Travel);
        ticks.extend(car.run(&mut c, 0.02));
        assert_eq!(c.state(), DriveState::Hold);
        assert_limits(&ticks);
        ticks.extend(car.run(&mut c, HOLD_S + BRAKE_SET_S + 0.01));
        assert_eq!(c.state(), DriveState::Idle);
        // Stop distance from crawl: v * sqrt(v / j) (the mean speed v/2 for 2 sqrt(v/j)).
        let stop_m = 0.05 * (0.05f64).sqrt();
        assert!((car.position_m - before_stop - stop_m).abs() < 1e-3, "{} {}", car.position_m, before_stop);
        assert_eq!(c.command_stop(), Err(SpeedCommandError::NoSpeedTravel));
        assert_eq!(c.command_speed(0.05), Err(SpeedCommandError::NoSpeedTravel));
    }

    #[test]
    fn a_speed_travel_stops_by_itself_at_the_last_landing() {
        for (direction, start, limit) in [(Direction::Up, 2.0f32, 2.7f32), (Direction::Down, 2.7, 2.0)] {
            let config = rig();
            let mut c = Controller::new(&config);
            let mut car = IdealCar { k: 0, position_m: 0.0 };
            car.run(&mut c, 0.01);
            c.command_speed_travel(speed_travel(direction, 0.4, start, limit)).unwrap();
            let mut ticks = car.run(&mut c, 5.0);
            assert_limits(&ticks);
            ticks.extend(car.run(&mut c, 1.0));
            assert_eq!(c.state(), DriveState::Idle, "{direction:?}");
            let moved = car.position_m * direction.sign() as f64;
            assert!((moved - 0.7).abs() < 1e-3, "{direction:?}: stopped {moved} m from the start, limit 0.7 m");
            let peak = ticks.iter().map(|o| o.telemetry.ref_speed_mps.abs()).fold(0.0f32, f32::max);
            assert_eq!(peak, 0.4, "reached the speed before the limit");
        }
    }

    #[test]
    fn the_observer_estimate_of_a_tick_is_used_at_the_next_and_a_missed_deadline_is_counted() {
        let config = rig();
        let chain = crate::config::reference_chain();
        let mut c = Controller::new(&config);
        let table = HarmonicTable::default();
        c.install_compensation(Strategy::CarObserver, &table, &chain);
        assert!(c.uses_observer());
        let mut task = crate::observer::ObserverTask::for_model(&chain).unwrap();
        let mut car = IdealCar { k: 0, position_m: 0.0 };
        car.run(&mut c, 0.01);
        c.command_travel(travel()).unwrap();
        // Through pre-torque: nothing published.
        for _ in 0..(PRE_TORQUE_S * config.current_loop_hz) as u32 - 8 {
            car.step(&mut c);
            assert!(!c.observer_input_waiting());
        }
        // Served after every step (as a task that finishes within the
        // period): at each tick the estimate in use is the one the task
        // computed from the previous tick's input.
        let mut published = 0;
        let mut served: Option<ObserverEstimate> = None;
        for _ in 0..1600 {
            car.step(&mut c);
            if c.observer_input_waiting() {
                published += 1;
                if let Some(previous) = served {
                    assert_eq!(c.observer_estimate(), Some(previous));
                }
                assert!(task.serve(&mut c));
                served = Some(task.observer().estimate()).filter(|_| published > 1);
            }
        }
        assert_eq!(c.state(), DriveState::BrakeLift);
        assert!(published >= 190, "{published} inputs in 0.1 s");
        assert_eq!(c.observer_missed_deadlines(), 0);
        assert!(c.observer_estimate().is_some());
        // A task late by a whole speed-loop period (one input never taken
        // before the next tick): counted at the next tick, whose own input
        // the task then serves.
        let divider = config.speed_loop_divider();
        let mut late_until = None;
        let mut after_skip = None;
        for i in 0..64u32 {
            car.step(&mut c);
            if !c.observer_input_waiting() {
                continue;
            }
            match late_until {
                None => late_until = Some(i + divider),
                Some(until) if i < until => {}
                Some(_) => {
                    after_skip.get_or_insert(c.observer_missed_deadlines());
                    task.serve(&mut c);
                }
            }
        }
        assert_eq!(after_skip, Some(1));
        assert_eq!(c.observer_missed_deadlines(), 1);
    }

    #[test]
    fn a_stop_before_the_brake_is_lifted_ends_the_travel_without_moving() {
        let mut c = Controller::new(&rig());
        let mut car = IdealCar { k: 0, position_m: 0.0 };
        car.run(&mut c, 0.01);
        c.command_speed_travel(speed_travel(Direction::Down, 0.3, 3.0, 1.0)).unwrap();
        car.run(&mut c, 0.1);
        c.command_stop().unwrap();
        car.run(&mut c, 1.5);
        assert_eq!(c.state(), DriveState::Idle);
        assert!(car.position_m.abs() < 1e-4, "{}", car.position_m);
    }

    #[test]
    fn speed_travels_and_speed_changes_out_of_range_are_refused() {
        let mut c = Controller::new(&rig());
        let bad = [
            speed_travel(Direction::Up, 0.5, 2.0, 7.0),   // above rated speed
            speed_travel(Direction::Up, 0.0, 2.0, 7.0),   // no speed
            speed_travel(Direction::Up, 0.4, 2.0, 1.0),   // limit behind the car
            speed_travel(Direction::Down, 0.4, 2.0, 2.0), // no room
            speed_travel(Direction::Up, 0.4, 2.0, 9.5),   // limit off the ropes
            speed_travel(Direction::Up, f32::NAN, 2.0, 7.0),
        ];
        for command in bad {
            assert_eq!(c.command_speed_travel(command), Err(CommandError::OutOfRange), "{command:?}");
        }
        assert_eq!(c.command_stop(), Err(SpeedCommandError::NoSpeedTravel));
        c.command_travel(travel()).unwrap();
        assert_eq!(c.command_speed(0.05), Err(SpeedCommandError::NoSpeedTravel), "a distance travel");
        assert_eq!(c.command_stop(), Err(SpeedCommandError::NoSpeedTravel));
        let mut c = Controller::new(&rig());
        c.command_speed_travel(speed_travel(Direction::Up, 0.4, 2.0, 7.0)).unwrap();
        assert_eq!(c.command_speed(0.0), Err(SpeedCommandError::OutOfRange));
        assert_eq!(c.command_speed(0.41), Err(SpeedCommandError::OutOfRange));
    }
}
