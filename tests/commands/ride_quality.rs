//! `host-sim ride-quality` on runs whose figures are known: an `EVIMP1`
//! export without a speed column (regions from the integrated vertical
//! acceleration) and a travel of the measurement format (regions from its
//! speed). The expected vibration figures come from the weighting factors
//! tabulated in ISO 2631-1 Table 3, the regions from the S-curve's own
//! closed form: nothing the command computed.

use std::f64::consts::PI;
use std::fs;
use std::path::Path;
use std::process::{Command, Output};

/// 1 mg in m/s^2.
const MG: f64 = 9.80665e-3;

fn host_sim(args: &[&str], file: &Path, out: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_host-sim"))
        .arg("ride-quality")
        .arg(file)
        .arg("--out")
        .arg(out)
        .args(args)
        .output()
        .unwrap()
}

/// A jerk-limited run: `rest` s still, up to speed `v` (m/s) with
/// acceleration `a` (m/s^2) and jerk `j` (m/s^3), `cruise` s at `v`, down
/// again, `rest` s still.
struct Run {
    v: f64,
    a: f64,
    j: f64,
    rest: f64,
    cruise: f64,
}

impl Run {
    fn ramp(&self) -> f64 {
        2.0 * self.a / self.j + (self.v / self.a - self.a / self.j)
    }

    fn duration(&self) -> f64 {
        2.0 * (self.rest + self.ramp()) + self.cruise
    }

    /// Acceleration and speed `tau` s into the ramp up.
    fn up(&self, tau: f64) -> (f64, f64) {
        let (tj, ramp) = (self.a / self.j, self.ramp());
        if tau <= 0.0 {
            (0.0, 0.0)
        } else if tau < tj {
            (self.j * tau, 0.5 * self.j * tau * tau)
        } else if tau < ramp - tj {
            (self.a, 0.5 * self.j * tj * tj + self.a * (tau - tj))
        } else if tau < ramp {
            let r = ramp - tau;
            (self.j * r, self.v - 0.5 * self.j * r * r)
        } else {
            (0.0, self.v)
        }
    }

    /// Acceleration (m/s^2) and speed (m/s) at `t` s.
    fn at(&self, t: f64) -> (f64, f64) {
        let t2 = self.rest + self.ramp() + self.cruise;
        if t < t2 {
            self.up(t - self.rest)
        } else {
            let (a, v) = self.up(t2 + self.ramp() - t);
            (-a, v)
        }
    }

    /// Where the speed first reaches and last leaves 95 % of `v`, s: on the
    /// last jerk phase, `v - j r^2 / 2 = 0.95 v`.
    fn constant_speed_s(&self) -> (f64, f64) {
        let r = (2.0 * 0.05 * self.v / self.j).sqrt();
        let t1 = self.rest + self.ramp();
        (t1 - r, t1 + self.cruise + r)
    }
}

fn json(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&fs::read_to_string(dir.join("ride_quality.json")).unwrap()).unwrap()
}

fn f(v: &serde_json::Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("{v} is not a number"))
}

/// The figures of `axis` in the region `index` (0 whole run, 1 constant speed).
fn axis<'a>(report: &'a serde_json::Value, index: usize, name: &str) -> &'a serde_json::Value {
    report["vibration"][index]["axes"].as_array().unwrap().iter().find(|a| a["axis"] == name).unwrap()
}

fn close(got: f64, expected: f64, rel: f64, what: &str) {
    assert!((got / expected - 1.0).abs() < rel, "{what}: {got} vs {expected}");
}

#[test]
fn an_evimp_export_gets_x_y_z_and_sound_over_the_regions_of_its_integrated_acceleration() {
    let tmp = tempfile::tempdir().unwrap();
    let fs_hz = 256.0;
    let run = Run { v: 1.5, a: 0.9, j: 1.2, rest: 3.0, cruise: 8.0 };
    let mut text = String::from("EVIMP1\n256\n");
    let n = (run.duration() * fs_hz) as usize;
    for k in 0..n {
        let t = k as f64 / fs_hz;
        let z = run.at(t).0 / MG + 3.0 + 40.0 * (2.0 * PI * 4.0 * t).sin();
        let x = 5.0 * (2.0 * PI * 2.0 * t).sin();
        let y = 5.0 * (2.0 * PI * 8.0 * t).sin();
        let sound = if (9.0 - t).abs() < 0.5 / fs_hz {
            70.0
        } else if (6.0..12.0).contains(&t) {
            50.0
        } else {
            40.0
        };
        text.push_str(&format!("{x:.4} {y:.4} {z:.4} {sound}\n"));
    }
    let file = tmp.path().join("run.txt");
    fs::write(&file, text).unwrap();
    let out = tmp.path().join("out");
    let o = host_sim(&[], &file, &out);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("direction not recorded") && !stdout.contains("direction up"), "{stdout}");
    let r = json(&out);
    assert!(r["direction"].is_null(), "{r}");
    assert_eq!(r["regions"]["from"], "the integrated vertical acceleration");
    let (c0, c1) = run.constant_speed_s();
    let cs = &r["regions"]["constant_speed_s"];
    assert!((f(&cs[0]) - c0).abs() < 0.03 && (f(&cs[1]) - c1).abs() < 0.03, "{cs} vs {c0}..{c1}");
    // Constant speed: 2 x amplitude x the ISO 2631-1 Table 3 factor (Wk at
    // 4 Hz 0.967, Wd at 2 Hz 0.890 and at 8 Hz 0.253). The Wk-weighted
    // motion profile (its 0.4 Hz high-pass tail reaches into the region)
    // adds about 0.8 mg to the largest z pairs: 1 % of the 40 mg sine's.
    assert_eq!(r["vibration"][1]["region"], "constant speed");
    close(f(&axis(&r, 1, "Z")["a95_peak_to_peak_mg"]), 80.0 * 0.967, 0.02, "Z A95");
    close(f(&axis(&r, 1, "X")["a95_peak_to_peak_mg"]), 10.0 * 0.890, 0.02, "X A95");
    close(f(&axis(&r, 1, "Y")["a95_peak_to_peak_mg"]), 10.0 * 0.253, 0.02, "Y A95");
    assert_eq!(axis(&r, 1, "X")["weighting"], "Wd");
    assert_eq!(axis(&r, 1, "Z")["weighting"], "Wk");
    let sound = &r["vibration"][1]["sound"];
    assert_eq!((f(&sound["max_dba"]), f(&sound["a95_dba"])), (70.0, 50.0), "{sound}");
    close(f(&sound["max_at_s"]), 9.0, 0.001, "sound max at");
    assert_eq!(f(&r["vibration"][0]["sound"]["a95_dba"]), 50.0);
    // Motion, the 3 mg offset taken off: plateau 0.9 m/s^2 plus the 4 Hz
    // vibration through the 10 Hz low-pass (|H| = 1/sqrt(1 + 0.4^4)).
    let motion = &r["motion"];
    let peak = 0.9 / MG + 40.0 / (1.0 + 0.4f64.powi(4)).sqrt();
    close(f(&motion["max_acceleration_mg"]), peak, 0.01, "max acceleration");
    close(f(&motion["max_deceleration_mg"]), peak, 0.01, "max deceleration");
    close(f(&motion["max_velocity_mps"]), 1.5, 0.01, "max velocity");
    close(f(&motion["distance_m"]), 1.5 * (run.ramp() + run.cruise), 0.01, "distance");
    // The CSV says the same, and the PNG is there.
    let csv = fs::read_to_string(out.join("ride_quality.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let row: Vec<&str> = csv.lines().nth(2).unwrap().split(',').collect();
    let col = |name: &str| row[header.iter().position(|h| *h == name).unwrap()].parse::<f64>().unwrap();
    assert_eq!(col("z_a95_pp_mg"), f(&axis(&r, 1, "Z")["a95_peak_to_peak_mg"]));
    assert_eq!(col("sound_max_dba"), 70.0);
    assert_eq!(&fs::read(out.join("ride_quality.png")).unwrap()[..8], b"\x89PNG\r\n\x1a\n");
    // A second run into the same folder does not replace the report.
    let again = host_sim(&[], &file, &out);
    assert!(!again.status.success());
    assert!(String::from_utf8_lossy(&again.stderr).contains("--force"));
    // An export has no speed to take the regions from.
    let o = host_sim(&["--regions-from", "speed"], &file, &tmp.path().join("speed"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("--regions-from speed") && err.contains("run.txt"), "{err}");
}

#[test]
fn a_travel_recording_takes_its_regions_from_its_speed_and_keeps_its_direction() {
    let tmp = tempfile::tempdir().unwrap();
    let fs_hz = 1000.0;
    let run = Run { v: 0.4, a: 0.5, j: 1.0, rest: 1.0, cruise: 5.0 };
    // The reference rig's sheave radius (configs/rig.toml): the car's speed
    // is the shaft speed times it.
    let sheave_radius_m = 0.065;
    let mut csv = String::from("time_s,acc_car_mps2,i_a_A,i_b_A,i_c_A,speed_radps\n");
    for k in 0..(run.duration() * fs_hz) as usize {
        let t = k as f64 / fs_hz;
        let (a, v) = run.at(t);
        // Down travel: negative acceleration first, negative speed.
        let acc = -a + 5.0 * MG * (2.0 * PI * 12.5 * t).sin();
        csv.push_str(&format!("{t:.6},{acc},0,0,0,{}\n", -v / sheave_radius_m));
    }
    let toml = "format = \"elevator-measurement/1\"\nkind = \"travel\"\nsample_rate_hz = 1000.0\nm_car_kg = 70.5\n\
                m_cw_kg = 33.0\ndirection = \"down\"\nlw_start_m = 7.6\nlw_end_m = 1.0\n";
    let file = tmp.path().join("down.toml");
    fs::write(&file, toml).unwrap();
    fs::write(tmp.path().join("down.csv"), csv).unwrap();
    let (c0, c1) = run.constant_speed_s();
    for (flag, from, tolerance) in
        [("auto", "the recorded speed", 0.06), ("acceleration", "the integrated vertical acceleration", 0.02)]
    {
        let out = tmp.path().join(flag);
        let o = host_sim(&["--regions-from", flag], &file, &out);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let r = json(&out);
        assert_eq!(r["direction"], "down");
        assert_eq!(r["regions"]["from"], from);
        let cs = &r["regions"]["constant_speed_s"];
        assert!((f(&cs[0]) - c0).abs() < tolerance && (f(&cs[1]) - c1).abs() < tolerance, "{flag}: {cs}");
        // Only the vertical axis is recorded: 12.5 Hz, 5 mg, Wk 0.902 in
        // ISO 2631-1 Table 3.
        let axes = r["vibration"][1]["axes"].as_array().unwrap();
        assert_eq!(axes.len(), 1);
        close(f(&axes[0]["a95_peak_to_peak_mg"]), 10.0 * 0.902, 0.02, "Z A95");
        assert!(r["vibration"][1]["sound"].is_null());
        close(f(&r["motion"]["max_velocity_mps"]), 0.4, 0.01, "max velocity");
    }
}

/// The figures the EVA analyzer printed for the public export
/// `assets/sample/2024F1447R01.txt` of github.com/westone-hq/OTIS (commit
/// 0e0a8a7e186f81666fa00df9ce54f8b0e9fbbf1a), as that repository's
/// `docs/domain_knowledge.md` quotes the report, with the column of
/// `ride_quality.csv` each is held against and its row (0 whole run, 1
/// constant speed). The repository labels the X, Y, Z figures "A95
/// peak-to-peak"; they agree with this command's maximum peak-to-peak over
/// the constant-speed region (within 3.3 %), not with its A95 (7.3, 9.1,
/// 15.7 mg): docs/analysis.md discusses it. Sound: the maximum over the
/// constant-speed region; velocity and distance from the integrated z.
const EVA_REPORT: [(&str, usize, f64); 6] = [
    ("x_max_pp_mg", 1, 8.2),
    ("y_max_pp_mg", 1, 12.9),
    ("z_max_pp_mg", 1, 22.2),
    ("sound_max_dba", 1, 71.7),
    ("max_velocity_mps", 0, 1.50),
    ("distance_m", 0, 20.0),
];

/// Against the analyzer: the export has no licence, so it is not in this
/// repository; give its path in `EVA_SAMPLE_EVIMP` and run
/// `cargo test -p host-sim --test integration commands::ride_quality:: -- --ignored`.
#[test]
#[ignore = "needs the analyzer export (no licence to copy it here): EVA_SAMPLE_EVIMP=<path>"]
fn the_public_eva_export_agrees_with_its_analyzer_report_within_5_percent() {
    let path = std::env::var("EVA_SAMPLE_EVIMP").expect("EVA_SAMPLE_EVIMP names the export 2024F1447R01.txt");
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("eva");
    let o = host_sim(&[], Path::new(&path), &out);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    println!("{}", String::from_utf8_lossy(&o.stdout));
    let csv = fs::read_to_string(out.join("ride_quality.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let rows: Vec<Vec<&str>> = csv.lines().skip(1).map(|l| l.split(',').collect()).collect();
    let value = |row: usize, name: &str| rows[row][header.iter().position(|h| *h == name).unwrap()].parse::<f64>();
    for (name, row, printed) in EVA_REPORT {
        let got = value(row, name).unwrap_or_else(|e| panic!("{name}: {e}"));
        println!("{name}: {got:.3} (analyzer {printed})");
        close(got, printed, 0.05, name);
    }
    // The analyzer's constant-speed region, 11.6-22.0 s, within 0.25 s.
    let r = json(&out);
    let cs = &r["regions"]["constant_speed_s"];
    assert!((f(&cs[0]) - 11.6).abs() < 0.25 && (f(&cs[1]) - 22.0).abs() < 0.25, "{cs}");
}

/// A travel of the foreign rig sample (`../shared/rig-sample`, read in
/// place): its accelerometers do not measure DC (the measurement format's
/// piezoelectric sensors), so the motion comes from the recorded speed. The
/// distance is held against the metadata's rope lengths, the velocity
/// against the recorded reference speed: neither is what the command reads.
#[test]
fn a_foreign_travel_gets_its_motion_from_the_recorded_speed_not_from_ac_coupled_accelerometers() {
    let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/rig-sample");
    let file = sample.join("travel_up_m70.5.toml");
    assert!(file.is_file(), "{}: the foreign rig sample is expected beside the repository", file.display());
    let meta: toml::Value = toml::from_str(&fs::read_to_string(&file).unwrap()).unwrap();
    let lw = |k: &str| meta[k].as_float().unwrap();
    let distance_m = (lw("lw_end_m") - lw("lw_start_m")).abs();
    let mut reader = csv::Reader::from_path(sample.join("travel_up_m70.5.csv")).unwrap();
    let column = reader.headers().unwrap().iter().position(|h| h == "ref_speed_mps").unwrap();
    let ref_max = reader.records().map(|r| r.unwrap()[column].parse::<f64>().unwrap().abs()).fold(0.0_f64, f64::max);
    let tmp = tempfile::tempdir().unwrap();
    for flag in ["auto", "acceleration"] {
        let out = tmp.path().join(flag);
        let o = host_sim(&["--regions-from", flag], &file, &out);
        assert!(o.status.success(), "{flag}: {}", String::from_utf8_lossy(&o.stderr));
        let motion = &json(&out)["motion"];
        assert!(motion["from"].as_str().unwrap().starts_with("recorded speed"), "{flag}: {motion}");
        close(f(&motion["distance_m"]), distance_m, 0.03, "distance against the metadata's rope lengths");
        close(f(&motion["max_velocity_mps"]), ref_max, 0.03, "max velocity against the reference speed");
    }
}
