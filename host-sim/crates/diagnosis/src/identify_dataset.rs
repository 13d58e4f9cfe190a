//! The paper's identification over a whole dataset, as `identify` reports
//! it and the gap diagnosis calibrates with it: every free decay (Eqn 9,
//! 11-12) and every travel (Eqn 13 with Eqn 4) on its own, each value held
//! against a physical plausibility range, outliers across recordings set
//! aside, and a reason for every recording left out.

use super::identify::{identify_free_decay, FreeDecayIdentification};
use super::travel_signals::{torque_balance, TorqueBalance, TravelTorque};
use recording::{Recording, RecordingKind, ACC_CAR};
use rig_config::RigConfig;

/// Plausible rope `EA`, N: from a thin synthetic cord to a thick steel rope.
pub const EA_RANGE_N: (f64, f64) = (1.0e4, 1.0e9);
/// Plausible guide damping of one rig side, kg/s (never negative).
pub const GUIDE_DAMPING_RANGE_KG_PER_S: (f64, f64) = (0.0, 1.0e4);
/// Plausible sheave rotational damping, N m s/rad (never negative).
pub const SHEAVE_DAMPING_RANGE_NMS_PER_RAD: (f64, f64) = (0.0, 100.0);
/// A value further than this many scaled median absolute deviations from
/// the median of its kind is an outlier (with three recordings or more).
pub const OUTLIER_MADS: f64 = 4.0;
/// ... and further than this fraction of the median (the spread of good
/// recordings can be tiny).
pub const OUTLIER_MIN_RELATIVE: f64 = 0.1;

/// One recording's identification.
#[derive(Clone, Debug)]
pub enum RecordingIdentification {
    /// A free decay: `EA`, damping ratio and guide damping.
    FreeDecay(FreeDecayIdentification),
    /// A travel: the constant-speed torque balance and the sheave damping.
    Travel(TorqueBalance),
}

/// A recording (or one of its values) left out, and why.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct LeftOut {
    /// Recording stem.
    pub recording: String,
    /// Why, in words.
    pub reason: String,
}

/// What the dataset gives.
#[derive(Clone, Debug, Default)]
pub struct DatasetIdentification {
    /// Free decays whose values are used.
    pub decays: Vec<(String, FreeDecayIdentification)>,
    /// Travels whose sheave damping is used.
    pub travels: Vec<(String, TorqueBalance)>,
    /// Recordings (or values) left out, with the reason.
    pub left_out: Vec<LeftOut>,
    /// Rope `EA`, N: the mean of the decays kept.
    pub rope_ea_n: Option<f64>,
    /// Damping ratio of the decays kept (Eqn 11).
    pub damping_ratio: Option<f64>,
    /// Guide damping of one side, kg/s (Eqn 12), mean of the decays kept.
    pub guide_damping_kg_per_s: Option<f64>,
    /// Sheave damping, N m s/rad (Eqn 13), mean of the travels kept.
    pub sheave_damping_nms_per_rad: Option<f64>,
}

/// Identifies every recording of `dataset` on `rig`. Free decays first:
/// their guide damping (or, with none, the rig's) enters the travels'
/// torque balance. `max_frequency_hz` bounds the search for a decay's first
/// mode. Never fails: a recording that gives nothing usable is left out
/// with the reason.
pub fn identify_dataset(
    rig: &RigConfig,
    dataset: &[(String, Recording)],
    max_frequency_hz: f64,
) -> DatasetIdentification {
    identify_dataset_on(rig, dataset, &[], max_frequency_hz)
}

/// [`identify_dataset`] with the travels' torques as derived before:
/// `torques[i]` that of `dataset[i]` where there is one (a travel without
/// one, or beyond the slice, has its torque derived here).
pub fn identify_dataset_on(
    rig: &RigConfig,
    dataset: &[(String, Recording)],
    torques: &[Option<TravelTorque>],
    max_frequency_hz: f64,
) -> DatasetIdentification {
    let m = &rig.mechanics;
    let mut out = DatasetIdentification::default();
    let mut decays = Vec::new();
    for (stem, recording) in dataset {
        let RecordingKind::FreeDecay { mass_kg, rope_length_m } = recording.meta.kind else { continue };
        let Some(acc) = recording.column(ACC_CAR) else {
            out.leave_out(stem, format!("no `{ACC_CAR}` column"));
            continue;
        };
        match identify_free_decay(
            &acc.values,
            recording.meta.sample_rate_hz,
            mass_kg,
            rope_length_m,
            m.rope_mass_per_length_kg_per_m,
            m.gravity_mps2,
            max_frequency_hz,
        ) {
            Ok(id) => decays.push((stem.clone(), id)),
            Err(e) => out.leave_out(stem, e.to_string()),
        }
    }
    let decays = out.plausible(decays, "rope EA", "N", EA_RANGE_N, |d| d.rope_ea_n);
    let decays = out.plausible(decays, "guide damping", "kg/s", GUIDE_DAMPING_RANGE_KG_PER_S, |d| d.damping_kg_per_s);
    out.rope_ea_n = mean(decays.iter().map(|(_, d)| d.rope_ea_n));
    out.damping_ratio = mean(decays.iter().map(|(_, d)| d.damping_ratio));
    out.guide_damping_kg_per_s = mean(decays.iter().map(|(_, d)| d.damping_kg_per_s));
    out.decays = decays;

    let guides = out.guide_damping_kg_per_s.map_or(m.c_cw_kg_per_s + m.c_car_kg_per_s, |c| 2.0 * c);
    let mut travels = Vec::new();
    for (i, (stem, recording)) in dataset.iter().enumerate() {
        if let RecordingKind::Travel { .. } = recording.meta.kind {
            match torque_balance(rig, recording, stem, guides, torques.get(i).and_then(Option::as_ref)) {
                Ok(b) => travels.push((stem.clone(), b)),
                Err(e) => out.leave_out(stem, format!("{e:#}")),
            }
        }
    }
    let travels = out.plausible(travels, "sheave damping", "N m s/rad", SHEAVE_DAMPING_RANGE_NMS_PER_RAD, |b| {
        b.sheave_damping_nms_per_rad
    });
    out.sheave_damping_nms_per_rad = mean(travels.iter().map(|(_, b)| b.sheave_damping_nms_per_rad));
    out.travels = travels;
    out
}

impl DatasetIdentification {
    fn leave_out(&mut self, stem: &str, reason: String) {
        self.left_out.push(LeftOut { recording: stem.to_string(), reason });
    }

    /// Keeps the entries whose `value` lies in `range` (unit `unit`) and,
    /// with three or more, is no outlier among them; leaves the others out
    /// with the reason.
    fn plausible<T>(
        &mut self,
        entries: Vec<(String, T)>,
        what: &str,
        unit: &str,
        range: (f64, f64),
        value: impl Fn(&T) -> f64,
    ) -> Vec<(String, T)> {
        let mut kept = Vec::new();
        for (stem, entry) in entries {
            let v = value(&entry);
            if v.is_finite() && v >= range.0 && v <= range.1 {
                kept.push((stem, entry));
            } else {
                self.leave_out(
                    &stem,
                    format!(
                        "{what} {v:.4e} {unit} lies outside the plausible range {:.1e} to {:.1e} {unit}",
                        range.0, range.1
                    ),
                );
            }
        }
        let values: Vec<f64> = kept.iter().map(|(_, e)| value(e)).collect();
        let Some((median, limit)) = outlier_limit(&values) else { return kept };
        let (good, outliers): (Vec<_>, Vec<_>) =
            kept.into_iter().partition(|(_, e)| (value(e) - median).abs() <= limit);
        for (stem, e) in outliers {
            self.leave_out(
                &stem,
                format!(
                    "{what} {:.4e} {unit} is an outlier: the median of the recordings is {median:.4e} {unit}",
                    value(&e)
                ),
            );
        }
        good
    }
}

/// The median of `values` and the distance from it beyond which a value is
/// an outlier: [`OUTLIER_MADS`] scaled median absolute deviations, at least
/// [`OUTLIER_MIN_RELATIVE`] of the median. `None` with fewer than three.
pub fn outlier_limit(values: &[f64]) -> Option<(f64, f64)> {
    if values.len() < 3 {
        return None;
    }
    let median = median(values);
    let deviations: Vec<f64> = values.iter().map(|v| (v - median).abs()).collect();
    let mad = 1.4826 * self::median(&deviations);
    Some((median, (OUTLIER_MADS * mad).max(OUTLIER_MIN_RELATIVE * median.abs())))
}

fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

fn mean(v: impl Iterator<Item = f64>) -> Option<f64> {
    let v: Vec<f64> = v.collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_outlier_among_consistent_values_is_found_and_a_pair_is_never_judged() {
        let (median, limit) = outlier_limit(&[3.0, 3.1, 2.9, -9.2, 3.05]).unwrap();
        assert!((median - 3.0).abs() < 1e-12);
        assert!((-9.2f64 - median).abs() > limit && (3.1f64 - median).abs() <= limit);
        assert_eq!(outlier_limit(&[3.0, -9.2]), None);
    }
}
