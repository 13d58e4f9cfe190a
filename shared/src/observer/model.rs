//! The reduced chain model of the observer: sheave, car and counterweight
//! joined by the two rope sides, scheduled on the rope lengths (Eqn 1-3).
//!
//! The 5-DOF chain of the paper (Eqn 6) has two rope-mass modes above 200 Hz
//! (224 and 259 Hz at `l_w = 4 m`), far above the 1-80 Hz band of the car
//! vibration. The observer drops them: each side's rope mass `mu l` is split
//! between its two ends, and each side becomes one spring of stiffness
//! `EA / l` (the two `2EA/l` springs of Eqn 1-2 in series). What remains is
//! the rigid-body mode and the two elastic modes (about 10 and 17 Hz).
//!
//! State `x` (SI units), positive in the rope direction of a car going up:
//!
//! | index | quantity |
//! |---|---|
//! | 0 | sheave-edge position `s = theta r`, m (relative to a moving origin) |
//! | 1 | sheave-edge speed `v`, m/s |
//! | 2 | car-side rope stretch `e_c = s - u_c`, m |
//! | 3 | car speed `v_c`, m/s |
//! | 4 | counterweight-side rope stretch `e_w = s - u_w`, m |
//! | 5 | counterweight speed `v_w`, m/s |
//!
//! with, for a stiffness scale `kappa` (estimated EA over nominal EA):
//!
//! * sheave (Eqn 5): `m_sh a = F - c_sh/r^2 v - kappa k_c e_c - kappa k_w e_w`
//! * car: `m_c a_c = kappa k_c e_c - c_c v_c`
//! * counterweight: `m_w a_w = kappa k_w e_w - c_w v_w`
//!
//! where `F` is the shaft torque minus the out-of-balance torque of Eqn 4,
//! divided by `r`. Coordinates are displacements from the static
//! equilibrium, as in the plant, so gravity enters only through Eqn 4.

use nalgebra::{SMatrix, SVector};

/// Number of mechanical states of the reduced chain.
pub const MECHANICAL_STATES: usize = 6;
/// Largest number of ripple harmonics the observer can carry.
pub const MAX_HARMONICS: usize = 5;

/// 6 x 6 matrix of the mechanical states.
pub type Matrix6 = SMatrix<f32, MECHANICAL_STATES, MECHANICAL_STATES>;
/// Vector of the mechanical states (units in the module table).
pub type Vector6 = SVector<f32, MECHANICAL_STATES>;

/// Index of the sheave-edge position, m.
pub const SHEAVE_POSITION: usize = 0;
/// Index of the sheave-edge speed, m/s.
pub const SHEAVE_SPEED: usize = 1;
/// Index of the car-side rope stretch, m.
pub const CAR_STRETCH: usize = 2;
/// Index of the car speed, m/s.
pub const CAR_SPEED: usize = 3;
/// Index of the counterweight-side rope stretch, m.
pub const CW_STRETCH: usize = 4;
/// Index of the counterweight speed, m/s.
pub const CW_SPEED: usize = 5;

/// Shortest rope side the model is evaluated at, m: lengths are clamped to
/// `[MIN_ROPE_LENGTH_M, l_t - MIN_ROPE_LENGTH_M]`, so no stiffness is infinite.
pub const MIN_ROPE_LENGTH_M: f32 = 0.05;

/// Parameters of the chain known to the observer, SI units. The car mass is
/// not here: it comes from the load weighing at the start of each travel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChainModel {
    /// Counterweight mass `m_w`, kg.
    pub m_cw_kg: f32,
    /// Total rope length `l_t = l_w + l_c`, m (Eqn 3).
    pub rope_total_length_m: f32,
    /// Nominal rope axial stiffness `EA`, N (Eqn 1-2); the observer estimates a scale on it.
    pub rope_ea_n: f32,
    /// Rope mass per length `mu`, kg/m.
    pub rope_mass_per_length_kg_per_m: f32,
    /// Rotor plus traction-sheave inertia `I`, kg m^2.
    pub sheave_inertia_kg_m2: f32,
    /// Traction-sheave radius `r`, m.
    pub sheave_radius_m: f32,
    /// Counterweight guide damping `c_w` (Eqn 12), kg/s, on its absolute speed.
    pub c_cw_kg_per_s: f32,
    /// Car guide damping `c_c` (Eqn 12), kg/s, on its absolute speed.
    pub c_car_kg_per_s: f32,
    /// Sheave rotational viscous damping `c_sh` (Eqn 13), N m s/rad.
    pub c_sheave_nms_per_rad: f32,
    /// Gravitational acceleration, m/s^2 (Eqn 4).
    pub gravity_mps2: f32,
    /// Encoder counts per mechanical revolution (after quadrature decoding).
    pub encoder_counts_per_rev: u32,
    /// Mechanical orders (per revolution) of the shaft ripple harmonics the
    /// observer estimates; 0 marks an unused slot. Only the orders are
    /// known: amplitudes and phases are estimated.
    pub ripple_orders: [u16; MAX_HARMONICS],
}

/// A parameter of [`ChainModel`] outside its physical range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelError {
    /// Name of the field.
    pub field: &'static str,
    /// What was expected.
    pub expected: &'static str,
}

impl core::fmt::Display for ModelError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "observer model field `{}` is out of range: expected {}", self.field, self.expected)
    }
}

/// The reduced chain at one pair of rope lengths: lumped masses (kg),
/// stiffnesses (N/m) and dampings (kg/s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReducedChain {
    /// Car plus half the car-side rope, kg.
    pub car_mass_kg: f32,
    /// Counterweight plus half the counterweight-side rope, kg.
    pub cw_mass_kg: f32,
    /// `I / r^2` plus half of each rope side, kg.
    pub sheave_mass_kg: f32,
    /// Car-side stiffness `kappa EA / l_c`, N/m.
    pub car_stiffness_n_per_m: f32,
    /// Counterweight-side stiffness `kappa EA / l_w`, N/m.
    pub cw_stiffness_n_per_m: f32,
    /// Car guide damping, kg/s.
    pub car_damping_kg_per_s: f32,
    /// Counterweight guide damping, kg/s.
    pub cw_damping_kg_per_s: f32,
    /// Sheave damping seen at the sheave edge `c_sh / r^2`, kg/s.
    pub sheave_damping_kg_per_s: f32,
}

impl ChainModel {
    /// Checks every field; the error names the first one out of range.
    pub fn validate(&self) -> Result<(), ModelError> {
        let positive = |v: f32| v.is_finite() && v > 0.0;
        let non_negative = |v: f32| v.is_finite() && v >= 0.0;
        let checks = [
            (positive(self.m_cw_kg), "m_cw_kg", "a finite mass > 0 kg"),
            (positive(self.rope_total_length_m), "rope_total_length_m", "a finite length > 0 m"),
            (
                self.rope_total_length_m > 2.0 * MIN_ROPE_LENGTH_M,
                "rope_total_length_m",
                "a length > 0.1 m (both sides at least 0.05 m)",
            ),
            (positive(self.rope_ea_n), "rope_ea_n", "a finite EA > 0 N"),
            (non_negative(self.rope_mass_per_length_kg_per_m), "rope_mass_per_length_kg_per_m", "a finite value >= 0"),
            (positive(self.sheave_inertia_kg_m2), "sheave_inertia_kg_m2", "a finite inertia > 0 kg m^2"),
            (positive(self.sheave_radius_m), "sheave_radius_m", "a finite radius > 0 m"),
            (non_negative(self.c_cw_kg_per_s), "c_cw_kg_per_s", "a finite damping >= 0 kg/s"),
            (non_negative(self.c_car_kg_per_s), "c_car_kg_per_s", "a finite damping >= 0 kg/s"),
            (non_negative(self.c_sheave_nms_per_rad), "c_sheave_nms_per_rad", "a finite damping >= 0 N m s/rad"),
            (non_negative(self.gravity_mps2), "gravity_mps2", "a finite value >= 0 m/s^2"),
            (self.encoder_counts_per_rev > 0, "encoder_counts_per_rev", "at least 1 count per revolution"),
        ];
        for (ok, field, expected) in checks {
            if !ok {
                return Err(ModelError { field, expected });
            }
        }
        Ok(())
    }

    /// Car-side length `l_c = l_t - l_w` for a counterweight-side length
    /// `lw_m` (Eqn 3), both clamped to at least [`MIN_ROPE_LENGTH_M`]; m.
    pub fn rope_lengths_m(&self, lw_m: f32) -> (f32, f32) {
        let lt = self.rope_total_length_m;
        // NaN falls to the lower bound: `max`/`min` return the other operand.
        let lw = lw_m.max(MIN_ROPE_LENGTH_M).min(lt - MIN_ROPE_LENGTH_M);
        (lw, lt - lw)
    }

    /// The reduced chain at counterweight-side length `lw_m` (m) with a car of
    /// `m_car_kg` (kg) and the stiffness scale `ea_scale` (dimensionless).
    pub fn reduced(&self, lw_m: f32, m_car_kg: f32, ea_scale: f32) -> ReducedChain {
        let (lw, lc) = self.rope_lengths_m(lw_m);
        let mu = self.rope_mass_per_length_kg_per_m;
        let r = self.sheave_radius_m;
        let ea = ea_scale * self.rope_ea_n;
        ReducedChain {
            car_mass_kg: m_car_kg + 0.5 * mu * lc,
            cw_mass_kg: self.m_cw_kg + 0.5 * mu * lw,
            sheave_mass_kg: self.sheave_inertia_kg_m2 / (r * r) + 0.5 * mu * (lc + lw),
            car_stiffness_n_per_m: ea / lc,
            cw_stiffness_n_per_m: ea / lw,
            car_damping_kg_per_s: self.c_car_kg_per_s,
            cw_damping_kg_per_s: self.c_cw_kg_per_s,
            sheave_damping_kg_per_s: self.c_sheave_nms_per_rad / (r * r),
        }
    }

    /// Eqn 4: out-of-balance torque at counterweight-side length `lw_m` (m)
    /// with a car of `m_car_kg`, N m (positive lifts the car):
    /// `(m_c - m_w + mu (l_c - l_w)) g r`.
    pub fn out_of_balance_torque_nm(&self, lw_m: f32, m_car_kg: f32) -> f32 {
        let (lw, lc) = self.rope_lengths_m(lw_m);
        (m_car_kg - self.m_cw_kg + self.rope_mass_per_length_kg_per_m * (lc - lw))
            * self.gravity_mps2
            * self.sheave_radius_m
    }

    /// Sheave-edge travel of one encoder count `2 pi r / counts`, m.
    pub fn metres_per_count(&self) -> f32 {
        core::f32::consts::TAU * self.sheave_radius_m / self.encoder_counts_per_rev as f32
    }
}

impl ReducedChain {
    /// System matrix `A` of `x' = A x + b F` (units of the module table, 1/s
    /// and 1/s^2 entries).
    pub fn system_matrix(&self) -> Matrix6 {
        let mut a = Matrix6::zeros();
        let ms = self.sheave_mass_kg;
        a[(SHEAVE_POSITION, SHEAVE_SPEED)] = 1.0;
        a[(SHEAVE_SPEED, SHEAVE_SPEED)] = -self.sheave_damping_kg_per_s / ms;
        a[(SHEAVE_SPEED, CAR_STRETCH)] = -self.car_stiffness_n_per_m / ms;
        a[(SHEAVE_SPEED, CW_STRETCH)] = -self.cw_stiffness_n_per_m / ms;
        a[(CAR_STRETCH, SHEAVE_SPEED)] = 1.0;
        a[(CAR_STRETCH, CAR_SPEED)] = -1.0;
        a[(CAR_SPEED, CAR_STRETCH)] = self.car_stiffness_n_per_m / self.car_mass_kg;
        a[(CAR_SPEED, CAR_SPEED)] = -self.car_damping_kg_per_s / self.car_mass_kg;
        a[(CW_STRETCH, SHEAVE_SPEED)] = 1.0;
        a[(CW_STRETCH, CW_SPEED)] = -1.0;
        a[(CW_SPEED, CW_STRETCH)] = self.cw_stiffness_n_per_m / self.cw_mass_kg;
        a[(CW_SPEED, CW_SPEED)] = -self.cw_damping_kg_per_s / self.cw_mass_kg;
        a
    }

    /// Input vector `b` of a force `F` (N) at the sheave edge, 1/kg.
    pub fn sheave_force_input(&self) -> Vector6 {
        let mut b = Vector6::zeros();
        b[SHEAVE_SPEED] = 1.0 / self.sheave_mass_kg;
        b
    }

    /// Car acceleration of state `x`, m/s^2 (positive up).
    pub fn car_acceleration_mps2(&self, x: &Vector6) -> f32 {
        (self.car_stiffness_n_per_m * x[CAR_STRETCH] - self.car_damping_kg_per_s * x[CAR_SPEED]) / self.car_mass_kg
    }

    /// Derivative of `A x` with respect to the stiffness scale at `kappa`,
    /// per unit scale (the stiffnesses of `self` are those at `kappa`).
    pub fn dynamics_per_stiffness_scale(&self, x: &Vector6, kappa: f32) -> Vector6 {
        let fc = self.car_stiffness_n_per_m * x[CAR_STRETCH] / kappa;
        let fw = self.cw_stiffness_n_per_m * x[CW_STRETCH] / kappa;
        let mut d = Vector6::zeros();
        d[SHEAVE_SPEED] = -(fc + fw) / self.sheave_mass_kg;
        d[CAR_SPEED] = fc / self.car_mass_kg;
        d[CW_SPEED] = fw / self.cw_mass_kg;
        d
    }
}

/// Zero-order-hold discretisation over `dt_s` by a truncated series with
/// `terms` terms (only `+ - * /`): returns `(Psi, Phi)` with
/// `Psi = sum_{j<terms} A^j dt^{j+1} / (j+1)!` (the integral of `e^{A t}`
/// over the step, s) and `Phi = I + A Psi` (`e^{A dt}`). The first omitted
/// term is bounded by `(|A| dt)^terms / terms!` relative to the result.
///
/// The products skip the zero entries of `A` (the chain's has 12 of 36);
/// each entry sums its nonzero terms in the order of the summation index,
/// which gives the chain's matrices the same bits as nalgebra's dense
/// products (a test checks it).
pub fn discretise(a: &Matrix6, dt_s: f32, terms: usize) -> (Matrix6, Matrix6) {
    const N: usize = MECHANICAL_STATES;
    let mut term = Matrix6::identity() * dt_s;
    let mut psi = term;
    for j in 1..terms.max(1) {
        // term A
        let mut product = Matrix6::zeros();
        for col in 0..N {
            for k in 0..N {
                let v = a[(k, col)];
                if v != 0.0 {
                    for i in 0..N {
                        product[(i, col)] += term[(i, k)] * v;
                    }
                }
            }
        }
        term = product * (dt_s / (j + 1) as f32);
        psi += term;
    }
    // A Psi
    let mut a_psi = Matrix6::zeros();
    for row in 0..N {
        for k in 0..N {
            let v = a[(row, k)];
            if v != 0.0 {
                for col in 0..N {
                    a_psi[(row, col)] += v * psi[(k, col)];
                }
            }
        }
    }
    (psi, Matrix6::identity() + a_psi)
}

#[cfg(test)]
pub(crate) mod tests {
    extern crate std;
    use super::*;
    use std::println;

    /// The rig's chain as the observer sees it (configs/rig.toml).
    pub(crate) fn rig_model() -> ChainModel {
        crate::config::reference_chain()
    }

    /// Right-hand side of the reduced chain written out in f64, independently
    /// of [`ReducedChain::system_matrix`]: sheave, car, counterweight.
    fn derivative_f64(m: &ChainModel, lw: f64, m_car: f64, x: &[f64; 6], force_n: f64) -> [f64; 6] {
        let lc = m.rope_total_length_m as f64 - lw;
        let mu = m.rope_mass_per_length_kg_per_m as f64;
        let r = m.sheave_radius_m as f64;
        let (kc, kw) = (m.rope_ea_n as f64 / lc, m.rope_ea_n as f64 / lw);
        let mc = m_car + mu * lc / 2.0;
        let mw = m.m_cw_kg as f64 + mu * lw / 2.0;
        let msh = m.sheave_inertia_kg_m2 as f64 / (r * r) + mu * (lc + lw) / 2.0;
        let [_, v, ec, vc, ew, vw] = *x;
        let rope_on_sheave = kc * ec + kw * ew;
        [
            v,
            (force_n - m.c_sheave_nms_per_rad as f64 / (r * r) * v - rope_on_sheave) / msh,
            v - vc,
            (kc * ec - m.c_car_kg_per_s as f64 * vc) / mc,
            v - vw,
            (kw * ew - m.c_cw_kg_per_s as f64 * vw) / mw,
        ]
    }

    /// `x(dt)` from `x0` with a constant sheave force, RK4 in 2000 substeps.
    fn integrate_f64(m: &ChainModel, lw: f64, m_car: f64, x0: [f64; 6], force_n: f64, dt: f64) -> [f64; 6] {
        let steps = 2000;
        let h = dt / steps as f64;
        let mut x = x0;
        let add = |a: &[f64; 6], k: &[f64; 6], s: f64| core::array::from_fn::<f64, 6, _>(|i| a[i] + s * k[i]);
        for _ in 0..steps {
            let k1 = derivative_f64(m, lw, m_car, &x, force_n);
            let k2 = derivative_f64(m, lw, m_car, &add(&x, &k1, h / 2.0), force_n);
            let k3 = derivative_f64(m, lw, m_car, &add(&x, &k2, h / 2.0), force_n);
            let k4 = derivative_f64(m, lw, m_car, &add(&x, &k3, h), force_n);
            x = core::array::from_fn(|i| x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]));
        }
        x
    }

    #[test]
    fn discretised_model_matches_an_f64_integration() {
        let model = rig_model();
        let dt = 1.0 / 2000.0;
        let mut worst: f64 = 0.0;
        for m_car in [33.0f32, 70.5] {
            for lw in [1.0f32, 4.0, 7.6] {
                let chain = model.reduced(lw, m_car, 1.0);
                let (psi, phi) = discretise(&chain.system_matrix(), dt, 8);
                let gamma = psi * chain.sheave_force_input();
                // Columns of Phi: unit initial states of each coordinate's scale.
                for j in 0..6 {
                    let scale = if j % 2 == 0 { 1.0e-4 } else { 1.0e-2 };
                    let mut x0 = [0.0; 6];
                    x0[j] = scale;
                    let reference = integrate_f64(&model, lw as f64, m_car as f64, x0, 0.0, dt as f64);
                    let norm = reference.iter().fold(0.0f64, |a, v| a.max(v.abs()));
                    for i in 0..6 {
                        let got = phi[(i, j)] as f64 * scale;
                        worst = worst.max((got - reference[i]).abs() / norm);
                    }
                }
                // Gamma: response to a 100 N sheave force from rest.
                let reference = integrate_f64(&model, lw as f64, m_car as f64, [0.0; 6], 100.0, dt as f64);
                let norm = reference.iter().fold(0.0f64, |a, v| a.max(v.abs()));
                for i in 0..6 {
                    worst = worst.max((gamma[i] as f64 * 100.0 - reference[i]).abs() / norm);
                }
            }
        }
        println!("largest difference of Phi and Gamma from the f64 RK4 integration: {worst:.2e} of the column");
        assert!(worst < 1.0e-5, "discretisation off by {worst:.2e}");
    }

    #[test]
    fn series_truncation_error_shrinks_with_terms() {
        let model = rig_model();
        let chain = model.reduced(1.0, 33.0, 1.0);
        let a = chain.system_matrix();
        let (_, reference) = discretise(&a, 5.0e-4, 16);
        let mut previous = f32::MAX;
        for terms in [2, 3, 4, 5] {
            let (_, phi) = discretise(&a, 5.0e-4, terms);
            let error = (phi - reference).abs().max();
            println!("{terms} terms: largest |Phi - Phi_16| = {error:.3e}");
            assert!(error < previous, "{terms} terms: {error} not below {previous}");
            previous = error;
        }
    }

    /// The products that skip the zeros of `A` against nalgebra's dense
    /// products of the same series: the same bits.
    #[test]
    fn sparse_discretisation_is_the_dense_series() {
        let model = rig_model();
        let dt = 1.0 / 2000.0;
        let mut worst: f32 = 0.0;
        for (lw, m_car, kappa) in [(0.05f32, 33.0f32, 0.5f32), (1.0, 70.5, 1.0), (4.0, 58.0, 1.3), (8.55, 70.5, 2.0)] {
            let a = model.reduced(lw, m_car, kappa).system_matrix();
            for terms in [2, 5, 8] {
                let mut term = Matrix6::identity() * dt;
                let mut psi = term;
                for j in 1..terms {
                    term = term * a * (dt / (j + 1) as f32);
                    psi += term;
                }
                let phi = Matrix6::identity() + a * psi;
                let (sparse_psi, sparse_phi) = discretise(&a, dt, terms);
                for (sparse, dense) in [(sparse_psi, psi), (sparse_phi, phi)] {
                    let error = (sparse - dense).abs().max() / dense.abs().max();
                    worst = worst.max(error);
                }
            }
        }
        println!("largest difference to the dense series, relative to the largest entry: {worst:.2e}");
        assert_eq!(worst, 0.0);
    }

    #[test]
    fn bad_fields_are_named() {
        let mut model = rig_model();
        model.rope_ea_n = f32::NAN;
        assert_eq!(model.validate().unwrap_err().field, "rope_ea_n");
        let mut model = rig_model();
        model.sheave_radius_m = -0.065;
        let error = model.validate().unwrap_err();
        assert_eq!(error.field, "sheave_radius_m");
        println!("{error}");
        let mut model = rig_model();
        model.encoder_counts_per_rev = 0;
        assert_eq!(model.validate().unwrap_err().field, "encoder_counts_per_rev");
        assert_eq!(rig_model().validate(), Ok(()));
    }

    #[test]
    fn extreme_rope_lengths_are_clamped_to_finite_stiffness() {
        let model = rig_model();
        for lw in [f32::NAN, f32::NEG_INFINITY, -3.0, 0.0, 8.6, 100.0, f32::INFINITY] {
            let chain = model.reduced(lw, 70.5, 1.0);
            let a = chain.system_matrix();
            assert!(a.iter().all(|v| v.is_finite()), "lw = {lw}: non-finite A");
            assert!(model.out_of_balance_torque_nm(lw, 70.5).is_finite(), "lw = {lw}");
            assert!(chain.car_stiffness_n_per_m <= model.rope_ea_n / MIN_ROPE_LENGTH_M);
        }
    }
}
