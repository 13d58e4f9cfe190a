//! The rate of a sampled signal by central differences.

/// The rate of `x` sampled at `fs` Hz, in the unit of `x` per second:
/// central differences inside, one-sided at the ends; 0 for a single
/// sample, empty for none.
pub fn central_difference(x: &[f64], fs: f64) -> Vec<f64> {
    let n = x.len();
    (0..n)
        .map(|k| {
            let (a, b) = (k.saturating_sub(1), (k + 1).min(n.saturating_sub(1)));
            if b > a {
                (x[b] - x[a]) * fs / (b - a) as f64
            } else {
                0.0
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_parabola_has_its_exact_rate_inside_and_a_one_sided_one_at_the_ends() {
        // x = t^2 at 10 Hz: central differences are exact for a parabola.
        let fs = 10.0;
        let x: Vec<f64> = (0..5).map(|k| (k as f64 / fs).powi(2)).collect();
        let v = central_difference(&x, fs);
        for k in 1..4 {
            assert!((v[k] - 2.0 * k as f64 / fs).abs() < 1e-12, "{v:?}");
        }
        assert!((v[0] - 0.1).abs() < 1e-12 && (v[4] - 0.7).abs() < 1e-12, "{v:?}");
        assert_eq!(central_difference(&[3.0], fs), [0.0]);
        assert!(central_difference(&[], fs).is_empty());
    }
}
