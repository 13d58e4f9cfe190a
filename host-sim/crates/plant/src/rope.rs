//! Rope chain parameters: stiffness `k = 2EA/l` (Eqn 1-2), rope masses
//! `mu l` lumped at the midpoint of each side, sheave `I/r^2`, and the
//! inertia, stiffness and damping matrices of Eqn 6 for given rope lengths.

use rig_config::RigConfig;

/// Index of the counterweight in the coordinate vector (`u_w`).
pub const CW: usize = 0;
/// Index of the counterweight-side rope mass (`u_1`).
pub const ROPE_CW: usize = 1;
/// Index of the sheave edge (`u_sh = theta r`).
pub const SHEAVE: usize = 2;
/// Index of the car-side rope mass (`u_2`).
pub const ROPE_CAR: usize = 3;
/// Index of the car (`u_c`).
pub const CAR: usize = 4;
/// Number of degrees of freedom.
pub const DOF: usize = 5;
/// Names of the coordinates, in index order.
pub const COORDINATE_NAMES: [&str; DOF] = ["cw", "rope_cw", "sheave", "rope_car", "car"];

/// Parameters of the 5-DOF chain, SI units.
#[derive(Clone, Debug, PartialEq)]
pub struct ChainParams {
    /// Counterweight mass `m_w`, kg.
    pub m_cw_kg: f64,
    /// Car mass `m_c`, kg.
    pub m_car_kg: f64,
    /// Rope `EA`, N.
    pub rope_ea_n: f64,
    /// Rope mass per length `mu`, kg/m.
    pub rope_mass_per_length_kg_per_m: f64,
    /// `l_t = l_w + l_c`, m.
    pub rope_total_length_m: f64,
    /// Sheave (rotor + traction sheave) inertia `I`, kg m^2.
    pub sheave_inertia_kg_m2: f64,
    /// Sheave radius `r`, m.
    pub sheave_radius_m: f64,
    /// Counterweight guide damping, kg/s (on its absolute velocity).
    pub c_cw_kg_per_s: f64,
    /// Car guide damping, kg/s (on its absolute velocity).
    pub c_car_kg_per_s: f64,
    /// Sheave rotational damping, N m s/rad.
    pub c_sheave_nms_per_rad: f64,
    /// Gravity, m/s^2.
    pub gravity_mps2: f64,
}

impl ChainParams {
    /// The chain of `rig` carrying a car of `m_car_kg`.
    pub fn from_rig(rig: &RigConfig, m_car_kg: f64) -> Self {
        let m = &rig.mechanics;
        Self {
            m_cw_kg: m.m_cw_kg,
            m_car_kg,
            rope_ea_n: m.rope_ea_n,
            rope_mass_per_length_kg_per_m: m.rope_mass_per_length_kg_per_m,
            rope_total_length_m: m.rope_total_length_m,
            sheave_inertia_kg_m2: m.sheave_inertia_kg_m2,
            sheave_radius_m: m.sheave_radius_m,
            c_cw_kg_per_s: m.c_cw_kg_per_s,
            c_car_kg_per_s: m.c_car_kg_per_s,
            c_sheave_nms_per_rad: m.c_sheave_nms_per_rad,
            gravity_mps2: m.gravity_mps2,
        }
    }

    /// Car-side rope length `l_c = l_t - l_w`, m.
    pub fn car_side_length_m(&self, counterweight_side_length_m: f64) -> f64 {
        self.rope_total_length_m - counterweight_side_length_m
    }

    /// Lumped masses (kg) for the rope lengths: `m_w, mu l_w, I/r^2, mu l_c, m_c`.
    pub fn masses_kg(&self, counterweight_side_length_m: f64) -> [f64; DOF] {
        let mu = self.rope_mass_per_length_kg_per_m;
        let lc = self.car_side_length_m(counterweight_side_length_m);
        [
            self.m_cw_kg,
            mu * counterweight_side_length_m,
            self.sheave_inertia_kg_m2 / (self.sheave_radius_m * self.sheave_radius_m),
            mu * lc,
            self.m_car_kg,
        ]
    }

    /// Spring stiffnesses `(k_w, k_c)` of the two sides, N/m (Eqn 1-2).
    pub fn spring_stiffness_n_per_m(&self, counterweight_side_length_m: f64) -> (f64, f64) {
        (
            rope_stiffness_n_per_m(self.rope_ea_n, counterweight_side_length_m),
            rope_stiffness_n_per_m(self.rope_ea_n, self.car_side_length_m(counterweight_side_length_m)),
        )
    }

    /// Viscous damping on each coordinate's absolute velocity, kg/s: guides
    /// of counterweight and car, sheave `c_sh / r^2` (rotational damping seen
    /// at the sheave edge).
    pub fn damping_kg_per_s(&self) -> [f64; DOF] {
        let r = self.sheave_radius_m;
        [self.c_cw_kg_per_s, 0.0, self.c_sheave_nms_per_rad / (r * r), 0.0, self.c_car_kg_per_s]
    }

    /// Stiffness matrix `K` of Eqn 6/10 (N/m): the chain cw - k_w - rope -
    /// k_w - sheave - k_c - rope - k_c - car.
    pub fn stiffness_matrix(&self, counterweight_side_length_m: f64) -> [[f64; DOF]; DOF] {
        let (kw, kc) = self.spring_stiffness_n_per_m(counterweight_side_length_m);
        let mut k = [[0.0; DOF]; DOF];
        for (i, j, s) in [(CW, ROPE_CW, kw), (ROPE_CW, SHEAVE, kw), (SHEAVE, ROPE_CAR, kc), (ROPE_CAR, CAR, kc)] {
            k[i][i] += s;
            k[j][j] += s;
            k[i][j] -= s;
            k[j][i] -= s;
        }
        k
    }

    /// Eqn 4: out-of-balance torque that holds the system at rest, N m
    /// (positive lifts the car): `(m_c - m_w + mu (l_c - l_w)) g r`.
    pub fn out_of_balance_torque_nm(&self, counterweight_side_length_m: f64) -> f64 {
        let lc = self.car_side_length_m(counterweight_side_length_m);
        (self.m_car_kg - self.m_cw_kg + self.rope_mass_per_length_kg_per_m * (lc - counterweight_side_length_m))
            * self.gravity_mps2
            * self.sheave_radius_m
    }
}

/// Eqn 1-2: stiffness of one rope side lumped as two springs in series
/// around its midpoint mass, each `2EA/l`, N/m.
pub fn rope_stiffness_n_per_m(ea_n: f64, length_m: f64) -> f64 {
    2.0 * ea_n / length_m
}
