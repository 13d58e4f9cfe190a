//! Torque-ripple compensation in closed loop: the model behind the learning
//! against the simulated plant, the best strategy on the 8 nominal travels,
//! and every strategy on the mismatch cases. By default the two sweeps run a
//! fixed subset of their travels; the full sweeps are ignored tests, run with
//! `cargo test --release -p host-sim --test integration -- --ignored NAME`.

use std::thread;

use crate::support::rig;
use closed_loop::compensation::{all_cases, calibrate_table, compensator, run_case, CompareRow, Mismatch};
use closed_loop::{simulate_travel_with, SimOptions, StepLog, TravelSpec};
use drive_core::config::Direction;
use drive_core::ripple::complex::Complex;
use drive_core::ripple::harmonics::HarmonicTable;
use drive_core::ripple::response::{chain_response, loop_response};
use drive_core::ripple::{RippleCompensator, Strategy};
use drive_core::speed_loop::equivalent_inertia_kg_m2;
use plant::modes::natural_modes;
use plant::rope::ChainParams;

/// The folded-chain mobility of `drive_core::ripple::response` peaks at the
/// natural frequencies of the host's 5-DOF eigen-solution (Eqn 10).
#[test]
fn chain_response_resonances_are_the_natural_frequencies_of_the_5_dof_model() {
    let rig = rig();
    let mut model = rig.observer_model();
    // Undamped, so the resonances are sharp.
    model.c_car_kg_per_s = 0.0;
    model.c_cw_kg_per_s = 0.0;
    model.c_sheave_nms_per_rad = 0.0;
    for (m_car, lw) in [(70.5, 4.0), (33.0, 2.0), (58.0, 6.5)] {
        let mut chain = ChainParams::from_rig(&rig, m_car);
        chain.c_car_kg_per_s = 0.0;
        chain.c_cw_kg_per_s = 0.0;
        chain.c_sheave_nms_per_rad = 0.0;
        let modes = natural_modes(&chain, lw).frequencies_hz;
        for &f in &modes[1..3] {
            // |mobility| grows without bound toward a resonance: compare 0.2 % either side with 5 % away.
            let at = |f_hz: f64| {
                chain_response(&model, m_car as f32, lw as f32, (std::f64::consts::TAU * f_hz) as f32)
                    .shaft_mobility
                    .norm_sqr()
            };
            let near = at(f * 0.998).min(at(f * 1.002));
            let away = at(f * 0.95).max(at(f * 1.05));
            println!("m_car {m_car} kg, lw {lw} m: mode {f:.3} Hz: |Y|^2 near {near:.3e}, 5 % away {away:.3e}");
            assert!(near > 100.0 * away, "no resonance of the folded chain at the 5-DOF mode {f} Hz");
        }
    }
}

/// Injects a known harmonic table (1 N m at orders 6 and 12) on a plant
/// without ripple and measures the speed-error response window by window
/// against `loop_response`: within 20 % and 25 degrees (the learning law
/// tolerates any phase error under 90 degrees) wherever the
/// response is above the learning floor.
#[test]
fn closed_loop_response_model_matches_the_simulated_drive() {
    let mut rig = rig();
    for r in rig.ripple.iter_mut() {
        r.amplitude_nm = 0.0;
    }
    let drive = rig.drive_config();
    let orders = [6u16, 12];
    let mut table = HarmonicTable::default();
    for o in orders {
        table.push_cosine(o, 1.0, 1.0, 0.0);
    }
    let mut comp = RippleCompensator::new(&drive, &rig.observer_model(), &orders, Strategy::Table);
    comp.set_table(table);
    comp.set_back_off(false);
    let mut controller = drive_core::Controller::new(&drive);
    controller.set_compensation(Some(comp));
    let spec = TravelSpec::full_travel(&rig, 70.5, Direction::Up);
    let mut log = StepLog::default();
    simulate_travel_with(&rig, &spec, &SimOptions::for_rig(&rig), &mut controller, None, Some(&mut log)).unwrap();
    let inertia = equivalent_inertia_kg_m2(&drive, 70.5);
    let ticks: Vec<_> = log.steps.iter().step_by(8).map(|(_, o)| o.telemetry).collect();
    let mut checked = 0;
    for &o in &orders {
        for w in ticks.chunks(2000) {
            if w.iter().any(|t| (t.ref_speed_mps - 0.4).abs() > 1e-6) {
                continue;
            }
            let measured = w.iter().fold(Complex::ZERO, |acc, t| {
                let th = o as f64 * t.angle_rad as f64;
                let e = 2.0 * (t.speed_ref_radps - t.speed_radps) / w.len() as f32;
                acc + Complex::new(e * th.cos() as f32, -e * th.sin() as f32)
            });
            let mid = w[w.len() / 2];
            let lw = rig.travel.lw_low_m as f32 + mid.angle_rad * rig.mechanics.sheave_radius_m as f32;
            let g = loop_response(&drive, &rig.observer_model(), 70.5, lw, inertia, mid.speed_radps * o as f32)
                .speed_error_per_torque;
            if g.norm_sqr() < 0.01 * 0.01 {
                continue;
            }
            let ratio = measured / g;
            let (gain, phase_deg) = (ratio.norm_sqr().sqrt(), ratio.im.atan2(ratio.re).to_degrees());
            println!(
                "order {o}, lw {lw:.2} m: |G| {:.4} rad/s/(N m), measured/model {gain:.3} at {phase_deg:+.1} deg",
                g.norm_sqr().sqrt()
            );
            assert!((gain - 1.0).abs() < 0.2 && phase_deg.abs() < 25.0, "order {o} at lw {lw}: {gain} {phase_deg}");
            checked += 1;
        }
    }
    assert!(checked >= 10, "only {checked} windows checked");
}

/// Runs `run_case` for `cases` on two threads.
fn run_cases(
    cases: Vec<(usize, closed_loop::compensation::Case)>,
    strategies: &[Strategy],
    table: HarmonicTable,
) -> Vec<CompareRow> {
    let rig = rig();
    let halves: Vec<Vec<_>> =
        vec![cases.iter().step_by(2).cloned().collect(), cases.iter().skip(1).step_by(2).cloned().collect()];
    thread::scope(|scope| {
        let handles: Vec<_> = halves
            .iter()
            .map(|half| {
                let rig = &rig;
                scope.spawn(move || {
                    half.iter()
                        .flat_map(|(i, c)| {
                            run_case(rig, *i, c, &table, strategies, 3)
                                .unwrap_or_else(|e| panic!("case {i} ({c:?}): {e:#}"))
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles.into_iter().flat_map(|h| h.join().unwrap()).collect()
    })
}

/// The best strategy (adaptive harmonics) on the nominal travels `cases`:
/// the car's 12 x f_mech component at least 20 dB down and its A95 at least
/// 60 % down.
fn assert_best_strategy(cases: Vec<(usize, closed_loop::compensation::Case)>) {
    let rows = run_cases(cases, &[Strategy::Off, Strategy::Adaptive], HarmonicTable::default());
    for r in rows.iter().filter(|r| r.strategy == "adaptive") {
        println!(
            "{} kg {}: 12x {:.4} m/s^2 ({:+.1} dB), A95 {:.1} mg ({:+.0} %), peak current {:.1} A, learning {:?} s",
            r.m_car_kg,
            r.direction,
            r.car_12x_mps2,
            r.car_12x_change_db,
            r.a95_mg,
            r.a95_change_pct,
            r.peak_current_a,
            r.learning_time_s
        );
        assert!(r.car_12x_change_db <= -20.0 && r.a95_change_pct <= -60.0, "{r:?}");
    }
}

/// The nominal travels of the rig, with their index in `all_cases`.
fn nominal_cases() -> Vec<(usize, closed_loop::compensation::Case)> {
    all_cases(&rig()).into_iter().enumerate().filter(|(_, c)| c.mismatch == Mismatch::Nominal).collect()
}

/// The nominal travels of the best-strategy check run by default (car mass,
/// direction): those with the smallest 12x and A95 margins in the full sweep.
const BEST_SUBSET: [(f64, Direction); 2] = [(33.0, Direction::Up), (70.5, Direction::Down)];

/// The best strategy on BEST_SUBSET of the 8 nominal travels.
#[test]
fn the_best_strategy_lowers_the_12x_car_vibration_20_db_and_a95_60_percent_on_a_subset_of_the_nominal_travels() {
    let cases: Vec<_> =
        nominal_cases().into_iter().filter(|(_, c)| BEST_SUBSET.contains(&(c.m_car_kg, c.direction))).collect();
    assert_eq!(cases.len(), BEST_SUBSET.len());
    assert_best_strategy(cases);
}

/// The best strategy on the 8 nominal travels (the full sweep):
/// `cargo test --release -p host-sim --test integration -- --ignored
/// the_best_strategy_lowers_the_12x_car_vibration_20_db_and_a95_60_percent_on_every_nominal_travel --nocapture`.
#[test]
#[ignore = "full sweep: run with --ignored"]
fn the_best_strategy_lowers_the_12x_car_vibration_20_db_and_a95_60_percent_on_every_nominal_travel() {
    let cases = nominal_cases();
    assert_eq!(cases.len(), 8);
    assert_best_strategy(cases);
}

/// The mismatch cases of the sweep (three travels each; `host-sim compare`
/// runs all 8), with their index in `all_cases`.
fn mismatch_cases() -> Vec<(usize, closed_loop::compensation::Case)> {
    all_cases(&rig())
        .into_iter()
        .enumerate()
        .filter(|(_, c)| {
            c.mismatch != Mismatch::Nominal
                && (((c.m_car_kg == 45.5 || c.m_car_kg == 70.5) && c.direction == Direction::Up)
                    || (c.m_car_kg == 33.0 && c.direction == Direction::Down))
        })
        .collect()
}

/// Every strategy on the mismatch cases `cases`: never more than 1 dB worse
/// than no compensation on the car's 12x line or its A95.
fn assert_no_strategy_worse(cases: Vec<(usize, closed_loop::compensation::Case)>) {
    let rig = rig();
    let table = calibrate_table(&rig).unwrap();
    let strategies = Strategy::ALL;
    let rows = run_cases(cases, &strategies, table);
    for r in rows.iter().filter(|r| r.strategy != "off") {
        let a95_db = 20.0 * (1.0 + r.a95_change_pct / 100.0).log10();
        println!(
            "{:>16} {:>5} kg {:>4} {:>9}: 12x {:+6.1} dB, A95 {:+6.1} dB, backed off [{}]",
            r.mismatch, r.m_car_kg, r.direction, r.strategy, r.car_12x_change_db, a95_db, r.backed_off_orders
        );
        assert!(r.car_12x_change_db <= 1.0 && a95_db <= 1.0, "{r:?}");
    }
}

/// The mismatch cases run by default (mismatch, car mass, direction), four
/// of the 15: the EA and phase-drift cases come closest to the 1 dB limit in
/// the full sweep; one ripple-amplitude case.
const MISMATCH_SUBSET: [(Mismatch, f64, Direction); 4] = [
    (Mismatch::RopeEa { factor: 0.8 }, 70.5, Direction::Up),
    (Mismatch::RopeEa { factor: 1.2 }, 33.0, Direction::Down),
    (Mismatch::RippleAmplitude { factor: 1.3 }, 45.5, Direction::Up),
    (Mismatch::RipplePhaseDrift { fraction: 0.005 }, 70.5, Direction::Up),
];

/// Every strategy on MISMATCH_SUBSET of the 15 mismatch cases.
#[test]
fn no_strategy_makes_a_subset_of_the_mismatch_cases_worse_than_no_compensation_by_more_than_1_db() {
    let cases: Vec<_> = mismatch_cases()
        .into_iter()
        .filter(|(_, c)| MISMATCH_SUBSET.contains(&(c.mismatch, c.m_car_kg, c.direction)))
        .collect();
    assert_eq!(cases.len(), MISMATCH_SUBSET.len());
    assert_no_strategy_worse(cases);
}

/// Every strategy on every mismatch case (the full sweep):
/// `cargo test --release -p host-sim --test integration -- --ignored
/// no_strategy_makes_a_mismatch_case_worse_than_no_compensation_by_more_than_1_db --nocapture`.
#[test]
#[ignore = "full sweep: run with --ignored"]
fn no_strategy_makes_a_mismatch_case_worse_than_no_compensation_by_more_than_1_db() {
    let cases = mismatch_cases();
    assert_eq!(cases.len(), 15);
    assert_no_strategy_worse(cases);
}

/// A travel with no ripple in the plant and a wrong table: the back-off
/// finds that the table makes things worse and switches it off.
#[test]
fn a_table_that_only_adds_vibration_backs_off() {
    let mut rig = rig();
    for r in rig.ripple.iter_mut() {
        r.amplitude_nm = 0.0;
    }
    let nominal = crate::support::rig();
    let table = closed_loop::compensation::rig_ripple_table(&nominal).negated();
    let spec = TravelSpec::full_travel(&rig, 70.5, Direction::Up);
    let (_, after) = closed_loop::compensation::travel_with_compensator(
        &rig,
        Mismatch::Nominal,
        &spec,
        &SimOptions::for_rig(&rig),
        compensator(&rig, Strategy::Table, Some(table)),
    )
    .unwrap();
    let backed = after.backed_off();
    println!("orders {:?}: backed off {:?}", &after.applied().orders[..5], &backed[..5]);
    // Order 12 (3.5 N m, well seen by the encoder) must back off.
    assert!(backed[2], "{backed:?}");
}
