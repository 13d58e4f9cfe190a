//! Fuzz targets (proptest, a fixed number of cases so that CI runs them in
//! about a second) for the parsers of text a user hands the commands: the
//! rig config (`--config`), a recording's metadata (the `<stem>.toml`
//! sidecar) and the `EVIMP1` export. Each must return an error or a value
//! that satisfies every documented bound; none may panic.
//! `tests/commands/recording_read.rs` fuzzes the samples reader. Recordings
//! that contradict themselves or their metadata are generated here by class
//! (wrapped or glitched angle, dead accelerometer, direction or distance
//! against the samples, a spike in a current or the speed) and must be refused naming the column or field;
//! so are absurd but positive rig values (accepted only where a run
//! finishes), free decays `identify` cannot use (each with its own cause)
//! and inputs that are not regular files.

use std::fs;
use std::path::{Path, PathBuf};

use proptest::prelude::*;
use proptest::test_runner::RngSeed;
use recording::evimp::EVIMP_BOUNDS;
use recording::{
    read_evimp, read_meta, RecordingKind, MAX_MASS_KG, MAX_ROPE_LENGTH_M, MAX_SAMPLE_RATE_HZ, META_FIELDS,
};
use rig_config::RigConfig;

/// Seed of every target: each CI run tries the same cases (a failure
/// reproduces; `PROPTEST_CASES` and another seed explore further by hand).
const SEED: u64 = 0x5eed_1e1f_b0a7;

/// Cases per target: enough to cover the strategies' shapes, small enough
/// for every CI run.
const CASES: u32 = 256;

/// Total rope length of the reference rig, m.
const ROPE_TOTAL_M: f64 = 8.6;

thread_local! {
    static DIR: tempfile::TempDir = tempfile::tempdir().unwrap();
}

/// Writes `bytes` to `name` in this thread's scratch directory.
fn scratch(name: &str, bytes: &[u8]) -> PathBuf {
    DIR.with(|d| {
        let path = d.path().join(name);
        fs::write(&path, bytes).unwrap();
        path
    })
}

/// One edit of a byte string; positions are taken modulo the length.
#[derive(Debug, Clone)]
enum Edit {
    Flip(usize, u8),
    Truncate(usize),
    Insert(usize, u8),
    Delete(usize, usize),
    /// Inserts one of a few texts that matter to TOML and numbers.
    Splice(usize, usize),
}

const SPLICES: [&str; 12] = ["\n", "=", "[", "]", "\"", "-", "1e308", "nan", "inf", "[]", "x = 1\n", "\n[mechanics]\n"];

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (any::<usize>(), 1..=255u8).prop_map(|(p, m)| Edit::Flip(p, m)),
        any::<usize>().prop_map(Edit::Truncate),
        (any::<usize>(), any::<u8>()).prop_map(|(p, b)| Edit::Insert(p, b)),
        (any::<usize>(), 1..40usize).prop_map(|(p, n)| Edit::Delete(p, n)),
        (any::<usize>(), 0..SPLICES.len()).prop_map(|(p, k)| Edit::Splice(p, k)),
    ]
}

fn apply(mut bytes: Vec<u8>, edits: &[Edit]) -> Vec<u8> {
    for e in edits {
        let len = bytes.len();
        match *e {
            Edit::Flip(p, m) if len > 0 => bytes[p % len] ^= m,
            Edit::Truncate(p) => bytes.truncate(p % (len + 1)),
            Edit::Insert(p, b) => bytes.insert(p % (len + 1), b),
            Edit::Delete(p, n) if len > 0 => {
                let start = p % len;
                bytes.drain(start..(start + n).min(len));
            }
            Edit::Splice(p, k) => {
                let at = p % (len + 1);
                bytes.splice(at..at, SPLICES[k].bytes());
            }
            _ => {}
        }
    }
    bytes
}

/// Number text a user (or a broken export) might write.
fn number_text() -> impl Strategy<Value = String> {
    prop_oneof![
        any::<f64>().prop_map(|v| format!("{v:?}")),
        (-1.0e3..1.0e3f64).prop_map(|v| format!("{v}")),
        any::<i64>().prop_map(|v| v.to_string()),
        prop::sample::select(vec!["0", "-0.0", "1e300", "-1e300", "nan", "inf", "-inf", "1e-320", "\"70.5\"", "[]"])
            .prop_map(String::from),
    ]
}

/// An `Ok` rig config satisfies what validation promises.
fn check_rig(text: &str) {
    match RigConfig::from_toml_str(text, "fuzz.toml") {
        Ok(rig) => {
            rig.validate("again").expect("a config accepted once validates again");
            let m = &rig.mechanics;
            assert!(!m.m_car_kg.is_empty());
            assert!(m.m_car_kg.iter().all(|v| v.is_finite() && *v > 0.0 && *v <= 1.0e5));
            assert!(rig.travel.lw_low_m < rig.travel.lw_high_m && rig.travel.lw_high_m < m.rope_total_length_m);
            let _ = rig.drive_config();
            let _ = rig.observer_model();
            // What the whole-rig bounds promise: a run finishes.
            let (rate, field, _) = rig.fastest_mechanical_rate();
            assert!(rate <= rig_config::MAX_MECHANICAL_RATE_RADPS, "{field}: {rate} rad/s");
            assert!(rig.reference_travel_s() <= rig_config::MAX_TRAVEL_S, "{}", rig.reference_travel_s());
            assert!(m.m_car_kg.iter().chain([&m.m_cw_kg]).all(|v| (1.0..=1.0e5).contains(v)), "{m:?}");
            let side = rig.travel.lw_low_m.min(m.rope_total_length_m - rig.travel.lw_high_m);
            assert!(side >= rig_config::MIN_ROPE_SIDE_M, "{side}");
        }
        Err(e) => {
            let e = e.to_string();
            assert!(e.starts_with("fuzz.toml"), "{e}");
            assert!(!e.contains("0000000000"), "a number written digit by digit: {e}");
        }
    }
}

/// An `Ok` metadata file satisfies the reader's bounds.
fn check_meta(path: &Path) {
    let Ok(meta) = read_meta(path, ROPE_TOTAL_M) else { return };
    assert!(meta.sample_rate_hz > 0.0 && meta.sample_rate_hz <= MAX_SAMPLE_RATE_HZ, "{meta:?}");
    match meta.kind {
        RecordingKind::Travel { m_car_kg, m_cw_kg, direction, lw_start_m, lw_end_m } => {
            for mass in [m_car_kg, m_cw_kg] {
                assert!(mass > 0.0 && mass <= MAX_MASS_KG, "{meta:?}");
            }
            for lw in [lw_start_m, lw_end_m] {
                assert!(lw > 0.0 && lw < ROPE_TOTAL_M, "{meta:?}");
            }
            let up = direction == recording::CarDirection::Up;
            assert_eq!(up, lw_end_m > lw_start_m, "{meta:?}");
            assert_ne!(lw_end_m, lw_start_m);
        }
        RecordingKind::FreeDecay { mass_kg, rope_length_m } => {
            assert!(mass_kg > 0.0 && mass_kg <= MAX_MASS_KG, "{meta:?}");
            assert!(rope_length_m > 0.0 && rope_length_m <= MAX_ROPE_LENGTH_M, "{meta:?}");
        }
    }
}

/// An `Ok` EVIMP export satisfies the reader's bounds.
fn check_evimp(path: &Path) {
    let Ok(e) = read_evimp(path) else { return };
    assert!(e.sample_rate_hz > 0.0 && e.sample_rate_hz <= MAX_SAMPLE_RATE_HZ);
    let n = e.len();
    assert!(n >= 2 && e.x_mg.len() == n && e.y_mg.len() == n);
    let mut channels = vec![&e.x_mg, &e.y_mg, &e.z_mg];
    if let Some(sound) = &e.sound_dba {
        assert_eq!(sound.len(), n);
        channels.push(sound);
    }
    for (values, (bound, _)) in channels.into_iter().zip(EVIMP_BOUNDS) {
        assert!(values.iter().all(|v| v.is_finite() && v.abs() <= bound));
    }
}

const META_TRAVEL: &str = "format = \"elevator-measurement/1\"
kind = \"travel\"
sample_rate_hz = 4096.0
description = \"fuzz\"
m_car_kg = 70.5
m_cw_kg = 33.0
direction = \"up\"
lw_start_m = 1.0
lw_end_m = 7.6
";

/// A metadata file of random fields: each known field absent or with a
/// random value, kinds and directions drawn from valid and invalid text,
/// and unknown fields.
fn meta_text() -> impl Strategy<Value = String> {
    let value = prop_oneof![
        number_text(),
        prop::sample::select(vec![
            "\"elevator-measurement/1\"",
            "\"travel\"",
            "\"free_decay\"",
            "\"up\"",
            "\"down\"",
            "true",
            "{ a = 1 }",
        ])
        .prop_map(String::from),
    ];
    (
        prop::collection::vec(prop::option::of(value), META_FIELDS.len()),
        prop::collection::vec(("[a-z_]{1,12}", number_text()), 0..3),
    )
        .prop_map(|(values, extra)| {
            let mut text = String::new();
            for (name, value) in META_FIELDS.iter().zip(values) {
                if let Some(v) = value {
                    text.push_str(&format!("{name} = {v}\n"));
                }
            }
            for (name, v) in extra {
                if !META_FIELDS.contains(&name.as_str()) {
                    text.push_str(&format!("{name} = {v}\n"));
                }
            }
            text
        })
}

/// An EVIMP export of random rows: the tag and the rate right or wrong,
/// 0-6 rows of 2-5 values (numbers beyond the bounds among them), spaces or
/// tabs between them.
fn evimp_text() -> impl Strategy<Value = String> {
    let tag = prop::sample::select(vec!["EVIMP1", "EVIMP1 ", "EVIMP2", ""]);
    let rate = prop_oneof![number_text(), Just("256".to_string())];
    let row = prop::collection::vec(number_text(), 2..=5);
    let sep = prop::sample::select(vec![" ", "\t", "  ", " \t "]);
    (tag, rate, prop::collection::vec(row, 0..6), sep, any::<bool>()).prop_map(|(tag, rate, rows, sep, crlf)| {
        let end = if crlf { "\r\n" } else { "\n" };
        let mut text = format!("{tag}{end}{rate}{end}");
        for row in rows {
            text.push_str(&row.join(sep));
            text.push_str(end);
        }
        text
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: CASES, failure_persistence: None, rng_seed: RngSeed::Fixed(SEED), ..ProptestConfig::default() })]

    #[test]
    fn rig_config_mutated_parses_or_is_refused(edits in prop::collection::vec(edit(), 0..6)) {
        let bytes = apply(rig_config::EMBEDDED_RIG_TOML.as_bytes().to_vec(), &edits);
        check_rig(&String::from_utf8_lossy(&bytes));
    }

    #[test]
    fn rig_config_with_random_values_is_valid_or_refused(line in any::<prop::sample::Index>(), value in number_text()) {
        // Replace the value of one `key = value` line of the embedded rig.
        let text = rig_config::EMBEDDED_RIG_TOML;
        let lines: Vec<&str> = text.lines().collect();
        let assignments: Vec<usize> = (0..lines.len()).filter(|&i| lines[i].contains(" = ")).collect();
        let i = assignments[line.index(assignments.len())];
        let key = lines[i].split(" = ").next().unwrap();
        let mut edited: Vec<String> = lines.iter().map(|l| l.to_string()).collect();
        edited[i] = format!("{key} = {value}");
        check_rig(&edited.join("\n"));
    }

    #[test]
    fn rig_config_with_an_unknown_field_is_refused_naming_it(table in any::<prop::sample::Index>(), name in "zz_[a-z_]{0,10}") {
        let text = rig_config::EMBEDDED_RIG_TOML;
        let headers: Vec<&str> = text.lines().filter(|l| l.starts_with('[')).collect();
        let header = headers[table.index(headers.len())];
        let edited = text.replacen(&format!("{header}\n"), &format!("{header}\n{name} = 1\n"), 1);
        let err = RigConfig::from_toml_str(&edited, "fuzz.toml").unwrap_err().to_string();
        prop_assert!(err.contains(&name) && err.contains("unknown field"), "{}", err);
    }

    #[test]
    fn sidecar_of_random_fields_is_valid_or_refused(text in meta_text()) {
        check_meta(&scratch("meta.toml", text.as_bytes()));
    }

    #[test]
    fn sidecar_mutated_is_valid_or_refused(edits in prop::collection::vec(edit(), 0..6)) {
        check_meta(&scratch("mutated.toml", &apply(META_TRAVEL.as_bytes().to_vec(), &edits)));
    }

    #[test]
    fn evimp_of_random_rows_is_valid_or_refused(text in evimp_text(), edits in prop::collection::vec(edit(), 0..3)) {
        check_evimp(&scratch("ride.txt", text.as_bytes()));
        check_evimp(&scratch("ride_mutated.txt", &apply(text.into_bytes(), &edits)));
    }
}

// ---------------------------------------------------------------------------
// Recordings that contradict themselves or their metadata: each class of
// defect generated on a consistent travel, written to disk and read back.

/// Sheave radius of the reference rig, m.
const SHEAVE_RADIUS_M: f64 = 0.065;

/// A consistent travel: `fs` Hz, the shaft up to `peak` rad/s and back over
/// `seconds` (a sine-shaped speed), `up` or down, the angle its exact
/// integral from `angle0`, a live accelerometer, metadata whose rope-length
/// change is the distance turned.
fn consistent_travel(fs: f64, peak: f64, seconds: f64, up: bool, angle0: f64) -> recording::Recording {
    use recording::{CarDirection, Column, Recording, RecordingMeta, ACC_CAR, ANGLE, I_A, I_B, I_C, SPEED, TIME_S};
    let n = (fs * seconds) as usize;
    let sign = if up { 1.0 } else { -1.0 };
    let speed: Vec<f64> = (0..n).map(|k| sign * peak * (std::f64::consts::PI * k as f64 / n as f64).sin()).collect();
    let angle: Vec<f64> = speed.iter().scan(angle0, |a, w| Some(std::mem::replace(a, *a + w / fs))).collect();
    let distance = (angle[n - 1] - angle[0]).abs() * SHEAVE_RADIUS_M;
    let (lw_start_m, lw_end_m) = if up { (1.0, 1.0 + distance) } else { (1.0 + distance, 1.0) };
    let zeros = vec![0.0; n];
    Recording {
        meta: RecordingMeta {
            kind: RecordingKind::Travel {
                m_car_kg: 45.5,
                m_cw_kg: 33.0,
                direction: if up { CarDirection::Up } else { CarDirection::Down },
                lw_start_m,
                lw_end_m,
            },
            sample_rate_hz: fs,
            description: None,
        },
        columns: vec![
            Column::new(TIME_S, (0..n).map(|k| k as f64 / fs).collect()),
            Column::new(ACC_CAR, (0..n).map(|k| 0.02 * (0.37 * k as f64).sin()).collect()),
            Column::new(I_A, zeros.clone()),
            Column::new(I_B, zeros.clone()),
            Column::new(I_C, zeros),
            Column::new(SPEED, speed),
            Column::new(ANGLE, angle),
        ],
    }
}

/// A defect of one class, with where it is applied.
#[derive(Debug, Clone)]
enum Defect {
    None,
    WrappedAngle,
    AngleGlitch {
        at: prop::sample::Index,
        rad: f64,
    },
    DeadAccelerometer {
        value: f64,
    },
    DirectionFlipped,
    DistanceScaled {
        factor: f64,
    },
    /// A one-sample spike of `times` the step [`LIMITS`] allows, in a
    /// current or the speed.
    Spike {
        at: prop::sample::Index,
        times: f64,
        speed: bool,
    },
}

/// The slew limits of the generated travels.
const LIMITS: recording::consistency::SlewLimits = recording::consistency::SlewLimits {
    current_a_per_s: 1.0e4,
    current_slack_a: 0.5,
    shaft_rad_per_s2: 1.0e3,
    speed_slack_radps: 0.5,
};

fn defect() -> impl Strategy<Value = Defect> {
    prop_oneof![
        Just(Defect::None),
        Just(Defect::WrappedAngle),
        (any::<prop::sample::Index>(), 0.2..3.0f64, any::<bool>())
            .prop_map(|(at, rad, neg)| Defect::AngleGlitch { at, rad: if neg { -rad } else { rad } }),
        (-1.0..1.0f64).prop_map(|value| Defect::DeadAccelerometer { value }),
        Just(Defect::DirectionFlipped),
        prop_oneof![1.5..50.0f64, 0.05..0.6f64].prop_map(|factor| Defect::DistanceScaled { factor }),
        (any::<prop::sample::Index>(), prop_oneof![-10.0..-1.5f64, 1.5..10.0f64], any::<bool>())
            .prop_map(|(at, times, speed)| Defect::Spike { at, times, speed }),
    ]
}

fn apply_defect(r: &mut recording::Recording, defect: &Defect) {
    use recording::{CarDirection, ACC_CAR, ANGLE};
    let take = |r: &mut recording::Recording, name: &str, f: &dyn Fn(&mut Vec<f64>)| {
        let c = r.columns.iter_mut().find(|c| c.name == name).unwrap();
        f(&mut c.values);
    };
    match defect {
        Defect::None => {}
        Defect::WrappedAngle => {
            take(r, ANGLE, &|v| v.iter_mut().for_each(|a| *a = a.rem_euclid(std::f64::consts::TAU)))
        }
        Defect::AngleGlitch { at, rad } => take(r, ANGLE, &|v| {
            let i = 1 + at.index(v.len() - 2);
            v[i] += rad;
        }),
        Defect::DeadAccelerometer { value } => take(r, ACC_CAR, &|v| v.iter_mut().for_each(|a| *a = *value)),
        Defect::DirectionFlipped => {
            if let RecordingKind::Travel { direction, lw_start_m, lw_end_m, .. } = &mut r.meta.kind {
                *direction = if *direction == CarDirection::Up { CarDirection::Down } else { CarDirection::Up };
                std::mem::swap(lw_start_m, lw_end_m);
            }
        }
        Defect::Spike { at, times, speed } => {
            let fs = r.meta.sample_rate_hz;
            let (name, limit) = if *speed {
                (recording::SPEED, 2.0 * LIMITS.shaft_rad_per_s2 / fs + LIMITS.speed_slack_radps)
            } else {
                (recording::I_B, 2.0 * LIMITS.current_a_per_s / fs + LIMITS.current_slack_a)
            };
            take(r, name, &|v| {
                let i = 1 + at.index(v.len() - 2);
                v[i] += times * limit;
            });
        }
        Defect::DistanceScaled { factor } => {
            if let RecordingKind::Travel { lw_start_m, lw_end_m, .. } = &mut r.meta.kind {
                let (lo, hi) = (lw_start_m.min(*lw_end_m), lw_start_m.max(*lw_end_m));
                let scaled = lo + (hi - lo) * factor;
                if *lw_end_m > *lw_start_m {
                    *lw_end_m = scaled;
                } else {
                    *lw_start_m = scaled;
                }
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, failure_persistence: None, rng_seed: RngSeed::Fixed(SEED), ..ProptestConfig::default() })]

    #[test]
    fn a_recording_that_contradicts_itself_or_its_metadata_is_refused_naming_the_column(
        fs in 200.0..4096.0f64,
        // At least 9.5 rad turned: every travel crosses a whole revolution (a wrap).
        peak in 5.0..15.0f64,
        seconds in 3.0..8.0f64,
        up in any::<bool>(),
        angle0 in -100.0..100.0f64,
        defect in defect(),
    ) {
        let mut r = consistent_travel(fs.round(), peak, seconds, up, angle0);
        // Rope lengths inside the reference rig's 8.6 m.
        if let RecordingKind::Travel { lw_start_m, lw_end_m, .. } = r.meta.kind {
            prop_assume!(lw_start_m.max(lw_end_m) < 8.0);
        }
        apply_defect(&mut r, &defect);
        if let RecordingKind::Travel { lw_start_m, lw_end_m, .. } = r.meta.kind {
            prop_assume!(lw_start_m.max(lw_end_m) < ROPE_TOTAL_M && lw_start_m.min(lw_end_m) > 0.0);
        }
        let dir = tempfile::tempdir().unwrap();
        let (toml, _) = recording::write_recording(dir.path(), "travel", &r).unwrap();
        let read = recording::read_recording(&toml, ROPE_TOTAL_M)
            .and_then(|rec| recording::consistency::check_travel_distance(&rec, &toml, SHEAVE_RADIUS_M).map(|()| rec))
            .and_then(|rec| recording::consistency::check_slew(&rec, &toml.with_extension("csv"), &LIMITS).map(|()| rec));
        let needle = match &defect {
            Defect::None => {
                prop_assert!(read.is_ok(), "a consistent travel refused: {}", read.unwrap_err());
                return Ok(());
            }
            Defect::WrappedAngle | Defect::AngleGlitch { .. } => "column `angle_rad`",
            Defect::DeadAccelerometer { .. } => "column `acc_car_mps2`",
            Defect::DirectionFlipped => "column `direction`",
            Defect::DistanceScaled { .. } => "column `lw_start_m, lw_end_m`",
            Defect::Spike { speed: true, .. } => "column `speed_radps`",
            Defect::Spike { speed: false, .. } => "column `i_b_A`",
        };
        let err = read.expect_err("a contradiction was accepted").to_string();
        prop_assert!(err.contains(needle), "{defect:?}: {err}");
    }
}

// ---------------------------------------------------------------------------
// Absurd but positive rig values: accepted only where a run finishes,
// else refused naming a field with its range and why.

/// A positive value of any magnitude, 1e-12 to 1e12 (log-uniform).
fn magnitude() -> impl Strategy<Value = f64> {
    (-12.0..12.0f64).prop_map(|e| 10f64.powf(e))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: CASES, failure_persistence: None, rng_seed: RngSeed::Fixed(SEED), ..ProptestConfig::default() })]

    #[test]
    fn a_rig_value_of_any_magnitude_is_accepted_only_where_a_run_finishes(
        line in any::<prop::sample::Index>(),
        value in magnitude(),
        second in any::<prop::sample::Index>(),
        other in magnitude(),
    ) {
        // One or two numeric values of the embedded rig replaced.
        let text = rig_config::EMBEDDED_RIG_TOML;
        let mut lines: Vec<String> = text.lines().map(String::from).collect();
        let numeric: Vec<usize> = (0..lines.len())
            .filter(|&i| {
                let v = lines[i].split(" = ").nth(1).unwrap_or("").split('#').next().unwrap().trim();
                v.parse::<f64>().is_ok() && !lines[i].starts_with('#')
            })
            .collect();
        for (at, v) in [(line, value), (second, other)] {
            let i = numeric[at.index(numeric.len())];
            let key = lines[i].split(" = ").next().unwrap().to_string();
            let integer = lines[i].split(" = ").nth(1).unwrap().split('#').next().unwrap().trim().parse::<i64>().is_ok();
            lines[i] = if integer { format!("{key} = {}", v.round() as i64) } else { format!("{key} = {v:e}") };
        }
        let text = lines.join("\n");
        check_rig(&text);
        if let Err(e) = RigConfig::from_toml_str(&text, "fuzz.toml") {
            let e = e.to_string();
            prop_assert!(e.contains("field `") || e.contains("TOML parse error at line"), "{}", e);
        }
    }
}

// ---------------------------------------------------------------------------
// Free decays `identify` cannot use: each class refused with its cause.

#[derive(Debug, Clone)]
enum DecayDefect {
    None,
    Growing,
    Step,
    Short { n: usize },
    RateClaimed,
    BandBelow { factor: f64 },
}

fn decay_defect() -> impl Strategy<Value = DecayDefect> {
    prop_oneof![
        Just(DecayDefect::None),
        Just(DecayDefect::Growing),
        Just(DecayDefect::Step),
        (2..64usize).prop_map(|n| DecayDefect::Short { n }),
        Just(DecayDefect::RateClaimed),
        (0.4..0.8f64).prop_map(|factor| DecayDefect::BandBelow { factor }),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, failure_persistence: None, rng_seed: RngSeed::Fixed(SEED), ..ProptestConfig::default() })]

    #[test]
    fn a_free_decay_identify_cannot_use_is_refused_with_its_own_cause(
        f in 3.0..60.0f64,
        zeta in 0.005..0.05f64,
        fs in prop::sample::select(vec![1024.0, 4096.0, 16384.0]),
        seconds in 2.0..5.0f64,
        rest in 0.0..0.5f64,
        defect in decay_defect(),
    ) {
        use host_sim::cli::identify_screen::{decay_refusal, MaxFrequency, DEFAULT_MAX_FREQUENCY_HZ};
        let mut acc: Vec<f64> = (0..(seconds * fs) as usize)
            .map(|i| {
                let t = i as f64 / fs - rest;
                if t < 0.0 { 1e-4 * (i as f64 * 0.7).sin() } else {
                    (-zeta * std::f64::consts::TAU * f * t).exp() * (std::f64::consts::TAU * f * t).sin()
                }
            })
            .collect();
        let (mut rate, mut band) = (fs, MaxFrequency { hz: DEFAULT_MAX_FREQUENCY_HZ, given: false });
        let needle = match defect {
            DecayDefect::None => "",
            DecayDefect::Growing => { acc.reverse(); "does not decay" }
            DecayDefect::Step => {
                let n = acc.len();
                acc.iter_mut().enumerate().for_each(|(i, v)| *v = if i < n / 2 { 0.0 } else { 1.0 });
                "no oscillation"
            }
            DecayDefect::Short { n } => { acc.truncate(n); "samples" }
            DecayDefect::RateClaimed => { rate = 1000.0 * fs; "the decay lasts" }
            DecayDefect::BandBelow { factor } => {
                band = MaxFrequency { hz: (factor * f).max(1.1), given: true };
                "--max-frequency = "
            }
        };
        let csv = Path::new("data/decay.csv");
        let refusal = decay_refusal(csv, &acc, rate, band);
        if needle.is_empty() {
            prop_assert!(refusal.is_none(), "a sound decay refused: {:?}", refusal);
        } else if let (DecayDefect::BandBelow { .. }, None) = (&defect, &refusal) {
            // Passed on: the identification in the band must then refuse it
            // (a mode at the band's top), never give an EA of another line.
            let id = diagnosis::identify::identify_free_decay(&acc, rate, 33.0, 2.5, 0.095, 9.81, band.hz);
            prop_assert!(id.is_err(), "a band below the mode gave {:?}", id);
        } else {
            let e = refusal.expect("an unusable decay was accepted");
            prop_assert!(e.contains(needle) && e.contains("data/decay."), "{:?}: {}", defect, e);
            prop_assert!(!e.contains("max_frequency_hz") && !e.contains("0000000000"), "{}", e);
        }
    }
}

// ---------------------------------------------------------------------------
// Inputs that are not regular files: refused at open, naming the path.

#[derive(Debug, Clone, Copy)]
enum OddFile {
    Folder,
    NamedPipe,
    DanglingLink,
    LinkToFolder,
    Empty,
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, failure_persistence: None, rng_seed: RngSeed::Fixed(SEED), ..ProptestConfig::default() })]

    #[cfg(unix)]
    #[test]
    fn an_input_that_is_no_regular_file_is_refused_naming_it(
        odd in prop::sample::select(vec![OddFile::Folder, OddFile::NamedPipe, OddFile::DanglingLink, OddFile::LinkToFolder, OddFile::Empty]),
        samples in any::<bool>(),
        stem in "[a-z]{1,8}",
    ) {
        let dir = tempfile::tempdir().unwrap();
        let meta = "format = \"elevator-measurement/1\"\nkind = \"free_decay\"\nsample_rate_hz = 1000.0\nmass_kg = 33.0\nrope_length_m = 2.5\n";
        let (toml, csv) = (dir.path().join(format!("{stem}.toml")), dir.path().join(format!("{stem}.csv")));
        let (odd_path, other) = if samples { (&csv, &toml) } else { (&toml, &csv) };
        fs::write(other, if samples { meta.to_string() } else { "time_s,acc_car_mps2\n0,0.1\n0.001,0.2\n".to_string() }).unwrap();
        match odd {
            OddFile::Folder => fs::create_dir(odd_path).unwrap(),
            OddFile::NamedPipe => prop_assert!(std::process::Command::new("mkfifo").arg(odd_path).status().unwrap().success()),
            OddFile::DanglingLink => std::os::unix::fs::symlink(dir.path().join("missing"), odd_path).unwrap(),
            OddFile::LinkToFolder => std::os::unix::fs::symlink(dir.path(), odd_path).unwrap(),
            OddFile::Empty => fs::write(odd_path, "").unwrap(),
        }
        // In a thread: a reader that waited on the pipe would hang the test.
        let path = dir.path().to_path_buf();
        let (send, receive) = std::sync::mpsc::channel();
        std::thread::spawn(move || send.send(recording::read_dataset(&path, ROPE_TOTAL_M).map(|d| d.len())));
        let read = receive.recv_timeout(std::time::Duration::from_secs(10)).expect("the reader hung");
        let file = odd_path.file_name().unwrap().to_str().unwrap();
        let e = read.expect_err("an odd file was read").to_string();
        if !samples && matches!(odd, OddFile::Folder | OddFile::LinkToFolder) {
            // A folder named `<stem>.toml` is no recording (a dataset may hold
            // one, `plots.toml/`): the dataset holds none.
            prop_assert!(e.contains("holds no recording"), "{:?} {}: {}", odd, file, e);
        } else {
            prop_assert!(e.contains(file), "{:?} {}: {}", odd, file, e);
        }
        // The dataset given as a file.
        let e = recording::read_dataset(other, ROPE_TOTAL_M).expect_err("a file read as a dataset").to_string();
        prop_assert!(e.contains(other.file_name().unwrap().to_str().unwrap()), "{}", e);
    }
}
