//! The drive's start-up and safe-state sequence, before the controller runs:
//! settling, current-offset calibration (outputs off), then the safe state
//! (gates off, brake applied) until the rotor alignment is commanded, the
//! commanded alignment and the brake setting after it, each protected.
//!
//! After any reset (power-up, watchdog, a chip reset) the drive stays in its
//! safe state: it settles, calibrates its current offsets with the outputs
//! off, and then waits, not ready, with gates off and the brake applied,
//! until [`StartupCommand::Align`] (the service port's `align`). Nothing
//! switches the bridge or opens the brake before that command. The
//! alignment injects current with the brake open ([`crate::alignment`]);
//! while it and the brake setting after it switch the bridge, the same
//! checks as the controller's guard them ([`Supervisor`]: over-current and
//! current sum, DC-bus under- and over-voltage, encoder step plausibility).
//! A fault ends the injection at once (outputs off, brake applied) and
//! latches until [`StartupCommand::Reset`]; after a reset the drive is
//! back in its safe state, waiting for the alignment command (or, after a
//! failed calibration, calibrates again).
//!
//! With an absolute encoder ([`Startup::with_angle_given`]) the pole
//! position is the stored offset (`DriveParameters::encoder_offset_counts`,
//! the count at electrical zero), checked to lie within one revolution and
//! taken by the controller from its first step, wherever a reset of the
//! chip alone left the rotor (`Controller::set_encoder_origin`); an offset
//! outside one revolution is refused and the sequence waits for the
//! commanded alignment instead (`LiftDrive::install_parameters`). What this
//! sequence does not do: identify the pole position with the brake closed,
//! or check the stored offset against the machine beyond that range. The
//! rig's encoder is incremental; the alignment moves the rotor (a quarter
//! of an electrical turn) with the brake open, so the car must be balanced
//! when it is commanded.

use crate::alignment::{Alignment, AlignmentError, AlignmentParams, AlignmentStep, Injection};
use crate::config::DriveConfig;
use crate::current_loop::current_from_code;
use crate::current_offset::{CurrentOffsets, OffsetCalibration, OffsetError, OffsetLimits};
use crate::fixed::{mul_int, q16, Q16};
use crate::supervisor::{Fault, Supervisor, SupervisorLimits};

/// PWM periods to wait after a reset before calibrating, letting the ADCs
/// and the shunt amplifiers settle: 160 periods = 10 ms at 16 kHz.
pub const SETTLE_STEPS: u16 = 160;

/// PWM periods averaged by the current-offset calibration: 1024 = 64 ms at 16 kHz.
pub const CALIBRATION_SAMPLES: u16 = 1024;

/// Why the start-up sequence latched a fault.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StartupFault {
    /// The current-offset calibration was rejected.
    Calibration(OffsetError),
    /// The commanded rotor alignment failed its checks.
    Alignment(AlignmentError),
    /// A protection tripped while the alignment switched the bridge.
    Protection(Fault),
}

/// A command to the start-up sequence.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StartupCommand {
    /// Run the rotor alignment (brake open, current injected).
    Align,
    /// Clear a latched start-up fault.
    Reset,
}

/// Why a [`StartupCommand`] was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StartupRefusal {
    /// Not waiting for it: settling, calibrating, aligning or running.
    Busy,
    /// A fault is latched: reset first.
    Faulted,
    /// Reset with no start-up fault latched.
    NothingToReset,
}

/// Something the sequence reports once.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StartupEvent {
    /// The offsets were calibrated; the drive waits for the alignment command.
    Calibrated(CurrentOffsets),
    /// The alignment passed: the encoder count at electrical angle zero.
    Aligned(u32),
    /// A fault was latched.
    Fault(StartupFault),
}

/// The outputs of one start-up period.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StartupOutput {
    /// Compare values, timer ticks (all 0 with the outputs off).
    pub compare: [u16; 3],
    /// Inverter outputs on.
    pub pwm_on: bool,
    /// Brake released.
    pub brake_released: bool,
    /// The phase-current codes seen (offset-corrected once calibrated), ADC codes.
    pub codes: [u16; 3],
    /// What happened in this period, if anything.
    pub event: Option<StartupEvent>,
}

/// What one period of the sequence asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StartupStep {
    /// The sequence drives the outputs itself.
    Drive(StartupOutput),
    /// Aligned: the controller runs, on these offset-corrected codes.
    Run([u16; 3]),
}

#[derive(Clone, Copy, Debug)]
enum Phase {
    Settling(u16),
    Calibrating(OffsetCalibration),
    /// Calibrated, safe state, waiting for [`StartupCommand::Align`].
    Waiting(CurrentOffsets),
    Aligning(Alignment, Injection, CurrentOffsets),
    /// Aligned: brake applied, current kept at electrical zero while it sets.
    BrakeSetting(u32, Injection, CurrentOffsets),
    Running(CurrentOffsets),
    /// The calibration failed: no offsets to run with.
    Failed,
}

/// The start-up sequence of one drive (see the module doc).
#[derive(Clone, Copy, Debug)]
pub struct Startup {
    config: DriveConfig,
    phase: Phase,
    guard: Supervisor,
    fault: Option<StartupFault>,
    measured_a: f32,
    last_count: Option<u32>,
    brake_set_steps: u32,
    lsb_a: Q16,
    dc_bus_v_per_code: Q16,
    /// The angle reference is given (no alignment): the controller runs
    /// right after the calibration ([`Startup::with_angle_given`]).
    angle_given: bool,
    /// Mid-scale ADC code (zero current).
    zero_code: u16,
}

impl Startup {
    /// The sequence after a reset, with the controller's protection `limits`
    /// (`Controller::supervisor_limits`).
    pub fn new(config: &DriveConfig, limits: SupervisorLimits) -> Self {
        Self {
            config: *config,
            phase: Phase::Settling(SETTLE_STEPS),
            guard: Supervisor::new(limits),
            fault: None,
            measured_a: 0.0,
            last_count: None,
            brake_set_steps: (crate::controller::BRAKE_SET_S * config.current_loop_hz) as u32,
            lsb_a: q16(config.current_lsb_a()),
            dc_bus_v_per_code: q16(config.dc_bus_sense_full_scale_v / config.adc_max_code() as f32),
            angle_given: false,
            zero_code: config.adc_zero_code(),
        }
    }

    /// The sequence for a machine whose electrical angle reference is
    /// given (an absolute encoder whose stored offset the controller takes,
    /// `Controller::set_encoder_origin`, or the simulated machine): after
    /// the calibration the controller runs at once, idle (gates off, brake
    /// applied) until a travel is commanded; [`StartupCommand::Align`] is
    /// refused ([`StartupRefusal::Busy`]).
    pub fn with_angle_given(mut self) -> Self {
        self.angle_given = true;
        self
    }

    /// The angle reference is not given after all (the stored offset was
    /// refused): after the calibration the sequence waits for
    /// [`StartupCommand::Align`], as without [`Startup::with_angle_given`].
    /// Before the sequence's first step.
    pub fn require_alignment(&mut self) {
        self.angle_given = false;
    }

    /// Whether the angle reference is given ([`Startup::with_angle_given`]).
    pub fn angle_given(&self) -> bool {
        self.angle_given
    }

    /// The latched fault, if any.
    pub fn fault(&self) -> Option<StartupFault> {
        self.fault
    }

    /// Whether the controller runs (aligned, no start-up phase left).
    pub fn is_running(&self) -> bool {
        matches!(self.phase, Phase::Running(_))
    }

    /// Whether the sequence waits for [`StartupCommand::Align`] in its safe state.
    pub fn is_waiting_for_alignment(&self) -> bool {
        matches!(self.phase, Phase::Waiting(_))
    }

    /// Applies a command (at the start of a period).
    ///
    /// # Errors
    /// [`StartupRefusal`]: the alignment outside the safe waiting state or
    /// with a fault latched, a reset with none latched.
    pub fn command(&mut self, command: StartupCommand) -> Result<(), StartupRefusal> {
        match command {
            StartupCommand::Align => match self.phase {
                _ if self.fault.is_some() => Err(StartupRefusal::Faulted),
                Phase::Waiting(offsets) => {
                    self.guard.reset();
                    self.last_count = None;
                    self.measured_a = 0.0;
                    self.phase = Phase::Aligning(
                        Alignment::new(AlignmentParams::for_drive(&self.config)),
                        Injection::new(&self.config),
                        offsets,
                    );
                    Ok(())
                }
                _ => Err(StartupRefusal::Busy),
            },
            StartupCommand::Reset => {
                if self.fault.take().is_none() {
                    return Err(StartupRefusal::NothingToReset);
                }
                self.guard.reset();
                if matches!(self.phase, Phase::Failed) {
                    self.phase = Phase::Settling(SETTLE_STEPS);
                }
                Ok(())
            }
        }
    }

    /// One PWM period: the raw phase-current codes (with the board's sign),
    /// the DC-bus code and the encoder count.
    pub fn step(&mut self, phase_codes: [u16; 3], dc_bus_code: u16, encoder_count: u32) -> StartupStep {
        // The running drive's path first, and without copying the phase:
        // it is inside every control step's deadline.
        if let Phase::Running(offsets) = &self.phase {
            return StartupStep::Run(offsets.correct(phase_codes, self.zero_code));
        }
        self.step_before_running(phase_codes, dc_bus_code, encoder_count)
    }

    fn step_before_running(&mut self, phase_codes: [u16; 3], dc_bus_code: u16, encoder_count: u32) -> StartupStep {
        let zero = self.config.adc_zero_code();
        let off = |codes: [u16; 3], event: Option<StartupEvent>| {
            StartupStep::Drive(StartupOutput { compare: [0; 3], pwm_on: false, brake_released: false, codes, event })
        };
        match self.phase {
            Phase::Settling(left) => {
                let left = left.saturating_sub(1);
                self.phase = if left == 0 {
                    let limits = OffsetLimits::for_adc_bits(self.config.adc_bits);
                    Phase::Calibrating(OffsetCalibration::new(CALIBRATION_SAMPLES, limits))
                } else {
                    Phase::Settling(left)
                };
                off(phase_codes, None)
            }
            Phase::Calibrating(mut calibration) => {
                calibration.push(phase_codes);
                self.phase = Phase::Calibrating(calibration);
                if !calibration.is_complete() {
                    return off(phase_codes, None);
                }
                match calibration.finish() {
                    Ok(offsets) => {
                        self.phase = if self.angle_given { Phase::Running(offsets) } else { Phase::Waiting(offsets) };
                        off(phase_codes, Some(StartupEvent::Calibrated(offsets)))
                    }
                    Err(error) => {
                        self.phase = Phase::Failed;
                        off(phase_codes, Some(self.latch(StartupFault::Calibration(error))))
                    }
                }
            }
            Phase::Waiting(offsets) => off(offsets.correct(phase_codes, zero), None),
            Phase::Failed => off(phase_codes, None),
            Phase::Running(offsets) => StartupStep::Run(offsets.correct(phase_codes, zero)),
            Phase::Aligning(mut alignment, mut injection, offsets) => {
                let codes = offsets.correct(phase_codes, zero);
                if let Some(fault) = self.protect(codes, dc_bus_code, encoder_count) {
                    self.phase = Phase::Waiting(offsets);
                    return off(codes, Some(self.latch(StartupFault::Protection(fault))));
                }
                let params = AlignmentParams::for_drive(&self.config);
                let (angle, current_a, event) = match alignment.step(encoder_count, self.measured_a) {
                    AlignmentStep::Inject { angle, current_a } => (angle, current_a, None),
                    AlignmentStep::Done(Ok(count)) => (0, params.current_a, Some(StartupEvent::Aligned(count))),
                    AlignmentStep::Done(Err(error)) => {
                        self.phase = Phase::Waiting(offsets);
                        return off(codes, Some(self.latch(StartupFault::Alignment(error))));
                    }
                };
                let (compare, measured_a) = injection.step(codes, dc_bus_code, angle, current_a);
                self.measured_a = measured_a;
                let aligned = event.is_some();
                self.phase = if aligned {
                    Phase::BrakeSetting(self.brake_set_steps, injection, offsets)
                } else {
                    Phase::Aligning(alignment, injection, offsets)
                };
                StartupStep::Drive(StartupOutput { compare, pwm_on: true, brake_released: !aligned, codes, event })
            }
            Phase::BrakeSetting(left, mut injection, offsets) => {
                let codes = offsets.correct(phase_codes, zero);
                if let Some(fault) = self.protect(codes, dc_bus_code, encoder_count) {
                    self.phase = Phase::Waiting(offsets);
                    return off(codes, Some(self.latch(StartupFault::Protection(fault))));
                }
                let current_a = AlignmentParams::for_drive(&self.config).current_a;
                let (compare, _) = injection.step(codes, dc_bus_code, 0, current_a);
                let left = left.saturating_sub(1);
                // The controller's first step follows with the rotor at
                // electrical zero: its angle reference.
                self.phase =
                    if left == 0 { Phase::Running(offsets) } else { Phase::BrakeSetting(left, injection, offsets) };
                StartupStep::Drive(StartupOutput { compare, pwm_on: true, brake_released: false, codes, event: None })
            }
        }
    }

    /// The controller's checks on one injection period; the fault, if one tripped.
    fn protect(&mut self, codes: [u16; 3], dc_bus_code: u16, encoder_count: u32) -> Option<Fault> {
        let zero = self.config.adc_zero_code();
        let currents = codes.map(|code| current_from_code(code, zero, self.lsb_a));
        self.guard.check_currents(codes, currents);
        self.guard.check_dc_bus(mul_int(dc_bus_code as i32, self.dc_bus_v_per_code));
        if let Some(last) = self.last_count {
            self.guard.check_encoder_step(encoder_count.wrapping_sub(last) as i32);
        }
        self.last_count = Some(encoder_count);
        self.guard.fault()
    }

    /// Latches `fault` (the first one stays); the event to report.
    fn latch(&mut self, fault: StartupFault) -> StartupEvent {
        if self.fault.is_none() {
            self.fault = Some(fault);
        }
        StartupEvent::Fault(fault)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::reference_rig;
    use crate::Controller;

    const ZERO: u16 = 2048;

    fn startup() -> Startup {
        let rig = reference_rig();
        Startup::new(&rig, *Controller::new(&rig).supervisor_limits())
    }

    /// A bus code of the rig's nominal 100 V (200 V full scale).
    const BUS_100V: u16 = 2048;

    fn drive(step: StartupStep) -> StartupOutput {
        match step {
            StartupStep::Drive(out) => out,
            StartupStep::Run(_) => panic!("the controller runs"),
        }
    }

    /// A start-up calibrated at rest, commanded to align and one period into
    /// the alignment (encoder at count 0).
    fn aligning() -> Startup {
        let mut s = startup();
        while !s.is_waiting_for_alignment() {
            s.step([ZERO; 3], BUS_100V, 0);
        }
        s.command(StartupCommand::Align).unwrap();
        drive(s.step([ZERO; 3], BUS_100V, 0));
        s
    }

    #[test]
    fn after_a_reset_the_drive_stays_safe_until_the_alignment_is_commanded() {
        let mut s = startup();
        // Ten seconds of periods at rest: calibrated, then waiting, gates
        // off and brake applied throughout; nothing reported but the calibration.
        let mut calibrated = 0;
        for _ in 0..160_000 {
            let out = drive(s.step([ZERO; 3], BUS_100V, 1234));
            assert!(!out.pwm_on && !out.brake_released && out.compare == [0; 3]);
            match out.event {
                Some(StartupEvent::Calibrated(_)) => calibrated += 1,
                None => {}
                other => panic!("{other:?}"),
            }
        }
        assert_eq!(calibrated, 1);
        assert!(s.is_waiting_for_alignment() && s.fault().is_none());
        // A reset with nothing latched changes nothing.
        assert_eq!(s.command(StartupCommand::Reset), Err(StartupRefusal::NothingToReset));
        // The command starts the injection.
        assert_eq!(s.command(StartupCommand::Align), Ok(()));
        let out = drive(s.step([ZERO; 3], BUS_100V, 1234));
        assert!(out.pwm_on && out.brake_released);
    }

    #[test]
    fn a_protection_trip_during_the_alignment_ends_safe_and_only_a_reset_clears_it() {
        let mut s = aligning();
        // The bus collapses (below the 70 V under-voltage level).
        let out = drive(s.step([ZERO; 3], 1000, 0));
        assert_eq!(out.event, Some(StartupEvent::Fault(StartupFault::Protection(Fault::DcBusUnderVoltage))));
        assert!(!out.pwm_on && !out.brake_released && out.compare == [0; 3]);
        // Latched: the alignment is refused, the outputs stay off.
        assert_eq!(s.command(StartupCommand::Align), Err(StartupRefusal::Faulted));
        for _ in 0..1000 {
            let out = drive(s.step([ZERO; 3], BUS_100V, 0));
            assert!(!out.pwm_on && !out.brake_released);
        }
        assert_eq!(s.command(StartupCommand::Reset), Ok(()));
        assert!(s.fault().is_none() && s.is_waiting_for_alignment());
        assert_eq!(s.command(StartupCommand::Align), Ok(()));
    }

    #[test]
    fn with_the_angle_given_the_controller_runs_after_the_calibration_and_never_before() {
        let mut s = startup().with_angle_given();
        let mut steps = 0u32;
        let codes = loop {
            match s.step([ZERO + 3; 3], BUS_100V, 0) {
                StartupStep::Drive(out) => assert!(!out.pwm_on && !out.brake_released && out.compare == [0; 3]),
                StartupStep::Run(codes) => break codes,
            }
            steps += 1;
        };
        assert_eq!(steps, (SETTLE_STEPS + CALIBRATION_SAMPLES) as u32);
        assert_eq!(codes, [ZERO; 3], "the offsets are taken off");
        assert!(s.is_running() && !s.is_waiting_for_alignment());
        assert_eq!(s.command(StartupCommand::Align), Err(StartupRefusal::Busy));
    }

    #[test]
    fn an_encoder_jump_during_the_alignment_trips() {
        let mut s = aligning();
        let out = drive(s.step([ZERO; 3], BUS_100V, 5000));
        assert_eq!(out.event, Some(StartupEvent::Fault(StartupFault::Protection(Fault::EncoderImplausible))));
        assert!(!out.pwm_on && !out.brake_released);
    }

    #[test]
    fn a_failed_calibration_is_cleared_by_a_reset_which_calibrates_again() {
        let mut s = startup();
        let mut failed = false;
        for _ in 0..2000 {
            // One channel far off mid-scale: refused.
            if let Some(StartupEvent::Fault(StartupFault::Calibration(_))) =
                drive(s.step([ZERO, ZERO, 3500], BUS_100V, 0)).event
            {
                failed = true;
                break;
            }
        }
        assert!(failed);
        assert_eq!(s.command(StartupCommand::Align), Err(StartupRefusal::Faulted));
        assert_eq!(s.command(StartupCommand::Reset), Ok(()));
        for _ in 0..2000 {
            s.step([ZERO; 3], BUS_100V, 0);
        }
        assert!(s.is_waiting_for_alignment() && s.fault().is_none());
    }
}
