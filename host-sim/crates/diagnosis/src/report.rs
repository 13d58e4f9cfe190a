//! The diagnosis report: `gap.json` (everything), `gap.md` (the answer in
//! words with its tables and plots), `gap_map.csv` and `ranking.csv` (for
//! pandas/MATLAB), and the gap-map plots (the excess gap per channel,
//! travel phase x band, before and after).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::error::{Context, Result};

use super::attribute::{Candidate, FittedParameter};
use super::calibrate::Calibration;
use super::locate::Location;
use super::measure::CellGap;
use super::signals::{Channel, Phase};
use super::{CarAccelerationViews, DriveModel, GapReport, RecordingGap, Verdict};
use plots::{heat_map_plot, HeatMap, HeatPanel};

const PHASES: [Phase; 6] =
    [Phase::Start, Phase::Acceleration, Phase::Constant, Phase::Deceleration, Phase::Stop, Phase::Decay];

/// Mean `d` (dB) per (channel, phase, band) over the recordings, for the
/// channels and phases present, in signal-chain and travel order.
pub fn gap_map(cells: &[CellGap], bands: usize) -> Vec<(Channel, Phase, Vec<Option<f64>>)> {
    mean_map(cells, bands, |c| c.d_db)
}

/// Mean of `value` per (channel, phase, band) over the recordings.
fn mean_map(
    cells: &[CellGap],
    bands: usize,
    value: impl Fn(&CellGap) -> f64,
) -> Vec<(Channel, Phase, Vec<Option<f64>>)> {
    let mut out = Vec::new();
    for channel in Channel::ALL {
        for phase in PHASES {
            let mut row = vec![None; bands];
            let mut any = false;
            for (b, slot) in row.iter_mut().enumerate() {
                let d: Vec<f64> = cells
                    .iter()
                    .filter(|c| c.channel == channel && c.phase == phase && c.band == b)
                    .map(&value)
                    .collect();
                if !d.is_empty() {
                    *slot = Some(d.iter().sum::<f64>() / d.len() as f64);
                    any = true;
                }
            }
            if any {
                out.push((channel, phase, row));
            }
        }
    }
    out
}

/// Draws the gap maps of `cells` (one panel per channel present; columns
/// the travel phases present, rows the bands by their centre frequency):
/// the mean excess of each cell over the recordings ([`CellGap::signed_beyond_db`]),
/// on a colour scale centred on zero (white: the model meets the data
/// within noise and tolerance; red: the data holds more power than the
/// model; blue: less), grey where a channel has no cell.
pub fn gap_map_plot(
    path: &Path,
    title: &str,
    cells: &[CellGap],
    bands_hz: &[(f64, f64)],
    limit_db: Option<f64>,
) -> Result<()> {
    let map = mean_map(cells, bands_hz.len(), CellGap::signed_beyond_db);
    if map.is_empty() || bands_hz.is_empty() {
        return Ok(());
    }
    let phases: Vec<Phase> = PHASES.into_iter().filter(|p| map.iter().any(|(_, q, _)| q == p)).collect();
    let channels: Vec<Channel> = Channel::ALL.into_iter().filter(|c| map.iter().any(|(d, ..)| d == c)).collect();
    let panels = channels
        .iter()
        .map(|&channel| HeatPanel {
            title: channel.name().to_string(),
            values: phases
                .iter()
                .map(|&phase| {
                    map.iter()
                        .find(|(c, p, _)| *c == channel && *p == phase)
                        .map_or_else(|| vec![None; bands_hz.len()], |(_, _, row)| row.clone())
                })
                .collect(),
        })
        .collect();
    let heat = HeatMap {
        title: title.to_string(),
        columns: phases.iter().map(|p| p.name().replace('_', " ")).collect(),
        rows: bands_hz.iter().map(|(lo, hi)| format_hz((lo * hi).sqrt())).collect(),
        x_label: "travel phase".to_string(),
        y_label: "third-octave band centre [Hz]".to_string(),
        colour_label: "excess gap [dB]".to_string(),
        limit: limit_db.filter(|l| *l > 0.0),
        panels,
    };
    heat_map_plot(path, &heat).with_context(|| format!("drawing {}", path.display()))
}

/// The colour scale of a gap map of `cells`, dB: the largest magnitude of
/// its mean cell excess ([`CellGap::signed_beyond_db`]), so that a map is read at the
/// gap's own size (a 0.2 dB gap is not white on a scale made for 20 dB);
/// `None` when every cell is within noise and tolerance.
pub fn gap_map_limit_db(cells: &[CellGap], bands: usize) -> Option<f64> {
    let largest = mean_map(cells, bands, CellGap::signed_beyond_db)
        .iter()
        .flat_map(|(.., row)| row.iter().flatten())
        .fold(0.0f64, |m, v| m.max(v.abs()));
    (largest > 0.0).then_some(largest)
}

/// A band centre for an axis: three significant figures.
fn format_hz(f: f64) -> String {
    if f >= 100.0 {
        format!("{f:.0}")
    } else if f >= 10.0 {
        format!("{f:.1}")
    } else {
        format!("{f:.2}")
    }
}

/// Writes `gap.json`, `gap_map.csv`, `ranking.csv`, `car_acceleration.csv`
/// (when the report has the car acceleration's views) and the gap-map plots
/// into `out`, then `gap.md` listing `extra_plots` (file names in `out`) too.
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
    w.write_record(["channel", "phase", "band_lo_hz", "band_hi_hz", "d_before_db", "d_after_db"])?;
    for (channel, phase, row) in &before {
        let row_after = after.iter().find(|(c, p, _)| c == channel && p == phase).map(|(.., r)| r.clone());
        for (b, v) in row.iter().enumerate() {
            let Some(v) = v else { continue };
            let a = row_after.as_ref().and_then(|r| r[b]).map_or(String::new(), |x| format!("{x:.3}"));
            let (lo, hi) = report.bands_hz[b];
            w.write_record([
                channel.name().to_string(),
                phase.name().to_string(),
                format!("{lo:.3}"),
                format!("{hi:.3}"),
                format!("{v:.3}"),
                a,
            ])?;
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
        let params: Vec<String> = c.parameters.iter().map(|p| parameter_text(p, 4)).collect();
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
    if let Some(views) = &report.car_acceleration_views {
        written.push(write_car_acceleration_csv(out, views)?);
    }

    let mut plots = Vec::new();
    let p = out.join("gap_map_before.png");
    let title = format!(
        "{}: excess gap of the calibrated nominal model (d beyond noise and tolerance; white: none)",
        report.dataset
    );
    // Before and after on the same scale, the gap's own (before).
    let limit = gap_map_limit_db(&report.map_before, bands);
    gap_map_plot(&p, &title, &report.map_before, &report.bands_hz, limit)?;
    plots.push(("gap map before (nominal model)".to_string(), "gap_map_before.png".to_string()));
    written.push(p);
    if !after.is_empty() {
        let p = out.join("gap_map_after.png");
        let title = format!(
            "{}: excess gap with {} (d beyond noise and tolerance; white: none)",
            report.dataset,
            report.explained_by.as_deref().unwrap_or("the explaining model")
        );
        gap_map_plot(&p, &title, &report.map_after, &report.bands_hz, limit)?;
        plots.push(("gap map after (explaining model)".to_string(), "gap_map_after.png".to_string()));
        written.push(p);
    }
    plots.extend(extra_plots.iter().cloned());
    let md = out.join("gap.md");
    std::fs::write(&md, markdown(report, &plots)).with_context(|| format!("writing {}", md.display()))?;
    written.push(md);
    Ok(written)
}

/// Writes the car acceleration's views ([`CarAccelerationViews`]) into
/// `out/car_acceleration.csv`: `time_s` (s from the recording's first
/// sample at the analysis rate, as exact as `f64` holds it) and one column per view (`data`,
/// `nominal_model`, `explaining_model`; m/s^2), a view shorter than the
/// data left empty past its end.
pub fn write_car_acceleration_csv(out: &Path, views: &CarAccelerationViews) -> Result<PathBuf> {
    let csv = out.join("car_acceleration.csv");
    let mut w = csv::Writer::from_path(&csv).with_context(|| format!("writing {}", csv.display()))?;
    let header: Vec<String> = std::iter::once("time_s".to_string())
        .chain(views.series.iter().map(|(label, _)| label.replace(' ', "_")))
        .collect();
    w.write_record(&header)?;
    let rows = views.series.iter().map(|(_, v)| v.len()).max().unwrap_or(0);
    for k in 0..rows {
        let time = (k as f64 / views.sample_rate_hz).to_string();
        let values = views.series.iter().map(|(_, v)| v.get(k).map_or(String::new(), |x| format!("{x:.9e}")));
        w.write_record(std::iter::once(time).chain(values))?;
    }
    w.flush()?;
    Ok(csv)
}

/// The report in words.
pub fn markdown(r: &GapReport, plots: &[(String, String)]) -> String {
    let mut s = String::new();
    overview(&mut s, r);
    explaining_effect(&mut s, r);
    location_section(&mut s, &r.location);
    calibration_section(&mut s, &r.calibration);
    ranking_section(&mut s, &r.ranking);
    if let Some(note) = r.once_per_revolution_note() {
        let _ = writeln!(s, "Once per revolution: {note}.\n");
    }
    recordings_section(&mut s, &r.recordings);
    let _ = writeln!(s, "\n## Gap measure\n\n{}\n", r.gap_measure);
    plots_section(&mut s, plots);
    s
}

/// The verdict in words: `explained_by` names the explaining effect,
/// `refused` tells that no effect was fitted.
fn verdict_text(verdict: Verdict, explained_by: Option<&str>, refused: bool) -> String {
    match verdict {
        Verdict::Nominal => {
            "**nominal**: the calibrated nominal model explains the data to the noise level".to_string()
        }
        Verdict::Explained => format!("**explained** by `{}`", explained_by.unwrap_or("?")),
        Verdict::Unexplained if refused => {
            "**unexplained**: the calibrated nominal model misses the data beyond noise and tolerance, and no effect \
             was fitted"
                .to_string()
        }
        Verdict::Unexplained => {
            "**unexplained**: no effect of the library (nor a pair) shrinks the held-out gap enough".to_string()
        }
    }
}

/// A persistent cell in words.
pub fn persistent_text(p: &crate::measure::PersistentCell) -> String {
    format!(
        "{}, {}, {}: beyond noise and tolerance in all {} recordings, by {:.2} dB RMS (chance {:.1e})",
        p.channel.name(),
        p.phase.name(),
        p.band,
        p.recordings,
        p.rms_beyond_db,
        p.chance
    )
}

/// The direct-axis lines in one line of words: the orders present and
/// their largest amplitude against what nominal allows, or that none is.
pub fn electrical_lines_text(e: &crate::electrical_lines::ElectricalLines) -> String {
    let measured = e.travels.len();
    if !e.present() {
        return format!(
            "none at electrical orders 1, 2, 6 beyond noise and cross coupling in {measured} travels ({:.2} dB)",
            e.excess_db
        );
    }
    let orders: Vec<String> = e
        .present_orders
        .iter()
        .map(|&o| {
            let lines = e.travels.iter().flat_map(|t| t.lines.iter().filter(move |l| l.order == o));
            let (amplitude, allowance) =
                lines.fold((0.0f64, 0.0f64), |(a, b), l| (a.max(l.amplitude_a), b.max(l.allowance_a)));
            let travels = e.travels.iter().filter(|t| t.lines.iter().any(|l| l.order == o && l.present)).count();
            format!(
                "order {o}: in {travels} of {measured} travels, up to {:.1} mA (nominal allows {:.1} mA)",
                1e3 * amplitude,
                1e3 * allowance
            )
        })
        .collect();
    format!("{} ({:.2} dB beyond)", orders.join("; "), e.excess_db)
}

/// The drive model in words.
fn drive_text(drive: DriveModel) -> &'static str {
    match drive {
        DriveModel::Project => "the project's drive core (closed loop, every channel compared)",
        DriveModel::Foreign => "another drive (the mechanics driven by the measured torque, accelerations compared)",
    }
}

/// Section: the title, the verdict, the rig's drive (with its speed loops),
/// why no effect was fitted, the recordings left out and the nominal
/// model's gap.
fn overview(s: &mut String, r: &GapReport) {
    let _ = writeln!(s, "# Sim-to-real gap: {}\n", r.dataset);
    let verdict = verdict_text(r.verdict, r.explained_by.as_deref(), r.ranking.is_empty());
    let _ = writeln!(s, "Verdict: {verdict}.\n");
    if let Some(note) = &r.verdict_note {
        let _ = writeln!(s, "{note}.\n");
    }
    if let Some(note) = r.no_effect_helps_note() {
        let _ = writeln!(s, "{note}.\n");
    }
    let _ = writeln!(s, "The rig's drive: {}; {}.\n", drive_text(r.drive.drive), r.drive.reason);
    speed_loops(s, &r.rig_speed_loops);
    if let Some(note) = &r.attribution_note {
        let _ = writeln!(s, "Attribution: {note}.\n");
    }
    for l in &r.left_out {
        let _ = writeln!(s, "Left out: `{}`: {}.\n", l.recording, l.reason);
    }
    if let Some(note) = r.begins_in_motion_note() {
        let _ = writeln!(s, "Start: {note}.\n");
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
    if let Some(p) = &r.persistent_cell {
        let _ = writeln!(s, "Persistent cell of the nominal model: {}.\n", persistent_text(p));
    }
    if !r.current_balance.is_empty() {
        let _ = writeln!(s, "Phase currents' balance: {}.\n", crate::current_balance::balance_text(&r.current_balance));
    }
    if let Some(e) = &r.electrical_lines {
        let _ = writeln!(s, "Direct-axis current's lines: {}.\n", electrical_lines_text(e));
        for (stem, reason) in &e.not_measured {
            let _ = writeln!(s, "Lines not measured: `{stem}`: {reason}.\n");
        }
    }
}

/// Section (when `explained`): how much the best candidate shrinks the
/// held-out gap, and its fitted parameters.
fn explaining_effect(s: &mut String, r: &GapReport) {
    if let (Verdict::Explained, Some(best)) = (r.verdict, r.ranking.first()) {
        let _ = writeln!(
            s,
            "`{}` shrinks the held-out gap from {:.2} dB to {:.2} dB ({:.0} %). Fitted parameters (all recordings; \
             uncertainty: jackknife over the folds, or the measurement's where a parameter was measured without \
             the model):\n",
            best.name,
            best.held_out_gap_before_db,
            best.held_out_gap_after_db,
            100.0 * best.held_out_shrink
        );
        for p in &best.parameters {
            let source = p.measured_by.map(|m| format!(" (measured by {m}, not fitted)")).unwrap_or_default();
            let _ = writeln!(
                s,
                "- `{}.{}` = {:.4e} +- {:.1e} {}{source}",
                p.effect, p.name, p.value, p.uncertainty, p.unit
            );
        }
        s.push('\n');
        if let Some(r) = &best.refit {
            let _ = writeln!(s, "{}\n", refit_text(r));
        }
    }
}

/// The calibration under an effect's hypothesis in words.
pub fn refit_text(r: &crate::hypotheses::Refit) -> String {
    format!(
        "Calibration re-done under the hypothesis of `{}`: EA {:.4e} N, guide damping {:.1} kg/s, sheave damping \
         {:.3} N m s/rad ({})",
        r.effect, r.rope_ea_n, r.guide_damping_kg_per_s, r.sheave_damping_nms_per_rad, r.note
    )
}

/// Section `Where the gap lies`: the subsystem, the tables per channel and
/// per phase, the strongest cells and the natural frequencies.
fn location_section(s: &mut String, l: &Location) {
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
}

/// Section `Calibration (step 1)`: the calibrated values against the rig's.
fn calibration_section(s: &mut String, c: &Calibration) {
    let _ = writeln!(s, "\n## Calibration (step 1)\n");
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
}

/// A parameter as `name=value+-uncertainty` with `digits` decimals of
/// the mantissa, followed by `(measured)` when it was measured without
/// the model.
fn parameter_text(p: &FittedParameter, digits: usize) -> String {
    let measured = if p.measured_by.is_some() { " (measured)" } else { "" };
    format!("{}={:.digits$e}+-{:.1e}{measured}", p.name, p.value, p.uncertainty)
}

/// Section `Ranking (step 4)`: one table row per candidate, best first.
fn ranking_section(s: &mut String, ranking: &[Candidate]) {
    let _ = writeln!(s, "## Ranking (step 4)\n");
    let _ = writeln!(
        s,
        "| rank | effect | parameters | training before/after (dB) | held-out before/after (dB) | shrink | score (dB) | named |\n|---|---|---|---|---|---|---|---|"
    );
    for (i, c) in ranking.iter().enumerate() {
        let params: Vec<String> = c.parameters.iter().map(|p| parameter_text(p, 3)).collect();
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.2}/{:.2} | {:.2}/{:.2} | {:.0} % | {:.2} | {} |",
            i + 1,
            c.name,
            params.join(", "),
            c.training_gap_before_db,
            c.training_gap_after_db,
            c.held_out_gap_before_db,
            c.held_out_gap_after_db,
            100.0 * c.held_out_shrink,
            c.score_db,
            if c.naming.named { "yes".to_string() } else { format!("no: {}", c.naming.reason) }
        );
    }
    if let Some(pulley) = ranking.first().and_then(|c| c.effects.diverting_pulley) {
        let _ = writeln!(s, "\n{}", pulley_note(&pulley));
    }
}

/// What the recordings fix of a fitted diverting pulley: its rim's
/// equivalent mass `J / r_p^2` (kg); the inertia only at a radius, which
/// the rope's motion does not tell.
fn pulley_note(pulley: &plant::effects::DivertingPulley) -> String {
    let (r, mass) = (pulley.radius_m, pulley.rim_mass_kg());
    format!(
        "The recordings fix the diverting pulley's equivalent mass at its rim, J / r_p^2 = {mass:.2} kg; its inertia \
         above is at the radius r_p = {r:.3} m the effect assumes (the rope's motion does not tell the radius): at the \
         rig's own radius r_p the inertia is {mass:.2} kg x r_p^2."
    )
}

/// Section `Recordings`: one table row per recording (`-` where a figure
/// does not apply).
fn recordings_section(s: &mut String, recordings: &[RecordingGap]) {
    let _ = writeln!(s, "\n## Recordings\n\n| recording | kind | gap (dB) | noise (dB) | excess nominal (dB) | closed loop / replay acc. < 80 Hz (dB) | excess explained (dB) |\n|---|---|---|---|---|---|---|");
    for g in recordings {
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
}

/// Section `Plots` (when there are any): every `(title, file)` as an image.
fn plots_section(s: &mut String, plots: &[(String, String)]) {
    if !plots.is_empty() {
        let _ = writeln!(s, "## Plots\n");
        for (title, file) in plots {
            let _ = writeln!(s, "{title}:\n\n![{title}]({file})\n");
        }
    }
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
    let _ = writeln!(s, "\nThe shaft angle the model follows, put on the currents' time base:\n");
    for l in loops {
        let _ = writeln!(s, "- {}: {}", l.recording, l.shaft_angle.text());
    }
    let _ = writeln!(s, "\nThe accelerometers' high-pass as the data show it (applied to every run of the model):\n");
    for l in loops {
        let _ = writeln!(s, "- {}: {}", l.recording, l.accelerometer_highpass.text());
    }
    let _ = writeln!(s, "\nThe brake at the end of each travel as the data show it:\n");
    for l in loops {
        let _ = writeln!(s, "- {}: {}", l.recording, l.stop_brake.text());
    }
    let _ = writeln!(s);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::attribute::FittedParameter;
    use crate::measure::GapValue;
    use plant::effects::Effects;

    /// The views come back from `car_acceleration.csv` as written: one
    /// column per view named after it, the time at the analysis rate, every
    /// value to ten significant digits, a shorter view empty past its end.
    #[test]
    fn the_car_acceleration_views_are_written_as_columns() {
        let dir = tempfile::tempdir().unwrap();
        let data: Vec<f64> = (0..50).map(|k| (0.3 * k as f64).sin() * 1.234_567_89e-2).collect();
        let model: Vec<f64> = data.iter().map(|x| -0.5 * x).collect();
        let views = CarAccelerationViews {
            recording: "travel_up".to_string(),
            sample_rate_hz: 1024.0,
            series: vec![("data".to_string(), data.clone()), ("nominal model".to_string(), model[..40].to_vec())],
        };
        let path = write_car_acceleration_csv(dir.path(), &views).unwrap();
        let mut reader = csv::Reader::from_path(&path).unwrap();
        assert_eq!(reader.headers().unwrap(), vec!["time_s", "data", "nominal_model"]);
        let rows: Vec<csv::StringRecord> = reader.records().map(|r| r.unwrap()).collect();
        assert_eq!(rows.len(), 50);
        for (k, row) in rows.iter().enumerate() {
            let time: f64 = row[0].parse().unwrap();
            assert!((time - k as f64 / 1024.0).abs() < 1e-12, "row {k}: {time}");
            let value: f64 = row[1].parse().unwrap();
            assert!((value - data[k]).abs() <= 1e-9 * data[k].abs() + 1e-300, "row {k}: {value} against {}", data[k]);
            if k < 40 {
                let m: f64 = row[2].parse().unwrap();
                assert!((m - model[k]).abs() <= 1e-9 * model[k].abs() + 1e-300, "row {k}");
            } else {
                assert_eq!(&row[2], "", "row {k}: past the model's end");
            }
        }
    }

    #[test]
    fn verdict_text_per_verdict() {
        assert!(verdict_text(Verdict::Nominal, Some("x"), true).starts_with("**nominal**"));
        assert_eq!(verdict_text(Verdict::Explained, Some("dead_time"), false), "**explained** by `dead_time`");
        assert_eq!(verdict_text(Verdict::Explained, None, false), "**explained** by `?`");
        assert!(verdict_text(Verdict::Unexplained, None, true).ends_with("no effect was fitted"));
        assert!(verdict_text(Verdict::Unexplained, None, false).contains("nor a pair"));
    }

    #[test]
    fn calibration_section_against_the_rig() {
        let c = Calibration {
            rope_ea_n: 1.2345e6,
            guide_damping_kg_per_s: 150.04,
            sheave_damping_nms_per_rad: 2.9996,
            reference_tension_n: None,
            decays: Vec::new(),
            travels: vec![("a".to_string(), 3.0), ("b".to_string(), 3.1)],
            skipped: vec!["x: short".to_string(), "y: flat".to_string()],
            nominal: (1.0e6, 148.0, 3.0),
        };
        let mut s = String::new();
        calibration_section(&mut s, &c);
        assert_eq!(
            s,
            "\n## Calibration (step 1)\n\nEA 1.2345e6 N (rig 1.0000e6), guide damping 150.0 kg/s (rig 148.0), sheave \
             damping 3.000 N m s/rad (rig 3.000); 0 decays, 2 travels used. Skipped: x: short; y: flat.\n\n"
        );
    }

    #[test]
    fn the_pulley_note_gives_the_equivalent_mass_the_recordings_fix() {
        let p = plant::effects::DivertingPulley {
            inertia_kg_m2: 0.0338,
            radius_m: 0.065,
            sheave_to_pulley_m: 0.5,
            damping_ratio: 0.02,
        };
        // 0.0338 / 0.065^2 = 8.00 kg.
        assert!(pulley_note(&p).contains("J / r_p^2 = 8.00 kg"), "{}", pulley_note(&p));
    }

    #[test]
    fn ranking_section_one_row_per_candidate() {
        let c = Candidate {
            name: "a + b".to_string(),
            parameters: vec![
                FittedParameter {
                    effect: "a",
                    name: "p",
                    unit: "s",
                    value: 0.00125,
                    uncertainty: 2.5e-4,
                    measured_by: None,
                },
                FittedParameter {
                    effect: "b",
                    name: "q",
                    unit: "N",
                    value: 40.0,
                    uncertainty: f64::NAN,
                    measured_by: Some("the currents' balance"),
                },
            ],
            fitted_parameters: 2,
            training_gap_before_db: 1.0,
            training_gap_after_db: 0.5,
            held_out_gap_before_db: 1.2,
            held_out_gap_after_db: 0.3,
            held_out_shrink: 0.75,
            score_db: 0.336,
            effects: Effects::none(),
            naming: crate::naming::Naming { named: true, reason: String::new() },
            ..Candidate::default()
        };
        let mut s = String::new();
        ranking_section(&mut s, &[c.clone(), c]);
        let rows: Vec<&str> = s.lines().filter(|l| l.starts_with("| ") && !l.starts_with("| rank")).collect();
        assert_eq!(rows.len(), 2);
        assert_eq!(
            rows[0],
            "| 1 | a + b | p=1.250e-3+-2.5e-4, q=4.000e1+-NaN (measured) | 1.00/0.50 | 1.20/0.30 | 75 % | 0.34 | yes |"
        );
        assert!(rows[1].starts_with("| 2 | a + b |"));
    }

    #[test]
    fn recordings_section_dashes_what_does_not_apply() {
        let g = |closed, replay, explained| RecordingGap {
            recording: "r".to_string(),
            kind: "travel",
            nominal: GapValue { gap_db: 1.0, noise_db: 0.25, beyond_db: 0.5 },
            nominal_excess_db: 0.5,
            closed_loop_acceleration_excess_db: closed,
            replay_acceleration_excess_db: replay,
            explained: None,
            explained_excess_db: explained,
            begins_in_motion: false,
        };
        let mut s = String::new();
        recordings_section(&mut s, &[g(Some(2.0), Some(0.5), Some(0.25)), g(Some(2.0), None, None)]);
        let rows: Vec<&str> = s.lines().filter(|l| l.starts_with("| r |")).collect();
        assert_eq!(
            rows,
            ["| r | travel | 1.00 | 0.25 | 0.50 | 2.00 / 0.50 | 0.25 |", "| r | travel | 1.00 | 0.25 | 0.50 | - | - |"]
        );
    }

    #[test]
    fn plots_section_only_with_plots() {
        let mut s = String::new();
        plots_section(&mut s, &[]);
        assert!(s.is_empty());
        plots_section(&mut s, &[("map".to_string(), "m.png".to_string())]);
        assert_eq!(s, "## Plots\n\nmap:\n\n![map](m.png)\n\n");
    }
}
