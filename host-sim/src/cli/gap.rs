//! `host-sim gap DATASET --out DIR`: the sim-to-real gap diagnosis.

use std::path::PathBuf;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use diagnosis::{diagnose, report::write_report, GapOptions};
use dsp::stft_spectrogram;
use plant::effects::EffectKind;
use plots::spectrogram_plot;
use rig_config::RigConfig;

/// Arguments of `gap`.
#[derive(Debug, Args)]
pub struct GapArgs {
    /// The dataset: a directory of recordings in the measurement format.
    pub dataset: PathBuf,
    /// The rig's drive: `auto` decides from the torque at standstill,
    /// `project` (this project's drive core: closed loop, every channel) or
    /// `foreign` (another drive: the mechanics driven by the measured torque).
    #[arg(long, value_enum, default_value = "auto")]
    pub drive: DriveArg,
    /// Output directory for gap.json, gap.md, CSV tables and plots.
    #[arg(long, value_name = "DIR", default_value = "out/gap")]
    pub out: PathBuf,
    /// Replace the report of an earlier run (default: refuse to overwrite).
    #[arg(long)]
    pub force: bool,
    /// Effects to try, comma separated (default: the whole library).
    #[arg(long = "effects", value_name = "NAMES", value_delimiter = ',')]
    pub effects: Vec<String>,
    /// Largest mean excess gap (dB) of the calibrated nominal model still
    /// called `nominal`.
    #[arg(long, value_name = "DB", default_value_t = diagnosis::NOMINAL_EXCESS_DB, allow_negative_numbers = true)]
    pub nominal_excess_db: f64,
    /// Largest RMS (dB) by which one cell (channel, phase, band or line)
    /// may lie beyond noise and tolerance in most recordings and the
    /// verdict still be `nominal`.
    #[arg(long, value_name = "DB", default_value_t = diagnosis::PERSISTENT_CELL_DB, allow_negative_numbers = true)]
    pub persistent_cell_db: f64,
    /// Smallest held-out shrink of the gap (0-1) for `explained`.
    #[arg(long, value_name = "FRACTION", default_value_t = diagnosis::EXPLAINED_SHRINK, allow_negative_numbers = true)]
    pub explained_shrink: f64,
}

/// `--drive` values.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum DriveArg {
    /// Decide from the data.
    Auto,
    /// This project's drive core.
    Project,
    /// Another drive.
    Foreign,
}

impl From<DriveArg> for diagnosis::DriveAssumption {
    fn from(d: DriveArg) -> Self {
        match d {
            DriveArg::Auto => Self::Auto,
            DriveArg::Project => Self::Project,
            DriveArg::Foreign => Self::Foreign,
        }
    }
}

/// Runs `gap`.
pub fn run(rig: &RigConfig, args: &GapArgs) -> anyhow::Result<()> {
    super::check_open_range("--nominal-excess-db", args.nominal_excess_db, 0.0, 100.0)?;
    super::check_open_range("--persistent-cell-db", args.persistent_cell_db, 0.0, 100.0)?;
    super::check_open_range("--explained-shrink", args.explained_shrink, 0.0, 1.0)?;
    let effects = effects_of(args)?;
    let dataset = super::read_dataset_on(rig, &args.dataset)?;
    let out = super::output_dir_reading(&args.out, args.force, &[&args.dataset])?;
    out.refuse_existing(["gap.json", "gap.md"])?;
    let bar = ProgressBar::new(1);
    bar.set_style(
        ProgressStyle::with_template("{msg:24} [{elapsed_precise}] {wide_bar} {pos}/{len} runs")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let progress = |step: &str, done: usize, total: usize| {
        bar.set_message(step.to_string());
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    };
    let options = GapOptions {
        drive: args.drive.into(),
        effects,
        nominal_excess_db: args.nominal_excess_db,
        persistent_cell_db: args.persistent_cell_db,
        explained_shrink: args.explained_shrink,
    };
    let name = args.dataset.display().to_string();
    let report = diagnose(rig, &name, &dataset, &options, &progress)?;
    bar.finish_and_clear();
    let plots = car_acceleration_plots(&out, &report)?;
    write_report(out.staging(), &report, &plots)?;
    let written = out.commit()?;
    print_summary(&report);
    for p in written {
        outln!("wrote {}", p.display());
    }
    Ok(())
}

/// The effects `--effects` names (all of the library when none).
fn effects_of(args: &GapArgs) -> anyhow::Result<Vec<EffectKind>> {
    if args.effects.is_empty() {
        return Ok(EffectKind::ALL.to_vec());
    }
    args.effects
        .iter()
        .map(|n| {
            EffectKind::from_name(n.trim()).ok_or_else(|| {
                anyhow::anyhow!(
                    "--effects: unknown effect `{n}`; the library has: {}",
                    EffectKind::ALL.map(EffectKind::name).join(", ")
                )
            })
        })
        .collect()
}

/// Spectrograms of the car acceleration, data and models side by side,
/// for the recording with the largest nominal gap: (caption, file) each.
fn car_acceleration_plots(
    out: &crate::output::OutputDir,
    report: &diagnosis::GapReport,
) -> anyhow::Result<Vec<(String, String)>> {
    let mut plots = Vec::new();
    if let Some(views) = &report.car_acceleration_views {
        let stem = &views.recording;
        for (label, values) in &views.series {
            let spectrogram = stft_spectrogram(values, views.sample_rate_hz, 0.5, 0.75, 400.0)?;
            let file = format!("spectrogram_{}.png", label.replace(' ', "_"));
            spectrogram_plot(
                &out.path(&file),
                &format!("car acceleration, {stem}: {label} (dB re 1 (m/s^2)^2/Hz)"),
                &spectrogram,
                &[],
                None,
            )?;
            plots.push((format!("car acceleration spectrogram of `{stem}`, {label}"), file));
        }
    }
    Ok(plots)
}

/// The report's summary on standard output: verdict, location, drive,
/// notes, the first candidates.
fn print_summary(report: &diagnosis::GapReport) {
    outln!(
        "verdict: {:?}{}",
        report.verdict,
        report.explained_by.as_ref().map_or(String::new(), |e| format!(" by {e}"))
    );
    outln!(
        "nominal excess gap {:.2} dB (noise {:.2} dB); located in {:?}, {}, {}, {}",
        report.nominal_excess_db,
        report.noise_gap_db,
        report.location.subsystem,
        report.location.channel.name(),
        report.location.phase.name(),
        report.location.band
    );
    if let Some(p) = &report.persistent_cell {
        outln!("persistent cell: {}", diagnosis::report::persistent_text(p));
    }
    if let Some(e) = &report.electrical_lines {
        outln!("direct-axis lines: {}", diagnosis::report::electrical_lines_text(e));
    }
    outln!("drive: {:?}: {}", report.drive.drive, report.drive.reason);
    print_rig_speed_loops(report);
    print_notes_and_ranking(report);
}

/// Each recording's speed loop of the rig's drive and its shaft angle.
fn print_rig_speed_loops(report: &diagnosis::GapReport) {
    for l in &report.rig_speed_loops {
        match (&l.controller, &l.refused) {
            (Some(c), _) => outln!(
                "  {}: the rig drive's speed loop Kp {:.2} N m s/rad, Ki {:.1} N m/rad, estimate {:.1} ms late \
                 and {:.1} ms lag ({:.1} % of the torque's 4-40 Hz vibration)",
                l.recording,
                c.kp_nms_per_rad,
                c.ki_nm_per_rad,
                1e3 * c.estimate_delay_s,
                1e3 * c.estimate_lag_s,
                100.0 * c.dynamic_fit
            ),
            (None, reason) => {
                outln!(
                    "  {}: the rig drive's speed loop not identified: {}",
                    l.recording,
                    reason.as_deref().unwrap_or("-")
                )
            }
        }
        outln!("    shaft angle: {}", l.shaft_angle.text());
        outln!("    accelerometer high-pass: {}", l.accelerometer_highpass.text());
    }
}

/// The attribution's notes, the recordings left out and the first five
/// candidates with their held-out gaps.
fn print_notes_and_ranking(report: &diagnosis::GapReport) {
    if let Some(note) = &report.attribution_note {
        outln!("attribution: {note}");
    }
    for l in &report.left_out {
        outln!("left out: {}: {}", l.recording, l.reason);
    }
    if let Some(note) = report.begins_in_motion_note() {
        outln!("start: {note}");
    }
    if let Some(note) = report.once_per_revolution_note() {
        outln!("once per revolution: {note}");
    }
    if let Some(note) = report.no_effect_helps_note() {
        outln!("{note}");
    }
    for r in report.ranking.iter().filter_map(|c| c.refit.as_ref()) {
        outln!("{}", diagnosis::report::refit_text(r));
    }
    for c in report.ranking.iter().take(5) {
        outln!(
            "  {:<48} held-out {:.2} -> {:.2} dB ({:+.0} %){}",
            c.name,
            c.held_out_gap_before_db,
            c.held_out_gap_after_db,
            -100.0 * c.held_out_shrink,
            if c.naming.named { "" } else { " (not named)" }
        );
    }
    outln!("{} simulations in {:.1} s", report.simulations, report.runtime_s);
}
