//! The integration tests of the drive core around the simulated plant, one
//! test binary (one link) with a module per subject; `lib.rs` holds the
//! helpers they share.

mod closed_loop;
mod compensation;
mod effects;
mod faults;
mod fixed_point;
mod gap;
mod modes;
mod observer;
mod pil;
mod pil_faults;
