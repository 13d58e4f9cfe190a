//! Step 4 of the pipeline as [`crate::diagnose`] runs it: the effects the
//! counterpart holds fitted to the mechanics ([`crate::attribute`], on the
//! calibrations re-done by [`crate::hypotheses`]) and named
//! ([`crate::naming`]); under another drive, the direct-axis current's
//! lines attributed on their own ([`crate::electrical_lines`]).

use crate::attribute::{attribute, Candidate, KnownParameter, Lab};
use crate::calibrate::Calibration;
use crate::compare::Compared;
use crate::current_balance::{currents_unbalanced, measured_gain_errors, RecordingBalance};
use crate::drive_finding::DriveModel;
use crate::travel_signals::TravelTorque;
use crate::verdict::GapOptions;
use crate::{driven, electrical_lines, hypotheses, naming};
use plant::effects::EffectKind;
use recording::Recording;
use rig_config::RigConfig;

/// Why some effects are not fitted to the mechanics under another drive,
/// in words (`None` when every effect is): each left-out effect's reason.
fn not_fitted_note(not_fitted: &[EffectKind]) -> Option<String> {
    (!not_fitted.is_empty()).then(|| {
        let names: Vec<&str> = not_fitted.iter().map(|k| k.name()).collect();
        let reasons: Vec<&str> = not_fitted
            .iter()
            .filter_map(|k| match k {
                EffectKind::DeadTime => Some(
                    "the dead time acts through the currents, which the measured torque already carries: it is \
                     fitted to the direct-axis current's lines instead",
                ),
                EffectKind::BrakeStop => Some(
                    "the brake clamp acts at standstill, where another drive's stop is compared only in a travel \
                     whose recording shows the brake stopping the turning sheave, and none does here",
                ),
                _ => None,
            })
            .collect();
        let why = if reasons.is_empty() { String::new() } else { format!(" ({})", reasons.join("; ")) };
        format!(
            "the rig's drive is another, so the effects are fitted with the mechanics driven by its measured torque; \
             not fitted to the mechanics: {}{why}",
            names.join(", ")
        )
    })
}

/// The parameters the recorded currents' balance measures without the
/// model: when the recorded currents are unbalanced (they carry the error:
/// the drive's transducer signals, or clamps that err), the gain errors
/// of phases a and b relative to phase c, `current_sensor_error`'s
/// `gain_error_a` and `gain_error_b`, where they lie within the effect's
/// declared range. Balanced currents say nothing of transducers that the
/// recording does not hold (the drive's, behind clamps): nothing held.
fn balance_parameters(balances: &[RecordingBalance]) -> Vec<KnownParameter> {
    let kind = EffectKind::CurrentSensorError;
    if !currents_unbalanced(balances) {
        return Vec::new();
    }
    let Some(gains) = measured_gain_errors(balances) else { return Vec::new() };
    let specs = kind.parameters();
    ["gain_error_a", "gain_error_b"]
        .iter()
        .zip(gains)
        .filter_map(|(name, (value, uncertainty))| {
            let index = specs.iter().position(|s| s.name == *name)?;
            (specs[index].min..=specs[index].max).contains(&value).then_some(KnownParameter {
                effect: kind,
                index,
                value,
                uncertainty,
                source: "the recorded currents' balance",
            })
        })
        .collect()
}

/// Steps 4 and 5 on the mechanics: every effect the counterpart holds
/// fitted (the calibration re-done under the hypotheses that it can
/// absorb; what the currents' `balances` measure held), cross-validated
/// and named; with the note on what is not fitted and the runs planned
/// per recording.
#[allow(clippy::too_many_arguments)]
pub(crate) fn attribute_mechanics(
    model: &RigConfig,
    calibration: &Calibration,
    dataset: &[(String, Recording)],
    travels: &[Option<TravelTorque>],
    balances: &[RecordingBalance],
    compared: &Compared,
    drive: DriveModel,
    options: &GapOptions,
    progress: &(dyn Fn(&str, usize, usize) + Sync),
) -> (Vec<Candidate>, Option<String>, usize) {
    let planned = std::sync::atomic::AtomicUsize::new(0);
    let report_progress = |done: usize, total: usize| {
        planned.store(total, std::sync::atomic::Ordering::Relaxed);
        progress("fitting effects", done, total);
    };
    // Under another drive the counterpart is the torque-driven mechanics,
    // which holds only some of the library's effects.
    let brake_seen = compared.targets.iter().any(|t| t.counterpart.shows_brake());
    let (kinds, not_fitted): (Vec<EffectKind>, Vec<EffectKind>) =
        options.effects.iter().partition(|k| drive == DriveModel::Project || driven::holds_effect(**k, brake_seen));
    // The calibration re-done under the hypotheses of the effects it can
    // absorb (step 4a).
    let refits: Vec<hypotheses::Refit> =
        kinds.iter().filter_map(|&k| hypotheses::refit(k, model, calibration, dataset, travels)).collect();
    let known = balance_parameters(balances);
    let lab = Lab {
        known: &known,
        refits: &refits,
        rig: model,
        targets: &compared.targets,
        bands: &compared.bands,
        reference_tension_n: calibration.reference_tension_n,
        progress: &report_progress,
    };
    let mut ranking = if kinds.is_empty() { Vec::new() } else { attribute(&lab, &kinds) };
    naming::name_candidates(&mut ranking);
    (ranking, not_fitted_note(&not_fitted), planned.load(std::sync::atomic::Ordering::Relaxed))
}

/// Under another drive, its transducer and inverter errors show in the
/// direct-axis current, not in the torque-driven mechanics: the lines'
/// own attribution (`None` under the project's drive).
pub(crate) fn electrical_lines_of(
    compared: &mut Compared,
    drive: DriveModel,
    options: &GapOptions,
) -> Option<electrical_lines::ElectricalLines> {
    (drive == DriveModel::Foreign).then(|| {
        let (measured, not_measured) = std::mem::take(&mut compared.direct_axis);
        let mut lines = electrical_lines::explain(measured, not_measured, &options.effects);
        naming::name_candidates(&mut lines.ranking);
        lines
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The note gives each left-out effect's own reason, and only theirs:
    /// with the brake seen in a recording, only the dead time is left out
    /// under another drive, and the note says nothing of the brake.
    #[test]
    fn the_not_fitted_note_gives_the_left_out_effects_reasons() {
        let left_out = |brake_seen: bool| -> Vec<EffectKind> {
            EffectKind::ALL.into_iter().filter(|k| !driven::holds_effect(*k, brake_seen)).collect()
        };
        assert_eq!(left_out(true), [EffectKind::DeadTime]);
        assert!(left_out(false).contains(&EffectKind::BrakeStop));
        let seen = not_fitted_note(&left_out(true)).expect("the dead time is left out");
        assert!(seen.contains("dead_time") && seen.contains("direct-axis") && !seen.contains("brake"), "{seen}");
        let unseen = not_fitted_note(&left_out(false)).expect("two left out");
        assert!(unseen.contains("brake_stop") && unseen.contains("none does here"), "{unseen}");
        assert_eq!(not_fitted_note(&[]), None);
    }
}
