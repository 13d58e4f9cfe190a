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
//! | Phase U current (Curr_fdbk1)     | PA0   | ADC1_IN1          | an |
//! | Phase V current (Curr_fdbk2)     | PC1   | ADC2_IN7          | an |
//! | Phase W current (Curr_fdbk3)     | PC0   | ADC1_IN6          | an |
//! | DC-bus voltage divider (VBUS)    | PA1   | ADC2_IN2          | an |
//! | DCP (RS-485) transmit, to DI     | PC10  | USART3_TX         | 7  |
//! | DCP (RS-485) receive, from RO    | PC11  | USART3_RX         | 7  |
//! | DCP (RS-485) driver enable DE+/RE| PB14  | USART3_DE         | 7  |
//!
//! ("an": analog mode.) All four analog pins are ADC12 inputs, i.e. both ADC1
//! and ADC2 can convert them, on the same channel numbers (PA0 IN1, PA1 IN2,
//! PC0 IN6, PC1 IN7). They are split so that each injected sequence (two
//! ranks, triggered together by TIM1_TRGO2) samples two phase currents at the
//! same instant:
//!
//! | ADC  | rank 1                 | rank 2                  |
//! |------|------------------------|-------------------------|
//! | ADC1 | IN1, phase U (12.5 cy) | IN6, phase W (12.5 cy)  |
//! | ADC2 | IN7, phase V (12.5 cy) | IN2, DC bus (24.5 cy)   |
//!
//! (Sampling times in ADC clock cycles at 42.5 MHz, see [`clock_config`].)
//! The DC bus gets the longer sampling time because its divider is a high
//! impedance source; it also makes ADC2 finish last, so ADC2's end of
//! sequence (JEOS) is the control interrupt.
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
//! - TIM4 is a 16-bit timer: `encoder.rs` extends its count to the `u32` of
//!   `drive_core::SensorFrame` in software (unambiguous, since the shaft moves
//!   far less than 2^15 counts in one PWM period).
//! - The timer of the Embassy time driver is TIM15 (Cargo feature
//!   `time-driver-tim15`), so it never takes TIM1 or TIM4.
//! - The analog pins are the IHM08M1's Arduino/morpho analog signals as ST's
//!   STM32 Nucleo-64 mapping of that board routes them (A0 = PA0 Curr_fdbk1,
//!   A1 = PA1 VBUS, A4 = PC1 Curr_fdbk2, A5 = PC0 Curr_fdbk3; PC2 carries
//!   its NTC, unused here), and the ADC1/ADC2 channel of each pin is checked
//!   at compile time below and at start-up against embassy-stm32's channel
//!   numbers. NOT verified against the UM1996 schematic and its three-shunt
//!   jumper settings (the IHM08M1 reportedly ships set up for one shunt): check
//!   J5/J6 and the op-amp gain before trusting the currents.
//! - NOT verified, and in conflict with `configs/rig.toml` as it stands:
//!   the IHM08M1 is a 10-48 V board (60 V MOSFETs) while the rig file
//!   assumes a 100 V bus, and the shield's current and bus-voltage scales
//!   (amplifier gain and offset, divider ratio) are not the rig file's
//!   assumed +-50 A and 200 V full scales. The firmware converts nothing
//!   itself: it hands the raw codes to the controller, which scales them
//!   with `configs/rig.toml`. Fix the rig file to the shield before running.
//! - NOT verified: the L6398 gate-driver inputs are taken as active high on
//!   both sides (TIM1 CCxP = CCxNP = 0), so a low gate pin is a switch off.
//! - NOT verified: the sign of the shunt amplifier outputs (positive phase
//!   current = current into the machine must read above mid-scale) and the
//!   direction of the encoder count (car up must count up).
//! - NOT verified: PA12, used here as TIM1_CH2N, is the IHM08M1's CPOUT
//!   (comparator output to TIM1_ETR) in ST's Nucleo-64 mapping; the shield
//!   must not drive that pin (open its resistor/solder bridge) or the two
//!   outputs fight.
//! - TIM1_BKIN on PA6 is active LOW: the IHM08M1's over-current circuit pulls
//!   the line to ground (UM1996: "generates a fault condition at the BKIN
//!   pin that goes to ground"); the pin has no internal pull, the shield's
//!   pull-up defines its idle level (NOT verified).
//! - DCP: an RS-485 transceiver (e.g. a 3.3 V MAX3485-class part) with DE
//!   and /RE tied together on PB14, which USART3 drives itself around each
//!   reply; A/B to the lift controller's DCP bus with its termination. The
//!   three USART3 pins are checked at compile time by the driver's pin
//!   traits (`dcp.rs`, `main.rs`); that PC10, PC11 and PB14 are free on the
//!   IHM08M1 and reachable on the NUCLEO's morpho connectors is NOT
//!   verified. Only a transceiver with a receiver that is
//!   disabled while transmitting keeps the drive from reading its own reply.
//! - Timer 2 (32-bit) is the 1 MHz time base of the control interrupt's time
//!   stamps; it uses no pin.
//!
//! Before `pwm::init` configures TIM1, the six gate pins are in their reset
//! state (analog mode, high impedance) and the gate-driver inputs rely on the
//! inverter board's pull-downs to keep every switch off: confirm that on the
//! IHM08M1 schematic before powering the bridge. From then on TIM1 drives
//! them, low (all switches off) whenever its main output enable MOE is 0.

use embassy_stm32::gpio::{Level, Output, Speed};
use embassy_stm32::rcc::{mux, AHBPrescaler, APBPrescaler, Pll, PllMul, PllPreDiv, PllRDiv, PllSource, Sysclk};
use embassy_stm32::{pac, peripherals};
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

/// ADC converting phases U and W (ranks 1 and 2 of its injected sequence).
pub type AdcUw = peripherals::ADC1;
/// ADC converting phase V and the DC bus (ranks 1 and 2); its end of
/// sequence is the control interrupt.
pub type AdcVBus = peripherals::ADC2;
/// Phase U current, shunt amplifier output (IHM08M1 Curr_fdbk1).
pub type CurrentUPin = peripherals::PA0;
/// Phase V current, shunt amplifier output (IHM08M1 Curr_fdbk2).
pub type CurrentVPin = peripherals::PC1;
/// Phase W current, shunt amplifier output (IHM08M1 Curr_fdbk3).
pub type CurrentWPin = peripherals::PC0;
/// DC-bus voltage divider output (IHM08M1 VBUS).
pub type DcBusPin = peripherals::PA1;
/// ADC1 channel of [`CurrentUPin`].
pub const CURRENT_U_CHANNEL: u8 = 1;
/// ADC2 channel of [`CurrentVPin`].
pub const CURRENT_V_CHANNEL: u8 = 7;
/// ADC1 channel of [`CurrentWPin`].
pub const CURRENT_W_CHANNEL: u8 = 6;
/// ADC2 channel of [`DcBusPin`].
pub const DC_BUS_CHANNEL: u8 = 2;

/// Free-running 32-bit microsecond counter of the control time stamps.
pub type TimebaseTimer = peripherals::TIM2;

/// SYSCLK (and HCLK, PCLK1, PCLK2, timer kernel clocks) after
/// [`clock_config`], Hz; `main` checks it against the clocks that
/// embassy-stm32 computed (which also range-checks PLL input and VCO).
pub const SYSCLK_HZ: u32 = 170_000_000;

/// Clock tree: 170 MHz SYSCLK from HSI16 through the PLL.
///
/// HSI16 / M 4 = 4 MHz PLL input, x N 85 = 340 MHz VCO, / R 2 = 170 MHz,
/// the G474's maximum, which needs Range 1 boost mode (flash wait states are
/// set by embassy-stm32). AHB, APB1 and APB2 undivided, so TIM1, TIM2, TIM4
/// and TIM15 all count at 170 MHz. ADC1/ADC2 run from SYSCLK; embassy-stm32's
/// ADC driver divides it by 4 to 42.5 MHz (the ADC's limit is 60 MHz).
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
    config.rcc.mux.adc12sel = mux::Adcsel::SYS;
    config
}

/// Puts the drive in its safe state from any context, without any driver:
/// TIM1's main output enable off (every gate low, both switches of each leg
/// off; takes effect immediately, not at the next PWM period) and the brake
/// applied (PC8 low). For the panic and fault handlers: TIM1 keeps switching
/// on its own when the core stops. Harmless before TIM1 is set up (its
/// registers ignore writes while its clock is off).
pub fn force_safe_state() {
    pac::TIM1.bdtr().modify(|w| w.set_moe(false));
    pac::GPIOC.bsrr().write(|w| w.set_br(8, true));
}

/// While a debugger halts the core: stops TIM1, whose outputs then go to
/// their safe state as if MOE were cleared (RM0440, debug support of the
/// advanced-control timers), and the independent watchdog, so that a
/// breakpoint neither leaves the bridge switching nor resets the chip. No
/// effect without a debugger.
pub fn freeze_on_debug_halt() {
    pac::DBGMCU.apb2fzr().modify(|w| w.set_tim1(true));
    pac::DBGMCU.apb1lfzr().modify(|w| w.set_iwdg(true));
}

/// Configures the brake output, applied (low) from the first instruction.
///
/// Fail-safe polarity: low applies the brake, so a reset (all pins
/// high-impedance inputs) also applies it, provided the brake driver's input
/// has a pull-down.
pub fn brake_output(pin: Peri<'static, BrakePin>) -> Output<'static> {
    Output::new(pin, Level::Low, Speed::Low)
}

// Compile-time check of the pin map against the G474RE's alternate functions
// and ADC inputs (the channel numbers are checked when `adc::init` runs).
const _: () = {
    use embassy_stm32::adc::AdcChannel;
    use embassy_stm32::timer::{BkIn1, BreakInputPin, Ch1, Ch2, Ch3};
    use embassy_stm32::timer::{TimerChannel, TimerComplementaryPin, TimerPin};

    // Each compiles only if pin P carries the signal on the G474RE.
    const fn pwm<P: TimerPin<PwmTimer, C>, C: TimerChannel>() {}
    const fn pwm_n<P: TimerComplementaryPin<PwmTimer, C>, C: TimerChannel>() {}
    const fn break_in<P: BreakInputPin<PwmTimer, BkIn1>>() {}
    const fn encoder<P: TimerPin<EncoderTimer, C>, C: TimerChannel>() {}
    const fn analog<P: AdcChannel<A>, A: embassy_stm32::adc::Instance>() {}

    pwm::<PwmUHigh, Ch1>();
    pwm::<PwmVHigh, Ch2>();
    pwm::<PwmWHigh, Ch3>();
    pwm_n::<PwmULow, Ch1>();
    pwm_n::<PwmVLow, Ch2>();
    pwm_n::<PwmWLow, Ch3>();
    break_in::<BreakIn>();
    encoder::<EncoderA, Ch1>();
    encoder::<EncoderB, Ch2>();
    analog::<Peri<'static, CurrentUPin>, AdcUw>();
    analog::<Peri<'static, CurrentWPin>, AdcUw>();
    analog::<Peri<'static, CurrentVPin>, AdcVBus>();
    analog::<Peri<'static, DcBusPin>, AdcVBus>();
};
