//! Tension stiffening: the rope's EA grows with its tension, EA = EA0 (T / T_ref)^alpha.

use super::declare::{
    Effect, Fit, FromData,
    ParamScale::{Linear, Log},
    ParamSpec, Seen,
};

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
        // `x^0` is exactly 1 for every `x` (NaN and infinities included):
        // the `powf` would return `ea0_n` bit for bit.
        if self.alpha == 0.0 {
            return ea0_n;
        }
        let ratio = tension_n.max(f64::MIN_POSITIVE) / self.reference_tension_n;
        ea0_n * ratio.powf(self.alpha)
    }

    /// Change of a rope segment's tension (N) when its stretch grows by
    /// `stretch_change_m` (m) from the static one, the tension following
    /// the rope's law `dT/d(strain) = EA(T)` at every instant, not only at
    /// the static tension: with `beta = 1 - alpha` and
    /// `s = EA0 T_ref^-alpha / l` (`l`, m, the segment's unstretched length),
    /// `T = (T_s^beta + beta s dx)^(1/beta)` integrates the law from the
    /// static tension `static_tension_n` (N). A segment stretched back below
    /// zero tension is slack (`T = 0`). Its slope at `dx = 0` is
    /// `EA(T_s) / l`, the linear spring of [`TensionStiffening::ea_n`]; a
    /// swing comparable to the static tension (a free decay released from a
    /// millimetre) makes the first mode's harmonics and a frequency that
    /// rises as the amplitude decays. (An exponent at or above 1 has no
    /// finite closed form; it falls back to the linear spring.)
    pub fn tension_change_n(&self, ea0_n: f64, static_tension_n: f64, stretch_change_m: f64, length_m: f64) -> f64 {
        self.segment(ea0_n, static_tension_n, length_m).tension_change_n(stretch_change_m)
    }

    /// A rope segment of unstretched length `length_m` (m) at static
    /// tension `static_tension_n` (N), `ea0_n` (N) the rig's EA, with what
    /// [`TensionStiffening::tension_change_n`] needs worked out once.
    pub fn segment(&self, ea0_n: f64, static_tension_n: f64, length_m: f64) -> StiffeningSegment {
        let beta = 1.0 - self.alpha;
        let t_s = static_tension_n.max(f64::MIN_POSITIVE);
        if beta <= 1e-6 || self.alpha == 0.0 {
            return StiffeningSegment {
                static_tension_n: t_s,
                linear_n_per_m: self.ea_n(ea0_n, t_s) / length_m,
                ..Default::default()
            };
        }
        let s = ea0_n * self.reference_tension_n.powf(-self.alpha) / length_m;
        StiffeningSegment {
            static_tension_n: t_s,
            linear_n_per_m: 0.0,
            static_power: t_s.powf(beta),
            slope: beta * s,
            inverse_beta: 1.0 / beta,
        }
    }

    /// The stretch change (m) that changes a segment's tension by
    /// `tension_change_n` (N) from `static_tension_n` (N): the inverse of
    /// [`TensionStiffening::tension_change_n`] (a tension at or below zero
    /// gives the stretch at which the segment goes slack).
    pub fn stretch_change_m(&self, ea0_n: f64, static_tension_n: f64, tension_change_n: f64, length_m: f64) -> f64 {
        self.segment(ea0_n, static_tension_n, length_m).stretch_change_m(tension_change_n)
    }
}

/// A rope segment under tension stiffening ([`TensionStiffening::segment`]):
/// `T = (T_s^beta + beta s dx)^(1/beta)`, or a linear spring where the
/// exponent has no closed form.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StiffeningSegment {
    /// Static tension `T_s`, N.
    pub static_tension_n: f64,
    /// Stiffness of the linear fallback, N/m (0 when the law applies).
    pub linear_n_per_m: f64,
    /// `T_s^beta`, N^beta.
    pub static_power: f64,
    /// `beta s`, N^beta/m.
    pub slope: f64,
    /// `1 / beta`, dimensionless.
    pub inverse_beta: f64,
}

impl StiffeningSegment {
    /// Tension change (N) for a stretch `stretch_change_m` (m) beyond the
    /// static one; `-T_s` once the segment is slack.
    #[inline]
    pub fn tension_change_n(&self, stretch_change_m: f64) -> f64 {
        if self.linear_n_per_m != 0.0 {
            return self.linear_n_per_m * stretch_change_m;
        }
        let base = self.static_power + self.slope * stretch_change_m;
        if base <= 0.0 {
            return -self.static_tension_n;
        }
        base.powf(self.inverse_beta) - self.static_tension_n
    }

    /// The stretch change (m) that changes the tension by
    /// `tension_change_n` (N): the inverse of
    /// [`StiffeningSegment::tension_change_n`] (a tension at or below zero
    /// gives the stretch at which the segment goes slack).
    pub fn stretch_change_m(&self, tension_change_n: f64) -> f64 {
        if self.linear_n_per_m != 0.0 {
            return tension_change_n / self.linear_n_per_m;
        }
        let t = (self.static_tension_n + tension_change_n).max(0.0);
        (t.powf(1.0 / self.inverse_beta) - self.static_power) / self.slope
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

impl Effect for TensionStiffening {
    const NAME: &'static str = "tension_stiffening";
    const PARAMETERS: &'static [ParamSpec] = &[
        ParamSpec::new("alpha", "-", 0.2, 0.0, 1.0, Linear, true, "exponent of EA = EA0 (T / T_ref)^alpha"),
        ParamSpec::new(
            "reference_tension_n",
            "N",
            323.73,
            10.0,
            1.0e4,
            Log,
            false,
            "tension at which EA equals the configured EA0 (default: 33 kg hanging)",
        )
        .from_data(FromData::StaticRopeTension),
    ];
    const FIT: Fit = Fit::Grid { axes: &[(0, &[0.2, 0.5, 0.85])], screened: true };
    const SEEN: Seen = Seen { in_free_decay: true, under_another_drive: true };

    fn from_values(v: &[f64]) -> Self {
        Self { alpha: v[0], reference_tension_n: v[1] }
    }

    fn values(&self) -> Vec<f64> {
        vec![self.alpha, self.reference_tension_n]
    }
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

    #[test]
    fn instantaneous_tension_follows_the_law_and_its_inverse() {
        let e = TensionStiffening { alpha: 0.45, reference_tension_n: 323.73 };
        let (ea0, t_s, l) = (1.0e6, 450.0, 0.25);
        // Slope at the static tension: the linear spring EA(T_s) / l.
        let dx = 1e-9;
        let slope = (e.tension_change_n(ea0, t_s, dx, l) - e.tension_change_n(ea0, t_s, -dx, l)) / (2.0 * dx);
        let linear = e.ea_n(ea0, t_s) / l;
        assert!((slope / linear - 1.0).abs() < 1e-6, "slope {slope} against {linear}");
        // The law dT/dx = EA(T)/l holds at a large swing too (central difference).
        let x = 2e-4;
        let t = t_s + e.tension_change_n(ea0, t_s, x, l);
        let d = (e.tension_change_n(ea0, t_s, x + dx, l) - e.tension_change_n(ea0, t_s, x - dx, l)) / (2.0 * dx);
        assert!((d / (e.ea_n(ea0, t) / l) - 1.0).abs() < 1e-5);
        // Stiffer when stretched than when relaxed: the swing is asymmetric.
        assert!(e.tension_change_n(ea0, t_s, x, l) > -e.tension_change_n(ea0, t_s, -x, l));
        // Slack below zero tension, and the inverse returns the stretch.
        assert_eq!(e.tension_change_n(ea0, t_s, -1.0, l), -t_s);
        for dt in [-300.0, -20.0, 0.0, 15.0, 400.0] {
            let back = e.tension_change_n(ea0, t_s, e.stretch_change_m(ea0, t_s, dt, l), l);
            assert!((back - dt).abs() < 1e-9 * t_s, "{dt} -> {back}");
        }
    }
}
