//! Signals of a travel recording that the analyses derive from its columns:
//! the unwrapped shaft angle, the counterweight-side rope length over time
//! and the electrical angle offset of the machine.

use dsp::AnalysisError;

use crate::error::{bail, DiagnosisError, Result};

/// The shaft angle, rad: the `angle_rad` column when there is one, else the
/// running trapezoidal integral of the speed (rad/s) from 0.
pub fn shaft_angle_rad(angle: Option<&[f64]>, speed_radps: &[f64], sample_rate_hz: f64) -> Vec<f64> {
    if let Some(angle) = angle {
        return angle.to_vec();
    }
    let dt = 1.0 / sample_rate_hz;
    let mut theta = Vec::with_capacity(speed_radps.len());
    let mut acc = 0.0;
    for (k, w) in speed_radps.iter().enumerate() {
        if k > 0 {
            acc += 0.5 * (w + speed_radps[k - 1]) * dt;
        }
        theta.push(acc);
    }
    theta
}

/// Where a travel's shaft angle comes from and how it was put on the
/// currents' time base ([`crate::angle_alignment`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct AngleAlignment {
    /// `true`: the recording's `angle_rad` column; `false`: the drive's speed
    /// estimate integrated.
    pub encoder_column: bool,
    /// The angle's delay behind the currents as read from them.
    pub delay: Option<crate::angle_alignment::AngleDelay>,
    /// Why the delay could not be read, when it could not.
    pub refused: Option<String>,
    /// How much later the angle is read (the delay, where it is applied), s.
    pub advanced_s: f64,
}

impl AngleAlignment {
    /// One line for a report.
    pub fn text(&self) -> String {
        let source = if self.encoder_column { "the encoder column" } else { "the speed estimate integrated" };
        match (&self.delay, &self.refused) {
            (Some(d), _) if self.advanced_s != 0.0 => format!(
                "{source}, {:.3} ms behind the currents (coherence {:.3}): read that much later",
                1e3 * d.delay_s,
                d.coherence
            ),
            (Some(d), _) => format!(
                "{source}, {:.3} ms from the currents (coherence {:.3}): used as recorded",
                1e3 * d.delay_s,
                d.coherence
            ),
            (None, reason) => {
                format!("{source}, used as recorded: its delay not read ({})", reason.as_deref().unwrap_or("-"))
            }
        }
    }
}

/// Largest phase error (rad) of the rig's highest ripple order at the
/// travel's top speed that an encoder column's delay behind the currents
/// may leave before the column is read later: 0.1 rad moves a ripple line by
/// a tenth of its amplitude. (The machine's current loop alone leaves
/// 0.04-0.06 ms on the project's and the foreign emulator's drives, up to
/// 0.03 rad at the 72nd order and 6.15 rad/s.)
pub const MAX_RIPPLE_PHASE_ERROR_RAD: f64 = 0.1;

/// The shaft angle of the travel `recording` (rad, [`shaft_angle_rad`]) on
/// the phase currents' time base: its delay behind the currents read from
/// them ([`crate::angle_alignment::angle_delay`]) and the angle read that
/// much later where it comes from the speed estimate (whose filter and
/// computation always delay it), or where an encoder column's delay turns
/// the rig's highest ripple order by more than
/// [`MAX_RIPPLE_PHASE_ERROR_RAD`] at the top speed. Without the phase
/// currents or the speed, the angle as recorded.
pub fn travel_shaft_angle(rig: &rig_config::RigConfig, recording: &recording::Recording) -> (Vec<f64>, AngleAlignment) {
    use recording::{ANGLE, I_A, I_B, I_C, SPEED};
    let fs = recording.meta.sample_rate_hz;
    let column = |name: &str| recording.column(name).map(|c| c.values.as_slice());
    let encoder = column(ANGLE);
    let speed = column(SPEED).unwrap_or(&[]);
    let angle = shaft_angle_rad(encoder, speed, fs);
    let delay = match (column(I_A), column(I_B), column(I_C)) {
        (Some(a), Some(b), Some(c)) => {
            crate::angle_alignment::angle_delay([a, b, c], &angle, speed, rig.motor.pole_pairs)
        }
        _ => Err("the recording has no phase currents".to_string()),
    };
    let top_order = rig.ripple.iter().map(|r| f64::from(r.mechanical_order)).fold(0.0, f64::max);
    let top_speed = speed.iter().fold(0.0f64, |m, w| m.max(w.abs()));
    let advanced_s = match &delay {
        Ok(d) if encoder.is_none() || top_order * top_speed * d.delay_s.abs() > MAX_RIPPLE_PHASE_ERROR_RAD => d.delay_s,
        _ => 0.0,
    };
    let angle = if advanced_s != 0.0 { crate::angle_alignment::advanced(&angle, advanced_s, fs) } else { angle };
    let (delay, refused) = match delay {
        Ok(d) => (Some(d), None),
        Err(e) => (None, Some(e)),
    };
    (angle, AngleAlignment { encoder_column: encoder.is_some(), delay, refused, advanced_s })
}

/// Counterweight-side rope length, m, along the travel: `l_w = l_w0 + r
/// (theta - theta_0)` (car up: the shaft angle grows and so does `l_w`).
pub fn counterweight_side_length_m(shaft_angle_rad: &[f64], lw_start_m: f64, sheave_radius_m: f64) -> Vec<f64> {
    let theta0 = shaft_angle_rad.first().copied().unwrap_or(0.0);
    shaft_angle_rad.iter().map(|t| lw_start_m + sheave_radius_m * (t - theta0)).collect()
}

/// Offset (rad) between the encoder's electrical angle `p theta` and the
/// rotor d axis, estimated from currents under vector control with `i_d = 0`:
/// the current vector then lies on the q axis, 90 electrical degrees ahead of
/// d, so the offset is the circular mean of `atan2(beta, alpha) - p theta -
/// pi/2`, weighted by the current magnitude (samples with the largest
/// currents dominate; the sign of the q current is taken into account).
pub fn electrical_offset_rad(
    i_a: &[f64],
    i_b: &[f64],
    i_c: &[f64],
    shaft_angle_rad: &[f64],
    pole_pairs: u32,
) -> Result<f64, AnalysisError> {
    let n = i_a.len();
    if n == 0 || i_b.len() != n || i_c.len() != n || shaft_angle_rad.len() != n {
        return Err(AnalysisError::InvalidParameter {
            name: "phase currents and angle",
            value: n as f64,
            expected: "four non-empty signals of equal length",
        });
    }
    let p = f64::from(pole_pairs);
    let (mut sx, mut sy) = (0.0, 0.0);
    for k in 0..n {
        let alpha = (2.0 * i_a[k] - i_b[k] - i_c[k]) / 3.0;
        let beta = (i_b[k] - i_c[k]) / 3f64.sqrt();
        // Rotate the current vector back by the electrical angle: what is
        // left is the vector in rotor coordinates, (i_d, i_q) up to the offset.
        let (s, c) = (p * shaft_angle_rad[k]).sin_cos();
        let (d, q) = (alpha * c + beta * s, beta * c - alpha * s);
        // A negative q current points the other way: fold it onto +q.
        let (d, q) = if q < 0.0 { (-d, -q) } else { (d, q) };
        // Angle of (d, q) from the +q axis, as a unit-weighted vector.
        sx += q;
        sy += -d;
    }
    if sx == 0.0 && sy == 0.0 {
        return Err(AnalysisError::InvalidParameter {
            name: "phase currents",
            value: 0.0,
            expected: "non-zero currents",
        });
    }
    Ok(sy.atan2(sx))
}

/// The machine torque of a travel recording (paper 3.3) and the signals it
/// rests on, as `analyze` and `identify` both use them.
pub struct TravelTorque {
    /// Shaft speed from the encoder, rad/s.
    pub speed_radps: Vec<f64>,
    /// Unwrapped shaft angle on the currents' time base ([`travel_shaft_angle`]), rad.
    pub shaft_angle_rad: Vec<f64>,
    /// Where the angle comes from and how it was aligned.
    pub angle_alignment: AngleAlignment,
    /// Electrical angle offset estimated from `i_d = 0`, rad.
    pub electrical_offset_rad: f64,
    /// Machine torque from the phase currents (dq0), N m.
    pub torque_nm: Vec<f64>,
    /// Samples of the constant-speed stage.
    pub constant_speed: std::ops::Range<usize>,
}

/// [`TravelTorque`] of the travel recording `stem` for the machine of `rig`.
pub fn travel_torque(
    rig: &rig_config::RigConfig,
    recording: &recording::Recording,
    stem: &str,
) -> Result<TravelTorque> {
    use recording::{I_A, I_B, I_C, SPEED};
    let column = |name: &str| -> Result<&[f64]> {
        recording
            .column(name)
            .map(|c| c.values.as_slice())
            .ok_or_else(|| DiagnosisError::Message(format!("recording `{stem}`: column `{name}` missing")))
    };
    let fs = recording.meta.sample_rate_hz;
    let mo = &rig.motor;
    let speed = column(SPEED)?;
    let (i_a, i_b, i_c) = (column(I_A)?, column(I_B)?, column(I_C)?);
    let (angle, angle_alignment) = travel_shaft_angle(rig, recording);
    let offset = electrical_offset_rad(i_a, i_b, i_c, &angle, mo.pole_pairs)?;
    let mut torque =
        dsp::machine_torque_nm(i_a, i_b, i_c, &angle, mo.pole_pairs, mo.flux_linkage_wb, mo.ld_h, mo.lq_h, offset)?;
    let expected = expected_torque_nm(rig, recording, &angle, speed)?;
    let agreement = sign_agreement(&torque, &expected);
    if agreement.abs() < MIN_SIGN_AGREEMENT {
        bail!(
            "recording `{stem}`: the machine torque from the currents neither follows nor opposes the torque that \
             the travel needs (Eqn 4, inertia and damping; correlation {agreement:.2}); expected a magnitude of \
             at least {MIN_SIGN_AGREEMENT}: are the phase currents, the speed sign (positive with the car going \
             up) and the masses right?"
        );
    }
    let offset = if agreement < 0.0 {
        torque.iter_mut().for_each(|t| *t = -*t);
        offset + std::f64::consts::PI
    } else {
        offset
    };
    Ok(TravelTorque {
        constant_speed: dsp::constant_speed_stage(speed, fs)?,
        speed_radps: speed.to_vec(),
        shaft_angle_rad: angle,
        angle_alignment,
        electrical_offset_rad: offset,
        torque_nm: torque,
    })
}

/// Smallest |correlation| between the machine torque from the currents and
/// the torque the travel needs ([`expected_torque_nm`]) that settles the
/// half-turn ambiguity of the electrical angle offset.
pub const MIN_SIGN_AGREEMENT: f64 = 0.3;

/// Normalised correlation of `torque` with `expected`: near +1 when the
/// currents' torque has the right sign, near -1 when the electrical angle
/// offset is half a turn off.
fn sign_agreement(torque: &[f64], expected: &[f64]) -> f64 {
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let norm = (dot(torque, torque) * dot(expected, expected)).sqrt();
    if norm > 0.0 {
        dot(torque, expected) / norm
    } else {
        0.0
    }
}

/// The shaft torque (N m, positive lifts the car) that the rigid nominal
/// chain of `rig` needs along the measured motion of a travel: the
/// out-of-balance torque of Eqn 4 at the rope length reached, the inertia
/// of sheave, masses and rope times the shaft acceleration (the speed's
/// derivative over 50 ms), and the damping of Eqn 13 times the speed. The
/// electrical angle offset found from `i_d = 0` is ambiguous by half a turn;
/// this torque tells which of the two is right, whatever drive ran the rig.
pub fn expected_torque_nm(
    rig: &rig_config::RigConfig,
    recording: &recording::Recording,
    shaft_angle_rad: &[f64],
    speed_radps: &[f64],
) -> Result<Vec<f64>> {
    let recording::RecordingKind::Travel { m_car_kg, m_cw_kg, lw_start_m, .. } = recording.meta.kind else {
        bail!("not a travel recording");
    };
    let m = &rig.mechanics;
    let mut chain = plant::ChainParams::from_rig(rig, m_car_kg);
    chain.m_cw_kg = m_cw_kg;
    let r = m.sheave_radius_m;
    let inertia =
        m.sheave_inertia_kg_m2 + (m_car_kg + m_cw_kg + m.rope_mass_per_length_kg_per_m * m.rope_total_length_m) * r * r;
    let damping = m.c_sheave_nms_per_rad + (m.c_cw_kg_per_s + m.c_car_kg_per_s) * r * r;
    let lw = counterweight_side_length_m(shaft_angle_rad, lw_start_m, r);
    let fs = recording.meta.sample_rate_hz;
    let half = ((0.025 * fs).round() as usize).max(1);
    let n = speed_radps.len();
    Ok((0..n)
        .map(|k| {
            let (a, b) = (k.saturating_sub(half), (k + half).min(n - 1));
            let accel = if b > a { (speed_radps[b] - speed_radps[a]) * fs / (b - a) as f64 } else { 0.0 };
            chain.out_of_balance_torque_nm(lw[k].clamp(0.0, m.rope_total_length_m))
                + inertia * accel
                + damping * speed_radps[k]
        })
        .collect())
}

/// Eqn 13 with Eqn 4 on one travel: what the constant-speed stage's torque
/// balance gives.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TorqueBalance {
    /// Mean machine torque from the phase currents over the stage, N m.
    pub mean_torque_nm: f64,
    /// Mean shaft speed over the stage, rad/s.
    pub mean_speed_radps: f64,
    /// Mean out-of-balance torque of Eqn 4 along the stage, N m.
    pub out_of_balance_torque_nm: f64,
    /// Sheave rotational damping (Eqn 13), N m s/rad.
    pub sheave_damping_nms_per_rad: f64,
}

/// The torque balance of the travel recording `stem` on `rig`, with
/// `guide_damping_kg_per_s` the guides' total viscous damping `c_w + c_c`
/// (kg/s): the machine torque from the currents (dq0, paper 3.3) averaged
/// over the constant-speed stage, less the out-of-balance torque of Eqn 4,
/// against the mean shaft speed; the travel's torque is `derived` as its
/// measurement derived it ([`travel_torque`]; none: derived here).
pub fn torque_balance(
    rig: &rig_config::RigConfig,
    recording: &recording::Recording,
    stem: &str,
    guide_damping_kg_per_s: f64,
    derived: Option<&TravelTorque>,
) -> Result<TorqueBalance> {
    let recording::RecordingKind::Travel { m_car_kg, m_cw_kg, lw_start_m, .. } = recording.meta.kind else {
        bail!("recording `{stem}` is not a travel");
    };
    let derived_here;
    let t = match derived {
        Some(t) => t,
        None => {
            derived_here = travel_torque(rig, recording, stem)?;
            &derived_here
        }
    };
    let m = &rig.mechanics;
    let stage = t.constant_speed.clone();
    let lw = counterweight_side_length_m(&t.shaft_angle_rad, lw_start_m, m.sheave_radius_m);
    let n = stage.len() as f64;
    let mut chain = plant::ChainParams::from_rig(rig, m_car_kg);
    chain.m_cw_kg = m_cw_kg;
    let mean_torque_nm = t.torque_nm[stage.clone()].iter().sum::<f64>() / n;
    let mean_speed_radps = t.speed_radps[stage.clone()].iter().sum::<f64>() / n;
    let out_of_balance_torque_nm = lw[stage].iter().map(|&l| chain.out_of_balance_torque_nm(l)).sum::<f64>() / n;
    Ok(TorqueBalance {
        mean_torque_nm,
        mean_speed_radps,
        out_of_balance_torque_nm,
        sheave_damping_nms_per_rad: crate::identify::sheave_damping_from_torque_balance(
            mean_torque_nm,
            mean_speed_radps,
            out_of_balance_torque_nm,
            guide_damping_kg_per_s,
            m.sheave_radius_m,
        )?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use plant::pmsm::phase_currents_a;

    #[test]
    fn offset_of_q_axis_currents_is_found() {
        for offset in [0.0, 0.4, -1.2] {
            let (mut a, mut b, mut c, mut theta) = (vec![], vec![], vec![], vec![]);
            for k in 0..5000 {
                let t = k as f64 * 1e-3;
                let iq = if k < 2500 { 12.0 } else { -7.0 };
                let th = 6.15 * t;
                let abc = phase_currents_a(0.0, iq, 6.0 * th + offset);
                a.push(abc[0]);
                b.push(abc[1]);
                c.push(abc[2]);
                theta.push(th);
            }
            let got = electrical_offset_rad(&a, &b, &c, &theta, 6).unwrap();
            assert!((got - offset).abs() < 1e-9, "{got} vs {offset}");
        }
    }

    #[test]
    fn angle_from_speed_and_rope_length() {
        let speed = vec![2.0; 1001];
        let theta = shaft_angle_rad(None, &speed, 1000.0);
        assert!((theta[1000] - 2.0).abs() < 1e-12);
        let lw = counterweight_side_length_m(&theta, 1.0, 0.065);
        assert!((lw[1000] - 1.13).abs() < 1e-12);
    }
}
