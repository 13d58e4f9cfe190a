//! Phase-current and DC-bus sampling: ADC1 and ADC2 injected sequences,
//! started together by TIM1's TRGO2 at the PWM counter peak.
//!
//! Register use (RM0440, ADC):
//! - embassy-stm32's `Adc::new` powers each ADC up (DEEPPWD = 0, ADVREGEN),
//!   calibrates it single-ended and differential (ADCAL), enables it (ADEN),
//!   sets the ADC12 prescaler (CCR.PRESC = /4: 42.5 MHz from SYSCLK) and
//!   12-bit resolution (CFGR.RES = 0, the reset value).
//! - `setup_injected_conversions` writes JSQR (JL = 1: two ranks; JSQ1/JSQ2
//!   the channels of the table in `board.rs`; JEXTSEL = 8: TIM1_TRGO2;
//!   JEXTEN = rising edge), the sampling times SMPRx, IER.JEOSIE (ADC2 only)
//!   and starts the injected conversions (CR.JADSTART).
//! - The control interrupt (`ADC1_2`, ADC2's JEOS) reads JDR1/JDR2 of both
//!   ADCs and clears JEOS/JEOC (write 1 to ISR).

use embassy_stm32::adc::{Adc, AdcChannel, AdcConfig, Exten, SampleTime};
use embassy_stm32::pac;
use embassy_stm32::triggers::TIM1_TRGO2;
use embassy_stm32::Peri;

use crate::board;
use crate::DRIVE_CONFIG;

/// Sampling time of the phase currents (op-amp outputs), ADC clock cycles.
pub const CURRENT_SAMPLE_TIME: SampleTime = SampleTime::CYCLES12_5;
/// Sampling time of the DC bus (resistive divider), ADC clock cycles.
pub const DC_BUS_SAMPLE_TIME: SampleTime = SampleTime::CYCLES24_5;

/// Polls of ADC1's end-of-sequence flag the interrupt allows after ADC2's
/// has fired: ADC1's sequence is 12 ADC cycles (48 CPU cycles) shorter, so
/// it is normally done already; 100 polls are well over 100 CPU cycles.
const ADC1_WAIT_POLLS: u32 = 100;

const _: () = assert!(DRIVE_CONFIG.adc_bits == 12, "the ADCs run at their 12-bit reset resolution");

/// One PWM period's raw conversions, ADC codes (0..=4095).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Samples {
    /// Phase currents U, V, W (controller phases a, b, c), codes with the
    /// board's sign ([`board_sign`]).
    pub phase_codes: [u16; 3],
    /// DC-bus divider, raw code.
    pub dc_bus_code: u16,
}

/// The sequences did not both complete.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Incomplete;

/// Powers up, calibrates and configures ADC1 and ADC2 for the injected
/// sequences of `board.rs`, triggered by TIM1_TRGO2, with the end-of-sequence
/// interrupt enabled on ADC2 (the NVIC line is enabled by `control::start`).
pub fn init(
    adc_uw: Peri<'static, board::AdcUw>,
    adc_v_bus: Peri<'static, board::AdcVBus>,
    current_u: Peri<'static, board::CurrentUPin>,
    current_v: Peri<'static, board::CurrentVPin>,
    current_w: Peri<'static, board::CurrentWPin>,
    dc_bus: Peri<'static, board::DcBusPin>,
) {
    let adc1 = Adc::new(adc_uw, AdcConfig::default());
    let adc2 = Adc::new(adc_v_bus, AdcConfig::default());

    let u = AdcChannel::<board::AdcUw>::degrade_adc(current_u);
    let w = AdcChannel::<board::AdcUw>::degrade_adc(current_w);
    let v = AdcChannel::<board::AdcVBus>::degrade_adc(current_v);
    let bus = AdcChannel::<board::AdcVBus>::degrade_adc(dc_bus);
    defmt::assert_eq!(u.get_hw_channel(), board::CURRENT_U_CHANNEL);
    defmt::assert_eq!(w.get_hw_channel(), board::CURRENT_W_CHANNEL);
    defmt::assert_eq!(v.get_hw_channel(), board::CURRENT_V_CHANNEL);
    defmt::assert_eq!(bus.get_hw_channel(), board::DC_BUS_CHANNEL);

    let injected_uw = adc1.setup_injected_conversions(
        [(u, CURRENT_SAMPLE_TIME), (w, CURRENT_SAMPLE_TIME)],
        TIM1_TRGO2,
        Exten::RISING_EDGE,
        false,
    );
    let injected_v_bus = adc2.setup_injected_conversions(
        [(v, CURRENT_SAMPLE_TIME), (bus, DC_BUS_SAMPLE_TIME)],
        TIM1_TRGO2,
        Exten::RISING_EDGE,
        true,
    );
    // Read by the interrupt through the register block; leaked so that their
    // Drop (which stops the ADC) never runs.
    core::mem::forget(injected_uw);
    core::mem::forget(injected_v_bus);
}

/// Whether ADC2 has finished an injected sequence that has not been taken.
#[inline]
pub fn sequence_done() -> bool {
    pac::ADC2.isr().read().jeos()
}

/// Largest ADC code.
const ADC_MAX_CODE: u16 = ((1u32 << crate::DRIVE_CONFIG.adc_bits) - 1) as u16;

/// A phase-current code with the board's sign: mirrored (`4095 - code`)
/// when the board's amplifiers invert
/// ([`crate::board::CURRENT_SENSE_INVERTED`]: on the IHM08M1 a current into
/// the machine lowers the reading), so that the drive core, which reads a
/// current into the machine above mid-scale, sees the right sign. The
/// mirror keeps both rails on rails; its one-code shift of mid-scale is
/// taken out by the offset calibration.
#[inline]
pub fn board_sign(code: u16) -> u16 {
    if crate::board::CURRENT_SENSE_INVERTED {
        ADC_MAX_CODE - code.min(ADC_MAX_CODE)
    } else {
        code
    }
}

/// Reads both sequences' results and clears their end-of-sequence flags.
/// Call when [`sequence_done`]; waits briefly for ADC1 if needed.
#[inline]
pub fn take() -> Result<Samples, Incomplete> {
    let (adc1, adc2) = (pac::ADC1, pac::ADC2);
    let mut polls = 0;
    while !adc1.isr().read().jeos() {
        polls += 1;
        if polls > ADC1_WAIT_POLLS {
            clear_flags();
            return Err(Incomplete);
        }
    }
    let samples = Samples {
        phase_codes: [
            board_sign(adc1.jdr(0).read().jdata()),
            board_sign(adc2.jdr(0).read().jdata()),
            board_sign(adc1.jdr(1).read().jdata()),
        ],
        dc_bus_code: adc2.jdr(1).read().jdata(),
    };
    clear_flags();
    Ok(samples)
}

/// Clears JEOS and JEOC of both ADCs (ISR bits are cleared by writing 1).
pub fn clear_flags() {
    for adc in [pac::ADC1, pac::ADC2] {
        adc.isr().write(|w| {
            w.set_jeos(true);
            w.set_jeoc(true);
        });
    }
}
