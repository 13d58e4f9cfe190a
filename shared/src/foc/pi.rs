//! Discrete PI controller with output limits and anti-windup.
//!
//! `u = clamp(p + x)` with `p = Kp e + ff` and the integrator
//! `x <- clamp(x + Ki Ts e, min(lo - p, 0), max(hi - p, 0))`: dynamic
//! clamping, so the integrator never holds more than the output limits leave
//! room for (no wind-up), and the output is a continuous function of the
//! inputs (no branch that a rounding difference could flip). Saturating
//! fixed point throughout.

use crate::fixed::{add, clamp, mul, sub, Q16};

/// PI gains in discrete form.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PiGains {
    /// Proportional gain `Kp` (output unit per input unit).
    pub kp: Q16,
    /// Integral gain times the sample period, `Ki Ts` (output unit per input unit and step).
    pub ki_ts: Q16,
}

/// PI controller state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pi {
    gains: PiGains,
    integral: Q16,
}

impl Pi {
    /// A PI controller with an empty integrator.
    pub const fn new(gains: PiGains) -> Self {
        Self { gains, integral: Q16::ZERO }
    }

    /// Integrator value (output unit).
    pub fn integral(&self) -> Q16 {
        self.integral
    }

    /// Empties the integrator.
    pub fn reset(&mut self) {
        self.integral = Q16::ZERO;
    }

    /// Sets the integrator so that a zero error gives `value` (bumpless start).
    pub fn preset(&mut self, value: Q16) {
        self.integral = value;
    }

    /// One step: `error` (input unit), `feed_forward` and the limits `lo <= hi`
    /// (output unit). Returns the limited output.
    pub fn update(&mut self, error: Q16, feed_forward: Q16, lo: Q16, hi: Q16) -> Q16 {
        let proportional = add(mul(self.gains.kp, error), feed_forward);
        let upper = sub(hi, proportional).max(Q16::ZERO);
        let lower = sub(lo, proportional).min(Q16::ZERO);
        self.integral = clamp(add(self.integral, mul(self.gains.ki_ts, error)), lower, upper);
        clamp(add(proportional, self.integral), lo, hi)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixed::q16;

    #[test]
    fn integrates_constant_error() {
        let mut pi = Pi::new(PiGains { kp: q16(2.0), ki_ts: q16(0.5) });
        let mut out = Q16::ZERO;
        for _ in 0..4 {
            out = pi.update(q16(1.0), Q16::ZERO, q16(-100.0), q16(100.0));
        }
        assert_eq!(out, q16(4.0)); // 2*1 + 4*0.5
    }

    #[test]
    fn does_not_wind_up_in_saturation() {
        let mut pi = Pi::new(PiGains { kp: q16(1.0), ki_ts: q16(1.0) });
        for _ in 0..1000 {
            assert_eq!(pi.update(q16(50.0), Q16::ZERO, q16(-10.0), q16(10.0)), q16(10.0));
        }
        assert!(pi.integral() <= q16(10.0));
        // The error reverses: the output leaves the limit at once.
        let out = pi.update(q16(-5.0), Q16::ZERO, q16(-10.0), q16(10.0));
        assert!(out < q16(10.0), "{out}");
    }
}
