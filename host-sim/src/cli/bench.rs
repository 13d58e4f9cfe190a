//! `host-sim bench`: how fast closed-loop travels simulate.

use std::time::Instant;

use clap::Args;
use drive_core::config::Direction;

use super::default_car_mass_kg;
use closed_loop::{simulate_travel, SimOptions, TravelSpec};
use plant::effects::Effects;
use plant::Integrator;
use rig_config::RigConfig;

/// Options of `bench`.
#[derive(Debug, Args)]
pub struct BenchArgs {
    /// Number of travels to time (alternating up and down).
    #[arg(long, default_value_t = 4, allow_negative_numbers = true)]
    pub repeat: usize,
    /// One effect on the simulated plant, `NAME` (default parameters) or
    /// `NAME:param=value,...`; repeatable (none: the nominal plant).
    #[arg(long = "effect", value_name = "NAME[:PARAM=VALUE,...]")]
    pub effect: Vec<String>,
    /// Time the plant's reference integrator (the RK4 as first written)
    /// instead of the default one.
    #[arg(long)]
    pub reference: bool,
}

/// Runs `bench`: times full travels of the heaviest car and reports the
/// ratio of simulated to wall-clock time.
pub fn run(rig: &RigConfig, args: &BenchArgs) -> anyhow::Result<()> {
    super::check_count("--repeat", args.repeat, 1, 1000)?;
    let m_car = default_car_mass_kg(rig);
    let mut options = SimOptions::for_rig(rig);
    options.effects = Effects::from_file_and_flags(None, &args.effect)?;
    if args.reference {
        options.integrator = Integrator::Reference;
    }
    let mut ratios = Vec::new();
    for k in 0..args.repeat {
        let direction = if k % 2 == 0 { Direction::Up } else { Direction::Down };
        let spec = TravelSpec::full_travel(rig, m_car, direction);
        let started = Instant::now();
        let run = simulate_travel(rig, &spec, &options, None)?;
        let wall = started.elapsed().as_secs_f64();
        let ratio = run.duration_s() / wall;
        outln!(
            "travel {} ({direction:?}): {:.2} s simulated in {wall:.3} s = {ratio:.1}x real time",
            k + 1,
            run.duration_s()
        );
        ratios.push(ratio);
    }
    ratios.sort_by(f64::total_cmp);
    outln!(
        "closed-loop travel, m_car = {m_car} kg, {}, {:?} integrator (RK4 steps <= {:.3e} s where the exact half-period step does not apply), {} Hz recording: median {:.1}x real time (min {:.1}x, max {:.1}x) on {} thread",
        options.effects.summary(),
        options.integrator,
        options.max_step_s,
        options.sample_rate_hz,
        ratios[ratios.len() / 2],
        ratios[0],
        ratios[ratios.len() - 1],
        1
    );
    Ok(())
}
