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
        let static_power = t_s.powf(beta);
        let inverse_beta = 1.0 / beta;
        StiffeningSegment {
            static_tension_n: t_s,
            linear_n_per_m: 0.0,
            static_power,
            slope: beta * s,
            inverse_beta,
            relative_per_m: beta * s / static_power,
            series: (inverse_beta <= SERIES_MAX_POWER).then(|| binomial_series(inverse_beta)),
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
    /// `beta s / T_s^beta`, 1/m: the relative change `u` of `T^beta` per
    /// metre of stretch change.
    pub relative_per_m: f64,
    /// The coefficients `C(1/beta, k + 1)` of `((1 + u)^(1/beta) - 1) / u`
    /// ([`SERIES_TERMS`] of them), where `1/beta` is at most
    /// [`SERIES_MAX_POWER`].
    pub series: Option<[f64; SERIES_TERMS]>,
}

/// Terms of [`StiffeningSegment::series`].
pub const SERIES_TERMS: usize = 14;

/// Largest `|u|` at which [`StiffeningSegment::tension_change_n`] sums the
/// series: the terms it leaves out are below `1.4e-16` of the sum there
/// for every power up to [`SERIES_MAX_POWER`] (`tests`).
pub const SERIES_REACH: f64 = 0.125;

/// Largest power `1 / beta` (an exponent `alpha` up to 0.75) for which a
/// segment keeps the series.
pub const SERIES_MAX_POWER: f64 = 4.0;

/// `sum_k c_k u^k` by Estrin's scheme (pairs, then pairs of pairs in
/// `u^2`, `u^4` and `u^8`): four dependent steps where Horner's takes
/// thirteen.
#[inline]
fn series_sum(c: &[f64; SERIES_TERMS], u: f64) -> f64 {
    let (u2, pair) = (u * u, |i: usize| c[i] + c[i + 1] * u);
    let (u4, quad) = (u2 * u2, |i: usize| pair(i) + pair(i + 2) * u2);
    let u8 = u4 * u4;
    let low = quad(0) + quad(4) * u4;
    let high = quad(8) + pair(12) * u4;
    low + high * u8
}

/// The binomial coefficients `C(p, k + 1)`, `k = 0 ..` [`SERIES_TERMS`]:
/// `((1 + u)^p - 1) / u = sum_k C(p, k + 1) u^k`.
fn binomial_series(p: f64) -> [f64; SERIES_TERMS] {
    let mut c = [0.0; SERIES_TERMS];
    c[0] = p;
    for k in 1..SERIES_TERMS {
        c[k] = c[k - 1] * (p - k as f64) / (k + 1) as f64;
    }
    c
}

impl StiffeningSegment {
    /// Tension change (N) for a stretch `stretch_change_m` (m) beyond the
    /// static one; `-T_s` once the segment is slack. Near the static
    /// tension (`T^beta` within [`SERIES_REACH`] of `T_s^beta`) as `T_s u
    /// sum_k C(1/beta, k + 1) u^k`, the change itself rather than the
    /// difference of two near tensions; elsewhere by the power.
    #[inline]
    pub fn tension_change_n(&self, stretch_change_m: f64) -> f64 {
        if self.linear_n_per_m != 0.0 {
            return self.linear_n_per_m * stretch_change_m;
        }
        let u = self.relative_per_m * stretch_change_m;
        if let Some(c) = &self.series {
            if u.abs() <= SERIES_REACH {
                return self.static_tension_n * u * series_sum(c, u);
            }
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
    /// The series near the static tension against the power law written
    /// with `ln_1p` and `exp_m1` (`T_s ((1 + u)^p - 1)` without the
    /// difference of near numbers), across the series' reach and the
    /// exponents it serves, and the law's two forms meeting at its edge.
    #[test]
    fn the_series_near_the_static_tension_is_the_power_law() {
        let (ea0, t_s, l) = (1.0e6, 450.0, 0.25);
        for alpha in [0.05, 0.3, 0.45, 0.6, 0.75] {
            let e = TensionStiffening { alpha, reference_tension_n: 323.73 };
            let segment = e.segment(ea0, t_s, l);
            assert!(segment.series.is_some(), "alpha {alpha}");
            let p = segment.inverse_beta;
            for i in -100..=100 {
                let u = SERIES_REACH * i as f64 / 100.0;
                let dx = u / segment.relative_per_m;
                let exact = t_s * (p * u.ln_1p()).exp_m1();
                let got = segment.tension_change_n(dx);
                assert!((got - exact).abs() <= 1e-15 * exact.abs(), "alpha {alpha}, u {u}: {got} against {exact}");
            }
            let edge = SERIES_REACH / segment.relative_per_m;
            let (inside, outside) = (segment.tension_change_n(edge), segment.tension_change_n(edge * (1.0 + 1e-15)));
            assert!((outside - inside).abs() < 1e-12 * inside.abs(), "alpha {alpha}: {inside} | {outside}");
        }
        let stiff = TensionStiffening { alpha: 0.8, reference_tension_n: 323.73 };
        assert!(stiff.segment(ea0, t_s, l).series.is_none());
    }

    /// The first term the series leaves out, at its reach, against the
    /// sum, for every power up to the largest it serves.
    #[test]
    fn the_series_left_out_is_below_the_rounding() {
        for i in 0..=300 {
            let p = 1.0 + (SERIES_MAX_POWER - 1.0) * i as f64 / 300.0;
            let c = binomial_series(p);
            let next = c[SERIES_TERMS - 1] * (p - SERIES_TERMS as f64) / (SERIES_TERMS + 1) as f64;
            // Every term left out is at most this one times u^j: a geometric tail.
            let tail = next.abs() * SERIES_REACH.powi(SERIES_TERMS as i32) / (1.0 - SERIES_REACH);
            let sum = |u: f64| (p * f64::ln_1p(u)).exp_m1() / u;
            let least = sum(SERIES_REACH).min(sum(-SERIES_REACH));
            assert!(tail < 1.4e-16 * least, "p {p}: {:e} of the sum", tail / least);
        }
    }
}
