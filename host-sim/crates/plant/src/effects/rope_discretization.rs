//! Rope discretization: N lumped elements per rope side instead of one.

use super::declare::{Effect, Fit, Neutral, ParamScale::Integer, ParamSpec, Seen};

/// Rope discretization: N lumped elements per rope side instead of one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RopeDiscretization {
    /// Elements per rope side (1: the paper's lumping).
    pub elements: usize,
}

use super::tension_stiffening::{rope_ea_n, static_tension_n, TensionStiffening};

/// Most elements per rope side (the parameter's range).
pub const MAX_ELEMENTS: usize = 8;

/// One rope side of length `l` hanging from the sheave (or pulley) with a
/// mass at its end, lumped into `N` elements: masses `mu l / N` at the
/// elements' midpoints, springs `N EA / l` between consecutive masses and
/// `2 N EA / l` from the end masses to the sheave and to the hanging body
/// (half an element each). `N = 1` is the paper's lumping (Eqn 1-2: one
/// mass `mu l` between two springs `2 EA / l`).
///
/// Ordering: masses and springs are listed from the hanging end upwards:
/// `springs[0]` joins the hanging body and `masses[0]`, `springs[N]` joins
/// `masses[N - 1]` and the sheave.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LumpedSide {
    /// Elements, `N`.
    pub elements: usize,
    /// Element masses, kg (the first `elements` are used).
    pub masses_kg: [f64; MAX_ELEMENTS],
    /// Spring stiffnesses, N/m (the first `elements + 1` are used).
    pub springs_n_per_m: [f64; MAX_ELEMENTS + 1],
}

impl RopeDiscretization {
    /// Elements per side, at least 1 and at most [`MAX_ELEMENTS`].
    pub fn elements_per_side(&self) -> usize {
        self.elements.clamp(1, MAX_ELEMENTS)
    }
}

/// Elements per side of `effect` (1, the paper's lumping, without it).
pub fn elements_per_side(effect: Option<&RopeDiscretization>) -> usize {
    effect.map_or(1, RopeDiscretization::elements_per_side)
}

/// Distance (m) from the hanging end of a side of `length_m` (m) in
/// `elements` elements to the middle of the rope that spring `j` stands
/// for: the end springs cover a half element (midpoints at `l / 4N` and
/// `l - l / 4N`), the inner spring `j` the rope between the midpoints of
/// elements `j - 1` and `j` (midpoint `j l / N`). Tension stiffening uses
/// the static tension there (the mean over the spring's rope, to first
/// order).
pub fn spring_midpoint_from_end_m(length_m: f64, elements: usize, j: usize) -> f64 {
    let element = length_m / elements as f64;
    if j == 0 {
        0.25 * element
    } else if j == elements {
        length_m - 0.25 * element
    } else {
        j as f64 * element
    }
}

/// The lumped side of `length_m` (m) rope of `mu_kg_per_m` (kg/m) and
/// nominal `ea0_n` (N) with `end_mass_kg` (kg) hanging at its end, in
/// `elements` (1 to [`MAX_ELEMENTS`]) elements; with `stiffening` each
/// spring's EA is taken at its static tension (gravity `gravity_mps2`).
pub fn lumped_side(
    length_m: f64,
    elements: usize,
    mu_kg_per_m: f64,
    ea0_n: f64,
    end_mass_kg: f64,
    gravity_mps2: f64,
    stiffening: Option<&TensionStiffening>,
) -> LumpedSide {
    let n = elements.clamp(1, MAX_ELEMENTS);
    let mut side = LumpedSide { elements: n, masses_kg: [0.0; MAX_ELEMENTS], springs_n_per_m: [0.0; MAX_ELEMENTS + 1] };
    for j in 0..n {
        side.masses_kg[j] = element_mass_kg(length_m, n, mu_kg_per_m);
    }
    for j in 0..=n {
        side.springs_n_per_m[j] =
            spring_n_per_m(length_m, n, j, mu_kg_per_m, ea0_n, end_mass_kg, gravity_mps2, stiffening);
    }
    side
}

/// Mass of one of the `elements` elements of a side of `length_m` (m) of
/// rope of `mu_kg_per_m` (kg/m), kg: `mu l / N`.
#[inline]
pub fn element_mass_kg(length_m: f64, elements: usize, mu_kg_per_m: f64) -> f64 {
    mu_kg_per_m * length_m / elements as f64
}

/// Stiffness (N/m) of spring `j` (0 at the hanging end, `elements` at the
/// sheave) of a side as in [`lumped_side`]: `2 N EA / l` at the ends,
/// `N EA / l` between elements, EA at the spring's static tension with
/// `stiffening`.
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn spring_n_per_m(
    length_m: f64,
    elements: usize,
    j: usize,
    mu_kg_per_m: f64,
    ea0_n: f64,
    end_mass_kg: f64,
    gravity_mps2: f64,
    stiffening: Option<&TensionStiffening>,
) -> f64 {
    let nf = elements as f64;
    let ea = match stiffening {
        None => ea0_n,
        Some(_) => {
            let below = spring_midpoint_from_end_m(length_m, elements, j);
            rope_ea_n(stiffening, ea0_n, static_tension_n(end_mass_kg, mu_kg_per_m, below, gravity_mps2))
        }
    };
    // End springs cover half an element: 2 N EA / l; inner ones N EA / l.
    let factor = if j == 0 || j == elements { 2.0 * nf } else { nf };
    factor * ea / length_m
}

impl Effect for RopeDiscretization {
    const NAME: &'static str = "rope_discretization";
    const PARAMETERS: &'static [ParamSpec] =
        &[ParamSpec::new("elements", "-", 4.0, 1.0, 8.0, Integer, true, "lumped elements per rope side")
            .neutral_at(Neutral::At(1.0))];
    const FIT: Fit = Fit::Grid { axes: &[(0, &[2.0, 4.0, 8.0])], screened: false };
    const SEEN: Seen = Seen { in_free_decay: false, under_another_drive: true };

    fn from_values(v: &[f64]) -> Self {
        Self { elements: v[0] as usize }
    }

    fn values(&self) -> Vec<f64> {
        vec![self.elements as f64]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_element_is_the_papers_lumping() {
        let s = lumped_side(3.7, 1, 0.095, 1.0e6, 70.5, 9.81, None);
        assert_eq!(s.masses_kg[0], 0.095 * 3.7);
        assert_eq!(s.springs_n_per_m[0], 2.0 * 1.0e6 / 3.7);
        assert_eq!(s.springs_n_per_m[1], 2.0 * 1.0e6 / 3.7);
    }

    #[test]
    fn series_compliance_and_mass_are_the_ropes() {
        for n in 1..=MAX_ELEMENTS {
            let s = lumped_side(2.0, n, 0.095, 1.0e6, 33.0, 9.81, None);
            let compliance: f64 = s.springs_n_per_m[..=n].iter().map(|k| 1.0 / k).sum();
            assert!((compliance - 2.0 / 1.0e6).abs() < 1e-18, "{n}");
            let mass: f64 = s.masses_kg[..n].iter().sum();
            assert!((mass - 0.19).abs() < 1e-12);
        }
        let stiff = TensionStiffening { alpha: 0.3, reference_tension_n: 300.0 };
        let s = lumped_side(2.0, 4, 0.095, 1.0e6, 33.0, 9.81, Some(&stiff));
        // Tension grows upwards, so does EA: the top spring's EA is largest.
        let ea = |j: usize| s.springs_n_per_m[j] * 2.0 / if j == 0 || j == 4 { 8.0 } else { 4.0 };
        assert!(ea(4) > ea(2) && ea(2) > ea(0));
        let expected = 1.0e6 * ((33.0 + 0.095 * 1.0) * 9.81 / 300.0f64).powf(0.3);
        assert!((ea(2) - expected).abs() < 1e-6 * expected);
    }
}
