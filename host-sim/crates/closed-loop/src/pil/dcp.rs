//! The processor in the loop with a lift controller on the DCP line: the
//! emulated chip (QEMU mps2-an386, the `pil/` target) runs the drive's
//! application layer (`drive_core::lift_drive::LiftDrive`: the start-up
//! sequence, the controller, the service port, the DCP slave and the
//! commands it gives, the observer's task, the code the firmware runs) with the PIL
//! frames on UART0, the DCP line on UART1 and the service port on UART2;
//! this side plays the lift controller ([`Master`]) and closes the loop
//! around the plant ([`Lift`]). A host build of the same application layer
//! (the shadow) takes the DCP and service bytes the chip reports it took at
//! each step, and every step's outputs, telemetry digest, DCP replies and
//! service answers must be equal bit for bit, or the step fails with both
//! printed.
//!
//! Used by `host-sim pil --dcp` and by the integration tests
//! (`tests/pil_dcp.rs`, `tests/pil_params.rs`, `tests/pil_faults.rs`); QEMU
//! is started by the one launcher of the target, [`super::Qemu`].

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::time::Duration;

use drive_core::dcp::channel::position_message;
use drive_core::dcp::command::{command_byte, Kind, Mode, Speed};
use drive_core::dcp::slave::{S1_TRAVEL, S6_BRAKE_OPEN};
use drive_core::dcp::{MasterFrame, SlaveConfig, SlaveFrame};
use drive_core::frame::{encode, Decoder, Message, StepReport, MAX_FRAME};
use drive_core::lift_drive::{
    speed_table, AngleReference, DcpPort, DriveOutput, LiftDrive, LiftGeometry, PeriodIo, ServiceReply,
};
use drive_core::param_store::DriveParameters;
use drive_core::ripple::Strategy;
use drive_core::service::ParamsStatus;
use drive_core::{ControlOutput, Controller, DriveConfig, SensorFrame};
use plant::{Plant, PlantInputs};
use rig_config::RigConfig;

use super::{PilError, PilOptions, Qemu};

/// Why the lift, the chip or the lift controller stopped.
#[derive(Debug, thiserror::Error)]
pub enum DcpError {
    /// The link to the chip: QEMU, its sockets, a frame.
    #[error(transparent)]
    Link(#[from] PilError),
    /// A check failed: the chip and its host shadow differ, the plant left
    /// its valid range, the car is outside the shaft, an answer did not
    /// come, a DCP reply is bad.
    #[error("{0}")]
    Check(String),
}

/// Returns [`DcpError::Check`] with the formatted message unless `cond`.
macro_rules! ensure {
    ($cond:expr, $($arg:tt)+) => {
        if !$cond {
            return Err(DcpError::Check(format!($($arg)+)));
        }
    };
}

/// An I/O error on the link, with what was being done.
fn io(context: &'static str) -> impl FnOnce(std::io::Error) -> DcpError {
    move |source| DcpError::Link(PilError::Io { context, source })
}

/// Instructions per SysTick tick: the 25 MHz tick is 40 ns, an instruction
/// 2^5 ns under `-icount shift=5`.
pub const INSTRUCTIONS_PER_TICK: f64 = 40.0 / 32.0;

/// How long to wait for QEMU to connect or for the chip to answer.
const TIMEOUT: Duration = Duration::from_secs(20);

/// The landings and the load weighing as the PIL target's build script
/// derives them from the rig: the lowest landing at `[travel].lw_low_m`,
/// the shaft up to `lw_high_m` (mm), and the heaviest car (kg).
pub fn geometry(rig: &RigConfig) -> (LiftGeometry, f32) {
    let shaft_travel_mm = ((rig.travel.lw_high_m - rig.travel.lw_low_m) * 1000.0).round() as u32;
    let heaviest = rig.mechanics.m_car_kg.iter().cloned().fold(f64::MIN, f64::max) as f32;
    (LiftGeometry { lw_lowest_landing_m: rig.travel.lw_low_m as f32, shaft_travel_mm }, heaviest)
}

/// The parameters the PIL target runs with when no record is stored: no
/// compensation (the rig's offline table, its `[[ripple]]` negated, ready
/// for `set strategy`), the heaviest car, DCP4.
pub fn default_parameters(rig: &RigConfig) -> DriveParameters {
    DriveParameters {
        strategy: Strategy::Off,
        table: crate::compensation::rig_ripple_table(rig).negated(),
        m_car_kg: geometry(rig).1,
        encoder_offset_counts: 0,
        dcp_mode: Mode::Dcp4,
    }
}

/// The host shadow: the target's application layer, built for the host,
/// started with `parameters` (what became of the stored record: `status`).
pub fn shadow(rig: &RigConfig, parameters: &DriveParameters, status: ParamsStatus) -> LiftDrive {
    let drive = rig.drive_config();
    let (geometry, m_car) = geometry(rig);
    let slave = SlaveConfig::new(Mode::Dcp4, speed_table(drive.rated_speed_mps), geometry.shaft_travel_mm);
    let port = DcpPort::new(slave, geometry, m_car);
    // The plant's rotor starts at electrical zero with the encoder at zero:
    // the angle reference is given (no alignment), as on the chip.
    let mut lift = LiftDrive::new(Controller::new(&drive), port, &drive, AngleReference::Given);
    lift.install_parameters(parameters, &rig.observer_model(), status);
    // The target writes its record (to the emulated flash).
    lift.set_savable(true);
    lift
}

/// What the chip did in one step.
#[derive(Clone, Debug, PartialEq)]
pub struct ChipStep {
    /// The step's outputs.
    pub report: StepReport,
    /// The DCP bytes it took this step.
    pub dcp_taken: Vec<u8>,
    /// Its DCP replies.
    pub dcp_replies: Vec<u8>,
    /// The service bytes it took this step.
    pub service_taken: Vec<u8>,
    /// The chain observer's task after the step, if it ran: its cost in
    /// SysTick ticks (25 MHz clock).
    pub observer_ticks: Option<u32>,
    /// The rest of the period's work after the outputs were handed out
    /// (the learning of the compensation's tick, the service and DCP
    /// bytes), before the observer's task: SysTick ticks.
    pub after_ticks: u32,
}

/// QEMU running the PIL target with three sockets: PIL frames, DCP, service port.
pub struct Chip {
    frames: TcpStream,
    dcp: TcpStream,
    service: TcpStream,
    decoder: Decoder,
    /// Kept for its drop, which ends QEMU.
    _qemu: Qemu,
}

impl Chip {
    /// Starts `qemu` (`qemu-system-arm`) on the target `elf` in the working
    /// directory `dir` (where the target keeps its emulated flash file):
    /// [`Qemu::launch`] with UART0 to UART2, `-icount shift=5`.
    pub fn launch(elf: &Path, qemu: &Path, dir: &Path) -> Result<Self, DcpError> {
        let options = PilOptions {
            elf: elf.to_path_buf(),
            qemu: qemu.to_path_buf(),
            icount_shift: 5,
            timeout: TIMEOUT,
            log: None,
            working_dir: Some(dir.to_path_buf()),
        };
        let (qemu, streams) = Qemu::launch(&options, 3)?;
        let [frames, dcp, service]: [TcpStream; 3] = streams.try_into().expect("three UARTs");
        Ok(Self { frames, dcp, service, decoder: Decoder::new(), _qemu: qemu })
    }

    /// Puts `dcp_out` on the DCP line and `service_out` on the service
    /// port, runs one step on `sensors`.
    pub fn step(&mut self, dcp_out: &[u8], service_out: &[u8], sensors: &SensorFrame) -> Result<ChipStep, DcpError> {
        if !service_out.is_empty() {
            self.service.write_all(service_out).map_err(io("send on the service port"))?;
        }
        if !dcp_out.is_empty() {
            self.dcp.write_all(dcp_out).map_err(io("send on the DCP line"))?;
        }
        let mut frame = [0u8; MAX_FRAME];
        let n = encode(&Message::Sense(*sensors), &mut frame);
        self.frames.write_all(&frame[..n]).map_err(io("send a frame"))?;
        let report = loop {
            let mut byte = [0u8; 1];
            self.frames.read_exact(&mut byte).map_err(io("no output frame from the chip"))?;
            match self.decoder.push(byte[0]) {
                Some(Ok(Message::Output(report))) => break report,
                Some(other) => return Err(DcpError::Check(format!("unexpected reply from the chip: {other:?}"))),
                None => {}
            }
        };
        let mut read = |n: usize| -> Result<Vec<u8>, DcpError> {
            let mut buf = vec![0u8; n];
            self.dcp.read_exact(&mut buf).map_err(io("no DCP record of the step from the chip"))?;
            Ok(buf)
        };
        let n_in = read(1)?[0] as usize;
        let dcp_taken = read(n_in)?;
        let n_out = read(1)?[0] as usize;
        let dcp_replies = read(n_out)?;
        let n_service = read(1)?[0] as usize;
        let service_taken = read(n_service)?;
        let observer = read(9)?;
        let observer_ticks =
            (observer[0] != 0).then(|| u32::from_le_bytes([observer[1], observer[2], observer[3], observer[4]]));
        let after_ticks = u32::from_le_bytes([observer[5], observer[6], observer[7], observer[8]]);
        Ok(ChipStep { report, dcp_taken, dcp_replies, service_taken, observer_ticks, after_ticks })
    }

    /// `n` bytes the chip sent on the service port.
    pub fn read_service(&mut self, n: usize) -> Result<Vec<u8>, DcpError> {
        let mut buf = vec![0u8; n];
        self.service.read_exact(&mut buf).map_err(io("no service answer from the chip"))?;
        Ok(buf)
    }
}

/// The shadow's edges: the bytes to take, the replies and answers it gives.
struct ShadowIo<'a> {
    dcp: &'a mut std::collections::VecDeque<u8>,
    service: &'a mut std::collections::VecDeque<u8>,
    replies: Vec<u8>,
    answers: Vec<u8>,
    saved: Option<DriveParameters>,
}

impl PeriodIo for ShadowIo<'_> {
    fn service_byte(&mut self) -> Option<u8> {
        self.service.pop_front()
    }

    fn dcp_byte(&mut self) -> Option<u8> {
        self.dcp.pop_front()
    }

    fn drive(&mut self, _output: &DriveOutput) {}

    fn service_reply(&mut self, reply: &ServiceReply) {
        self.answers.extend_from_slice(reply.line().as_bytes());
        self.saved = self.saved.or(reply.save);
    }

    fn dcp_reply(&mut self, reply: &[u8; 6]) {
        self.replies.extend_from_slice(reply);
    }
}

/// One step of [`Lift`].
#[derive(Clone, Debug, PartialEq)]
pub struct LiftStep {
    /// The outputs (the chip's and the shadow's: equal).
    pub output: ControlOutput,
    /// The DCP replies of the step.
    pub dcp_replies: Vec<u8>,
    /// The service answers of the step.
    pub service_answers: Vec<u8>,
    /// The parameters a `save` of the step wrote (the shadow's view).
    pub saved: Option<DriveParameters>,
    /// The chip's control step up to its outputs (what must be done
    /// before the PWM valley), instructions (SysTick ticks of the 25 MHz
    /// clock under `-icount shift=5`: 1.25 instructions a tick); `None`
    /// for the host build alone.
    pub instructions: Option<f64>,
    /// The rest of the chip's period before the observer's task (the
    /// compensation's learning, the service and DCP bytes), instructions.
    pub after_instructions: Option<f64>,
    /// Whether the chain observer's task ran after the step (the shadow's).
    pub observer_ran: bool,
    /// The chip's observer task after the step, instructions, if it ran
    /// (`None` also for the host build alone).
    pub observer_instructions: Option<f64>,
}

/// The lift: the plant, the chip and its shadow, stepped together (or the
/// host build alone, [`Lift::host_only`]).
pub struct Lift {
    plant: Plant,
    chip: Option<Chip>,
    /// Host only: the bytes on the lines not taken yet (DCP, service).
    pending: (std::collections::VecDeque<u8>, std::collections::VecDeque<u8>),
    shadow: LiftDrive,
    drive: DriveConfig,
    max_step_s: f64,
    lw_lowest_landing_m: f64,
    steps: u64,
    /// The chip's latest period, instructions (the step to its outputs and
    /// the rest before the observer's task).
    last_period_instructions: Option<f64>,
}

impl Lift {
    /// The plant with the car at `lw_start_m` (m of counterweight-side rope)
    /// and mass `m_car_kg`, the chip (started by [`Chip::launch`]; `None`:
    /// the host build alone, which takes the bytes on the lines as the chip
    /// does, at most 8 DCP bytes and one service line a step) and its shadow
    /// started with `parameters` (`status`: what became of the stored
    /// record, as the chip is expected to find it).
    pub fn new(
        rig: &RigConfig,
        chip: Option<Chip>,
        parameters: &DriveParameters,
        status: ParamsStatus,
        m_car_kg: f64,
        lw_start_m: f64,
    ) -> Result<Self, DcpError> {
        let (geometry, _) = geometry(rig);
        let lw_low = geometry.lw_lowest_landing_m as f64;
        let lw_high = lw_low + geometry.shaft_travel_mm as f64 / 1000.0;
        ensure!(
            (lw_low..=lw_high).contains(&lw_start_m),
            "the car must start between the landings: lw {lw_start_m} m is outside [{lw_low}, {lw_high}] m"
        );
        Ok(Self {
            plant: Plant::new(rig, m_car_kg, lw_start_m),
            chip,
            pending: Default::default(),
            shadow: shadow(rig, parameters, status),
            drive: rig.drive_config(),
            max_step_s: crate::SimOptions::for_rig(rig).max_step_s,
            lw_lowest_landing_m: lw_low,
            steps: 0,
            last_period_instructions: None,
        })
    }

    /// The car position measured in the shaft, mm above the lowest landing.
    pub fn position_mm(&self) -> f64 {
        (self.plant.observe().counterweight_side_length_m - self.lw_lowest_landing_m) * 1000.0
    }

    /// Steps run.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// The chip's latest period up to the observer's task, instructions
    /// (`None` for the host build alone): after [`Lift::ask`], the period
    /// that carried the request out.
    pub fn last_period_instructions(&self) -> Option<f64> {
        self.last_period_instructions
    }

    /// The shadow (state, parameters, DCP port).
    pub fn shadow(&self) -> &LiftDrive {
        &self.shadow
    }

    /// The plant (its car acceleration, rope lengths).
    pub fn plant(&self) -> &Plant {
        &self.plant
    }

    /// One PWM period: `dcp_out` on the DCP line, `service_out` on the
    /// service port, the chip's step checked against the shadow's, the
    /// plant advanced.
    pub fn step(&mut self, dcp_out: &[u8], service_out: &[u8]) -> Result<LiftStep, DcpError> {
        self.step_sensing(dcp_out, service_out, &mut |_| {})
    }

    /// [`Lift::step`] with the plant's sensor frame changed by `sense`
    /// before the chip and the shadow get it (a sensor fault).
    pub fn step_sensing(
        &mut self,
        dcp_out: &[u8],
        service_out: &[u8],
        sense: &mut dyn FnMut(&mut SensorFrame),
    ) -> Result<LiftStep, DcpError> {
        let k = self.steps;
        let mut sensors = crate::sensor_frame(&self.plant);
        sense(&mut sensors);
        let chip = match self.chip.as_mut() {
            Some(chip) => {
                Some(chip.step(dcp_out, service_out, &sensors).map_err(|e| DcpError::Check(format!("step {k}: {e}")))?)
            }
            None => None,
        };
        // The shadow takes what the chip took; alone, what is on the lines
        // (by the same rule: at most 8 DCP bytes, one service line).
        let (mut replayed, lines) = (Default::default(), &mut self.pending);
        let (dcp_in, service_in) = match &chip {
            Some(chip) => {
                replayed = (chip.dcp_taken.iter().copied().collect(), chip.service_taken.iter().copied().collect());
                (&mut replayed.0, &mut replayed.1)
            }
            None => {
                lines.0.extend(dcp_out);
                lines.1.extend(service_out);
                (&mut lines.0, &mut lines.1)
            }
        };
        let mut io =
            ShadowIo { dcp: dcp_in, service: service_in, replies: Vec::new(), answers: Vec::new(), saved: None };
        let period = self.shadow.period(&sensors, &mut io);
        let ShadowIo { replies: dcp_replies, answers: expected_answers, saved, .. } = io;
        ensure!(
            replayed.0.is_empty() && replayed.1.is_empty(),
            "step {k}: the shadow left bytes the chip took (DCP {:02x?}, service {:02x?})",
            replayed.0,
            replayed.1
        );
        let output = period.drive.control;
        let observer_ran = period.observer_ran;
        let instructions = chip.as_ref().map(|c| c.report.cost_ticks as f64 * INSTRUCTIONS_PER_TICK);
        let after_instructions = chip.as_ref().map(|c| c.after_ticks as f64 * INSTRUCTIONS_PER_TICK);
        self.last_period_instructions = instructions.zip(after_instructions).map(|(a, b)| a + b);
        let observer_instructions =
            chip.as_ref().and_then(|c| c.observer_ticks).map(|t| t as f64 * INSTRUCTIONS_PER_TICK);
        if let Some(chip) = &chip {
            ensure!(
                chip.observer_ticks.is_some() == observer_ran,
                "step {k}: the observer task ran on the {} only",
                if observer_ran { "host" } else { "chip" }
            );
        }
        let service_answers = match (self.chip.as_mut(), chip) {
            (Some(c), Some(chip)) => {
                let answers = c.read_service(expected_answers.len())?;
                Self::compare(k, &sensors, &chip, &answers, &expected_answers, &dcp_replies, &output)?;
                answers
            }
            _ => expected_answers,
        };
        self.plant.set_inputs(PlantInputs {
            pwm_compare: output.pwm_compare,
            pwm_enabled: output.pwm_enabled,
            brake_engaged: !output.brake_released,
        });
        self.plant.advance(1.0 / self.drive.current_loop_hz as f64, self.max_step_s);
        ensure!(self.plant.in_valid_range(), "step {k}: the plant left its valid range");
        self.steps += 1;
        Ok(LiftStep {
            output,
            dcp_replies,
            service_answers,
            saved,
            instructions,
            after_instructions,
            observer_ran,
            observer_instructions,
        })
    }

    /// Sends the service request `line` (without its `\n`) and steps until
    /// its answer has come (at most `max_steps`): the answer without its
    /// `\r\n`, and the parameters a `save` wrote. Nothing goes on the DCP line.
    pub fn ask(&mut self, line: &str, max_steps: u64) -> Result<(String, Option<DriveParameters>), DcpError> {
        let mut request = line.as_bytes().to_vec();
        request.push(b'\n');
        let mut answer = Vec::new();
        let mut saved = None;
        for i in 0..max_steps {
            let step = self.step(&[], if i == 0 { &request } else { &[] })?;
            answer.extend_from_slice(&step.service_answers);
            saved = saved.or(step.saved);
            if answer.ends_with(b"\r\n") {
                answer.truncate(answer.len() - 2);
                return Ok((String::from_utf8_lossy(&answer).into_owned(), saved));
            }
        }
        Err(DcpError::Check(format!("no answer to {line:?} within {max_steps} steps")))
    }

    /// The chip's step against the shadow's.
    fn compare(
        k: u64,
        sensors: &SensorFrame,
        chip: &ChipStep,
        service_answers: &[u8],
        expected_answers: &[u8],
        dcp_replies: &[u8],
        output: &ControlOutput,
    ) -> Result<(), DcpError> {
        ensure!(
            service_answers == expected_answers,
            "step {k}: service answers differ: chip {:?}, host {:?}",
            String::from_utf8_lossy(service_answers),
            String::from_utf8_lossy(expected_answers)
        );
        ensure!(
            chip.dcp_replies == dcp_replies,
            "step {k}: DCP replies differ: chip {:02x?}, host {:02x?}",
            chip.dcp_replies,
            dcp_replies
        );
        ensure!(
            chip.report.matches(output),
            "step {k}: first differing step\n  inputs {sensors:?}\n  host   {:?}\n  target {:?}",
            StepReport::new(output, chip.report.cost_ticks),
            chip.report
        );
        Ok(())
    }
}

/// Core clock of the STM32G474 the load is given against, Hz.
pub const CORE_CLOCK_HZ: f64 = 170.0e6;

/// The load of the control interrupt and the chain observer's task on the
/// emulated chip, from the instructions of each step (one cycle counted
/// per instruction: a lower bound of the cycles on the real M4), over the
/// steps with the inverter on.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CpuLoad {
    /// Steps counted (inverter on).
    pub steps: u64,
    /// Control steps' instructions, summed.
    pub control_instructions: f64,
    /// Largest control step (to the outputs), instructions.
    pub control_max: f64,
    /// The rest of the periods' work before the observer's task, summed, instructions.
    pub after_instructions: f64,
    /// Largest whole period without the observer's task (control step and
    /// the rest), instructions.
    pub period_max: f64,
    /// Observer runs counted.
    pub observer_runs: u64,
    /// Observer runs' instructions, summed.
    pub observer_instructions: f64,
    /// Largest observer run, instructions.
    pub observer_max: f64,
    /// Largest sum over one speed-loop period: the control steps of the
    /// `divider` PWM periods up to an observer run, and that run, instructions.
    pub worst_speed_period: f64,
    recent: std::collections::VecDeque<f64>,
    divider: usize,
    pwm_hz: f64,
}

impl CpuLoad {
    /// For `drive`'s PWM rate and speed-loop divider.
    pub fn new(drive: &DriveConfig) -> Self {
        Self {
            divider: drive.speed_loop_divider().max(1) as usize,
            pwm_hz: drive.current_loop_hz as f64,
            ..Self::default()
        }
    }

    /// CPU cycles of one PWM period at [`CORE_CLOCK_HZ`] (10 625 at 16 kHz).
    pub fn cycles_per_period(&self) -> f64 {
        CORE_CLOCK_HZ / self.pwm_hz
    }

    /// Adds a step of the chip (a step without the chip's figures or with
    /// the inverter off is not counted).
    pub fn add(&mut self, step: &LiftStep) {
        let Some(control) = step.instructions else { return };
        if !step.output.pwm_enabled {
            self.recent.clear();
            return;
        }
        let after = step.after_instructions.unwrap_or(0.0);
        self.steps += 1;
        self.control_instructions += control;
        self.control_max = self.control_max.max(control);
        self.after_instructions += after;
        self.period_max = self.period_max.max(control + after);
        self.recent.push_back(control + after);
        if self.recent.len() > self.divider {
            self.recent.pop_front();
        }
        if let Some(observer) = step.observer_instructions {
            self.observer_runs += 1;
            self.observer_instructions += observer;
            self.observer_max = self.observer_max.max(observer);
            self.worst_speed_period = self.worst_speed_period.max(self.recent.iter().sum::<f64>() + observer);
        }
    }

    /// Mean control step, instructions.
    pub fn control_mean(&self) -> f64 {
        self.control_instructions / self.steps.max(1) as f64
    }

    /// Mean observer run, instructions.
    pub fn observer_mean(&self) -> f64 {
        self.observer_instructions / self.observer_runs.max(1) as f64
    }

    /// Mean load, % of a 170 MHz core: the instructions of the control
    /// steps and the observer runs over the cycles of the steps counted.
    pub fn mean_percent(&self) -> f64 {
        100.0 * (self.control_instructions + self.after_instructions + self.observer_instructions)
            / (self.steps.max(1) as f64 * self.cycles_per_period())
    }

    /// Load of the busiest speed-loop period, % of a 170 MHz core.
    pub fn worst_period_percent(&self) -> f64 {
        100.0 * self.worst_speed_period / (self.divider as f64 * self.cycles_per_period())
    }

    /// One line: the load, and what it is made of.
    pub fn summary(&self) -> String {
        let mut line = format!(
            "CPU load of a 170 MHz core (one cycle an instruction) over {} steps with the inverter on: {:.1} % mean",
            self.steps,
            self.mean_percent()
        );
        if self.observer_runs > 0 {
            line += &format!(", {:.1} % in the busiest speed-loop period", self.worst_period_percent());
        }
        line += &format!(
            "; control interrupt {:.0} instructions a step to the outputs (max {:.0}), {:.0} a whole period (max {:.0})",
            self.control_mean(),
            self.control_max,
            (self.control_instructions + self.after_instructions) / self.steps.max(1) as f64,
            self.period_max
        );
        if self.observer_runs > 0 {
            line += &format!(
                ", chain observer task {:.0} instructions a run (max {:.0}), {} runs ({:.0} Hz)",
                self.observer_mean(),
                self.observer_max,
                self.observer_runs,
                self.observer_runs as f64 / self.steps.max(1) as f64 * self.pwm_hz,
            );
        }
        line
    }
}

/// PWM periods between two messages of the lift controller: 15 ms.
pub const CYCLE_STEPS: u64 = 240;

/// A travel the lift controller asks for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trip {
    /// Target landing, mm above the lowest landing.
    pub target_mm: i32,
    /// The speed bit it selects (DCP4: V4, the drive's travel speed).
    pub speed: Speed,
}

/// Where the lift controller is in its sequence.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Phase {
    /// Sending the position message (messages sent so far).
    Position(u32),
    /// Selecting the speed.
    Select,
    /// DCP4: the remaining distance, until the drive has stopped.
    Distance {
        /// The drive showed the travel running.
        started: bool,
    },
    /// DCP3: travel at the selected speed, until the deceleration point.
    Travel {
        /// The drive showed the travel running.
        started: bool,
    },
    /// DCP3: deceleration to crawl, until the stopping point.
    Crawl,
    /// DCP3: stop (stop switch cleared), until the drive has stopped.
    Stopping,
    /// After the arrival: the stop message.
    Stop,
    /// Drive enable cleared; then the next trip.
    Idle,
    /// Every trip done: idle messages.
    Done,
}

/// One finished trip.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Arrival {
    /// The trip.
    pub trip: Trip,
    /// Step at which the drive had stopped (brake applied, inverter off).
    pub step: u64,
    /// Car position then, mm above the lowest landing.
    pub position_mm: f64,
    /// Step at which the trip began (first message of its position message).
    pub start_step: u64,
}

/// A lift controller: one message every 15 ms ([`CYCLE_STEPS`]); before
/// each trip the car position (message `I9`) and the speed; in DCP4 the
/// remaining distance to the target until the drive has stopped; in DCP3
/// the travel command until the deceleration point, the deceleration to
/// crawl until the stopping point, then the stop. The deceleration and
/// stopping points come from the drive's speeds (`speed_table`) and its
/// acceleration and jerk limits, as a lift controller is set up for its
/// drive, and from the car position measured in the shaft.
pub struct Master {
    mode: Mode,
    trips: Vec<Trip>,
    phase: Phase,
    next_message_step: u64,
    channel: Vec<u8>,
    last_status: u8,
    /// Every reply, in order.
    pub replies: Vec<SlaveFrame>,
    /// The finished trips.
    pub arrivals: Vec<Arrival>,
    /// Stop talking at this step (the silent master).
    pub silent_from: Option<u64>,
    /// Step of the last message sent.
    pub last_sent: u64,
    trip_start: u64,
    /// The trip's direction, fixed when it begins.
    down: bool,
    speeds: [Option<f32>; 11],
    accel_mps2: f32,
    jerk_mps3: f32,
}

/// Distance to change speed from `from` to `to` (m/s) from and to zero
/// acceleration with limits `a` (m/s^2) and `j` (m/s^3), m.
fn ramp_distance_m(from: f64, to: f64, a: f64, j: f64) -> f64 {
    let dv = (from - to).abs();
    let duration = if dv * j >= a * a { dv / a + a / j } else { 2.0 * (dv / j).sqrt() };
    0.5 * (from + to) * duration
}

/// Crawl run before the stopping point, m: time for the messages to follow.
const CRAWL_M: f64 = 0.03;

impl Master {
    /// A controller speaking `mode` to a drive of `drive`'s limits, for `trips` in turn.
    pub fn new(mode: Mode, trips: Vec<Trip>, drive: &DriveConfig) -> Self {
        Self {
            mode,
            trips,
            phase: Phase::Position(0),
            next_message_step: 0,
            channel: Vec::new(),
            last_status: 0,
            replies: Vec::new(),
            arrivals: Vec::new(),
            silent_from: None,
            last_sent: 0,
            trip_start: 0,
            down: false,
            speeds: speed_table(drive.rated_speed_mps),
            accel_mps2: drive.max_accel_mps2,
            jerk_mps3: drive.max_jerk_mps3,
        }
    }

    /// Where it is in its sequence.
    pub fn phase(&self) -> Phase {
        self.phase
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

    fn speed_mps(&self, speed: Speed) -> f64 {
        self.speeds[speed.index()].unwrap_or(0.0) as f64
    }

    /// The bytes to put on the line at step `k` with the car `position_mm` above the lowest landing.
    pub fn bytes(&mut self, k: u64, position_mm: f64) -> Vec<u8> {
        if k < self.next_message_step || self.silent_from.is_some_and(|s| k >= s) {
            return Vec::new();
        }
        self.next_message_step = k + CYCLE_STEPS;
        self.last_sent = k;
        let trip = self.trips.first().copied();
        if self.phase == Phase::Position(0) {
            self.down = trip.is_some_and(|t| (t.target_mm as f64) < position_mm);
        }
        let down = self.down;
        // Distance ahead in the travel's direction, m (negative once past).
        let ahead_m = trip.map_or(0.0, |t| {
            let d = (t.target_mm as f64 - position_mm) / 1000.0;
            if down {
                -d
            } else {
                d
            }
        });
        let travelling = self.last_status & (S1_TRAVEL | S6_BRAKE_OPEN) != 0;
        let (a, j) = (self.accel_mps2 as f64, self.jerk_mps3 as f64);
        let crawl = self.speed_mps(Speed::V0);
        match self.phase {
            Phase::Position(sent) => {
                if sent == 0 {
                    self.trip_start = k;
                    self.channel.extend_from_slice(&position_message(position_mm.round() as i32));
                }
                // 12 bytes out in 6 messages, 3 more for the answer.
                self.phase = if sent + 1 >= 9 { Phase::Select } else { Phase::Position(sent + 1) };
                self.message(Kind::Stop, down, [0, 0])
            }
            Phase::Select => {
                let Some(trip) = trip else {
                    self.phase = Phase::Done;
                    return self.message(Kind::Idle, false, [0, 0]);
                };
                self.phase = match self.mode {
                    Mode::Dcp4 => Phase::Distance { started: false },
                    Mode::Dcp3 => Phase::Travel { started: false },
                };
                self.message(Kind::SpeedMode, down, trip.speed.data())
            }
            Phase::Distance { started } => {
                if started && !travelling {
                    return self.arrive(k, position_mm, down);
                }
                self.phase = Phase::Distance { started: started || travelling };
                // The remaining distance (0 once there or past it).
                let remaining = (ahead_m * 1000.0).max(0.0).round().min(32_767.0) as u16;
                self.message(Kind::Decelerate, down, remaining.to_be_bytes())
            }
            Phase::Travel { started } => {
                let speed = trip.map_or(0.0, |t| self.speed_mps(t.speed));
                let decelerate_at = ramp_distance_m(speed, crawl, a, j) + CRAWL_M;
                if started && !travelling {
                    // Stopped by itself (the shaft end): the trip is over.
                    return self.arrive(k, position_mm, down);
                }
                if started && ahead_m <= decelerate_at {
                    self.phase = Phase::Crawl;
                    return self.message(Kind::Decelerate, down, [0, 0]);
                }
                self.phase = Phase::Travel { started: started || travelling };
                self.message(Kind::Travel, down, [0, 0])
            }
            Phase::Crawl => {
                if ahead_m <= ramp_distance_m(crawl, 0.0, a, j) {
                    self.phase = Phase::Stopping;
                    return self.message(Kind::Stop, down, [0, 0]);
                }
                self.message(Kind::Decelerate, down, [0, 0])
            }
            Phase::Stopping => {
                if !travelling {
                    return self.arrive(k, position_mm, down);
                }
                self.message(Kind::Stop, down, [0, 0])
            }
            Phase::Stop => {
                self.phase = Phase::Idle;
                self.message(Kind::Idle, false, [0, 0])
            }
            Phase::Idle => {
                if !self.trips.is_empty() {
                    self.trips.remove(0);
                }
                self.phase = if self.trips.is_empty() { Phase::Done } else { Phase::Position(0) };
                self.message(Kind::Idle, false, [0, 0])
            }
            Phase::Done => self.message(Kind::Idle, false, [0, 0]),
        }
    }

    fn arrive(&mut self, k: u64, position_mm: f64, down: bool) -> Vec<u8> {
        if let Some(&trip) = self.trips.first() {
            self.arrivals.push(Arrival { trip, step: k, position_mm, start_step: self.trip_start });
        }
        self.phase = Phase::Stop;
        self.message(Kind::Stop, down, [0, 0])
    }

    /// Takes the drive's replies of a step (whole 6-byte messages).
    pub fn receive(&mut self, replies: &[u8]) -> Result<(), DcpError> {
        ensure!(replies.len() % 6 == 0, "a partial DCP reply: {replies:02x?}");
        for chunk in replies.chunks(6) {
            let bytes: [u8; 6] = chunk.try_into().expect("chunks of 6");
            let frame = SlaveFrame::decode(&bytes)
                .map_err(|e| DcpError::Check(format!("a bad DCP reply ({e:?}): {bytes:02x?}")))?;
            self.last_status = frame.status;
            self.replies.push(frame);
        }
        Ok(())
    }
}

/// The default PIL target ELF: `pil/target/thumbv7em-none-eabihf/release/pil`
/// (`PIL_ELF` overrides it).
pub fn default_elf() -> PathBuf {
    std::env::var_os("PIL_ELF").map(PathBuf::from).unwrap_or_else(crate::pil::default_elf_path)
}
