//! The chain observer's task, in an Embassy interrupt executor below the
//! control interrupt.
//!
//! The observer's update (`drive_core::observer::ChainObserver::update`, up
//! to about 35 000 instructions) does not fit the 62.5 us control
//! interrupt. With a strategy that uses it (`car-observer`), the controller
//! publishes the observer's input at each speed-loop tick (2 kHz, every 8th
//! PWM period) and the control interrupt signals it to this task
//! ([`INPUT`]); the task runs the observer with interrupts enabled (the
//! control interrupt preempts it every PWM period) and signals the output
//! back ([`OUTPUT`]), which the control interrupt hands to the controller
//! at the start of its next step, and the controller uses it at the next
//! speed-loop tick: the schedule of
//! `drive_core::observer::task`, the same as in the processor-in-the-loop
//! target and the host closed loop, so the three agree bit for bit. The
//! task has one speed-loop period (85 000 CPU cycles) per input; if it is
//! late the controller counts a missed deadline
//! (`Controller::observer_missed_deadlines`, in the telemetry summary) and
//! learns nothing from that tick.
//!
//! Priorities: the control interrupt (`ADC1_2`) is P0, the time driver
//! (`TIM1_BRK_TIM15`) P1, this executor's interrupt (`UART4`, a peripheral
//! the board does not use) [`PRIORITY`], the thread-mode tasks (DCP,
//! service port, telemetry) below all of them.

use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::peripheral::DWT;
use drive_core::observer::{ObserverInput, ObserverOutput, ObserverTask};
use embassy_executor::InterruptExecutor;
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::{InterruptExt, Priority};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::signal::Signal;

/// Priority of the observer's executor: below the control interrupt (P0)
/// and the time driver (P1), above the thread-mode tasks.
pub const PRIORITY: Priority = Priority::P2;

/// The executor of the observer's task, run by the `UART4` interrupt.
static EXECUTOR: InterruptExecutor = InterruptExecutor::new();

/// The input the controller published at a speed-loop tick, signalled by
/// the control interrupt (a newer input replaces one not yet taken).
pub static INPUT: Signal<CriticalSectionRawMutex, ObserverInput> = Signal::new();

/// The output of an input, signalled by the task; the control interrupt
/// takes it at the start of its next step and hands it to the controller.
pub static OUTPUT: Signal<CriticalSectionRawMutex, ObserverOutput> = Signal::new();

/// Longest observer run since start, CPU cycles (preemption by the control
/// interrupt included).
static MAX_CYCLES: AtomicU32 = AtomicU32::new(0);

/// Observer runs since start (wraps).
static RUNS: AtomicU32 = AtomicU32::new(0);

#[interrupt]
#[allow(unsafe_code)]
unsafe fn UART4() {
    // SAFETY: this is the executor's interrupt handler, the only place
    // `on_interrupt` is called, and `start` below runs before the interrupt
    // is unmasked (it unmasks it itself).
    unsafe { EXECUTOR.on_interrupt() }
}

/// Starts the executor at [`PRIORITY`] and spawns the task running `task`.
pub fn start(task: ObserverTask) {
    interrupt::UART4.set_priority(PRIORITY);
    let spawner = EXECUTOR.start(interrupt::UART4);
    spawner.spawn(defmt::unwrap!(run(task)));
}

/// Longest observer run since start, CPU cycles.
pub fn max_cycles() -> u32 {
    MAX_CYCLES.load(Ordering::Relaxed)
}

/// Observer runs since start (wraps).
pub fn runs() -> u32 {
    RUNS.load(Ordering::Relaxed)
}

/// The task: waits for an input, runs it, hands the output back.
#[embassy_executor::task]
async fn run(mut task: ObserverTask) {
    loop {
        let input = INPUT.wait().await;
        let start = DWT::cycle_count();
        OUTPUT.signal(task.run(&input));
        MAX_CYCLES.fetch_max(DWT::cycle_count().wrapping_sub(start), Ordering::Relaxed);
        RUNS.fetch_add(1, Ordering::Relaxed);
    }
}
