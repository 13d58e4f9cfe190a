//! Command-line interface: one file per command.
//!
//! The commands print with `outln!` (not `println!`): a closed standard
//! output ends the printing quietly instead of panicking
//! ([`crate::output::print_line`]); they write files through an
//! [`OutputDir`](crate::output::OutputDir) (temporary names, nothing
//! replaced without `--force`).

/// `println!` for the commands: the line goes to standard output through
/// [`crate::output::print_line`], which never panics (a closed pipe
/// silences the rest of the output).
macro_rules! outln {
    ($($arg:tt)*) => {
        $crate::output::print_line(format_args!($($arg)*))
    };
}

pub mod analyze;
pub mod bench;
pub mod compare;
pub mod dataset;
pub mod decay;
pub mod drive;
pub mod faults;
pub mod gap;
pub mod identify;
pub mod identify_screen;
pub mod modes;
pub mod pil;
pub mod ride_quality;
pub mod travel;

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Parser, Subcommand};

use recording::Recording;
use rig_config::RigConfig;

/// Elevator drive simulator: the nominal 5-DOF plant of Arrasate et al.
/// closed around the fixed-point drive core that also runs on the STM32G474.
#[derive(Debug, Parser)]
#[command(name = "host-sim", version, about, long_about = None)]
pub struct Cli {
    /// Rig description (TOML); default: the embedded configs/rig.toml.
    #[arg(long, global = true, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// The command.
    #[command(subcommand)]
    pub command: Command,
}

/// The commands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Natural frequencies and mode shapes (Eqn 10) against the
    /// counterweight-side rope length (paper Fig. 5).
    Modes(modes::ModesArgs),
    /// One closed-loop travel written as a recording, with plots of the
    /// high-passed car acceleration (Fig. 7) and its spectrogram (Fig. 6/8).
    Travel(travel::TravelArgs),
    /// Measures how fast travels simulate (ratio to real time).
    Bench(bench::BenchArgs),
    /// The paper's analyses of every travel in a dataset: dq0 torque, its
    /// ripple PSD with labelled lines, accelerations and their Burg and STFT
    /// spectrograms with the model's modes.
    Analyze(analyze::AnalyzeArgs),
    /// Simulated free-decay tests (a mass on a rope with a fixed top, Eqn 9)
    /// written as recordings.
    Decay(decay::DecayArgs),
    /// The paper's identification on a dataset: EA (Eqn 9) and damping
    /// (Eqn 11-12) from free decays, sheave damping (Eqn 13) from travels.
    Identify(identify::IdentifyArgs),
    /// Lift ride quality after ISO 18738-1 (ISO 2631-1 Wk weighting) of a
    /// recording or an EVIMP1 export.
    RideQuality(ride_quality::RideQualityArgs),
    /// Processor in the loop: the plant here, the drive core in QEMU's
    /// emulated Cortex-M4F; checks every step against the host build and
    /// reports the instructions per control step.
    Pil(pil::PilArgs),
    /// The drive under faults: every fault kind at several instants of a
    /// travel, car up and down (or the faults given), with detection time,
    /// reason, peak current and acceleration, displacement after detection.
    Faults(faults::FaultsArgs),
    /// Every torque-ripple compensation strategy (and none) over the rig's
    /// travels and model mismatches: ride quality, car vibration at 12, 36
    /// and 72 x f_mech, peak current, learning time.
    Compare(compare::CompareArgs),
    /// Rig-like recordings made by the full plant: travels and free decays
    /// with effects of the library on and sensor noise.
    Dataset(dataset::DatasetArgs),
    /// The sim-to-real gap diagnosis of a dataset: calibration, where the
    /// gap lies, which effect of the library explains it (cross-validated),
    /// verdict; gap.json, gap.md and plots.
    Gap(gap::GapArgs),
    /// One request to a drive's service port over a serial line (the
    /// NUCLEO's virtual COM port): parameters, state, fault log.
    Drive(drive::DriveArgs),
}

/// Runs a parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    let rig = load_rig(cli.config.as_deref())?;
    match cli.command {
        Command::Modes(args) => modes::run(&rig, &args),
        Command::Travel(args) => travel::run(&rig, &args),
        Command::Analyze(args) => analyze::run(&rig, &args),
        Command::Bench(args) => bench::run(&rig, &args),
        Command::Decay(args) => decay::run(&rig, &args),
        Command::Identify(args) => identify::run(&rig, &args),
        Command::RideQuality(args) => ride_quality::run(&rig, &args),
        Command::Pil(args) => pil::run(&rig, &args),
        Command::Faults(args) => faults::run(&rig, &args),
        Command::Compare(args) => compare::run(&rig, &args),
        Command::Dataset(args) => dataset::run(&rig, &args),
        Command::Gap(args) => gap::run(&rig, &args),
        Command::Drive(args) => drive::run(&rig, &args),
    }
}

/// The rig from `path`, or the embedded default.
pub fn load_rig(path: Option<&Path>) -> anyhow::Result<RigConfig> {
    Ok(match path {
        Some(path) => RigConfig::load(path)?,
        None => RigConfig::embedded_default()?,
    })
}

/// The message of `error` and of its causes, joined by `: `, each cause
/// once: a cause whose text the message already holds (an I/O error that the
/// error's own text quotes) is not repeated.
pub fn error_message(error: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in error.chain() {
        let cause = cause.to_string();
        if text.contains(&cause) {
            continue;
        }
        // A cause that repeats the context it is given in (`recording `x``
        // then `recording `x`: ...`) replaces it.
        if !text.is_empty() && cause.starts_with(text.as_str()) {
            text = cause;
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&cause);
    }
    text
}

/// Largest number of points of a sweep on the command line (e.g. `modes`'s
/// rope lengths): far beyond a useful plot or table, far below what would
/// exhaust memory or disk (`modes` writes about 600 bytes a point).
pub const MAX_SWEEP_POINTS: usize = 100_000;

/// Number of points of the sweep `from..=to` by `step` (all checked finite,
/// `step > 0`, `to >= from`), refused before anything is allocated when it
/// exceeds [`MAX_SWEEP_POINTS`], naming `step_flag` and the smallest step
/// accepted.
pub fn sweep_points(step_flag: &str, from: f64, to: f64, step: f64) -> anyhow::Result<usize> {
    let points = ((to - from) / step + 1e-9).floor() + 1.0;
    if points.is_finite() && points >= 1.0 && points <= MAX_SWEEP_POINTS as f64 {
        Ok(points as usize)
    } else {
        let smallest = (to - from) / (MAX_SWEEP_POINTS - 1) as f64;
        anyhow::bail!(
            "{step_flag} = {} gives {} points from {} to {}; expected at most {MAX_SWEEP_POINTS} points: a step of \
             at least {smallest:.3e}",
            readable(step),
            readable(points.round()),
            readable(from),
            readable(to)
        )
    }
}

/// Checks a command-line value against its physical range: finite and
/// inside `[lo, hi]`, the message saying why (`why`) with the unit.
pub fn check_physical_range(flag: &str, value: f64, lo: f64, hi: f64, unit: &str, why: &str) -> anyhow::Result<()> {
    if value.is_finite() && value >= lo && value <= hi {
        Ok(())
    } else {
        anyhow::bail!(
            "{flag} = {} is out of range: expected a finite value in [{}, {}] {unit}: {why}",
            readable(value),
            readable(lo),
            readable(hi)
        )
    }
}

/// Checks a command-line value: finite and inside `(lo, hi)` (exclusive).
pub fn check_open_range(flag: &str, value: f64, lo: f64, hi: f64) -> anyhow::Result<()> {
    if value.is_finite() && value > lo && value < hi {
        Ok(())
    } else {
        anyhow::bail!(
            "{flag} = {} is out of range: expected a finite value in ({}, {})",
            readable(value),
            readable(lo),
            readable(hi)
        )
    }
}

/// The samples of column `name` of the recording `stem`, or an error naming both.
pub fn column<'a>(recording: &'a Recording, name: &str, stem: &str) -> anyhow::Result<&'a [f64]> {
    recording
        .column(name)
        .map(|c| c.values.as_slice())
        .with_context(|| format!("recording `{stem}`: column `{name}` missing"))
}

/// Creates the output directory.
pub fn create_out_dir(dir: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create the output directory {}", dir.display()))
}

/// The output directory `dir` of a command, its files staged under
/// temporary names ([`OutputDir`](crate::output::OutputDir)); `force`
/// is the command's `--force`.
pub fn output_dir(dir: &Path, force: bool) -> anyhow::Result<crate::output::OutputDir> {
    Ok(crate::output::OutputDir::create(dir, force)?)
}

/// [`output_dir`] for a command that reads `inputs` (datasets or
/// recordings): refused when the output directory is one of them or lies
/// inside one, `--force` or not.
pub fn output_dir_reading(dir: &Path, force: bool, inputs: &[&Path]) -> anyhow::Result<crate::output::OutputDir> {
    crate::output::refuse_inside_inputs(dir, inputs)?;
    output_dir(dir, force)
}

/// Reads the dataset `dir` ([`recording::read_dataset`]: the format and each
/// recording against itself) and checks each travel's metadata against the
/// distance its shaft turned on `rig`'s sheave
/// ([`recording::consistency::check_travel_distance`]).
pub fn read_dataset_on(rig: &RigConfig, dir: &Path) -> anyhow::Result<Vec<(String, Recording)>> {
    let dataset = recording::read_dataset(dir, rig.mechanics.rope_total_length_m)?;
    let limits = slew_limits(rig);
    for (stem, recording) in &dataset {
        let toml_path = dir.join(format!("{stem}.toml"));
        recording::consistency::check_travel_distance(recording, &toml_path, rig.mechanics.sheave_radius_m)?;
        recording::consistency::check_slew(recording, &toml_path.with_extension("csv"), &limits)?;
        recording::consistency::check_pole_pairs(recording, &toml_path.with_extension("csv"), rig.motor.pole_pairs)?;
    }
    Ok(dataset)
}

/// How fast `rig`'s recorded signals can change
/// ([`recording::consistency::SlewLimits`]): a phase current by the whole
/// bus plus the back-EMF at twice the rated speed across the smallest
/// winding inductance, with an ADC quantum plus 2 % of the current range
/// as slack; the shaft by the largest measurable current's torque plus
/// twice the ropes' static pull on the machine and sheave inertia, with one
/// encoder line per sample period of a 1 kHz estimator as slack.
pub fn slew_limits(rig: &RigConfig) -> recording::consistency::SlewLimits {
    let (m, motor, inv) = (&rig.mechanics, &rig.motor, &rig.inverter);
    let heaviest = m.m_car_kg.iter().copied().fold(m.m_cw_kg, f64::max);
    let omega_max = 2.0 * rig.travel.rated_speed_mps / m.sheave_radius_m;
    let emf_v = f64::from(motor.pole_pairs) * motor.flux_linkage_wb * omega_max;
    let full_scale = inv.current_sense_full_scale_a;
    let rope_torque = 2.0 * m.gravity_mps2 * (heaviest + m.m_cw_kg) * m.sheave_radius_m;
    recording::consistency::SlewLimits {
        current_a_per_s: (inv.dc_bus_v + emf_v) / motor.ld_h.min(motor.lq_h),
        current_slack_a: 2.0 * full_scale / f64::from(1u32 << inv.adc_bits.min(24)) + 0.02 * full_scale,
        shaft_rad_per_s2: (motor.torque_constant_nm_per_a() * full_scale + rope_torque) / m.sheave_inertia_kg_m2,
        speed_slack_radps: std::f64::consts::TAU / f64::from(inv.encoder_counts_per_rev.max(1)) * 1000.0,
    }
}

/// Checks a count on the command line: inside `[lo, hi]`.
pub fn check_count(flag: &str, value: usize, lo: usize, hi: usize) -> anyhow::Result<()> {
    if (lo..=hi).contains(&value) {
        Ok(())
    } else {
        anyhow::bail!("{flag} = {value} is out of range: expected a whole number in [{lo}, {hi}]")
    }
}

/// A ripple-compensation strategy on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum StrategyArg {
    /// None.
    Off,
    /// Strategy 1: offline harmonic table.
    Table,
    /// Strategy 2: adaptive harmonics during the travel.
    Adaptive,
    /// Strategy 3: iterative learning across travels.
    Learning,
    /// Strategy 4: adaptive harmonics driven by the observer's car acceleration.
    CarObserver,
}

impl StrategyArg {
    /// The strategy.
    pub fn strategy(self) -> drive_core::ripple::Strategy {
        use drive_core::ripple::Strategy;
        match self {
            StrategyArg::Off => Strategy::Off,
            StrategyArg::Table => Strategy::Table,
            StrategyArg::Adaptive => Strategy::Adaptive,
            StrategyArg::Learning => Strategy::Learning,
            StrategyArg::CarObserver => Strategy::CarObserver,
        }
    }
}

/// The default car mass of `rig`: the heaviest car of `[mechanics].m_car_kg`
/// (a list the rig's check keeps non-empty).
pub fn default_car_mass_kg(rig: &RigConfig) -> f64 {
    rig.mechanics.m_car_kg.iter().copied().fold(f64::NEG_INFINITY, f64::max)
}

/// Lightest car a simulation takes, kg: lighter, the car on its rope rings
/// so fast (`sqrt(2EA / (l m))`) that the integrator's step shrinks without
/// end; no lift car weighs less.
pub const MIN_CAR_MASS_KG: f64 = 1.0;
/// Heaviest car a simulation takes, kg (the rig file's bound, and the
/// recording format's).
pub const MAX_CAR_MASS_KG: f64 = 1.0e5;

/// The car mass of a run: `--m-car` when given, else the rig's heaviest car
/// ([`default_car_mass_kg`]); either checked against
/// `[MIN_CAR_MASS_KG, MAX_CAR_MASS_KG]`, the error naming where the
/// value came from (the flag, or the rig's field).
pub fn car_mass_kg(rig: &RigConfig, given: Option<f64>) -> anyhow::Result<f64> {
    let (m, source) = match given {
        Some(m) => (m, "--m-car".to_string()),
        None => (
            default_car_mass_kg(rig),
            "the rig's heaviest car ([mechanics].m_car_kg of --config, the default of --m-car)".to_string(),
        ),
    };
    if m.is_finite() && (MIN_CAR_MASS_KG..=MAX_CAR_MASS_KG).contains(&m) {
        Ok(m)
    } else {
        anyhow::bail!(
            "{source} = {} is out of range: expected a car mass of at least {} kg and at most {} kg",
            readable(m),
            readable(MIN_CAR_MASS_KG),
            readable(MAX_CAR_MASS_KG)
        )
    }
}

/// A number as a reader wants it in a message (never 300 zeros): the
/// reader's own, so that every error writes numbers alike.
pub use recording::read::readable;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_in_messages_are_readable() {
        assert_eq!(readable(0.15), "0.15");
        assert_eq!(readable(100000.0), "100000");
        assert_eq!(readable(-1e-300), "-1e-300");
        assert_eq!(readable(1e300), "1e300");
        let e = check_open_range("--acc-noise", 200.0, -1e-300, 100.0).unwrap_err().to_string();
        assert_eq!(e, "--acc-noise = 200 is out of range: expected a finite value in (-1e-300, 100)");
    }

    #[test]
    fn the_default_car_is_the_rigs_heaviest_and_its_errors_name_the_field() {
        let mut rig = RigConfig::embedded_default().unwrap();
        rig.mechanics.m_car_kg = vec![20.0];
        // Not the counterweight's 33 kg.
        assert_eq!(car_mass_kg(&rig, None).unwrap(), 20.0);
        rig.mechanics.m_car_kg = vec![2.0e5];
        let e = car_mass_kg(&rig, None).unwrap_err().to_string();
        assert!(e.contains("[mechanics].m_car_kg") && !e.starts_with("--m-car"), "{e}");
        let e = car_mass_kg(&rig, Some(1e-9)).unwrap_err().to_string();
        assert!(e.starts_with("--m-car = 1e-9 is out of range"), "{e}");
    }

    #[test]
    fn an_os_error_quoted_by_its_context_is_printed_once() {
        let os = std::io::Error::new(std::io::ErrorKind::NotFound, "No such file or directory (os error 2)");
        let config = rig_config::ConfigError::Io { path: "/x.toml".into(), source: os };
        let message = error_message(&anyhow::Error::new(config));
        assert_eq!(message, "/x.toml: cannot read: No such file or directory (os error 2)");
        // A cause the message does not quote is kept.
        let e = anyhow::Error::new(std::io::Error::other("disk full")).context("writing out/a.csv");
        assert_eq!(error_message(&e), "writing out/a.csv: disk full");
        let e = anyhow::anyhow!("recording `x`: no stage").context("recording `x`");
        assert_eq!(error_message(&e), "recording `x`: no stage");
    }

    #[test]
    fn an_absurd_sweep_is_refused_before_allocation() {
        assert_eq!(sweep_points("--lw-step", 0.1, 8.5, 0.05).unwrap(), 169);
        let err = sweep_points("--lw-step", 0.1, 8.5, 1e-9).unwrap_err().to_string();
        assert!(err.contains("--lw-step") && err.contains("100000") && err.contains("8.400e-5"), "{err}");
        assert!(sweep_points("--lw-step", 0.1, 8.5, 1e-300).is_err());
    }
}
