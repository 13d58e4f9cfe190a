//! What step 3 of the diagnosis hands on: one recording prepared for the
//! comparison (its measured cells, noise and tolerances, the nominal
//! model's spectra, how its counterpart is simulated), which the location
//! ([`mod@super::locate`]) and the attribution ([`super::attribute`]) read
//! alike, neither from the other.

use super::measure::Tolerances;
use super::signals::Channel;
use super::simulate::Counterpart;
use super::spectra::{CellPowers, ChainSpectra, Segmentation};
use recording::Recording;

/// One recording prepared for the comparison.
#[derive(Clone, Debug)]
pub struct Target {
    /// Recording name.
    pub stem: String,
    /// Cross-validation group (car mass).
    pub group: String,
    /// What the simulation needs of the measured recording (metadata; for a
    /// decay its acceleration).
    pub recording: Recording,
    /// Measured cell powers.
    pub measured: CellPowers,
    /// Measured noise densities, unit^2/Hz.
    pub noise: Vec<(Channel, f64)>,
    /// The model's reproducibility per cell, dB.
    pub tolerances: Tolerances,
    /// Segmentation of the model's runs (the nominal run's, aligned).
    pub segmentation: Segmentation,
    /// Spectra of the nominal model's run.
    pub nominal: ChainSpectra,
    /// How the model's counterpart is made (each effect's the same way).
    pub counterpart: Counterpart,
}
