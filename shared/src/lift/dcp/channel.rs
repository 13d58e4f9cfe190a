//! The communication channel of DCP: the text carried two bytes per message
//! in the communication bytes, beside the process data.
//!
//! Framing (L1000A addendum pp. 28-33): null bytes while idle, a message is
//! `STX` (0x02) ... `ETX` (0x03); `STX 1C 'I' <n> ...` are the
//! information messages. This drive understands one of them, the position
//! message `STX 1C 'I' '9' SIGN P1..P6 ETX`, which the lift controller
//! sends "after each stop, while the drive is stationary": the car position
//! in mm from the lowest floor level, SIGN `'+'`, `'-'` or `'E'` (invalid)
//! (p. 33). The drive answers it with the base protocol's
//! `STX 1C 'I' '9' ETX` (the extended answer with the measured travel is not
//! implemented). Other messages are received and ignored (the public texts
//! do not say what a drive that lacks a message answers; this one answers
//! nothing).

/// Start of a channel message.
pub const STX: u8 = 0x02;
/// End of a channel message.
pub const ETX: u8 = 0x03;
/// The control character of the information messages (`STX 1C 'I' ...`).
pub const INFO: u8 = 0x1C;

/// Longest channel message body this drive receives (between STX and ETX), bytes.
pub const MAX_MESSAGE: usize = 16;

/// A channel message the drive understood.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChannelMessage {
    /// The position message: car position from the lowest floor level, mm
    /// (`None`: the master marked it invalid with `'E'`).
    Position(Option<i32>),
}

/// Assembles channel messages from the communication bytes of master messages.
#[derive(Clone, Copy, Debug, Default)]
pub struct ChannelReceiver {
    body: [u8; MAX_MESSAGE],
    len: usize,
    inside: bool,
    overflow: bool,
}

impl ChannelReceiver {
    /// One received communication byte; a complete message it understood, if any.
    pub fn push(&mut self, byte: u8) -> Option<ChannelMessage> {
        match byte {
            STX => {
                self.inside = true;
                self.len = 0;
                self.overflow = false;
                None
            }
            ETX if self.inside => {
                self.inside = false;
                if self.overflow {
                    None
                } else {
                    parse(&self.body[..self.len])
                }
            }
            _ if self.inside => {
                if self.len < MAX_MESSAGE {
                    self.body[self.len] = byte;
                    self.len += 1;
                } else {
                    self.overflow = true;
                }
                None
            }
            // Null bytes and anything outside STX..ETX.
            _ => None,
        }
    }
}

fn parse(body: &[u8]) -> Option<ChannelMessage> {
    match body {
        [INFO, b'I', b'9', sign, digits @ ..] if digits.len() == 6 => {
            let mut value: i32 = 0;
            for &d in digits {
                if !d.is_ascii_digit() {
                    return None;
                }
                value = value * 10 + (d - b'0') as i32;
            }
            match sign {
                b'+' => Some(ChannelMessage::Position(Some(value))),
                b'-' => Some(ChannelMessage::Position(Some(-value))),
                b'E' => Some(ChannelMessage::Position(None)),
                _ => None,
            }
        }
        _ => None,
    }
}

/// The position message of the lift controller for `position_mm` (|position| < 10^6 mm).
pub fn position_message(position_mm: i32) -> [u8; 12] {
    let mut out = [STX, INFO, b'I', b'9', if position_mm < 0 { b'-' } else { b'+' }, 0, 0, 0, 0, 0, 0, ETX];
    let mut v = position_mm.unsigned_abs().min(999_999);
    for slot in out[5..11].iter_mut().rev() {
        *slot = b'0' + (v % 10) as u8;
        v /= 10;
    }
    out
}

/// The drive's answer to a position message (base protocol).
pub const POSITION_ANSWER: [u8; 5] = [STX, INFO, b'I', b'9', ETX];

/// Bytes waiting to go out, two per slave message; null bytes when empty.
#[derive(Clone, Copy, Debug, Default)]
pub struct ChannelSender {
    queue: [u8; MAX_MESSAGE],
    head: usize,
    len: usize,
}

impl ChannelSender {
    /// Queues a message; false (and nothing queued) when it does not fit.
    pub fn send(&mut self, bytes: &[u8]) -> bool {
        if bytes.len() > MAX_MESSAGE - self.len {
            return false;
        }
        for &b in bytes {
            self.queue[(self.head + self.len) % MAX_MESSAGE] = b;
            self.len += 1;
        }
        true
    }

    /// The next two communication bytes (null bytes when idle).
    pub fn next_pair(&mut self) -> [u8; 2] {
        let mut pair = [0u8; 2];
        for slot in pair.iter_mut() {
            if self.len > 0 {
                *slot = self.queue[self.head];
                self.head = (self.head + 1) % MAX_MESSAGE;
                self.len -= 1;
            }
        }
        pair
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_position_message_two_bytes_at_a_time_is_understood() {
        for position in [0, 1, 2500, 999_999, -1234] {
            let bytes = position_message(position);
            let mut rx = ChannelReceiver::default();
            let mut got = None;
            for pair in bytes.chunks(2) {
                for &b in pair {
                    if let Some(m) = rx.push(b) {
                        got = Some(m);
                    }
                }
            }
            assert_eq!(got, Some(ChannelMessage::Position(Some(position))));
        }
    }

    #[test]
    fn invalid_and_unknown_messages_are_not_positions() {
        let mut rx = ChannelReceiver::default();
        let mut feed = |bytes: &[u8]| bytes.iter().filter_map(|&b| rx.push(b)).last();
        assert_eq!(
            feed(&[STX, INFO, b'I', b'9', b'E', b'0', b'0', b'0', b'0', b'0', b'0', ETX]),
            Some(ChannelMessage::Position(None))
        );
        assert_eq!(feed(&[STX, INFO, b'I', b'9', b'+', b'0', b'0', b'0', b'x', b'0', b'0', ETX]), None);
        assert_eq!(feed(&[STX, INFO, b'I', b'9', b'+', b'0', b'0', b'0', ETX]), None, "short");
        assert_eq!(feed(&[STX, INFO, b'I', b'8', b'5', b'0', ETX]), None);
        assert_eq!(feed(&[STX; 1]), None);
        assert_eq!(feed(&[b'A'; 40]), None, "overflow");
        assert_eq!(feed(&[ETX]), None);
        // A new STX restarts: the message after garbage is still understood.
        let ok = position_message(42);
        assert_eq!(feed(&ok), Some(ChannelMessage::Position(Some(42))));
    }

    #[test]
    fn the_sender_pads_with_null_bytes_and_refuses_what_does_not_fit() {
        let mut tx = ChannelSender::default();
        assert_eq!(tx.next_pair(), [0, 0]);
        assert!(tx.send(&POSITION_ANSWER));
        assert_eq!(tx.next_pair(), [STX, INFO]);
        assert_eq!(tx.next_pair(), [b'I', b'9']);
        assert_eq!(tx.next_pair(), [ETX, 0]);
        assert!(!tx.send(&[0u8; MAX_MESSAGE + 1]));
        assert_eq!(tx.next_pair(), [0, 0]);
    }
}
