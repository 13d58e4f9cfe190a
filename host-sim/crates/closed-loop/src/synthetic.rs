//! "Real" recordings made by the full plant: the nominal model with effects
//! of the library switched on, with sensor noise, written in the
//! measurement format. The project's tests and the README's worked example
//! use them as rig data whose truth is known. [`make_foreign_dataset`]
//! records them as a foreign rig would: another drive, another data
//! acquisition (`crate::foreign`).

use drive_core::config::Direction;
use drive_core::{Controller, DriveState};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

use crate::foreign::{simulate_commercial_travel, Acquisition, AnalogSignal, Channel, ForeignError, ForeignRig};
use crate::{simulate_travel, simulate_travel_faulted, FaultHook, SimError, SimOptions, TravelRun, TravelSpec};
use plant::effects::Effects;
use plant::free_decay::{simulate_free_decay_with, FreeDecayError, FreeDecaySpec};
use recording::{
    Column, Recording, RecordingKind, RecordingMeta, ACC_CAR, ACC_CW, ANGLE, I_A, I_B, I_C, REF_SPEED, SPEED, TIME_S,
};
use rig_config::RigConfig;

/// Why a dataset of the project's own rig ([`make_dataset`]) cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// A travel's closed-loop simulation failed.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// A free decay's simulation failed.
    #[error(transparent)]
    Decay(#[from] FreeDecayError),
}

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
pub fn make_dataset(rig: &RigConfig, spec: &DatasetSpec) -> Result<Vec<(String, Recording)>, DatasetError> {
    use rayon::prelude::*;
    let mut rng = StdRng::seed_from_u64(spec.seed);
    let travels: Vec<(f64, Direction)> =
        spec.m_car_kg.iter().flat_map(|&m| [(m, Direction::Up), (m, Direction::Down)]).collect();
    let runs: Vec<Result<(String, Recording), DatasetError>> = travels
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
            let name = travel_stem(m, direction);
            let description = format!("full plant: {}", spec.effects.summary());
            Ok((name, run.to_recording(&travel, rig.mechanics.m_cw_kg, description)))
        })
        .collect();
    let mut out = Vec::new();
    for run in runs {
        let (name, mut recording) = run?;
        recording.columns.retain(|c| recording::KNOWN_COLUMNS.contains(&c.name.as_str()));
        for acc in [ACC_CAR, ACC_CW] {
            add_noise(&mut recording, acc, spec.acc_noise_mps2, &mut rng);
        }
        for i in [I_A, I_B, I_C] {
            add_noise(&mut recording, i, spec.current_noise_a, &mut rng);
        }
        out.push((name, recording));
    }
    for &mass in &spec.decay_masses_kg {
        let decay = decay_spec(rig, spec, mass);
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
        out.push((decay_stem(mass), recording));
    }
    Ok(out)
}

/// The stem of the travel of `m_car_kg` in `direction` in a dataset of
/// [`make_dataset`] or [`make_foreign_dataset`].
pub fn travel_stem(m_car_kg: f64, direction: Direction) -> String {
    format!("travel_{}_m{m_car_kg:.1}", if direction == Direction::Up { "up" } else { "down" })
}

/// The stem of the free decay of `mass_kg` in a dataset.
pub fn decay_stem(mass_kg: f64) -> String {
    format!("decay_m{mass_kg:.1}")
}

/// Every stem of the dataset `spec` describes, before it is simulated.
pub fn dataset_stems(spec: &DatasetSpec) -> Vec<String> {
    let travels = spec.m_car_kg.iter().flat_map(|&m| [travel_stem(m, Direction::Up), travel_stem(m, Direction::Down)]);
    travels.chain(spec.decay_masses_kg.iter().map(|&m| decay_stem(m))).collect()
}

/// Rope elements of the free decays of a foreign rig: with 40 the rope's own
/// first ten or so modes (the second of a 2.5 m rope near 650 Hz) ring
/// within a few percent of the continuous rope's frequencies.
pub const FOREIGN_DECAY_ROPE_ELEMENTS: usize = 40;

/// Rope elements of the decay model (a continuous rope for Eqn 9): the
/// project's datasets and the diagnosis's counterparts of their decays.
pub const DECAY_ROPE_ELEMENTS: usize = 40;

/// Recording after the drive switches off when the foreign acquisition's
/// duration is automatic, s.
pub const FOREIGN_TAIL_S: f64 = 1.0;

/// The recordings of `spec` on `rig` as a foreign rig makes them: the
/// commercial drive instead of the drive core when `foreign.drive` is set,
/// the foreign data acquisition instead of the project's when
/// `foreign.acquisition` is set (stems as [`make_dataset`]'s). Only the
/// columns of the measurement format are written.
///
/// From `spec` come the travels (car masses, up and down between
/// `lw_low_m` and `lw_high_m`), the free decays (masses, rope length, and
/// their duration after the release when the acquisition's duration is
/// automatic), the integration step, the noise seed and the plant's
/// effects. With a foreign acquisition its own sample rate and noise replace
/// `spec.sample_rate_hz`, `spec.acc_noise_mps2` and `spec.current_noise_a`;
/// travels then start [`pre_trigger_s`](crate::foreign::Acquisition::pre_trigger_s) before the motion
/// (the drive entering its travel state; before the travel command the rig
/// is at rest, PWM off, brake applied) and free decays that long before the
/// release of the held mass, whose rope has [`FOREIGN_DECAY_ROPE_ELEMENTS`]
/// elements. With the project's acquisition the recordings are sampled
/// like [`make_dataset`]'s. The noise of each recording is drawn from its
/// own generator (seeded by `spec.seed` and the recording's index), so the
/// result does not depend on the order the travels run in.
///
/// # Errors
/// [`ForeignError`]: a parameter out of range, a combination the
/// simulation cannot represent, or a failed simulation.
pub fn make_foreign_dataset(
    rig: &RigConfig,
    spec: &DatasetSpec,
    foreign: &ForeignRig,
) -> Result<Vec<(String, Recording)>, ForeignError> {
    make_foreign_dataset_hooked(rig, spec, foreign, None)
}

/// Makes a fresh closed-loop hook for each travel of a dataset: something
/// the rig does that no parameter or effect describes (rail joints, a
/// fault).
pub type TravelHooks<'a> = &'a (dyn Fn() -> Box<dyn FaultHook> + Sync);

/// [`make_foreign_dataset`] with every travel run under a hook of `hooks`
/// (none: the rig as it is); the free decays are the rope's alone.
///
/// # Errors
/// As [`make_foreign_dataset`].
pub fn make_foreign_dataset_hooked(
    rig: &RigConfig,
    spec: &DatasetSpec,
    foreign: &ForeignRig,
    hooks: Option<TravelHooks>,
) -> Result<Vec<(String, Recording)>, ForeignError> {
    use rayon::prelude::*;
    foreign.validate()?;
    let travels: Vec<(f64, Direction)> =
        spec.m_car_kg.iter().flat_map(|&m| [(m, Direction::Up), (m, Direction::Down)]).collect();
    let runs: Vec<Result<(String, Recording), ForeignError>> = travels
        .par_iter()
        .enumerate()
        .map(|(index, &(m, direction))| {
            let (lw_start_m, lw_end_m) = match direction {
                Direction::Up => (spec.lw_low_m, spec.lw_high_m),
                Direction::Down => (spec.lw_high_m, spec.lw_low_m),
            };
            let travel = TravelSpec { m_car_kg: m, direction, lw_start_m, lw_end_m };
            let mut rng = recording_rng(spec.seed, index);
            let name = travel_stem(m, direction);
            let mut hook = hooks.map(|make| make());
            let hook = hook.as_mut().map(|h| h.as_mut() as &mut dyn FaultHook);
            let recording = foreign_travel(rig, spec, foreign, &travel, hook, &mut rng)?;
            Ok((name, recording))
        })
        .collect();
    let mut out = Vec::new();
    for run in runs {
        out.push(run?);
    }
    for (i, &mass) in spec.decay_masses_kg.iter().enumerate() {
        let mut rng = recording_rng(spec.seed, travels.len() + i);
        out.push((decay_stem(mass), foreign_decay(rig, spec, foreign, mass, &mut rng)?));
    }
    Ok(out)
}

/// The noise generator of recording `index` of a dataset seeded `seed`.
fn recording_rng(seed: u64, index: usize) -> StdRng {
    StdRng::seed_from_u64(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15).wrapping_add(index as u64))
}

/// What the recordings of a foreign rig say they are.
fn foreign_description(foreign: &ForeignRig, what: &str) -> String {
    let drive = if foreign.drive.is_some() { "commercial drive" } else { "project drive" };
    let daq = if foreign.acquisition.is_some() { "foreign acquisition" } else { "project acquisition" };
    format!("foreign rig ({drive}, {daq}): {what}")
}

/// One travel of a foreign rig.
fn foreign_travel(
    rig: &RigConfig,
    spec: &DatasetSpec,
    foreign: &ForeignRig,
    travel: &TravelSpec,
    hook: Option<&mut dyn FaultHook>,
    rng: &mut StdRng,
) -> Result<Recording, ForeignError> {
    let mut options =
        SimOptions { max_step_s: spec.max_step_s, sample_rate_hz: spec.sample_rate_hz, ..SimOptions::for_rig(rig) };
    options.effects = spec.effects;
    if let Some(acq) = &foreign.acquisition {
        options.sample_rate_hz = acq.analog_rate_hz();
        options.tail_s = if acq.duration_s > 0.0 { acq.duration_s + acq.pre_trigger_s } else { FOREIGN_TAIL_S };
    }
    let run = match &foreign.drive {
        Some(drive) => simulate_commercial_travel(rig, travel, drive, &options, hook)?,
        None => {
            let mut controller = Controller::new(&rig.drive_config());
            simulate_travel_faulted(rig, travel, &options, &mut controller, hook, None, None)?
        }
    };
    let description = foreign_description(foreign, "travel");
    let Some(acq) = &foreign.acquisition else {
        let mut recording = run.to_recording(travel, rig.mechanics.m_cw_kg, description);
        recording.columns.retain(|c| recording::KNOWN_COLUMNS.contains(&c.name.as_str()));
        for acc in [ACC_CAR, ACC_CW] {
            add_noise(&mut recording, acc, spec.acc_noise_mps2, rng);
        }
        for i in [I_A, I_B, I_C] {
            add_noise(&mut recording, i, spec.current_noise_a, rng);
        }
        return Ok(recording);
    };
    let travel_code = f64::from(DriveState::Travel.code());
    let trigger = run.drive_state.iter().position(|&s| s == travel_code).ok_or(ForeignError::NoMotion)?;
    let fs = run.sample_rate_hz;
    let start_s = run.time_s[trigger] - acq.pre_trigger_s;
    let end_s = if acq.duration_s > 0.0 { start_s + acq.duration_s } else { run.duration_s() };
    let count = acq.sample_count(end_s - start_s);
    // Before the travel command the rig is at rest: every signal at its first value.
    let pad = if start_s < 0.0 { (-start_s * fs).ceil() as usize + 4 } else { 0 };
    let signal_start_s = -(pad as f64) / fs;
    let mut record = |values: &[f64], channel: Channel| {
        let mut analog = vec![values.first().copied().unwrap_or(0.0); pad];
        analog.extend_from_slice(values);
        let signal = AnalogSignal { start_s: signal_start_s, rate_hz: fs, values: &analog };
        acq.record(&signal, channel, start_s, count, &mut *rng)
    };
    let currents = recorded_currents_a(&run, acq, &options.effects);
    let columns = vec![
        Column::new(TIME_S, acq.time_column(count)),
        Column::new(ACC_CAR, record(&run.acc_car_mps2, Channel::Accelerometer)),
        Column::new(ACC_CW, record(&run.acc_cw_mps2, Channel::Accelerometer)),
        Column::new(I_A, record(&currents[0], Channel::Current)),
        Column::new(I_B, record(&currents[1], Channel::Current)),
        Column::new(I_C, record(&currents[2], Channel::Current)),
        Column::new(SPEED, record(&run.speed_radps, Channel::Drive)),
        Column::new(ANGLE, record(&run.angle_rad, Channel::Drive)),
        Column::new(REF_SPEED, record(&run.ref_speed_mps, Channel::Drive)),
    ];
    let mut recording = run.to_recording(travel, rig.mechanics.m_cw_kg, description);
    recording.meta.sample_rate_hz = acq.sample_rate_hz;
    recording.columns = columns;
    Ok(recording)
}

/// The phase currents (A, at the run's rate) that `acq` records of `run`:
/// the machine's true currents, or with
/// [`drive_transducer_currents`](crate::foreign::Acquisition::drive_transducer_currents)
/// what the drive's transducers read of them through `effects` (the plant's
/// [`Effects::measured_currents_a`], before the drive's own ADC), the
/// currents the drive regulates.
pub fn recorded_currents_a(run: &TravelRun, acq: &Acquisition, effects: &Effects) -> [Vec<f64>; 3] {
    let mut currents = run.phase_currents_a.clone();
    if acq.drive_transducer_currents {
        let [a, b, c] = &mut currents;
        for k in 0..a.len() {
            [a[k], b[k], c[k]] = effects.measured_currents_a([a[k], b[k], c[k]]);
        }
    }
    currents
}

/// The free decay of `spec` on `rig` for the hanging mass `mass_kg`: the
/// rig's rope and guide damping, released from 2 m/s^2.
fn decay_spec(rig: &RigConfig, spec: &DatasetSpec, mass_kg: f64) -> FreeDecaySpec {
    let m = &rig.mechanics;
    FreeDecaySpec {
        mass_kg,
        rope_length_m: spec.decay_rope_length_m,
        rope_ea_n: m.rope_ea_n,
        rope_mass_per_length_kg_per_m: m.rope_mass_per_length_kg_per_m,
        damping_kg_per_s: m.c_car_kg_per_s,
        initial_acceleration_mps2: 2.0,
        elements: DECAY_ROPE_ELEMENTS,
    }
}

/// One free decay of a foreign rig.
fn foreign_decay(
    rig: &RigConfig,
    spec: &DatasetSpec,
    foreign: &ForeignRig,
    mass_kg: f64,
    rng: &mut StdRng,
) -> Result<Recording, ForeignError> {
    let mut decay = decay_spec(rig, spec, mass_kg);
    let kind = RecordingKind::FreeDecay { mass_kg, rope_length_m: spec.decay_rope_length_m };
    let description = Some(foreign_description(foreign, "free decay, top end of the rope fixed"));
    let Some(acq) = &foreign.acquisition else {
        let acc = simulate_free_decay_with(&decay, &spec.effects, spec.sample_rate_hz, spec.decay_duration_s)?;
        let time = (0..acc.len()).map(|i| i as f64 / spec.sample_rate_hz).collect();
        let mut recording = Recording {
            meta: RecordingMeta { kind, sample_rate_hz: spec.sample_rate_hz, description },
            columns: vec![Column::new(TIME_S, time), Column::new(ACC_CAR, acc)],
        };
        add_noise(&mut recording, ACC_CAR, spec.acc_noise_mps2, rng);
        return Ok(recording);
    };
    decay.initial_acceleration_mps2 = acq.release_acceleration_mps2;
    decay.elements = FOREIGN_DECAY_ROPE_ELEMENTS;
    let fs = acq.analog_rate_hz();
    let pre = acq.pre_trigger_s;
    let after_release_s = if acq.duration_s > 0.0 { acq.duration_s - pre } else { spec.decay_duration_s };
    // The mass is released at t = 0; held still (no acceleration) before.
    let pad = (pre * fs).ceil() as usize + 4;
    let mut analog = vec![0.0; pad];
    if after_release_s > 0.0 {
        analog.extend(simulate_free_decay_with(&decay, &spec.effects, fs, after_release_s + 8.0 / fs)?);
    }
    let signal = AnalogSignal { start_s: -(pad as f64) / fs, rate_hz: fs, values: &analog };
    let count = acq.sample_count(pre + after_release_s);
    let acc = acq.record(&signal, Channel::Accelerometer, -pre, count, rng);
    Ok(Recording {
        meta: RecordingMeta { kind, sample_rate_hz: acq.sample_rate_hz, description },
        columns: vec![Column::new(TIME_S, acq.time_column(count)), Column::new(ACC_CAR, acc)],
    })
}
