//! `host-sim decay`: simulated free-decay tests (paper section 3.4, Eqn 9),
//! written as `free_decay` recordings in the measurement format.

use std::path::PathBuf;

use clap::Args;

use super::{check_count, check_open_range, check_physical_range, output_dir};
use plant::effects::Effects;
use plant::free_decay::{eqn9_first_frequency_hz, simulate_free_decay_with, FreeDecaySpec, MAX_ELEMENTS};
use recording::write::write_recording;
use recording::{Column, Recording, RecordingKind, RecordingMeta, ACC_CAR, TIME_S};
use rig_config::RigConfig;

/// Options of `decay`.
#[derive(Debug, Args)]
pub struct DecayArgs {
    /// Hanging masses, kg (one recording each; default: the rig's car masses).
    #[arg(long = "mass", value_name = "KG", value_delimiter = ',', allow_negative_numbers = true)]
    pub masses_kg: Vec<f64>,
    /// Rope lengths from the fixed end to the mass, m (one recording per mass and length).
    #[arg(
        long = "length",
        value_name = "M",
        value_delimiter = ',',
        default_value = "4.0",
        allow_negative_numbers = true
    )]
    pub lengths_m: Vec<f64>,
    /// Rope EA, N (default: the rig's).
    #[arg(long = "ea", value_name = "N", allow_negative_numbers = true)]
    pub rope_ea_n: Option<f64>,
    /// Damping on the mass, kg/s (default: the rig's car guide damping).
    #[arg(long = "damping", value_name = "KG_PER_S", allow_negative_numbers = true)]
    pub damping_kg_per_s: Option<f64>,
    /// Recording length, s.
    #[arg(long = "duration", value_name = "S", default_value_t = 3.0, allow_negative_numbers = true)]
    pub duration_s: f64,
    /// Rope elements of the discretised rope.
    #[arg(long, default_value_t = 40, allow_negative_numbers = true)]
    pub elements: usize,
    /// Output directory (the dataset).
    #[arg(long, value_name = "DIR", default_value = "out/decay")]
    pub out: PathBuf,
    /// Replace recordings of the same stem (default: refuse to overwrite).
    #[arg(long)]
    pub force: bool,
    /// Effects of the library, from a TOML file (`[name]` tables); of them
    /// a free decay has tension stiffening, the car frame mode and dry
    /// guide friction, the others are ignored.
    #[arg(long = "effects", value_name = "FILE")]
    pub effects_file: Option<PathBuf>,
    /// One effect, `NAME` or `NAME:param=value,...`; repeatable, applied
    /// after `--effects`.
    #[arg(long = "effect", value_name = "NAME[:PARAM=VALUE,...]")]
    pub effect: Vec<String>,
}

/// Runs `decay`.
pub fn run(rig: &RigConfig, args: &DecayArgs) -> anyhow::Result<()> {
    let m = &rig.mechanics;
    let masses = if args.masses_kg.is_empty() { m.m_car_kg.clone() } else { args.masses_kg.clone() };
    check_open_range("--duration", args.duration_s, 0.0, 600.0)?;
    check_count("--elements", args.elements, 1, MAX_ELEMENTS)?;
    for &mass in &masses {
        let why = "lighter than 1 kg, the mass rings on its rope so fast that the run never ends; no lift carries \
                   more than 100 t";
        check_physical_range("--mass", mass, 1.0, 1.0e5, "kg", why)?;
    }
    for &length in &args.lengths_m {
        let why = "a rope of 0.1 m (a shorter one rings too fast to simulate) to 1000 m";
        check_physical_range("--length", length, rig_config::MIN_ROPE_SIDE_M, 1.0e3, "m", why)?;
    }
    if let Some(ea) = args.rope_ea_n {
        check_physical_range("--ea", ea, 1.0e4, 1.0e9, "N", "from a thin synthetic cord to a thick steel rope")?;
    }
    if let Some(c) = args.damping_kg_per_s {
        check_open_range("--damping", c, -1e-300, 1.0e6)?;
    }
    let stems: Vec<String> =
        masses.iter().flat_map(|mass| args.lengths_m.iter().map(move |length| stem(*mass, *length))).collect();
    let out = output_dir(&args.out, args.force)?;
    out.refuse_existing(stems.iter().flat_map(|s| [format!("{s}.toml"), format!("{s}.csv")]))?;
    let requested = Effects::from_file_and_flags(args.effects_file.as_deref(), &args.effect)?;
    let effects = requested.for_free_decay();
    let ignored: Vec<&str> =
        requested.enabled().into_iter().filter(|k| effects.values(*k).is_none()).map(|k| k.name()).collect();
    if !ignored.is_empty() {
        outln!("effects a free decay does not have, ignored: {}", ignored.join(", "));
    }
    let fs = rig.measurement.sample_rate_hz;
    let mut lines = Vec::new();
    for &mass in &masses {
        for &length in &args.lengths_m {
            let spec = FreeDecaySpec {
                mass_kg: mass,
                rope_length_m: length,
                rope_ea_n: args.rope_ea_n.unwrap_or(m.rope_ea_n),
                rope_mass_per_length_kg_per_m: m.rope_mass_per_length_kg_per_m,
                damping_kg_per_s: args.damping_kg_per_s.unwrap_or(m.c_car_kg_per_s),
                initial_acceleration_mps2: 2.0,
                elements: args.elements,
            };
            let acc = simulate_free_decay_with(&spec, &effects, fs, args.duration_s)?;
            let time: Vec<f64> = (0..acc.len()).map(|i| i as f64 / fs).collect();
            let recording = Recording {
                meta: RecordingMeta {
                    kind: RecordingKind::FreeDecay { mass_kg: mass, rope_length_m: length },
                    sample_rate_hz: fs,
                    description: Some(format!(
                        "host-sim free decay: EA {} N, mu {} kg/m, damping {} kg/s, {} rope elements, {}",
                        spec.rope_ea_n,
                        spec.rope_mass_per_length_kg_per_m,
                        spec.damping_kg_per_s,
                        spec.elements,
                        effects.summary()
                    )),
                },
                columns: vec![Column::new(TIME_S, time), Column::new(ACC_CAR, acc)],
            };
            let (toml, _) = write_recording(out.staging(), &stem(mass, length), &recording)?;
            lines.push(format!(
                "{}: m = {mass} kg on l = {length} m, first natural frequency (Eqn 9) {:.3} Hz",
                out.published(&toml).display(),
                eqn9_first_frequency_hz(spec.rope_ea_n, spec.rope_mass_per_length_kg_per_m, length, mass)
            ));
        }
    }
    out.commit()?;
    for line in lines {
        outln!("{line}");
    }
    Ok(())
}

/// The stem of the recording of `mass_kg` on `length_m`.
fn stem(mass_kg: f64, length_m: f64) -> String {
    format!("decay_l{length_m}_m{mass_kg}")
}
