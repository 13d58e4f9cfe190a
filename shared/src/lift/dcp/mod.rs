//! DCP (Drive Control and Position), the lift controller's serial interface
//! to the drive: codec and slave state machine, no hardware.
//!
//! DCP runs on RS-485, half duplex, 38 400 baud 8N1, between the lift
//! controller (the master) and the drive (the slave, which only answers).
//! Every message is 6 bytes: command or status byte, two data bytes, two
//! communication bytes, checksum.
//!
//! What this module follows, from public drive makers' DCP descriptions:
//! - YASKAWA, *AC Drive L1000A Technical Manual Addendum* (TOEP C710616
//!   134G), chapter 6 "DCP Interface", pp. 18-34: line settings, message
//!   layout, XOR checksum, command and status bits, the message table of
//!   DCP3 and DCP4, the speed bits, the position message `I9`, the answer to
//!   transmission errors ("the L1000A addendum" in the docs of the
//!   submodules).
//! - *DCP - Interface, Dynavert L, Technical
//!   Description* (July 2010 draft, 4BS0449-005), sections 1-2: the slave
//!   only answers, and it must have a timeout watchdog that takes the drive
//!   to a safe condition.
//! - KOLLMORGEN Steuerungstechnik, *SE DCP Description* (revision 1.0.0.14,
//!   2023), the protocol's owner: only its revision history was readable
//!   (16-bit distances, fast start, timeout safety function exist); nothing
//!   here depends on its body.
//!
//! Where these texts are silent (the message delimiting on the line, the
//! timeout value, the answer to errors other than a checksum error, the
//! byte order of the speed bits, the unit of the remaining distance, taken
//! as mm like the position message), the submodule that decides says so
//! and chooses the conservative reading: never a travel on a doubtful
//! message.
//!
//! - [`frame`]: the 6-byte codec and the receiver that delimits messages.
//! - [`command`]: the command byte, message types, speed bits, distances.
//! - [`channel`]: the text channel in the communication bytes (position message).
//! - [`slave`]: replies, requests to the drive, timeout watchdog.

pub mod channel;
pub mod command;
pub mod frame;
pub mod slave;

#[cfg(test)]
mod tests;

pub use command::{Mode, Speed};
pub use frame::{FrameError, FrameReceiver, MasterFrame, SlaveFrame};
pub use slave::{DriveStatus, Outcome, Request, Slave, SlaveConfig, StopReason, Travel};
