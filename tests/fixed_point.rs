//! The fixed-point current loop and space-vector modulation of `shared`
//! against an f64 reference of the same equations, over the whole input
//! range, and the guarantee that nothing wraps.
//!
//! Stated bound, for any ADC codes, any angle, any electrical speed within
//! +-2000 rad/s (54 times the rated speed), any q reference within +-32 A and any DC bus from 20 to
//! 200 V:
//! - `v_d` within 0.25 V of the f64 reference; `v_q` too, except on the
//!   voltage limit, where `v_q` is what the circle leaves after `v_d`
//!   (`sqrt(v_max^2 - v_d^2)`, whose slope `v_d/v_q` magnifies the `v_d`
//!   error): there the magnitude `|v|` is within 0.25 V of the reference;
//! - the modulator adds at most one count: each compare value is within
//!   `2 |dv| / V_dc` of the period plus one count of the reference, `dv` the
//!   difference of the two dq voltage vectors (a phase moves by at most
//!   `|dv|`, and the zero sequence by as much again). In the linear range at
//!   the rig's 100 V bus that is at most 39 counts of 5312 (0.7 % duty).
//!
//! Measured worst case over a million pseudo-random inputs (the last test):
//! 0.07 V on `v_d`, 0.04 V on `v_q` off the limit.
//!
//! The voltage error is the Q16.16 rounding of the currents and products
//! (sines and transform constants are Q2.30) times the proportional gain
//! (94 V/A) and the decoupling
//! `w_e L` (30 V/A at 2000 rad/s; above that it dominates, growing with
//! speed). Beyond that speed range the loop is checked only for what must
//! hold everywhere: no wrap, voltages on their limits, compares in range.

use drive_core::current_loop::{current_from_code, CurrentLoop, CurrentLoopParams};
use drive_core::fixed::{q16, Q16};
use drive_core::park_clarke::Abc;
use drive_core::DriveConfig;
use proptest::prelude::*;

const VOLTAGE_BOUND_V: f64 = 0.25;

fn drive() -> DriveConfig {
    crate::support::rig().drive_config()
}

/// The same current-loop step in f64, from empty integrators.
struct Reference {
    config: DriveConfig,
}

impl Reference {
    fn step(&self, codes: [u16; 3], angle: u32, speed_e: f64, iq_ref: f64, dc_bus: f64) -> ([f64; 2], [f64; 3]) {
        let c = &self.config;
        let lsb = c.current_lsb_a() as f64;
        let i = codes.map(|code| (code as f64 - c.adc_zero_code() as f64) * lsb);
        let alpha = (2.0 * i[0] - i[1] - i[2]) / 3.0;
        let beta = (i[1] - i[2]) / 3f64.sqrt();
        let theta = angle as f64 / 4_294_967_296.0 * std::f64::consts::TAU;
        let (s, co) = theta.sin_cos();
        let id = alpha * co + beta * s;
        let iq = beta * co - alpha * s;
        let wc = std::f64::consts::TAU * c.current_loop_bandwidth_hz as f64;
        let ts = 1.0 / c.current_loop_hz as f64;
        let (r, ld, lq, psi) = (c.stator_resistance_ohm as f64, c.ld_h as f64, c.lq_h as f64, c.flux_linkage_wb as f64);
        let dc = dc_bus.max(1.0);
        let v_max = dc / 3f64.sqrt() * 0.95;
        let pi = |error: f64, kp: f64, ff: f64, limit: f64| {
            // Dynamic integrator clamping, from an empty integrator.
            let proportional = kp * error + ff;
            let integral =
                (r * wc * ts * error).clamp((-limit - proportional).min(0.0), (limit - proportional).max(0.0));
            (proportional + integral).clamp(-limit, limit)
        };
        let vd = pi(-id, ld * wc, -speed_e * lq * iq, v_max);
        let vq_max = (v_max * v_max - vd * vd).max(0.0).sqrt();
        let vq = pi(iq_ref - iq, lq * wc, speed_e * (ld * id + psi), vq_max);
        let theta_out = theta + speed_e * ts;
        let (s, co) = theta_out.sin_cos();
        let va = vd * co - vq * s;
        let vb = vd * s + vq * co;
        let phases = [va, -0.5 * va + 0.5 * 3f64.sqrt() * vb, -0.5 * va - 0.5 * 3f64.sqrt() * vb];
        let max = phases.iter().copied().fold(f64::MIN, f64::max);
        let min = phases.iter().copied().fold(f64::MAX, f64::min);
        let v0 = -(max + min) / 2.0;
        let period = c.pwm_period_counts as f64;
        let compare = phases.map(|v| ((0.5 + (v + v0) / dc).clamp(0.0, 1.0) * period).round());
        ([vd, vq], compare)
    }
}

fn fixed_step(
    config: &DriveConfig,
    codes: [u16; 3],
    angle: u32,
    speed_e: f64,
    iq_ref: f64,
    dc_bus: f64,
) -> ([f64; 2], [u16; 3]) {
    let mut current_loop = CurrentLoop::new(CurrentLoopParams::from_config(config));
    let lsb = q16(config.current_lsb_a());
    let i = codes.map(|code| current_from_code(code, config.adc_zero_code(), lsb));
    let out = current_loop.step(
        Abc { a: i[0], b: i[1], c: i[2] },
        angle,
        q16(speed_e as f32),
        q16(iq_ref as f32),
        q16(dc_bus as f32),
    );
    ([out.voltage.d.to_num(), out.voltage.q.to_num()], out.compare)
}

/// Inputs rounded to what the fixed-point path can represent, so that both
/// sides see the same numbers.
fn representable(x: f64) -> f64 {
    q16(x as f32).to_num::<f64>()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(20_000))]

    #[test]
    fn current_loop_and_svm_within_the_stated_bound_of_f64(
        a in 0u16..4096, b in 0u16..4096, c in 0u16..4096,
        angle in any::<u32>(),
        speed_e in -2_000.0f64..2_000.0,
        iq_ref in -32.0f64..32.0,
        dc_bus in 20.0f64..200.0,
    ) {
        let config = drive();
        let (speed_e, iq_ref, dc_bus) = (representable(speed_e), representable(iq_ref), representable(dc_bus));
        let (v_fixed, compare_fixed) = fixed_step(&config, [a, b, c], angle, speed_e, iq_ref, dc_bus);
        let (v_ref, compare_ref) = Reference { config }.step([a, b, c], angle, speed_e, iq_ref, dc_bus);
        let v_max = dc_bus / 3f64.sqrt() * 0.95;
        let magnitude = |v: [f64; 2]| (v[0] * v[0] + v[1] * v[1]).sqrt();
        prop_assert!((v_fixed[0] - v_ref[0]).abs() <= VOLTAGE_BOUND_V, "v_d: fixed {} vs f64 {}", v_fixed[0], v_ref[0]);
        if magnitude(v_ref) < v_max - 2.0 * VOLTAGE_BOUND_V {
            prop_assert!((v_fixed[1] - v_ref[1]).abs() <= VOLTAGE_BOUND_V, "v_q: fixed {} vs f64 {}", v_fixed[1], v_ref[1]);
        } else {
            prop_assert!((magnitude(v_fixed) - magnitude(v_ref)).abs() <= VOLTAGE_BOUND_V, "|v|: fixed {:?} vs f64 {:?}", v_fixed, v_ref);
        }
        let dv = magnitude([v_fixed[0] - v_ref[0], v_fixed[1] - v_ref[1]]);
        let compare_bound = (2.0 * dv / dc_bus * config.pwm_period_counts as f64).ceil() as i32 + 1;
        for k in 0..3 {
            let diff = compare_fixed[k] as i32 - compare_ref[k] as i32;
            prop_assert!(diff.abs() <= compare_bound, "compare[{}]: fixed {} vs f64 {}", k, compare_fixed[k], compare_ref[k]);
            prop_assert!(compare_fixed[k] <= config.pwm_period_counts);
        }
    }
}

#[test]
fn extreme_inputs_saturate_in_the_right_direction_and_never_wrap() {
    let config = drive();
    let period = config.pwm_period_counts;
    let mut current_loop = CurrentLoop::new(CurrentLoopParams::from_config(&config));
    let lsb = q16(config.current_lsb_a());
    let zero = config.adc_zero_code();
    let i = [0u16, 4095, 4095].map(|code| current_from_code(code, zero, lsb));
    // Largest speeds and references the types hold: the voltage sits on its
    // limit with the sign of the demand, every compare inside the period.
    for (speed, iq_ref) in [(Q16::MAX, Q16::MAX), (Q16::MIN, Q16::MIN), (Q16::MAX, Q16::MIN), (Q16::MIN, Q16::MAX)] {
        for _ in 0..1000 {
            let out = current_loop.step(Abc { a: i[0], b: i[1], c: i[2] }, 0x1234_5678, speed, iq_ref, q16(100.0));
            assert!(out.compare.iter().all(|&x| x <= period), "{out:?}");
            let v_limit = 100.0 / 3f64.sqrt() * 0.95;
            let magnitude = (out.voltage.d.to_num::<f64>().powi(2) + out.voltage.q.to_num::<f64>().powi(2)).sqrt();
            assert!(magnitude <= v_limit + 1e-3, "|v| = {magnitude}");
        }
    }
    // A huge positive q-current error drives v_q to its positive limit.
    let mut current_loop = CurrentLoop::new(CurrentLoopParams::from_config(&config));
    let i0 = current_from_code(zero, zero, lsb);
    let out = current_loop.step(Abc { a: i0, b: i0, c: i0 }, 0, Q16::ZERO, q16(30_000.0), q16(100.0));
    assert!(out.voltage.q.to_num::<f64>() > 50.0, "{out:?}");
    let out = current_loop.step(Abc { a: i0, b: i0, c: i0 }, 0, Q16::ZERO, q16(-30_000.0), q16(100.0));
    assert!(out.voltage.q.to_num::<f64>() < -50.0, "{out:?}");
}

#[test]
fn worst_case_over_a_million_pseudo_random_inputs_is_inside_the_bound() {
    let config = drive();
    let mut seed = 0x2545_F491_4F6C_DD1Du64;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    let (mut worst_vd, mut worst_vq) = (0.0f64, 0.0f64);
    for _ in 0..1_000_000 {
        let codes = [(next() % 4096) as u16, (next() % 4096) as u16, (next() % 4096) as u16];
        let angle = next() as u32;
        let unit = |x: u64| (x % 1_000_000) as f64 / 1_000_000.0;
        let speed_e = representable(-2000.0 + 4000.0 * unit(next()));
        let iq_ref = representable(-32.0 + 64.0 * unit(next()));
        let dc_bus = representable(20.0 + 180.0 * unit(next()));
        let (v_fixed, _) = fixed_step(&config, codes, angle, speed_e, iq_ref, dc_bus);
        let (v_ref, _) = Reference { config }.step(codes, angle, speed_e, iq_ref, dc_bus);
        let v_max = dc_bus / 3f64.sqrt() * 0.95;
        worst_vd = worst_vd.max((v_fixed[0] - v_ref[0]).abs());
        if (v_ref[0].powi(2) + v_ref[1].powi(2)).sqrt() < v_max - 2.0 * VOLTAGE_BOUND_V {
            worst_vq = worst_vq.max((v_fixed[1] - v_ref[1]).abs());
        }
    }
    println!("worst |v_d error| {worst_vd:.4} V, worst |v_q error| off the limit {worst_vq:.4} V (bound {VOLTAGE_BOUND_V} V)");
    assert!(worst_vd <= VOLTAGE_BOUND_V && worst_vq <= VOLTAGE_BOUND_V);
}
