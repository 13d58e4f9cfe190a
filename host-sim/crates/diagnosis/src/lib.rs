//! The sim-to-real gap diagnosis (`host-sim gap`): where a dataset departs
//! from the nominal model, which unmodelled effect of the library
//! (`plant::effects`) explains it, and how much of the gap it removes on
//! recordings held out from its fit.
//!
//! The pipeline, [`diagnose`] (in [`mod@pipeline`]), step by step:
//!
//! 1. [`prepare`] measures every recording ([`signals`]; a travel's torque
//!    and shaft angle derived once, [`travel_signals`], and handed to every
//!    step after it), then [`mod@calibrate`]: EA, guide and sheave damping
//!    identified from the data.
//! 2. [`prepare`]: every recording's counterpart made with the calibrated
//!    nominal model: [`simulate`]
//!    (closed loop) or, for travels under another drive, the mechanics
//!    driven by the measured torque ([`driven`], the ripple's phases read
//!    from that torque by [`ripple_phase`], what every run reads of the
//!    recording kept across them by [`travel_readings`]); which drive the
//!    rig runs, [`drive_finding`] decides on the closed loop's runs.
//! 3. [`compare`]: the comparison targets ([`target`]) and the nominal
//!    model's gap in cells of channel x travel phase x band ([`measure`]),
//!    with the [`replay`] (measured shaft motion into the mechanics) beside
//!    it; [`mod@locate`]: the gap located along the signal chain, in time and
//!    in frequency.
//! 4. [`attribution`]: every effect fitted and cross-validated
//!    ([`attribute`]); an effect that the calibration can absorb on the
//!    calibration re-done under its hypothesis ([`hypotheses`]); under
//!    another drive, the direct-axis current's lines ([`electrical_lines`]);
//!    in every travel, whether the recorded phase currents sum to zero
//!    ([`current_balance`]: a current-measurement error without a model).
//! 5. [`naming`]: a candidate is named only when it shrinks the held-out
//!    gap beyond its scatter and its fitted strength leaves no effect by
//!    more than its uncertainty.
//! 6. [`verdict`]: `nominal`, `explained` or `unexplained`, in the
//!    [`GapReport`] that [`report`] writes.
//!
//! The paper's identification, which the calibration uses and `host-sim
//! identify` reports, is here too, because it needs the plant model:
//! [`identify`] (Eqn 9, 11-13), [`identify_dataset`] (over a dataset) and
//! [`travel_signals`] (shaft angle, rope length, torque balance of a travel).
//!
//! In the data flow config -> plant <-> controller -> recording -> analysis
//! -> diagnosis this crate is the last step: it reads recordings
//! (`recording`), analyses them (`dsp`) and simulates their counterparts on
//! the plant in closed loop (`plant`, `closed-loop`); nothing upstream
//! depends on it.

#![warn(missing_docs)]

pub mod acquisition;
pub mod angle_alignment;
pub mod attribute;
pub mod attribution;
pub mod calibrate;
pub mod compare;
pub mod current_balance;
pub mod drive_finding;
pub mod drive_law;
pub mod driven;
pub mod electrical_lines;
pub mod error;
pub mod hypotheses;
pub mod identify;
pub mod identify_dataset;
pub mod locate;
pub mod measure;
pub mod naming;
pub mod pipeline;
pub mod prepare;
pub mod replay;
pub mod report;
pub mod ripple_phase;
pub mod screen;
pub mod signals;
pub mod simulate;
pub mod spectra;
pub mod target;
pub mod transducer;
pub mod travel_readings;
pub mod travel_signals;
pub mod verdict;

pub use compare::{CarAccelerationViews, DECAY_TOP_MODE_FACTOR, FOREIGN_TOP_FRACTION, FOREIGN_TOP_HZ, GAP_MEASURE};
pub use drive_finding::{DriveAssumption, DriveFinding, DriveModel, DRIVE_MISMATCH_DB, PROFILE_SPEED_TOLERANCE};
pub use error::DiagnosisError;
pub use pipeline::diagnose;
pub use prepare::RigSpeedLoop;
pub use verdict::{
    GapOptions, GapReport, RecordingGap, Verdict, EXPLAINED_SHRINK, NOMINAL_EXCESS_DB, PERSISTENT_CELL_DB,
    SUB_NOMINAL_REMOVAL_FRACTION,
};
