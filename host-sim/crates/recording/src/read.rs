//! Reading recordings in measurement format version 1
//! (`shared/spec/measurement-format.md`): `<stem>.toml` + `<stem>.csv`.
//!
//! The reader accepts every dataset that follows the specification and
//! refuses anything else with a [`ReadError`] that names the file, the line
//! (CSV: the header is line 1; TOML: line and column as the `toml` crate
//! counts them), the field or column, and what was expected. Files are only
//! ever opened for reading.
//!
//! Decisions where the specification leaves room:
//! * CSV: fields are separated by `,` exactly; no whitespace is trimmed
//!   (` 1.5` is not a number, ` time_s` is not `time_s`). Line ends may be
//!   `\n` or `\r\n`; the last line may lack its line end; blank lines are
//!   allowed only at the end of the file. A UTF-8 byte-order mark before the
//!   header is skipped. Fields may be quoted (`"time_s"`, `""` for a quote
//!   inside) but a quoted field must close on its own line.
//! * Numbers are Rust `f64` text (`str::parse::<f64>`): `1e-3`, `-0.25`,
//!   `+2`, `.5`; `NaN`, `inf` and values that overflow to infinity are
//!   refused, as is an empty field.
//! * `time_s` need not start at 0; at least 2 samples are required so that
//!   the sampling can be checked.
//! * TOML: numeric fields may be written as integers (`m_cw_kg = 33`) as well
//!   as floats; `format`, `kind` and `direction` are case-sensitive. The
//!   fields of the other kind (e.g. `mass_kg` in a travel) are ignored like
//!   any unknown field.
//! * A dataset's recordings are the regular files named `<stem>.toml`
//!   (extension in lower case); a `.csv` without its `.toml` is ignored like
//!   any other file.

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::fs::{self, File};
use std::io::{self, BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use super::write::TIME_STEP_RELATIVE_TOLERANCE;
use super::{
    column_bound, CarDirection, Column, Recording, RecordingKind, RecordingMeta, FORMAT, MAX_LINE_BYTES, MAX_MASS_KG,
    MAX_META_BYTES, MAX_ROPE_LENGTH_M, MAX_SAMPLE_RATE_HZ, MIN_SAMPLE_RATE_HZ, TIME_S,
};

/// Error from reading a recording, a dataset or an EVIMP export. Every
/// variant names the file; where it applies also the line (1-based; the CSV
/// header is line 1), the field or column, and what was expected.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// A file or directory is missing or cannot be read.
    #[error("cannot read `{}`: {source}; expected a readable file", .path.display())]
    Io {
        /// File or directory being read.
        path: PathBuf,
        /// Underlying error.
        source: io::Error,
    },
    /// The metadata file has no samples file next to it.
    #[error("`{}` has no samples file `{}` next to it; expected `<stem>.toml` and `<stem>.csv` in pairs", .toml_path.display(), .csv_path.display())]
    MissingCsv {
        /// The metadata file.
        toml_path: PathBuf,
        /// The samples file that was looked for.
        csv_path: PathBuf,
    },
    /// [`read_recording`] was given a path that does not end in `.toml`.
    #[error("`{}` is not a metadata file; expected a path ending in `.toml`{}", .path.display(), toml_hint(.path))]
    NotTomlPath {
        /// The path given.
        path: PathBuf,
    },
    /// An input is not a regular file (a named pipe, a device, a socket,
    /// a folder).
    #[error("`{}` is {kind}; expected a regular file", .path.display())]
    NotRegularFile {
        /// The path given.
        path: PathBuf,
        /// What it is instead.
        kind: &'static str,
    },
    /// The dataset given is a file, not a folder.
    #[error("`{}` is a file; expected a dataset folder holding `<stem>.toml` + `<stem>.csv` pairs (for one recording, give the folder it is in)", .path.display())]
    DatasetIsFile {
        /// The path given.
        path: PathBuf,
    },
    /// The dataset directory holds no `<stem>.toml`.
    #[error("dataset directory `{}` holds no recording; expected at least one `<stem>.toml` with its `<stem>.csv`", .dir.display())]
    EmptyDataset {
        /// The dataset directory.
        dir: PathBuf,
    },
    /// A metadata file's name is not valid UTF-8, so it has no stem to report.
    #[error("file name `{}` is not UTF-8; expected a UTF-8 stem", .path.display())]
    NonUtf8FileName {
        /// The file.
        path: PathBuf,
    },
    /// The text is not valid UTF-8.
    #[error("`{}` line {line}, byte {byte}: not valid UTF-8; expected UTF-8 text", .path.display())]
    NotUtf8 {
        /// The file.
        path: PathBuf,
        /// Line (1-based).
        line: usize,
        /// First invalid byte within the line (1-based).
        byte: usize,
    },
    /// The metadata file is not valid TOML.
    #[error("`{}` line {line}, column {column}: TOML syntax error: {message}", .path.display())]
    TomlSyntax {
        /// The metadata file.
        path: PathBuf,
        /// Line (1-based) as the `toml` crate reports it.
        line: usize,
        /// Column (1-based, in characters) as the `toml` crate reports it.
        column: usize,
        /// The `toml` crate's description, including what it expected.
        message: String,
    },
    /// A required metadata field is missing.
    #[error("`{}`: required field `{field}` is missing; expected {expected}", .path.display())]
    MissingField {
        /// The metadata file.
        path: PathBuf,
        /// Field name.
        field: &'static str,
        /// What the field must hold.
        expected: String,
    },
    /// A metadata field has the wrong TOML type.
    #[error("`{}` line {line}: field `{field}` is {found}; expected {expected}", .path.display())]
    WrongType {
        /// The metadata file.
        path: PathBuf,
        /// Line of the value (1-based).
        line: usize,
        /// Field name.
        field: &'static str,
        /// TOML type found, e.g. `a string`.
        found: &'static str,
        /// Type required, e.g. `a number (kg)`.
        expected: &'static str,
    },
    /// `format` is not `"elevator-measurement/1"`.
    #[error("`{}` line {line}: field `format` is {found:?}; expected exactly \"elevator-measurement/1\"", .path.display())]
    UnknownFormat {
        /// The metadata file.
        path: PathBuf,
        /// Line of the value (1-based).
        line: usize,
        /// The value found.
        found: String,
    },
    /// `kind` is neither `"travel"` nor `"free_decay"`.
    #[error("`{}` line {line}: field `kind` is {found:?}; expected \"travel\" or \"free_decay\"", .path.display())]
    UnknownKind {
        /// The metadata file.
        path: PathBuf,
        /// Line of the value (1-based).
        line: usize,
        /// The value found.
        found: String,
    },
    /// A metadata value is outside its physical range (or not finite).
    #[error("`{}` line {line}: field `{field}` = {} is out of range; expected {expected}", .path.display(), readable(*.value))]
    OutOfRange {
        /// The metadata file.
        path: PathBuf,
        /// Line of the value (1-based).
        line: usize,
        /// Field name.
        field: &'static str,
        /// The value found (kg, m or Hz as the field's name says).
        value: f64,
        /// Accepted range with unit.
        expected: String,
    },
    /// `direction` is neither `"up"` nor `"down"`.
    #[error("`{}` line {line}: field `direction` is {found:?}; expected \"up\" or \"down\"", .path.display())]
    InvalidDirection {
        /// The metadata file.
        path: PathBuf,
        /// Line of the value (1-based).
        line: usize,
        /// The value found.
        found: String,
    },
    /// `direction` contradicts the change of `lw` (car up: `lw` grows).
    #[error("`{}` line {line}: field `direction` = \"{direction}\" contradicts lw_start_m = {lw_start_m} m and lw_end_m = {lw_end_m} m; expected lw_end_m {relation} lw_start_m (when the car goes up, lw grows)", .path.display())]
    DirectionMismatch {
        /// The metadata file.
        path: PathBuf,
        /// Line of `direction` (1-based).
        line: usize,
        /// Direction given (`"up"` or `"down"`).
        direction: &'static str,
        /// Counterweight-side rope length at the start, m.
        lw_start_m: f64,
        /// Counterweight-side rope length at the end, m.
        lw_end_m: f64,
        /// Required relation: `>` for up, `<` for down.
        relation: &'static str,
    },
    /// The samples file has no header row.
    #[error("`{}` line 1: {found}; expected a header row naming the columns, e.g. `time_s,acc_car_mps2`", .path.display())]
    NoHeader {
        /// The samples file.
        path: PathBuf,
        /// What was found instead (`the file is empty`, `the line is blank`).
        found: &'static str,
    },
    /// A header field is empty.
    #[error("`{}` line 1, field {field}: the column name is empty; expected a name such as `time_s`", .path.display())]
    EmptyColumnName {
        /// The samples file.
        path: PathBuf,
        /// Field number in the header (1-based).
        field: usize,
    },
    /// Two header fields have the same name.
    #[error("`{}` line 1: column `{name}` appears twice (fields {first} and {second}); expected unique column names", .path.display())]
    DuplicateColumn {
        /// The samples file.
        path: PathBuf,
        /// The repeated name.
        name: String,
        /// Field number of the first occurrence (1-based).
        first: usize,
        /// Field number of the second occurrence (1-based).
        second: usize,
    },
    /// A column the recording kind requires is missing from the header.
    #[error("`{}` line 1: required column `{column}` is missing{hint}; expected a header with {required} (a `{kind}` recording)", .path.display())]
    MissingColumn {
        /// The samples file.
        path: PathBuf,
        /// Name of the missing column.
        column: &'static str,
        /// Recording kind (`travel` or `free_decay`).
        kind: &'static str,
        /// The columns the kind requires, as text.
        required: String,
        /// A hint at a near miss in the header (e.g. surrounding spaces), or empty.
        hint: String,
    },
    /// A quoted field is malformed.
    #[error("`{}` line {line}, field {field}: {problem}; expected a quoted field that closes on the same line and is followed by `,` or the line end", .path.display())]
    BadQuoting {
        /// The file.
        path: PathBuf,
        /// Line (1-based).
        line: usize,
        /// Field number (1-based).
        field: usize,
        /// What is wrong.
        problem: &'static str,
    },
    /// A blank line before the end of the file.
    #[error("`{}` line {line} is blank; expected {expected} (blank lines are allowed only at the end of the file)", .path.display())]
    BlankLine {
        /// The file.
        path: PathBuf,
        /// Line (1-based).
        line: usize,
        /// What the line should hold.
        expected: String,
    },
    /// A row has the wrong number of fields.
    #[error("`{}` line {line} has {found} fields; expected {expected}", .path.display())]
    FieldCount {
        /// The file.
        path: PathBuf,
        /// Line (1-based).
        line: usize,
        /// Number of fields found.
        found: usize,
        /// Number expected and why.
        expected: String,
    },
    /// A sample field is empty (a gap in the data).
    #[error("`{}` line {line}, column `{column}`: the value is empty; expected a number (a gap in the data is an error)", .path.display())]
    EmptyValue {
        /// The file.
        path: PathBuf,
        /// Line (1-based).
        line: usize,
        /// Column name.
        column: String,
    },
    /// A sample field is not a number.
    #[error("`{}` line {line}, column `{column}`: `{text}` is not a number; expected f64 text with `.` as decimal mark, e.g. `-0.25` or `1e-3`", .path.display())]
    NotANumber {
        /// The file.
        path: PathBuf,
        /// Line (1-based).
        line: usize,
        /// Column name.
        column: String,
        /// The field's text (shortened if long).
        text: String,
    },
    /// A sample is NaN or infinite (or overflows to infinity).
    #[error("`{}` line {line}, column `{column}`: `{text}` is not finite; expected a finite number (NaN and infinity are not allowed: a gap in the data is an error)", .path.display())]
    NonFinite {
        /// The file.
        path: PathBuf,
        /// Line (1-based).
        line: usize,
        /// Column name.
        column: String,
        /// The field's text (shortened if long).
        text: String,
    },
    /// `time_s` does not advance by `1 / sample_rate_hz`.
    #[error("`{}` line {line}, column `time_s`: time steps by {} s from the line before; expected {} s (1 / sample_rate_hz) within a relative tolerance of 1e-6", .path.display(), readable(*.step_s), readable(*.expected_s))]
    NonUniformTime {
        /// The samples file.
        path: PathBuf,
        /// Line of the sample that ends the bad step (1-based).
        line: usize,
        /// Step found, s.
        step_s: f64,
        /// Step expected, `1 / sample_rate_hz`, s.
        expected_s: f64,
    },
    /// A file is larger than the reader reads whole.
    #[error("`{}` is larger than {limit} bytes; expected {what} (this bound is far beyond a real one)", .path.display())]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// The bound, bytes.
        limit: u64,
        /// What the file should be.
        what: &'static str,
    },
    /// A line is longer than any real line.
    #[error("`{}` line {line} is longer than {limit} bytes; expected one sample row of at most {limit} bytes (a real one is a few hundred)", .path.display())]
    LineTooLong {
        /// The file.
        path: PathBuf,
        /// Line (1-based).
        line: usize,
        /// The bound, bytes.
        limit: usize,
    },
    /// A sample of a known column lies beyond its physical bound
    /// ([`super::COLUMN_BOUNDS`]).
    #[error("`{}` line {line}, column `{column}`: `{text}` is beyond the physical bound of the column; expected a magnitude of at most {limit} {unit}", .path.display())]
    BeyondPhysicalBound {
        /// The file.
        path: PathBuf,
        /// Line (1-based).
        line: usize,
        /// Column name.
        column: String,
        /// The field's text (shortened if long).
        text: String,
        /// Largest magnitude accepted.
        limit: f64,
        /// Unit of the bound (and what it amounts to).
        unit: &'static str,
    },
    /// The samples contradict themselves or their metadata (a wrapped or
    /// glitched angle, a dead accelerometer, a travel that moves the other
    /// way than its metadata says): [`crate::consistency`].
    #[error("`{}`{}, column `{column}`: {found}; expected {expected}", .path.display(), .line.map(|l| format!(" line {l}")).unwrap_or_default())]
    Inconsistent {
        /// The file (the samples file, or the metadata file for a field).
        path: PathBuf,
        /// Line (1-based) of the first offending sample, if one.
        line: Option<usize>,
        /// The column (or metadata field) at fault.
        column: String,
        /// What the data show.
        found: String,
        /// What the format or the physics require.
        expected: String,
    },
    /// Fewer than 2 samples.
    #[error("`{}`: {found} sample row(s); expected at least 2", .path.display())]
    TooFewSamples {
        /// The file.
        path: PathBuf,
        /// Number of sample rows found.
        found: usize,
    },
    /// An EVIMP export does not start with the line `EVIMP1`.
    #[error("`{}` line 1: found `{found}`; expected `EVIMP1`", .path.display())]
    NotEvimp {
        /// The file.
        path: PathBuf,
        /// The first line (shortened if long).
        found: String,
    },
    /// The sample-rate line of an EVIMP export is missing or invalid.
    #[error("`{}` line 2: sample rate `{found}` is invalid; expected a finite number of Hz > 0, at most 1e7, e.g. `256`", .path.display())]
    EvimpSampleRate {
        /// The file.
        path: PathBuf,
        /// The line's text (shortened if long), or `<end of file>`.
        found: String,
    },
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

/// The hint of [`ReadError::NotTomlPath`]: the metadata file to give when
/// the samples file was given.
fn toml_hint(path: &Path) -> String {
    let toml = path.with_extension("toml");
    if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("csv")) && toml.is_file() {
        format!(" (this is the samples file of a recording: give its metadata file `{}`)", toml.display())
    } else {
        String::new()
    }
}

/// Longest excerpt of offending text quoted in an error message, characters.
const EXCERPT_CHARS: usize = 40;

/// `text`, shortened to [`EXCERPT_CHARS`] characters with `…` if longer.
pub(super) fn excerpt(text: &str) -> String {
    let mut chars = text.char_indices();
    match chars.nth(EXCERPT_CHARS) {
        Some((end, _)) => format!("{}…", &text[..end]),
        None => text.to_string(),
    }
}

/// Reads a text file line by line, read-only: strips `\n` / `\r\n`, skips a
/// UTF-8 byte-order mark on line 1 and checks UTF-8.
pub(super) struct LineReader {
    reader: BufReader<File>,
    buf: Vec<u8>,
    line: usize,
    path: PathBuf,
}

impl LineReader {
    /// Reader over an open file; `path` is used in errors.
    pub(super) fn new(file: File, path: &Path) -> Self {
        Self { reader: BufReader::with_capacity(1 << 16, file), buf: Vec::new(), line: 0, path: path.to_path_buf() }
    }

    /// The next line's number (1-based) and text without its line end, or
    /// `None` at the end of the file.
    pub(super) fn next_line(&mut self) -> Result<Option<(usize, &str)>, ReadError> {
        self.buf.clear();
        // At most one byte past the bound (and its line end): a line of
        // gigabytes is refused, not read.
        let n = (&mut self.reader)
            .take(MAX_LINE_BYTES as u64 + 2)
            .read_until(b'\n', &mut self.buf)
            .map_err(|source| ReadError::Io { path: self.path.clone(), source })?;
        if n == 0 {
            return Ok(None);
        }
        self.line += 1;
        let content = self.buf.strip_suffix(b"\n").map_or(self.buf.len(), |b| b.strip_suffix(b"\r").unwrap_or(b).len());
        if content > MAX_LINE_BYTES {
            return Err(ReadError::LineTooLong { path: self.path.clone(), line: self.line, limit: MAX_LINE_BYTES });
        }
        let mut bytes = self.buf.as_slice();
        if let Some(rest) = bytes.strip_suffix(b"\n") {
            bytes = rest;
            if let Some(rest) = bytes.strip_suffix(b"\r") {
                bytes = rest;
            }
        }
        let mut offset = 0;
        if self.line == 1 {
            if let Some(rest) = bytes.strip_prefix(b"\xEF\xBB\xBF") {
                bytes = rest;
                offset = 3;
            }
        }
        match std::str::from_utf8(bytes) {
            Ok(text) => Ok(Some((self.line, text))),
            Err(e) => {
                Err(ReadError::NotUtf8 { path: self.path.clone(), line: self.line, byte: offset + e.valid_up_to() + 1 })
            }
        }
    }
}

/// Opens `path` for reading: a regular file only (a named pipe would block
/// the open for ever, a device never end).
pub(super) fn open(path: &Path) -> Result<File, ReadError> {
    refuse_special_file(path)?;
    File::open(path).map_err(|source| ReadError::Io { path: path.to_path_buf(), source })
}

/// Refuses `path` when it exists and is not a regular file (after symbolic
/// links): a folder, a named pipe, a device or a socket. A missing file is
/// left to the open, whose error says so.
pub fn refuse_special_file(path: &Path) -> Result<(), ReadError> {
    let Ok(meta) = fs::metadata(path) else { return Ok(()) };
    if meta.is_file() {
        return Ok(());
    }
    let kind = if meta.is_dir() { "a folder" } else { special_kind(&meta) };
    Err(ReadError::NotRegularFile { path: path.to_path_buf(), kind })
}

#[cfg(unix)]
fn special_kind(meta: &fs::Metadata) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    let t = meta.file_type();
    if t.is_fifo() {
        "a named pipe"
    } else if t.is_char_device() || t.is_block_device() {
        "a device"
    } else if t.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    }
}

#[cfg(not(unix))]
fn special_kind(_meta: &fs::Metadata) -> &'static str {
    "not a regular file"
}

/// Reads one recording: the metadata `toml_path` (`<stem>.toml`) and the
/// samples `<stem>.csv` next to it.
///
/// * `toml_path`: path of the metadata file; must end in `.toml`.
/// * `rope_total_length_m`: total rope length of the rig, m (> 0;
///   `rig.mechanics.rope_total_length_m`); `lw_start_m` and `lw_end_m` must
///   lie in `(0, rope_total_length_m)`.
///
/// Returns the metadata in SI units (kg, m, Hz) and every column of the CSV
/// in file order (unknown columns included), values in the units of their
/// names (s, m/s^2, A, rad/s, rad, m/s). Neither file is modified.
///
/// # Errors
/// A [`ReadError`] naming the file, line, field or column and what was
/// expected; see the module documentation for the checks.
pub fn read_recording(toml_path: &Path, rope_total_length_m: f64) -> Result<Recording, ReadError> {
    let recording = parse_recording(toml_path, rope_total_length_m)?;
    crate::consistency::check(&recording, toml_path, &toml_path.with_extension("csv"))?;
    Ok(recording)
}

/// [`read_recording`] without the checks of the samples against themselves
/// and their metadata ([`crate::consistency`]): the format alone (fields,
/// columns, bounds, time step). For tools that test the format itself; the
/// commands read with [`read_recording`].
///
/// # Errors
/// A [`ReadError`] naming the file, line, field or column.
pub fn parse_recording(toml_path: &Path, rope_total_length_m: f64) -> Result<Recording, ReadError> {
    if toml_path.extension().is_none_or(|e| e != "toml") {
        return Err(ReadError::NotTomlPath { path: toml_path.to_path_buf() });
    }
    let csv_path = toml_path.with_extension("csv");
    refuse_special_file(&csv_path)?;
    let csv_file = File::open(&csv_path).map_err(|source| {
        if source.kind() == io::ErrorKind::NotFound {
            ReadError::MissingCsv { toml_path: toml_path.to_path_buf(), csv_path: csv_path.clone() }
        } else {
            ReadError::Io { path: csv_path.clone(), source }
        }
    })?;
    let meta = read_meta(toml_path, rope_total_length_m)?;
    let columns = read_columns_from(csv_file, &csv_path, &meta)?;
    Ok(Recording { meta, columns })
}

/// Reads every recording of the dataset directory `dir`: each regular file
/// `<stem>.toml` with its `<stem>.csv`, other files ignored; returned sorted
/// by stem (byte order).
///
/// * `rope_total_length_m`: total rope length of the rig, m (see
///   [`read_recording`]).
///
/// # Errors
/// The first [`ReadError`] in stem order; also when the directory cannot be
/// listed, holds no `<stem>.toml` ([`ReadError::EmptyDataset`]) or a
/// `<stem>.toml` has no `<stem>.csv` ([`ReadError::MissingCsv`]).
pub fn read_dataset(dir: &Path, rope_total_length_m: f64) -> Result<Vec<(String, Recording)>, ReadError> {
    read_dataset_with(dir, rope_total_length_m, read_recording)
}

/// [`read_dataset`] with [`parse_recording`]: the format alone, without the
/// checks of [`crate::consistency`].
///
/// # Errors
/// As [`read_dataset`].
pub fn parse_dataset(dir: &Path, rope_total_length_m: f64) -> Result<Vec<(String, Recording)>, ReadError> {
    read_dataset_with(dir, rope_total_length_m, parse_recording)
}

fn read_dataset_with(
    dir: &Path,
    rope_total_length_m: f64,
    read: fn(&Path, f64) -> Result<Recording, ReadError>,
) -> Result<Vec<(String, Recording)>, ReadError> {
    let io_err = |source| ReadError::Io { path: dir.to_path_buf(), source };
    if fs::metadata(dir).is_ok_and(|m| m.is_file()) {
        return Err(ReadError::DatasetIsFile { path: dir.to_path_buf() });
    }
    let mut stems = Vec::new();
    for entry in fs::read_dir(dir).map_err(io_err)? {
        let path = entry.map_err(io_err)?.path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        // A folder named `<stem>.toml` (`plots.toml/`) is no recording; a
        // named pipe, a device or a socket so named is refused naming it.
        let meta = fs::metadata(&path).map_err(|source| ReadError::Io { path: path.clone(), source })?;
        if meta.is_dir() {
            continue;
        }
        refuse_special_file(&path)?;
        let stem =
            path.file_stem().and_then(|s| s.to_str()).ok_or(ReadError::NonUtf8FileName { path: path.clone() })?;
        stems.push((stem.to_string(), path));
    }
    if stems.is_empty() {
        return Err(ReadError::EmptyDataset { dir: dir.to_path_buf() });
    }
    stems.sort();
    // Every pair must be complete before anything is parsed.
    for (_, toml_path) in &stems {
        let csv_path = toml_path.with_extension("csv");
        if !csv_path.exists() {
            return Err(ReadError::MissingCsv { toml_path: toml_path.clone(), csv_path });
        }
    }
    let recordings = on_every_core(&stems, |(_, toml_path)| read(toml_path, rope_total_length_m));
    // The first error in the stems' order, as a reading one after another gives.
    stems.into_iter().zip(recordings).map(|((stem, _), rec)| rec.map(|rec| (stem, rec))).collect()
}

/// `work` on every item, the items shared among as many threads as the
/// machine runs at once; the results in the items' order.
fn on_every_core<T: Sync, R: Send>(items: &[T], work: impl Fn(&T) -> R + Sync) -> Vec<R> {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get()).min(items.len());
    let next = AtomicUsize::new(0);
    let done: Vec<Mutex<Option<R>>> = items.iter().map(|_| Mutex::new(None)).collect();
    std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(item) = items.get(i) else { break };
                let result = work(item);
                *done[i].lock().unwrap_or_else(|poisoned| poisoned.into_inner()) = Some(result);
            });
        }
    });
    done.into_iter()
        .map(|slot| slot.into_inner().unwrap_or_else(|poisoned| poisoned.into_inner()))
        .map(|result| result.expect("every item is worked on before the threads end"))
        .collect()
}

/// One metadata field: its value and the line it is on.
struct Field<'a> {
    value: &'a toml::Value,
    line: usize,
}

/// The parsed metadata file with line numbers for its values.
struct MetaFile<'a> {
    path: &'a Path,
    text: &'a str,
    table: BTreeMap<String, toml::Spanned<toml::Value>>,
}

/// 1-based line and column (in characters) of byte `offset` in `text`.
fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    (line, before[line_start..].chars().count() + 1)
}

fn type_name(value: &toml::Value) -> &'static str {
    match value {
        toml::Value::String(_) => "a string",
        toml::Value::Integer(_) => "an integer",
        toml::Value::Float(_) => "a float",
        toml::Value::Boolean(_) => "a boolean",
        toml::Value::Datetime(_) => "a date-time",
        toml::Value::Array(_) => "an array",
        toml::Value::Table(_) => "a table",
    }
}

impl<'a> MetaFile<'a> {
    fn field(&self, name: &'static str, expected: &str) -> Result<Field<'_>, ReadError> {
        let spanned = self.table.get(name).ok_or_else(|| {
            let near = self.table.keys().find(|k| !META_FIELDS.contains(&k.as_str()) && is_near_miss(k, name));
            let hint = near.map(|k| format!(" (the file has `{k}`: misspelt?)")).unwrap_or_default();
            ReadError::MissingField {
                path: self.path.to_path_buf(),
                field: name,
                expected: format!("{expected}{hint}"),
            }
        })?;
        Ok(Field { value: spanned.get_ref(), line: line_column(self.text, spanned.span().start).0 })
    }

    fn wrong_type(&self, field: &Field<'_>, name: &'static str, expected: &'static str) -> ReadError {
        ReadError::WrongType {
            path: self.path.to_path_buf(),
            line: field.line,
            field: name,
            found: type_name(field.value),
            expected,
        }
    }

    /// A required string field.
    fn string(&self, name: &'static str, expected: &'static str) -> Result<(&str, usize), ReadError> {
        let field = self.field(name, expected)?;
        match field.value {
            toml::Value::String(s) => Ok((s.as_str(), field.line)),
            _ => Err(self.wrong_type(&field, name, "a string")),
        }
    }

    /// A required number (TOML float or integer) that must satisfy `ok`.
    fn number(
        &self,
        name: &'static str,
        expected: &str,
        ok: impl Fn(f64) -> bool,
        type_expected: &'static str,
    ) -> Result<(f64, usize), ReadError> {
        let field = self.field(name, expected)?;
        let value = match field.value {
            toml::Value::Float(v) => *v,
            toml::Value::Integer(i) => *i as f64,
            _ => return Err(self.wrong_type(&field, name, type_expected)),
        };
        if value.is_finite() && ok(value) {
            Ok((value, field.line))
        } else {
            Err(ReadError::OutOfRange {
                path: self.path.to_path_buf(),
                line: field.line,
                field: name,
                value,
                expected: expected.to_string(),
            })
        }
    }

    /// A number in `(0, max]`.
    fn positive(
        &self,
        name: &'static str,
        max: f64,
        expected: &str,
        type_expected: &'static str,
    ) -> Result<f64, ReadError> {
        self.number(name, expected, |v| v > 0.0 && v <= max, type_expected).map(|(v, _)| v)
    }
}

/// Every metadata field the specification defines
/// (`measurement-format.md`), in its order.
pub const META_FIELDS: [&str; 11] = [
    "format",
    "kind",
    "sample_rate_hz",
    "description",
    "m_car_kg",
    "m_cw_kg",
    "direction",
    "lw_start_m",
    "lw_end_m",
    "mass_kg",
    "rope_length_m",
];

/// Whether `key` looks like a misspelling of `name`: the same but for case,
/// `-`/`_` and surrounding spaces, or a unit suffix (`_hz`), or at most two
/// edits (insertions, deletions, substitutions) apart.
fn is_near_miss(key: &str, name: &str) -> bool {
    let normal = |s: &str| s.trim().to_ascii_lowercase().replace('-', "_");
    let (a, b) = (normal(key), normal(name));
    if a == b {
        return true;
    }
    // The unit left off, or one too many (`sample_rate` for `sample_rate_hz`).
    let unit_suffix =
        |long: &str, short: &str| long.strip_prefix(short).is_some_and(|rest| rest.starts_with('_') && rest.len() <= 4);
    if unit_suffix(&a, &b) || unit_suffix(&b, &a) {
        return true;
    }
    let (a, b): (Vec<char>, Vec<char>) = (a.chars().collect(), b.chars().collect());
    if a.len().abs_diff(b.len()) > 2 || a.len() > 64 {
        return false;
    }
    // Levenshtein distance, one row at a time.
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.iter().enumerate() {
        let mut previous = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let substitution = previous + usize::from(ca != cb);
            previous = row[j + 1];
            row[j + 1] = substitution.min(row[j] + 1).min(row[j + 1] + 1);
        }
    }
    row[b.len()] <= 2
}

/// Reads and checks the metadata file `toml_path` (`<stem>.toml`) alone.
///
/// * `rope_total_length_m`: total rope length of the rig, m (see
///   [`read_recording`]).
///
/// Returns the metadata in SI units (kg, m, Hz). The file is not modified.
///
/// # Errors
/// A [`ReadError`] naming the file, the line and the field: unreadable file,
/// not UTF-8, TOML syntax, `format` or `kind` missing or unknown, a required
/// field missing, a wrong type, a value out of range, `direction` invalid or
/// contradicting the change of `lw`.
pub fn read_meta(toml_path: &Path, rope_total_length_m: f64) -> Result<RecordingMeta, ReadError> {
    let io_err = |source| ReadError::Io { path: toml_path.to_path_buf(), source };
    let too_large = || ReadError::TooLarge {
        path: toml_path.to_path_buf(),
        limit: MAX_META_BYTES,
        what: "a metadata file of a few hundred bytes",
    };
    let file = open(toml_path)?;
    if file.metadata().map_err(io_err)?.len() > MAX_META_BYTES {
        return Err(too_large());
    }
    let mut bytes = Vec::new();
    file.take(MAX_META_BYTES + 1).read_to_end(&mut bytes).map_err(io_err)?;
    if bytes.len() as u64 > MAX_META_BYTES {
        return Err(too_large());
    }
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(&bytes);
    let text = std::str::from_utf8(bytes).map_err(|e| {
        let valid = &bytes[..e.valid_up_to()];
        let line_start = valid.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
        ReadError::NotUtf8 {
            path: toml_path.to_path_buf(),
            line: valid.iter().filter(|&&b| b == b'\n').count() + 1,
            byte: e.valid_up_to() - line_start + 1,
        }
    })?;
    parse_meta(text, toml_path, rope_total_length_m)
}

/// Parses metadata text; `path` is used in errors.
fn parse_meta(text: &str, path: &Path, rope_total_length_m: f64) -> Result<RecordingMeta, ReadError> {
    let table: BTreeMap<String, toml::Spanned<toml::Value>> = toml::from_str(text).map_err(|e| {
        let (line, column) = e.span().map_or((1, 1), |span| line_column(text, span.start));
        let mut message = e.message().trim().replace('\n', "; ");
        if !message.contains("expected") {
            message.push_str("; expected valid TOML (`key = value` lines, each key once)");
        }
        ReadError::TomlSyntax { path: path.to_path_buf(), line, column, message }
    })?;
    let file = MetaFile { path, text, table };

    let (format, line) = file.string("format", "format = \"elevator-measurement/1\"")?;
    if format != FORMAT {
        return Err(ReadError::UnknownFormat { path: path.to_path_buf(), line, found: excerpt(format) });
    }
    let (kind, kind_line) = file.string("kind", "kind = \"travel\" or kind = \"free_decay\"")?;
    let is_travel = match kind {
        "travel" => true,
        "free_decay" => false,
        other => {
            return Err(ReadError::UnknownKind { path: path.to_path_buf(), line: kind_line, found: excerpt(other) })
        }
    };
    let sample_rate_hz = file
        .number(
            "sample_rate_hz",
            &format!("a finite sample rate of {MIN_SAMPLE_RATE_HZ} to {MAX_SAMPLE_RATE_HZ} Hz"),
            |v| (MIN_SAMPLE_RATE_HZ..=MAX_SAMPLE_RATE_HZ).contains(&v),
            "a number (Hz)",
        )?
        .0;
    let description = match file.table.get("description") {
        None => None,
        Some(spanned) => match spanned.get_ref() {
            toml::Value::String(s) => Some(s.clone()),
            other => {
                let field = Field { value: other, line: line_column(text, spanned.span().start).0 };
                return Err(file.wrong_type(&field, "description", "a string"));
            }
        },
    };

    let kind = if is_travel { travel_kind(&file, rope_total_length_m)? } else { free_decay_kind(&file)? };
    Ok(RecordingMeta { kind, sample_rate_hz, description })
}

/// The fields of a travel's metadata, checked.
fn travel_kind(file: &MetaFile<'_>, rope_total_length_m: f64) -> Result<RecordingKind, ReadError> {
    let path = file.path;
    let m_car_kg = file.positive(
        "m_car_kg",
        MAX_MASS_KG,
        &format!("a finite car mass > 0 kg, at most {MAX_MASS_KG} kg"),
        "a number (kg)",
    )?;
    let m_cw_kg = file.positive(
        "m_cw_kg",
        MAX_MASS_KG,
        &format!("a finite counterweight mass > 0 kg, at most {MAX_MASS_KG} kg"),
        "a number (kg)",
    )?;
    let (direction_text, direction_line) = file.string("direction", "direction = \"up\" or direction = \"down\"")?;
    let direction = match direction_text {
        "up" => CarDirection::Up,
        "down" => CarDirection::Down,
        other => {
            return Err(ReadError::InvalidDirection {
                path: path.to_path_buf(),
                line: direction_line,
                found: excerpt(other),
            })
        }
    };
    let lw_expected =
        format!("a counterweight-side rope length in (0, {rope_total_length_m}) m (the rig's rope_total_length_m)");
    let inside = |v: f64| v > 0.0 && v < rope_total_length_m;
    let (lw_start_m, _) = file.number("lw_start_m", &lw_expected, inside, "a number (m)")?;
    let (lw_end_m, _) = file.number("lw_end_m", &lw_expected, inside, "a number (m)")?;
    let (consistent, relation) = match direction {
        CarDirection::Up => (lw_end_m > lw_start_m, ">"),
        CarDirection::Down => (lw_end_m < lw_start_m, "<"),
    };
    if !consistent {
        return Err(ReadError::DirectionMismatch {
            path: path.to_path_buf(),
            line: direction_line,
            direction: direction.as_str(),
            lw_start_m,
            lw_end_m,
            relation,
        });
    }
    Ok(RecordingKind::Travel { m_car_kg, m_cw_kg, direction, lw_start_m, lw_end_m })
}

/// The fields of a free decay's metadata, checked.
fn free_decay_kind(file: &MetaFile<'_>) -> Result<RecordingKind, ReadError> {
    let mass_kg = file.positive(
        "mass_kg",
        MAX_MASS_KG,
        &format!("a finite hanging mass > 0 kg, at most {MAX_MASS_KG} kg"),
        "a number (kg)",
    )?;
    let rope_length_m = file.positive(
        "rope_length_m",
        MAX_ROPE_LENGTH_M,
        &format!("a finite rope length > 0 m, at most {MAX_ROPE_LENGTH_M} m"),
        "a number (m)",
    )?;
    Ok(RecordingKind::FreeDecay { mass_kg, rope_length_m })
}

/// Splits a CSV line with quoted fields (RFC 4180 within one line).
/// On error returns the 1-based field number and what is wrong.
fn split_quoted(line: &str) -> Result<Vec<Cow<'_, str>>, (usize, &'static str)> {
    let mut fields = Vec::new();
    let mut rest = line;
    loop {
        let number = fields.len() + 1;
        if let Some(quoted) = rest.strip_prefix('"') {
            let mut value = String::new();
            let mut tail = quoted;
            loop {
                let Some(end) = tail.find('"') else {
                    return Err((number, "the quoted field is not closed before the end of the line"));
                };
                value.push_str(&tail[..end]);
                tail = &tail[end + 1..];
                if let Some(after) = tail.strip_prefix('"') {
                    value.push('"');
                    tail = after;
                } else {
                    break;
                }
            }
            fields.push(Cow::Owned(value));
            if tail.is_empty() {
                return Ok(fields);
            }
            match tail.strip_prefix(',') {
                Some(after) => rest = after,
                None => return Err((number, "text follows the closing quote")),
            }
        } else {
            match rest.find(',') {
                Some(comma) => {
                    fields.push(Cow::Borrowed(&rest[..comma]));
                    rest = &rest[comma + 1..];
                }
                None => {
                    fields.push(Cow::Borrowed(rest));
                    return Ok(fields);
                }
            }
        }
    }
}

/// Parses one sample field; `name` is its column's name, for errors.
#[inline]
fn parse_value(text: &str, path: &Path, line: usize, name: &str) -> Result<f64, ReadError> {
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => {
            Err(ReadError::NonFinite { path: path.to_path_buf(), line, column: name.to_string(), text: excerpt(text) })
        }
        Err(_) if text.is_empty() => {
            Err(ReadError::EmptyValue { path: path.to_path_buf(), line, column: name.to_string() })
        }
        Err(_) => {
            Err(ReadError::NotANumber { path: path.to_path_buf(), line, column: name.to_string(), text: excerpt(text) })
        }
    }
}

/// [`parse_value`], and for a known column (`bound` = its largest magnitude
/// and unit, [`super::COLUMN_BOUNDS`]) within that bound.
#[inline]
fn parse_bounded(
    text: &str,
    path: &Path,
    line: usize,
    name: &str,
    bound: Option<(f64, &'static str)>,
) -> Result<f64, ReadError> {
    let value = parse_value(text, path, line, name)?;
    match bound {
        Some((limit, unit)) if value.abs() > limit => Err(ReadError::BeyondPhysicalBound {
            path: path.to_path_buf(),
            line,
            column: name.to_string(),
            text: excerpt(text),
            limit,
            unit,
        }),
        _ => Ok(value),
    }
}

/// Reads and checks the samples file `csv_path` (`<stem>.csv`) for a
/// recording with metadata `meta` (from [`read_meta`]).
///
/// Returns every column in file order, values in the units of their names
/// (s, m/s^2, A, rad/s, rad, m/s). The file is not modified.
///
/// # Errors
/// A [`ReadError`] naming the file, the line (header = line 1) and the
/// column: unreadable file, not UTF-8, no header, empty or duplicate column
/// name, a column the kind requires missing, a blank line before the end, a
/// row with the wrong number of fields, a malformed quoted field, an empty,
/// non-numeric or non-finite value, `time_s` not stepping by
/// `1 / sample_rate_hz` (relative tolerance 1e-6), fewer than 2 samples.
pub fn read_columns(csv_path: &Path, meta: &RecordingMeta) -> Result<Vec<Column>, ReadError> {
    read_columns_from(open(csv_path)?, csv_path, meta)
}

fn read_columns_from(file: File, path: &Path, meta: &RecordingMeta) -> Result<Vec<Column>, ReadError> {
    let path_buf = || path.to_path_buf();
    let mut lines = LineReader::new(file, path);

    let names = read_header(&mut lines, path, meta)?;
    let bounds: Vec<Option<(f64, &'static str)>> = names.iter().map(|n| column_bound(n)).collect();
    let time_index = names.iter().position(|n| n == TIME_S).unwrap_or(0);
    let period = 1.0 / meta.sample_rate_hz;
    let ncols = names.len();
    let expected_fields = || format!("{ncols}, one per header column");

    let mut values: Vec<Vec<f64>> = vec![Vec::new(); ncols];
    let mut blank: Option<usize> = None;
    let mut previous_time: Option<f64> = None;
    let mut rows = 0usize;
    while let Some((line, text)) = lines.next_line()? {
        if text.is_empty() {
            blank.get_or_insert(line);
            continue;
        }
        if let Some(blank_line) = blank {
            return Err(ReadError::BlankLine {
                path: path_buf(),
                line: blank_line,
                expected: format!("a sample row with {ncols} comma-separated values"),
            });
        }
        if text.as_bytes().contains(&b'"') {
            let fields = split_quoted(text).map_err(|(field, problem)| ReadError::BadQuoting {
                path: path_buf(),
                line,
                field,
                problem,
            })?;
            if fields.len() != ncols {
                return Err(ReadError::FieldCount {
                    path: path_buf(),
                    line,
                    found: fields.len(),
                    expected: expected_fields(),
                });
            }
            for (((field, column), name), bound) in fields.iter().zip(&mut values).zip(&names).zip(&bounds) {
                column.push(parse_bounded(field, path, line, name, *bound)?);
            }
        } else {
            let found = text.bytes().filter(|&b| b == b',').count() + 1;
            if found != ncols {
                return Err(ReadError::FieldCount { path: path_buf(), line, found, expected: expected_fields() });
            }
            for (((field, column), name), bound) in text.split(',').zip(&mut values).zip(&names).zip(&bounds) {
                column.push(parse_bounded(field, path, line, name, *bound)?);
            }
        }
        let time = values[time_index][rows];
        if let Some(previous) = previous_time {
            let step = time - previous;
            // Written so that a non-finite step also fails.
            let uniform = (step - period).abs() <= TIME_STEP_RELATIVE_TOLERANCE * period;
            if !uniform {
                return Err(ReadError::NonUniformTime { path: path_buf(), line, step_s: step, expected_s: period });
            }
        }
        previous_time = Some(time);
        rows += 1;
    }
    if rows < 2 {
        return Err(ReadError::TooFewSamples { path: path_buf(), found: rows });
    }
    Ok(names.into_iter().zip(values).map(|(name, values)| Column { name, values }).collect())
}

/// The header line of a recording's CSV: its column names, each named once,
/// the columns `meta`'s kind requires among them.
fn read_header(lines: &mut LineReader, path: &Path, meta: &RecordingMeta) -> Result<Vec<String>, ReadError> {
    let path_buf = || path.to_path_buf();
    let names: Vec<String> = match lines.next_line()? {
        None => return Err(ReadError::NoHeader { path: path_buf(), found: "the file is empty" }),
        Some((_, "")) => return Err(ReadError::NoHeader { path: path_buf(), found: "the line is blank" }),
        Some((_, header)) => split_quoted(header)
            .map_err(|(field, problem)| ReadError::BadQuoting { path: path_buf(), line: 1, field, problem })?
            .into_iter()
            .map(Cow::into_owned)
            .collect(),
    };
    for (i, name) in names.iter().enumerate() {
        if name.is_empty() {
            return Err(ReadError::EmptyColumnName { path: path_buf(), field: i + 1 });
        }
        if let Some(first) = names[..i].iter().position(|n| n == name) {
            return Err(ReadError::DuplicateColumn {
                path: path_buf(),
                name: name.clone(),
                first: first + 1,
                second: i + 1,
            });
        }
    }
    let required = meta.kind.required_columns();
    for &column in required {
        if !names.iter().any(|n| n == column) {
            let hint = names
                .iter()
                .find(|n| n.trim().eq_ignore_ascii_case(column))
                .map(|n| format!(" (the header has `{n}`, which differs in spaces or case)"))
                .unwrap_or_default();
            let required = required.iter().map(|c| format!("`{c}`")).collect::<Vec<_>>().join(", ");
            return Err(ReadError::MissingColumn { path: path_buf(), column, kind: meta.kind.name(), required, hint });
        }
    }
    Ok(names)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The items' results come back in the items' order, whichever thread
    /// worked on them and however long each took.
    #[test]
    fn every_core_keeps_the_items_order() {
        let items: Vec<u64> = (0..37).collect();
        let got = on_every_core(&items, |&i| {
            std::thread::sleep(std::time::Duration::from_micros((i * 7919) % 500));
            i * i
        });
        assert_eq!(got, items.iter().map(|i| i * i).collect::<Vec<_>>());
        assert!(on_every_core(&[] as &[u64], |&i| i).is_empty());
    }

    #[test]
    fn line_column_counts_lines_and_characters() {
        let text = "a = 1\nbé = \"x\"\n";
        assert_eq!(line_column(text, 0), (1, 1));
        assert_eq!(line_column(text, 6), (2, 1));
        // After the two-byte `é`, the column counts characters.
        assert_eq!(line_column(text, 9), (2, 3));
        assert_eq!(line_column(text, 1000), (3, 1));
        // Inside a multi-byte character: rounds down.
        assert_eq!(line_column(text, 8), (2, 2));
    }

    #[test]
    fn split_quoted_follows_rfc4180_within_a_line() {
        let f = split_quoted("\"time_s\",acc,\"a \"\"q\"\" b\",\"\"").unwrap();
        assert_eq!(f, ["time_s", "acc", "a \"q\" b", ""]);
        assert_eq!(split_quoted("a,,b,").unwrap(), ["a", "", "b", ""]);
        assert_eq!(split_quoted("x,\"open"), Err((2, "the quoted field is not closed before the end of the line")));
        assert_eq!(split_quoted("\"a\"b,c"), Err((1, "text follows the closing quote")));
        // A quote inside an unquoted field is kept as text.
        assert_eq!(split_quoted("a\"b,c").unwrap(), ["a\"b", "c"]);
    }

    #[test]
    fn near_misses_of_field_names_are_recognised() {
        assert!(is_near_miss("m_car_kgs", "m_car_kg"));
        assert!(is_near_miss("M-Car_Kg", "m_car_kg"));
        assert!(is_near_miss("sample_rate", "sample_rate_hz"));
        assert!(!is_near_miss("description", "direction"));
        assert!(!is_near_miss("kind", "mass_kg"));
    }

    #[test]
    fn excerpt_shortens_long_text_on_character_boundaries() {
        assert_eq!(excerpt("short"), "short");
        let long = "é".repeat(100);
        let e = excerpt(&long);
        assert_eq!(e.chars().count(), EXCERPT_CHARS + 1);
        assert!(e.ends_with('…'));
    }
}
