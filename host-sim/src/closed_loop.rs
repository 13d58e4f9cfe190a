//! One closed-loop travel: the drive core of `shared` controls the plant.
//!
//! Timing per PWM period `Ts` (16 kHz): at `t_k` the sensors are sampled and
//! the controller steps; the brake output acts at once; the new PWM compare
//! values act from `t_k + Ts/2` (the next counter underflow of centre-aligned
//! PWM) to `t_k + 3Ts/2`. The data-acquisition system samples the plant at its
//! own rate (16384 Hz): the plant is integrated exactly to every sample
//! instant, so no interpolation is involved.

use indicatif::ProgressBar;
use shared::config::Direction;
use shared::{ControlOutput, Controller, DriveState, SensorFrame, TravelCommand};

use crate::config::RigConfig;
use crate::plant::{Plant, PlantInputs, PlantObservation};
use crate::recording::{CarDirection, Column, Recording, RecordingKind, RecordingMeta};

/// One travel to simulate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TravelSpec {
    /// Car mass, kg (the plant's and the load weighing's).
    pub m_car_kg: f64,
    /// Car direction.
    pub direction: Direction,
    /// Counterweight-side rope length at the start, m.
    pub lw_start_m: f64,
    /// Counterweight-side rope length at the end, m.
    pub lw_end_m: f64,
}

impl TravelSpec {
    /// The full travel of `rig` between `[travel].lw_low_m` and `lw_high_m`
    /// (car up: `lw` grows from low to high).
    pub fn full_travel(rig: &RigConfig, m_car_kg: f64, direction: Direction) -> Self {
        let (lw_start_m, lw_end_m) = match direction {
            Direction::Up => (rig.travel.lw_low_m, rig.travel.lw_high_m),
            Direction::Down => (rig.travel.lw_high_m, rig.travel.lw_low_m),
        };
        Self { m_car_kg, direction, lw_start_m, lw_end_m }
    }
}

/// Numerical settings of a simulation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimOptions {
    /// Longest integration step, s (default: a quarter of a PWM period).
    pub max_step_s: f64,
    /// Data-acquisition sample rate, Hz.
    pub sample_rate_hz: f64,
    /// Recording after the drive is back in `Idle`, s.
    pub tail_s: f64,
    /// Stop after this many control steps (a partial travel), if set.
    pub max_control_steps: Option<u64>,
}

impl SimOptions {
    /// Defaults for `rig`: step `Ts/4`, the rig's sample rate, 0.5 s tail.
    pub fn for_rig(rig: &RigConfig) -> Self {
        Self {
            max_step_s: 0.25 / rig.control.current_loop_hz,
            sample_rate_hz: rig.measurement.sample_rate_hz,
            tail_s: 0.5,
            max_control_steps: None,
        }
    }
}

/// Why a simulation stopped.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The travel is outside the rig.
    #[error("travel out of range: {0}")]
    BadTravel(String),
    /// The controller refused the travel command.
    #[error("the drive refused the travel command: {0:?}")]
    Refused(shared::controller::CommandError),
    /// The drive tripped.
    #[error("the drive tripped at t = {time_s:.4} s: {fault:?}")]
    Tripped {
        /// Time of the trip, s.
        time_s: f64,
        /// Fault.
        fault: shared::supervisor::Fault,
    },
    /// The simulation did not finish in the allowed time.
    #[error("the travel did not finish within {0:.1} s of simulated time")]
    Timeout(f64),
    /// The plant state became non-finite or a rope length left its range.
    #[error("the plant left its valid range at t = {0:.4} s")]
    Diverged(f64),
    /// The link to a controller outside this process failed.
    #[error("controller link: {0}")]
    Link(String),
}

/// A drive controller the closed loop can run: the drive core in this
/// process, or the same code on another processor behind a link.
pub trait DriveController {
    /// Starts a travel.
    fn command_travel(&mut self, command: TravelCommand) -> Result<(), SimError>;
    /// One PWM period.
    fn step(&mut self, sensors: &SensorFrame) -> Result<ControlOutput, SimError>;
}

impl DriveController for Controller {
    fn command_travel(&mut self, command: TravelCommand) -> Result<(), SimError> {
        Controller::command_travel(self, command).map_err(SimError::Refused)
    }

    fn step(&mut self, sensors: &SensorFrame) -> Result<ControlOutput, SimError> {
        Ok(Controller::step(self, sensors))
    }
}

/// What went into and came out of the controller, step by step.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StepLog {
    /// The travel command given before the first step.
    pub command: Option<TravelCommand>,
    /// Sensor readings and outputs of every control step, in order.
    pub steps: Vec<(SensorFrame, ControlOutput)>,
}

/// The samples of one simulated travel, each vector one value per
/// data-acquisition sample.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TravelRun {
    /// Sample rate, Hz.
    pub sample_rate_hz: f64,
    /// Sample times, s.
    pub time_s: Vec<f64>,
    /// Car acceleration, m/s^2, positive up.
    pub acc_car_mps2: Vec<f64>,
    /// Counterweight acceleration, m/s^2, positive up.
    pub acc_cw_mps2: Vec<f64>,
    /// Phase currents a, b, c, A.
    pub phase_currents_a: [Vec<f64>; 3],
    /// The drive's encoder speed estimate, rad/s.
    pub speed_radps: Vec<f64>,
    /// Encoder shaft angle, rad, unwrapped.
    pub angle_rad: Vec<f64>,
    /// Reference speed of a sheave-edge point, m/s.
    pub ref_speed_mps: Vec<f64>,
    /// Electromagnetic torque of the machine, N m.
    pub motor_torque_nm: Vec<f64>,
    /// Ripple torque, N m.
    pub ripple_torque_nm: Vec<f64>,
    /// True shaft speed, rad/s.
    pub shaft_speed_radps: Vec<f64>,
    /// Counterweight-side rope length, m.
    pub lw_m: Vec<f64>,
    /// Drive state code ([`DriveState::code`]): 0 idle, 1 pre-torque, 2 brake lift, 3 travel,
    /// 4 hold, 5 brake set, 100 + reason when tripped.
    pub drive_state: Vec<f64>,
}

/// Simulates `spec` on `rig` with the drive core (in this process) in the loop.
pub fn simulate_travel(
    rig: &RigConfig,
    spec: &TravelSpec,
    options: &SimOptions,
    progress: Option<&ProgressBar>,
) -> Result<TravelRun, SimError> {
    let mut controller = Controller::new(&rig.drive_config());
    simulate_travel_with(rig, spec, options, &mut controller, progress, None)
}

/// Simulates `spec` on `rig` with `controller` in the loop; `log`, if
/// given, receives every step's inputs and outputs.
pub fn simulate_travel_with(
    rig: &RigConfig,
    spec: &TravelSpec,
    options: &SimOptions,
    controller: &mut dyn DriveController,
    progress: Option<&ProgressBar>,
    mut log: Option<&mut StepLog>,
) -> Result<TravelRun, SimError> {
    let total = rig.mechanics.rope_total_length_m;
    let inside = |lw: f64| lw > 0.0 && lw < total;
    if !(inside(spec.lw_start_m) && inside(spec.lw_end_m)) {
        return Err(SimError::BadTravel(format!(
            "lw_start_m = {} and lw_end_m = {} must lie in (0, {total}) m",
            spec.lw_start_m, spec.lw_end_m
        )));
    }
    let distance = (spec.lw_end_m - spec.lw_start_m) * spec.direction.sign() as f64;
    if distance <= 0.0 {
        return Err(SimError::BadTravel(format!(
            "direction {:?} needs lw_end_m on the {} side of lw_start_m (car up: lw grows)",
            spec.direction,
            if spec.direction == Direction::Up { "greater" } else { "smaller" }
        )));
    }
    let command = TravelCommand {
        direction: spec.direction,
        distance_m: distance as f32,
        m_car_kg: spec.m_car_kg as f32,
        lw_start_m: spec.lw_start_m as f32,
    };
    controller.command_travel(command)?;
    if let Some(log) = log.as_deref_mut() {
        log.command = Some(command);
    }
    let mut plant = Plant::new(rig, spec.m_car_kg, spec.lw_start_m);

    let ts = 1.0 / rig.control.current_loop_hz;
    let sample_period = 1.0 / options.sample_rate_hz;
    // Generous bound: the profile plus the sequence plus the tail, doubled.
    let time_limit = 2.0 * (distance / rig.travel.rated_speed_mps + 10.0 + options.tail_s);
    let expected_steps = (time_limit / 2.0 / ts) as u64;
    if let Some(bar) = progress {
        bar.set_length(expected_steps);
    }
    let mut run = TravelRun { sample_rate_hz: options.sample_rate_hz, ..TravelRun::default() };
    let mut next_sample: u64 = 0;
    let mut finished_at: Option<f64> = None;
    let mut k: u64 = 0;
    loop {
        let t_k = k as f64 * ts;
        let sensors = plant.sensor_frame();
        let output = controller.step(&sensors)?;
        if let Some(log) = log.as_deref_mut() {
            log.steps.push((sensors, output));
        }
        if let DriveState::Tripped(fault) = output.state {
            return Err(SimError::Tripped { time_s: t_k, fault });
        }
        let mut inputs = plant.inputs();
        inputs.brake_engaged = !output.brake_released;
        plant.set_inputs(inputs);
        let mut advance_to = |plant: &mut Plant, t_end: f64, run: &mut TravelRun| {
            loop {
                let t_sample = next_sample as f64 * sample_period;
                if t_sample >= t_end {
                    break;
                }
                plant.advance(t_sample - plant.time_s(), options.max_step_s);
                record(run, t_sample, &plant.observe(), &output);
                next_sample += 1;
            }
            plant.advance(t_end - plant.time_s(), options.max_step_s);
        };
        advance_to(&mut plant, t_k + 0.5 * ts, &mut run);
        plant.set_inputs(PlantInputs {
            pwm_compare: output.pwm_compare,
            pwm_enabled: output.pwm_enabled,
            brake_engaged: !output.brake_released,
        });
        advance_to(&mut plant, (k + 1) as f64 * ts, &mut run);

        let o = plant.observe();
        if !(o.car_acceleration_mps2.is_finite() && inside(o.counterweight_side_length_m)) {
            return Err(SimError::Diverged(plant.time_s()));
        }
        if output.state == DriveState::Idle && k > 0 && finished_at.is_none() {
            finished_at = Some(t_k);
        }
        if let Some(t_done) = finished_at {
            if t_k >= t_done + options.tail_s {
                break;
            }
        }
        if t_k > time_limit {
            return Err(SimError::Timeout(time_limit));
        }
        k += 1;
        if options.max_control_steps.is_some_and(|max| k >= max) {
            break;
        }
        if let Some(bar) = progress {
            if k % 1600 == 0 {
                bar.set_position(k.min(expected_steps));
            }
        }
    }
    if let Some(bar) = progress {
        bar.finish_and_clear();
    }
    Ok(run)
}

fn record(run: &mut TravelRun, t: f64, o: &PlantObservation, output: &shared::ControlOutput) {
    run.time_s.push(t);
    run.acc_car_mps2.push(o.car_acceleration_mps2);
    run.acc_cw_mps2.push(o.counterweight_acceleration_mps2);
    for (column, value) in run.phase_currents_a.iter_mut().zip(o.phase_currents_a) {
        column.push(value);
    }
    run.speed_radps.push(output.telemetry.speed_radps as f64);
    run.angle_rad.push(output.telemetry.angle_rad as f64);
    run.ref_speed_mps.push(output.telemetry.ref_speed_mps as f64);
    run.motor_torque_nm.push(o.motor_torque_nm);
    run.ripple_torque_nm.push(o.ripple_torque_nm);
    run.shaft_speed_radps.push(o.shaft_speed_radps);
    run.lw_m.push(o.counterweight_side_length_m);
    run.drive_state.push(output.state.code() as f64);
}

impl TravelRun {
    /// The run as a recording in the measurement format: the required and
    /// optional columns of the format, then the simulator's own columns
    /// (`motor_torque_nm`, `ripple_torque_nm`, `shaft_speed_true_radps`,
    /// `lw_m`, `drive_state`), which readers keep and ignore.
    pub fn to_recording(&self, spec: &TravelSpec, m_cw_kg: f64, description: String) -> Recording {
        use crate::recording as rec;
        let columns = vec![
            Column::new(rec::TIME_S, self.time_s.clone()),
            Column::new(rec::ACC_CAR, self.acc_car_mps2.clone()),
            Column::new(rec::ACC_CW, self.acc_cw_mps2.clone()),
            Column::new(rec::I_A, self.phase_currents_a[0].clone()),
            Column::new(rec::I_B, self.phase_currents_a[1].clone()),
            Column::new(rec::I_C, self.phase_currents_a[2].clone()),
            Column::new(rec::SPEED, self.speed_radps.clone()),
            Column::new(rec::ANGLE, self.angle_rad.clone()),
            Column::new(rec::REF_SPEED, self.ref_speed_mps.clone()),
            Column::new("motor_torque_nm", self.motor_torque_nm.clone()),
            Column::new("ripple_torque_nm", self.ripple_torque_nm.clone()),
            Column::new("shaft_speed_true_radps", self.shaft_speed_radps.clone()),
            Column::new("lw_m", self.lw_m.clone()),
            Column::new("drive_state", self.drive_state.clone()),
        ];
        Recording {
            meta: RecordingMeta {
                kind: RecordingKind::Travel {
                    m_car_kg: spec.m_car_kg,
                    m_cw_kg,
                    direction: match spec.direction {
                        Direction::Up => CarDirection::Up,
                        Direction::Down => CarDirection::Down,
                    },
                    lw_start_m: spec.lw_start_m,
                    lw_end_m: spec.lw_end_m,
                },
                sample_rate_hz: self.sample_rate_hz,
                description: Some(description),
            },
            columns,
        }
    }

    /// Duration of the recording, s.
    pub fn duration_s(&self) -> f64 {
        self.time_s.len() as f64 / self.sample_rate_hz
    }
}
