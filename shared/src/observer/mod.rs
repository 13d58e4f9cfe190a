//! The reduced 5-DOF observer: estimates the car acceleration, the
//! dynamic rope forces and the shaft disturbance torque from the encoder and
//! the machine torque `Kt i_q`, at the speed-loop rate (2 kHz), in `f32`.
//!
//! * [`model`]: the chain reduced to sheave, car and counterweight with the
//!   rope stiffnesses `EA / l` scheduled on the rope lengths (Eqn 1-3), the
//!   out-of-balance torque of Eqn 4 and the series discretisation;
//! * [`kalman`]: the extended Kalman filter that also identifies a scale on
//!   `EA` and the angle-locked machine ripple it does not know;
//! * [`task`]: the observer as a task of its own beside the control step,
//!   on a fixed schedule (the estimate of a tick's input used at the next
//!   tick), with missed deadlines counted.
//!
//! Typical use at the speed tick, with the brake lifted:
//!
//! ```
//! use drive_core::observer::{ChainModel, ChainObserver, ObserverTuning};
//! let model = ChainModel {
//!     m_cw_kg: 33.0, rope_total_length_m: 8.6, rope_ea_n: 1.0e6, rope_mass_per_length_kg_per_m: 0.095,
//!     sheave_inertia_kg_m2: 0.3385, sheave_radius_m: 0.065, c_cw_kg_per_s: 148.0, c_car_kg_per_s: 148.0,
//!     c_sheave_nms_per_rad: 3.0, gravity_mps2: 9.81, encoder_counts_per_rev: 16384,
//!     ripple_orders: [1, 6, 12, 36, 72],
//! };
//! let mut observer = ChainObserver::new(model, ObserverTuning::default()).unwrap();
//! observer.start(1.0, 70.5, 0);
//! let holding_nm = model.out_of_balance_torque_nm(1.0, 70.5);
//! let estimate = observer.update(0, holding_nm);
//! assert!(estimate.car_acceleration_mps2.abs() < 1e-3);
//! ```

pub mod kalman;
pub mod model;
pub mod task;

pub use kalman::{ChainObserver, ObserverEstimate, ObserverTuning};
pub use model::{ChainModel, ModelError};
pub use task::{ObserverInput, ObserverLink, ObserverOutput, ObserverRequest, ObserverTask};
