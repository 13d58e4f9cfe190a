//! `host-sim identify DATASET`: the paper's identification on a dataset in
//! the measurement format: `EA` (Eqn 9) and the damping ratio (Eqn 11) with
//! the guide damping (Eqn 12) from every free decay, `EA` against rope
//! tension, and the sheave damping (Eqn 13) from every travel.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use serde::Serialize;

use super::{column, create_out_dir};
use crate::analysis::identify::identify_free_decay;
use crate::analysis::travel_signals::torque_balance;
use crate::config::RigConfig;
use crate::plots::{line_plot, Series};
use crate::recording::read::read_dataset;
use crate::recording::{Recording, RecordingKind, ACC_CAR};

/// Options of `identify`.
#[derive(Debug, Args)]
pub struct IdentifyArgs {
    /// The dataset directory (pairs `<stem>.toml` + `<stem>.csv`).
    pub dataset: PathBuf,
    /// Highest frequency searched for the first mode of a free decay, Hz.
    #[arg(long = "max-frequency", value_name = "HZ", default_value_t = 200.0)]
    pub max_frequency_hz: f64,
    /// Output directory.
    #[arg(long, value_name = "DIR", default_value = "out/identify")]
    pub out: PathBuf,
}

/// One free decay's result, with the recording it came from.
#[derive(Debug, Serialize)]
struct DecayResult {
    recording: String,
    mass_kg: f64,
    rope_length_m: f64,
    tension_n: f64,
    first_frequency_hz: f64,
    rope_ea_n: f64,
    damping_ratio: f64,
    guide_damping_kg_per_s: f64,
    cycles_used: usize,
}

/// One travel's result.
#[derive(Debug, Serialize)]
struct SheaveResult {
    recording: String,
    m_car_kg: f64,
    m_cw_kg: f64,
    mean_torque_nm: f64,
    mean_speed_radps: f64,
    out_of_balance_torque_nm: f64,
    sheave_damping_nms_per_rad: f64,
}

/// Everything `identify` found.
#[derive(Debug, Serialize)]
struct Report {
    dataset: String,
    free_decays: Vec<DecayResult>,
    mean_rope_ea_n: Option<f64>,
    mean_damping_ratio: Option<f64>,
    mean_guide_damping_kg_per_s: Option<f64>,
    travels: Vec<SheaveResult>,
    mean_sheave_damping_nms_per_rad: Option<f64>,
    skipped: Vec<String>,
}

fn mean(values: impl Iterator<Item = f64>) -> Option<f64> {
    let v: Vec<f64> = values.collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// Runs `identify`.
pub fn run(rig: &RigConfig, args: &IdentifyArgs) -> anyhow::Result<()> {
    let m = &rig.mechanics;
    let dataset = read_dataset(&args.dataset, m.rope_total_length_m)?;
    create_out_dir(&args.out)?;
    let mut report = Report {
        dataset: args.dataset.display().to_string(),
        free_decays: Vec::new(),
        mean_rope_ea_n: None,
        mean_damping_ratio: None,
        mean_guide_damping_kg_per_s: None,
        travels: Vec::new(),
        mean_sheave_damping_nms_per_rad: None,
        skipped: Vec::new(),
    };
    for (stem, recording) in &dataset {
        let fs = recording.meta.sample_rate_hz;
        match recording.meta.kind {
            RecordingKind::FreeDecay { mass_kg, rope_length_m } => {
                let acc = column(recording, ACC_CAR, stem)?;
                match identify_free_decay(
                    acc,
                    fs,
                    mass_kg,
                    rope_length_m,
                    m.rope_mass_per_length_kg_per_m,
                    m.gravity_mps2,
                    args.max_frequency_hz,
                ) {
                    Ok(id) => report.free_decays.push(DecayResult {
                        recording: stem.clone(),
                        mass_kg,
                        rope_length_m,
                        tension_n: id.tension_n,
                        first_frequency_hz: id.first_frequency_hz,
                        rope_ea_n: id.rope_ea_n,
                        damping_ratio: id.damping_ratio,
                        guide_damping_kg_per_s: id.damping_kg_per_s,
                        cycles_used: id.cycles_used,
                    }),
                    Err(e) => report.skipped.push(format!("{stem}: {e}")),
                }
            }
            RecordingKind::Travel { .. } => {}
        }
    }
    // Travels after the free decays, so that their guide damping is used.
    let identified_guides = mean(report.free_decays.iter().map(|d| d.guide_damping_kg_per_s));
    for (stem, recording) in &dataset {
        if let RecordingKind::Travel { .. } = recording.meta.kind {
            match sheave_damping(rig, stem, recording, identified_guides) {
                Ok(result) => report.travels.push(result),
                Err(e) => report.skipped.push(format!("{stem}: {e:#}")),
            }
        }
    }
    report.mean_rope_ea_n = mean(report.free_decays.iter().map(|d| d.rope_ea_n));
    report.mean_damping_ratio = mean(report.free_decays.iter().map(|d| d.damping_ratio));
    report.mean_guide_damping_kg_per_s = mean(report.free_decays.iter().map(|d| d.guide_damping_kg_per_s));
    report.mean_sheave_damping_nms_per_rad = mean(report.travels.iter().map(|t| t.sheave_damping_nms_per_rad));

    let json = args.out.join("identify.json");
    std::fs::write(&json, serde_json::to_string_pretty(&report)?)
        .with_context(|| format!("cannot write {}", json.display()))?;
    let csv_path = args.out.join("free_decays.csv");
    let mut csv = std::io::BufWriter::new(std::fs::File::create(&csv_path)?);
    writeln!(
        csv,
        "recording,mass_kg,rope_length_m,tension_n,first_frequency_hz,rope_ea_n,damping_ratio,guide_damping_kg_per_s"
    )?;
    for d in &report.free_decays {
        writeln!(
            csv,
            "{},{},{},{},{},{},{},{}",
            d.recording,
            d.mass_kg,
            d.rope_length_m,
            d.tension_n,
            d.first_frequency_hz,
            d.rope_ea_n,
            d.damping_ratio,
            d.guide_damping_kg_per_s
        )?;
    }
    csv.flush()?;
    if report.free_decays.len() >= 2 {
        let mut points: Vec<(f64, f64)> = report.free_decays.iter().map(|d| (d.tension_n, d.rope_ea_n)).collect();
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (x, y) = points.into_iter().unzip();
        line_plot(
            &args.out.join("ea_vs_tension.png"),
            "Rope EA from free decays (Eqn 9) against rope tension",
            "tension m g [N]",
            "EA [N]",
            &[Series::new("EA", x, y)],
        )?;
    }

    println!(
        "{:<28} {:>8} {:>6} {:>9} {:>12} {:>8} {:>10}",
        "free decay", "m [kg]", "l [m]", "f1 [Hz]", "EA [N]", "zeta", "c [kg/s]"
    );
    for d in &report.free_decays {
        println!(
            "{:<28} {:>8.1} {:>6.2} {:>9.3} {:>12.4e} {:>8.4} {:>10.1}",
            d.recording,
            d.mass_kg,
            d.rope_length_m,
            d.first_frequency_hz,
            d.rope_ea_n,
            d.damping_ratio,
            d.guide_damping_kg_per_s
        );
    }
    for t in &report.travels {
        println!("{:<28} c_sheave = {:.3} N m s/rad (Eqn 13)", t.recording, t.sheave_damping_nms_per_rad);
    }
    for s in &report.skipped {
        println!("skipped: {s}");
    }
    println!("wrote {}, {}", json.display(), csv_path.display());
    Ok(())
}

/// Eqn 13 on one travel recording ([`torque_balance`]), less the guide
/// damping (the rig's `c_cw + c_car`, or twice the identified guide damping
/// when free decays gave one).
fn sheave_damping(
    rig: &RigConfig,
    stem: &str,
    recording: &Recording,
    identified_guide_damping: Option<f64>,
) -> anyhow::Result<SheaveResult> {
    let RecordingKind::Travel { m_car_kg, m_cw_kg, .. } = recording.meta.kind else {
        anyhow::bail!("not a travel");
    };
    let m = &rig.mechanics;
    let guides = identified_guide_damping.map_or(m.c_cw_kg_per_s + m.c_car_kg_per_s, |c| 2.0 * c);
    let b = torque_balance(rig, recording, stem, guides)?;
    Ok(SheaveResult {
        recording: stem.to_string(),
        m_car_kg,
        m_cw_kg,
        mean_torque_nm: b.mean_torque_nm,
        mean_speed_radps: b.mean_speed_radps,
        out_of_balance_torque_nm: b.out_of_balance_torque_nm,
        sheave_damping_nms_per_rad: b.sheave_damping_nms_per_rad,
    })
}
