//! Current-sensor offset calibration at start-up.
//!
//! With no phase current flowing, every phase-current channel should read the
//! ADC's zero-current code (mid-scale). In practice the shunt amplifier's
//! output offset and the ADC's own offset shift each channel by some codes,
//! and an uncorrected offset is a constant current error that the current loop
//! turns into a torque ripple at the electrical frequency.
//!
//! At start-up, while no current can flow, the firmware feeds
//! [`OffsetCalibration::push`] one set of raw codes per PWM period;
//! [`OffsetCalibration::finish`] averages them per channel and checks that the
//! result is plausible:
//! - the measured zero-current code lies within [`MAX_OFFSET_PERCENT`] of full
//!   scale of mid-scale (a larger offset means a missing, mis-wired or
//!   saturated sensor, not an amplifier tolerance), and
//! - the channel is quiet: its samples span at most
//!   [`MAX_PEAK_TO_PEAK_PERCENT`] of full scale peak to peak (a noisier
//!   channel gives an unreliable mean, or current is flowing after all).
//!
//! From then on [`CurrentOffsets::correct`] moves every raw reading by the
//! measured offset before the controller sees it.
//!
//! Integer arithmetic only, on ADC codes ("codes": ADC output units, full
//! scale `2^adc_bits` codes); sums are `u32` and cannot overflow for up to
//! `u16::MAX` samples of 16-bit codes, and every conversion back to a code
//! saturates.

/// Largest accepted distance of a channel's measured zero-current code from
/// mid-scale, percent of full scale (`2^adc_bits` codes): 204 codes of a
/// 12-bit ADC, i.e. +-2.5 A on the reference rig's +-50 A current scale.
pub const MAX_OFFSET_PERCENT: u32 = 5;

/// Largest accepted peak-to-peak spread (largest minus smallest sample) of a
/// channel during the calibration, percent of full scale (`2^adc_bits`
/// codes): 40 codes of a 12-bit ADC, i.e. 1 A peak to peak on the reference
/// rig's +-50 A current scale.
pub const MAX_PEAK_TO_PEAK_PERCENT: u32 = 1;

/// Acceptance limits of a calibration, in ADC codes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OffsetLimits {
    /// ADC code of zero phase current (mid-scale), codes.
    pub zero_code: u16,
    /// Largest ADC code (the lowest is 0), codes.
    pub max_code: u16,
    /// Largest accepted |measured zero-current code - `zero_code`|, codes.
    pub max_offset_codes: u16,
    /// Largest accepted peak-to-peak spread of one channel's samples, codes.
    pub max_peak_to_peak_codes: u16,
}

impl OffsetLimits {
    /// The limits for an ADC of `adc_bits` bits (clamped to 1..=16): zero at
    /// `2^(adc_bits-1)`, largest code `2^adc_bits - 1`, offset bound
    /// [`MAX_OFFSET_PERCENT`] and noise bound [`MAX_PEAK_TO_PEAK_PERCENT`] of
    /// the full scale `2^adc_bits` (rounded down), codes.
    pub const fn for_adc_bits(adc_bits: u8) -> Self {
        let bits = if adc_bits < 1 {
            1
        } else if adc_bits > 16 {
            16
        } else {
            adc_bits
        };
        let full_scale = 1u32 << bits;
        Self {
            zero_code: (full_scale / 2) as u16,
            max_code: (full_scale - 1) as u16,
            max_offset_codes: (full_scale * MAX_OFFSET_PERCENT / 100) as u16,
            max_peak_to_peak_codes: (full_scale * MAX_PEAK_TO_PEAK_PERCENT / 100) as u16,
        }
    }
}

/// Why a calibration was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OffsetError {
    /// [`OffsetCalibration::finish`] was called before enough samples came in.
    NotEnoughSamples {
        /// Samples pushed so far.
        samples: u16,
        /// Samples the calibration needs.
        required: u16,
    },
    /// A channel's samples spread more than
    /// [`OffsetLimits::max_peak_to_peak_codes`].
    Noisy {
        /// Phase: 0 = a, 1 = b, 2 = c.
        phase: u8,
        /// Largest minus smallest sample of that channel, codes.
        peak_to_peak_codes: u16,
    },
    /// A channel's mean lies further than [`OffsetLimits::max_offset_codes`]
    /// from [`OffsetLimits::zero_code`].
    OffsetOutOfRange {
        /// Phase: 0 = a, 1 = b, 2 = c.
        phase: u8,
        /// Measured zero-current code (rounded mean) of that channel, codes.
        zero_current_code: u16,
    },
}

/// Accumulates raw phase-current codes while no current flows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OffsetCalibration {
    limits: OffsetLimits,
    required: u16,
    samples: u16,
    sum: [u32; 3],
    min: [u16; 3],
    max: [u16; 3],
}

impl OffsetCalibration {
    /// An empty calibration that needs `samples_required` sets of codes (at
    /// least 1; one set per PWM period, so 1024 sets take 64 ms at 16 kHz)
    /// and accepts the result within `limits`.
    pub const fn new(samples_required: u16, limits: OffsetLimits) -> Self {
        Self {
            limits,
            required: if samples_required == 0 { 1 } else { samples_required },
            samples: 0,
            sum: [0; 3],
            min: [u16::MAX; 3],
            max: [0; 3],
        }
    }

    /// Adds one set of raw codes of phases a, b, c (codes). Sets pushed after
    /// the calibration is complete are ignored, so the result is the mean of
    /// exactly the first `samples_required` sets.
    pub fn push(&mut self, codes: [u16; 3]) {
        if self.is_complete() {
            return;
        }
        for (phase, &code) in codes.iter().enumerate() {
            self.sum[phase] = self.sum[phase].saturating_add(code as u32);
            self.min[phase] = self.min[phase].min(code);
            self.max[phase] = self.max[phase].max(code);
        }
        self.samples += 1;
    }

    /// Sets of codes pushed so far (at most `samples_required`).
    pub fn samples(&self) -> u16 {
        self.samples
    }

    /// Whether `samples_required` sets have been pushed.
    pub fn is_complete(&self) -> bool {
        self.samples >= self.required
    }

    /// The measured offsets, or why they are not plausible. Checks, per phase
    /// a, b, c in turn: the peak-to-peak spread first (a noisy mean is
    /// meaningless), then the distance of the rounded mean from mid-scale.
    pub fn finish(&self) -> Result<CurrentOffsets, OffsetError> {
        if !self.is_complete() {
            return Err(OffsetError::NotEnoughSamples { samples: self.samples, required: self.required });
        }
        let n = self.samples as u32;
        let mut zero_current_codes = [0u16; 3];
        for (phase, code) in zero_current_codes.iter_mut().enumerate() {
            let peak_to_peak_codes = self.max[phase].saturating_sub(self.min[phase]);
            if peak_to_peak_codes > self.limits.max_peak_to_peak_codes {
                return Err(OffsetError::Noisy { phase: phase as u8, peak_to_peak_codes });
            }
            // Rounded mean; every sample is a u16, so the mean is one too.
            let mean = (self.sum[phase].saturating_add(n / 2) / n).min(u16::MAX as u32) as u16;
            if mean.abs_diff(self.limits.zero_code) > self.limits.max_offset_codes {
                return Err(OffsetError::OffsetOutOfRange { phase: phase as u8, zero_current_code: mean });
            }
            *code = mean;
        }
        Ok(CurrentOffsets { zero_current_codes, max_code: self.limits.max_code })
    }
}

/// Measured zero-current codes of the three phase-current channels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CurrentOffsets {
    /// Code each channel of phases a, b, c reads at zero current, codes.
    pub zero_current_codes: [u16; 3],
    /// Largest ADC code, codes.
    pub max_code: u16,
}

impl CurrentOffsets {
    /// Offsets that correct nothing: every channel reads `zero_code` at zero
    /// current, codes.
    pub const fn none(zero_code: u16, max_code: u16) -> Self {
        Self { zero_current_codes: [zero_code; 3], max_code }
    }

    /// Moves raw codes of phases a, b, c so that each channel's measured
    /// zero-current code maps to `zero_code` (codes):
    /// `raw - zero_current_code + zero_code`, clamped to `0..=max_code`.
    ///
    /// A raw code at a rail (0 or `max_code` and above) stays at that rail,
    /// so a saturated or disconnected sensor remains visible as one to the
    /// controller's plausibility check, whatever the offset.
    pub fn correct(&self, raw: [u16; 3], zero_code: u16) -> [u16; 3] {
        let max = self.max_code as i32;
        let mut out = [0u16; 3];
        for phase in 0..3 {
            let code = raw[phase];
            out[phase] = if code == 0 {
                0
            } else if code >= self.max_code {
                self.max_code
            } else {
                let moved = code as i32 - self.zero_current_codes[phase] as i32 + zero_code as i32;
                moved.clamp(0, max) as u16
            };
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const LIMITS: OffsetLimits = OffsetLimits::for_adc_bits(12);

    fn calibrate(samples: impl Iterator<Item = [u16; 3]>, required: u16) -> Result<CurrentOffsets, OffsetError> {
        let mut cal = OffsetCalibration::new(required, LIMITS);
        for codes in samples {
            cal.push(codes);
        }
        cal.finish()
    }

    #[test]
    fn twelve_bit_limits_are_the_stated_fractions_of_full_scale() {
        assert_eq!(
            LIMITS,
            OffsetLimits { zero_code: 2048, max_code: 4095, max_offset_codes: 204, max_peak_to_peak_codes: 40 }
        );
    }

    #[test]
    fn a_known_offset_is_measured_and_removed() {
        // Phase a sits 52 codes high, b 30 low, c on mid-scale; +-3 codes of noise.
        let noise = [-3i32, -1, 0, 2, 3, 1, -2, 0];
        let samples = (0..1024).map(|k| {
            let n = noise[k % noise.len()];
            [(2100 + n) as u16, (2018 + n) as u16, (2048 - n) as u16]
        });
        let offsets = calibrate(samples, 1024).unwrap();
        assert_eq!(offsets.zero_current_codes, [2100, 2018, 2048]);
        assert_eq!(offsets.correct([2100, 2018, 2048], 2048), [2048, 2048, 2048]);
        // A real current keeps its size: +100 codes on a, -100 on b.
        assert_eq!(offsets.correct([2200, 1918, 2048], 2048), [2148, 1948, 2048]);
    }

    #[test]
    fn pushes_after_completion_do_not_change_the_result() {
        let mut cal = OffsetCalibration::new(4, LIMITS);
        for _ in 0..4 {
            cal.push([2050, 2050, 2050]);
        }
        cal.push([2248, 2248, 2248]);
        assert_eq!(cal.samples(), 4);
        assert_eq!(cal.finish().unwrap().zero_current_codes, [2050; 3]);
    }

    #[test]
    fn too_few_samples_are_refused() {
        let mut cal = OffsetCalibration::new(16, LIMITS);
        cal.push([2048; 3]);
        assert_eq!(cal.finish(), Err(OffsetError::NotEnoughSamples { samples: 1, required: 16 }));
        assert_eq!(
            OffsetCalibration::new(0, LIMITS).finish(),
            Err(OffsetError::NotEnoughSamples { samples: 0, required: 1 })
        );
    }

    #[test]
    fn an_offset_beyond_the_bound_is_rejected_and_one_at_it_accepted() {
        let at_bound = 2048 + 204;
        assert!(calibrate(core::iter::repeat_n([2048, at_bound, 2048], 64), 64).is_ok());
        let beyond = 2048 - 205;
        assert_eq!(
            calibrate(core::iter::repeat_n([2048, 2048, beyond], 64), 64),
            Err(OffsetError::OffsetOutOfRange { phase: 2, zero_current_code: beyond })
        );
        // A channel stuck at a rail (missing sensor) is far outside as well.
        assert_eq!(
            calibrate(core::iter::repeat_n([0, 2048, 2048], 64), 64),
            Err(OffsetError::OffsetOutOfRange { phase: 0, zero_current_code: 0 })
        );
    }

    #[test]
    fn a_noisy_channel_is_rejected_even_with_a_good_mean() {
        // Phase b alternates +-21 codes around mid-scale: 42 codes peak to peak > 40.
        let samples = (0..256).map(|k| [2048, if k % 2 == 0 { 2027 } else { 2069 }, 2048]);
        assert_eq!(calibrate(samples, 256), Err(OffsetError::Noisy { phase: 1, peak_to_peak_codes: 42 }));
        // +-20 codes (40 peak to peak) is accepted.
        let samples = (0..256).map(|k| [2048, if k % 2 == 0 { 2028 } else { 2068 }, 2048]);
        assert_eq!(calibrate(samples, 256).unwrap().zero_current_codes, [2048; 3]);
    }

    #[test]
    fn correction_saturates_at_the_rails_and_keeps_rail_readings_on_them() {
        let offsets = CurrentOffsets { zero_current_codes: [2200, 1900, 2048], max_code: 4095 };
        // Raw readings at the rails stay there whatever the offset.
        assert_eq!(offsets.correct([0, 0, 0], 2048), [0, 0, 0]);
        assert_eq!(offsets.correct([4095, 4095, 4095], 2048), [4095, 4095, 4095]);
        assert_eq!(offsets.correct([u16::MAX; 3], 2048), [4095; 3]);
        // Near the rails the shift clamps instead of wrapping.
        assert_eq!(offsets.correct([100, 4000, 1], 2048), [0, 4095, 1]);
        // Phase b's 148-code shift moves a low raw code up, off the rail.
        assert_eq!(offsets.correct([2048, 1, 2048], 2048), [1896, 149, 2048]);
    }

    #[test]
    fn no_offsets_leave_codes_unchanged() {
        let none = CurrentOffsets::none(2048, 4095);
        assert_eq!(none.correct([1, 2048, 4094], 2048), [1, 2048, 4094]);
    }

    proptest! {
        #[test]
        fn corrected_codes_stay_in_range(
            raw in prop::array::uniform3(any::<u16>()),
            zero in prop::array::uniform3(1844u16..=2252),
        ) {
            let offsets = CurrentOffsets { zero_current_codes: zero, max_code: 4095 };
            for code in offsets.correct(raw, 2048) {
                prop_assert!(code <= 4095);
            }
        }

        #[test]
        fn the_mean_of_constant_codes_is_that_code(code in 1844u16..=2252, n in 1u16..2000) {
            let offsets = calibrate(core::iter::repeat_n([code; 3], n as usize), n).unwrap();
            prop_assert_eq!(offsets.zero_current_codes, [code; 3]);
        }
    }
}
