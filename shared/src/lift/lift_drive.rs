//! The lift drive's application layer: [`LiftDrive`], the start-up
//! sequence ([`crate::startup`]), the controller, the DCP port, the service
//! port ([`crate::service`]), the chain observer's mailbox and the faults
//! the hardware reports, one [`LiftDrive::period`] per PWM period with its
//! messages through [`PeriodIo`]. No hardware: the firmware (its control
//! interrupt), the PIL target and the host run this same code; only their
//! [`PeriodIo`] differs.
//!
//! - [`DcpPort`] takes the received bytes with their time stamps, delimits
//!   the messages ([`crate::dcp::FrameReceiver`]), runs the slave
//!   ([`crate::dcp::Slave`]) and returns the reply to send and the command
//!   for the controller.
//! - [`output_status`] is what the slave is told about the drive: the
//!   state, the outputs driven, any latched fault.
//! - [`apply`] applies a [`ControllerCommand`] to a [`Controller`].
//!
//! A distance travel (DCP4) becomes [`Controller::command_travel`]; a
//! speed-mode travel (DCP3, inspection, re-levelling) becomes
//! [`Controller::command_speed_travel`] at the selected speed, limited to
//! the shaft (the drive stops by itself at the last landing), then
//! [`Controller::command_speed`] at the deceleration point (crawl) and
//! [`Controller::command_stop`] at the floor (a jerk-limited ramp to rest,
//! then the brake). The safe stop is the supervisor's safe state (inverter
//! off, brake applied at once).

use crate::config::{Direction, DriveConfig};
use crate::controller::{
    CommandError, ControlOutput, Controller, DriveState, RetargetError, SensorFrame, SpeedCommandError,
    SpeedTravelCommand, Telemetry, TravelCommand,
};
use crate::dcp::command::{Mode, Speed};
use crate::dcp::frame::{FrameError, FrameReceiver, MasterFrame, CHARACTER_US, FRAME_LEN};
use crate::dcp::slave::{DriveStatus, Outcome, Refusal, Request, Slave, SlaveConfig, StopReason, Travel};
use crate::observer::{ChainModel, ObserverInput, ObserverOutput, ObserverTask};
use crate::param_store::DriveParameters;
use crate::ripple::harmonics::HarmonicTable;
use crate::ripple::Strategy;
use crate::service::{ParamsStatus, Response, ServiceState, FAULT_LOG, MAX_ANSWER, MAX_LINE};
use crate::startup::{Startup, StartupCommand, StartupEvent, StartupFault, StartupRefusal, StartupStep};
use crate::supervisor::Fault;

/// The speeds the drive offers for the DCP speed bits (order of
/// [`crate::dcp::Speed::ALL`]), m/s, as fractions of the rated car speed
/// `rated_mps` (m/s), chosen for the lab rig, whose lift controller has no
/// speed table of its own: V0 crawl 1/8, VN re-levelling 1/20, V1 1/4, VI
/// inspection 3/4, V2 1/2, V3 3/4, V4 the rated speed (the speed of the
/// distance travels); VF, V5, V6, V7 are not offered. (For a 0.4 m/s drive:
/// 0.05, 0.02, 0.1, 0.3, 0.2, 0.3 and 0.4 m/s.) DCP4 refuses V1 and V2
/// whatever the table says.
pub fn speed_table(rated_mps: f32) -> [Option<f32>; 11] {
    let mut speeds = [None; 11];
    for (speed, fraction) in [
        (Speed::V0, 0.125),
        (Speed::Vn, 0.05),
        (Speed::V1, 0.25),
        (Speed::Vi, 0.75),
        (Speed::V2, 0.5),
        (Speed::V3, 0.75),
        (Speed::V4, 1.0),
    ] {
        speeds[speed.index()] = Some(rated_mps * fraction);
    }
    speeds
}

/// Where the landings are in the drive's rope coordinate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LiftGeometry {
    /// Counterweight-side rope length `lw` with the car at the lowest landing, m
    /// (it grows as the car goes up).
    pub lw_lowest_landing_m: f32,
    /// Travel from the lowest to the highest landing, mm.
    pub shaft_travel_mm: u32,
}

/// What the controller is told to do.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ControllerCommand {
    /// Start a distance travel.
    Travel(TravelCommand),
    /// Start a speed travel.
    SpeedTravel(SpeedTravelCommand),
    /// The running distance travel's remaining distance, m, measured by the
    /// master `age_s` seconds before ([`Controller::command_remaining_distance`]).
    RemainingDistance {
        /// Remaining distance, m.
        remaining_m: f32,
        /// Time since the master started the message that carried it, s.
        age_s: f32,
    },
    /// Change the running speed travel's speed, m/s (the crawl at the deceleration point).
    Speed(f32),
    /// Stop the running speed travel (ramp to rest, then the brake).
    Stop,
    /// Stop now in the safe state (inverter off, brake applied).
    SafeStop(StopReason),
}

/// Why the controller did not take a command.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ApplyError {
    /// A travel refused.
    Travel(CommandError),
    /// A speed change or stop refused.
    Speed(SpeedCommandError),
    /// A changed remaining distance refused (the travel keeps its target).
    Remaining(RetargetError),
    /// A travel before the start-up sequence is done, or with a fault latched.
    NotReady,
}

fn direction(travel: Travel) -> Direction {
    match travel {
        Travel::Up => Direction::Up,
        Travel::Down => Direction::Down,
    }
}

/// The controller command of a slave request, with the car mass from the load weighing (kg).
pub fn controller_command(request: Request, geometry: &LiftGeometry, m_car_kg: f32) -> ControllerCommand {
    let lw_at = |position_mm: i32| geometry.lw_lowest_landing_m + position_mm as f32 / 1000.0;
    match request {
        Request::Distance { direction: d, distance_mm, start_position_mm } => {
            ControllerCommand::Travel(TravelCommand {
                direction: direction(d),
                distance_m: distance_mm as f32 / 1000.0,
                m_car_kg,
                lw_start_m: lw_at(start_position_mm),
            })
        }
        Request::Speed { direction: d, speed_mps, start_position_mm, .. } => {
            ControllerCommand::SpeedTravel(SpeedTravelCommand {
                direction: direction(d),
                speed_mps,
                m_car_kg,
                lw_start_m: lw_at(start_position_mm),
                // The last landing in the travel's direction.
                lw_limit_m: match d {
                    Travel::Up => lw_at(geometry.shaft_travel_mm as i32),
                    Travel::Down => geometry.lw_lowest_landing_m,
                },
            })
        }
        // The age is the port's to give (`DcpPort`); none known here.
        Request::Remaining { remaining_mm } => {
            ControllerCommand::RemainingDistance { remaining_m: remaining_mm as f32 / 1000.0, age_s: 0.0 }
        }
        Request::Crawl { speed_mps } => ControllerCommand::Speed(speed_mps),
        Request::Stop => ControllerCommand::Stop,
        Request::SafeStop(reason) => ControllerCommand::SafeStop(reason),
    }
}

/// Applies `command` to `controller`. A safe stop of an idle or tripped
/// drive changes nothing (it never clears a latched fault).
pub fn apply(command: ControllerCommand, controller: &mut Controller) -> Result<(), ApplyError> {
    match command {
        ControllerCommand::Travel(travel) => controller.command_travel(travel).map_err(ApplyError::Travel),
        ControllerCommand::SpeedTravel(travel) => controller.command_speed_travel(travel).map_err(ApplyError::Travel),
        ControllerCommand::RemainingDistance { remaining_m, age_s } => {
            controller.command_remaining_distance(remaining_m, age_s).map(|_| ()).map_err(ApplyError::Remaining)
        }
        ControllerCommand::Speed(speed_mps) => controller.command_speed(speed_mps).map_err(ApplyError::Speed),
        ControllerCommand::Stop => controller.command_stop().map_err(ApplyError::Speed),
        ControllerCommand::SafeStop(_) => {
            if !matches!(controller.state(), DriveState::Idle | DriveState::Tripped(_)) {
                controller.reset();
            }
            Ok(())
        }
    }
}

/// The harmonic table (N m) a drive keeps in its parameter record: after a
/// travel with `Strategy::Adaptive` or `Strategy::CarObserver`, what the
/// controller learned (the calibration of `Strategy::Table`); otherwise the
/// table of the compensation installed, or `installed` (N m) without one.
pub fn kept_table(controller: &Controller, installed: &HarmonicTable) -> HarmonicTable {
    match controller.compensation() {
        Some(c) => {
            let learned = c.learned_table();
            let learns = matches!(c.strategy(), Strategy::Adaptive | Strategy::CarObserver);
            let n = learned.len.min(learned.torque_nm.len());
            if learns && learned.torque_nm[..n].iter().any(|u| u.re != 0.0 || u.im != 0.0) {
                learned
            } else {
                c.table()
            }
        }
        None => *installed,
    }
}

/// Distance to stop from car speed `speed_mps` with the profile's
/// acceleration and jerk limits (the deceleration half of the S-curve),
/// mm, rounded up, at most `u16::MAX`.
pub fn braking_distance_mm(speed_mps: f32, config: &DriveConfig) -> u16 {
    let v = if speed_mps < 0.0 { -speed_mps } else { speed_mps };
    let (a, j) = (config.max_accel_mps2, config.max_jerk_mps3);
    if !(v > 0.0 && a > 0.0 && j > 0.0) {
        return 0;
    }
    // Peak deceleration: a, or sqrt(v j) when the speed is too low to reach it.
    let a_peak = if v * j < a * a { crate::profile::sqrt_newton(v * j) } else { a };
    let metres = 0.5 * v * (v / a_peak + a_peak / j);
    let mm = metres * 1000.0 + 1.0;
    if mm >= u16::MAX as f32 {
        u16::MAX
    } else {
        mm as u16
    }
}

/// The slave's view of the drive: `state` and shaft speed `speed_radps`
/// of the latest step; `ready_gate` is what the controller does not know
/// (current offsets calibrated, rotor aligned, no firmware fault).
pub fn drive_status(state: DriveState, speed_radps: f32, ready_gate: bool, config: &DriveConfig) -> DriveStatus {
    let speed_mps = speed_radps * config.sheave_radius_m;
    let speed_mps = if speed_mps < 0.0 { -speed_mps } else { speed_mps };
    DriveStatus {
        ready: ready_gate && state == DriveState::Idle,
        travelling: state.pwm_enabled() || state.brake_released(),
        fault: matches!(state, DriveState::Tripped(_)),
        brake_open: state.brake_released(),
        speed_mps,
        braking_distance_mm: braking_distance_mm(speed_mps, config),
    }
}

/// The status a drive reports from what it does rather than what its
/// controller intends: [`drive_status`] of the controller's `state` (none
/// before the controller runs: calibrating, waiting for the alignment,
/// aligning), with the fault bit set by any latched `fault` (the
/// controller's, the start-up sequence's, the firmware's own), ready only
/// without one, and "brake open" and "travelling" from the outputs driven
/// (`pwm_on`, `brake_released`). The firmware's DCP status.
pub fn output_status(
    state: Option<DriveState>,
    speed_radps: f32,
    ready_gate: bool,
    fault: bool,
    pwm_on: bool,
    brake_released: bool,
    config: &DriveConfig,
) -> DriveStatus {
    let mut status = match state {
        Some(state) => drive_status(state, speed_radps, ready_gate, config),
        None => DriveStatus::default(),
    };
    status.fault |= fault;
    status.ready &= !status.fault;
    status.brake_open = brake_released;
    status.travelling = pwm_on || brake_released;
    status
}

/// What one call of [`DcpPort`] produced.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PortEvent {
    /// The reply to send on the line, if a message was finished.
    pub reply: Option<[u8; FRAME_LEN]>,
    /// The command for the controller, if any.
    pub command: Option<ControllerCommand>,
    /// Why the finished message got the error answer, if it did.
    pub refused: Option<Refusal>,
}

/// The DCP port of the drive: receiver, slave and the mapping to the controller.
#[derive(Clone, Copy, Debug)]
pub struct DcpPort {
    receiver: FrameReceiver,
    /// When the first byte of the message being received came, us.
    message_start_us: u32,
    slave: Slave,
    geometry: LiftGeometry,
    m_car_kg: f32,
}

impl DcpPort {
    /// A port for a slave configured by `config`, the landings of
    /// `geometry` and a car mass from the load weighing of `m_car_kg` kg.
    pub fn new(config: SlaveConfig, geometry: LiftGeometry, m_car_kg: f32) -> Self {
        Self { receiver: FrameReceiver::default(), message_start_us: 0, slave: Slave::new(config), geometry, m_car_kg }
    }

    /// The slave (state, position).
    pub fn slave(&self) -> &Slave {
        &self.slave
    }

    /// The drive refused the remaining distance passed on
    /// ([`ApplyError::Remaining`]): the replies say so (S5 clear).
    pub fn refuse_remaining(&mut self) {
        self.slave.refuse_remaining();
    }

    /// The drive took the remaining distance passed on: the replies say so (S5 set).
    pub fn take_remaining(&mut self) {
        self.slave.take_remaining();
    }

    /// Sets the car mass of the load weighing, kg (used from the next travel).
    pub fn set_car_mass(&mut self, m_car_kg: f32) {
        self.m_car_kg = m_car_kg;
    }

    /// The car mass of the load weighing, kg.
    pub fn car_mass_kg(&self) -> f32 {
        self.m_car_kg
    }

    /// Restarts the slave speaking DCP variant `mode` (disabled, position
    /// unknown, no message half received).
    pub fn set_mode(&mut self, mode: Mode) {
        self.receiver = FrameReceiver::default();
        self.slave = Slave::new(SlaveConfig { mode, ..*self.slave.config() });
    }

    /// One byte received at `now_us`, with the drive's status now.
    pub fn byte(&mut self, byte: u8, now_us: u32, drive: &DriveStatus) -> PortEvent {
        let receiving = self.receiver.is_receiving();
        let finished = self.receiver.push(byte, now_us);
        let event = self.finish(finished, now_us, drive);
        if finished.is_some() || !receiving {
            self.message_start_us = now_us;
        }
        event
    }

    /// A UART error (framing, noise, overrun) at `now_us`.
    pub fn line_error(&mut self, now_us: u32, drive: &DriveStatus) -> PortEvent {
        let finished = self.receiver.line_error(now_us);
        self.finish(finished, now_us, drive)
    }

    /// Time passes: finishes a message after the idle gap, checks the timeout.
    pub fn poll(&mut self, now_us: u32, drive: &DriveStatus) -> PortEvent {
        let finished = self.receiver.poll(now_us);
        let mut event = self.finish(finished, now_us, drive);
        if event.command.is_none() {
            if let Some(request) = self.slave.poll(now_us, drive) {
                self.map(request, &mut event, now_us);
            }
        }
        event
    }

    fn finish(
        &mut self,
        finished: Option<Result<MasterFrame, FrameError>>,
        now_us: u32,
        drive: &DriveStatus,
    ) -> PortEvent {
        let mut event = PortEvent::default();
        if let Some(received) = finished {
            let Outcome { reply, request, refused } = self.slave.receive(received, now_us, drive);
            event.reply = Some(reply.encode());
            event.refused = refused;
            if let Some(request) = request {
                self.map(request, &mut event, now_us);
            }
        }
        event
    }

    fn map(&self, request: Request, event: &mut PortEvent, now_us: u32) {
        let mut command = controller_command(request, &self.geometry, self.m_car_kg);
        if let ControllerCommand::RemainingDistance { age_s, .. } = &mut command {
            // From the start of the message's first byte (one character
            // before it came) to now.
            let age_us = now_us.wrapping_sub(self.message_start_us).saturating_add(CHARACTER_US);
            *age_s = age_us.min(999_999) as f32 / 1.0e6;
        }
        event.command = Some(command);
    }
}

/// Most DCP bytes one [`LiftDrive::period`] takes.
pub const MAX_BYTES_PER_STEP: usize = 8;

/// Most reply bytes one [`LiftDrive::period`] gives: a reply per byte and one for the poll.
pub const MAX_REPLY_PER_STEP: usize = 6 * (MAX_BYTES_PER_STEP + 1);

/// Most service-port bytes one period takes (it stops after a line's end).
pub const MAX_SERVICE_BYTES_PER_STEP: usize = 8;

/// Longest service answer with its `\r\n`, bytes.
pub const MAX_SERVICE_REPLY: usize = MAX_ANSWER + 2;

/// Where the controller's electrical angle reference comes from after a reset.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AngleReference {
    /// An incremental encoder (the rig's; the firmware's drive): after the
    /// calibration the drive waits, gates off and brake applied, for the
    /// service port's `align` ([`crate::startup`]).
    Alignment,
    /// An absolute encoder: the electrical angle is the encoder count less
    /// the stored offset (`DriveParameters::encoder_offset_counts`, the
    /// count at electrical zero, installed by
    /// [`LiftDrive::install_parameters`]) from the controller's first step,
    /// after any reset and wherever the rotor then is (the simulated
    /// machine of the host and of the processor in the loop: offset 0):
    /// the controller runs after the calibration, idle (gates off, brake
    /// applied) until a travel is commanded; `align` is answered
    /// `error unsupported`. A stored offset outside one revolution is
    /// refused: the drive then waits for `align` as with
    /// [`AngleReference::Alignment`].
    Given,
}

/// A fault of the hardware around the drive, found by the firmware's own
/// checks and latched with [`LiftDrive::latch`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HardwareFault {
    /// A control step wrote its compares after the valley that follows its
    /// sample (`crate::pwm_timing`: they would take effect a period late).
    Overrun {
        /// CPU cycles from the step's start to its compare write.
        cycles: u32,
    },
    /// The next conversion sequence completed before the period's work finished.
    TriggerOverrun,
    /// The inverter's over-current comparator tripped the timer's break
    /// input (the hardware had already switched every gate off).
    InverterBreak,
    /// The phase-current conversions of a period were incomplete.
    AdcSequenceIncomplete,
}

/// A fault the application layer latches besides the controller's own trips.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DriveFault {
    /// The hardware's ([`HardwareFault`]).
    Hardware(HardwareFault),
    /// The start-up sequence's (calibration, alignment, a protection during it).
    Startup(StartupFault),
}

impl DriveFault {
    /// The supervisor fault it is reported as (the DCP fault bit, the
    /// service port's fault log, the reported state `Tripped`): an overrun
    /// is a missed deadline, the break an over-current, incomplete
    /// conversions and a refused calibration current-sensor faults, a
    /// failed alignment an encoder fault.
    pub fn as_fault(self) -> Fault {
        match self {
            DriveFault::Hardware(HardwareFault::Overrun { .. } | HardwareFault::TriggerOverrun) => {
                Fault::DeadlineMissed
            }
            DriveFault::Hardware(HardwareFault::InverterBreak) => Fault::OverCurrent,
            DriveFault::Hardware(HardwareFault::AdcSequenceIncomplete) => Fault::CurrentSensorImplausible,
            DriveFault::Startup(StartupFault::Calibration(_)) => Fault::CurrentSensorOffset,
            DriveFault::Startup(StartupFault::Alignment(_)) => Fault::EncoderImplausible,
            DriveFault::Startup(StartupFault::Protection(fault)) => fault,
        }
    }
}

/// The outputs of one period's control step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveOutput {
    /// Compares, gates and brake to drive, the reported state and the
    /// controller's telemetry. Before the controller runs (start-up) the
    /// start-up sequence's outputs, the state `Idle` (not ready) and zero
    /// telemetry; with a fault latched (any: the controller's, the start-up
    /// sequence's, the hardware's) gates off, compares 0, brake applied and
    /// the state `Tripped` with the fault. The brake is released only while
    /// the gates are on.
    pub control: ControlOutput,
    /// Whether the controller stepped (the start-up sequence is done).
    pub controller_ran: bool,
    /// The phase-current codes seen: offset-corrected once calibrated, ADC codes.
    pub codes: [u16; 3],
    /// What the start-up sequence reported this period.
    pub event: Option<StartupEvent>,
}

/// The answer to one service request line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ServiceReply {
    /// The answer, not yet written as text ([`ServiceReply::line`]).
    pub response: Response,
    /// The parameters to write to flash (a `save`): the caller writes them
    /// and, if that fails, sends `error flash-write\r\n` instead of this answer.
    pub save: Option<DriveParameters>,
}

/// An answer line with its `\r\n`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ServiceLine {
    bytes: [u8; MAX_SERVICE_REPLY],
    len: usize,
}

impl ServiceLine {
    /// The line's bytes.
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes[..self.len]
    }
}

impl ServiceReply {
    /// The answer line and its `\r\n` (formatting numbers: thousands of
    /// cycles, so the firmware does it in its service task, not in the
    /// control interrupt).
    pub fn line(&self) -> ServiceLine {
        let answer = self.response.write();
        let text = answer.as_bytes();
        let mut line = ServiceLine { bytes: [0; MAX_SERVICE_REPLY], len: text.len() + 2 };
        line.bytes[..text.len()].copy_from_slice(text);
        line.bytes[text.len()..text.len() + 2].copy_from_slice(b"\r\n");
        line
    }
}

/// The edges of the application layer for one PWM period: where its
/// messages come from and where its outputs go. The firmware's are its
/// peripherals and Embassy queues, the processor-in-the-loop target's its
/// emulated UARTs, the host's the bytes the chip reports it took.
pub trait PeriodIo {
    /// The next service-port byte received, if any.
    fn service_byte(&mut self) -> Option<u8>;
    /// The next DCP byte received, if any.
    fn dcp_byte(&mut self) -> Option<u8>;
    /// The chain observer's output handed back since the previous period
    /// by a task outside the drive (the firmware's), if any.
    fn observer_output(&mut self) -> Option<ObserverOutput> {
        None
    }
    /// Called just before the control step.
    fn control_started(&mut self) {}
    /// The period's outputs, as soon as the control step has them: drive
    /// them now (compares, gates, brake), before the messages are handled.
    fn drive(&mut self, output: &DriveOutput);
    /// A service-port answer to send.
    fn service_reply(&mut self, reply: &ServiceReply);
    /// A DCP reply to send.
    fn dcp_reply(&mut self, reply: &[u8; FRAME_LEN]);
    /// Latched faults were cleared by a reset: clear the hardware's latches
    /// too (the firmware: the timer's break flag).
    fn faults_cleared(&mut self) {}
    /// The chain observer's input of this speed-loop tick, for a task
    /// outside the drive (the firmware's); not called when the drive runs
    /// its own task ([`LiftDrive::take_observer_task`] not called).
    fn observer_input(&mut self, input: ObserverInput) {
        let _ = input;
    }
    /// Called just before the drive runs its own observer task, if it does.
    fn observer_started(&mut self) {}
}

/// What one [`LiftDrive::period`] did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PeriodOutput {
    /// The control step's outputs.
    pub drive: DriveOutput,
    /// A DCP command applied to the controller this period, and its result.
    pub applied: Option<(ControllerCommand, Result<(), ApplyError>)>,
    /// A DCP message got the error answer this period.
    pub refused: Option<Refusal>,
    /// Whether the drive's own chain observer task ran.
    pub observer_ran: bool,
}

/// The lift drive's application layer: the start-up sequence
/// ([`crate::startup`]), the controller, the DCP port, the service port,
/// the chain observer's mailbox and the faults the hardware reports, one
/// [`LiftDrive::period`] per PWM period. Its inputs and outputs are
/// messages through [`PeriodIo`]: received bytes, the sensor frame and the
/// observer's output in; replies, the outputs to drive and the observer's
/// input out. The firmware (its control interrupt), the
/// processor-in-the-loop target and the host run this same type.
#[derive(Clone, Copy, Debug)]
pub struct LiftDrive {
    controller: Controller,
    startup: Startup,
    hardware_fault: Option<HardwareFault>,
    port: DcpPort,
    config: DriveConfig,
    /// The reported state of the latest period.
    state: DriveState,
    speed_radps: f32,
    /// The outputs driven in the latest period.
    pwm_on: bool,
    brake_released: bool,
    /// What the service port reads and changes.
    service: ServiceState,
    /// The service request line being received.
    line: [u8; MAX_LINE + 1],
    line_len: usize,
    /// The chain model compensation strategies are installed on.
    chain: Option<ChainModel>,
    /// The rotor alignment's encoder offset, counts (kept in the record).
    encoder_offset_counts: u32,
    /// The chain observer's task (on the drive's chain model, once known),
    /// unless a task outside the drive runs it.
    observer_task: Option<ObserverTask>,
}

impl LiftDrive {
    /// The application layer of `controller` with `port` after a reset
    /// (settling, calibration, then the angle reference `angle`); `config`
    /// is the controller's. Its service port sets the strategy and the DCP
    /// variant, and cannot save (see [`LiftDrive::set_savable`]); no
    /// parameters are installed (see [`LiftDrive::install_parameters`]).
    pub fn new(controller: Controller, port: DcpPort, config: &DriveConfig, angle: AngleReference) -> Self {
        let service = ServiceState {
            strategy: Strategy::Off,
            table: HarmonicTable::default(),
            m_car_kg: port.car_mass_kg(),
            faults: [0; FAULT_LOG],
            fault_count: 0,
            state_code: DriveState::Idle.code(),
            speed_radps: 0.0,
            travelling: false,
            strategy_settable: true,
            dcp_mode: port.slave().config().mode,
            params: ParamsStatus::None,
            savable: false,
            save_requested: false,
        };
        let startup = Startup::new(config, *controller.supervisor_limits());
        let startup = match angle {
            AngleReference::Alignment => startup,
            AngleReference::Given => startup.with_angle_given(),
        };
        Self {
            controller,
            startup,
            hardware_fault: None,
            port,
            config: *config,
            state: DriveState::Idle,
            speed_radps: 0.0,
            pwm_on: false,
            brake_released: false,
            service,
            line: [0; MAX_LINE + 1],
            line_len: 0,
            chain: None,
            encoder_offset_counts: 0,
            observer_task: None,
        }
    }

    /// Installs the start-up parameters (the stored record's, or the
    /// defaults) on the drive model `chain`: the compensation strategy with
    /// its table, the car mass, the DCP variant, and with
    /// [`AngleReference::Given`] the encoder offset as the pole position
    /// (refused outside one revolution: the drive then waits for `align`);
    /// `status` is what became of the stored record (`get params`). Before
    /// the first period.
    pub fn install_parameters(&mut self, parameters: &DriveParameters, chain: &ChainModel, status: ParamsStatus) {
        self.chain = Some(*chain);
        self.observer_task = ObserverTask::for_model(chain).ok();
        self.controller.install_compensation(parameters.strategy, &parameters.table, chain);
        self.port.set_car_mass(parameters.m_car_kg);
        self.port.set_mode(parameters.dcp_mode);
        self.encoder_offset_counts = parameters.encoder_offset_counts;
        if self.startup.angle_given() && self.controller.set_encoder_origin(parameters.encoder_offset_counts).is_err() {
            self.startup.require_alignment();
        }
        self.service.strategy = parameters.strategy;
        self.service.table = parameters.table;
        self.service.m_car_kg = parameters.m_car_kg;
        self.service.dcp_mode = parameters.dcp_mode;
        self.service.params = status;
    }

    /// Whether the service port's `save` is carried out (the caller has a flash store).
    pub fn set_savable(&mut self, savable: bool) {
        self.service.savable = savable;
    }

    /// The parameters as they stand: the strategy, the table (after a
    /// travel with `Strategy::Adaptive` or `Strategy::CarObserver`, what it
    /// learned: the calibration of `Strategy::Table`; otherwise the table
    /// installed), the car mass, the encoder offset, the DCP variant.
    pub fn parameters(&self) -> DriveParameters {
        let table = kept_table(&self.controller, &self.service.table);
        DriveParameters {
            strategy: self.service.strategy,
            table,
            m_car_kg: self.port.car_mass_kg(),
            encoder_offset_counts: self.encoder_offset_counts,
            dcp_mode: self.port.slave().config().mode,
        }
    }

    /// The controller.
    pub fn controller(&self) -> &Controller {
        &self.controller
    }

    /// The controller, to install compensation directly (the
    /// processor-in-the-loop link's controller-level test messages).
    pub fn controller_mut(&mut self) -> &mut Controller {
        &mut self.controller
    }

    /// The start-up sequence.
    pub fn startup(&self) -> &Startup {
        &self.startup
    }

    /// The DCP port.
    pub fn port(&self) -> &DcpPort {
        &self.port
    }

    /// The chain observer's task, if the drive runs it itself.
    pub fn observer_task(&self) -> Option<&ObserverTask> {
        self.observer_task.as_ref()
    }

    /// Takes the chain observer's task out of the drive, for a task of its
    /// own (the firmware's interrupt executor): from then on each period
    /// hands the observer's input out ([`PeriodIo::observer_input`]) and
    /// takes its output in ([`PeriodIo::observer_output`]).
    pub fn take_observer_task(&mut self) -> Option<ObserverTask> {
        self.observer_task.take()
    }

    /// The state reported in the latest period (`Tripped` with any latched fault).
    pub fn state(&self) -> DriveState {
        self.state
    }

    /// The fault latched besides the controller's trips, if any.
    pub fn fault(&self) -> Option<DriveFault> {
        self.hardware_fault.map(DriveFault::Hardware).or(self.startup.fault().map(DriveFault::Startup))
    }

    /// Whether any fault is latched (the controller's included): the DCP fault bit.
    pub fn fault_latched(&self) -> bool {
        self.fault().is_some() || matches!(self.controller.state(), DriveState::Tripped(_))
    }

    /// Whether a travel may start: the start-up sequence done, no fault
    /// latched, the controller idle.
    pub fn is_ready(&self) -> bool {
        self.startup.is_running() && !self.fault_latched() && self.controller.state() == DriveState::Idle
    }

    /// Whether the drive is at rest in its safe state (gates off, brake
    /// applied, no travel, no alignment): the firmware may pause its
    /// periods to write the flash.
    pub fn is_quiescent(&self) -> bool {
        !self.pwm_on
            && !self.brake_released
            && matches!(self.controller.state(), DriveState::Idle | DriveState::Tripped(_))
            && (self.startup.is_running() || self.startup.is_waiting_for_alignment() || self.startup.fault().is_some())
    }

    /// After the caller held the periods back on purpose (a flash write):
    /// the next step's interval is not a missed deadline.
    pub fn resume_after_pause(&mut self) {
        self.controller.resume_after_pause();
    }

    /// Latches a hardware fault (the first one stays): from the next
    /// period gates off, brake applied, the fault reported, until a reset.
    /// The caller puts its outputs in the safe state at once.
    pub fn latch(&mut self, fault: HardwareFault) {
        if self.hardware_fault.is_none() {
            self.hardware_fault = Some(fault);
        }
        self.pwm_on = false;
        self.brake_released = false;
    }

    /// Clears every latched fault: the hardware's, the start-up sequence's
    /// (a failed calibration calibrates again) and the controller's trip
    /// (the service port's `reset`).
    ///
    /// # Errors
    /// [`StartupRefusal::NothingToReset`] when none is latched (it never
    /// stops a running travel).
    pub fn reset(&mut self) -> Result<(), StartupRefusal> {
        let tripped = matches!(self.controller.state(), DriveState::Tripped(_));
        let startup = self.startup.fault().is_some();
        if self.hardware_fault.is_none() && !tripped && !startup {
            return Err(StartupRefusal::NothingToReset);
        }
        self.hardware_fault = None;
        if startup {
            let _ = self.startup.command(StartupCommand::Reset);
        }
        if tripped {
            self.controller.reset();
        }
        self.state = self.controller.state();
        Ok(())
    }

    /// Starts the rotor alignment (the service port's `align`).
    ///
    /// # Errors
    /// [`StartupRefusal`]: not waiting for it, or a fault latched.
    pub fn align(&mut self) -> Result<(), StartupRefusal> {
        if self.hardware_fault.is_some() {
            return Err(StartupRefusal::Faulted);
        }
        self.startup.command(StartupCommand::Align)
    }

    /// Starts a distance travel directly (the processor-in-the-loop link's
    /// controller-level test messages; the lift controller's travels come
    /// over DCP).
    ///
    /// # Errors
    /// [`CommandError::NotIdle`] before the start-up sequence is done or
    /// with a fault latched; the controller's refusals.
    pub fn command_travel(&mut self, travel: TravelCommand) -> Result<(), CommandError> {
        if !self.startup.is_running() || self.fault().is_some() {
            return Err(CommandError::NotIdle);
        }
        self.controller.command_travel(travel)
    }

    /// One PWM period on `sensors` (phase-current codes with the board's
    /// sign, DC-bus code, encoder count, time stamp): the observer's output
    /// taken in, the control step (start-up sequence or controller) and its
    /// outputs driven at once ([`PeriodIo::drive`]), then the service
    /// port's bytes (up to the end of one line, at most
    /// [`MAX_SERVICE_BYTES_PER_STEP`]), the DCP bytes (at most
    /// [`MAX_BYTES_PER_STEP`]) time stamped with the period's time, the
    /// DCP idle gap and timeout, the commands applied (they act from the
    /// next period), and last the chain observer's task or its input handed out.
    pub fn period(&mut self, sensors: &SensorFrame, io: &mut impl PeriodIo) -> PeriodOutput {
        if let Some(output) = io.observer_output() {
            self.controller.deliver_observer_output(output);
        }
        io.control_started();
        let drive = self.control_step(sensors);
        io.drive(&drive);
        // What can wait until the outputs are driven (the learning of the
        // ripple compensation's tick).
        self.controller.finish_step();
        for _ in 0..MAX_SERVICE_BYTES_PER_STEP {
            let Some(byte) = io.service_byte() else { break };
            if let Some(reply) = self.service_byte(byte, io) {
                io.service_reply(&reply);
                break;
            }
        }
        let mut out = PeriodOutput { drive, applied: None, refused: None, observer_ran: false };
        for _ in 0..MAX_BYTES_PER_STEP {
            let Some(byte) = io.dcp_byte() else { break };
            let event = self.port.byte(byte, sensors.time_us, &self.status());
            self.handle(&event, io, &mut out);
        }
        let event = self.port.poll(sensors.time_us, &self.status());
        self.handle(&event, io, &mut out);
        match self.observer_task.as_mut() {
            Some(task) if self.controller.uses_observer() => {
                io.observer_started();
                out.observer_ran = task.serve(&mut self.controller);
            }
            Some(_) => {}
            None => {
                if let Some(input) = self.controller.take_observer_input() {
                    io.observer_input(input);
                }
            }
        }
        out
    }

    /// What the DCP slave is told: the reported state, the outputs driven,
    /// any latched fault.
    fn status(&self) -> DriveStatus {
        output_status(
            Some(self.state),
            self.speed_radps,
            self.startup.is_running() && self.fault().is_none(),
            self.fault_latched(),
            self.pwm_on,
            self.brake_released,
            &self.config,
        )
    }

    /// The start-up sequence or the controller, with the latched faults.
    fn control_step(&mut self, sensors: &SensorFrame) -> DriveOutput {
        let step = self.startup.step(sensors.phase_current_codes, sensors.dc_bus_code, sensors.encoder_count);
        let (mut control, controller_ran, codes, event) = match step {
            StartupStep::Drive(out) => (
                ControlOutput {
                    pwm_compare: out.compare,
                    pwm_enabled: out.pwm_on,
                    brake_released: out.brake_released,
                    state: self.controller.state(),
                    telemetry: Telemetry::default(),
                },
                false,
                out.codes,
                out.event,
            ),
            StartupStep::Run(codes) => {
                let frame = SensorFrame { phase_current_codes: codes, ..*sensors };
                (self.controller.step_to_output(&frame), true, codes, None)
            }
        };
        control.brake_released &= control.pwm_enabled;
        if let Some(fault) = self.fault() {
            control.pwm_enabled = false;
            control.pwm_compare = [0; 3];
            control.brake_released = false;
            control.state = DriveState::Tripped(fault.as_fault());
        }
        if let DriveState::Tripped(fault) = control.state {
            if self.state != control.state {
                self.service.log_fault(fault.code());
            }
        }
        self.state = control.state;
        self.speed_radps = control.telemetry.speed_radps;
        self.pwm_on = control.pwm_enabled;
        self.brake_released = control.brake_released;
        DriveOutput { control, controller_ran, codes, event }
    }

    /// One byte of the service port; the reply when it ends a request line.
    /// A `set` takes effect at once (refused during a travel): the strategy
    /// is installed over the table in use, the car mass is the next
    /// travel's, a new DCP variant restarts the slave; `reset` and `align`
    /// go to the drive ([`LiftDrive::reset`], [`LiftDrive::align`]).
    fn service_byte(&mut self, byte: u8, io: &mut impl PeriodIo) -> Option<ServiceReply> {
        if byte != b'\n' {
            // A line too long is answered `error line` once it ends.
            if self.line_len < self.line.len() {
                self.line[self.line_len] = byte;
                self.line_len += 1;
            }
            return None;
        }
        let parameters = self.parameters();
        let s = &mut self.service;
        s.state_code = self.state.code();
        s.speed_radps = self.speed_radps;
        s.travelling = self.pwm_on || self.brake_released || self.state.pwm_enabled() || self.state.brake_released();
        s.table = parameters.table;
        s.m_car_kg = parameters.m_car_kg;
        s.dcp_mode = parameters.dcp_mode;
        s.strategy_settable = self.chain.is_some();
        let before = *s;
        let request = crate::service::parse(&self.line[..self.line_len]).ok();
        let mut response = crate::service::respond(&self.line[..self.line_len], s);
        self.line_len = 0;
        let after = *s;
        if response.is_ok() {
            match request {
                Some(crate::service::Request::Reset) => {
                    if self.reset().is_ok() {
                        io.faults_cleared();
                    } else {
                        response = Response::Error("nothing-to-reset");
                    }
                }
                Some(crate::service::Request::Align) => {
                    if self.startup.angle_given() {
                        response = Response::Error("unsupported");
                    } else if self.align().is_err() {
                        response = Response::Error("busy");
                    }
                }
                _ => {}
            }
        }
        if after.strategy != before.strategy {
            if let Some(chain) = self.chain {
                self.controller.install_compensation(after.strategy, &after.table, &chain);
            }
        }
        if after.m_car_kg != before.m_car_kg {
            self.port.set_car_mass(after.m_car_kg);
        }
        if after.dcp_mode != before.dcp_mode {
            self.port.set_mode(after.dcp_mode);
        }
        let save = if after.save_requested {
            self.service.save_requested = false;
            Some(self.parameters())
        } else {
            None
        };
        Some(ServiceReply { response, save })
    }

    fn handle(&mut self, event: &PortEvent, io: &mut impl PeriodIo, out: &mut PeriodOutput) {
        if let Some(reply) = event.reply {
            io.dcp_reply(&reply);
        }
        if event.refused.is_some() {
            out.refused = event.refused;
        }
        if let Some(command) = event.command {
            let starts = matches!(command, ControllerCommand::Travel(_) | ControllerCommand::SpeedTravel(_));
            let result = if starts && !self.is_ready() {
                Err(ApplyError::NotReady)
            } else {
                apply(command, &mut self.controller)
            };
            match (command, result) {
                (_, Err(ApplyError::Remaining(_))) => self.port.refuse_remaining(),
                (ControllerCommand::RemainingDistance { .. }, Ok(())) => self.port.take_remaining(),
                _ => {}
            }
            if result.is_ok() && self.fault().is_none() {
                // The next status already shows a started travel or a stop.
                self.state = self.controller.state();
            }
            out.applied = Some((command, result));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::reference_rig;
    use crate::dcp::channel::position_message;
    use crate::dcp::command::{command_byte, Kind, Mode, Speed};
    use crate::dcp::frame::{CHARACTER_US, FRAME_GAP_US};

    fn port() -> DcpPort {
        let mut speeds = [None; 11];
        speeds[Speed::V4.index()] = Some(0.4);
        speeds[Speed::Vi.index()] = Some(0.3);
        DcpPort::new(
            SlaveConfig::new(Mode::Dcp4, speeds, 6600),
            LiftGeometry { lw_lowest_landing_m: 1.0, shaft_travel_mm: 6600 },
            70.5,
        )
    }

    /// Sends one message byte by byte and lets the gap pass; the event of the gap.
    fn send(port: &mut DcpPort, t: &mut u32, frame: MasterFrame, drive: &DriveStatus) -> PortEvent {
        for b in frame.encode() {
            assert_eq!(port.byte(b, *t, drive).reply, None);
            *t += CHARACTER_US;
        }
        *t += FRAME_GAP_US;
        port.poll(*t, drive)
    }

    #[test]
    fn the_output_status_reports_every_fault_and_the_brake_as_driven() {
        let rig = reference_rig();
        // Idle controller, a firmware fault latched: fault bit, not ready.
        let s = output_status(Some(DriveState::Idle), 0.0, true, true, false, false, &rig);
        assert!(s.fault && !s.ready && !s.brake_open && !s.travelling);
        // Before the controller runs (start-up), a start-up fault still shows.
        let s = output_status(None, 0.0, false, true, false, false, &rig);
        assert!(s.fault && !s.ready);
        // The controller in Travel but the outputs cut (a break): brake applied, not travelling.
        let s = output_status(Some(DriveState::Travel), 1.0, true, true, false, false, &rig);
        assert!(s.fault && !s.brake_open && !s.travelling);
        // The alignment drives the outputs with the brake open.
        let s = output_status(None, 0.0, false, false, true, true, &rig);
        assert!(!s.fault && s.brake_open && s.travelling && !s.ready);
        // Nothing latched, idle, ready.
        let s = output_status(Some(DriveState::Idle), 0.0, true, false, false, false, &rig);
        assert!(s.ready && !s.fault);
    }

    #[test]
    fn a_remaining_distance_becomes_a_travel_command_from_the_position_of_the_lowest_landing() {
        let rig = reference_rig();
        let mut p = port();
        let idle = drive_status(DriveState::Idle, 0.0, true, &rig);
        let mut t = 0;
        let mut channel = position_message(1500).to_vec();
        for _ in 0..9 {
            let mut comm = [0u8; 2];
            for slot in comm.iter_mut() {
                if !channel.is_empty() {
                    *slot = channel.remove(0);
                }
            }
            let frame = MasterFrame { command: command_byte(Kind::Stop, false), data: [0, 0], comm };
            assert!(send(&mut p, &mut t, frame, &idle).reply.is_some());
        }
        assert_eq!(p.slave().position_mm(), Some(1500));
        let frame =
            MasterFrame { command: command_byte(Kind::Decelerate, false), data: 2000u16.to_be_bytes(), comm: [0; 2] };
        let event = send(&mut p, &mut t, frame, &idle);
        let Some(ControllerCommand::Travel(travel)) = event.command else { panic!("{event:?}") };
        assert_eq!(travel.direction, Direction::Up);
        assert_eq!(travel.distance_m, 2.0);
        assert_eq!(travel.lw_start_m, 2.5);
        assert_eq!(travel.m_car_kg, 70.5);
        let mut c = Controller::new(&rig);
        assert_eq!(apply(ControllerCommand::Travel(travel), &mut c), Ok(()));
        assert_eq!(c.state(), DriveState::PreTorque);
        assert_eq!(apply(ControllerCommand::SafeStop(StopReason::Timeout), &mut c), Ok(()));
        assert_eq!(c.state(), DriveState::Idle);
    }

    /// Gives the port position `position_mm` over the channel of stop messages.
    /// The reference rig's drive, idle, its port given the position 1000 mm
    /// by the master; with the time (ms) the messages took.
    fn idle_at_1000_mm() -> (DriveConfig, DcpPort, Controller, u32) {
        let rig = reference_rig();
        let mut p = port();
        let c = Controller::new(&rig);
        let mut t = 0u32;
        let idle = drive_status(DriveState::Idle, 0.0, true, &rig);
        give_position(&mut p, &mut t, 1000, &idle);
        (rig, p, c, t)
    }

    fn give_position(p: &mut DcpPort, t: &mut u32, position_mm: i32, drive: &DriveStatus) {
        let mut channel = position_message(position_mm).to_vec();
        for _ in 0..9 {
            let mut comm = [0u8; 2];
            for slot in comm.iter_mut() {
                if !channel.is_empty() {
                    *slot = channel.remove(0);
                }
            }
            let frame = MasterFrame { command: command_byte(Kind::Stop, false), data: [0, 0], comm };
            send(p, t, frame, drive);
        }
        assert_eq!(p.slave().position_mm(), Some(position_mm));
    }

    #[test]
    fn a_speed_mode_travel_becomes_a_speed_travel_to_the_shaft_end_then_crawl_and_stop() {
        let rig = reference_rig();
        let mut p = port();
        let idle = drive_status(DriveState::Idle, 0.0, true, &rig);
        let moving = drive_status(DriveState::Travel, -0.3 / rig.sheave_radius_m, true, &rig);
        let mut t = 0;
        // Without the position: answered, not accepted, no travel.
        let speed =
            |down| MasterFrame { command: command_byte(Kind::SpeedMode, down), data: Speed::Vi.data(), comm: [0; 2] };
        let travel = |down| MasterFrame { command: command_byte(Kind::Travel, down), data: [0, 0], comm: [0; 2] };
        send(&mut p, &mut t, speed(true), &idle);
        let event = send(&mut p, &mut t, travel(true), &idle);
        assert_eq!(event.command, None);
        assert_eq!(event.reply.unwrap()[0] & crate::dcp::slave::S5_ACCEPTED, 0);
        let idle_message = MasterFrame { command: command_byte(Kind::Idle, false), data: [0, 0], comm: [0; 2] };
        send(&mut p, &mut t, idle_message, &idle);
        give_position(&mut p, &mut t, 1200, &idle);
        send(&mut p, &mut t, speed(true), &idle);
        let event = send(&mut p, &mut t, travel(true), &idle);
        let Some(ControllerCommand::SpeedTravel(command)) = event.command else { panic!("{event:?}") };
        assert_eq!(command.direction, Direction::Down);
        assert_eq!(command.speed_mps, 0.3);
        assert_eq!(command.lw_start_m, 2.2);
        assert_eq!(command.lw_limit_m, 1.0, "down to the lowest landing");
        let mut c = Controller::new(&rig);
        assert_eq!(apply(ControllerCommand::SpeedTravel(command), &mut c), Ok(()));
        assert_eq!(c.state(), DriveState::PreTorque);
        // The deceleration point (no crawl speed in this port: the stop).
        let decelerate = MasterFrame { command: command_byte(Kind::Decelerate, true), data: [0, 0], comm: [0; 2] };
        let event = send(&mut p, &mut t, decelerate, &moving);
        assert_eq!(event.command, Some(ControllerCommand::Stop));
        assert_eq!(apply(ControllerCommand::Stop, &mut c), Ok(()));
        assert_eq!(
            apply(ControllerCommand::Speed(0.05), &mut c),
            Err(ApplyError::Speed(SpeedCommandError::NoSpeedTravel))
        );
        // Up: the limit is the highest landing.
        let request = Request::Speed { direction: Travel::Up, speed: Speed::V4, speed_mps: 0.4, start_position_mm: 0 };
        let ControllerCommand::SpeedTravel(up) = controller_command(request, &p.geometry, 70.5) else { panic!() };
        assert_eq!((up.lw_start_m, up.lw_limit_m), (1.0, 7.6));
        assert_eq!(
            controller_command(Request::Crawl { speed_mps: 0.05 }, &p.geometry, 70.5),
            ControllerCommand::Speed(0.05)
        );
    }

    #[test]
    fn the_braking_distance_is_the_deceleration_half_of_the_s_curve() {
        let rig = reference_rig();
        // 0.4 m/s, 0.5 m/s^2, 1 m/s^3: a_peak = sqrt(0.4) = 0.632 > 0.5, so 0.5:
        // 0.5 * 0.4 * (0.8 + 0.5) = 0.26 m.
        assert_eq!(braking_distance_mm(0.4, &rig), 261);
        assert_eq!(braking_distance_mm(-0.4, &rig), 261);
        assert_eq!(braking_distance_mm(0.0, &rig), 0);
        let slow = braking_distance_mm(0.1, &rig) as f32;
        // a_peak = sqrt(0.1): 0.5 * 0.1 * 2 * sqrt(0.1) = 0.0316 m.
        assert!((slow - 32.6).abs() < 1.0, "{slow}");
        assert_eq!(braking_distance_mm(f32::NAN, &rig), 0);
        assert_eq!(braking_distance_mm(1e9, &rig), u16::MAX);
    }

    #[test]
    fn the_status_follows_the_controller_state() {
        let rig = reference_rig();
        let travel = drive_status(DriveState::Travel, -6.0, true, &rig);
        assert!(travel.travelling && travel.brake_open && !travel.ready && !travel.fault);
        assert!((travel.speed_mps - 0.39).abs() < 1e-6);
        let tripped = drive_status(DriveState::Tripped(crate::supervisor::Fault::OverCurrent), 0.0, true, &rig);
        assert!(tripped.fault && !tripped.ready && !tripped.travelling);
        assert!(!drive_status(DriveState::Idle, 0.0, false, &rig).ready, "not calibrated or aligned");
    }

    /// A DCP4 travel up 2000 mm from 1000 mm under a lift controller that
    /// measures the car on its own shaft encoder and sends the remaining
    /// distance every 15 ms; at 3 s the ropes slip by `slip_mm` (the car
    /// `slip_mm` ahead of the sheave's count). The car follows the speed
    /// reference exactly (as `controller`'s ideal car). Returns where the
    /// car stops in the master's coordinate (mm), whether any reply had S5
    /// clear during the travel, and the speed references of the speed-loop ticks (m/s).
    fn slipping_travel(slip_mm: f64) -> (f64, bool, std::vec::Vec<f32>) {
        extern crate std;
        let (rig, mut p, mut c, mut t) = idle_at_1000_mm();
        let counts_per_m = rig.encoder_counts_per_rev as f64 / (rig.sheave_radius_m as f64 * core::f64::consts::TAU);
        let (mut sheave_m, mut slip_m, mut speed_radps) = (0.0f64, 0.0f64, 0.0f32);
        let mut refused = false;
        let mut refs = std::vec::Vec::new();
        let mut started = false;
        let dt = 1.0 / rig.current_loop_hz as f64;
        for k in 0..(20.0 * rig.current_loop_hz) as u32 {
            let now_us = (k as f64 * dt * 1e6) as u32 + 1_000_000;
            if k as f64 * dt >= 3.0 {
                slip_m = slip_mm / 1000.0;
            }
            let car_mm = 1000.0 + (sheave_m + slip_m) * 1000.0;
            let status = drive_status(c.state(), speed_radps, true, &rig);
            if k % 240 == 0 && now_us > t {
                t = now_us;
                // The message's bytes and gap (2.48 ms) pass at once here,
                // the car standing still: the master measured it that long
                // before the drive takes it.
                let age_m = speed_radps as f64 * rig.sheave_radius_m as f64 * 2.48e-3;
                let remaining = (3000.0 - (car_mm - age_m * 1000.0)).round().max(0.0) as u16;
                let frame = if !started || status.travelling {
                    MasterFrame {
                        command: command_byte(Kind::Decelerate, false),
                        data: remaining.to_be_bytes(),
                        comm: [0; 2],
                    }
                } else {
                    MasterFrame { command: command_byte(Kind::Stop, false), data: [0, 0], comm: [0; 2] }
                };
                let event = send(&mut p, &mut t, frame, &status);
                if let Some(command) = event.command {
                    match (command, apply(command, &mut c)) {
                        (_, Err(ApplyError::Remaining(_))) => p.refuse_remaining(),
                        (ControllerCommand::RemainingDistance { .. }, Ok(())) => p.take_remaining(),
                        _ => {}
                    }
                    started = true;
                }
                if status.travelling && event.reply.unwrap()[0] & crate::dcp::slave::S5_ACCEPTED == 0 {
                    refused = true;
                }
            }
            let f = SensorFrame {
                phase_current_codes: [2048; 3],
                encoder_count: (sheave_m * counts_per_m).round() as i64 as u32,
                dc_bus_code: 2048,
                time_us: k * 62 + k / 2,
            };
            let out = c.step(&f);
            speed_radps = out.telemetry.speed_ref_radps;
            if out.brake_released {
                sheave_m += out.telemetry.speed_ref_radps as f64 * rig.sheave_radius_m as f64 * dt;
            }
            if k % rig.speed_loop_divider() == 0 && out.state == DriveState::Travel {
                refs.push(out.telemetry.ref_speed_mps);
            }
            if started && out.state == DriveState::Idle && k as f64 * dt > 5.0 {
                break;
            }
        }
        assert_eq!(c.state(), DriveState::Idle, "the travel ended");
        (1000.0 + (sheave_m + slip_m) * 1000.0, refused, refs)
    }

    /// Acceleration and jerk of speed references 0.5 ms apart, over 4 ms.
    fn assert_within_limits(refs: &[f32]) {
        let rig = reference_rig();
        let n = 8;
        let dt = n as f32 / rig.speed_loop_hz;
        let a: std::vec::Vec<f32> = (n..refs.len()).map(|i| (refs[i] - refs[i - n]) / dt).collect();
        for i in n..a.len() {
            assert!(a[i].abs() <= rig.max_accel_mps2 * 1.001, "acceleration {} at tick {i}", a[i]);
            let jerk = (a[i] - a[i - n]) / dt;
            assert!(jerk.abs() <= rig.max_jerk_mps3 * 1.02, "jerk {jerk} at tick {i}");
        }
        assert!(
            refs.iter().all(|&v| (-1e-4..=rig.rated_speed_mps * 1.0001).contains(&v)),
            "no reversal, at most rated"
        );
    }

    extern crate std;

    #[test]
    fn a_dcp4_travel_follows_a_remaining_distance_shortened_or_lengthened_by_rope_slip() {
        // Without slip, and with the car 40 mm ahead of (shorter) or 60 mm
        // behind (longer) the sheave's count from 3 s on, at rated speed.
        for slip_mm in [0.0, 40.0, -60.0] {
            let (stop_mm, refused, refs) = slipping_travel(slip_mm);
            assert!((stop_mm - 3000.0).abs() <= 3.0, "slip {slip_mm} mm: the car stops at {stop_mm} mm, not 3000");
            assert!(!refused, "slip {slip_mm} mm: a remaining distance refused");
            assert_within_limits(&refs);
        }
    }

    #[test]
    fn a_remaining_distance_shorter_than_the_stop_is_refused_and_the_travel_keeps_its_target() {
        // 400 mm ahead at rated speed (the stop takes 261 mm): the master's
        // remaining distance drops below the braking distance.
        let (stop_mm, refused, refs) = slipping_travel(1600.0);
        assert!(refused, "S5 cleared while the distance is refused");
        assert_within_limits(&refs);
        // The car went on to the first target (the sheave's 2000 mm) plus the slip.
        assert!((stop_mm - 4600.0).abs() <= 3.0, "{stop_mm}");
    }

    #[test]
    fn no_dcp_message_clears_a_latched_fault() {
        // DCP has no fault-reset command: the master clears B0 and waits
        // for S3 to clear; only the service port's `reset` clears the fault.
        let (rig, mut p, mut c, mut t) = idle_at_1000_mm();
        let mut bad = SensorFrame { phase_current_codes: [2048; 3], encoder_count: 0, dc_bus_code: 2048, time_us: 0 };
        c.step(&bad);
        bad.phase_current_codes = [2048 + 1300, 2048 - 650, 2048 - 650];
        bad.time_us = 62;
        let tripped = c.step(&bad).state;
        assert!(matches!(tripped, DriveState::Tripped(_)), "{tripped:?}");
        // Every command byte, with data of each kind, twice (edges of every bit).
        for round in 0..2 {
            for command in 0..=255u8 {
                for data in [[0, 0], [0x01, 0xF4], Speed::V4.data(), Speed::V0.data()] {
                    let status = drive_status(c.state(), 0.0, true, &rig);
                    let event = send(&mut p, &mut t, MasterFrame { command, data, comm: [0; 2] }, &status);
                    if let Some(command) = event.command {
                        let _ = apply(command, &mut c);
                    }
                    let reply = event.reply.unwrap()[0];
                    assert_eq!(c.state(), tripped, "round {round}, command {command:#010b}");
                    assert_ne!(reply & crate::dcp::slave::S3_FAULT, 0, "command {command:#010b}");
                    assert_eq!(reply & (crate::dcp::slave::S0_READY | crate::dcp::slave::S6_BRAKE_OPEN), 0);
                }
            }
        }
        let out = c.step(&SensorFrame { time_us: 124, ..bad });
        assert!(!out.pwm_enabled && !out.brake_released, "still in the safe state");
    }

    /// The firmware's edges in a test: no bytes in, the replies kept, and
    /// the deadline check of the firmware's control interrupt on a model of
    /// its timer (centre-aligned, ARR 5312 at 170 MHz: the sample at the
    /// peak, the compares loading at the valley 5312 cycles later): the
    /// period's work starts `latency` cycles after the peak and writes the
    /// compares `step_cycles` after its start.
    struct TimedEdges {
        latency: u32,
        step_cycles: u32,
        late: Option<u32>,
        replies: std::vec::Vec<[u8; FRAME_LEN]>,
        service_in: std::vec::Vec<u8>,
        answers: std::vec::Vec<ServiceLine>,
        cleared: bool,
    }

    impl PeriodIo for TimedEdges {
        fn service_byte(&mut self) -> Option<u8> {
            (!self.service_in.is_empty()).then(|| self.service_in.remove(0))
        }
        fn dcp_byte(&mut self) -> Option<u8> {
            None
        }
        fn drive(&mut self, _output: &DriveOutput) {
            let period = 2 * 5312;
            let written = self.latency + self.step_cycles;
            let counting_down = written % period < period / 2;
            if !crate::pwm_timing::compares_in_time(counting_down, self.step_cycles, 5312) {
                self.late = Some(self.step_cycles);
            }
        }
        fn service_reply(&mut self, reply: &ServiceReply) {
            self.answers.push(reply.line());
        }
        fn dcp_reply(&mut self, reply: &[u8; FRAME_LEN]) {
            self.replies.push(*reply);
        }
        fn faults_cleared(&mut self) {
            self.cleared = true;
        }
    }

    #[test]
    fn a_late_control_step_is_caught_and_holds_the_drive_safe_with_the_fault_bit_until_the_reset() {
        let rig = reference_rig();
        let mut drive = LiftDrive::new(Controller::new(&rig), port(), &rig, AngleReference::Given);
        let mut edges = TimedEdges {
            latency: 255,
            step_cycles: 1500,
            late: None,
            replies: std::vec::Vec::new(),
            service_in: std::vec::Vec::new(),
            answers: std::vec::Vec::new(),
            cleared: false,
        };
        let mut k = 0u32;
        let mut period = |drive: &mut LiftDrive, edges: &mut TimedEdges| {
            let sensors = SensorFrame {
                phase_current_codes: [2048; 3],
                encoder_count: 0,
                dc_bus_code: 2048,
                time_us: k * 62 + k / 2,
            };
            k += 1;
            let out = drive.period(&sensors, edges);
            // The firmware's control interrupt after the period.
            if let Some(cycles) = edges.late.take() {
                drive.latch(HardwareFault::Overrun { cycles });
            }
            out.drive.control
        };
        // The start-up, then a travel: the gates come on.
        while !drive.startup().is_running() {
            let out = period(&mut drive, &mut edges);
            assert!(!out.pwm_enabled && !out.brake_released);
        }
        let travel = TravelCommand { direction: Direction::Up, distance_m: 1.0, m_car_kg: 70.5, lw_start_m: 2.0 };
        assert_eq!(drive.command_travel(travel), Ok(()));
        let mut on = false;
        for _ in 0..100 {
            on |= period(&mut drive, &mut edges).pwm_enabled;
        }
        assert!(on, "the pre-torque switches the bridge");
        // Late by a hair (the compares written 5 313 cycles after the sample,
        // the valley at 5 312): caught; the worst step measured on the
        // emulated chip (5 376 instructions) would be too.
        for step_cycles in [5312 - 255 + 1, 5376] {
            let mut d = drive;
            let mut e = TimedEdges {
                latency: 255,
                step_cycles,
                late: None,
                replies: std::vec::Vec::new(),
                service_in: std::vec::Vec::new(),
                answers: std::vec::Vec::new(),
                cleared: false,
            };
            period(&mut d, &mut e);
            assert_eq!(d.fault(), Some(DriveFault::Hardware(HardwareFault::Overrun { cycles: step_cycles })));
        }
        // One cycle earlier it is in time.
        edges.step_cycles = 5312 - 255 - 1;
        period(&mut drive, &mut edges);
        assert_eq!(drive.fault(), None);
        // The late step: from the next period gates off, brake applied,
        // the fault reported, DCP S3 set and S0 clear, for as long as no
        // reset comes, whatever the controller wants.
        edges.step_cycles = 6000;
        period(&mut drive, &mut edges);
        edges.step_cycles = 1500;
        for _ in 0..2000 {
            let out = period(&mut drive, &mut edges);
            assert!(!out.pwm_enabled && !out.brake_released && out.pwm_compare == [0; 3], "{out:?}");
            assert_eq!(out.state, DriveState::Tripped(Fault::DeadlineMissed));
        }
        let status = drive.status();
        assert!(status.fault && !status.ready && !status.brake_open && !status.travelling);
        assert!(drive.command_travel(travel).is_err(), "no travel with the fault latched");
        // The service port's reset clears it (and the hardware's latch).
        edges.service_in.extend_from_slice(b"reset\n");
        period(&mut drive, &mut edges);
        assert_eq!(edges.answers.last().map(|l| l.as_bytes().to_vec()), Some(b"ok reset\r\n".to_vec()));
        assert!(edges.cleared);
        let out = period(&mut drive, &mut edges);
        assert_eq!((out.state, out.pwm_enabled, out.brake_released), (DriveState::Idle, false, false));
        assert!(drive.status().ready && !drive.status().fault);
        assert_eq!(drive.command_travel(travel), Ok(()));
        // A reset with nothing latched is refused.
        edges.service_in.extend_from_slice(b"reset\n");
        period(&mut drive, &mut edges);
        assert_eq!(edges.answers.last().map(|l| l.as_bytes().to_vec()), Some(b"error nothing-to-reset\r\n".to_vec()));
    }

    /// The pole position of an absolute encoder from the stored offset:
    /// installed within one revolution, the controller runs after the
    /// calibration and takes its angle from the offset (`align`
    /// unsupported); an offset of a revolution or more is refused and the
    /// drive waits, safe and not ready, for the commanded alignment.
    #[test]
    fn a_stored_encoder_offset_is_the_pole_position_only_within_one_revolution() {
        let rig = reference_rig();
        let parameters = |offset: u32| DriveParameters {
            strategy: Strategy::Off,
            table: HarmonicTable::default(),
            m_car_kg: 70.5,
            encoder_offset_counts: offset,
            dcp_mode: Mode::Dcp4,
        };
        let calibrated = |offset: u32| {
            let mut drive = LiftDrive::new(Controller::new(&rig), port(), &rig, AngleReference::Given);
            drive.install_parameters(&parameters(offset), &crate::config::reference_chain(), ParamsStatus::Stored);
            let mut io = TimedEdges {
                latency: 0,
                step_cycles: 0,
                late: None,
                replies: std::vec::Vec::new(),
                service_in: std::vec::Vec::new(),
                answers: std::vec::Vec::new(),
                cleared: false,
            };
            for k in 0..(crate::startup::SETTLE_STEPS + crate::startup::CALIBRATION_SAMPLES) as u32 + 10 {
                let sensors = SensorFrame {
                    phase_current_codes: [2048; 3],
                    encoder_count: 5_000,
                    dc_bus_code: 2048,
                    time_us: k * 62 + k / 2,
                };
                let out = drive.period(&sensors, &mut io).drive.control;
                assert!(!out.pwm_enabled && !out.brake_released && out.pwm_compare == [0; 3]);
            }
            drive
        };
        let within = calibrated(rig.encoder_counts_per_rev - 1);
        assert!(within.startup().is_running() && within.is_ready());
        assert_eq!(within.parameters().encoder_offset_counts, rig.encoder_counts_per_rev - 1);
        let mut refused = calibrated(rig.encoder_counts_per_rev);
        assert!(refused.startup().is_waiting_for_alignment() && !refused.is_ready());
        assert_eq!(refused.align(), Ok(()), "the alignment is commanded instead");
    }
}
