//! Torque-ripple compensation on the host: the strategies of
//! `drive_core::ripple` set up from the rig file, run over travels and model
//! mismatches, and the measures `host-sim compare` reports for each run.

use drive_core::config::Direction;
use drive_core::observer::{ChainObserver, ObserverTuning};
use drive_core::ripple::harmonics::HarmonicTable;
use drive_core::ripple::{RippleCompensator, Strategy};
use drive_core::Controller;
use serde::{Deserialize, Serialize};

use crate::{simulate_travel_faulted, FaultHook, SimError, SimOptions, TravelRun, TravelSpec};
use dsp::{constant_speed_stage, ride_quality, AnalysisError};
use plant::Plant;
use rig_config::RigConfig;

/// Why a comparison ([`run_case`]) stopped.
#[derive(Debug, thiserror::Error)]
pub enum CompareError {
    /// The travel without compensation failed.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// A travel with a compensation strategy failed.
    #[error("strategy {strategy}, travel {travel}")]
    Travel {
        /// The strategy's name ([`Strategy::name`]).
        strategy: &'static str,
        /// Which travel of the strategy, from 1.
        travel: usize,
        /// Why it failed.
        #[source]
        source: SimError,
    },
    /// The ride measures of a travel could not be computed.
    #[error(transparent)]
    Measures(#[from] AnalysisError),
}

/// The mechanical orders of the rig's `[[ripple]]` table, in file order.
pub fn ripple_orders(rig: &RigConfig) -> Vec<u16> {
    rig.ripple.iter().map(|r| r.mechanical_order.min(u16::MAX as u32) as u16).collect()
}

/// The rig's ripple `sum A_n cos(n theta + phi_n)` as a harmonic table, N m:
/// the ripple the plant applies, so `negated()` is a perfect compensation.
pub fn rig_ripple_table(rig: &RigConfig) -> HarmonicTable {
    let mut table = HarmonicTable::default();
    for (r, order) in rig.ripple.iter().zip(ripple_orders(rig)) {
        table.push_cosine(order, r.amplitude_nm as f32, r.phase_rad.cos() as f32, r.phase_rad.sin() as f32);
    }
    table
}

/// A compensator of the rig's ripple orders with `strategy`, and `table` as
/// the `Strategy::Table` table if given.
pub fn compensator(rig: &RigConfig, strategy: Strategy, table: Option<HarmonicTable>) -> RippleCompensator {
    let drive = rig.drive_config();
    let mut compensator = RippleCompensator::new(&drive, &rig.observer_model(), &ripple_orders(rig), strategy);
    if let Some(table) = table {
        compensator.set_table(table);
    }
    compensator
}

/// How the simulated rig differs from what the drive's model and table
/// assume.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum Mismatch {
    /// The plant is the nominal rig.
    Nominal,
    /// The plant's rope `EA` is `factor` times the nominal (the drive keeps the nominal).
    RopeEa {
        /// Factor on `EA` (dimensionless).
        factor: f64,
    },
    /// The plant's ripple amplitudes are `factor` times the nominal.
    RippleAmplitude {
        /// Factor on every `[[ripple]]` amplitude (dimensionless).
        factor: f64,
    },
    /// The plant's ripple phases drift with the shaft angle: each order `n`
    /// becomes `n (1 + fraction)`, so a harmonic slips by `n fraction` turns per revolution.
    RipplePhaseDrift {
        /// Relative order error (dimensionless).
        fraction: f64,
    },
}

impl Mismatch {
    /// The mismatch cases of `compare`: nominal, EA +-20 %, ripple amplitudes
    /// +-30 %, ripple phases drifting (0.5 % order error: the 12th order
    /// slips 0.06 turn, 22 degrees, per revolution).
    pub const CASES: [Mismatch; 6] = [
        Mismatch::Nominal,
        Mismatch::RopeEa { factor: 0.8 },
        Mismatch::RopeEa { factor: 1.2 },
        Mismatch::RippleAmplitude { factor: 0.7 },
        Mismatch::RippleAmplitude { factor: 1.3 },
        Mismatch::RipplePhaseDrift { fraction: 0.005 },
    ];

    /// Short label (`nominal`, `EA x0.8`, `ripple x1.3`, `phase drift 0.5%`).
    pub fn label(&self) -> String {
        match self {
            Mismatch::Nominal => "nominal".into(),
            Mismatch::RopeEa { factor } => format!("EA x{factor}"),
            Mismatch::RippleAmplitude { factor } => format!("ripple x{factor}"),
            Mismatch::RipplePhaseDrift { fraction } => format!("phase drift {}%", fraction * 100.0),
        }
    }

    /// The plant's rig for this mismatch (the drive keeps `nominal`'s drive config).
    pub fn plant_rig(&self, nominal: &RigConfig) -> RigConfig {
        let mut rig = nominal.clone();
        match *self {
            Mismatch::RopeEa { factor } => rig.mechanics.rope_ea_n *= factor,
            Mismatch::RippleAmplitude { factor } => {
                for r in rig.ripple.iter_mut() {
                    r.amplitude_nm *= factor;
                }
            }
            Mismatch::Nominal | Mismatch::RipplePhaseDrift { .. } => {}
        }
        rig
    }
}

/// The drive's chain observer for `rig` with the default tuning.
pub fn observer(rig: &RigConfig) -> Result<ChainObserver, SimError> {
    ChainObserver::new(rig.observer_model(), ObserverTuning::default())
        .map_err(|e| SimError::BadTravel(format!("observer model: {} must be {}", e.field, e.expected)))
}

/// Changes the plant's ripple orders before the first step (the phase-drift mismatch).
struct RippleOrderShift {
    fraction: f64,
    done: bool,
}

impl FaultHook for RippleOrderShift {
    fn before_step(&mut self, _t_s: f64, plant: &mut Plant) {
        if !self.done {
            for h in plant.ripple.harmonics.iter_mut() {
                h.mechanical_order *= 1.0 + self.fraction;
            }
            self.done = true;
        }
    }
}

/// One closed-loop travel on the plant of `nominal` changed by `mismatch`,
/// with `compensator` in a freshly powered-up drive of the nominal rig
/// (encoder from zero, as the plant's shaft angle); returns the run and the
/// compensator as the travel left it (what it learned).
pub fn travel_with_compensator(
    nominal: &RigConfig,
    mismatch: Mismatch,
    spec: &TravelSpec,
    options: &SimOptions,
    compensator: RippleCompensator,
) -> Result<(TravelRun, RippleCompensator), SimError> {
    let plant_rig = mismatch.plant_rig(nominal);
    let mut controller = Controller::new(&nominal.drive_config());
    let uses_observer = compensator.strategy() == Strategy::CarObserver;
    controller.set_observer(uses_observer);
    controller.set_compensation(Some(compensator));
    let task = drive_core::observer::ObserverTask::new(observer(nominal)?);
    let mut shift = RippleOrderShift { fraction: 0.0, done: false };
    let hook: Option<&mut dyn FaultHook> = match mismatch {
        Mismatch::RipplePhaseDrift { fraction } => {
            shift.fraction = fraction;
            Some(&mut shift)
        }
        _ => None,
    };
    let mut drive = crate::ObservedController { controller: &mut controller, task };
    let run = simulate_travel_faulted(&plant_rig, spec, options, &mut drive, hook, None, None)?;
    if uses_observer {
        // A missed deadline cannot happen here (the task runs after every
        // step); one would mean the schedule is broken.
        debug_assert_eq!(controller.observer_missed_deadlines(), 0);
    }
    let after = *controller.compensation().expect("installed above");
    Ok((run, after))
}

/// Mechanical orders whose car-acceleration amplitude `compare` reports
/// (12, 36 and 72 Hz at the rated 0.4 m/s, paper section 3.3).
pub const REPORTED_ORDERS: [u16; 3] = [12, 36, 72];
/// Window of the sliding order amplitude that times the learning, s.
pub const LEARNING_WINDOW_S: f64 = 1.0;

/// What `compare` measures on one travel.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RideMetrics {
    /// ISO 18738-1 A95 peak-to-peak of the Wk-weighted car vibration in the constant-speed stage, mg.
    pub a95_mg: f64,
    /// ISO 18738-1 maximum peak-to-peak in the constant-speed stage, mg.
    pub max_peak_to_peak_mg: f64,
    /// Car acceleration amplitude of the line at the orders
    /// [`REPORTED_ORDERS`] over the constant-speed stage ([`line_amplitude`],
    /// lock-in on the encoder angle), m/s^2.
    pub car_order_amplitude_mps2: [f64; 3],
    /// Largest phase-current vector magnitude `sqrt(2/3 (ia^2+ib^2+ic^2))` over the travel, A.
    pub peak_current_a: f64,
    /// End times (s) and car amplitude at order 12 (m/s^2) of consecutive
    /// [`LEARNING_WINDOW_S`] windows of the constant-speed stage.
    pub order12_windows: Vec<(f64, f64)>,
    /// Start of the constant-speed stage, s.
    pub stage_start_s: f64,
}

/// Amplitude of `signal` at mechanical order `n` over `range` (lock-in on `angle_rad`).
pub fn order_amplitude(signal: &[f64], angle_rad: &[f64], n: f64, range: std::ops::Range<usize>) -> f64 {
    let (mut re, mut im) = (0.0, 0.0);
    for i in range.clone() {
        let phase = n * angle_rad[i];
        re += signal[i] * phase.cos();
        im -= signal[i] * phase.sin();
    }
    2.0 * (re * re + im * im).sqrt() / range.len().max(1) as f64
}

/// Largest [`order_amplitude`] of `signal` within +-1.5 % of order `n`
/// (13 lock-ins 0.25 % apart, finer than the 1/revolutions resolution of a
/// travel): the line near the order, wherever a drifting ripple puts it.
pub fn line_amplitude(signal: &[f64], angle_rad: &[f64], n: f64, range: std::ops::Range<usize>) -> f64 {
    (-6..=6)
        .map(|i| order_amplitude(signal, angle_rad, n * (1.0 + 0.0025 * i as f64), range.clone()))
        .fold(0.0, f64::max)
}

/// The measures of one travel.
pub fn ride_metrics(run: &TravelRun) -> Result<RideMetrics, AnalysisError> {
    let fs = run.sample_rate_hz;
    let stage = constant_speed_stage(&run.speed_radps, fs)?;
    let quality = ride_quality(&run.acc_car_mps2, fs, Some(stage.clone()))?;
    let constant = quality.constant_speed.expect("a constant-speed range was given");
    let amplitude = |n: u16| line_amplitude(&run.acc_car_mps2, &run.angle_rad, n as f64, stage.clone());
    let window = (LEARNING_WINDOW_S * fs) as usize;
    let order12_windows = (stage.start..stage.end.saturating_sub(window))
        .step_by(window.max(1))
        .map(|start| {
            let end = start + window;
            (run.time_s[end - 1], order_amplitude(&run.acc_car_mps2, &run.angle_rad, 12.0, start..end))
        })
        .collect();
    let peak_current_a = (0..run.time_s.len())
        .map(|i| {
            let [a, b, c] = [&run.phase_currents_a[0], &run.phase_currents_a[1], &run.phase_currents_a[2]];
            (2.0 / 3.0 * (a[i] * a[i] + b[i] * b[i] + c[i] * c[i])).sqrt()
        })
        .fold(0.0, f64::max);
    Ok(RideMetrics {
        a95_mg: constant.a95_peak_to_peak_mg,
        max_peak_to_peak_mg: constant.max_peak_to_peak_mg,
        car_order_amplitude_mps2: REPORTED_ORDERS.map(amplitude),
        peak_current_a,
        order12_windows,
        stage_start_s: run.time_s[stage.start],
    })
}

/// Learning time: from the start of the constant-speed stage to the end of
/// the first window after which every window's order-12 car amplitude stays
/// at least 20 dB under the uncompensated travel's same window, minus one
/// window (0 if the first window already is); `None` if it never gets there.
pub fn learning_time_s(compensated: &RideMetrics, uncompensated: &RideMetrics) -> Option<f64> {
    let pairs: Vec<(f64, bool)> = compensated
        .order12_windows
        .iter()
        .zip(&uncompensated.order12_windows)
        .map(|(&(t, a), &(_, a0))| (t, a <= 0.1 * a0))
        .collect();
    let first_good_run = (0..pairs.len()).find(|&i| pairs[i..].iter().all(|&(_, good)| good))?;
    let end = pairs.get(first_good_run)?.0;
    Some((end - compensated.stage_start_s - LEARNING_WINDOW_S).max(0.0))
}

/// One row of the `compare` table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CompareRow {
    /// Index of the case in the full sweep (for sharding and merging).
    pub case_index: usize,
    /// Strategy name.
    pub strategy: String,
    /// Car mass, kg.
    pub m_car_kg: f64,
    /// `up` or `down`.
    pub direction: String,
    /// Mismatch label.
    pub mismatch: String,
    /// A95 peak-to-peak, constant speed, mg.
    pub a95_mg: f64,
    /// Maximum peak-to-peak, constant speed, mg.
    pub max_peak_to_peak_mg: f64,
    /// Car acceleration amplitude at order 12 (11.8 Hz at 0.4 m/s), m/s^2.
    pub car_12x_mps2: f64,
    /// At order 36 (35 Hz), m/s^2.
    pub car_36x_mps2: f64,
    /// At order 72 (71 Hz), m/s^2.
    pub car_72x_mps2: f64,
    /// Order-12 amplitude against no compensation, dB.
    pub car_12x_change_db: f64,
    /// A95 against no compensation, % (negative: better).
    pub a95_change_pct: f64,
    /// Largest phase-current vector magnitude, A.
    pub peak_current_a: f64,
    /// Learning time in the travel (see [`learning_time_s`]), s; empty if never.
    pub learning_time_s: Option<f64>,
    /// Travels run (iterative learning: the learning travels plus the one measured).
    pub travels: usize,
    /// Orders that backed off in the measured travel (space-separated).
    pub backed_off_orders: String,
}

/// One case of the sweep: a travel and a mismatch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Case {
    /// Car mass, kg.
    pub m_car_kg: f64,
    /// Direction.
    pub direction: Direction,
    /// Mismatch of the plant.
    pub mismatch: Mismatch,
}

/// Every case: the rig's car masses x up, down x [`Mismatch::CASES`].
pub fn all_cases(rig: &RigConfig) -> Vec<Case> {
    let mut cases = Vec::new();
    for mismatch in Mismatch::CASES {
        for &m_car_kg in &rig.mechanics.m_car_kg {
            for direction in [Direction::Up, Direction::Down] {
                cases.push(Case { m_car_kg, direction, mismatch });
            }
        }
    }
    cases
}

/// Runs every strategy on `case` and returns one row each (`Off` first).
/// `table` is the calibrated `Strategy::Table` table; iterative learning runs
/// `learning_travels` travels before the measured one.
pub fn run_case(
    rig: &RigConfig,
    case_index: usize,
    case: &Case,
    table: &HarmonicTable,
    strategies: &[Strategy],
    learning_travels: usize,
) -> Result<Vec<CompareRow>, CompareError> {
    let spec = TravelSpec::full_travel(rig, case.m_car_kg, case.direction);
    let options = SimOptions::for_rig(rig);
    let (off_run, _) =
        travel_with_compensator(rig, case.mismatch, &spec, &options, compensator(rig, Strategy::Off, None))?;
    let off = ride_metrics(&off_run)?;
    drop(off_run);
    let mut rows = Vec::new();
    for &strategy in strategies {
        let (metrics, comp, travels) = if strategy == Strategy::Off {
            (off.clone(), compensator(rig, Strategy::Off, None), 1)
        } else {
            let mut comp = compensator(rig, strategy, (strategy == Strategy::Table).then_some(*table));
            let travels = if strategy == Strategy::Learning { learning_travels + 1 } else { 1 };
            let mut last = None;
            for travel in 0..travels {
                let (run, after) = travel_with_compensator(rig, case.mismatch, &spec, &options, comp)
                    .map_err(|source| CompareError::Travel { strategy: strategy.name(), travel: travel + 1, source })?;
                comp = after;
                last = Some(ride_metrics(&run)?);
            }
            (last.expect("at least one travel"), comp, travels)
        };
        let backed: Vec<String> = (0..comp.applied().len)
            .filter(|&k| comp.backed_off()[k])
            .map(|k| comp.applied().orders[k].to_string())
            .collect();
        let [a12, a36, a72] = metrics.car_order_amplitude_mps2;
        rows.push(CompareRow {
            case_index,
            strategy: strategy.name().into(),
            m_car_kg: case.m_car_kg,
            direction: if case.direction == Direction::Up { "up" } else { "down" }.into(),
            mismatch: case.mismatch.label(),
            a95_mg: metrics.a95_mg,
            max_peak_to_peak_mg: metrics.max_peak_to_peak_mg,
            car_12x_mps2: a12,
            car_36x_mps2: a36,
            car_72x_mps2: a72,
            car_12x_change_db: 20.0 * (a12 / off.car_order_amplitude_mps2[0]).log10(),
            a95_change_pct: 100.0 * (metrics.a95_mg / off.a95_mg - 1.0),
            peak_current_a: metrics.peak_current_a,
            learning_time_s: if strategy == Strategy::Off { None } else { learning_time_s(&metrics, &off) },
            travels,
            backed_off_orders: backed.join(" "),
        });
    }
    Ok(rows)
}

/// the `Strategy::Table` table: what `Strategy::Adaptive` learns in a calibration travel of the
/// nominal rig (the heaviest car, up).
pub fn calibrate_table(rig: &RigConfig) -> Result<HarmonicTable, SimError> {
    let m_car = rig.mechanics.m_car_kg.iter().copied().fold(f64::MIN, f64::max);
    let spec = TravelSpec::full_travel(rig, m_car, Direction::Up);
    let (_, after) = travel_with_compensator(
        rig,
        Mismatch::Nominal,
        &spec,
        &SimOptions::for_rig(rig),
        compensator(rig, Strategy::Adaptive, None),
    )?;
    Ok(after.learned_table())
}
