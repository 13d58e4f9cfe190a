//! Motor encoder on TIM4 in quadrature encoder mode, extended to 32 bits.
//!
//! Register use (RM0440, general-purpose timer): embassy-stm32's `Qei` maps
//! TI1/TI2 on CC1S/CC2S = 01, sets SMCR.SMS = encoder mode 3 (counts on
//! both edges of both tracks: 4 counts per line), ARR = 0xFFFF, and starts
//! the counter; this module adds the input filters CCMR1.IC1F/IC2F. The
//! control interrupt reads CNT once per PWM period.

use embassy_stm32::gpio::Pull;
use embassy_stm32::pac;
use embassy_stm32::pac::timer::vals::FilterValue;
use embassy_stm32::timer::qei::{Config, Qei, QeiMode};
use embassy_stm32::timer::{Ch1, Ch2};
use embassy_stm32::Peri;

use crate::board;

/// Input filter of both tracks: 8 consecutive equal samples at 170/16 MHz,
/// i.e. edges must be stable for 0.75 us. The fastest the tracks toggle is
/// at the over-speed limit, about 1.2 rev/s x 4096 lines = 5 kHz, a 100 us
/// half period.
pub const INPUT_FILTER: FilterValue = FilterValue::FDTS_DIV16_N8;

/// Starts TIM4 counting the encoder (pull-ups on both tracks, for
/// open-collector encoders; harmless for push-pull ones).
pub fn init(
    tim: Peri<'static, board::EncoderTimer>,
    track_a: Peri<'static, board::EncoderA>,
    track_b: Peri<'static, board::EncoderB>,
) {
    let config = Config { ch1_pull: Pull::Up, ch2_pull: Pull::Up, mode: QeiMode::Mode3, auto_reload: u16::MAX };
    let qei = Qei::new::<Ch1, Ch2>(tim, track_a, track_b, config);
    pac::TIM4.ccmr_input(0).modify(|w| {
        w.set_icf(0, INPUT_FILTER);
        w.set_icf(1, INPUT_FILTER);
    });
    // Read through the register block by the interrupt; leaked so that its
    // Drop (TIM4 clock off) never runs.
    core::mem::forget(qei);
}

/// The 16-bit hardware count, counts.
#[inline]
pub fn raw_count() -> u16 {
    pac::TIM4.cnt().read().cnt()
}

/// Extends the 16-bit counter to the free-running `u32` count of
/// `drive_core::SensorFrame` (wrapping modulo 2^32): adds the signed 16-bit
/// difference of each reading. Exact as long as the counter moves less than
/// 2^15 counts between readings (at most a few counts per PWM period here).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Extender {
    last_raw: u16,
    count: u32,
}

impl Extender {
    /// Starts at the hardware count `raw`, counts.
    pub const fn new(raw: u16) -> Self {
        Self { last_raw: raw, count: raw as u32 }
    }

    /// Takes the hardware count `raw` and returns the extended count, counts.
    #[inline]
    pub fn extend(&mut self, raw: u16) -> u32 {
        let delta = raw.wrapping_sub(self.last_raw) as i16;
        self.last_raw = raw;
        self.count = self.count.wrapping_add(delta as i32 as u32);
        self.count
    }
}
