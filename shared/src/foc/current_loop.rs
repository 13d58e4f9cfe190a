//! The dq current loop (one step per PWM period, 16 kHz), fixed point.
//!
//! Phase currents -> Clarke -> Park (encoder electrical angle) -> two PI
//! controllers (`id_ref = 0`, `iq_ref` from the speed loop) with the
//! cross-coupling decoupling and back-EMF feed-forward of the PMSM voltage
//! equations
//!
//! `v_d = R i_d + L_d di_d/dt - w_e L_q i_q`,
//! `v_q = R i_q + L_q di_q/dt + w_e (L_d i_d + psi)`,
//!
//! -> voltage limit (d first, then q within the circle `V_dc/sqrt(3)`)
//! -> inverse Park at the angle advanced by one period -> space-vector
//! modulation. Timing: the currents are sampled at the centre of a
//! centre-aligned PWM period; the new compare values load at the next
//! counter underflow, half a period later, and act for one period, whose
//! centre is one period after the sample.
//! PI gains by pole-zero cancellation: `Kp = L wc`, `Ki = R wc`.

use crate::config::DriveConfig;
use crate::fixed::{add, mul, mul_int, mul_q30, q16, sqrt, sub, Q16, Q30};
use crate::park_clarke::{clarke, inverse_park, park, Abc, Dq, INV_SQRT3};
use crate::pi::{Pi, PiGains};
use crate::svpwm::{compare_values, duty_cycles};
use crate::trig::{sin_cos, Angle};

/// Fraction of the linear modulation limit `V_dc/sqrt(3)` the loop may use.
pub const MODULATION_MARGIN: Q16 = Q16::lit("0.95");
/// DC-bus voltage below which the modulator treats the bus as this value, V.
pub const MIN_DC_BUS_V: Q16 = Q16::lit("1");

/// Parameters of the current loop in fixed point, derived from the config.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CurrentLoopParams {
    /// d-axis PI gains (V/A, V/A per step).
    pub d_gains: PiGains,
    /// q-axis PI gains (V/A, V/A per step).
    pub q_gains: PiGains,
    /// `L_d`, H.
    pub ld_h: Q16,
    /// `L_q`, H.
    pub lq_h: Q16,
    /// Magnet flux linkage, Wb.
    pub flux_linkage_wb: Q16,
    /// Angle advance per unit electrical speed: binary angle per (rad/s), Q16 raw.
    pub advance_per_radps: i64,
    /// PWM timer period (compare value of 100 % duty), counts.
    pub period_counts: u16,
}

impl CurrentLoopParams {
    /// Gains for the bandwidth of `config`.
    pub fn from_config(config: &DriveConfig) -> Self {
        let wc = core::f32::consts::TAU * config.current_loop_bandwidth_hz;
        let ts = config.current_period_s();
        let gains = |l: f32| PiGains { kp: q16(l * wc), ki_ts: q16(config.stator_resistance_ohm * wc * ts) };
        // One period of rotation at 1 rad/s, as a binary angle (2^32 per turn).
        let advance = ts / core::f32::consts::TAU * 4_294_967_296.0;
        Self {
            d_gains: gains(config.ld_h),
            q_gains: gains(config.lq_h),
            ld_h: q16(config.ld_h),
            lq_h: q16(config.lq_h),
            flux_linkage_wb: q16(config.flux_linkage_wb),
            advance_per_radps: advance as i64,
            period_counts: config.pwm_period_counts,
        }
    }
}

/// Result of one current-loop step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CurrentLoopOutput {
    /// Timer compare values of phases a, b, c, counts.
    pub compare: [u16; 3],
    /// Measured dq currents, A.
    pub current: Dq,
    /// Commanded dq voltages after limiting, V.
    pub voltage: Dq,
}

/// The dq current controller.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CurrentLoop {
    params: CurrentLoopParams,
    d_pi: Pi,
    q_pi: Pi,
}

impl CurrentLoop {
    /// A current loop with empty integrators.
    pub fn new(params: CurrentLoopParams) -> Self {
        Self { params, d_pi: Pi::new(params.d_gains), q_pi: Pi::new(params.q_gains) }
    }

    /// Empties both integrators (PWM off).
    pub fn reset(&mut self) {
        self.d_pi.reset();
        self.q_pi.reset();
    }

    /// One period: phase currents (A), electrical angle, electrical speed
    /// (rad/s), q-current reference (A) and measured DC bus (V).
    pub fn step(
        &mut self,
        phase: Abc,
        angle: Angle,
        speed_e_radps: Q16,
        iq_ref: Q16,
        dc_bus_v: Q16,
    ) -> CurrentLoopOutput {
        let p = &self.params;
        let (sin, cos) = sin_cos(angle);
        let current = park(clarke(phase), sin, cos);

        // Decoupling and back-EMF feed-forward.
        let ff_d = sub(Q16::ZERO, mul(mul(speed_e_radps, p.lq_h), current.q));
        let ff_q = mul(speed_e_radps, add(mul(p.ld_h, current.d), p.flux_linkage_wb));

        let dc_bus = if dc_bus_v < MIN_DC_BUS_V { MIN_DC_BUS_V } else { dc_bus_v };
        let v_max = mul(mul_q30(dc_bus, INV_SQRT3), MODULATION_MARGIN);
        let v_d = self.d_pi.update(sub(Q16::ZERO, current.d), ff_d, -v_max, v_max);
        let v_q_max = sqrt(sub(mul(v_max, v_max), mul(v_d, v_d)));
        let v_q = self.q_pi.update(sub(iq_ref, current.q), ff_q, -v_q_max, v_q_max);
        let voltage = Dq { d: v_d, q: v_q };

        // The voltage acts centred one period later: advance the angle by Ts.
        // |speed bits| < 2^31 and the gain < 2^20: the product fits i64.
        let advance = (speed_e_radps.to_bits() as i64 * p.advance_per_radps) >> 16;
        let (sin_out, cos_out) = sin_cos(angle.wrapping_add(advance as i32 as u32));
        // 1/V_dc in Q2.30 (V_dc >= 1 V): 2^46 / raw bits, by one IEEE-754 f32
        // division (correctly rounded on every target, so bit-identical) and a
        // saturating conversion; within one Q2.30 step of the exact value.
        let inverse_dc_bus = Q30::from_bits((70_368_744_177_664.0f32 / dc_bus.to_bits() as f32) as i32);
        let duties = duty_cycles(inverse_park(voltage, sin_out, cos_out), inverse_dc_bus);
        CurrentLoopOutput { compare: compare_values(duties, p.period_counts), current, voltage }
    }
}

/// Phase current (A) of an ADC code, for a converter with `zero_code` at 0 A
/// and `lsb_a` amperes per code.
pub fn current_from_code(code: u16, zero_code: u16, lsb_a: Q16) -> Q16 {
    mul_int(code as i32 - zero_code as i32, lsb_a)
}
