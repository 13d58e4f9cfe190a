//! Processor-in-the-loop: the drive core compiled for the Cortex-M4F, in
//! QEMU's mps2-an386, against the host build of the same code. Needs
//! `qemu-system-arm` and the target ELF (`scripts/test.sh` provides both).

use std::time::Instant;

use crate::support::rig;
use closed_loop::pil::{PilOptions, PilTarget};
use closed_loop::{simulate_travel_with, DriveController, SimOptions, StepLog, TravelSpec};
use drive_core::config::Direction;
use drive_core::frame::StepReport;
use drive_core::{ControlOutput, Controller, DriveState};

fn launch() -> PilTarget {
    PilTarget::launch(&PilOptions::default(), &rig().drive_config()).unwrap_or_else(|e| panic!("{e}"))
}

/// Panics at the first step whose target report is not the host output.
fn assert_bit_identical(log: &StepLog, reports: &[StepReport], host: &[ControlOutput]) {
    assert_eq!(reports.len(), host.len(), "one report per step");
    if let Some(step) = (0..host.len()).find(|&i| !reports[i].matches(&host[i])) {
        panic!(
            "first differing step {step}:\n  inputs {:?}\n  host   {:?}\n  target {:?}",
            log.steps[step].0,
            StepReport::new(&host[step], reports[step].cost_ticks),
            reports[step]
        );
    }
}

#[test]
fn closed_loop_on_the_emulated_chip_is_bit_identical_to_the_host_build() {
    let rig = rig();
    let spec = TravelSpec::full_travel(&rig, 70.5, Direction::Up);
    // 0.35 s of pre-torque and brake lift, then 0.9 s into the acceleration.
    let options = SimOptions { max_control_steps: Some(20_000), ..SimOptions::for_rig(&rig) };
    let mut target = launch();
    let mut log = StepLog::default();
    let started = Instant::now();
    simulate_travel_with(&rig, &spec, &options, &mut target, None, Some(&mut log)).unwrap_or_else(|e| panic!("{e}"));
    println!("{} closed-loop PIL steps in {:.1} s", log.steps.len(), started.elapsed().as_secs_f64());
    assert!(log.steps.len() >= 16_000);
    assert!(
        log.steps.iter().any(|s| s.1.state == DriveState::Travel && s.1.telemetry.ref_speed_mps > 0.3),
        "the run must go from rest through the acceleration"
    );
    // An independent host build fed the logged inputs.
    let mut host = Controller::new(&rig.drive_config());
    host.command_travel(log.command.expect("a travel command")).unwrap();
    let expected: Vec<ControlOutput> = log.steps.iter().map(|s| host.step(&s.0)).collect();
    assert_bit_identical(&log, target.reports(), &expected);
}

#[test]
fn a_whole_host_travel_replayed_on_the_emulated_chip_gives_the_same_outputs() {
    let rig = rig();
    // A whole short travel: start, run-up, stop, brake, idle.
    let spec = TravelSpec { m_car_kg: 58.0, direction: Direction::Down, lw_start_m: 5.0, lw_end_m: 4.6 };
    let mut host = Controller::new(&rig.drive_config());
    let mut log = StepLog::default();
    simulate_travel_with(&rig, &spec, &SimOptions::for_rig(&rig), &mut host, None, Some(&mut log)).unwrap();
    let expected: Vec<ControlOutput> = log.steps.iter().map(|s| s.1).collect();
    assert!(expected.iter().any(|o| o.state == DriveState::BrakeSet));
    assert_eq!(expected.last().unwrap().state, DriveState::Idle);

    let mut target = launch();
    let started = Instant::now();
    target.command_travel(log.command.unwrap()).unwrap();
    for (sensors, _) in &log.steps {
        if let Err(e) = target.step(sensors) {
            panic!("{e}");
        }
    }
    println!("replayed {} steps of a whole travel in {:.1} s", log.steps.len(), started.elapsed().as_secs_f64());
    assert_bit_identical(&log, target.reports(), &expected);
}
