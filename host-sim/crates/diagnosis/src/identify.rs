//! The paper's parameter identification (sections 3.4 and 3.7):
//! - `EA` from a free decay: the first natural frequency from the spectrum,
//!   then Eqn 9 (`m gamma sin(gamma l) - mu cos(gamma l) = 0`,
//!   `f = gamma sqrt(EA/mu) / 2 pi`) solved for `EA`;
//! - the damping ratio by the logarithmic decrement (Eqn 11) and the guide
//!   damping `c = 2 zeta omega m` (Eqn 12);
//! - the sheave damping from the constant-speed torque balance (Eqn 13),
//!   corrected for the out-of-balance torque (Eqn 4) when the travel is not
//!   balanced.

use dsp::filter::highpass_zero_phase;
use dsp::spectrum::amplitude_spectrum;
use dsp::AnalysisError;
use plant::free_decay::eqn9_fundamental_gamma_l;

/// What a free decay gives.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FreeDecayIdentification {
    /// First natural frequency, Hz.
    pub first_frequency_hz: f64,
    /// Rope `EA` from Eqn 9, N.
    pub rope_ea_n: f64,
    /// Damping ratio from the logarithmic decrement (Eqn 11), dimensionless.
    pub damping_ratio: f64,
    /// Viscous damping `2 zeta omega m` (Eqn 12), kg/s.
    pub damping_kg_per_s: f64,
    /// Hanging mass, kg.
    pub mass_kg: f64,
    /// Rope tension at the mass, `m g`, N.
    pub tension_n: f64,
    /// Oscillation cycles used for the decrement.
    pub cycles_used: usize,
}

fn invalid(name: &'static str, value: f64, expected: &'static str) -> AnalysisError {
    AnalysisError::InvalidParameter { name, value, expected }
}

/// Eqn 9 solved for `EA` (N) given the first natural frequency `f1_hz`, the
/// rope (`mu` kg/m, length m) and the hanging mass (kg). With a massless rope
/// it is the single spring `EA = (2 pi f)^2 m l`.
pub fn rope_ea_from_first_frequency(f1_hz: f64, mu_kg_per_m: f64, length_m: f64, mass_kg: f64) -> f64 {
    let omega = std::f64::consts::TAU * f1_hz;
    if mu_kg_per_m * length_m < 1e-12 * mass_kg {
        return omega * omega * mass_kg * length_m;
    }
    let gamma = eqn9_fundamental_gamma_l(mu_kg_per_m * length_m, mass_kg) / length_m;
    mu_kg_per_m * (omega / gamma).powi(2)
}

/// Fraction of the largest acceleration magnitude whose first crossing
/// marks the release of a free decay.
pub const RELEASE_FRACTION: f64 = 0.2;
/// Pre-trigger samples shorter than this (s) give no noise estimate.
const MIN_QUIET_S: f64 = 0.05;
/// A spectral line counts as a mode when its amplitude is at least this
/// fraction of the band's largest line ...
const MODE_LINE_FRACTION: f64 = 0.05;
/// ... and this many times the band's median amplitude (the noise floor).
const MODE_LINE_OVER_FLOOR: f64 = 10.0;
/// A first mode closer than this fraction to the top of the search band is
/// refused: the band may have cut the mode off.
const BAND_EDGE_FRACTION: f64 = 0.97;

/// Identifies `EA`, the damping ratio and the guide damping from the
/// acceleration of a free decay (m/s^2, sampled at `sample_rate_hz`).
///
/// The decay may start anywhere in the recording: the release is the first
/// sample whose magnitude reaches [`RELEASE_FRACTION`] of the largest, and
/// what lies before it (a pre-trigger) gives the noise level. The first mode
/// is the spectral line of the released part between 0.5 Hz and
/// `max_frequency_hz` with the largest displacement amplitude (acceleration
/// over `f^2`), among the lines that stand clear of the noise floor: the rope
/// masses' own modes ring above it with more acceleration but far less
/// displacement (a line too broad to stand clear of the floor: the band's
/// largest). The decrement is fitted (least squares on the log of the
/// positive peaks) to the signal band-limited around that mode, from the
/// second cycle after its largest peak until the peaks fall below 5 % of the
/// largest or below three times the noise, and turned into
/// `zeta = delta / sqrt(4 pi^2 + delta^2)` (Eqn 11 is its small-damping form).
///
/// # Errors
/// A mode at the top edge of the search band (raise `max_frequency_hz`), a
/// band holding no mode, fewer than 3 usable cycles, or an amplitude that
/// does not decay (a negative damping is not physical).
pub fn identify_free_decay(
    acceleration_mps2: &[f64],
    sample_rate_hz: f64,
    mass_kg: f64,
    rope_length_m: f64,
    mu_kg_per_m: f64,
    gravity_mps2: f64,
    max_frequency_hz: f64,
) -> Result<FreeDecayIdentification, AnalysisError> {
    if !(mass_kg > 0.0 && mass_kg.is_finite()) {
        return Err(invalid("mass_kg", mass_kg, "a positive mass"));
    }
    if !(rope_length_m > 0.0 && rope_length_m.is_finite()) {
        return Err(invalid("rope_length_m", rope_length_m, "a positive length"));
    }
    if !(mu_kg_per_m >= 0.0 && mu_kg_per_m.is_finite()) {
        return Err(invalid("mu_kg_per_m", mu_kg_per_m, "a non-negative mass per length"));
    }
    if !(max_frequency_hz > 1.0 && max_frequency_hz.is_finite()) {
        return Err(invalid("max_frequency_hz", max_frequency_hz, "a frequency above 1 Hz"));
    }
    let release = release_index(acceleration_mps2)?;
    let released = &acceleration_mps2[release..];
    let top_hz = max_frequency_hz.min(0.5 * sample_rate_hz);
    let f1 = first_mode_hz(released, sample_rate_hz, top_hz)?;
    if f1 > BAND_EDGE_FRACTION * top_hz {
        return Err(AnalysisError::ModeAtBandEdge { frequency_hz: f1, band_top_hz: top_hz });
    }
    let (mode, quiet) = first_mode_signal(acceleration_mps2, release, sample_rate_hz, f1)?;
    let noise_rms = quiet.map(|q| (q.iter().map(|v| v * v).sum::<f64>() / q.len() as f64).sqrt());
    let used = decaying_peaks(&mode[release..], noise_rms.unwrap_or(0.0));
    if used.len() < 3 {
        return Err(AnalysisError::TooShort { len: used.len(), min: 3, what: "decaying cycles of the first mode" });
    }
    let decrement = log_decrement(&used);
    if decrement <= 0.0 {
        return Err(AnalysisError::NotDecaying { decrement });
    }
    let zeta = decrement / (4.0 * std::f64::consts::PI.powi(2) + decrement * decrement).sqrt();
    let omega = std::f64::consts::TAU * f1;
    Ok(FreeDecayIdentification {
        first_frequency_hz: f1,
        rope_ea_n: rope_ea_from_first_frequency(f1, mu_kg_per_m, rope_length_m, mass_kg),
        damping_ratio: zeta,
        damping_kg_per_s: 2.0 * zeta * omega * mass_kg,
        mass_kg,
        tension_n: mass_kg * gravity_mps2,
        cycles_used: used.len(),
    })
}

/// The positive peaks (m/s^2, one a cycle) of a free decay's first mode at
/// `f1_hz`, band-limited as [`identify_free_decay`] does, from the second
/// cycle after the largest while above 5 % of it and three times the noise:
/// the envelope that a model of the damping other than viscous is fitted to.
///
/// # Errors
/// A signal without a release.
pub fn first_mode_peaks(acceleration_mps2: &[f64], sample_rate_hz: f64, f1_hz: f64) -> Result<Vec<f64>, AnalysisError> {
    let release = release_index(acceleration_mps2)?;
    let (mode, quiet) = first_mode_signal(acceleration_mps2, release, sample_rate_hz, f1_hz)?;
    let noise_rms = quiet.map(|q| (q.iter().map(|v| v * v).sum::<f64>() / q.len() as f64).sqrt());
    Ok(decaying_peaks(&mode[release..], noise_rms.unwrap_or(0.0)))
}

/// The release of a free decay: the first sample whose magnitude reaches
/// [`RELEASE_FRACTION`] of the largest.
///
/// # Errors
/// [`AnalysisError::EmptySignal`] for a signal without a finite non-zero sample.
pub fn release_index(acceleration_mps2: &[f64]) -> Result<usize, AnalysisError> {
    let largest = acceleration_mps2.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if !(largest > 0.0 && largest.is_finite()) {
        return Err(AnalysisError::EmptySignal);
    }
    Ok(acceleration_mps2.iter().position(|v| v.abs() >= RELEASE_FRACTION * largest).unwrap_or(0))
}

/// The first mode (Hz) of a released decay: among the spectral lines below
/// `top_hz` that are local maxima, at least [`MODE_LINE_FRACTION`] of the
/// largest and [`MODE_LINE_OVER_FLOOR`] times the median, the one with the
/// largest displacement amplitude (`A / f^2`), refined by [`peak_near`].
///
/// [`peak_near`]: super::spectrum::AmplitudeSpectrum::peak_near
fn first_mode_hz(released: &[f64], sample_rate_hz: f64, top_hz: f64) -> Result<f64, AnalysisError> {
    let spectrum = amplitude_spectrum(released, sample_rate_hz, 4)?;
    let (f, a) = (&spectrum.frequency_hz, &spectrum.amplitude);
    let in_band: Vec<usize> = (1..f.len().saturating_sub(1)).filter(|&i| f[i] >= 0.5 && f[i] <= top_hz).collect();
    let largest = in_band.iter().fold(0.0f64, |m, &i| m.max(a[i]));
    let mut sorted: Vec<f64> = in_band.iter().map(|&i| a[i]).collect();
    sorted.sort_by(f64::total_cmp);
    let floor = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
    let threshold = (MODE_LINE_FRACTION * largest).max(MODE_LINE_OVER_FLOOR * floor);
    let best = in_band
        .iter()
        .filter(|&&i| a[i] >= threshold && a[i] > 0.0 && a[i] >= a[i - 1] && a[i] >= a[i + 1])
        .max_by(|&&i, &&j| (a[i] / (f[i] * f[i])).total_cmp(&(a[j] / (f[j] * f[j]))))
        // A line too broad to stand clear of the floor (a decay that dies
        // within a few cycles): the band's largest line.
        .or_else(|| in_band.iter().filter(|&&i| a[i] > 0.0).max_by(|&&i, &&j| a[i].total_cmp(&a[j])));
    let Some(&i) = best else {
        return Err(invalid("max_frequency_hz", top_hz, "a band above 0.5 Hz holding the first mode"));
    };
    Ok(spectrum.peak_near(f[i], 0.05).map_or(f[i], |p| p.frequency_hz))
}

/// The decay band-limited to the first mode at `f1` Hz (high-pass at
/// `f1/2`, less what a high-pass at `2 f1` keeps: the higher rope modes), and
/// the band-limited pre-trigger before `release` when it is long enough to
/// tell the noise.
pub(crate) fn first_mode_signal(
    acceleration_mps2: &[f64],
    release: usize,
    sample_rate_hz: f64,
    f1: f64,
) -> Result<(Vec<f64>, Option<Vec<f64>>), AnalysisError> {
    let above_half = highpass_zero_phase(acceleration_mps2, sample_rate_hz, 0.5 * f1)?;
    let above_double = highpass_zero_phase(&above_half, sample_rate_hz, (2.0 * f1).min(0.45 * sample_rate_hz))?;
    let mode: Vec<f64> = above_half.iter().zip(&above_double).map(|(a, b)| a - b).collect();
    // The zero-phase filters smear the release backwards by a few cycles.
    let margin = (3.0 * sample_rate_hz / f1) as usize;
    let quiet_end = release.saturating_sub(margin);
    let quiet = (quiet_end as f64 >= MIN_QUIET_S * sample_rate_hz).then(|| mode[..quiet_end].to_vec());
    Ok((mode, quiet))
}

/// The positive peaks of the band-limited decay used for the decrement:
/// from the second after the largest, while above 5 % of the largest and
/// three times `noise_rms`.
fn decaying_peaks(mode: &[f64], noise_rms: f64) -> Vec<f64> {
    let peaks = positive_peaks(mode);
    let (top, largest) = peaks.iter().enumerate().fold((0, 0.0f64), |b, (i, p)| if *p > b.1 { (i, *p) } else { b });
    let floor = (0.05 * largest).max(3.0 * noise_rms);
    peaks.iter().copied().skip(top + 2).take_while(|p| *p > floor).collect()
}

/// Logarithmic decrement per cycle: the least-squares slope of `ln(peak)`
/// against the cycle index, negated.
fn log_decrement(peaks: &[f64]) -> f64 {
    let n = peaks.len() as f64;
    let mean_k = (n - 1.0) / 2.0;
    let logs: Vec<f64> = peaks.iter().map(|p| p.ln()).collect();
    let mean_log = logs.iter().sum::<f64>() / n;
    let (mut num, mut den) = (0.0, 0.0);
    for (k, l) in logs.iter().enumerate() {
        num += (k as f64 - mean_k) * (l - mean_log);
        den += (k as f64 - mean_k).powi(2);
    }
    -num / den
}

/// The largest value of each positive half-cycle (between zero crossings).
fn positive_peaks(signal: &[f64]) -> Vec<f64> {
    let mut peaks = Vec::new();
    let mut current: Option<f64> = None;
    for &x in signal {
        if x > 0.0 {
            current = Some(current.map_or(x, |c| c.max(x)));
        } else if let Some(c) = current.take() {
            peaks.push(c);
        }
    }
    peaks
}

/// Eqn 13 with Eqn 4: the sheave's rotational damping (N m s/rad) from the
/// mean machine torque (N m) and the mean shaft speed (rad/s, non-zero) of a
/// constant-speed stage, the out-of-balance torque at the stage (N m,
/// positive lifts the car) and the guide damping `c_w + c_c` (kg/s) at the
/// sheave radius `r` (m): `c_sh = (tau - tau_e)/w - (c_w + c_c) r^2`.
pub fn sheave_damping_from_torque_balance(
    mean_torque_nm: f64,
    mean_speed_radps: f64,
    out_of_balance_torque_nm: f64,
    guide_damping_kg_per_s: f64,
    sheave_radius_m: f64,
) -> Result<f64, AnalysisError> {
    if !(mean_speed_radps.abs() > 1e-6 && mean_speed_radps.is_finite()) {
        return Err(invalid("mean_speed_radps", mean_speed_radps, "a non-zero constant speed"));
    }
    Ok((mean_torque_nm - out_of_balance_torque_nm) / mean_speed_radps
        - guide_damping_kg_per_s * sheave_radius_m * sheave_radius_m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use plant::free_decay::{eqn9_first_frequency_hz, simulate_free_decay, FreeDecaySpec};

    #[test]
    fn eqn9_inverts_its_own_frequency() {
        for (mass, length) in [(33.0, 1.0), (70.5, 4.0), (45.5, 7.5)] {
            let f = eqn9_first_frequency_hz(1.0e6, 0.095, length, mass);
            let ea = rope_ea_from_first_frequency(f, 0.095, length, mass);
            assert!((ea / 1.0e6 - 1.0).abs() < 1e-9, "{ea}");
        }
        // Massless limit: the single spring EA/l.
        let f = (1.0e6f64 / (2.0 * 33.0)).sqrt() / std::f64::consts::TAU;
        assert!((rope_ea_from_first_frequency(f, 0.0, 2.0, 33.0) / 1.0e6 - 1.0).abs() < 1e-12);
    }

    #[test]
    fn simulated_free_decays_give_back_ea_and_damping() {
        for (mass, length, ea) in [(33.0, 4.0, 1.0e6), (70.5, 2.0, 1.3e6), (45.5, 6.0, 0.8e6)] {
            let spec = FreeDecaySpec {
                mass_kg: mass,
                rope_length_m: length,
                rope_ea_n: ea,
                rope_mass_per_length_kg_per_m: 0.095,
                damping_kg_per_s: 148.0,
                initial_acceleration_mps2: 2.0,
                elements: 40,
            };
            let acc = simulate_free_decay(&spec, 16384.0, 3.0).unwrap();
            let id = identify_free_decay(&acc, 16384.0, mass, length, 0.095, 9.81, 200.0).unwrap();
            let f_true = eqn9_first_frequency_hz(ea, 0.095, length, mass);
            let zeta_true = 148.0 / (2.0 * mass * std::f64::consts::TAU * f_true);
            println!(
                "m {mass} l {length}: f1 {:.3} (Eqn 9 {f_true:.3}) EA {:.4e} (true {ea:.4e}) zeta {:.4} (true {zeta_true:.4})",
                id.first_frequency_hz, id.rope_ea_n, id.damping_ratio
            );
            assert!((id.rope_ea_n / ea - 1.0).abs() < 0.03);
            assert!((id.damping_ratio / zeta_true - 1.0).abs() < 0.10);
        }
    }

    #[test]
    fn torque_balance_recovers_the_sheave_damping() {
        // tau = tau_e + c_sh w + (c_w + c_c) r^2 w with c_sh = 3.
        let (w, r, c_guides, tau_e) = (6.15, 0.065, 296.0, 23.9);
        let tau = tau_e + 3.0 * w + c_guides * r * r * w;
        let c_sh = sheave_damping_from_torque_balance(tau, w, tau_e, c_guides, r).unwrap();
        assert!((c_sh - 3.0).abs() < 1e-12);
        assert!(sheave_damping_from_torque_balance(tau, 0.0, tau_e, c_guides, r).is_err());
    }
}
