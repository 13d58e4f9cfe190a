//! Clarke and Park transforms (amplitude-invariant), fixed point.
//!
//! Clarke: `alpha = (2a - b - c)/3`, `beta = (b - c)/sqrt(3)`.
//! Park:   `d = alpha cos + beta sin`, `q = -alpha sin + beta cos`,
//! with the d axis on the magnet flux (the paper's vector control oriented to
//! the magnets flux, section 2.1; the paper's dq0 torque estimate, 3.3).

use crate::fixed::{add, mul, mul_q30, sub, Q16, Q30};

/// 1/3 (dimensionless), Q2.30: a Q16.16 constant would be off by 1.5e-5
/// relative, 2 mA on a 150 A sum.
pub const ONE_THIRD: Q30 = Q30::lit("0.333333333333");
/// 1/sqrt(3) (dimensionless), Q2.30.
pub const INV_SQRT3: Q30 = Q30::lit("0.577350269190");
/// sqrt(3)/2 (dimensionless), Q2.30.
pub const SQRT3_HALF: Q30 = Q30::lit("0.866025403784");
/// 1/2 (dimensionless).
pub const HALF: Q16 = Q16::lit("0.5");

/// Three phase quantities (A or V).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Abc {
    /// Phase a.
    pub a: Q16,
    /// Phase b.
    pub b: Q16,
    /// Phase c.
    pub c: Q16,
}

/// Stationary two-axis quantities (A or V).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AlphaBeta {
    /// alpha axis, aligned with phase a.
    pub alpha: Q16,
    /// beta axis, 90 electrical degrees ahead of alpha.
    pub beta: Q16,
}

/// Rotor-frame quantities (A or V).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Dq {
    /// d axis, on the magnet flux.
    pub d: Q16,
    /// q axis, producing torque.
    pub q: Q16,
}

/// Clarke transform of three phase values, amplitude invariant.
pub fn clarke(abc: Abc) -> AlphaBeta {
    let two_a = add(abc.a, abc.a);
    AlphaBeta { alpha: mul_q30(sub(sub(two_a, abc.b), abc.c), ONE_THIRD), beta: mul_q30(sub(abc.b, abc.c), INV_SQRT3) }
}

/// Inverse Clarke transform (zero-sequence free).
pub fn inverse_clarke(ab: AlphaBeta) -> Abc {
    let half_alpha = mul(ab.alpha, HALF);
    let beta_part = mul_q30(ab.beta, SQRT3_HALF);
    Abc { a: ab.alpha, b: sub(beta_part, half_alpha), c: sub(Q16::ZERO, add(half_alpha, beta_part)) }
}

/// Park transform with the sine and cosine (Q2.30) of the electrical angle.
pub fn park(ab: AlphaBeta, sin: Q30, cos: Q30) -> Dq {
    Dq { d: add(mul_q30(ab.alpha, cos), mul_q30(ab.beta, sin)), q: sub(mul_q30(ab.beta, cos), mul_q30(ab.alpha, sin)) }
}

/// Inverse Park transform with the sine and cosine (Q2.30) of the electrical angle.
pub fn inverse_park(dq: Dq, sin: Q30, cos: Q30) -> AlphaBeta {
    AlphaBeta { alpha: sub(mul_q30(dq.d, cos), mul_q30(dq.q, sin)), beta: add(mul_q30(dq.d, sin), mul_q30(dq.q, cos)) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixed::q16;
    use crate::trig::{angle_from_radians, sin_cos};

    #[test]
    fn balanced_currents_give_constant_dq() {
        // i_a = I cos(theta), ... with the rotor at theta: d = I, q = 0.
        let amplitude = 12.5f64;
        for k in 0..64 {
            let theta = k as f64 * 0.1;
            let phase = |shift: f64| q16((amplitude * (theta - shift).cos()) as f32);
            let abc = Abc {
                a: phase(0.0),
                b: phase(2.0 * core::f64::consts::PI / 3.0),
                c: phase(-2.0 * core::f64::consts::PI / 3.0),
            };
            let (s, c) = sin_cos(angle_from_radians(theta));
            let dq = park(clarke(abc), s, c);
            assert!((dq.d.to_num::<f64>() - amplitude).abs() < 2e-3, "{dq:?}");
            assert!(dq.q.to_num::<f64>().abs() < 2e-3, "{dq:?}");
        }
    }

    #[test]
    fn inverse_transforms_round_trip() {
        let dq = Dq { d: q16(-3.25), q: q16(17.5) };
        let (s, c) = sin_cos(angle_from_radians(2.1));
        let back = park(clarke(inverse_clarke(inverse_park(dq, s, c))), s, c);
        assert!((back.d - dq.d).abs() < q16(1e-3));
        assert!((back.q - dq.q).abs() < q16(1e-3));
    }
}
