//! The model's counterpart of a recording: the same travel in closed loop
//! (the project's controller on the plant with the given effects), or the
//! same free decay, sampled at the analysis rate.

use std::sync::Arc;

use crate::error::{bail, Context, Result};
use crate::travel_readings::TravelReadings;
use crate::{acquisition, drive_law, driven, signals};

use crate::identify::release_index;
use drive_core::config::Direction;

use super::signals::{chain_signals, decimation_factor, ChainSignals};
use closed_loop::synthetic::DECAY_ROPE_ELEMENTS;
use closed_loop::{simulate_travel, SimOptions, TravelSpec};
use plant::effects::Effects;
use plant::free_decay::{simulate_free_decay_stepped, FreeDecaySpec};
use plant::step_rates::StepRates;
use recording::{CarDirection, Column, Recording, RecordingKind, RecordingMeta, ACC_CAR, TIME_S};
use rig_config::RigConfig;

/// Simulates the counterpart of `measured` (named `stem`) on `rig` with
/// `effects` as chain signals: sampled at the control rate (synchronous with
/// the PWM updates, so the averaged inverter's steps do not alias), then
/// decimated to the analysis rate like the data.
pub fn simulate_counterpart(
    rig: &RigConfig,
    effects: &Effects,
    measured: &Recording,
    stem: &str,
    max_step_s: f64,
) -> Result<ChainSignals> {
    let rate = model_sample_rate_hz(rig);
    let recording = simulate_recording(rig, effects, measured, stem, rate, max_step_s)?;
    chain_signals(rig, &recording, stem, decimation_factor(rate), false)
}

/// Longest integration step of the model's runs, s: one PWM period (the
/// plant still subdivides it for its stiffest mode).
pub fn model_step_s(rig: &RigConfig) -> f64 {
    1.0 / rig.control.current_loop_hz
}

/// Sample rate of the model's runs, Hz: the rig's control rate.
pub fn model_sample_rate_hz(rig: &RigConfig) -> f64 {
    rig.control.current_loop_hz
}

/// As [`simulate_counterpart`], the recording itself, sampled at
/// `sample_rate_hz`, integrated with steps of at most `max_step_s` (travels).
pub fn simulate_recording(
    rig: &RigConfig,
    effects: &Effects,
    measured: &Recording,
    stem: &str,
    sample_rate_hz: f64,
    max_step_s: f64,
) -> Result<Recording> {
    match measured.meta.kind {
        RecordingKind::Travel { m_car_kg, m_cw_kg, direction, lw_start_m, lw_end_m } => {
            let mut rig = rig.clone();
            rig.mechanics.m_cw_kg = m_cw_kg;
            let spec = TravelSpec {
                m_car_kg,
                direction: match direction {
                    CarDirection::Up => Direction::Up,
                    CarDirection::Down => Direction::Down,
                },
                lw_start_m,
                lw_end_m,
            };
            let options = SimOptions { max_step_s, sample_rate_hz, effects: *effects, ..SimOptions::for_rig(&rig) };
            let run = simulate_travel(&rig, &spec, &options, None)
                .with_context(|| format!("`{stem}`: simulating the travel with {}", effects.summary()))?;
            Ok(run.to_recording(&spec, m_cw_kg, format!("model of {stem}")))
        }
        RecordingKind::FreeDecay { mass_kg, rope_length_m } => {
            simulate_decay(rig, effects, measured, stem, sample_rate_hz, mass_kg, rope_length_m)
        }
    }
}

/// The model's counterpart of a free decay `measured` (named `stem`) of
/// `mass_kg` on `rope_length_m`, sampled at `sample_rate_hz`: released
/// where the test was, at the test's level (the RMS of its first second
/// after the release), after the same pre-trigger.
fn simulate_decay(
    rig: &RigConfig,
    effects: &Effects,
    measured: &Recording,
    stem: &str,
    sample_rate_hz: f64,
    mass_kg: f64,
    rope_length_m: f64,
) -> Result<Recording> {
    let acc = measured.column(ACC_CAR).with_context(|| format!("`{stem}`: no {ACC_CAR}"))?;
    let fs = measured.meta.sample_rate_hz;
    let release = release_index(&acc.values).with_context(|| format!("`{stem}`: finding the release"))?;
    let released_s = (acc.values.len() - release) as f64 / fs;
    let m = &rig.mechanics;
    let spec = FreeDecaySpec {
        mass_kg,
        rope_length_m,
        rope_ea_n: m.rope_ea_n,
        rope_mass_per_length_kg_per_m: m.rope_mass_per_length_kg_per_m,
        damping_kg_per_s: m.c_car_kg_per_s,
        initial_acceleration_mps2: 1.0,
        elements: DECAY_ROPE_ELEMENTS,
    };
    // The decay released at `initial_acceleration_mps2` over its first
    // `duration_s` (its samples do not depend on the duration).
    let simulate = |initial_acceleration_mps2: f64, duration_s: f64| {
        let spec = FreeDecaySpec { initial_acceleration_mps2, ..spec };
        simulate_free_decay_stepped(&spec, effects, sample_rate_hz, duration_s, DECAY_STEP_RATES)
            .with_context(|| format!("`{stem}`: simulating the free decay"))
    };
    // The held displacement is the test's, not the model's: the model's
    // decay takes the measured level over its first second.
    let measured_level = first_second_rms(&acc.values[release..], fs);
    let (unit, level) = if amplitude_dependent(effects) {
        // A stiffening rope or dry friction does not scale: the decay is
        // released at the level whose first second matches the test's.
        let peak = acc.values[release..].iter().take((0.05 * fs).ceil() as usize).fold(0.0f64, |m, v| m.max(v.abs()));
        // The search reads each decay's first second only, so it simulates
        // no more; the level found is then simulated over the whole decay
        // (unless the first second was all of it).
        let probe_s = released_s.min(1.0);
        let run = |a: f64| -> Result<(f64, (f64, Vec<f64>))> {
            let v = simulate(a, probe_s)?;
            Ok((first_second_rms(&v, sample_rate_hz), (a, v)))
        };
        let (rms, (released_at, probe)) = released_at_level(run, measured_level, peak)?;
        let decay = if probe_s < released_s { simulate(released_at, released_s)? } else { probe };
        // The remaining (small) difference scaled.
        (decay, measured_level / rms.max(1e-300))
    } else {
        let unit = simulate(1.0, released_s)?;
        let level = measured_level / first_second_rms(&unit, sample_rate_hz).max(1e-300);
        (unit, level)
    };
    let pre_trigger = (release as f64 / fs * sample_rate_hz).round() as usize;
    let values: Vec<f64> = std::iter::repeat_n(0.0, pre_trigger).chain(unit.iter().map(|a| a * level)).collect();
    let time = (0..values.len()).map(|i| i as f64 / sample_rate_hz).collect();
    Ok(Recording {
        meta: RecordingMeta {
            kind: measured.meta.kind.clone(),
            sample_rate_hz,
            description: Some(format!("model of {stem}")),
        },
        columns: vec![Column::new(TIME_S, time), Column::new(ACC_CAR, values)],
    })
}

/// A decay counterpart's RK4 steps: the torque-driven model's bounds
/// ([`crate::driven::MAX_RATE_PER_STEP`] up to the gap measure's top band,
/// [`crate::spectra::HIGHEST_BAND_HZ`], which covers every decay's compared
/// bands; [`crate::driven::MAX_RATE_PER_STEP_ABOVE_BANDS`] for the chain's
/// highest rate): the top modes of the decay's discretised rope (kilohertz)
/// damped numerically, every line below 1 kHz within 1e-4 of a uniformly
/// shorter step.
pub const DECAY_STEP_RATES: StepRates = StepRates {
    within_bands: crate::driven::MAX_RATE_PER_STEP,
    highest: crate::driven::MAX_RATE_PER_STEP_ABOVE_BANDS,
    band_top_hz: crate::spectra::HIGHEST_BAND_HZ,
};

/// RMS of the first second of `v` sampled at `rate_hz` (all of it if shorter).
fn first_second_rms(v: &[f64], rate_hz: f64) -> f64 {
    let v = &v[..(rate_hz as usize).min(v.len())];
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

/// Largest number of decays simulated to find the release level.
const RELEASE_LEVEL_RUNS: usize = 5;

/// Relative tolerance on the first second's RMS when matching the release level.
const RELEASE_LEVEL_TOLERANCE: f64 = 2e-3;

/// The decay released at the acceleration (m/s^2) at which its
/// first-second RMS reaches `target` (the test's), with that RMS: `run(a)`
/// gives a decay released at `a` and its RMS. Secant steps from `start`
/// (the test's first peak), at most [`RELEASE_LEVEL_RUNS`] decays: the RMS
/// grows with the release level (dry friction lowers it by a bounded
/// amount, a stiffening rope changes it smoothly), so the steps converge;
/// the closest decay's RMS and `run`'s other output for it are returned.
fn released_at_level<T>(run: impl Fn(f64) -> Result<(f64, T)>, target: f64, start: f64) -> Result<(f64, T)> {
    let start = if start > 0.0 && start.is_finite() { start } else { 1.0 };
    let mut best = run(start)?;
    if !(target > 0.0 && target.is_finite()) {
        return Ok(best);
    }
    // The last two levels and their RMS (the secant's points): a
    // proportional step first (exact for a linear decay), then secants.
    let (mut a0, mut r0) = (start, best.0);
    let mut a1 = if r0 > 0.0 { a0 * target / r0 } else { 2.0 * a0 };
    for _ in 1..RELEASE_LEVEL_RUNS {
        if (best.0 - target).abs() <= RELEASE_LEVEL_TOLERANCE * target || !(a1 > 0.0 && a1.is_finite()) {
            break;
        }
        let decay = run(a1)?;
        let r1 = decay.0;
        let slope = (r1 - r0) / (a1 - a0);
        let next =
            if slope > 0.0 && slope.is_finite() { a1 + (target - r1) / slope } else { a1 * target / r1.max(1e-300) };
        if (r1 - target).abs() < (best.0 - target).abs() {
            best = decay;
        }
        (a0, r0, a1) = (a1, r1, next.max(0.1 * a1));
    }
    Ok(best)
}

/// Whether `effects` make a free decay's shape depend on its amplitude
/// (a rope stiffening with its instantaneous tension, a force at the
/// guides such as dry friction): then the model's decay is released at the
/// test's level instead of being a scaled unit decay.
fn amplitude_dependent(effects: &Effects) -> bool {
    effects.tension_stiffening.is_some_and(|e| e.alpha != 0.0) || effects.guide_force_n(1.0) != 0.0
}

/// How the model's counterpart of a recording is made, as the diagnosis
/// found it for the nominal model: the attribution makes every effect's
/// counterpart the same way.
#[derive(Clone, Debug)]
pub enum Counterpart {
    /// Simulated ([`simulate_counterpart`]: the travel in closed loop with
    /// the project's drive, or the free decay), its accelerations then
    /// through the rig's accelerometer high-pass `highpass`.
    Simulated {
        /// The accelerometers' high-pass found from the data.
        highpass: acquisition::Highpass,
    },
    /// A travel under another drive: the mechanics driven by its measured
    /// torque ([`driven_counterpart`]).
    Driven(Arc<DrivenInputs>),
}

/// What the torque-driven counterpart of a travel takes from the recording.
#[derive(Clone, Debug)]
pub struct DrivenInputs {
    /// The measured chain signals (accelerations, phases, shaft angle).
    pub measured: ChainSignals,
    /// Machine torque from the measured currents, N m.
    pub torque_nm: Vec<f64>,
    /// The rig drive's speed estimate, rad/s.
    pub speed_estimate_radps: Vec<f64>,
    /// The rig drive's speed loop, where identified.
    pub controller: Option<drive_law::SpeedController>,
    /// The torque lines of the rig drive's current transducers.
    pub transducer_lines: Vec<driven::TransducerTorqueLine>,
    /// The series that give the true torque under a transducer error.
    pub transducer: Option<crate::transducer::TransducerSeries>,
    /// The rig's accelerometer high-pass, found once from the nominal model
    /// ([`driven_highpass`]).
    pub highpass: acquisition::Highpass,
    /// The rig's brake at the end of the travel, read on the nominal
    /// model's chain ([`driven_stop_brake`]).
    pub stop_brake: driven::StopBrake,
    /// What the runs read of the recorded torque and angle, kept across
    /// them.
    pub readings: Arc<TravelReadings>,
}

impl DrivenInputs {
    /// What the drive did, as the torque-driven model takes it.
    pub fn drive_record(&self) -> DriveRecord<'_> {
        DriveRecord {
            torque_nm: &self.torque_nm,
            speed_estimate_radps: &self.speed_estimate_radps,
            controller: self.controller,
            transducer_lines: &self.transducer_lines,
            transducer: self.transducer.as_ref(),
            readings: Some(&self.readings),
        }
    }
}

/// What another drive did in a travel, as the torque-driven model takes it.
#[derive(Clone, Copy, Debug)]
pub struct DriveRecord<'a> {
    /// Machine torque from the measured currents, N m.
    pub torque_nm: &'a [f64],
    /// The rig drive's speed estimate, rad/s.
    pub speed_estimate_radps: &'a [f64],
    /// The rig drive's speed loop, where identified.
    pub controller: Option<drive_law::SpeedController>,
    /// The torque lines of the rig drive's current transducers.
    pub transducer_lines: &'a [driven::TransducerTorqueLine],
    /// The series that give the true torque under a transducer error.
    pub transducer: Option<&'a crate::transducer::TransducerSeries>,
    /// What the runs read of the recorded torque and angle, kept across
    /// them; `None` for a torque that is not the recording's.
    pub readings: Option<&'a TravelReadings>,
}

impl Counterpart {
    /// Whether the recording shows the rig's brake stopping the turning
    /// sheave at the end of the travel, under another drive (the stop is
    /// then compared).
    pub fn shows_brake(&self) -> bool {
        self.stop_brake().is_some_and(|b| b.stops_the_sheave())
    }

    /// The rig's brake at the end of the travel, where the model is driven
    /// by the measured torque.
    pub fn stop_brake(&self) -> Option<driven::StopBrake> {
        match self {
            Counterpart::Driven(inputs) => Some(inputs.stop_brake),
            _ => None,
        }
    }

    /// The counterpart of `measured` (named `stem`) on `rig` with `effects`.
    pub fn simulate(
        &self,
        rig: &RigConfig,
        effects: &Effects,
        measured: &Recording,
        stem: &str,
    ) -> Result<ChainSignals> {
        match self {
            Counterpart::Simulated { highpass } => {
                let mut run = simulate_counterpart(rig, effects, measured, stem, model_step_s(rig))?;
                highpass_accelerations(&mut run, *highpass)?;
                Ok(run)
            }
            Counterpart::Driven(inputs) => driven_counterpart(
                rig,
                measured,
                &inputs.measured,
                inputs.drive_record(),
                inputs.highpass,
                &driven::DrivenSettings::default(),
                effects,
            ),
        }
    }
}

/// The torque-driven car and counterweight accelerations (m/s^2, as the
/// model records them, before the accelerometers' high-pass) of the travel
/// `recording` whose measured chain signals (with the torque and the
/// angle) are `measured`, the model with `effects`
/// ([`driven::holds_effect`]).
pub fn driven_accelerations(
    model: &RigConfig,
    recording: &Recording,
    measured: &ChainSignals,
    drive: DriveRecord,
    settings: &driven::DrivenSettings,
    effects: &Effects,
) -> Result<(Vec<f64>, Vec<f64>)> {
    driven::torque_driven_accelerations(model, &driven_travel(recording, measured, drive)?, settings, effects)
}

/// The rig's brake at the end of the travel `recording` (measured chain
/// signals `measured`) as the recording shows it, read on the chain of
/// `model` ([`driven::stop_brake`]).
pub fn driven_stop_brake(
    model: &RigConfig,
    recording: &Recording,
    measured: &ChainSignals,
    drive: DriveRecord,
) -> Result<driven::StopBrake> {
    driven::stop_brake(model, &driven_travel(recording, measured, drive)?)
}

/// What the torque-driven model takes of the travel `recording` whose
/// measured chain signals are `measured`, and of its drive.
fn driven_travel<'a>(
    recording: &Recording,
    measured: &'a ChainSignals,
    drive: DriveRecord<'a>,
) -> Result<driven::DrivenTravel<'a>> {
    let RecordingKind::Travel { m_car_kg, m_cw_kg, lw_start_m, .. } = recording.meta.kind else {
        bail!("not a travel");
    };
    let phase = |p: signals::Phase| measured.phases.iter().find(|(q, _)| *q == p).map(|(_, r)| r.clone());
    let Some(constant) = phase(signals::Phase::Constant) else {
        bail!("the travel has no constant-speed stage");
    };
    Ok(driven::DrivenTravel {
        m_car_kg,
        m_cw_kg,
        lw_start_m,
        torque_nm: drive.torque_nm,
        shaft_angle_rad: &measured.angle_rad,
        speed_estimate_radps: drive.speed_estimate_radps,
        controller: drive.controller,
        motion: driven::motion_from_angle(&measured.angle_rad, measured.sample_rate_hz),
        constant_speed: constant,
        reference_end: recorded_reference_end(recording, measured),
        sample_rate_hz: measured.sample_rate_hz,
        transducer_lines: drive.transducer_lines,
        transducer: drive.transducer,
        readings: drive.readings,
    })
}

/// Where the speed reference of `recording` ends ([`driven::reference_end`]),
/// as a sample of the measured chain signals `measured`; `None` where the
/// recording has no reference column.
fn recorded_reference_end(recording: &Recording, measured: &ChainSignals) -> Option<usize> {
    let factor = measured.decimation_from(recording.meta.sample_rate_hz);
    let reference = recording.column(recording::REF_SPEED)?;
    driven::reference_end(&reference.values).map(|end| end.div_ceil(factor))
}

/// The rig's accelerometer high-pass ([`acquisition::identify_highpass`])
/// that brings the torque-driven model's car acceleration `model_car`
/// (from [`driven_accelerations`]) closest to the measured one: a property
/// of the acquisition, found once per recording with the nominal model.
pub fn driven_highpass(measured: &ChainSignals, model_car: &[f64]) -> Result<acquisition::Highpass> {
    let measured_car = measured.channel(signals::Channel::CarAcceleration).unwrap_or(&[]);
    acquisition::identify_highpass(measured_car, model_car, measured.sample_rate_hz)
}

/// The torque-driven counterpart of the travel `recording`
/// ([`driven_accelerations`]), its accelerations through the rig's
/// accelerometer high-pass `highpass` ([`driven_signals`]).
pub fn driven_counterpart(
    model: &RigConfig,
    recording: &Recording,
    measured: &ChainSignals,
    drive: DriveRecord,
    highpass: acquisition::Highpass,
    settings: &driven::DrivenSettings,
    effects: &Effects,
) -> Result<ChainSignals> {
    let accelerations = driven_accelerations(model, recording, measured, drive, settings, effects)?;
    driven_signals(measured, accelerations, highpass)
}

/// The torque-driven model's car and counterweight accelerations
/// (`(car, cw)`, from [`driven_accelerations`]) as the rig's acquisition
/// records them: through its accelerometer high-pass `highpass`, on the
/// measured chain signals' phases and angle (the counterweight where the
/// rig records it).
pub fn driven_signals(
    measured: &ChainSignals,
    (car, cw): (Vec<f64>, Vec<f64>),
    highpass: acquisition::Highpass,
) -> Result<ChainSignals> {
    let fs = measured.sample_rate_hz;
    let mut channels = vec![(signals::Channel::CarAcceleration, highpass.apply(&car, fs)?)];
    if measured.channel(signals::Channel::CounterweightAcceleration).is_some() {
        channels.push((signals::Channel::CounterweightAcceleration, highpass.apply(&cw, fs)?));
    }
    Ok(ChainSignals {
        sample_rate_hz: measured.sample_rate_hz,
        channels,
        phases: measured.phases.clone(),
        noise_density: Vec::new(),
        angle_rad: measured.angle_rad.clone(),
    })
}

/// `signals`' accelerations through the high-pass `highpass`.
pub fn highpass_accelerations(signals: &mut ChainSignals, highpass: acquisition::Highpass) -> Result<()> {
    let fs = signals.sample_rate_hz;
    for (channel, values) in signals.channels.iter_mut() {
        if channel.subsystem() == signals::Subsystem::Mechanical {
            *values = highpass.apply(values, fs)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::Cell;

    /// A decay under dry friction: its first-second RMS grows as the
    /// square of a small release level (the friction stops it within a
    /// cycle) and linearly, less a bounded amount, at a large one. The
    /// level is found within the tolerance in at most the runs allowed,
    /// from a start far off on either side.
    #[test]
    fn the_release_level_is_found_where_the_decay_does_not_scale() {
        let rms = |a: f64| 0.35 * a * a / (a + 3.0);
        for start in [0.5, 12.0, 60.0] {
            let runs = Cell::new(0);
            let run = |a: f64| -> Result<(f64, Vec<f64>)> {
                runs.set(runs.get() + 1);
                Ok((rms(a), vec![a]))
            };
            let (level, decay) = released_at_level(run, 3.0, start).unwrap();
            assert!((level - 3.0).abs() <= RELEASE_LEVEL_TOLERANCE * 3.0, "start {start}: level {level}");
            assert!((rms(decay[0]) - level).abs() < 1e-12);
            assert!(runs.get() <= RELEASE_LEVEL_RUNS, "start {start}: {} runs", runs.get());
        }
    }
}
