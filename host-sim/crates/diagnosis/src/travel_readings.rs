//! What the torque-driven model reads of a travel's own recording (its
//! measured torque and shaft angle) the same way in every run of a fit:
//! worked out by the first run that needs it and kept for the others
//! ([`TravelReadings`], held by [`crate::simulate::DrivenInputs`]).
//!
//! A reading is kept under the inputs it depends on besides the recording
//! (a brake sample, a sheave radius, an order and a window), so a run that
//! asks with other inputs works its own out; a run whose torque or angle is
//! not the recording's (a hypothesised encoder or transducer error) reads
//! nothing from here ([`crate::driven::DrivenTravel::readings`]).

use std::ops::Range;
use std::sync::{Arc, Mutex};

use nalgebra::Complex;

use crate::error::Result;

/// The low-passed shaft motion and torque from which the brake is read
/// ([`crate::driven::unexplained_torque_nm`]), one value per sample.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BrakeSignals {
    /// Shaft angle from the first sample, rad.
    pub angle_rad: Vec<f64>,
    /// Measured torque, N m.
    pub torque_nm: Vec<f64>,
    /// Shaft speed, rad/s.
    pub speed_radps: Vec<f64>,
    /// Shaft acceleration, rad/s^2.
    pub acceleration_radps2: Vec<f64>,
}

/// The tracking loop's references of a travel: as recorded and as the loop
/// follows them past the brake (each a sheave-edge travel, m, and its
/// rate, m/s).
pub type TrackingReferences = ((Vec<f64>, Vec<f64>), (Vec<f64>, Vec<f64>));

/// The readings of one travel's recording, each worked out once.
#[derive(Debug, Default)]
pub struct TravelReadings {
    brake: Memo<(), Arc<BrakeSignals>>,
    tracking: Memo<(Option<usize>, u64), Arc<TrackingReferences>>,
    torque_lines: Memo<(u64, usize, usize), Option<Complex<f64>>>,
}

/// A copy starts with nothing read (the readings belong to the recording
/// the copy is made for).
impl Clone for TravelReadings {
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl TravelReadings {
    /// The brake's signals, `read` on first use.
    pub fn brake_signals(&self, read: impl FnOnce() -> Result<BrakeSignals>) -> Result<Arc<BrakeSignals>> {
        self.brake.get_or(&(), || read().map(Arc::new))
    }

    /// The tracking references for the brake at sample `brake` on a sheave
    /// of radius `radius_m` (m), `read` on first use.
    pub fn tracking(
        &self,
        brake: Option<usize>,
        radius_m: f64,
        read: impl FnOnce() -> Result<TrackingReferences>,
    ) -> Result<Arc<TrackingReferences>> {
        self.tracking.get_or(&(brake, radius_m.to_bits()), || read().map(Arc::new))
    }

    /// The measured torque's line of mechanical order `order` over the
    /// samples `window` ([`crate::ripple_phase::angle_locked_line`]),
    /// `read` on first use.
    pub fn torque_line(
        &self,
        order: f64,
        window: &Range<usize>,
        read: impl FnOnce() -> Option<Complex<f64>>,
    ) -> Option<Complex<f64>> {
        let key = (order.to_bits(), window.start, window.end);
        self.torque_lines.get_or(&key, || Ok(read())).ok().flatten()
    }
}

/// Values kept under their keys (a few per recording: a list searched in
/// order). A value is worked out outside the lock, so runs on other
/// threads wait only for the list; two that ask at once both work it out,
/// the same value, and the first is kept.
#[derive(Debug)]
struct Memo<K, V> {
    kept: Mutex<Vec<(K, V)>>,
}

impl<K, V> Default for Memo<K, V> {
    fn default() -> Self {
        Self { kept: Mutex::new(Vec::new()) }
    }
}

impl<K: PartialEq + Clone, V: Clone> Memo<K, V> {
    /// The value under `key`, from `work` when there is none yet (an error
    /// is returned and nothing kept).
    fn get_or(&self, key: &K, work: impl FnOnce() -> Result<V>) -> Result<V> {
        if let Some(value) = self.find(key) {
            return Ok(value);
        }
        let value = work()?;
        let mut kept = self.kept.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        if let Some((_, first)) = kept.iter().find(|(k, _)| k == key) {
            return Ok(first.clone());
        }
        kept.push((key.clone(), value.clone()));
        Ok(value)
    }

    /// The value under `key`, if kept.
    fn find(&self, key: &K) -> Option<V> {
        let kept = self.kept.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        kept.iter().find(|(k, _)| k == key).map(|(_, v)| v.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::bail;
    use std::cell::Cell;

    /// A reading is worked out once per key; an error is not kept.
    #[test]
    fn each_reading_is_worked_out_once_per_key() {
        let readings = TravelReadings::default();
        let calls = Cell::new(0);
        let line = |k: f64| {
            calls.set(calls.get() + 1);
            Some(Complex::new(k, 0.0))
        };
        assert_eq!(readings.torque_line(6.0, &(0..10), || line(6.0)), Some(Complex::new(6.0, 0.0)));
        assert_eq!(readings.torque_line(6.0, &(0..10), || line(-1.0)), Some(Complex::new(6.0, 0.0)));
        assert_eq!(readings.torque_line(6.0, &(0..11), || line(7.0)), Some(Complex::new(7.0, 0.0)));
        assert_eq!(calls.get(), 2);
        assert!(readings.brake_signals(|| bail!("not read")).is_err());
        let read = readings.brake_signals(|| Ok(BrakeSignals { angle_rad: vec![1.0], ..Default::default() }));
        assert_eq!(read.unwrap().angle_rad, vec![1.0]);
        let again = readings.brake_signals(|| bail!("read again"));
        assert_eq!(again.unwrap().angle_rad, vec![1.0]);
        assert!(readings.clone().brake_signals(|| bail!("a copy reads anew")).is_err());
    }
}
