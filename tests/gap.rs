//! The sim-to-real gap diagnosis (the `diagnosis` crate) on data whose truth
//! the test knows and the tool does not:
//!
//! - blind test: for every effect of the library, datasets from the full
//!   plant with that effect at random parameters, with sensor noise; the
//!   diagnosis must name the right effect first in at least 80 % of the
//!   cases, never say `nominal` when the effect changes the car acceleration
//!   by more than the noise, and for every `explained` case with the right
//!   effect shrink the held-out gap by at least 70 %;
//! - the nominal plant with off-nominal EA and damping: `nominal` after
//!   calibration, no effect reported;
//! - an effect not in the library (guide-rail joints kicking the car):
//!   `unexplained`, located in the mechanics, on the car, while it moves.
//!
//! Datasets are small to keep the test short: two car masses, up and down,
//! over 2.5 m of travel, and two free decays, sampled at 16 kHz. The blind
//! test runs three effects by default; the sweep over all ten is an ignored
//! test (`cargo test --release -p host-sim --test integration -- --ignored
//! blind_every_effect_is_named_and_removes_the_held_out_gap --nocapture`).

use closed_loop::synthetic::{add_noise, make_dataset, DatasetSpec};
use closed_loop::{simulate_travel_faulted, SimOptions, TravelSpec};
use diagnosis::{diagnose, GapOptions, GapReport, Verdict};
use drive_core::config::Direction;
use plant::effects::{EffectKind, Effects};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use recording::{Recording, ACC_CAR, ACC_CW, I_A, I_B, I_C, KNOWN_COLUMNS};
use rig_config::RigConfig;

use crate::support::{assert_unexplained_on_the_moving_car, RailJoints};

const ACC_NOISE_MPS2: f64 = 0.01;
const CURRENT_NOISE_A: f64 = 0.02;

fn rig() -> RigConfig {
    RigConfig::embedded_default().expect("the embedded rig loads")
}

fn spec(rig: &RigConfig, effects: Effects) -> DatasetSpec {
    DatasetSpec {
        m_car_kg: vec![45.5, 70.5],
        lw_low_m: 3.0,
        lw_high_m: 5.5,
        decay_masses_kg: vec![45.5, 70.5],
        decay_rope_length_m: 4.0,
        decay_duration_s: 2.0,
        sample_rate_hz: 16000.0,
        max_step_s: 0.5 / rig.control.current_loop_hz,
        acc_noise_mps2: 0.0,
        current_noise_a: 0.0,
        seed: 0,
        effects,
    }
}

fn with_noise(mut dataset: Vec<(String, Recording)>, seed: u64) -> Vec<(String, Recording)> {
    let mut rng = StdRng::seed_from_u64(seed);
    for (_, r) in dataset.iter_mut() {
        for c in [ACC_CAR, ACC_CW] {
            add_noise(r, c, ACC_NOISE_MPS2, &mut rng);
        }
        for c in [I_A, I_B, I_C] {
            add_noise(r, c, CURRENT_NOISE_A, &mut rng);
        }
    }
    dataset
}

fn run(rig: &RigConfig, name: &str, dataset: &[(String, Recording)]) -> GapReport {
    diagnose(rig, name, dataset, &GapOptions::default(), &|_, _, _| {}).expect("the diagnosis runs")
}

/// Largest RMS over the recordings of the difference of the car
/// acceleration between two datasets (noise-free, or with the same noise),
/// m/s^2.
pub(crate) fn car_change(a: &[(String, Recording)], b: &[(String, Recording)]) -> f64 {
    a.iter()
        .zip(b)
        .map(|((_, x), (_, y))| {
            let (x, y) = (&x.column(ACC_CAR).unwrap().values, &y.column(ACC_CAR).unwrap().values);
            let n = x.len().min(y.len());
            (x[..n].iter().zip(&y[..n]).map(|(p, q)| (p - q).powi(2)).sum::<f64>() / n as f64).sqrt()
        })
        .fold(0.0, f64::max)
}

/// Random parameters of `kind`, in ranges a rig could show and the drive
/// rides through (an effect not listed: its defaults).
pub(crate) fn draw(kind: EffectKind, rng: &mut StdRng) -> Vec<f64> {
    let mut v = kind.defaults();
    let log_uniform = |rng: &mut StdRng, lo: f64, hi: f64| (rng.gen_range(lo.ln()..hi.ln())).exp();
    match kind {
        EffectKind::TensionStiffening => v[0] = rng.gen_range(0.2..0.8),
        EffectKind::DivertingPulley => v[0] = log_uniform(rng, 0.01, 0.1),
        EffectKind::RopeDiscretization => v[0] = rng.gen_range(2..=8) as f64,
        EffectKind::CarFrameMode => {
            v[0] = log_uniform(rng, 120.0, 350.0);
            v[1] = log_uniform(rng, 0.01, 0.05);
        }
        EffectKind::CoulombGuideFriction => v[0] = rng.gen_range(15.0..60.0),
        EffectKind::BrakeStop => v[0] = log_uniform(rng, 5.0e3, 1.0e5),
        EffectKind::SheaveEccentricity => {
            v[0] = rng.gen_range(0.002..0.01);
            v[1] = rng.gen_range(0.0..std::f64::consts::TAU);
        }
        EffectKind::DeadTime => v[0] = rng.gen_range(0.2e-6..0.6e-6),
        EffectKind::CurrentSensorError => {
            v[0] = rng.gen_range(-0.3..0.3);
            v[1] = rng.gen_range(-0.3..0.3);
            v[2] = rng.gen_range(-0.02..0.02);
            v[3] = rng.gen_range(-0.02..0.02);
        }
        EffectKind::EncoderError => {
            v[0] = rng.gen_range(0.001..0.005);
            v[1] = rng.gen_range(0.0..std::f64::consts::TAU);
        }
        // An effect added to the library runs at its defaults until its
        // range of rig-like strengths is written here.
        #[allow(unreachable_patterns)]
        _ => {}
    }
    v
}

/// The blind test on the effects `kinds`: the parameters of every effect
/// of the library are drawn in turn from one seed, and only those of
/// `kinds` are run, so that a case of a subset is the same case (same
/// parameters, same noise) as in the full sweep.
fn blind(kinds: &[EffectKind]) {
    let rig = rig();
    let nominal = make_dataset(&rig, &spec(&rig, Effects::none())).expect("nominal dataset");
    let draws: usize = std::env::var("GAP_BLIND_DRAWS").ok().and_then(|s| s.parse().ok()).unwrap_or(1);
    let mut rng = StdRng::seed_from_u64(2026);
    let mut rows = Vec::new();
    for kind in EffectKind::ALL {
        for k in 0..draws {
            let values = draw(kind, &mut rng);
            if !kinds.contains(&kind) {
                continue;
            }
            let mut effects = Effects::none();
            effects.set(kind, &values).expect("drawn parameters are in range");
            let clean = make_dataset(&rig, &spec(&rig, effects)).expect("full-plant dataset");
            let change = car_change(&clean, &nominal);
            let data = with_noise(clean, 100 + k as u64);
            let report = run(&rig, kind.name(), &data);
            let best = report.ranking.first().expect("a ranking");
            rows.push((
                kind,
                values,
                change,
                report.verdict,
                best.name.clone(),
                best.held_out_shrink,
                report.runtime_s,
            ));
        }
    }
    println!(
        "{:<24} {:>10} {:>11} {:<12} {:<44} {:>7} {:>6}",
        "effect", "car change", "/ noise", "verdict", "first", "shrink", "time"
    );
    for (kind, values, change, verdict, first, shrink, time) in &rows {
        println!(
            "{:<24} {:>10.4} {:>11.2} {:<12} {:<44} {:>6.0}% {:>5.1}s  {:?}",
            kind.name(),
            change,
            change / ACC_NOISE_MPS2,
            format!("{verdict:?}"),
            first,
            100.0 * shrink,
            time,
            values
        );
    }
    let right = rows.iter().filter(|r| r.4 == r.0.name()).count();
    println!("right effect first: {right} of {}", rows.len());
    for (kind, _, change, verdict, ..) in &rows {
        assert!(
            !(*change > ACC_NOISE_MPS2 && *verdict == Verdict::Nominal),
            "{}: the effect changes the car acceleration by {change:.4} m/s^2 RMS (noise {ACC_NOISE_MPS2}) but the verdict is nominal",
            kind.name()
        );
    }
    for (kind, _, _, verdict, first, shrink, _) in &rows {
        if *verdict == Verdict::Explained && first == kind.name() {
            assert!(*shrink >= 0.7, "{}: held-out gap shrinks by only {:.0} %", kind.name(), 100.0 * shrink);
        }
    }
    assert!(right as f64 >= 0.8 * rows.len() as f64, "right effect first in only {right} of {} cases", rows.len());
}

/// The effects of the blind test run by default, three of the ten (each case
/// is a dataset and a diagnosis, about a minute on two cores): a mechanical
/// effect in the travels, one at the stop, and a sensor error of the drive.
const SUBSET_EFFECTS: [EffectKind; 3] =
    [EffectKind::CoulombGuideFriction, EffectKind::BrakeStop, EffectKind::CurrentSensorError];

/// The blind test on SUBSET_EFFECTS, the same cases as in the full sweep.
#[test]
fn blind_subset_effects_are_named_and_remove_the_held_out_gap() {
    blind(&SUBSET_EFFECTS);
}

/// The blind test on every effect of the library (about 7 min on two
/// cores): `cargo test --release -p host-sim --test integration -- --ignored
/// blind_every_effect_is_named_and_removes_the_held_out_gap --nocapture`.
#[test]
#[ignore = "full sweep: run with --ignored"]
fn blind_every_effect_is_named_and_removes_the_held_out_gap() {
    blind(&EffectKind::ALL);
}

#[test]
fn off_nominal_ea_and_damping_are_calibrated_away() {
    let rig = rig();
    let mut truth = rig.clone();
    truth.mechanics.rope_ea_n *= 1.15;
    truth.mechanics.c_car_kg_per_s *= 1.4;
    truth.mechanics.c_cw_kg_per_s *= 1.4;
    truth.mechanics.c_sheave_nms_per_rad *= 1.3;
    let data = with_noise(make_dataset(&truth, &spec(&truth, Effects::none())).expect("dataset"), 7);
    let report = run(&rig, "off-nominal EA and damping", &data);
    println!(
        "calibrated EA {:.4e} N (truth {:.4e}), guide damping {:.1} kg/s (truth {:.1}), sheave {:.3} (truth {:.3}); \
         nominal excess gap {:.2} dB, persistent cell {:?}, verdict {:?}",
        report.calibration.rope_ea_n,
        truth.mechanics.rope_ea_n,
        report.calibration.guide_damping_kg_per_s,
        truth.mechanics.c_car_kg_per_s,
        report.calibration.sheave_damping_nms_per_rad,
        truth.mechanics.c_sheave_nms_per_rad,
        report.nominal_excess_db,
        report.persistent_cell.as_ref().map(diagnosis::report::persistent_text),
        report.verdict
    );
    assert!((report.calibration.rope_ea_n / truth.mechanics.rope_ea_n - 1.0).abs() < 0.03);
    assert_eq!(report.verdict, Verdict::Nominal);
    assert!(report.explained_by.is_none());
}

#[test]
fn an_effect_outside_the_library_is_unexplained_and_located() {
    let rig = rig();
    let s = spec(&rig, Effects::none());
    let mut dataset: Vec<(String, Recording)> =
        make_dataset(&rig, &DatasetSpec { m_car_kg: Vec::new(), ..s.clone() }).expect("decays");
    for &m in &s.m_car_kg {
        for direction in [Direction::Up, Direction::Down] {
            let (lw_start_m, lw_end_m) =
                if direction == Direction::Up { (s.lw_low_m, s.lw_high_m) } else { (s.lw_high_m, s.lw_low_m) };
            let travel = TravelSpec { m_car_kg: m, direction, lw_start_m, lw_end_m };
            let options =
                SimOptions { max_step_s: s.max_step_s, sample_rate_hz: s.sample_rate_hz, ..SimOptions::for_rig(&rig) };
            // 0.4 m/s over a 4 mm step: the pulse lasts 10 ms.
            let mut joints = RailJoints::kicking_the_car();
            let mut controller = drive_core::Controller::new(&rig.drive_config());
            let run = simulate_travel_faulted(&rig, &travel, &options, &mut controller, Some(&mut joints), None, None)
                .expect("the travel with rail joints runs");
            let mut recording = run.to_recording(&travel, rig.mechanics.m_cw_kg, "rail joints".to_string());
            recording.columns.retain(|c| KNOWN_COLUMNS.contains(&c.name.as_str()));
            let name = format!("travel_{}_m{m:.1}", if direction == Direction::Up { "up" } else { "down" });
            dataset.push((name, recording));
        }
    }
    let data = with_noise(dataset, 11);
    let report = run(&rig, "rail joints", &data);
    assert_unexplained_on_the_moving_car(&report);
}
