//! The plant's rope chain as a line of lumped masses joined by springs,
//! built from [`ChainParams`] and the mechanical effects of [`Effects`]: the
//! nominal 5-DOF chain of Eqn 1-6 when no effect is on, and otherwise a
//! longer line (up to [`MAX_NODES`] coordinates).
//!
//! Nodes, from the counterweight end to the car end (every coordinate a
//! displacement from the static equilibrium at the start, positive in the
//! rope's direction when the car goes up, like [`super::rope`]):
//!
//! `cw`, `N` counterweight-side rope masses (the nearest to the counterweight
//! first), `sheave` (`u_sh = r0 theta`), [`pulley`], `N` car-side rope masses
//! (the nearest to the sheave first), car `hitch`, [car `body`].
//!
//! `N` is `rope_discretization`'s (1 without it: Eqn 1-2), the pulley node
//! is there with `diverting_pulley`, the body with `car_frame_mode` (the car
//! is then split into hitch and body joined by the frame spring and damper;
//! without it the hitch is the whole car and carries the accelerometer).
//! Springs join consecutive nodes. Rope lengths follow the rope's motion at
//! the sheave, `l_w = l_w0 + g(theta)` (Eqn 3; `g = u_sh` without
//! `sheave_eccentricity`), so masses and stiffnesses change during a travel.
//!
//! The forces are summed in [`super::spring_line`], the one place every
//! integrator of the plant, the free decay and the diagnosis's models take
//! them from; with `N = 1` and no other mechanical effect the line is the
//! nominal chain of Eqn 5 (a test holds it to the paper's stiffness-matrix
//! form).

use super::effects::rope_discretization::{element_mass_kg, elements_per_side, spring_n_per_m, MAX_ELEMENTS};
use super::effects::tension_stiffening::{rope_ea_n, static_tension_n};
use super::effects::Effects;
use super::mechanics::{Chain, MIN_ROPE_LENGTH_M};
use super::rope::ChainParams;
use super::spring_line::{self, NodeForce};

/// Most coordinates of the line: counterweight, `2 * 8` rope masses,
/// sheave, pulley, hitch and body.
pub const MAX_NODES: usize = 2 * MAX_ELEMENTS + 5;

/// Where each body sits in the line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    /// Number of coordinates.
    pub nodes: usize,
    /// Rope elements per side.
    pub elements: usize,
    /// Index of the sheave edge.
    pub sheave: usize,
    /// Index of the pulley rim, with `diverting_pulley`.
    pub pulley: Option<usize>,
    /// Index of the car's rope hitch (the whole car without `car_frame_mode`).
    pub hitch: usize,
    /// Index of the body carrying the accelerometer (`hitch` without `car_frame_mode`).
    pub body: usize,
}

impl Layout {
    /// The layout `effects` give.
    pub fn new(effects: &Effects) -> Self {
        let n = elements_per_side(effects.rope_discretization.as_ref());
        let sheave = n + 1;
        let pulley = effects.diverting_pulley.map(|_| sheave + 1);
        let hitch = pulley.unwrap_or(sheave) + n + 1;
        let body = if effects.car_frame_mode.is_some() { hitch + 1 } else { hitch };
        Self { nodes: body + 1, elements: n, sheave, pulley, hitch, body }
    }

    /// Index of the counterweight (always 0).
    pub fn counterweight(&self) -> usize {
        0
    }

    /// The counterweight-side rope node nearest the middle of the side.
    pub fn middle_cw_rope(&self) -> usize {
        1 + (self.elements - 1) / 2
    }

    /// The car-side rope node nearest the middle of the side below the
    /// sheave (or pulley).
    pub fn middle_car_rope(&self) -> usize {
        self.pulley.unwrap_or(self.sheave) + 1 + self.elements / 2
    }
}

/// What the brake does to the sheave in one evaluation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BrakeAction {
    /// Released: the sheave is free.
    Released,
    /// Applied, nominal: the sheave is held rigidly (its acceleration and
    /// velocity are zero).
    Held,
    /// Applied through the elastic clamp of `brake_stop`, clamped at
    /// `angle_rad` (rad).
    Clamped {
        /// Clamp angle, rad.
        angle_rad: f64,
    },
}

/// A step's coefficients of the line ([`Line::coefficients`]): the lumped
/// values, the masses inverted, the out-of-balance torque evaluated.
#[derive(Clone, Copy, Debug)]
pub struct Coefficients<'a> {
    /// Masses, springs and damping.
    pub lumped: &'a Lumped,
    /// `1 / m_i`, 1/kg (the first `nodes`).
    pub inv_mass: [f64; MAX_NODES],
    /// Sheave radius `r0`, m.
    pub radius_m: f64,
    /// `1 / r0`, 1/m.
    pub inv_radius_per_m: f64,
    /// Out-of-balance torque of Eqn 4, N m.
    pub out_of_balance_nm: f64,
}

/// Masses, springs and damping of the line at one configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lumped {
    /// Counterweight-side rope length, m (clamped to the model's range).
    pub lw_m: f64,
    /// Node masses, kg (the first `nodes` are used).
    pub masses_kg: [f64; MAX_NODES],
    /// `springs[i]` joins nodes `i` and `i + 1`, N/m.
    pub springs_n_per_m: [f64; MAX_NODES],
    /// Viscous damping on each node's absolute velocity, kg/s.
    pub damping_kg_per_s: [f64; MAX_NODES],
    /// Damper between hitch and body (frame mode), kg/s.
    pub frame_damping_kg_per_s: f64,
}

impl Lumped {
    /// Every value zero (the start of [`Line::lumped_into`]'s buffer).
    pub fn zeroed() -> Self {
        Self {
            lw_m: 0.0,
            masses_kg: [0.0; MAX_NODES],
            springs_n_per_m: [0.0; MAX_NODES],
            damping_kg_per_s: [0.0; MAX_NODES],
            frame_damping_kg_per_s: 0.0,
        }
    }
}

/// The line for a chain and its effects (only the mechanical effects
/// matter here: tension stiffening, pulley, discretisation, frame mode,
/// guide friction, brake clamp, sheave eccentricity).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Line {
    /// The effects.
    pub effects: Effects,
    /// Node indices.
    pub layout: Layout,
}

impl Line {
    /// The line of `effects`.
    pub fn new(effects: &Effects) -> Self {
        Self { effects: *effects, layout: Layout::new(effects) }
    }

    /// Rope displacement at the sheave, m, for sheave coordinate
    /// `u_sh_m` (m): `g(theta)` with eccentricity, `u_sh` without.
    pub fn sheave_rope_displacement_m(&self, params: &ChainParams, u_sh_m: f64) -> f64 {
        match &self.effects.sheave_eccentricity {
            None => u_sh_m,
            Some(e) => e.rope_displacement_m(params.sheave_radius_m, u_sh_m / params.sheave_radius_m),
        }
    }

    /// Counterweight-side rope length, m, unclamped (Eqn 3 with `g`).
    pub fn counterweight_side_length_m(&self, chain: &Chain, u_sh_m: f64) -> f64 {
        if chain.lengths_follow_sheave {
            chain.lw_start_m + self.sheave_rope_displacement_m(&chain.params, u_sh_m)
        } else {
            chain.lw_start_m
        }
    }

    /// Largest counterweight-side length the model accepts, m (the car
    /// side keeps [`MIN_ROPE_LENGTH_M`] below the pulley).
    fn lw_max_m(&self, p: &ChainParams) -> f64 {
        match &self.effects.diverting_pulley {
            None => p.rope_total_length_m - MIN_ROPE_LENGTH_M,
            Some(pulley) => p.rope_total_length_m - MIN_ROPE_LENGTH_M - pulley.sheave_to_pulley_m,
        }
    }

    /// Masses, springs and damping with the sheave at `u_sh_m` (m).
    pub fn lumped(&self, chain: &Chain, u_sh_m: f64) -> Lumped {
        let mut out = Lumped::zeroed();
        self.lumped_into(chain, u_sh_m, &mut out);
        out
    }

    /// [`Line::lumped`] written into `out`, which must hold zeros or an
    /// earlier result of this line (every call writes the same entries, the
    /// others stay zero): the integrator's per-step buffer, neither zeroed
    /// nor copied at each step.
    pub fn lumped_into(&self, chain: &Chain, u_sh_m: f64, out: &mut Lumped) {
        let p = &chain.params;
        let e = &self.effects;
        let layout = &self.layout;
        let lw = self.counterweight_side_length_m(chain, u_sh_m).clamp(MIN_ROPE_LENGTH_M, self.lw_max_m(p));
        let lc = p.car_side_length_m(lw);
        let n = layout.elements;
        let mu = p.rope_mass_per_length_kg_per_m;
        let g = p.gravity_mps2;
        let stiffening = e.tension_stiffening.as_ref();
        out.lw_m = lw;
        // Counterweight side, listed from the counterweight up.
        out.masses_kg[0] = p.m_cw_kg;
        let cw_element = element_mass_kg(lw, n, mu);
        for j in 0..n {
            out.masses_kg[1 + j] = cw_element;
        }
        let cw_spring = |j: usize| spring_n_per_m(lw, n, j, mu, p.rope_ea_n, p.m_cw_kg, g, stiffening);
        fill_side(&mut out.springs_n_per_m[..=n], stiffening.is_none(), cw_spring);
        let r = p.sheave_radius_m;
        out.masses_kg[layout.sheave] = p.sheave_inertia_kg_m2 / (r * r);
        // Car side, from the sheave (or pulley) down.
        let mut top = layout.sheave;
        let mut hanging = lc;
        if let (Some(pulley), Some(node)) = (&e.diverting_pulley, layout.pulley) {
            hanging = pulley.rope_below_pulley_m(lc);
            let tension = static_tension_n(p.m_car_kg, mu, hanging, g);
            out.springs_n_per_m[layout.sheave] =
                pulley.segment_stiffness_n_per_m(rope_ea_n(stiffening, p.rope_ea_n, tension));
            out.masses_kg[node] = pulley.equivalent_mass_kg(mu);
            top = node;
        }
        let car_element = element_mass_kg(hanging, n, mu);
        for j in 0..n {
            out.masses_kg[top + 1 + j] = car_element;
        }
        // Spring top + j is the side's spring n - j counted from the car.
        let car_spring = |j: usize| spring_n_per_m(hanging, n, n - j, mu, p.rope_ea_n, p.m_car_kg, g, stiffening);
        fill_side(&mut out.springs_n_per_m[top..=top + n], stiffening.is_none(), car_spring);
        match &e.car_frame_mode {
            None => out.masses_kg[layout.hitch] = p.m_car_kg,
            Some(frame) => {
                out.masses_kg[layout.hitch] = frame.hitch_mass_kg(p.m_car_kg);
                out.masses_kg[layout.body] = frame.body_mass_kg(p.m_car_kg);
                out.springs_n_per_m[layout.hitch] = frame.stiffness_n_per_m(p.m_car_kg);
                out.frame_damping_kg_per_s = frame.damping_kg_per_s(p.m_car_kg);
            }
        }
        out.damping_kg_per_s[0] = p.c_cw_kg_per_s;
        out.damping_kg_per_s[layout.sheave] = p.c_sheave_nms_per_rad / (r * r);
        out.damping_kg_per_s[layout.hitch] = p.c_car_kg_per_s;
        if let (Some(pulley), Some(node)) = (&e.diverting_pulley, layout.pulley) {
            out.damping_kg_per_s[node] =
                pulley.damping_kg_per_s(out.springs_n_per_m[layout.sheave], out.masses_kg[node]);
        }
    }

    /// Node accelerations (m/s^2) into `accel` (the first `nodes`), for
    /// positions `position_m` (m) and velocities `velocity_mps` (m/s) of
    /// the nodes, shaft torque `shaft_torque_nm` (N m, positive lifts the
    /// car), the brake's action and an extra vertical force on the car body
    /// `car_extra_force_n` (N, positive up).
    ///
    /// Forces: springs between consecutive nodes; the drive's torque minus
    /// the out-of-balance torque (Eqn 4) on the sheave, through the lever
    /// ratio `r(theta)/r0` with eccentricity (which also applies to every
    /// rope force on the sheave, whose rope end sits at `g(theta)`); viscous
    /// guide damping on counterweight and hitch, `c_sh / r^2` on the sheave;
    /// dry guide friction on counterweight and hitch; the frame damper
    /// between hitch and body; the brake (held, or the elastic clamp).
    #[allow(clippy::too_many_arguments)]
    pub fn accelerations(
        &self,
        chain: &Chain,
        position_m: &[f64],
        velocity_mps: &[f64],
        shaft_torque_nm: f64,
        brake: BrakeAction,
        car_extra_force_n: f64,
        accel: &mut [f64],
    ) {
        let lumped = self.lumped(chain, position_m[self.layout.sheave]);
        self.accelerations_of(
            chain,
            &lumped,
            position_m,
            velocity_mps,
            shaft_torque_nm,
            brake,
            car_extra_force_n,
            accel,
        );
    }

    /// [`Line::accelerations`] with the masses, springs and damping
    /// `lumped` given (m/s^2 into `accel`): the plant's integrator evaluates
    /// them once per step, at the step's midpoint, instead of at every
    /// stage.
    #[allow(clippy::too_many_arguments)]
    pub fn accelerations_of(
        &self,
        chain: &Chain,
        lumped: &Lumped,
        position_m: &[f64],
        velocity_mps: &[f64],
        shaft_torque_nm: f64,
        brake: BrakeAction,
        car_extra_force_n: f64,
        accel: &mut [f64],
    ) {
        let step = self.coefficients(chain, lumped);
        self.accelerations_with(&step, position_m, velocity_mps, shaft_torque_nm, brake, car_extra_force_n, accel);
    }

    /// The coefficients of `lumped` for [`Line::accelerations_with`]: the
    /// masses inverted (once per run of equal masses) and the
    /// out-of-balance torque (Eqn 4) evaluated.
    pub fn coefficients<'a>(&self, chain: &Chain, lumped: &'a Lumped) -> Coefficients<'a> {
        let mut inv_mass = [0.0; MAX_NODES];
        let mut last = (f64::NAN, f64::NAN);
        for (inv, &m) in inv_mass.iter_mut().zip(&lumped.masses_kg).take(self.layout.nodes) {
            if m != last.0 {
                last = (m, 1.0 / m);
            }
            *inv = last.1;
        }
        let p = &chain.params;
        Coefficients {
            lumped,
            inv_mass,
            inv_radius_per_m: 1.0 / p.sheave_radius_m,
            radius_m: p.sheave_radius_m,
            out_of_balance_nm: p.out_of_balance_torque_nm(lumped.lw_m),
        }
    }

    /// [`Line::accelerations`] with the coefficients `step` given
    /// ([`Line::coefficients`]): the springs' tensions and the node forces
    /// of [`spring_line::accelerations`], then the forces at the guides, the
    /// frame damper and the brake.
    #[allow(clippy::too_many_arguments)]
    pub fn accelerations_with(
        &self,
        step: &Coefficients,
        position_m: &[f64],
        velocity_mps: &[f64],
        shaft_torque_nm: f64,
        brake: BrakeAction,
        car_extra_force_n: f64,
        accel: &mut [f64],
    ) {
        let layout = &self.layout;
        let (n, sheave) = (layout.nodes, layout.sheave);
        let lumped = step.lumped;
        let (k, c, inv_m) = (&lumped.springs_n_per_m[..n], &lumped.damping_kg_per_s[..n], &step.inv_mass[..n]);
        let r = step.radius_m;
        let mut torque = shaft_torque_nm;
        if let BrakeAction::Clamped { angle_rad } = brake {
            if let Some(clamp) = &self.effects.brake_stop {
                torque += clamp.torque_nm(position_m[sheave] / r, angle_rad, velocity_mps[sheave] / r);
            }
        }
        let car = NodeForce { node: layout.body, force_n: car_extra_force_n };
        let spring = |i: usize, e: f64| k[i] * e;
        match &self.effects.sheave_eccentricity {
            None => {
                let drive =
                    NodeForce { node: sheave, force_n: (torque - step.out_of_balance_nm) * step.inv_radius_per_m };
                spring_line::linear_accelerations(k, c, inv_m, position_m, velocity_mps, &[drive, car], accel);
            }
            Some(e) => {
                // The rope at the sheave sits at g(theta), and every force on
                // the sheave acts through the lever ratio r(theta) / r0.
                let theta = position_m[sheave] / r;
                let mut ends = [0.0; MAX_NODES];
                ends[..n].copy_from_slice(&position_m[..n]);
                ends[sheave] = e.rope_displacement_m(r, theta);
                spring_line::linear_accelerations(k, c, inv_m, &ends, velocity_mps, &[car], accel);
                let lever = e.lever_ratio(theta);
                let elastic = spring(sheave, ends[sheave + 1] - ends[sheave])
                    - spring(sheave - 1, ends[sheave] - ends[sheave - 1]);
                let drive = (torque - step.out_of_balance_nm * lever) * step.inv_radius_per_m;
                accel[sheave] = (elastic * lever + drive - c[sheave] * velocity_mps[sheave]) * inv_m[sheave];
            }
        }
        spring_line::add_guide_forces(&self.effects, &[0, layout.hitch], velocity_mps, inv_m, accel);
        spring_line::add_damper((layout.hitch, layout.body), lumped.frame_damping_kg_per_s, velocity_mps, inv_m, accel);
        if brake == BrakeAction::Held {
            accel[sheave] = 0.0;
        }
    }

    /// An upper bound of the line's highest rate, rad/s, with the sheave at
    /// `u_sh_m` (m): Gershgorin's bound `sqrt(max_i sum_j |K_ij| / m_i)` of
    /// the elastic frequencies (with the brake clamp as a spring to ground),
    /// and the damping and dry-friction rates `c / m`, `F / (v_slip m)`.
    /// An explicit RK4 step `h` with `h omega_max <= 1` is stable and
    /// accurate.
    pub fn omega_max_radps(&self, chain: &Chain, u_sh_m: f64, clamped: bool) -> f64 {
        let lumped = self.lumped(chain, u_sh_m);
        let layout = &self.layout;
        let k = &lumped.springs_n_per_m;
        let mut elastic: f64 = 0.0;
        let mut rate: f64 = 0.0;
        for i in 0..layout.nodes {
            let left = if i > 0 { k[i - 1] } else { 0.0 };
            let right = if i + 1 < layout.nodes { k[i] } else { 0.0 };
            let mut row = 2.0 * (left + right);
            let mut c = lumped.damping_kg_per_s[i];
            if i == layout.sheave && clamped {
                if let Some(clamp) = &self.effects.brake_stop {
                    let r2 = chain.params.sheave_radius_m * chain.params.sheave_radius_m;
                    row += clamp.clamp_stiffness_nm_per_rad / r2;
                    c += clamp.clamp_damping_nms_per_rad / r2;
                }
            }
            if (i == layout.hitch || i == layout.body) && layout.body != layout.hitch {
                c += 2.0 * lumped.frame_damping_kg_per_s;
            }
            let m = lumped.masses_kg[i];
            elastic = elastic.max(row / m);
            rate = rate.max(c / m);
            if i == 0 || i == layout.hitch {
                rate = rate.max(self.effects.guide_force_rate_per_s(m));
            }
        }
        elastic.sqrt().max(rate)
    }

    /// Kinetic plus elastic energy of the line, J, plus the potential of
    /// the out-of-balance torque (`tau_ob g(theta) / r0`) and of a brake
    /// clamp: conserved without damping, friction, drive torque and with
    /// the rope lengths frozen (`Chain::lengths_follow_sheave = false`).
    pub fn mechanical_energy_j(
        &self,
        chain: &Chain,
        position_m: &[f64],
        velocity_mps: &[f64],
        clamp_angle_rad: Option<f64>,
    ) -> f64 {
        let p = &chain.params;
        let layout = &self.layout;
        let sheave = layout.sheave;
        let lumped = self.lumped(chain, position_m[sheave]);
        let mut ends = [0.0; MAX_NODES];
        ends[..layout.nodes].copy_from_slice(&position_m[..layout.nodes]);
        ends[sheave] = self.sheave_rope_displacement_m(p, position_m[sheave]);
        let kinetic: f64 =
            (0..layout.nodes).map(|i| 0.5 * lumped.masses_kg[i] * velocity_mps[i] * velocity_mps[i]).sum();
        let elastic: f64 =
            (0..layout.nodes - 1).map(|i| 0.5 * lumped.springs_n_per_m[i] * (ends[i + 1] - ends[i]).powi(2)).sum();
        let gravity = p.out_of_balance_torque_nm(lumped.lw_m) * ends[sheave] / p.sheave_radius_m;
        let clamp = match (clamp_angle_rad, &self.effects.brake_stop) {
            (Some(angle), Some(b)) => {
                0.5 * b.clamp_stiffness_nm_per_rad * (position_m[sheave] / p.sheave_radius_m - angle).powi(2)
            }
            _ => 0.0,
        };
        kinetic + elastic + gravity + clamp
    }
}

/// The springs of one side, `springs[j] = spring(j)`: with `uniform` (no
/// tension stiffening) the end springs are all one value and the inner
/// ones another, so each is computed once (the same arithmetic).
fn fill_side(springs: &mut [f64], uniform: bool, spring: impl Fn(usize) -> f64) {
    let last = springs.len() - 1;
    if uniform && last >= 1 {
        let end = spring(0);
        let inner = if last >= 2 { spring(1) } else { end };
        springs.fill(inner);
        springs[0] = end;
        springs[last] = end;
    } else {
        for (j, slot) in springs.iter_mut().enumerate() {
            *slot = spring(j);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::EffectKind;
    use crate::rope::DOF;
    use rig_config::RigConfig;

    fn chain(m_car: f64, lw: f64) -> Chain {
        Chain::new(ChainParams::from_rig(&RigConfig::embedded_default().unwrap(), m_car), lw)
    }

    #[test]
    fn layouts() {
        let nominal = Layout::new(&Effects::none());
        assert_eq!((nominal.nodes, nominal.sheave, nominal.hitch, nominal.body), (DOF, 2, 4, 4));
        let mut e = Effects::none();
        e.set(EffectKind::RopeDiscretization, &[8.0]).unwrap();
        e.set(EffectKind::DivertingPulley, &EffectKind::DivertingPulley.defaults()).unwrap();
        e.set(EffectKind::CarFrameMode, &EffectKind::CarFrameMode.defaults()).unwrap();
        let l = Layout::new(&e);
        assert_eq!(l.nodes, MAX_NODES);
        assert_eq!((l.sheave, l.pulley, l.hitch, l.body), (9, Some(10), 19, 20));
    }

    /// Eqn 5 as the paper writes it, `M(l) x'' + C x' + K(l) x = dF`, with
    /// the stiffness matrix assembled (`ChainParams::stiffness_matrix`):
    /// the line's accelerations checked against an independent form.
    fn paper_chain_acceleration(chain: &Chain, state: &crate::ChainState, torque_nm: f64, held: bool) -> [f64; DOF] {
        let p = &chain.params;
        let lw = chain.counterweight_side_length_m(state);
        let (masses, k, c) = (p.masses_kg(lw), p.stiffness_matrix(lw), p.damping_kg_per_s());
        let mut force = [0.0; DOF];
        force[crate::rope::SHEAVE] = (torque_nm - p.out_of_balance_torque_nm(lw)) / p.sheave_radius_m;
        let mut accel = [0.0; DOF];
        for i in 0..DOF {
            let elastic: f64 = (0..DOF).map(|j| k[i][j] * state.position_m[j]).sum();
            accel[i] = (force[i] - c[i] * state.velocity_mps[i] - elastic) / masses[i];
        }
        if held {
            accel[crate::rope::SHEAVE] = 0.0;
        }
        accel
    }

    /// The line without effects is the nominal chain of Eqn 5 at arbitrary
    /// states (and with N = 1, alpha = 0 switched on): the same
    /// accelerations to rounding (the line sums the springs' tensions, the
    /// paper's form the stiffness matrix's rows).
    #[test]
    fn nominal_line_is_the_nominal_chain() {
        let mut one = Effects::none();
        one.set(EffectKind::RopeDiscretization, &[1.0]).unwrap();
        one.set(EffectKind::TensionStiffening, &[0.0, 300.0]).unwrap();
        for effects in [Effects::none(), one] {
            let line = Line::new(&effects);
            for (m, lw, seed) in [(70.5, 1.3, 1.0), (33.0, 7.2, -2.0), (45.5, 4.0, 0.5)] {
                let c = chain(m, lw);
                let mut state = crate::ChainState::default();
                for i in 0..DOF {
                    state.position_m[i] = 1e-4 * seed * (i as f64 + 0.3).sin();
                    state.velocity_mps[i] = 0.3 * seed * (i as f64 * 1.7).cos();
                }
                for brake in [false, true] {
                    let expected = paper_chain_acceleration(&c, &state, 17.3 * seed, brake);
                    let mut got = [0.0; DOF];
                    let action = if brake { BrakeAction::Held } else { BrakeAction::Released };
                    line.accelerations(&c, &state.position_m, &state.velocity_mps, 17.3 * seed, action, 0.0, &mut got);
                    for (g, e) in got.iter().zip(&expected) {
                        assert!((g - e).abs() <= 1e-12 * (1.0 + e.abs()), "{got:?} against {expected:?}");
                    }
                }
            }
        }
    }
}
