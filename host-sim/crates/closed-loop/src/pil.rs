//! The link to the processor-in-the-loop target: the drive core compiled for
//! the Cortex-M4F (`pil/`) running in QEMU's `mps2-an386`, one frame per PWM
//! period over the emulated UART (a TCP socket on 127.0.0.1 that QEMU
//! connects to). Frames are `drive_core::frame`, the code the target uses too.
//!
//! QEMU runs with `-icount shift=N`: every instruction advances the virtual
//! clock by 2^N ns, and the target times each step with SysTick on the
//! 25 MHz processor clock of the machine, so a step's instructions are its
//! ticks times `40 ns / 2^N ns`.
//!
//! The target runs the drive's application layer
//! (`drive_core::lift_drive::LiftDrive`, as the firmware does); only UART0
//! is connected here, so its DCP line and service port hear nothing. It
//! starts as after any reset: [`PilTarget::launch`] first runs its
//! start-up sequence (settling and the current-offset calibration, gates
//! off and brake applied) on frames of the machine at rest, then the
//! controller is idle until a travel is commanded.
//!
//! Every step is checked as it happens: a host build of the same
//! application layer (the shadow) takes the same inputs, and the target's
//! outputs and telemetry digest must equal the shadow's bit for bit, or the
//! run stops at that step with both printed. The telemetry the closed loop
//! records is the shadow's, which the digest has shown to be the target's.
//! With a strategy that uses the chain observer, the target runs the
//! observer's task at the end of each period (kept by its `LiftDrive`) and
//! the shadow does the same, on the schedule of `drive_core::observer::task`.

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use std::time::{Duration, Instant};

use drive_core::dcp::{Mode, SlaveConfig};
use drive_core::frame::{
    command_result_from_code, encode, Decoder, Message, StepReport, ACK_FRAME_REJECTED, MAX_FRAME,
};
use drive_core::lift_drive::{
    speed_table, AngleReference, DcpPort, DriveOutput, LiftDrive, LiftGeometry, PeriodIo, ServiceReply,
};
use drive_core::param_store::DriveParameters;
use drive_core::service::ParamsStatus;
use drive_core::{ControlOutput, Controller, DriveConfig, SensorFrame, TravelCommand};

use crate::{corrupted_frame, DriveController, SimError};

pub mod dcp;

/// Processor clock of the MPS2 board in QEMU, which SysTick counts, Hz.
pub const MPS2_SYSCLK_HZ: f64 = 25.0e6;

/// Where the PIL target's ELF is built (`cargo build --release --target
/// thumbv7em-none-eabihf` in `pil/`, which `scripts/test.sh` does).
pub fn default_elf_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../pil/target/thumbv7em-none-eabihf/release/pil")
}

/// How to start the target.
#[derive(Clone, Debug, PartialEq)]
pub struct PilOptions {
    /// The target's ELF.
    pub elf: PathBuf,
    /// The QEMU executable.
    pub qemu: PathBuf,
    /// `-icount shift`: 2^shift ns of virtual time per instruction.
    pub icount_shift: u32,
    /// Longest wait for QEMU to connect or for one reply.
    pub timeout: Duration,
    /// File for QEMU's standard output and error (the defmt semihosting
    /// stream and any emulator message); none discards them.
    pub log: Option<PathBuf>,
    /// QEMU's working directory (where the target keeps its emulated flash
    /// file); none: the caller's.
    pub working_dir: Option<PathBuf>,
}

impl Default for PilOptions {
    fn default() -> Self {
        Self {
            elf: default_elf_path(),
            qemu: PathBuf::from("qemu-system-arm"),
            icount_shift: 5,
            timeout: Duration::from_secs(20),
            log: None,
            working_dir: None,
        }
    }
}

/// Why the link failed.
#[derive(Debug, thiserror::Error)]
pub enum PilError {
    /// The ELF is not there.
    #[error("PIL target {0} not found: build it with `cargo build --release --target thumbv7em-none-eabihf` in pil/ (scripts/test.sh does)")]
    ElfMissing(PathBuf),
    /// QEMU could not be started.
    #[error("cannot start {qemu}: {source} (install it with `apt-get install -y qemu-system-arm`)")]
    QemuMissing {
        /// The executable tried.
        qemu: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// Socket or file error.
    #[error("{context}: {source}")]
    Io {
        /// What was being done.
        context: &'static str,
        /// Cause.
        source: std::io::Error,
    },
    /// No connection or reply in time.
    #[error("no {0} from the PIL target within the timeout (QEMU log has details if --log was given)")]
    Timeout(&'static str),
    /// A frame failed its checks.
    #[error("bad frame from the PIL target: {0:?}")]
    Frame(drive_core::frame::FrameError),
    /// A valid frame of the wrong kind.
    #[error("unexpected reply from the PIL target: {0:?}")]
    Unexpected(Message),
    /// The start-up sequence failed or differed from the host build's.
    #[error("start-up of the PIL target: {0}")]
    StartUp(String),
}

impl From<PilError> for SimError {
    fn from(error: PilError) -> Self {
        SimError::Link(error.to_string())
    }
}

/// QEMU running the PIL target (`mps2-an386`, `-icount`, semihosting),
/// its first UARTs on TCP sockets of 127.0.0.1; killed when dropped. The
/// one launcher of the target: [`PilTarget`] connects UART0 (the PIL
/// frames), [`dcp::Chip`] UART0 to UART2 (the frames, the DCP line, the
/// service port).
pub struct Qemu {
    child: Child,
}

impl Qemu {
    /// Starts QEMU on `options.elf` (in `options.working_dir` if given) with
    /// UART0 to UART`uarts - 1` on sockets, and waits for each to connect
    /// (at most `options.timeout` each); the streams in UART order, each
    /// without Nagle's delay and with `options.timeout` as read timeout.
    pub fn launch(options: &PilOptions, uarts: usize) -> Result<(Self, Vec<TcpStream>), PilError> {
        if !options.elf.is_file() {
            return Err(PilError::ElfMissing(options.elf.clone()));
        }
        let elf = options.elf.canonicalize().map_err(|source| PilError::Io { context: "resolve the ELF", source })?;
        let listeners = (0..uarts)
            .map(|_| {
                TcpListener::bind("127.0.0.1:0").map_err(|source| PilError::Io { context: "bind 127.0.0.1", source })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let mut command = Command::new(&options.qemu);
        command.args(["-M", "mps2-an386", "-nographic", "-monitor", "none"]);
        for (i, listener) in listeners.iter().enumerate() {
            let port =
                listener.local_addr().map_err(|source| PilError::Io { context: "local address", source })?.port();
            command
                .arg("-chardev")
                .arg(format!("socket,id=uart{i},host=127.0.0.1,port={port},nodelay=on"))
                .arg("-serial")
                .arg(format!("chardev:uart{i}"));
        }
        command
            .args(["-icount", &format!("shift={}", options.icount_shift)])
            .args(["-semihosting-config", "enable=on,target=native", "-kernel"])
            .arg(&elf);
        if let Some(dir) = &options.working_dir {
            if !dir.is_dir() {
                return Err(PilError::Io {
                    context: "QEMU's working directory",
                    source: std::io::Error::other(format!("{} is not a directory", dir.display())),
                });
            }
            command.current_dir(dir);
        }
        let (stdout, stderr) = match &options.log {
            Some(path) => {
                let file =
                    std::fs::File::create(path).map_err(|source| PilError::Io { context: "QEMU log", source })?;
                let copy = file.try_clone().map_err(|source| PilError::Io { context: "QEMU log", source })?;
                (Stdio::from(file), Stdio::from(copy))
            }
            None => (Stdio::null(), Stdio::null()),
        };
        let child = command
            .stdin(Stdio::null())
            .stdout(stdout)
            .stderr(stderr)
            .spawn()
            .map_err(|source| PilError::QemuMissing { qemu: options.qemu.clone(), source })?;
        let mut qemu = Self { child };
        let streams =
            listeners.iter().map(|listener| qemu.accept(listener, options.timeout)).collect::<Result<Vec<_>, _>>()?;
        Ok((qemu, streams))
    }

    /// Waits for QEMU to connect to `listener` (at most `timeout`).
    fn accept(&mut self, listener: &TcpListener, timeout: Duration) -> Result<TcpStream, PilError> {
        listener.set_nonblocking(true).map_err(|source| PilError::Io { context: "listen", source })?;
        let started = Instant::now();
        let stream = loop {
            match listener.accept() {
                Ok((stream, _)) => break stream,
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                    if started.elapsed() > timeout {
                        return Err(PilError::Timeout("UART connection"));
                    }
                    if let Ok(Some(status)) = self.child.try_wait() {
                        return Err(PilError::Io {
                            context: "QEMU exited before connecting",
                            source: std::io::Error::other(status.to_string()),
                        });
                    }
                    std::thread::sleep(Duration::from_millis(5));
                }
                Err(source) => return Err(PilError::Io { context: "accept", source }),
            }
        };
        stream.set_nonblocking(false).map_err(|source| PilError::Io { context: "socket", source })?;
        stream.set_nodelay(true).map_err(|source| PilError::Io { context: "socket", source })?;
        stream.set_read_timeout(Some(timeout)).map_err(|source| PilError::Io { context: "socket", source })?;
        Ok(stream)
    }
}

impl Drop for Qemu {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The running target.
pub struct PilTarget {
    /// Kept for its drop, which ends QEMU.
    _qemu: Qemu,
    stream: TcpStream,
    decoder: Decoder,
    timeout: Duration,
    icount_shift: u32,
    reports: Vec<StepReport>,
    /// The host build of the target's application layer.
    shadow: LiftDrive,
}

impl PilTarget {
    /// Starts QEMU with the target ([`Qemu::launch`], UART0) and waits for
    /// its UART to connect; the target is built for `drive` (the rig's
    /// parameters), which the host shadow uses too.
    pub fn launch(options: &PilOptions, drive: &DriveConfig) -> Result<Self, PilError> {
        let (qemu, mut streams) = Qemu::launch(options, 1)?;
        let stream = streams.pop().expect("one UART");
        let mut target = Self {
            _qemu: qemu,
            stream,
            decoder: Decoder::new(),
            timeout: options.timeout,
            icount_shift: options.icount_shift,
            reports: Vec::new(),
            shadow: shadow(drive),
        };
        target.start_up(drive)?;
        Ok(target)
    }

    /// Runs the start-up sequence (settling and the current-offset
    /// calibration, gates off and brake applied throughout) on frames of
    /// the machine at rest (no current, the nominal bus, the encoder at
    /// zero), checked against the shadow; the steps are not kept in
    /// [`PilTarget::reports`].
    fn start_up(&mut self, drive: &DriveConfig) -> Result<(), PilError> {
        let zero = drive.adc_zero_code();
        let bus_code = (drive.dc_bus_nominal_v / drive.dc_bus_sense_full_scale_v * drive.adc_max_code() as f32) as u16;
        let mut k = 0u32;
        while !self.shadow.startup().is_running() {
            let rest = SensorFrame {
                phase_current_codes: [zero; 3],
                encoder_count: 0,
                dc_bus_code: bus_code,
                time_us: k.wrapping_mul(1_000_000) / drive.current_loop_hz as u32,
            };
            let output = self.step(&rest).map_err(|e| PilError::StartUp(e.to_string()))?;
            if output.pwm_enabled || output.brake_released {
                return Err(PilError::StartUp(format!("step {k} of the start-up drives the outputs: {output:?}")));
            }
            k += 1;
            if k > 100_000 {
                return Err(PilError::StartUp("the start-up sequence did not end".to_string()));
            }
        }
        self.reports.clear();
        Ok(())
    }

    /// Instructions per SysTick tick: `(1 / 25 MHz) / 2^shift ns`.
    pub fn instructions_per_tick(&self) -> f64 {
        1.0e9 / MPS2_SYSCLK_HZ / f64::from(1u32 << self.icount_shift)
    }

    /// The target's report of every step so far.
    pub fn reports(&self) -> &[StepReport] {
        &self.reports
    }

    /// Sends one message and waits for the reply.
    pub fn exchange(&mut self, message: &Message) -> Result<Message, PilError> {
        let mut frame = [0u8; MAX_FRAME];
        let n = encode(message, &mut frame);
        self.exchange_bytes(&frame[..n])
    }

    /// Sends raw bytes (a frame, possibly corrupted) and waits for the reply.
    pub fn exchange_bytes(&mut self, frame: &[u8]) -> Result<Message, PilError> {
        self.stream.write_all(frame).map_err(|source| PilError::Io { context: "send", source })?;
        let started = Instant::now();
        let mut buffer = [0u8; 256];
        loop {
            let count = match self.stream.read(&mut buffer) {
                Ok(0) => {
                    return Err(PilError::Io {
                        context: "receive",
                        source: std::io::Error::other("QEMU closed the connection"),
                    })
                }
                Ok(count) => count,
                Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {
                    return Err(PilError::Timeout("reply"))
                }
                Err(source) => return Err(PilError::Io { context: "receive", source }),
            };
            // One reply per request: a frame never arrives unasked, so the
            // reply is complete when the decoder yields.
            let mut reply = None;
            for (i, &byte) in buffer[..count].iter().enumerate() {
                if let Some(result) = self.decoder.push(byte) {
                    if i + 1 != count {
                        return Err(PilError::Unexpected(result.map_err(PilError::Frame)?));
                    }
                    reply = Some(result.map_err(PilError::Frame)?);
                }
            }
            if let Some(reply) = reply {
                return Ok(reply);
            }
            if started.elapsed() > self.timeout {
                return Err(PilError::Timeout("reply"));
            }
        }
    }
}

impl DriveController for PilTarget {
    fn command_travel(&mut self, command: TravelCommand) -> Result<(), SimError> {
        let host = self.shadow.command_travel(command);
        let target = match self.exchange(&Message::Travel(command))? {
            Message::Ack(code) => command_result_from_code(code),
            other => return Err(PilError::Unexpected(other).into()),
        };
        if host != target {
            return Err(SimError::Link(format!(
                "travel command: the target answered {target:?}, the host build {host:?}"
            )));
        }
        target.map_err(SimError::Refused)
    }

    fn step(&mut self, sensors: &SensorFrame) -> Result<ControlOutput, SimError> {
        let report = match self.exchange(&Message::Sense(*sensors))? {
            Message::Output(report) => report,
            other => return Err(PilError::Unexpected(other).into()),
        };
        self.shadow_check(sensors, report)
    }

    /// Sends the frame with byte `byte_index` XOR `xor`: the target rejects
    /// it ([`ACK_FRAME_REJECTED`], no step: `None`) or, if the corruption
    /// still decodes, steps on what it decoded, as the shadow then does.
    /// The sync bytes (0 and 1) cannot be corrupted here: the target would
    /// see no frame at all and the host could not tell when to stop waiting.
    fn step_corrupted(
        &mut self,
        sensors: &SensorFrame,
        byte_index: usize,
        xor: u8,
    ) -> Result<Option<ControlOutput>, SimError> {
        let mut frame = [0u8; MAX_FRAME];
        let n = encode(&Message::Sense(*sensors), &mut frame);
        if !(2..n).contains(&byte_index) {
            return Err(SimError::Link(format!(
                "frame corruption at byte {byte_index}: the PIL link corrupts bytes 2..{n} (after the sync pair)"
            )));
        }
        frame[byte_index] ^= xor;
        match self.exchange_bytes(&frame[..n])? {
            Message::Ack(ACK_FRAME_REJECTED) => Ok(None),
            Message::Output(report) => {
                let decoded = corrupted_frame(sensors, byte_index, xor).ok_or_else(|| {
                    SimError::Link("the target stepped on a frame the host codec rejects".to_string())
                })?;
                self.shadow_check(&decoded, report).map(Some)
            }
            other => Err(PilError::Unexpected(other).into()),
        }
    }
}

impl PilTarget {
    /// Installs ripple compensation `strategy` with `table` on the target
    /// and on the shadow alike ([`Controller::install_compensation`] with
    /// the drive's chain model `chain`); the table keeps its first
    /// [`drive_core::frame::COMPENSATION_HARMONICS`] harmonics, as the frame does.
    pub fn install_compensation(
        &mut self,
        strategy: drive_core::ripple::Strategy,
        table: &drive_core::ripple::harmonics::HarmonicTable,
        chain: &drive_core::observer::ChainModel,
    ) -> Result<(), PilError> {
        let mut sent = *table;
        sent.len = sent.len.min(drive_core::frame::COMPENSATION_HARMONICS);
        match self.exchange(&Message::Compensation { strategy, table: sent })? {
            Message::Ack(0) => {}
            other => return Err(PilError::Unexpected(other)),
        }
        // The target's drive keeps one task on its chain model (invalid:
        // none, and the controller counts every tick as a missed deadline).
        let parameters = DriveParameters {
            strategy,
            table: sent,
            m_car_kg: self.shadow.port().car_mass_kg(),
            encoder_offset_counts: 0,
            dcp_mode: Mode::Dcp4,
        };
        self.shadow.install_parameters(&parameters, chain, ParamsStatus::None);
        Ok(())
    }

    /// Steps the shadow on `sensors` and checks the target's `report` against it.
    fn shadow_check(&mut self, sensors: &SensorFrame, report: StepReport) -> Result<ControlOutput, SimError> {
        let host = self.shadow.period(sensors, &mut Unconnected).drive.control;
        if !report.matches(&host) {
            return Err(SimError::Link(format!(
                "step {}: the target's output differs from the host build\n  inputs {sensors:?}\n  target {report:?}\n  host   {:?}",
                self.reports.len(),
                StepReport::new(&host, report.cost_ticks)
            )));
        }
        self.reports.push(report);
        Ok(host)
    }
}

/// The shadow: the target's application layer built for the host, the
/// angle reference given (the plant's rotor starts at electrical zero), as
/// the target's. Its DCP port and service port hear nothing here, as the
/// target's (only UART0 is connected in this mode); their landings do not
/// matter.
fn shadow(drive: &DriveConfig) -> LiftDrive {
    let geometry = LiftGeometry { lw_lowest_landing_m: 0.0, shaft_travel_mm: 0 };
    let slave = SlaveConfig::new(Mode::Dcp4, speed_table(drive.rated_speed_mps), geometry.shaft_travel_mm);
    LiftDrive::new(Controller::new(drive), DcpPort::new(slave, geometry, 0.0), drive, AngleReference::Given)
}

/// The shadow's edges in this mode: nothing on the DCP line or the service port.
struct Unconnected;

impl PeriodIo for Unconnected {
    fn service_byte(&mut self) -> Option<u8> {
        None
    }

    fn dcp_byte(&mut self) -> Option<u8> {
        None
    }

    fn drive(&mut self, _output: &DriveOutput) {}

    fn service_reply(&mut self, _reply: &ServiceReply) {}

    fn dcp_reply(&mut self, _reply: &[u8; 6]) {}
}
