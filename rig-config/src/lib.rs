//! The rig description: `configs/rig.toml` (the project's copy of the
//! reference rig of the seed paper, embedded as the default of every
//! command), its validation, and the drive parameters derived from it.
//!
//! Every value is SI unless its name says otherwise. A value out of its
//! physical range is refused with the file, the `[section].field` and the
//! accepted range; so is a field the format does not know (a misspelt
//! optional field would otherwise leave its default in force), an empty car
//! list, and a file larger than [`MAX_TEXT_FILE_BYTES`].

#![warn(missing_docs)]

use std::path::Path;

pub mod board;

use drive_core::DriveConfig;
use serde::Deserialize;

/// The embedded default rig file (`configs/rig.toml`).
pub const EMBEDDED_RIG_TOML: &str = include_str!("../../configs/rig.toml");
/// Name used in error messages for the embedded rig file.
pub const EMBEDDED_RIG_NAME: &str = "configs/rig.toml (embedded)";

/// Largest text input file read whole (a rig file, an effects, faults or
/// foreign-rig file, a recording's metadata), bytes: 1 MiB, some hundred
/// times a real one (the reference rig file is under 4 kB).
pub const MAX_TEXT_FILE_BYTES: u64 = 1 << 20;

/// Reads the text file `path`, refusing one larger than `max_bytes` before
/// reading it whole (the size of a regular file is checked first; for a
/// pipe or device at most `max_bytes + 1` bytes are read).
///
/// # Errors
/// The I/O error; [`std::io::ErrorKind::FileTooLarge`] with the limit in
/// its message for a file over `max_bytes`; [`std::io::ErrorKind::InvalidData`]
/// for text that is not UTF-8.
pub fn read_text_file(path: &Path, max_bytes: u64) -> std::io::Result<String> {
    use std::io::Read;
    let too_large = || {
        std::io::Error::new(
            std::io::ErrorKind::FileTooLarge,
            format!("the file is larger than {max_bytes} bytes, the limit for this input"),
        )
    };
    let file = std::fs::File::open(path)?;
    if file.metadata()?.len() > max_bytes {
        return Err(too_large());
    }
    let mut bytes = Vec::new();
    file.take(max_bytes.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max_bytes {
        return Err(too_large());
    }
    String::from_utf8(bytes)
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, format!("not UTF-8 text: {e}")))
}

/// Errors loading or validating a rig file.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// File path.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// TOML syntax error, missing field or wrong type (the message has line and column).
    #[error("{path}: {message}")]
    Parse {
        /// File path.
        path: String,
        /// Parser message, with line and column.
        message: String,
    },
    /// A field that holds no usable value (e.g. an empty list).
    #[error("{path}: field `{field}` {found}: expected {expected}")]
    Invalid {
        /// File path.
        path: String,
        /// `[section].field`.
        field: String,
        /// What the field holds, in words.
        found: String,
        /// What is accepted, in words.
        expected: String,
    },
    /// A value outside its physical range.
    #[error("{path}: field `{field}` = {} is out of range: expected {expected}", readable(*value))]
    OutOfRange {
        /// File path.
        path: String,
        /// `[section].field`.
        field: String,
        /// Offending value.
        value: f64,
        /// Accepted range, in words.
        expected: String,
    },
}

/// `[mechanics]`: the 5-DOF model of the paper (Eqn 1-6, 10-13).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Mechanics {
    /// Counterweight mass `m_w`, kg.
    pub m_cw_kg: f64,
    /// Car masses of the tests, kg.
    pub m_car_kg: Vec<f64>,
    /// Total rope length `l_t = l_w + l_c`, m.
    pub rope_total_length_m: f64,
    /// Rope axial stiffness `EA`, N (Eqn 1-2, identified by Eqn 9).
    pub rope_ea_n: f64,
    /// Rope mass per length `mu`, kg/m.
    pub rope_mass_per_length_kg_per_m: f64,
    /// Machine rotor plus traction sheave inertia `I`, kg m^2.
    pub sheave_inertia_kg_m2: f64,
    /// Traction-sheave radius `r`, m.
    pub sheave_radius_m: f64,
    /// Gravitational acceleration, m/s^2.
    pub gravity_mps2: f64,
    /// Guide damping ratio `zeta` (Eqn 11), dimensionless.
    pub guide_damping_ratio: f64,
    /// Counterweight guide damping `c_w` (Eqn 12), kg/s.
    pub c_cw_kg_per_s: f64,
    /// Car guide damping `c_c` (Eqn 12), kg/s.
    pub c_car_kg_per_s: f64,
    /// Sheave rotational viscous damping `c_sh` (Eqn 13), N m s/rad.
    pub c_sheave_nms_per_rad: f64,
    /// First mode of the car frame (FE model), Hz.
    pub car_frame_first_mode_hz: f64,
    /// How each rope side's mass is lumped (only "all-at-midpoint").
    pub rope_lumping: String,
}

/// `[travel]`: the reference profile (paper Fig. 3).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Travel {
    /// Rated speed, m/s.
    pub rated_speed_mps: f64,
    /// Largest acceleration, m/s^2.
    pub max_accel_mps2: f64,
    /// Largest jerk, m/s^3.
    pub max_jerk_mps3: f64,
    /// Counterweight-side rope length at the bottom landing of the car, m.
    pub lw_low_m: f64,
    /// Counterweight-side rope length at the top landing of the car, m.
    pub lw_high_m: f64,
}

/// `[motor]`: PMSM in the dq frame.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Motor {
    /// Pole pairs `p` (Eqn 7).
    pub pole_pairs: u32,
    /// Stator resistance, ohm.
    pub stator_resistance_ohm: f64,
    /// d inductance, H.
    pub ld_h: f64,
    /// q inductance, H.
    pub lq_h: f64,
    /// Magnet flux linkage (peak, per phase), Wb.
    pub flux_linkage_wb: f64,
    /// Rated current (limit of the q-current reference), A.
    pub rated_current_a: f64,
    /// Over-current trip, A.
    pub overcurrent_trip_a: f64,
}

impl Motor {
    /// Torque per quadrature ampere at `i_d = 0`, `K_t = 1.5 p psi`, N m/A
    /// (the machine's torque, Eqn 7's frame).
    pub fn torque_constant_nm_per_a(&self) -> f64 {
        1.5 * f64::from(self.pole_pairs) * self.flux_linkage_wb
    }
}

/// `[inverter]`: power stage and sensors.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Inverter {
    /// DC-bus voltage, V.
    pub dc_bus_v: f64,
    /// PWM carrier frequency, Hz.
    pub pwm_hz: f64,
    /// Dead time, s.
    pub dead_time_s: f64,
    /// Phase-current sensing full scale (+-), A.
    pub current_sense_full_scale_a: f64,
    /// ADC resolution, bits.
    pub adc_bits: u32,
    /// Encoder counts per revolution (after quadrature).
    pub encoder_counts_per_rev: u32,
    /// DC-bus voltage at the top ADC code, V (assumed; default 200 V).
    #[serde(default = "default_dc_bus_sense_full_scale_v")]
    pub dc_bus_sense_full_scale_v: f64,
    /// PWM timer input clock, Hz (assumed; default 170 MHz, STM32G474 TIM1).
    #[serde(default = "default_pwm_timer_clock_hz")]
    pub pwm_timer_clock_hz: f64,
}

/// `[control]`: loop rates and bandwidths.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Control {
    /// Current-loop rate, Hz (one step per PWM period).
    pub current_loop_hz: f64,
    /// Speed-loop rate, Hz.
    pub speed_loop_hz: f64,
    /// Current-loop bandwidth, Hz (assumed; default 1000 Hz).
    #[serde(default = "default_current_bandwidth_hz")]
    pub current_loop_bandwidth_hz: f64,
    /// Speed-loop bandwidth, Hz (assumed; default 5 Hz).
    #[serde(default = "default_speed_bandwidth_hz")]
    pub speed_loop_bandwidth_hz: f64,
    /// Encoder speed-estimator natural frequency, Hz (assumed; default 25 Hz).
    #[serde(default = "default_estimator_bandwidth_hz")]
    pub speed_estimator_bandwidth_hz: f64,
    /// Over-speed trip as a multiple of rated speed (assumed; default 1.25).
    #[serde(default = "default_overspeed_factor")]
    pub overspeed_factor: f64,
    /// DC-bus under-voltage trip as a fraction of the nominal bus (assumed; default 0.7).
    #[serde(default = "default_undervoltage_fraction")]
    pub dc_bus_undervoltage_fraction: f64,
    /// DC-bus over-voltage trip as a fraction of the nominal bus (assumed; default 1.3).
    #[serde(default = "default_overvoltage_fraction")]
    pub dc_bus_overvoltage_fraction: f64,
    /// Largest plausible |i_a + i_b + i_c|, A (assumed; default 5 A).
    #[serde(default = "default_current_sum_limit_a")]
    pub current_sum_limit_a: f64,
}

/// One `[[ripple]]` component: an angle-locked shaft torque
/// `amplitude cos(order theta_m + phase)` (paper section 3.3).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Ripple {
    /// Source of the component.
    pub name: String,
    /// Harmonic order in mechanical revolutions (1, 6, 12, 36, 72).
    pub mechanical_order: u32,
    /// Torque amplitude, N m.
    pub amplitude_nm: f64,
    /// Phase, rad (the paper gives none; default 0).
    #[serde(default)]
    pub phase_rad: f64,
}

/// `[measurement]`: acquisition settings of the rig.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Measurement {
    /// Sample rate, Hz.
    pub sample_rate_hz: f64,
    /// High-pass cut-off applied before plotting, Hz.
    pub highpass_hz: f64,
    /// Spectrogram band, Hz.
    pub spectrogram_band_hz: [f64; 2],
}

/// The whole rig file.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RigConfig {
    /// `[mechanics]`.
    pub mechanics: Mechanics,
    /// `[travel]`.
    pub travel: Travel,
    /// `[motor]`.
    pub motor: Motor,
    /// `[inverter]`.
    pub inverter: Inverter,
    /// `[control]`.
    pub control: Control,
    /// `[[ripple]]`.
    #[serde(default)]
    pub ripple: Vec<Ripple>,
    /// `[measurement]`.
    pub measurement: Measurement,
}

fn default_dc_bus_sense_full_scale_v() -> f64 {
    200.0
}
fn default_pwm_timer_clock_hz() -> f64 {
    170.0e6
}
fn default_current_bandwidth_hz() -> f64 {
    1000.0
}
fn default_speed_bandwidth_hz() -> f64 {
    5.0
}
fn default_estimator_bandwidth_hz() -> f64 {
    25.0
}
fn default_overspeed_factor() -> f64 {
    1.25
}
fn default_undervoltage_fraction() -> f64 {
    0.7
}
fn default_overvoltage_fraction() -> f64 {
    1.3
}
fn default_current_sum_limit_a() -> f64 {
    5.0
}

/// `x` for a message: plain decimals for everyday magnitudes, scientific
/// notation for the very small and very large (never 300 zeros).
pub fn readable(x: f64) -> String {
    if x == 0.0 || !x.is_finite() || (1e-4..1e9).contains(&x.abs()) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// `message` with every number written digit by digit (the TOML parser
/// quotes `1e300` as 301 digits) rewritten by [`readable`].
pub fn readable_numbers(message: &str) -> String {
    let mut out = String::with_capacity(message.len());
    let mut rest = message;
    while let Some(start) = rest.find(|c: char| c.is_ascii_digit()) {
        out.push_str(&rest[..start]);
        let len = rest[start..].find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(rest.len() - start);
        let token = &rest[start..start + len];
        match token.parse::<f64>() {
            Ok(v) if token.len() > 20 => out.push_str(&readable(v)),
            _ => out.push_str(token),
        }
        rest = &rest[start + len..];
    }
    out.push_str(rest);
    out
}

/// Fastest rate of the rig's mechanics that a run accepts, rad/s (about
/// 160 kHz): the simulation steps at least once per `1 / omega` of the
/// fastest mode, so a faster one makes a 20 s travel take hours. The
/// reference rig's fastest, its shortest rope's elements, is about
/// 9200 rad/s.
pub const MAX_MECHANICAL_RATE_RADPS: f64 = 1.0e6;
/// Longest reference travel a rig may ask for, s: at the rig's sample rate
/// a longer one holds more samples than a run writes (and takes minutes to
/// simulate). The reference rig's travel takes about 19 s.
pub const MAX_TRAVEL_S: f64 = 600.0;
/// Shortest rope on either side of the sheave over the travel, m: a
/// shorter one rings too fast to simulate and leaves the sheave no room.
pub const MIN_ROPE_SIDE_M: f64 = 0.1;

/// The physical range of a field: `[lo, hi]` (or `(lo, hi]`), its unit and
/// why (for the message).
struct Bound<'w> {
    lo: f64,
    lo_open: bool,
    hi: f64,
    unit: &'static str,
    why: &'w str,
}

impl<'w> Bound<'w> {
    /// `[lo, hi]`.
    fn closed(lo: f64, hi: f64, unit: &'static str, why: &'w str) -> Self {
        Self { lo, lo_open: false, hi, unit, why }
    }

    /// `(lo, hi]`.
    fn above(lo: f64, hi: f64, unit: &'static str, why: &'w str) -> Self {
        Self { lo, lo_open: true, hi, unit, why }
    }
}

/// Range checker that names the file and field.
struct Checker<'a> {
    path: &'a str,
}

impl Checker<'_> {
    fn check(&self, field: &str, value: f64, b: Bound) -> Result<(), ConfigError> {
        let above = if b.lo_open { value > b.lo } else { value >= b.lo };
        if value.is_finite() && above && value <= b.hi {
            return Ok(());
        }
        let open = if b.lo_open { "(" } else { "[" };
        let unit = if b.unit.is_empty() { String::new() } else { format!(" {}", b.unit) };
        let why = if b.why.is_empty() { String::new() } else { format!(": {}", b.why) };
        Err(self.out_of_range(
            field,
            value,
            format!("a finite value in {open}{}, {}]{unit}{why}", readable(b.lo), readable(b.hi)),
        ))
    }

    /// [`Self::check`] of a field with a default (`default`): when the value
    /// refused is the default, the message says so (the file may never have
    /// given the field).
    fn check_defaulted(&self, field: &str, value: f64, default: f64, b: Bound) -> Result<(), ConfigError> {
        self.check(field, value, b).map_err(|e| match e {
            ConfigError::OutOfRange { path, field, value, expected } if value == default => ConfigError::OutOfRange {
                path,
                field,
                value,
                expected: format!(
                    "{expected} ({} is the field's default, in force when the file does not give it: give the field)",
                    readable(default)
                ),
            },
            e => e,
        })
    }

    fn out_of_range(&self, field: &str, value: f64, expected: String) -> ConfigError {
        ConfigError::OutOfRange { path: self.path.to_string(), field: field.to_string(), value, expected }
    }
}

impl RigConfig {
    /// Parses and validates rig TOML text; `origin` names it in errors.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let config: RigConfig = toml::from_str(text)
            .map_err(|e| ConfigError::Parse { path: origin.to_string(), message: readable_numbers(&e.to_string()) })?;
        config.validate(origin)?;
        Ok(config)
    }

    /// Reads, parses and validates a rig file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = read_text_file(path, MAX_TEXT_FILE_BYTES)
            .map_err(|source| ConfigError::Io { path: path.display().to_string(), source })?;
        Self::from_toml_str(&text, &path.display().to_string())
    }

    /// The embedded default rig (`configs/rig.toml`).
    pub fn embedded_default() -> Result<Self, ConfigError> {
        Self::from_toml_str(EMBEDDED_RIG_TOML, EMBEDDED_RIG_NAME)
    }

    /// Checks every value against its physical range, with the physical
    /// reason in the message; then the rig as a whole: its fastest
    /// mechanical rate ([`MAX_MECHANICAL_RATE_RADPS`]) and the length of
    /// its reference travel ([`MAX_TRAVEL_S`]), so that every run on an
    /// accepted rig finishes in bounded time and memory. `origin` names the
    /// file.
    pub fn validate(&self, origin: &str) -> Result<(), ConfigError> {
        let c = Checker { path: origin };
        self.validate_mechanics(&c)?;
        self.validate_travel(&c)?;
        self.validate_fastest_rate(&c)?;
        self.validate_motor_and_inverter(&c)?;
        self.validate_control(&c)?;
        self.validate_ripple_and_measurement(&c)
    }

    fn validate_mechanics(&self, c: &Checker) -> Result<(), ConfigError> {
        let m = &self.mechanics;
        const MASS: &str = "lighter than 1 kg, a mass rings on its rope so fast that a run never ends; \
                            no lift carries more than 100 t";
        c.check("[mechanics].m_cw_kg", m.m_cw_kg, Bound::closed(1.0, 1.0e5, "kg", MASS))?;
        if m.m_car_kg.is_empty() {
            return Err(ConfigError::Invalid {
                path: c.path.to_string(),
                field: "[mechanics].m_car_kg".to_string(),
                found: "is an empty list".to_string(),
                expected: "at least one car mass in kg, e.g. m_car_kg = [70.5] (the commands default to the \
                           heaviest)"
                    .to_string(),
            });
        }
        for (i, mass) in m.m_car_kg.iter().enumerate() {
            c.check(&format!("[mechanics].m_car_kg[{i}]"), *mass, Bound::closed(1.0, 1.0e5, "kg", MASS))?;
        }
        let length = "room for a travel (at least 1 m), no longer than any lift's hoist rope (1000 m)";
        c.check("[mechanics].rope_total_length_m", m.rope_total_length_m, Bound::closed(1.0, 1.0e3, "m", length))?;
        let ea = "from a thin synthetic cord to a thick steel rope";
        c.check("[mechanics].rope_ea_n", m.rope_ea_n, Bound::closed(1.0e4, 1.0e9, "N", ea))?;
        let mu = "from a 1 mm cord (about 0.001 kg/m) to a bundle of the heaviest steel ropes; \
                  a massless rope leaves its elements nothing to ring with";
        c.check(
            "[mechanics].rope_mass_per_length_kg_per_m",
            m.rope_mass_per_length_kg_per_m,
            Bound::closed(1.0e-3, 100.0, "kg/m", mu),
        )?;
        let inertia = "from a small machine's rotor (0.001 kg m^2) to the largest traction sheave";
        c.check(
            "[mechanics].sheave_inertia_kg_m2",
            m.sheave_inertia_kg_m2,
            Bound::closed(1.0e-3, 1.0e4, "kg m^2", inertia),
        )?;
        let radius = "a traction sheave of 1 cm to 2 m radius";
        c.check("[mechanics].sheave_radius_m", m.sheave_radius_m, Bound::closed(0.01, 2.0, "m", radius))?;
        let g = "the gravity of the Earth's surface, 9.78 m/s^2 at the equator to 9.83 m/s^2 at the poles";
        c.check("[mechanics].gravity_mps2", m.gravity_mps2, Bound::closed(9.7, 9.9, "m/s^2", g))?;
        let zeta = "a fraction of critical damping (1: critical; guides never damp more)";
        c.check("[mechanics].guide_damping_ratio", m.guide_damping_ratio, Bound::closed(0.0, 1.0, "", zeta))?;
        let guide = "never negative, and beyond the guides of any lift above 1e5 kg/s (the rig: 148 kg/s)";
        c.check("[mechanics].c_cw_kg_per_s", m.c_cw_kg_per_s, Bound::closed(0.0, 1.0e5, "kg/s", guide))?;
        c.check("[mechanics].c_car_kg_per_s", m.c_car_kg_per_s, Bound::closed(0.0, 1.0e5, "kg/s", guide))?;
        let sheave = "never negative, and beyond any machine's bearing and viscous loss above 1000 N m s/rad \
                      (the rig: 3 N m s/rad)";
        c.check(
            "[mechanics].c_sheave_nms_per_rad",
            m.c_sheave_nms_per_rad,
            Bound::closed(0.0, 1.0e3, "N m s/rad", sheave),
        )?;
        let frame = "a car frame's first mode (the rig: 235 Hz): below 1 Hz no frame stands, above 10 kHz no \
                     frame of a car rings";
        c.check(
            "[mechanics].car_frame_first_mode_hz",
            m.car_frame_first_mode_hz,
            Bound::closed(1.0, 1.0e4, "Hz", frame),
        )?;
        if m.rope_lumping != "all-at-midpoint" {
            return Err(ConfigError::Parse {
                path: c.path.to_string(),
                message: format!(
                    "field `[mechanics].rope_lumping` = {:?}: expected \"all-at-midpoint\"",
                    m.rope_lumping
                ),
            });
        }
        Ok(())
    }

    fn validate_travel(&self, c: &Checker) -> Result<(), ConfigError> {
        let (t, lt) = (&self.travel, self.mechanics.rope_total_length_m);
        let speed = "from the slowest lift (5 cm/s) to the fastest (about 20 m/s)";
        c.check("[travel].rated_speed_mps", t.rated_speed_mps, Bound::closed(0.05, 20.0, "m/s", speed))?;
        let accel = "from a crawl to 2 g, more than any lift's passengers bear";
        c.check("[travel].max_accel_mps2", t.max_accel_mps2, Bound::closed(0.05, 20.0, "m/s^2", accel))?;
        let jerk = "from a crawl to 100 m/s^3, more than any lift's drive commands";
        c.check("[travel].max_jerk_mps3", t.max_jerk_mps3, Bound::closed(0.05, 100.0, "m/s^3", jerk))?;
        let side = format!(
            "each rope side keeps at least {} m over the travel (a shorter one rings too fast to simulate), \
             of [mechanics].rope_total_length_m = {} m",
            readable(MIN_ROPE_SIDE_M),
            readable(lt)
        );
        let top = lt - MIN_ROPE_SIDE_M;
        c.check("[travel].lw_low_m", t.lw_low_m, Bound::closed(MIN_ROPE_SIDE_M, top, "m", &side))?;
        c.check(
            "[travel].lw_high_m",
            t.lw_high_m,
            Bound::above(t.lw_low_m, top, "m", &format!("above lw_low_m; {side}")),
        )?;
        let seconds = self.reference_travel_s();
        if seconds > MAX_TRAVEL_S {
            let distance = t.lw_high_m - t.lw_low_m;
            return Err(c.out_of_range(
                "[travel].rated_speed_mps",
                t.rated_speed_mps,
                format!(
                    "a travel of at most {} s: lw_low_m -> lw_high_m ({} m) at this speed, max_accel_mps2 and \
                     max_jerk_mps3 takes about {} s, which a run would simulate and record whole; a speed of at \
                     least {} m/s",
                    readable(MAX_TRAVEL_S),
                    readable(distance),
                    readable(seconds.round()),
                    readable((distance / (0.9 * MAX_TRAVEL_S)).max(0.05))
                ),
            ));
        }
        Ok(())
    }

    /// Duration of the reference travel from `lw_low_m` to `lw_high_m`, s:
    /// the cruise `d / v` plus the acceleration's `v / a + a / j` (an upper
    /// bound of the jerk-limited profile's).
    pub fn reference_travel_s(&self) -> f64 {
        let t = &self.travel;
        (t.lw_high_m - t.lw_low_m) / t.rated_speed_mps
            + t.rated_speed_mps / t.max_accel_mps2
            + t.max_accel_mps2 / t.max_jerk_mps3
    }

    /// The fastest rate of the rope-sheave chain over the travel, rad/s,
    /// and the field it comes from with the smallest value of that field
    /// that keeps it at [`MAX_MECHANICAL_RATE_RADPS`]: on the shortest rope
    /// side `l` (of the travel's range) with each side's mass at its
    /// midpoint, the rope's elements `sqrt(8 EA / (mu l^2))`, the sheave
    /// between its ropes `sqrt(8 EA r^2 / (I l))`, a hanging mass on its
    /// rope `sqrt(4 EA / (m l))`, and the damping rates `c / m`.
    pub fn fastest_mechanical_rate(&self) -> (f64, &'static str, f64) {
        let (m, t) = (&self.mechanics, &self.travel);
        let l = t.lw_low_m.min(m.rope_total_length_m - t.lw_high_m);
        let ea = m.rope_ea_n;
        let w2 = MAX_MECHANICAL_RATE_RADPS * MAX_MECHANICAL_RATE_RADPS;
        let r2 = m.sheave_radius_m * m.sheave_radius_m;
        let car = m.m_car_kg.iter().copied().fold(f64::INFINITY, f64::min);
        let w = MAX_MECHANICAL_RATE_RADPS;
        let rates = [
            (
                (8.0 * ea / (m.rope_mass_per_length_kg_per_m * l * l)).sqrt(),
                "[mechanics].rope_mass_per_length_kg_per_m",
                8.0 * ea / (l * l * w2),
            ),
            (
                (8.0 * ea * r2 / (m.sheave_inertia_kg_m2 * l)).sqrt(),
                "[mechanics].sheave_inertia_kg_m2",
                8.0 * ea * r2 / (l * w2),
            ),
            ((4.0 * ea / (m.m_cw_kg * l)).sqrt(), "[mechanics].m_cw_kg", 4.0 * ea / (l * w2)),
            ((4.0 * ea / (car * l)).sqrt(), "[mechanics].m_car_kg", 4.0 * ea / (l * w2)),
            (m.c_cw_kg_per_s / m.m_cw_kg, "[mechanics].m_cw_kg", m.c_cw_kg_per_s / w),
            (m.c_car_kg_per_s / car, "[mechanics].m_car_kg", m.c_car_kg_per_s / w),
            (
                m.c_sheave_nms_per_rad / m.sheave_inertia_kg_m2,
                "[mechanics].sheave_inertia_kg_m2",
                m.c_sheave_nms_per_rad / w,
            ),
        ];
        rates.into_iter().fold((0.0, "", 0.0), |a, b| if b.0 > a.0 { b } else { a })
    }

    fn validate_fastest_rate(&self, c: &Checker) -> Result<(), ConfigError> {
        let (rate, field, smallest) = self.fastest_mechanical_rate();
        if rate <= MAX_MECHANICAL_RATE_RADPS {
            return Ok(());
        }
        let m = &self.mechanics;
        let value = match field {
            "[mechanics].rope_mass_per_length_kg_per_m" => m.rope_mass_per_length_kg_per_m,
            "[mechanics].sheave_inertia_kg_m2" => m.sheave_inertia_kg_m2,
            "[mechanics].m_cw_kg" => m.m_cw_kg,
            _ => m.m_car_kg.iter().copied().fold(f64::INFINITY, f64::min),
        };
        let t = &self.travel;
        Err(c.out_of_range(
            field,
            value,
            format!(
                "a rig whose fastest mechanical rate is at most {} rad/s (the simulation steps at least once per \
                 1/rate; a faster mode makes a run never end): with [mechanics].rope_ea_n = {} N and the shortest \
                 rope side {} m (of lw_low_m and rope_total_length_m - lw_high_m) this value rings at {} rad/s; a \
                 value of at least {} (or a softer rope, a longer shortest side)",
                readable(MAX_MECHANICAL_RATE_RADPS),
                readable(m.rope_ea_n),
                readable(t.lw_low_m.min(m.rope_total_length_m - t.lw_high_m)),
                readable(rate.round()),
                readable(smallest),
            ),
        ))
    }

    fn validate_motor_and_inverter(&self, c: &Checker) -> Result<(), ConfigError> {
        let mo = &self.motor;
        c.check("[motor].pole_pairs", mo.pole_pairs as f64, Bound::closed(1.0, 64.0, "", "a machine's pole pairs"))?;
        let r = "from a large machine's milliohm to a small one's hundreds of ohm";
        c.check("[motor].stator_resistance_ohm", mo.stator_resistance_ohm, Bound::closed(1.0e-3, 1.0e3, "ohm", r))?;
        let l = "from a large machine's 10 uH to 10 H";
        c.check("[motor].ld_h", mo.ld_h, Bound::closed(1.0e-5, 10.0, "H", l))?;
        c.check("[motor].lq_h", mo.lq_h, Bound::closed(1.0e-5, 10.0, "H", l))?;
        let psi = "a permanent-magnet machine's flux linkage, 1 mWb to 100 Wb";
        c.check("[motor].flux_linkage_wb", mo.flux_linkage_wb, Bound::closed(1.0e-3, 100.0, "Wb", psi))?;
        let i = "a machine's rated current, 0.1 A to 10 kA";
        c.check("[motor].rated_current_a", mo.rated_current_a, Bound::closed(0.1, 1.0e4, "A", i))?;
        let trip = "above the rated current (a trip below it stops every travel)";
        c.check(
            "[motor].overcurrent_trip_a",
            mo.overcurrent_trip_a,
            Bound::above(mo.rated_current_a, 1.0e4, "A", trip),
        )?;
        let inv = &self.inverter;
        let bus = "an inverter's DC bus, 10 V (less drives no lift machine) to 10 kV";
        c.check("[inverter].dc_bus_v", inv.dc_bus_v, Bound::closed(10.0, 1.0e4, "V", bus))?;
        let pwm = "an inverter's switching frequency, 1 kHz to 100 kHz";
        c.check("[inverter].pwm_hz", inv.pwm_hz, Bound::closed(1.0e3, 1.0e5, "Hz", pwm))?;
        let dead = "at most a tenth of the PWM period";
        c.check("[inverter].dead_time_s", inv.dead_time_s, Bound::closed(0.0, 0.1 / inv.pwm_hz, "s", dead))?;
        let sense = "above the over-current trip, which the sensor must read";
        c.check(
            "[inverter].current_sense_full_scale_a",
            inv.current_sense_full_scale_a,
            Bound::above(mo.overcurrent_trip_a, 1.0e4, "A", sense),
        )?;
        c.check("[inverter].adc_bits", inv.adc_bits as f64, Bound::closed(8.0, 16.0, "bits", "a drive's ADC"))?;
        let counts = "an encoder's counts per revolution, 4 (one line) to 1e8";
        c.check(
            "[inverter].encoder_counts_per_rev",
            inv.encoder_counts_per_rev as f64,
            Bound::closed(4.0, 1.0e8, "", counts),
        )?;
        let bus_sense = "above the DC bus, which the sensor must read";
        c.check_defaulted(
            "[inverter].dc_bus_sense_full_scale_v",
            inv.dc_bus_sense_full_scale_v,
            default_dc_bus_sense_full_scale_v(),
            Bound::above(inv.dc_bus_v, 1.0e4, "V", bus_sense),
        )?;
        let clock = "at least 100 counts a half PWM period";
        c.check_defaulted(
            "[inverter].pwm_timer_clock_hz",
            inv.pwm_timer_clock_hz,
            default_pwm_timer_clock_hz(),
            Bound::closed(2.0 * inv.pwm_hz * 100.0, 1.0e9, "Hz", clock),
        )
    }

    fn validate_control(&self, c: &Checker) -> Result<(), ConfigError> {
        let (co, inv) = (&self.control, &self.inverter);
        let once = "one current-loop update per PWM period";
        c.check("[control].current_loop_hz", co.current_loop_hz, Bound::closed(inv.pwm_hz, inv.pwm_hz, "Hz", once))?;
        let speed = "from 10 Hz to the current loop's rate";
        c.check("[control].speed_loop_hz", co.speed_loop_hz, Bound::closed(10.0, co.current_loop_hz, "Hz", speed))?;
        let ratio = co.current_loop_hz / co.speed_loop_hz;
        if (ratio - ratio.round()).abs() > 1e-9 {
            return Err(c.out_of_range(
                "[control].speed_loop_hz",
                co.speed_loop_hz,
                "a whole divisor of current_loop_hz".to_string(),
            ));
        }
        let bandwidth =
            |of: &str, over: u32| format!("at most the loop rate over {over} ({of}): a sampled loop's limit");
        c.check_defaulted(
            "[control].current_loop_bandwidth_hz",
            co.current_loop_bandwidth_hz,
            default_current_bandwidth_hz(),
            Bound::above(0.0, co.current_loop_hz / 8.0, "Hz", &bandwidth("current_loop_hz", 8)),
        )?;
        c.check_defaulted(
            "[control].speed_loop_bandwidth_hz",
            co.speed_loop_bandwidth_hz,
            default_speed_bandwidth_hz(),
            Bound::above(0.0, co.speed_loop_hz / 20.0, "Hz", &bandwidth("speed_loop_hz", 20)),
        )?;
        c.check_defaulted(
            "[control].speed_estimator_bandwidth_hz",
            co.speed_estimator_bandwidth_hz,
            default_estimator_bandwidth_hz(),
            Bound::above(0.0, co.speed_loop_hz / 10.0, "Hz", &bandwidth("speed_loop_hz", 10)),
        )?;
        let over = "a trip above the rated speed, at most 10 times it";
        c.check("[control].overspeed_factor", co.overspeed_factor, Bound::above(1.0, 10.0, "", over))?;
        let under = "a fraction of the DC bus below 1";
        c.check(
            "[control].dc_bus_undervoltage_fraction",
            co.dc_bus_undervoltage_fraction,
            Bound::above(0.0, 1.0, "", under),
        )?;
        let over = "a multiple of the DC bus above 1, at most 10";
        c.check(
            "[control].dc_bus_overvoltage_fraction",
            co.dc_bus_overvoltage_fraction,
            Bound::above(1.0, 10.0, "", over),
        )?;
        let sum = "within the current sensor's full scale";
        c.check_defaulted(
            "[control].current_sum_limit_a",
            co.current_sum_limit_a,
            default_current_sum_limit_a(),
            Bound::above(0.0, inv.current_sense_full_scale_a, "A", sum),
        )
    }

    fn validate_ripple_and_measurement(&self, c: &Checker) -> Result<(), ConfigError> {
        for (i, r) in self.ripple.iter().enumerate() {
            let order = "a harmonic of the shaft's rotation, 1 to 1000";
            c.check(
                &format!("[[ripple]][{i}].mechanical_order"),
                r.mechanical_order as f64,
                Bound::closed(1.0, 1000.0, "", order),
            )?;
            let amplitude = "never negative, at most 10 kN m";
            c.check(
                &format!("[[ripple]][{i}].amplitude_nm"),
                r.amplitude_nm,
                Bound::closed(0.0, 1.0e4, "N m", amplitude),
            )?;
            let phase = "an angle, within +-1000 rad";
            c.check(&format!("[[ripple]][{i}].phase_rad"), r.phase_rad, Bound::closed(-1.0e3, 1.0e3, "rad", phase))?;
        }
        let me = &self.measurement;
        let fs = "slower than 100 Hz holds none of the rig's vibration (the paper: 16384 Hz); faster than 10 MHz \
                  no acquisition samples";
        c.check("[measurement].sample_rate_hz", me.sample_rate_hz, Bound::closed(100.0, 1.0e7, "Hz", fs))?;
        let nyquist = me.sample_rate_hz / 2.0;
        let below = "below the Nyquist frequency, half of sample_rate_hz";
        c.check("[measurement].highpass_hz", me.highpass_hz, Bound::closed(0.0, nyquist, "Hz", below))?;
        c.check(
            "[measurement].spectrogram_band_hz[0]",
            me.spectrogram_band_hz[0],
            Bound::closed(0.0, nyquist, "Hz", below),
        )?;
        c.check(
            "[measurement].spectrogram_band_hz[1]",
            me.spectrogram_band_hz[1],
            Bound::above(
                me.spectrogram_band_hz[0],
                nyquist,
                "Hz",
                "above the band's start and below the Nyquist frequency",
            ),
        )
    }

    /// PWM timer auto-reload for centre-aligned counting: `f_clk / (2 f_pwm)`, counts.
    pub fn pwm_period_counts(&self) -> u16 {
        let counts = self.inverter.pwm_timer_clock_hz / (2.0 * self.inverter.pwm_hz);
        counts.floor().clamp(1.0, u16::MAX as f64) as u16
    }

    /// Rust source of `pub const DRIVE_CONFIG: drive_core::DriveConfig = ...;`
    /// for the firmware build scripts, so that every binary runs the
    /// controller with the values the host uses. `origin` names the rig file
    /// in the generated comment.
    pub fn drive_config_source(&self, origin: &str) -> String {
        // DriveConfig is a struct of integer and f32 fields: its Debug text
        // (`DriveConfig { pole_pairs: 6, ld_h: 0.015, .. }`) is a valid struct
        // literal, which rustc type-checks where it is included. Validation
        // has already refused non-finite values, which would not be literals.
        format!(
            "// @generated from {origin} by rig-config. Do not edit.\n\
             /// Drive parameters of the rig, generated at build time from `{origin}`.\n\
             pub const DRIVE_CONFIG: drive_core::DriveConfig = drive_core::{:?};\n",
            self.drive_config()
        )
    }

    /// Rust source of `pub const CHAIN_MODEL: drive_core::observer::ChainModel =
    /// ...;` ([`RigConfig::observer_model`]) for build scripts, like
    /// [`RigConfig::drive_config_source`].
    pub fn chain_model_source(&self, origin: &str) -> String {
        format!(
            "// @generated from {origin} by rig-config. Do not edit.\n\
             /// The drive's model of the rope chain, generated at build time from `{origin}`.\n\
             pub const CHAIN_MODEL: drive_core::observer::{:?};\n",
            self.observer_model()
        )
        .replacen("ChainModel {", "ChainModel = drive_core::observer::ChainModel {", 1)
    }

    /// Rust source of `pub const RIPPLE: [(u16, f32, f32, f32); N] = [...];`
    /// for build scripts, like [`RigConfig::drive_config_source`]: each
    /// `[[ripple]]` component as (mechanical order, amplitude N m, cos and
    /// sin of its phase), from which the drive's offline compensation table
    /// is made.
    pub fn ripple_source(&self) -> String {
        let ripple: Vec<String> = self
            .ripple
            .iter()
            .map(|r| {
                format!(
                    "({}, {:?}, {:?}, {:?})",
                    r.mechanical_order.min(u16::MAX as u32),
                    r.amplitude_nm as f32,
                    r.phase_rad.cos() as f32,
                    r.phase_rad.sin() as f32
                )
            })
            .collect();
        format!(
            "/// The rig's torque ripple (`[[ripple]]`): mechanical order, amplitude N m, cos and sin of the phase.\n\
             pub const RIPPLE: [(u16, f32, f32, f32); {}] = [{}];\n",
            ripple.len(),
            ripple.join(", ")
        )
    }

    /// The drive-core parameters of this rig.
    pub fn drive_config(&self) -> DriveConfig {
        let m = &self.mechanics;
        let mo = &self.motor;
        let inv = &self.inverter;
        let co = &self.control;
        let t = &self.travel;
        DriveConfig {
            pole_pairs: mo.pole_pairs as u8,
            stator_resistance_ohm: mo.stator_resistance_ohm as f32,
            ld_h: mo.ld_h as f32,
            lq_h: mo.lq_h as f32,
            flux_linkage_wb: mo.flux_linkage_wb as f32,
            max_current_a: mo.rated_current_a as f32,
            overcurrent_trip_a: mo.overcurrent_trip_a as f32,
            dc_bus_nominal_v: inv.dc_bus_v as f32,
            pwm_hz: inv.pwm_hz as f32,
            pwm_period_counts: self.pwm_period_counts(),
            current_sense_full_scale_a: inv.current_sense_full_scale_a as f32,
            adc_bits: inv.adc_bits as u8,
            dc_bus_sense_full_scale_v: inv.dc_bus_sense_full_scale_v as f32,
            encoder_counts_per_rev: inv.encoder_counts_per_rev,
            current_loop_hz: co.current_loop_hz as f32,
            speed_loop_hz: co.speed_loop_hz as f32,
            current_loop_bandwidth_hz: co.current_loop_bandwidth_hz as f32,
            speed_loop_bandwidth_hz: co.speed_loop_bandwidth_hz as f32,
            speed_estimator_bandwidth_hz: co.speed_estimator_bandwidth_hz as f32,
            m_cw_kg: m.m_cw_kg as f32,
            rope_total_length_m: m.rope_total_length_m as f32,
            rope_mass_per_length_kg_per_m: m.rope_mass_per_length_kg_per_m as f32,
            sheave_inertia_kg_m2: m.sheave_inertia_kg_m2 as f32,
            sheave_radius_m: m.sheave_radius_m as f32,
            gravity_mps2: m.gravity_mps2 as f32,
            rated_speed_mps: t.rated_speed_mps as f32,
            max_accel_mps2: t.max_accel_mps2 as f32,
            max_jerk_mps3: t.max_jerk_mps3 as f32,
            overspeed_factor: co.overspeed_factor as f32,
            dc_bus_undervoltage_v: (co.dc_bus_undervoltage_fraction * inv.dc_bus_v) as f32,
            dc_bus_overvoltage_v: (co.dc_bus_overvoltage_fraction * inv.dc_bus_v) as f32,
            current_sum_limit_a: co.current_sum_limit_a as f32,
        }
    }

    /// The chain model of the reduced 5-DOF observer (`drive_core::observer`):
    /// the `[mechanics]` values in `f32` and the mechanical orders of the
    /// first `drive_core::observer::model::MAX_HARMONICS` `[[ripple]]` components
    /// (only the orders: the observer estimates amplitudes and phases).
    pub fn observer_model(&self) -> drive_core::observer::ChainModel {
        let m = &self.mechanics;
        let mut ripple_orders = [0u16; drive_core::observer::model::MAX_HARMONICS];
        for (slot, ripple) in ripple_orders.iter_mut().zip(&self.ripple) {
            *slot = ripple.mechanical_order.min(u16::MAX as u32) as u16;
        }
        drive_core::observer::ChainModel {
            m_cw_kg: m.m_cw_kg as f32,
            rope_total_length_m: m.rope_total_length_m as f32,
            rope_ea_n: m.rope_ea_n as f32,
            rope_mass_per_length_kg_per_m: m.rope_mass_per_length_kg_per_m as f32,
            sheave_inertia_kg_m2: m.sheave_inertia_kg_m2 as f32,
            sheave_radius_m: m.sheave_radius_m as f32,
            c_cw_kg_per_s: m.c_cw_kg_per_s as f32,
            c_car_kg_per_s: m.c_car_kg_per_s as f32,
            c_sheave_nms_per_rad: m.c_sheave_nms_per_rad as f32,
            gravity_mps2: m.gravity_mps2 as f32,
            encoder_counts_per_rev: self.inverter.encoder_counts_per_rev,
            ripple_orders,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every `[[ripple]]` component in the generated table, its phase as
    /// cos and sin; a phase of a quarter turn gives (0, 1).
    #[test]
    fn ripple_source_lists_every_component_with_its_phase() {
        let mut rig = RigConfig::embedded_default().unwrap();
        let source = rig.ripple_source();
        assert!(source.contains(&format!("; {}] = [", rig.ripple.len())), "{source}");
        assert!(source.contains("(12, 3.5, 1.0, 0.0)"), "{source}");
        rig.ripple[0].phase_rad = std::f64::consts::FRAC_PI_2;
        let turned = rig.ripple_source();
        let first = &turned[turned.find("= [").unwrap() + 3..];
        let fields: Vec<f32> = first[1..first.find(')').unwrap()].split(", ").map(|v| v.parse().unwrap()).collect();
        assert!(fields[2].abs() < 1e-6 && (fields[3] - 1.0).abs() < 1e-6, "{turned}");
    }

    #[test]
    fn embedded_default_loads_and_matches_the_shared_spec() {
        let rig = RigConfig::embedded_default().unwrap();
        assert_eq!(rig.mechanics.m_car_kg, vec![33.0, 45.5, 58.0, 70.5]);
        assert_eq!(rig.ripple.len(), 5);
        assert_eq!(rig.pwm_period_counts(), 5312);
        let spec = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/spec/rig.toml");
        if let Ok(spec) = RigConfig::load(&spec) {
            assert_eq!(spec, rig, "configs/rig.toml has drifted from shared/spec/rig.toml");
        }
    }

    #[test]
    fn observer_model_carries_the_rig_mechanics_and_ripple_orders() {
        let rig = RigConfig::embedded_default().unwrap();
        let model = rig.observer_model();
        assert_eq!(model.validate(), Ok(()));
        assert_eq!(model.ripple_orders, [1, 6, 12, 36, 72]);
        assert_eq!(model.rope_ea_n, 1.0e6);
        assert_eq!(model.m_cw_kg, 33.0);
        assert_eq!(model.encoder_counts_per_rev, 16384);
        // Eqn 4 at mid travel with the heaviest car equals the f64 value within f32 rounding.
        let lw = 4.3;
        let expected = (70.5 - 33.0 + 0.095 * (8.6 - 2.0 * lw)) * 9.81 * 0.065;
        let got = model.out_of_balance_torque_nm(lw as f32, 70.5) as f64;
        println!("Eqn 4 at lw = {lw} m: {got:.6} N m (f64 {expected:.6})");
        assert!((got - expected).abs() < 1e-4 * expected.abs());
    }

    #[test]
    fn out_of_range_names_field_and_range() {
        let text = EMBEDDED_RIG_TOML.replace("sheave_radius_m = 0.065", "sheave_radius_m = -0.065");
        let err = RigConfig::from_toml_str(&text, "bad.toml").unwrap_err().to_string();
        assert!(
            err.contains("bad.toml") && err.contains("[mechanics].sheave_radius_m") && err.contains("[0.01, 2] m"),
            "{err}"
        );
        let text = EMBEDDED_RIG_TOML.replace("lw_high_m = 7.6", "lw_high_m = 9.0");
        let err = RigConfig::from_toml_str(&text, "bad.toml").unwrap_err().to_string();
        assert!(err.contains("[travel].lw_high_m"), "{err}");
    }

    /// The rig with `line` (a whole line of the embedded file, found by its
    /// start `key`) replaced by `key = value`.
    fn rig_with(key: &str, value: &str) -> String {
        let line = EMBEDDED_RIG_TOML.lines().find(|l| l.starts_with(&format!("{key} = "))).unwrap();
        let text = EMBEDDED_RIG_TOML.replacen(line, &format!("{key} = {value}"), 1);
        assert_ne!(text, EMBEDDED_RIG_TOML, "{key}");
        text
    }

    #[test]
    fn every_value_is_bounded_below_and_above_with_the_physical_reason() {
        // Absurd but positive values, each side of every bound: refused
        // naming the file, the field, the range and why.
        let cases: &[(&str, &str, &str)] = &[
            ("m_cw_kg", "1e-9", "[mechanics].m_cw_kg"),
            ("m_cw_kg", "1e6", "[mechanics].m_cw_kg"),
            ("m_car_kg", "[1e-9]", "[mechanics].m_car_kg[0]"),
            ("m_car_kg", "[33.0, 2e5]", "[mechanics].m_car_kg[1]"),
            ("rope_total_length_m", "1e-6", "[mechanics].rope_total_length_m"),
            ("rope_total_length_m", "1e5", "[mechanics].rope_total_length_m"),
            ("rope_ea_n", "1e-9", "[mechanics].rope_ea_n"),
            ("rope_ea_n", "1e12", "[mechanics].rope_ea_n"),
            ("rope_mass_per_length_kg_per_m", "0.0", "[mechanics].rope_mass_per_length_kg_per_m"),
            ("rope_mass_per_length_kg_per_m", "1e-9", "[mechanics].rope_mass_per_length_kg_per_m"),
            ("rope_mass_per_length_kg_per_m", "1e3", "[mechanics].rope_mass_per_length_kg_per_m"),
            ("sheave_inertia_kg_m2", "1e-9", "[mechanics].sheave_inertia_kg_m2"),
            ("sheave_inertia_kg_m2", "1e5", "[mechanics].sheave_inertia_kg_m2"),
            ("sheave_radius_m", "1e-9", "[mechanics].sheave_radius_m"),
            ("sheave_radius_m", "10.0", "[mechanics].sheave_radius_m"),
            ("gravity_mps2", "1e-9", "[mechanics].gravity_mps2"),
            ("gravity_mps2", "100.0", "[mechanics].gravity_mps2"),
            ("c_cw_kg_per_s", "1e6", "[mechanics].c_cw_kg_per_s"),
            ("c_sheave_nms_per_rad", "1e6", "[mechanics].c_sheave_nms_per_rad"),
            ("car_frame_first_mode_hz", "1e-9", "[mechanics].car_frame_first_mode_hz"),
            ("car_frame_first_mode_hz", "1e5", "[mechanics].car_frame_first_mode_hz"),
            ("rated_speed_mps", "1e-9", "[travel].rated_speed_mps"),
            ("max_accel_mps2", "1e-9", "[travel].max_accel_mps2"),
            ("max_jerk_mps3", "1e-9", "[travel].max_jerk_mps3"),
            ("lw_low_m", "1e-7", "[travel].lw_low_m"),
            ("lw_high_m", "8.59", "[travel].lw_high_m"),
            ("stator_resistance_ohm", "1e-9", "[motor].stator_resistance_ohm"),
            ("ld_h", "1e-9", "[motor].ld_h"),
            ("lq_h", "100.0", "[motor].lq_h"),
            ("flux_linkage_wb", "1e-9", "[motor].flux_linkage_wb"),
            ("rated_current_a", "1e-9", "[motor].rated_current_a"),
            ("dc_bus_v", "1e-9", "[inverter].dc_bus_v"),
            ("sample_rate_hz", "1.0", "[measurement].sample_rate_hz"),
            ("sample_rate_hz", "1e8", "[measurement].sample_rate_hz"),
        ];
        for (key, value, field) in cases {
            let err = RigConfig::from_toml_str(&rig_with(key, value), "bad.toml").unwrap_err().to_string();
            assert!(err.starts_with(&format!("bad.toml: field `{field}` = ")), "{key} = {value}: {err}");
            // The range and its reason; no number written with hundreds of digits.
            assert!(err.contains("expected a finite value in ") && err.contains("]"), "{err}");
            let reason = &err[err.find(']').unwrap()..];
            assert!(reason.contains(": "), "{key} = {value}: no reason in {err}");
            assert!(!err.contains("0.0000000"), "{err}");
        }
    }

    #[test]
    fn a_default_refused_because_of_another_field_says_it_is_the_default() {
        // The file never gives dc_bus_sense_full_scale_v: its 200 V default
        // cannot read a 10 kV bus.
        let err = RigConfig::from_toml_str(&rig_with("dc_bus_v", "1e4"), "bad.toml").unwrap_err().to_string();
        assert!(err.contains("[inverter].dc_bus_sense_full_scale_v` = 200"), "{err}");
        assert!(err.contains("200 is the field's default, in force when the file does not give it"), "{err}");
        // A value the file gives is not called a default.
        let text =
            rig_with("dc_bus_v", "300.0").replace("[inverter]\n", "[inverter]\ndc_bus_sense_full_scale_v = 250.0\n");
        let err = RigConfig::from_toml_str(&text, "bad.toml").unwrap_err().to_string();
        assert!(err.contains("= 250 is out of range") && !err.contains("default"), "{err}");
    }

    #[test]
    fn a_rig_that_rings_too_fast_or_travels_too_long_is_refused_naming_the_field() {
        // Each value within its own bounds, the rig as a whole beyond the
        // simulation's: a stiff rope on a short side.
        let text = rig_with("rope_ea_n", "1e9");
        let text = text.replace("lw_low_m = 1.0 ", "lw_low_m = 0.1 ");
        let err = RigConfig::from_toml_str(&text, "bad.toml").unwrap_err().to_string();
        assert!(err.contains("[mechanics].rope_mass_per_length_kg_per_m") && err.contains("rad/s"), "{err}");
        let rig = RigConfig::embedded_default().unwrap();
        let (rate, field, _) = rig.fastest_mechanical_rate();
        assert!((8000.0..10000.0).contains(&rate) && field.contains("rope_mass"), "{rate} {field}");
        // ... and a light sheave of large radius between them.
        let text = text
            .replace("rope_mass_per_length_kg_per_m = 0.095", "rope_mass_per_length_kg_per_m = 100.0")
            .replace("sheave_radius_m = 0.065", "sheave_radius_m = 2.0")
            .replace("sheave_inertia_kg_m2 = 0.3385", "sheave_inertia_kg_m2 = 0.001");
        let err = RigConfig::from_toml_str(&text, "bad.toml").unwrap_err().to_string();
        assert!(err.contains("field `[mechanics].sheave_inertia_kg_m2` = 0.001") && err.contains("at least"), "{err}");
        // A travel of hours at the slowest speed on the longest rope.
        let text = rig_with("rope_total_length_m", "1000.0").replace("lw_high_m = 7.6", "lw_high_m = 900.0");
        let text = text.replace("rated_speed_mps = 0.4 ", "rated_speed_mps = 0.05 ");
        let err = RigConfig::from_toml_str(&text, "bad.toml").unwrap_err().to_string();
        assert!(err.contains("[travel].rated_speed_mps") && err.contains("600 s"), "{err}");
    }

    #[test]
    fn a_number_the_parser_quotes_digit_by_digit_is_written_readably() {
        let err = RigConfig::from_toml_str(&rig_with("name", "1e300"), "bad.toml").unwrap_err().to_string();
        assert!(err.contains("1e300") && !err.contains("0000000000"), "{err}");
        assert_eq!(readable_numbers("a 12 b 0.5 c 1000000000000000000000000"), "a 12 b 0.5 c 1e24");
    }

    #[test]
    fn missing_field_and_wrong_type_name_the_field_and_line() {
        let text = EMBEDDED_RIG_TOML.replace("rope_ea_n = 1.0e6", "");
        let err = RigConfig::from_toml_str(&text, "bad.toml").unwrap_err().to_string();
        assert!(err.contains("bad.toml") && err.contains("rope_ea_n"), "{err}");
        let text = EMBEDDED_RIG_TOML.replace("pole_pairs = 6", "pole_pairs = \"six\"");
        let err = RigConfig::from_toml_str(&text, "bad.toml").unwrap_err().to_string();
        assert!(err.contains("line") && err.contains("pole_pairs"), "{err}");
    }

    #[test]
    fn unknown_and_misspelt_fields_are_refused_naming_them() {
        // A misspelt optional field: refused, not silently replaced by its default.
        let text = EMBEDDED_RIG_TOML.replace("[control]\n", "[control]\nspeed_loop_bandwith_hz = 3.0\n");
        assert_ne!(text, EMBEDDED_RIG_TOML);
        let err = RigConfig::from_toml_str(&text, "bad.toml").unwrap_err().to_string();
        assert!(
            err.contains("bad.toml")
                && err.contains("speed_loop_bandwith_hz")
                && err.contains("speed_loop_bandwidth_hz"),
            "{err}"
        );
        // An extra field in any table, and an extra table.
        for (from, to) in [
            ("[mechanics]\n", "[mechanics]\nextra_field = 1\n"),
            ("[measurement]\n", "[measurement]\nextra_field = 1\n"),
            ("[[ripple]]\n", "[[ripple]]\nextra_field = 1\n"),
            ("[travel]\n", "[extra]\nx = 1\n\n[travel]\n"),
        ] {
            let text = EMBEDDED_RIG_TOML.replacen(from, to, 1);
            assert_ne!(text, EMBEDDED_RIG_TOML, "{from}");
            let err = RigConfig::from_toml_str(&text, "bad.toml").unwrap_err().to_string();
            assert!(err.contains("bad.toml") && err.contains("unknown field") && err.contains("line"), "{err}");
        }
    }

    #[test]
    fn an_empty_car_list_is_refused_naming_the_field() {
        let line = EMBEDDED_RIG_TOML.lines().find(|l| l.starts_with("m_car_kg")).unwrap();
        let text = EMBEDDED_RIG_TOML.replace(line, "m_car_kg = []");
        let err = RigConfig::from_toml_str(&text, "bad.toml").unwrap_err().to_string();
        assert!(err.contains("bad.toml") && err.contains("[mechanics].m_car_kg") && err.contains("empty"), "{err}");
        assert!(err.contains("expected at least one car mass"), "{err}");
    }

    #[test]
    fn a_file_over_the_size_bound_is_refused_before_it_is_read() {
        let dir = std::env::temp_dir().join(format!("rig-config-size-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("huge.toml");
        // Sparse: the size is what counts, not the bytes.
        let file = std::fs::File::create(&path).unwrap();
        file.set_len(MAX_TEXT_FILE_BYTES + 1).unwrap();
        let err = RigConfig::load(&path).unwrap_err().to_string();
        assert!(err.contains("huge.toml") && err.contains(&MAX_TEXT_FILE_BYTES.to_string()), "{err}");
        let small = dir.join("small.toml");
        std::fs::write(&small, EMBEDDED_RIG_TOML).unwrap();
        assert_eq!(RigConfig::load(&small).unwrap(), RigConfig::embedded_default().unwrap());
        assert_eq!(read_text_file(&small, 10).unwrap_err().kind(), std::io::ErrorKind::FileTooLarge);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn generated_source_is_a_struct_literal_of_every_field() {
        let rig = RigConfig::embedded_default().unwrap();
        let source = rig.drive_config_source("configs/rig.toml");
        assert!(
            source.contains("pub const DRIVE_CONFIG: drive_core::DriveConfig = drive_core::DriveConfig {"),
            "{source}"
        );
        assert!(source.contains("pole_pairs: 6,") && source.contains("pwm_period_counts: 5312,"), "{source}");
        assert!(!source.contains("NaN") && !source.contains("inf"), "{source}");
    }

    #[test]
    fn drive_config_derivations() {
        let drive = RigConfig::embedded_default().unwrap().drive_config();
        assert!((drive.torque_constant_nm_per_a() - 4.05).abs() < 1e-5);
        assert_eq!(drive.speed_loop_divider(), 8);
        assert_eq!(drive.adc_zero_code(), 2048);
    }
}
