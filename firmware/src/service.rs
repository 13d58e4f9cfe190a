//! The service port for the bench: LPUART1 on the ST-LINK virtual COM port
//! (PA2 TX, PA3 RX, 115 200 baud 8N1), the line protocol of
//! `drive_core::service` (`host-sim drive --port ...` on the PC), answered
//! by the drive's application layer (`drive_core::lift_drive::LiftDrive`,
//! in the control interrupt), as on the processor-in-the-loop target.
//!
//! Two tasks only move bytes: [`receive`] puts every byte received into
//! `edges::SERVICE_RX` (the interrupt takes a request line's bytes, up to 8
//! a period); [`send`] formats every answer of `edges::SERVICE_TX` (the
//! numbers take thousands of cycles: here, not in the interrupt) and writes
//! it. A `save` carries the parameter record to write (strategy, the table
//! learned or installed, car mass, encoder offset, DCP variant): the task
//! writes it to flash with the control interrupt paused, only with the
//! drive at rest in its safe state (`control::pause_if_idle`; otherwise
//! `error busy`), and answers `error flash-write` if the write fails.

use defmt::warn;
use embassy_stm32::usart::{self, BufferedUartRx, BufferedUartTx};
use embedded_io_async::{Read, Write};

use crate::params::ParamStore;
use crate::{control, edges};

/// Baud rate of the service port.
pub const BAUD: u32 = 115_200;

/// The USART settings of the service port: 115 200 baud 8N1.
pub fn uart_config() -> usart::Config {
    let mut config = usart::Config::default();
    config.baudrate = BAUD;
    config
}

/// Moves the bytes received to the control interrupt.
#[embassy_executor::task]
pub async fn receive(mut rx: BufferedUartRx<'static>) {
    let mut buf = [0u8; 16];
    loop {
        match rx.read(&mut buf).await {
            Ok(n) => {
                for &byte in &buf[..n] {
                    edges::SERVICE_RX.send(byte).await;
                }
            }
            // The line's request is cut: it ends as an unknown request.
            Err(e) => warn!("service port: line error {}", e),
        }
    }
}

/// Formats and sends the drive's answers; writes the record of a `save`.
#[embassy_executor::task]
pub async fn send(mut tx: BufferedUartTx<'static>, mut store: ParamStore) {
    loop {
        let reply = edges::SERVICE_TX.receive().await;
        let line = reply.line();
        let mut text = line.as_bytes();
        if let Some(parameters) = reply.save {
            if !control::pause_if_idle() {
                text = b"error busy\r\n";
            } else {
                let written = store.save(&parameters).await;
                control::resume();
                if !written {
                    text = b"error flash-write\r\n";
                }
            }
        }
        if tx.write_all(text).await.is_err() {
            warn!("service port: answer not sent");
        }
    }
}
