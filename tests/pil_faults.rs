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
