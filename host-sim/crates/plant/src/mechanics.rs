//! Eqn 3-6: the equations of motion of the 5-DOF chain during a travel,
//! `M(l) x'' + C x' + K(l) x = dF`, with the rope lengths following the
//! sheave (Eqn 3: `l_w = l_w0 + u_sh`, `l_c = l_t - l_w` in this crate's
//! sign convention) so that stiffness and rope masses change as the car
//! moves. Coordinates are displacements from the static equilibrium at the
//! start; the drive's shaft torque minus the out-of-balance torque of Eqn 4
//! acts on the sheave (Eqn 5: `dF_sh = tau_d / r`). The accelerations are
//! the line's ([`super::line::Line`] without effects is this chain); here
//! the chain's state, lengths and energy.

use super::rope::{ChainParams, DOF, SHEAVE};

/// Position (m) and velocity (m/s) of every coordinate.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ChainState {
    /// Displacements `u_w, u_1, u_sh, u_2, u_c`, m.
    pub position_m: [f64; DOF],
    /// Velocities, m/s.
    pub velocity_mps: [f64; DOF],
}

/// The chain during a travel.
#[derive(Clone, Debug, PartialEq)]
pub struct Chain {
    /// Masses, stiffness and damping parameters.
    pub params: ChainParams,
    /// Counterweight-side rope length when `u_sh = 0`, m.
    pub lw_start_m: f64,
    /// Rope lengths follow the sheave (Eqn 3); false freezes them (tests).
    pub lengths_follow_sheave: bool,
}

/// Smallest rope length the model accepts, m; the simulation stops before.
pub const MIN_ROPE_LENGTH_M: f64 = 1.0e-3;

impl Chain {
    /// A chain whose rope lengths follow the sheave from `lw_start_m`.
    pub fn new(params: ChainParams, lw_start_m: f64) -> Self {
        Self { params, lw_start_m, lengths_follow_sheave: true }
    }

    /// Counterweight-side rope length, m (Eqn 3).
    pub fn counterweight_side_length_m(&self, state: &ChainState) -> f64 {
        if self.lengths_follow_sheave {
            self.lw_start_m + state.position_m[SHEAVE]
        } else {
            self.lw_start_m
        }
    }

    /// Kinetic plus elastic energy, J, at the current lengths (for checks).
    pub fn mechanical_energy_j(&self, state: &ChainState) -> f64 {
        let lw = self.counterweight_side_length_m(state);
        let masses = self.params.masses_kg(lw);
        let k = self.params.stiffness_matrix(lw);
        let kinetic: f64 = (0..DOF).map(|i| 0.5 * masses[i] * state.velocity_mps[i].powi(2)).sum();
        let elastic: f64 = (0..DOF)
            .flat_map(|i| (0..DOF).map(move |j| (i, j)))
            .map(|(i, j)| 0.5 * state.position_m[i] * k[i][j] * state.position_m[j])
            .sum();
        kinetic + elastic
    }
}
