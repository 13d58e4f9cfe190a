//! The lower-priority task: every [`POLL_MS`] it feeds the watchdog (if the
//! control interrupt is alive), drains the interrupt's event and telemetry
//! queues (`edges.rs`) into the defmt log.
//!
//! Log levels: events (calibration, faults, commands) and state changes at
//! `info`/`error`, a one-line summary every [`SUMMARY_EVERY`] records
//! (1 s) at `info`, and every record (1 kHz) at `debug`, compiled out unless
//! `DEFMT_LOG=debug`.

use defmt::{debug, error, info, warn};
use drive_core::alignment::AlignmentError;
use drive_core::controller::{CommandError, RetargetError, SpeedCommandError};
use drive_core::current_offset::OffsetError;
use drive_core::dcp::slave::Refusal;
use drive_core::dcp::FrameError;
use drive_core::lift_drive::{ApplyError, ControllerCommand, DriveFault, HardwareFault};
use drive_core::startup::{StartupEvent, StartupFault};
use drive_core::supervisor::Fault;
use drive_core::DriveState;
use embassy_time::{Duration, Instant, Ticker};

use crate::edges::{Event, Record, EVENTS, RECORDS};
use crate::watchdog::Watchdog;
use crate::{control, pwm, DRIVE_CONFIG};

/// Polling period of the task, ms: 10 records per poll at 1 kHz, a tenth of
/// the watchdog timeout.
pub const POLL_MS: u64 = 10;

/// Records between two summary lines (1000 records = 1 s).
pub const SUMMARY_EVERY: u32 = 1000;

/// The task.
#[embassy_executor::task]
pub async fn run(mut watchdog: Watchdog) {
    let mut last_state: Option<(DriveState, bool)> = None;
    let mut records: u32 = 0;
    let mut ticker = Ticker::every(Duration::from_millis(POLL_MS));
    let mut last_poll = Instant::now();
    let mut stalled = false;
    loop {
        ticker.next().await;
        let now = Instant::now();
        let elapsed_us = now.duration_since(last_poll).as_micros().min(u32::MAX as u64) as u32;
        last_poll = now;
        let fed = watchdog.feed_if_alive(control::steps(), elapsed_us);
        if !fed && !stalled {
            error!("control interrupt stalled: the watchdog is no longer fed and will reset the chip");
        }
        stalled = !fed;

        while let Ok(event) = EVENTS.try_receive() {
            log_event(&event);
        }
        while let Ok(record) = RECORDS.try_receive() {
            records = records.wrapping_add(1);
            let state = Some((record.state, record.controller_ran));
            if state != last_state {
                info!("drive state: {=str} -> {=str}", state_name(last_state), state_name(state));
                last_state = state;
            }
            log_record(&record, records % SUMMARY_EVERY == 0);
        }
    }
}

fn log_record(r: &Record, summary: bool) {
    let t = &r.telemetry;
    debug!(
        "step {=u32} t {=u32} us state {=str} pwm {=bool} brake_released {=bool} codes {} bus {=u16} \
         enc {=u32} cmp {} cycles {=u32} id {=f32} iq {=f32} iq_ref {=f32} speed {=f32} speed_ref {=f32} \
         torque_ref {=f32}",
        r.step,
        r.time_us,
        state_name(Some((r.state, r.controller_ran))),
        r.pwm_on,
        r.brake_released,
        r.phase_codes,
        r.dc_bus_code,
        r.encoder_count,
        r.compare,
        r.cycles,
        t.id_a,
        t.iq_a,
        t.iq_ref_a,
        t.speed_radps,
        t.speed_ref_radps,
        t.torque_ref_nm
    );
    if summary {
        info!(
            "t {=u32} ms: {=str}, pwm {=bool}, brake released {=bool}, iq {=f32} A (ref {=f32}), speed {=f32} rad/s \
             (ref {=f32}), bus code {=u16}, longest step {=u32} cycles (deadline {=u32}), dropped {=u32}; chain observer: \
             {=u32} runs, longest {=u32} cycles, {=u32} missed deadlines",
            r.time_us / 1000,
            state_name(Some((r.state, r.controller_ran))),
            r.pwm_on,
            r.brake_released,
            t.iq_a,
            t.iq_ref_a,
            t.speed_radps,
            t.speed_ref_radps,
            r.dc_bus_code,
            control::max_cycles(),
            pwm::HALF_PERIOD_CYCLES,
            control::dropped(),
            crate::observer::runs(),
            crate::observer::max_cycles(),
            control::observer_missed_deadlines()
        );
    }
}

fn log_event(event: &Event) {
    match *event {
        Event::Startup(StartupEvent::Calibrated(offsets)) => {
            let [u, v, w] = offsets.zero_current_codes;
            info!(
                "current offsets calibrated with the inverter off: zero-current codes U {=u16} V {=u16} W {=u16} \
                 (mid-scale {=u16}); safe state (gates off, brake applied) until the align command",
                u,
                v,
                w,
                DRIVE_CONFIG.adc_zero_code()
            );
        }
        Event::Startup(StartupEvent::Aligned(count)) => info!(
            "rotor aligned: encoder count {=u32} at electrical angle zero (checks passed); brake applied, drive idle",
            count
        ),
        Event::Startup(StartupEvent::Fault(fault)) => log_fault(DriveFault::Startup(fault)),
        Event::Fault(fault) => log_fault(fault),
        Event::Command(command, Ok(())) => info!("command applied: {=str}", command_name(&command)),
        Event::Command(command, Err(e)) => {
            warn!("command refused: {=str}: {=str}", command_name(&command), refusal_name(e))
        }
        Event::Refused(refusal) => {
            warn!("DCP message answered with the error bit: {=str}", message_refusal_name(refusal))
        }
        Event::Dropped => warn!("a DCP reply or service answer was dropped: its queue was full"),
    }
}

fn log_fault(fault: DriveFault) {
    const SAFE: &str = "PWM off, brake applied, latched";
    match fault {
        DriveFault::Hardware(HardwareFault::Overrun { cycles }) => error!(
            "control step wrote its compares after the valley ({=u32} cycles after its start; the valley is {=u32} \
             cycles after the sample): {=str}",
            cycles,
            pwm::HALF_PERIOD_CYCLES,
            SAFE
        ),
        DriveFault::Hardware(HardwareFault::TriggerOverrun) => {
            error!("next ADC sequence completed before the control period's work finished: {=str}", SAFE)
        }
        DriveFault::Hardware(HardwareFault::InverterBreak) => {
            error!("inverter over-current (TIM1 break input): gates cut by hardware; {=str}", SAFE)
        }
        DriveFault::Hardware(HardwareFault::AdcSequenceIncomplete) => {
            error!("ADC1 sequence incomplete at ADC2's end of sequence: {=str}", SAFE)
        }
        DriveFault::Startup(StartupFault::Alignment(error)) => {
            let (what, counts) = match error {
                AlignmentError::CurrentNotReached => ("the injected current was not reached", 0),
                AlignmentError::NotSettled(c) => ("the rotor did not settle (counts of motion)", c as i32),
                AlignmentError::NoMotion(c) => ("the rotor did not turn (brake applied or no torque; counts)", c),
                AlignmentError::WrongDirection(c) => {
                    ("the rotor turned backwards (phase order or encoder direction; counts)", c)
                }
                AlignmentError::WrongDistance(c) => {
                    ("the rotor turned by the wrong angle (pole pairs or encoder counts; counts)", c)
                }
                AlignmentError::NotRepeatable(c) => {
                    ("the rotor did not return to its aligned position (counts off)", c)
                }
                AlignmentError::Runaway(c) => ("the load pulled the rotor off the current vector (counts)", c),
            };
            error!("rotor alignment failed: {=str} {=i32}: {=str} until a reset command", what, counts, SAFE)
        }
        DriveFault::Startup(StartupFault::Protection(fault)) => {
            error!("protection tripped during the alignment: {=str}: {=str}", fault.name(), SAFE)
        }
        DriveFault::Startup(StartupFault::Calibration(error)) => match error {
            OffsetError::NotEnoughSamples { samples, required } => error!(
                "current-offset calibration incomplete ({=u16} of {=u16} samples): {=str} until a reset command",
                samples, required, SAFE
            ),
            OffsetError::Noisy { phase, peak_to_peak_codes } => error!(
                "current-offset calibration failed: phase {=str} spans {=u16} codes peak to peak (limit {=u16}): \
                 {=str} until a reset command",
                phase_name(phase),
                peak_to_peak_codes,
                drive_core::current_offset::OffsetLimits::for_adc_bits(DRIVE_CONFIG.adc_bits).max_peak_to_peak_codes,
                SAFE
            ),
            OffsetError::OffsetOutOfRange { phase, zero_current_code } => error!(
                "current-offset calibration failed: phase {=str} reads {=u16} at zero current, more than {=u16} \
                 codes from mid-scale {=u16}: {=str} until a reset command",
                phase_name(phase),
                zero_current_code,
                drive_core::current_offset::OffsetLimits::for_adc_bits(DRIVE_CONFIG.adc_bits).max_offset_codes,
                DRIVE_CONFIG.adc_zero_code(),
                SAFE
            ),
        },
    }
}

fn message_refusal_name(refusal: Refusal) -> &'static str {
    use drive_core::dcp::command::CommandError;
    match refusal {
        Refusal::Frame(FrameError::Checksum) => "checksum",
        Refusal::Frame(FrameError::Truncated(_)) => "message too short",
        Refusal::Frame(FrameError::TooLong) => "message too long",
        Refusal::Frame(FrameError::Line) => "UART error in the message",
        Refusal::Command(CommandError::Unknown) => "unknown command",
        Refusal::Command(CommandError::BadSpeed) => "bad speed word",
        Refusal::Command(CommandError::DistanceOutOfRange) => "remaining distance out of range",
    }
}

fn phase_name(phase: u8) -> &'static str {
    match phase {
        0 => "U",
        1 => "V",
        2 => "W",
        _ => "?",
    }
}

fn command_name(command: &ControllerCommand) -> &'static str {
    match command {
        ControllerCommand::Travel(_) => "distance travel",
        ControllerCommand::SpeedTravel(_) => "speed travel",
        ControllerCommand::RemainingDistance { .. } => "remaining distance",
        ControllerCommand::Speed(_) => "speed change",
        ControllerCommand::Stop => "stop",
        ControllerCommand::SafeStop(_) => "safe stop",
    }
}

fn refusal_name(refusal: ApplyError) -> &'static str {
    match refusal {
        ApplyError::Travel(CommandError::NotIdle) => "drive not idle",
        ApplyError::Travel(CommandError::Profile(_)) => "no travel profile for that distance",
        ApplyError::Travel(CommandError::OutOfRange) => {
            "travel outside the rig, speed out of range or car mass not positive"
        }
        ApplyError::Speed(SpeedCommandError::NoSpeedTravel) => "no speed travel running",
        ApplyError::Speed(SpeedCommandError::OutOfRange) => "speed out of range",
        ApplyError::Remaining(RetargetError::NoDistanceTravel) => "no distance travel running",
        ApplyError::Remaining(RetargetError::CannotStop) => "remaining distance shorter than the car can stop in",
        ApplyError::Remaining(RetargetError::OutOfRange) => "remaining distance out of range",
        ApplyError::NotReady => "drive not calibrated or not aligned, or a fault is latched",
    }
}

/// Name of a drive state for the log: the reported state and whether the
/// controller ran ("starting" while the start-up sequence drives the
/// outputs, before the controller runs).
fn state_name(state: Option<(DriveState, bool)>) -> &'static str {
    let state = match state {
        None => return "none",
        Some((DriveState::Idle, false)) => return "starting (not ready)",
        Some((state, _)) => Some(state),
    };
    match state {
        None => "none",
        Some(DriveState::Idle) => "Idle",
        Some(DriveState::PreTorque) => "PreTorque",
        Some(DriveState::BrakeLift) => "BrakeLift",
        Some(DriveState::Travel) => "Travel",
        Some(DriveState::Hold) => "Hold",
        Some(DriveState::BrakeSet) => "BrakeSet",
        Some(DriveState::Tripped(fault)) => match fault {
            Fault::OverCurrent => "Tripped(OverCurrent)",
            Fault::OverSpeed => "Tripped(OverSpeed)",
            Fault::DcBusUnderVoltage => "Tripped(DcBusUnderVoltage)",
            Fault::DcBusOverVoltage => "Tripped(DcBusOverVoltage)",
            Fault::CurrentSensorImplausible => "Tripped(CurrentSensorImplausible)",
            Fault::EncoderImplausible => "Tripped(EncoderImplausible)",
            Fault::DeadlineMissed => "Tripped(DeadlineMissed)",
            Fault::CurrentSensorOffset => "Tripped(CurrentSensorOffset)",
            Fault::CurrentTracking => "Tripped(CurrentTracking)",
            Fault::BackEmfMismatch => "Tripped(BackEmfMismatch)",
            Fault::SpeedFollowing => "Tripped(SpeedFollowing)",
        },
    }
}
