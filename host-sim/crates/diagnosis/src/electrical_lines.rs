//! The direct-axis current's lines at electrical orders 1, 2 and 6: where
//! the transducer and inverter errors of a drive the project does not know
//! show in its recordings.
//!
//! A drive under vector control holds its direct-axis current, as its own
//! transducers report it, on a smooth reference (zero below field
//! weakening). The recorded phase currents are the machine's (the
//! recording format's "phase currents into the machine"), so where the
//! drive's transducers or inverter are wrong, the machine's direct-axis
//! current, taken in the frame the drive holds (`i_d = 0` on average,
//! [`crate::travel_signals::electrical_offset_rad`]), carries what the
//! drive regulated in:
//!
//! - an offset of the transducers, a current vector fixed in the stator,
//!   turns once per electrical revolution in that frame: a line at order 1,
//!   `-(o_alpha cos theta_e + o_beta sin theta_e)`;
//! - unequal gains, the reflected part `c K + d L` of the transducers' 2x2
//!   error gain in the stator frame (`K = diag(1, -1)`, `L` the swap), a
//!   line at order 2 in proportion to the current,
//!   `-(c i_d + d i_q) cos 2 theta_e - (d i_d - c i_q) sin 2 theta_e`;
//! - the inverter's dead time, a voltage error of each phase current's
//!   sign, through its 6th-order part, as far as the drive's current loop
//!   lets it through: a line at order 6. On the q axis (`i_d = 0`) that
//!   part of the voltage is `s j V (a5 e^{-6 j theta_e} + a7 e^{6 j
//!   theta_e})` (`s` the sign of `i_q`, `a5`, `a7` real: the hexagon's
//!   harmonics), and a current loop of real coefficients answers the two
//!   turning vectors with `G` and its conjugate, swapped when the rotor
//!   turns the other way; the line's cosine part is then `s sign(omega) X`
//!   and its sine part `s Y`, with `X`, `Y` the same for every travel at
//!   one speed.
//!
//! No mechanical effect puts a line there (the drive answers the machine's
//! motion on the quadrature axis); the part of the quadrature axis's lines
//! that the current loop's cross coupling leaves on the direct axis is
//! allowed for ([`CROSS_COUPLING_FRACTION`]). The mechanics driven by the
//! measured torque ([`crate::driven`]) cannot see these effects: the
//! recorded currents already carry them. This check can, whatever the
//! drive's gains.

use std::f64::consts::PI;

use nalgebra::{DMatrix, DVector};
use plant::effects::{EffectKind, Effects};
use recording::{Recording, RecordingKind};
use rig_config::RigConfig;

use crate::attribute::{jackknife_error, Candidate, FittedParameter, PARAMETER_PENALTY};
use crate::driven::TransducerTorqueLine;
use crate::error::{DiagnosisError, Result};
use crate::travel_signals::{travel_torque, TravelTorque};

/// Electrical orders (multiples of the electrical frequency `p omega_m`)
/// whose direct-axis lines are measured.
pub const ORDERS: [f64; 3] = [1.0, 2.0, 6.0];
/// Offsets (in orders) of the non-integer orders around each line whose
/// amplitudes give its noise level: nothing angle-locked lies there.
pub const NOISE_OFFSETS: [f64; 4] = [-0.5, -0.25, 0.25, 0.5];
/// A direct-axis line counts as present in a travel when its amplitude is
/// beyond this many times its noise level (a noise-only line gets there
/// with a chance of about `exp(-16)`)...
pub const LINE_NOISE_RATIO: f64 = 4.0;
/// ...and beyond this fraction of the quadrature-axis line at the same
/// order: the drive's speed loop puts lines on the quadrature axis (its
/// answer to the torque ripple), and its current loop's cross coupling
/// leaves a little of them on the direct axis. Measured on nominal rigs:
/// at most 2.3 % (the project's commercial drive, order 6, `dataset
/// --foreign-seed 101`) and 1 % (the independent emulator of
/// `rig-sample`); twice the larger, rounded up.
pub const CROSS_COUPLING_FRACTION: f64 = 0.05;

/// One direct-axis line of one travel.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct DirectAxisLine {
    /// Electrical order.
    pub order: f64,
    /// Cosine and sine coefficients of `i_d` against `order theta_e`, A.
    pub phasor_a: [f64; 2],
    /// Amplitude, A.
    pub amplitude_a: f64,
    /// Amplitude of the quadrature-axis line at the same order, A.
    pub quadrature_amplitude_a: f64,
    /// RMS amplitude of the direct-axis current at the orders
    /// [`NOISE_OFFSETS`] around, A.
    pub noise_a: f64,
    /// What nominal allows: the larger of the noise level and
    /// [`CROSS_COUPLING_FRACTION`] of the quadrature line, A.
    pub allowance_a: f64,
    /// Beyond [`LINE_NOISE_RATIO`] times the noise and beyond the cross
    /// coupling's share of the quadrature line.
    pub present: bool,
}

/// The direct-axis lines of one travel's constant-speed stage.
#[derive(Clone, Debug, serde::Serialize)]
pub struct TravelLines {
    /// Recording.
    pub recording: String,
    /// Mean direct-axis current over the stage, A.
    pub mean_id_a: f64,
    /// Mean quadrature-axis current over the stage (positive lifts the car), A.
    pub mean_iq_a: f64,
    /// The sign of the electrical angle's motion over the stage: +1 or -1.
    pub direction: f64,
    /// The offset of the frame the drive holds: `theta_e = p theta_m +
    /// offset`, rad.
    pub electrical_offset_rad: f64,
    /// One per [`ORDERS`].
    pub lines: Vec<DirectAxisLine>,
}

/// The lines of every travel and what explains them.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ElectricalLines {
    /// Per travel measured.
    pub travels: Vec<TravelLines>,
    /// Travels not measured, with the reason.
    pub not_measured: Vec<(String, String)>,
    /// Orders present in at least half of the travels (and one).
    pub present_orders: Vec<f64>,
    /// Mean excess of the direct-axis lines over what nominal allows, dB
    /// (`10 log10(1 + excess power / allowed power)` per travel).
    pub excess_db: f64,
    /// The library's electrical effects fitted to the lines, best first
    /// (held-out: each travel predicted from a fit on the others).
    pub ranking: Vec<Candidate>,
}

impl ElectricalLines {
    /// Whether a line is present: the rig's transducers or inverter differ
    /// from nominal.
    pub fn present(&self) -> bool {
        !self.present_orders.is_empty()
    }
}

/// Cosine and sine coefficients of `x` (its mean and trend removed) at
/// `order` times `theta_e` ([`dsp::sine_fit`]).
fn phasor(x: &[f64], theta_e: &[f64], order: f64) -> [f64; 2] {
    dsp::sine_fit(x, theta_e, order)
}

/// `x` less its least-squares straight line.
fn detrended(x: &[f64]) -> Vec<f64> {
    let n = x.len() as f64;
    let t_mean = (n - 1.0) / 2.0;
    let x_mean = x.iter().sum::<f64>() / n;
    let (mut sxt, mut stt) = (0.0, 0.0);
    for (k, v) in x.iter().enumerate() {
        let t = k as f64 - t_mean;
        sxt += (v - x_mean) * t;
        stt += t * t;
    }
    let slope = if stt > 0.0 { sxt / stt } else { 0.0 };
    x.iter().enumerate().map(|(k, v)| v - x_mean - slope * (k as f64 - t_mean)).collect()
}

fn amplitude(p: [f64; 2]) -> f64 {
    p[0].hypot(p[1])
}

/// The direct-axis lines of the travel recording `stem` on the machine of
/// `rig`, over its constant-speed stage.
pub fn travel_lines(rig: &RigConfig, recording: &Recording, stem: &str) -> Result<TravelLines> {
    travel_lines_of(recording, stem, &travel_torque(rig, recording, stem)?, rig.motor.pole_pairs)
}

/// [`travel_lines`] on the travel's torque `t` as derived before, for a
/// machine of `pole_pairs`.
pub fn travel_lines_of(recording: &Recording, stem: &str, t: &TravelTorque, pole_pairs: u32) -> Result<TravelLines> {
    use recording::{I_A, I_B, I_C};
    let column = |name: &str| recording.column(name).map(|c| &c.values[t.constant_speed.clone()]);
    let (Some(a), Some(b), Some(c)) = (column(I_A), column(I_B), column(I_C)) else {
        return Err(DiagnosisError::Message(format!("recording `{stem}`: phase currents missing")));
    };
    let angle = &t.shaft_angle_rad[t.constant_speed.clone()];
    lines_of_currents(stem, [a, b, c], angle, pole_pairs, t.electrical_offset_rad)
}

/// The direct-axis lines of the phase currents `abc` (A) over the shaft
/// angle `angle` (rad), in the frame `p angle + offset_rad` the drive holds.
pub fn lines_of_currents(stem: &str, abc: [&[f64]; 3], angle: &[f64], p: u32, offset_rad: f64) -> Result<TravelLines> {
    let (i_d, i_q) = dsp::dq_currents(abc[0], abc[1], abc[2], angle, p, offset_rad)?;
    let theta_e: Vec<f64> = angle.iter().map(|th| f64::from(p) * th + offset_rad).collect();
    let revolutions = (theta_e[theta_e.len() - 1] - theta_e[0]).abs() / (2.0 * PI);
    if revolutions < MIN_ELECTRICAL_REVOLUTIONS {
        return Err(DiagnosisError::Message(format!(
            "recording `{stem}`: its constant-speed stage turns {revolutions:.1} electrical revolutions; expected at \
             least {MIN_ELECTRICAL_REVOLUTIONS} to tell its lines from their neighbours"
        )));
    }
    let n = i_d.len() as f64;
    let (mean_id_a, mean_iq_a) = (i_d.iter().sum::<f64>() / n, i_q.iter().sum::<f64>() / n);
    let (d, q) = (detrended(&i_d), detrended(&i_q));
    let lines = ORDERS
        .iter()
        .map(|&order| {
            let phasor_a = phasor(&d, &theta_e, order);
            let quadrature_amplitude_a = amplitude(phasor(&q, &theta_e, order));
            let noise_power =
                NOISE_OFFSETS.iter().map(|o| amplitude(phasor(&d, &theta_e, order + o)).powi(2)).sum::<f64>()
                    / NOISE_OFFSETS.len() as f64;
            let noise_a = noise_power.sqrt();
            let amplitude_a = amplitude(phasor_a);
            let coupling_a = CROSS_COUPLING_FRACTION * quadrature_amplitude_a;
            DirectAxisLine {
                order,
                phasor_a,
                amplitude_a,
                quadrature_amplitude_a,
                noise_a,
                allowance_a: noise_a.max(coupling_a),
                present: amplitude_a > LINE_NOISE_RATIO * noise_a && amplitude_a > coupling_a,
            }
        })
        .collect();
    let direction = if theta_e[theta_e.len() - 1] >= theta_e[0] { 1.0 } else { -1.0 };
    Ok(TravelLines {
        recording: stem.to_string(),
        mean_id_a,
        mean_iq_a,
        direction,
        electrical_offset_rad: offset_rad,
        lines,
    })
}

/// Electrical orders at which the drive's current transducers put lines
/// (offset: 1, unequal gains: 2).
pub const TRANSDUCER_ORDERS: [f64; 2] = [1.0, 2.0];

/// The torque lines the drive's transducers put on the shaft, from the
/// present direct-axis lines of `lines` at [`TRANSDUCER_ORDERS`] on the
/// machine `motor` ([`crate::driven::TransducerTorqueLine`]: `K_t j D`, the
/// line turned from the electrical angle to the shaft angle).
pub fn transducer_torque_lines(motor: &rig_config::Motor, lines: &TravelLines) -> Vec<TransducerTorqueLine> {
    let p = f64::from(motor.pole_pairs);
    let kt = motor.torque_constant_nm_per_a();
    lines
        .lines
        .iter()
        .filter(|l| l.present && TRANSDUCER_ORDERS.contains(&l.order))
        .map(|l| {
            // i_d = a cos(k theta_e) + b sin(k theta_e) = Re(D e^{j k theta_e}), D = a - j b,
            // and e^{j k theta_e} = e^{j k offset} e^{j k p theta_m}.
            let (s, c) = (l.order * lines.electrical_offset_rad).sin_cos();
            let (dr, di) = (l.phasor_a[0], -l.phasor_a[1]);
            let (mr, mi) = (dr * c - di * s, dr * s + di * c);
            TransducerTorqueLine { mechanical_order: l.order * p, phasor_nm: [-kt * mi, kt * mr] }
        })
        .collect()
}

/// Fewest electrical revolutions of a constant-speed stage whose lines are
/// measured (the noise orders lie a quarter order from the lines: over
/// fewer revolutions they would not be told apart).
pub const MIN_ELECTRICAL_REVOLUTIONS: f64 = 20.0;

/// One explanation of the lines: which orders it predicts and how, linear
/// in its unknowns.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Model {
    /// Offsets and unequal gains of the transducers: orders 1 and 2.
    Transducers,
    /// The inverter's dead time: order 6.
    DeadTime,
    /// Both.
    Both,
}

impl Model {
    fn unknowns(self) -> usize {
        match self {
            Model::Transducers => 4,
            Model::DeadTime => 2,
            Model::Both => 6,
        }
    }

    fn name(self) -> String {
        match self {
            Model::Transducers => EffectKind::CurrentSensorError.name().to_string(),
            Model::DeadTime => EffectKind::DeadTime.name().to_string(),
            Model::Both => format!("{} + {}", EffectKind::CurrentSensorError.name(), EffectKind::DeadTime.name()),
        }
    }

    /// The rows (one per line coefficient, `(order index, cos or sin)`)
    /// of the travel's prediction, each a row over the unknowns
    /// `[o_alpha, o_beta, c, d, k6_cos, k6_sin]` restricted to the model's.
    fn rows(self, travel: &TravelLines, dead_time_threshold_a: f64) -> Vec<((usize, usize), Vec<f64>)> {
        let (id, iq) = (travel.mean_id_a, travel.mean_iq_a);
        // The dead time's 6th-order part grows with the current up to its
        // threshold and changes sign with it; the loop's phase turns with
        // the rotor's direction.
        let w6 = (iq / dead_time_threshold_a).tanh();
        let turning = travel.direction;
        let full: [((usize, usize), [f64; 6]); 6] = [
            ((0, 0), [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
            ((0, 1), [0.0, -1.0, 0.0, 0.0, 0.0, 0.0]),
            ((1, 0), [0.0, 0.0, -id, -iq, 0.0, 0.0]),
            ((1, 1), [0.0, 0.0, iq, -id, 0.0, 0.0]),
            ((2, 0), [0.0, 0.0, 0.0, 0.0, w6 * turning, 0.0]),
            ((2, 1), [0.0, 0.0, 0.0, 0.0, 0.0, w6]),
        ];
        let columns: &[usize] = match self {
            Model::Transducers => &[0, 1, 2, 3],
            Model::DeadTime => &[4, 5],
            Model::Both => &[0, 1, 2, 3, 4, 5],
        };
        let orders: &[usize] = match self {
            Model::Transducers => &[0, 1],
            Model::DeadTime => &[2],
            Model::Both => &[0, 1, 2],
        };
        full.iter()
            .filter(|(key, _)| orders.contains(&key.0))
            .map(|(key, row)| (*key, columns.iter().map(|&c| row[c]).collect()))
            .collect()
    }
}

/// Weighted least squares of the model on `travels`: each coefficient
/// weighted by its line's allowance.
fn fit(model: Model, travels: &[&TravelLines], threshold_a: f64) -> Option<Vec<f64>> {
    let mut rows = Vec::new();
    let mut rhs = Vec::new();
    for t in travels {
        for ((order, part), row) in model.rows(t, threshold_a) {
            let line = &t.lines[order];
            let w = 1.0 / line.allowance_a.max(f64::MIN_POSITIVE);
            rows.extend(row.iter().map(|v| v * w));
            rhs.push(line.phasor_a[part] * w);
        }
    }
    let m = model.unknowns();
    if rhs.len() < m {
        return None;
    }
    let a = DMatrix::from_row_slice(rhs.len(), m, &rows);
    let x = a.svd(true, true).solve(&DVector::from_vec(rhs), 1e-12).ok()?;
    x.iter().all(|v| v.is_finite()).then(|| x.iter().copied().collect())
}

/// The excess of a travel's lines over their allowances (after taking the
/// model's prediction `x` out), dB: `10 log10(1 + excess / allowed)`.
fn excess_db(t: &TravelLines, model: Option<(Model, &[f64])>, threshold_a: f64) -> f64 {
    let mut predicted = vec![[0.0; 2]; t.lines.len()];
    if let Some((model, x)) = model {
        for ((order, part), row) in model.rows(t, threshold_a) {
            predicted[order][part] = row.iter().zip(x).map(|(r, v)| r * v).sum();
        }
    }
    let (mut excess, mut allowed) = (0.0, 0.0);
    for (line, p) in t.lines.iter().zip(&predicted) {
        let residual = amplitude([line.phasor_a[0] - p[0], line.phasor_a[1] - p[1]]);
        excess += (residual.powi(2) - line.allowance_a.powi(2)).max(0.0);
        allowed += line.allowance_a.powi(2);
    }
    if allowed > 0.0 {
        10.0 * (1.0 + excess / allowed).log10()
    } else {
        0.0
    }
}

/// The library's parameters of the transducer fit, for a drive that forms
/// the current vector from all three transducers with phase c exact (as
/// the library's `current_sensor_error`): `o_alpha = (2 o_a - o_b) / 3`,
/// `o_beta = o_b / sqrt 3`, `c = (2 g_a - g_b) / 6`, `d = -g_b / (2 sqrt 3)`.
fn transducer_parameters(x: &[f64]) -> [f64; 4] {
    let s3 = 3f64.sqrt();
    let offset_b = s3 * x[1];
    let offset_a = (3.0 * x[0] + offset_b) / 2.0;
    let gain_b = -2.0 * s3 * x[3];
    let gain_a = (6.0 * x[2] + gain_b) / 2.0;
    [offset_a, offset_b, gain_a, gain_b]
}

/// The candidate of `model`: fitted on every travel, and held out travel by
/// travel; `before` is the travels' mean excess with no model, dB
/// ([`ElectricalLines::excess_db`]).
fn candidate(model: Model, travels: &[TravelLines], threshold_a: f64, before: f64) -> Option<Candidate> {
    let all: Vec<&TravelLines> = travels.iter().collect();
    let x = fit(model, &all, threshold_a)?;
    let n = travels.len() as f64;
    let training_after = travels.iter().map(|t| excess_db(t, Some((model, &x)), threshold_a)).sum::<f64>() / n;
    let mut held_out = Vec::new();
    let mut fold_values: Vec<Vec<f64>> = Vec::new();
    for (j, t) in travels.iter().enumerate() {
        let others: Vec<&TravelLines> = travels.iter().enumerate().filter(|(i, _)| *i != j).map(|(_, t)| t).collect();
        let fold = fit(model, &others, threshold_a)?;
        held_out.push(excess_db(t, Some((model, &fold)), threshold_a));
        fold_values.push(model_parameters(model, &fold).0.iter().map(|p| p.value).collect());
    }
    let held_out_after = held_out.iter().sum::<f64>() / n;
    let (mut parameters, effects) = model_parameters(model, &x);
    for (k, p) in parameters.iter_mut().enumerate() {
        let per_fold: Vec<f64> = fold_values.iter().map(|v| v[k]).collect();
        p.uncertainty = jackknife_error(&per_fold);
    }
    Some(Candidate {
        name: model.name(),
        fitted_parameters: model.unknowns(),
        parameters,
        training_gap_before_db: before,
        training_gap_after_db: training_after,
        held_out_gap_before_db: before,
        held_out_gap_after_db: held_out_after,
        held_out_shrink: if before > 0.0 { 1.0 - held_out_after / before } else { 0.0 },
        score_db: held_out_after * (1.0 + PARAMETER_PENALTY * model.unknowns() as f64),
        effects,
        held_out_improvements_db: travels
            .iter()
            .zip(&held_out)
            .map(|(t, after)| excess_db(t, None, threshold_a) - after)
            .collect(),
        search_edge: Vec::new(),
        naming: Default::default(),
        refit: None,
    })
}

/// The fitted parameters in words, and the library effect where its
/// parameters follow from the fit (the transducers'; the dead time's line
/// passes the drive's current loop, whose gains are not recorded, so its
/// size and phase are given, not the dead time in seconds).
fn model_parameters(model: Model, x: &[f64]) -> (Vec<FittedParameter>, Effects) {
    let mut parameters = Vec::new();
    let mut effects = Effects::none();
    let param = |effect: &'static str, name: &'static str, unit: &'static str, value: f64| FittedParameter {
        effect,
        name,
        unit,
        value,
        uncertainty: f64::NAN,
        measured_by: None,
    };
    if matches!(model, Model::Transducers | Model::Both) {
        let v = transducer_parameters(x);
        let kind = EffectKind::CurrentSensorError;
        for (spec, value) in kind.parameters().iter().zip(v) {
            parameters.push(param(kind.name(), spec.name, spec.unit, value));
        }
        // Outside the library's ranges the effect stays in words only.
        effects.set(kind, &v).ok();
    }
    if matches!(model, Model::DeadTime | Model::Both) {
        let k = &x[x.len() - 2..];
        let name = EffectKind::DeadTime.name();
        parameters.push(param(name, "order6_line_a", "A", amplitude([k[0], k[1]])));
        parameters.push(param(name, "order6_phase_rad", "rad", k[1].atan2(k[0])));
    }
    (parameters, effects)
}

/// The direct-axis lines of the travels `travels` (`(stem, recording)`) on
/// `rig`, and the library's electrical effects fitted to them when present.
/// Only the effects of `kinds` are fitted (the lines are measured whatever
/// they are).
pub fn electrical_lines(rig: &RigConfig, travels: &[(&str, &Recording)], kinds: &[EffectKind]) -> ElectricalLines {
    let mut measured = Vec::new();
    let mut not_measured = Vec::new();
    for (stem, recording) in travels {
        if !matches!(recording.meta.kind, RecordingKind::Travel { .. }) {
            continue;
        }
        match travel_lines(rig, recording, stem) {
            Ok(t) => measured.push(t),
            Err(e) => not_measured.push((stem.to_string(), format!("{e:#}"))),
        }
    }
    explain(measured, not_measured, kinds)
}

/// The orders present in the travels' lines `measured` and the library's
/// electrical effects among `kinds` fitted to them; `not_measured` as given.
pub fn explain(
    measured: Vec<TravelLines>,
    not_measured: Vec<(String, String)>,
    kinds: &[EffectKind],
) -> ElectricalLines {
    let needed = measured.len().div_ceil(2).max(1);
    let present_orders: Vec<f64> = ORDERS
        .iter()
        .enumerate()
        .filter(|(k, _)| measured.iter().filter(|t| t.lines[*k].present).count() >= needed && !measured.is_empty())
        .map(|(_, o)| *o)
        .collect();
    let threshold_a = EffectKind::DeadTime.defaults()[1];
    let excess_db = if measured.is_empty() {
        0.0
    } else {
        measured.iter().map(|t| excess_db(t, None, threshold_a)).sum::<f64>() / measured.len() as f64
    };
    // The pair only where lines of both kinds are present.
    let transducer_lines = present_orders.iter().any(|&o| o < 6.0);
    let dead_time_line = present_orders.contains(&6.0);
    let models: &[Model] = match (transducer_lines, dead_time_line) {
        (true, true) => &[Model::Transducers, Model::DeadTime, Model::Both],
        (false, false) => &[],
        _ => &[Model::Transducers, Model::DeadTime],
    };
    let tried = |m: &Model| match m {
        Model::Transducers => kinds.contains(&EffectKind::CurrentSensorError),
        Model::DeadTime => kinds.contains(&EffectKind::DeadTime),
        Model::Both => kinds.contains(&EffectKind::CurrentSensorError) && kinds.contains(&EffectKind::DeadTime),
    };
    let mut ranking: Vec<Candidate> = if measured.len() < 2 {
        Vec::new()
    } else {
        models.iter().filter(|m| tried(m)).filter_map(|&m| candidate(m, &measured, threshold_a, excess_db)).collect()
    };
    ranking.sort_by(|a, b| a.score_db.total_cmp(&b.score_db));
    ElectricalLines { travels: measured, not_measured, present_orders, excess_db, ranking }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{rngs::StdRng, Rng, SeedableRng};

    const P: u32 = 6;
    const OFFSET: f64 = 0.7;

    /// The machine's phase currents (summing to zero) when the drive holds
    /// its transducers' readings `(1 + g_x) i_x + o_x` (phases a and b,
    /// phase c exact), formed into the current vector by the three-phase
    /// Clarke transform, on `i_q` A of quadrature current with `i_d = 0`,
    /// plus `q_ripple` A on the quadrature axis at orders 1, 2, 6 and
    /// `leak` of it on the direct axis; `noise` A RMS of white noise per phase.
    fn travel(
        i_q: f64,
        errors: [f64; 4],
        (q_ripple, leak): (f64, f64),
        noise: f64,
        seed: u64,
    ) -> (Vec<[f64; 3]>, Vec<f64>) {
        let [oa, ob, ga, gb] = errors;
        let (fs, speed, seconds) = (4000.0, 6.15, 8.0);
        let mut rng = StdRng::seed_from_u64(seed);
        let s3 = 3f64.sqrt();
        let mut currents = Vec::new();
        let mut angle = Vec::new();
        for k in 0..(fs * seconds) as usize {
            let theta = speed * k as f64 / fs;
            let te = f64::from(P) * theta + OFFSET;
            let ripple: f64 = [1.0, 2.0, 6.0].iter().map(|o| (o * te + o).cos()).sum::<f64>() * q_ripple;
            let (d, q) = (leak * ripple, i_q + ripple);
            let (alpha, beta) = (d * te.cos() - q * te.sin(), d * te.sin() + q * te.cos());
            // The readings' Clarke transform equals the reference: solve
            // for the machine's i_a, i_b (i_c = -i_a - i_b).
            let (m11, m12, m21, m22) = ((3.0 + 2.0 * ga) / 3.0, -gb / 3.0, 1.0 / s3, (2.0 + gb) / s3);
            let (r1, r2) = (alpha - (2.0 * oa - ob) / 3.0, beta - ob / s3);
            let det = m11 * m22 - m12 * m21;
            let i_a = (r1 * m22 - m12 * r2) / det;
            let i_b = (m11 * r2 - m21 * r1) / det;
            let mut white = || noise * (rng.gen::<f64>() - 0.5) * 12f64.sqrt();
            currents.push([i_a + white(), i_b + white(), -i_a - i_b + white()]);
            angle.push(theta);
        }
        (currents, angle)
    }

    fn lines(i_q: f64, errors: [f64; 4], q_ripple: f64, leak: f64, seed: u64) -> TravelLines {
        let (currents, angle) = travel(i_q, errors, (q_ripple, leak), 0.02, seed);
        let column = |k: usize| currents.iter().map(|c| c[k]).collect::<Vec<f64>>();
        let (a, b, c) = (column(0), column(1), column(2));
        lines_of_currents("travel", [&a, &b, &c], &angle, P, OFFSET).unwrap()
    }

    #[test]
    fn transducer_errors_are_found_from_the_direct_axis_lines() {
        let truth = [0.3, -0.08, 0.012, -0.009];
        let travels: Vec<TravelLines> =
            [8.0, -4.0, 11.0, -2.0].iter().enumerate().map(|(k, &iq)| lines(iq, truth, 0.2, 0.0, k as u64)).collect();
        let found = explain(travels, Vec::new(), &EffectKind::ALL);
        assert_eq!(found.present_orders, vec![1.0, 2.0]);
        // No line at order 6: the pair with the dead time is not tried.
        assert!(found.ranking.iter().all(|c| !c.name.contains('+')));
        let best = &found.ranking[0];
        assert_eq!(best.name, "current_sensor_error");
        assert!(best.held_out_shrink > 0.9, "{}", best.held_out_shrink);
        for (p, t) in best.parameters.iter().zip(truth) {
            // First order in the gains: a few percent of the largest.
            let tolerance = if p.unit == "A" { 0.01 } else { 5e-4 };
            assert!((p.value - t).abs() < tolerance, "{} = {} against {t}", p.name, p.value);
        }
        let dead_time = found.ranking.iter().find(|c| c.name == "dead_time").unwrap();
        assert!(dead_time.held_out_shrink < 0.1, "{}", dead_time.held_out_shrink);
    }

    /// The torque line predicted from the direct-axis line (`K_t j D`)
    /// is the machine's own: the torque of its quadrature current, from
    /// currents solved from transducer readings the drive holds, read
    /// against the shaft angle. Both directions, offsets and gains.
    #[test]
    fn the_transducers_torque_lines_are_the_quadrature_currents() {
        let motor = rig_config::RigConfig::embedded_default().unwrap().motor;
        let kt = 1.5 * f64::from(P) * motor.flux_linkage_wb;
        for (i_q, errors) in [(8.0, [0.3, -0.08, 0.0, 0.0]), (-6.0, [-0.1, 0.2, 0.02, -0.015])] {
            let (currents, angle) = travel(i_q, errors, (0.0, 0.0), 0.005, 3);
            let column = |k: usize| currents.iter().map(|c| c[k]).collect::<Vec<f64>>();
            let (a, b, c) = (column(0), column(1), column(2));
            let t = lines_of_currents("travel", [&a, &b, &c], &angle, P, OFFSET).unwrap();
            let predicted = transducer_torque_lines(&motor, &t);
            let (_, q) = dsp::dq_currents(&a, &b, &c, &angle, P, OFFSET).unwrap();
            let torque: Vec<f64> = detrended(&q).iter().map(|v| kt * v).collect();
            let expected_orders = if errors[2] == 0.0 { vec![6.0] } else { vec![6.0, 12.0] };
            assert_eq!(predicted.iter().map(|l| l.mechanical_order).collect::<Vec<_>>(), expected_orders);
            for line in predicted {
                let [cos, sin] = phasor(&torque, &angle, line.mechanical_order);
                let measured = [cos, -sin];
                let size = measured[0].hypot(measured[1]);
                let miss = (line.phasor_nm[0] - measured[0]).hypot(line.phasor_nm[1] - measured[1]);
                assert!(
                    size > 0.05 && miss < 0.03 * size,
                    "order {}: {:?} against {measured:?}",
                    line.mechanical_order,
                    line.phasor_nm
                );
            }
        }
    }

    /// The lines are measured whatever the effects tried; only those
    /// asked for are fitted.
    #[test]
    fn only_the_effects_asked_for_are_fitted_to_the_lines() {
        let truth = [0.3, -0.08, 0.012, -0.009];
        let travels = || -> Vec<TravelLines> {
            [8.0, -4.0, 11.0].iter().enumerate().map(|(k, &iq)| lines(iq, truth, 0.2, 0.0, k as u64)).collect()
        };
        let found = explain(travels(), Vec::new(), &[EffectKind::DeadTime, EffectKind::CoulombGuideFriction]);
        assert_eq!(found.present_orders, vec![1.0, 2.0]);
        assert_eq!(found.ranking.iter().map(|c| c.name.as_str()).collect::<Vec<_>>(), ["dead_time"]);
        let found = explain(travels(), Vec::new(), &[EffectKind::CoulombGuideFriction]);
        assert!(found.present() && found.ranking.is_empty());
    }

    #[test]
    fn currents_without_noise_have_no_lines() {
        // Rounding is at the level of the neighbouring orders too.
        let (currents, angle) = travel(8.0, [0.0; 4], (0.0, 0.0), 0.0, 0);
        let column = |k: usize| currents.iter().map(|c| c[k]).collect::<Vec<f64>>();
        let (a, b, c) = (column(0), column(1), column(2));
        let t = lines_of_currents("travel", [&a, &b, &c], &angle, P, OFFSET).unwrap();
        assert!(t.lines.iter().all(|l| !l.present), "{:?}", t.lines);
    }

    #[test]
    fn the_speed_loops_lines_and_their_cross_coupling_are_nominal() {
        let travels: Vec<TravelLines> = [8.0, -4.0, 11.0, -2.0]
            .iter()
            .enumerate()
            .map(|(k, &iq)| lines(iq, [0.0; 4], 0.3, 0.02, k as u64))
            .collect();
        let found = explain(travels, Vec::new(), &EffectKind::ALL);
        assert!(found.present_orders.is_empty(), "{:?}", found.present_orders);
        assert!(found.ranking.is_empty());
        // The same leak, five times larger, is a line.
        let travels: Vec<TravelLines> = [8.0, -4.0, 11.0, -2.0]
            .iter()
            .enumerate()
            .map(|(k, &iq)| lines(iq, [0.0; 4], 0.3, 0.1, k as u64))
            .collect();
        assert_eq!(explain(travels, Vec::new(), &EffectKind::ALL).present_orders, ORDERS.to_vec());
    }
}
