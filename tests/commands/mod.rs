//! The commands' tests: `host-sim` run as a user runs it, on its own
//! recordings, foreign ones and broken input
//! (`cargo test -p host-sim --test integration commands::`).

mod bad_input;
mod cli;
mod decay_and_rig_input;
mod doc_commands;
mod foreign_rig;
mod input_fuzz;
mod outputs;
mod recording_read;
mod ride_quality;
mod rig_dev;
mod rig_sample;
