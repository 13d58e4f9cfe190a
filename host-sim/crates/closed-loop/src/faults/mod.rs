//! Fault injection in the closed loop: what can go wrong with the
//! sensors, the power stage, the bus, the control timing, the link, the load
//! and the brake, injected between the plant and the controller or in the
//! plant, several at once; and the runs of `host-sim faults`.
//!
//! A fault is a [`FaultKind`] with its parameters and an onset
//! ([`FaultSpec`]). On the command line: `KIND@WHEN[:KEY=VALUE,...]`, e.g.
//! `current-stuck@accel:phase=a,value_a=2` or `short@4.2`; in a TOML file
//! one `[[fault]]` table per fault with `kind`, `at` and the same keys.
//! `WHEN` is seconds from the travel command or a named instant of the
//! travel ([`Instant`]).
//!
//! - [`inject`]: the [`crate::FaultHook`] that applies them;
//! - [`run`]: one faulted travel and what it did (detection time, reason,
//!   peaks, displacement after detection), and the case matrix of
//!   `host-sim faults`.

pub mod inject;
pub mod run;

use std::collections::BTreeMap;
use std::fmt;

/// A named instant of a travel, resolved against its profile.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Instant {
    /// The travel command (pre-torque with the brake applied), t = 0.
    Start,
    /// In the acceleration: 0.6 s after the profile starts.
    Accel,
    /// Mid-way through the travel, at rated speed.
    Cruise,
    /// In the deceleration: 0.6 s before the profile ends.
    Decel,
}

impl Instant {
    /// Every named instant.
    pub const ALL: [Instant; 4] = [Instant::Start, Instant::Accel, Instant::Cruise, Instant::Decel];

    /// Its name on the command line and in tables.
    pub fn name(self) -> &'static str {
        match self {
            Instant::Start => "start",
            Instant::Accel => "accel",
            Instant::Cruise => "cruise",
            Instant::Decel => "decel",
        }
    }

    /// Time from the travel command, s, for a profile of `profile_duration_s`
    /// (s) that starts `profile_start_s` (s) after the command.
    pub fn time_s(self, profile_start_s: f64, profile_duration_s: f64) -> f64 {
        match self {
            Instant::Start => 0.0,
            Instant::Accel => profile_start_s + 0.6,
            Instant::Cruise => profile_start_s + 0.5 * profile_duration_s,
            Instant::Decel => profile_start_s + profile_duration_s - 0.6,
        }
    }
}

/// When a fault starts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Onset {
    /// Seconds after the travel command.
    At(f64),
    /// A named instant of the travel.
    Named(Instant),
}

/// A machine phase, or an inverter leg.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// Phase a (index 0).
    A,
    /// Phase b (index 1).
    B,
    /// Phase c (index 2).
    C,
}

impl Phase {
    /// Index 0..3.
    pub fn index(self) -> usize {
        match self {
            Phase::A => 0,
            Phase::B => 1,
            Phase::C => 2,
        }
    }

    fn parse(key: &str, value: &str) -> Result<Self, FaultParseError> {
        match value {
            "a" | "A" => Ok(Phase::A),
            "b" | "B" => Ok(Phase::B),
            "c" | "C" => Ok(Phase::C),
            _ => Err(FaultParseError::value(key, value, "a, b or c")),
        }
    }
}

/// What a disconnected phase-current sensor reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DisconnectedReading {
    /// The top ADC code (full scale).
    FullScale,
    /// ADC code 0 (the output pulled to ground).
    ZeroCode,
}

/// A fault and its parameters (SI units as named).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FaultKind {
    /// `current-stuck`: a phase-current reading frozen at `value_a` (A).
    CurrentStuck {
        /// Phase.
        phase: Phase,
        /// The reading, A.
        value_a: f64,
    },
    /// `current-disconnected`: a phase-current sensor reads full scale or code 0.
    CurrentDisconnected {
        /// Phase.
        phase: Phase,
        /// What it reads.
        reads: DisconnectedReading,
    },
    /// `current-drift`: a phase-current offset growing at `rate_a_per_s` (A/s).
    CurrentDrift {
        /// Phase.
        phase: Phase,
        /// Drift rate, A/s.
        rate_a_per_s: f64,
    },
    /// `encoder-lose`: the encoder misses a `fraction` (0..1) of its counts.
    EncoderLosingCounts {
        /// Fraction of the counts lost, dimensionless.
        fraction: f64,
    },
    /// `encoder-jump`: the counter jumps by `counts` once.
    EncoderJump {
        /// Jump, counts.
        counts: i64,
    },
    /// `encoder-stop`: the counter stops while the shaft turns.
    EncoderStopped,
    /// `short`: a phase-to-phase short between two inverter outputs.
    PhaseShort {
        /// Leg the short current leaves.
        from: Phase,
        /// Leg it enters.
        to: Phase,
        /// Resistance, ohm.
        resistance_ohm: f64,
        /// Inductance, H.
        inductance_h: f64,
    },
    /// `open-phase`: a machine phase disconnected.
    OpenPhase {
        /// Phase.
        phase: Phase,
    },
    /// `bus-sag`: the DC bus falls to `to_v` (V) at `rate_v_per_s` (V/s).
    DcBusSag {
        /// Final bus voltage, V.
        to_v: f64,
        /// Rate, V/s.
        rate_v_per_s: f64,
    },
    /// `bus-over`: the DC bus rises to `to_v` (V) at `rate_v_per_s` (V/s): the
    /// regenerated energy of a car going down loaded with the braking
    /// chopper failed.
    DcBusOverVoltage {
        /// Final bus voltage, V.
        to_v: f64,
        /// Rate, V/s.
        rate_v_per_s: f64,
    },
    /// `deadline-skip`: `steps` consecutive control steps do not run.
    DeadlineSkip {
        /// Steps skipped.
        steps: u32,
    },
    /// `deadline-late`: one control step runs `delay_us` (us) late.
    DeadlineLate {
        /// Delay, microseconds.
        delay_us: f64,
    },
    /// `load-change`: the car load changes suddenly by `delta_kg` (kg; a
    /// slack rope or a shifting load: negative, the car side loses weight).
    LoadChange {
        /// Change of car mass seen by the ropes, kg.
        delta_kg: f64,
    },
    /// `brake-stuck`: the brake does not open when commanded.
    BrakeNotOpening,
    /// `frame-corrupt`: `count` consecutive sensor frames corrupted on the
    /// link (byte `byte` of the encoding XOR `xor`).
    FrameCorruption {
        /// Frames corrupted.
        count: u32,
        /// Byte index in the encoded frame.
        byte: usize,
        /// Bits flipped.
        xor: u8,
    },
}

/// The kinds' names, in the order of the issue.
pub const KIND_NAMES: [&str; 16] = [
    "current-stuck",
    "current-disconnected",
    "current-drift",
    "encoder-lose",
    "encoder-jump",
    "encoder-stop",
    "short",
    "open-phase",
    "bus-sag",
    "bus-over",
    "deadline-skip",
    "deadline-late",
    "load-change",
    "brake-stuck",
    "frame-corrupt",
    "none",
];

impl FaultKind {
    /// The kind's name (`current-stuck`, ...).
    pub fn name(&self) -> &'static str {
        match self {
            FaultKind::CurrentStuck { .. } => "current-stuck",
            FaultKind::CurrentDisconnected { .. } => "current-disconnected",
            FaultKind::CurrentDrift { .. } => "current-drift",
            FaultKind::EncoderLosingCounts { .. } => "encoder-lose",
            FaultKind::EncoderJump { .. } => "encoder-jump",
            FaultKind::EncoderStopped => "encoder-stop",
            FaultKind::PhaseShort { .. } => "short",
            FaultKind::OpenPhase { .. } => "open-phase",
            FaultKind::DcBusSag { .. } => "bus-sag",
            FaultKind::DcBusOverVoltage { .. } => "bus-over",
            FaultKind::DeadlineSkip { .. } => "deadline-skip",
            FaultKind::DeadlineLate { .. } => "deadline-late",
            FaultKind::LoadChange { .. } => "load-change",
            FaultKind::BrakeNotOpening => "brake-stuck",
            FaultKind::FrameCorruption { .. } => "frame-corrupt",
        }
    }

    /// Its parameters in words, for tables (`phase a, 0 A`, `-50 kg`, ...).
    pub fn parameters(&self) -> String {
        let ph = |p: &Phase| ["a", "b", "c"][p.index()];
        match self {
            FaultKind::CurrentStuck { phase, value_a } => format!("phase {}, {value_a} A", ph(phase)),
            FaultKind::CurrentDisconnected { phase, reads } => format!(
                "phase {}, {}",
                ph(phase),
                match reads {
                    DisconnectedReading::FullScale => "full scale",
                    DisconnectedReading::ZeroCode => "code 0",
                }
            ),
            FaultKind::CurrentDrift { phase, rate_a_per_s } => format!("phase {}, {rate_a_per_s} A/s", ph(phase)),
            FaultKind::EncoderLosingCounts { fraction } => format!("{} % lost", fraction * 100.0),
            FaultKind::EncoderJump { counts } => format!("{counts:+} counts"),
            FaultKind::EncoderStopped | FaultKind::BrakeNotOpening => String::new(),
            FaultKind::PhaseShort { from, to, resistance_ohm, inductance_h } => {
                format!("{}-{}, {resistance_ohm} ohm, {} uH", ph(from), ph(to), inductance_h * 1e6)
            }
            FaultKind::OpenPhase { phase } => format!("phase {}", ph(phase)),
            FaultKind::DcBusSag { to_v, rate_v_per_s } | FaultKind::DcBusOverVoltage { to_v, rate_v_per_s } => {
                format!("to {to_v} V at {rate_v_per_s} V/s")
            }
            FaultKind::DeadlineSkip { steps } => format!("{steps} steps"),
            FaultKind::DeadlineLate { delay_us } => format!("{delay_us} us late"),
            FaultKind::LoadChange { delta_kg } => format!("{delta_kg:+} kg"),
            FaultKind::FrameCorruption { count, byte, xor } => format!("{count} frames, byte {byte} ^ {xor:#04x}"),
        }
    }

    /// The kind `name` with its default parameters overridden by `params`
    /// (key -> value as written). Errors name the key and what was expected.
    pub fn from_name(name: &str, params: &BTreeMap<String, String>) -> Result<Self, FaultParseError> {
        let mut p = Params { map: params.clone(), kind: name.to_string() };
        let kind = match name {
            "current-stuck" => FaultKind::CurrentStuck {
                phase: p.phase("phase", Phase::A)?,
                value_a: p.number("value_a", 0.0, -1.0e3, 1.0e3)?,
            },
            "current-disconnected" => FaultKind::CurrentDisconnected {
                phase: p.phase("phase", Phase::A)?,
                reads: match p.take("reads").as_deref() {
                    None | Some("full-scale") => DisconnectedReading::FullScale,
                    Some("zero-code") => DisconnectedReading::ZeroCode,
                    Some(other) => return Err(FaultParseError::value("reads", other, "full-scale or zero-code")),
                },
            },
            "current-drift" => FaultKind::CurrentDrift {
                phase: p.phase("phase", Phase::A)?,
                rate_a_per_s: p.number("rate_a_per_s", 20.0, -1.0e6, 1.0e6)?,
            },
            "encoder-lose" => FaultKind::EncoderLosingCounts { fraction: p.number("fraction", 0.25, 0.0, 1.0)? },
            "encoder-jump" => FaultKind::EncoderJump { counts: p.number("counts", 200.0, -1.0e9, 1.0e9)? as i64 },
            "encoder-stop" => FaultKind::EncoderStopped,
            "short" => FaultKind::PhaseShort {
                from: p.phase("from", Phase::A)?,
                to: p.phase("to", Phase::B)?,
                resistance_ohm: p.number("resistance_ohm", 0.1, 1.0e-4, 1.0e3)?,
                inductance_h: p.number("inductance_h", 20.0e-6, 1.0e-8, 1.0)?,
            },
            "open-phase" => FaultKind::OpenPhase { phase: p.phase("phase", Phase::A)? },
            "bus-sag" => FaultKind::DcBusSag {
                to_v: p.number("to_v", 50.0, 0.0, 1.0e4)?,
                rate_v_per_s: p.number("rate_v_per_s", 1000.0, 1.0e-3, 1.0e9)?,
            },
            "bus-over" => FaultKind::DcBusOverVoltage {
                to_v: p.number("to_v", 150.0, 0.0, 1.0e4)?,
                rate_v_per_s: p.number("rate_v_per_s", 500.0, 1.0e-3, 1.0e9)?,
            },
            "deadline-skip" => FaultKind::DeadlineSkip { steps: p.number("steps", 3.0, 1.0, 1.0e7)? as u32 },
            "deadline-late" => FaultKind::DeadlineLate { delay_us: p.number("delay_us", 120.0, 0.0, 1.0e6)? },
            "load-change" => FaultKind::LoadChange { delta_kg: p.number("delta_kg", -50.0, -1.0e4, 1.0e4)? },
            "brake-stuck" => FaultKind::BrakeNotOpening,
            "frame-corrupt" => FaultKind::FrameCorruption {
                count: p.number("count", 3.0, 1.0, 1.0e7)? as u32,
                byte: p.number("byte", 8.0, 0.0, 69.0)? as usize,
                xor: p.number("xor", 16.0, 1.0, 255.0)? as u8,
            },
            other => {
                return Err(FaultParseError::UnknownKind(other.to_string()));
            }
        };
        p.finish()?;
        if let FaultKind::PhaseShort { from, to, .. } = kind {
            if from == to {
                return Err(FaultParseError::value("to", "the same phase as from", "a different phase than from"));
            }
        }
        Ok(kind)
    }
}

/// One fault to inject: what and when.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaultSpec {
    /// The fault.
    pub kind: FaultKind,
    /// Its onset.
    pub onset: Onset,
}

impl fmt::Display for FaultSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.onset {
            Onset::At(t) => write!(f, "{}@{t}", self.kind.name()),
            Onset::Named(instant) => write!(f, "{}@{}", self.kind.name(), instant.name()),
        }
    }
}

/// Why a fault description was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FaultParseError {
    /// The text is not `KIND@WHEN[:KEY=VALUE,...]`.
    #[error("--fault {0:?}: expected KIND@WHEN[:KEY=VALUE,...], e.g. current-stuck@accel:phase=a,value_a=2")]
    Syntax(String),
    /// Unknown kind.
    #[error("unknown fault kind {0:?}: expected one of {kinds}", kinds = KIND_NAMES[..15].join(", "))]
    UnknownKind(String),
    /// A value out of range or of the wrong form.
    #[error("fault parameter {key} = {value:?}: expected {expected}")]
    Value {
        /// The key.
        key: String,
        /// The value given.
        value: String,
        /// What is accepted.
        expected: String,
    },
    /// A key the kind does not have.
    #[error("fault {kind}: unknown parameter {key:?} (accepted: {accepted})")]
    UnknownKey {
        /// The kind.
        kind: String,
        /// The key given.
        key: String,
        /// The keys of that kind.
        accepted: String,
    },
    /// TOML syntax or structure.
    #[error("fault file: {0}")]
    Toml(String),
}

impl FaultParseError {
    fn value(key: &str, value: &str, expected: &str) -> Self {
        FaultParseError::Value { key: key.to_string(), value: value.to_string(), expected: expected.to_string() }
    }
}

/// The parameters of one fault as given, consumed key by key.
struct Params {
    map: BTreeMap<String, String>,
    kind: String,
    // Keys the kind accepts are collected for the error message.
}

impl Params {
    fn take(&mut self, key: &str) -> Option<String> {
        self.map.remove(key)
    }

    fn phase(&mut self, key: &str, default: Phase) -> Result<Phase, FaultParseError> {
        match self.take(key) {
            None => Ok(default),
            Some(v) => Phase::parse(key, &v),
        }
    }

    fn number(&mut self, key: &str, default: f64, min: f64, max: f64) -> Result<f64, FaultParseError> {
        let Some(text) = self.take(key) else { return Ok(default) };
        match text.parse::<f64>() {
            Ok(v) if v.is_finite() && (min..=max).contains(&v) => Ok(v),
            _ => Err(FaultParseError::value(key, &text, &format!("a number in [{min}, {max}]"))),
        }
    }

    fn finish(self) -> Result<(), FaultParseError> {
        match self.map.into_keys().next() {
            None => Ok(()),
            Some(key) => Err(FaultParseError::UnknownKey {
                accepted: accepted_keys(&self.kind).join(", "),
                kind: self.kind,
                key,
            }),
        }
    }
}

/// The parameter keys of a kind.
pub fn accepted_keys(kind: &str) -> &'static [&'static str] {
    match kind {
        "current-stuck" => &["phase", "value_a"],
        "current-disconnected" => &["phase", "reads"],
        "current-drift" => &["phase", "rate_a_per_s"],
        "encoder-lose" => &["fraction"],
        "encoder-jump" => &["counts"],
        "short" => &["from", "to", "resistance_ohm", "inductance_h"],
        "open-phase" => &["phase"],
        "bus-sag" | "bus-over" => &["to_v", "rate_v_per_s"],
        "deadline-skip" => &["steps"],
        "deadline-late" => &["delay_us"],
        "load-change" => &["delta_kg"],
        "frame-corrupt" => &["count", "byte", "xor"],
        _ => &[],
    }
}

fn parse_onset(text: &str) -> Result<Onset, FaultParseError> {
    for instant in Instant::ALL {
        if text == instant.name() {
            return Ok(Onset::Named(instant));
        }
    }
    match text.parse::<f64>() {
        Ok(t) if t.is_finite() && t >= 0.0 => Ok(Onset::At(t)),
        _ => Err(FaultParseError::value("when", text, "seconds >= 0 or one of start, accel, cruise, decel")),
    }
}

/// Parses `KIND@WHEN[:KEY=VALUE,...]`.
pub fn parse_fault(text: &str) -> Result<FaultSpec, FaultParseError> {
    let (head, params) = match text.split_once(':') {
        Some((head, params)) => (head, params),
        None => (text, ""),
    };
    let (kind, when) = head.split_once('@').ok_or_else(|| FaultParseError::Syntax(text.to_string()))?;
    let mut map = BTreeMap::new();
    for pair in params.split(',').filter(|p| !p.trim().is_empty()) {
        let (key, value) = pair.split_once('=').ok_or_else(|| FaultParseError::Syntax(text.to_string()))?;
        map.insert(key.trim().to_string(), value.trim().to_string());
    }
    Ok(FaultSpec { kind: FaultKind::from_name(kind.trim(), &map)?, onset: parse_onset(when.trim())? })
}

/// Parses the `[[fault]]` tables of a TOML document: `kind`, `at` (seconds
/// or a named instant) and the kind's keys.
pub fn parse_fault_toml(text: &str) -> Result<Vec<FaultSpec>, FaultParseError> {
    let doc: toml::Table = text.parse().map_err(|e: toml::de::Error| FaultParseError::Toml(e.to_string()))?;
    for key in doc.keys() {
        if key != "fault" {
            return Err(FaultParseError::Toml(format!("unknown top-level key {key:?}: expected [[fault]] tables")));
        }
    }
    let Some(faults) = doc.get("fault") else { return Ok(Vec::new()) };
    let faults = faults.as_array().ok_or_else(|| FaultParseError::Toml("`fault` must be [[fault]] tables".into()))?;
    faults
        .iter()
        .enumerate()
        .map(|(i, entry)| {
            let table =
                entry.as_table().ok_or_else(|| FaultParseError::Toml(format!("fault {}: not a table", i + 1)))?;
            let mut map = BTreeMap::new();
            for (key, value) in table {
                let text = match value {
                    toml::Value::String(s) => s.clone(),
                    toml::Value::Integer(n) => n.to_string(),
                    toml::Value::Float(x) => x.to_string(),
                    other => {
                        return Err(FaultParseError::Toml(format!(
                            "fault {}: field {key} = {other}: expected a string or a number",
                            i + 1
                        )))
                    }
                };
                map.insert(key.clone(), text);
            }
            let kind =
                map.remove("kind").ok_or_else(|| FaultParseError::Toml(format!("fault {}: missing `kind`", i + 1)))?;
            let at = map.remove("at").ok_or_else(|| FaultParseError::Toml(format!("fault {}: missing `at`", i + 1)))?;
            Ok(FaultSpec { kind: FaultKind::from_name(&kind, &map)?, onset: parse_onset(&at)? })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn command_line_faults_parse_with_defaults_and_overrides() {
        let f = parse_fault("current-stuck@accel:phase=b,value_a=2.5").unwrap();
        assert_eq!(f.kind, FaultKind::CurrentStuck { phase: Phase::B, value_a: 2.5 });
        assert_eq!(f.onset, Onset::Named(Instant::Accel));
        let f = parse_fault("encoder-stop@3.25").unwrap();
        assert_eq!((f.kind, f.onset), (FaultKind::EncoderStopped, Onset::At(3.25)));
        for name in &KIND_NAMES[..15] {
            let spec = parse_fault(&format!("{name}@cruise")).unwrap();
            assert_eq!(spec.kind.name(), *name);
        }
    }

    #[test]
    fn bad_fault_text_is_refused_naming_what_is_wrong() {
        let cases = [
            ("current-stuck", "expected KIND@WHEN"),
            ("warp-core@1", "unknown fault kind"),
            ("current-stuck@-1", "seconds >= 0"),
            ("current-stuck@1:phase=d", "a, b or c"),
            ("current-stuck@1:value_a=NaN", "value_a"),
            ("encoder-lose@1:fraction=1.5", "fraction"),
            ("encoder-lose@1:speed=2", "unknown parameter \"speed\""),
            ("short@1:from=a,to=a", "different phase"),
        ];
        for (text, needle) in cases {
            let message = parse_fault(text).unwrap_err().to_string();
            assert!(message.contains(needle), "{text}: {message}");
        }
    }

    #[test]
    fn toml_fault_tables_parse_and_errors_name_the_entry() {
        let faults = parse_fault_toml(
            "[[fault]]\nkind = \"short\"\nat = 4.0\nresistance_ohm = 0.2\n\n[[fault]]\nkind = \"brake-stuck\"\nat = \"start\"\n",
        )
        .unwrap();
        assert_eq!(faults.len(), 2);
        assert!(matches!(faults[0].kind, FaultKind::PhaseShort { resistance_ohm, .. } if resistance_ohm == 0.2));
        assert_eq!(faults[1].onset, Onset::Named(Instant::Start));
        let e = parse_fault_toml("[[fault]]\nkind = \"short\"\n").unwrap_err().to_string();
        assert!(e.contains("fault 1: missing `at`"), "{e}");
        let e = parse_fault_toml("[fault]\nkind = 1\n").unwrap_err().to_string();
        assert!(e.contains("[[fault]]"), "{e}");
    }
}
