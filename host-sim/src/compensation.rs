//! Torque-ripple compensation on the host: the strategies of
//! `shared::ripple` set up from the rig file, run over travels, and the
//! measures `compare` reports for each run.

use shared::ripple::harmonics::HarmonicTable;
use shared::ripple::{RippleCompensator, Strategy};
use shared::Controller;

use crate::closed_loop::{simulate_travel_with, SimError, SimOptions, TravelRun, TravelSpec};
use crate::config::RigConfig;

/// The mechanical orders of the rig's `[[ripple]]` table, in file order.
pub fn ripple_orders(rig: &RigConfig) -> Vec<u16> {
    rig.ripple.iter().map(|r| r.mechanical_order.min(u16::MAX as u32) as u16).collect()
}

/// The rig's ripple `sum A_n cos(n theta + phi_n)` as a harmonic table, N m:
/// the ripple the plant applies, so `negated()` is a perfect compensation.
pub fn rig_ripple_table(rig: &RigConfig) -> HarmonicTable {
    let mut table = HarmonicTable::default();
    for r in &rig.ripple {
        let order = r.mechanical_order.min(u16::MAX as u32) as u16;
        table.push_cosine(order, r.amplitude_nm as f32, r.phase_rad.cos() as f32, r.phase_rad.sin() as f32);
    }
    table
}

/// A compensator of the rig's ripple orders with `strategy`, and `table` as
/// strategy 1's table if given.
pub fn compensator(rig: &RigConfig, strategy: Strategy, table: Option<HarmonicTable>) -> RippleCompensator {
    let drive = rig.drive_config();
    let mut compensator = RippleCompensator::new(&drive, &ripple_orders(rig), strategy);
    if let Some(table) = table {
        compensator.set_table(table);
    }
    compensator
}

/// One closed-loop travel with `compensator` in a freshly powered-up drive
/// (encoder from zero, as the plant's shaft angle); returns the run and the
/// compensator as the travel left it (what it learned).
pub fn travel_with_compensator(
    rig: &RigConfig,
    spec: &TravelSpec,
    options: &SimOptions,
    compensator: RippleCompensator,
) -> Result<(TravelRun, RippleCompensator), SimError> {
    let mut controller = Controller::new(&rig.drive_config());
    controller.set_compensation(compensator);
    let run = simulate_travel_with(rig, spec, options, &mut controller, None, None)?;
    Ok((run, *controller.compensation()))
}
