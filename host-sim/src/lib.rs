//! The `host-sim` commands: the command-line front end of the elevator
//! simulator and its tools (`host-sim --help` lists the commands).
//!
//! The work is done by the library crates under `host-sim/crates/`, along
//! the one-way data flow config -> plant <-> controller -> recording ->
//! analysis -> diagnosis: `rig-config` (the rig), `plant`, `closed-loop`
//! (the drive core of `drive-core` around the plant, faults, foreign rigs,
//! datasets, compensation, PIL), `recording`, `dsp` (signal processing),
//! `diagnosis` (identification and the gap diagnosis) and `plots`. This crate
//! only parses flags, calls them and writes their results ([`cli`], one
//! module per command).

#![warn(missing_docs)]

pub mod cli;
pub mod output;
