//! Named parameters of the parts of a foreign rig: one table per part with
//! units, defaults, accepted ranges and how [`random`](crate::foreign::ForeignDrive::random)
//! draws them, generated with the part's struct by `foreign_params!`.

use rand::Rng;

/// How a parameter is checked and drawn at random.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ParamKind {
    /// A real number in `[min, max]`, drawn uniformly.
    Real,
    /// A whole number in `[min, max]`, drawn uniformly.
    Integer,
    /// A switch, 0 (off) or 1 (on); drawn on with probability `p_on`.
    Switch {
        /// Probability of drawing "on", dimensionless.
        p_on: f64,
    },
    /// A real number in `[min, max]`, drawn from the listed values.
    Choice(&'static [f64]),
    /// A whole number in `[min, max]`, drawn from the listed values.
    IntegerChoice(&'static [f64]),
    /// A real number in `[min, max]` that random draws leave at its default.
    Fixed,
    /// Checked and drawn as the kind it holds, but after every other
    /// parameter of its part: a parameter whose random draw was added later,
    /// so that the values drawn before it for a given seed stay what they were.
    DrawnLast(&'static ParamKind),
}

impl ParamKind {
    /// The kind that checks and draws the value: the held kind of
    /// [`ParamKind::DrawnLast`], else this one.
    pub fn resolved(self) -> ParamKind {
        match self {
            ParamKind::DrawnLast(kind) => kind.resolved(),
            kind => kind,
        }
    }

    /// Whether random draws take this parameter after the others of its part.
    pub fn drawn_last(self) -> bool {
        matches!(self, ParamKind::DrawnLast(_))
    }
}

/// One named parameter of a foreign rig part.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamInfo {
    /// Name, with its unit as suffix (`_hz`, `_s`, `_pct`, ...).
    pub name: &'static str,
    /// Unit, as text (`"-"` when dimensionless or a switch).
    pub unit: &'static str,
    /// Default value (switches: 0 off, 1 on).
    pub default: f64,
    /// Smallest accepted value.
    pub min: f64,
    /// Largest accepted value.
    pub max: f64,
    /// How it is checked and drawn.
    pub kind: ParamKind,
    /// What it is.
    pub doc: &'static str,
}

impl ParamInfo {
    /// `Ok` when [`ParamInfo::accepts`] `value`, else the error that names
    /// the part (`drive` or `acquisition`), the parameter and its range.
    pub fn check(&self, part: &'static str, value: f64) -> Result<(), ParamError> {
        if self.accepts(value) {
            Ok(())
        } else {
            Err(ParamError::OutOfRange { part, name: self.name, value, expected: self.expected() })
        }
    }

    /// Whether `value` is accepted: finite, in `[min, max]`, a whole number
    /// for [`ParamKind::Integer`], 0 or 1 for [`ParamKind::Switch`].
    pub fn accepts(&self, value: f64) -> bool {
        let in_range = value.is_finite() && value >= self.min && value <= self.max;
        match self.kind.resolved() {
            ParamKind::Integer | ParamKind::IntegerChoice(_) => in_range && value.fract() == 0.0,
            ParamKind::Switch { .. } => value == 0.0 || value == 1.0,
            _ => in_range,
        }
    }

    /// What an accepted value looks like, for error messages and help.
    pub fn expected(&self) -> String {
        match self.kind.resolved() {
            ParamKind::Switch { .. } => "0 (off) or 1 (on)".to_string(),
            ParamKind::Integer | ParamKind::IntegerChoice(_) => {
                format!("a whole number in [{}, {}]", self.min, self.max)
            }
            _ => format!("a value in [{}, {}] {}", self.min, self.max, self.unit),
        }
    }

    /// A value drawn at random as [`ParamKind`] says.
    pub fn draw<R: Rng + ?Sized>(&self, rng: &mut R) -> f64 {
        match self.kind.resolved() {
            ParamKind::Real => rng.gen_range(self.min..=self.max),
            ParamKind::Integer => rng.gen_range(self.min as i64..=self.max as i64) as f64,
            ParamKind::Switch { p_on } => f64::from(u8::from(rng.gen_bool(p_on))),
            ParamKind::Choice(values) | ParamKind::IntegerChoice(values) => values[rng.gen_range(0..values.len())],
            ParamKind::Fixed | ParamKind::DrawnLast(_) => self.default,
        }
    }

    /// One line of help: `name = default (unit; range): doc`.
    pub fn help_line(&self) -> String {
        let range = match self.kind.resolved() {
            ParamKind::Switch { .. } => "0 off / 1 on".to_string(),
            _ => format!("{}..{} {}", self.min, self.max, self.unit),
        };
        format!("  {} = {}  ({range}): {}", self.name, self.default, self.doc)
    }
}

/// Why parameters of a foreign rig are refused.
#[derive(Debug, thiserror::Error)]
pub enum ParamError {
    /// No parameter of that name.
    #[error("{part}: no parameter `{name}`; the parameters are: {known}")]
    Unknown {
        /// The part (`drive` or `acquisition`).
        part: &'static str,
        /// The name given.
        name: String,
        /// The names there are.
        known: String,
    },
    /// A value out of its range.
    #[error("{part}: `{name}` = {value}: expected {expected}")]
    OutOfRange {
        /// The part (`drive` or `acquisition`).
        part: &'static str,
        /// Parameter.
        name: &'static str,
        /// The value given.
        value: f64,
        /// Accepted values.
        expected: String,
    },
    /// A foreign-rig file that cannot be read.
    #[error("{origin}: {message}")]
    File {
        /// Where it was read.
        origin: String,
        /// What is wrong.
        message: String,
    },
    /// A `name=value` assignment that cannot be read.
    #[error("{part}: cannot read `{text}`: expected `name=value` with a number (switches: 0 or 1)")]
    Syntax {
        /// The part (`drive` or `acquisition`).
        part: &'static str,
        /// The text given.
        text: String,
    },
}

/// A parameter's value type: `f64`, or `bool` for switches.
pub trait ParamValue: Copy {
    /// The value as a number (switches: 0 or 1).
    fn to_f64(self) -> f64;
    /// The value of a number already checked by [`ParamInfo::accepts`].
    fn from_f64(value: f64) -> Self;
}

impl ParamValue for f64 {
    fn to_f64(self) -> f64 {
        self
    }
    fn from_f64(value: f64) -> Self {
        value
    }
}

impl ParamValue for bool {
    fn to_f64(self) -> f64 {
        f64::from(u8::from(self))
    }
    fn from_f64(value: f64) -> Self {
        value != 0.0
    }
}

/// Splits `name=value` into its parts, for [`ParamError::Syntax`] naming `part`.
pub fn parse_assignment(part: &'static str, text: &str) -> Result<(String, f64), ParamError> {
    let syntax = || ParamError::Syntax { part, text: text.to_string() };
    let (name, value) = text.split_once('=').ok_or_else(syntax)?;
    let value: f64 = match value.trim() {
        "on" | "true" => 1.0,
        "off" | "false" => 0.0,
        v => v.parse().map_err(|_| syntax())?,
    };
    Ok((name.trim().to_string(), value))
}

/// Defines a parameter struct of a foreign rig part: its fields with their
/// docs, and `PARAMS`, `Default`, `get`, `set`, `set_from`, `validate`,
/// `random` and `summary` from one list of
/// `field: type = default, [min, max], "unit", kind;`.
macro_rules! foreign_params {
    (
        $(#[$meta:meta])*
        pub struct $name:ident in $part:literal {
            $(
                #[doc = $doc:literal]
                $field:ident : $ty:ty = $default:literal, [$min:literal, $max:literal], $unit:literal, $kind:expr;
            )*
        }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, PartialEq)]
        pub struct $name {
            $(
                #[doc = $doc]
                #[doc = concat!("\n\nUnit: ", $unit, "; default ", stringify!($default), "; range [",
                    stringify!($min), ", ", stringify!($max), "].")]
                pub $field: $ty,
            )*
        }

        impl Default for $name {
            fn default() -> Self {
                Self { $($field: <$ty as $crate::foreign::params::ParamValue>::from_f64($default),)* }
            }
        }

        impl $name {
            /// Every parameter: name, unit, default, range, how it is drawn, what it is.
            pub const PARAMS: &'static [$crate::foreign::params::ParamInfo] = &[
                $($crate::foreign::params::ParamInfo {
                    name: stringify!($field),
                    unit: $unit,
                    default: $default,
                    min: $min,
                    max: $max,
                    kind: $kind,
                    doc: $doc.trim_ascii(),
                },)*
            ];

            /// The value of parameter `name` (switches: 0 or 1), if there is one.
            pub fn get(&self, name: &str) -> Option<f64> {
                match name {
                    $(stringify!($field) => Some($crate::foreign::params::ParamValue::to_f64(self.$field)),)*
                    _ => None,
                }
            }

            /// Sets parameter `name` to `value` after checking it against its range.
            ///
            /// # Errors
            /// [`ParamError::Unknown`](crate::foreign::ParamError::Unknown) for a name
            /// that is not in [`Self::PARAMS`],
            /// [`ParamError::OutOfRange`](crate::foreign::ParamError::OutOfRange) for
            /// a value outside the range.
            pub fn set(&mut self, name: &str, value: f64) -> Result<(), $crate::foreign::params::ParamError> {
                let info = Self::PARAMS.iter().find(|p| p.name == name).ok_or_else(|| {
                    $crate::foreign::params::ParamError::Unknown {
                        part: $part,
                        name: name.to_string(),
                        known: Self::PARAMS.iter().map(|p| p.name).collect::<Vec<_>>().join(", "),
                    }
                })?;
                info.check($part, value)?;
                match name {
                    $(stringify!($field) => {
                        self.$field = <$ty as $crate::foreign::params::ParamValue>::from_f64(value)
                    })*
                    _ => {}
                }
                Ok(())
            }

            /// Applies `name=value` assignments in order ([`Self::set`]).
            ///
            /// # Errors
            /// Those of [`Self::set`], and
            /// [`ParamError::Syntax`](crate::foreign::ParamError::Syntax) for text
            /// that is not `name=value`.
            pub fn set_from<S: AsRef<str>>(&mut self, assignments: &[S]) -> Result<(), $crate::foreign::params::ParamError> {
                for text in assignments {
                    let (name, value) = $crate::foreign::params::parse_assignment($part, text.as_ref())?;
                    self.set(&name, value)?;
                }
                Ok(())
            }

            /// Checks every parameter against its range (fields are public).
            ///
            /// # Errors
            /// [`ParamError::OutOfRange`](crate::foreign::ParamError::OutOfRange) naming
            /// the first parameter out of its range.
            pub fn validate(&self) -> Result<(), $crate::foreign::params::ParamError> {
                for info in Self::PARAMS {
                    info.check($part, self.get(info.name).unwrap_or(f64::NAN))?;
                }
                Ok(())
            }

            /// A plausible set drawn at random within the ranges ([`ParamKind`](crate::foreign::ParamKind)
            /// says how each is drawn): in the order of [`Self::PARAMS`], those
            /// [`drawn last`](crate::foreign::ParamKind::DrawnLast) after all the others.
            pub fn random<R: rand::Rng + ?Sized>(rng: &mut R) -> Self {
                let mut out = Self::default();
                let first = Self::PARAMS.iter().filter(|p| !p.kind.drawn_last());
                for info in first.chain(Self::PARAMS.iter().filter(|p| p.kind.drawn_last())) {
                    let value = info.draw(rng);
                    // Every drawn value lies in its range.
                    let _ = out.set(info.name, value);
                }
                out
            }

            /// `name=value, ...` of every parameter.
            pub fn summary(&self) -> String {
                Self::PARAMS
                    .iter()
                    .map(|p| format!("{}={}", p.name, self.get(p.name).unwrap_or(f64::NAN)))
                    .collect::<Vec<_>>()
                    .join(", ")
            }

            /// Help text: one line per parameter with its default, range and unit.
            pub fn help() -> String {
                Self::PARAMS.iter().map(|p| p.help_line()).collect::<Vec<_>>().join("\n")
            }
        }
    };
}

pub(crate) use foreign_params;
