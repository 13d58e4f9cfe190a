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
//! - `coulomb_guide_friction`: each decay's acceleration extremes, one a
//!   half cycle, follow `B_{k+1} = p B_k + q` with `p = exp(-pi zeta)`
//!   (viscous) and `q = -2 F / m` (dry friction `F` on the mass `m`: the
//!   acceleration jumps by `2 F / m` where the friction reverses, at every
//!   turning point), read on the signal itself, not on its first-mode
//!   band-pass (`half_cycle_extremes`); the viscous part replaces the
//!   calibrated guide damping, the friction centres the effect's grid, and
//!   the travels' torque balance (Eqn 13) is read again with both to give
//!   the sheave damping (`2 F r`: the friction acts on car and
//!   counterweight alike).
//!
//! The effect is then fitted on these re-calibrated parameters
//! ([`super::attribute`]), its strength starting from what the decays gave.

use crate::calibrate::Calibration;
use crate::identify::first_mode_signal;
use crate::travel_signals::{torque_balance, TravelTorque};
use dsp::filter::highpass_zero_phase;
use plant::effects::EffectKind;
use plant::free_decay::eqn9_first_frequency_hz;
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

/// A lobe of a decay counts for the friction while its speed amplitude
/// (acceleration over `omega`) is at least this many times the effect's
/// default slip speed: below it the smoothed friction has not built up
/// (`tanh 4` = 0.9993) and the mass is about to stick.
const LOBE_SPEED_OVER_SLIP: f64 = 4.0;

/// Largest ratio of a decay's extremes a cycle apart still read as
/// a decay without viscous damping (a fitted ratio above 1 is the
/// least-squares scatter of one that holds at 1; well above it the
/// recording is not a decay).
const MAX_CYCLE_RATIO: f64 = 1.05;

/// The magnitudes of a decay's half-cycle extremes after its release,
/// one per lobe (half cycle) of the first mode.
///
/// Under dry friction `F` the acceleration of a mass `m` is, over each half
/// cycle, a cosine about the friction's shifted equilibrium, and it jumps
/// by `2 F / m` at every turning point (the friction reverses there), so
/// the half-cycle extremes follow `B_{k+1} = p B_k - 2 F / m` (`p` the
/// viscous decay over half a cycle). A first-mode band-pass of that
/// signal does not: the jumps form a square wave in quadrature with the
/// motion whose fundamental (`4 F / (pi m)`) lies in the band and props
/// the filtered envelope up as it decays (on a 58 kg decay with 20 N and
/// no viscous damping, the filtered peaks read 15.7 N and 36 kg/s). The
/// lobes are therefore told by the band-passed first mode's zero
/// crossings, and each extreme is read on the signal only high-passed at
/// `f1 / 5` (its offset removed, the jumps kept). The release's lobe is
/// left out (the friction builds up only once the mass moves), and the
/// lobes end at the first one slower than [`LOBE_SPEED_OVER_SLIP`] slip
/// speeds or below three times the noise.
fn half_cycle_extremes(acceleration_mps2: &[f64], sample_rate_hz: f64, f1_hz: f64, slip_mps: f64) -> Vec<f64> {
    let Ok(release) = crate::identify::release_index(acceleration_mps2) else { return Vec::new() };
    let (Ok(above_fifth), Ok((mode, _))) = (
        highpass_zero_phase(acceleration_mps2, sample_rate_hz, 0.2 * f1_hz),
        first_mode_signal(acceleration_mps2, release, sample_rate_hz, f1_hz),
    ) else {
        return Vec::new();
    };
    // Noise: the signal before the release (zero-phase filters smear the
    // release backwards by a few cycles), when there is one.
    let quiet_end = release.saturating_sub((3.0 * sample_rate_hz / f1_hz) as usize);
    let noise_rms = if quiet_end >= (0.05 * sample_rate_hz) as usize {
        (above_fifth[..quiet_end].iter().map(|v| v * v).sum::<f64>() / quiet_end as f64).sqrt()
    } else {
        0.0
    };
    let mut lobes = Vec::new();
    let mut current: Option<(bool, f64)> = None;
    for (m, x) in mode[release..].iter().zip(&above_fifth[release..]) {
        let sign = *m > 0.0;
        match current {
            Some((s, e)) if s == sign => current = Some((s, e.max(if sign { *x } else { -*x }))),
            Some((_, e)) => {
                lobes.push(e);
                current = Some((sign, if sign { *x } else { -*x }));
            }
            None => current = Some((sign, if sign { *x } else { -*x })),
        }
    }
    let floor = (LOBE_SPEED_OVER_SLIP * slip_mps * std::f64::consts::TAU * f1_hz).max(3.0 * noise_rms);
    lobes.into_iter().skip(1).take_while(|e| *e > floor).collect()
}

/// One decay's viscous damping (kg/s) and dry friction (N) from its
/// half-cycle extremes ([`half_cycle_extremes`]): `B_{k+1} = p B_k + q`
/// with `p = exp(-pi zeta)`, `q = -2 F / m`, fitted by least squares a
/// cycle apart over the extremes from a cycle after the release on, when
/// four or more are left; with fewer (a decay that stops dead within
/// three cycles), the viscous damping stays `viscous_kg_per_s` (the
/// calibration's) and only `F` is read, from every extreme. The viscous
/// damping is `None` when it was not read.
fn viscous_and_dry(
    recording: &Recording,
    f1_hz: f64,
    mass_kg: f64,
    viscous_kg_per_s: f64,
    slip_mps: f64,
) -> Option<(Option<f64>, f64)> {
    let acc = recording.column(ACC_CAR)?;
    let b = half_cycle_extremes(&acc.values, recording.meta.sample_rate_hz, f1_hz, slip_mps);
    let omega = std::f64::consts::TAU * f1_hz;
    let dry = |q: f64| (-q * mass_kg / 2.0).max(0.0);
    // Over a cycle (lobes of one sign, which the higher rope modes and the
    // sensor's offset shift alike): `B_{k+2} = p^2 B_k + q (1 + p)`, from
    // a cycle after the release on (the release's transient, the hold
    // letting go and an acquisition's filters, lies within it).
    if b.len() >= 5 {
        let b = &b[1..];
        if let Some((q2, p2, _)) = line_fit(&b[..b.len() - 2], &b[2..]) {
            // A decrement that grows (`p^2` above 1) reads as no viscous
            // damping: `q` is then the mean drop a cycle, halved.
            let (p, q) = if p2 > 1.0 {
                (1.0, b.windows(3).map(|w| w[2] - w[0]).sum::<f64>() / (b.len() - 2) as f64 / 2.0)
            } else {
                (p2.sqrt(), q2 / (1.0 + p2.sqrt()))
            };
            if p > 0.0 && p2 < MAX_CYCLE_RATIO {
                let zeta = (-p.ln() / std::f64::consts::PI).max(0.0);
                return Some((Some(2.0 * zeta * omega * mass_kg), dry(q)));
            }
        }
    }
    if b.len() < 2 {
        return None;
    }
    let p = (-std::f64::consts::PI * viscous_kg_per_s / (2.0 * omega * mass_kg)).exp();
    let q = b.windows(2).map(|w| w[1] - p * w[0]).sum::<f64>() / (b.len() - 1) as f64;
    Some((None, dry(q)))
}

/// `coulomb_guide_friction` under its hypothesis: viscous and dry guide
/// friction from the decays' envelopes, the sheave damping from the
/// travels' torque balance with both.
fn coulomb_guide_friction(
    model: &RigConfig,
    calibration: &Calibration,
    dataset: &[(String, Recording)],
    travels: &[Option<TravelTorque>],
) -> Option<Refit> {
    let kind = EffectKind::CoulombGuideFriction;
    let m = &model.mechanics;
    let slip = kind.parameters()[1].default;
    // Every decay, also one the calibration left out (a decay that stops
    // dead within two cycles gives no decrement, but its extremes still
    // drop by the friction): its first frequency measured, or Eqn 9's on
    // the calibrated EA.
    let decays: Vec<(&Recording, f64, f64)> = dataset
        .iter()
        .filter_map(|(stem, r)| {
            let RecordingKind::FreeDecay { mass_kg, rope_length_m } = r.meta.kind else { return None };
            let f1 = calibration.decays.iter().find(|d| d.recording == *stem).map_or_else(
                || eqn9_first_frequency_hz(m.rope_ea_n, m.rope_mass_per_length_kg_per_m, rope_length_m, mass_kg),
                |d| d.first_frequency_hz,
            );
            Some((r, f1, mass_kg))
        })
        .collect();
    let read = |viscous_kg_per_s: f64| -> Vec<(Option<f64>, f64)> {
        decays.iter().filter_map(|&(r, f1, mass)| viscous_and_dry(r, f1, mass, viscous_kg_per_s, slip)).collect()
    };
    // The viscous damping of the decays long enough to tell it; without
    // any, the rig's own (the calibration's reading of decays that stop
    // dead is the friction taken for viscous damping). The decays too short
    // to tell it are read again with it.
    let viscous: Vec<f64> = read(calibration.nominal.1).iter().filter_map(|v| v.0).collect();
    let c = if viscous.is_empty() { calibration.nominal.1 } else { viscous.iter().sum::<f64>() / viscous.len() as f64 };
    let per_decay = read(c);
    if per_decay.is_empty() {
        return None;
    }
    let n = per_decay.len() as f64;
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
    // Eqn 13 with the dry friction: tau - tau_e = (c_sh + 2 c r^2) w + 2 F r sign(w).
    let sheave: Vec<f64> = dataset
        .iter()
        .enumerate()
        .filter(|(_, (_, r))| matches!(r.meta.kind, RecordingKind::Travel { .. }))
        .filter_map(|(i, (stem, r))| {
            torque_balance(model, r, stem, 2.0 * c, travels.get(i).and_then(Option::as_ref)).ok()
        })
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
    Some(Refit {
        effect: kind.name(),
        rope_ea_n: m.rope_ea_n,
        guide_damping_kg_per_s: c,
        sheave_damping_nms_per_rad: sheave_damping,
        strength: (f, f_se),
        note: format!(
            "decay half-cycle extremes B(k+1) = p B(k) + q over {} decays: viscous {c:.1} kg/s ({} of them), \
             dry {f:.2} +- {f_se:.2} N; sheave damping {sheave_damping:.3} N m s/rad over {} travels",
            per_decay.len(),
            if viscous.is_empty() { "the calibration's".to_string() } else { format!("from {}", viscous.len()) },
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
    travels: &[Option<TravelTorque>],
) -> Option<Refit> {
    match kind {
        EffectKind::TensionStiffening => tension_stiffening(model, calibration),
        EffectKind::CoulombGuideFriction => coulomb_guide_friction(model, calibration, dataset, travels),
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

    /// A free decay of `mass_kg` on 4 m of the rig's rope (EA 1e6 N),
    /// released from `a0` m/s^2, with viscous damping `c` kg/s and dry
    /// friction `f` N (slip 2 mm/s), after 0.1 s at rest, as a recording.
    fn decay(mass_kg: f64, c: f64, f: f64, a0: f64) -> (Recording, f64) {
        use plant::free_decay::{simulate_free_decay_with, FreeDecaySpec};
        let fs = 16384.0;
        let spec = FreeDecaySpec {
            mass_kg,
            rope_length_m: 4.0,
            rope_ea_n: 1.0e6,
            rope_mass_per_length_kg_per_m: 0.095,
            damping_kg_per_s: c,
            initial_acceleration_mps2: a0,
            elements: 40,
        };
        let mut effects = plant::effects::Effects::none();
        if f > 0.0 {
            effects.set(EffectKind::CoulombGuideFriction, &[f, 0.002]).unwrap();
        }
        let mut acc = vec![0.0; (0.1 * fs) as usize];
        acc.extend(simulate_free_decay_with(&spec, &effects, fs, 3.0).unwrap());
        let recording = Recording {
            meta: recording::RecordingMeta {
                kind: RecordingKind::FreeDecay { mass_kg, rope_length_m: 4.0 },
                sample_rate_hz: fs,
                description: None,
            },
            columns: vec![recording::Column::new(ACC_CAR, acc)],
        };
        (recording, eqn9_first_frequency_hz(1.0e6, 0.095, 4.0, mass_kg))
    }

    #[test]
    fn viscous_and_dry_friction_are_read_back_from_simulated_decays() {
        // Viscous and dry together.
        let (r, f1) = decay(33.0, 160.0, 6.0, 6.2);
        let (c, f) = viscous_and_dry(&r, f1, 33.0, 148.0, 0.002).unwrap();
        let c = c.unwrap();
        assert!((c / 160.0 - 1.0).abs() < 0.05 && (f / 6.0 - 1.0).abs() < 0.1, "{c} {f}");
        // Dry friction alone (the filtered peaks: 36 kg/s and 15.7 N).
        let (r, f1) = decay(58.0, 0.0, 20.0, 10.0);
        let (c, f) = viscous_and_dry(&r, f1, 58.0, 148.0, 0.002).unwrap();
        assert!(c.unwrap() < 5.0 && (f / 20.0 - 1.0).abs() < 0.05, "{c:?} {f}");
        // Viscous alone: no friction.
        let (r, f1) = decay(33.0, 160.0, 0.0, 6.2);
        let (c, f) = viscous_and_dry(&r, f1, 33.0, 148.0, 0.002).unwrap();
        assert!((c.unwrap() / 160.0 - 1.0).abs() < 0.05 && f < 0.3, "{c:?} {f}");
        // A decay that stops dead after a cycle and a half (two lobes past
        // the release): the viscous damping given, the friction read.
        let (r, f1) = decay(58.0, 148.0, 20.0, 2.0);
        let (c, f) = viscous_and_dry(&r, f1, 58.0, 148.0, 0.002).unwrap();
        assert!(c.is_none() && (f / 20.0 - 1.0).abs() < 0.1, "{c:?} {f}");
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
