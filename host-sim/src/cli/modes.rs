//! `host-sim modes`: Eqn 10 over the travel (paper Fig. 5).

use std::io::Write;
use std::path::PathBuf;

use clap::Args;

use super::{car_mass_kg, check_open_range, output_dir, readable, sweep_points};
use plant::modes::natural_modes;
use plant::rope::{ChainParams, COORDINATE_NAMES, DOF};
use plots::{line_plot, stacked_plot, Band, Level, Panel, Series};
use rig_config::RigConfig;

/// Options of `modes`.
#[derive(Debug, Args)]
pub struct ModesArgs {
    /// Car mass, kg (default: the heaviest car of the rig).
    #[arg(long = "m-car", value_name = "KG", allow_negative_numbers = true)]
    pub m_car_kg: Option<f64>,
    /// Smallest counterweight-side rope length, m (default: 0.1).
    #[arg(long = "lw-from", value_name = "M", allow_negative_numbers = true)]
    pub lw_from_m: Option<f64>,
    /// Largest counterweight-side rope length, m (default: l_t - 0.1).
    #[arg(long = "lw-to", value_name = "M", allow_negative_numbers = true)]
    pub lw_to_m: Option<f64>,
    /// Step of the rope length, m.
    #[arg(long = "lw-step", value_name = "M", default_value_t = 0.05, allow_negative_numbers = true)]
    pub lw_step_m: f64,
    /// Output directory.
    #[arg(long, value_name = "DIR", default_value = "out/modes")]
    pub out: PathBuf,
    /// Replace the outputs of an earlier run (default: refuse to overwrite).
    #[arg(long)]
    pub force: bool,
}

/// The travel of the rig (`[travel]` `lw_low_m` to `lw_high_m`), shaded.
fn travel_band(rig: &RigConfig) -> Band {
    let t = &rig.travel;
    Band { x0: t.lw_low_m, x1: t.lw_high_m, label: format!("travel, lw {} -> {} m", t.lw_low_m, t.lw_high_m) }
}

/// The natural frequencies `series` (0-`band_hz`) with the torque-ripple
/// excitation lines of the rig (`[[ripple]]`, n x f_mech at the rated speed)
/// drawn across.
fn annotated(rig: &RigConfig, series: Vec<Series>, band_hz: f64) -> Panel {
    let f_mech = rig.travel.rated_speed_mps / (2.0 * std::f64::consts::PI * rig.mechanics.sheave_radius_m);
    let (x0, x1) = series
        .iter()
        .flat_map(|s| s.x.iter())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    let levels = rig
        .ripple
        .iter()
        .map(|r| (r, r.mechanical_order as f64 * f_mech))
        .filter(|(_, f)| *f <= band_hz)
        .map(|(r, f)| Level { y: f, x0, x1, label: format!("{}x f_mech = {f:.2} Hz ({})", r.mechanical_order, r.name) })
        .collect();
    Panel { y_label: "frequency [Hz]".to_string(), series, marks: vec![], levels }
}

/// Runs `modes`: writes `modes.csv`, `mode_shapes.csv`, `modes.png` (0 to
/// the spectrogram band, the ripple excitation lines at the rated speed and
/// the travel marked) and `modes_0-128hz.png` (the curves alone, as the
/// paper's Fig. 5); `modes.csv` holds every mode.
pub fn run(rig: &RigConfig, args: &ModesArgs) -> anyhow::Result<()> {
    let total = rig.mechanics.rope_total_length_m;
    let m_car = car_mass_kg(rig, args.m_car_kg)?;
    let lw_from = args.lw_from_m.unwrap_or(0.1);
    let lw_to = args.lw_to_m.unwrap_or(total - 0.1);
    check_open_range("--lw-from", lw_from, 1.0e-3, total)?;
    check_open_range("--lw-to", lw_to, lw_from, total)?;
    check_open_range("--lw-step", args.lw_step_m, 0.0, total)?;
    let count = sweep_points("--lw-step", lw_from, lw_to, args.lw_step_m)?;
    let band = rig.measurement.spectrogram_band_hz[1];
    let band_png = format!("modes_0-{band}hz.png");
    let out = output_dir(&args.out, args.force)?;
    out.refuse_existing(["modes.csv", "mode_shapes.csv", "modes.png", band_png.as_str()])?;

    let chain = ChainParams::from_rig(rig, m_car);
    // Lengths on the step grid, rounded so that e.g. 4.0 prints as 4.
    let lengths: Vec<f64> = (0..count).map(|i| ((lw_from + i as f64 * args.lw_step_m) * 1e9).round() / 1e9).collect();
    let modes: Vec<_> = lengths.iter().map(|&lw| natural_modes(&chain, lw)).collect();

    let csv_path = out.path("modes.csv");
    let mut csv = out.writer("modes.csv")?;
    writeln!(csv, "lw_m,f1_hz,f2_hz,f3_hz,f4_hz,f5_hz")?;
    for (lw, m) in lengths.iter().zip(&modes) {
        let f = m.frequencies_hz;
        writeln!(csv, "{lw},{},{},{},{},{}", f[0], f[1], f[2], f[3], f[4])?;
    }
    csv.flush()?;

    let shapes_path = out.path("mode_shapes.csv");
    let mut shapes = out.writer("mode_shapes.csv")?;
    writeln!(shapes, "lw_m,mode,f_hz,{}", COORDINATE_NAMES.map(|n| format!("u_{n}")).join(","))?;
    for (lw, m) in lengths.iter().zip(&modes) {
        for mode in 0..DOF {
            let u = m.shapes[mode].map(|v| v.to_string()).join(",");
            writeln!(shapes, "{lw},{},{},{u}", mode + 1, m.frequencies_hz[mode])?;
        }
    }
    shapes.flush()?;

    let series = |max_hz: f64| -> Vec<Series> {
        (1..DOF)
            .filter(|&k| modes.iter().any(|m| m.frequencies_hz[k] <= max_hz))
            .map(|k| {
                let (x, y): (Vec<f64>, Vec<f64>) = lengths
                    .iter()
                    .zip(&modes)
                    .map(|(&lw, m)| (lw, if m.frequencies_hz[k] <= max_hz { m.frequencies_hz[k] } else { f64::NAN }))
                    .unzip();
                Series::new(format!("f{}", k + 1), x, y)
            })
            .collect()
    };
    let title = format!("Natural frequencies (Eqn 10), m_car = {m_car} kg, m_cw = {} kg", rig.mechanics.m_cw_kg);
    let lw_label = "counterweight-side rope length lw [m]";
    stacked_plot(
        &out.path("modes.png"),
        &format!("{title}, 0-{band} Hz"),
        lw_label,
        &[annotated(rig, series(band), band)],
        &[travel_band(rig)],
    )?;
    line_plot(&out.path(&band_png), &format!("{title}, 0-{band} Hz"), lw_label, "frequency [Hz]", &series(band))?;

    outln!(
        "m_car = {m_car} kg: natural frequencies at {} rope lengths from {} to {} m",
        lengths.len(),
        readable(lw_from),
        readable(lw_to)
    );
    outln!("{:>8} {:>9} {:>9} {:>9} {:>9} {:>9}", "lw [m]", "f1 [Hz]", "f2 [Hz]", "f3 [Hz]", "f4 [Hz]", "f5 [Hz]");
    let stride = (lengths.len() / 12).max(1);
    for (i, (lw, m)) in lengths.iter().zip(&modes).enumerate() {
        if i % stride == 0 || (lw - 4.0).abs() < 1e-9 || i + 1 == lengths.len() {
            let f = m.frequencies_hz;
            outln!("{lw:8.3} {:9.2} {:9.2} {:9.2} {:9.2} {:9.2}", f[0], f[1], f[2], f[3], f[4]);
        }
    }
    let (csv_path, shapes_path) = (out.published(&csv_path), out.published(&shapes_path));
    out.commit()?;
    outln!("wrote {}, {} and plots in {}", csv_path.display(), shapes_path.display(), args.out.display());
    Ok(())
}
