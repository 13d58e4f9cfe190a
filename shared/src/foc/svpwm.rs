//! Space-vector modulation by min-max zero-sequence injection.
//!
//! The three reference phase voltages get the common-mode offset
//! `v0 = -(max + min)/2`, which centres them in the DC-bus window and gives
//! the linear range of space-vector modulation: a voltage vector of
//! amplitude up to `V_dc / sqrt(3)` in every direction. Beyond it (over-
//! modulation) each duty is clamped to `[0, 1]`, so the output is the
//! nearest realisable voltage on that phase and never an invalid compare.

use crate::fixed::{add, clamp, mul, mul_q30, sub, Q16, Q30};
use crate::park_clarke::{inverse_clarke, AlphaBeta, HALF};

/// Duty cycles (0..=1, dimensionless) of the three half bridges for the
/// stationary voltage `v` (V) on a DC bus of `1 / inverse_dc_bus_per_v` volts.
pub fn duty_cycles(v: AlphaBeta, inverse_dc_bus_per_v: Q30) -> [Q16; 3] {
    let abc = inverse_clarke(v);
    let phases = [abc.a, abc.b, abc.c];
    let max = phases.iter().copied().fold(Q16::MIN, Q16::max);
    let min = phases.iter().copied().fold(Q16::MAX, Q16::min);
    let zero_sequence = sub(Q16::ZERO, mul(add(max, min), HALF));
    phases.map(|phase| {
        let duty = add(HALF, mul_q30(add(phase, zero_sequence), inverse_dc_bus_per_v));
        clamp(duty, Q16::ZERO, Q16::ONE)
    })
}

/// Timer compare values (0..=`period_counts`) for the duty cycles: the
/// centre-aligned PWM output is high while the counter is below the compare.
pub fn compare_values(duties: [Q16; 3], period_counts: u16) -> [u16; 3] {
    let period = Q16::saturating_from_num(period_counts);
    duties.map(|duty| {
        let counts = mul(duty, period).round();
        clamp(counts, Q16::ZERO, period).to_num::<u16>()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixed::q16;

    #[test]
    fn linear_range_reproduces_line_voltages() {
        // 57 V (just under 100/sqrt(3)) in several directions on a 100 V bus.
        let inverse_dc = Q30::from_num(0.01);
        for k in 0..12 {
            let theta = k as f64 * core::f64::consts::FRAC_PI_6 + 0.1;
            let v = AlphaBeta { alpha: q16((57.0 * theta.cos()) as f32), beta: q16((57.0 * theta.sin()) as f32) };
            let d = duty_cycles(v, inverse_dc);
            let abc = inverse_clarke(v);
            // line voltage a-b = (d_a - d_b) V_dc
            let vab = (d[0] - d[1]).to_num::<f64>() * 100.0;
            assert!((vab - (abc.a - abc.b).to_num::<f64>()).abs() < 0.01, "k={k}");
            for duty in d {
                assert!(duty >= Q16::ZERO && duty <= Q16::ONE);
            }
        }
    }

    #[test]
    fn over_modulation_clamps() {
        let v = AlphaBeta { alpha: q16(30_000.0), beta: q16(-30_000.0) };
        let d = duty_cycles(v, Q30::from_num(0.01));
        assert!(d.iter().all(|x| *x >= Q16::ZERO && *x <= Q16::ONE));
        assert_eq!(d[0], Q16::ONE);
        assert_eq!(compare_values(d, 5312)[0], 5312);
    }
}
