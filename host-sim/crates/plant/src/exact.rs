//! Exact discretisation of the nominal chain over a PWM half period: the
//! closed loop's default for the nominal 5-DOF plant
//! ([`super::Integrator::Fast`] through [`Plant::advance_until`]).
//!
//! Over a half period the inverter's voltages are constant and the chain is
//! linear, `x' = A x + b f(t) + b_c F_c` (`x`: the five positions and
//! velocities; `f`: the force on the sheave edge, N; `F_c`: an extra force on
//! the car). `A` holds the springs, masses and damping, and the
//! out-of-balance torque of Eqn 4, which is linear in the sheave position
//! (`-tau_ob / r = f_0 + 2 mu g u_sh`). Its discretisation
//! `x(h) = Phi x(0) + sum_j Gamma_j f_j + Gamma_c F_c` for a force
//! `f(t) = sum_j f_j t^j` (j <= 3) is exact; `Phi = e^{Ah}` and
//! `Gamma_j = int_0^h e^{A(h-s)} b s^j ds` come from their Taylor series
//! (`rho(A h) <= 0.5`, 16 terms: truncation below 1e-19).
//!
//! What is approximated, with its bound:
//! - `A` is evaluated at a reference sheave position and refreshed when the
//!   sheave has moved half the refresh distance from it: [`REFRESH_DISTANCE_M`]
//!   times the shorter rope side's length in metres (at least 1, at most
//!   [`MAX_REFRESH_SCALE`]), so that the distance is the same fraction of
//!   the rope everywhere; the springs' and masses' change along the rope
//!   (`2EA/l`, `mu l`) up to there is added to second order (central
//!   differences at the refresh) as a force constant over the step, at the
//!   step's predicted midpoint: what is left is third order,
//!   `(0.25 mm / 1 m)^3`, below 2e-11 of the rope forces on either side.
//! - The machine currents over the half period are their degree-6 Taylor
//!   series in time (the voltage equations differentiated term by term with
//!   the shaft's speed, acceleration and jerk at the start; first term left
//!   out below 1e-20 A); the shaft torque is its cubic, with the ripple along
//!   the shaft angle `theta_0 + w t + alpha t^2/2 + jerk t^3/6` to third
//!   order (the first term left out, `(72 w h)^4 / 24`, is 2e-9 of the 72nd
//!   order's amplitude at 0.4 m/s).
//! - Samples inside the half period (the 16384 Hz acquisition) take the
//!   accelerations, speeds and positions from the cubic Hermite
//!   interpolants of the ends' values and derivatives: error `h^4/384` of
//!   the fourth derivative, 4e-6 of a 1 kHz rope-mass oscillation's
//!   amplitude, less for everything slower.
//!
//! The closed loop needs that precision: a plant error that moves a current
//! or encoder reading across one code changes what the drive does.

use super::line::Lumped;
use super::mechanics::MIN_ROPE_LENGTH_M;
use super::pmsm::phase_currents_cs_a;
use super::rope::{CAR, CW, DOF, SHEAVE};
use super::spring_line::{self, NodeForce};
use super::{Plant, PlantObservation, STATE_LEN};

/// Mechanical states: five positions, five velocities.
const MECH: usize = 2 * DOF;

/// Distance (m) over which the sheave may move before `A` is evaluated
/// anew (half of it either side of the reference position) when the
/// shorter rope side is 1 m long or less; it grows in proportion to that
/// side's length beyond (up to [`MAX_REFRESH_SCALE`] times).
pub const REFRESH_DISTANCE_M: f64 = 0.5e-3;

/// Largest factor on [`REFRESH_DISTANCE_M`] (a shorter side of 8 m).
pub const MAX_REFRESH_SCALE: f64 = 8.0;

/// Terms of the Taylor series of `Phi` and `Gamma_j` (`rho(A h) <= 0.5`:
/// the first term left out is below `0.5^16 / 16! = 7e-19`).
const TERMS: usize = 16;

/// Terms of the currents' Taylor series in time (degree 6: the first term
/// left out, `(R/L)^6 (V/L) h^7 / 7!`, is below 1e-20 A).
const SERIES: usize = 7;

/// `1 / (k + 1)` for the series' recursion.
const INVERSE: [f64; SERIES] = [1.0, 1.0 / 2.0, 1.0 / 3.0, 1.0 / 4.0, 1.0 / 5.0, 1.0 / 6.0, 1.0 / 7.0];

/// The chain's coefficients frozen at a reference sheave position.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Coefficients {
    /// `1 / m_i`, 1/kg.
    inv_mass: [f64; DOF],
    /// Spring `i` joins nodes `i` and `i + 1`, N/m.
    spring: [f64; DOF - 1],
    /// Viscous damping on absolute velocities, kg/s.
    damping: [f64; DOF],
    /// `2 mu g`: the out-of-balance force per metre of sheave travel, N/m.
    out_of_balance_n_per_m: f64,
    /// Out-of-balance force on the sheave edge at `u_sh = 0`, N.
    out_of_balance_n: f64,
    /// The brake holds the sheave.
    held: bool,
    /// Springs' first and second derivatives along the sheave position,
    /// N/m^2 and N/m^3.
    spring_slope: [[f64; DOF - 1]; 2],
    /// Masses' relative first and second derivatives along the sheave
    /// position, 1/m and 1/m^2.
    mass_slope: [[f64; DOF]; 2],
}

impl Coefficients {
    /// Accelerations (m/s^2) at positions `u` (m), velocities `v` (m/s),
    /// drive force on the sheave edge `f` (N) and extra car force `f_car` (N).
    fn accel(&self, u: &[f64], v: &[f64], f: f64, f_car: f64) -> [f64; DOF] {
        let sheave = f + self.out_of_balance_n + self.out_of_balance_n_per_m * u[SHEAVE];
        self.respond(u, v, sheave, f_car)
    }

    /// The change of the accelerations (m/s^2) when the springs and masses
    /// are taken at `du` (m) from the reference position instead of at it
    /// (to second order in `du`), for spring extensions `stretch` (m) and
    /// accelerations `a` (m/s^2).
    fn variation(&self, du: f64, stretch: &[f64; DOF - 1], a: &[f64; DOF]) -> [f64; DOF] {
        let [k1, k2] = &self.spring_slope;
        let [m1, m2] = &self.mass_slope;
        let mut t = [0.0; DOF - 1];
        for i in 0..DOF - 1 {
            t[i] = (k1[i] + 0.5 * k2[i] * du) * du * stretch[i];
        }
        let force = [t[0], t[1] - t[0], t[2] - t[1], t[3] - t[2], -t[3]];
        let mut out = [0.0; DOF];
        for i in 0..DOF {
            let relative_mass = (m1[i] + 0.5 * m2[i] * du) * du;
            out[i] = force[i] * self.inv_mass[i] - a[i] * relative_mass / (1.0 + relative_mass);
        }
        if self.held {
            out[SHEAVE] = 0.0;
        }
        out
    }

    /// Jerks (m/s^3) at velocities `v` (m/s), accelerations `a` (m/s^2) and
    /// drive force rate `f_rate` (N/s) on the sheave edge.
    fn jerk(&self, v: &[f64], a: &[f64; DOF], f_rate: f64) -> [f64; DOF] {
        let sheave = f_rate + self.out_of_balance_n_per_m * v[SHEAVE];
        self.respond(v, a, sheave, 0.0)
    }

    /// The line's response ([`spring_line::linear_accelerations`]) to the
    /// displacements `u` (m) and rates `rate` (m/s) with the force `sheave`
    /// (N) on the sheave edge and `f_car` (N) on the car: `(force_i - c_i
    /// rate_i) / m_i`, the sheave's zero when held. Accelerations from
    /// positions and velocities; differentiated, jerks from velocities and
    /// accelerations.
    fn respond(&self, u: &[f64], rate: &[f64], sheave: f64, f_car: f64) -> [f64; DOF] {
        let mut out = [0.0; DOF];
        let k = &self.spring;
        let applied = [NodeForce { node: SHEAVE, force_n: sheave }, NodeForce { node: CAR, force_n: f_car }];
        spring_line::linear_accelerations(k, &self.damping, &self.inv_mass, u, rate, &applied, &mut out);
        if self.held {
            out[SHEAVE] = 0.0;
        }
        out
    }

    /// `A x` for the mechanical state `x` (positions m, velocities m/s),
    /// from the chain's structure (no dense matrix).
    fn apply(&self, x: &[f64; MECH]) -> [f64; MECH] {
        let mut out = [0.0; MECH];
        out[..DOF].copy_from_slice(&x[DOF..]);
        if self.held {
            out[SHEAVE] = 0.0;
        }
        let a = self.accel(&x[..DOF], &x[DOF..], -self.out_of_balance_n, 0.0);
        out[DOF..].copy_from_slice(&a);
        out
    }
}

/// `Phi`, `Gamma_j` of one half period at one reference position.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct ExactStep {
    /// Set up for the plant now.
    valid: bool,
    /// Step, s.
    h: f64,
    /// Reference sheave position, m.
    u_ref_m: f64,
    /// Refresh distance, m: `A` holds within half of it of `u_ref_m`.
    distance_m: f64,
    coefficients: Coefficients,
    /// The step as one matrix, column by column, acting on
    /// [`ExactStep::inputs`]: `Phi` (columns 0-9), the responses
    /// `Gamma_j` to `t^j` (N) on the sheave edge (10-13), the response to a
    /// constant force (N) on the car (14), and `int_0^h e^{As} ds`
    /// restricted to the velocity inputs, the responses to a constant
    /// acceleration (m/s^2) of each node (15-19). Column by column, the
    /// product is ten-wide multiply-adds that vectorise.
    columns: [[f64; MECH]; COLUMNS],
}

/// Columns of [`ExactStep::columns`]: the state, four force terms, the car
/// force, five accelerations.
const COLUMNS: usize = MECH + 4 + 1 + DOF;

impl ExactStep {
    /// The state after the step from `x0` with the sheave-edge force
    /// `force` (N / s^j), car force `f_car` (N) and accelerations
    /// `correction` (m/s^2).
    fn apply(&self, x0: &[f64; MECH], force: &[f64; 4], f_car: f64, correction: &[f64; DOF]) -> [f64; MECH] {
        let mut inputs = [0.0; COLUMNS];
        inputs[..MECH].copy_from_slice(x0);
        inputs[MECH..MECH + 4].copy_from_slice(force);
        inputs[MECH + 4] = f_car;
        inputs[MECH + 5..].copy_from_slice(correction);
        let mut out = [0.0; MECH];
        for (column, &z) in self.columns.iter().zip(&inputs) {
            for (o, m) in out.iter_mut().zip(column) {
                *o += m * z;
            }
        }
        out
    }
}

/// `e^{Ah}` and `int_0^h e^{As} ds` (its velocity-input columns) by their
/// Taylor series, column by column.
fn transition(co: &Coefficients, h: f64) -> ([[f64; MECH]; MECH], [[f64; DOF]; MECH]) {
    let mut phi = [[0.0; MECH]; MECH];
    let mut psi = [[0.0; DOF]; MECH];
    for j in 0..MECH {
        // term = (A h)^k e_j / k!
        let mut term = [0.0; MECH];
        term[j] = 1.0;
        for k in 0..TERMS {
            let factor = h / (k + 1) as f64;
            for i in 0..MECH {
                phi[i][j] += term[i];
                if j >= DOF {
                    psi[i][j - DOF] += term[i] * factor;
                }
            }
            term = co.apply(&term).map(|x| x * factor);
        }
    }
    (phi, psi)
}

/// `Gamma_j = int_0^h e^{A(h-s)} b s^j ds` (j = 0..=3) by the Taylor
/// series of `e^{A(h-s)}`: `sum_k A^k b h^(k+j+1) j! / (k+j+1)!`.
fn input_responses(co: &Coefficients, b: &[f64; MECH], h: f64) -> [[f64; MECH]; 4] {
    let mut gamma = [[0.0; MECH]; 4];
    // w = A^k b h^(k+1) / (k+1)!
    let mut w: [f64; MECH] = b.map(|x| x * h);
    for k in 0..TERMS {
        let mut scale = 1.0;
        for (j, g) in gamma.iter_mut().enumerate() {
            if j > 0 {
                scale *= h * j as f64 / (k + j + 1) as f64;
            }
            for i in 0..MECH {
                g[i] += w[i] * scale;
            }
        }
        w = co.apply(&w).map(|x| x * h / (k + 2) as f64);
    }
    gamma
}

/// Cubic Hermite interpolation at `s` in [0, 1] of values `y0`, `y1` and
/// derivatives `d0`, `d1` over an interval of `h`.
fn hermite(s: f64, h: f64, y0: f64, d0: f64, y1: f64, d1: f64) -> f64 {
    let s2 = s * s;
    let s3 = s2 * s;
    (2.0 * s3 - 3.0 * s2 + 1.0) * y0 + (s3 - 2.0 * s2 + s) * h * d0 + (-2.0 * s3 + 3.0 * s2) * y1 + (s3 - s2) * h * d1
}

/// `sum_j c_j t^j`.
fn poly<const N: usize>(c: &[f64; N], t: f64) -> f64 {
    c.iter().rev().fold(0.0, |acc, &x| acc * t + x)
}

/// [`poly`] of a currents' series by pairs (Estrin's scheme): it sits on
/// the path from one half period to the next, three multiply-adds long
/// instead of six.
fn series_at(c: &[f64; SERIES], t: f64) -> f64 {
    const _: () = assert!(SERIES == 7, "written for degree 6");
    let t2 = t * t;
    let t4 = t2 * t2;
    ((c[0] + c[1] * t) + (c[2] + c[3] * t) * t2) + ((c[4] + c[5] * t) + c[6] * t2) * t4
}

impl Plant {
    /// True when a half period of `h` (s) can take the exact
    /// discretisation now (its matrices made ready): the fixed-size nominal
    /// path applies, the rope lengths follow the sheave and stay clear of
    /// their limits, no phase short is injected, and `h` times the chain's
    /// highest rate is at most 0.5.
    pub(crate) fn exact_ready(&mut self, h: f64) -> bool {
        let lw = self.line.counterweight_side_length_m(&self.chain, self.state[SHEAVE]);
        let p = &self.chain.params;
        let applies = self.nominal_path()
            && self.chain.lengths_follow_sheave
            && self.faults.phase_short.is_none()
            && lw > MIN_ROPE_LENGTH_M + 0.01
            && lw < p.rope_total_length_m - MIN_ROPE_LENGTH_M - 0.01
            && h > 0.0;
        if applies {
            self.refresh_exact(h);
        }
        applies && self.exact.valid
    }

    /// Makes `self.exact` hold for a step of `h` (s) from now (a step
    /// within 1e-9 of the last one's takes its matrices).
    fn refresh_exact(&mut self, h: f64) {
        let u = self.state[SHEAVE];
        let v = self.state[DOF + SHEAVE];
        let held = self.inputs.brake_engaged;
        let e = &self.exact;
        let fresh = e.h > 0.0
            && (h - e.h).abs() <= 1e-9 * e.h
            && e.coefficients.held == held
            && (u - e.u_ref_m).abs() <= 0.5 * e.distance_m;
        if fresh {
            return;
        }
        // The same fraction of the shorter side everywhere: the interval
        // (its reference ahead of the sheave by at most half of it) reaches
        // at most the largest distance (4 mm) from here, taken off the side's
        // length so that the side is at least that long all over it.
        let lw = self.line.counterweight_side_length_m(&self.chain, u);
        let shorter = lw.min(self.chain.params.car_side_length_m(lw));
        let distance =
            REFRESH_DISTANCE_M * (shorter - REFRESH_DISTANCE_M * MAX_REFRESH_SCALE).clamp(1.0, MAX_REFRESH_SCALE);
        // Ahead of the sheave when it will cross the interval soon (in 1000
        // steps), centred on it otherwise (at a stop).
        let ahead = if v.abs() * 1000.0 * h > distance { 0.5 * distance * v.signum() } else { 0.0 };
        let u_ref = u + ahead;
        let c = self.coefficients_at(u_ref, held, distance);
        let mut b = [0.0; MECH];
        if !held {
            b[DOF + SHEAVE] = c.inv_mass[SHEAVE];
        }
        let mut b_car = [0.0; MECH];
        b_car[DOF + CAR] = c.inv_mass[CAR];
        let (phi, psi) = transition(&c, h);
        let gamma = input_responses(&c, &b, h);
        let gamma_car = input_responses(&c, &b_car, h)[0];
        let mut columns = [[0.0; MECH]; COLUMNS];
        for i in 0..MECH {
            for j in 0..MECH {
                columns[j][i] = phi[i][j];
            }
            for j in 0..DOF {
                columns[MECH + 5 + j][i] = psi[i][j];
            }
        }
        columns[MECH..MECH + 4].copy_from_slice(&gamma);
        columns[MECH + 4] = gamma_car;
        self.exact = ExactStep {
            valid: h * self.line.omega_max_radps(&self.chain, u_ref, false) <= 0.5,
            h,
            u_ref_m: u_ref,
            distance_m: distance,
            coefficients: c,
            columns,
        };
    }

    /// The chain's coefficients at sheave position `u_ref` (m), with the
    /// springs' and masses' derivatives along it by central differences
    /// over half the refresh distance `distance` (m).
    fn coefficients_at(&self, u_ref: f64, held: bool, distance: f64) -> Coefficients {
        let d = 0.5 * distance;
        let [below, lumped, above]: [Lumped; 3] = [-d, 0.0, d].map(|x| self.line.lumped(&self.chain, u_ref + x));
        let p = &self.chain.params;
        let mut c = Coefficients {
            out_of_balance_n_per_m: 2.0 * p.rope_mass_per_length_kg_per_m * p.gravity_mps2,
            out_of_balance_n: -p.out_of_balance_torque_nm(self.chain.lw_start_m) / p.sheave_radius_m,
            held,
            ..Coefficients::default()
        };
        for i in 0..DOF {
            let (m0, m_lo, m_hi) = (lumped.masses_kg[i], below.masses_kg[i], above.masses_kg[i]);
            c.inv_mass[i] = 1.0 / m0;
            c.damping[i] = lumped.damping_kg_per_s[i];
            c.mass_slope[0][i] = (m_hi - m_lo) / (2.0 * d * m0);
            c.mass_slope[1][i] = (m_hi - 2.0 * m0 + m_lo) / (d * d * m0);
        }
        for i in 0..DOF - 1 {
            let (k0, k_lo, k_hi) = (lumped.springs_n_per_m[i], below.springs_n_per_m[i], above.springs_n_per_m[i]);
            c.spring[i] = k0;
            c.spring_slope[0][i] = (k_hi - k_lo) / (2.0 * d);
            c.spring_slope[1][i] = (k_hi - 2.0 * k0 + k_lo) / (d * d);
        }
        c
    }

    /// Taylor coefficients (t^0..t^6) of the machine currents `(i_d, i_q)`
    /// (A / s^k) over the half period: the voltage equations differentiated
    /// term by term, for the electrical speed `w(t) = w[0] + w[1] t + w[2]
    /// t^2` (rad/s) and `cos`, `sin` of the electrical angle at the start;
    /// the first `TERMS` (at most [`SERIES`]), the others zero (a constant,
    /// so that the recursion unrolls).
    fn current_series<const TERMS: usize>(&self, w: [f64; 3], c: f64, s: f64) -> ([f64; SERIES], [f64; SERIES]) {
        let n = STATE_LEN - 2;
        let mut id = [0.0; SERIES];
        let mut iq = [0.0; SERIES];
        (id[0], iq[0]) = (self.state[n], self.state[n + 1]);
        if !self.inputs.pwm_enabled {
            return (id, iq);
        }
        let m = &self.pmsm;
        let (r, ld, lq, psi) = (m.resistance_ohm, m.ld_h, m.lq_h, m.flux_linkage_wb);
        let (inv_ld, inv_lq) = (1.0 / ld, 1.0 / lq);
        let (va, vb) = self.v_alpha_beta;
        let mut vd = [0.0; SERIES];
        let mut vq = [0.0; SERIES];
        (vd[0], vq[0]) = (va * c + vb * s, -va * s + vb * c);
        let (lq_w0, ld_w0) = (lq * w[0], ld * w[0]);
        for k in 0..TERMS - 1 {
            // (w y)[k] = sum_j w[j] y[k - j]; the currents' older terms
            // (j >= 1) apart, so that the chain from one coefficient to
            // the next is four operations long.
            let (mut old_id, mut old_iq, mut w_vd, mut w_vq) = (0.0, 0.0, w[0] * vd[k], w[0] * vq[k]);
            for j in 1..3.min(k + 1) {
                old_id += w[j] * id[k - j];
                old_iq += w[j] * iq[k - j];
                w_vd += w[j] * vd[k - j];
                w_vq += w[j] * vq[k - j];
            }
            let scale = INVERSE[k];
            let psi_w = if k < 3 { psi * w[k] } else { 0.0 };
            id[k + 1] = ((vd[k] + lq * old_iq) + (lq_w0 * iq[k] - r * id[k])) * (inv_ld * scale);
            iq[k + 1] = ((vq[k] - ld * old_id - psi_w) - (r * iq[k] + ld_w0 * id[k])) * (inv_lq * scale);
            vd[k + 1] = w_vq * scale;
            vq[k + 1] = -w_vd * scale;
        }
        (id, iq)
    }

    /// Shaft torque (N m) as a cubic in time from the current series and
    /// the ripple's Taylor coefficients `q` along the shaft angle
    /// `theta_0 + w t + alpha t^2/2 + jerk t^3/6` (`motion = [w, alpha,
    /// jerk]`, rad/s^k).
    fn torque_cubic(&self, id: &[f64; SERIES], iq: &[f64; SERIES], q: &[f64; 4], motion: [f64; 3]) -> [f64; 4] {
        let m = &self.pmsm;
        let k = 1.5 * m.pole_pairs;
        let [w, alpha, jerk] = motion;
        let ripple = [
            q[0],
            q[1] * w,
            0.5 * q[1] * alpha + q[2] * w * w,
            q[1] * jerk / 6.0 + q[2] * w * alpha + q[3] * w * w * w,
        ];
        let mut torque = [0.0; 4];
        for j in 0..4 {
            let product: f64 = (0..=j).map(|i| id[i] * iq[j - i]).sum();
            torque[j] = k * (m.flux_linkage_wb * iq[j] + (m.ld_h - m.lq_h) * product) + ripple[j];
        }
        torque
    }

    /// Advances one half period of `h` (s) exactly (see the module), calling
    /// `on_sample(i, observation)` at offsets `offsets_s[i]` (s, ascending,
    /// in `[0, h)`).
    pub(crate) fn advance_exact(
        &mut self,
        h: f64,
        offsets_s: &[f64],
        on_sample: &mut dyn FnMut(usize, &PlantObservation),
    ) {
        let r = self.chain.params.sheave_radius_m;
        let p = self.pmsm.pole_pairs;
        let theta0 = self.state[SHEAVE] / r;
        let turn = self.state[DOF + SHEAVE] / r * h;
        self.angle.ensure_ahead(theta0, turn, &self.ripple, p);
        let q = self.angle.ripple_taylor(theta0);
        let (c, s) = self.angle.park(theta0, p);
        let co = self.exact.coefficients;
        let f_car = self.faults.car_extra_force_n;
        let mut x0 = [0.0; MECH];
        x0.copy_from_slice(&self.state[..MECH]);
        let (u0, v0) = (&x0[..DOF], &x0[DOF..]);
        let n = STATE_LEN - 2;
        let torque0 = self.pmsm.torque_nm(self.state[n], self.state[n + 1]) + q[0];
        let du = u0[SHEAVE] + 0.5 * h * v0[SHEAVE] - self.exact.u_ref_m;
        let mut stretch = [0.0; DOF - 1];
        for i in 0..DOF - 1 {
            stretch[i] = u0[i + 1] - u0[i] + 0.5 * h * (v0[i + 1] - v0[i]);
        }
        let frozen = co.accel(u0, v0, torque0 / r, f_car);
        let correction = co.variation(du, &stretch, &frozen);
        let a0: [f64; DOF] = std::array::from_fn(|i| frozen[i] + correction[i]);
        let (omega, alpha) = (v0[SHEAVE] / r, a0[SHEAVE] / r);
        // The shaft's jerk needs the torque's rate, which needs the currents'
        // first terms (the series' first two terms depend on `w[0]` alone).
        let (id, iq) = self.current_series::<2>([p * omega, 0.0, 0.0], c, s);
        let rate = self.torque_cubic(&id, &iq, &q, [omega, alpha, 0.0])[1];
        let jerk = co.jerk(v0, &a0, rate / r)[SHEAVE] / r;
        let (id, iq) = self.current_series::<SERIES>([p * omega, p * alpha, 0.5 * p * jerk], c, s);
        let force = self.torque_cubic(&id, &iq, &q, [omega, alpha, jerk]).map(|x| x / r);
        let e = &self.exact;
        let f0 = force[0] + co.out_of_balance_n;
        let mut x1 = e.apply(&x0, &[f0, force[1], force[2], force[3]], f_car, &correction);
        if co.held {
            x1[SHEAVE] = x0[SHEAVE];
            x1[DOF + SHEAVE] = 0.0;
        }
        if !offsets_s.is_empty() {
            let du0 = u0[SHEAVE] - self.exact.u_ref_m;
            let stretch0: [f64; DOF - 1] = std::array::from_fn(|i| u0[i + 1] - u0[i]);
            let at_start = co.variation(du0, &stretch0, &frozen);
            let a0_sample: [f64; DOF] = std::array::from_fn(|i| frozen[i] + at_start[i]);
            let ends = SampleEnds { x0, x1, a0: a0_sample, force, f_car, h, id, iq };
            for (i, &tau) in offsets_s.iter().enumerate() {
                let o = self.sample_inside(&ends, tau);
                on_sample(i, &o);
            }
        }
        self.state[..MECH].copy_from_slice(&x1);
        self.state[n] = series_at(&id, h);
        self.state[n + 1] = series_at(&iq, h);
        let theta1 = self.state[SHEAVE] / r;
        self.angle.ensure_ahead(theta1, theta1 - theta0, &self.ripple, p);
    }

    /// The observation at offset `tau` (s) inside the half period `ends`.
    fn sample_inside(&self, ends: &SampleEnds, tau: f64) -> PlantObservation {
        let co = &self.exact.coefficients;
        let h = ends.h;
        let (u0, v0) = (&ends.x0[..DOF], &ends.x0[DOF..]);
        let (u1, v1) = (&ends.x1[..DOF], &ends.x1[DOF..]);
        let f = &ends.force;
        let f_rate_at = |t: f64| (3.0 * f[3] * t + 2.0 * f[2]) * t + f[1];
        let j0 = co.jerk(v0, &ends.a0, f_rate_at(0.0));
        let frozen = co.accel(u1, v1, poly(f, h), ends.f_car);
        let du = u1[SHEAVE] - self.exact.u_ref_m;
        let stretch: [f64; DOF - 1] = std::array::from_fn(|i| u1[i + 1] - u1[i]);
        let correction = co.variation(du, &stretch, &frozen);
        let a1: [f64; DOF] = std::array::from_fn(|i| frozen[i] + correction[i]);
        let j1 = co.jerk(v1, &a1, f_rate_at(h));
        let sf = tau / h;
        let at = |i: usize| hermite(sf, h, ends.a0[i], j0[i], a1[i], j1[i]);
        let u_sh = hermite(sf, h, u0[SHEAVE], v0[SHEAVE], u1[SHEAVE], v1[SHEAVE]);
        let v_sh = hermite(sf, h, v0[SHEAVE], ends.a0[SHEAVE], v1[SHEAVE], a1[SHEAVE]);
        let u_car = hermite(sf, h, u0[CAR], v0[CAR], u1[CAR], v1[CAR]);
        let r = self.chain.params.sheave_radius_m;
        let theta = u_sh / r;
        let (ripple, c, s) = self.angle.eval(theta, &self.ripple, self.pmsm.pole_pairs);
        let (id, iq) = (series_at(&ends.id, tau), series_at(&ends.iq, tau));
        PlantObservation {
            car_acceleration_mps2: at(CAR),
            counterweight_acceleration_mps2: -at(CW),
            phase_currents_a: phase_currents_cs_a(id, iq, c, s),
            motor_torque_nm: self.pmsm.torque_nm(id, iq),
            ripple_torque_nm: ripple,
            shaft_speed_radps: v_sh / r,
            shaft_angle_rad: theta,
            counterweight_side_length_m: self.line.counterweight_side_length_m(&self.chain, u_sh),
            car_position_m: u_car,
        }
    }
}

/// What a sample inside a half period interpolates between.
struct SampleEnds {
    /// Mechanical state at the start.
    x0: [f64; MECH],
    /// Mechanical state at the end.
    x1: [f64; MECH],
    /// Accelerations at the start, m/s^2.
    a0: [f64; DOF],
    /// Drive force on the sheave edge, cubic in time, N / s^j.
    force: [f64; 4],
    /// Extra car force, N.
    f_car: f64,
    /// Half period, s.
    h: f64,
    /// `i_d` series, A / s^k.
    id: [f64; SERIES],
    /// `i_q` series, A / s^k.
    iq: [f64; SERIES],
}

#[cfg(test)]
mod tests {
    use super::super::{Integrator, PlantInputs};
    use super::*;
    use rig_config::RigConfig;

    /// What a run of half periods records: the machine currents and sheave
    /// speed at the ends, the car acceleration at the samples.
    struct Run {
        ends: Vec<[f64; 3]>,
        car: Vec<f64>,
    }

    /// `plant` over `periods` half periods of `h` (s): inputs that change
    /// every half period, the brake applied for the first 200 and the PWM off
    /// for 50 in the middle, a sample at a varying offset in each.
    fn run(mut plant: Plant, h: f64, periods: usize) -> Run {
        let mut out = Run { ends: Vec::new(), car: Vec::new() };
        for k in 0..periods {
            let c = (1300.0 + 900.0 * (k as f64 * 0.37).sin()) as u16;
            plant.set_inputs(PlantInputs {
                pwm_compare: [c, 2600 - c / 2, 900],
                pwm_enabled: !(2000..2050).contains(&k),
                brake_engaged: k < 200,
            });
            let t0 = plant.time_s();
            let sample = [t0 + h * (0.05 + 0.9 * ((k * 7) % 11) as f64 / 11.0)];
            plant.advance_until(t0 + h, 0.0625 * h, &sample, |_, o| out.car.push(o.car_acceleration_mps2));
            let o = plant.observe();
            out.ends.push([plant.state[2 * DOF], plant.state[2 * DOF + 1], o.shaft_speed_radps]);
            if plant.integrator == Integrator::Fast {
                assert!(plant.exact.valid && (plant.exact.h - h).abs() < 1e-9 * h, "the exact step ran");
            }
        }
        out
    }

    /// The exact half-period step against the reference RK4 at an eighth of
    /// the half period, open loop over 0.25 s (the sheave reaching about
    /// 0.1 m/s, the rope lengths changing, the brake released, the PWM off
    /// and on): the car acceleration within 1e-5 of its RMS, the currents
    /// and the shaft speed within 1e-8 of theirs.
    #[test]
    fn the_exact_step_matches_the_reference_open_loop() {
        let rig = RigConfig::embedded_default().unwrap();
        let h = 0.5 / rig.control.current_loop_hz;
        for (m_car, lw) in [(70.5, 1.2), (33.0, 7.3)] {
            let fast = Plant::new(&rig, m_car, lw);
            let mut reference = Plant::new(&rig, m_car, lw);
            reference.set_integrator(Integrator::Reference);
            let (a, b) = (run(fast, h, 8000), run(reference, h, 8000));
            let rms = |x: &mut dyn Iterator<Item = f64>| {
                let v: Vec<f64> = x.collect();
                (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
            };
            let car_scale = rms(&mut b.car.iter().copied());
            let car_diff = rms(&mut a.car.iter().zip(&b.car).map(|(x, y)| x - y));
            println!(
                "m_car {m_car} lw {lw}: car acceleration RMS {car_scale:.3e}, difference {:.2e}",
                car_diff / car_scale
            );
            assert!(car_scale > 1e-2 && car_diff < 1e-5 * car_scale, "{car_diff} of {car_scale}");
            for i in 0..3 {
                let scale = rms(&mut b.ends.iter().map(|e| e[i]));
                let diff = rms(&mut a.ends.iter().zip(&b.ends).map(|(x, y)| x[i] - y[i]));
                println!("  end value {i}: RMS {scale:.3e}, difference {:.2e}", diff / scale);
                assert!(scale > 1e-3 && diff < 1e-8 * scale, "{i}: {diff} of {scale}");
            }
        }
    }
}
