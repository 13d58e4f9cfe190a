//! The sim-to-real gap diagnosis (`host-sim gap`): where a dataset departs
//! from the nominal model, which unmodelled effect of the library
//! (`plant::effects`) explains it, and how much of the gap it removes on
//! recordings held out from its fit.
//!
//! 1. [`calibrate`]: EA, guide and sheave damping identified from the data.
//! 2. [`simulate`] (closed loop) and [`replay`] (measured shaft motion into
//!    the mechanics) of every recording with the calibrated nominal model.
//! 3. [`measure`]: the gap in cells of channel x travel phase x band,
//!    located along the signal chain, in time and in frequency ([`locate`]).
//! 4. [`attribute`]: every effect fitted and cross-validated.
//! 5. The verdict: `nominal`, `explained` or `unexplained` ([`report`]).

pub mod attribute;
pub mod calibrate;
pub mod locate;
pub mod measure;
pub mod replay;
pub mod report;
pub mod signals;
pub mod simulate;
pub mod spectra;

use std::time::Instant;

use anyhow::Context;
use rayon::prelude::*;

use crate::config::RigConfig;
use crate::plant::effects::{EffectKind, Effects};
use crate::recording::{Column, Recording, RecordingKind, ACC_CAR, TIME_S};
use attribute::{attribute, Candidate, Lab, Target};
use calibrate::{calibrate, Calibration};
use locate::{locate, Location};
use measure::{cell_gaps, gap_of_cells, CellGap, GapValue};
use signals::{chain_signals, decimation_factor, ChainSignals};
use simulate::{model_step_s, simulate_counterpart};
use spectra::{cell_powers, Bands, ChainSpectra, Segmentation};

/// Largest nominal excess gap (dB, mean over the recordings) that the
/// verdict still calls `nominal`.
pub const NOMINAL_EXCESS_DB: f64 = 0.15;
/// Smallest held-out shrink of the gap for `explained`.
pub const EXPLAINED_SHRINK: f64 = 0.7;

/// The verdict.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// The nominal model explains the data to the noise level.
    Nominal,
    /// An effect of the library (or a pair) explains the gap.
    Explained,
    /// No candidate shrinks the held-out gap enough.
    Unexplained,
}

/// Settings of a diagnosis.
#[derive(Clone, Debug)]
pub struct GapOptions {
    /// The effects to try (default: the whole library).
    pub effects: Vec<EffectKind>,
    /// See [`NOMINAL_EXCESS_DB`].
    pub nominal_excess_db: f64,
    /// See [`EXPLAINED_SHRINK`].
    pub explained_shrink: f64,
}

impl Default for GapOptions {
    fn default() -> Self {
        Self {
            effects: EffectKind::ALL.to_vec(),
            nominal_excess_db: NOMINAL_EXCESS_DB,
            explained_shrink: EXPLAINED_SHRINK,
        }
    }
}

/// One recording's gap.
#[derive(Clone, Debug, serde::Serialize)]
pub struct RecordingGap {
    /// Recording.
    pub recording: String,
    /// Kind: `travel` or `free_decay`.
    pub kind: &'static str,
    /// Against the calibrated nominal model, closed loop.
    pub nominal: GapValue,
    /// Excess gap of the nominal model, dB.
    pub nominal_excess_db: f64,
    /// Excess gap of the accelerations below 80 Hz, closed loop, dB.
    pub closed_loop_acceleration_excess_db: Option<f64>,
    /// The same for the replay (measured shaft motion into the mechanics), dB.
    pub replay_acceleration_excess_db: Option<f64>,
    /// Against the explaining model (when the verdict is `explained`).
    pub explained: Option<GapValue>,
    /// Excess gap with the explaining model, dB.
    pub explained_excess_db: Option<f64>,
}

/// What `gap` found.
#[derive(Clone, Debug, serde::Serialize)]
pub struct GapReport {
    /// The dataset.
    pub dataset: String,
    /// The verdict.
    pub verdict: Verdict,
    /// The explaining effect (or pair) when `explained`.
    pub explained_by: Option<String>,
    /// The gap measure, in words, with its unit.
    pub gap_measure: String,
    /// Mean excess gap of the calibrated nominal model over the recordings, dB.
    pub nominal_excess_db: f64,
    /// Mean noise gap of the recordings, dB.
    pub noise_gap_db: f64,
    /// Step 1.
    pub calibration: Calibration,
    /// Where the gap lies (nominal model).
    pub location: Location,
    /// Every effect (and pair) tried, best first.
    pub ranking: Vec<Candidate>,
    /// Per recording.
    pub recordings: Vec<RecordingGap>,
    /// Bands, `[lo, hi)` Hz, as the cell band indices use them.
    pub bands_hz: Vec<(f64, f64)>,
    /// Car-acceleration cells of the nominal model (the gap map before).
    pub map_before: Vec<CellGap>,
    /// The same with the explaining model (after).
    pub map_after: Vec<CellGap>,
    /// Wall-clock time of the diagnosis, s.
    pub runtime_s: f64,
    /// Simulations run.
    pub simulations: usize,
}

/// Text of the gap measure for reports.
pub const GAP_MEASURE: &str = "RMS over cells (channel x travel phase x third-octave band, 1 Hz - 1 kHz, each channel \
weighted alike) of d = 10 log10(P_measured / (P_model + N)), P the mean power density of the cell and N the \
measured noise density, in dB; the excess gap sqrt(gap^2 - noise^2) removes the scatter the measurement's own \
noise causes (noise = RMS of 4.34/sqrt(K) sqrt(N(2S+N))/(S+N) dB over the cells). Phase-free: a vibration \
need not match in phase.";

fn light_copy(recording: &Recording) -> Recording {
    let columns = match recording.meta.kind {
        RecordingKind::FreeDecay { .. } => {
            recording.columns.iter().filter(|c| c.name == ACC_CAR || c.name == TIME_S).cloned().collect()
        }
        RecordingKind::Travel { .. } => Vec::<Column>::new(),
    };
    Recording { meta: recording.meta.clone(), columns }
}

/// Time (s) at which the speed first reaches half its largest magnitude,
/// interpolated between samples.
fn half_speed_time_s(signals: &ChainSignals) -> Option<f64> {
    let speed = signals.channel(signals::Channel::Speed)?;
    let top = speed.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let half = 0.5 * top;
    let k = speed.iter().position(|v| v.abs() >= half)?;
    if k == 0 || top <= 0.0 {
        return Some(0.0);
    }
    let (a, b) = (speed[k - 1].abs(), speed[k].abs());
    let frac = if b > a { (half - a) / (b - a) } else { 0.0 };
    Some((k as f64 - 1.0 + frac) / signals.sample_rate_hz)
}

/// Gives the model's run the measured phases, shifted by the time offset
/// between the two runs (where the speed first reaches half its peak), and
/// trims both so that every phase covers the same stretch of the travel in
/// each: a phase's mean power then compares like with like.
fn align_phases(measured: &mut ChainSignals, model: &mut ChainSignals) {
    let offset_s = match (half_speed_time_s(measured), half_speed_time_s(model)) {
        (Some(m), Some(s)) => m - s,
        _ => 0.0,
    };
    let (fm, fs) = (measured.sample_rate_hz, model.sample_rate_hz);
    let (len_m, len_s) = (measured.len(), model.len());
    let mut model_phases = Vec::new();
    for (phase, range) in measured.phases.iter_mut() {
        let t0 = range.start as f64 / fm - offset_s;
        let t1 = range.end as f64 / fm - offset_s;
        // Clip to the model's run, then back to the measured one.
        let c0 = t0.max(0.0);
        let c1 = t1.min(len_s as f64 / fs);
        if c1 <= c0 {
            *range = range.start..range.start;
            model_phases.push((*phase, 0..0));
            continue;
        }
        let m0 = (((c0 + offset_s) * fm).round() as usize).min(len_m);
        let m1 = (((c1 + offset_s) * fm).round() as usize).clamp(m0, len_m);
        *range = m0..m1;
        let n = ((m1 - m0) as f64 / fm * fs).round() as usize;
        let s0 = ((c0 * fs).round() as usize).min(len_s);
        model_phases.push((*phase, s0..(s0 + n).min(len_s)));
    }
    model.phases = model_phases;
}

/// Runs the diagnosis of `dataset` (named `name`) on `rig`; `progress`
/// gets (step, runs done, runs planned).
pub fn diagnose(
    rig: &RigConfig,
    name: &str,
    dataset: &[(String, Recording)],
    options: &GapOptions,
    progress: &(dyn Fn(&str, usize, usize) + Sync),
) -> anyhow::Result<GapReport> {
    let started = Instant::now();
    if dataset.is_empty() {
        anyhow::bail!("dataset {name}: no recordings");
    }
    progress("calibrating", 0, 1);
    let (model, calibration) = calibrate(rig, dataset);
    let perturbed_models = [calibration.perturbed(&model, 1.0), calibration.perturbed(&model, -1.0)];

    // Measured signals and the nominal closed loop, per recording.
    progress("nominal model", 0, dataset.len());
    let prepared: Vec<anyhow::Result<(ChainSignals, ChainSignals, [ChainSignals; 2])>> = dataset
        .par_iter()
        .map(|(stem, recording)| {
            let factor = decimation_factor(recording.meta.sample_rate_hz);
            let measured = chain_signals(rig, recording, stem, factor, true)?;
            let step = model_step_s(&model);
            let nominal = simulate_counterpart(&model, &Effects::none(), recording, stem, step)?;
            let perturbed = [
                simulate_counterpart(&perturbed_models[0], &Effects::none(), recording, stem, step)?,
                simulate_counterpart(&perturbed_models[1], &Effects::none(), recording, stem, step)?,
            ];
            Ok((measured, nominal, perturbed))
        })
        .collect();
    let mut targets = Vec::new();
    let mut measured_all = Vec::new();
    let mut bands_all: Option<Bands> = None;
    for ((stem, recording), prepared) in dataset.iter().zip(prepared) {
        let (mut measured, mut nominal, mut perturbed) =
            prepared.with_context(|| format!("dataset {name}, recording `{stem}`"))?;
        let measured_for_perturbed = measured.clone();
        align_phases(&mut measured, &mut nominal);
        for p in perturbed.iter_mut() {
            align_phases(&mut measured_for_perturbed.clone(), p);
        }
        let seg_measured = Segmentation::of(&measured);
        let seg_model = Segmentation::of(&nominal);
        let bands = Bands::new(measured.sample_rate_hz, seg_measured.segment_len);
        if bands_all.as_ref().is_some_and(|b| b.edges_hz != bands.edges_hz) {
            anyhow::bail!(
                "dataset {name}: recording `{stem}` has a sample rate ({} Hz) whose analysis bands differ from the \
                 others'; expected one sample rate for the whole dataset",
                recording.meta.sample_rate_hz
            );
        }
        let measured_spectra = ChainSpectra::compute(&measured, &seg_measured, &bands);
        let nominal_spectra = ChainSpectra::compute(&nominal, &seg_model, &bands);
        let measured_cells = cell_powers(&[(&measured_spectra, 1.0)], &bands);
        let nominal_cells = cell_powers(&[(&nominal_spectra, 1.0)], &bands);
        let perturbed_cells: Vec<_> = perturbed
            .iter()
            .map(|p| cell_powers(&[(&ChainSpectra::compute(p, &Segmentation::of(p), &bands), 1.0)], &bands))
            .collect();
        let tolerances =
            measure::tolerances(&measured_cells, &measured.noise_density, &nominal_cells, &perturbed_cells);
        let group = match recording.meta.kind {
            RecordingKind::Travel { m_car_kg, .. } => format!("{m_car_kg:.1} kg"),
            RecordingKind::FreeDecay { mass_kg, .. } => format!("{mass_kg:.1} kg"),
        };
        targets.push(Target {
            stem: stem.clone(),
            group,
            recording: light_copy(recording),
            measured: measured_cells,
            noise: measured.noise_density.clone(),
            tolerances,
            segmentation: seg_model,
            nominal: nominal_spectra,
        });
        measured_all.push(measured);
        bands_all = Some(bands);
    }
    let bands = bands_all.unwrap_or_else(|| Bands::new(2048.0, 2048));
    progress("nominal model", dataset.len(), dataset.len());

    // Gap of the nominal model, and the replay of the travels.
    let nominal_cells: Vec<Vec<CellGap>> = targets
        .iter()
        .map(|t| cell_gaps(&t.measured, &t.noise, &t.tolerances, &cell_powers(&[(&t.nominal, 1.0)], &bands)))
        .collect();
    let replays: Vec<Option<Vec<CellGap>>> = dataset
        .par_iter()
        .zip(measured_all.par_iter())
        .zip(targets.par_iter())
        .map(|(((stem, recording), measured), target)| {
            replay::replay_cells(&model, recording, stem, measured, target, &bands).ok()
        })
        .collect();
    let low_acc = |c: &&CellGap| {
        c.channel.subsystem() == signals::Subsystem::Mechanical
            && !bands.is_line(c.band)
            && bands.edges_hz[c.band].1 <= 80.0
    };
    let mut recordings: Vec<RecordingGap> = targets
        .iter()
        .zip(&nominal_cells)
        .zip(&replays)
        .map(|((t, cells), replay)| {
            let nominal = gap_of_cells(cells.iter());
            let travel = matches!(t.recording.meta.kind, RecordingKind::Travel { .. });
            RecordingGap {
                recording: t.stem.clone(),
                kind: if travel { "travel" } else { "free_decay" },
                nominal,
                nominal_excess_db: nominal.excess_db(),
                closed_loop_acceleration_excess_db: travel
                    .then(|| gap_of_cells(cells.iter().filter(low_acc)).excess_db()),
                replay_acceleration_excess_db: replay
                    .as_ref()
                    .map(|r| gap_of_cells(r.iter().filter(low_acc)).excess_db()),
                explained: None,
                explained_excess_db: None,
            }
        })
        .collect();
    let n = recordings.len() as f64;
    let nominal_excess_db = recordings.iter().map(|r| r.nominal_excess_db).sum::<f64>() / n;
    let noise_gap_db = recordings.iter().map(|r| r.nominal.noise_db).sum::<f64>() / n;
    let location = locate(&nominal_cells, &recordings, &bands, &targets, &measured_all);

    // Attribution.
    let planned = std::sync::atomic::AtomicUsize::new(0);
    let report_progress = |done: usize, total: usize| {
        planned.store(total, std::sync::atomic::Ordering::Relaxed);
        progress("fitting effects", done, total);
    };
    let lab = Lab {
        rig: &model,
        targets: &targets,
        bands: &bands,
        reference_tension_n: calibration.reference_tension_n,
        progress: &report_progress,
    };
    let is_nominal = nominal_excess_db <= options.nominal_excess_db;
    let ranking = if options.effects.is_empty() { Vec::new() } else { attribute(&lab, &options.effects) };
    let best = ranking.first();
    let verdict = if is_nominal {
        Verdict::Nominal
    } else if best.is_some_and(|b| b.held_out_shrink >= options.explained_shrink) {
        Verdict::Explained
    } else {
        Verdict::Unexplained
    };
    // The nominal model and its two perturbations, then the attribution's runs.
    let mut simulations = (3 + planned.load(std::sync::atomic::Ordering::Relaxed)) * targets.len();

    // The explaining model on every recording: the gap after.
    let mut map_after = Vec::new();
    let explained_by = (verdict == Verdict::Explained).then(|| best.map(|b| b.name.clone())).flatten();
    if let (Verdict::Explained, Some(best)) = (verdict, best) {
        progress(&format!("checking {}", best.effects.summary()), 0, targets.len());
        let after: Vec<Option<Vec<CellGap>>> = targets
            .par_iter()
            .map(|t| {
                let s =
                    simulate_counterpart(&model, &best.effects, &t.recording, &t.stem, model_step_s(&model)).ok()?;
                let spectra = ChainSpectra::compute(&s, &t.segmentation, &bands);
                Some(cell_gaps(&t.measured, &t.noise, &t.tolerances, &cell_powers(&[(&spectra, 1.0)], &bands)))
            })
            .collect();
        simulations += targets.len();
        for (r, cells) in recordings.iter_mut().zip(&after) {
            if let Some(cells) = cells {
                let g = gap_of_cells(cells.iter());
                r.explained = Some(g);
                r.explained_excess_db = Some(g.excess_db());
            }
        }
        map_after =
            after.into_iter().flatten().flatten().filter(|c| c.channel == signals::Channel::CarAcceleration).collect();
    }
    let map_before =
        nominal_cells.into_iter().flatten().filter(|c| c.channel == signals::Channel::CarAcceleration).collect();
    Ok(GapReport {
        dataset: name.to_string(),
        verdict,
        explained_by,
        gap_measure: GAP_MEASURE.to_string(),
        nominal_excess_db,
        noise_gap_db,
        calibration,
        location,
        ranking,
        recordings,
        bands_hz: bands.edges_hz.clone(),
        map_before,
        map_after,
        runtime_s: started.elapsed().as_secs_f64(),
        simulations,
    })
}
