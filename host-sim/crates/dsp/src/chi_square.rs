//! The chi-square law of a spectral estimate: a power averaged over `K`
//! independent complex estimates, each a fixed amplitude plus complex
//! Gaussian noise, is `N / (2 K)` times a noncentral chi-square variable
//! of `2 K` degrees of freedom and noncentrality `2 K S / N` (`S` the
//! signal's power, `N` the noise's mean power). From a measured power it
//! gives the interval of signal powers the measurement allows
//! ([`signal_power_interval`]); a single estimate's is far from symmetric
//! in dB (pure noise reads below a fiftieth of its mean one time in fifty),
//! which a log-normal approximation misses.
//!
//! The noncentral law is the Poisson mixture of central ones (exact) below
//! ten degrees of freedom and up to a half noncentrality of 50, and
//! Patnaik's two-moment approximation (`c chi^2_nu`, near normal there)
//! otherwise; the central one goes through the regularized incomplete
//! gamma function (series and continued fraction, Numerical Recipes 6.2)
//! below thirty degrees of freedom, Wilson and Hilferty's normal law from
//! there on.

/// `ln Gamma(x)` for `x > 0` (Lanczos, g = 7, nine coefficients; relative
/// error below 1e-13).
pub fn ln_gamma(x: f64) -> f64 {
    const G: f64 = 7.0;
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection: Gamma(x) Gamma(1 - x) = pi / sin(pi x).
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let t = x + G + 0.5;
    let sum = C.iter().enumerate().skip(1).fold(C[0], |s, (i, c)| s + c / (x + i as f64));
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + sum.ln()
}

/// The regularized lower incomplete gamma function `P(a, x)` (`a > 0`,
/// `x >= 0`): the chance that a Gamma(a, 1) variable is at most `x`.
pub fn regularized_gamma_p(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    let front = (a * x.ln() - x - ln_gamma(a)).exp();
    if x < a + 1.0 {
        // Series: P = x^a e^-x / Gamma(a + 1) sum x^n / ((a + 1) ... (a + n)).
        let (mut term, mut sum, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..10_000 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-15 {
                break;
            }
        }
        (front * sum).clamp(0.0, 1.0)
    } else {
        // Continued fraction for Q = 1 - P (modified Lentz).
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let delta = d * c;
            h *= delta;
            if (delta - 1.0).abs() < 1e-15 {
                break;
            }
        }
        (1.0 - front * h).clamp(0.0, 1.0)
    }
}

/// Below this many degrees of freedom (and up to
/// [`EXACT_HALF_NONCENTRALITY`]) the noncentral law is summed exactly.
const EXACT_DOF: f64 = 10.0;

/// Above this half noncentrality the noncentral law is taken by Patnaik's
/// approximation (the law is near normal there).
const EXACT_HALF_NONCENTRALITY: f64 = 50.0;

/// From this many degrees of freedom on, the central law is Wilson and
/// Hilferty's (the cube root of `chi^2_nu / nu` normal; its distribution
/// function within about 0.002 of the exact one there).
const WILSON_HILFERTY_DOF: f64 = 30.0;

/// The distribution function of the central chi-square law of `nu > 0`
/// degrees of freedom at `x`: the regularized incomplete gamma function
/// below [`WILSON_HILFERTY_DOF`], Wilson and Hilferty's normal law of
/// `(x / nu)^(1/3)` from there on.
pub fn chi_square_cdf(nu: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if nu < WILSON_HILFERTY_DOF {
        return regularized_gamma_p(0.5 * nu, 0.5 * x);
    }
    let v = 2.0 / (9.0 * nu);
    standard_normal_cdf(((x / nu).cbrt() - (1.0 - v)) / v.sqrt())
}

/// The standard normal distribution function, through the complementary
/// error function's Chebyshev fit (Numerical Recipes 6.2, `erfcc`:
/// fractional error below 1.2e-7).
pub fn standard_normal_cdf(z: f64) -> f64 {
    let x = -z / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.5 * x.abs());
    let poly = -x * x - 1.265_512_23
        + t * (1.000_023_68
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06
                        + t * (0.278_868_07
                            + t * (-1.135_203_98 + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77))))))));
    let erfc = t * poly.exp();
    0.5 * if x >= 0.0 { erfc } else { 2.0 - erfc }
}

/// The distribution function of the noncentral chi-square law of `k > 0`
/// degrees of freedom and noncentrality `lambda >= 0` at `x`: below ten
/// degrees of freedom and a half noncentrality of 50 the Poisson mixture
/// `sum_j e^(-lambda/2) (lambda/2)^j / j! P(k/2 + j, x/2)` (the incomplete
/// gammas by their recurrence `P(a + 1, y) = P(a, y) - y^a e^-y / Gamma(a + 1)`),
/// otherwise Patnaik's `c chi^2_nu` with `c = (k + 2 lambda) / (k + lambda)`
/// and `nu = (k + lambda)^2 / (k + 2 lambda)` (the same mean and variance).
pub fn noncentral_chi_square_cdf(k: f64, lambda: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    let (a, y, mu) = (0.5 * k, 0.5 * x, 0.5 * lambda.max(0.0));
    if k >= EXACT_DOF || mu > EXACT_HALF_NONCENTRALITY {
        let c = (k + 2.0 * lambda) / (k + lambda);
        let nu = (k + lambda) * (k + lambda) / (k + 2.0 * lambda);
        return chi_square_cdf(nu, x / c);
    }
    let last = (mu + 12.0 * mu.sqrt() + 30.0).ceil() as usize;
    let mut gamma_p = regularized_gamma_p(a, y);
    let mut ln_term = a * y.ln() - y - ln_gamma(a + 1.0);
    let ln_mu = if mu > 0.0 { mu.ln() } else { f64::NEG_INFINITY };
    let ln_y = y.ln();
    let mut ln_weight = -mu;
    let mut sum = 0.0;
    for j in 0..=last {
        sum += ln_weight.exp() * gamma_p.max(0.0);
        // Next: P(a + j + 1, y) and the Poisson weight of j + 1.
        gamma_p -= ln_term.exp();
        ln_term += ln_y - (a + j as f64 + 1.0).ln();
        ln_weight += ln_mu - ((j + 1) as f64).ln();
    }
    sum.clamp(0.0, 1.0)
}

/// The chance (0-1) that a power averaged over `averages >= 1` independent
/// complex estimates of a signal of power `signal` (unit^2) in noise of
/// mean power `noise > 0` (unit^2) per estimate reads at most `x`
/// (unit^2): the noncentral chi-square law of `2 K` degrees of freedom and
/// noncentrality `2 K signal / noise` at `2 K x / noise`.
pub fn averaged_power_cdf(signal: f64, noise: f64, averages: f64, x: f64) -> f64 {
    let k = 2.0 * averages.max(1.0);
    noncentral_chi_square_cdf(k, k * signal.max(0.0) / noise, k * x / noise)
}

/// The signal powers (unit^2) a power `measured` (unit^2), averaged over
/// `averages >= 1` estimates in noise of mean power `noise` (unit^2) per
/// estimate, allows at the two-sided level `1 - 2 tail`: from
/// `signal_power_limit(.., 1 - tail)` to `signal_power_limit(.., tail)`.
pub fn signal_power_interval(measured: f64, noise: f64, averages: f64, tail: f64) -> (f64, f64) {
    (signal_power_limit(measured, noise, averages, 1.0 - tail), signal_power_limit(measured, noise, averages, tail))
}

/// The signal power (unit^2) whose law puts a power `measured` (unit^2),
/// averaged over `averages >= 1` estimates in noise of mean power `noise`
/// (unit^2) per estimate, at its `quantile` (0 where even no signal reads
/// that high); a high quantile gives the interval's lower end, a low one
/// its upper end. Without noise, `measured` itself. Found by bisection to
/// a relative 1e-4.
pub fn signal_power_limit(measured: f64, noise: f64, averages: f64, quantile: f64) -> f64 {
    if noise <= 0.0 || !measured.is_finite() {
        return measured.max(0.0);
    }
    let cdf = |signal: f64| averaged_power_cdf(signal, noise, averages, measured);
    // The distribution function at `measured` falls as the signal grows.
    if cdf(0.0) <= quantile {
        return 0.0;
    }
    let mut hi = measured.max(noise);
    while cdf(hi) > quantile && hi < 1e300 {
        hi *= 4.0;
    }
    let mut lo = 0.0;
    while hi - lo > 1e-4 * hi {
        let mid = 0.5 * (lo + hi);
        if cdf(mid) > quantile {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_signals::gaussian;

    /// Tabulated quantiles (Abramowitz and Stegun, table 26.8) read back
    /// through the distribution function, and closed forms: two degrees of
    /// freedom are the exponential law.
    #[test]
    fn central_law_matches_the_tables() {
        let cases = [(1.0, 0.95, 3.841_459), (10.0, 0.025, 3.246_973), (5.0, 0.99, 15.086_27), (30.0, 0.5, 29.336_03)];
        for (nu, p, q) in cases {
            let got = regularized_gamma_p(0.5 * nu, 0.5 * q);
            assert!((got - p).abs() < 1e-6, "nu {nu}: P({q}) = {got} against {p}");
            // Wilson-Hilferty's from thirty degrees of freedom.
            let bound = if nu < WILSON_HILFERTY_DOF { 1e-6 } else { 0.002 };
            assert!((noncentral_chi_square_cdf(nu, 0.0, q) - p).abs() < bound, "nu {nu} as noncentral");
        }
        // Wilson-Hilferty from thirty degrees of freedom: 30 and 100 at
        // their tabulated 2.5 % and 97.5 % points.
        for (nu, q, p) in [(30.0, 16.790_77, 0.025), (30.0, 46.979_24, 0.975), (100.0, 74.221_92, 0.025)] {
            assert!((chi_square_cdf(nu, q) - p).abs() < 0.002, "nu {nu}: {}", chi_square_cdf(nu, q));
        }
        assert!((standard_normal_cdf(-2.0) - 0.022_750_131_948_179_2).abs() < 1e-8);
        assert!((standard_normal_cdf(1.0) - 0.841_344_746_068_542_9).abs() < 1e-7);
        for x in [0.01, 0.5, 3.0, 12.0] {
            assert!((regularized_gamma_p(1.0, x) - (1.0 - (-x).exp())).abs() < 1e-12);
        }
        assert!((ln_gamma(0.5) - std::f64::consts::PI.sqrt().ln()).abs() < 1e-12);
        assert!((ln_gamma(10.0) - 362_880f64.ln()).abs() < 1e-10);
    }

    /// Simulated estimates (a line plus complex Gaussian noise, averaged
    /// over `K`): the law gives the share that reads below a level, and the
    /// interval from each reading holds the true signal power in
    /// `1 - 2 tail` of the draws (`1 - tail` without signal), from one estimate of pure noise to many
    /// estimates of a line well above it (the last five on Patnaik's law, the last two with Wilson and Hilferty's).
    #[test]
    fn the_law_and_its_interval_hold_simulated_estimates() {
        let (trials, tail) = (4_000, 0.022_75);
        for (averages, signal) in
            [(1usize, 0.0f64), (1, 0.3), (1, 3.0), (1, 30.0), (4, 1.0), (1, 300.0), (8, 40.0), (12, 0.0), (30, 2.0)]
        {
            let noise = 1.0;
            let g = gaussian(2 * averages * trials, 11 + averages as u64);
            let powers: Vec<f64> = (0..trials)
                .map(|t| {
                    (0..averages)
                        .map(|j| {
                            let i = 2 * (t * averages + j);
                            let (re, im) = (g[i] * (noise / 2.0f64).sqrt(), g[i + 1] * (noise / 2.0f64).sqrt());
                            (signal.sqrt() + re).powi(2) + im * im
                        })
                        .sum::<f64>()
                        / averages as f64
                })
                .collect();
            let mut sorted = powers.clone();
            sorted.sort_by(f64::total_cmp);
            for p in [0.05, 0.5, 0.95] {
                let x = sorted[(p * trials as f64) as usize];
                let law = averaged_power_cdf(signal, noise, averages as f64, x);
                // Binomial scatter of the share is at most 0.008.
                assert!((law - p).abs() < 0.025, "K {averages}, S/N {signal}: law {law} at the share {p}");
            }
            let missed = powers
                .iter()
                .filter(|&&x| {
                    let (lo, hi) = signal_power_interval(x, noise, averages as f64, tail);
                    signal < lo || signal > hi
                })
                .count() as f64
                / trials as f64;
            // No signal: a reading too low for pure noise still allows none,
            // so only the upper tail misses.
            let expected = if signal == 0.0 { tail } else { 2.0 * tail };
            assert!((missed - expected).abs() < 0.015, "K {averages}, S/N {signal}: missed {missed}");
        }
    }
}
