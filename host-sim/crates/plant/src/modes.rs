//! Eqn 10: natural frequencies and mode shapes `-K u = -M w^2 u` of the
//! 5-DOF chain at given rope lengths (paper Fig. 5).

use nalgebra::{SMatrix, SymmetricEigen};

use super::rope::{ChainParams, DOF};

/// Natural modes at one configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct Modes {
    /// Natural frequencies, Hz, ascending (the rigid-body mode at 0 Hz first).
    pub frequencies_hz: [f64; DOF],
    /// Mode shapes: `shapes[mode][coordinate]`, scaled to a largest |component| of 1
    /// with that component positive.
    pub shapes: [[f64; DOF]; DOF],
}

/// Natural modes of `params` with counterweight-side rope length `lw_m`.
///
/// Solved as the symmetric problem `M^-1/2 K M^-1/2 v = w^2 v` (M is
/// diagonal), `u = M^-1/2 v`. Eigenvalues below 1e-12 of the largest (the
/// rigid mode, which is 0 up to round-off) are reported as exactly 0 Hz.
pub fn natural_modes(params: &ChainParams, lw_m: f64) -> Modes {
    let masses = params.masses_kg(lw_m);
    let k = params.stiffness_matrix(lw_m);
    let inv_sqrt_m: [f64; DOF] = masses.map(|m| 1.0 / m.sqrt());
    let a = SMatrix::<f64, DOF, DOF>::from_fn(|i, j| k[i][j] * inv_sqrt_m[i] * inv_sqrt_m[j]);
    let eigen = SymmetricEigen::new(a);
    // Eigenvalues this far below the largest are round-off of the rigid mode.
    let round_off = 1e-12 * eigen.eigenvalues.iter().copied().fold(0.0f64, f64::max);
    let mut order: Vec<usize> = (0..DOF).collect();
    order.sort_by(|&x, &y| eigen.eigenvalues[x].total_cmp(&eigen.eigenvalues[y]));
    let mut frequencies_hz = [0.0; DOF];
    let mut shapes = [[0.0; DOF]; DOF];
    for (mode, &column) in order.iter().enumerate() {
        let lambda = eigen.eigenvalues[column];
        let lambda = if lambda < round_off { 0.0 } else { lambda };
        frequencies_hz[mode] = lambda.sqrt() / std::f64::consts::TAU;
        let mut shape = [0.0; DOF];
        for (i, value) in shape.iter_mut().enumerate() {
            *value = eigen.eigenvectors[(i, column)] * inv_sqrt_m[i];
        }
        let largest = shape.iter().copied().fold(0.0f64, |acc, v| if v.abs() > acc.abs() { v } else { acc });
        if largest != 0.0 {
            shape.iter_mut().for_each(|v| *v /= largest);
        }
        shapes[mode] = shape;
    }
    Modes { frequencies_hz, shapes }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rope::CAR;
    use rig_config::RigConfig;

    fn rig_chain(m_car: f64) -> ChainParams {
        ChainParams::from_rig(&RigConfig::embedded_default().unwrap(), m_car)
    }

    #[test]
    fn rigid_mode_moves_everything_together() {
        let modes = natural_modes(&rig_chain(70.5), 4.0);
        assert!(modes.frequencies_hz[0] < 1e-3);
        for v in modes.shapes[0] {
            assert!((v - 1.0).abs() < 1e-6, "{:?}", modes.shapes[0]);
        }
    }

    #[test]
    fn frequencies_satisfy_the_characteristic_equation() {
        // det(K - w^2 M) = 0 at every reported elastic frequency: check that
        // the smallest singular value of K - w^2 M is tiny relative to K.
        let p = rig_chain(45.5);
        for lw in [1.5, 4.0, 7.0] {
            let modes = natural_modes(&p, lw);
            let m = p.masses_kg(lw);
            let k = p.stiffness_matrix(lw);
            for f in &modes.frequencies_hz[1..] {
                let w2 = (f * std::f64::consts::TAU).powi(2);
                let d = SMatrix::<f64, DOF, DOF>::from_fn(|i, j| k[i][j] - if i == j { w2 * m[i] } else { 0.0 });
                let smallest = d.singular_values().min();
                assert!(smallest < 1e-6 * k[0][0], "lw={lw} f={f} sigma={smallest}");
            }
        }
    }

    #[test]
    fn car_mode_tends_to_the_single_spring_value() {
        // Rope masses -> 0 and sheave inertia -> infinity: the car hangs on
        // the two k_c springs in series (EA/l_c) from a fixed point.
        let mut p = rig_chain(70.5);
        p.rope_mass_per_length_kg_per_m = 1e-9;
        p.sheave_inertia_kg_m2 = 1e9;
        let lw = 3.0;
        let lc = p.car_side_length_m(lw);
        let k_series = p.rope_ea_n / lc;
        let car_alone = (k_series / p.m_car_kg).sqrt() / std::f64::consts::TAU;
        let cw_alone = (p.rope_ea_n / lw / p.m_cw_kg).sqrt() / std::f64::consts::TAU;
        let modes = natural_modes(&p, lw);
        let car_mode = modes
            .shapes
            .iter()
            .zip(modes.frequencies_hz)
            .filter(|(shape, _)| (shape[CAR] - 1.0).abs() < 1e-9)
            .map(|(_, f)| f)
            .find(|f| *f > 1.0)
            .expect("a mode dominated by the car");
        assert!((car_mode - car_alone).abs() < 1e-4 * car_alone, "{car_mode} vs {car_alone}");
        assert!(modes.frequencies_hz.iter().any(|f| (f - cw_alone).abs() < 1e-4 * cw_alone));
    }
}
