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

pub mod alignment;
pub mod config;
pub mod controller;
pub mod current_loop;
pub mod current_offset;
pub mod dcp;
pub mod fixed;
pub mod frame;
pub mod lift_drive;
pub mod observer;
pub mod param_store;
pub mod park_clarke;
pub mod pi;
pub mod profile;
pub mod pwm_timing;
pub mod ripple;
pub mod service;
pub mod speed_estimator;
pub mod speed_loop;
pub mod startup;
pub mod supervisor;
pub mod svpwm;
pub mod trig;

pub use config::DriveConfig;
pub use controller::{ControlOutput, Controller, DriveState, SensorFrame, SpeedTravelCommand, TravelCommand};
