//! One harness holds every effect of the library to the same three checks,
//! read from nothing but its declaration ([`plant::effects::Effect`]), so an
//! effect added to the library is checked without a line here:
//!
//! 1. **it changes the recording**: a dataset of the full plant with the
//!    effect at its default parameters differs from the nominal plant's
//!    in an acceleration or a phase current by more than the sensor noise
//!    the fit later sees;
//! 2. **it vanishes at its neutral value**: with every fitted strength at
//!    the value where the effect declares it vanishes (or, when that value
//!    lies outside the accepted range, at the end of the range nearest it),
//!    the recording is the nominal one (a change below a thousandth of the
//!    default's), or at least nearer to it than with the default;
//! 3. **it is fitted back**: on that dataset with a little noise, the gap
//!    diagnosis searching this effect alone finds each fitted strength
//!    within a quarter of the truth (a log-scale parameter: within a
//!    factor 1.5; a phase: within a quarter of a radian). The effects that
//!    fail it today are listed in [`NOT_FITTED_BACK`].
//!
//! Datasets are small: one car mass, up and down over 2.5 m, and one free
//! decay, sampled at 16 kHz.

use closed_loop::synthetic::{make_dataset, DatasetSpec};
use diagnosis::{diagnose, GapOptions};
use plant::effects::{EffectKind, Effects, Neutral, ParamScale};
use recording::{Recording, ACC_CAR, ACC_CW, ACC_MACHINE, I_A, I_B, I_C};
use rig_config::RigConfig;

/// Accelerometer noise added before the fit, m/s^2 RMS: a tenth of the
/// blind test's (`gap.rs`), a well-instrumented rig; the harness checks
/// that the fit recovers the effect, the blind test how well it is told
/// apart from the others through realistic noise.
const ACC_NOISE_MPS2: f64 = 0.001;
/// Current noise added before the fit, A RMS (a tenth of the blind test's).
const CURRENT_NOISE_A: f64 = 0.002;
/// The RMS change of a channel counted as a change: the noise's RMS within
/// a 10 Hz band of the 16 kHz recording (a line or a resonance that stands
/// above it is seen by a spectrum of that resolution), in noise units.
const VISIBLE_CHANGE: f64 = 0.035;

/// The effects whose strengths the gap diagnosis does not recover from a
/// recording of the reference rig made with their defaults (measured by
/// this test, stated in docs/diagnosis.md): dead time (a third of it), the
/// transducers' gain errors (a third and a twentieth), the encoder's
/// eccentricity (a third, within its uncertainty of none). Their first two
/// checks hold; the third is printed, and a listed effect that passes it
/// fails the test until it leaves the list.
const NOT_FITTED_BACK: [EffectKind; 3] =
    [EffectKind::DeadTime, EffectKind::CurrentSensorError, EffectKind::EncoderError];

fn rig() -> RigConfig {
    RigConfig::embedded_default().expect("the embedded rig loads")
}

fn spec(rig: &RigConfig, effects: Effects, noisy: bool) -> DatasetSpec {
    DatasetSpec {
        m_car_kg: vec![58.0],
        lw_low_m: 3.0,
        lw_high_m: 5.5,
        decay_masses_kg: vec![58.0],
        decay_rope_length_m: 4.0,
        decay_duration_s: 2.0,
        sample_rate_hz: 16000.0,
        max_step_s: 0.5 / rig.control.current_loop_hz,
        acc_noise_mps2: if noisy { ACC_NOISE_MPS2 } else { 0.0 },
        current_noise_a: if noisy { CURRENT_NOISE_A } else { 0.0 },
        seed: 11,
        effects,
    }
}

fn dataset(rig: &RigConfig, effects: Effects, noisy: bool) -> Vec<(String, Recording)> {
    make_dataset(rig, &spec(rig, effects, noisy)).expect("the dataset is simulated")
}

/// Largest RMS change of a noisy channel (accelerations, phase currents)
/// between two noise-free datasets, in units of that channel's noise in
/// the fit.
fn change(a: &[(String, Recording)], b: &[(String, Recording)]) -> f64 {
    let mut worst = 0.0f64;
    for ((_, x), (_, y)) in a.iter().zip(b) {
        for cx in &x.columns {
            let Some(cy) = y.column(&cx.name) else { continue };
            let n = cx.values.len().min(cy.values.len());
            let scale = match cx.name.as_str() {
                ACC_CAR | ACC_CW | ACC_MACHINE => ACC_NOISE_MPS2,
                I_A | I_B | I_C => CURRENT_NOISE_A,
                _ => continue,
            };
            let rms_diff = (cx.values[..n].iter().zip(&cy.values[..n]).map(|(p, q)| (p - q).powi(2)).sum::<f64>()
                / n as f64)
                .sqrt();
            worst = worst.max(rms_diff / scale);
        }
    }
    worst
}

/// The parameters of `kind` with every fitted strength at its neutral value
/// (or the end of its range nearest it), and whether all of them could be
/// set there (the effect should then vanish exactly).
fn neutral_values(kind: EffectKind) -> (Vec<f64>, bool) {
    let mut v = kind.defaults();
    let mut exact = true;
    for (x, spec) in v.iter_mut().zip(kind.parameters()) {
        if !spec.fitted {
            continue;
        }
        match spec.neutral {
            Neutral::At(v0) => {
                *x = v0.clamp(spec.min, spec.max);
                exact &= (spec.min..=spec.max).contains(&v0);
            }
            Neutral::AboveRange => {
                *x = spec.max;
                exact = false;
            }
            Neutral::NotAStrength => {}
        }
    }
    (v, exact)
}

fn with(kind: EffectKind, values: &[f64]) -> Effects {
    let mut e = Effects::none();
    e.set(kind, values).expect("declared values are in range");
    e
}

/// Check 3: the diagnosis searching `kind` alone on `data` (made with its
/// defaults) names it and finds its strengths.
fn fitted_back(rig: &RigConfig, kind: EffectKind, data: &[(String, Recording)]) -> Result<String, String> {
    let options = GapOptions { effects: vec![kind], ..GapOptions::default() };
    let report = diagnose(rig, kind.name(), data, &options, &|_, _, _| {}).map_err(|e| format!("{e:#}"))?;
    let c = report.ranking.iter().find(|c| c.name == kind.name()).ok_or("no candidate of the effect")?;
    let mut out = format!("verdict {:?}, held-out shrink {:.0} %, fitted:", report.verdict, 100.0 * c.held_out_shrink);
    for p in &c.parameters {
        out += &format!(" {}={:.4e}+-{:.1e}", p.name, p.value, p.uncertainty);
    }
    for (spec, truth) in kind.parameters().iter().zip(kind.defaults()) {
        let p = c.parameters.iter().find(|p| p.name == spec.name);
        let within = match (spec.fitted, spec.scale, spec.neutral, p) {
            (false, ..) => continue,
            (_, _, _, None) => false,
            // A phase: within a quarter of a radian, around the circle.
            (_, ParamScale::Angle, _, Some(p)) => {
                let d = (p.value - truth).rem_euclid(std::f64::consts::TAU);
                d.min(std::f64::consts::TAU - d) <= 0.25
            }
            // A damping ratio or alike that is not the effect's strength.
            (_, _, Neutral::NotAStrength, _) => continue,
            // A log-scale parameter is searched on a grid of about three
            // values per decade, refined between neighbours.
            (_, ParamScale::Log, _, Some(p)) => (p.value / truth).ln().abs() <= 1.5f64.ln(),
            (_, _, _, Some(p)) => (p.value - truth).abs() <= 0.25 * truth.abs(),
        };
        if !within {
            return Err(format!("{} not within reach of its truth {truth:.4e}: {out}", spec.name));
        }
    }
    Ok(out)
}

/// The three checks on every effect of the library.
#[test]
fn every_effect_changes_the_recording_vanishes_at_its_neutral_value_and_is_fitted_back() {
    let rig = rig();
    let nominal = dataset(&rig, Effects::none(), false);
    let mut failures = Vec::new();
    for kind in EffectKind::ALL {
        let on = dataset(&rig, with(kind, &kind.defaults()), false);
        let change_on = change(&on, &nominal);
        let (neutral, exact) = neutral_values(kind);
        let change_neutral = change(&dataset(&rig, with(kind, &neutral), false), &nominal);
        println!(
            "{:<24} change on {change_on:.3e} noise units, at its neutral value {change_neutral:.3e} ({})",
            kind.name(),
            if exact { "exact" } else { "range end" }
        );
        if change_on <= VISIBLE_CHANGE {
            failures.push(format!("{}: changes the recording by only {change_on:.3} noise units", kind.name()));
        }
        let vanishes = if exact { change_neutral <= 1e-3 * change_on } else { change_neutral < change_on };
        if !vanishes {
            failures.push(format!(
                "{}: at its neutral value the recording still changes by {change_neutral:.3e} (on: {change_on:.3e})",
                kind.name()
            ));
        }
        let noisy = dataset(&rig, with(kind, &kind.defaults()), true);
        let listed = NOT_FITTED_BACK.contains(&kind);
        match (fitted_back(&rig, kind, &noisy), listed) {
            (Ok(line), false) => println!("{:<24} fitted back: {line}", kind.name()),
            (Err(why), true) => println!("{:<24} not fitted back (listed): {why}", kind.name()),
            (Err(why), false) => failures.push(format!("{}: {why}", kind.name())),
            (Ok(line), true) => {
                failures.push(format!("{}: fitted back ({line}): take it off NOT_FITTED_BACK", kind.name()))
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Every declaration is coherent: a grid searches fitted parameters within
/// their ranges, a screened grid's first axis is parameter 0, probes lie
/// inside the range, and a neutral value is declared for every strength.
#[test]
fn every_declaration_is_coherent() {
    use plant::effects::Fit;
    for kind in EffectKind::ALL {
        let specs = kind.parameters();
        let in_range = |i: usize, x: f64| specs[i].fitted && x >= specs[i].min && x <= specs[i].max;
        match kind.fit() {
            Fit::Grid { axes, screened } => {
                assert!(!axes.is_empty(), "{}", kind.name());
                for &(i, values) in axes {
                    assert!(values.iter().all(|&x| in_range(i, x)), "{}: grid of {}", kind.name(), specs[i].name);
                }
                assert!(!screened || axes[0].0 == 0, "{}: a screened grid's first axis is parameter 0", kind.name());
            }
            Fit::Linear(strengths) => {
                for &(i, probe) in strengths {
                    assert!(in_range(i, probe) && probe > 0.0, "{}: probe of {}", kind.name(), specs[i].name);
                }
            }
            Fit::Polar { amplitude, phase, probe } => {
                assert!(in_range(amplitude, probe), "{}: amplitude probe", kind.name());
                assert_eq!(specs[phase].neutral, Neutral::NotAStrength, "{}: the phase", kind.name());
            }
        }
        for spec in specs {
            assert!(spec.min <= spec.default && spec.default <= spec.max, "{}.{}", kind.name(), spec.name);
        }
    }
}
