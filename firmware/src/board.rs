//! NUCLEO-G474RE board support: the pin map of the drive and the clock tree.
//!
//! # Pin map (the one place it is stated)
//!
//! Three-phase inverter: ST X-NUCLEO-IHM08M1 (STL220N6F7 bridge, L6398 gate
//! drivers) on the morpho connectors, with its STM32G4 mapping of the
//! complementary outputs.
//!
//! | Function                         | Pin   | Peripheral signal | AF |
//! |----------------------------------|-------|-------------------|----|
//! | Phase U high side                | PA8   | TIM1_CH1          | 6  |
//! | Phase V high side                | PA9   | TIM1_CH2          | 6  |
//! | Phase W high side                | PA10  | TIM1_CH3          | 6  |
//! | Phase U low side                 | PC13  | TIM1_CH1N         | 4  |
//! | Phase V low side                 | PA12  | TIM1_CH2N         | 6  |
//! | Phase W low side                 | PB15  | TIM1_CH3N         | 4  |
//! | Over-current break (gates off)   | PA6   | TIM1_BKIN         | 6  |
//! | Motor encoder A                  | PB6   | TIM4_CH1          | 2  |
//! | Motor encoder B                  | PB7   | TIM4_CH2          | 2  |
//! | Brake release (high = released)  | PC8   | GPIO output       | -  |
//!
//! What is verified and what is not:
//! - Every pin/signal/AF pair above is checked at compile time (the `const _`
//!   block at the end of this module) against embassy-stm32's pin traits,
//!   which come from ST's STM32G474RE data (stm32-metapac). A wrong pin
//!   does not build.
//! - The routing of the IHM08M1 gate inputs to PC13/PA12/PB15 (instead of
//!   the PA7/PB0/PB1 of its STM32F30x Nucleo mapping), PA6 as its
//!   over-current signal (project's board choice), and PB6/PB7/PC8 being
//!   free on both boards (chosen here) are NOT verified against
//!   UM1996 (IHM08M1) and UM2505 (NUCLEO-G474RE) solder-bridge settings:
//!   check them before powering the bridge.
//! - PC13 is also the NUCLEO's blue user button B1, and as an RTC-domain pin
//!   it has weak drive (G474 datasheet: at most 2 MHz into 30 pF, 3 mA,
//!   not to be used as a current source). Into the L6398's logic input at
//!   16 kHz PWM that is usable, but B1 must not be pressed while the bridge
//!   is powered, and its solder bridge should be opened.
//! - TIM4 is a 16-bit timer: the PWM/ADC issue has to extend its count to
//!   the `u32` of `shared::SensorFrame` in software. TIM2 (32-bit, encoder
//!   inputs PA15/PB3 AF1) would not need that; the project picked TIM4.
//! - The timer of the Embassy time driver is TIM15 (Cargo feature
//!   `time-driver-tim15`), so it never takes TIM1 or TIM4.
//! - The ADC channels of the phase currents and the DC bus belong to the
//!   PWM/ADC issue and are not assigned yet.
//!
//! While TIM1 is not configured (this build), the six gate pins stay in
//! their reset state (analog mode, high impedance), and the gate-driver
//! inputs rely on the inverter board's pull-downs to keep every switch off:
//! confirm that on the IHM08M1 schematic before powering the bridge.

use embassy_stm32::gpio::{Level, Output, Speed};
use embassy_stm32::peripherals;
use embassy_stm32::rcc::{AHBPrescaler, APBPrescaler, Pll, PllMul, PllPreDiv, PllRDiv, PllSource, Sysclk};
use embassy_stm32::{Config, Peri};

/// Inverter PWM timer: advanced-control timer with complementary outputs,
/// dead time and break input.
pub type PwmTimer = peripherals::TIM1;
/// Phase U high-side gate, TIM1_CH1.
pub type PwmUHigh = peripherals::PA8;
/// Phase V high-side gate, TIM1_CH2.
pub type PwmVHigh = peripherals::PA9;
/// Phase W high-side gate, TIM1_CH3.
pub type PwmWHigh = peripherals::PA10;
/// Phase U low-side gate, TIM1_CH1N.
pub type PwmULow = peripherals::PC13;
/// Phase V low-side gate, TIM1_CH2N.
pub type PwmVLow = peripherals::PA12;
/// Phase W low-side gate, TIM1_CH3N.
pub type PwmWLow = peripherals::PB15;
/// Over-current signal of the inverter board, TIM1_BKIN: forces the gate
/// outputs to their safe state in hardware, without software.
pub type BreakIn = peripherals::PA6;

/// Encoder timer, in quadrature encoder mode.
pub type EncoderTimer = peripherals::TIM4;
/// Encoder track A, TIM4_CH1.
pub type EncoderA = peripherals::PB6;
/// Encoder track B, TIM4_CH2.
pub type EncoderB = peripherals::PB7;

/// Brake output: high releases the machine brake, low applies it.
pub type BrakePin = peripherals::PC8;

/// SYSCLK (and HCLK, PCLK1, PCLK2, timer kernel clocks) after
/// [`clock_config`], Hz; `main` checks it against the clocks that
/// embassy-stm32 computed (which also range-checks PLL input and VCO).
pub const SYSCLK_HZ: u32 = 170_000_000;

/// Clock tree: 170 MHz SYSCLK from HSI16 through the PLL.
///
/// HSI16 / M 4 = 4 MHz PLL input, x N 85 = 340 MHz VCO, / R 2 = 170 MHz,
/// the G474's maximum, which needs Range 1 boost mode (flash wait states are
/// set by embassy-stm32). AHB, APB1 and APB2 undivided, so TIM1, TIM4 and
/// TIM15 all count at 170 MHz.
///
/// HSI16 is +-1 % over temperature: fine for the control loops, whose time
/// base is this same clock. The NUCLEO's 24 MHz HSE crystal can replace it
/// later if an absolute frequency reference is needed.
pub fn clock_config() -> Config {
    let mut config = Config::default();
    config.rcc.hsi = true;
    config.rcc.pll = Some(Pll {
        source: PllSource::HSI,
        prediv: PllPreDiv::DIV4,
        mul: PllMul::MUL85,
        divp: None,
        divq: None,
        divr: Some(PllRDiv::DIV2),
    });
    config.rcc.sys = Sysclk::PLL1_R;
    config.rcc.ahb_pre = AHBPrescaler::DIV1;
    config.rcc.apb1_pre = APBPrescaler::DIV1;
    config.rcc.apb2_pre = APBPrescaler::DIV1;
    config.rcc.boost = true;
    config
}

/// Configures the brake output, applied (low) from the first instruction.
///
/// Fail-safe polarity: low applies the brake, so a reset (all pins
/// high-impedance inputs) also applies it, provided the brake driver's input
/// has a pull-down.
pub fn brake_output(pin: Peri<'static, BrakePin>) -> Output<'static> {
    Output::new(pin, Level::Low, Speed::Low)
}

// Compile-time check of the pin map against the G474RE's alternate functions.
const _: () = {
    use embassy_stm32::timer::{BkIn1, BreakInputPin, Ch1, Ch2, Ch3};
    use embassy_stm32::timer::{TimerChannel, TimerComplementaryPin, TimerPin};

    // Each compiles only if pin P carries the signal on the G474RE.
    const fn pwm<P: TimerPin<PwmTimer, C>, C: TimerChannel>() {}
    const fn pwm_n<P: TimerComplementaryPin<PwmTimer, C>, C: TimerChannel>() {}
    const fn break_in<P: BreakInputPin<PwmTimer, BkIn1>>() {}
    const fn encoder<P: TimerPin<EncoderTimer, C>, C: TimerChannel>() {}

    pwm::<PwmUHigh, Ch1>();
    pwm::<PwmVHigh, Ch2>();
    pwm::<PwmWHigh, Ch3>();
    pwm_n::<PwmULow, Ch1>();
    pwm_n::<PwmVLow, Ch2>();
    pwm_n::<PwmWLow, Ch3>();
    break_in::<BreakIn>();
    encoder::<EncoderA, Ch1>();
    encoder::<EncoderB, Ch2>();
};
