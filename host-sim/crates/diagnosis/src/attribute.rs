//! Step 4 of the diagnosis: which effect of the library explains the gap.
//!
//! Every effect is fitted on a training part of the recordings and judged on
//! the recordings held out from the fit (leave-one-group-out across car
//! masses: a group is every recording of one mass, travels up and down and
//! decays; with a single mass, one recording per group). Two kinds of fit:
//!
//! - grid: effects whose parameters move natural frequencies (tension
//!   stiffening, pulley, rope elements, frame mode, brake clamp) are
//!   simulated on a grid of their fitted parameters, refined once around the
//!   best point on all recordings; a fold picks the grid point best on its
//!   training recordings;
//! - linear: effects that add a small excitation (guide friction, sheave
//!   eccentricity, dead time, current-sensor errors, encoder error) are
//!   simulated once per probe; their influence for any parameter value is
//!   the same combination of the probe runs' spectra (amplitude and phase as
//!   the two components `a cos`, `a sin`), and a fold fits the combination
//!   on its training recordings (Nelder-Mead).
//!
//! Effects are ranked by the held-out excess gap after the fit, with a
//! penalty of [`PARAMETER_PENALTY`] per fitted parameter; when no single
//! effect removes [`PAIR_TRIGGER_SHRINK`] of the held-out gap, the pairs of
//! the best three are tried too.

use std::f64::consts::TAU;

use rayon::prelude::*;

use super::measure::{gap, Tolerances};
use super::signals::Channel;
use super::simulate::{model_step_s, simulate_counterpart};
use super::spectra::{Bands, CellPowers, ChainSpectra, CrossPowers, Segmentation};
use plant::effects::{EffectKind, Effects, ParamScale};
use recording::Recording;
use rig_config::RigConfig;

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

/// One recording as the attribution sees it.
#[derive(Clone, Debug)]
pub struct Target {
    /// Recording name.
    pub stem: String,
    /// Cross-validation group (car mass).
    pub group: String,
    /// What the simulation needs of the measured recording (metadata; for a
    /// decay its acceleration).
    pub recording: Recording,
    /// Measured cell powers.
    pub measured: CellPowers,
    /// Measured noise densities, unit^2/Hz.
    pub noise: Vec<(Channel, f64)>,
    /// The model's reproducibility per cell, dB.
    pub tolerances: Tolerances,
    /// Segmentation of the model's runs (the nominal run's, aligned).
    pub segmentation: Segmentation,
    /// Spectra of the nominal model's run.
    pub nominal: ChainSpectra,
}

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
    /// Called after every batch of runs with (runs done, runs planned).
    pub progress: &'a (dyn Fn(usize, usize) + Sync),
}

/// One fitted parameter with its spread across the folds.
#[derive(Clone, Debug, serde::Serialize)]
pub struct FittedParameter {
    /// Effect.
    pub effect: &'static str,
    /// Parameter name (with its unit suffix).
    pub name: &'static str,
    /// Unit.
    pub unit: &'static str,
    /// Value fitted on all recordings.
    pub value: f64,
    /// Jackknife standard error over the folds (same unit).
    pub uncertainty: f64,
}

/// An effect (or a pair) after fitting and cross-validation.
#[derive(Clone, Debug, serde::Serialize)]
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
    /// The model with the effect(s) as fitted on all recordings.
    #[serde(skip)]
    pub effects: Effects,
}

/// How one effect is searched.
#[derive(Clone, Debug)]
enum Search {
    /// Simulated at these full parameter vectors.
    Grid(Vec<Vec<f64>>),
    /// Simulated at these probes; coefficients map to parameters by `map`.
    Linear { probes: Vec<Vec<f64>>, map: fn(&[f64]) -> Vec<f64>, clamp: fn(&[f64]) -> Vec<f64> },
}

const FRICTION_PROBE_N: f64 = 40.0;
const ECCENTRICITY_PROBE: f64 = 0.005;
const DEAD_TIME_PROBE_S: f64 = 0.3e-6;
const OFFSET_PROBE_A: f64 = 0.2;
const GAIN_PROBE: f64 = 0.01;
const ENCODER_PROBE_RAD: f64 = 0.002;

fn polar(c: &[f64], probe: f64, max: f64) -> Vec<f64> {
    let a = (probe * c[0].hypot(c[1])).min(max);
    vec![a, c[1].atan2(c[0]).rem_euclid(TAU)]
}

fn clamp_polar(c: &[f64], probe: f64, max: f64) -> Vec<f64> {
    let r = c[0].hypot(c[1]);
    let limit = max / probe;
    if r > limit {
        vec![c[0] * limit / r, c[1] * limit / r]
    } else {
        c.to_vec()
    }
}

fn search(kind: EffectKind, reference_tension_n: Option<f64>) -> Search {
    let d = kind.defaults();
    let with = |values: &[(usize, f64)]| {
        let mut v = d.clone();
        for &(i, x) in values {
            v[i] = x;
        }
        v
    };
    match kind {
        EffectKind::TensionStiffening => {
            let t = reference_tension_n.unwrap_or(d[1]).clamp(10.0, 1.0e4);
            Search::Grid([0.2, 0.5, 0.85].iter().map(|&a| with(&[(0, a), (1, t)])).collect())
        }
        EffectKind::DivertingPulley => {
            Search::Grid([0.004, 0.012, 0.035, 0.1].iter().map(|&j| with(&[(0, j)])).collect())
        }
        EffectKind::RopeDiscretization => Search::Grid([2.0, 4.0, 8.0].iter().map(|&n| with(&[(0, n)])).collect()),
        EffectKind::CarFrameMode => Search::Grid(
            [120.0, 200.0, 330.0].iter().flat_map(|&f| [0.015, 0.05].map(|z| with(&[(0, f), (1, z)]))).collect(),
        ),
        EffectKind::BrakeStop => Search::Grid([4.0e3, 3.0e4, 2.0e5].iter().map(|&k| with(&[(0, k)])).collect()),
        EffectKind::CoulombGuideFriction => Search::Linear {
            probes: vec![with(&[(0, FRICTION_PROBE_N)])],
            map: |c| vec![(FRICTION_PROBE_N * c[0]).clamp(0.0, 150.0), 0.002],
            clamp: |c| vec![c[0].clamp(0.0, 150.0 / FRICTION_PROBE_N)],
        },
        EffectKind::SheaveEccentricity => Search::Linear {
            probes: vec![with(&[(0, ECCENTRICITY_PROBE), (1, 0.0)]), with(&[(0, ECCENTRICITY_PROBE), (1, 0.25 * TAU)])],
            map: |c| polar(c, ECCENTRICITY_PROBE, 0.02),
            clamp: |c| clamp_polar(c, ECCENTRICITY_PROBE, 0.02),
        },
        EffectKind::DeadTime => Search::Linear {
            probes: vec![with(&[(0, DEAD_TIME_PROBE_S)])],
            map: |c| vec![(DEAD_TIME_PROBE_S * c[0]).clamp(0.0, 5.0e-6), 0.3],
            clamp: |c| vec![c[0].clamp(0.0, 5.0e-6 / DEAD_TIME_PROBE_S)],
        },
        EffectKind::CurrentSensorError => Search::Linear {
            probes: vec![
                vec![OFFSET_PROBE_A, 0.0, 0.0, 0.0],
                vec![0.0, OFFSET_PROBE_A, 0.0, 0.0],
                vec![0.0, 0.0, GAIN_PROBE, 0.0],
                vec![0.0, 0.0, 0.0, GAIN_PROBE],
            ],
            map: |c| {
                vec![
                    (OFFSET_PROBE_A * c[0]).clamp(-1.0, 1.0),
                    (OFFSET_PROBE_A * c[1]).clamp(-1.0, 1.0),
                    (GAIN_PROBE * c[2]).clamp(-0.05, 0.05),
                    (GAIN_PROBE * c[3]).clamp(-0.05, 0.05),
                ]
            },
            clamp: |c| {
                vec![
                    c[0].clamp(-1.0 / OFFSET_PROBE_A, 1.0 / OFFSET_PROBE_A),
                    c[1].clamp(-1.0 / OFFSET_PROBE_A, 1.0 / OFFSET_PROBE_A),
                    c[2].clamp(-0.05 / GAIN_PROBE, 0.05 / GAIN_PROBE),
                    c[3].clamp(-0.05 / GAIN_PROBE, 0.05 / GAIN_PROBE),
                ]
            },
        },
        EffectKind::EncoderError => Search::Linear {
            probes: vec![with(&[(0, ENCODER_PROBE_RAD), (1, 0.0)]), with(&[(0, ENCODER_PROBE_RAD), (1, 0.25 * TAU)])],
            map: |c| polar(c, ENCODER_PROBE_RAD, 0.01),
            clamp: |c| clamp_polar(c, ENCODER_PROBE_RAD, 0.01),
        },
    }
}

/// Number of fitted parameters of `kind`.
fn fitted_count(kind: EffectKind) -> usize {
    kind.parameters().iter().filter(|s| s.fitted).count()
}

/// Grid points to add around `best` (midpoints towards its neighbours along
/// every fitted dimension, in the parameter's scale).
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
        for n in [lower, upper] {
            if !n.is_finite() {
                continue;
            }
            let mid = match spec.scale {
                ParamScale::Log => (n * b[j]).sqrt(),
                ParamScale::Integer => {
                    let m = (0.5 * (n + b[j])).round();
                    if m == n || m == b[j] {
                        continue;
                    }
                    m
                }
                _ => 0.5 * (n + b[j]),
            };
            let mut p = b.clone();
            p[j] = mid;
            if !grid.contains(&p) && !out.contains(&p) {
                out.push(p);
            }
        }
    }
    out
}

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

impl Lab<'_> {
    /// Runs the model with each of `models` on every recording, in parallel.
    fn run_all(&self, models: &[Effects], done: &mut usize, planned: usize) -> Vec<Runs> {
        let jobs: Vec<(usize, usize)> =
            (0..models.len()).flat_map(|m| (0..self.targets.len()).map(move |t| (m, t))).collect();
        let results: Vec<Option<ChainSpectra>> = jobs
            .par_iter()
            .map(|&(m, t)| {
                let target = &self.targets[t];
                simulate_counterpart(self.rig, &models[m], &target.recording, &target.stem, model_step_s(self.rig))
                    .ok()
                    .map(|signals| ChainSpectra::compute(&signals, &target.segmentation, self.bands))
            })
            .collect();
        *done += models.len();
        (self.progress)(*done, planned);
        let mut out = vec![Vec::with_capacity(self.targets.len()); models.len()];
        for ((m, _), r) in jobs.into_iter().zip(results) {
            out[m].push(r);
        }
        out
    }

    fn excess(&self, t: usize, powers: &CellPowers) -> f64 {
        gap(&self.targets[t].measured, &self.targets[t].noise, &self.targets[t].tolerances, powers).excess_db()
    }

    /// The nominal model's excess gap on every recording, dB.
    pub fn nominal_excess(&self) -> Vec<f64> {
        (0..self.targets.len())
            .map(|t| self.excess(t, &CrossPowers::compute(&[&self.targets[t].nominal], self.bands).powers(&[1.0])))
            .collect()
    }
}

/// A family of models: base runs (grid points, or the nominal model) and
/// linear probes, fitted jointly.
struct Family {
    kinds: Vec<EffectKind>,
    /// Per base: the grid effects' parameter vectors and the runs.
    bases: Vec<(GridPoint, Runs)>,
    /// Per linear effect: its kind, its search, its probe runs.
    linear: Vec<(EffectKind, Search, Vec<Runs>)>,
    /// Per base, per recording: cross powers of [base, nominal, probes...].
    cross: Vec<Vec<Option<CrossPowers>>>,
}

impl Family {
    fn coefficient_count(&self) -> usize {
        self.linear.iter().map(|(_, _, p)| p.len()).sum()
    }

    fn prepare(&mut self, lab: &Lab) {
        self.cross = self
            .bases
            .iter()
            .map(|(_, runs)| {
                (0..lab.targets.len())
                    .into_par_iter()
                    .map(|t| {
                        let base = runs[t].as_ref()?;
                        let mut parts: Vec<&ChainSpectra> = vec![base, &lab.targets[t].nominal];
                        for (_, _, probes) in &self.linear {
                            for p in probes {
                                parts.push(p[t].as_ref()?);
                            }
                        }
                        Some(CrossPowers::compute(&parts, lab.bands))
                    })
                    .collect()
            })
            .collect();
    }

    fn clamp(&self, c: &[f64]) -> Vec<f64> {
        let mut out = Vec::with_capacity(c.len());
        let mut i = 0;
        for (_, s, probes) in &self.linear {
            let n = probes.len();
            if let Search::Linear { clamp, .. } = s {
                out.extend(clamp(&c[i..i + n]));
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

    /// Best `(base, coefficients, score)` on `set`.
    fn fit(&self, lab: &Lab, set: &[usize]) -> (usize, Vec<f64>, f64) {
        let d = self.coefficient_count();
        let mut best = (0, vec![0.0; d], f64::INFINITY);
        for b in 0..self.bases.len() {
            let (c, s) = if d == 0 {
                (Vec::new(), self.score(lab, b, &[], set))
            } else {
                let starts = starting_points(d);
                let (mut x0, mut s0) = (vec![0.0; d], f64::INFINITY);
                for x in starts {
                    let s = self.score(lab, b, &x, set);
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
                                x[i] = v;
                                let s = self.score(lab, b, &x, set);
                                if s < s0 {
                                    (x0, s0) = (x, s);
                                }
                            }
                        }
                    }
                }
                let (x1, _) = nelder_mead(|x| self.score(lab, b, x, set), &x0, 0.5, 60 * d + 40);
                nelder_mead(|x| self.score(lab, b, x, set), &x1, 0.2, 60 * d + 40)
            };
            if s < best.2 {
                best = (b, self.clamp(&c), s);
            }
        }
        best
    }

    /// The parameters (per effect, full vectors) at `(b, c)`.
    fn parameters(&self, b: usize, c: &[f64]) -> Vec<(EffectKind, Vec<f64>)> {
        let mut out = self.bases[b].0.clone();
        let mut i = 0;
        for (kind, s, probes) in &self.linear {
            let n = probes.len();
            if let Search::Linear { map, .. } = s {
                out.push((*kind, map(&c[i..i + n])));
            }
            i += n;
        }
        out
    }

    fn fitted_parameters(&self) -> usize {
        self.kinds.iter().map(|k| fitted_count(*k)).sum()
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

/// Cross-validates `family` into a candidate.
fn evaluate(lab: &Lab, family: &Family, nominal: &[f64]) -> Candidate {
    let all: Vec<usize> = (0..lab.targets.len()).collect();
    let folds = folds(lab.targets);
    let mut held_after = vec![f64::NAN; lab.targets.len()];
    let mut train_before = 0.0;
    let mut train_after = 0.0;
    let mut fold_params: Vec<Vec<(EffectKind, Vec<f64>)>> = Vec::new();
    for (train, held) in &folds {
        let (b, c, s) = family.fit(lab, train);
        train_before += train.iter().map(|&t| nominal[t]).sum::<f64>() / train.len() as f64;
        train_after += s;
        for &t in held {
            held_after[t] = family.score(lab, b, &c, &[t]);
        }
        fold_params.push(family.parameters(b, &c));
    }
    let k = folds.len().max(1) as f64;
    let (b, c, s_all) = family.fit(lab, &all);
    let params = family.parameters(b, &c);
    let effects = effects_of(&params).unwrap_or_default();
    let mut parameters = Vec::new();
    for (e, (kind, values)) in params.iter().enumerate() {
        for (j, spec) in kind.parameters().iter().enumerate() {
            if !spec.fitted {
                continue;
            }
            let per_fold: Vec<f64> = fold_params.iter().map(|p| p[e].1[j]).collect();
            let mean = per_fold.iter().sum::<f64>() / per_fold.len().max(1) as f64;
            let uncertainty = if per_fold.len() >= 2 {
                let n = per_fold.len() as f64;
                ((n - 1.0) / n * per_fold.iter().map(|v| (v - mean).powi(2)).sum::<f64>()).sqrt()
            } else {
                f64::NAN
            };
            parameters.push(FittedParameter {
                effect: kind.name(),
                name: spec.name,
                unit: spec.unit,
                value: values[j],
                uncertainty,
            });
        }
    }
    let held: Vec<usize> = (0..lab.targets.len()).filter(|&t| held_after[t].is_finite()).collect();
    let mean_of = |v: &dyn Fn(usize) -> f64| held.iter().map(|&t| v(t)).sum::<f64>() / held.len().max(1) as f64;
    let (before, after) = if held.is_empty() {
        (nominal.iter().sum::<f64>() / nominal.len().max(1) as f64, s_all)
    } else {
        (mean_of(&|t| nominal[t]), mean_of(&|t| held_after[t]))
    };
    let fitted = family.fitted_parameters();
    Candidate {
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

/// Fits every effect of the library (and pairs when needed); returns the
/// candidates ranked best first.
pub fn attribute(lab: &Lab, kinds: &[EffectKind]) -> Vec<Candidate> {
    let nominal = lab.nominal_excess();
    let nominal_effects = Effects::none();
    // Plan every run of the first stage.
    let searches: Vec<(EffectKind, Search)> = kinds.iter().map(|&k| (k, search(k, lab.reference_tension_n))).collect();
    let mut models: Vec<Effects> = Vec::new();
    let mut index: Vec<Vec<usize>> = Vec::new();
    for (kind, s) in &searches {
        let points = match s {
            Search::Grid(points) => points.clone(),
            Search::Linear { probes, .. } => probes.clone(),
        };
        let mut idx = Vec::new();
        for p in points {
            idx.push(models.len());
            models.push(effects_of(&[(*kind, p)]).unwrap_or(nominal_effects));
        }
        index.push(idx);
    }
    let mut planned = models.len();
    let mut done = 0;
    let runs = lab.run_all(&models, &mut done, planned);
    let nominal_runs: Runs = lab.targets.iter().map(|t| Some(t.nominal.clone())).collect();

    // Build the families; refine the grids of the effects that reduce the
    // gap at all, twice, around their best point on all recordings.
    let mut families: Vec<Family> = Vec::new();
    let all: Vec<usize> = (0..lab.targets.len()).collect();
    let nominal_mean = nominal.iter().sum::<f64>() / nominal.len().max(1) as f64;
    for ((kind, s), idx) in searches.iter().zip(&index) {
        let mut f = match s {
            Search::Grid(points) => Family {
                kinds: vec![*kind],
                bases: points.iter().zip(idx).map(|(p, &m)| (vec![(*kind, p.clone())], runs[m].clone())).collect(),
                linear: Vec::new(),
                cross: Vec::new(),
            },
            Search::Linear { .. } => Family {
                kinds: vec![*kind],
                bases: vec![(Vec::new(), nominal_runs.clone())],
                linear: vec![(*kind, s.clone(), idx.iter().map(|&m| runs[m].clone()).collect())],
                cross: Vec::new(),
            },
        };
        f.prepare(lab);
        families.push(f);
    }
    for _round in 0..REFINEMENT_ROUNDS {
        let mut refine_models = Vec::new();
        let mut refine_owner = Vec::new();
        for (i, f) in families.iter().enumerate() {
            if !f.linear.is_empty() {
                continue;
            }
            let (best, _, score) = f.fit(lab, &all);
            if score >= REFINE_IF_BELOW * nominal_mean {
                continue;
            }
            let kind = f.kinds[0];
            let points: Vec<Vec<f64>> = f.bases.iter().map(|(p, _)| p[0].1.clone()).collect();
            for p in refinement(kind, &points, best) {
                refine_models.push(effects_of(&[(kind, p.clone())]).unwrap_or(nominal_effects));
                refine_owner.push((i, kind, p));
            }
        }
        if refine_models.is_empty() {
            break;
        }
        planned = planned.max(done + refine_models.len());
        let extra = lab.run_all(&refine_models, &mut done, planned);
        let mut touched = Vec::new();
        for ((f, kind, p), r) in refine_owner.into_iter().zip(extra) {
            families[f].bases.push((vec![(kind, p)], r));
            touched.push(f);
        }
        touched.dedup();
        for f in touched {
            families[f].prepare(lab);
        }
    }
    (lab.progress)(planned, planned);
    let mut candidates: Vec<Candidate> = families.iter().map(|f| evaluate(lab, f, &nominal)).collect();
    candidates.sort_by(|a, b| a.score_db.total_cmp(&b.score_db));

    // Pairs of the best three when no single effect explains the gap.
    if candidates.first().is_some_and(|c| c.held_out_shrink < PAIR_TRIGGER_SHRINK) && candidates.len() >= 2 {
        let top: Vec<usize> = candidates
            .iter()
            .take(3)
            .filter_map(|c| families.iter().position(|f| f.kinds.len() == 1 && f.kinds[0].name() == c.name))
            .collect();
        let mut pair_models = Vec::new();
        let mut pair_plan = Vec::new();
        for i in 0..top.len() {
            for j in i + 1..top.len() {
                let (a, b) = (&families[top[i]], &families[top[j]]);
                // Grid x grid: the best two points of each, combined.
                if a.linear.is_empty() && b.linear.is_empty() {
                    let best_two = |f: &Family| -> Vec<Vec<(EffectKind, Vec<f64>)>> {
                        let mut scored: Vec<(usize, f64)> =
                            (0..f.bases.len()).map(|k| (k, f.score(lab, k, &[], &all))).collect();
                        scored.sort_by(|x, y| x.1.total_cmp(&y.1));
                        scored.iter().take(2).map(|(k, _)| f.bases[*k].0.clone()).collect()
                    };
                    let mut combos = Vec::new();
                    for pa in best_two(a) {
                        for pb in best_two(b) {
                            let mut both = pa.clone();
                            both.extend(pb.clone());
                            combos.push(both);
                        }
                    }
                    let start = pair_models.len();
                    for c in &combos {
                        pair_models.push(effects_of(c).unwrap_or(nominal_effects));
                    }
                    pair_plan.push((top[i], top[j], Some((start, combos))));
                } else {
                    pair_plan.push((top[i], top[j], None));
                }
            }
        }
        let pair_runs = if pair_models.is_empty() {
            Vec::new()
        } else {
            lab.run_all(&pair_models, &mut done, planned + pair_models.len())
        };
        for (ia, ib, grid) in pair_plan {
            let (a, b) = (&families[ia], &families[ib]);
            let mut f = match grid {
                Some((start, combos)) => Family {
                    kinds: vec![a.kinds[0], b.kinds[0]],
                    bases: combos.into_iter().enumerate().map(|(k, c)| (c, pair_runs[start + k].clone())).collect(),
                    linear: Vec::new(),
                    cross: Vec::new(),
                },
                None => {
                    // The grid one (if any) gives the bases; the linear ones add their probes.
                    let (grid_f, lin): (Option<&Family>, Vec<&Family>) =
                        match (a.linear.is_empty(), b.linear.is_empty()) {
                            (true, false) => (Some(a), vec![b]),
                            (false, true) => (Some(b), vec![a]),
                            _ => (None, vec![a, b]),
                        };
                    Family {
                        kinds: vec![a.kinds[0], b.kinds[0]],
                        bases: grid_f.map_or_else(|| vec![(Vec::new(), nominal_runs.clone())], |g| g.bases.clone()),
                        linear: lin.iter().flat_map(|f| f.linear.clone()).collect(),
                        cross: Vec::new(),
                    }
                }
            };
            f.prepare(lab);
            let pair = evaluate(lab, &f, &nominal);
            // A pair must earn its extra parameters: it is kept only when it
            // leaves clearly less of the held-out gap than its better member.
            let members = [a.kinds[0].name(), b.kinds[0].name()];
            let single_best = candidates
                .iter()
                .filter(|c| members.contains(&c.name.as_str()))
                .map(|c| c.held_out_gap_after_db)
                .fold(f64::INFINITY, f64::min);
            if pair.held_out_gap_after_db < PAIR_MARGIN * single_best {
                candidates.push(pair);
            }
        }
        candidates.sort_by(|a, b| a.score_db.total_cmp(&b.score_db));
    }
    candidates
}
