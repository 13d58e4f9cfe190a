//! Step 2 of the pipeline: each recording measured (its chain signals) and
//! its counterpart made with the calibrated nominal model and its two
//! perturbations: the closed loop with the project's drive or, for travels
//! under another drive ([`crate::drive_finding`]), the mechanics driven by
//! the measured torque ([`driven`]).

use rayon::prelude::*;
use std::sync::Arc;

use crate::drive_finding::DriveModel;
use crate::error::Result;
use crate::identify_dataset::LeftOut;
use crate::signals::{self, decimation_factor, measured_chain_signals, ChainSignals};
#[cfg(doc)]
use crate::simulate;
use crate::simulate::{
    driven_accelerations, driven_counterpart, driven_highpass, driven_signals, driven_stop_brake,
    highpass_accelerations, model_step_s, simulate_counterpart, Counterpart, DriveRecord, DrivenInputs,
};
use crate::travel_readings::TravelReadings;
use crate::{acquisition, drive_law, driven, electrical_lines, transducer, travel_signals};
use plant::effects::Effects;
use recording::{Recording, RecordingKind};
use rig_config::RigConfig;

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
    /// The rig's brake at the end of the travel as the data show it, and
    /// so whether its stop is compared ([`driven::stop_brake`]).
    pub stop_brake: driven::StopBrake,
}

/// One recording made ready for the gap: its measured chain signals and the
/// nominal model's counterpart with its two perturbations.
pub(crate) struct Prepared {
    pub(crate) stem: String,
    pub(crate) measured: ChainSignals,
    pub(crate) nominal: ChainSignals,
    pub(crate) perturbed: Vec<ChainSignals>,
    /// The torque-driven model's response to the current probes' noise in
    /// the measured torque (another draw of it), where the model is driven.
    pub(crate) noise_response: Option<ChainSignals>,
    /// The rig drive's speed loop as identified, or why not, where the
    /// model is driven.
    pub(crate) speed_loop: Option<Result<drive_law::SpeedController, String>>,
    /// The shaft angle's source and alignment, where the model is driven.
    pub(crate) shaft_angle: Option<travel_signals::AngleAlignment>,
    /// The accelerometers' high-pass found, where the model is driven.
    pub(crate) accelerometer_highpass: acquisition::Highpass,
    /// The direct-axis current's lines of the travel, or why not, where the
    /// model is driven ([`electrical_lines::travel_lines`]).
    pub(crate) direct_axis: Option<Result<electrical_lines::TravelLines, String>>,
    /// Simulations run: the nominal model, its perturbations, the
    /// counterpart's alternatives and the noise response.
    pub(crate) simulations: usize,
    /// How the counterpart is made, for the attribution's runs.
    pub(crate) how: Counterpart,
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

/// Step 2, first half: every recording measured, its chain signals and a
/// travel's torque and shaft angle (derived once, handed on to the steps
/// that need them), indexed as `dataset`; what cannot be measured goes to
/// `left_out` with its reason.
pub(crate) fn measure(
    rig: &RigConfig,
    dataset: &[(String, Recording)],
    left_out: &mut Vec<LeftOut>,
) -> (Vec<Option<ChainSignals>>, Vec<Option<travel_signals::TravelTorque>>) {
    let measured: Vec<Result<(ChainSignals, Option<travel_signals::TravelTorque>)>> = dataset
        .par_iter()
        .map(|(stem, recording)| {
            measured_chain_signals(rig, recording, stem, decimation_factor(recording.meta.sample_rate_hz))
        })
        .collect();
    let (mut signals, mut travels) = (Vec::new(), Vec::new());
    for (i, m) in measured.into_iter().enumerate() {
        match m {
            Ok((s, t)) => {
                signals.push(Some(s));
                travels.push(t);
            }
            Err(e) => {
                left_out.push(LeftOut { recording: dataset[i].0.clone(), reason: format!("{e:#}") });
                signals.push(None);
                travels.push(None);
            }
        }
    }
    (signals, travels)
}

/// Step 2, second half: the project's closed loop with the calibrated
/// nominal `model` on every measured recording (`measured`, indexed as
/// `dataset`).
pub(crate) fn run_closed_loop(
    model: &RigConfig,
    dataset: &[(String, Recording)],
    measured: Vec<Option<ChainSignals>>,
) -> Vec<MeasuredRun> {
    measured
        .into_par_iter()
        .enumerate()
        .filter_map(|(index, measured)| {
            let measured = measured?;
            let (stem, recording) = &dataset[index];
            let closed = simulate_counterpart(model, &Effects::none(), recording, stem, model_step_s(model));
            Some(MeasuredRun { index, measured, closed })
        })
        .collect()
}

/// One recording measured and run in the project's closed loop.
pub(crate) struct MeasuredRun {
    /// Its index in the dataset.
    pub(crate) index: usize,
    /// Its chain signals.
    pub(crate) measured: ChainSignals,
    /// The closed loop's run with the calibrated nominal model, or why not.
    pub(crate) closed: Result<ChainSignals>,
}

/// The series that give a travel's true torque under a current-transducer
/// error ([`transducer`]), on the grid of its chain signals `measured`;
/// none when the currents cannot be read again (the torque itself was).
fn transducer_series(
    rig: &RigConfig,
    recording: &Recording,
    stem: &str,
    measured: &ChainSignals,
    torque: &travel_signals::TravelTorque,
) -> Option<transducer::TransducerSeries> {
    let factor = measured.decimation_from(recording.meta.sample_rate_hz);
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

/// The calibrated model and the models at the calibration's uncertainty
/// that make a counterpart's tolerance.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Models<'a> {
    /// The calibrated model.
    pub nominal: &'a RigConfig,
    /// At the uncertainty's two ends.
    pub ends: [&'a RigConfig; 2],
    /// At its two middle points.
    pub middles: [&'a RigConfig; 2],
}

impl<'a> Models<'a> {
    /// `nominal` with its `perturbed` models in the order of
    /// [`crate::calibrate::PERTURBATION_STEPS`] (the ends, then the middle
    /// points: [`crate::calibrate::Calibration::perturbations`]).
    pub fn new(nominal: &'a RigConfig, perturbed: &'a [RigConfig; 4]) -> Self {
        let [up, down, half_up, half_down] = perturbed;
        Self { nominal, ends: [up, down], middles: [half_up, half_down] }
    }

    /// The four perturbed models: the ends, then the middle points.
    pub fn perturbed(&self) -> [&'a RigConfig; 4] {
        [self.ends[0], self.ends[1], self.middles[0], self.middles[1]]
    }
}

/// The model's counterpart of a measured recording, with its two
/// perturbations: the closed loop (the project's drive) or, for travels
/// under another drive, the torque-driven mechanics ([`driven`]); the
/// measured signals reduced to the channels the counterpart has.
pub(crate) fn counterpart(
    models: Models,
    drive: DriveModel,
    stem: &str,
    recording: &Recording,
    mut measured: ChainSignals,
    travel: Option<&travel_signals::TravelTorque>,
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
    let speed_loop = driven.then(|| rig_speed_controller(models.nominal, recording, &measured, &torque, &speed));
    let controller = speed_loop.as_ref().and_then(|found| found.as_ref().ok().copied());
    // The travel's torque and angle, where the model is driven by them.
    let driving = travel.filter(|_| driven);
    let shaft_angle = driving.map(|t| t.angle_alignment.clone());
    let direct_axis = driving.map(|t| {
        electrical_lines::travel_lines_of(recording, stem, t, models.nominal.motor.pole_pairs)
            .map_err(|e| format!("{e:#}"))
    });
    let transducer_lines = match &direct_axis {
        Some(Ok(lines)) => electrical_lines::transducer_torque_lines(&models.nominal.motor, lines),
        _ => Vec::new(),
    };
    let transducer = driving.and_then(|t| transducer_series(models.nominal, recording, stem, &measured, t));
    let readings = Arc::new(TravelReadings::default());
    let drive_record = DriveRecord {
        torque_nm: &torque,
        speed_estimate_radps: &speed,
        controller,
        transducer_lines: &transducer_lines,
        transducer: transducer.as_ref(),
        readings: Some(&readings),
    };
    let none = Effects::none();
    // The nominal torque-driven run, raw: the accelerometers' high-pass
    // belongs to the acquisition and is found from it once, then applied to
    // every run of the recording (this one included).
    let settings = driven::DrivenSettings::default();
    let nominal_driven = driven
        .then(|| driven_accelerations(models.nominal, recording, &measured, drive_record, &settings, &none))
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
        let stop_brake = driven_stop_brake(models.nominal, recording, &measured, drive_record)?;
        let inputs = DrivenInputs {
            measured: measured.clone(),
            torque_nm: torque.clone(),
            speed_estimate_radps: speed.clone(),
            controller,
            transducer_lines: transducer_lines.clone(),
            transducer: transducer.clone(),
            highpass,
            stop_brake,
            readings: readings.clone(),
        };
        // The nominal run shaped as the attribution shapes every effect's
        // (`Counterpart::simulate` -> `driven_counterpart`).
        let how = Counterpart::Driven(Arc::new(inputs));
        (driven_signals(&measured, raw, highpass)?, perturbed, how)
    } else {
        simulated_counterpart(models, drive, recording, stem, &measured, closed)?
    };
    let noise_response = if driven {
        let noisy = with_white_noise(&torque, torque_noise_density, measured.sample_rate_hz, stem);
        let run = driven_counterpart(
            models.nominal,
            recording,
            &measured,
            DriveRecord { torque_nm: &noisy, readings: None, ..drive_record },
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
/// settings): the four perturbed rigs of `models` ([`Models::perturbed`]:
/// the uncertainty's ends and middle points,
/// [`crate::calibrate::PERTURBATION_STEPS`]), the settings' alternatives on
/// the calibrated rig, and the start's alternatives when the recording
/// begins in motion.
fn driven_perturbed(
    models: Models,
    measured: &ChainSignals,
    run: impl Fn(&RigConfig, &driven::DrivenSettings) -> Result<ChainSignals> + Sync,
) -> Result<Vec<ChainSignals>> {
    let settings = driven::DrivenSettings::default();
    let mut runs: Vec<(&RigConfig, driven::DrivenSettings)> = models.perturbed().map(|m| (m, settings)).to_vec();
    runs.extend(driven::DrivenSettings::alternatives().map(|alternative| (models.nominal, alternative)));
    if driven::begins_in_motion(&measured.angle_rad, measured.sample_rate_hz) {
        runs.extend(driven::DrivenSettings::start_alternatives().map(|alternative| (models.nominal, alternative)));
    }
    // In parallel with the other recordings' runs: a long recording's
    // dozen runs need not wait for one thread at the end.
    runs.par_iter().map(|(model, settings)| run(model, settings)).collect()
}

/// The simulated counterpart of a recording (the closed loop's run
/// `closed`, or a free decay): the nominal run, the runs of the perturbed
/// models at the uncertainty's ends ([`Models::ends`]); under
/// another rig's data acquisition, its accelerometers' high-pass found
/// from the decay itself and applied to the model's.
fn simulated_counterpart(
    models: Models,
    drive: DriveModel,
    recording: &Recording,
    stem: &str,
    measured: &ChainSignals,
    closed: Result<ChainSignals>,
) -> Result<(ChainSignals, Vec<ChainSignals>, Counterpart)> {
    let none = Effects::none();
    let run_closed = |model: &RigConfig| simulate_counterpart(model, &none, recording, stem, model_step_s(model));
    let (mut nominal, mut perturbed) = (closed?, vec![run_closed(models.ends[0])?, run_closed(models.ends[1])?]);
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
    let factor = measured.decimation_from(recording.meta.sample_rate_hz);
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
