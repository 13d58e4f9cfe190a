//! Sequences of master messages through the slave, and properties over
//! corrupted and arbitrary messages.

extern crate std;

use std::vec::Vec;

use proptest::prelude::*;

use super::channel::{position_message, POSITION_ANSWER};
use super::command::{command_byte, Kind, Mode, Speed, B7_REPLY_ERROR};
use super::frame::{FrameError, FrameReceiver, MasterFrame, CHARACTER_US, FRAME_GAP_US};
use super::slave::*;

/// Speeds of the reference rig (m/s): V0 crawl 0.05, VN 0.02, VI 0.3, V3 0.3, V4 0.4 (rated).
fn speeds() -> [Option<f32>; 11] {
    let mut s = [None; 11];
    s[Speed::V0.index()] = Some(0.05);
    s[Speed::Vn.index()] = Some(0.02);
    s[Speed::Vi.index()] = Some(0.3);
    s[Speed::V3.index()] = Some(0.3);
    s[Speed::V4.index()] = Some(0.4);
    s
}

fn slave(mode: Mode) -> Slave {
    Slave::new(SlaveConfig::new(mode, speeds(), 6600))
}

fn idle_drive() -> DriveStatus {
    DriveStatus { ready: true, ..DriveStatus::default() }
}

fn moving_drive() -> DriveStatus {
    DriveStatus {
        ready: false,
        travelling: true,
        brake_open: true,
        speed_mps: 0.4,
        braking_distance_mm: 480,
        ..DriveStatus::default()
    }
}

fn frame(kind: Kind, down: bool, data: [u8; 2]) -> MasterFrame {
    MasterFrame { command: command_byte(kind, down), data, comm: [0, 0] }
}

/// A lift controller: sends messages every 15 ms, carrying its channel bytes.
struct Master {
    t_us: u32,
    channel: Vec<u8>,
}

impl Master {
    fn new() -> Self {
        Self { t_us: 1_000, channel: Vec::new() }
    }

    fn send(&mut self, slave: &mut Slave, mut frame: MasterFrame, drive: &DriveStatus) -> Outcome {
        for slot in frame.comm.iter_mut() {
            if !self.channel.is_empty() {
                *slot = self.channel.remove(0);
            }
        }
        self.t_us = self.t_us.wrapping_add(15_000);
        assert_eq!(slave.poll(self.t_us, drive), None, "timed out between messages");
        slave.receive(Ok(frame), self.t_us, drive)
    }
}

/// Enables the drive and gives it position `position_mm`.
fn with_position(slave: &mut Slave, master: &mut Master, position_mm: i32) {
    master.channel.extend_from_slice(&position_message(position_mm));
    let mut answer = Vec::new();
    // 12 bytes in, then 5 bytes of answer out, two per message.
    for _ in 0..9 {
        let out = master.send(slave, frame(Kind::Stop, false, [0, 0]), &idle_drive());
        assert_eq!(out.request, None);
        answer.extend_from_slice(&out.reply.comm);
    }
    assert_eq!(slave.position_mm(), Some(position_mm));
    let start = answer.iter().position(|&b| b != 0).expect("an answer on the channel");
    assert_eq!(&answer[start..start + POSITION_ANSWER.len()], &POSITION_ANSWER);
}

#[test]
fn a_dcp4_travel_passes_its_remaining_distances_on_and_moves_the_position() {
    let mut s = slave(Mode::Dcp4);
    let mut m = Master::new();
    with_position(&mut s, &mut m, 1000);
    let out = m.send(&mut s, frame(Kind::SpeedMode, false, Speed::V4.data()), &idle_drive());
    assert_eq!(out.request, None);
    assert_ne!(out.reply.status & S5_ACCEPTED, 0);
    let out = m.send(&mut s, frame(Kind::Decelerate, false, 2500u16.to_be_bytes()), &idle_drive());
    assert_eq!(
        out.request,
        Some(Request::Distance { direction: Travel::Up, distance_mm: 2500, start_position_mm: 1000 })
    );
    // Running: each remaining distance goes to the drive, accepted; once the
    // drive refuses one (it cannot stop within it), S5 is clear until it
    // takes one again.
    for remaining in (0..2500u16).rev().step_by(100) {
        let out = m.send(&mut s, frame(Kind::Decelerate, false, remaining.to_be_bytes()), &moving_drive());
        assert_eq!(out.reply.status & (S1_TRAVEL | S6_BRAKE_OPEN | S7_MESSAGE_ERROR), S1_TRAVEL | S6_BRAKE_OPEN);
        assert_eq!(out.reply.data, 480u16.to_be_bytes(), "deceleration distance");
        assert_eq!(out.request, Some(Request::Remaining { remaining_mm: remaining }), "{remaining}");
        assert_eq!(out.reply.status & S5_ACCEPTED == 0, (299..=899).contains(&remaining), "{remaining}");
        if remaining == 999 {
            s.refuse_remaining();
        }
        if remaining == 299 {
            s.take_remaining();
        }
    }

    // Arrived, brake set: the master still sends a few mm before clearing the stop switch.
    let out = m.send(&mut s, frame(Kind::Decelerate, false, 3u16.to_be_bytes()), &idle_drive());
    assert_eq!(out.request, None, "a second travel after the arrival");
    assert_eq!(s.position_mm(), Some(3500));
    assert_eq!(m.send(&mut s, frame(Kind::Stop, false, [0, 0]), &idle_drive()).request, None);
    assert_eq!(m.send(&mut s, frame(Kind::Idle, false, [0, 0]), &idle_drive()).request, None);
    // The next travel, down, from the new position.
    m.send(&mut s, frame(Kind::Stop, true, [0, 0]), &idle_drive());
    let out = m.send(&mut s, frame(Kind::Decelerate, true, 3500u16.to_be_bytes()), &idle_drive());
    assert_eq!(
        out.request,
        Some(Request::Distance { direction: Travel::Down, distance_mm: 3500, start_position_mm: 3500 })
    );
}

#[test]
fn distances_out_of_range_get_the_error_answer_and_no_travel() {
    let mut s = slave(Mode::Dcp4);
    let mut m = Master::new();
    with_position(&mut s, &mut m, 1000);
    for (down, distance) in [(false, 0x8000u16), (false, 5601), (true, 1001), (false, 0xFFFF)] {
        let out = m.send(&mut s, frame(Kind::Decelerate, down, distance.to_be_bytes()), &idle_drive());
        assert_eq!(out.request, None, "{distance}");
        assert_ne!(out.reply.status & S7_MESSAGE_ERROR, 0);
        assert_eq!(out.reply.status & S5_ACCEPTED, 0);
        assert_eq!(out.refused, Some(Refusal::Command(super::command::CommandError::DistanceOutOfRange)));
    }
    // The shaft's ends are in range.
    let out = m.send(&mut s, frame(Kind::Decelerate, false, 5600u16.to_be_bytes()), &idle_drive());
    assert!(matches!(out.request, Some(Request::Distance { distance_mm: 5600, .. })));
}

#[test]
fn without_a_position_message_a_distance_travel_is_refused_without_error() {
    let mut s = slave(Mode::Dcp4);
    let mut m = Master::new();
    m.send(&mut s, frame(Kind::Stop, false, [0, 0]), &idle_drive());
    let out = m.send(&mut s, frame(Kind::Decelerate, false, 1000u16.to_be_bytes()), &idle_drive());
    assert_eq!(out.request, None);
    assert_eq!(out.reply.status & (S5_ACCEPTED | S7_MESSAGE_ERROR), 0);
}

#[test]
fn a_drive_that_is_not_ready_gets_no_travel_and_says_so() {
    let mut s = slave(Mode::Dcp4);
    let mut m = Master::new();
    with_position(&mut s, &mut m, 0);
    let not_ready = DriveStatus { ready: false, ..idle_drive() };
    let out = m.send(&mut s, frame(Kind::Decelerate, false, 1000u16.to_be_bytes()), &not_ready);
    assert_eq!(out.request, None);
    assert_eq!(out.reply.status & (S0_READY | S5_ACCEPTED), 0);
}

#[test]
fn a_silent_master_stops_the_travel_safely_and_the_drive_waits_for_an_idle_message() {
    let mut s = slave(Mode::Dcp4);
    let mut m = Master::new();
    with_position(&mut s, &mut m, 0);
    m.send(&mut s, frame(Kind::Decelerate, false, 3000u16.to_be_bytes()), &idle_drive());
    m.send(&mut s, frame(Kind::Decelerate, false, 2990u16.to_be_bytes()), &moving_drive());
    let last = m.t_us;
    let timeout = s.config().timeout_us;
    assert_eq!(s.poll(last + timeout - 1, &moving_drive()), None);
    assert_eq!(s.poll(last + timeout, &moving_drive()), Some(Request::SafeStop(StopReason::Timeout)));
    assert!(s.halted());
    assert_eq!(s.poll(last + 2 * timeout, &idle_drive()), None, "stops once");
    // The master comes back mid-sequence: answered, not ready, no travel.
    m.t_us = last + 2 * timeout;
    let out = m.send(&mut s, frame(Kind::Decelerate, false, 2000u16.to_be_bytes()), &idle_drive());
    assert_eq!(out.request, None);
    assert_eq!(out.reply.status & S0_READY, 0);
    assert_eq!(s.position_mm(), None, "the position is unknown after a safe stop");
    m.send(&mut s, frame(Kind::Idle, false, [0, 0]), &idle_drive());
    assert!(!s.halted());
    with_position(&mut s, &mut m, 2000);
    let out = m.send(&mut s, frame(Kind::Decelerate, true, 2000u16.to_be_bytes()), &idle_drive());
    assert!(matches!(out.request, Some(Request::Distance { direction: Travel::Down, .. })));
}

#[test]
fn bad_messages_do_not_feed_the_watchdog() {
    let mut s = slave(Mode::Dcp4);
    let mut m = Master::new();
    with_position(&mut s, &mut m, 0);
    m.send(&mut s, frame(Kind::Decelerate, false, 3000u16.to_be_bytes()), &idle_drive());
    let start = m.t_us;
    let mut t = start;
    let mut stopped = None;
    while stopped.is_none() {
        t += 10_000;
        let mut bytes = frame(Kind::Decelerate, false, 2000u16.to_be_bytes()).encode();
        bytes[5] ^= 0x40;
        let out = s.receive(MasterFrame::decode(&bytes), t, &moving_drive());
        assert_eq!(out.request, None);
        assert_ne!(out.reply.status & S7_MESSAGE_ERROR, 0);
        stopped = s.poll(t, &moving_drive()).map(|r| (r, t));
    }
    assert_eq!(stopped, Some((Request::SafeStop(StopReason::Timeout), start + 100_000)));
}

#[test]
fn clearing_the_enable_during_a_travel_is_an_interruption() {
    let mut s = slave(Mode::Dcp4);
    let mut m = Master::new();
    with_position(&mut s, &mut m, 0);
    m.send(&mut s, frame(Kind::Decelerate, false, 3000u16.to_be_bytes()), &idle_drive());
    let out = m.send(&mut s, frame(Kind::Idle, false, [0, 0]), &moving_drive());
    assert_eq!(out.request, Some(Request::SafeStop(StopReason::Interrupted)));
}

#[test]
fn a_reversed_direction_or_an_early_stop_switch_stops_the_travel() {
    for spoil in [frame(Kind::Decelerate, true, 2000u16.to_be_bytes()), frame(Kind::Stop, false, [0, 0])] {
        let mut s = slave(Mode::Dcp4);
        let mut m = Master::new();
        with_position(&mut s, &mut m, 0);
        m.send(&mut s, frame(Kind::Decelerate, false, 3000u16.to_be_bytes()), &idle_drive());
        m.send(&mut s, frame(Kind::Decelerate, false, 2900u16.to_be_bytes()), &moving_drive());
        let out = m.send(&mut s, spoil, &moving_drive());
        assert_eq!(out.request, Some(Request::SafeStop(StopReason::Inconsistent)));
    }
}

#[test]
fn a_dcp3_travel_runs_at_the_selected_speed_then_crawls_and_stops_on_command() {
    let mut s = slave(Mode::Dcp3);
    let mut m = Master::new();
    with_position(&mut s, &mut m, 3000);
    let out = m.send(&mut s, frame(Kind::SpeedMode, true, Speed::V3.data()), &idle_drive());
    assert_eq!(out.request, None);
    let out = m.send(&mut s, frame(Kind::Travel, true, [0, 0]), &idle_drive());
    let expected =
        Request::Speed { direction: Travel::Down, speed: Speed::V3, speed_mps: 0.3, start_position_mm: 3000 };
    assert_eq!(out.request, Some(expected));
    assert_eq!(m.send(&mut s, frame(Kind::Travel, true, [0, 0]), &moving_drive()).request, None);
    let out = m.send(&mut s, frame(Kind::Decelerate, true, [0, 0]), &moving_drive());
    assert_eq!(out.request, Some(Request::Crawl { speed_mps: 0.05 }));
    assert_eq!(out.reply.data, [0, 0], "no deceleration distance in DCP3");
    let out = m.send(&mut s, frame(Kind::Stop, true, [0, 0]), &moving_drive());
    assert_eq!(out.request, Some(Request::Stop));
    m.send(&mut s, frame(Kind::Stop, true, [0, 0]), &idle_drive());
    m.send(&mut s, frame(Kind::Idle, true, [0, 0]), &idle_drive());
    // After a speed travel the position is unknown: the next travel waits for it.
    assert_eq!(s.position_mm(), None);
    m.send(&mut s, frame(Kind::SpeedMode, false, Speed::V3.data()), &idle_drive());
    let out = m.send(&mut s, frame(Kind::Travel, false, [0, 0]), &idle_drive());
    assert_eq!(out.request, None);
    assert_eq!(out.reply.status & S5_ACCEPTED, 0);
    m.send(&mut s, frame(Kind::Idle, false, [0, 0]), &idle_drive());
    // Inspection and re-levelling are speed travels too; a speed the drive lacks is a bad speed word.
    with_position(&mut s, &mut m, 2000);
    let out = m.send(&mut s, frame(Kind::SpeedMode, false, Speed::V7.data()), &idle_drive());
    assert_eq!(out.refused, Some(Refusal::Command(super::command::CommandError::BadSpeed)));
    let out = m.send(&mut s, frame(Kind::Relevel, false, [0, 0]), &idle_drive());
    let expected = Request::Speed { direction: Travel::Up, speed: Speed::Vn, speed_mps: 0.02, start_position_mm: 2000 };
    assert_eq!(out.request, Some(expected));
    // Crawl is never faster than the travel's own speed.
    let out = m.send(&mut s, frame(Kind::Decelerate, false, [0, 0]), &moving_drive());
    assert_eq!(out.request, Some(Request::Crawl { speed_mps: 0.02 }));
}

#[test]
fn without_a_crawl_speed_the_deceleration_point_is_the_stop() {
    let mut speeds = speeds();
    speeds[Speed::V0.index()] = None;
    let mut s = Slave::new(SlaveConfig::new(Mode::Dcp3, speeds, 6600));
    let mut m = Master::new();
    with_position(&mut s, &mut m, 1000);
    m.send(&mut s, frame(Kind::SpeedMode, false, Speed::V4.data()), &idle_drive());
    let out = m.send(&mut s, frame(Kind::Travel, false, [0, 0]), &idle_drive());
    assert!(matches!(out.request, Some(Request::Speed { speed: Speed::V4, .. })), "{out:?}");
    let out = m.send(&mut s, frame(Kind::Decelerate, false, [0, 0]), &moving_drive());
    assert_eq!(out.request, Some(Request::Stop));
    // The stop message that follows changes nothing more.
    assert_eq!(m.send(&mut s, frame(Kind::Stop, false, [0, 0]), &moving_drive()).request, None);
}

#[test]
fn a_travel_without_a_selected_speed_is_refused() {
    let mut s = slave(Mode::Dcp3);
    let mut m = Master::new();
    m.send(&mut s, frame(Kind::Stop, false, [0, 0]), &idle_drive());
    let out = m.send(&mut s, frame(Kind::Travel, false, [0, 0]), &idle_drive());
    assert_eq!(out.request, None);
    assert_eq!(out.reply.status & S5_ACCEPTED, 0);
}

#[test]
fn the_reply_error_bit_repeats_the_last_communication_bytes() {
    let mut s = slave(Mode::Dcp4);
    let mut m = Master::new();
    m.channel.extend_from_slice(&position_message(10));
    let mut replies = Vec::new();
    for _ in 0..7 {
        replies.push(m.send(&mut s, frame(Kind::Stop, false, [0, 0]), &idle_drive()).reply.comm);
    }
    let first = replies.iter().position(|c| *c != [0, 0]).unwrap();
    assert_eq!(replies[first], [POSITION_ANSWER[0], POSITION_ANSWER[1]]);
    // The master lost that reply: it sets B7, and gets the same bytes again.
    let mut again = frame(Kind::Stop, false, [0, 0]);
    again.command |= B7_REPLY_ERROR;
    let last = *replies.last().unwrap();
    assert_eq!(m.send(&mut s, again, &idle_drive()).reply.comm, last);
}

#[test]
fn truncated_and_overlong_messages_on_the_line_get_the_error_answer() {
    let mut s = slave(Mode::Dcp4);
    let mut m = Master::new();
    with_position(&mut s, &mut m, 0);
    let travel = frame(Kind::Decelerate, false, 3000u16.to_be_bytes()).encode();
    let mut rx = FrameReceiver::default();
    let mut t = m.t_us + 15_000;
    for bytes in [&travel[..5], &[travel.as_slice(), &[0u8]].concat()[..]] {
        for &b in bytes {
            assert_eq!(rx.push(b, t), None);
            t += CHARACTER_US;
        }
        t += FRAME_GAP_US;
        let received = rx.poll(t).expect("a message");
        assert!(matches!(received, Err(FrameError::Truncated(5) | FrameError::TooLong)));
        let out = s.receive(received, t, &idle_drive());
        assert_eq!(out.request, None);
        assert_ne!(out.reply.status & S7_MESSAGE_ERROR, 0);
    }
}

/// The slave enabled with a known position and V4 selected: one valid
/// message would start a travel.
fn armed() -> (Slave, Master) {
    let mut s = slave(Mode::Dcp4);
    let mut m = Master::new();
    with_position(&mut s, &mut m, 3000);
    m.send(&mut s, frame(Kind::SpeedMode, false, Speed::V4.data()), &idle_drive());
    (s, m)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    /// Any 6 bytes whose checksum fails: the error answer, never a request.
    #[test]
    fn a_message_with_a_wrong_checksum_never_starts_a_travel(bytes in any::<[u8; 6]>()) {
        let body = [bytes[0], bytes[1], bytes[2], bytes[3], bytes[4]];
        prop_assume!(super::frame::checksum(&body) != bytes[5]);
        let (mut s, m) = armed();
        let out = s.receive(MasterFrame::decode(&bytes), m.t_us + 15_000, &idle_drive());
        prop_assert_eq!(out.request, None);
        prop_assert_ne!(out.reply.status & S7_MESSAGE_ERROR, 0);
    }

    /// A travel message with any odd number of bits flipped in any one bit
    /// position across the six bytes (what an XOR checksum always detects):
    /// never a travel.
    #[test]
    fn a_corrupted_travel_message_never_starts_a_travel(
        bit in 0u8..8,
        low in 0u8..32,
        distance in 1u16..3000,
    ) {
        // Bytes 1-5 of `low`, the checksum byte when that count is even: every odd mask.
        let mask = low | if low.count_ones() % 2 == 0 { 1 << 5 } else { 0 };
        let (mut s, m) = armed();
        let mut bytes = frame(Kind::Decelerate, false, distance.to_be_bytes()).encode();
        for (i, byte) in bytes.iter_mut().enumerate() {
            if mask & (1 << i) != 0 {
                *byte ^= 1 << bit;
            }
        }
        let out = s.receive(MasterFrame::decode(&bytes), m.t_us + 15_000, &idle_drive());
        prop_assert_eq!(out.request, None);
        prop_assert_eq!(out.refused, Some(Refusal::Frame(FrameError::Checksum)));
    }

    /// Any byte stream with any timing, cut into messages by the receiver:
    /// every request comes from a message with a valid checksum, and no
    /// distance travel leaves the shaft.
    #[test]
    fn a_random_byte_stream_gives_requests_only_from_valid_messages(
        stream in proptest::collection::vec((any::<u8>(), 0u32..2000), 0..400),
    ) {
        let (mut s, m) = armed();
        let mut rx = FrameReceiver::default();
        let mut t = m.t_us;
        let mut bytes_of_message: Vec<u8> = Vec::new();
        for (byte, gap) in stream {
            t += gap;
            if let Some(received) = rx.push(byte, t) {
                let valid = received.is_ok();
                prop_assert_eq!(valid, bytes_of_message.len() == 6 && {
                    let b = &bytes_of_message;
                    super::frame::checksum(&[b[0], b[1], b[2], b[3], b[4]]) == b[5]
                });
                let out = s.receive(received, t, &idle_drive());
                if let Some(request) = out.request {
                    prop_assert!(valid);
                    if let Request::Distance { direction, distance_mm, start_position_mm } = request {
                        let end = match direction {
                            Travel::Up => start_position_mm + distance_mm as i32,
                            Travel::Down => start_position_mm - distance_mm as i32,
                        };
                        prop_assert!((0..=6600).contains(&end));
                    }
                }
                bytes_of_message.clear();
            }
            bytes_of_message.push(byte);
        }
    }
}
