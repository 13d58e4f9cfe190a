//! The drive's sensors as the controller sees them: 12-bit phase-current and
//! DC-bus ADC codes, the quadrature encoder counter and the microsecond
//! time stamp.

use rig_config::RigConfig;

/// Sensor scaling.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sensors {
    /// Amperes per phase-current code, A.
    pub current_lsb_a: f64,
    /// Code of zero current.
    pub current_zero_code: f64,
    /// Largest ADC code.
    pub adc_max_code: f64,
    /// DC-bus volts per code, V.
    pub dc_bus_lsb_v: f64,
    /// Encoder counts per mechanical revolution.
    pub encoder_counts_per_rev: f64,
}

impl Sensors {
    /// The sensors of `rig`.
    pub fn from_rig(rig: &RigConfig) -> Self {
        let inv = &rig.inverter;
        let half = (1u64 << (inv.adc_bits - 1)) as f64;
        let max = ((1u64 << inv.adc_bits) - 1) as f64;
        Self {
            current_lsb_a: inv.current_sense_full_scale_a / half,
            current_zero_code: half,
            adc_max_code: max,
            dc_bus_lsb_v: inv.dc_bus_sense_full_scale_v / max,
            encoder_counts_per_rev: inv.encoder_counts_per_rev as f64,
        }
    }

    /// ADC code of a phase current (rounded, clipped to the converter range).
    pub fn current_code(&self, current_a: f64) -> u16 {
        (self.current_zero_code + current_a / self.current_lsb_a).round().clamp(0.0, self.adc_max_code) as u16
    }

    /// ADC code of the DC-bus voltage.
    pub fn dc_bus_code(&self, dc_bus_v: f64) -> u16 {
        (dc_bus_v / self.dc_bus_lsb_v).round().clamp(0.0, self.adc_max_code) as u16
    }

    /// Encoder counter for the shaft angle `theta_m_rad` from the zero mark:
    /// whole counts, as the free-running 32-bit hardware counter holds them
    /// (modulo 2^32).
    pub fn encoder_count(&self, theta_m_rad: f64) -> u32 {
        let counts = (theta_m_rad / std::f64::consts::TAU * self.encoder_counts_per_rev).floor() as i64;
        counts.rem_euclid(1 << 32) as u32
    }

    /// Microsecond time stamp of `t_s` (a free-running 32-bit timer).
    pub fn time_us(t_s: f64) -> u32 {
        ((t_s * 1.0e6).floor() as i64).rem_euclid(1 << 32) as u32
    }
}
