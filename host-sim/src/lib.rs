//! Host simulator of the elevator: the nominal plant of the seed paper (5-DOF
//! ropes, car, counterweight and sheave; PMSM; averaged inverter; sensors)
//! closed around the drive core of `shared`, and the analysis of what it
//! records.
//!
//! Data flows one way: config -> plant <-> controller -> recording ->
//! analysis. The plant never knows which controller drives it.

#![warn(missing_docs)]

pub mod analysis;
pub mod cli;
pub mod closed_loop;
pub mod compensation;
pub mod diagnosis;
pub mod faults;
pub mod foreign;
pub mod output;
pub mod pil;
pub mod plant;
pub mod plots;
pub mod recording;
pub mod synthetic;

/// The rig description (re-exported from `rig-config`).
pub use rig_config as config;
