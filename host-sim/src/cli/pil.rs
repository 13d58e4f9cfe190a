//! `host-sim pil`: the plant in the simulator, the drive core in the
//! emulated Cortex-M4F; every step checked bit for bit against the host
//! build, and the cost of each step measured in instructions. With
//! `--dcp`, the chip runs the drive's application layer and this side
//! plays the lift controller on its DCP line ([`dcp`], the harness in the
//! `closed-loop` library).

use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use clap::Args;
use drive_core::config::Direction;
use drive_core::frame::StepReport;
use indicatif::{ProgressBar, ProgressStyle};

use super::travel::DirectionArg;
use super::StrategyArg;
use super::{check_open_range, default_car_mass_kg, output_dir};
use closed_loop::compensation::rig_ripple_table;
use closed_loop::pil::{dcp, default_elf_path, PilOptions, PilTarget};
use closed_loop::{simulate_travel_with, SimOptions, TravelSpec};
use rig_config::RigConfig;

/// Options of `pil`.
#[derive(Debug, Args)]
pub struct PilArgs {
    /// Car mass, kg (default: the heaviest car of the rig).
    #[arg(long = "m-car", value_name = "KG", allow_negative_numbers = true)]
    pub m_car_kg: Option<f64>,
    /// Car direction.
    #[arg(long, value_enum, default_value_t = DirectionArg::Up)]
    pub direction: DirectionArg,
    /// Control steps to run (16 000 per second; the default covers the start
    /// from rest through the acceleration); 0 runs the whole travel.
    #[arg(long, default_value_t = 20_000, allow_negative_numbers = true)]
    pub steps: u64,
    /// The PIL target ELF (default: pil/target/thumbv7em-none-eabihf/release/pil).
    #[arg(long, value_name = "FILE")]
    pub elf: Option<PathBuf>,
    /// The QEMU executable.
    #[arg(long, value_name = "FILE", default_value = "qemu-system-arm")]
    pub qemu: PathBuf,
    /// QEMU `-icount shift`: 2^shift ns of virtual time per instruction.
    #[arg(long = "icount-shift", default_value_t = 5, allow_negative_numbers = true)]
    pub icount_shift: u32,
    /// Ripple compensation on the target (the `Strategy::Table` table: the rig's
    /// `[[ripple]]` negated; `Strategy::CarObserver` adds the chain observer). Learning
    /// runs at rated speed: give `--steps 60000` to reach it.
    #[arg(long, value_enum, default_value_t = StrategyArg::Off)]
    pub compensation: StrategyArg,
    /// Output directory (`pil_steps.csv`, `qemu.log`).
    #[arg(long, value_name = "DIR", default_value = "out/pil")]
    pub out: PathBuf,
    /// Replace the outputs of an earlier run (default: refuse to overwrite).
    #[arg(long)]
    pub force: bool,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Play the lift controller on the DCP line instead: the chip runs the
    /// drive's application layer (DCP slave on its UART1, service port on
    /// UART2, controller), and host-sim sends DCP4 travels to each of
    /// `--landings` in turn from `--start-mm` (the position message, the
    /// speed, the remaining distance, stop and idle, one message every
    /// 15 ms), closed around the plant, every step checked bit for bit
    /// against the host build. Prints a summary per travel and writes
    /// `dcp_travels.csv` and the CPU load of the control interrupt and the
    /// chain observer's task. `--steps` and `--direction` do not apply;
    /// `--m-car` is the car's mass and is set as the drive's load weighing
    /// on the service port, `--compensation` (if not off) the drive's
    /// strategy (`set strategy`).
    #[arg(long)]
    pub dcp: bool,
    /// With `--dcp`: the landings to travel to in turn, mm above the lowest
    /// landing (within the rig's `[travel]`), comma separated.
    #[arg(
        long,
        value_name = "MM,...",
        value_delimiter = ',',
        default_value = "1600,1300,2000",
        allow_negative_numbers = true
    )]
    pub landings: Vec<i32>,
    /// With `--dcp`: where the car starts, mm above the lowest landing.
    #[arg(long = "start-mm", value_name = "MM", default_value_t = 1000.0, allow_negative_numbers = true)]
    pub start_mm: f64,
}

/// Cost of one class of steps, instructions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CostSummary {
    /// Steps in the class.
    pub steps: usize,
    /// Mean, instructions per step.
    pub mean: f64,
    /// Largest, instructions.
    pub max: f64,
}

fn summarize(costs: impl Iterator<Item = f64>) -> Option<CostSummary> {
    let values: Vec<f64> = costs.collect();
    (!values.is_empty()).then(|| CostSummary {
        steps: values.len(),
        mean: values.iter().sum::<f64>() / values.len() as f64,
        max: values.iter().copied().fold(0.0, f64::max),
    })
}

/// Runs `pil`.
pub fn run(rig: &RigConfig, args: &PilArgs) -> anyhow::Result<()> {
    let m_car = args.m_car_kg.unwrap_or_else(|| default_car_mass_kg(rig));
    check_open_range("--m-car", m_car, 0.0, 1.0e5)?;
    if args.dcp {
        return run_dcp(rig, args, m_car);
    }
    anyhow::ensure!(
        (1..=10).contains(&args.icount_shift),
        "--icount-shift = {} is out of range: expected 1 to 10",
        args.icount_shift
    );
    let direction = match args.direction {
        DirectionArg::Up => Direction::Up,
        DirectionArg::Down => Direction::Down,
    };
    let out = output_dir(&args.out, args.force)?;
    out.refuse_existing(["pil_steps.csv", "qemu.log"])?;
    let result = run_in(rig, args, m_car, direction, &out);
    if result.is_err() && !out.path("qemu.log").exists() {
        // QEMU never ran: nothing to keep.
        return result;
    }
    // The QEMU log is published also when the run fails: it tells why.
    let published = out.commit();
    result?;
    published?;
    outln!(
        "per-step costs: {}; QEMU log (defmt over semihosting): {}",
        args.out.join("pil_steps.csv").display(),
        args.out.join("qemu.log").display()
    );
    Ok(())
}

/// The PIL run of `run`, its files written into `out`.
fn run_in(
    rig: &RigConfig,
    args: &PilArgs,
    m_car: f64,
    direction: Direction,
    out: &crate::output::OutputDir,
) -> anyhow::Result<()> {
    let options = PilOptions {
        elf: args.elf.clone().unwrap_or_else(default_elf_path),
        qemu: args.qemu.clone(),
        icount_shift: args.icount_shift,
        log: Some(out.path("qemu.log")),
        ..PilOptions::default()
    };
    let drive = rig.drive_config();
    let mut target = PilTarget::launch(&options, &drive)?;
    let strategy = args.compensation.strategy();
    target.install_compensation(strategy, &rig_ripple_table(rig).negated(), &rig.observer_model())?;
    let spec = TravelSpec::full_travel(rig, m_car, direction);
    let sim_options =
        SimOptions { max_control_steps: (args.steps > 0).then_some(args.steps), ..SimOptions::for_rig(rig) };

    let bar = if args.quiet { ProgressBar::hidden() } else { ProgressBar::new(0) };
    bar.set_style(ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} steps {elapsed_precise} eta {eta}")?);
    bar.set_message("PIL");
    let started = Instant::now();
    let run = simulate_travel_with(rig, &spec, &sim_options, &mut target, Some(&bar), None)?;
    let wall = started.elapsed().as_secs_f64();
    let reports = target.reports();
    outln!(
        "{} control steps ({:.2} s of travel, m_car = {m_car} kg, {direction:?}, compensation {}) on the emulated \
         Cortex-M4F in {wall:.1} s: every output bit-identical to the host build",
        reports.len(),
        run.duration_s(),
        strategy.name()
    );

    let per_tick = target.instructions_per_tick();
    let divider = drive.speed_loop_divider() as usize;
    let instructions = |r: &StepReport| r.cost_ticks as f64 * per_tick;
    // Step k runs the speed loop when k is a multiple of the divider.
    let class_of = |i: usize, r: &StepReport| match (r.pwm_enabled, i % divider == 0) {
        (true, false) => 0,
        (true, true) => 1,
        (false, _) => 2,
    };
    let names = [
        "current loop + SVM (PWM on, no speed-loop tick)",
        "current loop + speed loop tick (every 8th step)",
        "idle (PWM off: supervisor only)",
    ];
    outln!("instructions per step under QEMU -icount shift={} ({per_tick} per SysTick tick):", args.icount_shift);
    outln!("{:<50} {:>7} {:>9} {:>9}", "steps", "count", "mean", "max");
    for (class, name) in names.iter().enumerate() {
        let costs = reports.iter().enumerate().filter(|(i, r)| class_of(*i, r) == class).map(|(_, r)| instructions(r));
        if let Some(s) = summarize(costs) {
            outln!("{name:<50} {:>7} {:>9.1} {:>9.1}", s.steps, s.mean, s.max);
        }
    }
    if let Some(s) = summarize(reports.iter().map(instructions)) {
        outln!("{:<50} {:>7} {:>9.1} {:>9.1}", "all steps", s.steps, s.mean, s.max);
    }

    let mut csv = out.writer("pil_steps.csv")?;
    writeln!(csv, "step,state,pwm_enabled,speed_loop_tick,cost_ticks,instructions")?;
    for (i, r) in reports.iter().enumerate() {
        writeln!(
            csv,
            "{i},{},{},{},{},{}",
            r.state.code(),
            r.pwm_enabled as u8,
            (i % divider == 0) as u8,
            r.cost_ticks,
            instructions(r)
        )?;
    }
    csv.flush()?;
    Ok(())
}

/// One travel of `pil --dcp`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TravelSummary {
    /// Where the car started, mm above the lowest landing.
    pub from_mm: f64,
    /// The target landing, mm.
    pub target_mm: i32,
    /// Where the car stopped, mm.
    pub landed_mm: f64,
    /// Control steps from the position message to the stop.
    pub steps: u64,
    /// Largest car speed measured by the drive, m/s.
    pub peak_speed_mps: f64,
}

impl TravelSummary {
    /// The columns of [`TravelSummary::row`] (`dcp_travels.csv`'s header).
    pub const COLUMNS: [&'static str; 8] =
        ["travel", "from_mm", "target_mm", "landed_mm", "error_mm", "steps", "time_s", "peak_speed_mps"];

    /// Travel number `travel` as a row of [`TravelSummary::COLUMNS`]; the
    /// time from the steps at `loop_hz` (Hz).
    pub fn row(&self, travel: usize, loop_hz: f64) -> [f64; 8] {
        [
            travel as f64,
            self.from_mm,
            f64::from(self.target_mm),
            self.landed_mm,
            self.landed_mm - f64::from(self.target_mm),
            self.steps as f64,
            self.steps as f64 / loop_hz,
            self.peak_speed_mps,
        ]
    }
}

/// Checks the `--dcp` landings: inside the shaft of `shaft_mm` mm, each
/// at least 10 mm from the one before (the first from `start_mm`).
pub fn check_landings(landings: &[i32], start_mm: f64, shaft_mm: u32) -> anyhow::Result<()> {
    anyhow::ensure!(!landings.is_empty(), "--landings is empty: expected at least one landing");
    anyhow::ensure!(
        start_mm.is_finite() && (0.0..=shaft_mm as f64).contains(&start_mm),
        "--start-mm = {start_mm} is out of range: expected 0 to {shaft_mm} mm (the rig's [travel])"
    );
    let mut previous = start_mm;
    for &landing in landings {
        anyhow::ensure!(
            (0..=shaft_mm as i64).contains(&(landing as i64)),
            "--landings: {landing} mm is out of range: expected 0 to {shaft_mm} mm (the rig's [travel])"
        );
        anyhow::ensure!(
            (landing as f64 - previous).abs() >= 10.0,
            "--landings: {landing} mm is less than 10 mm from the car's position before it ({previous} mm)"
        );
        previous = landing as f64;
    }
    Ok(())
}

/// Runs `pil --dcp`: the chip started with the car mass and strategy set,
/// the travels to each landing, their summary printed and written.
fn run_dcp(rig: &RigConfig, args: &PilArgs, m_car: f64) -> anyhow::Result<()> {
    let (geometry, _) = dcp::geometry(rig);
    check_landings(&args.landings, args.start_mm, geometry.shaft_travel_mm)?;
    let out = output_dir(&args.out, args.force)?;
    out.refuse_existing(["dcp_travels.csv"])?;
    // QEMU's working directory (where the target would keep its flash file):
    // fresh, so the chip starts with no stored parameters.
    let chip_dir = out.path("chip");
    std::fs::create_dir_all(&chip_dir).with_context(|| format!("cannot create {}", chip_dir.display()))?;
    let mut lift = start_dcp_lift(rig, args, m_car, &chip_dir)?;
    let drive = rig.drive_config();
    let started = Instant::now();
    let (k, master, peaks, load) = run_dcp_travels(args, &drive, &mut lift)?;
    let wall = started.elapsed().as_secs_f64();
    let summaries = travel_summaries(args.start_mm, &master.arrivals, &peaks);
    outln!(
        "{k} control steps ({:.2} s) of DCP4 travels on the emulated Cortex-M4F in {wall:.1} s, m_car = {m_car} kg, \
         compensation {}: every output, DCP reply and service answer bit-identical to the host build",
        k as f64 / drive.current_loop_hz as f64,
        args.compensation.strategy().name()
    );
    outln!("{}", load.summary());
    let missed = lift.shadow().controller().observer_missed_deadlines();
    if lift.shadow().controller().uses_observer() {
        outln!("chain observer: {missed} missed deadlines");
    }
    let loop_hz = drive.current_loop_hz as f64;
    print_travel_table(&summaries, loop_hz);
    let mut csv = out.writer("dcp_travels.csv")?;
    writeln!(csv, "{}", TravelSummary::COLUMNS.join(","))?;
    for (i, s) in summaries.iter().enumerate() {
        writeln!(csv, "{}", s.row(i + 1, loop_hz).map(|v| v.to_string()).join(","))?;
    }
    csv.flush()?;
    drop(csv);
    drop(lift);
    std::fs::remove_dir(&chip_dir).ok();
    out.commit()?;
    outln!("per travel: {}", args.out.join("dcp_travels.csv").display());
    Ok(())
}

/// The chip started in `chip_dir` with the car at `--start-mm`, the car
/// mass `m_car` set on its service port and `--compensation` (if not off)
/// as its strategy.
fn start_dcp_lift(
    rig: &RigConfig,
    args: &PilArgs,
    m_car: f64,
    chip_dir: &std::path::Path,
) -> anyhow::Result<dcp::Lift> {
    use drive_core::service::ParamsStatus;

    let (geometry, _) = dcp::geometry(rig);
    let elf = args.elf.clone().unwrap_or_else(dcp::default_elf);
    let chip = dcp::Chip::launch(&elf, &args.qemu, chip_dir)?;
    let lw_start = geometry.lw_lowest_landing_m as f64 + args.start_mm / 1000.0;
    let mut lift = dcp::Lift::new(rig, Some(chip), &dcp::default_parameters(rig), ParamsStatus::None, m_car, lw_start)?;
    let (answer, _) = lift.ask(&format!("set mass {}", m_car as f32), 2_000)?;
    anyhow::ensure!(answer.starts_with("ok mass"), "the drive refused the car mass: {answer}");
    let strategy = args.compensation.strategy();
    if strategy != drive_core::ripple::Strategy::Off {
        let (answer, _) = lift.ask(&format!("set strategy {}", strategy.name()), 2_000)?;
        anyhow::ensure!(answer.starts_with("ok strategy"), "the drive refused the strategy: {answer}");
    }
    Ok(lift)
}

/// The DCP4 travels to each of `--landings` in turn: the steps run, the
/// lift controller (its arrivals), each travel's peak car speed (m/s) and
/// the CPU load.
fn run_dcp_travels(
    args: &PilArgs,
    drive: &drive_core::DriveConfig,
    lift: &mut dcp::Lift,
) -> anyhow::Result<(u64, dcp::Master, Vec<f64>, dcp::CpuLoad)> {
    use drive_core::dcp::command::{Mode, Speed};

    let trips = args.landings.iter().map(|&target_mm| dcp::Trip { target_mm, speed: Speed::V4 }).collect();
    let mut master = dcp::Master::new(Mode::Dcp4, trips, drive);
    // Each travel within its time at rated speed plus 10 s of sequence.
    let mut budget = 0.0;
    let mut from = args.start_mm;
    for &landing in &args.landings {
        budget += (landing as f64 - from).abs() / 1000.0 / drive.rated_speed_mps as f64 + 10.0;
        from = landing as f64;
    }
    let max_steps = (budget * drive.current_loop_hz as f64) as u64;
    let bar = if args.quiet { ProgressBar::hidden() } else { ProgressBar::new(max_steps) };
    bar.set_style(ProgressStyle::with_template("{msg} [{bar:40}] {pos} steps {elapsed_precise}")?);
    bar.set_message("PIL, DCP");
    let mut peak = 0.0f64;
    let mut peaks = Vec::new();
    let mut load = dcp::CpuLoad::new(drive);
    let mut k = 0;
    while master.phase() != dcp::Phase::Done {
        anyhow::ensure!(k < max_steps, "the travels did not finish within {max_steps} steps");
        let bytes = master.bytes(k, lift.position_mm());
        let step = lift.step(&bytes, &[])?;
        master.receive(&step.dcp_replies)?;
        load.add(&step);
        peak = peak.max((step.output.telemetry.speed_radps * drive.sheave_radius_m).abs() as f64);
        if master.arrivals.len() > peaks.len() {
            peaks.push(peak);
            peak = 0.0;
        }
        k += 1;
        if k % 1600 == 0 {
            bar.set_position(k);
        }
    }
    bar.finish_and_clear();
    Ok((k, master, peaks, load))
}

/// One [`TravelSummary`] per arrival, the first travel from `start_mm`.
fn travel_summaries(start_mm: f64, arrivals: &[dcp::Arrival], peaks: &[f64]) -> Vec<TravelSummary> {
    let mut from = start_mm;
    arrivals
        .iter()
        .zip(peaks)
        .map(|(a, &peak_speed_mps)| {
            let s = TravelSummary {
                from_mm: from,
                target_mm: a.trip.target_mm,
                landed_mm: a.position_mm,
                steps: a.step - a.start_step,
                peak_speed_mps,
            };
            from = a.position_mm;
            s
        })
        .collect()
}

/// Prints one row per travel.
fn print_travel_table(summaries: &[TravelSummary], loop_hz: f64) {
    outln!(
        "{:>7} {:>9} {:>9} {:>10} {:>9} {:>8} {:>8} {:>10}",
        "travel",
        "from mm",
        "to mm",
        "landed mm",
        "error mm",
        "steps",
        "time s",
        "peak m/s"
    );
    for (i, s) in summaries.iter().enumerate() {
        let [travel, from, to, landed, error, steps, time, peak] = s.row(i + 1, loop_hz);
        outln!("{travel:>7} {from:>9.1} {to:>9} {landed:>10.2} {error:>+9.2} {steps:>8} {time:>8.2} {peak:>10.3}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn landings_outside_the_shaft_or_too_close_are_refused_by_name() {
        assert!(check_landings(&[1600, 1300, 2000], 1000.0, 6600).is_ok());
        let e = check_landings(&[7000], 1000.0, 6600).unwrap_err().to_string();
        assert!(e.contains("--landings: 7000 mm is out of range"), "{e}");
        let e = check_landings(&[1005], 1000.0, 6600).unwrap_err().to_string();
        assert!(e.contains("less than 10 mm"), "{e}");
        let e = check_landings(&[], 1000.0, 6600).unwrap_err().to_string();
        assert!(e.contains("--landings is empty"), "{e}");
        let e = check_landings(&[100], f64::NAN, 6600).unwrap_err().to_string();
        assert!(e.contains("--start-mm"), "{e}");
    }
}
