//! Fault supervisor: checks every sensor reading against its plausible range,
//! watches the consistency of the loops (current tracking, back-EMF against
//! the encoder speed, speed following) and latches the first fault. A latched
//! fault holds until an explicit [`Supervisor::reset`]; the controller then
//! keeps the PWM off and the brake applied.
//!
//! Detection bounds (the time from the onset of a fault that the check sees
//! to the step whose outputs are the safe state; `Ts` is the current-loop
//! period, 62.5 us on the rig, `Tsl` the speed-loop period, 0.5 ms):
//!
//! | code | fault | check | bound |
//! |---|---|---|---|
//! | 1 | [`Fault::OverCurrent`] | a phase above the trip level (a code at a rail counts when the other two phases confirm it) | the first sample above the level: 1 `Ts` |
//! | 2 | [`Fault::OverSpeed`] | speed estimate above the limit | 1 `Tsl` after the estimate crosses |
//! | 3, 4 | DC bus | measured bus outside its band | the first sample outside: 1 `Ts` |
//! | 5 | [`Fault::CurrentSensorImplausible`] | a code at a rail, or `|i_a + i_b + i_c|` above its limit | 1 `Ts` |
//! | 6 | [`Fault::EncoderImplausible`] | an encoder step above 4x the over-speed step | 1 `Ts` |
//! | 7 | [`Fault::DeadlineMissed`] | time since the previous step above 2.5 `Ts` | the next step that runs |
//! | 8 | [`Fault::CurrentSensorOffset`] | `|i_a + i_b + i_c|` low-passed ([`CURRENT_SUM_TAU_S`]) above a third of the code-5 limit | [`CURRENT_SUM_TAU_S`] `ln 2` + 1 `Tsl` for a sum of twice the level |
//! | 9 | [`Fault::CurrentTracking`] | `|i_d| + |i_q - i_q,ref|` low-passed ([`TRACKING_TAU_S`]) above [`TRACKING_LIMIT_FRACTION`] of the current limit, PWM on and at least [`MIN_CURRENT_FRACTION`] of it measured | [`TRACKING_TAU_S`] `ln 2` + 1 `Tsl` for an error of twice the level |
//! | 10 | [`Fault::BackEmfMismatch`] | the dq voltage the current loop applies against `R i + w_e L i + w_e psi` from the encoder speed, low-passed ([`BACK_EMF_TAU_S`]), PWM on, current as for 9 | [`BACK_EMF_TAU_S`] `ln 2` + 1 `Tsl` for a residual of twice the level |
//! | 11 | [`Fault::SpeedFollowing`] | `|w_ref - w|` low-passed ([`FOLLOWING_TAU_S`]) above [`FOLLOWING_LIMIT_FRACTION`] of the rated shaft speed, brake released | [`FOLLOWING_TAU_S`] `ln 2` + 1 `Tsl` for an error of twice the level |
//!
//! The low-pass checks run at the speed-loop rate on the latest current-loop
//! sample (no cost on the 16 kHz path beyond keeping that sample). Their
//! levels are set with margin above what the 8 nominal travels of the rig
//! reach (`tests/faults.rs` prints both).

use crate::fixed::Q16;

/// Time constant of the low-passed phase-current sum (`Fault::CurrentSensorOffset`), s.
pub const CURRENT_SUM_TAU_S: f32 = 0.002;
/// Level of the low-passed phase-current sum, as a fraction of the
/// instantaneous limit `current_sum_a` (`Fault::CurrentSensorOffset`), dimensionless.
pub const CURRENT_SUM_LEVEL_FRACTION: f32 = 1.0 / 3.0;
/// Time constant of the low-passed current tracking error (`Fault::CurrentTracking`), s.
pub const TRACKING_TAU_S: f32 = 0.004;
/// Level of the current tracking error as a fraction of the q-current limit
/// `max_current_a` (`Fault::CurrentTracking`), dimensionless.
pub const TRACKING_LIMIT_FRACTION: f32 = 0.15;
/// Smallest measured current `|i_d| + |i_q|` at which the current-loop
/// checks (faults 9 and 10) run, as a fraction of `max_current_a`: with no
/// current measured at all (a machine that is not connected, or a bench with
/// no machine) they hold, and the speed-following check (`Fault::SpeedFollowing`) is the
/// one that sees a drive that produces no torque. Dimensionless.
pub const MIN_CURRENT_FRACTION: f32 = 0.05;
/// Time constant of the low-passed back-EMF residual (`Fault::BackEmfMismatch`), s.
pub const BACK_EMF_TAU_S: f32 = 0.004;
/// Level of the back-EMF residual as a fraction of the back-EMF at the rated
/// shaft speed `p w_rated psi` (`Fault::BackEmfMismatch`), dimensionless.
pub const BACK_EMF_LIMIT_FRACTION: f32 = 0.25;
/// Time constant of the low-passed speed-following error (`Fault::SpeedFollowing`), s.
pub const FOLLOWING_TAU_S: f32 = 0.02;
/// Level of the speed-following error as a fraction of the rated shaft speed
/// (`Fault::SpeedFollowing`), dimensionless.
pub const FOLLOWING_LIMIT_FRACTION: f32 = 0.15;

/// Why the drive tripped. The discriminant is the reason code reported in
/// telemetry and recordings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Fault {
    /// A phase current above the trip level.
    OverCurrent = 1,
    /// Shaft speed above the over-speed limit.
    OverSpeed = 2,
    /// DC bus below the under-voltage limit.
    DcBusUnderVoltage = 3,
    /// DC bus above the over-voltage limit.
    DcBusOverVoltage = 4,
    /// A phase-current ADC code at a rail, or phase currents not summing to zero.
    CurrentSensorImplausible = 5,
    /// An encoder step larger than the shaft can physically make in one period.
    EncoderImplausible = 6,
    /// Time between two steps longer than the control deadline allows.
    DeadlineMissed = 7,
    /// The phase currents persistently do not sum to zero (a drifting or
    /// stuck phase-current sensor), below the instantaneous code-5 limit.
    CurrentSensorOffset = 8,
    /// The measured dq currents persistently miss their references (an open
    /// phase, a stuck sensor, a bus too low to drive the current).
    CurrentTracking = 9,
    /// The voltage the current loop needs disagrees with the machine model
    /// at the encoder's speed and angle (encoder stopped, losing counts or
    /// slipping while the shaft turns).
    BackEmfMismatch = 10,
    /// The shaft speed persistently misses its reference with the brake
    /// released (brake not opening, a sudden load change or slack rope, a
    /// stalled or runaway shaft).
    SpeedFollowing = 11,
}

impl Fault {
    /// Every fault, in code order.
    pub const ALL: [Fault; 11] = [
        Fault::OverCurrent,
        Fault::OverSpeed,
        Fault::DcBusUnderVoltage,
        Fault::DcBusOverVoltage,
        Fault::CurrentSensorImplausible,
        Fault::EncoderImplausible,
        Fault::DeadlineMissed,
        Fault::CurrentSensorOffset,
        Fault::CurrentTracking,
        Fault::BackEmfMismatch,
        Fault::SpeedFollowing,
    ];

    /// Reason code (1..=11).
    pub fn code(self) -> u8 {
        self as u8
    }

    /// The fault of a reason code, if it is one.
    pub fn from_code(code: u8) -> Option<Self> {
        Self::ALL.get(usize::from(code).checked_sub(1)?).copied()
    }

    /// The variant's name (for logs and tables).
    pub fn name(self) -> &'static str {
        match self {
            Fault::OverCurrent => "OverCurrent",
            Fault::OverSpeed => "OverSpeed",
            Fault::DcBusUnderVoltage => "DcBusUnderVoltage",
            Fault::DcBusOverVoltage => "DcBusOverVoltage",
            Fault::CurrentSensorImplausible => "CurrentSensorImplausible",
            Fault::EncoderImplausible => "EncoderImplausible",
            Fault::DeadlineMissed => "DeadlineMissed",
            Fault::CurrentSensorOffset => "CurrentSensorOffset",
            Fault::CurrentTracking => "CurrentTracking",
            Fault::BackEmfMismatch => "BackEmfMismatch",
            Fault::SpeedFollowing => "SpeedFollowing",
        }
    }
}

/// Limits of the supervisor, in the units named.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SupervisorLimits {
    /// Phase current trip level, A.
    pub overcurrent_a: Q16,
    /// Largest plausible |i_a + i_b + i_c|, A.
    pub current_sum_a: Q16,
    /// Shaft over-speed level, rad/s.
    pub overspeed_radps: Q16,
    /// DC-bus under-voltage level, V.
    pub dc_bus_under_v: Q16,
    /// DC-bus over-voltage level, V.
    pub dc_bus_over_v: Q16,
    /// Largest ADC code (the lowest is 0); a code at either rail is implausible.
    pub adc_max_code: u16,
    /// Largest plausible encoder increment in one current-loop period, counts.
    pub max_counts_per_step: i32,
    /// Longest allowed time between two steps, microseconds.
    pub max_step_interval_us: u32,
    /// Consistency checks run at the speed-loop rate (faults 8 to 11).
    pub monitors: MonitorLimits,
}

/// Levels and filter gains of the consistency checks (faults 8 to 11).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MonitorLimits {
    /// Speed-loop period, s.
    pub period_s: f32,
    /// Low-passed |phase-current sum| level, A (`Fault::CurrentSensorOffset`).
    pub current_sum_level_a: f32,
    /// Low-passed current tracking error level, A (`Fault::CurrentTracking`).
    pub tracking_level_a: f32,
    /// Low-passed back-EMF residual level, V (`Fault::BackEmfMismatch`).
    pub back_emf_level_v: f32,
    /// Low-passed speed-following error level, rad/s (`Fault::SpeedFollowing`).
    pub following_level_radps: f32,
    /// Smallest measured `|i_d| + |i_q|` for faults 9 and 10, A.
    pub min_current_a: f32,
    /// Stator resistance `R`, ohm.
    pub resistance_ohm: f32,
    /// `L_d`, H.
    pub ld_h: f32,
    /// `L_q`, H.
    pub lq_h: f32,
    /// Magnet flux linkage `psi`, Wb.
    pub flux_linkage_wb: f32,
}

impl MonitorLimits {
    /// The levels of the module documentation for a drive with these
    /// parameters: speed-loop period `period_s` (s), instantaneous current-sum
    /// limit `current_sum_a` (A), q-current limit `max_current_a` (A), rated
    /// shaft speed `rated_radps` (rad/s), pole pairs, `R` (ohm), `L_d`, `L_q`
    /// (H) and `psi` (Wb).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        period_s: f32,
        current_sum_a: f32,
        max_current_a: f32,
        rated_radps: f32,
        pole_pairs: f32,
        resistance_ohm: f32,
        ld_h: f32,
        lq_h: f32,
        flux_linkage_wb: f32,
    ) -> Self {
        Self {
            period_s,
            current_sum_level_a: CURRENT_SUM_LEVEL_FRACTION * current_sum_a,
            tracking_level_a: TRACKING_LIMIT_FRACTION * max_current_a,
            back_emf_level_v: BACK_EMF_LIMIT_FRACTION * pole_pairs * rated_radps * flux_linkage_wb,
            following_level_radps: FOLLOWING_LIMIT_FRACTION * rated_radps,
            min_current_a: MIN_CURRENT_FRACTION * max_current_a,
            resistance_ohm,
            ld_h,
            lq_h,
            flux_linkage_wb,
        }
    }
}

/// What the consistency checks see at one speed-loop tick: the latest
/// current-loop sample and the speed loop's reference and estimate.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MonitorSample {
    /// The PWM was on for the latest current-loop step (faults 9 and 10 run only then).
    pub pwm_enabled: bool,
    /// The brake is released (`Fault::SpeedFollowing` is checked only then).
    pub brake_released: bool,
    /// Sum of the measured phase currents, A.
    pub current_sum_a: f32,
    /// Measured d current, A.
    pub id_a: f32,
    /// Measured q current, A.
    pub iq_a: f32,
    /// q-current reference of that step, A.
    pub iq_ref_a: f32,
    /// Commanded d voltage of that step (after limiting), V.
    pub vd_v: f32,
    /// Commanded q voltage of that step (after limiting), V.
    pub vq_v: f32,
    /// Electrical speed from the encoder, rad/s.
    pub speed_e_radps: f32,
    /// Shaft speed reference, rad/s.
    pub speed_ref_radps: f32,
    /// Shaft speed estimate, rad/s.
    pub speed_radps: f32,
}

/// The low-passed quantities of the consistency checks, in their units.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MonitorLevels {
    /// Low-passed |phase-current sum|, A (`Fault::CurrentSensorOffset`).
    pub current_sum_a: f32,
    /// Low-passed `|i_d| + |i_q - i_q,ref|`, A (`Fault::CurrentTracking`).
    pub tracking_a: f32,
    /// Low-passed back-EMF residual `|r_d| + |r_q|`, V (`Fault::BackEmfMismatch`).
    pub back_emf_residual_v: f32,
    /// Low-passed `|w_ref - w|`, rad/s (`Fault::SpeedFollowing`).
    pub following_radps: f32,
}

/// `|x|` with basic operations only (no libm).
fn abs(x: f32) -> f32 {
    if x < 0.0 {
        -x
    } else {
        x
    }
}

/// First-order low-pass step `y += a (x - y)`; a non-finite input saturates
/// the filter at `f32::MAX` (so it trips) instead of poisoning it.
fn low_pass(y: f32, x: f32, gain: f32) -> f32 {
    let next = y + gain * (x - y);
    if next.is_finite() {
        next
    } else {
        f32::MAX
    }
}

/// Fault latch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Supervisor {
    limits: SupervisorLimits,
    latched: Option<Fault>,
    levels: MonitorLevels,
}

impl Supervisor {
    /// A supervisor with no fault latched.
    pub fn new(limits: SupervisorLimits) -> Self {
        Self { limits, latched: None, levels: MonitorLevels::default() }
    }

    /// The latched fault, if any.
    pub fn fault(&self) -> Option<Fault> {
        self.latched
    }

    /// The low-passed quantities of the consistency checks now.
    pub fn monitor_levels(&self) -> MonitorLevels {
        self.levels
    }

    /// The limits in force.
    pub fn limits(&self) -> &SupervisorLimits {
        &self.limits
    }

    /// Clears the latch (explicit operator reset) and the filters.
    pub fn reset(&mut self) {
        self.latched = None;
        self.levels = MonitorLevels::default();
    }

    fn trip(&mut self, fault: Fault) {
        if self.latched.is_none() {
            self.latched = Some(fault);
        }
    }

    /// Checks the phase-current codes and the currents (A) they convert to.
    ///
    /// A phase above the trip level is an over-current when its code is not at
    /// a rail, or when the other two phases confirm it (their sum is above
    /// the trip level too: a phase-to-phase short drives both sensors to
    /// their rails); a code at a rail without that confirmation is a sensor
    /// fault (disconnected, shorted to a supply).
    pub fn check_currents(&mut self, codes: [u16; 3], currents: [Q16; 3]) {
        let adc_max_code = self.limits.adc_max_code;
        let at_rail = |c: u16| c == 0 || c >= adc_max_code;
        let trip_level = self.limits.overcurrent_a;
        for phase in 0..3 {
            if currents[phase].saturating_abs() <= trip_level {
                continue;
            }
            let others = currents[(phase + 1) % 3].saturating_add(currents[(phase + 2) % 3]);
            if !at_rail(codes[phase]) || others.saturating_abs() > trip_level {
                self.trip(Fault::OverCurrent);
            }
        }
        if codes.iter().any(|&c| at_rail(c)) {
            self.trip(Fault::CurrentSensorImplausible);
        }
        let sum = currents[0].saturating_add(currents[1]).saturating_add(currents[2]);
        if sum.saturating_abs() > self.limits.current_sum_a {
            self.trip(Fault::CurrentSensorImplausible);
        }
    }

    /// Checks the measured DC bus, V.
    pub fn check_dc_bus(&mut self, dc_bus_v: Q16) {
        if dc_bus_v < self.limits.dc_bus_under_v {
            self.trip(Fault::DcBusUnderVoltage);
        } else if dc_bus_v > self.limits.dc_bus_over_v {
            self.trip(Fault::DcBusOverVoltage);
        }
    }

    /// Checks one encoder increment, counts.
    pub fn check_encoder_step(&mut self, delta_counts: i32) {
        if delta_counts.saturating_abs() > self.limits.max_counts_per_step {
            self.trip(Fault::EncoderImplausible);
        }
    }

    /// Checks the estimated shaft speed, rad/s.
    pub fn check_speed(&mut self, speed_radps: Q16) {
        if speed_radps.saturating_abs() > self.limits.overspeed_radps {
            self.trip(Fault::OverSpeed);
        }
    }

    /// Checks the time since the previous step, microseconds.
    pub fn check_step_interval(&mut self, interval_us: u32) {
        if interval_us > self.limits.max_step_interval_us {
            self.trip(Fault::DeadlineMissed);
        }
    }

    /// The consistency checks (faults 8 to 11), once per speed-loop period.
    ///
    /// - `Fault::CurrentSensorOffset`: the low-passed `|i_a + i_b + i_c|`;
    /// - `Fault::CurrentTracking` (PWM on, measured current above [`MIN_CURRENT_FRACTION`]): the low-passed `|i_d| + |i_q - i_q,ref|`;
    /// - `Fault::BackEmfMismatch` (PWM on, the same current): the residual of the dq voltage equations of the
    ///   machine at the encoder speed, `r_d = v_d - (R i_d - w_e L_q i_q)`,
    ///   `r_q = v_q - (R i_q + w_e (L_d i_d + psi))`, low-passed `|r_d| + |r_q|`
    ///   (the `L di/dt` terms average out over the filter);
    /// - `Fault::SpeedFollowing` (brake released): the low-passed `|w_ref - w|`.
    ///
    /// A filter whose condition does not hold decays to zero.
    pub fn check_consistency(&mut self, sample: &MonitorSample) {
        let m = self.limits.monitors;
        let gain = |tau_s: f32| {
            let g = m.period_s / tau_s;
            if g > 1.0 {
                1.0
            } else {
                g
            }
        };
        let l = &mut self.levels;
        l.current_sum_a = low_pass(l.current_sum_a, abs(sample.current_sum_a), gain(CURRENT_SUM_TAU_S));
        let measured = abs(sample.id_a) + abs(sample.iq_a);
        // A NaN current runs the checks (and trips) rather than skipping them.
        let enough_current = measured >= m.min_current_a || measured.is_nan();
        let (tracking, residual) = if sample.pwm_enabled && enough_current {
            let we = sample.speed_e_radps;
            let r_d = sample.vd_v - (m.resistance_ohm * sample.id_a - we * m.lq_h * sample.iq_a);
            let r_q = sample.vq_v - (m.resistance_ohm * sample.iq_a + we * (m.ld_h * sample.id_a + m.flux_linkage_wb));
            (abs(sample.id_a) + abs(sample.iq_a - sample.iq_ref_a), abs(r_d) + abs(r_q))
        } else {
            (0.0, 0.0)
        };
        l.tracking_a = low_pass(l.tracking_a, tracking, gain(TRACKING_TAU_S));
        l.back_emf_residual_v = low_pass(l.back_emf_residual_v, residual, gain(BACK_EMF_TAU_S));
        let following = if sample.brake_released { abs(sample.speed_ref_radps - sample.speed_radps) } else { 0.0 };
        l.following_radps = low_pass(l.following_radps, following, gain(FOLLOWING_TAU_S));

        let levels = *l;
        if levels.current_sum_a > m.current_sum_level_a {
            self.trip(Fault::CurrentSensorOffset);
        }
        if levels.tracking_a > m.tracking_level_a {
            self.trip(Fault::CurrentTracking);
        }
        if levels.back_emf_residual_v > m.back_emf_level_v {
            self.trip(Fault::BackEmfMismatch);
        }
        if levels.following_radps > m.following_level_radps {
            self.trip(Fault::SpeedFollowing);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixed::q16;

    fn limits() -> SupervisorLimits {
        SupervisorLimits {
            overcurrent_a: q16(30.0),
            current_sum_a: q16(5.0),
            overspeed_radps: q16(7.7),
            dc_bus_under_v: q16(70.0),
            dc_bus_over_v: q16(130.0),
            adc_max_code: 4095,
            max_counts_per_step: 7,
            max_step_interval_us: 156,
            monitors: MonitorLimits::new(0.0005, 5.0, 20.0, 6.15, 6.0, 1.2, 0.015, 0.015, 0.45),
        }
    }

    #[test]
    fn reason_codes_round_trip_and_stay_put() {
        for (i, fault) in Fault::ALL.iter().enumerate() {
            assert_eq!(fault.code() as usize, i + 1);
            assert_eq!(Fault::from_code(fault.code()), Some(*fault));
        }
        assert_eq!(Fault::from_code(0), None);
        assert_eq!(Fault::from_code(12), None);
        assert_eq!(Fault::DeadlineMissed.code(), 7);
    }

    #[test]
    fn a_short_at_both_rails_is_an_over_current_and_one_rail_alone_a_sensor_fault() {
        let mut s = Supervisor::new(limits());
        s.check_currents([4095, 0, 2048], [q16(50.0), q16(-50.0), q16(0.0)]);
        assert_eq!(s.fault(), Some(Fault::OverCurrent));
        let mut s = Supervisor::new(limits());
        s.check_currents([4095, 2040, 2056], [q16(50.0), q16(-0.2), q16(0.2)]);
        assert_eq!(s.fault(), Some(Fault::CurrentSensorImplausible));
    }

    /// Steps of a constant error `level` times the limit until the trip,
    /// against the bound `tau ln(1 / (1 - 1/level))` + one period.
    fn steps_to_trip(sample: MonitorSample, tau_s: f32, level: f32, fault: Fault) {
        let mut s = Supervisor::new(limits());
        let mut steps = 0;
        while s.fault().is_none() && steps < 10_000 {
            s.check_consistency(&sample);
            steps += 1;
        }
        assert_eq!(s.fault(), Some(fault));
        let bound_s = -tau_s * libm_ln(1.0 - 1.0 / level) + 0.0005;
        assert!(steps as f32 * 0.0005 <= bound_s + 1e-6, "{fault:?}: {steps} steps, bound {bound_s} s");
    }

    /// Natural logarithm by its series around 1 (test only; |1 - x| < 1).
    fn libm_ln(x: f32) -> f32 {
        let u = (x - 1.0) / (x + 1.0);
        let mut sum = 0.0;
        let mut term = u;
        for k in 0..40 {
            sum += term / (2 * k + 1) as f32;
            term *= u * u;
        }
        2.0 * sum
    }

    #[test]
    fn each_consistency_check_trips_within_its_bound_and_not_below_its_level() {
        let m = limits().monitors;
        let on = MonitorSample { pwm_enabled: true, brake_released: true, ..MonitorSample::default() };
        // A healthy sample: the voltage the model wants at zero speed and current.
        steps_to_trip(
            MonitorSample { current_sum_a: 2.0 * m.current_sum_level_a, ..on },
            CURRENT_SUM_TAU_S,
            2.0,
            Fault::CurrentSensorOffset,
        );
        steps_to_trip(
            MonitorSample { id_a: 2.0 * m.tracking_level_a, vd_v: 2.0 * m.tracking_level_a * m.resistance_ohm, ..on },
            TRACKING_TAU_S,
            2.0,
            Fault::CurrentTracking,
        );
        steps_to_trip(
            MonitorSample { vq_v: 2.0 * m.back_emf_level_v + 2.0 * m.resistance_ohm, iq_a: 2.0, iq_ref_a: 2.0, ..on },
            BACK_EMF_TAU_S,
            2.0,
            Fault::BackEmfMismatch,
        );
        // No measured current: the current-loop checks hold.
        let mut s = Supervisor::new(limits());
        for _ in 0..1000 {
            s.check_consistency(&MonitorSample { iq_ref_a: 10.0, vq_v: 50.0, brake_released: false, ..on });
        }
        assert_eq!(s.fault(), None);
        steps_to_trip(
            MonitorSample { speed_ref_radps: 2.0 * m.following_level_radps, ..on },
            FOLLOWING_TAU_S,
            2.0,
            Fault::SpeedFollowing,
        );
        // Just below every level, for a long time: no trip.
        let mut s = Supervisor::new(limits());
        let below = MonitorSample {
            current_sum_a: 0.95 * m.current_sum_level_a,
            iq_a: 2.0,
            iq_ref_a: 2.0 + 0.95 * m.tracking_level_a,
            vq_v: 2.0 * m.resistance_ohm + 0.95 * m.back_emf_level_v,
            speed_ref_radps: 0.95 * m.following_level_radps,
            ..on
        };
        for _ in 0..20_000 {
            s.check_consistency(&below);
        }
        assert_eq!(s.fault(), None, "{:?}", s.monitor_levels());
        // The machine equations at speed with current: no residual.
        let we = 36.9;
        let running = MonitorSample {
            id_a: 0.0,
            iq_a: 12.0,
            iq_ref_a: 12.0,
            vd_v: -we * m.lq_h * 12.0,
            vq_v: m.resistance_ohm * 12.0 + we * m.flux_linkage_wb,
            speed_e_radps: we,
            ..on
        };
        let mut s = Supervisor::new(limits());
        for _ in 0..20_000 {
            s.check_consistency(&running);
        }
        assert_eq!(s.fault(), None);
        assert!(s.monitor_levels().back_emf_residual_v < 1e-3, "{:?}", s.monitor_levels());
    }

    #[test]
    fn a_non_finite_sample_trips_instead_of_poisoning_the_filters() {
        let mut s = Supervisor::new(limits());
        s.check_consistency(&MonitorSample {
            pwm_enabled: true,
            iq_a: 5.0,
            vq_v: f32::NAN,
            ..MonitorSample::default()
        });
        assert_eq!(s.fault(), Some(Fault::BackEmfMismatch));
        s.reset();
        assert_eq!(s.fault(), None);
        assert_eq!(s.monitor_levels(), MonitorLevels::default());
    }
}
