//! The model's counterpart of a recording: the same travel in closed loop
//! (the project's controller on the plant with the given effects), or the
//! same free decay, sampled at the analysis rate.

use crate::error::{Context, Result};

use crate::identify::release_index;
use drive_core::config::Direction;

use super::signals::{chain_signals, decimation_factor, ChainSignals};
use closed_loop::synthetic::DECAY_ROPE_ELEMENTS;
use closed_loop::{simulate_travel, SimOptions, TravelSpec};
use plant::effects::Effects;
use plant::free_decay::{simulate_free_decay_with, FreeDecaySpec};
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
            let unit = simulate_free_decay_with(&spec, effects, sample_rate_hz, released_s)
                .with_context(|| format!("`{stem}`: simulating the free decay"))?;
            // The held displacement is the test's, not the model's: the
            // model's decay takes the measured level over its first second.
            let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
            let first_s = |v: &[f64], rate: f64| rms(&v[..((rate as usize).min(v.len()))]);
            let level = first_s(&acc.values[release..], fs) / first_s(&unit, sample_rate_hz).max(1e-300);
            let pre_trigger = (release as f64 / fs * sample_rate_hz).round() as usize;
            let values: Vec<f64> =
                std::iter::repeat_n(0.0, pre_trigger).chain(unit.iter().map(|a| a * level)).collect();
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
    }
}
