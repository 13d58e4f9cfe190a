//! Drive firmware of the elevator on the NUCLEO-G474RE (STM32G474RE) with an
//! X-NUCLEO-IHM08M1 three-phase inverter.
//!
//! Peripherals (pin map and what is not verified: `board.rs`):
//! - TIM1 (`pwm.rs`): 16 kHz centre-aligned complementary PWM, 1 us hardware
//!   dead time, over-current break input BKIN, compare update once per
//!   period at the counter underflow, TRGO2 at the counter peak.
//! - ADC1/ADC2 (`adc.rs`): injected sequences of the three phase currents and
//!   the DC bus, started by TRGO2; ADC2's end of sequence is the control
//!   interrupt.
//! - TIM4 (`encoder.rs`): quadrature encoder; TIM2 (`timebase.rs`): 1 MHz
//!   time stamps; TIM8 on PC8: brake (idle = applied); IWDG (`watchdog.rs`).
//!
//! The control interrupt (`control.rs`, highest priority) runs the drive's
//! application layer, `drive_core::lift_drive::LiftDrive` (the code the
//! processor-in-the-loop target and the host run), once per PWM period with
//! the measured values: the start-up sequence, the controller (its speed
//! loop, profile and speed observer inside), the service port's requests
//! and the DCP slave. With the strategy `car-observer`, the chain observer
//! runs in a task of its own (`observer.rs`: an interrupt executor below
//! the control interrupt), fed by the controller at each speed-loop tick
//! and read back at the next. Five thread-mode Embassy tasks only move
//! bytes and log, through the channels of `edges.rs`: `telemetry.rs` logs
//! what the interrupt queues and feeds the watchdog while the interrupt is
//! alive; `dcp.rs` receives and sends the DCP line's bytes; `service.rs`
//! receives the service port's bytes, formats and sends the answers and
//! writes the parameter record of a `save`.
//!
//! Start-up: clocks, then the peripherals with the inverter off (MOE = 0,
//! brake applied), then the control interrupt, which waits 10 ms for the
//! analog front end to settle and calibrates the current-sensor offsets over
//! 64 ms (`drive_core::current_offset`) with the PWM outputs DISABLED: with every
//! switch off no phase current can flow, so the measured codes are the true
//! zero, whereas at 50 % duty the zero holds only for a standing machine and
//! matched legs, and the bridge would be switching before its current
//! readings are trustworthy. (The switching noise that couples into the
//! readings is therefore not part of the offset.) A rejected calibration
//! latches a fault (PWM off, brake applied) and the log says why. Then the
//! drive stays in its safe state (gates off, brake applied, not ready)
//! until the service port commands the rotor alignment (`align`:
//! `drive_core::startup`, current injected at electrical 0, +90 and 0
//! degrees with the brake open, checked from the encoder and guarded by the
//! controller's protections); after it the brake is set and the drive is
//! Idle and reports itself ready to the lift controller. The same holds
//! after every reset (power-up, watchdog, reset button).
//!
//! Travel commands come from a lift controller over DCP (`dcp.rs`: UART5,
//! RS-485 half duplex with the USART driving the transceiver's DE): DCP4
//! distance travels with the position message after each stop, or DCP3
//! speed-mode travels (the variant is a stored parameter, settable on the
//! service port; DCP4 by default); the slave's
//! timeout watchdog stops the drive safely (inverter off, brake applied)
//! when the master falls silent. The car mass of the load weighing is a
//! parameter (`params.rs`, settable on the service port), the heaviest car
//! of the rig until one is stored. A latched fault is cleared by the service
//! port's `reset` (a failed calibration then calibrates again).
//!
//! Service port (`service.rs`): LPUART1 on the ST-LINK virtual COM port,
//! the line protocol of `drive_core::service` (`host-sim drive --port`):
//! strategy (settable), table, car mass (settable), DCP variant (settable), fault
//! log, state, the stored record's status, and `save` (writes the record
//! with the drive idle).
//!
//! Compensation: the ripple-compensation strategy and its harmonic table
//! are parameters, read at start-up from the parameter record in flash
//! (`params.rs`, version and CRC checked); without a valid record the drive
//! installs [`DEFAULT_STRATEGY`] with the offline table of the rig's ripple.
//!
//! Build and flash: `cargo flash` (alias for `cargo run -p firmware --release
//! --target thumbv7em-none-eabihf`) from the workspace root, or `cargo run
//! --release` inside `firmware/` (whose `.cargo/config.toml` sets the
//! target). A plain `cargo run -p firmware --release` from the root cannot
//! pick the target: cargo reads `.cargo/config.toml` only from the current
//! directory upwards, a per-package target (`forced-target`) is unstable
//! (`-Z per-package-target`), and an alias named `run` is ignored because it
//! would shadow a built-in command.
#![no_std]
#![no_main]
#![deny(unsafe_code)]
#![warn(missing_docs)]

mod adc;
#[macro_use]
mod board;
mod control;
mod dcp;
mod edges;
mod encoder;
mod observer;
mod params;
mod pwm;
mod service;
mod telemetry;
mod timebase;
mod watchdog;

use defmt::{error, info, warn};
use defmt_rtt as _;
use drive_core::dcp::{Mode, SlaveConfig};
use drive_core::lift_drive::{speed_table, AngleReference, DcpPort, LiftDrive};
use drive_core::param_store::DriveParameters;
use drive_core::ripple::harmonics::HarmonicTable;
use drive_core::ripple::Strategy;
use drive_core::Controller;
use embassy_executor::Spawner;
use embassy_stm32::gpio::{Output, Speed};
use embassy_stm32::peripherals::{LPUART1, UART5};
use embassy_stm32::time::Hertz;
use embassy_stm32::{bind_interrupts, usart};

include!(concat!(env!("OUT_DIR"), "/drive_config.rs"));

/// The compensation strategy installed when no valid parameter record is stored.
pub const DEFAULT_STRATEGY: Strategy = Strategy::Table;

/// The DCP variant without a stored record: distance mode.
pub const DCP_MODE: Mode = Mode::Dcp4;

bind_interrupts!(struct Irqs {
    UART5 => usart::BufferedInterruptHandler<UART5>;
    LPUART1 => usart::BufferedInterruptHandler<LPUART1>;
});

/// The offline compensation table: the rig's ripple (`RIPPLE`), negated.
fn offline_table() -> HarmonicTable {
    let mut table = HarmonicTable::default();
    for (order, amplitude_nm, cos_phase, sin_phase) in RIPPLE {
        table.push_cosine(order, amplitude_nm, cos_phase, sin_phase);
    }
    table.negated()
}

// rig-config derives the PWM period from its own idea of the timer clock
// (centre-aligned counting): it must be the clock this board runs TIM1 at.
const _: () = assert!(
    (board::SYSCLK_HZ as f32 / (2.0 * DRIVE_CONFIG.pwm_hz)) as u16 == DRIVE_CONFIG.pwm_period_counts,
    "configs/rig.toml's pwm_timer_clock_hz does not match board::SYSCLK_HZ"
);

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = embassy_stm32::init(board::clock_config());
    board::freeze_on_debug_halt();
    let brake = board::Brake::new(p.TIM8, board_pin!(p, BrakePin));

    let clocks = embassy_stm32::rcc::clocks(&p.RCC);
    info!("board: {=str}; clocks: {}", board::BOARD_NAME, clocks);
    defmt::assert!(
        clocks.sys.to_hertz() == Some(Hertz(board::SYSCLK_HZ)),
        "SYSCLK is not the 170 MHz the drive timing assumes"
    );

    // DWT cycle counter: the control interrupt times itself with it.
    let Some(mut core) = cortex_m::Peripherals::take() else {
        defmt::panic!("Cortex-M core peripherals already taken");
    };
    core.DCB.enable_trace();
    core.DWT.enable_cycle_counter();

    timebase::init(p.TIM2);
    encoder::init(p.TIM4, board_pin!(p, EncoderA), board_pin!(p, EncoderB));
    if let Err(e) = pwm::init(
        p.TIM1,
        board_pin!(p, PwmUHigh),
        board_pin!(p, PwmVHigh),
        board_pin!(p, PwmWHigh),
        board_pin!(p, PwmULow),
        board_pin!(p, PwmVLow),
        board_pin!(p, PwmWLow),
        board_pin!(p, BreakIn),
    ) {
        error!("TIM1 setup failed ({}): the inverter stays off", e);
        halt();
    }
    info!(
        "TIM1: ARR {=u16} (PWM {=f32} Hz), dead time {=u32} ticks (DTG {=u8:#x}), ADC trigger {=u16} ticks before the peak",
        pwm::PERIOD_COUNTS,
        board::SYSCLK_HZ as f32 / pwm::PERIOD_CYCLES as f32,
        pwm::DEAD_TIME_INSERTED_COUNTS,
        pwm::DTG,
        pwm::TRIGGER_LEAD_COUNTS
    );
    adc::init(
        p.ADC1,
        p.ADC2,
        board_pin!(p, CurrentUPin),
        board_pin!(p, CurrentVPin),
        board_pin!(p, CurrentWPin),
        board_pin!(p, DcBusPin),
    );

    let mut store = params::ParamStore::new(p.FLASH);
    let (stored, params_status) = store.load().await;
    let parameters = stored.unwrap_or(DriveParameters {
        strategy: DEFAULT_STRATEGY,
        table: offline_table(),
        m_car_kg: DEFAULT_CAR_MASS_KG,
        encoder_offset_counts: 0,
        dcp_mode: DCP_MODE,
    });
    info!(
        "compensation: {=str} over {=usize} harmonics ({=str}); car mass {=f32} kg",
        parameters.strategy.name(),
        parameters.table.len,
        if stored.is_some() { "stored parameters" } else { "defaults" },
        parameters.m_car_kg
    );
    // The drive's application layer, the code the processor-in-the-loop
    // target and the host run: the rig's encoder is incremental, so the
    // angle reference comes from the commanded alignment.
    let slave = SlaveConfig::new(DCP_MODE, speed_table(DRIVE_CONFIG.rated_speed_mps), LIFT_GEOMETRY.shaft_travel_mm);
    let port = DcpPort::new(slave, LIFT_GEOMETRY, parameters.m_car_kg);
    let mut app = LiftDrive::new(Controller::new(&DRIVE_CONFIG), port, &DRIVE_CONFIG, AngleReference::Alignment);
    app.install_parameters(&parameters, &CHAIN_MODEL, params_status);
    app.set_savable(true);
    // The chain observer runs in a task of its own, below the control interrupt.
    match app.take_observer_task() {
        Some(task) => {
            observer::start(task);
            info!("chain observer task running (interrupt executor at priority {=u8})", observer::PRIORITY as u8);
        }
        None => error!("chain observer model refused: with car-observer every speed tick counts a missed deadline"),
    }
    control::start(app, brake);
    info!(
        "control interrupt running: current loop {=f32} Hz, speed loop {=f32} Hz; calibrating current offsets",
        DRIVE_CONFIG.current_loop_hz, DRIVE_CONFIG.speed_loop_hz
    );

    let watchdog = watchdog::Watchdog::start(p.IWDG, control::steps());
    spawner.spawn(defmt::unwrap!(telemetry::run(watchdog)));

    // The UART interrupts only move bytes: below the control interrupt (P0),
    // the time driver (P1) and the observer's executor (P2).
    {
        use embassy_stm32::interrupt::{self, InterruptExt, Priority};
        interrupt::UART5.set_priority(Priority::P3);
        interrupt::LPUART1.set_priority(Priority::P3);
    }
    let tx_buffer = defmt::unwrap!(cortex_m::singleton!(: [u8; 32] = [0; 32]));
    let rx_buffer = defmt::unwrap!(cortex_m::singleton!(: [u8; 64] = [0; 64]));
    // The transceiver's driver enable: released (listening) from here on.
    let dcp_de = Output::new(board_pin!(p, DcpDe), dcp::DE_RELEASED, Speed::Low);
    match usart::BufferedUart::new(
        p.UART5,
        board_pin!(p, DcpRx),
        board_pin!(p, DcpTx),
        tx_buffer,
        rx_buffer,
        Irqs,
        dcp::uart_config(),
    ) {
        Ok(uart) => {
            let (tx, rx) = uart.split();
            spawner.spawn(defmt::unwrap!(dcp::receive(rx)));
            spawner.spawn(defmt::unwrap!(dcp::send(tx, dcp_de)));
        }
        Err(e) => error!("UART5 (DCP) setup failed ({}): no lift controller link, the drive stays idle", e),
    }
    let service_tx = defmt::unwrap!(cortex_m::singleton!(: [u8; 512] = [0; 512]));
    let service_rx = defmt::unwrap!(cortex_m::singleton!(: [u8; 128] = [0; 128]));
    match usart::BufferedUart::new(p.LPUART1, p.PA3, p.PA2, service_tx, service_rx, Irqs, service::uart_config()) {
        Ok(uart) => {
            let (tx, rx) = uart.split();
            spawner.spawn(defmt::unwrap!(service::receive(rx)));
            spawner.spawn(defmt::unwrap!(service::send(tx, store)));
        }
        Err(e) => error!("LPUART1 (service port) setup failed ({}): no service port", e),
    }
}

/// Stops with the drive in its safe state: undefined instruction, so the
/// HardFault handler below (and a debugger, which stops there) takes over.
fn halt() -> ! {
    board::force_safe_state();
    cortex_m::asm::udf()
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    // First the inverter: TIM1 keeps switching whatever the core does.
    board::force_safe_state();
    error!("panic: {}", defmt::Display2Format(info));
    halt()
}

#[defmt::panic_handler]
fn defmt_panic() -> ! {
    // defmt::panic!/assert! have printed their message already.
    halt()
}

/// HardFault (also the end of [`halt`]): safe state, then wait for the
/// watchdog to restart the chip (if it runs; otherwise stay here).
#[cortex_m_rt::exception]
#[allow(unsafe_code)]
unsafe fn HardFault(_frame: &cortex_m_rt::ExceptionFrame) -> ! {
    // SAFETY: nothing unsafe happens here; cortex-m-rt requires the HardFault
    // handler to be declared `unsafe fn`. It only writes TIM1's BDTR and
    // GPIOC's BSRR through the PAC.
    board::force_safe_state();
    loop {
        cortex_m::asm::nop();
    }
}
