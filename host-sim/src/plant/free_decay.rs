//! The free-decay test of the paper (section 3.4, Eqn 9): a mass hanging
//! from a rope whose top end is fixed, machine not running. The rope is
//! discretised into `elements` lumped segments (springs `EA n / l`, node
//! masses `mu l / n`, half at the end node, which also carries the hanging
//! mass); guide damping acts on the mass. The mass is held displaced by a
//! static force and released at `t = 0`; its acceleration is what the
//! accelerometer records. With many elements the first natural frequency
//! tends to the continuous rope's, the root of Eqn 9.

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
    check("mass_kg", spec.mass_kg, spec.mass_kg > 0.0, "> 0 kg")?;
    check("rope_length_m", spec.rope_length_m, spec.rope_length_m > 0.0, "> 0 m")?;
    check("rope_ea_n", spec.rope_ea_n, spec.rope_ea_n > 0.0, "> 0 N")?;
    let mu = spec.rope_mass_per_length_kg_per_m;
    check("rope_mass_per_length_kg_per_m", mu, mu >= 0.0, ">= 0 kg/m")?;
    check("damping_kg_per_s", spec.damping_kg_per_s, spec.damping_kg_per_s >= 0.0, ">= 0 kg/s")?;
    check("initial_acceleration_mps2", spec.initial_acceleration_mps2, true, "a finite value")?;
    check("elements", spec.elements as f64, (1..=MAX_ELEMENTS).contains(&spec.elements), "1 to 400")?;
    // A massless rope is one spring: its inner nodes would have no mass.
    let n = if mu == 0.0 { 1 } else { spec.elements };
    check("sample_rate_hz", sample_rate_hz, sample_rate_hz > 0.0, "> 0 Hz")?;
    check("duration_s", duration_s, duration_s > 0.0 && duration_s * sample_rate_hz < 1.0e8, "> 0 s, < 1e8 samples")?;

    let k = spec.rope_ea_n * n as f64 / spec.rope_length_m;
    let segment = mu * spec.rope_length_m / n as f64;
    let mut masses = vec![segment; n];
    masses[n - 1] = 0.5 * segment + spec.mass_kg;
    // The chain's highest frequency sets the step: h w_max <= 1 (RK4 is
    // stable below 2.78 and accurate well below it).
    let w_max = 2.0 * (k / masses.iter().copied().fold(f64::INFINITY, f64::min)).sqrt();
    let substeps = (w_max / sample_rate_hz).ceil().max(1.0) as usize;
    let h = 1.0 / sample_rate_hz / substeps as f64;

    // Static deflection under the force F0 = m a0 at the mass: u_i = F0 i / k.
    let force = spec.mass_kg * spec.initial_acceleration_mps2;
    let mut state = vec![0.0; 2 * n];
    for (i, u) in state.iter_mut().take(n).enumerate() {
        *u = -force * (i + 1) as f64 / k;
    }
    let c = spec.damping_kg_per_s;
    let acceleration = |y: &[f64], out: &mut [f64]| {
        for i in 0..n {
            let below = if i == 0 { 0.0 } else { y[i - 1] };
            let above = if i + 1 < n { y[i + 1] } else { y[i] };
            let mut f = -k * (y[i] - below) + k * (above - y[i]);
            if i == n - 1 {
                f -= c * y[n + i];
            }
            out[i] = f / masses[i];
        }
    };
    let samples = (duration_s * sample_rate_hz).round() as usize;
    let mut record = Vec::with_capacity(samples);
    let mut accel = vec![0.0; n];
    for _ in 0..samples {
        acceleration(&state, &mut accel);
        record.push(accel[n - 1]);
        for _ in 0..substeps {
            state = rk4_vec(&state, h, |y, dy| {
                dy[..n].copy_from_slice(&y[n..]);
                acceleration(y, &mut dy[n..]);
            });
        }
    }
    Ok(record)
}

/// RK4 on a heap state (the chain's length is chosen at run time).
fn rk4_vec(y: &[f64], h: f64, f: impl Fn(&[f64], &mut [f64])) -> Vec<f64> {
    let len = y.len();
    let (mut k1, mut k2, mut k3, mut k4) = (vec![0.0; len], vec![0.0; len], vec![0.0; len], vec![0.0; len]);
    let mut tmp = vec![0.0; len];
    f(y, &mut k1);
    for i in 0..len {
        tmp[i] = y[i] + 0.5 * h * k1[i];
    }
    f(&tmp, &mut k2);
    for i in 0..len {
        tmp[i] = y[i] + 0.5 * h * k2[i];
    }
    f(&tmp, &mut k3);
    for i in 0..len {
        tmp[i] = y[i] + h * k3[i];
    }
    f(&tmp, &mut k4);
    (0..len).map(|i| y[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])).collect()
}

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
