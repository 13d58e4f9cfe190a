//! Step 4 of the diagnosis: which effect of the library explains the gap.
//!
//! Every effect is fitted on a training part of the recordings and judged on
//! the recordings held out from the fit (leave-one-group-out across car
//! masses: a group is every recording of one mass, travels up and down and
//! decays; with a single mass, one recording per group). Two kinds of fit:
//!
//! - grid: effects whose parameters move natural frequencies (tension
//!   stiffening, pulley, rope elements, frame mode, brake clamp) are
//!   simulated on a grid of their fitted parameters, refined around the
//!   best point on all recordings (and past it where it ends its searched
//!   line); a fold picks the grid point best on its
//!   training recordings. The grid of an effect that places a resonance
//!   with one parameter (pulley, tension stiffening, brake clamp) is the
//!   bracket its screen found ([`super::screen`]), not a fixed coarse one;
//! - linear: effects that add a small excitation (guide friction, sheave
//!   eccentricity, dead time, current-sensor errors, encoder error) are
//!   simulated once per probe; their influence for any parameter value is
//!   the same combination of the probe runs' spectra (amplitude and phase as
//!   the two components `a cos`, `a sin`), and a fold fits the combination
//!   on its training recordings (Nelder-Mead). The model is linear in
//!   these strengths only to first order, so a fit that shrinks the gap
//!   is taken again with probes around its answer ([`relinearize`]).
//!
//! Effects are ranked by the held-out excess gap after the fit, with a
//! penalty of [`PARAMETER_PENALTY`] per fitted parameter; when no single
//! effect removes [`PAIR_TRIGGER_SHRINK`] of the held-out gap, the pairs of
//! the best three are tried too.

use std::f64::consts::TAU;

use rayon::prelude::*;

use super::hypotheses::Refit;
use super::measure::gap;
use super::screen;
use super::spectra::{Bands, CellPowers, ChainSpectra, CrossPowers};
use super::target::Target;
use plant::effects::{EffectKind, Effects, Fit as Declared, FromData, Neutral, ParamScale, ParamSpec};
use recording::RecordingKind;
use rig_config::RigConfig;

mod relinearize;

/// Relative penalty per fitted parameter on the held-out gap when ranking.
pub const PARAMETER_PENALTY: f64 = 0.03;
/// Pairs are tried when the best single effect shrinks the held-out gap by less.
pub const PAIR_TRIGGER_SHRINK: f64 = 0.7;
/// Rounds of grid refinement around the best point.
pub const REFINEMENT_ROUNDS: usize = 2;
/// A grid is refined only when its best point leaves less than this
/// fraction of the nominal model's gap (on all recordings).
pub const REFINE_IF_BELOW: f64 = 0.9;
/// A pair is kept only when its held-out gap after the fit is below this
/// fraction of its better member's.
pub const PAIR_MARGIN: f64 = 0.8;

/// What the attribution works on.
pub struct Lab<'a> {
    /// The calibrated rig.
    pub rig: &'a RigConfig,
    /// The recordings.
    pub targets: &'a [Target],
    /// The bands.
    pub bands: &'a Bands,
    /// `tension_stiffening`'s reference tension from the calibration, N.
    pub reference_tension_n: Option<f64>,
    /// The calibration re-done under the hypotheses of the effects it can
    /// absorb ([`super::hypotheses`]): such an effect is fitted on its
    /// re-calibrated rig, over the grid its calibration gave.
    pub refits: &'a [Refit],
    /// Parameters measured without the model (the recorded currents'
    /// balance, [`crate::current_balance`]): held at their value in every
    /// fit of their effect instead of fitted to the mechanics.
    pub known: &'a [KnownParameter],
    /// Called after every batch of runs with (runs done, runs planned).
    pub progress: &'a (dyn Fn(usize, usize) + Sync),
}

/// A parameter of a linear effect measured without the model: every fit
/// holds it at its value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KnownParameter {
    /// The effect.
    pub effect: EffectKind,
    /// The parameter's index in the effect's declaration.
    pub index: usize,
    /// Its measured value (the parameter's unit).
    pub value: f64,
    /// Its standard error (same unit).
    pub uncertainty: f64,
    /// What measured it, in words.
    pub source: &'static str,
}

/// One fitted parameter with its spread across the folds.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct FittedParameter {
    /// Effect.
    pub effect: &'static str,
    /// Parameter name (with its unit suffix).
    pub name: &'static str,
    /// Unit.
    pub unit: &'static str,
    /// Value fitted on all recordings.
    pub value: f64,
    /// Jackknife standard error over the folds (same unit), or the
    /// measurement's standard error for a parameter measured without the
    /// model.
    pub uncertainty: f64,
    /// What measured the parameter when it was not fitted to the
    /// mechanics ([`KnownParameter`]); `None`: fitted.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub measured_by: Option<&'static str>,
}

/// An effect (or a pair) after fitting and cross-validation.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Candidate {
    /// Effect name, or `a + b` for a pair.
    pub name: String,
    /// Its parameters as fitted on all recordings.
    pub parameters: Vec<FittedParameter>,
    /// Number of fitted parameters.
    pub fitted_parameters: usize,
    /// Mean training excess gap before (nominal model), dB.
    pub training_gap_before_db: f64,
    /// Mean training excess gap after the fit, dB.
    pub training_gap_after_db: f64,
    /// Mean held-out excess gap before, dB.
    pub held_out_gap_before_db: f64,
    /// Mean held-out excess gap after the fit on the other recordings, dB.
    pub held_out_gap_after_db: f64,
    /// `1 - after / before` on the held-out recordings.
    pub held_out_shrink: f64,
    /// Ranking score: held-out gap after times `1 + penalty * parameters`, dB.
    pub score_db: f64,
    /// Per held-out recording, the excess gap the fit on the other
    /// recordings removes there (before - after), dB.
    pub held_out_improvements_db: Vec<f64>,
    /// The fitted parameters (`effect.parameter`) that sit at the edge of
    /// their search on the side where the effect vanishes
    /// ([`super::naming::Neutral`]).
    pub search_edge: Vec<String>,
    /// Whether the candidate may be named ([`super::naming`]).
    pub naming: super::naming::Naming,
    /// The calibration under the candidate's hypothesis, when it was
    /// re-done ([`super::hypotheses`]): the effect is fitted on that rig.
    pub refit: Option<Refit>,
    /// The model with the effect(s) as fitted on all recordings.
    #[serde(skip)]
    pub effects: Effects,
}

/// How one effect is searched.
#[derive(Clone, Debug)]
enum Search {
    /// Simulated at these full parameter vectors.
    Grid(Vec<Vec<f64>>),
    /// Simulated at these probes; the coefficients map to the parameters
    /// of `kind` by its declared fit ([`linear_parameters`]).
    Linear { probes: Vec<Vec<f64>>, kind: EffectKind },
}

/// The parameter vector every search of `kind` starts from: its defaults,
/// a parameter taken from the data ([`FromData`]) at the measured value
/// within its range.
fn search_base(kind: EffectKind, reference_tension_n: Option<f64>) -> Vec<f64> {
    kind.parameters()
        .iter()
        .map(|spec| match (spec.from_data, reference_tension_n) {
            (Some(FromData::StaticRopeTension), Some(t)) => t.clamp(spec.min, spec.max),
            _ => spec.default,
        })
        .collect()
}

/// The search of `kind`, as its declaration ([`Declared`]) says: a grid's
/// points (every combination of its axes, the first outermost), or a
/// linear effect's probes (each strength alone at its probe, the other
/// fitted strengths at their neutral value; an amplitude at phase 0 and a
/// quarter turn).
fn search(kind: EffectKind, reference_tension_n: Option<f64>) -> Search {
    let base = search_base(kind, reference_tension_n);
    let specs = kind.parameters();
    match kind.fit() {
        Declared::Grid { axes, .. } => {
            let mut points = vec![base];
            for &(i, values) in axes {
                points = points
                    .iter()
                    .flat_map(|p| {
                        values.iter().map(move |&x| {
                            let mut q = p.clone();
                            q[i] = x;
                            q
                        })
                    })
                    .collect();
            }
            Search::Grid(points)
        }
        Declared::Linear(strengths) => {
            let mut neutral = base;
            for &(j, _) in strengths {
                neutral[j] = match specs[j].neutral {
                    Neutral::At(v) => v,
                    _ => 0.0,
                };
            }
            let probes = strengths
                .iter()
                .map(|&(i, probe)| {
                    let mut p = neutral.clone();
                    p[i] = probe;
                    p
                })
                .collect();
            Search::Linear { probes, kind }
        }
        Declared::Polar { amplitude, phase, probe } => {
            let probes = [0.0, 0.25 * TAU]
                .iter()
                .map(|&angle| {
                    let mut p = base.clone();
                    p[amplitude] = probe;
                    p[phase] = angle;
                    p
                })
                .collect();
            Search::Linear { probes, kind }
        }
    }
}

/// The parameters of the linear effect `kind` at coefficients `c` (one per
/// probe, [`search`]): each strength its probe times its coefficient
/// within its range; an amplitude and phase from the two coefficients as
/// the components `a cos`, `a sin`.
fn linear_parameters(kind: EffectKind, c: &[f64]) -> Vec<f64> {
    let specs = kind.parameters();
    let mut out = search_base(kind, None);
    match kind.fit() {
        Declared::Linear(strengths) => {
            for (&(i, probe), &ci) in strengths.iter().zip(c) {
                out[i] = (probe * ci).clamp(specs[i].min, specs[i].max);
            }
        }
        Declared::Polar { amplitude, phase, probe } => {
            out[amplitude] = (probe * c[0].hypot(c[1])).min(specs[amplitude].max);
            out[phase] = c[1].atan2(c[0]).rem_euclid(TAU);
        }
        Declared::Grid { .. } => {}
    }
    out
}

/// The coefficients `c` of the linear effect `kind` kept where its
/// parameters stay within their ranges.
fn clamp_coefficients(kind: EffectKind, c: &[f64]) -> Vec<f64> {
    let specs = kind.parameters();
    match kind.fit() {
        Declared::Linear(strengths) => strengths
            .iter()
            .zip(c)
            .map(|(&(i, probe), &ci)| ci.clamp(specs[i].min / probe, specs[i].max / probe))
            .collect(),
        Declared::Polar { amplitude, probe, .. } => {
            let r = c[0].hypot(c[1]);
            let limit = specs[amplitude].max / probe;
            if r > limit {
                vec![c[0] * limit / r, c[1] * limit / r]
            } else {
                c.to_vec()
            }
        }
        Declared::Grid { .. } => c.to_vec(),
    }
}

/// Number of fitted parameters of `kind`.
fn fitted_count(kind: EffectKind) -> usize {
    kind.parameters().iter().filter(|s| s.fitted).count()
}

/// Grid points to add around `best` along every fitted dimension, in the
/// parameter's scale: midpoints towards its neighbours, and where it ends
/// its searched line, a point as far beyond that end as its neighbour lies
/// within (kept in the accepted range: halfway to the range's end where
/// the step would leave it): a best point at the end of its line is not
/// yet a minimum, and the search goes on past it.
fn refinement(kind: EffectKind, grid: &[Vec<f64>], best: usize) -> Vec<Vec<f64>> {
    let specs = kind.parameters();
    let b = &grid[best];
    let mut out: Vec<Vec<f64>> = Vec::new();
    for (j, spec) in specs.iter().enumerate() {
        if !spec.fitted {
            continue;
        }
        let same_elsewhere =
            |p: &Vec<f64>| p.iter().zip(b).enumerate().all(|(i, (x, y))| i == j || (x - y).abs() <= 1e-12 * y.abs());
        let line: Vec<f64> = grid.iter().filter(|p| same_elsewhere(p)).map(|p| p[j]).collect();
        let lower = line.iter().copied().filter(|&x| x < b[j]).fold(f64::NEG_INFINITY, f64::max);
        let upper = line.iter().copied().filter(|&x| x > b[j]).fold(f64::INFINITY, f64::min);
        let towards = [lower, upper].into_iter().filter(|n| n.is_finite()).filter_map(|n| midpoint(spec, n, b[j]));
        let beyond = match (lower.is_finite(), upper.is_finite()) {
            (false, true) => beyond_the_end(spec, b[j], upper),
            (true, false) => beyond_the_end(spec, b[j], lower),
            _ => None,
        };
        for x in towards.chain(beyond) {
            let mut p = b.clone();
            p[j] = x;
            if !grid.contains(&p) && !out.contains(&p) {
                out.push(p);
            }
        }
    }
    out
}

/// The point halfway between `a` and `b` in `spec`'s scale (`None` for
/// whole numbers with none between them).
fn midpoint(spec: &ParamSpec, a: f64, b: f64) -> Option<f64> {
    match spec.scale {
        ParamScale::Log => Some((a * b).sqrt()),
        ParamScale::Integer => Some((0.5 * (a + b)).round()).filter(|m| *m != a && *m != b),
        _ => Some(0.5 * (a + b)),
    }
}

/// The point past `end` (the end of a searched line) as far from it as its
/// `neighbour` on the line, in `spec`'s scale; where that leaves the
/// accepted range (or, on a linear scale, reaches its bound), halfway (in
/// the scale) between `end` and the range's bound; `None` when `end` is
/// the bound (or a phase, which has no end).
fn beyond_the_end(spec: &ParamSpec, end: f64, neighbour: f64) -> Option<f64> {
    let bound = if neighbour > end { spec.min } else { spec.max };
    let step = match spec.scale {
        ParamScale::Log if end > 0.0 && neighbour > 0.0 => end * end / neighbour,
        ParamScale::Log | ParamScale::Angle => return None,
        _ => 2.0 * end - neighbour,
    };
    // A linear range's bound is where the effect vanishes (the screen's
    // dense line leaves it out too); another scale's bound is a value.
    let inside = match (neighbour > end, spec.scale == ParamScale::Linear) {
        (true, true) => step > bound,
        (true, false) => step >= bound,
        (false, true) => step < bound,
        (false, false) => step <= bound,
    };
    let x = if inside { step } else { midpoint(spec, end, bound)? };
    Some(x).filter(|&x| x != end && x.is_finite() && (spec.min..=spec.max).contains(&x))
}

/// Per recording, the spectra of one model's run (`None` where it failed).
type Runs = Vec<Option<ChainSpectra>>;
/// The parameter vectors of the grid effects of one model.
type GridPoint = Vec<(EffectKind, Vec<f64>)>;

fn effects_of(points: &[(EffectKind, Vec<f64>)]) -> Option<Effects> {
    let mut e = Effects::none();
    for (k, v) in points {
        e.set(*k, v).ok()?;
    }
    Some(e)
}

/// How many runs are done and planned, for [`Lab::progress`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct RunCount {
    /// Models run on every recording so far.
    done: usize,
    /// Models planned so far.
    planned: usize,
}

impl Lab<'_> {
    /// Runs the model with each of `models` on every recording, in parallel;
    /// counts them as done and reports the progress.
    fn run_all(&self, models: &[Effects], count: &mut RunCount) -> Vec<Runs> {
        let out = self.run_on(models, &self.all());
        count.done += models.len();
        (self.progress)(count.done, count.planned);
        out
    }

    /// Runs the model with each of `models` on the recordings `set`, in
    /// parallel: per model, per recording of `set` (in its order).
    fn run_on(&self, models: &[Effects], set: &[usize]) -> Vec<Runs> {
        self.run_on_rig(self.rig, models, set)
    }

    /// [`Self::run_on`] on `rig` instead of the calibrated rig.
    fn run_on_rig(&self, rig: &RigConfig, models: &[Effects], set: &[usize]) -> Vec<Runs> {
        let jobs: Vec<(usize, usize)> = (0..models.len()).flat_map(|m| set.iter().map(move |&t| (m, t))).collect();
        let results: Vec<Option<ChainSpectra>> = jobs
            .par_iter()
            .map(|&(m, t)| {
                let target = &self.targets[t];
                if self.runs_as_nominal(rig, &models[m], target) {
                    return Some(target.nominal.clone());
                }
                target
                    .counterpart
                    .simulate(rig, &models[m], &target.recording, &target.stem)
                    .ok()
                    .map(|signals| ChainSpectra::compute(&signals, &target.segmentation, self.bands))
            })
            .collect();
        let mut out = vec![Vec::with_capacity(set.len()); models.len()];
        for ((m, _), r) in jobs.into_iter().zip(results) {
            out[m].push(r);
        }
        out
    }

    /// Whether the run of `effects` on `rig` for `target` is its nominal
    /// run: a free decay, on the calibrated rig, with none of the effects a
    /// free decay has ([`Effects::for_free_decay`]).
    fn runs_as_nominal(&self, rig: &RigConfig, effects: &Effects, target: &Target) -> bool {
        matches!(target.recording.meta.kind, RecordingKind::FreeDecay { .. })
            && effects.for_free_decay().is_nominal()
            && (std::ptr::eq(rig, self.rig) || rig == self.rig)
    }

    /// Step: the screened grid of every effect of `kinds` that is screened
    /// ([`screen::is_screened`]): its dense line run on the recording the
    /// nominal model (excess `nominal`, dB) misses most, and the best point
    /// with its neighbours kept. An effect whose line did not run keeps its
    /// grid.
    fn screen(&self, kinds: &[EffectKind], nominal: &[f64], count: &mut RunCount) -> Vec<(EffectKind, Vec<Vec<f64>>)> {
        let Some(t) = screen::screening_target(nominal) else {
            return Vec::new();
        };
        // Each screened effect: its dense line and the grid it replaces.
        type Points = Vec<Vec<f64>>;
        let mut lines: Vec<(EffectKind, Points, Points)> = Vec::new();
        for &kind in kinds.iter().filter(|&&k| screen::is_screened(k)) {
            if let Search::Grid(points) = search(kind, self.reference_tension_n) {
                lines.push((kind, screen::dense_line(kind, &screen::line_template(kind, &points[0])), points));
            }
        }
        let models: Vec<Effects> = lines
            .iter()
            .flat_map(|(k, line, _)| line.iter().map(|p| effects_of(&[(*k, p.clone())])))
            .flatten()
            .collect();
        if models.len() != lines.iter().map(|(_, l, _)| l.len()).sum::<usize>() {
            // A value the effect refuses: keep the grids.
            return Vec::new();
        }
        let equivalent = models.len().div_ceil(self.targets.len().max(1));
        count.planned += equivalent;
        let runs = self.run_on(&models, &[t]);
        count.done += equivalent;
        (self.progress)(count.done, count.planned);
        let mut scores =
            runs.iter().map(|r| r[0].as_ref().map_or(f64::INFINITY, |spectra| self.run_excess(t, spectra)));
        let mut out = Vec::new();
        for (kind, line, grid) in lines {
            let line_scores: Vec<f64> = scores.by_ref().take(line.len()).collect();
            if let Some(kept) = screen::bracket(&line_scores) {
                let bracket: Vec<f64> = kept.into_iter().map(|i| line[i][0]).collect();
                out.push((kind, screen::across_grid(&bracket, &grid)));
            }
        }
        out
    }

    fn excess(&self, t: usize, powers: &CellPowers) -> f64 {
        gap(&self.targets[t].measured, &self.targets[t].noise, &self.targets[t].tolerances, powers).excess_db()
    }

    /// The excess gap on recording `t` of one model's run there, dB.
    fn run_excess(&self, t: usize, spectra: &ChainSpectra) -> f64 {
        self.excess(t, &CrossPowers::compute(&[spectra], self.bands).powers(&[1.0]))
    }

    /// The nominal model's excess gap on every recording, dB.
    pub fn nominal_excess(&self) -> Vec<f64> {
        (0..self.targets.len()).map(|t| self.run_excess(t, &self.targets[t].nominal)).collect()
    }

    /// Every recording's index.
    fn all(&self) -> Vec<usize> {
        (0..self.targets.len()).collect()
    }
}

/// A base model of a family: one point of its grid effects (or the nominal
/// model) with its runs.
#[derive(Clone, Debug)]
struct Base {
    /// The grid effects' parameter vectors (empty for the nominal model).
    point: GridPoint,
    /// Its runs.
    runs: Runs,
}

/// A linear effect of a family with its probe runs.
#[derive(Clone, Debug)]
struct LinearEffect {
    /// The effect.
    kind: EffectKind,
    /// Its search ([`Search::Linear`]).
    search: Search,
    /// Per probe, its runs.
    probes: Vec<Runs>,
    /// The coefficients the probes are taken around ([`linear_parameters`]'s,
    /// one per probe): zero for probes around the nominal model.
    origin: Vec<f64>,
    /// Per probe, the step of its coefficient from the origin.
    steps: Vec<f64>,
}

impl LinearEffect {
    /// Probes around the nominal model, one unit step each.
    fn around_nominal(kind: EffectKind, search: Search, probes: Vec<Runs>) -> Self {
        let n = probes.len();
        Self { kind, search, probes, origin: vec![0.0; n], steps: vec![1.0; n] }
    }

    /// The coefficients ([`linear_parameters`]'s) of the fitted ones `c`
    /// (one per probe, in probe steps from the origin).
    fn absolute(&self, c: &[f64]) -> Vec<f64> {
        self.origin.iter().zip(&self.steps).zip(c).map(|((o, s), c)| o + s * c).collect()
    }

    /// The fitted coefficients of the coefficients `absolute`.
    fn relative(&self, absolute: &[f64]) -> Vec<f64> {
        absolute.iter().enumerate().map(|(p, &a)| self.relative_at(p, a)).collect()
    }

    /// Probe `p`'s fitted coefficient of its coefficient `absolute`.
    fn relative_at(&self, p: usize, absolute: f64) -> f64 {
        (absolute - self.origin[p]) / self.steps[p]
    }
}

/// A family's best fit on a set of recordings.
#[derive(Clone, Debug, PartialEq)]
struct Fit {
    /// Index of the base in [`Family::bases`].
    base: usize,
    /// The linear effects' coefficients (clamped), one per probe.
    coefficients: Vec<f64>,
    /// Mean excess gap over the set, dB.
    excess_db: f64,
}

/// A family of models: base runs (grid points, or the nominal model) and
/// linear probes, fitted jointly.
struct Family {
    /// Its effects (one, or the two of a pair).
    kinds: Vec<EffectKind>,
    /// The grid effects' points (or the nominal model) with their runs.
    bases: Vec<Base>,
    /// The linear effects with their probe runs.
    linear: Vec<LinearEffect>,
    /// Per base, per recording: cross powers of [base, nominal, probes...].
    cross: Vec<Vec<Option<CrossPowers>>>,
    /// The calibration under the family's hypothesis, whose rig its runs
    /// use (`None`: the calibrated rig).
    refit: Option<Refit>,
    /// Whether the linear probes are differences from the base's runs (the
    /// model at the probes' origin, [`relinearize`]) rather than from the
    /// nominal model's.
    probes_from_base: bool,
}

impl Family {
    fn coefficient_count(&self) -> usize {
        self.linear.iter().map(|l| l.probes.len()).sum()
    }

    fn prepare(&mut self, lab: &Lab) {
        self.cross = self
            .bases
            .iter()
            .map(|base| {
                (0..lab.targets.len())
                    .into_par_iter()
                    .map(|t| {
                        let base = base.runs[t].as_ref()?;
                        let reference = if self.probes_from_base { base } else { &lab.targets[t].nominal };
                        let mut parts: Vec<&ChainSpectra> = vec![base, reference];
                        for l in &self.linear {
                            for p in &l.probes {
                                parts.push(p[t].as_ref()?);
                            }
                        }
                        Some(CrossPowers::compute(&parts, lab.bands))
                    })
                    .collect()
            })
            .collect();
    }

    /// Per coefficient, its value when the parameter it scales is known
    /// ([`Lab::known`]): the known value over the probe's; `None`: fitted.
    fn held_coefficients(&self, known: &[KnownParameter]) -> Vec<Option<f64>> {
        let mut out = Vec::with_capacity(self.coefficient_count());
        for l in &self.linear {
            match l.kind.fit() {
                Declared::Linear(strengths) if l.probes.len() == strengths.len() => {
                    out.extend(strengths.iter().enumerate().map(|(p, &(i, probe))| {
                        let known = known.iter().find(|k| k.effect == l.kind && k.index == i)?;
                        Some(l.relative_at(p, known.value / probe))
                    }));
                }
                _ => out.extend(std::iter::repeat_n(None, l.probes.len())),
            }
        }
        out
    }

    fn clamp(&self, c: &[f64]) -> Vec<f64> {
        let mut out = Vec::with_capacity(c.len());
        let mut i = 0;
        for l in &self.linear {
            let n = l.probes.len();
            if let Search::Linear { kind, .. } = &l.search {
                out.extend(l.relative(&clamp_coefficients(*kind, &l.absolute(&c[i..i + n]))));
            }
            i += n;
        }
        out
    }

    /// Mean excess gap over `set` at base `b`, coefficients `c` (clamped).
    fn score(&self, lab: &Lab, b: usize, c: &[f64], set: &[usize]) -> f64 {
        let c = self.clamp(c);
        let mut w = vec![1.0, -c.iter().sum::<f64>()];
        w.extend_from_slice(&c);
        let mut sum = 0.0;
        for &t in set {
            match &self.cross[b][t] {
                Some(cross) => sum += lab.excess(t, &cross.powers(&w)),
                None => return f64::INFINITY,
            }
        }
        sum / set.len().max(1) as f64
    }

    /// The free coefficients (those not `held`) of no effect: zero, or,
    /// for probes around an answer, that answer's distance from no effect
    /// in probe steps.
    fn neutral_start(&self, held: &[Option<f64>]) -> Vec<f64> {
        let neutral = self.linear.iter().flat_map(|l| l.relative(&vec![0.0; l.probes.len()]));
        neutral.zip(held).filter(|(_, h)| h.is_none()).map(|(n, _)| n).collect()
    }

    /// Best fit on `set`, the known coefficients held.
    fn fit(&self, lab: &Lab, set: &[usize]) -> Fit {
        let held = self.held_coefficients(lab.known);
        // The full coefficient vector from the free ones.
        let full = |free: &[f64]| -> Vec<f64> {
            let mut free = free.iter();
            held.iter().map(|h| h.unwrap_or_else(|| free.next().copied().unwrap_or(0.0))).collect()
        };
        let score = |b: usize, free: &[f64]| self.score(lab, b, &full(free), set);
        let d = held.iter().filter(|h| h.is_none()).count();
        let mut best = Fit { base: 0, coefficients: self.clamp(&full(&[])), excess_db: f64::INFINITY };
        for b in 0..self.bases.len() {
            let (c, s) = if d == 0 {
                (Vec::new(), score(b, &[]))
            } else {
                // Every fit starts from no effect, also where the probes
                // are taken around an answer on all recordings: a fold's
                // fit owes nothing to its held-out recordings.
                let neutral = self.neutral_start(&held);
                let starts = starting_points(d);
                let (mut x0, mut s0) = (neutral.clone(), f64::INFINITY);
                for x in starts {
                    let x: Vec<f64> = x.iter().zip(&neutral).map(|(x, n)| x + n).collect();
                    let s = score(b, &x);
                    if s < s0 {
                        (x0, s0) = (x, s);
                    }
                }
                // Coordinate sweeps: the components of a many-parameter
                // effect act on different lines, nearly independently.
                if d >= 3 {
                    for _ in 0..2 {
                        for i in 0..d {
                            for v in [-4.0, -2.5, -1.5, -0.75, -0.25, 0.0, 0.25, 0.75, 1.5, 2.5, 4.0] {
                                let mut x = x0.clone();
                                x[i] = neutral[i] + v;
                                let s = score(b, &x);
                                if s < s0 {
                                    (x0, s0) = (x, s);
                                }
                            }
                        }
                    }
                }
                let (x1, _) = nelder_mead(|x| score(b, x), &x0, 0.5, 60 * d + 40);
                nelder_mead(|x| score(b, x), &x1, 0.2, 60 * d + 40)
            };
            if s < best.excess_db {
                best = Fit { base: b, coefficients: self.clamp(&full(&c)), excess_db: s };
            }
        }
        best
    }

    /// The parameters (per effect, full vectors) at `(b, c)`.
    fn parameters(&self, b: usize, c: &[f64]) -> Vec<(EffectKind, Vec<f64>)> {
        let mut out = self.bases[b].point.clone();
        let mut i = 0;
        for l in &self.linear {
            let n = l.probes.len();
            if let Search::Linear { kind, .. } = &l.search {
                out.push((l.kind, linear_parameters(*kind, &l.absolute(&c[i..i + n]))));
            }
            i += n;
        }
        out
    }

    /// The parameters fitted to the mechanics: the declared fitted ones
    /// but those held known.
    fn fitted_parameters(&self, known: &[KnownParameter]) -> usize {
        let held = self.held_coefficients(known).iter().filter(|h| h.is_some()).count();
        self.kinds.iter().map(|k| fitted_count(*k)).sum::<usize>() - held
    }

    /// The fitted grid parameters (`effect.parameter`) of base `b` that
    /// sit at the end of their searched line (the bases equal to `b` but
    /// in that parameter) on the side where the effect vanishes, with
    /// values the effect accepts left between that end and the neutral
    /// value: the fit could have gone on towards no effect.
    fn search_edge(&self, b: usize) -> Vec<String> {
        let mut out = Vec::new();
        let best = &self.bases[b].point;
        for (e, (kind, values)) in best.iter().enumerate() {
            for (j, spec) in kind.parameters().iter().enumerate() {
                if !spec.fitted {
                    continue;
                }
                let line: Vec<f64> = self
                    .bases
                    .iter()
                    .filter(|base| {
                        base.point.len() == best.len()
                            && base.point.iter().zip(best).enumerate().all(|(f, ((k, v), (kb, vb)))| {
                                k == kb
                                    && v.iter().zip(vb).enumerate().all(|(i, (x, y))| {
                                        (f == e && i == j) || (x - y).abs() <= 1e-12 * y.abs().max(1e-300)
                                    })
                            })
                    })
                    .map(|base| base.point[e].1[j])
                    .collect();
                if line.len() < 2 {
                    continue;
                }
                let v = values[j];
                let lo = line.iter().copied().fold(f64::INFINITY, f64::min);
                let hi = line.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                let open_towards_neutral = match spec.neutral {
                    Neutral::At(v0) if v0 < v => {
                        v <= lo && if spec.scale == ParamScale::Integer { v - 1.0 > v0 } else { v > spec.min }
                    }
                    Neutral::At(v0) if v0 > v => v >= hi && v < spec.max,
                    Neutral::AboveRange => v >= hi && v < spec.max,
                    _ => false,
                };
                if open_towards_neutral {
                    out.push(format!("{}.{}", kind.name(), spec.name));
                }
            }
        }
        out
    }
}

fn starting_points(d: usize) -> Vec<Vec<f64>> {
    let mut out = vec![vec![0.0; d]];
    if d <= 2 {
        let values = [-2.0, -1.0, 1.0, 2.0];
        if d == 1 {
            out.extend(values.iter().map(|&v| vec![v]));
        } else {
            for &a in &[-2.0, -1.0, 0.0, 1.0, 2.0] {
                for &b in &[-2.0, -1.0, 0.0, 1.0, 2.0] {
                    out.push(vec![a, b]);
                }
            }
        }
    } else {
        for i in 0..d {
            for v in [-1.5, 1.5] {
                let mut x = vec![0.0; d];
                x[i] = v;
                out.push(x);
            }
        }
    }
    out
}

/// Nelder-Mead minimisation of `f` from `x0` with initial step `step`;
/// returns the best point and its value.
pub fn nelder_mead(f: impl Fn(&[f64]) -> f64, x0: &[f64], step: f64, max_evals: usize) -> (Vec<f64>, f64) {
    let d = x0.len();
    let mut simplex: Vec<(Vec<f64>, f64)> = Vec::with_capacity(d + 1);
    simplex.push((x0.to_vec(), f(x0)));
    for i in 0..d {
        let mut x = x0.to_vec();
        x[i] += step;
        let v = f(&x);
        simplex.push((x, v));
    }
    let mut evals = d + 1;
    while evals < max_evals {
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        if (simplex[d].1 - simplex[0].1).abs() < 1e-4 {
            break;
        }
        let centroid: Vec<f64> = (0..d).map(|j| simplex[..d].iter().map(|p| p.0[j]).sum::<f64>() / d as f64).collect();
        let towards =
            |t: f64| -> Vec<f64> { (0..d).map(|j| centroid[j] + t * (simplex[d].0[j] - centroid[j])).collect() };
        let xr = towards(-1.0);
        let fr = f(&xr);
        evals += 1;
        if fr < simplex[0].1 {
            let xe = towards(-2.0);
            let fe = f(&xe);
            evals += 1;
            simplex[d] = if fe < fr { (xe, fe) } else { (xr, fr) };
        } else if fr < simplex[d - 1].1 {
            simplex[d] = (xr, fr);
        } else {
            let xc = towards(0.5);
            let fc = f(&xc);
            evals += 1;
            if fc < simplex[d].1 {
                simplex[d] = (xc, fc);
            } else {
                let best = simplex[0].0.clone();
                for p in simplex.iter_mut().skip(1) {
                    p.0 = (0..d).map(|j| best[j] + 0.5 * (p.0[j] - best[j])).collect();
                    p.1 = f(&p.0);
                    evals += 1;
                }
            }
        }
    }
    simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
    simplex.swap_remove(0)
}

/// Cross-validation folds: per group, (training, held out) recording indices.
fn folds(targets: &[Target]) -> Vec<(Vec<usize>, Vec<usize>)> {
    let mut groups: Vec<&str> = targets.iter().map(|t| t.group.as_str()).collect();
    groups.sort();
    groups.dedup();
    let by_group = groups.len() >= 2;
    let keys: Vec<String> = if by_group {
        groups.iter().map(|g| g.to_string()).collect()
    } else {
        targets.iter().map(|t| t.stem.clone()).collect()
    };
    keys.iter()
        .map(|k| {
            let held: Vec<usize> = (0..targets.len())
                .filter(|&i| if by_group { targets[i].group == *k } else { targets[i].stem == *k })
                .collect();
            let train: Vec<usize> = (0..targets.len()).filter(|i| !held.contains(i)).collect();
            (train, held)
        })
        .filter(|(train, held)| !train.is_empty() && !held.is_empty())
        .collect()
}

/// Jackknife standard error of one parameter from its values fitted per
/// fold (same unit); NaN with fewer than two folds.
pub(crate) fn jackknife_error(per_fold: &[f64]) -> f64 {
    let mean = per_fold.iter().sum::<f64>() / per_fold.len().max(1) as f64;
    if per_fold.len() >= 2 {
        let n = per_fold.len() as f64;
        ((n - 1.0) / n * per_fold.iter().map(|v| (v - mean).powi(2)).sum::<f64>()).sqrt()
    } else {
        f64::NAN
    }
}

/// Step: the fitted parameters of `params` (fitted on all recordings), each
/// with its jackknife error over `fold_params` (the same effects fitted per
/// fold), or, when `known`, the measurement's error and source.
fn fitted_parameter_list(
    params: &[(EffectKind, Vec<f64>)],
    fold_params: &[GridPoint],
    known: &[KnownParameter],
) -> Vec<FittedParameter> {
    let mut parameters = Vec::new();
    for (e, (kind, values)) in params.iter().enumerate() {
        for (j, spec) in kind.parameters().iter().enumerate() {
            if !spec.fitted {
                continue;
            }
            let per_fold: Vec<f64> = fold_params.iter().map(|p| p[e].1[j]).collect();
            let measured = known.iter().find(|k| k.effect == *kind && k.index == j);
            parameters.push(FittedParameter {
                effect: kind.name(),
                name: spec.name,
                unit: spec.unit,
                value: values[j],
                uncertainty: measured.map_or_else(|| jackknife_error(&per_fold), |k| k.uncertainty),
                measured_by: measured.map(|k| k.source),
            });
        }
    }
    parameters
}

/// Cross-validates `family` into a candidate.
fn evaluate(lab: &Lab, family: &Family, nominal: &[f64]) -> Candidate {
    let all = lab.all();
    let folds = folds(lab.targets);
    let mut held_after = vec![f64::NAN; lab.targets.len()];
    let mut train_before = 0.0;
    let mut train_after = 0.0;
    let mut fold_params: Vec<GridPoint> = Vec::new();
    for (train, held) in &folds {
        let fit = family.fit(lab, train);
        train_before += train.iter().map(|&t| nominal[t]).sum::<f64>() / train.len() as f64;
        train_after += fit.excess_db;
        for &t in held {
            held_after[t] = family.score(lab, fit.base, &fit.coefficients, &[t]);
        }
        fold_params.push(family.parameters(fit.base, &fit.coefficients));
    }
    let k = folds.len().max(1) as f64;
    let fit_all = family.fit(lab, &all);
    let s_all = fit_all.excess_db;
    let params = family.parameters(fit_all.base, &fit_all.coefficients);
    let effects = effects_of(&params).unwrap_or_default();
    let parameters = fitted_parameter_list(&params, &fold_params, lab.known);
    let held: Vec<usize> = (0..lab.targets.len()).filter(|&t| held_after[t].is_finite()).collect();
    let mean_of = |v: &dyn Fn(usize) -> f64| held.iter().map(|&t| v(t)).sum::<f64>() / held.len().max(1) as f64;
    let (before, after) = if held.is_empty() {
        (nominal.iter().sum::<f64>() / nominal.len().max(1) as f64, s_all)
    } else {
        (mean_of(&|t| nominal[t]), mean_of(&|t| held_after[t]))
    };
    let fitted = family.fitted_parameters(lab.known);
    Candidate {
        held_out_improvements_db: held.iter().map(|&t| nominal[t] - held_after[t]).collect(),
        search_edge: family.search_edge(fit_all.base),
        naming: Default::default(),
        refit: family.refit.clone(),
        name: family.kinds.iter().map(|k| k.name()).collect::<Vec<_>>().join(" + "),
        parameters,
        fitted_parameters: fitted,
        training_gap_before_db: if folds.is_empty() { before } else { train_before / k },
        training_gap_after_db: if folds.is_empty() { s_all } else { train_after / k },
        held_out_gap_before_db: before,
        held_out_gap_after_db: after,
        held_out_shrink: if before > 0.0 { 1.0 - after / before } else { 0.0 },
        score_db: after * (1.0 + PARAMETER_PENALTY * fitted as f64),
        effects,
    }
}

/// One effect of the first stage, as planned.
struct PlannedEffect {
    /// The effect.
    kind: EffectKind,
    /// How it is searched.
    search: Search,
    /// Indices in [`FirstStage::models`] of its grid points or probes, in order.
    models: Vec<usize>,
}

/// Every run of the first stage: each effect's grid points or probes.
struct FirstStage {
    /// The effects, in the order asked.
    effects: Vec<PlannedEffect>,
    /// The models to run, every effect's points in turn.
    models: Vec<Effects>,
}

/// Step: plans the first stage's runs of `kinds` (a point that the effect
/// refuses runs as the nominal model); a screened effect's grid is its
/// points in `screened`.
fn plan_first_stage(
    kinds: &[EffectKind],
    reference_tension_n: Option<f64>,
    screened: &[(EffectKind, Vec<Vec<f64>>)],
) -> FirstStage {
    let mut models: Vec<Effects> = Vec::new();
    let mut effects = Vec::new();
    for &kind in kinds {
        let search = match screened.iter().find(|(k, _)| *k == kind) {
            Some((_, points)) => Search::Grid(points.clone()),
            None => search(kind, reference_tension_n),
        };
        let points = match &search {
            Search::Grid(points) => points.clone(),
            Search::Linear { probes, .. } => probes.clone(),
        };
        let mut idx = Vec::new();
        for p in points {
            idx.push(models.len());
            models.push(effects_of(&[(kind, p)]).unwrap_or(Effects::none()));
        }
        effects.push(PlannedEffect { kind, search, models: idx });
    }
    FirstStage { effects, models }
}

/// Step: the family of one planned effect from the first stage's `runs`: a
/// grid effect's bases are its points; a linear effect has the nominal
/// model (`nominal_runs`) as its only base and its probes. Not prepared.
fn family_of(planned: &PlannedEffect, runs: &[Runs], nominal_runs: &Runs) -> Family {
    let kind = planned.kind;
    match &planned.search {
        Search::Grid(points) => Family {
            kinds: vec![kind],
            bases: points
                .iter()
                .zip(&planned.models)
                .map(|(p, &m)| Base { point: vec![(kind, p.clone())], runs: runs[m].clone() })
                .collect(),
            linear: Vec::new(),
            cross: Vec::new(),
            refit: None,
            probes_from_base: false,
        },
        Search::Linear { .. } => Family {
            kinds: vec![kind],
            bases: vec![Base { point: Vec::new(), runs: nominal_runs.clone() }],
            linear: vec![LinearEffect::around_nominal(
                kind,
                planned.search.clone(),
                planned.models.iter().map(|&m| runs[m].clone()).collect(),
            )],
            cross: Vec::new(),
            refit: None,
            probes_from_base: false,
        },
    }
}

/// A grid point to add to a family's grid.
#[derive(Clone, Debug, PartialEq)]
struct RefinementPoint {
    /// Index of the family.
    family: usize,
    /// Its (only) effect.
    kind: EffectKind,
    /// The effect's full parameter vector.
    values: Vec<f64>,
}

/// Step: the points of one refinement round: around the best point on all
/// recordings of every grid family that leaves less than
/// [`REFINE_IF_BELOW`] of `nominal_mean` (dB).
fn refinement_points(lab: &Lab, families: &[Family], nominal_mean: f64) -> Vec<RefinementPoint> {
    let all = lab.all();
    let mut out = Vec::new();
    for (i, f) in families.iter().enumerate() {
        if !f.linear.is_empty() {
            continue;
        }
        let fit = f.fit(lab, &all);
        if fit.excess_db >= REFINE_IF_BELOW * nominal_mean {
            continue;
        }
        let kind = f.kinds[0];
        let points: Vec<Vec<f64>> = f.bases.iter().map(|b| b.point[0].1.clone()).collect();
        for values in refinement(kind, &points, fit.base) {
            out.push(RefinementPoint { family: i, kind, values });
        }
    }
    out
}

/// Step: adds the refinement `points` with their `runs` as bases of their
/// families; returns the families touched (in order, each once when the
/// points come grouped by family).
fn add_refinement(families: &mut [Family], points: Vec<RefinementPoint>, runs: Vec<Runs>) -> Vec<usize> {
    let mut touched = Vec::new();
    for (p, r) in points.into_iter().zip(runs) {
        families[p.family].bases.push(Base { point: vec![(p.kind, p.values)], runs: r });
        touched.push(p.family);
    }
    touched.dedup();
    touched
}

/// Step: refines the grids of the effects that reduce the gap at all, up to
/// [`REFINEMENT_ROUNDS`] times, around their best point on all recordings.
fn refine_grids(lab: &Lab, families: &mut [Family], nominal_mean: f64, count: &mut RunCount) {
    for _round in 0..REFINEMENT_ROUNDS {
        let points = refinement_points(lab, families, nominal_mean);
        let models: Vec<Effects> =
            points.iter().map(|p| effects_of(&[(p.kind, p.values.clone())]).unwrap_or(Effects::none())).collect();
        if models.is_empty() {
            break;
        }
        count.planned = count.planned.max(count.done + models.len());
        // Each point on its family's rig (a re-calibrated one under its
        // hypothesis), the points of one rig in one batch.
        let rig_of = |p: &RefinementPoint| families[p.family].refit.as_ref().map(|r| &r.rig);
        let mut runs: Vec<Option<Runs>> = vec![None; models.len()];
        let mut groups: Vec<Option<&RigConfig>> = Vec::new();
        for p in &points {
            if !groups.contains(&rig_of(p)) {
                groups.push(rig_of(p));
            }
        }
        for g in groups {
            let idx: Vec<usize> = (0..points.len()).filter(|&i| rig_of(&points[i]) == g).collect();
            let batch: Vec<Effects> = idx.iter().map(|&i| models[i]).collect();
            let out = lab.run_on_rig(g.unwrap_or(lab.rig), &batch, &lab.all());
            for (i, r) in idx.into_iter().zip(out) {
                runs[i] = Some(r);
            }
        }
        count.done += models.len();
        (lab.progress)(count.done, count.planned);
        let runs: Vec<Runs> = runs.into_iter().map(Option::unwrap_or_default).collect();
        for f in add_refinement(families, points, runs) {
            families[f].prepare(lab);
        }
    }
}

impl Candidate {
    /// The rig the candidate's effects were fitted on: the re-calibrated
    /// one under its hypothesis, otherwise `calibrated`.
    pub fn rig<'a>(&'a self, calibrated: &'a RigConfig) -> &'a RigConfig {
        self.refit.as_ref().map_or(calibrated, |r| &r.rig)
    }
}

/// Sorts candidates best first (lowest score).
fn rank(candidates: &mut [Candidate]) {
    candidates.sort_by(|a, b| a.score_db.total_cmp(&b.score_db));
}

/// Fits every effect of the library (and pairs when needed); returns the
/// candidates ranked best first.
pub fn attribute(lab: &Lab, kinds: &[EffectKind]) -> Vec<Candidate> {
    let nominal = lab.nominal_excess();
    let mut count = RunCount { done: 0, planned: 0 };
    let refit_of = |k: EffectKind| lab.refits.iter().find(|r| r.effect == k.name());
    let (refitted, kinds): (Vec<EffectKind>, Vec<EffectKind>) = kinds.iter().partition(|&&k| refit_of(k).is_some());
    let screened = lab.screen(&kinds, &nominal, &mut count);
    let plan = plan_first_stage(&kinds, lab.reference_tension_n, &screened);
    count.planned +=
        plan.models.len() + refitted.iter().filter_map(|&k| refit_of(k)).map(|r| r.grid.len()).sum::<usize>();
    let runs = lab.run_all(&plan.models, &mut count);
    let nominal_runs: Runs = lab.targets.iter().map(|t| Some(t.nominal.clone())).collect();
    let mut families: Vec<Family> = Vec::new();
    for planned in &plan.effects {
        let mut f = family_of(planned, &runs, &nominal_runs);
        f.prepare(lab);
        families.push(f);
    }
    for kind in refitted {
        let Some(refit) = refit_of(kind) else { continue };
        let mut f = refit_family(lab, kind, refit, &mut count);
        f.prepare(lab);
        families.push(f);
    }
    let nominal_mean = nominal.iter().sum::<f64>() / nominal.len().max(1) as f64;
    refine_grids(lab, &mut families, nominal_mean, &mut count);
    // A linear effect's fit taken again around its answer; the pairs
    // combine the probes around the nominal model.
    let relinearized: Vec<Option<Family>> =
        families.iter().map(|f| relinearize::around_the_fit(lab, f, nominal_mean, &mut count)).collect();
    (lab.progress)(count.planned, count.planned);
    let mut candidates: Vec<Candidate> =
        families.iter().zip(&relinearized).map(|(f, r)| evaluate(lab, r.as_ref().unwrap_or(f), &nominal)).collect();
    rank(&mut candidates);
    if wants_pairs(&candidates) {
        add_pairs(lab, &families, &mut candidates, &nominal, &nominal_runs, &mut count);
        rank(&mut candidates);
    }
    candidates
}

/// Step: the family of `kind` under its hypothesis: its grid from the
/// re-done calibration `refit`, run on the re-calibrated rig.
fn refit_family(lab: &Lab, kind: EffectKind, refit: &Refit, count: &mut RunCount) -> Family {
    let models: Vec<Effects> =
        refit.grid.iter().map(|p| effects_of(&[(kind, p.clone())]).unwrap_or(Effects::none())).collect();
    let runs = lab.run_on_rig(&refit.rig, &models, &lab.all());
    count.done += models.len();
    (lab.progress)(count.done, count.planned);
    Family {
        kinds: vec![kind],
        bases: refit.grid.iter().zip(runs).map(|(p, runs)| Base { point: vec![(kind, p.clone())], runs }).collect(),
        linear: Vec::new(),
        cross: Vec::new(),
        refit: Some(refit.clone()),
        probes_from_base: false,
    }
}

/// Whether pairs are tried: the best single effect shrinks the held-out gap
/// by less than [`PAIR_TRIGGER_SHRINK`], and there are two effects at least.
fn wants_pairs(candidates: &[Candidate]) -> bool {
    candidates.first().is_some_and(|c| c.held_out_shrink < PAIR_TRIGGER_SHRINK) && candidates.len() >= 2
}

/// Step: the families of the best three candidates (ranked), those of a
/// single effect.
fn top_singles(candidates: &[Candidate], families: &[Family]) -> Vec<usize> {
    candidates
        .iter()
        .take(3)
        .filter_map(|c| families.iter().position(|f| f.kinds.len() == 1 && f.kinds[0].name() == c.name))
        // A family on its own re-calibrated rig pairs with no other.
        .filter(|&i| families[i].refit.is_none())
        .collect()
}

/// The grid points of the best two bases of a grid family by `score` (mean
/// excess gap of base `k`, dB), best first.
fn best_two_bases(f: &Family, score: impl Fn(usize) -> f64) -> Vec<GridPoint> {
    let mut scored: Vec<(usize, f64)> = (0..f.bases.len()).map(|k| (k, score(k))).collect();
    scored.sort_by(|x, y| x.1.total_cmp(&y.1));
    scored.iter().take(2).map(|(k, _)| f.bases[*k].point.clone()).collect()
}

/// Every point of `a` with every point of `b` (`a` the outer loop), joined.
fn grid_combos(a: &[GridPoint], b: &[GridPoint]) -> Vec<GridPoint> {
    let mut combos = Vec::new();
    for pa in a {
        for pb in b {
            let mut both = pa.clone();
            both.extend(pb.clone());
            combos.push(both);
        }
    }
    combos
}

/// A grid x grid pair's own runs.
#[derive(Clone, Debug, PartialEq)]
struct GridPair {
    /// Index of the first combination's model in [`PairPlans::models`].
    first_model: usize,
    /// The combined grid points, in the order of their models.
    combos: Vec<GridPoint>,
}

/// One pair of effects to fit.
#[derive(Clone, Debug, PartialEq)]
struct PairPlan {
    /// Index of the first member's family.
    first: usize,
    /// Index of the second member's family.
    second: usize,
    /// For two grid effects, the combinations to run; `None` when one of
    /// them is linear (the pair reuses the members' runs).
    grid: Option<GridPair>,
}

/// The pairs to fit and the models they need run.
struct PairPlans {
    /// The models of every grid x grid combination.
    models: Vec<Effects>,
    /// The pairs, in order.
    pairs: Vec<PairPlan>,
}

/// Step: plans every pair of the `top` families; two grid effects combine
/// the best two points of each (on all recordings).
fn plan_pairs(lab: &Lab, families: &[Family], top: &[usize]) -> PairPlans {
    let all = lab.all();
    let mut models = Vec::new();
    let mut pairs = Vec::new();
    for i in 0..top.len() {
        for j in i + 1..top.len() {
            let (a, b) = (&families[top[i]], &families[top[j]]);
            let grid = if a.linear.is_empty() && b.linear.is_empty() {
                let best = |f: &Family| best_two_bases(f, |k| f.score(lab, k, &[], &all));
                let combos = grid_combos(&best(a), &best(b));
                let first_model = models.len();
                for c in &combos {
                    models.push(effects_of(c).unwrap_or(Effects::none()));
                }
                Some(GridPair { first_model, combos })
            } else {
                None
            };
            pairs.push(PairPlan { first: top[i], second: top[j], grid });
        }
    }
    PairPlans { models, pairs }
}

/// Step: the family of a pair of single-effect families `a` and `b`: a grid
/// pair's bases are its combinations with their `pair_runs`; otherwise the
/// grid member (if any) gives the bases (else the nominal model,
/// `nominal_runs`) and the linear members add their probes. Not prepared.
fn pair_family(a: &Family, b: &Family, grid: Option<GridPair>, pair_runs: &[Runs], nominal_runs: &Runs) -> Family {
    match grid {
        Some(GridPair { first_model, combos }) => Family {
            kinds: vec![a.kinds[0], b.kinds[0]],
            bases: combos
                .into_iter()
                .enumerate()
                .map(|(k, c)| Base { point: c, runs: pair_runs[first_model + k].clone() })
                .collect(),
            linear: Vec::new(),
            cross: Vec::new(),
            refit: None,
            probes_from_base: false,
        },
        None => {
            let (grid_f, lin): (Option<&Family>, Vec<&Family>) = match (a.linear.is_empty(), b.linear.is_empty()) {
                (true, false) => (Some(a), vec![b]),
                (false, true) => (Some(b), vec![a]),
                _ => (None, vec![a, b]),
            };
            Family {
                kinds: vec![a.kinds[0], b.kinds[0]],
                bases: grid_f
                    .map_or_else(|| vec![Base { point: Vec::new(), runs: nominal_runs.clone() }], |g| g.bases.clone()),
                linear: lin.iter().flat_map(|f| f.linear.clone()).collect(),
                cross: Vec::new(),
                refit: None,
                probes_from_base: false,
            }
        }
    }
}

/// Whether `pair` earns its extra parameters: its held-out gap after the
/// fit is below [`PAIR_MARGIN`] times that of its better member (the
/// candidates named in `members`).
fn keeps_pair(candidates: &[Candidate], members: [&str; 2], pair: &Candidate) -> bool {
    let single_best = candidates
        .iter()
        .filter(|c| members.contains(&c.name.as_str()))
        .map(|c| c.held_out_gap_after_db)
        .fold(f64::INFINITY, f64::min);
    pair.held_out_gap_after_db < PAIR_MARGIN * single_best
}

/// Step: fits the pairs of the best three single effects and adds those
/// that [`keeps_pair`] keeps to `candidates` (unranked).
fn add_pairs(
    lab: &Lab,
    families: &[Family],
    candidates: &mut Vec<Candidate>,
    nominal: &[f64],
    nominal_runs: &Runs,
    count: &mut RunCount,
) {
    let top = top_singles(candidates, families);
    let plans = plan_pairs(lab, families, &top);
    let pair_runs = if plans.models.is_empty() {
        Vec::new()
    } else {
        count.planned += plans.models.len();
        lab.run_all(&plans.models, count)
    };
    // The pairs fitted side by side, then kept in their order.
    let fitted: Vec<Candidate> = plans
        .pairs
        .par_iter()
        .map(|plan| {
            let (a, b) = (&families[plan.first], &families[plan.second]);
            let mut f = pair_family(a, b, plan.grid.clone(), &pair_runs, nominal_runs);
            f.prepare(lab);
            evaluate(lab, &f, nominal)
        })
        .collect();
    for (plan, pair) in plans.pairs.iter().zip(fitted) {
        let (a, b) = (&families[plan.first], &families[plan.second]);
        if keeps_pair(candidates, [a.kinds[0].name(), b.kinds[0].name()], &pair) {
            candidates.push(pair);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs told apart by their length: `runs(n)` has `n` recordings.
    fn runs(n: usize) -> Runs {
        vec![None; n]
    }

    fn grid_family(kind: EffectKind, points: &[f64]) -> Family {
        Family {
            kinds: vec![kind],
            bases: points
                .iter()
                .enumerate()
                .map(|(i, &x)| {
                    let mut v = kind.defaults();
                    v[0] = x;
                    Base { point: vec![(kind, v)], runs: runs(10 + i) }
                })
                .collect(),
            linear: Vec::new(),
            cross: Vec::new(),
            refit: None,
            probes_from_base: false,
        }
    }

    fn linear_family(kind: EffectKind, probes: usize) -> Family {
        Family {
            kinds: vec![kind],
            bases: vec![Base { point: Vec::new(), runs: runs(1) }],
            linear: vec![LinearEffect::around_nominal(
                kind,
                search(kind, None),
                (0..probes).map(|p| runs(20 + p)).collect(),
            )],
            cross: Vec::new(),
            refit: None,
            probes_from_base: false,
        }
    }

    fn candidate(name: &str, shrink: f64, after_db: f64) -> Candidate {
        Candidate {
            name: name.to_string(),
            parameters: Vec::new(),
            fitted_parameters: 1,
            training_gap_before_db: 1.0,
            training_gap_after_db: after_db,
            held_out_gap_before_db: 1.0,
            held_out_gap_after_db: after_db,
            held_out_shrink: shrink,
            score_db: after_db,
            effects: Effects::none(),
            ..Candidate::default()
        }
    }

    #[test]
    fn first_stage_numbers_every_point_in_turn() {
        let kinds = [EffectKind::DivertingPulley, EffectKind::DeadTime, EffectKind::SheaveEccentricity];
        let plan = plan_first_stage(&kinds, None, &[]);
        // 4 pulley inertias x 3 damping ratios, 1 dead-time probe, 2
        // eccentricity probes.
        assert_eq!(plan.models.len(), 15);
        let idx: Vec<&[usize]> = plan.effects.iter().map(|e| e.models.as_slice()).collect();
        assert_eq!(idx, [&(0..12).collect::<Vec<_>>()[..], &[12], &[13, 14]]);
        assert_eq!(plan.effects[1].kind, EffectKind::DeadTime);
        assert_eq!(plan.models[0].values(EffectKind::DivertingPulley).unwrap()[0], 0.004);
        assert_eq!(plan.models[1].values(EffectKind::DivertingPulley).unwrap()[3], 0.02);
        assert_eq!(plan.models[11].values(EffectKind::DivertingPulley).unwrap()[0], 0.1);
        assert_eq!(plan.models[12].values(EffectKind::DeadTime).unwrap()[0], 0.3e-6);
        assert_eq!(plan.models[14].values(EffectKind::SheaveEccentricity).unwrap(), [0.005, 0.25 * TAU]);
        assert_eq!(plan.models[12].enabled(), [EffectKind::DeadTime]);
    }

    #[test]
    fn families_of_grid_and_linear_effects() {
        let plan = plan_first_stage(&[EffectKind::RopeDiscretization, EffectKind::SheaveEccentricity], None, &[]);
        let all_runs: Vec<Runs> = (0..plan.models.len()).map(|m| runs(100 + m)).collect();
        let nominal = runs(7);
        let grid = family_of(&plan.effects[0], &all_runs, &nominal);
        assert_eq!(grid.kinds, [EffectKind::RopeDiscretization]);
        assert!(grid.linear.is_empty());
        let elements: Vec<f64> = grid.bases.iter().map(|b| b.point[0].1[0]).collect();
        assert_eq!(elements, [2.0, 4.0, 8.0]);
        assert_eq!(grid.bases.iter().map(|b| b.runs.len()).collect::<Vec<_>>(), [100, 101, 102]);
        let linear = family_of(&plan.effects[1], &all_runs, &nominal);
        assert_eq!(linear.bases.len(), 1);
        assert!(linear.bases[0].point.is_empty());
        assert_eq!(linear.bases[0].runs.len(), 7);
        assert_eq!(linear.linear[0].probes.iter().map(Vec::len).collect::<Vec<_>>(), [103, 104]);
        assert_eq!(linear.coefficient_count(), 2);
    }

    #[test]
    fn refinement_adds_midpoints_and_reports_each_family_once() {
        // Integer scale: 4 between 2 and 8 gives 3 and 6.
        let grid = [vec![2.0], vec![4.0], vec![8.0]];
        assert_eq!(refinement(EffectKind::RopeDiscretization, &grid, 1), [vec![3.0], vec![6.0]]);
        // Log scale: geometric mean towards the one neighbour, and as far
        // past the line's end (4e3 / 4 = 1e3, the range's bound).
        let grid = [vec![4.0e3, 5.0], vec![1.6e4, 5.0]];
        let r = refinement(EffectKind::BrakeStop, &grid, 0);
        assert_eq!(r.len(), 2);
        assert!((r[0][0] - 8.0e3).abs() < 1e-9 && r[0][1] == 5.0);
        assert!((r[1][0] - 1.0e3).abs() < 1e-9 && r[1][1] == 5.0);
        // Linear scale: past the lower end by the neighbour's step; where
        // that reaches the bound at which the effect vanishes, halfway to it.
        let near = |r: Vec<Vec<f64>>, want: &[f64]| {
            r.len() == want.len() && r.iter().zip(want).all(|(p, w)| (p[0] - w).abs() < 1e-12)
        };
        let grid = [vec![0.5, 323.73], vec![0.55, 323.73], vec![0.6, 323.73]];
        assert!(near(refinement(EffectKind::TensionStiffening, &grid, 0), &[0.525, 0.45]));
        assert!(near(refinement(EffectKind::TensionStiffening, &grid, 2), &[0.575, 0.65]));
        let grid = [vec![0.05, 323.73], vec![0.1, 323.73]];
        assert!(near(refinement(EffectKind::TensionStiffening, &grid, 0), &[0.075, 0.025]));
        // A best point on the range's bound has nothing past it.
        let grid = [vec![4.0], vec![8.0]];
        assert_eq!(refinement(EffectKind::RopeDiscretization, &grid, 1), [vec![6.0]]);

        let mut families = vec![
            grid_family(EffectKind::RopeDiscretization, &[2.0, 4.0]),
            grid_family(EffectKind::BrakeStop, &[4.0e3]),
        ];
        let point = |family, kind: EffectKind, x| {
            let mut values = kind.defaults();
            values[0] = x;
            RefinementPoint { family, kind, values }
        };
        let points = vec![
            point(0, EffectKind::RopeDiscretization, 3.0),
            point(0, EffectKind::RopeDiscretization, 6.0),
            point(1, EffectKind::BrakeStop, 8.0e3),
        ];
        let touched = add_refinement(&mut families, points, vec![runs(1), runs(2), runs(3)]);
        assert_eq!(touched, [0, 1]);
        let elements: Vec<f64> = families[0].bases.iter().map(|b| b.point[0].1[0]).collect();
        assert_eq!(elements, [2.0, 4.0, 3.0, 6.0]);
        assert_eq!(families[0].bases[3].runs.len(), 2);
        assert_eq!(families[1].bases[1].point, [(EffectKind::BrakeStop, vec![8.0e3, 5.0])]);
    }

    #[test]
    fn pairs_only_when_the_best_single_falls_short() {
        let short = candidate("a", PAIR_TRIGGER_SHRINK - 0.01, 0.5);
        let enough = candidate("a", PAIR_TRIGGER_SHRINK, 0.5);
        let other = candidate("b", 0.0, 1.0);
        assert!(wants_pairs(&[short.clone(), other.clone()]));
        assert!(!wants_pairs(&[enough, other]));
        assert!(!wants_pairs(&[short]));
        assert!(!wants_pairs(&[]));
    }

    #[test]
    fn top_singles_are_the_best_three_single_effects() {
        let families = [
            grid_family(EffectKind::RopeDiscretization, &[2.0]),
            linear_family(EffectKind::DeadTime, 1),
            grid_family(EffectKind::BrakeStop, &[4.0e3]),
            linear_family(EffectKind::EncoderError, 2),
        ];
        let ranked = [
            candidate("dead_time", 0.1, 0.1),
            candidate("dead_time + brake_stop", 0.1, 0.2),
            candidate("encoder_error", 0.1, 0.3),
            candidate("rope_discretization", 0.1, 0.4),
        ];
        assert_eq!(top_singles(&ranked, &families), [1, 3]);
    }

    #[test]
    fn grid_pairs_combine_the_best_two_points_of_each() {
        let f = grid_family(EffectKind::RopeDiscretization, &[1.0, 2.0, 4.0, 8.0]);
        let scores = [3.0, 1.0, 2.0, 1.5];
        let best = best_two_bases(&f, |k| scores[k]);
        assert_eq!(best.iter().map(|p| p[0].1[0]).collect::<Vec<_>>(), [2.0, 8.0]);
        let a = |x: f64| vec![(EffectKind::RopeDiscretization, vec![x])];
        let b = |x: f64| vec![(EffectKind::BrakeStop, vec![x, 5.0])];
        let combos = grid_combos(&[a(2.0), a(8.0)], &[b(1.0e3), b(1.0e4)]);
        assert_eq!(combos.len(), 4);
        assert_eq!(combos[1], [a(2.0)[0].clone(), b(1.0e4)[0].clone()]);
        assert_eq!(combos[2], [a(8.0)[0].clone(), b(1.0e3)[0].clone()]);
    }

    #[test]
    fn pair_families_take_bases_and_probes_from_their_members() {
        let grid = grid_family(EffectKind::RopeDiscretization, &[2.0, 4.0]);
        let lin_a = linear_family(EffectKind::DeadTime, 1);
        let lin_b = linear_family(EffectKind::EncoderError, 2);
        let nominal = runs(7);
        // Linear first, grid second: the grid's bases, the linear's probes.
        let f = pair_family(&lin_a, &grid, None, &[], &nominal);
        assert_eq!(f.kinds, [EffectKind::DeadTime, EffectKind::RopeDiscretization]);
        assert_eq!(f.bases.iter().map(|b| b.runs.len()).collect::<Vec<_>>(), [10, 11]);
        assert_eq!(f.coefficient_count(), 1);
        // Two linear effects: the nominal base, both probes sets in order.
        let f = pair_family(&lin_a, &lin_b, None, &[], &nominal);
        assert_eq!(f.bases.len(), 1);
        assert_eq!(f.bases[0].runs.len(), 7);
        assert_eq!(
            f.linear.iter().map(|l| l.kind).collect::<Vec<_>>(),
            [EffectKind::DeadTime, EffectKind::EncoderError]
        );
        assert_eq!(f.coefficient_count(), 3);
        assert_eq!(f.fitted_parameters(&[]), 3);
        // Grid x grid: the combinations with their own runs, from `first_model` on.
        let combos =
            vec![vec![(EffectKind::RopeDiscretization, vec![2.0])], vec![(EffectKind::RopeDiscretization, vec![4.0])]];
        let pair_runs: Vec<Runs> = (0..5).map(|m| runs(30 + m)).collect();
        let f =
            pair_family(&grid, &grid, Some(GridPair { first_model: 3, combos: combos.clone() }), &pair_runs, &nominal);
        assert_eq!(
            f.bases.iter().map(|b| (b.point.clone(), b.runs.len())).collect::<Vec<_>>(),
            [(combos[0].clone(), 33), (combos[1].clone(), 34)]
        );
        assert!(f.linear.is_empty());
    }

    #[test]
    fn known_parameters_hold_their_coefficients_and_are_not_counted_as_fitted() {
        let f = linear_family(EffectKind::CurrentSensorError, 4);
        assert_eq!(f.held_coefficients(&[]), [None; 4]);
        let known = [KnownParameter {
            effect: EffectKind::CurrentSensorError,
            index: 2,
            value: -0.04,
            uncertainty: 1e-4,
            source: "a measurement",
        }];
        // gain_error_a's probe is 0.01: the coefficient that gives -0.04.
        let held = f.held_coefficients(&known);
        assert_eq!(held.iter().filter(|h| h.is_some()).count(), 1);
        assert!((held[2].expect("held") + 4.0).abs() < 1e-12, "{held:?}");
        assert_eq!(f.fitted_parameters(&known), 3);
        // Another effect's known parameter does not touch it.
        let other = [KnownParameter { effect: EffectKind::EncoderError, ..known[0] }];
        assert_eq!(f.held_coefficients(&other), [None; 4]);
        let listed = fitted_parameter_list(
            &[(EffectKind::CurrentSensorError, vec![0.1, 0.0, -0.04, 0.0])],
            &vec![vec![(EffectKind::CurrentSensorError, vec![0.2, 0.0, -0.04, 0.0])]; 2],
            &known,
        );
        assert_eq!(listed[2].measured_by, Some("a measurement"));
        assert_eq!(listed[2].uncertainty, 1e-4);
        assert_eq!(listed[0].measured_by, None);
    }

    #[test]
    fn a_pair_is_kept_only_clearly_below_its_better_member() {
        let ranked = [candidate("a", 0.1, 1.0), candidate("b", 0.1, 0.5), candidate("c", 0.1, 0.1)];
        // The better member of (a, b) leaves 0.5 dB: the pair must leave < 0.4 dB.
        assert!(keeps_pair(&ranked, ["a", "b"], &candidate("a + b", 0.0, 0.39)));
        assert!(!keeps_pair(&ranked, ["a", "b"], &candidate("a + b", 0.0, 0.4)));
        assert!(!keeps_pair(&ranked, ["b", "c"], &candidate("b + c", 0.0, 0.39)));
    }

    #[test]
    fn jackknife_error_of_the_fold_values() {
        // Mean 2, deviations +-1: sqrt(1/2 * 2) = 1.
        assert!((jackknife_error(&[1.0, 3.0]) - 1.0).abs() < 1e-15);
        // Mean 2, squares 1 + 0 + 1: sqrt(2/3 * 2).
        assert!((jackknife_error(&[1.0, 2.0, 3.0]) - (4.0f64 / 3.0).sqrt()).abs() < 1e-15);
        assert!(jackknife_error(&[5.0]).is_nan());
        assert!(jackknife_error(&[]).is_nan());
    }

    #[test]
    fn fitted_parameter_list_skips_the_fixed_parameters() {
        let params = vec![(EffectKind::DeadTime, vec![2.0e-6, 0.3])];
        let folds =
            vec![vec![(EffectKind::DeadTime, vec![1.0e-6, 0.3])], vec![(EffectKind::DeadTime, vec![3.0e-6, 0.3])]];
        let list = fitted_parameter_list(&params, &folds, &[]);
        assert_eq!(list.len(), 1);
        assert_eq!((list[0].effect, list[0].name, list[0].unit), ("dead_time", "dead_time_s", "s"));
        assert_eq!(list[0].value, 2.0e-6);
        assert!((list[0].uncertainty - 1.0e-6).abs() < 1e-18);
    }
}
