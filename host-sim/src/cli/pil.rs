//! `host-sim pil`: the plant in the simulator, the drive core in the
//! emulated Cortex-M4F; every step checked bit for bit against the host
//! build, and the cost of each step measured in instructions.

pub mod dcp;

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
use closed_loop::pil::{default_elf_path, PilOptions, PilTarget};
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

    let path = out.path("pil_steps.csv");
    let mut csv = std::io::BufWriter::new(
        std::fs::File::create(&path).with_context(|| format!("cannot write {}", path.display()))?,
    );
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
