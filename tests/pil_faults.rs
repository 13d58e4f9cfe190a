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
/// against its host shadow bit for bit (`host_sim::cli::pil::dcp::Lift`):
/// after power-up the drive calibrates with gates off and the brake
/// applied and the car does not move until the lift controller commands a
/// travel; a current-offset calibration refused at power-up, and a DC-bus
/// over-voltage while idle, each leave gates off, the brake applied and
/// the DCP fault bit S3 set (S0 ready clear), no travel starting while the
/// lift controller keeps asking; the service port's `reset` clears each
/// (the calibration runs again), and the travel then runs and lands.
#[test]
fn start_up_and_faults_of_the_application_layer_on_the_emulated_chip_end_safe_until_the_reset_command() {
    use drive_core::dcp::command::{Mode, Speed};
    use drive_core::dcp::slave::{S0_READY, S3_FAULT};
    use drive_core::dcp::SlaveFrame;
    use drive_core::service::ParamsStatus;
    use drive_core::startup::{CALIBRATION_SAMPLES, SETTLE_STEPS};
    use host_sim::cli::pil::dcp::{default_elf, default_parameters, geometry, Chip, Lift, Master, Phase, Trip};
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
