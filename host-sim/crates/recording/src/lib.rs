//! Recordings in the project's measurement format, version 1
//! (`shared/spec/measurement-format.md`).
//!
//! A recording is a pair of files with the same stem in a dataset
//! directory: `<stem>.toml` (metadata) and `<stem>.csv` (samples, one column
//! per signal, found by header name). This crate holds the in-memory types
//! shared by the writer ([`write`](mod@write)) and the reader ([`read`]); the
//! column-name constants below are the header names of the specification.
//! [`evimp`] reads the `EVIMP1` text export of lift ride-quality analyzers.
//!
//! In the data flow config -> plant <-> controller -> recording -> analysis
//! -> diagnosis this crate is the recording: the closed loop writes it, the
//! analysis and the diagnosis read it. It depends on no other crate of the
//! project.

#![warn(missing_docs)]

use std::path::PathBuf;

pub mod consistency;
pub mod evimp;
pub mod read;
pub mod write;

pub use evimp::{read_evimp, EvimpRecording};
pub use read::{
    parse_dataset, parse_recording, read_columns, read_dataset, read_meta, read_recording, ReadError, META_FIELDS,
};
pub use write::write_recording;

/// Value of the metadata field `format` for version 1 of the format.
pub const FORMAT: &str = "elevator-measurement/1";

/// Column `time_s`: sample time from the start of the recording, s.
/// Required for every kind.
pub const TIME_S: &str = "time_s";
/// Column `acc_car_mps2`: vertical acceleration of the car frame, m/s^2,
/// positive up. Required for every kind.
pub const ACC_CAR: &str = "acc_car_mps2";
/// Column `acc_cw_mps2`: vertical acceleration of the counterweight frame,
/// m/s^2, positive up. Optional.
pub const ACC_CW: &str = "acc_cw_mps2";
/// Column `acc_machine_mps2`: vertical acceleration of the machine frame,
/// m/s^2, positive up. Optional.
pub const ACC_MACHINE: &str = "acc_machine_mps2";
/// Column `i_a_A`: phase current a into the machine, A. Required for travel.
pub const I_A: &str = "i_a_A";
/// Column `i_b_A`: phase current b into the machine, A. Required for travel.
pub const I_B: &str = "i_b_A";
/// Column `i_c_A`: phase current c into the machine, A. Required for travel.
pub const I_C: &str = "i_c_A";
/// Column `speed_radps`: machine shaft speed as the drive's (filtered)
/// encoder speed estimate reports it, rad/s, positive when the car moves up.
/// Required for travel.
pub const SPEED: &str = "speed_radps";
/// Column `angle_rad`: mechanical shaft angle from the encoder, unwrapped,
/// rad. Optional.
pub const ANGLE: &str = "angle_rad";
/// Column `ref_speed_mps`: reference speed of a sheave-edge point given to
/// the drive, m/s. Optional.
pub const REF_SPEED: &str = "ref_speed_mps";

/// The physical bound of every column the specification defines: the
/// largest magnitude a sample may have, with its unit and what it bounds.
/// Far beyond any rig (an elevator's car accelerates at about 1 m/s^2, its
/// machine turns at a few rad/s), far below where arithmetic on the values
/// overflows: the reader refuses a sample past it as a corrupt value, naming
/// the file, line and column. Unknown columns are only required to be finite.
pub const COLUMN_BOUNDS: [(&str, f64, &str); 10] = [
    (TIME_S, 1.0e9, "s (about 32 years)"),
    (ACC_CAR, 1.0e4, "m/s^2 (about 1000 g)"),
    (ACC_CW, 1.0e4, "m/s^2 (about 1000 g)"),
    (ACC_MACHINE, 1.0e4, "m/s^2 (about 1000 g)"),
    (I_A, 1.0e5, "A"),
    (I_B, 1.0e5, "A"),
    (I_C, 1.0e5, "A"),
    (SPEED, 1.0e4, "rad/s (about 95 000 rpm)"),
    (ANGLE, 1.0e9, "rad"),
    (REF_SPEED, 100.0, "m/s"),
];

/// The bound of column `name` in [`COLUMN_BOUNDS`] (largest magnitude and
/// its unit), or `None` for a column the specification does not define.
pub fn column_bound(name: &str) -> Option<(f64, &'static str)> {
    COLUMN_BOUNDS.iter().find(|(n, _, _)| *n == name).map(|&(_, bound, unit)| (bound, unit))
}

/// Largest metadata values the reader accepts (the rig file's own bounds):
/// sample rate, Hz.
pub const MAX_SAMPLE_RATE_HZ: f64 = 1.0e7;
/// Smallest sample rate the reader accepts, Hz: slower, a recording holds
/// nothing of a lift's vibration (the format's accelerometers are not to be
/// trusted below 0.5 Hz, which a 1 Hz rate cannot even resolve).
pub const MIN_SAMPLE_RATE_HZ: f64 = 1.0;
/// Largest mass (car, counterweight, free-decay mass), kg.
pub const MAX_MASS_KG: f64 = 1.0e5;
/// Largest free-decay rope length, m.
pub const MAX_ROPE_LENGTH_M: f64 = 1.0e3;
/// Largest metadata file (`<stem>.toml`) read, bytes (a real one is a few
/// hundred).
pub const MAX_META_BYTES: u64 = 1 << 20;
/// Longest line of a samples file or an EVIMP export, bytes, line end
/// excluded (a row of ten columns is about 250).
pub const MAX_LINE_BYTES: usize = 1 << 20;

/// Every column the specification defines, in the order of its table.
pub const KNOWN_COLUMNS: [&str; 10] = [TIME_S, ACC_CAR, ACC_CW, ACC_MACHINE, I_A, I_B, I_C, SPEED, ANGLE, REF_SPEED];

/// Columns required in a `travel` recording.
pub const TRAVEL_REQUIRED_COLUMNS: [&str; 6] = [TIME_S, ACC_CAR, I_A, I_B, I_C, SPEED];
/// Columns required in a `free_decay` recording.
pub const FREE_DECAY_REQUIRED_COLUMNS: [&str; 2] = [TIME_S, ACC_CAR];

/// Direction the car moves in during a travel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CarDirection {
    /// Car moves up: the car-side rope shortens, the counterweight-side rope
    /// length `lw` grows.
    Up,
    /// Car moves down: `lw` shrinks.
    Down,
}

impl CarDirection {
    /// Text of the metadata field `direction`: `"up"` or `"down"`.
    pub fn as_str(self) -> &'static str {
        match self {
            CarDirection::Up => "up",
            CarDirection::Down => "down",
        }
    }
}

/// What was recorded, with the kind's metadata fields.
#[derive(Debug, Clone, PartialEq)]
pub enum RecordingKind {
    /// A travel of the car driven by the machine (`kind = "travel"`).
    Travel {
        /// Car mass, kg (> 0).
        m_car_kg: f64,
        /// Counterweight mass, kg (> 0).
        m_cw_kg: f64,
        /// Car direction.
        direction: CarDirection,
        /// Counterweight-side rope length at the start, m (> 0).
        lw_start_m: f64,
        /// Counterweight-side rope length at the end, m (> 0; larger than
        /// `lw_start_m` when the car goes up, smaller when it goes down).
        lw_end_m: f64,
    },
    /// A mass hanging from a rope whose top end is fixed, machine not
    /// running; the transient is in `acc_car_mps2` (`kind = "free_decay"`).
    FreeDecay {
        /// Hanging mass, kg (> 0).
        mass_kg: f64,
        /// Rope length from the fixed end to the mass, m (> 0).
        rope_length_m: f64,
    },
}

impl RecordingKind {
    /// Text of the metadata field `kind`: `"travel"` or `"free_decay"`.
    pub fn name(&self) -> &'static str {
        match self {
            RecordingKind::Travel { .. } => "travel",
            RecordingKind::FreeDecay { .. } => "free_decay",
        }
    }

    /// Header names of the columns this kind requires.
    pub fn required_columns(&self) -> &'static [&'static str] {
        match self {
            RecordingKind::Travel { .. } => &TRAVEL_REQUIRED_COLUMNS,
            RecordingKind::FreeDecay { .. } => &FREE_DECAY_REQUIRED_COLUMNS,
        }
    }
}

/// Metadata of a recording (the `<stem>.toml` file, apart from `format`).
#[derive(Debug, Clone, PartialEq)]
pub struct RecordingMeta {
    /// Kind of recording and its fields.
    pub kind: RecordingKind,
    /// Sample rate, Hz (> 0); `time_s` advances by `1 / sample_rate_hz`.
    pub sample_rate_hz: f64,
    /// Optional free text.
    pub description: Option<String>,
}

/// One signal: a header name and one value per sample, in the column's unit
/// (see the column-name constants, e.g. [`ACC_CAR`] in m/s^2).
#[derive(Debug, Clone, PartialEq)]
pub struct Column {
    /// Header name, e.g. [`TIME_S`].
    pub name: String,
    /// Samples, in the column's unit.
    pub values: Vec<f64>,
}

impl Column {
    /// Column from a header name and its samples (in the column's unit).
    pub fn new(name: impl Into<String>, values: Vec<f64>) -> Self {
        Self { name: name.into(), values }
    }
}

/// A complete recording: metadata plus columns of equal length.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    /// Metadata.
    pub meta: RecordingMeta,
    /// Columns in file order; names unique.
    pub columns: Vec<Column>,
}

impl Recording {
    /// The column with header `name`, if present.
    pub fn column(&self, name: &str) -> Option<&Column> {
        self.columns.iter().find(|c| c.name == name)
    }
}

/// Error from writing (and validating) a recording. Each variant names the
/// field, column or file that is wrong and what was expected.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// A metadata value is out of its physical range or not finite.
    #[error("metadata field `{field}` = {value} is invalid; expected {expected}")]
    InvalidMeta {
        /// Field name as in the TOML file, e.g. `m_car_kg`.
        field: &'static str,
        /// The value given.
        value: f64,
        /// Accepted range.
        expected: &'static str,
    },
    /// `direction` disagrees with the change of `lw`.
    #[error("metadata field `direction` = \"{direction}\" contradicts lw_start_m = {lw_start_m} m and lw_end_m = {lw_end_m} m; expected lw_end_m {expected} lw_start_m")]
    DirectionMismatch {
        /// Direction given (`"up"` or `"down"`).
        direction: &'static str,
        /// Counterweight-side rope length at the start, m.
        lw_start_m: f64,
        /// Counterweight-side rope length at the end, m.
        lw_end_m: f64,
        /// Required relation (`">"` for up, `"<"` for down).
        expected: &'static str,
    },
    /// The file stem cannot be used as a file name.
    #[error("recording stem {stem:?} is invalid; expected {expected}")]
    InvalidStem {
        /// The stem given.
        stem: String,
        /// What a stem must look like.
        expected: &'static str,
    },
    /// A column header name is unusable.
    #[error("column name {name:?} is invalid; expected {expected}")]
    InvalidColumnName {
        /// The name given.
        name: String,
        /// What a name must look like.
        expected: &'static str,
    },
    /// Two columns have the same header name.
    #[error("column `{name}` appears more than once; expected unique column names")]
    DuplicateColumn {
        /// The repeated name.
        name: String,
    },
    /// A column required by the recording kind is missing.
    #[error("column `{column}` is missing; a `{kind}` recording requires it")]
    MissingColumn {
        /// Name of the missing column.
        column: &'static str,
        /// Recording kind (`travel` or `free_decay`).
        kind: &'static str,
    },
    /// The recording has no samples.
    #[error("column `time_s` has no samples; expected at least one sample")]
    Empty,
    /// Columns differ in length.
    #[error("column `{column}` has {len} samples but `time_s` has {expected}; expected equal lengths")]
    LengthMismatch {
        /// Name of the offending column.
        column: String,
        /// Its length.
        len: usize,
        /// Length of `time_s`.
        expected: usize,
    },
    /// A sample is NaN or infinite (a gap in the data is an error).
    #[error("column `{column}` sample {sample} (CSV line {line}) is {value}; expected a finite number")]
    NonFinite {
        /// Name of the column.
        column: String,
        /// Zero-based sample index.
        sample: usize,
        /// One-based line number in the CSV file (the header is line 1).
        line: usize,
        /// The offending value.
        value: f64,
    },
    /// `time_s` does not advance by `1 / sample_rate_hz`.
    #[error("column `time_s` steps by {step_s} s from sample {sample_before} to {sample} (CSV line {line}); expected {expected_s} s (1 / sample_rate_hz) within 1e-6 relative")]
    NonUniformTime {
        /// Zero-based index of the sample that ends the bad step.
        sample: usize,
        /// Zero-based index of the sample before it.
        sample_before: usize,
        /// One-based CSV line number of `sample`.
        line: usize,
        /// Actual step, s.
        step_s: f64,
        /// Expected step `1 / sample_rate_hz`, s.
        expected_s: f64,
    },
    /// Creating the directory or writing a file failed.
    #[error("writing `{path}` failed: {source}")]
    Io {
        /// File or directory being written.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// The CSV writer failed.
    #[error("writing CSV `{path}` failed: {source}")]
    Csv {
        /// File being written.
        path: PathBuf,
        /// Underlying error.
        source: csv::Error,
    },
    /// The metadata could not be serialized as TOML.
    #[error("serializing the metadata for `{path}` failed: {source}")]
    Toml {
        /// File being written.
        path: PathBuf,
        /// Underlying error.
        source: toml::ser::Error,
    },
}
