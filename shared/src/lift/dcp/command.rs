//! The master's command byte and data bytes: which message a frame is.
//!
//! Command bits (L1000A addendum pp. 18-19): B0 drive enable, B1 travel
//! command (DCP3) / change of distance (DCP4), B2 stop switch, B3 speed
//! transfer in the data bytes, B4 direction (0 up, 1 down), B5 speed change
//! (the same meaning as B3, ORed), B6 desired distance instead of actual
//! distance (the addendum's drive does not support it, nor does this one),
//! B7 error in the drive's last reply.
//!
//! Message types by bits B3..B0 with B6 clear (p. 20, the same table for
//! DCP3 and DCP4): `0000` idle, `0001` stop, `0011` re-levelling, `0101`
//! deceleration (DCP3) or remaining distance (DCP4), `0111` travel, `1001`
//! speed mode, `1111` speed mode after a fast start. Every other pattern,
//! and B6 set, is not a DCP message: [`CommandError::Unknown`].
//!
//! Speeds: the data bytes of a speed-mode message carry one bit per speed,
//! G0 V0 crawl, G1 VN re-levelling, G2 VF, G3 V1, G4 VI inspection, G5 V2,
//! G6 V3, G7 V4 fast, G8 V5, G9 V6, G10 V7 (pp. 20-21). The excerpts do not
//! show which data byte holds G0: this drive reads the two bytes as one word,
//! most significant byte first (the order of the remaining distance), bit n
//! being Gn. A word with no bit or more than one bit set is refused. V7, V6,
//! V5, V2 and V1 "are not available with DCP4" (p. 21).

/// Drive enable (B0).
pub const B0_ENABLE: u8 = 1 << 0;
/// Travel command (DCP3) / change of distance (DCP4) (B1).
pub const B1_TRAVEL: u8 = 1 << 1;
/// Stop switch (B2).
pub const B2_STOP_SWITCH: u8 = 1 << 2;
/// Speed transfer in the data bytes (B3).
pub const B3_SPEED: u8 = 1 << 3;
/// Direction: set is down (B4).
pub const B4_DOWN: u8 = 1 << 4;
/// Speed change, ORed with B3 (B5).
pub const B5_SPEED_CHANGE: u8 = 1 << 5;
/// Desired distance instead of actual distance (B6, not supported).
pub const B6_DESIRED_DISTANCE: u8 = 1 << 6;
/// The master found an error in the drive's last reply (B7).
pub const B7_REPLY_ERROR: u8 = 1 << 7;

/// The protocol variant the drive runs, a parameter of the drive.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Speed mode: the lift controller selects speeds and gives the
    /// deceleration point and the stop.
    Dcp3,
    /// Distance mode: the lift controller gives the remaining distance and
    /// the drive plans the travel to it.
    Dcp4,
}

/// A speed of the speed-mode bits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Speed {
    /// G0: V0, crawl.
    V0,
    /// G1: VN, re-levelling.
    Vn,
    /// G2: VF.
    Vf,
    /// G3: V1.
    V1,
    /// G4: VI, inspection.
    Vi,
    /// G5: V2, intermediate 2.
    V2,
    /// G6: V3, intermediate 1.
    V3,
    /// G7: V4, fast.
    V4,
    /// G8: V5.
    V5,
    /// G9: V6.
    V6,
    /// G10: V7.
    V7,
}

impl Speed {
    /// Every speed, in the order of its bit G0..G10.
    pub const ALL: [Speed; 11] = [
        Speed::V0,
        Speed::Vn,
        Speed::Vf,
        Speed::V1,
        Speed::Vi,
        Speed::V2,
        Speed::V3,
        Speed::V4,
        Speed::V5,
        Speed::V6,
        Speed::V7,
    ];

    /// Its bit number n of Gn.
    pub fn bit(self) -> u8 {
        self as u8
    }

    /// The data bytes selecting this speed (most significant first).
    pub fn data(self) -> [u8; 2] {
        (1u16 << self.bit()).to_be_bytes()
    }

    /// Whether DCP `mode` has this speed (DCP4 lacks V7, V6, V5, V2, V1).
    pub fn in_mode(self, mode: Mode) -> bool {
        mode == Mode::Dcp3 || !matches!(self, Speed::V7 | Speed::V6 | Speed::V5 | Speed::V2 | Speed::V1)
    }

    /// Index into a table of speeds ordered as [`Speed::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }
}

/// The message type of a command byte.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// `0000`: drive not enabled.
    Idle,
    /// `0001`: enabled, no travel (also the end of a travel).
    Stop,
    /// `0011`: re-levelling.
    Relevel,
    /// `0101`: deceleration to crawl (DCP3), remaining distance (DCP4).
    Decelerate,
    /// `0111`: travel.
    Travel,
    /// `1001`: speed mode, the speed in the data bytes.
    SpeedMode,
    /// `1111`: speed mode after a fast start.
    FastStartSpeedMode,
}

/// A decoded master command.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Command {
    /// Message type.
    pub kind: Kind,
    /// Travel direction is down (B4).
    pub down: bool,
    /// The master found an error in the drive's last reply (B7).
    pub reply_error: bool,
    /// The two data bytes as one word, most significant first.
    pub data: u16,
}

/// Why a command byte or its data is refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CommandError {
    /// The bit pattern is not one of the DCP messages (or B6 is set).
    Unknown,
    /// The speed word selects no speed, several, or one this mode or drive lacks.
    BadSpeed,
    /// The remaining distance is zero, has bit 15 set (15-bit mode) or leaves the shaft.
    DistanceOutOfRange,
}

impl Command {
    /// The command of a master frame's command and data bytes.
    pub fn decode(command: u8, data: [u8; 2]) -> Result<Self, CommandError> {
        if command & B6_DESIRED_DISTANCE != 0 {
            return Err(CommandError::Unknown);
        }
        // B5 has the meaning of B3 (ORed).
        let speed = (command & (B3_SPEED | B5_SPEED_CHANGE)) != 0;
        let low = (command & 0x07) | if speed { B3_SPEED } else { 0 };
        let kind = match low {
            0b0000 => Kind::Idle,
            0b0001 => Kind::Stop,
            0b0011 => Kind::Relevel,
            0b0101 => Kind::Decelerate,
            0b0111 => Kind::Travel,
            0b1001 => Kind::SpeedMode,
            0b1111 => Kind::FastStartSpeedMode,
            _ => return Err(CommandError::Unknown),
        };
        Ok(Self {
            kind,
            down: command & B4_DOWN != 0,
            reply_error: command & B7_REPLY_ERROR != 0,
            data: u16::from_be_bytes(data),
        })
    }

    /// The speed of a speed-mode word: exactly one bit G0..G10 set, and in `mode`.
    pub fn speed(&self, mode: Mode) -> Result<Speed, CommandError> {
        let word = self.data;
        if word.count_ones() != 1 {
            return Err(CommandError::BadSpeed);
        }
        let speed = *Speed::ALL.get(word.trailing_zeros() as usize).ok_or(CommandError::BadSpeed)?;
        if speed.in_mode(mode) {
            Ok(speed)
        } else {
            Err(CommandError::BadSpeed)
        }
    }

    /// The 15-bit remaining distance, mm (bit 15 set is out of range).
    pub fn remaining_distance_mm(&self) -> Result<u16, CommandError> {
        if self.data & 0x8000 != 0 {
            Err(CommandError::DistanceOutOfRange)
        } else {
            Ok(self.data)
        }
    }
}

/// A command byte for `kind` and direction (B3 for the speed modes).
pub fn command_byte(kind: Kind, down: bool) -> u8 {
    let low = match kind {
        Kind::Idle => 0b0000,
        Kind::Stop => 0b0001,
        Kind::Relevel => 0b0011,
        Kind::Decelerate => 0b0101,
        Kind::Travel => 0b0111,
        Kind::SpeedMode => 0b1001,
        Kind::FastStartSpeedMode => 0b1111,
    };
    low | if down { B4_DOWN } else { 0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_seven_message_types_decode_and_every_other_pattern_is_unknown() {
        let mut known = 0;
        for byte in 0..=255u8 {
            match Command::decode(byte, [0, 1]) {
                Ok(c) => {
                    known += 1;
                    assert_eq!(byte & B6_DESIRED_DISTANCE, 0);
                    // Re-encoding gives back the byte up to B5 (= B3), B7 and the direction.
                    let again = command_byte(c.kind, c.down) | (byte & (B7_REPLY_ERROR | B5_SPEED_CHANGE));
                    let b3 = if byte & B5_SPEED_CHANGE != 0 && byte & B3_SPEED == 0 { B3_SPEED } else { 0 };
                    assert_eq!(again, byte | b3, "{byte:#010b}");
                }
                Err(e) => assert_eq!(e, CommandError::Unknown),
            }
        }
        // B5 clear: 7 patterns of B3..B0; B5 set: B2..B0 `001` or `111` with
        // B3 either way; each with B4 and B7 either way.
        assert_eq!(known, (7 + 2 * 2) * 2 * 2);
        assert_eq!(Command::decode(0x07, [0, 0]).unwrap().kind, Kind::Travel);
        assert_eq!(Command::decode(0x05 | B4_DOWN, [0, 0]).unwrap().kind, Kind::Decelerate);
        assert_eq!(Command::decode(0x05 | B6_DESIRED_DISTANCE, [0, 0]), Err(CommandError::Unknown));
        assert_eq!(Command::decode(0x02, [0, 0]), Err(CommandError::Unknown), "travel without enable");
    }

    #[test]
    fn a_speed_word_needs_exactly_one_bit_of_the_mode() {
        let decode = |data: [u8; 2], mode| Command::decode(0x09, data).unwrap().speed(mode);
        for speed in Speed::ALL {
            assert_eq!(decode(speed.data(), Mode::Dcp3), Ok(speed));
            let dcp4 = decode(speed.data(), Mode::Dcp4);
            assert_eq!(dcp4.is_ok(), !matches!(speed, Speed::V1 | Speed::V2 | Speed::V5 | Speed::V6 | Speed::V7));
        }
        assert_eq!(decode([0, 0], Mode::Dcp3), Err(CommandError::BadSpeed));
        assert_eq!(decode([0, 0b11], Mode::Dcp3), Err(CommandError::BadSpeed));
        assert_eq!(decode([0x08, 0], Mode::Dcp3), Err(CommandError::BadSpeed), "G11 does not exist");
        assert_eq!(Speed::V4.data(), [0x00, 0x80]);
        assert_eq!(Speed::V5.data(), [0x01, 0x00]);
    }

    #[test]
    fn a_remaining_distance_with_bit_15_is_out_of_range() {
        let c = Command::decode(0x05, [0x7F, 0xFF]).unwrap();
        assert_eq!(c.remaining_distance_mm(), Ok(32_767));
        let c = Command::decode(0x05, [0x80, 0x00]).unwrap();
        assert_eq!(c.remaining_distance_mm(), Err(CommandError::DistanceOutOfRange));
    }
}
