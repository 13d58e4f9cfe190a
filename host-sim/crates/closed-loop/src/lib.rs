//! The drive closed around the plant, and what runs on closed loops.
//!
//! In the data flow config -> plant <-> controller -> recording -> analysis
//! -> diagnosis this crate is the `<->` and the arrow to the recording: the
//! drive core (`drive-core`) or another [`DriveController`] steps on the
//! plant's sensor frames, and a travel becomes a [`Recording`]. It depends on
//! `drive-core`, `plant`, `recording` and `rig-config`, and on `dsp` for the
//! ride measures of the compensation runs; nothing downstream (the diagnosis)
//! is visible from here.
//!
//! - this crate's root: one closed-loop travel ([`simulate_travel`] and its
//!   variants), the data acquisition, the [`FaultHook`];
//! - [`faults`]: fault kinds, their injection and the runs of `host-sim faults`;
//! - [`foreign`]: a commercial drive and a foreign data acquisition;
//! - [`synthetic`]: rig-like datasets from the full plant (`host-sim dataset`);
//! - [`compensation`]: the ripple-compensation strategies over travels and
//!   mismatches (`host-sim compare`);
//! - [`pil`]: the drive core in QEMU as a [`DriveController`] (`host-sim pil`).
//!
//! One closed-loop travel: the drive core controls the plant.
//!
//! Timing per PWM period `Ts` (16 kHz): at `t_k` the sensors are sampled and
//! the controller steps; the brake output acts at once; the new PWM compare
//! values act from `t_k + Ts/2` (the next counter underflow of centre-aligned
//! PWM) to `t_k + 3Ts/2`. The data-acquisition system samples the plant at its
//! own rate (16384 Hz): the plant is integrated exactly to every sample
//! instant, so no interpolation is involved.

#![warn(missing_docs)]

pub mod compensation;
pub mod faults;
pub mod foreign;
pub mod pil;
pub mod synthetic;

use drive_core::config::Direction;
use drive_core::{ControlOutput, Controller, DriveState, SensorFrame, TravelCommand};
use indicatif::ProgressBar;

use plant::effects::Effects;
use plant::{Integrator, Plant, PlantInputs, PlantObservation};
use recording::{CarDirection, Column, Recording, RecordingKind, RecordingMeta};
use rig_config::RigConfig;

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
    /// Longest RK4 step, s (default: a quarter of a PWM period). The
    /// nominal plant with [`Integrator::Fast`] takes each PWM half period in
    /// one exact step instead ([`plant::exact`]) and does not use it.
    pub max_step_s: f64,
    /// Data-acquisition sample rate, Hz.
    pub sample_rate_hz: f64,
    /// Recording after the drive is back in `Idle`, s.
    pub tail_s: f64,
    /// Stop after this many control steps (a partial travel), if set.
    pub max_control_steps: Option<u64>,
    /// The library's effects on the simulated plant (none: the nominal plant).
    pub effects: Effects,
    /// How the plant integrates (default [`Integrator::Fast`];
    /// [`Integrator::Reference`] is the yardstick of its accuracy).
    pub integrator: Integrator,
}

impl SimOptions {
    /// Defaults for `rig`: step `Ts/4`, the rig's sample rate, 0.5 s tail,
    /// the nominal plant.
    pub fn for_rig(rig: &RigConfig) -> Self {
        Self {
            max_step_s: 0.25 / rig.control.current_loop_hz,
            sample_rate_hz: rig.measurement.sample_rate_hz,
            tail_s: 0.5,
            max_control_steps: None,
            effects: Effects::none(),
            integrator: Integrator::Fast,
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
    Refused(drive_core::controller::CommandError),
    /// The drive tripped.
    #[error("the drive tripped at t = {time_s:.4} s: {fault:?}")]
    Tripped {
        /// Time of the trip, s.
        time_s: f64,
        /// Fault.
        fault: drive_core::supervisor::Fault,
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
    /// The recording of the travel would not fit in memory.
    #[error(
        "a travel of about {duration_s:.0} s sampled at {sample_rate_hz} Hz would hold {:.1} GB of samples; \
         expected at most {:.1} GB: a sample rate of at most {:.0} Hz",
        bytes / 1e9,
        MAX_RUN_BYTES / 1e9,
        sample_rate_hz * MAX_RUN_BYTES / bytes
    )]
    TooLarge {
        /// Sample rate asked for, Hz.
        sample_rate_hz: f64,
        /// Expected duration of the travel, s.
        duration_s: f64,
        /// Memory its samples would take, bytes.
        bytes: f64,
    },
}

/// Largest memory the samples of one simulated travel may take, bytes
/// (1 GiB: a 20 s travel at about 400 kHz; a dataset runs several at once).
pub const MAX_RUN_BYTES: f64 = (1u64 << 30) as f64;

/// Signals a [`TravelRun`] records per sample (each an `f64`).
const RUN_SIGNALS: f64 = 12.0;

/// A drive controller the closed loop can run: the drive core in this
/// process, or the same code on another processor behind a link.
pub trait DriveController {
    /// Starts a travel.
    fn command_travel(&mut self, command: TravelCommand) -> Result<(), SimError>;
    /// One PWM period.
    fn step(&mut self, sensors: &SensorFrame) -> Result<ControlOutput, SimError>;
    /// One PWM period whose sensor frame is corrupted on the link: byte
    /// `byte_index` of its encoding XOR `xor`. `None`: the controller did not
    /// step (the frame was rejected). The default runs the frame through the
    /// link codec in this process ([`corrupted_frame`]).
    fn step_corrupted(
        &mut self,
        sensors: &SensorFrame,
        byte_index: usize,
        xor: u8,
    ) -> Result<Option<ControlOutput>, SimError> {
        match corrupted_frame(sensors, byte_index, xor) {
            Some(frame) => self.step(&frame).map(Some),
            None => Ok(None),
        }
    }
}

/// What happens to one control step under fault injection ([`FaultHook`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum StepAction {
    /// The controller steps on this frame (possibly altered by a sensor fault).
    Run(SensorFrame),
    /// The step runs `delay_s` (s) late: the frame carries the time stamp of
    /// its execution; with a delay of half a period or more the previous
    /// outputs act to the end of this period and the new ones from then on.
    Late {
        /// The sensor readings (sampled on time by the hardware trigger).
        frame: SensorFrame,
        /// Delay of the step, s.
        delay_s: f64,
    },
    /// The step does not run: the timer keeps the previous compare values,
    /// enable and brake outputs.
    Skip,
    /// The frame reaches the controller corrupted: byte `byte_index` of its
    /// link encoding (`drive_core::frame`) XOR `xor`.
    Corrupt {
        /// The sensor readings before corruption.
        frame: SensorFrame,
        /// Index of the corrupted byte in the encoded frame.
        byte_index: usize,
        /// Bits flipped in that byte.
        xor: u8,
    },
}

/// Fault injection into the closed loop (see `crate::faults`): plant-side
/// faults change the plant before a step, sensor and timing faults change
/// what the controller gets, and the run may go on after a trip.
///
/// Every method has a default that changes nothing (the plant untouched,
/// the readings passed on, the run ended by a trip): a hook implements only
/// what it injects.
pub trait FaultHook {
    /// Before the step at `t_s` (s): change the plant (faults in the power
    /// stage, the bus, the load or the brake). Default: nothing.
    fn before_step(&mut self, _t_s: f64, _plant: &mut Plant) {}
    /// What the controller gets at `t_s` for the readings `frame`. Default:
    /// the readings, on time ([`StepAction::Run`]).
    fn sensors(&mut self, _t_s: f64, frame: SensorFrame, _plant: &Plant) -> StepAction {
        StepAction::Run(frame)
    }
    /// After the period that started at `t_s`, with the outputs in force.
    /// Default: nothing.
    fn after_step(&mut self, _t_s: f64, _plant: &Plant, _output: &ControlOutput) {}
    /// How long (s) to keep simulating after a trip (PWM off, brake
    /// commanded); `None` ends the run with [`SimError::Tripped`]. Default:
    /// `None`.
    fn keep_running_after_trip_s(&self) -> Option<f64> {
        None
    }
}

/// What the controller receives of a sensor frame corrupted on the link:
/// the frame encoded with the link codec (`drive_core::frame`), byte
/// `byte_index` XOR `xor`, decoded by a fresh decoder; `None` when the
/// decoder rejects it (CRC) or never completes it.
pub fn corrupted_frame(sensors: &SensorFrame, byte_index: usize, xor: u8) -> Option<SensorFrame> {
    use drive_core::frame::{encode, Decoder, Message, MAX_FRAME};
    let mut bytes = [0u8; MAX_FRAME];
    let n = encode(&Message::Sense(*sensors), &mut bytes);
    if let Some(byte) = bytes[..n].get_mut(byte_index) {
        *byte ^= xor;
    }
    let mut decoder = Decoder::new();
    bytes[..n].iter().find_map(|&byte| match decoder.push(byte) {
        Some(Ok(Message::Sense(frame))) => Some(frame),
        _ => None,
    })
}

impl DriveController for Controller {
    fn command_travel(&mut self, command: TravelCommand) -> Result<(), SimError> {
        Controller::command_travel(self, command).map_err(SimError::Refused)
    }

    fn step(&mut self, sensors: &SensorFrame) -> Result<ControlOutput, SimError> {
        Ok(Controller::step(self, sensors))
    }
}

/// The drive core with the chain observer's task: after each control step
/// the task serves the input the controller published (if any), as a task
/// of lower priority that finishes before the next PWM period; the
/// controller uses its estimate at the next speed-loop tick
/// (`drive_core::observer::task`), as on the chip.
pub struct ObservedController<'a> {
    /// The drive core.
    pub controller: &'a mut Controller,
    /// The observer's task.
    pub task: drive_core::observer::ObserverTask,
}

impl DriveController for ObservedController<'_> {
    fn command_travel(&mut self, command: TravelCommand) -> Result<(), SimError> {
        Controller::command_travel(self.controller, command).map_err(SimError::Refused)
    }

    fn step(&mut self, sensors: &SensorFrame) -> Result<ControlOutput, SimError> {
        let output = Controller::step(self.controller, sensors);
        self.task.serve(self.controller);
        Ok(output)
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
    log: Option<&mut StepLog>,
) -> Result<TravelRun, SimError> {
    simulate_travel_faulted(rig, spec, options, controller, None, progress, log)
}

/// [`simulate_travel_with`] with faults injected by `hook` (none: the
/// nominal loop). With a hook that keeps running after a trip, the run goes
/// on with the controller tripped (PWM off, brake commanded) for that long
/// and returns `Ok`; a corrupted frame goes through
/// [`DriveController::step_corrupted`].
pub fn simulate_travel_faulted(
    rig: &RigConfig,
    spec: &TravelSpec,
    options: &SimOptions,
    controller: &mut dyn DriveController,
    mut hook: Option<&mut dyn FaultHook>,
    progress: Option<&ProgressBar>,
    mut log: Option<&mut StepLog>,
) -> Result<TravelRun, SimError> {
    let total = rig.mechanics.rope_total_length_m;
    let (command, distance) = travel_command(spec, total)?;
    controller.command_travel(command)?;
    if let Some(log) = log.as_deref_mut() {
        log.command = Some(command);
    }
    let mut plant = Plant::with_effects(rig, spec.m_car_kg, spec.lw_start_m, &options.effects);
    plant.set_integrator(options.integrator);

    let ts = 1.0 / rig.control.current_loop_hz;
    // Generous bound: the profile plus the sequence plus the tail, doubled.
    let time_limit = 2.0 * (distance / rig.travel.rated_speed_mps + 10.0 + options.tail_s);
    let expected_steps = (time_limit / 2.0 / ts) as u64;
    let bytes = time_limit / 2.0 * options.sample_rate_hz * RUN_SIGNALS * 8.0;
    if bytes > MAX_RUN_BYTES {
        return Err(SimError::TooLarge { sample_rate_hz: options.sample_rate_hz, duration_s: time_limit / 2.0, bytes });
    }
    if let Some(bar) = progress {
        bar.set_length(expected_steps);
    }
    let mut run = TravelRun::with_capacity(options.sample_rate_hz, expected_samples(time_limit, options));
    let mut acquisition = Acquisition {
        ts,
        sample_period: 1.0 / options.sample_rate_hz,
        next_sample: 0,
        max_step_s: options.max_step_s,
        sample_times: Vec::new(),
    };
    let mut finished_at: Option<f64> = None;
    let mut k: u64 = 0;
    // Outputs in force (what the timer holds when a step does not run).
    let mut held: Option<ControlOutput> = None;
    let mut tripped_at: Option<f64> = None;
    loop {
        let t_k = k as f64 * ts;
        let (stepped, late) = control_step(controller, &mut hook, &mut plant, t_k, ts)?;
        let output = output_in_force(stepped, held, &mut log);
        if let DriveState::Tripped(fault) = output.state {
            if trip_run_over(&hook, fault, t_k, &mut tripped_at)? {
                break;
            }
        }
        // A late step's outputs load one underflow later: the previous ones act this period.
        let previous = held.unwrap_or(output);
        let applied_first_half = if late { previous } else { output };
        held = Some(output);
        acquisition.period(&mut plant, &mut run, k, &output, applied_first_half, late);
        if let Some(hook) = hook.as_deref_mut() {
            hook.after_step(t_k, &plant, &output);
        }

        if !plant.in_valid_range() {
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

/// Samples to reserve room for in a run whose time limit is `time_limit`
/// (s): those of half of it (the bound [`MAX_RUN_BYTES`] is checked on),
/// so that the columns do not grow (and copy) during the run; pages of the
/// room not reached are never touched.
fn expected_samples(time_limit: f64, options: &SimOptions) -> usize {
    let samples = time_limit / 2.0 * options.sample_rate_hz;
    if samples.is_finite() && samples > 0.0 {
        samples as usize + 16
    } else {
        0
    }
}

/// True when the counterweight-side rope length `lw` (m) lies inside the
/// rope of length `total_m` (m), ends excluded.
fn inside_rope(lw: f64, total_m: f64) -> bool {
    lw > 0.0 && lw < total_m
}

/// The drive's command for `spec` on a rope of `total_m` (m) and the travel
/// distance (m), or why `spec` is not a travel of that rope.
fn travel_command(spec: &TravelSpec, total_m: f64) -> Result<(TravelCommand, f64), SimError> {
    let total = total_m;
    let inside = |lw: f64| inside_rope(lw, total);
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
    Ok((command, distance))
}

/// The plant's sensor readings as the drive core's frame.
pub fn sensor_frame(plant: &Plant) -> SensorFrame {
    let r = plant.sensor_readings();
    SensorFrame {
        phase_current_codes: r.phase_current_codes,
        encoder_count: r.encoder_count,
        dc_bus_code: r.dc_bus_code,
        time_us: r.time_us,
    }
}

/// The control step at `t_k` (s) of a PWM period `ts` (s): the hook changes
/// the plant and what the controller gets, the controller steps (or not).
/// Returns the frame the controller stepped on with its outputs (`None`: no
/// step ran) and whether the outputs came late (half a period or more).
fn control_step(
    controller: &mut dyn DriveController,
    hook: &mut Option<&mut dyn FaultHook>,
    plant: &mut Plant,
    t_k: f64,
    ts: f64,
) -> Result<(Option<(SensorFrame, ControlOutput)>, bool), SimError> {
    if let Some(hook) = hook.as_deref_mut() {
        hook.before_step(t_k, plant);
    }
    let sensors = sensor_frame(plant);
    let action = match hook.as_deref_mut() {
        Some(hook) => hook.sensors(t_k, sensors, plant),
        None => StepAction::Run(sensors),
    };
    let (stepped, late) = match action {
        StepAction::Run(frame) => (Some((frame, controller.step(&frame)?)), false),
        StepAction::Late { mut frame, delay_s } => {
            frame.time_us = frame.time_us.wrapping_add((delay_s * 1.0e6).round() as u32);
            (Some((frame, controller.step(&frame)?)), delay_s >= 0.5 * ts)
        }
        StepAction::Skip => (None, false),
        StepAction::Corrupt { frame, byte_index, xor } => {
            (controller.step_corrupted(&frame, byte_index, xor)?.map(|o| (frame, o)), false)
        }
    };
    Ok((stepped, late))
}

/// The outputs in force after a control step: the step's (logged in `log`),
/// else the `held` ones of the last step, else everything off (idle).
fn output_in_force(
    stepped: Option<(SensorFrame, ControlOutput)>,
    held: Option<ControlOutput>,
    log: &mut Option<&mut StepLog>,
) -> ControlOutput {
    match (stepped, held) {
        (Some((frame, output)), _) => {
            if let Some(log) = log.as_deref_mut() {
                log.steps.push((frame, output));
            }
            output
        }
        (None, Some(previous)) => previous,
        (None, None) => ControlOutput {
            pwm_compare: [0; 3],
            pwm_enabled: false,
            brake_released: false,
            state: DriveState::Idle,
            telemetry: drive_core::controller::Telemetry::default(),
        },
    }
}

/// The drive tripped with `fault` at `t_k` (s): an error when the hook does
/// not keep the run going after a trip, else whether the time it keeps it
/// going (counted from the first trip, `tripped_at`) is over.
fn trip_run_over(
    hook: &Option<&mut dyn FaultHook>,
    fault: drive_core::supervisor::Fault,
    t_k: f64,
    tripped_at: &mut Option<f64>,
) -> Result<bool, SimError> {
    match hook.as_deref().and_then(|h| h.keep_running_after_trip_s()) {
        None => Err(SimError::Tripped { time_s: t_k, fault }),
        Some(after_s) => {
            let since = *tripped_at.get_or_insert(t_k);
            Ok(t_k >= since + after_s)
        }
    }
}

/// The data acquisition of a travel: samples the plant every
/// `sample_period` s while it advances through the PWM periods of `ts` s.
struct Acquisition {
    /// PWM period, s.
    ts: f64,
    /// Sample period of the acquisition, s.
    sample_period: f64,
    /// Index of the next sample to take.
    next_sample: u64,
    /// Longest integration step of the plant, s.
    max_step_s: f64,
    /// Sample times inside the interval being advanced, s (reused).
    sample_times: Vec<f64>,
}

impl Acquisition {
    /// Advances `plant` to `t_end` (s), recording into `run` every sample
    /// instant on the way with the drive's `output`.
    fn advance_to(&mut self, plant: &mut Plant, t_end: f64, run: &mut TravelRun, output: &ControlOutput) {
        self.sample_times.clear();
        loop {
            let t_sample = self.next_sample as f64 * self.sample_period;
            if t_sample >= t_end {
                break;
            }
            self.sample_times.push(t_sample);
            self.next_sample += 1;
        }
        plant.advance_until(t_end, self.max_step_s, &self.sample_times, |t, o| record(run, t, o, output));
    }

    /// PWM period `k`: the brake output acts at once, `applied_first_half`
    /// from the next counter underflow (half a period on) to the end of the
    /// period; a `late` step's `output` loads at the end of the period.
    fn period(
        &mut self,
        plant: &mut Plant,
        run: &mut TravelRun,
        k: u64,
        output: &ControlOutput,
        applied_first_half: ControlOutput,
        late: bool,
    ) {
        let ts = self.ts;
        let t_k = k as f64 * ts;
        let mut inputs = plant.inputs();
        inputs.brake_engaged = !applied_first_half.brake_released;
        plant.set_inputs(inputs);
        self.advance_to(plant, t_k + 0.5 * ts, run, output);
        plant.set_inputs(PlantInputs {
            pwm_compare: applied_first_half.pwm_compare,
            pwm_enabled: applied_first_half.pwm_enabled,
            brake_engaged: !applied_first_half.brake_released,
        });
        self.advance_to(plant, (k + 1) as f64 * ts, run, output);
        if late {
            plant.set_inputs(PlantInputs {
                pwm_compare: output.pwm_compare,
                pwm_enabled: output.pwm_enabled,
                brake_engaged: !output.brake_released,
            });
        }
    }
}

fn record(run: &mut TravelRun, t: f64, o: &PlantObservation, output: &drive_core::ControlOutput) {
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
    /// An empty run at `sample_rate_hz` (Hz) with room for `samples` samples
    /// in every column.
    pub fn with_capacity(sample_rate_hz: f64, samples: usize) -> Self {
        let column = || Vec::with_capacity(samples);
        Self {
            sample_rate_hz,
            time_s: column(),
            acc_car_mps2: column(),
            acc_cw_mps2: column(),
            phase_currents_a: [column(), column(), column()],
            speed_radps: column(),
            angle_rad: column(),
            ref_speed_mps: column(),
            motor_torque_nm: column(),
            ripple_torque_nm: column(),
            shaft_speed_radps: column(),
            lw_m: column(),
            drive_state: column(),
        }
    }

    /// The run as a recording in the measurement format: the required and
    /// optional columns of the format, then the simulator's own columns
    /// (`motor_torque_nm`, `ripple_torque_nm`, `shaft_speed_true_radps`,
    /// `lw_m`, `drive_state`), which readers keep and ignore.
    pub fn to_recording(&self, spec: &TravelSpec, m_cw_kg: f64, description: String) -> Recording {
        self.clone().into_recording(spec, m_cw_kg, description)
    }

    /// [`TravelRun::to_recording`] taking the run's columns instead of
    /// copying them.
    pub fn into_recording(self, spec: &TravelSpec, m_cw_kg: f64, description: String) -> Recording {
        use recording as rec;
        let sample_rate_hz = self.sample_rate_hz;
        let [i_a, i_b, i_c] = self.phase_currents_a;
        let columns = vec![
            Column::new(rec::TIME_S, self.time_s),
            Column::new(rec::ACC_CAR, self.acc_car_mps2),
            Column::new(rec::ACC_CW, self.acc_cw_mps2),
            Column::new(rec::I_A, i_a),
            Column::new(rec::I_B, i_b),
            Column::new(rec::I_C, i_c),
            Column::new(rec::SPEED, self.speed_radps),
            Column::new(rec::ANGLE, self.angle_rad),
            Column::new(rec::REF_SPEED, self.ref_speed_mps),
            Column::new("motor_torque_nm", self.motor_torque_nm),
            Column::new("ripple_torque_nm", self.ripple_torque_nm),
            Column::new("shaft_speed_true_radps", self.shaft_speed_radps),
            Column::new("lw_m", self.lw_m),
            Column::new("drive_state", self.drive_state),
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
                sample_rate_hz,
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
