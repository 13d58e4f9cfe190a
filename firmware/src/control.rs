//! The control interrupt: the drive's application layer
//! (`drive_core::lift_drive::LiftDrive`, the code the processor-in-the-loop
//! target and the host run) once per PWM period, in ADC2's
//! end-of-injected-sequence interrupt (`ADC1_2`, the highest priority),
//! with the peripherals and the queues of `edges.rs` at its edges. Nothing
//! of the drive's logic is here: this module reads the sensors, hands
//! `LiftDrive::period` its messages and drives what it returns.
//!
//! Each period, about 1.5 us after the PWM counter peak triggered the
//! conversions, the interrupt
//! 1. reads the time stamp (TIM2), the encoder (TIM4), the four injected
//!    conversions (ADC1/ADC2 JDR1-2, the phase currents with the board's
//!    sign) and TIM1's break flag, which latches a hardware fault;
//! 2. runs `LiftDrive::period`, whose control step's outputs it drives at
//!    once: the three compares (taking effect at the next PWM valley), MOE
//!    and the brake (TIM8_CH3); the drive keeps the brake applied unless
//!    the gates are on and switches both off with any fault latched;
//! 3. latches an overrun if the compares were written after the valley
//!    that follows the sample (TIM1 no longer counting down, or half a
//!    period gone by the DWT cycle counter: `drive_core::pwm_timing`), or
//!    if the next sequence completed before the period's work finished;
//! 4. every [`RECORD_DECIMATION`]th period queues a telemetry record.
//!
//! Sharing: the interrupt owns the drive inside a
//! `critical_section::Mutex`; the service task reaches it only through
//! [`pause_if_idle`] and [`resume`] around a flash write.

use core::cell::RefCell;
use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::peripheral::DWT;
use critical_section::Mutex;
use drive_core::lift_drive::{
    ControllerCommand, DriveFault, DriveOutput, HardwareFault, LiftDrive, PeriodIo, ServiceReply,
};
use drive_core::observer::{ObserverInput, ObserverOutput};
use drive_core::pwm_timing::compares_in_time;
use drive_core::SensorFrame;
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::{InterruptExt, Priority};

use crate::adc::{self, Incomplete, Samples};
use crate::edges::{self, Event, Record};
use crate::encoder::{self, Extender};
use crate::{board, observer, pwm, timebase};

/// Every how many periods the interrupt queues a telemetry record (16: 1 kHz).
pub const RECORD_DECIMATION: u32 = 16;

struct Drive {
    app: LiftDrive,
    encoder: Extender,
    brake: board::Brake,
    steps: u32,
}

static DRIVE: Mutex<RefCell<Option<Drive>>> = Mutex::new(RefCell::new(None));
static STEPS: AtomicU32 = AtomicU32::new(0);
static MAX_CYCLES: AtomicU32 = AtomicU32::new(0);
static DROPPED: AtomicU32 = AtomicU32::new(0);
static OBSERVER_MISSED: AtomicU32 = AtomicU32::new(0);

/// Hands the drive and the brake pin to the interrupt and enables it. Call
/// after `pwm::init` and `adc::init`; the drive then settles, calibrates
/// and stays in its safe state (gates off, brake applied) until the
/// service port's `align` (`drive_core::startup`).
pub fn start(app: LiftDrive, brake: board::Brake) {
    critical_section::with(|cs| {
        DRIVE.borrow_ref_mut(cs).replace(Drive { app, encoder: Extender::new(encoder::raw_count()), brake, steps: 0 });
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
    // behind critical-section mutexes, Embassy channels and atomics, and the
    // registers of TIM1, TIM2, TIM4, TIM8, ADC1 and ADC2, which no other code
    // writes once `start` runs. Nothing relies on ADC1_2 staying masked (no
    // embassy driver is bound to it).
    unsafe { interrupt::ADC1_2.enable() };
}

/// Pauses the control interrupt for a flash write if the drive is at rest
/// in its safe state (`LiftDrive::is_quiescent`: gates off, brake applied,
/// no travel or alignment); whether it did. Resume with [`resume`].
pub fn pause_if_idle() -> bool {
    critical_section::with(|cs| {
        let idle = DRIVE.borrow_ref(cs).as_ref().is_some_and(|d| d.app.is_quiescent());
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
            drive.app.resume_after_pause();
        }
    });
    enable_control_interrupt();
}

/// Control interrupts served since start (wraps).
pub fn steps() -> u32 {
    STEPS.load(Ordering::Relaxed)
}

/// Longest period's work since start, CPU cycles.
pub fn max_cycles() -> u32 {
    MAX_CYCLES.load(Ordering::Relaxed)
}

/// Records, events, replies and answers dropped because a queue was full.
pub fn dropped() -> u32 {
    DROPPED.load(Ordering::Relaxed)
}

/// Speed-loop ticks whose observer estimate was not back in time, as of
/// the latest record.
pub fn observer_missed_deadlines() -> u32 {
    OBSERVER_MISSED.load(Ordering::Relaxed)
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
        Some(drive) => drive.period(entry_cycles, time_us, encoder_raw, samples, broke),
        None => pwm::set_outputs_enabled(false),
    });
    STEPS.fetch_add(1, Ordering::Relaxed);
}

fn push_event(event: Event) {
    if edges::EVENTS.try_send(event).is_err() {
        DROPPED.fetch_add(1, Ordering::Relaxed);
    }
}

/// The drive's edges in one period: the queues, the observer's signals,
/// and the timer and brake outputs written as soon as the control step
/// has them.
struct Edges<'a> {
    entry_cycles: u32,
    brake: &'a mut board::Brake,
    /// Cycles from the period's start to the compare write, if it came after the valley.
    late: Option<u32>,
}

impl PeriodIo for Edges<'_> {
    fn service_byte(&mut self) -> Option<u8> {
        edges::SERVICE_RX.try_receive().ok()
    }

    fn dcp_byte(&mut self) -> Option<u8> {
        edges::DCP_RX.try_receive().ok()
    }

    fn observer_output(&mut self) -> Option<ObserverOutput> {
        observer::OUTPUT.try_take()
    }

    fn drive(&mut self, output: &DriveOutput) {
        let c = &output.control;
        pwm::set_compares(if c.pwm_enabled { c.pwm_compare } else { [0; 3] });
        // The real deadline: the compares must be in before the valley that
        // follows the sample (`drive_core::pwm_timing`).
        let write_cycles = DWT::cycle_count().wrapping_sub(self.entry_cycles);
        if !compares_in_time(pwm::counting_down(), write_cycles, pwm::HALF_PERIOD_CYCLES) {
            self.late = Some(write_cycles);
        }
        pwm::set_outputs_enabled(c.pwm_enabled);
        self.brake.set_released(c.brake_released);
    }

    fn service_reply(&mut self, reply: &ServiceReply) {
        if edges::SERVICE_TX.try_send(*reply).is_err() {
            push_event(Event::Dropped);
        }
    }

    fn dcp_reply(&mut self, reply: &[u8; 6]) {
        if edges::DCP_TX.try_send(*reply).is_err() {
            push_event(Event::Dropped);
        }
    }

    fn faults_cleared(&mut self) {
        pwm::clear_break_flag();
    }

    fn observer_input(&mut self, input: ObserverInput) {
        observer::INPUT.signal(input);
    }
}

impl Drive {
    fn period(
        &mut self,
        entry_cycles: u32,
        time_us: u32,
        encoder_raw: u16,
        samples: Result<Samples, Incomplete>,
        broke: bool,
    ) {
        self.steps = self.steps.wrapping_add(1);
        let encoder_count = self.encoder.extend(encoder_raw);
        if broke {
            self.latch(HardwareFault::InverterBreak);
        }
        let Ok(samples) = samples else {
            self.latch(HardwareFault::AdcSequenceIncomplete);
            return;
        };
        let sensors = SensorFrame {
            phase_current_codes: samples.phase_codes,
            encoder_count,
            dc_bus_code: samples.dc_bus_code,
            time_us,
        };
        let mut edges = Edges { entry_cycles, brake: &mut self.brake, late: None };
        let out = self.app.period(&sensors, &mut edges);
        if let Some(cycles) = edges.late {
            self.latch(HardwareFault::Overrun { cycles });
        } else if adc::sequence_done() {
            self.latch(HardwareFault::TriggerOverrun);
        }
        let cycles = DWT::cycle_count().wrapping_sub(entry_cycles);
        MAX_CYCLES.fetch_max(cycles, Ordering::Relaxed);

        if let Some(event) = out.drive.event {
            push_event(Event::Startup(event));
        }
        if let Some((command, result)) = out.applied {
            // The lift controller repeats the remaining distance every
            // message: only its refusals are logged.
            if result.is_err() || !matches!(command, ControllerCommand::RemainingDistance { .. }) {
                push_event(Event::Command(command, result));
            }
        }
        if let Some(refusal) = out.refused {
            push_event(Event::Refused(refusal));
        }
        if self.steps % RECORD_DECIMATION == 0 {
            let c = out.drive.control;
            OBSERVER_MISSED.store(self.app.controller().observer_missed_deadlines(), Ordering::Relaxed);
            let record = Record {
                step: self.steps,
                time_us,
                state: self.app.state(),
                controller_ran: out.drive.controller_ran,
                pwm_on: c.pwm_enabled,
                brake_released: c.brake_released,
                phase_codes: out.drive.codes,
                dc_bus_code: samples.dc_bus_code,
                encoder_count,
                compare: c.pwm_compare,
                cycles,
                telemetry: c.telemetry,
            };
            if edges::RECORDS.try_send(record).is_err() {
                DROPPED.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Puts the outputs in the safe state at once and latches `fault` in
    /// the drive (the first one stays; it reports it from the next period).
    fn latch(&mut self, fault: HardwareFault) {
        pwm::set_outputs_enabled(false);
        self.brake.set_released(false);
        let first = self.app.fault().is_none();
        self.app.latch(fault);
        if first {
            push_event(Event::Fault(DriveFault::Hardware(fault)));
        }
    }
}
