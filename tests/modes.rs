//! Eqn 10 checked by an independent computation: the roots of
//! det(K - w^2 M) found by scanning and bisection with a hand-written
//! Gaussian elimination, against the eigen-solver used by `host-sim modes`.

use crate::support::rig;
use plant::modes::natural_modes;
use plant::rope::ChainParams;

/// det(A) by Gaussian elimination with partial pivoting.
fn determinant(mut a: [[f64; 5]; 5]) -> f64 {
    let mut det = 1.0;
    for col in 0..5 {
        let pivot = (col..5).max_by(|&x, &y| a[x][col].abs().total_cmp(&a[y][col].abs())).unwrap();
        if a[pivot][col] == 0.0 {
            return 0.0;
        }
        if pivot != col {
            a.swap(pivot, col);
            det = -det;
        }
        det *= a[col][col];
        let pivot_row = a[col];
        for row in a.iter_mut().skip(col + 1) {
            let factor = row[col] / pivot_row[col];
            for (value, pivot_value) in row.iter_mut().zip(pivot_row.iter()).skip(col) {
                *value -= factor * pivot_value;
            }
        }
    }
    det
}

/// Elastic natural frequencies (Hz) from the sign changes of det(K - w^2 M),
/// with the chain assembled here from the rig values directly (Eqn 1-2, rope
/// mass mu*l all at the midpoint, sheave I/r^2).
fn independent_frequencies(m_car: f64, lw: f64) -> Vec<f64> {
    let rig = rig();
    let m = &rig.mechanics;
    let lc = m.rope_total_length_m - lw;
    let (kw, kc) = (2.0 * m.rope_ea_n / lw, 2.0 * m.rope_ea_n / lc);
    let masses = [
        m.m_cw_kg,
        m.rope_mass_per_length_kg_per_m * lw,
        m.sheave_inertia_kg_m2 / m.sheave_radius_m.powi(2),
        m.rope_mass_per_length_kg_per_m * lc,
        m_car,
    ];
    let stiffness = [
        [kw, -kw, 0.0, 0.0, 0.0],
        [-kw, 2.0 * kw, -kw, 0.0, 0.0],
        [0.0, -kw, kw + kc, -kc, 0.0],
        [0.0, 0.0, -kc, 2.0 * kc, -kc],
        [0.0, 0.0, 0.0, -kc, kc],
    ];
    let det_at = |f: f64| {
        let w2 = (std::f64::consts::TAU * f).powi(2);
        let mut a = stiffness;
        for (i, row) in a.iter_mut().enumerate() {
            row[i] -= w2 * masses[i];
        }
        determinant(a)
    };
    let mut roots = Vec::new();
    let mut f = 0.5;
    let mut previous = det_at(f);
    while f < 3000.0 {
        let next_f = f * 1.0005;
        let value = det_at(next_f);
        if value.signum() != previous.signum() {
            let (mut lo, mut hi) = (f, next_f);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if det_at(mid).signum() == det_at(lo).signum() {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            roots.push(0.5 * (lo + hi));
        }
        previous = value;
        f = next_f;
    }
    roots
}

#[test]
fn eigen_solver_matches_the_independent_determinant_roots() {
    let rig = rig();
    for &m_car in &rig.mechanics.m_car_kg {
        for lw in [1.0, 2.5, 4.0, 5.5, 7.6] {
            let solver = natural_modes(&ChainParams::from_rig(&rig, m_car), lw).frequencies_hz;
            let independent = independent_frequencies(m_car, lw);
            assert_eq!(independent.len(), 4, "m_car {m_car} lw {lw}: {independent:?}");
            assert!(solver[0].abs() < 1e-3, "rigid-body mode {}", solver[0]);
            for (a, b) in solver[1..].iter().zip(&independent) {
                assert!((a - b).abs() < 0.005 * b, "m_car {m_car} lw {lw}: {a} vs {b}");
            }
        }
    }
}

#[test]
fn paper_reference_point_at_lw_4m_with_the_heaviest_car() {
    let rig = rig();
    let independent = independent_frequencies(70.5, 4.0);
    let solver = natural_modes(&ChainParams::from_rig(&rig, 70.5), 4.0).frequencies_hz;
    println!("lw = 4.0 m, m_car = 70.5 kg: solver {solver:.2?}, determinant roots {independent:.2?}");
    // The quoted values (about 10.6, 17.5, 224.8, 258.7 Hz).
    for (got, quoted) in solver[1..].iter().zip([10.6, 17.5, 224.8, 258.7]) {
        assert!((got - quoted).abs() < 0.005 * quoted, "{got} vs {quoted}");
    }
}
