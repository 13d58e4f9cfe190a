//! The gap measure: how far a simulation's spectra lie from a recording's,
//! without asking the phase of a vibration to match.
//!
//! For every cell (channel, travel phase, third-octave band) present in
//! both, `d = 10 log10(P_measured / (P_simulated + N))` in dB, with `N` the
//! measured channel's noise density (the simulation has no sensor noise).
//! The gap of a recording is the RMS of `d` over its cells, every channel
//! weighted alike, in dB. A perfect model still leaves the scatter of the
//! measured estimate: a cell averaging `K` bins and segments with signal
//! power `S` and noise `N` has a log standard deviation of about
//! `4.34 / sqrt(K) * sqrt(N (2 S + N)) / (S + N)` dB; the RMS of that over
//! the cells is the noise gap. A cell counts towards the excess gap only
//! where `d` lies beyond its noise bound plus a tolerance. A band averages
//! many estimates and its bound is `2 sigma`. A line (the angle-locked
//! amplitude over the constant-speed stage) is a single estimate, whose
//! law is far from log-normal: in noise it reads below a fiftieth of its
//! mean one time in fifty, which `2 sigma` counted as a gap of 8 dB and
//! more. Its bound is how far towards the model the signal powers its
//! reading allows reach (the noncentral chi-square law of two degrees of
//! freedom, [`dsp::chi_square`], at the level `1 - 2 NOISE_TAIL`, two normal
//! standard deviations). Reports give the gap, the noise gap and the excess.

use super::signals::{Channel, Phase};
use super::spectra::{Bands, CellKey, CellPowers};
use dsp::signal_power_limit;
use std::cell::RefCell;
use std::collections::HashMap;

/// Dynamic range of the comparison: a floor this far below the channel's
/// strongest measured cell (-80 dB) is added to both sides of every cell,
/// so that content a data-acquisition system would not resolve (and
/// integration details of the model far below the signal) does not count.
const FLOOR: f64 = 1e-8;

/// One cell's comparison.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CellGap {
    /// Channel.
    pub channel: Channel,
    /// Travel phase.
    pub phase: Phase,
    /// Band index.
    pub band: usize,
    /// Measured density, unit^2/Hz.
    pub measured: f64,
    /// Simulated density plus the measured noise density, unit^2/Hz.
    pub simulated: f64,
    /// `10 log10(measured / simulated)`, dB.
    pub d_db: f64,
    /// Expected scatter of `d` from the measurement's own noise, dB.
    pub noise_db: f64,
    /// How far towards zero the measured power's noise lets `d` reach, dB:
    /// for a band twice its noise scatter, for a line (a single estimate)
    /// from the reading to the end, on the model's side, of the interval of
    /// signal powers it allows at the level `1 - 2 NOISE_TAIL` (the
    /// noncentral chi-square law of two degrees of freedom); 0 where `|d|`
    /// is within the tolerance (the cell counts nothing whatever the bound).
    pub noise_bound_db: f64,
    /// The model's reproducibility in this cell, dB.
    pub tolerance_db: f64,
}

impl CellGap {
    /// How far `|d|` lies beyond its noise bound and the model's
    /// reproducibility, dB (0 inside them).
    pub fn beyond_db(&self) -> f64 {
        (self.d_db.abs() - self.noise_bound_db - self.tolerance_db).max(0.0)
    }

    /// [`CellGap::beyond_db`] with the sign of `d`, dB.
    pub fn signed_beyond_db(&self) -> f64 {
        self.d_db.signum() * self.beyond_db()
    }
}

/// The chance that noise alone puts a cell's `d` below its interval, and
/// above it: the normal law's tail beyond two standard deviations.
pub const NOISE_TAIL: f64 = 0.022_750_131_948_179_2;

/// Fewest recordings in which a cell must lie beyond noise and tolerance to
/// be persistent.
pub const PERSISTENT_MIN_RECORDINGS: usize = 3;

/// Largest chance (family-wise over the dataset's cells) that cells beyond
/// noise and tolerance at the dataset's own rate would put one cell beyond
/// in as many recordings, for that cell to be persistent.
pub const PERSISTENT_CHANCE: f64 = 0.01;

/// A cell (channel, phase, band or line) that lies beyond noise and
/// tolerance in every recording that has it: a gap confined to one band or
/// one line, which the mean over all cells dilutes (a once-per-revolution
/// line moves one cell of the hundred and fifty of a travel).
#[derive(Clone, Debug, serde::Serialize)]
pub struct PersistentCell {
    /// Channel.
    pub channel: Channel,
    /// Travel phase (or `decay`).
    pub phase: Phase,
    /// Band (`lo-hi Hz`) or line (`order n`).
    pub band: String,
    /// Recordings that have the cell, every one beyond noise and tolerance.
    pub recordings: usize,
    /// RMS over those recordings of [`CellGap::beyond_db`], dB.
    pub rms_beyond_db: f64,
    /// Chance that cells beyond at the dataset's rate put one of its cells
    /// beyond in every recording, family-wise over the cells (Bonferroni).
    pub chance: f64,
}

/// The persistent cell with the largest RMS beyond noise and tolerance, if
/// any: among `per_recording` (each recording's cells), a cell beyond in
/// every one of at least [`PERSISTENT_MIN_RECORDINGS`] recordings, which
/// cells beyond at the dataset's own rate `q` (the share of all its cells
/// beyond) do with a chance `q^n` per cell, at most [`PERSISTENT_CHANCE`]
/// over all cells.
pub fn persistent_cell(per_recording: &[Vec<CellGap>], bands: &Bands) -> Option<PersistentCell> {
    let mut by_key: Vec<(CellKey, Vec<f64>)> = Vec::new();
    for c in per_recording.iter().flatten() {
        let key = (c.channel, c.phase, c.band);
        match by_key.binary_search_by(|(k, _)| k.cmp(&key)) {
            Ok(i) => by_key[i].1.push(c.beyond_db()),
            Err(i) => by_key.insert(i, (key, vec![c.beyond_db()])),
        }
    }
    let cells = by_key.iter().map(|(_, b)| b.len()).sum::<usize>();
    let beyond = by_key.iter().flat_map(|(_, b)| b).filter(|b| **b > 0.0).count();
    let rate = beyond as f64 / cells.max(1) as f64;
    let keys = by_key.len() as f64;
    by_key
        .into_iter()
        .filter_map(|((channel, phase, band), beyond)| {
            let recordings = beyond.len();
            let chance = keys * rate.powi(recordings as i32);
            let persistent = recordings >= PERSISTENT_MIN_RECORDINGS
                && beyond.iter().all(|b| *b > 0.0)
                && chance <= PERSISTENT_CHANCE;
            let rms_beyond_db = (beyond.iter().map(|b| b * b).sum::<f64>() / recordings as f64).sqrt();
            persistent.then(|| PersistentCell {
                channel,
                phase,
                band: bands.label(band),
                recordings,
                rms_beyond_db,
                chance,
            })
        })
        .max_by(|a, b| a.rms_beyond_db.total_cmp(&b.rms_beyond_db))
}

/// How far (dB) a cell may stray beyond twice its noise scatter before it
/// counts, at least: the model's reproducibility on data from the same
/// model. Cells whose content hangs on details the calibration cannot pin
/// down get more: 1.5 times the change the model shows there when its
/// calibrated parameters move by their uncertainty (the ringing after the
/// brake sets moves by several dB when the drive's stop sequence shifts by
/// one control period).
pub const TOLERANCE_DB: f64 = 0.5;

/// Tolerance of every cell, dB, sorted by cell.
pub type Tolerances = Vec<(CellKey, f64)>;

fn tolerance_of(tolerances: &Tolerances, key: CellKey) -> f64 {
    tolerances.binary_search_by(|(k, _)| k.cmp(&key)).map_or(TOLERANCE_DB, |i| tolerances[i].1)
}

/// The tolerances from the nominal model and the same with its calibrated
/// parameters perturbed by their uncertainty (`perturbed`, up and down),
/// against the measured noise and floor.
pub fn tolerances(
    measured: &CellPowers,
    noise: &[(Channel, f64)],
    nominal: &CellPowers,
    perturbed: &[CellPowers],
) -> Tolerances {
    let floors = channel_floors(measured);
    let mut out = Vec::new();
    for (key, (p_nominal, _, scale)) in &nominal.cells {
        let floor = floors.iter().find(|(c, _)| *c == key.0).map_or(1e-30, |(_, f)| *f) * scale;
        let n = noise.iter().find(|(c, _)| *c == key.0).map_or(0.0, |(_, n)| *n) * scale;
        let change = perturbed
            .iter()
            .filter_map(|p| p.get(*key))
            .map(|(q, _, _)| (10.0 * ((q + n + floor) / (p_nominal + n + floor)).log10()).abs())
            .fold(0.0, f64::max);
        out.push((*key, TOLERANCE_DB.max(1.5 * change)));
    }
    out.sort_by_key(|a| a.0);
    out
}

/// The gap of one recording.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct GapValue {
    /// RMS of `d` over the cells, dB.
    pub gap_db: f64,
    /// RMS of the expected scatter from noise, dB.
    pub noise_db: f64,
    /// RMS over the cells of `max(|d| - 2 sigma - tolerance, 0)`: the gap
    /// beyond what noise and the model's reproducibility explain, dB.
    pub beyond_db: f64,
}

impl GapValue {
    /// The gap beyond noise and tolerance ([`GapValue::beyond_db`]), dB:
    /// the figure the verdict and the attribution use.
    pub fn excess_db(&self) -> f64 {
        self.beyond_db
    }
}

/// One cell's `d`, its noise scatter `sigma` (dB) and its noise bound
/// ([`CellGap::noise_bound_db`], computed only where `|d|` exceeds
/// `tolerance`). A band's averages count as `0.6 K` independent estimates
/// (the Hann segments' overlap), its bound is `2 sigma`. A single estimate
/// (a line) takes the signal powers its measured power allows
/// ([`dsp::chi_square::signal_power_interval`] at [`NOISE_TAIL`]) and how
/// far from the reading towards the model's power that interval reaches.
fn cell(measured: f64, averages: f64, simulated: f64, noise: f64, floor: f64, tolerance: f64) -> (f64, f64, f64) {
    let sim = simulated + noise;
    let d = 10.0 * ((measured + floor) / (sim + floor)).log10();
    let s = (measured - noise).max(0.0);
    let effective = if averages > 1.0 { 0.6 * averages } else { 1.0 };
    let sigma = 4.34 / effective.sqrt() * (noise * (2.0 * s + noise)).sqrt() / (s + noise + floor);
    let bound = if d.abs() <= tolerance {
        0.0
    } else if averages > 1.0 {
        // Averaged: the law is near log-normal, the interval +-2 sigma.
        2.0 * sigma
    } else {
        // Below the model the interval's upper end, above it the lower.
        let quantile = if d < 0.0 { NOISE_TAIL } else { 1.0 - NOISE_TAIL };
        let end = line_power_limit(measured, noise, quantile);
        (10.0 * ((end + noise + floor) / (measured + floor)).log10()).abs()
    };
    (d, sigma, bound)
}

/// [`signal_power_limit`] of a line (one estimate) read at `measured`
/// (unit^2) in noise `noise` (unit^2) at `quantile`: a function of the
/// measured cell alone, which a fit asks for at every trial of the model,
/// so each thread keeps the values it has worked out (the same values, to
/// the bit; the memory is let go past [`LINE_LIMITS_KEPT`] of them).
fn line_power_limit(measured: f64, noise: f64, quantile: f64) -> f64 {
    thread_local! {
        static KEPT: RefCell<HashMap<[u64; 3], f64>> = RefCell::new(HashMap::new());
    }
    let key = [measured.to_bits(), noise.to_bits(), quantile.to_bits()];
    if let Some(limit) = KEPT.with(|kept| kept.borrow().get(&key).copied()) {
        return limit;
    }
    let limit = signal_power_limit(measured, noise, 1.0, quantile);
    KEPT.with(|kept| {
        let mut kept = kept.borrow_mut();
        if kept.len() >= LINE_LIMITS_KEPT {
            kept.clear();
        }
        kept.insert(key, limit);
    });
    limit
}

/// Most line limits a thread keeps ([`line_power_limit`]): a dataset's
/// line cells times their two quantiles, many times over.
const LINE_LIMITS_KEPT: usize = 1 << 16;

fn channel_floors(measured: &CellPowers) -> Vec<(Channel, f64)> {
    let mut out: Vec<(Channel, f64)> = Vec::new();
    for ((channel, _, _), (p, _, scale)) in &measured.cells {
        if *scale != 1.0 {
            continue;
        }
        match out.iter_mut().find(|(c, _)| c == channel) {
            Some(e) => e.1 = e.1.max(*p),
            None => out.push((*channel, *p)),
        }
    }
    out.into_iter().map(|(c, max)| (c, FLOOR * max + 1e-30)).collect()
}

/// Every cell's comparison between `measured` (with its noise densities in
/// `noise`) and `simulated`.
pub fn cell_gaps(
    measured: &CellPowers,
    noise: &[(Channel, f64)],
    tolerances: &Tolerances,
    simulated: &CellPowers,
) -> Vec<CellGap> {
    let floors = channel_floors(measured);
    let mut out = Vec::new();
    for ((channel, phase, band), (p, k, scale)) in &measured.cells {
        let Some((q, _, _)) = simulated.get((*channel, *phase, *band)) else { continue };
        let floor = floors.iter().find(|(c, _)| c == channel).map_or(1e-30, |(_, f)| *f) * scale;
        let n = noise.iter().find(|(c, _)| c == channel).map_or(0.0, |(_, n)| *n) * scale;
        let tolerance_db = tolerance_of(tolerances, (*channel, *phase, *band));
        let (d, sigma, bound) = cell(*p, *k, q, n, floor, tolerance_db);
        out.push(CellGap {
            channel: *channel,
            phase: *phase,
            band: *band,
            measured: *p,
            simulated: q + n,
            d_db: d,
            noise_db: sigma,
            noise_bound_db: bound,
            tolerance_db,
        });
    }
    out
}

/// The gap over `cells`, every channel weighted alike.
pub fn gap_of_cells<'a>(cells: impl Iterator<Item = &'a CellGap>) -> GapValue {
    let mut per: Vec<(Channel, [f64; 3], usize)> = Vec::new();
    for c in cells {
        let beyond = c.beyond_db();
        let add = [c.d_db * c.d_db, c.noise_db * c.noise_db, beyond * beyond];
        match per.iter_mut().find(|(ch, ..)| *ch == c.channel) {
            Some(e) => {
                for (sum, a) in e.1.iter_mut().zip(add) {
                    *sum += a;
                }
                e.2 += 1;
            }
            None => per.push((c.channel, add, 1)),
        }
    }
    if per.is_empty() {
        return GapValue::default();
    }
    let m = per.len() as f64;
    let mean = |k: usize| (per.iter().map(|(_, s, n)| s[k] / *n as f64).sum::<f64>() / m).sqrt();
    GapValue { gap_db: mean(0), noise_db: mean(1), beyond_db: mean(2) }
}

/// The gap between `measured` and `simulated` (see the module docs).
pub fn gap(
    measured: &CellPowers,
    noise: &[(Channel, f64)],
    tolerances: &Tolerances,
    simulated: &CellPowers,
) -> GapValue {
    gap_of_cells(cell_gaps(measured, noise, tolerances, simulated).iter())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A line's limit read again is the one worked out, to the bit, and
    /// each reading's own (the measured power, the noise and the
    /// quantile all count).
    #[test]
    fn kept_line_limits_are_the_worked_out_ones() {
        for round in 0..2 {
            for (p, n) in [(1e-3, 1e-4), (1e-3, 2e-4), (2e-3, 1e-4), (5e-6, 1e-6)] {
                for q in [NOISE_TAIL, 1.0 - NOISE_TAIL] {
                    assert_eq!(line_power_limit(p, n, q), signal_power_limit(p, n, 1.0, q), "round {round}");
                }
            }
        }
    }

    #[test]
    fn a_cell_of_pure_noise_scatters_by_the_chi_square_law() {
        // Signal-free cell: sigma = 4.34 / sqrt(0.6 K).
        let (d, s, _) = cell(1.0, 100.0, 0.0, 1.0, 1e-30, 0.5);
        assert!(d.abs() < 1e-9);
        assert!((s - 4.34 / 60f64.sqrt()).abs() < 1e-9, "{s}");
        // Signal far above the noise: no scatter, d is the level ratio.
        let (d, s, bound) = cell(1000.0, 100.0, 100.0, 0.0, 1e-30, 0.5);
        assert!((d - 10.0).abs() < 1e-9 && s == 0.0 && bound == 0.0);
    }

    /// Readings of a line whose model is right (a line of power `S` plus
    /// complex Gaussian noise of power `N`) lie beyond their noise bound in
    /// `2 NOISE_TAIL` of the draws (`NOISE_TAIL` without signal: a reading
    /// too low for pure noise allows no signal, which is the model's), from
    /// pure noise to a line well above it; the symmetric `+-2 sigma` in dB
    /// puts a noise-dominated line's readings beyond three times as often.
    #[test]
    fn readings_of_a_right_line_lie_beyond_their_bound_at_the_tails_rate() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let normal = rand_distr::Normal::new(0.0, 1.0).unwrap();
        let (trials, n) = (10_000, 1.0);
        for s in [0.0f64, 0.15, 3.0, 30.0] {
            let (mut beyond, mut beyond_sigma) = (0, 0);
            for _ in 0..trials {
                let (re, im): (f64, f64) = (rng.sample(normal), rng.sample(normal));
                let p = (s.sqrt() + re * (n / 2.0f64).sqrt()).powi(2) + im * im * n / 2.0;
                let (d, sigma, bound) = cell(p, 1.0, s, n, 1e-30, 0.0);
                beyond += usize::from(d.abs() > bound + 1e-9);
                beyond_sigma += usize::from(d.abs() > 2.0 * sigma);
            }
            let rate = beyond as f64 / trials as f64;
            let expected = if s == 0.0 { NOISE_TAIL } else { 2.0 * NOISE_TAIL };
            assert!((rate - expected).abs() < 0.012, "S/N {s}: {rate}");
            if s == 0.15 {
                assert!(beyond_sigma as f64 / trials as f64 > 3.0 * 2.0 * NOISE_TAIL, "{beyond_sigma}");
            }
        }
    }

    fn car_cell(band: usize, d_db: f64) -> CellGap {
        CellGap {
            channel: Channel::CarAcceleration,
            phase: Phase::Constant,
            band,
            measured: 1.0,
            simulated: 1.0,
            d_db,
            noise_db: 0.25,
            noise_bound_db: 0.5,
            tolerance_db: 0.5,
        }
    }

    #[test]
    fn a_cell_beyond_in_every_recording_is_persistent_unless_chance_explains_it() {
        let bands = Bands::new(4096.0, 4096, Vec::new());
        // Band 1 beyond (|d| - 2 sigma - tolerance = 2 dB) in all four
        // recordings, with either sign; band 2 in three of four; forty
        // cells inside.
        let d1 = [3.0, -3.0, 3.0, 3.0];
        let d2 = [3.0, 3.0, 3.0, 0.0];
        let recording = |r: usize| {
            let mut cells = vec![car_cell(1, d1[r]), car_cell(2, d2[r])];
            cells.extend((3..43).map(|b| car_cell(b, 0.1)));
            cells
        };
        let recordings: Vec<Vec<CellGap>> = (0..4).map(recording).collect();
        let p = persistent_cell(&recordings, &bands).expect("band 1 is persistent");
        assert_eq!((p.band.as_str(), p.recordings), (bands.label(1).as_str(), 4));
        assert!((p.rms_beyond_db - 2.0).abs() < 1e-12, "{}", p.rms_beyond_db);
        // 7 of 168 cells beyond: 42 (7/168)^4 = 1.3e-4.
        assert!((p.chance - 42.0 * (7.0f64 / 168.0).powi(4)).abs() < 1e-12, "{}", p.chance);
        // Two recordings: too few. Four, but a tenth of all cells beyond:
        // chance explains it.
        assert!(persistent_cell(&recordings[..2], &bands).is_none());
        let crowded: Vec<Vec<CellGap>> = (0..4)
            .map(|r| recording(r).into_iter().map(|c| car_cell(c.band, 3.0 * c.d_db.signum())).collect())
            .collect();
        assert!(persistent_cell(&crowded, &bands).is_none());
    }
}
