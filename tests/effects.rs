//! The plant's library of effects, each against its physics: the nominal
//! limits bit for bit, convergence of the discretised rope, the frame mode
//! in a free vibration, energy conservation of the extended line, dry
//! friction in the torque balance, the eccentric sheave's kinematics and
//! excitation, the dead time's voltage error, the current-sensor offset's
//! torque ripple, the encoder error in the drive's angle, and the elastic
//! brake's stop transient.

use std::f64::consts::{PI, TAU};

use crate::support::{constant_speed_range, mean, rig};
use closed_loop::{simulate_travel, SimOptions, TravelRun, TravelSpec};
use drive_core::config::Direction;
use dsp::amplitude_spectrum;
use plant::effects::{
    CarFrameMode, CoulombGuideFriction, CurrentSensorError, DeadTime, DivertingPulley, EffectKind, Effects,
    EncoderError, RopeDiscretization, SheaveEccentricity,
};
use plant::free_decay::eqn9_first_frequency_hz;
use plant::line::Lumped;
use plant::{Plant, PlantInputs};
use rig_config::RigConfig;

/// Eigenfrequencies (Hz, ascending) of the undamped line on the nodes
/// `first..=last` of `lumped` (springs to nodes outside the range hold them
/// to ground), with `extra[(node, k)]` springs to ground (N/m): the
/// symmetric tridiagonal `M^-1/2 K M^-1/2` by Sturm-sequence bisection,
/// independent of the plant's code.
fn line_frequencies_hz(lumped: &Lumped, first: usize, last: usize, extra: &[(usize, f64)]) -> Vec<f64> {
    let k = &lumped.springs_n_per_m;
    let m = &lumped.masses_kg;
    let n = last - first + 1;
    let mut diag = vec![0.0; n];
    let mut off = vec![0.0; n.saturating_sub(1)];
    for (j, i) in (first..=last).enumerate() {
        let left = if i > 0 { k[i - 1] } else { 0.0 };
        let mut d = left + k[i];
        for &(node, stiffness) in extra {
            if node == i {
                d += stiffness;
            }
        }
        diag[j] = d / m[i];
        if i < last {
            off[j] = -k[i] / (m[i] * m[i + 1]).sqrt();
        }
    }
    let count_below = |x: f64| {
        let mut count = 0;
        let mut q = 1.0;
        for j in 0..n {
            let b2 = if j > 0 { off[j - 1] * off[j - 1] } else { 0.0 };
            q = diag[j] - x - if j > 0 { b2 / q } else { 0.0 };
            if q == 0.0 {
                q = -1e-300;
            }
            if q < 0.0 {
                count += 1;
            }
        }
        count
    };
    let upper =
        (0..n).map(|j| diag[j].abs() + 2.0 * off.iter().fold(0.0f64, |a, b| a.max(b.abs()))).fold(0.0, f64::max);
    (0..n)
        .map(|index| {
            let (mut lo, mut hi) = (0.0, upper * 1.01 + 1.0);
            for _ in 0..200 {
                let mid = 0.5 * (lo + hi);
                if count_below(mid) > index {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            (0.5 * (lo + hi)).sqrt() / TAU
        })
        .collect()
}

fn options(rig: &RigConfig, effects: Effects, seconds: f64) -> SimOptions {
    SimOptions {
        effects,
        max_control_steps: Some((seconds * rig.control.current_loop_hz) as u64),
        ..SimOptions::for_rig(rig)
    }
}

fn travel(rig: &RigConfig, m_car: f64, direction: Direction, options: &SimOptions) -> TravelRun {
    let spec = TravelSpec::full_travel(rig, m_car, direction);
    simulate_travel(rig, &spec, options, None).expect("the travel runs")
}

/// Amplitude of the line nearest `frequency_hz` in `signal`.
fn line_amplitude(signal: &[f64], fs: f64, frequency_hz: f64) -> f64 {
    let spectrum = amplitude_spectrum(signal, fs, 8).unwrap();
    spectrum.peak_near(frequency_hz, 0.1).expect("a line").amplitude
}

#[test]
fn one_element_and_alpha_zero_reproduce_the_nominal_plant_bit_for_bit() {
    let rig = rig();
    let nominal = travel(&rig, 70.5, Direction::Up, &options(&rig, Effects::none(), 2.5));
    assert!(nominal.time_s.len() > 40_000);
    for kinds in [
        vec![(EffectKind::RopeDiscretization, vec![1.0])],
        vec![(EffectKind::TensionStiffening, vec![0.0, 500.0])],
        vec![(EffectKind::RopeDiscretization, vec![1.0]), (EffectKind::TensionStiffening, vec![0.0, 50.0])],
    ] {
        let mut effects = Effects::none();
        for (kind, values) in &kinds {
            effects.set(*kind, values).unwrap();
        }
        let run = travel(&rig, 70.5, Direction::Up, &options(&rig, effects, 2.5));
        assert!(run == nominal, "{} differs from the nominal plant", effects.summary());
    }
    // And the check can fail: two elements are another plant.
    let mut two = Effects::none();
    two.set(EffectKind::RopeDiscretization, &[2.0]).unwrap();
    let run = travel(&rig, 70.5, Direction::Up, &options(&rig, two, 2.5));
    assert!(run.acc_car_mps2 != nominal.acc_car_mps2);
}

/// With the sheave held the car side is a rope fixed at the top with the
/// car hanging: its lumped frequencies converge to the continuous rope's
/// (Eqn 9) as the elements grow, and the plant rings at them.
#[test]
fn discretised_car_side_converges_to_the_continuous_rope() {
    let rig = rig();
    let (m_car, lw) = (33.0, 1.6);
    let lc = rig.mechanics.rope_total_length_m - lw;
    let m = &rig.mechanics;
    let exact = eqn9_first_frequency_hz(m.rope_ea_n, m.rope_mass_per_length_kg_per_m, lc, m_car);
    let mut errors = Vec::new();
    for n in [1usize, 2, 4, 8] {
        let effects = Effects { rope_discretization: Some(RopeDiscretization { elements: n }), ..Effects::none() };
        let plant = Plant::with_effects(&rig, m_car, lw, &effects);
        let layout = plant.line().layout;
        let lumped = plant.line().lumped(&plant.chain, 0.0);
        let f = line_frequencies_hz(&lumped, layout.sheave + 1, layout.body, &[]);
        let error = (f[0] - exact).abs() / exact;
        println!("N = {n}: first car-side frequency {:.4} Hz (Eqn 9: {exact:.4} Hz), error {:.2e}", f[0], error);
        errors.push(error);
    }
    for pair in errors.windows(2) {
        assert!(pair[1] < 0.5 * pair[0], "no convergence: {errors:?}");
    }
    assert!(errors[3] < 2e-4, "{errors:?}");

    // The plant itself rings at the lumped frequency (N = 4, brake held).
    let effects = Effects { rope_discretization: Some(RopeDiscretization { elements: 4 }), ..Effects::none() };
    let mut plant = Plant::with_effects(&rig, m_car, lw, &effects);
    plant.chain.lengths_follow_sheave = false;
    plant.chain.params.c_car_kg_per_s = 0.0;
    let layout = plant.line().layout;
    let lumped = plant.line().lumped(&plant.chain, 0.0);
    let f = line_frequencies_hz(&lumped, layout.sheave + 1, layout.body, &[]);
    let mut velocity = vec![0.0; layout.nodes];
    velocity[layout.body] = 0.01;
    plant.set_node_state(&vec![0.0; layout.nodes], &velocity);
    let fs = 16384.0;
    let acc: Vec<f64> = (0..(2.0 * fs) as usize)
        .map(|_| {
            plant.advance(1.0 / fs, 1.0 / 16000.0);
            plant.observe().car_acceleration_mps2
        })
        .collect();
    let spectrum = amplitude_spectrum(&acc, fs, 8).unwrap();
    let peak = spectrum.peak_near(f[0], 0.2).unwrap();
    println!("plant free vibration: {:.4} Hz, lumped eigenvalue {:.4} Hz", peak.frequency_hz, f[0]);
    assert!((peak.frequency_hz - f[0]).abs() < 0.002 * f[0]);
}

/// The frame mode's frequency appears in a free vibration of the car,
/// above the hitch-held 235 Hz, near the free-free `f / sqrt(1 - beta)`
/// (the rope is soft against the frame spring), where the undamped line's
/// eigenvalue puts it; the nominal car has no line there.
#[test]
fn frame_mode_rings_in_a_free_vibration() {
    let rig = rig();
    let frame = CarFrameMode { frequency_hz: 235.0, damping_ratio: 0.01, mass_fraction: 0.3 };
    let fs = 16384.0;
    let ring = |effects: Effects| -> (Vec<f64>, Plant) {
        let mut plant = Plant::with_effects(&rig, 70.5, 7.0, &effects);
        let nodes = plant.nodes();
        let body = plant.line().layout.body;
        let mut velocity = vec![0.0; nodes];
        velocity[body] = 0.01;
        plant.set_node_state(&vec![0.0; nodes], &velocity);
        let acc = (0..(fs as usize / 2))
            .map(|_| {
                plant.advance(1.0 / fs, 1.0 / 16000.0);
                plant.observe().car_acceleration_mps2
            })
            .collect();
        (acc, plant)
    };
    let (acc, plant) = ring(Effects { car_frame_mode: Some(frame), ..Effects::none() });
    let layout = plant.line().layout;
    let lumped = plant.line().lumped(&plant.chain, plant.node_state().0[layout.sheave]);
    let f = line_frequencies_hz(&lumped, layout.sheave + 1, layout.body, &[]);
    println!("car-side eigenfrequencies with the sheave held: {f:.2?} Hz");
    let frame_hz = f
        .iter()
        .copied()
        .find(|&x| x > 235.0 && x < 1.1 * frame.free_free_frequency_hz())
        .expect("a mode above the hitch-held frame frequency, near the free-free one");
    let spectrum = amplitude_spectrum(&acc, fs, 8).unwrap();
    let peak = spectrum.peak_near(frame_hz, 0.1).unwrap();
    let floor = spectrum.median_amplitude_in(100.0, 500.0).unwrap();
    println!(
        "frame line at {:.2} Hz, {:.3e} m/s^2, {:.0}x the median",
        peak.frequency_hz,
        peak.amplitude,
        peak.amplitude / floor
    );
    assert!((peak.frequency_hz - frame_hz).abs() < 0.005 * frame_hz);
    assert!(peak.amplitude > 30.0 * floor);
    let (nominal, _) = ring(Effects::none());
    let nominal_line = amplitude_spectrum(&nominal, fs, 8).unwrap().peak_near(frame_hz, 0.1).unwrap().amplitude;
    assert!(nominal_line < 0.05 * peak.amplitude, "nominal {nominal_line:.3e}");
}

/// Without damping, friction and drive torque, with the rope lengths
/// frozen, the extended line (pulley, 3 elements per side, frame mode,
/// eccentric sheave) conserves its energy (the out-of-balance torque's
/// potential included): forces, lever arms and masses are consistent.
#[test]
fn extended_line_conserves_energy_without_damping() {
    let rig = rig();
    let effects = Effects {
        diverting_pulley: Some(DivertingPulley {
            inertia_kg_m2: 0.02,
            radius_m: 0.065,
            sheave_to_pulley_m: 0.5,
            damping_ratio: 0.0,
        }),
        rope_discretization: Some(RopeDiscretization { elements: 3 }),
        car_frame_mode: Some(CarFrameMode { frequency_hz: 235.0, damping_ratio: 0.0, mass_fraction: 0.3 }),
        sheave_eccentricity: Some(SheaveEccentricity { eccentricity: 0.02, phase_rad: 0.4 }),
        ..Effects::none()
    };
    let mut plant = Plant::with_effects(&rig, 70.5, 3.0, &effects);
    plant.chain.lengths_follow_sheave = false;
    let p = &mut plant.chain.params;
    (p.c_car_kg_per_s, p.c_cw_kg_per_s, p.c_sheave_nms_per_rad) = (0.0, 0.0, 0.0);
    plant.ripple.harmonics.clear();
    plant.set_inputs(PlantInputs { brake_engaged: false, ..PlantInputs::default() });
    let nodes = plant.nodes();
    assert_eq!(nodes, 1 + 3 + 1 + 1 + 3 + 2);
    let position: Vec<f64> = (0..nodes).map(|i| 2e-5 * ((i as f64) * 1.3).sin()).collect();
    let velocity: Vec<f64> = (0..nodes).map(|i| 0.05 * ((i as f64) * 0.7).cos()).collect();
    plant.set_node_state(&position, &velocity);
    let e0 = plant.mechanical_energy_j();
    let mut worst: f64 = 0.0;
    for _ in 0..2000 {
        plant.advance(1.0e-4, 1.0e-5);
        worst = worst.max((plant.mechanical_energy_j() - e0).abs());
    }
    let kinetic0: f64 = 0.5 * 70.5 * 0.05f64.powi(2);
    println!("energy {e0:.6e} J, largest drift {worst:.3e} J over 0.2 s");
    assert!(worst < 1e-6 * kinetic0, "energy drift {worst:.3e} J");
    // The sheave turned: the eccentric lever arms were exercised.
    assert!(plant.observe().shaft_angle_rad.abs() > 0.05);
}

/// Dry guide friction on car and counterweight adds `2 F r` of shaft torque
/// at constant speed, against the motion.
#[test]
fn coulomb_friction_shows_in_the_torque_balance() {
    let rig = rig();
    let friction = CoulombGuideFriction { friction_n: 40.0, slip_speed_mps: 0.002 };
    let r = rig.mechanics.sheave_radius_m;
    for (direction, sign) in [(Direction::Up, 1.0), (Direction::Down, -1.0)] {
        let mean_torque = |effects: Effects| {
            let run = travel(&rig, 70.5, direction, &options(&rig, effects, 7.0));
            let range = constant_speed_range(&run, rig.travel.rated_speed_mps, 0.5);
            assert!(range.len() > 3 * 16384);
            mean(&run.motor_torque_nm[range])
        };
        let extra = mean_torque(Effects { coulomb_guide_friction: Some(friction), ..Effects::none() })
            - mean_torque(Effects::none());
        let expected = sign * 2.0 * friction.friction_n * r;
        println!("{direction:?}: extra torque {extra:.4} N m, 2 F r = {expected:.4} N m");
        assert!((extra - expected).abs() < 0.02 * expected.abs());
    }
}

/// The eccentric sheave moves the rope `2 pi r0` per revolution (and not
/// `r0 theta` within it), and at constant shaft speed the car sees the
/// rope's speed variation: a once-per-revolution acceleration `e r0 w^2`.
#[test]
fn eccentric_sheave_kinematics_and_once_per_revolution_excitation() {
    let mut rig = rig();
    let ecc = SheaveEccentricity { eccentricity: 0.02, phase_rad: 1.0 };
    let effects = Effects { sheave_eccentricity: Some(ecc), ..Effects::none() };
    let r0 = rig.mechanics.sheave_radius_m;
    let mut plant = Plant::with_effects(&rig, 70.5, 3.0, &effects);
    let sheave = plant.line().layout.sheave;
    let mut at = |theta: f64| {
        let mut position = vec![0.0; plant.nodes()];
        position[sheave] = r0 * theta;
        plant.set_node_state(&position, &[]);
        plant.observe().counterweight_side_length_m - 3.0
    };
    assert!((at(TAU) - TAU * r0).abs() < 1e-12);
    assert!((at(2.0 * TAU) - 2.0 * TAU * r0).abs() < 1e-12);
    let quarter = at(0.5 * PI);
    let expected = r0 * (0.5 * PI + 0.02 * ((0.5 * PI + 1.0).sin() - 1.0f64.sin()));
    assert!((quarter - expected).abs() < 1e-12 && (quarter - 0.5 * PI * r0).abs() > 1e-4);

    // Closed loop without the machine's ripple (whose order 1 would mask it).
    rig.ripple.clear();
    let line = |effects: Effects| {
        let run = travel(&rig, 70.5, Direction::Up, &options(&rig, effects, 7.0));
        let range = constant_speed_range(&run, rig.travel.rated_speed_mps, 0.5);
        let w = mean(&run.shaft_speed_radps[range.clone()]);
        (line_amplitude(&run.acc_car_mps2[range], run.sample_rate_hz, w / TAU), w)
    };
    let (amplitude, w) = line(effects);
    let (nominal, _) = line(Effects::none());
    let predicted = ecc.eccentricity * r0 * w * w;
    println!("once per revolution: {amplitude:.4e} m/s^2 (e r0 w^2 = {predicted:.4e}), nominal {nominal:.2e}");
    assert!((amplitude - predicted).abs() < 0.15 * predicted);
    assert!(nominal < 0.1 * amplitude);
}

/// The dead time lowers the voltage a phase gets by `4/3 T_d f_pwm V_dc`
/// when its current flows out of it and the other two carry it back: with a
/// DC voltage on phase a and the rotor held, the steady current is
/// `(v_a - 4/3 dV) / R` instead of `v_a / R`.
#[test]
fn dead_time_lowers_the_applied_voltage_by_the_formula() {
    let rig = rig();
    let dead = DeadTime { dead_time_s: 2.0e-6, current_threshold_a: 0.3 };
    let steady = |effects: Effects| {
        let mut plant = Plant::with_effects(&rig, 70.5, 3.0, &effects);
        let period = plant.pwm_period_counts;
        let half = period / 2;
        let compare = [half + period / 8, half, half];
        plant.set_inputs(PlantInputs { pwm_compare: compare, pwm_enabled: true, brake_engaged: true });
        plant.advance(0.2, 1.0 / 64000.0);
        let v_a = 2.0 / 3.0 * (period / 8) as f64 / period as f64 * rig.inverter.dc_bus_v;
        (plant.observe().phase_currents_a, v_a)
    };
    let (nominal, v_a) = steady(Effects::none());
    let r = rig.motor.stator_resistance_ohm;
    assert!((nominal[0] - v_a / r).abs() < 1e-6 * nominal[0]);
    let (with, _) = steady(Effects { dead_time: Some(dead), ..Effects::none() });
    let dv = dead.dead_time_s * rig.inverter.pwm_hz * rig.inverter.dc_bus_v;
    // Currents: a = I, b = c = -I/2; the tanh is saturated at these currents.
    let saturation = (0.5 * with[0] / dead.current_threshold_a).tanh();
    let expected = (v_a - 4.0 / 3.0 * dv * saturation) / r;
    println!("phase a: {:.4} A nominal, {:.4} A with dead time (formula {expected:.4} A)", nominal[0], with[0]);
    assert!((with[0] - expected).abs() < 1e-3 * expected);
    assert!((with[1] + 0.5 * with[0]).abs() < 1e-9);
}

/// An offset in the current the drive measures is a DC vector in the
/// stationary frame: the current loop puts its opposite into the machine,
/// which the rotor sees as a q-current (torque) ripple once per electrical
/// period, of amplitude `Kt |o_alpha beta|` with the speed loop open. The
/// speed loop reacts to the speed ripple this torque causes (about 6 Hz, near
/// its bandwidth), which changes the closed-loop amplitude by some ten per
/// cent: the bounds allow for it.
#[test]
fn current_sensor_offset_gives_a_once_per_electrical_period_ripple() {
    let mut rig = rig();
    rig.ripple.clear();
    let error = CurrentSensorError { offset_a_a: 0.3, offset_b_a: -0.2, gain_error_a: 0.0, gain_error_b: 0.0 };
    let line = |effects: Effects| {
        let run = travel(&rig, 70.5, Direction::Up, &options(&rig, effects, 7.0));
        let range = constant_speed_range(&run, rig.travel.rated_speed_mps, 0.5);
        let f_e = rig.motor.pole_pairs as f64 * mean(&run.shaft_speed_radps[range.clone()]) / TAU;
        let torque = line_amplitude(&run.motor_torque_nm[range.clone()], run.sample_rate_hz, f_e);
        let dc_a = mean(&run.phase_currents_a[0][range]);
        (torque, dc_a, f_e)
    };
    let (torque, dc_a, f_e) = line(Effects { current_sensor_error: Some(error), ..Effects::none() });
    let (nominal, nominal_dc_a, _) = line(Effects::none());
    // The offsets in the stationary frame (the drive's Clarke of a, b, c,
    // `alpha = (2a - b - c) / 3`, `beta = (b - c) / sqrt 3`, c exact).
    let (oa, ob) = (error.offset_a_a, error.offset_b_a);
    let alpha = (2.0 * oa - ob) / 3.0;
    let beta = ob / 3f64.sqrt();
    let kt = 1.5 * rig.motor.pole_pairs as f64 * rig.motor.flux_linkage_wb;
    let predicted = kt * alpha.hypot(beta);
    println!(
        "torque line at f_e = {f_e:.3} Hz: {torque:.4} N m (Kt |o| = {predicted:.4}), nominal {nominal:.2e}; mean i_a {dc_a:.4} A (nominal {nominal_dc_a:.4})"
    );
    assert!(torque > 0.8 * predicted && torque < 1.4 * predicted);
    assert!(nominal < 0.01 * torque);
    // The true current carries the opposite of the offset's alpha part.
    let shift = dc_a - nominal_dc_a;
    assert!(shift < -0.6 * alpha && shift > -1.4 * alpha, "DC shift of i_a {shift:.4} A, -alpha = {:.4} A", -alpha);
}

/// The encoder's eccentricity shows in the drive's recorded angle: it
/// differs from the true angle by `a sin(theta + phase)` (plus the constant
/// of where the drive starts counting).
#[test]
fn encoder_error_shows_in_the_recorded_angle() {
    let rig = rig();
    let error = EncoderError { eccentricity_rad: 0.004, phase_rad: 0.8 };
    let run = travel(
        &rig,
        70.5,
        Direction::Up,
        &options(&rig, Effects { encoder_error: Some(error), ..Effects::none() }, 7.0),
    );
    let range = constant_speed_range(&run, rig.travel.rated_speed_mps, 0.5);
    let r = rig.mechanics.sheave_radius_m;
    let lw0 = run.lw_m[0];
    let diffs: Vec<f64> = range.clone().map(|i| run.angle_rad[i] - (run.lw_m[i] - lw0) / r).collect();
    let offset = mean(&diffs);
    let d: Vec<f64> = diffs.iter().map(|x| x - offset).collect();
    let shifted: Vec<f64> = range.clone().map(|i| (run.lw_m[i] - lw0) / r + error.phase_rad).collect();
    // Least squares of d = A sin(theta + phase) + B cos(theta + phase).
    let [b, a] = dsp::sine_fit(&d, &shifted, 1.0);
    println!("angle error: {a:.5} rad in phase, {b:.5} rad in quadrature (a = {})", error.eccentricity_rad);
    assert!((a - error.eccentricity_rad).abs() < 0.05 * error.eccentricity_rad);
    assert!(b.abs() < 0.1 * error.eccentricity_rad);
}

/// The elastic brake: at the stop the drive hands the out-of-balance
/// torque to the brake (PWM off), the sheave turns onto the clamp and the
/// ropes ring: a car-acceleration transient the nominal (frozen) brake does
/// not have; the sheave rings at the clamped line's eigenfrequency near
/// `sqrt(k / I)`; the drive does not trip.
#[test]
fn brake_stop_rings_at_the_stop() {
    let rig = rig();
    let brake = plant::effects::BrakeStop { clamp_stiffness_nm_per_rad: 3.0e4, clamp_damping_nms_per_rad: 5.0 };
    let spec = TravelSpec { m_car_kg: 70.5, direction: Direction::Up, lw_start_m: 3.0, lw_end_m: 3.6 };
    let run_with = |effects: Effects| {
        let options = SimOptions { effects, tail_s: 1.0, ..SimOptions::for_rig(&rig) };
        simulate_travel(&rig, &spec, &options, None).expect("the drive completes the travel without a trip")
    };
    let clamped = run_with(Effects { brake_stop: Some(brake), ..Effects::none() });
    let nominal = run_with(Effects::none());
    // PWM off: the first Idle sample after brake set.
    let off = |run: &TravelRun| run.drive_state.windows(2).position(|w| w[0] == 5.0 && w[1] == 0.0).unwrap() + 1;
    let fs = clamped.sample_rate_hz;
    let window = |run: &TravelRun, signal: &[f64]| signal[off(run)..off(run) + (0.5 * fs) as usize].to_vec();
    let peak = |v: &[f64]| v.iter().fold(0.0f64, |a, b| a.max(b.abs()));
    let before = |run: &TravelRun| peak(&run.acc_car_mps2[off(run) - (0.1 * fs) as usize..off(run)]);
    let with_peak = peak(&window(&clamped, &clamped.acc_car_mps2));
    let nominal_peak = peak(&window(&nominal, &nominal.acc_car_mps2));
    println!(
        "car acceleration after PWM off: {with_peak:.4} m/s^2 with the clamp, {nominal_peak:.4} nominal (before: {:.4} / {:.4})",
        before(&clamped),
        before(&nominal)
    );
    assert!(with_peak > 3.0 * nominal_peak && with_peak > 2.0 * before(&clamped));
    // Statically the clamp takes the whole out-of-balance torque: the sheave
    // settles `tau_ob / k` back (the ropes return to their static forces).
    let settle = |run: &TravelRun| run.lw_m[off(run) + (0.9 * fs) as usize] - run.lw_m[off(run) - 1];
    let chain = plant::rope::ChainParams::from_rig(&rig, 70.5);
    let r = rig.mechanics.sheave_radius_m;
    let expected = -r * chain.out_of_balance_torque_nm(clamped.lw_m[off(&clamped)]) / brake.clamp_stiffness_nm_per_rad;
    println!(
        "rope at the sheave after the hand-over: {:.3e} m (r tau_ob / k = {expected:.3e} m), nominal {:.1e} m",
        settle(&clamped),
        settle(&nominal)
    );
    assert!((settle(&clamped) - expected).abs() < 0.03 * expected.abs());
    assert_eq!(settle(&nominal), 0.0);

    // The sheave's ringing frequency against the clamped line's eigenvalue.
    let effects = Effects { brake_stop: Some(brake), ..Effects::none() };
    let lw_end = clamped.lw_m[off(&clamped)];
    let plant = Plant::with_effects(&rig, 70.5, lw_end, &effects);
    let layout = plant.line().layout;
    let lumped = plant.line().lumped(&plant.chain, 0.0);
    let r2 = rig.mechanics.sheave_radius_m.powi(2);
    let f =
        line_frequencies_hz(&lumped, 0, layout.nodes - 1, &[(layout.sheave, brake.clamp_stiffness_nm_per_rad / r2)]);
    let simple = brake.clamp_frequency_hz(rig.mechanics.sheave_inertia_kg_m2);
    let sheave_mode = f.iter().copied().min_by(|a, b| (a - simple).abs().total_cmp(&(b - simple).abs())).unwrap();
    let speed = window(&clamped, &clamped.shaft_speed_radps);
    let spectrum = amplitude_spectrum(&speed, fs, 16).unwrap();
    let ringing = spectrum.peak_near(sheave_mode, 0.3).unwrap();
    println!(
        "sheave rings at {:.2} Hz; clamped line mode {sheave_mode:.2} Hz; sqrt(k/I)/2pi = {simple:.2} Hz; modes {f:.2?}",
        ringing.frequency_hz
    );
    assert!((ringing.frequency_hz - sheave_mode).abs() < 0.03 * sheave_mode);
    assert!((sheave_mode - simple).abs() < 0.15 * simple);
}

/// Every mechanical effect on, 8 elements per side on the shortest
/// counterweight side: the closed loop with a coarse `max_step_s` (one PWM
/// period) and a 2048 Hz recording stays stable (the plant limits its own
/// step) and agrees with a run at an eighth of that step.
#[test]
fn the_extended_plant_is_stable_and_accurate_with_a_coarse_step() {
    let rig = rig();
    let mut effects = Effects::none();
    for kind in [
        EffectKind::TensionStiffening,
        EffectKind::DivertingPulley,
        EffectKind::CarFrameMode,
        EffectKind::CoulombGuideFriction,
        EffectKind::BrakeStop,
        EffectKind::SheaveEccentricity,
    ] {
        effects.set(kind, &kind.defaults()).unwrap();
    }
    effects.set(EffectKind::RopeDiscretization, &[8.0]).unwrap();
    let run = |max_step_s: f64| {
        let options = SimOptions { max_step_s, sample_rate_hz: 2048.0, ..options(&rig, effects, 3.0) };
        travel(&rig, 70.5, Direction::Up, &options)
    };
    let coarse = run(1.0 / 16000.0);
    let fine = run(1.0 / 128000.0);
    let rms = (fine.acc_car_mps2.iter().map(|a| a * a).sum::<f64>() / fine.acc_car_mps2.len() as f64).sqrt();
    let worst = coarse.acc_car_mps2.iter().zip(&fine.acc_car_mps2).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    println!("car acceleration: rms {rms:.4e} m/s^2, largest coarse - fine difference {worst:.3e} m/s^2");
    assert!(coarse.acc_car_mps2.iter().all(|a| a.is_finite()));
    assert!(rms > 1e-3 && worst < 0.02 * rms);
}
