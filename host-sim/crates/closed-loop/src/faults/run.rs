//! One faulted travel and what it did, and the case matrix of
//! `host-sim faults`: every fault kind at several instants of a travel, in
//! both directions.

use drive_core::config::Direction;
use drive_core::controller::{BRAKE_LIFT_S, PRE_TORQUE_S};
use drive_core::profile::SCurve;
use drive_core::supervisor::Fault;
use drive_core::Controller;

use super::inject::{FaultInjector, Observed};
use super::{FaultKind, FaultSpec, Instant, Onset, KIND_NAMES};
use crate::{simulate_travel_faulted, DriveController, SimOptions, TravelSpec};
use rig_config::RigConfig;

/// Simulated time after a trip, s: long enough for the car to settle on
/// the ropes with the brake applied.
pub const AFTER_TRIP_S: f64 = 0.5;

/// One faulted travel to run.
#[derive(Clone, Debug, PartialEq)]
pub struct FaultCase {
    /// The travel.
    pub travel: TravelSpec,
    /// The faults (several at once allowed).
    pub faults: Vec<FaultSpec>,
}

/// What a faulted travel did.
#[derive(Clone, Debug, PartialEq)]
pub struct FaultOutcome {
    /// The faults, as `KIND@WHEN` joined with `+`.
    pub label: String,
    /// Their parameters in words, joined with `; `.
    pub parameters: String,
    /// Car mass, kg.
    pub m_car_kg: f64,
    /// Direction.
    pub direction: Direction,
    /// Earliest onset, s from the travel command.
    pub onset_s: f64,
    /// Trip time minus onset, s (none: not detected).
    pub detection_s: Option<f64>,
    /// Reason of the trip.
    pub reason: Option<Fault>,
    /// What the injector saw (peaks, displacement after the trip, safe state).
    pub observed: Observed,
    /// Landing error at the end of an undetected travel, m.
    pub landing_error_m: Option<f64>,
    /// How the simulation ended otherwise (plant out of range, timeout).
    pub error: Option<String>,
}

/// Start (s after the travel command) and duration (s) of the profile of `travel` on `rig`.
pub fn profile_timing_s(rig: &RigConfig, travel: &TravelSpec) -> (f64, f64) {
    let t = &rig.travel;
    let distance = (travel.lw_end_m - travel.lw_start_m).abs();
    let duration =
        SCurve::plan(distance as f32, t.rated_speed_mps as f32, t.max_accel_mps2 as f32, t.max_jerk_mps3 as f32)
            .map(|p| p.duration_s() as f64)
            .unwrap_or(0.0);
    ((PRE_TORQUE_S + BRAKE_LIFT_S) as f64, duration)
}

/// Seconds from the travel command of `onset` for `travel` on `rig`.
pub fn onset_time_s(rig: &RigConfig, travel: &TravelSpec, onset: Onset) -> f64 {
    match onset {
        Onset::At(t) => t,
        Onset::Named(instant) => {
            let (start, duration) = profile_timing_s(rig, travel);
            instant.time_s(start, duration)
        }
    }
}

/// Runs `case` with `controller` in the loop (a fresh controller per case).
pub fn run_case_with(
    rig: &RigConfig,
    case: &FaultCase,
    controller: &mut dyn DriveController,
    after_trip_s: f64,
) -> FaultOutcome {
    let mut injector = FaultInjector::new(
        &case.faults,
        |onset| onset_time_s(rig, &case.travel, onset),
        rig.mechanics.gravity_mps2,
        Some(after_trip_s),
    );
    let options = SimOptions { tail_s: 0.1, ..SimOptions::for_rig(rig) };
    let result = simulate_travel_faulted(rig, &case.travel, &options, controller, Some(&mut injector), None, None);
    let observed = injector.observed();
    let onset_s = injector.onsets_s().into_iter().fold(f64::INFINITY, f64::min);
    let (mut landing_error_m, mut error) = (None, None);
    match result {
        Ok(run) if observed.trip.is_none() => {
            landing_error_m = run.lw_m.last().map(|lw| lw - case.travel.lw_end_m);
        }
        Ok(_) => {}
        // Plant out of range, timeout, a link failure, a refused command.
        Err(e) => error = Some(e.to_string()),
    }
    FaultOutcome {
        label: case.faults.iter().map(|f| f.to_string()).collect::<Vec<_>>().join("+"),
        parameters: case.faults.iter().map(|f| f.kind.parameters()).collect::<Vec<_>>().join("; "),
        m_car_kg: case.travel.m_car_kg,
        direction: case.travel.direction,
        onset_s,
        detection_s: observed.trip.map(|(t, _)| t - observed.first_onset_s.unwrap_or(onset_s)),
        reason: observed.trip.map(|(_, f)| f),
        observed,
        landing_error_m,
        error,
    }
}

/// Runs `case` with the drive core in this process.
pub fn run_case(rig: &RigConfig, case: &FaultCase) -> FaultOutcome {
    let mut controller = Controller::new(&rig.drive_config());
    run_case_with(rig, case, &mut controller, AFTER_TRIP_S)
}

/// The instants at which a kind is injected in the matrix: a brake that does
/// not open matters at the start; everything else in the acceleration, at
/// rated speed and in the deceleration.
pub fn instants_of(kind: &FaultKind) -> &'static [Instant] {
    match kind {
        FaultKind::BrakeNotOpening => &[Instant::Start],
        _ => &[Instant::Accel, Instant::Cruise, Instant::Decel],
    }
}

/// Every fault kind of the issue with its default parameters (and the
/// disconnected sensor both ways).
pub fn default_kinds() -> Vec<FaultKind> {
    let none = std::collections::BTreeMap::new();
    let mut kinds: Vec<FaultKind> =
        KIND_NAMES[..15].iter().map(|name| FaultKind::from_name(name, &none).expect("defaults parse")).collect();
    let mut zero_code = std::collections::BTreeMap::new();
    zero_code.insert("reads".to_string(), "zero-code".to_string());
    kinds.insert(2, FaultKind::from_name("current-disconnected", &zero_code).expect("parses"));
    kinds
}

/// The matrix of `host-sim faults`: every kind of [`default_kinds`] at its
/// instants, car up and down, for a car of `m_car_kg` over the full travel.
pub fn default_matrix(rig: &RigConfig, m_car_kg: f64) -> Vec<FaultCase> {
    let mut cases = Vec::new();
    for kind in default_kinds() {
        for &instant in instants_of(&kind) {
            for direction in [Direction::Up, Direction::Down] {
                cases.push(FaultCase {
                    travel: TravelSpec::full_travel(rig, m_car_kg, direction),
                    faults: vec![FaultSpec { kind, onset: Onset::Named(instant) }],
                });
            }
        }
    }
    cases
}
