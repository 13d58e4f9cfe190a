//! Criterion benchmarks of the simulation's speed: one PWM half period of
//! the nominal plant (the exact step with a 16384 Hz sample in it, and the
//! reference RK4 over the same interval), one half period of the plant with
//! the 21-node line, the car-frame mode and the brake clamp (RK4), a
//! whole closed-loop travel (the `host-sim bench` travel), and the gap
//! diagnosis's torque-driven model of that travel (the run `gap` repeats for
//! every hypothesis on a recording under another drive) with the nominal
//! chain, tension stiffening and the diverting pulley.
//!
//! ```text
//! cargo bench -p host-sim --bench simulation
//! ```

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use drive_core::config::Direction;

use closed_loop::{simulate_travel, SimOptions, TravelSpec};
use diagnosis::driven::{motion_from_angle, torque_driven_accelerations, DrivenSettings, DrivenTravel};
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

/// What the torque-driven model takes of a travel recording: motor
/// torque (N m), encoder angle (rad) and speed estimate (rad/s), every
/// `step`-th sample of the closed-loop `run` (the recording at its rate
/// divided by `step`), with the constant-speed stage found in the speed
/// estimate as the diagnosis finds it ([`dsp::constant_speed_stage`]).
struct Recorded {
    torque_nm: Vec<f64>,
    angle_rad: Vec<f64>,
    speed_radps: Vec<f64>,
    constant_speed: std::ops::Range<usize>,
    sample_rate_hz: f64,
    lw_start_m: f64,
}

impl Recorded {
    fn of(run: &closed_loop::TravelRun, step: usize) -> Self {
        let every = |v: &[f64]| v.iter().step_by(step).copied().collect::<Vec<f64>>();
        let (speed_radps, sample_rate_hz) = (every(&run.speed_radps), run.sample_rate_hz / step as f64);
        Self {
            torque_nm: every(&run.motor_torque_nm),
            angle_rad: every(&run.angle_rad),
            constant_speed: dsp::constant_speed_stage(&speed_radps, sample_rate_hz).unwrap(),
            speed_radps,
            sample_rate_hz,
            lw_start_m: run.lw_m[0],
        }
    }

    fn travel(&self, m_car_kg: f64, m_cw_kg: f64) -> DrivenTravel<'_> {
        DrivenTravel {
            m_car_kg,
            m_cw_kg,
            lw_start_m: self.lw_start_m,
            torque_nm: &self.torque_nm,
            shaft_angle_rad: &self.angle_rad,
            speed_estimate_radps: &self.speed_radps,
            controller: None,
            motion: motion_from_angle(&self.angle_rad, self.sample_rate_hz),
            constant_speed: self.constant_speed.clone(),
            reference_end: None,
            sample_rate_hz: self.sample_rate_hz,
            transducer_lines: &[],
            transducer: None,
            // Every iteration reads the recording anew: one run of a fit.
            readings: None,
        }
    }
}

/// The torque-driven model of the diagnosis on the nominal travel's own
/// recording (16384 Hz, and every fourth sample of it: 4096 Hz; no speed
/// loop identified), with the nominal chain and two effects that change
/// it: tension stiffening (a spring law per rope spring) and the diverting
/// pulley (a node more, the general line).
fn torque_driven_travel(c: &mut Criterion) {
    let rig = RigConfig::embedded_default().unwrap();
    let spec = TravelSpec::full_travel(&rig, 70.5, Direction::Up);
    let run = simulate_travel(&rig, &spec, &SimOptions::for_rig(&rig), None).unwrap();
    let (full, quarter) = (Recorded::of(&run, 1), Recorded::of(&run, 4));
    let mut stiffening = Effects::none();
    stiffening.set(EffectKind::TensionStiffening, &[0.45, 323.73]).unwrap();
    let mut pulley = Effects::none();
    pulley.set(EffectKind::DivertingPulley, &EffectKind::DivertingPulley.defaults()).unwrap();
    let mut group = c.benchmark_group("torque-driven model of the travel (19.15 s recorded)");
    group.sample_size(10);
    let settings = DrivenSettings::default();
    let cases = [
        ("nominal chain, 16384 Hz", &full, Effects::none()),
        ("nominal chain, 4096 Hz", &quarter, Effects::none()),
        ("tension stiffening, 16384 Hz", &full, stiffening),
        ("diverting pulley, 16384 Hz", &full, pulley),
    ];
    for (name, recorded, effects) in cases {
        let travel = recorded.travel(70.5, rig.mechanics.m_cw_kg);
        group.bench_function(name, |b| {
            b.iter(|| black_box(torque_driven_accelerations(&rig, &travel, &settings, &effects).unwrap()))
        });
    }
    group.finish();
}

criterion_group!(benches, plant_step, whole_travel, torque_driven_travel);
criterion_main!(benches);
