//! The drive-agnostic counterpart of a travel: the nominal mechanics driven
//! by what the rig's own drive did. The machine torque from the measured
//! currents acts on the sheave together with the rig's torque ripple
//! (angle-locked, paper 3.3); a slow tracking loop on the measured shaft
//! angle keeps the model's rigid-body motion on the measured one (a torque
//! integrated open loop drifts). The brake holds the sheave before the
//! motion; after it the drive holds it (the measured torque, the rig's
//! speed loop answering the model's departures) until the brake takes it
//! where the recording shows that ([`brake_engagement`]). Nothing of the
//! rig's drive is assumed: its gains, speed estimate, pre-torque and start
//! and stop sequence are all in the recording.
//!
//! Below a quarter of the chain's first elastic mode ([`RIGID_FRACTION`])
//! the chain turns as one rigid body, and the car and counterweight
//! accelerations there are the rope's at the sheave, taken from the
//! measured angle (through the effect's kinematics: sheave eccentricity's
//! rope displacement, encoder error's true angle) rather than from the
//! model: what the drive did against the slow ripple orders, and their
//! unknown phases, then no longer blur the once-per-revolution line, where
//! the kinematic effects show.
//!
//! The ripple's phases are not in the rig file. Where the rig's speed loop
//! rejects a ripple order, the currents carry its mirror image: the order's
//! phase is then read from the measured torque's angle-locked line, less
//! the line the drive's own current transducers put there
//! ([`TransducerTorqueLine`]), through the speed loop on the chain
//! ([`crate::ripple_phase`]).

use std::f64::consts::TAU;
use std::ops::Range;
use std::sync::Arc;

use crate::error::{bail, Context, Result};

use super::drive_law::SpeedController;
use super::travel_readings::{BrakeSignals, TrackingReferences, TravelReadings};
use dsp::{central_difference, highpass_zero_phase, lowpass_complement_zero_phase};
use plant::angle::AngleSeries;
use plant::effects::{EffectKind, Effects};
use plant::line::{BrakeAction, Coefficients, Line, Lumped, MAX_NODES};
use plant::mechanics::Chain;
use plant::ripple::RippleTorque;
use plant::step_rates::StepRates;
use plant::ChainParams;
use rig_config::RigConfig;

/// Bandwidth of the tracking loop on the measured shaft angle, Hz: well
/// below the chain's first elastic mode (about 8 Hz and up on the reference
/// rig), so that vibrations come from the torque, not from the tracking;
/// high enough to hold the slow rigid-body motion, including what the rig's
/// speed loop does against the first ripple order (about 1 Hz at rated
/// speed), whose phase the model cannot know.
pub const TRACKING_BANDWIDTH_HZ: f64 = 2.0;
/// Damping ratio of the tracking loop.
pub const TRACKING_DAMPING: f64 = 1.0;
/// The measured angle is low-passed at this frequency before the tracking
/// loop uses it, Hz (encoder quantisation would otherwise reach the torque).
pub const TRACKING_REFERENCE_LOWPASS_HZ: f64 = 5.0;
/// Largest product of the integration step and any rate of the chain up
/// to the compared bands' top (the chain's highest rate is Gershgorin's
/// bound, [`plant::line::Line::omega_max_radps`]) in the torque-driven
/// model and the decay counterparts: a sample is split into as many RK4
/// steps as this needs ([`STEP_RATES`]). One step per sample (4 kHz) put `h omega` near 0.75 for the
/// car-side rope-mass mode (up to about 490 Hz on the reference rig), whose
/// response RK4 then got wrong by enough to leave 6-15 dB of gap in
/// 160-400 Hz on a rig with a stiffer rope and more guide damping.
pub const MAX_RATE_PER_STEP: f64 = 0.25;
/// Largest product of the integration step and the chain's highest rate
/// where that rate lies above the compared bands
/// ([`crate::compare::FOREIGN_TOP_HZ`]): the modes there (a discretised
/// rope's top modes, a clamped sheave's) are not compared, and RK4, stable
/// up to `2 sqrt(2)` (2.83), damps them numerically; [`MAX_RATE_PER_STEP`]
/// still holds for every rate up to the bands' top.
pub const MAX_RATE_PER_STEP_ABOVE_BANDS: f64 = 2.0;

/// The torque-driven model's RK4 steps: [`MAX_RATE_PER_STEP`] up to the
/// bands compared under another drive ([`crate::compare::FOREIGN_TOP_HZ`]),
/// [`MAX_RATE_PER_STEP_ABOVE_BANDS`] for the chain's highest rate.
pub const STEP_RATES: StepRates = StepRates {
    within_bands: MAX_RATE_PER_STEP,
    highest: MAX_RATE_PER_STEP_ABOVE_BANDS,
    band_top_hz: crate::compare::FOREIGN_TOP_HZ,
};

/// What the torque-driven counterpart assumes where the recording is silent:
/// the diagnosis runs it as given and with each moved, so that the gap's
/// tolerance covers what these choices change.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DrivenSettings {
    /// Bandwidth of the tracking loop, Hz.
    pub tracking_bandwidth_hz: f64,
    /// Ripple phases read from the measured torque where the drive rejects
    /// an order ([`crate::ripple_phase::ripple_matched_to_the_drive`]); `false`: the rig file's.
    pub ripple_phases_from_torque: bool,
    /// Added to every ripple order's phase, rad: the rig file gives no
    /// phases, so the tolerance is taken over the phase circle.
    pub ripple_phase_shift_rad: f64,
    /// The rig drive's speed loop, where identified
    /// ([`DrivenTravel::controller`]), answers the model's departures from
    /// the rig's speed estimate: the measured torque plus
    /// `-Kp de - Ki integral(de)`, `de` the model's estimate minus the
    /// rig's. A resonance the drive holds down is held down in the model
    /// too, where the measured torque alone would replay it open loop.
    /// `false`: the measured torque alone.
    pub speed_feedback: bool,
    /// The chain's state at the first sample when the recording begins
    /// with the rig already moving ([`begins_in_motion`]).
    pub start_state: StartState,
}

/// The chain's state at the first sample of a recording that begins with
/// the rig already moving: the rig's brake lifted before the recording
/// started, and how hard that lift jolted the chain (the motor torque then
/// against the out-of-balance torque) is not recorded. The rope-mass
/// modes, lightly damped, ring from it through the whole travel, their
/// acceleration growing as their frequency rises with the shortening rope.
/// The model starts moving with the rig in the quasi-static state of the
/// measured speed (the torque that keeps that speed, `moving_start`); the
/// measured torque acts from the first sample on, through a constant offset
/// where an alternative asks for it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StartState {
    /// No offset: the measured torque's departure from the torque that keeps
    /// the speed jolts the chain at the first sample.
    AsRecorded,
    /// No jolt: the brake lifted against a pre-torque that balanced the load
    /// (offset: the torque that keeps the speed minus the first samples').
    Balanced,
    /// The jolt of a brake lifted at the first sample with no motor torque,
    /// the whole torque that keeps the speed released (offset: minus the
    /// first samples' torque).
    Unheld,
}

/// Span at the start of a recording over which the torque the chain had at
/// its first sample is averaged, s.
pub const START_TORQUE_SPAN_S: f64 = 0.01;

/// Whether the rig is already moving at the recording's first sample
/// (the encoder turns within [`STANDSTILL_WINDOW_S`] of it).
pub fn begins_in_motion(shaft_angle_rad: &[f64], sample_rate_hz: f64) -> bool {
    moving_at_first_sample(&motion_from_angle(shaft_angle_rad, sample_rate_hz))
}

/// Whether `motion` ([`motion_from_angle`]) holds the first sample.
fn moving_at_first_sample(motion: &Range<usize>) -> bool {
    motion.start == 0 && !motion.is_empty()
}

impl Default for DrivenSettings {
    fn default() -> Self {
        Self {
            tracking_bandwidth_hz: TRACKING_BANDWIDTH_HZ,
            ripple_phases_from_torque: true,
            ripple_phase_shift_rad: 0.0,
            speed_feedback: false,
            start_state: StartState::AsRecorded,
        }
    }
}

impl DrivenSettings {
    /// The settings moved within what the data cannot decide: tracking
    /// bandwidth halved and doubled, ripple phases from the rig file and
    /// turned by a quarter, a half and three quarters of a period.
    pub fn alternatives() -> [Self; 7] {
        let d = Self::default();
        let turned = |quarters: f64| Self { ripple_phase_shift_rad: quarters * 0.25 * TAU, ..d };
        [
            Self { tracking_bandwidth_hz: 0.5 * d.tracking_bandwidth_hz, ..d },
            Self { tracking_bandwidth_hz: 2.0 * d.tracking_bandwidth_hz, ..d },
            Self { ripple_phases_from_torque: false, ..d },
            turned(1.0),
            turned(2.0),
            turned(3.0),
            Self { speed_feedback: true, ..d },
        ]
    }

    /// The start states other than the default, for a recording that
    /// begins in motion ([`StartState`]).
    pub fn start_alternatives() -> [Self; 2] {
        let d = Self::default();
        [Self { start_state: StartState::Balanced, ..d }, Self { start_state: StartState::Unheld, ..d }]
    }
}

/// The encoder's resolution as the recorded angle shows it: its smallest
/// step between samples, rad (a tiny value for a smooth angle).
pub fn encoder_step_rad(shaft_angle_rad: &[f64]) -> f64 {
    let step =
        shaft_angle_rad.windows(2).map(|w| (w[1] - w[0]).abs()).filter(|d| *d > 1e-12).fold(f64::INFINITY, f64::min);
    if step.is_finite() {
        step
    } else {
        1e-12
    }
}

/// Half-width of the window over which the shaft angle must change for the
/// rig to count as moving, s.
pub const STANDSTILL_WINDOW_S: f64 = 0.05;

/// The samples in which the shaft turns, from the measured angle (rad) at
/// `sample_rate_hz`: from the first to the last sample at which the angle
/// changes over +-[`STANDSTILL_WINDOW_S`] by more than four of its smallest
/// steps (the encoder's resolution) and at least 1e-4 rad. A drive's speed
/// estimate lags; the encoder tells when the brake holds.
pub fn motion_from_angle(shaft_angle_rad: &[f64], sample_rate_hz: f64) -> Range<usize> {
    let n = shaft_angle_rad.len();
    let threshold = standstill_threshold_rad(shaft_angle_rad);
    let w = standstill_window_samples(sample_rate_hz);
    let moving =
        |k: usize| (shaft_angle_rad[(k + w).min(n - 1)] - shaft_angle_rad[k.saturating_sub(w)]).abs() > threshold;
    let first = (0..n).find(|&k| moving(k));
    let last = (0..n).rev().find(|&k| moving(k));
    match (first, last) {
        (Some(a), Some(b)) => a..b + 1,
        _ => 0..0,
    }
}

/// The change of the shaft angle (rad) over `2 x` [`STANDSTILL_WINDOW_S`]
/// above which the shaft counts as turning: four encoder steps
/// ([`encoder_step_rad`]), at least 0.1 mrad.
fn standstill_threshold_rad(shaft_angle_rad: &[f64]) -> f64 {
    (4.0 * encoder_step_rad(shaft_angle_rad)).max(1e-4)
}

/// [`STANDSTILL_WINDOW_S`] in samples at `sample_rate_hz` (Hz), at least one.
fn standstill_window_samples(sample_rate_hz: f64) -> usize {
    ((STANDSTILL_WINDOW_S * sample_rate_hz).round() as usize).max(1)
}

/// Low-pass of the shaft angle and the torque in which the brake's torque
/// on the sheave is read ([`brake_engagement`]), Hz: a brake that catches a
/// moving sheave stops it within milliseconds, and the encoder's
/// quantisation, twice differentiated, swamps the reading above.
pub const BRAKE_READING_LOWPASS_HZ: f64 = 50.0;
/// The brake's torque counts where it departs from its level at the end of
/// the motion by more than this many times its RMS departure from its mean
/// over the constant-speed stage (the chain's elastic vibration and the
/// ripple, which the rigid chain leaves in the reading).
pub const BRAKE_NOISE_FACTOR: f64 = 4.0;
/// ... and by more than this fraction of the machine torque's RMS over the
/// constant-speed stage (what the drive's torque does at standstill that
/// is not a brake: an encoder count's step, static friction).
pub const BRAKE_TORQUE_FLOOR_FRACTION: f64 = 0.25;
/// Span before the search for the brake over which the brake's reading
/// gives its level at the end of the motion, s: the model's errors of the
/// out-of-balance torque and the damping, which the drive's holding torque
/// shares, cancel.
pub const BRAKE_LEVEL_SPAN_S: f64 = 0.25;

/// The torque on the rigid chain at the sheave (N m, one per sample) that
/// neither the machine nor the nominal chain gives,
/// `J theta'' + c theta' + tau_ob(l_w) - T`, with `J` the rigid chain's inertia
/// ([`rigid_inertia_kg_m2`]), `c` its viscous damping at the sheave,
/// `tau_ob` the out-of-balance torque at the rope length reached and `T`
/// the measured torque, the angle and torque low-passed at
/// [`BRAKE_READING_LOWPASS_HZ`]. Zero while the drive alone moves or
/// holds the chain (up to the model's errors); a brake's torque where it
/// holds the sheave.
pub fn unexplained_torque_nm(params: &ChainParams, travel: &DrivenTravel) -> Result<Vec<f64>> {
    let signals = match travel.readings {
        Some(readings) => readings.brake_signals(|| brake_signals(travel))?,
        None => Arc::new(brake_signals(travel)?),
    };
    let BrakeSignals { angle_rad: angle, torque_nm: torque, speed_radps: speed, acceleration_radps2: acceleration } =
        &*signals;
    let r = params.sheave_radius_m;
    let inertia = rigid_inertia_kg_m2(params);
    let damping = params.c_sheave_nms_per_rad + (params.c_car_kg_per_s + params.c_cw_kg_per_s) * r * r;
    Ok((0..angle.len())
        .map(|k| {
            let out_of_balance = params.out_of_balance_torque_nm(travel.lw_start_m + r * angle[k]);
            inertia * acceleration[k] + damping * speed[k] + out_of_balance - torque[k]
        })
        .collect())
}

/// The travel's shaft angle (from its first sample) and torque low-passed
/// at [`BRAKE_READING_LOWPASS_HZ`], with the angle's speed and
/// acceleration (central differences): what [`unexplained_torque_nm`]
/// reads the brake from.
fn brake_signals(travel: &DrivenTravel) -> Result<BrakeSignals> {
    let n = travel.torque_nm.len().min(travel.shaft_angle_rad.len());
    let fs = travel.sample_rate_hz;
    let theta0 = travel.shaft_angle_rad[0];
    let relative: Vec<f64> = travel.shaft_angle_rad[..n].iter().map(|a| a - theta0).collect();
    let angle_rad = lowpassed(&relative, fs, BRAKE_READING_LOWPASS_HZ).context("low-passing the shaft angle")?;
    let torque_nm =
        lowpassed(&travel.torque_nm[..n], fs, BRAKE_READING_LOWPASS_HZ).context("low-passing the torque")?;
    let speed_radps = central_difference(&angle_rad, fs);
    let acceleration_radps2 = central_difference(&speed_radps, fs);
    Ok(BrakeSignals { angle_rad, torque_nm, speed_radps, acceleration_radps2 })
}

/// The sample at which the rig's brake takes the sheave at the end of the
/// travel, where the recording shows it: the first sample, from
/// `2 x` [`STANDSTILL_WINDOW_S`] before the encoder's standstill on, at
/// which the torque on the sheave that the machine does not give
/// ([`unexplained_torque_nm`]) leaves its level over the
/// [`BRAKE_LEVEL_SPAN_S`] before by more than [`BRAKE_NOISE_FACTOR`] times
/// its RMS departure over the constant-speed stage and
/// [`BRAKE_TORQUE_FLOOR_FRACTION`] of the torque's RMS there, taken back to
/// where the departure was a quarter of that. A brake that catches
/// the sheave still turning stops it faster than the torque can; a drive
/// that hands the load to its brake releases its torque while the sheave
/// stands still. `None`: the drive holds the sheave to the end (or the
/// travel has no constant-speed stage to read the level from).
pub fn brake_engagement(params: &ChainParams, travel: &DrivenTravel) -> Result<Option<usize>> {
    let stage = travel.constant_speed.clone();
    if stage.len() < 2 || travel.motion.is_empty() {
        return Ok(None);
    }
    let unexplained = unexplained_torque_nm(params, travel)?;
    let n = unexplained.len();
    let stage = stage.start.min(n)..stage.end.min(n);
    let mean = |x: &[f64]| x.iter().sum::<f64>() / x.len().max(1) as f64;
    let stage_mean = mean(&unexplained[stage.clone()]);
    let spread = mean(&unexplained[stage.clone()].iter().map(|b| (b - stage_mean).powi(2)).collect::<Vec<_>>()).sqrt();
    let torque_rms = mean(&travel.torque_nm[stage.clone()].iter().map(|t| t * t).collect::<Vec<_>>()).sqrt();
    let threshold = (BRAKE_NOISE_FACTOR * spread).max(BRAKE_TORQUE_FLOOR_FRACTION * torque_rms);
    let fs = travel.sample_rate_hz;
    let w = standstill_window_samples(fs);
    let from = travel.motion.end.saturating_sub(2 * w).max(stage.end).min(n);
    let span = ((BRAKE_LEVEL_SPAN_S * fs).round() as usize).max(1);
    let before = from.saturating_sub(span).max(stage.end).min(from)..from;
    let level = if before.is_empty() { stage_mean } else { mean(&unexplained[before]) };
    let departure = |k: usize| (unexplained[k] - level).abs();
    let Some(first) = (from..n).find(|&k| departure(k) > threshold) else {
        return Ok(None);
    };
    let onset = (from..first).rev().find(|&k| departure(k) <= 0.25 * threshold).map_or(from, |k| k + 1);
    Ok(Some(onset))
}

/// The chain of `rig` with the travel's car and counterweight masses.
fn travel_chain_params(rig: &RigConfig, travel: &DrivenTravel) -> ChainParams {
    let mut params = ChainParams::from_rig(rig, travel.m_car_kg);
    params.m_cw_kg = travel.m_cw_kg;
    params
}

/// How the end of the motion is timed against the brake
/// ([`stop_brake`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum StopClock {
    /// The recorded speed reference's end ([`reference_end`]).
    Reference,
    /// The encoder's standstill ([`motion_from_angle`]); the recording has
    /// no speed reference.
    Encoder,
}

/// The rig's brake at the end of a travel as the recording shows it
/// ([`stop_brake`]).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub enum StopBrake {
    /// No brake found ([`brake_engagement`]): the drive holds the sheave to
    /// the end of the recording.
    NotFound,
    /// The brake takes the turning sheave `at_s` s into the recording; its
    /// clamp then rings with the chain.
    StopsTheSheave {
        /// Where the brake takes the sheave, s.
        at_s: f64,
        /// What the brake is timed against.
        clock: StopClock,
    },
    /// The drive sets the brake on the standing sheave and hands it the
    /// load, `at_s` s into the recording: the drive's own stop sequence.
    HandedOver {
        /// Where the brake takes the load, s.
        at_s: f64,
        /// What the brake is timed against.
        clock: StopClock,
    },
}

impl StopBrake {
    /// Whether the brake stops the turning sheave (the stop is then
    /// compared under another drive).
    pub fn stops_the_sheave(&self) -> bool {
        matches!(self, StopBrake::StopsTheSheave { .. })
    }

    /// In words, for the report.
    pub fn text(&self) -> String {
        let clock = |c: &StopClock| match c {
            StopClock::Reference => "the speed reference's end",
            StopClock::Encoder => "the encoder's standstill (no speed reference recorded)",
        };
        match self {
            StopBrake::NotFound => "no brake found: the drive holds the sheave; the stop is not compared".to_string(),
            StopBrake::StopsTheSheave { at_s, clock: c } => {
                format!("the brake takes the turning sheave at {at_s:.3} s (by {}): the stop is compared", clock(c))
            }
            StopBrake::HandedOver { at_s, clock: c } => format!(
                "the drive hands the load to its brake at {at_s:.3} s (after {}): its own stop sequence, not compared",
                clock(c)
            ),
        }
    }
}

/// The rig's brake at the end of the travel, read on the chain of `rig`
/// with the travel's masses ([`brake_engagement`]): whether it takes a
/// turning sheave, whose clamp then rings with the chain. Where the travel
/// records its speed reference, the brake does when it takes the sheave
/// before the reference's end ([`DrivenTravel::reference_end`]), up to
/// [`STANDSTILL_WINDOW_S`] after it: the drive still commands the motion
/// the brake stops. A drive that sets its brake on the standing sheave
/// after its reference has ended and then releases its torque hands the
/// load over statically, whatever the release turns the sheave through an
/// elastic clamp: that stop is the drive's own sequence. Without a
/// recorded reference, the brake takes a turning sheave when it is found
/// before the encoder's standstill ([`DrivenTravel::motion`]), which a
/// drive that releases its torque slowly into an elastic clamp can also
/// show.
pub fn stop_brake(rig: &RigConfig, travel: &DrivenTravel) -> Result<StopBrake> {
    let Some(brake) = brake_engagement(&travel_chain_params(rig, travel), travel)? else {
        return Ok(StopBrake::NotFound);
    };
    let (clock, stops) = match travel.reference_end {
        Some(end) => (StopClock::Reference, brake <= end + standstill_window_samples(travel.sample_rate_hz)),
        None => (StopClock::Encoder, brake < travel.motion.end),
    };
    let at_s = brake as f64 / travel.sample_rate_hz;
    Ok(if stops { StopBrake::StopsTheSheave { at_s, clock } } else { StopBrake::HandedOver { at_s, clock } })
}

/// The sample after the last at which the speed reference `reference`
/// (any unit) exceeds `1e-6` of its peak: where the drive stops commanding
/// motion. `None` for a reference that never departs from zero.
pub fn reference_end(reference: &[f64]) -> Option<usize> {
    let peak = reference.iter().fold(0.0_f64, |m, r| m.max(r.abs()));
    if peak <= 0.0 || !peak.is_finite() {
        return None;
    }
    reference.iter().rposition(|r| r.abs() > 1e-6 * peak).map(|k| k + 1)
}

/// What the counterpart needs of a travel recording, at one sample rate.
pub struct DrivenTravel<'a> {
    /// Car mass, kg.
    pub m_car_kg: f64,
    /// Counterweight mass, kg.
    pub m_cw_kg: f64,
    /// Counterweight-side rope length at the start, m.
    pub lw_start_m: f64,
    /// Machine torque from the measured currents, N m (positive lifts the car).
    pub torque_nm: &'a [f64],
    /// Measured shaft angle, rad (positive: car up).
    pub shaft_angle_rad: &'a [f64],
    /// The rig drive's own speed estimate, rad/s.
    pub speed_estimate_radps: &'a [f64],
    /// The rig drive's speed loop, when identified
    /// ([`super::drive_law::identify_speed_controller`]).
    pub controller: Option<SpeedController>,
    /// Samples in which the rig moves ([`motion_from_angle`]; outside them
    /// the brake holds the sheave).
    pub motion: Range<usize>,
    /// Samples of the constant-speed stage.
    pub constant_speed: Range<usize>,
    /// The sample at which the recorded speed reference ends
    /// ([`reference_end`]); `None` where the recording has no reference.
    pub reference_end: Option<usize>,
    /// Sample rate, Hz.
    pub sample_rate_hz: f64,
    /// The torque lines of the rig drive's current transducers over the
    /// constant-speed stage (none where the direct-axis current shows none).
    pub transducer_lines: &'a [TransducerTorqueLine],
    /// The series that give the machine's true torque from the recorded
    /// currents under a transducer error (`current_sensor_error`), when
    /// the recorded currents are the drive's own transducer signals.
    pub transducer: Option<&'a crate::transducer::TransducerSeries>,
    /// What the runs read of this recording's torque and angle, kept across
    /// them ([`TravelReadings`]); `None`: every run reads anew.
    pub readings: Option<&'a TravelReadings>,
}

impl<'a> DrivenTravel<'a> {
    /// The same travel with the torque (N m) and the shaft angle (rad)
    /// replaced where given (then nothing is read from the recording's
    /// kept readings).
    fn with<'b>(&'b self, torque_nm: Option<&'b [f64]>, shaft_angle_rad: Option<&'b [f64]>) -> DrivenTravel<'b> {
        let replaced = torque_nm.is_some() || shaft_angle_rad.is_some();
        DrivenTravel {
            readings: if replaced { None } else { self.readings },
            torque_nm: torque_nm.unwrap_or(self.torque_nm),
            shaft_angle_rad: shaft_angle_rad.unwrap_or(self.shaft_angle_rad),
            motion: self.motion.clone(),
            constant_speed: self.constant_speed.clone(),
            ..*self
        }
    }
}

/// An angle-locked line of the torque that the rig drive's current
/// transducers put on the shaft. The drive holds the currents its
/// transducers report; where they report an offset (a vector fixed in the
/// stator) or unequal gains (its reflected part), the machine's currents
/// carry the error's negative in the drive's frame, a vector `e` turning at
/// electrical order 1 or 2 whose quadrature component is its direct one a
/// quarter turn on: as lines in the shaft angle, `Q = j D`. The direct-axis
/// line `D` is measured ([`crate::electrical_lines`]), so the torque line
/// is `K_t j D` (`K_t = 1.5 p psi`), before the drive's speed loop answers
/// it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TransducerTorqueLine {
    /// Mechanical order (the electrical order times the pole pairs).
    pub mechanical_order: f64,
    /// The line as `Re(X e^{j n theta_m})`: `[Re X, Im X]`, N m.
    pub phasor_nm: [f64; 2],
}

/// The rigid chain's inertia at the sheave, kg m^2: the sheave's and every
/// mass the ropes carry (car, counterweight, the ropes) at the sheave's
/// radius.
pub fn rigid_inertia_kg_m2(params: &ChainParams) -> f64 {
    let r = params.sheave_radius_m;
    let masses_kg =
        params.m_car_kg + params.m_cw_kg + params.rope_mass_per_length_kg_per_m * params.rope_total_length_m;
    params.sheave_inertia_kg_m2 + masses_kg * r * r
}

/// The rig drive's speed estimate of the model's shaft, as the identified
/// estimate's dead time and lag make it, and the integral of its departure
/// from the rig's estimate.
struct ModelEstimate {
    /// The estimate, rad/s.
    estimate_radps: f64,
    /// Integral of (model's estimate - rig's estimate), rad.
    departure_integral_rad: f64,
    /// The model's shaft speeds within the dead time, rad/s.
    speeds: std::collections::VecDeque<f64>,
    /// Per-sample decay of the estimate's first-order lag.
    decay: f64,
}

impl ModelEstimate {
    fn new(controller: &SpeedController, fs: f64, start_radps: f64) -> Self {
        let decay = if controller.estimate_lag_s > 0.0 { (-1.0 / (fs * controller.estimate_lag_s)).exp() } else { 0.0 };
        let dead_samples = (controller.estimate_delay_s * fs).round() as usize;
        Self {
            estimate_radps: start_radps,
            departure_integral_rad: 0.0,
            speeds: std::collections::VecDeque::from(vec![start_radps; dead_samples + 1]),
            decay,
        }
    }

    /// At standstill: the estimate is the rig's, nothing departs.
    fn hold(&mut self, rig_estimate_radps: f64) {
        self.estimate_radps = rig_estimate_radps;
        self.departure_integral_rad = 0.0;
        self.speeds.iter_mut().for_each(|v| *v = 0.0);
    }

    /// One sample of `h` s: the model's shaft speed in, the departure from
    /// the rig's estimate integrated.
    fn advance(&mut self, shaft_speed_radps: f64, rig_estimate_radps: f64, h: f64) {
        self.speeds.push_back(shaft_speed_radps);
        let speed = self.speeds.pop_front().unwrap_or(0.0);
        self.departure_integral_rad += (self.estimate_radps - rig_estimate_radps) * h;
        self.estimate_radps = self.decay * self.estimate_radps + (1.0 - self.decay) * speed;
    }
}

impl SpeedController {
    /// The loop's answer (N m) to the model's departure from the rig's
    /// speed estimate `rig_estimate_radps` (rad/s): `-Kp de - Ki integral(de)`.
    fn answer_nm(&self, model: &ModelEstimate, rig_estimate_radps: f64) -> f64 {
        -self.kp_nms_per_rad * (model.estimate_radps - rig_estimate_radps)
            - self.ki_nm_per_rad * model.departure_integral_rad
    }
}

/// Positions (m) and velocities (m/s) of the line's nodes
/// ([`plant::line::Layout`]; the first `nodes` are used).
#[derive(Clone, Copy, Debug, Default)]
struct NodeState {
    position_m: [f64; MAX_NODES],
    velocity_mps: [f64; MAX_NODES],
}

/// RK4 steps per sample of `h` s for `line` on `chain` over the travel
/// whose sheave edge moves `travel_m` (m) from the start: enough for
/// `rates` at the stiffer end of the travel (with the brake's clamp where
/// `clamped`).
fn steps_per_sample(line: &Line, chain: &Chain, travel_m: f64, h: f64, rates: StepRates, clamped: bool) -> usize {
    let omega = [0.0, travel_m].map(|u| line.omega_max_radps(chain, u, clamped)).into_iter().fold(0.0, f64::max);
    rates.steps(omega, h)
}

/// The effects of the library the torque-driven model can hold, as each
/// declares ([`plant::effects::Seen::under_another_drive`]): the mechanical
/// ones of [`Line`] while the rig moves, the encoder's angle error (the
/// model reads the true angle from the recorded one) and the current
/// transducers' errors (the model takes the true torque from the recorded
/// currents, read as the drive's transducer signals: [`crate::transducer`]);
/// not an error the recorded currents carry themselves. The brake's clamp
/// acts once the brake holds, at standstill, where another drive's own
/// sequence is not compared; only where a recording shows the brake
/// stopping the turning sheave ([`stop_brake`]: `brake_seen`)
/// is its stop compared, and the clamp held there.
pub fn holds_effect(kind: EffectKind, brake_seen: bool) -> bool {
    kind.seen().under_another_drive || (kind == EffectKind::BrakeStop && brake_seen)
}

/// Car and counterweight accelerations (m/s^2, positive up) of the chain
/// of `rig` with the mechanical `effects` ([`Line`]; the nominal 5-DOF
/// chain without them) driven by the measured torque of `travel` plus the
/// ripple (RK4, [`STEP_RATES`] steps per sample at least, the
/// torque linear between samples). With `encoder_error` the recorded angle
/// is taken back to the true one first.
pub fn torque_driven_accelerations(
    rig: &RigConfig,
    travel: &DrivenTravel,
    settings: &DrivenSettings,
    effects: &Effects,
) -> Result<(Vec<f64>, Vec<f64>)> {
    torque_driven_accelerations_with(rig, travel, settings, effects, STEP_RATES)
}

/// The true shaft angle (rad) from the recorded one under `effects`'
/// encoder error (`theta_m - a sin(theta_m + phase)`, first order in `a`).
fn true_shaft_angle_rad(recorded_rad: &[f64], effects: &Effects) -> Option<Vec<f64>> {
    let e = effects.encoder_error.as_ref()?;
    Some(recorded_rad.iter().map(|&t| t - e.eccentricity_rad * (t + e.phase_rad).sin()).collect())
}

/// The torque the shaft got (N m) when `effects` hold a current-sensor
/// error and the travel's currents are the drive's transducer signals;
/// `None`: the recorded torque is the shaft's.
fn true_torque_nm(travel: &DrivenTravel, effects: &Effects) -> Option<Vec<f64>> {
    match (&effects.current_sensor_error, travel.transducer) {
        (Some(error), Some(series)) => Some(series.true_torque_nm(travel.torque_nm, error)),
        _ => None,
    }
}

/// An error naming the time `t_s` (s) when the packed `state` is not all
/// finite: the model diverged.
fn check_finite(state: &[f64], t_s: f64) -> Result<()> {
    if !state.iter().all(|x| x.is_finite()) {
        bail!("the torque-driven model diverged at t = {t_s:.3} s");
    }
    Ok(())
}

/// The shaft's ripple torque the model adds to the measured torque: the
/// rig's, its phases matched to the drive's torque when `settings` say so
/// (less the torque `transducer_error_nm` (N m) a hypothesised transducer
/// error adds, as the drive answers it), shifted by the settings' phase.
fn ripple_of(
    rig: &RigConfig,
    travel: &DrivenTravel,
    settings: &DrivenSettings,
    transducer_error_nm: Option<&[f64]>,
) -> RippleTorque {
    let mut ripple = if settings.ripple_phases_from_torque {
        crate::ripple_phase::ripple_matched_to_the_drive(rig, travel, transducer_error_nm)
    } else {
        RippleTorque::from_rig(&rig.ripple)
    };
    ripple.harmonics.iter_mut().for_each(|h| h.phase_rad += settings.ripple_phase_shift_rad);
    ripple
}

/// The tracking loop's gains for `bandwidth_hz` (Hz): accelerations per
/// metre (1/s^2) and per metre per second (1/s) of error.
fn tracking_gains(bandwidth_hz: f64) -> (f64, f64) {
    let wb = TAU * bandwidth_hz;
    (wb * wb, 2.0 * TRACKING_DAMPING * wb)
}

/// The chain's state at the first sample and the torque offset (N m)
/// applied while it moves: at rest without either, unless the recording
/// begins in motion; then the chain starts moving with the rig in the
/// quasi-static state of its speed `speed_mps` (m/s), jolted as the start
/// state says (what the rig's brake lift left before the recording is not
/// recorded).
fn start_state(
    line: &Line,
    chain: &Chain,
    travel: &DrivenTravel,
    settings: &DrivenSettings,
    speed_mps: f64,
) -> (NodeState, f64) {
    if !moving_at_first_sample(&travel.motion) {
        return (NodeState::default(), 0.0);
    }
    let n = travel.torque_nm.len().min(travel.shaft_angle_rad.len());
    let span = ((START_TORQUE_SPAN_S * travel.sample_rate_hz).round() as usize).clamp(1, n);
    let first_nm = travel.torque_nm[..span].iter().sum::<f64>() / span as f64;
    let (state, needed_nm) = moving_start(line, chain, speed_mps, first_nm);
    let offset_nm = match settings.start_state {
        StartState::AsRecorded => 0.0,
        StartState::Balanced => needed_nm - first_nm,
        StartState::Unheld => -first_nm,
    };
    (state, offset_nm)
}

/// How the sheave is held at one sample of the travel.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Hold {
    /// Before the motion: the brake holds it (rigid, as in the nominal
    /// plant; the brake's lift is not compared).
    BeforeMotion,
    /// The machine torque drives it, with the tracking loop; `at_rest`:
    /// after the motion, where the drive holds it at standstill with its
    /// speed loop.
    Drive {
        /// After the motion.
        at_rest: bool,
    },
    /// The brake has taken it at the end of the travel
    /// ([`brake_engagement`]): rigid, or through the clamp of `brake_stop`.
    Brake,
}

/// Who holds the sheave when: the motion (from the encoder) and the
/// sample the brake takes it at the end, if it does.
struct StopSequence {
    motion: Range<usize>,
    brake: Option<usize>,
}

impl Hold {
    /// What the brake does to the sheave, clamped at `clamp` (rad) with
    /// `brake_stop` once the brake has taken it.
    fn brake(self, clamp: Option<f64>) -> BrakeAction {
        match (self, clamp) {
            (Hold::Drive { .. }, _) => BrakeAction::Released,
            (Hold::Brake, Some(angle_rad)) => BrakeAction::Clamped { angle_rad },
            _ => BrakeAction::Held,
        }
    }

    /// The rig drive's speed loop acting on the model: at rest after the
    /// motion where identified, in the motion where the settings ask for it.
    fn speed_loop(self, travel: &DrivenTravel, settings: &DrivenSettings) -> SpeedController {
        match self {
            Hold::Drive { at_rest: true } => travel.controller.unwrap_or_default(),
            Hold::Drive { at_rest: false } if settings.speed_feedback => travel.controller.unwrap_or_default(),
            _ => SpeedController::default(),
        }
    }
}

impl StopSequence {
    fn at(&self, k: usize) -> Hold {
        if self.motion.is_empty() || k < self.motion.start {
            Hold::BeforeMotion
        } else if self.brake.is_some_and(|b| k >= b) {
            Hold::Brake
        } else {
            Hold::Drive { at_rest: k >= self.motion.end }
        }
    }
}

/// [`torque_driven_accelerations`] with the step's `rates` in place of
/// [`STEP_RATES`].
///
/// While the machine torque drives the chain, the tracking loop acts on
/// the rigid-body coordinate (the mass-weighted mean of the line's
/// displacements) as a force spread in proportion to mass: it moves the
/// rigid-body mode alone and neither drives nor damps the elastic modes.
/// Before the motion the brake holds the sheave (rigid, as in the nominal
/// plant). After the motion the drive holds it, its speed loop (where
/// identified) answering the model's departures from the rig's speed
/// estimate (`-Kp de - Ki integral(de)`, `de` the model's estimate minus
/// the rig's), until the brake takes it where the recording shows it
/// ([`brake_engagement`]): from there the sheave is held rigidly, or with
/// `brake_stop` clamped at the angle it has then, the measured torque (the
/// drive's release) acting on it. The same speed loop acts during the
/// motion when the settings ask for it.
fn torque_driven_accelerations_with(
    rig: &RigConfig,
    travel: &DrivenTravel,
    settings: &DrivenSettings,
    effects: &Effects,
    rates: StepRates,
) -> Result<(Vec<f64>, Vec<f64>)> {
    let corrected = true_shaft_angle_rad(travel.shaft_angle_rad, effects);
    let true_torque = true_torque_nm(travel, effects);
    let transducer_error_nm: Option<Vec<f64>> =
        true_torque.as_ref().map(|t| t.iter().zip(travel.torque_nm).map(|(t, r)| t - r).collect());
    let travel = &travel.with(true_torque.as_deref(), corrected.as_deref());
    let n = travel.torque_nm.len().min(travel.shaft_angle_rad.len());
    if n < 2 {
        bail!("the travel has {n} samples; expected at least 2");
    }
    let (fs, r) = (travel.sample_rate_hz, rig.mechanics.sheave_radius_m);
    let params = travel_chain_params(rig, travel);
    let sequence = StopSequence { motion: travel.motion.clone(), brake: brake_engagement(&params, travel)? };
    let references = match travel.readings {
        Some(readings) => readings
            .tracking(sequence.brake, r, || tracking_references(&travel.shaft_angle_rad[..n], sequence.brake, fs, r))?,
        None => Arc::new(tracking_references(&travel.shaft_angle_rad[..n], sequence.brake, fs, r)?),
    };
    let (reference, tracked) = &*references;
    let chain = Chain::new(params, travel.lw_start_m);
    let line = Line::new(effects);
    let (layout, nodes) = (line.layout, line.layout.nodes);
    let ripple = ripple_of(rig, travel, settings, transducer_error_nm.as_deref());
    let tracking = tracking_gains(settings.tracking_bandwidth_hz);
    let (h, theta0) = (1.0 / fs, travel.shaft_angle_rad[0]);
    let moved_m = (travel.shaft_angle_rad[n - 1] - theta0) * r;
    // The clamp of `brake_stop` stiffens the line only once the brake has
    // taken the sheave: before, the line's own rates set the step.
    let free_steps = steps_per_sample(&line, &chain, moved_m, h, rates, false);
    let clamped_steps = steps_per_sample(&line, &chain, moved_m, h, rates, effects.brake_stop.is_some());
    let (state, offset_nm) = start_state(&line, &chain, travel, settings, reference.1[0]);
    // The clamp's angle once the brake has taken the sheave (`brake_stop`);
    // accelerations at sample k + frac of the packed state `y` into `acc`,
    // the speed loop's answer `feedback_nm` (N m) held over the sample.
    let mut clamp_angle_rad: Option<f64> = None;
    // The line's masses and springs (`step`) are taken at the start of each
    // RK4 step, as the plant's general line takes them: over one step the
    // sheave moves a fraction of a millimetre of metres of rope.
    let deriv = |y: &[f64],
                 k: usize,
                 frac: f64,
                 feedback_nm: f64,
                 clamp: Option<f64>,
                 series: &AngleSeries,
                 step: &Coefficients,
                 total_kg: f64,
                 acc: &mut [f64]| {
        let (position, velocity) = y.split_at(nodes);
        let j = (k + 1).min(n - 1);
        let hold = sequence.at(k);
        let offset = if hold == Hold::BeforeMotion { 0.0 } else { offset_nm };
        let torque = travel.torque_nm[k] + frac * (travel.torque_nm[j] - travel.torque_nm[k]) + offset + feedback_nm;
        let theta = theta0 + position[layout.sheave] / r;
        let shaft = torque + series.ripple_nm(theta, &ripple);
        line.accelerations_with(step, position, velocity, shaft, hold.brake(clamp), 0.0, acc);
        if let Hold::Drive { .. } = hold {
            let (u, v) = (tracked.0[k] + frac * (tracked.0[j] - tracked.0[k]), tracked.1[k]);
            let body =
                tracking_acceleration(&step.lumped.masses_kg[..nodes], total_kg, position, velocity, (u, v), tracking);
            acc[..nodes].iter_mut().for_each(|a| *a += body);
        }
    };
    let (mut car, mut cw) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let mut estimate = ModelEstimate::new(&travel.controller.unwrap_or_default(), fs, travel.speed_estimate_radps[0]);
    // The ripple as a polynomial of the angle about a recent one (refreshed
    // between samples): a few multiply-adds per stage in place of the
    // harmonics' sines.
    let mut series = AngleSeries::default();
    let mut packed = packed_state(&state, nodes);
    let y = &mut packed[..2 * nodes];
    let mut work = [0.0; 5 * 2 * MAX_NODES];
    let mut a = [0.0; MAX_NODES];
    let mut lumped = Lumped::zeroed();
    for k in 0..n {
        series.ensure(theta0 + y[layout.sheave] / r, &ripple, 0.0);
        let hold = sequence.at(k);
        if sequence.brake == Some(k) {
            meet_the_brake(&line, &chain, y, tracked.1[k]);
            clamp_angle_rad = effects.brake_stop.map(|_| y[layout.sheave] / r);
        }
        if !matches!(hold, Hold::Drive { .. }) {
            if clamp_angle_rad.is_none() {
                y[nodes + layout.sheave] = 0.0;
            }
            estimate.hold(travel.speed_estimate_radps[k]);
        }
        let feedback_nm = hold.speed_loop(travel, settings).answer_nm(&estimate, travel.speed_estimate_radps[k]);
        line.lumped_into(&chain, y[layout.sheave], &mut lumped);
        // The sample's masses and springs serve its output and its first step.
        let mut step = line.coefficients(&chain, &lumped);
        let mut total_kg = total_mass_kg(&step.lumped.masses_kg[..nodes]);
        deriv(y, k, 0.0, feedback_nm, clamp_angle_rad, &series, &step, total_kg, &mut a);
        car.push(a[layout.body]);
        cw.push(-a[layout.counterweight()]);
        if k + 1 == n {
            break;
        }
        let steps = if hold == Hold::Brake { clamped_steps } else { free_steps };
        let sub = 1.0 / steps as f64;
        for j in 0..steps {
            let start = j as f64 * sub;
            if j > 0 {
                line.lumped_into(&chain, y[layout.sheave], &mut lumped);
                step = line.coefficients(&chain, &lumped);
                total_kg = total_mass_kg(&step.lumped.masses_kg[..nodes]);
            }
            // The first step starts where the sample's accelerations were taken.
            let first = (j == 0).then_some(&a[..]);
            plant::rk4_second_order_step_from(y, h * sub, &mut work, first, |frac, y, dv| {
                deriv(y, k, start + frac * sub, feedback_nm, clamp_angle_rad, &series, &step, total_kg, dv);
            });
        }
        estimate.advance(y[nodes + layout.sheave] / r, travel.speed_estimate_radps[k], h);
        check_finite(y, k as f64 * h)?;
    }
    let split_hz = RIGID_FRACTION * first_mode_hz(&chain, travel, r);
    let rope = rope_acceleration_mps2(travel, effects, r, &reference.1)?;
    below_from_the_angle((&car, &cw), &rope, fs, split_hz)
}

/// The chain meets the brake at the rig's speed `speed_mps` (m/s, the
/// tracking reference's): the torque-driven rigid-body motion drifts within
/// the tracking loop's bandwidth, and the brake's stop rings in proportion
/// to that speed. Every node of the packed state `y` gets the same change
/// of velocity (the elastic state is kept).
fn meet_the_brake(line: &Line, chain: &Chain, y: &mut [f64], speed_mps: f64) {
    let (nodes, sheave) = (line.layout.nodes, line.layout.sheave);
    let lumped = line.lumped(chain, y[sheave]);
    let shift = speed_mps - mass_weighted_mean(&lumped.masses_kg[..nodes], &y[nodes..2 * nodes]);
    y[nodes..2 * nodes].iter_mut().for_each(|v| *v += shift);
}

/// The tracking references (m, m/s; [`tracking_reference_m`]) of the
/// measured angle `shaft_angle_rad` (rad): as recorded, and the one the
/// tracking loop follows, the angle continued past the brake's sample
/// `brake` ([`continued_past`]) so that its low-pass does not anticipate
/// the brake's stop.
fn tracking_references(shaft_angle_rad: &[f64], brake: Option<usize>, fs: f64, r: f64) -> Result<TrackingReferences> {
    let reference = tracking_reference_m(shaft_angle_rad, fs, r)?;
    let tracked = match brake {
        Some(b) => tracking_reference_m(&continued_past(shaft_angle_rad, b, fs), fs, r)?,
        None => reference.clone(),
    };
    Ok((reference, tracked))
}

/// The shaft angle (rad) as recorded up to sample `b` and from there on
/// turning on at its mean speed over the [`BRAKE_READING_LOWPASS_HZ`]
/// period before `b`: the motion the rig would have had without its brake.
fn continued_past(shaft_angle_rad: &[f64], b: usize, fs: f64) -> Vec<f64> {
    let b = b.min(shaft_angle_rad.len().saturating_sub(1));
    let span = ((fs / BRAKE_READING_LOWPASS_HZ).round() as usize).clamp(1, b.max(1));
    let speed = (shaft_angle_rad[b] - shaft_angle_rad[b.saturating_sub(span)]) / span as f64;
    (0..shaft_angle_rad.len())
        .map(|k| if k <= b { shaft_angle_rad[k] } else { shaft_angle_rad[b] + speed * (k - b) as f64 })
        .collect()
}

/// The acceleration (m/s^2) the tracking force gives every node of the
/// line: the `(kp, kd)` gains (1/s^2, 1/s) on the departure of the line's
/// centre of mass (`masses`, kg, summing to `total_kg`; `position`, m;
/// `velocity`, m/s) from the reference `(u, v)` (m, m/s). Both moments are
/// summed in one pass, each in the nodes' order ([`mass_weighted_mean`]'s
/// values to the bit).
fn tracking_acceleration(
    masses: &[f64],
    total_kg: f64,
    position: &[f64],
    velocity: &[f64],
    (u, v): (f64, f64),
    (kp, kd): (f64, f64),
) -> f64 {
    let (mut at_m, mut moving) = (-0.0, -0.0);
    for ((m, x), w) in masses.iter().zip(position).zip(velocity) {
        at_m += m * x;
        moving += m * w;
    }
    kp * (u - at_m / total_kg) + kd * (v - moving / total_kg)
}

/// The sum of the nodes' `masses` (kg), in their order.
fn total_mass_kg(masses: &[f64]) -> f64 {
    masses.iter().sum()
}

/// The mean of the nodes' `x` weighted by their `masses` (kg): the
/// rigid-body coordinate of positions or velocities.
fn mass_weighted_mean(masses: &[f64], x: &[f64]) -> f64 {
    masses.iter().zip(x).map(|(m, x)| m * x).sum::<f64>() / total_mass_kg(masses)
}

/// The line's state packed for the integrator: the `nodes` positions (m),
/// then their velocities (m/s).
fn packed_state(state: &NodeState, nodes: usize) -> [f64; 2 * MAX_NODES] {
    let mut y = [0.0; 2 * MAX_NODES];
    y[..nodes].copy_from_slice(&state.position_m[..nodes]);
    y[nodes..2 * nodes].copy_from_slice(&state.velocity_mps[..nodes]);
    y
}

/// Below this fraction of the chain's first elastic mode the chain turns as
/// one rigid body: the car and counterweight accelerations there are the
/// rope's at the sheave, from the measured angle.
pub const RIGID_FRACTION: f64 = 0.25;

/// The chain's lowest first elastic mode over the travel (Eqn 10 at the
/// counterweight-side rope lengths of its start and end), Hz.
fn first_mode_hz(chain: &Chain, travel: &DrivenTravel, r: f64) -> f64 {
    let angle = travel.shaft_angle_rad;
    let moved_m = r * (angle[angle.len() - 1] - angle[0]);
    [travel.lw_start_m, travel.lw_start_m + moved_m]
        .iter()
        .map(|&lw| plant::modes::natural_modes(&chain.params, lw).frequencies_hz[1])
        .fold(f64::INFINITY, f64::min)
}

/// The rope's acceleration at the sheave (m/s^2, positive: car up) from the
/// measured (true) shaft angle, low-passed as the tracking reference is:
/// `r theta''`, the rate of the tracking reference's speed
/// (`reference_mps`, [`tracking_reference_m`]), or with sheave eccentricity
/// the second derivative of its rope displacement.
fn rope_acceleration_mps2(travel: &DrivenTravel, effects: &Effects, r: f64, reference_mps: &[f64]) -> Result<Vec<f64>> {
    let fs = travel.sample_rate_hz;
    let Some(e) = effects.sheave_eccentricity.as_ref() else {
        return Ok(central_difference(reference_mps, fs));
    };
    let theta0 = travel.shaft_angle_rad[0];
    let displacement: Vec<f64> = travel.shaft_angle_rad.iter().map(|a| e.rope_displacement_m(r, a - theta0)).collect();
    let smooth = lowpassed_m(&displacement, fs).context("low-passing the rope displacement")?;
    Ok(central_difference(&central_difference(&smooth, fs), fs))
}

/// The model's car and counterweight accelerations above `split_hz` and
/// the rope's below it (complementary zero-phase split; the counterweight
/// moves against the car).
fn below_from_the_angle(
    (car, cw): (&[f64], &[f64]),
    rope: &[f64],
    fs: f64,
    split_hz: f64,
) -> Result<(Vec<f64>, Vec<f64>)> {
    let rope_high = highpass_zero_phase(rope, fs, split_hz).context("splitting the rope's acceleration")?;
    let rope_low: Vec<f64> = rope.iter().zip(&rope_high).map(|(a, h)| a - h).collect();
    let split = |model: &[f64], sign: f64| -> Result<Vec<f64>> {
        let high = highpass_zero_phase(model, fs, split_hz).context("splitting the model's acceleration")?;
        Ok(high.iter().zip(&rope_low).map(|(h, low)| h + sign * low).collect())
    };
    Ok((split(car, 1.0)?, split(cw, -1.0)?))
}

/// The chain moving as one at `speed_mps` (m/s) in the quasi-static state
/// of the shaft torque that keeps it at that speed: every rope stretched by
/// the forces it carries (the nodes' damping and friction, the
/// out-of-balance torque), nothing ringing; the mass-weighted mean
/// displacement zero. Returns that state and that torque (N m), found from
/// the line's node forces at `torque_nm`.
fn moving_start(line: &Line, chain: &Chain, speed_mps: f64, torque_nm: f64) -> (NodeState, f64) {
    let layout = line.layout;
    let nodes = layout.nodes;
    let lumped = line.lumped(chain, 0.0);
    let mut state = NodeState::default();
    state.velocity_mps[..nodes].iter_mut().for_each(|v| *v = speed_mps);
    let mut a = [0.0; MAX_NODES];
    line.accelerations_of(
        chain,
        &lumped,
        &state.position_m,
        &state.velocity_mps,
        torque_nm,
        BrakeAction::Released,
        0.0,
        &mut a,
    );
    // Node forces with no elastic deflection, N; the torque that keeps the
    // speed takes their sum off the sheave.
    let mut forces = [0.0; MAX_NODES];
    (0..nodes).for_each(|i| forces[i] = lumped.masses_kg[i] * a[i]);
    let total: f64 = forces[..nodes].iter().sum();
    forces[layout.sheave] -= total;
    let needed_nm = torque_nm - total * chain.params.sheave_radius_m;
    // No acceleration: the rope between nodes i and i + 1 carries the
    // forces on the nodes up to i.
    let mut carried = 0.0;
    for (i, (force, spring)) in forces.iter().zip(&lumped.springs_n_per_m).take(nodes - 1).enumerate() {
        carried -= force;
        state.position_m[i + 1] = state.position_m[i] + carried / spring;
    }
    let masses = &lumped.masses_kg[..nodes];
    let mean = masses.iter().zip(&state.position_m).map(|(m, x)| m * x).sum::<f64>() / masses.iter().sum::<f64>();
    state.position_m[..nodes].iter_mut().for_each(|x| *x -= mean);
    (state, needed_nm)
}

/// A displacement (m) low-passed at [`TRACKING_REFERENCE_LOWPASS_HZ`].
fn lowpassed_m(displacement_m: &[f64], fs: f64) -> Result<Vec<f64>> {
    lowpassed(displacement_m, fs, TRACKING_REFERENCE_LOWPASS_HZ)
}

/// `x` low-passed at `corner_hz` (zero phase: the signal less its
/// high-passed part).
fn lowpassed(x: &[f64], fs: f64, corner_hz: f64) -> Result<Vec<f64>> {
    Ok(lowpass_complement_zero_phase(x, fs, corner_hz)?)
}

/// The tracking loop's reference: the measured sheave-edge travel (m) from
/// the start, low-passed at [`TRACKING_REFERENCE_LOWPASS_HZ`], and its rate
/// (m/s, central differences).
fn tracking_reference_m(shaft_angle_rad: &[f64], fs: f64, r: f64) -> Result<(Vec<f64>, Vec<f64>)> {
    let theta0 = shaft_angle_rad[0];
    let relative: Vec<f64> = shaft_angle_rad.iter().map(|a| (a - theta0) * r).collect();
    let u = lowpassed_m(&relative, fs).context("low-passing the measured shaft angle")?;
    let v = central_difference(&u, fs);
    Ok((u, v))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A travel of `chain`'s car from the chain's start, the whole of it the
    /// constant-speed stage: measured torque (N m), angle (rad) and speed
    /// estimate (rad/s), the samples in motion, the sample rate (Hz).
    fn travel_of<'a>(
        chain: &Chain,
        (torque_nm, shaft_angle_rad, speed_estimate_radps): (&'a [f64], &'a [f64], &'a [f64]),
        motion: Range<usize>,
        sample_rate_hz: f64,
    ) -> DrivenTravel<'a> {
        DrivenTravel {
            m_car_kg: chain.params.m_car_kg,
            m_cw_kg: chain.params.m_cw_kg,
            lw_start_m: chain.lw_start_m,
            torque_nm,
            shaft_angle_rad,
            speed_estimate_radps,
            controller: None,
            motion,
            constant_speed: 0..torque_nm.len(),
            reference_end: None,
            sample_rate_hz,
            transducer_lines: &[],
            transducer: None,
            readings: None,
        }
    }

    /// The tracking force's one-pass moments give, to the bit, the centre
    /// of mass the nodes' two weighted means give (positions and
    /// velocities of either sign, masses of a rope line and its end masses).
    #[test]
    fn the_tracking_force_is_the_weighted_means_to_the_bit() {
        use rand::{rngs::StdRng, Rng, SeedableRng};
        let mut rng = StdRng::seed_from_u64(11);
        for nodes in [1, 5, 12, MAX_NODES] {
            let masses: Vec<f64> =
                (0..nodes).map(|i| if i % 4 == 0 { 70.5 } else { rng.gen_range(0.05..3.0) }).collect();
            let position: Vec<f64> = (0..nodes).map(|_| rng.gen_range(-0.02..0.02)).collect();
            let velocity: Vec<f64> = (0..nodes).map(|_| rng.gen_range(-1.6..1.6)).collect();
            let (reference, gains) = ((rng.gen_range(-0.02..0.02), rng.gen_range(-1.6..1.6)), (3.9e3, 88.0));
            let both = tracking_acceleration(&masses, total_mass_kg(&masses), &position, &velocity, reference, gains);
            let apart = gains.0 * (reference.0 - mass_weighted_mean(&masses, &position))
                + gains.1 * (reference.1 - mass_weighted_mean(&masses, &velocity));
            assert_eq!(both.to_bits(), apart.to_bits(), "{nodes} nodes: {both} against {apart}");
        }
    }

    /// Two seconds at 0.5 m/s from the rope length of `chain` sampled at
    /// `fs` (Hz): the measured torque (N m) holding the out-of-balance
    /// torque with 2 N m lines at 300 Hz and `second_hz` and a 1 N m line at
    /// 20 Hz, the shaft angle (rad) and the speed estimate (rad/s).
    fn constant_speed_inputs(
        rig: &RigConfig,
        chain: &Chain,
        fs: f64,
        second_hz: f64,
    ) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let n = (2.0 * fs) as usize;
        let r = rig.mechanics.sheave_radius_m;
        let hold = chain.params.out_of_balance_torque_nm(chain.lw_start_m);
        let t = |k: usize| k as f64 / fs;
        let torque = (0..n)
            .map(|k| {
                hold + 2.0 * (TAU * 300.0 * t(k)).sin()
                    + 2.0 * (TAU * second_hz * t(k)).sin()
                    + (TAU * 20.0 * t(k)).sin()
            })
            .collect();
        let angle = (0..n).map(|k| 0.5 * t(k) / r).collect();
        (torque, angle, vec![0.5 / r; n])
    }

    /// The car acceleration of the torque-driven model does not change when
    /// its step is halved: a travel at constant speed driven by a torque
    /// with lines near the car-side rope-mass mode (300 and 450 Hz) and one
    /// near the first mode (20 Hz), at a 4096 Hz analysis rate.
    #[test]
    fn halving_the_step_changes_nothing() {
        let rig = RigConfig::embedded_default().unwrap();
        let (fs, chain) = (4096.0, Chain::new(ChainParams::from_rig(&rig, 70.5), 2.0));
        let (torque, angle, speed) = constant_speed_inputs(&rig, &chain, fs, 450.0);
        let travel = travel_of(&chain, (&torque, &angle, &speed), 0..torque.len(), fs);
        let settings = DrivenSettings::default();
        let run = |rate: f64| {
            let rates =
                StepRates { within_bands: rate, highest: rate.max(MAX_RATE_PER_STEP_ABOVE_BANDS), ..STEP_RATES };
            torque_driven_accelerations_with(&rig, &travel, &settings, &Effects::none(), rates).unwrap().0
        };
        let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        let diff = |a: &[f64], b: &[f64]| rms(&a.iter().zip(b).map(|(x, y)| x - y).collect::<Vec<_>>()) / rms(b);
        let (default, half) = (run(MAX_RATE_PER_STEP), run(0.5 * MAX_RATE_PER_STEP));
        let one_step_per_sample = run(1e3);
        let (d_default, d_one) = (diff(&default, &half), diff(&one_step_per_sample, &half));
        println!("difference from the half step: default {d_default:.2e}, one step per sample {d_one:.2e}");
        assert!(d_default < 1e-3, "default step: {d_default:.2e} of the RMS from the half step");
        // What the split into several steps per sample is for.
        assert!(d_one > 10.0 * d_default, "one step per sample: {d_one:.2e}, default {d_default:.2e}");
    }

    /// A travel whose readings are kept (the brake's signals, the tracking
    /// references, the torque's lines at the rig's ripple orders) gives,
    /// on every run, the accelerations of the travel read anew, to the
    /// bit: under another ripple phase too, and under an encoder error,
    /// whose corrected angle reads its own.
    #[test]
    fn kept_readings_change_no_run() {
        let rig = RigConfig::embedded_default().unwrap();
        let (fs, chain) = (4096.0, Chain::new(ChainParams::from_rig(&rig, 70.5), 2.0));
        let (mut torque, angle, speed) = constant_speed_inputs(&rig, &chain, fs, 450.0);
        // The rig's ripple orders, each at its own phase, for the runs to read.
        for (i, h) in rig.ripple.iter().enumerate() {
            let order = f64::from(h.mechanical_order);
            torque.iter_mut().zip(&angle).for_each(|(t, a)| *t += h.amplitude_nm * (order * a + i as f64).cos());
        }
        let n = torque.len();
        let travel =
            || DrivenTravel { constant_speed: 0..n / 2, ..travel_of(&chain, (&torque, &angle, &speed), 0..n, fs) };
        let readings = TravelReadings::default();
        let (fresh, kept) = (travel(), DrivenTravel { readings: Some(&readings), ..travel() });
        let shifted = DrivenSettings { ripple_phase_shift_rad: 0.7, ..DrivenSettings::default() };
        let mut encoder = Effects::none();
        encoder.encoder_error = Some(plant::effects::EncoderError { eccentricity_rad: 1e-3, phase_rad: 0.4 });
        for settings in [DrivenSettings::default(), shifted] {
            for effects in [Effects::none(), encoder] {
                let anew = torque_driven_accelerations(&rig, &fresh, &settings, &effects).unwrap();
                for _ in 0..2 {
                    assert_eq!(torque_driven_accelerations(&rig, &kept, &settings, &effects).unwrap(), anew);
                }
            }
        }
    }

    /// With the rope in elements the line's top modes lie far above the
    /// compared bands: stepping them at [`MAX_RATE_PER_STEP_ABOVE_BANDS`]
    /// takes a fraction of the steps and leaves the accelerations below the
    /// bands' top where a uniformly short step puts them.
    #[test]
    fn the_modes_above_the_bands_take_a_longer_step() {
        let rig = RigConfig::embedded_default().unwrap();
        let (fs, chain) = (4096.0, Chain::new(ChainParams::from_rig(&rig, 70.5), 2.0));
        let (torque, angle, speed) = constant_speed_inputs(&rig, &chain, fs, 1500.0);
        let travel = travel_of(&chain, (&torque, &angle, &speed), 0..torque.len(), fs);
        let mut effects = Effects::none();
        effects.rope_discretization = Some(plant::effects::RopeDiscretization { elements: 8 });
        let line = Line::new(&effects);
        let omega = line.omega_max_radps(&chain, 0.0, false);
        let uniform = StepRates::uniform(0.5 * MAX_RATE_PER_STEP);
        let (default_steps, uniform_steps) = (STEP_RATES.steps(omega, 1.0 / fs), uniform.steps(omega, 1.0 / fs));
        assert!(4 * default_steps <= uniform_steps, "{default_steps} steps a sample against {uniform_steps}");
        let run = |rates: StepRates| {
            let car =
                torque_driven_accelerations_with(&rig, &travel, &DrivenSettings::default(), &effects, rates).unwrap().0;
            let above = highpass_zero_phase(&car, fs, crate::compare::FOREIGN_TOP_HZ).unwrap();
            car.iter().zip(above).map(|(a, h)| a - h).collect::<Vec<f64>>()
        };
        let (default, fine) = (run(STEP_RATES), run(uniform));
        let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        let diff: Vec<f64> = default.iter().zip(&fine).map(|(a, b)| a - b).collect();
        let d = rms(&diff) / rms(&fine);
        println!("within the bands, {default_steps} against {uniform_steps} steps a sample: {d:.2e} of the RMS");
        assert!(d < 1e-3, "{d:.2e} of the RMS within the bands");
    }

    /// A recording that begins with the rig moving at constant speed under
    /// a torque 20 N m below the out-of-balance torque: as recorded, the
    /// chain rings from that jolt at the first sample; `Balanced` starts
    /// it without a jolt (nothing rings: the torque is constant); `Unheld`
    /// rings from the whole out-of-balance torque. Recordings that begin
    /// at standstill are run as recorded whatever the start state.
    #[test]
    fn the_start_state_sets_the_jolt_of_a_recording_that_begins_in_motion() {
        // No ripple: the torque is constant, only the jolt rings.
        let mut rig = RigConfig::embedded_default().unwrap();
        rig.ripple.clear();
        let fs = 4096.0;
        let n = 4096;
        let r = rig.mechanics.sheave_radius_m;
        let lw = 2.0;
        let chain = Chain::new(ChainParams::from_rig(&rig, 70.5), lw);
        let hold = chain.params.out_of_balance_torque_nm(lw);
        let torque = vec![hold - 20.0; n];
        let angle: Vec<f64> = (0..n).map(|k| 0.5 * k as f64 / fs / r).collect();
        let speed = vec![0.5 / r; n];
        assert!(begins_in_motion(&angle, fs));
        let later: Vec<f64> = (0..n).map(|k| 0.5 * (k.saturating_sub(1024)) as f64 / fs / r).collect();
        assert!(!begins_in_motion(&later, fs), "a recording standing still for 0.25 s begins at standstill");
        let travel = travel_of(&chain, (&torque, &angle, &speed), motion_from_angle(&angle, fs), fs);
        // Elastic vibration of the car above the tracking loop (10 Hz and up)
        // over the first half second, RMS m/s^2.
        let ring = |start_state: StartState, travel: &DrivenTravel| {
            let settings = DrivenSettings { start_state, ..DrivenSettings::default() };
            let car = torque_driven_accelerations(&rig, travel, &settings, &Effects::none()).unwrap().0;
            let high = highpass_zero_phase(&car, fs, 10.0).unwrap();
            (high[..n / 8].iter().map(|x| x * x).sum::<f64>() / (n / 8) as f64).sqrt()
        };
        let (recorded, balanced, unheld) = (
            ring(StartState::AsRecorded, &travel),
            ring(StartState::Balanced, &travel),
            ring(StartState::Unheld, &travel),
        );
        println!(
            "ring over the first 0.5 s: as recorded {recorded:.2e}, balanced {balanced:.2e}, unheld {unheld:.2e} m/s^2"
        );
        assert!(balanced < 1e-3 * recorded, "balanced {balanced:.2e}, as recorded {recorded:.2e}");
        // The ring is linear in the jolt: the torque's departure from the
        // one that keeps the speed as recorded, that whole torque unheld.
        let (_, needed) = moving_start(&Line::new(&Effects::none()), &chain, 0.5, torque[0]);
        let ratio = unheld / recorded;
        let expected = needed.abs() / (needed - torque[0]).abs();
        assert!((ratio / expected - 1.0).abs() < 0.05, "ratio {ratio:.3}, expected {expected:.3}");
        // At standstill at the first sample: no offset.
        let still = DrivenTravel { motion: 100..n, ..travel };
        assert_eq!(ring(StartState::Unheld, &still), ring(StartState::AsRecorded, &still));
    }

    /// Below a quarter of the chain's first mode the car moves with the
    /// rope at the sheave: a measured angle that wobbles at 1 Hz (1 mm at
    /// the sheave's edge) with a constant torque gives the car that wobble's
    /// acceleration, `(2 pi)^2 * 1 mm`, to 2 %, and the counterweight the
    /// opposite; the same wobble at 40 Hz, above the split, does not pass.
    #[test]
    fn below_the_first_mode_the_car_moves_with_the_measured_angle() {
        let mut rig = RigConfig::embedded_default().unwrap();
        rig.ripple.clear();
        let fs = 1024.0;
        let n = 8192;
        let r = rig.mechanics.sheave_radius_m;
        let lw = 2.0;
        let chain = Chain::new(ChainParams::from_rig(&rig, 45.5), lw);
        let torque = vec![chain.params.out_of_balance_torque_nm(lw); n];
        let speed = vec![0.0; n];
        let run = |f_hz: f64| {
            let angle: Vec<f64> = (0..n).map(|k| 1e-3 * (TAU * f_hz * k as f64 / fs).sin() / r).collect();
            let travel = travel_of(&chain, (&torque, &angle, &speed), 0..n, fs);
            let (car, cw) =
                torque_driven_accelerations(&rig, &travel, &DrivenSettings::default(), &Effects::none()).unwrap();
            // The line at f_hz over the middle half, m/s^2.
            let line = |x: &[f64]| {
                let (mut re, mut im) = (0.0, 0.0);
                for (k, v) in x.iter().enumerate().take(3 * n / 4).skip(n / 4) {
                    let (sn, cs) = (TAU * f_hz * k as f64 / fs).sin_cos();
                    re += v * cs;
                    im += v * sn;
                }
                (2.0 * re / (n / 2) as f64, 2.0 * im / (n / 2) as f64)
            };
            (line(&car), line(&cw))
        };
        let ((car_re, car_im), (cw_re, cw_im)) = run(1.0);
        let expected = -(TAU * 1.0).powi(2) * 1e-3;
        println!(
            "1 Hz: car ({car_re:.5}, {car_im:.5}), counterweight ({cw_re:.5}, {cw_im:.5}), rope {expected:.5} m/s^2"
        );
        assert!((car_im / expected - 1.0).abs() < 0.02 && car_re.abs() < 0.02 * expected.abs());
        assert!((cw_im / -expected - 1.0).abs() < 0.02);
        let ((high_re, high_im), _) = run(40.0);
        let rope_40 = (TAU * 40.0).powi(2) * 1e-3;
        println!("40 Hz: car {:.5} of the rope's {rope_40:.3} m/s^2", high_re.hypot(high_im));
        assert!(high_re.hypot(high_im) < 0.05 * rope_40);
    }

    /// A rigid travel of the reference rig's 70.5 kg car at 1 rad/s from
    /// 0.2 s, its torque what the rigid chain needs, ending as `end` says
    /// (`speed` at `t` s, rad/s; `torque` at `t` from the out-of-balance
    /// and damping torque and the rigid chain's inertia torque, N m); the
    /// angle through a 1e-4 rad encoder. Returns where the brake takes the
    /// sheave, s.
    fn brake_found(speed: impl Fn(f64) -> f64, torque: impl Fn(f64, f64, f64) -> f64) -> Option<f64> {
        brake_read(speed, torque, None).0
    }

    /// [`brake_found`], the speed reference ending at `reference_end` s
    /// where given, and whether the brake stops the turning sheave
    /// ([`stop_brake`]).
    fn brake_read(
        speed: impl Fn(f64) -> f64,
        torque: impl Fn(f64, f64, f64) -> f64,
        reference_end: Option<f64>,
    ) -> (Option<f64>, bool) {
        let rig = RigConfig::embedded_default().unwrap();
        let (chain, fs, (torque, angle, estimate)) = rigid_travel(&rig, speed, torque);
        let mut travel = travel_of(&chain, (&torque, &angle, &estimate), motion_from_angle(&angle, fs), fs);
        travel.constant_speed = 500..1900;
        travel.reference_end = reference_end.map(|t| (t * fs).round() as usize);
        let found = brake_engagement(&chain.params, &travel).unwrap().map(|k| k as f64 / fs);
        (found, stop_brake(&rig, &travel).unwrap().stops_the_sheave())
    }

    /// The chain, sample rate (Hz) and the torque (N m), angle (rad) and
    /// speed estimate (rad/s) of [`brake_found`]'s rigid travel.
    #[allow(clippy::type_complexity)]
    fn rigid_travel(
        rig: &RigConfig,
        speed: impl Fn(f64) -> f64,
        torque: impl Fn(f64, f64, f64) -> f64,
    ) -> (Chain, f64, (Vec<f64>, Vec<f64>, Vec<f64>)) {
        let params = ChainParams::from_rig(rig, 70.5);
        let (fs, n, lw) = (1000.0, 5000, 2.0);
        let r = params.sheave_radius_m;
        let speed: Vec<f64> = (0..n).map(|k| speed(k as f64 / fs)).collect();
        let mut exact = vec![0.0; n];
        (1..n).for_each(|k| exact[k] = exact[k - 1] + 0.5 * (speed[k] + speed[k - 1]) / fs);
        let angle: Vec<f64> = exact.iter().map(|a| (a / 1e-4).round() * 1e-4).collect();
        let inertia = rigid_inertia_kg_m2(&params);
        let damping = params.c_sheave_nms_per_rad + (params.c_car_kg_per_s + params.c_cw_kg_per_s) * r * r;
        let torque: Vec<f64> = (0..n)
            .map(|k| {
                let alpha = (speed[(k + 1).min(n - 1)] - speed[k.saturating_sub(1)]) * fs / 2.0;
                let steady = params.out_of_balance_torque_nm(lw + r * exact[k]) + damping * speed[k];
                torque(k as f64 / fs, steady, inertia * alpha)
            })
            .collect();
        (Chain::new(params, lw), fs, (torque, angle, speed))
    }

    /// The brake's clamp changes nothing before the brake takes the sheave:
    /// with the stiffest clamp of `brake_stop`'s range the torque-driven
    /// model moves as with the rigid brake up to the brake, and rings on
    /// the clamp after it.
    #[test]
    fn the_clamp_acts_only_once_the_brake_has_taken_the_sheave() {
        let rig = RigConfig::embedded_default().unwrap();
        let turning = |t: f64| if (0.2..2.0).contains(&t) { 1.0 } else { 0.0 };
        let braked = |_: f64, steady: f64, _: f64| steady;
        let (chain, fs, (torque, angle, estimate)) = rigid_travel(&rig, turning, braked);
        let mut travel = travel_of(&chain, (&torque, &angle, &estimate), motion_from_angle(&angle, fs), fs);
        travel.constant_speed = 500..1900;
        let brake = brake_engagement(&chain.params, &travel).unwrap().expect("the brake catches the sheave");
        let mut clamped = Effects::none();
        clamped.set(EffectKind::BrakeStop, &[1.0e6, 5.0]).unwrap();
        let settings = DrivenSettings::default();
        let (rigid, _) = torque_driven_accelerations(&rig, &travel, &settings, &Effects::none()).unwrap();
        let (elastic, _) = torque_driven_accelerations(&rig, &travel, &settings, &clamped).unwrap();
        let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        let difference = |range: Range<usize>| {
            let d: Vec<f64> = rigid[range.clone()].iter().zip(&elastic[range.clone()]).map(|(a, b)| a - b).collect();
            rms(&d) / rms(&rigid[range])
        };
        // The split into the rigid and elastic parts is zero-phase: its
        // tail carries the brake's ring back in time (a few 1e-5 of the
        // RMS in the last 0.1 s before the brake); the first second of the
        // travel, a second before the brake, is clear of it.
        let (before, after) = (difference(0..(fs as usize)), difference(brake..rigid.len()));
        println!(
            "clamp against rigid brake: {before:.2e} of the RMS over the first second, {after:.2e} after the brake"
        );
        assert!(before < 1e-6, "before the brake at sample {brake}: {before:.2e}");
        assert!(after > 1e-3, "the clamp rings after the brake: {after:.2e}");
    }

    /// A brake that catches the sheave while the reference still commands
    /// motion stops the turning sheave; a drive that sets its brake after
    /// its reference has ended and then releases its torque hands the
    /// load over, even where the release turns the sheave (the encoder's
    /// standstill after the brake).
    #[test]
    fn the_brake_stops_the_sheave_where_the_reference_still_runs() {
        let turning = |t: f64| if (0.2..2.0).contains(&t) { 1.0 } else { 0.0 };
        let braked = |_: f64, steady: f64, _: f64| steady;
        assert!(brake_read(turning, braked, Some(2.0)).1, "caught as the reference ends");
        assert!(brake_read(turning, braked, None).1, "caught before the encoder stands still");
        // The drive brings the sheave to rest at 3 s, with its reference,
        // holds it, and releases its torque over 0.4 s from 3.5 s; the
        // clamp yields 1.6 mrad meanwhile, so the encoder's standstill
        // comes after the brake.
        let creeping = |t: f64| {
            if t < 0.2 {
                0.0
            } else {
                (3.0 - t).clamp(0.0, 1.0) + if (3.5..3.9).contains(&t) { 0.004 } else { 0.0 }
            }
        };
        let released =
            |t: f64, steady: f64, inertial: f64| (steady + inertial) * (1.0 - (t - 3.5) / 0.4).clamp(0.0, 1.0);
        let (handed, stops) = brake_read(creeping, released, Some(3.0));
        assert!(handed.is_some_and(|t| t > 3.5), "released from 3.5 s, found at {handed:?} s");
        assert!(!stops, "handed over after the reference's end");
        assert!(brake_read(creeping, released, None).1, "without a reference, read by the encoder");
    }

    /// The report says for each reading whether the stop is compared, and
    /// against what the brake was timed.
    #[test]
    fn the_brake_reading_says_whether_the_stop_is_compared() {
        let stops = StopBrake::StopsTheSheave { at_s: 12.3456, clock: StopClock::Reference };
        let handed = StopBrake::HandedOver { at_s: 13.0, clock: StopClock::Encoder };
        assert!(stops.stops_the_sheave() && !handed.stops_the_sheave() && !StopBrake::NotFound.stops_the_sheave());
        assert!(stops.text().contains("12.346 s") && stops.text().ends_with("the stop is compared"));
        assert!(stops.text().contains("speed reference"), "{}", stops.text());
        assert!(handed.text().contains("not compared") && handed.text().contains("no speed reference recorded"));
        assert!(StopBrake::NotFound.text().contains("not compared"));
    }

    #[test]
    fn the_reference_ends_where_it_stops_commanding_motion() {
        let reference = [0.0, 0.5, 1.0, 1.0, 0.5, 1e-9, 1e-300, 0.0, 0.0];
        assert_eq!(reference_end(&reference), Some(5), "the tail below 1e-6 of the peak is no motion");
        assert_eq!(reference_end(&[0.0; 4]), None);
        assert_eq!(reference_end(&[f64::NAN, 1.0]), Some(2));
    }

    /// The brake is found where it catches the turning sheave and where the
    /// drive hands it the load at standstill; not where the drive brings
    /// the sheave to rest and holds it.
    #[test]
    fn the_brake_is_where_the_recording_shows_it() {
        let turning = |t: f64| if (0.2..2.0).contains(&t) { 1.0 } else { 0.0 };
        let smooth = |t: f64| if t < 0.2 { 0.0 } else { (3.0 - t).clamp(0.0, 1.0) };
        // The brake, not the drive, stops the sheave.
        let braked = |_: f64, steady: f64, _: f64| steady;
        let caught = brake_found(turning, braked).expect("a brake that catches the sheave");
        let held = |_: f64, steady: f64, inertial: f64| steady + inertial;
        assert!((caught - 2.0).abs() < 0.02, "caught at {caught} s, stopped at 2 s");
        assert_eq!(brake_found(smooth, held), None, "the drive holds");
        let released =
            |t: f64, steady: f64, inertial: f64| (steady + inertial) * (1.0 - (t - 3.5) / 0.05).clamp(0.0, 1.0);
        let handed = brake_found(smooth, released).expect("the drive releases its torque");
        assert!((handed - 3.5).abs() < 0.02, "released from 3.5 s, found at {handed} s");
    }

    #[test]
    fn the_motion_is_where_the_encoder_turns() {
        // At rest 1 s, turning at 2 rad/s for 2 s, at rest 1 s; an encoder of
        // 16384 counts per revolution.
        let fs = 1000.0;
        let q = TAU / 16384.0;
        let angle: Vec<f64> = (0..4000)
            .map(|k| {
                let t = (k as f64 / fs - 1.0).clamp(0.0, 2.0);
                ((2.0 * t) / q).floor() * q
            })
            .collect();
        let m = motion_from_angle(&angle, fs);
        // Within the window (50 ms) and the four-count threshold of the edges.
        assert!(m.start >= 945 && m.start <= 1005, "{m:?}");
        assert!(m.end >= 2995 && m.end <= 3055, "{m:?}");
    }
}
