//! The recorded phase currents' balance: the three phase currents of a
//! machine in star without a neutral wire sum to zero at every instant
//! (Kirchhoff's current law), whatever the drive, the load or the rig.
//! Recorded currents that do not are measured with an error, and the way
//! they fail to sum to zero gives the error without any model: with each
//! phase recorded as `s_x = g_x i_x + o_x` (gain `g_x`, offset `o_x`, A),
//! `sum_x (s_x - o_x) / g_x = 0` at every sample, that is
//!
//! `a_a s_a + a_b s_b + s_c = b`, with `a_x = g_c / g_x` and
//! `b = g_c sum_x o_x / g_x` (A),
//!
//! linear in `a_a`, `a_b` and `b`: a least-squares fit over a travel's
//! samples gives the gains of phases a and b relative to phase c and the
//! offsets' weighted sum (phase c the reference, as
//! `plant::effects::CurrentSensorError` has it). Which transducers erred
//! (the drive's own, whose signals the recording may be, or the rig's
//! clamps) the balance does not tell; the offsets' vector in the
//! machine's plane (the part that makes torque) is not in it either.

use nalgebra::{Matrix3, Vector3};
use recording::{Recording, I_A, I_B, I_C};

/// Standard errors by which a fitted value must leave its balanced value
/// (gain ratio 1, offset sum 0) for the currents to be called unbalanced.
pub const UNBALANCED_SIGMAS: f64 = 4.0;

// The standard errors count the residual as noise; the acquisition's
// quantiser makes part of it a function of the currents themselves, which
// a long travel turns into a "significant" gain error of a few parts in
// 10^4. An error is therefore also asked to stand above the recording's
// noise: the part of the currents' sum that the fit explains at least as
// large (RMS) as what it leaves.

/// One travel's balance fit.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RecordingBalance {
    /// Recording.
    pub recording: String,
    /// `g_a / g_c`, `g_b / g_c`: gains of phases a and b relative to phase c.
    pub gain_ratio: [f64; 2],
    /// `g_c sum_x o_x / g_x`: the offsets' weighted sum, A.
    pub offset_sum_a: f64,
    /// Standard errors of `g_a / g_c`, `g_b / g_c` and of the offset sum (A),
    /// from the residual's variance with the samples' correlation counted
    /// (its lag-one autocorrelation).
    pub standard_errors: [f64; 3],
    /// RMS of the recorded currents' sum, A.
    pub sum_rms_a: f64,
    /// RMS of what the fit leaves of it (the acquisition's noise when the
    /// fit holds), A.
    pub residual_rms_a: f64,
}

impl RecordingBalance {
    /// RMS of the part of the currents' sum that the fit explains, A.
    pub fn explained_rms_a(&self) -> f64 {
        (self.sum_rms_a.powi(2) - self.residual_rms_a.powi(2)).max(0.0).sqrt()
    }

    /// Whether the currents are measured with an error: a fitted value
    /// leaves its balanced value by more than [`UNBALANCED_SIGMAS`]
    /// standard errors, and the part of the sum it explains stands above
    /// the recording's noise (at least the RMS the fit leaves).
    pub fn unbalanced(&self) -> bool {
        let away = [self.gain_ratio[0] - 1.0, self.gain_ratio[1] - 1.0, self.offset_sum_a];
        let significant = away.iter().zip(self.standard_errors).any(|(d, se)| d.abs() > UNBALANCED_SIGMAS * se);
        significant && self.explained_rms_a() >= self.residual_rms_a
    }
}

/// The balance of every travel of `dataset` that records the three phase
/// currents (in dataset order); a travel whose currents do not constrain
/// the fit (too short, or no current flowing) is skipped.
pub fn current_balance(dataset: &[(String, Recording)]) -> Vec<RecordingBalance> {
    dataset.iter().filter_map(|(stem, r)| recording_balance(stem, r)).collect()
}

/// The balance fit of one recording, `None` when it lacks a phase current
/// or the currents do not constrain the fit.
pub fn recording_balance(stem: &str, recording: &Recording) -> Option<RecordingBalance> {
    let column = |name| recording.column(name).map(|c| c.values.as_slice());
    let (s_a, s_b, s_c) = (column(I_A)?, column(I_B)?, column(I_C)?);
    let n = s_a.len().min(s_b.len()).min(s_c.len());
    if derived_phase(&s_a[..n], &s_b[..n], &s_c[..n]) {
        return None;
    }
    let rows = |k: usize| ([s_a[k], s_b[k], -1.0], -s_c[k]);
    let (x, inverse) = least_squares((0..n).map(rows))?;
    let residual: Vec<f64> = (0..n)
        .map(|k| {
            let (row, y) = rows(k);
            row.iter().zip(x).map(|(r, xi)| r * xi).sum::<f64>() - y
        })
        .collect();
    let dof = n.checked_sub(3).filter(|&d| d > 0)? as f64;
    let variance = residual.iter().map(|r| r * r).sum::<f64>() / dof;
    let inflation = correlation_inflation(&residual);
    let se = |i: usize| (variance * inverse[i][i] * inflation).sqrt();
    let (a_a, a_b) = (x[0], x[1]);
    // g_x / g_c = 1 / a_x: the standard error through the derivative 1 / a_x^2.
    Some(RecordingBalance {
        recording: stem.to_string(),
        gain_ratio: [1.0 / a_a, 1.0 / a_b],
        offset_sum_a: x[2],
        standard_errors: [se(0) / (a_a * a_a), se(1) / (a_b * a_b), se(2)],
        sum_rms_a: rms((0..n).map(|k| s_a[k] + s_b[k] + s_c[k])),
        residual_rms_a: rms(residual.iter().copied()),
    })
    .filter(|b| b.gain_ratio.iter().chain(&b.standard_errors).all(|v| v.is_finite()))
}

/// Whether the third phase current is the other two's negative sum (an
/// acquisition that records two phases and derives the third): the sum is
/// zero to the float's rounding (below 1e-9 of the currents' RMS), so the
/// balance says nothing about the transducers.
fn derived_phase(s_a: &[f64], s_b: &[f64], s_c: &[f64]) -> bool {
    let sum = rms(s_a.iter().zip(s_b).zip(s_c).map(|((a, b), c)| a + b + c));
    let currents = rms(s_a.iter().chain(s_b).chain(s_c).copied());
    sum <= DERIVED_PHASE_FRACTION * currents
}

/// The currents' sum (RMS) below which, as a fraction of the currents'
/// RMS, the third phase is taken as derived from the other two: float
/// rounding of a sum of three, far below any transducer's resolution.
const DERIVED_PHASE_FRACTION: f64 = 1e-9;

/// The gain errors of phases a and b relative to phase c that the
/// balances of a dataset's travels measure together (`g_x / g_c - 1`, as
/// `plant::effects::CurrentSensorError`'s `gain_error_a`, `gain_error_b`),
/// each with its standard error: the inverse-variance mean over the
/// travels, its error the larger of the weighted one and the travels'
/// scatter (the standard error of their plain mean). `None` without a
/// balance.
pub fn measured_gain_errors(balances: &[RecordingBalance]) -> Option<[(f64, f64); 2]> {
    if balances.is_empty() {
        return None;
    }
    let combined = |i: usize| {
        let weights: Vec<f64> = balances.iter().map(|b| b.standard_errors[i].max(f64::MIN_POSITIVE).powi(-2)).collect();
        let total: f64 = weights.iter().sum();
        let mean = balances.iter().zip(&weights).map(|(b, w)| w * b.gain_ratio[i]).sum::<f64>() / total;
        let n = balances.len() as f64;
        let plain = balances.iter().map(|b| b.gain_ratio[i]).sum::<f64>() / n;
        let scatter = if balances.len() >= 2 {
            (balances.iter().map(|b| (b.gain_ratio[i] - plain).powi(2)).sum::<f64>() / (n - 1.0) / n).sqrt()
        } else {
            0.0
        };
        (mean - 1.0, total.sqrt().recip().max(scatter))
    };
    Some([combined(0), combined(1)]).filter(|g| g.iter().all(|(v, e)| v.is_finite() && e.is_finite()))
}

/// Whether the dataset's currents are measured with an error: more than
/// half of its balanced travels are unbalanced ([`RecordingBalance::unbalanced`]).
pub fn currents_unbalanced(balances: &[RecordingBalance]) -> bool {
    2 * balances.iter().filter(|b| b.unbalanced()).count() > balances.len()
}

/// Least squares of `rows` (`[row; 3]`, `y`) by the normal equations: the
/// solution and the inverse of the normal matrix, `None` when the normal
/// matrix's determinant is not above 1e-12 of the product of its diagonal
/// (the currents do not constrain the fit).
fn least_squares(rows: impl Iterator<Item = ([f64; 3], f64)>) -> Option<([f64; 3], [[f64; 3]; 3])> {
    let mut normal = Matrix3::zeros();
    let mut right = Vector3::zeros();
    for (row, y) in rows {
        let row = Vector3::from(row);
        normal += row * row.transpose();
        right += row * y;
    }
    let scale = normal.diagonal().product();
    let det = normal.determinant();
    if !(det.is_finite() && scale > 0.0 && det > 1e-12 * scale) {
        return None;
    }
    let inverse = normal.try_inverse()?;
    let x = inverse * right;
    Some((x.into(), std::array::from_fn(|i| std::array::from_fn(|j| inverse[(i, j)]))))
}

/// Factor by which correlated samples inflate a mean's variance, from the
/// lag-one autocorrelation `rho` of `residual`: `(1 + rho) / (1 - rho)`
/// (an AR(1) model of the residual), at least 1.
fn correlation_inflation(residual: &[f64]) -> f64 {
    let power: f64 = residual.iter().map(|r| r * r).sum();
    let lag_one: f64 = residual.windows(2).map(|w| w[0] * w[1]).sum();
    let rho = if power > 0.0 { (lag_one / power).clamp(0.0, 0.999) } else { 0.0 };
    (1.0 + rho) / (1.0 - rho)
}

fn rms(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, count) = values.fold((0.0, 0usize), |(s, c), v| (s + v * v, c + 1));
    if count == 0 {
        0.0
    } else {
        (sum / count as f64).sqrt()
    }
}

/// The balance in words, for the report: each travel's gains and offset
/// sum when unbalanced, or that every travel's currents sum to zero
/// within their noise.
pub fn balance_text(balances: &[RecordingBalance]) -> String {
    let unbalanced: Vec<&RecordingBalance> = balances.iter().filter(|b| b.unbalanced()).collect();
    if unbalanced.is_empty() {
        let worst = balances.iter().map(|b| b.sum_rms_a).fold(0.0, f64::max);
        return format!(
            "the recorded phase currents sum to zero within their noise in {} of {} travels (sum at most {:.3} A RMS)",
            balances.len(),
            balances.len(),
            worst
        );
    }
    let rows: Vec<String> = unbalanced
        .iter()
        .map(|b| {
            format!(
                "`{}`: g_a/g_c {:.4} +- {:.1e}, g_b/g_c {:.4} +- {:.1e}, offset sum {:.4} +- {:.1e} A (sum {:.3} A RMS, {:.3} A left)",
                b.recording,
                b.gain_ratio[0],
                b.standard_errors[0],
                b.gain_ratio[1],
                b.standard_errors[1],
                b.offset_sum_a,
                b.standard_errors[2],
                b.sum_rms_a,
                b.residual_rms_a
            )
        })
        .collect();
    format!(
        "the recorded phase currents do not sum to zero in {} of {} travels: a current-measurement error \
         (the drive's transducers or the rig's clamps; {} standard errors and above the recording's noise): {}",
        unbalanced.len(),
        balances.len(),
        UNBALANCED_SIGMAS,
        rows.join("; ")
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use recording::{CarDirection, Column, RecordingKind, RecordingMeta};

    /// Balanced currents of a turning machine, recorded through gains and
    /// offsets, with a deterministic pseudo-noise of `noise_a` (A).
    fn recorded(gains: [f64; 3], offsets: [f64; 3], noise_a: f64) -> Recording {
        let n = 20_000;
        let mut columns: Vec<Column> =
            [I_A, I_B, I_C].iter().map(|name| Column { name: name.to_string(), values: Vec::new() }).collect();
        let mut seed = 12_345_u64;
        let mut noise = || {
            seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            noise_a * ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 12f64.sqrt()
        };
        for k in 0..n {
            let angle = 2.0 * std::f64::consts::PI * 7.3 * k as f64 / 4096.0;
            let amplitude = 3.0 + 2.0 * (k as f64 / n as f64);
            for (x, column) in columns.iter_mut().enumerate() {
                let i = amplitude * (angle - 2.0 * std::f64::consts::PI * x as f64 / 3.0).cos();
                column.values.push(gains[x] * i + offsets[x] + noise());
            }
        }
        let kind = RecordingKind::Travel {
            m_car_kg: 70.5,
            m_cw_kg: 33.0,
            direction: CarDirection::Up,
            lw_start_m: 1.0,
            lw_end_m: 7.6,
        };
        Recording { meta: RecordingMeta { kind, sample_rate_hz: 4096.0, description: None }, columns }
    }

    #[test]
    fn gains_and_offsets_come_back_from_the_currents_sum() {
        let (g, o) = ([0.97, 1.02, 1.01], [-0.20, 0.10, 0.05]);
        let b = recording_balance("t", &recorded(g, o, 0.02)).expect("a fit");
        let expected_sum = g[2] * (o[0] / g[0] + o[1] / g[1] + o[2] / g[2]);
        assert!((b.gain_ratio[0] - g[0] / g[2]).abs() < 5.0 * b.standard_errors[0].max(1e-4), "{b:?}");
        assert!((b.gain_ratio[1] - g[1] / g[2]).abs() < 5.0 * b.standard_errors[1].max(1e-4), "{b:?}");
        assert!((b.offset_sum_a - expected_sum).abs() < 5.0 * b.standard_errors[2].max(1e-4), "{b:?}");
        assert!(b.unbalanced());
        assert!((b.residual_rms_a / (0.02 * 3f64.sqrt()) - 1.0).abs() < 0.1, "{b:?}");
        assert!(balance_text(&[b]).contains("do not sum to zero"));
    }

    #[test]
    fn balanced_currents_with_noise_are_called_balanced() {
        let b = recording_balance("t", &recorded([1.0; 3], [0.0; 3], 0.02)).expect("a fit");
        assert!(!b.unbalanced(), "{b:?}");
        assert!(balance_text(&[b]).contains("sum to zero within their noise"));
    }

    #[test]
    fn an_error_below_the_recordings_noise_is_not_called_one() {
        let b = recording_balance("t", &recorded([1.001, 1.0, 1.0], [0.0; 3], 0.02)).expect("a fit");
        assert!(b.explained_rms_a() < b.residual_rms_a, "{b:?}");
        assert!(!b.unbalanced(), "{b:?}");
        let b = recording_balance("t", &recorded([1.02, 1.0, 1.0], [0.0; 3], 0.02)).expect("a fit");
        assert!(b.unbalanced(), "{b:?}");
    }

    #[test]
    fn a_travel_without_current_or_a_phase_is_skipped() {
        let mut r = recorded([1.0; 3], [0.0; 3], 0.0);
        r.columns.iter_mut().for_each(|c| c.values.iter_mut().for_each(|v| *v = 0.0));
        assert!(recording_balance("zero", &r).is_none());
        let mut r = recorded([1.0; 3], [0.0; 3], 0.01);
        r.columns.retain(|c| c.name != I_C);
        assert!(recording_balance("two phases", &r).is_none());
    }

    #[test]
    fn a_third_phase_derived_from_the_other_two_is_no_balance() {
        let mut r = recorded([0.97, 1.02, 1.0], [0.1, 0.0, 0.0], 0.01);
        let derived: Vec<f64> = r.columns[0].values.iter().zip(&r.columns[1].values).map(|(a, b)| -(a + b)).collect();
        r.columns[2].values = derived;
        assert!(recording_balance("derived", &r).is_none());
    }

    #[test]
    fn the_dataset_gain_errors_combine_the_travels() {
        let (g, o) = ([0.97, 1.02, 1.01], [-0.20, 0.10, 0.05]);
        let balances: Vec<RecordingBalance> =
            [0.02, 0.03].iter().map(|&noise| recording_balance("t", &recorded(g, o, noise)).expect("a fit")).collect();
        let [(ga, ea), (gb, eb)] = measured_gain_errors(&balances).expect("measured");
        assert!((ga - (g[0] / g[2] - 1.0)).abs() < 5.0 * ea.max(1e-4), "{ga} +- {ea}");
        assert!((gb - (g[1] / g[2] - 1.0)).abs() < 5.0 * eb.max(1e-4), "{gb} +- {eb}");
        assert!(currents_unbalanced(&balances));
        assert!(measured_gain_errors(&[]).is_none());
        assert!(!currents_unbalanced(&[]));
    }
}
