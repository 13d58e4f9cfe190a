//! Criterion benchmarks of the simulation's speed: one PWM half period of
//! the nominal plant (the exact step with a 16384 Hz sample in it, and the
//! reference RK4 over the same interval), one half period of the plant with
//! the 21-node line, the car-frame mode and the brake clamp (RK4), and a
//! whole closed-loop travel (the `host-sim bench` travel).
//!
//! ```text
//! cargo bench -p host-sim --bench simulation
//! ```

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use drive_core::config::Direction;

use closed_loop::{simulate_travel, SimOptions, TravelSpec};
use plant::effects::{EffectKind, Effects};
use plant::{Integrator, Plant, PlantInputs};
use rig_config::RigConfig;

/// The 21-node line, the car-frame mode and the brake clamp.
fn heavy_effects() -> Effects {
    let mut effects = Effects::none();
    effects.set(EffectKind::RopeDiscretization, &[8.0]).unwrap();
    for kind in [EffectKind::DivertingPulley, EffectKind::CarFrameMode, EffectKind::BrakeStop] {
        effects.set(kind, &kind.defaults()).unwrap();
    }
    effects
}

/// A plant of `effects` moving (brake released, PWM on), 0.1 s into a run
/// with the given integrator.
fn moving_plant(rig: &RigConfig, effects: &Effects, integrator: Integrator) -> Plant {
    let mut plant = Plant::with_effects(rig, 70.5, 3.0, effects);
    plant.set_integrator(integrator);
    plant.set_inputs(PlantInputs { pwm_compare: [1500, 2400, 900], pwm_enabled: true, brake_engaged: false });
    let h = 0.5 / rig.control.current_loop_hz;
    for _ in 0..3200 {
        let t = plant.time_s() + h;
        plant.advance_until(t, 0.5 * h, &[], |_, _| {});
    }
    plant
}

fn plant_step(c: &mut Criterion) {
    let rig = RigConfig::embedded_default().unwrap();
    let h = 0.5 / rig.control.current_loop_hz;
    let max_step = 0.25 / rig.control.current_loop_hz;
    let cases = [
        ("plant half period, nominal, fast (exact)", Effects::none(), Integrator::Fast),
        ("plant half period, nominal, reference RK4", Effects::none(), Integrator::Reference),
        ("plant half period, 21 nodes + frame + clamp, fast RK4", heavy_effects(), Integrator::Fast),
    ];
    for (name, effects, integrator) in cases {
        let mut plant = moving_plant(&rig, &effects, integrator);
        let mut sum = 0.0;
        c.bench_function(name, |b| {
            b.iter(|| {
                let t0 = plant.time_s();
                plant.advance_until(t0 + h, max_step, &[t0 + 0.4 * h], |_, o| sum += o.car_acceleration_mps2);
                black_box(sum)
            })
        });
    }
}

fn whole_travel(c: &mut Criterion) {
    let rig = RigConfig::embedded_default().unwrap();
    let spec = TravelSpec::full_travel(&rig, 70.5, Direction::Up);
    let mut group = c.benchmark_group("closed-loop travel (19.15 s simulated)");
    group.sample_size(10);
    let nominal = SimOptions::for_rig(&rig);
    let heavy = SimOptions { effects: heavy_effects(), ..nominal };
    for (name, options) in [("nominal", nominal), ("21 nodes + frame + clamp", heavy)] {
        group.bench_function(name, |b| b.iter(|| black_box(simulate_travel(&rig, &spec, &options, None).unwrap())));
    }
    group.finish();
}

criterion_group!(benches, plant_step, whole_travel);
criterion_main!(benches);
