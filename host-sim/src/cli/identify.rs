//! `host-sim identify DATASET`: the paper's identification on a dataset in
//! the measurement format: `EA` (Eqn 9) and the damping ratio (Eqn 11) with
//! the guide damping (Eqn 12) from every free decay, `EA` against rope
//! tension, and the sheave damping (Eqn 13) from every travel.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use serde::Serialize;

use super::identify_screen::{
    ea_disagreement, name_decay_files, screen_decays, EaEstimate, MaxFrequency, DEFAULT_MAX_FREQUENCY_HZ,
};
use diagnosis::identify::rope_ea_from_first_frequency;
use diagnosis::identify_dataset::{identify_dataset, DatasetIdentification, LeftOut};
use plots::{stacked_plot, Level, Mark, Panel, Series};
use recording::{Recording, RecordingKind};
use rig_config::RigConfig;

/// Options of `identify`.
#[derive(Debug, Args)]
pub struct IdentifyArgs {
    /// The dataset directory (pairs `<stem>.toml` + `<stem>.csv`).
    pub dataset: PathBuf,
    /// Highest frequency searched for the first mode of a free decay, Hz
    /// (default 200 Hz).
    #[arg(long = "max-frequency", value_name = "HZ", allow_negative_numbers = true)]
    pub max_frequency_hz: Option<f64>,
    /// Output directory.
    #[arg(long, value_name = "DIR", default_value = "out/identify")]
    pub out: PathBuf,
    /// Replace the outputs of an earlier run (default: refuse to overwrite).
    #[arg(long)]
    pub force: bool,
}

/// Files `identify` writes.
const OUTPUTS: [&str; 4] = ["identify.json", "free_decays.csv", "ea_vs_tension.png", "free_decays.png"];

/// Refuses a dataset of which a kind of recording gives nothing: every free
/// decay (or every travel) left out. The error lists each one's reason and,
/// when `--max-frequency` lies below the first mode that the rig's `EA`
/// predicts for a decay (Eqn 9), says so. `kinds` holds every recording
/// of the dataset, those left out before the identification too.
fn refuse_empty_results(
    rig: &RigConfig,
    dataset_dir: &Path,
    band: MaxFrequency,
    kinds: &[(String, RecordingKind)],
    id: &DatasetIdentification,
) -> anyhow::Result<()> {
    let m = &rig.mechanics;
    let reasons = |decays: bool| -> String {
        let of_kind =
            |stem: &str| kinds.iter().any(|(s, k)| s == stem && matches!(k, RecordingKind::FreeDecay { .. }) == decays);
        id.left_out
            .iter()
            .filter(|l| of_kind(&l.recording))
            .map(|l| format!("\n  {}: {}", l.recording, l.reason))
            .collect()
    };
    let decays: Vec<(&str, f64, f64)> = kinds
        .iter()
        .filter_map(|(stem, kind)| match *kind {
            RecordingKind::FreeDecay { mass_kg, rope_length_m } => Some((stem.as_str(), mass_kg, rope_length_m)),
            RecordingKind::Travel { .. } => None,
        })
        .collect();
    if !decays.is_empty() && id.decays.is_empty() {
        let predicted = decays
            .iter()
            .map(|&(stem, mass, length)| {
                let f1 = plant::free_decay::eqn9_first_frequency_hz(
                    m.rope_ea_n,
                    m.rope_mass_per_length_kg_per_m,
                    length,
                    mass,
                );
                (stem, f1)
            })
            .min_by(|a, b| a.1.total_cmp(&b.1));
        let hint = match predicted {
            Some((stem, f1)) if band.hz < f1 => format!(
                "\n{} lies below the first mode that the rig's EA ({:e} N) predicts \
                 (Eqn 9: {f1:.2} Hz for `{stem}`): expected a --max-frequency above the first mode",
                band.describe(),
                m.rope_ea_n
            ),
            _ => String::new(),
        };
        anyhow::bail!(
            "no free decay of `{}` gives EA (Eqn 9); every one was left out:{}{hint}",
            dataset_dir.display(),
            reasons(true)
        );
    }
    let travels = kinds.len() - decays.len();
    if travels > 0 && id.travels.is_empty() {
        anyhow::bail!(
            "no travel of `{}` gives the sheave damping (Eqn 13); every one was left out:{}",
            dataset_dir.display(),
            reasons(false)
        );
    }
    Ok(())
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
    /// Set when the decays' EA values disagree beyond their uncertainty:
    /// the mean is then no single EA of the rope.
    rope_ea_disagreement: Option<String>,
    mean_damping_ratio: Option<f64>,
    mean_guide_damping_kg_per_s: Option<f64>,
    travels: Vec<SheaveResult>,
    mean_sheave_damping_nms_per_rad: Option<f64>,
    left_out: Vec<LeftOut>,
}

/// Half-width of the band drawn around the rig's EA in `ea_vs_tension.png`,
/// as a fraction: the axis spans at least this much, so that scatter of a
/// few 0.01 % does not read as a trend.
const EA_BAND_FRACTION: f64 = 0.01;

/// The cycles of a free decay that the identification's decrement uses,
/// read again for the plots: the first mode isolated as the identification
/// isolates it (zero-phase high-pass at `f1 / 2` minus zero-phase
/// high-pass at `2 f1`), its positive half-cycles after the release, and
/// from the second after the largest on, `cycles_used` of them.
#[derive(Debug, Clone, PartialEq)]
struct DecayCycles {
    /// Time of each used cycle's peak, s (parabolic interpolation through
    /// the peak sample and its neighbours).
    peak_times_s: Vec<f64>,
}

impl DecayCycles {
    /// The cycles of `acceleration_mps2` (sampled at `fs` Hz) with the
    /// identified first mode `f1_hz` and `cycles_used`; `None` when the
    /// record holds fewer than two such cycles.
    fn find(acceleration_mps2: &[f64], fs: f64, f1_hz: f64, cycles_used: usize) -> Option<Self> {
        let release = diagnosis::identify::release_index(acceleration_mps2).ok()?;
        let half = dsp::highpass_zero_phase(acceleration_mps2, fs, 0.5 * f1_hz).ok()?;
        let double = dsp::highpass_zero_phase(&half, fs, (2.0 * f1_hz).min(0.45 * fs)).ok()?;
        let mode: Vec<f64> = half.iter().zip(&double).map(|(a, b)| a - b).collect();
        // Positive half-cycles after the release: (peak index, peak value).
        let mut peaks: Vec<(usize, f64)> = Vec::new();
        let mut current: Option<(usize, f64)> = None;
        for (i, &x) in mode.iter().enumerate().skip(release) {
            if x > 0.0 {
                current = Some(current.map_or((i, x), |c| if x > c.1 { (i, x) } else { c }));
            } else if let Some(c) = current.take() {
                peaks.push(c);
            }
        }
        let top = peaks.iter().enumerate().fold((0, 0.0), |b, (k, p)| if p.1 > b.1 { (k, p.1) } else { b }).0;
        let used: Vec<f64> = peaks
            .iter()
            .skip(top + 2)
            .take(cycles_used)
            .map(|&(i, _)| {
                let (a, b, c) = (mode[i - 1], mode[i], mode[(i + 1).min(mode.len() - 1)]);
                let curvature = a - 2.0 * b + c;
                let shift = if curvature < 0.0 { (0.5 * (a - c) / curvature).clamp(-0.5, 0.5) } else { 0.0 };
                (i as f64 + shift) / fs
            })
            .collect();
        (used.len() >= 2).then_some(Self { peak_times_s: used })
    }

    /// The frequency of each cycle, Hz: the inverse of the spacing of
    /// consecutive peaks (a decaying sinusoid's peaks are one damped period
    /// apart).
    fn frequencies_hz(&self) -> Vec<f64> {
        self.peak_times_s.windows(2).map(|w| 1.0 / (w[1] - w[0])).collect()
    }
}

/// Twice the standard error of the mean of `values` (the sample standard
/// deviation over `sqrt(n)`), `None` for fewer than two values.
fn two_standard_errors(values: &[f64]) -> Option<f64> {
    let n = values.len();
    if n < 2 {
        return None;
    }
    let mean = values.iter().sum::<f64>() / n as f64;
    let variance = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    Some(2.0 * (variance / n as f64).sqrt())
}

/// A free decay's point of `ea_vs_tension.png`: tension (N), EA (N), its
/// error bar's half-width (N, when the record holds two cycles or more) and
/// its label.
struct EaPoint {
    tension_n: f64,
    ea_n: f64,
    error_n: Option<f64>,
    label: String,
}

/// `ea_vs_tension.png`: each free decay's EA (Eqn 9) as a point labelled
/// with its recording, with an error bar of twice the standard error of
/// the EA of its single cycles (each cycle's frequency, from the spacing of
/// its peak to the next, through Eqn 9: the scatter the frequency estimate
/// carries); the rig's EA (`[mechanics].rope_ea_n`) as a line and +-1 %
/// around it (the axis spans at least that band).
fn ea_plot(path: &Path, dataset: &Path, points: &[EaPoint], rig_ea_n: f64) -> anyhow::Result<()> {
    let (lo, hi) =
        points.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.tension_n), b.max(p.tension_n)));
    // Room on the right for the last point's label.
    let span = (hi - lo).max(1.0);
    let (x0, x1) = (lo - 0.1 * span, hi + 0.4 * span);
    let level = |f: f64, label: String| Level { y: rig_ea_n * f, x0, x1, label };
    let panel = Panel {
        y_label: "EA [N]".to_string(),
        series: vec![Series::new("rig EA", vec![x0, x1], vec![rig_ea_n, rig_ea_n])],
        marks: points
            .iter()
            .map(|p| Mark {
                x: p.tension_n,
                y: p.ea_n,
                label: match p.error_n {
                    Some(e) if e.is_finite() => format!("{}: {:.5e} +- {e:.0} N", p.label, p.ea_n),
                    _ => p.label.clone(),
                },
                y_error: p.error_n,
            })
            .collect(),
        levels: vec![
            level(1.0 + EA_BAND_FRACTION, format!("rig EA + {:.0} %", 100.0 * EA_BAND_FRACTION)),
            level(
                1.0 - EA_BAND_FRACTION,
                format!("rig EA - {:.0} % (rig EA {rig_ea_n:.4e} N)", 100.0 * EA_BAND_FRACTION),
            ),
        ],
    };
    let title = format!(
        "{}: rope EA from free decays (Eqn 9) against tension, bars +-2 standard errors of the cycles' EA",
        dataset.display()
    );
    stacked_plot(path, &title, "tension m g [N]", &[panel], &[])?;
    Ok(())
}

/// Free decays drawn in `free_decays.png`, at most (one panel each).
const MAX_DECAY_PANELS: usize = 8;

/// `free_decays.png`: each identified free decay's car acceleration with the
/// envelope of its identification, `+-A exp(-zeta 2 pi f1 (t - t_A))`
/// (zeta and f1 as identified, Eqn 11; anchored at the largest magnitude
/// `A`, at `t_A`), from the largest magnitude on, and the window of the
/// cycles the decrement used ([`DecayCycles`]) marked as a dashed segment
/// at zero.
fn decays_plot(
    path: &Path,
    dataset_dir: &Path,
    dataset: &[(String, Recording)],
    id: &DatasetIdentification,
) -> anyhow::Result<()> {
    let mut panels = Vec::new();
    for (stem, d) in id.decays.iter().take(MAX_DECAY_PANELS) {
        let Some((_, rec)) = dataset.iter().find(|(s, _)| s == stem) else { continue };
        let Some(acc) = rec.column(recording::ACC_CAR) else { continue };
        let fs = rec.meta.sample_rate_hz;
        let time: Vec<f64> = (0..acc.values.len()).map(|i| i as f64 / fs).collect();
        let (k, peak) =
            acc.values.iter().enumerate().fold((0, 0.0_f64), |m, (i, v)| if v.abs() > m.1 { (i, v.abs()) } else { m });
        let rate = d.damping_ratio * std::f64::consts::TAU * d.first_frequency_hz;
        let envelope = |sign: f64| -> Vec<f64> {
            time.iter()
                .map(|&t| if t >= time[k] { sign * peak * (-rate * (t - time[k])).exp() } else { f64::NAN })
                .collect()
        };
        let window = DecayCycles::find(&acc.values, fs, d.first_frequency_hz, d.cycles_used).map(|c| {
            let (t0, t1) = (c.peak_times_s[0], c.peak_times_s[c.peak_times_s.len() - 1]);
            Level { y: 0.0, x0: t0, x1: t1, label: format!("{} cycles used ({t0:.2}-{t1:.2} s)", d.cycles_used) }
        });
        panels.push(Panel {
            y_label: format!("{stem} [m/s^2]"),
            series: vec![
                Series::new("car acceleration", time.clone(), acc.values.clone()),
                Series::new(
                    format!("envelope: f1 {:.3} Hz, zeta {:.4}", d.first_frequency_hz, d.damping_ratio),
                    time.clone(),
                    envelope(1.0),
                ),
                Series::new("envelope (lower)", time.clone(), envelope(-1.0)),
            ],
            levels: window.into_iter().collect(),
            ..Panel::default()
        });
    }
    if panels.is_empty() {
        return Ok(());
    }
    let title =
        format!("{}: free decays with the envelope of their identified damping (Eqn 11)", dataset_dir.display());
    stacked_plot(path, &title, "time [s]", &panels, &[])?;
    Ok(())
}

/// Runs `identify`: the decays screened ([`screen_decays`]), the dataset
/// identified, the results written and printed.
pub fn run(rig: &RigConfig, args: &IdentifyArgs) -> anyhow::Result<()> {
    let band = MaxFrequency {
        hz: args.max_frequency_hz.unwrap_or(DEFAULT_MAX_FREQUENCY_HZ),
        given: args.max_frequency_hz.is_some(),
    };
    super::check_open_range("--max-frequency", band.hz, 1.0, 1.0e6)?;
    let dataset = super::read_dataset_on(rig, &args.dataset)?;
    let out = super::output_dir_reading(&args.out, args.force, &[&args.dataset])?;
    out.refuse_existing(OUTPUTS)?;
    let kinds: Vec<(String, RecordingKind)> = dataset.iter().map(|(s, r)| (s.clone(), r.meta.kind.clone())).collect();
    let (dataset, screened_out) = screen_decays(&args.dataset, dataset, band);
    let mut id = identify_dataset(rig, &dataset, band.hz);
    name_decay_files(&args.dataset, &kinds, band, &mut id.left_out);
    id.left_out.splice(0..0, screened_out);
    refuse_empty_results(rig, &args.dataset, band, &kinds, &id)?;
    let points = ea_points(rig, &dataset, &id);
    let report = build_report(args, &kinds, &id, &points);

    let json = out.path(OUTPUTS[0]);
    std::fs::write(&json, serde_json::to_string_pretty(&report)?)
        .with_context(|| format!("cannot write {}", json.display()))?;
    let csv_path = out.path(OUTPUTS[1]);
    write_csv(&csv_path, &report.free_decays)?;
    if points.len() >= 2 {
        ea_plot(&out.path(OUTPUTS[2]), &args.dataset, &points, rig.mechanics.rope_ea_n)?;
    }
    if !id.decays.is_empty() {
        decays_plot(&out.path(OUTPUTS[3]), &args.dataset, &dataset, &id)?;
    }
    let (json, csv_path) = (out.published(&json), out.published(&csv_path));
    out.commit()?;
    print_report(&report);
    outln!("wrote {}, {}", json.display(), csv_path.display());
    Ok(())
}

/// Each identified free decay's point of `ea_vs_tension.png`, with the
/// error bar of its single cycles' EA ([`DecayCycles`]).
fn ea_points(rig: &RigConfig, dataset: &[(String, Recording)], id: &DatasetIdentification) -> Vec<EaPoint> {
    let m = &rig.mechanics;
    id.decays
        .iter()
        .map(|(stem, decay)| {
            let rec = dataset.iter().find(|(s, _)| s == stem).map(|(_, r)| r);
            let length = match rec.map(|r| &r.meta.kind) {
                Some(RecordingKind::FreeDecay { rope_length_m, .. }) => *rope_length_m,
                _ => f64::NAN,
            };
            let cycles = rec.and_then(|rec| {
                let acc = rec.column(recording::ACC_CAR)?;
                DecayCycles::find(&acc.values, rec.meta.sample_rate_hz, decay.first_frequency_hz, decay.cycles_used)
            });
            let cycle_ea: Vec<f64> = cycles
                .map(|c| {
                    c.frequencies_hz()
                        .iter()
                        .map(|&f| {
                            rope_ea_from_first_frequency(f, m.rope_mass_per_length_kg_per_m, length, decay.mass_kg)
                        })
                        .collect()
                })
                .unwrap_or_default();
            EaPoint {
                tension_n: decay.tension_n,
                ea_n: decay.rope_ea_n,
                error_n: two_standard_errors(&cycle_ea),
                label: stem.clone(),
            }
        })
        .collect()
}

/// The report of `identify`: each decay and travel kept with the
/// recording's masses and rope, the means, and whether the decays' EA
/// values agree within their uncertainty ([`ea_disagreement`]).
fn build_report(
    args: &IdentifyArgs,
    kinds: &[(String, RecordingKind)],
    id: &DatasetIdentification,
    points: &[EaPoint],
) -> Report {
    let kind_of = |stem: &str| kinds.iter().find(|(s, _)| s == stem).map(|(_, k)| k.clone());
    let estimates: Vec<EaEstimate> =
        points.iter().map(|p| EaEstimate { recording: p.label.clone(), ea_n: p.ea_n, error_n: p.error_n }).collect();
    Report {
        dataset: args.dataset.display().to_string(),
        free_decays: id
            .decays
            .iter()
            .map(|(stem, d)| DecayResult {
                recording: stem.clone(),
                mass_kg: d.mass_kg,
                rope_length_m: match kind_of(stem) {
                    Some(RecordingKind::FreeDecay { rope_length_m, .. }) => rope_length_m,
                    _ => f64::NAN,
                },
                tension_n: d.tension_n,
                first_frequency_hz: d.first_frequency_hz,
                rope_ea_n: d.rope_ea_n,
                damping_ratio: d.damping_ratio,
                guide_damping_kg_per_s: d.damping_kg_per_s,
                cycles_used: d.cycles_used,
            })
            .collect(),
        mean_rope_ea_n: id.rope_ea_n,
        rope_ea_disagreement: ea_disagreement(&estimates),
        mean_damping_ratio: id.damping_ratio,
        mean_guide_damping_kg_per_s: id.guide_damping_kg_per_s,
        travels: id
            .travels
            .iter()
            .map(|(stem, b)| {
                let (m_car_kg, m_cw_kg) = match kind_of(stem) {
                    Some(RecordingKind::Travel { m_car_kg, m_cw_kg, .. }) => (m_car_kg, m_cw_kg),
                    _ => (f64::NAN, f64::NAN),
                };
                SheaveResult {
                    recording: stem.clone(),
                    m_car_kg,
                    m_cw_kg,
                    mean_torque_nm: b.mean_torque_nm,
                    mean_speed_radps: b.mean_speed_radps,
                    out_of_balance_torque_nm: b.out_of_balance_torque_nm,
                    sheave_damping_nms_per_rad: b.sheave_damping_nms_per_rad,
                }
            })
            .collect(),
        mean_sheave_damping_nms_per_rad: id.sheave_damping_nms_per_rad,
        left_out: id.left_out.clone(),
    }
}

/// `free_decays.csv`: one row per free decay kept.
fn write_csv(path: &Path, decays: &[DecayResult]) -> anyhow::Result<()> {
    let mut csv = std::io::BufWriter::new(
        std::fs::File::create(path).with_context(|| format!("cannot write {}", path.display()))?,
    );
    writeln!(
        csv,
        "recording,mass_kg,rope_length_m,tension_n,first_frequency_hz,rope_ea_n,damping_ratio,guide_damping_kg_per_s"
    )?;
    for d in decays {
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
    Ok(())
}

/// The report's table on standard output: the decays, the travels, a
/// disagreement of the decays' EA values, the recordings left out.
fn print_report(report: &Report) {
    outln!(
        "{:<28} {:>8} {:>6} {:>9} {:>12} {:>8} {:>10}",
        "free decay",
        "m [kg]",
        "l [m]",
        "f1 [Hz]",
        "EA [N]",
        "zeta",
        "c [kg/s]"
    );
    for d in &report.free_decays {
        outln!(
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
        outln!(
            "{:<28} c_sheave = {:.3} N m s/rad (Eqn 13; mean torque {:+.2} N m at {:+.3} rad/s)",
            t.recording,
            t.sheave_damping_nms_per_rad,
            t.mean_torque_nm,
            t.mean_speed_radps
        );
    }
    if let Some(note) = &report.rope_ea_disagreement {
        outln!("note: {note}");
    }
    for l in &report.left_out {
        outln!("left out: {}: {}", l.recording, l.reason);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decay_cycles_give_the_damped_frequency_of_a_decaying_sine() {
        // A 6.25 Hz decay (zeta 0.02) released at 1 s after rest, 4096 Hz:
        // the cycles' peaks are one damped period apart.
        let (fs, f, zeta): (f64, f64, f64) = (4096.0, 6.25, 0.02);
        let wd = std::f64::consts::TAU * f * (1.0 - zeta * zeta).sqrt();
        let a: Vec<f64> = (0..(8.0 * fs) as usize)
            .map(|i| {
                let t = i as f64 / fs - 1.0;
                if t < 0.0 {
                    0.0
                } else {
                    (-zeta * std::f64::consts::TAU * f * t).exp() * (wd * t).sin()
                }
            })
            .collect();
        let cycles = DecayCycles::find(&a, fs, f, 12).unwrap();
        assert_eq!(cycles.peak_times_s.len(), 12);
        let fd = wd / std::f64::consts::TAU;
        for fk in cycles.frequencies_hz() {
            assert!((fk / fd - 1.0).abs() < 2e-4, "{fk} vs {fd}");
        }
        // The window starts at the second peak after the largest (the
        // identification's rule) and the record is too short for 100.
        assert!(cycles.peak_times_s[0] > 1.0 + 1.5 / f);
        assert!(DecayCycles::find(&a, fs, f, 100).unwrap().peak_times_s.len() < 100);
    }

    #[test]
    fn two_standard_errors_of_a_known_set() {
        // 1, 2, 3, 4: sample variance 5/3, standard error sqrt(5/12).
        let e = two_standard_errors(&[1.0, 2.0, 3.0, 4.0]).unwrap();
        assert!((e - 2.0 * (5.0_f64 / 12.0).sqrt()).abs() < 1e-12);
        assert_eq!(two_standard_errors(&[1.0]), None);
    }
}
