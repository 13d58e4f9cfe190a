//! The travel: the controller's sequence from start-up to brake set, the
//! jerk-limited profile it follows, the speed loop with the out-of-balance
//! feed-forward of the paper (Eqn 4), and the fault supervisor that trips it.
//!
//! [`startup`] runs first (settling, current offsets, rotor alignment);
//! then [`controller`] takes one step per PWM period: the reference of
//! [`profile`], the torque of [`speed_loop`], the checks of [`supervisor`].

pub mod controller;
pub mod profile;
pub mod speed_loop;
pub mod startup;
pub mod supervisor;
