//! Processor in the loop with a lift controller on the DCP line: the
//! emulated chip (QEMU mps2-an386) runs the drive's application layer
//! (`drive_core::lift_drive::LiftDrive`: DCP slave, the commands it gives,
//! the controller) with the PIL frames on UART0 and the DCP line on UART1;
//! this side plays the lift controller and closes the loop around the
//! plant. A host build of the same application layer (the shadow) takes
//! the DCP bytes the chip reports it took at each step, and every step's
//! outputs, telemetry digest and DCP replies must be equal bit for bit.
//!
//! Needs `qemu-system-arm` and the PIL ELF (`scripts/test.sh` builds both;
//! `PIL_ELF` overrides the path).

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use drive_core::dcp::channel::position_message;
use drive_core::dcp::command::{command_byte, Kind, Mode, Speed};
use drive_core::dcp::slave::{S1_TRAVEL, S6_BRAKE_OPEN, S7_MESSAGE_ERROR};
use drive_core::dcp::{MasterFrame, SlaveConfig, SlaveFrame};
use drive_core::frame::{encode, Decoder, Message, StepReport, MAX_FRAME};
use drive_core::lift_drive::{DcpPort, LiftDrive, LiftGeometry};
use drive_core::{Controller, DriveState, SensorFrame};
use plant::{Plant, PlantInputs};
use rig_config::RigConfig;

fn rig() -> RigConfig {
    RigConfig::embedded_default().expect("the embedded rig loads")
}

/// The landings and load weighing as the PIL target's build script derives them.
fn geometry(rig: &RigConfig) -> (LiftGeometry, f32) {
    let shaft_travel_mm = ((rig.travel.lw_high_m - rig.travel.lw_low_m) * 1000.0).round() as u32;
    let heaviest = rig.mechanics.m_car_kg.iter().cloned().fold(f64::MIN, f64::max) as f32;
    (LiftGeometry { lw_lowest_landing_m: rig.travel.lw_low_m as f32, shaft_travel_mm }, heaviest)
}

/// The host shadow: the target's application layer, built for the host.
fn shadow(rig: &RigConfig) -> LiftDrive {
    let drive = rig.drive_config();
    let (geometry, m_car) = geometry(rig);
    let mut speeds = [None; 11];
    speeds[Speed::V4.index()] = Some(drive.rated_speed_mps);
    let port = DcpPort::new(SlaveConfig::new(Mode::Dcp4, speeds, geometry.shaft_travel_mm), geometry, m_car);
    LiftDrive::new(Controller::new(&drive), port, &drive)
}

/// QEMU running the PIL target with two sockets: PIL frames and DCP.
struct Chip {
    qemu: Child,
    frames: TcpStream,
    dcp: TcpStream,
    decoder: Decoder,
}

impl Drop for Chip {
    fn drop(&mut self) {
        let _ = self.qemu.kill();
        let _ = self.qemu.wait();
    }
}

fn accept(listener: &TcpListener, qemu: &mut Child) -> TcpStream {
    listener.set_nonblocking(true).unwrap();
    let started = Instant::now();
    loop {
        match listener.accept() {
            Ok((stream, _)) => {
                stream.set_nonblocking(false).unwrap();
                stream.set_nodelay(true).unwrap();
                stream.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
                return stream;
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                if let Ok(Some(status)) = qemu.try_wait() {
                    panic!("QEMU exited before connecting: {status}");
                }
                assert!(started.elapsed() < Duration::from_secs(20), "QEMU did not connect within 20 s");
                std::thread::sleep(Duration::from_millis(5));
            }
            Err(e) => panic!("accept: {e}"),
        }
    }
}

impl Chip {
    fn launch() -> Self {
        let elf = std::env::var_os("PIL_ELF").map(PathBuf::from).unwrap_or_else(|| {
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../pil/target/thumbv7em-none-eabihf/release/pil")
        });
        assert!(elf.is_file(), "PIL target {} not found: build pil/ (scripts/test.sh does)", elf.display());
        let frames = TcpListener::bind("127.0.0.1:0").unwrap();
        let dcp = TcpListener::bind("127.0.0.1:0").unwrap();
        let socket = |id: &str, l: &TcpListener| {
            format!("socket,id={id},host=127.0.0.1,port={},nodelay=on", l.local_addr().unwrap().port())
        };
        let mut qemu = Command::new("qemu-system-arm")
            .args(["-M", "mps2-an386", "-nographic", "-monitor", "none"])
            .args(["-chardev", &socket("uart0", &frames), "-serial", "chardev:uart0"])
            .args(["-chardev", &socket("uart1", &dcp), "-serial", "chardev:uart1"])
            .args(["-icount", "shift=5", "-semihosting-config", "enable=on,target=native", "-kernel"])
            .arg(&elf)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("qemu-system-arm starts (apt-get install -y qemu-system-arm)");
        let frames = accept(&frames, &mut qemu);
        let dcp = accept(&dcp, &mut qemu);
        Self { qemu, frames, dcp, decoder: Decoder::new() }
    }

    /// Puts `dcp_out` on the DCP line, runs one step on `sensors`; the
    /// step's report, the DCP bytes the chip took and its replies.
    fn step(&mut self, dcp_out: &[u8], sensors: &SensorFrame) -> (StepReport, Vec<u8>, Vec<u8>) {
        if !dcp_out.is_empty() {
            self.dcp.write_all(dcp_out).unwrap();
        }
        let mut frame = [0u8; MAX_FRAME];
        let n = encode(&Message::Sense(*sensors), &mut frame);
        self.frames.write_all(&frame[..n]).unwrap();
        let report = loop {
            let mut byte = [0u8; 1];
            self.frames.read_exact(&mut byte).expect("an output frame from the chip");
            match self.decoder.push(byte[0]) {
                Some(Ok(Message::Output(report))) => break report,
                Some(other) => panic!("unexpected reply from the chip: {other:?}"),
                None => {}
            }
        };
        let mut read = |n: usize| {
            let mut buf = vec![0u8; n];
            self.dcp.read_exact(&mut buf).expect("the chip's DCP record of the step");
            buf
        };
        let n_in = read(1)[0] as usize;
        let taken = read(n_in);
        let n_out = read(1)[0] as usize;
        let replies = read(n_out);
        (report, taken, replies)
    }
}

/// A lift controller: one message every 15 ms (240 PWM periods), a DCP4
/// travel to each target in turn with the position message before each
/// travel, from the car position of its own shaft measurement.
struct Master {
    targets: Vec<i32>,
    phase: Phase,
    next_message_step: u64,
    channel: Vec<u8>,
    last_status: u8,
    replies: Vec<SlaveFrame>,
    /// Steps at which a travel ended (brake closed again), with the car position, mm.
    arrivals: Vec<(u64, f64)>,
    /// Stop talking at this step (the silent master).
    silent_from: Option<u64>,
    /// Step of the last message sent.
    last_sent: u64,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Phase {
    Position(u32),
    Select,
    Run { target: i32, started: bool, down: bool },
    Stop,
    Idle,
    Done,
}

const CYCLE_STEPS: u64 = 240;

impl Master {
    fn new(targets: Vec<i32>) -> Self {
        Self {
            targets,
            phase: Phase::Position(0),
            next_message_step: 0,
            channel: Vec::new(),
            last_status: 0,
            replies: Vec::new(),
            arrivals: Vec::new(),
            silent_from: None,
            last_sent: 0,
        }
    }

    fn message(&mut self, kind: Kind, down: bool, data: [u8; 2]) -> Vec<u8> {
        let mut comm = [0u8; 2];
        for slot in comm.iter_mut() {
            if !self.channel.is_empty() {
                *slot = self.channel.remove(0);
            }
        }
        MasterFrame { command: command_byte(kind, down), data, comm }.encode().to_vec()
    }

    /// The bytes to put on the line at step `k` with the car `position_mm` above the lowest landing.
    fn bytes(&mut self, k: u64, position_mm: f64) -> Vec<u8> {
        if k < self.next_message_step || self.silent_from.is_some_and(|s| k >= s) {
            return Vec::new();
        }
        self.next_message_step = k + CYCLE_STEPS;
        self.last_sent = k;
        let target = self.targets.first().copied();
        let down = target.is_some_and(|t| (t as f64) < position_mm);
        match self.phase {
            Phase::Position(sent) => {
                if sent == 0 {
                    self.channel.extend_from_slice(&position_message(position_mm.round() as i32));
                }
                // 12 bytes out in 6 messages, 3 more for the answer.
                self.phase = if sent + 1 >= 9 { Phase::Select } else { Phase::Position(sent + 1) };
                self.message(Kind::Stop, down, [0, 0])
            }
            Phase::Select => {
                self.phase = match target {
                    Some(target) => Phase::Run { target, started: false, down },
                    None => Phase::Done,
                };
                self.message(Kind::SpeedMode, down, Speed::V4.data())
            }
            Phase::Run { target, started, down } => {
                let travelling = self.last_status & (S1_TRAVEL | S6_BRAKE_OPEN) != 0;
                if started && !travelling {
                    self.arrivals.push((k, position_mm));
                    self.phase = Phase::Stop;
                    return self.message(Kind::Stop, down, [0, 0]);
                }
                self.phase = Phase::Run { target, started: started || travelling, down };
                // The remaining distance in the travel's direction (0 once
                // there or past it); the direction stays that of the travel.
                let ahead = if down { position_mm - target as f64 } else { target as f64 - position_mm };
                let remaining = ahead.max(0.0).round().min(32_767.0) as u16;
                self.message(Kind::Decelerate, down, remaining.to_be_bytes())
            }
            Phase::Stop => {
                self.phase = Phase::Idle;
                self.message(Kind::Idle, false, [0, 0])
            }
            Phase::Idle => {
                self.targets.remove(0);
                self.phase = if self.targets.is_empty() { Phase::Done } else { Phase::Position(0) };
                self.message(Kind::Idle, false, [0, 0])
            }
            Phase::Done => self.message(Kind::Idle, false, [0, 0]),
        }
    }

    fn receive(&mut self, replies: &[u8]) {
        for chunk in replies.chunks(6) {
            let bytes: [u8; 6] = chunk.try_into().expect("whole replies");
            let frame = SlaveFrame::decode(&bytes).expect("a reply with a valid checksum");
            self.last_status = frame.status;
            self.replies.push(frame);
        }
    }
}

/// Everything a run gives back.
struct Run {
    steps: u64,
    states: Vec<DriveState>,
    brake_released: Vec<bool>,
    shadow: LiftDrive,
}

/// Runs the chip and the shadow closed around the plant for at most
/// `max_steps`, until `done` says so; `master` decides the bytes of each step.
fn run_loop(
    master: &mut dyn FnMut(u64, f64) -> Vec<u8>,
    on_replies: &mut dyn FnMut(&[u8]),
    done: &mut dyn FnMut(u64, &DriveState) -> bool,
    max_steps: u64,
    lw_start_m: f64,
) -> Run {
    let rig = rig();
    let (geometry, m_car) = geometry(&rig);
    let options = closed_loop::SimOptions::for_rig(&rig);
    let ts = 1.0 / rig.control.current_loop_hz;
    let mut plant = Plant::new(&rig, m_car as f64, lw_start_m);
    let mut chip = Chip::launch();
    let mut host = shadow(&rig);
    let mut states = Vec::new();
    let mut brake_released = Vec::new();
    let started = Instant::now();
    let mut k = 0;
    while k < max_steps {
        let sensors = closed_loop::sensor_frame(&plant);
        let lw = plant.observe().counterweight_side_length_m;
        let position_mm = (lw - geometry.lw_lowest_landing_m as f64) * 1000.0;
        let out = master(k, position_mm);
        let (report, taken, replies) = chip.step(&out, &sensors);
        let dcp = host.dcp_step(&taken, sensors.time_us);
        assert_eq!(replies, &dcp.reply[..dcp.reply_len], "step {k}: DCP replies of the chip and the host differ");
        let output = host.control_step(&sensors);
        assert!(
            report.matches(&output),
            "step {k}: first differing step\n  inputs {sensors:?}\n  host   {:?}\n  target {report:?}",
            StepReport::new(&output, report.cost_ticks)
        );
        on_replies(&replies);
        plant.set_inputs(PlantInputs {
            pwm_compare: output.pwm_compare,
            pwm_enabled: output.pwm_enabled,
            brake_engaged: !output.brake_released,
        });
        plant.advance(ts, options.max_step_s);
        assert!(plant.in_valid_range(), "step {k}: the plant left its valid range");
        states.push(output.state);
        brake_released.push(output.brake_released);
        k += 1;
        if done(k, &output.state) {
            break;
        }
    }
    println!("{k} DCP PIL steps in {:.1} s", started.elapsed().as_secs_f64());
    Run { steps: k, states, brake_released, shadow: host }
}

#[test]
fn dcp4_travels_between_landings_on_the_emulated_chip_are_bit_identical_to_the_host() {
    let rig = rig();
    let (geometry, _) = geometry(&rig);
    // Car at 1000 mm above the lowest landing; up 600 mm, then down 300 mm.
    let lw_start = geometry.lw_lowest_landing_m as f64 + 1.0;
    let master = std::cell::RefCell::new(Master::new(vec![1600, 1300]));
    let run = run_loop(
        &mut |k, position| master.borrow_mut().bytes(k, position),
        &mut |replies| master.borrow_mut().receive(replies),
        &mut |_, _| master.borrow().phase == Phase::Done,
        200_000,
        lw_start,
    );
    let master = master.into_inner();
    assert_eq!(master.phase, Phase::Done, "the sequence did not finish in {} steps", run.steps);
    assert_eq!(master.arrivals.len(), 2);
    for ((_, position), target) in master.arrivals.iter().zip([1600.0, 1300.0]) {
        println!("landed at {position:.2} mm, target {target} mm");
        assert!((position - target).abs() < 3.0, "landed at {position:.1} mm, target {target} mm");
    }
    assert!(master.replies.iter().all(|r| r.status & S7_MESSAGE_ERROR == 0), "a good message got the error bit");
    assert_eq!(run.shadow.port().slave().position_mm(), Some(1300));
    let travelled = run.states.iter().filter(|s| **s == DriveState::Travel).count();
    assert!(travelled > 16_000, "{travelled} steps in Travel");
}

#[test]
fn a_silent_master_mid_travel_stops_the_drive_within_the_timeout_with_the_brake_applied() {
    let rig = rig();
    let (geometry, _) = geometry(&rig);
    let lw_start = geometry.lw_lowest_landing_m as f64 + 1.0;
    let master = std::cell::RefCell::new(Master::new(vec![3000]));
    let mut travel_since = None;
    let run = run_loop(
        &mut |k, position| {
            let mut m = master.borrow_mut();
            m.bytes(k, position)
        },
        &mut |replies| master.borrow_mut().receive(replies),
        &mut |k, state| {
            // Silent after 0.5 s of travel; stop the run 0.2 s after that.
            if *state == DriveState::Travel && travel_since.is_none() {
                travel_since = Some(k);
            }
            match travel_since {
                Some(t) if k == t + 8_000 => {
                    master.borrow_mut().silent_from = Some(k);
                    false
                }
                Some(t) => k >= t + 8_000 + 3_200,
                None => false,
            }
        },
        200_000,
        lw_start,
    );
    let master = master.into_inner();
    let last = master.last_sent as usize;
    let stopped = (last..run.steps as usize)
        .find(|&k| run.states[k] == DriveState::Idle)
        .expect("the drive stopped after the master fell silent");
    assert!(run.states[..last].contains(&DriveState::Travel));
    assert!(!run.brake_released[stopped], "brake applied at the stop");
    assert!(run.states[stopped..].iter().all(|s| *s == DriveState::Idle), "stays stopped");
    let ts_ms = 1000.0 / rig.control.current_loop_hz;
    let delay_ms = (stopped - last) as f64 * ts_ms;
    // The watchdog runs from the end of the last message: 6 bytes and the
    // idle gap after its first byte, then 100 ms.
    println!("safe stop {delay_ms:.2} ms after the last message started");
    assert!((100.0..=103.0).contains(&delay_ms), "{delay_ms} ms");
}

#[test]
fn corrupted_and_truncated_messages_are_answered_with_the_error_bit_and_never_start_a_travel() {
    let rig = rig();
    let (geometry, _) = geometry(&rig);
    let lw_start = geometry.lw_lowest_landing_m as f64 + 1.0;
    let travel =
        MasterFrame { command: command_byte(Kind::Decelerate, false), data: 500u16.to_be_bytes(), comm: [0; 2] };
    let good = travel.encode();
    let mut corrupted = good;
    corrupted[2] ^= 0x10;
    let unknown = MasterFrame { command: 0x02, ..travel }.encode();
    let out_of_range = MasterFrame { data: 0x8100u16.to_be_bytes(), ..travel }.encode();
    let long = [good.as_slice(), &[0x00]].concat();
    let bad: Vec<Vec<u8>> = vec![corrupted.to_vec(), good[..5].to_vec(), long, unknown.to_vec(), out_of_range.to_vec()];
    // Position, V4, then the bad messages one per cycle, then the good one.
    let mut script: Vec<Vec<u8>> = Vec::new();
    let mut channel = position_message(1000).to_vec();
    for _ in 0..9 {
        let mut comm = [0u8; 2];
        for slot in comm.iter_mut() {
            if !channel.is_empty() {
                *slot = channel.remove(0);
            }
        }
        script.push(MasterFrame { command: command_byte(Kind::Stop, false), data: [0, 0], comm }.encode().to_vec());
    }
    script.push(
        MasterFrame { command: command_byte(Kind::SpeedMode, false), data: Speed::V4.data(), comm: [0; 2] }
            .encode()
            .to_vec(),
    );
    let first_bad = script.len();
    script.extend(bad.iter().cloned());
    let good_at = script.len();
    script.push(good.to_vec());
    let replies = std::cell::RefCell::new(Vec::<(u64, SlaveFrame)>::new());
    let step = std::cell::Cell::new(0u64);
    let run = run_loop(
        &mut |k, _| {
            step.set(k);
            if k % CYCLE_STEPS == 0 {
                script.get((k / CYCLE_STEPS) as usize).cloned().unwrap_or_default()
            } else {
                Vec::new()
            }
        },
        &mut |bytes| {
            for chunk in bytes.chunks(6) {
                let frame = SlaveFrame::decode(chunk.try_into().unwrap()).unwrap();
                replies.borrow_mut().push((step.get(), frame));
            }
        },
        &mut |k, _| k >= (good_at as u64 + 2) * CYCLE_STEPS,
        100_000,
        lw_start,
    );
    let replies = replies.into_inner();
    // One reply per message, in order.
    assert_eq!(replies.len(), good_at + 1, "{replies:?}");
    for (i, (_, reply)) in replies.iter().enumerate() {
        let error = reply.status & S7_MESSAGE_ERROR != 0;
        assert_eq!(error, (first_bad..good_at).contains(&i), "message {i}: status {:#010b}", reply.status);
    }
    let good_step = (good_at as u64 * CYCLE_STEPS) as usize;
    assert!(run.states[..good_step].iter().all(|s| *s == DriveState::Idle), "a bad message started a travel");
    assert!(run.states[good_step..].contains(&DriveState::PreTorque), "the good message starts the travel");
}
