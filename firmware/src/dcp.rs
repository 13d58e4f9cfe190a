//! The lift controller's link: UART5, RS-485 half duplex, 38 400 baud 8N1,
//! carrying DCP to and from the drive's application layer
//! (`drive_core::lift_drive::LiftDrive`, in the control interrupt).
//!
//! Pins (the board description, `board.rs`): PC12 UART5_TX (AF5) to the
//! transceiver's DI, PD2 UART5_RX (AF5, pull-up: the transceiver's RO floats
//! while it drives) from RO, PC10 a plain GPIO output to DE and /RE tied
//! together. Not the UART's own DE: UART5_DE is PB4 only, the IHM08M1's
//! over-current reference CURRENT_REF, and every other hardware DE pin of
//! this package is a shield signal too (`docs/firmware.md`, the DcpDe row).
//! [`send`] raises DE before the first byte of a reply and lowers it when
//! the UART reports the last stop bit out (transmission complete, the
//! buffered UART's `flush`), a few microseconds of interrupt latency after
//! it; with /RE tied to DE the receiver is off while the drive talks, so
//! its own reply is never read back. Until `main` makes PC10 an output
//! (and through any reset) the pin is high-impedance: the transceiver's
//! DE needs a pull-down so that the drive never holds the line then.
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
use embassy_stm32::gpio::{Level, Output};
use embassy_stm32::usart::{self, BufferedUartRx, BufferedUartTx};
use embedded_io_async::{Read, Write};

use crate::edges;

/// The USART settings of DCP: 38 400 baud, 8 data bits, no parity, one stop
/// bit.
pub fn uart_config() -> usart::Config {
    let mut config = usart::Config::default();
    config.baudrate = drive_core::dcp::frame::BAUD;
    config.data_bits = usart::DataBits::DataBits8;
    config.parity = usart::Parity::ParityNone;
    config.stop_bits = usart::StopBits::STOP1;
    config.rx_pull = embassy_stm32::gpio::Pull::Up;
    config.eager_reads = Some(1);
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

/// The pin level of the driver enable [`send`] drives while a reply goes
/// out (the description's active level of `DcpDe`).
pub const DE_ASSERTED: Level = if crate::board::DCP_DE_ACTIVE_LOW { Level::Low } else { Level::High };

/// The pin level of the driver enable while the drive listens.
pub const DE_RELEASED: Level = if crate::board::DCP_DE_ACTIVE_LOW { Level::High } else { Level::Low };

/// Sends the drive's replies, driving the transceiver's DE around each.
#[embassy_executor::task]
pub async fn send(mut tx: BufferedUartTx<'static>, mut de: Output<'static>) {
    loop {
        let reply = edges::DCP_TX.receive().await;
        de.set_level(DE_ASSERTED);
        if let Err(e) = tx.write_all(&reply).await {
            error!("DCP reply not sent: {}", e);
        }
        // Transmission complete: the stop bit of the last byte is out.
        if let Err(e) = tx.flush().await {
            error!("DCP reply not flushed: {}", e);
        }
        de.set_level(DE_RELEASED);
    }
}
