//! The board description (`configs/boards/<name>.toml`): the pins, their
//! alternate functions and active levels, the current and bus-voltage
//! sensing (scale and sign), the power board's ratings and the trip levels
//! derived from them, each fact with the manual it comes from.
//!
//! The rig (`configs/rig.toml`) describes the machine and the lift; the
//! board describes the electronics the firmware runs on. The firmware's
//! build script generates its pin types and polarities
//! ([`Board::firmware_source`]) and its drive parameters
//! ([`Board::drive_config`]: the rig's, with this board's sensing scales
//! and trip levels) from one description; a second board is a second file.

use drive_core::DriveConfig;
use serde::Deserialize;

use crate::{ConfigError, RigConfig};

/// The board the firmware is built for unless `DRIVE_BOARD` names another.
pub const DEFAULT_BOARD: &str = "nucleo-g474re-ihm08m1";

/// The embedded default board description.
pub const EMBEDDED_BOARD_TOML: &str = include_str!("../../configs/boards/nucleo-g474re-ihm08m1.toml");

/// One pin of the board.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Pin {
    /// The firmware's type alias of the pin (`PwmULow`).
    pub name: String,
    /// What the pin does, as the pin table of `docs/firmware.md` says it.
    pub function: String,
    /// The MCU pin (`PA7`).
    pub pin: String,
    /// The peripheral signal (`TIM1_CH1N`, `ADC1_IN1`).
    pub signal: String,
    /// Alternate-function number; -1 for none: an analog input (signal
    /// `ADCn_INm`) or a plain GPIO the firmware drives itself (signal
    /// `GPIO_OUTPUT`).
    pub af: i8,
    /// Pin level of the asserted function: `high`, `low`, or `-`.
    pub active: String,
    /// Where the facts of this row come from (document, table, page).
    pub source: String,
}

/// Phase-current sensing of the power board.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CurrentSense {
    /// Shunt resistance, ohm.
    pub shunt_ohm: f64,
    /// Amplifier gain from shunt voltage to ADC input, V/V; negative for an
    /// inverting amplifier (a current into the machine reads below mid-scale).
    pub amplifier_gain: f64,
    /// ADC reference (full-scale input), V.
    pub adc_reference_v: f64,
    /// Source of these values.
    pub source: String,
}

/// DC-bus sensing of the power board.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DcBusSense {
    /// ADC input volts per bus volt (divider ratio).
    pub divider_gain: f64,
    /// Source of this value.
    pub source: String,
}

/// Ratings of the power board.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Ratings {
    /// Lowest rated DC-bus voltage, V.
    pub dc_bus_min_v: f64,
    /// Highest rated DC-bus voltage, V.
    pub dc_bus_max_v: f64,
    /// Rated output current, A rms.
    pub phase_current_max_a_rms: f64,
    /// Source of these values.
    pub source: String,
}

/// How the drive runs on the board.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Operation {
    /// The DC-bus supply the drive is set up for, V.
    pub dc_bus_nominal_v: f64,
}

/// A board description.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Board {
    /// Name of the description (the file name without `.toml`).
    pub name: String,
    /// The microcontroller.
    pub mcu: String,
    /// Every pin the firmware uses.
    pub pin: Vec<Pin>,
    /// Phase-current sensing.
    pub current_sense: CurrentSense,
    /// DC-bus sensing.
    pub dc_bus_sense: DcBusSense,
    /// Ratings of the power board.
    pub ratings: Ratings,
    /// Operating point.
    pub operation: Operation,
}

/// The pins the firmware needs, by type alias.
pub const REQUIRED_PINS: [&str; 17] = [
    "PwmUHigh",
    "PwmVHigh",
    "PwmWHigh",
    "PwmULow",
    "PwmVLow",
    "PwmWLow",
    "BreakIn",
    "EncoderA",
    "EncoderB",
    "BrakePin",
    "CurrentUPin",
    "CurrentVPin",
    "CurrentWPin",
    "DcBusPin",
    "DcpTx",
    "DcpRx",
    "DcpDe",
];

fn bad(origin: &str, field: &str, value: f64, expected: &str) -> ConfigError {
    ConfigError::OutOfRange {
        path: origin.to_string(),
        field: field.to_string(),
        value,
        expected: expected.to_string(),
    }
}

fn invalid(origin: &str, field: &str, found: &str, expected: &str) -> ConfigError {
    ConfigError::Invalid {
        path: origin.to_string(),
        field: field.to_string(),
        found: found.to_string(),
        expected: expected.to_string(),
    }
}

impl Board {
    /// Parses and checks a description; `origin` names it in errors.
    ///
    /// # Errors
    /// A parse error, a missing or doubled pin, an active level other than
    /// `high`, `low` or `-`, or a scale or rating out of its range.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let board: Board = toml::from_str(text)
            .map_err(|e| ConfigError::Parse { path: origin.to_string(), message: e.to_string() })?;
        for name in REQUIRED_PINS {
            let count = board.pin.iter().filter(|p| p.name == name).count();
            if count != 1 {
                return Err(invalid(origin, &format!("[[pin]] {name}"), &format!("{count} rows"), "exactly one row"));
            }
        }
        for p in &board.pin {
            if !matches!(p.active.as_str(), "high" | "low" | "-") {
                return Err(invalid(origin, &format!("[[pin]] {}.active", p.name), &p.active, "high, low or -"));
            }
        }
        let cs = &board.current_sense;
        if !(cs.shunt_ohm > 0.0 && cs.amplifier_gain.abs() > 0.0 && cs.adc_reference_v > 0.0) {
            return Err(bad(origin, "[current_sense]", cs.shunt_ohm, "positive shunt and reference, non-zero gain"));
        }
        if !(board.dc_bus_sense.divider_gain > 0.0 && board.dc_bus_sense.divider_gain <= 1.0) {
            return Err(bad(origin, "[dc_bus_sense].divider_gain", board.dc_bus_sense.divider_gain, "(0, 1]"));
        }
        let r = &board.ratings;
        let nominal = board.operation.dc_bus_nominal_v;
        if !(r.dc_bus_min_v > 0.0 && r.dc_bus_min_v < nominal && nominal <= r.dc_bus_max_v) {
            return Err(bad(origin, "[operation].dc_bus_nominal_v", nominal, "inside the rated bus range"));
        }
        Ok(board)
    }

    /// The embedded default description ([`DEFAULT_BOARD`]).
    ///
    /// # Errors
    /// As [`Board::from_toml_str`].
    pub fn embedded_default() -> Result<Self, ConfigError> {
        Self::from_toml_str(EMBEDDED_BOARD_TOML, "configs/boards/nucleo-g474re-ihm08m1.toml (embedded)")
    }

    /// The row of the pin the firmware calls `name`.
    pub fn pin(&self, name: &str) -> Option<&Pin> {
        self.pin.iter().find(|p| p.name == name)
    }

    /// Whether the pin `name` is active low (`false` for one not listed).
    pub fn active_low(&self, name: &str) -> bool {
        self.pin(name).is_some_and(|p| p.active == "low")
    }

    /// Phase current at either end of the ADC range: the reference's half
    /// over shunt times |gain|, A (31.85 A on the IHM08M1).
    pub fn current_full_scale_a(&self) -> f64 {
        let cs = &self.current_sense;
        0.5 * cs.adc_reference_v / (cs.shunt_ohm * cs.amplifier_gain.abs())
    }

    /// Whether the current amplifiers invert (negative gain).
    pub fn current_sense_inverted(&self) -> bool {
        self.current_sense.amplifier_gain < 0.0
    }

    /// DC-bus voltage at the top ADC code, V (63.2 V on the IHM08M1).
    pub fn dc_bus_full_scale_v(&self) -> f64 {
        self.current_sense.adc_reference_v / self.dc_bus_sense.divider_gain
    }

    /// Rated peak phase current, A: the rated rms times sqrt(2).
    pub fn phase_current_max_peak_a(&self) -> f64 {
        self.ratings.phase_current_max_a_rms * std::f64::consts::SQRT_2
    }

    /// The drive parameters on this board: the rig's, with the board's
    /// sensing scales, its bus voltage, and trip levels inside its ratings:
    /// over-current at the lowest of the machine's trip, the board's rated
    /// peak current and 95 % of the sensing range; under-voltage at the
    /// rig's fraction of the nominal bus, not below the board's lowest
    /// rated bus; over-voltage at the rig's fraction, not above the board's
    /// highest rated bus.
    ///
    /// # Errors
    /// A machine whose rated current the board's trip level would not allow.
    pub fn drive_config(&self, rig: &RigConfig) -> Result<DriveConfig, ConfigError> {
        let mut c = rig.drive_config();
        let nominal = self.operation.dc_bus_nominal_v;
        let full_scale = self.current_full_scale_a();
        let trip = rig.motor.overcurrent_trip_a.min(self.phase_current_max_peak_a()).min(0.95 * full_scale);
        if trip < rig.motor.rated_current_a {
            return Err(bad(&self.name, "over-current trip on the board", trip, "at least [motor].rated_current_a"));
        }
        c.dc_bus_nominal_v = nominal as f32;
        c.current_sense_full_scale_a = full_scale as f32;
        c.dc_bus_sense_full_scale_v = self.dc_bus_full_scale_v() as f32;
        c.overcurrent_trip_a = trip as f32;
        c.dc_bus_undervoltage_v =
            (rig.control.dc_bus_undervoltage_fraction * nominal).max(self.ratings.dc_bus_min_v) as f32;
        c.dc_bus_overvoltage_v =
            (rig.control.dc_bus_overvoltage_fraction * nominal).min(self.ratings.dc_bus_max_v) as f32;
        Ok(c)
    }

    /// Rust source of the firmware's board module: one type alias per pin
    /// (`pub type PwmULow = embassy_stm32::peripherals::PA7;`), its AF and
    /// active level, and the sensing sign.
    pub fn firmware_source(&self, origin: &str) -> String {
        let mut s = format!("// @generated from {origin} by rig-config. Do not edit.\n");
        s += &format!(
            "/// Name of the board description the firmware was built for.\npub const BOARD_NAME: &str = {:?};\n",
            self.name
        );
        for p in &self.pin {
            let upper = screaming(&p.name);
            s += &format!(
                "/// {}: {} ({}, AF {}, active {}).\npub type {} = embassy_stm32::peripherals::{};\n",
                p.function, p.pin, p.signal, p.af, p.active, p.name, p.pin
            );
            s += &format!(
                "/// Alternate function of [`{}`] in the description (-1: none, analog or plain GPIO).\n#[allow(dead_code)]\npub const {upper}_AF: i8 = {};\n",
                p.name, p.af
            );
            s += &format!(
                "/// Whether [`{}`] is active low.\n#[allow(dead_code)]\npub const {upper}_ACTIVE_LOW: bool = {};\n",
                p.name,
                p.active == "low"
            );
        }
        s += "/// The MCU pin of a pin of the description, taken from embassy's `Peripherals` (`board_pin!(p, PwmULow)`).\n\
               macro_rules! board_pin {\n";
        for p in &self.pin {
            s += &format!("    ($p:ident, {}) => {{ $p.{} }};\n", p.name, p.pin);
        }
        s += "}\n";
        s += &format!(
            "/// The current amplifiers invert: a current into the machine reads below mid-scale.\n\
             pub const CURRENT_SENSE_INVERTED: bool = {};\n",
            self.current_sense_inverted()
        );
        s
    }

    /// Rust source of `pub const DRIVE_CONFIG` for the firmware
    /// ([`Board::drive_config`]).
    ///
    /// # Errors
    /// As [`Board::drive_config`].
    pub fn drive_config_source(&self, rig: &RigConfig, origin: &str) -> Result<String, ConfigError> {
        Ok(format!(
            "// @generated from {origin} and the board {} by rig-config. Do not edit.\n\
             /// Drive parameters of the rig on the board, generated at build time.\n\
             pub const DRIVE_CONFIG: drive_core::DriveConfig = drive_core::{:?};\n",
            self.name,
            self.drive_config(rig)?
        ))
    }
}

/// `PwmULow` -> `PWM_U_LOW`.
fn screaming(name: &str) -> String {
    let mut out = String::new();
    for (i, ch) in name.chars().enumerate() {
        if ch.is_ascii_uppercase() && i > 0 {
            out.push('_');
        }
        out.push(ch.to_ascii_uppercase());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rows of the pin table in `docs/firmware.md` ("Pin map" section):
    /// (function, pin, signal, AF, active, source).
    fn doc_rows() -> Vec<[String; 6]> {
        let doc = include_str!("../../docs/firmware.md");
        let start =
            doc.find("| Function | Pin | Signal | AF | Active | Source |").expect("docs/firmware.md has the pin table");
        doc[start..]
            .lines()
            .skip(2)
            .take_while(|l| l.starts_with('|'))
            .map(|l| {
                let cells: Vec<String> = l.trim_matches('|').split('|').map(|c| c.trim().replace('`', "")).collect();
                assert_eq!(cells.len(), 6, "pin table row {l:?}");
                [0, 1, 2, 3, 4, 5].map(|i| cells[i].clone())
            })
            .collect()
    }

    #[test]
    fn board_description_parses_and_has_every_pin() {
        let b = Board::embedded_default().unwrap();
        assert_eq!(b.name, DEFAULT_BOARD);
        assert_eq!(b.pin.len(), REQUIRED_PINS.len());
    }

    /// The firmware's pin types, AFs and polarities are generated from the
    /// description; the description must say what the documented pin table
    /// says, row for row, and the generated source must carry each row.
    #[test]
    fn board_pin_configuration_matches_the_documented_table() {
        let b = Board::embedded_default().unwrap();
        let rows = doc_rows();
        assert_eq!(rows.len(), b.pin.len(), "one documented row per pin of the description");
        let source = b.firmware_source("test");
        for p in &b.pin {
            let row = rows
                .iter()
                .find(|r| r[1] == p.pin)
                .unwrap_or_else(|| panic!("{} ({}) not in the doc table", p.name, p.pin));
            assert_eq!(row[0], p.function, "{}", p.pin);
            assert_eq!(row[2], p.signal, "{}", p.pin);
            let af = match (p.af, p.signal.as_str()) {
                (af, "GPIO_OUTPUT") => {
                    assert_eq!(af, -1, "{}: a plain GPIO has no alternate function", p.pin);
                    "io".to_string()
                }
                (af, _) if af < 0 => "an".to_string(),
                (af, _) => af.to_string(),
            };
            assert_eq!(row[3], af, "{}", p.pin);
            assert_eq!(row[4], p.active, "{}", p.pin);
            assert!(!row[5].is_empty(), "{}: the doc row names no source", p.pin);
            assert!(source.contains(&format!("pub type {} = embassy_stm32::peripherals::{};", p.name, p.pin)));
            let upper = screaming(&p.name);
            assert!(source.contains(&format!("pub const {upper}_AF: i8 = {};", p.af)));
            assert!(source.contains(&format!("pub const {upper}_ACTIVE_LOW: bool = {};", p.active == "low")));
        }
    }

    /// The facts of the manuals, transcribed: the L6398's LIN is active low
    /// (datasheet truth table), HIN active high; the IHM08M1's low-side
    /// inputs sit on PA7/PB0/PB1 (TIM1_CH1N-CH3N, AF6 on the G474RE); BKIN
    /// is active low; the amplifiers invert (gain -5.18, NuttX's IHM08M1
    /// board parameters). No pin the firmware uses is on a shield signal it
    /// must not drive (the sources in the description): PA12 CPOUT, PA11
    /// and PB14 (the BKIN net), PB15 (the U low-side net), PB4 (the
    /// over-current reference CURRENT_REF), PC13 (the user button B1), nor
    /// on one of the shield's other inputs or outputs (PA15/PB3/PB10
    /// encoder/Hall, PC9/PC3/PB11/PC4/PC5 back-EMF, PC2 temperature, PA4
    /// potentiometer, PB2 LED, PA5/PB5 debug connector).
    #[test]
    fn board_description_agrees_with_the_cited_manuals() {
        let b = Board::embedded_default().unwrap();
        for (name, pin, signal) in
            [("PwmULow", "PA7", "TIM1_CH1N"), ("PwmVLow", "PB0", "TIM1_CH2N"), ("PwmWLow", "PB1", "TIM1_CH3N")]
        {
            let p = b.pin(name).unwrap();
            assert_eq!((p.pin.as_str(), p.signal.as_str(), p.af), (pin, signal, 6));
            assert!(b.active_low(name), "{name}: L6398 LIN is active low");
        }
        for name in ["PwmUHigh", "PwmVHigh", "PwmWHigh"] {
            assert!(!b.active_low(name), "{name}: L6398 HIN is active high");
        }
        assert!(b.active_low("BreakIn"));
        assert!(!b.active_low("BrakePin"), "brake released by a high level, applied by reset and idle");
        let shield_signals = [
            "PA12", "PA11", "PB14", "PB15", "PB4", "PC13", "PA15", "PB3", "PB10", "PC9", "PC3", "PB11", "PC4", "PC5",
            "PC2", "PA4", "PB2", "PA5", "PB5",
        ];
        for p in &b.pin {
            assert!(!shield_signals.contains(&p.pin.as_str()), "{} on {}, a shield signal", p.name, p.pin);
        }
        // The pins the shield's sources name for the functions the firmware uses.
        for (name, pin) in [
            ("PwmUHigh", "PA8"),
            ("PwmVHigh", "PA9"),
            ("PwmWHigh", "PA10"),
            ("BreakIn", "PA6"),
            ("CurrentUPin", "PA0"),
            ("CurrentVPin", "PC1"),
            ("CurrentWPin", "PC0"),
            ("DcBusPin", "PA1"),
        ] {
            assert_eq!(b.pin(name).unwrap().pin, pin, "{name}");
        }
        assert!(b.current_sense_inverted());
        assert!((b.current_full_scale_a() - 31.85).abs() < 0.01, "{}", b.current_full_scale_a());
        assert!((b.dc_bus_full_scale_v() - 63.22).abs() < 0.01, "{}", b.dc_bus_full_scale_v());
    }

    #[test]
    fn trip_levels_stay_inside_the_board_ratings() {
        let b = Board::embedded_default().unwrap();
        let rig = RigConfig::embedded_default().unwrap();
        let c = b.drive_config(&rig).unwrap();
        assert!(c.overcurrent_trip_a as f64 <= b.phase_current_max_peak_a() + 1e-3);
        assert!(c.overcurrent_trip_a < c.current_sense_full_scale_a);
        assert!(c.overcurrent_trip_a >= c.max_current_a);
        assert!(c.dc_bus_overvoltage_v as f64 <= b.ratings.dc_bus_max_v);
        assert!(c.dc_bus_undervoltage_v as f64 >= b.ratings.dc_bus_min_v);
        assert!(c.dc_bus_undervoltage_v < c.dc_bus_nominal_v && c.dc_bus_nominal_v < c.dc_bus_overvoltage_v);
        assert!(c.dc_bus_overvoltage_v < c.dc_bus_sense_full_scale_v);
    }

    /// The commanded alignment on the board, closed around a star-connected
    /// R-L machine held at rest (ideal inverter, phase voltages from the
    /// compares and the bus), the shunt amplifiers as the board has them
    /// (inverting) and the firmware's mirror of the codes when the
    /// description says they invert (`firmware/src/adc.rs`); returns the
    /// largest phase current, A, and the fault, with whether the outputs
    /// ended off and the brake applied. `r`: the machine's phase resistance, ohm.
    fn align_on_the_board(mirror_codes: bool, r: f64) -> (f64, Option<drive_core::startup::StartupFault>, bool) {
        use drive_core::startup::{Startup, StartupCommand, StartupEvent, StartupStep};
        let board = Board::embedded_default().unwrap();
        let rig = RigConfig::embedded_default().unwrap();
        let config = board.drive_config(&rig).unwrap();
        let mut startup = Startup::new(&config, *drive_core::Controller::new(&config).supervisor_limits());
        let lsb = config.current_sense_full_scale_a as f64 / 2048.0;
        let bus_v = board.operation.dc_bus_nominal_v;
        let bus_code = (bus_v / config.dc_bus_sense_full_scale_v as f64 * 4095.0).round() as u16;
        let l = rig.motor.ld_h;
        let dt = 1.0 / config.current_loop_hz as f64;
        let period = config.pwm_period_counts as f64;
        let mut i = [0.0f64; 3];
        let mut peak: f64 = 0.0;
        let mut fault = None;
        let mut safe_after = false;
        for n in 0..16_000 {
            // The board's amplifier inverts: a current into the machine reads below mid-scale.
            let raw = i.map(|x| (2048.0 - x / lsb).round().clamp(0.0, 4095.0) as u16);
            let codes = if mirror_codes { raw.map(|c| 4095 - c) } else { raw };
            if n == 2000 {
                assert!(startup.is_waiting_for_alignment());
                startup.command(StartupCommand::Align).unwrap();
            }
            let out = match startup.step(codes, bus_code, 1000) {
                StartupStep::Drive(out) => out,
                StartupStep::Run(_) => break,
            };
            if let Some(StartupEvent::Fault(f)) = out.event {
                fault = Some(f);
            }
            if fault.is_some() {
                safe_after = !out.pwm_on && !out.brake_released;
                if n > 2000 + 100 && out.event.is_none() {
                    break;
                }
            }
            let v = if out.pwm_on { out.compare.map(|c| c as f64 / period * bus_v) } else { [0.0; 3] };
            let mean = (v[0] + v[1] + v[2]) / 3.0;
            for k in 0..3 {
                // Outputs off: the currents decay through the body diodes (taken as zero voltage).
                i[k] += (v[k] - mean - r * i[k]) / l * dt;
            }
            peak = peak.max(i.iter().fold(0.0f64, |m, x| m.max(x.abs())));
        }
        (peak, fault, safe_after)
    }

    #[test]
    fn the_alignment_on_the_board_reaches_its_current_without_a_trip() {
        let rig = RigConfig::embedded_default().unwrap();
        let (peak, fault, _) = align_on_the_board(true, rig.motor.stator_resistance_ohm);
        assert_eq!(fault, None);
        assert!(peak > 5.0 && peak < 15.0, "{peak} A");
    }

    /// A current-sign error at start-up (the amplifiers' inversion not
    /// taken out): the loop runs away to the voltage limit. With the rig's
    /// machine (1.2 ohm) that limit is 16.5 A on the 36 V bus and the
    /// alignment refuses the current it never reaches; with a machine of
    /// 0.1 ohm the over-current protection trips. Either way the current
    /// stays below the board's rated peak, and the drive ends with gates
    /// off and the brake applied.
    #[test]
    fn a_current_sign_error_at_start_up_trips_before_the_board_limit() {
        use drive_core::startup::StartupFault;
        let board = Board::embedded_default().unwrap();
        let rig = RigConfig::embedded_default().unwrap();
        for (r, expected) in [
            (
                rig.motor.stator_resistance_ohm,
                StartupFault::Alignment(drive_core::alignment::AlignmentError::CurrentNotReached),
            ),
            (0.1, StartupFault::Protection(drive_core::supervisor::Fault::OverCurrent)),
        ] {
            let (peak, fault, safe) = align_on_the_board(false, r);
            assert_eq!(fault, Some(expected), "{r} ohm: peak {peak} A");
            assert!(peak < board.phase_current_max_peak_a() + 0.5, "{r} ohm: {peak} A");
            assert!(peak < board.current_full_scale_a());
            assert!(safe, "{r} ohm: gates off and brake applied after the trip");
        }
    }

    #[test]
    fn a_description_without_a_pin_is_refused() {
        let text = EMBEDDED_BOARD_TOML.replacen("name = \"DcpDe\"", "name = \"Other\"", 1);
        assert!(Board::from_toml_str(&text, "test").is_err());
    }
}
