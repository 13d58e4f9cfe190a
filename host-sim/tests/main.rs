//! The commands' integration tests, one binary (one link) with a module per
//! concern: `cargo test -p host-sim --test host-sim <module>::`.

mod bad_input;
mod cli;
mod doc_commands;
mod foreign_rig;
mod input_fuzz;
mod recording_read;
mod ride_quality;
mod rig_sample;
