//! The chain observer as a task of its own, outside the control step, on a
//! fixed schedule.
//!
//! The observer's update (about 8 800 instructions on the Cortex-M4F on
//! average, up to 15 300; a PWM period is 10 625 cycles at 170 MHz) does
//! not fit the 16 kHz control interrupt, so the controller does not run
//! it: at each speed-loop tick `k` it publishes the observer's input (an
//! [`ObserverInput`]: the encoder counter and the machine torque `Kt i_q` of
//! that tick, or the start of a travel when the brake lifts) in its
//! [`ObserverLink`], and an [`ObserverTask`] running at a lower priority takes
//! it, runs [`ChainObserver::update`] and hands back an [`ObserverOutput`].
//!
//! Schedule (the same on the chip, in the processor-in-the-loop target and
//! in the host closed loop, which is why they stay bit-identical): **the
//! estimate computed from tick `k`'s input is used at tick `k + 1`**, by the
//! ripple compensation's learning step of that tick. The task has one
//! speed-loop period (8 PWM periods, 500 us at 2 kHz) for each input.
//!
//! A missed deadline (the output of tick `k` not handed back when tick
//! `k + 1` runs, or an input of tick `k` overwritten by tick `k + 1`'s before
//! the task took it) is never hidden: the controller counts it
//! ([`ObserverLink::missed_deadlines`], [`crate::Controller::observer_missed_deadlines`]),
//! tick `k + 1` learns without a car acceleration (as before the observer
//! has started), and a late output is discarded, never used at a later tick
//! as if it were fresh.

use super::kalman::{ChainObserver, ObserverEstimate, ObserverTuning};
use super::model::{ChainModel, ModelError};

/// What the observer task is asked to do for one speed-loop tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ObserverRequest {
    /// The brake has just lifted: [`ChainObserver::start`] with the
    /// counterweight-side rope length (m), the car mass (kg) and the encoder
    /// counter (counts) now.
    Start {
        /// Counterweight-side rope length, m.
        lw_m: f32,
        /// Car mass of the load weighing, kg.
        m_car_kg: f32,
        /// Encoder counter, counts (wrapping).
        encoder_count: u32,
    },
    /// One speed-loop tick: [`ChainObserver::update`] with the encoder
    /// counter (counts) and the machine torque `Kt i_q` (N m).
    Update {
        /// Encoder counter, counts (wrapping).
        encoder_count: u32,
        /// Machine torque from the measured q current, N m.
        motor_torque_nm: f32,
    },
}

/// The observer's input of one speed-loop tick, published by the controller.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObserverInput {
    /// The speed-loop tick it belongs to (wrapping count of the controller's ticks).
    pub tick: u32,
    /// What to do.
    pub request: ObserverRequest,
}

/// What the observer task hands back for one input.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObserverOutput {
    /// The tick of the input it was computed from.
    pub tick: u32,
    /// The estimate after an update; `None` after a start (no estimate yet).
    pub estimate: Option<ObserverEstimate>,
}

/// The controller's side of the link to the observer task: the input
/// published at the latest tick, the output handed back, the estimate in
/// use and the missed deadlines. Plain data: the firmware keeps it inside
/// the controller, behind the control interrupt's critical section.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ObserverLink {
    /// Input published and not taken yet by the task.
    pending: Option<ObserverInput>,
    /// Tick of the latest input published (taken or not).
    published: Option<u32>,
    /// Output handed back by the task, not consumed yet.
    delivered: Option<ObserverOutput>,
    /// A start was published in this travel: the next ticks publish updates.
    started: bool,
    /// The latest estimate consumed (the one in use).
    estimate: Option<ObserverEstimate>,
    /// Deadlines missed since the link was made.
    missed: u32,
}

impl ObserverLink {
    /// At tick `tick`: the output of the input published at tick `tick - 1`,
    /// if the task handed it back in time. A published input with no output
    /// of its tick is a missed deadline (counted); an output of an older
    /// tick is discarded.
    pub fn consume(&mut self, tick: u32) -> Option<ObserverOutput> {
        let expected = self.published.filter(|&t| t == tick.wrapping_sub(1))?;
        self.published = None;
        match self.delivered.take() {
            Some(output) if output.tick == expected => {
                if output.estimate.is_some() {
                    self.estimate = output.estimate;
                }
                Some(output)
            }
            _ => {
                self.missed = self.missed.saturating_add(1);
                // The task has not even taken it: it never will.
                self.pending = None;
                None
            }
        }
    }

    /// Publishes the input of tick `tick`. One still waiting (the task did
    /// not take the previous one) is replaced; its deadline was already
    /// counted by [`ObserverLink::consume`].
    pub fn publish(&mut self, tick: u32, request: ObserverRequest) {
        if matches!(request, ObserverRequest::Start { .. }) {
            self.started = true;
            self.estimate = None;
        }
        self.pending = Some(ObserverInput { tick, request });
        self.published = Some(tick);
    }

    /// Whether a start was published (updates follow at the next ticks).
    pub fn is_started(&self) -> bool {
        self.started
    }

    /// Whether an input waits for the task.
    pub fn is_waiting(&self) -> bool {
        self.pending.is_some()
    }

    /// The observer task takes the input waiting, if any.
    pub fn take(&mut self) -> Option<ObserverInput> {
        self.pending.take()
    }

    /// The observer task hands back the output of an input.
    pub fn deliver(&mut self, output: ObserverOutput) {
        self.delivered = Some(output);
    }

    /// The latest estimate in use (consumed at a tick), if any since the start.
    pub fn estimate(&self) -> Option<ObserverEstimate> {
        self.estimate
    }

    /// Deadlines the task missed since the link was made (inputs whose
    /// output was not back by the next tick).
    pub fn missed_deadlines(&self) -> u32 {
        self.missed
    }
}

/// The chain observer run as a task: takes the inputs the controller
/// publishes and hands back the outputs (see the module documentation for
/// the schedule).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObserverTask {
    observer: ChainObserver,
    runs: u32,
}

impl ObserverTask {
    /// A task running `observer`.
    pub fn new(observer: ChainObserver) -> Self {
        Self { observer, runs: 0 }
    }

    /// A task running the observer of `chain` with the default tuning.
    pub fn for_model(chain: &ChainModel) -> Result<Self, ModelError> {
        ChainObserver::new(*chain, ObserverTuning::default()).map(Self::new)
    }

    /// The observer (its latest estimate, restarts).
    pub fn observer(&self) -> &ChainObserver {
        &self.observer
    }

    /// Inputs processed since the task was made.
    pub fn runs(&self) -> u32 {
        self.runs
    }

    /// Processes one input: a start or an update of the observer.
    pub fn run(&mut self, input: &ObserverInput) -> ObserverOutput {
        self.runs = self.runs.wrapping_add(1);
        let estimate = match input.request {
            ObserverRequest::Start { lw_m, m_car_kg, encoder_count } => {
                self.observer.start(lw_m, m_car_kg, encoder_count);
                None
            }
            ObserverRequest::Update { encoder_count, motor_torque_nm } => {
                Some(self.observer.update(encoder_count, motor_torque_nm))
            }
        };
        ObserverOutput { tick: input.tick, estimate }
    }

    /// Takes the input waiting in `controller`'s link, runs it and hands
    /// the output back: what the task does each time it wakes, in one call
    /// (host and processor-in-the-loop targets, which run it between two
    /// control steps). Whether an input was waiting.
    pub fn serve(&mut self, controller: &mut crate::Controller) -> bool {
        let Some(input) = controller.take_observer_input() else {
            return false;
        };
        let output = self.run(&input);
        controller.deliver_observer_output(output);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn update(count: u32) -> ObserverRequest {
        ObserverRequest::Update { encoder_count: count, motor_torque_nm: 1.0 }
    }

    fn output(tick: u32, a: f32) -> ObserverOutput {
        ObserverOutput {
            tick,
            estimate: Some(ObserverEstimate { car_acceleration_mps2: a, ..ObserverEstimate::default() }),
        }
    }

    #[test]
    fn the_estimate_of_a_tick_is_used_at_the_next_and_a_late_one_never() {
        let mut link = ObserverLink::default();
        assert_eq!(link.consume(10), None, "nothing published: no deadline");
        link.publish(10, ObserverRequest::Start { lw_m: 1.0, m_car_kg: 70.0, encoder_count: 0 });
        assert!(link.is_started());
        let input = link.take().unwrap();
        assert_eq!(input.tick, 10);
        link.deliver(ObserverOutput { tick: 10, estimate: None });
        assert_eq!(link.consume(11), Some(ObserverOutput { tick: 10, estimate: None }));
        assert_eq!(link.estimate(), None);
        link.publish(11, update(5));
        link.take().unwrap();
        link.deliver(output(11, 0.5));
        assert_eq!(link.consume(12).and_then(|o| o.estimate).map(|e| e.car_acceleration_mps2), Some(0.5));
        assert_eq!(link.missed_deadlines(), 0);
        // Tick 12's input taken but its output not back by tick 13: missed,
        // and the late output is not used at tick 14.
        link.publish(12, update(6));
        link.take().unwrap();
        assert_eq!(link.consume(13), None);
        assert_eq!(link.missed_deadlines(), 1);
        link.deliver(output(12, 0.7));
        link.publish(13, update(7));
        assert_eq!(link.consume(14), None, "the output of tick 12 is not tick 13's");
        assert_eq!(link.missed_deadlines(), 2);
        assert_eq!(link.take(), None, "tick 13's input, never taken, is dropped");
        assert_eq!(link.estimate().map(|e| e.car_acceleration_mps2), Some(0.5), "the last one in time stays");
    }

    #[test]
    fn a_task_computes_what_the_observer_run_inline_computes() {
        let chain = crate::config::reference_chain();
        let mut inline = ChainObserver::new(chain, ObserverTuning::default()).unwrap();
        let mut task = ObserverTask::for_model(&chain).unwrap();
        inline.start(2.0, 70.5, 100);
        let start = ObserverRequest::Start { lw_m: 2.0, m_car_kg: 70.5, encoder_count: 100 };
        assert_eq!(task.run(&ObserverInput { tick: 0, request: start }).estimate, None);
        let holding = chain.out_of_balance_torque_nm(2.0, 70.5);
        for k in 1..200u32 {
            let count = 100 + k * k / 16;
            let torque = holding + 0.01 * k as f32;
            let expected = inline.update(count, torque);
            let request = ObserverRequest::Update { encoder_count: count, motor_torque_nm: torque };
            let got = task.run(&ObserverInput { tick: k, request });
            assert_eq!(got, ObserverOutput { tick: k, estimate: Some(expected) });
        }
        assert_eq!(task.runs(), 200);
    }
}
