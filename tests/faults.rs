//! Drive safety under faults: every fault kind injected into a closed-loop
//! travel is detected within its stated bound, the drive goes to and stays
//! in its safe state (PWM off, brake commanded, no machine torque) until an
//! explicit reset; the 8 nominal travels keep their consistency checks well
//! below the trip levels; and arbitrary sensor inputs never make the
//! controller panic or leave its safe state once tripped.
//!
//! `cargo test -p host-sim --test integration faults:: -- --nocapture`
//! prints the measured figures.

use crate::support::rig;
use closed_loop::faults::run::{run_case_with, FaultCase, FaultOutcome};
use closed_loop::faults::{parse_fault, FaultSpec};
use closed_loop::{simulate_travel_with, DriveController, SimError, SimOptions, TravelSpec};
use drive_core::config::Direction;
use drive_core::controller::CommandError;
use drive_core::supervisor::{Fault, MonitorLevels, BACK_EMF_TAU_S, CURRENT_SUM_TAU_S};
use drive_core::{ControlOutput, Controller, DriveState, SensorFrame, TravelCommand};
use proptest::prelude::*;

/// Current-loop period of the rig, s.
const TS: f64 = 1.0 / 16_000.0;
/// Speed-loop period of the rig, s.
const TSL: f64 = 1.0 / 2_000.0;

/// The drive core, keeping the largest consistency-check levels it reached.
struct Watched {
    controller: Controller,
    worst: MonitorLevels,
}

impl DriveController for Watched {
    fn command_travel(&mut self, command: TravelCommand) -> Result<(), SimError> {
        DriveController::command_travel(&mut self.controller, command)
    }
    fn step(&mut self, sensors: &SensorFrame) -> Result<ControlOutput, SimError> {
        let out = self.controller.step(sensors);
        let l = self.controller.monitor_levels();
        let w = &mut self.worst;
        w.current_sum_a = w.current_sum_a.max(l.current_sum_a);
        w.tracking_a = w.tracking_a.max(l.tracking_a);
        w.back_emf_residual_v = w.back_emf_residual_v.max(l.back_emf_residual_v);
        w.following_radps = w.following_radps.max(l.following_radps);
        Ok(out)
    }
}

#[test]
fn the_8_nominal_travels_stay_well_below_every_consistency_level() {
    let rig = rig();
    let mut worst_ratio: f32 = 0.0;
    for &m_car in &rig.mechanics.m_car_kg {
        for direction in [Direction::Up, Direction::Down] {
            let spec = TravelSpec::full_travel(&rig, m_car, direction);
            let mut w = Watched { controller: Controller::new(&rig.drive_config()), worst: MonitorLevels::default() };
            simulate_travel_with(&rig, &spec, &SimOptions::for_rig(&rig), &mut w, None, None)
                .unwrap_or_else(|e| panic!("m_car {m_car} {direction:?}: {e}"));
            let m = w.controller.supervisor_limits().monitors;
            let ratios = [
                w.worst.current_sum_a / m.current_sum_level_a,
                w.worst.tracking_a / m.tracking_level_a,
                w.worst.back_emf_residual_v / m.back_emf_level_v,
                w.worst.following_radps / m.following_level_radps,
            ];
            println!(
                "m_car {m_car:5.1} kg {direction:?}: current sum {:.3}/{:.3} A, tracking {:.3}/{:.3} A, back-EMF residual {:.2}/{:.2} V, following {:.3}/{:.3} rad/s",
                w.worst.current_sum_a,
                m.current_sum_level_a,
                w.worst.tracking_a,
                m.tracking_level_a,
                w.worst.back_emf_residual_v,
                m.back_emf_level_v,
                w.worst.following_radps,
                m.following_level_radps
            );
            worst_ratio = ratios.iter().fold(worst_ratio, |a, &b| a.max(b));
        }
    }
    println!("largest nominal level: {:.0} % of its trip level", 100.0 * worst_ratio);
    assert!(worst_ratio < 0.7, "a nominal travel reaches {:.0} % of a trip level", 100.0 * worst_ratio);
}

/// A 1.5 m travel of the heaviest car: long enough for every instant, short
/// enough to run every fault in a debug build.
fn travel(direction: Direction) -> TravelSpec {
    let (lw_start_m, lw_end_m) = match direction {
        Direction::Up => (3.0, 4.5),
        Direction::Down => (4.5, 3.0),
    };
    TravelSpec { m_car_kg: 70.5, direction, lw_start_m, lw_end_m }
}

/// Runs `faults` (the `--fault` syntax) on a fresh drive core; returns the
/// outcome and the controller after the run.
fn run(faults: &[&str], direction: Direction) -> (FaultOutcome, Controller) {
    let rig = rig();
    let specs: Vec<FaultSpec> = faults.iter().map(|f| parse_fault(f).unwrap()).collect();
    let case = FaultCase { travel: travel(direction), faults: specs };
    let mut controller = Controller::new(&rig.drive_config());
    let outcome = run_case_with(&rig, &case, &mut controller, 0.3);
    (outcome, controller)
}

/// Asserts a detection within `bound_s` with one of `reasons`, then the safe
/// state to the end of the run and recovery only by reset.
fn assert_detected(faults: &[&str], direction: Direction, reasons: &[Fault], bound_s: f64) -> FaultOutcome {
    let (o, mut controller) = run(faults, direction);
    let obs = o.observed;
    println!(
        "{:45} {direction:?}: detection {} ms (bound {:.3} ms), reason {:?}, peak current {:.1} A, peak car acc. {:.2} m/s^2 (after trip {:.2}), displacement after detection {:.2} mm",
        o.label,
        o.detection_s.map_or("-".into(), |d| format!("{:.3}", d * 1e3)),
        bound_s * 1e3,
        o.reason,
        obs.peak_current_a,
        obs.peak_car_acceleration_mps2,
        obs.peak_car_acceleration_after_trip_mps2,
        obs.car_displacement_after_trip_m * 1e3
    );
    assert_eq!(o.error, None, "{}", o.label);
    let detection = o.detection_s.unwrap_or_else(|| panic!("{}: not detected", o.label));
    let reason = o.reason.unwrap();
    assert!(reasons.contains(&reason), "{}: reason {reason:?}, expected one of {reasons:?}", o.label);
    assert!(detection <= bound_s + 1e-9, "{}: detected after {detection} s, bound {bound_s} s", o.label);
    // Safe state from the trip to the end of the run (0.3 s): PWM off and
    // brake commanded at every step, no machine torque (nothing can push the
    // car away from its reference), never left Tripped by itself.
    assert!(!obs.unsafe_output_after_trip, "{}: PWM on or brake released after the trip", o.label);
    assert_eq!(obs.torque_after_trip_nm, 0.0, "{}: machine torque after the trip", o.label);
    assert!(!obs.left_tripped, "{}: left Tripped without a reset", o.label);
    assert!(
        obs.car_displacement_after_trip_m < 0.02,
        "{}: car moved {} m after the trip",
        o.label,
        obs.car_displacement_after_trip_m
    );
    // Recovery only by an explicit reset.
    assert_eq!(controller.state(), DriveState::Tripped(reason));
    let command = TravelCommand { direction, distance_m: 0.5, m_car_kg: 70.5, lw_start_m: 4.0 };
    assert_eq!(controller.command_travel(command), Err(CommandError::NotIdle));
    controller.reset();
    assert_eq!(controller.state(), DriveState::Idle);
    o
}

#[test]
fn a_phase_to_phase_short_trips_on_over_current_within_two_periods() {
    // The short current rises through 30 A within the period it starts in
    // (10 V over 20 uH is 0.5 A/us); the next sample sees it.
    for (fault, direction) in [("short@accel", Direction::Up), ("short@cruise:from=b,to=c", Direction::Down)] {
        let o = assert_detected(&[fault], direction, &[Fault::OverCurrent], 2.0 * TS);
        assert!(o.observed.peak_current_a > 30.0);
    }
}

#[test]
fn a_disconnected_current_sensor_trips_in_the_same_step() {
    for (fault, direction) in [
        ("current-disconnected@accel", Direction::Up),
        ("current-disconnected@decel:phase=c,reads=zero-code", Direction::Down),
    ] {
        assert_detected(&[fault], direction, &[Fault::CurrentSensorImplausible], TS);
    }
}

#[test]
fn a_drifting_current_sensor_trips_once_its_offset_passes_the_filtered_level() {
    // Offset rate * t crosses the 1.67 A level of the low-passed sum after
    // level/rate; the filter adds at most 2 tau, the tick one speed period.
    let rate = 20.0;
    let level = 5.0 / 3.0;
    let bound = level / rate + 2.0 * CURRENT_SUM_TAU_S as f64 + TSL;
    assert_detected(&["current-drift@cruise:rate_a_per_s=20"], Direction::Up, &[Fault::CurrentSensorOffset], bound);
    assert_detected(
        &["current-drift@accel:phase=b,rate_a_per_s=-20"],
        Direction::Down,
        &[Fault::CurrentSensorOffset],
        bound,
    );
}

#[test]
fn a_current_sensor_stuck_at_zero_amperes_trips_within_100_ms() {
    // Stuck at 0 A the reading is wrong by the phase's own current, so the
    // sum and the current loop disagree as soon as the phase carries current.
    let reasons =
        [Fault::CurrentSensorOffset, Fault::CurrentTracking, Fault::BackEmfMismatch, Fault::CurrentSensorImplausible];
    assert_detected(&["current-stuck@accel"], Direction::Up, &reasons, 0.1);
    assert_detected(&["current-stuck@cruise:phase=b"], Direction::Down, &reasons, 0.1);
}

#[test]
fn an_encoder_that_stops_while_the_shaft_turns_trips_on_the_back_emf_within_20_ms() {
    // At 0.4 m/s the missing back-EMF is 4x the 4.15 V level: the filter
    // alone needs tau ln(4/3); the current loop takes a few ms to show it.
    for (instant, direction) in [("accel", Direction::Up), ("cruise", Direction::Down), ("decel", Direction::Up)] {
        let o = assert_detected(&[&format!("encoder-stop@{instant}")], direction, &[Fault::BackEmfMismatch], 0.02);
        assert!(o.detection_s.unwrap() > BACK_EMF_TAU_S as f64 * 0.25, "faster than the filter allows");
    }
}

#[test]
fn an_encoder_losing_counts_trips_within_150_ms() {
    // A quarter of the counts lost: the electrical angle slips by a quarter
    // of the true one, the back-EMF turns out of the model's axis.
    assert_detected(&["encoder-lose@cruise"], Direction::Up, &[Fault::BackEmfMismatch], 0.15);
    assert_detected(&["encoder-lose@accel:fraction=0.5"], Direction::Down, &[Fault::BackEmfMismatch], 0.15);
}

#[test]
fn an_encoder_jump_trips_in_the_same_step() {
    assert_detected(&["encoder-jump@cruise"], Direction::Up, &[Fault::EncoderImplausible], TS);
    assert_detected(&["encoder-jump@accel:counts=-50"], Direction::Down, &[Fault::EncoderImplausible], TS);
}

#[test]
fn an_open_phase_trips_within_200_ms() {
    let reasons = [Fault::BackEmfMismatch, Fault::CurrentTracking, Fault::SpeedFollowing];
    assert_detected(&["open-phase@cruise"], Direction::Up, &reasons, 0.2);
    assert_detected(&["open-phase@accel:phase=b"], Direction::Down, &reasons, 0.2);
}

#[test]
fn dc_bus_sag_and_over_voltage_trip_when_the_bus_crosses_its_limit() {
    // 100 V nominal; limits 70 V and 130 V; ramps at the given rates.
    assert_detected(
        &["bus-sag@cruise:to_v=50,rate_v_per_s=1000"],
        Direction::Up,
        &[Fault::DcBusUnderVoltage],
        0.030 + TS,
    );
    assert_detected(
        &["bus-over@decel:to_v=150,rate_v_per_s=500"],
        Direction::Down,
        &[Fault::DcBusOverVoltage],
        0.060 + TS,
    );
}

#[test]
fn missed_and_late_control_steps_trip_at_the_next_step_that_runs() {
    // The deadline is 2.5 periods between two steps: 3 skipped steps make
    // the next one 4 periods after the last; a step 120 us late is 3 periods after it.
    assert_detected(&["deadline-skip@accel:steps=3"], Direction::Up, &[Fault::DeadlineMissed], 3.0 * TS);
    assert_detected(&["deadline-late@cruise:delay_us=120"], Direction::Down, &[Fault::DeadlineMissed], TS);
    // One skipped step (2 periods between steps) is within the deadline.
    let (o, _) = run(&["deadline-skip@accel:steps=1"], Direction::Up);
    assert_eq!(o.reason, None, "one missed step must not trip");
}

#[test]
fn corrupted_link_frames_are_rejected_and_a_burst_trips_as_a_missed_deadline() {
    assert_detected(&["frame-corrupt@cruise:count=3"], Direction::Up, &[Fault::DeadlineMissed], 3.0 * TS);
    // Five frames lost (a CRC byte corrupted): the step after them trips.
    assert_detected(
        &["frame-corrupt@accel:count=5,byte=17,xor=1"],
        Direction::Down,
        &[Fault::DeadlineMissed],
        5.0 * TS,
    );
}

#[test]
fn a_sudden_load_loss_trips_on_speed_following_within_100_ms() {
    // 50 kg of the car's 70.5 kg lost (a slack rope): 32 N m of out-of-balance
    // torque gone at once.
    assert_detected(&["load-change@cruise"], Direction::Up, &[Fault::SpeedFollowing], 0.1);
    assert_detected(&["load-change@accel"], Direction::Down, &[Fault::SpeedFollowing], 0.1);
}

#[test]
fn a_smaller_load_change_is_ridden_through_and_the_car_lands_on_target() {
    // 30 kg (19 N m) is within what the speed loop corrects without leaving
    // its following band: no trip, and the landing is as accurate as nominal.
    let (o, _) = run(&["load-change@cruise:delta_kg=30"], Direction::Up);
    println!("load-change +30 kg: reason {:?}, landing error {:?} m", o.reason, o.landing_error_m);
    assert_eq!(o.reason, None);
    assert!(o.landing_error_m.unwrap().abs() < 0.005);
}

#[test]
fn a_brake_that_does_not_open_trips_on_speed_following_within_half_a_second_of_the_profile_start() {
    let profile_start = 0.35;
    assert_detected(&["brake-stuck@start"], Direction::Up, &[Fault::SpeedFollowing], profile_start + 0.5);
    let o = assert_detected(&["brake-stuck@start"], Direction::Down, &[Fault::SpeedFollowing], profile_start + 0.5);
    assert!(o.detection_s.unwrap() > profile_start, "tripped before the profile asked for motion");
}

#[test]
fn several_faults_at_once_trip_on_the_first_detectable_one() {
    let o = assert_detected(
        &["encoder-stop@accel", "bus-sag@accel:to_v=60,rate_v_per_s=100", "deadline-skip@cruise:steps=10"],
        Direction::Up,
        &[Fault::BackEmfMismatch],
        0.02,
    );
    assert_eq!(o.label, "encoder-stop@accel+bus-sag@accel+deadline-skip@cruise");
}

/// A plausible frame near the state of a drive at rest, or anything at all.
fn frame_strategy() -> impl Strategy<Value = (SensorFrame, u32)> {
    let plausible =
        (prop::array::uniform3(2000u16..2100), -8i32..8, 1900u16..2200, 55u32..70).prop_map(|(codes, step, dc, dt)| {
            (SensorFrame { phase_current_codes: codes, encoder_count: step as u32, dc_bus_code: dc, time_us: dt }, 1)
        });
    let anything = (prop::array::uniform3(any::<u16>()), any::<u32>(), any::<u16>(), any::<u32>()).prop_map(
        |(codes, enc, dc, t)| {
            (SensorFrame { phase_current_codes: codes, encoder_count: enc, dc_bus_code: dc, time_us: t }, 0)
        },
    );
    prop_oneof![20 => plausible, 1 => anything]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Arbitrary ADC codes, encoder counts and time stamps (mostly plausible
    /// increments so that travels run, sometimes anything): the controller
    /// never panics, and once tripped it keeps PWM off (compares 0) and the
    /// brake applied at every step until the reset; then it runs again.
    #[test]
    fn arbitrary_sensor_inputs_never_panic_and_never_leave_the_safe_state(
        frames in prop::collection::vec(frame_strategy(), 2_000..12_000),
        reset_at in 0usize..12_000,
        m_car in 1.0f32..200.0,
        up in any::<bool>(),
    ) {
        let rig = rig();
        let mut c = Controller::new(&rig.drive_config());
        let direction = if up { Direction::Up } else { Direction::Down };
        let command = TravelCommand { direction, distance_m: 1.0, m_car_kg: m_car, lw_start_m: 4.0 };
        prop_assert!(c.command_travel(command).is_ok());
        let (mut encoder, mut time_us) = (0u32, 0u32);
        let mut tripped: Option<Fault> = None;
        for (k, (frame, relative)) in frames.iter().enumerate() {
            let mut f = *frame;
            if *relative == 1 {
                // Plausible: increments on the running counter and clock.
                encoder = encoder.wrapping_add(f.encoder_count);
                time_us = time_us.wrapping_add(f.time_us);
                f.encoder_count = encoder;
                f.time_us = time_us;
            } else {
                encoder = f.encoder_count;
                time_us = f.time_us;
            }
            if k == reset_at {
                c.reset();
                tripped = None;
                prop_assert_eq!(c.state(), DriveState::Idle);
            }
            let out = c.step(&f);
            if let Some(fault) = tripped {
                prop_assert_eq!(out.state, DriveState::Tripped(fault), "left Tripped at step {}", k);
            }
            if let DriveState::Tripped(fault) = out.state {
                tripped = Some(fault);
                prop_assert!(!out.pwm_enabled && !out.brake_released && out.pwm_compare == [0; 3], "{:?}", out);
                prop_assert_eq!(c.command_travel(command), Err(CommandError::NotIdle));
            }
            prop_assert!(out.pwm_compare.iter().all(|&v| v <= 5312), "{:?}", out.pwm_compare);
        }
    }
}
