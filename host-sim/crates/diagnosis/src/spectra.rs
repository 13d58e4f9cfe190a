//! Short-time spectra of the chain signals and their powers in cells of
//! (channel, travel phase, third-octave band). The transform is linear, so
//! the spectra of a linear combination of simulations are the same
//! combination of their spectra: the attribution fits effects whose
//! influence is small by combining a few simulations instead of running one
//! per trial value.

use std::ops::Range;

use realfft::num_complex::Complex64;
use realfft::RealFftPlanner;

use super::signals::{ChainSignals, Channel, Phase};
use plant::ripple::unit_power;
use rig_config::RigConfig;

/// Lowest band edge, Hz (accelerometers are not trusted below 0.5 Hz).
pub const LOWEST_BAND_HZ: f64 = 1.0;
/// Highest band edge, Hz.
pub const HIGHEST_BAND_HZ: f64 = 1000.0;
/// Segment length, s (1 Hz bins).
pub const SEGMENT_S: f64 = 1.0;

/// Mechanical orders below the rig's own whose angle-locked lines are cells
/// of their own in the constant-speed stage: the once-per-revolution line
/// and its first harmonics (eccentricities of the sheave and the machine,
/// the encoder's error). A 1 s segment cannot resolve a 1 Hz line.
pub const REVOLUTION_ORDERS: [u32; 3] = [1, 2, 3];

/// The mechanical orders whose lines are cells of their own for `rig`:
/// [`REVOLUTION_ORDERS`], the rig file's ripple orders (paper 3.3) and the
/// machine's first two electrical orders (`p` and `2 p`: a current
/// transducer's offset and gain error), ascending, each once.
pub fn line_orders(rig: &RigConfig) -> Vec<u32> {
    let p = rig.motor.pole_pairs;
    let mut orders: Vec<u32> = REVOLUTION_ORDERS
        .into_iter()
        .chain(rig.ripple.iter().map(|r| r.mechanical_order))
        .chain([p, 2 * p])
        .filter(|&o| o > 0)
        .collect();
    orders.sort_unstable();
    orders.dedup();
    orders
}

/// Third-octave bands from [`LOWEST_BAND_HZ`] to [`HIGHEST_BAND_HZ`] (or 45 %
/// of the sample rate), each holding at least one bin of the segment's
/// transform; after them, as cells `len()..len() + line_orders.len()`, the
/// angle-locked lines of `line_orders` ([`line_orders`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Bands {
    /// `[lo, hi)` edges of every band, Hz.
    pub edges_hz: Vec<(f64, f64)>,
    /// For every bin of the transform, its band.
    pub bin_band: Vec<Option<usize>>,
    /// The mechanical orders whose lines follow the bands as cells.
    pub line_orders: Vec<u32>,
}

impl Bands {
    /// The bands for segments of `segment_len` samples at `sample_rate_hz`,
    /// followed by the lines of `line_orders` (mechanical orders).
    pub fn new(sample_rate_hz: f64, segment_len: usize, line_orders: Vec<u32>) -> Self {
        let df = sample_rate_hz / segment_len as f64;
        let top = HIGHEST_BAND_HZ.min(0.45 * sample_rate_hz);
        let bins = segment_len / 2 + 1;
        let mut edges_hz = Vec::new();
        let mut bin_band = vec![None; bins];
        let mut k = 0;
        loop {
            let lo = LOWEST_BAND_HZ * 2f64.powf(k as f64 / 3.0);
            let hi = LOWEST_BAND_HZ * 2f64.powf((k + 1) as f64 / 3.0);
            if lo >= top {
                break;
            }
            let hi = hi.min(top);
            let members: Vec<usize> = (0..bins).filter(|&b| (b as f64 * df) >= lo && (b as f64 * df) < hi).collect();
            if !members.is_empty() {
                for b in members {
                    bin_band[b] = Some(edges_hz.len());
                }
                edges_hz.push((lo, hi));
            }
            k += 1;
        }
        Self { edges_hz, bin_band, line_orders }
    }

    /// Number of bands.
    pub fn len(&self) -> usize {
        self.edges_hz.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.edges_hz.is_empty()
    }

    /// Whether cell index `b` is a line (not a band).
    pub fn is_line(&self, b: usize) -> bool {
        b >= self.len()
    }

    /// Cell index `b` as text: `lo-hi Hz` or `order n`.
    pub fn label(&self, b: usize) -> String {
        match self.edges_hz.get(b) {
            Some((lo, hi)) => format!("{lo:.1}-{hi:.1} Hz"),
            None => format!("order {}", self.line_orders.get(b - self.len()).copied().unwrap_or(0)),
        }
    }
}

/// Where the segments of a recording lie: Hann segments of [`SEGMENT_S`]
/// with half overlap inside each phase; a phase shorter than a segment gets
/// one shorter, zero-padded segment.
#[derive(Clone, Debug, PartialEq)]
pub struct Segmentation {
    /// Sample rate, Hz.
    pub sample_rate_hz: f64,
    /// Transform length, samples.
    pub segment_len: usize,
    /// Every segment: its phase, its sample range.
    pub segments: Vec<(Phase, Range<usize>)>,
    /// The constant-speed stage, where the lines are measured.
    pub constant: Option<Range<usize>>,
}

impl Segmentation {
    /// The segmentation of `signals`' phases.
    pub fn of(signals: &ChainSignals) -> Self {
        let n = (SEGMENT_S * signals.sample_rate_hz).round().max(16.0) as usize;
        let mut segments = Vec::new();
        for (phase, range) in &signals.phases {
            let len = range.len();
            if len < n / 8 {
                continue;
            }
            if len < n {
                segments.push((*phase, range.clone()));
                continue;
            }
            let mut start = range.start;
            while start + n <= range.end {
                segments.push((*phase, start..start + n));
                start += n / 2;
            }
        }
        let constant =
            signals.phases.iter().find(|(p, r)| *p == Phase::Constant && r.len() >= n).map(|(_, r)| r.clone());
        Self { sample_rate_hz: signals.sample_rate_hz, segment_len: n, segments, constant }
    }

    /// The phases that have segments, in order.
    pub fn phases(&self) -> Vec<Phase> {
        let mut out: Vec<Phase> = self.segments.iter().map(|(p, _)| *p).collect();
        out.dedup();
        out
    }
}

/// The short-time spectra of one channel on a segmentation.
#[derive(Clone, Debug)]
pub struct ChannelSpectra {
    /// Bins kept per segment (up to the top band).
    pub bins: usize,
    /// Density scale of each segment, `2 / (fs sum(w^2))`, s/unit-free.
    pub scale: Vec<f64>,
    /// Segment-major transforms, `bins` per segment.
    pub data: Vec<Complex64>,
    /// Complex amplitudes of the bands' line orders over the constant-speed
    /// stage (empty without one), unit.
    pub lines: Vec<Complex64>,
    /// Noise scale of a line, `2 / T` (1/s, T the stage's duration): a
    /// noise density `N` adds `2 N / T` to a line's squared amplitude.
    pub line_noise_scale: f64,
}

/// The spectra of every channel of a recording on one segmentation.
#[derive(Clone, Debug)]
pub struct ChainSpectra {
    /// The segmentation.
    pub segmentation: Segmentation,
    /// Per channel.
    pub channels: Vec<(Channel, ChannelSpectra)>,
}

/// Hann windows by length, each with its energy `sum(w^2)`, made once per
/// length (a recording's segments share one or two lengths).
#[derive(Default)]
struct HannWindows {
    by_len: Vec<(usize, Vec<f64>, f64)>,
}

impl HannWindows {
    /// The window of `len` samples and its energy.
    fn of(&mut self, len: usize) -> (&[f64], f64) {
        let at = match self.by_len.iter().position(|(l, _, _)| *l == len) {
            Some(at) => at,
            None => {
                let window: Vec<f64> =
                    (0..len).map(|i| 0.5 - 0.5 * (std::f64::consts::TAU * i as f64 / len as f64).cos()).collect();
                let energy = window.iter().map(|w| w * w).sum();
                self.by_len.push((len, window, energy));
                self.by_len.len() - 1
            }
        };
        let (_, window, energy) = &self.by_len[at];
        (window, *energy)
    }
}

/// [`angle_locked_lines_of`] of one signal `x`.
#[cfg(test)]
fn angle_locked_lines(x: &[f64], theta: &[f64], orders: &[u32], window: &[f64], fs: f64) -> (Vec<Complex64>, f64) {
    let (mut lines, scale) = angle_locked_lines_of(&[x], theta, orders, window, fs);
    (lines.pop().unwrap_or_default(), scale)
}

/// Complex amplitudes (unit of `x`) of the mechanical `orders`' lines in
/// each of `xs` (its mean removed) along the shaft angle `theta` (rad) under a Hann
/// window `w` over the stage: `2 / sum(w) sum w (x - mean) e^(-i k (theta -
/// theta_0))` (`w` of the length of `x`), one `sin_cos` per sample and the
/// orders by powers of it ([`unit_power`]). A stage holds a fractional
/// number of revolutions: without the window, a strong line (the rig's order 12 is some hundred
/// times its order 2 in the car's acceleration) leaks into the weak ones
/// by `1 / (pi d N)` of its amplitude, `d` orders away over `N`
/// revolutions (about 1/500 at `d = 10`, `N = 15`); the window's side lobes
/// fall as `1 / (d N)^3`. With them, the factor that takes the noise's
/// one-sided density (unit^2/Hz) to a line's expected power (unit^2) at
/// sample rate `fs` (Hz): `2 fs sum(w^2) / sum(w)^2` (`3 fs / n`).
/// Each sample's rotation and its powers are worked out once for all the
/// signals.
fn angle_locked_lines_of(
    xs: &[&[f64]],
    theta: &[f64],
    orders: &[u32],
    window: &[f64],
    fs: f64,
) -> (Vec<Vec<Complex64>>, f64) {
    let means: Vec<f64> = xs.iter().map(|x| x.iter().sum::<f64>() / x.len().max(1) as f64).collect();
    let mut sums = vec![vec![Complex64::new(0.0, 0.0); orders.len()]; xs.len()];
    let len = xs.iter().map(|x| x.len()).min().unwrap_or(0).min(theta.len()).min(window.len());
    let mut powers = vec![Complex64::new(0.0, 0.0); orders.len()];
    for k in 0..len {
        let (s, c) = (theta[k] - theta[0]).sin_cos();
        for (power, &order) in powers.iter_mut().zip(orders) {
            let (ck, sk) = unit_power(c, s, order);
            *power = Complex64::new(ck, -sk);
        }
        for ((x, mean), sums) in xs.iter().zip(&means).zip(sums.iter_mut()) {
            let weight = window[k] * (x[k] - mean);
            for (sum, power) in sums.iter_mut().zip(&powers) {
                *sum += *power * weight;
            }
        }
    }
    let (s1, s2) = window.iter().fold((0.0, 0.0), |(a, b), w| (a + w, b + w * w));
    let s1 = s1.max(1e-12);
    let lines = sums.into_iter().map(|sums| sums.into_iter().map(|a| a * (2.0 / s1)).collect()).collect();
    (lines, 2.0 * fs * s2 / (s1 * s1))
}

impl ChainSpectra {
    /// Spectra of `signals` on `segmentation` (samples beyond the end of a
    /// signal count as zero).
    pub fn compute(signals: &ChainSignals, segmentation: &Segmentation, bands: &Bands) -> Self {
        let n = segmentation.segment_len;
        let mut planner = RealFftPlanner::<f64>::new();
        let fft = planner.plan_fft_forward(n);
        let bins = bands.bin_band.iter().rposition(|b| b.is_some()).map_or(0, |b| b + 1);
        let mut input = fft.make_input_vec();
        let mut output = fft.make_output_vec();
        let mut windows = HannWindows::default();
        let mut channels = Vec::new();
        let (lines_of, line_noise_scale) = match &segmentation.constant {
            Some(r) if signals.angle_rad.len() >= r.end => {
                let stage: Vec<&[f64]> = signals.channels.iter().map(|(_, values)| &values[r.clone()]).collect();
                let window = windows.of(r.len()).0;
                let theta = &signals.angle_rad[r.clone()];
                angle_locked_lines_of(&stage, theta, &bands.line_orders, window, segmentation.sample_rate_hz)
            }
            _ => (Vec::new(), 0.0),
        };
        let mut lines_of = lines_of.into_iter();
        for (channel, values) in &signals.channels {
            let mut scale = Vec::with_capacity(segmentation.segments.len());
            let mut data = Vec::with_capacity(segmentation.segments.len() * bins);
            for (_, range) in &segmentation.segments {
                let len = range.len();
                let (window, w2) = windows.of(len);
                let seg: Vec<f64> = range.clone().map(|i| values.get(i).copied().unwrap_or(0.0)).collect();
                let mean = seg.iter().sum::<f64>() / len as f64;
                input.iter_mut().for_each(|x| *x = 0.0);
                for i in 0..len {
                    input[i] = (seg[i] - mean) * window[i];
                }
                // Input length matches the plan, so the transform cannot fail.
                if fft.process(&mut input, &mut output).is_err() {
                    output.iter_mut().for_each(|x| *x = Complex64::new(0.0, 0.0));
                }
                scale.push(2.0 / (segmentation.sample_rate_hz * w2.max(1e-12)));
                data.extend_from_slice(&output[..bins]);
            }
            let lines = lines_of.next().unwrap_or_default();
            channels.push((*channel, ChannelSpectra { bins, scale, data, lines, line_noise_scale }));
        }
        Self { segmentation: segmentation.clone(), channels }
    }

    /// The spectra of `channel`, if present.
    pub fn channel(&self, channel: Channel) -> Option<&ChannelSpectra> {
        self.channels.iter().find(|(c, _)| *c == channel).map(|(_, s)| s)
    }
}

/// A cell: channel, travel phase, band index.
pub type CellKey = (Channel, Phase, usize);

/// One cell's power: a band's mean density (unit^2/Hz) or a line's squared
/// amplitude (unit^2), the number of averages in it, and the factor that
/// turns a noise density into the noise it adds to the cell (1 for a band,
/// `2 / T` for a line).
pub type CellPower = (f64, f64, f64);

/// The power of every (channel, phase, band or line) cell.
#[derive(Clone, Debug, Default)]
pub struct CellPowers {
    /// `(channel, phase, band) -> (power, averages, noise scale)`.
    pub cells: Vec<(CellKey, CellPower)>,
}

impl CellPowers {
    /// The cell's power, if present.
    pub fn get(&self, key: CellKey) -> Option<CellPower> {
        self.cells.binary_search_by(|(k, _)| k.cmp(&key)).ok().map(|i| self.cells[i].1)
    }
}

/// Cell powers of the linear combination `sum(coefficient * spectra)` of
/// spectra on one segmentation (the first part's).
pub fn cell_powers(parts: &[(&ChainSpectra, f64)], bands: &Bands) -> CellPowers {
    let spectra: Vec<&ChainSpectra> = parts.iter().map(|(s, _)| *s).collect();
    let weights: Vec<f64> = parts.iter().map(|(_, w)| *w).collect();
    CrossPowers::compute(&spectra, bands).powers(&weights)
}

/// The cross powers of several spectra on one segmentation, per cell:
/// `S_ij = mean over the cell's bins and segments of scale Re(X_i conj(X_j))`,
/// so that the cell power of `sum(w_i X_i)` is `w^T S w` without touching
/// the spectra again.
#[derive(Clone, Debug, Default)]
pub struct CrossPowers {
    /// Number of spectra.
    pub parts: usize,
    /// `(cell, averages, noise scale, S row-major parts x parts)`, sorted by cell.
    pub cells: Vec<(CellKey, f64, f64, Vec<f64>)>,
}

impl CrossPowers {
    /// Cross powers of `parts` (all on the first one's segmentation).
    pub fn compute(parts: &[&ChainSpectra], bands: &Bands) -> Self {
        let Some(first) = parts.first() else {
            return Self::default();
        };
        let n = parts.len();
        let segs = &first.segmentation.segments;
        let phases = first.segmentation.phases();
        let mut cells = Vec::new();
        for (channel, spectra) in &first.channels {
            let all: Vec<&ChannelSpectra> = parts.iter().filter_map(|s| s.channel(*channel)).collect();
            if all.len() != n {
                continue;
            }
            let bins = spectra.bins;
            let mut sum = vec![vec![vec![0.0; n * n]; bands.len()]; phases.len()];
            let mut count = vec![vec![0.0; bands.len()]; phases.len()];
            for (s, (phase, _)) in segs.iter().enumerate() {
                let p = phases.iter().position(|q| q == phase).unwrap_or(0);
                let scale = spectra.scale[s];
                for b in 0..bins {
                    let Some(band) = bands.bin_band[b] else { continue };
                    let acc = &mut sum[p][band];
                    for i in 0..n {
                        let xi = all[i].data[s * bins + b];
                        for j in i..n {
                            let v = scale * (xi * all[j].data[s * bins + b].conj()).re;
                            acc[i * n + j] += v;
                        }
                    }
                    count[p][band] += 1.0;
                }
            }
            for (p, phase) in phases.iter().enumerate() {
                for band in 0..bands.len() {
                    let k = count[p][band];
                    if k > 0.0 {
                        let mut m = sum[p][band].clone();
                        for i in 0..n {
                            for j in i..n {
                                m[i * n + j] /= k;
                                m[j * n + i] = m[i * n + j];
                            }
                        }
                        cells.push(((*channel, *phase, band), k, 1.0, m));
                    }
                }
            }
            if all.iter().all(|c| c.lines.len() == bands.line_orders.len()) {
                for j in 0..bands.line_orders.len() {
                    let mut m = vec![0.0; n * n];
                    for i in 0..n {
                        for k in 0..n {
                            m[i * n + k] = (all[i].lines[j] * all[k].lines[j].conj()).re;
                        }
                    }
                    cells.push(((*channel, Phase::Constant, bands.len() + j), 1.0, spectra.line_noise_scale, m));
                }
            }
        }
        cells.sort_by_key(|a| a.0);
        Self { parts: n, cells }
    }

    /// Cell powers of `sum(weights_i X_i)`.
    pub fn powers(&self, weights: &[f64]) -> CellPowers {
        let n = self.parts;
        let cells = self
            .cells
            .iter()
            .map(|(key, k, scale, m)| {
                let mut p = 0.0;
                for i in 0..n {
                    for j in 0..n {
                        p += weights[i] * weights[j] * m[i * n + j];
                    }
                }
                (*key, (p.max(0.0), *k, *scale))
            })
            .collect();
        CellPowers { cells }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    /// The reference rig's lines: the revolution's, its ripple orders 1, 6,
    /// 12, 36, 72 and its electrical orders 6 and 12 (6 pole pairs); a rig
    /// with 4 pole pairs and other ripple orders gets its own.
    #[test]
    fn line_orders_come_from_the_rig_file() {
        let mut rig = RigConfig::embedded_default().unwrap();
        assert_eq!(line_orders(&rig), vec![1, 2, 3, 6, 12, 36, 72]);
        rig.motor.pole_pairs = 4;
        for (r, order) in rig.ripple.iter_mut().zip([1, 8, 24, 48, 48]) {
            r.mechanical_order = order;
        }
        assert_eq!(line_orders(&rig), vec![1, 2, 3, 4, 8, 24, 48]);
    }

    /// The lines by powers of one rotation against each order's own
    /// `sin_cos` (the naive windowed sum), on an irregular angle.
    #[test]
    fn angle_locked_lines_match_the_naive_sum() {
        let theta: Vec<f64> = (0..5000).map(|i| 0.01 * i as f64 + 0.3 * (0.002 * i as f64).sin()).collect();
        let x: Vec<f64> = theta.iter().map(|t| 0.7 * (6.0 * t + 0.4).cos() + 0.2 * (72.0 * t).sin() + 0.1).collect();
        let orders = [1, 6, 12, 72];
        let mut windows = HannWindows::default();
        let window = windows.of(x.len()).0.to_vec();
        let (got, _) = angle_locked_lines(&x, &theta, &orders, &window, 1000.0);
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let s1: f64 = window.iter().sum();
        for (g, &k) in got.iter().zip(&orders) {
            let mut a = Complex64::new(0.0, 0.0);
            for ((v, t), w) in x.iter().zip(&theta).zip(&window) {
                let (s, c) = (k as f64 * (t - theta[0])).sin_cos();
                a += Complex64::new(c, -s) * (w * (v - mean));
            }
            let naive = a * (2.0 / s1);
            assert!((g - naive).norm() < 1e-12, "order {k}: {g} against {naive}");
        }
        assert!((got[1].norm() - 0.7).abs() < 0.02 && (got[3].norm() - 0.2).abs() < 0.02, "{got:?}");
    }

    /// A line a hundred times weaker than its neighbour ten orders away is
    /// read within 2 % in amplitude and 0.02 rad in phase over a stage of
    /// 15.37 revolutions (the rectangular sum is off by about 9 % there).
    #[test]
    fn a_strong_line_does_not_leak_into_a_weak_one() {
        let n = 20_000;
        let theta: Vec<f64> = (0..n).map(|i| 15.37 * TAU * i as f64 / n as f64).collect();
        let x: Vec<f64> = theta.iter().map(|t| (12.0 * t + 0.3).cos() + 0.01 * (2.0 * t + 1.1).cos()).collect();
        let mut windows = HannWindows::default();
        let (lines, _) = angle_locked_lines(&x, &theta, &[2, 12], windows.of(n).0, 4096.0);
        assert!((lines[0].norm() - 0.01).abs() < 2e-4 && (lines[0].arg() - 1.1).abs() < 0.02, "{}", lines[0]);
        let rectangular = vec![1.0; n];
        let (plain, _) = angle_locked_lines(&x, &theta, &[2], &rectangular, 4096.0);
        assert!((plain[0] - Complex64::from_polar(0.01, 1.1)).norm() > 0.05 * 0.01, "{}", plain[0]);
    }

    /// The noise scale: white noise of one-sided density `N0` gives a line
    /// whose mean power over many stages is `N0` times the scale.
    #[test]
    fn the_line_noise_scale_is_the_windowed_estimator_s() {
        use rand::{Rng, SeedableRng};
        let (n, fs, sigma) = (4000, 4096.0, 0.3);
        let theta: Vec<f64> = (0..n).map(|i| 0.013 * i as f64).collect();
        let mut windows = HannWindows::default();
        let window = windows.of(n).0.to_vec();
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let normal = rand_distr::Normal::new(0.0, sigma).unwrap();
        let (mut sum, trials) = (0.0, 400);
        let mut scale = 0.0;
        for _ in 0..trials {
            let x: Vec<f64> = (0..n).map(|_| rng.sample(normal)).collect();
            let (lines, s) = angle_locked_lines(&x, &theta, &[6], &window, fs);
            sum += lines[0].norm_sqr();
            scale = s;
        }
        let density = 2.0 * sigma * sigma / fs;
        let ratio = sum / trials as f64 / (density * scale);
        assert!((ratio - 1.0).abs() < 0.15, "mean line power / (density x scale) = {ratio}");
        assert!((scale - 3.0 * fs / n as f64).abs() < 1e-3 * scale, "Hann: 3 fs / n, got {scale}");
    }
}
