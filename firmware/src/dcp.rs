//! The lift controller's link: the DCP slave (`drive_core::lift_drive::DcpPort`)
//! on UART5, RS-485 half duplex, 38 400 baud 8N1.
//!
//! Pins (the board description, `board.rs`): PC12 UART5_TX (AF5) to the
//! transceiver's DI, PD2 UART5_RX (AF5, pull-up: the transceiver's RO floats
//! while it drives) from RO, PB4 UART5_DE (AF8) to DE and /RE tied together
//! (not PB14, USART3's DE, reported on the IHM08M1's break net). The UART drives DE
//! itself around every transmission (assertion and de-assertion times of one
//! bit), so the line is released as soon as the reply's stop bit is out; the
//! receiver is disabled while the drive talks, so its own reply is never
//! read back.
//!
//! The task reads bytes as they arrive (one interrupt per byte) and time
//! stamps them with the 1 MHz Embassy clock; between bytes it wakes every
//! [`POLL_US`] to finish a message after the idle gap and to run the
//! slave's timeout watchdog. A finished message is answered at once; the
//! command it carries goes to the control interrupt through its command
//! queue and is applied at the next PWM period. A safe stop is never
//! dropped: if the queue is full it is retried at the next wake-up.
//!
//! Logic (framing, protocol, watchdog, the mapping to the controller) is all
//! in `drive_core`; this module only moves bytes and time stamps.

use defmt::{error, info, warn};
use drive_core::dcp::slave::Refusal;
use drive_core::dcp::FrameError;
use drive_core::lift_drive::{output_status, ControllerCommand, DcpPort, PortEvent};
use embassy_stm32::usart::{self, BufferedUart};
use embassy_time::{with_timeout, Duration, Instant};
use embedded_io_async::{Read, Write};

use crate::control::{self, Command};
use crate::DRIVE_CONFIG;

/// Longest wait for a byte before the task finishes a pending message and
/// checks the timeout, us: a quarter of the DCP idle gap.
pub const POLL_US: u64 = drive_core::dcp::frame::FRAME_GAP_US as u64 / 4;

/// The USART settings of DCP: 38 400 baud, 8 data bits, no parity, one stop
/// bit; DE asserted one bit time before the start bit and released one bit
/// time after the stop bit (16 sixteenths).
pub fn uart_config() -> usart::Config {
    let mut config = usart::Config::default();
    config.baudrate = drive_core::dcp::frame::BAUD;
    config.data_bits = usart::DataBits::DataBits8;
    config.parity = usart::Parity::ParityNone;
    config.stop_bits = usart::StopBits::STOP1;
    config.rx_pull = embassy_stm32::gpio::Pull::Up;
    config.eager_reads = Some(1);
    config.de_assertion_time = 16;
    config.de_deassertion_time = 16;
    config
}

fn now_us() -> u32 {
    // Wraps every 71.6 minutes, as the slave's clock may.
    Instant::now().as_micros() as u32
}

/// The drive's status for the lift controller, from the control interrupt's
/// snapshot (`drive_core::lift_drive::output_status`): the fault bit set by
/// any latched fault (the firmware's, the start-up sequence's, the
/// controller's), "brake open" and "travelling" from the outputs actually
/// driven (brake output released, inverter on), not from the controller's
/// state.
fn status() -> drive_core::dcp::DriveStatus {
    let s = control::snapshot();
    output_status(s.state, s.speed_radps, s.ready_gate, s.fault, s.pwm_on, s.brake_released, &DRIVE_CONFIG)
}

/// The DCP task: owns the USART and the port until the chip stops.
#[embassy_executor::task]
pub async fn run(mut uart: BufferedUart<'static>, mut port: DcpPort) {
    info!(
        "DCP slave on UART5 (RS-485, {=u32} baud 8N1): waiting for the lift controller",
        drive_core::dcp::frame::BAUD
    );
    let mut pending: Option<Command> = None;
    let mut buf = [0u8; 8];
    loop {
        // The load weighing of the service port, from the next travel on.
        if let Some(m_car_kg) = crate::service::car_mass_kg() {
            port.set_car_mass(m_car_kg);
        }
        // The DCP variant of the service port: the slave restarts in it.
        if let Some(mode) = crate::service::dcp_mode() {
            if mode != port.slave().config().mode {
                info!("DCP slave restarted in the other variant");
                port.set_mode(mode);
            }
        }
        let event = match with_timeout(Duration::from_micros(POLL_US), uart.read(&mut buf)).await {
            Ok(Ok(n)) => {
                for &byte in &buf[..n] {
                    let event = port.byte(byte, now_us(), &status());
                    handle(&mut uart, &event, &mut pending).await;
                }
                PortEvent::default()
            }
            Ok(Err(e)) => {
                warn!("DCP line error: {}", e);
                port.line_error(now_us(), &status())
            }
            Err(_) => PortEvent::default(),
        };
        handle(&mut uart, &event, &mut pending).await;
        let event = port.poll(now_us(), &status());
        handle(&mut uart, &event, &mut pending).await;
        match control::take_remaining_outcome() {
            Some(true) => port.take_remaining(),
            Some(false) => port.refuse_remaining(),
            None => {}
        }
        if let Some(command) = pending.take() {
            if let Err(command) = control::submit(command) {
                pending = Some(command);
            }
        }
    }
}

async fn handle(uart: &mut BufferedUart<'static>, event: &PortEvent, pending: &mut Option<Command>) {
    if let Some(reply) = event.reply {
        if let Err(e) = uart.write_all(&reply).await {
            error!("DCP reply not sent: {}", e);
        }
        if let Err(e) = uart.flush().await {
            error!("DCP reply not flushed: {}", e);
        }
    }
    if let Some(refusal) = event.refused {
        warn!("DCP message answered with the error bit: {=str}", refusal_name(refusal));
    }
    if let Some(command) = event.command {
        if let ControllerCommand::SafeStop(reason) = command {
            warn!("DCP safe stop: {=str}", reason_name(reason));
        }
        let command = Command::Drive(command);
        // A newer command replaces one still waiting for room in the queue.
        if let Err(command) = control::submit(command) {
            *pending = Some(command);
        }
    }
}

fn refusal_name(refusal: Refusal) -> &'static str {
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

fn reason_name(reason: drive_core::dcp::StopReason) -> &'static str {
    use drive_core::dcp::StopReason;
    match reason {
        StopReason::Timeout => "no valid message within the timeout",
        StopReason::Interrupted => "drive enable cleared during the travel",
        StopReason::Inconsistent => "command contradicting the running travel",
    }
}
