//! The service port for the bench: LPUART1 on the ST-LINK virtual COM port
//! (PA2 TX, PA3 RX, 115 200 baud 8N1), the line protocol of
//! `drive_core::service` (`host-sim drive --port ...` on the PC).
//!
//! What it reads and changes lives in [`STATE`]: the strategy and table
//! installed at start-up, the car mass of the load weighing (the DCP task
//! takes a new one before the next travel), the fault log (the controller's
//! trips, filled by the telemetry task) and the drive's state and speed (from
//! the control interrupt's snapshot, refreshed before each answer).
//! `set strategy` is answered `error unsupported`: installing another
//! strategy between travels is not implemented on the chip yet. `set
//! dcp-mode` restarts the DCP slave in the other variant (the DCP task
//! takes it). `save` writes the parameter record (strategy, table, car
//! mass, the stored encoder offset, DCP variant) to flash with the drive
//! idle and the control interrupt paused (`params.rs`); the table is what
//! the controller learned in its latest travel with `adaptive` or
//! `car-observer` (`drive_core::lift_drive::kept_table`, read from the
//! paused controller), else the table installed. During a travel or the
//! start-up `save` is answered `error busy`. `reset` clears latched faults
//! (`error nothing-to-reset` when none is latched) and `align` commands
//! the rotor alignment (accepted only in the safe state after the
//! calibration with nothing latched, else `error busy`): both go to the
//! control interrupt's command queue.

use core::cell::RefCell;

use critical_section::Mutex;
use defmt::warn;
use drive_core::param_store::DriveParameters;
use drive_core::service::{answer, parse, Request, ServiceState, MAX_LINE};
use embassy_stm32::usart::{self, BufferedUart};
use embedded_io_async::{Read, Write};

use crate::control;
use crate::params::ParamStore;

/// Baud rate of the service port.
pub const BAUD: u32 = 115_200;

/// The state the service port reads and changes (set once by `main`).
pub static STATE: Mutex<RefCell<Option<ServiceState>>> = Mutex::new(RefCell::new(None));

/// The USART settings of the service port: 115 200 baud 8N1.
pub fn uart_config() -> usart::Config {
    let mut config = usart::Config::default();
    config.baudrate = BAUD;
    config
}

/// The car mass of the load weighing now, kg (`None` before `main` set the state).
pub fn car_mass_kg() -> Option<f32> {
    critical_section::with(|cs| STATE.borrow_ref(cs).as_ref().map(|s| s.m_car_kg))
}

/// The DCP variant set on the service port (`None` before `main` set the state).
pub fn dcp_mode() -> Option<drive_core::dcp::Mode> {
    critical_section::with(|cs| STATE.borrow_ref(cs).as_ref().map(|s| s.dcp_mode))
}

/// Logs a controller fault code in the service port's fault log.
pub fn log_fault(code: u8) {
    critical_section::with(|cs| {
        if let Some(s) = STATE.borrow_ref_mut(cs).as_mut() {
            s.log_fault(code);
        }
    });
}

/// The service task: one answer line per request line; `store` keeps the
/// parameters, `encoder_offset_counts` is the stored encoder offset (kept
/// as it is in a new record).
#[embassy_executor::task]
pub async fn run(mut uart: BufferedUart<'static>, mut store: ParamStore, encoder_offset_counts: u32) {
    let mut line = [0u8; MAX_LINE + 1];
    let mut len = 0;
    let mut byte = [0u8; 1];
    loop {
        match uart.read(&mut byte).await {
            Ok(0) => continue,
            Ok(_) => {}
            Err(e) => {
                warn!("service port: line error {}", e);
                len = 0;
                continue;
            }
        }
        if byte[0] != b'\n' {
            // A line too long is answered `error line` once it ends.
            if len < line.len() {
                line[len] = byte[0];
                len += 1;
            }
            continue;
        }
        // Copied out and back: formatting an answer takes far longer than
        // the control interrupt may be held off (one PWM period).
        let Some(mut state) = critical_section::with(|cs| *STATE.borrow_ref(cs)) else {
            len = 0;
            continue;
        };
        let snapshot = control::snapshot();
        if let Some(drive) = snapshot.state {
            state.state_code = drive.code();
            state.travelling = drive.pwm_enabled() || drive.brake_released();
        }
        state.speed_radps = snapshot.speed_radps;
        // `get table` shows the table `save` would keep (the learned one
        // after a learning travel), as the PIL target's application layer.
        let installed = state.table;
        state.table = control::kept_table(&installed);
        let request = parse(&line[..len]).ok();
        let reply = answer(&line[..len], &mut state);
        let mut text: &[u8] = reply.as_bytes();
        if text.starts_with(b"ok") {
            match request {
                Some(Request::Reset) if !snapshot.fault => text = b"error nothing-to-reset",
                Some(Request::Reset) if control::submit(control::Command::Reset).is_err() => text = b"error busy",
                Some(Request::Align) if !snapshot.awaiting_alignment || snapshot.fault => text = b"error busy",
                Some(Request::Align) if control::submit(control::Command::Align).is_err() => text = b"error busy",
                _ => {}
            }
        }
        if state.save_requested {
            state.save_requested = false;
            if !control::pause_if_idle() {
                text = b"error busy";
            } else {
                // The controller is idle and its interrupt paused: what it
                // learned in its latest travel is the table to keep.
                let parameters = DriveParameters {
                    strategy: state.strategy,
                    table: control::kept_table(&installed),
                    m_car_kg: state.m_car_kg,
                    encoder_offset_counts,
                    dcp_mode: state.dcp_mode,
                };
                let written = store.save(&parameters).await;
                control::resume();
                if !written {
                    text = b"error flash-write";
                }
            }
        }
        critical_section::with(|cs| {
            if let Some(shared) = STATE.borrow_ref_mut(cs).as_mut() {
                shared.m_car_kg = state.m_car_kg;
                shared.dcp_mode = state.dcp_mode;
            }
        });
        len = 0;
        if uart.write_all(text).await.is_err() || uart.write_all(b"\r\n").await.is_err() {
            warn!("service port: answer not sent");
        }
    }
}
