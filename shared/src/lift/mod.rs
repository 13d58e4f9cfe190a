//! The lift drive as the installation sees it: the application layer
//! ([`lift_drive`]) and its ports, the lift controller's DCP link
//! ([`dcp`]), the service port ([`service`]) and the parameters kept
//! across power cycles ([`param_store`]).

pub mod dcp;
pub mod lift_drive;
pub mod param_store;
pub mod service;
