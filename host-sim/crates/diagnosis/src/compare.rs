//! Step 3 of the pipeline: each prepared recording made a comparison target
//! (measured and nominal cells on the analysis bands, tolerances from the
//! perturbed runs) and the nominal model's gap per recording; after the
//! verdict, the explaining model's gap and the car acceleration's views.

use rayon::prelude::*;

use crate::drive_finding::DriveModel;
use crate::error::Result;
use crate::identify_dataset::LeftOut;
use crate::measure::{self, cell_gaps, gap_of_cells, CellGap};
use crate::prepare::{Prepared, RigSpeedLoop};
use crate::signals::{self, ChainSignals};
use crate::spectra::{self, cell_powers, Bands, ChainSpectra, Segmentation};
use crate::target::Target;
use crate::travel_signals::TravelTorque;
use crate::verdict::RecordingGap;
use crate::{driven, electrical_lines, replay};
use plant::effects::Effects;
use plant::free_decay::eqn9_first_frequency_hz;
use recording::{Column, Recording, RecordingKind, ACC_CAR, TIME_S};
use rig_config::RigConfig;

/// On a rig that is not the project's, a free decay's gap is taken up to
/// this multiple of its first natural frequency (Eqn 9): the decay tests the
/// first mode (Eqn 9, 11); the rope's own modes above it ring as the test's
/// release and the rope's make excite them, which the nominal model does not
/// claim to know.
pub const DECAY_TOP_MODE_FACTOR: f64 = 4.0;

/// On a rig that is not the project's, band cells are compared up to this
/// fraction of the recording's sample rate: its data acquisition's
/// anti-alias filter may already act above
/// ([`crate::acquisition::ANTI_ALIAS_START_FRACTION`]).
pub const FOREIGN_TOP_FRACTION: f64 = crate::acquisition::ANTI_ALIAS_START_FRACTION;
/// ... and up to this frequency, Hz: the torque from currents sampled by
/// the data acquisition stands for the shaft's only below the current
/// loop's bandwidth (a few hundred Hz on a commercial drive); above it the
/// inverter's switching ripple, aliased, drives the torque-driven model
/// where the rig's shaft never saw it. The car frame's first mode (235 Hz)
/// stays inside.
pub const FOREIGN_TOP_HZ: f64 = 500.0;

/// The car acceleration (m/s^2, positive up) of one recording as measured
/// and as the diagnosis's models give it: the project's drive in closed
/// loop or the mechanics driven by the measured torque, whichever the
/// diagnosis used.
#[derive(Clone, Debug)]
pub struct CarAccelerationViews {
    /// Recording.
    pub recording: String,
    /// Sample rate of every series, Hz (the analysis rate).
    pub sample_rate_hz: f64,
    /// (label, series): `data`, `nominal model` and, when `explained`,
    /// `explaining model`.
    pub series: Vec<(String, Vec<f64>)>,
}

/// The views of the recording with the largest nominal excess gap: its
/// measured car acceleration, the nominal model's and, with `explaining`,
/// the explaining model's (a model that cannot run loses its view, never
/// the diagnosis).
pub(crate) fn car_acceleration_views(
    model: &RigConfig,
    c: &Compared,
    recordings: &[RecordingGap],
    explaining: Option<(&RigConfig, &Effects)>,
) -> Option<CarAccelerationViews> {
    let worst = (0..recordings.len())
        .max_by(|&a, &b| recordings[a].nominal_excess_db.total_cmp(&recordings[b].nominal_excess_db))?;
    let (target, measured) = (c.targets.get(worst)?, c.measured.get(worst)?);
    let car = |s: &ChainSignals| s.channel(signals::Channel::CarAcceleration).map(<[f64]>::to_vec);
    let mut series = vec![("data".to_string(), car(measured)?)];
    let nominal = Effects::none();
    for (label, view) in [("nominal model", Some((model, &nominal))), ("explaining model", explaining)] {
        let Some((rig, effects)) = view else { continue };
        if let Some(values) =
            target.counterpart.simulate(rig, effects, &target.recording, &target.stem).ok().as_ref().and_then(car)
        {
            series.push((label.to_string(), values));
        }
    }
    Some(CarAccelerationViews { recording: target.stem.clone(), sample_rate_hz: measured.sample_rate_hz, series })
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
pub(crate) fn align_phases(measured: &mut ChainSignals, model: &mut ChainSignals) {
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

/// The measured cells of a recording from a rig with another drive, made
/// comparable with the model: what that rig does not tell is taken out, and
/// the torque-driven model's response to the torque's measurement noise
/// (`noise_response`) is added, as the model gets the sensors' noise.
/// `stop_compared`: the recording shows the brake stopping the turning
/// sheave at the end of the travel, so the stop is kept.
fn foreign_rig_cells(
    measured_cells: &mut spectra::CellPowers,
    recording: &Recording,
    bands: &Bands,
    model: &RigConfig,
    noise_response: Option<&ChainSignals>,
    stop_compared: bool,
) {
    // At standstill, before and after the motion, another drive lifts and
    // sets its brake against its own pre-torque and holding torque when it
    // likes. Where the recording does not say when, those transients are
    // the drive's, not a gap of the mechanics: not compared. Where it shows
    // the brake stopping the turning sheave at the end
    // (`driven::stop_brake`), the model takes it there and the
    // stop is compared. Its data
    // acquisition's anti-alias filter may start at a fifth of the sample
    // rate, and its torque stands for the shaft's only below the current
    // loop's bandwidth: bands above are not compared.
    if let Some(response) = noise_response {
        let top_hz = (FOREIGN_TOP_FRACTION * recording.meta.sample_rate_hz).min(FOREIGN_TOP_HZ);
        measured_cells.cells.retain(|((_, phase, band), _)| {
            let standstill = match phase {
                signals::Phase::Start => true,
                signals::Phase::Stop => !stop_compared,
                _ => false,
            };
            !standstill && (bands.is_line(*band) || bands.edges_hz[*band].1 <= top_hz)
        });
        let spectra = ChainSpectra::compute(response, &Segmentation::of(response), bands);
        let extra = cell_powers(&[(&spectra, 1.0)], bands);
        for (key, power) in measured_cells.cells.iter_mut() {
            power.0 += extra.get(*key).map_or(0.0, |e| e.0);
        }
    }
    if let RecordingKind::FreeDecay { mass_kg, rope_length_m } = recording.meta.kind {
        let m = &model.mechanics;
        let f1 = eqn9_first_frequency_hz(m.rope_ea_n, m.rope_mass_per_length_kg_per_m, rope_length_m, mass_kg);
        measured_cells.cells.retain(|((_, _, band), _)| bands.edges_hz[*band].1 <= DECAY_TOP_MODE_FACTOR * f1);
    }
}

/// What the diagnosis compares, per recording kept: the targets of the
/// attribution, the measured signals, and where they came from.
pub(crate) struct Compared {
    /// One per recording kept.
    pub(crate) targets: Vec<Target>,
    /// The measured chain signals of each target.
    pub(crate) measured: Vec<ChainSignals>,
    /// Their spectra on the target's segmentation of them, computed once.
    pub(crate) measured_spectra: Vec<ChainSpectra>,
    /// Index of each target's recording in the dataset.
    used: Vec<usize>,
    /// The analysis bands (one sample rate for the dataset).
    pub(crate) bands: Bands,
    /// The rig drive's speed loop per travel under another drive.
    pub(crate) rig_speed_loops: Vec<RigSpeedLoop>,
    /// The direct-axis lines per travel kept under another drive: measured,
    /// or (recording, why not).
    pub(crate) direct_axis: (Vec<electrical_lines::TravelLines>, Vec<(String, String)>),
    /// Simulations run for the nominal model, its perturbations and the
    /// counterpart's alternatives.
    pub(crate) simulations: usize,
}

/// One recording's comparison target from its prepared counterpart: the
/// measured and simulated cells on the analysis bands (returned with it:
/// [`compared`] takes only recordings whose bands are the dataset's), the
/// tolerances from the perturbed runs.
fn target_of(
    prepared: Prepared,
    recording: &Recording,
    drive: DriveModel,
    model: &RigConfig,
) -> (Target, ChainSignals, ChainSpectra, Bands) {
    let Prepared { stem, mut measured, mut nominal, mut perturbed, noise_response, how, .. } = prepared;
    let measured_for_perturbed = measured.clone();
    align_phases(&mut measured, &mut nominal);
    for p in perturbed.iter_mut() {
        align_phases(&mut measured_for_perturbed.clone(), p);
    }
    let seg_measured = Segmentation::of(&measured);
    let seg_model = Segmentation::of(&nominal);
    let bands = Bands::new(measured.sample_rate_hz, seg_measured.segment_len, spectra::line_orders(model));
    let measured_spectra = ChainSpectra::compute(&measured, &seg_measured, &bands);
    let nominal_spectra = ChainSpectra::compute(&nominal, &seg_model, &bands);
    let mut measured_cells = cell_powers(&[(&measured_spectra, 1.0)], &bands);
    if drive == DriveModel::Foreign {
        let stop_compared = how.shows_brake();
        foreign_rig_cells(&mut measured_cells, recording, &bands, model, noise_response.as_ref(), stop_compared);
    }
    let nominal_cells = cell_powers(&[(&nominal_spectra, 1.0)], &bands);
    let perturbed_cells: Vec<_> = perturbed
        .iter()
        .map(|p| cell_powers(&[(&ChainSpectra::compute(p, &Segmentation::of(p), &bands), 1.0)], &bands))
        .collect();
    let tolerances = measure::tolerances(&measured_cells, &measured.noise_density, &nominal_cells, &perturbed_cells);
    let group = match recording.meta.kind {
        RecordingKind::Travel { m_car_kg, .. } => format!("{m_car_kg:.1} kg"),
        RecordingKind::FreeDecay { mass_kg, .. } => format!("{mass_kg:.1} kg"),
    };
    let target = Target {
        stem,
        group,
        recording: light_copy(recording),
        measured: measured_cells,
        noise: measured.noise_density.clone(),
        tolerances,
        segmentation: seg_model,
        nominal: nominal_spectra,
        counterpart: how,
    };
    (target, measured, measured_spectra, bands)
}

/// The comparison targets of every prepared recording; what cannot be
/// compared goes to `left_out` with its reason.
pub(crate) fn compared(
    dataset: &[(String, Recording)],
    prepared: Vec<(usize, Result<Prepared>)>,
    drive: DriveModel,
    model: &RigConfig,
    left_out: &mut Vec<LeftOut>,
) -> Option<Compared> {
    let (mut targets, mut measured_all, mut used, mut rig_speed_loops) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut direct_axis = (Vec::new(), Vec::new());
    let mut measured_spectra = Vec::new();
    let mut bands_all: Option<Bands> = None;
    let mut simulations = 0;
    let mut ready = Vec::new();
    for (i, prepared) in prepared {
        let stem = &dataset[i].0;
        let mut prepared = match prepared {
            Ok(p) => p,
            Err(e) => {
                left_out.push(LeftOut { recording: stem.clone(), reason: format!("{e:#}") });
                continue;
            }
        };
        simulations += prepared.simulations;
        if let (Some(found), Some(shaft_angle)) = (&prepared.speed_loop, prepared.shaft_angle.take()) {
            let (controller, refused) = match found {
                Ok(c) => (Some(*c), None),
                Err(reason) => (None, Some(reason.clone())),
            };
            rig_speed_loops.push(RigSpeedLoop {
                recording: stem.clone(),
                controller,
                refused,
                shaft_angle,
                accelerometer_highpass: prepared.accelerometer_highpass,
                stop_brake: prepared.how.stop_brake().unwrap_or(crate::driven::StopBrake::NotFound),
            });
        }
        let lines = prepared.direct_axis.take();
        ready.push((i, prepared, lines));
    }
    // Every recording's spectra (the measured, the nominal and the
    // perturbed runs') side by side, then taken in the recordings' order.
    let computed: Vec<_> = ready
        .into_par_iter()
        .map(|(i, prepared, lines)| (i, lines, target_of(prepared, &dataset[i].1, drive, model)))
        .collect();
    for (i, lines, (target, measured, spectra, bands)) in computed {
        let (stem, recording) = &dataset[i];
        if bands_all.as_ref().is_some_and(|b| b.edges_hz != bands.edges_hz) {
            let reason = format!(
                "its sample rate ({} Hz) gives other analysis bands than the dataset's first recording; \
                 expected one sample rate for the whole dataset",
                recording.meta.sample_rate_hz
            );
            left_out.push(LeftOut { recording: stem.clone(), reason });
            continue;
        }
        match lines {
            Some(Ok(l)) => direct_axis.0.push(l),
            Some(Err(reason)) => direct_axis.1.push((stem.clone(), reason)),
            None => {}
        }
        targets.push(target);
        measured_all.push(measured);
        measured_spectra.push(spectra);
        used.push(i);
        bands_all = Some(bands);
    }
    let bands = bands_all?;
    Some(Compared {
        targets,
        measured: measured_all,
        measured_spectra,
        used,
        bands,
        rig_speed_loops,
        direct_axis,
        simulations,
    })
}

/// The nominal model's cells of every target and each recording's gap
/// (with the project's drive, the replay's too, its shaft following the
/// angle of `travels`, indexed as `dataset`).
pub(crate) fn nominal_gaps(
    model: &RigConfig,
    dataset: &[(String, Recording)],
    travels: &[Option<TravelTorque>],
    c: &Compared,
    drive: DriveModel,
) -> (Vec<Vec<CellGap>>, Vec<RecordingGap>) {
    let bands = &c.bands;
    let nominal_cells: Vec<Vec<CellGap>> = c
        .targets
        .iter()
        .map(|t| cell_gaps(&t.measured, &t.noise, &t.tolerances, &cell_powers(&[(&t.nominal, 1.0)], bands)))
        .collect();
    let replays: Vec<Option<Vec<CellGap>>> = c
        .used
        .par_iter()
        .zip(c.measured.par_iter())
        .zip(c.targets.par_iter())
        .map(|((&i, measured), target)| {
            let (stem, recording) = &dataset[i];
            if drive != DriveModel::Project {
                return None;
            }
            let angle = &travels.get(i)?.as_ref()?.shaft_angle_rad;
            replay::replay_cells(model, recording, stem, angle, measured, target, bands).ok()
        })
        .collect();
    let low_acc = |c: &&CellGap| {
        c.channel.subsystem() == signals::Subsystem::Mechanical
            && !bands.is_line(c.band)
            && bands.edges_hz[c.band].1 <= 80.0
    };
    let recordings = c
        .targets
        .iter()
        .zip(&nominal_cells)
        .zip(&replays)
        .zip(&c.measured)
        .map(|(((t, cells), replay), measured)| {
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
                begins_in_motion: travel && driven::begins_in_motion(&measured.angle_rad, measured.sample_rate_hz),
            }
        })
        .collect();
    (nominal_cells, recordings)
}

/// The explaining model (`effects`) on every target: each recording's gap
/// after, and the cells (every channel) of the maps after.
pub(crate) fn gap_after(
    model: &RigConfig,
    effects: &Effects,
    c: &Compared,
    recordings: &mut [RecordingGap],
) -> Vec<CellGap> {
    let bands = &c.bands;
    let after: Vec<Option<Vec<CellGap>>> = c
        .targets
        .par_iter()
        .map(|t| {
            let s = t.counterpart.simulate(model, effects, &t.recording, &t.stem).ok()?;
            let spectra = ChainSpectra::compute(&s, &t.segmentation, bands);
            Some(cell_gaps(&t.measured, &t.noise, &t.tolerances, &cell_powers(&[(&spectra, 1.0)], bands)))
        })
        .collect();
    for (r, cells) in recordings.iter_mut().zip(&after) {
        if let Some(cells) = cells {
            let g = gap_of_cells(cells.iter());
            r.explained = Some(g);
            r.explained_excess_db = Some(g.excess_db());
        }
    }
    after.into_iter().flatten().flatten().collect()
}
