//! `host-sim compare`: every ripple-compensation strategy (and none) over the
//! rig's travels and the model mismatches, as one table (CSV, Markdown,
//! JSON) with plots; `--shard k/N` runs a part of the sweep, `--merge`
//! joins the parts.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context};
use clap::Args;
use drive_core::ripple::harmonics::HarmonicTable;
use drive_core::ripple::Strategy;
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;

use super::output_dir;
use closed_loop::compensation::{all_cases, calibrate_table, run_case, CompareRow};
use plots::{line_plot, Series};
use rig_config::RigConfig;

/// Options of `compare`.
#[derive(Debug, Args)]
pub struct CompareArgs {
    /// Run only part `k` of `N` of the cases (`k/N`, 1 <= k <= N): case `i`
    /// belongs to part `i mod N + 1`. Merge the parts with `--merge`.
    #[arg(long, value_name = "K/N")]
    pub shard: Option<String>,
    /// Merge the `compare.csv` files of shards into one table instead of simulating.
    #[arg(long, value_name = "CSV", num_args = 1..)]
    pub merge: Vec<PathBuf>,
    /// Only the nominal plant (no mismatch cases).
    #[arg(long)]
    pub nominal_only: bool,
    /// Travels iterative learning runs before the measured one.
    #[arg(long, value_name = "N", default_value_t = 3, allow_negative_numbers = true)]
    pub learning_travels: usize,
    /// Output directory.
    #[arg(long, value_name = "DIR", default_value = "out/compare")]
    pub out: PathBuf,
    /// Replace the tables of an earlier run (default: refuse to overwrite).
    #[arg(long)]
    pub force: bool,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// The strategies `compare` runs: all of them.
pub const STRATEGIES: [Strategy; 5] = Strategy::ALL;

/// `k/N` of `--shard`.
fn parse_shard(text: &str) -> anyhow::Result<(usize, usize)> {
    let bad = || anyhow::anyhow!("--shard {text:?}: expected K/N with whole numbers 1 <= K <= N");
    let (k, n) = text.split_once('/').ok_or_else(bad)?;
    let (k, n): (usize, usize) = (k.trim().parse().map_err(|_| bad())?, n.trim().parse().map_err(|_| bad())?);
    if k == 0 || n == 0 || k > n {
        return Err(bad());
    }
    Ok((k, n))
}

/// Runs `compare`.
pub fn run(rig: &RigConfig, args: &CompareArgs) -> anyhow::Result<()> {
    if !args.merge.is_empty() {
        if args.shard.is_some() {
            bail!("--merge and --shard exclude each other");
        }
        let rows = merge_shards(&args.merge)?;
        let out = output_dir(&args.out, args.force)?;
        out.refuse_existing(OUTPUTS)?;
        write_outputs(&out, &rows, None)?;
        out.commit()?;
        return Ok(());
    }
    if args.learning_travels > 50 {
        bail!("--learning-travels {}: expected at most 50", args.learning_travels);
    }
    let shard = args.shard.as_deref().map(parse_shard).transpose()?;
    let out = output_dir(&args.out, args.force)?;
    out.refuse_existing(OUTPUTS)?;
    let started = Instant::now();
    let table = calibrate_table(rig).context("calibration travel for the `Strategy::Table` table")?;
    let cases: Vec<(usize, _)> = all_cases(rig)
        .into_iter()
        .enumerate()
        .filter(|(_, c)| !args.nominal_only || c.mismatch == closed_loop::compensation::Mismatch::Nominal)
        .filter(|(i, _)| shard.is_none_or(|(k, n)| i % n + 1 == k))
        .collect();
    let bar = if args.quiet { ProgressBar::hidden() } else { ProgressBar::new(cases.len() as u64) };
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} cases {elapsed_precise} eta {eta}")?
            .progress_chars("=> "),
    );
    bar.set_message("compare");
    let results: Vec<anyhow::Result<Vec<CompareRow>>> = cases
        .par_iter()
        .map(|(i, case)| {
            let rows = run_case(rig, *i, case, &table, &STRATEGIES, args.learning_travels).with_context(|| {
                format!("case {i}: {} kg {:?} {}", case.m_car_kg, case.direction, case.mismatch.label())
            });
            bar.inc(1);
            rows
        })
        .collect();
    bar.finish_and_clear();
    let mut rows = Vec::new();
    for r in results {
        rows.extend(r?);
    }
    let wall = started.elapsed().as_secs_f64();
    outln!("{} cases x {} strategies in {wall:.1} s", cases.len(), STRATEGIES.len());
    write_outputs(&out, &rows, Some(&table))?;
    out.commit()?;
    Ok(())
}

/// Files `compare` writes.
const OUTPUTS: [&str; 6] =
    ["compare.csv", "compare.json", "compare.md", "compare_summary.md", "compare_12x.png", "compare_a95.png"];

/// Largest `compare.csv` that `--merge` reads, bytes (a full sweep's is
/// about 100 kB).
const MAX_MERGE_CSV_BYTES: u64 = 64 << 20;

/// The rows of every shard `paths`, sorted by case. Refused: a file with no
/// row (not a shard), and a case and strategy given twice (the same shard
/// merged twice, or overlapping shards), naming both files.
fn merge_shards(paths: &[PathBuf]) -> anyhow::Result<Vec<CompareRow>> {
    let mut rows: Vec<(CompareRow, &Path)> = Vec::new();
    for path in paths {
        let shard = read_rows(path)?;
        if shard.is_empty() {
            bail!(
                "{}: no data row; expected a compare.csv written by `host-sim compare --shard` (a header and one \
                 row per case and strategy)",
                path.display()
            );
        }
        for row in shard {
            if let Some((_, first)) =
                rows.iter().find(|(r, _)| r.case_index == row.case_index && r.strategy == row.strategy)
            {
                bail!(
                    "--merge: case {} with strategy `{}` is in {} and again in {}; expected each case once (merge \
                     every shard once, shards of one sweep)",
                    row.case_index,
                    row.strategy,
                    first.display(),
                    path.display()
                );
            }
            rows.push((row, path));
        }
    }
    let mut rows: Vec<CompareRow> = rows.into_iter().map(|(r, _)| r).collect();
    rows.sort_by_key(|r| r.case_index);
    Ok(rows)
}

fn read_rows(path: &Path) -> anyhow::Result<Vec<CompareRow>> {
    let size = std::fs::metadata(path).with_context(|| format!("cannot read {}", path.display()))?.len();
    if size > MAX_MERGE_CSV_BYTES {
        bail!(
            "{}: {size} bytes; expected a compare.csv of at most {MAX_MERGE_CSV_BYTES} bytes (a full sweep's is \
             about 100 kB)",
            path.display()
        );
    }
    let mut reader = csv::Reader::from_path(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut rows = Vec::new();
    for (i, row) in reader.deserialize().enumerate() {
        let row: CompareRow =
            row.with_context(|| format!("{}: data row {}: not a compare.csv row", path.display(), i + 1))?;
        rows.push(row);
    }
    Ok(rows)
}

/// The summary per plant case and strategy, in the order the rows first
/// name them: travels run, the order-12 change and the A95 change against
/// no compensation (mean over the case's travels, the worst in brackets),
/// the mean A95 and order-36 and order-72 amplitudes, the largest peak
/// current, the median learning time, the travels where a harmonic backed off.
fn summary_markdown(rows: &[CompareRow]) -> String {
    let mut md = String::from(
        "| plant | strategy | travels | car 12x vs off dB (worst) | A95 vs off dB (worst) | A95 mg mean | car 36x mean m/s^2 | car 72x mean m/s^2 | peak current A (max) | learning s (median) | backed off (travels) |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let mut groups: Vec<(&str, &str)> = Vec::new();
    for r in rows {
        if !groups.contains(&(r.mismatch.as_str(), r.strategy.as_str())) {
            groups.push((r.mismatch.as_str(), r.strategy.as_str()));
        }
    }
    for (mismatch, strategy) in groups {
        let g: Vec<&CompareRow> = rows.iter().filter(|r| r.mismatch == mismatch && r.strategy == strategy).collect();
        let n = g.len() as f64;
        let mean = |f: &dyn Fn(&CompareRow) -> f64| g.iter().map(|r| f(r)).sum::<f64>() / n;
        let worst = |f: &dyn Fn(&CompareRow) -> f64| g.iter().map(|r| f(r)).fold(f64::NEG_INFINITY, f64::max);
        let a95_db = |r: &CompareRow| 20.0 * (1.0 + r.a95_change_pct / 100.0).max(1e-12).log10();
        let mut learning: Vec<f64> = g.iter().filter_map(|r| r.learning_time_s).collect();
        learning.sort_by(f64::total_cmp);
        let median = learning.get(learning.len() / 2).map_or("-".to_string(), |v| format!("{v:.1}"));
        md += &format!(
            "| {mismatch} | {strategy} | {} | {:+.1} ({:+.1}) | {:+.1} ({:+.1}) | {:.1} | {:.4} | {:.4} | {:.1} | {median} | {} |\n",
            g.len(),
            mean(&|r| r.car_12x_change_db),
            worst(&|r| r.car_12x_change_db),
            mean(&a95_db),
            worst(&a95_db),
            mean(&|r| r.a95_mg),
            mean(&|r| r.car_36x_mps2),
            mean(&|r| r.car_72x_mps2),
            worst(&|r| r.peak_current_a),
            g.iter().filter(|r| !r.backed_off_orders.is_empty()).count()
        );
    }
    md
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map_or("never".into(), |v| format!("{v:.1}"))
}

fn write_outputs(
    output: &crate::output::OutputDir,
    rows: &[CompareRow],
    table: Option<&HarmonicTable>,
) -> anyhow::Result<()> {
    let out = output.staging();
    let csv_path = out.join("compare.csv");
    let mut writer =
        csv::Writer::from_path(&csv_path).with_context(|| format!("cannot write {}", csv_path.display()))?;
    for row in rows {
        writer.serialize(row)?;
    }
    writer.flush()?;
    let json_path = out.join("compare.json");
    let table_json = table.map(|t| {
        (0..t.len)
            .map(|k| serde_json::json!({"order": t.orders[k], "re_nm": t.torque_nm[k].re, "im_nm": t.torque_nm[k].im}))
            .collect::<Vec<_>>()
    });
    std::fs::write(
        &json_path,
        serde_json::to_string_pretty(&serde_json::json!({"calibrated_table": table_json, "rows": rows}))?,
    )?;

    let mut md = String::from(
        "| case | m_car kg | dir | mismatch | strategy | A95 mg | max p-p mg | car 12x m/s^2 | 12x vs off dB | A95 vs off % | car 36x | car 72x | peak current A | learning s | travels | backed off |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        md += &format!(
            "| {} | {} | {} | {} | {} | {:.2} | {:.2} | {:.4} | {:+.1} | {:+.0} | {:.4} | {:.4} | {:.1} | {} | {} | {} |\n",
            r.case_index,
            r.m_car_kg,
            r.direction,
            r.mismatch,
            r.strategy,
            r.a95_mg,
            r.max_peak_to_peak_mg,
            r.car_12x_mps2,
            r.car_12x_change_db,
            r.a95_change_pct,
            r.car_36x_mps2,
            r.car_72x_mps2,
            r.peak_current_a,
            fmt_opt(r.learning_time_s),
            r.travels,
            r.backed_off_orders
        );
    }
    let md_path = out.join("compare.md");
    std::fs::write(&md_path, md)?;
    std::fs::write(out.join("compare_summary.md"), summary_markdown(rows))?;

    // Per strategy: order-12 change and A95 change against the case index.
    let mut strategies: Vec<&str> = rows.iter().map(|r| r.strategy.as_str()).collect();
    strategies.sort();
    strategies.dedup();
    let series = |f: &dyn Fn(&CompareRow) -> f64| -> Vec<Series> {
        strategies
            .iter()
            .filter(|s| **s != "off")
            .map(|s| {
                let (x, y) = rows.iter().filter(|r| r.strategy == *s).map(|r| (r.case_index as f64, f(r))).unzip();
                Series::new(*s, x, y)
            })
            .collect()
    };
    let db_path = out.join("compare_12x.png");
    let a95_path = out.join("compare_a95.png");
    let s12 = series(&|r| r.car_12x_change_db);
    if !s12.is_empty() {
        line_plot(&db_path, "Car acceleration at 12 x f_mech against no compensation", "case", "change [dB]", &s12)?;
        line_plot(
            &a95_path,
            "Car A95 (ISO 18738-1) against no compensation",
            "case",
            "change [%]",
            &series(&|r| r.a95_change_pct),
        )?;
        outln!("plots: {}, {}", output.published(&db_path).display(), output.published(&a95_path).display());
    }
    outln!(
        "table: {}, {}, {}",
        output.published(&csv_path).display(),
        output.published(&md_path).display(),
        output.published(&json_path).display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(strategy: &str, change_db: f64, a95_pct: f64, learning: Option<f64>, backed_off: &str) -> CompareRow {
        CompareRow {
            case_index: 0,
            strategy: strategy.into(),
            m_car_kg: 70.5,
            direction: "up".into(),
            mismatch: "nominal".into(),
            a95_mg: 10.0 * (1.0 + a95_pct / 100.0),
            max_peak_to_peak_mg: 0.0,
            car_12x_mps2: 0.0,
            car_36x_mps2: 0.01,
            car_72x_mps2: 0.002,
            car_12x_change_db: change_db,
            a95_change_pct: a95_pct,
            peak_current_a: 5.0 - change_db / 10.0,
            learning_time_s: learning,
            travels: 1,
            backed_off_orders: backed_off.into(),
        }
    }

    #[test]
    fn the_summary_takes_means_worst_cases_medians_and_counts_per_group() {
        let rows = [
            row("off", 0.0, 0.0, None, ""),
            row("off", 0.0, 0.0, None, ""),
            row("adaptive", -10.0, -50.0, Some(1.0), ""),
            row("adaptive", -20.0, -75.0, Some(3.0), "12"),
            row("adaptive", -30.0, -90.0, Some(2.0), ""),
        ];
        let md = summary_markdown(&rows);
        let lines: Vec<&str> = md.lines().collect();
        assert_eq!(lines.len(), 4, "{md}");
        assert_eq!(
            lines[2],
            "| nominal | off | 2 | +0.0 (+0.0) | +0.0 (+0.0) | 10.0 | 0.0100 | 0.0020 | 5.0 | - | 0 |"
        );
        // A95 -50 %, -75 %, -90 %: 20 log10 of 0.5, 0.25, 0.1 = -6.02, -12.04,
        // -20 dB, mean -12.69 dB; A95 5, 2.5 and 1 mg, mean 2.83 mg; peak
        // current 6, 7 and 8 A; learning times 1, 2, 3 s: median 2 s.
        assert_eq!(
            lines[3],
            "| nominal | adaptive | 3 | -20.0 (-10.0) | -12.7 (-6.0) | 2.8 | 0.0100 | 0.0020 | 8.0 | 2.0 | 1 |"
        );
    }
}
