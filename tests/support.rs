//! Helpers shared by the integration tests: the reference travel (computed
//! once per test binary) and the selection of its constant-speed stage.

use std::sync::OnceLock;

use closed_loop::{simulate_travel, FaultHook, SimOptions, TravelRun, TravelSpec};
use diagnosis::signals::{Channel, Phase, Subsystem};
use diagnosis::{GapReport, Verdict};
use drive_core::config::Direction;
use plant::Plant;
use rig_config::RigConfig;

/// The embedded reference rig.
pub fn rig() -> RigConfig {
    RigConfig::embedded_default().expect("the embedded rig loads")
}

/// The paper's reference travel: m_car = 70.5 kg, car up over the full travel.
pub fn reference_travel() -> &'static TravelRun {
    static RUN: OnceLock<TravelRun> = OnceLock::new();
    RUN.get_or_init(|| {
        let rig = rig();
        let spec = TravelSpec::full_travel(&rig, 70.5, Direction::Up);
        simulate_travel(&rig, &spec, &SimOptions::for_rig(&rig), None).expect("the reference travel runs")
    })
}

/// Sample indices of the constant-speed stage (reference at rated speed),
/// less `trim_s` at each end so that the run-up transients are excluded.
pub fn constant_speed_range(run: &TravelRun, rated_speed_mps: f64, trim_s: f64) -> std::ops::Range<usize> {
    let at_speed: Vec<usize> = run
        .ref_speed_mps
        .iter()
        .enumerate()
        .filter(|(_, v)| (v.abs() - rated_speed_mps).abs() < 1e-6)
        .map(|(i, _)| i)
        .collect();
    let trim = (trim_s * run.sample_rate_hz) as usize;
    let first = at_speed.first().copied().unwrap_or(0) + trim;
    let last = at_speed.last().copied().unwrap_or(0).saturating_sub(trim);
    first..last.max(first)
}

/// Mean of a slice.
pub fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

/// Root mean square of a slice.
pub fn rms(values: &[f64]) -> f64 {
    (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt()
}

/// Guide-rail joints kick the car: a force pulse as the shoe passes each
/// step. Not an effect of the library.
pub struct RailJoints {
    /// Distance between joints, m.
    pub spacing_m: f64,
    /// Force on the car body while the shoe is on the step, N (up).
    pub force_n: f64,
    /// Length of the step along the rail, m.
    pub width_m: f64,
}

impl RailJoints {
    /// Joints every 0.8 m, 150 N over a 4 mm step (10 ms at 0.4 m/s).
    pub fn kicking_the_car() -> Self {
        Self { spacing_m: 0.8, force_n: 150.0, width_m: 0.004 }
    }
}

impl FaultHook for RailJoints {
    fn before_step(&mut self, _t_s: f64, plant: &mut Plant) {
        let x = plant.observe().car_position_m + 100.0 * self.spacing_m;
        let phase = x.rem_euclid(self.spacing_m);
        plant.faults.car_extra_force_n = if phase < self.width_m { self.force_n } else { 0.0 };
    }
}

/// An effect outside the library: `unexplained`, located in the mechanics,
/// on the car, while it moves.
pub fn assert_unexplained_on_the_moving_car(report: &GapReport) {
    let l = &report.location;
    let best = report.ranking.first();
    println!(
        "verdict {:?}; best {} shrink {:.0} %; located {:?} / {} / {} / {} ({})",
        report.verdict,
        best.map_or("-", |b| b.name.as_str()),
        100.0 * best.map_or(0.0, |b| b.held_out_shrink),
        l.subsystem,
        l.channel.name(),
        l.phase.name(),
        l.band,
        l.reasoning
    );
    assert_eq!(report.verdict, Verdict::Unexplained);
    assert_eq!(l.subsystem, Subsystem::Mechanical);
    assert_eq!(l.channel, Channel::CarAcceleration);
    assert!(matches!(l.phase, Phase::Acceleration | Phase::Constant | Phase::Deceleration), "{:?}", l.phase);
}
