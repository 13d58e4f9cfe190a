//! The drive's current transducers seen through the mechanics: when a
//! recording's phase currents are the drive's own transducer signals, a
//! transducer's offset or gain error is not in them (the drive regulates
//! what it senses) but in the machine's true currents, and so in the
//! torque that moves the shaft. The torque-driven model takes the true
//! torque from the recorded currents under the hypothesis of an error:
//! `i = (i_rec - o) / (1 + g)` for phases a and b (phase c the reference,
//! as `plant::effects::CurrentSensorError` has it).
//!
//! The torque change is linear in the series this module keeps, so one
//! pass over the recording serves every parameter value: with
//! `c_x = d i_q / d i_x` of the Park transform at the electrical angle
//! (`dsp::dq_currents`), `dT = 1.5 p psi sum_x -(o_x c_x + g_x c_x i_rec_x)
//! / (1 + g_x)`. (The reluctance torque is left out: exact for a machine
//! with `L_d = L_q`, first order otherwise.)

use crate::error::{Context, Result};
use plant::effects::CurrentSensorError;
use recording::{Recording, I_A, I_B};
use rig_config::RigConfig;

/// `1 / sqrt(3)`, dimensionless.
const FRAC_1_SQRT_3: f64 = 0.577_350_269_189_625_8;

/// The series of a travel that give the torque change of any transducer
/// error, on the chain signals' (decimated) sample grid.
#[derive(Clone, Debug, PartialEq)]
pub struct TransducerSeries {
    /// `1.5 p psi`, N m/A.
    pub torque_per_q_amp: f64,
    /// `c_a`, `c_b`: the q current per ampere of phase a and b, A/A.
    pub q_per_phase: [Vec<f64>; 2],
    /// `c_a i_a`, `c_b i_b`: the q current the recorded phase currents
    /// carry, A.
    pub recorded_q_by_phase: [Vec<f64>; 2],
}

impl TransducerSeries {
    /// The series of the travel `recording` (`stem` names it) on the rig's
    /// machine, with the shaft angle `shaft_angle_rad` (rad) and electrical
    /// offset `electrical_offset_rad` (rad) its torque was computed with,
    /// decimated by `factor`.
    pub fn of(
        rig: &RigConfig,
        recording: &Recording,
        stem: &str,
        shaft_angle_rad: &[f64],
        electrical_offset_rad: f64,
        factor: usize,
    ) -> Result<Self> {
        let column = |name: &str| {
            recording.column(name).map(|c| c.values.as_slice()).with_context(|| format!("`{stem}`: no `{name}`"))
        };
        let (i_a, i_b) = (column(I_A)?, column(I_B)?);
        let p = f64::from(rig.motor.pole_pairs);
        let n = i_a.len().min(i_b.len()).min(shaft_angle_rad.len());
        let mut c = [Vec::with_capacity(n), Vec::with_capacity(n)];
        let mut ci = [Vec::with_capacity(n), Vec::with_capacity(n)];
        for k in 0..n {
            let (s, co) = (p * shaft_angle_rad[k] + electrical_offset_rad).sin_cos();
            // i_q = -i_alpha sin + i_beta cos with the amplitude-invariant
            // Clarke transform: d i_q / d i_a and d i_q / d i_b.
            let (ca, cb) = (-2.0 / 3.0 * s, s / 3.0 + FRAC_1_SQRT_3 * co);
            c[0].push(ca);
            c[1].push(cb);
            ci[0].push(ca * i_a[k]);
            ci[1].push(cb * i_b[k]);
        }
        let decimated = |v: Vec<f64>| -> Result<Vec<f64>> {
            if factor > 1 {
                dsp::decimate(&v, factor).with_context(|| format!("`{stem}`: decimating the transducer series"))
            } else {
                Ok(v)
            }
        };
        let [c_a, c_b] = c;
        let [ci_a, ci_b] = ci;
        Ok(Self {
            torque_per_q_amp: 1.5 * p * rig.motor.flux_linkage_wb,
            q_per_phase: [decimated(c_a)?, decimated(c_b)?],
            recorded_q_by_phase: [decimated(ci_a)?, decimated(ci_b)?],
        })
    }

    /// The machine's true torque (N m) under the transducer error `error`:
    /// `recorded_nm` (N m, from the recorded currents) plus the change.
    pub fn true_torque_nm(&self, recorded_nm: &[f64], error: &CurrentSensorError) -> Vec<f64> {
        let offsets = [error.offset_a_a, error.offset_b_a];
        let gains = [error.gain_error_a, error.gain_error_b];
        recorded_nm
            .iter()
            .enumerate()
            .map(|(k, &t)| {
                let mut dq = 0.0;
                for x in 0..2 {
                    let (c, ci) = (self.q_per_phase[x].get(k), self.recorded_q_by_phase[x].get(k));
                    if let (Some(c), Some(ci)) = (c, ci) {
                        dq -= (offsets[x] * c + gains[x] * ci) / (1.0 + gains[x]);
                    }
                }
                t + self.torque_per_q_amp * dq
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    /// The torque change the series give equals the torque of the
    /// corrected currents minus that of the recorded ones, computed by
    /// `dsp::machine_torque_nm` (an independent dq transform).
    #[test]
    fn the_torque_change_is_the_corrected_currents_torque() {
        let rig = rig_config::RigConfig::embedded_default().unwrap();
        let fs = 4096.0;
        let n = 4096;
        let p = f64::from(rig.motor.pole_pairs);
        let offset = 0.7;
        let angle: Vec<f64> = (0..n).map(|k| 6.15 * k as f64 / fs).collect();
        let phase = |shift: f64| -> Vec<f64> {
            angle.iter().map(|&t| -8.0 * (p * t + offset - shift).sin() + 0.3 * (2.0 * p * t).cos()).collect()
        };
        let (i_a, i_b, i_c) = (phase(0.0), phase(TAU / 3.0), phase(-TAU / 3.0));
        let recording = Recording {
            meta: recording::RecordingMeta {
                kind: recording::RecordingKind::Travel {
                    m_car_kg: 33.0,
                    m_cw_kg: 50.0,
                    direction: recording::CarDirection::Up,
                    lw_start_m: 1.0,
                    lw_end_m: 7.6,
                },
                sample_rate_hz: fs,
                description: None,
            },
            columns: vec![
                recording::Column::new(I_A, i_a.clone()),
                recording::Column::new(I_B, i_b.clone()),
                recording::Column::new(recording::I_C, i_c.clone()),
            ],
        };
        let m = &rig.motor;
        let torque = |a: &[f64], b: &[f64]| {
            dsp::machine_torque_nm(a, b, &i_c, &angle, m.pole_pairs, m.flux_linkage_wb, m.ld_h, m.ld_h, offset).unwrap()
        };
        let recorded = torque(&i_a, &i_b);
        let error = CurrentSensorError { offset_a_a: -0.25, offset_b_a: 0.05, gain_error_a: -0.04, gain_error_b: 0.01 };
        let corrected = |i: &[f64], o: f64, g: f64| -> Vec<f64> { i.iter().map(|x| (x - o) / (1.0 + g)).collect() };
        let expected = torque(&corrected(&i_a, -0.25, -0.04), &corrected(&i_b, 0.05, 0.01));
        let series = TransducerSeries::of(&rig, &recording, "t", &angle, offset, 1).unwrap();
        let got = series.true_torque_nm(&recorded, &error);
        let worst = got.iter().zip(&expected).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-9, "largest difference {worst} N m");
        // And the error moves the torque (the check is not vacuous).
        let moved = got.iter().zip(&recorded).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(moved > 0.5, "{moved}");
    }
}
