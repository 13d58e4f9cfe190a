//! Inverter PWM on TIM1: centre-aligned complementary PWM with hardware dead
//! time, the over-current break input, and the ADC trigger.
//!
//! Register use (RM0440, advanced-control timer):
//! - CR1: centre-aligned mode 1 (CMS = 01), auto-reload preload (ARPE),
//!   CKD = 1 so the dead-time clock is the 170 MHz timer clock.
//! - PSC = 0, ARR = `DRIVE_CONFIG.pwm_period_counts` (5312): the counter runs
//!   0 -> ARR -> 0 in 2 ARR ticks, one PWM period (16.0 kHz at 170 MHz).
//! - CCMR1/CCMR2: channels 1-3 in PWM mode 1 with compare preload (OCxREF
//!   active, i.e. high side on, while CNT < CCRx); channel 4 in PWM mode 2 at
//!   CCR4 = ARR - [`TRIGGER_LEAD_COUNTS`], so OC4REF rises just before the
//!   counter peak, in the middle of the zero vector where all three low
//!   sides conduct and the low-side shunts carry the phase currents.
//! - CR2: MMS2 = OC4REF, so TRGO2 (ADC1/ADC2 injected trigger JEXTSEL 8)
//!   rises once per period at the peak; OISx = 0, OISxN = 1 on the
//!   IHM08M1 (idle: high-side inputs low, low-side inputs high, every
//!   switch off; from the board description's active levels).
//! - RCR: repetition counter 1 with the update event phased onto the
//!   counter underflow (`lock_update_to_underflow` sets and checks the
//!   phase), so the preloaded compares written by the control interrupt
//!   after the peak's sample take effect once per period, at the next
//!   valley, half a period after the sample.
//! - BDTR: dead time DTG from `DEAD_TIME_S` (1 us = 170 ticks, exact), break
//!   input 1 enabled (BKE) active low (BKP = 0) with an 8-sample filter (47 ns),
//!   OSSI = OSSR = 1 (outputs driven to their idle level, every switch off,
//!   when MOE = 0), AOE = 0 (only software sets MOE again after a break),
//!   MOE = 0 at start, then LOCK level 3 (dead time, break, polarities,
//!   off-states and output modes can no longer be written until reset).
//! - AF1: BKINE = 1, BKINP = 0: the PA6 pin feeds break input 1 unchanged.
//! - CCER: CC1E-CC3E and CC1NE-CC3NE set; CCxP from the high sides' and
//!   CCxNP from the low sides' active level (on the IHM08M1 CCxP = 0,
//!   CCxNP = 1: the L6398's LIN is active low); CC4E set too, though CH4
//!   has no pin (OC4REF is internal).
//! - SR: BIF (break flag) polled by the control interrupt, UIF during [`init`].
//!
//! A break (the IHM08M1's over-current comparator pulling PA6 low) clears MOE
//! in hardware within the filter time, without software; the control
//! interrupt sees BIF and latches a fault so that it never sets MOE again.

use embassy_stm32::gpio::{AfType, Flex, OutputType, Pull};
use embassy_stm32::pac;
use embassy_stm32::pac::timer::vals::{Ckd, FilterValue, Lock, Mms2, Ocm, Ossi, Ossr, Urs};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::complementary_pwm::{BreakInputPolarity, ComplementaryPwm, ComplementaryPwmPin};
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::timer::{BkIn1, BreakInputPin, Channel};
use embassy_stm32::Peri;

use crate::board;
use crate::{DEAD_TIME_S, DRIVE_CONFIG};

/// The high-side gate inputs are active low (board description).
const HIGH_ACTIVE_LOW: bool = board::PWM_U_HIGH_ACTIVE_LOW;
/// The low-side gate inputs are active low (board description: the L6398's LIN).
const LOW_ACTIVE_LOW: bool = board::PWM_U_LOW_ACTIVE_LOW;

/// Auto-reload value: counter peak, and the compare of a 100 % duty, timer ticks.
pub const PERIOD_COUNTS: u16 = DRIVE_CONFIG.pwm_period_counts;

/// One PWM period in CPU cycles (`2 * ARR`; the timer counts at SYSCLK).
pub const PERIOD_CYCLES: u32 = 2 * PERIOD_COUNTS as u32;

/// Half a PWM period in CPU cycles: from the sample at the counter peak to
/// the valley where the compares load, the control step's deadline.
pub const HALF_PERIOD_CYCLES: u32 = PERIOD_COUNTS as u32;

/// How many timer ticks before the counter peak the ADC trigger (OC4REF)
/// rises: 16 ticks = 94 ns, so that the ADC's 12.5-cycle (294 ns) sampling
/// window, which opens a few ADC clocks after the trigger, lies around the
/// middle of the zero vector; OC4REF stays high for `2 * 16 - 1` ticks,
/// wide enough for the ADC's trigger synchronisation.
pub const TRIGGER_LEAD_COUNTS: u16 = 16;

/// Requested dead time in timer ticks (rounded to nearest), from `DEAD_TIME_S`.
pub const DEAD_TIME_COUNTS: u32 = (DEAD_TIME_S * board::SYSCLK_HZ as f32 + 0.5) as u32;

/// BDTR.DTG and the dead time it gives, timer ticks, with CKD = 1 (t_DTS =
/// one timer tick): the smallest representable dead time not shorter than
/// `counts` (RM0440 DTG encoding: 0..=127 in steps of 1, 128..=254 of 2,
/// 256..=504 of 8, 512..=1008 of 16); `None` above 1008 ticks.
pub const fn dead_time_register(counts: u32) -> Option<(u8, u32)> {
    if counts <= 127 {
        Some((counts as u8, counts))
    } else if counts <= 254 {
        let steps = counts.div_ceil(2);
        Some((0b1000_0000 | (steps - 64) as u8, steps * 2))
    } else if counts <= 504 {
        let steps = counts.div_ceil(8);
        Some((0b1100_0000 | (steps - 32) as u8, steps * 8))
    } else if counts <= 1008 {
        let steps = counts.div_ceil(16);
        Some((0b1110_0000 | (steps - 32) as u8, steps * 16))
    } else {
        None
    }
}

const DEAD_TIME: (u8, u32) = match dead_time_register(DEAD_TIME_COUNTS) {
    Some(dtg) => dtg,
    None => panic!("[inverter].dead_time_s is longer than TIM1 can insert (1008 ticks = 5.9 us)"),
};
/// BDTR.DTG value of the configured dead time.
pub const DTG: u8 = DEAD_TIME.0;
/// Dead time TIM1 inserts, timer ticks (170 = 1.0 us for the rig file's 1 us).
pub const DEAD_TIME_INSERTED_COUNTS: u32 = DEAD_TIME.1;

const _: () = {
    assert!(DEAD_TIME_COUNTS > 0, "a complementary bridge needs a dead time");
    assert!(
        DEAD_TIME_INSERTED_COUNTS < PERIOD_COUNTS as u32 / 8,
        "dead time above 1/16 of the PWM period: check [inverter].dead_time_s"
    );
    assert!(PERIOD_COUNTS > 4 * TRIGGER_LEAD_COUNTS, "PWM period too short for the ADC trigger lead");
    assert!(
        DRIVE_CONFIG.current_loop_hz == DRIVE_CONFIG.pwm_hz,
        "the firmware runs one controller step per PWM period: current_loop_hz must equal pwm_hz"
    );
};

/// Why [`init`] refused to run the inverter.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum PwmError {
    /// The counter produced no update event within three PWM periods.
    NoUpdateEvent,
    /// The update event could not be phased onto the counter underflow.
    UpdateNotAtUnderflow,
}

/// Sets TIM1 up as described in the module doc and starts it, outputs off
/// (MOE = 0: every switch off). Call once; TIM1 and its pins then belong to the
/// control interrupt for the rest of the run.
#[allow(clippy::too_many_arguments)]
pub fn init(
    tim: Peri<'static, board::PwmTimer>,
    u_high: Peri<'static, board::PwmUHigh>,
    v_high: Peri<'static, board::PwmVHigh>,
    w_high: Peri<'static, board::PwmWHigh>,
    u_low: Peri<'static, board::PwmULow>,
    v_low: Peri<'static, board::PwmVLow>,
    w_low: Peri<'static, board::PwmWLow>,
    break_in: Peri<'static, board::BreakIn>,
) -> Result<(), PwmError> {
    // The driver enables TIM1's clock, selects centre-aligned mode, PWM mode
    // 1 with preload on all four channels, and starts the counter. It also
    // sets MOE with every channel still disabled (pins not driven, like their
    // reset state); MOE goes off first thing below, before any channel is
    // enabled.
    let mut pwm = ComplementaryPwm::new(
        tim,
        Some(PwmPin::new(u_high, OutputType::PushPull)),
        Some(ComplementaryPwmPin::new(u_low, OutputType::PushPull)),
        Some(PwmPin::new(v_high, OutputType::PushPull)),
        Some(ComplementaryPwmPin::new(v_low, OutputType::PushPull)),
        Some(PwmPin::new(w_high, OutputType::PushPull)),
        Some(ComplementaryPwmPin::new(w_low, OutputType::PushPull)),
        None,
        None,
        Hertz(DRIVE_CONFIG.pwm_hz as u32),
        CountingMode::CenterAlignedDownInterrupts,
    );
    pwm.set_master_output_enable(false);

    let t = pac::TIM1;
    t.cr1().modify(|w| {
        w.set_cen(false);
        w.set_ckd(Ckd::DIV1);
    });

    // Exact period: the driver's frequency rounding may differ from the
    // rig-config derivation the controller's compares are scaled to.
    t.psc().write_value(0);
    t.arr().write(|w| w.set_arr(PERIOD_COUNTS));
    for channel in 0..3 {
        t.ccr(channel).write(|w| w.set_ccr(0));
    }

    // ADC trigger: OC4REF (PWM mode 2) high around the peak, as TRGO2.
    t.ccmr_output(1).modify(|w| {
        w.set_ocm(1, Ocm::PWM_MODE2);
        w.set_ocpe(1, true);
    });
    t.ccr(3).write(|w| w.set_ccr(PERIOD_COUNTS - TRIGGER_LEAD_COUNTS));
    // CH4 has no pin in alternate-function mode, so enabling its output
    // drives nothing; it only makes sure OC4REF is generated.
    t.ccer().modify(|w| w.set_cce(3, true));
    pwm.set_mms2(Mms2::COMPARE_OC4);

    // Safe state and break input.
    pwm.set_off_state_selection_idle(Ossi::IDLE_LEVEL);
    pwm.set_off_state_selection_run(Ossr::IDLE_LEVEL);
    // Gate polarities from the board description: the L6398's HIN active
    // high, its LIN active low (datasheet truth table). The idle levels
    // (OISx, OISxN) are pin levels (RM0440, output control bits of the
    // complementary channels, as remembered: not re-read, check on the
    // first power-up): each the inactive level of its input, so MOE = 0
    // turns every switch off.
    t.ccer().modify(|w| {
        for channel in 0..3 {
            w.set_ccp(channel, HIGH_ACTIVE_LOW);
            w.set_ccnp(channel, LOW_ACTIVE_LOW);
        }
    });
    t.cr2().modify(|w| {
        for channel in 0..3 {
            w.set_ois(channel, HIGH_ACTIVE_LOW);
            w.set_oisn(channel, !LOW_ACTIVE_LOW);
        }
    });
    t.bdtr().modify(|w| w.set_dtg(DTG));
    let break_af = <board::BreakIn as BreakInputPin<board::PwmTimer, BkIn1>>::af_num(&break_in);
    let mut break_pin = Flex::new(break_in);
    break_pin.set_as_af_unchecked(break_af, AfType::input(Pull::None));
    pwm.set_automatic_output_enable(false);
    pwm.set_break_polarity(BreakInputPolarity::ACTIVE_LOW);
    pwm.set_break_filter(FilterValue::FCK_INT_N8);
    pwm.set_break_input_pin_enable(true);
    pwm.set_break_enable(true);

    // Outputs under timer control from now on: with MOE = 0 and OSSI = 1
    // they drive their idle level, every switch off.
    for channel in [Channel::Ch1, Channel::Ch2, Channel::Ch3] {
        pwm.enable(channel);
    }

    // Load the shadow registers (PSC, ARR, CCR, repetition counter 0) and
    // start: with RCR = 0 every overflow and underflow is an update event.
    t.rcr().write(|w| w.set_rep(0));
    t.cr1().modify(|w| w.set_urs(Urs::COUNTER_ONLY));
    t.egr().write(|w| w.set_ug(true));
    t.cr1().modify(|w| w.set_urs(Urs::ANY_EVENT));
    t.cr1().modify(|w| w.set_cen(true));
    let phased = critical_section::with(|_| lock_update_to_underflow());

    t.bdtr().modify(|w| w.set_lock(Lock::LEVEL3));
    clear_break_flag();

    // TIM1 and the pins stay configured for the whole run and are driven
    // through the register block from here on: the drivers are leaked so that
    // their Drop (TIM1 clock off, pins floating) never runs.
    core::mem::forget(pwm);
    core::mem::forget(break_pin);
    phased
}

/// Phases the update event onto the counter underflow, with the counter
/// running. With RCR = 0 every overflow and underflow is an update, and each
/// update reloads the repetition counter from RCR; writing RCR = 1 right
/// after the update at a peak makes the next update (reloading 1) the
/// underflow, and from then on every update is an underflow, once per
/// period, if the repetition counter behaves as RM0440 describes. Four
/// updates are checked afterwards; if they are not all underflows, the same
/// is tried once more with RCR written after an underflow instead, so the
/// result does not rest on one reading of the reference manual. Runs with
/// interrupts masked (at most about 13 PWM periods, 0.8 ms): RCR must be
/// written within half a period (31 us) of the update.
fn lock_update_to_underflow() -> Result<(), PwmError> {
    let t = pac::TIM1;
    for write_after_peak in [true, false] {
        t.rcr().write(|w| w.set_rep(0));
        // The next update reloads 0: from there on every event is an update.
        wait_update()?;
        let mut armed = false;
        for _ in 0..2 {
            if wait_update()? == write_after_peak {
                t.rcr().write(|w| w.set_rep(1));
                armed = true;
                break;
            }
        }
        if !armed {
            continue;
        }
        let mut all_underflows = true;
        for _ in 0..4 {
            all_underflows &= !wait_update()?;
        }
        if all_underflows {
            return Ok(());
        }
    }
    Err(PwmError::UpdateNotAtUnderflow)
}

/// Clears UIF, waits for the next update event (at most three PWM periods)
/// and tells whether it came at the peak (`true`) or at the underflow: the
/// counter is then within a few ticks of ARR or of 0.
fn wait_update() -> Result<bool, PwmError> {
    let t = pac::TIM1;
    clear_sr(|w| w.set_uif(false));
    // Each poll takes more than one CPU cycle, so this bounds the wait to
    // more than three periods.
    for _ in 0..3 * PERIOD_CYCLES {
        if t.sr().read().uif() {
            return Ok(t.cnt().read().cnt() > PERIOD_COUNTS / 2);
        }
    }
    Err(PwmError::NoUpdateEvent)
}

/// Writes SR with every flag bit 1 except those `clear` sets to 0 (SR flags
/// are cleared by writing 0; writing 1 leaves them unchanged).
fn clear_sr(clear: impl FnOnce(&mut pac::timer::regs::SrAdv)) {
    let mut value = pac::timer::regs::SrAdv(0xFFFF_FFFF);
    clear(&mut value);
    pac::TIM1.sr().write_value(value);
}

/// Writes the three phase compares, timer ticks (0 = low side on for the
/// whole period, [`PERIOD_COUNTS`] = high side on). Preloaded: they take
/// effect at the next update event, the counter underflow.
#[inline]
pub fn set_compares(compare: [u16; 3]) {
    let t = pac::TIM1;
    for (channel, value) in compare.into_iter().enumerate() {
        t.ccr(channel).write(|w| w.set_ccr(value.min(PERIOD_COUNTS)));
    }
}

/// Main output enable (BDTR.MOE): `false` clears it at once (the safe
/// state, every switch off); `true` sets it only if it is off and no break
/// has been flagged (BIF, cleared only by the reset command). MOE is
/// written only on a change, never rewritten each period: a break that
/// clears it between the step's read of the break flag and this call stays
/// in force (with AOE = 0 only software sets MOE again).
#[inline]
pub fn set_outputs_enabled(enabled: bool) {
    let t = pac::TIM1;
    let on = t.bdtr().read().moe();
    if !enabled {
        if on {
            t.bdtr().modify(|w| w.set_moe(false));
        }
    } else if !on && !break_occurred() {
        t.bdtr().modify(|w| w.set_moe(true));
    }
}

/// Whether TIM1 counts down (between the counter peak, where the currents
/// are sampled, and the valley, where the preloaded compares load).
#[inline]
pub fn counting_down() -> bool {
    pac::TIM1.cr1().read().dir() == pac::timer::vals::Dir::DOWN
}

/// Whether a break (BKIN over-current) has occurred since the flag was last
/// cleared; the hardware has then already cleared MOE.
#[inline]
pub fn break_occurred() -> bool {
    pac::TIM1.sr().read().bif(0)
}

/// Clears the break flag (BIF).
pub fn clear_break_flag() {
    clear_sr(|w| w.set_bif(0, false));
}
