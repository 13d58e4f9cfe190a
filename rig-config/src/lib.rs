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
    #[error("{path}: field `{field}` = {value} is out of range: expected {expected}")]
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

/// Range checker that names the file and field.
struct Checker<'a> {
    path: &'a str,
}

impl Checker<'_> {
    fn within(&self, field: &str, value: f64, lo: f64, hi: f64, lo_open: bool) -> Result<(), ConfigError> {
        let above = if lo_open { value > lo } else { value >= lo };
        if value.is_finite() && above && value <= hi {
            Ok(())
        } else {
            let open = if lo_open { "(" } else { "[" };
            Err(ConfigError::OutOfRange {
                path: self.path.to_string(),
                field: field.to_string(),
                value,
                expected: format!("a finite value in {open}{lo}, {hi}]"),
            })
        }
    }

    fn positive(&self, field: &str, value: f64, hi: f64) -> Result<(), ConfigError> {
        self.within(field, value, 0.0, hi, true)
    }

    fn non_negative(&self, field: &str, value: f64, hi: f64) -> Result<(), ConfigError> {
        self.within(field, value, 0.0, hi, false)
    }
}

impl RigConfig {
    /// Parses and validates rig TOML text; `origin` names it in errors.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let config: RigConfig = toml::from_str(text)
            .map_err(|e| ConfigError::Parse { path: origin.to_string(), message: e.to_string() })?;
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

    /// Checks every value against its physical range; `origin` names the file.
    pub fn validate(&self, origin: &str) -> Result<(), ConfigError> {
        let c = Checker { path: origin };
        let m = &self.mechanics;
        c.positive("[mechanics].m_cw_kg", m.m_cw_kg, 1.0e5)?;
        if m.m_car_kg.is_empty() {
            return Err(ConfigError::Invalid {
                path: origin.to_string(),
                field: "[mechanics].m_car_kg".to_string(),
                found: "is an empty list".to_string(),
                expected: "at least one car mass in kg, e.g. m_car_kg = [70.5] (the commands default to the \
                           heaviest)"
                    .to_string(),
            });
        }
        for (i, mass) in m.m_car_kg.iter().enumerate() {
            c.positive(&format!("[mechanics].m_car_kg[{i}]"), *mass, 1.0e5)?;
        }
        c.positive("[mechanics].rope_total_length_m", m.rope_total_length_m, 1.0e3)?;
        c.positive("[mechanics].rope_ea_n", m.rope_ea_n, 1.0e12)?;
        c.non_negative("[mechanics].rope_mass_per_length_kg_per_m", m.rope_mass_per_length_kg_per_m, 1.0e3)?;
        c.positive("[mechanics].sheave_inertia_kg_m2", m.sheave_inertia_kg_m2, 1.0e4)?;
        c.positive("[mechanics].sheave_radius_m", m.sheave_radius_m, 10.0)?;
        c.positive("[mechanics].gravity_mps2", m.gravity_mps2, 100.0)?;
        c.non_negative("[mechanics].guide_damping_ratio", m.guide_damping_ratio, 1.0)?;
        c.non_negative("[mechanics].c_cw_kg_per_s", m.c_cw_kg_per_s, 1.0e6)?;
        c.non_negative("[mechanics].c_car_kg_per_s", m.c_car_kg_per_s, 1.0e6)?;
        c.non_negative("[mechanics].c_sheave_nms_per_rad", m.c_sheave_nms_per_rad, 1.0e6)?;
        c.positive("[mechanics].car_frame_first_mode_hz", m.car_frame_first_mode_hz, 1.0e5)?;
        if m.rope_lumping != "all-at-midpoint" {
            return Err(ConfigError::Parse {
                path: origin.to_string(),
                message: format!(
                    "field `[mechanics].rope_lumping` = {:?}: expected \"all-at-midpoint\"",
                    m.rope_lumping
                ),
            });
        }
        let t = &self.travel;
        c.positive("[travel].rated_speed_mps", t.rated_speed_mps, 20.0)?;
        c.positive("[travel].max_accel_mps2", t.max_accel_mps2, 20.0)?;
        c.positive("[travel].max_jerk_mps3", t.max_jerk_mps3, 100.0)?;
        c.positive("[travel].lw_low_m", t.lw_low_m, m.rope_total_length_m)?;
        c.within("[travel].lw_high_m", t.lw_high_m, t.lw_low_m, m.rope_total_length_m, true)?;
        if t.lw_high_m >= m.rope_total_length_m {
            c.within("[travel].lw_high_m", t.lw_high_m, t.lw_low_m, m.rope_total_length_m * (1.0 - 1e-9), true)?;
        }
        let mo = &self.motor;
        c.within("[motor].pole_pairs", mo.pole_pairs as f64, 1.0, 64.0, false)?;
        c.positive("[motor].stator_resistance_ohm", mo.stator_resistance_ohm, 1.0e3)?;
        c.positive("[motor].ld_h", mo.ld_h, 10.0)?;
        c.positive("[motor].lq_h", mo.lq_h, 10.0)?;
        c.positive("[motor].flux_linkage_wb", mo.flux_linkage_wb, 100.0)?;
        c.positive("[motor].rated_current_a", mo.rated_current_a, 1.0e4)?;
        c.within("[motor].overcurrent_trip_a", mo.overcurrent_trip_a, mo.rated_current_a, 1.0e4, true)?;
        let inv = &self.inverter;
        c.positive("[inverter].dc_bus_v", inv.dc_bus_v, 1.0e4)?;
        c.within("[inverter].pwm_hz", inv.pwm_hz, 1.0e3, 1.0e5, false)?;
        c.non_negative("[inverter].dead_time_s", inv.dead_time_s, 0.1 / inv.pwm_hz)?;
        c.within(
            "[inverter].current_sense_full_scale_a",
            inv.current_sense_full_scale_a,
            mo.overcurrent_trip_a,
            1.0e4,
            true,
        )?;
        c.within("[inverter].adc_bits", inv.adc_bits as f64, 8.0, 16.0, false)?;
        c.within("[inverter].encoder_counts_per_rev", inv.encoder_counts_per_rev as f64, 4.0, 1.0e8, false)?;
        c.within("[inverter].dc_bus_sense_full_scale_v", inv.dc_bus_sense_full_scale_v, inv.dc_bus_v, 1.0e4, true)?;
        c.within("[inverter].pwm_timer_clock_hz", inv.pwm_timer_clock_hz, 2.0 * inv.pwm_hz * 100.0, 1.0e9, false)?;
        let co = &self.control;
        c.within("[control].current_loop_hz", co.current_loop_hz, inv.pwm_hz, inv.pwm_hz, false)?;
        c.within("[control].speed_loop_hz", co.speed_loop_hz, 10.0, co.current_loop_hz, false)?;
        let ratio = co.current_loop_hz / co.speed_loop_hz;
        if (ratio - ratio.round()).abs() > 1e-9 {
            return Err(ConfigError::OutOfRange {
                path: origin.to_string(),
                field: "[control].speed_loop_hz".to_string(),
                value: co.speed_loop_hz,
                expected: "a whole divisor of current_loop_hz".to_string(),
            });
        }
        c.within(
            "[control].current_loop_bandwidth_hz",
            co.current_loop_bandwidth_hz,
            0.0,
            co.current_loop_hz / 8.0,
            true,
        )?;
        c.within("[control].speed_loop_bandwidth_hz", co.speed_loop_bandwidth_hz, 0.0, co.speed_loop_hz / 20.0, true)?;
        c.within(
            "[control].speed_estimator_bandwidth_hz",
            co.speed_estimator_bandwidth_hz,
            0.0,
            co.speed_loop_hz / 10.0,
            true,
        )?;
        c.within("[control].overspeed_factor", co.overspeed_factor, 1.0, 10.0, true)?;
        c.within("[control].dc_bus_undervoltage_fraction", co.dc_bus_undervoltage_fraction, 0.0, 1.0, true)?;
        c.within("[control].dc_bus_overvoltage_fraction", co.dc_bus_overvoltage_fraction, 1.0, 10.0, true)?;
        c.positive("[control].current_sum_limit_a", co.current_sum_limit_a, inv.current_sense_full_scale_a)?;
        for (i, r) in self.ripple.iter().enumerate() {
            c.within(&format!("[[ripple]][{i}].mechanical_order"), r.mechanical_order as f64, 1.0, 1000.0, false)?;
            c.non_negative(&format!("[[ripple]][{i}].amplitude_nm"), r.amplitude_nm, 1.0e4)?;
            c.within(&format!("[[ripple]][{i}].phase_rad"), r.phase_rad, -1.0e3, 1.0e3, false)?;
        }
        let me = &self.measurement;
        c.within("[measurement].sample_rate_hz", me.sample_rate_hz, 1.0, 1.0e7, false)?;
        c.within("[measurement].highpass_hz", me.highpass_hz, 0.0, me.sample_rate_hz / 2.0, false)?;
        c.non_negative("[measurement].spectrogram_band_hz[0]", me.spectrogram_band_hz[0], me.sample_rate_hz / 2.0)?;
        c.within(
            "[measurement].spectrogram_band_hz[1]",
            me.spectrogram_band_hz[1],
            me.spectrogram_band_hz[0],
            me.sample_rate_hz / 2.0,
            true,
        )?;
        Ok(())
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
            err.contains("bad.toml") && err.contains("[mechanics].sheave_radius_m") && err.contains("(0, 10]"),
            "{err}"
        );
        let text = EMBEDDED_RIG_TOML.replace("lw_high_m = 7.6", "lw_high_m = 9.0");
        let err = RigConfig::from_toml_str(&text, "bad.toml").unwrap_err().to_string();
        assert!(err.contains("[travel].lw_high_m"), "{err}");
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
