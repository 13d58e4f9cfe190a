//! The full plant's library of unmodelled effects: each a file that
//! declares everything about it ([`Effect`]: name, parameters with units
//! and ranges, how the gap diagnosis fits it, where it can be seen) beside
//! its physics, switched on in any combination through [`Effects`] (a TOML
//! file, `[name] parameter = value`, or `--effect name:param=value`
//! flags). With every effect off the plant is the paper's nominal model.
//!
//! The library is the one list in [`library!`]'s invocation below: adding
//! an effect is its file and one line there (docs/model.md, "Adding an
//! effect"). The values of one effect travel as a slice in the order of its
//! parameters ([`Effects::set`], [`Effects::values`]).

pub mod declare;

pub use declare::{Effect, Fit, FromData, Neutral, ParamScale, ParamSpec, Seen};

/// Builds the library from its list, `module::Type,` per effect (the
/// module is the effect's file and its field in [`Effects`]): the
/// [`EffectKind`] of each, [`EffectKind::ALL`] in list order, the
/// [`Effects`] set, and every per-effect dispatch, read from the effects'
/// [`Effect`] declarations.
macro_rules! library {
    ($($module:ident :: $ty:ident),* $(,)?) => {
        $(pub mod $module;)*
        $(pub use $module::$ty;)*

        /// One effect of the library.
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum EffectKind {
            $(
                #[doc = concat!("[`", stringify!($ty), "`]")]
                $ty,
            )*
        }

        const EFFECT_COUNT: usize = [$(stringify!($ty)),*].len();

        impl EffectKind {
            /// Every effect of the library, in the list's order.
            pub const ALL: [EffectKind; EFFECT_COUNT] = [$(EffectKind::$ty),*];

            /// The effect's name in files, flags and reports ([`Effect::NAME`]).
            pub fn name(self) -> &'static str {
                match self {
                    $(EffectKind::$ty => <$ty as Effect>::NAME,)*
                }
            }

            /// Its parameters, in the order of [`Effects::set`] ([`Effect::PARAMETERS`]).
            pub fn parameters(self) -> &'static [ParamSpec] {
                match self {
                    $(EffectKind::$ty => <$ty as Effect>::PARAMETERS,)*
                }
            }

            /// How the gap diagnosis fits it ([`Effect::FIT`]).
            pub fn fit(self) -> Fit {
                match self {
                    $(EffectKind::$ty => <$ty as Effect>::FIT,)*
                }
            }

            /// Where it can be seen ([`Effect::SEEN`]).
            pub fn seen(self) -> Seen {
                match self {
                    $(EffectKind::$ty => <$ty as Effect>::SEEN,)*
                }
            }
        }

        /// Which effects the plant has, with their parameters (all off: the
        /// nominal plant).
        #[derive(Clone, Copy, Debug, Default, PartialEq)]
        pub struct Effects {
            $(
                #[doc = concat!("[`", stringify!($ty), "`], when on.")]
                pub $module: Option<$ty>,
            )*
        }

        impl Effects {
            /// Switches `kind` on with `values` (in [`EffectKind::parameters`]
            /// order), checked against their ranges.
            pub fn set(&mut self, kind: EffectKind, values: &[f64]) -> Result<(), EffectError> {
                check_values(kind, values, "effect parameters")?;
                match kind {
                    $(EffectKind::$ty => self.$module = Some(<$ty as Effect>::from_values(values)),)*
                }
                Ok(())
            }

            /// Switches `kind` off.
            pub fn clear(&mut self, kind: EffectKind) {
                match kind {
                    $(EffectKind::$ty => self.$module = None,)*
                }
            }

            /// The parameter values of `kind` (in [`EffectKind::parameters`]
            /// order) when it is on.
            pub fn values(&self, kind: EffectKind) -> Option<Vec<f64>> {
                match kind {
                    $(EffectKind::$ty => self.$module.as_ref().map(Effect::values),)*
                }
            }

            /// Whether an effect that is on acts at the guides
            /// ([`Effect::AT_GUIDES`]).
            pub fn acts_at_guides(&self) -> bool {
                false $(|| (<$ty as Effect>::AT_GUIDES && self.$module.is_some()))*
            }

            /// The force (N) at a guide whose body moves at `velocity_mps`
            /// (m/s): the sum of the effects' that act there
            /// ([`Effect::guide_force_n`]).
            pub fn guide_force_n(&self, velocity_mps: f64) -> f64 {
                let mut force = 0.0;
                $(
                    if let (true, Some(e)) = (<$ty as Effect>::AT_GUIDES, &self.$module) {
                        force += e.guide_force_n(velocity_mps);
                    }
                )*
                force
            }

            /// The largest rate (1/s) of the guide forces on a body of
            /// `mass_kg` ([`Effect::guide_force_rate_per_s`]).
            pub fn guide_force_rate_per_s(&self, mass_kg: f64) -> f64 {
                let mut rate = 0.0f64;
                $(
                    if let (true, Some(e)) = (<$ty as Effect>::AT_GUIDES, &self.$module) {
                        rate = rate.max(e.guide_force_rate_per_s(mass_kg));
                    }
                )*
                rate
            }

            /// The phase currents (A) the drive's transducers read when
            /// `currents_a` flow, through every effect that is on
            /// ([`Effect::measured_currents_a`]).
            pub fn measured_currents_a(&self, currents_a: [f64; 3]) -> [f64; 3] {
                let mut out = currents_a;
                $(
                    if let Some(e) = &self.$module {
                        out = e.measured_currents_a(out);
                    }
                )*
                out
            }

            /// The shaft angle (rad) the encoder reads at `angle_rad`,
            /// through every effect that is on ([`Effect::measured_angle_rad`]).
            pub fn measured_angle_rad(&self, angle_rad: f64) -> f64 {
                let mut out = angle_rad;
                $(
                    if let Some(e) = &self.$module {
                        out = e.measured_angle_rad(out);
                    }
                )*
                out
            }
        }
    };
}

// The library: one line per effect.
library! {
    tension_stiffening::TensionStiffening,
    diverting_pulley::DivertingPulley,
    rope_discretization::RopeDiscretization,
    car_frame_mode::CarFrameMode,
    coulomb_guide_friction::CoulombGuideFriction,
    brake_stop::BrakeStop,
    sheave_eccentricity::SheaveEccentricity,
    dead_time::DeadTime,
    current_sensor_error::CurrentSensorError,
    encoder_error::EncoderError,
}

impl EffectKind {
    /// The effect named `name`, if any.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == name)
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
    /// ([`Seen::in_free_decay`]; see `free_decay::simulate_free_decay_with`).
    pub fn for_free_decay(&self) -> Self {
        let mut out = *self;
        for kind in EffectKind::ALL.into_iter().filter(|k| !k.seen().in_free_decay) {
            out.clear(kind);
        }
        out
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
