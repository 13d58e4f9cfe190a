//! The queues at the edges of the drive's application layer
//! (`drive_core::lift_drive::LiftDrive`, run by the control interrupt):
//! Embassy channels between the interrupt and the thread-mode tasks, each
//! touched for one push or pop inside a critical section (a few hundred
//! cycles at most, the longest a task can delay the interrupt).
//!
//! In: the DCP bytes ([`DCP_RX`], the DCP task), the service-port bytes
//! ([`SERVICE_RX`], the service task); out: the DCP replies ([`DCP_TX`]),
//! the service answers ([`SERVICE_TX`]), what the telemetry task logs
//! ([`EVENTS`], [`RECORDS`]). The chain observer's input and output are
//! the observer module's signals. This module depends on no other of the
//! firmware: every task and the interrupt name it, it names none of them.

use drive_core::controller::Telemetry;
use drive_core::dcp::frame::FRAME_LEN;
use drive_core::dcp::slave::Refusal;
use drive_core::lift_drive::{ApplyError, ControllerCommand, DriveFault, ServiceReply};
use drive_core::startup::StartupEvent;
use drive_core::DriveState;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;

/// DCP bytes received, not yet taken by the interrupt: 64 bytes, 17 ms of
/// the line at 38 400 baud (the interrupt takes up to 8 a period).
pub static DCP_RX: Channel<CriticalSectionRawMutex, u8, 64> = Channel::new();

/// DCP replies to send (one per master message, 6 bytes each).
pub static DCP_TX: Channel<CriticalSectionRawMutex, [u8; FRAME_LEN], 4> = Channel::new();

/// Service-port bytes received, not yet taken by the interrupt (a request
/// line is at most 65 bytes with its `\n`).
pub static SERVICE_RX: Channel<CriticalSectionRawMutex, u8, 128> = Channel::new();

/// Service answers to format and send (the service task formats them: the
/// numbers take thousands of cycles, too long for the interrupt).
pub static SERVICE_TX: Channel<CriticalSectionRawMutex, ServiceReply, 2> = Channel::new();

/// Events for the telemetry task to log.
pub static EVENTS: Channel<CriticalSectionRawMutex, Event, 8> = Channel::new();

/// Telemetry records the queue holds: 32 ms at 1 kHz, against the
/// telemetry task's 10 ms polling period.
pub const RECORD_CAPACITY: usize = 32;

/// Decimated telemetry records for the telemetry task.
pub static RECORDS: Channel<CriticalSectionRawMutex, Record, RECORD_CAPACITY> = Channel::new();

/// Something the telemetry task logs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Event {
    /// What the start-up sequence reported (calibrated, aligned, a fault).
    Startup(StartupEvent),
    /// A hardware fault was latched (gates off, brake applied).
    Fault(DriveFault),
    /// A DCP command the controller refused, or one applied (the
    /// remaining distances taken, repeated every message, are not logged).
    Command(ControllerCommand, Result<(), ApplyError>),
    /// A DCP message answered with the error bit.
    Refused(Refusal),
    /// A reply or answer was dropped: its queue was full.
    Dropped,
}

/// One decimated snapshot of a period, for the telemetry task.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Record {
    /// Period number since start (wraps), PWM periods.
    pub step: u32,
    /// Time stamp of the period's sample, microseconds (wraps).
    pub time_us: u32,
    /// The state the drive reports (`Tripped` with any latched fault).
    pub state: DriveState,
    /// Whether the controller ran (the start-up sequence done).
    pub controller_ran: bool,
    /// Inverter outputs on (MOE) after the period.
    pub pwm_on: bool,
    /// Brake released after the period.
    pub brake_released: bool,
    /// Phase-current codes U, V, W: offset-corrected once calibrated, raw
    /// before, ADC codes.
    pub phase_codes: [u16; 3],
    /// DC-bus code, ADC code.
    pub dc_bus_code: u16,
    /// Extended encoder count, counts.
    pub encoder_count: u32,
    /// Compares written, timer ticks.
    pub compare: [u16; 3],
    /// Duration of the period's work, CPU cycles.
    pub cycles: u32,
    /// The controller's telemetry (all zero before it runs).
    pub telemetry: Telemetry,
}
