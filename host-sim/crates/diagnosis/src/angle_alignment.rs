//! The shaft angle put on the phase currents' time base.
//!
//! Under vector control the phase currents' space vector turns with the
//! rotor: with a constant direct-axis current (`i_d = 0` on a surface
//! machine) it keeps a fixed electrical angle to the rotor,
//! `p theta + delta + pi/2` (`delta` the encoder's electrical offset; a negative quadrature
//! current points it the other way, which doubling the angle folds away). A
//! recorded angle that lags the currents by `d` (the drive's speed estimate
//! integrated where the recording has no encoder column: the estimate's
//! filter and its computation delay it; or an encoder sampled later than the
//! currents) leaves `p (theta(t) - theta(t - d)) ~ p omega d` between the
//! current vector's angle and `p` times the recorded one: a straight line in
//! the shaft speed whose slope is `p d`. Reading the angle `d` later puts it
//! where the currents, and so the measured torque, are.

use std::f64::consts::PI;

/// Samples whose current magnitude is below this fraction of the travel's
/// 90th percentile are not used: near zero current the vector's angle is
/// the transducers' noise.
pub const MIN_CURRENT_FRACTION: f64 = 0.3;

/// Samples slower than this fraction of the travel's top speed are not
/// used: at standstill the brake may hold the shaft against any current.
pub const MIN_SPEED_FRACTION: f64 = 0.05;

/// Smallest coherence `|mean(e^{2 i (phi - p theta)})|` of the current
/// vector's angle with the recorded rotor angle for a delay to be read: a
/// drive under vector control keeps its current vector at one angle to the
/// rotor, so the coherence is near 1.
pub const MIN_COHERENCE: f64 = 0.8;

/// Fewest usable samples.
pub const MIN_SAMPLES: usize = 200;

/// The delay of a recorded shaft angle behind the phase currents.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct AngleDelay {
    /// Delay of the angle behind the currents, s (negative: ahead).
    pub delay_s: f64,
    /// Coherence of the current vector's angle with the angle (1: fixed).
    pub coherence: f64,
    /// RMS of the current vector's angle about the fitted line, electrical rad.
    pub residual_rad: f64,
    /// Samples used.
    pub samples: usize,
}

/// The delay (s) of `angle_rad` behind the phase currents `currents_a`
/// (`i_a`, `i_b`, `i_c`, A) of a machine with `pole_pairs`, with
/// `speed_radps` the shaft speed (rad/s), all on one sample clock: the slope of the current vector's angle relative to `p theta` against the
/// speed, over `p`. The reason when the recording cannot support it.
pub fn angle_delay(
    currents_a: [&[f64]; 3],
    angle_rad: &[f64],
    speed_radps: &[f64],
    pole_pairs: u32,
) -> Result<AngleDelay, String> {
    let [i_a, i_b, i_c] = currents_a;
    let n = i_a.len().min(i_b.len()).min(i_c.len()).min(angle_rad.len()).min(speed_radps.len());
    let p = f64::from(pole_pairs);
    // The current vector (magnitude, angle) of every sample.
    let vectors: Vec<(f64, f64)> = (0..n)
        .map(|k| {
            let alpha = (2.0 * i_a[k] - i_b[k] - i_c[k]) / 3.0;
            let beta = (i_b[k] - i_c[k]) / 3f64.sqrt();
            (alpha.hypot(beta), beta.atan2(alpha))
        })
        .collect();
    let used = usable_samples(&vectors, speed_radps)?;
    // Twice the current vector's angle relative to `p theta`: a negative
    // quadrature current (half a turn) folds onto a positive one.
    let doubled: Vec<(f64, f64)> = used.iter().map(|&k| (2.0 * (vectors[k].1 - p * angle_rad[k])).sin_cos()).collect();
    let (s, c) = doubled.iter().fold((0.0, 0.0), |(s, c), (ds, dc)| (s + ds, c + dc));
    let coherence = s.hypot(c) / used.len() as f64;
    if coherence < MIN_COHERENCE {
        return Err(format!(
            "the current vector does not keep one angle to the recorded rotor angle (coherence {coherence:.2}; \
             expected at least {MIN_COHERENCE} under vector control)"
        ));
    }
    let mean = s.atan2(c);
    // Each sample's angle about the mean, electrical rad (within a quarter turn).
    let residual: Vec<f64> = doubled.iter().map(|(ds, dc)| wrap(ds.atan2(*dc) - mean) / 2.0).collect();
    let speeds: Vec<f64> = used.iter().map(|&k| speed_radps[k]).collect();
    let (slope, rms) = line_fit(&speeds, &residual);
    Ok(AngleDelay { delay_s: slope / p, coherence, residual_rad: rms, samples: used.len() })
}

/// The samples of a travel whose current vector (`vectors`: magnitude and
/// angle) and speed are large enough to read the vector's angle
/// ([`MIN_CURRENT_FRACTION`], [`MIN_SPEED_FRACTION`]).
fn usable_samples(vectors: &[(f64, f64)], speed_radps: &[f64]) -> Result<Vec<usize>, String> {
    let n = vectors.len();
    let mut magnitudes: Vec<f64> = vectors.iter().map(|v| v.0).collect();
    let top_speed = speed_radps[..n].iter().fold(0.0f64, |m, w| m.max(w.abs()));
    if n == 0 || top_speed <= 0.0 {
        return Err("the shaft does not turn".to_string());
    }
    magnitudes.sort_by(f64::total_cmp);
    let floor = MIN_CURRENT_FRACTION * magnitudes[(9 * n / 10).min(n - 1)];
    let used: Vec<usize> =
        (0..n).filter(|&k| vectors[k].0 > floor && speed_radps[k].abs() >= MIN_SPEED_FRACTION * top_speed).collect();
    if used.len() < MIN_SAMPLES {
        return Err(format!(
            "{} samples turn with current; expected at least {MIN_SAMPLES} to read the current vector's angle",
            used.len()
        ));
    }
    let (lo, hi) = used.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &k| {
        let w = speed_radps[k].abs();
        (lo.min(w), hi.max(w))
    });
    if hi - lo < 0.5 * top_speed {
        return Err(format!(
            "the speed spans {:.2}-{:.2} rad/s where the current is read; expected a span of at least half the top \
             speed ({:.2} rad/s) to tell a delay from the encoder's offset",
            lo, hi, top_speed
        ));
    }
    Ok(used)
}

/// `x` wrapped into (-pi, pi].
fn wrap(x: f64) -> f64 {
    let y = (x + PI).rem_euclid(2.0 * PI) - PI;
    if y == -PI {
        PI
    } else {
        y
    }
}

/// Least-squares slope of `y` on `x` with an intercept, and the RMS residual.
fn line_fit(x: &[f64], y: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxx: f64 = x.iter().map(|v| (v - mx).powi(2)).sum();
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    let rss: f64 = x.iter().zip(y).map(|(a, b)| (b - my - slope * (a - mx)).powi(2)).sum();
    (slope, (rss / n).sqrt())
}

/// `angle_rad` (sampled at `sample_rate_hz`) read `delay_s` later: linear
/// interpolation between samples, the first and last steps extended beyond
/// the ends.
pub fn advanced(angle_rad: &[f64], delay_s: f64, sample_rate_hz: f64) -> Vec<f64> {
    let n = angle_rad.len();
    if n < 2 {
        return angle_rad.to_vec();
    }
    let shift = delay_s * sample_rate_hz;
    (0..n)
        .map(|k| {
            let x = k as f64 + shift;
            let i = (x.floor().max(0.0) as usize).min(n - 2);
            let f = x - i as f64;
            angle_rad[i] + f * (angle_rad[i + 1] - angle_rad[i])
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use plant::pmsm::phase_currents_a;

    /// A travel: speed ramps up over 2 s, holds 3 s, ramps down 2 s, at
    /// `fs`; the true angle, its speed, and currents on the q axis of the
    /// true angle (negative at the deceleration) with `offset_rad`.
    fn travel(fs: f64, offset_rad: f64) -> (Vec<f64>, Vec<f64>, [Vec<f64>; 3]) {
        let n = (7.0 * fs) as usize;
        let speed_at = |t: f64| 6.15 * (t / 2.0).min(1.0).min((7.0 - t) / 2.0).max(0.0);
        let (mut theta, mut speed, mut abc) = (Vec::new(), Vec::new(), [Vec::new(), Vec::new(), Vec::new()]);
        let mut th = 0.3;
        for k in 0..n {
            let t = k as f64 / fs;
            let w = speed_at(t);
            let iq = if t < 5.0 { 12.0 + 0.5 * (TAU_12 * t).sin() } else { -6.0 };
            let i = phase_currents_a(0.0, iq, 6.0 * th + offset_rad);
            (0..3).for_each(|j| abc[j].push(i[j]));
            theta.push(th);
            speed.push(w);
            th += w / fs;
        }
        (theta, speed, abc)
    }
    const TAU_12: f64 = 2.0 * PI * 12.0;

    fn delayed(x: &[f64], samples: usize) -> Vec<f64> {
        (0..x.len()).map(|k| x[k.saturating_sub(samples)]).collect()
    }

    #[test]
    fn a_late_angle_is_found_late_by_its_delay_whatever_the_encoder_offset() {
        let fs = 4096.0;
        for offset in [0.0, 2.0, -2.9] {
            let (theta, speed, abc) = travel(fs, offset);
            let [a, b, c] = [&abc[0][..], &abc[1][..], &abc[2][..]];
            let on_time = angle_delay([a, b, c], &theta, &speed, 6).unwrap();
            assert!(on_time.delay_s.abs() < 2e-6, "{on_time:?}");
            assert!(on_time.coherence > 0.999, "{on_time:?}");
            // 5 samples late: 1.221 ms.
            let late = angle_delay([a, b, c], &delayed(&theta, 5), &speed, 6).unwrap();
            assert!((late.delay_s - 5.0 / fs).abs() < 0.02 * 5.0 / fs, "{late:?}");
        }
    }

    #[test]
    fn the_advanced_angle_is_the_angle_on_time() {
        let fs = 4096.0;
        let (theta, _, _) = travel(fs, 0.0);
        let back = advanced(&delayed(&theta, 5), 5.0 / fs, fs);
        let worst = (5..theta.len() - 5).map(|k| (back[k] - theta[k]).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-12, "{worst}");
        // A fractional delay: a straight line is read exactly.
        let line: Vec<f64> = (0..100).map(|k| 0.01 * k as f64).collect();
        let half = advanced(&line, 0.5 / fs, fs);
        assert!((0..100).all(|k| (half[k] - 0.01 * (k as f64 + 0.5)).abs() < 1e-12));
    }

    #[test]
    fn currents_that_do_not_follow_the_angle_are_refused_with_the_reason() {
        let fs = 4096.0;
        let (theta, speed, abc) = travel(fs, 0.0);
        // Currents of another rotor turning at twice the speed.
        let doubled: Vec<f64> = theta.iter().map(|t| 2.0 * t).collect();
        let [a, b, c] = [&abc[0][..], &abc[1][..], &abc[2][..]];
        let err = angle_delay([a, b, c], &doubled, &speed, 6).unwrap_err();
        assert!(err.contains("coherence"), "{err}");
        let still = vec![0.0; theta.len()];
        assert!(angle_delay([a, b, c], &theta, &still, 6).unwrap_err().contains("does not turn"));
    }
}
