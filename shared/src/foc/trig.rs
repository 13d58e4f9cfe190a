//! Sine and cosine of binary angles, identical bits on every target.
//!
//! An angle is a `u32` fraction of one turn (binary angle measurement:
//! `2^32` = 2 pi rad). Adding angles modulo a turn is the arithmetic of a
//! circle, so angle sums use `wrapping_add` on purpose; nothing else does.
//!
//! The values come from a quarter-wave table of 257 entries in Q1.30,
//! computed at compile time by an integer Taylor series (no floating point,
//! no libm), with linear interpolation between entries. Worst-case error
//! against the exact sine: 5e-6 (table step pi/512, interpolation bound
//! step^2/8 = 4.7e-6) plus the Q16.16 rounding of the result (7.6e-6).

use crate::fixed::Q30;

/// A binary angle: `u32` fraction of a turn (`1 << 32` = 2 pi rad).
pub type Angle = u32;

/// A quarter turn as a binary angle.
pub const QUARTER_TURN: u32 = 1 << 30;

const SEGMENTS: usize = 256;
/// pi/2 in Q60 (1811004864519280711 = round(pi/2 * 2^60)).
const HALF_PI_Q60: i128 = 1_811_004_864_519_280_711;

/// sin(k/SEGMENTS * pi/2) in Q30, by Taylor series in Q60 integer arithmetic.
const fn sin_entry_q30(k: usize) -> i32 {
    let x: i128 = HALF_PI_Q60 * k as i128 / SEGMENTS as i128;
    let x2: i128 = (x * x) >> 60;
    let mut term: i128 = x;
    let mut sum: i128 = x;
    let mut n: i128 = 1;
    while n < 30 {
        // term_{n+2} = -term_n * x^2 / ((n+1)(n+2))
        term = -((term * x2) >> 60) / ((n + 1) * (n + 2));
        sum += term;
        n += 2;
    }
    // Q60 -> Q30 with rounding.
    ((sum + (1 << 29)) >> 30) as i32
}

const fn build_table() -> [i32; SEGMENTS + 1] {
    let mut table = [0i32; SEGMENTS + 1];
    let mut k = 0;
    while k <= SEGMENTS {
        table[k] = sin_entry_q30(k);
        k += 1;
    }
    table
}

/// sin over the first quadrant, Q30, 257 points from 0 to pi/2 inclusive.
static QUARTER_SINE_Q30: [i32; SEGMENTS + 1] = build_table();

/// sin of an angle in the first quadrant given as `0..=QUARTER_TURN`, Q30.
fn quarter_sine_q30(position: u32) -> i32 {
    // 256 segments of 2^22 each; 16 bits of interpolation fraction.
    let index = (position >> 22) as usize;
    if index >= SEGMENTS {
        return QUARTER_SINE_Q30[SEGMENTS];
    }
    let fraction = ((position >> 6) & 0xFFFF) as i64;
    let lo = QUARTER_SINE_Q30[index] as i64;
    let hi = QUARTER_SINE_Q30[index + 1] as i64;
    (lo + (((hi - lo) * fraction + (1 << 15)) >> 16)) as i32
}

/// sin of a binary angle, Q30.
fn sine_q30(angle: Angle) -> i32 {
    let quadrant = angle >> 30;
    let position = angle & (QUARTER_TURN - 1);
    match quadrant {
        0 => quarter_sine_q30(position),
        1 => quarter_sine_q30(QUARTER_TURN - position),
        2 => -quarter_sine_q30(position),
        _ => -quarter_sine_q30(QUARTER_TURN - position),
    }
}

/// (sin, cos) of a binary angle, dimensionless Q2.30.
pub fn sin_cos(angle: Angle) -> (Q30, Q30) {
    (Q30::from_bits(sine_q30(angle)), Q30::from_bits(sine_q30(angle.wrapping_add(QUARTER_TURN))))
}

/// Binary angle of `radians` (any real value, reduced modulo 2 pi), for
/// configuration and tests; not used on the 16 kHz path.
pub fn angle_from_radians(radians: f64) -> Angle {
    let turns = radians / core::f64::consts::TAU;
    let fraction = turns - ((turns as i64) as f64);
    let fraction = if fraction < 0.0 { fraction + 1.0 } else { fraction };
    (fraction * 4_294_967_296.0) as u64 as u32
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    #[test]
    fn matches_f64_sine_everywhere() {
        let mut worst = 0.0f64;
        for k in 0..200_003u64 {
            let angle = (k * 21_474_733) as u32; // a stride coprime to 2^32 spread over the circle
            let radians = angle as f64 / 4_294_967_296.0 * core::f64::consts::TAU;
            let (s, c) = sin_cos(angle);
            worst = worst.max((s.to_num::<f64>() - radians.sin()).abs());
            worst = worst.max((c.to_num::<f64>() - radians.cos()).abs());
        }
        assert!(worst < 5.0e-6, "worst error {worst}");
    }

    #[test]
    fn table_end_points_are_exact() {
        assert_eq!(QUARTER_SINE_Q30[0], 0);
        assert_eq!(QUARTER_SINE_Q30[SEGMENTS], 1 << 30);
        assert_eq!(sin_cos(0), (Q30::ZERO, Q30::ONE));
        assert_eq!(sin_cos(QUARTER_TURN), (Q30::ONE, Q30::ZERO));
    }

    #[test]
    fn radians_to_binary_angle() {
        assert_eq!(angle_from_radians(0.0), 0);
        assert_eq!(angle_from_radians(core::f64::consts::FRAC_PI_2), QUARTER_TURN);
        assert_eq!(angle_from_radians(-core::f64::consts::FRAC_PI_2), 3 * QUARTER_TURN);
    }
}
