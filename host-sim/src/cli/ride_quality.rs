//! `host-sim ride-quality FILE`: lift ride quality after ISO 18738-1 of one
//! recording: the project's format (`<stem>.toml`, vertical = `acc_car_mps2`,
//! constant-speed region from `speed_radps`) or the text export of lift
//! ride-quality analyzers (`EVIMP1`, vertical = z; no speed signal, so the
//! whole run only).

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use serde::Serialize;

use super::output_dir;
use dsp::{constant_speed_stage, ride_quality, wk_weighting, RideQuality};
use plots::{line_plot, Series};
use recording::{read_evimp, read_recording, RecordingKind, ACC_CAR, SPEED};
use rig_config::RigConfig;

/// Options of `ride-quality`.
#[derive(Debug, Args)]
pub struct RideQualityArgs {
    /// A recording (`<stem>.toml`, with its `<stem>.csv` beside it) or an `EVIMP1` text export.
    pub file: PathBuf,
    /// Output directory.
    #[arg(long, value_name = "DIR", default_value = "out/ride-quality")]
    pub out: PathBuf,
    /// Replace the outputs of an earlier run (default: refuse to overwrite).
    #[arg(long)]
    pub force: bool,
}

/// Files `ride-quality` writes.
const OUTPUTS: [&str; 3] = ["ride_quality.json", "ride_quality.csv", "ride_quality_wk.png"];

#[derive(Debug, Serialize)]
struct RegionReport {
    region: &'static str,
    start_s: f64,
    end_s: f64,
    max_peak_to_peak_mg: f64,
    a95_peak_to_peak_mg: f64,
    peak_to_peak_count: usize,
    max_acceleration_mg: f64,
    max_deceleration_mg: f64,
    max_jerk_mps3: f64,
}

fn region_report(name: &'static str, q: &RideQuality, fs: f64) -> RegionReport {
    RegionReport {
        region: name,
        start_s: q.region.start as f64 / fs,
        end_s: q.region.end as f64 / fs,
        max_peak_to_peak_mg: q.max_peak_to_peak_mg,
        a95_peak_to_peak_mg: q.a95_peak_to_peak_mg,
        peak_to_peak_count: q.peak_to_peak_count,
        max_acceleration_mg: q.max_acceleration_mg,
        max_deceleration_mg: q.max_deceleration_mg,
        max_jerk_mps3: q.max_jerk_mps3,
    }
}

/// The start of the first line of `path` (at most 64 bytes, lossy UTF-8,
/// trimmed): `EVIMP1` for an EVIMP export.
fn first_line(path: &Path) -> anyhow::Result<String> {
    let file = std::fs::File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
    let mut head = Vec::new();
    file.take(64).read_to_end(&mut head).with_context(|| format!("cannot read {}", path.display()))?;
    let head = head.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(&head);
    let line = head.split(|&b| b == b'\n').next().unwrap_or_default();
    Ok(String::from_utf8_lossy(line).trim().to_string())
}

/// Runs `ride-quality`.
pub fn run(rig: &RigConfig, args: &RideQualityArgs) -> anyhow::Result<()> {
    let first = first_line(&args.file)?;
    let is_toml = args.file.extension().is_some_and(|e| e == "toml");
    let (vertical, fs, stage, source) = if first == "EVIMP1" {
        let e = read_evimp(&args.file)?;
        (e.z_mps2(), e.sample_rate_hz, None, "EVIMP1 export (z axis)")
    } else if is_toml {
        let recording = read_recording(&args.file, rig.mechanics.rope_total_length_m)?;
        let fs = recording.meta.sample_rate_hz;
        let acc = recording.column(ACC_CAR).map(|c| c.values.clone()).context("no acc_car_mps2 column")?;
        let stage = match (&recording.meta.kind, recording.column(SPEED)) {
            (RecordingKind::Travel { .. }, Some(speed)) => match constant_speed_stage(&speed.values, fs) {
                Ok(stage) => Some(stage),
                Err(e) => {
                    eprintln!("note: no constant-speed region, the whole run only: {e}");
                    None
                }
            },
            _ => None,
        };
        (acc, fs, stage, "measurement format (acc_car_mps2)")
    } else {
        let sibling = args.file.with_extension("toml");
        let hint = if args.file.extension().is_some_and(|e| e == "csv") && sibling.is_file() {
            format!(" (it is the samples file of a recording: give its metadata file `{}`)", sibling.display())
        } else {
            String::new()
        };
        anyhow::bail!(
            "`{}` is neither an `EVIMP1` export (its first line is {first:?}, not `EVIMP1`) nor a recording of the \
             measurement format{hint}; expected an EVIMP1 text export or the `<stem>.toml` of a recording, with its \
             `<stem>.csv` beside it",
            args.file.display()
        );
    };
    let out = output_dir(&args.out, args.force)?;
    out.refuse_existing(OUTPUTS)?;
    let report = ride_quality(&vertical, fs, stage)
        .with_context(|| format!("`{}`: ride quality (ISO 18738-1)", args.file.display()))?;
    let mut regions = vec![region_report("whole run", &report.whole_run, fs)];
    if let Some(q) = &report.constant_speed {
        regions.push(region_report("constant speed", q, fs));
    }
    #[derive(Serialize)]
    struct Out<'a> {
        file: String,
        source: &'a str,
        sample_rate_hz: f64,
        direction: String,
        regions: &'a [RegionReport],
    }
    let json_path = out.path(OUTPUTS[0]);
    let summary = Out {
        file: args.file.display().to_string(),
        source,
        sample_rate_hz: fs,
        direction: format!("{:?}", report.direction),
        regions: &regions,
    };
    std::fs::write(&json_path, serde_json::to_string_pretty(&summary)?)?;
    let csv_path = out.path(OUTPUTS[1]);
    let mut csv = std::io::BufWriter::new(std::fs::File::create(&csv_path)?);
    writeln!(csv, "region,start_s,end_s,max_peak_to_peak_mg,a95_peak_to_peak_mg,peak_to_peak_count,max_acceleration_mg,max_deceleration_mg,max_jerk_mps3")?;
    for r in &regions {
        writeln!(
            csv,
            "{},{},{},{},{},{},{},{},{}",
            r.region,
            r.start_s,
            r.end_s,
            r.max_peak_to_peak_mg,
            r.a95_peak_to_peak_mg,
            r.peak_to_peak_count,
            r.max_acceleration_mg,
            r.max_deceleration_mg,
            r.max_jerk_mps3
        )?;
    }
    csv.flush()?;
    let weighted: Vec<f64> = wk_weighting(&vertical, fs)?.iter().map(|a| a / dsp::ride_quality::MPS2_PER_MG).collect();
    let time: Vec<f64> = (0..weighted.len()).map(|i| i as f64 / fs).collect();
    let png = out.path(OUTPUTS[2]);
    line_plot(
        &png,
        "Vertical vibration, ISO 2631-1 Wk weighted",
        "time [s]",
        "acceleration [mg]",
        &[Series::new("Wk", time, weighted)],
    )?;

    let published: Vec<PathBuf> = out.commit()?;
    outln!("{} ({source}), {fs} Hz, direction {:?}", args.file.display(), report.direction);
    outln!(
        "{:<16} {:>10} {:>10} {:>10} {:>10} {:>10}",
        "region",
        "max p-p",
        "A95 p-p",
        "max acc",
        "max dec",
        "max jerk"
    );
    outln!("{:<16} {:>10} {:>10} {:>10} {:>10} {:>10}", "", "[mg]", "[mg]", "[mg]", "[mg]", "[m/s^3]");
    for r in &regions {
        outln!(
            "{:<16} {:>10.1} {:>10.1} {:>10.1} {:>10.1} {:>10.3}",
            r.region,
            r.max_peak_to_peak_mg,
            r.a95_peak_to_peak_mg,
            r.max_acceleration_mg,
            r.max_deceleration_mg,
            r.max_jerk_mps3
        );
    }
    outln!("wrote {}", published.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "));
    Ok(())
}
