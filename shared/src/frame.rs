//! The processor-in-the-loop (PIL) frame codec, used by both ends of the
//! link: the emulated chip and `host-sim`.
//!
//! A frame is `0xA5 0x5A kind len payload[len] crc_lo crc_hi`, little-endian
//! fields, with the CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) of
//! `kind len payload`. The decoder resynchronises on the next sync pair after
//! any error, so a corrupted byte costs one frame, never the link.
//! Floating-point values travel as their IEEE-754 bits, so nothing is lost.

use crate::config::Direction;
use crate::controller::{CommandError, ControlOutput, DriveState, SensorFrame, Telemetry, TravelCommand};
use crate::profile::ProfileError;
use crate::ripple::complex::Complex;
use crate::ripple::harmonics::HarmonicTable;
use crate::ripple::Strategy;

/// First sync byte.
pub const SYNC0: u8 = 0xA5;
/// Second sync byte.
pub const SYNC1: u8 = 0x5A;
/// Largest payload, bytes.
pub const MAX_PAYLOAD: usize = 64;
/// Largest encoded frame, bytes.
pub const MAX_FRAME: usize = MAX_PAYLOAD + 6;

/// [`Message::Ack`] code of the chip's answer to a frame its decoder
/// rejected (CRC, kind, length or field): the step of a rejected `Sense`
/// frame does not run, which the controller sees as a missed deadline at the
/// next frame.
pub const ACK_FRAME_REJECTED: u8 = 0xFF;

const KIND_SENSE: u8 = 0x01;
const KIND_TRAVEL: u8 = 0x02;
const KIND_RESET: u8 = 0x03;
const KIND_COMPENSATION: u8 = 0x04;
/// Harmonics a [`Message::Compensation`] frame carries.
pub const COMPENSATION_HARMONICS: usize = 6;
const COMPENSATION_LEN: usize = 2 + 10 * COMPENSATION_HARMONICS;
const KIND_OUTPUT: u8 = 0x81;
const KIND_ACK: u8 = 0x82;

/// One controller step's result as the chip reports it: the outputs that
/// drive the hardware in full, the telemetry as a digest (the link is a slow
/// UART; the host recomputes the telemetry and checks the digest).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StepReport {
    /// Timer compare values of phases a, b, c, counts.
    pub pwm_compare: [u16; 3],
    /// Gate drivers enabled.
    pub pwm_enabled: bool,
    /// Brake released.
    pub brake_released: bool,
    /// State after the step.
    pub state: DriveState,
    /// [`telemetry_digest`] of the step's telemetry.
    pub telemetry_digest: u32,
    /// Cost of the step in the chip's cycle counter ticks (SysTick), counts.
    pub cost_ticks: u32,
}

impl StepReport {
    /// The report of `output`, with the cost of the step.
    pub fn new(output: &ControlOutput, cost_ticks: u32) -> Self {
        Self {
            pwm_compare: output.pwm_compare,
            pwm_enabled: output.pwm_enabled,
            brake_released: output.brake_released,
            state: output.state,
            telemetry_digest: telemetry_digest(&output.telemetry),
            cost_ticks,
        }
    }

    /// Whether `output` is bit for bit the output this report describes
    /// (telemetry through its digest; the cost is not part of the output).
    pub fn matches(&self, output: &ControlOutput) -> bool {
        let mut same = Self::new(output, self.cost_ticks);
        same.cost_ticks = self.cost_ticks;
        same == *self
    }
}

/// FNV-1a (32-bit) of the bits of every telemetry value, in field order.
pub fn telemetry_digest(t: &Telemetry) -> u32 {
    let mut hash: u32 = 0x811C_9DC5;
    for value in [
        t.id_a,
        t.iq_a,
        t.iq_ref_a,
        t.speed_radps,
        t.speed_ref_radps,
        t.ref_speed_mps,
        t.angle_rad,
        t.torque_ff_nm,
        t.torque_ref_nm,
    ] {
        for byte in value.to_bits().to_le_bytes() {
            hash ^= byte as u32;
            hash = hash.wrapping_mul(0x0100_0193);
        }
    }
    hash
}

/// A message of the PIL link.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Message {
    /// Host -> chip: the sensor readings of one PWM period; the chip steps.
    Sense(SensorFrame),
    /// Host -> chip: start a travel.
    Travel(TravelCommand),
    /// Host -> chip: clear a latched fault.
    Reset,
    /// Host -> chip: install ripple compensation `strategy` with `table`
    /// (its first [`COMPENSATION_HARMONICS`] harmonics), see
    /// [`crate::Controller::install_compensation`].
    Compensation {
        /// Strategy.
        strategy: Strategy,
        /// Strategy 1's table and the orders, N m.
        table: HarmonicTable,
    },
    /// Chip -> host: the result of a step.
    Output(StepReport),
    /// Chip -> host: reply to `Travel` or `Reset`: 0 accepted, else a refusal code.
    Ack(u8),
}

/// What is wrong with a received frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// The CRC does not match.
    Checksum,
    /// Unknown kind byte.
    UnknownKind(u8),
    /// Payload length wrong for its kind (or above [`MAX_PAYLOAD`]).
    Length {
        /// Kind byte.
        kind: u8,
        /// Received length.
        len: u8,
    },
    /// A field holds a value no encoder writes (state, fault or direction code).
    BadField,
}

/// Reply code of a travel or reset command: 0 accepted, 1 not idle, 2 no
/// profile for the travel, 3 travel outside the rig.
pub fn command_result_code(result: Result<(), CommandError>) -> u8 {
    match result {
        Ok(()) => 0,
        Err(CommandError::NotIdle) => 1,
        Err(CommandError::Profile(_)) => 2,
        Err(CommandError::OutOfRange) => 3,
    }
}

/// The command result of a reply code (see [`command_result_code`]).
pub fn command_result_from_code(code: u8) -> Result<(), CommandError> {
    match code {
        0 => Ok(()),
        1 => Err(CommandError::NotIdle),
        2 => Err(CommandError::Profile(ProfileError::NonPositiveLimit)),
        _ => Err(CommandError::OutOfRange),
    }
}

/// CRC-16/CCITT-FALSE of `bytes`, continuing from `crc` (start: 0xFFFF).
pub fn crc16(mut crc: u16, bytes: &[u8]) -> u16 {
    for &byte in bytes {
        crc ^= (byte as u16) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 { (crc << 1) ^ 0x1021 } else { crc << 1 };
        }
    }
    crc
}

struct Writer<'a> {
    buf: &'a mut [u8; MAX_FRAME],
    at: usize,
}

impl Writer<'_> {
    fn bytes(&mut self, bytes: &[u8]) {
        self.buf[self.at..self.at + bytes.len()].copy_from_slice(bytes);
        self.at += bytes.len();
    }
    fn u8(&mut self, v: u8) {
        self.bytes(&[v]);
    }
    fn u16(&mut self, v: u16) {
        self.bytes(&v.to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.bytes(&v.to_le_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.bytes(&v.to_bits().to_le_bytes());
    }
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> [u8; N] {
        let mut out = [0u8; N];
        out.copy_from_slice(&self.bytes[self.at..self.at + N]);
        self.at += N;
        out
    }
    fn u8(&mut self) -> u8 {
        self.take::<1>()[0]
    }
    fn u16(&mut self) -> u16 {
        u16::from_le_bytes(self.take())
    }
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take())
    }
    fn f32(&mut self) -> f32 {
        f32::from_bits(self.u32())
    }
}

const SENSE_LEN: usize = 3 * 2 + 4 + 2 + 4;
const TRAVEL_LEN: usize = 1 + 3 * 4;
const OUTPUT_LEN: usize = 3 * 2 + 2 + 4 + 4;

fn payload_len(kind: u8) -> Option<usize> {
    match kind {
        KIND_SENSE => Some(SENSE_LEN),
        KIND_TRAVEL => Some(TRAVEL_LEN),
        KIND_RESET => Some(0),
        KIND_COMPENSATION => Some(COMPENSATION_LEN),
        KIND_OUTPUT => Some(OUTPUT_LEN),
        KIND_ACK => Some(1),
        _ => None,
    }
}

/// Encodes `message` into `buf`; returns the frame length, bytes.
pub fn encode(message: &Message, buf: &mut [u8; MAX_FRAME]) -> usize {
    let mut w = Writer { buf, at: 2 };
    let kind = match message {
        Message::Sense(_) => KIND_SENSE,
        Message::Travel(_) => KIND_TRAVEL,
        Message::Reset => KIND_RESET,
        Message::Compensation { .. } => KIND_COMPENSATION,
        Message::Output(_) => KIND_OUTPUT,
        Message::Ack(_) => KIND_ACK,
    };
    w.u8(kind);
    w.u8(payload_len(kind).unwrap_or(0) as u8);
    match message {
        Message::Sense(f) => {
            f.phase_current_codes.iter().for_each(|&c| w.u16(c));
            w.u32(f.encoder_count);
            w.u16(f.dc_bus_code);
            w.u32(f.time_us);
        }
        Message::Travel(t) => {
            w.u8(match t.direction {
                Direction::Up => 0,
                Direction::Down => 1,
            });
            w.f32(t.distance_m);
            w.f32(t.m_car_kg);
            w.f32(t.lw_start_m);
        }
        Message::Reset => {}
        Message::Compensation { strategy, table } => {
            let len = table.len.min(COMPENSATION_HARMONICS);
            w.u8(strategy.code());
            w.u8(len as u8);
            for k in 0..COMPENSATION_HARMONICS {
                let (order, u) = if k < len { (table.orders[k], table.torque_nm[k]) } else { (0, Complex::ZERO) };
                w.u16(order);
                w.f32(u.re);
                w.f32(u.im);
            }
        }
        Message::Output(r) => {
            r.pwm_compare.iter().for_each(|&c| w.u16(c));
            w.u8(r.pwm_enabled as u8 | (r.brake_released as u8) << 1);
            w.u8(r.state.code());
            w.u32(r.telemetry_digest);
            w.u32(r.cost_ticks);
        }
        Message::Ack(code) => w.u8(*code),
    }
    let end = w.at;
    let crc = crc16(0xFFFF, &buf[2..end]);
    buf[0] = SYNC0;
    buf[1] = SYNC1;
    buf[end..end + 2].copy_from_slice(&crc.to_le_bytes());
    end + 2
}

fn parse(kind: u8, payload: &[u8]) -> Result<Message, FrameError> {
    let mut r = Reader { bytes: payload, at: 0 };
    Ok(match kind {
        KIND_SENSE => Message::Sense(SensorFrame {
            phase_current_codes: [r.u16(), r.u16(), r.u16()],
            encoder_count: r.u32(),
            dc_bus_code: r.u16(),
            time_us: r.u32(),
        }),
        KIND_TRAVEL => {
            let direction = match r.u8() {
                0 => Direction::Up,
                1 => Direction::Down,
                _ => return Err(FrameError::BadField),
            };
            Message::Travel(TravelCommand { direction, distance_m: r.f32(), m_car_kg: r.f32(), lw_start_m: r.f32() })
        }
        KIND_RESET => Message::Reset,
        KIND_COMPENSATION => {
            let strategy = Strategy::from_code(r.u8()).ok_or(FrameError::BadField)?;
            let len = r.u8() as usize;
            if len > COMPENSATION_HARMONICS {
                return Err(FrameError::BadField);
            }
            let mut table = HarmonicTable { len, ..HarmonicTable::default() };
            for k in 0..COMPENSATION_HARMONICS {
                let (order, re, im) = (r.u16(), r.f32(), r.f32());
                if k < len {
                    table.orders[k] = order;
                    table.torque_nm[k] = Complex::new(re, im);
                }
            }
            Message::Compensation { strategy, table }
        }
        KIND_OUTPUT => {
            let pwm_compare = [r.u16(), r.u16(), r.u16()];
            let flags = r.u8();
            if flags > 0b11 {
                return Err(FrameError::BadField);
            }
            let state = DriveState::from_code(r.u8()).ok_or(FrameError::BadField)?;
            Message::Output(StepReport {
                pwm_compare,
                pwm_enabled: flags & 1 != 0,
                brake_released: flags & 2 != 0,
                state,
                telemetry_digest: r.u32(),
                cost_ticks: r.u32(),
            })
        }
        KIND_ACK => Message::Ack(r.u8()),
        other => return Err(FrameError::UnknownKind(other)),
    })
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    Sync0,
    Sync1,
    Kind,
    Len,
    Payload,
    CrcLo,
    CrcHi,
}

/// Streaming frame decoder: feed it bytes as they arrive.
#[derive(Clone, Debug)]
pub struct Decoder {
    phase: Phase,
    kind: u8,
    len: usize,
    payload: [u8; MAX_PAYLOAD],
    filled: usize,
    crc_lo: u8,
}

impl Default for Decoder {
    fn default() -> Self {
        Self::new()
    }
}

impl Decoder {
    /// A decoder waiting for a sync pair.
    pub const fn new() -> Self {
        Self { phase: Phase::Sync0, kind: 0, len: 0, payload: [0; MAX_PAYLOAD], filled: 0, crc_lo: 0 }
    }

    /// Takes one byte; returns a message or an error when a frame ends.
    pub fn push(&mut self, byte: u8) -> Option<Result<Message, FrameError>> {
        match self.phase {
            Phase::Sync0 => {
                if byte == SYNC0 {
                    self.phase = Phase::Sync1;
                }
            }
            Phase::Sync1 => {
                self.phase = match byte {
                    SYNC1 => Phase::Kind,
                    SYNC0 => Phase::Sync1,
                    _ => Phase::Sync0,
                }
            }
            Phase::Kind => {
                self.kind = byte;
                self.phase = Phase::Len;
            }
            Phase::Len => {
                let expected = payload_len(self.kind);
                self.len = byte as usize;
                self.filled = 0;
                if expected != Some(self.len) {
                    self.phase = Phase::Sync0;
                    return Some(Err(match expected {
                        None => FrameError::UnknownKind(self.kind),
                        Some(_) => FrameError::Length { kind: self.kind, len: byte },
                    }));
                }
                self.phase = if self.len == 0 { Phase::CrcLo } else { Phase::Payload };
            }
            Phase::Payload => {
                self.payload[self.filled] = byte;
                self.filled += 1;
                if self.filled == self.len {
                    self.phase = Phase::CrcLo;
                }
            }
            Phase::CrcLo => {
                self.crc_lo = byte;
                self.phase = Phase::CrcHi;
            }
            Phase::CrcHi => {
                self.phase = Phase::Sync0;
                let received = u16::from_le_bytes([self.crc_lo, byte]);
                let crc = crc16(crc16(0xFFFF, &[self.kind, self.len as u8]), &self.payload[..self.len]);
                if crc != received {
                    return Some(Err(FrameError::Checksum));
                }
                return Some(parse(self.kind, &self.payload[..self.len]));
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::supervisor::Fault;
    use std::vec::Vec;

    fn messages() -> [Message; 7] {
        let mut table = HarmonicTable::default();
        table.push_cosine(12, 3.5, 0.6, -0.8);
        table.push_cosine(72, 0.5, -1.0, 0.0);
        let output = ControlOutput {
            pwm_compare: [1, 2656, 5312],
            pwm_enabled: true,
            brake_released: false,
            state: DriveState::Tripped(Fault::EncoderImplausible),
            telemetry: Telemetry { id_a: -0.0, iq_a: 12.5, angle_rad: f32::MIN_POSITIVE, ..Telemetry::default() },
        };
        [
            Message::Sense(SensorFrame {
                phase_current_codes: [0, 2048, 4095],
                encoder_count: u32::MAX,
                dc_bus_code: 2048,
                time_us: 123_456_789,
            }),
            Message::Travel(TravelCommand {
                direction: Direction::Down,
                distance_m: 6.6,
                m_car_kg: 70.5,
                lw_start_m: 7.6,
            }),
            Message::Reset,
            Message::Compensation { strategy: Strategy::Learning, table },
            Message::Output(StepReport::new(&output, 987)),
            Message::Ack(0),
            Message::Ack(3),
        ]
    }

    #[test]
    fn every_message_round_trips_bit_for_bit() {
        let mut decoder = Decoder::new();
        for message in messages() {
            let mut buf = [0u8; MAX_FRAME];
            let n = encode(&message, &mut buf);
            let decoded: Vec<_> = buf[..n].iter().filter_map(|&b| decoder.push(b)).collect();
            assert_eq!(decoded, [Ok(message)]);
        }
    }

    #[test]
    fn a_flipped_bit_is_caught_and_the_next_frame_still_decodes() {
        for message in messages() {
            let mut buf = [0u8; MAX_FRAME];
            let n = encode(&message, &mut buf);
            for bit in 0..(n * 8) {
                let mut corrupted = buf;
                corrupted[bit / 8] ^= 1 << (bit % 8);
                let mut decoder = Decoder::new();
                let results: Vec<_> = corrupted[..n].iter().filter_map(|&b| decoder.push(b)).collect();
                assert!(results.iter().all(|r| r.as_ref() != Ok(&message)), "bit {bit} of {message:?} slipped through");
                // A clean frame afterwards decodes (after at most one more frame's bytes).
                let mut stream = [0u8; 2 * MAX_FRAME];
                stream[..n].copy_from_slice(&buf[..n]);
                stream[n..2 * n].copy_from_slice(&buf[..n]);
                let decoded: Vec<_> = stream[..2 * n].iter().filter_map(|&b| decoder.push(b)).collect();
                assert!(decoded.contains(&Ok(message)), "bit {bit}: no recovery");
            }
        }
    }

    #[test]
    fn a_report_matches_only_its_own_output() {
        let output = ControlOutput {
            pwm_compare: [10, 20, 30],
            pwm_enabled: true,
            brake_released: true,
            state: DriveState::Travel,
            telemetry: Telemetry { speed_radps: 6.15, ..Telemetry::default() },
        };
        let report = StepReport::new(&output, 42);
        assert!(report.matches(&output));
        let mut other = output;
        other.telemetry.speed_radps = f32::from_bits(6.15f32.to_bits() + 1); // one ulp
        assert!(!report.matches(&other));
        other = output;
        other.pwm_compare[2] = 31;
        assert!(!report.matches(&other));
    }

    #[test]
    fn crc_matches_the_check_value() {
        assert_eq!(crc16(0xFFFF, b"123456789"), 0x29B1);
    }
}
