//! Step 4a of the diagnosis: the calibration re-done under an effect's
//! hypothesis, so that the calibration does not eat the effect.
//!
//! The calibration (step 1) reads the decays and travels as the nominal
//! model would: with tension stiffening the decays at different tensions
//! give different `EA`, and their mean becomes the calibrated `EA`; with
//! dry guide friction the decays stop dead and, read as viscous damping,
//! give a guide damping several times the rig's. An effect fitted on top of
//! such a calibration explains nothing. Under the hypothesis of an effect
//! the same recordings are read with the effect in the model:
//!
//! - `tension_stiffening`: `ln EA = ln EA0 + alpha ln(T / T_ref)` fitted to
//!   the decays' (tension, `EA`) by least squares (`T_ref` their geometric
//!   mean tension): `EA0` replaces the calibrated `EA`, `alpha` (with its
//!   standard error) centres the effect's grid;
//! - `coulomb_guide_friction`: each decay's first-mode peaks, one a cycle,
//!   follow `A_{n+1} = p A_n + q` with `p = exp(-2 pi zeta)` (viscous) and
//!   `q = -4 F / m` (dry friction `F` on the mass `m`: `4 F / k` of
//!   displacement a cycle, `k = m omega^2`); the viscous part replaces the
//!   calibrated guide damping, the friction centres the effect's grid, and
//!   the travels' torque balance (Eqn 13) is read again with both to give
//!   the sheave damping.
//!
//! The effect is then fitted on these re-calibrated parameters
//! ([`super::attribute`]), its strength starting from what the decays gave.

use crate::calibrate::Calibration;
use crate::identify::first_mode_peaks;
use crate::travel_signals::torque_balance;
use plant::effects::EffectKind;
use recording::{Recording, RecordingKind, ACC_CAR};
use rig_config::RigConfig;

/// The calibration under one effect's hypothesis.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Refit {
    /// The effect.
    pub effect: &'static str,
    /// Rope `EA` under the hypothesis, N.
    pub rope_ea_n: f64,
    /// Guide damping of car and counterweight, kg/s.
    pub guide_damping_kg_per_s: f64,
    /// Sheave damping, N m s/rad.
    pub sheave_damping_nms_per_rad: f64,
    /// The effect's fitted strength from the calibration recordings, in the
    /// unit of its first parameter, with its standard error.
    pub strength: (f64, f64),
    /// How it was found, in words.
    pub note: String,
    /// The rig with the re-calibrated values.
    #[serde(skip)]
    pub rig: RigConfig,
    /// The effect's parameter vectors to simulate (its grid).
    #[serde(skip)]
    pub grid: Vec<Vec<f64>>,
}

/// Least-squares line `y = a + b x`: `(a, b, standard error of b)`; the
/// error is 0 with two points, `None` with fewer or no spread in `x`.
fn line_fit(x: &[f64], y: &[f64]) -> Option<(f64, f64, f64)> {
    let n = x.len();
    if n < 2 {
        return None;
    }
    let mx = x.iter().sum::<f64>() / n as f64;
    let my = y.iter().sum::<f64>() / n as f64;
    let sxx: f64 = x.iter().map(|v| (v - mx).powi(2)).sum();
    if sxx <= 1e-12 * (1.0 + mx * mx) {
        return None;
    }
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let b = sxy / sxx;
    let a = my - b * mx;
    let se = if n > 2 {
        let rss: f64 = x.iter().zip(y).map(|(u, v)| (v - a - b * u).powi(2)).sum();
        (rss / (n - 2) as f64 / sxx).sqrt()
    } else {
        0.0
    };
    Some((a, b, se))
}

/// A grid of a strength around `centre` (`+- spread`, clamped to the
/// parameter's range `[lo, hi]`), as full parameter vectors of `kind` with
/// the strength at index 0 and `rest` after it.
fn strength_grid(kind: EffectKind, centre: f64, spread: f64, rest: &[f64]) -> Vec<Vec<f64>> {
    let spec = kind.parameters()[0];
    let mut values: Vec<f64> =
        [centre - spread, centre, centre + spread].iter().map(|v| v.clamp(spec.min, spec.max)).collect();
    values.dedup_by(|a, b| (*a - *b).abs() <= 1e-12 * b.abs().max(1e-12));
    values
        .into_iter()
        .map(|v| {
            let mut p = vec![v];
            p.extend_from_slice(rest);
            p
        })
        .collect()
}

/// `tension_stiffening` under its hypothesis: `EA0` and `alpha` from the
/// decays' `EA` against their tension.
fn tension_stiffening(model: &RigConfig, calibration: &Calibration) -> Option<Refit> {
    let d = &calibration.decays;
    let t_ref = calibration.reference_tension_n?;
    let x: Vec<f64> = d.iter().map(|d| (d.tension_n / t_ref).ln()).collect();
    let y: Vec<f64> = d.iter().map(|d| d.rope_ea_n.ln()).collect();
    let (a, alpha, se) = line_fit(&x, &y)?;
    let kind = EffectKind::TensionStiffening;
    let spec = kind.parameters()[0];
    if alpha.is_nan() || alpha <= spec.min {
        return None;
    }
    let alpha = alpha.min(spec.max);
    let ea0 = a.exp();
    let mut rig = model.clone();
    rig.mechanics.rope_ea_n = ea0;
    // The grid's spread: the exponent's standard error, at least a tenth
    // of it (three decays leave one degree of freedom).
    let spread = se.max(0.1 * alpha);
    let t_param = t_ref.clamp(kind.parameters()[1].min, kind.parameters()[1].max);
    Some(Refit {
        effect: kind.name(),
        rope_ea_n: ea0,
        guide_damping_kg_per_s: model.mechanics.c_car_kg_per_s,
        sheave_damping_nms_per_rad: model.mechanics.c_sheave_nms_per_rad,
        strength: (alpha, se),
        note: format!(
            "EA against tension over {} decays: EA0 {ea0:.4e} N at {t_ref:.1} N, exponent {alpha:.3} +- {se:.3}",
            d.len()
        ),
        grid: strength_grid(kind, alpha, spread, &[t_param]),
        rig,
    })
}

/// One decay's viscous damping (kg/s) and dry friction (N) from its
/// first-mode peaks.
fn viscous_and_dry(recording: &Recording, f1_hz: f64, mass_kg: f64) -> Option<(f64, f64)> {
    let acc = recording.column(ACC_CAR)?;
    let peaks = first_mode_peaks(&acc.values, recording.meta.sample_rate_hz, f1_hz).ok()?;
    if peaks.len() < 4 {
        return None;
    }
    let (q, p, _) = line_fit(&peaks[..peaks.len() - 1], &peaks[1..])?;
    if !(p > 0.0 && p < 1.0 + 1e-9) {
        return None;
    }
    let zeta = (-p.min(1.0).ln() / std::f64::consts::TAU).max(0.0);
    let omega = std::f64::consts::TAU * f1_hz;
    Some((2.0 * zeta * omega * mass_kg, (-q * mass_kg / 4.0).max(0.0)))
}

/// `coulomb_guide_friction` under its hypothesis: viscous and dry guide
/// friction from the decays' envelopes, the sheave damping from the
/// travels' torque balance with both.
fn coulomb_guide_friction(
    model: &RigConfig,
    calibration: &Calibration,
    dataset: &[(String, Recording)],
) -> Option<Refit> {
    let kind = EffectKind::CoulombGuideFriction;
    let per_decay: Vec<(f64, f64)> = calibration
        .decays
        .iter()
        .filter_map(|d| {
            let (_, r) = dataset.iter().find(|(s, _)| *s == d.recording)?;
            viscous_and_dry(r, d.first_frequency_hz, d.mass_kg)
        })
        .collect();
    if per_decay.is_empty() {
        return None;
    }
    let n = per_decay.len() as f64;
    let c = per_decay.iter().map(|v| v.0).sum::<f64>() / n;
    let f = per_decay.iter().map(|v| v.1).sum::<f64>() / n;
    let f_se = if per_decay.len() > 1 {
        (per_decay.iter().map(|v| (v.1 - f).powi(2)).sum::<f64>() / (n - 1.0) / n).sqrt()
    } else {
        0.0
    };
    let spec = kind.parameters()[0];
    if f.is_nan() || f <= spec.min {
        return None;
    }
    let m = &model.mechanics;
    // Eqn 13 with the dry friction: tau - tau_e = (c_sh + 2 c r^2) w + 2 F r sign(w).
    let sheave: Vec<f64> = dataset
        .iter()
        .filter(|(_, r)| matches!(r.meta.kind, RecordingKind::Travel { .. }))
        .filter_map(|(stem, r)| torque_balance(model, r, stem, 2.0 * c).ok())
        .map(|b| {
            b.sheave_damping_nms_per_rad
                - 2.0 * f * m.sheave_radius_m * b.mean_speed_radps.signum() / b.mean_speed_radps
        })
        .filter(|v| v.is_finite() && *v >= 0.0 && *v <= 100.0)
        .collect();
    let sheave_damping =
        if sheave.is_empty() { m.c_sheave_nms_per_rad } else { sheave.iter().sum::<f64>() / sheave.len() as f64 };
    let mut rig = model.clone();
    rig.mechanics.c_car_kg_per_s = c;
    rig.mechanics.c_cw_kg_per_s = c;
    rig.mechanics.c_sheave_nms_per_rad = sheave_damping;
    let slip = kind.parameters()[1].default;
    Some(Refit {
        effect: kind.name(),
        rope_ea_n: m.rope_ea_n,
        guide_damping_kg_per_s: c,
        sheave_damping_nms_per_rad: sheave_damping,
        strength: (f, f_se),
        note: format!(
            "decay envelopes A(n+1) = p A(n) + q over {} decays: viscous {c:.1} kg/s, dry {f:.2} +- {f_se:.2} N; \
             sheave damping {sheave_damping:.3} N m s/rad over {} travels",
            per_decay.len(),
            sheave.len()
        ),
        grid: strength_grid(kind, f, (0.5 * f).max(2.0 * f_se), &[slip]),
        rig,
    })
}

/// The calibration under the hypothesis of `kind`, for the effects that
/// the calibration's parameters can absorb; `None` for the others, or when
/// the recordings show no sign of the effect (a decreasing `EA`, no dry
/// friction), where the calibration stands as it is.
pub fn refit(
    kind: EffectKind,
    model: &RigConfig,
    calibration: &Calibration,
    dataset: &[(String, Recording)],
) -> Option<Refit> {
    match kind {
        EffectKind::TensionStiffening => tension_stiffening(model, calibration),
        EffectKind::CoulombGuideFriction => coulomb_guide_friction(model, calibration, dataset),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_fit_recovers_a_line_and_its_error() {
        let x = [0.0, 1.0, 2.0, 3.0];
        let y: Vec<f64> = x.iter().map(|v| 1.0 + 0.5 * v).collect();
        let (a, b, se) = line_fit(&x, &y).unwrap();
        assert!((a - 1.0).abs() < 1e-12 && (b - 0.5).abs() < 1e-12 && se < 1e-12);
        assert!(line_fit(&[1.0, 1.0], &[0.0, 1.0]).is_none());
        assert!(line_fit(&[1.0], &[0.0]).is_none());
    }

    #[test]
    fn viscous_and_dry_envelopes_are_told_apart() {
        // A_{n+1} = p A_n - 4 F / m, p for zeta 0.01, F 6 N on 33 kg.
        let (m, f) = (33.0, 6.0);
        let p = (-std::f64::consts::TAU * 0.01f64).exp();
        let mut a = vec![12.0];
        for _ in 0..20 {
            let next = p * a.last().unwrap() - 4.0 * f / m;
            if next <= 0.5 {
                break;
            }
            a.push(next);
        }
        let (q, p_fit, _) = line_fit(&a[..a.len() - 1], &a[1..]).unwrap();
        assert!((p_fit - p).abs() < 1e-9);
        assert!((-q * m / 4.0 - f).abs() < 1e-9);
    }

    #[test]
    fn strength_grids_stay_in_range() {
        let g = strength_grid(EffectKind::TensionStiffening, 0.95, 0.1, &[323.7]);
        assert_eq!(g.len(), 3);
        assert!(g.iter().all(|p| p[0] <= 1.0 && p[1] == 323.7));
        let g = strength_grid(EffectKind::CoulombGuideFriction, 0.5, 1.0, &[0.002]);
        assert_eq!(g[0][0], 0.0);
    }
}
