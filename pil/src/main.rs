//! Processor-in-the-loop target: the drive's application layer
//! (`drive_core::lift_drive::LiftDrive`, the type the firmware's control
//! interrupt runs), compiled for the Cortex-M4F exactly as for the
//! STM32G474, on QEMU's `mps2-an386`.
//!
//! The host (`host-sim pil`) sends one [`Message::Sense`] frame per PWM
//! period over UART0; the target runs one `LiftDrive::period` on it and
//! answers with a [`Message::Output`] frame that carries the outputs, a
//! digest of the telemetry and the cost of the control step up to its
//! outputs (the start-up sequence or the controller: what the firmware
//! must finish before the PWM valley) in SysTick ticks (processor clock,
//! 25 MHz on this machine; under `qemu -icount shift=N` each instruction
//! advances time by 2^N ns, so the host converts ticks to instructions).
//! The drive starts as after any reset: settling and the current-offset
//! calibration with gates off and the brake applied, then, its angle
//! reference given (`AngleReference::Given`: the simulated rotor starts at
//! electrical zero), idle until a travel is commanded. Travel and reset
//! commands (the controller-level test messages) are acknowledged with
//! [`Message::Ack`]. The frame codec is `drive_core::frame`, the same code
//! the host uses.
//!
//! The lift controller's DCP line is UART1 and the service port
//! (`drive_core::service`, one ASCII line per request) UART2: the period
//! takes, after the control step, the service bytes that have arrived up
//! to the end of one line (at most
//! `drive_core::lift_drive::MAX_SERVICE_BYTES_PER_STEP`) and writes the
//! answer to a finished line on UART2, then the DCP bytes (at most
//! `drive_core::lift_drive::MAX_BYTES_PER_STEP`) with the frame's time
//! stamp as the DCP clock. One record per period goes out on UART1:
//! `n_in, the DCP bytes taken, n_out, the reply bytes, n_service, the
//! service bytes taken, observer, its cost, the rest` (`observer` 1 when
//! the chain observer's task ran after the period's work, then its cost in
//! SysTick ticks as four little-endian bytes, 0 otherwise; `the rest` the
//! ticks of the period's work after the outputs and before the observer's
//! task, four little-endian bytes). The host's lift controller reads its
//! replies from the records, and the host shadow replays the same bytes at
//! the same periods, so the chip and the host run the same application
//! layer bit for bit whatever the emulator's timing of the bytes.
//!
//! Parameters: the drive's parameter record (`drive_core::param_store`)
//! under key 0 of a `sequential-storage` map, as the firmware keeps it,
//! over an emulated flash (`flash.rs`) that QEMU keeps in the file
//! `pil-flash.bin` of its working directory. At start-up a record that
//! passes every check is installed, otherwise the defaults (no
//! compensation over the rig's offline table, the heaviest car, DCP4) and
//! the service port's `get params` says why; the service port's `save`
//! writes the record. Starting QEMU again in the same directory is a power
//! cycle.
//!
//! The chain observer: with a strategy that uses it, the controller
//! publishes the observer's input at each speed-loop tick and the
//! observer's task (`drive_core::observer::ObserverTask`, kept by the
//! drive) runs at the end of the period, before the next frame: a task below the control interrupt that finishes within the
//! PWM period, on the schedule of `drive_core::observer::task` (the
//! estimate of tick `k`'s input used at tick `k + 1`), the firmware's.
//!
//! Logging: defmt over semihosting (feature `semihosting`, the default) or
//! RTT (feature `rtt`); the controller code is the same either way.
#![no_std]
#![no_main]
#![deny(unsafe_code)]

mod flash;
mod uart;

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;
use cortex_m_rt::entry;
use drive_core::dcp::{Mode, SlaveConfig};
use drive_core::frame::{command_result_code, encode, Decoder, Message, StepReport, ACK_FRAME_REJECTED, MAX_FRAME};
use drive_core::lift_drive::{
    speed_table, AngleReference, DcpPort, DriveOutput, LiftDrive, PeriodIo, ServiceReply, MAX_BYTES_PER_STEP,
    MAX_REPLY_PER_STEP, MAX_SERVICE_BYTES_PER_STEP,
};
use drive_core::param_store::{DriveParameters, MAX_RECORD};
use drive_core::ripple::harmonics::HarmonicTable;
use drive_core::ripple::Strategy;
use drive_core::service::{record_error_word, ParamsStatus};
use drive_core::Controller;
use sequential_storage::cache::{Cache, Uncached};
use sequential_storage::map::{MapConfig, MapStorage};

#[cfg(feature = "rtt")]
use defmt_rtt as _;
#[cfg(feature = "semihosting")]
use defmt_semihosting as _;

include!(concat!(env!("OUT_DIR"), "/drive_config.rs"));
include!(concat!(env!("OUT_DIR"), "/chain_model.rs"));
include!(concat!(env!("OUT_DIR"), "/lift.rs"));
include!(concat!(env!("OUT_DIR"), "/ripple.rs"));

/// The map key of the parameter record (the firmware's).
const KEY: u8 = 0;

type Store = MapStorage<u8, flash::Flash, Cache<Uncached, Uncached, Uncached, u8>>;

/// The offline compensation table: the rig's ripple (`RIPPLE`), negated (the firmware's).
fn offline_table() -> HarmonicTable {
    let mut table = HarmonicTable::default();
    for (order, amplitude_nm, cos_phase, sin_phase) in RIPPLE {
        table.push_cosine(order, amplitude_nm, cos_phase, sin_phase);
    }
    table.negated()
}

/// The stored parameters if a record passes every check, and what became of it.
fn load(store: &mut Store) -> (Option<DriveParameters>, ParamsStatus) {
    let mut buffer = [0u8; MAX_RECORD + 16];
    match embassy_futures::block_on(store.fetch_item::<&[u8]>(&mut buffer, &KEY)) {
        Ok(None) => (None, ParamsStatus::None),
        Ok(Some(record)) => match DriveParameters::decode(record) {
            Ok(parameters) => (Some(parameters), ParamsStatus::Stored),
            Err(e) => (None, ParamsStatus::Refused(e)),
        },
        Err(e) => {
            defmt::warn!("parameters: the store cannot be read: {}", e);
            (None, ParamsStatus::Unreadable)
        }
    }
}

/// Writes `parameters` as the stored record.
fn save(store: &mut Store, parameters: &DriveParameters) -> bool {
    let mut record = [0u8; MAX_RECORD];
    let n = parameters.encode(&mut record);
    let mut buffer = [0u8; MAX_RECORD + 16];
    match embassy_futures::block_on(store.store_item(&mut buffer, &KEY, &&record[..n])) {
        Ok(()) => true,
        Err(e) => {
            defmt::warn!("parameters: not written: {}", e);
            false
        }
    }
}

/// The DCP slave of the target: distance mode, the speeds of
/// `drive_core::lift_drive::speed_table` (the firmware's configuration).
fn dcp_port() -> DcpPort {
    DcpPort::new(
        SlaveConfig::new(Mode::Dcp4, speed_table(DRIVE_CONFIG.rated_speed_mps), LIFT_GEOMETRY.shaft_travel_mm),
        LIFT_GEOMETRY,
        DEFAULT_CAR_MASS_KG,
    )
}

/// The parameters without a stored record: no compensation (the rig's
/// offline table ready for `set strategy`), the heaviest car, DCP4.
fn default_parameters() -> DriveParameters {
    DriveParameters {
        strategy: Strategy::Off,
        table: offline_table(),
        m_car_kg: DEFAULT_CAR_MASS_KG,
        encoder_offset_counts: 0,
        dcp_mode: Mode::Dcp4,
    }
}

/// SysTick reload: the full 24-bit range, ticks.
const SYSTICK_RELOAD: u32 = 0x00FF_FFFF;

#[entry]
fn main() -> ! {
    let Some(mut core) = cortex_m::Peripherals::take() else {
        // Only reachable if something took the peripherals before main.
        panic!("core peripherals already taken");
    };
    core.SYST.set_clock_source(SystClkSource::Core);
    core.SYST.set_reload(SYSTICK_RELOAD);
    core.SYST.clear_current();
    core.SYST.enable_counter();

    // The two SysTick reads around a step cost something themselves: measure
    // that once with nothing between them and take it off every step.
    let first = SYST::get_current();
    let second = SYST::get_current();
    let timing_overhead_ticks = first.wrapping_sub(second) & SYSTICK_RELOAD;

    let mut uart = uart::Uart0::enable();
    let mut dcp_uart = uart::Polled::uart1();
    let mut service_uart = uart::Polled::uart2();
    let mut drive = LiftDrive::new(Controller::new(&DRIVE_CONFIG), dcp_port(), &DRIVE_CONFIG, AngleReference::Given);
    let mut store: Store =
        MapStorage::new(flash::Flash::load(), const { MapConfig::new(0..flash::SIZE as u32) }, Cache::new_uncached());
    let (stored, status) = load(&mut store);
    match status {
        ParamsStatus::Stored => defmt::info!("parameters: stored record installed"),
        ParamsStatus::None => defmt::info!("parameters: none stored, running with the defaults"),
        ParamsStatus::Refused(e) => {
            defmt::warn!("parameters: stored record refused ({=str}), running with the defaults", record_error_word(e))
        }
        ParamsStatus::Unreadable => defmt::warn!("parameters: store unreadable, running with the defaults"),
    }
    drive.install_parameters(&stored.unwrap_or_else(default_parameters), &CHAIN_MODEL, status);
    drive.set_savable(true);
    let mut record = [0u8; 3 + MAX_BYTES_PER_STEP + MAX_REPLY_PER_STEP + MAX_SERVICE_BYTES_PER_STEP + 9];
    let mut decoder = Decoder::new();
    let mut frame = [0u8; MAX_FRAME];
    defmt::info!("PIL target up: PWM {} Hz, waiting for frames on UART0", DRIVE_CONFIG.pwm_hz);

    loop {
        let reply = match decoder.push(uart.read_byte()) {
            None => continue,
            Some(Ok(Message::Sense(sensors))) => {
                let mut io = ChipIo::new(&mut dcp_uart, &mut service_uart, &mut store, timing_overhead_ticks);
                let period = drive.period(&sensors, &mut io);
                let observer_end = SYST::get_current();
                let observer_cost = match (period.observer_ran, io.observer_start) {
                    (true, Some(start)) => {
                        (start.wrapping_sub(observer_end) & SYSTICK_RELOAD).saturating_sub(timing_overhead_ticks)
                    }
                    _ => 0,
                };
                let after_end = io.after_end.unwrap_or(observer_end);
                let after_ticks =
                    (io.after_start.wrapping_sub(after_end) & SYSTICK_RELOAD).saturating_sub(timing_overhead_ticks);
                let n = io.write_record(&mut record, period.observer_ran, observer_cost, after_ticks);
                let cost_ticks = io.control_ticks;
                dcp_uart.write_all(&record[..n]);
                Message::Output(StepReport::new(&period.drive.control, cost_ticks))
            }
            Some(Ok(Message::Travel(command))) => Message::Ack(command_result_code(drive.command_travel(command))),
            Some(Ok(Message::Reset)) => {
                // Nothing latched: nothing to clear, as the service port's `reset`.
                let _ = drive.reset();
                Message::Ack(0)
            }
            Some(Ok(Message::Compensation { strategy, table })) => {
                drive.controller_mut().install_compensation(strategy, &table, &CHAIN_MODEL);
                Message::Ack(0)
            }
            Some(Ok(Message::Output(_) | Message::Ack(_))) => continue,
            Some(Err(error)) => {
                // A rejected frame is a step that does not run: the
                // controller's deadline check sees the gap at the next frame.
                // The host is told so that it does not wait for an output.
                defmt::warn!("dropped a bad frame: {}", defmt::Debug2Format(&error));
                Message::Ack(ACK_FRAME_REJECTED)
            }
        };
        let n = encode(&reply, &mut frame);
        uart.write_all(&frame[..n]);
    }
}

/// The edges of the application layer on the emulated chip: UART1 (DCP)
/// and UART2 (service port) polled, the parameter store written on `save`,
/// the control step timed with SysTick; what a period took and replied, for
/// its record on UART1.
struct ChipIo<'a> {
    dcp_uart: &'a mut uart::Polled,
    service_uart: &'a mut uart::Polled,
    store: &'a mut Store,
    timing_overhead_ticks: u32,
    dcp_taken: [u8; MAX_BYTES_PER_STEP],
    n_dcp: usize,
    replies: [u8; MAX_REPLY_PER_STEP],
    n_replies: usize,
    service_taken: [u8; MAX_SERVICE_BYTES_PER_STEP],
    n_service: usize,
    control_start: u32,
    /// The control step's cost, SysTick ticks (the two reads' own cost taken off).
    control_ticks: u32,
    /// When the outputs were handed out: the rest of the period's work starts.
    after_start: u32,
    /// When the rest of the period's work ended, if the observer's task ran after it.
    after_end: Option<u32>,
    observer_start: Option<u32>,
}

impl<'a> ChipIo<'a> {
    fn new(
        dcp_uart: &'a mut uart::Polled,
        service_uart: &'a mut uart::Polled,
        store: &'a mut Store,
        timing_overhead_ticks: u32,
    ) -> Self {
        Self {
            dcp_uart,
            service_uart,
            store,
            timing_overhead_ticks,
            dcp_taken: [0; MAX_BYTES_PER_STEP],
            n_dcp: 0,
            replies: [0; MAX_REPLY_PER_STEP],
            n_replies: 0,
            service_taken: [0; MAX_SERVICE_BYTES_PER_STEP],
            n_service: 0,
            control_start: 0,
            control_ticks: 0,
            after_start: 0,
            after_end: None,
            observer_start: None,
        }
    }

    /// The step's record: `n_in, the DCP bytes taken, n_out, the reply
    /// bytes, n_service, the service bytes taken, observer, its cost, the
    /// cost of the rest of the period`; its length.
    fn write_record(&self, record: &mut [u8], observer_ran: bool, observer_ticks: u32, after_ticks: u32) -> usize {
        let n_in = self.n_dcp;
        record[0] = n_in as u8;
        record[1..1 + n_in].copy_from_slice(&self.dcp_taken[..n_in]);
        record[1 + n_in] = self.n_replies as u8;
        let mut end = 2 + n_in + self.n_replies;
        record[2 + n_in..end].copy_from_slice(&self.replies[..self.n_replies]);
        record[end] = self.n_service as u8;
        record[end + 1..end + 1 + self.n_service].copy_from_slice(&self.service_taken[..self.n_service]);
        end += 1 + self.n_service;
        record[end] = observer_ran as u8;
        record[end + 1..end + 5].copy_from_slice(&observer_ticks.to_le_bytes());
        record[end + 5..end + 9].copy_from_slice(&after_ticks.to_le_bytes());
        end + 9
    }
}

impl PeriodIo for ChipIo<'_> {
    fn service_byte(&mut self) -> Option<u8> {
        if self.n_service == MAX_SERVICE_BYTES_PER_STEP {
            return None;
        }
        let byte = self.service_uart.try_read_byte()?;
        self.service_taken[self.n_service] = byte;
        self.n_service += 1;
        Some(byte)
    }

    fn dcp_byte(&mut self) -> Option<u8> {
        if self.n_dcp == MAX_BYTES_PER_STEP {
            return None;
        }
        let byte = self.dcp_uart.try_read_byte()?;
        self.dcp_taken[self.n_dcp] = byte;
        self.n_dcp += 1;
        Some(byte)
    }

    fn control_started(&mut self) {
        self.control_start = SYST::get_current();
    }

    fn drive(&mut self, _output: &DriveOutput) {
        let end = SYST::get_current();
        // SysTick counts down, modulo its 24-bit reload.
        self.control_ticks =
            (self.control_start.wrapping_sub(end) & SYSTICK_RELOAD).saturating_sub(self.timing_overhead_ticks);
        self.after_start = SYST::get_current();
    }

    fn service_reply(&mut self, reply: &ServiceReply) {
        let written = reply.save.is_none_or(|p| save(self.store, &p));
        if written {
            self.service_uart.write_all(reply.line().as_bytes());
        } else {
            self.service_uart.write_all(b"error flash-write\r\n");
        }
    }

    fn dcp_reply(&mut self, reply: &[u8; 6]) {
        let end = (self.n_replies + reply.len()).min(MAX_REPLY_PER_STEP);
        let n = end - self.n_replies;
        self.replies[self.n_replies..end].copy_from_slice(&reply[..n]);
        self.n_replies = end;
    }

    fn observer_started(&mut self) {
        let now = SYST::get_current();
        self.after_end = Some(now);
        self.observer_start = Some(now);
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    defmt::error!("panic: {}", defmt::Debug2Format(info));
    cortex_m_semihosting::debug::exit(cortex_m_semihosting::debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::bkpt();
    }
}
