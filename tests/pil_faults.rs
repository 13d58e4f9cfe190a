//! Faults through the processor-in-the-loop target: the drive core compiled
//! for the Cortex-M4F in QEMU detects the over-current of a phase short, an
//! encoder that stops or loses counts, missed control steps and a corrupted
//! frame stream exactly as the host build does (every step shadow-checked
//! bit for bit), within the same bounds. Needs `qemu-system-arm` and the
//! target ELF (`scripts/test.sh` provides both).

use std::time::Instant;

use crate::support::rig;
use closed_loop::faults::parse_fault;
use closed_loop::faults::run::{run_case_with, FaultCase, FaultOutcome};
use closed_loop::pil::{PilOptions, PilTarget};
use closed_loop::TravelSpec;
use drive_core::config::Direction;
use drive_core::supervisor::Fault;
use drive_core::{Controller, DriveState};

const TS: f64 = 1.0 / 16_000.0;
/// Simulated time after the trip: enough to see the safe state held.
const AFTER_TRIP_S: f64 = 0.05;

fn case(fault: &str, direction: Direction) -> FaultCase {
    let (lw_start_m, lw_end_m) = match direction {
        Direction::Up => (3.0, 4.5),
        Direction::Down => (4.5, 3.0),
    };
    FaultCase {
        travel: TravelSpec { m_car_kg: 70.5, direction, lw_start_m, lw_end_m },
        faults: vec![parse_fault(fault).unwrap()],
    }
}

/// Runs `fault` on the host build and on the emulated chip; both must trip
/// at the same time for the same reason, within `bound_s`, and keep the
/// safe state.
fn on_host_and_chip(fault: &str, direction: Direction, reason: Fault, bound_s: f64) {
    let rig = rig();
    let case = case(fault, direction);
    let mut host = Controller::new(&rig.drive_config());
    let on_host = run_case_with(&rig, &case, &mut host, AFTER_TRIP_S);
    let mut target = PilTarget::launch(&PilOptions::default(), &rig.drive_config()).unwrap_or_else(|e| panic!("{e}"));
    let started = Instant::now();
    let on_chip = run_case_with(&rig, &case, &mut target, AFTER_TRIP_S);
    let show = |o: &FaultOutcome| {
        format!("detection {:?} ms, reason {:?}, error {:?}", o.detection_s.map(|d| d * 1e3), o.reason, o.error)
    };
    println!(
        "{fault} {direction:?}: chip {} ({} steps in {:.1} s); host {}",
        show(&on_chip),
        target.reports().len(),
        started.elapsed().as_secs_f64(),
        show(&on_host)
    );
    assert_eq!(on_chip.error, None, "the link or the shadow check failed");
    assert_eq!(on_chip.reason, Some(reason));
    assert_eq!(on_chip.detection_s, on_host.detection_s, "chip and host detect at different steps");
    assert!(
        on_chip.detection_s.unwrap() <= bound_s + 1e-9,
        "detected after {:?} s, bound {bound_s} s",
        on_chip.detection_s
    );
    let obs = on_chip.observed;
    assert!(!obs.unsafe_output_after_trip && !obs.left_tripped && obs.torque_after_trip_nm == 0.0, "{obs:?}");
    // The chip's last reported state is still the trip.
    assert_eq!(target.reports().last().unwrap().state, DriveState::Tripped(reason));
}

#[test]
fn over_current_of_a_phase_short_on_the_emulated_chip() {
    on_host_and_chip("short@accel", Direction::Up, Fault::OverCurrent, 2.0 * TS);
}

#[test]
fn encoder_stop_and_count_loss_on_the_emulated_chip() {
    on_host_and_chip("encoder-stop@accel", Direction::Down, Fault::BackEmfMismatch, 0.02);
    on_host_and_chip("encoder-lose@accel:fraction=0.5", Direction::Up, Fault::BackEmfMismatch, 0.15);
}

#[test]
fn missed_deadline_and_corrupted_frames_on_the_emulated_chip() {
    on_host_and_chip("deadline-skip@accel:steps=3", Direction::Up, Fault::DeadlineMissed, 3.0 * TS);
    on_host_and_chip("deadline-late@accel:delay_us=120", Direction::Down, Fault::DeadlineMissed, TS);
    // Three frames whose CRC fails: the chip rejects them and trips at the next one.
    on_host_and_chip("frame-corrupt@accel:count=3,byte=9,xor=4", Direction::Up, Fault::DeadlineMissed, 3.0 * TS);
}

/// The start-up sequence and the faults of the application layer
/// (`drive_core::lift_drive::LiftDrive`) on the emulated chip, every step
/// against its host shadow bit for bit (`closed_loop::pil::dcp::Lift`):
/// after power-up the drive calibrates with gates off and the brake
/// applied and the car does not move until the lift controller commands a
/// travel; a current-offset calibration refused at power-up, and a DC-bus
/// over-voltage while idle, each leave gates off, the brake applied and
/// the DCP fault bit S3 set (S0 ready clear), no travel starting while the
/// lift controller keeps asking; the service port's `reset` clears each
/// (the calibration runs again), and the travel then runs and lands.
#[test]
fn start_up_and_faults_of_the_application_layer_on_the_emulated_chip_end_safe_until_the_reset_command() {
    use closed_loop::pil::dcp::{default_elf, default_parameters, geometry, Chip, Lift, Master, Phase, Trip};
    use drive_core::dcp::command::{Mode, Speed};
    use drive_core::dcp::slave::{S0_READY, S3_FAULT};
    use drive_core::dcp::SlaveFrame;
    use drive_core::service::ParamsStatus;
    use drive_core::startup::{CALIBRATION_SAMPLES, SETTLE_STEPS};
    use std::path::Path;

    let rig = rig();
    let drive = rig.drive_config();
    let (geometry, m_car) = geometry(&rig);
    let dir = tempfile::tempdir().unwrap();
    let chip = Chip::launch(&default_elf(), Path::new("qemu-system-arm"), dir.path()).expect("the PIL target starts");
    let lw_start = geometry.lw_lowest_landing_m as f64 + 1.0;
    let mut lift =
        Lift::new(&rig, Some(chip), &default_parameters(&rig), ParamsStatus::None, m_car as f64, lw_start).unwrap();
    let mut master = Master::new(Mode::Dcp4, vec![Trip { target_mm: 1600, speed: Speed::V4 }], &drive);
    let start_mm = lift.position_mm();
    let calibration_steps = (SETTLE_STEPS + CALIBRATION_SAMPLES) as u64;
    let started = Instant::now();
    // One period: the lift controller's bytes, `service` on the service
    // port, the sensors changed by `sense`; the replies' status bytes.
    let k = std::cell::Cell::new(0u64);
    let period = |lift: &mut Lift,
                  master: &mut Master,
                  service: &[u8],
                  sense: &mut dyn FnMut(&mut drive_core::SensorFrame)|
     -> (drive_core::ControlOutput, Vec<u8>, Vec<u8>) {
        let out = master.bytes(k.get(), lift.position_mm());
        let step = lift.step_sensing(&out, service, sense).unwrap_or_else(|e| panic!("{e:#}"));
        master.receive(&step.dcp_replies).unwrap();
        k.set(k.get() + 1);
        let status = step.dcp_replies.chunks(6).map(|c| SlaveFrame::decode(c.try_into().unwrap()).unwrap().status);
        (step.output, status.collect(), step.service_answers)
    };
    let assert_safe = |out: &drive_core::ControlOutput, what: &str| {
        assert!(
            !out.pwm_enabled && !out.brake_released && out.pwm_compare == [0; 3],
            "{what}: gates on or brake released: {out:?}"
        );
    };

    // Power-up with the W current channel reading 1000 codes off mid-scale:
    // the calibration refuses it at its end.
    let mut answers = Vec::new();
    for _ in 0..calibration_steps + 8_000 {
        let calibrating = k.get() < calibration_steps;
        let (out, status, _) = period(&mut lift, &mut master, &[], &mut |s| {
            if calibrating {
                s.phase_current_codes[2] = s.phase_current_codes[2].saturating_add(1000);
            }
        });
        assert_safe(&out, "power-up with a bad current channel");
        for s in status {
            assert_eq!(s & S0_READY, 0, "step {}: ready with a channel off", k.get() - 1);
            if k.get() > calibration_steps + 1 {
                assert_ne!(s & S3_FAULT, 0, "step {}: no fault bit after the refused calibration", k.get() - 1);
            }
        }
        if k.get() > calibration_steps + 1 {
            assert!(matches!(out.state, DriveState::Tripped(Fault::CurrentSensorOffset)), "{:?}", out.state);
        }
    }
    assert!(matches!(master.phase(), Phase::Distance { started: false }), "the lift controller asks for the travel");
    assert!((lift.position_mm() - start_mm).abs() < 0.01, "the car moved: {} mm", lift.position_mm() - start_mm);

    // The reset on the service port: the calibration runs again (the
    // channel reads right now), then the travel the lift controller keeps
    // asking for starts and lands.
    let mut reset_at = None;
    for i in 0..200_000u64 {
        let request: &[u8] = if i == 0 { b"reset\n" } else { &[] };
        let (out, status, answer) = period(&mut lift, &mut master, request, &mut |_| {});
        answers.extend(answer);
        if reset_at.is_none() && answers.ends_with(b"\r\n") {
            reset_at = Some(k.get());
        }
        if reset_at.is_some_and(|r| k.get() < r + calibration_steps) {
            assert_safe(&out, "the calibration after the reset");
            assert!(status.iter().all(|s| s & S0_READY == 0), "ready before the calibration ended");
        }
        if master.phase() == Phase::Done || master.arrivals.len() == 1 {
            break;
        }
    }
    assert_eq!(String::from_utf8_lossy(&answers), "ok reset\r\n");
    let arrival = master.arrivals.first().expect("the travel ran after the reset");
    println!("landed at {:.2} mm after the reset (target 1600 mm)", arrival.position_mm);
    assert!((arrival.position_mm - 1600.0).abs() < 3.0, "{}", arrival.position_mm);

    // Idle at the landing: the DC bus rises over the trip level for 10 ms.
    let over_code = drive.adc_max_code();
    let mut tripped = false;
    for _ in 0..160 {
        let (out, _, _) = period(&mut lift, &mut master, &[], &mut |s| s.dc_bus_code = over_code);
        tripped |= out.state == DriveState::Tripped(Fault::DcBusOverVoltage);
        if tripped {
            assert_safe(&out, "the over-voltage trip");
        }
    }
    assert!(tripped, "the over-voltage while idle trips");
    // Latched with the bus back: S3 set, not ready, safe, until the reset.
    let mut answers = Vec::new();
    for i in 0..4_000u64 {
        let request: &[u8] = if i == 2_000 { b"reset\n" } else { &[] };
        let (out, status, answer) = period(&mut lift, &mut master, request, &mut |_| {});
        answers.extend(answer);
        if answers.is_empty() {
            assert_safe(&out, "the latched over-voltage");
            assert!(status.iter().all(|s| s & S3_FAULT != 0 && s & S0_READY == 0), "{status:02x?}");
        } else if answers.ends_with(b"\r\n") && i > 2_100 {
            assert_eq!(out.state, DriveState::Idle);
            assert!(status.iter().all(|s| s & S3_FAULT == 0 && s & S0_READY != 0), "{status:02x?}");
        }
    }
    assert_eq!(String::from_utf8_lossy(&answers), "ok reset\r\n");
    let ask = |lift: &mut Lift, line: &str| lift.ask(line, 2_000).unwrap_or_else(|e| panic!("{e:#}")).0;
    assert_eq!(ask(&mut lift, "get faults"), "faults 2 8 4");
    assert_eq!(ask(&mut lift, "align"), "error unsupported", "the loop's machine gives the angle");
    println!(
        "{} steps with start-up and fault resets, chip and host identical, in {:.1} s",
        k.get(),
        started.elapsed().as_secs_f64()
    );
}

/// The emulated chip and its host shadow on a plant of their own, so that
/// the chip can be restarted while the lift goes on: a watchdog reset
/// (or any reset of the microcontroller alone) leaves the machine, the
/// car and the ropes as they were, moving or not, and boots the firmware
/// afresh, as `Chip::launch` boots the target afresh in the same working
/// directory (its emulated flash kept).
struct Restartable {
    rig: rig_config::RigConfig,
    dir: tempfile::TempDir,
    plant: plant::Plant,
    chip: Option<closed_loop::pil::dcp::Chip>,
    shadow: drive_core::lift_drive::LiftDrive,
    max_step_s: f64,
    lw_lowest_landing_m: f64,
    steps: u64,
}

/// The shadow's edges in [`Restartable`]: the DCP bytes the chip took, its replies.
struct TakenBytes {
    dcp: std::collections::VecDeque<u8>,
    replies: Vec<u8>,
}

impl drive_core::lift_drive::PeriodIo for TakenBytes {
    fn service_byte(&mut self) -> Option<u8> {
        None
    }

    fn dcp_byte(&mut self) -> Option<u8> {
        self.dcp.pop_front()
    }

    fn drive(&mut self, _output: &drive_core::lift_drive::DriveOutput) {}

    fn service_reply(&mut self, _reply: &drive_core::lift_drive::ServiceReply) {}

    fn dcp_reply(&mut self, reply: &[u8; 6]) {
        self.replies.extend_from_slice(reply);
    }
}

impl Restartable {
    /// The car at rest `lw_start_m` with the rig's heaviest car, the chip booted.
    fn new(lw_start_m: f64) -> Self {
        let rig = rig();
        let (geometry, m_car) = closed_loop::pil::dcp::geometry(&rig);
        let mut lift = Self {
            plant: plant::Plant::new(&rig, m_car as f64, lw_start_m),
            max_step_s: closed_loop::SimOptions::for_rig(&rig).max_step_s,
            lw_lowest_landing_m: geometry.lw_lowest_landing_m as f64,
            dir: tempfile::tempdir().unwrap(),
            chip: None,
            shadow: closed_loop::pil::dcp::shadow(
                &rig,
                &closed_loop::pil::dcp::default_parameters(&rig),
                drive_core::service::ParamsStatus::None,
            ),
            rig,
            steps: 0,
        };
        lift.reset_chip();
        lift
    }

    /// The chip reset on its own (a watchdog reset): QEMU stopped where it
    /// was and started again on the same target and emulated flash; the
    /// shadow is the application layer as the firmware builds it after
    /// any reset. The plant is not touched.
    fn reset_chip(&mut self) {
        use closed_loop::pil::dcp::{default_elf, default_parameters, shadow, Chip};
        self.chip = None; // QEMU killed first: one target on the sockets at a time
        let chip = Chip::launch(&default_elf(), std::path::Path::new("qemu-system-arm"), self.dir.path());
        self.chip = Some(chip.expect("the PIL target starts"));
        self.shadow = shadow(&self.rig, &default_parameters(&self.rig), drive_core::service::ParamsStatus::None);
    }

    fn position_mm(&self) -> f64 {
        (self.plant.observe().counterweight_side_length_m - self.lw_lowest_landing_m) * 1000.0
    }

    /// One PWM period with `dcp_out` on the DCP line: the chip's step
    /// checked bit for bit against the shadow's, the plant advanced on the
    /// outputs; the outputs and the DCP replies.
    fn period(&mut self, dcp_out: &[u8]) -> (drive_core::ControlOutput, Vec<u8>) {
        let k = self.steps;
        let sensors = closed_loop::sensor_frame(&self.plant);
        let chip =
            self.chip.as_mut().unwrap().step(dcp_out, &[], &sensors).unwrap_or_else(|e| panic!("step {k}: {e:#}"));
        let mut io = TakenBytes { dcp: chip.dcp_taken.iter().copied().collect(), replies: Vec::new() };
        let output = self.shadow.period(&sensors, &mut io).drive.control;
        assert!(io.dcp.is_empty(), "step {k}: the shadow left DCP bytes the chip took");
        assert!(chip.report.matches(&output), "step {k}: chip {:?}, host {output:?}", chip.report);
        assert_eq!(chip.dcp_replies, io.replies, "step {k}: DCP replies differ");
        self.plant.set_inputs(plant::PlantInputs {
            pwm_compare: output.pwm_compare,
            pwm_enabled: output.pwm_enabled,
            brake_engaged: !output.brake_released,
        });
        self.plant.advance(1.0 / self.rig.drive_config().current_loop_hz as f64, self.max_step_s);
        assert!(self.plant.in_valid_range(), "step {k}: the plant left its valid range");
        self.steps += 1;
        (output, io.replies)
    }
}

/// A watchdog reset of the emulated chip, mid-travel and again idle at the
/// landing, with the machine and the car going on as they were: from the
/// first period after each reset the gates are off and the brake applied
/// (the car, stopped by the brake, stays where it stopped), the drive does
/// not report ready before its calibration has ended, and the car does not
/// move while the lift controller commands nothing; it moves again only
/// when the lift controller commands a travel, which lands: the pole
/// position after the reset is the simulated absolute encoder's stored
/// offset (`AngleReference::Given`), not the rotor's position at the reset
/// (taking that as electrical zero tripped the travel after the reset with
/// a back-EMF mismatch, the car 0.7 mm off). Every period is the chip's
/// `LiftDrive` against its host shadow, bit for bit.
#[test]
fn a_watchdog_reset_mid_travel_and_idle_leaves_the_drive_safe_until_a_command() {
    use closed_loop::pil::dcp::{Master, Phase, Trip};
    use drive_core::dcp::command::{Mode, Speed};
    use drive_core::dcp::slave::S0_READY;
    use drive_core::dcp::SlaveFrame;
    use drive_core::startup::{CALIBRATION_SAMPLES, SETTLE_STEPS};

    let started = Instant::now();
    let drive = rig().drive_config();
    let calibration_steps = (SETTLE_STEPS + CALIBRATION_SAMPLES) as u64;
    let (geometry, _) = closed_loop::pil::dcp::geometry(&rig());
    let mut lift = Restartable::new(geometry.lw_lowest_landing_m as f64 + 1.0);
    let status = |replies: &[u8]| -> Vec<u8> {
        replies.chunks(6).map(|c| SlaveFrame::decode(c.try_into().unwrap()).unwrap().status).collect()
    };
    let period = |lift: &mut Restartable, master: &mut Master| {
        let k = lift.steps;
        let out = master.bytes(k, lift.position_mm());
        let (output, replies) = lift.period(&out);
        master.receive(&replies).unwrap();
        (output, status(&replies))
    };
    let assert_safe = |out: &drive_core::ControlOutput, what: &str| {
        assert!(
            !out.pwm_enabled && !out.brake_released && out.pwm_compare == [0; 3],
            "{what}: gates on or brake released: {out:?}"
        );
    };
    // After a reset: a lift controller that commands no travel (it sends
    // the car position, then idle messages); `what` names the case. The
    // drive must stay safe throughout, report ready only after its
    // calibration, and the car, once the brake has stopped it, must not
    // move. Returns the car's speed at the reset and how far it went after it.
    let after_reset = |lift: &mut Restartable, what: &str| -> (f64, f64) {
        let speed_at_reset = lift.plant.observe().shaft_speed_radps;
        lift.reset_chip();
        let mut idle = Master::new(Mode::Dcp4, vec![], &drive);
        let at_reset_mm = lift.position_mm();
        let mut stopped_at: Option<f64> = None;
        for i in 0..calibration_steps + 8_000 {
            let (out, status) = period(lift, &mut idle);
            assert_safe(&out, what);
            if i < calibration_steps {
                assert!(status.iter().all(|s| s & S0_READY == 0), "{what}, period {i}: ready while calibrating");
            }
            let speed = lift.plant.observe().shaft_speed_radps.abs();
            match stopped_at {
                None if speed < 1e-3 && i > 0 => stopped_at = Some(lift.position_mm()),
                Some(p) => {
                    let drift = (lift.position_mm() - p).abs();
                    assert!(drift < 0.05, "{what}, period {i}: the car moved {drift} mm with the brake applied");
                }
                None => {}
            }
        }
        assert!(stopped_at.is_some(), "{what}: the brake did not stop the car");
        assert_eq!(idle.phase(), Phase::Done, "{what}: the lift controller's messages were answered");
        (speed_at_reset, lift.position_mm() - at_reset_mm)
    };

    // Power-up, then a travel up 600 mm at rated speed; the watchdog
    // resets the chip at cruising speed.
    let mut master = Master::new(Mode::Dcp4, vec![Trip { target_mm: 1600, speed: Speed::V4 }], &drive);
    let cruise = 0.5 * drive.rated_shaft_speed_radps() as f64;
    let mut reached = false;
    for _ in 0..200_000 {
        period(&mut lift, &mut master);
        if lift.plant.observe().shaft_speed_radps > cruise {
            reached = true;
            break;
        }
    }
    assert!(reached, "the travel did not reach {cruise} rad/s");
    let (speed, stopping_mm) = after_reset(&mut lift, "the reset mid-travel");
    // The plant's brake holds the sheave as soon as it is applied: the car
    // stops within the ropes' stretch.
    println!("reset at {speed:.2} rad/s: the car stopped {stopping_mm:.3} mm on, gates off throughout");
    assert!(speed > cruise && stopping_mm.abs() < 100.0, "{speed} rad/s, {stopping_mm} mm");

    // The lift controller commands a travel: it runs and lands (the pole
    // position from the encoder's stored offset, not from where the rotor
    // was when the chip restarted).
    let mut master = Master::new(Mode::Dcp4, vec![Trip { target_mm: 1300, speed: Speed::V4 }], &drive);
    for _ in 0..200_000 {
        period(&mut lift, &mut master);
        if !master.arrivals.is_empty() {
            break;
        }
    }
    let arrival = master.arrivals.first().expect("the travel commanded after the reset ran");
    assert!((arrival.position_mm - 1300.0).abs() < 3.0, "landed at {} mm", arrival.position_mm);

    // Idle at the landing, the watchdog resets the chip again.
    for _ in 0..2_000 {
        period(&mut lift, &mut master);
    }
    let (speed, moved_mm) = after_reset(&mut lift, "the reset idle at the landing");
    assert!(speed.abs() < 1e-3 && moved_mm.abs() < 0.05, "idle: {speed} rad/s, moved {moved_mm} mm");
    println!(
        "{} periods with two watchdog resets, chip and host identical, in {:.1} s",
        lift.steps,
        started.elapsed().as_secs_f64()
    );
}
