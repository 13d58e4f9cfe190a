//! The drive's parameters as one versioned, CRC-checked record: what the
//! firmware keeps in flash across power cycles (the compensation strategy,
//! the learned harmonic table, the car mass of the load weighing, the rotor
//! alignment's encoder offset, the DCP variant) and refuses whole when any
//! check fails.
//!
//! Record layout, little-endian: `magic` ("LDP", 3 bytes), `version` (1),
//! `length` of the body (u16), body, CRC-32 (IEEE 802.3: polynomial
//! 0x04C11DB7 reflected, init and final XOR 0xFFFFFFFF) of everything
//! before it. Body: strategy code (u8), table length n (u8, at most
//! [`MAX_HARMONICS`]), n times (order u16, re f32, im f32 in N m), car mass
//! (f32, kg), encoder offset (u32, counts), DCP variant (u8: 3 or 4; version
//! 2 on; a version 1 record, without it, reads as DCP4). A record is used
//! only if magic, version, length, CRC, strategy code, table length and
//! every value (finite numbers, car mass positive, DCP 3 or 4) check;
//! otherwise the drive runs with its defaults and says why ([`RecordError`]).

use crate::dcp::Mode;

use crate::ripple::complex::Complex;
use crate::ripple::harmonics::{HarmonicTable, MAX_HARMONICS};
use crate::ripple::Strategy;

/// First bytes of a record.
pub const MAGIC: [u8; 3] = *b"LDP";
/// The record version this code reads and writes.
pub const VERSION: u8 = 2;
/// The older version this code still reads (no DCP variant: DCP4).
pub const VERSION_1: u8 = 1;
/// Header bytes (magic, version, body length).
const HEADER: usize = 6;
/// Largest body, bytes.
const MAX_BODY: usize = 2 + MAX_HARMONICS * 10 + 9;
/// Largest record, bytes.
pub const MAX_RECORD: usize = HEADER + MAX_BODY + 4;

/// CRC-32 (IEEE 802.3) of `bytes`.
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for &b in bytes {
        crc ^= b as u32;
        for _ in 0..8 {
            let mask = (crc & 1).wrapping_neg();
            crc = (crc >> 1) ^ (0xEDB8_8320 & mask);
        }
    }
    !crc
}

/// What the drive keeps across power cycles.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveParameters {
    /// The ripple-compensation strategy installed at start-up.
    pub strategy: Strategy,
    /// The harmonic table: learned, or the offline table (N m).
    pub table: HarmonicTable,
    /// Car mass of the load weighing, kg.
    pub m_car_kg: f32,
    /// Encoder count at electrical angle zero from the rotor alignment, counts.
    pub encoder_offset_counts: u32,
    /// The DCP variant the lift controller speaks.
    pub dcp_mode: Mode,
}

/// Why a stored record is refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RecordError {
    /// Shorter than its header and CRC, or than its stated length.
    Truncated,
    /// Not a parameter record.
    Magic,
    /// Written by another version of the firmware.
    Version(u8),
    /// The CRC does not match: corrupted.
    Crc,
    /// The body's length, strategy code, table length or a value is invalid.
    Content,
}

impl DriveParameters {
    /// The record of these parameters; its length in `out`.
    pub fn encode(&self, out: &mut [u8; MAX_RECORD]) -> usize {
        let n = self.table.len.min(MAX_HARMONICS);
        let body_len = 2 + n * 10 + 9;
        out[..3].copy_from_slice(&MAGIC);
        out[3] = VERSION;
        out[4..6].copy_from_slice(&(body_len as u16).to_le_bytes());
        let mut i = HEADER;
        let mut put = |bytes: &[u8]| {
            out[i..i + bytes.len()].copy_from_slice(bytes);
            i += bytes.len();
        };
        put(&[self.strategy.code(), n as u8]);
        for k in 0..n {
            put(&self.table.orders[k].to_le_bytes());
            put(&self.table.torque_nm[k].re.to_le_bytes());
            put(&self.table.torque_nm[k].im.to_le_bytes());
        }
        put(&self.m_car_kg.to_le_bytes());
        put(&self.encoder_offset_counts.to_le_bytes());
        put(&[match self.dcp_mode {
            Mode::Dcp3 => 3,
            Mode::Dcp4 => 4,
        }]);
        let end = HEADER + body_len;
        let crc = crc32(&out[..end]);
        out[end..end + 4].copy_from_slice(&crc.to_le_bytes());
        end + 4
    }

    /// The parameters of a stored record, if every check passes.
    pub fn decode(record: &[u8]) -> Result<Self, RecordError> {
        if record.len() < HEADER + 4 {
            return Err(RecordError::Truncated);
        }
        if record[..3] != MAGIC {
            return Err(RecordError::Magic);
        }
        let version = record[3];
        if version != VERSION && version != VERSION_1 {
            return Err(RecordError::Version(version));
        }
        // The DCP variant byte, from version 2 on.
        let mode_len = if version == VERSION_1 { 0 } else { 1 };
        let body_len = u16::from_le_bytes([record[4], record[5]]) as usize;
        let end = HEADER + body_len;
        if body_len > MAX_BODY {
            return Err(RecordError::Content);
        }
        if record.len() < end + 4 {
            return Err(RecordError::Truncated);
        }
        let stored = u32::from_le_bytes([record[end], record[end + 1], record[end + 2], record[end + 3]]);
        if crc32(&record[..end]) != stored {
            return Err(RecordError::Crc);
        }
        let body = &record[HEADER..end];
        let strategy = Strategy::from_code(body[0]).ok_or(RecordError::Content)?;
        let n = body[1] as usize;
        if n > MAX_HARMONICS || body_len != 2 + n * 10 + 8 + mode_len {
            return Err(RecordError::Content);
        }
        let f32_at = |i: usize| f32::from_le_bytes([body[i], body[i + 1], body[i + 2], body[i + 3]]);
        let mut table = HarmonicTable::default();
        for k in 0..n {
            let at = 2 + k * 10;
            let (re, im) = (f32_at(at + 2), f32_at(at + 6));
            if !(re.is_finite() && im.is_finite()) {
                return Err(RecordError::Content);
            }
            table.orders[k] = u16::from_le_bytes([body[at], body[at + 1]]);
            table.torque_nm[k] = Complex::new(re, im);
        }
        table.len = n;
        let at = 2 + n * 10;
        let m_car_kg = f32_at(at);
        if !(m_car_kg.is_finite() && m_car_kg > 0.0) {
            return Err(RecordError::Content);
        }
        let encoder_offset_counts = u32::from_le_bytes([body[at + 4], body[at + 5], body[at + 6], body[at + 7]]);
        let dcp_mode = match body.get(at + 8).copied() {
            None => Mode::Dcp4,
            Some(3) => Mode::Dcp3,
            Some(4) => Mode::Dcp4,
            Some(_) => return Err(RecordError::Content),
        };
        Ok(Self { strategy, table, m_car_kg, encoder_offset_counts, dcp_mode })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ripple::Strategy;
    use proptest::prelude::{prop_assert, proptest};

    fn sample() -> DriveParameters {
        let mut table = HarmonicTable::zero(&[1, 6, 12, 36, 72]);
        for (k, u) in table.torque_nm.iter_mut().take(5).enumerate() {
            *u = Complex::new(0.1 * k as f32 - 0.2, -1.5 + k as f32);
        }
        DriveParameters {
            strategy: Strategy::Adaptive,
            table,
            m_car_kg: 70.5,
            encoder_offset_counts: 12_345,
            dcp_mode: Mode::Dcp3,
        }
    }

    #[test]
    fn the_crc_is_the_ieee_crc32() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
    }

    #[test]
    fn a_record_round_trips_bit_for_bit() {
        let p = sample();
        let mut buf = [0u8; MAX_RECORD];
        let n = p.encode(&mut buf);
        assert_eq!(n, HEADER + 2 + 5 * 10 + 9 + 4);
        assert_eq!(DriveParameters::decode(&buf[..n]), Ok(p));
        let mut empty = p;
        empty.table = HarmonicTable::default();
        empty.strategy = Strategy::Off;
        let n = empty.encode(&mut buf);
        assert_eq!(DriveParameters::decode(&buf[..n]), Ok(empty));
    }

    #[test]
    fn headers_of_other_records_are_refused_by_name() {
        let mut buf = [0u8; MAX_RECORD];
        let n = sample().encode(&mut buf);
        let mut bad = buf;
        bad[0] = b'X';
        assert_eq!(DriveParameters::decode(&bad[..n]), Err(RecordError::Magic));
        let mut bad = buf;
        bad[3] = 3;
        assert_eq!(DriveParameters::decode(&bad[..n]), Err(RecordError::Version(3)));
        assert_eq!(DriveParameters::decode(&buf[..n - 1]), Err(RecordError::Truncated));
        assert_eq!(DriveParameters::decode(&buf[..5]), Err(RecordError::Truncated));
        // A valid CRC over invalid content: a NaN amplitude.
        let mut bad = buf;
        bad[HEADER + 2 + 2..HEADER + 2 + 6].copy_from_slice(&f32::NAN.to_le_bytes());
        let crc = crc32(&bad[..n - 4]);
        bad[n - 4..n].copy_from_slice(&crc.to_le_bytes());
        assert_eq!(DriveParameters::decode(&bad[..n]), Err(RecordError::Content));
        // A DCP variant other than 3 or 4.
        let mut bad = buf;
        bad[n - 5] = 5;
        let crc = crc32(&bad[..n - 4]);
        bad[n - 4..n].copy_from_slice(&crc.to_le_bytes());
        assert_eq!(DriveParameters::decode(&bad[..n]), Err(RecordError::Content));
    }

    #[test]
    fn a_version_1_record_reads_as_dcp4() {
        // Version 1: the same body without the DCP byte.
        let mut buf = [0u8; MAX_RECORD];
        let n = sample().encode(&mut buf);
        let mut v1 = [0u8; MAX_RECORD];
        v1[..n - 5].copy_from_slice(&buf[..n - 5]);
        v1[3] = VERSION_1;
        let body_len = u16::from_le_bytes([buf[4], buf[5]]) - 1;
        v1[4..6].copy_from_slice(&body_len.to_le_bytes());
        let crc = crc32(&v1[..n - 5]);
        v1[n - 5..n - 1].copy_from_slice(&crc.to_le_bytes());
        let expected = DriveParameters { dcp_mode: Mode::Dcp4, ..sample() };
        assert_eq!(DriveParameters::decode(&v1[..n - 1]), Ok(expected));
    }

    proptest! {
        /// Any one corrupted byte after the version (length, body or CRC;
        /// CRC-32 detects every error burst up to 32 bits) is refused.
        #[test]
        fn a_corrupted_record_is_refused(at in 4usize..72, flip in 1u8..=255) {
            let mut buf = [0u8; MAX_RECORD];
            let n = sample().encode(&mut buf);
            let at = at % n;
            buf[at] ^= flip;
            prop_assert!(DriveParameters::decode(&buf[..n]).is_err());
        }
    }
}
