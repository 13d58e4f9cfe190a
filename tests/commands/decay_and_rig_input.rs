//! Free decays `identify` cannot use and rigs no run can finish on: each
//! refused with its true cause in the user's terms (the file and column,
//! the metadata field, the flag given or its default, the rig's field with
//! the physical reason), a decay's mode above the band searched never
//! turned into an EA, EA values that disagree never averaged silently, and
//! an absurd rig refused before any run starts, within seconds.

use std::fs;
use std::path::{Path, PathBuf};
use std::time::Duration;

use super::bad_input::{run_err, run_err_within, run_ok, s};

/// The samples (m/s^2) and metadata of a simulated free decay of `mass` kg
/// on `length` m of the reference rope, at 16384 Hz.
fn simulated_decay(tmp: &Path, mass: &str, length: &str) -> (Vec<f64>, String) {
    let dir = tmp.join(format!("sim_{mass}_{length}"));
    run_ok(&["decay", "--mass", mass, "--length", length, "--out", s(&dir)]);
    let stem = format!("decay_l{length}_m{mass}");
    let meta = fs::read_to_string(dir.join(format!("{stem}.toml"))).unwrap();
    let csv = fs::read_to_string(dir.join(format!("{stem}.csv"))).unwrap();
    let values = csv.lines().skip(1).map(|l| l.split(',').nth(1).unwrap().parse().unwrap()).collect();
    (values, meta)
}

/// Writes a free decay `dir/decay.{toml,csv}` of `values` at `fs` Hz under
/// `meta` with its sample rate replaced; returns the dataset folder.
fn write_decay(dir: &Path, meta: &str, values: &[f64], fs: f64) -> PathBuf {
    fs::create_dir_all(dir).unwrap();
    let line = meta.lines().find(|l| l.starts_with("sample_rate_hz")).unwrap();
    fs::write(dir.join("decay.toml"), meta.replace(line, &format!("sample_rate_hz = {fs:?}"))).unwrap();
    let mut csv = String::from("time_s,acc_car_mps2\n");
    for (i, v) in values.iter().enumerate() {
        csv.push_str(&format!("{:?},{v:?}\n", i as f64 / fs));
    }
    fs::write(dir.join("decay.csv"), csv).unwrap();
    dir.to_path_buf()
}

fn read_report(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&fs::read_to_string(dir.join("identify.json")).unwrap()).unwrap()
}

#[test]
fn a_decay_whose_mode_lies_above_max_frequency_is_left_out_naming_the_flag_and_the_mode() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    // First modes 17.5 Hz and 7.7 Hz.
    run_ok(&["decay", "--mass", "33", "--length", "2.5", "--out", s(&data)]);
    run_ok(&["decay", "--mass", "70.5", "--length", "6", "--out", s(&data)]);
    let out = tmp.path().join("id");
    // Before: EA 7.3e4 N from a line at 4.7 Hz, with the damping of the
    // 17.5 Hz oscillation, averaged with 1.0e6 N into the rope's EA.
    let stdout = run_ok(&["identify", s(&data), "--max-frequency", "10", "--out", s(&out)]).stdout;
    let stdout = String::from_utf8_lossy(&stdout);
    assert!(stdout.contains("left out: decay_l2.5_m33") && stdout.contains("--max-frequency = 10 Hz"), "{stdout}");
    let report = read_report(&out);
    let decays = report["free_decays"].as_array().unwrap();
    assert_eq!(decays.len(), 1, "{report}");
    assert_eq!(decays[0]["recording"], "decay_l6_m70.5");
    let mean = report["mean_rope_ea_n"].as_f64().unwrap();
    assert!((mean / 1.0e6 - 1.0).abs() < 0.03, "mean EA {mean}");
    let reason = report["left_out"][0]["reason"].as_str().unwrap();
    assert!(
        reason.contains("decay_l2.5_m33.csv`, column `acc_car_mps2`") && reason.contains("rings at 17.5"),
        "{reason}"
    );
    assert!(reason.contains("above --max-frequency = 10 Hz") && reason.contains("mode lies above"), "{reason}");
    // The default band holds both modes: both kept, their EA agree.
    let out = tmp.path().join("id200");
    run_ok(&["identify", s(&data), "--out", s(&out)]);
    let report = read_report(&out);
    assert_eq!(report["free_decays"].as_array().unwrap().len(), 2, "{report}");
    assert!(report["rope_ea_disagreement"].is_null(), "{report}");
}

#[test]
fn ea_values_that_disagree_beyond_their_uncertainty_are_not_averaged_silently() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    run_ok(&["decay", "--mass", "33", "--length", "2.5", "--out", s(&data)]);
    run_ok(&["decay", "--mass", "70.5", "--length", "6", "--out", s(&data)]);
    // The second decay's metadata claim a 5 m rope: its EA comes out about
    // 20 % apart, far beyond the scatter of its cycles.
    let toml = data.join("decay_l6_m70.5.toml");
    fs::write(&toml, fs::read_to_string(&toml).unwrap().replace("rope_length_m = 6.0", "rope_length_m = 5.0")).unwrap();
    let out = tmp.path().join("id");
    let stdout = String::from_utf8_lossy(&run_ok(&["identify", s(&data), "--out", s(&out)]).stdout).into_owned();
    assert!(stdout.contains("note: the decays' EA values disagree beyond their uncertainty"), "{stdout}");
    let note = read_report(&out)["rope_ea_disagreement"].as_str().unwrap().to_string();
    assert!(note.contains("decay_l2.5_m33") && note.contains("decay_l6_m70.5"), "{note}");
}

#[test]
fn a_decay_identify_cannot_use_gets_its_true_cause_naming_the_file_and_column() {
    let tmp = tempfile::tempdir().unwrap();
    let (decay, meta) = simulated_decay(tmp.path(), "33", "2.5");
    let fs = 16384.0;
    let reversed: Vec<f64> = decay.iter().rev().copied().collect();
    let khz: Vec<f64> = (0..decay.len())
        .map(|i| {
            let t = i as f64 / fs;
            (-2.0 * t).exp() * (std::f64::consts::TAU * 500.0 * t).sin()
        })
        .collect();
    let step: Vec<f64> = (0..decay.len()).map(|i| if i < decay.len() / 2 { 0.0 } else { 1.0 }).collect();
    let cases: Vec<(&str, Vec<f64>, f64, &[&str])> = vec![
        // Before: "the signal has 0 samples; expected at least 3 ...".
        ("growing", reversed, fs, &["decay.csv`, column `acc_car_mps2`", "does not decay"]),
        ("khz", khz, fs, &["decay.csv`, column `acc_car_mps2`", "rings at 500", "--max-frequency (default 200 Hz)"]),
        ("step", step, fs, &["decay.csv`, column `acc_car_mps2`", "no oscillation", "a step"]),
        // Before: "invalid parameter `max_frequency_hz`", a flag nobody gave.
        ("two", decay[..2].to_vec(), fs, &["decay.csv`, column `acc_car_mps2`: 2 samples"]),
        ("hour", decay[..3600].to_vec(), 1.0, &["decay.toml`: sample_rate_hz = 1 Hz", "Nyquist"]),
        ("mhz", decay.clone(), 1.0e7, &["decay.csv`, column `acc_car_mps2`", "the decay lasts", "sample_rate_hz"]),
    ];
    for (name, values, rate, needles) in cases {
        let data = write_decay(&tmp.path().join(name), &meta, &values, rate);
        let err = run_err(&["identify", s(&data), "--out", s(&tmp.path().join(format!("out_{name}")))]);
        for needle in needles {
            assert!(err.contains(needle), "{name}: `{needle}` not in {err}");
        }
        for wrong in ["max_frequency_hz", "has 0 samples", "signal is empty"] {
            assert!(!err.contains(wrong), "{name}: {err}");
        }
    }
    // The sound decay itself is identified.
    let data = write_decay(&tmp.path().join("sound"), &meta, &decay, fs);
    run_ok(&["identify", s(&data), "--out", s(&tmp.path().join("out_sound"))]);
}

/// The embedded rig with the line `key = ...` set to `key = value`.
fn rig_with(key: &str, value: &str) -> String {
    let rig = rig_config::EMBEDDED_RIG_TOML;
    let line = rig.lines().find(|l| l.starts_with(&format!("{key} = "))).unwrap();
    rig.replacen(line, &format!("{key} = {value}"), 1)
}

#[cfg(unix)]
#[test]
fn an_absurd_rig_is_refused_before_any_run_naming_the_field_and_why() {
    let tmp = tempfile::tempdir().unwrap();
    // Before: `travel` never returned (the first three), or ran a travel of
    // 6.6e9 s into a 1e7 GB refusal, or panicked (a rope of 1 um).
    let rigs = [
        ("inertia", rig_with("sheave_inertia_kg_m2", "1e-9"), "[mechanics].sheave_inertia_kg_m2` = 1e-9"),
        ("cw", rig_with("m_cw_kg", "1e-9"), "[mechanics].m_cw_kg` = 1e-9"),
        ("rope", rig_with("rope_mass_per_length_kg_per_m", "1e-9"), "[mechanics].rope_mass_per_length_kg_per_m`"),
        ("speed", rig_with("rated_speed_mps", "1e-9"), "[travel].rated_speed_mps` = 1e-9"),
        ("length", rig_with("rope_total_length_m", "1e-6"), "[mechanics].rope_total_length_m` = 1e-6"),
        ("stiff", rig_with("rope_ea_n", "1e12"), "[mechanics].rope_ea_n` = 1e12"),
        ("gravity", rig_with("gravity_mps2", "1e-9"), "[mechanics].gravity_mps2` = 1e-9"),
        ("car", rig_with("m_car_kg", "[33.0, 2e5]"), "[mechanics].m_car_kg[1]` = 200000"),
    ];
    let limit = Duration::from_secs(20);
    for (name, text, field) in rigs {
        let path = tmp.path().join(format!("{name}.toml"));
        fs::write(&path, text).unwrap();
        for command in [vec!["travel", "--quiet"], vec!["decay"], vec!["modes"], vec!["faults", "--quiet"]] {
            let out = tmp.path().join(format!("out_{name}"));
            let mut args = vec!["--config", s(&path)];
            args.extend(&command);
            args.extend(["--out", s(&out)]);
            let err = run_err_within(&args, limit);
            assert!(err.contains(&format!("{name}.toml: field `{field}")), "{args:?}: {err}");
            assert!(err.contains("is out of range: expected a finite value in"), "{err}");
            assert!(!err.contains("--m-car") && !err.contains("0.00000000"), "{err}");
            assert!(!out.exists(), "a refused run left {out:?}");
        }
    }
}

#[cfg(unix)]
#[test]
fn a_flag_of_an_absurd_magnitude_is_refused_before_the_run_with_readable_numbers() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    // Before: a sweep from 0.000...0001 m, a count of 8.4e300 points written
    // digit by digit, a whole travel simulated before its spectrogram window
    // was refused as `window_s` = 0.000...0001, a decay of a 1e-300 kg mass
    // written under a 300-digit stem.
    let cases: [(&[&str], &str); 6] = [
        (&["modes", "--lw-from", "1e-300"], "--lw-from = 1e-300 is out of range"),
        (&["modes", "--lw-step", "1e-300"], "--lw-step = 1e-300 gives 8.4e300 points"),
        (&["travel", "--quiet", "--spectrogram-window", "1e-300"], "--spectrogram-window = 1e-300"),
        (&["travel", "--quiet", "--lw-start", "1e-300"], "--lw-start = 1e-300"),
        (&["decay", "--mass", "1e-300"], "--mass = 1e-300 is out of range: expected a finite value in [1, 100000] kg"),
        (&["decay", "--length", "1e300"], "--length = 1e300 is out of range"),
    ];
    for (args, needle) in cases {
        let mut args = args.to_vec();
        args.extend(["--out", s(&out)]);
        let err = run_err_within(&args, Duration::from_secs(10));
        assert!(err.contains(needle) && !err.contains("0000000000"), "{args:?}: {err}");
        assert!(!out.exists(), "{args:?} left {out:?}");
    }
}

#[test]
fn a_rig_of_another_pole_pair_count_than_the_recordings_machine_is_named() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let travel = ["travel", "--quiet", "--m-car", "45.5", "--lw-start", "2", "--lw-end", "5", "--stem", "up"];
    run_ok(&[&travel[..], &["--out", s(&data)]].concat());
    // Before: "the machine torque from the currents neither follows nor
    // opposes the torque that the travel needs", naming no file nor field.
    for pole_pairs in ["5", "12"] {
        let rig = tmp.path().join(format!("p{pole_pairs}.toml"));
        fs::write(&rig, rig_with("pole_pairs", pole_pairs)).unwrap();
        for command in ["analyze", "identify"] {
            let out = tmp.path().join(format!("{command}_{pole_pairs}"));
            let err = run_err(&["--config", s(&rig), command, s(&data), "--out", s(&out)]);
            assert!(err.contains("up.csv`, column `i_a_A, i_b_A`"), "{err}");
            assert!(err.contains("6.00 electrical turns per shaft turn"), "{err}");
            assert!(err.contains(&format!("[motor].pole_pairs = {pole_pairs}")), "{err}");
        }
    }
    run_ok(&["analyze", s(&data), "--out", s(&tmp.path().join("right"))]);
}

#[test]
fn modes_and_faults_simulate_the_rigs_only_car_not_the_counterweight() {
    let tmp = tempfile::tempdir().unwrap();
    let rig = tmp.path().join("light.toml");
    fs::write(&rig, rig_with("m_car_kg", "[20.0]")).unwrap();
    // Before: both simulated 33 kg, the counterweight's mass.
    let modes = run_ok(&["--config", s(&rig), "modes", "--out", s(&tmp.path().join("modes"))]).stdout;
    assert!(String::from_utf8_lossy(&modes).starts_with("m_car = 20 kg:"), "{}", String::from_utf8_lossy(&modes));
    let out = tmp.path().join("faults");
    let args = ["--config", s(&rig), "faults", "--quiet", "--direction", "up", "--fault", "current-stuck@5"];
    run_ok(&[&args[..], &["--out", s(&out)]].concat());
    let report = fs::read_to_string(out.join("faults.json")).unwrap();
    assert!(report.contains("\"m_car_kg\": 20.0") && !report.contains("\"m_car_kg\": 33.0"), "{report}");
}
