//! The reduced 5-DOF observer (`drive_core::observer`) against the plant: for
//! every nominal travel (4 car masses x up/down, full travel, the
//! plant with its torque ripple and quantised sensors) the closed loop runs
//! with the drive core, and the observer is fed offline at the speed-loop
//! rate with exactly what the chip has at each speed tick: the encoder
//! counter and the measured q current (`Kt i_q`). Its car acceleration is
//! compared with the plant's, both band-passed 1-80 Hz (zero phase), from
//! brake lift to landing (end of the `Travel` state). By default two of the
//! travels run (the ones with the largest error); the sweeps over all 8 are
//! ignored tests, run with `cargo test --release -p host-sim --test integration --
//! --ignored NAME`.

use crate::support::{rig, rms};
use closed_loop::{simulate_travel_with, SimOptions, StepLog, TravelRun, TravelSpec};
use drive_core::config::Direction;
use drive_core::observer::{ChainObserver, ObserverTuning};
use drive_core::{Controller, DriveState};
use dsp::highpass_zero_phase;
use plant::modes::natural_modes;
use plant::rope::ChainParams;
use rig_config::RigConfig;

/// Evaluation band, Hz (1-80 Hz).
const BAND_HZ: (f64, f64) = (1.0, 80.0);

/// One travel's comparison.
struct Outcome {
    label: String,
    truth_rms_mps2: f64,
    error_rms_mps2: f64,
    final_ea_n: f32,
    restarts: u32,
}

impl Outcome {
    fn ratio(&self) -> f64 {
        self.error_rms_mps2 / self.truth_rms_mps2
    }
}

/// Zero-phase 2nd-order Butterworth low-pass (bilinear, forward and back),
/// started from rest: the signals start near zero after the 1 Hz high-pass.
fn lowpass_zero_phase(signal: &[f64], sample_rate_hz: f64, cutoff_hz: f64) -> Vec<f64> {
    let k = (std::f64::consts::PI * cutoff_hz / sample_rate_hz).tan();
    let norm = 1.0 / (1.0 + std::f64::consts::SQRT_2 * k + k * k);
    let b0 = k * k * norm;
    let (b1, b2) = (2.0 * b0, b0);
    let a1 = 2.0 * (k * k - 1.0) * norm;
    let a2 = (1.0 - std::f64::consts::SQRT_2 * k + k * k) * norm;
    let pass = |x: &mut Vec<f64>| {
        let (mut s1, mut s2) = (0.0, 0.0);
        for v in x.iter_mut() {
            let y = b0 * *v + s1;
            s1 = b1 * *v - a1 * y + s2;
            s2 = b2 * *v - a2 * y;
            *v = y;
        }
    };
    let mut out = signal.to_vec();
    pass(&mut out);
    out.reverse();
    pass(&mut out);
    out.reverse();
    out
}

fn band_pass(signal: &[f64], sample_rate_hz: f64) -> Vec<f64> {
    let high = highpass_zero_phase(signal, sample_rate_hz, BAND_HZ.0).expect("high-pass of a finite signal");
    lowpass_zero_phase(&high, sample_rate_hz, BAND_HZ.1)
}

/// Linear interpolation of the plant's 16384 Hz car acceleration at `t_s`.
fn truth_at(run: &TravelRun, t_s: f64) -> f64 {
    let position = t_s * run.sample_rate_hz;
    let i = (position.floor() as usize).min(run.acc_car_mps2.len() - 2);
    let frac = position - i as f64;
    run.acc_car_mps2[i] * (1.0 - frac) + run.acc_car_mps2[i + 1] * frac
}

/// Simulates one travel on `plant_rig` with the drive configured from the
/// nominal rig, feeds the observer (nominal model) from the step log and
/// compares its car acceleration with the plant's.
fn observe_travel(plant_rig: &RigConfig, m_car_kg: f64, direction: Direction, label: String) -> Outcome {
    let nominal = rig();
    let drive = nominal.drive_config();
    let spec = TravelSpec::full_travel(plant_rig, m_car_kg, direction);
    let mut controller = Controller::new(&drive);
    let mut log = StepLog::default();
    let run =
        simulate_travel_with(plant_rig, &spec, &SimOptions::for_rig(plant_rig), &mut controller, None, Some(&mut log))
            .unwrap_or_else(|e| panic!("{label}: the travel runs: {e}"));

    let divider = drive.speed_loop_divider() as usize;
    let step_s = 1.0 / drive.current_loop_hz as f64;
    let kt = drive.torque_constant_nm_per_a();
    let lift = log.steps.iter().position(|(_, out)| out.state == DriveState::BrakeLift).expect("the brake lifts");
    let landing = log.steps.iter().rposition(|(_, out)| out.state == DriveState::Travel).expect("the car travels");
    let brake_set = log.steps.iter().rposition(|(_, out)| out.state == DriveState::Hold).expect("the car holds");
    // First speed tick at or after brake lift (the controller's speed tick
    // runs on steps divisible by the divider).
    let first = lift.div_ceil(divider) * divider;

    let mut observer = ChainObserver::new(nominal.observer_model(), ObserverTuning::default()).expect("valid model");
    observer.start(spec.lw_start_m as f32, m_car_kg as f32, log.steps[first].0.encoder_count);
    let (mut estimate, mut truth, mut in_window) = (Vec::new(), Vec::new(), Vec::new());
    for k in (first..=brake_set).step_by(divider) {
        let (sensors, output) = &log.steps[k];
        let e = observer.update(sensors.encoder_count, kt * output.telemetry.iq_a);
        assert!(e.car_acceleration_mps2.is_finite(), "{label}: non-finite estimate at step {k}");
        estimate.push(e.car_acceleration_mps2 as f64);
        truth.push(truth_at(&run, k as f64 * step_s));
        in_window.push(k <= landing);
    }
    let rate_hz = drive.speed_loop_hz as f64;
    let truth_band = band_pass(&truth, rate_hz);
    let estimate_band = band_pass(&estimate, rate_hz);
    let window = in_window.iter().take_while(|&&w| w).count();
    let error: Vec<f64> = (0..window).map(|i| estimate_band[i] - truth_band[i]).collect();
    Outcome {
        label,
        truth_rms_mps2: rms(&truth_band[..window]),
        error_rms_mps2: rms(&error),
        final_ea_n: observer.estimate().rope_ea_n,
        restarts: observer.restarts(),
    }
}

/// The 8 travels of the rig with the plant's EA scaled by `ea_factor`, two at a time.
fn eight_travels(ea_factor: f64) -> Vec<Outcome> {
    let jobs: Vec<(f64, Direction)> =
        rig().mechanics.m_car_kg.iter().flat_map(|&m| [Direction::Up, Direction::Down].map(|d| (m, d))).collect();
    assert_eq!(jobs.len(), 8);
    travels(ea_factor, &jobs)
}

/// The travels `jobs` (car mass, direction) with the plant's EA scaled by
/// `ea_factor`, two at a time.
fn travels(ea_factor: f64, jobs: &[(f64, Direction)]) -> Vec<Outcome> {
    let mut plant_rig = rig();
    plant_rig.mechanics.rope_ea_n *= ea_factor;
    let plant_rig = &plant_rig;
    let mut outcomes: Vec<Outcome> = std::thread::scope(|scope| {
        let handles: Vec<_> = jobs
            .chunks(jobs.len().div_ceil(2))
            .map(|chunk| {
                scope.spawn(move || {
                    chunk
                        .iter()
                        .map(|&(m, d)| {
                            observe_travel(plant_rig, m, d, format!("EA x{ea_factor}, m_car {m:5.1} kg, {d:?}"))
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles.into_iter().flat_map(|h| h.join().expect("travel thread")).collect()
    });
    outcomes.sort_by(|a, b| a.label.cmp(&b.label));
    for o in &outcomes {
        println!(
            "{:34} truth RMS {:.3} m/s^2, error RMS {:.3} m/s^2 = {:5.1} %, EA estimate {:.3e} N, restarts {}",
            o.label,
            o.truth_rms_mps2,
            o.error_rms_mps2,
            100.0 * o.ratio(),
            o.final_ea_n,
            o.restarts
        );
    }
    outcomes
}

fn assert_all_below(outcomes: &[Outcome], limit: f64) {
    let worst = outcomes.iter().max_by(|a, b| a.ratio().total_cmp(&b.ratio())).expect("travels");
    println!("worst: {} at {:.1} % (limit {:.0} %)", worst.label, 100.0 * worst.ratio(), 100.0 * limit);
    for o in outcomes {
        assert_eq!(o.restarts, 0, "{}: the filter restarted", o.label);
        assert!(o.truth_rms_mps2 > 0.05, "{}: no car vibration to estimate ({:.3} m/s^2)", o.label, o.truth_rms_mps2);
        assert!(
            o.ratio() < limit,
            "{}: error RMS {:.1} % of the car vibration RMS, limit {:.0} %",
            o.label,
            100.0 * o.ratio(),
            100.0 * limit
        );
    }
}

/// The travels run by default (car mass, direction): those with the largest
/// error of the full sweep, nominal and with the EA off.
const SUBSET_TRAVELS: [(f64, Direction); 2] = [(70.5, Direction::Up), (33.0, Direction::Down)];

/// The nominal travels run by default: SUBSET_TRAVELS of the 8.
#[test]
fn car_acceleration_error_under_25_percent_on_a_subset_of_the_nominal_travels() {
    let outcomes = travels(1.0, &SUBSET_TRAVELS);
    assert_all_below(&outcomes, 0.25);
}

/// The full sweep: `cargo test --release -p host-sim --test integration -- --ignored
/// car_acceleration_error_under_25_percent_on_all_8_nominal_travels --nocapture`.
#[test]
#[ignore = "full sweep: run with --ignored"]
fn car_acceleration_error_under_25_percent_on_all_8_nominal_travels() {
    let outcomes = eight_travels(1.0);
    assert_all_below(&outcomes, 0.25);
}

/// Errors under 40 % and the EA estimate moving towards the plant's, on
/// the travels `outcomes` of a plant whose EA is `factor` times nominal.
fn assert_ea_off(outcomes: &[Outcome], factor: f64) {
    assert_all_below(outcomes, 0.40);
    // The filter's stiffness scale moves from nominal towards the plant's EA.
    for o in outcomes {
        let scale = o.final_ea_n as f64 / rig().mechanics.rope_ea_n;
        assert!(
            (scale - factor).abs() < 0.5 * (1.0 - factor).abs(),
            "{}: EA scale estimate {scale:.3} not closer to {factor} than to 1",
            o.label
        );
    }
}

/// The plant's EA off by 20 % on the travels run by default: SUBSET_TRAVELS of the 8.
#[test]
fn car_acceleration_error_under_40_percent_with_the_plant_ea_off_by_20_percent_on_a_subset_of_the_travels() {
    for factor in [0.8, 1.2] {
        assert_ea_off(&travels(factor, &SUBSET_TRAVELS), factor);
    }
}

/// The full sweep: `cargo test --release -p host-sim --test integration -- --ignored
/// car_acceleration_error_under_40_percent_with_the_plant_ea_off_by_20_percent --nocapture`.
#[test]
#[ignore = "full sweep: run with --ignored"]
fn car_acceleration_error_under_40_percent_with_the_plant_ea_off_by_20_percent() {
    for factor in [0.8, 1.2] {
        assert_ea_off(&eight_travels(factor), factor);
    }
}

/// The reduced model keeps the two elastic modes of the 5-DOF chain in the
/// band: its frequencies (closed-form roots of the free-free 3-mass chain,
/// `l^2 - l (k_w (1/m_w + 1/m_sh) + k_c (1/m_sh + 1/m_c)) + k_w k_c (m_w + m_sh + m_c) / (m_w m_sh m_c) = 0`)
/// against `host-sim`'s 5-DOF eigenvalues (Eqn 10), every car mass, 1 to 7.6 m.
#[test]
fn reduced_model_keeps_the_elastic_modes_of_the_5dof_chain() {
    let rig = rig();
    let model = rig.observer_model();
    let mut worst: f64 = 0.0;
    for &m_car in &rig.mechanics.m_car_kg {
        let params = ChainParams::from_rig(&rig, m_car);
        for lw in [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.6] {
            let c = model.reduced(lw as f32, m_car as f32, 1.0);
            let (mw, msh, mc) = (c.cw_mass_kg as f64, c.sheave_mass_kg as f64, c.car_mass_kg as f64);
            let (kw, kc) = (c.cw_stiffness_n_per_m as f64, c.car_stiffness_n_per_m as f64);
            let b = kw * (1.0 / mw + 1.0 / msh) + kc * (1.0 / msh + 1.0 / mc);
            let q = kw * kc * (mw + msh + mc) / (mw * msh * mc);
            let disc = (b * b - 4.0 * q).sqrt();
            let reduced = [(b - disc) / 2.0, (b + disc) / 2.0].map(|l| l.sqrt() / std::f64::consts::TAU);
            let full = natural_modes(&params, lw).frequencies_hz;
            let errors = [reduced[0] / full[1] - 1.0, reduced[1] / full[2] - 1.0];
            println!(
                "m_car {m_car:5.1} kg, lw {lw:3.1} m: reduced {:7.3} {:7.3} Hz, 5-DOF {:7.3} {:7.3} Hz ({:+.2} %, {:+.2} %)",
                reduced[0],
                reduced[1],
                full[1],
                full[2],
                100.0 * errors[0],
                100.0 * errors[1]
            );
            worst = errors.iter().fold(worst, |w, e| w.max(e.abs()));
        }
    }
    println!("largest difference {:.3} %", 100.0 * worst);
    assert!(worst < 0.01, "reduced model differs from the 5-DOF modes by {:.2} %", 100.0 * worst);
}
