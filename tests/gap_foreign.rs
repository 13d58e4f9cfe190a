//! The gap diagnosis on recordings of foreign rigs whose truth the test
//! knows and the tool does not: a commercial drive and a foreign data
//! acquisition drawn at random (`ForeignRig::random`), the nominal rig, a
//! parameter-only change (EA within +-20 %, damping within +-50 %) and the
//! library's effects at random strengths.
//!
//! CI runs two cases on one draw (tension stiffening, and guide-rail joints
//! that are not in the library) and the direct-axis lines of the nominal
//! rig, the electrical effects and every mechanical one on that draw, with
//! its currents recorded by clamps and by the drive's transducers, the
//! nominal rig of draw 109 (whose rope-mass modes ring through the
//! travel), and the nominal rig of a rig that is not the reference rig
//! (its masses, rope, sheave, an eight-pole-pair machine and its ripple
//! orders, given as the model's configuration) on draw 7, whose effects
//! are an ignored test; the
//! sweep over draws, the nominal and parameter-only rigs, every effect of
//! the library and the rail joints is an ignored test that prints the
//! whole table, each draw with its acquisition's variant (the
//! accelerometers' high-pass order, the currents recorded by clamps or by
//! the drive's transducers; `GAP_FOREIGN_CASES` picks cases: effect names,
//! `nominal` and `rail_joints`):
//! `cargo test --release -p host-sim --test integration gap_foreign:: -- --ignored --nocapture`
//! (`GAP_FOREIGN_DRAWS=N` draws, default 2, from `GAP_FOREIGN_FIRST`,
//! default 100: the foreign rig of `--foreign-seed 100` and on;
//! `GAP_FOREIGN_DUMP=DIR` writes each case's recordings to
//! `DIR/draw<d>_<case>/` for `host-sim gap`).

use closed_loop::foreign::ForeignRig;
use closed_loop::synthetic::{make_foreign_dataset_hooked, DatasetSpec, TravelHooks};
use diagnosis::attribute::FittedParameter;
use diagnosis::driven::holds_effect;
use diagnosis::{diagnose, GapOptions, GapReport, Verdict};
use dsp::welch_psd;
use plant::effects::{CurrentSensorError, EffectKind, Effects};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use recording::{Recording, ACC_CAR, I_A, I_B, I_C};
use rig_config::RigConfig;

use crate::gap::{car_change, draw};
use crate::support::{assert_unexplained_on_the_moving_car, rig, RailJoints};

/// One case of the sweep: what was drawn, what the diagnosis said.
struct Case {
    draw: u64,
    /// The acquisition's variant ([`acquisition_variant`]).
    variant: String,
    truth: String,
    change: Change,
    /// RMS white noise of the draw's accelerometers, m/s^2.
    noise_mps2: f64,
    /// The rig's EA (N), guide damping (kg/s) and sheave damping
    /// (N m s/rad) for the nominal and parameter-only rigs, whose
    /// calibration the sweep checks.
    calibration_truth: Option<(f64, f64, f64)>,
    report: GapReport,
}

/// How much a case's car acceleration differs from the nominal rig's (the
/// same acquisition noise in both), m/s^2, largest over the recordings.
#[derive(Clone, Copy, Debug, Default)]
struct Change {
    /// RMS of the sample-by-sample difference: it also counts the same
    /// vibration shifted in time (a closed loop perturbed at all drifts).
    rms_mps2: f64,
    /// `sqrt(sum_k |P_a(f_k) - P_b(f_k)| df)` of the two Welch densities
    /// (1 s segments, half overlap): the change of the spectrum, which the
    /// blind test holds against the noise.
    signature_mps2: f64,
}

impl Change {
    fn between(a: &[(String, Recording)], b: &[(String, Recording)]) -> Self {
        let signature = |(x, y): (&Recording, &Recording)| {
            let fs = x.meta.sample_rate_hz;
            let psd = |r: &Recording| {
                welch_psd(&r.column(ACC_CAR).expect("car acceleration").values, fs, fs.round() as usize, 0.5)
                    .expect("the car acceleration's spectrum")
            };
            let (p, q) = (psd(x), psd(y));
            let df = p.frequency_hz.get(1).copied().unwrap_or(0.0);
            (p.density.iter().zip(&q.density).map(|(u, v)| (u - v).abs()).sum::<f64>() * df).sqrt()
        };
        let signature_mps2 = a.iter().zip(b).map(|((_, x), (_, y))| signature((x, y))).fold(0.0, f64::max);
        Self { rms_mps2: car_change(a, b), signature_mps2 }
    }
}

/// Largest relative errors of the calibrated EA, guide damping and sheave
/// damping (the bounds the sample's identification meets).
const CALIBRATION_BOUNDS: (f64, f64, f64) = (0.02, 0.15, 0.10);

impl Case {
    /// An effect's case (not the nominal or parameter-only rig).
    fn is_effect(&self) -> bool {
        self.truth != "nominal" && !self.truth.starts_with("EA ") && self.truth != OUTSIDE
    }

    /// The effect's car-acceleration signature is at least twice the
    /// noise: the cases the blind test counts.
    fn counts(&self) -> bool {
        self.is_effect() && self.change.signature_mps2 >= 2.0 * self.noise_mps2
    }

    /// The verdict is not `nominal` and the ranking puts the true effect first.
    fn named_first(&self) -> bool {
        self.report.verdict != Verdict::Nominal
            && self.report.ranking.first().is_some_and(|b| self.truth.starts_with(&format!("{} ", b.name)))
    }

    /// Relative errors of the calibrated EA, guide and sheave damping.
    fn calibration_errors(&self) -> Option<(f64, f64, f64)> {
        self.calibration_truth.map(|truth| calibration_errors(&self.report, truth))
    }

    /// `explained` by the true effect.
    fn explained(&self) -> bool {
        self.report.verdict == Verdict::Explained
            && self.report.explained_by.as_deref().is_some_and(|e| self.truth.starts_with(&format!("{e} ")))
    }
}

/// The EA (N), guide damping (kg/s) and sheave damping (N m s/rad) of
/// `rig`, the values its calibration should find.
fn calibration_truth(rig: &RigConfig) -> (f64, f64, f64) {
    let m = &rig.mechanics;
    (m.rope_ea_n, m.c_car_kg_per_s, m.c_sheave_nms_per_rad)
}

/// Relative errors of `report`'s calibrated EA, guide and sheave damping
/// against `truth` ([`calibration_truth`]).
fn calibration_errors(report: &GapReport, (ea, guide, sheave): (f64, f64, f64)) -> (f64, f64, f64) {
    let c = &report.calibration;
    (c.rope_ea_n / ea - 1.0, c.guide_damping_kg_per_s / guide - 1.0, c.sheave_damping_nms_per_rad / sheave - 1.0)
}

/// The two car masses up and down over the full travel and their two free
/// decays, recorded by `foreign` from `truth` with `effects`.
fn foreign_dataset(truth: &RigConfig, foreign: &ForeignRig, effects: Effects) -> Vec<(String, Recording)> {
    foreign_dataset_hooked(truth, foreign, effects, None)
}

/// The same with every travel under a hook of `hooks` (something outside
/// the library).
fn foreign_dataset_hooked(
    truth: &RigConfig,
    foreign: &ForeignRig,
    effects: Effects,
    hooks: Option<TravelHooks>,
) -> Vec<(String, Recording)> {
    let spec = DatasetSpec {
        m_car_kg: vec![45.5, 70.5],
        decay_masses_kg: vec![45.5, 70.5],
        effects,
        ..DatasetSpec::rig(truth)
    };
    make_foreign_dataset_hooked(truth, &spec, foreign, hooks).expect("foreign dataset")
}

/// The foreign rig of draw `d`: drive and acquisition at random, as
/// `host-sim dataset --foreign-seed d` draws them.
fn foreign_rig(d: u64) -> ForeignRig {
    ForeignRig::random(&mut StdRng::seed_from_u64(d))
}

/// The foreign rig of draw 8 with its acquisition's accelerometers
/// high-passed in first order and its currents recorded by clamps (the
/// machine's true currents): draw 8 itself draws a second-order high-pass
/// and the drive's transducer currents. The CI tests on draw 8 are about
/// effects, not about those two variants, and keep the rig they were
/// measured on; the direct-axis lines of the transducers' errors also need
/// the true currents (recorded as the drive's transducer signals they are
/// clean: [`foreign_rig_current_sensor_error_recorded_by_the_drive_leaves_its_currents_clean`]).
fn draw_8_first_order_clamps() -> ForeignRig {
    let mut foreign = foreign_rig(8);
    let acquisition = foreign.acquisition.as_mut().expect("draw 8 records with its own acquisition");
    acquisition.highpass_order = 1;
    acquisition.drive_transducer_currents = false;
    foreign
}

/// The acquisition's variant of `foreign`: the order of the
/// accelerometers' high-pass and which currents it records.
fn acquisition_variant(foreign: &ForeignRig) -> String {
    foreign.acquisition.map_or("project".to_string(), |a| {
        format!("hp{} {}", a.highpass_order, if a.drive_transducer_currents { "drive" } else { "clamps" })
    })
}

fn diagnosed(model: &RigConfig, name: &str, data: &[(String, Recording)]) -> GapReport {
    diagnose(model, name, data, &GapOptions::default(), &|_, _, _| {}).expect("the diagnosis runs")
}

/// Writes a case's recordings to `$GAP_FOREIGN_DUMP/draw<d>_<case>/` when
/// that variable names a directory, so that one case of the sweep can be
/// run again with `host-sim gap` (as recordings in files: the values go
/// through the format's text).
fn dump(d: u64, case: &str, data: &[(String, Recording)]) {
    let Ok(root) = std::env::var("GAP_FOREIGN_DUMP") else { return };
    let dir = std::path::Path::new(&root).join(format!("draw{d}_{case}"));
    for (stem, recording) in data {
        recording::write_recording(&dir, stem, recording).expect("the dump is written");
    }
}

/// A rig whose EA and damping are drawn within +-20 % and +-50 %.
fn parameter_only(nominal: &RigConfig, rng: &mut StdRng) -> RigConfig {
    let mut truth = nominal.clone();
    let m = &mut truth.mechanics;
    m.rope_ea_n *= rng.gen_range(0.8..1.2);
    let guide = rng.gen_range(0.5..1.5);
    m.c_car_kg_per_s *= guide;
    m.c_cw_kg_per_s *= guide;
    m.c_sheave_nms_per_rad *= rng.gen_range(0.5..1.5);
    truth
}

fn print_table(cases: &[Case]) {
    println!(
        "{:>4} {:<10} {:<70} {:>10} {:>9} {:<12} {:<24} {:>7} {:>8} {:>10}  calibration error EA / guide / sheave",
        "draw", "daq", "truth", "car change", "sig/noise", "verdict", "first", "shrink", "excess", "persistent"
    );
    for c in cases {
        let (first, shrink) =
            c.report.ranking.first().map_or(("-".to_string(), 0.0), |b| (b.name.clone(), b.held_out_shrink));
        println!(
            "{:>4} {:<10} {:<70} {:>10.4} {:>9.1} {:<12} {:<24} {:>6.0}% {:>6.2}dB {:>8.2}dB  {}",
            c.draw,
            c.variant,
            c.truth,
            c.change.rms_mps2,
            c.change.signature_mps2 / c.noise_mps2,
            format!("{:?}", c.report.verdict),
            first,
            100.0 * shrink,
            c.report.nominal_excess_db,
            c.report.persistent_cell.as_ref().map_or(0.0, |p| p.rms_beyond_db),
            c.calibration_errors().map_or(String::new(), |(ea, guide, sheave)| format!(
                "{:+.1} % / {:+.1} % / {:+.1} %",
                100.0 * ea,
                100.0 * guide,
                100.0 * sheave
            ))
        );
    }
}

/// The library's effects in the sweep's order: those the torque-driven
/// model holds first, then the others, so that adding the others left every
/// earlier case (parameters and noise) as it was.
fn sweep_order() -> Vec<EffectKind> {
    let (held, others): (Vec<EffectKind>, Vec<EffectKind>) =
        EffectKind::ALL.into_iter().partition(|k| holds_effect(*k, false));
    held.into_iter().chain(others).collect()
}

/// What the sweep runs, from `GAP_FOREIGN_CASES` (a comma-separated list of
/// effect names, `nominal`, which stands for the nominal and the
/// parameter-only rig, and `rail_joints`); all of them when unset.
fn selected(name: &str) -> bool {
    std::env::var("GAP_FOREIGN_CASES").map_or(true, |list| list.split(',').any(|c| c.trim() == name))
}

/// One draw: the nominal rig, a parameter-only rig and each effect of the
/// library, as [`selected`]. The parameters of every case are drawn in
/// turn from one seed whatever is run, so that a case run alone is the same
/// case as in the whole sweep. The dead time and the current-sensor errors
/// act on the simulated machine's own phases, so their cases run with the
/// draw's drive turned to a rotor starting at 0 deg.
fn sweep_draw(d: u64, cases: &mut Vec<Case>) {
    let model = rig();
    let foreign = foreign_rig(d);
    let mut rng = StdRng::seed_from_u64(1000 + d);
    let nominal = foreign_dataset(&model, &foreign, Effects::none());
    let noise_mps2 = foreign.acquisition.map_or(0.0, |a| a.acc_noise_mps2);
    let variant = acquisition_variant(&foreign);
    let truth = parameter_only(&model, &mut rng);
    if selected("nominal") {
        dump(d, "nominal", &nominal);
        let report = diagnosed(&model, "nominal", &nominal);
        cases.push(Case {
            draw: d,
            variant: variant.clone(),
            truth: "nominal".into(),
            change: Change::default(),
            noise_mps2,
            calibration_truth: Some(calibration_truth(&model)),
            report,
        });
        let data = foreign_dataset(&truth, &foreign, Effects::none());
        dump(d, "param_only", &data);
        let m = &truth.mechanics;
        let name = format!(
            "EA {:.3e} N, guide {:.0} kg/s, c_sheave {:.2} N m s/rad",
            m.rope_ea_n, m.c_car_kg_per_s, m.c_sheave_nms_per_rad
        );
        let report = diagnosed(&model, &name, &data);
        let change = Change::between(&data, &nominal);
        let calibration_truth = Some(calibration_truth(&truth));
        cases.push(Case {
            draw: d,
            variant: variant.clone(),
            truth: name,
            change,
            noise_mps2,
            calibration_truth,
            report,
        });
    }
    // The acquisition's noise is drawn from the same seed in both datasets,
    // so it cancels in the change.
    let mut at_zero_deg: Option<(ForeignRig, Vec<(String, Recording)>)> = None;
    for kind in sweep_order() {
        let values = draw(kind, &mut rng);
        if !selected(kind.name()) {
            continue;
        }
        let mut effects = Effects::none();
        effects.set(kind, &values).expect("drawn parameters are in range");
        let (rig_of_case, reference) = if matches!(kind, EffectKind::DeadTime | EffectKind::CurrentSensorError) {
            let (rig, data) = at_zero_deg.get_or_insert_with(|| {
                let mut turned = foreign;
                if let Some(drive) = turned.drive.as_mut() {
                    drive.rotor_start_angle_deg = 0.0;
                }
                (turned, foreign_dataset(&model, &turned, Effects::none()))
            });
            (*rig, &*data)
        } else {
            (foreign, &nominal)
        };
        let data = foreign_dataset(&model, &rig_of_case, effects);
        let values_text: Vec<String> = values
            .iter()
            .map(|v| if v.abs() < 1e-3 && *v != 0.0 { format!("{v:.3e}") } else { format!("{v:.4}") })
            .collect();
        let truth = format!("{} [{}]", kind.name(), values_text.join(", "));
        dump(d, kind.name(), &data);
        let report = diagnosed(&model, &truth, &data);
        let change = Change::between(&data, reference);
        cases.push(Case {
            draw: d,
            variant: variant.clone(),
            truth,
            change,
            noise_mps2,
            calibration_truth: None,
            report,
        });
    }
    if selected("rail_joints") {
        let data = rail_joints_dataset(&model, &foreign);
        dump(d, "rail_joints", &data);
        let report = diagnosed(&model, OUTSIDE, &data);
        let change = Change::between(&data, &nominal);
        let truth = OUTSIDE.into();
        cases.push(Case { draw: d, variant, truth, change, noise_mps2, calibration_truth: None, report });
    }
}

/// The case of an effect outside the library: guide-rail joints kicking the
/// car ([`RailJoints::kicking_the_car`]).
const OUTSIDE: &str = "rail_joints (not in the library)";

/// The dataset of `foreign` on `model` with rail joints kicking the car.
fn rail_joints_dataset(model: &RigConfig, foreign: &ForeignRig) -> Vec<(String, Recording)> {
    let hooks = || Box::new(RailJoints::kicking_the_car()) as Box<dyn closed_loop::FaultHook>;
    foreign_dataset_hooked(model, foreign, Effects::none(), Some(&hooks))
}

/// Guide-rail joints on a foreign rig (not an effect of the library):
/// `unexplained`, located in the mechanics, on the car, while it moves.
#[test]
fn foreign_rig_rail_joints_are_unexplained_and_located() {
    let model = rig();
    let report = diagnosed(&model, OUTSIDE, &rail_joints_dataset(&model, &draw_8_first_order_clamps()));
    assert_unexplained_on_the_moving_car(&report);
}

/// A foreign acquisition whose accelerometers are high-passed by a
/// second-order Butterworth at 1 Hz (an acquisition's own AC coupling, not
/// the sensor's single pole) on the nominal rig: the diagnosis finds the
/// filter's order and corner from each travel, applies them to the model
/// and keeps the rig `nominal`.
#[test]
fn foreign_rig_second_order_accelerometer_highpass_is_found_and_the_rig_stays_nominal() {
    let model = rig();
    let mut foreign = draw_8_first_order_clamps();
    let acquisition = foreign.acquisition.as_mut().expect("draw 8 records with its own acquisition");
    acquisition.highpass_order = 2;
    acquisition.highpass_hz = 1.0;
    let report = diagnosed(&model, "second-order high-pass", &foreign_dataset(&model, &foreign, Effects::none()));
    println!("verdict {:?}, excess {:.2} dB", report.verdict, report.nominal_excess_db);
    // One step of the candidates' geometric grid of corners.
    let step = (3.0f64 / 0.05).powf(1.0 / 35.0);
    assert!(!report.rig_speed_loops.is_empty());
    for l in &report.rig_speed_loops {
        let found = l.accelerometer_highpass;
        println!("{}: {}", l.recording, found.text());
        assert!(found.order == 2 && (found.corner_hz / 1.0).ln().abs() <= step.ln(), "{}: {found:?}", l.recording);
    }
    assert_eq!(report.verdict, Verdict::Nominal);
}

/// The nominal rig of draw 109 (the reference rig, its drive and
/// acquisition drawn at random): the rope-mass modes of its 128-256 Hz
/// ring with what the measured torque put into them over a whole travel,
/// and the torque-driven model's share of that turns with EA by a fraction
/// of a per mil. The model is run across the calibration's uncertainty
/// (its ends and middle points, `calibrate::PERTURBATION_STEPS`) and the
/// rig stays `nominal`; with the ends alone it was `unexplained` (0.16 dB,
/// the car's 128-161 Hz at constant speed). The attribution tries one
/// effect: the verdict on a nominal rig rests on the nominal model.
#[test]
fn foreign_nominal_rig_whose_rope_modes_ring_through_the_travel_stays_nominal() {
    let model = rig();
    let data = foreign_dataset(&model, &foreign_rig(109), Effects::none());
    let options = GapOptions { effects: vec![EffectKind::CoulombGuideFriction], ..GapOptions::default() };
    let report = diagnose(&model, "draw 109", &data, &options, &|_, _, _| {}).expect("the diagnosis runs");
    let errors = calibration_errors(&report, calibration_truth(&model));
    println!(
        "verdict {:?}, excess {:.2} dB, calibration errors {errors:.4?}",
        report.verdict, report.nominal_excess_db
    );
    assert_eq!(report.verdict, Verdict::Nominal);
    let (ea, guide, sheave) = CALIBRATION_BOUNDS;
    assert!(errors.0.abs() < ea && errors.1.abs() < guide && errors.2.abs() < sheave, "{errors:?}");
}

/// A rig that is not the reference rig (`configs/examples/another_rig.toml`),
/// given to the diagnosis as its configuration: a heavier counterweight and
/// cars (48 kg; 40 and 85 kg), a longer, stiffer and heavier rope (10.5 m,
/// EA 1.6e6 N, 0.13 kg/m), a larger sheave (r 0.08 m, I 0.52 kg m^2), more
/// damping (190 kg/s at the guides, 4 N m s/rad at the sheave), an
/// eight-pole-pair machine whose ripple lies at mechanical orders 1, 8, 16,
/// 48 and 96 (the reference's electrical orders), and a faster, longer
/// travel (0.5 m/s, lw 1.0 to 9.2 m).
fn another_rig() -> RigConfig {
    const PATH: &str = "configs/examples/another_rig.toml";
    RigConfig::from_toml_str(include_str!("../configs/examples/another_rig.toml"), PATH).expect("a valid rig")
}

/// The nominal rig of [`another_rig`] recorded by draw 7's drive and
/// acquisition (the 85 kg car up and down, the decays of both cars),
/// diagnosed with that rig as the model: `nominal`, with EA within 2 %,
/// the guide damping within 15 % and the sheave damping within 10 % (the
/// bounds asked of the foreign parameter-only rig). The whole dataset of
/// `host-sim dataset --config` (both cars) and three effects on it are in
/// docs/diagnosis.md.
#[test]
fn foreign_rig_that_is_not_the_reference_rig_stays_nominal() {
    let other = another_rig();
    let spec = DatasetSpec { m_car_kg: vec![85.0], ..DatasetSpec::rig(&other) };
    let data = make_foreign_dataset_hooked(&other, &spec, &foreign_rig(7), None).expect("foreign dataset");
    let report = diagnosed(&other, "another rig", &data);
    let errors = calibration_errors(&report, calibration_truth(&other));
    println!(
        "verdict {:?}, excess {:.2} dB, calibration errors {errors:.4?}",
        report.verdict, report.nominal_excess_db
    );
    assert_eq!(report.verdict, Verdict::Nominal);
    assert!(errors.0.abs() < 0.02 && errors.1.abs() < 0.15 && errors.2.abs() < 0.10, "{errors:?}");
}

/// An effect on [`another_rig`]: its values that differ from the
/// defaults (index, value), the strength as read from the fitted
/// parameters (`what`, for the print) and its truth.
struct EffectCase {
    kind: EffectKind,
    set: Vec<(usize, f64)>,
    what: &'static str,
    strength: fn(&[FittedParameter]) -> Option<f64>,
    truth: f64,
}

/// The value of the fitted parameter `name` among `parameters`.
fn value(parameters: &[FittedParameter], name: &str) -> Option<f64> {
    parameters.iter().find(|p| p.name == name).map(|p| p.value)
}

/// Three effects of the library on [`another_rig`] (its whole dataset, as
/// `host-sim dataset --config` records it, by draw 7's drive and
/// acquisition), diagnosed with that rig as the model: each named first
/// with its strength within 30 % of the truth (the pulley's inertia over
/// its radius squared, what the line sees), the held-out shrink printed.
/// About 13 minutes on two cores; its figures are in docs/diagnosis.md.
#[test]
#[ignore = "three effects on another rig, about 13 minutes: run with --ignored"]
fn foreign_rig_that_is_not_the_reference_rig_effects_are_named() {
    let other = another_rig();
    let cases = [
        EffectCase {
            kind: EffectKind::CoulombGuideFriction,
            set: vec![(0, 8.0)],
            what: "friction N",
            strength: |p| value(p, "friction_n"),
            truth: 8.0,
        },
        EffectCase {
            kind: EffectKind::TensionStiffening,
            set: vec![(0, 0.4)],
            what: "alpha",
            strength: |p| value(p, "alpha"),
            truth: 0.4,
        },
        // The line sees the pulley as its inertia over its radius squared;
        // the radius is not fitted: the model keeps the default one.
        EffectCase {
            kind: EffectKind::DivertingPulley,
            set: vec![(0, 0.1), (1, 0.1)],
            what: "inertia / radius^2 kg",
            strength: |p| {
                let radius = value(p, "radius_m").unwrap_or(EffectKind::DivertingPulley.defaults()[1]);
                Some(value(p, "inertia_kg_m2")? / (radius * radius))
            },
            truth: 0.1 / (0.1 * 0.1),
        },
    ];
    for EffectCase { kind, set, what, strength, truth } in cases {
        let mut values = kind.defaults();
        set.iter().for_each(|&(i, v)| values[i] = v);
        let mut effects = Effects::none();
        effects.set(kind, &values).unwrap();
        let spec = DatasetSpec { effects, ..DatasetSpec::rig(&other) };
        let data = make_foreign_dataset_hooked(&other, &spec, &foreign_rig(7), None).expect("foreign dataset");
        let report = diagnosed(&other, kind.name(), &data);
        let best = report.ranking.first().expect("a ranking");
        let fitted = strength(&best.parameters).unwrap_or(f64::NAN);
        println!(
            "{}: verdict {:?}, excess {:.2} dB, first {} ({what} {fitted:.4}, truth {truth:.4}), held-out shrink {:.0} %",
            kind.name(),
            report.verdict,
            report.nominal_excess_db,
            best.name,
            100.0 * best.held_out_shrink
        );
        assert_eq!(best.name, kind.name());
        assert!((fitted / truth - 1.0).abs() < 0.3, "{what} {fitted} for {truth}");
    }
}

/// Tension stiffening (alpha 0.437) on a foreign rig: the nominal model
/// misses the data and the diagnosis names the effect first.
#[test]
fn foreign_rig_tension_stiffening_is_named_first() {
    let model = rig();
    let foreign = draw_8_first_order_clamps();
    let mut effects = Effects::none();
    effects.set(EffectKind::TensionStiffening, &[0.437, EffectKind::TensionStiffening.defaults()[1]]).unwrap();
    let report = diagnosed(&model, "tension stiffening", &foreign_dataset(&model, &foreign, effects));
    let first = report.ranking.first().map(|b| b.name.as_str());
    println!(
        "verdict {:?}, excess {:.2} dB, first {first:?}, shrink {:.0} %",
        report.verdict,
        report.nominal_excess_db,
        100.0 * report.ranking.first().map_or(0.0, |b| b.held_out_shrink)
    );
    assert_ne!(report.verdict, Verdict::Nominal);
    assert_eq!(first, Some("tension_stiffening"));
    assert!(report.attribution_note.as_deref().is_some_and(|n| n.contains("dead_time")));
}

/// A diverting pulley (0.06 kg m^2) on a foreign rig: its mode, crossed by
/// the ripple's high orders, matches the data only near its true frequency,
/// so a coarse grid of the inertia steps over it; the screen brackets it and
/// the diagnosis explains the gap with the pulley, the inertia within a
/// fifth.
#[test]
fn foreign_rig_diverting_pulley_is_explained() {
    let model = rig();
    let foreign = draw_8_first_order_clamps();
    let mut effects = Effects::none();
    let mut values = EffectKind::DivertingPulley.defaults();
    values[0] = 0.06;
    effects.set(EffectKind::DivertingPulley, &values).unwrap();
    let report = diagnosed(&model, "diverting pulley", &foreign_dataset(&model, &foreign, effects));
    let best = report.ranking.first().expect("a ranking");
    let inertia = value(&best.parameters, "inertia_kg_m2");
    println!(
        "verdict {:?}, excess {:.2} dB, first {} (inertia {inertia:?}), shrink {:.0} %",
        report.verdict,
        report.nominal_excess_db,
        best.name,
        100.0 * best.held_out_shrink
    );
    assert_eq!(report.verdict, Verdict::Explained);
    assert_eq!(best.name, "diverting_pulley");
    let inertia = inertia.expect("the pulley's inertia fitted");
    assert!((inertia / 0.06 - 1.0).abs() < 0.2, "inertia {inertia} kg m^2 for 0.06");
}

/// The direct-axis lines of a foreign rig's travels (its drive turned to a
/// rotor start at 0 degrees, as the library's electrical effects need;
/// its currents recorded by clamps, in which the drive's transducer errors
/// show) with `effects`.
fn direct_axis_lines(effects: Effects) -> diagnosis::electrical_lines::ElectricalLines {
    let model = rig();
    let mut foreign = draw_8_first_order_clamps();
    if let Some(drive) = foreign.drive.as_mut() {
        drive.rotor_start_angle_deg = 0.0;
    }
    let data = foreign_dataset(&model, &foreign, effects);
    let travels: Vec<(&str, &Recording)> = data.iter().map(|(s, r)| (s.as_str(), r)).collect();
    diagnosis::electrical_lines::electrical_lines(&model, &travels, &EffectKind::ALL)
}

/// Under another drive the transducers' and the inverter's errors are in
/// the recorded currents and so in the torque that drives the model: the
/// direct-axis current's lines show them. The nominal rig has none; the
/// plant's current-sensor error, regulated in by the commercial drive, is
/// fitted back to its offsets and gains; the plant's dead time puts a
/// line at order 6 that `dead_time` explains.
#[test]
fn foreign_rig_electrical_effects_show_in_the_direct_axis_lines() {
    let nominal = direct_axis_lines(Effects::none());
    assert!(!nominal.present(), "{:?}", nominal.present_orders);

    let truth = [0.15, -0.05, 0.008, -0.005];
    let mut effects = Effects::none();
    effects.set(EffectKind::CurrentSensorError, &truth).unwrap();
    let found = direct_axis_lines(effects);
    let best = &found.ranking[0];
    println!("{}: {:.0} %", best.name, 100.0 * best.held_out_shrink);
    assert_eq!(best.name, "current_sensor_error");
    assert!(best.held_out_shrink >= 0.7, "{}", best.held_out_shrink);
    for (p, t) in best.parameters.iter().zip(truth) {
        println!("{} = {:.4} (truth {t})", p.name, p.value);
        assert!((p.value - t).abs() <= 0.1 * t.abs() + 1e-3, "{} = {} against {t}", p.name, p.value);
    }

    let mut effects = Effects::none();
    effects.set(EffectKind::DeadTime, &[3e-7, EffectKind::DeadTime.defaults()[1]]).unwrap();
    let found = direct_axis_lines(effects);
    assert_eq!(found.present_orders, vec![6.0]);
    let best = &found.ranking[0];
    println!("{}: {:.0} %", best.name, 100.0 * best.held_out_shrink);
    assert_eq!(best.name, "dead_time");
    assert!(best.held_out_shrink >= 0.7, "{}", best.held_out_shrink);
}

/// No mechanical effect of the library (nor the encoder's error) puts a
/// line on the direct axis: the drive answers the motion on the
/// quadrature axis. Each at its default strength on a foreign rig. (The
/// torque-driven model also holds the current transducers' error, read
/// back into the torque, but that one is electrical: its lines are the
/// test above's.)
#[test]
fn foreign_rig_mechanical_effects_leave_the_direct_axis_clean() {
    let mechanical = |k: &EffectKind| holds_effect(*k, false) && *k != EffectKind::CurrentSensorError;
    for kind in EffectKind::ALL.into_iter().filter(mechanical) {
        let mut effects = Effects::none();
        effects.set(kind, &kind.defaults()).unwrap();
        let found = direct_axis_lines(effects);
        assert!(!found.present(), "{}: lines at orders {:?}", kind.name(), found.present_orders);
    }
}

/// A rig whose export records the drive's own transducer signals: under a
/// current-sensor error the drive regulates what its transducers report, so
/// the recorded currents are those it senses, `(1 + g) i + o` of the true
/// currents `i` on phases a and b (phase c exact), and their direct-axis
/// lines are clean, as on `../shared/rig-dev/current_sensor_error`; the
/// same travels recorded by clamps carry the true currents, whose lines
/// show the error. Checked sample by sample: the drive's recording is the
/// sensor error applied to the clamps' recording (same acquisition and
/// noise), within what the acquisition's quantiser and the error's gain
/// on the noise leave.
#[test]
fn foreign_rig_current_sensor_error_recorded_by_the_drive_leaves_its_currents_clean() {
    let model = rig();
    let error = CurrentSensorError { offset_a_a: 0.15, offset_b_a: -0.05, gain_error_a: 0.008, gain_error_b: -0.005 };
    let effects = Effects { current_sensor_error: Some(error), ..Effects::none() };
    let mut foreign = draw_8_first_order_clamps();
    if let Some(drive) = foreign.drive.as_mut() {
        drive.rotor_start_angle_deg = 0.0;
    }
    let spec = DatasetSpec { m_car_kg: vec![70.5], decay_masses_kg: vec![], effects, ..DatasetSpec::rig(&model) };
    let record = |drive_transducer_currents: bool| {
        let mut rig = foreign;
        rig.acquisition.as_mut().expect("a foreign acquisition").drive_transducer_currents = drive_transducer_currents;
        make_foreign_dataset_hooked(&model, &spec, &rig, None).expect("foreign dataset")
    };
    let (by_drive, by_clamps) = (record(true), record(false));
    let acquisition = foreign.acquisition.expect("a foreign acquisition");
    let tolerance_a = (1.0 + error.gain_error_a.abs()) * acquisition.current_step_a()
        + error.gain_error_a.abs().max(error.gain_error_b.abs()) * 6.0 * acquisition.current_noise_a;
    for ((stem, drive), (_, clamps)) in by_drive.iter().zip(&by_clamps) {
        let phases = |r: &Recording| [I_A, I_B, I_C].map(|n| r.column(n).expect("a current column").values.clone());
        let (sensed, true_currents) = (phases(drive), phases(clamps));
        let mut worst = 0.0f64;
        for k in 0..sensed[0].len() {
            let expected = error.measured_a([0, 1, 2].map(|p| true_currents[p][k]));
            for p in 0..3 {
                worst = worst.max((sensed[p][k] - expected[p]).abs());
            }
        }
        let offset: f64 =
            (0..sensed[0].len()).map(|k| sensed[0][k] - true_currents[0][k]).sum::<f64>() / sensed[0].len() as f64;
        println!("{stem}: sensed - error(true) up to {worst:.2e} A (tolerance {tolerance_a:.2e}); phase a differs by {offset:+.3} A on average");
        assert!(worst <= tolerance_a, "{stem}: the drive's recording is {worst} A off the sensor error of the clamps'");
    }
    let lines = |data: &[(String, Recording)]| {
        let travels: Vec<(&str, &Recording)> = data.iter().map(|(s, r)| (s.as_str(), r)).collect();
        diagnosis::electrical_lines::electrical_lines(&model, &travels, &EffectKind::ALL)
    };
    let (sensed, true_lines) = (lines(&by_drive), lines(&by_clamps));
    println!("lines: drive's transducers {:?}, clamps {:?}", sensed.present_orders, true_lines.present_orders);
    assert!(!sensed.present(), "the drive's transducer currents carry lines at orders {:?}", sensed.present_orders);
    assert!(true_lines.present_orders.contains(&1.0), "clamps: lines at {:?}", true_lines.present_orders);
}

/// The sweep over foreign draws (6-18 minutes a draw on two cores): every
/// nominal and parameter-only rig `nominal` and calibrated within the bounds,
/// the effects at twice the noise or more named first in 80 % of the cases and
/// explained in 70 %, the effect outside the library `unexplained`.
#[test]
#[ignore = "full sweep: run with --ignored"]
fn foreign_rigs_blind_sweep() {
    let env = |name: &str, default: u64| std::env::var(name).ok().and_then(|s| s.parse().ok()).unwrap_or(default);
    let (draws, first) = (env("GAP_FOREIGN_DRAWS", 2), env("GAP_FOREIGN_FIRST", 100));
    let mut cases = Vec::new();
    for d in 0..draws {
        sweep_draw(first + d, &mut cases);
        print_table(&cases);
    }
    let counted: Vec<&Case> = cases.iter().filter(|c| c.counts()).collect();
    let named = counted.iter().filter(|c| c.named_first()).count();
    let explained = counted.iter().filter(|c| c.explained()).count();
    let below = cases.iter().filter(|c| c.is_effect() && !c.counts()).count();
    println!(
        "effects at twice the noise or more: named first (verdict not nominal) {named} of {n}, explained by the true \
         effect {explained} of {n}; {below} effect cases below twice the noise not counted",
        n = counted.len()
    );
    let n = counted.len();
    assert!(10 * named >= 8 * n, "named first {named} of {n}: the blind test asks 80 %");
    assert!(10 * explained >= 7 * n, "explained {explained} of {n}: the blind test asks 70 %");
    for c in cases.iter().filter(|c| c.truth == OUTSIDE) {
        assert_eq!(c.report.verdict, Verdict::Unexplained, "draw {}: {}", c.draw, c.truth);
    }
    for c in cases.iter().filter(|c| !c.is_effect() && c.truth != OUTSIDE) {
        assert_eq!(c.report.verdict, Verdict::Nominal, "draw {}: {}", c.draw, c.truth);
        let (ea, guide, sheave) = c.calibration_errors().expect("the rig's values are known");
        let (ea_bound, guide_bound, sheave_bound) = CALIBRATION_BOUNDS;
        assert!(
            ea.abs() <= ea_bound && guide.abs() <= guide_bound && sheave.abs() <= sheave_bound,
            "draw {}: {}: calibration off by {ea:+.3} / {guide:+.3} / {sheave:+.3}",
            c.draw,
            c.truth
        );
    }
}
