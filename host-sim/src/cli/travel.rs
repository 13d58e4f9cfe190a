//! `host-sim travel`: one closed-loop travel, its recording and plots.

use std::path::PathBuf;
use std::time::Instant;

use clap::{Args, ValueEnum};
use drive_core::config::Direction;
use drive_core::ripple::Strategy;
use drive_core::Controller;
use indicatif::{ProgressBar, ProgressStyle};

use super::{car_mass_kg, check_open_range, check_physical_range, output_dir, readable};
use closed_loop::compensation::{compensator, rig_ripple_table};
use closed_loop::{simulate_travel_with, SimOptions, TravelSpec};
use dsp::{highpass_zero_phase, stft_spectrogram, Spectrogram};
use plant::effects::Effects;
use plant::modes::natural_modes;
use plant::rope::{ChainParams, DOF};
use plots::{line_plot, spectrogram_plot_with_top_axis, Series, TopAxis};
use recording::write::write_recording;
use rig_config::RigConfig;

/// Car direction on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum DirectionArg {
    /// Car up (lw grows).
    Up,
    /// Car down (lw shrinks).
    Down,
}

/// Options of `travel`.
#[derive(Debug, Args)]
pub struct TravelArgs {
    /// Car mass, kg (default: the heaviest car of the rig).
    #[arg(long = "m-car", value_name = "KG", allow_negative_numbers = true)]
    pub m_car_kg: Option<f64>,
    /// Car direction.
    #[arg(long, value_enum, default_value_t = DirectionArg::Up)]
    pub direction: DirectionArg,
    /// Counterweight-side rope length at the start, m (default: the rig's travel range).
    #[arg(long = "lw-start", value_name = "M", allow_negative_numbers = true)]
    pub lw_start_m: Option<f64>,
    /// Counterweight-side rope length at the end, m (default: the rig's travel range).
    #[arg(long = "lw-end", value_name = "M", allow_negative_numbers = true)]
    pub lw_end_m: Option<f64>,
    /// Longest RK4 step, s, of plants with effects (default: a quarter of a PWM
    /// period); the nominal plant takes one exact step per PWM half period.
    #[arg(long = "max-step", value_name = "S", allow_negative_numbers = true)]
    pub max_step_s: Option<f64>,
    /// Spectrogram window, s.
    #[arg(long = "spectrogram-window", value_name = "S", default_value_t = 2.0, allow_negative_numbers = true)]
    pub spectrogram_window_s: f64,
    /// Recording stem (default: travel_<direction>_m<mass>).
    #[arg(long)]
    pub stem: Option<String>,
    /// Output directory (the dataset).
    #[arg(long, value_name = "DIR", default_value = "out/travel")]
    pub out: PathBuf,
    /// Replace a recording and plots of the same stem (default: refuse to overwrite).
    #[arg(long)]
    pub force: bool,
    /// Torque-ripple compensation of the drive.
    #[arg(long, value_enum, default_value_t = CompensationArg::Off)]
    pub compensation: CompensationArg,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Effects of the library on the simulated plant, from a TOML file
    /// (`[name]` tables of parameters; see `plant::effects`).
    #[arg(long = "effects", value_name = "FILE")]
    pub effects_file: Option<PathBuf>,
    /// One effect on the simulated plant, `NAME` (default parameters) or
    /// `NAME:param=value,...`; repeatable, applied after `--effects`.
    #[arg(long = "effect", value_name = "NAME[:PARAM=VALUE,...]")]
    pub effect: Vec<String>,
}

/// Ripple compensation on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum CompensationArg {
    /// None.
    Off,
    /// Strategy 1 with the rig file's own `[[ripple]]` as its table, back-off
    /// disabled: the exact cancellation of the simulated ripple, so that the
    /// machine torque from the currents carries the rig's ripple amplitudes
    /// (a check of the measurement chain; a real rig must identify its table).
    RigTable,
    /// Strategy 2: adaptive harmonics learned during the travel.
    Adaptive,
}

/// The travel `args` ask for: the car mass, the direction, and the rope
/// lengths at start and end, each checked to leave both rope sides their
/// shortest length.
fn travel_spec(rig: &RigConfig, args: &TravelArgs) -> anyhow::Result<TravelSpec> {
    let total = rig.mechanics.rope_total_length_m;
    let m_car = car_mass_kg(rig, args.m_car_kg)?;
    let direction = match args.direction {
        DirectionArg::Up => Direction::Up,
        DirectionArg::Down => Direction::Down,
    };
    let mut spec = TravelSpec::full_travel(rig, m_car, direction);
    let side = rig_config::MIN_ROPE_SIDE_M;
    let why = format!(
        "each rope side keeps at least {} m of [mechanics].rope_total_length_m = {} m (a shorter one rings too \
         fast to simulate)",
        readable(side),
        readable(total)
    );
    if let Some(lw) = args.lw_start_m {
        check_physical_range("--lw-start", lw, side, total - side, "m", &why)?;
        spec.lw_start_m = lw;
    }
    if let Some(lw) = args.lw_end_m {
        check_physical_range("--lw-end", lw, side, total - side, "m", &why)?;
        spec.lw_end_m = lw;
    }
    Ok(spec)
}

/// The drive's controller with the ripple compensation `compensation`, and
/// how the recording describes it.
fn controller_for(rig: &RigConfig, compensation: CompensationArg) -> (Controller, &'static str) {
    let mut controller = Controller::new(&rig.drive_config());
    let description = match compensation {
        CompensationArg::Off => "no ripple compensation",
        CompensationArg::RigTable => {
            let mut c = compensator(rig, Strategy::Table, Some(rig_ripple_table(rig).negated()));
            c.set_back_off(false);
            controller.set_compensation(Some(c));
            "ripple compensation: the rig's ripple as the table (exact cancellation)"
        }
        CompensationArg::Adaptive => {
            controller.set_compensation(Some(compensator(rig, Strategy::Adaptive, None)));
            "ripple compensation: adaptive harmonics"
        }
    };
    (controller, description)
}

/// Runs `travel`.
pub fn run(rig: &RigConfig, args: &TravelArgs) -> anyhow::Result<()> {
    let spec = travel_spec(rig, args)?;
    let (m_car, direction) = (spec.m_car_kg, spec.direction);
    let mut options = SimOptions::for_rig(rig);
    options.effects = Effects::from_file_and_flags(args.effects_file.as_deref(), &args.effect)?;
    if let Some(step) = args.max_step_s {
        // At least 1 ns: a full travel takes about 1.3e6 steps of the
        // default 15.6 us; a much smaller step would run for days.
        check_open_range("--max-step", step, 1e-9, 0.5 / rig.control.current_loop_hz + 1e-15)?;
        options.max_step_s = step;
    }
    // At least 16 samples of the recording: a shorter window resolves nothing.
    let shortest = 16.0 / rig.measurement.sample_rate_hz;
    let why = "at least 16 samples of [measurement].sample_rate_hz, at most a minute";
    check_physical_range("--spectrogram-window", args.spectrogram_window_s, shortest, 60.0, "s", why)?;
    let stem = args
        .stem
        .clone()
        .unwrap_or_else(|| format!("travel_{}_m{m_car}", if direction == Direction::Up { "up" } else { "down" }));
    let out = output_dir(&args.out, args.force)?;
    out.refuse_existing(
        ["toml", "csv"]
            .map(|e| format!("{stem}.{e}"))
            .into_iter()
            .chain(PLOTS.map(|suffix| format!("{stem}_{suffix}.png"))),
    )?;

    let bar = if args.quiet { ProgressBar::hidden() } else { ProgressBar::new(0) };
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:40}] {percent:>3}% {elapsed_precise} eta {eta}")?
            .progress_chars("=> "),
    );
    bar.set_message("simulating");
    let started = Instant::now();
    let (mut controller, description) = controller_for(rig, args.compensation);
    let run = simulate_travel_with(rig, &spec, &options, &mut controller, Some(&bar), None)?;
    let wall = started.elapsed().as_secs_f64();
    outln!(
        "simulated {:.2} s of travel (m_car = {m_car} kg, {direction:?}, lw {} -> {} m, {}) in {wall:.2} s: {:.1}x real time",
        run.duration_s(),
        spec.lw_start_m,
        spec.lw_end_m,
        options.effects.summary(),
        run.duration_s() / wall
    );

    let recording = run.into_recording(
        &spec,
        rig.mechanics.m_cw_kg,
        format!(
            "host-sim closed-loop travel, {}, step {:.3e} s, {description}",
            options.effects.summary(),
            options.max_step_s
        ),
    );
    let columns = RunColumns::of(&recording)?;
    // The recording is written on a second thread while this one draws the
    // plots (both only read its columns).
    let (written, plot_paths) = std::thread::scope(|scope| {
        let writer = scope.spawn(|| write_recording(out.staging(), &stem, &recording));
        let plot_paths = plots(rig, &spec, &columns, args, &stem, &out);
        (writer.join(), plot_paths)
    });
    let (toml_path, csv_path) = written.map_err(|_| anyhow::anyhow!("the thread writing the recording panicked"))??;
    let plot_paths = plot_paths?;
    let (toml_path, csv_path) = (out.published(&toml_path), out.published(&csv_path));
    out.commit()?;
    outln!("recording: {} and {}", toml_path.display(), csv_path.display());
    outln!("plots: {}", plot_paths.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "));
    Ok(())
}

/// STFT spectrogram (90 % overlap, 0-`band_hi` Hz) of the whole record,
/// stop included: the signal is extended by half a window of zeros at each
/// end, so that the first and last frames are centred on its first and last
/// samples; times in s from the record's start.
fn whole_record_spectrogram(x: &[f64], fs: f64, window_s: f64, band_hi: f64) -> anyhow::Result<Spectrogram> {
    let pad = (0.5 * window_s * fs).round() as usize;
    let mut padded = vec![0.0; pad];
    padded.extend_from_slice(x);
    padded.extend(std::iter::repeat_n(0.0, pad));
    let mut spectrogram = stft_spectrogram(&padded, fs, window_s, 0.9, band_hi)?;
    let shift = pad as f64 / fs;
    spectrogram.times_s.iter_mut().for_each(|t| *t -= shift);
    Ok(spectrogram)
}

/// The columns of a travel's recording that its plots draw.
struct RunColumns<'a> {
    /// Sample rate, Hz.
    sample_rate_hz: f64,
    time_s: &'a [f64],
    acc_car_mps2: &'a [f64],
    lw_m: &'a [f64],
    speed_radps: &'a [f64],
    ref_speed_mps: &'a [f64],
}

impl<'a> RunColumns<'a> {
    /// The columns of `recording` (a travel run's, [`TravelRun::into_recording`]).
    fn of(travel: &'a recording::Recording) -> anyhow::Result<Self> {
        let column = |name: &str| {
            travel
                .column(name)
                .map(|c| c.values.as_slice())
                .ok_or_else(|| anyhow::anyhow!("the travel's recording has no column {name}"))
        };
        Ok(Self {
            sample_rate_hz: travel.meta.sample_rate_hz,
            time_s: column(recording::TIME_S)?,
            acc_car_mps2: column(recording::ACC_CAR)?,
            lw_m: column("lw_m")?,
            speed_radps: column(recording::SPEED)?,
            ref_speed_mps: column(recording::REF_SPEED)?,
        })
    }
}

/// The plots of a travel: `<stem>_<suffix>.png`.
const PLOTS: [&str; 3] = ["acc_car_hp", "spectrogram", "drive"];

/// Draws the [`PLOTS`] into `out`; returns their published paths.
fn plots(
    rig: &RigConfig,
    spec: &TravelSpec,
    run: &RunColumns,
    args: &TravelArgs,
    stem: &str,
    out: &crate::output::OutputDir,
) -> anyhow::Result<Vec<PathBuf>> {
    let fs = run.sample_rate_hz;
    let highpass_hz = rig.measurement.highpass_hz;
    let filtered = highpass_zero_phase(run.acc_car_mps2, fs, highpass_hz)?;
    let hp_path = out.path(format!("{stem}_{}.png", PLOTS[0]));
    line_plot(
        &hp_path,
        &format!(
            "{stem}: car acceleration, high-passed at {highpass_hz} Hz (paper Fig. 7), m_car = {} kg",
            spec.m_car_kg
        ),
        "time [s]",
        "acceleration [m/s^2]",
        &[Series::new("car (simulated)", run.time_s.to_vec(), filtered.clone())],
    )?;

    let [band_lo, band_hi] = rig.measurement.spectrogram_band_hz;
    let spectrogram = whole_record_spectrogram(&filtered, fs, args.spectrogram_window_s, band_hi)?;
    let chain = ChainParams::from_rig(rig, spec.m_car_kg);
    let at = |t: f64| ((t.max(0.0) * fs) as usize).min(run.lw_m.len() - 1);
    let modes_over_time: Vec<[f64; DOF]> =
        spectrogram.times_s.iter().map(|&t| natural_modes(&chain, run.lw_m[at(t)]).frequencies_hz).collect();
    let mut overlays: Vec<Series> = (1..DOF)
        .filter(|&k| modes_over_time.iter().any(|f| f[k] >= band_lo && f[k] <= band_hi))
        .map(|k| {
            let y = modes_over_time.iter().map(|f| if f[k] <= band_hi { f[k] } else { f64::NAN }).collect();
            Series::new(format!("model f{}", k + 1), spectrogram.times_s.clone(), y)
        })
        .collect();
    // The ripple orders n x f_mech, f_mech from the encoder speed.
    for order in rig.ripple.iter().map(|r| r.mechanical_order) {
        let y: Vec<f64> = spectrogram
            .times_s
            .iter()
            .map(|&t| order as f64 * run.speed_radps[at(t)].abs() / std::f64::consts::TAU)
            .map(|f| if f > 0.5 && f <= band_hi { f } else { f64::NAN })
            .collect();
        if y.iter().any(|f| f.is_finite()) {
            overlays.push(Series::new(format!("{order}x f_mech"), spectrogram.times_s.clone(), y));
        }
    }
    let (lw0, lw1) = (run.lw_m[0], run.lw_m[run.lw_m.len() - 1]);
    let spectrogram_path = out.path(format!("{stem}_{}.png", PLOTS[1]));
    let rope = TopAxis::at_multiples("counterweight-side rope length lw [m]", run.time_s, run.lw_m, 0.5, 1);
    spectrogram_plot_with_top_axis(
        &spectrogram_path,
        &format!(
            "{stem}: car acceleration (STFT, {} s), lw {lw0:.2} -> {lw1:.2} m, dB re 1 (m/s^2)^2/Hz",
            args.spectrogram_window_s
        ),
        &spectrogram,
        &overlays,
        None,
        Some(&rope),
    )?;

    let drive_path = out.path(format!("{stem}_{}.png", PLOTS[2]));
    let r = rig.mechanics.sheave_radius_m;
    line_plot(
        &drive_path,
        &format!("{stem}: drive, reference and estimated sheave-edge speed"),
        "time [s]",
        "speed [m/s]",
        &[
            Series::new("reference", run.time_s.to_vec(), run.ref_speed_mps.to_vec()),
            Series::new("encoder estimate", run.time_s.to_vec(), run.speed_radps.iter().map(|w| w * r).collect()),
        ],
    )?;
    Ok([hp_path, spectrogram_path, drive_path].iter().map(|p| out.published(p)).collect())
}
