//! NUCLEO-G474RE board support: the pin map of the drive (generated from
//! the board description), the clock tree, the brake output and the safe
//! state.
//!
//! # Pin map
//!
//! The pins, their alternate functions and active levels come from the
//! board description (`configs/boards/nucleo-g474re-ihm08m1.toml`, or the
//! one `DRIVE_BOARD` names), through `build.rs` into
//! `$OUT_DIR/board_generated.rs`: one type alias per pin (`PwmULow`), its
//! AF and active level (`PWM_U_LOW_ACTIVE_LOW`), a `board_pin!` macro that
//! takes the pin from embassy's `Peripherals`, and the current-sense sign.
//! The table with the manual behind each row is in `docs/firmware.md`
//! ("Pin map and scales"); `cargo test -p rig-config board` checks that the
//! description says what that table says. The `const _` block at the end
//! of this module checks every pin against embassy-stm32's pin traits
//! (ST's own STM32G474RE data): a pin that cannot carry its signal does not
//! build.
//!
//! On the IHM08M1 (facts and sources in the table):
//! - Gates: high sides PA8/PA9/PA10 (TIM1_CH1-CH3), low sides PA7/PB0/PB1
//!   (TIM1_CH1N-CH3N, AF6; NuttX's IHM08M1 table, oxifoc's transcription
//!   of UM1996 tables 3/4). The L6398's HIN is active high and its LIN
//!   active low (its truth table), so the timer's complementary outputs
//!   are active low (CCxNP = 1) with an idle level high (OISxN = 1): with
//!   MOE = 0 and OSSI = 1 every gate input is at its off level (RM0440
//!   table 265, `pwm.rs`). Before `pwm::init` the pins are high-impedance
//!   and the L6398's own input bias keeps the switches off (HIN pull-down,
//!   LIN pull-up: datasheet table 8, the input bias currents).
//! - TIM1_BKIN on PA6, active low. The shield also routes its BKIN net to
//!   PA11 and PB14, and the U low-side input to PB15 (solder resistors
//!   R73, R74, R86), and its over-current reference CURRENT_REF to PB4:
//!   the firmware never configures those pins (reset state, analog).
//! - Brake on PC8 as TIM8_CH3 in forced-output mode ([`Brake`]): released
//!   only while TIM8's MOE is set and the channel is forced active; idle,
//!   a debug halt (DBG_TIM8_STOP: the outputs go to their idle level as if
//!   MOE were 0, RM0440 advanced-control timers, debug mode), a reset
//!   (pin high-impedance, the brake driver's pull-down) and
//!   [`force_safe_state`] all apply it.
//! - The DCP transceiver on UART5 (PC12 TX, PD2 RX) with its driver enable
//!   on PC10, a plain GPIO `dcp.rs` drives around each reply: UART5's own
//!   DE pin is PB4 (CURRENT_REF), and every other UART's DE pin of this
//!   package is a shield signal too. Not on PA12 (the shield's comparator
//!   output CPOUT) nor PC13 (the user button B1): no output of the
//!   firmware is.
//! - The phase currents on PA0 (ADC1_IN1), PC1 (ADC2_IN7), PC0 (ADC1_IN6),
//!   the bus on PA1 (ADC2_IN2): each injected sequence (two ranks,
//!   triggered together by TIM1_TRGO2) samples two phase currents at the
//!   same instant:
//!
//! | ADC  | rank 1                 | rank 2                  |
//! |------|------------------------|-------------------------|
//! | ADC1 | IN1, phase U (12.5 cy) | IN6, phase W (12.5 cy)  |
//! | ADC2 | IN7, phase V (12.5 cy) | IN2, DC bus (24.5 cy)   |
//!
//! (Sampling times in ADC clock cycles at 42.5 MHz, see [`clock_config`].)
//! The DC bus gets the longer sampling time because its divider is a high
//! impedance source; it also makes ADC2 finish last, so ADC2's end of
//! sequence (JEOS) is the control interrupt. The shield's amplifiers invert
//! ([`CURRENT_SENSE_INVERTED`]): `adc.rs` mirrors each current code so the
//! drive core sees a current into the machine above mid-scale.
//!
//! Not verified without the boards (also in `docs/firmware.md`): the
//! IHM08M1's solder bridges and jumpers for three shunts (J5/J6), BKIN's
//! active-low level, that PB6, PB7, PC8, PC10, PC12 and PD2 are free on
//! the shield, the brake driver's pull-down, the sign of the encoder count.
//! Of the RM0440 facts used here and in `pwm.rs`, table 265 (MOE = 0 with
//! OSSI = 1: outputs at their idle levels OISx/OISxN) was read; that a
//! debug-halted advanced timer disables its outputs as if MOE were 0 and
//! the TIM1 LOCK levels are quoted as remembered: check them with a scope
//! on the first power-up, bridge supply off.
//!
//! - TIM4 is a 16-bit timer: `encoder.rs` extends its count to the `u32` of
//!   `drive_core::SensorFrame` in software.
//! - The timer of the Embassy time driver is TIM15 (Cargo feature
//!   `time-driver-tim15`), so it never takes TIM1, TIM4 or TIM8.
//! - Timer 2 (32-bit) is the 1 MHz time base of the control interrupt's time
//!   stamps; it uses no pin.

use embassy_stm32::gpio::{AfType, Flex, OutputType, Speed};
use embassy_stm32::pac::timer::vals::{Lock, Ocm, Ossi, Ossr};
use embassy_stm32::rcc::{mux, AHBPrescaler, APBPrescaler, Pll, PllMul, PllPreDiv, PllRDiv, PllSource, Sysclk};
use embassy_stm32::timer::{Ch3, TimerPin};
use embassy_stm32::{pac, peripherals};
use embassy_stm32::{Config, Peri};

include!(concat!(env!("OUT_DIR"), "/board_generated.rs"));

/// Inverter PWM timer: advanced-control timer with complementary outputs,
/// dead time and break input.
pub type PwmTimer = peripherals::TIM1;
/// Encoder timer, in quadrature encoder mode.
pub type EncoderTimer = peripherals::TIM4;
/// Brake timer: an advanced-control timer, so that a debug halt and MOE = 0
/// put its output to the idle level (brake applied).
pub type BrakeTimer = peripherals::TIM8;
/// ADC converting phases U and W (ranks 1 and 2 of its injected sequence).
pub type AdcUw = peripherals::ADC1;
/// ADC converting phase V and the DC bus (ranks 1 and 2); its end of
/// sequence is the control interrupt.
pub type AdcVBus = peripherals::ADC2;
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
/// TIM1's main output enable off (every gate input at its off level: high
/// sides low, low sides high; immediate) and TIM8's off (the brake output
/// at its idle level: applied). For the panic and fault handlers: the
/// timers keep running on their own when the core stops. Harmless before
/// the timers are set up (their registers ignore writes while their clocks
/// are off).
pub fn force_safe_state() {
    pac::TIM1.bdtr().modify(|w| w.set_moe(false));
    pac::TIM8.bdtr().modify(|w| w.set_moe(false));
}

/// While a debugger halts the core: stops TIM1 and TIM8, whose outputs then
/// go to their idle levels as if MOE were cleared (RM0440, debug mode of the
/// advanced-control timers; OSSI = 1 on both): gates off and brake applied;
/// and stops the independent watchdog, so that a breakpoint does not reset
/// the chip. No effect without a debugger.
pub fn freeze_on_debug_halt() {
    pac::DBGMCU.apb2fzr().modify(|w| {
        w.set_tim1(true);
        w.set_tim8(true);
    });
    pac::DBGMCU.apb1lfzr().modify(|w| w.set_iwdg(true));
}

/// The brake output: PC8 as TIM8_CH3 in forced-output mode. Released only
/// while TIM8's MOE is 1 and the channel is forced active; MOE = 0 (idle,
/// [`force_safe_state`], a debug halt) drives the idle level, which
/// applies the brake, and so does the pin's reset state (high impedance,
/// the brake driver's pull-down).
pub struct Brake(());

impl Brake {
    /// Sets TIM8 and the pin up, brake applied.
    pub fn new(tim: Peri<'static, BrakeTimer>, pin: Peri<'static, BrakePin>) -> Self {
        // The low-level driver enables and resets TIM8's clock; it is leaked
        // so that its Drop never stops the clock.
        core::mem::forget(embassy_stm32::timer::low_level::Timer::new(tim));
        let t = pac::TIM8;
        t.bdtr().modify(|w| {
            w.set_moe(false);
            w.set_ossi(Ossi::IDLE_LEVEL);
            w.set_ossr(Ossr::IDLE_LEVEL);
        });
        let active_low = BRAKE_PIN_ACTIVE_LOW;
        // Idle level = the applied level (low for an active-high release).
        t.cr2().modify(|w| w.set_ois(2, active_low));
        t.ccmr_output(1).modify(|w| w.set_ocm(0, Ocm::FORCE_INACTIVE));
        t.ccer().modify(|w| {
            w.set_ccp(2, active_low);
            w.set_cce(2, true);
        });
        // LOCK level 1: the idle level and off-state selection stay as set
        // (level 3 would also lock the output mode, which releases it).
        t.bdtr().modify(|w| w.set_lock(Lock::LEVEL1));
        t.cr1().modify(|w| w.set_cen(true));
        let af = <BrakePin as TimerPin<BrakeTimer, Ch3>>::af_num(&pin);
        let mut flex = Flex::new(pin);
        flex.set_as_af_unchecked(af, AfType::output(OutputType::PushPull, Speed::Low));
        core::mem::forget(flex);
        Brake(())
    }

    /// Releases (`true`) or applies the brake, immediately.
    #[inline]
    pub fn set_released(&mut self, released: bool) {
        let t = pac::TIM8;
        t.ccmr_output(1).modify(|w| w.set_ocm(0, if released { Ocm::FORCE_ACTIVE } else { Ocm::FORCE_INACTIVE }));
        t.bdtr().modify(|w| w.set_moe(released));
    }
}

// Compile-time check of the pin map against the G474RE's alternate functions
// and ADC inputs (the channel numbers are checked when `adc::init` runs).
const _: () = {
    use embassy_stm32::adc::AdcChannel;
    use embassy_stm32::timer::{BkIn1, BreakInputPin, Ch1, Ch2};
    use embassy_stm32::timer::{TimerChannel, TimerComplementaryPin};
    use embassy_stm32::usart::{RxPin, TxPin};

    // Each compiles only if pin P carries the signal on the G474RE.
    const fn pwm<P: TimerPin<PwmTimer, C>, C: TimerChannel>() {}
    const fn pwm_n<P: TimerComplementaryPin<PwmTimer, C>, C: TimerChannel>() {}
    const fn break_in<P: BreakInputPin<PwmTimer, BkIn1>>() {}
    const fn encoder<P: TimerPin<EncoderTimer, C>, C: TimerChannel>() {}
    const fn brake<P: TimerPin<BrakeTimer, Ch3>>() {}
    const fn analog<P: AdcChannel<A>, A: embassy_stm32::adc::Instance>() {}
    const fn dcp<Tx: TxPin<DcpUart>, Rx: RxPin<DcpUart>>() {}
    const fn gpio<P: embassy_stm32::gpio::Pin>() {}

    pwm::<PwmUHigh, Ch1>();
    pwm::<PwmVHigh, Ch2>();
    pwm::<PwmWHigh, Ch3>();
    pwm_n::<PwmULow, Ch1>();
    pwm_n::<PwmVLow, Ch2>();
    pwm_n::<PwmWLow, Ch3>();
    break_in::<BreakIn>();
    encoder::<EncoderA, Ch1>();
    encoder::<EncoderB, Ch2>();
    brake::<BrakePin>();
    analog::<Peri<'static, CurrentUPin>, AdcUw>();
    analog::<Peri<'static, CurrentWPin>, AdcUw>();
    analog::<Peri<'static, CurrentVPin>, AdcVBus>();
    analog::<Peri<'static, DcBusPin>, AdcVBus>();
    dcp::<DcpTx, DcpRx>();
    gpio::<DcpDe>();
    assert!(DCP_DE_AF == -1, "the driver enable is a plain GPIO output, not the UART's DE");

    // The gate polarity the L6398 needs: high sides active high, low sides
    // active low (the description's rows; pwm.rs programs CCxP/CCxNP and
    // OISx/OISxN from them).
    assert!(!PWM_U_HIGH_ACTIVE_LOW && !PWM_V_HIGH_ACTIVE_LOW && !PWM_W_HIGH_ACTIVE_LOW);
    assert!(PWM_U_LOW_ACTIVE_LOW == PWM_V_LOW_ACTIVE_LOW && PWM_V_LOW_ACTIVE_LOW == PWM_W_LOW_ACTIVE_LOW);
    assert!(BREAK_IN_ACTIVE_LOW, "pwm.rs programs TIM1's break input active low");
};

/// The UART of the DCP line (the description's `DcpTx`/`DcpRx` pins; its
/// driver enable `DcpDe` is a GPIO).
pub type DcpUart = peripherals::UART5;
