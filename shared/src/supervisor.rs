//! Fault supervisor: checks every sensor reading against its plausible range
//! and latches the first fault. A latched fault holds until an explicit
//! [`Supervisor::reset`]; the controller then keeps the PWM off and the brake
//! applied.

use crate::fixed::Q16;

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
}

impl Fault {
    /// Reason code (1..=7).
    pub fn code(self) -> u8 {
        self as u8
    }

    /// The fault of a reason code, if it is one.
    pub fn from_code(code: u8) -> Option<Self> {
        Some(match code {
            1 => Fault::OverCurrent,
            2 => Fault::OverSpeed,
            3 => Fault::DcBusUnderVoltage,
            4 => Fault::DcBusOverVoltage,
            5 => Fault::CurrentSensorImplausible,
            6 => Fault::EncoderImplausible,
            7 => Fault::DeadlineMissed,
            _ => return None,
        })
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
}

/// Fault latch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Supervisor {
    limits: SupervisorLimits,
    latched: Option<Fault>,
}

impl Supervisor {
    /// A supervisor with no fault latched.
    pub fn new(limits: SupervisorLimits) -> Self {
        Self { limits, latched: None }
    }

    /// The latched fault, if any.
    pub fn fault(&self) -> Option<Fault> {
        self.latched
    }

    /// Clears the latch (explicit operator reset).
    pub fn reset(&mut self) {
        self.latched = None;
    }

    fn trip(&mut self, fault: Fault) {
        if self.latched.is_none() {
            self.latched = Some(fault);
        }
    }

    /// Checks the phase-current codes and the currents (A) they convert to.
    pub fn check_currents(&mut self, codes: [u16; 3], currents: [Q16; 3]) {
        if codes.iter().any(|&c| c == 0 || c >= self.limits.adc_max_code) {
            self.trip(Fault::CurrentSensorImplausible);
        }
        if currents.iter().any(|i| i.saturating_abs() > self.limits.overcurrent_a) {
            self.trip(Fault::OverCurrent);
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
}
