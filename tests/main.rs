//! The integration tests of the drive core around the simulated plant, one
//! test binary (one link) with a module per subject; `lib.rs` holds the
//! helpers they share.
//!
//! The heavy sweeps run a fixed subset by default; each full sweep is an
//! ignored test of the same assertions, run on demand with
//! `cargo test --release -p integration-tests -- --ignored NAME`.

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
