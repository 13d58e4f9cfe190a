//! Rotor alignment at start-up by current injection, with a check that it
//! worked, before the drive accepts its first travel.
//!
//! The drive's encoder is incremental: at power-up the electrical angle of
//! the rotor is unknown, and the controller takes the count of its first
//! step as electrical angle zero. The alignment makes that true: it drives
//! a current vector at electrical angle 0 (the rotor's magnet axis, d,
//! turns onto it), then at +90 degrees, then at 0 again, and checks from
//! the encoder that
//! - the rotor settled at each position (no more than
//!   [`AlignmentParams::settle_tolerance_counts`] of motion over the last
//!   quarter of each hold);
//! - the quarter electrical turn moved it by `+counts_per_rev / (4 p)`
//!   counts within 25 %: no motion means a blocked rotor (brake applied,
//!   no current), the opposite sign a swapped phase or encoder direction,
//!   another distance a wrong pole-pair or encoder-count parameter;
//! - it came back to where it was at 0 (within the settle tolerance);
//! - the measured current reached 80 % of the reference by the end of the
//!   first ramp;
//! - the rotor never went further than one electrical turn from where
//!   it started (it settles at most half a turn away, and overshoots by
//!   less than that): more means the
//!   load is pulling it, and the drive must stop at once.
//!
//! The result is the encoder count at electrical angle zero; the drive
//! keeps the rotor there (brake applied) until the controller's first step.
//!
//! The rotor has to turn, so the brake must be open during the alignment: on
//! an installed lift the car must be balanced against the counterweight (or
//! the ropes off the sheave), otherwise the out-of-balance torque pulls the
//! rotor off the current vector and the check fails (or, under
//! [`AlignmentParams::current_a`], the rotor is held at an angle error).
//!
//! [`Alignment::step`] runs once per PWM period and gives the current
//! vector; [`Injection`] turns it into compare values with the drive's
//! current loop.

use crate::config::DriveConfig;
use crate::current_loop::{current_from_code, CurrentLoop, CurrentLoopParams};
use crate::fixed::{mul_int, q16, Q16};
use crate::park_clarke::Abc;
use crate::trig::Angle;

/// A quarter electrical turn as a binary angle.
const QUARTER_TURN: Angle = 1 << 30;

/// Parameters of the alignment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AlignmentParams {
    /// Injected current magnitude, A.
    pub current_a: f32,
    /// Time of the current ramp from 0, s.
    pub ramp_s: f32,
    /// Time at each of the three positions, s.
    pub hold_s: f32,
    /// PWM (step) rate, Hz.
    pub step_hz: f32,
    /// Encoder counts per mechanical revolution.
    pub counts_per_rev: u32,
    /// Pole pairs.
    pub pole_pairs: u8,
    /// Largest motion while settled, counts.
    pub settle_tolerance_counts: u32,
}

impl AlignmentParams {
    /// Half the drive's largest q current, 0.3 s ramps, 2 s holds (the
    /// rotor on the current vector is a lightly damped spring: about 3 Hz
    /// and a damping ratio of 0.17 on the reference rig) and a settle
    /// tolerance of 1/20 of a quarter electrical turn (at least 2 counts).
    pub fn for_drive(config: &DriveConfig) -> Self {
        let quarter = config.encoder_counts_per_rev / (4 * config.pole_pairs.max(1) as u32);
        Self {
            current_a: 0.5 * config.max_current_a,
            ramp_s: 0.3,
            hold_s: 2.0,
            step_hz: config.current_loop_hz,
            counts_per_rev: config.encoder_counts_per_rev,
            pole_pairs: config.pole_pairs,
            settle_tolerance_counts: (quarter / 20).max(2),
        }
    }

    fn steps(&self, seconds: f32) -> u32 {
        let n = seconds * self.step_hz;
        if n >= 1.0 {
            n as u32
        } else {
            1
        }
    }

    /// Encoder counts of a quarter electrical turn.
    pub fn quarter_turn_counts(&self) -> i32 {
        (self.counts_per_rev / (4 * self.pole_pairs.max(1) as u32)) as i32
    }
}

/// Why the alignment failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AlignmentError {
    /// The measured current did not reach 80 % of the reference.
    CurrentNotReached,
    /// The rotor was still moving at the end of a hold, counts of motion.
    NotSettled(u32),
    /// The quarter turn did not move the rotor (blocked or no torque), counts.
    NoMotion(i32),
    /// The quarter turn moved the rotor backwards (phase or encoder direction), counts.
    WrongDirection(i32),
    /// The quarter turn moved the rotor by the wrong amount (pole pairs, encoder), counts.
    WrongDistance(i32),
    /// Back at 0 the rotor did not return to its first position, counts off.
    NotRepeatable(i32),
    /// The rotor moved more than one electrical turn from where it
    /// started (the load pulls it off the current vector), counts.
    Runaway(i32),
}

/// What to do this period.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AlignmentStep {
    /// Drive a current vector of `current_a` amperes at electrical angle `angle`.
    Inject {
        /// Angle of the current vector (binary angle, electrical).
        angle: Angle,
        /// Its magnitude, A.
        current_a: f32,
    },
    /// Finished: the encoder count at electrical angle zero, or why not.
    Done(Result<u32, AlignmentError>),
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Stage {
    Ramp,
    HoldZero,
    HoldQuarter,
    HoldBack,
    Done(Result<u32, AlignmentError>),
}

/// The alignment sequence.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Alignment {
    params: AlignmentParams,
    stage: Stage,
    ticks: u32,
    settle_min: u32,
    settle_max: u32,
    at_zero: u32,
    start: Option<u32>,
    peak_current_a: f32,
}

impl Alignment {
    /// A sequence with `params`, at its start.
    pub fn new(params: AlignmentParams) -> Self {
        Self {
            params,
            stage: Stage::Ramp,
            ticks: 0,
            settle_min: 0,
            settle_max: 0,
            at_zero: 0,
            start: None,
            peak_current_a: 0.0,
        }
    }

    /// The result, once finished.
    pub fn result(&self) -> Option<Result<u32, AlignmentError>> {
        match self.stage {
            Stage::Done(result) => Some(result),
            _ => None,
        }
    }

    /// One PWM period with the encoder count and the measured current magnitude (A).
    pub fn step(&mut self, encoder_count: u32, current_a: f32) -> AlignmentStep {
        let p = self.params;
        let (ramp, hold) = (p.steps(p.ramp_s), p.steps(p.hold_s));
        self.ticks += 1;
        let start = *self.start.get_or_insert(encoder_count);
        let travelled = encoder_count.wrapping_sub(start) as i32;
        if !matches!(self.stage, Stage::Done(_)) && travelled.unsigned_abs() > 4 * p.quarter_turn_counts() as u32 {
            return self.finish(Err(AlignmentError::Runaway(travelled)));
        }
        if current_a > self.peak_current_a {
            self.peak_current_a = current_a;
        }
        let stage_ticks = self.ticks;
        // The settle window: the last quarter of each hold.
        let in_window = |length: u32| stage_ticks > length - length / 4;
        let full = AlignmentStep::Inject { angle: 0, current_a: p.current_a };
        match self.stage {
            Stage::Ramp => {
                let current_a = p.current_a * self.ticks as f32 / ramp as f32;
                if self.ticks >= ramp {
                    if self.peak_current_a < 0.8 * p.current_a {
                        return self.finish(Err(AlignmentError::CurrentNotReached));
                    }
                    self.next(Stage::HoldZero);
                }
                AlignmentStep::Inject { angle: 0, current_a }
            }
            Stage::HoldZero | Stage::HoldQuarter | Stage::HoldBack => {
                if in_window(hold) {
                    self.track(encoder_count, stage_ticks == hold - hold / 4 + 1);
                }
                // The quarter turn and the way back are ramped over the ramp
                // time, so as not to ring the rotor.
                let fraction = (self.ticks as u64).min(ramp as u64);
                let ramped = (QUARTER_TURN as u64 * fraction / ramp as u64) as Angle;
                let angle = match self.stage {
                    Stage::HoldQuarter => ramped,
                    Stage::HoldBack => QUARTER_TURN - ramped,
                    _ => 0,
                };
                if self.ticks < hold {
                    return AlignmentStep::Inject { angle, current_a: p.current_a };
                }
                let motion = self.settle_max.wrapping_sub(self.settle_min);
                if motion > p.settle_tolerance_counts {
                    return self.finish(Err(AlignmentError::NotSettled(motion)));
                }
                match self.stage {
                    Stage::HoldZero => {
                        self.at_zero = encoder_count;
                        self.next(Stage::HoldQuarter);
                        full
                    }
                    Stage::HoldQuarter => {
                        let moved = encoder_count.wrapping_sub(self.at_zero) as i32;
                        let expected = p.quarter_turn_counts();
                        let off = moved - expected;
                        if moved.abs() < expected / 4 {
                            return self.finish(Err(AlignmentError::NoMotion(moved)));
                        }
                        if moved < 0 {
                            return self.finish(Err(AlignmentError::WrongDirection(moved)));
                        }
                        if off.abs() > expected / 4 {
                            return self.finish(Err(AlignmentError::WrongDistance(moved)));
                        }
                        self.next(Stage::HoldBack);
                        AlignmentStep::Inject { angle: QUARTER_TURN, current_a: p.current_a }
                    }
                    _ => {
                        let off = encoder_count.wrapping_sub(self.at_zero) as i32;
                        if off.unsigned_abs() > p.settle_tolerance_counts {
                            return self.finish(Err(AlignmentError::NotRepeatable(off)));
                        }
                        self.finish(Ok(encoder_count))
                    }
                }
            }
            Stage::Done(result) => AlignmentStep::Done(result),
        }
    }

    fn next(&mut self, stage: Stage) {
        self.stage = stage;
        self.ticks = 0;
    }

    /// Settle window bookkeeping: motion relative to the window's first count.
    fn track(&mut self, count: u32, first_of_window: bool) {
        if first_of_window {
            self.settle_min = count;
            self.settle_max = count;
            return;
        }
        // Signed distance from the window's minimum, modulo 2^32.
        if (count.wrapping_sub(self.settle_min) as i32) < 0 {
            self.settle_min = count;
        }
        if (count.wrapping_sub(self.settle_max) as i32) > 0 {
            self.settle_max = count;
        }
    }

    fn finish(&mut self, result: Result<u32, AlignmentError>) -> AlignmentStep {
        self.stage = Stage::Done(result);
        AlignmentStep::Done(result)
    }
}

/// The current loop that realises an [`AlignmentStep::Inject`]: the drive's
/// own dq current loop, run at the Park angle 90 degrees behind the vector
/// so that its q axis carries the injected current.
#[derive(Clone, Copy, Debug)]
pub struct Injection {
    current_loop: CurrentLoop,
    lsb_a: Q16,
    zero_code: u16,
    dc_bus_v_per_code: Q16,
}

impl Injection {
    /// The injection of the drive described by `config`.
    pub fn new(config: &DriveConfig) -> Self {
        Self {
            current_loop: CurrentLoop::new(CurrentLoopParams::from_config(config)),
            lsb_a: q16(config.current_lsb_a()),
            zero_code: config.adc_zero_code(),
            dc_bus_v_per_code: q16(config.dc_bus_sense_full_scale_v / config.adc_max_code() as f32),
        }
    }

    /// Compare values for a current vector of `current_a` A at electrical
    /// `angle`, from the phase-current and DC-bus ADC codes; and the
    /// measured current magnitude, A (the q current of the loop).
    pub fn step(&mut self, codes: [u16; 3], dc_bus_code: u16, angle: Angle, current_a: f32) -> ([u16; 3], f32) {
        let [a, b, c] = codes.map(|code| current_from_code(code, self.zero_code, self.lsb_a));
        let dc_bus_v = mul_int(dc_bus_code as i32, self.dc_bus_v_per_code);
        let out = self.current_loop.step(
            Abc { a, b, c },
            angle.wrapping_sub(QUARTER_TURN),
            Q16::ZERO,
            q16(current_a),
            dc_bus_v,
        );
        (out.compare, out.current.q.to_bits() as f32 * (1.0 / 65536.0))
    }

    /// Empties the loop's integrators (outputs off).
    pub fn reset(&mut self) {
        self.current_loop.reset();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::reference_rig;

    /// A rotor driven by an ideal current source: torque `Kt I sin(vector -
    /// rotor)` (electrical angles), inertia, viscous damping, a load torque;
    /// semi-implicit Euler at the PWM rate. `direction` -1 swaps the encoder.
    fn run(
        load_nm: f32,
        direction: f64,
        pole_pairs_seen: u8,
        start_electrical_rad: f64,
    ) -> (Result<u32, AlignmentError>, f64, u32) {
        let rig = reference_rig();
        let mut params = AlignmentParams::for_drive(&rig);
        params.pole_pairs = pole_pairs_seen;
        let mut alignment = Alignment::new(params);
        let p = rig.pole_pairs as f64;
        let kt = rig.torque_constant_nm_per_a() as f64;
        let j = rig.sheave_inertia_kg_m2 as f64 + 70.5 * 0.065 * 0.065;
        let damping = 3.0 + 2.0 * 148.0 * 0.065 * 0.065;
        let dt = 1.0 / rig.current_loop_hz as f64;
        let cpr = rig.encoder_counts_per_rev as f64;
        let mut theta_m = start_electrical_rad / p;
        let mut omega = 0.0;
        let count_at = |theta_m: f64| (direction * theta_m / core::f64::consts::TAU * cpr).round() as i64 as u32;
        let mut current = 0.0f32;
        for _ in 0..200_000 {
            match alignment.step(count_at(theta_m).wrapping_add(1000), current) {
                AlignmentStep::Inject { angle, current_a } => {
                    current = current_a;
                    let vector = angle as f64 / 4_294_967_296.0 * core::f64::consts::TAU;
                    let torque =
                        kt * current_a as f64 * (vector - p * theta_m).sin() - load_nm as f64 - damping * omega;
                    omega += torque / j * dt;
                    theta_m += omega * dt;
                }
                AlignmentStep::Done(result) => {
                    let electrical = (p * theta_m).rem_euclid(core::f64::consts::TAU);
                    let error = if electrical > core::f64::consts::PI {
                        electrical - core::f64::consts::TAU
                    } else {
                        electrical
                    };
                    return (result, error, count_at(theta_m).wrapping_add(1000));
                }
            }
        }
        panic!("the alignment did not finish");
    }

    #[test]
    fn a_free_rotor_is_aligned_to_electrical_zero_from_any_start() {
        for start in [-3.0, -1.5, 0.0, 0.7, 2.5, 3.1] {
            let (result, error, count) = run(0.0, 1.0, 6, start);
            assert_eq!(result, Ok(count), "start {start}");
            assert!(error.abs() < 0.02, "start {start}: {error} rad electrical off");
        }
    }

    #[test]
    fn a_blocked_rotor_a_swapped_encoder_and_wrong_pole_pairs_are_refused() {
        // Out-of-balance torque beyond what the current holds: the rotor runs away.
        assert!(matches!(run(60.0, 1.0, 6, 0.3).0, Err(AlignmentError::Runaway(_))));
        assert!(matches!(run(0.0, -1.0, 6, 0.3).0, Err(AlignmentError::WrongDirection(_))));
        assert!(matches!(run(0.0, 1.0, 3, 0.3).0, Err(AlignmentError::WrongDistance(_))));
    }

    #[test]
    fn no_current_is_refused_before_anything_moves() {
        let rig = reference_rig();
        let mut alignment = Alignment::new(AlignmentParams::for_drive(&rig));
        let mut last = AlignmentStep::Inject { angle: 0, current_a: 0.0 };
        for _ in 0..20_000 {
            last = alignment.step(5, 0.0);
            if matches!(last, AlignmentStep::Done(_)) {
                break;
            }
        }
        assert_eq!(last, AlignmentStep::Done(Err(AlignmentError::CurrentNotReached)));
    }

    #[test]
    fn a_rotor_that_cannot_move_is_no_motion() {
        let rig = reference_rig();
        let mut alignment = Alignment::new(AlignmentParams::for_drive(&rig));
        let mut last = None;
        for _ in 0..100_000 {
            if let AlignmentStep::Done(r) = alignment.step(7, 10.0) {
                last = Some(r);
                break;
            }
        }
        assert_eq!(last, Some(Err(AlignmentError::NoMotion(0))));
    }
}
