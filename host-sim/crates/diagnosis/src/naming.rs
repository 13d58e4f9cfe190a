//! Step 5 of the diagnosis: which fitted candidate may be named.
//!
//! A fit always returns values, and the best of a ranking is only the least
//! bad: guide friction fitted at 0 N ranks first with no shrink when every
//! other effect makes the gap worse. A candidate is named only when
//!
//! 1. it shrinks the held-out gap beyond the scatter of that shrink over the
//!    held-out recordings (mean improvement larger than its standard error),
//! 2. the fitted strength of each of its effects leaves the value at which
//!    the effect vanishes (its neutral value) by more than its uncertainty
//!    (jackknife over the folds; for an effect of several strengths, their
//!    RMS in units of their uncertainties), and
//! 3. no fitted parameter sits at the edge of its search on the side of the
//!    neutral value (there the fit could have gone on towards no effect: the
//!    strength is not determined).
//!
//! Otherwise the report says that no effect of the library helps; the
//! ranking keeps the named candidates first.

use crate::attribute::Candidate;

use plant::effects::EffectKind;
pub use plant::effects::Neutral;

/// The neutral value of parameter `parameter` of effect `effect` (the
/// library's names), as the effect declares it
/// ([`plant::effects::ParamSpec::neutral`]); a parameter the library does
/// not declare (an electrical line's amplitude) vanishes at zero.
pub fn neutral(effect: &str, parameter: &str) -> Neutral {
    EffectKind::from_name(effect)
        .and_then(|kind| kind.parameters().iter().find(|s| s.name == parameter))
        .map_or(Neutral::At(0.0), |spec| spec.neutral)
}

/// Whether a candidate may be named, and why not.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct Naming {
    /// The candidate passes every test of the module.
    pub named: bool,
    /// Why it is not named (empty when it is).
    pub reason: String,
}

/// Mean and standard error of `v` (standard error 0 with fewer than two
/// values).
fn mean_and_standard_error(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    if v.is_empty() {
        return (0.0, 0.0);
    }
    let mean = v.iter().sum::<f64>() / n;
    if v.len() < 2 {
        return (mean, 0.0);
    }
    let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    (mean, sd / n.sqrt())
}

/// How far `value` lies from `neutral` in units of `uncertainty`; an
/// unknown or zero uncertainty counts any difference as beyond it.
fn distance_in_uncertainties(value: f64, neutral: f64, uncertainty: f64) -> f64 {
    let d = (value - neutral).abs();
    if d == 0.0 {
        0.0
    } else if uncertainty.is_finite() && uncertainty > 0.0 {
        d / uncertainty
    } else {
        f64::INFINITY
    }
}

/// Judges candidate `c` (module doc).
pub fn judge(c: &Candidate) -> Naming {
    let not = |reason: String| Naming { named: false, reason };
    let (mean, se) = mean_and_standard_error(&c.held_out_improvements_db);
    if c.held_out_improvements_db.is_empty() || mean <= 0.0 || mean <= se {
        return not(format!(
            "it does not shrink the held-out gap beyond the shrink's scatter over the recordings ({mean:+.3} +- {se:.3} dB)"
        ));
    }
    if !c.search_edge.is_empty() {
        return not(format!(
            "{} fitted at the edge of its search on the side of no effect: the strength is not determined",
            c.search_edge.join(", ")
        ));
    }
    let mut effects: Vec<&str> = c.parameters.iter().map(|p| p.effect).collect();
    effects.dedup();
    for effect in effects {
        let z: Vec<f64> = c
            .parameters
            .iter()
            .filter(|p| p.effect == effect)
            .filter_map(|p| match neutral(p.effect, p.name) {
                Neutral::At(v0) => Some(distance_in_uncertainties(p.value, v0, p.uncertainty)),
                _ => None,
            })
            .collect();
        if z.is_empty() {
            continue;
        }
        let rms =
            (z.iter().map(|x| if x.is_finite() { x * x } else { f64::INFINITY }).sum::<f64>() / z.len() as f64).sqrt();
        if rms <= 1.0 {
            return not(format!(
                "the fitted strength of {effect} lies within its uncertainty of no effect ({rms:.2} uncertainties \
                 away)"
            ));
        }
    }
    Naming { named: true, reason: String::new() }
}

/// Judges every candidate of `ranking` and puts the named ones first, each
/// group in its former order.
pub fn name_candidates(ranking: &mut Vec<Candidate>) {
    for c in ranking.iter_mut() {
        c.naming = judge(c);
    }
    let (named, not): (Vec<Candidate>, Vec<Candidate>) =
        std::mem::take(ranking).into_iter().partition(|c| c.naming.named);
    ranking.extend(named);
    ranking.extend(not);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::attribute::FittedParameter;

    fn candidate(name: &'static str, value: f64, uncertainty: f64, improvements: &[f64]) -> Candidate {
        Candidate {
            name: name.to_string(),
            parameters: vec![FittedParameter {
                effect: name,
                name: "friction_n",
                unit: "N",
                value,
                uncertainty,
                measured_by: None,
            }],
            held_out_improvements_db: improvements.to_vec(),
            ..Candidate::default()
        }
    }

    #[test]
    fn a_strength_at_its_neutral_value_is_not_named() {
        let c = candidate("coulomb_guide_friction", 0.0, 0.0, &[1.0, 1.1, 0.9]);
        assert!(!judge(&c).named);
        let c = candidate("coulomb_guide_friction", 0.8, 1.5, &[1.0, 1.1, 0.9]);
        assert!(!judge(&c).named, "within its uncertainty of none");
        let c = candidate("coulomb_guide_friction", 6.0, 1.5, &[1.0, 1.1, 0.9]);
        assert!(judge(&c).named);
    }

    #[test]
    fn a_shrink_within_its_scatter_is_not_named() {
        assert!(!judge(&candidate("coulomb_guide_friction", 6.0, 1.0, &[0.5, -0.6, 0.05])).named);
        assert!(!judge(&candidate("coulomb_guide_friction", 6.0, 1.0, &[-0.1, -0.2])).named);
        assert!(!judge(&candidate("coulomb_guide_friction", 6.0, 1.0, &[])).named);
        assert!(judge(&candidate("coulomb_guide_friction", 6.0, 1.0, &[0.5, 0.6, 0.05])).named);
    }

    #[test]
    fn an_edge_of_the_search_towards_no_effect_is_not_named() {
        let mut c = candidate("car_frame_mode", 120.0, 0.0, &[1.0, 1.0]);
        c.parameters[0].name = "frequency_hz";
        assert!(judge(&c).named, "a frequency has no neutral value to leave");
        c.search_edge = vec!["car_frame_mode.damping_ratio".to_string()];
        assert!(!judge(&c).named);
    }

    #[test]
    fn neutral_values_of_the_library() {
        assert_eq!(neutral("rope_discretization", "elements"), Neutral::At(1.0));
        assert_eq!(neutral("sheave_eccentricity", "phase_rad"), Neutral::NotAStrength);
        assert_eq!(neutral("car_frame_mode", "damping_ratio"), Neutral::AboveRange);
        assert_eq!(neutral("tension_stiffening", "alpha"), Neutral::At(0.0));
    }

    #[test]
    fn named_candidates_come_first() {
        let mut r = vec![
            candidate("coulomb_guide_friction", 0.0, 0.0, &[0.0, 0.0]),
            candidate("brake_stop", 2.0e4, 1.0e3, &[1.0, 1.2]),
        ];
        name_candidates(&mut r);
        assert_eq!(r[0].name, "brake_stop");
        assert!(r[0].naming.named && !r[1].naming.named);
    }
}
