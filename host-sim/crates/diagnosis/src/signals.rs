//! The signals the gap is measured on, along the signal chain of the drive:
//! the machine torque from the phase currents (electrical), the
//! drive's shaft speed estimate (shaft), the accelerations (mechanical).
//! Measured and simulated recordings go through the same code: decimated to
//! the analysis rate, cut into travel phases, with the sensor noise density
//! estimated from the measured recording's high band.

use std::ops::Range;

use crate::error::{Context, Result};

use crate::identify::release_index;
use crate::travel_signals::{travel_torque, TravelTorque};
use dsp::{decimate, travel_phases, welch_psd};
use plant::free_decay::eqn9_first_frequency_hz;
use recording::{Recording, RecordingKind, ACC_CAR, ACC_CW, ACC_MACHINE};
use rig_config::RigConfig;

/// Lowest sample rate the gap is measured at, Hz: recordings are decimated
/// by the largest whole factor that keeps at least this rate, so that the
/// decimation filter is flat up to the top band (1 kHz). Covers the rope
/// and car-frame modes with room to spare.
pub const ANALYSIS_RATE_HZ: f64 = 4000.0;

/// Cycles of the first mode (Eqn 9, at the rig's EA) after a free decay's
/// release before its comparison starts. How the hold lets go (a latch, a
/// cut wire, a force ramped off, the rope's own masses released out of
/// their static shape) is the test's, not the rig's, and every rig does it
/// its own way; the release's transient is over within a cycle or two,
/// the free ringing that follows is the chain's. The comparison's first
/// segment opens there (its window is zero at the start), so neither the
/// release's step nor the pre-trigger before it enters the spectra.
pub const DECAY_SETTLE_CYCLES: f64 = 2.0;

/// One signal of the chain, in signal-chain order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Channel {
    /// Machine torque from the phase currents (dq0, paper 3.3), N m.
    Torque,
    /// The drive's shaft speed estimate, rad/s.
    Speed,
    /// Car acceleration, m/s^2.
    CarAcceleration,
    /// Counterweight acceleration, m/s^2.
    CounterweightAcceleration,
    /// Machine-frame acceleration, m/s^2.
    MachineAcceleration,
}

/// Where along the chain a channel sits.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Subsystem {
    /// Inverter, machine, current control: what the currents show.
    Electrical,
    /// Speed control and the shaft: what the speed estimate shows.
    Drive,
    /// Ropes, car, counterweight: what the accelerometers show.
    Mechanical,
}

impl Channel {
    /// Every channel, in signal-chain order.
    pub const ALL: [Channel; 5] = [
        Channel::Torque,
        Channel::Speed,
        Channel::CarAcceleration,
        Channel::CounterweightAcceleration,
        Channel::MachineAcceleration,
    ];

    /// Name in reports, with its unit.
    pub fn name(self) -> &'static str {
        match self {
            Channel::Torque => "torque_nm",
            Channel::Speed => "speed_radps",
            Channel::CarAcceleration => "acc_car_mps2",
            Channel::CounterweightAcceleration => "acc_cw_mps2",
            Channel::MachineAcceleration => "acc_machine_mps2",
        }
    }

    /// The subsystem the channel observes.
    pub fn subsystem(self) -> Subsystem {
        match self {
            Channel::Torque => Subsystem::Electrical,
            Channel::Speed => Subsystem::Drive,
            _ => Subsystem::Mechanical,
        }
    }
}

/// Part of a recording in time.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// Standstill before the motion (brake lift, pre-torque).
    Start,
    /// Acceleration stage.
    Acceleration,
    /// Constant-speed stage.
    Constant,
    /// Deceleration stage.
    Deceleration,
    /// Standstill after the motion (brake set, the stop).
    Stop,
    /// A free decay.
    Decay,
}

impl Phase {
    /// Name in reports.
    pub fn name(self) -> &'static str {
        match self {
            Phase::Start => "start",
            Phase::Acceleration => "acceleration",
            Phase::Constant => "constant_speed",
            Phase::Deceleration => "deceleration",
            Phase::Stop => "stop",
            Phase::Decay => "decay",
        }
    }
}

/// The chain's signals of one recording at the analysis rate.
#[derive(Clone, Debug)]
pub struct ChainSignals {
    /// Sample rate, Hz.
    pub sample_rate_hz: f64,
    /// The channels present, each one value per sample in its unit.
    pub channels: Vec<(Channel, Vec<f64>)>,
    /// The travel phases (or the decay) as sample ranges.
    pub phases: Vec<(Phase, Range<usize>)>,
    /// One-sided noise density of each channel, unit^2/Hz (measured
    /// recordings; zero for simulations).
    pub noise_density: Vec<(Channel, f64)>,
    /// Shaft angle from the encoder, rad, one value per sample (travels;
    /// empty for decays): the reference of the angle-locked lines.
    pub angle_rad: Vec<f64>,
}

impl ChainSignals {
    /// The factor by which these signals were decimated from a recording
    /// sampled at `recording_rate_hz` (Hz): one of their samples is this
    /// many of the recording's.
    pub fn decimation_from(&self, recording_rate_hz: f64) -> usize {
        (recording_rate_hz / self.sample_rate_hz).round().max(1.0) as usize
    }

    /// The samples of `channel`, if present.
    pub fn channel(&self, channel: Channel) -> Option<&[f64]> {
        self.channels.iter().find(|(c, _)| *c == channel).map(|(_, v)| v.as_slice())
    }

    /// Length in samples.
    pub fn len(&self) -> usize {
        self.channels.first().map_or(0, |(_, v)| v.len())
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Lowest frequency the model has content below, Hz: the noise floor is
/// read above it.
pub const MODEL_CONTENT_TOP_HZ: f64 = 1100.0;

/// The band a channel's noise floor is read in, Hz. An accelerometer's
/// (`below_the_anti_alias`) runs from [`MODEL_CONTENT_TOP_HZ`], where the
/// model has no content, up to where the acquisition's anti-alias filter
/// may start ([`crate::acquisition::ANTI_ALIAS_START_FRACTION`] of the
/// sample rate), when that leaves at least half an
/// octave. Otherwise, and for the drive's signals (the currents carry the
/// current loop's own content up to its bandwidth, kHz), the floor is read
/// from 0.55 of the Nyquist frequency (from 1.1 kHz) to 0.95 of it, or
/// over the top 15 % of the band for recordings sampled under 2800 Hz; an
/// anti-alias filter acting there lowers it (`docs/diagnosis.md`).
pub fn noise_band_hz(sample_rate_hz: f64, below_the_anti_alias: bool) -> (f64, f64) {
    let nyquist = 0.5 * sample_rate_hz;
    let flat_top = crate::acquisition::ANTI_ALIAS_START_FRACTION * sample_rate_hz;
    if below_the_anti_alias && flat_top >= MODEL_CONTENT_TOP_HZ * 2f64.sqrt() {
        (MODEL_CONTENT_TOP_HZ, flat_top.min(0.95 * nyquist))
    } else if nyquist >= 1400.0 {
        ((0.55 * nyquist).max(MODEL_CONTENT_TOP_HZ), 0.95 * nyquist)
    } else {
        (0.85 * nyquist, 0.95 * nyquist)
    }
}

/// Whole decimation factor from `sample_rate_hz` to at least [`ANALYSIS_RATE_HZ`].
pub fn decimation_factor(sample_rate_hz: f64) -> usize {
    ((sample_rate_hz / ANALYSIS_RATE_HZ).floor() as usize).max(1)
}

/// One-sided noise density (unit^2/Hz) of `signal`: the median Welch PSD
/// level over the band `band_hz` (Hz, [`noise_band_hz`]).
pub fn noise_density(signal: &[f64], sample_rate_hz: f64, band_hz: (f64, f64)) -> Result<f64> {
    let segment = (sample_rate_hz / 4.0).round().max(64.0) as usize;
    if signal.len() < segment {
        return Ok(0.0);
    }
    let psd = welch_psd(signal, sample_rate_hz, segment, 0.5)?;
    let (lo, hi) = band_hz;
    let mut band: Vec<f64> =
        psd.frequency_hz.iter().zip(&psd.density).filter(|(f, _)| **f >= lo && **f <= hi).map(|(_, d)| *d).collect();
    if band.is_empty() {
        return Ok(0.0);
    }
    let mid = band.len() / 2;
    let (_, median, _) = band.select_nth_unstable_by(mid, f64::total_cmp);
    Ok(*median)
}

/// The sample (at the recording's rate) where a free decay's comparison
/// starts: [`DECAY_SETTLE_CYCLES`] of the first mode after the release
/// (0 without a car acceleration to find it in).
fn decay_comparison_start(
    rig: &RigConfig,
    car_mps2: &[f64],
    sample_rate_hz: f64,
    mass_kg: f64,
    length_m: f64,
) -> usize {
    let Ok(release) = release_index(car_mps2) else { return 0 };
    let m = &rig.mechanics;
    let f1 = eqn9_first_frequency_hz(m.rope_ea_n, m.rope_mass_per_length_kg_per_m, length_m, mass_kg);
    let settle = if f1.is_finite() && f1 > 0.0 { (DECAY_SETTLE_CYCLES / f1 * sample_rate_hz).round() } else { 0.0 };
    (release + settle as usize).min(car_mps2.len())
}

/// The chain signals of `recording` (`stem` names it in errors): currents
/// turned into the machine torque with the rig's machine, every channel
/// decimated by `factor`, the phases found on the decimated speed; with
/// `measured`, the noise density of every channel from its full-rate samples.
pub fn chain_signals(
    rig: &RigConfig,
    recording: &Recording,
    stem: &str,
    factor: usize,
    measured: bool,
) -> Result<ChainSignals> {
    let torque = travel_torque_of(rig, recording, stem)?;
    chain_signals_on(rig, recording, stem, factor, measured, torque.as_ref())
}

/// A measured recording's chain signals ([`chain_signals`], with the
/// noise densities) and, for a travel, the torque and shaft angle they
/// were derived from, for the steps after the measurement to use instead
/// of deriving them again.
pub fn measured_chain_signals(
    rig: &RigConfig,
    recording: &Recording,
    stem: &str,
    factor: usize,
) -> Result<(ChainSignals, Option<TravelTorque>)> {
    let torque = travel_torque_of(rig, recording, stem)?;
    Ok((chain_signals_on(rig, recording, stem, factor, true, torque.as_ref())?, torque))
}

/// A travel's [`TravelTorque`]; none for a free decay.
fn travel_torque_of(rig: &RigConfig, recording: &Recording, stem: &str) -> Result<Option<TravelTorque>> {
    match recording.meta.kind {
        RecordingKind::Travel { .. } => Ok(Some(travel_torque(rig, recording, stem)?)),
        RecordingKind::FreeDecay { .. } => Ok(None),
    }
}

/// [`chain_signals`] on a travel's `torque` (none for a free decay).
fn chain_signals_on(
    rig: &RigConfig,
    recording: &Recording,
    stem: &str,
    factor: usize,
    measured: bool,
    torque: Option<&TravelTorque>,
) -> Result<ChainSignals> {
    let fs = recording.meta.sample_rate_hz;
    // The full-rate channels, borrowed: decimated into new vectors.
    let mut full: Vec<(Channel, &[f64])> = Vec::new();
    let mut angle: &[f64] = &[];
    let is_travel = torque.is_some();
    if let Some(torque) = torque {
        angle = &torque.shaft_angle_rad;
        full.push((Channel::Torque, &torque.torque_nm));
        full.push((Channel::Speed, &torque.speed_radps));
    }
    for (channel, name) in [
        (Channel::CarAcceleration, ACC_CAR),
        (Channel::CounterweightAcceleration, ACC_CW),
        (Channel::MachineAcceleration, ACC_MACHINE),
    ] {
        if let Some(c) = recording.column(name) {
            full.push((channel, &c.values));
        }
    }
    let compared_from = match recording.meta.kind {
        RecordingKind::FreeDecay { mass_kg, rope_length_m } => {
            let car = full.iter().find(|(c, _)| *c == Channel::CarAcceleration).map(|(_, v)| *v);
            decay_comparison_start(rig, car.unwrap_or(&[]), fs, mass_kg, rope_length_m)
        }
        RecordingKind::Travel { .. } => 0,
    };
    let mut noise = Vec::new();
    if measured {
        for (channel, values) in &full {
            let compared = &values[compared_from.min(values.len())..];
            noise.push((
                *channel,
                noise_density(compared, fs, noise_band_hz(fs, channel.subsystem() == Subsystem::Mechanical))
                    .with_context(|| format!("`{stem}`: noise of {}", channel.name()))?,
            ));
        }
    }
    let rate = fs / factor as f64;
    let mut channels = Vec::new();
    for (channel, values) in full {
        let values = if factor > 1 { decimate(values, factor)? } else { values.to_vec() };
        channels.push((channel, values));
    }
    let len = channels.iter().map(|(_, v)| v.len()).min().unwrap_or(0);
    for (_, v) in channels.iter_mut() {
        v.truncate(len);
    }
    let mut angle_rad: Vec<f64> = angle.iter().step_by(factor).copied().collect();
    angle_rad.truncate(len);
    let phases = if is_travel {
        let speed = channels.iter().find(|(c, _)| *c == Channel::Speed).map(|(_, v)| v.as_slice()).unwrap_or(&[]);
        let p = travel_phases(speed, rate).with_context(|| format!("`{stem}`: travel phases"))?;
        vec![
            (Phase::Start, p.start),
            (Phase::Acceleration, p.acceleration),
            (Phase::Constant, p.constant),
            (Phase::Deceleration, p.deceleration),
            (Phase::Stop, p.stop),
        ]
    } else {
        vec![(Phase::Decay, compared_from.div_ceil(factor).min(len)..len)]
    };
    Ok(ChainSignals { sample_rate_hz: rate, channels, phases, noise_density: noise, angle_rad })
}

#[cfg(test)]
mod tests {
    use super::*;
    use closed_loop::foreign::acquisition::butterworth_lowpass;
    use rand::SeedableRng;
    use rand_distr::Distribution;

    /// White noise of a known density through the steepest anti-alias
    /// filter an acquisition may have (8th-order Butterworth from a fifth
    /// of the sample rate up): the floor read is the noise's own density
    /// within 1 dB at every rate that leaves a band between the model's
    /// content and the filter (from 7.8 kHz). Over the top of the band
    /// instead (0.55-0.95 of Nyquist), the filter is down 44 dB at its
    /// middle (0.375 of the rate: `(0.375 / 0.2)^16`).
    #[test]
    fn the_noise_floor_is_read_below_the_anti_alias_filter() {
        for fs in [8192.0, 10_000.0, 12_800.0, 16_384.0, 25_600.0] {
            let density: f64 = 1.0e-6;
            let normal = rand_distr::Normal::new(0.0, (density * 0.5 * fs).sqrt()).unwrap();
            let mut rng = rand::rngs::StdRng::seed_from_u64(7);
            let mut x: Vec<f64> = (0..(20.0 * fs) as usize).map(|_| normal.sample(&mut rng)).collect();
            for section in butterworth_lowpass(8, 0.2 * fs, fs) {
                section.filter(&mut x);
            }
            let (lo, hi) = noise_band_hz(fs, true);
            let read = noise_density(&x, fs, (lo, hi)).unwrap();
            let error_db = 10.0 * (read / density).log10();
            assert!(error_db.abs() < 1.0, "{fs} Hz: floor {read:.3e} against {density:.1e} ({error_db:+.2} dB)");
            assert!(lo >= MODEL_CONTENT_TOP_HZ && hi <= 0.95 * 0.5 * fs && hi > lo, "{fs} Hz: band {lo}-{hi} Hz");
        }
    }
}
