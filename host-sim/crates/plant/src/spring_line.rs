//! The one place where a line of point masses joined by springs gets its
//! accelerations: the travel's rope line ([`super::line::Line`], under
//! every integrator of the plant and in the diagnosis's torque-driven
//! model), the nominal chain's exact discretisation ([`super::exact`]) and
//! the free decay's hanging rope ([`super::free_decay`]).
//!
//! Nodes are numbered along the line; spring `i` joins nodes `i` and
//! `i + 1`. A spring's tension pulls its two nodes together: node `i` gets
//! `+T_i` and node `i + 1` gets `-T_i` (Eqn 5's stiffness matrix, written
//! as the springs' tensions, so each spring's law is evaluated once).

use super::effects::Effects;

/// A force applied at one node, N (positive in the line's direction).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodeForce {
    /// The node.
    pub node: usize,
    /// The force, N.
    pub force_n: f64,
}

/// Accelerations (m/s^2) into `accel[..n]` of the `n = inv_mass.len()`
/// nodes at positions `position_m` (m) and velocities `velocity_mps`
/// (m/s): node `i` gets `(T_i - T_(i-1) + F_i - c_i v_i) / m_i`, with
/// `T_i = tension(i, x_(i+1) - x_i)` the tension of spring `i` (N) at its
/// extension (m), `F_i` the sum of the `applied` forces at node `i` (N),
/// `c_i = damping[i]` the viscous damping on the node's absolute velocity
/// (kg/s) and `1 / m_i = inv_mass[i]` (1/kg; zero for a fixed node).
pub fn accelerations(
    tension: impl Fn(usize, f64) -> f64,
    damping: &[f64],
    inv_mass: &[f64],
    position_m: &[f64],
    velocity_mps: &[f64],
    applied: &[NodeForce],
    accel: &mut [f64],
) {
    let n = inv_mass.len();
    let (x, a) = (&position_m[..n], &mut accel[..n]);
    spring_forces(&tension, x, a);
    finish_accelerations(damping, inv_mass, velocity_mps, applied, a);
}

/// [`accelerations`] of linear springs, `T_i = springs[i] (x_(i+1) - x_i)`
/// with `springs` in N/m: the same values, in loops without a call per
/// spring (that vectorise).
pub fn linear_accelerations(
    springs: &[f64],
    damping: &[f64],
    inv_mass: &[f64],
    position_m: &[f64],
    velocity_mps: &[f64],
    applied: &[NodeForce],
    accel: &mut [f64],
) {
    let n = inv_mass.len();
    if n == 0 {
        return;
    }
    // Slices of the nodes' length: the loops run without bounds checks
    // (and vectorise).
    let (a, k, x) = (&mut accel[..n], &springs[..n - 1], &position_m[..n]);
    // The tension of the spring on node i's lower side.
    let mut below = 0.0;
    for i in 0..n - 1 {
        let above = k[i] * (x[i + 1] - x[i]);
        a[i] = above - below;
        below = above;
    }
    a[n - 1] = 0.0 - below;
    finish_accelerations(damping, inv_mass, velocity_mps, applied, a);
}

/// From the springs' net forces in `accel` (N) to the accelerations
/// (m/s^2): the `applied` forces added in their order (the same sums as
/// adding them node by node), then `(force - c v) / m` with `damping` `c`
/// (kg/s), `inv_mass` `1 / m` (1/kg) and `velocity_mps` `v` (m/s).
fn finish_accelerations(
    damping: &[f64],
    inv_mass: &[f64],
    velocity_mps: &[f64],
    applied: &[NodeForce],
    accel: &mut [f64],
) {
    for f in applied {
        if let Some(force) = accel.get_mut(f.node) {
            *force += f.force_n;
        }
    }
    let n = accel.len();
    let (c, v, inv_mass) = (&damping[..n], &velocity_mps[..n], &inv_mass[..n]);
    for i in 0..n {
        accel[i] = (accel[i] - c[i] * v[i]) * inv_mass[i];
    }
}

/// The springs' net force on each node, N, into `force` (as long as `x`):
/// `T_i - T_(i-1)` with `T_i = tension(i, x_(i+1) - x_i)`, no spring below
/// the first node nor above the last.
fn spring_forces(tension: &impl Fn(usize, f64) -> f64, x: &[f64], force: &mut [f64]) {
    let Some(last) = x.len().checked_sub(1) else { return };
    // The tension of the spring on node i's lower side.
    let mut below = 0.0;
    for i in 0..last {
        let above = tension(i, x[i + 1] - x[i]);
        force[i] = above - below;
        below = above;
    }
    force[last] = 0.0 - below;
}

/// Adds the force the effects apply at the guides
/// ([`Effects::guide_force_n`], N, of each node's velocity) on each of
/// `nodes` to its acceleration (m/s^2) in `accel`.
pub fn add_guide_forces(effects: &Effects, nodes: &[usize], velocity_mps: &[f64], inv_mass: &[f64], accel: &mut [f64]) {
    if effects.acts_at_guides() {
        for &i in nodes {
            accel[i] += effects.guide_force_n(velocity_mps[i]) * inv_mass[i];
        }
    }
}

/// Adds a damper of `damping_kg_per_s` (kg/s) between the nodes `ends`
/// (on their relative velocity) to their accelerations (m/s^2) in `accel`.
#[inline(always)]
pub fn add_damper(
    ends: (usize, usize),
    damping_kg_per_s: f64,
    velocity_mps: &[f64],
    inv_mass: &[f64],
    accel: &mut [f64],
) {
    let (from, to) = ends;
    if from != to && damping_kg_per_s != 0.0 {
        let f = damping_kg_per_s * (velocity_mps[to] - velocity_mps[from]);
        accel[from] += f * inv_mass[from];
        accel[to] -= f * inv_mass[to];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The kernel against the stiffness matrix assembled naively (Eqn 5's
    /// `K` of a free-free line), on random-ish values: the same forces to
    /// rounding.
    #[test]
    fn matches_the_assembled_stiffness_matrix() {
        let n = 7;
        let k: Vec<f64> = (0..n - 1).map(|i| 1.0e5 * (1.0 + 0.3 * (i as f64).sin())).collect();
        let c: Vec<f64> = (0..n).map(|i| 10.0 * (i % 3) as f64).collect();
        let m: Vec<f64> = (0..n).map(|i| 2.0 + i as f64).collect();
        let inv: Vec<f64> = m.iter().map(|m| 1.0 / m).collect();
        let x: Vec<f64> = (0..n).map(|i| 1e-3 * (1.7 * i as f64).cos()).collect();
        let v: Vec<f64> = (0..n).map(|i| 0.2 * (0.9 * i as f64).sin()).collect();
        let applied = [NodeForce { node: 2, force_n: 40.0 }, NodeForce { node: 2, force_n: -3.0 }];
        let mut a = vec![0.0; n];
        accelerations(|i, e| k[i] * e, &c, &inv, &x, &v, &applied, &mut a);
        let mut stiffness = vec![vec![0.0; n]; n];
        for (i, &ki) in k.iter().enumerate() {
            stiffness[i][i] += ki;
            stiffness[i + 1][i + 1] += ki;
            stiffness[i][i + 1] -= ki;
            stiffness[i + 1][i] -= ki;
        }
        for i in 0..n {
            let elastic: f64 = (0..n).map(|j| stiffness[i][j] * x[j]).sum();
            let f = if i == 2 { 37.0 } else { 0.0 };
            let expected = (f - c[i] * v[i] - elastic) / m[i];
            assert!((a[i] - expected).abs() <= 1e-12 * (1.0 + expected.abs()), "node {i}: {} against {expected}", a[i]);
        }
    }

    /// A fixed node (zero inverse mass) does not move; a spring's law is
    /// read with its extension.
    #[test]
    fn a_fixed_node_stays_and_the_law_sees_the_extension() {
        let x = [0.0, 0.01, 0.03];
        let mut a = [f64::NAN; 3];
        let law = |i: usize, e: f64| if i == 0 { 100.0 * e * e } else { 50.0 * e };
        accelerations(law, &[0.0; 3], &[0.0, 1.0, 0.5], &x, &[0.0; 3], &[], &mut a);
        assert_eq!(a[0], 0.0);
        assert!((a[1] - (50.0 * 0.02 - 100.0 * 0.01 * 0.01)).abs() < 1e-15);
        assert!((a[2] - (-50.0 * 0.02 * 0.5)).abs() < 1e-15);
    }
}
