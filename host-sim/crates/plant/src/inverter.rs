//! Averaged three-phase inverter: over one PWM period each half bridge
//! applies its duty cycle of the DC bus; the star point floats, so the
//! phase-to-neutral voltages are the leg voltages minus their mean. The DC
//! bus bounds what can be applied (duties are limited to 0..1 by the timer).
//! With the PWM disabled all switches are open; the machine's back-EMF at
//! lift speeds (< 20 V) is far below the bus, so the freewheeling diodes do
//! not conduct once the current has decayed, which the plant models as the
//! currents set to zero.

/// Phase-to-neutral voltages (V) of the compare values (counts of a timer
/// period `period_counts`) on a bus of `dc_bus_v` volts.
pub fn phase_voltages_v(compare: [u16; 3], period_counts: u16, dc_bus_v: f64) -> [f64; 3] {
    let period = period_counts.max(1) as f64;
    let leg = compare.map(|c| (c as f64).min(period) / period * dc_bus_v);
    let mean = (leg[0] + leg[1] + leg[2]) / 3.0;
    leg.map(|v| v - mean)
}

/// Clarke transform (amplitude invariant) of phase voltages, `(alpha, beta)` V.
pub fn alpha_beta_v(phase_v: [f64; 3]) -> (f64, f64) {
    let [a, b, c] = phase_v;
    ((2.0 * a - b - c) / 3.0, (b - c) / 3f64.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_voltages_follow_duty_differences() {
        let v = phase_voltages_v([4000, 2656, 1000], 5312, 100.0);
        assert!((v[0] - v[1] - (4000.0 - 2656.0) / 5312.0 * 100.0).abs() < 1e-12);
        assert!(v.iter().sum::<f64>().abs() < 1e-12);
        let (alpha, _) = alpha_beta_v(v);
        assert!((alpha - v[0]).abs() < 1e-12);
    }
}
