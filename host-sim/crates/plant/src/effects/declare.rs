//! What an effect of the library declares about itself ([`Effect`]): its
//! name, its parameters with units and ranges, where each one makes the
//! effect vanish, how the gap diagnosis fits it and where it can be seen.
//! The plant, the dataset command and the diagnosis read these
//! declarations; none of them keeps a table of its own per effect.

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

/// Where an effect's parameter makes the effect vanish.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Neutral {
    /// At this value (a friction of 0 N, an inertia of 0, one rope element).
    At(f64),
    /// Beyond the parameter's largest value (a frame mode's frequency or
    /// damping: the mode leaves the band or dies out).
    AboveRange,
    /// The parameter is not a strength (a phase, a damping ratio).
    NotAStrength,
}

/// A value the diagnosis measures on the recordings and gives a parameter
/// that is not fitted, instead of its default.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FromData {
    /// The static rope tension the free decays show, N.
    StaticRopeTension,
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
    /// the value the diagnosis derives from the data, [`ParamSpec::from_data`]).
    pub fitted: bool,
    /// Where the effect vanishes along it: zero unless declared otherwise
    /// ([`ParamSpec::neutral_at`]); a phase is not a strength.
    pub neutral: Neutral,
    /// The value the diagnosis measures for it, when not fitted.
    pub from_data: Option<FromData>,
    /// What it is.
    pub doc: &'static str,
}

impl ParamSpec {
    /// A parameter named `name` (unit `unit`) with its `default`, accepted
    /// range `[min, max]`, search `scale`, whether the diagnosis fits it
    /// and what it is (`doc`); it vanishes at zero (a phase: not a
    /// strength) and takes no value from the data.
    #[allow(clippy::too_many_arguments)]
    pub const fn new(
        name: &'static str,
        unit: &'static str,
        default: f64,
        min: f64,
        max: f64,
        scale: ParamScale,
        fitted: bool,
        doc: &'static str,
    ) -> Self {
        let neutral = match scale {
            ParamScale::Angle => Neutral::NotAStrength,
            _ => Neutral::At(0.0),
        };
        Self { name, unit, default, min, max, scale, fitted, neutral, from_data: None, doc }
    }

    /// The same parameter, the effect vanishing as `neutral` says.
    pub const fn neutral_at(self, neutral: Neutral) -> Self {
        Self { neutral, ..self }
    }

    /// The same parameter, given the value the diagnosis measures as
    /// `source` when it has one.
    pub const fn from_data(self, source: FromData) -> Self {
        Self { from_data: Some(source), ..self }
    }
}

/// How the gap diagnosis fits an effect's fitted parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Fit {
    /// The model is simulated at every combination of these values of the
    /// fitted parameters (`(parameter index, values)`, the first
    /// outermost), the others at their defaults; the best point is refined
    /// between its neighbours. `screened`: the first parameter (index 0,
    /// the first axis) sets a natural frequency, and a dense line over its
    /// whole range finds where it is worth fitting before the grid runs.
    Grid {
        /// Each fitted parameter's values.
        axes: &'static [(usize, &'static [f64])],
        /// Whether a dense line over the first axis's range is run first.
        screened: bool,
    },
    /// The recordings change linearly with each of these strengths
    /// (`(parameter index, probe value)`): each is simulated alone at its
    /// probe (the other fitted parameters at their neutral value, the rest
    /// at their defaults) and the changes are combined by least squares,
    /// each coefficient kept within the parameter's range.
    Linear(&'static [(usize, f64)]),
    /// An amplitude and its phase (`r = a cos(theta + phase)` and alike):
    /// simulated at amplitude `probe` with phase 0 and a quarter turn, the
    /// two changes combined by least squares into amplitude and phase.
    Polar {
        /// Index of the amplitude parameter.
        amplitude: usize,
        /// Index of the phase parameter, rad.
        phase: usize,
        /// Amplitude of the two probes.
        probe: f64,
    },
}

/// Where an effect can be seen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Seen {
    /// In a free decay (rope and car ringing with the drive idle): the
    /// free-decay model has the effect.
    pub in_free_decay: bool,
    /// In a travel under a drive other than the project's: the diagnosis's
    /// torque-driven model, driven by the recorded currents, can hold it
    /// (not an error the recorded currents carry themselves, not an effect
    /// of the stop, which another drive's start and stop do not show alike).
    pub under_another_drive: bool,
}

/// What an effect of the library is and declares: implemented by each
/// effect's own file, listed once in [`crate::effects`]. Its physics are
/// its own methods, called where the plant needs them.
pub trait Effect: Copy + std::fmt::Debug + PartialEq {
    /// Name in files, flags and reports.
    const NAME: &'static str;
    /// Its parameters, in the order of [`Effect::from_values`].
    const PARAMETERS: &'static [ParamSpec];
    /// How the gap diagnosis fits it.
    const FIT: Fit;
    /// Where it can be seen.
    const SEEN: Seen;
    /// The effect with parameter values `v` (in [`Effect::PARAMETERS`]
    /// order, checked against their ranges).
    fn from_values(v: &[f64]) -> Self;
    /// Its parameter values, in [`Effect::PARAMETERS`] order.
    fn values(&self) -> Vec<f64>;

    // The physics hooks: what the plant asks of every effect that is on,
    // in the list's order. The defaults leave the nominal plant as it is;
    // an effect overrides those where it acts. Effects that change the
    // line's layout or springs (rope elements, the pulley, the frame mode,
    // the stiffening rope), the sheave's geometry, the brake or the
    // inverter are built into the line and the inverter instead
    // (`plant/src/line.rs`, `plant/src/lib.rs`).

    /// Whether the effect puts a force on the car and the counterweight at
    /// their guides ([`Effect::guide_force_n`]); the plant leaves its fast
    /// nominal path when one does.
    const AT_GUIDES: bool = false;

    /// The force (N) at a guide whose body moves at `velocity_mps` (m/s,
    /// the force in the same coordinate).
    fn guide_force_n(&self, _velocity_mps: f64) -> f64 {
        0.0
    }

    /// Largest slope `|dF/dv| / m` (1/s) of [`Effect::guide_force_n`] on a
    /// body of `mass_kg` (kg): the rate an explicit integrator's step must
    /// resolve.
    fn guide_force_rate_per_s(&self, _mass_kg: f64) -> f64 {
        0.0
    }

    /// The phase currents (A) the drive's transducers read when
    /// `currents_a` (A) flow.
    fn measured_currents_a(&self, currents_a: [f64; 3]) -> [f64; 3] {
        currents_a
    }

    /// The shaft angle (rad) the encoder reads at the true angle
    /// `angle_rad` (rad).
    fn measured_angle_rad(&self, angle_rad: f64) -> f64 {
        angle_rad
    }
}
