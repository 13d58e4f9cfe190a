//! Parameters of the drive core, in SI units.
//!
//! The host builds a [`DriveConfig`] from `configs/rig.toml`; the firmware
//! gets the same values generated at build time from the same file. The
//! controller derives every gain from these values in [`crate::Controller::new`].

/// Car travel direction.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Direction {
    /// Car up: the counterweight-side rope length `lw` grows.
    Up,
    /// Car down: `lw` shrinks.
    Down,
}

impl Direction {
    /// +1.0 for up, -1.0 for down (dimensionless).
    pub fn sign(self) -> f32 {
        match self {
            Direction::Up => 1.0,
            Direction::Down => -1.0,
        }
    }
}

/// Every parameter the drive core needs, SI units, as named.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveConfig {
    // --- machine (PMSM) ---
    /// Pole pairs `p` (Eqn 7: omega_s = p * omega_m).
    pub pole_pairs: u8,
    /// Stator resistance per phase, ohm.
    pub stator_resistance_ohm: f32,
    /// d-axis inductance, H.
    pub ld_h: f32,
    /// q-axis inductance, H.
    pub lq_h: f32,
    /// Permanent-magnet flux linkage (peak, per phase), Wb.
    pub flux_linkage_wb: f32,
    /// Largest q-current the speed loop may ask for, A.
    pub max_current_a: f32,
    /// Phase current that trips the drive, A.
    pub overcurrent_trip_a: f32,

    // --- inverter and sensing ---
    /// Nominal DC-bus voltage, V.
    pub dc_bus_nominal_v: f32,
    /// PWM carrier frequency, Hz.
    pub pwm_hz: f32,
    /// PWM timer auto-reload value: the compare value of a 100 % duty, counts.
    pub pwm_period_counts: u16,
    /// Phase-current transducer full scale: +-this value over the ADC range, A.
    pub current_sense_full_scale_a: f32,
    /// ADC resolution, bits (phase currents and DC bus).
    pub adc_bits: u8,
    /// DC-bus voltage at the top ADC code, V.
    pub dc_bus_sense_full_scale_v: f32,
    /// Encoder counts per mechanical revolution (after quadrature decoding).
    pub encoder_counts_per_rev: u32,

    // --- control ---
    /// Current-loop rate: one [`crate::Controller::step`] per period, Hz.
    pub current_loop_hz: f32,
    /// Speed-loop rate, Hz; `current_loop_hz / speed_loop_hz` must be a whole number.
    pub speed_loop_hz: f32,
    /// Closed-loop bandwidth of the dq current loops, Hz.
    pub current_loop_bandwidth_hz: f32,
    /// Closed-loop bandwidth of the speed loop, Hz.
    pub speed_loop_bandwidth_hz: f32,
    /// Natural frequency of the encoder speed estimator (tracking loop), Hz.
    pub speed_estimator_bandwidth_hz: f32,

    // --- mechanics known to the drive (feed-forward, Eqn 4) ---
    /// Counterweight mass `m_w`, kg.
    pub m_cw_kg: f32,
    /// Total rope length `l_t = l_w + l_c`, m.
    pub rope_total_length_m: f32,
    /// Rope mass per length `mu`, kg/m.
    pub rope_mass_per_length_kg_per_m: f32,
    /// Rotor plus traction-sheave inertia `I`, kg m^2.
    pub sheave_inertia_kg_m2: f32,
    /// Traction-sheave radius `r`, m.
    pub sheave_radius_m: f32,
    /// Gravitational acceleration, m/s^2.
    pub gravity_mps2: f32,

    // --- travel profile ---
    /// Rated car speed, m/s.
    pub rated_speed_mps: f32,
    /// Largest car acceleration, m/s^2.
    pub max_accel_mps2: f32,
    /// Largest car jerk, m/s^3.
    pub max_jerk_mps3: f32,

    // --- supervisor ---
    /// Over-speed trip as a multiple of the rated speed (dimensionless, > 1).
    pub overspeed_factor: f32,
    /// DC-bus under-voltage trip, V.
    pub dc_bus_undervoltage_v: f32,
    /// DC-bus over-voltage trip, V.
    pub dc_bus_overvoltage_v: f32,
    /// Largest plausible |i_a + i_b + i_c| of a star-connected machine, A.
    pub current_sum_limit_a: f32,
}

impl DriveConfig {
    /// Torque constant `Kt = 1.5 p psi`, N m/A (surface magnets, id = 0).
    pub fn torque_constant_nm_per_a(&self) -> f32 {
        1.5 * self.pole_pairs as f32 * self.flux_linkage_wb
    }

    /// Current-loop period, s.
    pub fn current_period_s(&self) -> f32 {
        1.0 / self.current_loop_hz
    }

    /// Current-loop steps per speed-loop step (at least 1).
    pub fn speed_loop_divider(&self) -> u32 {
        let ratio = self.current_loop_hz / self.speed_loop_hz;
        if ratio < 1.0 {
            1
        } else {
            // Round to nearest without libm; the host validates that it is whole.
            (ratio + 0.5) as u32
        }
    }

    /// Rated mechanical shaft speed `v / r`, rad/s.
    pub fn rated_shaft_speed_radps(&self) -> f32 {
        self.rated_speed_mps / self.sheave_radius_m
    }

    /// Phase current of one ADC code step, A.
    pub fn current_lsb_a(&self) -> f32 {
        self.current_sense_full_scale_a / (1u32 << (self.adc_bits - 1)) as f32
    }

    /// ADC code of zero phase current (mid-scale).
    pub fn adc_zero_code(&self) -> u16 {
        1u16 << (self.adc_bits - 1)
    }

    /// Largest ADC code.
    pub fn adc_max_code(&self) -> u16 {
        ((1u32 << self.adc_bits) - 1) as u16
    }
}

/// The reference rig's drive parameters as `configs/rig.toml` gives them,
/// for the unit tests of this crate.
#[cfg(test)]
pub(crate) fn reference_rig() -> DriveConfig {
    DriveConfig {
        pole_pairs: 6,
        stator_resistance_ohm: 1.2,
        ld_h: 0.015,
        lq_h: 0.015,
        flux_linkage_wb: 0.45,
        max_current_a: 20.0,
        overcurrent_trip_a: 30.0,
        dc_bus_nominal_v: 100.0,
        pwm_hz: 16000.0,
        pwm_period_counts: 5312,
        current_sense_full_scale_a: 50.0,
        adc_bits: 12,
        dc_bus_sense_full_scale_v: 200.0,
        encoder_counts_per_rev: 16384,
        current_loop_hz: 16000.0,
        speed_loop_hz: 2000.0,
        current_loop_bandwidth_hz: 1000.0,
        speed_loop_bandwidth_hz: 5.0,
        speed_estimator_bandwidth_hz: 25.0,
        m_cw_kg: 33.0,
        rope_total_length_m: 8.6,
        rope_mass_per_length_kg_per_m: 0.095,
        sheave_inertia_kg_m2: 0.3385,
        sheave_radius_m: 0.065,
        gravity_mps2: 9.81,
        rated_speed_mps: 0.4,
        max_accel_mps2: 0.5,
        max_jerk_mps3: 1.0,
        overspeed_factor: 1.25,
        dc_bus_undervoltage_v: 70.0,
        dc_bus_overvoltage_v: 130.0,
        current_sum_limit_a: 5.0,
    }
}

/// The reference rig's chain as `configs/rig.toml` gives it, for the unit
/// tests of this crate.
#[cfg(test)]
pub(crate) fn reference_chain() -> crate::observer::ChainModel {
    crate::observer::ChainModel {
        m_cw_kg: 33.0,
        rope_total_length_m: 8.6,
        rope_ea_n: 1.0e6,
        rope_mass_per_length_kg_per_m: 0.095,
        sheave_inertia_kg_m2: 0.3385,
        sheave_radius_m: 0.065,
        c_cw_kg_per_s: 148.0,
        c_car_kg_per_s: 148.0,
        c_sheave_nms_per_rad: 3.0,
        gravity_mps2: 9.81,
        encoder_counts_per_rev: 16384,
        ripple_orders: [1, 6, 12, 36, 72],
    }
}
