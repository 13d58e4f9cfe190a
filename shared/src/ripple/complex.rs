//! A complex number in `f32` with only the four IEEE operations, so that the
//! chip and the host compute the same bits (no `hypot`, no `atan2`).

use core::ops::{Add, Div, Mul, Neg, Sub};

/// `re + j im`, dimension of whatever it stands for.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Complex {
    /// Real part.
    pub re: f32,
    /// Imaginary part.
    pub im: f32,
}

impl Complex {
    /// Zero.
    pub const ZERO: Self = Self { re: 0.0, im: 0.0 };
    /// One.
    pub const ONE: Self = Self { re: 1.0, im: 0.0 };

    /// `re + j im`.
    pub const fn new(re: f32, im: f32) -> Self {
        Self { re, im }
    }

    /// Complex conjugate.
    pub fn conj(self) -> Self {
        Self { re: self.re, im: -self.im }
    }

    /// `|z|^2`.
    pub fn norm_sqr(self) -> f32 {
        self.re * self.re + self.im * self.im
    }

    /// `z * k` for a real `k`.
    pub fn scale(self, k: f32) -> Self {
        Self { re: self.re * k, im: self.im * k }
    }

    /// `1 / z`; a zero `z` gives zero (never an infinity that travels).
    pub fn recip(self) -> Self {
        let n = self.norm_sqr();
        if n > 0.0 && n.is_finite() {
            Self { re: self.re / n, im: -self.im / n }
        } else {
            Self::ZERO
        }
    }

    /// Both parts finite.
    pub fn is_finite(self) -> bool {
        self.re.is_finite() && self.im.is_finite()
    }
}

impl Add for Complex {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self { re: self.re + o.re, im: self.im + o.im }
    }
}

impl Sub for Complex {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        Self { re: self.re - o.re, im: self.im - o.im }
    }
}

impl Neg for Complex {
    type Output = Self;
    fn neg(self) -> Self {
        Self { re: -self.re, im: -self.im }
    }
}

impl Mul for Complex {
    type Output = Self;
    fn mul(self, o: Self) -> Self {
        Self { re: self.re * o.re - self.im * o.im, im: self.re * o.im + self.im * o.re }
    }
}

impl Div for Complex {
    type Output = Self;
    #[allow(clippy::suspicious_arithmetic_impl)]
    fn div(self, o: Self) -> Self {
        self * o.recip()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn division_undoes_multiplication_and_zero_does_not_explode() {
        let a = Complex::new(1.5, -2.0);
        let b = Complex::new(-0.25, 3.0);
        let back = (a * b) / b;
        assert!((back - a).norm_sqr() < 1e-10, "{back:?}");
        assert_eq!(a / Complex::ZERO, Complex::ZERO);
        assert_eq!(Complex::new(0.0, 1.0) * Complex::new(0.0, 1.0), -Complex::ONE);
    }
}
