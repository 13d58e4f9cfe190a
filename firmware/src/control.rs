//! The control interrupt: one `drive_core::Controller::step` per PWM period, in
//! ADC2's end-of-injected-sequence interrupt (`ADC1_2`, the highest priority),
//! and the state it shares with the telemetry task.
//!
//! Each period, about 1.5 us after the PWM counter peak triggered the
//! conversions, the interrupt
//! 1. reads the time stamp (TIM2), the encoder (TIM4) and the four injected
//!    conversions (ADC1/ADC2 JDR1-2), and TIM1's break flag;
//! 2. applies at most one queued command (travel, align or reset);
//! 3. runs the start-up sequence (`drive_core::startup`: settling, the
//!    current-offset calibration with the outputs off, the safe state until
//!    the alignment is commanded, the protected alignment), afterwards
//!    steps the controller with the offset-corrected codes;
//! 4. writes the three compares (taking effect at the next PWM valley), sets
//!    MOE from `pwm_enabled` and drives the brake from `brake_released`
//!    (released only while the inverter is on), unless a firmware fault is
//!    latched;
//! 5. latches an overrun if the compares were written after the valley that
//!    follows the sample (TIM1 no longer counting down, or half a period
//!    gone by the DWT cycle counter: `drive_core::pwm_timing`), or if the
//!    next sequence completed before the step finished;
//! 6. every [`RECORD_DECIMATION`]th step queues a telemetry record.
//!
//! Sharing: the interrupt owns the controller, inside a
//! `critical_section::Mutex`; the telemetry task never touches it. The chain
//! observer's task (`observer.rs`, a lower-priority interrupt executor)
//! gets each input the controller publishes through an Embassy `Signal`
//! and signals its output back, which the interrupt delivers to the
//! controller at the start of a step (the observer module does not call
//! into this one). The task and the
//! interrupt exchange commands, events and records through `heapless`
//! queues behind critical sections, each held for one push or pop (a few
//! hundred cycles at most, the longest the task can delay the interrupt).
//!
//! Firmware faults latch on top of the controller's own supervisor: PWM off
//! (MOE = 0), brake applied, until a reset command (the service port's
//! `reset`); after a failed calibration the reset calibrates again.

use core::cell::{Cell, RefCell};
use core::sync::atomic::{AtomicU32, AtomicU8, Ordering};

use cortex_m::peripheral::DWT;
use critical_section::{CriticalSection, Mutex};
use drive_core::alignment::AlignmentError;
use drive_core::controller::Telemetry;
use drive_core::current_offset::{CurrentOffsets, OffsetError};
use drive_core::lift_drive::{self, ApplyError, ControllerCommand};
use drive_core::pwm_timing::compares_in_time;
use drive_core::ripple::harmonics::HarmonicTable;
use drive_core::startup::{
    Startup, StartupCommand, StartupEvent, StartupFault, StartupOutput, StartupRefusal, StartupStep,
};
use drive_core::supervisor::Fault;
use drive_core::{ControlOutput, Controller, DriveState, SensorFrame};
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::{InterruptExt, Priority};
use heapless::Deque;

use crate::adc::{self, Incomplete, Samples};
use crate::encoder::{self, Extender};
use crate::{board, observer, pwm, timebase, DRIVE_CONFIG};

/// Every how many steps the interrupt queues a telemetry record (16: 1 kHz).
pub const RECORD_DECIMATION: u32 = 16;

/// Telemetry records the queue holds: 32 ms at 1 kHz, against the task's
/// 10 ms polling period.
pub const RECORD_CAPACITY: usize = 32;

const EVENT_CAPACITY: usize = 8;
const COMMAND_CAPACITY: usize = 4;

/// A command from the task, applied by the interrupt at its next step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Command {
    /// A command of the DCP slave: a distance or speed travel (accepted
    /// only when calibrated, fault-free and idle), a speed change or stop of
    /// a speed travel, or a safe stop (inverter off, brake applied: the DCP
    /// slave's timeout or a travel interruption; it changes nothing when
    /// idle or tripped, and never clears a fault).
    Drive(ControllerCommand),
    /// Clear latched faults: the controller's, the firmware's (overrun,
    /// break, ADC) and the start-up sequence's (a failed calibration
    /// calibrates again). Refused when nothing is latched, so that it can
    /// never stop a running travel. From the service port's `reset`.
    Reset,
    /// Run the rotor alignment (brake open, current injected): accepted
    /// only in the safe state after the calibration, with nothing latched.
    /// From the service port's `align`.
    Align,
}

/// Why a command was not applied.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    /// Refused by the controller.
    Controller(ApplyError),
    /// The drive is still calibrating or not aligned, or a fault is latched.
    NotReady,
    /// The start-up sequence is not waiting for that command.
    Busy,
    /// Reset with no fault latched.
    NothingToReset,
}

/// A firmware-level fault, latched by the interrupt.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FirmwareFault {
    /// A step wrote its compares after the valley that follows its sample
    /// (they would take effect a period late).
    Overrun {
        /// Cycles from the step's start to its compare write, CPU cycles (170 per microsecond).
        cycles: u32,
    },
    /// The next conversion sequence completed before the step finished.
    TriggerOverrun,
    /// The inverter's over-current comparator tripped TIM1's break input
    /// (the hardware had already switched every gate off).
    InverterBreak,
    /// ADC1's sequence had not completed when ADC2's had.
    AdcSequenceIncomplete,
    /// The start-up current-offset calibration was rejected.
    Calibration(OffsetError),
    /// The commanded rotor alignment failed its checks.
    Alignment(AlignmentError),
    /// A protection tripped while the alignment switched the bridge.
    Protection(Fault),
}

impl From<StartupFault> for FirmwareFault {
    fn from(fault: StartupFault) -> Self {
        match fault {
            StartupFault::Calibration(e) => FirmwareFault::Calibration(e),
            StartupFault::Alignment(e) => FirmwareFault::Alignment(e),
            StartupFault::Protection(f) => FirmwareFault::Protection(f),
        }
    }
}

/// Something the task should log.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Event {
    /// The current-offset calibration passed; the drive is idle and accepts
    /// commands.
    Calibrated(CurrentOffsets),
    /// The rotor alignment passed: the encoder count at electrical angle zero.
    Aligned(u32),
    /// A firmware fault was latched.
    Fault(FirmwareFault),
    /// A command was applied.
    Applied(Command),
    /// A command was refused.
    Refused(Command, Refusal),
}

/// One decimated snapshot of a step, for the telemetry task.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Record {
    /// Step number since start (wraps), PWM periods.
    pub step: u32,
    /// Time stamp of the step's sample, microseconds (wraps).
    pub time_us: u32,
    /// Controller state, `None` while calibrating or after a failed
    /// calibration.
    pub state: Option<DriveState>,
    /// Latched firmware fault.
    pub fault: Option<FirmwareFault>,
    /// Inverter outputs on (MOE) after the step.
    pub pwm_on: bool,
    /// Brake released after the step.
    pub brake_released: bool,
    /// Phase-current codes U, V, W: offset-corrected once calibrated, raw
    /// before, ADC codes.
    pub phase_codes: [u16; 3],
    /// DC-bus code, ADC code.
    pub dc_bus_code: u16,
    /// Extended encoder count, counts.
    pub encoder_count: u32,
    /// Compares written, timer ticks.
    pub compare: [u16; 3],
    /// Duration of the step, CPU cycles.
    pub cycles: u32,
    /// The controller's telemetry (all zero before it runs).
    pub telemetry: Telemetry,
}

/// The drive as the DCP task sees it, written by every step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Snapshot {
    /// Controller state after the latest step (`None` before it runs).
    pub state: Option<DriveState>,
    /// Estimated shaft speed, rad/s.
    pub speed_radps: f32,
    /// Current offsets calibrated, rotor aligned and no firmware fault latched.
    pub ready_gate: bool,
    /// A fault is latched: the firmware's, the start-up sequence's or the
    /// controller's (the DCP status's fault bit).
    pub fault: bool,
    /// The drive waits in its safe state for the alignment command.
    pub awaiting_alignment: bool,
    /// Inverter outputs on after the latest step (also during the alignment).
    pub pwm_on: bool,
    /// Brake released after the latest step (also during the alignment).
    pub brake_released: bool,
}

/// The harmonic table to keep in the parameter record
/// (`drive_core::lift_drive::kept_table`: what the controller learned in
/// its latest travel with a learning strategy, else the table installed;
/// `installed` before the controller runs), N m. Copies the controller's
/// table in a critical section: call it with the control interrupt paused.
pub fn kept_table(installed: &HarmonicTable) -> HarmonicTable {
    critical_section::with(|cs| {
        DRIVE.borrow_ref(cs).as_ref().map_or(*installed, |d| lift_drive::kept_table(&d.controller, installed))
    })
}

/// Speed-loop ticks whose observer estimate was not back in time, since start.
pub fn observer_missed_deadlines() -> u32 {
    critical_section::with(|cs| DRIVE.borrow_ref(cs).as_ref().map_or(0, |d| d.controller.observer_missed_deadlines()))
}

/// The latest [`Snapshot`].
pub fn snapshot() -> Snapshot {
    critical_section::with(|cs| SNAPSHOT.borrow(cs).get())
}

struct Drive {
    controller: Controller,
    /// Settling, calibration, the safe state until the alignment command,
    /// the commanded alignment (`drive_core::startup`).
    startup: Startup,
    fault: Option<FirmwareFault>,
    encoder: Extender,
    brake: board::Brake,
    steps: u32,
}

static DRIVE: Mutex<RefCell<Option<Drive>>> = Mutex::new(RefCell::new(None));
static RECORDS: Mutex<RefCell<Deque<Record, RECORD_CAPACITY>>> = Mutex::new(RefCell::new(Deque::new()));
static EVENTS: Mutex<RefCell<Deque<Event, EVENT_CAPACITY>>> = Mutex::new(RefCell::new(Deque::new()));
static COMMANDS: Mutex<RefCell<Deque<Command, COMMAND_CAPACITY>>> = Mutex::new(RefCell::new(Deque::new()));
static SNAPSHOT: Mutex<Cell<Snapshot>> = Mutex::new(Cell::new(Snapshot {
    state: None,
    speed_radps: 0.0,
    ready_gate: false,
    fault: false,
    awaiting_alignment: false,
    pwm_on: false,
    brake_released: false,
}));
static STEPS: AtomicU32 = AtomicU32::new(0);
/// What the controller made of the latest DCP remaining distance: 0 not
/// yet read, [`REMAINING_TAKEN`] or [`REMAINING_REFUSED`].
static REMAINING: AtomicU8 = AtomicU8::new(0);
const REMAINING_TAKEN: u8 = 1;
const REMAINING_REFUSED: u8 = 2;

/// Whether the controller refused (`Some(false)`) or took (`Some(true)`)
/// the latest remaining distance of a DCP4 travel since the previous call;
/// the DCP task tells its slave (S5 in the replies).
pub fn take_remaining_outcome() -> Option<bool> {
    match REMAINING.swap(0, Ordering::Relaxed) {
        REMAINING_TAKEN => Some(true),
        REMAINING_REFUSED => Some(false),
        _ => None,
    }
}
static MAX_CYCLES: AtomicU32 = AtomicU32::new(0);
static DROPPED: AtomicU32 = AtomicU32::new(0);

/// Hands the controller and the brake pin to the interrupt and enables it.
/// Call after `pwm::init` and `adc::init`; the drive then settles,
/// calibrates and stays in its safe state (gates off, brake applied) until
/// the alignment is commanded ([`Command::Align`]).
pub fn start(controller: Controller, brake: board::Brake) {
    critical_section::with(|cs| {
        let startup = Startup::new(&DRIVE_CONFIG, *controller.supervisor_limits());
        DRIVE.borrow_ref_mut(cs).replace(Drive {
            controller,
            startup,
            fault: None,
            encoder: Extender::new(encoder::raw_count()),
            brake,
            steps: 0,
        });
    });
    adc::clear_flags();
    // The Embassy time driver's timer (TIM15) shares its vector with TIM1's
    // break; below the control interrupt, it can never delay a step.
    interrupt::TIM1_BRK_TIM15.set_priority(Priority::P1);
    interrupt::ADC1_2.set_priority(Priority::P0);
    interrupt::ADC1_2.unpend();
    enable_control_interrupt();
}

#[allow(unsafe_code)]
fn enable_control_interrupt() {
    // SAFETY: unmasking ADC1_2 is sound: its handler below only touches state
    // behind critical-section mutexes and atomics, and the registers of TIM1,
    // TIM2, TIM4, ADC1 and ADC2, which no other code writes once `start`
    // runs. Nothing relies on ADC1_2 staying masked (no embassy driver is
    // bound to it).
    unsafe { interrupt::ADC1_2.enable() };
}

/// Pauses the control interrupt for a flash write if the drive is idle
/// (running, no travel: inverter off, brake applied) or tripped and no
/// command waits for it; whether it did. Resume with [`resume`].
pub fn pause_if_idle() -> bool {
    critical_section::with(|cs| {
        let drive = DRIVE.borrow_ref(cs);
        let waiting = !COMMANDS.borrow_ref(cs).is_empty();
        let idle = !waiting
            && drive.as_ref().is_some_and(|d| {
                d.startup.is_waiting_for_alignment()
                    || (d.startup.is_running()
                        && matches!(d.controller.state(), DriveState::Idle | DriveState::Tripped(_)))
            });
        if idle {
            interrupt::ADC1_2.disable();
        }
        idle
    })
}

/// Resumes the control interrupt after [`pause_if_idle`]: the conversions
/// that completed meanwhile are dropped and the controller does not count
/// the pause as a missed deadline.
pub fn resume() {
    critical_section::with(|cs| {
        adc::clear_flags();
        interrupt::ADC1_2.unpend();
        if let Some(drive) = DRIVE.borrow_ref_mut(cs).as_mut() {
            drive.controller.resume_after_pause();
        }
    });
    enable_control_interrupt();
}

/// Queues a command for the interrupt; gives it back if the queue is full.
pub fn submit(command: Command) -> Result<(), Command> {
    critical_section::with(|cs| COMMANDS.borrow_ref_mut(cs).push_back(command))
}

/// The oldest queued telemetry record.
pub fn pop_record() -> Option<Record> {
    critical_section::with(|cs| RECORDS.borrow_ref_mut(cs).pop_front())
}

/// The oldest queued event.
pub fn pop_event() -> Option<Event> {
    critical_section::with(|cs| EVENTS.borrow_ref_mut(cs).pop_front())
}

/// Control interrupts served since start (wraps).
pub fn steps() -> u32 {
    STEPS.load(Ordering::Relaxed)
}

/// Longest step since start, CPU cycles.
pub fn max_cycles() -> u32 {
    MAX_CYCLES.load(Ordering::Relaxed)
}

/// Records and events dropped because the task did not drain the queues.
pub fn dropped() -> u32 {
    DROPPED.load(Ordering::Relaxed)
}

/// The control interrupt: ADC2's end of injected sequence, once per PWM
/// period (see the module doc).
#[interrupt]
fn ADC1_2() {
    let entry_cycles = DWT::cycle_count();
    // JEOS of ADC2 is the only enabled source of this vector.
    if !adc::sequence_done() {
        return;
    }
    let time_us = timebase::now_us();
    let encoder_raw = encoder::raw_count();
    let samples = adc::take();
    let broke = pwm::break_occurred();
    critical_section::with(|cs| match DRIVE.borrow_ref_mut(cs).as_mut() {
        Some(drive) => drive.step(cs, entry_cycles, time_us, encoder_raw, samples, broke),
        None => pwm::set_outputs_enabled(false),
    });
    STEPS.fetch_add(1, Ordering::Relaxed);
}

fn push_event(cs: CriticalSection, event: Event) {
    if EVENTS.borrow_ref_mut(cs).push_back(event).is_err() {
        DROPPED.fetch_add(1, Ordering::Relaxed);
    }
}

impl Drive {
    fn step(
        &mut self,
        cs: CriticalSection,
        entry_cycles: u32,
        time_us: u32,
        encoder_raw: u16,
        samples: Result<Samples, Incomplete>,
        broke: bool,
    ) {
        self.steps = self.steps.wrapping_add(1);
        let encoder_count = self.encoder.extend(encoder_raw);
        if broke {
            self.latch(cs, FirmwareFault::InverterBreak);
        }
        if let Some(command) = COMMANDS.borrow_ref_mut(cs).pop_front() {
            self.apply(cs, command);
        }
        if let Some(output) = observer::OUTPUT.try_take() {
            self.controller.deliver_observer_output(output);
        }

        let (output, injected, codes, dc_bus_code) = match samples {
            Ok(samples) => {
                let (output, injected, codes) = self.sense(cs, samples, encoder_count, time_us);
                (output, injected, codes, samples.dc_bus_code)
            }
            Err(Incomplete) => {
                self.latch(cs, FirmwareFault::AdcSequenceIncomplete);
                (None, None, [0; 3], 0)
            }
        };

        let (pwm_on, compare, brake_wanted) = match injected {
            Some(i) => (self.fault.is_none() && i.pwm_on, i.compare, i.brake_released),
            None => (
                self.fault.is_none() && output.is_some_and(|o| o.pwm_enabled),
                output.map_or([0; 3], |o| o.pwm_compare),
                output.is_some_and(|o| o.brake_released),
            ),
        };
        let compare = if pwm_on { compare } else { [0; 3] };
        pwm::set_compares(compare);
        // The real deadline: the compares must be in before the valley that
        // follows the sample (`drive_core::pwm_timing`).
        let write_cycles = DWT::cycle_count().wrapping_sub(entry_cycles);
        let in_time = compares_in_time(pwm::counting_down(), write_cycles, pwm::HALF_PERIOD_CYCLES);
        pwm::set_outputs_enabled(pwm_on);
        // Fail-safe: the brake is released only while the inverter drives
        // the machine, whatever the controller asks.
        let brake_released = pwm_on && brake_wanted;
        self.brake.set_released(brake_released);

        let cycles = DWT::cycle_count().wrapping_sub(entry_cycles);
        if !in_time {
            self.latch(cs, FirmwareFault::Overrun { cycles: write_cycles });
        } else if adc::sequence_done() {
            self.latch(cs, FirmwareFault::TriggerOverrun);
        }
        MAX_CYCLES.fetch_max(cycles, Ordering::Relaxed);
        SNAPSHOT.borrow(cs).set(Snapshot {
            state: output.map(|o| o.state),
            speed_radps: output.map_or(0.0, |o| o.telemetry.speed_radps),
            ready_gate: self.fault.is_none() && self.startup.is_running(),
            fault: self.fault.is_some() || output.is_some_and(|o| matches!(o.state, DriveState::Tripped(_))),
            awaiting_alignment: self.startup.is_waiting_for_alignment(),
            pwm_on,
            brake_released,
        });

        if self.steps % RECORD_DECIMATION == 0 {
            let record = Record {
                step: self.steps,
                time_us,
                state: output.map(|o| o.state),
                fault: self.fault,
                pwm_on: pwm_on && self.fault.is_none(),
                brake_released: brake_released && self.fault.is_none(),
                phase_codes: codes,
                dc_bus_code,
                encoder_count,
                compare,
                cycles,
                telemetry: output.map_or(Telemetry::default(), |o| o.telemetry),
            };
            if RECORDS.borrow_ref_mut(cs).push_back(record).is_err() {
                DROPPED.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Start-up sequence or controller step; returns the controller's output
    /// (if it ran), the start-up sequence's outputs (if it drives them) and
    /// the phase codes it saw.
    fn sense(
        &mut self,
        cs: CriticalSection,
        samples: Samples,
        encoder_count: u32,
        time_us: u32,
    ) -> (Option<ControlOutput>, Option<StartupOutput>, [u16; 3]) {
        match self.startup.step(samples.phase_codes, samples.dc_bus_code, encoder_count) {
            StartupStep::Drive(out) => {
                match out.event {
                    Some(StartupEvent::Calibrated(offsets)) => push_event(cs, Event::Calibrated(offsets)),
                    Some(StartupEvent::Aligned(count)) => push_event(cs, Event::Aligned(count)),
                    Some(StartupEvent::Fault(fault)) => self.latch(cs, fault.into()),
                    None => {}
                }
                (None, Some(out), out.codes)
            }
            StartupStep::Run(codes) => {
                let frame = SensorFrame {
                    phase_current_codes: codes,
                    encoder_count,
                    dc_bus_code: samples.dc_bus_code,
                    time_us,
                };
                let output = self.controller.step(&frame);
                // The observer's task gets the input through its signal; the
                // output it signals back is delivered at the start of a
                // later step, before the next speed-loop tick uses it.
                if let Some(input) = self.controller.take_observer_input() {
                    observer::INPUT.signal(input);
                }
                (Some(output), None, codes)
            }
        }
    }

    fn apply(&mut self, cs: CriticalSection, command: Command) {
        let result = match command {
            Command::Drive(command) => {
                let starts = matches!(command, ControllerCommand::Travel(_) | ControllerCommand::SpeedTravel(_));
                if starts && (self.fault.is_some() || !self.startup.is_running()) {
                    Err(Refusal::NotReady)
                } else {
                    lift_drive::apply(command, &mut self.controller).map_err(Refusal::Controller)
                }
            }
            Command::Align => {
                if self.fault.is_some() {
                    Err(Refusal::NotReady)
                } else {
                    self.startup.command(StartupCommand::Align).map_err(|e| match e {
                        StartupRefusal::Faulted => Refusal::NotReady,
                        _ => Refusal::Busy,
                    })
                }
            }
            Command::Reset => {
                let controller_tripped = matches!(self.controller.state(), DriveState::Tripped(_));
                let startup_fault = self.startup.fault().is_some();
                if self.fault.is_none() && !controller_tripped && !startup_fault {
                    Err(Refusal::NothingToReset)
                } else {
                    pwm::clear_break_flag();
                    self.fault = None;
                    if startup_fault {
                        let _ = self.startup.command(StartupCommand::Reset);
                    }
                    if controller_tripped {
                        self.controller.reset();
                    }
                    Ok(())
                }
            }
        };
        if let Command::Drive(ControllerCommand::RemainingDistance { .. }) = command {
            let outcome = if result.is_ok() { REMAINING_TAKEN } else { REMAINING_REFUSED };
            REMAINING.store(outcome, Ordering::Relaxed);
            // The lift controller repeats it every message: only refusals are logged.
            if result.is_ok() {
                return;
            }
        }
        push_event(
            cs,
            match result {
                Ok(()) => Event::Applied(command),
                Err(refusal) => Event::Refused(command, refusal),
            },
        );
    }

    /// Latches `fault` (the first one stays) and puts the drive in its safe
    /// state at once.
    fn latch(&mut self, cs: CriticalSection, fault: FirmwareFault) {
        pwm::set_outputs_enabled(false);
        self.brake.set_released(false);
        if self.fault.is_none() {
            self.fault = Some(fault);
            push_event(cs, Event::Fault(fault));
        }
    }
}
