//! The diagnosis report: `gap.json` (everything), `gap.md` (the answer in
//! words with its tables and plots), `gap_map.csv` and `ranking.csv` (for
//! pandas/MATLAB), and the gap-map plots (car acceleration, travel phase x
//! band, before and after).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::error::{Context, Result};

use super::measure::CellGap;
use super::signals::Phase;
use super::{DriveModel, GapReport, Verdict};
use dsp::Spectrogram;
use plots::spectrogram_plot;

const PHASES: [Phase; 6] =
    [Phase::Start, Phase::Acceleration, Phase::Constant, Phase::Deceleration, Phase::Stop, Phase::Decay];

/// Mean `d` (dB) per (phase, band) over the recordings, for the phases present.
pub fn gap_map(cells: &[CellGap], bands: usize) -> Vec<(Phase, Vec<Option<f64>>)> {
    let mut out = Vec::new();
    for phase in PHASES {
        let mut row = vec![None; bands];
        let mut any = false;
        for (b, slot) in row.iter_mut().enumerate() {
            let d: Vec<f64> = cells.iter().filter(|c| c.phase == phase && c.band == b).map(|c| c.d_db).collect();
            if !d.is_empty() {
                *slot = Some(d.iter().sum::<f64>() / d.len() as f64);
                any = true;
            }
        }
        if any {
            out.push((phase, row));
        }
    }
    out
}

/// Draws a gap map as a heat map: x the phases in order, y the band centres.
pub fn gap_map_plot(
    path: &Path,
    title: &str,
    map: &[(Phase, Vec<Option<f64>>)],
    bands_hz: &[(f64, f64)],
) -> Result<()> {
    if map.is_empty() || bands_hz.is_empty() {
        return Ok(());
    }
    let spectrogram = Spectrogram {
        times_s: (0..map.len()).map(|i| i as f64).collect(),
        frequency_hz: (0..bands_hz.len()).map(|b| b as f64).collect(),
        psd_db: map.iter().map(|(_, row)| row.iter().map(|v| v.unwrap_or(0.0)).collect()).collect(),
    };
    let labels: Vec<String> = map.iter().enumerate().map(|(i, (p, _))| format!("{i} {}", p.name())).collect();
    let title = format!(
        "{title} | x: {} | y: band 0 = {:.0} Hz .. {} = {:.0} Hz | colour: d, dB",
        labels.join(", "),
        bands_hz[0].0,
        bands_hz.len() - 1,
        bands_hz[bands_hz.len() - 1].1
    );
    spectrogram_plot(path, &title, &spectrogram, &[], Some((-20.0, 20.0)))
        .with_context(|| format!("drawing {}", path.display()))
}

/// Writes `gap.json`, `gap_map.csv`, `ranking.csv` and the gap-map plots into
/// `out`, then `gap.md` listing `extra_plots` (file names in `out`) too.
pub fn write_report(out: &Path, report: &GapReport, extra_plots: &[(String, String)]) -> Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    let json = out.join("gap.json");
    std::fs::write(&json, serde_json::to_string_pretty(report)?)
        .with_context(|| format!("writing {}", json.display()))?;
    written.push(json);

    let bands = report.bands_hz.len();
    let before = gap_map(&report.map_before, bands);
    let after = gap_map(&report.map_after, bands);
    let csv = out.join("gap_map.csv");
    let mut w = csv::Writer::from_path(&csv).with_context(|| format!("writing {}", csv.display()))?;
    w.write_record(["phase", "band_lo_hz", "band_hi_hz", "d_before_db", "d_after_db"])?;
    for (phase, row) in &before {
        let row_after = after.iter().find(|(p, _)| p == phase).map(|(_, r)| r.clone());
        for (b, v) in row.iter().enumerate() {
            let Some(v) = v else { continue };
            let a = row_after.as_ref().and_then(|r| r[b]).map_or(String::new(), |x| format!("{x:.3}"));
            let (lo, hi) = report.bands_hz[b];
            w.write_record([phase.name().to_string(), format!("{lo:.3}"), format!("{hi:.3}"), format!("{v:.3}"), a])?;
        }
    }
    w.flush()?;
    written.push(csv);
    let csv = out.join("ranking.csv");
    let mut w = csv::Writer::from_path(&csv).with_context(|| format!("writing {}", csv.display()))?;
    w.write_record([
        "rank",
        "effect",
        "fitted_parameters",
        "parameters",
        "training_before_db",
        "training_after_db",
        "held_out_before_db",
        "held_out_after_db",
        "held_out_shrink",
        "score_db",
    ])?;
    for (i, c) in report.ranking.iter().enumerate() {
        let params: Vec<String> =
            c.parameters.iter().map(|p| format!("{}={:.4e}+-{:.1e}", p.name, p.value, p.uncertainty)).collect();
        w.write_record([
            (i + 1).to_string(),
            c.name.clone(),
            c.fitted_parameters.to_string(),
            params.join(" "),
            format!("{:.3}", c.training_gap_before_db),
            format!("{:.3}", c.training_gap_after_db),
            format!("{:.3}", c.held_out_gap_before_db),
            format!("{:.3}", c.held_out_gap_after_db),
            format!("{:.3}", c.held_out_shrink),
            format!("{:.3}", c.score_db),
        ])?;
    }
    w.flush()?;
    written.push(csv);

    let mut plots = Vec::new();
    let p = out.join("gap_map_before.png");
    gap_map_plot(&p, "car acc., nominal", &before, &report.bands_hz)?;
    plots.push(("gap map before (nominal model)".to_string(), "gap_map_before.png".to_string()));
    written.push(p);
    if !after.is_empty() {
        let p = out.join("gap_map_after.png");
        gap_map_plot(&p, "car acc., explaining model", &after, &report.bands_hz)?;
        plots.push(("gap map after (explaining model)".to_string(), "gap_map_after.png".to_string()));
        written.push(p);
    }
    plots.extend(extra_plots.iter().cloned());
    let md = out.join("gap.md");
    std::fs::write(&md, markdown(report, &plots)).with_context(|| format!("writing {}", md.display()))?;
    written.push(md);
    Ok(written)
}

/// The report in words.
pub fn markdown(r: &GapReport, plots: &[(String, String)]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Sim-to-real gap: {}\n", r.dataset);
    let verdict = match r.verdict {
        Verdict::Nominal => {
            "**nominal**: the calibrated nominal model explains the data to the noise level".to_string()
        }
        Verdict::Explained => format!("**explained** by `{}`", r.explained_by.as_deref().unwrap_or("?")),
        Verdict::Unexplained if r.attribution_refused.is_some() => {
            "**unexplained**: the calibrated nominal model misses the data beyond noise and tolerance, and no effect \
             was fitted (see Attribution)"
                .to_string()
        }
        Verdict::Unexplained => {
            "**unexplained**: no effect of the library (nor a pair) shrinks the held-out gap enough".to_string()
        }
    };
    let _ = writeln!(s, "Verdict: {verdict}.\n");
    let drive = match r.drive.drive {
        DriveModel::Project => "the project's drive core (closed loop, every channel compared)",
        DriveModel::Foreign => {
            "another drive (the nominal mechanics driven by the measured torque, accelerations compared)"
        }
    };
    let _ = writeln!(s, "The rig's drive: {drive}; {}.\n", r.drive.reason);
    speed_loops(&mut s, &r.rig_speed_loops);
    if let Some(why) = &r.attribution_refused {
        let _ = writeln!(s, "Attribution: {why}.\n");
    }
    for l in &r.left_out {
        let _ = writeln!(s, "Left out: `{}`: {}.\n", l.recording, l.reason);
    }
    let _ = writeln!(
        s,
        "Nominal model: excess gap {:.2} dB (noise gap {:.2} dB), mean over {} recordings; {} simulations in {:.1} s.\n",
        r.nominal_excess_db,
        r.noise_gap_db,
        r.recordings.len(),
        r.simulations,
        r.runtime_s
    );
    if let (Verdict::Explained, Some(best)) = (r.verdict, r.ranking.first()) {
        let _ = writeln!(
            s,
            "`{}` shrinks the held-out gap from {:.2} dB to {:.2} dB ({:.0} %). Fitted parameters (all recordings; \
             uncertainty: jackknife over the folds):\n",
            best.name,
            best.held_out_gap_before_db,
            best.held_out_gap_after_db,
            100.0 * best.held_out_shrink
        );
        for p in &best.parameters {
            let _ = writeln!(s, "- `{}.{}` = {:.4e} +- {:.1e} {}", p.effect, p.name, p.value, p.uncertainty, p.unit);
        }
        s.push('\n');
    }
    let l = &r.location;
    let _ = writeln!(s, "## Where the gap lies\n");
    let _ = writeln!(
        s,
        "Subsystem: **{:?}** ({}). Channel `{}`, phase `{}`, {}.\n",
        l.subsystem,
        l.reasoning,
        l.channel.name(),
        l.phase.name(),
        l.band
    );
    let _ = writeln!(s, "| channel | subsystem | excess gap (dB) |\n|---|---|---|");
    for c in &l.channels {
        let _ = writeln!(s, "| {} | {:?} | {:.2} |", c.channel.name(), c.subsystem, c.excess_db);
    }
    let _ = writeln!(s, "\n| phase ({}) | RMS d (dB) | mean d (dB) |\n|---|---|---|", l.channel.name());
    for p in &l.phases {
        let _ = writeln!(s, "| {} | {:.2} | {:.2} |", p.slice, p.rms_d_db, p.mean_d_db);
    }
    let _ = writeln!(
        s,
        "\nStrongest cells:\n\n| recording | channel | phase | band or line | d (dB) |\n|---|---|---|---|---|"
    );
    for c in &l.strongest_cells {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:+.1} |",
            c.recording,
            c.channel.name(),
            c.phase.name(),
            c.band,
            c.d_db
        );
    }
    let _ = writeln!(s, "\nNatural frequencies (strongest car-acceleration peak 2-400 Hz):\n\n| recording | phase | data (Hz) | model (Hz) |\n|---|---|---|---|");
    for f in &l.natural_frequencies {
        let _ = writeln!(s, "| {} | {} | {:.1} | {:.1} |", f.recording, f.phase.name(), f.measured_hz, f.model_hz);
    }
    let _ = writeln!(s, "\n## Calibration (step 1)\n");
    let c = &r.calibration;
    let _ = writeln!(
        s,
        "EA {:.4e} N (rig {:.4e}), guide damping {:.1} kg/s (rig {:.1}), sheave damping {:.3} N m s/rad (rig {:.3}); \
         {} decays, {} travels used.{}\n",
        c.rope_ea_n,
        c.nominal.0,
        c.guide_damping_kg_per_s,
        c.nominal.1,
        c.sheave_damping_nms_per_rad,
        c.nominal.2,
        c.decays.len(),
        c.travels.len(),
        if c.skipped.is_empty() { String::new() } else { format!(" Skipped: {}.", c.skipped.join("; ")) }
    );
    let _ = writeln!(s, "## Ranking (step 4)\n");
    let _ = writeln!(
        s,
        "| rank | effect | parameters | training before/after (dB) | held-out before/after (dB) | shrink | score (dB) |\n|---|---|---|---|---|---|---|"
    );
    for (i, c) in r.ranking.iter().enumerate() {
        let params: Vec<String> =
            c.parameters.iter().map(|p| format!("{}={:.3e}+-{:.1e}", p.name, p.value, p.uncertainty)).collect();
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.2}/{:.2} | {:.2}/{:.2} | {:.0} % | {:.2} |",
            i + 1,
            c.name,
            params.join(", "),
            c.training_gap_before_db,
            c.training_gap_after_db,
            c.held_out_gap_before_db,
            c.held_out_gap_after_db,
            100.0 * c.held_out_shrink,
            c.score_db
        );
    }
    let _ = writeln!(s, "\n## Recordings\n\n| recording | kind | gap (dB) | noise (dB) | excess nominal (dB) | closed loop / replay acc. < 80 Hz (dB) | excess explained (dB) |\n|---|---|---|---|---|---|---|");
    for g in &r.recordings {
        let _ = writeln!(
            s,
            "| {} | {} | {:.2} | {:.2} | {:.2} | {} | {} |",
            g.recording,
            g.kind,
            g.nominal.gap_db,
            g.nominal.noise_db,
            g.nominal_excess_db,
            match (g.closed_loop_acceleration_excess_db, g.replay_acceleration_excess_db) {
                (Some(a), Some(b)) => format!("{a:.2} / {b:.2}"),
                _ => "-".to_string(),
            },
            g.explained_excess_db.map_or("-".to_string(), |v| format!("{v:.2}"))
        );
    }
    let _ = writeln!(s, "\n## Gap measure\n\n{}\n", r.gap_measure);
    if !plots.is_empty() {
        let _ = writeln!(s, "## Plots\n");
        for (title, file) in plots {
            let _ = writeln!(s, "{title}:\n\n![{title}]({file})\n");
        }
    }
    s
}

/// The table of the rig drive's speed loop as each travel shows it.
fn speed_loops(s: &mut String, loops: &[super::RigSpeedLoop]) {
    if loops.is_empty() {
        return;
    }
    let _ = writeln!(
        s,
        "The rig drive's speed loop, identified from its own input and output (speed reference and estimate, \
         torque); the tolerance covers the model with this loop answering its departures from the rig's speed:\n"
    );
    let _ = writeln!(
        s,
        "| travel | Kp (N m s/rad) | Ki (N m/rad) | estimate delay (ms) | estimate lag (ms) | fit 4-40 Hz |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for l in loops {
        match (&l.controller, &l.refused) {
            (Some(c), _) => {
                let _ = writeln!(
                    s,
                    "| {} | {:.2} | {:.1} | {:.1} | {:.1} | {:.1} % |",
                    l.recording,
                    c.kp_nms_per_rad,
                    c.ki_nm_per_rad,
                    1e3 * c.estimate_delay_s,
                    1e3 * c.estimate_lag_s,
                    100.0 * c.dynamic_fit
                );
            }
            (None, reason) => {
                let _ =
                    writeln!(s, "| {} | not identified: {} | | | | |", l.recording, reason.as_deref().unwrap_or("-"));
            }
        }
    }
    let _ = writeln!(s);
}
