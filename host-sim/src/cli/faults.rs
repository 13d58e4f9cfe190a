//! `host-sim faults`: the drive under faults. Every fault kind at
//! several instants of a travel (acceleration, rated speed, deceleration),
//! car up and down, or the faults given with `--fault` / `--faults-file`
//! (several at once); a table of detection time, reason, peak current, peak
//! car acceleration and car displacement after detection, as CSV, Markdown
//! and JSON.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant as WallClock;

use anyhow::Context;
use clap::{Args, ValueEnum};
use drive_core::config::Direction;
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;

use super::{car_mass_kg, check_open_range, output_dir};
use closed_loop::faults::run::{default_matrix, profile_timing_s, run_case_with, FaultCase, FaultOutcome};
use closed_loop::faults::{parse_fault, parse_fault_toml, FaultSpec};
use closed_loop::TravelSpec;
use rig_config::RigConfig;

/// Directions to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Directions {
    /// Car up.
    Up,
    /// Car down.
    Down,
    /// Both.
    Both,
}

/// Options of `faults`.
#[derive(Debug, Args)]
pub struct FaultsArgs {
    /// A fault to inject, `KIND@WHEN[:KEY=VALUE,...]` (repeat for several at
    /// once). KIND: current-stuck, current-disconnected, current-drift,
    /// encoder-lose, encoder-jump, encoder-stop, short, open-phase, bus-sag,
    /// bus-over, deadline-skip, deadline-late, load-change, brake-stuck,
    /// frame-corrupt. WHEN: seconds from the travel command, or start, accel,
    /// cruise, decel. Without --fault or --faults-file: every kind at its
    /// instants.
    #[arg(long = "fault", value_name = "KIND@WHEN[:K=V,..]")]
    pub faults: Vec<String>,
    /// A TOML file of `[[fault]]` tables (`kind`, `at`, the kind's keys),
    /// injected together with any --fault.
    #[arg(long = "faults-file", value_name = "FILE")]
    pub faults_file: Option<PathBuf>,
    /// Car mass, kg (default: the heaviest car of the rig).
    #[arg(long = "m-car", value_name = "KG", allow_negative_numbers = true)]
    pub m_car_kg: Option<f64>,
    /// Car directions.
    #[arg(long, value_enum, default_value_t = Directions::Both)]
    pub direction: Directions,
    /// Simulated time after a trip, s.
    #[arg(long = "after-trip", value_name = "S", default_value_t = closed_loop::faults::run::AFTER_TRIP_S, allow_negative_numbers = true)]
    pub after_trip_s: f64,
    /// Output directory (`faults.csv`, `faults.md`, `faults.json`).
    #[arg(long, value_name = "DIR", default_value = "out/faults")]
    pub out: PathBuf,
    /// Replace the tables of an earlier run (default: refuse to overwrite).
    #[arg(long)]
    pub force: bool,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// The cases `args` ask for.
pub fn cases(rig: &RigConfig, args: &FaultsArgs) -> anyhow::Result<Vec<FaultCase>> {
    let m_car = car_mass_kg(rig, args.m_car_kg)?;
    check_open_range("--after-trip", args.after_trip_s, 0.0, 60.0)?;
    let mut given: Vec<FaultSpec> =
        args.faults.iter().map(|text| parse_fault(text)).collect::<Result<_, _>>().map_err(anyhow::Error::from)?;
    if let Some(path) = &args.faults_file {
        let text = rig_config::read_text_file(path, rig_config::MAX_TEXT_FILE_BYTES)
            .with_context(|| format!("cannot read {}", path.display()))?;
        given.extend(parse_fault_toml(&text).with_context(|| format!("{}", path.display()))?);
    }
    let directions: &[Direction] = match args.direction {
        Directions::Up => &[Direction::Up],
        Directions::Down => &[Direction::Down],
        Directions::Both => &[Direction::Up, Direction::Down],
    };
    let cases = if given.is_empty() {
        default_matrix(rig, m_car).into_iter().filter(|c| directions.contains(&c.travel.direction)).collect()
    } else {
        directions
            .iter()
            .map(|&d| FaultCase { travel: TravelSpec::full_travel(rig, m_car, d), faults: given.clone() })
            .collect()
    };
    Ok(cases)
}

/// Runs `faults`.
pub fn run(rig: &RigConfig, args: &FaultsArgs) -> anyhow::Result<()> {
    let cases = cases(rig, args)?;
    let out = output_dir(&args.out, args.force)?;
    out.refuse_existing(["faults.md", "faults.csv", "faults.json"])?;
    let bar = if args.quiet { ProgressBar::hidden() } else { ProgressBar::new(cases.len() as u64) };
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} faulted travels, {elapsed} ({eta} left)")
            .expect("valid template"),
    );
    let started = WallClock::now();
    let outcomes: Vec<FaultOutcome> = cases
        .par_iter()
        .map(|case| {
            let mut controller = drive_core::Controller::new(&rig.drive_config());
            let outcome = run_case_with(rig, case, &mut controller, args.after_trip_s);
            bar.inc(1);
            outcome
        })
        .collect();
    bar.finish_and_clear();
    let elapsed = started.elapsed().as_secs_f64();
    refuse_never_injected(rig, &cases, &outcomes)?;

    let rows: Vec<Row> = outcomes.iter().map(Row::of).collect();
    let md = markdown(&rows);
    std::fs::write(out.path("faults.md"), &md).context("cannot write faults.md")?;
    write_csv(&out.path("faults.csv"), &rows)?;
    let json = serde_json::to_string_pretty(&serde_json::json!({
        "m_car_kg": cases.first().map(|c| c.travel.m_car_kg),
        "after_trip_s": args.after_trip_s,
        "wall_time_s": elapsed,
        "cases": rows,
    }))?;
    std::fs::write(out.path("faults.json"), json).context("cannot write faults.json")?;
    out.commit()?;
    outln!("{}", md.trim_end_matches('\n'));
    outln!("{} faulted travels in {elapsed:.1} s; tables in {}", rows.len(), args.out.display());
    Ok(())
}

/// Refuses a run in which a given fault never started (its onset after
/// the end of the simulated travel): a "not detected" row would report a
/// fault that was never there.
fn refuse_never_injected(rig: &RigConfig, cases: &[FaultCase], outcomes: &[FaultOutcome]) -> anyhow::Result<()> {
    for (case, outcome) in cases.iter().zip(outcomes) {
        if outcome.observed.first_onset_s.is_none() && outcome.error.is_none() {
            let (start_s, duration_s) = profile_timing_s(rig, &case.travel);
            anyhow::bail!(
                "--fault {}: never injected: the {} kg car's travel {} ends its motion {:.2} s after the travel \
                 command and the simulation stopped before the onset; expected an onset before {:.2} s, or start, \
                 accel, cruise or decel",
                outcome.label,
                case.travel.m_car_kg,
                direction_name(case.travel.direction),
                start_s + duration_s,
                start_s + duration_s
            );
        }
    }
    Ok(())
}

/// `up` or `down`.
fn direction_name(direction: Direction) -> &'static str {
    match direction {
        Direction::Up => "up",
        Direction::Down => "down",
    }
}

/// One line of the table.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Row {
    /// Fault kinds, `+`-joined.
    pub fault: String,
    /// Their parameters.
    pub parameters: String,
    /// Onset (named instant or seconds), `+`-joined.
    pub instant: String,
    /// `up` or `down`.
    pub direction: &'static str,
    /// Onset, s from the travel command.
    pub onset_s: f64,
    /// Detection time after the onset, ms (none: not detected).
    pub detection_ms: Option<f64>,
    /// Reason code.
    pub reason_code: Option<u8>,
    /// Reason name.
    pub reason: Option<&'static str>,
    /// Peak |leg current| from the onset, A.
    pub peak_current_a: f64,
    /// Peak |car acceleration| from the onset to the trip, m/s^2.
    pub peak_car_acceleration_mps2: f64,
    /// Peak |car acceleration| after the trip (brake), m/s^2.
    pub peak_car_acceleration_after_trip_mps2: f64,
    /// Largest car displacement after detection, mm.
    pub car_displacement_after_detection_mm: Option<f64>,
    /// PWM off, brake applied, zero machine torque and still tripped to the end.
    pub safe_state_held: Option<bool>,
    /// Landing error of an undetected fault's travel, mm.
    pub landing_error_mm: Option<f64>,
    /// How the run ended otherwise.
    pub error: Option<String>,
}

impl Row {
    /// The row of `o`.
    pub fn of(o: &FaultOutcome) -> Self {
        let (fault, instant): (Vec<&str>, Vec<&str>) =
            o.label.split('+').map(|l| l.split_once('@').unwrap_or((l, ""))).unzip();
        let tripped = o.reason.is_some();
        let obs = &o.observed;
        Self {
            fault: fault.join("+"),
            parameters: o.parameters.clone(),
            instant: instant.join("+"),
            direction: direction_name(o.direction),
            onset_s: o.onset_s,
            detection_ms: o.detection_s.map(|s| s * 1e3),
            reason_code: o.reason.map(|r| r.code()),
            reason: o.reason.map(|r| r.name()),
            peak_current_a: obs.peak_current_a,
            peak_car_acceleration_mps2: obs.peak_car_acceleration_mps2,
            peak_car_acceleration_after_trip_mps2: obs.peak_car_acceleration_after_trip_mps2,
            car_displacement_after_detection_mm: tripped.then_some(obs.car_displacement_after_trip_m * 1e3),
            safe_state_held: tripped
                .then_some(!obs.unsafe_output_after_trip && !obs.left_tripped && obs.torque_after_trip_nm == 0.0),
            landing_error_mm: o.landing_error_m.map(|m| m * 1e3),
            error: o.error.clone(),
        }
    }
}

fn opt(value: Option<f64>, decimals: usize) -> String {
    value.map_or_else(|| "-".to_string(), |v| format!("{v:.decimals$}"))
}

/// The Markdown table.
pub fn markdown(rows: &[Row]) -> String {
    let mut md = String::from(
        "| fault | parameters | instant | dir | onset (s) | detection (ms) | reason | peak current (A) | peak car acc. to trip (m/s^2) | peak car acc. after trip (m/s^2) | car displacement after detection (mm) | safe state held |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let reason = match (r.reason_code, r.reason) {
            (Some(code), Some(name)) => format!("{code} {name}"),
            _ => match (&r.error, r.landing_error_mm) {
                (Some(e), _) => format!("not detected ({e})"),
                (None, Some(mm)) => format!("not detected (landed {mm:+.1} mm off)"),
                _ => "not detected".to_string(),
            },
        };
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {:.3} | {} | {} | {:.1} | {:.2} | {:.2} | {} | {} |",
            r.fault,
            r.parameters,
            r.instant,
            r.direction,
            r.onset_s,
            opt(r.detection_ms, 2),
            reason,
            r.peak_current_a,
            r.peak_car_acceleration_mps2,
            r.peak_car_acceleration_after_trip_mps2,
            opt(r.car_displacement_after_detection_mm, 1),
            r.safe_state_held.map_or("-", |s| if s { "yes" } else { "NO" }),
        );
    }
    md
}

fn write_csv(path: &std::path::Path, rows: &[Row]) -> anyhow::Result<()> {
    let mut w = csv::Writer::from_path(path).with_context(|| format!("cannot write {}", path.display()))?;
    w.write_record([
        "fault",
        "parameters",
        "instant",
        "direction",
        "onset_s",
        "detection_ms",
        "reason_code",
        "reason",
        "peak_current_a",
        "peak_car_acceleration_mps2",
        "peak_car_acceleration_after_trip_mps2",
        "car_displacement_after_detection_mm",
        "safe_state_held",
        "landing_error_mm",
        "error",
    ])?;
    let s = |v: Option<f64>| v.map(|v| v.to_string()).unwrap_or_default();
    for r in rows {
        w.write_record([
            r.fault.clone(),
            r.parameters.clone(),
            r.instant.clone(),
            r.direction.to_string(),
            r.onset_s.to_string(),
            s(r.detection_ms),
            r.reason_code.map(|c| c.to_string()).unwrap_or_default(),
            r.reason.unwrap_or_default().to_string(),
            r.peak_current_a.to_string(),
            r.peak_car_acceleration_mps2.to_string(),
            r.peak_car_acceleration_after_trip_mps2.to_string(),
            s(r.car_displacement_after_detection_mm),
            r.safe_state_held.map(|b| b.to_string()).unwrap_or_default(),
            s(r.landing_error_mm),
            r.error.clone().unwrap_or_default(),
        ])?;
    }
    w.flush()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(faults: &[&str], out: PathBuf) -> FaultsArgs {
        FaultsArgs {
            faults: faults.iter().map(|s| s.to_string()).collect(),
            faults_file: None,
            m_car_kg: None,
            direction: Directions::Up,
            after_trip_s: 0.05,
            out,
            force: false,
            quiet: true,
        }
    }

    #[test]
    fn the_default_matrix_covers_every_kind_at_its_instants_in_both_directions() {
        let rig = RigConfig::embedded_default().unwrap();
        let mut a = args(&[], PathBuf::from("unused"));
        a.direction = Directions::Both;
        let cases = cases(&rig, &a).unwrap();
        // 15 kinds (+ the disconnected sensor both ways) x 3 instants x 2
        // directions, the brake at the start only.
        assert_eq!(cases.len(), (15 * 3 + 1) * 2);
        for name in &closed_loop::faults::KIND_NAMES[..15] {
            assert!(cases.iter().any(|c| c.faults[0].kind.name() == *name), "{name}");
        }
    }

    #[test]
    fn bad_options_are_refused_naming_the_flag() {
        let rig = RigConfig::embedded_default().unwrap();
        let e = cases(&rig, &args(&["short@soon"], PathBuf::from("x"))).unwrap_err().to_string();
        assert!(e.contains("seconds >= 0 or one of start, accel, cruise, decel"), "{e}");
        let mut a = args(&["short@1"], PathBuf::from("x"));
        a.m_car_kg = Some(-1.0);
        assert!(cases(&rig, &a).unwrap_err().to_string().contains("--m-car"));
        let mut a = args(&[], PathBuf::from("x"));
        a.faults_file = Some(PathBuf::from("/nonexistent/faults.toml"));
        assert!(cases(&rig, &a).unwrap_err().to_string().contains("/nonexistent/faults.toml"));
    }

    #[test]
    fn two_faults_at_once_write_the_three_tables() {
        let rig = RigConfig::embedded_default().unwrap();
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("f.toml");
        std::fs::write(&file, "[[fault]]\nkind = \"deadline-skip\"\nat = 0.5\nsteps = 4\n").unwrap();
        let mut a = args(&["bus-sag@0.6"], dir.path().to_path_buf());
        a.faults_file = Some(file);
        run(&rig, &a).unwrap();
        let md = std::fs::read_to_string(dir.path().join("faults.md")).unwrap();
        assert!(md.contains("| bus-sag+deadline-skip |"), "{md}");
        assert!(md.contains("7 DeadlineMissed"), "{md}");
        let csv = std::fs::read_to_string(dir.path().join("faults.csv")).unwrap();
        assert_eq!(csv.lines().count(), 2);
        let json: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.path().join("faults.json")).unwrap()).unwrap();
        // 4 skipped steps: the step after them is 5 periods after the last.
        let detection = json["cases"][0]["detection_ms"].as_f64().unwrap();
        assert!((detection - 4.0 / 16.0).abs() < 1e-6, "{detection}");
    }
}
