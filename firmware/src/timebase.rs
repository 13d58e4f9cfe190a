//! Microsecond time stamps of the control interrupt: TIM2, a 32-bit timer,
//! free-running at 1 MHz (PSC = 169 at 170 MHz, ARR = 0xFFFF_FFFF), so its
//! CNT is the `time_us` of `drive_core::SensorFrame` directly, wrapping modulo
//! 2^32 like the controller expects.

use embassy_stm32::pac;
use embassy_stm32::timer::low_level::Timer;
use embassy_stm32::Peri;

use crate::board;

/// Counting rate of the time stamps, Hz.
pub const TICK_HZ: u32 = 1_000_000;

const _: () = assert!(board::SYSCLK_HZ % TICK_HZ == 0, "TIM2 cannot divide SYSCLK down to 1 MHz exactly");

/// Starts TIM2 at [`TICK_HZ`].
pub fn init(tim: Peri<'static, board::TimebaseTimer>) {
    // Enables and resets TIM2's clock.
    let timer = Timer::new(tim);
    let t = pac::TIM2;
    t.psc().write_value((board::SYSCLK_HZ / TICK_HZ - 1) as u16);
    t.arr().write_value(u32::MAX);
    // Load PSC into its shadow register.
    t.egr().write(|w| w.set_ug(true));
    t.cr1().modify(|w| w.set_cen(true));
    // Read through the register block; leaked so that its Drop (TIM2 clock
    // off) never runs.
    core::mem::forget(timer);
}

/// Microseconds since [`init`], wrapping modulo 2^32.
#[inline]
pub fn now_us() -> u32 {
    pac::TIM2.cnt().read()
}
