//! Fixed-point number types of the 16 kHz path.
//!
//! All arithmetic on these types in this crate saturates: a result outside
//! the range of the type sticks at the bound of the type, it never wraps.
//! Angles are the one exception by design: they are binary angles (see
//! [`crate::trig`]), where arithmetic modulo one turn *is* the mathematics.

use fixed::types::{I16F16, I2F30};

/// Signed Q16.16: range +-32768, resolution 2^-16 = 1.5e-5. Used for
/// currents (A), voltages (V), speeds (rad/s), torques (N m) and gains.
pub type Q16 = I16F16;

/// Signed Q2.30: range +-2, resolution 2^-30 = 9.3e-10. Used for small
/// factors that need more precision than [`Q16`] (the inverse DC bus, 1/V).
pub type Q30 = I2F30;

/// Saturating `a * b` of a [`Q16`] and a [`Q30`], as [`Q16`] (rounded to nearest).
#[inline]
pub fn mul_q30(a: Q16, b: Q30) -> Q16 {
    let wide = (a.to_bits() as i64 * b.to_bits() as i64 + (1 << 29)) >> 30;
    Q16::from_bits(wide.clamp(i32::MIN as i64, i32::MAX as i64) as i32)
}

/// Converts an `f32` to [`Q16`], saturating at the range of the type; NaN maps to zero.
pub fn q16(value: f32) -> Q16 {
    if value.is_nan() {
        Q16::ZERO
    } else {
        Q16::saturating_from_num(value)
    }
}

/// Saturating `a * b`.
#[inline]
pub fn mul(a: Q16, b: Q16) -> Q16 {
    a.saturating_mul(b)
}

/// Saturating `a + b`.
#[inline]
pub fn add(a: Q16, b: Q16) -> Q16 {
    a.saturating_add(b)
}

/// Saturating `a - b`.
#[inline]
pub fn sub(a: Q16, b: Q16) -> Q16 {
    a.saturating_sub(b)
}

/// `value` limited to `[lo, hi]` (assumes `lo <= hi`).
#[inline]
pub fn clamp(value: Q16, lo: Q16, hi: Q16) -> Q16 {
    if value > hi {
        hi
    } else if value < lo {
        lo
    } else {
        value
    }
}

/// Square root of a non-negative [`Q16`] (negative input gives zero),
/// truncated to 2^-8 (0.0039 for volts): the 32-bit integer square root of
/// the raw value, `sqrt(bits / 2^16) = isqrt(bits) / 2^8`, which the
/// Cortex-M4 computes without 64-bit arithmetic.
pub fn sqrt(value: Q16) -> Q16 {
    if value <= Q16::ZERO {
        return Q16::ZERO;
    }
    Q16::from_bits(((value.to_bits() as u32).isqrt() << 8) as i32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn saturates_instead_of_wrapping() {
        assert_eq!(add(Q16::MAX, Q16::ONE), Q16::MAX);
        assert_eq!(sub(Q16::MIN, Q16::ONE), Q16::MIN);
        assert_eq!(mul(q16(30_000.0), q16(-30_000.0)), Q16::MIN);
        assert_eq!(q16(1.0e9), Q16::MAX);
        assert_eq!(q16(f32::NAN), Q16::ZERO);
    }

    #[test]
    fn sqrt_within_its_stated_resolution() {
        for x in [0.0f64, 1.0e-4, 0.5, 2.0, 3333.3, 32_000.0] {
            let got = sqrt(Q16::from_num(x)).to_num::<f64>();
            let want = Q16::from_num(x).to_num::<f64>().sqrt();
            assert!(got <= want && want - got < 1.0 / 256.0, "sqrt({x}) = {got}, want {want}");
        }
    }
}
