//! What `identify` checks of each free decay before it identifies it, so
//! that a decay it cannot use is left out with its true cause, in the
//! user's terms (the file, the column, the metadata field or the flag that
//! was given), and a decay whose first mode lies above the band searched
//! never gives the EA of another line; and whether the EA values of the
//! decays kept agree within their uncertainty before their mean is
//! reported as the rope's.

use std::path::Path;

use diagnosis::identify::{identify_free_decay, release_index};
use diagnosis::identify_dataset::LeftOut;
use recording::{Recording, RecordingKind, ACC_CAR};

use super::readable;

/// Default of `identify --max-frequency`, Hz.
pub const DEFAULT_MAX_FREQUENCY_HZ: f64 = 200.0;
/// Fewest samples of a free decay: fewer hold no cycles to count.
pub const MIN_DECAY_SAMPLES: usize = 64;
/// Lowest frequency the first mode is searched from, Hz (the
/// identification's).
pub const LOWEST_MODE_HZ: f64 = 0.5;
/// Cycles of the fastest mode searched that a decay must span after its
/// release (the identification's decrement needs three).
pub const MIN_CYCLES: f64 = 3.0;
/// Spread (standard deviation) of the released record below this fraction
/// of its largest magnitude: no oscillation (a step, an offset).
const MIN_OSCILLATION_FRACTION: f64 = 1e-3;
/// Fraction of the Nyquist frequency that the whole-band search for the
/// decay's own mode reaches.
const WHOLE_BAND_FRACTION: f64 = 0.9;

/// `--max-frequency` as the user gave it (or its default).
#[derive(Debug, Clone, Copy)]
pub struct MaxFrequency {
    /// Top of the band searched for a free decay's first mode, Hz.
    pub hz: f64,
    /// Whether the user gave the flag.
    pub given: bool,
}

impl MaxFrequency {
    /// The flag for a message: `--max-frequency = 10 Hz`, or its default.
    pub fn describe(&self) -> String {
        if self.given {
            format!("--max-frequency = {} Hz", readable(self.hz))
        } else {
            format!("--max-frequency (default {} Hz)", readable(self.hz))
        }
    }
}

/// Splits `dataset` into the recordings `identify` hands on (every travel,
/// every free decay that passes [`decay_refusal`]) and the free decays
/// left out with their reason. `dir` is the dataset's folder.
pub fn screen_decays(
    dir: &Path,
    dataset: Vec<(String, Recording)>,
    band: MaxFrequency,
) -> (Vec<(String, Recording)>, Vec<LeftOut>) {
    let mut kept = Vec::new();
    let mut left_out = Vec::new();
    for (stem, rec) in dataset {
        let refusal = match (&rec.meta.kind, rec.column(ACC_CAR)) {
            (RecordingKind::FreeDecay { .. }, Some(acc)) => {
                let csv = dir.join(format!("{stem}.csv"));
                decay_refusal(&csv, &acc.values, rec.meta.sample_rate_hz, band)
            }
            _ => None,
        };
        match refusal {
            Some(reason) => left_out.push(LeftOut { recording: stem, reason }),
            None => kept.push((stem, rec)),
        }
    }
    (kept, left_out)
}

/// Why the car acceleration `acc` (m/s^2, at `fs` Hz) of the free decay in
/// `csv` cannot give the rope's EA, or `None` when it can be tried: too few
/// samples, a sample rate whose Nyquist frequency lies below the band, a
/// record shorter than [`MIN_CYCLES`] of the fastest mode searched, no
/// oscillation after the release (a step), a mode above `band` (the line
/// the decay rings at, found over the whole band up to the Nyquist
/// frequency, lies above `--max-frequency`), an oscillation that grows.
pub fn decay_refusal(csv: &Path, acc: &[f64], fs: f64, band: MaxFrequency) -> Option<String> {
    let at = format!("`{}`, column `{ACC_CAR}`", csv.display());
    let meta = csv.with_extension("toml");
    let n = acc.len();
    if n < MIN_DECAY_SAMPLES {
        return Some(format!(
            "{at}: {n} samples ({} s) hold no free decay; expected at least {MIN_DECAY_SAMPLES} samples spanning \
             several cycles of the first mode",
            readable(n as f64 / fs)
        ));
    }
    let nyquist = 0.5 * fs;
    if nyquist <= 2.0 * LOWEST_MODE_HZ {
        return Some(format!(
            "`{}`: sample_rate_hz = {} Hz resolves frequencies up to {} Hz only (the Nyquist frequency), \
             while the first mode is searched from {LOWEST_MODE_HZ} Hz up to {}: expected a sample rate of at \
             least twice the first mode (the rig's recordings: thousands of Hz)",
            meta.display(),
            readable(fs),
            readable(nyquist),
            band.describe()
        ));
    }
    let release = release_index(acc).ok()?;
    let released = &acc[release..];
    let top = band.hz.min(nyquist);
    let lasts = released.len() as f64 / fs;
    if lasts < MIN_CYCLES / top {
        return Some(format!(
            "{at}: the decay lasts {} s after its release (line {}, t = {} s): shorter than {MIN_CYCLES} cycles \
             of the fastest mode searched ({} Hz: {} or the Nyquist frequency of sample_rate_hz = {} Hz); \
             expected at least {} s (is `{}`'s sample_rate_hz right?)",
            readable(lasts),
            release + 2,
            readable(release as f64 / fs),
            readable(top),
            band.describe(),
            readable(fs),
            readable(MIN_CYCLES / top),
            meta.display()
        ));
    }
    if let Some(reason) = no_oscillation(released, release, fs) {
        return Some(format!("{at}: {reason}"));
    }
    if let Some(reason) = mode_above_band(released, fs, band) {
        return Some(format!("{at}: {reason}"));
    }
    grows(released, release, fs).map(|reason| format!("{at}: {reason}"))
}

/// A released record (from sample `release`) that stays where it is: a
/// step or an offset, no decay.
fn no_oscillation(released: &[f64], release: usize, fs: f64) -> Option<String> {
    let n = released.len() as f64;
    let mean = released.iter().sum::<f64>() / n;
    let spread = (released.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt();
    let largest = released.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    (spread < MIN_OSCILLATION_FRACTION * largest).then(|| {
        format!(
            "after the release (line {}, t = {} s) the signal holds no oscillation: it stays at {mean:.4} m/s^2 \
             (spread {spread:.2e} m/s^2), a step or an offset; expected a free decay (an oscillation dying away)",
            release + 2,
            readable(release as f64 / fs)
        )
    })
}

/// Share of the record's spectral power (up to [`WHOLE_BAND_FRACTION`] of
/// the Nyquist frequency) below which the band holds no mode of the decay,
/// only leakage and noise (a first mode carries most of a decay's power).
const BAND_POWER_FRACTION: f64 = 0.1;

/// The decay's strongest spectral line (acceleration amplitude, over the
/// released record up to [`WHOLE_BAND_FRACTION`] of the Nyquist frequency)
/// when it lies above `band` and the band holds less than
/// [`BAND_POWER_FRACTION`] of the record's power: whatever the
/// identification found there would be leakage or noise, its EA no rope's.
/// A first mode inside the band with a higher rope mode ringing harder
/// passes.
fn mode_above_band(released: &[f64], fs: f64, band: MaxFrequency) -> Option<String> {
    let whole = WHOLE_BAND_FRACTION * 0.5 * fs;
    if band.hz >= whole {
        return None;
    }
    let spectrum = dsp::amplitude_spectrum(released, fs, 4).ok()?;
    let (f, a) = (&spectrum.frequency_hz, &spectrum.amplitude);
    let lines = |hi: f64| (0..f.len()).filter(move |&i| f[i] >= LOWEST_MODE_HZ && f[i] <= hi);
    let top = lines(whole).fold(None, |m: Option<usize>, i| match m {
        Some(j) if a[j] >= a[i] => Some(j),
        _ => Some(i),
    })?;
    if f[top] <= band.hz {
        return None;
    }
    let power = |hi: f64| lines(hi).map(|i| a[i] * a[i]).sum::<f64>();
    let share = power(band.hz) / power(whole);
    if share >= BAND_POWER_FRACTION {
        return None;
    }
    // The mode to name: the first mode as the identification finds it over
    // the whole band (the largest displacement among the clear lines; the
    // strongest acceleration line may be a rope's own mode), else the
    // strongest line.
    let first = identify_free_decay(released, fs, 1.0, 1.0, 0.0, 9.81, whole).ok().map(|id| id.first_frequency_hz);
    let (f1, what) = match first {
        Some(f1) if f1 > band.hz => (f1, "its first mode, found as the identification finds it"),
        _ => (spectrum.peak_near(f[top], 0.05).map_or(f[top], |p| p.frequency_hz), "its strongest line"),
    };
    Some(format!(
        "the decay rings at {f1:.2} Hz ({what}, searched up to {} Hz), above {}, which holds {:.1} % of its power: \
         the mode lies above the band searched, whose lines would give another oscillation's EA and damping; \
         expected --max-frequency above {:.1} Hz",
        readable(whole.round()),
        band.describe(),
        100.0 * share,
        1.2 * f1
    ))
}

/// A released record that grows: at least as much of its energy (the sum
/// of its squared samples) before its largest swing as after it. A free
/// decay swings largest within a cycle of its release and spends its energy
/// dying away.
fn grows(released: &[f64], release: usize, fs: f64) -> Option<String> {
    let peak =
        released.iter().enumerate().fold((0, 0.0f64), |m, (i, v)| if v.abs() > m.1 { (i, v.abs()) } else { m }).0;
    let energy = |s: &[f64]| s.iter().map(|v| v * v).sum::<f64>();
    let (before, after) = (energy(&released[..peak]), energy(&released[peak..]));
    (before >= after).then(|| {
        format!(
            "the oscillation does not decay: its largest swing comes at line {} (t = {} s), {} s after the release, \
             with {:.0} % of the record's energy before it; expected a free decay, largest at its release and dying \
             away (a negative damping is not physical)",
            release + peak + 2,
            readable((release + peak) as f64 / fs),
            readable(peak as f64 / fs),
            100.0 * before / (before + after)
        )
    })
}

/// A free decay's EA with its uncertainty: twice the standard error of the
/// EA of its single cycles, N (`None` with fewer than two cycles).
#[derive(Debug, Clone, PartialEq)]
pub struct EaEstimate {
    /// Recording stem.
    pub recording: String,
    /// EA (Eqn 9), N.
    pub ea_n: f64,
    /// Twice the standard error of the cycles' EA, N.
    pub error_n: Option<f64>,
}

/// Prefixes the reason of each free decay that the identification left
/// out with its samples file and column (`dir` the dataset's folder):
/// the identification knows the signal only.
/// A reason about the search band also names the flag that sets it.
pub fn name_decay_files(dir: &Path, kinds: &[(String, RecordingKind)], band: MaxFrequency, left_out: &mut [LeftOut]) {
    for l in left_out {
        let decay = kinds.iter().any(|(s, k)| *s == l.recording && matches!(k, RecordingKind::FreeDecay { .. }));
        if decay {
            let csv = dir.join(format!("{}.csv", l.recording));
            let flag = if l.reason.contains("search band") {
                format!(" (the band's top: {})", band.describe())
            } else {
                String::new()
            };
            l.reason = format!("`{}`, column `{ACC_CAR}`: {}{flag}", csv.display(), l.reason);
        }
    }
}

/// When the EA values of two decays differ by more than the sum of their
/// uncertainties: the pair furthest apart (in units of that sum), in words
/// for the report, which then says that the mean is no single EA of the
/// rope (a rope stiffening with tension, a decay of another line).
pub fn ea_disagreement(estimates: &[EaEstimate]) -> Option<String> {
    let mut worst: Option<(f64, &EaEstimate, &EaEstimate)> = None;
    for (i, a) in estimates.iter().enumerate() {
        for b in &estimates[i + 1..] {
            let (Some(ea), Some(eb)) = (a.error_n, b.error_n) else { continue };
            let sigma = (ea + eb).max(1e-9 * a.ea_n.abs().max(b.ea_n.abs()));
            let apart = (a.ea_n - b.ea_n).abs() / sigma;
            if apart > 1.0 && worst.is_none_or(|w| apart > w.0) {
                worst = Some((apart, a, b));
            }
        }
    }
    worst.map(|(apart, a, b)| {
        format!(
            "the decays' EA values disagree beyond their uncertainty: `{}` {:.4e} +- {:.1e} N and `{}` {:.4e} +- \
             {:.1e} N lie {apart:.1} times their summed uncertainty apart; their mean is no single EA of the rope \
             (EA changing with tension, or a decay of another line)",
            a.recording,
            a.ea_n,
            a.error_n.unwrap_or(0.0),
            b.recording,
            b.ea_n,
            b.error_n.unwrap_or(0.0)
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    /// A free decay at `f` Hz (damping ratio 0.02, growing with `zeta < 0`)
    /// released after 0.5 s of rest, `seconds` long at `fs` Hz.
    fn decay(f: f64, zeta: f64, fs: f64, seconds: f64) -> Vec<f64> {
        (0..(seconds * fs) as usize)
            .map(|i| {
                let t = i as f64 / fs - 0.5;
                if t < 0.0 {
                    1e-4 * (i as f64).sin()
                } else {
                    (-zeta * TAU * f * t).exp() * (TAU * f * t).sin()
                }
            })
            .collect()
    }

    fn refusal(acc: &[f64], fs: f64, hz: f64, given: bool) -> Option<String> {
        decay_refusal(Path::new("d/decay.csv"), acc, fs, MaxFrequency { hz, given })
    }

    #[test]
    fn a_sound_decay_passes_and_each_unusable_one_gets_its_own_cause() {
        assert_eq!(refusal(&decay(17.5, 0.02, 4096.0, 6.0), 4096.0, 200.0, false), None);
        let e = refusal(&[0.0, 1.0], 4096.0, 200.0, false).unwrap();
        assert!(e.starts_with("`d/decay.csv`, column `acc_car_mps2`: 2 samples"), "{e}");
        let e = refusal(&decay(0.3, 0.02, 1.0, 3600.0), 1.0, 200.0, false).unwrap();
        assert!(e.contains("`d/decay.toml`: sample_rate_hz = 1 Hz") && !e.contains("max_frequency_hz"), "{e}");
        // The rig's decay with its metadata claiming 1e7 Hz: 2.5 ms long.
        let e = refusal(&decay(17.5, 0.02, 4096.0, 6.0), 1e7, 200.0, false).unwrap();
        assert!(e.contains("the decay lasts") && e.contains("sample_rate_hz = 10000000 Hz"), "{e}");
        let step: Vec<f64> = (0..4096).map(|i| if i < 2048 { 0.0 } else { 1.0 }).collect();
        let e = refusal(&step, 4096.0, 200.0, false).unwrap();
        assert!(e.contains("no oscillation") && e.contains("line 2050"), "{e}");
        let e = refusal(&decay(17.5, -0.005, 4096.0, 6.0), 4096.0, 200.0, false).unwrap();
        assert!(e.contains("does not decay"), "{e}");
    }

    #[test]
    fn a_mode_above_the_band_is_named_with_the_flag_given_or_its_default() {
        let e = refusal(&decay(17.5, 0.02, 4096.0, 6.0), 4096.0, 10.0, true).unwrap();
        assert!(e.contains("rings at 17.50 Hz") && e.contains("above --max-frequency = 10 Hz"), "{e}");
        let e = refusal(&decay(500.0, 0.002, 4096.0, 6.0), 4096.0, 200.0, false).unwrap();
        assert!(e.contains("rings at 500.") && e.contains("--max-frequency (default 200 Hz)"), "{e}");
        assert_eq!(refusal(&decay(7.7, 0.02, 4096.0, 6.0), 4096.0, 10.0, true), None);
    }

    #[test]
    fn ea_values_apart_beyond_their_uncertainty_are_named() {
        let est = |r: &str, ea: f64, e: Option<f64>| EaEstimate { recording: r.into(), ea_n: ea, error_n: e };
        let agree = [est("a", 1.0002e6, Some(300.0)), est("b", 1.0001e6, Some(200.0))];
        assert_eq!(ea_disagreement(&agree), None);
        let apart = [est("a", 7.29e4, Some(50.0)), est("b", 1.0002e6, Some(300.0)), est("c", 1.0e6, None)];
        let note = ea_disagreement(&apart).unwrap();
        assert!(note.contains("`a` 7.2900e4") && note.contains("`b` 1.0002e6"), "{note}");
    }
}
