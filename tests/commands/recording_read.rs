//! Reading datasets in measurement format version 1 and `EVIMP1` exports:
//! round trips with the writer, every kind of malformed input refused with a
//! message naming the file, the line/field/column and what was expected,
//! inputs never modified, and no panic on arbitrary or mutated input. The
//! format is tested through `parse_recording` and `parse_dataset` (the
//! samples here stress the text, not the physics); the checks of a
//! recording against itself are in `recording::consistency`.

use std::fs;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::{Instant, SystemTime};

use proptest::prelude::*;
use recording::{
    parse_dataset, parse_recording, read_evimp, read_recording, write_recording, CarDirection, Column, ReadError,
    Recording, RecordingKind, RecordingMeta, ACC_CAR, ACC_CW, ACC_MACHINE, ANGLE, I_A, I_B, I_C, REF_SPEED, SPEED,
    TIME_S,
};
use rig_config::RigConfig;

/// Total rope length of the default rig, m (8.6).
fn rope_total() -> f64 {
    static TOTAL: OnceLock<f64> = OnceLock::new();
    *TOTAL.get_or_init(|| RigConfig::embedded_default().unwrap().mechanics.rope_total_length_m)
}

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
        description: Some("travel, \"quoted\" text\nand a second line".to_string()),
    }
}

/// Values that stress the text round trip.
fn tricky(i: usize, col: usize) -> f64 {
    let specials =
        [0.1 + 0.2, -0.0, 1e-300, 5e-324, f64::MAX, f64::MIN_POSITIVE, std::f64::consts::PI, -1.0 / 3.0, 1e16];
    match (i + col) % 3 {
        0 => specials[(i * 7 + col) % specials.len()],
        _ => ((i * 31 + col * 17) as f64).sin() * 10f64.powi((i % 9) as i32 - 4),
    }
}

/// [`tricky`] for the known column `name`: a value beyond the column's
/// physical bound (`f64::MAX`, `1e16`) is scaled into it, still a value
/// that stresses the text round trip. Unknown columns keep every value.
fn tricky_in(name: &str, i: usize, col: usize) -> f64 {
    let v = tricky(i, col);
    match recording::column_bound(name) {
        Some((bound, _)) if v.abs() > bound => v * (bound / f64::MAX),
        _ => v,
    }
}

/// A travel with every known column (not in the table's order) and two
/// unknown ones.
fn travel_recording(rows: usize) -> Recording {
    let mut columns = vec![Column::new(ACC_CAR, (0..rows).map(|i| tricky_in(ACC_CAR, i, 1)).collect())];
    columns.push(Column::new(TIME_S, (0..rows).map(|i| i as f64 / FS).collect()));
    for (c, name) in [ACC_CW, ACC_MACHINE, I_A, I_B, I_C, SPEED, ANGLE, REF_SPEED].iter().enumerate() {
        columns.push(Column::new(*name, (0..rows).map(|i| tricky_in(name, i, c + 2)).collect()));
    }
    columns.push(Column::new("strain_gauge_V", (0..rows).map(|i| tricky(i, 11)).collect()));
    columns.push(Column::new("temperature_degC", vec![21.5; rows]));
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
            Column::new(TIME_S, (0..rows).map(|i| 0.25 + i as f64 / 1000.0).collect()),
            Column::new(ACC_CAR, (0..rows).map(|i| tricky_in(ACC_CAR, i, 1)).collect()),
        ],
    }
}

fn assert_bit_identical(a: &Recording, b: &Recording) {
    assert_eq!(a.meta, b.meta);
    assert_eq!(a.columns.len(), b.columns.len());
    for (x, y) in a.columns.iter().zip(&b.columns) {
        assert_eq!(x.name, y.name);
        assert_eq!(x.values.len(), y.values.len(), "column {}", x.name);
        for (i, (u, v)) in x.values.iter().zip(&y.values).enumerate() {
            assert_eq!(u.to_bits(), v.to_bits(), "column {} sample {i}: {u:?} vs {v:?}", x.name);
        }
    }
}

// ---------------------------------------------------------------------------
// Round trips and accepted variations

#[test]
fn travel_round_trip_is_bit_identical() {
    let dir = tempfile::tempdir().unwrap();
    let rec = travel_recording(2000);
    let (toml_path, _) = write_recording(dir.path(), "travel_up_m70.5_01", &rec).unwrap();
    let back = parse_recording(&toml_path, rope_total()).unwrap();
    assert_bit_identical(&rec, &back);
    assert_eq!(rec, back);
}

#[test]
fn free_decay_round_trip_is_bit_identical() {
    let dir = tempfile::tempdir().unwrap();
    let rec = decay_recording(300);
    let (toml_path, _) = write_recording(dir.path(), "decay_l4.0_m33", &rec).unwrap();
    let back = parse_recording(&toml_path, rope_total()).unwrap();
    assert_bit_identical(&rec, &back);
}

const VALID_TOML: &str = "format = \"elevator-measurement/1\"
kind = \"travel\"
sample_rate_hz = 1000.0
description = \"hand-written\"
m_car_kg = 70.5
m_cw_kg = 33.0
direction = \"up\"
lw_start_m = 1.0
lw_end_m = 7.6
";

const VALID_CSV: &str = "time_s,acc_car_mps2,i_a_A,i_b_A,i_c_A,speed_radps
0,0.1,1,2,-3,0.5
0.001,-0.2,1.5,2.5,-4,0.75
0.002,1e-3,-0.25,2,-1.75,1
0.003,0.0,0,0,0,1.25
";

fn write_pair(dir: &Path, stem: &str, toml: impl AsRef<[u8]>, csv: impl AsRef<[u8]>) -> PathBuf {
    let toml_path = dir.join(format!("{stem}.toml"));
    fs::write(&toml_path, toml).unwrap();
    fs::write(dir.join(format!("{stem}.csv")), csv).unwrap();
    toml_path
}

#[test]
fn hand_written_dataset_with_windows_line_ends_bom_quotes_and_integers_loads() {
    let dir = tempfile::tempdir().unwrap();
    let toml = VALID_TOML.replace("m_cw_kg = 33.0", "m_cw_kg = 33\noperator = \"unknown fields are allowed\"");
    let csv = format!(
        "\u{feff}\"time_s\",acc_car_mps2,i_a_A,i_b_A,i_c_A,speed_radps,extra\r\n{}\r\n\r\n",
        VALID_CSV.lines().skip(1).map(|l| format!("{l},\"7\"")).collect::<Vec<_>>().join("\r\n")
    );
    let path = write_pair(dir.path(), "windows", toml.replace('\n', "\r\n"), csv);
    let rec = parse_recording(&path, rope_total()).unwrap();
    assert_eq!(rec.meta.sample_rate_hz, 1000.0);
    assert_eq!(rec.meta.description.as_deref(), Some("hand-written"));
    assert!(matches!(rec.meta.kind, RecordingKind::Travel { m_cw_kg: 33.0, .. }));
    let names: Vec<&str> = rec.columns.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, [TIME_S, ACC_CAR, I_A, I_B, I_C, SPEED, "extra"]);
    assert_eq!(rec.column(ACC_CAR).unwrap().values, [0.1, -0.2, 1e-3, 0.0]);
    assert_eq!(rec.column("extra").unwrap().values, [7.0; 4]);
}

#[test]
fn dataset_reads_every_pair_sorted_by_stem_and_ignores_other_files() {
    let dir = tempfile::tempdir().unwrap();
    write_recording(dir.path(), "travel_b", &travel_recording(20)).unwrap();
    write_recording(dir.path(), "decay_l4.0_m33", &decay_recording(20)).unwrap();
    write_pair(dir.path(), "a_hand", VALID_TOML, VALID_CSV);
    fs::write(dir.path().join("README.txt"), "notes").unwrap();
    fs::write(dir.path().join("orphan.csv"), "not a recording").unwrap();
    fs::create_dir(dir.path().join("plots.toml")).unwrap();
    let set = parse_dataset(dir.path(), rope_total()).unwrap();
    let stems: Vec<&str> = set.iter().map(|(s, _)| s.as_str()).collect();
    assert_eq!(stems, ["a_hand", "decay_l4.0_m33", "travel_b"]);
    assert_bit_identical(&set[2].1, &travel_recording(20));
    assert_bit_identical(&set[1].1, &decay_recording(20));
}

// ---------------------------------------------------------------------------
// Malformed datasets: each error names the file and the line/field/column
// and says what was expected.

/// Writes the pair, reads it, and checks that the message contains every
/// needle (and the file name of `named`, "toml" or "csv").
fn refused(toml: impl AsRef<[u8]>, csv: impl AsRef<[u8]>, named: &str, needles: &[&str]) -> ReadError {
    let dir = tempfile::tempdir().unwrap();
    let path = write_pair(dir.path(), "rec_01", toml, csv);
    let err = parse_recording(&path, rope_total()).expect_err("malformed input was accepted");
    let msg = err.to_string();
    assert!(msg.contains(&format!("rec_01.{named}`")), "message {msg:?} does not name rec_01.{named}");
    assert!(msg.contains("expected"), "message {msg:?} does not say what was expected");
    for needle in needles {
        assert!(msg.contains(needle), "message {msg:?} does not contain {needle:?}");
    }
    err
}

fn toml_with(from: &str, to: &str) -> String {
    assert!(VALID_TOML.contains(from), "{from}");
    VALID_TOML.replace(from, to)
}

fn csv_with(from: &str, to: &str) -> String {
    assert!(VALID_CSV.contains(from), "{from}");
    VALID_CSV.replacen(from, to, 1)
}

#[test]
fn k01_missing_files() {
    let dir = tempfile::tempdir().unwrap();
    // The .csv of a recording is missing.
    let path = dir.path().join("lonely.toml");
    fs::write(&path, VALID_TOML).unwrap();
    let msg = parse_recording(&path, rope_total()).unwrap_err().to_string();
    assert!(msg.contains("lonely.toml") && msg.contains("lonely.csv") && msg.contains("expected"), "{msg}");
    // In a dataset too.
    let msg = parse_dataset(dir.path(), rope_total()).unwrap_err().to_string();
    assert!(msg.contains("lonely.csv") && msg.contains("in pairs"), "{msg}");
    // The .toml itself is missing (but its .csv exists).
    fs::write(dir.path().join("ghost.csv"), VALID_CSV).unwrap();
    let err = parse_recording(&dir.path().join("ghost.toml"), rope_total()).unwrap_err();
    assert!(matches!(err, ReadError::Io { .. }), "{err:?}");
    let msg = err.to_string();
    assert!(msg.contains("ghost.toml") && msg.contains("cannot read") && msg.contains("expected"), "{msg}");
    // Not a .toml path.
    let msg = parse_recording(&dir.path().join("ghost.csv"), rope_total()).unwrap_err().to_string();
    assert!(msg.contains("ghost.csv") && msg.contains("expected a path ending in `.toml`"), "{msg}");
}

#[test]
fn k02_empty_or_unreadable_dataset() {
    let dir = tempfile::tempdir().unwrap();
    fs::write(dir.path().join("orphan.csv"), VALID_CSV).unwrap();
    let msg = parse_dataset(dir.path(), rope_total()).unwrap_err().to_string();
    assert!(msg.contains(&dir.path().display().to_string()) && msg.contains("no recording"), "{msg}");
    assert!(msg.contains("expected at least one `<stem>.toml`"), "{msg}");
    let missing = dir.path().join("no_such_dir");
    let msg = parse_dataset(&missing, rope_total()).unwrap_err().to_string();
    assert!(msg.contains("no_such_dir") && msg.contains("cannot read"), "{msg}");
}

#[test]
fn k03_not_utf8() {
    let mut toml = VALID_TOML.as_bytes().to_vec();
    toml.splice(56..56, [0xff, 0xfe]); // inside line 3
    let e = refused(&toml, VALID_CSV, "toml", &["line 3", "UTF-8"]);
    assert!(matches!(e, ReadError::NotUtf8 { line: 3, .. }), "{e:?}");
    let mut csv = VALID_CSV.as_bytes().to_vec();
    let at = VALID_CSV.find("0.001").unwrap() + 2;
    csv.insert(at, 0xc3);
    let e = refused(VALID_TOML, &csv, "csv", &["line 3, byte 3", "not valid UTF-8", "expected UTF-8"]);
    assert!(matches!(e, ReadError::NotUtf8 { line: 3, byte: 3, .. }), "{e:?}");
}

#[test]
fn k04_toml_syntax_error_has_line_and_column() {
    let toml = toml_with("m_cw_kg = 33.0", "m_cw_kg = = 33.0");
    let e = refused(&toml, VALID_CSV, "toml", &["line 6, column 11", "TOML syntax error", "expected"]);
    assert!(matches!(e, ReadError::TomlSyntax { line: 6, column: 11, .. }), "{e:?}");
    // Duplicate keys are syntax errors in TOML.
    refused(format!("{VALID_TOML}kind = \"travel\"\n"), VALID_CSV, "toml", &["line 10", "duplicate key"]);
}

#[test]
fn k05_format_missing_or_unknown() {
    refused(
        toml_with("format = \"elevator-measurement/1\"\n", ""),
        VALID_CSV,
        "toml",
        &["`format` is missing", "format = \"elevator-measurement/1\""],
    );
    let e = refused(
        toml_with("elevator-measurement/1", "elevator-measurement/2"),
        VALID_CSV,
        "toml",
        &["line 1", "`format`", "\"elevator-measurement/2\"", "expected exactly \"elevator-measurement/1\""],
    );
    assert!(matches!(e, ReadError::UnknownFormat { line: 1, .. }));
}

#[test]
fn k06_kind_missing_or_unknown() {
    refused(toml_with("kind = \"travel\"\n", ""), VALID_CSV, "toml", &["`kind` is missing", "\"free_decay\""]);
    refused(
        toml_with("kind = \"travel\"", "kind = \"Travel\""),
        VALID_CSV,
        "toml",
        &["line 2", "`kind`", "\"Travel\"", "expected \"travel\" or \"free_decay\""],
    );
}

#[test]
fn k07_required_field_missing_names_it() {
    for field in ["sample_rate_hz", "m_car_kg", "m_cw_kg", "direction", "lw_start_m", "lw_end_m"] {
        let line = VALID_TOML.lines().find(|l| l.starts_with(field)).unwrap();
        let toml = toml_with(&format!("{line}\n"), "");
        let e = refused(&toml, VALID_CSV, "toml", &[&format!("required field `{field}` is missing")]);
        assert!(matches!(e, ReadError::MissingField { .. }), "{e:?}");
    }
    let decay = "format = \"elevator-measurement/1\"\nkind = \"free_decay\"\nsample_rate_hz = 1000\nmass_kg = 33\n";
    refused(decay, "time_s,acc_car_mps2\n0,1\n0.001,2\n", "toml", &["`rope_length_m` is missing", "rope length > 0 m"]);
}

#[test]
fn k08_wrong_type_names_field_and_type() {
    let e = refused(
        toml_with("m_car_kg = 70.5", "m_car_kg = \"70.5\""),
        VALID_CSV,
        "toml",
        &["line 5", "field `m_car_kg` is a string", "expected a number (kg)"],
    );
    assert!(matches!(e, ReadError::WrongType { line: 5, field: "m_car_kg", .. }), "{e:?}");
    refused(
        toml_with("direction = \"up\"", "direction = true"),
        VALID_CSV,
        "toml",
        &["line 7", "`direction` is a boolean", "expected a string"],
    );
    refused(
        toml_with("format = \"elevator-measurement/1\"", "format = 1"),
        VALID_CSV,
        "toml",
        &["line 1", "`format` is an integer"],
    );
    refused(
        toml_with("description = \"hand-written\"", "description = [1]"),
        VALID_CSV,
        "toml",
        &["line 4", "`description` is an array", "expected a string"],
    );
    refused(
        toml_with("sample_rate_hz = 1000.0", "sample_rate_hz = { hz = 1000 }"),
        VALID_CSV,
        "toml",
        &["line 3", "`sample_rate_hz` is a table", "a number (Hz)"],
    );
}

#[test]
fn k09_value_out_of_physical_range_names_field() {
    let cases = [
        ("m_car_kg = 70.5", "m_car_kg = -70.5", "line 5", "`m_car_kg` = -70.5", "car mass > 0 kg"),
        ("m_cw_kg = 33.0", "m_cw_kg = 0.0", "line 6", "`m_cw_kg` = 0", "counterweight mass > 0 kg"),
        (
            "sample_rate_hz = 1000.0",
            "sample_rate_hz = 0",
            "line 3",
            "`sample_rate_hz` = 0",
            "sample rate of 1 to 10000000 Hz",
        ),
        (
            "sample_rate_hz = 1000.0",
            "sample_rate_hz = -1e3",
            "line 3",
            "`sample_rate_hz` = -1000",
            "sample rate of 1 to 10000000 Hz",
        ),
        ("sample_rate_hz = 1000.0", "sample_rate_hz = nan", "line 3", "`sample_rate_hz` = NaN", "finite"),
        ("lw_start_m = 1.0", "lw_start_m = 0.0", "line 8", "`lw_start_m` = 0", "in (0, 8.6) m"),
        ("lw_end_m = 7.6", "lw_end_m = 8.6", "line 9", "`lw_end_m` = 8.6", "in (0, 8.6) m"),
        ("lw_end_m = 7.6", "lw_end_m = inf", "line 9", "`lw_end_m` = inf", "rope_total_length_m"),
    ];
    for (from, to, line, field, expected) in cases {
        let e = refused(toml_with(from, to), VALID_CSV, "toml", &[line, field, "out of range", expected]);
        assert!(matches!(e, ReadError::OutOfRange { .. }), "{e:?}");
    }
    let decay = |mass: &str, length: &str| {
        format!("format = \"elevator-measurement/1\"\nkind = \"free_decay\"\nsample_rate_hz = 1000.0\nmass_kg = {mass}\nrope_length_m = {length}\n")
    };
    let csv = "time_s,acc_car_mps2\n0,1\n0.001,2\n";
    refused(decay("-33", "4"), csv, "toml", &["line 4", "`mass_kg` = -33", "mass > 0 kg"]);
    refused(decay("33", "0"), csv, "toml", &["line 5", "`rope_length_m` = 0", "rope length > 0 m"]);
    refused(decay("33", "-4.0"), csv, "toml", &["line 5", "`rope_length_m` = -4"]);
}

#[test]
fn k10_direction_invalid() {
    let e = refused(
        toml_with("direction = \"up\"", "direction = \"Up\""),
        VALID_CSV,
        "toml",
        &["line 7", "`direction` is \"Up\"", "expected \"up\" or \"down\""],
    );
    assert!(matches!(e, ReadError::InvalidDirection { .. }));
}

#[test]
fn k11_direction_contradicts_rope_length_change() {
    let e = refused(
        toml_with("direction = \"up\"", "direction = \"down\""),
        VALID_CSV,
        "toml",
        &["line 7", "`direction` = \"down\"", "lw_start_m = 1 m", "lw_end_m = 7.6 m", "expected lw_end_m < lw_start_m"],
    );
    assert!(matches!(e, ReadError::DirectionMismatch { relation: "<", .. }));
    refused(
        toml_with("lw_end_m = 7.6", "lw_end_m = 1.0"),
        VALID_CSV,
        "toml",
        &["`direction` = \"up\"", "expected lw_end_m > lw_start_m", "lw grows"],
    );
}

#[test]
fn k12_csv_empty_or_without_header() {
    let e = refused(VALID_TOML, "", "csv", &["line 1", "the file is empty", "expected a header row"]);
    assert!(matches!(e, ReadError::NoHeader { .. }));
    refused(VALID_TOML, format!("\n{VALID_CSV}"), "csv", &["line 1", "blank", "expected a header row"]);
}

#[test]
fn k13_required_column_missing_names_it() {
    for column in [TIME_S, ACC_CAR, I_A, I_B, I_C, SPEED] {
        let csv = VALID_CSV.replacen(column, "other", 1);
        let e = refused(
            VALID_TOML,
            &csv,
            "csv",
            &["line 1", &format!("required column `{column}` is missing"), "`travel`"],
        );
        assert!(matches!(e, ReadError::MissingColumn { .. }), "{e:?}");
    }
    // A near miss is pointed out.
    refused(
        VALID_TOML,
        csv_with("time_s,acc_car_mps2,", "time_s, acc_car_mps2,"),
        "csv",
        &["required column `acc_car_mps2` is missing", "the header has ` acc_car_mps2`"],
    );
}

#[test]
fn k14_duplicate_or_empty_column_name() {
    let e = refused(
        VALID_TOML,
        csv_with("speed_radps", "i_a_A"),
        "csv",
        &["line 1", "column `i_a_A` appears twice (fields 3 and 6)", "expected unique column names"],
    );
    assert!(matches!(e, ReadError::DuplicateColumn { first: 3, second: 6, .. }), "{e:?}");
    // A trailing comma on every line makes an empty last column name.
    let trailing = VALID_CSV.replace('\n', ",\n");
    refused(VALID_TOML, trailing, "csv", &["line 1, field 7", "column name is empty", "expected a name"]);
}

#[test]
fn k15_row_with_wrong_number_of_fields() {
    let e = refused(
        VALID_TOML,
        csv_with("0.002,1e-3,", "0.002,1e-3,,"),
        "csv",
        &["line 4 has 7 fields", "expected 6, one per header column"],
    );
    assert!(matches!(e, ReadError::FieldCount { line: 4, found: 7, .. }));
    refused(VALID_TOML, csv_with(",0.75\n", "\n"), "csv", &["line 3 has 5 fields", "expected 6"]);
    // A decimal comma shows as an extra field.
    refused(VALID_TOML, csv_with("-0.2", "-0,2"), "csv", &["line 3 has 7 fields"]);
}

#[test]
fn k16_value_not_a_number() {
    let e = refused(
        VALID_TOML,
        csv_with("1.5,2.5", "1.5,2.5.1"),
        "csv",
        &["line 3, column `i_b_A`", "`2.5.1` is not a number", "expected f64 text"],
    );
    assert!(matches!(e, ReadError::NotANumber { line: 3, .. }));
    refused(VALID_TOML, csv_with("0.1,1,2", "0.1, 1,2"), "csv", &["line 2, column `i_a_A`", "` 1` is not a number"]);
    refused(VALID_TOML, csv_with(",0.5\n", ",\"fast\"\n"), "csv", &["line 2, column `speed_radps`", "`fast`"]);
}

#[test]
fn k17_nan_infinite_or_empty_value_is_a_gap() {
    let e = refused(
        VALID_TOML,
        csv_with("1e-3", "NaN"),
        "csv",
        &["line 4, column `acc_car_mps2`", "`NaN` is not finite", "expected a finite number"],
    );
    assert!(matches!(e, ReadError::NonFinite { line: 4, .. }));
    refused(VALID_TOML, csv_with("-4", "-inf"), "csv", &["line 3, column `i_c_A`", "`-inf` is not finite"]);
    refused(VALID_TOML, csv_with("-4", "-1e400"), "csv", &["line 3, column `i_c_A`", "`-1e400` is not finite"]);
    let e = refused(
        VALID_TOML,
        csv_with("0,0,0,1.25", "0,,0,1.25"),
        "csv",
        &["line 5, column `i_b_A`", "the value is empty", "expected a number (a gap in the data is an error)"],
    );
    assert!(matches!(e, ReadError::EmptyValue { line: 5, .. }));
}

#[test]
fn k18_time_not_uniform() {
    let e = refused(
        VALID_TOML,
        csv_with("0.002,", "0.0021,"),
        "csv",
        &["line 4, column `time_s`", "steps by 0.0010999", "expected 0.001 s (1 / sample_rate_hz)", "1e-6"],
    );
    assert!(matches!(e, ReadError::NonUniformTime { line: 4, .. }), "{e:?}");
    // Decreasing time.
    refused(VALID_TOML, csv_with("0.003,", "0.001,"), "csv", &["line 5, column `time_s`", "steps by -0.001"]);
    // The wrong sample rate in the metadata.
    refused(
        toml_with("sample_rate_hz = 1000.0", "sample_rate_hz = 1024.0"),
        VALID_CSV,
        "csv",
        &["line 3", "expected 0.0009765625 s"],
    );
    // A relative error of 2e-6 is refused, 0.5e-6 is accepted.
    refused(VALID_TOML, csv_with("0.001,", "0.001000002,"), "csv", &["line 3"]);
    let dir = tempfile::tempdir().unwrap();
    let ok = write_pair(dir.path(), "jitter", VALID_TOML, csv_with("0.001,", "0.0010000005,"));
    parse_recording(&ok, rope_total()).unwrap();
}

#[test]
fn k19_fewer_than_two_samples() {
    let header = VALID_CSV.lines().next().unwrap();
    let e = refused(VALID_TOML, format!("{header}\n"), "csv", &["0 sample row(s)", "expected at least 2"]);
    assert!(matches!(e, ReadError::TooFewSamples { found: 0, .. }));
    let one: String = VALID_CSV.lines().take(2).map(|l| format!("{l}\n")).collect();
    refused(VALID_TOML, one, "csv", &["1 sample row(s)", "expected at least 2"]);
}

#[test]
fn k20_blank_line_inside_the_samples() {
    let e = refused(
        VALID_TOML,
        csv_with("\n0.002", "\n\n0.002"),
        "csv",
        &["line 4 is blank", "expected a sample row with 6 comma-separated values"],
    );
    assert!(matches!(e, ReadError::BlankLine { line: 4, .. }));
    // Blank lines at the end are fine.
    let dir = tempfile::tempdir().unwrap();
    let ok = write_pair(dir.path(), "tail", VALID_TOML, format!("{VALID_CSV}\n\n"));
    assert_eq!(parse_recording(&ok, rope_total()).unwrap().columns[0].values.len(), 4);
}

#[test]
fn k21_malformed_quoting() {
    let e = refused(
        VALID_TOML,
        csv_with("0.001,-0.2", "0.001,\"-0.2"),
        "csv",
        &["line 3, field 2", "not closed before the end of the line", "expected a quoted field"],
    );
    assert!(matches!(e, ReadError::BadQuoting { line: 3, field: 2, .. }));
    refused(
        VALID_TOML,
        csv_with("time_s", "\"time_s\"x"),
        "csv",
        &["line 1, field 1", "text follows the closing quote"],
    );
}

// ---------------------------------------------------------------------------
// Inputs are never modified.

fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>, SystemTime)> {
    let mut files: Vec<_> = fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let path = e.unwrap().path();
            let meta = fs::metadata(&path).unwrap();
            let bytes = if meta.is_file() { fs::read(&path).unwrap() } else { Vec::new() };
            (path, bytes, meta.modified().unwrap())
        })
        .collect();
    files.sort();
    files
}

#[test]
fn reading_does_not_modify_the_dataset() {
    let dir = tempfile::tempdir().unwrap();
    write_recording(dir.path(), "travel", &travel_recording(100)).unwrap();
    write_recording(dir.path(), "decay", &decay_recording(100)).unwrap();
    write_pair(dir.path(), "windows", VALID_TOML.replace('\n', "\r\n"), VALID_CSV.replace('\n', "\r\n"));
    let bad = dir.path().join("bad");
    fs::create_dir(&bad).unwrap();
    write_pair(&bad, "nan", VALID_TOML, csv_with("1e-3", "NaN"));
    fs::write(bad.join("rec.evimp.txt"), "EVIMP1\n256\n1 2 3 4\n").unwrap();
    // Let a modification, if any, show in the time stamps.
    std::thread::sleep(std::time::Duration::from_millis(20));
    let before = (snapshot(dir.path()), snapshot(&bad));

    parse_dataset(dir.path(), rope_total()).unwrap();
    parse_recording(&dir.path().join("travel.toml"), rope_total()).unwrap();
    parse_dataset(&bad, rope_total()).unwrap_err();
    read_evimp(&bad.join("rec.evimp.txt")).unwrap_err();

    let after = (snapshot(dir.path()), snapshot(&bad));
    assert_eq!(before, after, "a file was modified, created or removed");
}

// ---------------------------------------------------------------------------
// EVIMP1

fn evimp_file(dir: &Path, text: impl AsRef<[u8]>) -> PathBuf {
    let path = dir.join("ride.txt");
    fs::write(&path, text).unwrap();
    path
}

#[test]
fn evimp_with_and_without_sound() {
    let dir = tempfile::tempdir().unwrap();
    let rec = read_evimp(&evimp_file(
        dir.path(),
        "EVIMP1\n256\n-3.351 3.545 -1.787 58.073\n-2.074 2.49 -1.255 59.165\n0 0.5\t1e1  64\n",
    ))
    .unwrap();
    assert_eq!(rec.sample_rate_hz, 256.0);
    assert_eq!(rec.x_mg, [-3.351, -2.074, 0.0]);
    assert_eq!(rec.y_mg, [3.545, 2.49, 0.5]);
    assert_eq!(rec.z_mg, [-1.787, -1.255, 10.0]);
    assert_eq!(rec.sound_dba, Some(vec![58.073, 59.165, 64.0]));
    assert_eq!(rec.len(), 3);
    assert!((rec.z_mps2()[2] - 0.0980665).abs() < 1e-15);

    let rec = read_evimp(&evimp_file(dir.path(), "\u{feff}EVIMP1\r\n100.0\r\n1 2 3\r\n4 5 6\r\n\r\n")).unwrap();
    assert_eq!(rec.sample_rate_hz, 100.0);
    assert_eq!(rec.z_mg, [3.0, 6.0]);
    assert_eq!(rec.sound_dba, None);
}

fn evimp_refused(text: impl AsRef<[u8]>, needles: &[&str]) -> ReadError {
    let dir = tempfile::tempdir().unwrap();
    let err = read_evimp(&evimp_file(dir.path(), text)).expect_err("malformed EVIMP accepted");
    let msg = err.to_string();
    assert!(msg.contains("ride.txt`") && msg.contains("expected"), "{msg}");
    for needle in needles {
        assert!(msg.contains(needle), "message {msg:?} does not contain {needle:?}");
    }
    err
}

#[test]
fn evimp_errors_name_line_and_column() {
    evimp_refused("", &["line 1", "<end of file>", "expected `EVIMP1`"]);
    evimp_refused("EVIMP2\n256\n1 2 3\n1 2 3\n", &["line 1", "`EVIMP2`", "expected `EVIMP1`"]);
    evimp_refused("EVIMP1\n", &["line 2", "<end of file>", "Hz > 0"]);
    evimp_refused("EVIMP1\n0\n1 2 3\n1 2 3\n", &["line 2", "sample rate `0`", "Hz > 0"]);
    evimp_refused("EVIMP1\n256 Hz\n1 2 3\n1 2 3\n", &["line 2", "`256 Hz`"]);
    evimp_refused("EVIMP1\n256\n1 2\n", &["line 3 has 2 fields", "expected 3 (x y z in mg) or 4"]);
    evimp_refused("EVIMP1\n256\n1 2 3 4 5\n", &["line 3 has 5 fields"]);
    let e = evimp_refused(
        "EVIMP1\n256\n1 2 3 4\n1 2 3\n",
        &["line 4 has 3 fields", "expected 4, as in the first sample row (line 3)"],
    );
    assert!(matches!(e, ReadError::FieldCount { line: 4, found: 3, .. }));
    evimp_refused("EVIMP1\n256\n1 2 3 4\n1 2,5 3 4\n", &["line 4, column `y_mg`", "`2,5` is not a number"]);
    evimp_refused("EVIMP1\n256\n1 2 3 4\n1 2 3 nan\n", &["line 4, column `sound_dba`", "`nan` is not finite"]);
    evimp_refused("EVIMP1\n256\n1 2 3\n\n1 2 3\n", &["line 4 is blank", "expected a sample row with 3 values"]);
    evimp_refused("EVIMP1\n256\n1 2 3\n", &["1 sample row(s)", "expected at least 2"]);
    evimp_refused(b"EVIMP1\n256\n1 2 \xff3\n".as_slice(), &["line 3, byte 5", "not valid UTF-8"]);
    let dir = tempfile::tempdir().unwrap();
    let msg = read_evimp(&dir.path().join("absent.txt")).unwrap_err().to_string();
    assert!(msg.contains("absent.txt") && msg.contains("cannot read"), "{msg}");
}

// ---------------------------------------------------------------------------
// No panic on arbitrary or mutated input.

/// One edit of a byte string; positions are taken modulo the length.
#[derive(Debug, Clone)]
enum Edit {
    Flip(usize, u8),
    Truncate(usize),
    Insert(usize, u8),
    InsertComma(usize),
    Delete(usize, usize),
}

fn edit_strategy() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (any::<usize>(), 1..=255u8).prop_map(|(p, m)| Edit::Flip(p, m)),
        any::<usize>().prop_map(Edit::Truncate),
        (any::<usize>(), any::<u8>()).prop_map(|(p, b)| Edit::Insert(p, b)),
        any::<usize>().prop_map(Edit::InsertComma),
        (any::<usize>(), 1..20usize).prop_map(|(p, n)| Edit::Delete(p, n)),
    ]
}

fn apply(mut bytes: Vec<u8>, edits: &[Edit]) -> Vec<u8> {
    for edit in edits {
        let len = bytes.len();
        match *edit {
            Edit::Flip(p, m) if len > 0 => bytes[p % len] ^= m,
            Edit::Truncate(p) => bytes.truncate(p % (len + 1)),
            Edit::Insert(p, b) => bytes.insert(p % (len + 1), b),
            Edit::InsertComma(p) => bytes.insert(p % (len + 1), b','),
            Edit::Delete(p, n) if len > 0 => {
                let start = p % len;
                bytes.drain(start..(start + n).min(len));
            }
            _ => {}
        }
    }
    bytes
}

/// A written recording's text, to mutate.
fn written_pair() -> (Vec<u8>, Vec<u8>) {
    static PAIR: OnceLock<(Vec<u8>, Vec<u8>)> = OnceLock::new();
    PAIR.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let (toml, csv) = write_recording(dir.path(), "w", &travel_recording(6)).unwrap();
        (fs::read(toml).unwrap(), fs::read(csv).unwrap())
    })
    .clone()
}

/// Reads the pair; the result must be Ok or Err, and an Ok result must be
/// consistent.
fn read_never_panics(dir: &Path, toml: &[u8], csv: &[u8]) {
    let path = write_pair(dir, "fuzz", toml, csv);
    if let Ok(rec) = read_recording(&path, rope_total()) {
        let rows = rec.column(TIME_S).expect("time_s").values.len();
        assert!(rows >= 2);
        assert!(rec.columns.iter().all(|c| c.values.len() == rows && c.values.iter().all(|v| v.is_finite())));
    }
}

const FUZZ_CASES: u32 = 5000;

thread_local! {
    /// One scratch directory per test thread, reused by every case; in
    /// memory where possible (rewriting files on a disk file system costs
    /// milliseconds each).
    static FUZZ_DIR: std::rc::Rc<tempfile::TempDir> = std::rc::Rc::new({
        let shm = Path::new("/dev/shm");
        let in_memory = if shm.is_dir() { tempfile::tempdir_in(shm).ok() } else { None };
        in_memory.unwrap_or_else(|| tempfile::tempdir().unwrap())
    });
}

fn fuzz_dir() -> std::rc::Rc<tempfile::TempDir> {
    FUZZ_DIR.with(|d| d.clone())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: FUZZ_CASES, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_bytes_never_panic(csv in prop::collection::vec(any::<u8>(), 0..400), toml in prop::collection::vec(any::<u8>(), 0..300)) {
        let dir = fuzz_dir();
        read_never_panics(dir.path(), VALID_TOML.as_bytes(), &csv);
        read_never_panics(dir.path(), &toml, VALID_CSV.as_bytes());
        read_never_panics(dir.path(), &toml, &csv);
        let _ = read_evimp(&evimp_file(dir.path(), &csv));
    }

    #[test]
    fn mutated_valid_files_never_panic(
        csv_edits in prop::collection::vec(edit_strategy(), 0..6),
        toml_edits in prop::collection::vec(edit_strategy(), 0..6),
        which in 0..3u8,
    ) {
        let dir = fuzz_dir();
        let (toml, csv) = if which == 0 { written_pair() } else { (VALID_TOML.into(), VALID_CSV.into()) };
        let (toml_m, csv_m) = (apply(toml.clone(), &toml_edits), apply(csv.clone(), &csv_edits));
        match which {
            2 => read_never_panics(dir.path(), &toml_m, &csv_m),
            _ => {
                read_never_panics(dir.path(), &toml, &csv_m);
                read_never_panics(dir.path(), &toml_m, &csv);
            }
        }
        let evimp = apply(b"EVIMP1\n256\n-3.351 3.545 -1.787 58.073\n-2.074 2.49 -1.255 59.165\n".to_vec(), &csv_edits);
        let _ = read_evimp(&evimp_file(dir.path(), evimp));
    }
}

// ---------------------------------------------------------------------------
// Read time of a full-size recording (printed, not asserted).

/// 20 s at 16384 Hz with 14 columns, as the rig records. Run with
/// `cargo test --release -p host-sim --test integration commands::recording_read:: -- --ignored --nocapture`.
#[test]
#[ignore = "timing; run on demand"]
fn read_time_of_a_20_s_recording_at_16384_hz() {
    let rows = 20 * 16384;
    let mut rec = travel_recording(rows);
    for k in 0..2 {
        rec.columns.push(Column::new(format!("aux_{k}"), (0..rows).map(|i| tricky(i, 20 + k)).collect()));
    }
    assert_eq!(rec.columns.len(), 14);
    let dir = tempfile::tempdir().unwrap();
    let (toml_path, csv_path) = write_recording(dir.path(), "big", &rec).unwrap();
    let size = fs::metadata(&csv_path).unwrap().len();
    let mut best = f64::INFINITY;
    for _ in 0..5 {
        let start = Instant::now();
        let back = parse_recording(&toml_path, rope_total()).unwrap();
        best = best.min(start.elapsed().as_secs_f64());
        assert_eq!(back.columns[0].values.len(), rows);
    }
    println!("read {rows} rows x 14 columns ({:.1} MB): best of 5 {:.3} s", size as f64 / 1e6, best);
}
