//! Step 2, second way: replay. The measured shaft motion drives the nominal
//! mechanical model (the sheave's position is prescribed from the encoder
//! angle; ropes, car and counterweight respond), which needs no knowledge of
//! the rig's drive. When the replay matches the accelerations and the closed
//! loop does not, the gap lies upstream of the sheave (drive or electrical);
//! when the replay misses them too, it lies in the mechanics.

use dsp::lowpass_complement_zero_phase;
use plant::effects::Effects;
use plant::line::{BrakeAction, Line};
use plant::rope::{CAR, CW, DOF, SHEAVE};
use plant::{Chain, ChainParams, ChainState};
use rig_config::RigConfig;

use crate::error::{bail, Result};

/// The prescribed angle is low-passed at this frequency, Hz (encoder
/// quantisation would otherwise drive the rope masses' modes); it keeps the
/// ripple orders up to 72 x f_mech.
pub const REPLAY_LOWPASS_HZ: f64 = 100.0;

/// Car and counterweight accelerations (m/s^2, positive up) of the nominal
/// chain of `rig` (car `m_car_kg`, counterweight `m_cw_kg`, starting at
/// `lw_start_m`) when its sheave follows `shaft_angle_rad` (rad, sampled at
/// `sample_rate_hz`, positive: car up).
pub fn replay_accelerations(
    rig: &RigConfig,
    m_car_kg: f64,
    m_cw_kg: f64,
    lw_start_m: f64,
    shaft_angle_rad: &[f64],
    sample_rate_hz: f64,
) -> Result<(Vec<f64>, Vec<f64>)> {
    let n = shaft_angle_rad.len();
    if n < 2 {
        bail!("replay: the shaft angle has {n} samples; expected at least 2");
    }
    let theta0 = shaft_angle_rad[0];
    let relative: Vec<f64> = shaft_angle_rad.iter().map(|a| a - theta0).collect();
    let r = rig.mechanics.sheave_radius_m;
    let low = lowpass_complement_zero_phase(&relative, sample_rate_hz, REPLAY_LOWPASS_HZ)?;
    let sheave: Vec<f64> = low.iter().map(|a| a * r).collect();
    let mut params = ChainParams::from_rig(rig, m_car_kg);
    params.m_cw_kg = m_cw_kg;
    let chain = Chain::new(params, lw_start_m);
    let h = 1.0 / sample_rate_hz;
    let mut state = ChainState::default();
    state.position_m[SHEAVE] = sheave[0];
    let mut car = Vec::with_capacity(n);
    let mut cw = Vec::with_capacity(n);
    let line = Line::new(&Effects::none());
    let accel_at = |s: &ChainState| {
        let mut a = [0.0; DOF];
        line.accelerations(&chain, &s.position_m, &s.velocity_mps, 0.0, BrakeAction::Released, 0.0, &mut a);
        a
    };
    let mut work = [0.0; 10 * DOF];
    for k in 0..n {
        let a = accel_at(&state);
        car.push(a[CAR]);
        cw.push(-a[CW]);
        if k + 1 == n {
            break;
        }
        let (u0, u1) = (sheave[k], sheave[k + 1]);
        let v = (u1 - u0) / h;
        let with_sheave = |s: &ChainState, frac: f64| {
            let mut s = *s;
            s.position_m[SHEAVE] = u0 + frac * (u1 - u0);
            s.velocity_mps[SHEAVE] = v;
            s
        };
        let deriv = |s: &ChainState| -> ChainState {
            let a = accel_at(s);
            let mut d = ChainState { position_m: s.velocity_mps, velocity_mps: a };
            d.position_m[SHEAVE] = 0.0;
            d.velocity_mps[SHEAVE] = 0.0;
            d
        };
        // The plant's integrator on positions and velocities packed in one
        // slice; every stage's sheave put on the recorded one.
        let unpack = |y: &[f64]| {
            let mut s = ChainState::default();
            s.position_m.copy_from_slice(&y[..DOF]);
            s.velocity_mps.copy_from_slice(&y[DOF..]);
            s
        };
        let s0 = with_sheave(&state, 0.0);
        let mut y = [0.0; 2 * DOF];
        y[..DOF].copy_from_slice(&s0.position_m);
        y[DOF..].copy_from_slice(&s0.velocity_mps);
        plant::rk4_step_in_time(&mut y, h, &mut work, |frac, y, dy| {
            let d = deriv(&with_sheave(&unpack(y), frac));
            dy[..DOF].copy_from_slice(&d.position_m);
            dy[DOF..].copy_from_slice(&d.velocity_mps);
        });
        let next = unpack(&y);
        state = with_sheave(&next, 1.0);
        if !state.position_m.iter().chain(&state.velocity_mps).all(|x| x.is_finite()) {
            bail!("replay diverged at t = {:.3} s", k as f64 * h);
        }
    }
    Ok((car, cw))
}

/// The replay's accelerations of the travel `recording` (`stem`), its
/// shaft following `shaft_angle_rad` (rad, at the recording's rate, on the
/// currents' time base: [`crate::travel_signals::travel_shaft_angle`]),
/// against the measured cells of `target`, cell by cell (car and
/// counterweight channels, the measured phases).
pub fn replay_cells(
    rig: &RigConfig,
    recording: &recording::Recording,
    stem: &str,
    shaft_angle_rad: &[f64],
    measured: &super::signals::ChainSignals,
    target: &super::target::Target,
    bands: &super::spectra::Bands,
) -> Result<Vec<super::measure::CellGap>> {
    use super::signals::{decimation_factor, ChainSignals, Channel};
    use super::spectra::{cell_powers, ChainSpectra, Segmentation};
    use recording::RecordingKind;
    let RecordingKind::Travel { m_car_kg, m_cw_kg, lw_start_m, .. } = recording.meta.kind else {
        bail!("`{stem}`: only travels are replayed");
    };
    let fs = recording.meta.sample_rate_hz;
    let factor = decimation_factor(fs);
    let angle = if factor > 1 { dsp::decimate(shaft_angle_rad, factor)? } else { shaft_angle_rad.to_vec() };
    let len = measured.len().min(angle.len());
    let (car, cw) = replay_accelerations(rig, m_car_kg, m_cw_kg, lw_start_m, &angle[..len], measured.sample_rate_hz)?;
    let mut channels = vec![(Channel::CarAcceleration, car)];
    if measured.channel(Channel::CounterweightAcceleration).is_some() {
        channels.push((Channel::CounterweightAcceleration, cw));
    }
    let replay = ChainSignals {
        sample_rate_hz: measured.sample_rate_hz,
        channels,
        phases: measured.phases.clone(),
        noise_density: Vec::new(),
        angle_rad: measured.angle_rad.clone(),
    };
    let seg = Segmentation::of(measured);
    let spectra = ChainSpectra::compute(&replay, &seg, bands);
    Ok(super::measure::cell_gaps(
        &target.measured,
        &target.noise,
        &target.tolerances,
        &cell_powers(&[(&spectra, 1.0)], bands),
    ))
}
