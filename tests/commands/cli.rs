//! The `host-sim` binary as a user runs it: outputs, and clear errors for
//! bad flags and bad rig files.

use std::process::Command;

fn host_sim() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-sim"))
}

#[test]
fn modes_writes_the_csv_with_the_paper_frequencies_at_lw_4m() {
    let dir = tempfile::tempdir().unwrap();
    let out = host_sim().args(["modes", "--m-car", "70.5", "--out"]).arg(dir.path()).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let csv = std::fs::read_to_string(dir.path().join("modes.csv")).unwrap();
    assert_eq!(csv.lines().next().unwrap(), "lw_m,f1_hz,f2_hz,f3_hz,f4_hz,f5_hz");
    let row: Vec<f64> = csv
        .lines()
        .find(|l| l.starts_with("4,"))
        .expect("a row at lw = 4 m")
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    for (got, quoted) in row[1..].iter().zip([0.0, 10.6, 17.5, 224.8, 258.7]) {
        assert!((got - quoted).abs() <= 0.005 * quoted, "{row:?}");
    }
    for png in ["modes.png", "modes_0-128hz.png"] {
        let bytes = std::fs::read(dir.path().join(png)).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    }
}

#[test]
fn travel_writes_a_recording_in_the_measurement_format_and_plots() {
    let dir = tempfile::tempdir().unwrap();
    let out = host_sim()
        .args(["travel", "--quiet", "--m-car", "45.5", "--direction", "down", "--lw-start", "4.2", "--lw-end", "3.4"])
        .args(["--stem", "short", "--out"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let meta: toml::Table = std::fs::read_to_string(dir.path().join("short.toml")).unwrap().parse().unwrap();
    assert_eq!(meta["format"].as_str(), Some("elevator-measurement/1"));
    assert_eq!(meta["kind"].as_str(), Some("travel"));
    assert_eq!(meta["direction"].as_str(), Some("down"));
    assert_eq!(meta["sample_rate_hz"].as_float(), Some(16384.0));
    let mut reader = csv::Reader::from_path(dir.path().join("short.csv")).unwrap();
    let header = reader.headers().unwrap().clone();
    for column in ["time_s", "acc_car_mps2", "i_a_A", "i_b_A", "i_c_A", "speed_radps", "angle_rad", "ref_speed_mps"] {
        assert!(header.iter().any(|h| h == column), "missing {column}");
    }
    let rows = reader.records().count();
    assert!(rows > 16384, "{rows} samples");
    for suffix in ["acc_car_hp", "spectrogram", "drive"] {
        assert!(dir.path().join(format!("short_{suffix}.png")).exists(), "{suffix}");
    }
}

#[test]
fn bad_flags_and_bad_rig_files_name_what_is_wrong() {
    let out = host_sim().args(["modes", "--m-car", "-3"]).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--m-car = -3") && err.contains("at least 1 kg and at most 100000 kg"), "{err}");

    let out = host_sim().args(["travel", "--lw-start", "9.5"]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("--lw-start") && err.contains("8.6"), "{err}");

    let out = host_sim().args(["travel", "--direction", "up", "--lw-start", "5", "--lw-end", "4"]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("lw grows"), "{err}");

    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("rig.toml");
    let text = rig_config::EMBEDDED_RIG_TOML.replace("rope_ea_n = 1.0e6", "rope_ea_n = 0.0");
    std::fs::write(&bad, text).unwrap();
    let out = host_sim().arg("--config").arg(&bad).args(["modes"]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("rig.toml") && err.contains("[mechanics].rope_ea_n"), "{err}");
}

#[test]
fn identify_recovers_ea_damping_and_sheave_damping_from_simulated_tests() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("dataset");
    let run = |args: &[&str]| {
        let out = host_sim().args(args).output().unwrap();
        assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    };
    let data_s = data.to_str().unwrap();
    run(&["decay", "--mass", "33,70.5", "--length", "2.5", "--ea", "1.2e6", "--out", data_s]);
    run(&[
        "travel",
        "--quiet",
        "--m-car",
        "58",
        "--lw-start",
        "2.0",
        "--lw-end",
        "6.5",
        "--stem",
        "up",
        "--out",
        data_s,
    ]);
    let out_dir = dir.path().join("id");
    run(&["identify", data_s, "--out", out_dir.to_str().unwrap()]);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("identify.json")).unwrap()).unwrap();
    for decay in report["free_decays"].as_array().unwrap() {
        let mass = decay["mass_kg"].as_f64().unwrap();
        let f1 = decay["first_frequency_hz"].as_f64().unwrap();
        let zeta_true = 148.0 / (2.0 * mass * std::f64::consts::TAU * f1);
        let ea = decay["rope_ea_n"].as_f64().unwrap();
        let zeta = decay["damping_ratio"].as_f64().unwrap();
        assert!((ea / 1.2e6 - 1.0).abs() < 0.03, "EA {ea}");
        assert!((zeta / zeta_true - 1.0).abs() < 0.10, "zeta {zeta} vs {zeta_true}");
    }
    let c_sheave = report["travels"][0]["sheave_damping_nms_per_rad"].as_f64().unwrap();
    assert!((c_sheave - 3.0).abs() < 0.15, "c_sheave {c_sheave}");
}

#[test]
fn analyze_recovers_the_ripple_lines_frequency_within_1_percent_and_amplitude_within_5_percent() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("dataset");
    let data_s = data.to_str().unwrap();
    let out = host_sim()
        .args([
            "travel",
            "--quiet",
            "--m-car",
            "45.5",
            "--lw-start",
            "1.5",
            "--lw-end",
            "7.0",
            "--stem",
            "up",
            // The drive cancels the simulated shaft ripple exactly, so the
            // machine torque from the currents carries the rig's amplitudes.
            "--compensation",
            "rig-table",
            "--out",
            data_s,
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let out_dir = dir.path().join("an");
    let out = host_sim().args(["analyze", data_s, "--out", out_dir.to_str().unwrap()]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("analyze.json")).unwrap()).unwrap();
    let travel = &report["travels"][0];
    // The reference speed is 0.4 m/s on a 65 mm sheave: 0.9794 Hz.
    let f_mech = travel["mechanical_frequency_hz"].as_f64().unwrap();
    assert!((f_mech - 0.4 / 0.065 / std::f64::consts::TAU).abs() < 0.01 * f_mech, "{f_mech}");
    // The orders the rig's [[ripple]] excites (the others are noise here).
    let lines: Vec<&serde_json::Value> = travel["ripple_lines"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|l| [1, 6, 12, 36, 72].contains(&l["mechanical_order"].as_u64().unwrap()))
        .collect();
    assert_eq!(lines.len(), 5);
    let rig = rig_config::RigConfig::embedded_default().unwrap();
    for line in lines {
        let expected = line["expected_frequency_hz"].as_f64().unwrap();
        let found = line["frequency_hz"].as_f64().unwrap();
        assert!((found - expected).abs() <= 0.01 * expected, "{line}");
        let order = line["mechanical_order"].as_u64().unwrap() as u32;
        let known = rig.ripple.iter().find(|r| r.mechanical_order == order).unwrap().amplitude_nm;
        let amplitude = line["amplitude_nm"].as_f64().unwrap();
        println!("order {order}: {found:.3} Hz (expected {expected:.3}), {amplitude:.4} N m (known {known})");
        assert!((amplitude - known).abs() <= 0.05 * known, "{line}: amplitude {amplitude} vs {known} N m");
    }
    for file in ["up/torque_psd.csv", "up/acc_car_mps2_spectrogram_burg.png", "up/acc_car_mps2_hp.png"] {
        assert!(out_dir.join(file).exists(), "{file}");
    }
}
