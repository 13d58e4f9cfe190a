//! Another data acquisition: what a rig's own measurement chain does to the
//! signals of the plant before they reach a recording.
//!
//! The plant is simulated at a high "analog" rate
//! ([`Acquisition::analog_rate_hz`]); each channel then goes through:
//!
//! 1. accelerometers only: the high-pass of the piezoelectric sensor and
//!    its charge amplifier, corner [`Acquisition::highpass_hz`], first order
//!    or, with an acquisition's own AC coupling or filter, a second-order
//!    Butterworth ([`Acquisition::highpass_order`]; no DC, content below the
//!    corner attenuated);
//! 2. every channel: the anti-alias low-pass, a Butterworth filter of order
//!    [`Acquisition::antialias_order`] with its corner at
//!    [`Acquisition::antialias_fraction`] times the sample rate (both
//!    filters by the bilinear transform at the analog rate, corners
//!    pre-warped);
//! 3. sampling by the acquisition's own clock, not locked to the drive's
//!    PWM: nominal rate [`Acquisition::sample_rate_hz`] (what the recording
//!    says), true rate off by [`Acquisition::clock_offset_ppm`]; the
//!    filtered analog signal is read at those instants by cubic (Catmull-Rom)
//!    interpolation;
//! 4. white Gaussian noise on the accelerometer and current channels;
//! 5. current channels: quantisation by an ADC of
//!    [`Acquisition::current_bits`] over `+-`[`Acquisition::current_full_scale_a`]
//!    (values clipped to its range).
//!
//! The phase currents recorded are the machine's true currents (independent
//! clamps) or, with [`Acquisition::drive_transducer_currents`], the drive's
//! own transducer signals: the currents it senses and regulates, which
//! differ from the true ones by the plant's `current_sensor_error`.
//!
//! The drive's own signals (speed estimate, encoder angle, reference speed)
//! go through steps 2 and 3 only. A recording starts
//! [`Acquisition::pre_trigger_s`] before its trigger (travels: the start of
//! the motion; free decays: the release) and lasts [`Acquisition::duration_s`]
//! (or an automatic length).

use rand::Rng;
use rand_distr::{Distribution, Normal};

use super::params::{foreign_params, ParamKind};

foreign_params! {
    /// Parameters of a foreign data acquisition, with units, defaults and
    /// ranges ([`Acquisition::PARAMS`]); also the timing of a recording and
    /// how a free decay is started.
    pub struct Acquisition in "acquisition" {
        /// Nominal sample rate of the recordings (what their metadata says), Hz.
        sample_rate_hz: f64 = 4096.0, [1000.0, 25600.0], "Hz",
            ParamKind::Choice(&[4096.0, 5000.0, 8192.0, 10000.0, 12800.0, 16384.0]);
        /// Error of the acquisition's sample clock, ppm (positive: it runs fast, its samples are closer in true time).
        clock_offset_ppm: f64 = 0.0, [-200.0, 200.0], "ppm", ParamKind::Real;
        /// Corner of the accelerometers' high-pass (sensor and charge amplifier, or the acquisition's AC coupling: `highpass_order`), Hz.
        highpass_hz: f64 = 0.5, [0.2, 1.0], "Hz", ParamKind::Real;
        /// Order of the accelerometers' high-pass: 1 (sensor and charge amplifier) or 2 (Butterworth, an acquisition's AC coupling); drawn 1 or 2 with equal probability, after the other parameters.
        highpass_order: u32 = 1.0, [1.0, 2.0], "-", ParamKind::DrawnLast(&ParamKind::IntegerChoice(&[1.0, 2.0]));
        /// Corner of the anti-alias low-pass as a fraction of the sample rate.
        antialias_fraction: f64 = 0.4, [0.2, 0.45], "-", ParamKind::Real;
        /// Order of the anti-alias Butterworth low-pass.
        antialias_order: u32 = 4.0, [1.0, 8.0], "-", ParamKind::IntegerChoice(&[4.0, 6.0, 8.0]);
        /// RMS white noise on every accelerometer channel, m/s^2.
        acc_noise_mps2: f64 = 0.005, [0.0, 0.03], "m/s^2", ParamKind::Real;
        /// RMS white noise on every current channel before quantisation, A.
        current_noise_a: f64 = 0.01, [0.0, 0.1], "A", ParamKind::Real;
        /// Resolution of the current channels' ADC, bits.
        current_bits: u32 = 12.0, [8.0, 16.0], "bit", ParamKind::IntegerChoice(&[12.0, 14.0, 16.0]);
        /// Full scale of the current channels, +- A.
        current_full_scale_a: f64 = 50.0, [25.0, 100.0], "A", ParamKind::Choice(&[25.0, 50.0, 100.0]);
        /// Recorded before the trigger (travels: the start of the motion; free decays: the release), s.
        pre_trigger_s: f64 = 0.5, [0.0, 2.0], "s", ParamKind::Real;
        /// Length of every recording, s; 0: automatic (travels: to 1 s after the drive switches off; free decays: the dataset's decay duration after the release).
        duration_s: f64 = 0.0, [0.0, 120.0], "s", ParamKind::Fixed;
        /// Free decays: acceleration of the mass just after its release (sets how far it is held), m/s^2.
        release_acceleration_mps2: f64 = 2.0, [0.5, 4.0], "m/s^2", ParamKind::Real;
        /// Which phase currents are recorded: 0 (off) the machine's true currents, as independent clamps measure them; 1 (on) the drive's own transducer signals, the currents it senses and regulates (a transducer gain or offset error then leaves the recorded currents clean and shows in the mechanics); drawn on with probability 0.5, after the other parameters.
        drive_transducer_currents: bool = 0.0, [0.0, 1.0], "-", ParamKind::DrawnLast(&ParamKind::Switch { p_on: 0.5 });
    }
}

impl super::params::ParamValue for u32 {
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
    fn from_f64(value: f64) -> Self {
        value as u32
    }
}

/// What a channel measures, which sets its processing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Channel {
    /// An accelerometer: high-pass, anti-alias, sampling, noise.
    Accelerometer,
    /// A phase current: anti-alias, sampling, noise, quantisation.
    Current,
    /// A signal of the drive (speed, angle, reference): anti-alias and sampling.
    Drive,
}

/// A signal simulated at a uniform analog rate.
#[derive(Clone, Copy, Debug)]
pub struct AnalogSignal<'a> {
    /// Time of the first value, s.
    pub start_s: f64,
    /// Rate of the values, Hz.
    pub rate_hz: f64,
    /// The values, in the channel's unit.
    pub values: &'a [f64],
}

impl Acquisition {
    /// Rate at which the plant is simulated for this acquisition, Hz: four
    /// times the sample rate rounded up to a power of two, at least 65536
    /// (the plant's content above half of it is negligible).
    pub fn analog_rate_hz(&self) -> f64 {
        (4.0 * self.sample_rate_hz).max(65_536.0).log2().ceil().exp2()
    }

    /// True sample rate of the acquisition's clock, Hz.
    pub fn true_rate_hz(&self) -> f64 {
        self.sample_rate_hz * (1.0 + self.clock_offset_ppm * 1.0e-6)
    }

    /// Number of samples in `duration_s` (s) of true time (at least 1).
    pub fn sample_count(&self, duration_s: f64) -> usize {
        ((duration_s * self.true_rate_hz()).floor() as usize).max(1)
    }

    /// True times (s) of `count` samples, the first at `start_s` (s).
    pub fn sample_instants(&self, start_s: f64, count: usize) -> Vec<f64> {
        let period = 1.0 / self.true_rate_hz();
        (0..count).map(|k| start_s + k as f64 * period).collect()
    }

    /// The nominal time column of `count` samples: `k / sample_rate_hz`, s.
    pub fn time_column(&self, count: usize) -> Vec<f64> {
        (0..count).map(|k| k as f64 / self.sample_rate_hz).collect()
    }

    /// Quantisation step of the current channels, A.
    pub fn current_step_a(&self) -> f64 {
        2.0 * self.current_full_scale_a / (1u64 << self.current_bits.min(62)) as f64
    }

    /// `value` (A) through the current channels' ADC: rounded to a whole
    /// number of steps, clipped to `[-full scale, full scale - step]`.
    pub fn quantise_current_a(&self, value: f64) -> f64 {
        let step = self.current_step_a();
        let half = (1u64 << (self.current_bits.clamp(1, 62) - 1)) as f64;
        (value / step).round().clamp(-half, half - 1.0) * step
    }

    /// The recorded samples of `signal` on channel `channel`: `count`
    /// samples of the acquisition's clock from the true time `start_s` (s),
    /// with the noise drawn from `rng`.
    pub fn record<R: Rng + ?Sized>(
        &self,
        signal: &AnalogSignal<'_>,
        channel: Channel,
        start_s: f64,
        count: usize,
        rng: &mut R,
    ) -> Vec<f64> {
        let fs = signal.rate_hz;
        let mut x = signal.values.to_vec();
        if channel == Channel::Accelerometer {
            if self.highpass_order >= 2 {
                butterworth_highpass2(self.highpass_hz, fs).filter(&mut x);
            } else {
                highpass_first_order(&mut x, self.highpass_hz, fs);
            }
        }
        for section in
            butterworth_lowpass(self.antialias_order as usize, self.antialias_fraction * self.sample_rate_hz, fs)
        {
            section.filter(&mut x);
        }
        let mut out: Vec<f64> =
            self.sample_instants(start_s, count).iter().map(|t| catmull_rom(&x, (t - signal.start_s) * fs)).collect();
        let rms = match channel {
            Channel::Accelerometer => self.acc_noise_mps2,
            Channel::Current => self.current_noise_a,
            Channel::Drive => 0.0,
        };
        if let Ok(normal) = Normal::new(0.0, rms) {
            if rms > 0.0 {
                out.iter_mut().for_each(|v| *v += normal.sample(rng));
            }
        }
        if channel == Channel::Current {
            out.iter_mut().for_each(|v| *v = self.quantise_current_a(*v));
        }
        out
    }
}

/// First-order high-pass `s / (s + wc)` at `corner_hz` (Hz) on samples at
/// `rate_hz` (Hz), in place, by the bilinear transform with the corner
/// pre-warped; the input is taken as constant before its first value (the
/// output starts at 0).
pub fn highpass_first_order(x: &mut [f64], corner_hz: f64, rate_hz: f64) {
    let k = (std::f64::consts::PI * corner_hz / rate_hz).tan();
    let b0 = 1.0 / (1.0 + k);
    let a1 = (k - 1.0) / (k + 1.0);
    let (mut x_prev, mut y_prev) = (x.first().copied().unwrap_or(0.0), 0.0);
    for v in x.iter_mut() {
        let y = b0 * (*v - x_prev) - a1 * y_prev;
        x_prev = *v;
        y_prev = y;
        *v = y;
    }
}

/// Second-order Butterworth high-pass `s^2 / (s^2 + sqrt 2 wc s + wc^2)` at
/// `corner_hz` (Hz) for samples at `rate_hz` (Hz): the bilinear transform
/// with the corner pre-warped.
pub fn butterworth_highpass2(corner_hz: f64, rate_hz: f64) -> Section {
    let k = (std::f64::consts::PI * corner_hz / rate_hz).tan();
    let norm = 1.0 / (1.0 + std::f64::consts::SQRT_2 * k + k * k);
    Section {
        b: [norm, -2.0 * norm, norm],
        a: [2.0 * (k * k - 1.0) * norm, (1.0 - std::f64::consts::SQRT_2 * k + k * k) * norm],
    }
}

/// One second-order (or first-order, `b2 = a2 = 0`) section
/// `(b0 + b1 z^-1 + b2 z^-2) / (1 + a1 z^-1 + a2 z^-2)`, dimensionless.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Section {
    /// Numerator.
    pub b: [f64; 3],
    /// Denominator `a1`, `a2` (`a0 = 1`).
    pub a: [f64; 2],
}

impl Section {
    /// Filters `x` in place (transposed direct form II), the state set as if
    /// the input had been constant at its first value forever.
    pub fn filter(&self, x: &mut [f64]) {
        let [b0, b1, b2] = self.b;
        let [a1, a2] = self.a;
        let u = x.first().copied().unwrap_or(0.0);
        let gain = (b0 + b1 + b2) / (1.0 + a1 + a2);
        let mut s2 = (b2 - a2 * gain) * u;
        let mut s1 = (b1 - a1 * gain) * u + s2;
        for v in x.iter_mut() {
            let y = b0 * *v + s1;
            s1 = b1 * *v - a1 * y + s2;
            s2 = b2 * *v - a2 * y;
            *v = y;
        }
    }
}

/// Sections of a Butterworth low-pass of `order` (>= 1) with its -3 dB
/// corner at `corner_hz` (Hz), for samples at `rate_hz` (Hz): the bilinear
/// transform with the corner pre-warped, one second-order section per pair
/// of poles (`Q = 1 / (2 sin((2k - 1) pi / (2n)))`) and a first-order one
/// for an odd order.
pub fn butterworth_lowpass(order: usize, corner_hz: f64, rate_hz: f64) -> Vec<Section> {
    let k = (std::f64::consts::PI * corner_hz / rate_hz).tan();
    let n = order.max(1);
    let mut sections: Vec<Section> = (1..=n / 2)
        .map(|i| {
            let q = 1.0 / (2.0 * ((2 * i - 1) as f64 * std::f64::consts::PI / (2 * n) as f64).sin());
            let norm = 1.0 / (1.0 + k / q + k * k);
            let b0 = k * k * norm;
            Section { b: [b0, 2.0 * b0, b0], a: [2.0 * (k * k - 1.0) * norm, (1.0 - k / q + k * k) * norm] }
        })
        .collect();
    if n % 2 == 1 {
        let b0 = k / (1.0 + k);
        sections.push(Section { b: [b0, b0, 0.0], a: [(k - 1.0) / (k + 1.0), 0.0] });
    }
    sections
}

/// `x` read at the fractional index `position` by Catmull-Rom cubic
/// interpolation, the ends held.
pub fn catmull_rom(x: &[f64], position: f64) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    let last = (x.len() - 1) as isize;
    let i = position.floor();
    let f = position - i;
    let at = |j: isize| x[j.clamp(0, last) as usize];
    let i = i as isize;
    let (p0, p1, p2, p3) = (at(i - 1), at(i), at(i + 1), at(i + 2));
    p1 + 0.5 * f * (p2 - p0 + f * (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3 + f * (3.0 * (p1 - p2) + p3 - p0)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Gain of `sections` at `f` (Hz) for samples at `fs` (Hz), from the
    /// transfer function on the unit circle.
    fn gain(sections: &[Section], f: f64, fs: f64) -> f64 {
        let w = std::f64::consts::TAU * f / fs;
        let z = |k: f64| (-(k * w)).sin_cos();
        sections
            .iter()
            .map(|s| {
                let (s1, c1) = z(1.0);
                let (s2, c2) = z(2.0);
                let num = (s.b[0] + s.b[1] * c1 + s.b[2] * c2, s.b[1] * s1 + s.b[2] * s2);
                let den = (1.0 + s.a[0] * c1 + s.a[1] * c2, s.a[0] * s1 + s.a[1] * s2);
                (num.0.hypot(num.1)) / (den.0.hypot(den.1))
            })
            .product()
    }

    #[test]
    fn butterworth_is_flat_then_3_db_down_at_the_corner_then_falls_with_its_order() {
        for order in 1..=8 {
            let s = butterworth_lowpass(order, 1638.4, 65_536.0);
            assert!((gain(&s, 1.0, 65_536.0) - 1.0).abs() < 1e-6);
            assert!((gain(&s, 1638.4, 65_536.0) - 0.5f64.sqrt()).abs() < 1e-9, "order {order}");
            // An octave above: about 6 dB per order (the bilinear transform adds a little).
            let g = gain(&s, 2.0 * 1638.4, 65_536.0);
            let expected = 1.0 / (1.0 + 4f64.powi(order as i32)).sqrt();
            assert!(g <= expected * 1.01 && g > expected * 0.8, "order {order}: {g} vs {expected}");
        }
    }

    #[test]
    fn second_order_high_pass_is_3_db_down_at_its_corner_and_falls_40_db_a_decade() {
        let s = [butterworth_highpass2(1.0, 8192.0)];
        assert!((gain(&s, 1.0, 8192.0) - 0.5f64.sqrt()).abs() < 1e-9);
        assert!((gain(&s, 100.0, 8192.0) - 1.0).abs() < 1e-3);
        // |H| = (f/fc)^2 / sqrt(1 + (f/fc)^4) of the analog filter.
        let g = gain(&s, 0.1, 8192.0);
        assert!((g / (0.01 / (1.0f64 + 1e-4).sqrt()) - 1.0).abs() < 1e-3, "{g}");
    }

    #[test]
    fn high_pass_kills_dc_and_passes_the_band() {
        let fs = 65_536.0;
        let mut x: Vec<f64> =
            (0..(4.0 * fs) as usize).map(|k| 1.0 + (std::f64::consts::TAU * 20.0 * k as f64 / fs).sin()).collect();
        highpass_first_order(&mut x, 0.5, fs);
        let tail = &x[(3.0 * fs) as usize..];
        let mean = tail.iter().sum::<f64>() / tail.len() as f64;
        let peak = tail.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(mean.abs() < 1e-3 && (peak - 1.0).abs() < 2e-3, "{mean} {peak}");
    }

    #[test]
    fn quantiser_steps_and_clips() {
        let a = Acquisition::default();
        assert_eq!(a.current_step_a(), 100.0 / 4096.0);
        assert_eq!(a.quantise_current_a(0.05), 2.0 * 100.0 / 4096.0);
        assert_eq!(a.quantise_current_a(80.0), 2047.0 * 100.0 / 4096.0);
        assert_eq!(a.quantise_current_a(-80.0), -50.0);
        let err = Acquisition::default().set("current_bits", 12.5).unwrap_err().to_string();
        assert!(err.contains("current_bits") && err.contains("whole number in [8, 16]"), "{err}");
    }

    #[test]
    fn catmull_rom_is_exact_on_cubics_inside() {
        let x: Vec<f64> = (0..10).map(|k| (k as f64).powi(2) * 0.5 - k as f64).collect();
        let f = |t: f64| t * t * 0.5 - t;
        for p in [1.0, 2.25, 4.5, 7.75] {
            assert!((catmull_rom(&x, p) - f(p)).abs() < 1e-12, "{p}");
        }
    }

    #[test]
    fn variants_drawn_last_leave_the_other_draws_as_they_were_and_take_both_values() {
        use rand::SeedableRng;
        let mut seen = (Vec::new(), Vec::new());
        for seed in 0..40 {
            let drawn = Acquisition::random(&mut rand::rngs::StdRng::seed_from_u64(seed));
            // The parameters drawn first, one after the other from the same seed.
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            for p in Acquisition::PARAMS.iter().filter(|p| !p.kind.drawn_last()) {
                assert_eq!(drawn.get(p.name), Some(p.draw(&mut rng)), "seed {seed}: {}", p.name);
            }
            seen.0.push(drawn.highpass_order);
            seen.1.push(drawn.drive_transducer_currents);
        }
        assert!(seen.0.contains(&1) && seen.0.contains(&2), "{:?}", seen.0);
        assert!(seen.1.contains(&false) && seen.1.contains(&true), "{:?}", seen.1);
    }

    #[test]
    fn clock_offset_spaces_the_samples_in_true_time() {
        let a = Acquisition { sample_rate_hz: 5000.0, clock_offset_ppm: 100.0, ..Acquisition::default() };
        let t = a.sample_instants(0.25, 5001);
        assert!((t[5000] - t[0] - 1.0 / 1.0001).abs() < 1e-12);
        assert_eq!(a.time_column(3), vec![0.0, 0.0002, 0.0004]);
        assert_eq!(a.analog_rate_hz(), 65_536.0);
        let fast = Acquisition { sample_rate_hz: 25_600.0, ..Acquisition::default() };
        assert_eq!(fast.analog_rate_hz(), 131_072.0);
    }
}
