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
    Q16::from_bits(saturate((a.to_bits() as i64 * b.to_bits() as i64 + (1 << 29)) >> 30))
}

/// `wide` limited to the `i32` range (one compare of the high word on the Cortex-M4).
#[inline]
fn saturate(wide: i64) -> i32 {
    let narrow = wide as i32;
    if narrow as i64 == wide {
        narrow
    } else if wide < 0 {
        i32::MIN
    } else {
        i32::MAX
    }
}

/// Converts an `f32` to [`Q16`], saturating at the range of the type; NaN maps to zero.
pub fn q16(value: f32) -> Q16 {
    if value.is_nan() {
        Q16::ZERO
    } else {
        Q16::saturating_from_num(value)
    }
}

/// Saturating `a * b`, rounded toward minus infinity: one 32x32->64-bit
/// multiply, a shift and a clamp (the `fixed` crate's generic saturating
/// multiply costs over ten times more on the Cortex-M4).
#[inline]
pub fn mul(a: Q16, b: Q16) -> Q16 {
    Q16::from_bits(saturate((a.to_bits() as i64 * b.to_bits() as i64) >> 16))
}

/// `count` (a whole number, e.g. ADC codes) times `scale`, saturating.
#[inline]
pub fn mul_int(count: i32, scale: Q16) -> Q16 {
    Q16::from_bits(count.saturating_mul(scale.to_bits()))
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
    fn multiplication_matches_the_fixed_crate_and_saturates() {
        let values = [0.0f32, 1.0, -1.0, 0.5, -2.75, 123.456, -0.000_1, 181.0, 30_000.0, -30_000.0];
        for &a in &values {
            for &b in &values {
                let (a, b) = (q16(a), q16(b));
                // The fixed crate rounds toward minus infinity too.
                assert_eq!(mul(a, b), a.saturating_mul(b), "{a} * {b}");
            }
        }
        // 4095 codes of 3200/65536 V: exactly 13 104 000 / 65536 V.
        assert_eq!(mul_int(4095, Q16::from_bits(3200)), Q16::from_bits(13_104_000));
        assert_eq!(mul_int(i32::MAX, Q16::ONE), Q16::MAX);
    }

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
