//! Drive firmware of the elevator on the NUCLEO-G474RE (STM32G474RE).
//!
//! This build brings up the clocks, the brake output and the drive core of
//! `shared` with the rig's parameters (generated at build time from
//! `configs/rig.toml`), and runs the controller on a timer tick. The inverter
//! PWM (TIM1), the ADC sampling and the encoder (TIM4) come with the PWM/ADC
//! issue; until then the bridge stays off and the brake stays applied.
#![no_std]
#![no_main]
#![deny(unsafe_code)]
#![warn(missing_docs)]

mod board;

use defmt::{info, Debug2Format};
use embassy_executor::Spawner;
use embassy_stm32::gpio::Level;
use embassy_stm32::time::Hertz;
use embassy_time::{Duration, Instant, Ticker};
use shared::{Controller, SensorFrame};
use {defmt_rtt as _, panic_probe as _};

include!(concat!(env!("OUT_DIR"), "/drive_config.rs"));

/// Rate of the placeholder control tick, Hz: the current-loop rate, because
/// `Controller::step` is one PWM period and its supervisor latches
/// `DeadlineMissed` if steps come more than 2.5 periods apart.
const TICK_HZ: u64 = DRIVE_CONFIG.current_loop_hz as u64;
const _: () = assert!(
    TICK_HZ > 0 && TICK_HZ as f32 == DRIVE_CONFIG.current_loop_hz,
    "current_loop_hz must be a whole number of hertz"
);
// rig-config derives the PWM period from its own idea of the timer clock
// (centre-aligned counting): it must be the clock this board runs TIM1 at.
const _: () = assert!(
    (board::SYSCLK_HZ as f32 / (2.0 * DRIVE_CONFIG.pwm_hz)) as u16 == DRIVE_CONFIG.pwm_period_counts,
    "configs/rig.toml's pwm_timer_clock_hz does not match board::SYSCLK_HZ"
);

/// Whether this build drives the inverter. It does not: TIM1 is not set up,
/// so the machine produces no torque and the brake must stay applied whatever
/// the controller asks. The PWM/ADC issue removes this interlock.
const INVERTER_PWM_RUNNING: bool = false;

#[embassy_executor::main]
async fn main(_spawner: Spawner) {
    let p = embassy_stm32::init(board::clock_config());

    let clocks = embassy_stm32::rcc::clocks(&p.RCC);
    info!("clocks: {}", clocks);
    defmt::assert!(
        clocks.sys.to_hertz() == Some(Hertz(board::SYSCLK_HZ)),
        "SYSCLK is not the 170 MHz the drive timing assumes"
    );

    let mut brake = board::brake_output(p.PC8);
    let mut controller = Controller::new(&DRIVE_CONFIG);
    info!(
        "drive core up: PWM {} Hz, current loop {} Hz, speed loop {} Hz, control tick {} Hz",
        DRIVE_CONFIG.pwm_hz, DRIVE_CONFIG.current_loop_hz, DRIVE_CONFIG.speed_loop_hz, TICK_HZ
    );

    // PLACEHOLDER for the ADC interrupt path of the PWM/ADC issue, which will
    // call `Controller::step` from the ADC end-of-conversion interrupt once
    // per PWM period with measured values. Here an async ticker stands in for
    // that interrupt. No sensor is read, and the frame says so instead of
    // inventing measurements:
    // - phase currents at the ADC zero-current code: the bridge is off, so no
    //   phase current flows;
    // - encoder count 0: the encoder is not read;
    // - DC-bus code 0: the bus is not measured. The supervisor therefore
    //   latches `Tripped(DcBusUnderVoltage)` at the first step: PWM off, brake
    //   applied, which is the right state for a drive without measurements;
    // - time: the real uptime in microseconds (wraps modulo 2^32 like the
    //   controller expects).
    let idle_code = DRIVE_CONFIG.adc_zero_code();
    let mut ticker = Ticker::every(Duration::from_hz(TICK_HZ));
    let mut ticks: u64 = 0;
    loop {
        ticker.next().await;

        let frame = SensorFrame {
            phase_current_codes: [idle_code; 3],
            encoder_count: 0,
            dc_bus_code: 0,
            // Truncation is the intended wrap-around of the u32 microsecond clock.
            time_us: Instant::now().as_micros() as u32,
        };
        let output = controller.step(&frame);

        // Brake applied = low. Released only when the controller asks for it
        // AND the inverter holds the load (never, in this build).
        let release = output.brake_released && INVERTER_PWM_RUNNING;
        brake.set_level(if release { Level::High } else { Level::Low });

        ticks += 1;
        if ticks % TICK_HZ == 0 {
            info!(
                "t={}s state={} pwm_enabled={} brake_released={} (pin {}) compare={}",
                ticks / TICK_HZ,
                Debug2Format(&output.state),
                output.pwm_enabled,
                output.brake_released,
                if release { "high" } else { "low" },
                output.pwm_compare,
            );
        }
    }
}
