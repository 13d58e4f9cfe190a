//! Machine torque from the three phase currents by the dq0 transformation
//! (seed paper, section 3.3: "the machine torque has been estimated from the
//! measured three phase current intensities by means of the dq0
//! transformation").
//!
//! The transforms follow the simulator's PMSM convention
//! (`plant::pmsm::phase_currents_a`): amplitude-invariant Clarke,
//! then Park at the electrical angle `theta_e = p * theta_m + offset`, with
//! the d axis on the magnet flux. For dq currents `(i_d, i_q)` the phase
//! currents are
//!
//! ```text
//! i_a = i_d cos(theta_e) - i_q sin(theta_e)
//! i_b = i_d cos(theta_e - 2 pi / 3) - i_q sin(theta_e - 2 pi / 3)
//! i_c = i_d cos(theta_e + 2 pi / 3) - i_q sin(theta_e + 2 pi / 3)
//! ```
//!
//! and [`dq_currents`] inverts exactly that.

use super::{check_signal, AnalysisError};

/// `1 / sqrt(3)`, dimensionless.
const FRAC_1_SQRT_3: f64 = 0.577_350_269_189_625_8;

/// Checks that the three phase currents and the angle have the same number
/// of samples (the first being `i_a`), at least one, all finite.
fn check_inputs(i_a: &[f64], i_b: &[f64], i_c: &[f64], shaft_angle_rad: &[f64]) -> Result<(), AnalysisError> {
    check_signal(i_a, 1, "a dq0 transformation")?;
    for (name, s) in [("i_b", i_b), ("i_c", i_c), ("shaft_angle_rad", shaft_angle_rad)] {
        if s.len() != i_a.len() {
            return Err(AnalysisError::InvalidParameter {
                name,
                value: s.len() as f64,
                expected: "as many samples as i_a (the value is the number of samples)",
            });
        }
        check_signal(s, 1, "a dq0 transformation")?;
    }
    Ok(())
}

/// d and q axis currents (A) of the phase currents `i_a`, `i_b`, `i_c` (A).
///
/// * `i_a`, `i_b`, `i_c`: phase currents into the machine, A, sampled at the
///   same instants as `shaft_angle_rad`; all four slices have the same length
///   (at least 1).
/// * `shaft_angle_rad`: mechanical shaft angle, rad (wrapped or unwrapped).
/// * `pole_pairs`: number of pole pairs `p`, at least 1.
/// * `electrical_offset_rad`: electrical angle of the d axis when the shaft
///   angle is 0, rad (0 for the simulator; for a real encoder the offset
///   found by the drive's alignment).
///
/// Amplitude-invariant Clarke transform
/// `i_alpha = (2 i_a - i_b - i_c) / 3`, `i_beta = (i_b - i_c) / sqrt(3)`,
/// then Park at `theta_e = p * theta_m + offset`:
/// `i_d = i_alpha cos(theta_e) + i_beta sin(theta_e)`,
/// `i_q = -i_alpha sin(theta_e) + i_beta cos(theta_e)`.
/// A sinusoidal current of peak amplitude `I` gives `|(i_d, i_q)| = I`. The
/// zero-sequence part `(i_a + i_b + i_c) / 3` (a common-mode offset, zero in
/// a star-connected machine) drops out.
///
/// Returns `(i_d, i_q)`, each with one value per input sample, in A.
///
/// # Errors
/// [`AnalysisError::EmptySignal`] or [`AnalysisError::NonFinite`] for a bad
/// signal, [`AnalysisError::InvalidParameter`] when the lengths differ (named
/// after the slice whose length differs from `i_a`), when `pole_pairs` is 0 or
/// when the offset is not finite.
pub fn dq_currents(
    i_a: &[f64],
    i_b: &[f64],
    i_c: &[f64],
    shaft_angle_rad: &[f64],
    pole_pairs: u32,
    electrical_offset_rad: f64,
) -> Result<(Vec<f64>, Vec<f64>), AnalysisError> {
    if pole_pairs == 0 {
        return Err(AnalysisError::InvalidParameter {
            name: "pole_pairs",
            value: 0.0,
            expected: "at least 1 pole pair",
        });
    }
    if !electrical_offset_rad.is_finite() {
        return Err(AnalysisError::InvalidParameter {
            name: "electrical_offset_rad",
            value: electrical_offset_rad,
            expected: "a finite angle in rad",
        });
    }
    check_inputs(i_a, i_b, i_c, shaft_angle_rad)?;

    let p = f64::from(pole_pairs);
    let n = i_a.len();
    let mut i_d = Vec::with_capacity(n);
    let mut i_q = Vec::with_capacity(n);
    for k in 0..n {
        let alpha = (2.0 * i_a[k] - i_b[k] - i_c[k]) / 3.0;
        let beta = (i_b[k] - i_c[k]) * FRAC_1_SQRT_3;
        let (s, c) = (p * shaft_angle_rad[k] + electrical_offset_rad).sin_cos();
        i_d.push(alpha * c + beta * s);
        i_q.push(-alpha * s + beta * c);
    }
    if i_d.iter().chain(&i_q).any(|v| !v.is_finite()) {
        return Err(AnalysisError::NumericOverflow { what: "dq currents" });
    }
    Ok((i_d, i_q))
}

/// Electromagnetic torque of the machine, N m, from its phase currents.
///
/// * `i_a`, `i_b`, `i_c`, `shaft_angle_rad`, `pole_pairs`,
///   `electrical_offset_rad`: as for [`dq_currents`] (A, rad).
/// * `flux_linkage_wb`: magnet flux linkage `psi` (peak, per phase), Wb,
///   finite.
/// * `ld_h`, `lq_h`: d and q axis inductances, H, finite and >= 0.
///
/// `T = 1.5 p (psi i_q + (L_d - L_q) i_d i_q)` with `(i_d, i_q)` from
/// [`dq_currents`], per sample; the same expression as the simulator's
/// `PmsmParams::torque_nm`. The torque is positive when it lifts the car in
/// the simulator's convention. It is the air-gap torque the currents
/// produce; cogging torque (no current) is not in it.
///
/// # Errors
/// Those of [`dq_currents`], and [`AnalysisError::InvalidParameter`] for a
/// non-finite flux linkage or a negative or non-finite inductance.
#[allow(clippy::too_many_arguments)]
pub fn machine_torque_nm(
    i_a: &[f64],
    i_b: &[f64],
    i_c: &[f64],
    shaft_angle_rad: &[f64],
    pole_pairs: u32,
    flux_linkage_wb: f64,
    ld_h: f64,
    lq_h: f64,
    electrical_offset_rad: f64,
) -> Result<Vec<f64>, AnalysisError> {
    if !flux_linkage_wb.is_finite() {
        return Err(AnalysisError::InvalidParameter {
            name: "flux_linkage_wb",
            value: flux_linkage_wb,
            expected: "a finite flux linkage in Wb",
        });
    }
    for (name, value) in [("ld_h", ld_h), ("lq_h", lq_h)] {
        if !(value.is_finite() && value >= 0.0) {
            return Err(AnalysisError::InvalidParameter { name, value, expected: "a finite inductance >= 0 H" });
        }
    }
    let (i_d, i_q) = dq_currents(i_a, i_b, i_c, shaft_angle_rad, pole_pairs, electrical_offset_rad)?;
    let k = 1.5 * f64::from(pole_pairs);
    let torque: Vec<f64> =
        i_d.iter().zip(&i_q).map(|(&d, &q)| k * (flux_linkage_wb * q + (ld_h - lq_h) * d * q)).collect();
    if torque.iter().any(|v| !v.is_finite()) {
        return Err(AnalysisError::NumericOverflow { what: "machine torque" });
    }
    Ok(torque)
}

#[cfg(test)]
mod tests {
    use super::*;
    use plant::pmsm::{phase_currents_a, PmsmParams};
    use std::f64::consts::PI;

    /// Phase currents written out from the inverse transform of the module
    /// documentation (independent of the plant's implementation).
    fn inverse_dq0(i_d: f64, i_q: f64, theta_e: f64, i_0: f64) -> [f64; 3] {
        let third = 2.0 * PI / 3.0;
        [
            i_d * theta_e.cos() - i_q * theta_e.sin() + i_0,
            i_d * (theta_e - third).cos() - i_q * (theta_e - third).sin() + i_0,
            i_d * (theta_e + third).cos() - i_q * (theta_e + third).sin() + i_0,
        ]
    }

    struct Case {
        i_a: Vec<f64>,
        i_b: Vec<f64>,
        i_c: Vec<f64>,
        theta_m: Vec<f64>,
        i_d: Vec<f64>,
        i_q: Vec<f64>,
    }

    /// A travel-like record: shaft accelerating, `i_q` with a DC part and
    /// 1 Hz, 12 Hz and 72 Hz ripple, a small varying `i_d`, and a
    /// zero-sequence offset added to all three phases.
    fn case(p: f64, offset: f64, zero_sequence: f64) -> Case {
        let fs = 16384.0;
        let n = 20_000;
        let mut c = Case { i_a: vec![], i_b: vec![], i_c: vec![], theta_m: vec![], i_d: vec![], i_q: vec![] };
        for k in 0..n {
            let t = k as f64 / fs;
            let theta_m = 0.3 + 3.0 * t * t - 1.7;
            let i_d = -1.2 + 0.4 * (2.0 * PI * 5.0 * t).sin();
            let i_q = 8.0
                + 0.5 * (2.0 * PI * t).sin()
                + 0.9 * (2.0 * PI * 12.0 * t + 0.4).sin()
                + 0.1 * (2.0 * PI * 72.0 * t).cos();
            let [a, b, cc] = inverse_dq0(i_d, i_q, p * theta_m + offset, zero_sequence * (2.0 * PI * 3.0 * t).cos());
            c.i_a.push(a);
            c.i_b.push(b);
            c.i_c.push(cc);
            c.theta_m.push(theta_m);
            c.i_d.push(i_d);
            c.i_q.push(i_q);
        }
        c
    }

    #[test]
    fn dq_currents_invert_the_inverse_transform() {
        for (p, offset, zs) in [(6u32, 0.0, 0.0), (6, 0.7, 0.5), (1, -2.0, 0.0), (4, 10.0, 3.0)] {
            let c = case(f64::from(p), offset, zs);
            let (i_d, i_q) = dq_currents(&c.i_a, &c.i_b, &c.i_c, &c.theta_m, p, offset).unwrap();
            let err =
                i_d.iter().zip(&c.i_d).chain(i_q.iter().zip(&c.i_q)).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            assert!(err < 1e-12, "p {p} offset {offset}: max error {err} A");
        }
    }

    #[test]
    fn torque_with_ripple_is_recovered_within_1e_9() {
        let (p, psi, ld, lq) = (6u32, 0.45, 0.012, 0.018);
        for (offset, zs) in [(0.0, 0.0), (0.9, 1.0)] {
            let c = case(f64::from(p), offset, zs);
            let torque = machine_torque_nm(&c.i_a, &c.i_b, &c.i_c, &c.theta_m, p, psi, ld, lq, offset).unwrap();
            assert_eq!(torque.len(), c.i_a.len());
            let mut err: f64 = 0.0;
            for ((t, &i_d), &i_q) in torque.iter().zip(&c.i_d).zip(&c.i_q) {
                let expected = 1.5 * 6.0 * (psi * i_q + (ld - lq) * i_d * i_q);
                err = err.max((t - expected).abs());
            }
            eprintln!("offset {offset}, zero sequence {zs}: max torque error {err:.2e} N m");
            assert!(err < 1e-9, "max torque error {err} N m");
        }
    }

    #[test]
    fn follows_the_plant_convention() {
        // Currents from the plant's own inverse transform (offset 0) and the
        // plant's torque expression.
        let params =
            PmsmParams { pole_pairs: 6.0, resistance_ohm: 1.2, ld_h: 0.015, lq_h: 0.02, flux_linkage_wb: 0.45 };
        let (mut a, mut b, mut c, mut th, mut expected) = (vec![], vec![], vec![], vec![], vec![]);
        for k in 0..5000 {
            let theta_m = -0.002 * k as f64;
            let (id, iq) = (0.5 * (k as f64 * 0.01).sin(), -7.0 + (k as f64 * 0.003).cos());
            let [ia, ib, ic] = phase_currents_a(id, iq, 6.0 * theta_m);
            a.push(ia);
            b.push(ib);
            c.push(ic);
            th.push(theta_m);
            expected.push(params.torque_nm(id, iq));
        }
        let t = machine_torque_nm(&a, &b, &c, &th, 6, 0.45, 0.015, 0.02, 0.0).unwrap();
        let err = t.iter().zip(&expected).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
        assert!(err < 1e-9, "max error {err} N m");
    }

    #[test]
    fn bad_inputs_are_errors() {
        let x = [1.0, 2.0, 3.0];
        let name = |r: Result<Vec<f64>, AnalysisError>| match r {
            Err(AnalysisError::InvalidParameter { name, .. }) => name,
            other => panic!("unexpected {other:?}"),
        };
        assert_eq!(name(machine_torque_nm(&x, &x[..2], &x, &x, 6, 0.4, 0.01, 0.01, 0.0)), "i_b");
        assert_eq!(name(machine_torque_nm(&x, &x, &x, &x[..1], 6, 0.4, 0.01, 0.01, 0.0)), "shaft_angle_rad");
        assert_eq!(name(machine_torque_nm(&x, &x, &x, &x, 0, 0.4, 0.01, 0.01, 0.0)), "pole_pairs");
        assert_eq!(name(machine_torque_nm(&x, &x, &x, &x, 6, f64::NAN, 0.01, 0.01, 0.0)), "flux_linkage_wb");
        assert_eq!(name(machine_torque_nm(&x, &x, &x, &x, 6, 0.4, -0.01, 0.01, 0.0)), "ld_h");
        assert_eq!(name(machine_torque_nm(&x, &x, &x, &x, 6, 0.4, 0.01, f64::INFINITY, 0.0)), "lq_h");
        assert_eq!(name(machine_torque_nm(&x, &x, &x, &x, 6, 0.4, 0.01, 0.01, f64::NAN)), "electrical_offset_rad");
        assert_eq!(machine_torque_nm(&[], &[], &[], &[], 6, 0.4, 0.01, 0.01, 0.0), Err(AnalysisError::EmptySignal));
        let bad = [1.0, f64::NAN, 3.0];
        assert!(matches!(
            machine_torque_nm(&x, &x, &bad, &x, 6, 0.4, 0.01, 0.01, 0.0),
            Err(AnalysisError::NonFinite { index: 1, .. })
        ));
        assert!(matches!(
            dq_currents(&[1e308], &[-1e308], &[-1e308], &[0.0], 1, 0.0),
            Err(AnalysisError::NumericOverflow { .. })
        ));
    }
}
