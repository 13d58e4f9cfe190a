//! The DCP message codec: fixed 6-byte master and slave messages and the
//! receiver that delimits them on the byte stream of a half-duplex line.
//!
//! Layout (both directions, L1000A addendum p. 18): byte 1 the command byte
//! (master) or status byte (slave), bytes 2-3 the two data bytes (process
//! data), bytes 4-5 the two communication bytes, byte 6 the checksum, "the
//! result of an XOR operation across all 5 data bytes" (p. 20).
//!
//! Delimiting: the public texts give the fixed length but not how a
//! receiver finds the start of a message after a lost or extra byte. This
//! receiver ends a message when the line has been idle for
//! [`FRAME_GAP_US`] (3.5 character times at 38 400 baud 8N1, the Modbus RTU
//! convention), so that a message with a missing byte is reported as
//! truncated and one with extra bytes as too long instead of shifting every
//! later message by the difference.

/// Bytes in a DCP message, either direction.
pub const FRAME_LEN: usize = 6;

/// Line rate of DCP, baud (8 data bits, no parity, 1 stop bit).
pub const BAUD: u32 = 38_400;

/// Time of one character on the line (10 bits at [`BAUD`]), us (rounded up).
pub const CHARACTER_US: u32 = (10 * 1_000_000u32).div_ceil(BAUD);

/// Idle time that ends a message: 3.5 character times, us.
pub const FRAME_GAP_US: u32 = (7 * CHARACTER_US).div_ceil(2);

/// XOR of the five bytes before the checksum.
pub fn checksum(bytes: &[u8; 5]) -> u8 {
    bytes.iter().fold(0, |acc, b| acc ^ b)
}

/// A message of the lift controller (the master).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MasterFrame {
    /// Command byte (bits B0-B7, see [`super::command`]).
    pub command: u8,
    /// The two data bytes (speed bits or remaining distance, most significant first).
    pub data: [u8; 2],
    /// The two communication bytes (text channel, see [`super::channel`]).
    pub comm: [u8; 2],
}

/// A message of the drive (the slave).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SlaveFrame {
    /// Status byte (bits S0-S7, see [`super::status`]).
    pub status: u8,
    /// The two data bytes (deceleration distance or extended status).
    pub data: [u8; 2],
    /// The two communication bytes.
    pub comm: [u8; 2],
}

fn encode(first: u8, data: [u8; 2], comm: [u8; 2]) -> [u8; FRAME_LEN] {
    let body = [first, data[0], data[1], comm[0], comm[1]];
    [body[0], body[1], body[2], body[3], body[4], checksum(&body)]
}

fn decode(bytes: &[u8; FRAME_LEN]) -> Result<(u8, [u8; 2], [u8; 2]), FrameError> {
    let body = [bytes[0], bytes[1], bytes[2], bytes[3], bytes[4]];
    if checksum(&body) != bytes[5] {
        return Err(FrameError::Checksum);
    }
    Ok((bytes[0], [bytes[1], bytes[2]], [bytes[3], bytes[4]]))
}

impl MasterFrame {
    /// The six bytes on the line, checksum last.
    pub fn encode(&self) -> [u8; FRAME_LEN] {
        encode(self.command, self.data, self.comm)
    }

    /// The message of six received bytes, if the checksum holds.
    pub fn decode(bytes: &[u8; FRAME_LEN]) -> Result<Self, FrameError> {
        decode(bytes).map(|(command, data, comm)| Self { command, data, comm })
    }
}

impl SlaveFrame {
    /// The six bytes on the line, checksum last.
    pub fn encode(&self) -> [u8; FRAME_LEN] {
        encode(self.status, self.data, self.comm)
    }

    /// The message of six received bytes, if the checksum holds.
    pub fn decode(bytes: &[u8; FRAME_LEN]) -> Result<Self, FrameError> {
        decode(bytes).map(|(status, data, comm)| Self { status, data, comm })
    }
}

/// Why received bytes are not a message.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// The checksum byte is not the XOR of the other five.
    Checksum,
    /// The line fell idle after this many bytes (fewer than six).
    Truncated(u8),
    /// More than six bytes arrived without the idle gap between messages.
    TooLong,
    /// The UART reported a framing, noise, parity or overrun error in the message.
    Line,
}

/// Delimits master messages on the received byte stream by the idle gap.
///
/// Feed every received byte with [`FrameReceiver::push`] and call
/// [`FrameReceiver::poll`] at least once per gap time; a message (or its
/// error) is reported once the line has been idle for the gap after it.
#[derive(Clone, Copy, Debug)]
pub struct FrameReceiver {
    bytes: [u8; FRAME_LEN],
    len: usize,
    too_long: bool,
    line_error: bool,
    last_byte_us: u32,
    gap_us: u32,
}

impl Default for FrameReceiver {
    fn default() -> Self {
        Self::new(FRAME_GAP_US)
    }
}

impl FrameReceiver {
    /// A receiver that ends a message after `gap_us` microseconds of idle line.
    pub fn new(gap_us: u32) -> Self {
        Self { bytes: [0; FRAME_LEN], len: 0, too_long: false, line_error: false, last_byte_us: 0, gap_us }
    }

    /// Whether bytes of an unfinished message are held.
    pub fn is_receiving(&self) -> bool {
        self.len > 0 || self.too_long || self.line_error
    }

    /// One received byte at time `now_us` (wrapping microsecond clock). If
    /// the line had been idle for the gap since the previous byte, the
    /// message held so far is finished first and returned.
    pub fn push(&mut self, byte: u8, now_us: u32) -> Option<Result<MasterFrame, FrameError>> {
        let finished = self.poll(now_us);
        if self.len < FRAME_LEN {
            self.bytes[self.len] = byte;
            self.len += 1;
        } else {
            self.too_long = true;
        }
        self.last_byte_us = now_us;
        finished
    }

    /// The UART flagged an error on a byte at `now_us`: the message it
    /// belongs to is reported as [`FrameError::Line`].
    pub fn line_error(&mut self, now_us: u32) -> Option<Result<MasterFrame, FrameError>> {
        let finished = self.poll(now_us);
        self.line_error = true;
        self.last_byte_us = now_us;
        finished
    }

    /// The message held, if the line has been idle for the gap at `now_us`.
    pub fn poll(&mut self, now_us: u32) -> Option<Result<MasterFrame, FrameError>> {
        if !self.is_receiving() || now_us.wrapping_sub(self.last_byte_us) < self.gap_us {
            return None;
        }
        let result = if self.line_error {
            Err(FrameError::Line)
        } else if self.too_long {
            Err(FrameError::TooLong)
        } else if self.len < FRAME_LEN {
            Err(FrameError::Truncated(self.len as u8))
        } else {
            MasterFrame::decode(&self.bytes)
        };
        self.len = 0;
        self.too_long = false;
        self.line_error = false;
        Some(result)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_gap_is_three_and_a_half_characters_at_38400_baud() {
        assert_eq!(CHARACTER_US, 261);
        assert_eq!(FRAME_GAP_US, 914);
    }

    #[test]
    fn a_message_round_trips_and_its_checksum_is_the_xor_of_five_bytes() {
        let m = MasterFrame { command: 0x05, data: [0x12, 0x34], comm: [0x02, 0x1C] };
        let bytes = m.encode();
        assert_eq!(bytes[5], 0x05 ^ 0x12 ^ 0x34 ^ 0x02 ^ 0x1C);
        assert_eq!(MasterFrame::decode(&bytes), Ok(m));
        let s = SlaveFrame { status: 0x41, data: [0, 200], comm: [0, 0] };
        assert_eq!(SlaveFrame::decode(&s.encode()), Ok(s));
    }

    #[test]
    fn every_single_bit_error_is_caught_by_the_checksum() {
        let bytes = MasterFrame { command: 0x07, data: [0x01, 0xF4], comm: [0, 0] }.encode();
        for i in 0..FRAME_LEN {
            for bit in 0..8 {
                let mut bad = bytes;
                bad[i] ^= 1 << bit;
                assert_eq!(MasterFrame::decode(&bad), Err(FrameError::Checksum), "byte {i} bit {bit}");
            }
        }
    }

    fn feed(rx: &mut FrameReceiver, bytes: &[u8], t0: u32) -> (Vec<Result<MasterFrame, FrameError>>, u32) {
        let mut out = Vec::new();
        let mut t = t0;
        for &b in bytes {
            out.extend(rx.push(b, t));
            t = t.wrapping_add(CHARACTER_US);
        }
        (out, t)
    }

    extern crate std;
    use std::vec::Vec;

    #[test]
    fn the_receiver_delimits_messages_by_the_idle_gap() {
        let mut rx = FrameReceiver::default();
        let m = MasterFrame { command: 0x01, data: [0, 0], comm: [0, 0] };
        let (early, t) = feed(&mut rx, &m.encode(), 1000);
        assert!(early.is_empty());
        assert_eq!(rx.poll(t + FRAME_GAP_US - CHARACTER_US - 1), None, "finished before the gap");
        assert_eq!(rx.poll(t - CHARACTER_US + FRAME_GAP_US), Some(Ok(m)));
        assert_eq!(rx.poll(t + 10 * FRAME_GAP_US), None, "reported twice");
    }

    #[test]
    fn short_and_long_messages_are_length_errors_and_the_next_message_is_intact() {
        let mut rx = FrameReceiver::default();
        let m = MasterFrame { command: 0x05, data: [0x03, 0xE8], comm: [0, 0] };
        let bytes = m.encode();
        let (_, t) = feed(&mut rx, &bytes[..4], 0);
        let t = t + FRAME_GAP_US;
        let (out, t) = feed(&mut rx, &bytes, t);
        assert_eq!(out, [Err(FrameError::Truncated(4))]);
        let mut long = bytes.to_vec();
        long.push(0x00);
        let (out, t) = feed(&mut rx, &long, t + FRAME_GAP_US);
        assert_eq!(out, [Ok(m)]);
        assert_eq!(rx.poll(t + FRAME_GAP_US), Some(Err(FrameError::TooLong)));
        rx.line_error(t + 2 * FRAME_GAP_US);
        assert_eq!(rx.poll(t + 4 * FRAME_GAP_US), Some(Err(FrameError::Line)));
    }

    #[test]
    fn the_gap_is_measured_across_the_wrap_of_the_microsecond_clock() {
        let mut rx = FrameReceiver::default();
        let m = MasterFrame { command: 0x00, data: [0, 0], comm: [0, 0] };
        let (_, t) = feed(&mut rx, &m.encode(), u32::MAX - 800);
        assert_eq!(rx.poll(t.wrapping_add(FRAME_GAP_US)), Some(Ok(m)));
    }
}
