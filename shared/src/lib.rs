//! The drive core of the elevator: fixed-point vector control of the PMSM,
//! the jerk-limited travel profile, the speed loop with the out-of-balance
//! feed-forward of the paper (Eqn 4) and the fault supervisor.
//!
//! The same code runs on the STM32G474 and in `host-sim`, bit for bit: the
//! 16 kHz path is integer/fixed-point (`fixed` crate, saturating), the rest
//! uses only IEEE-754 `f32` add, subtract, multiply and divide, which are
//! correctly rounded on both targets. No `f32::sin`, no `sqrt` from a libm.
//!
//! Equation numbers refer to Arrasate et al., "Measurement and simulation of
//! machine-borne vertical vibration in elevator systems" (the seed paper).
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

// Crate-wide: the parameters and the number types.
pub mod config; // `DriveConfig`: the drive's parameters in SI units
pub mod fixed; // Q16.16 / Q2.30 fixed point, saturating arithmetic, integer sqrt

// By concern.
pub mod foc; // field-oriented control: the 16 kHz current path, offsets, rotor alignment
pub mod lift; // the lift drive's application layer and its ports: DCP, service, parameters
pub mod observer; // the reduced chain observer (car acceleration, rope forces)
pub mod ripple; // torque-ripple compensation and its learning
pub mod travel; // the travel: controller sequence, profile, speed loop, start-up, fault supervisor

// The processor-in-the-loop link.
pub mod frame; // the PIL frame codec, both ends of the link

// The modules by their flat paths (`drive_core::controller`, ...), as the
// firmware, the PIL target, the simulator and the tests name them.
pub use foc::{alignment, current_loop, current_offset, park_clarke, pi, pwm_timing, speed_estimator, svpwm, trig};
pub use lift::{dcp, lift_drive, param_store, service};
pub use travel::{controller, profile, speed_loop, startup, supervisor};

pub use config::DriveConfig;
pub use controller::{ControlOutput, Controller, DriveState, SensorFrame, SpeedTravelCommand, TravelCommand};
