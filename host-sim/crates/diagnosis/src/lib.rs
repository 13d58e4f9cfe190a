//! The sim-to-real gap diagnosis (`host-sim gap`): where a dataset departs
//! from the nominal model, which unmodelled effect of the library
//! (`plant::effects`) explains it, and how much of the gap it removes on
//! recordings held out from its fit.
//!
//! The pipeline, [`diagnose`], step by step:
//!
//! 1. [`mod@calibrate`]: EA, guide and sheave damping identified from the data.
//! 2. [`prepare`]: every recording measured ([`signals`]) and its
//!    counterpart made with the calibrated nominal model: [`simulate`]
//!    (closed loop) or, for travels under another drive, the mechanics
//!    driven by the measured torque ([`driven`]); which drive the rig runs,
//!    [`drive_finding`] decides on the closed loop's runs.
//! 3. [`compare`]: the comparison targets ([`target`]) and the nominal
//!    model's gap in cells of channel x travel phase x band ([`measure`]),
//!    with the [`replay`] (measured shaft motion into the mechanics) beside
//!    it; [`mod@locate`]: the gap located along the signal chain, in time and
//!    in frequency.
//! 4. [`attribution`]: every effect fitted and cross-validated
//!    ([`attribute`]); an effect that the calibration can absorb on the
//!    calibration re-done under its hypothesis ([`hypotheses`]); under
//!    another drive, the direct-axis current's lines ([`electrical_lines`]);
//!    in every travel, whether the recorded phase currents sum to zero
//!    ([`current_balance`]: a current-measurement error without a model).
//! 5. [`naming`]: a candidate is named only when it shrinks the held-out
//!    gap beyond its scatter and its fitted strength leaves no effect by
//!    more than its uncertainty.
//! 6. [`verdict`]: `nominal`, `explained` or `unexplained`, in the
//!    [`GapReport`] that [`report`] writes.
//!
//! The paper's identification, which the calibration uses and `host-sim
//! identify` reports, is here too, because it needs the plant model:
//! [`identify`] (Eqn 9, 11-13), [`identify_dataset`] (over a dataset) and
//! [`travel_signals`] (shaft angle, rope length, torque balance of a travel).
//!
//! In the data flow config -> plant <-> controller -> recording -> analysis
//! -> diagnosis this crate is the last step: it reads recordings
//! (`recording`), analyses them (`dsp`) and simulates their counterparts on
//! the plant in closed loop (`plant`, `closed-loop`); nothing upstream
//! depends on it.

#![warn(missing_docs)]

pub mod acquisition;
pub mod angle_alignment;
pub mod attribute;
pub mod attribution;
pub mod calibrate;
pub mod compare;
pub mod current_balance;
pub mod drive_finding;
pub mod drive_law;
pub mod driven;
pub mod electrical_lines;
pub mod error;
pub mod hypotheses;
pub mod identify;
pub mod identify_dataset;
pub mod locate;
pub mod measure;
pub mod naming;
pub mod prepare;
pub mod replay;
pub mod report;
pub mod screen;
pub mod signals;
pub mod simulate;
pub mod spectra;
pub mod target;
pub mod transducer;
pub mod travel_signals;
pub mod verdict;

use std::time::Instant;

use rayon::prelude::*;

pub use compare::{CarAccelerationViews, DECAY_TOP_MODE_FACTOR, FOREIGN_TOP_FRACTION, FOREIGN_TOP_HZ, GAP_MEASURE};
pub use drive_finding::{DriveAssumption, DriveFinding, DriveModel, DRIVE_MISMATCH_DB, PROFILE_SPEED_TOLERANCE};
pub use error::DiagnosisError;
pub use prepare::RigSpeedLoop;
pub use verdict::{
    GapOptions, GapReport, RecordingGap, Verdict, EXPLAINED_SHRINK, NOMINAL_EXCESS_DB, PERSISTENT_CELL_DB,
    SUB_NOMINAL_REMOVAL_FRACTION,
};

use crate::error::{bail, Result};
use attribution::{attribute_mechanics, electrical_lines_of};
use calibrate::calibrate;
use compare::{car_acceleration_views, compared, gap_after, nominal_gaps};
use drive_finding::decide_drive;
use locate::locate;
use measure::persistent_cell;
use prepare::{counterpart, measure_and_run_closed_loop, Prepared};
use recording::Recording;
use rig_config::RigConfig;
use verdict::{explained_by, verdict_of};

/// Runs the diagnosis of `dataset` (named `name`) on `rig`; `progress`
/// gets (step, runs done, runs planned). A recording that cannot be
/// measured or simulated is left out with the reason; the verdict is given
/// on the rest.
pub fn diagnose(
    rig: &RigConfig,
    name: &str,
    dataset: &[(String, Recording)],
    options: &GapOptions,
    progress: &(dyn Fn(&str, usize, usize) + Sync),
) -> Result<GapReport> {
    let started = Instant::now();
    if dataset.is_empty() {
        bail!("dataset {name}: no recordings");
    }
    progress("calibrating", 0, 1);
    let (model, calibration) = calibrate(rig, dataset);
    let perturbed_models = [calibration.perturbed(&model, 1.0), calibration.perturbed(&model, -1.0)];
    let mut left_out = Vec::new();

    progress("nominal model", 0, dataset.len());
    let runs = measure_and_run_closed_loop(rig, &model, dataset, &mut left_out);
    let drive = decide_drive(options.drive, dataset, &runs);
    let prepared: Vec<(usize, Result<Prepared>)> = runs
        .into_par_iter()
        .map(|(i, measured, closed)| {
            let (stem, recording) = &dataset[i];
            let models = [&model, &perturbed_models[0], &perturbed_models[1]];
            (i, counterpart(models, drive.drive, stem, recording, measured, closed))
        })
        .collect();
    let Some(mut compared) = compared(dataset, prepared, drive.drive, &model, &mut left_out) else {
        let reasons: Vec<String> = left_out.iter().map(|l| format!("`{}`: {}", l.recording, l.reason)).collect();
        bail!("dataset {name}: no recording could be diagnosed: {}", reasons.join("; "));
    };
    progress("nominal model", dataset.len(), dataset.len());
    let (nominal_cells, mut recordings) = nominal_gaps(&model, dataset, &compared, drive.drive);
    let n = recordings.len() as f64;
    let nominal_excess_db = recordings.iter().map(|r| r.nominal_excess_db).sum::<f64>() / n;
    let noise_gap_db = recordings.iter().map(|r| r.nominal.noise_db).sum::<f64>() / n;
    let location = locate(&nominal_cells, &recordings, &compared.bands, &compared.targets, &compared.measured);

    let persistent_cell = persistent_cell(&nominal_cells, &compared.bands);
    // Recorded currents that do not sum to zero are measured with an
    // error, however small the gap it leaves: not the nominal rig.
    let current_balance = current_balance::current_balance(dataset);
    let unbalanced = current_balance::currents_unbalanced(&current_balance);
    let is_nominal = nominal_excess_db <= options.nominal_excess_db
        && persistent_cell.as_ref().is_none_or(|p| p.rms_beyond_db <= options.persistent_cell_db)
        && !unbalanced;
    let (mechanical_ranking, attribution_note, planned) =
        attribute_mechanics(&model, &calibration, dataset, &current_balance, &compared, drive.drive, options, progress);
    let electrical_lines = electrical_lines_of(&mut compared, drive.drive, options);
    let electrical = electrical_lines.as_ref().filter(|e| e.present());
    let verdict = verdict_of(is_nominal, mechanical_ranking.first(), electrical, options);
    let verdict_note = verdict::form_error_note(verdict, mechanical_ranking.first(), options)
        .or_else(|| verdict::unbalanced_note(verdict, unbalanced));
    // The mechanics' candidate the verdict rests on: a named one, also when
    // it explains a gap within the nominal threshold (the verdict says so),
    // not when what it removes of such a gap is the model's form error.
    let best = mechanical_ranking
        .first()
        .filter(|c| c.naming.named)
        .filter(|c| !is_nominal || (verdict == Verdict::Explained && verdict::explains(c, true, options)));
    let mut simulations = compared.simulations + planned * compared.targets.len();
    let explained_by = (verdict == Verdict::Explained).then(|| explained_by(electrical, best));
    let mut map_after = Vec::new();
    if let (Verdict::Explained, Some(best)) = (verdict, best) {
        progress(&format!("checking {}", best.effects.summary()), 0, compared.targets.len());
        map_after = gap_after(best.rig(&model), &best.effects, &compared, &mut recordings);
        simulations += compared.targets.len();
    }
    let explaining = (verdict == Verdict::Explained).then(|| best.map(|b| (b.rig(&model), &b.effects))).flatten();
    let car_acceleration_views = car_acceleration_views(&model, &compared, &recordings, explaining);
    simulations += car_acceleration_views.as_ref().map_or(0, |v| v.series.len().saturating_sub(1));
    let map_before = nominal_cells.into_iter().flatten().collect();
    let ranking =
        electrical.map(|e| e.ranking.clone()).unwrap_or_default().into_iter().chain(mechanical_ranking).collect();
    Ok(GapReport {
        dataset: name.to_string(),
        verdict,
        drive,
        rig_speed_loops: std::mem::take(&mut compared.rig_speed_loops),
        left_out,
        attribution_note,
        explained_by,
        verdict_note,
        gap_measure: GAP_MEASURE.to_string(),
        nominal_excess_db,
        noise_gap_db,
        persistent_cell,
        electrical_lines,
        current_balance,
        car_acceleration_views,
        calibration,
        location,
        ranking,
        recordings,
        bands_hz: compared.bands.edges_hz.clone(),
        map_before,
        map_after,
        runtime_s: started.elapsed().as_secs_f64(),
        simulations,
    })
}
