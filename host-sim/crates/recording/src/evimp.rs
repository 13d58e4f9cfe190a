//! Reading the `EVIMP1` text export of common lift ride-quality analyzers.
//!
//! Layout:
//!
//! ```text
//! EVIMP1                      line 1: the format tag
//! 256                         line 2: sample rate, Hz
//! -3.351 3.545 -1.787 58.073  then one row per sample: x y z in mg,
//! -2.074 2.49 -1.255 59.165   optionally a 4th value, sound level in dB(A)
//! ```
//!
//! z is the vertical axis; x and y are horizontal. 1 mg = 1e-3 g_n =
//! 9.80665e-3 m/s^2.
//!
//! Decisions (the format has no published specification):
//! * Values are separated by any run of spaces or tabs; leading and trailing
//!   whitespace on a line is ignored. Numbers are Rust `f64` text with `.` as
//!   decimal mark; NaN, infinity and non-numbers are errors.
//! * Rows hold 3 values (x y z) or 4 (x y z sound); the first sample row
//!   (line 3) decides, and every row must then have that many values, so the
//!   sound column is either present in every sample or absent from all.
//! * Line ends `\n` or `\r\n`; a UTF-8 byte-order mark is skipped; blank
//!   lines are allowed only at the end of the file; at least 2 samples.
//! * Physical bounds ([`EVIMP_BOUNDS`]): |x|, |y|, |z| at most 1e6 mg
//!   (1000 g), the sound level at most 300 dB(A) in magnitude, the sample
//!   rate at most 1e7 Hz; a line is at most [`super::MAX_LINE_BYTES`] long.

use std::path::Path;

use super::read::{excerpt, open, LineReader, ReadError};

/// Standard gravity, m/s^2: 1 mg = 1e-3 of it.
pub const STANDARD_GRAVITY_MPS2: f64 = 9.80665;

/// Column names used in error messages, in row order.
const COLUMNS: [&str; 4] = ["x_mg", "y_mg", "z_mg", "sound_dba"];

/// The largest magnitude of each value of a row (in the order of
/// `x_mg`, `y_mg`, `z_mg`, `sound_dba`) and its unit: far beyond any lift.
pub const EVIMP_BOUNDS: [(f64, &str); 4] =
    [(1.0e6, "mg (1000 g)"), (1.0e6, "mg (1000 g)"), (1.0e6, "mg (1000 g)"), (300.0, "dB(A)")];

/// A ride-quality recording read from an `EVIMP1` text export.
#[derive(Debug, Clone, PartialEq)]
pub struct EvimpRecording {
    /// Sample rate, Hz (> 0).
    pub sample_rate_hz: f64,
    /// Horizontal acceleration x, mg, one value per sample.
    pub x_mg: Vec<f64>,
    /// Horizontal acceleration y, mg, one value per sample.
    pub y_mg: Vec<f64>,
    /// Vertical acceleration z, mg, one value per sample.
    pub z_mg: Vec<f64>,
    /// Sound level, dB(A), one value per sample; `None` when the rows hold
    /// only x y z.
    pub sound_dba: Option<Vec<f64>>,
}

impl EvimpRecording {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.z_mg.len()
    }

    /// Whether there are no samples (never true for a recording returned by
    /// [`read_evimp`]).
    pub fn is_empty(&self) -> bool {
        self.z_mg.is_empty()
    }

    /// Vertical acceleration z converted to m/s^2.
    pub fn z_mps2(&self) -> Vec<f64> {
        self.z_mg.iter().map(|v| v * 1e-3 * STANDARD_GRAVITY_MPS2).collect()
    }
}

/// Reads an `EVIMP1` export (see the module documentation for the layout).
///
/// Returns the sample rate in Hz, x, y, z in mg and, if the rows have a
/// fourth value, the sound level in dB(A). The file is not modified.
///
/// # Errors
/// A [`ReadError`] naming the file, the line, the column (`x_mg`, `y_mg`,
/// `z_mg`, `sound_dba`) and what was expected: unreadable file, not UTF-8,
/// first line not `EVIMP1` ([`ReadError::NotEvimp`]), missing or invalid
/// sample rate ([`ReadError::EvimpSampleRate`]), a row with other than 3 or 4
/// values or a different count than the first row
/// ([`ReadError::FieldCount`]), a non-numeric or non-finite value, a blank
/// line before the end, fewer than 2 samples.
pub fn read_evimp(path: &Path) -> Result<EvimpRecording, ReadError> {
    let path_buf = || path.to_path_buf();
    let mut lines = LineReader::new(open(path)?, path);

    let tag = lines.next_line()?.map(|(_, l)| l.trim().to_string());
    match tag.as_deref() {
        Some("EVIMP1") => {}
        Some(other) => return Err(ReadError::NotEvimp { path: path_buf(), found: excerpt(other) }),
        None => return Err(ReadError::NotEvimp { path: path_buf(), found: "<end of file>".to_string() }),
    }
    let sample_rate_hz = match lines.next_line()? {
        None => return Err(ReadError::EvimpSampleRate { path: path_buf(), found: "<end of file>".to_string() }),
        Some((_, text)) => match text.trim().parse::<f64>() {
            Ok(rate) if rate.is_finite() && rate > 0.0 && rate <= super::MAX_SAMPLE_RATE_HZ => rate,
            _ => return Err(ReadError::EvimpSampleRate { path: path_buf(), found: excerpt(text.trim()) }),
        },
    };

    let mut columns: [Vec<f64>; 4] = Default::default();
    let mut width: Option<(usize, usize)> = None; // (values per row, line that set it)
    let mut blank: Option<usize> = None;
    let mut rows = 0usize;
    while let Some((line, text)) = lines.next_line()? {
        let text = text.trim();
        if text.is_empty() {
            blank.get_or_insert(line);
            continue;
        }
        if let Some(blank_line) = blank {
            let expected = match width {
                Some((n, _)) => format!("a sample row with {n} values"),
                None => "a sample row with 3 or 4 values".to_string(),
            };
            return Err(ReadError::BlankLine { path: path_buf(), line: blank_line, expected });
        }
        let found = text.split_ascii_whitespace().count();
        match width {
            None if found == 3 || found == 4 => width = Some((found, line)),
            None => {
                return Err(ReadError::FieldCount {
                    path: path_buf(),
                    line,
                    found,
                    expected: "3 (x y z in mg) or 4 (x y z in mg, sound in dB(A)), separated by spaces".to_string(),
                })
            }
            Some((n, first)) if n != found => {
                return Err(ReadError::FieldCount {
                    path: path_buf(),
                    line,
                    found,
                    expected: format!("{n}, as in the first sample row (line {first})"),
                })
            }
            Some(_) => {}
        }
        for (((field, column), name), (limit, unit)) in
            text.split_ascii_whitespace().zip(&mut columns).zip(COLUMNS).zip(EVIMP_BOUNDS)
        {
            let value = match field.parse::<f64>() {
                Ok(v) if v.is_finite() && v.abs() > limit => {
                    return Err(ReadError::BeyondPhysicalBound {
                        path: path_buf(),
                        line,
                        column: name.to_string(),
                        text: excerpt(field),
                        limit,
                        unit,
                    })
                }
                Ok(v) if v.is_finite() => v,
                Ok(_) => {
                    return Err(ReadError::NonFinite {
                        path: path_buf(),
                        line,
                        column: name.to_string(),
                        text: excerpt(field),
                    })
                }
                Err(_) => {
                    return Err(ReadError::NotANumber {
                        path: path_buf(),
                        line,
                        column: name.to_string(),
                        text: excerpt(field),
                    })
                }
            };
            column.push(value);
        }
        rows += 1;
    }
    if rows < 2 {
        return Err(ReadError::TooFewSamples { path: path_buf(), found: rows });
    }
    let [x_mg, y_mg, z_mg, sound] = columns;
    let sound_dba = (width.map(|(n, _)| n) == Some(4)).then_some(sound);
    Ok(EvimpRecording { sample_rate_hz, x_mg, y_mg, z_mg, sound_dba })
}
