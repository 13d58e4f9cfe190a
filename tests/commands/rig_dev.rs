//! Foreign recordings with and without unmodelled effects:
//! `../shared/rig-dev/` beside the repository holds six datasets of the
//! reference rig by the independent rig emulator of `../shared/rig-sample/`
//! (its own drive, acquisition and way of recording the currents), the
//! answer of each in its README. Read in place, never written.
//!
//! CI diagnoses five of them (the parameter-only rig, tension
//! stiffening, the brake at the stop, dry guide friction and the
//! diverting pulley). The diagnosis of the six takes longer than the CI budget: that
//! test is ignored and prints the table of `docs/diagnosis.md`
//! (`cargo test --release -p host-sim --test integration commands::rig_dev -- --ignored --nocapture`).
//! It fails when the parameter-only rig is not `nominal` or its
//! calibration misses the README's values (EA within 2 %, guide damping
//! within 15 %, sheave damping within 10 %), and when a dataset with an
//! effect is explained by another effect than its own (a wrong answer);
//! a dataset with an effect called `nominal` or `unexplained` is a miss,
//! counted and printed (the table in `docs/diagnosis.md`).

use std::path::PathBuf;
use std::time::Instant;

use diagnosis::{diagnose, GapOptions, GapReport, Verdict};
use recording::read::read_dataset;
use recording::Recording;
use rig_config::RigConfig;

/// The datasets and what the README says a correct diagnosis finds (the
/// effect, or `None` for the parameter-only rig).
const DATASETS: [(&str, Option<&str>); 6] = [
    ("param_only", None),
    ("current_sensor_error", Some("current_sensor_error")),
    ("tension_stiffening", Some("tension_stiffening")),
    ("brake_stop", Some("brake_stop")),
    ("coulomb_guide_friction", Some("coulomb_guide_friction")),
    ("diverting_pulley", Some("diverting_pulley")),
];

/// The reference rig and the dataset `name` of `../shared/rig-dev`, read in place.
fn read(name: &str) -> (RigConfig, Vec<(String, Recording)>) {
    let rig = RigConfig::embedded_default().expect("the embedded rig loads");
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/rig-dev").join(name);
    assert!(dir.is_dir(), "{}: the rig-dev datasets are expected beside the repository", dir.display());
    let data = read_dataset(&dir, rig.mechanics.rope_total_length_m).expect("rig-dev follows the measurement format");
    (rig, data)
}

fn diagnosed(name: &str) -> (GapReport, f64) {
    let (rig, data) = read(name);
    let started = Instant::now();
    let report = diagnose(&rig, name, &data, &GapOptions::default(), &|_, _, _| {}).expect("a verdict");
    (report, started.elapsed().as_secs_f64())
}

/// The diagnosis of the dataset `name` with an effect: `explained` by that
/// effect (the dataset's name), first, held-out shrink at least 70 %; its
/// best candidate.
fn explained_by_its_effect(name: &str) -> diagnosis::attribute::Candidate {
    let (r, _) = diagnosed(name);
    assert_eq!(r.verdict, Verdict::Explained, "{name}: {:?} by {:?}", r.verdict, r.explained_by);
    assert_eq!(r.explained_by.as_deref(), Some(name));
    let first = r.ranking.into_iter().next().expect("a ranking");
    assert!(first.held_out_shrink >= 0.7, "{name}: held-out shrink {:.2}", first.held_out_shrink);
    first
}

/// The parameter-only rig is `nominal` with the README's values (EA
/// within 2 %, guide damping within 15 %, sheave damping within 10 %) and
/// the tension-stiffening rig `explained` by tension stiffening with its
/// exponent within 30 % of the README's 0.45: read in place, the whole
/// library, two of the six diagnoses (a few minutes).
#[test]
fn param_only_is_nominal_and_tension_stiffening_is_explained() {
    let (r, _) = diagnosed("param_only");
    let c = &r.calibration;
    let within = |v: f64, t: f64, tol: f64| (v / t - 1.0).abs() <= tol;
    assert_eq!(r.verdict, Verdict::Nominal, "param_only: {:?} by {:?}", r.verdict, r.explained_by);
    assert!(within(c.rope_ea_n, 8.5e5, 0.02), "EA {:.4e} N", c.rope_ea_n);
    assert!(within(c.guide_damping_kg_per_s, 200.0, 0.15), "guide {:.1} kg/s", c.guide_damping_kg_per_s);
    assert!(within(c.sheave_damping_nms_per_rad, 4.5, 0.10), "sheave {:.3}", c.sheave_damping_nms_per_rad);

    let first = explained_by_its_effect("tension_stiffening");
    let alpha = first.parameters.iter().find(|p| p.name == "alpha").expect("the exponent is fitted").value;
    assert!(within(alpha, 0.45, 0.30), "exponent {alpha:.3} against the README's 0.45");
}

/// The diverting-pulley rig `explained` by the pulley, first, held-out
/// shrink at least 70 %, with the pulley's equivalent mass at its rim
/// (`J / r_p^2`, what the rope's motion fixes: the README's 0.08 kg m^2 at
/// 0.1 m is 8 kg) within 30 %: read in place, the whole library.
#[test]
fn diverting_pulley_is_explained_with_its_equivalent_mass() {
    let first = explained_by_its_effect("diverting_pulley");
    let pulley = first.effects.diverting_pulley.expect("the pulley is fitted");
    let mass_kg = pulley.rim_mass_kg();
    assert!((mass_kg / 8.0 - 1.0).abs() <= 0.30, "equivalent mass {mass_kg:.2} kg against the README's 8 kg");
}

/// The dry-guide-friction rig `explained` by the friction, first,
/// held-out shrink at least 70 %, with the car's friction force within
/// 30 % of the README's 6 N: its decays stop dead, so the calibration is
/// done again under the hypothesis and each decay released at the test's
/// level. Read in place, the whole library.
#[test]
fn coulomb_guide_friction_is_explained_with_its_force() {
    let first = explained_by_its_effect("coulomb_guide_friction");
    let force = first.parameters.iter().find(|p| p.name == "friction_n").expect("the force is fitted").value;
    assert!((force / 6.0 - 1.0).abs() <= 0.30, "friction {force:.2} N against the README's 6 N on the car");
}

/// The brake-stop rig `explained` by the brake's clamp, first, held-out
/// shrink at least 70 %, its stop compared where the brake takes the
/// turning sheave, and the clamp's fitted stiffness within 30 % of the
/// README's 4e5 N m/rad.
#[test]
fn brake_stop_is_explained_by_the_clamp() {
    let first = explained_by_its_effect("brake_stop");
    let value = |name: &str| first.parameters.iter().find(|p| p.name == name).expect("the clamp is fitted").value;
    let (stiffness, damping) = (value("clamp_stiffness_nm_per_rad"), value("clamp_damping_nms_per_rad"));
    println!(
        "brake_stop: clamp {stiffness:.4e} N m/rad ({:+.0} % against the README's 4e5), damping {damping:.1} N m s/rad",
        100.0 * (stiffness / 4.0e5 - 1.0)
    );
    assert!((stiffness / 4.0e5 - 1.0).abs() <= 0.30, "clamp {stiffness:.4e} N m/rad against the README's 4e5");
}

/// The recorded phase currents' balance, read in place without a model:
/// in `current_sensor_error` (the drive's transducer signals, gains 0.97,
/// 1.02, 1.01 and offsets -0.20, +0.10, +0.05 A in the README) every
/// travel's currents fail to sum to zero, and the balance gives the gains
/// of phases a and b relative to phase c and the offsets' weighted sum
/// `g_c sum o_x / g_x` within 5 % of the README's deviations; in the five
/// other datasets every travel's currents sum to zero within their noise.
#[test]
fn the_current_sensor_error_shows_in_the_recorded_currents_balance() {
    use diagnosis::current_balance::current_balance;
    for (name, truth) in DATASETS {
        let balances = current_balance(&read(name).1);
        assert_eq!(balances.len(), 4, "{name}: four travels record three phase currents");
        for b in &balances {
            println!(
                "{name} {}: {:?} {:.4} A, unbalanced {}",
                b.recording,
                b.gain_ratio,
                b.offset_sum_a,
                b.unbalanced()
            );
            if truth != Some("current_sensor_error") {
                assert!(!b.unbalanced(), "{name}: {b:?}");
                continue;
            }
            let (g, o) = ([0.97, 1.02, 1.01], [-0.20, 0.10, 0.05]);
            let offset_sum = g[2] * (o[0] / g[0] + o[1] / g[1] + o[2] / g[2]);
            assert!(b.unbalanced(), "{name}: {b:?}");
            for (fitted, truth) in [(b.gain_ratio[0], g[0] / g[2]), (b.gain_ratio[1], g[1] / g[2])] {
                assert!(
                    (fitted - truth).abs() <= 0.05 * (truth - 1.0).abs(),
                    "{name}: gain ratio {fitted:.5} against {truth:.5}"
                );
            }
            assert!((b.offset_sum_a - offset_sum).abs() <= 0.05 * offset_sum.abs(), "{name}: {:.4} A", b.offset_sum_a);
        }
    }
}

#[test]
#[ignore = "six foreign diagnoses, several minutes: run with --ignored"]
fn rig_dev_datasets_table() {
    println!(
        "| dataset | verdict | ranked first (fitted) | named | held-out shrink | nominal excess | calibration | time |\n\
         |---|---|---|---|---|---|---|---|"
    );
    let mut wrong = Vec::new();
    let mut misses = Vec::new();
    for (name, truth) in DATASETS {
        let (r, time) = diagnosed(name);
        let first = r.ranking.first();
        let fitted = first.map_or("-".to_string(), |c| {
            let p: Vec<String> = c.parameters.iter().map(|p| format!("{} {:.3e}", p.name, p.value)).collect();
            let pulley =
                c.effects.diverting_pulley.map_or(String::new(), |d| format!(", J/r_p^2 {:.2} kg", d.rim_mass_kg()));
            format!("{} ({}{pulley})", c.name, p.join(", "))
        });
        let c = &r.calibration;
        println!(
            "| {name} | {:?} | {fitted} | {} | {} | {:.2} dB | EA {:.4e} N, guide {:.1} kg/s, sheave {:.3} N m s/rad | {time:.0} s |",
            r.verdict,
            first.map_or("-", |c| if c.naming.named { "yes" } else { "no" }),
            first.map_or("-".to_string(), |c| format!("{:.0} %", 100.0 * c.held_out_shrink)),
            r.nominal_excess_db,
            c.rope_ea_n,
            c.guide_damping_kg_per_s,
            c.sheave_damping_nms_per_rad,
        );
        match truth {
            None => {
                let within = |v: f64, t: f64, tol: f64| (v / t - 1.0).abs() <= tol;
                if r.verdict != Verdict::Nominal
                    || !within(c.rope_ea_n, 8.5e5, 0.02)
                    || !within(c.guide_damping_kg_per_s, 200.0, 0.15)
                    || !within(c.sheave_damping_nms_per_rad, 4.5, 0.10)
                {
                    wrong.push(format!(
                        "{name}: {:?}, calibration EA {:.4e} guide {:.1} sheave {:.3}",
                        r.verdict, c.rope_ea_n, c.guide_damping_kg_per_s, c.sheave_damping_nms_per_rad
                    ));
                }
            }
            Some(effect) => {
                let other = r.explained_by.as_deref().is_some_and(|e| !e.split(" + ").any(|n| n == effect));
                if other {
                    wrong.push(format!("{name}: {:?} by {:?}", r.verdict, r.explained_by));
                } else if r.verdict != Verdict::Explained {
                    misses.push(name);
                }
            }
        }
    }
    println!("right {} of {}; missed: {misses:?}", DATASETS.len() - misses.len() - wrong.len(), DATASETS.len());
    assert!(wrong.is_empty(), "wrong: {wrong:?}");
}
