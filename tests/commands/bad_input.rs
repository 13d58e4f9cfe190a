//! The commands under bad input and odd data: each case either
//! gives the right answer or stops with an error that names the recording,
//! the flag or the field and what would be accepted; nothing is overwritten
//! without `--force`, a failed run leaves no file, a closed standard output
//! ends quietly, and every input has a size bound.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use recording::{read_evimp, read_recording, ReadError, MAX_LINE_BYTES, MAX_META_BYTES};

pub(super) fn host_sim() -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_host-sim"));
    command.env("RUST_BACKTRACE", "0");
    command
}

/// Runs `host-sim args` and returns its output.
pub(super) fn run(args: &[&str]) -> Output {
    host_sim().args(args).output().unwrap()
}

/// Runs `host-sim args`, which must succeed.
pub(super) fn run_ok(args: &[&str]) -> Output {
    let out = run(args);
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    out
}

/// Runs `host-sim args`, which must fail without a panic; returns stderr.
pub(super) fn run_err(args: &[&str]) -> String {
    let out = run(args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "{args:?} succeeded: {}", String::from_utf8_lossy(&out.stdout));
    // 1: the command's error; 2: clap's (a value that does not parse).
    assert!(matches!(out.status.code(), Some(1 | 2)), "{args:?}: {err}");
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    err
}

pub(super) fn s(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// A short simulated travel of a 45.5 kg car from `lw_start_m` to
/// `lw_end_m`, written as `<dir>/<stem>.toml` + `.csv`.
fn simulate_travel(dir: &Path, stem: &str, direction: &str, lw_start_m: &str, lw_end_m: &str) {
    run_ok(&[
        "travel",
        "--quiet",
        "--m-car",
        "45.5",
        "--direction",
        direction,
        "--lw-start",
        lw_start_m,
        "--lw-end",
        lw_end_m,
        "--stem",
        stem,
        "--out",
        s(dir),
    ]);
}

fn entries(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = match fs::read_dir(dir) {
        Ok(read) => read.map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect(),
        Err(_) => Vec::new(),
    };
    names.sort();
    names
}

// ---------------------------------------------------------------------------
// Estimates the data cannot support are refused with the reason.

#[test]
fn identify_and_analyze_refuse_a_travel_without_a_constant_speed_stage() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    // 0.8 m: the ramps all but meet (0.2 s of cruise).
    simulate_travel(&data, "short", "down", "4.2", "3.4");
    // The same travel cut at 0.49 s, in its run-up, its metadata unchanged
    // (before: c_sheave = -82.7 N m s/rad, exit 0).
    let cut = tmp.path().join("cut");
    fs::create_dir(&cut).unwrap();
    let csv = fs::read_to_string(data.join("short.csv")).unwrap();
    let rows = (0.49f64 * 16384.0).round() as usize;
    let head: Vec<&str> = csv.lines().take(rows + 1).collect();
    fs::write(cut.join("short.csv"), head.join("\n") + "\n").unwrap();
    fs::copy(data.join("short.toml"), cut.join("short.toml")).unwrap();

    // The cut recording contradicts its metadata (0.8 m of rope, 1 mm turned):
    // refused with both sides named, by both commands.
    for command in ["identify", "analyze"] {
        let out = tmp.path().join("cut-out");
        let err = run_err(&[command, s(&cut), "--out", s(&out)]);
        assert!(err.contains("short.toml") && err.contains("0.800 m") && err.contains("m of rope"), "{command}: {err}");
        assert!(!out.exists(), "{command} left {:?}", entries(&out));
    }
    // The whole travel: no constant-speed stage of 1 s.
    {
        let dataset = &data;
        let out = tmp.path().join("id");
        let err = run_err(&["identify", s(dataset), "--out", s(&out)]);
        assert!(err.contains("no travel") && err.contains("short:") && err.contains("constant-speed stage"), "{err}");
        assert!(err.contains("expected at least 1 s"), "{err}");
        assert!(!out.exists(), "identify left {:?}", entries(&out));
        let out = tmp.path().join("an");
        let err = run_err(&["analyze", s(dataset), "--out", s(&out)]);
        assert!(err.contains("recording `short`") && err.contains("constant-speed stage"), "{err}");
        assert!(!out.exists(), "analyze left {:?}", entries(&out));
    }
}

#[test]
fn analyze_refuses_a_stage_shorter_than_the_welch_segment_and_leaves_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    // 1.4 m up: a constant-speed stage of about 1.8 s.
    simulate_travel(&data, "mid", "up", "2.0", "3.4");
    let out = tmp.path().join("an");
    // Before: the segment was silently cut to the stage, `1 x f_mech` reported at a wrong frequency.
    let err = run_err(&["analyze", s(&data), "--out", s(&out)]);
    assert!(err.contains("recording `mid`") && err.contains("--welch-segment 4 s"), "{err}");
    assert!(err.contains("give a --welch-segment of at most 1.8"), "{err}");
    assert!(!out.exists(), "analyze left {:?}", entries(&out));

    // A segment that fits: the lines it resolves, the others named as not resolved.
    let stdout = run_ok(&["analyze", s(&data), "--welch-segment", "1.5", "--out", s(&out)]).stdout;
    let stdout = String::from_utf8_lossy(&stdout);
    assert!(stdout.contains("not resolved with --welch-segment 1.5 s"), "{stdout}");
    let report: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(out.join("analyze.json")).unwrap()).unwrap();
    let travel = &report["travels"][0];
    let f_mech = travel["mechanical_frequency_hz"].as_f64().unwrap();
    assert!((f_mech - 0.4 / 0.065 / std::f64::consts::TAU).abs() < 0.01 * f_mech, "{f_mech}");
    assert!(travel["unresolved_orders"].as_array().unwrap().contains(&serde_json::json!(1)), "{travel}");
    let lines = travel["ripple_lines"].as_array().unwrap();
    assert!(lines.iter().all(|l| l["mechanical_order"] != 1), "{travel}");
    let line12 = lines.iter().find(|l| l["mechanical_order"] == 12).expect("the 12x line");
    let found = line12["frequency_hz"].as_f64().unwrap();
    assert!((found / (12.0 * f_mech) - 1.0).abs() < 0.01, "{line12}");

    // A second run into the same folder is refused, and --force replaces.
    let err = run_err(&["analyze", s(&data), "--welch-segment", "1.5", "--out", s(&out)]);
    assert!(err.contains("analyze.json") && err.contains("--force"), "{err}");
    run_ok(&["analyze", s(&data), "--welch-segment", "1.5", "--out", s(&out), "--force"]);

    // A window the recording cannot hold names the recording and the flag; nothing is left.
    let out = tmp.path().join("an2");
    let err = run_err(&["analyze", s(&data), "--welch-segment", "1", "--stft-window", "100", "--out", s(&out)]);
    assert!(err.contains("recording `mid`") && err.contains("--stft-window 100 s"), "{err}");
    assert!(!out.exists(), "analyze left {:?}", entries(&out));
    // Flags out of range are refused before any work, negative numbers as values.
    for (flag, value, range) in [
        ("--welch-segment", "-1", "(0, 600)"),
        ("--burg-window", "0", "(0, 600)"),
        ("--stft-window", "601", "(0, 600)"),
        ("--burg-order", "0", "[1, 1000]"),
    ] {
        let err = run_err(&["analyze", s(&data), flag, value, "--out", s(&out)]);
        assert!(err.contains(&format!("{flag} = {value}")) && err.contains(range), "{err}");
    }
    let err = run_err(&["analyze", s(&data), "--burg-order", "-1"]);
    assert!(err.contains("--burg-order"), "{err}");
    assert!(!out.exists());
}

#[test]
fn identify_refuses_a_search_band_below_the_mode_and_a_zero_band() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    run_ok(&["decay", "--mass", "33", "--length", "2.5", "--out", s(&data)]);
    let out = tmp.path().join("id");
    // Before: f1 = 5.25 Hz, EA = 3.07e5 N (or every decay skipped), exit 0.
    let err = run_err(&["identify", s(&data), "--max-frequency", "5", "--out", s(&out)]);
    assert!(err.contains("no free decay") && err.contains("decay_l2.5_m33"), "{err}");
    assert!(err.contains("--max-frequency = 5 Hz") && err.contains("Eqn 9: 17.50 Hz"), "{err}");
    assert!(!out.exists());
    let err = run_err(&["identify", s(&data), "--max-frequency", "0", "--out", s(&out)]);
    assert!(err.contains("--max-frequency = 0 is out of range") && err.contains("(1, 1000000)"), "{err}");
    let err = run_err(&["identify", s(&data), "--max-frequency", "-5", "--out", s(&out)]);
    assert!(err.contains("--max-frequency = -5 is out of range"), "{err}");
    run_ok(&["identify", s(&data), "--out", s(&out)]);
    let report: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(out.join("identify.json")).unwrap()).unwrap();
    let ea = report["free_decays"][0]["rope_ea_n"].as_f64().unwrap();
    assert!((ea / 1.0e6 - 1.0).abs() < 0.03, "EA {ea}");
}

// ---------------------------------------------------------------------------
// Configs: unknown fields, empty car lists, size.

#[test]
fn a_config_with_an_unknown_field_or_no_car_is_refused_naming_the_field() {
    let tmp = tempfile::tempdir().unwrap();
    let rig = rig_config::EMBEDDED_RIG_TOML;
    let cases = [
        // Before: ignored, the default used.
        (rig.replace("[control]\n", "[control]\nspeed_loop_bandwith_hz = 3.0\n"), "speed_loop_bandwith_hz"),
        (rig.replace("[mechanics]\n", "[mechanics]\nextra_field = 1\n"), "unknown field `extra_field`"),
        // Before: modes ran with 33 kg, the counterweight's mass.
        (
            rig.replace(rig.lines().find(|l| l.starts_with("m_car_kg")).unwrap(), "m_car_kg = []"),
            "[mechanics].m_car_kg` is an empty list",
        ),
    ];
    for (i, (text, needle)) in cases.iter().enumerate() {
        assert_ne!(text, rig);
        let path = tmp.path().join(format!("rig{i}.toml"));
        fs::write(&path, text).unwrap();
        let out = tmp.path().join("modes");
        let err = run_err(&["--config", s(&path), "modes", "--out", s(&out)]);
        assert!(err.contains(&format!("rig{i}.toml")) && err.contains(needle), "{err}");
        assert!(!out.exists());
    }
    // A config far larger than a real one is refused before it is read (sparse: no disk used).
    let path = tmp.path().join("huge.toml");
    fs::File::create(&path).unwrap().set_len(2 << 30).unwrap();
    let err = run_err(&["--config", s(&path), "modes"]);
    assert!(err.contains("huge.toml") && err.contains("larger than 1048576 bytes"), "{err}");
    // The repository's configs parse.
    for entry in fs::read_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            rig_config::RigConfig::load(&path).unwrap_or_else(|e| panic!("{e}"));
        }
    }
}

// ---------------------------------------------------------------------------
// The reader: physical bounds per channel, size bounds.

const VALID_TOML: &str = "format = \"elevator-measurement/1\"
kind = \"travel\"
sample_rate_hz = 1000.0
m_car_kg = 70.5
m_cw_kg = 33.0
direction = \"up\"
lw_start_m = 1.0
lw_end_m = 7.6
";

const VALID_CSV: &str = "time_s,acc_car_mps2,i_a_A,i_b_A,i_c_A,speed_radps,aux_unknown
0,0.1,1,2,-3,0.5,0
0.001,-0.2,1.5,2.5,-4,0.75,0
0.002,1e-3,-0.25,2,-1.75,1,0
";

fn write_pair(dir: &Path, stem: &str, toml: impl AsRef<[u8]>, csv: impl AsRef<[u8]>) -> PathBuf {
    let toml_path = dir.join(format!("{stem}.toml"));
    fs::write(&toml_path, toml).unwrap();
    fs::write(dir.join(format!("{stem}.csv")), csv).unwrap();
    toml_path
}

#[test]
fn samples_beyond_the_physical_bound_of_their_channel_are_refused_naming_file_line_column() {
    let tmp = tempfile::tempdir().unwrap();
    let cases = [
        // Before: 1e300 passed as data.
        ("0.1,1,2,-3,0.5", "1e300,1,2,-3,0.5", "acc_car_mps2", "`1e300`", "10000 m/s^2"),
        ("0.1,1,2,-3,0.5", "0.1,1,2e5,-3,0.5", "i_b_A", "`2e5`", "100000 A"),
        ("0.1,1,2,-3,0.5", "0.1,1,2,-3,-2e4", "speed_radps", "`-2e4`", "10000 rad/s"),
    ];
    for (from, to, column, text, bound) in cases {
        let path = write_pair(tmp.path(), "rec", VALID_TOML, VALID_CSV.replacen(from, to, 1));
        let err = read_recording(&path, 8.6).unwrap_err();
        assert!(matches!(err, ReadError::BeyondPhysicalBound { line: 2, .. }), "{err:?}");
        let msg = err.to_string();
        for needle in ["rec.csv", "line 2", column, text, bound, "expected a magnitude of at most"] {
            assert!(msg.contains(needle), "{msg} lacks {needle}");
        }
    }
    // A column the format does not define is only required to be finite.
    let path = write_pair(tmp.path(), "rec", VALID_TOML, VALID_CSV.replacen(",0\n", ",1e300\n", 1));
    assert_eq!(read_recording(&path, 8.6).unwrap().column("aux_unknown").unwrap().values[0], 1e300);
    // Metadata beyond any rig.
    let path = write_pair(tmp.path(), "rec", VALID_TOML.replace("m_car_kg = 70.5", "m_car_kg = 1e300"), VALID_CSV);
    let msg = read_recording(&path, 8.6).unwrap_err().to_string();
    assert!(msg.contains("`m_car_kg` = 1e300 is out of range") && msg.contains("at most 100000 kg"), "{msg}");
    // The CLI says the same.
    let err = run_err(&[
        "ride-quality",
        s(&write_pair(tmp.path(), "rec", VALID_TOML, VALID_CSV.replacen("0.1", "1e300", 1))),
    ]);
    assert!(err.contains("rec.csv` line 2, column `acc_car_mps2`"), "{err}");
    // EVIMP1: z in mg.
    let evimp = tmp.path().join("ride.txt");
    fs::write(&evimp, "EVIMP1\n256\n1 2 3\n1 2 3e9\n").unwrap();
    let msg = read_evimp(&evimp).unwrap_err().to_string();
    assert!(msg.contains("ride.txt` line 4, column `z_mg`") && msg.contains("1000000 mg"), "{msg}");
}

#[test]
fn inputs_beyond_their_size_bound_are_refused_naming_file_and_bound() {
    let tmp = tempfile::tempdir().unwrap();
    // A metadata file of 2 GiB (sparse): refused before reading.
    let path = write_pair(tmp.path(), "huge", "", VALID_CSV);
    fs::File::options().write(true).open(&path).unwrap().set_len(2 << 30).unwrap();
    let err = read_recording(&path, 8.6).unwrap_err();
    assert!(matches!(err, ReadError::TooLarge { limit: MAX_META_BYTES, .. }), "{err:?}");
    assert!(err.to_string().contains("huge.toml` is larger than 1048576 bytes"), "{err}");
    // A samples file whose second line never ends (4 GiB of zero bytes, sparse): refused after 1 MiB.
    let path = write_pair(tmp.path(), "long", VALID_TOML, "time_s,acc_car_mps2,i_a_A,i_b_A,i_c_A,speed_radps\n");
    let csv = tmp.path().join("long.csv");
    fs::File::options().write(true).open(&csv).unwrap().set_len(4 << 30).unwrap();
    let err = read_recording(&path, 8.6).unwrap_err();
    assert!(matches!(err, ReadError::LineTooLong { line: 2, limit: MAX_LINE_BYTES, .. }), "{err:?}");
    assert!(err.to_string().contains("long.csv` line 2 is longer than 1048576 bytes"), "{err}");
    // A line exactly at the bound is read (and refused for what it holds).
    let line = format!("{},", "1".repeat(MAX_LINE_BYTES - 1));
    let path = write_pair(tmp.path(), "edge", VALID_TOML, format!("{}\n{line}\n", VALID_CSV.lines().next().unwrap()));
    let err = read_recording(&path, 8.6).unwrap_err();
    assert!(matches!(err, ReadError::FieldCount { line: 2, .. }), "{err:?}");
    // EVIMP1 too.
    let evimp = tmp.path().join("ride.txt");
    fs::write(&evimp, "EVIMP1\n256\n").unwrap();
    fs::File::options().write(true).open(&evimp).unwrap().set_len(3 << 30).unwrap();
    let err = read_evimp(&evimp).unwrap_err();
    assert!(matches!(err, ReadError::LineTooLong { line: 3, .. }), "{err:?}");
    // An effects, faults or foreign-rig file as well.
    let big = tmp.path().join("big.toml");
    fs::File::create(&big).unwrap().set_len(2 << 30).unwrap();
    let err = run_err(&["travel", "--effects", s(&big), "--out", s(&tmp.path().join("t"))]);
    assert!(err.contains("big.toml") && err.contains("larger than 1048576 bytes"), "{err}");
    let err = run_err(&["faults", "--faults-file", s(&big), "--out", s(&tmp.path().join("f"))]);
    assert!(err.contains("big.toml") && err.contains("larger than 1048576 bytes"), "{err}");
    let err = run_err(&["dataset", "--foreign-file", s(&big), "--out", s(&tmp.path().join("d"))]);
    assert!(err.contains("big.toml") && err.contains("larger than 1048576 bytes"), "{err}");
}

#[test]
fn an_absurd_sweep_is_refused_before_any_allocation() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("modes");
    // Before: `memory allocation of 67200000008 bytes failed` (1e-9), 535 MB written (1e-5).
    for step in ["1e-9", "1e-5"] {
        let err = run_err(&["modes", "--lw-step", step, "--out", s(&out)]);
        assert!(err.contains("--lw-step") && err.contains("expected at most 100000 points"), "{err}");
        assert!(err.contains("a step of at least 8.400e-5"), "{err}");
        assert!(!out.exists());
    }
    let err = run_err(&["decay", "--elements", "100000000", "--out", s(&out)]);
    assert!(err.contains("--elements = 100000000 is out of range") && err.contains("[1, 400]"), "{err}");
    let err = run_err(&["bench", "--repeat", "1000000000"]);
    assert!(err.contains("--repeat = 1000000000 is out of range"), "{err}");
    let err = run_err(&["travel", "--max-step", "1e-300", "--out", s(&out)]);
    assert!(err.contains("--max-step"), "{err}");
    assert!(!out.exists());
}

// ---------------------------------------------------------------------------
// Files: no overwrite without --force, nothing half-written.

#[test]
fn commands_never_overwrite_an_existing_recording_without_force() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    run_ok(&["decay", "--mass", "33", "--length", "2.5", "--out", s(&data)]);
    let toml = data.join("decay_l2.5_m33.toml");
    let edited = fs::read_to_string(&toml).unwrap().replace("host-sim free decay", "my edited description");
    fs::write(&toml, &edited).unwrap();
    let before = entries(&data);
    // Before: replaced without a word.
    let err = run_err(&["decay", "--mass", "33,45.5", "--length", "2.5", "--out", s(&data)]);
    assert!(err.contains("decay_l2.5_m33.toml` exists") && err.contains("--force"), "{err}");
    assert_eq!(fs::read_to_string(&toml).unwrap(), edited);
    assert_eq!(entries(&data), before, "a refused run wrote files");
    run_ok(&["decay", "--mass", "33", "--length", "2.5", "--out", s(&data), "--force"]);
    assert!(fs::read_to_string(&toml).unwrap().contains("host-sim free decay"));
    assert_eq!(entries(&data), before);

    // travel and dataset refuse before they simulate.
    fs::write(data.join("up.toml"), "mine").unwrap();
    let err = run_err(&["travel", "--quiet", "--stem", "up", "--out", s(&data)]);
    assert!(err.contains("up.toml` exists") && err.contains("--force"), "{err}");
    fs::write(data.join("travel_down_m70.5.csv"), "mine").unwrap();
    let err = run_err(&["dataset", "--mass", "70.5", "--out", s(&data)]);
    assert!(err.contains("travel_down_m70.5.csv` exists") && err.contains("--force"), "{err}");
    assert_eq!(fs::read_to_string(data.join("up.toml")).unwrap(), "mine");
    // modes, a second time.
    let out = tmp.path().join("modes");
    run_ok(&["modes", "--out", s(&out)]);
    let err = run_err(&["modes", "--out", s(&out)]);
    assert!(err.contains("modes.csv` exists (and 3 more outputs of this run)"), "{err}");
    run_ok(&["modes", "--out", s(&out), "--force"]);
    assert_eq!(entries(&out), ["mode_shapes.csv", "modes.csv", "modes.png", "modes_0-128hz.png"]);
}

// ---------------------------------------------------------------------------
// Standard output closed by its reader.

#[test]
fn a_closed_standard_output_ends_the_command_quietly() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("modes");
    for args in [vec!["modes", "--out", s(&out)], vec!["--help"], vec!["modes", "--help"]] {
        // Before: `failed printing to stdout: Broken pipe`, exit 101.
        let mut child = host_sim().args(&args).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
        drop(child.stdout.take());
        let result = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&result.stderr);
        assert!(result.status.success(), "{args:?}: {:?} {err}", result.status);
        assert!(!err.contains("panicked") && !err.contains("Broken pipe"), "{args:?}: {err}");
    }
    // The command did its work.
    assert!(out.join("modes.csv").is_file());
}

// ---------------------------------------------------------------------------
// Clear errors.

#[test]
fn errors_name_the_file_to_give_and_print_an_os_error_once() {
    let tmp = tempfile::tempdir().unwrap();
    // Before: `No such file or directory (os error 2): No such file or directory (os error 2)`.
    for args in [
        vec!["--config", "/nonexistent/rig.toml", "modes"],
        vec!["identify", "/nonexistent/dataset"],
        vec!["ride-quality", "/nonexistent/x.toml"],
    ] {
        let err = run_err(&args);
        assert_eq!(err.matches("os error 2").count(), 1, "{args:?}: {err}");
        assert!(err.contains("/nonexistent/"), "{err}");
    }
    // The samples file given where the metadata file is expected: which file to give.
    let toml = write_pair(tmp.path(), "rec", VALID_TOML, VALID_CSV);
    let csv = toml.with_extension("csv");
    let err = run_err(&["ride-quality", s(&csv)]);
    assert!(err.contains(&format!("give its metadata file `{}`", toml.display())), "{err}");
    let msg = read_recording(&csv, 8.6).unwrap_err().to_string();
    assert!(msg.contains(&format!("give its metadata file `{}`", toml.display())), "{msg}");
    // An unknown file: both accepted formats named.
    let other = tmp.path().join("notes.txt");
    fs::write(&other, "hello\n").unwrap();
    let err = run_err(&["ride-quality", s(&other)]);
    assert!(err.contains("EVIMP1") && err.contains("measurement format") && err.contains("`<stem>.toml`"), "{err}");
    // A misspelt required field of a recording's metadata: the near miss named.
    let toml = write_pair(tmp.path(), "rec", VALID_TOML.replace("m_car_kg", "m_car_kgs"), VALID_CSV);
    let msg = read_recording(&toml, 8.6).unwrap_err().to_string();
    assert!(msg.contains("`m_car_kg` is missing") && msg.contains("the file has `m_car_kgs`"), "{msg}");
    // Negative values are values, range-checked like --m-car -3.
    for (args, needle) in [
        (vec!["modes", "--m-car", "-3"], "--m-car = -3 is out of range"),
        (vec!["analyze", "x", "--welch-segment", "-1"], "--welch-segment = -1 is out of range"),
        (vec!["travel", "--spectrogram-window", "-2"], "--spectrogram-window = -2 is out of range"),
        (vec!["dataset", "--acc-noise", "-0.1"], "--acc-noise = -0.1 is out of range"),
        (vec!["gap", "x", "--explained-shrink", "-0.5"], "--explained-shrink = -0.5 is out of range"),
    ] {
        let err = run_err(&args);
        assert!(err.contains(needle), "{args:?}: {err}");
    }
}

// ---------------------------------------------------------------------------
// Estimates refused by the analysis itself: a mode at the band edge, a
// negative damping, a torque sign that contradicts the travel.

fn decay_spec() -> plant::free_decay::FreeDecaySpec {
    plant::free_decay::FreeDecaySpec {
        mass_kg: 33.0,
        rope_length_m: 2.5,
        rope_ea_n: 1.0e6,
        rope_mass_per_length_kg_per_m: 0.095,
        damping_kg_per_s: 148.0,
        initial_acceleration_mps2: 2.0,
        elements: 40,
    }
}

#[test]
fn a_mode_at_the_top_of_the_search_band_and_a_growing_oscillation_are_refused() {
    use diagnosis::identify::identify_free_decay;
    use dsp::AnalysisError;
    use plant::free_decay::{eqn9_first_frequency_hz, simulate_free_decay};
    let (fs, spec) = (4096.0, decay_spec());
    let acc = simulate_free_decay(&spec, fs, 3.0).unwrap();
    let f1 = eqn9_first_frequency_hz(1.0e6, 0.095, 2.5, 33.0);
    let identify = |acc: &[f64], top: f64| identify_free_decay(acc, fs, 33.0, 2.5, 0.095, 9.81, top);
    // The band's top just above the mode: the line found lies at the edge.
    match identify(&acc, 1.01 * f1) {
        Err(AnalysisError::ModeAtBandEdge { frequency_hz, band_top_hz }) => {
            assert!(frequency_hz > 0.97 * band_top_hz, "{frequency_hz} {band_top_hz}")
        }
        other => panic!("band top {:.2} Hz: {other:?}", 1.01 * f1),
    }
    let id = identify(&acc, 200.0).unwrap();
    assert!((id.first_frequency_hz / f1 - 1.0).abs() < 0.01 && id.damping_ratio > 0.0, "{id:?}");
    // After a first large swing the oscillation grows: not a free decay.
    let growing: Vec<f64> = (0..(3.0 * fs) as usize)
        .map(|k| {
            let t = k as f64 / fs;
            let amplitude = if t < 0.1 { 2.0 } else { 0.5 * (1.0 + 0.5 * t) };
            amplitude * (std::f64::consts::TAU * f1 * t).sin()
        })
        .collect();
    match identify(&growing, 200.0) {
        Err(AnalysisError::NotDecaying { decrement }) => assert!(decrement <= 0.0),
        other => panic!("a growing oscillation: {other:?}"),
    }
}

#[test]
fn the_torque_sign_is_resolved_by_the_travel_and_refused_when_the_currents_contradict_it() {
    use closed_loop::{simulate_travel, SimOptions, TravelSpec};
    use diagnosis::travel_signals::travel_torque;
    use recording::{I_A, I_B, I_C};
    let rig = rig_config::RigConfig::embedded_default().unwrap();
    let spec =
        TravelSpec { m_car_kg: 70.5, direction: drive_core::config::Direction::Up, lw_start_m: 2.0, lw_end_m: 3.6 };
    let run = simulate_travel(&rig, &spec, &SimOptions::for_rig(&rig), None).unwrap();
    let recording = run.to_recording(&spec, rig.mechanics.m_cw_kg, "half turn".to_string());
    let right = travel_torque(&rig, &recording, "up").unwrap();
    let mean = |t: &diagnosis::travel_signals::TravelTorque| {
        t.torque_nm[t.constant_speed.clone()].iter().sum::<f64>() / t.constant_speed.len() as f64
    };
    // Eqn 4: the 70.5 kg car going up against a 33 kg counterweight needs about +24 N m and more.
    assert!(mean(&right) > 20.0, "{}", mean(&right));
    // Currents of the opposite sign: `i_d = 0` alone gives the same offset, the torque's sign wrong
    // (before: -50.1 N m for this car going up). The torque the travel needs turns it half a turn.
    let mut flipped = recording.clone();
    for column in flipped.columns.iter_mut().filter(|c| [I_A, I_B, I_C].contains(&c.name.as_str())) {
        column.values.iter_mut().for_each(|v| *v = -*v);
    }
    let resolved = travel_torque(&rig, &flipped, "up").unwrap();
    assert!((mean(&resolved) - mean(&right)).abs() < 1e-3 * mean(&right).abs(), "{}", mean(&resolved));
    let turn = (resolved.electrical_offset_rad - right.electrical_offset_rad).rem_euclid(std::f64::consts::TAU);
    assert!((turn - std::f64::consts::PI).abs() < 1e-6, "offsets differ by {turn} rad");
    // Currents that neither follow nor oppose the torque the travel needs: refused.
    let mut unrelated = recording.clone();
    for (j, column) in unrelated.columns.iter_mut().filter(|c| [I_A, I_B, I_C].contains(&c.name.as_str())).enumerate() {
        let phase = j as f64 * std::f64::consts::TAU / 3.0;
        column.values = (0..column.values.len())
            .map(|k| 10.0 * (std::f64::consts::TAU * 50.0 * k as f64 / 16384.0 - phase).cos())
            .collect();
    }
    let err = travel_torque(&rig, &unrelated, "up").err().expect("unrelated currents are refused").to_string();
    assert!(err.contains("recording `up`") && err.contains("neither follows nor opposes"), "{err}");
}

#[test]
fn a_fault_after_the_end_of_the_travel_is_refused_not_reported_undetected() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("faults");
    let err = run_err(&["faults", "--quiet", "--direction", "up", "--fault", "current-stuck@300", "--out", s(&out)]);
    assert!(err.contains("current-stuck@300") && err.contains("never injected"), "{err}");
    assert!(!out.exists(), "a refused run wrote {out:?}");
}

#[test]
fn the_rigs_car_is_simulated_as_given_and_an_absurd_one_is_refused_naming_its_source() {
    let tmp = tempfile::tempdir().unwrap();
    let rig = rig_config::EMBEDDED_RIG_TOML;
    let with_cars = |cars: &str, name: &str| {
        let path = tmp.path().join(name);
        fs::write(&path, rig.replace(rig.lines().find(|l| l.starts_with("m_car_kg")).unwrap(), cars)).unwrap();
        path
    };
    // Before: 33 kg (the counterweight) simulated for a rig whose only car is 20 kg.
    let light = with_cars("m_car_kg = [20.0]", "light.toml");
    let out = tmp.path().join("light");
    run_ok(&["--config", s(&light), "travel", "--quiet", "--lw-start", "3", "--lw-end", "4", "--out", s(&out)]);
    let toml =
        fs::read_dir(&out).unwrap().map(|e| e.unwrap().path()).find(|p| p.extension().is_some_and(|e| e == "toml"));
    let meta = fs::read_to_string(toml.unwrap()).unwrap();
    assert!(meta.contains("m_car_kg = 20.0"), "{meta}");
    // A car of the rig beyond the bound names the rig's field, not a flag nobody gave
    // (before: `m_car_kg = [1e5]` passed the rig's check, then `travel` blamed `--m-car`).
    let heavy = with_cars("m_car_kg = [99999.9, 2e5]", "heavy.toml");
    let err = run_err(&["--config", s(&heavy), "travel", "--quiet", "--out", s(&tmp.path().join("heavy"))]);
    assert!(err.contains("heavy.toml: field `[mechanics].m_car_kg[1]` = 200000"), "{err}");
    assert!(!err.contains("--m-car"), "{err}");
    let heaviest = with_cars("m_car_kg = [1e5]", "heaviest.toml");
    let out = host_sim()
        .args(["--config", s(&heaviest), "travel", "--quiet", "--out", s(&tmp.path().join("heaviest"))])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("--m-car") && !err.contains("panicked"), "{err}");
    // A car of a nanogram would never finish: refused before the run, with readable numbers.
    let err = run_err(&["travel", "--quiet", "--m-car", "1e-9", "--out", s(&tmp.path().join("nano"))]);
    assert!(err.contains("--m-car = 1e-9 is out of range") && err.contains("at least 1 kg"), "{err}");
}

#[test]
fn a_sample_rate_far_below_any_recording_and_a_file_given_as_the_dataset_are_refused_clearly() {
    let tmp = tempfile::tempdir().unwrap();
    let toml = write_pair(tmp.path(), "slow", VALID_TOML.replace("1000.0", "1e-300"), VALID_CSV);
    let err = run_err(&["identify", s(tmp.path()), "--out", s(&tmp.path().join("out"))]);
    assert!(err.contains("slow.toml") && err.contains("sample_rate_hz"), "{err}");
    assert!(!err.contains("0000000000"), "a number printed digit by digit: {err}");
    let err = run_err(&["analyze", s(&toml), "--out", s(&tmp.path().join("out"))]);
    assert!(err.contains("is a file; expected a dataset folder"), "{err}");
}

/// Runs `host-sim args`, killed after `limit`; returns stderr, or panics if
/// it had to be killed (a hang) or succeeded.
#[cfg(unix)]
pub(super) fn run_err_within(args: &[&str], limit: std::time::Duration) -> String {
    let mut child = host_sim().args(args).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
    let started = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if started.elapsed() > limit {
            child.kill().unwrap();
            panic!("{args:?} still running after {limit:?}: a hang");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let out = child.wait_with_output().unwrap();
    assert!(!out.status.success(), "{args:?} succeeded");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[cfg(unix)]
#[test]
fn an_input_that_is_a_named_pipe_is_refused_at_open_not_waited_on() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    fs::create_dir(&data).unwrap();
    fs::write(data.join("rec.toml"), VALID_TOML).unwrap();
    let fifo = data.join("rec.csv");
    assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    let limit = std::time::Duration::from_secs(30);
    for args in [
        vec!["analyze", s(&data), "--out", s(&tmp.path().join("a"))],
        vec!["ride-quality", s(&fifo), "--out", s(&tmp.path().join("r"))],
    ] {
        let err = run_err_within(&args, limit);
        assert!(err.contains("rec.csv` is a named pipe; expected a regular file"), "{args:?}: {err}");
    }
}

#[test]
fn metadata_that_contradict_the_samples_are_refused_with_both_sides_named() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    simulate_travel(&data, "up", "up", "3", "4");
    let toml = data.join("up.toml");
    let original = fs::read_to_string(&toml).unwrap();
    // The samples of a 1 m travel under metadata of 6.6 m.
    fs::write(
        &toml,
        original.replace("lw_start_m = 3.0", "lw_start_m = 1.0").replace("lw_end_m = 4.0", "lw_end_m = 7.6"),
    )
    .unwrap();
    let err = run_err(&["analyze", s(&data), "--out", s(&tmp.path().join("a"))]);
    assert!(err.contains("up.toml") && err.contains("6.600 m") && err.contains("m of rope"), "{err}");
    // An up travel whose metadata say down.
    fs::write(
        &toml,
        original.replace("direction = \"up\"", "direction = \"down\"").replace("lw_start_m = 3.0", "lw_start_m = 4.5"),
    )
    .unwrap();
    let err = run_err(&["analyze", s(&data), "--out", s(&tmp.path().join("a"))]);
    assert!(err.contains("up.toml") && err.contains("direction = \"down\"") && err.contains("moved up"), "{err}");
}

#[test]
fn a_sample_rate_whose_recording_would_not_fit_in_memory_is_refused_before_the_run() {
    let tmp = tempfile::tempdir().unwrap();
    // Before: 4.7-7.4 GB allocated, then an allocation abort (exit 134).
    let out = tmp.path().join("dataset");
    let err = run_err(&["dataset", "--sample-rate", "999999", "--out", s(&out)]);
    assert!(err.contains("GB of samples") && err.contains("a sample rate of at most"), "{err}");
    assert!(!out.exists(), "a refused run left {out:?}");
    let rig = rig_config::EMBEDDED_RIG_TOML;
    let line = rig.lines().find(|l| l.starts_with("sample_rate_hz")).unwrap();
    let path = tmp.path().join("fast.toml");
    fs::write(&path, rig.replace(line, "sample_rate_hz = 1e7")).unwrap();
    let err = run_err(&["--config", s(&path), "travel", "--quiet", "--out", s(&tmp.path().join("travel"))]);
    assert!(err.contains("GB of samples"), "{err}");
}

#[test]
fn a_one_sample_glitch_in_a_current_or_the_speed_is_named_with_its_line_and_column() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    simulate_travel(&data, "up", "up", "3", "4");
    let csv = data.join("up.csv");
    let original = fs::read_to_string(&csv).unwrap();
    let header: Vec<&str> = original.lines().next().unwrap().split(',').collect();
    for (column, glitch) in [("i_b_A", 80.0), ("speed_radps", 40.0)] {
        let index = header.iter().position(|h| *h == column).unwrap();
        let mut lines: Vec<String> = original.lines().map(String::from).collect();
        // Line 1001 of the file (the header is line 1).
        let mut fields: Vec<String> = lines[1000].split(',').map(String::from).collect();
        fields[index] = format!("{}", fields[index].parse::<f64>().unwrap() + glitch);
        lines[1000] = fields.join(",");
        fs::write(&csv, lines.join("\n") + "\n").unwrap();
        // Before: "torque neither follows nor opposes the motion", no line, no column.
        let err = run_err(&["analyze", s(&data), "--out", s(&tmp.path().join("a"))]);
        assert!(err.contains("up.csv` line 1001") && err.contains(column) && err.contains("glitch"), "{err}");
    }
}
