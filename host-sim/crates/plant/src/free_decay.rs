//! The free-decay test of the paper (section 3.4, Eqn 9): a mass hanging
//! from a rope whose top end is fixed, machine not running. The rope is
//! discretised into `elements` lumped segments (springs `EA n / l`, node
//! masses `mu l / n`, half at the end node, which also carries the hanging
//! mass); guide damping acts on the mass. The mass is held displaced by a
//! static force and released at `t = 0`; its acceleration is what the
//! accelerometer records. With many elements the first natural frequency
//! tends to the continuous rope's, the root of Eqn 9.

use super::effects::tension_stiffening::{static_tension_n, StiffeningSegment};
use super::effects::{Effects, TensionStiffening};
use super::spring_line::{self, NodeForce};
use super::step_rates::{StepRates, STABLE_RATE_PER_STEP};
use super::Rk4;

/// One free-decay test.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FreeDecaySpec {
    /// Hanging mass, kg.
    pub mass_kg: f64,
    /// Rope length from the fixed end to the mass, m.
    pub rope_length_m: f64,
    /// Rope axial stiffness `EA`, N.
    pub rope_ea_n: f64,
    /// Rope mass per length `mu`, kg/m.
    pub rope_mass_per_length_kg_per_m: f64,
    /// Viscous damping on the mass (guide shoes), kg/s.
    pub damping_kg_per_s: f64,
    /// Initial acceleration of the mass at release, m/s^2 (sets the static force).
    pub initial_acceleration_mps2: f64,
    /// Number of rope elements.
    pub elements: usize,
}

/// Largest number of rope elements accepted.
pub const MAX_ELEMENTS: usize = 400;

/// Why a free decay cannot be simulated.
#[derive(Debug, thiserror::Error)]
pub enum FreeDecayError {
    /// A parameter outside its range.
    #[error("free decay: `{name}` = {value} is out of range: expected {expected}")]
    OutOfRange {
        /// Parameter.
        name: &'static str,
        /// Value given.
        value: f64,
        /// Accepted range.
        expected: &'static str,
    },
}

fn check(name: &'static str, value: f64, ok: bool, expected: &'static str) -> Result<(), FreeDecayError> {
    if ok && value.is_finite() {
        Ok(())
    } else {
        Err(FreeDecayError::OutOfRange { name, value, expected })
    }
}

/// Simulates `duration_s` seconds sampled at `sample_rate_hz`; returns the
/// acceleration of the mass, m/s^2 (positive up; the release is downward-first).
pub fn simulate_free_decay(
    spec: &FreeDecaySpec,
    sample_rate_hz: f64,
    duration_s: f64,
) -> Result<Vec<f64>, FreeDecayError> {
    simulate_free_decay_with(spec, &Effects::none(), sample_rate_hz, duration_s)
}

/// [`simulate_free_decay`] with the library's `effects` that apply to a
/// mass hanging on a rope with a fixed top:
///
/// - `tension_stiffening`: each rope spring's EA follows its instantaneous
///   tension (`TensionStiffening::tension_change_n`), from its static
///   tension `(m + mu l_below) g` with `l_below` the rope below the middle
///   of the spring's segment (`spec.rope_ea_n` is `EA0`, gravity 9.81
///   m/s^2): a release from a millimetre swings the tension by about the
///   static one, so the spring is far from linear;
/// - `car_frame_mode`: the hanging mass is split like the car, a hitch
///   `(1 - beta) m` on the rope (which carries the guide damping and
///   friction) and a body `beta m` on the frame spring and damper, which
///   carries the accelerometer; the static force of the release is spread
///   over both in proportion to their masses, so that they start with the
///   same acceleration;
/// - `coulomb_guide_friction` (and any effect acting at the guides):
///   `-F tanh(v / v_slip)` on the mass (hitch).
///
/// The other effects concern the sheave, the pulley, the travel's rope
/// discretisation (the decay has its own `spec.elements`), the brake, the
/// inverter or the drive's sensors, none of which a free decay has: they
/// are ignored. With none of the three the result is
/// [`simulate_free_decay`]'s, bit for bit.
pub fn simulate_free_decay_with(
    spec: &FreeDecaySpec,
    effects: &Effects,
    sample_rate_hz: f64,
    duration_s: f64,
) -> Result<Vec<f64>, FreeDecayError> {
    simulate_free_decay_stepped(spec, effects, sample_rate_hz, duration_s, StepRates::uniform(RATE_PER_STEP))
}

/// Largest product of [`simulate_free_decay_with`]'s RK4 step and the
/// chain's highest rate (its Gershgorin bound `w_max`, rad/s).
pub const RATE_PER_STEP: f64 = 1.0;

/// [`simulate_free_decay_with`] with RK4 steps split as `rates` ask for
/// the chain's highest rate `w_max` (its Gershgorin bound, rad/s):
/// [`StepRates::within_bands`] for every rate up to the bands' top,
/// [`StepRates::highest`] (at most [`STABLE_RATE_PER_STEP`]) for `w_max`.
/// The highest rates are the discretised rope's own top modes (kilohertz,
/// an artefact of its elements): a longer step there damps them numerically
/// and leaves the modes far below them as they are (`tests`: the response
/// below 1 kHz within 1e-4 of a uniform step sixteen times shorter than
/// the highest rate's).
pub fn simulate_free_decay_stepped(
    spec: &FreeDecaySpec,
    effects: &Effects,
    sample_rate_hz: f64,
    duration_s: f64,
    rates: StepRates,
) -> Result<Vec<f64>, FreeDecayError> {
    check_spec(spec)?;
    check("sample_rate_hz", sample_rate_hz, sample_rate_hz > 0.0, "> 0 Hz")?;
    check("duration_s", duration_s, duration_s > 0.0 && duration_s * sample_rate_hz < 1.0e8, "> 0 s, < 1e8 samples")?;
    let stable = |r: f64| r > 0.0 && r <= STABLE_RATE_PER_STEP;
    check("rates.within_bands", rates.within_bands, stable(rates.within_bands), "in (0, 2.5]")?;
    check("rates.highest", rates.highest, stable(rates.highest), "in (0, 2.5]")?;
    check("rates.band_top_hz", rates.band_top_hz, rates.band_top_hz > 0.0, "> 0 Hz")?;
    let chain = DecayChain::new(spec, effects);
    let substeps = rates.steps(chain.w_max(spec), 1.0 / sample_rate_hz);
    let h = 1.0 / sample_rate_hz / substeps as f64;
    let mut state = chain.released_state(spec);
    let nodes = chain.nodes;
    let samples = (duration_s * sample_rate_hz).round() as usize;
    let mut record = Vec::with_capacity(samples);
    let mut accel = vec![0.0; nodes];
    let mut rk4 = Rk4::new();
    for _ in 0..samples {
        chain.acceleration(&state, &mut accel);
        record.push(accel[nodes - 1]);
        for j in 0..substeps {
            // The first step starts where the sample's accelerations were taken.
            let first = (j == 0).then_some(&accel[..]);
            rk4.step_second_order(&mut state, h, first, |y, acc| chain.acceleration(y, acc));
        }
    }
    Ok(record)
}

/// The spec's ranges (the sampling's are checked by the caller).
fn check_spec(spec: &FreeDecaySpec) -> Result<(), FreeDecayError> {
    check("mass_kg", spec.mass_kg, spec.mass_kg > 0.0, "> 0 kg")?;
    check("rope_length_m", spec.rope_length_m, spec.rope_length_m > 0.0, "> 0 m")?;
    check("rope_ea_n", spec.rope_ea_n, spec.rope_ea_n > 0.0, "> 0 N")?;
    let mu = spec.rope_mass_per_length_kg_per_m;
    check("rope_mass_per_length_kg_per_m", mu, mu >= 0.0, ">= 0 kg/m")?;
    check("damping_kg_per_s", spec.damping_kg_per_s, spec.damping_kg_per_s >= 0.0, ">= 0 kg/s")?;
    check("initial_acceleration_mps2", spec.initial_acceleration_mps2, true, "a finite value")?;
    check("elements", spec.elements as f64, (1..=MAX_ELEMENTS).contains(&spec.elements), "1 to 400")
}

/// The decay rig discretised: `n` rope nodes (the last the hitch), then,
/// with the car-frame mode, the body on its frame spring.
struct DecayChain {
    /// Rope nodes.
    n: usize,
    /// All nodes (`n`, or `n + 1` with the frame).
    nodes: usize,
    /// The linear rope's spring, N/m.
    k: f64,
    /// Each rope spring's stiffness, N/m (spring `i` joins node `i - 1`,
    /// the fixed top for `i = 0`, and node `i`).
    springs: Vec<f64>,
    /// The springs between the nodes, N/m (the rope's from its second on,
    /// then the frame's): the kernel's springs of a rope without
    /// stiffening ([`spring_line::linear_accelerations`]).
    kernel_springs: Vec<f64>,
    /// Each spring's static tension, N.
    static_tensions: Vec<f64>,
    /// Under tension stiffening, each spring's law about its static tension.
    segments: Vec<StiffeningSegment>,
    /// Rope segment length, m.
    segment_length: f64,
    /// Node masses, kg.
    masses: Vec<f64>,
    /// `1 / m_i`, 1/kg.
    inv_mass: Vec<f64>,
    /// Viscous damping on each node, kg/s (the guides' on the hitch).
    damping: Vec<f64>,
    /// The body's mass (car-frame mode), kg.
    body_mass: f64,
    /// Frame spring (N/m) and damper (kg/s), zero without the frame.
    k_frame: f64,
    c_frame: f64,
    stiffening: Option<TensionStiffening>,
    frame: bool,
    /// The effects acting at the guides ([`Effects::guide_force_n`]), on
    /// the car only (the counterweight is not in the decay).
    guides: Option<Effects>,
}

impl DecayChain {
    fn new(spec: &FreeDecaySpec, effects: &Effects) -> Self {
        let mu = spec.rope_mass_per_length_kg_per_m;
        // A massless rope is one spring: its inner nodes would have no mass.
        let n = if mu == 0.0 { 1 } else { spec.elements };
        let k = spec.rope_ea_n * n as f64 / spec.rope_length_m;
        let segment_length = spec.rope_length_m / n as f64;
        let stiffening = effects.tension_stiffening;
        // Spring i joins node i - 1 (the fixed top for i = 0) and node i; its
        // static tension (tension stiffening).
        let static_tensions: Vec<f64> = (0..n)
            .map(|i| {
                let below = spec.rope_length_m * (1.0 - (i as f64 + 0.5) / n as f64);
                static_tension_n(spec.mass_kg, mu, below, DECAY_GRAVITY_MPS2)
            })
            .collect();
        let springs: Vec<f64> = match &stiffening {
            None => vec![k; n],
            Some(e) => static_tensions.iter().map(|&t| e.ea_n(spec.rope_ea_n, t) / segment_length).collect(),
        };
        // Under stiffening, each spring's tension follows its instantaneous
        // stretch beyond the static one.
        let segments: Vec<_> = match &stiffening {
            None => Vec::new(),
            Some(e) => static_tensions.iter().map(|&t| e.segment(spec.rope_ea_n, t, segment_length)).collect(),
        };
        let segment = mu * spec.rope_length_m / n as f64;
        let frame = effects.car_frame_mode;
        let (hitch_mass, body_mass) = match &frame {
            None => (spec.mass_kg, 0.0),
            Some(f) => (f.hitch_mass_kg(spec.mass_kg), f.body_mass_kg(spec.mass_kg)),
        };
        let (k_frame, c_frame) = match &frame {
            None => (0.0, 0.0),
            Some(f) => (f.stiffness_n_per_m(spec.mass_kg), f.damping_kg_per_s(spec.mass_kg)),
        };
        let nodes = if frame.is_some() { n + 1 } else { n };
        let mut masses = vec![segment; nodes];
        masses[n - 1] = 0.5 * segment + hitch_mass;
        if frame.is_some() {
            masses[n] = body_mass;
        }
        let inv_mass = masses.iter().map(|m| 1.0 / m).collect();
        let kernel_springs = springs[1..].iter().copied().chain(frame.is_some().then_some(k_frame)).collect();
        let mut damping = vec![0.0; nodes];
        damping[n - 1] = spec.damping_kg_per_s;
        Self {
            n,
            nodes,
            k,
            springs,
            kernel_springs,
            static_tensions,
            segments,
            segment_length,
            masses,
            inv_mass,
            damping,
            body_mass,
            k_frame,
            c_frame,
            stiffening,
            frame: frame.is_some(),
            guides: effects.acts_at_guides().then_some(*effects),
        }
    }

    /// The chain's highest frequency, rad/s, which sets the step:
    /// `h w_max <= 1` by default (RK4 is stable below 2.78 and accurate well
    /// below it; [`simulate_free_decay_stepped`]).
    fn w_max(&self, spec: &FreeDecaySpec) -> f64 {
        let (n, masses) = (self.n, &self.masses);
        let mut k_max = self.springs.iter().copied().fold(0.0f64, f64::max);
        if let Some(e) = &self.stiffening {
            // The stiffest a spring gets: at its static tension plus three
            // times the release force (the swing never exceeds it).
            let swing = 3.0 * (spec.mass_kg * spec.initial_acceleration_mps2).abs();
            let t_max = self.static_tensions.iter().copied().fold(0.0f64, f64::max) + swing;
            k_max = k_max.max(e.ea_n(spec.rope_ea_n, t_max) / self.segment_length);
        }
        let mut w_max = 2.0 * (k_max / masses[..n].iter().copied().fold(f64::INFINITY, f64::min)).sqrt();
        if self.frame {
            let (k_frame, c_frame, body_mass) = (self.k_frame, self.c_frame, self.body_mass);
            w_max = w_max
                .max((2.0 * (k_max + k_frame) / masses[n - 1]).sqrt())
                .max((2.0 * k_frame / body_mass).sqrt())
                .max(2.0 * c_frame / body_mass.min(masses[n - 1]));
        }
        if let Some(g) = &self.guides {
            w_max = w_max.max(g.guide_force_rate_per_s(masses[n - 1]));
        }
        w_max
    }

    /// The state at release: the static deflection under the force
    /// `F0 = m a0` at the mass (`u_i = F0 i / k` for the linear rope), at rest.
    fn released_state(&self, spec: &FreeDecaySpec) -> Vec<f64> {
        let n = self.n;
        let force = spec.mass_kg * spec.initial_acceleration_mps2;
        let mut state = vec![0.0; 2 * self.nodes];
        match &self.stiffening {
            None => {
                for (i, u) in state.iter_mut().take(n).enumerate() {
                    *u = -force * (i + 1) as f64 / self.k;
                }
            }
            Some(_) => {
                let mut u = 0.0;
                for (i, segment) in self.segments.iter().enumerate() {
                    u -= segment.stretch_change_m(force);
                    state[i] = u;
                }
            }
        }
        if self.frame {
            // The body's share of the static force stretches the frame spring.
            state[n] = state[n - 1] - self.body_mass * spec.initial_acceleration_mps2 / self.k_frame;
        }
        state
    }

    /// The nodes' accelerations `out` (m/s^2) at the state `y` (positions
    /// then velocities): the line's forces ([`spring_line::accelerations`];
    /// kernel spring `i` is the rope's spring `i + 1`, the frame spring
    /// last, the top spring's tension on node 0 as a force), the guides
    /// and the frame damper.
    fn acceleration(&self, y: &[f64], out: &mut [f64]) {
        let (n, nodes) = (self.n, self.nodes);
        let (position, velocity) = (&y[..nodes], &y[nodes..2 * nodes]);
        let inv_mass = &self.inv_mass;
        let top = NodeForce { node: 0, force_n: -self.rope_tension_n(0, position[0]) };
        if self.stiffening.is_none() {
            let springs = &self.kernel_springs;
            spring_line::linear_accelerations(springs, &self.damping, inv_mass, position, velocity, &[top], out);
        } else {
            let tension = |i: usize, e: f64| if i + 1 < n { self.rope_tension_n(i + 1, e) } else { self.k_frame * e };
            spring_line::accelerations(tension, &self.damping, inv_mass, position, velocity, &[top], out);
        }
        if let Some(g) = &self.guides {
            spring_line::add_guide_forces(g, &[n - 1], velocity, inv_mass, out);
        }
        if self.frame {
            spring_line::add_damper((n - 1, n), self.c_frame, velocity, inv_mass, out);
        }
    }

    /// The tension (N, beyond the static one) of the rope's spring `i`
    /// (joining node `i - 1`, the fixed top for `i = 0`, and node `i`) at
    /// the extension `e` (m, the lower node's displacement less the
    /// upper's).
    #[inline]
    fn rope_tension_n(&self, i: usize, e: f64) -> f64 {
        if self.stiffening.is_none() {
            self.springs[i] * e
        } else {
            -self.segments[i].tension_change_n(-e)
        }
    }
}

/// Gravity of the decay rig (tension stiffening's static tensions), m/s^2.
pub const DECAY_GRAVITY_MPS2: f64 = 9.81;

/// Eqn 9 for the fundamental: `x tan x = mu l / m` with `x = gamma l` in
/// (0, pi/2), by bisection; returns `gamma l` (dimensionless).
pub fn eqn9_fundamental_gamma_l(rope_mass_kg: f64, hanging_mass_kg: f64) -> f64 {
    let ratio = rope_mass_kg / hanging_mass_kg;
    let (mut lo, mut hi) = (0.0f64, std::f64::consts::FRAC_PI_2);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid * mid.tan() < ratio {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Eqn 9: first natural frequency (Hz) of a rope (`EA`, `mu`, length `l`)
/// fixed at the top with `m` hanging: `f = gamma sqrt(EA/mu) / (2 pi)`.
pub fn eqn9_first_frequency_hz(ea_n: f64, mu_kg_per_m: f64, length_m: f64, mass_kg: f64) -> f64 {
    let gamma = eqn9_fundamental_gamma_l(mu_kg_per_m * length_m, mass_kg) / length_m;
    gamma * (ea_n / mu_kg_per_m).sqrt() / std::f64::consts::TAU
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::TensionStiffening;

    fn spec(initial_acceleration_mps2: f64) -> FreeDecaySpec {
        FreeDecaySpec {
            mass_kg: 33.0,
            rope_length_m: 2.5,
            rope_ea_n: 1.0e6,
            rope_mass_per_length_kg_per_m: 0.0,
            damping_kg_per_s: 20.0,
            initial_acceleration_mps2,
            elements: 1,
        }
    }

    /// Amplitude (m/s^2) of the line at `f_hz` in `x` sampled at `fs`.
    fn line(x: &[f64], fs: f64, f_hz: f64) -> f64 {
        let (mut re, mut im) = (0.0, 0.0);
        let n = x.len() as f64;
        for (k, v) in x.iter().enumerate() {
            let ph = std::f64::consts::TAU * f_hz * k as f64 / fs;
            // Hann window: the decay's leakage stays off the harmonic.
            let w = 0.5 - 0.5 * (std::f64::consts::TAU * k as f64 / n).cos();
            re += w * v * ph.cos();
            im -= w * v * ph.sin();
        }
        2.0 * re.hypot(im) / x.len() as f64
    }

    /// With the reference tension at the static one, a small release gives
    /// the linear chain's decay; a large one (a swing about the static
    /// tension) gives the first mode's second harmonic, which the linear
    /// chain has not.
    #[test]
    fn a_stiffening_rope_is_linear_when_small_and_makes_harmonics_when_large() {
        let fs = 4096.0;
        let t_static = 33.0 * DECAY_GRAVITY_MPS2;
        let mut effects = Effects::none();
        effects.tension_stiffening = Some(TensionStiffening { alpha: 0.45, reference_tension_n: t_static });
        let small = simulate_free_decay_with(&spec(0.01), &effects, fs, 1.0).unwrap();
        let linear = simulate_free_decay(&spec(0.01), fs, 1.0).unwrap();
        let worst = small.iter().zip(&linear).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-4 * 0.01 * 10.0, "small release departs from the linear chain by {worst} m/s^2");
        // First frequency of the single spring: sqrt(k / m) / 2 pi.
        let f1 = (1.0e6 / 2.5 / 33.0f64).sqrt() / std::f64::consts::TAU;
        let second = |x: &[f64]| line(&x[..2048], fs, 2.0 * f1) / line(&x[..2048], fs, f1);
        let large = simulate_free_decay_with(&spec(12.0), &effects, fs, 1.0).unwrap();
        let large_linear = simulate_free_decay(&spec(12.0), fs, 1.0).unwrap();
        assert!(second(&large) > 0.05, "second harmonic {} of the first", second(&large));
        assert!(second(&large) > 10.0 * second(&large_linear), "{} against {}", second(&large), second(&large_linear));
    }

    /// Steps at `h w_max = 2` for the discretised rope's top modes
    /// (kilohertz), which they damp, and `h w <= 0.25` up to 1 kHz leave
    /// the decay's lines where a uniform step sixteen times shorter than
    /// the first puts them: the first mode, its harmonics of the stiffening
    /// rope and the rope's second mode, all below 1 kHz.
    #[test]
    fn a_longer_step_keeps_the_lines_below_a_kilohertz() {
        let fs = 4096.0;
        let mut effects = Effects::none();
        effects.tension_stiffening =
            Some(TensionStiffening { alpha: 0.45, reference_tension_n: 45.5 * DECAY_GRAVITY_MPS2 });
        let spec = FreeDecaySpec {
            mass_kg: 45.5,
            rope_length_m: 4.0,
            rope_mass_per_length_kg_per_m: 0.1,
            elements: 20,
            ..spec(3.0)
        };
        let split = StepRates { within_bands: 0.25, highest: 2.0, band_top_hz: 1000.0 };
        let fine = simulate_free_decay_stepped(&spec, &effects, fs, 0.5, StepRates::uniform(0.125)).unwrap();
        let coarse = simulate_free_decay_stepped(&spec, &effects, fs, 0.5, split).unwrap();
        let f1 = eqn9_first_frequency_hz(spec.rope_ea_n, 0.1, 4.0, 45.5);
        // The rope's second mode: `x tan x = mu l / m` has its next root
        // just above pi, so near `f1 pi / x1` for this light rope.
        let f2 = f1 * std::f64::consts::PI / eqn9_fundamental_gamma_l(0.4, 45.5);
        let first = line(&fine, fs, f1);
        for f in [f1, 2.0 * f1, 3.0 * f1, f2] {
            let (a, b) = (line(&fine, fs, f), line(&coarse, fs, f));
            assert!((a - b).abs() < 1e-4 * first, "{f:.1} Hz: {b} against {a} (first mode {first})");
        }
        let err: f64 = fine.iter().zip(&coarse).map(|(a, b)| (a - b) * (a - b)).sum();
        let power: f64 = fine.iter().map(|a| a * a).sum();
        assert!((err / power).sqrt() < 2e-3, "RMS difference {} of the RMS", (err / power).sqrt());
        // Past RK4's stability the step is refused.
        assert!(simulate_free_decay_stepped(&spec, &effects, fs, 0.5, StepRates::uniform(3.0)).is_err());
        let no_band = StepRates { band_top_hz: 0.0, ..split };
        assert!(simulate_free_decay_stepped(&spec, &effects, fs, 0.5, no_band).is_err());
    }

    /// A decay's samples do not depend on how long it is simulated: the
    /// first second of a three-second decay is the one-second decay, bit
    /// for bit (the diagnosis searches a release level on first seconds).
    #[test]
    fn a_shorter_decay_is_the_longer_ones_beginning() {
        let fs = 4096.0;
        let mut effects = Effects::none();
        effects.tension_stiffening =
            Some(TensionStiffening { alpha: 0.45, reference_tension_n: 33.0 * DECAY_GRAVITY_MPS2 });
        let spec = FreeDecaySpec { elements: 8, rope_mass_per_length_kg_per_m: 0.2, ..spec(12.0) };
        let long = simulate_free_decay_with(&spec, &effects, fs, 3.0).unwrap();
        let short = simulate_free_decay_with(&spec, &effects, fs, 1.0).unwrap();
        assert_eq!(short.len(), 4096);
        assert_eq!(long.len(), 3 * 4096);
        assert!(short.iter().zip(&long).all(|(a, b)| a.to_bits() == b.to_bits()));
        assert!(long[4096..].iter().any(|a| *a != 0.0));
    }
}
