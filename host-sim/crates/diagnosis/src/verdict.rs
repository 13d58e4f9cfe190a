//! Step 6 of the pipeline: the verdict (`nominal`, `explained` or
//! `unexplained`) from the nominal model's gap and the attribution's best
//! candidate, with the diagnosis's settings ([`GapOptions`]) and what it
//! found ([`GapReport`]).

use crate::attribute::Candidate;
use crate::calibrate::Calibration;
use crate::compare::CarAccelerationViews;
use crate::drive_finding::{DriveAssumption, DriveFinding, DriveModel};
use crate::identify_dataset::LeftOut;
use crate::locate::Location;
use crate::measure::{CellGap, GapValue, PersistentCell};
use crate::prepare::RigSpeedLoop;
use crate::{current_balance, electrical_lines};
#[cfg(doc)]
use crate::{drive_law, driven, measure, naming};
use plant::effects::EffectKind;

/// Largest nominal excess gap (dB, mean over the recordings) that the
/// verdict still calls `nominal`.
pub const NOMINAL_EXCESS_DB: f64 = 0.15;
/// Largest RMS (dB) by which a persistent cell
/// ([`measure::persistent_cell`]: beyond noise and tolerance in every
/// recording that has it, more often than chance allows) may lie beyond
/// them for the verdict still to be `nominal`.
pub const PERSISTENT_CELL_DB: f64 = 1.0;
/// Smallest held-out shrink of the gap for `explained`.
pub const EXPLAINED_SHRINK: f64 = 0.7;
/// Under a nominal gap (within the nominal threshold, no persistent cell)
/// an effect explains the data only when it removes at least this fraction
/// of the threshold from the held-out recordings' excess gap. The
/// threshold stands for the model's own form error on a rig of the class;
/// an effect that removes less is fitting that error, however consistently
/// (on a foreign draw's nominal rig the encoder error removed 0.011 dB of
/// 0.013 in every fold; on the independent emulator's parameter-only rig the
/// pulley removed 0.057 dB of 0.11, the most measured on a rig without an
/// effect: half the threshold keeps clear of both).
pub const SUB_NOMINAL_REMOVAL_FRACTION: f64 = 0.5;

/// The verdict.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// The nominal model explains the data to the noise level.
    Nominal,
    /// An effect of the library (or a pair) explains the gap.
    Explained,
    /// No candidate shrinks the held-out gap enough.
    Unexplained,
}

/// Settings of a diagnosis.
#[derive(Clone, Debug)]
pub struct GapOptions {
    /// What to assume about the rig's drive.
    pub drive: DriveAssumption,
    /// The effects to try (default: the whole library).
    pub effects: Vec<EffectKind>,
    /// See [`NOMINAL_EXCESS_DB`].
    pub nominal_excess_db: f64,
    /// See [`PERSISTENT_CELL_DB`].
    pub persistent_cell_db: f64,
    /// See [`EXPLAINED_SHRINK`].
    pub explained_shrink: f64,
}

impl Default for GapOptions {
    fn default() -> Self {
        Self {
            drive: DriveAssumption::Auto,
            effects: EffectKind::ALL.to_vec(),
            nominal_excess_db: NOMINAL_EXCESS_DB,
            persistent_cell_db: PERSISTENT_CELL_DB,
            explained_shrink: EXPLAINED_SHRINK,
        }
    }
}

/// One recording's gap.
#[derive(Clone, Debug, serde::Serialize)]
pub struct RecordingGap {
    /// Recording.
    pub recording: String,
    /// Kind: `travel` or `free_decay`.
    pub kind: &'static str,
    /// Against the calibrated nominal model, closed loop.
    pub nominal: GapValue,
    /// Excess gap of the nominal model, dB.
    pub nominal_excess_db: f64,
    /// Excess gap of the accelerations below 80 Hz, closed loop, dB.
    pub closed_loop_acceleration_excess_db: Option<f64>,
    /// The same for the replay (measured shaft motion into the mechanics), dB.
    pub replay_acceleration_excess_db: Option<f64>,
    /// Against the explaining model (when the verdict is `explained`).
    pub explained: Option<GapValue>,
    /// Excess gap with the explaining model, dB.
    pub explained_excess_db: Option<f64>,
    /// A travel whose rig is already moving at the first sample (its brake
    /// lifted before the recording started): the chain's state there is not
    /// recorded ([`driven::StartState`]).
    pub begins_in_motion: bool,
}

/// What `gap` found.
#[derive(Clone, Debug, serde::Serialize)]
pub struct GapReport {
    /// The dataset.
    pub dataset: String,
    /// The verdict.
    pub verdict: Verdict,
    /// The drive the travels' model assumes, and why.
    pub drive: DriveFinding,
    /// The rig drive's speed loop identified from each travel under another
    /// drive ([`drive_law`]).
    pub rig_speed_loops: Vec<RigSpeedLoop>,
    /// Recordings not diagnosed, with the reason (the calibration's own
    /// left-out recordings are in [`Calibration::skipped`]).
    pub left_out: Vec<LeftOut>,
    /// What the attribution left out, and why (under another drive).
    pub attribution_note: Option<String>,
    /// The explaining effect (or pair) when `explained`.
    pub explained_by: Option<String>,
    /// When the verdict is `nominal` although a named candidate shrinks
    /// the held-out gap enough: why, in words ([`SUB_NOMINAL_REMOVAL_FRACTION`]);
    /// when it is not `nominal` because the recorded currents do not sum
    /// to zero ([`crate::current_balance`]) and no effect explains the
    /// gap: that.
    pub verdict_note: Option<String>,
    /// The gap measure, in words, with its unit.
    pub gap_measure: String,
    /// Mean excess gap of the calibrated nominal model over the recordings, dB.
    pub nominal_excess_db: f64,
    /// Mean noise gap of the recordings, dB.
    pub noise_gap_db: f64,
    /// The nominal model's persistent cell with the largest RMS beyond
    /// noise and tolerance, if any; beyond [`PERSISTENT_CELL_DB`] it alone
    /// makes the verdict other than `nominal`.
    pub persistent_cell: Option<PersistentCell>,
    /// Under another drive: the direct-axis current's lines at electrical
    /// orders 1, 2 and 6 and the electrical effects fitted to them
    /// ([`electrical_lines`]); a line present makes the verdict other than
    /// `nominal`.
    pub electrical_lines: Option<electrical_lines::ElectricalLines>,
    /// Each travel's phase-current balance ([`current_balance`]): currents
    /// unbalanced in most travels make the verdict other than `nominal` and
    /// hold `current_sensor_error`'s gains in its fit.
    pub current_balance: Vec<current_balance::RecordingBalance>,
    /// The car acceleration of the recording with the largest nominal gap,
    /// measured and from the models the diagnosis compared it with (for
    /// spectrograms; not in `gap.json`).
    #[serde(skip)]
    pub car_acceleration_views: Option<CarAccelerationViews>,
    /// Step 1.
    pub calibration: Calibration,
    /// Where the gap lies (nominal model).
    pub location: Location,
    /// Every effect (and pair) tried, best first.
    pub ranking: Vec<Candidate>,
    /// Per recording.
    pub recordings: Vec<RecordingGap>,
    /// Bands, `[lo, hi)` Hz, as the cell band indices use them.
    pub bands_hz: Vec<(f64, f64)>,
    /// Cells of every channel of the nominal model (the gap maps before).
    pub map_before: Vec<CellGap>,
    /// The same with the explaining model (after).
    pub map_after: Vec<CellGap>,
    /// Wall-clock time of the diagnosis, s.
    pub runtime_s: f64,
    /// Simulations run.
    pub simulations: usize,
}

impl GapReport {
    /// When the two best candidates are the sheave's eccentricity and the
    /// encoder's error, in either order: they move the rope alike for the
    /// measured angle, and what tells them apart, in words.
    pub fn once_per_revolution_note(&self) -> Option<String> {
        let [first, second] = [self.ranking.first()?, self.ranking.get(1)?].map(|c| c.name.as_str());
        (self.verdict != Verdict::Nominal && move_the_rope_alike(first, second)).then(|| {
            format!(
                "{first} and {second} both move the rope by r0 (theta + e sin(theta + phi)) for the measured \
                     angle theta, one through the sheave's geometry, the other through the encoder's reading: the \
                     recordings tell them apart only through the torque, under the rig's once-per-revolution \
                     ripple; a second shaft sensor or a runout measurement of the sheave settles which"
            )
        })
    }

    /// When the nominal model misses the data and no candidate of the
    /// ranking may be named ([`naming`]): that no effect of the library
    /// helps, with why the best is not named.
    pub fn no_effect_helps_note(&self) -> Option<String> {
        if self.verdict == Verdict::Nominal || self.ranking.iter().any(|c| c.naming.named) {
            return None;
        }
        let first = self.ranking.first()?;
        Some(format!(
            "No effect of the library helps: the best fit, `{}`, is not named because {}",
            first.name, first.naming.reason
        ))
    }

    /// The travels that begin with the rig already moving and what the
    /// diagnosis does about them, in words; `None` when there are none.
    pub fn begins_in_motion_note(&self) -> Option<String> {
        let travels: Vec<&str> =
            self.recordings.iter().filter(|g| g.begins_in_motion).map(|g| g.recording.as_str()).collect();
        (!travels.is_empty()).then(|| {
            let handled = if self.drive.drive == DriveModel::Foreign {
                "the model starts there in the quasi-static state of the measured speed, and the tolerance covers \
                 the unknown jolt of the brake lift, from none (a pre-torque that balanced the load) to the whole \
                 torque (no pre-torque)"
            } else {
                "the closed loop runs the travel from standstill, so the start of the comparison is not the rig's"
            };
            format!(
                "{} begin{} with the rig already moving (its brake lifted before the recording started): {handled}",
                travels.join(", "),
                if travels.len() == 1 { "s" } else { "" }
            )
        })
    }
}

/// Whether candidates `a` and `b` are the sheave's eccentricity and the
/// encoder's error, in either order.
fn move_the_rope_alike(a: &str, b: &str) -> bool {
    let pair = [EffectKind::SheaveEccentricity.name(), EffectKind::EncoderError.name()];
    a != b && pair.contains(&a) && pair.contains(&b)
}

/// The verdict from the nominal model's gap (`is_nominal`) with the best
/// candidate of the attribution, and the direct-axis lines when present
/// with theirs: `explained` when a named candidate removes the held-out
/// gap (shrink at least the option's) and the lines' gap is explained
/// too, whatever the nominal gap's size, as long as what it removes of a
/// nominal gap is more than the model's own form error
/// ([`SUB_NOMINAL_REMOVAL_FRACTION`]); otherwise `nominal` when neither
/// shows a gap, `explained` when every gap shown is explained.
pub(crate) fn verdict_of(
    is_nominal: bool,
    best: Option<&Candidate>,
    electrical: Option<&electrical_lines::ElectricalLines>,
    options: &GapOptions,
) -> Verdict {
    let lines_explained = electrical.is_none_or(|e| e.ranking.first().is_some_and(|c| explains(c, false, options)));
    if best.is_some_and(|c| explains(c, is_nominal, options)) && lines_explained {
        // A named effect that removes the held-out gap wins over the
        // nominal model, however small that gap: the same machinery
        // compares both on the same held-out recordings.
        Verdict::Explained
    } else if is_nominal && electrical.is_none() {
        Verdict::Nominal
    } else if is_nominal && lines_explained {
        Verdict::Explained
    } else {
        Verdict::Unexplained
    }
}

/// Whether candidate `c` explains the gap it was fitted to: named, its
/// held-out shrink at least the option's, and, for a gap within the
/// nominal threshold (`within_nominal`), removing at least
/// [`SUB_NOMINAL_REMOVAL_FRACTION`] of the threshold (more than the
/// model's own form error).
pub(crate) fn explains(c: &Candidate, within_nominal: bool, options: &GapOptions) -> bool {
    c.naming.named
        && c.held_out_shrink >= options.explained_shrink
        && (!within_nominal || removed_db(c) >= SUB_NOMINAL_REMOVAL_FRACTION * options.nominal_excess_db)
}

/// What candidate `c` removes from the held-out excess gap, dB.
fn removed_db(c: &Candidate) -> f64 {
    c.held_out_gap_before_db - c.held_out_gap_after_db
}

/// Why a named candidate that shrinks the held-out gap enough does not
/// make a nominal gap `explained` (the verdict is `nominal`): what it
/// removes against [`SUB_NOMINAL_REMOVAL_FRACTION`] of the threshold, in
/// words; `None` otherwise.
pub(crate) fn form_error_note(verdict: Verdict, best: Option<&Candidate>, options: &GapOptions) -> Option<String> {
    let c = best.filter(|c| explains(c, false, options) && !explains(c, true, options))?;
    let least = SUB_NOMINAL_REMOVAL_FRACTION * options.nominal_excess_db;
    (verdict == Verdict::Nominal).then(|| {
        format!(
            "`{}` removes {:.3} dB of the held-out excess gap ({:.0} %), less than half the nominal threshold \
             ({least:.3} dB): the nominal model's own form error on a rig of the class, not the evidence of an effect",
            c.name,
            removed_db(c),
            100.0 * c.held_out_shrink
        )
    })
}

/// Why the verdict is not `nominal` when the recorded phase currents do
/// not sum to zero (`unbalanced`) and the verdict is `unexplained`, in
/// words; `None` otherwise.
pub(crate) fn unbalanced_note(verdict: Verdict, unbalanced: bool) -> Option<String> {
    (unbalanced && verdict == Verdict::Unexplained).then(|| {
        "the recorded phase currents do not sum to zero (see the currents' balance): the currents are measured \
         with an error, so the rig is not the nominal one, whatever the gap's size; no effect of the library, \
         `current_sensor_error` with the gains the balance measures included, explains the gap it leaves in \
         the mechanics"
            .to_string()
    })
}

/// The names of what explains the gap: the lines' named effect, then the
/// mechanics', joined by ` + `.
pub(crate) fn explained_by(electrical: Option<&electrical_lines::ElectricalLines>, best: Option<&Candidate>) -> String {
    let names: Vec<&str> = electrical
        .and_then(|e| e.ranking.first())
        .filter(|c| c.naming.named)
        .into_iter()
        .chain(best)
        .map(|c| c.name.as_str())
        .collect();
    names.join(" + ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::naming;
    use plant::effects::Effects;

    fn candidate(shrink: f64) -> Candidate {
        Candidate {
            name: "effect".into(),
            parameters: Vec::new(),
            fitted_parameters: 1,
            training_gap_before_db: 1.0,
            training_gap_after_db: 1.0 - shrink,
            held_out_gap_before_db: 1.0,
            held_out_gap_after_db: 1.0 - shrink,
            held_out_shrink: shrink,
            score_db: 1.0 - shrink,
            effects: Effects::none(),
            naming: naming::Naming { named: true, reason: String::new() },
            ..Candidate::default()
        }
    }

    fn lines_explained_by(shrink: f64) -> electrical_lines::ElectricalLines {
        electrical_lines::ElectricalLines {
            travels: Vec::new(),
            not_measured: Vec::new(),
            present_orders: vec![1.0],
            excess_db: 10.0,
            ranking: vec![candidate(shrink)],
        }
    }

    #[test]
    fn every_gap_shown_must_be_explained() {
        let o = GapOptions::default();
        let (good, poor) = (candidate(0.9), candidate(0.2));
        let (lines_good, lines_poor) = (lines_explained_by(0.9), lines_explained_by(0.2));
        assert_eq!(verdict_of(true, Some(&poor), None, &o), Verdict::Nominal);
        assert_eq!(verdict_of(true, Some(&poor), Some(&lines_good), &o), Verdict::Explained);
        assert_eq!(verdict_of(true, Some(&good), Some(&lines_poor), &o), Verdict::Unexplained);
        assert_eq!(verdict_of(false, Some(&good), Some(&lines_good), &o), Verdict::Explained);
        assert_eq!(verdict_of(false, Some(&poor), Some(&lines_good), &o), Verdict::Unexplained);
        assert_eq!(verdict_of(false, Some(&good), None, &o), Verdict::Explained);
        assert_eq!(verdict_of(false, None, None, &o), Verdict::Unexplained);
        let not_named = Candidate { naming: naming::Naming::default(), ..candidate(0.9) };
        assert_eq!(verdict_of(false, Some(&not_named), None, &o), Verdict::Unexplained);
    }

    /// Within the nominal threshold a named effect explains the data only
    /// when it removes more than the model's own form error.
    #[test]
    fn a_nominal_gap_is_explained_only_beyond_the_form_error() {
        let o = GapOptions::default();
        let removing = |before: f64, after: f64| Candidate {
            held_out_gap_before_db: before,
            held_out_gap_after_db: after,
            held_out_shrink: 1.0 - after / before,
            ..candidate(0.9)
        };
        let fitting_the_form_error = removing(0.01, 0.002);
        assert_eq!(verdict_of(true, Some(&fitting_the_form_error), None, &o), Verdict::Nominal);
        assert_eq!(verdict_of(true, Some(&removing(0.14, 0.01)), None, &o), Verdict::Explained);
        // Beyond the threshold the shrink alone decides.
        assert_eq!(verdict_of(false, Some(&removing(0.2, 0.05)), None, &o), Verdict::Explained);
        // The lines explain their own gap; the mechanics' candidate then
        // still does not explain its own (the report leaves it out).
        let lines = lines_explained_by(0.9);
        assert_eq!(verdict_of(true, Some(&fitting_the_form_error), Some(&lines), &o), Verdict::Explained);
        assert!(explains(&fitting_the_form_error, false, &o) && !explains(&fitting_the_form_error, true, &o));
        let note = form_error_note(Verdict::Nominal, Some(&fitting_the_form_error), &o).expect("a note");
        assert!(note.contains("0.008 dB") && note.contains("0.075 dB"), "{note}");
        assert!(form_error_note(Verdict::Explained, Some(&removing(0.14, 0.01)), &o).is_none());
    }

    #[test]
    fn only_the_eccentricity_and_the_encoder_error_move_the_rope_alike() {
        assert!(move_the_rope_alike("sheave_eccentricity", "encoder_error"));
        assert!(move_the_rope_alike("encoder_error", "sheave_eccentricity"));
        assert!(!move_the_rope_alike("encoder_error", "encoder_error"));
        assert!(!move_the_rope_alike("sheave_eccentricity", "sheave_eccentricity + encoder_error"));
        assert!(!move_the_rope_alike("sheave_eccentricity", "coulomb_guide_friction"));
    }
}
