//! `host-sim dataset --out DIR`: "rig" recordings made by the full plant
//! (effects of the library on, sensor noise), for the gap diagnosis.

use std::path::PathBuf;

use clap::Args;

use super::create_out_dir;
use crate::config::RigConfig;
use crate::plant::effects::Effects;
use crate::recording::write_recording;
use crate::synthetic::{make_dataset, DatasetSpec};

/// Arguments of `dataset`.
#[derive(Debug, Args)]
pub struct DatasetArgs {
    /// Effects of the full plant from a TOML file (`[name] param = value`).
    #[arg(long = "effects", value_name = "FILE")]
    pub effects_file: Option<PathBuf>,
    /// An effect, `name` or `name:param=value,...` (repeatable).
    #[arg(long = "effect", value_name = "EFFECT")]
    pub effect: Vec<String>,
    /// Car masses, kg (default: the rig's four); one travel up and one down each.
    #[arg(long = "mass", value_name = "KG", value_delimiter = ',')]
    pub masses_kg: Vec<f64>,
    /// Sample rate, Hz (default: the rig's).
    #[arg(long, value_name = "HZ")]
    pub sample_rate: Option<f64>,
    /// RMS accelerometer noise, m/s^2.
    #[arg(long, value_name = "MPS2", default_value_t = 0.01)]
    pub acc_noise: f64,
    /// RMS current-probe noise, A.
    #[arg(long, value_name = "A", default_value_t = 0.02)]
    pub current_noise: f64,
    /// Seed of the noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output directory (the dataset).
    #[arg(long, value_name = "DIR", default_value = "out/dataset")]
    pub out: PathBuf,
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
    if let Some(fs) = args.sample_rate {
        super::check_open_range("--sample-rate", fs, 500.0, 1.0e6)?;
        spec.sample_rate_hz = fs;
    }
    super::check_open_range("--acc-noise", args.acc_noise, -1e-300, 100.0)?;
    super::check_open_range("--current-noise", args.current_noise, -1e-300, 100.0)?;
    spec.acc_noise_mps2 = args.acc_noise;
    spec.current_noise_a = args.current_noise;
    spec.seed = args.seed;
    create_out_dir(&args.out)?;
    println!(
        "simulating {} travels and {} decays with {}",
        2 * spec.m_car_kg.len(),
        spec.decay_masses_kg.len(),
        spec.effects.summary()
    );
    for (stem, recording) in make_dataset(rig, &spec)? {
        let (toml, _) = write_recording(&args.out, &stem, &recording)?;
        println!("wrote {}", toml.display());
    }
    Ok(())
}
