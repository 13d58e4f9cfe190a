//! Step 2 of the pipeline, between the measurement and the counterparts of
//! [`crate::prepare`]: which drive the rig runs. The project's drive core
//! when its closed loop reproduces the travels' torque at standstill and
//! their constant speed, another drive otherwise (or as the option says).

use crate::compare::align_phases;
#[cfg(doc)]
use crate::driven;
use crate::measure::cell_gaps;
use crate::prepare::MeasuredRun;
use crate::signals::{self, ChainSignals};
use crate::spectra::{cell_powers, Bands, ChainSpectra, Segmentation};
use recording::{Recording, RecordingKind};

/// Largest RMS gap (dB) of the torque at standstill (start and stop cells)
/// between the recording and the project's drive in closed loop for which
/// the rig is taken to run the project's drive.
pub const DRIVE_MISMATCH_DB: f64 = 6.0;

/// What the diagnosis may assume about the rig's drive.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum DriveAssumption {
    /// Decide from the data ([`DRIVE_MISMATCH_DB`]).
    #[default]
    Auto,
    /// The rig runs the project's drive core.
    Project,
    /// The rig runs another drive.
    Foreign,
}

/// The drive model of the travels' counterparts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DriveModel {
    /// The project's drive core in closed loop with the plant: every
    /// channel (torque, speed, accelerations) compared, the replay beside it.
    Project,
    /// Another drive: the mechanics driven by the measured torque
    /// ([`driven`]); the accelerations compared.
    Foreign,
}

/// The drive model used and why.
#[derive(Clone, Debug, serde::Serialize)]
pub struct DriveFinding {
    /// The model.
    pub drive: DriveModel,
    /// Why, in words.
    pub reason: String,
}

/// RMS (dB) over the torque channel's start and stop cells of how far the
/// closed loop's torque lies from the measured: the drive's own start and
/// stop sequence (brake timing, pre-torque, torque ramps), which any other
/// drive does its own way.
fn start_stop_torque_gap_db(measured: &ChainSignals, closed: &ChainSignals) -> Option<f64> {
    let (mut measured, mut closed) = (measured.clone(), closed.clone());
    align_phases(&mut measured, &mut closed);
    let seg = Segmentation::of(&measured);
    // The torque's start and stop cells only: no lines.
    let bands = Bands::new(measured.sample_rate_hz, seg.segment_len, Vec::new());
    let m = cell_powers(&[(&ChainSpectra::compute(&measured, &seg, &bands), 1.0)], &bands);
    let c = cell_powers(&[(&ChainSpectra::compute(&closed, &Segmentation::of(&closed), &bands), 1.0)], &bands);
    let cells = cell_gaps(&m, &measured.noise_density, &Vec::new(), &c);
    let d: Vec<f64> = cells
        .iter()
        .filter(|c| {
            c.channel == signals::Channel::Torque && matches!(c.phase, signals::Phase::Start | signals::Phase::Stop)
        })
        .map(|c| c.d_db * c.d_db)
        .collect();
    (!d.is_empty()).then(|| (d.iter().sum::<f64>() / d.len() as f64).sqrt())
}

/// Largest relative difference between the mean speed of a travel's
/// constant-speed stage and the project's drive's on the same travel for
/// the rig to count as run by the project's drive: that drive holds its
/// rated speed (integral action on the speed error) whatever the effect;
/// another drive runs at its own.
pub const PROFILE_SPEED_TOLERANCE: f64 = 0.02;

/// Mean absolute value (of the speed channel, rad/s) over the
/// constant-speed stage of `signals`, if it has both.
fn constant_stage_speed_radps(signals: &ChainSignals) -> Option<f64> {
    let speed = signals.channel(signals::Channel::Speed)?;
    let stage = signals.phases.iter().find(|(p, _)| *p == signals::Phase::Constant)?.1.clone();
    let stage = stage.start.min(speed.len())..stage.end.min(speed.len());
    (!stage.is_empty()).then(|| speed[stage.clone()].iter().map(|v| v.abs()).sum::<f64>() / stage.len() as f64)
}

/// Why the travel `measured` was not run by the project's drive whose run
/// of it is `closed`, judged by the speed it travels at
/// ([`PROFILE_SPEED_TOLERANCE`]); `None` when the speeds agree or either is
/// missing.
fn speed_profile_mismatch(stem: &str, measured: &ChainSignals, closed: &ChainSignals) -> Option<String> {
    let (m, c) = (constant_stage_speed_radps(measured)?, constant_stage_speed_radps(closed)?);
    let relative = m / c - 1.0;
    (c > 0.0 && relative.abs() > PROFILE_SPEED_TOLERANCE).then(|| {
        format!(
            "travel `{stem}` runs at {m:.3} rad/s at constant speed, the project's drive at {c:.3} rad/s \
             ({:+.1} %, more than {:.0} %): another speed profile",
            100.0 * relative,
            100.0 * PROFILE_SPEED_TOLERANCE
        )
    })
}

/// Which drive the travels' model assumes, and why.
pub(crate) fn decide_drive(
    option: DriveAssumption,
    dataset: &[(String, Recording)],
    runs: &[MeasuredRun],
) -> DriveFinding {
    let travels = runs.iter().filter(|r| matches!(dataset[r.index].1.meta.kind, RecordingKind::Travel { .. }));
    match option {
        DriveAssumption::Project => {
            return DriveFinding { drive: DriveModel::Project, reason: "set by --drive project".into() }
        }
        DriveAssumption::Foreign => {
            return DriveFinding { drive: DriveModel::Foreign, reason: "set by --drive foreign".into() }
        }
        DriveAssumption::Auto => {}
    }
    let (mut count, mut at_standstill, mut at_speed) = (0, 0, 0);
    for MeasuredRun { index, measured, closed, .. } in travels {
        let stem = &dataset[*index].0;
        count += 1;
        let reason = match closed {
            Err(e) => format!("the project's drive cannot run travel `{stem}` ({e:#})"),
            Ok(closed) => {
                let d = start_stop_torque_gap_db(measured, closed);
                at_standstill += usize::from(d.is_some());
                at_speed += usize::from(
                    constant_stage_speed_radps(measured).is_some() && constant_stage_speed_radps(closed).is_some(),
                );
                if let Some(d) = d.filter(|d| *d > DRIVE_MISMATCH_DB) {
                    format!(
                        "the torque of travel `{stem}` at standstill (start and stop) lies {d:.1} dB (RMS) from the \
                         project's drive (more than {DRIVE_MISMATCH_DB} dB): another start and stop sequence"
                    )
                } else if let Some(reason) = speed_profile_mismatch(stem, measured, closed) {
                    reason
                } else {
                    continue;
                }
            }
        };
        return DriveFinding { drive: DriveModel::Foreign, reason };
    }
    DriveFinding { drive: DriveModel::Project, reason: project_drive_evidence(count, at_standstill, at_speed) }
}

/// What the dataset shows for the project's drive, in words: of `count`
/// travels, `at_standstill` compared at their start and stop, `at_speed`
/// at constant speed; a claim only for what was compared.
fn project_drive_evidence(count: usize, at_standstill: usize, at_speed: usize) -> String {
    if count == 0 {
        return "no travel in the dataset: which drive ran the rig is not decided (free decays run none); \
                the project's is assumed"
            .into();
    }
    if at_standstill == 0 && at_speed == 0 {
        return format!(
            "none of the {count} travels has a standstill or a constant-speed stage to compare: the project's \
             drive is assumed, not shown"
        );
    }
    let mut shown = Vec::new();
    if at_standstill > 0 {
        shown.push(format!(
            "the torque at standstill of {at_standstill} of {count} travels within {DRIVE_MISMATCH_DB} dB"
        ));
    }
    if at_speed > 0 {
        shown.push(format!(
            "the constant speed of {at_speed} of {count} travels within {:.0} %",
            100.0 * PROFILE_SPEED_TOLERANCE
        ));
    }
    let mut reason = format!("the project's drive reproduces {}", shown.join(" and "));
    if at_standstill < count || at_speed < count {
        reason.push_str(" (the others have no such stage to compare)");
    }
    reason
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The drive's finding claims only what was compared: nothing about
    /// travels in a dataset of decays, nothing about standstill in travels
    /// cut from the constant-speed stage.
    #[test]
    fn the_drive_evidence_names_only_what_was_compared() {
        let none = project_drive_evidence(0, 0, 0);
        assert!(none.contains("no travel") && !none.contains("reproduces"), "{none}");
        let cut = project_drive_evidence(2, 0, 2);
        assert!(!cut.contains("standstill"), "{cut}");
        assert!(cut.contains("constant speed of 2 of 2"), "{cut}");
        let bare = project_drive_evidence(3, 0, 0);
        assert!(bare.contains("assumed, not shown"), "{bare}");
        let all = project_drive_evidence(4, 4, 4);
        assert!(all.contains("standstill of 4 of 4") && !all.contains("others"), "{all}");
        assert!(project_drive_evidence(4, 3, 4).contains("others have no such stage"));
    }

    /// A travel's speed channel: a ramp to `top` rad/s, held, a ramp down.
    fn travel(top: f64) -> ChainSignals {
        let n = 3000;
        let speed: Vec<f64> = (0..n)
            .map(|k| match k {
                0..=999 => top * k as f64 / 1000.0,
                1000..=1999 => top,
                _ => top * (n - k) as f64 / 1000.0,
            })
            .collect();
        ChainSignals {
            sample_rate_hz: 1000.0,
            channels: vec![(signals::Channel::Speed, speed)],
            phases: vec![
                (signals::Phase::Acceleration, 0..1000),
                (signals::Phase::Constant, 1000..2000),
                (signals::Phase::Deceleration, 2000..3000),
            ],
            noise_density: Vec::new(),
            angle_rad: Vec::new(),
        }
    }

    #[test]
    fn another_speed_at_constant_speed_is_another_drive() {
        let project = travel(6.15);
        assert!((constant_stage_speed_radps(&project).unwrap() - 6.15).abs() < 1e-9);
        assert!(speed_profile_mismatch("t", &travel(6.15 * 1.015), &project).is_none());
        let reason = speed_profile_mismatch("t", &travel(5.70), &project).expect("7 % slower");
        assert!(reason.contains("`t`") && reason.contains("-7.3 %"), "{reason}");
        // The direction does not matter, a missing stage gives no verdict.
        assert!(speed_profile_mismatch("t", &travel(-6.15), &project).is_none());
        let mut no_stage = travel(5.0);
        no_stage.phases.clear();
        assert!(speed_profile_mismatch("t", &no_stage, &project).is_none());
    }
}
