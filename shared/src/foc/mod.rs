//! Field-oriented control of the PMSM: the 16 kHz path from the phase
//! currents and the encoder to the PWM compares, in fixed point, and what
//! it needs at start-up (current-sensor offsets, rotor alignment).
//!
//! Phase currents -> Clarke -> Park ([`park_clarke`], angle from
//! [`speed_estimator`], sine and cosine from [`trig`]) -> dq current loop
//! ([`current_loop`], PI controllers of [`pi`]) -> inverse Park ->
//! space-vector modulation ([`svpwm`]), written before the deadline of
//! [`pwm_timing`].

pub mod alignment;
pub mod current_loop;
pub mod current_offset;
pub mod park_clarke;
pub mod pi;
pub mod pwm_timing;
pub mod speed_estimator;
pub mod svpwm;
pub mod trig;
