//! Writing a [`Recording`] as `<stem>.toml` + `<stem>.csv`.

use std::fs;
use std::io::Write as _;
use std::path::{Path, PathBuf};

use serde::Serialize;

use super::{CarDirection, Recording, RecordingError, RecordingKind, RecordingMeta, FORMAT, TIME_S};

/// Relative tolerance of the `time_s` step against `1 / sample_rate_hz`.
pub const TIME_STEP_RELATIVE_TOLERANCE: f64 = 1e-6;

/// The metadata file's layout: fields in the order of the specification.
#[derive(Serialize)]
struct MetaFile<'a> {
    format: &'static str,
    kind: &'static str,
    sample_rate_hz: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    description: Option<&'a str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    m_car_kg: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    m_cw_kg: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    direction: Option<&'static str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    lw_start_m: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    lw_end_m: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    mass_kg: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    rope_length_m: Option<f64>,
}

impl<'a> MetaFile<'a> {
    fn new(meta: &'a RecordingMeta) -> Self {
        let mut file = MetaFile {
            format: FORMAT,
            kind: meta.kind.name(),
            sample_rate_hz: meta.sample_rate_hz,
            description: meta.description.as_deref(),
            m_car_kg: None,
            m_cw_kg: None,
            direction: None,
            lw_start_m: None,
            lw_end_m: None,
            mass_kg: None,
            rope_length_m: None,
        };
        match meta.kind {
            RecordingKind::Travel { m_car_kg, m_cw_kg, direction, lw_start_m, lw_end_m } => {
                file.m_car_kg = Some(m_car_kg);
                file.m_cw_kg = Some(m_cw_kg);
                file.direction = Some(direction.as_str());
                file.lw_start_m = Some(lw_start_m);
                file.lw_end_m = Some(lw_end_m);
            }
            RecordingKind::FreeDecay { mass_kg, rope_length_m } => {
                file.mass_kg = Some(mass_kg);
                file.rope_length_m = Some(rope_length_m);
            }
        }
        file
    }
}

/// Validates `recording` and writes it to `dir` as `<stem>.toml` and
/// `<stem>.csv` in measurement format version 1; returns the paths of the
/// TOML and the CSV file, in that order.
///
/// * `dir`: dataset directory; created (with parents) if missing.
/// * `stem`: file name stem, non-empty, not `.`/`..`, without `/`, `\` or
///   control characters.
/// * `recording`: metadata in SI units (kg, m, Hz) and columns in the units
///   of their names (s, m/s^2, A, rad/s, rad, m/s).
///
/// Checks before anything is written:
/// * metadata: `sample_rate_hz`, the masses and the rope lengths finite and
///   positive; for a travel, `lw_end_m > lw_start_m` when the car goes up
///   and `lw_end_m < lw_start_m` when it goes down (whether `lw` lies within
///   the rope's total length is not known here and is left to the reader);
/// * columns: names non-empty, unique, without `,`, `"`, line breaks or
///   surrounding spaces; the columns the kind requires present (travel:
///   `time_s`, `acc_car_mps2`, `i_a_A`, `i_b_A`, `i_c_A`, `speed_radps`;
///   free decay: `time_s`, `acc_car_mps2`); all columns as long as `time_s`,
///   at least one sample; every value finite;
/// * `time_s` steps by `1 / sample_rate_hz` within a relative tolerance of
///   1e-6 of that period.
///
/// The TOML holds `format = "elevator-measurement/1"`, `kind`,
/// `sample_rate_hz`, `description` (if any) and the kind's fields. The CSV
/// has one header row with the column names in the order of
/// `recording.columns`, then one row per sample, comma separated, `\n` line
/// ends, each number as the shortest text that parses back to the same f64
/// bit pattern (Rust `{:?}`, e.g. `0.1`, `1e-7`, `-0.0`). Both files are
/// written to `<name>.tmp` first and renamed when complete, so a failure
/// leaves no partial recording.
///
/// # Errors
/// A [`RecordingError`] naming the offending field, column, sample or file.
pub fn write_recording(dir: &Path, stem: &str, recording: &Recording) -> Result<(PathBuf, PathBuf), RecordingError> {
    validate_stem(stem)?;
    validate_meta(&recording.meta)?;
    validate_columns(recording)?;

    let toml_path = dir.join(format!("{stem}.toml"));
    let csv_path = dir.join(format!("{stem}.csv"));
    let toml_text = toml::to_string(&MetaFile::new(&recording.meta))
        .map_err(|source| RecordingError::Toml { path: toml_path.clone(), source })?;

    fs::create_dir_all(dir).map_err(|source| RecordingError::Io { path: dir.to_path_buf(), source })?;
    let csv_tmp = tmp_path(&csv_path);
    let toml_tmp = tmp_path(&toml_path);
    let result = write_csv(&csv_tmp, &csv_path, recording)
        .and_then(|()| {
            fs::write(&toml_tmp, toml_text.as_bytes())
                .map_err(|source| RecordingError::Io { path: toml_path.clone(), source })
        })
        .and_then(|()| rename(&csv_tmp, &csv_path))
        .and_then(|()| rename(&toml_tmp, &toml_path));
    if result.is_err() {
        // Best effort cleanup of temporaries; the original error is reported.
        let _ = fs::remove_file(&csv_tmp);
        let _ = fs::remove_file(&toml_tmp);
    }
    result.map(|()| (toml_path, csv_path))
}

fn tmp_path(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_os_string();
    name.push(".tmp");
    PathBuf::from(name)
}

fn rename(from: &Path, to: &Path) -> Result<(), RecordingError> {
    fs::rename(from, to).map_err(|source| RecordingError::Io { path: to.to_path_buf(), source })
}

fn write_csv(tmp: &Path, final_path: &Path, recording: &Recording) -> Result<(), RecordingError> {
    let csv_err = |source| RecordingError::Csv { path: final_path.to_path_buf(), source };
    let io_err = |source| RecordingError::Io { path: final_path.to_path_buf(), source };
    let mut writer = csv::WriterBuilder::new().has_headers(false).from_path(tmp).map_err(csv_err)?;
    writer.write_record(recording.columns.iter().map(|c| c.name.as_str())).map_err(csv_err)?;
    // The samples are numbers, which never need quoting: each is written
    // as the shortest text that reads back to the same f64 (`ryu`, the
    // float formatting the `csv` crate itself uses), a row at a time.
    let file = writer.into_inner().map_err(|e| io_err(e.into_error()))?;
    let mut out = std::io::BufWriter::with_capacity(1 << 20, file);
    let rows = recording.columns.first().map_or(0, |c| c.values.len());
    let mut numbers = ryu::Buffer::new();
    let mut line = Vec::with_capacity(32 * recording.columns.len());
    for row in 0..rows {
        line.clear();
        for (i, column) in recording.columns.iter().enumerate() {
            if i > 0 {
                line.push(b',');
            }
            line.extend_from_slice(numbers.format(column.values[row]).as_bytes());
        }
        line.push(b'\n');
        out.write_all(&line).map_err(io_err)?;
    }
    out.flush().map_err(io_err)
}

fn validate_stem(stem: &str) -> Result<(), RecordingError> {
    let bad =
        stem.is_empty() || stem == "." || stem == ".." || stem.chars().any(|c| c == '/' || c == '\\' || c.is_control());
    if bad {
        return Err(RecordingError::InvalidStem {
            stem: stem.to_string(),
            expected: "a non-empty file name without `/`, `\\` or control characters, not `.` or `..`",
        });
    }
    Ok(())
}

fn positive(field: &'static str, value: f64, expected: &'static str) -> Result<(), RecordingError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(RecordingError::InvalidMeta { field, value, expected })
    }
}

fn validate_meta(meta: &RecordingMeta) -> Result<(), RecordingError> {
    positive("sample_rate_hz", meta.sample_rate_hz, "a finite sample rate > 0 Hz")?;
    match meta.kind {
        RecordingKind::Travel { m_car_kg, m_cw_kg, direction, lw_start_m, lw_end_m } => {
            positive("m_car_kg", m_car_kg, "a finite car mass > 0 kg")?;
            positive("m_cw_kg", m_cw_kg, "a finite counterweight mass > 0 kg")?;
            positive("lw_start_m", lw_start_m, "a finite rope length > 0 m")?;
            positive("lw_end_m", lw_end_m, "a finite rope length > 0 m")?;
            let (consistent, expected) = match direction {
                CarDirection::Up => (lw_end_m > lw_start_m, ">"),
                CarDirection::Down => (lw_end_m < lw_start_m, "<"),
            };
            if !consistent {
                return Err(RecordingError::DirectionMismatch {
                    direction: direction.as_str(),
                    lw_start_m,
                    lw_end_m,
                    expected,
                });
            }
        }
        RecordingKind::FreeDecay { mass_kg, rope_length_m } => {
            positive("mass_kg", mass_kg, "a finite mass > 0 kg")?;
            positive("rope_length_m", rope_length_m, "a finite rope length > 0 m")?;
        }
    }
    Ok(())
}

fn validate_columns(recording: &Recording) -> Result<(), RecordingError> {
    let columns = &recording.columns;
    for (i, column) in columns.iter().enumerate() {
        let name = column.name.as_str();
        let bad =
            name.is_empty() || name.trim() != name || name.chars().any(|c| c == ',' || c == '"' || c.is_control());
        if bad {
            return Err(RecordingError::InvalidColumnName {
                name: name.to_string(),
                expected: "a non-empty name without `,`, `\"`, control characters or surrounding spaces",
            });
        }
        if columns[..i].iter().any(|c| c.name == name) {
            return Err(RecordingError::DuplicateColumn { name: name.to_string() });
        }
    }
    let kind = &recording.meta.kind;
    for &required in kind.required_columns() {
        if recording.column(required).is_none() {
            return Err(RecordingError::MissingColumn { column: required, kind: kind.name() });
        }
    }
    let time = recording.column(TIME_S).ok_or(RecordingError::MissingColumn { column: TIME_S, kind: kind.name() })?;
    let rows = time.values.len();
    if rows == 0 {
        return Err(RecordingError::Empty);
    }
    for column in columns {
        if column.values.len() != rows {
            return Err(RecordingError::LengthMismatch {
                column: column.name.clone(),
                len: column.values.len(),
                expected: rows,
            });
        }
        if let Some((sample, &value)) = column.values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(RecordingError::NonFinite { column: column.name.clone(), sample, line: sample + 2, value });
        }
    }
    let period = 1.0 / recording.meta.sample_rate_hz;
    for (i, pair) in time.values.windows(2).enumerate() {
        let step = pair[1] - pair[0];
        // Written so that a non-finite step (overflow) also fails.
        let uniform = (step - period).abs() <= TIME_STEP_RELATIVE_TOLERANCE * period;
        if !uniform {
            return Err(RecordingError::NonUniformTime {
                sample: i + 1,
                sample_before: i,
                line: i + 3,
                step_s: step,
                expected_s: period,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::{Column, ACC_CAR, ACC_CW, ACC_MACHINE, ANGLE, I_A, I_B, I_C, KNOWN_COLUMNS, REF_SPEED, SPEED};
    use super::*;

    const FS: f64 = 16384.0;

    fn travel_meta() -> RecordingMeta {
        RecordingMeta {
            kind: RecordingKind::Travel {
                m_car_kg: 70.5,
                m_cw_kg: 33.0,
                direction: CarDirection::Up,
                lw_start_m: 1.0,
                lw_end_m: 7.6,
            },
            sample_rate_hz: FS,
            description: Some("simulated travel, \"quoted\" text\nsecond line".to_string()),
        }
    }

    /// Values chosen to stress the text round trip.
    fn tricky(i: usize, col: usize) -> f64 {
        let specials = [
            0.1 + 0.2,
            -0.0,
            1e-300,
            5e-324,
            f64::MAX,
            f64::MIN_POSITIVE,
            std::f64::consts::PI,
            -1.0 / 3.0,
            123_456_789.123_456_79,
            1e16,
            2.5e-7,
        ];
        match (i + col) % 3 {
            0 => specials[(i * 7 + col) % specials.len()],
            _ => ((i * 31 + col * 17) as f64).sin() * 10f64.powi((i % 9) as i32 - 4),
        }
    }

    fn travel_recording(rows: usize) -> Recording {
        let mut columns = vec![Column::new(TIME_S, (0..rows).map(|i| i as f64 / FS).collect())];
        for (c, name) in KNOWN_COLUMNS.iter().enumerate().skip(1) {
            columns.push(Column::new(*name, (0..rows).map(|i| tricky(i, c)).collect()));
        }
        columns.push(Column::new("extra_unknown", vec![42.0; rows]));
        Recording { meta: travel_meta(), columns }
    }

    fn decay_recording(rows: usize) -> Recording {
        Recording {
            meta: RecordingMeta {
                kind: RecordingKind::FreeDecay { mass_kg: 33.0, rope_length_m: 4.0 },
                sample_rate_hz: 1000.0,
                description: None,
            },
            columns: vec![
                Column::new(ACC_CAR, (0..rows).map(|i| tricky(i, 1)).collect()),
                Column::new(TIME_S, (0..rows).map(|i| 0.25 + i as f64 / 1000.0).collect()),
            ],
        }
    }

    fn float_bits(table: &toml::Table, key: &str) -> u64 {
        table[key].as_float().unwrap_or_else(|| panic!("{key} is not a float")).to_bits()
    }

    #[test]
    fn travel_round_trip_is_bit_exact() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("new/dataset");
        let rec = travel_recording(500);
        let (toml_path, csv_path) = write_recording(&target, "travel_up_m70.5_01", &rec).unwrap();
        assert_eq!(toml_path, target.join("travel_up_m70.5_01.toml"));
        assert_eq!(csv_path, target.join("travel_up_m70.5_01.csv"));

        // Metadata.
        let text = fs::read_to_string(&toml_path).unwrap();
        let table: toml::Table = toml::from_str(&text).unwrap();
        assert_eq!(table["format"].as_str(), Some("elevator-measurement/1"));
        assert_eq!(table["kind"].as_str(), Some("travel"));
        assert_eq!(table["direction"].as_str(), Some("up"));
        assert_eq!(table["description"].as_str(), rec.meta.description.as_deref());
        assert_eq!(float_bits(&table, "sample_rate_hz"), FS.to_bits());
        assert_eq!(float_bits(&table, "m_car_kg"), 70.5f64.to_bits());
        assert_eq!(float_bits(&table, "m_cw_kg"), 33.0f64.to_bits());
        assert_eq!(float_bits(&table, "lw_start_m"), 1.0f64.to_bits());
        assert_eq!(float_bits(&table, "lw_end_m"), 7.6f64.to_bits());
        assert!(!table.contains_key("mass_kg") && !table.contains_key("rope_length_m"));
        assert_eq!(table.len(), 9);

        // Samples.
        let mut reader = csv::Reader::from_path(&csv_path).unwrap();
        let headers: Vec<String> = reader.headers().unwrap().iter().map(String::from).collect();
        let names: Vec<&str> = rec.columns.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(headers, names);
        let mut rows = 0;
        for (i, record) in reader.records().enumerate() {
            let record = record.unwrap();
            assert_eq!(record.len(), rec.columns.len());
            for (field, column) in record.iter().zip(&rec.columns) {
                let parsed: f64 = field.parse().unwrap();
                assert_eq!(parsed.to_bits(), column.values[i].to_bits(), "column {} row {i}: {field}", column.name);
            }
            rows += 1;
        }
        assert_eq!(rows, 500);
        // No temporary files are left behind.
        let mut names: Vec<String> =
            fs::read_dir(&target).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
        names.sort();
        assert_eq!(names, ["travel_up_m70.5_01.csv", "travel_up_m70.5_01.toml"]);
        // Plain comma-separated text with `\n` line ends and the header first.
        let raw = fs::read_to_string(&csv_path).unwrap();
        assert!(raw.starts_with("time_s,acc_car_mps2,acc_cw_mps2,"));
        assert!(!raw.contains('\r'));
        assert_eq!(raw.lines().count(), 501);
    }

    #[test]
    fn free_decay_round_trip_without_description() {
        let dir = tempfile::tempdir().unwrap();
        let rec = decay_recording(50);
        let (toml_path, csv_path) = write_recording(dir.path(), "decay_l4.0_m33", &rec).unwrap();
        let table: toml::Table = toml::from_str(&fs::read_to_string(toml_path).unwrap()).unwrap();
        assert_eq!(table["kind"].as_str(), Some("free_decay"));
        assert_eq!(float_bits(&table, "sample_rate_hz"), 1000.0f64.to_bits());
        assert_eq!(float_bits(&table, "mass_kg"), 33.0f64.to_bits());
        assert_eq!(float_bits(&table, "rope_length_m"), 4.0f64.to_bits());
        assert!(!table.contains_key("description"));
        assert!(!table.contains_key("direction"));
        assert_eq!(table.len(), 5);
        let mut reader = csv::Reader::from_path(csv_path).unwrap();
        assert_eq!(reader.headers().unwrap(), vec![ACC_CAR, TIME_S]);
        for (i, record) in reader.records().enumerate() {
            let record = record.unwrap();
            for (field, column) in record.iter().zip(&rec.columns) {
                assert_eq!(field.parse::<f64>().unwrap().to_bits(), column.values[i].to_bits());
            }
        }
    }

    /// Runs the writer on a broken recording; checks that the error message
    /// names `needle` and that nothing was written.
    fn expect_error(rec: &Recording, stem: &str, needle: &str) -> RecordingError {
        let dir = tempfile::tempdir().unwrap();
        let err = write_recording(dir.path(), stem, rec).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains(needle), "message {msg:?} does not name {needle:?}");
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 0, "files written");
        err
    }

    fn with_travel(f: impl Fn(&mut f64, &mut f64, &mut CarDirection, &mut f64, &mut f64)) -> Recording {
        let mut rec = travel_recording(10);
        if let RecordingKind::Travel { m_car_kg, m_cw_kg, direction, lw_start_m, lw_end_m } = &mut rec.meta.kind {
            f(m_car_kg, m_cw_kg, direction, lw_start_m, lw_end_m);
        }
        rec
    }

    #[test]
    fn metadata_errors_name_the_field() {
        let mut rec = travel_recording(10);
        rec.meta.sample_rate_hz = 0.0;
        expect_error(&rec, "s", "sample_rate_hz");
        rec.meta.sample_rate_hz = f64::NAN;
        expect_error(&rec, "s", "sample_rate_hz");

        expect_error(&with_travel(|m, _, _, _, _| *m = -70.5), "s", "m_car_kg");
        expect_error(&with_travel(|_, m, _, _, _| *m = 0.0), "s", "m_cw_kg");
        expect_error(&with_travel(|_, _, _, l, _| *l = -1.0), "s", "lw_start_m");
        expect_error(&with_travel(|_, _, _, _, l| *l = f64::INFINITY), "s", "lw_end_m");

        let mut rec = decay_recording(10);
        rec.meta.kind = RecordingKind::FreeDecay { mass_kg: -1.0, rope_length_m: 4.0 };
        expect_error(&rec, "s", "mass_kg");
        rec.meta.kind = RecordingKind::FreeDecay { mass_kg: 1.0, rope_length_m: 0.0 };
        expect_error(&rec, "s", "rope_length_m");
    }

    #[test]
    fn direction_must_match_rope_length_change() {
        let down_but_growing = with_travel(|_, _, d, _, _| *d = CarDirection::Down);
        let e = expect_error(&down_but_growing, "s", "direction");
        assert!(matches!(e, RecordingError::DirectionMismatch { direction: "down", expected: "<", .. }));
        let up_but_shrinking = with_travel(|_, _, _, s, e| {
            *s = 7.6;
            *e = 1.0;
        });
        expect_error(&up_but_shrinking, "s", "lw_end_m > lw_start_m");
        let no_change = with_travel(|_, _, _, s, e| {
            *s = 3.0;
            *e = 3.0;
        });
        expect_error(&no_change, "s", "direction");
        // Down with shrinking lw is fine.
        let dir = tempfile::tempdir().unwrap();
        let ok = with_travel(|_, _, d, s, e| {
            *d = CarDirection::Down;
            *s = 7.6;
            *e = 1.0;
        });
        let (toml_path, _) = write_recording(dir.path(), "down", &ok).unwrap();
        let table: toml::Table = toml::from_str(&fs::read_to_string(toml_path).unwrap()).unwrap();
        assert_eq!(table["direction"].as_str(), Some("down"));
    }

    #[test]
    fn column_errors_name_the_column() {
        // Missing required travel column.
        for required in [TIME_S, ACC_CAR, I_A, I_B, I_C, SPEED] {
            let mut rec = travel_recording(10);
            rec.columns.retain(|c| c.name != required);
            let e = expect_error(&rec, "s", required);
            assert!(e.to_string().contains("travel"));
        }
        // Optional columns may be left out.
        let dir = tempfile::tempdir().unwrap();
        let mut rec = travel_recording(10);
        rec.columns.retain(|c| ![ACC_CW, ACC_MACHINE, ANGLE, REF_SPEED].contains(&c.name.as_str()));
        write_recording(dir.path(), "minimal", &rec).unwrap();

        // Missing required decay column.
        let mut rec = decay_recording(10);
        rec.columns.retain(|c| c.name != ACC_CAR);
        expect_error(&rec, "s", "acc_car_mps2");

        // Length mismatch.
        let mut rec = travel_recording(10);
        rec.columns[3].values.pop();
        let e = expect_error(&rec, "s", "acc_machine_mps2");
        assert!(e.to_string().contains("9 samples") && e.to_string().contains("10"));

        // NaN and infinity name the column, sample and CSV line.
        let mut rec = travel_recording(10);
        rec.columns[5].values[4] = f64::NAN;
        let e = expect_error(&rec, "s", "i_b_A");
        assert!(matches!(e, RecordingError::NonFinite { sample: 4, line: 6, .. }), "{e:?}");
        let mut rec = travel_recording(10);
        rec.columns[0].values[9] = f64::NEG_INFINITY;
        expect_error(&rec, "s", "time_s");

        // Duplicate and malformed names.
        let mut rec = travel_recording(10);
        rec.columns.push(Column::new(SPEED, vec![0.0; 10]));
        expect_error(&rec, "s", "speed_radps");
        for bad in ["", "a,b", "q\"", " lead", "line\nbreak"] {
            let mut rec = travel_recording(10);
            rec.columns.push(Column::new(bad, vec![0.0; 10]));
            let e = expect_error(&rec, "s", "column name");
            assert!(matches!(e, RecordingError::InvalidColumnName { .. }));
        }

        // No samples.
        let mut rec = decay_recording(0);
        rec.columns.iter_mut().for_each(|c| c.values.clear());
        expect_error(&rec, "s", "time_s");
    }

    #[test]
    fn time_must_be_uniform_within_tolerance() {
        let period = 1.0 / FS;
        // 0.5e-6 relative jitter is accepted.
        let dir = tempfile::tempdir().unwrap();
        let mut rec = travel_recording(10);
        rec.columns[0].values[5] += 0.5e-6 * period;
        write_recording(dir.path(), "jitter", &rec).unwrap();
        // 2e-6 relative is not.
        let mut rec = travel_recording(10);
        rec.columns[0].values[5] += 2e-6 * period;
        let e = expect_error(&rec, "s", "time_s");
        assert!(matches!(e, RecordingError::NonUniformTime { sample: 5, sample_before: 4, line: 7, .. }), "{e:?}");
        assert!(e.to_string().contains("sample_rate_hz"));
        // A recording whose time is for another sample rate.
        let mut rec = travel_recording(10);
        rec.meta.sample_rate_hz = 8192.0;
        expect_error(&rec, "s", "time_s");
        // Decreasing time.
        let mut rec = decay_recording(10);
        rec.columns[1].values.reverse();
        expect_error(&rec, "s", "time_s");
    }

    #[test]
    fn stem_is_checked() {
        let rec = decay_recording(3);
        for bad in ["", ".", "..", "a/b", "a\\b", "tab\there"] {
            let e = expect_error(&rec, bad, "stem");
            assert!(matches!(e, RecordingError::InvalidStem { .. }));
        }
    }

    #[test]
    fn toml_text_follows_the_specification_layout() {
        let dir = tempfile::tempdir().unwrap();
        let mut rec = travel_recording(3);
        rec.meta.description = Some("free text".to_string());
        let (toml_path, _) = write_recording(dir.path(), "layout", &rec).unwrap();
        let text = fs::read_to_string(toml_path).unwrap();
        let keys: Vec<&str> = text.lines().filter_map(|l| l.split_once('=').map(|(k, _)| k.trim())).collect();
        assert_eq!(
            keys,
            [
                "format",
                "kind",
                "sample_rate_hz",
                "description",
                "m_car_kg",
                "m_cw_kg",
                "direction",
                "lw_start_m",
                "lw_end_m"
            ]
        );
        assert!(text.contains("format = \"elevator-measurement/1\""), "{text}");
        assert!(text.contains("kind = \"travel\""), "{text}");
    }
}
