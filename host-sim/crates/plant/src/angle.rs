//! The plant's angle-locked terms, the ripple torque
//! `sum_n A_n cos(n theta + phi_n)` (N m) and the Park rotation
//! `(cos p theta, sin p theta)`, as Taylor polynomials of the shaft angle
//! `theta` (rad) about a reference angle, so that an integration stage
//! costs a few multiply-adds instead of a `sin_cos` and the harmonics'
//! powers.
//!
//! The polynomials have degree [`DEGREE`] and are used while the fastest
//! harmonic (order `n_max`, or the pole pairs `p` if more) has turned by at
//! most [`MAX_PHASE_RAD`] from the reference: the truncation error is then
//! at most `sum |A_n| x^13 / 13!` with `x = 0.3`, below `3e-17` of the
//! ripple's summed amplitude (and of the unit Park vector), below an ulp.
//! Outside that interval the terms are computed directly.

use crate::ripple::RippleTorque;

/// Degree of the Taylor polynomials.
pub const DEGREE: usize = 12;

/// Largest phase change, rad, of the fastest angle-locked term over which
/// the polynomials are used (either side of the reference angle).
pub const MAX_PHASE_RAD: f64 = 0.3;

/// Taylor polynomials of the ripple torque and the Park rotation about a
/// reference shaft angle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AngleSeries {
    /// Reference shaft angle, rad (NaN: no polynomial yet).
    theta_ref_rad: f64,
    /// Half width of the interval around the reference where the
    /// polynomials hold, rad.
    half_width_rad: f64,
    /// Coefficients of `delta^j` of the ripple torque, N m / rad^j.
    ripple_nm: [f64; DEGREE + 1],
    /// Coefficients of `delta^j` of the ripple torque's first three
    /// derivatives divided by `m!` (`m` = 1, 2, 3): `binom(j + m, m)
    /// ripple_nm[j + m]`, for [`AngleSeries::ripple_taylor`].
    ripple_shifted: [[f64; DEGREE + 1]; 3],
    /// Coefficients of `delta^j` of `cos(p theta)` and `sin(p theta)`, 1 /
    /// rad^j, side by side: the two polynomials evaluated as one of pairs.
    cos_sin_p: [[f64; 2]; DEGREE + 1],
}

impl Default for AngleSeries {
    fn default() -> Self {
        Self {
            theta_ref_rad: f64::NAN,
            half_width_rad: 0.0,
            ripple_nm: [0.0; DEGREE + 1],
            ripple_shifted: [[0.0; DEGREE + 1]; 3],
            cos_sin_p: [[0.0; 2]; DEGREE + 1],
        }
    }
}

/// Adds `scale d^j/dtheta^j cos(n theta + phase) / j!` at `theta = 0`
/// shifted by `phase` (rad) to `coefficients[j]`, for a term of order `n`.
fn add_cos_series(coefficients: &mut [f64; DEGREE + 1], scale: f64, n: f64, phase: f64) {
    let (s, c) = phase.sin_cos();
    let cycle = [c, -s, -c, s];
    let mut factor = scale;
    for (j, coefficient) in coefficients.iter_mut().enumerate() {
        *coefficient += factor * cycle[j % 4];
        factor *= n / (j + 1) as f64;
    }
}

/// `n` choose `k` (small arguments), as a float.
const fn binomial(n: usize, k: usize) -> f64 {
    let (mut acc, mut i) = (1.0, 0);
    while i < k {
        acc = acc * (n - i) as f64 / (i + 1) as f64;
        i += 1;
    }
    acc
}

/// `binomial(j + m, m)` at `[m - 1][j]` for `m` = 1, 2, 3: the factors of
/// [`AngleSeries`]'s shifted ripple coefficients, worked out when the crate
/// is compiled rather than at every refresh.
const SHIFT_BINOMIALS: [[f64; DEGREE + 1]; 3] = {
    let mut table = [[0.0; DEGREE + 1]; 3];
    let mut m = 1;
    while m <= 3 {
        let mut j = 0;
        while j + m <= DEGREE {
            table[m - 1][j] = binomial(j + m, m);
            j += 1;
        }
        m += 1;
    }
    table
};

/// `sum_j coefficients[j] x^j` by Estrin's scheme: pairs, then pairs of
/// pairs with `x^2`, `x^4`, `x^8`, so that the chain of dependent
/// operations is 5 multiply-adds long instead of Horner's 12 (the
/// polynomials sit on the path of every integration stage). The same value
/// as Horner's rule to a few ulps (the terms fall by `0.3^j / j!`).
fn estrin(c: &[f64; DEGREE + 1], x: f64) -> f64 {
    const _: () = assert!(DEGREE == 12, "Estrin's scheme below is written for degree 12");
    let x2 = x * x;
    let x4 = x2 * x2;
    let x8 = x4 * x4;
    let p01 = c[0] + c[1] * x;
    let p23 = c[2] + c[3] * x;
    let p45 = c[4] + c[5] * x;
    let p67 = c[6] + c[7] * x;
    let p89 = c[8] + c[9] * x;
    let p1011 = c[10] + c[11] * x;
    let low = (p01 + p23 * x2) + (p45 + p67 * x2) * x4;
    let high = (p89 + p1011 * x2) + c[12] * x4;
    low + high * x8
}

/// [`estrin`] of two polynomials at once, their coefficients side by side:
/// every operation of the scheme on both lanes (the same values, one
/// vector instruction for two).
fn estrin_pairs(c: &[[f64; 2]; DEGREE + 1], x: f64) -> [f64; 2] {
    // `a + b x` lane by lane (a product, then a sum: no fused operation).
    let affine = |a: [f64; 2], b: [f64; 2], x: f64| [a[0] + b[0] * x, a[1] + b[1] * x];
    let x2 = x * x;
    let x4 = x2 * x2;
    let x8 = x4 * x4;
    let p01 = affine(c[0], c[1], x);
    let p23 = affine(c[2], c[3], x);
    let p45 = affine(c[4], c[5], x);
    let p67 = affine(c[6], c[7], x);
    let p89 = affine(c[8], c[9], x);
    let p1011 = affine(c[10], c[11], x);
    let low = affine(affine(p01, p23, x2), affine(p45, p67, x2), x4);
    let high = affine(affine(p89, p1011, x2), c[12], x4);
    affine(low, high, x8)
}

/// The angle-locked terms computed directly at shaft angle `theta_rad`
/// (rad), where the polynomials do not hold: the ripple torque (N m) of
/// `ripple` (zero without it), `cos(p theta)` and `sin(p theta)` for
/// `pole_pairs` `p`. Out of line: the polynomials' callers stay short.
#[cold]
#[inline(never)]
fn direct_terms(theta_rad: f64, ripple: Option<&RippleTorque>, pole_pairs: f64) -> (f64, f64, f64) {
    let (s, c) = (pole_pairs * theta_rad).sin_cos();
    (ripple.map_or(0.0, |r| r.torque_nm(theta_rad)), c, s)
}

impl AngleSeries {
    /// True when the polynomials hold at shaft angle `theta_rad` (rad).
    pub fn covers(&self, theta_rad: f64) -> bool {
        (theta_rad - self.theta_ref_rad).abs() <= self.half_width_rad
    }

    /// Makes sure the polynomials hold at `theta_rad` (rad) with half their
    /// interval to spare (for the stages of a step from there): refreshes
    /// them about `theta_rad` for `ripple` and `pole_pairs` otherwise.
    pub fn ensure(&mut self, theta_rad: f64, ripple: &RippleTorque, pole_pairs: f64) {
        // A NaN reference (no polynomial yet) compares false: refresh.
        let inside = (theta_rad - self.theta_ref_rad).abs() <= 0.5 * self.half_width_rad;
        if !inside {
            self.refresh(theta_rad, ripple, pole_pairs);
        }
    }

    /// Makes sure the polynomials hold from `theta_rad` (rad) over a
    /// further `step_rad` (rad, signed: the shaft's turn over the coming
    /// step) with a twentieth of their interval to spare; refreshes them
    /// otherwise, about a reference half their half-width ahead of
    /// `theta_rad` in the direction of `step_rad` (when the step is short
    /// beside the interval), so that a shaft turning steadily uses them
    /// about three times as long as with [`AngleSeries::ensure`].
    pub fn ensure_ahead(&mut self, theta_rad: f64, step_rad: f64, ripple: &RippleTorque, pole_pairs: f64) {
        let reach = step_rad.abs();
        // A NaN reference (no polynomial yet) compares false: refresh.
        let inside = (theta_rad - self.theta_ref_rad).abs() + reach <= 0.95 * self.half_width_rad;
        if !inside {
            let half_width = Self::half_width_rad(ripple, pole_pairs);
            let ahead = if reach <= 0.4 * half_width { (0.5 * half_width).copysign(step_rad) } else { 0.0 };
            self.refresh(theta_rad + ahead, ripple, pole_pairs);
        }
    }

    /// Half width of the polynomials' interval, rad, for `ripple` and
    /// `pole_pairs`: [`MAX_PHASE_RAD`] of the fastest term.
    fn half_width_rad(ripple: &RippleTorque, pole_pairs: f64) -> f64 {
        let fastest = ripple.harmonics.iter().map(|h| h.mechanical_order.abs()).fold(pole_pairs.abs(), f64::max);
        MAX_PHASE_RAD / fastest.max(1.0)
    }

    /// The polynomials about `theta_rad` (rad) for `ripple` and `pole_pairs`.
    pub fn refresh(&mut self, theta_rad: f64, ripple: &RippleTorque, pole_pairs: f64) {
        *self = Self {
            theta_ref_rad: theta_rad,
            half_width_rad: Self::half_width_rad(ripple, pole_pairs),
            ..Self::default()
        };
        for h in &ripple.harmonics {
            let n = h.mechanical_order;
            add_cos_series(&mut self.ripple_nm, h.amplitude_nm, n, n * theta_rad + h.phase_rad);
        }
        for (m, (shifted, factors)) in (1..).zip(self.ripple_shifted.iter_mut().zip(&SHIFT_BINOMIALS)) {
            for ((slot, c), factor) in shifted.iter_mut().zip(&self.ripple_nm[m..]).zip(factors) {
                *slot = factor * c;
            }
        }
        let electrical = pole_pairs * theta_rad;
        let mut cos_p = [0.0; DEGREE + 1];
        let mut sin_p = [0.0; DEGREE + 1];
        add_cos_series(&mut cos_p, 1.0, pole_pairs, electrical);
        add_cos_series(&mut sin_p, 1.0, pole_pairs, electrical - 0.5 * std::f64::consts::PI);
        self.cos_sin_p = std::array::from_fn(|j| [cos_p[j], sin_p[j]]);
    }

    /// `cos(p theta)` and `sin(p theta)` from the polynomials at `delta`
    /// (rad) from the reference.
    fn cos_sin(&self, delta: f64) -> (f64, f64) {
        let [c, s] = estrin_pairs(&self.cos_sin_p, delta);
        (c, s)
    }

    /// Taylor coefficients of the ripple torque about `theta_rad` (rad):
    /// `R(theta + d) = sum_m c_m d^m + O(d^4)`, N m / rad^m, from the
    /// polynomial (the reference's re-expanded at `theta_rad`; call
    /// [`AngleSeries::ensure`] first so that it holds there).
    pub fn ripple_taylor(&self, theta_rad: f64) -> [f64; 4] {
        let delta = theta_rad - self.theta_ref_rad;
        // The m-th coefficient about theta_rad is the m-th derivative over
        // m! there: four independent polynomials (no chain of dependent
        // passes).
        let [d1, d2, d3] = &self.ripple_shifted;
        [estrin(&self.ripple_nm, delta), estrin(d1, delta), estrin(d2, delta), estrin(d3, delta)]
    }

    /// Ripple torque (N m) at shaft angle `theta_rad` (rad): from the
    /// polynomial where it holds, else computed directly from `ripple`.
    pub fn ripple_nm(&self, theta_rad: f64, ripple: &RippleTorque) -> f64 {
        let delta = theta_rad - self.theta_ref_rad;
        if delta.abs() <= self.half_width_rad {
            estrin(&self.ripple_nm, delta)
        } else {
            ripple.torque_nm(theta_rad)
        }
    }

    /// `cos(p theta)` and `sin(p theta)` at shaft angle `theta_rad` (rad),
    /// the same values as [`AngleSeries::eval`]'s without the ripple.
    #[inline]
    pub fn park(&self, theta_rad: f64, pole_pairs: f64) -> (f64, f64) {
        let delta = theta_rad - self.theta_ref_rad;
        if delta.abs() <= self.half_width_rad {
            self.cos_sin(delta)
        } else {
            let (_, c, s) = direct_terms(theta_rad, None, pole_pairs);
            (c, s)
        }
    }

    /// Ripple torque (N m), `cos(p theta)` and `sin(p theta)` at shaft
    /// angle `theta_rad` (rad): from the polynomials where they hold, else
    /// computed directly from `ripple` and `pole_pairs`.
    #[inline]
    pub fn eval(&self, theta_rad: f64, ripple: &RippleTorque, pole_pairs: f64) -> (f64, f64, f64) {
        let delta = theta_rad - self.theta_ref_rad;
        if delta.abs() <= self.half_width_rad {
            let (c, s) = self.cos_sin(delta);
            (estrin(&self.ripple_nm, delta), c, s)
        } else {
            direct_terms(theta_rad, Some(ripple), pole_pairs)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ripple::RippleHarmonic;

    /// The polynomials agree with the direct terms over their interval, at
    /// angles near zero and far into a travel, and are refreshed outside.
    #[test]
    fn polynomials_match_the_direct_terms() {
        let ripple = RippleTorque {
            harmonics: [(1.0, 2.0, 0.0), (6.0, 0.3, 0.4), (12.0, 3.5, -1.0), (36.0, 0.3, 2.0), (72.0, 0.5, 0.1)]
                .iter()
                .map(|&(n, a, phi)| RippleHarmonic { mechanical_order: n, amplitude_nm: a, phase_rad: phi })
                .collect(),
        };
        let p = 6.0;
        let mut series = AngleSeries::default();
        assert!(!series.covers(0.0));
        for theta0 in [0.0, -3.7, 101.3] {
            series.refresh(theta0, &ripple, p);
            let half = MAX_PHASE_RAD / 72.0;
            for k in -20..=20 {
                let theta = theta0 + 0.999 * half * k as f64 / 20.0;
                assert!(series.covers(theta));
                let (r, c, s) = series.eval(theta, &ripple, p);
                let direct: f64 = ripple
                    .harmonics
                    .iter()
                    .map(|h| h.amplitude_nm * (h.mechanical_order * theta + h.phase_rad).cos())
                    .sum();
                assert!((r - direct).abs() < 1e-12, "ripple at {theta}: {r} vs {direct}");
                assert_eq!(series.ripple_nm(theta, &ripple), r);
                assert!((c - (p * theta).cos()).abs() < 1e-13 && (s - (p * theta).sin()).abs() < 1e-13);
            }
            // The re-expanded coefficients against finite differences of the direct terms.
            let at = theta0 + 0.4 * half;
            let q = series.ripple_taylor(at);
            let direct = |t: f64| {
                ripple
                    .harmonics
                    .iter()
                    .map(|h| h.amplitude_nm * (h.mechanical_order * t + h.phase_rad).cos())
                    .sum::<f64>()
            };
            let d = 1e-6;
            let first = (direct(at + d) - direct(at - d)) / (2.0 * d);
            let d = 1e-5;
            let second = (direct(at + d) - 2.0 * direct(at) + direct(at - d)) / (d * d);
            assert!((q[0] - direct(at)).abs() < 1e-12, "{} vs {}", q[0], direct(at));
            assert!((q[1] - first).abs() < 1e-6 * first.abs().max(1.0), "{} vs {first}", q[1]);
            assert!((2.0 * q[2] - second).abs() < 1e-5 * second.abs().max(1.0), "{} vs {second}", 2.0 * q[2]);
            assert!(!series.covers(theta0 + 1.01 * half));
            let outside = theta0 + 1.5 * half;
            assert!((series.ripple_nm(outside, &ripple) - direct(outside)).abs() < 1e-12, "computed directly outside");
            let mut moved = series;
            moved.ensure(theta0 + 0.6 * half, &ripple, p);
            assert_ne!(moved, series, "refreshed beyond half the interval");
        }
    }
}
