//! Angle-indexed harmonic torque: `u(theta) = sum_n Re(U_n e^{j n theta})`
//! over mechanical orders `n`, with `theta` the shaft angle from the
//! encoder. This is the form of the paper's ripple (section 3.3: orders 1,
//! 6, 12, 36 and 72 of the mechanical frequency) and of every compensation
//! strategy's output; evaluated at 16 kHz in fixed point.

use super::complex::Complex;
use crate::fixed::{mul_q30, q16, Q16};
use crate::trig::{sin_cos, Angle};

/// Most harmonics a compensator handles.
pub const MAX_HARMONICS: usize = 8;

/// Harmonic coefficients `U_n = a_n - j b_n` (so that
/// `Re(U_n e^{j n theta}) = a_n cos(n theta) + b_n sin(n theta)`), N m.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HarmonicTable {
    /// Mechanical orders (per revolution); the first `len` are used.
    pub orders: [u16; MAX_HARMONICS],
    /// Complex amplitudes `U_n`, N m.
    pub torque_nm: [Complex; MAX_HARMONICS],
    /// Number of harmonics in use.
    pub len: usize,
}

impl HarmonicTable {
    /// A table of `orders` (at most [`MAX_HARMONICS`]; the rest are dropped)
    /// with zero amplitudes.
    pub fn zero(orders: &[u16]) -> Self {
        let mut table = Self::default();
        for (slot, &order) in table.orders.iter_mut().zip(orders.iter()) {
            *slot = order;
            table.len += 1;
        }
        table
    }

    /// Appends order `order` with amplitude `amplitude_nm` and phase
    /// `(cos_phase, sin_phase)` of `amplitude cos(n theta + phase)`; false when full.
    pub fn push_cosine(&mut self, order: u16, amplitude_nm: f32, cos_phase: f32, sin_phase: f32) -> bool {
        if self.len == MAX_HARMONICS {
            return false;
        }
        // A cos(n theta + phi) = Re(A e^{j phi} e^{j n theta}).
        self.orders[self.len] = order;
        self.torque_nm[self.len] = Complex::new(amplitude_nm * cos_phase, amplitude_nm * sin_phase);
        self.len += 1;
        true
    }

    /// The table with every amplitude negated: the compensation of a ripple.
    pub fn negated(&self) -> Self {
        let mut table = *self;
        for u in table.torque_nm.iter_mut() {
            *u = -*u;
        }
        table
    }

    /// Torque at shaft angle `theta` (binary angle), N m, in `f32` (for tests and the host).
    pub fn torque_at_nm(&self, theta: Angle) -> f32 {
        (0..self.len)
            .map(|k| {
                let (s, c) = sin_cos(theta.wrapping_mul(self.orders[k] as u32));
                let u = self.torque_nm[k];
                u.re * c.to_num::<f32>() - u.im * s.to_num::<f32>()
            })
            .sum()
    }
}

/// The 16 kHz form of a [`HarmonicTable`]: q-current coefficients in fixed point.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HarmonicCurrent {
    orders: [u16; MAX_HARMONICS],
    /// `(a_n, b_n)` in q current, A.
    coefficients_a: [(Q16, Q16); MAX_HARMONICS],
    len: usize,
}

impl HarmonicCurrent {
    /// The q current of `table` for a machine of torque constant
    /// `torque_constant_nm_per_a`, with harmonics flagged in `muted` left out.
    pub fn from_table(table: &HarmonicTable, torque_constant_nm_per_a: f32, muted: &[bool; MAX_HARMONICS]) -> Self {
        let inverse_kt = 1.0 / torque_constant_nm_per_a;
        let mut current = Self { orders: table.orders, len: table.len, ..Self::default() };
        let used = table.len.min(MAX_HARMONICS);
        for ((slot, u), &mute) in current.coefficients_a.iter_mut().zip(&table.torque_nm).zip(muted).take(used) {
            if !mute {
                *slot = (q16(u.re * inverse_kt), q16(-u.im * inverse_kt));
            }
        }
        current
    }

    /// q current at shaft angle `theta` (binary angle), A: one sine/cosine
    /// lookup and two saturating multiplies per harmonic.
    pub fn at(&self, theta: Angle) -> Q16 {
        let mut sum = Q16::ZERO;
        for k in 0..self.len {
            let (a, b) = self.coefficients_a[k];
            if a == Q16::ZERO && b == Q16::ZERO {
                continue;
            }
            let (s, c) = sin_cos(theta.wrapping_mul(self.orders[k] as u32));
            sum = sum.saturating_add(mul_q30(a, c)).saturating_add(mul_q30(b, s));
        }
        sum
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::trig::angle_from_radians;

    #[test]
    fn fixed_point_current_matches_the_f64_harmonic_sum_within_a_few_lsb() {
        let mut table = HarmonicTable::default();
        for (order, amp, phase) in
            [(1u16, 2.0f64, 0.3f64), (6, 0.3, -1.0), (12, 3.5, 2.0), (36, 0.3, 0.1), (72, 0.5, -2.9)]
        {
            assert!(table.push_cosine(order, amp as f32, phase.cos() as f32, phase.sin() as f32));
        }
        let kt = 4.05f32;
        let current = HarmonicCurrent::from_table(&table.negated(), kt, &[false; MAX_HARMONICS]);
        for i in 0..2000 {
            let theta = i as f64 * 0.0137;
            let expected: f64 =
                [(1.0, 2.0, 0.3), (6.0, 0.3, -1.0), (12.0, 3.5, 2.0), (36.0, 0.3, 0.1), (72.0, 0.5, -2.9)]
                    .iter()
                    .map(|(n, a, p): &(f64, f64, f64)| -a * (n * theta + p).cos() / kt as f64)
                    .sum();
            let got = current.at(angle_from_radians(theta)).to_num::<f64>();
            // Q16 coefficients (2^-17 A each) and Q30 trig: 10 terms of at most 2e-5 A.
            assert!((got - expected).abs() < 1e-4, "theta {theta}: {got} vs {expected}");
            let torque = table.torque_at_nm(angle_from_radians(theta)) as f64;
            assert!((torque + expected * kt as f64).abs() < 1e-4, "{torque}");
        }
    }

    #[test]
    fn muted_harmonics_are_left_out() {
        let mut table = HarmonicTable::default();
        table.push_cosine(12, 4.05, 1.0, 0.0);
        table.push_cosine(36, 4.05, 1.0, 0.0);
        let mut muted = [false; MAX_HARMONICS];
        muted[0] = true;
        let current = HarmonicCurrent::from_table(&table, 4.05, &muted);
        // Only order 36 remains: cos(36 * 0) = 1 A at theta = 0, and at 1/144 turn cos(pi/2) = 0.
        assert!((current.at(0).to_num::<f64>() - 1.0).abs() < 1e-4);
        assert!(current.at(u32::MAX / 144).to_num::<f64>().abs() < 1e-3);
    }
}
