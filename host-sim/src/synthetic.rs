//! "Real" recordings made by the full plant: the nominal model with effects
//! of the library switched on, with sensor noise, written in the
//! measurement format. The project's tests and the README's worked example
//! use them as rig data whose truth is known.

use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use shared::config::Direction;

use crate::closed_loop::{simulate_travel, SimOptions, TravelSpec};
use crate::config::RigConfig;
use crate::plant::effects::Effects;
use crate::plant::free_decay::{simulate_free_decay_with, FreeDecaySpec};
use crate::recording::{Column, Recording, RecordingKind, RecordingMeta, ACC_CAR, ACC_CW, I_A, I_B, I_C, TIME_S};

/// What to record.
#[derive(Clone, Debug)]
pub struct DatasetSpec {
    /// Car masses, kg: one travel up and one down for each.
    pub m_car_kg: Vec<f64>,
    /// Counterweight-side rope length at the low end of the travels, m.
    pub lw_low_m: f64,
    /// ... and at the high end, m.
    pub lw_high_m: f64,
    /// Free decays: hanging masses, kg.
    pub decay_masses_kg: Vec<f64>,
    /// Free decays: rope length, m.
    pub decay_rope_length_m: f64,
    /// Free decays: duration, s.
    pub decay_duration_s: f64,
    /// Sample rate of the recordings, Hz.
    pub sample_rate_hz: f64,
    /// Longest integration step of the travels, s.
    pub max_step_s: f64,
    /// RMS white noise on every accelerometer, m/s^2.
    pub acc_noise_mps2: f64,
    /// RMS white noise on every phase-current probe, A.
    pub current_noise_a: f64,
    /// Seed of the noise.
    pub seed: u64,
    /// The effects of the full plant.
    pub effects: Effects,
}

impl DatasetSpec {
    /// The rig's dataset: its four car masses up and down over the full
    /// travel, four decays of the same masses on a 4 m rope, at the rig's
    /// sample rate, 0.01 m/s^2 and 0.02 A of noise.
    pub fn rig(rig: &RigConfig) -> Self {
        Self {
            m_car_kg: rig.mechanics.m_car_kg.clone(),
            lw_low_m: rig.travel.lw_low_m,
            lw_high_m: rig.travel.lw_high_m,
            decay_masses_kg: rig.mechanics.m_car_kg.clone(),
            decay_rope_length_m: 4.0,
            decay_duration_s: 3.0,
            sample_rate_hz: rig.measurement.sample_rate_hz,
            max_step_s: 0.25 / rig.control.current_loop_hz,
            acc_noise_mps2: 0.01,
            current_noise_a: 0.02,
            seed: 1,
            effects: Effects::none(),
        }
    }
}

/// Adds white Gaussian noise of `rms` to column `name` of `recording`.
pub fn add_noise(recording: &mut Recording, name: &str, rms: f64, rng: &mut StdRng) {
    let Ok(normal) = Normal::new(0.0, rms) else { return };
    if rms <= 0.0 {
        return;
    }
    if let Some(c) = recording.columns.iter_mut().find(|c| c.name == name) {
        for v in c.values.iter_mut() {
            *v += normal.sample(rng);
        }
    }
}

/// The recordings of `spec` on `rig` (stems `travel_up_m70.5`,
/// `decay_m33.0`, ...), noise included.
pub fn make_dataset(rig: &RigConfig, spec: &DatasetSpec) -> anyhow::Result<Vec<(String, Recording)>> {
    use rayon::prelude::*;
    let mut rng = StdRng::seed_from_u64(spec.seed);
    let travels: Vec<(f64, Direction)> =
        spec.m_car_kg.iter().flat_map(|&m| [(m, Direction::Up), (m, Direction::Down)]).collect();
    let runs: Vec<anyhow::Result<(String, Recording)>> = travels
        .par_iter()
        .map(|&(m, direction)| {
            let (lw_start_m, lw_end_m) = match direction {
                Direction::Up => (spec.lw_low_m, spec.lw_high_m),
                Direction::Down => (spec.lw_high_m, spec.lw_low_m),
            };
            let travel = TravelSpec { m_car_kg: m, direction, lw_start_m, lw_end_m };
            let options = SimOptions {
                max_step_s: spec.max_step_s,
                sample_rate_hz: spec.sample_rate_hz,
                effects: spec.effects,
                ..SimOptions::for_rig(rig)
            };
            let run = simulate_travel(rig, &travel, &options, None)?;
            let name = format!("travel_{}_m{m:.1}", if direction == Direction::Up { "up" } else { "down" });
            let description = format!("full plant: {}", spec.effects.summary());
            Ok((name, run.to_recording(&travel, rig.mechanics.m_cw_kg, description)))
        })
        .collect();
    let mut out = Vec::new();
    for run in runs {
        let (name, mut recording) = run?;
        recording.columns.retain(|c| crate::recording::KNOWN_COLUMNS.contains(&c.name.as_str()));
        for acc in [ACC_CAR, ACC_CW] {
            add_noise(&mut recording, acc, spec.acc_noise_mps2, &mut rng);
        }
        for i in [I_A, I_B, I_C] {
            add_noise(&mut recording, i, spec.current_noise_a, &mut rng);
        }
        out.push((name, recording));
    }
    let m = &rig.mechanics;
    for &mass in &spec.decay_masses_kg {
        let decay = FreeDecaySpec {
            mass_kg: mass,
            rope_length_m: spec.decay_rope_length_m,
            rope_ea_n: m.rope_ea_n,
            rope_mass_per_length_kg_per_m: m.rope_mass_per_length_kg_per_m,
            damping_kg_per_s: m.c_car_kg_per_s,
            initial_acceleration_mps2: 2.0,
            elements: crate::diagnosis::simulate::DECAY_ROPE_ELEMENTS,
        };
        let acc = simulate_free_decay_with(&decay, &spec.effects, spec.sample_rate_hz, spec.decay_duration_s)?;
        let time = (0..acc.len()).map(|i| i as f64 / spec.sample_rate_hz).collect();
        let mut recording = Recording {
            meta: RecordingMeta {
                kind: RecordingKind::FreeDecay { mass_kg: mass, rope_length_m: spec.decay_rope_length_m },
                sample_rate_hz: spec.sample_rate_hz,
                description: Some(format!("full plant: {}", spec.effects.summary())),
            },
            columns: vec![Column::new(TIME_S, time), Column::new(ACC_CAR, acc)],
        };
        add_noise(&mut recording, ACC_CAR, spec.acc_noise_mps2, &mut rng);
        out.push((format!("decay_m{mass:.1}"), recording));
    }
    Ok(out)
}
