//! Helpers shared by the integration tests: the reference travel (computed
//! once per test binary) and the selection of its constant-speed stage.

use std::sync::OnceLock;

use closed_loop::{simulate_travel, SimOptions, TravelRun, TravelSpec};
use drive_core::config::Direction;
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
