//! The deadline of a control step on centre-aligned PWM with preloaded
//! compares that take effect at the counter's underflow (the valley).
//!
//! The phase currents are sampled at the counter peak; the step that uses
//! them starts after the conversions and must write its compares before
//! the next valley, half a PWM period after the sample: compares written
//! after the valley take effect a whole period late (at the valley after
//! it). That, not a whole period from the step's start, is the deadline.
//! The firmware reads the timer's direction when the compares are written
//! and the cycles since the step started ([`compares_in_time`]).

/// Whether compares written with the counter counting down
/// (`counting_down`, i.e. between the peak and the valley) and
/// `cycles_since_start` CPU cycles after the step started (the step starts
/// after the peak) take effect at the coming valley. The direction alone
/// cannot tell a write in the next period's down-count; the cycle count
/// rules that out as long as the step starts less than half a period
/// (`half_period_cycles`) after the peak.
pub fn compares_in_time(counting_down: bool, cycles_since_start: u32, half_period_cycles: u32) -> bool {
    counting_down && cycles_since_start < half_period_cycles
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A centre-aligned counter clocked at the CPU clock: peak at t = 0,
    /// valley at half a period; whether it counts down `t` cycles after a peak.
    fn counting_down_at(t: u32, period_cycles: u32) -> bool {
        t % period_cycles < period_cycles / 2
    }

    #[test]
    fn a_step_that_ends_after_the_valley_is_caught_and_one_before_it_is_not() {
        // The firmware's PWM: ARR 5312 at 170 MHz, a period of 10 624 cycles.
        let period = 2 * 5312;
        let half = period / 2;
        for latency in [0, 255, 1000, half - 1] {
            for duration in (0..3 * period).step_by(7) {
                let written = latency + duration;
                let late = written >= half;
                let seen_in_time = compares_in_time(counting_down_at(written, period), duration, half);
                assert_eq!(seen_in_time, !late, "latency {latency}, step {duration} cycles");
            }
        }
        // The worst step measured on the emulated Cortex-M4F, 5 376
        // instructions, at one cycle each after a 255-cycle start: late.
        assert!(!compares_in_time(counting_down_at(255 + 5376, period), 5376, half));
    }
}
