//! The lift controller's link: UART5, RS-485 half duplex, 38 400 baud 8N1,
//! carrying DCP to and from the drive's application layer
//! (`drive_core::lift_drive::LiftDrive`, in the control interrupt).
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
//! Two tasks only move bytes: [`receive`] puts every byte received into
//! `edges::DCP_RX` (the control interrupt takes up to 8 a PWM period and
//! time stamps them with the period's sensor time, as the
//! processor-in-the-loop target does); [`send`] writes every reply of
//! `edges::DCP_TX`. A UART error drops the byte: the message it was part
//! of ends short and is answered with the error bit. Framing, protocol,
//! timeout watchdog and the mapping to the controller are all in
//! `drive_core`.

use defmt::{error, info, warn};
use embassy_stm32::usart::{self, BufferedUartRx, BufferedUartTx};
use embedded_io_async::{Read, Write};

use crate::edges;

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

/// Moves the bytes received to the control interrupt.
#[embassy_executor::task]
pub async fn receive(mut rx: BufferedUartRx<'static>) {
    info!(
        "DCP slave on UART5 (RS-485, {=u32} baud 8N1): waiting for the lift controller",
        drive_core::dcp::frame::BAUD
    );
    let mut buf = [0u8; 8];
    loop {
        match rx.read(&mut buf).await {
            Ok(n) => {
                for &byte in &buf[..n] {
                    edges::DCP_RX.send(byte).await;
                }
            }
            Err(e) => warn!("DCP line error (byte dropped): {}", e),
        }
    }
}

/// Sends the drive's replies.
#[embassy_executor::task]
pub async fn send(mut tx: BufferedUartTx<'static>) {
    loop {
        let reply = edges::DCP_TX.receive().await;
        if let Err(e) = tx.write_all(&reply).await {
            error!("DCP reply not sent: {}", e);
        }
        if let Err(e) = tx.flush().await {
            error!("DCP reply not flushed: {}", e);
        }
    }
}
