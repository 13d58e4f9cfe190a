//! The [`FaultHook`] that applies [`FaultSpec`]s to a closed-loop travel,
//! and what it observes of the plant while doing so.

use drive_core::supervisor::Fault;
use drive_core::{ControlOutput, DriveState, SensorFrame};

use super::{DisconnectedReading, FaultKind, FaultSpec, Onset};
use crate::{FaultHook, StepAction};
use plant::{PhaseShort, Plant};

/// A fault with its onset resolved to seconds from the travel command.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Active {
    kind: FaultKind,
    onset_s: f64,
    started: bool,
    /// Encoder counter (true reading) at the onset.
    encoder_at_onset: u32,
    /// Steps this fault has acted on (skips, late steps, corrupted frames).
    steps_done: u32,
}

/// What the injector saw of the plant and the drive from the first onset on.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Observed {
    /// The earliest onset, s from the travel command (once it has happened).
    pub first_onset_s: Option<f64>,
    /// The step at which the drive tripped (s) and why.
    pub trip: Option<(f64, Fault)>,
    /// Largest |leg current| (machine plus short) from the first onset, A,
    /// at the end of every control period.
    pub peak_current_a: f64,
    /// Largest |car acceleration| from the first onset to the trip (or the
    /// end of the run), m/s^2, at the end of every control period.
    pub peak_car_acceleration_mps2: f64,
    /// Largest |car acceleration| after the trip, m/s^2: the brake stopping
    /// the sheave (ideal in the plant: at once) with the car on the ropes.
    pub peak_car_acceleration_after_trip_mps2: f64,
    /// Car position at the trip, m (positive up).
    pub car_position_at_trip_m: f64,
    /// Largest |car position - position at the trip| after the trip, m.
    pub car_displacement_after_trip_m: f64,
    /// Largest |machine torque| from the period after the trip on, N m.
    pub torque_after_trip_nm: f64,
    /// A period after the trip had the PWM enabled or the brake released.
    pub unsafe_output_after_trip: bool,
    /// The drive left `Tripped` by itself after the trip.
    pub left_tripped: bool,
}

/// Applies faults to the plant and the controller's inputs.
#[derive(Clone, Debug)]
pub struct FaultInjector {
    faults: Vec<Active>,
    nominal_dc_bus_v: Option<f64>,
    gravity_mps2: f64,
    after_trip_s: Option<f64>,
    observed: Observed,
}

impl FaultInjector {
    /// Injects `faults` (onsets resolved with `resolve`: a named instant to
    /// seconds); after a trip the run goes on for `after_trip_s` (s) if set.
    pub fn new(
        faults: &[FaultSpec],
        resolve: impl Fn(Onset) -> f64,
        gravity_mps2: f64,
        after_trip_s: Option<f64>,
    ) -> Self {
        Self {
            faults: faults
                .iter()
                .map(|f| Active {
                    kind: f.kind,
                    onset_s: resolve(f.onset),
                    started: false,
                    encoder_at_onset: 0,
                    steps_done: 0,
                })
                .collect(),
            nominal_dc_bus_v: None,
            gravity_mps2,
            after_trip_s,
            observed: Observed::default(),
        }
    }

    /// What was observed so far.
    pub fn observed(&self) -> Observed {
        self.observed
    }

    /// Onsets of the faults, s from the travel command.
    pub fn onsets_s(&self) -> Vec<f64> {
        self.faults.iter().map(|f| f.onset_s).collect()
    }
}

/// A bus voltage ramp from `from_v` towards `to_v` at `rate_v_per_s` for `elapsed_s`.
fn ramp_v(from_v: f64, to_v: f64, rate_v_per_s: f64, elapsed_s: f64) -> f64 {
    let step = rate_v_per_s * elapsed_s;
    if to_v < from_v {
        (from_v - step).max(to_v)
    } else {
        (from_v + step).min(to_v)
    }
}

impl FaultHook for FaultInjector {
    fn before_step(&mut self, t_s: f64, plant: &mut Plant) {
        let nominal_bus = *self.nominal_dc_bus_v.get_or_insert(plant.dc_bus_v);
        let true_encoder = plant.sensor_frame().encoder_count;
        for fault in &mut self.faults {
            if t_s < fault.onset_s {
                continue;
            }
            let first = !fault.started;
            if first {
                fault.started = true;
                fault.encoder_at_onset = true_encoder;
                let onset = self.observed.first_onset_s.get_or_insert(t_s);
                *onset = onset.min(t_s);
            }
            let elapsed = t_s - fault.onset_s;
            match fault.kind {
                FaultKind::PhaseShort { from, to, resistance_ohm, inductance_h } if first => {
                    plant.faults.phase_short =
                        Some(PhaseShort { from: from.index(), to: to.index(), resistance_ohm, inductance_h });
                }
                FaultKind::OpenPhase { phase } if first => plant.set_open_phase(Some(phase.index())),
                FaultKind::DcBusSag { to_v, rate_v_per_s } | FaultKind::DcBusOverVoltage { to_v, rate_v_per_s } => {
                    plant.dc_bus_v = ramp_v(nominal_bus, to_v, rate_v_per_s, elapsed);
                }
                FaultKind::LoadChange { delta_kg } if first => {
                    plant.faults.car_extra_force_n += -delta_kg * self.gravity_mps2;
                }
                FaultKind::BrakeNotOpening if first => plant.faults.brake_stuck_closed = true,
                _ => {}
            }
        }
    }

    fn sensors(&mut self, t_s: f64, mut frame: SensorFrame, plant: &Plant) -> StepAction {
        let mut timing = None;
        let view = plant.observe();
        let leg_currents = view.phase_currents_a;
        // The peaks include the instant of the onset, before the controller acts.
        let o = &mut self.observed;
        if o.first_onset_s.is_some() && o.trip.is_none() {
            o.peak_current_a = leg_currents.iter().fold(o.peak_current_a, |m, i| m.max(i.abs()));
            o.peak_car_acceleration_mps2 = o.peak_car_acceleration_mps2.max(view.car_acceleration_mps2.abs());
        }
        let max_code = plant.sensors.adc_max_code as u16;
        for fault in self.faults.iter_mut().filter(|f| f.started) {
            let elapsed = t_s - fault.onset_s;
            match fault.kind {
                FaultKind::CurrentStuck { phase, value_a } => {
                    frame.phase_current_codes[phase.index()] = plant.sensors.current_code(value_a);
                }
                FaultKind::CurrentDisconnected { phase, reads } => {
                    frame.phase_current_codes[phase.index()] = match reads {
                        DisconnectedReading::FullScale => max_code,
                        DisconnectedReading::ZeroCode => 0,
                    };
                }
                FaultKind::CurrentDrift { phase, rate_a_per_s } => {
                    let i = phase.index();
                    frame.phase_current_codes[i] = plant.sensors.current_code(leg_currents[i] + rate_a_per_s * elapsed);
                }
                FaultKind::EncoderLosingCounts { fraction } => {
                    let moved = frame.encoder_count.wrapping_sub(fault.encoder_at_onset) as i32 as f64;
                    let seen = ((1.0 - fraction) * moved).floor() as i64;
                    frame.encoder_count = fault.encoder_at_onset.wrapping_add(seen as u32);
                }
                FaultKind::EncoderJump { counts } => {
                    frame.encoder_count = frame.encoder_count.wrapping_add(counts as u32);
                }
                FaultKind::EncoderStopped => frame.encoder_count = fault.encoder_at_onset,
                FaultKind::DeadlineSkip { steps } if fault.steps_done < steps && timing.is_none() => {
                    fault.steps_done += 1;
                    timing = Some(StepAction::Skip);
                }
                FaultKind::DeadlineLate { delay_us } if fault.steps_done == 0 && timing.is_none() => {
                    fault.steps_done = 1;
                    timing = Some(StepAction::Late { frame, delay_s: delay_us * 1.0e-6 });
                }
                FaultKind::FrameCorruption { count, byte, xor } if fault.steps_done < count && timing.is_none() => {
                    fault.steps_done += 1;
                    timing = Some(StepAction::Corrupt { frame, byte_index: byte, xor });
                }
                _ => {}
            }
        }
        // Sensor faults act on the frame whatever happens to the step.
        match timing {
            None => StepAction::Run(frame),
            Some(StepAction::Late { delay_s, .. }) => StepAction::Late { frame, delay_s },
            Some(StepAction::Corrupt { byte_index, xor, .. }) => StepAction::Corrupt { frame, byte_index, xor },
            Some(other) => other,
        }
    }

    fn after_step(&mut self, t_s: f64, plant: &Plant, output: &ControlOutput) {
        let o = &mut self.observed;
        if o.first_onset_s.is_none() {
            return;
        }
        let view = plant.observe();
        let current = view.phase_currents_a.iter().fold(0.0f64, |m, i| m.max(i.abs()));
        o.peak_current_a = o.peak_current_a.max(current);
        match (o.trip, output.state) {
            (None, DriveState::Tripped(fault)) => {
                o.trip = Some((t_s, fault));
                o.car_position_at_trip_m = view.car_position_m;
            }
            (Some(_), state) => {
                if !matches!(state, DriveState::Tripped(_)) {
                    o.left_tripped = true;
                }
                if output.pwm_enabled || output.brake_released {
                    o.unsafe_output_after_trip = true;
                }
                o.torque_after_trip_nm = o.torque_after_trip_nm.max(view.motor_torque_nm.abs());
                o.car_displacement_after_trip_m =
                    o.car_displacement_after_trip_m.max((view.car_position_m - o.car_position_at_trip_m).abs());
            }
            (None, _) => {}
        }
        // The brake acts from the trip step on: its period counts as after the trip.
        let acceleration = view.car_acceleration_mps2.abs();
        if o.trip.is_none() {
            o.peak_car_acceleration_mps2 = o.peak_car_acceleration_mps2.max(acceleration);
        } else {
            o.peak_car_acceleration_after_trip_mps2 = o.peak_car_acceleration_after_trip_mps2.max(acceleration);
        }
    }

    fn keep_running_after_trip_s(&self) -> Option<f64> {
        self.after_trip_s
    }
}
