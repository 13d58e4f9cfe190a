//! The least-squares fit of one angle-locked line: `x ~ a cos(n theta) +
//! b sin(n theta)` over samples of the angle `theta`, for lines read
//! against a measured angle (not a time base), where the angle's speed
//! varies and the record holds no whole number of periods.

/// Cosine and sine coefficients `[a, b]` (units of `x`) of the line at
/// `order` times the angle `theta_rad` (rad) that fits `x` best in the
/// least-squares sense over the pair (the mean is not fitted: remove it
/// first). `[0, 0]` when the pair cannot be told apart (fewer than two
/// distinct phases).
pub fn sine_fit(x: &[f64], theta_rad: &[f64], order: f64) -> [f64; 2] {
    let (mut cc, mut ss, mut cs, mut xc, mut xs) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (&v, &t) in x.iter().zip(theta_rad) {
        let (s, c) = (order * t).sin_cos();
        cc += c * c;
        ss += s * s;
        cs += c * s;
        xc += v * c;
        xs += v * s;
    }
    let det = cc * ss - cs * cs;
    if det.abs() < f64::EPSILON * (cc * ss).max(1.0) {
        return [0.0, 0.0];
    }
    [(ss * xc - cs * xs) / det, (cc * xs - cs * xc) / det]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A line over a fraction of a period and an uneven angle: the pair is
    /// solved, not projected, so the coefficients come back exactly.
    #[test]
    fn recovers_a_line_over_an_uneven_part_of_a_period() {
        let theta: Vec<f64> = (0..500).map(|k| 0.4 + 0.002 * k as f64 + 1e-6 * (k * k) as f64).collect();
        let x: Vec<f64> = theta.iter().map(|t| 0.7 * (3.0 * t).cos() - 0.2 * (3.0 * t).sin()).collect();
        let [a, b] = sine_fit(&x, &theta, 3.0);
        assert!((a - 0.7).abs() < 1e-9 && (b + 0.2).abs() < 1e-9, "{a} {b}");
    }

    #[test]
    fn a_single_phase_cannot_be_split() {
        assert_eq!(sine_fit(&[1.0, 1.0], &[0.3, 0.3], 1.0), [0.0, 0.0]);
    }
}
