//! Step 4a of the diagnosis: where along its one fitted parameter an effect
//! that places a resonance (diverting pulley, tension stiffening, brake
//! clamp) is worth fitting.
//!
//! A resonance matches the recordings only near its true frequency: a grid
//! point a fifth of an octave off puts the model's peak where the rig has
//! none and scores worse than no effect at all, so a coarse grid steps over
//! it. The screen runs a dense line of [`SCREEN_POINTS`] values over the
//! parameter's whole range (in its scale) on one recording, the one the
//! nominal model misses most, and gives the attribution the best of them
//! with its two neighbours: a bracket that the grid refinement then halves.

use plant::effects::{EffectKind, Fit, ParamScale};

/// Values of the fitted parameter on a screened effect's dense line.
pub const SCREEN_POINTS: usize = 24;

/// The effects that are screened: grid effects whose first fitted
/// parameter sets a natural frequency, as they declare
/// ([`plant::effects::Fit::Grid`]'s `screened`).
pub fn is_screened(kind: EffectKind) -> bool {
    matches!(kind.fit(), Fit::Grid { screened: true, .. })
}

/// The dense line of `kind`: `template` (the effect's full parameter vector,
/// fixed parameters as the attribution sets them) with its first parameter
/// at [`SCREEN_POINTS`] values over its range, evenly in its scale (a
/// linear range from its minimum leaves the minimum out: there the effect
/// is absent).
pub fn dense_line(kind: EffectKind, template: &[f64]) -> Vec<Vec<f64>> {
    let spec = kind.parameters()[0];
    let n = SCREEN_POINTS;
    (0..n)
        .map(|i| {
            let value = match spec.scale {
                ParamScale::Log => spec.min * (spec.max / spec.min).powf(i as f64 / (n - 1) as f64),
                _ => spec.min + (spec.max - spec.min) * (i + 1) as f64 / n as f64,
            };
            let mut p = template.to_vec();
            p[0] = value;
            p
        })
        .collect()
}

/// The template of `kind`'s dense line from its grid's `first` point: the
/// fitted parameters other than the screened one at the effect's defaults
/// (the grid searches them; the line is run once, at their middle).
pub fn line_template(kind: EffectKind, first: &[f64]) -> Vec<f64> {
    let defaults = kind.defaults();
    let specs = kind.parameters();
    first.iter().enumerate().map(|(j, &v)| if j > 0 && specs[j].fitted { defaults[j] } else { v }).collect()
}

/// The grid a screened effect is fitted on: every value of `bracket` (of
/// its first parameter) with every distinct setting of its other
/// parameters in `grid` (a pulley's damping ratios: the screen places the
/// resonance, the grid still searches how damped it is).
pub fn across_grid(bracket: &[f64], grid: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let mut rests: Vec<&[f64]> = Vec::new();
    for p in grid {
        if !rests.contains(&&p[1..]) {
            rests.push(&p[1..]);
        }
    }
    bracket
        .iter()
        .flat_map(|&x| rests.iter().map(move |rest| std::iter::once(x).chain(rest.iter().copied()).collect()))
        .collect()
}

/// Indices of the best point of a line by `scores` (lower is better; not
/// finite: the run failed) and its two neighbours, three consecutive
/// indices (at an end of the line, the three nearest it); `None` when no
/// point scored.
pub fn bracket(scores: &[f64]) -> Option<Vec<usize>> {
    let (best, _) = scores.iter().enumerate().filter(|(_, s)| s.is_finite()).min_by(|a, b| a.1.total_cmp(b.1))?;
    let n = scores.len();
    if n <= 3 {
        return Some((0..n).collect());
    }
    let first = best.saturating_sub(1).min(n - 3);
    Some((first..first + 3).collect())
}

/// The recording to screen on: the one with the largest nominal excess gap
/// (`nominal_db`, dB); `None` when there is none.
pub fn screening_target(nominal_db: &[f64]) -> Option<usize> {
    nominal_db.iter().enumerate().filter(|(_, s)| s.is_finite()).max_by(|a, b| a.1.total_cmp(b.1)).map(|(i, _)| i)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_screened_bracket_keeps_the_grids_other_parameters() {
        let grid = vec![vec![1.0, 7.0, 0.1], vec![2.0, 7.0, 0.1], vec![1.0, 7.0, 0.3], vec![2.0, 7.0, 0.3]];
        let out = across_grid(&[5.0, 6.0], &grid);
        assert_eq!(out, vec![vec![5.0, 7.0, 0.1], vec![5.0, 7.0, 0.3], vec![6.0, 7.0, 0.1], vec![6.0, 7.0, 0.3]]);
        // A one-parameter grid gives the bracket alone.
        let one = vec![vec![1.0, 7.0], vec![2.0, 7.0]];
        assert_eq!(across_grid(&[5.0, 6.0], &one), vec![vec![5.0, 7.0], vec![6.0, 7.0]]);
    }

    #[test]
    fn the_dense_line_spans_the_range_in_its_scale() {
        let kind = EffectKind::DivertingPulley;
        let spec = kind.parameters()[0];
        let line = dense_line(kind, &kind.defaults());
        assert_eq!(line.len(), SCREEN_POINTS);
        assert!((line[0][0] - spec.min).abs() < 1e-12 && (line[SCREEN_POINTS - 1][0] - spec.max).abs() < 1e-12);
        let ratio = line[1][0] / line[0][0];
        assert!(line.windows(2).all(|w| (w[1][0] / w[0][0] - ratio).abs() < 1e-9), "geometric");
        assert!(line.iter().all(|p| p[1..] == kind.defaults()[1..]), "fixed parameters kept");
        let alpha = dense_line(EffectKind::TensionStiffening, &EffectKind::TensionStiffening.defaults());
        assert!(alpha[0][0] > 0.0 && (alpha[SCREEN_POINTS - 1][0] - 1.0).abs() < 1e-12, "no absent effect");
    }

    #[test]
    fn the_bracket_holds_the_best_point_and_its_neighbours() {
        let inf = f64::INFINITY;
        assert_eq!(bracket(&[3.0, 2.0, 1.0, 2.5, 4.0]), Some(vec![1, 2, 3]));
        assert_eq!(bracket(&[0.5, 2.0, 1.0, 2.5, 4.0]), Some(vec![0, 1, 2]));
        assert_eq!(bracket(&[3.0, 2.0, 1.0, 2.5, 0.1]), Some(vec![2, 3, 4]));
        assert_eq!(bracket(&[inf, f64::NAN, 1.0, inf, 4.0]), Some(vec![1, 2, 3]));
        assert_eq!(bracket(&[inf, inf]), None);
        assert_eq!(screening_target(&[0.1, f64::NAN, 2.0, 0.3]), Some(2));
        assert_eq!(screening_target(&[]), None);
    }
}
