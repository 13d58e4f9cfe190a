//! The project's integration tests, one test binary (one link) with a module
//! per subject: the drive core closed around the simulated plant, the
//! processor in the loop on the emulated Cortex-M4, and the commands as a
//! user runs them (`commands`). `support.rs` holds the helpers they share.
//!
//! Run one subject with `cargo test -p host-sim --test integration MODULE::`.
//! The heavy sweeps run a fixed subset by default; each full sweep is an
//! ignored test of the same assertions, run on demand with
//! `cargo test --release -p host-sim --test integration -- --ignored NAME`.

mod closed_loop;
mod commands;
mod compensation;
mod docs_layout;
mod effect_harness;
mod effects;
mod faults;
mod fixed_point;
mod gap;
mod gap_foreign;
mod modes;
mod observer;
mod pil;
mod pil_dcp;
mod pil_faults;
mod pil_params;
mod support;
