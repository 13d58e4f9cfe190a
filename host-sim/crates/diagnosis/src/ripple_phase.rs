//! The ripple's phases under another drive, read from the drive's torque.
//!
//! The rig file gives the ripple's amplitudes, not its phases. Where the
//! rig's speed loop rejects an order, the currents carry its mirror image
//! `-T A e^{j phi}`, `T = 1 - S` the loop's complementary sensitivity
//! ([`speed_loop_sensitivity`]). `S` is computed on the chain the loop
//! drives: the sheave's mobility of the paper's 5-DOF chain (Eqn 6,
//! [`drive_core::ripple::response::chain_response`]) at the rope lengths
//! of the moment, which near a mode differs from the rigid chain's in
//! magnitude and in phase. The rope lengths change along the travel, so
//! the line is read window by window over whole revolutions of the shaft
//! ([`revolution_windows`]) and the ripple's phasor fitted to all windows
//! at once: `P = -sum conj(T_w) X_w / sum |T_w|^2`, each window weighted
//! by its length.

use nalgebra::{Complex, Matrix4, Vector4};
use std::f64::consts::TAU;
use std::ops::Range;

use super::drive_law::SpeedController;
use super::driven::{DrivenTravel, TransducerTorqueLine};
use drive_core::observer::ChainModel;
use plant::ripple::RippleTorque;
use rig_config::RigConfig;

/// A ripple order's lines in the measured torque count as the drive's
/// rejection of it (and give its phase) when the ripple they give through
/// the loop's rejection is at least this fraction of the order's amplitude
/// in the rig file.
pub const REJECTED_FRACTION: f64 = 0.3;

/// ... and when that ripple, through each window's rejection, explains at
/// least this share of the windows' lines' power (a majority: the lines
/// move with the rope lengths as the chain's rejection says).
pub const EXPLAINED_SHARE: f64 = 0.5;

/// The sensitivity `S = 1 / (1 + L)` of the rig drive's speed loop at the
/// angular frequency `omega_radps` (rad/s, signed: negative for a line
/// that turns back with the shaft, where `S` is the conjugate), on a chain
/// whose sheave has the mobility `mobility` (shaft speed per shaft torque,
/// rad/s per N m, at `omega_radps`): `L = (K_p + K_i / s) e^{-s tau_d} /
/// (1 + s tau_l) Y`. A torque that the drive adds to its own output (its
/// transducers' error) reaches the shaft as `S` times it; a torque from
/// outside (the ripple) leaves `-(1 - S)` times it in the currents.
pub fn speed_loop_sensitivity(controller: &SpeedController, mobility: Complex<f64>, omega_radps: f64) -> Complex<f64> {
    let s = Complex::new(0.0, omega_radps);
    let controller_gain = Complex::new(controller.kp_nms_per_rad, 0.0) + controller.ki_nm_per_rad / s;
    let estimate = (-s * controller.estimate_delay_s).exp() / (1.0 + s * controller.estimate_lag_s);
    1.0 / (1.0 + controller_gain * estimate * mobility)
}

/// The mobility `1 / (J s)` (rad/s per N m) of a rigid inertia
/// `inertia_kg_m2` (kg m^2) at `omega_radps` (rad/s, signed).
pub fn rigid_mobility(inertia_kg_m2: f64, omega_radps: f64) -> Complex<f64> {
    1.0 / Complex::new(0.0, omega_radps * inertia_kg_m2)
}

/// The sheave's mobility (rad/s per N m) of the 5-DOF chain `chain`
/// carrying a car of `m_car_kg` at the counterweight-side rope length
/// `lw_m` (m), at `omega_radps` (rad/s, signed), Eqn 6 with the guide and
/// sheave damping of Eqn 12-13 (the drive core's
/// [`drive_core::ripple::response::chain_response`], in `f32`).
pub fn chain_mobility(chain: &ChainModel, m_car_kg: f64, lw_m: f64, omega_radps: f64) -> Complex<f64> {
    let y = drive_core::ripple::response::chain_response(chain, m_car_kg as f32, lw_m as f32, omega_radps as f32)
        .shaft_mobility;
    Complex::new(f64::from(y.re), f64::from(y.im))
}

/// Consecutive windows of whole shaft revolutions within `stage` of the
/// shaft angle `angle_rad` (rad): each runs until the shaft has turned a
/// full revolution from its first sample. A stage shorter than one
/// revolution is one window; a last partial revolution is left out.
pub fn revolution_windows(angle_rad: &[f64], stage: Range<usize>) -> Vec<Range<usize>> {
    let stage = stage.start.min(angle_rad.len())..stage.end.min(angle_rad.len());
    let mut windows = Vec::new();
    let mut start = stage.start;
    for k in stage.clone() {
        if (angle_rad[k] - angle_rad[start]).abs() >= TAU {
            windows.push(start..k);
            start = k;
        }
    }
    if windows.is_empty() && stage.len() >= 2 {
        windows.push(stage);
    }
    windows
}

/// The line of order `order` (per revolution) in `torque_nm` (N m) over
/// the shaft angle `angle_rad` (rad), as `Re(X e^{j n theta})` (N m),
/// fitted by least squares together with a constant and a ramp in time
/// (the out-of-balance torque changes with the rope lengths). `None`
/// where the fit is singular (a shaft that does not turn).
pub fn angle_locked_line(torque_nm: &[f64], angle_rad: &[f64], order: f64) -> Option<Complex<f64>> {
    let n = torque_nm.len().min(angle_rad.len());
    let middle = (n as f64 - 1.0) / 2.0;
    let mut normal = Matrix4::<f64>::zeros();
    let mut right = Vector4::<f64>::zeros();
    for k in 0..n {
        let (s, c) = (order * angle_rad[k]).sin_cos();
        let basis = Vector4::new(1.0, k as f64 - middle, c, s);
        normal += basis * basis.transpose();
        right += basis * torque_nm[k];
    }
    let fit = normal.lu().solve(&right)?;
    fit.iter().all(|x| x.is_finite()).then(|| Complex::new(fit[2], -fit[3]))
}

/// The ripple of `rig` with each order's phase read from the measured
/// torque's angle-locked lines over the constant-speed stage of `travel`,
/// window by window ([`revolution_windows`]), each less the drive's
/// transducer line at that order as its speed loop lets it through
/// ([`TransducerTorqueLine`]; under a hypothesised transducer error, the
/// line of the torque `error_nm` (N m, on the travel's grid) that the
/// error adds to the recorded one, in its place). The currents carry
/// `-T A e^{j phi}`: where
/// the loop is identified, `T` is the chain's at each window's rope
/// lengths (module documentation), elsewhere `T = 1`. An order's phase is
/// read where the ripple the lines give is at least [`REJECTED_FRACTION`]
/// of the order's amplitude and explains at least [`EXPLAINED_SHARE`] of
/// the lines' power; the rig file's phase elsewhere.
pub fn ripple_matched_to_the_drive(rig: &RigConfig, travel: &DrivenTravel, error_nm: Option<&[f64]>) -> RippleTorque {
    let mut chain = rig.observer_model();
    chain.m_cw_kg = travel.m_cw_kg as f32;
    let mobility = |lw_m, omega_radps| chain_mobility(&chain, travel.m_car_kg, lw_m, omega_radps);
    ripple_read_through(rig, travel, error_nm, &mobility)
}

/// [`ripple_matched_to_the_drive`] on a sheave of mobility `mobility(l_w,
/// omega)` (rad/s per N m) at the counterweight-side rope length `l_w`
/// (m) and the angular frequency `omega` (rad/s, signed).
fn ripple_read_through(
    rig: &RigConfig,
    travel: &DrivenTravel,
    error_nm: Option<&[f64]>,
    mobility: &dyn Fn(f64, f64) -> Complex<f64>,
) -> RippleTorque {
    let mut ripple = RippleTorque::from_rig(&rig.ripple);
    let windows = revolution_windows(travel.shaft_angle_rad, travel.constant_speed.clone());
    if windows.is_empty() {
        return ripple;
    }
    for h in &mut ripple.harmonics {
        let transducer = match error_nm {
            Some(error_nm) => TransducerLine::Hypothesised(error_nm),
            None => travel
                .transducer_lines
                .iter()
                .find(|l| l.mechanical_order == h.mechanical_order)
                .map_or(TransducerLine::None, TransducerLine::Measured),
        };
        let mut reading = PhaseReading::default();
        for window in &windows {
            if let Some((line, rejection)) = window_line(rig, travel, mobility, h.mechanical_order, window, transducer)
            {
                reading.add(line, rejection, window.len() as f64);
            }
        }
        if let Some(phase_rad) = reading.phase_rad(h.amplitude_nm) {
            h.phase_rad = phase_rad;
        }
    }
    ripple
}

/// The torque line the rig drive's current transducers put on the shaft,
/// which the drive's speed loop answers as it answers the ripple.
#[derive(Clone, Copy)]
enum TransducerLine<'a> {
    /// None known.
    None,
    /// Measured in the direct-axis current, over the whole stage.
    Measured(&'a TransducerTorqueLine),
    /// The torque (N m, on the travel's grid) a hypothesised transducer
    /// error adds to the recorded one: its line read window by window.
    Hypothesised(&'a [f64]),
}

/// One window's line of order `order` in the drive's torque, less the
/// transducer line `transducer` as the speed loop passes it, and the
/// loop's rejection `T = 1 - S` there on a sheave of mobility `mobility`
/// ([`ripple_read_through`]; 1 where the loop is not identified). The
/// shaft gets the ripple `A` and the transducers' line `E`; the drive
/// answers both, so the torque it puts out carries `-T A + S E`.
fn window_line(
    rig: &RigConfig,
    travel: &DrivenTravel,
    mobility: &dyn Fn(f64, f64) -> Complex<f64>,
    order: f64,
    window: &Range<usize>,
    transducer: TransducerLine,
) -> Option<(Complex<f64>, Complex<f64>)> {
    let angle = &travel.shaft_angle_rad[window.clone()];
    let read = || angle_locked_line(&travel.torque_nm[window.clone()], angle, order);
    let mut line = match travel.readings {
        Some(readings) => readings.torque_line(order, window, read),
        None => read(),
    }?;
    let seconds = (angle.len() as f64 - 1.0).max(1.0) / travel.sample_rate_hz;
    let omega = order * (angle[angle.len() - 1] - angle[0]) / seconds;
    let mean_angle = angle.iter().sum::<f64>() / angle.len() as f64;
    let lw_m = travel.lw_start_m + rig.mechanics.sheave_radius_m * mean_angle;
    let sensitivity = travel.controller.map(|c| speed_loop_sensitivity(&c, mobility(lw_m, omega), omega));
    let passed = sensitivity.unwrap_or(Complex::new(1.0, 0.0));
    match transducer {
        TransducerLine::None => {}
        TransducerLine::Measured(t) => line -= passed * Complex::new(t.phasor_nm[0], t.phasor_nm[1]),
        TransducerLine::Hypothesised(error_nm) => {
            let error = error_nm.get(window.clone()).and_then(|e| angle_locked_line(e, angle, order));
            line -= passed * error.unwrap_or_default();
        }
    }
    Some((line, sensitivity.map_or(Complex::new(1.0, 0.0), |s| 1.0 - s)))
}

/// The least-squares sums of the ripple's phasor over the windows.
#[derive(Default)]
struct PhaseReading {
    /// `sum w conj(T) X`, N m.
    correlation: Complex<f64>,
    /// `sum w |T|^2`.
    rejection_power: f64,
    /// `sum w |X|^2`, N^2 m^2.
    line_power: f64,
}

impl PhaseReading {
    /// One window's line `line` (N m) under the rejection `rejection`, of
    /// weight `weight` (its length).
    fn add(&mut self, line: Complex<f64>, rejection: Complex<f64>, weight: f64) {
        self.correlation += rejection.conj() * line * weight;
        self.rejection_power += rejection.norm_sqr() * weight;
        self.line_power += line.norm_sqr() * weight;
    }

    /// The ripple's phasor `A e^{j phi}` (N m) the windows' lines give:
    /// `-sum conj(T) X / sum |T|^2`.
    fn ripple_nm(&self) -> Option<Complex<f64>> {
        (self.rejection_power > 0.0).then(|| -self.correlation / self.rejection_power)
    }

    /// The share of the lines' power (0-1) that the ripple
    /// [`Self::ripple_nm`] explains through each window's rejection.
    fn explained(&self) -> f64 {
        if self.line_power > 0.0 && self.rejection_power > 0.0 {
            self.correlation.norm_sqr() / (self.rejection_power * self.line_power)
        } else {
            0.0
        }
    }

    /// The ripple's phase (rad) where the recovered ripple is at least
    /// [`REJECTED_FRACTION`] of `amplitude_nm` (N m) and explains at least
    /// [`EXPLAINED_SHARE`] of the lines' power.
    fn phase_rad(&self, amplitude_nm: f64) -> Option<f64> {
        let ripple = self.ripple_nm()?;
        (ripple.norm() >= REJECTED_FRACTION * amplitude_nm && self.explained() >= EXPLAINED_SHARE).then(|| ripple.arg())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use plant::rope::{ChainParams, DOF, SHEAVE};

    /// The speed loop's sensitivity against the loop run in time: a rigid
    /// inertia under a PI on a delayed, lagged speed estimate, a torque line
    /// added to the drive's output; the line of the torque it then puts out
    /// is `S` times the added one (both directions of turning).
    #[test]
    fn the_sensitivity_is_what_the_loop_does_in_time() {
        let controller = controller();
        let (inertia, fs) = (1.1, 20_000.0);
        let delay = (controller.estimate_delay_s * fs).round() as usize;
        for omega in [TAU * 5.4, -TAU * 5.4, TAU * 11.0] {
            let (mut speed, mut estimate, mut integral) = (0.0, 0.0, 0.0);
            let mut past = std::collections::VecDeque::from(vec![0.0; delay + 1]);
            let seconds = 30.0;
            let (mut re, mut im, mut count) = (0.0, 0.0, 0.0);
            for k in 0..(seconds * fs) as usize {
                let t = k as f64 / fs;
                past.push_back(speed);
                let seen = past.pop_front().unwrap();
                estimate += (seen - estimate) / (1.0 + controller.estimate_lag_s * fs);
                integral += -estimate / fs;
                let added = (omega * t).cos();
                let torque = controller.kp_nms_per_rad * -estimate + controller.ki_nm_per_rad * integral + added;
                speed += torque / inertia / fs;
                if t > seconds / 2.0 {
                    re += torque * (omega * t).cos();
                    im -= torque * (omega * t).sin();
                    count += 1.0;
                }
            }
            let measured = Complex::new(2.0 * re / count, 2.0 * im / count);
            let s = speed_loop_sensitivity(&controller, rigid_mobility(inertia, omega), omega);
            assert!((s - measured).norm() < 0.02 * s.norm(), "omega {omega}: S = {s} against {measured}");
        }
    }

    /// The chain's mobility tends to the rigid chain's well below its
    /// first mode (the whole inertia at the sheave) and to the sheave's
    /// alone well above the rope modes, with the guide and sheave damping
    /// at the sheave.
    #[test]
    fn the_chain_mobility_has_the_rigid_limits() {
        let rig = RigConfig::embedded_default().unwrap();
        let params = ChainParams::from_rig(&rig, 70.5);
        let chain = rig.observer_model();
        let r = params.sheave_radius_m;
        let all = params.masses_kg(4.0).iter().sum::<f64>() * r * r;
        let damping = params.damping_kg_per_s().iter().sum::<f64>() * r * r;
        for (omega, inertia) in [(TAU * 0.5, all), (TAU * 5000.0, params.sheave_inertia_kg_m2)] {
            let chain = chain_mobility(&chain, 70.5, 4.0, omega);
            let rigid = 1.0 / (1.0 / rigid_mobility(inertia, omega) + damping);
            assert!((chain - rigid).norm() < 0.02 * rigid.norm(), "{omega} rad/s: {chain} against {rigid}");
        }
    }

    /// The angle-locked line fitted with a constant and a ramp against the
    /// naive correlation over whole revolutions of a signal that holds only
    /// the line: the same; and with a large ramp added, still the line.
    #[test]
    fn the_line_fit_sees_through_a_ramp() {
        let n = 4000;
        let angle: Vec<f64> = (0..n).map(|k| 3.0 * TAU * k as f64 / n as f64).collect();
        let line = Complex::new(0.7, -0.4);
        let pure: Vec<f64> = angle.iter().map(|a| (line * Complex::from_polar(1.0, 6.0 * a)).re).collect();
        let naive = pure
            .iter()
            .zip(&angle)
            .map(|(t, a)| *t * Complex::from_polar(2.0 / n as f64, -6.0 * a))
            .sum::<Complex<f64>>();
        let fitted = angle_locked_line(&pure, &angle, 6.0).unwrap();
        assert!((fitted - naive).norm() < 1e-3, "{fitted} against the naive {naive}");
        for order in [1.0, 6.0] {
            let ramped: Vec<f64> = angle
                .iter()
                .enumerate()
                .map(|(k, a)| 40.0 + 0.01 * k as f64 + (line * Complex::from_polar(1.0, order * a)).re)
                .collect();
            let fitted = angle_locked_line(&ramped, &angle, order).unwrap();
            assert!((fitted - line).norm() < 1e-9, "order {order}: {fitted} against {line}");
        }
    }

    /// The ripple's phase read from a drive's torque on the elastic chain
    /// run in time: the 5-DOF chain (its rope lengths changing along the
    /// travel) under a PI speed loop on a delayed, lagged estimate, an
    /// order-12 ripple whose line crosses the first mode during the
    /// stage. The chain-aware reading finds the phase within 0.15 rad;
    /// the rigid chain's sensitivity in its place misses it by more.
    #[test]
    fn the_phase_is_read_through_the_chain() {
        let rig = RigConfig::embedded_default().unwrap();
        let params = ChainParams::from_rig(&rig, 70.5);
        let (order, amplitude, phase) = (12.0, 1.0, 0.8);
        let r = params.sheave_radius_m;
        let lw_start = 2.5;
        let f_mid = plant::modes::natural_modes(&params, lw_start + 1.5).frequencies_hz[1];
        let shaft_speed = TAU * f_mid / order;
        let seconds = 3.0 / (shaft_speed * r);
        let travel =
            travel_in_time(&params, lw_start, shaft_speed, seconds, [order, amplitude, phase], [order, 0.0, 0.0]);
        let mut ripple_rig = rig.clone();
        ripple_rig.ripple.retain(|c| c.mechanical_order == 12);
        ripple_rig.ripple[0].amplitude_nm = amplitude;
        let driven = travel.driven(&params);
        let read = ripple_matched_to_the_drive(&ripple_rig, &driven, None).harmonics[0].phase_rad;
        let miss = |p: f64| (Complex::from_polar(1.0, p) / Complex::from_polar(1.0, phase)).arg().abs();
        let inertia = crate::driven::rigid_inertia_kg_m2(&params);
        let rigid = ripple_read_through(&ripple_rig, &driven, None, &|_, omega| rigid_mobility(inertia, omega))
            .harmonics[0]
            .phase_rad;
        println!(
            "order 12 at {f_mid:.2} Hz mid-stage: chain-aware miss {:.3} rad, rigid {:.3} rad",
            miss(read),
            miss(rigid)
        );
        assert!(miss(read) < 0.15, "read {read} rad against {phase} rad");
        assert!(miss(rigid) > 2.0 * miss(read), "the rigid chain's reading misses by {} rad", miss(rigid));
    }

    /// Under a transducer error the machine's torque carries the error's
    /// line `E` beside the drive's answer; the shaft gets the ripple and
    /// `E`, and the drive answers both. Read from the machine's torque less
    /// `E` as the loop passes it (the hypothesis that names `E`), the
    /// ripple's phase is found within 0.15 rad; read from the drive's own
    /// record without the hypothesis, or from the machine's torque with
    /// `E` left in, the error pulls it off.
    #[test]
    fn the_phase_is_read_less_a_hypothesised_transducer_error() {
        let rig = RigConfig::embedded_default().unwrap();
        let params = ChainParams::from_rig(&rig, 70.5);
        let (order, amplitude, phase) = (12.0, 1.0, 0.8);
        let error = [order, 0.8, 2.6];
        let lw_start = 2.5;
        let f_mid = plant::modes::natural_modes(&params, lw_start + 1.5).frequencies_hz[1];
        let shaft_speed = TAU * f_mid / order;
        let seconds = 3.0 / (shaft_speed * params.sheave_radius_m);
        let travel = travel_in_time(&params, lw_start, shaft_speed, seconds, [order, amplitude, phase], error);
        let mut ripple_rig = rig.clone();
        ripple_rig.ripple.retain(|c| c.mechanical_order == 12);
        ripple_rig.ripple[0].amplitude_nm = amplitude;
        let error_nm: Vec<f64> = travel.angle_rad.iter().map(|a| error[1] * (error[0] * a + error[2]).cos()).collect();
        let machine_nm: Vec<f64> = travel.torque_nm.iter().zip(&error_nm).map(|(t, e)| t + e).collect();
        let mut machine = travel.driven(&params);
        machine.torque_nm = &machine_nm;
        let hypothesis = ripple_matched_to_the_drive(&ripple_rig, &machine, Some(&error_nm));
        let unaware = ripple_matched_to_the_drive(&ripple_rig, &travel.driven(&params), None);
        // The machine's torque with the error left in: the loop's answer
        // to it reads as ripple.
        let left_in = ripple_matched_to_the_drive(&ripple_rig, &machine, None);
        let miss = |m: &RippleTorque| {
            (Complex::from_polar(1.0, m.harmonics[0].phase_rad) / Complex::from_polar(1.0, phase)).arg().abs()
        };
        println!(
            "under the hypothesis miss {:.3} rad, without it {:.3} rad, with the error left in {:.3} rad",
            miss(&hypothesis),
            miss(&unaware),
            miss(&left_in)
        );
        assert!(miss(&hypothesis) < 0.15, "{hypothesis:?}");
        assert!(miss(&unaware) > 0.5, "the error should pull the unaware reading off: {unaware:?}");
        assert!(miss(&left_in) > 4.0 * miss(&hypothesis), "the error left in should pull the reading off: {left_in:?}");
    }

    /// The reading gives the phase of lines that follow the rejection, and
    /// none where they do not (lines of one size whose phases turn by a
    /// quarter from window to window, against a rejection that stays put),
    /// nor where the ripple they give is below [`REJECTED_FRACTION`] of the
    /// order's amplitude.
    #[test]
    fn the_phase_is_read_only_where_the_lines_follow_the_rejection() {
        let ripple = Complex::from_polar(2.0, 0.9);
        let rejections = [Complex::new(0.9, 0.3), Complex::new(0.4, -0.2), Complex::new(0.1, 0.2)];
        let mut following = PhaseReading::default();
        let mut turning = PhaseReading::default();
        for (k, t) in rejections.iter().enumerate() {
            following.add(-t * ripple, *t, 100.0);
            let quarter_turns = Complex::from_polar(1.0, std::f64::consts::FRAC_PI_2 * k as f64);
            turning.add(-rejections[0] * ripple * quarter_turns, rejections[0], 100.0);
        }
        let phase = following.phase_rad(2.0).expect("lines that follow the rejection give the phase");
        assert!((phase - 0.9).abs() < 1e-12, "{phase}");
        assert!(turning.explained() < EXPLAINED_SHARE, "{}", turning.explained());
        assert_eq!(turning.phase_rad(2.0), None);
        assert_eq!(following.phase_rad(2.0 / REJECTED_FRACTION * 1.01), None);
    }

    fn controller() -> SpeedController {
        SpeedController {
            kp_nms_per_rad: 26.0,
            ki_nm_per_rad: 80.0,
            estimate_lag_s: 0.0005,
            estimate_delay_s: 0.003,
            dynamic_fit: 1.0,
        }
    }

    /// A recorded travel at constant speed: the drive's torque (N m) and the
    /// shaft angle (rad) at 4 kHz.
    struct TravelInTime {
        torque_nm: Vec<f64>,
        angle_rad: Vec<f64>,
        estimate_radps: Vec<f64>,
        lw_start_m: f64,
        sample_rate_hz: f64,
    }

    impl TravelInTime {
        fn driven(&self, params: &ChainParams) -> DrivenTravel<'_> {
            let n = self.torque_nm.len();
            DrivenTravel {
                m_car_kg: params.m_car_kg,
                m_cw_kg: params.m_cw_kg,
                lw_start_m: self.lw_start_m,
                torque_nm: &self.torque_nm,
                shaft_angle_rad: &self.angle_rad,
                speed_estimate_radps: &self.estimate_radps,
                controller: Some(controller()),
                motion: 0..n,
                constant_speed: n / 10..n,
                reference_end: None,
                sample_rate_hz: self.sample_rate_hz,
                transducer_lines: &[],
                transducer: None,
                readings: None,
            }
        }
    }

    /// The chain of `params` turned at `shaft_speed` (rad/s) from the
    /// counterweight-side rope length `lw_start` (m) for `seconds`, the
    /// ripple `[order, amplitude (N m), phase (rad)]` on its shaft and the
    /// drive's PI loop answering the sheave's departure from the constant
    /// speed: the chain's departures from the steady motion, symplectic
    /// Euler at 40 960 Hz (`h omega` below 0.1 for its highest mode),
    /// recorded every tenth step.
    fn travel_in_time(
        params: &ChainParams,
        lw_start: f64,
        shaft_speed: f64,
        seconds: f64,
        ripple: [f64; 3],
        transducer_error: [f64; 3],
    ) -> TravelInTime {
        let c = controller();
        let (fs, every) = (40_960.0, 10);
        let h = 1.0 / fs;
        let r = params.sheave_radius_m;
        let delay = (c.estimate_delay_s * fs).round() as usize;
        let mut past = std::collections::VecDeque::from(vec![0.0; delay + 1]);
        let (mut x, mut v) = ([0.0; DOF], [0.0; DOF]);
        let (mut estimate, mut integral) = (0.0, 0.0);
        let damping = params.damping_kg_per_s();
        let mut recorded = TravelInTime {
            torque_nm: Vec::new(),
            angle_rad: Vec::new(),
            estimate_radps: Vec::new(),
            lw_start_m: lw_start,
            sample_rate_hz: fs / every as f64,
        };
        for k in 0..(seconds * fs) as usize {
            let t = k as f64 * h;
            let angle = shaft_speed * t + x[SHEAVE] / r;
            let lw = lw_start + r * angle;
            past.push_back(v[SHEAVE] / r);
            estimate += (past.pop_front().unwrap() - estimate) / (1.0 + c.estimate_lag_s * fs);
            integral -= estimate * h;
            let drive = -c.kp_nms_per_rad * estimate + c.ki_nm_per_rad * integral;
            // The drive's transducers err: the machine puts out the drive's
            // torque plus the error's line, the drive records its own.
            let error = transducer_error[1] * (transducer_error[0] * angle + transducer_error[2]).cos();
            let shaft = drive + error + ripple[1] * (ripple[0] * angle + ripple[2]).cos();
            if k % every == 0 {
                recorded.torque_nm.push(drive);
                recorded.angle_rad.push(angle);
                recorded.estimate_radps.push(shaft_speed + estimate);
            }
            let (masses, stiffness) = (params.masses_kg(lw), params.stiffness_matrix(lw));
            for i in 0..DOF {
                let spring: f64 = (0..DOF).map(|j| stiffness[i][j] * x[j]).sum();
                let applied = if i == SHEAVE { shaft / r } else { 0.0 };
                v[i] += h * (applied - spring - damping[i] * v[i]) / masses[i];
            }
            (0..DOF).for_each(|i| x[i] += h * v[i]);
        }
        recorded
    }
}
