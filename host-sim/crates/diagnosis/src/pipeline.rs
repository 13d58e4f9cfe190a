//! The diagnosis's pipeline, [`diagnose`]: the steps of the crate's table
//! of contents in their order, each a named function that hands its
//! results to the next.

use std::time::Instant;

use crate::attribute::Candidate;
use crate::attribution::{attribute_mechanics, electrical_lines_of};
use crate::calibrate::{calibrate, Calibration};
use crate::compare::{car_acceleration_views, compared, gap_after, nominal_gaps, CarAccelerationViews, Compared};
use crate::current_balance::{self, RecordingBalance};
use crate::drive_finding::{decide_drive, DriveFinding};
use crate::error::{bail, Result};
use crate::identify_dataset::LeftOut;
use crate::locate::{locate, Location};
use crate::measure::{persistent_cell, CellGap, PersistentCell};
use crate::prepare::{counterpart, measure, run_closed_loop, Models, Prepared};
use crate::travel_signals::TravelTorque;
use crate::verdict::{self, explained_by, verdict_of, GapOptions, GapReport, RecordingGap, Verdict};
use plant::effects::Effects;
use rayon::prelude::*;
use recording::Recording;
use rig_config::RigConfig;

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
    let mut nominal = nominal_comparison(rig, name, dataset, options, progress)?;
    let mut gap = nominal_gap(&nominal, dataset, options);
    let (mechanical_ranking, attribution_note, planned) = attribute_mechanics(
        &nominal.model,
        &nominal.calibration,
        dataset,
        &nominal.travels,
        &gap.current_balance,
        &nominal.compared,
        nominal.drive.drive,
        options,
        progress,
    );
    let electrical_lines = electrical_lines_of(&mut nominal.compared, nominal.drive.drive, options);
    let electrical = electrical_lines.as_ref().filter(|e| e.present());
    let verdict = verdict_of(gap.is_nominal, mechanical_ranking.first(), electrical, options);
    let verdict_note = verdict::form_error_note(verdict, mechanical_ranking.first(), options)
        .or_else(|| verdict::unbalanced_note(verdict, gap.unbalanced));
    let best = verdict_basis(&mechanical_ranking, verdict, gap.is_nominal, options);
    let explained_by = (verdict == Verdict::Explained).then(|| explained_by(electrical, best));
    let explaining =
        (verdict == Verdict::Explained).then(|| best.map(|b| (b.rig(&nominal.model), &b.effects))).flatten();
    let (map_after, car_acceleration_views, checked) =
        check_explanation(&nominal, &mut gap.recordings, explaining, progress);
    let simulations = nominal.compared.simulations + planned * nominal.compared.targets.len() + checked;
    let ranking =
        electrical.map(|e| e.ranking.clone()).unwrap_or_default().into_iter().chain(mechanical_ranking).collect();
    Ok(GapReport {
        dataset: name.to_string(),
        verdict,
        drive: nominal.drive,
        rig_speed_loops: std::mem::take(&mut nominal.compared.rig_speed_loops),
        left_out: nominal.left_out,
        attribution_note,
        explained_by,
        verdict_note,
        gap_measure: crate::GAP_MEASURE.to_string(),
        nominal_excess_db: gap.excess_db,
        noise_gap_db: gap.noise_db,
        persistent_cell: gap.persistent_cell,
        electrical_lines,
        current_balance: gap.current_balance,
        car_acceleration_views,
        calibration: nominal.calibration,
        location: gap.location,
        ranking,
        recordings: gap.recordings,
        bands_hz: nominal.compared.bands.edges_hz.clone(),
        map_before: gap.cells.into_iter().flatten().collect(),
        map_after,
        runtime_s: started.elapsed().as_secs_f64(),
        simulations,
    })
}

/// What steps 1 to 3 give: the calibrated nominal model and each
/// recording's comparison with its counterpart.
struct NominalComparison {
    /// The rig with the calibrated EA, guide and sheave damping.
    model: RigConfig,
    /// How they were calibrated.
    calibration: Calibration,
    /// Which drive the rig runs.
    drive: DriveFinding,
    /// The comparison targets.
    compared: Compared,
    /// Per recording of the dataset, a travel's torque and shaft angle as
    /// its measurement derived them.
    travels: Vec<Option<TravelTorque>>,
    /// The recordings left out, with their reasons.
    left_out: Vec<LeftOut>,
}

/// Steps 1 to 3: measures every recording, calibrates the model on them,
/// runs the closed loop on each, decides the drive on those runs and makes
/// each recording's counterpart (with the calibration's perturbed models,
/// for the cells' tolerances).
fn nominal_comparison(
    rig: &RigConfig,
    name: &str,
    dataset: &[(String, Recording)],
    options: &GapOptions,
    progress: &(dyn Fn(&str, usize, usize) + Sync),
) -> Result<NominalComparison> {
    progress("calibrating", 0, 1);
    let mut left_out = Vec::new();
    let (measured, travels) = measure(rig, dataset, &mut left_out);
    let (model, calibration) = calibrate(rig, dataset, &travels);
    let perturbed_models = calibration.perturbations(&model);

    progress("nominal model", 0, dataset.len());
    let runs = run_closed_loop(&model, dataset, measured);
    let drive = decide_drive(options.drive, dataset, &runs);
    let prepared: Vec<(usize, Result<Prepared>)> = runs
        .into_par_iter()
        .map(|run| {
            let (stem, recording) = &dataset[run.index];
            let models = Models::new(&model, &perturbed_models);
            (
                run.index,
                counterpart(
                    models,
                    drive.drive,
                    stem,
                    recording,
                    run.measured,
                    travels[run.index].as_ref(),
                    run.closed,
                ),
            )
        })
        .collect();
    let Some(compared) = compared(dataset, prepared, drive.drive, &model, &mut left_out) else {
        let reasons: Vec<String> = left_out.iter().map(|l| format!("`{}`: {}", l.recording, l.reason)).collect();
        bail!("dataset {name}: no recording could be diagnosed: {}", reasons.join("; "));
    };
    progress("nominal model", dataset.len(), dataset.len());
    Ok(NominalComparison { model, calibration, drive, compared, travels, left_out })
}

/// The nominal model's gap, step 3's figures.
struct NominalGap {
    /// Per recording, its cells.
    cells: Vec<Vec<CellGap>>,
    /// Per recording, its gaps.
    recordings: Vec<RecordingGap>,
    /// Mean excess gap over the recordings, dB.
    excess_db: f64,
    /// Mean noise gap over the recordings, dB.
    noise_db: f64,
    /// Where the gap lies.
    location: Location,
    /// The cell that departs in every recording, if one does.
    persistent_cell: Option<PersistentCell>,
    /// Per travel, whether its phase currents sum to zero.
    current_balance: Vec<RecordingBalance>,
    /// Whether the recorded currents are measured with an error.
    unbalanced: bool,
    /// Whether the nominal model holds: the excess within the threshold, no
    /// persistent cell beyond its own, the currents balanced.
    is_nominal: bool,
}

/// Step 3's figures: the nominal gap of every recording, where it lies,
/// and whether the nominal model holds.
fn nominal_gap(nominal: &NominalComparison, dataset: &[(String, Recording)], options: &GapOptions) -> NominalGap {
    let compared = &nominal.compared;
    let (cells, recordings) = nominal_gaps(&nominal.model, dataset, &nominal.travels, compared, nominal.drive.drive);
    let n = recordings.len() as f64;
    let excess_db = recordings.iter().map(|r| r.nominal_excess_db).sum::<f64>() / n;
    let noise_db = recordings.iter().map(|r| r.nominal.noise_db).sum::<f64>() / n;
    let location = locate(&cells, &recordings, &compared.bands, &compared.targets, &compared.measured_spectra);
    let persistent_cell = persistent_cell(&cells, &compared.bands);
    // Recorded currents that do not sum to zero are measured with an
    // error, however small the gap it leaves: not the nominal rig.
    let current_balance = current_balance::current_balance(dataset);
    let unbalanced = current_balance::currents_unbalanced(&current_balance);
    let is_nominal = excess_db <= options.nominal_excess_db
        && persistent_cell.as_ref().is_none_or(|p| p.rms_beyond_db <= options.persistent_cell_db)
        && !unbalanced;
    NominalGap {
        cells,
        recordings,
        excess_db,
        noise_db,
        location,
        persistent_cell,
        current_balance,
        unbalanced,
        is_nominal,
    }
}

/// Step 6's check: the explaining model's (`explaining`, its rig and its
/// effects, if the verdict names one) gap on every recording, written into
/// `recordings` and returned as the map after, and the car acceleration's
/// views of the recording the nominal model misses most; with the
/// simulations both ran.
fn check_explanation(
    nominal: &NominalComparison,
    recordings: &mut [RecordingGap],
    explaining: Option<(&RigConfig, &Effects)>,
    progress: &(dyn Fn(&str, usize, usize) + Sync),
) -> (Vec<CellGap>, Option<CarAccelerationViews>, usize) {
    let targets = nominal.compared.targets.len();
    let mut simulations = 0;
    let map_after = match explaining {
        Some((explaining_rig, effects)) => {
            progress(&format!("checking {}", effects.summary()), 0, targets);
            simulations += targets;
            gap_after(explaining_rig, effects, &nominal.compared, recordings)
        }
        None => Vec::new(),
    };
    let views = car_acceleration_views(&nominal.model, &nominal.compared, recordings, explaining);
    simulations += views.as_ref().map_or(0, |v| v.series.len().saturating_sub(1));
    (map_after, views, simulations)
}

/// The mechanics' candidate the verdict rests on: a named one, also when
/// it explains a gap within the nominal threshold (the verdict says so),
/// not when what it removes of such a gap is the model's form error.
fn verdict_basis<'a>(
    ranking: &'a [Candidate],
    verdict: Verdict,
    is_nominal: bool,
    options: &GapOptions,
) -> Option<&'a Candidate> {
    ranking
        .first()
        .filter(|c| c.naming.named)
        .filter(|c| !is_nominal || (verdict == Verdict::Explained && verdict::explains(c, true, options)))
}
