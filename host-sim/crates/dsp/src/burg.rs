//! Autoregressive (AR) spectral estimation by Burg's method, and the Burg
//! spectrogram of the seed paper (section 3.6, Fig. 6: spectrogram of the
//! car acceleration "calculated by the Burg algorithm", 0-128 Hz, in dB re
//! 1 (m/s^2)^2/Hz).
//!
//! * [`burg`] fits an AR model `x[n] + a_1 x[n-1] + ... + a_p x[n-p] = e[n]`
//!   (white `e` of variance `sigma^2`) to a signal;
//! * [`ArModel::psd`] evaluates the model's one-sided PSD with the same
//!   scaling as [`welch_psd`](super::welch::welch_psd);
//! * [`select_order`] picks the order by AIC, FPE or MDL;
//! * [`decimate`] low-passes (linear-phase Kaiser FIR) and downsamples;
//! * [`burg_spectrogram`] combines them into a spectrogram, one AR model per
//!   segment of the decimated signal, segments in parallel.

use rayon::prelude::*;

use super::{check_sample_rate, check_signal, AnalysisError, Spectrogram};

/// PSD values below this (in unit^2/Hz) are clamped before taking the
/// logarithm, as in [`stft_spectrogram`](super::stft_spectrogram).
const PSD_FLOOR: f64 = 1e-300;
/// Stop-band attenuation of the anti-alias filter of [`decimate`], dB.
const ANTI_ALIAS_ATTENUATION_DB: f64 = 80.0;
/// [`burg_spectrogram`] decimates to the highest rate that is at least this
/// many times `max_frequency_hz`; dimensionless.
const OVERSAMPLING: f64 = 4.0;
/// Largest number of frequencies [`burg_spectrogram`] evaluates.
const MAX_FREQUENCIES: f64 = 1e6;

/// Autoregressive model `x[n] + sum_{k=1..p} a_k x[n-k] = e[n]`, with `e`
/// white noise of variance `noise_variance`.
///
/// `coefficients[k - 1]` is `a_k` (dimensionless); its length is the model
/// order `p`. `noise_variance` is in unit^2, unit being that of the modelled
/// signal. A model from [`burg`] is stable (all poles inside the unit
/// circle).
#[derive(Debug, Clone, PartialEq)]
pub struct ArModel {
    /// `a_1 ..= a_p`, dimensionless.
    pub coefficients: Vec<f64>,
    /// Variance of the driving white noise (the prediction error), unit^2.
    pub noise_variance: f64,
}

/// Criterion for [`select_order`]. With `N` samples and `E_m` the Burg
/// prediction-error variance at order `m`:
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OrderCriterion {
    /// Akaike information criterion `N ln(E_m) + 2 m`. Tends to
    /// overestimate the order by one or two for long records.
    Aic,
    /// Akaike's final prediction error `E_m (N + m + 1) / (N - m - 1)`;
    /// asymptotically the same choice as AIC.
    Fpe,
    /// Rissanen's minimum description length `N ln(E_m) + m ln(N)`;
    /// consistent (picks the true order of an AR process as `N` grows).
    Mdl,
}

/// Burg recursion up to `order` on a checked signal. Calls
/// `on_order(m, E_m)` for `m = 0 ..= order` with the prediction-error
/// variance (unit^2) at order `m`, and returns the model of order `order`.
/// With `taper`, the products in each reflection coefficient are weighted
/// by the parabolic window of Kaveh and Lippert.
fn burg_recursion(x: &[f64], order: usize, taper: bool, mut on_order: impl FnMut(usize, f64)) -> ArModel {
    let n = x.len();
    let mut f = x.to_vec();
    let mut b = x.to_vec();
    // a[0] = 1 implicitly; a[1..=m] are the coefficients at order m.
    let mut a = vec![0.0; order + 1];
    let mut scratch = vec![0.0; order + 1];
    let mut e = x.iter().map(|v| v * v).sum::<f64>() / n as f64;
    on_order(0, e);
    for m in 1..=order {
        // Reflection coefficient minimising the sum of the forward and
        // backward prediction-error powers (Burg): f[n] holds f_{m-1}[n],
        // b[n-1] holds b_{m-1}[n-1], for n = m .. N-1.
        let (mut num, mut den) = (0.0, 0.0);
        if taper {
            // w_j = (j + 1) (L - j) for the L = N - m products, j = i - m
            // (the scale of w cancels in k).
            let len = (n - m) as f64;
            for i in m..n {
                let j = (i - m) as f64;
                let w = (j + 1.0) * (len - j);
                num += w * f[i] * b[i - 1];
                den += w * (f[i] * f[i] + b[i - 1] * b[i - 1]);
            }
        } else {
            for i in m..n {
                num += f[i] * b[i - 1];
                den += f[i] * f[i] + b[i - 1] * b[i - 1];
            }
        }
        let k = if den > 0.0 { (-2.0 * num / den).clamp(-1.0, 1.0) } else { 0.0 };
        // Errors of order m; descending so that b[i - 1] is still of order m-1.
        for i in (m..n).rev() {
            let (fo, bo) = (f[i], b[i - 1]);
            f[i] = fo + k * bo;
            b[i] = bo + k * fo;
        }
        // Levinson update of the coefficients.
        scratch[..m].copy_from_slice(&a[..m]);
        for i in 1..m {
            a[i] = scratch[i] + k * scratch[m - i];
        }
        a[m] = k;
        e *= 1.0 - k * k;
        on_order(m, e);
    }
    ArModel { coefficients: a[1..].to_vec(), noise_variance: e.max(0.0) }
}

/// AR model of `signal` of order `order` by Burg's method.
///
/// * `signal`: uniformly sampled, any unit, finite, more than `order`
///   samples. It is used as is: remove its mean first if it has one (a
///   constant would otherwise be modelled as a pole at 0 Hz).
/// * `order`: model order `p` (0 gives the white-noise model).
///
/// Each stage chooses the reflection coefficient `k_m` that minimises the sum
/// of the forward and backward prediction-error energies of order `m` over
/// the samples where both are defined; `|k_m| <= 1`, so the model is stable.
/// The coefficients follow by the Levinson recursion and the noise variance
/// is `E_p = mean(x^2) prod(1 - k_m^2)` (unit^2).
///
/// # Errors
/// [`AnalysisError::EmptySignal`], [`AnalysisError::TooShort`] (not more than
/// `order` samples) or [`AnalysisError::NonFinite`] for a bad signal,
/// [`AnalysisError::NumericOverflow`] for signal values near the f64 limit.
pub fn burg(signal: &[f64], order: usize) -> Result<ArModel, AnalysisError> {
    checked_burg(signal, order, false)
}

/// AR model of `signal` of order `order` by the tapered Burg method of
/// Kaveh and Lippert (1983), the method [`burg_spectrogram`] uses.
///
/// * `signal`, `order`: as for [`burg`].
///
/// The same recursion as [`burg`], except that the sums in each reflection
/// coefficient weight the `L = N - m` error products of stage `m` by the
/// parabolic window `w_j = (j + 1)(L - j)`, `j = 0 .. L-1`; `|k_m| <= 1`
/// still holds, so the model is stable. Plain Burg places the peak of a
/// sinusoid in a short record off its frequency by an amount that depends on
/// the sinusoid's phase (up to about 0.15 / T Hz for a record of T s, e.g.
/// 1.2 % at 12.3 Hz in a 1 s record); the taper reduces that error about
/// tenfold (0.04 % there at 10 dB SNR). For long records of an AR process
/// both give the same coefficients (the taper costs a little efficiency).
///
/// # Errors
/// As for [`burg`].
pub fn burg_tapered(signal: &[f64], order: usize) -> Result<ArModel, AnalysisError> {
    checked_burg(signal, order, true)
}

/// [`burg`] or [`burg_tapered`] with the input and output checks.
fn checked_burg(signal: &[f64], order: usize, taper: bool) -> Result<ArModel, AnalysisError> {
    check_signal(signal, order.saturating_add(1), "a Burg AR model (more samples than the order)")?;
    let model = burg_recursion(signal, order, taper, |_, _| {});
    if !model.noise_variance.is_finite() || model.coefficients.iter().any(|a| !a.is_finite()) {
        return Err(AnalysisError::NumericOverflow { what: "Burg AR model" });
    }
    Ok(model)
}

/// Order `m` in `0 ..= max_order` that minimises `criterion` for the Burg
/// models of `signal` (the smallest such order on a tie).
///
/// * `signal`: as for [`burg`], more than `max_order + 1` samples.
/// * `max_order`: largest order considered.
/// * `criterion`: see [`OrderCriterion`]; `N` is `signal.len()`.
///
/// One (plain) Burg recursion up to `max_order` gives all the
/// prediction-error variances `E_m`.
///
/// # Errors
/// As for [`burg`], with at least `max_order + 2` samples required (FPE
/// divides by `N - m - 1`).
pub fn select_order(signal: &[f64], max_order: usize, criterion: OrderCriterion) -> Result<usize, AnalysisError> {
    check_signal(signal, max_order.saturating_add(2), "Burg order selection (more samples than max_order + 1)")?;
    let n = signal.len() as f64;
    let mut errors = Vec::with_capacity(max_order + 1);
    burg_recursion(signal, max_order, false, |_, e| errors.push(e));
    if errors.iter().any(|e| !e.is_finite()) {
        return Err(AnalysisError::NumericOverflow { what: "Burg prediction-error variance" });
    }
    let score = |m: usize, e: f64| {
        let mf = m as f64;
        match criterion {
            OrderCriterion::Aic => n * e.ln() + 2.0 * mf,
            OrderCriterion::Fpe => e * (n + mf + 1.0) / (n - mf - 1.0),
            OrderCriterion::Mdl => n * e.ln() + mf * n.ln(),
        }
    };
    let mut best = (0, score(0, errors[0]));
    for (m, &e) in errors.iter().enumerate().skip(1) {
        let s = score(m, e);
        if s < best.1 {
            best = (m, s);
        }
    }
    Ok(best.0)
}

impl ArModel {
    /// One-sided PSD of the model at `frequencies_hz` (Hz), in unit^2/Hz.
    ///
    /// * `frequencies_hz`: any finite frequencies (the PSD is even and
    ///   periodic in `sample_rate_hz`).
    /// * `sample_rate_hz`: sample rate of the modelled signal, Hz, finite and
    ///   > 0.
    ///
    /// `P(f) = 2 sigma^2 / (fs |1 + sum_k a_k exp(-j 2 pi f k / fs)|^2)`: twice
    /// the two-sided density, the same one-sided scaling as
    /// [`welch_psd`](super::welch::welch_psd) (whose integral over
    /// `0..fs/2` is the variance). Unlike the DFT bins of Welch's method,
    /// which are halved at 0 Hz and the Nyquist frequency because those bins
    /// straddle the band edges, this is the continuous density and is doubled
    /// there too.
    ///
    /// # Errors
    /// [`AnalysisError::InvalidParameter`] for a bad sample rate, a
    /// non-finite frequency (`frequencies_hz`, value = the frequency),
    /// non-finite coefficients (`coefficients`) or a negative or non-finite
    /// noise variance (`noise_variance`); [`AnalysisError::NumericOverflow`]
    /// if the PSD is infinite (a pole on the unit circle).
    pub fn psd(&self, frequencies_hz: &[f64], sample_rate_hz: f64) -> Result<Vec<f64>, AnalysisError> {
        check_sample_rate(sample_rate_hz)?;
        if let Some(&value) = self.coefficients.iter().find(|a| !a.is_finite()) {
            return Err(AnalysisError::InvalidParameter {
                name: "coefficients",
                value,
                expected: "finite AR coefficients",
            });
        }
        if !(self.noise_variance.is_finite() && self.noise_variance >= 0.0) {
            return Err(AnalysisError::InvalidParameter {
                name: "noise_variance",
                value: self.noise_variance,
                expected: "a finite noise variance >= 0",
            });
        }
        if let Some(&value) = frequencies_hz.iter().find(|f| !f.is_finite()) {
            return Err(AnalysisError::InvalidParameter {
                name: "frequencies_hz",
                value,
                expected: "finite frequencies in Hz",
            });
        }
        let numerator = 2.0 * self.noise_variance / sample_rate_hz;
        let psd: Vec<f64> = frequencies_hz
            .iter()
            .map(|&f| {
                // Horner in z^-1 = exp(-j w): A = 1 + z^-1 (a_1 + z^-1 (a_2 + ...)).
                let (s, c) = (2.0 * std::f64::consts::PI * f / sample_rate_hz).sin_cos();
                let (zr, zi) = (c, -s);
                let (mut re, mut im) = (0.0, 0.0);
                for &a in self.coefficients.iter().rev() {
                    let (r, i) = (re * zr - im * zi, re * zi + im * zr);
                    re = r + a;
                    im = i;
                }
                let (r, i) = (re * zr - im * zi, re * zi + im * zr);
                let (re, im) = (1.0 + r, i);
                numerator / (re * re + im * im)
            })
            .collect();
        if psd.iter().any(|p| !p.is_finite()) {
            return Err(AnalysisError::NumericOverflow { what: "AR power spectral density" });
        }
        Ok(psd)
    }
}

/// Modified Bessel function of the first kind, order 0 (power series).
fn bessel_i0(x: f64) -> f64 {
    let q = 0.25 * x * x;
    let (mut term, mut sum, mut k) = (1.0, 1.0, 1.0);
    while term > 1e-17 * sum {
        term *= q / (k * k);
        sum += term;
        k += 1.0;
    }
    sum
}

/// Anti-alias filter of [`decimate`] for `factor` (>= 2): linear-phase
/// low-pass FIR by the Kaiser window method, odd length, unit gain at 0 Hz.
/// Cutoff (-6 dB) at `0.5 / factor` cycles/sample (the output Nyquist
/// frequency), transition band `0.25 / factor ..= 0.75 / factor`,
/// [`ANTI_ALIAS_ATTENUATION_DB`] in the stop band.
fn anti_alias_fir(factor: usize) -> Vec<f64> {
    let a = ANTI_ALIAS_ATTENUATION_DB;
    let beta = 0.1102 * (a - 8.7);
    let cutoff = 0.5 / factor as f64;
    let transition_rad = 2.0 * std::f64::consts::PI * (0.5 / factor as f64);
    let order = ((a - 8.0) / (2.285 * transition_rad)).ceil() as usize;
    let half = order.div_ceil(2);
    let i0_beta = bessel_i0(beta);
    let mut h: Vec<f64> = (0..=2 * half)
        .map(|i| {
            let t = i as f64 - half as f64;
            let r = t / half as f64;
            let window = bessel_i0(beta * (1.0 - r * r).max(0.0).sqrt()) / i0_beta;
            let arg = std::f64::consts::PI * 2.0 * cutoff * t;
            let sinc = if t == 0.0 { 1.0 } else { arg.sin() / arg };
            2.0 * cutoff * sinc * window
        })
        .collect();
    let sum: f64 = h.iter().sum();
    h.iter_mut().for_each(|v| *v /= sum);
    h
}

/// Index `i` reflected into `0..n` about the end samples
/// (`x[-i] = x[i]`, `x[n - 1 + i] = x[n - 1 - i]`), repeatedly if needed.
fn reflect(i: isize, n: usize) -> usize {
    if n == 1 {
        return 0;
    }
    let period = 2 * (n as isize - 1);
    let j = i.rem_euclid(period);
    if j >= n as isize {
        (period - j) as usize
    } else {
        j as usize
    }
}

/// Low-pass filters `signal` and keeps every `factor`-th sample.
///
/// * `signal`: uniformly sampled, any unit (the output has the same unit),
///   at least one sample, finite.
/// * `factor`: decimation factor, at least 1 (1 returns a copy).
///
/// Output sample `m` is at the time of input sample `m * factor` (no delay):
/// the anti-alias filter is a symmetric (linear-phase) FIR applied centred,
/// i.e. with zero phase. The output has `(len - 1) / factor + 1` samples.
/// The filter is a Kaiser-window (beta = 7.86) windowed sinc of about
/// `10 * factor + 1` taps with unit gain at 0 Hz and its -6 dB point at the
/// output Nyquist frequency `fs / (2 factor)`: flat within 0.002 dB up to
/// `fs / (4 factor)` and at least 78 dB down from `3 fs / (4 factor)`, so
/// nothing aliases into `0 ..= fs / (4 factor)` (the band to keep) by more
/// than -78 dB; `fs / (4 factor) .. fs / (2 factor)` holds the transition
/// band and some aliased content. Beyond the ends the signal is mirrored
/// about its first and last samples. Only every `factor`-th output is
/// computed (about `10 factor` multiplications per output sample). The PSD
/// in unit^2/Hz is unchanged in the band kept.
///
/// # Errors
/// [`AnalysisError::EmptySignal`] or [`AnalysisError::NonFinite`] for a bad
/// signal, [`AnalysisError::InvalidParameter`] for `factor == 0`,
/// [`AnalysisError::NumericOverflow`] for signal values near the f64 limit.
pub fn decimate(signal: &[f64], factor: usize) -> Result<Vec<f64>, AnalysisError> {
    if factor == 0 {
        return Err(AnalysisError::InvalidParameter {
            name: "factor",
            value: 0.0,
            expected: "a decimation factor of at least 1",
        });
    }
    check_signal(signal, 1, "decimation")?;
    if factor == 1 {
        return Ok(signal.to_vec());
    }
    let h = anti_alias_fir(factor);
    let half = h.len() / 2;
    let n = signal.len();
    let out: Vec<f64> = (0..(n - 1) / factor + 1)
        .map(|m| {
            let centre = m * factor;
            if centre >= half && centre + half < n {
                signal[centre - half..=centre + half].iter().zip(&h).map(|(x, c)| x * c).sum()
            } else {
                h.iter()
                    .enumerate()
                    .map(|(j, c)| c * signal[reflect(centre as isize + j as isize - half as isize, n)])
                    .sum()
            }
        })
        .collect();
    if out.iter().any(|v| !v.is_finite()) {
        return Err(AnalysisError::NumericOverflow { what: "decimated signal" });
    }
    Ok(out)
}

/// Spectrogram of `signal` by Burg AR models of short segments, like the
/// seed paper's Fig. 6.
///
/// * `signal`: uniformly sampled, any unit (the PSD is in unit^2/Hz; for an
///   acceleration in m/s^2, dB re 1 (m/s^2)^2/Hz), finite.
/// * `sample_rate_hz`: sample rate in Hz, finite and > 0.
/// * `window_s`: segment length in s; `round(window_s * fs_d)` samples of
///   the decimated signal (rate `fs_d`, below), at least `2 * order` and at
///   most the decimated signal's length.
/// * `overlap`: fraction of a segment shared with the next one, in `[0, 1)`;
///   the hop is `round(window * (1 - overlap))` decimated samples, at least 1.
/// * `order`: AR model order per segment, at least 1.
/// * `max_frequency_hz`: highest frequency evaluated, Hz,
///   `0 < max_frequency_hz <= sample_rate_hz / 2`.
/// * `frequency_step_hz`: spacing of the evaluated frequencies, Hz, finite
///   and > 0 (at most 10^6 frequencies). The AR PSD is a continuous function,
///   so the step only sets the sampling of the plot, not the resolution.
///
/// Steps:
/// 1. Decimation by `D = max(1, floor(fs / (4 max_frequency_hz)))` with
///    [`decimate`] (zero-phase Kaiser FIR, flat to `fs_d / 4 >=
///    max_frequency_hz`, alias-free band), to `fs_d = fs / D`. For the
///    paper's 16384 Hz and 0-128 Hz: `D = 32`, `fs_d = 512 Hz`, a 323-tap
///    filter. The AR model then spends its poles on `0 .. fs_d / 2` rather
///    than on the whole 0-8192 Hz band, and the segments are 32 times
///    shorter.
/// 2. Segments of the decimated signal, starting at sample 0 and advancing
///    by the hop; samples after the last full segment are not used. Each
///    segment has its own mean removed and gets a Burg model of order
///    `order` by [`burg_tapered`] (no data window: Burg works on the raw
///    segment; the Kaveh-Lippert taper weights the error products instead,
///    which keeps a line's peak at its frequency whatever its phase in the
///    segment).
/// 3. Each model's one-sided PSD ([`ArModel::psd`] at `fs_d`) at
///    `0, step, 2 step, ... <= max_frequency_hz`, in dB
///    (`10 log10(PSD)`, PSD clamped at 1e-300 unit^2/Hz). The segments are
///    processed in parallel (rayon).
///
/// `times_s` holds each segment's centre time, measured like the input's
/// sample times (input sample `k` is at `k / sample_rate_hz`).
///
/// Settings for the paper's figure (16384 Hz, 0-128 Hz): `window_s = 1.0`
/// (512 decimated samples), `overlap = 0.75` (0.25 s hop), `order = 40`,
/// `max_frequency_hz = 128.0`, `frequency_step_hz = 0.25`. A 20 s record
/// then takes a few milliseconds (decimation included). A higher order
/// separates close lines better but splits and shifts lines in short
/// segments; keep `order` well below the window length (here a tenth).
///
/// # Errors
/// [`AnalysisError::EmptySignal`] or [`AnalysisError::NonFinite`] for a bad
/// signal, [`AnalysisError::TooShort`] when the signal is shorter than one
/// window (the minimum is in input samples),
/// [`AnalysisError::InvalidParameter`] for a bad sample rate, window,
/// overlap, order, maximum frequency or frequency step,
/// [`AnalysisError::NumericOverflow`] for signal values near the f64 limit.
pub fn burg_spectrogram(
    signal: &[f64],
    sample_rate_hz: f64,
    window_s: f64,
    overlap: f64,
    order: usize,
    max_frequency_hz: f64,
    frequency_step_hz: f64,
) -> Result<Spectrogram, AnalysisError> {
    check_sample_rate(sample_rate_hz)?;
    crate::check_window(window_s, overlap)?;
    if order == 0 {
        return Err(AnalysisError::InvalidParameter {
            name: "order",
            value: 0.0,
            expected: "an AR order of at least 1",
        });
    }
    if !(max_frequency_hz.is_finite() && max_frequency_hz > 0.0 && max_frequency_hz <= 0.5 * sample_rate_hz) {
        return Err(AnalysisError::InvalidParameter {
            name: "max_frequency_hz",
            value: max_frequency_hz,
            expected: "a frequency with 0 < max_frequency_hz <= sample_rate_hz / 2",
        });
    }
    if !(frequency_step_hz.is_finite()
        && frequency_step_hz > 0.0
        && max_frequency_hz / frequency_step_hz < MAX_FREQUENCIES)
    {
        return Err(AnalysisError::InvalidParameter {
            name: "frequency_step_hz",
            value: frequency_step_hz,
            expected: "a finite step > 0 Hz giving at most 1e6 frequencies up to max_frequency_hz",
        });
    }
    check_signal(signal, 1, "a Burg spectrogram")?;

    let factor = ((sample_rate_hz / (OVERSAMPLING * max_frequency_hz)).floor() as usize).max(1);
    let fs_d = sample_rate_hz / factor as f64;
    let window_samples = (window_s * fs_d).round();
    if window_samples < 2.0 * order as f64 {
        return Err(AnalysisError::InvalidParameter {
            name: "window_s",
            value: window_s,
            expected: "a window of at least 2 * order samples after decimation (window_s * fs_d >= 2 order)",
        });
    }
    let nd = (signal.len() - 1) / factor + 1;
    if window_samples > nd as f64 {
        let min = (window_samples - 1.0) * factor as f64 + 1.0;
        return Err(AnalysisError::TooShort {
            len: signal.len(),
            min: min.min(usize::MAX as f64) as usize,
            what: "one Burg spectrogram window (window_s * sample_rate_hz samples)",
        });
    }
    let x = decimate(signal, factor)?;
    let nwin = window_samples as usize;
    let hop = ((nwin as f64) * (1.0 - overlap)).round().max(1.0) as usize;
    let segments = 1 + (x.len() - nwin) / hop;
    let bins = (max_frequency_hz / frequency_step_hz * (1.0 + 1e-12)).floor() as usize + 1;
    let frequency_hz: Vec<f64> = (0..bins).map(|k| k as f64 * frequency_step_hz).collect();

    let psd_db = (0..segments)
        .into_par_iter()
        .map(|seg| {
            let chunk = &x[seg * hop..seg * hop + nwin];
            let mean = chunk.iter().sum::<f64>() / nwin as f64;
            let centred: Vec<f64> = chunk.iter().map(|v| v - mean).collect();
            let model = burg_tapered(&centred, order)?;
            let row: Vec<f64> =
                model.psd(&frequency_hz, fs_d)?.into_iter().map(|p| 10.0 * p.max(PSD_FLOOR).log10()).collect();
            Ok(row)
        })
        .collect::<Result<Vec<_>, AnalysisError>>()?;
    let times_s = (0..segments).map(|seg| (seg * hop) as f64 / fs_d + 0.5 * (nwin - 1) as f64 / fs_d).collect();
    Ok(Spectrogram { times_s, frequency_hz, psd_db })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_signals::gaussian;
    use crate::welch::welch_psd;
    use std::f64::consts::PI;

    /// Polynomial coefficients a_1..a_p of prod (1 - 2 r cos(th) z^-1 + r^2 z^-2)
    /// for the pole pairs `(r, th)`.
    fn from_pole_pairs(pairs: &[(f64, f64)]) -> Vec<f64> {
        let mut poly = vec![1.0];
        for &(r, th) in pairs {
            let sec = [1.0, -2.0 * r * th.cos(), r * r];
            let mut next = vec![0.0; poly.len() + 2];
            for (i, p) in poly.iter().enumerate() {
                for (j, s) in sec.iter().enumerate() {
                    next[i + j] += p * s;
                }
            }
            poly = next;
        }
        poly[1..].to_vec()
    }

    /// AR process `x[n] = e[n] - sum a_k x[n-k]`, `e` white Gaussian of
    /// variance `var`, after a 2000-sample burn-in.
    fn ar_process(a: &[f64], var: f64, n: usize, seed: u64) -> Vec<f64> {
        let burn = 2000;
        let e = gaussian(n + burn, seed);
        let mut x = vec![0.0; n + burn];
        for i in 0..n + burn {
            let mut v = var.sqrt() * e[i];
            for (k, ak) in a.iter().enumerate() {
                if i > k {
                    v -= ak * x[i - k - 1];
                }
            }
            x[i] = v;
        }
        x.split_off(burn)
    }

    /// True one-sided PSD of the AR process, written with complex
    /// exponentials independently of `ArModel::psd`.
    fn true_psd(a: &[f64], var: f64, f: f64, fs: f64) -> f64 {
        let w = 2.0 * PI * f / fs;
        let (mut re, mut im) = (1.0, 0.0);
        for (k, ak) in a.iter().enumerate() {
            let arg = w * (k + 1) as f64;
            re += ak * arg.cos();
            im -= ak * arg.sin();
        }
        2.0 * var / fs / (re * re + im * im)
    }

    #[test]
    fn burg_recovers_ar2_and_ar4_coefficients() {
        let ar2 = from_pole_pairs(&[(0.9, 2.0 * PI * 0.1)]);
        let ar4 = from_pole_pairs(&[(0.95, 2.0 * PI * 0.05), (0.85, 2.0 * PI * 0.2)]);
        for (a, var, seed) in [(ar2.clone(), 1.0, 1), (ar2, 0.25, 2), (ar4.clone(), 2.0, 3), (ar4, 1.0, 4)] {
            let x = ar_process(&a, var, 50_000, seed);
            let model = burg(&x, a.len()).unwrap();
            let worst = model.coefficients.iter().zip(&a).map(|(e, t)| (e - t).abs()).fold(0.0, f64::max);
            let var_err = model.noise_variance / var - 1.0;
            eprintln!("AR({}): worst coefficient error {worst:.5}, noise variance error {var_err:+.4}", a.len());
            assert!(worst < 0.02, "coefficients {:?} vs {a:?}", model.coefficients);
            assert!(var_err.abs() < 0.05, "noise variance {} vs {var}", model.noise_variance);
        }
    }

    #[test]
    fn burg_matches_levinson_on_a_textbook_case() {
        // Order 1 by hand: k = -2 sum x[n] x[n-1] / sum (x[n]^2 + x[n-1]^2),
        // E_1 = mean(x^2) (1 - k^2).
        let x = [1.0, -0.5, 0.25, 2.0, -1.0];
        let num: f64 = (1..5).map(|n| x[n] * x[n - 1]).sum();
        let den: f64 = (1..5).map(|n| x[n] * x[n] + x[n - 1] * x[n - 1]).sum();
        let k = -2.0 * num / den;
        let e0 = x.iter().map(|v| v * v).sum::<f64>() / 5.0;
        let m = burg(&x, 1).unwrap();
        assert!((m.coefficients[0] - k).abs() < 1e-15);
        assert!((m.noise_variance - e0 * (1.0 - k * k)).abs() < 1e-15);
        let m0 = burg(&x, 0).unwrap();
        assert!(m0.coefficients.is_empty() && (m0.noise_variance - e0).abs() < 1e-15);
    }

    #[test]
    fn ar_psd_agrees_with_welch_and_the_true_psd() {
        let fs = 1000.0;
        let a = from_pole_pairs(&[(0.9, 2.0 * PI * 0.1)]);
        let x = ar_process(&a, 1.0, 50_000, 5);
        let model = burg(&x, 2).unwrap();
        let welch = welch_psd(&x, fs, 1024, 0.5).unwrap();
        let ar = model.psd(&welch.frequency_hz, fs).unwrap();
        // Away from the 100 Hz peak (outside 80-120 Hz) and the band edges.
        let (mut worst_welch, mut worst_true): (f64, f64) = (0.0, 0.0);
        for (k, &f) in welch.frequency_hz.iter().enumerate() {
            if !(5.0..=495.0).contains(&f) || (80.0..=120.0).contains(&f) {
                continue;
            }
            let db = |p: f64| 10.0 * p.log10();
            worst_welch = worst_welch.max((db(ar[k]) - db(welch.density[k])).abs());
            worst_true = worst_true.max((db(ar[k]) - db(true_psd(&a, 1.0, f, fs))).abs());
        }
        eprintln!("AR(2) PSD: Burg vs Welch worst {worst_welch:.2} dB, vs true {worst_true:.3} dB");
        assert!(worst_welch < 2.0, "Burg vs Welch: {worst_welch} dB");
        assert!(worst_true < 0.2, "Burg vs true PSD: {worst_true} dB");
        // The integral of the one-sided AR PSD over 0..fs/2 is the variance.
        let df = 0.01;
        let grid: Vec<f64> = (0..50_000).map(|k| (k as f64 + 0.5) * df).collect();
        let integral: f64 = model.psd(&grid, fs).unwrap().iter().sum::<f64>() * df;
        let var = x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64;
        assert!((integral / var - 1.0).abs() < 0.02, "integral {integral} vs variance {var}");
    }

    /// Frequency (Hz) of the largest PSD value on a fine grid.
    fn peak_frequency(model: &ArModel, fs: f64, lo: f64, hi: f64, step: f64) -> f64 {
        let grid: Vec<f64> = (0..=((hi - lo) / step) as usize).map(|k| lo + k as f64 * step).collect();
        let p = model.psd(&grid, fs).unwrap();
        let k = p.iter().enumerate().max_by(|x, y| x.1.total_cmp(y.1)).unwrap().0;
        grid[k]
    }

    /// Worst relative peak-frequency error of `fit` over sinusoids of
    /// amplitude 1 at 12.3, 37.3, 72 and 101.7 Hz (512 Hz sampling, `n`
    /// samples) with six phases each, in white noise of rms `noise_rms`.
    fn worst_peak_error(
        fit: fn(&[f64], usize) -> Result<ArModel, AnalysisError>,
        n: usize,
        order: usize,
        noise_rms: f64,
    ) -> f64 {
        let fs = 512.0;
        let mut worst: f64 = 0.0;
        for (i, &f0) in [12.3, 37.3, 72.0, 101.7].iter().enumerate() {
            for j in 0..6 {
                let phase = j as f64 * PI / 6.0;
                let e = gaussian(n, (10 * i + j) as u64 + 1);
                let x: Vec<f64> =
                    (0..n).map(|k| (2.0 * PI * f0 * k as f64 / fs + phase).sin() + noise_rms * e[k]).collect();
                let model = fit(&x, order).unwrap();
                let f = peak_frequency(&model, fs, 1.0, 255.0, 0.005);
                worst = worst.max((f / f0 - 1.0).abs());
            }
        }
        worst
    }

    #[test]
    fn sinusoid_in_noise_peak_is_within_half_a_percent() {
        // Plain Burg on 8 s records (order 20), tapered Burg on 1 s records
        // (a spectrogram segment, order 40); SNR 11 dB (noise rms 0.2) and
        // 17 dB (0.1).
        for noise_rms in [0.2, 0.1] {
            let plain_long = worst_peak_error(burg, 4096, 20, noise_rms);
            let tapered_short = worst_peak_error(burg_tapered, 512, 40, noise_rms);
            let plain_short = worst_peak_error(burg, 512, 40, noise_rms);
            eprintln!(
                "noise {noise_rms}: worst peak error plain 8 s {plain_long:.5}, tapered 1 s {tapered_short:.5}, \
                 plain 1 s {plain_short:.5}"
            );
            assert!(plain_long < 0.005, "plain Burg, 8 s: {plain_long}");
            assert!(tapered_short < 0.005, "tapered Burg, 1 s: {tapered_short}");
            // What the taper is for: plain Burg's phase-dependent bias in
            // short records.
            assert!(tapered_short < plain_short / 3.0, "tapered {tapered_short} vs plain {plain_short}");
        }
    }

    #[test]
    fn tapered_burg_recovers_ar4_coefficients() {
        let ar4 = from_pole_pairs(&[(0.95, 2.0 * PI * 0.05), (0.85, 2.0 * PI * 0.2)]);
        let x = ar_process(&ar4, 1.0, 50_000, 8);
        let model = burg_tapered(&x, 4).unwrap();
        let worst = model.coefficients.iter().zip(&ar4).map(|(e, t)| (e - t).abs()).fold(0.0, f64::max);
        eprintln!("tapered AR(4): worst coefficient error {worst:.5}, noise variance {:.4}", model.noise_variance);
        assert!(worst < 0.02, "coefficients {:?} vs {ar4:?}", model.coefficients);
        assert!((model.noise_variance - 1.0).abs() < 0.05);
    }

    #[test]
    fn order_selection_finds_the_true_order() {
        let ar4 = from_pole_pairs(&[(0.95, 2.0 * PI * 0.05), (0.85, 2.0 * PI * 0.2)]);
        let ar2 = from_pole_pairs(&[(0.8, 2.0 * PI * 0.3)]);
        for (a, seed) in [(ar4, 21), (ar2, 22)] {
            let x = ar_process(&a, 1.0, 50_000, seed);
            let p = a.len();
            let mdl = select_order(&x, 20, OrderCriterion::Mdl).unwrap();
            let aic = select_order(&x, 20, OrderCriterion::Aic).unwrap();
            let fpe = select_order(&x, 20, OrderCriterion::Fpe).unwrap();
            eprintln!("AR({p}): MDL {mdl}, AIC {aic}, FPE {fpe}");
            assert_eq!(mdl, p);
            assert!(aic.abs_diff(p) <= 1, "AIC picked {aic}");
            assert!(fpe.abs_diff(p) <= 1, "FPE picked {fpe}");
        }
        // White noise: order 0 by MDL.
        assert_eq!(select_order(&gaussian(10_000, 5), 10, OrderCriterion::Mdl).unwrap(), 0);
    }

    /// |H(f)| of an FIR centred on its middle tap (zero phase: real).
    fn fir_gain(h: &[f64], f_rel: f64) -> f64 {
        let half = (h.len() / 2) as f64;
        h.iter().enumerate().map(|(i, c)| c * (2.0 * PI * f_rel * (i as f64 - half)).cos()).sum::<f64>().abs()
    }

    #[test]
    fn anti_alias_filter_is_flat_in_the_band_and_stops_aliases() {
        for factor in [2, 4, 32] {
            let h = anti_alias_fir(factor);
            assert_eq!(h.len() % 2, 1);
            for i in 0..h.len() {
                assert!((h[i] - h[h.len() - 1 - i]).abs() < 1e-18);
            }
            let out_rate = 1.0 / factor as f64; // cycles/sample of the input
            let mut pass: f64 = 0.0;
            for k in 0..=200 {
                let g = fir_gain(&h, 0.25 * out_rate * k as f64 / 200.0);
                pass = pass.max((20.0 * g.log10()).abs());
            }
            let mut stop: f64 = -1000.0;
            for k in 0..=2000 {
                let f = 0.75 * out_rate + (0.5 - 0.75 * out_rate) * k as f64 / 2000.0;
                stop = stop.max(20.0 * fir_gain(&h, f).log10());
            }
            let nyquist = 20.0 * fir_gain(&h, 0.5 * out_rate).log10();
            eprintln!(
                "factor {factor}: {} taps, pass ripple {pass:.5} dB, stop {stop:.1} dB, {nyquist:.2} dB at fs_d/2",
                h.len()
            );
            assert!(pass < 0.002, "passband deviation {pass} dB");
            assert!(stop < -78.0, "stop band {stop} dB");
            assert!((nyquist + 6.02).abs() < 0.1, "{nyquist} dB at the output Nyquist frequency");
        }
    }

    #[test]
    fn decimate_keeps_in_band_tones_in_phase_and_removes_aliases() {
        let fs = 16384.0;
        let n = 2 * 16384 + 77;
        let tone = |f: f64, k: usize| (2.0 * PI * f * k as f64 / fs + 0.4).sin();
        let x: Vec<f64> = (0..n).map(|k| tone(100.0, k) + tone(500.0, k) + 3.0).collect();
        let y = decimate(&x, 32).unwrap();
        assert_eq!(y.len(), (n - 1) / 32 + 1);
        // Away from the ends: the 100 Hz tone and the offset sample by
        // sample (zero phase), the 500 Hz tone (which would alias to 12 Hz)
        // gone.
        let mut err: f64 = 0.0;
        for (m, v) in y.iter().enumerate().take(y.len() - 20).skip(20) {
            err = err.max((v - (tone(100.0, 32 * m) + 3.0)).abs());
        }
        assert!(err < 2e-4, "max deviation {err}");
        // Near the ends the mirrored signal is still bounded and finite.
        assert!(y.iter().all(|v| v.is_finite() && v.abs() < 6.0));
        assert_eq!(decimate(&x, 1).unwrap(), x);
        let single = decimate(&[2.5], 8).unwrap();
        assert!(single.len() == 1 && (single[0] - 2.5).abs() < 1e-14);
        assert_eq!(reflect(-3, 5), 3);
        assert_eq!(reflect(6, 5), 2);
        assert_eq!(reflect(-9, 5), 1);
        assert_eq!(reflect(7, 1), 0);
    }

    #[test]
    fn spectrogram_level_of_white_noise_is_two_variance_over_fs() {
        // White noise of rms 0.1 at 16384 Hz: one-sided 2 sigma^2 / fs in
        // the kept band after decimation by 32.
        let fs = 16384.0;
        let sigma = 0.1;
        let x: Vec<f64> = gaussian((10.0 * fs) as usize, 9).iter().map(|v| sigma * v).collect();
        let s = burg_spectrogram(&x, fs, 1.0, 0.5, 10, 128.0, 0.5).unwrap();
        let expected_db = 10.0 * (2.0 * sigma * sigma / fs).log10();
        let mut all: Vec<f64> = s.psd_db.iter().flat_map(|row| row[10..250].iter().copied()).collect();
        all.sort_by(f64::total_cmp);
        let mean_lin = all.iter().map(|db| 10f64.powf(db / 10.0)).sum::<f64>() / all.len() as f64;
        let mean_db = 10.0 * mean_lin.log10();
        eprintln!("white noise: mean level {mean_db:.2} dB, expected {expected_db:.2} dB");
        assert!((mean_db - expected_db).abs() < 0.5, "{mean_db} dB vs {expected_db} dB");
        assert_eq!(s.frequency_hz.len(), 257);
        assert_eq!(*s.frequency_hz.last().unwrap(), 128.0);
        // Decimated rate 512 Hz, 512-sample windows, hop 256.
        assert_eq!(s.times_s.len(), 1 + ((x.len() - 1) / 32 + 1 - 512) / 256);
        assert!((s.times_s[0] - 511.0 / 2.0 / 512.0).abs() < 1e-12);
        assert!((s.times_s[1] - s.times_s[0] - 0.5).abs() < 1e-12);
    }

    #[test]
    fn spectrogram_tracks_stepped_tones_without_aliases() {
        // 12, 36 and 72 Hz in consecutive 4 s blocks plus a 500 Hz tone that
        // would alias to 12 Hz without the anti-alias filter, in noise.
        let fs = 16384.0;
        let blocks = [(0.0, 4.0, 36.0), (4.0, 8.0, 12.0), (8.0, 12.0, 72.0)];
        let noise = gaussian((12.0 * fs) as usize, 17);
        let mut phase = 0.0;
        let x: Vec<f64> = (0..noise.len())
            .map(|k| {
                let t = k as f64 / fs;
                let f = blocks.iter().find(|b| t >= b.0 && t < b.1).map_or(72.0, |b| b.2);
                phase += 2.0 * PI * f / fs;
                0.3 * phase.sin() + 2.0 * (2.0 * PI * 500.0 * t).sin() + 0.05 * noise[k]
            })
            .collect();
        let s = burg_spectrogram(&x, fs, 1.0, 0.75, 40, 128.0, 0.05).unwrap();
        let mut checked = 0;
        for (i, &t) in s.times_s.iter().enumerate() {
            let Some(block) = blocks.iter().find(|b| t - 0.5 >= b.0 && t + 0.5 <= b.1) else { continue };
            let row = &s.psd_db[i];
            let k = row.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).unwrap().0;
            let f = s.frequency_hz[k];
            assert!((f / block.2 - 1.0).abs() < 0.005, "t {t}: peak {f} Hz, expected {}", block.2);
            if block.2 != 12.0 {
                // No alias of the 500 Hz tone at 12 Hz: the level there is
                // far below the line.
                let k12 = (12.0 / 0.05) as usize;
                assert!(row[k] - row[k12] > 30.0, "t {t}: 12 Hz at {} dB vs peak {} dB", row[k12], row[k]);
            }
            checked += 1;
        }
        assert!(checked >= 30, "only {checked} segments checked");
    }

    #[test]
    fn bad_inputs_are_errors() {
        let x = vec![0.5; 2000];
        let name = |r: Result<Spectrogram, AnalysisError>| match r {
            Err(AnalysisError::InvalidParameter { name, .. }) => name,
            other => panic!("unexpected {other:?}"),
        };
        assert_eq!(name(burg_spectrogram(&x, -1.0, 1.0, 0.5, 4, 10.0, 1.0)), "sample_rate_hz");
        assert_eq!(name(burg_spectrogram(&x, 100.0, 0.0, 0.5, 4, 10.0, 1.0)), "window_s");
        assert_eq!(name(burg_spectrogram(&x, 100.0, 0.05, 0.5, 4, 10.0, 1.0)), "window_s");
        assert_eq!(name(burg_spectrogram(&x, 100.0, 1.0, 1.0, 4, 10.0, 1.0)), "overlap");
        assert_eq!(name(burg_spectrogram(&x, 100.0, 1.0, 0.5, 0, 10.0, 1.0)), "order");
        assert_eq!(name(burg_spectrogram(&x, 100.0, 1.0, 0.5, 4, 60.0, 1.0)), "max_frequency_hz");
        assert_eq!(name(burg_spectrogram(&x, 100.0, 1.0, 0.5, 4, 10.0, 0.0)), "frequency_step_hz");
        assert_eq!(name(burg_spectrogram(&x, 100.0, 1.0, 0.5, 4, 10.0, 1e-6)), "frequency_step_hz");
        assert!(matches!(
            burg_spectrogram(&x, 100.0, 30.0, 0.5, 4, 10.0, 1.0),
            Err(AnalysisError::TooShort { len: 2000, .. })
        ));
        let mut y = x.clone();
        y[5] = f64::NAN;
        assert!(matches!(
            burg_spectrogram(&y, 100.0, 1.0, 0.5, 4, 10.0, 1.0),
            Err(AnalysisError::NonFinite { index: 5, .. })
        ));
        // A constant: zero after mean removal, PSD at the floor.
        let s = burg_spectrogram(&x, 100.0, 1.0, 0.5, 4, 10.0, 1.0).unwrap();
        assert!(s.psd_db.iter().flatten().all(|v| *v == -3000.0));

        assert!(matches!(burg(&[1.0, 2.0], 2), Err(AnalysisError::TooShort { len: 2, min: 3, .. })));
        assert!(matches!(burg(&[1e300, -1e300, 1e300], 1), Err(AnalysisError::NumericOverflow { .. })));
        assert!(matches!(select_order(&[1.0, 2.0, 3.0], 2, OrderCriterion::Aic), Err(AnalysisError::TooShort { .. })));
        assert!(matches!(decimate(&[1.0], 0), Err(AnalysisError::InvalidParameter { name: "factor", .. })));
        let m = ArModel { coefficients: vec![0.5], noise_variance: 1.0 };
        assert!(matches!(m.psd(&[1.0], 0.0), Err(AnalysisError::InvalidParameter { name: "sample_rate_hz", .. })));
        assert!(matches!(
            m.psd(&[f64::NAN], 10.0),
            Err(AnalysisError::InvalidParameter { name: "frequencies_hz", .. })
        ));
        let bad = ArModel { coefficients: vec![f64::NAN], noise_variance: 1.0 };
        assert!(matches!(bad.psd(&[1.0], 10.0), Err(AnalysisError::InvalidParameter { name: "coefficients", .. })));
        let bad = ArModel { coefficients: vec![], noise_variance: -1.0 };
        assert!(matches!(bad.psd(&[1.0], 10.0), Err(AnalysisError::InvalidParameter { name: "noise_variance", .. })));
        // A pole on the unit circle at 0 Hz: infinite PSD there.
        let unit = ArModel { coefficients: vec![-1.0], noise_variance: 1.0 };
        assert!(matches!(unit.psd(&[0.0], 10.0), Err(AnalysisError::NumericOverflow { .. })));
    }

    #[test]
    #[ignore = "timing measurement: cargo test --release -p dsp -- --ignored --nocapture timing"]
    fn timing_of_a_20_s_record() {
        use crate::dq0::machine_torque_nm;
        use std::time::Instant;
        let fs = 16384.0;
        let n = (20.0 * fs) as usize;
        let noise = gaussian(n, 1);
        let acc: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 / fs;
                0.05 * noise[k] + 0.2 * (2.0 * PI * 12.0 * t).sin() + 0.05 * (2.0 * PI * 72.0 * t).sin()
            })
            .collect();
        let theta: Vec<f64> = (0..n).map(|k| 6.15 * k as f64 / fs).collect();
        let (mut ia, mut ib, mut ic) = (vec![], vec![], vec![]);
        for &th in &theta {
            let e = 6.0 * th;
            ia.push(5.0 * (e + 0.5 * PI).cos());
            ib.push(5.0 * (e + 0.5 * PI - 2.0 * PI / 3.0).cos());
            ic.push(5.0 * (e + 0.5 * PI + 2.0 * PI / 3.0).cos());
        }
        let best = |f: &mut dyn FnMut()| {
            (0..5)
                .map(|_| {
                    let t0 = Instant::now();
                    f();
                    t0.elapsed().as_secs_f64()
                })
                .fold(f64::INFINITY, f64::min)
        };
        let t_burg = best(&mut || {
            burg_spectrogram(&acc, fs, 1.0, 0.75, 40, 128.0, 0.25).unwrap();
        });
        let t_decimate = best(&mut || {
            decimate(&acc, 32).unwrap();
        });
        let t_welch = best(&mut || {
            welch_psd(&acc, fs, 4 * 16384, 0.5).unwrap();
        });
        let t_welch_1s = best(&mut || {
            welch_psd(&acc, fs, 16384, 0.5).unwrap();
        });
        let t_dq0 = best(&mut || {
            machine_torque_nm(&ia, &ib, &ic, &theta, 6, 0.45, 0.015, 0.015, 0.0).unwrap();
        });
        eprintln!(
            "20 s at 16384 Hz (best of 5): Burg spectrogram {:.1} ms (decimation alone {:.1} ms), \
             Welch 4 s segments {:.1} ms, Welch 1 s segments {:.1} ms, dq0 torque {:.1} ms",
            t_burg * 1e3,
            t_decimate * 1e3,
            t_welch * 1e3,
            t_welch_1s * 1e3,
            t_dq0 * 1e3
        );
    }
}
