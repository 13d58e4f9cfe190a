//! `host-sim analyze DATASET`: the paper's analyses of every travel in a
//! dataset (section 3.3 and 3.6): the machine torque from the phase currents
//! (dq0, electrical angle from the encoder), the constant-speed stage, the
//! Welch PSD of the torque ripple over that stage with each line labelled by
//! its source, and the car (counterweight, machine) acceleration high-passed
//! at 1 Hz with its Burg and STFT spectrograms, 0-128 Hz, dB re 1 m/s^2,
//! the model's natural frequencies traced on them.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use serde::Serialize;

use super::{check_count, check_open_range, output_dir_reading};
use diagnosis::travel_signals::{counterweight_side_length_m, travel_torque, TravelTorque};
use dsp::{burg_spectrogram, highpass_zero_phase, stft_spectrogram, welch_psd, Psd, Spectrogram};
use plant::modes::natural_modes;
use plant::rope::{ChainParams, DOF};
use plots::{spectrogram_plot_with_top_axis, stacked_plot, Band, Mark, Panel, Series, TopAxis};
use recording::{Recording, RecordingKind, ACC_CAR, ACC_CW, ACC_MACHINE};
use rig_config::RigConfig;

/// Options of `analyze`.
#[derive(Debug, Args)]
pub struct AnalyzeArgs {
    /// The dataset directory (pairs `<stem>.toml` + `<stem>.csv`).
    pub dataset: PathBuf,
    /// Welch segment length for the torque PSD, s (at most the constant-speed
    /// stage; the frequency resolution is 1 / segment).
    #[arg(long = "welch-segment", value_name = "S", default_value_t = 4.0, allow_negative_numbers = true)]
    pub welch_segment_s: f64,
    /// Burg spectrogram: window, s.
    #[arg(long = "burg-window", value_name = "S", default_value_t = 1.0, allow_negative_numbers = true)]
    pub burg_window_s: f64,
    /// Burg spectrogram: AR model order.
    #[arg(long = "burg-order", default_value_t = 40, allow_negative_numbers = true)]
    pub burg_order: usize,
    /// STFT spectrogram window, s.
    #[arg(long = "stft-window", value_name = "S", default_value_t = 2.0, allow_negative_numbers = true)]
    pub stft_window_s: f64,
    /// Output directory (one folder per recording).
    #[arg(long, value_name = "DIR", default_value = "out/analyze")]
    pub out: PathBuf,
    /// Replace the outputs of an earlier run (default: refuse to overwrite).
    #[arg(long)]
    pub force: bool,
}

/// Longest analysis window of the flags, s.
const MAX_WINDOW_S: f64 = 600.0;
/// Highest Burg order of `--burg-order`.
const MAX_BURG_ORDER: usize = 1000;
/// A line is resolved when it lies at least this many bins of the Welch
/// PSD from 0 Hz and from the Nyquist frequency (`Psd::line_amplitude`) ...
const LINE_EDGE_BINS: f64 = 3.0;
/// ... and this many bins from every other line of the list (two main
/// lobes of the Hann window and a bin between them).
const LINE_SEPARATION_BINS: f64 = 5.0;

/// A line is found when its peak PSD stands at least this far above the
/// local floor: the median PSD of the [`FLOOR_HALF_BINS`] bins on each side
/// of the peak, the [`FLOOR_GAP_BINS`] nearest bins left out (the line's own
/// main lobe). Below it, what the line's search window holds is the floor
/// (a mode sweeping past, noise), not the line: it is reported as not found,
/// without an amplitude. dB.
const LINE_ABOVE_FLOOR_DB: f64 = 10.0;
/// Bins on each side of a line's peak over which its local floor is taken.
const FLOOR_HALF_BINS: usize = 16;
/// Bins on each side of a line's peak left out of its local floor.
const FLOOR_GAP_BINS: usize = 4;

/// An order of the ripple list whose line does not stand above the local
/// floor of the torque PSD.
#[derive(Debug, Serialize)]
struct MissingLine {
    source: String,
    mechanical_order: u32,
    expected_frequency_hz: f64,
    /// Peak PSD over the local floor, dB (below [`LINE_ABOVE_FLOOR_DB`]).
    above_floor_db: f64,
}

/// A labelled line of the torque ripple.
#[derive(Debug, Serialize)]
struct RippleLine {
    source: String,
    mechanical_order: u32,
    expected_frequency_hz: f64,
    frequency_hz: f64,
    amplitude_nm: f64,
}

/// What `analyze` reports for one travel.
#[derive(Debug, Serialize)]
struct TravelAnalysis {
    recording: String,
    constant_speed_start_s: f64,
    constant_speed_end_s: f64,
    mechanical_frequency_hz: f64,
    electrical_offset_rad: f64,
    /// Where the shaft angle comes from and its delay behind the currents.
    shaft_angle: diagnosis::travel_signals::AngleAlignment,
    mean_torque_nm: f64,
    ripple_lines: Vec<RippleLine>,
    /// Orders whose line the Welch segment cannot resolve (too close to 0 Hz,
    /// the Nyquist frequency or another line): not reported.
    unresolved_orders: Vec<u32>,
    /// Orders whose line is not above the local floor of the PSD.
    not_found: Vec<MissingLine>,
    files: Vec<String>,
}

/// The sources of the torque ripple lines the paper names (section 3.3),
/// as multiples of the mechanical frequency for `p` pole pairs.
fn ripple_sources(pole_pairs: u32) -> Vec<(u32, String)> {
    let p = pole_pairs;
    vec![
        (1, "mechanical order 1 (imbalance, eccentricity)".to_string()),
        (p, "electrical fundamental (p)".to_string()),
        (2 * p, "2nd-order radial force (2p)".to_string()),
        (3 * p, "3rd harmonic of the fundamental (3p)".to_string()),
        (4 * p, "4th harmonic of the fundamental (4p)".to_string()),
        (6 * p, "electromagnetic ripple k = 6 (6p)".to_string()),
        (12 * p, "cogging n = 12 (12p)".to_string()),
    ]
}

/// Runs `analyze`.
pub fn run(rig: &RigConfig, args: &AnalyzeArgs) -> anyhow::Result<()> {
    check_open_range("--welch-segment", args.welch_segment_s, 0.0, MAX_WINDOW_S)?;
    check_open_range("--burg-window", args.burg_window_s, 0.0, MAX_WINDOW_S)?;
    check_count("--burg-order", args.burg_order, 1, MAX_BURG_ORDER)?;
    check_open_range("--stft-window", args.stft_window_s, 0.0, MAX_WINDOW_S)?;
    let dataset = super::read_dataset_on(rig, &args.dataset)?;
    let out = output_dir_reading(&args.out, args.force, &[&args.dataset])?;
    let travels = dataset.iter().filter(|(_, r)| matches!(r.meta.kind, RecordingKind::Travel { .. }));
    out.refuse_existing(
        std::iter::once("analyze.json".to_string()).chain(travels.map(|(stem, _)| format!("{stem}/torque_psd.csv"))),
    )?;
    let mut results = Vec::new();
    let mut skipped = Vec::new();
    for (stem, recording) in &dataset {
        match recording.meta.kind {
            RecordingKind::Travel { .. } => results
                .push(analyze_travel(rig, args, stem, recording, &out).with_context(|| format!("recording `{stem}`"))?),
            RecordingKind::FreeDecay { .. } => skipped.push(format!("{stem}: free decay (see `identify`)")),
        }
    }
    let json = out.path("analyze.json");
    #[derive(Serialize)]
    struct Report<'a> {
        dataset: String,
        travels: &'a [TravelAnalysis],
        skipped: &'a [String],
    }
    let report = Report { dataset: args.dataset.display().to_string(), travels: &results, skipped: &skipped };
    std::fs::write(&json, serde_json::to_string_pretty(&report)?)
        .with_context(|| format!("cannot write {}", json.display()))?;
    let json = out.published(&json);
    out.commit()?;
    for t in &results {
        outln!(
            "{}: constant speed {:.2}-{:.2} s, f_mech {:.4} Hz, mean torque {:.2} N m",
            t.recording,
            t.constant_speed_start_s,
            t.constant_speed_end_s,
            t.mechanical_frequency_hz,
            t.mean_torque_nm
        );
        outln!("  shaft angle: {}", t.shaft_angle.text());
        for line in &t.ripple_lines {
            outln!(
                "  {:>3} x f_mech {:>8.3} Hz: {:>8.4} N m  {}",
                line.mechanical_order,
                line.frequency_hz,
                line.amplitude_nm,
                line.source
            );
        }
        for m in &t.not_found {
            outln!(
                "  {:>3}x {:>8.3} Hz  not found: {:.1} dB above the local floor (a line needs {LINE_ABOVE_FLOOR_DB} dB)",
                m.mechanical_order,
                m.expected_frequency_hz,
                m.above_floor_db
            );
        }
        if !t.unresolved_orders.is_empty() {
            outln!(
                "  not resolved with --welch-segment {} s (lines too close to 0 Hz or to each other): orders {:?}",
                args.welch_segment_s,
                t.unresolved_orders
            );
        }
    }
    for s in &skipped {
        outln!("skipped {s}");
    }
    outln!("wrote {} and one folder per travel in {}", json.display(), args.out.display());
    Ok(())
}

fn analyze_travel(
    rig: &RigConfig,
    args: &AnalyzeArgs,
    stem: &str,
    recording: &Recording,
    output: &crate::output::OutputDir,
) -> anyhow::Result<TravelAnalysis> {
    let RecordingKind::Travel { m_car_kg, m_cw_kg, lw_start_m, .. } = recording.meta.kind else {
        anyhow::bail!("`{stem}` is not a travel");
    };
    let fs = recording.meta.sample_rate_hz;
    let out = output.path(stem);
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    let mut files = TravelFiles { stem, out, output, published: Vec::new() };

    let TravelTorque {
        speed_radps: speed,
        shaft_angle_rad: angle,
        angle_alignment,
        electrical_offset_rad: offset,
        torque_nm: torque,
        constant_speed: stage,
    } = travel_torque(rig, recording, stem)?;
    let stage_speed = &speed[stage.clone()];
    let f_mech = stage_speed.iter().map(|w| w.abs()).sum::<f64>() / stage_speed.len() as f64 / std::f64::consts::TAU;
    let stage_torque = &torque[stage.clone()];
    let mean_torque = stage_torque.iter().sum::<f64>() / stage_torque.len() as f64;
    let (ripple_lines, unresolved_orders, not_found) =
        torque_psd_outputs(rig, args, &mut files, fs, &stage, stage_torque, f_mech)?;
    let stage_band = Band {
        x0: stage.start as f64 / fs,
        x1: stage.end as f64 / fs,
        label: "constant-speed stage (torque PSD)".to_string(),
    };
    let torque_png = files.out.join("torque.png");
    let time: Vec<f64> = (0..torque.len()).map(|i| i as f64 / fs).collect();
    stacked_plot(
        &torque_png,
        &format!("{stem}: machine torque from the phase currents (dq0), the stage of the torque PSD shaded"),
        "time [s]",
        &[Panel {
            y_label: "torque [N m]".to_string(),
            series: vec![Series::new("torque", time.clone(), torque.clone())],
            ..Panel::default()
        }],
        std::slice::from_ref(&stage_band),
    )?;
    files.publish(&torque_png);

    // Accelerations: 1 Hz zero-phase high-pass, spectrograms with the model's modes.
    let mut chain = ChainParams::from_rig(rig, m_car_kg);
    chain.m_cw_kg = m_cw_kg;
    let lw = counterweight_side_length_m(&angle, lw_start_m, rig.mechanics.sheave_radius_m);
    let traces = Traces { fs, chain: &chain, lw: &lw, speed: &speed, time: &time, stage_band: &stage_band };
    for (name, label) in [(ACC_CAR, "car"), (ACC_CW, "counterweight"), (ACC_MACHINE, "machine")] {
        let Some(acc) = recording.column(name) else { continue };
        acceleration_outputs(rig, args, &mut files, name, label, &acc.values, &traces)?;
    }
    Ok(TravelAnalysis {
        recording: stem.to_string(),
        constant_speed_start_s: stage.start as f64 / fs,
        constant_speed_end_s: stage.end as f64 / fs,
        mechanical_frequency_hz: f_mech,
        electrical_offset_rad: offset,
        shaft_angle: angle_alignment,
        mean_torque_nm: mean_torque,
        ripple_lines,
        unresolved_orders,
        not_found,
        files: files.published,
    })
}

/// A travel's output folder and the files published in it so far.
struct TravelFiles<'a> {
    stem: &'a str,
    /// The travel's folder (in the staging folder).
    out: std::path::PathBuf,
    output: &'a crate::output::OutputDir,
    /// Where the written files land, in order.
    published: Vec<String>,
}

impl TravelFiles<'_> {
    /// Records `path` (written) under its published name.
    fn publish(&mut self, path: &std::path::Path) {
        self.published.push(self.output.published(path).display().to_string());
    }
}

/// The torque's ripple PSD over the constant-speed `stage` (Welch, the
/// `--welch-segment`), written as `torque_psd.csv` and `torque_psd.png`
/// with its lines found: the lines, the unresolved orders, those not found.
fn torque_psd_outputs(
    rig: &RigConfig,
    args: &AnalyzeArgs,
    files: &mut TravelFiles<'_>,
    fs: f64,
    stage: &std::ops::Range<usize>,
    stage_torque: &[f64],
    f_mech: f64,
) -> anyhow::Result<(Vec<RippleLine>, Vec<u32>, Vec<MissingLine>)> {
    let stage_s = stage_torque.len() as f64 / fs;
    if args.welch_segment_s > stage_s {
        anyhow::bail!(
            "the constant-speed stage ({:.2}-{:.2} s) lasts {stage_s:.2} s, shorter than the Welch segment \
             (--welch-segment {} s); expected a stage of at least one segment: give a --welch-segment of at most \
             {:.2} s (its frequency resolution is 1 / segment)",
            stage.start as f64 / fs,
            stage.end as f64 / fs,
            args.welch_segment_s,
            (stage_s * 100.0).floor() / 100.0
        );
    }
    let segment = (args.welch_segment_s * fs).round() as usize;
    let psd = welch_psd(stage_torque, fs, segment, 0.5).context("torque PSD (--welch-segment)")?;
    let (ripple_lines, unresolved_orders, not_found) = find_ripple_lines(&psd, f_mech, fs, rig.motor.pole_pairs);
    let psd_csv = files.out.join("torque_psd.csv");
    let mut csv = std::io::BufWriter::new(std::fs::File::create(&psd_csv)?);
    writeln!(csv, "frequency_hz,torque_psd_nm2_per_hz")?;
    for (f, d) in psd.frequency_hz.iter().zip(&psd.density) {
        writeln!(csv, "{f},{d}")?;
    }
    csv.flush()?;
    files.publish(&psd_csv);
    let psd_png = files.out.join("torque_psd.png");
    let title = format!(
        "{}: torque ripple PSD, constant-speed stage {:.2}-{:.2} s (Welch, {} s segments)",
        files.stem,
        stage.start as f64 / fs,
        stage.end as f64 / fs,
        args.welch_segment_s
    );
    torque_psd_plot(&psd_png, &title, &psd, &ripple_lines)?;
    files.publish(&psd_png);
    Ok((ripple_lines, unresolved_orders, not_found))
}

/// What the acceleration plots trace: the sample rate (Hz), the model's
/// chain and rope lengths `lw` (m, per sample), the shaft speed (rad/s),
/// the time axis (s) and the constant-speed stage.
struct Traces<'a> {
    fs: f64,
    chain: &'a ChainParams,
    lw: &'a [f64],
    speed: &'a [f64],
    time: &'a [f64],
    stage_band: &'a Band,
}

/// Acceleration column `name` (`label` in titles) high-passed and plotted,
/// and its Burg and STFT spectrograms with the model's modes and the
/// ripple orders traced.
fn acceleration_outputs(
    rig: &RigConfig,
    args: &AnalyzeArgs,
    files: &mut TravelFiles<'_>,
    name: &str,
    label: &str,
    values: &[f64],
    traces: &Traces<'_>,
) -> anyhow::Result<()> {
    let (stem, fs) = (files.stem, traces.fs);
    let [_, band_hi] = rig.measurement.spectrogram_band_hz;
    let rope = TopAxis::at_multiples("counterweight-side rope length lw [m]", traces.time, traces.lw, 0.5, 1);
    let filtered = highpass_zero_phase(values, fs, rig.measurement.highpass_hz)
        .with_context(|| format!("`{name}`: high-pass at [measurement].highpass_hz"))?;
    let hp_png = files.out.join(format!("{name}_hp.png"));
    stacked_plot(
        &hp_png,
        &format!("{stem}: {label} acceleration, high-passed at {} Hz", rig.measurement.highpass_hz),
        "time [s]",
        &[Panel {
            y_label: "acceleration [m/s^2]".to_string(),
            series: vec![Series::new(label, traces.time.to_vec(), filtered.clone())],
            ..Panel::default()
        }],
        std::slice::from_ref(traces.stage_band),
    )?;
    files.publish(&hp_png);
    let burg = burg_spectrogram(&filtered, fs, args.burg_window_s, 0.75, args.burg_order, band_hi, 0.25).with_context(
        || {
            format!(
                "`{name}`: Burg spectrogram (--burg-window {} s, --burg-order {})",
                args.burg_window_s, args.burg_order
            )
        },
    )?;
    let stft = stft_spectrogram(&filtered, fs, args.stft_window_s, 0.9, band_hi)
        .with_context(|| format!("`{name}`: STFT spectrogram (--stft-window {} s)", args.stft_window_s))?;
    for (method, spectrogram) in [("burg", &burg), ("stft", &stft)] {
        let png = files.out.join(format!("{name}_spectrogram_{method}.png"));
        spectrogram_plot_with_top_axis(
            &png,
            &format!("{stem}: {label} acceleration ({method}), dB re 1 (m/s^2)^2/Hz, modes and orders traced"),
            spectrogram,
            &[
                mode_overlays(traces.chain, traces.lw, fs, spectrogram, band_hi),
                order_overlays(rig, traces.speed, fs, spectrogram, band_hi),
            ]
            .concat(),
            None,
            Some(&rope),
        )?;
        files.publish(&png);
    }
    Ok(())
}

/// Peak PSD over the local floor at `frequency_hz`, dB: the largest density
/// within the line's main lobe over the median of the surrounding bins (see
/// [`LINE_ABOVE_FLOOR_DB`]).
fn above_floor_db(psd: &Psd, frequency_hz: f64) -> f64 {
    let n = psd.density.len();
    let centre =
        ((frequency_hz - psd.frequency_hz[0]) / psd.bin_width_hz()).round().clamp(0.0, (n - 1) as f64) as usize;
    let lobe = centre.saturating_sub(2)..(centre + 3).min(n);
    let peak = psd.density[lobe].iter().copied().fold(0.0, f64::max);
    let mut floor: Vec<f64> = (centre.saturating_sub(FLOOR_HALF_BINS)..(centre + FLOOR_HALF_BINS + 1).min(n))
        .filter(|k| k.abs_diff(centre) > FLOOR_GAP_BINS)
        .map(|k| psd.density[k])
        .collect();
    if floor.is_empty() {
        return f64::INFINITY;
    }
    let mid = floor.len() / 2;
    let median = *floor.select_nth_unstable_by(mid, f64::total_cmp).1;
    10.0 * (peak / median.max(f64::MIN_POSITIVE)).log10()
}

/// The ripple lines of the orders of [`ripple_sources`] in the torque PSD:
/// found (with amplitude), unresolved (too close to 0 Hz, Nyquist or another
/// line) and not found (not above the local floor).
fn find_ripple_lines(
    psd: &Psd,
    f_mech: f64,
    fs: f64,
    pole_pairs: u32,
) -> (Vec<RippleLine>, Vec<u32>, Vec<MissingLine>) {
    let (mut found, mut unresolved, mut missing) = (Vec::new(), Vec::new(), Vec::new());
    let sources = ripple_sources(pole_pairs);
    let bins = psd.bin_width_hz();
    for (order, source) in &sources {
        let (order, source) = (*order, source.clone());
        let expected = order as f64 * f_mech;
        if expected >= 0.5 * fs {
            continue;
        }
        let nearest = sources
            .iter()
            .filter(|(o, _)| *o != order)
            .map(|(o, _)| (*o as f64 * f_mech - expected).abs())
            .fold(f64::INFINITY, f64::min);
        let resolved = expected >= LINE_EDGE_BINS * bins
            && expected <= 0.5 * fs - LINE_EDGE_BINS * bins
            && nearest >= LINE_SEPARATION_BINS * bins;
        if !resolved {
            unresolved.push(order);
            continue;
        }
        let Some((frequency_hz, amplitude_nm)) = psd.line_amplitude(expected, (0.03 * expected).max(2.0 * bins)) else {
            continue;
        };
        let above = above_floor_db(psd, frequency_hz);
        if above < LINE_ABOVE_FLOOR_DB {
            missing.push(MissingLine {
                source,
                mechanical_order: order,
                expected_frequency_hz: expected,
                above_floor_db: above,
            });
            continue;
        }
        found.push(RippleLine {
            source,
            mechanical_order: order,
            expected_frequency_hz: expected,
            frequency_hz,
            amplitude_nm,
        });
    }
    (found, unresolved, missing)
}

/// `torque_psd.png`: the PSD 0-100 Hz in dB, each found line marked with
/// its order, source and amplitude.
fn torque_psd_plot(path: &std::path::Path, title: &str, psd: &Psd, lines: &[RippleLine]) -> anyhow::Result<()> {
    let db = |d: f64| 10.0 * d.max(1e-30).log10();
    let (x, y): (Vec<f64>, Vec<f64>) =
        psd.frequency_hz.iter().zip(&psd.density).filter(|(f, _)| **f <= 100.0).map(|(f, d)| (*f, db(*d))).unzip();
    let marks = lines
        .iter()
        .filter(|l| l.frequency_hz <= 100.0)
        .map(|l| {
            let k = ((l.frequency_hz - psd.frequency_hz[0]) / psd.bin_width_hz()).round() as usize;
            let lobe = k.saturating_sub(2)..(k + 3).min(psd.density.len());
            let peak = psd.density[lobe].iter().copied().fold(0.0, f64::max);
            let label = format!("{}x {} {:.3} N m", l.mechanical_order, l.source, l.amplitude_nm);
            Mark { x: l.frequency_hz, y: db(peak), label, y_error: None }
        })
        .collect();
    let panel = Panel {
        y_label: "PSD [dB re 1 (N m)^2/Hz]".to_string(),
        series: vec![Series::new("machine torque (dq0)", x, y)],
        marks,
        levels: vec![],
    };
    stacked_plot(path, title, "frequency [Hz]", &[panel], &[])?;
    Ok(())
}

/// The ripple orders of the rig (`[[ripple]]`) n x f_mech at each
/// spectrogram time, f_mech from the encoder speed `speed` (rad/s), as
/// overlay curves inside the band.
fn order_overlays(rig: &RigConfig, speed: &[f64], fs: f64, spectrogram: &Spectrogram, band_hi: f64) -> Vec<Series> {
    let at = |t: f64| ((t.max(0.0) * fs) as usize).min(speed.len() - 1);
    rig.ripple
        .iter()
        .map(|r| {
            let y: Vec<f64> = spectrogram
                .times_s
                .iter()
                .map(|&t| r.mechanical_order as f64 * speed[at(t)].abs() / std::f64::consts::TAU)
                .map(|f| if f > 0.5 && f <= band_hi { f } else { f64::NAN })
                .collect();
            Series::new(format!("{}x f_mech", r.mechanical_order), spectrogram.times_s.clone(), y)
        })
        .filter(|s| s.y.iter().any(|f| f.is_finite()))
        .collect()
}

/// The model's elastic natural frequencies (Eqn 10) at the rope length of
/// each spectrogram time, as overlay curves inside the band.
fn mode_overlays(chain: &ChainParams, lw: &[f64], fs: f64, spectrogram: &Spectrogram, band_hi: f64) -> Vec<Series> {
    let total = chain.rope_total_length_m;
    let modes: Vec<[f64; DOF]> = spectrogram
        .times_s
        .iter()
        .map(|t| {
            let l = lw[((t * fs) as usize).min(lw.len() - 1)].clamp(1e-3, total - 1e-3);
            natural_modes(chain, l).frequencies_hz
        })
        .collect();
    (1..DOF)
        .filter(|&k| modes.iter().any(|f| f[k] <= band_hi))
        .map(|k| {
            let y = modes.iter().map(|f| if f[k] <= band_hi { f[k] } else { f64::NAN }).collect();
            Series::new(format!("model f{}", k + 1), spectrogram.times_s.clone(), y)
        })
        .collect()
}
