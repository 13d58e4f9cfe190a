//! The drive's sensors as the controller sees them: 12-bit phase-current and
//! DC-bus ADC codes, the quadrature encoder counter and the microsecond
//! time stamp.

use rig_config::RigConfig;

/// Sensor scaling.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sensors {
    /// Amperes per phase-current code, A.
    pub current_lsb_a: f64,
    /// Code of zero current.
    pub current_zero_code: f64,
    /// Largest ADC code.
    pub adc_max_code: f64,
    /// DC-bus volts per code, V.
    pub dc_bus_lsb_v: f64,
    /// Encoder counts per mechanical revolution.
    pub encoder_counts_per_rev: f64,
}

impl Sensors {
    /// The sensors of `rig`.
    pub fn from_rig(rig: &RigConfig) -> Self {
        let inv = &rig.inverter;
        let half = (1u64 << (inv.adc_bits - 1)) as f64;
        let max = ((1u64 << inv.adc_bits) - 1) as f64;
        Self {
            current_lsb_a: inv.current_sense_full_scale_a / half,
            current_zero_code: half,
            adc_max_code: max,
            dc_bus_lsb_v: inv.dc_bus_sense_full_scale_v / max,
            encoder_counts_per_rev: inv.encoder_counts_per_rev as f64,
        }
    }

    /// ADC code of a phase current (rounded, clipped to the converter range).
    pub fn current_code(&self, current_a: f64) -> u16 {
        round(self.current_zero_code + current_a / self.current_lsb_a).clamp(0.0, self.adc_max_code) as u16
    }

    /// ADC code of the DC-bus voltage.
    pub fn dc_bus_code(&self, dc_bus_v: f64) -> u16 {
        round(dc_bus_v / self.dc_bus_lsb_v).clamp(0.0, self.adc_max_code) as u16
    }

    /// Encoder counter for the shaft angle `theta_m_rad` from the zero mark:
    /// whole counts, as the free-running 32-bit hardware counter holds them
    /// (modulo 2^32).
    pub fn encoder_count(&self, theta_m_rad: f64) -> u32 {
        let counts = floor_i64(theta_m_rad / std::f64::consts::TAU * self.encoder_counts_per_rev);
        counts.rem_euclid(1 << 32) as u32
    }

    /// Microsecond time stamp of `t_s` (a free-running 32-bit timer).
    pub fn time_us(t_s: f64) -> u32 {
        floor_i64(t_s * 1.0e6).rem_euclid(1 << 32) as u32
    }
}

/// [`f64::round`] (halves away from zero), the same value, without the
/// library call that baseline x86-64 (no SSE4.1 `roundsd`) makes of it:
/// below 2^52 in magnitude the integer part is exact as an `i64`, and the
/// fraction `x - trunc(x)` is exact.
#[inline]
fn round(x: f64) -> f64 {
    const LIMIT: f64 = (1u64 << 52) as f64;
    if x.abs() < LIMIT {
        let whole = (x as i64) as f64;
        let fraction = x - whole;
        // Without branches (the fraction is as often above a half as below):
        // the step away from zero, and the sign of `x` (-0.0 for a
        // negative `x` that rounds to zero, like `f64::round`).
        let step = (fraction >= 0.5) as i64 - (fraction <= -0.5) as i64;
        (whole + step as f64).copysign(x)
    } else {
        x.round()
    }
}

/// `x.floor() as i64` (saturating, NaN to 0), the same value without the
/// library call: the conversion truncates towards zero, one less below
/// zero when that was not whole (exact: below 2^52 in magnitude the
/// truncated value is exact as a float, above it `x` is whole).
#[inline]
fn floor_i64(x: f64) -> i64 {
    let t = x as i64;
    t.saturating_sub(((t as f64) > x) as i64)
}

#[cfg(test)]
mod tests {
    use super::{floor_i64, round};

    /// The same value as `floor() as i64`: whole numbers and their
    /// neighbours on both sides of zero, the limits and NaN.
    #[test]
    fn floor_is_the_standard_one() {
        let mut values = vec![0.0, -0.0, 0.5, -0.5, 1e300, -1e300, f64::INFINITY, f64::NEG_INFINITY, f64::NAN];
        values.extend([9.2e18, -9.2e18, 9.3e18, -9.3e18, 4503599627370495.5, -4503599627370495.5]);
        for k in -20000..20000 {
            let x = k as f64;
            values.extend([x, x.next_up(), x.next_down(), x * 0.123456789, x * 1.0e6 + 0.3]);
        }
        for x in values {
            assert_eq!(floor_i64(x), x.floor() as i64, "{x}");
        }
    }

    /// The same value as `f64::round` bit for bit: halves, neighbours of
    /// halves, signed zeros, large values and NaN.
    #[test]
    fn round_is_the_standard_one() {
        let mut values = vec![0.0, -0.0, 0.5, -0.5, 1.5, -1.5, 2.5, -2.5, 4095.5, 1e300, -1e300, f64::INFINITY];
        values.extend([0.49999999999999994, -0.49999999999999994, 4503599627370495.5, 4503599627370497.0]);
        for k in -20000..20000 {
            let x = k as f64 * 0.123456789 + 0.5;
            values.extend([x, x.next_up(), x.next_down(), (k as f64 + 0.5).next_down(), (k as f64 + 0.5).next_up()]);
        }
        for x in values {
            assert_eq!(round(x).to_bits(), x.round().to_bits(), "{x}");
        }
        assert!(round(f64::NAN).is_nan());
    }
}
