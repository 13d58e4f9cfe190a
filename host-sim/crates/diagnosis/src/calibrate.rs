//! Step 1 of the diagnosis: the parameters the paper itself treats as
//! uncertain are identified from the data with the paper's procedures, so
//! that a parameter error is not taken for a missing effect: `EA` from the
//! free decays' first frequency (Eqn 9), guide damping from their
//! logarithmic decrement (Eqn 11-12), the sheave's damping from the torque
//! balance of the constant-speed stage (Eqn 13 with Eqn 4).

use crate::identify_dataset::identify_dataset_on;
use crate::travel_signals::TravelTorque;
use recording::Recording;
use rig_config::RigConfig;

/// Highest frequency searched for a decay's first mode, Hz.
pub const DECAY_MAX_FREQUENCY_HZ: f64 = 100.0;

/// What one free decay gave.
#[derive(Clone, Debug, serde::Serialize)]
pub struct DecayCalibration {
    /// Recording.
    pub recording: String,
    /// Hanging mass, kg.
    pub mass_kg: f64,
    /// Static tension at the mass, N.
    pub tension_n: f64,
    /// First natural frequency measured, Hz.
    pub first_frequency_hz: f64,
    /// `EA` from Eqn 9, N.
    pub rope_ea_n: f64,
    /// Damping ratio (Eqn 11).
    pub damping_ratio: f64,
    /// Guide damping (Eqn 12), kg/s.
    pub guide_damping_kg_per_s: f64,
}

/// The calibrated parameters and where they come from.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Calibration {
    /// Rope `EA` used, N (mean over the decays, or the rig's).
    pub rope_ea_n: f64,
    /// Guide damping of car and counterweight used, kg/s.
    pub guide_damping_kg_per_s: f64,
    /// Sheave rotational damping used, N m s/rad.
    pub sheave_damping_nms_per_rad: f64,
    /// Geometric mean of the decays' tensions, N: the tension at which the
    /// calibrated `EA` holds (`tension_stiffening`'s reference).
    pub reference_tension_n: Option<f64>,
    /// Per free decay.
    pub decays: Vec<DecayCalibration>,
    /// Sheave damping per travel, N m s/rad.
    pub travels: Vec<(String, f64)>,
    /// Recordings that could not be used, with the reason.
    pub skipped: Vec<String>,
    /// The rig's values before calibration: EA (N), guide damping (kg/s), sheave damping (N m s/rad).
    pub nominal: (f64, f64, f64),
}

/// Smallest relative perturbation of each calibrated parameter when the
/// model's sensitivity is probed (EA, guide damping, sheave damping).
pub const MIN_PERTURBATION: [f64; 3] = [0.005, 0.03, 0.03];

/// Where the perturbed models lie, in units of the calibration's
/// uncertainty ([`Calibration::perturbed`]): its two ends, then its two
/// middle points. The ends serve every counterpart; the middle points
/// serve the torque-driven model of a travel under another drive, whose
/// rope-mass modes (damped by nothing but the guides through the car and
/// counterweight) ring with what the measured torque put into them over
/// the whole travel: what they hold at its end turns with the rope's `EA`
/// by a fraction of a per mil, not monotonically, so the ends of the
/// interval alone do not show how far the model can move there.
pub const PERTURBATION_STEPS: [f64; 4] = [1.0, -1.0, 0.5, -0.5];

impl Calibration {
    /// Relative standard errors of EA, guide damping and sheave damping
    /// (spread of the per-recording values over the square root of their
    /// number), at least [`MIN_PERTURBATION`].
    pub fn relative_uncertainty(&self) -> [f64; 3] {
        let se = |v: Vec<f64>| -> f64 {
            let n = v.len() as f64;
            if n < 2.0 {
                return 0.0;
            }
            let m = v.iter().sum::<f64>() / n;
            let sd = (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            if m.abs() > 0.0 {
                sd / n.sqrt() / m.abs()
            } else {
                0.0
            }
        };
        [
            se(self.decays.iter().map(|d| d.rope_ea_n).collect()).max(MIN_PERTURBATION[0]),
            se(self.decays.iter().map(|d| d.guide_damping_kg_per_s).collect()).max(MIN_PERTURBATION[1]),
            se(self.travels.iter().map(|t| t.1).collect()).max(MIN_PERTURBATION[2]),
        ]
    }

    /// `model` with EA, guide and sheave damping moved by `sign` (a step
    /// of [`PERTURBATION_STEPS`]) times their relative uncertainty: how
    /// much of the data the calibration cannot pin down.
    pub fn perturbed(&self, model: &RigConfig, sign: f64) -> RigConfig {
        let [ea, guide, sheave] = self.relative_uncertainty().map(|u| sign * u);
        let mut out = model.clone();
        out.mechanics.rope_ea_n *= 1.0 + ea;
        out.mechanics.c_car_kg_per_s *= 1.0 + guide;
        out.mechanics.c_cw_kg_per_s *= 1.0 + guide;
        out.mechanics.c_sheave_nms_per_rad *= 1.0 + sheave;
        out
    }

    /// `model` perturbed at each of [`PERTURBATION_STEPS`], in that order.
    pub fn perturbations(&self, model: &RigConfig) -> [RigConfig; 4] {
        PERTURBATION_STEPS.map(|step| self.perturbed(model, step))
    }
}

/// Calibrates `rig` on `dataset` ([`identify_dataset_on`]: every recording
/// on its own, implausible values and outliers left out with the reason),
/// `travels[i]` the torque of travel `dataset[i]` as its measurement
/// derived it (none: derived here); returns the calibrated rig and the
/// record. A value the data does not give stays the rig's.
pub fn calibrate(
    rig: &RigConfig,
    dataset: &[(String, Recording)],
    travels: &[Option<TravelTorque>],
) -> (RigConfig, Calibration) {
    let m = &rig.mechanics;
    let id = identify_dataset_on(rig, dataset, travels, DECAY_MAX_FREQUENCY_HZ);
    let decays: Vec<DecayCalibration> = id
        .decays
        .iter()
        .map(|(stem, d)| DecayCalibration {
            recording: stem.clone(),
            mass_kg: d.mass_kg,
            tension_n: d.tension_n,
            first_frequency_hz: d.first_frequency_hz,
            rope_ea_n: d.rope_ea_n,
            damping_ratio: d.damping_ratio,
            guide_damping_kg_per_s: d.damping_kg_per_s,
        })
        .collect();
    let rope_ea_n = id.rope_ea_n.unwrap_or(m.rope_ea_n);
    let guide = id.guide_damping_kg_per_s.unwrap_or(0.5 * (m.c_cw_kg_per_s + m.c_car_kg_per_s));
    let sheave = id.sheave_damping_nms_per_rad.unwrap_or(m.c_sheave_nms_per_rad);
    let reference_tension_n = (!decays.is_empty())
        .then(|| (decays.iter().map(|d| d.tension_n.ln()).sum::<f64>() / decays.len() as f64).exp());
    let mut calibrated = rig.clone();
    calibrated.mechanics.rope_ea_n = rope_ea_n;
    calibrated.mechanics.c_cw_kg_per_s = guide;
    calibrated.mechanics.c_car_kg_per_s = guide;
    calibrated.mechanics.c_sheave_nms_per_rad = sheave;
    let calibration = Calibration {
        rope_ea_n,
        guide_damping_kg_per_s: guide,
        sheave_damping_nms_per_rad: sheave,
        reference_tension_n,
        decays,
        travels: id.travels.iter().map(|(stem, b)| (stem.clone(), b.sheave_damping_nms_per_rad)).collect(),
        skipped: id.left_out.iter().map(|l| format!("{}: {}", l.recording, l.reason)).collect(),
        nominal: (m.rope_ea_n, 0.5 * (m.c_cw_kg_per_s + m.c_car_kg_per_s), m.c_sheave_nms_per_rad),
    };
    (calibrated, calibration)
}
