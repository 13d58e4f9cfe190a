//! The full plant's library of unmodelled effects: each a small module with
//! named parameters, switched on in any combination through [`Effects`] (a
//! TOML file, `[name] parameter = value`, or `--effect name:param=value`
//! flags). With every effect off the plant is the paper's nominal model.
//!
//! The parameters of every effect are listed in [`EffectKind::parameters`]
//! with their units, ranges and which of them the gap diagnosis fits; the
//! values of one effect travel as a slice in that order
//! ([`Effects::set`], [`Effects::values`]).

pub mod brake_stop;
pub mod car_frame_mode;
pub mod coulomb_guide_friction;
pub mod current_sensor_error;
pub mod dead_time;
pub mod diverting_pulley;
pub mod encoder_error;
pub mod rope_discretization;
pub mod sheave_eccentricity;
pub mod tension_stiffening;

pub use brake_stop::BrakeStop;
pub use car_frame_mode::CarFrameMode;
pub use coulomb_guide_friction::CoulombGuideFriction;
pub use current_sensor_error::CurrentSensorError;
pub use dead_time::DeadTime;
pub use diverting_pulley::DivertingPulley;
pub use encoder_error::EncoderError;
pub use rope_discretization::RopeDiscretization;
pub use sheave_eccentricity::SheaveEccentricity;
pub use tension_stiffening::TensionStiffening;

use std::f64::consts::TAU;

/// One effect of the library.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum EffectKind {
    /// EA grows with rope tension: `EA = EA0 (T / T_ref)^alpha`.
    TensionStiffening,
    /// The diverting pulley as a rotational degree of freedom between sheave and car.
    DivertingPulley,
    /// `N` lumped rope elements per side instead of one.
    RopeDiscretization,
    /// A flexible car-frame mode between the rope hitch and the accelerometer.
    CarFrameMode,
    /// Dry friction at the guide shoes of car and counterweight.
    CoulombGuideFriction,
    /// The brake clamps the sheave elastically at the end of the travel.
    BrakeStop,
    /// The traction sheave's radius varies with its angle.
    SheaveEccentricity,
    /// The inverter's dead time distorts the phase voltages.
    DeadTime,
    /// Gain and offset errors of the phase-current transducers the drive trusts.
    CurrentSensorError,
    /// Encoder eccentricity: an angle error once per revolution.
    EncoderError,
}

/// How a parameter is searched when it is fitted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamScale {
    /// Evenly over `[min, max]`.
    Linear,
    /// Evenly in `log` over `[min, max]` (`min > 0`).
    Log,
    /// Whole numbers in `[min, max]`.
    Integer,
    /// A phase angle, rad, periodic over `[0, 2 pi)`.
    Angle,
}

/// One named parameter of an effect.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamSpec {
    /// Name, with its unit as suffix (`_n`, `_hz`, `_s`, `_rad`, ...).
    pub name: &'static str,
    /// Unit, as text (`"-"` when dimensionless).
    pub unit: &'static str,
    /// Value when the effect is switched on without it.
    pub default: f64,
    /// Smallest accepted value.
    pub min: f64,
    /// Largest accepted value.
    pub max: f64,
    /// How the diagnosis searches it.
    pub scale: ParamScale,
    /// Whether the gap diagnosis fits it (otherwise it keeps its default or
    /// the value the diagnosis derives from the data).
    pub fitted: bool,
    /// What it is.
    pub doc: &'static str,
}

#[allow(clippy::too_many_arguments)]
const fn p(
    name: &'static str,
    unit: &'static str,
    default: f64,
    min: f64,
    max: f64,
    scale: ParamScale,
    fitted: bool,
    doc: &'static str,
) -> ParamSpec {
    ParamSpec { name, unit, default, min, max, scale, fitted, doc }
}

use ParamScale::{Angle, Integer, Linear, Log};

const TENSION_STIFFENING: [ParamSpec; 2] = [
    p("alpha", "-", 0.2, 0.0, 1.0, Linear, true, "exponent of EA = EA0 (T / T_ref)^alpha"),
    p(
        "reference_tension_n",
        "N",
        323.73,
        10.0,
        1.0e4,
        Log,
        false,
        "tension at which EA equals the configured EA0 (default: 33 kg hanging)",
    ),
];
const DIVERTING_PULLEY: [ParamSpec; 4] = [
    p("inertia_kg_m2", "kg m^2", 0.02, 0.002, 0.2, Log, true, "pulley inertia"),
    p("radius_m", "m", 0.065, 0.02, 0.3, Linear, false, "pulley radius"),
    p("sheave_to_pulley_m", "m", 0.5, 0.05, 0.9, Linear, false, "rope length from the sheave to the pulley"),
    p("damping_ratio", "-", 0.02, 0.002, 0.5, Log, true, "damping ratio of the pulley's own mode"),
];
const ROPE_DISCRETIZATION: [ParamSpec; 1] =
    [p("elements", "-", 4.0, 1.0, 8.0, Integer, true, "lumped elements per rope side")];
const CAR_FRAME_MODE: [ParamSpec; 3] = [
    p("frequency_hz", "Hz", 235.0, 80.0, 500.0, Log, true, "frame mode with the hitch held"),
    p("damping_ratio", "-", 0.02, 0.005, 0.2, Log, true, "modal damping ratio"),
    p("mass_fraction", "-", 0.3, 0.02, 0.8, Linear, false, "share of the car mass on the accelerometer side"),
];
const COULOMB_GUIDE_FRICTION: [ParamSpec; 2] = [
    p("friction_n", "N", 20.0, 0.0, 150.0, Linear, true, "dry friction force at each guide (car and counterweight)"),
    p("slip_speed_mps", "m/s", 0.002, 1.0e-3, 0.05, Log, false, "speed over which the friction force builds up (tanh)"),
];
const BRAKE_STOP: [ParamSpec; 2] = [
    p(
        "clamp_stiffness_nm_per_rad",
        "N m/rad",
        3.0e4,
        1.0e3,
        1.0e6,
        Log,
        true,
        "torsional stiffness of the clamped brake",
    ),
    p("clamp_damping_nms_per_rad", "N m s/rad", 5.0, 0.0, 200.0, Linear, false, "damping of the clamped brake"),
];
const SHEAVE_ECCENTRICITY: [ParamSpec; 2] = [
    p(
        "eccentricity",
        "-",
        0.005,
        0.0,
        0.02,
        Linear,
        true,
        "relative radius variation: r = r0 (1 + e cos(theta + phase))",
    ),
    p("phase_rad", "rad", 0.0, 0.0, TAU, Angle, true, "angle of the largest radius"),
];
const DEAD_TIME: [ParamSpec; 2] = [
    p("dead_time_s", "s", 1.0e-6, 0.0, 5.0e-6, Linear, true, "dead time per switching edge"),
    p("current_threshold_a", "A", 0.3, 0.01, 5.0, Log, false, "current over which the error reaches its full value"),
];
const CURRENT_SENSOR_ERROR: [ParamSpec; 4] = [
    p("offset_a_a", "A", 0.2, -1.0, 1.0, Linear, true, "offset of the phase-a transducer"),
    p("offset_b_a", "A", -0.1, -1.0, 1.0, Linear, true, "offset of the phase-b transducer"),
    p("gain_error_a", "-", 0.01, -0.05, 0.05, Linear, true, "relative gain error of phase a"),
    p("gain_error_b", "-", -0.01, -0.05, 0.05, Linear, true, "relative gain error of phase b"),
];
const ENCODER_ERROR: [ParamSpec; 2] = [
    p("eccentricity_rad", "rad", 0.002, 0.0, 0.01, Linear, true, "angle error amplitude, once per revolution"),
    p("phase_rad", "rad", 0.0, 0.0, TAU, Angle, true, "phase: error = a sin(theta + phase)"),
];

impl EffectKind {
    /// Every effect of the library, in a fixed order.
    pub const ALL: [EffectKind; 10] = [
        EffectKind::TensionStiffening,
        EffectKind::DivertingPulley,
        EffectKind::RopeDiscretization,
        EffectKind::CarFrameMode,
        EffectKind::CoulombGuideFriction,
        EffectKind::BrakeStop,
        EffectKind::SheaveEccentricity,
        EffectKind::DeadTime,
        EffectKind::CurrentSensorError,
        EffectKind::EncoderError,
    ];

    /// The effect's name in files, flags and reports.
    pub fn name(self) -> &'static str {
        match self {
            EffectKind::TensionStiffening => "tension_stiffening",
            EffectKind::DivertingPulley => "diverting_pulley",
            EffectKind::RopeDiscretization => "rope_discretization",
            EffectKind::CarFrameMode => "car_frame_mode",
            EffectKind::CoulombGuideFriction => "coulomb_guide_friction",
            EffectKind::BrakeStop => "brake_stop",
            EffectKind::SheaveEccentricity => "sheave_eccentricity",
            EffectKind::DeadTime => "dead_time",
            EffectKind::CurrentSensorError => "current_sensor_error",
            EffectKind::EncoderError => "encoder_error",
        }
    }

    /// The effect named `name`, if any.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }

    /// Its parameters, in the order of [`Effects::set`].
    pub fn parameters(self) -> &'static [ParamSpec] {
        match self {
            EffectKind::TensionStiffening => &TENSION_STIFFENING,
            EffectKind::DivertingPulley => &DIVERTING_PULLEY,
            EffectKind::RopeDiscretization => &ROPE_DISCRETIZATION,
            EffectKind::CarFrameMode => &CAR_FRAME_MODE,
            EffectKind::CoulombGuideFriction => &COULOMB_GUIDE_FRICTION,
            EffectKind::BrakeStop => &BRAKE_STOP,
            EffectKind::SheaveEccentricity => &SHEAVE_ECCENTRICITY,
            EffectKind::DeadTime => &DEAD_TIME,
            EffectKind::CurrentSensorError => &CURRENT_SENSOR_ERROR,
            EffectKind::EncoderError => &ENCODER_ERROR,
        }
    }

    /// Default values of its parameters.
    pub fn defaults(self) -> Vec<f64> {
        self.parameters().iter().map(|s| s.default).collect()
    }
}

/// A bad effect description.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum EffectError {
    /// No effect of that name.
    #[error("{origin}: unknown effect `{name}`; the library has: {known}")]
    UnknownEffect {
        /// Where it was read.
        origin: String,
        /// The name given.
        name: String,
        /// The names known.
        known: String,
    },
    /// No parameter of that name.
    #[error("{origin}: effect `{effect}` has no parameter `{name}`; it has: {known}")]
    UnknownParameter {
        /// Where it was read.
        origin: String,
        /// The effect.
        effect: &'static str,
        /// The name given.
        name: String,
        /// Its parameters.
        known: String,
    },
    /// A value outside its range, not finite, or not a number.
    #[error("{origin}: `{effect}.{name}` = {value}: expected {expected}")]
    BadValue {
        /// Where it was read.
        origin: String,
        /// The effect.
        effect: &'static str,
        /// The parameter.
        name: &'static str,
        /// The value given, as text.
        value: String,
        /// What is accepted.
        expected: String,
    },
    /// A malformed file or flag.
    #[error("{origin}: {message}")]
    Syntax {
        /// Where it was read.
        origin: String,
        /// What is wrong.
        message: String,
    },
}

/// Which effects the plant has, with their parameters (all off: the
/// nominal plant).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Effects {
    /// EA grows with tension.
    pub tension_stiffening: Option<TensionStiffening>,
    /// The diverting pulley's rotation.
    pub diverting_pulley: Option<DivertingPulley>,
    /// More rope elements per side.
    pub rope_discretization: Option<RopeDiscretization>,
    /// The car frame's first mode.
    pub car_frame_mode: Option<CarFrameMode>,
    /// Dry guide friction.
    pub coulomb_guide_friction: Option<CoulombGuideFriction>,
    /// Elastic brake clamp at the stop.
    pub brake_stop: Option<BrakeStop>,
    /// Eccentric traction sheave.
    pub sheave_eccentricity: Option<SheaveEccentricity>,
    /// Inverter dead time.
    pub dead_time: Option<DeadTime>,
    /// Current transducer errors.
    pub current_sensor_error: Option<CurrentSensorError>,
    /// Encoder eccentricity.
    pub encoder_error: Option<EncoderError>,
}

fn check_values(kind: EffectKind, values: &[f64], origin: &str) -> Result<(), EffectError> {
    let specs = kind.parameters();
    if values.len() != specs.len() {
        return Err(EffectError::Syntax {
            origin: origin.to_string(),
            message: format!("effect `{}` takes {} parameters, got {}", kind.name(), specs.len(), values.len()),
        });
    }
    for (spec, &v) in specs.iter().zip(values) {
        let integer_ok = spec.scale != ParamScale::Integer || v.fract() == 0.0;
        if !(v.is_finite() && v >= spec.min && v <= spec.max && integer_ok) {
            return Err(EffectError::BadValue {
                origin: origin.to_string(),
                effect: kind.name(),
                name: spec.name,
                value: format!("{v}"),
                expected: format!(
                    "{}a value in [{}, {}] {}",
                    if spec.scale == ParamScale::Integer { "a whole number, " } else { "" },
                    spec.min,
                    spec.max,
                    spec.unit
                ),
            });
        }
    }
    Ok(())
}

impl Effects {
    /// The nominal plant: no effect.
    pub fn none() -> Self {
        Self::default()
    }

    /// Whether no effect is on.
    pub fn is_nominal(&self) -> bool {
        self.enabled().is_empty()
    }

    /// The effects switched on, in [`EffectKind::ALL`] order.
    pub fn enabled(&self) -> Vec<EffectKind> {
        EffectKind::ALL.into_iter().filter(|&k| self.values(k).is_some()).collect()
    }

    /// Switches `kind` on with `values` (in [`EffectKind::parameters`]
    /// order), checked against their ranges.
    pub fn set(&mut self, kind: EffectKind, values: &[f64]) -> Result<(), EffectError> {
        check_values(kind, values, "effect parameters")?;
        let v = values;
        match kind {
            EffectKind::TensionStiffening => {
                self.tension_stiffening = Some(TensionStiffening { alpha: v[0], reference_tension_n: v[1] })
            }
            EffectKind::DivertingPulley => {
                self.diverting_pulley = Some(DivertingPulley {
                    inertia_kg_m2: v[0],
                    radius_m: v[1],
                    sheave_to_pulley_m: v[2],
                    damping_ratio: v[3],
                })
            }
            EffectKind::RopeDiscretization => {
                self.rope_discretization = Some(RopeDiscretization { elements: v[0] as usize })
            }
            EffectKind::CarFrameMode => {
                self.car_frame_mode =
                    Some(CarFrameMode { frequency_hz: v[0], damping_ratio: v[1], mass_fraction: v[2] })
            }
            EffectKind::CoulombGuideFriction => {
                self.coulomb_guide_friction = Some(CoulombGuideFriction { friction_n: v[0], slip_speed_mps: v[1] })
            }
            EffectKind::BrakeStop => {
                self.brake_stop = Some(BrakeStop { clamp_stiffness_nm_per_rad: v[0], clamp_damping_nms_per_rad: v[1] })
            }
            EffectKind::SheaveEccentricity => {
                self.sheave_eccentricity = Some(SheaveEccentricity { eccentricity: v[0], phase_rad: v[1] })
            }
            EffectKind::DeadTime => self.dead_time = Some(DeadTime { dead_time_s: v[0], current_threshold_a: v[1] }),
            EffectKind::CurrentSensorError => {
                self.current_sensor_error = Some(CurrentSensorError {
                    offset_a_a: v[0],
                    offset_b_a: v[1],
                    gain_error_a: v[2],
                    gain_error_b: v[3],
                })
            }
            EffectKind::EncoderError => {
                self.encoder_error = Some(EncoderError { eccentricity_rad: v[0], phase_rad: v[1] })
            }
        }
        Ok(())
    }

    /// Switches `kind` off.
    pub fn clear(&mut self, kind: EffectKind) {
        match kind {
            EffectKind::TensionStiffening => self.tension_stiffening = None,
            EffectKind::DivertingPulley => self.diverting_pulley = None,
            EffectKind::RopeDiscretization => self.rope_discretization = None,
            EffectKind::CarFrameMode => self.car_frame_mode = None,
            EffectKind::CoulombGuideFriction => self.coulomb_guide_friction = None,
            EffectKind::BrakeStop => self.brake_stop = None,
            EffectKind::SheaveEccentricity => self.sheave_eccentricity = None,
            EffectKind::DeadTime => self.dead_time = None,
            EffectKind::CurrentSensorError => self.current_sensor_error = None,
            EffectKind::EncoderError => self.encoder_error = None,
        }
    }

    /// The parameter values of `kind` (in [`EffectKind::parameters`] order)
    /// when it is on.
    pub fn values(&self, kind: EffectKind) -> Option<Vec<f64>> {
        match kind {
            EffectKind::TensionStiffening => self.tension_stiffening.map(|e| vec![e.alpha, e.reference_tension_n]),
            EffectKind::DivertingPulley => {
                self.diverting_pulley.map(|e| vec![e.inertia_kg_m2, e.radius_m, e.sheave_to_pulley_m, e.damping_ratio])
            }
            EffectKind::RopeDiscretization => self.rope_discretization.map(|e| vec![e.elements as f64]),
            EffectKind::CarFrameMode => {
                self.car_frame_mode.map(|e| vec![e.frequency_hz, e.damping_ratio, e.mass_fraction])
            }
            EffectKind::CoulombGuideFriction => {
                self.coulomb_guide_friction.map(|e| vec![e.friction_n, e.slip_speed_mps])
            }
            EffectKind::BrakeStop => {
                self.brake_stop.map(|e| vec![e.clamp_stiffness_nm_per_rad, e.clamp_damping_nms_per_rad])
            }
            EffectKind::SheaveEccentricity => self.sheave_eccentricity.map(|e| vec![e.eccentricity, e.phase_rad]),
            EffectKind::DeadTime => self.dead_time.map(|e| vec![e.dead_time_s, e.current_threshold_a]),
            EffectKind::CurrentSensorError => {
                self.current_sensor_error.map(|e| vec![e.offset_a_a, e.offset_b_a, e.gain_error_a, e.gain_error_b])
            }
            EffectKind::EncoderError => self.encoder_error.map(|e| vec![e.eccentricity_rad, e.phase_rad]),
        }
    }

    /// Switches on the effects of a TOML text (`origin` names it in
    /// errors): one table per effect, `[name]`, with any of its parameters
    /// (the others keep their defaults).
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, EffectError> {
        let table: toml::Table = text
            .parse()
            .map_err(|e: toml::de::Error| EffectError::Syntax { origin: origin.to_string(), message: e.to_string() })?;
        let mut effects = Effects::none();
        for (name, body) in &table {
            let kind = known_kind(name, origin)?;
            let body = body.as_table().ok_or_else(|| EffectError::Syntax {
                origin: origin.to_string(),
                message: format!("`{name}` must be a table `[{name}]` of parameters"),
            })?;
            let mut values = kind.defaults();
            for (param, value) in body {
                let index = param_index(kind, param, origin)?;
                let spec = &kind.parameters()[index];
                values[index] = match value {
                    toml::Value::Float(f) => *f,
                    toml::Value::Integer(i) => *i as f64,
                    other => {
                        return Err(EffectError::BadValue {
                            origin: origin.to_string(),
                            effect: kind.name(),
                            name: spec.name,
                            value: other.to_string(),
                            expected: format!("a number in {}", spec.unit),
                        })
                    }
                };
            }
            check_values(kind, &values, origin)?;
            effects.set(kind, &values)?;
        }
        Ok(effects)
    }

    /// Switches on the effect of one command-line flag: `name` (defaults)
    /// or `name:param=value,param=value`.
    pub fn apply_flag(&mut self, flag: &str) -> Result<(), EffectError> {
        let origin = format!("--effect {flag}");
        let (name, rest) = flag.split_once(':').unwrap_or((flag, ""));
        let kind = known_kind(name.trim(), &origin)?;
        let mut values = self.values(kind).unwrap_or_else(|| kind.defaults());
        for assignment in rest.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (param, value) = assignment.split_once('=').ok_or_else(|| EffectError::Syntax {
                origin: origin.clone(),
                message: format!("`{assignment}` must be `parameter=value`"),
            })?;
            let index = param_index(kind, param.trim(), &origin)?;
            let spec = &kind.parameters()[index];
            values[index] = value.trim().parse::<f64>().map_err(|_| EffectError::BadValue {
                origin: origin.clone(),
                effect: kind.name(),
                name: spec.name,
                value: value.trim().to_string(),
                expected: format!("a number in {}", spec.unit),
            })?;
        }
        check_values(kind, &values, &origin)?;
        self.set(kind, &values)
    }
}

impl Effects {
    /// The effects of an optional TOML file (`file`, see
    /// [`Effects::from_toml_str`]) and then of command-line flags (`flags`,
    /// see [`Effects::apply_flag`]), which override the file's values.
    /// Errors name the file or flag, the parameter and the accepted range.
    pub fn from_file_and_flags(file: Option<&std::path::Path>, flags: &[String]) -> Result<Self, EffectError> {
        let mut effects = match file {
            None => Effects::none(),
            Some(path) => {
                let origin = path.display().to_string();
                let text = rig_config::read_text_file(path, rig_config::MAX_TEXT_FILE_BYTES).map_err(|e| {
                    EffectError::Syntax {
                        origin: origin.clone(),
                        message: format!("cannot read the effects file: {e}"),
                    }
                })?;
                Effects::from_toml_str(&text, &origin)?
            }
        };
        for flag in flags {
            effects.apply_flag(flag)?;
        }
        Ok(effects)
    }

    /// The effects on with their values, for reports and recordings:
    /// `nominal plant (no effect)` or `effects: name(param=value, ...), ...`.
    pub fn summary(&self) -> String {
        let on = self.enabled();
        if on.is_empty() {
            return "nominal plant (no effect)".to_string();
        }
        let parts: Vec<String> = on
            .iter()
            .map(|&kind| {
                let values = self.values(kind).unwrap_or_default();
                let params: Vec<String> =
                    kind.parameters().iter().zip(&values).map(|(spec, v)| format!("{}={v}", spec.name)).collect();
                format!("{}({})", kind.name(), params.join(", "))
            })
            .collect();
        format!("effects: {}", parts.join(", "))
    }

    /// These effects restricted to those a free decay has
    /// (`tension_stiffening`, `car_frame_mode`, `coulomb_guide_friction`,
    /// see `free_decay::simulate_free_decay_with`).
    pub fn for_free_decay(&self) -> Self {
        Self {
            tension_stiffening: self.tension_stiffening,
            car_frame_mode: self.car_frame_mode,
            coulomb_guide_friction: self.coulomb_guide_friction,
            ..Self::none()
        }
    }
}

fn known_kind(name: &str, origin: &str) -> Result<EffectKind, EffectError> {
    EffectKind::from_name(name).ok_or_else(|| EffectError::UnknownEffect {
        origin: origin.to_string(),
        name: name.to_string(),
        known: EffectKind::ALL.map(EffectKind::name).join(", "),
    })
}

fn param_index(kind: EffectKind, param: &str, origin: &str) -> Result<usize, EffectError> {
    kind.parameters().iter().position(|s| s.name == param).ok_or_else(|| EffectError::UnknownParameter {
        origin: origin.to_string(),
        effect: kind.name(),
        name: param.to_string(),
        known: kind.parameters().iter().map(|s| s.name).collect::<Vec<_>>().join(", "),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_effect_round_trips_its_defaults() {
        for kind in EffectKind::ALL {
            let mut e = Effects::none();
            e.set(kind, &kind.defaults()).unwrap();
            assert_eq!(e.values(kind), Some(kind.defaults()), "{}", kind.name());
            assert_eq!(e.enabled(), vec![kind]);
            e.clear(kind);
            assert!(e.is_nominal());
        }
    }

    #[test]
    fn toml_and_flags_name_what_is_wrong() {
        let e =
            Effects::from_toml_str("[dead_time]\ndead_time_s = 2e-6\n[rope_discretization]\nelements = 3\n", "x.toml")
                .unwrap();
        assert_eq!(e.dead_time.unwrap().dead_time_s, 2e-6);
        assert_eq!(e.rope_discretization.unwrap().elements, 3);
        let err = Effects::from_toml_str("[dead_tme]\n", "x.toml").unwrap_err().to_string();
        assert!(err.contains("x.toml") && err.contains("dead_tme"), "{err}");
        let err = Effects::from_toml_str("[rope_discretization]\nelements = 2.5\n", "x.toml").unwrap_err().to_string();
        assert!(err.contains("rope_discretization.elements") && err.contains("whole number"), "{err}");
        let mut f = Effects::none();
        f.apply_flag("car_frame_mode:frequency_hz=200").unwrap();
        assert_eq!(f.car_frame_mode.unwrap().frequency_hz, 200.0);
        let err = f.apply_flag("car_frame_mode:freq=200").unwrap_err().to_string();
        assert!(err.contains("freq") && err.contains("frequency_hz"), "{err}");
        let err = f.apply_flag("dead_time:dead_time_s=abc").unwrap_err().to_string();
        assert!(err.contains("abc"), "{err}");
    }

    #[test]
    fn files_and_flags_combine_and_errors_name_their_origin() {
        let dir = std::env::temp_dir().join(format!("effects-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("e.toml");
        std::fs::write(&path, "[brake_stop]\nclamp_stiffness_nm_per_rad = 5e4\n").unwrap();
        let e = Effects::from_file_and_flags(Some(&path), &["encoder_error:eccentricity_rad=0.001".into()]).unwrap();
        assert_eq!(e.brake_stop.unwrap().clamp_stiffness_nm_per_rad, 5e4);
        assert_eq!(e.encoder_error.unwrap().eccentricity_rad, 0.001);
        let summary = e.summary();
        assert!(summary.contains("brake_stop(clamp_stiffness_nm_per_rad=50000"), "{summary}");
        assert!(summary.contains("encoder_error(eccentricity_rad=0.001"), "{summary}");
        assert_eq!(Effects::none().summary(), "nominal plant (no effect)");
        let err = Effects::from_file_and_flags(Some(&dir.join("missing.toml")), &[]).unwrap_err().to_string();
        assert!(err.contains("missing.toml"), "{err}");
        let err = Effects::from_file_and_flags(None, &["brake_stop:clamp_stiffness_nm_per_rad=-1".into()])
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("--effect") && err.contains("clamp_stiffness_nm_per_rad") && err.contains("[1000"),
            "{err}"
        );
        std::fs::remove_dir_all(&dir).ok();
        let d = e.for_free_decay();
        assert!(d.is_nominal());
    }
}
