//! `host-sim dataset --out DIR`: "rig" recordings made by the full plant
//! (effects of the library on, sensor noise), for the gap diagnosis; with
//! `--drive commercial` and/or `--acquisition foreign` (or
//! `--foreign-seed N`) recorded as a foreign rig would record them.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, ValueEnum};
use rand::SeedableRng;

use super::output_dir;
use closed_loop::foreign::{Acquisition, ForeignDrive, ForeignRig};
use closed_loop::synthetic::{dataset_stems, make_dataset, make_foreign_dataset, DatasetSpec};
use plant::effects::Effects;
use recording::write_recording;
use rig_config::RigConfig;

/// Default RMS accelerometer noise of the project's acquisition, m/s^2.
const DEFAULT_ACC_NOISE_MPS2: f64 = 0.01;
/// Default RMS current-probe noise of the project's acquisition, A.
const DEFAULT_CURRENT_NOISE_A: f64 = 0.02;

/// Which drive runs the rig.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum DriveArg {
    /// The project's drive core (`drive_core::Controller`).
    Project,
    /// A generic commercial drive (`host_sim::foreign::commercial_drive`).
    Commercial,
}

/// Which data acquisition records the rig.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum AcquisitionArg {
    /// The project's: exact samples at the sample rate, white noise.
    Project,
    /// A foreign one: high-passed accelerometers, anti-alias filter, its own
    /// clock, noise, current quantisation, pre-trigger.
    Foreign,
}

/// The parameters of the foreign rig's parts, for `--help`.
fn foreign_help() -> String {
    format!(
        "Foreign rigs: --drive commercial and --acquisition foreign replace the project's drive and data \
         acquisition; --drive-param / --daq-param set one parameter each (and select that part); \
         --foreign-seed N draws every parameter of both parts at random within its range, --foreign-file FILE \
         reads them ([drive] and [acquisition] tables of name = value, as dataset prints them); the flags then \
         override single values. --sample-rate, --acc-noise and --current-noise act on the acquisition in use. \
         With the dead_time or current_sensor_error effect the commercial drive needs rotor_start_angle_deg=0 \
         (those effects belong to the simulated machine's own phases).\n\n\
         Commercial drive parameters (--drive-param NAME=VALUE), default (range unit): what\n{}\n\n\
         Foreign acquisition parameters (--daq-param NAME=VALUE), default (range unit): what\n{}",
        ForeignDrive::help(),
        Acquisition::help()
    )
}

/// Arguments of `dataset`.
#[derive(Debug, Args)]
#[command(after_long_help = foreign_help())]
pub struct DatasetArgs {
    /// Effects of the full plant from a TOML file (`[name] param = value`).
    #[arg(long = "effects", value_name = "FILE")]
    pub effects_file: Option<PathBuf>,
    /// An effect, `name` or `name:param=value,...` (repeatable).
    #[arg(long = "effect", value_name = "EFFECT")]
    pub effect: Vec<String>,
    /// Car masses, kg (default: the rig's four); one travel up and one down each.
    #[arg(long = "mass", value_name = "KG", value_delimiter = ',', allow_negative_numbers = true)]
    pub masses_kg: Vec<f64>,
    /// Sample rate, Hz (default: the rig's, or the foreign acquisition's).
    #[arg(long, value_name = "HZ", allow_negative_numbers = true)]
    pub sample_rate: Option<f64>,
    /// RMS accelerometer noise, m/s^2 (default: 0.01, or the foreign acquisition's).
    #[arg(long, value_name = "MPS2", allow_negative_numbers = true)]
    pub acc_noise: Option<f64>,
    /// RMS current-probe noise, A (default: 0.02, or the foreign acquisition's).
    #[arg(long, value_name = "A", allow_negative_numbers = true)]
    pub current_noise: Option<f64>,
    /// Seed of the noise.
    #[arg(long, default_value_t = 1, allow_negative_numbers = true)]
    pub seed: u64,
    /// The drive: the project's drive core or a commercial drive (default:
    /// project, commercial with --drive-param or --foreign-seed).
    #[arg(long, value_enum, value_name = "DRIVE")]
    pub drive: Option<DriveArg>,
    /// A commercial-drive parameter, `name=value` (repeatable; list below with units and ranges).
    #[arg(long = "drive-param", value_name = "NAME=VALUE")]
    pub drive_params: Vec<String>,
    /// The data acquisition: the project's or a foreign one (default:
    /// project, foreign with --daq-param or --foreign-seed).
    #[arg(long, value_enum, value_name = "DAQ")]
    pub acquisition: Option<AcquisitionArg>,
    /// A foreign-acquisition parameter, `name=value` (repeatable; list below with units and ranges).
    #[arg(long = "daq-param", value_name = "NAME=VALUE")]
    pub daq_params: Vec<String>,
    /// Draws a foreign rig at random with this seed: the commercial drive's
    /// and the foreign acquisition's parameters within their ranges.
    #[arg(long = "foreign-seed", value_name = "N", conflicts_with = "foreign_file", allow_negative_numbers = true)]
    pub foreign_seed: Option<u64>,
    /// A foreign rig from a TOML file: `[drive]` and/or `[acquisition]`
    /// tables of `name = value` (what `dataset` prints for a foreign rig).
    #[arg(long = "foreign-file", value_name = "FILE")]
    pub foreign_file: Option<PathBuf>,
    /// Output directory (the dataset).
    #[arg(long, value_name = "DIR", default_value = "out/dataset")]
    pub out: PathBuf,
    /// Replace recordings of the same stem (default: refuse to overwrite).
    #[arg(long)]
    pub force: bool,
}

/// The foreign rig the flags describe (`None` when both parts are the project's).
fn foreign_rig(args: &DatasetArgs) -> anyhow::Result<Option<ForeignRig>> {
    let from_file = match &args.foreign_file {
        Some(path) => {
            let text = rig_config::read_text_file(path, rig_config::MAX_TEXT_FILE_BYTES)
                .with_context(|| format!("cannot read the foreign-rig file {}", path.display()))?;
            Some(ForeignRig::from_toml_str(&text, &path.display().to_string())?)
        }
        None => None,
    };
    let implied = |params: &[String], in_file: bool| args.foreign_seed.is_some() || !params.is_empty() || in_file;
    let commercial = match args.drive {
        Some(d) => d == DriveArg::Commercial,
        None => implied(&args.drive_params, from_file.is_some_and(|f| f.drive.is_some())),
    };
    let foreign_daq = match args.acquisition {
        Some(a) => a == AcquisitionArg::Foreign,
        None => implied(&args.daq_params, from_file.is_some_and(|f| f.acquisition.is_some())),
    };
    if !commercial && !args.drive_params.is_empty() {
        anyhow::bail!("--drive-param sets a parameter of the commercial drive: it cannot go with --drive project");
    }
    if !foreign_daq && !args.daq_params.is_empty() {
        anyhow::bail!(
            "--daq-param sets a parameter of the foreign acquisition: it cannot go with --acquisition project"
        );
    }
    if !commercial && !foreign_daq {
        return Ok(None);
    }
    let base = match (args.foreign_seed, from_file) {
        (Some(seed), _) => ForeignRig::random(&mut rand::rngs::StdRng::seed_from_u64(seed)),
        (None, Some(file)) => ForeignRig {
            drive: file.drive.or(Some(ForeignDrive::default())),
            acquisition: file.acquisition.or(Some(Acquisition::default())),
        },
        (None, None) => ForeignRig::commercial(),
    };
    let mut rig =
        ForeignRig { drive: base.drive.filter(|_| commercial), acquisition: base.acquisition.filter(|_| foreign_daq) };
    if let Some(drive) = rig.drive.as_mut() {
        drive.set_from(&args.drive_params)?;
    }
    if let Some(acq) = rig.acquisition.as_mut() {
        acq.set_from(&args.daq_params)?;
        let overrides = [
            ("sample_rate_hz", args.sample_rate),
            ("acc_noise_mps2", args.acc_noise),
            ("current_noise_a", args.current_noise),
        ];
        for (name, value) in overrides {
            if let Some(v) = value {
                acq.set(name, v)?;
            }
        }
    }
    Ok(Some(rig))
}

/// Runs `dataset`.
pub fn run(rig: &RigConfig, args: &DatasetArgs) -> anyhow::Result<()> {
    let mut spec = DatasetSpec::rig(rig);
    spec.effects = Effects::from_file_and_flags(args.effects_file.as_deref(), &args.effect)?;
    if !args.masses_kg.is_empty() {
        for &m in &args.masses_kg {
            super::check_open_range("--mass", m, 0.0, 1.0e4)?;
        }
        spec.m_car_kg = args.masses_kg.clone();
        spec.decay_masses_kg = args.masses_kg.clone();
    }
    let foreign = foreign_rig(args)?;
    let project_daq = foreign.is_none_or(|f| f.acquisition.is_none());
    if project_daq {
        if let Some(fs) = args.sample_rate {
            super::check_open_range("--sample-rate", fs, 500.0, 1.0e6)?;
            spec.sample_rate_hz = fs;
        }
        let acc_noise = args.acc_noise.unwrap_or(DEFAULT_ACC_NOISE_MPS2);
        let current_noise = args.current_noise.unwrap_or(DEFAULT_CURRENT_NOISE_A);
        super::check_open_range("--acc-noise", acc_noise, -1e-300, 100.0)?;
        super::check_open_range("--current-noise", current_noise, -1e-300, 100.0)?;
        spec.acc_noise_mps2 = acc_noise;
        spec.current_noise_a = current_noise;
    }
    spec.seed = args.seed;
    let out = output_dir(&args.out, args.force)?;
    out.refuse_existing(dataset_stems(&spec).iter().flat_map(|s| [format!("{s}.toml"), format!("{s}.csv")]))?;
    outln!(
        "simulating {} travels and {} decays with {}",
        2 * spec.m_car_kg.len(),
        spec.decay_masses_kg.len(),
        spec.effects.summary()
    );
    let recordings = match &foreign {
        None => make_dataset(rig, &spec)?,
        Some(foreign) => {
            outln!("foreign rig:\n{}", foreign.to_toml());
            make_foreign_dataset(rig, &spec, foreign)?
        }
    };
    for (stem, recording) in recordings {
        write_recording(out.staging(), &stem, &recording)?;
    }
    for path in out.commit()? {
        if path.extension().is_some_and(|e| e == "toml") {
            outln!("wrote {}", path.display());
        }
    }
    Ok(())
}
