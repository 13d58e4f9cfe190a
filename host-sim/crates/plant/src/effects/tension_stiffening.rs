//! Tension stiffening: the rope's EA grows with its tension, EA = EA0 (T / T_ref)^alpha.

/// Tension stiffening: the rope's EA grows with its tension, EA = EA0 (T / T_ref)^alpha.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TensionStiffening {
    /// Exponent, dimensionless.
    pub alpha: f64,
    /// Tension at which EA equals the configured EA0, N.
    pub reference_tension_n: f64,
}

impl TensionStiffening {
    /// Axial stiffness `EA = EA0 (T / T_ref)^alpha` (N) of rope at static
    /// tension `tension_n` (N), `ea0_n` (N) the rig's configured EA. A
    /// tension at or below zero (a slack rope) is taken as the smallest
    /// positive tension, so the result is finite and never NaN; `alpha = 0`
    /// returns `ea0_n` exactly. (Never inlined: LLVM would otherwise
    /// speculate the `powf` into the nominal plant's path.)
    #[inline(never)]
    pub fn ea_n(&self, ea0_n: f64, tension_n: f64) -> f64 {
        let ratio = tension_n.max(f64::MIN_POSITIVE) / self.reference_tension_n;
        ea0_n * ratio.powf(self.alpha)
    }
}

/// EA (N) of rope at static tension `tension_n` (N): [`TensionStiffening::ea_n`]
/// with the effect on, `ea0_n` (N) without it.
pub fn rope_ea_n(effect: Option<&TensionStiffening>, ea0_n: f64, tension_n: f64) -> f64 {
    match effect {
        Some(e) => e.ea_n(ea0_n, tension_n),
        None => ea0_n,
    }
}

/// Static tension (N) of a vertical rope at a point with `rope_below_m` (m)
/// of rope of `mu_kg_per_m` (kg/m) hanging below it and `end_mass_kg` (kg)
/// at its end, under gravity `gravity_mps2` (m/s^2): `(m + mu l) g`.
pub fn static_tension_n(end_mass_kg: f64, mu_kg_per_m: f64, rope_below_m: f64, gravity_mps2: f64) -> f64 {
    (end_mass_kg + mu_kg_per_m * rope_below_m) * gravity_mps2
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ea_follows_the_power_law_and_alpha_zero_is_exact() {
        let e = TensionStiffening { alpha: 0.5, reference_tension_n: 100.0 };
        assert!((e.ea_n(1.0e6, 400.0) - 2.0e6).abs() < 1e-6);
        assert!((e.ea_n(1.0e6, 25.0) - 0.5e6).abs() < 1e-6);
        assert!(e.ea_n(1.0e6, -5.0).is_finite());
        let zero = TensionStiffening { alpha: 0.0, reference_tension_n: 323.73 };
        assert_eq!(zero.ea_n(1.0e6, 691.6), 1.0e6);
        assert_eq!(rope_ea_n(None, 1.0e6, 5.0), 1.0e6);
        assert!((static_tension_n(70.5, 0.095, 2.0, 9.81) - 70.69 * 9.81).abs() < 1e-9);
    }
}
