//! The drive's side of DCP: answers every master message, turns valid
//! commands into requests to the drive, and stops the drive safely when the
//! master falls silent.
//!
//! The slave only answers: each received message (or each bad one) gets
//! exactly one reply, built from the drive's status at that moment
//! ([`DriveStatus`]). What the master commands comes out as a [`Request`]
//! that the application applies to the controller; the slave learns whether
//! the drive took it from the status of the next message.
//!
//! Bad messages ([`super::frame::FrameError`], an unknown command byte, a
//! bad speed word, a remaining distance out of range) get the error answer:
//! the current status with S7 set ("error in last message received", the
//! L1000A addendum's answer to a checksum error, p. 34; the public texts do
//! not give a separate answer for the other errors, so they get the same),
//! S5 ("accepted") clear, and never a request. Their communication bytes are
//! dropped: the master repeats its message after S7.
//!
//! Timeout watchdog ("the control equipment must be equipped with a timeout
//! watchdog. When the timeout time elapses, the system will automatically
//! switch to a safe condition", Dynavert L DCP description 4BS0449-005,
//! section 2): only valid messages feed it. When it expires with the drive
//! enabled, the slave requests [`Request::SafeStop`] and refuses every
//! travel until the master sends an idle message (B0 clear). The excerpts
//! found give no value for the timeout; [`SlaveConfig::timeout_us`] is a
//! parameter, by default 100 ms (about six message cycles of a lift
//! controller polling every 15 ms, and 1/20 of a second of travel at
//! rated speed on the reference rig: 20 mm).
//!
//! Sequences (L1000A addendum pp. 18-20):
//! - DCP4 distance travel: the master sends the remaining distance
//!   (`0101`, mm, 15 bits) with the stop switch B2 on from the start; the
//!   drive plans its own profile and stops with the brake applied at 0 mm;
//!   then the master clears B2 (`0001`) and B0 (`0000`). Later remaining
//!   distances (the master repeats it in every message, measured on its own
//!   shaft encoder: after rope slip it differs from the drive's plan) are
//!   passed on ([`Request::Remaining`]): the drive plans the rest of the
//!   travel again when the target moved (within its acceleration and jerk
//!   limits, never past the new target). A remaining distance the car
//!   cannot stop within from its reference is refused by the drive, which
//!   tells the slave ([`Slave::refuse_remaining`]): the travel goes on to
//!   the target it had, and S5 ("accepted") is clear in the replies from
//!   the next one on until a remaining distance is taken again (the reply
//!   to the refused message itself is sent before the drive has judged it). The drive's position after the travel is the target of the first
//!   remaining distance: after rope slip the master's later distances lead
//!   to that same floor in its own coordinate; a master that changes the
//!   destination sends the position message after the stop, as after every
//!   stop.
//! - DCP3 speed travel: speed mode (`1001`, the speed bit), travel (`0111`),
//!   at the deceleration point B1 cleared (`0101`: slow down to V0 crawl), at
//!   the floor B2 cleared (`0001`: stop), then B0 cleared. Re-levelling
//!   (`0011`) is a travel at VN. The crawl is requested once per travel
//!   phase the master enters (it repeats its message; the drive ignores a
//!   crawl it already runs at); a travel slower than V0 keeps its speed;
//!   without a V0 the deceleration point is the stop (short of the floor
//!   rather than past it).
//! - B0 cleared during a travel is a travel interruption: safe stop.
//!   So is, conservatively, a reversed direction or a cleared stop switch
//!   before a distance travel has arrived (the texts do not cover them).
//!
//! Faults: DCP has no fault-reset command (the L1000A addendum's command
//! bits B0..B7 are all taken, none is a reset; its fault bit S3 tells the
//! master to clear B0 and wait until the fault is cleared on the drive's
//! side, p. 21). No message clears a latched fault here: an idle message
//! (B0 clear) only disables the slave, since taking it as a reset would
//! clear every fault at once. The master sends idle messages until S3
//! clears and S0 returns; the fault is cleared on the drive's service port.
//!
//! Position: the master sends the car position after each stop (channel
//! message `I9`, see [`super::channel`]); a distance or speed travel needs
//! it (the drive derives its rope lengths and the shaft limits from it), so
//! until the first one arrives travels are refused (answered, S5 clear). A distance travel's
//! arrival moves the drive's position to its target; a speed travel or a
//! safe stop forgets it until the next position message.

use super::channel::{ChannelMessage, ChannelReceiver, ChannelSender, POSITION_ANSWER};
use super::command::{Command, CommandError, Kind, Mode, Speed};
use super::frame::{FrameError, MasterFrame, SlaveFrame};

/// Drive ready (S0).
pub const S0_READY: u8 = 1 << 0;
/// Travel active (S1).
pub const S1_TRAVEL: u8 = 1 << 1;
/// Stop switch (S2): its meaning in the public text is unclear; this drive never sets it.
pub const S2_STOP_SWITCH: u8 = 1 << 2;
/// Fault active (S3).
pub const S3_FAULT: u8 = 1 << 3;
/// Speed below the levelling speed (S4).
pub const S4_BELOW_LEVELLING: u8 = 1 << 4;
/// Distance or speed accepted (S5).
pub const S5_ACCEPTED: u8 = 1 << 5;
/// Mechanical brake open (S6).
pub const S6_BRAKE_OPEN: u8 = 1 << 6;
/// Error in the last message received (S7).
pub const S7_MESSAGE_ERROR: u8 = 1 << 7;

/// Largest 15-bit distance, mm.
pub const MAX_DISTANCE_MM: u16 = 0x7FFF;

/// Parameters of the DCP slave.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SlaveConfig {
    /// DCP3 (speed mode) or DCP4 (distance mode).
    pub mode: Mode,
    /// Time without a valid message after which an enabled drive is
    /// stopped safely, us.
    pub timeout_us: u32,
    /// Car speed of each speed bit G0..G10 (order of [`Speed::ALL`]), m/s;
    /// `None`: this drive does not offer it (refused as a bad speed word).
    pub speeds_mps: [Option<f32>; 11],
    /// Travel from the lowest to the highest landing, mm: no distance
    /// travel may leave `0..=shaft_travel_mm`.
    pub shaft_travel_mm: u32,
    /// Car speed under which S4 ("below levelling speed") is set, m/s.
    pub levelling_speed_mps: f32,
}

impl SlaveConfig {
    /// A configuration with the default timeout (100 ms) and the levelling
    /// threshold of the L1000A addendum (0.3 m/s, p. 22).
    pub fn new(mode: Mode, speeds_mps: [Option<f32>; 11], shaft_travel_mm: u32) -> Self {
        Self { mode, timeout_us: 100_000, speeds_mps, shaft_travel_mm, levelling_speed_mps: 0.3 }
    }
}

/// What the drive reports to the slave at each message.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DriveStatus {
    /// Ready for a travel: calibrated, rotor aligned, no fault, idle.
    pub ready: bool,
    /// A travel is running (inverter on or brake open).
    pub travelling: bool,
    /// A fault is latched (inverter off, brake applied).
    pub fault: bool,
    /// The brake is open (lifted).
    pub brake_open: bool,
    /// Car speed magnitude, m/s.
    pub speed_mps: f32,
    /// Distance the car needs to stop from its current speed, mm.
    pub braking_distance_mm: u16,
}

/// Travel direction of a request.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Travel {
    /// Car up (B4 clear).
    Up,
    /// Car down (B4 set).
    Down,
}

/// Why the slave stops the drive safely.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StopReason {
    /// No valid message for [`SlaveConfig::timeout_us`].
    Timeout,
    /// B0 cleared during a travel.
    Interrupted,
    /// A command contradicting the running travel (direction, stop switch).
    Inconsistent,
}

/// What the master asked the drive to do.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Request {
    /// A distance travel (DCP4) of `distance_mm` from `start_position_mm`
    /// (mm above the lowest landing).
    Distance {
        /// Direction.
        direction: Travel,
        /// Travel distance, mm (> 0).
        distance_mm: u16,
        /// Car position at the start, mm above the lowest landing.
        start_position_mm: i32,
    },
    /// A speed travel (DCP3, or inspection and re-levelling) from
    /// `start_position_mm` (mm above the lowest landing).
    Speed {
        /// Direction.
        direction: Travel,
        /// The selected speed.
        speed: Speed,
        /// Its car speed, m/s.
        speed_mps: f32,
        /// Car position at the start, mm above the lowest landing.
        start_position_mm: i32,
    },
    /// Slow down to crawl speed V0 (DCP3 deceleration point), or stay at
    /// the travel's speed if that is lower.
    Crawl {
        /// The car speed to go on at, m/s.
        speed_mps: f32,
    },
    /// The running distance travel's remaining distance, as the master
    /// measures it, mm from the car to the target (DCP4 `0101` during the travel).
    Remaining {
        /// Remaining distance, mm.
        remaining_mm: u16,
    },
    /// Stop at the floor from crawl, brake applied (DCP3 stop).
    Stop,
    /// Stop now: inverter off, brake applied.
    SafeStop(StopReason),
}

/// Why a message got the error answer (for logs and tests).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    /// The bytes are not a message.
    Frame(FrameError),
    /// The command or its data is not valid.
    Command(CommandError),
}

/// One reply and what to do.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Outcome {
    /// The reply to send.
    pub reply: SlaveFrame,
    /// What the drive must do, if anything.
    pub request: Option<Request>,
    /// Why the message got the error answer, if it did.
    pub refused: Option<Refusal>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Phase {
    /// B0 clear (or power-up): no travel.
    Disabled,
    /// B0 set, no travel.
    Enabled,
    /// A distance travel requested (`started` once the drive showed it running).
    Distance { direction: Travel, target_mm: i32, started: bool },
    /// A speed travel requested or running at `speed_mps` (m/s).
    SpeedTravel { direction: Travel, started: bool, speed_mps: f32 },
    /// Stopping at the end of a speed travel.
    Stopping,
    /// A travel ended or was refused: no new travel before a stop or idle message.
    Done,
    /// Safe-stopped: travels refused until an idle message.
    Halted,
}

/// The DCP slave state machine.
#[derive(Clone, Copy, Debug)]
pub struct Slave {
    config: SlaveConfig,
    phase: Phase,
    selected: Option<Speed>,
    accepted: bool,
    /// The drive refused the latest remaining distance passed on.
    remaining_refused: bool,
    position_mm: Option<i32>,
    last_valid_us: u32,
    channel_rx: ChannelReceiver,
    channel_tx: ChannelSender,
    last_comm: [u8; 2],
}

impl Slave {
    /// A slave, disabled, position unknown.
    pub fn new(config: SlaveConfig) -> Self {
        Self {
            config,
            phase: Phase::Disabled,
            selected: None,
            accepted: false,
            remaining_refused: false,
            position_mm: None,
            last_valid_us: 0,
            channel_rx: ChannelReceiver::default(),
            channel_tx: ChannelSender::default(),
            last_comm: [0; 2],
        }
    }

    /// The parameters.
    pub fn config(&self) -> &SlaveConfig {
        &self.config
    }

    /// The car position the drive knows, mm above the lowest landing.
    pub fn position_mm(&self) -> Option<i32> {
        self.position_mm
    }

    /// Whether the slave has stopped the drive and waits for an idle message.
    pub fn halted(&self) -> bool {
        self.phase == Phase::Halted
    }

    /// Checks the timeout at `now_us`; a safe stop when it has expired with the drive enabled.
    pub fn poll(&mut self, now_us: u32, drive: &DriveStatus) -> Option<Request> {
        if matches!(self.phase, Phase::Disabled | Phase::Halted) {
            return None;
        }
        if now_us.wrapping_sub(self.last_valid_us) < self.config.timeout_us {
            return None;
        }
        Some(self.halt(StopReason::Timeout, drive))
    }

    fn halt(&mut self, reason: StopReason, _drive: &DriveStatus) -> Request {
        self.phase = Phase::Halted;
        self.selected = None;
        self.accepted = false;
        self.position_mm = None;
        Request::SafeStop(reason)
    }

    /// A message (or the error of one) received at `now_us`, with the drive's status.
    pub fn receive(&mut self, received: Result<MasterFrame, FrameError>, now_us: u32, drive: &DriveStatus) -> Outcome {
        self.track(drive);
        let frame = match received {
            Ok(frame) => frame,
            Err(e) => return self.error_answer(Refusal::Frame(e), drive),
        };
        let command = match Command::decode(frame.command, frame.data) {
            Ok(c) => c,
            Err(e) => return self.error_answer(Refusal::Command(e), drive),
        };
        let request = match self.command(&command, drive) {
            Ok(request) => request,
            Err(e) => return self.error_answer(Refusal::Command(e), drive),
        };
        self.last_valid_us = now_us;
        for byte in frame.comm {
            if let Some(ChannelMessage::Position(position)) = self.channel_rx.push(byte) {
                // Only while stationary, as the position message is defined.
                if !drive.travelling && !matches!(self.phase, Phase::Distance { .. } | Phase::SpeedTravel { .. }) {
                    self.position_mm = position.filter(|p| (0..=self.config.shaft_travel_mm as i32).contains(p));
                }
                // Queued whether or not the position was usable: the base
                // protocol's answer carries no result.
                self.channel_tx.send(&POSITION_ANSWER);
            }
        }
        let comm = if command.reply_error { self.last_comm } else { self.channel_tx.next_pair() };
        self.last_comm = comm;
        Outcome { reply: self.reply(drive, false, comm), request, refused: None }
    }

    /// Follows the drive: a requested travel that started, or ended, or never started.
    fn track(&mut self, drive: &DriveStatus) {
        let (started, target) = match self.phase {
            Phase::Distance { started, target_mm, .. } => (started, Some(target_mm)),
            Phase::SpeedTravel { started, .. } => (started, None),
            Phase::Stopping if !drive.travelling => {
                // Where a speed travel ends is the master's business: forget the position.
                self.phase = Phase::Done;
                self.position_mm = None;
                return;
            }
            _ => return,
        };
        if drive.travelling {
            match &mut self.phase {
                Phase::Distance { started, .. } | Phase::SpeedTravel { started, .. } => *started = true,
                _ => {}
            }
            return;
        }
        // Ended (or refused by the drive: never started).
        if started && !drive.fault {
            self.position_mm = target;
        } else {
            self.accepted = false;
            if started {
                self.position_mm = None;
            }
        }
        self.phase = Phase::Done;
    }

    /// A travel (or relevelling) command at rest: the speed travel at the
    /// selected speed (relevelling: Vn), when the speed is configured, the
    /// position known and the drive ready; otherwise refused (S5 clear).
    fn speed_travel(&mut self, c: &Command, direction: Travel, drive: &DriveStatus) -> Option<Request> {
        let speed = if c.kind == Kind::Relevel { Some(Speed::Vn) } else { self.selected };
        let Some((speed, speed_mps)) = speed.and_then(|s| Some((s, self.config.speeds_mps[s.index()]?))) else {
            self.accepted = false;
            return None;
        };
        // The drive's rope lengths (feed-forward) and shaft ends need the position.
        let Some(start_position_mm) = self.position_mm else {
            self.accepted = false;
            return None;
        };
        if !drive.ready {
            self.accepted = false;
            return None;
        }
        self.accepted = true;
        self.phase = Phase::SpeedTravel { direction, started: false, speed_mps };
        Some(Request::Speed { direction, speed, speed_mps, start_position_mm })
    }

    /// A remaining distance during a distance travel towards `target_mm`.
    /// One that puts the car outside the shaft (seen from the target) is
    /// out of range.
    fn remaining(&mut self, direction: Travel, target_mm: i32, remaining_mm: u16) -> Result<Request, CommandError> {
        let remaining = remaining_mm as i32;
        let beyond = match direction {
            Travel::Up => target_mm - remaining < 0,
            Travel::Down => target_mm + remaining > self.config.shaft_travel_mm as i32,
        };
        if beyond {
            return Err(CommandError::DistanceOutOfRange);
        }
        // Whether the car can stop within it, the drive decides
        // ([`Slave::refuse_remaining`] when it cannot): until it
        // takes one again, S5 stays as it said.
        self.accepted = !self.remaining_refused;
        Ok(Request::Remaining { remaining_mm })
    }

    fn command(&mut self, c: &Command, drive: &DriveStatus) -> Result<Option<Request>, CommandError> {
        let direction = if c.down { Travel::Down } else { Travel::Up };
        // Range checks first: a bad value is an error answer in any phase.
        let speed = match c.kind {
            Kind::SpeedMode | Kind::FastStartSpeedMode => Some(self.speed(c)?),
            _ => None,
        };
        let distance = match (c.kind, self.config.mode, self.phase) {
            (Kind::Decelerate, Mode::Dcp4, Phase::Disabled | Phase::Enabled | Phase::Distance { .. } | Phase::Done) => {
                Some(c.remaining_distance_mm()?)
            }
            _ => None,
        };
        if c.kind == Kind::Idle {
            let travelling = matches!(self.phase, Phase::Distance { .. } | Phase::SpeedTravel { .. } | Phase::Stopping)
                || drive.travelling;
            if travelling && self.phase != Phase::Halted {
                return Ok(Some(self.halt(StopReason::Interrupted, drive)));
            }
            self.phase = Phase::Disabled;
            self.selected = None;
            return Ok(None);
        }
        if self.phase == Phase::Halted {
            // Enabled commands are answered (not ready) but not acted on.
            return Ok(None);
        }
        if self.phase == Phase::Disabled {
            self.phase = Phase::Enabled;
        }
        match (c.kind, self.phase) {
            (Kind::SpeedMode, Phase::Enabled) => {
                self.selected = speed;
                self.accepted = true;
                Ok(None)
            }
            // A speed change during a travel and the fast start are not offered.
            (Kind::SpeedMode | Kind::FastStartSpeedMode, _) => {
                self.accepted = false;
                Ok(None)
            }
            (Kind::Travel | Kind::Relevel, Phase::Enabled) => Ok(self.speed_travel(c, direction, drive)),
            (Kind::Travel | Kind::Relevel, Phase::SpeedTravel { direction: running, .. }) => {
                if running != direction {
                    return Ok(Some(self.halt(StopReason::Inconsistent, drive)));
                }
                Ok(None)
            }
            (Kind::Decelerate, Phase::SpeedTravel { direction: running, speed_mps, .. }) => {
                if running != direction {
                    return Ok(Some(self.halt(StopReason::Inconsistent, drive)));
                }
                // Without a crawl speed, the deceleration point is the stop:
                // short of the floor rather than past it.
                match self.config.speeds_mps[Speed::V0.index()] {
                    Some(crawl) => Ok(Some(Request::Crawl { speed_mps: crawl.min(speed_mps) })),
                    None => {
                        self.phase = Phase::Stopping;
                        Ok(Some(Request::Stop))
                    }
                }
            }
            (Kind::Decelerate, Phase::Enabled) if self.config.mode == Mode::Dcp4 => {
                let distance_mm = distance.unwrap_or(0);
                self.distance_travel(direction, distance_mm, drive)
            }
            (Kind::Decelerate, Phase::Distance { direction: running, target_mm, .. }) => {
                if running != direction {
                    return Ok(Some(self.halt(StopReason::Inconsistent, drive)));
                }
                // Range-checked above.
                self.remaining(direction, target_mm, distance.unwrap_or(0)).map(Some)
            }
            (Kind::Stop, Phase::Distance { started, .. }) => {
                if drive.travelling || !started {
                    // Stop switch off before the arrival.
                    return Ok(Some(self.halt(StopReason::Inconsistent, drive)));
                }
                self.phase = Phase::Enabled;
                Ok(None)
            }
            (Kind::Stop, Phase::SpeedTravel { .. }) => {
                self.phase = Phase::Stopping;
                Ok(Some(Request::Stop))
            }
            (Kind::Stop, Phase::Done) => {
                self.phase = Phase::Enabled;
                Ok(None)
            }
            (Kind::Stop, _) => Ok(None),
            // After a travel: answered, not acted on, until a stop message.
            (_, Phase::Done) => Ok(None),
            // Deceleration from rest in DCP3, or anything while stopping:
            // answered, not acted on.
            _ => {
                self.accepted = false;
                Ok(None)
            }
        }
    }

    /// The drive refused the latest remaining distance passed on (it cannot
    /// stop within it): S5 clear in the replies until
    /// [`Slave::take_remaining`] says it took one again.
    pub fn refuse_remaining(&mut self) {
        if matches!(self.phase, Phase::Distance { .. }) {
            self.accepted = false;
            self.remaining_refused = true;
        }
    }

    /// The drive took the latest remaining distance passed on: S5 set again.
    pub fn take_remaining(&mut self) {
        if matches!(self.phase, Phase::Distance { .. }) {
            self.remaining_refused = false;
        }
    }

    fn speed(&self, c: &Command) -> Result<Speed, CommandError> {
        let speed = c.speed(self.config.mode)?;
        if self.config.speeds_mps[speed.index()].is_none() {
            return Err(CommandError::BadSpeed);
        }
        Ok(speed)
    }

    fn distance_travel(
        &mut self,
        direction: Travel,
        distance_mm: u16,
        drive: &DriveStatus,
    ) -> Result<Option<Request>, CommandError> {
        if distance_mm == 0 {
            // Already there: nothing to do.
            return Ok(None);
        }
        // The drive's profile runs at rated speed: V4 or no preselection.
        let speed_ok = matches!(self.selected, None | Some(Speed::V4));
        let Some(start) = self.position_mm else {
            self.accepted = false;
            return Ok(None);
        };
        let target = match direction {
            Travel::Up => start + distance_mm as i32,
            Travel::Down => start - distance_mm as i32,
        };
        if !(0..=self.config.shaft_travel_mm as i32).contains(&target) {
            return Err(CommandError::DistanceOutOfRange);
        }
        if !speed_ok || !drive.ready {
            self.accepted = false;
            return Ok(None);
        }
        self.accepted = true;
        self.phase = Phase::Distance { direction, target_mm: target, started: false };
        self.remaining_refused = false;
        Ok(Some(Request::Distance { direction, distance_mm, start_position_mm: start }))
    }

    fn error_answer(&mut self, refusal: Refusal, drive: &DriveStatus) -> Outcome {
        let comm = self.channel_tx.next_pair();
        self.last_comm = comm;
        Outcome { reply: self.reply(drive, true, comm), request: None, refused: Some(refusal) }
    }

    fn reply(&self, drive: &DriveStatus, error: bool, comm: [u8; 2]) -> SlaveFrame {
        let mut status = 0;
        let flag = |on: bool, bit: u8| if on { bit } else { 0 };
        status |= flag(drive.ready && !drive.fault && self.phase != Phase::Halted, S0_READY);
        status |= flag(drive.travelling, S1_TRAVEL);
        status |= flag(drive.fault, S3_FAULT);
        status |= flag(drive.speed_mps < self.config.levelling_speed_mps, S4_BELOW_LEVELLING);
        status |= flag(self.accepted && !error && self.phase != Phase::Halted, S5_ACCEPTED);
        status |= flag(drive.brake_open, S6_BRAKE_OPEN);
        status |= flag(error, S7_MESSAGE_ERROR);
        let data = match self.config.mode {
            // The deceleration distance, 15 bits.
            Mode::Dcp4 => drive.braking_distance_mm.min(MAX_DISTANCE_MM).to_be_bytes(),
            // "the actual deceleration distance (which is 00 (Hex) in DCP3 mode)".
            Mode::Dcp3 => [0, 0],
        };
        SlaveFrame { status, data, comm }
    }
}
