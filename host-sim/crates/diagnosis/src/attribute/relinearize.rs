//! A linear effect's fit taken again around its answer.
//!
//! A linear effect's influence is the combination of its probe runs'
//! spectra, each probe one strength alone around the nominal model. The
//! model is linear in the strengths only to first order: a dry friction
//! that sticks, a transducer error whose torque moves the ripple phases the
//! model reads from the drive's torque ([`crate::ripple_phase`]). Where
//! the first fit shrinks the gap, the model is run at its answer and at a
//! step from it along each strength ([`probe_step`]), and the effect
//! fitted again on those runs, up to [`super::REFINEMENT_ROUNDS`] times
//! (as a grid is refined around its best point): the combination is then
//! exact at the answer and first order around it.

use super::Lab;
use super::{
    clamp_coefficients, linear_parameters, Base, Family, LinearEffect, RunCount, Runs, Search, REFINEMENT_ROUNDS,
    REFINE_IF_BELOW,
};
use plant::effects::{EffectKind, Effects, Fit as Declared};

/// The smallest step of a probe around an answer, in first-stage probes.
const MIN_STEP: f64 = 0.1;

/// The family of a single linear effect (`family`, probes around the
/// nominal model) fitted again around its answer on all recordings, round
/// by round while the fit leaves less than [`REFINE_IF_BELOW`] of
/// `nominal_mean` (dB) and moves; `None` for a grid or a pair, or where
/// the first fit does not shrink the gap.
pub(super) fn around_the_fit(lab: &Lab, family: &Family, nominal_mean: f64, count: &mut RunCount) -> Option<Family> {
    if family.linear.len() != 1 || family.bases.len() != 1 || !family.bases[0].point.is_empty() {
        return None;
    }
    let all = lab.all();
    let mut current: Option<Family> = None;
    for _round in 0..REFINEMENT_ROUNDS {
        let f = current.as_ref().unwrap_or(family);
        let fit = f.fit(lab, &all);
        if fit.excess_db >= REFINE_IF_BELOW * nominal_mean || fit.coefficients.iter().all(|c| c.abs() < 1e-9) {
            break;
        }
        let linear = &f.linear[0];
        let origin = linear.absolute(&fit.coefficients);
        let held = f.held_coefficients(lab.known);
        current = Some(family_around(lab, linear.kind, &linear.search, &origin, &held, count));
    }
    current
}

/// The step (in coefficients, a first-stage probe being one) of probe `i`
/// from `origin` for `kind`: half the answer's distance from no effect
/// along that strength (an amplitude's, for a polar effect), within a
/// tenth of a probe and a whole one; forward, else back, else half as
/// far, whichever keeps the effect's parameters within their ranges. A
/// step comparable to the answer keeps the linearisation local: a dry
/// friction probed at 40 N says little about the model at 2 N.
fn probe_step(kind: EffectKind, origin: &[f64], i: usize) -> f64 {
    let distance = match kind.fit() {
        Declared::Polar { .. } => origin.iter().map(|c| c * c).sum::<f64>().sqrt(),
        _ => origin[i].abs(),
    };
    let size = (0.5 * distance).clamp(MIN_STEP, 1.0);
    let within = |s: f64| {
        let mut c = origin.to_vec();
        c[i] += s;
        clamp_coefficients(kind, &c).iter().zip(&c).all(|(a, b)| (a - b).abs() <= 1e-12 * b.abs().max(1.0))
    };
    [size, -size, 0.5 * size, -0.5 * size].into_iter().find(|&s| within(s)).unwrap_or(size)
}

/// Step: the family of `kind` with its probes around the coefficients
/// `origin`: the model at the origin (its base and the probes' reference)
/// and one step from it along each coefficient not `held` (a held one's
/// probe is the origin's run: it never moves).
fn family_around(
    lab: &Lab,
    kind: EffectKind,
    search: &Search,
    origin: &[f64],
    held: &[Option<f64>],
    count: &mut RunCount,
) -> Family {
    let steps: Vec<f64> = (0..origin.len()).map(|i| probe_step(kind, origin, i)).collect();
    let effects_at = |c: &[f64]| super::effects_of(&[(kind, linear_parameters(kind, c))]).unwrap_or(Effects::none());
    let mut models = vec![effects_at(origin)];
    let free: Vec<usize> = (0..origin.len()).filter(|&i| held.get(i).is_none_or(Option::is_none)).collect();
    for &i in &free {
        let mut c = origin.to_vec();
        c[i] += steps[i];
        models.push(effects_at(&c));
    }
    count.planned = count.planned.max(count.done + models.len());
    let mut runs = lab.run_all(&models, count).into_iter();
    let centre: Runs = runs.next().unwrap_or_default();
    let mut probes: Vec<Runs> = vec![centre.clone(); origin.len()];
    for (&i, r) in free.iter().zip(runs) {
        probes[i] = r;
    }
    let mut around = Family {
        kinds: vec![kind],
        bases: vec![Base { point: Vec::new(), runs: centre }],
        linear: vec![LinearEffect { kind, search: search.clone(), probes, origin: origin.to_vec(), steps }],
        cross: Vec::new(),
        refit: None,
        probes_from_base: true,
    };
    around.prepare(lab);
    around
}

#[cfg(test)]
mod tests {
    use super::super::{search, KnownParameter};
    use super::*;

    /// The linear and polar effects of the library.
    fn linear_kinds() -> Vec<EffectKind> {
        EffectKind::ALL.into_iter().filter(|k| !matches!(k.fit(), Declared::Grid { .. })).collect()
    }

    /// Every probe around an origin moves its own coefficient and stays a
    /// model the effect accepts: from no effect, and from every strength
    /// at the largest the effect accepts (where a unit step forward would
    /// leave the range).
    #[test]
    fn every_probe_moves_its_coefficient_within_the_range() {
        for kind in linear_kinds() {
            let n = match search(kind, None) {
                Search::Linear { probes, .. } => probes.len(),
                Search::Grid(_) => unreachable!("{kind:?} is linear"),
            };
            let edge = clamp_coefficients(kind, &vec![1e6; n]);
            for origin in [vec![0.0; n], edge.clone()] {
                for i in 0..n {
                    let step = probe_step(kind, &origin, i);
                    let mut moved = origin.clone();
                    moved[i] += step;
                    assert_eq!(clamp_coefficients(kind, &moved), moved, "{kind:?} probe {i} from {origin:?}");
                    assert_ne!(
                        linear_parameters(kind, &moved),
                        linear_parameters(kind, &origin),
                        "{kind:?} probe {i} from {origin:?} does not move the effect"
                    );
                }
            }
        }
    }

    /// Coefficients counted from an origin in probe steps give back the
    /// effect's own; a parameter the data measure is held at its value,
    /// which is no step at all when the origin already holds it.
    #[test]
    fn coefficients_around_an_origin_are_the_effects_own() {
        let kind = EffectKind::CurrentSensorError;
        let origin = vec![-1.2, 0.4, 2.0, -0.5];
        let linear = LinearEffect {
            kind,
            search: search(kind, None),
            probes: vec![Vec::new(); 4],
            origin: origin.clone(),
            steps: vec![1.0, -1.0, 0.5, 1.0],
        };
        let relative = [0.3, -0.2, 1.0, 0.0];
        let absolute = linear.absolute(&relative);
        let expected = [-0.9, 0.6, 2.5, -0.5];
        assert!(absolute.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-12), "{absolute:?}");
        let back = linear.relative(&absolute);
        assert!(back.iter().zip(relative).all(|(a, b)| (a - b).abs() < 1e-12), "{back:?}");
        let probe = match kind.fit() {
            Declared::Linear(strengths) => strengths[2].1,
            _ => unreachable!(),
        };
        let known = [KnownParameter { effect: kind, index: 2, value: 2.0 * probe, uncertainty: 0.0, source: "a test" }];
        let family = Family {
            kinds: vec![kind],
            bases: Vec::new(),
            linear: vec![linear],
            cross: Vec::new(),
            refit: None,
            probes_from_base: false,
        };
        let held = family.held_coefficients(&known);
        assert_eq!(held.len(), 4);
        assert!(held[2].is_some_and(|h| h.abs() < 1e-12), "{held:?}");
        assert!(held.iter().enumerate().all(|(i, h)| i == 2 || h.is_none()), "{held:?}");
    }
}
