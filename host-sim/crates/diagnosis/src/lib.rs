//! The sim-to-real gap diagnosis (`host-sim gap`): where a dataset departs
//! from the nominal model, which unmodelled effect of the library
//! (`plant::effects`) explains it, and how much of the gap it removes on
//! recordings held out from its fit.
//!
//! 1. [`calibrate`]: EA, guide and sheave damping identified from the data.
//! 2. [`simulate`] (closed loop) and [`replay`] (measured shaft motion into
//!    the mechanics) of every recording with the calibrated nominal model.
//! 3. [`measure`]: the gap in cells of channel x travel phase x band, each
//!    recording prepared once for it ([`target`]), located along the signal
//!    chain, in time and in frequency ([`locate`]).
//! 4. [`attribute`]: every effect fitted and cross-validated; an effect
//!    that the calibration can absorb on the calibration re-done under its
//!    hypothesis ([`hypotheses`]).
//! 5. [`naming`]: a candidate is named only when it shrinks the held-out
//!    gap beyond its scatter and its fitted strength leaves no effect by
//!    more than its uncertainty.
//! 6. The verdict: `nominal`, `explained` or `unexplained` ([`report`]).
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
pub mod calibrate;
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
pub mod replay;
pub mod report;
pub mod screen;
pub mod signals;
pub mod simulate;
pub mod spectra;
pub mod target;
pub mod transducer;
pub mod travel_signals;

use std::time::Instant;

use rayon::prelude::*;

pub use error::DiagnosisError;

use crate::error::{bail, Result};
use crate::identify_dataset::LeftOut;
use attribute::{attribute, Candidate, Lab};
use calibrate::{calibrate, Calibration};
use locate::{locate, Location};
use measure::{cell_gaps, gap_of_cells, persistent_cell, CellGap, GapValue, PersistentCell};
use plant::effects::{EffectKind, Effects};
use plant::free_decay::eqn9_first_frequency_hz;
use recording::{Column, Recording, RecordingKind, ACC_CAR, TIME_S};
use rig_config::RigConfig;
use signals::{chain_signals, decimation_factor, ChainSignals};
use simulate::{
    driven_accelerations, driven_counterpart, driven_highpass, driven_signals, highpass_accelerations, model_step_s,
    simulate_counterpart, Counterpart, DriveRecord, DrivenInputs,
};
use spectra::{cell_powers, Bands, ChainSpectra, Segmentation};
use target::Target;

/// Largest nominal excess gap (dB, mean over the recordings) that the
/// verdict still calls `nominal`.
pub const NOMINAL_EXCESS_DB: f64 = 0.15;
/// Largest RMS (dB) by which a persistent cell
/// ([`measure::persistent_cell`]: beyond noise and tolerance in every
/// recording that has it, more often than chance allows) may lie beyond
/// them for the verdict still to be `nominal`.
pub const PERSISTENT_CELL_DB: f64 = 1.0;
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

/// Largest RMS gap (dB) of the torque at standstill (start and stop cells)
/// between the recording and the project's drive in closed loop for which
/// the rig is taken to run the project's drive.
pub const DRIVE_MISMATCH_DB: f64 = 6.0;

/// On a rig that is not the project's, a free decay's gap is taken up to
/// this multiple of its first natural frequency (Eqn 9): the decay tests the
/// first mode (Eqn 9, 11); the rope's own modes above it ring as the test's
/// release and the rope's make excite them, which the nominal model does not
/// claim to know.
pub const DECAY_TOP_MODE_FACTOR: f64 = 4.0;

/// On a rig that is not the project's, band cells are compared up to this
/// fraction of the recording's sample rate: its data acquisition's
/// anti-alias filter may already act above (the measurement format does not
/// promise a flat response up to Nyquist).
pub const FOREIGN_TOP_FRACTION: f64 = 0.2;
/// ... and up to this frequency, Hz: the torque from currents sampled by
/// the data acquisition stands for the shaft's only below the current
/// loop's bandwidth (a few hundred Hz on a commercial drive); above it the
/// inverter's switching ripple, aliased, drives the torque-driven model
/// where the rig's shaft never saw it. The car frame's first mode (235 Hz)
/// stays inside.
pub const FOREIGN_TOP_HZ: f64 = 500.0;

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

/// The rig drive's speed loop as one travel shows it.
#[derive(Clone, Debug, serde::Serialize)]
pub struct RigSpeedLoop {
    /// The travel.
    pub recording: String,
    /// The identified controller, when the data show a PI on the speed
    /// estimate.
    pub controller: Option<drive_law::SpeedController>,
    /// Why not, otherwise.
    pub refused: Option<String>,
    /// The shaft angle the travel's model follows: its source and its delay
    /// behind the currents ([`travel_signals::travel_shaft_angle`]).
    pub shaft_angle: travel_signals::AngleAlignment,
    /// The high-pass (order and corner) that brings the model's slow car
    /// acceleration closest to the measured one: the rig's accelerometers
    /// as the data show them, applied to every run
    /// ([`simulate::driven_highpass`]).
    pub accelerometer_highpass: acquisition::Highpass,
}

/// Settings of a diagnosis.
#[derive(Clone, Debug)]
pub struct GapOptions {
    /// What to assume about the rig's drive.
    pub drive: DriveAssumption,
    /// The effects to try (default: the whole library).
    pub effects: Vec<EffectKind>,
    /// See [`NOMINAL_EXCESS_DB`].
    pub nominal_excess_db: f64,
    /// See [`PERSISTENT_CELL_DB`].
    pub persistent_cell_db: f64,
    /// See [`EXPLAINED_SHRINK`].
    pub explained_shrink: f64,
}

impl Default for GapOptions {
    fn default() -> Self {
        Self {
            drive: DriveAssumption::Auto,
            effects: EffectKind::ALL.to_vec(),
            nominal_excess_db: NOMINAL_EXCESS_DB,
            persistent_cell_db: PERSISTENT_CELL_DB,
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
    /// A travel whose rig is already moving at the first sample (its brake
    /// lifted before the recording started): the chain's state there is not
    /// recorded ([`driven::StartState`]).
    pub begins_in_motion: bool,
}

/// What `gap` found.
#[derive(Clone, Debug, serde::Serialize)]
pub struct GapReport {
    /// The dataset.
    pub dataset: String,
    /// The verdict.
    pub verdict: Verdict,
    /// The drive the travels' model assumes, and why.
    pub drive: DriveFinding,
    /// The rig drive's speed loop identified from each travel under another
    /// drive ([`drive_law`]).
    pub rig_speed_loops: Vec<RigSpeedLoop>,
    /// Recordings not diagnosed, with the reason (the calibration's own
    /// left-out recordings are in [`Calibration::skipped`]).
    pub left_out: Vec<LeftOut>,
    /// What the attribution left out, and why (under another drive).
    pub attribution_note: Option<String>,
    /// The explaining effect (or pair) when `explained`.
    pub explained_by: Option<String>,
    /// The gap measure, in words, with its unit.
    pub gap_measure: String,
    /// Mean excess gap of the calibrated nominal model over the recordings, dB.
    pub nominal_excess_db: f64,
    /// Mean noise gap of the recordings, dB.
    pub noise_gap_db: f64,
    /// The nominal model's persistent cell with the largest RMS beyond
    /// noise and tolerance, if any; beyond [`PERSISTENT_CELL_DB`] it alone
    /// makes the verdict other than `nominal`.
    pub persistent_cell: Option<PersistentCell>,
    /// Under another drive: the direct-axis current's lines at electrical
    /// orders 1, 2 and 6 and the electrical effects fitted to them
    /// ([`electrical_lines`]); a line present makes the verdict other than
    /// `nominal`.
    pub electrical_lines: Option<electrical_lines::ElectricalLines>,
    /// The car acceleration of the recording with the largest nominal gap,
    /// measured and from the models the diagnosis compared it with (for
    /// spectrograms; not in `gap.json`).
    #[serde(skip)]
    pub car_acceleration_views: Option<CarAccelerationViews>,
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
    /// Cells of every channel of the nominal model (the gap maps before).
    pub map_before: Vec<CellGap>,
    /// The same with the explaining model (after).
    pub map_after: Vec<CellGap>,
    /// Wall-clock time of the diagnosis, s.
    pub runtime_s: f64,
    /// Simulations run.
    pub simulations: usize,
}

impl GapReport {
    /// When the two best candidates are the sheave's eccentricity and the
    /// encoder's error, in either order: they move the rope alike for the
    /// measured angle, and what tells them apart, in words.
    pub fn once_per_revolution_note(&self) -> Option<String> {
        let [first, second] = [self.ranking.first()?, self.ranking.get(1)?].map(|c| c.name.as_str());
        (self.verdict != Verdict::Nominal && move_the_rope_alike(first, second)).then(|| {
            format!(
                "{first} and {second} both move the rope by r0 (theta + e sin(theta + phi)) for the measured \
                     angle theta, one through the sheave's geometry, the other through the encoder's reading: the \
                     recordings tell them apart only through the torque, under the rig's once-per-revolution \
                     ripple; a second shaft sensor or a runout measurement of the sheave settles which"
            )
        })
    }

    /// When the nominal model misses the data and no candidate of the
    /// ranking may be named ([`naming`]): that no effect of the library
    /// helps, with why the best is not named.
    pub fn no_effect_helps_note(&self) -> Option<String> {
        if self.verdict == Verdict::Nominal || self.ranking.iter().any(|c| c.naming.named) {
            return None;
        }
        let first = self.ranking.first()?;
        Some(format!(
            "No effect of the library helps: the best fit, `{}`, is not named because {}",
            first.name, first.naming.reason
        ))
    }

    /// The travels that begin with the rig already moving and what the
    /// diagnosis does about them, in words; `None` when there are none.
    pub fn begins_in_motion_note(&self) -> Option<String> {
        let travels: Vec<&str> =
            self.recordings.iter().filter(|g| g.begins_in_motion).map(|g| g.recording.as_str()).collect();
        (!travels.is_empty()).then(|| {
            let handled = if self.drive.drive == DriveModel::Foreign {
                "the model starts there in the quasi-static state of the measured speed, and the tolerance covers \
                 the unknown jolt of the brake lift, from none (a pre-torque that balanced the load) to the whole \
                 torque (no pre-torque)"
            } else {
                "the closed loop runs the travel from standstill, so the start of the comparison is not the rig's"
            };
            format!(
                "{} begin{} with the rig already moving (its brake lifted before the recording started): {handled}",
                travels.join(", "),
                if travels.len() == 1 { "s" } else { "" }
            )
        })
    }
}

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
fn car_acceleration_views(
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

/// Whether candidates `a` and `b` are the sheave's eccentricity and the
/// encoder's error, in either order.
fn move_the_rope_alike(a: &str, b: &str) -> bool {
    let pair = [EffectKind::SheaveEccentricity.name(), EffectKind::EncoderError.name()];
    a != b && pair.contains(&a) && pair.contains(&b)
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

/// One recording made ready for the gap: its measured chain signals and the
/// nominal model's counterpart with its two perturbations.
struct Prepared {
    stem: String,
    measured: ChainSignals,
    nominal: ChainSignals,
    perturbed: Vec<ChainSignals>,
    /// The torque-driven model's response to the current probes' noise in
    /// the measured torque (another draw of it), where the model is driven.
    noise_response: Option<ChainSignals>,
    /// The rig drive's speed loop as identified, or why not, where the
    /// model is driven.
    speed_loop: Option<Result<drive_law::SpeedController, String>>,
    /// The shaft angle's source and alignment, where the model is driven.
    shaft_angle: Option<travel_signals::AngleAlignment>,
    /// The accelerometers' high-pass found, where the model is driven.
    accelerometer_highpass: acquisition::Highpass,
    /// The direct-axis current's lines of the travel, or why not, where the
    /// model is driven ([`electrical_lines::travel_lines`]).
    direct_axis: Option<Result<electrical_lines::TravelLines, String>>,
    /// Simulations run: the nominal model, its perturbations, the
    /// counterpart's alternatives and the noise response.
    simulations: usize,
    /// How the counterpart is made, for the attribution's runs.
    how: Counterpart,
}

/// `signal` plus white Gaussian noise of one-sided density `density`
/// (unit^2/Hz) at `sample_rate_hz`, seeded from `stem` (reproducible).
fn with_white_noise(signal: &[f64], density: f64, sample_rate_hz: f64, stem: &str) -> Vec<f64> {
    use rand::SeedableRng;
    use rand_distr::Distribution;
    let sigma = (density * 0.5 * sample_rate_hz).sqrt();
    let Ok(normal) = rand_distr::Normal::new(0.0, sigma) else { return signal.to_vec() };
    let seed = stem.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3));
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    signal.iter().map(|v| v + normal.sample(&mut rng)).collect()
}

/// `a - b`, channel by channel (same channels, lengths and phases).
fn difference(a: &ChainSignals, b: &ChainSignals) -> ChainSignals {
    let mut out = a.clone();
    for ((_, x), (_, y)) in out.channels.iter_mut().zip(&b.channels) {
        x.iter_mut().zip(y).for_each(|(x, y)| *x -= y);
    }
    out
}

/// The measured chain signals of every recording and, for the decision on
/// the drive, the closed loop's nominal run of each (an error where it
/// cannot run, e.g. the project's drive trips on the recording).
fn measure_and_run_closed_loop(
    rig: &RigConfig,
    model: &RigConfig,
    dataset: &[(String, Recording)],
    left_out: &mut Vec<LeftOut>,
) -> Vec<(usize, ChainSignals, Result<ChainSignals>)> {
    let runs: Vec<Result<(ChainSignals, Result<ChainSignals>)>> = dataset
        .par_iter()
        .map(|(stem, recording)| {
            let factor = decimation_factor(recording.meta.sample_rate_hz);
            let measured = chain_signals(rig, recording, stem, factor, true)?;
            let closed = simulate_counterpart(model, &Effects::none(), recording, stem, model_step_s(model));
            Ok((measured, closed))
        })
        .collect();
    let mut out = Vec::new();
    for (i, run) in runs.into_iter().enumerate() {
        match run {
            Ok((measured, closed)) => out.push((i, measured, closed)),
            Err(e) => left_out.push(LeftOut { recording: dataset[i].0.clone(), reason: format!("{e:#}") }),
        }
    }
    out
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
fn decide_drive(
    option: DriveAssumption,
    dataset: &[(String, Recording)],
    runs: &[(usize, ChainSignals, Result<ChainSignals>)],
) -> DriveFinding {
    let travels = runs.iter().filter(|(i, ..)| matches!(dataset[*i].1.meta.kind, RecordingKind::Travel { .. }));
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
    for (i, measured, closed) in travels {
        let stem = &dataset[*i].0;
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

/// The series that give a travel's true torque under a current-transducer
/// error ([`transducer`]), on the grid of its chain signals `measured`;
/// none when the currents cannot be read again (the torque itself was).
fn transducer_series(
    rig: &RigConfig,
    recording: &Recording,
    stem: &str,
    measured: &ChainSignals,
) -> Option<transducer::TransducerSeries> {
    let torque = travel_signals::travel_torque(rig, recording, stem).ok()?;
    let factor = (recording.meta.sample_rate_hz / measured.sample_rate_hz).round().max(1.0) as usize;
    transducer::TransducerSeries::of(
        rig,
        recording,
        stem,
        &torque.shaft_angle_rad,
        torque.electrical_offset_rad,
        factor,
    )
    .ok()
}

/// The model's counterpart of a measured recording, with its two
/// perturbations: the closed loop (the project's drive) or, for travels
/// under another drive, the torque-driven mechanics ([`driven`]); the
/// measured signals reduced to the channels the counterpart has.
fn counterpart(
    models: [&RigConfig; 3],
    drive: DriveModel,
    stem: &str,
    recording: &Recording,
    mut measured: ChainSignals,
    closed: Result<ChainSignals>,
) -> Result<Prepared> {
    let driven = matches!(recording.meta.kind, RecordingKind::Travel { .. }) && drive == DriveModel::Foreign;
    let torque = measured.channel(signals::Channel::Torque).map(<[f64]>::to_vec).unwrap_or_default();
    let speed = measured.channel(signals::Channel::Speed).map(<[f64]>::to_vec).unwrap_or_default();
    let torque_noise_density =
        measured.noise_density.iter().find(|(c, _)| *c == signals::Channel::Torque).map_or(0.0, |(_, n)| *n);
    if driven {
        measured.channels.retain(|(c, _)| {
            matches!(c, signals::Channel::CarAcceleration | signals::Channel::CounterweightAcceleration)
        });
        measured.noise_density.retain(|(c, _)| measured.channels.iter().any(|(m, _)| m == c));
    }
    let speed_loop = driven.then(|| rig_speed_controller(models[0], recording, &measured, &torque, &speed));
    let controller = speed_loop.as_ref().and_then(|found| found.as_ref().ok().copied());
    let shaft_angle = driven.then(|| travel_signals::travel_shaft_angle(models[0], recording).1);
    let direct_axis =
        driven.then(|| electrical_lines::travel_lines(models[0], recording, stem).map_err(|e| format!("{e:#}")));
    let transducer_lines = match &direct_axis {
        Some(Ok(lines)) => electrical_lines::transducer_torque_lines(&models[0].motor, lines),
        _ => Vec::new(),
    };
    let transducer = if driven { transducer_series(models[0], recording, stem, &measured) } else { None };
    let drive_record = DriveRecord {
        torque_nm: &torque,
        speed_estimate_radps: &speed,
        controller,
        transducer_lines: &transducer_lines,
        transducer: transducer.as_ref(),
    };
    let none = Effects::none();
    // The nominal torque-driven run, raw: the accelerometers' high-pass
    // belongs to the acquisition and is found from it once, then applied to
    // every run of the recording (this one included).
    let settings = driven::DrivenSettings::default();
    let nominal_driven = driven
        .then(|| driven_accelerations(models[0], recording, &measured, drive_record, &settings, &none))
        .transpose()?;
    let highpass = match &nominal_driven {
        Some((car, _)) => driven_highpass(&measured, car)?,
        None => acquisition::Highpass::NONE,
    };
    let run_driven = |model: &RigConfig, settings: &driven::DrivenSettings| {
        driven_counterpart(model, recording, &measured, drive_record, highpass, settings, &none)
    };
    let (nominal, perturbed, how) = if let Some(raw) = nominal_driven {
        let perturbed = driven_perturbed(models, &measured, run_driven)?;
        let inputs = DrivenInputs {
            measured: measured.clone(),
            torque_nm: torque.clone(),
            speed_estimate_radps: speed.clone(),
            controller,
            transducer_lines: transducer_lines.clone(),
            transducer: transducer.clone(),
            highpass,
        };
        // The nominal run shaped as the attribution shapes every effect's
        // (`Counterpart::simulate` -> `driven_counterpart`).
        let how = Counterpart::Driven(std::sync::Arc::new(inputs));
        (driven_signals(&measured, raw, highpass)?, perturbed, how)
    } else {
        simulated_counterpart(models, drive, recording, stem, &measured, closed)?
    };
    let noise_response = if driven {
        let noisy = with_white_noise(&torque, torque_noise_density, measured.sample_rate_hz, stem);
        let run = driven_counterpart(
            models[0],
            recording,
            &measured,
            DriveRecord { torque_nm: &noisy, ..drive_record },
            highpass,
            &driven::DrivenSettings::default(),
            &none,
        )?;
        Some(difference(&run, &nominal))
    } else {
        None
    };
    let simulations = 1 + perturbed.len() + usize::from(noise_response.is_some());
    Ok(Prepared {
        stem: stem.to_string(),
        measured,
        nominal,
        perturbed,
        noise_response,
        speed_loop,
        shaft_angle,
        accelerometer_highpass: highpass,
        direct_axis,
        simulations,
        how,
    })
}

/// The torque-driven model's perturbed runs (`run` on a model with
/// settings): the two perturbed rigs of `models`, the settings'
/// alternatives on the calibrated rig, and the start's alternatives when
/// the recording begins in motion.
fn driven_perturbed(
    models: [&RigConfig; 3],
    measured: &ChainSignals,
    run: impl Fn(&RigConfig, &driven::DrivenSettings) -> Result<ChainSignals>,
) -> Result<Vec<ChainSignals>> {
    let settings = driven::DrivenSettings::default();
    let mut perturbed = vec![run(models[1], &settings)?, run(models[2], &settings)?];
    for alternative in driven::DrivenSettings::alternatives() {
        perturbed.push(run(models[0], &alternative)?);
    }
    if driven::begins_in_motion(&measured.angle_rad, measured.sample_rate_hz) {
        for alternative in driven::DrivenSettings::start_alternatives() {
            perturbed.push(run(models[0], &alternative)?);
        }
    }
    Ok(perturbed)
}

/// The simulated counterpart of a recording (the closed loop's run
/// `closed`, or a free decay): the nominal run, the perturbed models'
/// runs; under another rig's data acquisition, its accelerometers'
/// high-pass found from the decay itself and applied to the model's.
fn simulated_counterpart(
    models: [&RigConfig; 3],
    drive: DriveModel,
    recording: &Recording,
    stem: &str,
    measured: &ChainSignals,
    closed: Result<ChainSignals>,
) -> Result<(ChainSignals, Vec<ChainSignals>, Counterpart)> {
    let none = Effects::none();
    let run_closed = |model: &RigConfig| simulate_counterpart(model, &none, recording, stem, model_step_s(model));
    let (mut nominal, mut perturbed) = (closed?, vec![run_closed(models[1])?, run_closed(models[2])?]);
    let mut highpass = acquisition::Highpass::NONE;
    if drive == DriveModel::Foreign {
        highpass = decay_highpass(measured, &nominal)?;
        for run in std::iter::once(&mut nominal).chain(perturbed.iter_mut()) {
            highpass_accelerations(run, highpass)?;
        }
    }
    Ok((nominal, perturbed, Counterpart::Simulated { highpass }))
}

/// The accelerometer high-pass (order and corner) that brings the model's
/// car acceleration closest to the measured one below
/// [`acquisition::COMPARISON_LOWPASS_HZ`], the model read at the measured
/// signal's instants (linear interpolation).
fn decay_highpass(measured: &ChainSignals, model: &ChainSignals) -> Result<acquisition::Highpass> {
    let (Some(data), Some(sim)) =
        (measured.channel(signals::Channel::CarAcceleration), model.channel(signals::Channel::CarAcceleration))
    else {
        return Ok(acquisition::Highpass::NONE);
    };
    let ratio = model.sample_rate_hz / measured.sample_rate_hz;
    let at = |k: usize| {
        let x = k as f64 * ratio;
        let i = x.floor() as usize;
        let f = x - i as f64;
        match (sim.get(i), sim.get(i + 1)) {
            (Some(a), Some(b)) => Some(a + f * (b - a)),
            (Some(a), None) => Some(*a),
            _ => None,
        }
    };
    let resampled: Vec<f64> = (0..data.len()).map_while(at).collect();
    acquisition::identify_highpass(data, &resampled, measured.sample_rate_hz)
}

/// The rig drive's speed controller identified from the travel
/// `recording` ([`drive_law`]): its measured chain signals, torque and
/// speed estimate, and the speed reference when recorded; the reason when
/// the data do not show a PI on the speed estimate.
fn rig_speed_controller(
    model: &RigConfig,
    recording: &Recording,
    measured: &ChainSignals,
    torque: &[f64],
    speed: &[f64],
) -> Result<drive_law::SpeedController, String> {
    let factor = (recording.meta.sample_rate_hz / measured.sample_rate_hz).round().max(1.0) as usize;
    let r = model.mechanics.sheave_radius_m;
    let reference: Option<Vec<f64>> = recording
        .column(recording::REF_SPEED)
        .map(|c| c.values.iter().step_by(factor).map(|v| v / r).take(torque.len()).collect());
    let constant_speed = measured
        .phases
        .iter()
        .find(|(p, _)| *p == signals::Phase::Constant)
        .ok_or("the travel has no constant-speed stage")?
        .1
        .clone();
    let data = drive_law::ControllerData {
        torque_nm: torque,
        shaft_angle_rad: &measured.angle_rad,
        speed_estimate_radps: speed,
        reference_radps: reference.as_deref().filter(|r| r.len() == torque.len()),
        motion: driven::motion_from_angle(&measured.angle_rad, measured.sample_rate_hz),
        constant_speed,
        sample_rate_hz: measured.sample_rate_hz,
    };
    drive_law::identify_speed_controller(&data).map_err(|e| format!("{e:#}"))
}

/// The measured cells of a recording from a rig with another drive, made
/// comparable with the model: what that rig does not tell is taken out, and
/// the torque-driven model's response to the torque's measurement noise
/// (`noise_response`) is added, as the model gets the sensors' noise.
fn foreign_rig_cells(
    measured_cells: &mut spectra::CellPowers,
    recording: &Recording,
    bands: &Bands,
    model: &RigConfig,
    noise_response: Option<&ChainSignals>,
) {
    // At standstill, before and after the motion, another drive lifts and
    // sets its brake against its own pre-torque and holding torque when it
    // likes; the recording does not say when. Those transients are the
    // drive's, not a gap of the mechanics: not compared. Its data
    // acquisition's anti-alias filter may start at a fifth of the sample
    // rate, and its torque stands for the shaft's only below the current
    // loop's bandwidth: bands above are not compared.
    if let Some(response) = noise_response {
        let top_hz = (FOREIGN_TOP_FRACTION * recording.meta.sample_rate_hz).min(FOREIGN_TOP_HZ);
        measured_cells.cells.retain(|((_, phase, band), _)| {
            !matches!(phase, signals::Phase::Start | signals::Phase::Stop)
                && (bands.is_line(*band) || bands.edges_hz[*band].1 <= top_hz)
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
struct Compared {
    /// One per recording kept.
    targets: Vec<Target>,
    /// The measured chain signals of each target.
    measured: Vec<ChainSignals>,
    /// Index of each target's recording in the dataset.
    used: Vec<usize>,
    /// The analysis bands (one sample rate for the dataset).
    bands: Bands,
    /// The rig drive's speed loop per travel under another drive.
    rig_speed_loops: Vec<RigSpeedLoop>,
    /// The direct-axis lines per travel kept under another drive: measured,
    /// or (recording, why not).
    direct_axis: (Vec<electrical_lines::TravelLines>, Vec<(String, String)>),
    /// Simulations run for the nominal model, its perturbations and the
    /// counterpart's alternatives.
    simulations: usize,
}

/// One recording's comparison target from its prepared counterpart: the
/// measured and simulated cells on the analysis bands, the tolerances from
/// the perturbed runs; `bands_so_far` are the dataset's bands when an
/// earlier recording set them. The reason in words when it cannot be
/// compared.
fn target_of(
    prepared: Prepared,
    recording: &Recording,
    bands_so_far: Option<&Bands>,
    drive: DriveModel,
    model: &RigConfig,
) -> std::result::Result<(Target, ChainSignals, Bands), String> {
    let Prepared { stem, mut measured, mut nominal, mut perturbed, noise_response, how, .. } = prepared;
    let measured_for_perturbed = measured.clone();
    align_phases(&mut measured, &mut nominal);
    for p in perturbed.iter_mut() {
        align_phases(&mut measured_for_perturbed.clone(), p);
    }
    let seg_measured = Segmentation::of(&measured);
    let seg_model = Segmentation::of(&nominal);
    let bands = Bands::new(measured.sample_rate_hz, seg_measured.segment_len, spectra::line_orders(model));
    if bands_so_far.is_some_and(|b| b.edges_hz != bands.edges_hz) {
        return Err(format!(
            "its sample rate ({} Hz) gives other analysis bands than the dataset's first recording; \
             expected one sample rate for the whole dataset",
            recording.meta.sample_rate_hz
        ));
    }
    let measured_spectra = ChainSpectra::compute(&measured, &seg_measured, &bands);
    let nominal_spectra = ChainSpectra::compute(&nominal, &seg_model, &bands);
    let mut measured_cells = cell_powers(&[(&measured_spectra, 1.0)], &bands);
    if drive == DriveModel::Foreign {
        foreign_rig_cells(&mut measured_cells, recording, &bands, model, noise_response.as_ref());
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
    Ok((target, measured, bands))
}

/// The comparison targets of every prepared recording; what cannot be
/// compared goes to `left_out` with its reason.
fn compared(
    dataset: &[(String, Recording)],
    prepared: Vec<(usize, Result<Prepared>)>,
    drive: DriveModel,
    model: &RigConfig,
    left_out: &mut Vec<LeftOut>,
) -> Option<Compared> {
    let (mut targets, mut measured_all, mut used, mut rig_speed_loops) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut direct_axis = (Vec::new(), Vec::new());
    let mut bands_all: Option<Bands> = None;
    let mut simulations = 0;
    for (i, prepared) in prepared {
        let (stem, recording) = &dataset[i];
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
            });
        }
        let lines = prepared.direct_axis.take();
        match target_of(prepared, recording, bands_all.as_ref(), drive, model) {
            Ok((target, measured, bands)) => {
                match lines {
                    Some(Ok(l)) => direct_axis.0.push(l),
                    Some(Err(reason)) => direct_axis.1.push((stem.clone(), reason)),
                    None => {}
                }
                targets.push(target);
                measured_all.push(measured);
                used.push(i);
                bands_all = Some(bands);
            }
            Err(reason) => left_out.push(LeftOut { recording: stem.clone(), reason }),
        }
    }
    let bands = bands_all?;
    Some(Compared { targets, measured: measured_all, used, bands, rig_speed_loops, direct_axis, simulations })
}

/// The nominal model's cells of every target and each recording's gap
/// (with the project's drive, the replay's too).
fn nominal_gaps(
    model: &RigConfig,
    dataset: &[(String, Recording)],
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
            let project = drive == DriveModel::Project;
            project.then(|| replay::replay_cells(model, recording, stem, measured, target, bands).ok()).flatten()
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
fn gap_after(model: &RigConfig, effects: &Effects, c: &Compared, recordings: &mut [RecordingGap]) -> Vec<CellGap> {
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

/// The verdict from the nominal model's gap (`is_nominal`) with the best
/// candidate of the attribution, and the direct-axis lines when present
/// with theirs: `explained` when a named candidate removes the held-out
/// gap (shrink at least the option's) and the lines' gap is explained
/// too, whatever the nominal gap's size; otherwise `nominal` when neither
/// shows a gap, `explained` when every gap shown is explained.
fn verdict_of(
    is_nominal: bool,
    best: Option<&Candidate>,
    electrical: Option<&electrical_lines::ElectricalLines>,
    options: &GapOptions,
) -> Verdict {
    let explains =
        |c: Option<&Candidate>| c.is_some_and(|b| b.naming.named && b.held_out_shrink >= options.explained_shrink);
    let lines_explained = electrical.is_none_or(|e| explains(e.ranking.first()));
    if explains(best) && lines_explained {
        // A named effect that removes the held-out gap wins over the
        // nominal model, however small that gap: the same machinery
        // compares both on the same held-out recordings.
        Verdict::Explained
    } else if is_nominal && electrical.is_none() {
        Verdict::Nominal
    } else if is_nominal && lines_explained {
        Verdict::Explained
    } else {
        Verdict::Unexplained
    }
}

/// Why some effects are not fitted to the mechanics under another drive,
/// in words (`None` when every effect is).
fn not_fitted_note(not_fitted: &[EffectKind]) -> Option<String> {
    (!not_fitted.is_empty()).then(|| {
        let names: Vec<&str> = not_fitted.iter().map(|k| k.name()).collect();
        format!(
            "the rig's drive is another, so the effects are fitted with the mechanics driven by its measured torque; \
             not fitted to the mechanics: {} (the dead time acts through the currents, which the measured torque \
             already carries: it is fitted to the direct-axis current's lines instead; the brake clamp acts at \
             standstill, where another drive's start and stop are not compared)",
            names.join(", ")
        )
    })
}

/// Steps 4 and 5 on the mechanics: every effect the counterpart holds
/// fitted (the calibration re-done under the hypotheses that it can
/// absorb), cross-validated and named; with the note on what is not
/// fitted and the runs planned per recording.
fn attribute_mechanics(
    model: &RigConfig,
    calibration: &Calibration,
    dataset: &[(String, Recording)],
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
    let (kinds, not_fitted): (Vec<EffectKind>, Vec<EffectKind>) =
        options.effects.iter().partition(|k| drive == DriveModel::Project || driven::holds_effect(**k));
    // The calibration re-done under the hypotheses of the effects it can
    // absorb (step 4a).
    let refits: Vec<hypotheses::Refit> =
        kinds.iter().filter_map(|&k| hypotheses::refit(k, model, calibration, dataset)).collect();
    let lab = Lab {
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
fn electrical_lines_of(
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

/// The names of what explains the gap: the lines' named effect, then the
/// mechanics', joined by ` + `.
fn explained_by(electrical: Option<&electrical_lines::ElectricalLines>, best: Option<&Candidate>) -> String {
    let names: Vec<&str> = electrical
        .and_then(|e| e.ranking.first())
        .filter(|c| c.naming.named)
        .into_iter()
        .chain(best)
        .map(|c| c.name.as_str())
        .collect();
    names.join(" + ")
}

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
    let is_nominal = nominal_excess_db <= options.nominal_excess_db
        && persistent_cell.as_ref().is_none_or(|p| p.rms_beyond_db <= options.persistent_cell_db);
    let (mechanical_ranking, attribution_note, planned) =
        attribute_mechanics(&model, &calibration, dataset, &compared, drive.drive, options, progress);
    let electrical_lines = electrical_lines_of(&mut compared, drive.drive, options);
    let electrical = electrical_lines.as_ref().filter(|e| e.present());
    let verdict = verdict_of(is_nominal, mechanical_ranking.first(), electrical, options);
    // The mechanics' candidate the verdict rests on: a named one, also when
    // it explains a gap within the nominal threshold (the verdict says so).
    let best = mechanical_ranking
        .first()
        .filter(|c| c.naming.named)
        .filter(|c| !is_nominal || (verdict == Verdict::Explained && c.held_out_shrink >= options.explained_shrink));
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
        gap_measure: GAP_MEASURE.to_string(),
        nominal_excess_db,
        noise_gap_db,
        persistent_cell,
        electrical_lines,
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

    fn candidate(shrink: f64) -> Candidate {
        Candidate {
            name: "effect".into(),
            parameters: Vec::new(),
            fitted_parameters: 1,
            training_gap_before_db: 1.0,
            training_gap_after_db: 1.0 - shrink,
            held_out_gap_before_db: 1.0,
            held_out_gap_after_db: 1.0 - shrink,
            held_out_shrink: shrink,
            score_db: 1.0 - shrink,
            effects: Effects::none(),
            naming: naming::Naming { named: true, reason: String::new() },
            ..Candidate::default()
        }
    }

    fn lines_explained_by(shrink: f64) -> electrical_lines::ElectricalLines {
        electrical_lines::ElectricalLines {
            travels: Vec::new(),
            not_measured: Vec::new(),
            present_orders: vec![1.0],
            excess_db: 10.0,
            ranking: vec![candidate(shrink)],
        }
    }

    #[test]
    fn every_gap_shown_must_be_explained() {
        let o = GapOptions::default();
        let (good, poor) = (candidate(0.9), candidate(0.2));
        let (lines_good, lines_poor) = (lines_explained_by(0.9), lines_explained_by(0.2));
        assert_eq!(verdict_of(true, Some(&poor), None, &o), Verdict::Nominal);
        assert_eq!(verdict_of(true, Some(&poor), Some(&lines_good), &o), Verdict::Explained);
        assert_eq!(verdict_of(true, Some(&good), Some(&lines_poor), &o), Verdict::Unexplained);
        assert_eq!(verdict_of(false, Some(&good), Some(&lines_good), &o), Verdict::Explained);
        assert_eq!(verdict_of(false, Some(&poor), Some(&lines_good), &o), Verdict::Unexplained);
        assert_eq!(verdict_of(false, Some(&good), None, &o), Verdict::Explained);
        assert_eq!(verdict_of(false, None, None, &o), Verdict::Unexplained);
        let not_named = Candidate { naming: naming::Naming::default(), ..candidate(0.9) };
        assert_eq!(verdict_of(false, Some(&not_named), None, &o), Verdict::Unexplained);
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
    fn only_the_eccentricity_and_the_encoder_error_move_the_rope_alike() {
        assert!(move_the_rope_alike("sheave_eccentricity", "encoder_error"));
        assert!(move_the_rope_alike("encoder_error", "sheave_eccentricity"));
        assert!(!move_the_rope_alike("encoder_error", "encoder_error"));
        assert!(!move_the_rope_alike("sheave_eccentricity", "sheave_eccentricity + encoder_error"));
        assert!(!move_the_rope_alike("sheave_eccentricity", "coulomb_guide_friction"));
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
